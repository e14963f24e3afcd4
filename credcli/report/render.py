"""Renderers: Rich tables, CSV, JSON and Markdown, from plain records.

A command builds a Report (parameters, tables, and the JSON document); the renderers only
format it. Floats keep full precision in CSV and JSON; tables round them for reading.
"""

from __future__ import annotations

import csv
import io
import math
import operator
import re
from collections.abc import Callable, Iterator, Mapping
from dataclasses import asdict, dataclass, field

from credcli.engine.config import (
    LOCATION_CONDITIONS,
    SMM_CONDITION,
    DiagnosisConfig,
    Label,
    Variant,
)
from credcli.engine.diagnosis import SegmentDiagnosis
from credcli.engine.short import SegmentResults, ShortSegments
from credcli.errors import printable
from credcli.logid import LogId
from credcli.report import jsontext
from credcli.report.formats import (  # noqa: F401 (OutputFormat, PVALUE_FLOOR re-exported)
    PVALUE_FLOOR,
    OutputFormat,
    format_pvalue,
)
from credcli.report.records import (
    RecordBatch,
    Records,
    anchor_record,
    comparison_record,
    log_record,
    range_record,
    segment_records,
    shown_label,
    uwb_segment_record,
)
from credcli.segments import LogSummary
from credcli.studies.simulate import CONFUSION_LABELS
from credcli.studies.uwb import dropped_text
from credcli.version import __version__


@dataclass(frozen=True)
class Column:
    """One column of a :class:`Table`: the record key it shows and how it is shown.

    The record keeps the full value (CSV and JSON write it); a column only decides how
    people read it: rounding, shortening, wrapping, and which columns a narrow terminal
    hides first.

    Attributes
    ----------
    key : str
        The record's key whose value the column shows (and the CSV header).
    header : str
        The column's heading in tables.
    digits : int, default 4
        Significant digits of a float in tables (:func:`format_cell`); 0 for text and
        integer columns, which are also left-aligned.
    wrap : int, default 0
        Wrap text at this width in Rich tables; 0: never wrap.
    show : callable, optional
        ``show(row)``: the cell from the whole row, for display only (e.g. a factor with
        its interval); None: the row's value at ``key``.
    limit : int, default 0
        Shorten longer text to this many characters in tables, the last one "…"; 0:
        never.
    keep : bool, default False
        Never shortened on a narrow terminal (labels, N, d).
    rank : int, default 5
        On a narrow terminal, the columns of the highest rank are hidden first; rank 0
        is never hidden.
    pvalue : bool, default False
        A p-value: below ``PVALUE_FLOOR`` (0.001) it reads "<0.001".
    """

    key: str
    header: str
    digits: int = 4  # significant digits in tables; 0 for text/int columns
    wrap: int = 0  # wrap text at this width in Rich tables (0: never wrap)
    show: Callable[[dict], object] | None = None  # the cell from the whole row (display only)
    limit: int = 0  # shorten longer text to this many characters in tables (0: never)
    keep: bool = False  # never shortened on a narrow terminal (labels, N, d)
    rank: int = 5  # on a narrow terminal, columns of the highest rank are hidden first
    pvalue: bool = False  # a p-value: below 0.001 it reads "<0.001"

    def value(self, row: dict):
        """The cell's value as tables show it, before :func:`format_cell`.

        Parameters
        ----------
        row : dict
            A record of the table.

        Returns
        -------
        object
            ``show(row)``, or the row's value at ``key`` (None when it has none); text
            longer than ``limit`` shortened to ``limit`` characters ending in "…", and a
            ``pvalue`` below ``PVALUE_FLOOR`` as its text ("<0.001").

        Examples
        --------
        >>> Column("segment", "segment", 0, limit=6).value({"segment": "run_0001"})
        'run_0…'
        """
        value = self.show(row) if self.show is not None else row.get(self.key)
        if self.limit and isinstance(value, str) and len(value) > self.limit:
            return value[: self.limit - 1] + "…"
        if self.pvalue and isinstance(value, float) and value < PVALUE_FLOOR:
            return format_pvalue(value)
        return value


SHOWN_ROWS = 1000
"""Most rows a table shows for people (terminal, text, Markdown, HTML): a log of 10⁶
one-epoch segments is read in CSV or JSON, which keep every row."""


@dataclass(frozen=True)
class Table:
    """A titled table of records, with the columns people read.

    Attributes
    ----------
    title : str
        The table's title (and, in a CSV of several tables, the ``table`` cell of each
        of its rows).
    columns : tuple of Column
        The columns shown in tables, in order.
    rows : list of dict
        The records, one per row; CSV and JSON keep every key and every row.
    caption : str, default ""
        A line under the table (the test's level, what a column means, ...).
    """

    title: str
    columns: tuple[Column, ...]
    rows: list[dict]
    caption: str = ""

    def shown(self) -> Table:
        """The table as people read it: at most ``SHOWN_ROWS`` rows, the caption saying so.

        Returns
        -------
        Table
            This table when it has at most ``SHOWN_ROWS`` rows; otherwise its first
            ``SHOWN_ROWS`` rows, with a caption saying that every row is in the CSV and
            JSON outputs.
        """
        if len(self.rows) <= SHOWN_ROWS:
            return self
        more = (
            f"the first {SHOWN_ROWS:,} of {len(self.rows):,} rows; every row is in the CSV "
            "and JSON outputs"
        )
        caption = f"{self.caption}; {more}" if self.caption else more
        return Table(self.title, self.columns, self.rows[:SHOWN_ROWS], caption)


@dataclass(frozen=True)
class Report:
    """What a command outputs: tables for people, ``document`` for machines (JSON).

    A diagnose document's ``segments`` (and its table's rows) are
    :class:`~credcli.report.records.Records`, a sequence of the records made as they are
    read; :func:`text_pieces` writes them (``json.loads`` of its JSON is the document as
    plain values).

    Attributes
    ----------
    tables : list of Table
        The tables of the terminal, text, Markdown and CSV outputs, in order.
    document : dict
        The JSON document: ``version``, ``command``, ``parameters`` and the command's
        results (records as JSON values).
    notes : list of str
        Lines printed after the tables (advice, findings, what was dropped); default
        none.
    """

    tables: list[Table]
    document: dict
    notes: list[str] = field(default_factory=list)


def _label_text(rec: dict) -> str:
    """The label as tables show it: the record's ``label``, already the shown label
    (:func:`credcli.report.records.shown_label`)."""
    return str(rec["label"])


NAME_LIMIT = 60
"""Longest segment or log name shown in a table cell (JSON and CSV keep the whole name)."""

SEGMENT_COLUMNS = (
    Column("segment", "segment", 0, limit=NAME_LIMIT, rank=0),
    Column("n", "N", 0, keep=True, rank=0),
    Column("dim", "d", 0, keep=True, rank=0),
    Column("label", "label", 0, keep=True, rank=0, show=_label_text),
    Column("scale_factor", "cov × (interval)", 0, show=lambda r: scale_interval(r), rank=1),
    Column("scale_pvalue", "scale p", 3, pvalue=True, rank=3),
    Column("elt_pvalue", "ELT p", 3, pvalue=True, rank=2),
    Column("bias_mahalanobis", "|bias| [σ]", 3, rank=3),
    Column("rmse", "RMSE", 4, rank=4),
    Column("block_length", "L", 0, rank=4),
    Column("nci", "NCI [dB]", 3, rank=5),
    Column("anees", "ANEES", 4, rank=5),
    Column("nees_label", "NEES baseline", 0, rank=6),
    Column("nci_label", "NCI baseline", 0, rank=6),
)

SEGMENT_COLUMNS_ALL = SEGMENT_COLUMNS + (
    Column("nci_centered", "NCI centred", 3),
    Column("nll", "NLL", 4),
    Column("es", "ES", 4),
    Column("delta_nll_minus", "ΔNLL−", 3),
    Column("delta_nll_plus", "ΔNLL+", 3),
    Column("delta_es_minus", "ΔES−", 3),
    Column("delta_es_plus", "ΔES+", 3),
    Column("srd_nll", "SRD NLL", 3),
    Column("srd_es", "SRD ES", 3),
)


WHITENESS_COLUMN = Column("whiteness_pvalue", "white p", 3, pvalue=True, rank=2)
"""The innovations' portmanteau p-value (--innovations), after the ELT's."""


def _number(x: float | None) -> str:
    """A short number for sentences: 3 significant digits, no float noise; "—" for a
    number that is not there (an open interval's end)."""
    return "—" if x is None else f"{x:.3g}"


def _interval(factor: float | None, low: float | None, high: float | None) -> str:
    """'2.3 (1.9–2.8)': a factor with its interval; '2.3 (no interval)' without one."""
    if low is None or high is None:
        return f"{_number(factor)} (no interval)"
    return f"{_number(factor)} ({_number(low)}–{_number(high)})"


def scale_interval(rec: dict) -> str | None:
    """The ``cov ×`` cell of a segment record: κ̂ with its interval.

    Parameters
    ----------
    rec : dict
        A segment record ([segment_record][credcli.report.records.segment_record]).

    Returns
    -------
    str or None
        '2.3 (1.9–2.8)'; '2.3 (no interval)' where the data hold too few batches for one
        (the segment's reason says why); None when no scale was estimated.
    """
    if rec.get("scale_factor") is None:
        return None
    return _interval(rec["scale_factor"], rec.get("scale_factor_low"), rec.get("scale_factor_high"))


NOISE_CONDITIONS = frozenset({Label.OPTIMISM.value, Label.PESSIMISM.value})
"""The conditions of a label that a covariance factor answers."""


def _finite(x) -> float | None:
    """A number as the records give it: None when it is missing, NaN or infinite."""
    return None if x is None or not math.isfinite(x) else float(x)


def _finites(values) -> list[float | None]:
    return [_finite(float(v)) for v in values]


def scale_text(diag) -> str | None:
    """κ̂ with its interval, as the ``cov ×`` cell shows it, from a Diagnosis.

    Parameters
    ----------
    diag : Diagnosis
        A segment's diagnosis.

    Returns
    -------
    str or None
        '2.3 (1.9–2.8)', '2.3 (no interval)', or None when no finite κ̂ was estimated.
    """
    sc = diag.scale
    factor = None if sc is None else _finite(sc.scale_factor)
    if factor is None:
        return None
    return _interval(factor, _finite(sc.scale_factor_low), _finite(sc.scale_factor_high))


def bias_size(diag) -> float | None:
    """The GLS mean's size in standard deviations (``|bias| [σ]``), or None.

    Parameters
    ----------
    diag : Diagnosis
        A segment's diagnosis.

    Returns
    -------
    float or None
        √(μ̂ᵀ W̄ μ̂) of the scale test; None when there is none or it is not finite.
    """
    return None if diag.scale is None else _finite(diag.scale.bias_mahalanobis)


def advice(item: SegmentDiagnosis) -> str | None:
    """What a user acts on for a segment that is not credible, in one line.

    Parameters
    ----------
    item : SegmentDiagnosis
        A diagnosed segment.

    Returns
    -------
    str or None
        "segment: what to do": the covariance factor (per direction or block where they
        differ), the bias and the component to look at first, a time offset to fix first,
        or why there is no verdict; None for a credible segment with both questions
        answered.
    """
    diag = item.diagnosis
    label, untested = diag.label, [q.value for q in diag.untested]
    if label is Label.CREDIBLE and not untested:
        return None
    if label is Label.INSUFFICIENT:
        return f"{item.segment}: no verdict: {diag.reason}"
    noise = bool(label.conditions & NOISE_CONDITIONS)
    sc = diag.scale
    parts = []
    offset = None if diag.time_offset is None else _finite(diag.time_offset.seconds)
    if offset is not None:  # the cause to fix first
        which = "lags" if offset > 0 else "leads"
        parts.append(
            f"the estimate {which} the truth by {_number(abs(offset))} s: fix the "
            "time stamps before the covariance"
        )
    if untested:
        parts.append(f"{' and '.join(untested)} untested: {diag.reason}")
    if diag.by_direction:
        parts.append(direction_advice(diag))
    elif noise:
        parts.append(f"multiply the covariance by {scale_text(diag)}")
    if diag.blocks and noise:
        parts.append(block_advice(diag))
    location = label.location
    if location in ("bias", SMM_CONDITION):
        bias = ", ".join(_number(b) for b in _finites(sc.bias))
        parts.append(f"bias ({bias}) in the log's units, {_number(bias_size(diag))} σ")
        parts.append(_smm_hint(diag))
    elif location == "asymmetric":
        mean = diag.mean_test
        parts.append(
            f"errors not symmetric about zero (ELT p {format_pvalue(_finite(diag.elt_pvalue))}) "
            f"with no mean found (mean test p "
            f"{format_pvalue(None if mean is None else _finite(mean.pvalue))}; "
            f"mean {_number(bias_size(diag))} σ)"
        )
    return f"{item.segment}: " + "; ".join(p for p in parts if p)


def _factors(factors, low, high) -> list[str]:
    """Each factor with its interval, "f (low–high)"."""
    return [
        f"{_number(f)} ({_number(lo)}–{_number(hi)})"
        for f, lo, hi in zip(_finites(factors), _finites(low), _finites(high))
    ]


def direction_advice(diag) -> str:
    """The matrix correction of a scale decided along principal directions.

    Parameters
    ----------
    diag : Diagnosis
        A diagnosis whose noise label comes from its directions (``by_direction``).

    Returns
    -------
    str
        The factor (interval) along each direction of the whitened errors, for Σ̂_k to
        become L_k Ŝ L_kᵀ.
    """
    dirs = diag.directions
    parts = [
        f"{factor} along ({', '.join(_number(c) for c in _finites(v))})"
        for factor, v in zip(_factors(dirs.factors, dirs.low, dirs.high), dirs.vectors.T)
    ]
    return (
        "the misfit differs between directions; multiply the covariance, in whitened "
        "coordinates, by " + ", ".join(parts) + " (Σ̂_k → L_k Ŝ L_kᵀ)"
    )


def block_advice(diag) -> str:
    """The factor (interval) of each named block of the state.

    Parameters
    ----------
    diag : Diagnosis
        A diagnosis with named blocks (a pose's position and orientation).

    Returns
    -------
    str
        "by block: position f (low–high), …": the blocks of the covariance to correct,
        when they differ.
    """
    blocks = diag.blocks
    factors = _factors(
        [b.factor for b in blocks], [b.low for b in blocks], [b.high for b in blocks]
    )
    return "by block: " + ", ".join(f"{b.name} {f}" for b, f in zip(blocks, factors))


def _smm_hint(diag) -> str:
    """What an SMM finding means for the estimator, and the axis to look at first: the
    component whose mean is the most standard errors from zero."""
    sc = diag.scale
    bias = [] if sc is None else _finites(sc.bias)
    stderr = [] if sc is None else _finites(sc.bias_stderr)
    ratios = [
        abs(b) / s if s else 0.0 for b, s in zip(bias, stderr) if b is not None and s is not None
    ]
    if not ratios or max(ratios) == 0:
        return ""
    k = max(range(len(ratios)), key=ratios.__getitem__)
    return f"look first at component {k} ({_number(ratios[k])} standard errors from 0)"


LOCATION_MEANING = {
    "bias": (
        "bias: the errors have a mean that no covariance allows for, so retuning the noise "
        "will not fix it; look for a model mismatch: an unmodelled sensor bias, lever arm, "
        "time offset, frame or motion model"
    ),
    "asymmetric": (
        "asymmetric: the errors are not symmetric about zero though the mean test finds no "
        "mean: skewed errors or outliers on one side (non-line-of-sight or multipath ranges, "
        "a one-sided fault), which a Gaussian covariance cannot describe; look at the "
        "measurement model's tails, or gate the outliers"
    ),
    SMM_CONDITION: (
        "smm: the errors are not symmetric about zero (the paper's system-model mismatch), "
        "and no mean test could run to tell a bias from skewed errors; look for a model "
        "mismatch: an unmodelled sensor bias, lever arm, time offset, frame or motion model"
    ),
}
"""What each location condition means for the estimator (the advice's last lines)."""


def format_cell(value, digits: int) -> str:
    """A cell's value as text for people (tables, Markdown, HTML, CI summaries).

    Parameters
    ----------
    value : object
        The cell's value (:meth:`Column.value`): None, a bool, a float, a list of them,
        or anything else shown as ``str(value)``.
    digits : int
        Significant digits of a float; 0 for the shortest ``g`` form.

    Returns
    -------
    str
        "—" for None; "yes" / "no" for a bool; a float with ``digits`` significant
        digits, in scientific notation when it is non-zero and below 10^-digits in size;
        a list as "(a, b, ...)", each item formatted alike.

    Examples
    --------
    >>> format_cell(2.34567, 3), format_cell(0.000123, 3), format_cell(None, 3)
    ('2.35', '1.23e-04', '—')
    >>> format_cell([1.0, 2.5], 3), format_cell(True, 0), format_cell(12, 4)
    ('(1, 2.5)', 'yes', '12')
    """
    if value is None:
        return "—"
    if isinstance(value, list):
        return "(" + ", ".join(format_cell(v, digits) for v in value) + ")"
    if value is None:
        return "—"
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, float):
        if digits == 0:
            return f"{value:g}"
        if value != 0 and abs(value) < 10 ** (-digits):
            return f"{value:.{digits - 1}e}"
        return f"{value:.{digits}g}"
    return str(value)


def _csv_cell(value) -> str:
    if value is None:
        return ""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return repr(value)
    if isinstance(value, int):
        return str(value)
    if isinstance(value, list):  # "-0.07 -0.35" is text, and a formula, to a spreadsheet
        return _unformula(" ".join(_csv_cell(v) for v in value))
    text = str(value)
    if text[:1] in _FORMULA_STARTS:  # a name from the data: never a spreadsheet formula
        return "'" + text
    return text


_FORMULA_STARTS = frozenset("=+-@\t\r")
"""A text cell starting with one of these is read as a formula by spreadsheets (OWASP, CSV
injection); it is written with a leading apostrophe. Numbers are written as numbers."""


def _unformula(text: str) -> str:
    """``text`` with a leading apostrophe where a spreadsheet would read it as a formula."""
    return "'" + text if text[:1] in _FORMULA_STARTS else text


_FORMULA_START = operator.methodcaller("startswith", tuple(_FORMULA_STARTS))
"""Whether a text starts as a formula (:data:`_FORMULA_STARTS`), one C call a text."""


_LABEL_STYLE = {
    Label.CREDIBLE.value: "green",
    Label.INSUFFICIENT.value: "dim",
    "regressed": "bold red",
    "improved": "green",
    "unchanged": "dim",
}
_LABEL_KEYS = {"label", "nees_label", "nci_label", "status"}


def _fitting_columns(table: Table, texts, width: int | None) -> list[int]:
    """Indices of the columns to show: all when they fit in ``width``; otherwise the columns
    of the highest rank (the rightmost first) are hidden until the rest fits. Columns of
    rank 0 (segment, N, d, label) are always shown."""
    shown = list(range(len(table.columns)))
    if width is None:
        return shown

    def need(k: int) -> int:
        col = table.columns[k]
        widest = max([len(col.header)] + [len(t[k]) for t in texts])
        return (min(widest, max(col.wrap, len(col.header))) if col.wrap else widest) + 3

    while sum(need(k) for k in shown) + 1 > width:
        droppable = [k for k in shown if table.columns[k].rank > 0]
        if not droppable:
            break
        shown.remove(max(droppable, key=lambda k: (table.columns[k].rank, k)))
    return shown


def rich_table(table: Table, width: int | None = None):
    """A ``rich.table.Table`` for the terminal, hiding the least important columns when the
    table would be wider than ``width`` (the caption names them).

    The table shows at most ``SHOWN_ROWS`` rows (:meth:`Table.shown`). Columns of the
    highest ``rank`` (the rightmost first) are hidden until the rest fits; rank-0 columns
    are always shown. Titles, captions and cells are escaped for Rich markup and made
    printable (:func:`credcli.errors.printable`); label and status cells are coloured.

    Parameters
    ----------
    table : Table
        The table to show.
    width : int, optional
        The terminal's width in characters; None: every column is shown.

    Returns
    -------
    rich.table.Table
        The table, ready for ``Console.print``.
    """
    from rich.markup import escape
    from rich.table import Table as RichTable

    table = table.shown()
    texts = [
        [format_cell(col.value(row), col.digits) for col in table.columns] for row in table.rows
    ]
    shown = _fitting_columns(table, texts, width)
    caption = table.caption
    if len(shown) < len(table.columns):
        hidden = ", ".join(c.header for k, c in enumerate(table.columns) if k not in shown)
        caption = (caption + "; " if caption else "") + (
            f"not shown at this width: {hidden} (see the JSON or CSV output)"
        )
    columns = [table.columns[k] for k in shown]
    texts = [[t[k] for k in shown] for t in texts]
    table = Table(table.title, tuple(columns), table.rows, caption)
    out = RichTable(
        title=escape(printable(table.title)),
        caption=escape(printable(table.caption)) or None,
        title_justify="left",
    )
    for k, col in enumerate(table.columns):
        widest = max([len(col.header)] + [len(t[k]) for t in texts])
        out.add_column(
            escape(col.header),
            justify="right" if col.digits else "left",
            no_wrap=not col.wrap,
            max_width=col.wrap or None,
            min_width=widest if col.keep else None,
            overflow="fold" if col.wrap else "ellipsis",
        )
    for row, row_texts in zip(table.rows, texts):
        cells = []
        for col, raw in zip(table.columns, row_texts):
            text = escape(printable(raw))
            if col.key in _LABEL_KEYS and isinstance(row.get(col.key), str):
                text = f"[{_LABEL_STYLE.get(text, 'bold yellow')}]{text}[/]"
            cells.append(text)
        out.add_row(*cells)
    return out


def json_safe(value):
    """``value`` with every non-finite float (nested in dicts, lists, tuples) as None, as
    the records write them: JSON has no Inf or NaN, and every format takes the same
    report.

    Parameters
    ----------
    value : object
        A JSON-like value: dicts, lists and tuples of floats, strings, ints, bools, None.

    Returns
    -------
    object
        A copy of ``value`` with each NaN or infinite float as None and each tuple as a
        list; any other value as it is.

    Examples
    --------
    >>> json_safe({"a": [1.0, float("inf")], "b": (float("nan"), "x")})
    {'a': [1.0, None], 'b': [None, 'x']}
    """
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {k: json_safe(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [json_safe(v) for v in value]
    return value


TEXT_PIECE = 1 << 20
"""Characters of a streamed output's pieces (:func:`text_pieces`)."""


def text_pieces(report: Report, fmt: OutputFormat, width: int = 160) -> Iterator[str]:
    """:func:`to_text` in pieces of about :data:`TEXT_PIECE` characters.

    JSON is streamed a record at a time (:func:`credcli.report.jsontext.iterencode`, the
    bytes of ``json.JSONEncoder(indent=2, allow_nan=False)``), so that a document of 10⁶
    segments is never held as one string; the other formats come in one piece. The
    records are JSON-safe as made (:func:`credcli.report.records.json_value`); the rest of
    the document is made so here (:func:`json_safe`).

    Parameters
    ----------
    report : Report
        The report to write.
    fmt : OutputFormat
        The output format.
    width : int, default 160
        The width of a TABLE output in characters (ignored by the other formats).

    Yields
    ------
    str
        Consecutive pieces of the text; joined, they are ``to_text(report, fmt, width)``
        (the JSON ends with a newline).
    """
    if fmt is OutputFormat.CSV:
        yield from _csv_pieces(report)
        return
    if fmt is not OutputFormat.JSON:
        yield to_text(report, fmt, width)
        return
    document = {
        key: value if key == "segments" else json_safe(value)
        for key, value in report.document.items()
    }
    records = document.get("segments")
    texts = _record_texts(records) if isinstance(records, Records) else None
    pieces = jsontext.iterencode(document, "segments", TEXT_PIECE, texts)
    last = next(pieces)
    for piece in pieces:
        yield last
        last = piece
    yield last + "\n"


BATCH_ROWS = 4096
"""Records of a batch (:class:`credcli.report.records.RecordBatch`) written at a time: the
Python values of that many rows exist at once, not of a million."""


def _batch_chunks(batch: RecordBatch) -> Iterator[tuple[dict, int]]:
    """(the columns, the rows) of each chunk of BATCH_ROWS records of ``batch``."""
    for start in range(0, len(batch), BATCH_ROWS):
        stop = min(start + BATCH_ROWS, len(batch))
        yield batch.columns(start, stop), stop - start


def _record_texts(records: Records) -> Iterator[list[str]]:
    """The records' JSON texts at level 2 in lists of consecutive records, a batch's from
    one template (:func:`credcli.report.jsontext.encode_rows`)."""
    singles: list[str] = []
    for part in records.parts:
        if not isinstance(part, RecordBatch):
            singles.append(jsontext.encode(part, 2))
            if len(singles) >= 64:
                yield singles
                singles = []
            continue
        yield singles
        singles = []
        for columns, count in _batch_chunks(part):
            yield jsontext.encode_rows(part.shared, columns, count, 2)
    yield singles


def to_text(report: Report, fmt: OutputFormat, width: int = 160) -> str:
    """The whole report as text in ``fmt`` (a plain table without colour for TABLE).

    Parameters
    ----------
    report : Report
        The report to write.
    fmt : OutputFormat
        JSON: the document, indented by two spaces; CSV: every row of every table
        (RFC 4180, full-precision floats); MARKDOWN: the tables and notes as shown;
        TABLE: the Rich tables and the notes, without colour.
    width : int, default 160
        The width of a TABLE output in characters; narrower tables hide their least
        important columns (:func:`rich_table`).

    Returns
    -------
    str
        The report as text.
    """
    if fmt is OutputFormat.JSON:
        return "".join(text_pieces(report, fmt, width))
    if fmt is OutputFormat.CSV:
        return _csv(report)
    if fmt is OutputFormat.MARKDOWN:
        return _markdown(report)
    from rich.console import Console

    buf = io.StringIO()
    # never the notebook's display: in Jupyter, Rich would show the table there and leave
    # the buffer empty
    console = Console(
        file=buf, width=width, color_system=None, force_terminal=False, force_jupyter=False
    )
    for table in report.tables:
        console.print(rich_table(table, width))
    for note in report.notes:
        console.print(printable(note), markup=False)
    return buf.getvalue()


def _csv(report: Report) -> str:
    """One valid CSV (RFC 4180: CRLF line ends, cells with a comma, quote, CR or LF quoted).
    Several tables share it: a first column ``table`` names each row's
    table, and the header is the union of the tables' columns."""
    return "".join(_csv_pieces(report))


def _csv_pieces(report: Report) -> Iterator[str]:
    """:func:`_csv` in pieces of about TEXT_PIECE characters, a batch of records
    (:class:`credcli.report.records.RecordBatch`) written from one template per chunk."""
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\r\n")  # RFC 4180: a CR or LF in a cell is quoted
    if len(report.tables) == 1:
        keys = _csv_keys(report.tables[0])
        writer.writerow(keys)
        prefix: tuple[str, ...] = ()
    else:
        keys = []
        for table in report.tables:
            keys.extend(c.key for c in table.columns if c.key not in keys)
        writer.writerow(["table", *keys])
    for table in report.tables:
        if len(report.tables) > 1:
            prefix = (table.title,)
        rows = table.rows.parts if isinstance(table.rows, Records) else table.rows
        for row in rows:
            if isinstance(row, RecordBatch) and len(prefix) + len(keys) > 1:  # (the writer
                # quotes a row's only cell when it is empty)
                for columns, count in _batch_chunks(row):
                    buf.writelines(_csv_lines(row.shared, columns, count, keys, prefix))
                    if buf.tell() >= TEXT_PIECE:
                        yield _emptied(buf)
            else:
                for record in row if isinstance(row, RecordBatch) else (row,):
                    writer.writerow([*prefix, *(_csv_cell(record.get(k)) for k in keys)])
                    if buf.tell() >= TEXT_PIECE:
                        yield _emptied(buf)
    yield buf.getvalue()


def _emptied(buf: io.StringIO) -> str:
    """What ``buf`` holds, leaving it empty."""
    text = buf.getvalue()
    buf.seek(0)
    buf.truncate()
    return text


def _csv_keys(table: Table) -> list[str]:
    """A single table's CSV holds every key of its records, not only the shown columns."""
    if isinstance(table.rows, Records):
        return table.rows.keys() or [c.key for c in table.columns]
    keys: list[str] = []
    for row in table.rows:
        keys.extend(k for k in row if k not in keys)
    return keys or [c.key for c in table.columns]


def _csv_lines(shared: dict, columns: dict, count: int, keys, prefix=()) -> list[str]:
    """The CSV lines of ``count`` records that differ only at the keys of ``columns``
    (record k is ``shared | {key: columns[key][k]}``), as the CSV writer writes their
    cells (:func:`_csv_cell`) at ``keys``, after the cells ``prefix``: one template filled
    with each column's cells."""
    forms = [_csv_field(text).replace("%", "%%") for text in prefix]
    holes: list[list[str]] = []
    made: dict[int, tuple[str, list]] = {}  # a column met twice is written once
    for key in keys:
        if key in columns:
            column = columns[key]
            if id(column) not in made:
                made[id(column)] = _csv_column(column)
            form, texts = made[id(column)]
            forms.append(form)
            holes.extend(texts)
        else:
            forms.append(_csv_field(_csv_cell(shared.get(key))).replace("%", "%%"))
    template = ",".join(forms) + "\r\n"
    if not holes:
        return [template % ()] * count
    return list(map(template.__mod__, zip(*holes)))


_CSV_QUOTED = frozenset(',"\r\n')
"""A cell with one of these characters is quoted by the CSV writer (delimiter, quote
character, line ends)."""


def _csv_field(text: str) -> str:
    """One cell as the CSV writer writes it among others: quoted when it holds a comma, a
    quote or a line end."""
    if _CSV_QUOTED.isdisjoint(text):
        return text
    buf = io.StringIO()
    csv.writer(buf, lineterminator="\r\n").writerow([text, ""])
    return buf.getvalue()[: -len(",\r\n")]


def _csv_column(values: list) -> tuple[str, list[list[str]]]:
    """(a %-template of one cell, the texts that fill its holes, a list per hole) of a
    column of record values: numbers as :func:`_csv_cell` writes them, one C call a value;
    lists of numbers a column per position; anything else cell by cell."""
    if isinstance(values, jsontext.ListColumn):
        return _csv_lists(values.positions) or ("%s", [[_csv_field(_csv_cell(v)) for v in values]])
    kinds = set(map(type, values))
    if len(kinds) == 1:
        kind = kinds.pop()
        if kind is float:
            return "%s", [list(map(float.__repr__, values))]
        if kind is int:
            return "%s", [list(map(int.__repr__, values))]
        if kind is type(None):
            return "", []
        if kind is str and not any(map(_FORMULA_START, values)):
            if _CSV_QUOTED.isdisjoint("".join(values)):
                return "%s", [values]
            return "%s", [list(map(_csv_field, values))]
        if kind is list and len(sizes := set(map(len, values))) == 1 and sizes != {0}:
            found = _csv_lists([list(p) for p in zip(*values)])
            if found:
                return found
    return "%s", [[_csv_field(_csv_cell(v)) for v in values]]


def _csv_lists(positions) -> tuple[str, list[list[str]]] | None:
    """:func:`_csv_column` of lists of numbers of one length (at least one), given as their
    positions' columns: a cell per list, its numbers joined by spaces; None for anything
    else."""
    if not positions or not all(set(map(type, p)) <= {float, type(None)} for p in positions):
        return None
    holes = [
        [_csv_cell(v) for v in p] if None in p else list(map(float.__repr__, p)) for p in positions
    ]
    holes[0] = [_unformula(text) for text in holes[0]]  # the cell's text starts with it
    return " ".join(["%s"] * len(positions)), holes


_MARKDOWN_SPECIAL = re.compile(r"([\\`*_\[\]<>|#~])")


def markdown_text(text: str) -> str:
    """Text as Markdown shows it literally, on one line.

    ``|`` would end a table cell, ``*``, ``_``, ``[``, ``<`` and the rest would start
    markup (a segment named ``run_1_*``); each is escaped with a backslash. Line breaks
    become spaces and a control character is escaped (:func:`credcli.errors.printable`).

    Parameters
    ----------
    text : str
        Any text (a name or value from the data, a title, a note).

    Returns
    -------
    str
        ``text`` on one line, with Markdown's special characters backslash-escaped.

    Examples
    --------
    >>> print(markdown_text("run_1_*|a\\nb"))
    run\\_1\\_\\*\\|a b
    """
    return _MARKDOWN_SPECIAL.sub(r"\\\1", printable(" ".join(str(text).splitlines())))


def _markdown(report: Report) -> str:
    lines: list[str] = []
    for table in (t.shown() for t in report.tables):
        lines.append(f"### {markdown_text(table.title)}")
        lines.append("")
        lines.append("| " + " | ".join(markdown_text(c.header) for c in table.columns) + " |")
        lines.append("|" + "|".join("---" if not c.digits else "---:" for c in table.columns) + "|")
        for row in table.rows:
            cells = [markdown_text(format_cell(c.value(row), c.digits)) for c in table.columns]
            lines.append("| " + " | ".join(cells) + " |")
        if table.caption:
            lines.extend(["", markdown_text(table.caption)])
        lines.append("")
    lines.extend(f"{markdown_text(note)}  " for note in report.notes)
    return "\n".join(lines).rstrip() + "\n"


def diagnose_report(
    results: list[SegmentDiagnosis],
    config: DiagnosisConfig,
    parameters: dict,
    logs: Mapping[LogId, LogSummary],
    show_all: bool,
    monte_carlo: dict | None = None,
) -> Report:
    """The `credcli diagnose` report: one row per segment, and the JSON document (with
    the per-epoch ANEES test of Monte Carlo runs, when given).

    Results are matched to their log by id (``SegmentDiagnosis.log``), never by name.
    With segments of more than one log, each row names its log and a second table
    compares the logs (accuracy over all epochs, credible segments).

    Parameters
    ----------
    results : list of SegmentDiagnosis
        The diagnosed segments, in report order.
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
    monte_carlo : dict, optional
        The per-epoch ANEES test of Monte Carlo runs
        (:func:`credcli.report.records.monte_carlo_record`): a note, and the document's
        ``monte_carlo``; None: no such test.

    Returns
    -------
    Report
        The segment table (with the innovations' whiteness column when any segment has
        that test), the logs' table when there are several logs, the notes (ELT
        subsamples, dropped rows, advice, findings, correlated innovations, the Monte
        Carlo test) and the document (``version``, ``command``, ``parameters``, ``logs``,
        ``segments`` and, when given, ``monte_carlo``).
    """
    records = segment_records(results)
    summaries, logs = logs, {log_id: log_record(summary) for log_id, summary in logs.items()}
    parts = _parts(results)
    multi = len({part.log for part in parts}) > 1
    columns = SEGMENT_COLUMNS_ALL if show_all else SEGMENT_COLUMNS
    if any(_singles(results, lambda r: r.whiteness is not None)):
        columns = columns[:7] + (WHITENESS_COLUMN,) + columns[7:]
    if multi:
        columns = (Column("log", "log", 0, limit=NAME_LIMIT),) + columns
    notes = []
    sub = [
        r.segment
        for r in _singles(results, lambda r: r.diagnosis.elt and r.diagnosis.elt.subsampled)
    ]
    if sub:
        notes.append(
            f"ELT ran on a random subsample of {config.max_elt_epochs} epochs in "
            f"segment(s) {', '.join(sub)} (memory budget; see `max_elt_epochs`)."
        )
    for summary in summaries.values():
        if summary.dropped_rows:
            notes.append(f"{summary.id.name}: dropped {summary.dropped_rows} row(s) with NaN/Inf.")
    notes.extend(_advice_lines(results))
    notes.extend(_finding_lines(results))
    notes.extend(_whiteness_lines(results))
    if monte_carlo is not None:
        mc = monte_carlo
        notes.append(
            f"Monte Carlo: {mc['runs']} runs; the per-epoch ANEES is inside its "
            f"{100 * mc['confidence']:g}% χ²_{mc['dof']} bounds [{_number(mc['lower'])}, "
            f"{_number(mc['upper'])}] at {100 * mc['fraction_inside']:.1f}% of the epochs "
            f"(expected {100 * mc['confidence']:g}%); per segment: "
            + ", ".join(f"{k} {100 * v:.1f}%" for k, v in mc["segments"].items())
        )
    table = Table("credcli diagnose", columns, records, caption=_level_caption(config))
    tables = [table, _logs_table(logs, results)] if multi else [table]
    document = {
        "version": __version__,
        "command": "diagnose",
        "parameters": parameters,
        "logs": list(logs.values()),
        "segments": records,
    }
    if monte_carlo is not None:
        document["monte_carlo"] = monte_carlo
    return Report(tables, document, notes)


LOG_COLUMNS = (
    Column("path", "log", 0, limit=NAME_LIMIT, rank=0),
    Column("epochs", "N", 0, keep=True, rank=0),
    Column("credible", "credible", 0, keep=True, rank=0),
    Column("rmse", "RMSE", 4, rank=1),
    Column("error_norm_mean", "mean ‖e‖", 4, rank=2),
    Column("error_norm_median", "median ‖e‖", 4, rank=2),
    Column("error_norm_max", "max ‖e‖", 4, rank=2),
)
"""The logs side by side (as evo_res compares results): accuracy over all epochs of each
log, and how many of its segments are credible."""


def _parts(results) -> list:
    """The results as parts: each a SegmentDiagnosis or a run of segments too short for a
    verdict (:class:`credcli.engine.short.ShortSegments`), whose items are not made."""
    return list(results.parts) if isinstance(results, SegmentResults) else list(results)


def _singles(results, keep) -> list[SegmentDiagnosis]:
    """The results that are not part of a run of short segments, where ``keep(result)``."""
    return [p for p in _parts(results) if not isinstance(p, ShortSegments) and keep(p)]


def _logs_table(logs: Mapping[LogId, dict], results) -> Table:
    good: dict[LogId, int] = dict.fromkeys(logs, 0)
    total: dict[LogId, int] = dict.fromkeys(logs, 0)
    for part in _parts(results):
        if part.log not in total:
            continue
        if isinstance(part, ShortSegments):  # insufficient-data, every one
            total[part.log] += len(part)
            continue
        total[part.log] += 1
        diag = part.diagnosis
        good[part.log] += shown_label(diag.label, diag.untested) == Label.CREDIBLE.value
    rows = [
        info | {"credible": f"{good[log_id]} of {total[log_id]}"} for log_id, info in logs.items()
    ]
    return Table("logs compared", LOG_COLUMNS, rows, caption="accuracy over all epochs of each log")


def _advice_lines(results, limit: int = 10) -> list[str]:
    """The advice of each segment that has one (:func:`advice`), at most ``limit``, then
    what each location condition found means. A run of short segments gives each its
    reason without making its items."""
    lines, count, found = [], 0, set()
    for part in _parts(results):
        if isinstance(part, ShortSegments):
            found.add(Label.INSUFFICIENT.location)
            for k in range(min(len(part), max(0, limit - len(lines)))):
                lines.append(f"{part.names[k]}: no verdict: {part.reason(int(part.n[k]))}")
            count += len(part)
            continue
        found.add(part.diagnosis.label.location)
        line = advice(part)
        if line:
            count += 1
            if len(lines) < limit:
                lines.append(line)
    if count > limit:
        lines.append(f"... and {count - limit} more segment(s); see the JSON output")
    lines += [LOCATION_MEANING[c] for c in LOCATION_CONDITIONS if c in found]
    return lines


def _finding_lines(results, limit: int = 10) -> list[str]:
    """The findings the engine reports beside the labels (a slowly varying error, ...)."""
    found = _singles(results, lambda r: r.diagnosis.findings)
    lines = [f"{item.segment}: {f}" for item in found for f in item.diagnosis.findings]
    if len(lines) > limit:
        lines = lines[:limit] + [
            f"... and {len(lines) - limit} more finding(s); see the JSON output"
        ]
    return lines


def _whiteness_lines(results, limit: int = 10) -> list[str]:
    """Segments whose innovations are not white at the whiteness test's share of α (the
    engine's decision, ``Whiteness.rejected``)."""
    bad = _singles(results, lambda r: r.whiteness is not None and r.whiteness.rejected)
    lines = [
        f"{item.segment}: innovations correlated in time (portmanteau p = "
        f"{format_cell(item.whiteness.pvalue, 3)}, {item.whiteness.lags} lags, level "
        f"{format_cell(item.whiteness.level, 3)}): the filter's "
        "model or noise is inconsistent even if the NIS level is right"
        for item in bad[:limit]
    ]
    if len(bad) > limit:
        lines.append(f"... and {len(bad) - limit} more segment(s) with correlated innovations")
    return lines


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

_SHORT = {
    Label.CREDIBLE.value: "Credible",
    Label.OPTIMISM.value: "O",
    Label.PESSIMISM.value: "P",
    Label.SMM.value: "SMM",
    Label.OPTIMISM_SMM.value: "O+SMM",
    Label.PESSIMISM_SMM.value: "P+SMM",
    Label.INSUFFICIENT.value: "insuff.",
}


def _pct(x):
    return None if x is None else round(100.0 * x, 1)


_METHOD_HEADERS = {
    "calibrated": "calibrated [%]",
    "ks": "ks [%]",
    "paper": "paper rule [%]",
    "nees": "NEES [%]",
    "nci": "NCI [%]",
}


def _method_columns(methods) -> tuple[Column, ...]:
    return tuple(Column(m.value, _METHOD_HEADERS[m.value], 3) for m in methods)


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
    rows = []
    for s in study.scenarios:
        row = {"scenario": s.value}
        for method, acc in study.accuracy.items():
            row[method.value] = _pct(acc[s])
        if paper_protocol:
            row["published"] = _pct(PAPER_TABLE_II[s.value])
        rows.append(row)
    cols = (Column("scenario", "scenario", 0),) + _method_columns(study.accuracy)
    if paper_protocol:
        cols += (Column("published", "published [%]", 3),)
    table2 = Table(
        "Table II: diagnosis accuracy",
        cols,
        rows,
        caption=f"{study.trials} trials per scenario; ks = the authors' code, paper rule = "
        "Algorithm 1 as printed"
        + ("; published = the paper's Table II (proposed method)" if paper_protocol else ""),
    )
    conf_rows = [
        {"scenario": t.value} | {lab.value: study.confusion[t][lab] for lab in CONFUSION_LABELS}
        for t in study.scenarios
    ]
    conf_cols = (Column("scenario", "true \\ diagnosed", 0),) + tuple(
        Column(lab.value, _SHORT[lab.value], 0) for lab in CONFUSION_LABELS
    )
    table3 = Table(
        f"Table III: confusion matrix of the {study.variant.value} variant", conf_cols, conf_rows
    )
    document = {
        "version": __version__,
        "command": "simulate",
        "parameters": parameters,
        "accuracy": {
            m.value: {s.value: acc[s] for s in study.scenarios} for m, acc in study.accuracy.items()
        },
        "confusion_variant": study.variant.value,
        "confusion": {
            t.value: {lab.value: study.confusion[t][lab] for lab in CONFUSION_LABELS}
            for t in study.scenarios
        },
    }
    return Report([table2, table3], document)


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
    rows = [
        {"value": p.value, "scenario": p.truth.value, "trials": p.trials}
        | {m.value: _pct(a) for m, a in p.accuracy.items()}
        for p in points
    ]
    cols = (
        Column("value", sweep.parameter.value, 4),
        Column("scenario", "true label", 0),
        Column("trials", "trials", 0),
    ) + _method_columns(points[0].accuracy if points else ())
    document = {
        "version": __version__,
        "command": "simulate",
        "parameters": parameters,
        "sweep": {
            "parameter": sweep.parameter.value,
            "values": list(sweep.values),
            "points": [
                {
                    "value": p.value,
                    "scenario": p.truth.value,
                    "trials": p.trials,
                    "accuracy": {m.value: a for m, a in p.accuracy.items()},
                }
                for p in points
            ],
        },
    }
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

    def cols(x):
        return (
            Column(x, "ρ" if x == "rho" else "γ", 4),
            Column("mean_es", "mean ES", 5),
            Column("expected_es", "E[ES] exact", 5),
            Column("mean_nll", "mean NLL", 5),
            Column("expected_nll", "E[NLL] exact", 5),
        )

    tables = [
        Table(
            "Fig. 1a: scores against the covariance scale ρ (γ = 0)",
            cols("rho"),
            [asdict(p) for p in by_rho],
            caption=f"sample means over {runs} runs; exact expectations",
        ),
        Table(
            "Fig. 1b: scores against the bias γ (μ = γ·1, ρ = 1)",
            cols("gamma"),
            [asdict(p) for p in by_gamma],
            caption=f"sample means over {runs} runs; exact expectations",
        ),
    ]
    document = {
        "version": __version__,
        "command": "simulate",
        "parameters": parameters,
        "curves": {"rho": [asdict(p) for p in by_rho], "gamma": [asdict(p) for p in by_gamma]},
    }
    return Report(tables, document)


UWB_COLUMNS = (
    Column("segment", "period", 0, limit=NAME_LIMIT, rank=0),
    Column("t_start", "t start [s]", 4, rank=3),
    Column("t_end", "t end [s]", 4, rank=3),
    Column("n", "fixes", 0, keep=True, rank=0),
    Column("label", "label", 0, keep=True, rank=0, show=_label_text),
    Column("scale_factor", "cov × (interval)", 0, show=lambda r: scale_interval(r), rank=1),
    Column("elt_pvalue", "ELT p", 3, pvalue=True, rank=2),
    Column("bias_mahalanobis", "|bias| [σ]", 3, rank=3),
    Column("rmse", "RMSE", 4, rank=4),
    Column("range_label", "range evidence", 0, rank=1),
    Column("range_agrees", "agrees", 0, rank=1),
    Column("nees_label", "NEES", 0, rank=5),
    Column("nci_label", "NCI", 0, rank=5),
    Column("nci", "NCI [dB]", 3, rank=6),
    Column("anees", "ANEES", 4, rank=6),
)


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
    range_cols = (
        Column("segment", "period", 0),
        Column("anchor", "anchor", 0),
        Column("n", "ranges", 0),
        Column("mean_error", "bias [m]", 3),
        Column("bias_stderr", "± s.e. [m]", 2),
        Column("std_error", "std [m]", 3),
        Column("robust_std", "robust std [m]", 3),
        Column("median_std", "reported std [m]", 3),
        Column("robust_ratio", "robust / reported", 3),
        Column("beyond_3sigma", "beyond 3σ", 2),
    )
    anchor_cols = (
        Column("id", "anchor", 0),
        Column("x", "x [m]", 4),
        Column("y", "y [m]", 4),
        Column("z", "z [m]", 4),
        Column("source", "source", 0),
        Column("rms_mm", "gt_range RMS [mm]", 3),
        Column("check", "check", 0),
        Column("rows", "ranges", 0),
    )
    notes = list(run.ranges.notes) + list(run.notes) + _advice_lines(results) + agreement
    notes.append(_screening_note(run, run.settings))
    tables = [
        Table(
            "Anchors", anchor_cols, anchors, caption=f"check: gt_range RMS <= {1000 * warn:g} mm"
        ),
        Table(
            "Range errors per period and anchor (Figs. 4 and 5)",
            range_cols,
            ranges,
            caption=f"range column: {run.ranges.range_column}; error = range − gt_range, "
            "after screening; robust std = 1.4826 MAD; beyond 3σ: |error − bias| > 3 reported std",
        ),
        Table("Table IV: diagnosis per period", UWB_COLUMNS, segments),
    ]
    document = {
        "version": __version__,
        "command": "uwb",
        "parameters": parameters,
        "segments": segments,
        "anchors": anchors,
        "ranges": ranges,
        "screening": {
            "packets": run.packets,
            "fixes": int(run.fixes.time.size),
            "dropped": run.fixes.dropped,
            "moved_to_global_minimum": run.fixes.moved,
            "residual_scale": run.fixes.residual_scale,
        },
        "notes": notes,
    }
    return Report(tables, document, notes)


GATE_COLUMNS = (
    Column("segment", "segment", 0, limit=NAME_LIMIT),
    Column("status", "status", 0),
    Column("labels", "label (baseline → now)", 0),
    Column("nci", "NCI [dB]", 0),
    Column("anees", "ANEES", 0),
    Column("elt", "ELT p", 0),
    Column("why", "why", 0, wrap=60),
)


def _pair(old, new, key):
    def f(snap):
        v = None if snap is None else getattr(snap, key)
        if key.endswith("pvalue"):
            return format_pvalue(v)
        return "—" if v is None else f"{v:.3g}"

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
        {
            "segment": c.segment,
            "status": c.status.value,
            "labels": f"{_label(c.old) or '—'} → {_label(c.new) or '—'}",
            "nci": _pair(c.old, c.new, "nci"),
            "anees": _pair(c.old, c.new, "anees"),
            "elt": _pair(c.old, c.new, "elt_pvalue"),
            "why": "; ".join(c.reasons + c.improvements) or "—",
        }
        for c in comparisons
    ]
    document = {
        "version": __version__,
        "command": "gate",
        "baseline": baseline,
        "parameters": parameters,
        "passed": passed,
        "verdict": verdict,
        "segments": [comparison_record(c) for c in comparisons],
    }
    return Report([Table("credcli gate", GATE_COLUMNS, rows)], document)
