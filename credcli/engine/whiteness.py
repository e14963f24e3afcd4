"""Whiteness of a filter's innovations: a portmanteau test on the whitened innovations.

A consistent Kalman filter's innovations ν_k are zero-mean, have covariance S_k and are
white (Bar-Shalom, Li and Kirubarajan, *Estimation with Applications to Tracking and
Navigation*, 2001, Sec. 5.4). Whitened by the Cholesky factor of the claimed S_k,
w_k = L_k⁻¹ ν_k, they are then i.i.d. N(0, I_m), and serial correlation in them is
evidence of an inconsistent filter even where the NIS level looks right.

The statistic is Hosking's (1980, JASA 75(371), Eq. (2.5)) multivariate portmanteau, the
multivariate form of Ljung and Box's (1978, Biometrika 65(2)):

    Q_h = n² Σ_{k=1}^{h} (n − k)⁻¹ tr(Ĉ_kᵀ Ĉ_0⁻¹ Ĉ_k Ĉ_0⁻¹),   Ĉ_k = n⁻¹ Σ_t w̃_t w̃_{t−k}ᵀ

with w̃ the centred whitened innovations, referred to χ² with m²h degrees of freedom. For
m = 1 it is Ljung–Box's statistic times n/(n + 2). The number of lags is
h = min(10, ⌊n/5⌋) (Hyndman and Athanasopoulos, *Forecasting: Principles and Practice*,
3rd ed., Sec. 5.4, for non-seasonal data).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import special

MAX_LAGS = 10


@dataclass(frozen=True)
class Whiteness:
    """The portmanteau test of one segment's whitened innovations."""

    statistic: float
    pvalue: float
    lags: int
    dof: int
    level: float = float("nan")  # its share of α (:func:`innovation_levels`); NaN: none

    @property
    def rejected(self) -> bool:
        """Whether the innovations are correlated in time at :attr:`level`."""
        return bool(self.pvalue < self.level)


def innovation_levels(alpha: float) -> tuple[float, float]:
    """(α of the two questions, α_W of the whiteness test) for innovations: under a right
    filter the innovations are white (Mehra 1970), so whiteness is a third question of the
    same segment. Šidák's split gives each of the three tests the same share,
    1 − (1 − α)^{1/3}: the two questions together 1 − (1 − α)^{2/3}, whiteness the rest,
    and a right filter is flagged at most α in all."""
    each = -math.expm1(math.log1p(-alpha) / 3.0)
    pair = -math.expm1(2.0 * math.log1p(-alpha) / 3.0)
    return pair, each


def default_lags(n: int) -> int:
    """h = min(10, n // 5), at least 1."""
    return max(1, min(MAX_LAGS, n // 5))


def portmanteau(whitened: np.ndarray, lags: int | None = None) -> Whiteness:
    """Hosking's Q_h of whitened innovations (n, m); see the module docstring."""
    w = np.asarray(whitened, dtype=float)
    n, m = w.shape
    h = default_lags(n) if lags is None else int(lags)
    if not 1 <= h < n:
        raise ValueError(f"lags must be between 1 and n - 1 = {n - 1}; got {h}")
    w = w - w.mean(axis=0)
    c0 = w.T @ w / n
    c0_inv = np.linalg.inv(c0)
    total = 0.0
    for k in range(1, h + 1):  # h <= 10 small matrix products, not a loop over epochs
        ck = w[k:].T @ w[:-k] / n
        total += float(np.trace(ck.T @ c0_inv @ ck @ c0_inv)) / (n - k)
    statistic = n * n * total
    dof = m * m * h
    return Whiteness(statistic, float(special.chdtrc(dof, statistic)), h, dof)
