"""A time offset between estimate and truth (issue 31, item 3).

An estimate stamped δ seconds late, x̂_k = x(t_k − δ), has errors e_k = x(t_k) − x(t_k − δ)
≈ δ·ẋ(t_k): a misfit proportional to the truth's velocity, which no covariance fixes. The
offset is estimated jointly with a constant bias μ by generalised least squares in the
claimed metric, e_k = μ + δ ẋ_k + ε_k with Cov ε_k = Σ̂_k, on the whitened errors
z_k = L_k⁻¹ e_k and velocities w_k = L_k⁻¹ ẋ_k (so that on a straight line at constant
speed, where a lag and a bias are the same data, δ has no precision and nothing is claimed).

Its standard error under the claim is (Σ_k w̃_kᵀ w̃_k)^{-1/2}, w̃ the velocities with their
GLS mean removed, inflated by √τ, τ the errors' largest variance ratio (their memory; the
velocity is smooth, so the regression sum averages over τ-epoch stretches as a mean does).
A lag **explains the misfit** when it is significant at :data:`OFFSET_LEVEL` (two-sided) and
removing it takes at least half of the excess of the NEES over its claim away: then the
finding comes first, before any covariance advice.
"""

from __future__ import annotations

import functools
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


def truth_velocity(truth: np.ndarray | None, time: np.ndarray | None) -> np.ndarray | None:
    """ẋ (N, d) by central differences in time (``np.gradient``; one-sided at the ends).

    Parameters
    ----------
    truth : numpy.ndarray or None, shape (N, d)
        The true states x(t_k).
    time : numpy.ndarray or None, shape (N,)
        The time stamps t_k.

    Returns
    -------
    numpy.ndarray or None
        The velocities (N, d) in the states' units per time unit; None without truth or
        time, with fewer than 3 epochs, or when a time stamp is not finite or the times
        do not strictly increase.
    """
    if truth is None or time is None or truth.shape[0] < 3:
        return None
    t = np.asarray(time, dtype=float)
    if not np.all(np.isfinite(t)) or np.any(np.diff(t) <= 0):
        return None
    return np.gradient(np.asarray(truth, dtype=float), t, axis=0)


@dataclass(frozen=True)
class Motion:
    """The truth of a log, or of a segment with one epoch beyond each end where the log has
    one, and its time stamps: what :meth:`velocity` differentiates, only where a segment's
    label names a misfit and a time offset is looked for (a log's velocities are N × d
    numbers, otherwise held for its whole diagnosis).

    Attributes
    ----------
    truth : numpy.ndarray, shape (M, d)
        The true states, floats.
    time : numpy.ndarray, shape (M,)
        Their time stamps, finite and increasing.
    first : int
        The row of ``truth`` that is the segment's first epoch (0 or 1).
    n : int
        The segment's epochs.
    step : float or None
        The log's time step where every step is the same (``np.gradient``'s uniform case,
        decided on the whole log), else None.
    known : numpy.ndarray or None
        The velocities themselves, for epochs that are not one slice of the log (then
        ``truth`` and ``time`` are empty).
    """

    truth: np.ndarray
    time: np.ndarray
    first: int
    n: int
    step: float | None
    known: np.ndarray | None = None

    def part(self, index) -> Motion:
        """The motion of the epochs ``index`` of this whole log's motion.

        Parameters
        ----------
        index : slice or numpy.ndarray
            A slice (step 1) of the log's epochs, or their indices.

        Returns
        -------
        Motion
            The slice with one epoch beyond each end where there is one; for indices that
            are not a slice, their velocities, taken from the whole log's.
        """
        if not isinstance(index, slice):
            empty = np.zeros(0)
            return Motion(empty, empty, 0, len(index), None, self._velocities[index])
        start, stop, _ = index.indices(self.n)
        low, high = max(start - 1, 0), min(stop + 1, self.n)
        return Motion(
            self.truth[low:high], self.time[low:high], start - low, stop - start, self.step
        )

    @functools.cached_property
    def _velocities(self) -> np.ndarray:
        return self.velocity()

    def velocity(self) -> np.ndarray:
        """ẋ at the segment's epochs: to the bit ``np.gradient`` of the whole log's truth
        at them (:func:`truth_velocity`), whose formula at an epoch reads only its two
        neighbours (central differences; one-sided at the log's ends), the uniform one
        where the whole log's steps are all equal.

        Returns
        -------
        numpy.ndarray, shape (n, d)
            The velocities.
        """
        if self.known is not None:
            return self.known
        f, last = self.truth, self.truth.shape[0] - 1
        rows = np.arange(self.first, self.first + self.n)
        out = np.empty((self.n, f.shape[1]))
        inner = (rows > 0) & (rows < last)
        k = rows[inner]
        if self.step is not None:
            out[inner] = (f[k + 1] - f[k - 1]) / (2.0 * self.step)
        else:
            dx = np.diff(self.time)
            dx1, dx2 = dx[k - 1][:, None], dx[k][:, None]
            a = -(dx2) / (dx1 * (dx1 + dx2))
            b = (dx2 - dx1) / (dx1 * dx2)
            c = dx1 / (dx2 * (dx1 + dx2))
            out[inner] = a * f[k - 1] + b * f[k] + c * f[k + 1]
        # the log's own ends: a part's extra epochs make every other end an inner epoch
        if self.n and rows[0] == 0:
            step = self.step if self.step is not None else self.time[1] - self.time[0]
            out[0] = (f[1] - f[0]) / step
        if self.n and rows[-1] == last:
            step = self.step if self.step is not None else self.time[-1] - self.time[-2]
            out[-1] = (f[-1] - f[-2]) / step
        return out


def motion(truth: np.ndarray | None, time: np.ndarray | None) -> Motion | None:
    """The whole log's :class:`Motion`, or None where :func:`truth_velocity` gives None
    (no truth or time, fewer than 3 epochs, time stamps not finite or not increasing).

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
