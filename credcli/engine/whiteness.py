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

from credcli.errors import CredcliError

MAX_LAGS = 10


@dataclass(frozen=True)
class Whiteness:
    """The portmanteau test of one segment's whitened innovations.

    Attributes
    ----------
    statistic : float
        Hosking's Q_h (module docstring).
    pvalue : float
        P(χ²_dof >= Q_h).
    lags : int
        h, the number of lags summed.
    dof : int
        m²h, the degrees of freedom of the χ² reference.
    level : float
        The test's share of α (``innovation_levels``); NaN when none was set, and then
        ``rejected`` is False.
    """

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
    """The levels of the two questions and of the whiteness test, for innovations.

    Under a right filter the innovations are white (Mehra 1970), so whiteness is a third
    question of the same segment. Šidák's split gives each of the three tests the same
    share, 1 − (1 − α)^{1/3}: the two questions together 1 − (1 − α)^{2/3}, whiteness the
    rest, and a right filter is flagged at most α in all.

    Parameters
    ----------
    alpha : float
        α, the overall false-alarm level of the segment, in (0, 1).

    Returns
    -------
    pair : float
        1 − (1 − α)^{2/3}, the level left to the scale and location questions.
    each : float
        1 − (1 − α)^{1/3}, α_W of the whiteness test.

    Examples
    --------
    >>> pair, each = innovation_levels(0.05)
    >>> round(pair, 5), round(each, 5), round(1 - (1 - pair) * (1 - each), 12)
    (0.03362, 0.01695, 0.05)
    """
    each = -math.expm1(math.log1p(-alpha) / 3.0)
    pair = -math.expm1(2.0 * math.log1p(-alpha) / 3.0)
    return pair, each


def default_lags(n: int) -> int:
    """The default number of lags: h = min(10, n // 5), at least 1.

    Parameters
    ----------
    n : int
        Epochs of innovations.

    Returns
    -------
    int
        h (Hyndman and Athanasopoulos' rule for non-seasonal data).
    """
    return max(1, min(MAX_LAGS, n // 5))


def portmanteau(whitened: np.ndarray, lags: int | None = None) -> Whiteness:
    r"""Hosking's Q_h of whitened innovations; see the module docstring.

    Parameters
    ----------
    whitened : numpy.ndarray, shape (n, m)
        The innovations whitened by their claimed covariances, w_k = L_k⁻¹ ν_k; they are
        centred here.
    lags : int or None
        h, the number of lags (default ``default_lags(n)``).

    Returns
    -------
    Whiteness
        Q_h, its p-value against χ² with m²h degrees of freedom, h and m²h; ``level`` is
        left NaN for the caller to set.

    Raises
    ------
    CredcliError
        If ``lags`` is not between 1 and n − 1.

    Notes
    -----
    .. math:: Q_h = n^2 \sum_{k=1}^{h} \frac{1}{n-k}
              \operatorname{tr}(\hat C_k^\top \hat C_0^{-1} \hat C_k \hat C_0^{-1})

    Ĉ_0 must be invertible (numpy raises ``LinAlgError`` otherwise).

    References
    ----------
    J. R. M. Hosking, "The multivariate portmanteau statistic", JASA 75(371), 1980,
    Eq. (2.5).

    Examples
    --------
    >>> w = np.random.default_rng(0).standard_normal((500, 2))
    >>> test = portmanteau(w)
    >>> test.lags, test.dof, bool(test.pvalue > 0.01)
    (10, 40, True)
    """
    w = np.asarray(whitened, dtype=float)
    n, m = w.shape
    h = default_lags(n) if lags is None else int(lags)
    if not 1 <= h < n:
        raise CredcliError(f"lags must be between 1 and n − 1 = {n - 1}; got {h}")
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
