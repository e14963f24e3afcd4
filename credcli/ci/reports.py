"""Reports for CI pages: JUnit XML (one test case per segment) and Markdown summaries."""

from __future__ import annotations

import os
import re
import stat
import xml.etree.ElementTree as ET
from dataclasses import dataclass

from credcli.errors import CredcliError
from credcli.report.records import json_value, shown_label
from credcli.report.render import OutputFormat, format_cell, markdown_text, to_text


@dataclass(frozen=True)
class Case:
    """One JUnit test case: a segment, and why it failed (None when it passed).

    Attributes
    ----------
    name : str
        The test case's name: the segment's name.
    classname : str
        The test case's class: the command and the log's stem
        (``credcli.diagnose.<stem>``, ``credcli.ci.gate.<stem>``).
    failure : str or None
        Why it failed, the failure's message; None when it passed.
    details : str, default ""
        More text: the failure's body, or the passing case's ``system-out``.
    """

    name: str
    classname: str
    failure: str | None
    details: str = ""


_NOT_XML = re.compile("[^\t\n\r\x20-\ud7ff\ue000-\ufffd\U00010000-\U0010ffff]")


def xml_text(text: str) -> str:
    r"""``text`` with the characters XML 1.0 forbids written as ``#xNN``.

    Those are most C0 controls, lone surrogates and U+FFFE/U+FFFF; pytest writes them
    the same way, and the document stays valid.

    Parameters
    ----------
    text : str
        A name or message from the data.

    Returns
    -------
    str
        ``text`` with each forbidden character replaced.

    Examples
    --------
    >>> xml_text("run\x07 1\tok")
    'run#x07 1\tok'
    """
    return _NOT_XML.sub(lambda m: f"#x{ord(m.group()):02X}", text)


def junit_xml(suite: str, cases: list[Case]) -> str:
    """A JUnit XML document with one <testsuite>; failures carry their reason.

    Names and messages from the data pass through :func:`xml_text`.

    Parameters
    ----------
    suite : str
        The test suite's name.
    cases : list of Case
        The test cases, one per segment, in order.

    Returns
    -------
    str
        The indented XML document, with its declaration and a final newline.

    Examples
    --------
    >>> cases = [Case("cruise", "credcli.diagnose.log", None), Case("urban", "x", "bias")]
    >>> print(junit_xml("log", cases).splitlines()[1])
    <testsuites name="credcli" tests="2" failures="1">
    """
    failures = sum(c.failure is not None for c in cases)
    root = ET.Element("testsuites", name="credcli", tests=str(len(cases)), failures=str(failures))
    node = ET.SubElement(
        root,
        "testsuite",
        name=xml_text(suite),
        tests=str(len(cases)),
        failures=str(failures),
        errors="0",
        skipped="0",
    )
    for case in cases:
        name, classname = xml_text(case.name), xml_text(case.classname)
        tc = ET.SubElement(node, "testcase", name=name, classname=classname)
        if case.failure is not None:
            message = xml_text(case.failure)
            fail = ET.SubElement(tc, "failure", message=message, type="CredibilityRegression")
            fail.text = xml_text(case.details or case.failure)
        elif case.details:
            ET.SubElement(tc, "system-out").text = xml_text(case.details)
    ET.indent(root)
    return '<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(root, encoding="unicode") + "\n"


def check_step_summary(path: str) -> None:
    """Check that $GITHUB_STEP_SUMMARY is a regular file or a new one (GitHub's always is).

    A FIFO with no reader would block the run forever, a device is not a summary, and a
    symbolic link would send the summary to the file it points to.

    Parameters
    ----------
    path : str
        The value of $GITHUB_STEP_SUMMARY.

    Raises
    ------
    CredcliError
        If ``path`` exists and is a symbolic link or not a regular file, or cannot be
        examined.
    """
    try:
        mode = os.lstat(path).st_mode
    except FileNotFoundError:
        return
    except OSError as exc:
        raise CredcliError(f"GITHUB_STEP_SUMMARY={path}: {exc.strerror}") from exc
    if stat.S_ISLNK(mode):
        raise CredcliError(
            f"GITHUB_STEP_SUMMARY={path}: is a symbolic link; credcli does not write through "
            "links (GitHub's summary file never is one)"
        )
    if not stat.S_ISREG(mode):
        raise CredcliError(
            f"GITHUB_STEP_SUMMARY={path}: not a regular file; the job summary is appended "
            "to a file (unset the variable outside GitHub Actions)"
        )


def append_step_summary(markdown: str) -> None:
    """Append to $GITHUB_STEP_SUMMARY when it is set (GitHub Actions' job summary).

    Nothing happens when the variable is unset or empty.

    Parameters
    ----------
    markdown : str
        The summary; a final newline is added when it has none.

    Raises
    ------
    CredcliError
        If the file is not a regular one (:func:`check_step_summary`) or cannot be
        appended to.
    """
    path = os.environ.get("GITHUB_STEP_SUMMARY")
    if not path:
        return
    check_step_summary(path)
    flags = os.O_WRONLY | os.O_APPEND | os.O_CREAT | getattr(os, "O_NOFOLLOW", 0)
    try:  # never through a link planted at the name after the check
        with os.fdopen(os.open(path, flags, 0o666), "a", encoding="utf-8") as fh:
            fh.write(markdown if markdown.endswith("\n") else markdown + "\n")
    except OSError as exc:
        raise CredcliError(
            f"GITHUB_STEP_SUMMARY={path}: cannot append the summary: {exc.strerror}"
        ) from exc


def gate_cases(comparisons, thresholds, log: str) -> list[Case]:
    """One JUnit case per segment the gate compared.

    Parameters
    ----------
    comparisons : list of SegmentComparison
        The gate's comparisons (``credcli.ci.gate.compare``).
    thresholds : Thresholds
        The gate's thresholds (whether new or missing segments fail).
    log : str
        The log's path or name; its stem names the cases' class
        (``credcli.ci.gate.<stem>``).

    Returns
    -------
    list of Case
        In the order of ``comparisons``; a failing case's message is its reasons, every
        case's details its reasons and improvements.
    """
    cases = []
    for c in comparisons:
        failed = c.failed_with(thresholds)
        details = "; ".join(c.reasons + c.improvements)
        cases.append(
            Case(
                c.segment,
                f"credcli.ci.gate.{_classname(os.path.splitext(os.path.basename(log))[0])}",
                "; ".join(c.reasons) if failed else None,
                details,
            )
        )
    return cases


def fail_on_cases(results, failing: list[int], fail_on) -> list[Case]:
    """One JUnit case per diagnosed segment.

    Parameters
    ----------
    results : sequence of SegmentDiagnosis
        The diagnosed segments (``credcli.engine.diagnosis.SegmentDiagnosis``).
    failing : list of int
        The indices of the failing ones (``credcli.ci.gate.fail_on_verdict``).
    fail_on : FailOn
        The conditions of ``--fail-on``, named in the failure messages.

    Returns
    -------
    list of Case
        In the order of ``results``, classed by their log's stem
        (``credcli.diagnose.<stem>``); the details give the label, ELT p-value, NCI and
        ANEES.
    """
    bad = set(failing)
    listed = str(fail_on)
    cases = []
    for k, result in enumerate(results):
        d = result.diagnosis
        label = shown_label(d.label, d.untested)
        cases.append(
            Case(
                result.segment,
                f"credcli.diagnose.{_classname(result.log.stem)}",
                f"label {label} matches --fail-on {listed}" if k in bad else None,
                f"label {label}, ELT p {_cell(d.elt_pvalue)}, NCI {_cell(d.nci)} dB, "
                f"ANEES {_cell(d.anees)}",
            )
        )
    return cases


def _cell(value) -> str:
    return format_cell(json_value(value), 3)


def _classname(stem: str) -> str:
    """A JUnit class name from a log's stem (unique among the logs of one command)."""
    return "".join(ch if ch.isalnum() or ch in "_-" else "_" for ch in stem) or "log"


def summary_markdown(heading: str, verdict: str, report, context: str = "") -> str:
    """The Markdown summary of a CI run.

    A heading, the verdict in bold, the context if any, then the report's own tables (the
    same ones the other output formats show).

    Parameters
    ----------
    heading : str
        The section's heading (a level-2 Markdown heading).
    verdict : str
        The one-line verdict.
    report : Report
        The command's report, rendered as ``--format markdown`` renders it.
    context : str, default ""
        A line between the verdict and the tables (the baseline and thresholds); none
        when empty.

    Returns
    -------
    str
        The Markdown text; every text from the data is escaped.
    """
    parts = [f"## {markdown_text(heading)}", "", f"**{markdown_text(verdict)}**", ""]
    if context:
        parts += [markdown_text(context), ""]
    parts.append(to_text(report, OutputFormat.MARKDOWN))
    return "\n".join(parts)
