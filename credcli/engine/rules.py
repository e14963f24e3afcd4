"""The rules: decide(evidence, config) -> a verdict, for the calibrated, ks and paper
variants. A rule reads only the typed :class:`credcli.engine.evidence.Evidence` of a segment
and its configuration, so it can be tested on evidence written by hand."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import special

from credcli.engine import episodes, metrics
from credcli.engine.config import DiagnosisConfig, Label, Question, Variant
from credcli.engine.evidence import Evidence
from credcli.engine.scale import DirectionScales, ScaleTest


@dataclass(frozen=True)
class Verdict:
    """What a rule decides on one segment's evidence: the label, which questions it left
    untested, why, whether the location test found SMM (None: untested), and whether the
    noise part comes from the principal directions."""

    label: Label
    untested: tuple[Question, ...]
    reason: str | None
    smm_detected: bool | None
    by_direction: bool
    by_median: bool = False  # the scale decided by the dependence-free median bound


def decide(evidence: Evidence, config: DiagnosisConfig) -> Verdict:
    """The label of one segment from its evidence, by ``config``'s variant.

    calibrated: the scale test at α_S with the relevance floor τ and the equivalence margin
    :data:`CREDIBLE_FACTOR` (or the principal directions where they disagree), and the
    location condition of the GLS mean test and the ELT at their shares of α_L: bias,
    asymmetric, or smm where no mean test ran. paper and ks: Algorithm 1
    (lines 2–23), SMM from the ELT.
    """
    scale_reason = evidence.scale_reason
    noise_override = None
    by_median = False
    if config.calibrated and scale_reason is None:
        scale_reason = inconclusive_scale(evidence.scale, config)
        directions = evidence.directions
        if directions is not None and mixed(directions, config):
            noise_override = direction_noise(directions, config)
            if noise_override is not None:
                scale_reason = None  # decided along a principal direction
    declined = scale_reason
    if config.calibrated and scale_reason is not None and median_optimism(evidence, config):
        scale_reason, by_median = None, True  # too large for any memory to explain
    location_reason = evidence.location_reason
    location_open = evidence.mean_test is None and evidence.elt_level is None
    if config.calibrated and not location_open and not evidence.location_rejected:
        unresolved = inconclusive_location(evidence)
        if unresolved is not None:
            location_open = True
            location_reason = "; ".join(r for r in (unresolved, location_reason) if r)
    untested = tuple(
        q
        for q, missing in (
            (Question.SCALE, scale_reason is not None),
            (Question.LOCATION, location_open),
        )
        if missing
    )
    if Question.LOCATION in untested and location_reason is None and scale_reason is None:
        location_reason = declined  # one reason declined both; the scale was decided after
    reason = "; ".join(r for r in (scale_reason, location_reason) if r) or None
    by_direction = noise_override is not None
    if by_median:
        noise_override = "optimism"
    if len(untested) == 2 or (not config.calibrated and evidence.elt_level is None):
        return Verdict(Label.INSUFFICIENT, (), reason, None, by_direction)
    smm = evidence.location_rejected
    if config.calibrated and noise_override is not None:
        label = Label.compose(noise_override, evidence.location_condition)
    elif config.calibrated:
        scale = None if scale_reason else evidence.scale
        label = calibrated_label(scale, evidence.location_condition, config)
    elif smm:
        label = label_with_smm(evidence.nci_centered, evidence.probes, config.tau_nci)
    else:
        label = label_without_smm(evidence.nci, evidence.ks_pvalue, config)
    located = None if Question.LOCATION in untested else smm
    return Verdict(label, untested, reason, located, by_direction, by_median)


def median_optimism(evidence: Evidence, config: DiagnosisConfig) -> bool:
    """Whether the median GLS-centred NEES is above the dependence-free bound at α_S/2
    (:func:`credcli.engine.episodes.median_bound`): the covariance is too small whatever
    the errors' memory, where the memory-adjusted scale test could not decide (a diverging
    filter, whose squared errors' variance ratio leaves no degrees of freedom)."""
    if evidence.q_median is None:
        return False
    return evidence.q_median > episodes.median_bound(evidence.dim, config.scale_level)


def nees_label(nees_total: float, n: int, dim: int, alpha: float = 0.05) -> Label:
    """:func:`nees_baseline` from the sum of the NEES values of ``n`` epochs."""
    dof = n * dim
    if nees_total > special.chdtri(dof, alpha / 2):
        return Label.OPTIMISM
    if nees_total < special.chdtri(dof, 1 - alpha / 2):
        return Label.PESSIMISM
    return Label.CREDIBLE


def nees_baseline(eps: np.ndarray, dim: int, alpha: float = 0.05) -> Label:
    """NEES classifier: two-sided χ² test of ΣNEES with N·d degrees of freedom.

    The NEES baseline of Table II. Above the upper 1−α/2 quantile: optimism; below the
    lower α/2 quantile: pessimism; credible between.

    Parameters
    ----------
    eps : numpy.ndarray, shape (N,)
        The NEES values ε_k of Eq. (1) ([nees][credcli.engine.metrics.nees]).
    dim : int
        The state dimension d.
    alpha : float
        The test's level.

    Returns
    -------
    Label
        ``optimism``, ``pessimism`` or ``credible``.

    References
    ----------
    P. Yan, L.-T. Hsu and R. Sun, "Credible Uncertainty Quantification under Noise and
    System Model Mismatch", Eqs. (1)-(2) and Table II.

    Examples
    --------
    >>> eps = 2.0 * np.random.default_rng(0).chisquare(2, size=100)  # Σ̂ half the truth
    >>> str(nees_baseline(eps, 2))
    'optimism'
    """
    return nees_label(float(np.sum(eps)), eps.size, dim, alpha)


def nci_baseline(nci_value: float, tau: float = 0.5) -> Label:
    """NCI classifier: optimism above +τ, pessimism below −τ, credible inside.

    The NCI baseline of Table II, and the steps of Algorithm 1 without SMM (Section
    III-B).

    Parameters
    ----------
    nci_value : float
        The NCI in dB, Eq. (4) ([nci][credcli.engine.metrics.nci]).
    tau : float
        τ_NCI in dB (0.5 in the paper, Section IV-A).

    Returns
    -------
    Label
        ``optimism``, ``pessimism`` or ``credible``.

    References
    ----------
    P. Yan, L.-T. Hsu and R. Sun, "Credible Uncertainty Quantification under Noise and
    System Model Mismatch", Eq. (4), Section III-B and Table II.

    Examples
    --------
    >>> [str(nci_baseline(x)) for x in (1.2, -0.7, 0.3)]
    ['optimism', 'pessimism', 'credible']
    """
    if nci_value > tau:
        return Label.OPTIMISM
    if nci_value < -tau:
        return Label.PESSIMISM
    return Label.CREDIBLE


CREDIBLE_FACTOR = 2.0
"""The calibrated rule calls a scale credible only when its 1 − α_S interval lies within
[1/2, 2] (3 dB): then a misfit by a factor 2 or more is excluded at level α_S/2 on either
side (two one-sided tests). A wider interval that contains 1 is inconclusive, and the scale
question untested, not credible: never a guess behind a label. On the paper's protocol
(N = 100, d = 2, independent) the interval is about [0.8, 1.27]: every segment is decided."""


def bias_margin(dim: int) -> float:
    """The calibrated rule calls a location credible only when the mean's confidence region
    excludes a bias of this many σ (‖μ‖ in the metric of the mean claimed precision):
    √(d(F − 1)), F = :data:`CREDIBLE_FACTOR`, i.e. √2σ for d = 2. A bias b raises the
    mean NEES from d to d + b², so b² = d(F − 1) is the bias that misfits the claimed
    covariance as much as the scale's margin, a factor F = 2 on the NEES: the two questions
    share one definition of a relevant misfit. A region that reaches past it is
    inconclusive, and the location question untested: no "no bias" claim from a mean test
    too weak to see one. Where κ̂ > 1 the margin is in the σ of the corrected covariance,
    √κ̂ times the claimed one (:func:`inconclusive_location`): after the covariance is
    multiplied by κ̂, a bias misfits it as much as b/√κ̂ would the claimed one."""
    return math.sqrt(dim * (CREDIBLE_FACTOR - 1.0))


def inconclusive_location(evidence: Evidence) -> str | None:
    """Why a location that no test rejects still does not support "no bias", or None."""
    mean = evidence.mean_test
    # in the σ of the covariance as the scale's answer corrects it (κ̂ > 1): the bias that
    # matters once the covariance is fixed; never narrower than the claimed σ
    inflation = evidence.scale.scale_factor if evidence.scale.scale_factor > 1.0 else 1.0
    margin = bias_margin(evidence.dim) * math.sqrt(inflation)
    if mean is None:
        return (
            f"location inconclusive: no mean test ran, so no bias of {margin:.3g}σ is "
            "excluded (the ELT has no margin)"
        )
    bound = mean.bias_bound(evidence.scale.bias_mahalanobis, evidence.mean_level)
    if bound < margin:
        return None
    return (
        f"location inconclusive: the bias is {evidence.scale.bias_mahalanobis:.3g}σ and its "
        f"{1 - evidence.mean_level:.4g} confidence region reaches {bound:.3g}σ, which does "
        f"not exclude one of {margin:.3g}σ (too few independent epochs or batches)"
    )


def inconclusive_scale(scale: ScaleTest, config: DiagnosisConfig) -> str | None:
    """Why a scale test that finds no misfit still does not support "credible", or None."""
    if noise(scale, config) is not None:
        return None
    low, high = scale.scale_factor_low, scale.scale_factor_high
    if low >= 1.0 / CREDIBLE_FACTOR and high <= CREDIBLE_FACTOR:
        return None
    return (
        f"scale inconclusive: κ̂ {scale.scale_factor:.3g} with interval [{low:.3g}, {high:.3g}] "
        f"finds no misfit but does not exclude one of a factor {CREDIBLE_FACTOR:g} "
        "(too few independent epochs or batches for a tighter interval)"
    )


def mixed(directions: DirectionScales, config: DiagnosisConfig) -> bool:
    """Whether the directions disagree in sign: one too large and another too small, each
    beyond its interval and the relevance floor. One factor for the whole covariance is then
    the wrong advice, and the label follows the directions (optimism)."""
    db = 10.0 * np.log10(np.maximum(directions.factors, np.finfo(float).tiny))
    too_small = np.any((directions.low > 1.0) & (db > config.tau_nci))
    too_large = np.any((directions.high < 1.0) & (db < -config.tau_nci))
    return bool(too_small and too_large)


def direction_noise(directions: DirectionScales, config: DiagnosisConfig) -> str | None:
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


def noise(scale: ScaleTest, config: DiagnosisConfig) -> str | None:
    """ "optimism", "pessimism" or None: the scale test at α_S with the relevance floor τ."""
    half = config.scale_level / 2
    db = 10.0 * math.log10(scale.scale_factor) if scale.scale_factor > 0 else -math.inf
    if scale.pvalue_upper < half and db > config.tau_nci:
        return "optimism"
    if scale.pvalue_lower < half and db < -config.tau_nci:
        return "pessimism"
    return None


def calibrated_label(
    scale: ScaleTest | None, location: str | None, config: DiagnosisConfig
) -> Label:
    """Scale part (two-sided at α_S, with the relevance floor τ) plus the location
    condition (:attr:`credcli.engine.evidence.Evidence.location_condition`); without a
    scale test, the location half alone (or credible as far as the location goes)."""
    if scale is None:
        return Label.compose(None, location)
    return Label.compose(noise(scale, config), location)


def label_without_smm(nci_value: float, ks_p: float, config: DiagnosisConfig) -> Label:
    """Lines 2–8 of Algorithm 1, with the KS check of the authors' code for Variant.KS."""
    if config.variant is Variant.KS and (
        ks_p >= config.ks_alpha or abs(nci_value) <= config.tau_nci
    ):
        return Label.CREDIBLE
    return nci_baseline(nci_value, config.tau_nci)


def label_with_smm(nci_centred: float, probes: metrics.Probes | None, tau: float) -> Label:
    """Lines 10–23 of Algorithm 1 on the bias-corrected estimate x̃_k."""
    if nci_centred < -tau:
        return Label.PESSIMISM_SMM
    if nci_centred > tau:
        assert probes is not None
        if probes.all_positive:
            return Label.SMM
        if greater(probes.srd_nll, probes.srd_es):
            return Label.OPTIMISM_SMM
    return Label.SMM


def greater(a: float, b: float) -> bool:
    return not math.isnan(a) and not math.isnan(b) and a > b
