r"""Long memory: a fractional candidate beside the AR sieve of :mod:`credcli.engine.memory`.

An AR(p) sieve estimates the long-run variance consistently for short-memory processes
(Berk 1974), but errors whose autocorrelation decays as a power of the lag, ρ(h) ∝ h^{2d−1}
with 0 < d < 1/2 (fractional integration, long memory), have no finite long-run variance:
the variance of a mean of N epochs falls as N^{2d−1}, not 1/N, and a sieve of the orders a
segment allows stops the rise of the spectrum short of frequency zero. Fitted to ARFIMA
errors with d = 0.3, the sieve gives a mean's variance ratio v_N of 3–8 where it is 28
(N = 300) and 86 (N = 2,000), and the location test says "bias" on a third to a half of
credible segments.

So each principal direction is also fitted an ARFIMA(p, d, 0) model,

.. math:: (1 - B)^d\,A(B)\,x_t = u_t,

by conditional sums of squares (Chung & Baillie 1993; Beran 1995): for d on a grid
(:data:`FRACTIONS`) the series is fractionally differenced (the binomial expansion of
(1 − B)^d truncated at the series' start) and fitted by Burg's recursion, p and d by the
corrected AIC. Whether the memory is short or long is decided by BIC's charge for d
(:func:`_fractional_fits`), so short-memory errors keep their AR model (none of 200 white
series; no SE(3) filter run of ``benchmarks/se3.py``) while most ARFIMA d = 0.3 series of
2,000 epochs take the fractional one. Short memory has a second shape beside the sieve's,
the ARMA(p, 1) (:func:`_moving_average_fits`): an AR(1) under white noise, the slow + white
errors of issue 30, is an ARMA(1, 1) whose nearly cancelling roots the sieve needs many
lags for, and fractional noise mimics it with one parameter; so a fractional model is
taken only where it also fits better than the best ARMA(p, 1). Where it is chosen and
implies more memory over the segment than the direction's own model, the direction takes
it (:func:`with_long_memory`); a direction's memory is never shortened. Where the data
support the fractional model (its AICc within :data:`SUPPORT` of the sieve's, Burnham &
Anderson 2002, and no ARMA(p, 1) beating it by BIC's margin) and it is not taken, or an
ARMA(p, 1) that fits better than the sieve and within :data:`SUPPORT` of the best, the
model keeps the one implying the most memory as its ``alternative``, in every direction
that has less memory of its own (:func:`_weak_alternative`), under which a bias and a
scale finding must hold as well (:func:`credcli.engine.evidence.memory_evidence`).
Directions that share one model (from three directions on, those whose memory does not
stand out of the principal directions' selection, :func:`credcli.engine.memory.
_distinct_directions`) are fitted their candidates together, as one series of their
epochs, and take one choice (:func:`_pooled_choice`).

The model's autocorrelation is exact (:func:`arfima_autocorrelation`), so every test of
the engine reads the variance of a window mean, of a centred sum of squares and of sign
blocks from it as from an AR model; its estimation error, d included, comes from a
parametric bootstrap of the fitted model (:func:`fractional_spread`: series drawn by
circulant embedding, refitted within the class).

References
----------
K.-Y. Chung and R. T. Baillie, "Small sample bias in conditional sum-of-squares estimators
of fractionally integrated ARMA models", Empirical Economics 18(4), 1993.
J. Beran, "Maximum likelihood estimation of the differencing parameter for invertible short
and long memory autoregressive integrated moving average models", J. R. Stat. Soc. B 57(4),
1995.
R. B. Davies and D. S. Harte, "Tests for Hurst effect", Biometrika 74(1), 1987.
J. R. M. Hosking, "Fractional differencing", Biometrika 68(1), 1981.
G. Schwarz, "Estimating the dimension of a model", Ann. Stat. 6(2), 1978.
K. P. Burnham and D. R. Anderson, *Model Selection and Multimodel Inference*, 2nd ed.,
Springer, 2002.
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import NamedTuple

import numpy as np
from scipy import special

from credcli.engine.memory import (
    BOOTSTRAP_EPOCHS,
    BOOTSTRAP_REPLICATES,
    Memory,
    NoFiniteMemory,
    SeriesMemory,
    ar_filter,
    autocovariance_of_ar,
    burg,
    corrected_memory,
    decay_horizon,
    max_order,
    mean_variance_ratio,
)
from credcli.engine.units import power_of_two_unit

FRACTIONS = 0.05 * np.arange(1, 10)
"""The grid of the fractional order d (0.05 … 0.45) searched beside d = 0: a step of 0.05
is about one standard error of d̂ on 300 epochs (√(6/π²N) = 0.045, Beran 1995)."""
FIT_EPOCHS = 1 << 16
"""Most epochs the candidates are fitted on: a longer segment's first 2^16 (its errors are
stationary under the model; d̂ on 65,536 epochs has a standard error near 0.003, Beran
1995), so a segment of millions of epochs costs the fit of 65,536."""
FEWEST_EPOCHS = 32
"""Shortest series given a fractional candidate: on fewer epochs a rise of the spectrum at
low frequencies rests on a handful of periodogram ordinates."""
SUPPORT = 2.0
"""AICc margin within which a fractional model that BIC does not take is still a memory the
data support, and so the model's ``alternative``: a model within 2 of the best has
substantial support (Burnham & Anderson 2002, Sec. 2.6). With the margin 0 (AICc prefers
it) 27 and 23 % of the zoo's credible ARFIMA d = 0.3 segments of 50 and 300 epochs were
false alarms (seed 20240); with the margin 2, 13 and 13 %, at a cost of 5 of 490 detections
of a 1σ bias at N/τ >= 30 on each of two seeds (docs/measured.md). It loses that
support where an ARMA(p, 1) fits better by BIC's margin (log T − 2 beyond AICc's), evidence
against long memory as firm as what takes a fractional model over the sieve (session 24)."""


MOVING_AVERAGES = np.array([-0.9, -0.8, -0.7, -0.6, -0.45, -0.3, -0.15, 0.15, 0.3, 0.45])
"""The grid of θ of the short-memory ARMA(p, 1) candidate that a fractional model has to
beat (:func:`_moving_average_fits`): an AR(1) plus white noise, the slow + white mixture of
issue 30, is an ARMA(1, 1) whose θ is negative (−0.73 for φ 0.9 with 70 % white), and its
near-cancelling roots are what an AR sieve needs many lags for and fractional noise
mimics with one parameter."""

NEAR_UNIT_MOVING_AVERAGES = np.array([-0.98, -0.95])
"""θ beyond :data:`MOVING_AVERAGES`' end, tried only where fractional noise runs to the
grid's top (:func:`_fractional_fits`): a random walk under white noise has θ near −1, and on
the grid's end, −0.9, an ARMA passes it off as an AR root at 0.95–0.98. Not in the grid
itself: there they would mimic fractional noise too (ARFIMA d 0.3 at 2,000 epochs took
its fractional model less often, and its v_N fell to half the truth)."""

UNIT_ROOT_MARGIN = 30.0
"""Fewest correlation times 1/(1 − r) of the slowest root r of an ARMA(p, 1) model's AR
part that the fitted series must hold, T(1 − r) >= 30, for that model to count as memory
the series settles from where it fits better than fractional noise at the grid's top
(:func:`_fractional_fits`). T(r − 1) is Dickey & Fuller's normalised-bias statistic of a unit
root; 30 is beyond its 1 % point with a fitted mean and trend (−29.5 for large T; −20.7
with a mean alone: W. A. Fuller, Introduction to Statistical Time Series, 1976, Table
8.5.1, as in J. D. Hamilton, Time Series Analysis, 1994, Table B.5; a simulation of 4,000
random walks of 2,000 steps here gave −30.5 and −20.4). Measured on 2,000 epochs: random
walks of steps 0.05 under unit white noise (six seeds; five run to the top) give
T(1 − r) 3.6–26; slow + white (0.98, 85 % white), whose fractional fit runs to the top
in 6 of 20 segments, 54 in the one looked at (θ −0.9, φ 0.973)."""


def fractional_difference(x: np.ndarray, d: float) -> np.ndarray:
    """(1 − B)^d x along the last axis, the expansion truncated at the series' start.

    Parameters
    ----------
    x : numpy.ndarray, shape (..., T)
        The series.
    d : float or numpy.ndarray
        The fractional order; an array of shape x.shape[:-1] gives each series its own.

    Returns
    -------
    numpy.ndarray
        y_t = Σ_{k <= t} π_k x_{t−k}, π_0 = 1, π_k = π_{k−1}(k − 1 − d)/k, in the shape of
        ``x`` (one FFT convolution).

    Examples
    --------
    d = 1 is the first difference (the first epoch kept):

    >>> fractional_difference(np.array([1.0, 3.0, 6.0]), 1.0).round(12).tolist()
    [1.0, 2.0, 3.0]
    """
    t = x.shape[-1]
    k = np.arange(1, t)
    d = np.asarray(d, dtype=float)[..., None]
    weights = np.concatenate(
        [np.ones(d.shape), np.cumprod((k - 1.0 - d) / k, axis=-1)], axis=-1
    ).reshape(d.shape[:-1] + (t,))
    size = 1 << (2 * t - 1).bit_length()
    product = np.fft.rfft(x, size, axis=-1) * np.fft.rfft(weights, size)
    return np.fft.irfft(product, size, axis=-1)[..., :t]


def fractional_autocovariance(d: float, lags: int) -> np.ndarray:
    """γ(0) … γ(lags − 1) of fractional noise (1 − B)^{−d} u, unit innovations.

    Parameters
    ----------
    d : float
        The fractional order, below 1/2.
    lags : int
        How many lags (at least 1).

    Returns
    -------
    numpy.ndarray, shape (lags,)
        γ(0) = Γ(1 − 2d)/Γ(1 − d)² times ρ(h), ρ(h) = ρ(h − 1)(h − 1 + d)/(h − d)
        (Hosking 1981, Biometrika 68(1)).
    """
    h = np.arange(1, lags)
    rho = np.concatenate([[1.0], np.cumprod((h - 1.0 + d) / (h - d))])
    return rho * math.exp(special.gammaln(1.0 - 2.0 * d) - 2.0 * special.gammaln(1.0 - d))


def arfima_autocorrelation(phi: np.ndarray, d: float, lags: int) -> np.ndarray:
    """ρ(0) … ρ(lags − 1) of the ARFIMA(p, d, 0) (1 − B)^d A(B) x = u.

    Parameters
    ----------
    phi : numpy.ndarray, shape (p,)
        The AR part's coefficients (stationary).
    d : float
        The fractional order, in [0, 1/2).
    lags : int
        How many lags (at least 1).

    Returns
    -------
    numpy.ndarray, shape (lags,)
        The autocorrelation.

    Notes
    -----
    x is the AR filter 1/A(B) applied to fractional noise, so its autocovariance is the
    noise's convolved with the AR filter's own (unit innovations):
    γ_x(h) = Σ_m γ_A(m) γ_d(h + m), m over the AR's decay horizon in both directions.
    """
    if phi.size == 0:
        gamma = fractional_autocovariance(d, lags)
        return gamma / gamma[0]
    span = decay_horizon(phi, 1)
    kernel = autocovariance_of_ar(phi, 1.0, span)
    kernel = np.concatenate([kernel[:0:-1], kernel])  # lags −(span − 1) … span − 1
    noise = fractional_autocovariance(d, lags + span)
    reach = np.abs(np.arange(-(span - 1), lags + span - 1))
    size = 1 << (reach.size + kernel.size).bit_length()
    full = np.fft.irfft(np.fft.rfft(noise[reach], size) * np.fft.rfft(kernel, size), size)
    gamma = full[kernel.size - 1 : kernel.size - 1 + lags]
    return gamma / gamma[0]


def _moving_average_fits(
    x: np.ndarray, p_max: int, thetas: np.ndarray = MOVING_AVERAGES
) -> tuple[np.ndarray, list]:
    """Each series' best ARMA(p, 1) model, θ on the grid ``thetas`` and
    p = 0 … ``p_max``, fitted as the fractional candidates are: the series is filtered by
    (1 + θB)⁻¹ from a zero state (conditional sums of squares) and fitted by Burg's
    recursion, θ charged as one more parameter.

    Parameters
    ----------
    x : numpy.ndarray, shape (k, T) or (k, m, T)
        Centred series, each of one segment or pooled over m segments (Burg's recursion
        pools them).
    p_max : int
        The largest AR order.
    thetas : numpy.ndarray, default MOVING_AVERAGES
        The grid of θ.

    Returns
    -------
    costs : numpy.ndarray, shape (k,)
        The least AICc of each series over θ and p.
    models : list of (float, numpy.ndarray)
        (θ, φ) of each series' model of least AICc.
    """
    x = x[:, None, :] if x.ndim == 2 else x
    k, m, t = x.shape
    # (1 + θB)u = x is u_t = x_t − θ u_{t−1}: the AR filter with coefficient −θ
    filtered = np.stack([ar_filter(np.array([-theta]), x.T).T for theta in thetas])
    fit = burg(filtered.reshape(-1, m, t), p_max)
    flat = fit.aicc(extra=1).reshape(thetas.size, k, p_max + 1)
    flat = flat.transpose(1, 0, 2).reshape(k, -1)
    best = np.argmin(flat, axis=1)
    grid, orders = np.divmod(best, p_max + 1)
    models = [
        (float(thetas[g]), fit.coefficients(int(g) * k + j, int(p)))
        for j, (g, p) in enumerate(zip(grid.tolist(), orders.tolist()))
    ]
    return flat[np.arange(k), best], models


def arma_autocorrelation(phi: np.ndarray, theta: float, lags: int) -> np.ndarray:
    """ρ(0) … ρ(lags − 1) of the ARMA(p, 1) A(B) x = (1 + θB) u.

    Parameters
    ----------
    phi : numpy.ndarray, shape (p,)
        The AR part's coefficients (stationary; empty: an MA(1)).
    theta : float
        The MA coefficient θ.
    lags : int
        How many lags (at least 1).

    Returns
    -------
    numpy.ndarray, shape (lags,)
        The autocorrelation.

    Notes
    -----
    x is the MA filter 1 + θB applied to the AR process y = u/A(B), so
    γ_x(h) = (1 + θ²) γ_y(h) + θ (γ_y(|h − 1|) + γ_y(h + 1)).

    Examples
    --------
    An MA(1) has ρ(1) = θ/(1 + θ²) and nothing beyond:

    >>> arma_autocorrelation(np.zeros(0), 0.5, 3).round(12).tolist()
    [1.0, 0.4, 0.0]
    """
    if phi.size:
        gamma = autocovariance_of_ar(phi, 1.0, lags + 1)
    else:
        gamma = np.r_[1.0, np.zeros(lags)]
    previous = np.r_[gamma[1], gamma[: lags - 1]]  # γ_y(|h − 1|)
    x = (1.0 + theta * theta) * gamma[:lags] + theta * (previous + gamma[1 : lags + 1])
    return x / x[0]


def _fractional_fits(x: np.ndarray, p_max: int, choose: bool = True):
    """Each series' model: the AR sieve (d = 0) or ARFIMA(p, d, 0), d on the grid
    :data:`FRACTIONS`, orders 0 … ``p_max``.

    Within each class the order (and d) is the one of least AICc, as in the sieve. A
    fractional model is taken only where its AICc is also below the best ARMA(p, 1)'s
    (:func:`_moving_average_fits`, θ charged as d is): short memory that an MA part
    describes is no evidence of long memory. Between the classes, d costs BIC's log T
    instead of AICc's 2: whether the memory is short or
    long is a yes-or-no question, which BIC answers consistently (Schwarz 1978) where AIC
    keeps choosing the larger class with a fixed probability when the smaller one holds.
    On real filter errors, whose spectra are sums of a few AR shapes, AICc's 2 took a
    fractional model on one direction in most SE(3) runs of 6,000 epochs (AICc gains 0–5;
    ARFIMA d = 0.3 gives gains above 10 at 2,000 epochs in two runs of three).

    The sieve here has no smallest order: a forced AR(1) (:data:`~credcli.engine.memory.
    MIN_ORDER`) would weigh as much as fractional noise, which would then win half the
    time on white errors. The grid is searched coarse (every other point) and then at the
    two neighbours of the best coarse point, for 6 Burg fits per series instead of 9.

    Parameters
    ----------
    x : numpy.ndarray, shape (k, T) or (k, m, T)
        Centred series, each of one segment or pooled over m segments (the directions
        that share a model, :func:`_pooled_choice`); BIC's log T is then log mT.
    p_max : int
        The largest order.
    choose : bool, default True
        Whether to choose the class; False: every series gets its best fractional model
        (the bootstrap's refits of a fractional model, :func:`fractional_spread`).

    Returns
    -------
    _Choice
        Per series: d (0: the AR sieve), p and φ of the model taken (its AR part where
        d > 0); whether the choice was weak (the fractional model's AICc within
        :data:`SUPPORT` of the sieve's, BIC not taking it, and no ARMA(p, 1) beating it by
        BIC's margin, log T − 2 beyond AICc's: the evidence that takes a fractional model
        over the sieve, here against long memory); the best fractional model's
        (d, φ), taken or not; whether the best ARMA(p, 1) is a supported alternative (its
        AICc below the sieve's and within :data:`SUPPORT` of the best of the three), and
        its (θ, φ).
    """
    x = x[:, None, :] if x.ndim == 2 else x
    k, m, t = x.shape
    log_epochs = math.log(m * t)
    step = float(FRACTIONS[1] - FRACTIONS[0])
    coarse = FRACTIONS[1::2]
    fit = burg(
        np.stack([x] + [fractional_difference(x, g) for g in coarse]).reshape(-1, m, t), p_max
    )
    sieve_cost = fit.aicc()[:k]
    plain = sieve_cost.min(axis=1)
    fractional = fit.aicc(extra=1)[k:].reshape(coarse.size, k, p_max + 1)
    best = np.argmin(fractional.min(axis=2), axis=0)
    centre = coarse[best]
    neighbours = [centre - step, centre + step]
    near = burg(
        np.stack([fractional_difference(x, f[:, None]) for f in neighbours]).reshape(-1, m, t),
        p_max,
    )
    # the candidates of each series: the best coarse d, then its two neighbours
    fractions = np.stack([centre, *neighbours])
    costs = np.concatenate(
        [fractional[best, np.arange(k)][None], near.aicc(extra=1).reshape(2, k, p_max + 1)]
    )
    flat = costs.transpose(1, 0, 2).reshape(k, -1)
    chosen = np.argmin(flat, axis=1)
    which, orders = np.divmod(chosen, p_max + 1)
    # the class (short or long memory) by BIC: d costs log T where AICc charges 2, and so
    # does the MA coefficient of the short-memory ARMA(p, 1) models (an AR(1) under white
    # noise, which fractional noise mimics on a few hundred epochs and the sieve needs many
    # lags for), so a fractional model is taken where it beats the sieve by log T − 2 and
    # the ARMA models outright
    cost = flat[np.arange(k), chosen]
    moving, arma = _moving_average_fits(x, p_max) if choose else (np.full(k, np.inf), [])
    # (at the grid's top the errors are no more stationary than d = 1/2 allows, whatever
    # an ARMA with a root near the unit circle makes of them: no finite memory; unless an
    # ARMA fits them better with a root the series settles from)
    top = fractions[which, np.arange(k)] >= FRACTIONS[-1] - 1e-9
    if choose and top.any():
        rows = np.flatnonzero(top)
        edge, edge_arma = _moving_average_fits(x[rows], p_max, NEAR_UNIT_MOVING_AVERAGES)
        for i, j in enumerate(rows.tolist()):
            if min(edge[i], moving[j]) >= cost[j]:
                continue  # fractional noise at the top fits better: no finite memory
            phi = edge_arma[i][1] if edge[i] < moving[j] else arma[j][1]
            top[j] = t * (1.0 - slowest_root(phi)) < UNIT_ROOT_MARGIN
    # a fractional model the data support, unless an ARMA(p, 1) beats it by the margin that
    # takes a fractional model over the sieve (BIC's log T − 2 beyond AICc): short memory
    # the data choose as firmly as they would choose long memory over the sieve
    preferred = (cost < plain + SUPPORT) & ~(moving + (log_epochs - 2.0) < cost)
    taken = (cost + (log_epochs - 2.0) < plain) & ((cost < moving) | top)
    if not choose:
        taken[:] = True
    candidates = []
    for j in range(k):
        if which[j] == 0:
            phi = fit.coefficients(k * (1 + int(best[j])) + j, int(orders[j]))
        else:
            phi = near.coefficients(k * (int(which[j]) - 1) + j, int(orders[j]))
        candidates.append((float(fractions[which[j], j]), phi))
    sieve = np.argmin(sieve_cost, axis=1)
    # an ARMA(p, 1) the data prefer to the sieve, within SUPPORT of the best model of all
    arma_weak = (moving < plain) & (moving < np.minimum(plain, cost) + SUPPORT)
    return _Choice(
        np.where(taken, [c[0] for c in candidates], 0.0),
        np.where(taken, orders, sieve),
        [
            c[1] if taken[j] else fit.coefficients(j, int(sieve[j]))
            for j, c in enumerate(candidates)
        ],
        preferred & ~taken,
        candidates,
        arma_weak,
        arma,
    )


def slowest_root(phi: np.ndarray) -> float:
    """The largest modulus r of the roots of an AR polynomial's characteristic equation,
    z^p − φ₁z^{p−1} − … − φ_p = 0 (0 for p = 0): the model is stationary for r < 1, and its
    slowest component decays as r^h, over about 1/(1 − r) lags.

    Parameters
    ----------
    phi : numpy.ndarray, shape (p,)
        The AR coefficients φ₁ … φ_p.

    Returns
    -------
    float
        r.

    Examples
    --------
    >>> round(slowest_root(np.array([1.49, -0.495])), 12)  # roots 0.99 and 0.5
    0.99
    """
    return float(np.max(np.abs(np.roots(np.r_[1.0, -phi])))) if phi.size else 0.0


class _Choice(NamedTuple):
    """What :func:`_fractional_fits` chose for each series."""

    fractions: np.ndarray  # d of the model taken (0: the AR sieve)
    orders: np.ndarray  # its AR order
    coefficients: list  # its AR coefficients
    weak: np.ndarray  # AICc within SUPPORT of the sieve's, not taken, no ARMA far better
    candidates: list  # (d, φ) of the best fractional model, taken or not
    arma_weak: np.ndarray  # the best ARMA(p, 1) beats the sieve, AICc within SUPPORT of the best
    arma: list  # (θ, φ) of the best ARMA(p, 1) (empty without the class choice)


def _longer_memory(phi: np.ndarray, fraction: float, n: int, own) -> np.ndarray | None:
    """ρ over ``n`` lags of the ARFIMA(p, d, 0) with AR part ``phi`` and d = ``fraction``
    where it implies more memory over the segment than the direction's model ``own`` (a
    larger v_n); None where it does not, or where its AR part has a root on the unit
    circle."""
    rho = _fractional_rho(phi, fraction, n)
    return rho if rho is not None and mean_variance_ratio(rho) > own.mean_ratio(n) else None


def _fractional_rho(phi: np.ndarray, fraction: float, n: int) -> np.ndarray | None:
    """ρ over ``n`` lags of the ARFIMA(p, d, 0) with AR part ``phi`` and d = ``fraction``
    (:func:`arfima_autocorrelation`); None where its AR part has a root on the unit
    circle."""
    try:
        return arfima_autocorrelation(phi, fraction, n)
    except np.linalg.LinAlgError:
        return None


def _circulant_draws(gamma: np.ndarray, count: int, gen: np.random.Generator) -> np.ndarray:
    """``count`` Gaussian series with autocovariance ``gamma`` (length T), by circulant
    embedding (Davies & Harte 1987): exact where the embedding's eigenvalues are
    nonnegative, as for fractional noise; a negative one (a short, strongly correlated
    model) is set to zero. One complex FFT gives two independent series."""
    t = gamma.size
    circle = np.concatenate([gamma, gamma[-2:0:-1]])
    root = np.sqrt(np.clip(np.fft.fft(circle).real, 0.0, None) / circle.size)
    pairs = (count + 1) // 2
    z = gen.standard_normal((pairs, circle.size)) + 1j * gen.standard_normal((pairs, circle.size))
    w = np.fft.fft(root * z, axis=1)[:, :t]
    return np.concatenate([w.real, w.imag])[:count]


def fractional_spread(
    phi: np.ndarray, d: float, n: int, p_max: int, seed: int
) -> tuple[float, float, float]:
    """The estimation error of a fitted ARFIMA(p, d, 0) model's memory (parametric
    bootstrap, as :func:`credcli.engine.memory.bootstrap_spread` for AR models).

    B = :data:`~credcli.engine.memory.BOOTSTRAP_REPLICATES` series of ``n`` epochs (at most
    :data:`~credcli.engine.memory.BOOTSTRAP_EPOCHS`) are drawn from the model, centred and
    refitted within its class (d on the grid and p by AICc: the error of d̂ given long
    memory, whose downward bias in small samples is corrected; the choice of the class
    itself is not bootstrapped, as BIC's choice rarely errs where it is made); the variance
    and bias of log v_n* (the variance ratio of an n-epoch mean, which long memory makes
    grow with n) and the variance of log τ₂* (τ₂ = Σ_{h<n} ρ(h)²) are returned, scaled by
    min(1, BOOTSTRAP_EPOCHS/n).

    Parameters
    ----------
    phi : numpy.ndarray
        The AR part.
    d : float
        The fractional order.
    n : int
        Epochs behind the fit.
    p_max : int
        The largest AR order of the refits.
    seed : int
        Seeds the draws together with ``n`` and ``p_max``.

    Returns
    -------
    var_log_v, bias_log_v, var_log_tau2 : tuple of float
    """
    # the trailing 7 keeps these draws apart from the AR models' bootstrap stream
    gen = np.random.default_rng(np.random.SeedSequence([seed, n, p_max, 7]))
    shrink = min(1.0, BOOTSTRAP_EPOCHS / n)
    n = min(n, BOOTSTRAP_EPOCHS)
    rho = arfima_autocorrelation(phi, d, n)
    draws = _circulant_draws(rho, BOOTSTRAP_REPLICATES, gen)
    draws -= draws.mean(axis=1, keepdims=True)
    fractions, _, coefficients, *_ = _fractional_fits(draws, p_max, choose=False)
    logs, squares = np.empty(draws.shape[0]), np.empty(draws.shape[0])
    for i, (g, refit) in enumerate(zip(fractions, coefficients)):
        r = arfima_autocorrelation(refit, float(g), n)
        logs[i] = math.log(max(mean_variance_ratio(r), 1.0))
        squares[i] = math.log(float(np.sum(r * r)))
    truth = math.log(max(mean_variance_ratio(rho), 1.0))
    return (
        float(np.var(logs, ddof=1)) * shrink,
        (float(np.mean(logs)) - truth) * shrink,
        float(np.var(squares, ddof=1)) * shrink,
    )


def with_long_memory(memory: Memory, residuals: np.ndarray) -> Memory:
    """``memory`` with each principal direction's fractional model where the data choose it
    and it implies more memory over the segment.

    Parameters
    ----------
    memory : Memory
        The AR sieve's model of ``residuals`` (:func:`credcli.engine.memory.fit_memory`).
    residuals : numpy.ndarray, shape (N, d)
        The mean-free whitened residuals it was fitted on; the candidates are fitted on
        the first :data:`FIT_EPOCHS` of them at most. A fractional model keeps its
        autocorrelation at every lag of the segment (it never decays below rounding).

    Returns
    -------
    Memory
        ``memory`` itself where no direction changes (white errors, pooled runs, segments
        shorter than :data:`FEWEST_EPOCHS`, or the AR sieve chosen everywhere); else a copy
        whose changed directions hold a :class:`~credcli.engine.memory.SeriesMemory` with
        ``fraction`` d > 0, and whose ``alternative`` holds the weakly chosen fractional
        or ARMA(p, 1) model of most memory (:func:`_weak_alternative`), where there is one.

    Raises
    ------
    NoFiniteMemory
        Where a direction's fractional model is chosen at the top of the grid (d = 0.45):
        the likelihood still rises towards d = 1/2, where the errors stop being stationary
        (a drift, a random walk; a time offset's error), and no mean over the segment
        settles; unless an ARMA(p, 1) model fits the direction better with a root the
        segment settles from (:data:`UNIT_ROOT_MARGIN`).
    """
    n = residuals.shape[0]
    if memory.white or memory.segments != 1 or n < FEWEST_EPOCHS:
        return memory
    units = [rows for _, rows in memory.pooled_groups()]
    x, search = _direction_series(memory, residuals, units)
    choice = _pooled_choice(x, search, units)
    fractions, orders, weak = choice.fractions, choice.orders, choice.weak
    if np.any(fractions >= FRACTIONS[-1] - 1e-9):
        raise NoFiniteMemory(
            f"a fractional order at the grid's top, {FRACTIONS[-1]:g}: the errors are no "
            "more stationary than d = 1/2 allows"
        )
    series = list(memory.series)
    for rows in units:
        i = rows[0]
        if not fractions[i] > 0:
            continue
        phi, fraction = choice.coefficients[i], float(fractions[i])
        rho = _longer_memory(phi, fraction, n, series[i])
        if rho is None:
            continue
        spread = fractional_spread(phi, fraction, n, search, int(orders[i]) + i)
        log_v = math.log(mean_variance_ratio(rho))
        taken = corrected_memory(phi, rho, log_v, spread, fraction)
        for j in rows:  # the directions that share a model share its fractional one
            series[j] = taken
    alternative = _weak_alternative(series, weak, choice, x, n, search, units)
    if alternative is None and all(new is old for new, old in zip(series, memory.series)):
        return memory
    chosen = replace(memory, series=tuple(series))
    if alternative is None:
        return chosen
    return replace(chosen, alternative=replace(chosen, series=alternative))


def white_alternative(memory: Memory, residuals: np.ndarray) -> Memory | None:
    """``memory``, a white model (BIC takes no memory in any direction), with the
    alternative with more memory that its residuals support, or None where they support
    none (or the model is not white, pools runs, or has fewer than
    :data:`FEWEST_EPOCHS` epochs).

    The candidates are those of :func:`with_long_memory` (fractional noise that AICc
    supports or BIC takes, an ARMA(p, 1) that AICc prefers to the sieve), but the model
    stays white: BIC took no memory, and the alternative serves only to check that a bias
    the independent mean test finds holds under more memory as well
    (:func:`credcli.engine.evidence.memory_evidence`). Weak memory that lasts, an ARMA(1, 1)
    with nearly cancelling roots such as a slow part under 90 % white noise, is what BIC
    misses on hundreds of epochs and what makes an independent mean test reject too often.
    Fitted only where that test rejects, so a credible segment pays nothing for it.

    Parameters
    ----------
    memory : Memory
        The white model.
    residuals : numpy.ndarray, shape (N, d)
        The mean-free whitened residuals it was fitted on.

    Returns
    -------
    Memory or None
        ``memory`` with its ``alternative``, or None.
    """
    n = residuals.shape[0]
    if not memory.white or memory.segments != 1 or n < FEWEST_EPOCHS:
        return None
    units = [rows for _, rows in memory.pooled_groups()]
    x, search = _direction_series(memory, residuals, units)
    choice = _pooled_choice(x, search, units)
    weak = choice.weak | (choice.fractions > 0)  # a fractional model BIC takes: more so
    series = list(memory.series)
    alternative = _weak_alternative(series, weak, choice, x, n, search, units)
    if alternative is None:
        return None
    return replace(memory, alternative=replace(memory, series=alternative))


def _direction_series(
    memory: Memory, residuals: np.ndarray, units: list[list[int]]
) -> tuple[np.ndarray, int]:
    """The residuals in the model's principal directions, centred and scaled to a unit of
    their own, one for each group in ``units`` (:meth:`~credcli.engine.memory.Memory.
    pooled_groups`; a row per direction, at most :data:`FIT_EPOCHS` epochs), and the
    largest AR order of the candidates fitted to them."""
    x = (residuals[:FIT_EPOCHS] @ memory.directions).T
    x = x - x.mean(axis=1, keepdims=True)
    for rows in units:
        x[rows] /= power_of_two_unit(x[rows])
    # the fractional part carries the memory the sieve's orders were reaching for, so its
    # AR part needs no more lags than the bootstrap's search beyond the directions' own
    search = min(max_order(residuals.shape[0]), 2 * max(m.order for m in memory.series) + 4)
    return x, search


def _pooled_choice(x: np.ndarray, p_max: int, units: list[list[int]]) -> _Choice:
    """:func:`_fractional_fits` of each direction (rows of ``x``), where each group of
    directions that share a model is fitted together: its rows, in one unit
    (:func:`_direction_series`, as the sieve pooled them: :func:`credcli.engine.memory.
    _one_unit`), pooled as segments of one series, and the one choice is every row's.

    The directions share a model where their memory does not stand out of the principal
    directions' selection (:func:`credcli.engine.memory._distinct_directions`), and the
    principal directions are ordered by their memory: fitted apart, the first of them
    shows the most by selection, and among many directions a chance long-memory candidate
    in one of them is the rule (30 independent white directions over 300 epochs, one
    white model shared: a fractional model "fits" a direction in 2 of 20 segments and
    fractional noise at the grid's top a third, and 4 more lose their location to a weak
    candidate of one direction, ``benchmarks/dimensions.py``). Pooled, the candidate is
    judged on all their epochs, without selection. A fractional model the group takes
    gets the estimation error of one direction's fit (:func:`fractional_spread` draws one
    series), larger than the pooled fit's: its degrees of freedom err low.
    """
    if all(len(rows) == 1 for rows in units):
        return _fractional_fits(x, p_max)
    fields: dict = {name: [None] * x.shape[0] for name in _Choice._fields}
    alone = [rows[0] for rows in units if len(rows) == 1]
    fits = [(_fractional_fits(x[alone], p_max), [[i] for i in alone])] if alone else []
    # each group in one unit (:func:`_direction_series`), as the sieve pooled it
    fits += [(_fractional_fits(x[rows][None], p_max), [rows]) for rows in units if len(rows) > 1]
    for choice, groups in fits:
        for name, values in choice._asdict().items():
            for value, rows in zip(values, groups):
                for i in rows:
                    fields[name][i] = value
    arrays = ("fractions", "orders", "weak", "arma_weak")
    return _Choice(**{k: np.array(v) if k in arrays else v for k, v in fields.items()})


def _weak_alternative(
    series: list,
    weak: np.ndarray,
    choice: _Choice,
    x: np.ndarray,
    n: int,
    p_max: int,
    units: list[list[int]],
):
    """The directions' models with the memory the data weakly support, or None where no
    direction has any.

    A weakly chosen fractional model (AICc within :data:`SUPPORT` of the sieve's, not
    taken as the model, no ARMA(p, 1) beating it by BIC's margin) is a memory the segment
    cannot rule out in its direction; so is an ARMA(p, 1) that the data prefer to the
    sieve and that is within :data:`SUPPORT` of the best model (``choice.arma_weak``,
    ``choice.arma``: :func:`_fractional_fits`; an AR(1) under white noise, whose slow part
    a short segment's sieve fits too little, or long memory that an ARMA with a root near
    the unit circle describes as well). Each direction takes its own such model where it
    implies more memory over the segment than the direction's model
    (:func:`mean_variance_ratio`).

    Such a memory may be shared by other directions, which show it less: the principal
    directions are ordered by their fitted memory, so a direction that shares the long
    memory shows it less by selection (two independent ARFIMA(0, 0.3, 0) components of
    300 epochs: on the segments whose mean was called a bias, the second direction's fit
    gave v_N 2–5, the truth 28). So one model of those classes is fitted on the directions
    together (:func:`_shared_model`: the direction of most such memory and every direction
    with less memory of its own), and where their pooled data support it as one direction
    supports its weak candidate, it is each such direction's alternative too, where it
    implies more memory than the direction's own. The pooled fit does not select by
    memory, as each direction's own fit does. Where one direction's weak memory is not
    the others' (a slow heading error beside a fast position error, or a chance candidate
    among many independent directions) the pooled data do not support it, or the model
    fitted on all of them has little memory, and the others keep their own: giving the
    weak memory of any direction to every direction (the rule before session 36) made a
    chance candidate of one of 15 independent directions every direction's alternative,
    and a 1σ bias over 300 independent epochs was found in 9 of 20 segments, 20 of 20
    since (``benchmarks/dimensions.py``, docs/measured.md).

    Its degrees of freedom are the direction's own (no bootstrap): the alternative serves
    only to check that a location or scale finding holds under more memory as well
    (:func:`credcli.engine.evidence.memory_evidence`), and more degrees of freedom make
    that check reject more readily, so it declines no more findings than a bootstrap
    would."""
    firsts = [rows[0] for rows in units]  # a group's choice is each of its rows'
    fitted = []  # (v_n, model, origin) of each direction's weakly supported memory
    for i in [i for i in firsts if weak[i]]:
        fraction, phi = choice.candidates[i]
        rho = None if fraction >= FRACTIONS[-1] - 1e-9 else _fractional_rho(phi, fraction, n)
        if rho is not None:
            fitted.append((mean_variance_ratio(rho), (fraction, 0.0, phi, rho), i))
    for i in [i for i in firsts if choice.arma_weak[i]]:
        theta, phi = choice.arma[i]
        try:
            rho = arma_autocorrelation(phi, theta, n)
        except np.linalg.LinAlgError:  # a root on the unit circle: no ARMA memory to hold
            continue
        if np.all(np.isfinite(rho)):
            fitted.append((mean_variance_ratio(rho), (0.0, theta, phi, rho), i))
    if not fitted:
        return None
    ratios = [own.mean_ratio(n) for own in series]
    best: list = [None] * len(series)  # (v_n, model) of each direction's alternative
    for ratio, model, origin in fitted:
        if ratio > ratios[origin] and (best[origin] is None or ratio > best[origin][0]):
            best[origin] = (ratio, model)
    most, _, origin = max(fitted, key=lambda f: f[0])
    rows = [origin] + [i for i, r in enumerate(ratios) if i != origin and r < most]
    if len(rows) > 1:
        classes = {model[1] == 0.0 for _, model, _ in fitted}  # True: fractional
        shared = _shared_model(x[rows], classes, n, p_max)
        if shared is not None:
            ratio, model = shared
            for i in rows:
                if ratio > ratios[i] and (best[i] is None or ratio > best[i][0]):
                    best[i] = shared
    for rows in units:  # a group's rows take one alternative, the one of most memory
        held = [best[j] for j in rows if best[j] is not None]
        if held:
            most_held = max(held, key=lambda b: b[0])
            for j in rows:
                best[j] = most_held
    if all(b is None for b in best):
        return None
    out = list(series)
    for rows in units:  # one model object per group: its directions share its error
        chosen = best[rows[0]]
        if chosen is not None:
            fraction, theta, phi, rho = chosen[1]
            own = series[rows[0]]
            made = SeriesMemory(phi, rho, own.dof, own.square_dof, fraction, theta)
            for i in rows:
                out[i] = made
    return tuple(out)


def _shared_model(x: np.ndarray, classes: set, n: int, p_max: int):
    """One model of long memory or of an ARMA(p, 1) shared by the series ``x`` (rows),
    with its v_n and (d, θ, φ, ρ), where the rows together support it as one direction
    supports its weak candidate (:func:`_fractional_fits`); None otherwise.

    The rows, each scaled to unit mean square, are pooled by Burg's recursion (one
    reflection coefficient from every row's prediction errors): the AR sieve, ARFIMA(p, d,
    0) with d on the grid :data:`FRACTIONS` below its top and ARMA(p, 1) with θ on
    :data:`MOVING_AVERAGES`, for the classes in ``classes`` (True: fractional, False: ARMA),
    the orders up to ``p_max``, each by AICc over all the rows' epochs. A fractional model
    is supported where its AICc is within :data:`SUPPORT` of the sieve's and no ARMA(p, 1)
    beats it by BIC's margin; an ARMA(p, 1) where it beats the sieve and is within
    :data:`SUPPORT` of the best of the three. Of those supported, the one of more memory
    over ``n`` epochs. The rows share the selection of the principal directions on both
    sides of the comparison, so a direction that shows less memory by that selection does
    not count against the shared model."""
    m, t = x.shape
    rms = np.sqrt(np.mean(x * x, axis=1, keepdims=True))
    z = x / np.where(rms > 0.0, rms, 1.0)
    sieve = float(np.min(burg(z[None], p_max).aicc()))
    found = []
    if True in classes:
        stack = np.stack([fractional_difference(z, g) for g in FRACTIONS[:-1]])
        fit = burg(stack, p_max)
        costs = fit.aicc(extra=1)
        which, order = np.unravel_index(int(np.argmin(costs)), costs.shape)
        found.append((float(costs[which, order]), float(FRACTIONS[which]), 0.0, fit, which, order))
    if False in classes:
        stack = np.stack([ar_filter(np.array([-g]), z.T).T for g in MOVING_AVERAGES])
        fit = burg(stack, p_max)
        costs = fit.aicc(extra=1)
        which, order = np.unravel_index(int(np.argmin(costs)), costs.shape)
        found.append(
            (float(costs[which, order]), 0.0, float(MOVING_AVERAGES[which]), fit, which, order)
        )
    moving = min((f[0] for f in found if f[2] != 0.0), default=math.inf)
    least = min([sieve] + [f[0] for f in found])
    out = []
    for cost, fraction, theta, fit, which, order in found:
        if fraction > 0:
            supported = cost < sieve + SUPPORT and not moving + (math.log(m * t) - 2.0) < cost
        else:
            supported = cost < sieve and cost < least + SUPPORT
        if not supported:
            continue
        phi = fit.coefficients(int(which), int(order))
        if fraction > 0:
            rho = _fractional_rho(phi, fraction, n)
        else:
            try:
                rho = arma_autocorrelation(phi, theta, n)
            except np.linalg.LinAlgError:
                rho = None
        if rho is not None and np.all(np.isfinite(rho)):
            out.append((mean_variance_ratio(rho), (fraction, theta, phi, rho)))
    return max(out, key=lambda f: f[0]) if out else None
