"""Output formats (plain Python: the command line reads them without the renderers)."""

from __future__ import annotations

import enum


class OutputFormat(str, enum.Enum):
    TABLE = "table"
    CSV = "csv"
    JSON = "json"
    MARKDOWN = "markdown"


PVALUE_FLOOR = 0.001
"""Text shows smaller p-values as "<0.001" (JSON and CSV keep the number)."""


def format_pvalue(p: float | None) -> str:
    """A p-value as every table, summary, gate line and plot title shows it: three
    significant digits, "<0.001" below the floor, "—" when there is none."""
    if p is None or p != p:
        return "—"
    return f"<{PVALUE_FLOOR:g}" if p < PVALUE_FLOOR else f"{p:.3g}"
