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
        The truth's velocity ẋ_k (``truth_velocity``).
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
