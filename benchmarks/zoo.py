"""A development zoo of error processes ("families") with known truth, to measure a
credibility rule on serial dependence of many shapes.

``make(family, n, rng, misfit)`` returns a :class:`Case`: errors e_k = truth − estimate
(N, d), the claimed covariances (N, d, d), and what is true about them: the factor between
the true and the claimed covariance, a bias, and the family's integrated correlation time τ.

Conventions
-----------
- Whitening is by the symmetric inverse square root of the claimed covariance, as the
  engine's ``elt.whiten``. The synthetic families are generated as e_k = Σ_k^{1/2} w_k with
  w a unit-variance whitened process, so the whitened errors are exactly w.
- τ = the largest eigenvalue of Γ(0)⁻¹ S(0), S(0) the long-run covariance (spectral density
  at 0, Σ_h Γ(h)) and Γ(0) the marginal covariance of the errors: the largest long-run
  variance over whitened directions (it does not depend on the whitening). For independent
  whitened components it is the largest component's (Σ_h ρ(h)).
- Credible by construction with ``misfit="none"``: every linear family starts from its
  stationary law (ARMA pasts drawn jointly with the stationary covariance and handed to
  ``lfilter`` with ``lfiltic``; VAR(1) Kalman error states from the Lyapunov solution), so
  Cov(e_k) = cov_k exactly at every epoch.
- Misfits: ``"small4"``: the claimed covariance is the true one / 4 (truth_factor 4,
  optimism); ``"large4"``: claimed = 4 × true (truth_factor 0.25, pessimism); ``"bias1"``:
  a constant bias b is added to the errors (truth_factor 1). b = c Σ̄^{1/2} u₁, Σ̄ the mean
  claimed covariance and u₁ the first axis, with c such that the mean over epochs of
  bᵀ Σ_k⁻¹ b is 1: for a fixed covariance b is exactly 1σ along the first whitened axis;
  for the time-varying ones (rotating, resized, filters) it is a constant physical offset of
  1σ in the root-mean-square Mahalanobis sense.
- Kalman families (``kf-*``) are steady-state filters (constant gain and P: the state of a
  filter run long after its start), simulated through their error recursion
  e⁺_k = (I − KH)F e⁺_{k−1} + (I − KH)w_k − K v_k, which is exact for a linear filter and
  does not need the truth or the measurements. The claimed covariance is the filter's P⁺
  (block of the reported components). For "small4"/"large4" the right filter is kept and
  its P rescaled, except in ``kf-cv-10hz-mistuned`` (see below).
- ``kf-cv-10hz-mistuned``: "small4" runs the filter with Q×1/8 and R×1/2, "large4" with
  Q×8 and R×2: its noise level 4× off (geometric mean) and its Q/R ratio 4× off too.
  Scaling Q and R by the same factor leaves the steady-state gain unchanged, so it would
  give exactly the rescaled right filter; these change the gain, the errors' dependence
  (τ 23.2 and 6.6 epochs against 11.7) and the size of the misfit: truth_factor 3.40 and
  0.418. τ reported is the mistuned filter's. The true error covariance is the exact suboptimal-filter (Joseph)
  recursion's fixed point, P_true = A P_true Aᵀ + (I−KH) Q_true (I−KH)ᵀ + K R_true Kᵀ, and
  truth_factor = trace(P_true)/trace(P_claimed) over the reported components (constant over
  epochs at steady state).
- Library families (filterpy UKF/EKF, Stone Soup EKF and UKF, a bootstrap particle
  filter, a GTSAM smoother, the SE(3) EKF, invariant EKF and UKF of ``se3_filters.py``
  and navlie's) are run as their users run them, right-tuned, after a burn-in; they are only
  approximately credible, so truth_factor is NaN for "none" and "bias1", and 4 / 0.25
  *relative to the right-tuned filter* for "small4" / "large4" (claimed P rescaled). Their τ
  is a constant measured once by batch means (see ``LIBRARY_TAU``). Runs are cached in the
  process by (family, n, seed), so the four misfits of one draw reuse one filter run.

numpy, scipy and the sibling ``se3_filters`` (numpy and scipy) at import; filterpy,
stonesoup, gtsam and navlie are imported inside their families.
"""

from __future__ import annotations

import functools
import math
import os
import sys
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy import linalg, signal

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))  # as memory.py: se3_filters

import se3_filters  # noqa: E402

MISFITS = ("none", "small4", "large4", "bias1")
FIXED_COV = np.array([[4.0, 1.2], [1.2, 1.0]])
"""The fixed, non-diagonal claimed covariance of the synthetic families."""


@dataclass(frozen=True)
class Case:
    family: str
    errors: np.ndarray  # (N, d)
    cov: np.ndarray  # (N, d, d) claimed covariance
    truth_factor: float  # true error covariance / claimed
    bias_sigma: float  # constant bias added, in claimed-sigma units
    tau: float  # integrated correlation time (epochs) of the whitened errors
    rate_hz: float | None


# --------------------------------------------------------------------------- helpers
def _sym_sqrt(cov: np.ndarray) -> np.ndarray:
    lam, vec = np.linalg.eigh(cov)
    return (vec * np.sqrt(np.clip(lam, 0.0, None))[..., None, :]) @ np.swapaxes(vec, -1, -2)


def _sym_inv_sqrt(cov: np.ndarray) -> np.ndarray:
    lam, vec = np.linalg.eigh(cov)
    return (vec / np.sqrt(lam)[..., None, :]) @ np.swapaxes(vec, -1, -2)


def whiten(errors: np.ndarray, cov: np.ndarray) -> np.ndarray:
    """Σ_k^{-1/2} e_k with the symmetric inverse square root (as the engine whitens)."""
    return np.einsum("nij,nj->ni", _sym_inv_sqrt(cov), errors)


def _tau_from(lrv: np.ndarray, gamma0: np.ndarray) -> float:
    """Largest eigenvalue of Γ0⁻¹ S(0)."""
    lrv, gamma0 = np.atleast_2d(lrv), np.atleast_2d(gamma0)
    return float(linalg.eigh((lrv + lrv.T) / 2, (gamma0 + gamma0.T) / 2, eigvals_only=True)[-1])


def _bias_vector(cov: np.ndarray, sigma: float = 1.0) -> np.ndarray:
    """Constant b along Σ̄^{1/2}u₁ with mean_k bᵀΣ_k⁻¹b = sigma² (see the module doc)."""
    u = _sym_sqrt(cov.mean(axis=0))[:, 0]
    m = np.einsum("i,nij,j->n", u, np.linalg.inv(cov), u).mean()
    return sigma * u / math.sqrt(m)


# --------------------------------------------------------------------------- ARMA
def _psi(phi, theta, length: int) -> np.ndarray:
    imp = np.zeros(length)
    imp[0] = 1.0
    return signal.lfilter(np.r_[1.0, theta], np.r_[1.0, -np.asarray(phi, float)], imp)


def _psi_length(phi) -> int:
    if len(phi) == 0:
        return 64
    rmax = float(np.max(np.abs(np.roots(np.r_[1.0, -np.asarray(phi, float)]))))
    return int(math.ceil(math.log(1e-18) / math.log(rmax))) + 64


@functools.cache
def _arma_setup(phi: tuple, theta: tuple):
    psi = _psi(phi, theta, _psi_length(phi))
    p, q = len(phi), len(theta)
    gamma = np.array([psi[: psi.size - h] @ psi[h:] for h in range(max(p, 1) + 1)])
    # joint covariance of (y_{-1..-p}, eps_{-1..-q}), innovations of unit variance
    m = p + q
    c = np.zeros((m, m))
    for i in range(p):
        for j in range(p):
            c[i, j] = gamma[abs(i - j)]
        for j in range(q):  # Cov(y_{-1-i}, eps_{-1-j}) = psi_{j-i} for j >= i
            if j >= i:
                c[i, p + j] = c[p + j, i] = psi[j - i]
    c[p:, p:] = np.eye(q)
    chol = np.linalg.cholesky(c + 1e-14 * np.eye(m)) if m else np.zeros((0, 0))
    a = np.r_[1.0, -np.asarray(phi, float)]
    b = np.r_[1.0, np.asarray(theta, float)]
    tau = float(b.sum() ** 2 / a.sum() ** 2 / gamma[0])
    return a, b, chol, math.sqrt(gamma[0]), tau


def arma(phi, theta, n: int, d: int, rng: np.random.Generator) -> np.ndarray:
    """(n, d) independent stationary ARMA(p, q) components of unit variance:
    y_k = Σφ_i y_{k−i} + ε_k + Σθ_j ε_{k−j}, started from the stationary law."""
    phi, theta = tuple(float(x) for x in phi), tuple(float(x) for x in theta)
    a, b, chol, sd, _ = _arma_setup(phi, theta)
    p, q = len(phi), len(theta)
    past = rng.standard_normal((p + q, d))
    eps = rng.standard_normal((n, d))
    if p + q == 0:
        return eps
    past = chol @ past
    zi = np.stack([signal.lfiltic(b, a, y=past[:p, j], x=past[p:, j]) for j in range(d)], axis=1)
    return signal.lfilter(b, a, eps, axis=0, zi=zi)[0] / sd


def arma_tau(phi, theta) -> float:
    return _arma_setup(tuple(map(float, phi)), tuple(map(float, theta)))[4]


def arma_rho(phi, theta, n: int) -> np.ndarray:
    """ρ(0 … n − 1) of a stationary ARMA: the autocorrelation of its ψ weights (FFT)."""
    psi = _psi(phi, theta, _psi_length(phi) + n)
    size = 1 << int(2 * psi.size - 1).bit_length()
    gamma = np.fft.irfft(np.abs(np.fft.rfft(psi, size)) ** 2, size)[:n]
    return gamma / gamma[0]


# --------------------------------------------------------------------------- ARFIMA
def arfima_rho(d_frac: float, n: int) -> np.ndarray:
    h = np.arange(1, n)
    return np.r_[1.0, np.cumprod((h - 1 + d_frac) / (h - d_frac))]


@functools.lru_cache(maxsize=16)
def _davies_harte(d_frac: float, n: int):
    r = arfima_rho(d_frac, n + 1)
    c = np.r_[r[: n + 1], r[n - 1 : 0 : -1]]
    lam = np.fft.fft(c).real
    if lam.min() < -1e-9 * lam.max():
        raise ValueError("circulant embedding not nonnegative")
    return np.sqrt(np.clip(lam, 0.0, None) / c.size)


def arfima(d_frac: float, n: int, dim: int, rng: np.random.Generator) -> np.ndarray:
    """(n, dim) independent exact ARFIMA(0, d, 0) components of unit variance
    (Davies–Harte circulant embedding: one complex FFT gives two independent series)."""
    sq = _davies_harte(d_frac, n)
    out = np.empty((n, dim))
    for j in range(0, dim, 2):
        z = rng.standard_normal(sq.size) + 1j * rng.standard_normal(sq.size)
        w = np.fft.fft(sq * z)[:n]
        out[:, j] = w.real
        if j + 1 < dim:
            out[:, j + 1] = w.imag
    return out


def arfima_tau_n(d_frac: float, n: int) -> float:
    """τ_N = N·Var(mean)/γ(0) = 1 + 2Σ_{h<N}(1 − h/N)ρ(h) (τ itself is infinite)."""
    rho = arfima_rho(d_frac, n)
    h = np.arange(1, n)
    return float(1.0 + 2.0 * np.sum((1.0 - h / n) * rho[1:]))


# --------------------------------------------------------------------------- covariances
def fixed_cov(n: int, rng) -> np.ndarray:
    return np.broadcast_to(FIXED_COV, (n, 2, 2))


def rotating_cov(n: int, rng, anisotropy: float = 20.0, period: float = 400.0):
    """Axes of std ``anisotropy`` and 1, turning once every ``period`` epochs (random phase)."""
    angle = rng.uniform(0, 2 * np.pi) + 2 * np.pi * np.arange(n) / period
    c, s = np.cos(angle), np.sin(angle)
    rot = np.stack([np.c_[c, -s], np.c_[s, c]], axis=1)
    return rot @ np.diag([anisotropy**2, 1.0]) @ np.swapaxes(rot, 1, 2)


def resized_cov(n: int, rng, ratio: float = 10.0, period: float = 300.0):
    """FIXED_COV × s_k, s_k = ratio^{(1 + sin)/2} in [1, ratio], period ``period`` epochs."""
    phase = rng.uniform(0, 2 * np.pi) + 2 * np.pi * np.arange(n) / period
    s = ratio ** ((1 + np.sin(phase)) / 2)
    return s[:, None, None] * FIXED_COV


# --------------------------------------------------------------------------- synthetic
@dataclass(frozen=True)
class Synthetic:
    white: Callable  # (n, rng) -> (n, d) whitened, unit-variance
    cov: Callable  # (n, rng) -> (n, d, d)
    tau: Callable  # n -> tau
    rhos: Callable  # n -> each whitened direction's ρ(0 … n − 1) (independent directions)


def white_rho(n: int) -> np.ndarray:
    return np.r_[1.0, np.zeros(n - 1)]


def both_directions(rho: Callable) -> Callable:
    """Two directions of the same autocorrelation ``rho(n)``."""
    return lambda n: [rho(n)] * 2


def arma_rhos(phi, theta=()) -> Callable:
    return both_directions(functools.partial(arma_rho, tuple(phi), tuple(theta)))


def slow_white_rho(phi: float, w: float) -> Callable:
    def rho(n):
        out = (1.0 - w) * arma_rho((phi,), (), n)
        out[0] = 1.0
        return out

    return both_directions(rho)


def ar_errors(phi):
    return lambda n, rng: arma(phi, (), n, 2, rng)


def slow_white(phi, w):
    def gen(n, rng):
        return math.sqrt(1 - w) * arma((phi,), (), n, 2, rng) + math.sqrt(w) * rng.standard_normal(
            (n, 2)
        )

    return gen


def _slow_and_white_dirs(n, rng):
    return np.c_[arma((0.98,), (), n, 1, rng), rng.standard_normal((n, 1))]


_AR2_COMPLEX = (2 * 0.95 * math.cos(0.3), -(0.95**2))
_AR2_SMOOTH = (1.9, -0.9025)

SYNTHETIC: dict[str, Synthetic] = {
    "iid": Synthetic(
        lambda n, rng: rng.standard_normal((n, 2)),
        fixed_cov,
        lambda n: 1.0,
        both_directions(white_rho),
    ),
    **{
        f"ar1-{phi}": Synthetic(
            ar_errors((phi,)),
            fixed_cov,
            functools.partial(lambda n, p: arma_tau((p,), ()), p=phi),
            arma_rhos((phi,)),
        )
        for phi in (0.5, 0.9, 0.99)
    },
    "ar2-complex": Synthetic(
        ar_errors(_AR2_COMPLEX),
        fixed_cov,
        lambda n: arma_tau(_AR2_COMPLEX, ()),
        arma_rhos(_AR2_COMPLEX),
    ),
    "ar2-smooth": Synthetic(
        ar_errors(_AR2_SMOOTH),
        fixed_cov,
        lambda n: arma_tau(_AR2_SMOOTH, ()),
        arma_rhos(_AR2_SMOOTH),
    ),
    "arma11": Synthetic(
        lambda n, rng: arma((0.9,), (-0.5,), n, 2, rng),
        fixed_cov,
        lambda n: arma_tau((0.9,), (-0.5,)),
        arma_rhos((0.9,), (-0.5,)),
    ),
    "slow-white-0.95-0.5": Synthetic(
        slow_white(0.95, 0.5),
        fixed_cov,
        lambda n: 0.5 * arma_tau((0.95,), ()) + 0.5,
        slow_white_rho(0.95, 0.5),
    ),
    "slow-white-0.99-0.3": Synthetic(
        slow_white(0.99, 0.3),
        fixed_cov,
        lambda n: 0.7 * arma_tau((0.99,), ()) + 0.3,
        slow_white_rho(0.99, 0.3),
    ),
    "arfima-0.3": Synthetic(
        lambda n, rng: arfima(0.3, n, 2, rng),
        fixed_cov,
        lambda n: arfima_tau_n(0.3, n),
        both_directions(functools.partial(arfima_rho, 0.3)),
    ),
    "slow-and-white-dirs": Synthetic(
        _slow_and_white_dirs,
        fixed_cov,
        lambda n: arma_tau((0.98,), ()),
        lambda n: [arma_rho((0.98,), (), n), white_rho(n)],
    ),
    # whitened by the true Σ_k: AR(1) 0.9 in both directions
    "rotating-cov": Synthetic(
        ar_errors((0.9,)), rotating_cov, lambda n: arma_tau((0.9,), ()), arma_rhos((0.9,))
    ),
    "resized-cov": Synthetic(
        ar_errors((0.9,)), resized_cov, lambda n: arma_tau((0.9,), ()), arma_rhos((0.9,))
    ),
}


# --------------------------------------------------------------------------- oracle
def direction_rhos(family: str, n: int) -> list[np.ndarray] | None:
    """The autocorrelation ρ(0 … n − 1) of each whitened direction of a synthetic family
    (the directions are independent), or None for the Kalman and library families."""
    return SYNTHETIC[family].rhos(n) if family in SYNTHETIC else None


def oracle_scale_decided(rhos: list[np.ndarray], n: int, level: float) -> tuple[float, float]:
    """What the scale question can decide with the dependence known: the share of credible
    Gaussian segments of n epochs whose one-sided 1 − ``level`` bounds of κ lie within
    [1/2, 2] (the calibrated rule's "decided" for the scale: two one-sided tests at α_S,
    :data:`credcli.engine.rules.CREDIBLE_FACTOR`), and the Satterthwaite degrees of freedom
    ν behind it.

    The centred sum of squares T = Σ_i x_iᵀ M x_i (M = I − 11ᵀ/n, direction i with
    Toeplitz correlation R_i) has E = Σ tr(M R_i) and V = 2 Σ tr((M R_i)²); with T/c ~ χ²_ν,
    c = V/(2E), ν = 2E²/V (Satterthwaite 1946) and κ̂ = T/E, the bounds of κ are
    [X/q₊, X/q₋] for X = T/c and q± the χ²_ν quantiles at 1 − level and level, so the
    question is decided with probability F_ν(2q₋) − F_ν(q₊/2) at κ = 1. The rule estimates
    the dependence, so it decides less often.
    """
    from scipy import stats

    h = np.arange(1, n)
    e = v = 0.0
    for rho in rhos:
        rho = np.asarray(rho, dtype=float)[:n]
        ones_r_ones = n + 2.0 * float(np.sum((n - h) * rho[1:]))
        r_ones = linalg.toeplitz(rho) @ np.ones(n)
        tr_r2 = n + 2.0 * float(np.sum((n - h) * rho[1:] ** 2))
        e += n - ones_r_ones / n
        v += 2.0 * (tr_r2 - 2.0 * float(r_ones @ r_ones) / n + (ones_r_ones / n) ** 2)
    nu = 2.0 * e * e / v
    q_low, q_high = stats.chi2.ppf([level, 1 - level], nu)
    return max(0.0, float(stats.chi2.cdf(2 * q_low, nu) - stats.chi2.cdf(q_high / 2, nu))), nu


# --------------------------------------------------------------------------- Kalman
R_2D = np.array([[1.0, 0.6], [0.6, 2.0]])
"""Position measurement noise (m²) of the 2-D Kalman families: correlated axes, so that P
is not diagonal."""


def cv_model(rate_hz: float, q: float = 0.5):
    dt = 1.0 / rate_hz
    f1 = np.array([[1.0, dt], [0.0, 1.0]])
    q1 = q * np.array([[dt**3 / 3, dt**2 / 2], [dt**2 / 2, dt]])
    f, qm = np.kron(np.eye(2), f1), np.kron(np.eye(2), q1)  # state (x, vx, y, vy)
    h = np.array([[1.0, 0, 0, 0], [0, 0, 1.0, 0]])
    return f, qm, h, R_2D, h  # outputs: positions


def ca_model(rate_hz: float, q: float = 0.5, r: float = 1.0):
    dt = 1.0 / rate_hz
    f = np.array([[1.0, dt, dt**2 / 2], [0, 1.0, dt], [0, 0, 1.0]])
    qm = q * np.array(
        [
            [dt**5 / 20, dt**4 / 8, dt**3 / 6],
            [dt**4 / 8, dt**3 / 3, dt**2 / 2],
            [dt**3 / 6, dt**2 / 2, dt],
        ]
    )
    h = np.array([[1.0, 0, 0]])
    return f, qm, h, np.array([[r]]), np.array([[1.0, 0, 0], [0, 1.0, 0]])  # position, velocity


def rw_model(rate_hz: float, q: float = 1.0):
    dt = 1.0 / rate_hz
    return np.eye(2), q * dt * np.eye(2), np.eye(2), R_2D, np.eye(2)


@dataclass(frozen=True)
class _LinearKF:
    """A steady-state Kalman filter's error process (a VAR(1)), possibly mistuned."""

    A: np.ndarray  # (I − KH)F
    U_sqrt: np.ndarray  # square root of the driving noise covariance
    P_true: np.ndarray  # stationary covariance of the full error state
    C: np.ndarray  # reported components
    claimed: np.ndarray  # C P_filter⁺ Cᵀ
    true_out: np.ndarray  # C P_true Cᵀ
    tau: float
    vec: np.ndarray  # eigenvectors of A
    vec_inv: np.ndarray
    lam: np.ndarray  # eigenvalues of A


def _steady_filter(f, q, h, r):
    p_minus = linalg.solve_discrete_are(f.T, h.T, q, r)
    s = h @ p_minus @ h.T + r
    k = np.linalg.solve(s, h @ p_minus).T
    ikh = np.eye(f.shape[0]) - k @ h
    return k, ikh @ p_minus @ ikh.T + k @ r @ k.T


def linear_kf(model, q_factor: float = 1.0, r_factor: float = 1.0) -> _LinearKF:
    """The error process of the steady-state filter tuned with Q·q_factor, R·r_factor on a
    truth with the model's own Q and R."""
    f, q, h, r, c = model
    k, p_filter = _steady_filter(f, q * q_factor, h, r * r_factor)
    ikh = np.eye(f.shape[0]) - k @ h
    a = ikh @ f
    u = ikh @ q @ ikh.T + k @ r @ k.T
    p_true = linalg.solve_discrete_lyapunov(a, u)
    eye = np.eye(f.shape[0])
    # long-run covariance of x_k = A x_{k−1} + u_k: (I−A)⁻¹ U (I−A)⁻ᵀ
    g = np.linalg.solve(eye - a, eye)
    lrv = c @ g @ u @ g.T @ c.T
    true_out = c @ p_true @ c.T
    lam, vec = np.linalg.eig(a)
    if np.linalg.cond(vec) > 1e8:
        raise ValueError("error transition not safely diagonalisable")
    return _LinearKF(
        A=a,
        U_sqrt=_sym_sqrt(u),
        P_true=p_true,
        C=c,
        claimed=c @ p_filter @ c.T,
        true_out=true_out,
        tau=_tau_from(lrv, true_out),
        vec=vec,
        vec_inv=np.linalg.inv(vec),
        lam=lam,
    )


def kf_errors(kf: _LinearKF, n: int, rng: np.random.Generator) -> np.ndarray:
    """(n, d) errors of the steady-state filter from its stationary law, by modal lfilter."""
    m = kf.A.shape[0]
    x0 = _sym_sqrt(kf.P_true) @ rng.standard_normal(m)  # the state before epoch 0
    u = rng.standard_normal((n, m)) @ kf.U_sqrt.T
    z = u @ kf.vec_inv.T  # modal driving noise (complex)
    z0 = kf.vec_inv @ x0
    out = np.empty((n, m), dtype=complex)
    for i, lam in enumerate(kf.lam):
        out[:, i] = signal.lfilter([1.0], [1.0, -lam], z[:, i], zi=[lam * z0[i]])[0]
    x = (out @ kf.vec.T).real
    return x @ kf.C.T


KF_MODELS = {
    "kf-cv-1hz": (lambda: cv_model(1.0), 1.0),
    "kf-cv-10hz": (lambda: cv_model(10.0), 10.0),
    "kf-cv-100hz": (lambda: cv_model(100.0), 100.0),
    "kf-ca-1hz": (lambda: ca_model(1.0), 1.0),
    "kf-ca-10hz": (lambda: ca_model(10.0), 10.0),
    "kf-ca-100hz": (lambda: ca_model(100.0), 100.0),
    "kf-rw-1hz": (lambda: rw_model(1.0), 1.0),
    "kf-rw-10hz": (lambda: rw_model(10.0), 10.0),
    "kf-rw-100hz": (lambda: rw_model(100.0), 100.0),
    "kf-cv-10hz-mistuned": (lambda: cv_model(10.0), 10.0),
}
MISTUNE = {"small4": (1 / 8, 1 / 2), "large4": (8.0, 2.0)}
"""(Q, R) factors of the filter in ``kf-cv-10hz-mistuned``: its noise level 4× off (the
geometric mean of the factors) and its Q/R ratio 4× off, the same way."""


@functools.cache
def filter_of(family: str, q_factor: float = 1.0, r_factor: float = 1.0) -> _LinearKF:
    return linear_kf(KF_MODELS[family][0](), q_factor=q_factor, r_factor=r_factor)


# --------------------------------------------------------------------------- libraries
LIBRARY_TAU = {
    # Measured once with ``estimate_library_tau(family)``: 40 independent right-tuned runs
    # of 2000 epochs after the family's burn-in (seed 2024), errors whitened by the claimed
    # covariance, batch means; τ = the largest eigenvalue of B·Cov(batch means) relative to
    # the whitened covariance, read where it had stopped growing with B (B = 50/100/200/400):
    "filterpy-ukf-pendulum": 3.6,  # 3.4 / 3.6 / 3.7 / 3.4
    "filterpy-ekf-range": 14.4,  # 14.5 / 14.5 / 14.4 / 14.4
    "stonesoup-ekf-radar": 25.0,  # 23.1 / 27.1 / 24.7 / 25.7
    "stonesoup-ukf-radar": 25.0,  # 23.1 / 27.2 / 24.8 / 25.9 (the EKF's truth and measurements)
    "pf-1d": 1.0,  # 1.0 / 1.0 / 1.0 / 0.9 (whitened variance 15: rare collapses, see below)
    "gtsam-pose2-smoother": 48.0,  # 31.7 / 42.3 / 48.5 / 48.4
    # the SE(3) filters agree to millimetres, so their τ do (max |whitened cov − I| ≤ 0.046):
    "se3-ekf": 21.5,  # 17.7 / 20.7 / 21.7 / 21.3
    "se3-iekf": 21.5,  # 17.7 / 20.7 / 21.7 / 21.3
    "se3-ukf": 21.5,  # 17.7 / 20.7 / 21.7 / 21.3
    "navlie-se3-ekf": 21.5,  # 17.7 / 20.7 / 21.6 / 21.3
    "navlie-se3-iekf": 21.5,  # 17.7 / 20.7 / 21.6 / 21.3
    "navlie-se3-ukf": 21.5,  # 17.7 / 20.7 / 21.7 / 21.3
}
LIBRARY_RATE = {
    "filterpy-ukf-pendulum": 20.0,
    "filterpy-ekf-range": 10.0,
    "stonesoup-ekf-radar": 1.0,
    "stonesoup-ukf-radar": 1.0,
    "pf-1d": 1.0,
    "gtsam-pose2-smoother": 10.0,
    **{f: 100.0 for f in ("se3-ekf", "se3-iekf", "se3-ukf")},
    **{f: 100.0 for f in ("navlie-se3-ekf", "navlie-se3-iekf", "navlie-se3-ukf")},
}
BURN_IN = {
    "filterpy-ukf-pendulum": 200,
    "filterpy-ekf-range": 200,
    "stonesoup-ekf-radar": 50,
    "stonesoup-ukf-radar": 50,
    "pf-1d": 20,
    "gtsam-pose2-smoother": 0,
    **{f: 100 for f in ("se3-ekf", "se3-iekf", "se3-ukf")},  # 1 s: ten updates
    **{f: 100 for f in ("navlie-se3-ekf", "navlie-se3-iekf", "navlie-se3-ukf")},
}


def _pendulum_fx(x, dt, g=9.81, damping=0.2):
    """RK4 step of θ'' = −g sin θ − damping·θ' (length 1 m); works on (2,) or (n, 2)."""

    def deriv(s):
        return np.stack([s[..., 1], -g * np.sin(s[..., 0]) - damping * s[..., 1]], axis=-1)

    k1 = deriv(x)
    k2 = deriv(x + dt / 2 * k1)
    k3 = deriv(x + dt / 2 * k2)
    k4 = deriv(x + dt * k3)
    return x + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)


def _run_ukf_pendulum(steps: int, rng: np.random.Generator):
    """filterpy UnscentedKalmanFilter (Merwe sigma points) on a damped pendulum (1 m,
    damping 0.2/s) driven by white angular-acceleration noise (q = 1 rad²/s³), measuring
    the bob's position (sin θ, −cos θ) (σ = 0.05 m each) at 20 Hz. Errors: angle and rate
    (d = 2). (With sin θ alone, θ and π − θ are confused when it swings high.)"""
    from filterpy.kalman import MerweScaledSigmaPoints, UnscentedKalmanFilter

    dt, q, sig = 1.0 / 20.0, 1.0, 0.05
    qm = q * np.array([[dt**3 / 3, dt**2 / 2], [dt**2 / 2, dt]])
    p0 = np.diag([0.3**2, 1.5**2])
    points = MerweScaledSigmaPoints(2, alpha=0.5, beta=2.0, kappa=1.0)
    ukf = UnscentedKalmanFilter(
        dim_x=2,
        dim_z=2,
        dt=dt,
        hx=lambda x: np.array([np.sin(x[0]), -np.cos(x[0])]),
        fx=lambda x, dt: _pendulum_fx(x, dt),
        points=points,
    )
    ukf.Q, ukf.R, ukf.P = qm, sig**2 * np.eye(2), p0.copy()
    x = np.sqrt(np.diag(p0)) * rng.standard_normal(2)
    ukf.x = np.zeros(2)
    chol_q = np.linalg.cholesky(qm)
    kicks = rng.standard_normal((steps, 2)) @ chol_q.T
    noise = sig * rng.standard_normal((steps, 2))
    err, cov = np.empty((steps, 2)), np.empty((steps, 2, 2))
    for k in range(steps):
        x = _pendulum_fx(x, dt) + kicks[k]
        ukf.predict()
        ukf.update(np.array([np.sin(x[0]), -np.cos(x[0])]) + noise[k])
        err[k] = x - ukf.x
        cov[k] = ukf.P
    return err, cov


BEACONS = np.array([[-1000.0, -1000.0], [1000.0, -1000.0], [1000.0, 1000.0], [-1000.0, 1000.0]])


def _run_ekf_range(steps: int, rng: np.random.Generator):
    """filterpy ExtendedKalmanFilter on a nearly-constant-velocity target (q = 0.05 m²/s³)
    ranged from four beacons at (±1 km, ±1 km) (σ = 1 m each) at 10 Hz. Errors: position."""
    from filterpy.kalman import ExtendedKalmanFilter

    f, qm, *_ = cv_model(10.0, q=0.05)
    r = np.eye(len(BEACONS))
    p0 = np.diag([25.0, 1.0, 25.0, 1.0])
    ekf = ExtendedKalmanFilter(dim_x=4, dim_z=len(BEACONS))
    ekf.F, ekf.Q, ekf.R, ekf.P = f, qm, r, p0.copy()
    x = np.array([0.0, 0.0, 0.0, 0.0]) + np.sqrt(np.diag(p0)) * rng.standard_normal(4)
    ekf.x = np.zeros(4)
    chol_q = np.linalg.cholesky(qm)
    kicks = rng.standard_normal((steps, 4)) @ chol_q.T
    noise = rng.standard_normal((steps, len(BEACONS)))

    def hx(s):
        return np.hypot(s[0] - BEACONS[:, 0], s[2] - BEACONS[:, 1])

    def jac(s):
        rho = hx(s)
        j = np.zeros((len(BEACONS), 4))
        j[:, 0] = (s[0] - BEACONS[:, 0]) / rho
        j[:, 2] = (s[2] - BEACONS[:, 1]) / rho
        return j

    err, cov = np.empty((steps, 2)), np.empty((steps, 2, 2))
    for k in range(steps):
        x = f @ x + kicks[k]
        ekf.predict()
        ekf.update(hx(x) + noise[k], jac, hx)
        err[k] = (x - ekf.x)[[0, 2]]
        cov[k] = ekf.P[np.ix_([0, 2], [0, 2])]
    return err, cov


def _run_stonesoup_radar(steps: int, rng: np.random.Generator, filt: str = "ekf"):
    """Stone Soup KalmanPredictor + ExtendedKalmanUpdater (``filt`` "ekf") or
    UnscentedKalmanPredictor + UnscentedKalmanUpdater with their default sigma points
    (``filt`` "ukf") with CartesianToBearingRange
    (σ_bearing = 0.01 rad, σ_range = 5 m) of a radar at the origin, on a nearly constant
    velocity target (q = 0.05 m²/s³ per axis) starting 10 km away at 10 m/s across the line
    of sight, 1 Hz. The updater symmetrises its covariance, and the EKF's uses the Joseph
    form (with the defaults P loses symmetry by ~2% over 2000 updates and stops being
    positive definite; the UKF's has no measurement matrix for it, and its P stays
    positive definite: smallest eigenvalue 6.46 m² over 2,000 updates in three runs).
    Bearings are Stone Soup ``Bearing``s (wrapped). Errors: position (d = 2). Both filters
    see the same truth and measurements for the same ``rng``."""
    import datetime as dt_

    from stonesoup.models.measurement.nonlinear import CartesianToBearingRange
    from stonesoup.models.transition.linear import (
        CombinedLinearGaussianTransitionModel,
        ConstantVelocity,
    )
    from stonesoup.predictor.kalman import KalmanPredictor, UnscentedKalmanPredictor
    from stonesoup.types.angle import Bearing
    from stonesoup.types.array import StateVector
    from stonesoup.types.detection import Detection
    from stonesoup.types.hypothesis import SingleHypothesis
    from stonesoup.types.state import GaussianState
    from stonesoup.updater.kalman import ExtendedKalmanUpdater, UnscentedKalmanUpdater

    q = 0.05
    transition = CombinedLinearGaussianTransitionModel([ConstantVelocity(q), ConstantVelocity(q)])
    r = np.diag([0.01**2, 5.0**2])
    meas = CartesianToBearingRange(ndim_state=4, mapping=(0, 2), noise_covar=r)
    if filt == "ekf":
        predictor = KalmanPredictor(transition)
        updater = ExtendedKalmanUpdater(meas, force_symmetric_covariance=True, use_joseph_cov=True)
    else:
        predictor = UnscentedKalmanPredictor(transition)
        updater = UnscentedKalmanUpdater(meas, force_symmetric_covariance=True)
    f, qm, *_ = cv_model(1.0, q=q)
    chol_q = np.linalg.cholesky(qm)
    p0 = np.diag([100.0, 25.0, 100.0, 25.0])
    mean0 = np.array([10000.0, 0.0, 0.0, 10.0])
    x = mean0 + np.sqrt(np.diag(p0)) * rng.standard_normal(4)
    start = dt_.datetime(2024, 1, 1)
    state = GaussianState(mean0[:, None], p0.copy(), timestamp=start)
    kicks = rng.standard_normal((steps, 4)) @ chol_q.T
    noise = rng.standard_normal((steps, 2)) * np.sqrt(np.diag(r))
    err, cov = np.empty((steps, 2)), np.empty((steps, 2, 2))
    for k in range(steps):
        t = start + dt_.timedelta(seconds=k + 1)
        x = f @ x + kicks[k]
        z = StateVector(
            [Bearing(math.atan2(x[2], x[0]) + noise[k, 0]), math.hypot(x[0], x[2]) + noise[k, 1]]
        )
        pred = predictor.predict(state, timestamp=t)
        det = Detection(z, timestamp=t, measurement_model=meas)
        state = updater.update(SingleHypothesis(pred, det))
        m = np.asarray(state.state_vector, float).ravel()
        err[k] = (x - m)[[0, 2]]
        cov[k] = np.asarray(state.covar, float)[np.ix_([0, 2], [0, 2])]
    return err, cov


def _run_pf_1d(steps: int, rng: np.random.Generator, particles: int = 5000):
    """A bootstrap particle filter (systematic resampling every step, 5000 particles) on the
    dynamics of the univariate nonstationary growth model, x_k = x/2 + 25x/(1+x²) +
    8cos(1.2k) + w (Var w = 10), measured directly: z = x + v (Var v = 1). Claimed
    covariance: the weighted particle variance; estimate: the weighted mean (d = 1). (With the
    classic z = x²/20 + v the posterior is bimodal and a 1000-particle filter loses a mode
    now and then: whitened errors of thousands of σ, which measures the filter's collapse
    rather than the rule.) Even so the predicted cloud is sometimes far wider than the
    likelihood (the dynamics' slope reaches 25 near 0), the weights degenerate and the
    particle variance collapses at that epoch: about 1 epoch in 7000 has |whitened| > 6
    (1 in 4000 with 1000 particles)."""

    def fx(x, k):
        return x / 2 + 25 * x / (1 + x**2) + 8 * math.cos(1.2 * k)

    x = rng.normal(0.0, math.sqrt(5.0))
    p = rng.normal(0.0, math.sqrt(5.0), particles)
    err, cov = np.empty((steps, 1)), np.empty((steps, 1, 1))
    for k in range(1, steps + 1):
        x = fx(x, k) + math.sqrt(10.0) * rng.standard_normal()
        z = x + rng.standard_normal()
        p = fx(p, k) + math.sqrt(10.0) * rng.standard_normal(particles)
        logw = -0.5 * (z - p) ** 2
        w = np.exp(logw - logw.max())
        w /= w.sum()
        mean = w @ p
        err[k - 1, 0] = x - mean
        cov[k - 1, 0, 0] = max(w @ (p - mean) ** 2, 1e-12)
        cdf = np.cumsum(w)
        cdf[-1] = 1.0
        p = p[np.searchsorted(cdf, (rng.uniform() + np.arange(particles)) / particles)]
    return err, cov


def _run_gtsam_pose2(
    steps: int,
    rng: np.random.Generator,
    v: float = 5.0,
    odo_sig: tuple = (0.05, 0.02, math.radians(1.0)),
    gps_sig: float = 0.5,
):
    """GTSAM batch smoother (Levenberg–Marquardt, then Marginals) over Pose2 odometry at
    10 Hz (σ = 5 cm, 2 cm, 1° per step) and GPS-like position factors at 1 Hz (σ = 0.5 m,
    a CustomFactor on the translation), a prior on the first pose drawn from its own
    covariance; the vehicle drives at 5 m/s turning ±0.3 rad/s. Errors: x, y (world frame)
    and heading (d = 3); claimed covariance: the marginals rotated into the world frame.
    (At 1 m/s with 0.2° odometry the heading is barely observable and the errors' τ is of
    the order of the run: batch means did not converge by B = 1000.)"""
    import gtsam

    dt, odo_sig = 0.1, np.asarray(odo_sig, float)
    prior_sig = np.array([1.0, 1.0, 0.1])
    t = np.arange(steps) * dt
    omega = 0.3 * np.sin(2 * np.pi * (t / 20.0 + rng.uniform()))
    truth = [gtsam.Pose2(0.0, 0.0, rng.uniform(-np.pi, np.pi))]
    for k in range(steps - 1):
        truth.append(truth[-1].compose(gtsam.Pose2(v * dt, 0.0, omega[k] * dt)))
    graph, init = gtsam.NonlinearFactorGraph(), gtsam.Values()
    prior_mean = truth[0].compose(gtsam.Pose2.Expmap(prior_sig * rng.standard_normal(3)))
    graph.add(gtsam.PriorFactorPose2(0, prior_mean, gtsam.noiseModel.Diagonal.Sigmas(prior_sig)))
    odo_noise = gtsam.noiseModel.Diagonal.Sigmas(odo_sig)
    est = prior_mean
    init.insert(0, est)
    for k in range(steps - 1):
        rel = truth[k].between(truth[k + 1])
        meas = rel.compose(gtsam.Pose2.Expmap(odo_sig * rng.standard_normal(3)))
        graph.add(gtsam.BetweenFactorPose2(k, k + 1, meas, odo_noise))
        est = est.compose(meas)
        init.insert(k + 1, est)
    gps_noise = gtsam.noiseModel.Isotropic.Sigma(2, gps_sig)

    def gps_error(z):
        def error(this, values, jacobians):
            pose = values.atPose2(this.keys()[0])
            if jacobians is not None:
                j = np.zeros((2, 3))
                j[:, :2] = pose.rotation().matrix()
                jacobians[0] = j
            return np.array([pose.x(), pose.y()]) - z

        return error

    for k in range(0, steps, int(round(1.0 / dt))):
        z = np.array([truth[k].x(), truth[k].y()]) + gps_sig * rng.standard_normal(2)
        graph.add(gtsam.CustomFactor(gps_noise, [k], gps_error(z)))
    result = gtsam.LevenbergMarquardtOptimizer(graph, init).optimize()
    marginals = gtsam.Marginals(graph, result)
    err, cov = np.empty((steps, 3)), np.empty((steps, 3, 3))
    for k in range(steps):
        pose = result.atPose2(k)
        err[k] = [
            truth[k].x() - pose.x(),
            truth[k].y() - pose.y(),
            (truth[k].theta() - pose.theta() + np.pi) % (2 * np.pi) - np.pi,
        ]
        j = np.eye(3)
        j[:2, :2] = pose.rotation().matrix()
        cov[k] = j @ marginals.marginalCovariance(k) @ j.T
    return err, cov


NAVLIE_SE3 = ("ekf", "iekf", "ukf")


def _run_se3(steps: int, rng: np.random.Generator, filt: str, navlie: bool):
    """One run of an SE(3) filter of ``se3_filters.py`` (``navlie``: navlie's): pose from a
    noisy body-frame twist at 100 Hz, four landmarks' body-frame positions at 10 Hz (σ = 5 cm).
    Errors: the body-frame error Log(T̂⁻¹T), rotation then translation (d = 6), with the
    claimed covariance in the same convention (the invariant EKF's world-frame covariance
    moved by the adjoint)."""
    run = se3_filters.run_navlie if navlie else se3_filters.run
    err, cov = run(filt, steps, rng)
    return err[0], cov[0]


LIBRARY_RUNS = {
    "filterpy-ukf-pendulum": _run_ukf_pendulum,
    "filterpy-ekf-range": _run_ekf_range,
    "stonesoup-ekf-radar": _run_stonesoup_radar,
    "stonesoup-ukf-radar": functools.partial(_run_stonesoup_radar, filt="ukf"),
    "pf-1d": _run_pf_1d,
    "gtsam-pose2-smoother": _run_gtsam_pose2,
    **{f"se3-{f}": functools.partial(_run_se3, filt=f, navlie=False) for f in se3_filters.FILTERS},
    **{f"navlie-se3-{f}": functools.partial(_run_se3, filt=f, navlie=True) for f in NAVLIE_SE3},
}
OPTIONAL = {
    "gtsam-pose2-smoother": "gtsam",
    **{f"navlie-se3-{f}": "navlie" for f in NAVLIE_SE3},
}
"""Families that run only where their library imports."""


@functools.cache
def _available(module: str) -> bool:
    try:
        __import__(module)
    except ImportError:
        return False
    return True


@functools.lru_cache(maxsize=8)
def library_run(family: str, n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """n epochs of a right-tuned library filter after its burn-in (cached in the process)."""
    rng = np.random.default_rng(seed)
    burn = BURN_IN[family]
    err, cov = LIBRARY_RUNS[family](burn + n, rng)
    err, cov = err[burn:], cov[burn:]
    err.setflags(write=False)
    cov.setflags(write=False)
    return err, cov


# --------------------------------------------------------------------------- public
def families() -> list[str]:
    libs = [f for f in LIBRARY_RUNS if f not in OPTIONAL or _available(OPTIONAL[f])]
    return [*SYNTHETIC, *KF_MODELS, *libs]


def kind(family: str) -> str:
    if family in SYNTHETIC:
        return "synthetic"
    if family in KF_MODELS:
        return "kf"
    if family in LIBRARY_RUNS:
        return "library"
    raise KeyError(f"unknown family {family!r}; known: {', '.join(families())}")


def _misfit_cov(cov: np.ndarray, misfit: str) -> tuple[np.ndarray, float]:
    if misfit == "small4":
        return cov / 4.0, 4.0
    if misfit == "large4":
        return cov * 4.0, 0.25
    return cov, 1.0


def make(family: str, n: int, rng: np.random.Generator, misfit: str = "none") -> Case:
    """One case of ``family`` with N = n epochs, drawn from ``rng`` only. The draws do not
    depend on ``misfit``: the same rng state gives the same underlying errors for every
    misfit (paired cases)."""
    if misfit not in MISFITS:
        raise ValueError(f"misfit must be one of {MISFITS}")
    k = kind(family)
    rate = None
    if k == "synthetic":
        fam = SYNTHETIC[family]
        w = fam.white(n, rng)
        cov_true = np.ascontiguousarray(fam.cov(n, rng))
        errors = np.einsum("nij,nj->ni", _sym_sqrt(cov_true), w)
        cov, factor = _misfit_cov(cov_true, misfit)
        tau = fam.tau(n)
    elif k == "kf":
        rate = KF_MODELS[family][1]
        if family == "kf-cv-10hz-mistuned" and misfit in MISTUNE:
            kf = filter_of(family, *MISTUNE[misfit])
            factor = float(np.trace(kf.true_out) / np.trace(kf.claimed))
            cov = np.broadcast_to(kf.claimed, (n, *kf.claimed.shape))
        else:
            kf = filter_of(family)
            cov, factor = _misfit_cov(np.broadcast_to(kf.claimed, (n, *kf.claimed.shape)), misfit)
        errors = kf_errors(kf, n, rng)
        tau = kf.tau
    else:
        rate = LIBRARY_RATE[family]
        seed = int(rng.integers(2**63))
        errors, cov0 = library_run(family, n, seed)
        errors = errors.copy()
        cov, factor = _misfit_cov(cov0, misfit)
        if misfit in ("none", "bias1"):
            factor = float("nan")
        tau = LIBRARY_TAU[family]
    bias = 0.0
    if misfit == "bias1":
        errors = errors + _bias_vector(np.asarray(cov))
        bias = 1.0
    return Case(family, errors, np.asarray(cov), factor, bias, float(tau), rate)


# --------------------------------------------------------------------------- checks
class _BatchMeans:
    """Accumulates batch means (known zero mean) and the covariance of whitened errors."""

    def __init__(self, batch: int):
        self.batch, self.mm, self.nb, self.cc, self.ne = batch, 0.0, 0, 0.0, 0

    def add(self, white: np.ndarray) -> None:
        nb = white.shape[0] // self.batch
        means = white[: nb * self.batch].reshape(nb, self.batch, -1).mean(axis=1)
        self.mm = self.mm + means.T @ means
        self.nb += nb
        self.cc = self.cc + white.T @ white
        self.ne += white.shape[0]

    def result(self) -> tuple[float, np.ndarray]:
        """(τ̂ = largest eigenvalue of B·E[m mᵀ] relative to the whitened covariance, that
        covariance)."""
        c = self.cc / self.ne
        return _tau_from(self.batch * self.mm / self.nb, c), c


def check_family(
    name: str, batches: int = 2000, seed: int = 12345, n: int = 2000
) -> tuple[float, float, float]:
    """(τ closed form, τ by batch means of a long simulation, max |Cov − I| of the whitened
    errors) for ``family`` with misfit "none".

    Batches of B = max(500, 30τ) epochs, about ``batches`` of them, simulated in runs of 10
    batches, each run started afresh from the stationary law. ``arfima-0.3``: τ is τ_N at
    N = n, so the batches are ``batches`` independent runs of n epochs. Library families: τ
    is the stored constant; runs of ``n`` epochs after burn-in, batches of
    B = min(n/5, max(50, 10τ)), ``batches`` of them in all."""
    rng = np.random.default_rng(seed)
    k = kind(name)
    if k == "library":
        tau = LIBRARY_TAU[name]
        guess = tau if np.isfinite(tau) else 20.0
        batch = int(min(n // 5, max(50, 10 * guess)))
        runs = max(1, int(math.ceil(batches / (n // batch))))
        acc = _BatchMeans(batch)
        for _ in range(runs):
            acc.add(whiten(*library_run(name, n, int(rng.integers(2**63)))))
    else:
        tau = make(name, n, rng).tau
        if name.startswith("arfima"):
            batch, per_run = n, 1
        else:
            batch, per_run = int(max(500, 30 * tau)), 10
        acc = _BatchMeans(batch)
        for _ in range(int(math.ceil(batches / per_run))):
            case = make(name, batch * per_run, rng)
            acc.add(whiten(case.errors, case.cov))
    t_bm, c = acc.result()
    return tau, t_bm, float(np.max(np.abs(c - np.eye(c.shape[0]))))


def estimate_library_tau(family: str, runs: int = 40, n: int = 2000, batch: int = 200):
    """τ of a library family by batch means over ``runs`` right-tuned runs of ``n`` epochs
    (how LIBRARY_TAU was measured); returns (τ̂, whitened covariance)."""
    rng = np.random.default_rng(2024)
    acc = _BatchMeans(batch)
    for _ in range(runs):
        acc.add(whiten(*library_run(family, n, int(rng.integers(2**63)))))
    return acc.result()
