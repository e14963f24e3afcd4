"""Algorithm 1, its variants, and the single-metric baselines."""

from __future__ import annotations

import dataclasses
import math
import warnings

import numpy as np
import pytest
from helpers import gaussian_segment
from scipy import special, stats

from credcli.engine import diagnosis as dg
from credcli.engine import rules
from credcli.engine.diagnosis import DiagnosisConfig, Label, Variant
from credcli.engine.metrics import Probes
from credcli.errors import CredcliError

PLANTED = {
    Label.CREDIBLE: (1.0, None),
    Label.OPTIMISM: (0.3, None),
    Label.PESSIMISM: (4.0, None),
    Label.BIAS: (1.0, [2.0, -1.0]),
    Label.OPTIMISM_BIAS: (0.2, [2.0, -1.0]),
    Label.PESSIMISM_BIAS: (5.0, [8.0, -4.0]),  # an offset no slow error within the claim draws
}


@pytest.mark.parametrize("label", list(PLANTED))
def test_every_label_is_reachable_from_planted_data(label):
    rho, bias = PLANTED[label]
    gen = np.random.default_rng(21)
    errors, cov = gaussian_segment(gen, n=400, d=2, rho=rho, bias=bias)
    assert dg.diagnose_errors(errors, cov, rng=0).label is label


def test_insufficient_data_is_never_a_guess(rng):
    errors, cov = gaussian_segment(rng, n=9, d=2)
    d = dg.diagnose_errors(errors, cov, rng=0)
    assert d.label is Label.INSUFFICIENT and d.elt is None and d.nci is None
    # ten epochs are diagnosed (the tests run), though at 10 epochs neither margin, a
    # factor 2 on the scale nor a √2σ bias, can be excluded
    ten = dg.diagnose_errors(*gaussian_segment(rng, n=10, d=2), rng=0)
    assert ten.mean_test is not None and ten.scale is not None
    # with sign blocks of 5 epochs, 25 epochs give 5 blocks: p < 0.05 would be impossible
    config = DiagnosisConfig(block_length=5, variant="ks")
    assert config.min_n(2) == 26
    assert (
        dg.diagnose_errors(*gaussian_segment(rng, n=25, d=2), config, 0).label is Label.INSUFFICIENT
    )
    # calibrated: the ELT's share α_E = α_L/2 = 0.0127 needs 2^(1−m) <= α_E/2, m >= 9 blocks;
    # with fewer, the GLS mean test (batch means of 5+ epochs) answers the location alone
    config = DiagnosisConfig(block_length=5)
    assert config.min_blocks == 9 and config.min_n(2) == 10
    short = dg.diagnose_errors(*gaussian_segment(rng, n=40, d=2), config, 0)
    assert short.elt is None and "leaves 8 of the 9 sign blocks" in short.reason
    assert short.mean_test.batches == 8 and short.label is not Label.INSUFFICIENT
    enough = dg.diagnose_errors(*gaussian_segment(rng, n=41, d=2), config, 0)
    assert enough.label is not Label.INSUFFICIENT and enough.elt.n_used == 41


def probes_eigen(**kw):
    base = dict(
        c=2.0,
        nll_minus=0,
        nll=0,
        nll_plus=0,
        es_minus=0,
        es=0,
        es_plus=0,
        delta_nll_minus=1.0,
        delta_nll_plus=1.0,
        delta_es_minus=1.0,
        delta_es_plus=1.0,
        srd_nll=0.0,
        srd_es=0.0,
    )
    base.update(kw)
    return Probes(**base)


def test_smm_branch_decisions():
    """Lines 11–23 of Algorithm 1, branch by branch."""
    tau = 0.5
    assert rules.label_with_smm(-0.6, None, tau) is Label.PESSIMISM_SMM
    assert rules.label_with_smm(0.3, None, tau) is Label.SMM
    assert rules.label_with_smm(0.6, probes_eigen(), tau) is Label.SMM  # all four probes positive
    mixed = dict(delta_nll_plus=-0.2)
    assert (
        rules.label_with_smm(0.6, probes_eigen(**mixed, srd_nll=3, srd_es=1), tau)
        is Label.OPTIMISM_SMM
    )
    assert rules.label_with_smm(0.6, probes_eigen(**mixed, srd_nll=1, srd_es=3), tau) is Label.SMM


def test_no_smm_branch_variants():
    paper = DiagnosisConfig(variant=Variant.PAPER)
    ks = DiagnosisConfig(variant=Variant.KS)
    assert rules.label_without_smm(0.8, 0.5, paper) is Label.OPTIMISM
    assert rules.label_without_smm(-0.8, 0.5, paper) is Label.PESSIMISM
    assert rules.label_without_smm(0.2, 0.0, paper) is Label.CREDIBLE
    assert rules.label_without_smm(0.8, 0.5, ks) is Label.CREDIBLE  # KS does not reject
    assert rules.label_without_smm(0.8, 0.001, ks) is Label.OPTIMISM  # KS rejects, NCI > τ
    assert rules.label_without_smm(-0.8, 0.001, ks) is Label.PESSIMISM
    assert rules.label_without_smm(0.4, 0.001, ks) is Label.CREDIBLE  # |NCI| <= τ


def test_ks_variant_raises_credible_rate_at_n100():
    """The fact behind (a): as printed, Algorithm 1 calls ~76% of credible trials credible
    at N = 100; with the KS check, ~94%."""
    hits = {Variant.PAPER: 0, Variant.KS: 0}
    for k in range(150):
        gen = np.random.default_rng(500 + k)
        errors, cov = gaussian_segment(gen, n=100, d=2)
        for v in hits:
            hits[v] += (
                dg.diagnose_errors(errors, cov, DiagnosisConfig(variant=v), k).label
                is Label.CREDIBLE
            )
    assert 0.60 <= hits[Variant.PAPER] / 150 <= 0.85
    assert hits[Variant.KS] / 150 >= 0.88


def test_nees_baseline_thresholds_match_scipy_chi2():
    n, d = 100, 2
    lo, hi = stats.chi2.ppf([0.025, 0.975], n * d)
    eps = np.full(n, hi / n * 1.0001)
    assert dg.nees_baseline(eps, d) is Label.OPTIMISM
    assert dg.nees_baseline(np.full(n, hi / n * 0.9999), d) is Label.CREDIBLE
    assert dg.nees_baseline(np.full(n, lo / n * 0.9999), d) is Label.PESSIMISM
    assert dg.nees_baseline(np.full(n, lo / n * 1.0001), d) is Label.CREDIBLE


def test_nci_baseline():
    assert dg.nci_baseline(0.51) is Label.OPTIMISM
    assert dg.nci_baseline(-0.51) is Label.PESSIMISM
    assert dg.nci_baseline(0.5) is Label.CREDIBLE


def test_ks_pvalue_agrees_with_scipy_exact(rng):
    for d in (1, 2, 5):
        for scale in (1.0, 1.3, 0.7):
            eps = stats.chi2.rvs(d, size=120, random_state=rng) * scale
            ours = dg.ks_chi2_pvalue(eps, d)
            ref = stats.kstest(eps, "chi2", args=(d,), method="exact").pvalue
            if ref < 0.05:
                assert ours == pytest.approx(ref, abs=1e-6)
            assert (ours < 0.01) == (ref < 0.01)


@pytest.mark.parametrize("above", [1, 960, 50_000])
def test_the_vectorised_smirnov_tail_is_scipys_exact_sum(above):
    """Beyond SMIRNOV_SCIPY_MAX epochs the Birnbaum–Tingey sum is evaluated as one array;
    scipy's smirnov sums the same series term by term (exact up to 10⁶ epochs)."""
    from credcli.engine import evidence

    n = evidence.SMIRNOV_SCIPY_MAX + above
    for c in (0.3, 0.9, 1.5, 2.2, 3.0):
        d = c / math.sqrt(n)
        assert evidence.smirnov_tail(n, d) == pytest.approx(special.smirnov(n, d), rel=1e-9)
    assert evidence.smirnov_tail(n, 0.0) == 1.0 and evidence.smirnov_tail(n, 1.0) == 0.0


def test_the_ks_statistic_and_smirnov_sum_in_chunks_are_the_whole_arrays(rng):
    """Past a chunk of epochs (linalg.EPOCH_CHUNK) the KS statistic and the Birnbaum–Tingey
    sum are taken chunk by chunk; each is, to the bit, the one-array form."""
    from credcli.engine import evidence, linalg

    n = linalg.EPOCH_CHUNK + 40_000
    eps = rng.chisquare(2, size=n) * 1.002
    x = np.sort(eps)
    cdf = special.chdtr(2, x)
    i = np.arange(1, n + 1)
    d_stat = max(float(np.max(i / n - cdf)), float(np.max(cdf - (i - 1) / n)))
    j = np.arange(math.floor(n * (1.0 - d_stat)) + 1, dtype=float)
    assert j.size > linalg.EPOCH_CHUNK
    log_terms = (
        special.gammaln(n + 1.0)
        - special.gammaln(j + 1.0)
        - special.gammaln(n - j + 1.0)
        + (n - j) * np.log1p(-(d_stat + j / n))
        + (j - 1.0) * np.log(d_stat + j / n)
    )
    top = float(np.max(log_terms))
    tail = float(d_stat * math.exp(top) * np.sum(np.exp(log_terms - top)))
    assert evidence.smirnov_tail(n, d_stat) == tail
    assert dg.ks_chi2_pvalue(eps, 2) == float(min(1.0, 2.0 * tail))


def test_result_carries_every_intermediate_number(rng):
    errors, cov = gaussian_segment(rng, n=200, d=2, rho=0.2, bias=[2, 0])
    d = dg.diagnose_errors(errors, cov, DiagnosisConfig(metrics="all"), rng=1)
    assert dataclasses.is_dataclass(d)
    with pytest.raises(dataclasses.FrozenInstanceError):
        d.label = Label.CREDIBLE
    assert d.n == 200 and d.dim == 2
    assert d.anees == pytest.approx(
        np.mean(np.einsum("ni,nij,nj->n", errors, np.linalg.inv(cov), errors)) / 2
    )
    assert d.probes is not None and d.scores is not None
    assert d.elt_pvalue is not None and d.nci_centered is not None and d.ks_pvalue is not None


def test_same_seed_same_result_and_segment_streams_independent(rng):
    errors, cov = gaussian_segment(rng, n=80, d=2)
    a = dg.diagnose_errors(errors, cov, rng=dg.segment_seed(0, "a"))
    b = dg.diagnose_errors(errors, cov, rng=dg.segment_seed(0, "a"))
    c = dg.diagnose_errors(errors, cov, rng=dg.segment_seed(0, "b"))
    np.testing.assert_array_equal(a.elt.null_distribution, b.elt.null_distribution)
    assert not np.array_equal(a.elt.null_distribution, c.elt.null_distribution)


@pytest.mark.parametrize(
    "field, value", [("tau_nci", 0), ("alpha", 1.5), ("c", 1.0), ("n_flips", 0)]
)
def test_config_validation(field, value):
    with pytest.raises(CredcliError, match=f"invalid setting.*{field}|{field}.*invalid setting"):
        DiagnosisConfig(**{field: value})


def test_shared_covariance_api_equals_per_epoch_covariances(rng):
    import credcli

    errors, cov = gaussian_segment(rng, n=100, d=2)  # one Σ̂ for every epoch
    a = credcli.diagnose(errors, cov[0], rng=4)
    b = dg.diagnose_errors(errors, cov, rng=4)
    assert a.label is b.label
    assert a.nci == pytest.approx(b.nci, rel=1e-12)
    assert a.elt_pvalue == b.elt_pvalue


@pytest.mark.parametrize("name", ["variant", "srd_form", "metrics", "slow_errors"])
def test_a_setting_that_is_no_choice_is_named(name):
    """Every choice of DiagnosisConfig refuses an unknown value the same way: a CredcliError
    naming the setting and its choices (srd_form and metrics raised a bare ValueError)."""
    with pytest.raises(CredcliError, match=f"`{name}` must be one of") as info:
        DiagnosisConfig(**{name: "nonsense"})
    assert info.value.parameter == name


@pytest.mark.parametrize("variant", list(Variant))
@pytest.mark.parametrize("shift", [100, -60])  # errors 2^shift claimed standard deviations
def test_errors_whose_squares_leave_float64_keep_their_nci_and_label(variant, shift):
    """The NCI's ε* = eᵀM⁻¹e, M the errors' own MSE matrix, is scale-free. Errors of 2^600
    (their squares overflow) with covariances of 2^1000, or of 2^-560 (their squares
    underflow) with covariances of 2^-1000, are the same log as errors of 2^shift with
    unit covariances, rescaled exactly: the same NCI, NCI baseline and label. (Before, the MSE
    matrix overflowed to inf, so the NCI was undefined and the ks and paper variants called
    an optimistic log credible, or underflowed to zeros: insufficient-data.)"""
    e = np.random.default_rng(3).standard_normal((300, 2))
    config = DiagnosisConfig(variant=variant)
    eye = np.broadcast_to(np.eye(2), (300, 2, 2))
    plain = dg.diagnose_errors(e * 2.0**shift, eye, config, rng=0)
    scale = 500 if shift > 0 else -500
    with np.errstate(all="ignore"):  # what the extreme units make of other figures
        extreme = dg.diagnose_errors(
            e * 2.0 ** (shift + scale), eye * 2.0 ** (2 * scale), config, rng=0
        )
    assert extreme.label is plain.label
    assert extreme.nci_label is (Label.OPTIMISM if shift > 0 else Label.PESSIMISM)
    assert extreme.nci == pytest.approx(plain.nci, rel=1e-12)
    assert abs(plain.nci - 10 * math.log10(2.0 ** (2 * shift))) < 3  # the scale in dB, ± d·κ̂


@pytest.mark.parametrize("offset", [0.0, 1.0])  # none, and a 1σ bias
def test_errors_far_above_their_claim_keep_their_location_test(offset):
    """The mean test is scale-free in the errors: errors of 2^560 with covariances of
    2^1000 (whitened, 2^60 σ; the errors' squares overflow) are tested as the same errors
    with unit covariances scaled by 2^-560, to the same p-value and location, with no
    floating-point warning, and the standard errors of the bias scale with the errors
    (they were inf)."""
    e = np.random.default_rng(7).standard_normal((50, 3)) + offset / math.sqrt(3)
    eye = np.broadcast_to(np.eye(3), (50, 3, 3))
    plain = dg.diagnose_errors(e * 2.0**60, eye, rng=0)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        far = dg.diagnose_errors(e * 2.0**560, eye * 2.0**1000, rng=0)
    assert far.label is plain.label
    assert far.mean_test.pvalue == pytest.approx(plain.mean_test.pvalue, rel=1e-9)
    assert far.scale.scale_factor == pytest.approx(plain.scale.scale_factor, rel=1e-9)
    np.testing.assert_allclose(far.scale.bias_stderr, plain.scale.bias_stderr * 2.0**500, rtol=1e-9)


@pytest.mark.parametrize("seed", range(4))
def test_errors_far_below_their_claim_are_not_called_biased(seed):
    """Credible-shaped errors of 2^-600 claimed σ (their squares underflow): pessimism, a
    finite mean test, and a bias only where that test rejects at its level, without a
    floating-point warning. (Before, the mean test's covariance was 0·inf: NaN, a p-value
    of 0 and a bias found on errors of mean zero. Seed 1's mean is off zero by chance, p
    0.006 below the level 0.0127: since session 36 no weak memory of another of the six
    directions is every direction's alternative, and the bias is claimed at its level.)"""
    e = np.random.default_rng(seed).standard_normal((50, 6)) * 2.0**-600
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        result = dg.diagnose_errors(e, np.eye(6)[None].repeat(50, axis=0), rng=0)
    assert result.label in (Label.PESSIMISM, Label.PESSIMISM_BIAS)
    assert 0.0 < result.mean_test.pvalue <= 1.0
    biased = result.mean_test.pvalue < DiagnosisConfig().mean_level
    assert (result.label is Label.PESSIMISM_BIAS) == biased
