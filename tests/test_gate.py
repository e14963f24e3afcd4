"""CI gate: --fail-on, baselines, regressions, JUnit and Markdown reports (end to end)."""

from __future__ import annotations

import json
import os
import re
import subprocess
import xml.etree.ElementTree as ET

import pytest
from helpers import SAMPLE, run

from credcli.ci import gate
from credcli.engine.diagnosis import Label
from credcli.errors import CredcliError
from credcli.report import records

GOOD = SAMPLE / "estimator_log.csv"
REGRESSED = SAMPLE / "estimator_log_regressed.csv"


def _cli(*args):
    """The command line (in this process): its exit code, stdout and stderr."""
    return subprocess.CompletedProcess(args, *run(*args))


@pytest.fixture(autouse=True)
def no_step_summary(monkeypatch):
    """No GitHub step summary unless a test sets one (a CI runner sets it for its job)."""
    monkeypatch.delenv("GITHUB_STEP_SUMMARY", raising=False)


@pytest.fixture(scope="module")
def baseline(tmp_path_factory):
    """A baseline of the good sample log, recorded once for the tests that gate on it."""
    path = tmp_path_factory.mktemp("baseline") / "baseline.json"
    proc = _cli("baseline", GOOD, "-o", path)
    assert proc.returncode == 0, proc.stderr
    return path


def test_fail_on_parsing_and_matching():
    any_of = gate.parse_fail_on("optimism,smm")
    assert any_of == gate.FailOn(conditions=frozenset({"optimism", "smm"}))
    # smm, the paper's condition, covers both location findings
    assert {lab for lab in Label if gate.fails(lab, any_of)} == {
        lab for lab in Label if lab.conditions & {"optimism"} or lab.location is not None
    }
    combined = gate.parse_fail_on("pessimism+bias")  # that label only
    assert [lab for lab in Label if gate.fails(lab, combined)] == [Label.PESSIMISM_BIAS]
    assert str(combined) == "pessimism+bias" and str(any_of) == "optimism,smm"
    paper = gate.parse_fail_on("pessimism+smm")  # every label whose paper label it is
    assert {lab for lab in Label if gate.fails(lab, paper)} == {
        Label.PESSIMISM_SMM,
        Label.PESSIMISM_BIAS,
        Label.PESSIMISM_ASYMMETRIC,
    }
    both = gate.parse_fail_on("opt+smm, pessimism")
    assert {lab for lab in Label if gate.fails(lab, both)} == {
        Label.PESSIMISM,
        Label.OPTIMISM_SMM,
        Label.OPTIMISM_BIAS,
        Label.OPTIMISM_ASYMMETRIC,
    } | {lab for lab in Label if "pessimism" in lab.conditions}
    asym = gate.parse_fail_on("asymmetric")
    assert {lab for lab in Label if gate.fails(lab, asym)} == {
        Label.ASYMMETRIC,
        Label.OPTIMISM_ASYMMETRIC,
        Label.PESSIMISM_ASYMMETRIC,
    }
    nc = gate.parse_fail_on("noncredible")
    assert all(gate.fails(lab, nc) for lab in Label if lab is not Label.CREDIBLE)
    assert not gate.fails(Label.CREDIBLE, nc)
    smm = gate.parse_fail_on("smm")
    assert gate.fails(Label.OPTIMISM_SMM, smm) and not gate.fails(Label.OPTIMISM, smm)
    assert not gate.fails(Label.INSUFFICIENT, smm)
    assert gate.fails(Label.INSUFFICIENT, gate.parse_fail_on("insufficient-data"))
    for bad in ("credible", "biased", ""):
        with pytest.raises(CredcliError, match="fail_on"):
            gate.parse_fail_on(bad)


def _rec(label, nci=0.1, anees=1.0, p=0.5):
    return records.Snapshot.from_record(
        {"segment": "s", "label": label, "nci": nci, "anees": anees, "elt_pvalue": p}
    )


@pytest.mark.parametrize(
    "old, new, regressed, reason",
    [
        (_rec("credible"), _rec("optimism"), True, "label credible -> optimism"),
        (_rec("optimism"), _rec("optimism+smm", p=0.5), True, "gained smm"),
        (_rec("optimism"), _rec("optimism"), False, None),
        (_rec("smm"), _rec("bias"), False, None),  # the same finding, named more precisely
        (_rec("bias"), _rec("pessimism+asymmetric"), True, "gained pessimism"),
        (_rec("credible"), _rec("asymmetric"), True, "label credible -> asymmetric"),
        (_rec("smm", nci=1.0), _rec("smm", nci=2.1), True, "|NCI| 1.00 -> 2.10 dB"),
        (_rec("smm", nci=1.0), _rec("smm", nci=-1.9), False, None),  # |NCI| +0.9 <= 1
        (
            _rec("pessimism", anees=0.5),
            _rec("pessimism", anees=0.39),
            True,
            "further from 1 by x1.28",
        ),
        (_rec("pessimism", anees=0.5), _rec("pessimism", anees=0.41), False, None),
        (_rec("optimism", anees=2.0), _rec("optimism", anees=2.6), True, "x1.30"),
        # an ANEES of exactly 0 (every error 0) is a value, infinitely far from 1
        (_rec("pessimism", anees=0.5), _rec("pessimism", anees=0.0), True, "ANEES 0.5 -> 0"),
        (_rec("pessimism", anees=0.0), _rec("pessimism", anees=0.0), False, None),
        (_rec("credible", p=0.2), _rec("credible", p=0.01), True, "ELT newly rejects"),
        (_rec("optimism+smm"), _rec("optimism"), False, None),  # lost a condition: improved
    ],
)
def test_regression_rules(old, new, regressed, reason):
    c = gate.compare_segment("s", old, new, 0.05, gate.Thresholds())
    assert c.failed is regressed
    if reason:
        assert any(reason in r for r in c.reasons)


def test_improvements_are_reported():
    c = gate.compare_segment(
        "s",
        _rec("optimism+smm", nci=5, anees=3, p=0.001),
        _rec("credible", nci=0.2, anees=1.1, p=0.4),
        0.05,
        gate.Thresholds(),
    )
    assert c.status is gate.Status.IMPROVED
    assert len(c.improvements) == 4


def test_good_log_passes_and_regressed_log_fails_end_to_end(tmp_path, baseline, monkeypatch):
    base = baseline
    doc = json.loads(base.read_text())
    assert (
        doc["schema_version"] == records.BASELINE_SCHEMA_VERSION
        and doc["kind"] == records.BASELINE_KIND
    )
    assert doc["parameters"]["seed"] == 0 and len(doc["segments"]) == 6

    junit, summary, step = tmp_path / "ok.xml", tmp_path / "ok.md", tmp_path / "step.md"
    monkeypatch.setenv("GITHUB_STEP_SUMMARY", str(step))
    proc = _cli(
        "gate",
        GOOD,
        "--baseline",
        base,
        "--junit",
        junit,
        "--summary",
        summary,
    )
    assert proc.returncode == 0, proc.stderr
    assert (
        proc.stderr.strip()
        .splitlines()[-1]
        .startswith("credcli: PASS: no regression in 6 segment(s)")
    )
    assert "\x1b[" not in proc.stdout  # no colour codes when not a terminal
    suite = ET.parse(junit).getroot()
    assert suite.get("tests") == "6" and suite.get("failures") == "0"

    junit, summary = tmp_path / "bad.xml", tmp_path / "bad.md"
    proc = _cli(
        "gate",
        REGRESSED,
        "--baseline",
        base,
        "--junit",
        junit,
        "--summary",
        summary,
    )
    assert proc.returncode == 1
    verdict = proc.stderr.strip().splitlines()[-1]
    assert verdict.startswith("credcli: FAIL: 2 of 6 segment(s) regressed")
    cases = {tc.get("name"): tc for tc in ET.parse(junit).getroot().iter("testcase")}
    assert len(cases) == 6
    # named by the command, then the log, as diagnose's are (was credcli.ci.gate.<stem>)
    assert {tc.get("classname") for tc in cases.values()} == {
        f"credcli.gate.{os.path.splitext(os.path.basename(REGRESSED))[0]}"
    }
    failed = {
        name: tc.find("failure").get("message")
        for name, tc in cases.items()
        if tc.find("failure") is not None
    }
    assert set(failed) == {"cruise", "hover"}
    assert "label credible -> optimism" in failed["cruise"]
    assert "gained bias" in failed["hover"] and "ELT newly rejects" in failed["hover"]
    md = summary.read_text()
    assert "**FAIL: 2 of 6 segment(s) regressed" in md
    assert "| cruise | regressed | credible → optimism | 0.141 → 4.12 |" in md
    assert "| turn | unchanged | optimism → optimism |" in md
    literal = re.sub(r"\\(.)", r"\1", md)  # Markdown's escapes undone
    # 0.953: the sequential p-value; 0.0127: the ELT's share of α_L (the mean test has the rest)
    assert "ELT newly rejects (p 0.953 -> <0.001 < 0.0127)" in literal
    # the step summary got both runs appended
    step_text = step.read_text()
    assert step_text.count("## credcli gate:") == 2 and "PASS" in step_text and "FAIL" in step_text


def test_gate_json_output(baseline):
    proc = _cli("gate", REGRESSED, "--baseline", baseline, "-f", "json")
    doc = json.loads(proc.stdout)
    assert doc["passed"] is False
    status = {s["segment"]: s["status"] for s in doc["segments"]}
    assert status == {
        "cruise": "regressed",
        "turn": "unchanged",
        "hover": "regressed",
        "gps-multipath": "unchanged",
        "tunnel": "unchanged",
        "urban": "unchanged",
    }


def test_missing_and_new_segments(tmp_path, baseline):
    base = baseline
    fewer = tmp_path / "fewer.csv"
    lines = GOOD.read_text().splitlines(keepends=True)
    fewer.write_text("".join(line for line in lines if ",urban," not in line))
    proc = _cli("gate", fewer, "--baseline", base)
    assert proc.returncode == 1 and "missing" in proc.stdout
    proc = _cli("gate", fewer, "--baseline", base, "--allow-new-segments")
    assert proc.returncode == 0 and "1 missing" in proc.stderr


def test_different_parameters_or_schema_are_errors(tmp_path):
    base = tmp_path / "b.json"
    _cli("baseline", GOOD, "-o", base, "--tau", "0.8")
    proc = _cli("gate", GOOD, "--baseline", base, "--tau", "0.5")
    assert (
        proc.returncode == 2
        and "different parameters (tau_nci: baseline 0.8, now 0.5)" in proc.stderr
    )
    proc = _cli("gate", GOOD, "--baseline", base)  # the baseline's tau is used
    assert proc.returncode == 0
    doc = json.loads(base.read_text())
    doc["schema_version"] = 99
    base.write_text(json.dumps(doc))
    proc = _cli("gate", GOOD, "--baseline", base)
    assert proc.returncode == 2 and "schema version 99 is not supported" in proc.stderr
    base.write_text("{not json")
    assert _cli("gate", GOOD, "--baseline", base).returncode == 2
    plain = tmp_path / "plain.json"
    plain.write_text(_cli("diagnose", GOOD, "-f", "json").stdout)
    proc = _cli("gate", GOOD, "--baseline", plain)
    assert proc.returncode == 2 and "not a credcli baseline" in proc.stderr


def test_diagnose_fail_on(tmp_path):
    proc = _cli("diagnose", GOOD, "--fail-on", "optimism,smm")
    assert proc.returncode == 1
    assert proc.stderr.strip().endswith(
        "gps-multipath (bias), tunnel (pessimism+bias), urban (optimism+bias)"
    )
    assert "FAIL: 4 of 6 segment(s) match --fail-on optimism,smm" in proc.stderr
    proc = _cli("diagnose", GOOD, "--fail-on", "insufficient-data")
    assert proc.returncode == 0 and "PASS" in proc.stderr
    junit, summary = tmp_path / "j.xml", tmp_path / "s.md"
    proc = _cli(
        "diagnose", GOOD, "--fail-on", "noncredible", "--junit", junit, "--summary", summary
    )
    assert proc.returncode == 1
    md = summary.read_text()
    assert "**FAIL: 5 of 6 segment(s) match --fail-on noncredible" in md
    assert "| cruise | 300 | 2 | credible |" in md
    fails = [
        tc.get("name")
        for tc in ET.parse(junit).getroot().iter("testcase")
        if tc.find("failure") is not None
    ]
    assert fails == ["turn", "hover", "gps-multipath", "tunnel", "urban"]
    assert _cli("diagnose", GOOD, "--fail-on", "bogus").returncode == 2
    assert _cli("diagnose", "missing.csv", "--fail-on", "smm").returncode == 2


def test_a_baseline_of_one_variant_is_not_gated_with_another(tmp_path):
    base = tmp_path / "ks.json"
    assert _cli("baseline", GOOD, "-o", base, "--variant", "ks").returncode == 0
    assert json.loads(base.read_text())["parameters"]["variant"] == "ks"
    proc = _cli("gate", GOOD, "--baseline", base, "--variant", "calibrated")
    assert proc.returncode == 2
    assert "variant: baseline 'ks', now 'calibrated'" in proc.stderr
    assert proc.stderr.count("\n") == 1
    ok = _cli("gate", GOOD, "--baseline", base, "-f", "json")  # the baseline's variant is used
    assert ok.returncode == 0 and json.loads(ok.stdout)["parameters"]["variant"] == "ks"


def test_a_number_the_gate_table_lacks_is_a_dash_not_nan():
    from credcli.report.builders import _pair

    assert _pair(_rec("credible", anees=float("nan")), _rec("credible", anees=1.25), "anees") == (
        "— → 1.25"
    )
    assert _pair(None, _rec("credible", nci=0.5), "nci") == "— → 0.5"


def test_a_gate_that_compares_no_segment_fails(tmp_path, baseline):
    """New and missing segments allowed, but no segment of the log in the baseline: the
    gate compared nothing and cannot say "no regression" (it said PASS)."""
    other = tmp_path / "other.csv"
    lines = GOOD.read_text().splitlines(keepends=True)
    renamed = [lines[0]] + [line.replace(",urban,", ",elsewhere,") for line in lines[1:]]
    other.write_text(
        "".join(line for line in renamed if ",elsewhere," in line or line is renamed[0])
    )
    proc = _cli("gate", other, "--baseline", baseline, "--allow-new-segments")
    assert proc.returncode == 1, proc.stderr
    assert "no segment of the log is in the baseline" in proc.stderr
    assert "nothing was compared" in proc.stderr


def test_a_baseline_without_segments_is_refused(tmp_path, baseline):
    """A baseline holding no segment compares nothing; it was accepted."""
    doc = json.loads(baseline.read_text())
    doc["segments"] = []
    empty = tmp_path / "empty.json"
    empty.write_text(json.dumps(doc))
    proc = _cli("gate", GOOD, "--baseline", empty)
    assert proc.returncode == 2 and "the baseline holds no segments" in proc.stderr
