"""The numbers behind a segment's figures: NEES per epoch (Eq. (4)), the whitened errors
the ELT flips (Eq. (12)), and the mean NLL and energy score against a scale of the claimed
covariance (Eqs. (7), (10); Fig. 1), for the claimed errors and for the errors with their
mean removed. The plots draw these; they compute nothing."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import special

from credcli.engine.elt import whiten
from credcli.engine.metrics import nees, score_curves

PROBE_CURVE_SCALES = (0.25, 4.0, 17)
"""The covariance scales of the score curves: geomspace(1/4, 4, 17), plus 1/c, 1 and c."""


def curve_scales(c: float) -> np.ndarray:
    """The scales at which the score curves are evaluated, with 1/c, 1 and c among them."""
    return np.unique(np.r_[np.geomspace(*PROBE_CURVE_SCALES), 1.0 / c, 1.0, c])


@dataclass(frozen=True)
class ScoreCurves:
    """Mean NLL and mean ES at each scale, of the errors as claimed and centred."""

    scales: np.ndarray
    claimed: tuple[np.ndarray, np.ndarray]
    centred: tuple[np.ndarray, np.ndarray]


@dataclass(frozen=True)
class SegmentCurves:
    """A segment's NEES, whitened errors and (for a segment with a verdict) score curves."""

    nees: np.ndarray
    whitened: np.ndarray
    scores: ScoreCurves | None = None


def segment_curves(errors: np.ndarray, cov: np.ndarray, c: float | None) -> SegmentCurves:
    """The curves of one segment; the score curves around the probe factor ``c`` unless it
    is None (a segment without a verdict)."""
    scores = None
    if c is not None:
        scales = curve_scales(c)
        scores = ScoreCurves(
            scales,
            score_curves(errors, cov, scales),
            score_curves(errors - errors.mean(axis=0), cov, scales),
        )
    return SegmentCurves(nees(errors, cov), whiten(errors, cov), scores)


def running_mean(values: np.ndarray, window: int) -> np.ndarray:
    """The trailing mean of ``window`` consecutive values, one per full window
    (``len(values) - window + 1`` numbers; the i-th ends at ``values[i + window - 1]``),
    as ``pandas.Series(values).rolling(window).mean().dropna()``."""
    values = np.asarray(values, dtype=float)
    if not 1 <= window <= values.size:
        raise ValueError(f"window must be between 1 and {values.size}; got {window}")
    sums = np.cumsum(np.r_[0.0, values])
    return (sums[window:] - sums[:-window]) / window


def running_mean_bounds(dim: int, window: int, alpha: float, runs: int = 1) -> tuple[float, float]:
    r"""The two-sided 1 − α interval of the running mean of ``window`` epochs of NEES (or of
    the per-epoch average NEES over ``runs`` Monte Carlo runs) when the epochs are
    independent and the covariance is right:

    .. math:: \bar\epsilon_w \sim \chi^2_{w M d} / (w M)

    Errors correlated in time leave this interval more often than α even when credible."""
    dof = window * runs * dim
    return (
        float(special.chdtri(dof, 1 - alpha / 2)) / (window * runs),
        float(special.chdtri(dof, alpha / 2)) / (window * runs),
    )


def default_window(n: int) -> int:
    """The running mean's window when none is given: N/50 epochs, from 10 to 500 (never
    more than N)."""
    return max(1, min(n, max(10, min(500, n // 50))))
