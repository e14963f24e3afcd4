"""Renderers: Rich tables, CSV, JSON and Markdown, from a Report.

A command's builder (:mod:`credcli.report.builders`) makes a Report (tables, notes and the
JSON document); the renderers only format it, and name no key of a record. Floats keep full
precision in CSV and JSON; tables round them for reading.
"""

from __future__ import annotations

import csv
import io
import math
import operator
import re
from collections.abc import Iterator

from credcli.engine.config import Label
from credcli.errors import printable
from credcli.report import jsontext
from credcli.report.formats import (  # noqa: F401 (OutputFormat, PVALUE_FLOOR re-exported)
    PVALUE_FLOOR,
    OutputFormat,
)
from credcli.report.records import SEGMENTS, RecordBatch, RecordBlock, Records, StreamedRecords
from credcli.report.tables import Report, Table


def format_cell(value, digits: int) -> str:
    """A cell's value as text for people (tables, Markdown, HTML, CI summaries).

    Parameters
    ----------
    value : object
        The cell's value (:meth:`credcli.report.tables.Column.value`): None, a bool, a float, a list of them,
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
        return float.__repr__(value)  # numpy's float64 repr is "np.float64(0.1)"
    if isinstance(value, int):
        return int.__repr__(value)
    if isinstance(value, list):  # "-0.07 -0.35" is text, and a formula, to a spreadsheet
        return _unformula(" ".join(_csv_cell(v) for v in value))
    text = str(value)
    if text[:1] in _FORMULA_STARTS:  # a name from the data: never a spreadsheet formula
        return "'" + text
    return text


_FORMULA_STARTS = frozenset("=+-@\t\r＝＋－＠")
"""A text cell starting with one of these is read as a formula by spreadsheets (OWASP, CSV
injection); it is written with a leading apostrophe. Numbers are written as numbers. The
full-width forms (U+FF1D, U+FF0B, U+FF0D, U+FF20) are included: a spreadsheet that
normalises text input (East Asian locales) may read them as the ASCII ones."""


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

    The table shows at most ``SHOWN_ROWS`` rows (:meth:`credcli.report.tables.Table.shown`). Columns of the
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
            if col.coloured and isinstance(row.get(col.key), str):
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
        key: value if key == SEGMENTS else json_safe(value)
        for key, value in report.document.items()
    }
    records = document.get(SEGMENTS)
    texts = _record_texts(records) if isinstance(records, (Records, StreamedRecords)) else None
    pieces = jsontext.iterencode(document, SEGMENTS, TEXT_PIECE, texts)
    last = next(pieces)
    for piece in pieces:
        yield last
        last = piece
    yield last + "\n"


TEXT_RECORDS = 64
"""Records whose JSON texts are handed to the encoder together (:func:`_record_texts`)."""

BATCH_ROWS = 4096
"""Records of a batch (:class:`credcli.report.records.RecordBatch`) written at a time: the
Python values of that many rows exist at once, not of a million."""


def _batch_chunks(batch: RecordBatch) -> Iterator[tuple[dict, int]]:
    """(the columns, the rows) of each chunk of BATCH_ROWS records of ``batch``."""
    for start in range(0, len(batch), BATCH_ROWS):
        stop = min(start + BATCH_ROWS, len(batch))
        yield batch.columns(start, stop), stop - start


def _record_texts(records: Records | StreamedRecords) -> Iterator[list[str]]:
    """The records' JSON texts at level 2 in lists of consecutive records, a batch's from
    one template (:func:`credcli.report.jsontext.encode_rows`); streamed records are made
    as their texts are asked for."""
    singles: list[str] = []
    for part in records.parts:
        if not isinstance(part, RecordBatch):
            for record in part if isinstance(part, RecordBlock) else (part,):
                singles.append(jsontext.encode(record, 2))
                if len(singles) >= TEXT_RECORDS:
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
        file=buf,
        width=width,
        color_system=None,
        force_terminal=False,
        force_jupyter=False,
        highlight=False,  # Rich's highlighter takes a minute on a 100,000-character name
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
        rows = (
            table.rows.parts if isinstance(table.rows, (Records, StreamedRecords)) else table.rows
        )
        for row in rows:
            if isinstance(row, RecordBatch) and len(prefix) + len(keys) > 1:  # (the writer
                # quotes a row's only cell when it is empty)
                for columns, count in _batch_chunks(row):
                    buf.writelines(_csv_lines(row.shared, columns, count, keys, prefix))
                    if buf.tell() >= TEXT_PIECE:
                        yield _emptied(buf)
            else:
                for record in row if isinstance(row, (RecordBatch, RecordBlock)) else (row,):
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
    if isinstance(table.rows, (Records, StreamedRecords)):
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
