"""Output formats (plain Python: the command line reads them without the renderers)."""

from __future__ import annotations

import enum


class OutputFormat(str, enum.Enum):
    TABLE = "table"
    CSV = "csv"
    JSON = "json"
    MARKDOWN = "markdown"
