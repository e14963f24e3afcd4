"""Column layouts of estimator logs (plain Python: the command line reads its defaults)."""

from __future__ import annotations

import enum
from dataclasses import dataclass, replace


class CovKind(str, enum.Enum):
    """How the claimed covariance is stored."""

    FULL = "full"  # cov_i_j for every i, j
    UPPER = "upper"  # cov_i_j for i <= j
    VAR = "var"  # var_i, a diagonal covariance
    STD = "std"  # std_i, a diagonal covariance


@dataclass(frozen=True)
class LogSchema:
    """Column names of a log. Explicit column lists win over prefixes.

    ``cov_columns`` is read by its length: d² entries are the full matrix in row-major
    order, d(d+1)/2 the upper triangle in row-major order, d the diagonal (variances, or
    standard deviations when ``cov_kind`` is ``std``).
    """

    time: str = "time"
    segment: str = "segment"
    truth_prefix: str = "truth_"
    estimate_prefix: str = "est_"
    cov_prefix: str = "cov_"
    var_prefix: str = "var_"
    std_prefix: str = "std_"
    truth_columns: tuple[str, ...] = ()
    estimate_columns: tuple[str, ...] = ()
    cov_columns: tuple[str, ...] = ()
    cov_kind: CovKind | None = None

    def updated(self, **changes) -> LogSchema:
        """A copy with the given non-None fields changed (for CLI > config > defaults)."""
        changes = {k: v for k, v in changes.items() if v is not None}
        for key in ("truth_columns", "estimate_columns", "cov_columns"):
            if key in changes:
                changes[key] = tuple(changes[key])
        if "cov_kind" in changes:
            changes["cov_kind"] = CovKind(changes["cov_kind"])
        return replace(self, **changes)
