"""The report of each command, made from its typed results: the tables people read, the
notes (advice, findings, what was dropped) and the JSON document.

A builder reads typed values (SegmentDiagnosis, StudyResult, UwbRun, SegmentComparison)
and writes prose; the records and columns, and every key they have, come from
:mod:`credcli.report.records`; :mod:`credcli.report.render` formats the Report.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator, Mapping

from credcli.engine.config import LOCATION_CONDITIONS, DiagnosisConfig, Label, Variant
from credcli.engine.diagnosis import SegmentDiagnosis
from credcli.engine.montecarlo import MonteCarlo
from credcli.engine.short import SegmentResults, ShortSegments
from credcli.logid import LogId
from credcli.report.advice import LOCATION_MEANING, advice
from credcli.report.formats import format_number, format_pvalue
from credcli.report.records import (
    ANCHOR_COLUMNS,
    BLOCK_RECORDS,
    CURVE_COLUMNS_GAMMA,
    CURVE_COLUMNS_RHO,
    GATE_COLUMNS,
    LOG_COLUMNS,
    LOG_NAME_COLUMN,
    RANGE_COLUMNS,
    SEGMENT_COLUMNS,
    SEGMENT_COLUMNS_ALL,
    UWB_COLUMNS,
    WHITENESS_COLUMN,
    RecordBatch,
    Records,
    StreamedRecords,
    accuracy_columns,
    accuracy_row,
    anchor_record,
    compared_log_row,
    comparison_record,
    confusion_columns,
    confusion_row,
    curve_records,
    curves_document,
    diagnose_document,
    gate_document,
    gate_row,
    log_record,
    monte_carlo_record,
    range_record,
    record_blocks,
    segment_record,
    shown_label,
    simulate_document,
    sweep_columns,
    sweep_document,
    sweep_row,
    uwb_document,
    uwb_segment_record,
)
from credcli.report.render import format_cell
from credcli.report.tables import Report, Table
from credcli.segments import LogSummary
from credcli.studies.simulate import CONFUSION_LABELS
from credcli.studies.uwb import dropped_text


def diagnose_report(
    results: Iterable,
    config: DiagnosisConfig,
    parameters: dict,
    logs: Mapping[LogId, LogSummary],
    show_all: bool,
    monte_carlo: MonteCarlo | None = None,
) -> Report:
    """The `credcli diagnose` report: one row per segment, and the JSON document (with
    the per-epoch ANEES test of Monte Carlo runs, when given).

    Results are matched to their log by id (``SegmentDiagnosis.log``), never by name.
    With segments of more than one log, each row names its log and a second table
    compares the logs (accuracy over all epochs, credible segments).

    The results are read once, in order, and each is dropped once its record and its
    share of the notes are taken: ``results`` may be an iterator over results as they are
    diagnosed, and the report then holds a record a segment, not a result, and every
    :data:`~credcli.report.records.BLOCK_RECORDS` consecutive records as columns
    (:class:`~credcli.report.records.RecordBlock`).

    Parameters
    ----------
    results : SegmentResults, or iterable of SegmentDiagnosis and ShortSegments
        The diagnosed segments, in report order (a run of segments too short for a verdict
        as one :class:`~credcli.engine.short.ShortSegments`, whose items are not made).
    config : DiagnosisConfig
        The rule the results were decided with (the table's caption; the ELT's
        subsample size in the notes).
    parameters : dict
        Its record (and the run's other settings), written as the document's
        ``parameters``.
    logs : Mapping of LogId to LogSummary
        Each log's summary by its id, in order; written here
        (:func:`credcli.report.records.log_record`) as the document's ``logs``.
    show_all : bool
        Show every metric's column (NLL, ES, their SRDs, ...), not only the main ones.
    monte_carlo : MonteCarlo, optional
        The per-epoch ANEES test of Monte Carlo runs
        (:class:`credcli.engine.montecarlo.MonteCarlo`): a note, and the document's
        ``monte_carlo`` (:func:`credcli.report.records.monte_carlo_record`); None: no
        such test.

    Returns
    -------
    Report
        The segment table (with the innovations' whiteness column when any segment has
        that test), the logs' table when there are several logs, the notes (ELT
        subsamples, dropped rows, advice, findings, correlated innovations, the Monte
        Carlo test) and the document (``version``, ``command``, ``parameters``, ``logs``,
        ``segments`` and, when given, ``monte_carlo``).
    """
    notes = _SegmentNotes()
    parts: list = []
    pending: list[dict] = []  # records since the last block (BLOCK_RECORDS in a row make one)
    for part in _parts(results):
        if isinstance(part, ShortSegments):
            parts.extend(pending)
            pending = []
            parts.append(RecordBatch(part))
        else:
            pending.append(segment_record(part))
            if len(pending) == BLOCK_RECORDS:
                parts.extend(record_blocks(pending))
                pending = []
        notes.add(part)
    records = Records((*parts, *pending))
    summaries, logs = logs, {log_id: log_record(summary) for log_id, summary in logs.items()}
    multi = len(notes.logs) > 1
    columns = _segment_columns(show_all, notes.whiteness.column, multi)
    lines = []
    sub = [f"{log.name}: {name}" if multi else name for log, name in notes.subsampled]
    if sub:
        lines.append(
            f"ELT ran on a random subsample of {config.max_elt_epochs} epochs in "
            f"segment(s) {', '.join(sub)} (memory budget; see `max_elt_epochs`)."
        )
    for summary in summaries.values():
        if summary.dropped_rows:
            lines.append(f"{summary.id.name}: dropped {summary.dropped_rows} row(s) with NaN/Inf.")
    lines.extend(notes.advice.lines())
    lines.extend(notes.findings.lines())
    lines.extend(notes.whiteness.lines())
    if monte_carlo is not None:
        lines.append(_monte_carlo_line(monte_carlo))
    table = Table("credcli diagnose", columns, records, caption=_level_caption(config))
    tables = [table, _logs_table(logs, notes)] if multi else [table]
    mc_record = None if monte_carlo is None else monte_carlo_record(monte_carlo)
    document = diagnose_document(parameters, list(logs.values()), records, mc_record)
    return Report(tables, document, lines)


def _segment_columns(show_all: bool, whiteness: bool = False, multi: bool = False) -> tuple:
    """The segment table's columns: every metric's with ``show_all``, the innovations'
    whiteness after the seventh for innovations, the log's name first for several logs:
    all known before any result (:func:`streamed_diagnose_report`)."""
    columns = SEGMENT_COLUMNS_ALL if show_all else SEGMENT_COLUMNS
    if whiteness:
        columns = columns[:7] + (WHITENESS_COLUMN,) + columns[7:]
    return (LOG_NAME_COLUMN,) + columns if multi else columns


def streamed_diagnose_report(
    results: Iterable,
    config: DiagnosisConfig,
    parameters: dict,
    logs: Mapping[LogId, LogSummary],
    show_all: bool,
    innovations: bool = False,
    monte_carlo: MonteCarlo | None = None,
) -> Report:
    """The `credcli diagnose` report as it can be written while its segments are
    diagnosed: the records are made as a writer reads them
    (:class:`~credcli.report.records.StreamedRecords`), so that no more than the record
    being written is held. Written as JSON, and as CSV where it has tables, it is what
    :func:`diagnose_report` makes of the same results, byte for byte. It has no notes
    (neither format has them), and it can be written once. Its tables' columns are known
    before any result (:func:`_segment_columns`: a log of innovations has the whiteness
    column, and every record of it the whiteness keys). With several logs, the logs' table
    counts each log's segments as they pass and makes its rows when the writer reaches it,
    after the last segment.

    Parameters
    ----------
    results : SegmentResults, or iterable of SegmentDiagnosis and ShortSegments
        The diagnosed segments, in report order; read only as the report is written.
    config : DiagnosisConfig
        The rule the results are decided with (the table's caption).
    parameters : dict
        The document's ``parameters``.
    logs : Mapping of LogId to LogSummary
        Each log's summary by its id, in order (the document's ``logs``).
    show_all : bool
        Every metric's column, not only the main ones.
    innovations : bool, default False
        The logs hold innovations.
    monte_carlo : MonteCarlo, optional
        The per-epoch ANEES test of Monte Carlo runs (the document's ``monte_carlo``).

    Returns
    -------
    Report
        The tables, no notes, and the document.
    """
    multi = len(logs) > 1 and monte_carlo is None  # pooled runs are one log's segments
    notes = _SegmentNotes()
    records = StreamedRecords(_noted(_parts(results), notes) if multi else results)
    entries = {log_id: log_record(summary) for log_id, summary in logs.items()}
    mc_record = None if monte_carlo is None else monte_carlo_record(monte_carlo)
    columns = _segment_columns(show_all, innovations, multi)
    tables = [Table("credcli diagnose", columns, records, caption=_level_caption(config))]
    if multi:
        tables.append(_logs_table(entries, notes, counted_later=True))
    document = diagnose_document(parameters, list(entries.values()), records, mc_record)
    return Report(tables, document)


def _noted(parts: Iterable, notes: _SegmentNotes) -> Iterator:
    """``parts`` as they come, each one's share of the notes taken on the way."""
    for part in parts:
        notes.add(part)
        yield part


def _monte_carlo_line(mc: MonteCarlo) -> str:
    """The note of the per-epoch ANEES test: the share of epochs inside the bounds, overall
    and per segment."""
    confidence = 1.0 - mc.level
    return (
        f"Monte Carlo: {mc.runs} runs; the per-epoch ANEES is inside its "
        f"{100 * confidence:g}% χ²_{mc.runs * mc.dim} bounds [{format_number(mc.lower)}, "
        f"{format_number(mc.upper)}] at {100 * float(mc.inside.mean()):.1f}% of the epochs "
        f"(expected {100 * confidence:g}%); per segment: "
        + ", ".join(f"{k} {100 * v:.1f}%" for k, v in mc.segments.items())
    )


def _parts(results) -> Iterable:
    """The results as parts: each a SegmentDiagnosis or a run of segments too short for a
    verdict (:class:`credcli.engine.short.ShortSegments`), whose items are not made."""
    return results.parts if isinstance(results, SegmentResults) else results


class _Listed:
    """A note's lines, one per item, at most ``limit`` of them, then how many more there
    were (``... and N more`` :attr:`MORE`); taken an item at a time (:meth:`listed`)."""

    MORE = "item(s)"

    def __init__(self, limit: int = 10):
        self.limit, self.shown, self.count = limit, [], 0

    def listed(self, line: str) -> None:
        if len(self.shown) < self.limit:
            self.shown.append(line)
        self.count += 1

    def lines(self) -> list[str]:
        more = self.count - self.limit
        return [*self.shown, f"... and {more} more {self.MORE}"] if more > 0 else list(self.shown)


class _Advice(_Listed):
    """The advice of each segment that has one (:func:`credcli.report.advice.advice`), at
    most ``limit``, then what each location condition found means; taken a part at a
    time (:meth:`add`). A run of short segments gives each its reason without making its
    items."""

    MORE = "segment(s); see the JSON output"

    def __init__(self, limit: int = 10):
        super().__init__(limit)
        self.found: set = set()

    def add(self, part) -> None:
        if isinstance(part, ShortSegments):
            self.found.add(Label.INSUFFICIENT.location)
            shown = min(len(part), max(0, self.limit - len(self.shown)))
            for k in range(shown):
                self.listed(f"{part.names[k]}: no verdict: {part.reason(int(part.n[k]))}")
            self.count += len(part) - shown
            return
        self.found.add(part.diagnosis.label.location)
        line = advice(part)
        if line:
            self.listed(line)

    def lines(self) -> list[str]:
        meanings = [LOCATION_MEANING[c] for c in LOCATION_CONDITIONS if c in self.found]
        return super().lines() + meanings


class _Findings(_Listed):
    """The findings the engine reports beside the labels (a slowly varying error, ...),
    at most ``limit`` lines."""

    MORE = "finding(s); see the JSON output"

    def add(self, result: SegmentDiagnosis) -> None:
        for f in result.diagnosis.findings:
            self.listed(f"{result.segment}: {f}")


class _Whiteness(_Listed):
    """Segments whose innovations are not white at the whiteness test's share of α (the
    engine's decision, ``Whiteness.rejected``), at most ``limit`` lines; and whether any
    segment is of innovations or has the test (the table's column)."""

    MORE = "segment(s) with correlated innovations"

    def __init__(self, limit: int = 10):
        super().__init__(limit)
        self.column = False

    def add(self, result: SegmentDiagnosis) -> None:
        white = result.whiteness
        self.column = self.column or result.innovations or white is not None
        if white is not None and white.rejected:
            self.listed(
                f"{result.segment}: innovations correlated in time (portmanteau p = "
                f"{format_cell(white.pvalue, 3)}, {white.lags} lags, level "
                f"{format_cell(white.level, 3)}): the filter's "
                "model or noise is inconsistent even if the NIS level is right"
            )


class _SegmentNotes:
    """What the `diagnose` report says beside the records, taken a part at a time
    (:meth:`add`): the advice, findings and whiteness notes, the segments whose ELT ran on
    a subsample, and each log's segments and credible ones."""

    def __init__(self):
        self.advice, self.findings, self.whiteness = _Advice(), _Findings(), _Whiteness()
        self.subsampled: list[tuple[LogId, str]] = []
        self.logs: dict[LogId, list[int]] = {}  # [credible, segments] by log

    def add(self, part) -> None:
        counts = self.logs.setdefault(part.log, [0, 0])
        self.advice.add(part)
        if isinstance(part, ShortSegments):  # insufficient-data, every one
            counts[1] += len(part)
            return
        diag = part.diagnosis
        counts[0] += shown_label(diag.label, diag.untested) == Label.CREDIBLE.value
        counts[1] += 1
        if diag.elt and diag.elt.subsampled:
            self.subsampled.append((part.log, part.segment))
        self.findings.add(part)
        self.whiteness.add(part)


def _logs_table(
    logs: Mapping[LogId, dict], notes: _SegmentNotes, counted_later: bool = False
) -> Table:
    """The table comparing several logs: each one's accuracy over all its epochs and its
    credible segments of all, from ``notes``; with ``counted_later``, the rows are made
    when the table is read (after the segments whose passing counts them), once."""

    def rows() -> Iterator[dict]:
        for log_id, entry in logs.items():
            credible, segments = notes.logs.get(log_id, [0, 0])
            yield compared_log_row(entry, f"{credible} of {segments}")

    caption = "accuracy over all epochs of each log"
    # a generator's body runs at its first reading: after the segments, when counted later
    return Table(
        "logs compared", LOG_COLUMNS, rows() if counted_later else list(rows()), caption=caption
    )


def _advice_lines(results) -> list[str]:
    """The advice notes of ``results`` (:class:`_Advice`)."""
    fold = _Advice()
    for part in _parts(results):
        fold.add(part)
    return fold.lines()


def _level_caption(config: DiagnosisConfig) -> str:
    if config.variant is not Variant.CALIBRATED:
        return f"variant {config.variant.value}: ELT at α = {config.alpha:g}"
    return (
        f"calibrated rule: false-alarm level {config.alpha:g} per segment "
        "(ELT and scale test at 1 − √(1 − α) each); cov ×: factor for the claimed covariance"
    )


PAPER_TABLE_II = {
    Label.CREDIBLE.value: 0.94,
    Label.OPTIMISM.value: 0.84,
    Label.PESSIMISM.value: 0.90,
    Label.SMM.value: 0.80,
    Label.OPTIMISM_SMM.value: 0.82,
    Label.PESSIMISM_SMM.value: 1.00,
}
"""Accuracy of the proposed method in the paper's Table II."""


def _pct(x):
    return None if x is None else round(100.0 * x, 1)


def simulate_report(study, parameters: dict, paper_protocol: bool) -> Report:
    """Table II (accuracy per scenario and method) and Table III (confusion matrix).

    Parameters
    ----------
    study : StudyResult
        The study (:func:`credcli.studies.simulate.run_study`): accuracy per method and
        scenario, and the confusion matrix of one variant.
    parameters : dict
        The study's settings, written as the document's ``parameters``.
    paper_protocol : bool
        Whether the study ran the paper's protocol: then Table II also shows the paper's
        published accuracy (``PAPER_TABLE_II``) beside each scenario.

    Returns
    -------
    Report
        Table II with accuracies in percent (1 decimal), Table III with counts, and the
        document with the accuracies as fractions (``accuracy``), ``confusion_variant``
        and ``confusion``.
    """
    rows = [
        accuracy_row(
            s.value,
            {method.value: _pct(acc[s]) for method, acc in study.accuracy.items()},
            _pct(PAPER_TABLE_II[s.value]) if paper_protocol else None,
        )
        for s in study.scenarios
    ]
    table2 = Table(
        "Table II: diagnosis accuracy",
        accuracy_columns(study.accuracy, paper_protocol),
        rows,
        caption=f"{study.trials} trials per scenario; ks = the authors' code, paper rule = "
        "Algorithm 1 as printed"
        + ("; published = the paper's Table II (proposed method)" if paper_protocol else ""),
    )
    conf_rows = [
        confusion_row(t.value, {lab.value: study.confusion[t][lab] for lab in CONFUSION_LABELS})
        for t in study.scenarios
    ]
    table3 = Table(
        f"Table III: confusion matrix of the {study.variant.value} variant",
        confusion_columns(CONFUSION_LABELS),
        conf_rows,
    )
    return Report([table2, table3], simulate_document(parameters, study, CONFUSION_LABELS))


def sweep_report(sweep, points, parameters: dict) -> Report:
    """The accuracy of every method against one swept parameter (``simulate --sweep``).

    Parameters
    ----------
    sweep : Sweep
        The parameter swept and its values (:class:`credcli.studies.simulate.Sweep`).
    points : list of SweepPoint
        The accuracy of every method at each value, per true label
        (:func:`credcli.studies.simulate.run_sweep`).
    parameters : dict
        The study's settings, written as the document's ``parameters``.

    Returns
    -------
    Report
        One table, a row per point with the accuracies in percent (1 decimal), and the
        document whose ``sweep`` holds the parameter, its values and each point's
        accuracies as fractions.
    """
    rows = [sweep_row(p, {m.value: _pct(a) for m, a in p.accuracy.items()}) for p in points]
    cols = sweep_columns(sweep.parameter.value, points[0].accuracy if points else ())
    document = sweep_document(parameters, sweep, points)
    return Report([Table(f"Accuracy against {sweep.parameter.value}", cols, rows)], document)


def curves_report(by_rho, by_gamma, runs: int, parameters: dict) -> Report:
    """The Fig. 1 curves (``runs`` Monte Carlo runs a point) against their exact values.

    Parameters
    ----------
    by_rho : list of CurvePoint
        Fig. 1a: the scores against the covariance scale ρ, at γ = 0.
    by_gamma : list of CurvePoint
        Fig. 1b: the scores against the bias γ, at ρ = 1.
    runs : int
        Monte Carlo runs per point (for the captions).
    parameters : dict
        The study's settings, written as the document's ``parameters``.

    Returns
    -------
    Report
        Two tables (Fig. 1a and 1b: the sample means of ES and NLL beside their exact
        expectations) and the document whose ``curves`` holds both lists of points.
    """
    tables = [
        Table(
            "Fig. 1a: scores against the covariance scale ρ (γ = 0)",
            CURVE_COLUMNS_RHO,
            curve_records(by_rho),
            caption=f"sample means over {runs} runs; exact expectations",
        ),
        Table(
            "Fig. 1b: scores against the bias γ (μ = γ·1, ρ = 1)",
            CURVE_COLUMNS_GAMMA,
            curve_records(by_gamma),
            caption=f"sample means over {runs} runs; exact expectations",
        ),
    ]
    return Report(tables, curves_document(parameters, by_rho, by_gamma))


def _screening_note(run, settings) -> str:
    """One line: packets, fixes, and every packet dropped with its reason."""
    f = run.fixes
    scale = (
        f", residual scale {f.residual_scale:.3g} of the claimed variance"
        if f.residual_scale is not None
        else ""
    )
    screen = (
        f"screening on (stale packets; residual test at {settings.residual_level:g}{scale})"
        if settings.screen
        else "screening off (`screen` none)"
    )
    moved = f"; {f.moved} fix(es) moved to the global minimum" if f.moved else ""
    return (
        f"{run.packets} packets of >= {settings.min_anchors} anchors within "
        f"{settings.packet_window:g} s; {f.time.size} fixes; dropped: {dropped_text(f)}"
        f"{moved}; {screen}; solve: {settings.robust.value}; {run.log.n} fixes in "
        f"{len(run.segments)} period(s)."
    )


def uwb_report(run, results, checks, parameters: dict) -> Report:
    """Table IV per period with the range-level verdict beside it, the range-level table
    per period and anchor (Figs. 4 and 5), and the anchors.

    Parameters
    ----------
    run : UwbRun
        Everything the `uwb` pipeline computed: anchors, fixes, periods, range statistics
        and its settings (:class:`credcli.studies.uwb.UwbRun`).
    results : list of SegmentDiagnosis
        The diagnosis of each period, in order.
    checks : list of RangeCheck
        The range-level verdict of each result, one per result, in the same order
        (:func:`credcli.studies.uwb.range_checks`).
    parameters : dict
        The diagnosis and pipeline settings, written as the document's ``parameters``.

    Returns
    -------
    Report
        The anchors' table, the range errors per period and anchor, Table IV; the notes
        (the reader's and pipeline's warnings, the advice, whether each position-level
        label agrees with the range-level evidence, and the screening line); and the
        document (``segments``, ``anchors``, ``ranges``, ``screening`` and ``notes``).

    Raises
    ------
    ValueError
        If ``checks`` and ``results`` differ in length.
    """
    segments = [uwb_segment_record(r, c) for r, c in zip(results, checks, strict=True)]
    agreement = [
        f"{r.segment}: the position-level label "
        f"{shown_label(r.diagnosis.label, r.diagnosis.untested)} "
        f"{'agrees with' if check.agrees else 'DISAGREES with'} the range-level evidence, "
        f"{check.label} ({check.why})"
        for r, check in zip(results, checks)
        if check.agrees is not None
    ]
    ranges = [range_record(s) for s in run.range_stats]
    warn = run.settings.anchor_rms_warn
    anchors = [anchor_record(a, a.disagrees(warn)) for a in run.anchors]
    notes = list(run.ranges.notes) + list(run.notes) + _advice_lines(results) + agreement
    notes.append(_screening_note(run, run.settings))
    tables = [
        Table(
            "Anchors", ANCHOR_COLUMNS, anchors, caption=f"check: gt_range RMS <= {1000 * warn:g} mm"
        ),
        Table(
            "Range errors per period and anchor (Figs. 4 and 5)",
            RANGE_COLUMNS,
            ranges,
            caption=f"range column: {run.ranges.range_column}; error = range − gt_range, "
            "after screening; robust std = 1.4826 MAD; beyond 3σ: |error − bias| > 3 reported std",
        ),
        Table("Table IV: diagnosis per period", UWB_COLUMNS, segments),
    ]
    document = uwb_document(parameters, segments, anchors, ranges, run, notes)
    return Report(tables, document, notes)


def _pair(old, new, key: str) -> str:
    """``"baseline → now"`` of one of the Snapshots' numbers (``key``: its field)."""

    def f(snap):
        v = None if snap is None else getattr(snap, key)
        if key.endswith("pvalue"):
            return format_pvalue(v)
        return "—" if v is None or v != v else f"{v:.3g}"  # NaN (v != v) is no number

    return f"{f(old)} → {f(new)}"


def _label(snap) -> str | None:
    return None if snap is None else snap.label.value


def gate_report(comparisons, parameters: dict, baseline: str, passed: bool, verdict: str) -> Report:
    """The `credcli gate` report: each segment of the baseline against the same segment now.

    Parameters
    ----------
    comparisons : list of SegmentComparison
        Every segment compared (:func:`credcli.ci.gate.compare`).
    parameters : dict
        The new diagnosis's settings, written as the document's ``parameters``.
    baseline : str
        The baseline file's path, as given.
    passed : bool
        Whether no segment fails the gate.
    verdict : str
        The verdict line (:func:`credcli.ci.gate.verdict_line`).

    Returns
    -------
    Report
        One table, a row per segment: its status, its label, NCI, ANEES and ELT p-value
        as "baseline → now", and why it changed; and the document (``baseline``,
        ``parameters``, ``passed``, ``verdict`` and a record per segment).
    """
    rows = [
        gate_row(
            segment=c.segment,
            status=c.status.value,
            labels=f"{_label(c.old) or '—'} → {_label(c.new) or '—'}",
            nci=_pair(c.old, c.new, "nci"),
            anees=_pair(c.old, c.new, "anees"),
            elt=_pair(c.old, c.new, "elt_pvalue"),
            why="; ".join(c.reasons + c.improvements) or "—",
        )
        for c in comparisons
    ]
    records = [comparison_record(c) for c in comparisons]
    document = gate_document(baseline, parameters, passed, verdict, records)
    return Report([Table("credcli gate", GATE_COLUMNS, rows)], document)
