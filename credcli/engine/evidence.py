"""Evidence: every statistic a rule may use, gathered once per segment.

:func:`gather` computes, for each configuration of a segment, the typed :class:`Evidence`
(NEES/NCI baselines, the scale test, the location plan with the GLS mean test and the ELT,
the principal directions, the probes) that :func:`credcli.engine.rules.decide` turns into
a verdict. Evidence shared between configurations (scale tests, mean tests, ELTs with the
same blocks) is computed once; an ELT shared by several variants stops only when none of
them can still reject.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
from scipy import special

from credcli.engine import batches, correlation, dependence, episodes, linalg, metrics
from credcli.engine.config import SMM_CONDITION, DiagnosisConfig, MetricsLevel, SrdForm
from credcli.engine.elt import ELTResult, tested_blocks, whiten, whitened_location_test
from credcli.engine.episodes import Burst, Divergence
from credcli.engine.longmemory import SUPPORT, white_alternative, with_long_memory
from credcli.engine.memory import (
    Memory,
    NoFiniteMemory,
    TimeScales,
    fit_memory,
    mean_free,
    principal_directions,
    time_scales,
)
from credcli.engine.scale import (
    DirectionScales,
    ScaleTest,
    batch_scale_test,
    direction_scales,
    directions_under_either,
    gls_residuals,
    memory_scale_test,
    memory_tail_factor,
    scale_test,
    under_either,
    untested_scale,
)
from credcli.engine.units import power_of_two_unit
from credcli.errors import CredcliError


@dataclass(frozen=True)
class Evidence:
    """The statistics of one segment under one configuration (see :func:`gather`).

    The location question is answered by ``mean_test`` at ``mean_level`` and/or the ELT at
    ``elt_level`` (None: not run); ``location_reason`` says why one is missing.

    Attributes
    ----------
    n, dim : int
        Epochs N and state dimension d of the segment.
    nci : float
        The NCI, Eq. (4), of the errors (with the given MSE matrix, or the segment's).
    nci_centered : float
        The NCI of the errors less their mean, with their own MSE matrix (Section III-C).
    anees : float
        Mean NEES over d.
    ks_pvalue : float
        Two-sided Kolmogorov–Smirnov p-value of the NEES values against χ²_d
        (:func:`ks_chi2_pvalue`).
    nees_total : float
        Σ_k ε_k, the sum of the NEES values, Eq. (1).
    scale : ScaleTest
        The scale test (untested ones carry κ̂ and NaN intervals).
    scale_reason : str or None
        Why the scale test cannot answer (None: it can).
    directions : DirectionScales or None
        The per-direction scale factors (calibrated, d > 1, where the overall test ran).
    block_length : int
        Epochs per ELT sign block.
    effective_n : float
        N over the largest variance ratio τ of the whitened errors.
    autocorrelation : float
        The largest lag-1 autocorrelation of the whitened error components.
    mean_test : MeanTest or None
        The GLS mean test (calibrated rule), None when it did not run.
    mean_level : float
        The mean test's level (0.0 when it did not run; the level it ran at where its
        bias was declined).
    elt : ELTResult or None
        The empirical location test, None when it did not run.
    elt_level : float or None
        The ELT's level (None: not run).
    location_reason : str or None
        Why a location test is missing (None: both ran, or the rule needs only one).
    probes : Probes or None, default None
        Scores of the centred predictive with the SRDs, Eqs. (18)-(19): where the paper's
        rule needs them, or every metric is asked for.
    scores : Probes or None, default None
        Scores of the claimed predictive (every metric asked for).
    memory : Memory or None, default None
        The dependence model, for a configuration whose tests read it.
    memory_source : str or None, default None
        Where the model was fitted: ``"segment"`` or ``"run"``.
    time_scales : TimeScales or None, default None
        The variance at every averaging time, for a model fitted on this segment.
    q_median : float or None, default None
        The median GLS-centred NEES (the dependence-free bound's statistic).
    bursts : tuple of Burst, default ()
        Where the NEES leaves its band (Page's CUSUM).
    divergence : Divergence or None, default None
        Errors growing beyond any plausible tuning (calibrated rule).
    bias_declined : bool, default False
        A bias the mean test found under the fitted model and its alternative with more
        memory does not confirm (the location is then answered under the alternative, or
        untested).
    """

    n: int
    dim: int
    nci: float
    nci_centered: float
    anees: float
    ks_pvalue: float
    nees_total: float
    scale: ScaleTest
    scale_reason: str | None
    directions: DirectionScales | None
    block_length: int
    effective_n: float
    autocorrelation: float
    mean_test: batches.MeanTest | None
    mean_level: float
    elt: ELTResult | None
    elt_level: float | None
    location_reason: str | None
    probes: metrics.Probes | None = None
    scores: metrics.Probes | None = None
    memory: Memory | None = None
    memory_source: str | None = None
    time_scales: TimeScales | None = None
    q_median: float | None = None
    bursts: tuple[Burst, ...] = ()
    divergence: Divergence | None = None
    bias_declined: bool = False

    @property
    def mean_rejected(self) -> bool:
        """Whether the GLS mean test rejects at its level: a bias."""
        return bool(self.mean_test is not None and self.mean_test.pvalue < self.mean_level)

    @property
    def elt_rejected(self) -> bool:
        """Whether the ELT rejects central symmetry at its level."""
        return bool(self.elt is not None and self.elt.pvalue < self.elt_level)

    @property
    def location_rejected(self) -> bool:
        """Whether the ELT or the GLS mean test rejects at its level (the paper's SMM)."""
        return self.elt_rejected or self.mean_rejected

    @property
    def location_condition(self) -> str | None:
        """What the location tests found (:data:`credcli.engine.config.LOCATION_CONDITIONS`):
        "bias" when the mean test rejects; "asymmetric" when only the ELT rejects and the
        mean test ran; "smm" when the ELT rejects and no mean test ran; None."""
        if self.mean_rejected:
            return "bias"
        if self.elt_rejected:
            return "asymmetric" if self.mean_test is not None else SMM_CONDITION
        return None


def gather(errors, cov, chol, configs, gen, mse, runs=1, memory=None) -> list[Evidence]:
    """The evidence of one segment for each configuration in ``configs``.

    The calibrated rule with estimated dependence (``block_length`` auto, one run) reads
    the segment's memory from a fitted AR sieve (:func:`credcli.engine.memory.fit_memory`),
    or from ``memory``, the model of the whole run the segment is a window of
    (:func:`memory_evidence`). ``paper``, ``ks``, fixed block lengths and pooled Monte Carlo
    ``runs`` keep the lag-1 screening and batch means (:mod:`credcli.engine.dependence`).
    Evidence shared between configurations (scale tests, mean tests, ELTs with the same
    blocks) is computed once.

    Whole-length intermediates are freed as soon as they are used, to keep the peak memory
    of long segments down; the probes need ``chol`` to the end, and make the centred errors
    again (:func:`_centred`) rather than hold them. Past one chunk of epochs
    (:data:`credcli.engine.linalg.EPOCH_CHUNK`) the inverse factors, the GLS scores and
    the NEES are made again, with the same bits, where they are read
    (:class:`Inverses`, :func:`credcli.engine.linalg.by_inverse_chunks`).

    Parameters
    ----------
    errors : numpy.ndarray, shape (N, d)
        The errors e_k = x_k − x̂_k (validated).
    cov : numpy.ndarray, shape (N, d, d)
        The claimed covariances.
    chol : numpy.ndarray, shape (N, d, d)
        Their Cholesky factors L_k.
    configs : list of DiagnosisConfig
        The configurations, all with N >= ``min_n(d)``.
    gen : numpy.random.Generator
        Source of the ELT's sign flips (drawn in the order of ``configs``).
    mse : numpy.ndarray, shape (d, d), or None
        The MSE matrix of the NCI, Eq. (4); None: estimated from the errors.
    runs : int, default 1
        Equal independent Monte Carlo runs pooled one after the other in the segment.
    memory : Memory, optional
        The dependence model of the run this segment is a window of; None: fitted on the
        segment where a configuration reads it.

    Returns
    -------
    list of Evidence
        One per configuration, in the order of ``configs``.

    Raises
    ------
    CredcliError
        When a NEES is not finite (an error whose square overflows), or a given ``mse``
        is singular.
    Undecidable
        When the MSE matrix estimated from the segment is singular (the errors span fewer
        than d dimensions).
    """
    n, d = errors.shape
    probes_possible = any(not c.calibrated or c.metrics is MetricsLevel.ALL for c in configs)
    # the one whitening F_k = Σ_k^{-1/2}: the NEES, the GLS residuals, the memory's and the
    # ELT's (frame-free: linalg.whitening_factors)
    inverse = linalg.whitening_factors(cov)
    with np.errstate(over="ignore", invalid="ignore"):
        eps = metrics.nees_inverse(errors, inverse)
    if not np.all(np.isfinite(eps)):
        raise CredcliError(_overflow_message(errors, chol, eps))
    if not probes_possible:  # the Cholesky factors' last use without the probes: the
        del chol  # whitening stands in for them (2·10⁶ epochs: 61 MiB fewer through the NCI)
    if mse is not None:  # the caller's MSE matrix
        star = metrics.nees_factored(errors, mse_cholesky(np.asarray(mse, dtype=float), True))
    else:
        star = _mse_nees(errors)
    nci_raw = metrics.nci_of(eps, star)
    del star
    ks_p = ks_chi2_pvalue(eps, d)
    nees_total = float(np.sum(eps))
    anees = float(np.mean(eps) / d)
    # past one chunk of epochs the NEES, the inverses and the GLS scores are made again
    # (the same bits) where they are read rather than held through the model's fit, checks
    # and tests (2·10⁶ epochs: peak 561 → 459 MiB resident, docs/performance.md)
    again = n > linalg.EPOCH_CHUNK
    if again:
        del eps
    centred = _centred(errors)
    centred_star = _mse_nees(centred)  # (its temporaries first)
    centred_eps = metrics.nees_inverse(centred, inverse)
    del centred
    nci_centred = metrics.nci_of(centred_eps, centred_star)
    del centred_eps, centred_star
    modelled = [c for c in configs if reads_memory(c, runs)]
    # a long segment's scores are made where its model's tests read them, from cov
    gls = gls_residuals(errors, None, inverse, cov if again else None)
    # the whitened errors s_k = F_k e_k (the ELT's, Eq. (12), and the lag-1 screening's):
    # the held factors' product, whiten's bits; past one chunk of epochs, where only the
    # memory model reads the dependence, whiten makes them after the model's tests, when
    # the model's residuals are freed (the peak memory)
    early = len(modelled) < len(configs) or n < SCREENED_BELOW
    s = None
    if not again:
        s = linalg.whitened_by(inverse, errors)
    elif early:
        s = whiten(errors, cov)
    r1 = correlation.autocorrelation(s) if s is not None else None
    if len(modelled) < len(configs):  # the lag-1 screening of paper, ks and fixed blocks
        dep = dependence.serial_dependence(s, gls.q, r1)
        located, tau_location = dependence.location_dependence(s, r1, dep)
    else:
        ones = np.ones(d)
        dep = dependence.SerialDependence(False, ones, ones, 1.0, None)
        located, tau_location = False, ones
    dependent, tau_point, tau, tau_q = dep.dependent, dep.tau_point, dep.tau, dep.tau_q
    source = "run" if memory is not None else "segment"
    scales_check = None
    drifting = None
    fitted_on = None  # the residuals of the segment's own model, for its time-scale check
    if modelled and memory is None:
        fitted_on = memory_residuals(gls, inverse)
        if again:  # the inverses are made again where the model's tests read them, not
            inverse = None  # held through its fit and checks (2·10⁶ epochs: 61 MiB)
        try:
            memory = segment_memory(gls, None, s, residuals=fitted_on)[0]
        except NoFiniteMemory:
            drifting = _drift_evidence(gls, n)
            source, fitted_on = None, None
    if fitted_on is not None:  # the model's check at every averaging time, and its refit
        scales_check = time_scales(fitted_on, memory)
        try:
            refit = white_refit(memory, fitted_on, gls.q, scales_check)
        except NoFiniteMemory:
            refit, memory, scales_check, source = None, None, None, None
            drifting = _drift_evidence(gls, n)
        if refit is not None:
            memory = refit
            scales_check = time_scales(fitted_on, memory)
    # the model's tests read the segment's own residuals where a white model's bias needs
    # them; a long segment's are made again there (rarely) rather than held
    residuals = None if again else fitted_on
    del fitted_on
    if inverse is None:
        inverse = Inverses(cov)  # made again only where a test reads them
    if drifting is not None:
        model_evidence = dict.fromkeys(modelled, drifting)
    else:
        model_evidence = {
            c: memory_evidence(gls, inverse, c, memory, n, residuals=residuals)
            for c in dict.fromkeys(modelled)
        }
    del residuals, inverse
    if again:  # the NEES as at the start, its factors made a chunk at a time
        eps = linalg.by_inverse_chunks(metrics.nees_inverse, errors, cov)
        gls.release_scores()  # made again if read again (the model's rule does not)
    squares_ratio = memory.squares.variance_ratio if memory is not None else tau_q
    found_bursts = episodes.bursts(eps, d, squares_ratio)
    q_median = float(np.median(gls.q))
    diverging = {
        c.scale_level: episodes.divergence(q_median, eps, d, c.scale_level)
        for c in configs
        if c.calibrated
    }
    del eps  # before the ELT's whitened errors are made (a long segment's peak memory)
    if s is None:
        s = whiten(errors, cov)
        r1 = correlation.autocorrelation(s)
    autocorr = float(np.max(r1))
    effective_n = float(n / max(1.0, float(np.max(tau_point))))
    if any(diverging.values()):  # the divergence names the run-away tail: not a burst
        found_bursts = tuple(b for b in found_bursts if b.stop < n)
    slow = _slow_memory(scales_check, memory) if memory is not None else None
    if slow is None and modelled and source is not None:
        slow = _unresolved_memory(memory, n, source == "run")
    if slow is not None:
        model_evidence = {c: _declined(ev, slow) for c, ev in model_evidence.items()}
    # every scale and mean test now, so the GLS residuals can be freed
    scales: dict = {}
    means: dict = {}
    directional: dict = {}
    for config in configs:
        if config in model_evidence:
            continue
        key = _scale_key(config, refers_to_batches(config, dependent))
        if key not in scales:
            batched = refers_to_batches(config, dependent)
            scales[key] = scale_evidence(gls, config, tau, tau_q, batched, runs=runs)
            if config.calibrated and d > 1 and scales[key][1] is None:
                k = scales[key][0].batches
                directional[key] = direction_scales(gls, config.scale_level, k)
        mean_key = (refers_to_batches(config, located), config.fixed_block_length)
        if config.calibrated and mean_key not in means:
            means[mean_key] = mean_evidence(gls, config, tau_location, mean_key[0], runs)
    del gls
    plans = [
        model_evidence[config].plan
        if config in model_evidence
        else location_plan(config, n, tau_location, means, located, runs)
        if config.calibrated
        else location_plan(config, n, tau, means, dependent, runs)  # paper, ks: unchanged
        for config in configs
    ]
    exact = any(c.exact_pvalue for c in configs)
    used = [plan.elt_level for plan in plans if plan.elt_level is not None]
    stop_level = None if exact or not used else max(used)
    elts: dict = {}
    scorer = None
    out = []
    for config, plan in zip(configs, plans):
        if config in model_evidence:
            modelled_config = model_evidence[config]
            scale, scale_reason = modelled_config.scale, modelled_config.scale_reason
            directions = modelled_config.directions
            segment_n = (
                float(n / max(1.0, float(np.max(memory.variance_ratios))))
                if memory is not None
                else 0.0  # no finite memory: no independent epochs to count
            )
        else:
            key = _scale_key(config, refers_to_batches(config, dependent))
            scale, scale_reason = scales[key]
            calibrated = config.calibrated and scale_reason is None
            directions = directional.get(key) if calibrated else None
            segment_n = effective_n
        elt = None
        if plan.elt_level is not None:
            separate = config.calibrated and plan.block > 1
            elt_key = (plan.block, separate, config.n_flips, config.max_elt_epochs)
            if elt_key not in elts:
                elts[elt_key] = whitened_location_test(
                    s,
                    config.n_flips,
                    gen,
                    plan.block,
                    config.max_elt_epochs,
                    separate_blocks=separate,
                    stop_level=stop_level,
                    runs=runs,
                )
            elt = elts[elt_key]
        evidence = Evidence(
            n=n,
            dim=d,
            nci=nci_raw,
            nci_centered=nci_centred,
            anees=anees,
            ks_pvalue=ks_p,
            nees_total=nees_total,
            scale=scale,
            scale_reason=scale_reason,
            directions=directions,
            block_length=plan.block,
            effective_n=segment_n,
            autocorrelation=autocorr,
            mean_test=plan.mean_test,
            mean_level=plan.mean_level,
            elt=elt,
            elt_level=plan.elt_level,
            location_reason=plan.reason,
            bias_declined=plan.bias_declined,
            memory=memory if config in model_evidence else None,
            memory_source=source if config in model_evidence else None,
            time_scales=scales_check if config in model_evidence else None,
            q_median=q_median,
            bursts=found_bursts,
            divergence=diverging.get(config.scale_level) if config.calibrated else None,
        )
        everything = config.metrics is MetricsLevel.ALL
        needs_probes = (
            not config.calibrated and evidence.location_rejected and nci_centred > config.tau_nci
        )
        if needs_probes or everything:
            if scorer is None:
                scorer = metrics.EnergyScorer(cov)
            absolute = config.srd_form is SrdForm.ABSOLUTE
            probes = metrics.probes_scored(_centred(errors), scorer, chol, config.c, absolute)
            scores = (
                metrics.probes_scored(errors, scorer, chol, config.c, absolute)
                if everything
                else None
            )
            evidence = replace(evidence, probes=probes, scores=scores)
        out.append(evidence)
    return out


def _centred(errors: np.ndarray) -> np.ndarray:
    """The errors less their mean, e_k − ē: made where they are used (the same bits each
    time), not held through the segment's evidence (an (N, d) array)."""
    return errors - errors.mean(axis=0)


def refers_to_batches(config: DiagnosisConfig, dependent: bool) -> bool:
    """Whether the calibrated rule refers this segment's tests to batch means.

    Parameters
    ----------
    config : DiagnosisConfig
        The configuration.
    dependent : bool
        Whether the screening found the epochs serially dependent.

    Returns
    -------
    bool
        True for the calibrated rule on serially dependent epochs: estimated
        (``dependent``), or declared by a fixed block length above 1 (a fixed 1 declares
        them independent). False for ``paper`` and ``ks``.
    """
    fixed = config.fixed_block_length
    return config.calibrated and (fixed > 1 if fixed is not None else dependent)


def _scale_key(config: DiagnosisConfig, batched: bool) -> tuple:
    """Configurations with equal keys share one scale test."""
    return (config.block_length == 1, config.scale_level, batched and config.fixed_block_length)


def _batch_length_for(config: DiagnosisConfig, tau: float) -> int:
    """Batches are at least the fixed sign-block length, else estimated from ``tau``."""
    return config.fixed_block_length or batches.batch_length(tau)


def scale_evidence(
    gls, config: DiagnosisConfig, tau, tau_q: float, batched: bool, level=None, runs: int = 1
):
    """The scale test of the lag-1 route, and why it is untested.

    Batch means on dependent epochs (:func:`credcli.engine.scale.batch_scale_test`, the
    runs as batches where :func:`batch_plan` allows), else the χ² (Satterthwaite-scaled)
    test of :func:`credcli.engine.scale.scale_test`.

    Parameters
    ----------
    gls : GlsResiduals
        The segment's GLS residuals (:func:`credcli.engine.scale.gls_residuals`).
    config : DiagnosisConfig
        The configuration (its fixed block length, if any, is the least batch length).
    tau : numpy.ndarray, shape (d,)
        The variance ratio τ per component (Satterthwaite scaling, centring of κ̄).
    tau_q : float
        The variance ratio of the squared errors q, which sets the batch length.
    batched : bool
        Whether the test refers to batch means (:func:`refers_to_batches`).
    level : float, optional
        The test's level; default the configuration's α_S.
    runs : int, default 1
        Equal Monte Carlo runs pooled in the segment (:func:`batch_plan`).

    Returns
    -------
    scale : ScaleTest
        The test; where too few batches fit, κ̂ and the bias with a NaN interval and
        p-values (:func:`credcli.engine.scale.untested_scale`).
    reason : str or None
        Why the scale is untested (None: it is tested).
    """
    level = config.scale_level if level is None else level
    if not batched:
        fixed = config.block_length == 1
        return scale_test(gls, level, None if fixed else tau), None
    n = gls.whitened.shape[0]
    length = _batch_length_for(config, tau_q)
    k, aligned = batch_plan(n, length, batches.MIN_SCALE_BATCHES, runs)
    if aligned:
        return batch_scale_test(gls, level, k, taus=tau, independent=True), None
    if not k:  # κ̂ and the bias are still reported; the interval and p-values are NaN
        return untested_scale(gls), (
            f"scale untested: the squared errors' serial dependence (variance ratio "
            f"{tau_q:.3g}) needs batches of {length} epochs, and fewer than the "
            f"{batches.MIN_SCALE_BATCHES} the scale test needs fit in {n}"
        )
    return batch_scale_test(gls, level, k, tau_q, tau), None


def mean_evidence(gls, config: DiagnosisConfig, tau, batched: bool, runs: int = 1):
    """The GLS mean test of the lag-1 route, and why it is untested.

    Hotelling on batch score sums on dependent epochs
    (:func:`credcli.engine.batches.batch_mean_test`, with the neighbouring-batch
    correction unless the runs are the batches), else Hotelling's test of independent
    epochs (:func:`credcli.engine.batches.independent_mean_test`) with T² divided by
    max_i τ_i.

    Parameters
    ----------
    gls : GlsResiduals
        The segment's GLS residuals.
    config : DiagnosisConfig
        The configuration (its fixed block length, if any, is the least batch length).
    tau : numpy.ndarray, shape (d,)
        The variance ratio τ per component; the largest sets the batch length.
    batched : bool
        Whether the test refers to batch means.
    runs : int, default 1
        Equal Monte Carlo runs pooled in the segment (:func:`batch_plan`).

    Returns
    -------
    mean_test : MeanTest or None
        The test, None when fewer batches than it needs fit.
    reason : str or None
        Why it is untested (None: it ran).
    """
    n, d = gls.whitened.shape
    if not batched:
        return batches.independent_mean_test(gls, float(np.max(tau))), None
    worst = float(np.max(tau))
    smallest = batches.min_location_batches(d)
    length = _batch_length_for(config, worst)
    k, aligned = batch_plan(n, length, smallest, runs)
    if not k:
        return None, (
            f"serial dependence (variance ratio {worst:.3g}) needs batches of {length} epochs "
            f"for the mean test, and fewer than the {smallest} it needs fit in {n}"
        )
    sums = np.add.reduceat(gls.scores, batches.bounds(n, k), axis=0)
    inflation = 1.0 if aligned else batches.boundary_inflation(worst, n, k)
    return batches.batch_mean_test(sums, inflation, gls), None


def batch_plan(n: int, length: int, smallest: int, runs: int) -> tuple[int, bool]:
    """The number of batches K, and whether the batches are the runs.

    A segment that pools ``runs`` independent Monte Carlo runs of equal length has batches
    that are independent by construction: the runs themselves. They are used when there
    are at least as many runs as batches of ``length`` epochs would fit (and at least
    ``smallest``); then no estimate of the correlation time decides the reference, and no
    correction for neighbouring batches is needed.

    Parameters
    ----------
    n : int
        Epochs in the segment.
    length : int
        The shortest batch, in epochs.
    smallest : int
        The fewest batches the test needs.
    runs : int
        Equal runs pooled in the segment (1: a single run).

    Returns
    -------
    k : int
        ``runs`` when the runs are the batches; otherwise K batches of at least
        ``length`` epochs (at most ``MAX_BATCHES``), or 0 when fewer than ``smallest`` fit
        (:func:`credcli.engine.batches.batch_count`).
    aligned : bool
        Whether the batches are the runs.
    """
    k = batches.batch_count(n, length, smallest)
    if runs > 1 and n % runs == 0 and runs >= max(k, smallest):
        return runs, True
    return k, False


@dataclass(frozen=True)
class LocationPlan:
    """How one configuration answers the location question on this segment.

    Attributes
    ----------
    block : int
        Epochs per ELT sign block.
    mean_test : MeanTest or None
        The GLS mean test, None when it does not run.
    mean_level : float
        Its level (0.0 when it does not run; the level it ran at when its bias was
        declined).
    elt_level : float or None
        The ELT's level (None: the ELT does not run).
    reason : str or None
        Why a location test does not run (None: the plan is complete).
    bias_declined : bool, default False
        The mean test found a bias under the fitted model that its alternative with more
        memory does not confirm (:func:`_held_under_alternative`): the errors sit off zero,
        whatever the cause.
    """

    block: int
    mean_test: batches.MeanTest | None
    mean_level: float
    elt_level: float | None
    reason: str | None
    bias_declined: bool = False


def location_plan(config: DiagnosisConfig, n, tau, means, dependent, runs) -> LocationPlan:
    """The location plan of the lag-1 route.

    Sign blocks of the fixed block length, else from the AR(1) plug-in τ
    (:func:`credcli.engine.correlation.block_length`); the calibrated rule splits α_L
    between the mean test from ``means`` and the ELT (:func:`split_location`); ``paper``
    and ``ks`` run the ELT alone, at α_L.

    Parameters
    ----------
    config : DiagnosisConfig
        The configuration.
    n : int
        Epochs in the segment.
    tau : numpy.ndarray, shape (d,)
        The variance ratio τ per component, for the sign-block length.
    means : dict
        The mean tests already run, ``(batched, fixed block length) -> (MeanTest or None,
        reason)`` (:func:`mean_evidence`).
    dependent : bool
        Whether the epochs were found serially dependent (which mean test applies).
    runs : int
        Equal runs pooled in the segment (the ELT flips each run's errors in its own
        blocks).

    Returns
    -------
    LocationPlan
        The sign-block length, the tests that run, their levels, and why one does not.
    """
    block = config.fixed_block_length or correlation.block_length(tau)
    cause = (
        f"serial dependence (variance ratio {float(np.max(tau)):.3g}) needs sign blocks of "
        f"{block} epochs, which"
    )
    if not config.calibrated:
        elt_ok, why_not_elt = _elt_fits(config, n, block, runs, cause)
        return LocationPlan(
            block, None, 0.0, config.location_level if elt_ok else None, why_not_elt
        )
    mean_test, why_not_mean = means[
        (refers_to_batches(config, dependent), config.fixed_block_length)
    ]
    return split_location(config, n, block, runs, mean_test, why_not_mean, cause)


def _elt_fits(config: DiagnosisConfig, n: int, block: int, runs: int, cause: str):
    """(whether the ELT has its sign blocks, why not): ``cause`` names what asks for blocks
    of ``block`` epochs when they, not the memory budget, are too few."""
    n_blocks = tested_blocks(n, block, config.max_elt_epochs, runs)
    if n_blocks >= config.min_blocks:
        return True, None
    if tested_blocks(n, block, n, runs) >= config.min_blocks:
        cause = f"its budget of {config.max_elt_epochs} epochs (max_elt_epochs)"
    return False, (
        f"ELT not run: {cause} leaves {n_blocks} of the {config.min_blocks} sign blocks it needs"
    )


def split_location(
    config: DiagnosisConfig, n: int, block: int, runs: int, mean_test, why_not_mean, cause: str
) -> LocationPlan:
    """The calibrated rule's split of the location level between the mean test and the ELT.

    The GLS mean test runs at α_L·MEAN_SHARE and the ELT at the rest; a test that cannot
    run leaves the whole α_L to the other.

    Parameters
    ----------
    config : DiagnosisConfig
        The configuration (its levels, ELT budget and fewest sign blocks).
    n : int
        Epochs in the segment.
    block : int
        Epochs per sign block.
    runs : int
        Equal runs pooled in the segment.
    mean_test : MeanTest or None
        The GLS mean test, None when it cannot run.
    why_not_mean : str or None
        Why the mean test cannot run.
    cause : str
        What asks for blocks of ``block`` epochs, for the reason when too few fit (the
        start of a sentence ending "which").

    Returns
    -------
    LocationPlan
        The sign-block length, the tests that run at their levels, and why one does not.
    """
    elt_ok, why_not_elt = _elt_fits(config, n, block, runs, cause)
    if mean_test is not None and elt_ok:
        return LocationPlan(block, mean_test, config.mean_level, config.elt_level, None)
    if mean_test is not None:  # the mean test takes the whole location level
        return LocationPlan(block, mean_test, config.location_level, None, why_not_elt)
    if elt_ok:
        reason = f"mean test not run: {why_not_mean}"
        return LocationPlan(block, None, 0.0, config.location_level, reason)
    reason = f"location untested: {why_not_elt}; the mean test: {why_not_mean}"
    return LocationPlan(block, None, 0.0, None, reason)


class Undecidable(Exception):
    """A segment whose data cannot carry the tests at all.

    The segment is `insufficient-data` with the exception's ``reason``, and the other
    segments of the log are diagnosed as usual.

    Parameters
    ----------
    reason : str
        Why the segment cannot be tested (kept as ``reason``).
    """

    def __init__(self, reason: str) -> None:
        super().__init__(reason)
        self.reason = reason


DEGENERATE = (
    "the errors span fewer than d dimensions (for example a component whose error is the "
    "same in every epoch), so the MSE matrix of the NCI, Eq. (4), is singular"
)


def mse_cholesky(mse: np.ndarray, given: bool = False) -> np.ndarray:
    """The Cholesky factor of the NCI's MSE matrix.

    Parameters
    ----------
    mse : numpy.ndarray, shape (d, d)
        The MSE matrix of Eq. (4).
    given : bool, default False
        Whether the caller gave it (else it was estimated from the segment).

    Returns
    -------
    numpy.ndarray, shape (d, d)
        Its lower Cholesky factor.

    Raises
    ------
    CredcliError
        When a given ``mse`` is singular (an error in the input, naming ``mse``).
    Undecidable
        When an estimated one is singular: the segment is insufficient-data.
    """
    try:
        factor = np.linalg.cholesky(mse)
    except np.linalg.LinAlgError as exc:
        if given:
            raise CredcliError(
                "the given MSE matrix is singular; the NCI, Eq. (4), needs it positive definite",
                "mse",
            ) from exc
        raise Undecidable(DEGENERATE) from exc
    # errors the same in two components (or a constant one, centred) make M singular, but
    # its Cholesky factorisation may pass by rounding: 7 of 40 segments of two equal
    # columns did, and got "bias" (their sample covariance inverted); singular to working
    # precision is what the correlation matrix's smallest eigenvalue tells, free of units
    if not given and mse.shape[0] > 1:
        if not linalg.smallest_correlation_eigenvalue(mse[None])[0] > linalg.CORRELATION_FLOOR:
            raise Undecidable(DEGENERATE)
    return factor


def _mse_nees(errors: np.ndarray) -> np.ndarray:
    """ε*_k = e_kᵀ M⁻¹ e_k with M the segment's own MSE matrix (:func:`metrics.mse_matrix`),
    the NCI's second term, Eq. (4).

    ε* is scale-free in e, so where the errors' squares leave float64's normal range
    (errors beyond about 1e154 or below 1e-154 in the log's units, whatever their claimed
    covariance) it is made on e / 2^j (:func:`credcli.engine.units.power_of_two_unit`), an
    exact rescaling: elsewhere M is made as before, with the same bits. Without it such
    errors gave an MSE matrix of inf (no NCI, and the ks and paper variants, which read
    the NCI, said credible) or of zeros (insufficient-data, as if the errors spanned fewer
    than d dimensions).

    Parameters
    ----------
    errors : numpy.ndarray, shape (N, d)
        The errors (or the centred errors).

    Returns
    -------
    numpy.ndarray, shape (N,)
        ε*.

    Raises
    ------
    Undecidable
        When M is singular (the errors span fewer than d dimensions).
    """
    with np.errstate(over="ignore", invalid="ignore", under="ignore"):
        mse = metrics.mse_matrix(errors)
    if not (np.all(np.isfinite(mse)) and np.min(np.diag(mse)) >= np.finfo(float).tiny):
        errors = errors / power_of_two_unit(errors)
        mse = metrics.mse_matrix(errors)
    return metrics.nees_factored(errors, mse_cholesky(mse))


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


def ks_chi2_pvalue(eps: np.ndarray, dim: int) -> float:
    """Two-sided Kolmogorov–Smirnov p-value of NEES values against χ²_d.

    p = min(1, 2·S_n(D)), with D = max(D⁺, D⁻) the two-sided statistic and S_n the exact
    one-sided Smirnov tail (:func:`smirnov_tail`). It agrees with
    ``scipy.stats.kstest(method="exact")`` closely enough that the decision at the 1 %
    level is the exact test's (docs/measured.md has the comparison), and avoids importing
    scipy.stats.

    Parameters
    ----------
    eps : numpy.ndarray, shape (N,)
        The NEES values ε_k, Eq. (1).
    dim : int
        The state dimension d (the χ² degrees of freedom).

    Returns
    -------
    float
        The p-value, in [0, 1].

    Examples
    --------
    >>> eps = np.random.default_rng(4).chisquare(2, size=200)
    >>> ks_chi2_pvalue(eps, 2) > 0.05, ks_chi2_pvalue(4.0 * eps, 2) < 1e-6
    (True, True)
    """
    cdf = np.sort(np.asarray(eps, dtype=float))
    n = cdf.size
    special.chdtr(dim, cdf, out=cdf)
    largest = []  # D⁺ and D⁻ by chunks: no N-long temporaries; a NaN stays a NaN
    for sl in linalg.epoch_chunks(n):
        i = np.arange(sl.start + 1, min(sl.stop, n) + 1)
        part = cdf[sl]
        largest += [np.max(i / n - part), np.max(part - (i - 1) / n)]
    d_stat = float(np.max(largest))
    return float(min(1.0, 2.0 * smirnov_tail(n, d_stat)))


SMIRNOV_SCIPY_MAX = 40
"""Up to this many epochs the one-sided Smirnov tail is scipy's ``smirnov``; beyond, the
Birnbaum–Tingey sum as one array (:func:`smirnov_tail`), which scipy evaluates term by
term: on a credible segment the statistic is small and all N terms count. The array costs
about 16 µs at any size up to a few thousand epochs, scipy's sum 3 µs below 40 epochs
(another method) and 0.7 µs per epoch above (docs/performance.md has the costs)."""


def smirnov_tail(n: int, d: float) -> float:
    r"""P(D⁺_n ≥ d), the exact one-sided Smirnov tail (Birnbaum & Tingey 1951).

    scipy's ``smirnov`` up to :data:`SMIRNOV_SCIPY_MAX` epochs (and for d outside (0, 1)),
    else the sum below in logarithms as one array (every term is positive: no
    cancellation; docs/performance.md has its accuracy and cost). Beyond 10⁶ epochs scipy
    switches to an asymptotic form; this stays exact.

    Parameters
    ----------
    n : int
        The sample size.
    d : float
        The value of the one-sided statistic D⁺_n.

    Returns
    -------
    float
        P(D⁺_n ≥ d).

    Notes
    -----
    .. math:: P(D_n^+ \ge d) = d \sum_{j=0}^{\lfloor n(1-d)\rfloor} \binom{n}{j}
              \left(1 - d - \tfrac{j}{n}\right)^{n-j} \left(d + \tfrac{j}{n}\right)^{j-1}

    References
    ----------
    Z. W. Birnbaum and F. H. Tingey, "One-sided confidence contours for probability
    distribution functions", Ann. Math. Stat. 22(4), 1951.
    """
    if n <= SMIRNOV_SCIPY_MAX or d <= 0.0 or d >= 1.0:
        return float(special.smirnov(n, d))
    terms = math.floor(n * (1.0 - d)) + 1
    log_terms = np.empty(terms)
    for sl in linalg.epoch_chunks(terms):  # term by term: chunks keep the temporaries short
        j = np.arange(sl.start, min(sl.stop, terms), dtype=float)
        x = j / n
        with np.errstate(divide="ignore"):
            log_terms[sl] = (
                special.gammaln(n + 1.0)
                - special.gammaln(j + 1.0)
                - special.gammaln(n - j + 1.0)
                + (n - j) * np.log1p(-(d + x))
                + (j - 1.0) * np.log(d + x)
            )
    top = float(np.max(log_terms))
    log_terms -= top
    return float(d * math.exp(top) * np.sum(np.exp(log_terms, out=log_terms)))


def reads_memory(config: DiagnosisConfig, runs: int) -> bool:
    """Whether ``config``'s tests read the fitted dependence model.

    Parameters
    ----------
    config : DiagnosisConfig
        The configuration.
    runs : int
        Equal Monte Carlo runs pooled in the segment.

    Returns
    -------
    bool
        True for the calibrated rule with the block length estimated (auto), on one run.
    """
    return config.calibrated and config.fixed_block_length is None and runs == 1


@dataclass(frozen=True)
class ModelEvidence:
    """The scale test, principal directions and location plan of one configuration under
    the dependence model (:func:`memory_evidence`).

    Attributes
    ----------
    scale : ScaleTest
        The scale test under the model (untested, with κ̂, when the model is known to too
        few degrees of freedom).
    scale_reason : str or None
        Why the scale is untested (None: tested).
    directions : DirectionScales or None
        The scale factor per principal direction (d > 1, scale tested).
    plan : LocationPlan
        How the location question is answered under the model.
    """

    scale: ScaleTest
    scale_reason: str | None
    directions: DirectionScales | None
    plan: LocationPlan


MEMORY_BLOCK_LOSS = correlation.BLOCK_VARIANCE_LOSS
"""ε of the ELT's sign blocks under the fitted model (as for the AR(1) plug-in)."""
MIN_MODEL_DOF = 4
"""Fewest degrees of freedom ν_Ω of the dependence model for a scale interval: Student's t
with 3 has a 0.6 % tail at 5.5 standard errors, beyond which an interval says nothing."""
SCREENED_BELOW = 200
"""Segments shorter than this are screened for weak memory by their lag-1 autocorrelation
as well as by the sieve's criteria (BIC whether there is any memory, AICc its order),
which find no memory in weakly dependent errors on short windows too often (the mean test
then loses its level on the windows it left white); on longer segments the criteria alone
see such memory, and the screen would send many independent segments to the bootstrap
(docs/measured.md)."""
MIN_MEAN_DOF = 3
"""Fewest denominator degrees of freedom of the mean test's F (as for batch means, K − d)."""


class Inverses:
    """The whitening factors F_k = Σ_k^{-1/2} of a segment's covariances, made when a
    model's test first reads them.

    A white model's tests read them only for a bias they find, so a long credible segment
    does not make and hold N × d × d numbers it has no use for (2·10⁶ epochs, d = 2:
    61 MiB at the peak of its diagnosis); the numbers are those of the factors made at the
    start (:func:`credcli.engine.linalg.whitening_factors`).
    """

    def __init__(self, cov: np.ndarray) -> None:
        self._cov = cov
        self._made: np.ndarray | None = None

    def __call__(self) -> np.ndarray:
        if self._made is None:
            self._made = linalg.whitening_factors(self._cov)
        return self._made


def _read(inverse) -> np.ndarray:
    """``inverse`` itself, or the factors an :class:`Inverses` makes."""
    return inverse() if isinstance(inverse, Inverses) else inverse


def memory_evidence(
    gls,
    inverse,
    config: DiagnosisConfig,
    memory: Memory,
    n: int,
    level: float | None = None,
    residuals: np.ndarray | None = None,
) -> ModelEvidence:
    """The calibrated rule's evidence under the dependence model ``memory``.

    A white model (no memory in any series by BIC, fitted on this segment,
    :func:`credcli.engine.memory.fit_memory`) keeps the exact tests for
    independent epochs: the χ² scale test with its tail factor, Hotelling's mean test, the
    ELT with single-epoch signs; a bias that mean test finds must hold as well under the
    alternative with more memory that the residuals support (:func:`_held_if_white`).
    Otherwise the scale test and the GLS mean test are referred to their distributions
    under the model (:func:`credcli.engine.scale.memory_scale_test`,
    :func:`credcli.engine.batches.memory_mean_test`), and the ELT flips blocks long enough
    to lose at most ε of the variance under the model
    (:meth:`credcli.engine.memory.Memory.block_length`), leaving out pairs in the same or
    adjacent blocks. The scale is untested when the model has fewer than
    :data:`MIN_MODEL_DOF` degrees of freedom, the mean test when it leaves fewer than
    :data:`MIN_MEAN_DOF`, or fewer than
    :data:`credcli.engine.batches.MIN_HOLDING_EPOCHS` epochs' worth of leverage hold the
    GLS mean; where a few epochs hold the GLS weights
    (:func:`credcli.engine.batches.claim_following_errors`, or that floor), the test of
    the claim as its local misfit corrects it answers "no bias beyond the margin" where its
    region is the narrower (:func:`_corrected_claim_location`; it never names a bias).
    Where the model has an alternative with more memory (a fractional model the data
    support and BIC does not take, or an ARMA(p, 1) they prefer to the sieve:
    :attr:`credcli.engine.memory.Memory.alternative`), a finding must hold under it as
    well: the scale's and the directions' intervals are the union of the two models'
    (:func:`credcli.engine.scale.under_either`), and a bias the mean test finds must be
    found under both (:func:`_held_under_alternative`).

    Parameters
    ----------
    gls : GlsResiduals
        The segment's GLS residuals.
    inverse : numpy.ndarray, shape (N, d, d), or Inverses
        The whitening factors, F_k = Σ_k^{-1/2} per epoch
        (:func:`credcli.engine.linalg.whitening_factors`), or the :class:`Inverses` that
        makes them where read.
    config : DiagnosisConfig
        The configuration (calibrated).
    memory : Memory
        The dependence model (fitted on this segment, or the run's).
    n : int
        Epochs in the segment.
    level : float, optional
        The scale test's level; default α_S.
    residuals : numpy.ndarray or None, optional
        The residuals the model was fitted on (:func:`memory_residuals`) where the caller
        holds them; None: made again where a white model's bias needs them.

    Returns
    -------
    ModelEvidence
        The scale test and why it is untested, the principal directions' factors, and
        the location plan.
    """
    d = gls.whitened.shape[1]
    level = config.scale_level if level is None else level
    if memory.white and memory.epochs == n:
        scale = scale_test(gls, level, np.ones(d), squares_white=True)
        directions = direction_scales(gls, level, 0) if d > 1 else None
        mean = batches.independent_mean_test(gls, 1.0)
        plan = split_location(config, n, 1, 1, mean, None, _MEMORY_BLOCKS.format(block=1))
        held = _held_if_white(plan, gls, memory, inverse, residuals)
        return ModelEvidence(scale, None, directions, held)
    tail = memory_tail_factor(gls, memory)
    scale = memory_scale_test(gls, memory, level, tail)
    alternative = memory.alternative
    if alternative is not None:  # a scale finding must hold under more memory as well
        other_tail = memory_tail_factor(gls, alternative)
        scale = under_either(scale, memory_scale_test(gls, alternative, level, other_tail))
    mean, stderr = batches.memory_mean_test(gls, memory, _read(inverse))
    scale = replace(scale, bias_stderr=stderr)
    tau = float(np.max(memory.variance_ratios))
    if scale.model_dof < MIN_MODEL_DOF:
        untested = untested_scale(gls)
        scale = replace(untested, bias_stderr=stderr, model_dof=scale.model_dof)
        directions = None
        # the reference is the variance of the squares: under the errors' model τ₂ = Σρ²
        # sets it (not τ: an oscillating memory has τ̂ well below 1 and τ₂ of several
        # epochs), or the squares' own memory where it implies more (memory_scale_test)
        tau2 = max(float(2.0 * np.sum(series.rho**2) - 1.0) for series in memory.series)
        tau_q = memory.squares.variance_ratio
        scale_reason = (
            f"scale untested: the variance of the squared errors it is referred to is known "
            f"to {scale.model_dof:.3g} degrees of freedom, fewer than the {MIN_MODEL_DOF} an "
            f"interval needs (the errors' memory: τ₂ = Σρ² {tau2:.3g} epochs, N/τ₂ "
            f"{n / tau2:.3g}; the squares' own: τ̂ {tau_q:.3g} epochs, N/τ̂ {n / tau_q:.3g})"
        )
    else:
        directions = direction_scales(gls, level, 0, memory, tail) if d > 1 else None
        if directions is not None and alternative is not None:
            other = direction_scales(gls, level, 0, alternative, other_tail)
            directions = directions_under_either(directions, other)
        scale_reason = None
    why_not = None
    if mean.weights_follow > 1.0 or mean.holding < batches.MIN_HOLDING_EPOCHS:
        # a few epochs hold the GLS weights
        mean, scale = _corrected_claim_location(gls, _read(inverse), memory, mean, scale, config)
    if not mean.dof[1] >= MIN_MEAN_DOF:
        cause = f"the errors' memory (τ̂ {tau:.3g} epochs, N/τ̂ {n / tau:.3g}) leaves"
        if mean.holding < batches.MIN_HOLDING_EPOCHS:  # batches.holding_epochs
            cause = (
                f"the claim's precision puts the GLS mean on {mean.holding:.3g} epochs' worth "
                f"of leverage along one direction, fewer than {batches.MIN_HOLDING_EPOCHS}, "
                "whose variance no model or reading of so few epochs knows: that leaves"
            )
        elif mean.weights_follow > 1.0:  # batches.claim_following_errors
            cause = cause.removesuffix(" leaves") + (
                " and a claim that shrinks where the errors grow (the GLS sum varies "
                f"{mean.weights_follow:.3g}× as much as the memory alone says, and a few "
                "epochs hold it) leave"
            )
        why_not = (
            f"{cause} it {max(mean.dof[1], 0.0):.3g} degrees of freedom, fewer than {MIN_MEAN_DOF}"
        )
        mean = None
    block = memory.block_length(MEMORY_BLOCK_LOSS)
    plan = split_location(config, n, block, 1, mean, why_not, _MEMORY_BLOCKS.format(block=block))
    return ModelEvidence(
        scale, scale_reason, directions, _held_under_alternative(plan, gls, memory, inverse)
    )


def corrected_claim_test(gls, inverse: np.ndarray, memory: Memory):
    """The mean test of the claim as its local misfit corrects it
    (:func:`_corrected_claim_location` reads it).

    κ_k from :func:`credcli.engine.batches.local_misfit` with ``memory``'s τ; the
    whitened errors and factors divided by √κ_k; a model fitted on the corrected errors
    less their constants (:func:`segment_memory_of`); their unweighted sum tested under it
    (:func:`credcli.engine.batches.whitened_mean_test`).

    Parameters
    ----------
    gls : GlsResiduals
        The segment's GLS residuals.
    inverse : numpy.ndarray, shape (N, d, d)
        The whitening factors F_k.
    memory : Memory
        The segment's model (its τ sets the misfit's window).

    Returns
    -------
    tuple or None
        (test, centre, standard errors, norm) as
        :func:`credcli.engine.batches.whitened_mean_test` returns them; None where the
        corrected errors have no finite memory.
    """
    s = gls.whitened + np.einsum("nij,j->ni", inverse, gls.mean)
    misfit = batches.local_misfit(s, float(np.max(memory.variance_ratios)))
    root = 1.0 / np.sqrt(misfit)
    corrected = mean_free(s * root[:, None], inverse * root[:, None, None], overwrite=True)
    try:
        model = segment_memory_of(corrected, np.einsum("ni,ni->n", corrected, corrected))
    except NoFiniteMemory:
        return None
    return batches.whitened_mean_test(gls, model, inverse, misfit)


def _corrected_claim_location(
    gls, inverse: np.ndarray, memory: Memory, mean, scale: ScaleTest, config: DiagnosisConfig
):
    """The mean test that answers "no bias beyond the margin" where the claim follows the
    errors' size (``mean.weights_follow`` > 1) or few epochs hold the GLS mean
    (``mean.holding`` below :data:`credcli.engine.batches.MIN_HOLDING_EPOCHS`), and the
    scale test with its bias fields.

    The whitened errors are corrected by the claim's local misfit and their unweighted
    sum tested under a model fitted on them (:func:`corrected_claim_test`). Of the two
    tests with :data:`MIN_MEAN_DOF` degrees of freedom, the one whose confidence region is the
    narrower (its ``spread``, which the variance estimate sets, not the centre) answers
    "no bias": one test chosen before its answer is read, not whichever of two excludes
    the margin. Where the GLS test answers, it stays as it is. Where the corrected one
    does and finds no bias at the location's level, it is the mean test, and the scale's
    bias fields are its centre, standard errors and norm; where it finds one, the GLS test
    stays to name a bias, without its region (``spread`` NaN): the corrected test never
    names a misfit, and no "no bias" is claimed.

    Parameters
    ----------
    gls : GlsResiduals
        The segment's GLS residuals.
    inverse : numpy.ndarray, shape (N, d, d)
        The whitening factors F_k.
    memory : Memory
        The model the GLS test was referred to (its τ sets the misfit's window).
    mean : MeanTest
        The GLS test under ``memory``.
    scale : ScaleTest
        The scale test, whose bias fields are the GLS mean's.
    config : DiagnosisConfig
        The configuration (its location level).

    Returns
    -------
    mean : MeanTest
        ``mean``, the corrected claim's test, or ``mean`` without its region.
    scale : ScaleTest
        ``scale`` with the bias fields of the test returned.
    """
    corrected = corrected_claim_test(gls, inverse, memory)
    if corrected is None:
        return mean, scale
    test, centre, stderr, norm = corrected
    if not test.dof[1] >= MIN_MEAN_DOF:
        return mean, scale
    if mean.dof[1] >= MIN_MEAN_DOF and not test.spread < mean.spread:
        return mean, scale  # the GLS region is the narrower: the GLS test answers
    if test.pvalue < config.location_level:  # a shift the GLS test may name; no "no bias"
        return replace(mean, spread=math.nan), scale
    return test, replace(scale, bias=centre, bias_stderr=stderr, bias_mahalanobis=norm)


def _held_if_white(
    plan: LocationPlan, gls, memory: Memory, inverse, residuals: np.ndarray | None = None
) -> LocationPlan:
    """``plan`` of a white model, with a bias its mean test finds checked under the
    alternative with more memory that the residuals support
    (:func:`credcli.engine.longmemory.white_alternative`, fitted only then), as
    :func:`_held_under_alternative` checks a modelled segment's; ``residuals``: those the
    model was fitted on, where the caller holds them (else made here)."""
    test = plan.mean_test
    if test is None or not test.pvalue < plan.mean_level:
        return plan
    if residuals is None:
        residuals = memory_residuals(gls, _read(inverse))
    alternative = white_alternative(memory, residuals)
    return plan if alternative is None else _held_under_alternative(plan, gls, alternative, inverse)


def _held_under_alternative(plan: LocationPlan, gls, memory: Memory, inverse) -> LocationPlan:
    """``plan``, or the location answered under the model's alternative with more memory
    (:attr:`credcli.engine.memory.Memory.alternative`) where the mean test finds a bias
    that the alternative does not: where the data support a fractional model (its AICc
    within ``longmemory.SUPPORT`` of the sieve's, no ARMA(p, 1) better by BIC's margin) and
    BIC does not take it, or an ARMA(p, 1) with more memory than the sieve's, one segment
    cannot tell the two memories apart, and a mean off by that much is within what the
    longer memory lets a mean wander.

    A bias is then not claimed, and "no bias of the margin's size"
    (:func:`credcli.engine.rules.inconclusive_location`) is claimed only as the
    alternative's mean test supports it: its confidence region, about the same centre and
    at the same level, is the wider of the two (the alternative has at least as much
    memory in every direction), so where it excludes the margin so does the fitted
    model's, and the claim holds whichever memory is right, as the scale's interval covers
    both
    (:func:`credcli.engine.scale.directions_under_either`). The ELT, whose sign blocks the
    longer memory would lengthen, does not run. Where the alternative's region is not the
    wider one, or its test has too few degrees of freedom, the location is untested."""
    alternative = memory.alternative
    test = plan.mean_test
    if alternative is None or test is None or not test.pvalue < plan.mean_level:
        return plan
    other, _ = batches.memory_mean_test(gls, alternative, _read(inverse))
    usable = other.dof[1] >= MIN_MEAN_DOF
    if usable and other.pvalue < plan.mean_level:
        return plan
    support = (
        f"that fits them almost as well (its AICc within {SUPPORT:g} of theirs, not taken as "
        "the model)"
        if memory.alternative_fraction > 0
        else f"that fits them better (its AICc below theirs, within {SUPPORT:g} of the best)"
    )
    found = (
        f"the mean test finds a bias (p {test.pvalue:.2g}) under the errors' short-memory "
        f"model, but not under {memory.alternative_name} {support}"
    )
    radius = other.bias_bound(0.0, plan.mean_level)  # the region's reach about its centre
    if usable and radius >= test.bias_bound(0.0, plan.mean_level):
        reason = (
            f"{found} (p {other.pvalue:.2g}); one segment cannot tell the two apart, so the "
            "location is judged under the latter, whose wider confidence region holds "
            "under either (ELT not run)"
        )
        return LocationPlan(plan.block, other, plan.mean_level, None, reason, bias_declined=True)
    reason = (
        f"location untested: {found}; one segment cannot tell the two apart (a longer "
        "segment, or more runs, can)"
    )
    return LocationPlan(plan.block, None, plan.mean_level, None, reason, bias_declined=True)


_MEMORY_BLOCKS = "the errors' memory needs sign blocks of {block} epochs, which"


def memory_residuals(gls, inverse) -> np.ndarray:
    """The whitened errors without their fitted constants: what the memory is fitted on.

    In the frame the model's tests use (the GLS residuals and scores).

    Parameters
    ----------
    gls : GlsResiduals
        The GLS residuals (their ``whitened`` errors and ``mean``).
    inverse : numpy.ndarray, shape (N, d, d)
        The whitening factors the residuals were made with, F_k = Σ_k^{-1/2} per epoch
        (:func:`credcli.engine.linalg.whitening_factors`).

    Returns
    -------
    numpy.ndarray, shape (N, d)
        z_k = F_k e_k less its fitted constants (:func:`credcli.engine.memory.mean_free`).
    """
    z = np.einsum("nij,j->ni", inverse, gls.mean)
    z += gls.whitened
    return mean_free(z, inverse, overwrite=True)


def _slow_memory(scales: TimeScales | None, memory: Memory) -> str | None:
    """The finding of errors slower than the fitted memory explains, or None: at a tested
    averaging time, or over the whole segment (its lowest frequency)."""
    if scales is None:
        return None
    consequence = (
        "errors slower than the segment can resolve may be read as a bias or a wrong scale, "
        "so neither question is answered (a longer segment, or windows of one run, can decide)"
    )
    if scales.failed_at is not None:
        m = scales.failed_at
        i = int(np.flatnonzero(scales.epochs == m)[0])
        return (
            f"slowly varying errors: averaged over {m} epochs they vary "
            f"{scales.observed[i] / scales.predicted[i]:.3g}× as much as the memory fitted on "
            f"this segment explains (p {scales.pvalue:.2g}); {consequence}"
        )
    if scales.lowest_failed:
        return (
            f"slowly varying errors: over the whole segment (its lowest frequency) they vary "
            f"{scales.lowest_ratio:.3g}× as much as the memory fitted on this segment explains "
            f"(p {scales.lowest_pvalue:.2g}), as long memory does; {consequence}"
        )
    return None


MIN_RESOLUTION = 8.0
"""Fewest correlation times a segment must hold to be judged by the memory fitted on it:
an AR fit on a window of a few correlation times sees only the part of the memory that the
window resolves, underestimating τ and calling windows a misfit (docs/measured.md), so
the memory itself is then unknown. A window of a run, judged by the run's model, needs as
many: its spread about its own mean is then mostly the part of the error faster than the
window, and reading the claim's scale from it rests on the model's split of slow and fast
memory within the window, which the run's fit knows least (windows of the development zoo
below N/τ 4: false alarms in 11–32 % of credible windows of several families, measured
when the run's model was first corrected for the windows' centring; docs/measured.md)."""


def window_unresolved(measure: str) -> str:
    """The reason of a window of a run left unjudged for memory it does not resolve, with
    ``measure`` saying which model leaves it how many correlation times.

    Parameters
    ----------
    measure : str
        E.g. "the run's model has τ̂ 20 epochs, which leaves N/τ̂ 2.5".

    Returns
    -------
    str
        The reason.
    """
    return (
        f"memory comparable to the window: {measure}, fewer than {MIN_RESOLUTION:g} "
        "correlation times; the window's spread about its own mean is mostly the error's "
        "faster part, so neither question is answered for the window (the run's own verdict "
        "covers the total error; longer windows can decide)"
    )


def _unresolved_memory(memory: Memory, n: int, window: bool = False) -> str | None:
    """Why a segment (a window of a run judged by the run's model, where ``window``) is too
    short for the memory, or None."""
    tau = float(np.max(memory.variance_ratios))
    if n / tau >= MIN_RESOLUTION:
        return None
    if window:
        return window_unresolved(
            f"the run's model has τ̂ {tau:.3g} epochs, which leaves N/τ̂ {n / tau:.3g}"
        )
    fraction = max(m.fraction for m in memory.series)
    if fraction > 0:
        return (
            f"long memory: a fractional model (d̂ {fraction:.2g}) fits the errors, whose "
            f"mean then varies as much as that of {n / tau:.3g} independent epochs, fewer "
            f"than {MIN_RESOLUTION:g}; neither question is answered (the variance of a mean "
            f"falls as N^(2d−1), so only much longer segments or more runs can decide)"
        )
    return (
        f"memory comparable to the segment: τ̂ {tau:.3g} epochs leaves N/τ̂ {n / tau:.3g}, "
        f"fewer than {MIN_RESOLUTION:g} correlation times, and the true memory may be longer "
        "than the segment shows; neither question is answered (a longer segment, or windows "
        "of one run, can decide)"
    )


NO_FINITE_MEMORY = (
    "no finite memory: the errors cannot be told from a drift, a random walk or a smooth "
    "curve (the dependence model fitted on them has a root on the unit circle, or a "
    "fractional order at the edge of stationarity that no model with a root the segment "
    "settles from fits better), so no average over the segment is shown to settle; "
    "neither question is answered"
)
"""Why a segment whose fitted memory is not finite gets no verdict (:func:`gather`). It
claims no drift: a stationary slow error whose root the segment cannot tell from the unit
circle gets it too (slow + white errors, AR root 0.94 under 80 % white noise, 300 epochs:
3 of 60 credible segments, ``benchmarks/variants.py --set fifth``), as Dickey and Fuller's
test, which cannot reject a unit root there, would have it."""


def _drift_evidence(gls, n: int) -> ModelEvidence:
    """Both questions declined because the segment's memory is not finite
    (:class:`credcli.engine.memory.NoFiniteMemory`)."""
    plan = LocationPlan(n, None, 0.0, None, NO_FINITE_MEMORY)
    return ModelEvidence(untested_scale(gls), NO_FINITE_MEMORY, None, plan)


def _declined(ev: ModelEvidence, reason: str) -> ModelEvidence:
    """``ev`` with both questions declined for ``reason``."""
    plan = LocationPlan(ev.plan.block, None, 0.0, None, None)
    return ModelEvidence(ev.scale, reason, None, plan)


WHITE_REFIT_LEVEL = 0.05
"""Level at which the time scales of errors taken as independent (BIC took no memory)
reject them, so that the sieve is fitted again as on a screened segment
(:func:`white_refit`): the rule's α; on independent errors about 4 % of the segments BIC
takes as white are fitted again (the check is Bonferroni's, conservative)."""


def white_refit(
    memory: Memory, residuals: np.ndarray, q: np.ndarray, scales: TimeScales
) -> Memory | None:
    """The sieve fitted again as on a screened segment (AICc's order, at least AR(1), its
    estimation error bootstrapped; :func:`credcli.engine.memory.fit_memory`), where BIC
    took no memory but the variance at longer averaging times rejects independent errors
    at :data:`WHITE_REFIT_LEVEL`; None otherwise.

    Weak memory that lasts escapes BIC on hundreds of epochs: an ARMA(1, 1) with nearly
    cancelling roots (0.8 and −0.7: lag-1 autocorrelation 0.1, τ 2.25) was taken as
    independent on 300 epochs, and then 6 of 60 credible segments got a misfit's label (4
    after the refit) and the time scales declined both questions on 6 more (none after),
    where the memory, once fitted, decides them (docs/measured.md).

    Parameters
    ----------
    memory : Memory
        The model fitted on ``residuals``.
    residuals : numpy.ndarray, shape (N, d)
        The mean-free whitened residuals (:func:`memory_residuals`).
    q : numpy.ndarray, shape (N,)
        Their squared norms.
    scales : TimeScales
        ``memory``'s check at every averaging time (:func:`time_scales`).

    Returns
    -------
    Memory or None
        The model fitted again, with its long-memory alternatives
        (:func:`credcli.engine.longmemory.with_long_memory`), or None.

    Raises
    ------
    NoFiniteMemory
        Where the model fitted again has no finite memory.
    """
    if not memory.white or scales.pvalue is None or not scales.pvalue < WHITE_REFIT_LEVEL:
        return None
    return with_long_memory(fit_memory(residuals, q, screened=True), residuals)


def segment_memory(gls, inverse, s, residuals=None) -> tuple[Memory, np.ndarray]:
    """The dependence model fitted on one segment (or run), and the residuals it was
    fitted on, for its check at every averaging time (:func:`time_scales`), which the
    caller makes once the per-epoch inverses are freed (a long segment's peak memory).

    Below :data:`SCREENED_BELOW` epochs the sieve is also told of memory that the lag-1
    autocorrelation of the whitened errors ``s`` shows, centred or about zero, at
    SCREENING_LEVEL (a slow excursion moves a window's mean and hides from the centred
    one), read along their principal directions
    (:func:`credcli.engine.memory.principal_directions`), not the log's axes: the same
    errors in a rotated frame are screened alike (``benchmarks/frame.py``).

    Parameters
    ----------
    gls : GlsResiduals
        The segment's GLS residuals (the model is fitted on
        :func:`memory_residuals` and their ``q``).
    inverse : numpy.ndarray, shape (N, d, d)
        The whitening factors the GLS residuals were made with (:func:`memory_residuals`).
    s : numpy.ndarray, shape (N, d), or None
        The whitened errors, for the lag-1 screening (None for a segment of
        :data:`SCREENED_BELOW` epochs or more, which is not screened).
    residuals : numpy.ndarray, shape (N, d), optional
        :func:`memory_residuals` of ``gls`` and ``inverse``, where the caller has made
        them (``inverse`` is not read then).

    Returns
    -------
    memory : Memory
        The fitted model (:func:`credcli.engine.memory.fit_memory`).
    residuals : numpy.ndarray, shape (N, d)
        The mean-free whitened residuals it was fitted on (:func:`memory_residuals`).
    """
    n = gls.whitened.shape[0]
    screened = False
    if n < SCREENED_BELOW:
        along = s @ principal_directions(s)
        screened = correlation.serially_dependent(
            correlation.autocorrelation(along), n, correlation.SCREENING_LEVEL
        ) or correlation.serially_dependent(
            correlation.autocorrelation(along, about_zero=True), n, correlation.SCREENING_LEVEL
        )
    if residuals is None:
        residuals = memory_residuals(gls, inverse)
    return with_long_memory(fit_memory(residuals, gls.q, screened=screened), residuals), residuals


def segment_memory_of(
    residuals: np.ndarray, q: np.ndarray, cover: int | None = None, runs: int = 1
) -> Memory:
    """The dependence model of mean-free whitened residuals and their squares.

    Screened by their own lag-1 autocorrelation at SCREENING_LEVEL, whatever their length
    (unlike :func:`segment_memory`).

    Parameters
    ----------
    residuals : numpy.ndarray, shape (N, d)
        Mean-free whitened residuals, ``runs`` equal runs one after the other.
    q : numpy.ndarray, shape (N,)
        Their squares summed over components (centred NEES).
    cover : int, optional
        The longest window the model will judge (:func:`credcli.engine.memory.fit_memory`).
    runs : int, default 1
        The runs pooled: one model, each run centred on its own mean
        (:func:`credcli.engine.memory.fit_memory`; no long-memory candidates).

    Returns
    -------
    Memory
        The fitted model (:func:`credcli.engine.memory.fit_memory`).
    """
    n = residuals.shape[0]
    screened = correlation.serially_dependent(
        correlation.autocorrelation(residuals), n, correlation.SCREENING_LEVEL
    )
    memory = fit_memory(residuals, q, runs=runs, screened=screened, cover=cover)
    return with_long_memory(memory, residuals)
