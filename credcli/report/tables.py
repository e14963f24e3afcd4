"""What a command outputs, before any format: a Report of titled Tables of records, each
with the Columns people read, its notes, and the JSON document.

The renderers (:mod:`credcli.report.render`, :mod:`credcli.report.html`) format a Report; the
builders (:mod:`credcli.report.builders`) make one; the records
(:mod:`credcli.report.records`) say which keys a column shows.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

from credcli.report.formats import PVALUE_FLOOR, format_pvalue


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
        Significant digits of a float in tables (:func:`credcli.report.render.format_cell`); 0 for text and
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
    coloured : bool, default False
        A label or a status: Rich and HTML tables colour a text cell by its value.
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
    coloured: bool = False  # a label or status: coloured by its value in tables

    def value(self, row: dict):
        """The cell's value as tables show it, before :func:`credcli.report.render.format_cell`.

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
    read; :func:`credcli.report.render.text_pieces` writes them (``json.loads`` of its JSON is the document as
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
