"""Segments too short for a verdict are diagnosed, reported and written as columns
(issue 32 item 7, issue 35 item 3): every output is what the per-segment path writes, byte
for byte, and no object is held per segment."""

from __future__ import annotations

import csv
import gc
import io
import json
import xml.etree.ElementTree as ET

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from credcli.ci.gate import fail_on_verdict, parse_fail_on
from credcli.ci.reports import Case, CaseBatch, fail_on_cases, junit_xml, xml_text
from credcli.engine.config import DiagnosisConfig, Label
from credcli.engine.diagnosis import Diagnosis, SegmentDiagnosis
from credcli.engine.metrics import Accuracy
from credcli.engine.short import SegmentResults, ShortSegments
from credcli.io.arrays import log_from_arrays
from credcli.report import jsontext, render
from credcli.report.builders import diagnose_report
from credcli.report.records import Records, segment_record, segment_records
from credcli.report.render import OutputFormat, text_pieces, to_text
from credcli.schedule.plans import diagnose_plans
from credcli.segments import Segment, Segments, by_column, lengths, log_summary, split

NAMES = [
    "a,b",
    '"q"',
    "<x&y>",
    "=cmd",
    "-1",
    "tab\tname",
    "é-ü",
    "\ue000pua",
    "new\nline",
    "%s%d",
    "",
    "ctl\x01x",
]


def _mixed_log(timed: bool = True, huge: bool = False):
    """Long segments between runs of short ones (one to three epochs, odd names), and a
    run that ends the log; ``huge``: two short segments whose error squares overflow (their
    RMSE is inf, null in the records)."""
    names = []
    for k, name in enumerate(NAMES):
        names += [name] * (1 + k % 3)
        if k % 4 == 3:
            names += [f"long{k}"] * 40
    names += [f"tail{k}" for k in range(5)]
    n = len(names)
    rng = np.random.default_rng(11)
    e = rng.standard_normal((n, 2)) * 1.3
    cov = np.broadcast_to(np.eye(2), (n, 2, 2)).copy()
    if huge:
        e[0, 0] = e[1, 1] = 1e160
        cov[:2] *= 1e300
    time = np.arange(n) * 0.1 if timed else None
    return log_from_arrays(errors=e, cov=cov, time=time, segment=np.array(names, dtype=object))


def _report(results, log, plan, config):
    return diagnose_report(results, config, {"seed": 3}, {log.id: log_summary(log, plan)}, False)


@pytest.mark.parametrize("timed, huge", [(True, False), (False, True)])
def test_a_run_of_short_segments_is_written_as_its_items_are(timed, huge):
    """The batched results give every output (JSON, CSV, table, Markdown, --fail-on's JUnit
    and verdict) byte for byte as the same results one by one do, the per-record path."""
    log = _mixed_log(timed, huge)
    plan = split(log)
    config = DiagnosisConfig()
    results = diagnose_plans([(log, plan)], config, seed=3)
    assert isinstance(results, SegmentResults)
    assert sum(isinstance(p, ShortSegments) for p in results.parts) == 4  # the runs
    items = list(results)  # the per-segment path: one SegmentDiagnosis each
    assert [r.segment for r in items] == [s.name for s in plan]
    records = segment_records(results)
    assert list(records) == [segment_record(r) for r in items]
    batched, single = _report(results, log, plan, config), _report(items, log, plan, config)
    for fmt in OutputFormat:
        assert "".join(text_pieces(batched, fmt)) == "".join(text_pieces(single, fmt))
        assert to_text(batched, fmt) == to_text(single, fmt)
    for text in ("insufficient-data", "noncredible", "optimism"):
        fail_on = parse_fail_on(text)
        verdict = fail_on_verdict(results, fail_on)
        assert verdict == fail_on_verdict(items, fail_on)
        cases = fail_on_cases(results, verdict[2], fail_on)
        expanded = fail_on_cases(items, verdict[2], fail_on)
        assert any(isinstance(c, CaseBatch) for c in cases)
        assert junit_xml("credcli", cases) == _reference_junit("credcli", expanded)


def test_the_short_segments_items_are_what_their_records_say():
    """Item k of a batch, of the results and of the records: the same segment, for any
    index and slice."""
    log = _mixed_log()
    results = diagnose_plans([(log, split(log))], DiagnosisConfig(), seed=3)
    items, records = list(results), segment_records(results)
    assert isinstance(records, Records) and len(records) == len(items) == len(results)
    for k in (0, 1, 5, len(items) - 1, -1, -len(items)):
        assert segment_record(results[k]) == records[k] == segment_record(items[k])
    assert list(map(segment_record, results[3:9])) == list(map(segment_record, items[3:9]))
    assert records[-4:] == [segment_record(r) for r in items[-4:]]
    with pytest.raises(IndexError):
        results[len(items)]
    assert list(results.verdicts()) == [(r.diagnosis.label, r.diagnosis.untested) for r in items]
    assert list(records) == [segment_record(r) for r in items]


def test_segments_of_a_column_are_their_items():
    values = np.array(["b", "a", "a", "c", "b", "d"], dtype=object)
    time = np.arange(6) * 0.5
    segments = by_column(values, time)
    assert isinstance(segments, Segments) and len(segments) == 4
    assert [s.name for s in segments] == ["b", "a", "c", "d"]
    assert segments[-4].name == "b" and [s.name for s in segments[1:3]] == ["a", "c"]
    np.testing.assert_array_equal(segments[0].index, [0, 4])
    assert (segments[0].t_start, segments[0].t_end) == (0.0, 2.0)
    assert lengths(segments).tolist() == [2, 2, 1, 1] == [len(s.index) for s in segments]
    assert lengths(list(segments)).tolist() == [2, 2, 1, 1]
    assert isinstance(segments[3], Segment) and not segments[3].window
    assert len(by_column(values[:0])) == 0


def test_short_segments_hold_no_object_per_segment():
    """2 × 10⁴ one-epoch segments, diagnosed, reported and written as JSON and CSV: no
    Segment, Diagnosis, SegmentDiagnosis, Accuracy or record dict per segment is held, and
    the outputs come in pieces of a bounded size, not one string."""
    n = 20_000
    names = np.array([f"s{k}" for k in range(n)], dtype=object)
    e = np.random.default_rng(0).standard_normal((n, 2))
    log = log_from_arrays(errors=e, cov=np.eye(2), time=np.arange(n) * 0.1, segment=names)
    plan = split(log)
    config = DiagnosisConfig()
    results = diagnose_plans([(log, plan)], config, seed=0)
    report = _report(results, log, plan, config)
    per_segment = (Segment, Diagnosis, SegmentDiagnosis, Accuracy)
    for fmt in (OutputFormat.JSON, OutputFormat.CSV):
        pieces = text_pieces(report, fmt)
        sizes = [len(next(pieces)), len(next(pieces))]
        gc.collect()
        held = [o for o in gc.get_objects() if isinstance(o, per_segment)]
        dicts = sum(isinstance(o, dict) and "label_answered" in o for o in gc.get_objects())
        assert len(held) < 10 and dicts < 10, (len(held), dicts)
        sizes += [len(p) for p in pieces]
        assert len(sizes) > 3 and max(sizes) < render.BATCH_ROWS * 3_000
    assert len(results.parts) == 1 and len(report.document["segments"].parts) == 1


_SCALAR = (
    st.none()
    | st.booleans()
    | st.integers(-(10**20), 10**20)
    | st.floats(allow_nan=False, allow_infinity=False)
    | st.text(alphabet=st.characters(codec="utf-8"), max_size=6)
)
_KINDS = {  # columns as a batch holds them: one type each, or anything
    "floats": st.floats(allow_nan=False, allow_infinity=False),
    "texts": st.text(max_size=6),
    "ints": st.integers(-(10**6), 10**6),
    "nulls": st.none(),
    "pairs": st.lists(st.floats(allow_nan=False, allow_infinity=False), min_size=2, max_size=2),
    "mixed": _SCALAR | st.lists(_SCALAR, max_size=3),
}


@st.composite
def _rows(draw):
    shared = draw(st.dictionaries(st.text(max_size=5), _SCALAR, min_size=1, max_size=6))
    count = draw(st.integers(0, 5))
    columns = {}
    for key in draw(st.sets(st.sampled_from(sorted(shared)))):
        kind = draw(st.sampled_from(sorted(_KINDS)))
        values = draw(st.lists(_KINDS[kind], min_size=count, max_size=count))
        if kind == "pairs" and draw(st.booleans()):
            values = jsontext.ListColumn([[v[0] for v in values], [v[1] for v in values]])
        columns[key] = values
    return shared, columns, count


@settings(max_examples=300, deadline=None)
@given(rows=_rows(), level=st.integers(0, 3))
def test_rows_from_one_template_are_each_rows_text(rows, level):
    """encode_rows writes each row as encode does (the standard library's bytes), and the
    CSV lines of a batch are the CSV writer's rows of the same cells: keys and texts with
    % signs, quotes, commas, line ends, formula starts; lists by position or whole."""
    shared, columns, count = rows
    each = [shared | {k: v[i] for k, v in columns.items()} for i in range(count)]
    got = jsontext.encode_rows(shared, columns, count, level)
    assert got == [jsontext.encode(row, level) for row in each]
    assert [json.loads(text) for text in got] == [json.loads(json.dumps(row)) for row in each]
    keys = ["extra", *shared]
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\r\n")
    for row in each:
        writer.writerow(["title", *(render._csv_cell(row.get(k)) for k in keys)])
    assert "".join(render._csv_lines(shared, columns, count, keys, ("title",))) == buf.getvalue()


def _reference_junit(suite, cases) -> str:
    """JUnit as one ElementTree of every case (credcli's writer before batches)."""
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
        tc = ET.SubElement(
            node, "testcase", name=xml_text(case.name), classname=xml_text(case.classname)
        )
        if case.failure is not None:
            message = xml_text(case.failure)
            fail = ET.SubElement(tc, "failure", message=message, type="CredibilityRegression")
            fail.text = xml_text(case.details or case.failure)
        elif case.details:
            ET.SubElement(tc, "system-out").text = xml_text(case.details)
    ET.indent(root)
    return '<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(root, encoding="unicode") + "\n"


@pytest.mark.parametrize("classname", ["credcli.diagnose.run", "pua\ue000class"])
def test_junit_of_a_batch_is_the_tree_of_its_cases(classname):
    """A CaseBatch's cases, between single cases, as one ElementTree of every case writes
    them: names escaped (control characters as #xNN, quotes, <, &, tabs, line ends), a
    failure or details or neither; a class name holding the template's placeholder too."""
    batches = [
        CaseBatch(NAMES, classname, "label insufficient-data matches", "label x, <p> & q"),
        CaseBatch(["a", "b"], classname, None, "details"),
        CaseBatch(["c", "d\x1b"], classname, None, ""),
    ]
    singles = [Case("one", classname, None, "d"), Case("two & <", classname, "bad", "")]
    cases = [singles[0], *batches, singles[1]]
    expanded = [c for case in cases for c in (case if isinstance(case, CaseBatch) else [case])]
    assert junit_xml("suite <1>", cases) == _reference_junit("suite <1>", expanded)
    assert junit_xml("empty", []) == _reference_junit("empty", [])
    ET.fromstring(junit_xml("suite", cases).split("\n", 1)[1])  # valid XML


def test_the_labels_of_a_batch_are_insufficient_data():
    log = _mixed_log()
    results = diagnose_plans([(log, split(log))], DiagnosisConfig(), seed=3)
    short = next(p for p in results.parts if isinstance(p, ShortSegments))
    assert {r.diagnosis.label for r in short} == {Label.INSUFFICIENT}
    assert [r.diagnosis.n for r in short] == short.n.tolist()
