"""Reports for CI pages: JUnit XML (one test case per segment) and Markdown summaries."""

from __future__ import annotations

import os
import xml.etree.ElementTree as ET
from dataclasses import dataclass

from credcli.errors import CredcliError


@dataclass(frozen=True)
class Case:
    """One JUnit test case: a segment, and why it failed (None when it passed)."""

    name: str
    classname: str
    failure: str | None
    details: str = ""


def junit_xml(suite: str, cases: list[Case]) -> str:
    """A JUnit XML document with one <testsuite>; failures carry their reason."""
    failures = sum(c.failure is not None for c in cases)
    root = ET.Element("testsuites", name="credcli", tests=str(len(cases)), failures=str(failures))
    node = ET.SubElement(
        root,
        "testsuite",
        name=suite,
        tests=str(len(cases)),
        failures=str(failures),
        errors="0",
        skipped="0",
    )
    for case in cases:
        tc = ET.SubElement(node, "testcase", name=case.name, classname=case.classname)
        if case.failure is not None:
            fail = ET.SubElement(tc, "failure", message=case.failure, type="CredibilityRegression")
            fail.text = case.details or case.failure
        elif case.details:
            ET.SubElement(tc, "system-out").text = case.details
    ET.indent(root)
    return '<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(root, encoding="unicode") + "\n"


def append_step_summary(markdown: str) -> None:
    """Append to $GITHUB_STEP_SUMMARY when it is set (GitHub Actions' job summary)."""
    path = os.environ.get("GITHUB_STEP_SUMMARY")
    if not path:
        return
    try:
        with open(path, "a", encoding="utf-8") as fh:
            fh.write(markdown if markdown.endswith("\n") else markdown + "\n")
    except OSError as exc:
        raise CredcliError(
            f"GITHUB_STEP_SUMMARY={path}: cannot append the summary: {exc.strerror}"
        ) from exc


def _fmt(x, spec=".3g"):
    return "—" if x is None else format(x, spec)


def gate_cases(comparisons, thresholds, log: str) -> list[Case]:
    cases = []
    for c in comparisons:
        failed = c.failed_with(thresholds)
        details = "; ".join(c.reasons + c.improvements)
        cases.append(
            Case(
                c.segment,
                f"credcli.gate.{_classname(log)}",
                "; ".join(c.reasons) if failed else None,
                details,
            )
        )
    return cases


def fail_on_cases(records: list[dict], failing: list[dict], fail_on) -> list[Case]:
    bad = {id(r) for r in failing}
    listed = ",".join(sorted(fail_on))
    return [
        Case(
            r["segment"],
            f"credcli.diagnose.{_classname(r['log'])}",
            f"label {r['label']} matches --fail-on {listed}" if id(r) in bad else None,
            f"label {r['label']}, ELT p {_fmt(r['elt_pvalue'])}, NCI {_fmt(r['nci'])} dB, ANEES {_fmt(r['anees'])}",
        )
        for r in records
    ]


def _classname(path: str) -> str:
    stem = os.path.splitext(os.path.basename(path))[0]
    return "".join(ch if ch.isalnum() or ch in "_-" else "_" for ch in stem) or "log"


_ICON = {"regressed": "❌", "improved": "✅", "unchanged": "➖", "new": "🆕", "missing": "⚠️"}


def gate_markdown(comparisons, thresholds, verdict: str, log: str, baseline: str) -> str:
    lines = [
        f"## credcli gate: {log}",
        "",
        f"**{verdict}**",
        "",
        f"Baseline `{baseline}`; thresholds: |NCI| +{thresholds.max_nci_increase:g} dB, "
        f"ANEES ×{thresholds.max_anees_ratio:g} further from 1, label gaining a condition, "
        f"ELT newly rejecting{'; new/missing segments allowed' if thresholds.allow_new_segments else ''}.",
        "",
        "| segment | status | label | NCI [dB] | ANEES | ELT p | why |",
        "|---|---|---|---:|---:|---:|---|",
    ]
    for c in comparisons:
        old, new = c.old or {}, c.new or {}
        label = f"{old.get('label', '—')} → {new.get('label', '—')}"
        why = "; ".join(c.reasons + c.improvements).replace("|", "\\|") or "—"
        lines.append(
            f"| {c.segment} | {_ICON[c.status.value]} {c.status.value} | {label} | "
            f"{_fmt(old.get('nci'))} → {_fmt(new.get('nci'))} | {_fmt(old.get('anees'))} → "
            f"{_fmt(new.get('anees'))} | {_fmt(old.get('elt_pvalue'))} → {_fmt(new.get('elt_pvalue'))} | {why} |"
        )
    return "\n".join(lines) + "\n"


def fail_on_markdown(records: list[dict], failing: list[dict], verdict: str) -> str:
    bad = {id(r) for r in failing}
    lines = [
        "## credcli diagnose",
        "",
        f"**{verdict}**",
        "",
        "| log | segment | N | label | ELT p | NCI [dB] | ANEES | result |",
        "|---|---|---:|---|---:|---:|---:|---|",
    ]
    for r in records:
        lines.append(
            f"| {os.path.basename(r['log'])} | {r['segment']} | {r['n']} | {r['label']} | "
            f"{_fmt(r['elt_pvalue'])} | {_fmt(r['nci'])} | {_fmt(r['anees'])} | "
            f"{'❌ fail' if id(r) in bad else '✅ pass'} |"
        )
    return "\n".join(lines) + "\n"
