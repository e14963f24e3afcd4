"""What a segment's NEES does in time: bursts where it leaves its χ² band for a run of
epochs, and a filter that diverges (issue 31, item 4). Findings reported beside the label,
and one dependence-free bound on the scale that lets a diverging filter be named
``optimism`` where the memory-adjusted tests cannot decide.

Three pieces, each with its reference:

- :func:`median_bound`: Markov's inequality on the share F of epochs whose NEES exceeds
  c. Under the claim every epoch's NEES is χ²_d whatever the dependence between epochs, so
  E F = P(χ²_d > c) and P(F >= ½) <= 2 P(χ²_d > c): a median NEES above the χ²_d quantile
  at 1 − α/4 rejects "the covariance is not too small" at α/2, with no model of the memory.
  It is applied to the GLS-centred NEES, whose marginal is stochastically smaller than
  χ²_d under the claim, so the bound stays valid after centring (it would not for the lower
  side: centring a window of slow errors removes their slow part).
- :func:`bursts`: Page's (1954, Biometrika 41) CUSUM of the NEES for a shift of the scale
  from 1 to κ₁ = :data:`BURST_FACTOR`, S_k = max(0, S_{k−1} + ℓ_k) with the log-likelihood
  ratio ℓ_k = −(d/2) ln κ₁ + (NEES_k/2)(1 − 1/κ₁) of χ²_d scaled by κ₁ against χ²_d. As
  E e^{ℓ} = 1 under the claim, each excursion of S reaches h with probability at most e^{−h}
  (Wald), and a segment of N independent epochs has a false burst with probability at most
  N e^{−h}; h = ln(N/:data:`BURST_LEVEL`). With serially dependent squared errors the
  increments are divided by the squares' variance ratio τ_q (a sum over τ_q epochs carries
  the information of one), so a slow wander of the NEES is not listed as bursts.
  Computed in one pass as S_k = W_k − min(0, min_{j<=k} W_j), W the cumulative sum of ℓ.
- :func:`divergence`: the median bound fires and the NEES keeps growing (the last quarter's
  median at least :data:`GROWTH` times the first's) or sits beyond any plausible tuning
  (:data:`IMPLAUSIBLE` times the χ²_d median); it started at the first block of epochs from
  which every block's median stays above the bound.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import special

BURST_FACTOR = 4.0
"""κ₁ of the CUSUM: a burst is a run of epochs whose NEES looks 4× its claim."""

BURST_LEVEL = 0.01
"""Per segment of independent epochs, the chance of listing a burst where there is none."""

MAX_BURSTS = 3
"""Bursts listed per segment (the largest first); the finding counts the rest."""

MAX_BURST_SHARE = 0.25
"""An excursion longer than this share of the segment is no burst: the segment's level,
which the scale test answers (or a divergence)."""

GROWTH = 10.0
IMPLAUSIBLE = 100.0


@dataclass(frozen=True)
class Burst:
    """A run of epochs whose NEES looks ``BURST_FACTOR`` times its claim.

    Attributes
    ----------
    start, stop : int
        Epochs ``start`` … ``stop`` − 1 of the segment (0-based), where the CUSUM rose
        from 0 to its peak.
    peak_nees : float
        The largest NEES among them.
    statistic : float
        The CUSUM's peak, against the threshold h = ln(N/``BURST_LEVEL``).
    """

    start: int
    stop: int
    peak_nees: float
    statistic: float  # the CUSUM's peak, against the threshold h

    def describe(self, dim: int) -> str:
        """The burst as one sentence for the report (epochs 1-based).

        Parameters
        ----------
        dim : int
            d, the state dimension: the NEES is compared with χ²_d's 99.9 % point.

        Returns
        -------
        str
            The epochs, their count and the peak NEES against χ²_d's 99.9 % point.
        """
        band = float(special.chdtri(dim, 0.001))
        return (
            f"burst: epochs {self.start + 1}–{self.stop} of the segment ({self.stop - self.start} "
            f"epochs), NEES up to {self.peak_nees:.3g} against {band:.3g}, χ²_{dim}'s 99.9 % "
            "point: a fault or an unmodelled event there, whatever the segment's label"
        )


@dataclass(frozen=True)
class Divergence:
    """A filter whose errors grow beyond its covariance.

    Attributes
    ----------
    start : int
        The epoch (0-based) from which every block's median NEES is above the bound
        (``median_bound``).
    first_median, last_median : float
        The median NEES of the segment's first and last quarters.
    """

    start: int
    first_median: float
    last_median: float

    def describe(self) -> str:
        """The divergence as one sentence for the report (epochs 1-based).

        Returns
        -------
        str
            The first and last quarters' median NEES, the epoch it started from, and the
            advice to fix the filter before its covariance.
        """
        return (
            f"diverging: the median NEES goes from {self.first_median:.3g} in the first "
            f"quarter to {self.last_median:.3g} in the last, beyond any plausible tuning from "
            f"epoch {self.start + 1} of the segment on; fix the filter (linearisation, "
            "observability, numerical conditioning) before its covariance"
        )


def median_bound(dim: int, level: float) -> float:
    """c with 2 P(χ²_d > c) = ``level``/2: a median NEES above it rejects at ``level``/2.

    Markov's inequality on the share of epochs whose NEES exceeds c (module docstring):
    valid whatever the dependence between epochs.

    Parameters
    ----------
    dim : int
        d, the state dimension.
    level : float
        The level; the bound rejects "the covariance is not too small" at ``level``/2.

    Returns
    -------
    float
        c, the χ²_d quantile at 1 − ``level``/4.

    Examples
    --------
    >>> round(median_bound(2, 0.05), 2)  # χ²_2 at 0.9875
    8.76
    """
    return float(special.chdtri(dim, level / 4.0))


def bursts(eps: np.ndarray, dim: int, squares_ratio: float = 1.0) -> tuple[Burst, ...]:
    """The NEES bursts of a segment, the largest first, by Page's CUSUM (module docstring).

    Parameters
    ----------
    eps : numpy.ndarray, shape (N,)
        The segment's NEES per epoch.
    dim : int
        d, the state dimension.
    squares_ratio : float
        τ_q, the variance ratio of the squared errors; the CUSUM's increments are divided
        by max(τ_q, 1) (default 1: independent epochs).

    Returns
    -------
    tuple of Burst
        Every excursion of the CUSUM above h = ln(N/``BURST_LEVEL``) whose rise lasts at
        most ``MAX_BURST_SHARE`` of the segment, ordered by their peaks, largest first;
        empty with fewer than 2 epochs. The caller lists at most ``MAX_BURSTS``.

    Examples
    --------
    >>> eps = np.random.default_rng(0).chisquare(2, 1000)
    >>> eps[500:520] *= 20.0  # twenty epochs of errors 4.5 times too large
    >>> [(b.start, b.stop) for b in bursts(eps, 2)]  # up to the CUSUM's peak
    [(500, 519)]
    """
    n = eps.size
    if n < 2:
        return ()
    k1 = BURST_FACTOR
    step = (-0.5 * dim * math.log(k1) + 0.5 * (1.0 - 1.0 / k1) * eps) / max(squares_ratio, 1.0)
    # the walk, its running floor and S made in two arrays of N (a segment of millions of
    # epochs holds little else at this point)
    walk = np.cumsum(step, out=step)
    floor = np.minimum.accumulate(walk)
    np.minimum(floor, 0.0, out=floor)
    s = np.subtract(walk, floor, out=walk)
    del floor
    h = math.log(n / BURST_LEVEL)
    above = s > h
    if not above.any():
        return ()
    # an excursion: from the epoch after S was last 0 to the epoch where it peaks
    zero = s <= 0.0
    found = []
    k = 0
    while True:
        hits = np.flatnonzero(above[k:])
        if not hits.size:
            break
        hit = k + int(hits[0])
        zeros_before = np.flatnonzero(zero[:hit])
        start = int(zeros_before[-1]) + 1 if zeros_before.size else 0
        after = np.flatnonzero(zero[hit:])
        end = hit + int(after[0]) if after.size else n
        peak = start + int(np.argmax(s[start:end]))
        if peak + 1 - start <= n * MAX_BURST_SHARE:
            found.append(Burst(start, peak + 1, float(eps[start : peak + 1].max()), float(s[peak])))
        k = end
    return tuple(sorted(found, key=lambda b: -b.statistic))


def divergence(q_median: float, eps: np.ndarray, dim: int, level: float) -> Divergence | None:
    """The segment's divergence (module docstring), or None.

    Parameters
    ----------
    q_median : float
        The median of the GLS-centred NEES, which the median bound is applied to.
    eps : numpy.ndarray, shape (N,)
        The segment's NEES per epoch.
    dim : int
        d, the state dimension.
    level : float
        The level of the median bound (``median_bound``).

    Returns
    -------
    Divergence or None
        The divergence when ``q_median`` is above the median bound and the NEES grows
        (the last quarter's median at least ``GROWTH`` times the first's) or sits beyond
        any tuning (its median at least ``IMPLAUSIBLE`` times χ²_d's); it starts at the
        first block of max(4, N // 20) epochs from which every block's median is above the
        bound. None otherwise, with fewer than 8 epochs, or when the last block is back
        within the bound.
    """
    n = eps.size
    if n < 8 or not q_median > median_bound(dim, level):
        return None
    quarter = n // 4
    first, last = float(np.median(eps[:quarter])), float(np.median(eps[-quarter:]))
    typical = float(special.chdtri(dim, 0.5))
    if not (last >= GROWTH * first or float(np.median(eps)) >= IMPLAUSIBLE * typical):
        return None
    bound = median_bound(dim, level)
    size = max(4, n // 20)
    starts = np.arange(0, n, size)
    medians = np.array([np.median(eps[a : a + size]) for a in starts])  # ≤ 21 blocks
    below = np.flatnonzero(medians <= bound)
    begin = int(starts[below[-1] + 1]) if below.size and below[-1] + 1 < starts.size else 0
    if below.size and below[-1] + 1 >= starts.size:
        return None  # the last block is back within the bound: not diverging
    return Divergence(begin, first, last)
