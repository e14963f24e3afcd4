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


def format_number(x: float | None) -> str:
    """A number for sentences (advice, notes): three significant digits, no float noise.

    Parameters
    ----------
    x : float or None
        The number; None where there is none (an open interval's end).

    Returns
    -------
    str
        ``x`` in the ``.3g`` form, or ``"—"`` for None.

    Examples
    --------
    >>> format_number(2.34567), format_number(None)
    ('2.35', '—')
    """
    return "—" if x is None else f"{x:.3g}"


def format_interval(factor: float | None, low: float | None, high: float | None) -> str:
    """A factor with its interval, as the ``cov ×`` cell and the advice show it.

    Parameters
    ----------
    factor : float or None
        The factor.
    low, high : float or None
        The interval's ends; None for either: no interval.

    Returns
    -------
    str
        ``"2.3 (1.9–2.8)"``, or ``"2.3 (no interval)"`` without one (:func:`format_number`
        spells each number).

    Examples
    --------
    >>> format_interval(2.3, 1.9, 2.8), format_interval(2.3, None, 2.8)
    ('2.3 (1.9–2.8)', '2.3 (no interval)')
    """
    if low is None or high is None:
        return f"{format_number(factor)} (no interval)"
    return f"{format_number(factor)} ({format_number(low)}–{format_number(high)})"
