"""The unified diagnosis (Algorithm 1) and the single-metric baselines of Table II."""

from __future__ import annotations

import functools
import math
import zlib
from dataclasses import dataclass, field, replace
from typing import NamedTuple

import numpy as np
from scipy import special

from credcli.engine import batches, dependence, metrics
from credcli.engine.config import (  # noqa: F401 (the names of a diagnosis, re-exported)
    AUTO,
    DEFAULT_MAX_EPOCHS,
    DIAGNOSIS_LABELS,
    LABEL_ALIASES,
    MAX_FLIPS,
    MIN_ELT_EPOCHS,
    DiagnosisConfig,
    Label,
    MetricsLevel,
    Question,
    SrdForm,
    Variant,
    parse_label,
)
from credcli.engine.elt import ELTResult, tested_blocks, whiten, whitened_location_test
from credcli.engine.rng import RngLike, as_generator
from credcli.engine.scale import (
    DirectionScales,
    ScaleTest,
    batch_scale_test,
    direction_scales,
    gls_residuals,
    scale_test,
    untested_scale,
)
from credcli.engine.whiteness import Whiteness, portmanteau
from credcli.errors import CredcliError


@dataclass(frozen=True)
class BlockScale:
    """The scale factor of one named block of the state (its marginal errors against its
    block of the claimed covariance), with its interval at the scale level shared among
    the blocks (Bonferroni); NaN bounds when the block's scale cannot be tested."""

    name: str
    indices: tuple[int, ...]
    factor: float
    low: float
    high: float


@dataclass(frozen=True)
class Diagnosis:
    """Result of Algorithm 1 on one segment, with every intermediate number.

    ``scores`` are the mean NLL/ES of the claimed predictive N(x̂, sΣ̂) at s = 1/c, 1, c;
    ``probes`` are those of the centred predictive F̃ (Eq. (18)) with the SRDs (19).
    Either is None when not computed.
    """

    label: Label
    n: int
    dim: int
    elt: ELTResult | None = None
    smm_detected: bool | None = None
    nci: float | None = None
    nci_centered: float | None = None
    anees: float | None = None
    ks_pvalue: float | None = None
    nees_label: Label | None = None
    nci_label: Label | None = None
    scores: metrics.Probes | None = None
    probes: metrics.Probes | None = None
    scale: ScaleTest | None = None
    block_length: int | None = None
    effective_n: float | None = None
    autocorrelation: float | None = None
    reason: str | None = None
    config: DiagnosisConfig = field(default_factory=DiagnosisConfig, repr=False)
    mean_test: batches.MeanTest | None = None
    untested: tuple[Question, ...] = ()
    directions: DirectionScales | None = None  # per principal direction (calibrated, d > 1)
    by_direction: bool = False  # the noise label comes from the directions (mixed, anisotropic)
    blocks: tuple[BlockScale, ...] = ()  # per named block of the state (pose: position, ...)

    @property
    def partial(self) -> bool:
        """Whether one of the two questions was answered and the other was not."""
        return bool(self.untested) and self.label is not Label.INSUFFICIENT

    def __repr__(self) -> str:
        kappa = "" if self.scale is None else f", scale_factor={self.scale.scale_factor:.4g}"
        return f"Diagnosis(label={self.label.value!r}, n={self.n}, dim={self.dim}{kappa})"

    @property
    def cov_scale(self) -> float | None:
        """Factor k such that kΣ̂ gives ANEES = 1 on this segment (mean NEES / d)."""
        return self.anees

    @property
    def elt_statistic(self) -> float | None:
        return None if self.elt is None else self.elt.statistic

    @property
    def elt_pvalue(self) -> float | None:
        return None if self.elt is None else self.elt.pvalue


def nees_baseline(eps: np.ndarray, dim: int, alpha: float = 0.05) -> Label:
    """NEES classifier: two-sided χ² test of ΣNEES with N·d degrees of freedom.

    Above the upper 1−α/2 quantile: optimism; below the lower α/2 quantile: pessimism.
    """
    dof = eps.size * dim
    total = float(np.sum(eps))
    if total > special.chdtri(dof, alpha / 2):
        return Label.OPTIMISM
    if total < special.chdtri(dof, 1 - alpha / 2):
        return Label.PESSIMISM
    return Label.CREDIBLE


def nci_baseline(nci_value: float, tau: float = 0.5) -> Label:
    """NCI classifier: optimism above +τ, pessimism below −τ, credible inside."""
    if nci_value > tau:
        return Label.OPTIMISM
    if nci_value < -tau:
        return Label.PESSIMISM
    return Label.CREDIBLE


def ks_chi2_pvalue(eps: np.ndarray, dim: int) -> float:
    """Two-sided Kolmogorov–Smirnov p-value of NEES values against χ²_d.

    p = min(1, 2·S_n(D)), with S_n the exact one-sided Smirnov tail. Against
    ``scipy.stats.kstest(method="exact")`` over 3000 samples (n = 20–300) the largest
    difference was 1.5e-8 where p < 0.02, 7e-7 where p < 0.05 and 2e-4 where p < 0.2, so the
    decision at the 1% level is the exact test's; it avoids importing scipy.stats.
    """
    x = np.sort(eps)
    n = x.size
    cdf = special.chdtr(dim, x)
    i = np.arange(1, n + 1)
    d_stat = max(float(np.max(i / n - cdf)), float(np.max(cdf - (i - 1) / n)))
    return float(min(1.0, 2.0 * special.smirnov(n, d_stat)))


def segment_seed(seed: int | None, name: str) -> np.random.SeedSequence:
    """Per-segment random stream: a function of the seed and the segment's name only."""
    return np.random.SeedSequence(entropy=seed, spawn_key=(zlib.crc32(name.encode()),))


def diagnose_errors(
    errors: np.ndarray,
    cov: np.ndarray,
    config: DiagnosisConfig | None = None,
    rng: RngLike = None,
    mse: np.ndarray | None = None,
    runs: int = 1,
) -> Diagnosis:
    """One segment of errors e_k = x_k − x̂_k (N, d) with claimed covariances (N, d, d),
    by ``config``'s rule (the calibrated variant by default). ``runs``: the segment pools
    that many independent Monte Carlo runs of N/runs epochs, one after the other; the ELT
    flips each run's errors in their own blocks.

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> e = rng.normal(size=(200, 2))
    >>> diagnose_errors(e, np.broadcast_to(np.eye(2), (200, 2, 2)), rng=1).label.value
    'credible'
    """
    config = config or DiagnosisConfig()
    errors, cov = metrics.check_errors_cov(errors, cov)
    return _diagnose_variants(errors, cov, [config], as_generator(rng), mse, runs)[0]


def _cholesky(cov: np.ndarray) -> np.ndarray:
    """The covariances' Cholesky factors, or the error naming the first that is not
    positive definite (:func:`credcli.engine.metrics.cholesky`)."""
    return metrics.cholesky(cov)


def diagnose_variants(
    errors: np.ndarray,
    cov: np.ndarray,
    variants: list[Variant],
    config: DiagnosisConfig | None = None,
    rng: RngLike = None,
) -> dict[Variant, Diagnosis]:
    """Diagnose one segment with several variants, computing shared evidence once.

    The variants' configurations are ``config`` with only the variant changed. ELTs with
    the same block length and pair set are run once, in the order the variants are listed,
    so a variant listed first draws its sign flips exactly as :func:`diagnose_errors` does.
    """
    errors, cov = metrics.check_errors_cov(errors, cov)
    configs = _variant_configs(config or DiagnosisConfig(), tuple(Variant(v) for v in variants))
    results = _diagnose_variants(errors, cov, configs, as_generator(rng), None)
    return {c.variant: r for c, r in zip(configs, results)}


@functools.lru_cache(maxsize=16)
def _variant_configs(config: DiagnosisConfig, variants: tuple[Variant, ...]):
    """``config`` with each variant (made and validated once, not per trial of a study;
    a tuple, since every caller shares it)."""
    return tuple(replace(config, variant=v) for v in variants)


def _diagnose_variants(errors, cov, configs, gen, mse, runs=1) -> list[Diagnosis]:
    """Evidence once (metrics, dependence, scale tests, ELTs by block length), then each
    configuration's rule. The Cholesky factors are made here, so that nothing else holds
    them once they are freed."""
    n, d = errors.shape
    chol = _cholesky(cov)
    if n < min(c.min_n(d) for c in configs):
        return [_too_short(n, d, c) for c in configs]
    # Whole-length intermediates are freed as soon as they are used (a 2,000,000-epoch
    # segment peaks ~250 MiB lower); the probes need ``centred`` and ``chol`` to the end.
    probes_possible = any(not c.calibrated or c.metrics is MetricsLevel.ALL for c in configs)
    with np.errstate(over="ignore", invalid="ignore"):
        eps = metrics.nees_factored(errors, chol)
    if not np.all(np.isfinite(eps)):
        raise CredcliError(_overflow_message(errors, chol, eps))
    mse = metrics.mse_matrix(errors) if mse is None else np.asarray(mse, dtype=float)
    nci_raw = metrics.nci_factored(errors, chol, _mse_cholesky(mse), eps)
    ks_p = ks_chi2_pvalue(eps, d)
    nees_labels = {c.nees_alpha: nees_baseline(eps, d, c.nees_alpha) for c in configs}
    anees = float(np.mean(eps) / d)
    del eps
    centred = errors - errors.mean(axis=0)
    nci_centred = metrics.nci_factored(centred, chol, _mse_cholesky(metrics.mse_matrix(centred)))
    gls = gls_residuals(errors, chol)
    if not probes_possible:
        del centred, chol
    s = whiten(errors, cov)
    r1 = dependence.autocorrelation(s)
    dep = _serial_dependence(s, gls.q, r1)
    dependent, tau_point, tau, tau_q = dep.dependent, dep.tau_point, dep.tau, dep.tau_q
    located, tau_location = _location_dependence(s, r1, dep)
    autocorr = float(np.max(r1))
    effective_n = float(n / max(1.0, float(np.max(tau_point))))
    # every scale and mean test now, so the GLS residuals can be freed
    scales: dict = {}
    means: dict = {}
    directional: dict = {}
    for config in configs:
        batched = _batched(config, dependent)
        key = _scale_key(config, batched)
        if key not in scales:
            scales[key] = _scale_evidence(gls, config, tau, tau_q, batched, runs=runs)
            if config.calibrated and d > 1 and scales[key][1] is None:
                k = scales[key][0].batches
                directional[key] = direction_scales(gls, config.scale_level, k)
        mean_key = (_batched(config, located), config.fixed_block_length)
        if config.calibrated and mean_key not in means:
            means[mean_key] = _mean_evidence(gls, config, tau_location, mean_key[0], runs)
    del gls
    elts: dict = {}
    plans = [
        _location_plan(config, n, tau_location, means, located, runs)
        if config.calibrated
        else _location_plan(config, n, tau, means, dependent, runs)  # paper, ks: unchanged
        for config in configs
    ]
    # an ELT shared by several variants stops only when none of them can still reject
    exact = any(c.exact_pvalue for c in configs)
    used = [plan.elt_level for plan in plans if plan.elt_level is not None]
    stop_level = None if exact or not used else max(used)
    scorer = None
    out = []
    for config, plan in zip(configs, plans):
        if n < config.min_n(d):
            out.append(_too_short(n, d, config))
            continue
        scale, scale_reason = scales[_scale_key(config, _batched(config, dependent))]
        directions = None
        if config.calibrated and scale_reason is None:
            scale_reason = _inconclusive_scale(scale, config)
            directions = directional.get(_scale_key(config, _batched(config, dependent)))
        block = plan.block
        common = {
            "n": n,
            "dim": d,
            "nci": nci_raw,
            "nci_centered": nci_centred,
            "anees": anees,
            "ks_pvalue": ks_p,
            "nees_label": nees_labels[config.nees_alpha],
            "nci_label": nci_baseline(nci_raw, config.tau_nci),
            "scale": scale,
            "block_length": block,
            "effective_n": effective_n,
            "autocorrelation": autocorr,
            "config": config,
            "mean_test": plan.mean_test,
        }
        noise_override = None
        if directions is not None and _mixed(directions, config):
            noise_override = _direction_noise(directions, config)
            if noise_override is not None:
                scale_reason = None  # decided along a principal direction
        common["directions"] = directions
        common["by_direction"] = noise_override is not None
        untested = tuple(
            q
            for q, missing in (
                (Question.SCALE, scale_reason is not None),
                (Question.LOCATION, plan.mean_test is None and plan.elt_level is None),
            )
            if missing
        )
        reason = "; ".join(r for r in (scale_reason, plan.reason) if r) or None
        if len(untested) == 2 or (not config.calibrated and plan.elt_level is None):
            out.append(Diagnosis(label=Label.INSUFFICIENT, reason=reason, **common))
            continue
        elt = None
        if plan.elt_level is not None:
            separate = config.calibrated and block > 1
            elt_key = (block, separate, config.n_flips, config.max_elt_epochs)
            if elt_key not in elts:
                elts[elt_key] = whitened_location_test(
                    s,
                    config.n_flips,
                    gen,
                    block,
                    config.max_elt_epochs,
                    separate_blocks=separate,
                    stop_level=stop_level,
                    runs=runs,
                )
            elt = elts[elt_key]
        smm = bool(
            (elt is not None and elt.pvalue < plan.elt_level)
            or (plan.mean_test is not None and plan.mean_test.pvalue < plan.mean_level)
        )
        everything = config.metrics is MetricsLevel.ALL
        needs_probes = not config.calibrated and smm and nci_centred > config.tau_nci
        if (needs_probes or everything) and scorer is None:
            scorer = metrics.EnergyScorer(cov)
        absolute = config.srd_form is SrdForm.ABSOLUTE
        probes = (
            metrics.probes_scored(centred, scorer, chol, config.c, absolute)
            if needs_probes or everything
            else None
        )
        scores = (
            metrics.probes_scored(errors, scorer, chol, config.c, absolute) if everything else None
        )
        if config.calibrated and noise_override is not None:
            label = Label.compose(noise_override, smm)
        elif config.calibrated:
            label = _calibrated_label(None if scale_reason else scale, smm, config)
        elif smm:
            label = _label_with_smm(nci_centred, probes, config.tau_nci)
        else:
            label = _label_without_smm(nci_raw, ks_p, config)
        out.append(
            Diagnosis(
                label=label,
                elt=elt,
                smm_detected=None if Question.LOCATION in untested else smm,
                scores=scores,
                probes=probes,
                untested=untested,
                reason=reason,
                **common,
            )
        )
    return out


def _overflow_message(errors: np.ndarray, chol: np.ndarray, eps: np.ndarray) -> str:
    """Why a NEES is not finite: an error so many claimed standard deviations away that its
    square overflows float64 (the whitened error itself is finite, or it is reported so)."""
    k = int(np.flatnonzero(~np.isfinite(eps))[0])
    factor = chol if chol.ndim == 2 else chol[k]
    with np.errstate(over="ignore", invalid="ignore"):
        size = float(np.max(np.abs(np.linalg.solve(factor, errors[k]))))
    return (
        f"epoch {k + 1} of the segment: the error is {size:.3g} claimed standard deviations, "
        "whose square overflows double precision; are the covariance and the errors in the "
        "same units (variance, not standard deviation; m, not mm), or did the estimate diverge?"
    )


def _too_short(n: int, d: int, config: DiagnosisConfig) -> Diagnosis:
    smallest = config.min_n(d)
    needs = f"min_epochs {config.min_epochs} and d + 2"
    if not config.calibrated:
        needs = f"min_epochs {config.min_epochs}, d + 2, and {config.min_blocks} sign blocks"
    return Diagnosis(
        label=Label.INSUFFICIENT,
        n=n,
        dim=d,
        reason=f"{n} epochs; at least {smallest} are needed ({needs})",
        config=config,
    )


class _Dependence(NamedTuple):
    """What the segment's serial dependence implies for its tests (:func:`_serial_dependence`)."""

    dependent: bool  # the scale (and, for paper/ks, the ELT) refer to dependent epochs
    tau_point: np.ndarray  # the kernel τ̂ per component (the reported effective N); 1s if not
    tau: np.ndarray  # τ per component for lengths, the neighbour correction, the centring
    tau_q: float  # τ of the squared errors q, for the scale's batches
    weak_tau: np.ndarray | None  # τ of weak evidence where no batches fit (the location's)


def _serial_dependence(s: np.ndarray, q: np.ndarray, r1: np.ndarray | None = None) -> _Dependence:
    """Whether the whitened errors ``s`` are serially dependent
    (:func:`credcli.engine.dependence.serially_dependent`): at ``DEPENDENCE_LEVEL``
    (1 %), or at ``SCREENING_LEVEL`` (20 %) where the batch-means tests fit in the
    segment. The tests for independent epochs lose their level on weak dependence that a
    1 % test misses (9 % wrong labels on 50-epoch AR(1) windows with φ = 0.3), while batch
    means on independent epochs lose only some power. Where no batches fit, weak evidence
    keeps the independent-epoch tests rather than leaving the segment untested; its τ is
    ``weak_tau``, which the calibrated rule's location question uses
    (:func:`_location_dependence`). If dependent, the kernel τ̂ of each component and, for
    the lengths of batches and sign blocks, the neighbour correction and the centring of
    κ̄, the larger of τ̂ and the bias-corrected AR(1) τ; for the squared errors q also at
    least the τ that the errors' own τ implies for a Gaussian AR(1). On independent epochs
    all are 1."""
    r1 = dependence.autocorrelation(s) if r1 is None else r1
    n, d = s.shape
    ones = np.ones(d)
    if not dependence.serially_dependent(r1, n, dependence.SCREENING_LEVEL):
        return _Dependence(False, ones, ones, 1.0, None)
    tau_point = dependence.variance_ratio(s)
    tau = np.maximum(tau_point, dependence.ar1_variance_ratio(r1, n))
    tau_q = max(
        float(dependence.variance_ratio(q)[0]),
        float(dependence.ar1_variance_ratio(dependence.autocorrelation(q), n)[0]),
        dependence.squared_variance_ratio(tau),
    )
    if not dependence.serially_dependent(r1, n) and not _batches_fit(n, d, tau, tau_q):
        return _Dependence(False, ones, ones, 1.0, tau)  # weak, and no batches fit
    return _Dependence(True, tau_point, tau, tau_q, None)


def _location_dependence(s: np.ndarray, r1: np.ndarray, dep: _Dependence):
    """(dependent, τ per component) for the calibrated rule's location question.

    Under the location's null hypothesis the errors have mean zero, so their dependence is
    screened once more by the lag-1 autocorrelation about zero
    (:func:`credcli.engine.dependence.autocorrelation`), at ``SCREENING_LEVEL``.
    The centred one misses exactly the windows that matter: a slow excursion of weakly
    dependent errors shifts their sample mean and, once that is removed, leaves little
    lag-1 correlation, so such windows passed the screening and went to the tests for
    independent epochs, which found a "bias" in them (AR(1) φ = 0.3, correct covariance:
    19 % smm among the unflagged 50-epoch windows). A window flagged either way goes to
    batch means where they fit; where they do not, the tests for independent epochs run
    with its τ: the ELT in blocks, the mean test's T² divided by max_i τ_i. The lengths
    come from the centred estimate (the bias-corrected AR(1) τ): a real bias inflates the
    uncentred autocorrelation, and lengths from it left the paper's smm scenarios untested
    (Table II's smm column 96 -> 88 % on one seed). Wrong labels on correct covariances,
    AR(1) φ = 0.3: 11.8 % -> 5.3 % at N = 25, 7.7 % -> 6.4 % at N = 50 (1,000 windows)."""
    if dep.dependent:
        return True, dep.tau
    n, d = s.shape
    about_zero = dependence.serially_dependent(
        dependence.autocorrelation(s, about_zero=True), n, dependence.SCREENING_LEVEL
    )
    if dep.weak_tau is None and not about_zero:
        return False, dep.tau
    tau = (
        dep.weak_tau
        if dep.weak_tau is not None
        else np.maximum(dep.tau, dependence.ar1_variance_ratio(r1, n))
    )
    length = batches.batch_length(float(np.max(tau)))
    fits = batches.batch_count(n, length, batches.min_location_batches(d))
    return bool(fits), tau


def _batches_fit(n: int, d: int, tau: np.ndarray, tau_q: float) -> bool:
    """Whether the batch-means scale test and mean test both fit in ``n`` epochs."""
    scale = batches.batch_count(n, batches.batch_length(tau_q), batches.MIN_SCALE_BATCHES)
    worst = float(np.max(tau))
    mean = batches.batch_count(n, batches.batch_length(worst), batches.min_location_batches(d))
    return bool(scale) and bool(mean)


def _batched(config: DiagnosisConfig, dependent: bool) -> bool:
    """Whether the calibrated rule refers this segment's tests to batch means: serially
    dependent epochs (estimated, or declared by a fixed block length above 1; a fixed 1
    declares them independent)."""
    fixed = config.fixed_block_length
    return config.calibrated and (fixed > 1 if fixed is not None else dependent)


def _scale_key(config: DiagnosisConfig, batched: bool) -> tuple:
    """Configurations with equal keys share one scale test."""
    return (config.block_length == 1, config.scale_level, batched and config.fixed_block_length)


def _batch_length(config: DiagnosisConfig, tau: float) -> int:
    """Batches are at least the fixed sign-block length, else estimated from ``tau``."""
    return config.fixed_block_length or batches.batch_length(tau)


def _scale_evidence(
    gls, config: DiagnosisConfig, tau, tau_q: float, batched: bool, level=None, runs: int = 1
):
    """(scale test or None, why it is untested): batch means on dependent epochs, else the
    χ² (Satterthwaite-scaled) test of :func:`credcli.engine.scale.scale_test`; at
    ``level`` (default: the configuration's α_S). ``runs``: see :func:`_batches`."""
    level = config.scale_level if level is None else level
    if not batched:
        fixed = config.block_length == 1
        return scale_test(gls, level, None if fixed else tau), None
    n = gls.whitened.shape[0]
    length = _batch_length(config, tau_q)
    k, aligned = _batches(n, length, batches.MIN_SCALE_BATCHES, runs)
    if aligned:
        return batch_scale_test(gls, level, k, taus=tau, independent=True), None
    if not k:  # κ̂ and the bias are still reported; the interval and p-values are NaN
        return untested_scale(gls), (
            f"scale untested: the squared errors' serial dependence (variance ratio "
            f"{tau_q:.3g}) needs batches of {length} epochs, and fewer than the "
            f"{batches.MIN_SCALE_BATCHES} the scale test needs fit in {n}"
        )
    return batch_scale_test(gls, level, k, tau_q, tau), None


def _mean_evidence(gls, config: DiagnosisConfig, tau, batched: bool, runs: int = 1):
    """(the GLS mean test or None, why it is untested): Hotelling on batch score sums on
    dependent epochs, else Hotelling's test of independent epochs. ``runs``: see
    :func:`_batches`."""
    n, d = gls.whitened.shape
    if not batched:
        return batches.independent_mean_test(gls, float(np.max(tau))), None
    worst = float(np.max(tau))
    smallest = batches.min_location_batches(d)
    length = _batch_length(config, worst)
    k, aligned = _batches(n, length, smallest, runs)
    if not k:
        return None, (
            f"serial dependence (variance ratio {worst:.3g}) needs batches of {length} epochs "
            f"for the mean test, and fewer than the {smallest} it needs fit in {n}"
        )
    sums = np.add.reduceat(gls.scores, batches.bounds(n, k), axis=0)
    inflation = 1.0 if aligned else batches.boundary_inflation(worst, n, k)
    return batches.batch_mean_test(sums, inflation), None


def _batches(n: int, length: int, smallest: int, runs: int) -> tuple[int, bool]:
    """(K, whether the batches are the runs). A segment that pools ``runs`` independent
    Monte Carlo runs of equal length has batches that are independent by construction:
    the runs themselves. They are used when there are at least as many runs as batches of
    ``length`` epochs would fit (and at least ``smallest``); then no estimate of the
    correlation time decides the reference, and no correction for neighbouring batches is
    needed. Otherwise K batches of at least ``length`` epochs, or 0 when fewer than
    ``smallest`` fit (:func:`credcli.engine.batches.batch_count`)."""
    k = batches.batch_count(n, length, smallest)
    if runs > 1 and n % runs == 0 and runs >= max(k, smallest):
        return runs, True
    return k, False


@dataclass(frozen=True)
class _LocationPlan:
    """How one configuration answers the location question on this segment: the mean test
    at ``mean_level`` and/or the ELT at ``elt_level`` (None: not run), and why not."""

    block: int
    mean_test: batches.MeanTest | None
    mean_level: float
    elt_level: float | None
    reason: str | None


def _location_plan(config: DiagnosisConfig, n, tau, means, dependent, runs) -> _LocationPlan:
    """The calibrated rule runs the GLS mean test at α_L·MEAN_SHARE and the ELT at the
    rest; a test that cannot run leaves the whole α_L to the other. ``paper`` and ``ks``
    run the ELT alone."""
    block = config.fixed_block_length or dependence.block_length(tau)
    n_blocks = tested_blocks(n, block, config.max_elt_epochs, runs)
    elt_ok = n_blocks >= config.min_blocks
    why_not_elt = None
    if not elt_ok:
        budget = tested_blocks(n, block, n, runs) >= config.min_blocks
        cause = (
            f"its budget of {config.max_elt_epochs} epochs (max_elt_epochs)"
            if budget
            else f"serial dependence (variance ratio {float(np.max(tau)):.3g}) needs sign "
            f"blocks of {block} epochs, which"
        )
        why_not_elt = (
            f"ELT not run: {cause} leaves {n_blocks} of the {config.min_blocks} sign blocks "
            "it needs"
        )
    if not config.calibrated:
        return _LocationPlan(
            block, None, 0.0, config.location_level if elt_ok else None, why_not_elt
        )
    mean_test, why_not_mean = means[(_batched(config, dependent), config.fixed_block_length)]
    if mean_test is not None and elt_ok:
        return _LocationPlan(block, mean_test, config.mean_level, config.elt_level, None)
    if mean_test is not None:  # the mean test takes the whole location level
        return _LocationPlan(block, mean_test, config.location_level, None, why_not_elt)
    if elt_ok:
        reason = f"mean test not run: {why_not_mean}"
        return _LocationPlan(block, None, 0.0, config.location_level, reason)
    reason = f"location untested: {why_not_elt}; the mean test: {why_not_mean}"
    return _LocationPlan(block, None, 0.0, None, reason)


CREDIBLE_FACTOR = 2.0
"""The calibrated rule calls a scale credible only when its 1 − α_S interval lies within
[1/2, 2] (3 dB): then a misfit by a factor 2 or more is excluded at level α_S/2 on either
side (two one-sided tests). A wider interval that contains 1 is inconclusive, and the scale
question untested, not credible: never a guess behind a label. On the paper's protocol
(N = 100, d = 2, independent) the interval is about [0.8, 1.27]: every segment is decided."""


def _inconclusive_scale(scale: ScaleTest, config: DiagnosisConfig) -> str | None:
    """Why a scale test that finds no misfit still does not support "credible", or None."""
    if _noise(scale, config) is not None:
        return None
    low, high = scale.scale_factor_low, scale.scale_factor_high
    if low >= 1.0 / CREDIBLE_FACTOR and high <= CREDIBLE_FACTOR:
        return None
    return (
        f"scale inconclusive: κ̂ {scale.scale_factor:.3g} with interval [{low:.3g}, {high:.3g}] "
        f"finds no misfit but does not exclude one of a factor {CREDIBLE_FACTOR:g} "
        "(too few independent batches for a tighter interval)"
    )


def _mixed(directions: DirectionScales, config: DiagnosisConfig) -> bool:
    """Whether the directions disagree in sign: one too large and another too small, each
    beyond its interval and the relevance floor. One factor for the whole covariance is then
    the wrong advice, and the label follows the directions (optimism)."""
    db = 10.0 * np.log10(np.maximum(directions.factors, np.finfo(float).tiny))
    too_small = np.any((directions.low > 1.0) & (db > config.tau_nci))
    too_large = np.any((directions.high < 1.0) & (db < -config.tau_nci))
    return bool(too_small and too_large)


def _direction_noise(directions: DirectionScales, config: DiagnosisConfig) -> str | None:
    """The noise label from the principal directions, where the overall scale test was
    inconclusive: "optimism" when some direction's factor is above 1 (interval and relevance
    floor τ), whatever the others do, since a covariance too small in one direction makes
    the estimator overconfident there (mixed directions are optimism; the advice gives the
    matrix correction); else "pessimism" when some direction's is below 1; else None."""
    db = 10.0 * np.log10(np.maximum(directions.factors, np.finfo(float).tiny))
    if np.any((directions.low > 1.0) & (db > config.tau_nci)):
        return "optimism"
    if np.any((directions.high < 1.0) & (db < -config.tau_nci)):
        return "pessimism"
    return None


def _noise(scale: ScaleTest, config: DiagnosisConfig) -> str | None:
    """ "optimism", "pessimism" or None: the scale test at α_S with the relevance floor τ."""
    half = config.scale_level / 2
    db = 10.0 * math.log10(scale.scale_factor) if scale.scale_factor > 0 else -math.inf
    if scale.pvalue_upper < half and db > config.tau_nci:
        return "optimism"
    if scale.pvalue_lower < half and db < -config.tau_nci:
        return "pessimism"
    return None


def _calibrated_label(scale: ScaleTest | None, smm: bool, config: DiagnosisConfig) -> Label:
    """Scale part (two-sided at α_S, with the relevance floor τ) plus SMM; without a scale
    test, the location half alone (smm, or credible as far as the location goes)."""
    if scale is None:
        return Label.compose(None, smm)
    return Label.compose(_noise(scale, config), smm)


def _mse_cholesky(mse: np.ndarray) -> np.ndarray:
    try:
        return np.linalg.cholesky(mse)
    except np.linalg.LinAlgError as exc:
        raise CredcliError(
            "the errors span fewer than d dimensions (for example a component whose error is "
            "the same in every epoch), so the MSE matrix of the NCI, Eq. (4), is singular; "
            "drop that component or give the MSE matrix"
        ) from exc


def _label_without_smm(nci_value: float, ks_p: float, config: DiagnosisConfig) -> Label:
    """Lines 2–8 of Algorithm 1, with the KS check of the authors' code for Variant.KS."""
    if config.variant is Variant.KS and (
        ks_p >= config.ks_alpha or abs(nci_value) <= config.tau_nci
    ):
        return Label.CREDIBLE
    return nci_baseline(nci_value, config.tau_nci)


def _label_with_smm(nci_centred: float, probes: metrics.Probes | None, tau: float) -> Label:
    """Lines 10–23 of Algorithm 1 on the bias-corrected estimate x̃_k."""
    if nci_centred < -tau:
        return Label.PESSIMISM_SMM
    if nci_centred > tau:
        assert probes is not None
        if probes.all_positive:
            return Label.SMM
        if _greater(probes.srd_nll, probes.srd_es):
            return Label.OPTIMISM_SMM
    return Label.SMM


def _greater(a: float, b: float) -> bool:
    return not math.isnan(a) and not math.isnan(b) and a > b


@dataclass(frozen=True)
class SegmentDiagnosis:
    """A Diagnosis tied to its segment of a log."""

    log: str
    segment: str
    t_start: float | None
    t_end: float | None
    diagnosis: Diagnosis
    whiteness: Whiteness | None = None  # of innovations (--innovations)


def diagnose_log(
    log,
    segments,
    config: DiagnosisConfig | None = None,
    seed: int | None = 0,
    progress=None,
) -> list[SegmentDiagnosis]:
    """Run Algorithm 1 on every segment of an EstimatorLog.

    Each segment's sign flips come from :func:`segment_seed` (the seed and the segment's
    name), so a segment's result does not depend on the other segments.
    ``progress``, if given, is called as ``progress(done, total)`` after each segment.
    """
    config = config or DiagnosisConfig()
    errors = log.errors
    out = []
    for done, seg in enumerate(segments, start=1):
        diag = diagnose_segment(
            errors[seg.index],
            log.cov[seg.index],
            config,
            seed,
            seg.name,
            log.source,
            blocks=getattr(log, "blocks", ()),
        )
        out.append(SegmentDiagnosis(log.source, seg.name, seg.t_start, seg.t_end, diag))
        if progress is not None:
            progress(done, len(segments))
    return out


def innovation_whiteness(errors: np.ndarray, cov: np.ndarray) -> Whiteness | None:
    """The portmanteau test of innovations whitened by their claimed covariance, or None
    for a segment too short for one lag."""
    if errors.shape[0] < 5 + errors.shape[1]:
        return None
    return portmanteau(whiten(errors, cov))


def diagnose_segment(
    errors: np.ndarray,
    cov: np.ndarray,
    config: DiagnosisConfig,
    seed: int | None,
    name: str,
    source: str = "<memory>",
    runs: int = 1,
    blocks: tuple = (),
) -> Diagnosis:
    """One named segment of a log, its sign flips from :func:`segment_seed`; an error names
    the log and the segment. ``runs``: see :func:`diagnose_errors`; ``blocks``: named
    blocks of the state (:data:`credcli.engine.lie.STATE_BLOCKS`) whose scale factors the
    calibrated rule reports beside the overall one (:func:`block_scales`)."""
    try:
        errors, cov = metrics.check_errors_cov(errors, cov)
        n, d = errors.shape
        if n < config.min_n(d):  # checked as diagnose_errors checks, without a random stream
            _cholesky(cov)
            return _too_short(n, d, config)
        diag = diagnose_errors(errors, cov, config, segment_seed(seed, name), runs=runs)
        if blocks and config.calibrated:
            diag = replace(diag, blocks=block_scales(errors, cov, blocks, config, runs))
        return diag
    except CredcliError as exc:
        raise CredcliError(f"{source}: segment '{name}': {exc.message}") from exc


def block_scales(
    errors: np.ndarray, cov: np.ndarray, blocks: tuple, config: DiagnosisConfig, runs: int = 1
) -> tuple[BlockScale, ...]:
    """The scale factor of each named block of the state, as the calibrated rule finds the
    overall one (batch means when the block's errors are serially dependent, the χ² test
    otherwise; pooled Monte Carlo ``runs`` as the batches, as for the overall one), each
    interval at α_S divided by the number of blocks.

    The marginal of a Gaussian error is Gaussian with the marginal block of the covariance,
    so each block is a credibility question of its own (paper, Section II, for any d): a
    pose filter can be right about its position and optimistic about its attitude, which
    one factor for the 6×6 covariance averages away.

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> e = rng.normal(size=(2000, 4)) * [1, 1, 2, 2]  # the second block's Σ̂ 4× too small
    >>> cov = np.broadcast_to(np.eye(4), (2000, 4, 4))
    >>> b = block_scales(e, cov, (("a", (0, 1)), ("b", (2, 3))), DiagnosisConfig())
    >>> [(x.name, bool(x.low < k < x.high)) for x, k in zip(b, (1.0, 4.0))]
    [('a', True), ('b', True)]
    """
    level = config.scale_level / len(blocks)
    out = []
    for name, indices in blocks:
        idx = np.asarray(indices)
        e = errors[:, idx]
        c = cov[:, idx[:, None], idx[None, :]]
        gls = gls_residuals(e, _cholesky(c))
        s = whiten(e, c)
        dep = _serial_dependence(s, gls.q)
        batched = _batched(config, dep.dependent)
        test, _ = _scale_evidence(gls, config, dep.tau, dep.tau_q, batched, level, runs)
        out.append(
            BlockScale(
                name,
                tuple(int(i) for i in indices),
                float(test.scale_factor),
                float(test.scale_factor_low),
                float(test.scale_factor_high),
            )
        )
    return tuple(out)
