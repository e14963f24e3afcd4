"""Output formats (plain Python: the command line reads them without the renderers)."""

from __future__ import annotations

import enum


class OutputFormat(str, enum.Enum):
    """The output formats of every command (``--format``): the value is the option's text.

    Attributes
    ----------
    TABLE : str
        ``"table"``: Rich tables for people (the default).
    CSV : str
        ``"csv"``: one row per record, every key of the records a column.
    JSON : str
        ``"json"``: the whole document for machines.
    MARKDOWN : str
        ``"markdown"``: Markdown tables (as in the CI job summary).
    """

    TABLE = "table"
    CSV = "csv"
    JSON = "json"
    MARKDOWN = "markdown"


PVALUE_FLOOR = 0.001
"""Text shows smaller p-values as "<0.001" (JSON and CSV keep the number)."""


def format_pvalue(p: float | None) -> str:
    """A p-value as every table, summary, gate line and plot title shows it.

    Three significant digits, ``"<0.001"`` below :data:`PVALUE_FLOOR`, ``"—"`` when there
    is none (JSON and CSV keep the number).

    Parameters
    ----------
    p : float or None
        The p-value; None or NaN when no test was run.

    Returns
    -------
    str
        The p-value as text.

    Examples
    --------
    >>> format_pvalue(0.04321), format_pvalue(0.0004), format_pvalue(None)
    ('0.0432', '<0.001', '—')
    """
    if p is None or p != p:
        return "—"
    return f"<{PVALUE_FLOOR:g}" if p < PVALUE_FLOOR else f"{p:.3g}"
