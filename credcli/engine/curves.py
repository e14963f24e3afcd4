"""The numbers behind a segment's figures: NEES per epoch (Eq. (4)), the whitened errors
the ELT flips (Eq. (12)), and the mean NLL and energy score against a scale of the claimed
covariance (Eqs. (7), (10); Fig. 1), for the claimed errors and for the errors with their
mean removed. The plots draw these; they compute nothing."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

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
