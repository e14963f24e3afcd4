"""A time offset between estimate and truth (issue 31, item 3).

An estimate stamped δ seconds late, x̂_k = x(t_k − δ), has errors e_k = x(t_k) − x(t_k − δ)
≈ δ·ẋ(t_k): a misfit proportional to the truth's velocity, which no covariance fixes. The
offset is estimated jointly with a constant bias μ by generalised least squares in the
claimed metric, e_k = μ + δ ẋ_k + ε_k with Cov ε_k = Σ̂_k, on the whitened errors
z_k = Σ̂_k^{-1/2} e_k and velocities w_k = Σ̂_k^{-1/2} ẋ_k (so that on a straight line at constant
speed, where a lag and a bias are the same data, δ has no precision and nothing is claimed).

Its standard error under the claim is (Σ_k w̃_kᵀ w̃_k)^{-1/2}, w̃ the velocities with their
GLS mean removed, inflated by √τ, τ the errors' largest variance ratio (their memory; the
velocity is smooth, so the regression sum averages over τ-epoch stretches as a mean does).
A lag **explains the misfit** when it is significant at :data:`OFFSET_LEVEL` (two-sided) and
removing it takes at least half of the excess of the NEES over its claim away: then the
finding comes first, before any covariance advice.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import special

from credcli.engine.linalg import inverse_sqrt

OFFSET_LEVEL = 0.001
"""Two-sided level of the offset's significance: a finding that reorders the advice."""

EXPLAINED_SHARE = 0.5
"""The share of the NEES's excess over its claim that removing the offset must remove."""


@dataclass(frozen=True)
class TimeOffset:
    """A time offset that explains a segment's misfit (module docstring).

    Attributes
    ----------
    seconds : float
        δ̂ in the time column's unit: positive when the estimate lags the truth.
    stderr : float
        Its standard error under the claim, inflated by √τ for the errors' memory.
    kappa_before, kappa_after : float
        κ̂, the scale of the centred NEES, before and after removing the offset.
    """

    seconds: float
    stderr: float
    kappa_before: float
    kappa_after: float

    def describe(self) -> str:
        """The finding as one sentence for the report.

        Returns
        -------
        str
            Which way and by how much the estimate is offset, κ̂ before and after, and the
            advice to fix the time stamps before the covariance.
        """
        which = "lags" if self.seconds > 0 else "leads"
        return (
            f"time offset: the estimate {which} the truth by {abs(self.seconds):.3g} s "
            f"(± {self.stderr:.2g}); without it κ̂ goes from {self.kappa_before:.3g} to "
            f"{self.kappa_after:.3g}: fix the time stamps before the covariance"
        )


@dataclass(frozen=True, eq=False)
class Motion:
    """The truth of a log, or of one contiguous stretch of its epochs with one epoch beyond
    each end where the log has one, and its time stamps: what :meth:`velocity`
    differentiates, only where a segment's label names a misfit and a time offset is looked
    for (the velocities of a whole log are N × d numbers held for its whole diagnosis
    otherwise).

    The velocity is ``np.gradient(truth, time, axis=0)`` of the whole log (central
    differences; one-sided at the log's ends) at the stretch's epochs, to the bit: each
    epoch's value reads only its two neighbours, and the formula is numpy's uniform one
    where every step of the whole log is equal (numpy decides that on the array it is
    given, which a stretch could not tell).

    Attributes
    ----------
    truth : numpy.ndarray, shape (M, d)
        The true states, floats.
    time : numpy.ndarray, shape (M,)
        Their time stamps, finite and increasing.
    first : int
        The row of ``truth`` that is the stretch's first epoch (0 for a whole log; 1 where
        the log has an epoch before the stretch).
    n : int
        The stretch's epochs.
    step : float or None
        The whole log's time step where every step is the same, else None.
    """

    truth: np.ndarray
    time: np.ndarray
    first: int
    n: int
    step: float | None

    @property
    def whole(self) -> bool:
        """Whether this is a whole log's motion (what :meth:`part` cuts from)."""
        return self.first == 0 and self.n == self.truth.shape[0]

    def part(self, index: slice | np.ndarray) -> Motion | np.ndarray:
        """The motion of some of this whole log's epochs.

        Parameters
        ----------
        index : slice or numpy.ndarray of int
            A slice of the epochs (step 1), or the epochs' indices.

        Returns
        -------
        Motion or numpy.ndarray
            For a slice, its :class:`Motion` (views of this one's arrays, one epoch
            beyond each end where there is one); for indices, their velocities, taken now
            (an interleaved segment's epochs are no stretch of the log).
        """
        if not self.whole:
            raise ValueError("Motion.part cuts from a whole log's motion")
        if not isinstance(index, slice):
            index = np.asarray(index, dtype=np.intp)
            return _velocities(self.truth, self.time, self.step, index)
        start, stop, stride = index.indices(self.n)
        if stride != 1:
            raise ValueError("Motion.part takes a slice of step 1")
        low, high = max(start - 1, 0), min(stop + 1, self.n)
        return Motion(
            self.truth[low:high], self.time[low:high], start - low, stop - start, self.step
        )

    def velocity(self) -> np.ndarray:
        """ẋ at the stretch's epochs (the class docstring says how).

        Returns
        -------
        numpy.ndarray, shape (n, d)
            The velocities.
        """
        return _velocities(self.truth, self.time, self.step, slice(self.first, self.first + self.n))


def _velocities(f: np.ndarray, t: np.ndarray, step: float | None, rows) -> np.ndarray:
    """``np.gradient(f, t, axis=0)[rows]`` where ``f`` and ``t`` hold every neighbour of
    ``rows`` and their first and last rows are the log's ends: numpy's operations, in its
    order, on the rows asked for only (a slice reads views, indices copy n rows)."""
    last = f.shape[0] - 1
    if isinstance(rows, slice):
        at = np.arange(rows.start, rows.stop)
        lo, hi = max(rows.start, 1), min(rows.stop, last)  # the inner stretch
        inner = slice(lo - rows.start, max(hi - rows.start, 0))
        before, here, after = slice(lo - 1, hi - 1), slice(lo, hi), slice(lo + 1, hi + 1)
    else:
        at = rows
        keep = (rows > 0) & (rows < last)
        inner = np.flatnonzero(keep)
        here = rows[keep]
        before, after = here - 1, here + 1
    out = np.empty((at.size, f.shape[1]))
    if step is not None:  # numpy's uniform formula
        out[inner] = (f[after] - f[before]) / (2.0 * step)
    else:
        dx1 = (t[here] - t[before])[:, None]
        dx2 = (t[after] - t[here])[:, None]
        a = -(dx2) / (dx1 * (dx1 + dx2))
        b = (dx2 - dx1) / (dx1 * dx2)
        c = dx1 / (dx2 * (dx1 + dx2))
        out[inner] = a * f[before] + b * f[here] + c * f[after]
    for k in np.flatnonzero(at == 0):  # the log's first epoch: one-sided
        out[k] = (f[1] - f[0]) / (step if step is not None else t[1] - t[0])
    for k in np.flatnonzero(at == last):  # and its last
        out[k] = (f[-1] - f[-2]) / (step if step is not None else t[-1] - t[-2])
    return out


def motion(truth: np.ndarray | None, time: np.ndarray | None) -> Motion | None:
    """The whole log's :class:`Motion`, or None where the velocity is not defined: no truth
    or time, fewer than 3 epochs, time stamps not finite or not increasing.

    Parameters
    ----------
    truth : numpy.ndarray or None, shape (N, d)
        The true states x(t_k).
    time : numpy.ndarray or None, shape (N,)
        The time stamps t_k.

    Returns
    -------
    Motion or None
        Holding the arrays themselves (no copy of float arrays).
    """
    if truth is None or time is None or truth.shape[0] < 3:
        return None
    t = np.asarray(time, dtype=float)
    if not np.all(np.isfinite(t)):
        return None
    dx = np.diff(t)
    if np.any(dx <= 0):
        return None
    step = float(dx[0]) if bool((dx == dx[0]).all()) else None
    return Motion(np.asarray(truth, dtype=float), t, 0, truth.shape[0], step)


def time_offset(
    errors: np.ndarray, cov: np.ndarray, velocity: np.ndarray, memory_ratio: float = 1.0
) -> TimeOffset | None:
    """The offset that explains a segment's misfit (module docstring), or None.

    Parameters
    ----------
    errors : numpy.ndarray, shape (N, d)
        The errors e_k.
    cov : numpy.ndarray, shape (N, d, d)
        The claimed covariances Σ̂_k, positive definite; the errors and velocities are
        whitened by their symmetric inverse square roots.
    velocity : numpy.ndarray, shape (N, d)
        The truth's velocity ẋ_k (:meth:`Motion.velocity`).
    memory_ratio : float
        τ, the errors' largest variance ratio; the standard error is inflated by
        √max(τ, 1) (default 1: independent epochs).

    Returns
    -------
    TimeOffset or None
        The offset; None with fewer than d + 3 epochs, when the velocity carries no
        information apart from a constant bias (constant velocity), when δ̂ is not
        significant at ``OFFSET_LEVEL`` (two-sided), when κ̂ before is at most 1, or
        when removing the offset takes less than ``EXPLAINED_SHARE`` of the excess
        κ̂ − 1 away.
    """
    n, d = errors.shape
    if n < d + 3:
        return None
    # Σ̂_k^{-1/2}, the symmetric root (as :func:`credcli.engine.elt.whiten` takes it): the
    # constant's whitened regressors, and what whitens the errors and the velocities
    roots = inverse_sqrt(cov)  # (N, d, d)
    z = np.einsum("nij,nj->ni", roots, errors)
    w = np.einsum("nij,nj->ni", roots, velocity)
    # GLS of z_k = R_k μ + w_k δ: the normal equations in (μ, δ)
    a_mm = np.einsum("nji,njk->ik", roots, roots)
    a_md = np.einsum("nji,nj->i", roots, w)
    a_dd = float(np.einsum("nj,nj->", w, w))
    b_m = np.einsum("nji,nj->i", roots, z)
    b_d = float(np.einsum("nj,nj->", w, z))
    mu0 = np.linalg.solve(a_mm, b_m)
    info = a_dd - a_md @ np.linalg.solve(a_mm, a_md)  # Σ w̃ᵀw̃, μ profiled out
    if not info > 1e-12 * max(a_dd, 1e-300):
        return None  # constant velocity: a lag is a bias
    delta = (b_d - a_md @ mu0) / info
    stderr = math.sqrt(max(memory_ratio, 1.0) / info)
    if abs(delta) / stderr < float(special.ndtri(1.0 - OFFSET_LEVEL / 2.0)):
        return None
    mu1 = mu0 - np.linalg.solve(a_mm, a_md) * delta
    before = z - np.einsum("nij,j->ni", roots, mu0)
    after = z - np.einsum("nij,j->ni", roots, mu1) - w * delta
    dof = (n - 1) * d
    kappa0 = float(np.einsum("nj,nj->", before, before)) / dof
    kappa1 = float(np.einsum("nj,nj->", after, after)) / max(dof - 1, 1)
    if kappa0 <= 1.0 or kappa0 - kappa1 < EXPLAINED_SHARE * (kappa0 - 1.0):
        return None
    return TimeOffset(float(delta), stderr, kappa0, kappa1)
