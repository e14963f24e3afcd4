"""Serial dependence of whitened errors: long-run variances and sign-block lengths.

Filter and smoother errors are correlated in time, and heavy tails inflate the variance of
squared errors the same way. The calibrated rule needs two numbers from the data:

- the long-run variance Ω = Σ_h γ(h) of a series, for the reference distribution of the
  scale test (:mod:`credcli.engine.scale`);
- a block length L for the ELT's sign flips, long enough that flipping whole blocks keeps
  almost all of the variance of the statistic.

Long-run variance: Bartlett kernel after AR(1) prewhitening (Andrews & Monahan 1992,
Econometrica 60(4), Eq. (2.4)), with the Andrews (1991, Econometrica 59(3), Eqs. (5.1)–(5.3),
(6.4)) AR(1) plug-in bandwidth S = 1.1447 (α̂(1) T)^{1/3},
α̂(1) = 4ρ̂²/((1 − ρ̂)²(1 + ρ̂)²). The prewhitening coefficient is capped at ±0.999, so
that recolouring by 1/(1 − ρ̂)² stays bounded (τ̂ <= 1999). Andrews & Monahan cap it at
0.97, for near-unit-root regressors in samples of a few hundred; a filter's errors at 100 Hz
have lag-1 autocorrelations of 0.99 and more in samples of thousands, where the 0.97 cap
makes τ̂ far too small, and sign blocks and batches with it (figures in docs/measured.md).

Block length: with τ = Ω/γ(0), a sign flip of blocks of length L loses the covariance
across block boundaries, a fraction G/(L Ω) of the variance (G = 2 Σ_h h γ(h), the notation
of Politis & White 2004). For an AR(1) with τ = (1 + φ)/(1 − φ), G/Ω = (τ² − 1)/(2τ), so the
smallest L that loses at most a fraction ε is ⌈(τ² − 1)/(2τε)⌉. This is the AR(1) plug-in
of that criterion (Andrews' plug-in idea applied to Politis and White's bias term).
"""

from __future__ import annotations

import math

import numpy as np

from credcli.engine.units import power_of_two_unit
from credcli.errors import CredcliError

_BARTLETT_CONSTANT = 1.1447  # Andrews (1991), Eq. (6.4), Bartlett kernel
_MAX_PREWHITEN = 0.999  # cap on the AR(1) prewhitening coefficient (see above)
BLOCK_VARIANCE_LOSS = 0.1
"""ε: the largest fraction of the statistic's variance a block sign flip may lose."""


def _ratio(num: np.ndarray, den: np.ndarray, otherwise: float) -> np.ndarray:
    """num/den where den > 0, else ``otherwise`` (a column that does not vary)."""
    positive = den > 0
    return np.where(positive, num / np.where(positive, den, 1.0), otherwise)


def _lag1(x: np.ndarray) -> np.ndarray:
    """Least-squares AR(1) coefficient of each column of a centred (T, p) array."""
    num = np.einsum("tp,tp->p", x[1:], x[:-1])
    return _ratio(num, np.einsum("tp,tp->p", x[:-1], x[:-1]), 0.0)


def autocorrelation(x: np.ndarray, about_zero: bool = False) -> np.ndarray:
    """Lag-1 sample autocorrelation γ̂(1)/γ̂(0) of each column of x, after centring.

    Parameters
    ----------
    x : numpy.ndarray, shape (T,) or (T, p)
        The series, one per column (more axes are flattened into columns).
    about_zero : bool
        Σ x_k x_{k−1} / Σ x_k² without centring: the estimate under a null hypothesis of
        mean zero, which a slow excursion of the sample mean does not hide (default
        False).

    Returns
    -------
    numpy.ndarray, shape (p,)
        r̂₁ per column; 0 for a column that does not vary, and for T < 2.

    Examples
    --------
    An AR(1) with φ = 0.5; about zero, a mean of 3 reads as strong dependence:

    >>> from scipy.signal import lfilter
    >>> x = lfilter([1.0], [1.0, -0.5], np.random.default_rng(0).standard_normal(10_000))
    >>> round(float(autocorrelation(x)[0]), 1), round(float(autocorrelation(x + 3, True)[0]), 1)
    (0.5, 0.9)
    """
    x = np.asarray(x, dtype=float)
    x = x.reshape(x.shape[0], -1)
    x = x / power_of_two_unit(x, axis=0)  # exact; the squares cannot overflow
    if not about_zero:
        x -= x.mean(axis=0)  # in the quotient: no second N × p array
    if x.shape[0] < 2:
        return np.zeros(x.shape[1])
    g1 = np.einsum("tp,tp->p", x[1:], x[:-1])
    return _ratio(g1, np.einsum("tp,tp->p", x, x), 0.0)


def andrews_bandwidth(rho: np.ndarray, n: int) -> np.ndarray:
    r"""Andrews (1991) AR(1) plug-in bandwidth of the Bartlett kernel, per column.

    .. math:: S = 1.1447\,\big(\hat\alpha(1)\,T\big)^{1/3},\qquad
              \hat\alpha(1) = \frac{4\hat\rho^2}{(1-\hat\rho)^2(1+\hat\rho)^2}

    Parameters
    ----------
    rho : numpy.ndarray
        ρ̂, the lag-1 autocorrelation of each column (capped at ±0.999, as the
        prewhitening is).
    n : int
        T, the number of epochs.

    Returns
    -------
    numpy.ndarray
        S per column, in lags (a real number; 0 for ρ̂ = 0).

    References
    ----------
    D. W. K. Andrews, "Heteroskedasticity and autocorrelation consistent covariance
    matrix estimation", Econometrica 59(3), 1991, Eqs. (5.1)–(5.3), (6.4).
    """
    rho = np.clip(np.asarray(rho, dtype=float), -_MAX_PREWHITEN, _MAX_PREWHITEN)
    alpha1 = 4.0 * rho**2 / ((1.0 - rho) ** 2 * (1.0 + rho) ** 2)
    return _BARTLETT_CONSTANT * np.cbrt(alpha1 * n)


def long_run_variance(x: np.ndarray) -> np.ndarray:
    r"""Long-run variance Ω = Σ_h γ(h) of each column of x (T,) or (T, p).

    AR(1) prewhitening, Bartlett kernel with the Andrews plug-in bandwidth on the
    prewhitened residuals, then recolouring (Andrews & Monahan 1992):

    .. math::
        \hat\Omega = \frac{\hat\gamma_\varepsilon(0) + 2\sum_{j<S}(1 - j/S)\,
                     \hat\gamma_\varepsilon(j)}{(1-\hat\rho)^2},
        \qquad \varepsilon_t = x_t - \hat\rho x_{t-1}

    The loop runs over lags (at most S, of order T^{1/3}), vectorised over epochs.

    Parameters
    ----------
    x : numpy.ndarray, shape (T,) or (T, p)
        The series, one per column; centred here.

    Returns
    -------
    numpy.ndarray, shape (p,)
        Ω̂ per column, >= 0; the plain variance (about the mean) for T < 3.

    References
    ----------
    D. W. K. Andrews and J. C. Monahan, "An improved heteroskedasticity and
    autocorrelation consistent covariance matrix estimator", Econometrica 60(4), 1992,
    Eq. (2.4).

    Examples
    --------
    For white noise Ω is the variance:

    >>> x = np.random.default_rng(0).standard_normal(100_000)
    >>> round(float(long_run_variance(x)[0]), 1)
    1.0
    """
    x = np.asarray(x, dtype=float)
    x = x.reshape(x.shape[0], -1)
    n = x.shape[0]
    x = x - x.mean(axis=0)
    if n < 3:
        return np.einsum("tp,tp->p", x, x) / max(n, 1)
    rho = np.clip(_lag1(x), -_MAX_PREWHITEN, _MAX_PREWHITEN)
    resid = x[1:] - rho * x[:-1]
    m = resid.shape[0]
    bandwidth = andrews_bandwidth(_lag1(resid - resid.mean(axis=0)), m)
    omega = np.einsum("tp,tp->p", resid, resid) / m
    for lag in range(1, min(int(np.max(bandwidth)) + 1, m)):
        weight = np.clip(1.0 - lag / np.maximum(bandwidth, 1e-300), 0.0, None)
        if not np.any(weight > 0):
            break
        omega += 2.0 * weight * np.einsum("tp,tp->p", resid[lag:], resid[:-lag]) / m
    omega = np.maximum(omega, 0.0)
    return omega / (1.0 - rho) ** 2


def variance_ratio(x: np.ndarray) -> np.ndarray:
    """τ = Ω / γ(0) per column: 1 for independent epochs, (1 + φ)/(1 − φ) for an AR(1).

    Parameters
    ----------
    x : numpy.ndarray, shape (T,) or (T, p)
        The series, one per column (rescaled by a power of two first: exact, and the
        squares cannot overflow).

    Returns
    -------
    numpy.ndarray, shape (p,)
        τ̂ = ``long_run_variance(x)`` / the sample variance, per column; 1 for a column
        that does not vary.

    Examples
    --------
    >>> from scipy.signal import lfilter
    >>> x = lfilter([1.0], [1.0, -0.5], np.random.default_rng(0).standard_normal(100_000))
    >>> round(float(variance_ratio(x)[0]), 1)  # AR(1), φ = 0.5: τ = 3
    3.0
    """
    x = np.asarray(x, dtype=float)
    x = x.reshape(x.shape[0], -1)
    x = x / power_of_two_unit(x, axis=0)  # exact; the squares cannot overflow
    return _ratio(long_run_variance(x), x.var(axis=0), 1.0)


DEPENDENCE_LEVEL = 0.01
"""Level of the test for serial dependence that decides whether τ̂ is used at all."""

SCREENING_LEVEL = 0.2
"""Level at which weaker evidence of serial dependence still sends a segment to the
dependence-aware tests, where their batches fit (:func:`credcli.engine.dependence.serial_dependence`)."""


def serially_dependent(r1: np.ndarray, n: int, level: float = DEPENDENCE_LEVEL) -> bool:
    """Whether some of the lag-1 autocorrelations of ``n`` epochs is significant.

    Under independence √n·r̂₁ is asymptotically N(0, 1) (Bartlett 1946); the columns are
    tested two-sided at ``level`` with a Bonferroni split. On independent data τ̂ is
    noisy (at n = 25 its lag-1 coefficient has a standard error of 0.2), and using it
    would ask for sign blocks that are not needed; this gate keeps L = 1 there.

    Parameters
    ----------
    r1 : array_like
        The lag-1 autocorrelations r̂₁ of the columns (``autocorrelation``).
    n : int
        The number of epochs they were estimated from.
    level : float
        The overall two-sided level (default ``DEPENDENCE_LEVEL``, 1 %); each of the p
        columns is tested at ``level``/p.

    Returns
    -------
    bool
        True when some |r̂₁|·√n exceeds the normal quantile at 1 − ``level``/(2p); False
        for n < 3.

    Examples
    --------
    >>> serially_dependent([0.05, 0.3], 100), serially_dependent([0.05, 0.1], 100)
    (True, False)
    """
    from scipy import special

    r1 = np.atleast_1d(np.asarray(r1, dtype=float))
    if n < 3:
        return False
    z = float(special.ndtri(1.0 - level / (2 * r1.size)))
    return bool(np.any(np.abs(r1) * np.sqrt(n) > z))


def block_length(tau: np.ndarray | float, loss: float = BLOCK_VARIANCE_LOSS) -> int:
    """Smallest sign-block length that loses at most ``loss`` of the variance, AR(1) plug-in.

    L = max_i ⌈(τ_i² − 1)/(2 τ_i ε)⌉, and 1 when every τ_i <= 1.

    Parameters
    ----------
    tau : numpy.ndarray or float
        The variance ratios τ_i of the whitened components (non-finite ones are ignored).
    loss : float
        ε, the largest fraction of the statistic's variance the block flips may lose, in
        (0, 1) (default ``BLOCK_VARIANCE_LOSS``, 0.1).

    Returns
    -------
    int
        L >= 1, in epochs.

    Raises
    ------
    CredcliError
        If ``loss`` is not in (0, 1).

    Examples
    --------
    >>> block_length(19.0)  # AR(1) with φ = 0.9
    95
    >>> block_length(1.0)
    1
    """
    if not 0 < loss < 1:
        raise CredcliError(f"loss must be in (0, 1); got {loss}")
    tau = np.atleast_1d(np.asarray(tau, dtype=float))
    tau = np.maximum(tau[np.isfinite(tau)], 1.0) if tau.size else np.ones(1)
    if tau.size == 0:
        return 1
    need = (tau**2 - 1.0) / (2.0 * tau * loss)
    return max(1, math.ceil(float(np.max(need)) - 1e-9))


def ar1_variance_ratio(r1: np.ndarray, n: int) -> np.ndarray:
    r"""τ per column from the lag-1 autocorrelations of ``n`` epochs, bias-corrected, as
    an AR(1).

    The least-squares lag-1 coefficient of a short series with an estimated mean is biased
    towards 0 by about (1 + 3ρ)/T (Kendall 1954; Marriott & Pope 1954, Biometrika 41), so
    ρ̃ = ρ̂ + (1 + 3ρ̂)/T (capped as the prewhitening is) and τ = (1 + ρ̃)/(1 − ρ̃). Used
    with :func:`variance_ratio` as the larger of the two, for lengths of batches and sign
    blocks only: in a window of 50–120 epochs the kernel τ̂ is often far below the truth,
    and the windows where it happens to be low would be the ones decided, with false
    alarms well above the level on AR(1) errors (docs/measured.md has the table).

    Parameters
    ----------
    r1 : numpy.ndarray
        The lag-1 autocorrelations r̂₁ of the columns (``autocorrelation``).
    n : int
        T, the number of epochs they were estimated from.

    Returns
    -------
    numpy.ndarray
        τ = (1 + ρ̃)/(1 − ρ̃) per column, with ρ̃ clipped to [0, 0.999]: at least 1.

    Examples
    --------
    >>> x = np.random.default_rng(0).standard_normal(100_000)
    >>> round(float(ar1_variance_ratio(autocorrelation(x), x.size)[0]), 2)
    1.0
    """
    r1 = np.asarray(r1, dtype=float)
    rho = np.clip(r1 + (1.0 + 3.0 * r1) / max(n, 1), 0.0, _MAX_PREWHITEN)
    return (1.0 + rho) / (1.0 - rho)


def squared_variance_ratio(tau: np.ndarray) -> float:
    r"""τ of the squared series x² for a Gaussian AR(1) x with variance ratio τ, the largest
    over the columns: the autocorrelation of x² is φ^{2|h|} (Isserlis), so
    τ_{x²} = (1 + φ²)/(1 − φ²) with φ = (τ − 1)/(τ + 1).

    The squared errors of a short window estimate their own τ worse than the errors do (the
    sample mean of a skewed, slowly varying series absorbs most of its slow part); this is
    the floor the scale test's batch length takes from the errors.

    Parameters
    ----------
    tau : numpy.ndarray
        The variance ratios τ of the columns (values below 1 count as 1).

    Returns
    -------
    float
        The largest τ_{x²} over the columns, at least 1.

    Examples
    --------
    >>> round(squared_variance_ratio(np.array([19.0])), 2)  # φ = 0.9
    9.53
    """
    tau = np.maximum(np.asarray(tau, dtype=float), 1.0)
    phi = (tau - 1.0) / (tau + 1.0)
    return float(np.max((1.0 + phi**2) / (1.0 - phi**2)))
