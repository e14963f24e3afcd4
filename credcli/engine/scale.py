"""The scale test of the calibrated rule: is the claimed covariance too small or too large?

With W_k = Σ̂_k⁻¹, the GLS mean μ̂ = (Σ W_k)⁻¹ Σ W_k e_k and

.. math:: T = \\sum_k (e_k - \\hat\\mu)^\\top W_k (e_k - \\hat\\mu),

T ~ χ²_ν with ν = (N − 1)d exactly when the errors are independent Gaussian with
covariance Σ̂_k, whatever their mean (Cochran's theorem; the GLS residuals are the
projection of the whitened errors off the d-dimensional mean space). This is the NEES of
Eq. (1) on centred errors, so the test keeps its level under SMM, unlike the NCI (4).

Dependent or heavy-tailed errors make T more variable than χ²_ν. The reference then is a
Satterthwaite-scaled χ² (Satterthwaite 1946): T/f ~ χ²_{ν₀/f}, matching the mean ν₀ and
the variance N·Ω_q, with Ω_q the long-run variance of q_k = (e_k − μ̂)ᵀW_k(e_k − μ̂)
(:func:`credcli.engine.correlation.long_run_variance`), so serial correlation and kurtosis both
widen it. Because a short heavy-tailed sample that misses its rare large errors
underestimates Ω_q exactly when T is small, f is at least the factor implied by the
sample's quantile tails (:func:`tail_factor`). ν₀ = Nd − Σ_i max(1, τ_i): estimating the mean removes τ_i degrees of freedom per
whitened component when the epochs are correlated.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np
from scipy import special

from credcli.engine import correlation
from credcli.engine.batches import (
    MeanTest,
    batch_mean_test,
    batch_scale,
    boundary_inflation,
    bounds,
)
from credcli.engine.linalg import EPOCH_CHUNK, by_inverse_chunks, epoch_chunks, lower_inverse
from credcli.engine.memory import studentized_quantile
from credcli.engine.units import power_of_two_unit


@dataclass(frozen=True)
class ScaleTest:
    """Outcome of the scale test on one segment.

    Is the claimed covariance too small (optimism) or too large (pessimism)? T, the NEES
    of Eq. (1) on GLS-centred errors, is referred to χ²_ν, ν = (N − 1)d, for independent
    Gaussian errors (Cochran's theorem), and to a Satterthwaite-scaled χ² when the errors
    are dependent or heavy-tailed; see the module ``credcli.engine.scale``. A
    [Diagnosis][credcli.engine.diagnosis.Diagnosis] holds it as ``scale``.

    Attributes
    ----------
    statistic : float
        T, the sum of the centred NEES q_k.
    dof : float
        Degrees of freedom of the reference χ² after the Satterthwaite scaling (ν₀/f).
    satterthwaite : float
        f >= 1; T/f is referred to χ²_{dof}. 1 for independent Gaussian errors.
    scale_factor : float
        κ̂ = T/ν₀: multiply the claimed covariance by this to make it fit.
    scale_factor_low, scale_factor_high : float
        The equal-tailed 1 − level interval of κ.
    pvalue_upper, pvalue_lower : float
        P(χ² >= T/f) (small: optimism) and P(χ² <= T/f) (small: pessimism).
    bias : numpy.ndarray
        The GLS mean μ̂ (d,), in the log's units.
    bias_stderr : numpy.ndarray
        Its standard error per component (d,), dependence-adjusted.
    bias_mahalanobis : float
        ‖μ̂‖ in whitened units, √(μ̂ᵀ W̄ μ̂) with W̄ the mean of W_k.
    batches : int
        K when the reference is batch means (``credcli.engine.batches``: serially
        dependent errors; ``dof`` is then K − 1 of Student's t); 0 for the χ² reference.
    model_dof : float
        ν_Ω, the degrees of freedom of the dependence model behind the reference
        (``memory_scale_test``); inf when the reference assumes no estimated memory.
    equivalence_interval : tuple of float or None
        κ's one-sided 1 − level bounds, lower and upper (the equal-tailed 1 − 2·level
        interval): where they lie within [1/F, F] the two one-sided tests of κ ≤ 1/F and
        κ ≥ F each reject at the test's level, so a misfit by F or more is excluded at that
        level (Schuirmann 1987; [CREDIBLE_FACTOR][credcli.engine.rules.CREDIBLE_FACTOR]). None where
        the test has no interval.
    short_memory_interval : tuple of float or None
        The fitted model's own ``equivalence_interval`` where an alternative with more
        memory that the data do not exclude (long memory, or an ARMA) widened it
        (``under_either``); None otherwise.

    References
    ----------
    F. E. Satterthwaite, "An approximate distribution of estimates of variance
    components", *Biometrics Bulletin* 2(6), 1946. D. J. Schuirmann, "A comparison of the
    two one-sided tests procedure and the power approach for assessing the equivalence of
    average bioavailability", *J. Pharmacokinetics and Biopharmaceutics* 15(6), 1987.

    Examples
    --------
    >>> from credcli import diagnose
    >>> e = np.random.default_rng(0).standard_normal((400, 2)) * 2.0  # 2σ errors, Σ̂ = I
    >>> test = diagnose(e, np.eye(2), seed=0).scale
    >>> round(test.scale_factor, 1), bool(test.scale_factor_low < 4 < test.scale_factor_high)
    (4.0, True)
    >>> test.pvalue < 0.001
    True
    """

    statistic: float
    dof: float
    satterthwaite: float
    scale_factor: float
    scale_factor_low: float
    scale_factor_high: float
    pvalue_upper: float
    pvalue_lower: float
    bias: np.ndarray
    bias_stderr: np.ndarray
    bias_mahalanobis: float
    batches: int = 0
    model_dof: float = float("inf")  # ν_Ω of a dependence model's reference (inf: none)
    equivalence_interval: tuple[float, float] | None = None
    short_memory_interval: tuple[float, float] | None = None

    @property
    def pvalue(self) -> float:
        """Two-sided p-value, 2 min(upper, lower), at most 1 (NaN when untested).

        Small for optimism (``pvalue_upper`` small) and for pessimism (``pvalue_lower``).
        """
        if np.isnan(self.pvalue_upper) or np.isnan(self.pvalue_lower):
            return float("nan")
        return min(1.0, 2.0 * min(self.pvalue_upper, self.pvalue_lower))

    def __repr__(self) -> str:
        return (
            f"ScaleTest(scale_factor={self.scale_factor:.4g}, pvalue={self.pvalue:.3g}, "
            f"dof={self.dof:.4g})"
        )


@dataclass(frozen=True)
class GlsResiduals:
    """Centred, whitened errors: what the scale test and the dependence estimate share.

    Attributes
    ----------
    mean : numpy.ndarray
        μ̂ (d,), the GLS mean (Σ W_k)⁻¹ Σ W_k e_k.
    whitened : numpy.ndarray
        u_k = L_k⁻¹(e_k − μ̂) (N, d), the whitened residuals.
    precision_sum : numpy.ndarray
        Σ W_k (d, d), W_k = Σ̂_k⁻¹.
    make_scores : callable
        Returns the scores g_k = W_k e_k (N, d), so that Σ g_k = (Σ W_k) μ̂: those made
        with the residuals, or made when first read (:attr:`scores`).
    """

    mean: np.ndarray  # μ̂ (d,)
    whitened: np.ndarray  # u_k = L_k⁻¹(e_k − μ̂), (N, d)
    precision_sum: np.ndarray  # Σ W_k (d, d)
    make_scores: Callable[[], np.ndarray] = field(repr=False, compare=False)

    @functools.cached_property
    def scores(self) -> np.ndarray:
        """g_k = W_k e_k (N, d), so that Σ g_k = (Σ W_k) μ̂: the mean tests' scores."""
        return self.make_scores()

    def release_scores(self) -> None:
        """Forget :attr:`scores` where they were made when first read (they are made
        again if read again): a long segment does not hold them past its mean tests."""
        vars(self).pop("scores", None)

    @functools.cached_property
    def q(self) -> np.ndarray:
        """q_k = (e_k − μ̂)ᵀ W_k (e_k − μ̂), computed once (the scale and dependence
        estimates of a segment all read it)."""
        return np.einsum("ni,ni->n", self.whitened, self.whitened)

    @functools.cached_property
    def tail_quantiles(self) -> np.ndarray:
        """The quantiles at ``_TAIL_PROBS`` of the :func:`standardized` residuals' pooled
        components, computed once (the overall, per-direction and model scale tests all
        read their tails, :func:`tail_factor`)."""
        u = standardized(self.whitened)
        return tail_quantiles(u, overwrite=u is not self.whitened)  # a copy: select in it

    @property
    def bias_mahalanobis(self) -> float:
        """‖μ̂‖ in the metric of the mean claimed precision, Σ W_k / N: the bias in σ."""
        n = self.whitened.shape[0]
        return float(np.sqrt(max(0.0, self.mean @ (self.precision_sum / n) @ self.mean)))


def gls_residuals(
    errors: np.ndarray,
    chol: np.ndarray | None,
    inverse: np.ndarray | None = None,
    cov: np.ndarray | None = None,
) -> GlsResiduals:
    """μ̂ = (Σ Σ_k⁻¹)⁻¹ Σ Σ_k⁻¹ e_k and the whitened residuals F_k(e_k − μ̂), with
    whitening factors F_kᵀF_k = Σ_k⁻¹ given (the segment's Σ_k^{-1/2},
    :func:`credcli.engine.linalg.whitening_factors`) or made here as L_k⁻¹
    (:func:`credcli.engine.linalg.lower_inverse`).

    Parameters
    ----------
    errors : numpy.ndarray, shape (N, d)
        The errors e_k (clean).
    chol : numpy.ndarray, shape (N, d, d) or (d, d), or None
        The Cholesky factors L_k of Σ̂_k, or one shared factor; None where ``inverse``
        is given (not read then).
    inverse : numpy.ndarray or None, shape (N, d, d)
        The whitening factors F_k where the caller has them (the residuals are then
        F_k(e_k − μ̂)); None (default): L_k⁻¹, computed here chunk by chunk. Not read with
        a shared factor.
    cov : numpy.ndarray or None, shape (N, d, d)
        The covariances, where the scores are to be made from them when first read
        (a chunk of epochs at a time, with ``inverse`` the segment's
        :func:`credcli.engine.linalg.whitening_factors`: the same numbers; a long
        segment's model fit and checks then do not hold them); None (default): made here.

    Returns
    -------
    GlsResiduals
        μ̂, the whitened residuals u_k, Σ W_k and the scores W_k e_k.
    """
    n, d = errors.shape
    if inverse is None and chol.ndim == 2:
        inv = lower_inverse(chol[None])[0]  # L⁻¹
        z = errors @ inv.T
        precision_sum = n * (inv.T @ inv)
        scores = z @ inv
        weighted = inv.T @ z.sum(axis=0)
        mean = np.linalg.solve(precision_sum, weighted)
        return GlsResiduals(
            mean, z - inv @ mean, precision_sum, functools.partial(_as_made, scores)
        )
    z = np.empty((n, d))
    scores = np.empty((n, d)) if cov is None else None
    precision_sum = np.zeros((d, d))
    weighted = np.zeros(d)
    single = n <= EPOCH_CHUNK  # then the one chunk's L_k⁻¹ is kept for the second pass
    for sl in epoch_chunks(n):  # chunks of epochs: bounded temporaries
        inv = lower_inverse(chol[sl]) if inverse is None else inverse[sl]  # L_k⁻¹
        z[sl] = np.einsum("nij,nj->ni", inv, errors[sl])
        precision_sum += np.einsum("nki,nkj->ij", inv, inv)
        if scores is not None:
            scores[sl] = np.einsum("nki,nk->ni", inv, z[sl])
        weighted += np.einsum("nki,nk->i", inv, z[sl])
    mean = np.linalg.solve(precision_sum, weighted)
    for sl in epoch_chunks(n):
        if inverse is not None:
            inv = inverse[sl]
        elif not single:
            inv = lower_inverse(chol[sl])
        z[sl] -= np.einsum("nij,j->ni", inv, mean)
    if scores is None:
        return GlsResiduals(
            mean, z, precision_sum, functools.partial(_per_epoch_scores, errors, cov)
        )
    return GlsResiduals(mean, z, precision_sum, functools.partial(_as_made, scores))


def _as_made(scores: np.ndarray) -> np.ndarray:
    """The scores made with the residuals (:attr:`GlsResiduals.make_scores`)."""
    return scores


def _per_epoch_scores(errors: np.ndarray, cov: np.ndarray) -> np.ndarray:
    """The GLS scores g_k = W_k e_k = F_kᵀ(F_k e_k) (N, d), with F_k = Σ_k^{-1/2} made
    from ``cov`` a chunk of epochs at a time
    (:func:`credcli.engine.linalg.by_inverse_chunks`): the numbers :func:`gls_residuals`
    makes with the segment's factors."""
    return by_inverse_chunks(_scores_of, errors, cov, errors.shape[1:])


def _scores_of(errors: np.ndarray, inverse: np.ndarray) -> np.ndarray:
    """g_k = F_kᵀ(F_k e_k), as :func:`gls_residuals` makes them."""
    return np.einsum("nki,nk->ni", inverse, np.einsum("nij,nj->ni", inverse, errors))


_TAIL_PROBS = (0.025, 0.25, 0.75, 0.975)
_GAUSS_RATIO = float(special.ndtri(0.975) / special.ndtri(0.75))  # 2.906
_RATIO_SE = 3.85  # standard deviation of the ratio under the normal, times √m (measured)
_T_NU = np.geomspace(4.05, 2000.0, 600)
_T_RATIO = special.stdtrit(_T_NU, 0.975) / special.stdtrit(_T_NU, 0.75)  # decreasing in ν
TAIL_GATE = 1.28
"""The ratio is read as a tail only when it exceeds the normal value by this many standard
errors (one-sided 10 %); below that the tails are taken as normal. The value trades false
alarms on heavy tails against accuracy on Gaussian errors (measured in docs/measured.md)."""


def tail_quantiles(u: np.ndarray, overwrite: bool = False) -> np.ndarray:
    """The quantiles at ``_TAIL_PROBS`` (2.5, 25, 75 and 97.5 %) of the pooled components
    of ``u``: what :func:`tail_factor` reads.

    Parameters
    ----------
    u : numpy.ndarray, shape (N, d)
        The standardized residuals (:func:`standardized`).
    overwrite : bool, default False
        Select the quantiles in ``u`` itself, reordering it, rather than in a copy (the
        same values; no second N × d array).

    Returns
    -------
    numpy.ndarray, shape (4,)
        The four quantiles, increasing.
    """
    return np.quantile(u.ravel(), _TAIL_PROBS, overwrite_input=overwrite)


def tail_factor(
    u: np.ndarray,
    gate: float = TAIL_GATE,
    memory_ratio: float = 1.0,
    quantiles: np.ndarray | None = None,
) -> float:
    """Variance factor of q_k = ‖u_k‖² implied by the tails of the whitened residuals u (N, d).

    The ratio R = (Q.975 − Q.025)/(Q.75 − Q.25) of the pooled components is 2.906 for the
    normal and larger for heavier tails; it does not collapse in a sample that happens to
    miss its rare large errors, as the sample variance of q_k does. When R exceeds 2.906 by
    more than ``gate`` standard errors it is read as a Student-t with ν degrees of freedom
    (excess kurtosis k = 6/(ν − 4)); for an elliptical law Var(q) = 2d(1 + (d + 2)k/6), so
    the factor is 1 + (d + 2)k/6. ν is floored at 4.05; otherwise the factor is 1.

    Parameters
    ----------
    u : numpy.ndarray, shape (N, d)
        The whitened residuals (standardized per direction: ``standardized``).
    gate : float
        Standard errors of R above its normal value before R is read as a tail (default
        ``TAIL_GATE``).
    memory_ratio : float, default 1
        The variance of R relative to independent epochs, for serially dependent residuals
        (:func:`quartic_ratio` of their model). R is a ratio of ranges of symmetric
        quantiles: even and free of scale, so its Hermite rank is 4 and its variance grows
        with Σρ⁴, not with τ = Σρ or Σρ² (measured: 0.53–0.66 × (1 + 2Σ_{h>0} ρ(h)⁴) for
        AR(1) φ 0.5–0.97 and AR(2) with complex or double roots). Ignoring it, the gate
        opened on 14–20 % of Gaussian AR(2) windows (roots 0.95∠±0.3), not 10 %.
    quantiles : numpy.ndarray, optional
        The :func:`tail_quantiles` the ratio is read from, where the caller has them
        already (``GlsResiduals.tail_quantiles``, of the standardized residuals); ``u`` then
        gives only the shape (N, d).

    Returns
    -------
    float
        The factor f >= 1 on the variance of q_k: 1 for normal tails, or when the
        quartiles coincide.
    """
    n, d = u.shape
    m = u.size
    q = tail_quantiles(u) if quantiles is None else quantiles
    inner = q[2] - q[1]
    if not inner > 0:
        return 1.0
    ratio = (q[3] - q[0]) / inner
    if ratio <= _GAUSS_RATIO + gate * _RATIO_SE * np.sqrt(max(memory_ratio, 1.0) / m):
        return 1.0
    nu = float(np.interp(ratio, _T_RATIO[::-1], _T_NU[::-1]))
    kurtosis = 6.0 / (nu - 4.0)
    return 1.0 + (d + 2) * kurtosis / 6.0


def quartic_ratio(memory, n: int) -> float:
    """1 + 2 Σ_{0<h<n} ρ(h)⁴ averaged over the principal directions of a dependence model:
    the variance of a scale-free even statistic of the pooled components (the tail ratio of
    :func:`tail_factor`) relative to independent epochs, to leading Hermite order (Arcones
    1994: a scale-free even statistic has Hermite rank 4).

    Parameters
    ----------
    memory : Memory
        The fitted dependence model (``credcli.engine.memory.Memory``).
    n : int
        Epochs in the window.

    Returns
    -------
    float
        The ratio, at least 1 (1 for white errors).
    """
    # ρ is zero past the model's horizon: its kept lags are the whole sum
    return float(np.mean([1.0 + 2.0 * np.sum(m.rho[1:n] ** 4) for m in memory.series]))


def standardized(u: np.ndarray) -> np.ndarray:
    """The whitened residuals in their principal directions, each divided by its own spread.

    What the tail check pools (``tail_factor``). Unequal variances between directions are
    a misfit of the covariance's shape, not heavy tails, and would otherwise read as tails
    (and hide the misfit).

    Parameters
    ----------
    u : numpy.ndarray, shape (N, d)
        The whitened residuals.

    Returns
    -------
    numpy.ndarray, shape (N, d)
        u rotated onto the eigenvectors of uᵀu/(N − 1), each column divided by the square
        root of its eigenvalue and signed so that its first epoch is not negative; u
        itself for d = 1.

    Notes
    -----
    An eigenvector's sign is the eigensolver's choice, and the tail ratio pools the
    columns' 2.5 and 97.5 % quantiles, which a skewed column's sign moves: the same errors
    in another frame (e → Re, Σ → RΣRᵀ), or another LAPACK, read a tail factor of 1.0 or
    14.5 (``benchmarks/frame.py``). The first epoch's sign is the data's own, and it
    leaves the columns' skews as unaligned as the solver's signs did: signed by their
    skewness instead, the pooled columns' tails read heavier, and the i.i.d. zoo family
    at 50 epochs lost 10 points of its decided segments (87 → 77 %).
    """
    n, d = u.shape
    if d == 1:
        return u
    values, vectors = np.linalg.eigh(u.T @ u / max(n - 1, 1))
    scale = np.sqrt(np.maximum(values, np.finfo(float).tiny))
    rotated = u @ vectors
    rotated /= scale  # in place: one N × d array
    flipped = rotated[0] < 0
    if flipped.any():
        rotated[:, flipped] *= -1.0
    return rotated


def scale_test(
    residuals: GlsResiduals,
    level: float,
    tau: np.ndarray | None = None,
    squares_white: bool = False,
) -> ScaleTest:
    """The scale test at two-sided ``level``, from the GLS residuals.

    With fewer than ``MIN_REFERENCE_DOF`` degrees of freedom left, the p-values are NaN
    and the interval (0, ∞): nothing is decided.

    Parameters
    ----------
    residuals : GlsResiduals
        The GLS residuals of the segment (``gls_residuals``).
    level : float
        α_S: the interval is 1 − α_S, each tail of the test α_S/2.
    tau : array (d,), optional
        Variance ratios τ_i of the whitened components
        (:func:`credcli.engine.correlation.variance_ratio`). None: independent epochs, the exact
        χ²_{(N−1)d} reference with no Satterthwaite factor.
    squares_white : bool
        With ``tau``: the squared errors are known to be serially independent (a white
        dependence model, :attr:`credcli.engine.memory.Memory.white`), so their variance,
        not a long-run variance, sets the Satterthwaite factor (default False).

    Returns
    -------
    ScaleTest
        κ̂ = T/ν₀, its interval, the one-sided p-values of T/f against χ²_{ν₀/f}, and
        the GLS bias with its standard error (its variance scaled by κ̂ and, with
        ``tau``, by the largest τ_i).

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> e = rng.standard_normal((500, 2)) * 2.0  # errors twice the claimed 1-sigma
    >>> r = gls_residuals(e, np.linalg.cholesky(np.eye(2)))
    >>> t = scale_test(r, 0.05)
    >>> round(t.scale_factor, 1), t.scale_factor_low < 4 < t.scale_factor_high
    (3.8, True)
    """
    q = residuals.q
    n, d = residuals.whitened.shape
    total = float(q.sum())
    cov_mean = np.linalg.inv(residuals.precision_sum)  # Cov(μ̂) for κ = 1, independent
    if tau is None:
        nu0 = float((n - 1) * d)
        factor = 1.0
        inflation = 1.0
    else:
        tau = np.maximum(np.asarray(tau, dtype=float), 1.0)
        nu0 = float(n * d - tau.sum())
        q_mean = total / n
        # scale-free: the long-run variance of q/q̄ (q̄² can overflow for extreme scales)
        if not q_mean > 0:
            omega = 0.0
        elif squares_white:
            omega = float(np.var(q / q_mean))
        else:
            omega = float(correlation.long_run_variance(q / q_mean)[0])
        factor = max(1.0, nu0 * omega / (2.0 * n))
        factor = max(factor, tail_factor(residuals.whitened, quantiles=residuals.tail_quantiles))
        inflation = float(tau.max())
    nu0 = max(nu0, 1.0)
    dof = nu0 / factor
    x = total / factor
    upper, lower = _pvalues(x, dof)
    kappa = total / nu0
    low, high = chi2_interval(x, dof, level)
    variances = np.clip(np.diag(cov_mean), 0.0, None)
    with np.errstate(over="ignore"):
        stderr = np.sqrt(variances * kappa * inflation)
    if not np.all(np.isfinite(stderr)):  # the product's range, not its roots': split them
        stderr = np.sqrt(variances) * math.sqrt(kappa * inflation)
    mean = residuals.mean
    return ScaleTest(
        statistic=total,
        dof=dof,
        satterthwaite=factor,
        scale_factor=kappa,
        scale_factor_low=low,
        scale_factor_high=high,
        pvalue_upper=upper,
        pvalue_lower=lower,
        bias=mean,
        bias_stderr=stderr,
        bias_mahalanobis=residuals.bias_mahalanobis,
        equivalence_interval=chi2_interval(x, dof, _one_sided(level)),
    )


MIN_REFERENCE_DOF = 1.0
"""Below one degree of freedom the Satterthwaite χ² is no sum of squares (its density is
unbounded at 0) and its quantiles bound nothing: the interval is (0, ∞)."""


def _pvalues(x: float, dof: float) -> tuple[float, float]:
    """(P upper, P lower) of x against χ²_dof; NaN below :data:`MIN_REFERENCE_DOF`."""
    if not dof >= MIN_REFERENCE_DOF:
        return math.nan, math.nan
    return float(special.chdtrc(dof, x)), float(special.chdtr(dof, x))


def chi2_interval(x: float, dof: float, level: float) -> tuple[float, float]:
    """The 1 − ``level`` interval of κ from T/c = ``x`` ~ κ·χ²_dof, equal tails.

    Parameters
    ----------
    x : float
        T/c, the statistic divided by the Satterthwaite factor.
    dof : float
        The degrees of freedom of the reference χ².
    level : float
        The two-sided level.

    Returns
    -------
    low, high : float
        x/χ²_dof(1 − level/2) and x/χ²_dof(level/2); (0, ∞) below ``MIN_REFERENCE_DOF``.

    Examples
    --------
    >>> low, high = chi2_interval(100.0, 100.0, 0.05)
    >>> round(low, 3), round(high, 3)
    (0.772, 1.347)
    """
    upper = float(special.chdtri(dof, level / 2))
    return _interval(x, dof, upper, float(special.chdtri(dof, 1 - level / 2)))


def _one_sided(level: float) -> float:
    """The two-sided level whose equal-tailed interval gives one-sided bounds at ``level``:
    2·level (at most 1, where the interval is the median's point)."""
    return min(2.0 * level, 1.0)


def _interval(x: float, dof: float, upper: float, lower: float) -> tuple[float, float]:
    """(x/upper, x/lower) from the reference's upper and lower quantiles, or (0, ∞) where
    the reference has fewer than :data:`MIN_REFERENCE_DOF` degrees of freedom (a short
    segment of heavy-tailed or slow errors): such an interval decides nothing, where the
    quantiles, underflowing to 0, would claim a misfit or end the run with a division by
    zero (issue 31, items 7 and 9)."""
    if not (dof >= MIN_REFERENCE_DOF and upper > 0.0):
        return 0.0, math.inf
    with np.errstate(over="ignore"):
        return x / upper, (x / lower if lower > 0.0 else math.inf)


def batch_scale_test(
    residuals: GlsResiduals,
    level: float,
    k: int,
    tau_q: float = 1.0,
    taus=None,
    independent: bool = False,
) -> ScaleTest:
    """The scale test on serially dependent errors, by batch means.

    Batch means with ``k`` batches (:func:`credcli.engine.batches.batch_scale`), and the
    bias's standard error from the batch sums of the GLS scores (their covariance times K
    is that of Σ W_k e_k). ``tau_q`` and ``taus`` (the variance ratios of q and of the
    whitened errors) correct both for the correlation of neighbouring batches
    (:func:`credcli.engine.batches.boundary_inflation`), unless the batches are
    ``independent`` (independent Monte Carlo runs).

    Parameters
    ----------
    residuals : GlsResiduals
        The GLS residuals of the segment.
    level : float
        α_S, the two-sided level.
    k : int
        K, the number of batches.
    tau_q : float
        The variance ratio of q_k (default 1).
    taus : array_like or None
        The variance ratios τ_i of the whitened components (d,) (default None: all 1);
        they also set the centring's loss of degrees of freedom, Σ_i max(1, τ_i).
    independent : bool
        The batches are independent (Monte Carlo runs): no boundary inflation (default
        False).

    Returns
    -------
    ScaleTest
        Student's t reference with ``dof`` K − 1 and ``batches`` K; the bias with its
        batch-means standard error.
    """
    q = residuals.q
    n, d = residuals.whitened.shape
    taus = np.ones(d) if taus is None else np.asarray(taus, dtype=float)
    centring = float(np.sum(np.maximum(taus, 1.0)))
    inflation = 1.0 if independent else boundary_inflation(tau_q, n, k)
    result = batch_scale(q, d, k, level, inflation, centring)
    starts = bounds(n, k)
    sums = np.add.reduceat(residuals.scores, starts, axis=0)
    # the sums are in units of the precision, cov_mean in its inverse: scaled by a power
    # of two each (exact), their product cannot overflow for any scale of Σ̂
    unit = power_of_two_unit(sums)
    cov_mean = np.linalg.inv(residuals.precision_sum) * unit
    inflation = 1.0 if independent else boundary_inflation(float(np.max(taus)), n, k)
    cov_sum = k * inflation * np.cov(sums / unit, rowvar=False).reshape(d, d)
    stderr = np.sqrt(np.clip(np.diag(cov_mean @ cov_sum @ cov_mean), 0.0, None))
    mean = residuals.mean
    return ScaleTest(
        statistic=float(q.sum()),
        dof=float(k - 1),
        satterthwaite=1.0,
        scale_factor=result.scale_factor,
        scale_factor_low=result.scale_factor_low,
        scale_factor_high=result.scale_factor_high,
        pvalue_upper=result.pvalue_upper,
        pvalue_lower=result.pvalue_lower,
        bias=mean,
        bias_stderr=stderr,
        bias_mahalanobis=residuals.bias_mahalanobis,
        batches=k,
        equivalence_interval=result.equivalence_interval,
    )


def untested_scale(residuals: GlsResiduals) -> ScaleTest:
    """κ̂ = T/((N − 1)d) and the GLS bias, without an interval or p-values (NaN).

    The numbers of a segment whose scale question cannot be tested.

    Parameters
    ----------
    residuals : GlsResiduals
        The GLS residuals of the segment.

    Returns
    -------
    ScaleTest
        T, κ̂, the bias and its Mahalanobis size; NaN for ``dof``, ``satterthwaite``, the
        interval, the p-values and ``bias_stderr``.
    """
    q = residuals.q
    n, d = residuals.whitened.shape
    mean = residuals.mean
    nan = float("nan")
    return ScaleTest(
        statistic=float(q.sum()),
        dof=nan,
        satterthwaite=nan,
        scale_factor=float(q.sum()) / max(1, (n - 1) * d),
        scale_factor_low=nan,
        scale_factor_high=nan,
        pvalue_upper=nan,
        pvalue_lower=nan,
        bias=mean,
        bias_stderr=np.full(d, nan),
        bias_mahalanobis=residuals.bias_mahalanobis,
    )


DIRECTION_POWER = 3
"""Each direction's interval is at level/d³: Bonferroni over the d directions, and d² more
because the directions are chosen from the data (the largest of d eigenvalues is biased
up). At level/d alone the false alarms on credible segments rose above the level, while
level/d³ decides anisotropic mismatch as often (measured in docs/measured.md)."""


@dataclass(frozen=True)
class DirectionScales:
    """The covariance factor along each principal direction of the whitened residuals.

    ``vectors`` (d, d) holds the directions as columns (whitened coordinates), ``factors``
    the mean squared residual along each (the eigenvalues of Ŝ = Σ u_k u_kᵀ/(N − 1)), with
    intervals each two-sided at level/d³ (:data:`DIRECTION_POWER`), widened for the
    directions' choice from the data (:func:`selection_widened`). In whitened
    coordinates the corrected covariance is L_k Ŝ L_kᵀ: ``vectors`` and ``factors`` are
    that matrix correction.

    Attributes
    ----------
    vectors : numpy.ndarray
        The principal directions (d, d) as columns, largest factor first.
    factors : numpy.ndarray
        The factor along each direction (d,).
    low, high : numpy.ndarray
        The interval of each factor (d,).
    sphericity_pvalue : float or None
        p-value of "the same factor in every direction" (``sphericity_pvalue``); None
        when not computed (d = 1, too few batches, or a dependence model).
    """

    vectors: np.ndarray
    factors: np.ndarray
    low: np.ndarray
    high: np.ndarray
    sphericity_pvalue: float | None = None  # :func:`sphericity_pvalue`


def direction_scales(
    residuals: GlsResiduals,
    level: float,
    batches: int = 0,
    memory=None,
    tail: float | None = None,
) -> DirectionScales:
    """Per-direction factors of the whitened GLS residuals u_k (N, d).

    For independent epochs each direction's w_k² = (v_iᵀu_k)² is referred to χ² with
    (N − 1)/f degrees of freedom, f the tail factor of the residuals standardized per
    direction (:func:`standardized`): pooled components of unequal variances look like heavy
    tails, standardized ones do not. With ``batches`` K > 0 (dependent epochs), Student's t on the
    log of the batch means of w_k², as :func:`credcli.engine.batches.batch_scale`. With a
    dependence model ``memory`` (:class:`credcli.engine.memory.Memory`), each direction's
    sum of squares is referred to the Satterthwaite χ² of the model's least informative
    direction (its centred-sum moments), studentized by the model's ν_Ω as the overall
    test is (:func:`memory_scale_test`). The
    directions are estimated from the same data, so the largest factor is biased up and the
    smallest down, by about 2√(d/ν) relatively for large d: each interval is widened by
    that (:func:`selection_widened`). The rule uses these intervals where the overall test
    is inconclusive, or where they disagree in sign (:func:`credcli.engine.rules.mixed`).

    Parameters
    ----------
    residuals : GlsResiduals
        The GLS residuals of the segment.
    level : float
        α_S; each direction's interval is two-sided at level/d³ (``DIRECTION_POWER``).
    batches : int
        K > 0: batch means with K batches (dependent epochs); 0 (default): independent
        epochs.
    memory : Memory or None
        A fitted dependence model (``credcli.engine.memory.Memory``); it takes precedence
        over ``batches`` (default None).
    tail : float or None
        With ``memory``: :func:`memory_tail_factor` of these residuals, where the caller
        has it (default None: computed here).

    Returns
    -------
    DirectionScales
        The directions, their factors and intervals; with a dependence model the factors
        are in units of the model's expected sums of squares and the sphericity p-value
        is None.
    """
    u = residuals.whitened
    n, d = u.shape
    values, vectors = np.linalg.eigh(u.T @ u / max(n - 1, 1))
    order = np.argsort(values)[::-1]
    values, vectors = values[order], vectors[:, order]
    w2 = (u @ vectors) ** 2
    each = level / d**DIRECTION_POWER
    low, high = np.empty(d), np.empty(d)
    if memory is not None:
        moments = [m.centred_square_moments(n) for m in memory.series]
        expected, variance = min(moments, key=lambda ev: 2.0 * ev[0] ** 2 / ev[1])
        variance *= memory_tail_factor(residuals, memory) if tail is None else tail
        c = variance / (2.0 * expected)
        dof = 2.0 * expected * expected / variance
        upper = _studentized_chi2_quantile(dof, memory.square_dof, each / 2, upper=True)
        lower = _studentized_chi2_quantile(dof, memory.square_dof, each / 2, upper=False)
        with np.errstate(over="ignore", divide="ignore"):
            x = values * (n - 1) / c
            low, high = x / upper, x / lower
        values = values * (n - 1) / expected
        low, high = selection_widened(low, high, d, dof)
        return DirectionScales(vectors, values, low, high, None)
    if batches:
        for i in range(d):
            r = batch_scale(w2[:, i], 1, batches, each)
            low[i], high[i] = r.scale_factor_low, r.scale_factor_high
        low, high = selection_widened(low, high, d, batches)
    else:
        f = tail_factor(u, quantiles=residuals.tail_quantiles)
        for i in range(d):
            low[i], high[i] = chi2_interval(values[i] * (n - 1) / f, (n - 1) / f, each)
        low, high = selection_widened(low, high, d, (n - 1) / f)
    return DirectionScales(vectors, values, low, high, sphericity_pvalue(residuals, batches))


TW_MEAN = -1.2065
"""The mean of the Tracy–Widom law of order 1 (Tracy & Widom 1996; Johnstone 2001)."""


def selection_widened(
    low: np.ndarray, high: np.ndarray, d: int, dof: float
) -> tuple[np.ndarray, np.ndarray]:
    """Direction intervals widened by the spread that choosing the directions from the data
    adds: the extreme eigenvalues of a sample covariance of ν degrees of freedom in d
    dimensions sit near (1 ± x)² times the true one however isotropic the truth, while each
    direction's interval covers only its own sampling error.

    √ν(Ŝ − I) tends to a d × d Gaussian orthogonal ensemble (off-diagonal variance 1), whose
    largest eigenvalue has the mean b_d ≈ 2√d + μ_TW d^{-1/6} (the semicircle's edge and the
    Tracy–Widom mean μ_TW = −1.2065 on its scale: Johnstone 2001), so x = b_d/(2√ν), which
    for large d is the Marchenko–Pastur edge √(d/ν) (Bai & Yin 1993). Simulated means
    (20,000 draws): 1.25, 3.75, 6.83, 10.17 at d = 2, 6, 15, 30, against b_d 1.75, 4.00,
    6.98, 10.27, which errs towards wider intervals where d is small; d = 1 selects nothing.

    Without it, credible errors of d = 30 in 1,000 epochs (eigenvalues 0.68–1.37) were
    called optimism in 19 of 20 segments, d = 15 in 9 of 20, and a single direction ¼ too
    large read as optimism; the level/d³ of :data:`DIRECTION_POWER` covers the directions'
    own fluctuations.

    Parameters
    ----------
    low, high : numpy.ndarray, shape (d,)
        Each direction's interval for its own sampling error.
    d : int
        The dimension.
    dof : float
        ν: the degrees of freedom of each direction's sum of squares (N − 1 over the tail
        factor; the dependence model's Satterthwaite ν; the number of batches).

    Returns
    -------
    low, high : numpy.ndarray
        ``low`` / (1 + x)² and ``high`` / (1 − x)² (∞ where x >= 1); unchanged for d = 1.

    References
    ----------
    I. M. Johnstone, "On the distribution of the largest eigenvalue in principal
    components analysis", Ann. Stat. 29(2), 2001. C. A. Tracy and H. Widom, "On orthogonal
    and symplectic matrix ensembles", Commun. Math. Phys. 177, 1996. Z. D. Bai and Y. Q.
    Yin, "Limit of the smallest eigenvalue of a large dimensional sample covariance
    matrix", Ann. Probab. 21(3), 1993.

    Examples
    --------
    >>> low, high = selection_widened(np.array([1.0]), np.array([1.0]), 30, 1000.0)
    >>> round(float(low[0]), 3), round(float(high[0]), 3)
    (0.74, 1.425)
    """
    if d < 2:
        return low, high
    edge = 2.0 * math.sqrt(d) + TW_MEAN * d ** (-1.0 / 6.0)
    spread = edge / (2.0 * math.sqrt(dof)) if dof > 0 else math.inf
    if spread >= 1.0:
        return low / (1.0 + spread) ** 2, np.full(np.shape(high), np.inf)
    with np.errstate(over="ignore"):  # an end already near the largest float: ∞, as meant
        return low / (1.0 + spread) ** 2, high / (1.0 - spread) ** 2


def sphericity_pvalue(residuals: GlsResiduals, batches: int = 0) -> float | None:
    r"""p-value of "the misfit is the same in every direction" (Ŝ ∝ I), or None.

    Independent epochs: Mauchly's test with Bartlett's correction (Mauchly 1940),
    :math:`-(n - \frac{2d^2 + d + 2}{6d}) \ln W \sim \chi^2_{d(d+1)/2 - 1}`,
    :math:`W = \det\hat S / (\operatorname{tr}\hat S / d)^d`, n = N − 1; it assumes Gaussian
    errors (heavy tails make it reject more often). With ``batches`` K (dependent epochs):
    Hotelling on the batch means of the m = d(d+1)/2 − 1 contrasts u_iu_j (i < j) and
    u_i² − u_1², referred to F(m, K − m); None when K <= m + 2. Reported, not used by the
    labels, which follow the per-direction intervals (:func:`direction_scales`).

    Parameters
    ----------
    residuals : GlsResiduals
        The GLS residuals of the segment.
    batches : int
        K > 0: Hotelling's test on K batch means; 0 (default): Mauchly's test.

    Returns
    -------
    float or None
        The p-value; None for d = 1 or K <= m + 2; 0 when Ŝ is singular.

    References
    ----------
    J. W. Mauchly, "Significance test for sphericity of a normal n-variate distribution",
    Ann. Math. Statist. 11(2), 1940.
    """
    u = residuals.whitened
    n_epochs, d = u.shape
    if d < 2:
        return None
    m = d * (d + 1) // 2 - 1
    if batches:
        if batches <= m + 2:
            return None

        iu = np.triu_indices(d, 1)
        contrasts = np.c_[(u[:, iu[0]] * u[:, iu[1]]), u[:, 1:] ** 2 - u[:, :1] ** 2]
        starts = bounds(n_epochs, batches)
        sizes = np.diff(np.r_[starts, n_epochs])[:, None]
        means = np.add.reduceat(contrasts, starts, axis=0) / sizes
        return batch_mean_test(means).pvalue
    n = n_epochs - 1
    s = u.T @ u / n
    sign, logdet = np.linalg.slogdet(s)
    trace = float(np.trace(s))
    if sign <= 0 or not trace > 0:
        return 0.0
    log_w = logdet - d * np.log(trace / d)
    statistic = -(n - (2 * d * d + d + 2) / (6 * d)) * log_w
    return float(special.chdtrc(m, max(statistic, 0.0)))


def memory_tail_factor(residuals: GlsResiduals, memory) -> float:
    """The tail factor of the standardized residuals under a dependence model's memory
    (:func:`tail_factor` with :func:`quartic_ratio`), which the overall and the
    per-direction scale tests share.

    Parameters
    ----------
    residuals : GlsResiduals
        The GLS residuals of the segment.
    memory : Memory
        The fitted dependence model (``credcli.engine.memory.Memory``).

    Returns
    -------
    float
        f >= 1.
    """
    u = residuals.whitened
    ratio = quartic_ratio(memory, u.shape[0])
    return tail_factor(u, memory_ratio=ratio, quantiles=residuals.tail_quantiles)


CROSS_REACH = 3.0
"""Lags over which :func:`cross_lag_variance` sums the directions' cross-covariances, in
units of the directions' largest τ̂: on the zoo's CA Kalman filters (position and
velocity, whose lagged cross-covariances are 26 % of the sum of squares' variance) 3τ
holds 99.7–99.9 % of Σ_h c_ij(h)², 2τ 97 % (``benchmarks/cross_terms.py``)."""
CROSS_EPOCHS = 1 << 18
"""Most epochs on which :func:`cross_lag_variance` reads the cross-correlations (the first
of a longer segment, as the sieve is fitted on its first ``memory.SIEVE_EPOCHS``): the
FFTs of a 2,000,000-epoch segment's two directions took 0.92 s, of 2^18 epochs 0.04 s."""
CROSS_SIGNIFICANCE = 2.0
"""Standard errors (under independent directions) by which the cross-lag term must exceed 0
to enter the scale test, as the centred NEES's own variance must exceed the directions'
(:func:`memory_scale_test`): below it the term is noise, whose variance would only take
degrees of freedom from the test (between slow or long-memory directions the sample
cross-correlations are large and noisy)."""


def cross_lag_variance(residuals: GlsResiduals, memory) -> tuple[float, float]:
    r"""What the principal directions' lagged cross-covariances add to the variance of the
    centred sum of squares, which the directions' own models treat as independent.

    For Gaussian errors Cov(T_i, T_j) = 2 Σ_{s,t} c_ij(t − s)², T_i the direction's sum of
    squares and c_ij its cross-covariance with direction j (Isserlis). The directions
    diagonalise the lag-0 and the long-run covariance, not every lag: position and
    velocity errors stay correlated across lags (``benchmarks/cross_terms.py``). The sum
    is estimated from the residuals' sample cross-correlations r̂_ij(h) on the first
    m = min(N, :data:`CROSS_EPOCHS`) epochs over |h| <= H = :data:`CROSS_REACH`·max τ̂_i (at
    most m/4), each less its expectation where the directions are independent,
    E r̂_ij(h)² = Σ_k ρ_i(k)ρ_j(k)/m (Bartlett 1946), with the directions' fitted ρ. The
    total counts only where it exceeds :data:`CROSS_SIGNIFICANCE` of its standard errors
    under independent directions; then its own error enters the scale test's model degrees
    of freedom beside the directions' models': Var r̂_ij(h)² is about
    2b²/m² + 4c_ij(h)²b/m with b = Σ_k ρ_i(k)ρ_j(k), the lags taken as independent.

    Parameters
    ----------
    residuals : GlsResiduals
        The GLS residuals.
    memory : Memory
        The dependence model: its directions and their autocorrelations.

    Returns
    -------
    cross, spread : tuple of float
        Σ_{i≠j} Cov(T_i, T_j) in the units of
        :meth:`credcli.engine.memory.SeriesMemory.centred_square_moments` (unit-variance
        directions), and half its estimate's variance (the form of the scale test's
        ``spread``); (0, 0) where it is not significant, for d = 1 or fewer than 16 epochs.

    References
    ----------
    M. S. Bartlett, "On the theoretical specification and sampling properties of
    autocorrelated time-series", J. R. Stat. Soc. Suppl. 8(1), 1946.
    """
    n, d = residuals.whitened.shape
    if d < 2 or n < 16:
        return 0.0, 0.0
    m = min(n, CROSS_EPOCHS)  # the correlations are read on the first m epochs
    x = residuals.whitened[:m] @ memory.directions
    x = x - x.mean(axis=0)
    scale = np.sqrt(np.mean(x * x, axis=0))
    if not np.all(scale > 0):
        return 0.0, 0.0
    x = x / scale
    reach = max(float(np.max(memory.variance_ratios)), 1.0)
    lags = int(min(math.ceil(CROSS_REACH * reach), m // 4))
    r = _lagged_correlations(x, lags)  # r[h]_ij = r̂_ij(h), h = 0 … H
    counts = (n - np.arange(lags + 1)).astype(float)
    windows = np.array([series.window(m)[1:] for series in memory.series])
    null = (1.0 + 2.0 * windows @ windows.T) / m  # E r̂_ij(h)², independent directions
    excess = r * r - null
    # lag h > 0 of the pair (i, j) is r[h]_ij, lag −h is r[h]_ji; lag 0 once
    folded = excess + np.swapaxes(excess, 1, 2)
    folded[0] = excess[0]
    squared = counts**2
    positive = np.maximum(excess, 0.0)
    positive = positive + np.swapaxes(positive, 1, 2)
    positive[0] = np.maximum(excess[0], 0.0)
    pairs = np.triu_indices(d, 1)
    total = 4.0 * float(np.einsum("h,hij->ij", counts, folded)[pairs].sum())
    # Var r̂² ≈ 2b²/m² + 4c²b/m per lag, b = m·null: over both signs of every lag
    independent = 32.0 * float(np.sum(null[pairs] ** 2)) * float(squared[0] + 2 * squared[1:].sum())
    signal = 64.0 * float(np.sum(null[pairs] * np.einsum("h,hij->ij", squared, positive)[pairs]))
    if not total > CROSS_SIGNIFICANCE * math.sqrt(independent):
        return 0.0, 0.0
    return total, (independent + signal) / 2.0


def _lagged_correlations(x: np.ndarray, lags: int) -> np.ndarray:
    """r[h] = x[:m − h]ᵀ x[h:]/m for h = 0 … ``lags`` (x: m × d, centred, unit variance):
    by products of the lagged series where there are few lags, by FFT where there are many
    (cost (H + 1)·m·d² against about d²·2m·log₂(2m))."""
    m, d = x.shape
    size = 1 << (2 * m - 1).bit_length()
    out = np.empty((lags + 1, d, d))
    if lags + 1 <= 2 * size.bit_length():
        for h in range(lags + 1):
            out[h] = x[: m - h].T @ x[h:]
        return out / m
    spectra = np.fft.rfft(x, size, axis=0)
    for i in range(d):  # a row of pairs at a time: (size, d), not (size, d, d)
        row = np.fft.irfft(spectra[:, i, None].conj() * spectra, size, axis=0)
        out[:, i, :] = row[: lags + 1]
    return out / m


def memory_scale_test(
    residuals: GlsResiduals, memory, level: float, tail: float | None = None
) -> ScaleTest:
    r"""The scale test of serially dependent errors under a fitted dependence model
    (:class:`credcli.engine.memory.Memory`, possibly fitted on a whole run of which these
    epochs are a window).

    Under the model, each principal direction's centred sum of squares is a Gaussian
    quadratic form with exact mean E_i and variance V_i
    (:meth:`credcli.engine.memory.SeriesMemory.centred_square_moments`); T = Σ_k q_k has
    mean E = Σ E_i and variance V = f Σ V_i, f the tail factor of the residuals
    (:func:`tail_factor`), or V_q/κ̂², the variance of T implied by the centred NEES's own
    fitted memory (heavy tails and any dependence between directions), where that exceeds
    it by two of its own standard errors. Then T/c ~ χ²_ν
    with c = V/(2E), ν = 2E²/V (Satterthwaite 1946) and κ̂ = T/E: at short windows of slow
    errors E is well below (N − 1)d, since centring a window removes its slow part.

    The model's own estimation error enters through the degrees of freedom of τ₂ = Σρ²
    (to which V is proportional; :func:`credcli.engine.memory.bootstrap_spread`): each
    one-sided p-value is the χ² evidence as a normal score referred to Student's t with
    ν_Ω degrees of freedom, and the interval is inverted from the same p-values, so the
    interval and the test agree.

    Parameters
    ----------
    residuals : GlsResiduals
        The GLS residuals of the epochs tested.
    memory : Memory
        The fitted dependence model (``credcli.engine.memory.Memory``): per-direction
        series memories and the memory of the squares.
    level : float
        α_S, the two-sided level.
    tail : float, optional
        :func:`memory_tail_factor` of these residuals and model, where the caller has it.

    Returns
    -------
    ScaleTest
        κ̂ = T/E, its interval and the studentized p-values (NaN below
        ``MIN_REFERENCE_DOF``), ``model_dof`` ν_Ω; ``bias_stderr`` is NaN (the model's
        mean test fills it).
    """
    q = residuals.q
    n, d = residuals.whitened.shape
    total = float(q.sum())
    moments = [series.centred_square_moments(n) for series in memory.series]
    expected = sum(e_i for e_i, _ in moments)
    gaussian = sum(v_i for _, v_i in moments)
    # Var(V)/2 from each distinct model's ν: directions fitted apart are independent, and
    # directions that share one model share its error
    spread = 0.0
    for model, served in memory.models():
        v = sum(moments[i][1] for i in served)
        # ν 0: a refit of the bootstrap had no finite τ₂, so nothing bounds the reference
        spread += v * v / model.square_dof if model.square_dof > 0 else math.inf
    kappa = total / expected
    # the directions' lagged cross-covariances, which their models leave out
    cross, cross_spread = cross_lag_variance(residuals, memory)
    gaussian += cross
    spread += cross_spread
    # ν of V = Σ V_i from each model's ν (Satterthwaite); the tail factor scales V and its
    # error alike, so it leaves ν as it is
    dof_model = gaussian * gaussian / spread if spread > 0 else math.inf
    gaussian *= memory_tail_factor(residuals, memory) if tail is None else tail
    variance = gaussian
    if kappa > 0:
        q_mean = total / n
        # q's own variance of T in units of κ = 1: Var(q/q̄)·n·v_q·(q̄/κ̂)², scale-free
        own = float(np.var(q / q_mean)) * n * memory.squares.mean_ratio(n) * (expected / n) ** 2
        # q's own estimate is noisier (ν_Ω of the squares): it replaces the Gaussian one
        # only where it exceeds it by two of its standard errors
        if own > variance * (1.0 + 2.0 * math.sqrt(2.0 / memory.squares.dof)):
            variance = own
            dof_model = min(dof_model, memory.squares.dof)
    c = variance / (2.0 * expected)
    dof = 2.0 * expected * expected / variance
    x = total / c
    upper, lower = _studentized_chi2(x, dof, dof_model)
    if not dof >= MIN_REFERENCE_DOF:
        upper = lower = math.nan
    low, high = _studentized_interval(x, dof, dof_model, level)
    equivalence = _studentized_interval(x, dof, dof_model, _one_sided(level))
    return ScaleTest(
        statistic=total,
        dof=dof,
        satterthwaite=c * dof / expected,
        scale_factor=kappa,
        scale_factor_low=low,
        scale_factor_high=high,
        pvalue_upper=upper,
        pvalue_lower=lower,
        bias=residuals.mean,
        bias_stderr=np.full(d, np.nan),  # filled by the model's mean test
        bias_mahalanobis=residuals.bias_mahalanobis,
        model_dof=dof_model,
        equivalence_interval=equivalence,
    )


def under_either(test: ScaleTest, other: ScaleTest) -> ScaleTest:
    """``test`` (the fitted model's) as a finding that must hold under ``other`` (a model
    the data do not exclude) as well: each one-sided p-value the larger of the two, the
    interval the smallest one that holds both (an intersection–union test: its level
    holds under either model; R. L. Berger, "Multiparameter hypothesis testing and
    acceptance sampling", Technometrics 24(4), 1982).

    Parameters
    ----------
    test, other : ScaleTest
        The scale test of the same residuals under the fitted model and under the other.

    Returns
    -------
    ScaleTest
        ``test`` with the union interval and union one-sided bounds, the larger p-values
        (NaN where either is) and the fewer model degrees of freedom, and its own one-sided
        bounds as ``short_memory_interval`` where the union's are wider; κ̂ stays the
        fitted model's.
    """
    own = test.equivalence_interval
    equivalence = _union(own, other.equivalence_interval)
    return replace(
        test,
        scale_factor_low=min(test.scale_factor_low, other.scale_factor_low),
        scale_factor_high=max(test.scale_factor_high, other.scale_factor_high),
        pvalue_upper=_larger(test.pvalue_upper, other.pvalue_upper),
        pvalue_lower=_larger(test.pvalue_lower, other.pvalue_lower),
        model_dof=min(test.model_dof, other.model_dof),
        equivalence_interval=equivalence,
        short_memory_interval=own if equivalence != own else None,
    )


def _union(a: tuple[float, float] | None, b: tuple[float, float] | None):
    """The smallest interval holding both (None where either is None: no bounds)."""
    if a is None or b is None:
        return None
    return min(a[0], b[0]), max(a[1], b[1])


def directions_under_either(scales: DirectionScales, other: DirectionScales) -> DirectionScales:
    """:func:`under_either` for the factors of the same principal directions (those of the
    residuals, whichever the model): each interval the smallest one that holds both.

    Parameters
    ----------
    scales, other : DirectionScales
        The directions' factors of the same residuals under the fitted model and under the
        other.

    Returns
    -------
    DirectionScales
        ``scales`` with each direction's interval the union of the two.
    """
    return replace(
        scales, low=np.minimum(scales.low, other.low), high=np.maximum(scales.high, other.high)
    )


def _larger(a: float, b: float) -> float:
    """The larger p-value, NaN (no test) where either is."""
    return math.nan if math.isnan(a) or math.isnan(b) else max(a, b)


def _studentized_chi2(x: float, dof: float, dof_model: float) -> tuple[float, float]:
    """(P upper, P lower) of x against χ²_dof, each turned into a normal score and referred
    to Student's t with ``dof_model`` degrees of freedom (the reference's own uncertainty)."""
    upper = _studentized(special.chdtrc(dof, x), dof_model)
    return float(upper), float(_studentized(special.chdtr(dof, x), dof_model))


def _studentized(tail, dof_model: float):
    """A χ² tail probability (or an array of them) as a normal score referred to Student's
    t with ``dof_model`` degrees of freedom (:func:`credcli.engine.memory.studentized_tail`,
    elementwise)."""
    z = -special.ndtri(np.maximum(tail, 1e-300))
    return special.ndtr(-z) if not math.isfinite(dof_model) else special.stdtr(dof_model, -z)


def _studentized_interval(x: float, dof: float, dof_model: float, level: float):
    """The equal-tailed 1 − ``level`` interval of κ inverted from the studentized p-values
    (:func:`_studentized_chi2`)."""
    return _interval(
        x,
        dof,
        _studentized_chi2_quantile(dof, dof_model, level / 2, upper=True),
        _studentized_chi2_quantile(dof, dof_model, level / 2, upper=False),
    )


def _studentized_chi2_quantile(dof: float, dof_model: float, p: float, upper: bool) -> float:
    """The x whose studentized upper (or lower) p-value is ``p``: the χ²_dof quantile at the
    normal tail of Student's critical value."""
    tail = float(special.ndtr(-studentized_quantile(p, dof_model)))
    if upper:
        return 2.0 * float(special.gammainccinv(dof / 2.0, tail))
    return max(2.0 * float(special.gammaincinv(dof / 2.0, tail)), np.finfo(float).tiny)


FAST_SHARES = np.linspace(0.0, 1.0, 401)[1:]
"""The grid of κ, the fast part's share of the claimed covariance, on which
:func:`slow_offset_pvalue` takes its supremum (steps of 0.0025)."""


def slow_mean_variance(share, mean_var, kappa_hat):
    """v(κ) = 1 − κ + κ s²/κ̂: the variance of the mean, in σ² of the claim, of errors made
    of a slow part holding 1 − κ of the claim (one value over the segment) and a fast part
    of scale κ whose mean varies by s² at the fitted scale κ̂ (the slow reading of
    :func:`slow_offset_pvalue` and :func:`slow_spread_pvalue`).

    Parameters
    ----------
    share : float or numpy.ndarray
        κ, the fast part's share of the claim.
    mean_var : float
        s², the fitted model's variance of the mean along x̂ at the fitted scale.
    kappa_hat : float
        κ̂, the fitted scale.

    Returns
    -------
    float or numpy.ndarray
        v(κ), the shape of ``share``.
    """
    return 1.0 - share + share * mean_var / kappa_hat


def offset_mean_variance(test: ScaleTest, mean: MeanTest) -> float:
    """s² = ‖x̂‖²/T²: the fitted model's variance of the mean along x̂, at the fitted
    scale, read from the mean test (T² = ``t2_per_f`` · F), as the slow readings use it
    (:func:`slow_mean_variance`).

    Parameters
    ----------
    test : ScaleTest
        The segment's scale test (‖x̂‖ as ``bias_mahalanobis``).
    mean : MeanTest
        The segment's mean test.

    Returns
    -------
    float
        s²; NaN where T² is not positive and finite.
    """
    t2 = float(mean.t2_per_f) * float(mean.statistic)
    if not (t2 > 0 and math.isfinite(t2)):
        return math.nan
    return float(test.bias_mahalanobis) ** 2 / t2


def slow_spread_pvalue(test: ScaleTest, mean_var: float, d: int) -> float:
    """The p-value of the reading that a pessimism is credible errors with a slow part: the
    lower tail P(χ²_d <= ‖x̂‖²/v(κ)) at the upper end κ of κ̂'s interval, where it is
    largest (:func:`slow_mean_variance`; at an end of 1 or more no slow part is needed,
    and the p-value is 1). An offset too small for a slow part of 1 − κ rejects the
    reading; NaN where κ̂ or the offset is not a number to read.

    Parameters
    ----------
    test : ScaleTest
        The segment's scale test (κ̂, its interval, ‖x̂‖ as ``bias_mahalanobis``).
    mean_var : float
        s², the fitted model's variance of the mean along x̂ at the fitted scale.
    d : int
        The state dimension.

    Returns
    -------
    float
        The p-value; 1 where the interval reaches 1, NaN where it cannot be read.
    """
    factor, high = float(test.scale_factor), float(test.scale_factor_high)
    offset_sq = float(test.bias_mahalanobis) ** 2
    if not (factor > 0 and math.isfinite(offset_sq) and not math.isnan(high)):
        return math.nan
    if not high < 1:
        return 1.0
    return float(special.chdtr(d, offset_sq / slow_mean_variance(high, mean_var, factor)))


def slow_offset_pvalue(test: ScaleTest, mean: MeanTest, d: int) -> tuple[float, float]:
    r"""The p-value of the reading that a segment's offset is a credible error slower than
    the segment, and the fast share κ at which the reading fits best.

    The reading, for a fast share 0 < κ <= 1: in the claim's whitened coordinates the
    errors are s + f_k, with s ~ N(0, (1 − κ)I) one value over the segment (the slow part,
    whose drift within the segment counts in f) and f_k the fitted dependence model's
    process at scale κ, so that the claimed covariance is the errors' total. For Gaussian
    errors the centred scale κ̂ and the mean x̂ (in σ of the claim) are then independent:

    - κ̂ν/κ follows the scale test's reference (χ²_ν, studentized by the model's own
      ν_Ω: :func:`_studentized_chi2`), and its upper tail p₁(κ) is the evidence that the
      spread about the mean leaves no room for a slow part of 1 − κ;
    - x̂ ~ N(0, v(κ)I) with v(κ) = 1 − κ + κ s²/κ̂, s² = ‖x̂‖²/T² the model's variance of
      the mean along x̂ at the fitted scale κ̂ (T² the mean test's Hotelling statistic),
      and p₂(κ) = P(χ²_d >= ‖x̂‖²/v(κ)).

    Fisher's combination −2 ln(p₁p₂), referred to χ²₄, is a level test of each κ, so its
    largest p-value over κ (:data:`FAST_SHARES`) is a level test of the union: a credible
    slow error is rejected only where it is rejected at every share. The scale weighs in
    where the interval of κ alone would not: a 1σ bias over independent epochs (claim I,
    d = 2, 100 segments each, the mean test's level) rejects the slow reading in 28 of 94
    segments of 50 epochs, 71 of 100 of 200 and 99 of 99 of 1,000, a 2σ bias over 50
    epochs in 96 of 100; the offset check of pessimism with a bias, which asks only
    whether some κ in the scale's interval leaves room for the offset, finds room in 93,
    100 and 95 of those 1σ segments.

    Parameters
    ----------
    test : ScaleTest
        The segment's scale test (κ̂, ν, ν_Ω, and ‖x̂‖ as ``bias_mahalanobis``); where it has
        no reference (NaN p-values) p₁ is 1: only the mean then speaks.
    mean : MeanTest
        The mean test under the same model (its F statistic and ``t2_per_f``).
    d : int
        The state dimension.

    Returns
    -------
    pvalue : float
        The largest combined p-value over κ.
    share : float
        The κ where it is largest.

    References
    ----------
    R. A. Fisher, *Statistical Methods for Research Workers*, 4th ed., 1932, §21.1.
    R. L. Berger, "Multiparameter hypothesis testing and acceptance sampling",
    Technometrics 24(4), 1982 (a union of nulls rejected where each is).
    """
    offset_sq = float(test.bias_mahalanobis) ** 2
    mean_var = offset_mean_variance(test, mean)
    kappa_hat = float(test.scale_factor)
    if math.isnan(mean_var) or not (kappa_hat > 0 and math.isfinite(kappa_hat)):
        return math.nan, math.nan
    share = FAST_SHARES
    if math.isnan(test.pvalue_upper):
        upper = np.ones(share.size)
    else:
        upper = _studentized(special.chdtrc(test.dof, kappa_hat * test.dof / share), test.model_dof)
    spread = slow_mean_variance(share, mean_var, kappa_hat)
    located = special.chdtrc(d, offset_sq / spread)
    with np.errstate(divide="ignore"):
        combined = special.chdtrc(4, -2.0 * (np.log(upper) + np.log(located)))
    best = int(np.argmax(combined))
    return float(combined[best]), float(share[best])
