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
from credcli.errors import CredcliError

PROBE_CURVE_SCALES = (0.25, 4.0, 17)
"""The covariance scales of the score curves: geomspace(1/4, 4, 17), plus 1/c, 1 and c."""


def curve_scales(c: float) -> np.ndarray:
    """The scales at which the score curves are evaluated, with 1/c, 1 and c among them.

    Parameters
    ----------
    c : float
        The probe factor of Eq. (18).

    Returns
    -------
    numpy.ndarray
        geomspace(1/4, 4, 17) with 1/c, 1 and c added, sorted; a grid point within
        10⁻⁹ (relative) of an added scale gives way to it, so that no scale appears twice
        (geomspace's 2.0 is 2 less one unit in the last place).

    Examples
    --------
    >>> scales = curve_scales(3.0)
    >>> scales.size, float(scales[0]), float(scales[-1]), bool(np.isclose(scales, 1 / 3).any())
    (19, 0.25, 4.0, True)
    >>> curve_scales(2.0).size  # 1/2, 1 and 2 are on the grid already: 17 scales, each once
    17
    """
    probes = np.array([1.0 / c, 1.0, c])
    grid = np.geomspace(*PROBE_CURVE_SCALES)
    near = np.isclose(grid[:, None], probes[None, :], rtol=1e-9, atol=0.0).any(axis=1)
    return np.unique(np.r_[grid[~near], probes])


@dataclass(frozen=True)
class ScoreCurves:
    """Mean NLL and mean ES at each scale, of the errors as claimed and centred.

    Attributes
    ----------
    scales : numpy.ndarray
        The covariance scales s (``curve_scales``).
    claimed : tuple of numpy.ndarray
        (mean NLL, mean ES) at each scale, of the errors as given
        (``credcli.engine.metrics.score_curves``).
    centred : tuple of numpy.ndarray
        The same for the errors with their mean removed.
    """

    scales: np.ndarray
    claimed: tuple[np.ndarray, np.ndarray]
    centred: tuple[np.ndarray, np.ndarray]


@dataclass(frozen=True)
class SegmentCurves:
    """A segment's NEES, whitened errors and (for a segment with a verdict) score curves.

    Attributes
    ----------
    nees : numpy.ndarray
        The NEES per epoch (N,), Eq. (1).
    whitened : numpy.ndarray
        The whitened errors Σ̂_k^{-1/2} e_k (N, d) that the ELT flips, Eq. (12).
    scores : ScoreCurves or None
        The score curves; None for a segment without a verdict.
    """

    nees: np.ndarray
    whitened: np.ndarray
    scores: ScoreCurves | None = None


def segment_curves(errors: np.ndarray, cov: np.ndarray, c: float | None) -> SegmentCurves:
    """The curves of one segment.

    Parameters
    ----------
    errors : numpy.ndarray, shape (N, d)
        The errors e_k = x_k − x̂_k.
    cov : numpy.ndarray, shape (N, d, d)
        The claimed covariances Σ̂_k.
    c : float or None
        The probe factor the score curves are drawn around (``curve_scales``); None: no
        score curves (a segment without a verdict).

    Returns
    -------
    SegmentCurves
        The NEES, the whitened errors and, unless ``c`` is None, the score curves.

    Raises
    ------
    CredcliError
        If the arrays are malformed or a covariance is not positive definite (as
        ``credcli.engine.metrics.nees`` checks them).
    """
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
    """The trailing mean of ``window`` consecutive values, one per full window.

    As ``pandas.Series(values).rolling(window).mean().dropna()``, from one cumulative sum.

    Parameters
    ----------
    values : array_like, shape (N,)
        The series (the NEES of a segment, or the ANEES of Monte Carlo runs).
    window : int
        The number of consecutive values averaged, 1 <= window <= N.

    Returns
    -------
    numpy.ndarray, shape (N − window + 1,)
        The means; the i-th ends at ``values[i + window - 1]``.

    Raises
    ------
    CredcliError
        If ``window`` is not between 1 and N.

    Examples
    --------
    >>> running_mean(np.array([1.0, 2.0, 3.0, 6.0]), 2).tolist()
    [1.5, 2.5, 4.5]
    """
    values = np.asarray(values, dtype=float)
    if not 1 <= window <= values.size:
        raise CredcliError(
            f"a running mean's window must be between 1 and {values.size}; got {window}"
        )
    sums = np.cumsum(np.r_[0.0, values])
    return (sums[window:] - sums[:-window]) / window


def running_mean_bounds(dim: int, window: int, alpha: float, runs: int = 1) -> tuple[float, float]:
    r"""The two-sided 1 − α interval of the running mean of NEES under a right covariance.

    The running mean of ``window`` epochs of NEES (or of the per-epoch average NEES over
    ``runs`` Monte Carlo runs), when the epochs are independent and the covariance is
    right:

    .. math:: \bar\epsilon_w \sim \chi^2_{w M d} / (w M)

    Errors correlated in time leave this interval more often than α even when credible.

    Parameters
    ----------
    dim : int
        d, the state dimension.
    window : int
        w, the epochs per running mean.
    alpha : float
        α, the two-sided level.
    runs : int
        M, the Monte Carlo runs averaged at each epoch (default 1).

    Returns
    -------
    lower, upper : float
        χ²_{wMd}(α/2)/(wM) and χ²_{wMd}(1 − α/2)/(wM).

    Examples
    --------
    >>> low, high = running_mean_bounds(2, 50, 0.05)
    >>> round(low, 3), round(high, 3)  # about d = 2, the mean NEES
    (1.484, 2.591)
    """
    dof = window * runs * dim
    return (
        float(special.chdtri(dof, 1 - alpha / 2)) / (window * runs),
        float(special.chdtri(dof, alpha / 2)) / (window * runs),
    )


def default_window(n: int) -> int:
    """The running mean's window when none is given.

    Parameters
    ----------
    n : int
        N, the epochs of the series.

    Returns
    -------
    int
        N // 50 epochs, at least 10 and at most 500, but never more than N (and at
        least 1).
    """
    return max(1, min(n, max(10, min(500, n // 50))))
