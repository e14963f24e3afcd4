"""The unified diagnosis (Algorithm 1) and the single-metric baselines of Table II."""

from __future__ import annotations

import functools
import math
import zlib
from dataclasses import dataclass, field, replace

import numpy as np
from scipy import special

from credcli.engine import batches, dependence, episodes, evidence, linalg, metrics, rules, timing
from credcli.engine.config import (  # noqa: F401 (the names of a diagnosis, re-exported)
    AUTO,
    DEFAULT_MAX_EPOCHS,
    DIAGNOSIS_LABELS,
    LABEL_ALIASES,
    LOCATION_CONDITIONS,
    MAX_FLIPS,
    MIN_ELT_EPOCHS,
    DiagnosisConfig,
    Label,
    MetricsLevel,
    Question,
    SlowErrors,
    SrdForm,
    Variant,
    given_config,
    parse_label,
)
from credcli.engine.elt import ELTResult, whiten
from credcli.engine.evidence import ks_chi2_pvalue  # noqa: F401 (re-exported)
from credcli.engine.memory import Memory, NoFiniteMemory, TimeScales, time_scales
from credcli.engine.rng import RngLike, as_generator
from credcli.engine.rules import nci_baseline, nees_baseline  # noqa: F401 (re-exported)
from credcli.engine.scale import (
    DirectionScales,
    ScaleTest,
    gls_residuals,
    slow_offset_pvalue,
    untested_scale,
)
from credcli.engine.timing import TimeOffset
from credcli.engine.whiteness import Whiteness, innovation_levels, portmanteau
from credcli.errors import CredcliError
from credcli.logid import LogId


@dataclass(frozen=True)
class BlockScale:
    """The scale factor of one named block of the state (:func:`block_scales`).

    Its marginal errors against its block of the claimed covariance, with its interval at
    the scale level shared among the blocks (Bonferroni).

    Attributes
    ----------
    name : str
        The block's name (pose: position, orientation).
    indices : tuple of int
        The state components of the block.
    factor : float
        κ̂ of the block.
    low, high : float
        Its interval; NaN when the block's scale cannot be tested.
    """

    name: str
    indices: tuple[int, ...]
    factor: float
    low: float
    high: float


@dataclass(frozen=True, slots=True)
class Diagnosis:
    """Result of Algorithm 1 on one segment, with every intermediate number.

    Frozen; made by [credcli.diagnose][credcli.api.diagnose] and, per segment, by
    [credcli.diagnose_log][credcli.api.diagnose_log]. A number that was not computed is
    None.

    Attributes
    ----------
    label : Label
        The verdict ([Label][credcli.engine.config.Label]).
    n, dim : int
        Epochs N and state dimension d of the segment.
    elt : ELTResult or None
        The empirical location test (Section III-A); unpacks as ``statistic, pvalue``.
    smm_detected : bool or None
        Whether the location question found a misfit (the paper's SMM).
    nci, nci_centered : float or None
        NCI (Eq. (4)) of the errors, and of the errors less their mean (Section III-C).
    anees : float or None
        Mean NEES / d.
    ks_pvalue : float or None
        Two-sided Kolmogorov–Smirnov p-value of the NEES values against χ²_d (the ``ks``
        variant).
    nees_label, nci_label : Label or None
        The single-metric baselines of Table II (``credcli.nees_baseline``,
        ``credcli.nci_baseline``).
    scores : Probes or None
        The mean NLL/ES of the claimed predictive N(x̂, sΣ̂) at s = 1/c, 1, c.
    probes : Probes or None
        Those of the centred predictive F̃ (Eq. (18)) with the SRDs (19).
    scale : ScaleTest or None
        The scale test: κ̂ (``scale_factor``), its interval, the GLS mean ``bias``.
    block_length : int or None
        Epochs per ELT sign block.
    effective_n : float or None
        N over the largest variance ratio of the whitened errors (their memory).
    autocorrelation : float or None
        The largest lag-1 autocorrelation of the whitened error components.
    reason : str or None
        Why a question was left unanswered, or why the data are insufficient.
    config : DiagnosisConfig
        The settings of the diagnosis.
    mean_test : MeanTest or None
        The GLS mean test (calibrated rule).
    untested : tuple of Question
        The questions (scale, location) the data could not answer.
    directions : DirectionScales or None
        The scale factor per principal direction (calibrated, d > 1).
    by_direction : bool
        Whether the noise label comes from the directions (mixed, anisotropic).
    blocks : tuple of BlockScale
        The scale factor per named block of the state (pose: position, orientation).
    memory : Memory or None
        The dependence model used.
    memory_source : str or None
        ``"segment"`` (fitted here) or ``"run"`` (the whole run's).
    time_scales : TimeScales or None
        The variance by averaging time.
    findings : tuple of str
        What the data show beside the label (slow errors, bursts, a divergence, ...).
    time_offset : TimeOffset or None
        A lag of the estimate that explains the misfit.
    accuracy : Accuracy or None
        RMSE, mean, median and max error (evo's figures), beside the credibility.

    Examples
    --------
    >>> from credcli import diagnose
    >>> e = np.random.default_rng(0).standard_normal((400, 2)) * 2.0
    >>> d = diagnose(e, np.eye(2), seed=0)
    >>> d
    Diagnosis(label='optimism', n=400, dim=2, scale_factor=4.004)
    >>> str(d.label), d.partial, round(d.anees, 2)
    ('optimism', False, 4.01)
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
    memory: Memory | None = field(default=None, repr=False)  # the dependence model used
    memory_source: str | None = None  # "segment" (fitted here) or "run" (the whole run's)
    time_scales: TimeScales | None = field(default=None, repr=False)  # variance by averaging time
    findings: tuple[str, ...] = ()  # what the data show beside the label (slow errors, ...)
    time_offset: TimeOffset | None = None  # a lag of the estimate that explains the misfit
    accuracy: metrics.Accuracy | None = None  # RMSE, mean, median, max error (evo's figures)

    @property
    def partial(self) -> bool:
        """Whether one of the two questions was answered and the other was not.

        False for an insufficient-data label (neither was answered).
        """
        return bool(self.untested) and self.label is not Label.INSUFFICIENT

    def __repr__(self) -> str:
        kappa = "" if self.scale is None else f", scale_factor={self.scale.scale_factor:.4g}"
        return f"Diagnosis(label={self.label.value!r}, n={self.n}, dim={self.dim}{kappa})"

    @property
    def elt_statistic(self) -> float | None:
        """T_obs of the ELT, Eq. (13) (``elt.statistic``), or None when it did not run."""
        return None if self.elt is None else self.elt.statistic

    @property
    def elt_pvalue(self) -> float | None:
        """The ELT's p-value, Eq. (16) (``elt.pvalue``), or None when it did not run."""
        return None if self.elt is None else self.elt.pvalue


def segment_seed(seed: int | None, name: str) -> np.random.SeedSequence:
    """Per-segment random stream: a function of the seed and the segment's name only.

    Parameters
    ----------
    seed : int or None
        The run's seed (None: fresh entropy).
    name : str
        The segment's name (its CRC-32 is the spawn key).

    Returns
    -------
    numpy.random.SeedSequence
        The segment's seed sequence, the same for the same seed and name.

    Examples
    --------
    >>> a = np.random.default_rng(segment_seed(0, "cruise")).integers(1 << 30)
    >>> b = np.random.default_rng(segment_seed(0, "cruise")).integers(1 << 30)
    >>> c = np.random.default_rng(segment_seed(0, "turn")).integers(1 << 30)
    >>> bool(a == b), bool(a == c)
    (True, False)
    """
    return np.random.SeedSequence(entropy=seed, spawn_key=(zlib.crc32(name.encode()),))


def diagnose_errors(
    errors: np.ndarray,
    cov: np.ndarray,
    config: DiagnosisConfig | None = None,
    rng: RngLike = None,
    mse: np.ndarray | None = None,
    runs: int = 1,
    memory: Memory | None = None,
) -> Diagnosis:
    """Diagnose one segment of errors with their claimed covariances, by ``config``'s rule.

    Parameters
    ----------
    errors : numpy.ndarray, shape (N, d)
        The errors e_k = x_k − x̂_k ((N,) is d = 1).
    cov : numpy.ndarray, shape (N, d, d)
        The claimed covariances, one per epoch.
    config : DiagnosisConfig, optional
        The settings; default the calibrated variant's defaults.
    rng : int, numpy.random.Generator, numpy.random.SeedSequence or None
        Source of the ELT's sign flips.
    mse : numpy.ndarray, shape (d, d), optional
        The MSE matrix of the NCI, Eq. (4); default estimated from the errors.
    runs : int, default 1
        The segment pools that many independent Monte Carlo runs of N/runs epochs, one
        after the other; the ELT flips each run's errors in their own blocks.
    memory : Memory, optional
        The dependence model of the run the segment is a window of (:func:`run_model`);
        default fitted on the segment where the rule reads one.

    Returns
    -------
    Diagnosis
        The label and every number behind it; insufficient-data for a segment too short
        (``config.min_n(d)``) or whose errors span fewer than d dimensions.

    Raises
    ------
    CredcliError
        For invalid arrays (shapes, non-finite values, a covariance that is not positive
        definite), a singular given ``mse``, or a NEES that overflows.

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> e = rng.normal(size=(200, 2))
    >>> diagnose_errors(e, np.broadcast_to(np.eye(2), (200, 2, 2)), rng=1).label.value
    'credible'
    """
    config = given_config(config)
    errors, cov = linalg.check_errors_cov(errors, cov)
    return _diagnose_checked(errors, cov, config, rng, mse, runs, memory)


def _diagnose_checked(
    errors, cov, config, rng, mse=None, runs=1, memory=None, accuracy=None
) -> Diagnosis:
    """:func:`diagnose_errors` on errors and covariances already validated (once: the
    check is a pass over every covariance); ``accuracy``: the errors' own, where known."""
    gen = as_generator(rng)
    return _diagnose_variants(errors, cov, [config], gen, mse, runs, memory, accuracy)[0]


def _cholesky(cov: np.ndarray) -> np.ndarray:
    """The covariances' Cholesky factors, or the error naming the first that is not
    positive definite (:func:`credcli.engine.linalg.cholesky`)."""
    return linalg.cholesky(cov)


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
    so a variant listed first draws its sign flips exactly as ``diagnose_errors`` (the core
    of [credcli.diagnose][credcli.api.diagnose]) does.

    Parameters
    ----------
    errors : array_like, shape (N, d)
        The errors e_k = x_k − x̂_k ((N,) is d = 1).
    cov : array_like, shape (N, d, d)
        The claimed covariances, one per epoch.
    variants : list of Variant or str
        The decision rules: ``"calibrated"``, ``"paper"``, ``"ks"``.
    config : DiagnosisConfig, optional
        The other settings; the defaults when not given.
    rng : int, numpy.random.Generator, numpy.random.SeedSequence or None
        Source of the ELT's sign flips.

    Returns
    -------
    dict of Variant to Diagnosis
        One diagnosis per variant.

    Raises
    ------
    CredcliError
        For invalid arrays (shapes, non-finite values, a covariance that is not symmetric
        positive definite), naming the argument and the epoch; for a variant that is not
        one of the names of ``Variant`` (naming ``variants``).

    Examples
    --------
    >>> e = np.random.default_rng(1).standard_normal((500, 2)) * 0.5
    >>> cov = np.broadcast_to(np.eye(2), (500, 2, 2))
    >>> found = diagnose_variants(e, cov, ["calibrated", "paper"], rng=0)
    >>> {v.value: d.label.value for v, d in found.items()}
    {'calibrated': 'pessimism', 'paper': 'pessimism'}
    """
    errors, cov = linalg.check_errors_cov(errors, cov)
    try:
        chosen = tuple(Variant(v) for v in variants)
    except ValueError:
        names = ", ".join(v.value for v in Variant)
        raise CredcliError(
            f"variants must name variants among {names}; got {list(variants)!r}", "variants"
        ) from None
    configs = _variant_configs(given_config(config), chosen)
    results = _diagnose_variants(errors, cov, configs, as_generator(rng), None)
    return {c.variant: r for c, r in zip(configs, results)}


@functools.lru_cache(maxsize=16)
def _variant_configs(config: DiagnosisConfig, variants: tuple[Variant, ...]):
    """``config`` with each variant (made and validated once, not per trial of a study;
    a tuple, since every caller shares it)."""
    return tuple(replace(config, variant=v) for v in variants)


def _diagnose_variants(
    errors, cov, configs, gen, mse, runs=1, memory=None, accuracy=None
) -> list[Diagnosis]:
    """Validate, gather the evidence once (:func:`credcli.engine.evidence.gather`), then
    decide by each configuration's rule (:func:`credcli.engine.rules.decide`); the errors'
    accuracy is ``accuracy`` where the caller knows it (the whole log's). The
    Cholesky factors are made as gather's argument, so that gather holds the only reference
    and frees them once it no longer needs them (N × d × d values; CPython 3.11 and later,
    where a call's arguments leave the caller's stack)."""
    n, d = errors.shape
    if n < min(c.min_n(d) for c in configs):
        _cholesky(cov)  # a covariance that is not positive definite is named all the same
        found = [_too_short(n, d, c) for c in configs]
    else:
        try:
            gathered = evidence.gather(errors, cov, _cholesky(cov), configs, gen, mse, runs, memory)
        except evidence.Undecidable as exc:
            gathered = None
            found = [
                Diagnosis(Label.INSUFFICIENT, n, d, reason=exc.reason, config=c) for c in configs
            ]
        if gathered is not None:
            found = [_diagnosis(ev, config) for ev, config in zip(gathered, configs)]
    if accuracy is None and n:
        accuracy = metrics.accuracy(errors)
    return [replace(found_one, accuracy=accuracy) for found_one in found]


def _diagnosis(ev: evidence.Evidence, config: DiagnosisConfig) -> Diagnosis:
    """The Diagnosis of one configuration: its verdict and every number behind it."""
    verdict = rules.decide(ev, config)
    common = {
        "n": ev.n,
        "dim": ev.dim,
        "nci": ev.nci,
        "nci_centered": ev.nci_centered,
        "anees": ev.anees,
        "ks_pvalue": ev.ks_pvalue,
        "nees_label": rules.nees_label(ev.nees_total, ev.n, ev.dim, config.nees_alpha),
        "nci_label": nci_baseline(ev.nci, config.tau_nci),
        "scale": ev.scale,
        "block_length": ev.block_length,
        "effective_n": ev.effective_n,
        "autocorrelation": ev.autocorrelation,
        "config": config,
        "mean_test": ev.mean_test,
        "directions": ev.directions,
        "by_direction": verdict.by_direction,
        "reason": verdict.reason,
        "memory": ev.memory,
        "memory_source": ev.memory_source,
        "time_scales": ev.time_scales,
        # a window judged with its run's model leaves long memory to the run's own segment
        "findings": (memory_findings(ev.memory) if ev.memory_source != "run" else ())
        + episode_findings(ev, verdict, config)
        + slow_offset_findings(ev, verdict.label, config),
    }
    if verdict.label is Label.INSUFFICIENT:
        return Diagnosis(label=Label.INSUFFICIENT, **common)
    return Diagnosis(
        label=verdict.label,
        elt=ev.elt,
        smm_detected=verdict.smm_detected,
        scores=ev.scores,
        probes=ev.probes,
        untested=verdict.untested,
        **common,
    )


def memory_findings(memory) -> tuple[str, ...]:
    """Long memory, where the segment's model found it (:mod:`credcli.engine.longmemory`).

    Parameters
    ----------
    memory : Memory or None
        The segment's dependence model.

    Returns
    -------
    tuple of str
        One sentence naming the largest fractional order d̂ and how the variance of a mean
        falls with its length; empty where every direction has the AR sieve's model.
    """
    if memory is None:
        return ()
    fractions = [m.fraction for m in memory.series]
    largest = max(fractions)
    if largest <= 0:
        return ()
    count = sum(f > 0 for f in fractions)
    return (
        f"long memory: a fractional model (d̂ {largest:.2g}) fits {count} of "
        f"{len(fractions)} directions better than any short-memory one, so the variance of "
        f"a mean of N epochs falls as N^{2 * largest - 1:.2g}, not 1/N: longer segments "
        "settle a bias or a scale more slowly than their length suggests",
    )


def slow_offset_findings(
    ev: evidence.Evidence, label: Label, config: DiagnosisConfig
) -> tuple[str, ...]:
    """A bias that an error slower than the segment explains as well, where it does.

    A bias label holds under the memory fitted on the segment, which sees no error slower
    than the segment: such an error, near one value over its epochs, is an offset too.
    Where one holding part of the claimed covariance (the rest fast) explains the offset
    and the spread about it together at the mean test's level
    (:func:`credcli.engine.scale.slow_offset_pvalue`), the label stands and this finding
    names the other reading with its p-value; only windows of one run, more runs or the
    knowledge that no such error exists (``slow_errors`` excluded) tell the two apart.
    Pessimism with a bias is not looked at here: the rule itself weighs the slow reading
    there, and declines the segment where it holds (:func:`credcli.engine.rules.offset_covered`).

    On a segment shorter than :data:`credcli.engine.rules.SLOW_READING_BELOW` epochs, or
    on a longer one whose errors support a model with more memory under which they hold
    few independent epochs (:func:`credcli.engine.rules.few_under_alternative`), where
    the slow reading fits with a p-value of at least
    :data:`credcli.engine.rules.SLOW_READING_FIT` the rule declines the bias
    (``rules.offset_covered``), so this finding stands beside a bias whose slow reading's
    p-value lies between the mean test's level and that, or beside a longer segment's
    without such an alternative.
    ``slow_errors`` expected declines those too; not by default, measured
    (docs/measured.md): on ``benchmarks/variants.py`` declining every such bias cuts the
    false alarms of slow + white (0.97, 75 %) errors at 50 epochs to 2 of 60 (8 by
    default, 20 without declining), and finds a 1σ bias at N/τ >= 30 in 620 of 1,180
    segments (1,039 by default, 1,055 without); a scale pinned near 1 over a few hundred
    dependent epochs leaves room for a slow part of a sixth of the claim, whose draws
    reach 1σ.

    Parameters
    ----------
    ev : Evidence
        The segment's statistics (scale and mean tests, the memory's source).
    label : Label
        The rule's label.
    config : DiagnosisConfig
        The configuration (``slow_errors``).

    Returns
    -------
    tuple of str
        One sentence, or none: for a label other than ``bias``, a memory not fitted on this
        segment (a window judged with its run's, which holds the run's slow parts), slow
        errors excluded, or an offset the slow reading does not explain.
    """
    test = ev.mean_test
    if (
        label is not Label.BIAS
        or ev.memory_source != "segment"
        or config.slow_errors is SlowErrors.EXCLUDED
        or test is None
        or ev.scale is None
    ):
        return ()
    pvalue, share = slow_offset_pvalue(ev.scale, test, ev.dim)
    if not pvalue >= ev.mean_level:
        return ()
    return (
        f"the bias may be an error slower than the segment instead: one holding "
        f"{1.0 - share:.2g} of the claimed covariance, near one value over the {ev.n} "
        f"epochs, with the rest fast, explains the offset of {ev.scale.bias_mahalanobis:.3g}σ "
        f"and the spread κ̂ {ev.scale.scale_factor:.3g} together (p {pvalue:.2g}, not "
        f"below the mean test's {ev.mean_level:.3g}); windows of one run or more runs tell "
        "the two apart; `slow_errors` expected declines such a bias, and excluded states "
        "that the errors hold no such error",
    )


def episode_findings(ev: evidence.Evidence, verdict, config: DiagnosisConfig) -> tuple[str, ...]:
    """What the NEES does in time (:mod:`credcli.engine.episodes`).

    Parameters
    ----------
    ev : Evidence
        The segment's statistics (divergence, bursts, median NEES).
    verdict : Verdict
        The rule's verdict (whether the scale was decided by the median bound).
    config : DiagnosisConfig
        The configuration (α_S for the median bound).

    Returns
    -------
    tuple of str
        A divergence, the scale decided by the median bound, and the largest bursts (at
        most ``episodes.MAX_BURSTS``, then how many more), each as a sentence.
    """
    out = []
    if ev.divergence is not None:
        out.append(ev.divergence.describe())
    if verdict.by_median:
        bound = episodes.median_bound(ev.dim, config.scale_level)
        out.append(
            f"median NEES {ev.q_median:.3g} above {bound:.3g}, a bound that holds whatever "
            "the errors' memory (Markov): the covariance is too small (scale decided by it)"
        )
    shown = ev.bursts[: episodes.MAX_BURSTS]
    out += [b.describe(ev.dim) for b in shown]
    if len(ev.bursts) > len(shown):
        out.append(f"and {len(ev.bursts) - len(shown)} more burst(s)")
    return tuple(out)


def too_short_batch(
    errors: np.ndarray, cov: np.ndarray, lengths: np.ndarray, config: DiagnosisConfig
) -> list[Diagnosis]:
    """The diagnoses of consecutive segments too short for a verdict, checked and measured
    together.

    A log of 10⁶ one-epoch segments is a few numpy calls, not 10⁶ diagnoses.

    Parameters
    ----------
    errors : numpy.ndarray, shape (N, d)
        The errors of the segments, one after the other (N = Σ ``lengths``).
    cov : numpy.ndarray, shape (N, d, d)
        Their claimed covariances (validated and factored, so that an invalid one is
        still an error).
    lengths : numpy.ndarray of int
        Epochs of each segment, all below ``config.min_n(d)``.
    config : DiagnosisConfig
        The configuration (its ``min_n`` is the reason's figure).

    Returns
    -------
    list of Diagnosis
        One per segment: insufficient-data with the reason, and its accuracy
        (:func:`credcli.engine.metrics.grouped_accuracy`).

    Raises
    ------
    CredcliError
        For invalid arrays, or a covariance that is not positive definite.
    """
    errors, cov = linalg.check_errors_cov(errors, cov)
    _cholesky(cov)
    d = errors.shape[1]
    accuracies = metrics.grouped_accuracy(errors, lengths)
    reasons = {int(n): too_short_reason(int(n), d, config) for n in np.unique(lengths)}
    return [
        Diagnosis(Label.INSUFFICIENT, n, d, reason=reasons[n], config=config, accuracy=accuracy)
        for n, accuracy in zip(lengths.tolist(), accuracies, strict=True)
    ]


def too_short_reason(n: int, d: int, config: DiagnosisConfig) -> str:
    """Why a segment of ``n`` epochs is too short for a verdict.

    Parameters
    ----------
    n, d : int
        The segment's epochs and state dimension.
    config : DiagnosisConfig
        The settings whose minimum (:meth:`DiagnosisConfig.min_n`) it is below.

    Returns
    -------
    str
        The reason an insufficient-data result gives.
    """
    needs = f"min_epochs {config.min_epochs} and d + 2"
    if not config.calibrated:
        needs = f"min_epochs {config.min_epochs}, d + 2, and {config.min_blocks} sign blocks"
    return f"{n} epochs; at least {config.min_n(d)} are needed ({needs})"


def _too_short(n: int, d: int, config: DiagnosisConfig) -> Diagnosis:
    return Diagnosis(
        label=Label.INSUFFICIENT, n=n, dim=d, reason=too_short_reason(n, d, config), config=config
    )


@dataclass(frozen=True, slots=True)
class SegmentDiagnosis:
    """A Diagnosis tied to its segment of a log: one item of a
    [Results][credcli.api.Results].

    Attributes
    ----------
    log : LogId
        Which log ([LogId][credcli.logid.LogId]); ``str(item.log)`` is its name (its
        file, or ``source``), as in messages and records.
    segment : str
        The segment's name.
    t_start, t_end : float or None
        The segment's first and last time stamps (None for a log without time).
    diagnosis : Diagnosis
        The segment's [Diagnosis][credcli.engine.diagnosis.Diagnosis].
    whiteness : Whiteness or None
        The portmanteau test of the innovations (``credcli diagnose --innovations``).
    innovations : bool, default False
        The errors are a filter's innovations (``--innovations``): the segment's record
        has the whiteness keys, None where it is too short for the test (N < d + 5), so
        that every record of such a log has the same keys.

    Examples
    --------
    >>> from credcli import diagnose_log, read_log
    >>> item = diagnose_log(read_log("sample_data/estimator_log.csv"))[0]
    >>> item.segment, str(item.diagnosis.label)
    ('cruise', 'credible')
    """

    log: LogId
    segment: str
    t_start: float | None
    t_end: float | None
    diagnosis: Diagnosis
    whiteness: Whiteness | None = None  # of innovations (--innovations)
    innovations: bool = False

    def verdict(self) -> SegmentVerdict:
        """What a CI check reads of this segment
        ([SegmentVerdict][credcli.engine.diagnosis.SegmentVerdict]).

        Returns
        -------
        SegmentVerdict
            Its log, name, label, untested questions, ELT p-value, NCI and ANEES.
        """
        d = self.diagnosis
        return SegmentVerdict(
            self.log, self.segment, d.label, d.untested, d.elt_pvalue, d.nci, d.anees
        )


@dataclass(frozen=True)
class SegmentVerdict:
    """A segment's verdict and the numbers a CI report gives beside it, without the rest
    of its diagnosis: what ``diagnose --fail-on`` keeps of each segment (about 0.5 kB,
    where a SegmentDiagnosis holds some 10 kB).

    Attributes
    ----------
    log : LogId
        Which log.
    segment : str
        The segment's name.
    label : Label
        Its label.
    untested : tuple of Question
        The questions the label leaves open.
    elt_pvalue, nci, anees : float or None
        Its ELT p-value, NCI (dB) and ANEES, as its Diagnosis has them.
    """

    log: LogId
    segment: str
    label: Label
    untested: tuple[Question, ...]
    elt_pvalue: float | None
    nci: float | None
    anees: float | None

    def verdict(self) -> SegmentVerdict:
        """Itself (as [SegmentDiagnosis.verdict][credcli.engine.diagnosis.SegmentDiagnosis.verdict]
        gives a result's).

        Returns
        -------
        SegmentVerdict
            This verdict.
        """
        return self


def diagnose_segments(
    log,
    segments,
    config: DiagnosisConfig | None = None,
    seed: int | None = 0,
    progress=None,
) -> list[SegmentDiagnosis]:
    """Run Algorithm 1 on every segment of an EstimatorLog.

    Each segment's sign flips come from :func:`segment_seed` (the seed and the segment's
    name), so a segment's result does not depend on the other segments. Windows of one
    run (``segment.window``) are judged against the run's dependence model
    (:func:`run_model`), whose findings go to the run's own segment.

    Parameters
    ----------
    log : EstimatorLog
        The log (its errors, covariances, truth and time, id and state blocks).
    segments : list of Segment
        The segments to diagnose, in output order.
    config : DiagnosisConfig, optional
        The settings; default the calibrated variant's defaults.
    seed : int or None, default 0
        The seed of every segment's sign flips (:func:`segment_seed`).
    progress : callable, optional
        Called as ``progress(done, total)`` after each segment.

    Returns
    -------
    list of SegmentDiagnosis
        One per segment, in the order of ``segments``.

    Raises
    ------
    CredcliError
        For an invalid segment, naming the log and the segment (:func:`diagnose_segment`).
    """
    config = given_config(config)
    errors = log.errors
    windows = [seg.index for seg in segments if getattr(seg, "window", False)]
    run = run_model(errors, log.cov, windows, config) if windows else RunModel(None)
    moving = timing.motion(log.truth, log.time)
    out = []
    for done, seg in enumerate(segments, start=1):
        window = getattr(seg, "window", False)
        diag = diagnose_segment(
            errors[seg.index],
            log.cov[seg.index],
            config,
            seed,
            seg.name,
            log.id,
            blocks=getattr(log, "blocks", ()),
            memory=run.memory if window else None,
            findings=run.findings if windows and not window else (),  # the run's own
            declined=run.window_reason if window else None,
            motion=None if moving is None else moving.part(linalg.as_slice(seg.index)),
        )
        out.append(SegmentDiagnosis(log.id, seg.name, seg.t_start, seg.t_end, diag))
        if progress is not None:
            progress(done, len(segments))
    return out


def innovation_whiteness(
    errors: np.ndarray, cov: np.ndarray, level: float | None = None
) -> Whiteness | None:
    """The portmanteau test of innovations whitened by their claimed covariance.

    Parameters
    ----------
    errors : numpy.ndarray, shape (N, d)
        The innovations.
    cov : numpy.ndarray, shape (N, d, d)
        Their claimed covariances.
    level : float, optional
        The test's share of α (:func:`credcli.engine.whiteness.innovation_levels`);
        None leaves the result's level NaN.

    Returns
    -------
    Whiteness or None
        The test, or None for a segment too short for one lag (N < d + 5), or whose
        innovations span fewer than d dimensions (their sample covariance Ĉ_0 singular:
        constant or collinear innovations, which the two questions then decline with
        their reason).
    """
    if errors.shape[0] < 5 + errors.shape[1]:
        return None
    try:
        white = portmanteau(whiten(errors, cov))
    except np.linalg.LinAlgError:
        return None
    return white if level is None else replace(white, level=level)


def innovation_config(config: DiagnosisConfig) -> tuple[DiagnosisConfig, float]:
    """The configuration of innovations' two questions, and the whiteness test's level.

    Under a right filter the innovations are white (Mehra 1970, IEEE TAC 15(2)): their
    null is independent epochs, so the questions are tested with single-epoch signs and
    the exact χ² and Hotelling references (``block_length`` 1), and correlation in time is
    a finding of its own, the portmanteau test, inside the α split
    (:func:`credcli.engine.whiteness.innovation_levels`), not a reason to decline. The
    paper and ks variants keep their own level and take the whiteness test at α.

    Parameters
    ----------
    config : DiagnosisConfig
        The configuration for estimation errors.

    Returns
    -------
    config : DiagnosisConfig
        For the calibrated rule, ``block_length`` 1 and α the two questions' Šidák share;
        else ``config`` unchanged.
    level : float
        The whiteness test's level: its Šidák share of α (calibrated), else α.

    References
    ----------
    R. K. Mehra, "On the identification of variances and adaptive Kalman filtering",
    IEEE Trans. Autom. Control 15(2), 1970.
    """
    if not config.calibrated:
        return config, config.alpha
    pair, each = innovation_levels(config.alpha)
    return replace(config, block_length=1, alpha=pair), each


@dataclass(frozen=True)
class RunModel:
    """What a run tells its windows (:func:`run_model`).

    Attributes
    ----------
    memory : Memory or None
        The dependence model of the errors within a window, fitted once on all windows
        (None: no model, the windows are diagnosed as segments).
    findings : tuple of str, default ()
        The run's findings (a slowly varying error between windows).
    unresolved : str or None, default None
        Why no window of the run is judged though the run is homogeneous: the whole run's
        own model holds more memory within a window's length than the window resolves
        (:func:`run_model`).
    """

    memory: Memory | None
    findings: tuple[str, ...] = ()
    unresolved: str | None = None

    @property
    def window_reason(self) -> str | None:
        """Why a window of this run gets no label of its own: the errors vary slowly
        between windows, so a window cannot tell a bias from that slow error, and its
        spread is only the fast part; or the whole run's memory is comparable to a window
        (:attr:`unresolved`); None otherwise."""
        if not self.findings:
            return self.unresolved
        return (
            "no window verdict: the run's errors vary slowly between windows, or its conditions "
            "change (see the run's finding); a window cannot tell a bias from that slow error, "
            "and its spread is the fast part only: the run's own verdict covers the total "
            "error, and a segment column can name windows of different conditions"
        )


HOMOGENEITY_LEVEL = 0.01
"""Level of the test that the windows' means vary no more than the memory within a window
explains (:func:`run_model`)."""


def _homogeneity(memory: Memory, means: np.ndarray, centred: np.ndarray, sizes) -> tuple:
    """The statistic of :func:`run_model`'s homogeneity test and its degrees of freedom
    d(W − 1) (0: no test).

    Along each principal direction i, the W window means ȳ_wi (``means`` rotated) are
    weighed by n_w/(κ̂_i v_i(n_w)), v_i(n) the model's :meth:`~credcli.engine.memory.
    SeriesMemory.mean_ratio`, about their weighted centre. κ̂_i is one scale for the run:
    Σ_w Σ_k (y_wki − ȳ_wi)² / Σ_w (n_w − v_i(n_w)), the expectation of a window's sum of
    squares about its own mean being κ_i (n_w − v_i(n_w)) under the model. It pools every
    window's spread (Σ n_w epochs), so the statistic is χ²_{d(W−1)} up to that estimate's
    error. A window's mean divided by its own spread instead is a t statistic of n_w − 1
    degrees of freedom or fewer: its square has mean n_w/(n_w − 3) times a χ²₁'s (1.43 for
    windows of 10 epochs) and a heavier tail: one run of 200,000 independent epochs in
    windows of 10, 50 and 200 epochs was found to vary slowly (p 0, 1e-9, 0.005).

    Where the model's memory leaves the windows' spread no epochs to read
    (Σ_w (n_w − v_i(n_w)) <= 0 along some direction), there is no test.
    """
    rotated = means @ memory.directions
    sizes = np.asarray(sizes)
    ratios = np.array([[m.mean_ratio(int(k)) for m in memory.series] for k in sizes])
    within = np.sum(sizes[:, None] - ratios, axis=0)
    if not np.all(within > 0):
        return 0.0, 0
    scale = np.sum((centred @ memory.directions) ** 2, axis=0) / within
    if not np.all(scale > 0):
        return 0.0, 0
    weights = sizes[:, None] / (ratios * scale)
    centre = np.sum(rotated * weights, axis=0) / np.sum(weights, axis=0)
    statistic = float(np.sum(weights * (rotated - centre) ** 2))
    return statistic, means.shape[1] * (len(sizes) - 1)


def run_model(errors: np.ndarray, cov: np.ndarray, windows, config: DiagnosisConfig) -> RunModel:
    r"""The dependence model against which the windows of one run are judged, and the run's
    homogeneity finding.

    The model is fitted once on every window (:func:`credcli.engine.evidence.segment_memory_of`
    on the windows' whitened errors as runs of one length, the median window's, each
    centred on its own mean: :func:`credcli.engine.memory.fit_memory` with ``runs``): the
    memory within a window, estimated from the whole run, so that short windows are judged
    with a model they could not fit themselves, and no window's bias or scale reads as
    memory. The pooled fit of short centred runs has less memory than the runs (Nickell
    1981): the model is corrected for it (:func:`credcli.engine.memory.centring_corrected`).
    Fitted on the windows one after the other as one series, each divided by its own root
    mean square, an AR(1) with φ = 0.5 in 40 windows of 10 epochs got τ̂ 1.7 for 3, and
    in 10,000 windows of 100 epochs (φ = 0.7) v_100 2.1 for 5.5; now 5.6.

    Homogeneity (:func:`_homogeneity`): under that model the window means ȳ_w (principal
    directions) have variance κ_i v_i(n_w)/n_w, κ_i the run's scale along direction i, so
    :math:`\sum_w \sum_i n_w (\bar y_{wi} - \bar y_i)^2 / (\hat\kappa_i v_i(n_w))` is
    about :math:`\chi^2_{d(W-1)}` (adjacent windows' means taken as independent), κ̂_i
    from the spread of every window about its own mean; divided by d(W − 1) it is referred
    to F(d(W − 1), ν), ν the model's least certain direction's degrees of freedom (χ² for
    a model known, white), since v_i(n) are estimates. A rejection is the finding of a
    slowly varying error (or conditions that change between windows): each window's verdict
    then describes the errors about that window's mean, and the run's own verdict the total.

    Parameters
    ----------
    errors : numpy.ndarray, shape (N, d)
        The whole run's errors.
    cov : numpy.ndarray, shape (N, d, d)
        Their claimed covariances.
    windows : list of numpy.ndarray
        The epochs (indices into the run) of each window.
    config : DiagnosisConfig
        The configuration; only a rule that reads the dependence model
        (:func:`credcli.engine.evidence.reads_memory`) gets one.

    Returns
    -------
    RunModel
        The model and the homogeneity finding (at :data:`HOMOGENEITY_LEVEL`); no model
        when the rule reads none or fewer than two windows are long enough.

    Raises
    ------
    CredcliError
        For invalid arrays, or a covariance that is not positive definite.
    """
    if not evidence.reads_memory(config, 1) or len(windows) < 2:
        return RunModel(None)
    errors, cov = linalg.check_errors_cov(errors, cov)
    d = errors.shape[1]
    _cholesky(cov)  # positive definite, or the error naming the epoch
    inverse = linalg.whitening_factors(cov)
    gls = gls_residuals(errors, None, inverse)
    z = evidence.memory_residuals(gls, inverse)
    parts, means, sizes = [], [], []
    for index in windows:
        w = z[index]
        if w.shape[0] < max(config.min_n(d), 3):
            continue
        centre = w.mean(axis=0)
        parts.append(w - centre)
        means.append(centre)
        sizes.append(w.shape[0])
    if len(parts) < 2:
        return RunModel(None)
    # the model is fitted on runs of one length, the median window's: each window at least
    # that long gives its first epochs, centred again by the fit
    length = sorted(sizes)[len(sizes) // 2]
    runs = [p[:length] for p in parts if p.shape[0] >= length]
    pooled = np.concatenate(runs)
    try:
        memory = evidence.segment_memory_of(
            pooled, np.einsum("ni,ni->n", pooled, pooled), cover=max(sizes), runs=len(runs)
        )
    except NoFiniteMemory:  # each window is then judged (and declined) as a segment
        return RunModel(None)
    memory = replace(memory, segments=1)  # each window reads it as one series' memory
    statistic, dof = _homogeneity(memory, np.asarray(means), np.concatenate(parts), sizes)
    if not dof:
        return RunModel(memory)
    # the model's v_i(n) are estimates: F(d(W − 1), ν), ν its least certain direction's
    nu = min(m.dof for m in memory.series)
    if math.isfinite(nu):
        pvalue = float(special.fdtrc(dof, nu, statistic / dof))
    else:
        pvalue = float(special.chdtrc(dof, statistic))
    findings = ()
    if pvalue < HOMOGENEITY_LEVEL:
        findings = (
            f"slowly varying error: the {len(parts)} windows' means vary "
            f"{statistic / dof:.3g}× as much as the memory within a window explains "
            f"(p {pvalue:.2g}): a slowly varying error, or conditions that change between "
            "windows; this verdict of the whole run covers the total error",
        )
    # where the finding declines the windows already, the whole run's fit is not needed
    unresolved = None if findings else _whole_run_unresolved(z, length)
    return RunModel(memory, findings, unresolved)


def _whole_run_unresolved(z: np.ndarray, length: int) -> str | None:
    """Why windows of ``length`` epochs are too short for the memory of the whole run
    whose mean-free whitened residuals are ``z``, or None.

    The windows' own model sees what a window resolves: long memory (a fractional model,
    whose variance of a mean falls as N^(2d−1)) and a slow part hide in windows that are
    short against them, and the centring correction cannot bring back what no window
    shows. The whole run's own model (:func:`credcli.engine.evidence.segment_memory_of`,
    long-memory candidates included) is fitted on every epoch at once; where its v(n) at
    the window length leaves fewer than :data:`credcli.engine.evidence.MIN_RESOLUTION`
    correlation times, or it has no finite memory, no window is judged. Measured on the
    development zoo's windows of 50 epochs of ARFIMA d 0.3 errors (N/v_N 1.1): without
    this, false alarms in 8 % of credible windows (docs/measured.md).
    """
    try:
        whole = evidence.segment_memory_of(z, np.einsum("ni,ni->n", z, z), cover=length)
    except NoFiniteMemory:
        return (
            "memory comparable to the window: the whole run's errors have no finite memory "
            "(a drift, a random walk, or long memory at the edge of stationarity); no window "
            "is judged, and the run's own verdict says why"
        )
    ratio = max(m.mean_ratio(length) for m in whole.series)
    if length / ratio >= evidence.MIN_RESOLUTION:
        return None
    return evidence.window_unresolved(
        f"the whole run's model has v {ratio:.3g} over a window of {length} epochs, which "
        f"leaves N/v {length / ratio:.3g}"
    )


def diagnose_segment(
    errors: np.ndarray,
    cov: np.ndarray,
    config: DiagnosisConfig,
    seed: int | None,
    name: str,
    source: LogId | str = "<memory>",
    runs: int = 1,
    blocks: tuple = (),
    memory: Memory | None = None,
    findings: tuple[str, ...] = (),
    declined: str | None = None,
    motion: timing.Motion | np.ndarray | None = None,
    fitted_mean: str | None = None,
    accuracy: metrics.Accuracy | None = None,
) -> Diagnosis:
    """Diagnose one named segment of a log, its sign flips from :func:`segment_seed`.

    Parameters
    ----------
    errors : numpy.ndarray, shape (N, d)
        The segment's errors.
    cov : numpy.ndarray, shape (N, d, d)
        Their claimed covariances.
    config : DiagnosisConfig
        The settings.
    seed : int or None
        The seed of the sign flips, with ``name``.
    name : str
        The segment's name.
    source : LogId or str, default "<memory>"
        The log, for error messages.
    runs : int, default 1
        See :func:`diagnose_errors`.
    blocks : tuple, default ()
        Named blocks of the state, ``(name, indices)`` pairs
        (:data:`credcli.engine.lie.STATE_BLOCKS`), whose scale factors the calibrated rule
        reports beside the overall one (:func:`block_scales`).
    memory : Memory, optional
        The dependence model of the run the segment is a window of (:func:`run_model`).
    findings : tuple of str, default ()
        The run's findings, for the run's own segment.
    declined : str, optional
        Why a window of a run gets no label of its own (:attr:`RunModel.window_reason`):
        the numbers stay, the label is insufficient-data.
    motion : Motion or numpy.ndarray, optional
        The segment's truth and time stamps, or its velocities themselves
        (:meth:`credcli.engine.timing.Motion.part`), to look for a time offset that
        explains a misfit (:func:`credcli.engine.timing.time_offset`), named first among
        the findings; the velocity is taken only then.
    fitted_mean : str, optional
        Why the errors' mean is no evidence (an alignment fitted it), which leaves the
        location question open (:func:`without_location`).
    accuracy : Accuracy, optional
        The accuracy of ``errors``, where it is known already (the whole log's, made for
        its summary); None: computed here.

    Returns
    -------
    Diagnosis
        The segment's diagnosis.

    Raises
    ------
    CredcliError
        For invalid arrays or settings, the message prefixed with the log and the
        segment's name.
    """
    try:
        errors, cov = linalg.check_errors_cov(errors, cov)
        n, d = errors.shape
        if n < config.min_n(d):  # checked as diagnose_errors checks, without a random stream
            return too_short_batch(errors, cov, np.array([n]), config)[0]
        diag = _diagnose_checked(
            errors, cov, config, segment_seed(seed, name), None, runs, memory, accuracy
        )
        if blocks and config.calibrated:
            diag = replace(diag, blocks=block_scales(errors, cov, blocks, config, runs))
        if findings:
            diag = replace(diag, findings=diag.findings + findings)
        if motion is not None and diag.label.conditions and declined is None:
            velocity = motion.velocity() if isinstance(motion, timing.Motion) else motion
            offset = timing.time_offset(errors, cov, velocity, memory_ratio(diag))
            if offset is not None:
                diag = replace(
                    diag, time_offset=offset, findings=(offset.describe(),) + diag.findings
                )
        if fitted_mean is not None:
            diag = without_location(diag, fitted_mean)
        if declined is not None:  # the numbers stay; the label claims no misfit
            diag = replace(
                diag, label=Label.INSUFFICIENT, reason=declined, untested=(), smm_detected=None
            )
        return diag
    except CredcliError as exc:
        raise CredcliError(f"{source}: segment '{name}': {exc.message}") from exc


def without_location(diag: Diagnosis, reason: str) -> Diagnosis:
    """``diag`` with its location question left open, ``reason`` saying why.

    For errors whose mean was fitted away before they reached the test, so that "no bias"
    would be a claim the data cannot make.

    Parameters
    ----------
    diag : Diagnosis
        The diagnosis.
    reason : str
        Why the location question is open (appended to ``diag.reason``).

    Returns
    -------
    Diagnosis
        ``diag`` unchanged when it is insufficient-data or its location is already open;
        else its noise condition alone (or insufficient-data, with the scale question open
        too), the location untested and ``smm_detected`` None.
    """
    if diag.label is Label.INSUFFICIENT or Question.LOCATION in diag.untested:
        return diag
    noise = next(iter(diag.label.conditions - frozenset(LOCATION_CONDITIONS)), None)
    untested = (*diag.untested, Question.LOCATION)
    label = Label.INSUFFICIENT if Question.SCALE in untested else Label.compose(noise, None)
    reason = "; ".join(r for r in (diag.reason, reason) if r)
    return replace(diag, label=label, untested=untested, reason=reason, smm_detected=None)


def memory_ratio(diag: Diagnosis) -> float:
    """τ, the largest variance ratio of a diagnosis's errors.

    Parameters
    ----------
    diag : Diagnosis
        The diagnosis.

    Returns
    -------
    float
        Its memory model's largest τ, or N over the lag-1 route's effective N; N where the
        errors have no finite memory (effective N 0: the segment is worth one epoch); 1
        when it has neither.
    """
    if diag.memory is not None:
        return float(np.max(diag.memory.variance_ratios))
    if diag.effective_n is not None and diag.effective_n <= 0:
        return float(diag.n)
    if diag.effective_n:
        return diag.n / diag.effective_n
    return 1.0


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

    Parameters
    ----------
    errors : numpy.ndarray, shape (N, d)
        The segment's errors.
    cov : numpy.ndarray, shape (N, d, d)
        Their claimed covariances.
    blocks : tuple
        ``(name, indices)`` pairs, one per named block of the state.
    config : DiagnosisConfig
        The configuration (calibrated).
    runs : int, default 1
        Equal Monte Carlo runs pooled in the segment.

    Returns
    -------
    tuple of BlockScale
        One per block, in the order of ``blocks``.

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
        _cholesky(c)  # positive definite, or the error naming the epoch
        inverse = linalg.whitening_factors(c)
        gls = gls_residuals(e, None, inverse)
        s = linalg.whitened_by(inverse, e)
        if evidence.reads_memory(config, runs):  # the block's memory, fitted as a segment's
            try:
                memory, residuals = evidence.segment_memory(gls, inverse, s)
                if memory.white:  # the time scales only where they can refit (white_refit)
                    scales = time_scales(residuals, memory)
                    memory = evidence.white_refit(memory, residuals, gls.q, scales) or memory
            except NoFiniteMemory:
                test = untested_scale(gls)  # no interval: the block's errors drift
            else:
                test = evidence.memory_evidence(
                    gls, inverse, config, memory, e.shape[0], level=level
                ).scale
        else:
            dep = dependence.serial_dependence(s, gls.q)
            batched = evidence.refers_to_batches(config, dep.dependent)
            test, _ = evidence.scale_evidence(gls, config, dep.tau, dep.tau_q, batched, level, runs)
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
