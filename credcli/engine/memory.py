r"""The memory of a segment's errors: an autoregressive sieve with its order chosen by AICc,
and what it implies for every test of the calibrated rule.

Filter and smoother errors are not AR(1): a filter integrating white noise at a high rate
gives smooth errors (lag-1 autocorrelation near 1 that decorrelate within tens of epochs),
and a slow component under a fast one hides in the lag-1 autocorrelation of the sum. One lag
cannot tell these apart; a sieve can. Berk (1974, Ann. Stat. 2(3)) shows that an AR(p) fitted
with p growing with N estimates the spectral density at frequency zero (so the long-run
variance Ω) consistently for general linear stationary processes, with

.. math:: \hat\Omega = \frac{\hat\sigma^2}{\hat A(1)^2},\qquad
          \hat A(1) = 1 - \sum_{j=1}^{p}\hat\phi_j .

The fit is Burg's (1968) maximum-entropy recursion: it keeps every root inside the unit
circle however close the process is to a unit root, where Yule–Walker estimates are biased
towards white noise (Tjøstheim & Paulsen 1983, Biometrika 70(2)). The order is the one of
the corrected AIC (Hurvich & Tsai 1989, Biometrika 76(2)) among p = 0 … p_max, with
p_max = ⌈12 (N/100)^{1/4}⌉ (Schwert 1989), at most N/4.

From the fitted model the exact finite-sample moments follow (:class:`SeriesMemory`):
the variance of a window mean, the mean and variance of a window's centred sum of squares
(Gaussian quadratic forms, Cochran/Isserlis), the variance lost by sign blocks of length L,
and the covariance of the GLS mean for claimed covariances that change from epoch to
epoch. The model's own estimation error is carried into the critical values by a
parametric bootstrap of the fitted model (:func:`bootstrap_spread`: 40 series drawn from
it and refitted as the data were, order selection included), expressed as the degrees of
freedom ν = 2/Var(log τ̂*) of a χ²-distributed variance estimate (and likewise for
τ₂ = Σρ², to which the scale test's variance is proportional); the bootstrap's bias towards
less memory is corrected. A statistic studentized by the model is referred to Student's t
(or F) with those degrees of freedom instead of the normal (or χ²).

Memory differs between directions (a slow heading error beside a fast position error), so
the whitened errors are modelled per principal direction of their long-run covariance
(:func:`fit_memory`).
"""

from __future__ import annotations

import functools
import math
import sys
from dataclasses import dataclass, replace

import numpy as np
from scipy import special
from scipy.linalg import lapack

from credcli.engine import compiled
from credcli.engine.linalg import epoch_chunks
from credcli.engine.units import power_of_two_unit

MAX_ORDER_CAP = 60
"""The largest AR order ever fitted (a 60-lag sieve already follows smooth 100 Hz errors)."""
NEGLIGIBLE = 1e-9
"""An autocorrelation below this (relative) is zero for the sums over lags."""
MAX_HORIZON = 1 << 20
"""The longest lag kept in a model's autocorrelation function."""


def max_order(n: int) -> int:
    """The sieve's largest AR order for a series of ``n`` epochs.

    Parameters
    ----------
    n : int
        Epochs N of the series (of one run, when runs are pooled).

    Returns
    -------
    int
        p_max = ⌈12 (N/100)^{1/4}⌉ (Schwert 1989), at most N/4 and :data:`MAX_ORDER_CAP`,
        and at least 0.

    Examples
    --------
    >>> max_order(100), max_order(10_000), max_order(10), max_order(10**7)
    (12, 38, 2, 60)
    """
    return int(max(0, min(MAX_ORDER_CAP, n // 4, math.ceil(12.0 * (n / 100.0) ** 0.25))))


def aicc_penalty(parameters, epochs):
    """AICc's charge for ``parameters`` estimated from ``epochs``: 2kT/(T − k − 1), the
    denominator at least 1 (Hurvich & Tsai 1989).

    Parameters
    ----------
    parameters : int or numpy.ndarray of int
        k.
    epochs : int
        T.

    Returns
    -------
    float or numpy.ndarray
        The charge, in the shape of ``parameters``.

    Examples
    --------
    >>> float(aicc_penalty(2, 100))
    4.123711340206185
    """
    return 2.0 * parameters * epochs / np.maximum(epochs - parameters - 1, 1)


def mean_variance_ratio(rho: np.ndarray) -> float:
    """v_n = n·Var(x̄_n)/γ(0) = 1 + 2 Σ_{0<h<n} (1 − h/n) ρ(h) of a window of n epochs.

    Parameters
    ----------
    rho : numpy.ndarray, shape (n,)
        The autocorrelation ρ(0) … ρ(n − 1) over the window.

    Returns
    -------
    float
        v_n, not floored (an antipersistent model gives less than 1).

    Examples
    --------
    >>> mean_variance_ratio(np.array([1.0, 0.5, 0.0, 0.0]))
    1.75
    """
    n = rho.size
    h = np.arange(1, n)
    return float(1.0 + 2.0 * np.sum((1.0 - h / n) * rho[1:]))


@dataclass(frozen=True)
class BurgFit:
    """Burg's recursion on k series, each pooled over m equal segments of T epochs.

    Made by :func:`burg`; every array is indexed by series first, then by order.

    Attributes
    ----------
    reflection : numpy.ndarray, shape (k, p_max)
        The reflection coefficients κ_1 … κ_{p_max} of each series.
    variance : numpy.ndarray, shape (k, p_max + 1)
        The innovation variance σ²_p of each series at orders p = 0 … p_max (σ²_0 is the
        series' mean square; floored at the smallest positive float).
    epochs : int
        m·T, the epochs behind each fit.
    segments : int
        m, the segments pooled into each fit.
    """

    reflection: np.ndarray
    variance: np.ndarray
    epochs: int  # m·T, the epochs behind each fit
    segments: int

    def aicc(self, extra: int = 0) -> np.ndarray:
        """The corrected AIC (Hurvich & Tsai 1989) of each order.

        Parameters
        ----------
        extra : int, default 0
            Parameters of the model beside the p coefficients and the innovation variance
            (a fractional order, :mod:`credcli.engine.longmemory`).

        Returns
        -------
        numpy.ndarray, shape (k, p_max + 1)
            AICc(p) = T log σ²_p + :func:`aicc_penalty` (p + 1 + extra, T) per series and
            order p, with T = :attr:`epochs`.
        """
        t = self.epochs
        p = np.arange(self.variance.shape[1])
        with np.errstate(divide="ignore"):
            log_var = np.log(self.variance)
        return t * log_var + aicc_penalty(p + 1 + extra, t)

    def bic(self) -> np.ndarray:
        """Schwarz's criterion of each order, BIC(p) = T log σ²_p + p log T (Schwarz
        1978; the innovation variance, a parameter of every order, left out).

        Consistent where AICc is not: on a series without memory its order 0 is chosen
        with probability tending to 1, and any fixed memory is found with probability
        tending to 1 (Hannan & Quinn 1979), where AICc picks some order above 0 with a
        probability that does not vanish: on 2,000 series of independent epochs, 28 % at
        T = 200, 1,000 and 5,000 against BIC's 2.6, 1.1 and 0.4 %. :func:`fit_memory`
        asks it whether there is memory at all.

        Returns
        -------
        numpy.ndarray, shape (k, p_max + 1)
            BIC(p) per series and order p, with T = :attr:`epochs`.
        """
        t = self.epochs
        p = np.arange(self.variance.shape[1])
        return t * np.log(self.variance) + p * math.log(t)

    def orders(self, minimum: int = 0) -> np.ndarray:
        """The order of least AICc per series, at least ``minimum``.

        Parameters
        ----------
        minimum : int, default 0
            The smallest order allowed.

        Returns
        -------
        numpy.ndarray of int, shape (k,)
            The order p in ``minimum`` … p_max of least :meth:`aicc`, per series.
        """
        return minimum + np.argmin(self.aicc()[:, minimum:], axis=1)

    def coefficients(self, series: int, order: int) -> np.ndarray:
        """φ_1 … φ_p of one series at ``order`` (Levinson's step from the reflections).

        Parameters
        ----------
        series : int
            Index of the series (row of :attr:`reflection`).
        order : int
            The AR order p (at most p_max).

        Returns
        -------
        numpy.ndarray, shape (p,)
            The coefficients φ_1 … φ_p of x_t = Σ φ_j x_{t−j} + u_t (empty for p = 0).
        """
        return ar_coefficients(self.reflection[series, :order])


def ar_coefficients(reflection: np.ndarray) -> np.ndarray:
    """φ_1 … φ_p of the AR model with reflection coefficients k_1 … k_p (Levinson's step).

    Parameters
    ----------
    reflection : numpy.ndarray, shape (p,)
        The reflection coefficients, as :func:`burg` gives them.

    Returns
    -------
    numpy.ndarray, shape (p,)
        The coefficients of x_t = Σ φ_j x_{t−j} + u_t (empty for p = 0).

    Examples
    --------
    >>> ar_coefficients(np.array([-0.5])).tolist()
    [0.5]
    """
    a = np.zeros(0)
    for k in reflection:
        a = np.concatenate([a + k * a[::-1], [k]])
    return -a


BURG_CHUNK = 1 << 16
"""Epochs per chunk of Burg's in-place update (bounded temporaries on long runs)."""
KERNEL_UPDATES = 50_000_000
"""Series × epochs × orders of Burg's recursion a process runs with numpy before it turns
to the compiled update (:func:`credcli.engine.compiled.burg_update_kernel`, when numba is
installed; at once where numba is loaded already): numba's import and first call are
repaid by then. Both give the same bits, so the choice never shows in a result."""

_updates_done = [0]  # Burg work this process has done (forked workers start from their parent's)


def _update_kernel(work: int):
    """The compiled Burg update once this process has done :data:`KERNEL_UPDATES` of
    Burg's work, or where numba is loaded already; None before that, or without numba."""
    _updates_done[0] += work
    if _updates_done[0] <= KERNEL_UPDATES and "numba" not in sys.modules:
        return None
    return compiled.burg_update_kernel()


def burg(x: np.ndarray, order: int) -> BurgFit:
    r"""Burg's recursion up to ``order`` on each of k series, each pooled over its segments.

    The forward and backward prediction errors of every segment enter one reflection
    coefficient: the segments share a model and nothing else. A loop over orders (at most
    :data:`MAX_ORDER_CAP`), vectorised over series and epochs; the prediction errors are
    updated in place in chunks of :data:`BURG_CHUNK` epochs, or by the compiled kernel in
    one pass (:func:`_update_kernel`; the same bits).

    Parameters
    ----------
    x : numpy.ndarray, shape (k, m, T)
        k series of m segments of T epochs each, already centred (the caller centres
        them; this function does not).
    order : int
        The largest order p_max fitted.

    Returns
    -------
    BurgFit
        The reflection coefficients (k, p_max) and innovation variances (k, p_max + 1),
        with ``epochs`` = m·T and ``segments`` = m.

    Notes
    -----
    At order p, with f and b the forward and backward prediction errors of order p − 1,

    .. math:: \kappa_p = \frac{-2\sum_t f_t b_{t-1}}{\sum_t f_t^2 + \sum_t b_{t-1}^2},
              \qquad \sigma_p^2 = \sigma_{p-1}^2 (1 - \kappa_p^2),

    the sums running over every segment (Burg 1968). |κ_p| < 1 keeps every root inside
    the unit circle.
    """
    k, m, t = x.shape
    f = x.copy()
    b = x.copy()
    variance = np.empty((k, order + 1))
    variance[:, 0] = np.einsum("kmt,kmt->k", x, x) / (m * t)
    reflection = np.zeros((k, order))
    kernel = _update_kernel(k * m * t * order)
    for p in range(1, order + 1):
        fp = f[:, :, p:]
        bp = b[:, :, p - 1 : -1]
        num = -2.0 * np.einsum("kmt,kmt->k", fp, bp)
        den = np.einsum("kmt,kmt->k", fp, fp) + np.einsum("kmt,kmt->k", bp, bp)
        kappa = np.where(den > 0, num / np.where(den > 0, den, 1.0), 0.0)
        kappa = np.clip(kappa, -1.0 + 1e-12, 1.0 - 1e-12)
        reflection[:, p - 1] = kappa
        variance[:, p] = variance[:, p - 1] * (1.0 - kappa**2)
        if kernel is not None:
            kernel(f, b, kappa, p)
            continue
        k3 = kappa[:, None, None]
        # f_t += κ b_{t−1} and b_t = b_{t−1} + κ f_t (old f_t) in place, in chunks of
        # epochs from the end: a chunk reads b one epoch before it, which no later (that
        # is, earlier) chunk has written yet; temporaries stay at a chunk's size
        for stop in range(t, p, -BURG_CHUNK):
            start = max(p, stop - BURG_CHUNK)
            f_old = f[:, :, start:stop].copy()
            b_old = b[:, :, start - 1 : stop - 1]
            f[:, :, start:stop] += k3 * b_old
            b[:, :, start:stop] = b_old + k3 * f_old
    variance = np.maximum(variance, np.finfo(float).tiny)
    return BurgFit(reflection, variance, m * t, m)


def _yule_walker_matrix(phi: np.ndarray) -> np.ndarray:
    """A of the Yule–Walker system A γ = σ² e_0 of an AR(p): A[k, l] collects φ_j at
    |k − j| = l (γ(0) … γ(p) solve it). An entry that collects two terms (j = k − l and
    j = k + l) subtracts the one of the smaller j first (:func:`_yule_walker_places`)."""
    p = phi.size
    a = np.eye(p + 1)
    for rows, columns, terms in _yule_walker_places(p):
        a[rows, columns] -= phi[terms]
    return a


@functools.lru_cache(maxsize=128)
def _yule_walker_places(p: int) -> tuple:
    """Where each φ_j enters the Yule–Walker matrix of order p, in two passes in which no
    entry repeats: j <= k (column k − j), then j > k (column j − k); each pass (rows,
    columns, indices into φ)."""
    k, j = np.divmod(np.arange((p + 1) * p), p)
    j += 1
    below = j <= k
    places = tuple((k[part], np.abs(k - j)[part], j[part] - 1) for part in (below, ~below))
    for index in (i for part in places for i in part):
        index.flags.writeable = False  # shared by every call of this order
    return places


class NoFiniteMemory(ArithmeticError):
    """A fitted AR model has a root on the unit circle to working precision, where its
    Yule–Walker system is singular: the errors drift (a trend, a random walk, a smooth
    curve) and have no finite memory that a segment could resolve (:func:`fit_memory`)."""


RECURSION_CHUNK = 1 << 16
"""Most lags :func:`autocovariance_of_ar` runs its recursion over at once: LAPACK's banded
solve holds p + 1 rows of that length and a copy (a model of order 53 kept over 2^20 lags,
as a segment of 2,000,000 epochs keeps it, held 880 MiB; docs/performance.md)."""


def autocovariance_of_ar(phi: np.ndarray, sigma2: float, lags: int) -> np.ndarray:
    """γ(0) … γ(lags − 1) of the stationary AR(p) x_t = Σ φ_j x_{t−j} + u_t, Var u = σ².

    Parameters
    ----------
    phi : numpy.ndarray, shape (p,)
        The AR coefficients φ_1 … φ_p (empty: white noise); the model must be stationary.
    sigma2 : float
        The innovation variance σ².
    lags : int
        How many lags to return (at least 1).

    Returns
    -------
    numpy.ndarray, shape (lags,)
        The autocovariances γ(0) … γ(lags − 1).

    Notes
    -----
    γ(0) … γ(p) solve the p + 1 Yule–Walker equations γ(k) − Σ_j φ_j γ(|k − j|) = σ² δ_k0;
    later lags follow the recursion γ(h) = Σ_j φ_j γ(h − j) (:func:`ar_filter`, with the
    known γ(1) … γ(p) as inputs), run over at most :data:`RECURSION_CHUNK` lags at once,
    each chunk's inputs the terms of the p lags before it. The first chunk is one pass's
    bits; later ones agree with one pass to rounding (the filter's own order of sums).

    Examples
    --------
    An AR(1) has γ(h) = σ² φ^h / (1 − φ²):

    >>> np.round(autocovariance_of_ar(np.array([0.5]), 0.75, 4), 6)
    array([1.   , 0.5  , 0.25 , 0.125])
    """
    p = phi.size
    if p == 0:
        out = np.zeros(lags)
        out[0] = sigma2
        return out
    a = _yule_walker_matrix(phi)
    rhs = np.zeros(p + 1)
    rhs[0] = sigma2
    gamma = np.linalg.solve(a, rhs)
    if lags <= p + 1:
        return gamma[:lags].copy()
    out = np.empty(lags)
    out[: p + 1] = gamma
    for start in range(p + 1, lags, RECURSION_CHUNK):
        stop = min(lags, start + RECURSION_CHUNK)
        out[start:stop] = ar_continued(phi, out[start - p : start], np.zeros(stop - start))
    return out


def ar_continued(phi: np.ndarray, before: np.ndarray, z: np.ndarray) -> np.ndarray:
    """x with x_t = Σ_j φ_j x_{t−j} + z_t along the first axis of z, the p values before
    x_0 given (``before``, x_{−p} … x_{−1}): :func:`ar_filter` from a zero state, with the
    terms that reach back before x_0 added to its first p inputs (written over z).

    Parameters
    ----------
    phi : numpy.ndarray, shape (p,), p >= 1
        The AR coefficients.
    before : numpy.ndarray, shape (p,) or (p, m)
        The p values before the first, oldest first.
    z : numpy.ndarray, shape (T,) or (T, m), float64
        The inputs; overwritten.

    Returns
    -------
    numpy.ndarray
        x, in the shape of z.

    Examples
    --------
    >>> ar_continued(np.array([0.5]), np.array([2.0]), np.zeros(3)).tolist()
    [1.0, 0.5, 0.25]
    """
    p = phi.size
    for j in range(1, p + 1):  # x_t reads x_{t−j} from before where t < j
        reach = min(j, z.shape[0])
        z[:reach] += phi[j - 1] * before[p - j : p - j + reach]
    return ar_filter(phi, z)


def ar_filter(phi: np.ndarray, z: np.ndarray) -> np.ndarray:
    """x with x_t = Σ_j φ_j x_{t−j} + z_t from a zero state, along the first axis of z.

    The recursion is forward substitution in the unit lower-triangular banded Toeplitz
    system with first column (1, −φ_1, …, −φ_p), solved by LAPACK's ``dtbtrs`` (scipy's
    ``lfilter`` does the same recursion, but ``scipy.signal`` costs half a second to import
    on every run).

    Parameters
    ----------
    phi : numpy.ndarray, shape (p,)
        The AR coefficients φ_1 … φ_p.
    z : numpy.ndarray, shape (T,) or (T, m)
        The inputs, one series per column.

    Returns
    -------
    numpy.ndarray
        x, in the shape of z.

    Examples
    --------
    >>> ar_filter(np.array([0.5]), np.array([1.0, 0.0, 0.0, 1.0])).tolist()
    [1.0, 0.5, 0.25, 1.125]
    """
    z = np.asarray(z, dtype=float)
    t = z.shape[0]
    if t == 0 or phi.size == 0:
        return z.copy()
    kd = min(phi.size, t - 1)
    band = np.empty((kd + 1, t))
    band[0] = 1.0
    band[1:] = -phi[:kd, None]
    x, info = lapack.dtbtrs(band, z.reshape(t, -1), uplo="L", trans="N", diag="U")
    if info != 0:  # a unit diagonal is never singular
        raise np.linalg.LinAlgError(f"dtbtrs failed (info {info})")
    return x.reshape(z.shape)


def stationary_draws(
    phi: np.ndarray, gen: np.random.Generator, rows: int, n: int, burn: int | None = None, out=None
) -> np.ndarray:
    """``rows`` series of ``n`` epochs of the stationary AR model ``phi`` with unit Gaussian
    innovations.

    By default each series is the last ``n`` of ``burn + n`` epochs from a zero state, the
    burn-in the model's own decay horizon (:func:`decay_horizon`, 0 for white noise):
    stationary to :data:`NEGLIGIBLE`. Where that horizon is longer than
    :data:`EXACT_START_BEYOND` epochs, each series starts instead from the model's
    stationary distribution itself (:func:`started_filter`): as many values drawn, and
    exact at any horizon, where a burn-in of :data:`MAX_BURN_IN` epochs left a model near
    a unit root short of its variance (φ = 0.99999: by e^{-4}, 2 %) and cost that many
    draws for every series. A given ``burn`` always takes the burn-in.

    The values are those of one draw ``gen.standard_normal((rows, burn + n))`` (with the
    stationary start, ``burn`` 0), taken in chunks of whole rows of at most
    :data:`DRAWN_AT_ONCE` values (a generator fills an array in order, and each series is
    filtered on its own), so the series are the same bits as drawn whole, and the burn-in
    is never held for every row at once.

    Parameters
    ----------
    phi : numpy.ndarray, shape (p,)
        The AR coefficients (p may be 0: white noise).
    gen : numpy.random.Generator
        The draws' source.
    rows, n : int
        The series, and the epochs kept of each.
    burn : int, optional
        The epochs drawn before them from a zero state; default the model's decay horizon,
        or the stationary start beyond :data:`EXACT_START_BEYOND`.
    out : numpy.ndarray, shape (rows, n), optional
        Where to write the series.

    Returns
    -------
    numpy.ndarray, shape (rows, n)
        The series, one per row (``out`` where given).

    Examples
    --------
    >>> phi = np.array([0.9])
    >>> whole = ar_filter(phi, np.random.default_rng(3).standard_normal((5, 12)).T)[4:].T
    >>> drawn = stationary_draws(phi, np.random.default_rng(3), 5, 8, 4)
    >>> bool(np.array_equal(drawn, whole))
    True
    """
    burn, factor = draws_start(phi) if burn is None else (burn, None)
    out = np.empty((rows, n)) if out is None else out
    step = max(1, DRAWN_AT_ONCE // (n + burn))
    for start in range(0, rows, step):
        stop = min(rows, start + step)
        z = gen.standard_normal((stop - start, n + burn)).T
        if factor is None:
            out[start:stop] = ar_filter(phi, z)[burn:].T
        else:
            out[start:stop] = started_filter(phi, z, factor).T
    return out


def draws_start(phi: np.ndarray) -> tuple[int, np.ndarray | None]:
    """How a bootstrap's series of the AR model ``phi`` start stationary: a burn-in of the
    model's decay horizon (at most :data:`MAX_BURN_IN`, 0 for white noise) from a zero
    state, or, past :data:`EXACT_START_BEYOND` epochs of it, the stationary law's factor
    (:func:`stationary_factor`, :func:`started_filter`) and no burn-in.

    Parameters
    ----------
    phi : numpy.ndarray, shape (p,)
        The AR coefficients (stationary).

    Returns
    -------
    burn : int
        The epochs to draw and filter before each series.
    factor : numpy.ndarray, shape (p, p), or None
        The start's factor; None where the burn-in starts the series.

    Examples
    --------
    >>> draws_start(np.array([0.5]))[0], draws_start(np.array([0.5]))[1] is None
    (32, True)
    >>> burn, factor = draws_start(np.array([0.999]))
    >>> burn, factor.round(3).tolist()
    (0, [[22.366]])
    """
    burn = min(MAX_BURN_IN, decay_horizon(phi, 0)) if phi.size else 0
    factor = stationary_factor(phi) if burn > EXACT_START_BEYOND else None
    return (burn, None) if factor is None else (0, factor)


def stationary_factor(phi: np.ndarray) -> np.ndarray | None:
    """The lower Cholesky factor L of Γ_p, the covariance of p consecutive values of the
    stationary AR(p) ``phi`` with unit innovations (Toeplitz in γ(0) … γ(p − 1),
    :func:`autocovariance_of_ar`); None where it is not positive definite to working
    precision (a root too near the unit circle), which the burn-in then stands in for.

    Parameters
    ----------
    phi : numpy.ndarray, shape (p,), p >= 1
        The AR coefficients (stationary).

    Returns
    -------
    numpy.ndarray, shape (p, p), or None
        L with L Lᵀ = Γ_p.

    Examples
    --------
    An AR(1) has Γ_1 = 1/(1 − φ²):

    >>> stationary_factor(np.array([0.6])).round(12).tolist()
    [[1.25]]
    """
    p = phi.size
    try:
        gamma = autocovariance_of_ar(phi, 1.0, p)
        lags = np.abs(np.arange(p)[:, None] - np.arange(p)[None, :])
        factor = np.linalg.cholesky(gamma[lags])
    except np.linalg.LinAlgError:
        return None
    return factor if np.all(np.isfinite(factor)) else None


def started_filter(phi: np.ndarray, z: np.ndarray, factor: np.ndarray) -> np.ndarray:
    """Stationary AR series from standard normal draws, along the first axis of z,
    written over z: the first p values (x_0 … x_{p−1}) = L (z_0 … z_{p−1}), with L the
    factor of their stationary covariance (:func:`stationary_factor`), and
    x_t = Σ_j φ_j x_{t−j} + z_t after them. Every x_t then has the stationary distribution
    exactly (a Gaussian AR(p) is a Markov chain in its last p values, and they start in
    its stationary law), which a burn-in from a zero state reaches only to the power of its
    slowest root.

    The recursion past the start is :func:`ar_continued` from the start (as
    :func:`autocovariance_of_ar` continues its lags). Written over z, so that a chunk of
    draws holds two arrays of its size, as the burn-in's does (z and the filter's output).

    Parameters
    ----------
    phi : numpy.ndarray, shape (p,), p >= 1
        The AR coefficients (stationary).
    z : numpy.ndarray, shape (T,) or (T, m), float64
        Independent standard normal values, one series per column; overwritten.
    factor : numpy.ndarray, shape (p, p)
        L, lower triangular, L Lᵀ = Γ_p.

    Returns
    -------
    numpy.ndarray
        x, in the shape of z (z itself).

    Examples
    --------
    >>> z = np.array([1.0, 0.5, 0.0])
    >>> started_filter(np.array([0.6]), z, np.array([[1.25]])).tolist()
    [1.25, 1.25, 0.75]
    """
    t, p = z.shape[0], phi.size
    head = min(p, t)
    column = (slice(None),) + (None,) * (z.ndim - 1)
    start = np.zeros((head, *z.shape[1:]))
    for k in range(head):  # L z term by term: each series' own sums, whatever the others
        start[k:] += factor[k:head, k][column] * z[k]
    z[:head] = start
    if t > p:
        z[p:] = ar_continued(phi, z[:p], z[p:])
    return z


def decay_horizon(phi: np.ndarray, n: int) -> int:
    """Lags to keep of an AR model's autocorrelation.

    Parameters
    ----------
    phi : numpy.ndarray, shape (p,)
        The AR coefficients (stationary).
    n : int
        The fewest lags to keep (the segment's length).

    Returns
    -------
    int
        Lags until the slowest root's power has decayed below :data:`NEGLIGIBLE`, at least
        ``n`` (and p + 1), at most :data:`MAX_HORIZON`.
    """
    if phi.size == 0:
        return max(n, 1)
    if phi.size == 1:  # the root of 1 − φz⁻¹ is φ (np.roots' 1×1 eigenvalue, which moves
        r = abs(float(phi[0]))  # only below 1e-150, where the horizon is its floor)
    else:
        roots = np.abs(np.roots(np.concatenate([[1.0], -phi])))
        r = float(np.max(roots)) if roots.size else 0.0
    if r <= 0.0:
        return max(n, phi.size + 1)
    decay = math.log(NEGLIGIBLE) / math.log(min(r, 1.0 - 1e-12))
    return int(min(MAX_HORIZON, max(n, phi.size + 1, math.ceil(decay) + phi.size + 1)))


def _memoised(method):
    """Keep a model-only method's answers on its (frozen) instance, by argument.

    The windows of one run are judged against one model and ask it the same questions
    (the moments of a window of n epochs, the sign-block length), window after window;
    the answers depend on the model and n alone. Arrays come back read-only, so that no
    caller can change a shared answer."""

    @functools.wraps(method)
    def answer(self, *args):
        memo = self.__dict__.setdefault("_memo", {})
        key = (method.__name__, *args)
        if key not in memo:
            value = method(self, *args)
            if isinstance(value, np.ndarray):
                value.setflags(write=False)
            memo[key] = value
        return memo[key]

    return answer


class _Answering:
    """A frozen model that keeps answers (:func:`_memoised`): they are a cache, so they stay
    behind when the model is pickled (a worker's results carry their models to the parent,
    where 10⁵ segments' answers would hold some 200 MB)."""

    def __getstate__(self) -> dict:
        state = dict(self.__dict__)
        state.pop("_memo", None)
        return state


@dataclass(frozen=True)
class SeriesMemory(_Answering):
    """The fitted memory of one standardized series (:func:`series_memory`).

    Attributes
    ----------
    phi : numpy.ndarray, shape (p,)
        The AR(p) coefficients at the order of least AICc (empty: white).
    rho : numpy.ndarray, shape (H,)
        The model's autocorrelation ρ(0) = 1, ρ(1), … ρ(H − 1), kept up to a horizon H
        where it has decayed (zero beyond); after the bootstrap's bias correction.
    dof : float
        ν_Ω, the degrees of freedom of the long-run variance estimate (inf: known, as for
        white noise).
    square_dof : float, default inf
        ν of τ₂ = Σρ², the scale test's model uncertainty.
    fraction : float, default 0
        d of a long-memory model (1 − B)^d A(B) x = u, whose AR part is ``phi``
        (:mod:`credcli.engine.longmemory`); 0 for the AR sieve's models. Its ``rho`` spans
        every lag of the segment.
    moving : float, default 0
        θ of a short-memory ARMA(p, 1) model A(B) x = (1 + θB) u whose AR part is ``phi``,
        a model's alternative only (:mod:`credcli.engine.longmemory`); 0 otherwise.
    """

    phi: np.ndarray
    rho: np.ndarray
    dof: float
    square_dof: float = math.inf
    fraction: float = 0.0
    moving: float = 0.0

    @property
    def order(self) -> int:
        """The AR order (of the AR part, for a long-memory model)."""
        return int(self.phi.size)

    @functools.cached_property
    def variance_ratio(self) -> float:
        """τ = Ω/γ(0) = 1 + 2 Σ_{h>0} ρ(h): the integrated correlation time, in epochs.

        A long-memory model (``fraction`` > 0) has no finite τ (Σρ diverges); its
        ``variance_ratio`` is v_N of the segment's N epochs (:meth:`mean_ratio`), so that
        N/τ counts the independent epochs the segment's mean is worth."""
        if self.fraction > 0:
            return self.mean_ratio(self.rho.size)
        return float(1.0 + 2.0 * np.sum(self.rho[1:]))

    @_memoised
    def window(self, n: int) -> np.ndarray:
        """The autocorrelation over a window of ``n`` epochs.

        Parameters
        ----------
        n : int
            Epochs in the window.

        Returns
        -------
        numpy.ndarray, shape (n,)
            ρ(0) … ρ(n − 1), zero past the horizon.
        """
        if n <= self.rho.size:
            return self.rho[:n]
        return np.concatenate([self.rho, np.zeros(n - self.rho.size)])

    @_memoised
    def test_window(self, n: int) -> np.ndarray:
        """The autocorrelation the tests use over a window of ``n`` epochs.

        The floor of :meth:`mean_ratio` (v_n >= 1), for quadratic forms with time-varying
        weights: a fitted antipersistence is replaced by white noise.

        Parameters
        ----------
        n : int
            Epochs in the window.

        Returns
        -------
        numpy.ndarray, shape (n,)
            :meth:`window` ``(n)``, or white noise's (1, 0, …, 0) where the fitted one has
            v_n < 1.
        """
        rho = self.window(n)
        if mean_variance_ratio(rho) < 1.0:
            return np.eye(1, n)[0]
        return rho

    @_memoised
    def mean_ratio(self, n: int) -> float:
        """The variance ratio v_n of the mean of a window of ``n`` epochs, at least 1.

        A fitted antipersistence (v_n < 1, which a spurious order on a short window of
        white errors often shows) never narrows a test.

        Parameters
        ----------
        n : int
            Epochs in the window.

        Returns
        -------
        float
            v_n = n·Var(x̄_n)/γ(0) = 1 + 2 Σ_{0<h<n} (1 − h/n) ρ(h), floored at 1 (τ as
            n → ∞).
        """
        return max(mean_variance_ratio(self.window(n)), 1.0)

    @_memoised
    def centred_square_moments(self, n: int) -> tuple[float, float]:
        r"""Mean and variance of the centred sum of squares over a window of ``n`` epochs.

        Of Σ_k (x_k − x̄)² for a Gaussian series with this autocorrelation and unit
        variance.

        Parameters
        ----------
        n : int
            Epochs in the window.

        Returns
        -------
        mean, variance : tuple of float
            E and Var of Σ_k (x_k − x̄)², each floored at 1e-12.

        Notes
        -----
        With R the n × n Toeplitz correlation (first row :meth:`window`) and
        C = I − 11ᵀ/n, E = tr(CR) = n − 1ᵀR1/n and
        Var = 2 tr((CRC)²) = 2[tr R² − 2|R1|²/n + (1ᵀR1/n)²] (Isserlis), in O(n).
        """
        rho = self.window(n)
        # tr R² = Σ_h w_h (n − h) ρ(h)², w_0 = 1, w_h = 2: the products in one array
        weights = np.full(n, 2.0)
        weights[0] = 1.0
        np.multiply(weights, np.arange(n, 0, -1), out=weights)
        weights *= np.square(rho)
        tr_r2 = float(np.sum(weights))
        del weights
        row = _toeplitz_row_sums(rho)
        ones_r_ones = float(row.sum())
        mean = n - ones_r_ones / n
        var = 2.0 * (tr_r2 - 2.0 * float(row @ row) / n + (ones_r_ones / n) ** 2)
        return max(mean, 1e-12), max(var, 1e-12)

    @_memoised
    def block_loss(self) -> float:
        """The variance a sign block loses across its boundaries, per epoch of its length.

        A sign block of length L loses about G/(LΩ) of the variance of the sum across its
        boundaries (G of Politis & White 2004, over the long-run variance Ω).

        Returns
        -------
        float
            G/Ω = 2 Σ_h h ρ(h) / τ; (τ² − 1)/(2τ) for an AR(1). 0 when it is negative or
            the series is white.
        """
        h = np.arange(self.rho.size)
        tau = self.variance_ratio
        if tau <= 1e-12:
            return 0.0
        return max(0.0, float(2.0 * np.sum(h * self.rho)) / tau)

    @_memoised
    def decorrelation_lag(self, threshold: float = 0.2) -> int:
        """The first lag from which |ρ(h)| stays below ``threshold``.

        Sign blocks at least this long keep every strong correlation between epochs inside
        a block or between neighbouring blocks (whose pairs the ELT leaves out). It governs
        oscillating errors, whose signed correlations nearly cancel in G (AR(2) with
        complex roots: G/Ω ≈ 0 while |ρ(h)| stays above 0.2 for ten epochs).

        Parameters
        ----------
        threshold : float, default 0.2
            The correlation below which two epochs count as decorrelated.

        Returns
        -------
        int
            One more than the last lag h >= 1 with |ρ(h)| >= ``threshold``; 1 when there
            is none.
        """
        above = np.flatnonzero(np.abs(self.rho[1:]) >= threshold)
        return int(above[-1]) + 2 if above.size else 1


def _toeplitz_row_sums(rho: np.ndarray) -> np.ndarray:
    """R·1 for the symmetric Toeplitz R with first row ρ (n): r_k = Σ_l ρ(|k − l|), from
    cumulative sums (O(n))."""
    c = np.cumsum(rho)
    # Σ_{l≤k} ρ(k − l) = c[k];  Σ_{l>k} ρ(l − k) = c[n − 1 − k] − ρ(0)
    out = c + c[::-1]
    out -= rho[0]
    return out


def _order_memory(fit: BurgFit, series: int, order: int, n: int):
    """(φ, autocorrelation, log max(τ, 1)) of one series at one order."""
    phi = fit.coefficients(series, order)
    sigma2 = float(fit.variance[series, order])
    gamma = autocovariance_of_ar(phi, sigma2, decay_horizon(phi, n))
    g0 = float(gamma[0])
    with np.errstate(over="ignore", invalid="ignore"):
        rho = gamma / g0 if g0 > 0 else np.eye(1, gamma.size)[0]
    if not np.all(np.abs(rho) <= 1.0 + 1e-9):  # a root on the unit circle, to precision
        raise np.linalg.LinAlgError("the fitted model's autocorrelation is not bounded by 1")
    log_tau = math.log(max(1.0 + 2.0 * float(np.sum(rho[1:])), 1.0))
    return phi, rho, log_tau


MIN_ORDER = 1
"""The sieve's smallest order on short runs that have memory (by BIC or the lag-1
screening). AICc chooses order 0 on short windows of weakly dependent errors too often,
and the tests for independent epochs then lose their level there (docs/measured.md); an
AR(1) at least, its estimation error bootstrapped, keeps the level there."""
FORCED_BELOW = 200
"""Runs shorter than this that have memory get :data:`MIN_ORDER` in every series; longer
ones keep AICc's order 0 for a series that shows no memory (known white, no bootstrap).
Whether a run has memory at all is BIC's question (:meth:`BurgFit.bic`)."""
SIEVE_EPOCHS = 1 << 18
"""Most epochs of a run the sieve is fitted on (:func:`fit_memory`): a longer run's first
2^18. Its errors are stationary under the model, and the sieve's τ̂ from 262,144 epochs
already has a relative standard error of order √(p/N) (Berk 1974), 1.5 % at the largest
order, 60, so a segment of millions of epochs pays for this many (Burg's recursion makes a
pass over the series per order) and no more. Every autocorrelation still covers the whole
segment, and the time-scale check (:func:`time_scales`) reads every epoch."""
BOOTSTRAP_REPLICATES = 40
"""Series drawn from each fitted model to measure its estimation error (a variance from
40 draws is within ±22 % at one standard error, which moves a t critical value at 20
degrees of freedom by about 3 %)."""
MAX_BIAS_FACTOR = 3.0
"""Most the bootstrap's bias correction stretches the fitted correlations."""
MAX_BURN_IN = 200_000
"""Longest burn-in of a bootstrap series (epochs); the model's own decay horizon below."""
EXACT_START_BEYOND = 1024
"""Decay horizon (epochs) beyond which a bootstrap series starts from its model's
stationary distribution instead of a burn-in (:func:`stationary_draws`). Both give
stationary series (the burn-in to :data:`NEGLIGIBLE`, below :data:`MAX_BURN_IN`), so this
is a choice of cost alone: past it the burn-in is longer than most series drawn and
costs that many draws and filter steps for every one, where the start costs a p × p
factor once per model (measured: docs/performance.md). Below it the burn-in is kept, and
so are the draws of every model that is not slow."""
DRAWN_AT_ONCE = 1 << 22
"""Most values of white noise drawn at once for a bootstrap's AR series, burn-in included
(:func:`stationary_draws`, 32 MiB): a slow model's burn-in of up to :data:`MAX_BURN_IN`
epochs for each of many series then costs time, not memory. Drawn whole, 20 directions
sharing a model of τ̂ about 17,000 over 20,000 epochs took 1.7 GB in one bootstrap, and
100-epoch windows of a 36,000-epoch run of such errors 4.8 GB (docs/performance.md)."""
BOOTSTRAP_EPOCHS = 1 << 14
"""Longest bootstrap series. Longer runs are bootstrapped at this length and the spread
and bias scaled by its ratio to the run's length (both are O(1/N) for a fitted AR model,
Berk 1974): series as long as a very long segment cost time and memory in proportion for
degrees of freedom in the tens of thousands, which no critical value can tell from
infinity (docs/performance.md)."""


def _log_tau(phi: np.ndarray, sigma2: float) -> float:
    """log max(τ, 1), τ = Ω/γ(0) of an AR(p) from its coefficients (γ(0) by Yule–Walker):
    the tests use τ no smaller than 1 (:meth:`SeriesMemory.mean_ratio`)."""
    a1 = 1.0 - float(phi.sum())
    gamma0 = float(autocovariance_of_ar(phi, sigma2, 1)[0])
    return math.log(max(sigma2 / max(a1 * a1, 1e-300) / max(gamma0, 1e-300), 1.0))


def bootstrap_spread(
    phis: list[np.ndarray],
    n: int,
    p_max: int,
    seed: int,
    minimum: int = 0,
    segments: int = 1,
    runs: int = 1,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The estimation error of fitted AR models' memory, by a parametric bootstrap.

    B = :data:`BOOTSTRAP_REPLICATES` series of ``n`` epochs are drawn from each model in
    ``phis`` (unit innovations, Gaussian, stationary by a burn-in), each centred and
    refitted as the data were (Burg, order by AICc among ``minimum`` … ``p_max``); the
    variance and bias of their log τ̂ (τ floored at 1) and the variance of their log τ̂₂
    are returned. This is the parametric bootstrap of the fitted model (Efron & Tibshirani
    1993, Ch. 6 and 10), order selection included: a near-white model fitted by chance on
    a short window refits near τ = 1 and has a small spread, a persistent one a large
    spread and a bias towards less memory (Burg's and the sample mean's), which
    :func:`series_memory` corrects. Beyond :data:`BOOTSTRAP_EPOCHS` the series are that
    long and the spread and bias are scaled to ``n``.

    Parameters
    ----------
    phis : list of numpy.ndarray
        The AR coefficients φ of each fitted model (each of order >= 1 in practice).
    n : int
        Epochs N behind the fit.
    p_max : int
        The largest order the refits may choose.
    seed : int
        Seeds the draws together with ``n``, ``p_max`` and the number of models
        (``fit_memory`` passes the sum of the fitted orders): the same models give the
        same spread.
    minimum : int, default 0
        The smallest order the refits may choose.
    segments : int, default 1
        Independent series of ``n`` epochs behind each fit, each centred on its own mean
        and pooled by the refit as the fit pooled them (the principal directions that
        share one model, :func:`_distinct_directions`, :func:`_common_model`).
    runs : int, default 1
        Runs of ``n`` epochs in each of those series, each centred on its own mean and
        pooled by the refit (the windows of one run, :func:`credcli.engine.diagnosis.
        run_model`): the refits then have the bias of centring each short run as well
        (within-group estimation, Nickell 1981), which does not fall with the number of
        runs. At most BOOTSTRAP_EPOCHS // n runs are drawn (at least one); the variances
        are scaled by their share of ``runs``, the bias is not.

    Returns
    -------
    var_log_tau, bias_log_tau, var_log_tau2 : tuple of numpy.ndarray
        Three arrays of shape (len(phis),): Var(log τ̂*), mean(log τ̂*) − log τ, and
        Var(log τ̂₂*) with τ₂ = Σρ², each scaled by min(1, BOOTSTRAP_EPOCHS/n).

    Notes
    -----
    τ of each refit comes from its reflection coefficients (:func:`_log_taus`).
    """
    entropy = [seed, n, p_max, len(phis)] + ([runs] if runs > 1 else [])
    gen = np.random.default_rng(np.random.SeedSequence(entropy))
    b = BOOTSTRAP_REPLICATES
    shrink = min(1.0, BOOTSTRAP_EPOCHS / n)
    n = min(n, BOOTSTRAP_EPOCHS)
    drawn = min(runs, max(1, BOOTSTRAP_EPOCHS // n))
    spread_shrink = shrink * drawn / runs
    series = segments * drawn
    draws = np.empty((len(phis), b * series, n))
    for i, phi in enumerate(phis):
        stationary_draws(phi, gen, b * series, n, out=draws[i])
    draws -= draws.mean(axis=2, keepdims=True)
    fit = burg(draws.reshape(len(phis) * b, series, n), p_max)
    orders = fit.orders(minimum)
    logs = _log_taus(fit.reflection, orders).reshape(len(phis), b)
    truths = np.array([_log_tau(phi, 1.0) for phi in phis])
    squares = np.log(_square_ratios(fit.reflection, orders)).reshape(len(phis), b)
    # a refit without finite τ₂ leaves τ₂'s spread unbounded (no degrees of freedom)
    finite = np.isfinite(squares).all(axis=1)
    spread = np.var(np.where(finite[:, None], squares, 0.0), axis=1, ddof=1)
    return (
        np.var(logs, axis=1, ddof=1) * spread_shrink,
        (np.mean(logs, axis=1) - truths) * shrink,
        np.where(finite, spread * spread_shrink, np.inf),
    )


SPECTRUM_POINTS = 4096
"""Most frequencies on which :func:`_square_ratios` integrates an AR spectrum; a model with
a root nearer the unit circle (modulus above about 0.986) needs more to keep the aliasing
below :data:`ALIASING`, and its τ₂ is summed in the time domain instead
(:func:`_square_sums`)."""
FEWEST_SPECTRUM_POINTS = 64
"""Fewest frequencies on which :func:`_square_ratios` integrates an AR spectrum."""
ALIASING = 1e-18
"""Largest relative aliasing error G²r^G of the grid mean of the squared spectrum (r the
largest root modulus, G the grid), below every float64 rounding."""


def _grid_points(a: np.ndarray) -> np.ndarray:
    """The grid G of each AR polynomial's spectrum (rows of ``a``, a_0 = 1): the fewest
    points, a power of two from :data:`FEWEST_SPECTRUM_POINTS` to :data:`SPECTRUM_POINTS`,
    with G²r^G <= :data:`ALIASING`; 0 where no such grid has that few points. The grid
    mean of f or f² differs from its integral by the autocovariances of f or f² at
    multiples of G (the Poisson sum), which decay as r^h and h·r^h.

    r is the largest root modulus of each polynomial at its own degree (the coefficients
    past it are zeros, roots at 0): |a_1| at degree 1, the eigenvalues of the companion
    matrix of that degree from degree 2 on, one batch per degree (a refit of a
    bootstrap is mostly of degree 0–2 in a fit of p_max up to some 60)."""
    p = a.shape[1] - 1
    if p == 0:
        return np.full(a.shape[0], FEWEST_SPECTRUM_POINTS)
    present = a[:, 1:] != 0
    degree = np.where(present.any(axis=1), p - np.argmax(present[:, ::-1], axis=1), 0)
    radius = np.where(degree == 1, np.abs(a[:, 1]), 0.0)
    for order in np.unique(degree[degree >= 2]).tolist():
        rows = degree == order
        companion = np.zeros((int(rows.sum()), order, order))
        companion[:, 0, :] = -a[rows, 1 : order + 1]
        companion[:, np.arange(1, order), np.arange(order - 1)] = 1.0
        radius[rows] = np.max(np.abs(np.linalg.eigvals(companion)), axis=1)
    grids = FEWEST_SPECTRUM_POINTS * 2 ** np.arange(
        int(math.log2(SPECTRUM_POINTS // FEWEST_SPECTRUM_POINTS)) + 1
    )
    with np.errstate(divide="ignore"):
        log_error = 2.0 * np.log(grids)[None, :] + grids[None, :] * np.log(radius)[:, None]
    fine = log_error <= math.log(ALIASING)
    return np.where(fine.any(axis=1), grids[np.argmax(fine, axis=1)], 0)


def _square_ratios(reflection: np.ndarray, orders: np.ndarray) -> np.ndarray:
    """τ₂ = Σ_h ρ(h)² of each AR model given by its reflection coefficients (k, p_max) at
    its order: Levinson's step on all models at once, then Parseval on the spectrum
    f ∝ 1/|A(e^{iω})|², τ₂ = mean(f²)/mean(f)², on each model's grid (:func:`_grid_points`;
    one FFT per grid size); a model no grid of :data:`SPECTRUM_POINTS` frequencies keeps
    within :data:`ALIASING` (a root of modulus above about 0.986, which 4,096 points left
    10 % off at 0.999 and 60 % off at 0.9999) has τ₂ summed in the time domain
    (:func:`_square_sums`). The scale test's variance is proportional to τ₂
    (:meth:`SeriesMemory.centred_square_moments`), so its spread is the scale's model
    uncertainty."""
    k, p_max = reflection.shape
    a = np.zeros((k, p_max + 1))
    a[:, 0] = 1.0
    for j in range(1, p_max + 1):
        step = np.where(j <= orders, reflection[:, j - 1], 0.0)
        a[:, 1 : j + 1] += step[:, None] * a[:, j - 1 :: -1].copy()
    grid = _grid_points(a)
    ratios = np.empty(k)
    slow = grid == 0
    for order in np.unique(orders[slow]).tolist():
        rows = slow & (orders == order)
        ratios[rows] = 2.0 * _square_sums(reflection[rows, :order]) - 1.0
    for points in np.unique(grid[~slow]).tolist():
        rows = grid == points
        # the coefficients are real, so the spectrum is even: its half from rfft, the inner
        # frequencies counted twice, is the whole circle's mean at half the cost
        # a refit with a root on the unit circle has an unbounded spectrum: τ₂ = ∞
        with np.errstate(divide="ignore", over="ignore", invalid="ignore"):
            spectrum = 1.0 / np.abs(np.fft.rfft(a[rows], points, axis=1)) ** 2
            weights = np.r_[1.0, np.full(points // 2 - 1, 2.0), 1.0] / points
            ratios[rows] = (spectrum**2 @ weights) / (spectrum @ weights) ** 2
    return np.where(np.isfinite(ratios), ratios, np.inf)


MAX_DOUBLINGS = 64
"""Most squarings of the companion matrix in :func:`_square_sums` (2⁶⁴ lags): a model
whose powers have not died out by then has τ₂ = ∞ (a root on the unit circle)."""


def _square_sums(reflection: np.ndarray) -> np.ndarray:
    """S = Σ_{h>=0} ρ(h)² of AR(p) models of one order p >= 1, given by their reflection
    coefficients (rows of ``reflection``, shape (k, p)), however near the unit circle
    their roots.

    ρ(0) … ρ(p − 1) come from the reflection coefficients by Levinson's recursion run
    backwards, ρ(m) = −k_m E_{m−1} − Σ_{i<m} a_i^{(m−1)} ρ(m − i), E_m = E_{m−1}(1 − k_m²),
    E_0 = ρ(0) = 1 (the Durbin–Levinson algorithm, Brockwell & Davis 1991, §5.2). Beyond,
    the state X_h = (ρ(h), …, ρ(h − p + 1)) follows X_{h+1} = F X_h with F the companion
    matrix, so Σ_{h>=p−1} ρ(h)² = W₁₁ with W = Σ_m F^m X Xᵀ (F^m)ᵀ, X = X_{p−1}: the
    solution of the Stein equation W − F W Fᵀ = X Xᵀ, found by Smith's doubling (R. A.
    Smith 1968, SIAM J. Appl. Math. 16(1)), W ← W + G W Gᵀ, G ← G² from G = F, which after
    j steps has summed 2^j lags. Every term is positive semi-definite (no cancellation),
    and j is about log₂ of the model's horizon, so a root of modulus 1 − 10⁻⁶ costs some 25
    products of p × p matrices.

    Parameters
    ----------
    reflection : numpy.ndarray, shape (k, p)
        Reflection coefficients, |k_j| < 1.

    Returns
    -------
    numpy.ndarray, shape (k,)
        S of each model; inf where the powers of F have not died out after
        :data:`MAX_DOUBLINGS` squarings.
    """
    count, p = reflection.shape
    rho = np.zeros((count, p))
    rho[:, 0] = 1.0
    a = np.ones((count, 1))  # a^{(m−1)}, its E_{m−1} in ``error``; a^{(p)} at the end
    error = np.ones(count)
    for m in range(1, p + 1):
        k_m = reflection[:, m - 1]
        if m < p:
            rho[:, m] = -k_m * error - np.sum(a[:, 1:] * rho[:, m - 1 : 0 : -1], axis=1)
        a = np.concatenate([a, np.zeros((count, 1))], axis=1)
        a = a + k_m[:, None] * a[:, ::-1]  # Levinson's step-up
        error = error * (1.0 - k_m**2)
    state = rho[:, ::-1]  # X_{p−1} = (ρ(p − 1), …, ρ(0))
    power = np.zeros((count, p, p))
    power[:, 0, :] = -a[:, 1:]
    power[:, np.arange(1, p), np.arange(p - 1)] = 1.0
    total = state[:, :, None] * state[:, None, :]
    done = np.zeros(count, dtype=bool)
    with np.errstate(over="ignore", invalid="ignore"):  # a unit root's sums grow: τ₂ = ∞
        for _ in range(MAX_DOUBLINGS):
            total = total + power @ total @ np.swapaxes(power, 1, 2)
            power = power @ power
            # the lags not yet summed are G W Gᵀ, negligible once G's entries are
            done = np.max(np.abs(power), axis=(1, 2)) < NEGLIGIBLE**2
            if done.all():
                break
    head = np.sum(rho[:, : p - 1] ** 2, axis=1)
    return np.where(done, head + total[:, 0, 0], np.inf)


def series_memory(
    fit: BurgFit, series: int, n: int, spread: tuple | None = None, minimum: int = 0
) -> SeriesMemory:
    """The :class:`SeriesMemory` of one series of a Burg fit at its order of least AICc,
    with its bootstrap's degrees of freedom and bias correction (:func:`corrected_memory`).

    Parameters
    ----------
    fit : BurgFit
        The fit (:func:`burg`).
    series : int
        Index of the series in ``fit``.
    n : int
        Epochs per window the autocorrelation must cover (at least this horizon is kept).
    spread : tuple of float, optional
        The bootstrap's (Var log τ̂*, bias of log τ̂*, Var log τ̂₂*) for this series
        (:func:`bootstrap_spread`), which every series of order > 0 has. None: known
        (infinite degrees of freedom, no correction); order 0 without a spread is known
        white noise.
    minimum : int, default 0
        The smallest order allowed.

    Returns
    -------
    SeriesMemory
        φ, the (bias-corrected) autocorrelation, and ν for τ and τ₂.
    """
    order = int(fit.orders(minimum)[series])
    phi, rho, log_tau = _order_memory(fit, series, order, n)
    if spread is None:
        return SeriesMemory(phi, rho, math.inf)
    return corrected_memory(phi, rho, log_tau, spread)


def corrected_memory(
    phi: np.ndarray, rho: np.ndarray, log_tau: float, spread: tuple, fraction: float = 0.0
) -> SeriesMemory:
    """A fitted model with its bootstrap's degrees of freedom and bias correction.

    Parameters
    ----------
    phi, rho : numpy.ndarray
        The model's AR coefficients and autocorrelation.
    log_tau : float
        log of the memory the bootstrap measured (τ, or a long-memory model's v_N), at
        least 0.
    spread : tuple of float
        The bootstrap's (Var log τ̂*, bias of log τ̂*, Var log τ̂₂*).
    fraction : float, default 0
        The model's fractional order d.

    Returns
    -------
    SeriesMemory
        ν = 2/variance for τ and for τ₂; a bias towards less memory corrected by stretching
        ρ(h), h > 0, by the factor that multiplies τ (linear in ρ) by exp(−bias), at most
        :data:`MAX_BIAS_FACTOR` (a bias towards more memory is left, which errs on the safe
        side).
    """
    var_log, bias, var_square = (float(v) for v in spread)
    tau = math.exp(log_tau)
    if bias < 0 and tau > 1.0 + 1e-9:  # τ̂ is low by exp(bias): lengthen the memory
        factor = min((tau * math.exp(-bias) - 1.0) / (tau - 1.0), MAX_BIAS_FACTOR)
        rho = np.concatenate([rho[:1], np.clip(rho[1:] * factor, -1.0, 1.0)])
    dof = 2.0 / var_log if var_log > 0 else math.inf
    square_dof = 2.0 / var_square if var_square > 0 else math.inf
    return SeriesMemory(phi, rho, dof, square_dof, fraction)


@dataclass(frozen=True)
class Memory(_Answering):
    """The dependence model of a run's whitened errors (:func:`fit_memory`).

    Attributes
    ----------
    directions : numpy.ndarray, shape (d, d)
        Orthonormal principal directions (columns) of the long-run covariance.
    series : tuple of SeriesMemory
        One memory per principal direction, in the order of ``directions``' columns.
        Directions that share one model hold it, the same object: from
        :data:`SELECTED_FROM` directions on (one run), those whose memory does not stand
        out of the selection (:func:`_distinct_directions`); otherwise those whose own fit
        shows less memory than the directions' common model (:func:`_common_model`).
    squares : SeriesMemory
        The memory of the centred NEES q (which carries heavy tails as well as memory).
    epochs : int
        Epochs N behind the fit.
    segments : int, default 1
        The runs the fit pooled.
    alternative : Memory or None, default None
        The same model with more memory where the data support one: a fractional model
        (its AICc within ``longmemory.SUPPORT`` of the sieve's, no ARMA(p, 1) better by
        BIC's margin) that BIC does not take, or an ARMA(p, 1) preferred to the sieve and
        within ``longmemory.SUPPORT`` of the best, in the direction whose data support
        it, and a model of that class fitted on the directions together in those with less
        memory of their own where their pooled data support it (:mod:`credcli.engine.
        longmemory`); each direction keeps its own model where these imply less memory. A
        location or scale finding must hold under it as well. None where no direction
        changes.
    """

    directions: np.ndarray
    series: tuple[SeriesMemory, ...]
    squares: SeriesMemory
    epochs: int
    segments: int = 1
    alternative: Memory | None = None

    @property
    def white(self) -> bool:
        """Whether the errors are taken as independent (:func:`fit_memory`): then the exact
        tests for independent epochs apply. A long-memory model of AR order 0 (fractional
        noise) is not white."""
        return all(
            m.order == 0 and m.fraction == 0 and m.moving == 0 for m in (*self.series, self.squares)
        )

    @property
    def alternative_changes(self) -> list[SeriesMemory]:
        """The directions' models that the :attr:`alternative` replaces (empty without
        one)."""
        if self.alternative is None:
            return []
        return [a for a, m in zip(self.alternative.series, self.series) if a is not m]

    @property
    def alternative_fraction(self) -> float:
        """The largest d among the directions' models the :attr:`alternative` replaces: > 0
        for a long-memory alternative, 0 for an ARMA one or none."""
        return max((m.fraction for m in self.alternative_changes), default=0.0)

    @property
    def alternative_name(self) -> str | None:
        """The :attr:`alternative` in words, as the reasons name it ("a long-memory one
        (d̂ 0.3)", "an ARMA one (θ̂ -0.7) with more memory"), from the directions it
        changed; None without one."""
        if self.alternative is None:
            return None
        if self.alternative_fraction > 0:
            return f"a long-memory one (d̂ {self.alternative_fraction:.2g})"
        theta = max((m.moving for m in self.alternative_changes), key=abs, default=0.0)
        return f"an ARMA one (θ̂ {theta:.2g}) with more memory"

    @functools.cached_property
    def variance_ratios(self) -> np.ndarray:
        """τ per principal direction (read-only)."""
        ratios = np.array([m.variance_ratio for m in self.series])
        ratios.setflags(write=False)
        return ratios

    @property
    def dof(self) -> float:
        """ν_Ω of the least certain direction (the location's reference)."""
        return float(min(m.dof for m in self.series))

    @property
    def square_dof(self) -> float:
        """ν of τ₂ = Σρ² of the least certain direction (the scale's reference)."""
        return float(min(m.square_dof for m in self.series))

    def models(self) -> list[tuple[SeriesMemory, tuple[int, ...]]]:
        """The distinct models of the directions, each with the directions it serves.

        Returns
        -------
        list of (SeriesMemory, tuple of int)
            One entry per model object in :attr:`series`, in order of first use: a model
            fitted on one direction serves that one; a model the directions share
            (:func:`_distinct_directions`, :func:`_common_model`) serves every direction
            that took it, which share its estimation error.
        """
        served: dict[int, tuple[SeriesMemory, list[int]]] = {}
        for i, series in enumerate(self.series):
            served.setdefault(id(series), (series, []))[1].append(i)
        return [(series, tuple(index)) for series, index in served.values()]

    def pooled_groups(self) -> list[tuple[SeriesMemory, list[int]]]:
        """The directions taken together wherever they share a model: :meth:`models` from
        :data:`SELECTED_FROM` directions on, where such directions are fitted their
        long-memory candidates together (:mod:`credcli.engine.longmemory`) and share one
        variance in the mean test (:func:`credcli.engine.batches.memory_mean_test`); with
        fewer directions each is a group of one, as the sieve's directions are there.

        Returns
        -------
        list of (SeriesMemory, list of int)
            Each group's model and its directions, in order of first use.
        """
        if len(self.series) < SELECTED_FROM:
            return [(series, [i]) for i, series in enumerate(self.series)]
        return [(series, list(rows)) for series, rows in self.models()]

    @_memoised
    def block_length(self, loss: float) -> int:
        """The shortest sign block that loses at most ``loss`` of the variance in every
        direction.

        Parameters
        ----------
        loss : float
            ε, the largest fraction of the variance a block may lose across its boundaries.

        Returns
        -------
        int
            L = ⌈max_i (G/Ω)_i / ε⌉ (:meth:`SeriesMemory.block_loss`), and no shorter than
            any direction's :meth:`SeriesMemory.decorrelation_lag`; at least 1.
        """
        worst = max(m.block_loss() for m in self.series)
        lag = max(m.decorrelation_lag() for m in self.series)
        return max(1, lag, math.ceil(worst / loss - 1e-9))


def moving_sums(x: np.ndarray, width: int) -> np.ndarray:
    """The sums of ``width`` consecutive epochs of each run, computed in place of ``x``.

    One cumulative sum C over the epochs, then C_{k+w−1} − C_{k−1} (C_{−1} = 0) written
    over C from its end in pieces of w epochs, each reading epochs not yet written: the
    values of ``np.cumsum`` and one subtraction, without a second array, in T/w numpy
    calls (:func:`principal_directions` has w ≈ √T: about 1,400 on 2·10⁶ epochs).

    Parameters
    ----------
    x : numpy.ndarray, shape (R, T, d)
        R runs of T epochs; overwritten.
    width : int
        w >= 1 epochs per sum.

    Returns
    -------
    numpy.ndarray, shape (R, max(T − w + 1, 0), d)
        A view of ``x``: the sum of epochs k … k + w − 1 of each run, k = 0 … T − w.

    Examples
    --------
    >>> moving_sums(np.arange(5.0).reshape(1, 5, 1), 2)[0, :, 0].tolist()
    [1.0, 3.0, 5.0, 7.0]
    """
    t = x.shape[1]
    c = np.cumsum(x, axis=1, out=x)
    for stop in range(t, width, -width):
        start = max(width, stop - width)
        np.subtract(c[:, start:stop], c[:, start - width : stop - width], out=c[:, start:stop])
    return c[:, width - 1 :]


def principal_directions(s: np.ndarray, runs: int = 1) -> np.ndarray:
    """Orthonormal directions of the whitened errors ``s`` in which they are uncorrelated
    both at lag 0 and in the long run, as nearly as one rotation allows, slowest first.

    The dependence model treats its directions as independent series, so they should
    diagonalise both the lag-0 covariance Γ₀ and the long-run covariance Ω. One rotation
    does both where the errors are independent series in some frame; it is found by
    Jacobi rotations that minimise the two matrices' squared off-diagonal entries
    together (Cardoso & Souloumiac 1996), each matrix scaled to unit trace and Γ₀ weighted
    by √(2H/3), the ratio of the two estimates' relative standard errors (a Bartlett Ω
    with bandwidth H has Var Ω̂/Ω² ≈ 4H/(3T), Andrews 1991; Γ̂₀ has about 2/T), so that
    each counts by what it knows. Under the null Γ₀ ≈ I holds no direction, and the
    rotation is close to Ω's eigenvectors, as before; where Ω cannot tell directions
    apart, Γ₀ decides. That is
    the case of a short segment with one slow and one white direction: centring takes
    most of the slow direction's variance, its long-run variance is then no larger than
    the white one's, and Ω's eigenvectors alone mixed the two (N = 50, the slow one's
    lag-1 autocorrelation 0.8–0.9: rotations of 10–60°, a fitted τ of about 2 on both
    mixtures where the slow axis alone is fitted 10–16, and false alarms on 21 % of such
    credible segments). The directions are ordered by τ = vᵀΩv / vᵀΓ₀v, largest first.

    The directions only rotate the whitened frame, so the lag-0 covariance is unchanged;
    a poor estimate costs efficiency, not level.

    Parameters
    ----------
    s : numpy.ndarray, shape (N, d)
        The whitened errors, ``runs`` equal runs one after the other.
    runs : int, default 1
        The runs pooled in ``s``; each is centred on its own mean.

    Returns
    -------
    numpy.ndarray, shape (d, d)
        The directions (columns), from a Bartlett estimate of Ω with bandwidth ⌈√T⌉ (T
        epochs per run, as moving sums) and the sample Γ₀ of the centred runs; the 1 × 1
        identity when d = 1.

    References
    ----------
    J.-F. Cardoso and A. Souloumiac, "Jacobi angles for simultaneous diagonalization",
    SIAM J. Matrix Anal. Appl. 17(1), 1996.
    D. W. K. Andrews, "Heteroskedasticity and autocorrelation consistent covariance
    matrix estimation", Econometrica 59(3), 1991.
    """
    n, d = s.shape
    if d == 1:
        return np.ones((1, 1))
    x = s.reshape(runs, n // runs, d)
    x = x - x.mean(axis=1, keepdims=True)
    t = x.shape[1]
    band = max(1, min(t - 1, math.ceil(math.sqrt(t))))
    gamma = np.einsum("mti,mtj->ij", x, x)
    # the Bartlett estimate with bandwidth H is, up to the ends, the covariance of sums of
    # H + 1 consecutive epochs over H + 1: no loop over lags, no second copy of N × d
    sums = moving_sums(x, band + 1)
    sums = sums if runs == 1 else np.ascontiguousarray(sums)
    del x
    omega = np.einsum("mti,mtj->ij", sums, sums) / (band + 1)
    del sums
    traces = float(np.trace(gamma)), float(np.trace(omega))
    if not min(traces) > 0:  # no spread to rotate
        return np.eye(d)
    weighted = math.sqrt(2.0 * band / 3.0) * gamma / traces[0]
    rotation = joint_rotation(np.stack([weighted, omega / traces[1]]))
    with np.errstate(divide="ignore", invalid="ignore"):
        taus = np.sum(rotation * (omega @ rotation), axis=0) / np.sum(
            rotation * (gamma @ rotation), axis=0
        )
    return rotation[:, np.argsort(-np.nan_to_num(taus), kind="stable")]


JACOBI_SWEEPS = 8
"""Most sweeps over the pairs of directions in :func:`joint_rotation`. Two matrices that
one rotation cannot make diagonal keep it turning by ever smaller angles; their
off-diagonal sum settles in its third digit within 2–4 sweeps (d = 6 and 15, measured),
and two directions (d = 2) take one."""


def _round_robin(d: int) -> list[tuple[np.ndarray, np.ndarray]]:
    """The pairs (p, q) of d indices in d − 1 rounds (d rounds for odd d) of disjoint
    pairs: the circle method, index 0 fixed and the others turning one place a round."""
    m = d + d % 2
    others = list(range(1, m))
    rounds = []
    for _ in range(m - 1):
        ring = [0, *others]
        pairs = [(ring[i], ring[m - 1 - i]) for i in range(m // 2)]
        pairs = [(min(a, b), max(a, b)) for a, b in pairs if a < d and b < d]
        rounds.append((np.array([a for a, _ in pairs]), np.array([b for _, b in pairs])))
        others = others[-1:] + others[:-1]
    return rounds


def _turn_angles(a: np.ndarray, p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """The Jacobi angle of each pair (p_j, q_j) for the matrices ``a`` (K, d, d): with
    h_k = (M_pp − M_qq, 2M_pq) and G = Σ_k h_k h_kᵀ, a quarter of the angle of G's
    principal axis (Cardoso & Souloumiac 1996)."""
    hx = a[:, p, p] - a[:, q, q]
    hy = 2.0 * a[:, p, q]
    return 0.25 * np.arctan2(2.0 * np.sum(hx * hy, axis=0), np.sum(hx * hx - hy * hy, axis=0))


def joint_rotation(matrices: np.ndarray, tolerance: float = 1e-12) -> np.ndarray:
    """The rotation V that makes symmetric matrices as diagonal as one rotation can.

    From the eigenvectors of their sum (from the identity for d = 2, where one turn is
    exact), Jacobi sweeps over the pairs (p, q) each turn by
    the angle that minimises the sum of the squared (p, q) entries of VᵀM_kV over the
    matrices: with h_k = (M_pp − M_qq, 2M_pq) and G = Σ h_k h_kᵀ, a quarter of the angle of
    G's principal axis (Cardoso & Souloumiac 1996), until no turn has a sine above
    ``tolerance``. A sweep takes the pairs in rounds of disjoint pairs (the circle
    method), each round's turns at once: a turn in the plane (p, q) moves rows and
    columns p and q only, so a round's turns do not meet.

    Parameters
    ----------
    matrices : numpy.ndarray, shape (K, d, d)
        Symmetric matrices, each weighted by its scale.
    tolerance : float, default 1e-12
        The smallest sine of a turn still made.

    Returns
    -------
    numpy.ndarray, shape (d, d)
        V, orthonormal (columns).

    Examples
    --------
    Two matrices with the eigenvectors (1, 1)/√2 and (1, −1)/√2 in common:

    >>> q = np.array([[1.0, 1.0], [1.0, -1.0]]) / np.sqrt(2)
    >>> m = np.stack([q @ np.diag([3.0, 1.0]) @ q.T, q @ np.diag([1.0, 5.0]) @ q.T])
    >>> v = joint_rotation(m)
    >>> bool(np.allclose(np.abs(v.T @ q).max(axis=0), 1.0))
    True
    """
    a = np.array(matrices, dtype=float)
    d = a.shape[1]
    if d == 2:  # one pair: its turn from the identity is the optimum, in closed form
        angle = float(_turn_angles(a, np.array([0]), np.array([1]))[0])
        cos, sin = math.cos(angle), math.sin(angle)
        return np.array([[cos, -sin], [sin, cos]])
    _, v = np.linalg.eigh(a.sum(axis=0))
    a = v.T @ a @ v
    rounds = _round_robin(d)
    for _ in range(JACOBI_SWEEPS):
        turned = False
        for p, q in rounds:
            angle = _turn_angles(a, p, q)
            sin = np.sin(angle)
            if not np.any(np.abs(sin) > tolerance):
                continue
            cos = np.cos(angle)
            turned = True
            for m in (a, a.swapaxes(1, 2)):  # columns p, q, then rows p, q
                mp, mq = m[..., p], m[..., q]
                m[..., p], m[..., q] = cos * mp + sin * mq, cos * mq - sin * mp
            vp, vq = v[:, p], v[:, q]
            v[:, p], v[:, q] = cos * vp + sin * vq, cos * vq - sin * vp
        if not turned:
            break
    return v


CENTRING_STEPS = 4
"""Fixed-point steps of :func:`centring_corrected`. Each moves the reflections by the
bootstrap's bias at the last step's model. On 4,000 windows of 10 epochs of an AR(1) with
φ = 0.5, Burg's pooled φ̂ is 0.31 and the corrected one 0.50 (0.50 and 0.002 at order 2);
eight steps moved the median v_10 of 20 runs of 40 such windows by 2 % (2.31 → 2.36, true
2.6)."""
REFLECTION_LIMIT = 0.999
"""Largest |reflection| a corrected model takes (a stationary AR model has |k_j| < 1)."""


def centring_corrected(fit: BurgFit, orders, t: int, seed: int) -> BurgFit:
    """``fit`` with each series' reflections up to its order corrected for the centring of
    each of its runs.

    Burg's pooled fit of runs of t epochs, each centred on its own mean, is biased towards
    less memory by O(τ/t) (within-group estimation of an autoregression, Nickell 1981):
    over windows of 10 epochs of an AR(1) with φ = 0.5 it gives φ̂ ≈ 0.31, so τ̂ ≈ 1.9
    for τ = 3, and that bias does not fall with the number of runs. The correction is the
    fixed point of k = k̂ − (E k̂*(k) − k) (bootstrap bias correction, iterated; Efron &
    Tibshirani 1993, Ch. 10), with k̂ the fit's reflections at each series' order and
    E k̂*(k) the mean of the reflections refitted, at that order, to
    :data:`BOOTSTRAP_REPLICATES` series drawn from the model with reflections k in runs of
    t epochs, each centred (at most BOOTSTRAP_EPOCHS // t runs), :data:`CENTRING_STEPS`
    steps from k = k̂, each |k_j| at most :data:`REFLECTION_LIMIT`.

    Parameters
    ----------
    fit : BurgFit
        Burg's fit of k series, each pooled over ``fit.segments`` runs of ``t`` epochs.
    orders : numpy.ndarray of int, shape (k,)
        Each series' order (0: left as it is).
    t : int
        Epochs per run.
    seed : int
        Seeds the draws (with t, the runs and the largest order).

    Returns
    -------
    BurgFit
        ``fit`` itself for one run or no series of order > 0; else a copy whose
        reflections up to each series' order are corrected (the others, and the
        innovation variances, as they were).

    References
    ----------
    S. Nickell, "Biases in dynamic models with fixed effects", Econometrica 49(6), 1981.
    B. Efron and R. J. Tibshirani, *An Introduction to the Bootstrap*, Chapman & Hall, 1993.
    """
    orders = np.asarray(orders, dtype=int)
    rows = np.flatnonzero(orders > 0)
    runs = fit.segments
    if runs < 2 or rows.size == 0:
        return fit
    p = int(orders.max())
    within = np.arange(p)[None, :] < orders[rows, None]
    target = np.where(within, fit.reflection[rows, :p], 0.0)
    k = target.copy()
    drawn = min(runs, max(1, BOOTSTRAP_EPOCHS // t))
    b = BOOTSTRAP_REPLICATES
    gen = np.random.default_rng(np.random.SeedSequence([seed, t, runs, p, rows.size]))
    for _ in range(CENTRING_STEPS):
        draws = np.empty((rows.size, b * drawn, t))
        for j, i in enumerate(rows.tolist()):
            phi = ar_coefficients(k[j, : orders[i]])
            stationary_draws(phi, gen, b * drawn, t, out=draws[j])
        draws -= draws.mean(axis=2, keepdims=True)
        refit = burg(draws.reshape(rows.size * b, drawn, t), p).reflection
        mean = refit.reshape(rows.size, b, p).mean(axis=1)
        k = np.where(within, np.clip(target - (mean - k), -REFLECTION_LIMIT, REFLECTION_LIMIT), 0.0)
    reflection = fit.reflection.copy()
    reflection[rows, :p] = np.where(within, k, reflection[rows, :p])
    return replace(fit, reflection=reflection)


def fit_memory(
    s: np.ndarray,
    q: np.ndarray,
    runs: int = 1,
    order: int | None = None,
    screened: bool = False,
    cover: int | None = None,
) -> Memory:
    """The :class:`Memory` of whitened errors and their centred NEES: an AR sieve per
    principal direction.

    The errors are rotated to their :func:`principal_directions`; each direction and q is
    cut to each run's first :data:`SIEVE_EPOCHS` epochs, centred (per run), scaled by a
    power of two, and fitted by :func:`burg` with the order of least AICc. The principal
    directions are chosen to differ, so fitted apart the first of them get too much
    memory and the last too little. From :data:`SELECTED_FROM` directions on (one run),
    the directions whose long-run variance does not stand out beyond that selection
    share one model fitted on them together (:func:`_distinct_directions`); with fewer,
    or runs pooled, where AICc cannot tell the directions' memories apart
    (:func:`_common_model`), a direction whose own model shows less memory than their
    common model takes the common one. Where BIC, whose choice of order 0 is consistent,
    finds no memory in any series and the caller's lag-1 screening (``screened``, on short
    segments) found no dependence either, the errors are taken as independent (the exact
    tests apply, :attr:`Memory.white`). AICc, an efficient criterion for a sieve (Shibata
    1980), chooses the order of each series where there is memory. Otherwise every series gets
    at least :data:`MIN_ORDER` (on runs shorter than :data:`FORCED_BELOW` epochs, or when
    ``screened``), and the models' estimation error and bias come from the parametric
    bootstrap (:func:`bootstrap_spread`).

    Parameters
    ----------
    s : numpy.ndarray, shape (N, d)
        The whitened errors, N = runs × T epochs of ``runs`` equal runs one after the other
        (pooled: one model, each run centred on its own mean).
    q : numpy.ndarray, shape (N,)
        Their centred NEES.
    runs : int, default 1
        The runs pooled in ``s`` and ``q``; taken as 1 when it is below 1 or does not
        divide N.
    order : int, optional
        The largest AR order; default :func:`max_order` of the epochs fitted,
        min(T, :data:`SIEVE_EPOCHS`).
    screened : bool, default False
        Whether the caller's lag-1 screening found dependence: then the errors are never
        taken as white, and every series gets at least :data:`MIN_ORDER`.
    cover : int, optional
        The longest window the model will judge: each autocorrelation is kept up to this
        lag at least (and on to where it decays), where the default is T, every lag of
        the fit. A run's model judges windows much shorter than the run, and its
        autocorrelations past their decay are only zeros held (and shipped to every
        worker and back with every result).

    Returns
    -------
    Memory
        The principal directions, one :class:`SeriesMemory` per direction and one for q.

    Raises
    ------
    NoFiniteMemory
        When a fitted model has a root on the unit circle to working precision, so that
        its Yule–Walker system is singular.

    References
    ----------
    K. N. Berk, "Consistent autoregressive spectral estimates", Ann. Stat. 2(3), 1974.
    C. M. Hurvich and C.-L. Tsai, "Regression and time series model selection in small
    samples", Biometrika 76(2), 1989.
    G. Schwarz, "Estimating the dimension of a model", Ann. Stat. 6(2), 1978.
    E. J. Hannan and B. G. Quinn, "The determination of the order of an autoregression",
    J. R. Stat. Soc. B 41(2), 1979.
    R. Shibata, "Asymptotically efficient selection of the order of the model for
    estimating parameters of a linear process", Ann. Stat. 8(1), 1980.

    Examples
    --------
    An AR(2) with complex roots (oscillating errors, τ = 1.889): the sieve finds it.

    >>> from scipy.signal import lfilter
    >>> rng = np.random.default_rng(1)
    >>> x = lfilter([1], [1, -1.6, 0.8], rng.standard_normal((20_000, 1)), axis=0)
    >>> m = fit_memory(x / x.std(), (x[:, 0] / x.std()) ** 2)
    >>> m.series[0].order >= 2, bool(abs(m.series[0].variance_ratio - 1.889) < 0.2)
    (True, True)
    """
    s = np.asarray(s, dtype=float)
    n, d = s.shape
    if runs < 1 or n % runs:
        runs = 1
    t = n // runs
    directions = principal_directions(s, runs)
    # the sieve is fitted on each run's first SIEVE_EPOCHS epochs at most (only they are
    # rotated; a segment no longer than that is s itself)
    fitted_t = min(t, SIEVE_EPOCHS)
    first = s.reshape(runs, t, d)[:, :fitted_t].reshape(-1, d)
    y = (first @ directions).T.reshape(d, runs, fitted_t)
    qs = np.asarray(q, dtype=float).reshape(1, runs, t)[:, :, :fitted_t]
    stacked = np.concatenate([y, qs], axis=0)
    stacked = stacked - stacked.mean(axis=2, keepdims=True)
    stacked = stacked / power_of_two_unit(stacked.reshape(d + 1, -1), axis=1)[:, None, None]
    p_max = max_order(fitted_t) if order is None else int(order)
    fit = burg(stacked, p_max)
    if not screened and not np.any(np.argmin(fit.bic(), axis=1)):
        white = SeriesMemory(np.zeros(0), np.ones(1), math.inf)
        return Memory(directions, (white,) * d, white, n, runs)
    # short or screened: every series at least AR(1); else AICc's order, 0 included
    minimum = min(MIN_ORDER, p_max) if screened or t < FORCED_BELOW else 0
    orders = fit.orders(minimum)
    lifted: list[int] = []  # the directions that take the shared model
    selected = d >= SELECTED_FROM and runs == 1
    if selected:  # the directions whose memory is not their own share one model
        seed = int(orders.sum())
        k, common = _distinct_directions(y, first, orders, minimum, p_max, seed)
        lifted = list(range(k, d)) if common is not None else []
    else:  # one for all where AICc prefers it
        common = _common_model(fit, stacked[:d], orders, minimum, p_max, runs) if d > 1 else None
    if runs > 1:  # Burg's fit of short runs, each centred, has less memory than the runs
        fit = centring_corrected(fit, orders, fitted_t, int(orders.sum()))
    if common is not None:
        pooled, p = common
        if runs > 1:
            pooled = centring_corrected(pooled, [p], fitted_t, p)
        if not selected:  # a direction with less memory than the common model takes it
            shared_tau = _log_taus(pooled.reflection, [p])[0]
            lifted = np.flatnonzero(_log_taus(fit.reflection[:d], orders[:d]) < shared_tau)
            lifted = lifted.tolist()
    keep = [i for i in range(d + 1) if i not in lifted]
    # the bootstrap draws runs of the epochs fitted, each centred as the fit centred them
    memories = dict(
        zip(
            keep, _fitted_memories(fit, orders, minimum, p_max, fitted_t, t, cover, keep, runs=runs)
        )
    )
    if lifted:  # the shared model's refits pool as many series as its fit did
        pooled_rows = len(lifted) if selected else d
        shared = _fitted_memories(
            pooled, [p], minimum, p_max, fitted_t, t, cover, [0], segments=pooled_rows, runs=runs
        )
        memories.update(dict.fromkeys(lifted, shared[0]))
    return Memory(directions, tuple(memories[i] for i in range(d)), memories[d], n, runs)


def _log_taus(reflection: np.ndarray, orders) -> np.ndarray:
    """log max(τ, 1) of AR models from their reflection coefficients k_j (rows) at
    ``orders``, without forming the autocorrelation: γ(0) = σ²_p/Π(1 − k_j²) and
    A(1) = Π(1 + k_j) (Levinson's step at z = 1), so τ = σ²_p/(A(1)²γ(0)) =
    Π_{j <= p} (1 − k_j)/(1 + k_j)."""
    steps = np.log1p(-reflection) - np.log1p(reflection)
    cumulative = np.concatenate([np.zeros((steps.shape[0], 1)), np.cumsum(steps, axis=1)], axis=1)
    return np.maximum(cumulative[np.arange(len(orders)), np.asarray(orders, dtype=int)], 0.0)


def _fitted_memories(fit, orders, minimum, p_max, n, t, cover, picked, segments=1, runs=1) -> list:
    """One :class:`SeriesMemory` for each series of ``fit`` in ``picked`` at its order, with
    the bootstrap's spread of every one of order > 0 (one bootstrap call, seeded by their
    orders; ``segments`` series of ``runs`` runs of ``n`` epochs per replicate for a model
    fitted on that many)."""
    orders = np.asarray(orders)
    spreads: dict = {}
    fitted = [int(i) for i in picked if orders[i] > 0]
    try:  # the models' Yule–Walker systems: singular only for a root on the unit circle
        if fitted:
            phis = [fit.coefficients(i, int(orders[i])) for i in fitted]
            search = min(p_max, 2 * int(orders[fitted].max()) + 4)
            seed = int(orders[list(picked)].sum())
            spread, bias, square = bootstrap_spread(phis, n, search, seed, minimum, segments, runs)
            for i, v, b, w in zip(fitted, spread, bias, square):
                # runs pooled: the fit is corrected for their centring already
                # (centring_corrected), and the bootstrap's bias is that one
                spreads[i] = (v, b if runs == 1 else 0.0, w)
        floor = t if cover is None else min(t, int(cover))
        return [series_memory(fit, int(i), floor, spreads.get(int(i)), minimum) for i in picked]
    except np.linalg.LinAlgError as exc:
        raise NoFiniteMemory(str(exc)) from exc


ROTATION_PENALTY = 2.0
"""AIC's charge for each angle of the principal directions, d(d − 1)/2 of them, when one
memory per direction is weighed against one memory for all (:func:`_common_model`): the
directions are fitted to the data, and on them even directions of one memory differ."""


def _common_model(fit, y, orders, minimum, p_max, runs):
    """One AR model for every principal direction, where AICc cannot tell the directions'
    memories apart; else None. Weighed for two directions, and for runs pooled
    (:data:`SELECTED_FROM`).

    Fitted apart, d directions of one memory get d different models by chance, and the
    principal directions make it worse: they are chosen to differ most in memory, so the
    last of them gets the least (two directions of
    AR(1) φ = 0.9, τ = 19, N = 300: median τ̂ 0.74 τ on that direction, 0.87 τ where it
    takes the common model; ``tests/test_memory.py``). One
    model fitted on all of them (each scaled to unit mean square, as segments of one
    series, which Burg pools) has d times the epochs and no selection.

    The two are weighed by their Gaussian likelihoods from one-step prediction errors on
    the epochs both predict (Burg's σ²_p is not the common model's error on a direction
    whose own coefficients differ): AICc for each direction's p_i + 1 parameters and the
    directions' angles (:data:`ROTATION_PENALTY`), against the common p coefficients and
    d variances over d·N epochs.

    Parameters
    ----------
    fit : BurgFit
        The fit of the directions' series (rows 0 … d − 1) and of q.
    y : numpy.ndarray, shape (d, runs, T)
        The directions' centred series.
    orders : numpy.ndarray of int
        The AICc orders of ``fit``'s series.
    minimum, p_max : int
        The smallest and largest orders; the common model's order is at most
        2 max_i p_i + 4 (the bootstrap's search).
    runs : int
        The runs pooled in each series.

    Returns
    -------
    tuple of (BurgFit, int), or None
        The common model's fit and its AICc order, or None where the directions' own
        models fit better.
    """
    d, _, t = y.shape
    z = _unit_rows(y)
    pooled, p = _pooled_fit(z, orders, minimum, p_max)
    first = max(p, int(orders[:d].max()))
    epochs = runs * (t - first)
    own = [_log_mean_square(z[i], fit.coefficients(i, int(orders[i])), first) for i in range(d)]
    params = orders[:d] + 1
    own_cost = epochs * sum(own) + float(np.sum(aicc_penalty(params, epochs)))
    own_cost += ROTATION_PENALTY * d * (d - 1) / 2
    common = pooled.coefficients(0, p)
    shared = sum(_log_mean_square(z[i], common, first) for i in range(d))
    count, many = p + d, d * epochs
    if epochs * shared + aicc_penalty(count, many) > own_cost:
        return None
    return pooled, p


def _unit_rows(y: np.ndarray) -> np.ndarray:
    """The directions' series ``y`` (d, runs, T), each scaled to unit mean square."""
    unit = np.sqrt(np.mean(y * y, axis=(1, 2)))
    return y / np.where(unit > 0, unit, 1.0)[:, None, None]


def _pooled_fit(z: np.ndarray, orders, minimum: int, p_max: int) -> tuple[BurgFit, int]:
    """One AR model of the directions' series ``z`` (d, runs, T) together, pooled by
    Burg's recursion as segments of one series, and its AICc order: at most 2 max_i p_i + 4
    of the directions' own ``orders`` (the bootstrap's search; a model that needs many
    more lags than any direction's is no common description of them), at least
    ``minimum``."""
    d, runs, t = z.shape
    search = min(p_max, 2 * int(np.max(orders[:d])) + 4)
    pooled = burg(z.reshape(1, d * runs, t), search)
    return pooled, int(pooled.orders(min(minimum, search))[0])


def _one_unit(y: np.ndarray) -> np.ndarray:
    """The directions' series ``y`` in one unit, a power of two (:func:`credcli.engine.
    units.power_of_two_unit`): pooled so, each direction counts by its own variance, and
    the pooled fit is that of any rotation of them. Scaled each to unit mean square, the
    directions that the rotation found with little variance (the data's, by chance) would
    count as much as the others: 16 directions of one AR(1) φ 0.8 over 600 epochs gave a
    pooled φ̂ of 0.765–0.785 so, 0.79–0.81 in one unit."""
    return y / power_of_two_unit(y)


SELECTED_FROM = 3
"""Fewest principal directions whose selection :func:`_distinct_directions` weighs (on a
segment, one run): from three directions on, a direction keeps a model of its own only
where its long-run variance stands out beyond what picking the most persistent of them
gives, and the others share one model fitted on them together. Two directions are one
angle apart; there the directions' common model is weighed by AICc
(:func:`_common_model`), and a direction keeps its own model where it shows more memory
than the common one. Measured on the zoo (``benchmarks/memory.py``, seed 20240), giving
both directions the common model wherever AICc prefers it raised the false alarms of
slow + white errors (φ 0.99, 70 % slow) 2 → 7 of 70, where the first direction's
selection offsets the sieve's short-segment underestimate."""
DISTINCT_LEVEL = 0.1
"""Upper tail of :func:`_distinct_directions`' null beyond which a principal direction's
long-run variance is its own: a direction of the common memory keeps a model of its own
(with the selection's excess memory) in about one segment of ten, erring towards more
memory."""
DISTINCT_REPLICATES = 40
"""Sets of directions drawn from the shared model by :func:`_distinct_directions`: the
90th percentile of 40 draws lies between their 33rd and 39th (a binomial 95 % interval)."""
DISTINCT_EPOCHS = 1 << 12
"""Most epochs :func:`_distinct_directions` reads and draws: the selection matters where a
segment is short against its directions' number; 4,096 epochs of 30 directions, 40 times,
are 39 MB."""
DISTINCT_DRAWN = 1 << 24
"""Most values :func:`_distinct_directions` draws at once, burn-in included (128 MB). A
model whose decay horizon is longer than :data:`EXACT_START_BEYOND` starts its draws from
its stationary distribution (:func:`started_filter`) and draws no burn-in; one whose
factor is not positive definite to working precision (a root nearer the unit circle)
takes the burn-in this allows, and may start short of stationarity, on segments whose
memory leaves them undecided anyway."""


def _long_run_ratios(x: np.ndarray) -> np.ndarray:
    """How far each principal direction's long-run variance stands out, for each of a
    batch of sets of series.

    Parameters
    ----------
    x : numpy.ndarray, shape (B, T, d)
        B sets of d series (centred here; not overwritten).

    Returns
    -------
    numpy.ndarray, shape (B, d)
        λ_j / mean(λ_j … λ_{d−1}), j = 0 … d − 1, of the generalised eigenvalues
        λ_0 >= … >= λ_{d−1} of the Bartlett long-run covariance (bandwidth ⌈√T⌉, as
        :func:`principal_directions`) against the lag-0 covariance: the j-th direction's
        τ against the mean of the directions from it on. Eigenvalues are invariant to a
        rotation of the series, so the principal directions need not be found.
    """
    _, t, d = x.shape
    x = x - x.mean(axis=1, keepdims=True)
    band = max(1, min(t - 1, math.ceil(math.sqrt(t))))
    gamma = np.einsum("bti,btj->bij", x, x)
    sums = moving_sums(x, band + 1)
    omega = np.einsum("bti,btj->bij", sums, sums) / (band + 1)
    w, v = np.linalg.eigh(gamma)
    scaled = v / np.sqrt(np.maximum(w, np.finfo(float).tiny))[:, None, :]
    lam = np.linalg.eigvalsh(np.swapaxes(scaled, 1, 2) @ omega @ scaled)[:, ::-1]
    tails = np.cumsum(lam[:, ::-1], axis=1)[:, ::-1] / np.arange(d, 0, -1)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(tails > 0, lam / tails, 1.0)


def _distinct_directions(y, s, orders, minimum: int, p_max: int, seed: int):
    """How many of the first principal directions have a memory of their own, and the model
    the others share.

    The principal directions are ordered by their long-run variance
    (:func:`principal_directions`), so on d directions of one memory the first ones' own
    fits show more memory than the truth, and the more so the more directions there are
    (30 independent white directions over 300 epochs: τ̂ 4.6–14.5 on the first, where the
    truth is 1), and a chance long-memory candidate in one of them is the rule. A step
    down: for j = 0, 1, …, the directions j … d − 1 are fitted one AR model together
    (:func:`_pooled_fit`); :data:`DISTINCT_REPLICATES` sets of d − j independent series are
    drawn from it (unit innovations, stationary by a burn-in); and direction j has a memory
    of its own where its long-run variance against the mean of the directions from it on
    (:func:`_long_run_ratios`) lies above the upper :data:`DISTINCT_LEVEL` quantile of the
    same ratio for the first direction of each drawn set: a parametric bootstrap of the
    selection under the hypothesis that the d − j directions share one memory (Efron &
    Tibshirani 1993, Ch. 16). The first j that does not stand out ends the count, and the
    directions from it on share the model fitted on them. One slow direction among many
    white ones stands out at j = 0 and the white ones share a white model; 30 white
    directions share one from j = 0.

    Parameters
    ----------
    y : numpy.ndarray, shape (d, 1, T)
        The principal directions' series (centred here, and pooled in one unit,
        :func:`_one_unit`).
    s : numpy.ndarray, shape (T, d)
        The same errors before the rotation (the ratios do not depend on it); the first
        :data:`DISTINCT_EPOCHS` epochs are read, and drawn.
    orders : numpy.ndarray of int
        The directions' own AICc orders (the shared model's search, :func:`_pooled_fit`).
    minimum, p_max : int
        The shared models' smallest and largest orders.
    seed : int
        Seeds the draws together with the shape.

    Returns
    -------
    k : int
        The directions with a memory of their own, the first k.
    shared : tuple of (BurgFit, int), or None
        The model of directions k … d − 1 and its order; None where fewer than two are
        left (each keeps its own model).
    """
    d = y.shape[0]
    t = min(s.shape[0], DISTINCT_EPOCHS)
    observed = _long_run_ratios(s[None, :t])[0]
    gen = np.random.default_rng(np.random.SeedSequence([seed, t, d, p_max]))
    b = DISTINCT_REPLICATES
    y = y - y.mean(axis=2, keepdims=True)
    for j in range(d - 1):
        pooled, p = _pooled_fit(_one_unit(y[j:]), orders[j:d], minimum, p_max)
        phi = pooled.coefficients(0, p)
        burn, factor = draws_start(phi)
        if factor is None:  # a burn-in, within the draws' budget
            burn = min(burn, max(0, DISTINCT_DRAWN // (b * (d - j)) - t))
            drawn = ar_filter(phi, gen.standard_normal((t + burn, b * (d - j))))[burn:]
        else:  # a slow model's series from its stationary start (stationary_draws)
            drawn = started_filter(phi, gen.standard_normal((t, b * (d - j))), factor)
        null = _long_run_ratios(drawn.reshape(t, b, d - j).transpose(1, 0, 2))[:, 0]
        if not observed[j] > np.quantile(null, 1.0 - DISTINCT_LEVEL):
            return j, (pooled, p)
    return d - 1, None


def _log_mean_square(x: np.ndarray, phi: np.ndarray, first: int) -> float:
    """log of the mean square of x_t − Σ_j φ_j x_{t−j} over epochs t >= ``first`` of each
    segment (rows of ``x``, shape (m, T))."""
    e = x[:, first:].copy()
    for j, c in enumerate(phi, start=1):
        e -= c * x[:, first - j : x.shape[1] - j]
    return math.log(max(float(np.mean(e * e)), np.finfo(float).tiny))


def studentized_tail(z: float, dof: float) -> float:
    """The upper tail of Student's t, or of the normal when ν is infinite.

    Parameters
    ----------
    z : float
        The point.
    dof : float
        ν, the degrees of freedom (``math.inf``: the normal).

    Returns
    -------
    float
        P(T_ν >= z).

    Examples
    --------
    >>> round(studentized_tail(1.96, math.inf), 4), round(studentized_tail(2.0, 4.0), 4)
    (0.025, 0.0581)
    """
    if not math.isfinite(dof):
        return float(special.ndtr(-z))
    return float(special.stdtr(dof, -z))


def studentized_quantile(p: float, dof: float) -> float:
    """The upper quantile of Student's t, or of the normal when ν is infinite.

    The inverse of :func:`studentized_tail` in ``z``.

    Parameters
    ----------
    p : float
        The upper-tail probability, in (0, 1).
    dof : float
        ν, the degrees of freedom (``math.inf``: the normal).

    Returns
    -------
    float
        The z with P(T_ν >= z) = p.
    """
    if not math.isfinite(dof):
        return float(-special.ndtri(p))
    return float(-special.stdtrit(dof, p))


def mean_free(s: np.ndarray, inverse: np.ndarray, overwrite: bool = False) -> np.ndarray:
    r"""The whitened errors less their fitted constants: the residuals the memory is fitted on.

    The least-squares fit is by a constant in whitened space and a constant in the log's
    space, s_k ≈ m + L_k⁻¹b. A bias of either kind turns into a slowly varying whitened
    error when the claimed covariance turns, and a memory model fitted on it would read
    the bias as memory, inflating τ̂ and taking degrees of freedom from the mean test
    (docs/measured.md). Under the null the 2d regressors cost 2d of N·d degrees of
    freedom.

    Parameters
    ----------
    s : numpy.ndarray, shape (N, d)
        The whitened errors s_k = F_k e_k.
    inverse : numpy.ndarray, shape (N, d, d)
        The whitening factors F_k = Σ_k^{-1/2}, one per epoch
        (:func:`credcli.engine.linalg.whitening_factors`; a constant covariance's are
        one factor broadcast).
    overwrite : bool, default False
        Whether the residuals may be made in ``s`` itself (a caller's own copy: a
        segment of millions of epochs then holds one array of them, not three).

    Returns
    -------
    numpy.ndarray, shape (N, d)
        s_k − m̂ − F_k b̂ (with one covariance the two constants are one, and the
        least-squares solution of least norm fits them).
    """
    n, d = s.shape
    # the sums are those of inverse/unit, whose squares cannot overflow; within SAFE_UNIT
    # of 1 they are taken on the inverse and divided after, which gives the same bits
    # (rounding commutes with a power of two) without a copy of the inverse
    unit = power_of_two_unit(inverse)
    safe = 1.0 / SAFE_UNIT <= unit <= SAFE_UNIT
    inv = inverse if safe else inverse / unit
    after = unit if safe else 1.0
    normal = np.empty((2 * d, 2 * d))
    normal[:d, :d] = n * np.eye(d)
    normal[:d, d:] = inv.sum(axis=0) / after
    normal[d:, :d] = normal[:d, d:].T
    normal[d:, d:] = np.einsum("nki,nkj->ij", inv, inv) / (after * after)
    rhs = np.concatenate([s.sum(axis=0), np.einsum("nki,nk->i", inv, s) / after])
    coef = np.linalg.lstsq(normal, rhs, rcond=None)[0]
    out = np.subtract(s, coef[:d], out=s if overwrite else None)
    constant = coef[d:] / after
    for sl in epoch_chunks(n):  # bounded temporaries; each epoch's product is its own
        out[sl] -= np.einsum("nij,j->ni", inv[sl], constant)
    return out


SAFE_UNIT = 2.0**200
"""Largest power-of-two unit (and 1/SAFE_UNIT the smallest) of the inverse factors whose
sums of products :func:`mean_free` takes without rescaling them: the largest products, near
the unit squared, then stay far inside float64's range (2^±400 of 2^±1022), and the sums
divided by the unit after are the bits of the sums of the rescaled copy wherever no product
leaves the normal range, which only products too small to change a sum's bits can."""


SCALE_CHECK_LEVEL = 0.01
"""Level of the check that the fitted memory explains the variance at long averaging times
(:func:`time_scales`), Bonferroni over the scales it tests and the whole segment's lowest
frequency: a correct model loses at most 1 % of its verdicts to it."""
MIN_SCALE_BLOCKS = 8
"""Fewest blocks at an averaging time (the χ² of the check then has d·7 degrees of freedom)."""


@dataclass(frozen=True)
class TimeScales:
    r"""The errors' variance at every averaging time, against what the claim and the fitted
    memory predict: in the spirit of the Allan variance of the whitened errors (IEEE Std
    952), with the memory model as the reference instead of white noise.

    The scales are m = 1, 2, 4, … epochs (at least :data:`MIN_SCALE_BLOCKS` blocks of m
    epochs); every array below has one entry per scale. The longest scales hold too few
    blocks for that check, and long memory (ARFIMA) shows there first, so the whole
    segment is checked as well, at its lowest Fourier frequency. One check at one level:
    a check of each of K tested scales and of the lowest frequency at level/(K + 1).
    Made by :func:`time_scales`.

    Attributes
    ----------
    epochs : numpy.ndarray of int
        The averaging times m.
    observed : numpy.ndarray
        m times the variance of the m-epoch means of the whitened residuals (each principal
        direction in units of its own variance, averaged over directions).
    predicted : numpy.ndarray
        The model's v_m (:meth:`SeriesMemory.mean_ratio`, averaged over directions; 1 at
        every m for independent errors).
    low, high : numpy.ndarray
        The central 1 − level interval of ``observed`` under the model (a χ² with
        d(K − 1) degrees of freedom for K blocks).
    pvalues : numpy.ndarray
        The upper-tail p-value at each scale.
    tested : numpy.ndarray of bool
        The scales long enough against the fitted correlation time (m >= 2τ̂, m >= 2) to
        enter the check.
    pvalue : float or None
        Bonferroni over the tested scales and the lowest frequency (one family at
        :data:`SCALE_CHECK_LEVEL`); None on segments too short for any block.
    lowest_ratio, lowest_pvalue : float or None, default None
        The whole segment's check (:func:`lowest_frequency_check`): the periodogram of
        the whitened residuals at the lowest Fourier frequency 2π/N, summed over the
        directions in units of what the model predicts there and divided by d, and its
        p-value against Gamma(d, 1); None on segments too short for any block.
    """

    epochs: np.ndarray
    observed: np.ndarray
    predicted: np.ndarray
    low: np.ndarray
    high: np.ndarray
    pvalues: np.ndarray
    tested: np.ndarray
    pvalue: float | None
    lowest_ratio: float | None = None
    lowest_pvalue: float | None = None

    @property
    def lowest_failed(self) -> bool:
        """Whether the whole segment varies more than the model explains, at its share of
        :data:`SCALE_CHECK_LEVEL` (Bonferroni with the tested scales)."""
        count = int(self.tested.sum()) + 1
        return self.lowest_pvalue is not None and self.lowest_pvalue * count < SCALE_CHECK_LEVEL

    @property
    def failed_at(self) -> int | None:
        """The shortest tested averaging time whose variance the model does not explain at
        the check's level, or None."""
        if self.pvalue is None or self.pvalue >= SCALE_CHECK_LEVEL:
            return None
        count = int(self.tested.sum()) + (self.lowest_pvalue is not None)
        bad = self.tested & (self.pvalues * count < SCALE_CHECK_LEVEL)
        return int(self.epochs[np.flatnonzero(bad)[0]]) if bad.any() else None


def time_scales(y: np.ndarray, memory: Memory, level: float = SCALE_CHECK_LEVEL) -> TimeScales:
    """The variance of the whitened residuals at every averaging time, under ``memory``.

    Parameters
    ----------
    y : numpy.ndarray, shape (N, d)
        The mean-free whitened residuals (:func:`mean_free`), in the frame the model was
        fitted in.
    memory : Memory
        The dependence model fitted on them.
    level : float, default SCALE_CHECK_LEVEL
        The level of the intervals [``low``, ``high``] at each scale.

    Returns
    -------
    TimeScales
        Observed and predicted variance ratios, intervals and p-values per scale, the
        Bonferroni p-value of the check, and the lowest frequency's check.

    Notes
    -----
    With K = ⌊N/m⌋ blocks of m epochs, block sums S_{ji} in direction i (centred over the
    blocks) and γ̂_i the direction's variance (its sum of squares over the expected
    centred sum, :meth:`SeriesMemory.centred_square_moments`), the statistic at scale m
    is Σ_i Σ_j S_{ji}² / (m γ̂_i v_{i,m}), referred to χ² with d(K − 1) degrees of freedom.
    The scales are powers of two, so each block sum is the sum of two at half the scale:
    one pass over the epochs for all scales, where a sum per scale made one each.
    """
    n, d = y.shape
    rotated = y @ memory.directions
    variances = np.array(
        [
            float(rotated[:, i] @ rotated[:, i]) / series.centred_square_moments(n)[0]
            for i, series in enumerate(memory.series)
        ]
    )
    variances = np.where(variances > 0, variances, 1.0)
    tau = float(np.max(memory.variance_ratios))
    lowest_ratio, lowest_pvalue = lowest_frequency_check(rotated, memory, variances)
    rows = []
    m = 1
    block_sums = rotated  # at scale m, each the sum of two at scale m/2
    while n // m >= MIN_SCALE_BLOCKS:
        k = n // m
        sums = block_sums
        half = n // (2 * m)
        if half >= MIN_SCALE_BLOCKS:  # the next scale's sums, before these are centred
            block_sums = sums[0 : 2 * half : 2] + sums[1 : 2 * half : 2]
        # centred and squared in place: no copy of the N × d residuals at the scale of one
        sums = np.subtract(sums, sums.mean(axis=0), out=sums)
        ratios = np.array([series.mean_ratio(m) for series in memory.series])
        per_direction = np.sum(np.square(sums, out=sums), axis=0) / ((k - 1) * m * variances)
        observed = float(np.mean(per_direction))
        predicted = float(np.mean(ratios))
        dof = d * (k - 1)
        statistic = float(np.sum(per_direction / ratios)) * (k - 1)
        low = predicted * float(special.chdtri(dof, 1 - level / 2)) / dof
        high = predicted * float(special.chdtri(dof, level / 2)) / dof
        rows.append((m, observed, predicted, low, high, float(special.chdtrc(dof, statistic))))
        m *= 2
    if not rows:
        empty = np.zeros(0)
        return TimeScales(empty, empty, empty, empty, empty, empty, np.zeros(0, bool), None)
    table = np.array(rows)
    epochs = table[:, 0].astype(int)
    tested = epochs >= max(2.0, 2.0 * tau)
    pvalues = table[:, 5]
    family = np.append(pvalues[tested], lowest_pvalue)
    pvalue = float(min(1.0, family.min() * family.size))
    return TimeScales(
        epochs,
        table[:, 1],
        table[:, 2],
        table[:, 3],
        table[:, 4],
        pvalues,
        tested,
        pvalue,
        lowest_ratio,
        lowest_pvalue,
    )


LOWEST_CHECKED = 1e-9
"""Smallest expected periodogram at the lowest frequency, relative to the size of the sum
that gives it, that :func:`lowest_frequency_check` trusts (below: cancellation)."""


def lowest_frequency_check(
    rotated: np.ndarray, memory: Memory, variances: np.ndarray
) -> tuple[float, float]:
    r"""The whole segment against the model: the periodogram at the lowest Fourier frequency.

    An AR sieve cannot follow long memory (spectral density unbounded at frequency zero,
    ARFIMA d > 0): the variance it leaves unexplained is largest at the lowest frequency,
    where the block scales of :func:`time_scales` hold too few blocks to see it.

    Parameters
    ----------
    rotated : numpy.ndarray, shape (N, d)
        Each direction's series x, in the model's frame (the residuals times
        ``memory.directions``).
    memory : Memory
        The dependence model.
    variances : numpy.ndarray, shape (d,)
        γ̂₀ of each direction's series.

    Returns
    -------
    ratio, pvalue : tuple of float
        S/d' and P(Gamma(d', 1) ≥ S), S the sum over the d' directions whose model predicts
        power there of the periodogram over that expectation; (NaN, 1.0) where no
        direction's does (memory spanning the segment, which the resolution rule
        declines).

    Notes
    -----
    At ω₁ = 2π/N the periodogram is I = |Σ_t x_t e^{−iω₁t}|²/N, and under the model

    .. math:: E\,I(ω_1) = γ_0 \Big[1 + 2\sum_{h=1}^{N-1} (1 - h/N)\,ρ(h) \cos(ω_1 h)\Big]

    (exact for a stationary series; the mean does not enter at a Fourier frequency). Under
    the model each ratio is about Exp(1) and the directions are independent, so their sum
    S is Gamma(d, 1).

    References
    ----------
    P. J. Brockwell and R. A. Davis, *Time Series: Theory and Methods*, 2nd ed., 1991,
    Thm 10.3.2 (periodogram ordinates are asymptotically independent exponentials with
    the spectral density as mean).
    """
    n, d = rotated.shape
    # |Σ x_t e^{−iω₁t}|² as (Σ x_t cos ω₁t)² + (Σ x_t sin ω₁t)²: two real products, where
    # one complex product made a complex copy of the series; on a segment of millions of
    # epochs every temporary is an array of N numbers, so the lags are floats from the
    # start (exact below 2⁵³), the sines overwrite the angles and (1 − h/N) cos(ω₁h) is
    # made in the array of h/N
    angle = np.arange(n, dtype=float)
    angle *= 2.0 * np.pi
    angle /= n
    cosine = np.cos(angle)
    np.sin(angle, out=angle)
    ordinate = ((cosine @ rotated) ** 2 + (angle @ rotated) ** 2) / n
    del angle
    weights = np.arange(1, n, dtype=float)
    weights /= n
    np.subtract(1.0, weights, out=weights)
    weights *= cosine[1:]
    del cosine
    expected = np.array([1.0 + 2.0 * float(weights @ m.window(n)[1:]) for m in memory.series])
    # a model whose memory spans the segment predicts almost no power at 2π/N (none for a
    # constant), and the sum above cancels to rounding, or below zero where the bias
    # correction stretched ρ: such a direction has no prediction to check
    checked = expected > LOWEST_CHECKED * (1.0 + 2.0 * np.abs(weights).sum())
    if not checked.any():
        return math.nan, 1.0
    total = float(np.sum(ordinate[checked] / (variances[checked] * expected[checked])))
    count = int(checked.sum())
    return total / count, float(special.gammaincc(count, total))
