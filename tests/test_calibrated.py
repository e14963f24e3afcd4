"""The calibrated rule: the scale test's level and coverage, the GLS mean, the dependence
estimates against closed forms, and the rule on AR(1) and Kalman-filter errors."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import special

from credcli.cli import main
from credcli.engine import correlation
from credcli.engine.diagnosis import DiagnosisConfig, Label, diagnose_errors
from credcli.engine.scale import gls_residuals, scale_test

ALPHA_S = 1 - math.sqrt(0.95)


def _random_covs(rng, n, d):
    a = rng.standard_normal((n, d, d))
    return a @ np.swapaxes(a, 1, 2) + 0.5 * np.eye(d)


def test_sidak_split():
    config = DiagnosisConfig()
    assert config.location_level == pytest.approx(ALPHA_S) == config.scale_level
    assert 1 - (1 - config.location_level) * (1 - config.scale_level) == pytest.approx(0.05)
    assert DiagnosisConfig(variant="ks").location_level == 0.05


def test_statistic_equals_explicit_inverse_computation(rng):
    """T and μ̂ by Cholesky solves equal the textbook formulas with explicit inverses."""
    n, d = 40, 3
    cov = _random_covs(rng, n, d)
    e = rng.standard_normal((n, d)) + 2.0
    res = gls_residuals(e, np.linalg.cholesky(cov))
    w = np.linalg.inv(cov)
    mu = np.linalg.solve(w.sum(axis=0), np.einsum("nij,nj->i", w, e))
    r = e - mu
    assert np.allclose(res.mean, mu, rtol=1e-12)
    assert res.q.sum() == pytest.approx(np.einsum("ni,nij,nj->", r, w, r), rel=1e-12)


def test_gls_mean_is_the_plain_mean_for_a_constant_covariance(rng):
    e = rng.standard_normal((57, 2)) * [1.0, 3.0] + [0.4, -2.0]
    chol = np.linalg.cholesky(np.array([[2.0, 0.7], [0.7, 1.0]]))
    assert np.allclose(gls_residuals(e, chol).mean, e.mean(axis=0), rtol=1e-12, atol=1e-14)
    batched = gls_residuals(e, np.broadcast_to(chol, (57, 2, 2)))
    assert np.allclose(batched.mean, e.mean(axis=0), rtol=1e-12, atol=1e-14)


def _scale_draws(draws, n, d, kappa, seed):
    """T on ``draws`` segments with per-epoch covariances Σ̂_k, true covariance κΣ̂_k and a bias."""
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(draws):
        cov = _random_covs(rng, n, d)
        chol = np.linalg.cholesky(cov)
        e = np.sqrt(kappa) * np.einsum("nij,nj->ni", chol, rng.standard_normal((n, d))) + 3.0
        out.append(scale_test(gls_residuals(e, chol), ALPHA_S))
    return out


def test_scale_test_size_is_alpha_s_in_each_tail():
    """20,000 credible segments (N = 8, d = 2, varying Σ̂_k, bias 3): each tail rejects at
    α_S/2 = 1.27 % within 4 Monte Carlo standard errors (0.08 %)."""
    results = _scale_draws(20_000, 8, 2, 1.0, seed=1)
    upper = np.mean([r.pvalue_upper < ALPHA_S / 2 for r in results])
    lower = np.mean([r.pvalue_lower < ALPHA_S / 2 for r in results])
    se = math.sqrt(ALPHA_S / 2 * (1 - ALPHA_S / 2) / 20_000)
    assert abs(upper - ALPHA_S / 2) < 4 * se, upper
    assert abs(lower - ALPHA_S / 2) < 4 * se, lower
    assert results[0].dof == 14  # (N − 1)d


def test_scale_interval_covers_the_true_factor():
    """Σ_true = 2.5 Σ̂: the 1 − α_S interval covers 2.5 in 97.5 % ± 4 s.e. of 4,000 draws,
    and κ̂ is unbiased (E[T] = ν κ)."""
    results = _scale_draws(4_000, 12, 2, 2.5, seed=2)
    cover = np.mean([r.scale_factor_low <= 2.5 <= r.scale_factor_high for r in results])
    se = math.sqrt(ALPHA_S * (1 - ALPHA_S) / 4_000)
    assert abs(cover - (1 - ALPHA_S)) < 4 * se, cover
    kappas = np.array([r.scale_factor for r in results])
    assert abs(kappas.mean() - 2.5) < 4 * kappas.std() / math.sqrt(kappas.size)


def test_interval_matches_chi_square_quantiles():
    rng = np.random.default_rng(3)
    e = rng.standard_normal((30, 2))
    r = scale_test(gls_residuals(e, np.eye(2)), 0.05)
    t = r.statistic
    assert r.scale_factor_low == pytest.approx(t / special.chdtri(58, 0.025), rel=1e-12)
    assert r.scale_factor_high == pytest.approx(t / special.chdtri(58, 0.975), rel=1e-12)
    assert r.pvalue == pytest.approx(2 * min(special.chdtr(58, t), special.chdtrc(58, t)))


@pytest.mark.parametrize(
    ("end", "inside"),
    [("upper", 0.99), ("upper", 1.01), ("lower", 1.01), ("lower", 0.99)],
)
def test_a_credible_scale_is_two_one_sided_tests_at_alpha_s(end, inside):
    """The scale is credible where κ's one-sided 1 − α_S bounds lie within [½, 2]
    (Schuirmann's two one-sided tests at α_S): 12 independent epochs, d = 2, ν = 22, T ~
    κχ²_22, so the bounds are [T/q₊, T/q₋], q± the χ²_22 quantiles at 1 − α_S and α_S, and
    the scale is decided for T between q₊/2 and 2q₋ (18.4 and 22.0). T is set 1 % inside
    or outside either end (the 1 − α_S two-sided interval, q at α_S/2, would decide
    neither: 2q₋ is then 20.6)."""
    from credcli.engine import rules
    from credcli.engine.config import DiagnosisConfig

    n, nu, level = 12, 22, ALPHA_S
    end_value = (
        2 * special.chdtri(nu, 1 - level) if end == "upper" else special.chdtri(nu, level) / 2
    )
    below = inside < 1 if end == "upper" else inside > 1  # which side is within the margin
    e = np.random.default_rng(5).standard_normal((n, 2))
    e -= e.mean(axis=0)
    e *= math.sqrt(end_value * inside / float((e**2).sum()))
    test = scale_test(gls_residuals(e, np.eye(2)), level)
    assert test.statistic == pytest.approx(end_value * inside, rel=1e-12)
    assert test.equivalence_interval == pytest.approx(
        (
            test.statistic / special.chdtri(nu, level),
            test.statistic / special.chdtri(nu, 1 - level),
        ),
        rel=1e-12,
    )
    decided = rules.inconclusive_scale(test, DiagnosisConfig()) is None
    assert decided is below
    assert test.scale_factor_high > 2.0 or test.scale_factor_low < 0.5  # α_S/2 each side


def test_the_credible_scale_holds_its_level_on_dependent_errors():
    """A covariance half the errors' (κ = 2, the margin), AR(1) errors φ = 0.5, N = 40,
    d = 2, 600 segments: the rule claims the scale credible (within a factor 2) in at most
    α_S + 3 standard errors of them, its studentized bounds under the fitted memory holding
    the two one-sided tests' level (measured 8 of 600)."""
    from credcli.engine.config import Question

    rng = np.random.default_rng(11)
    n, reps, phi = 40, 600, 0.5
    z = rng.standard_normal((reps, n + 100, 2))
    x = np.zeros_like(z)
    x[:, 0] = z[:, 0]
    for k in range(1, n + 100):  # a loop over 140 epochs, vectorized over the segments
        x[:, k] = phi * x[:, k - 1] + math.sqrt(1 - phi**2) * z[:, k]
    cov = np.broadcast_to(np.eye(2), (n, 2, 2))
    claimed = 0
    for r in range(reps):
        d = diagnose_errors(x[r, 100:] * math.sqrt(2.0), cov, rng=r)
        named = {"optimism", "pessimism"} & set(str(d.label).split("+"))
        tested = d.label is not Label.INSUFFICIENT and Question.SCALE not in d.untested
        claimed += tested and not named
    assert claimed / reps <= ALPHA_S + 3 * math.sqrt(ALPHA_S * (1 - ALPHA_S) / reps), claimed


def test_andrews_bandwidth_published_formula():
    """Andrews (1991), Eq. (6.4): S = 1.1447 (α(1) T)^(1/3), α(1) = 4ρ²/((1−ρ)²(1+ρ)²)."""
    alpha1 = 4 * 0.25 / (0.25 * 2.25)
    assert correlation.andrews_bandwidth(np.array([0.5]), 100)[0] == pytest.approx(
        1.1447 * (alpha1 * 100) ** (1 / 3)
    )
    assert correlation.andrews_bandwidth(np.array([0.0]), 100)[0] == 0.0


def test_long_run_variance_equals_a_direct_bartlett_sum():
    """Against an independent computation: prewhiten, Bartlett sum with explicit loops, recolour."""
    rng = np.random.default_rng(4)
    x = np.convolve(rng.standard_normal(300), [1.0, 0.8, 0.5], mode="valid")
    c = x - x.mean()
    rho = float(np.dot(c[1:], c[:-1]) / np.dot(c[:-1], c[:-1]))
    eps = c[1:] - rho * c[:-1]
    m = eps.size
    r2 = eps - eps.mean()
    rho2 = float(np.dot(r2[1:], r2[:-1]) / np.dot(r2[:-1], r2[:-1]))
    band = 1.1447 * (4 * rho2**2 / ((1 - rho2) ** 2 * (1 + rho2) ** 2) * m) ** (1 / 3)
    total = sum(eps[t] * eps[t] for t in range(m)) / m
    for j in range(1, m):
        if j >= band:
            break
        total += 2 * (1 - j / band) * sum(eps[t] * eps[t - j] for t in range(j, m)) / m
    assert correlation.long_run_variance(x)[0] == pytest.approx(total / (1 - rho) ** 2, rel=1e-10)


@pytest.mark.parametrize("phi", [0.0, 0.5, 0.9])
def test_variance_ratio_of_an_ar1_is_its_closed_form(phi):
    """τ = (1 + φ)/(1 − φ) for an AR(1); 200,000 epochs, within 6 %."""
    from scipy.signal import lfilter

    z = np.random.default_rng(5).standard_normal(200_000)
    x = lfilter([1.0], [1.0, -phi], z)
    assert correlation.variance_ratio(x)[0] == pytest.approx((1 + phi) / (1 - phi), rel=0.06)


def test_block_length_from_the_variance_ratio():
    # AR(1) φ = 0.5: τ = 3, (9 − 1)/(2·3·0.1) = 13.3 -> 14; φ = 0.9: τ = 19 -> 95
    assert correlation.block_length(3.0) == 14
    assert correlation.block_length(19.0) == 95
    assert correlation.block_length(np.array([0.7, 1.0])) == 1


def test_automatic_block_length_is_small_on_independent_errors():
    """On independent errors the sieve's order is mostly 0 (single-epoch signs); where AICc
    fits a spurious order the blocks stay short: at least 20 of them in 500 epochs."""
    lengths = []
    for seed in range(20):
        rng = np.random.default_rng(seed)
        e = rng.standard_normal((500, 2))
        d = diagnose_errors(e, np.broadcast_to(np.eye(2), (500, 2, 2)), rng=seed)
        lengths.append(d.block_length)
    assert np.median(lengths) == 1 and np.mean(np.array(lengths) <= 2) >= 0.8
    assert max(lengths) <= 500 // 20


def _ar1(rng, n, d, phi):
    from scipy.signal import lfilter

    z = rng.standard_normal((n, d))
    c = math.sqrt(1 - phi**2)
    return lfilter([c], [1.0, -phi], z, axis=0, zi=(1 - c) * z[:1])[0]


@pytest.mark.slow
def test_false_alarms_on_ar1_errors_are_controlled():
    """AR(1) φ = 0.9, N = 2000, correct covariance: of 150 stored seeds at most 10 % are not
    credible (credcli 0.1 labelled 88 % smm), and at most 4 are insufficient-data (the model
    check at every time scale, 1 %: 1.5 expected, s.e. 1.2; one of these seeds is declined
    at the lowest frequency). At the measured rate (6.5 % over 400 trials,
    docs/measured.md) 150 trials exceed 10 % with probability about 5 %; these seeds are
    fixed, so the test is deterministic."""
    labels = []
    for seed in range(150):
        rng = np.random.default_rng([7, seed])
        e = _ar1(rng, 2000, 2, 0.9) @ np.array([[1.0, 0.0], [0.5, 2.0]]).T
        cov = np.broadcast_to(np.array([[1.0, 0.5], [0.5, 4.25]]), (2000, 2, 2))
        labels.append(diagnose_errors(e, cov, rng=seed).label)
    assert labels.count(Label.INSUFFICIENT) <= 4
    assert np.mean([lab is not Label.CREDIBLE for lab in labels]) <= 0.10


def test_too_few_blocks_is_insufficient_data_with_a_reason():
    rng = np.random.default_rng(8)
    e = _ar1(rng, 300, 2, 0.98)
    d = diagnose_errors(e, np.broadcast_to(np.eye(2), (300, 2, 2)), rng=0)
    assert d.label is Label.INSUFFICIENT and d.elt is None
    # AR(1) φ = 0.98 in 300 epochs: three correlation times, so the memory itself is unknown
    assert "memory comparable to the segment" in d.reason and "neither question" in d.reason
    assert d.effective_n < 300 / 10
    assert d.scale is not None and d.scale.scale_factor > 0  # the numbers are still reported


# --- a 2-D constant-velocity Kalman filter, for tests on real filter errors ----------------
#
# Truth: x_{k+1} = F x_k + w_k (+ a constant acceleration when asked), w_k ~ N(0, Q);
# measurements y_k = H x_k + v_k, v_k ~ N(0, R). The filter runs with its own Q_f, R_f.
# Returned: position errors (truth − estimate) and the filter's position covariance.


def _cv_model(dt: float, q: float):
    f1 = np.array([[1.0, dt], [0.0, 1.0]])
    q1 = q * np.array([[dt**3 / 3, dt**2 / 2], [dt**2 / 2, dt]])
    # state order (px, vx, py, vy)
    f = np.kron(np.eye(2), f1)
    qm = np.kron(np.eye(2), q1)
    h = np.kron(np.eye(2), np.array([[1.0, 0.0]]))
    return f, qm, h


def _run_filter(
    n: int,
    seed: int,
    q: float = 0.1,
    r: float = 1.0,
    filter_scale: float = 1.0,
    acceleration: float = 0.0,
    dt: float = 1.0,
    burn_in: int = 50,
):
    """Position errors (n, 2) and covariances (n, 2, 2) of a CV filter after ``burn_in``.

    ``filter_scale`` multiplies the Q and R the filter assumes (1: exactly right);
    ``acceleration`` adds an unmodelled constant acceleration to the truth (both axes).
    """
    rng = np.random.default_rng(seed)
    f, qm, h = _cv_model(dt, q)
    rm = r * np.eye(2)
    qf, rf = filter_scale * qm, filter_scale * rm
    total = n + burn_in
    x = np.zeros(4)
    xh = np.zeros(4)
    p = np.eye(4) * 10.0
    acc = np.array([0.5 * dt**2, dt, 0.5 * dt**2, dt]) * acceleration
    chol_q = np.linalg.cholesky(qm)
    errors = np.empty((total, 2))
    covs = np.empty((total, 2, 2))
    idx = [0, 2]
    for k in range(total):
        x = f @ x + chol_q @ rng.standard_normal(4) + acc
        y = h @ x + np.sqrt(r) * rng.standard_normal(2)
        xh = f @ xh
        p = f @ p @ f.T + qf
        s = h @ p @ h.T + rf
        gain = np.linalg.solve(s, h @ p).T
        xh = xh + gain @ (y - h @ xh)
        p = (np.eye(4) - gain @ h) @ p
        p = 0.5 * (p + p.T)
        errors[k] = (x - xh)[idx]
        covs[k] = p[np.ix_(idx, idx)]
    return errors[burn_in:], covs[burn_in:]


@pytest.mark.parametrize(
    "kwargs, expected",
    [
        ({}, Label.CREDIBLE),
        ({"filter_scale": 0.2}, Label.OPTIMISM),
        ({"acceleration": 0.05}, Label.BIAS),
    ],
)
def test_constant_velocity_kalman_filter(kwargs, expected):
    """Correct Q and R: credible (lag-1 autocorrelation about 0.6); Q and R 5x too small:
    optimism with κ̂ near 5; an unmodelled acceleration: smm. Three stored seeds each."""
    for seed in range(3):
        e, cov = _run_filter(1500, seed, **kwargs)
        d = diagnose_errors(e, cov, rng=seed)
        assert d.label is expected, (seed, d)
        assert d.block_length > 1 and d.autocorrelation > 0.3
        if "filter_scale" in kwargs:
            # Q and R both x0.2: the Riccati solution P is exactly x0.2 and the gain, hence
            # the errors, unchanged, so the true factor is exactly 5
            assert d.scale.scale_factor_low < 5.0 < d.scale.scale_factor_high


def test_relevance_floor_keeps_small_mismatches_credible():
    """A 2 % scale mismatch on 200,000 epochs is significant but below τ = 0.5 dB."""
    rng = np.random.default_rng(9)
    n = 200_000
    e = rng.standard_normal((n, 2)) * math.sqrt(1.02)
    config = DiagnosisConfig(max_elt_epochs=500, n_flips=200, block_length=1)
    d = diagnose_errors(e, np.broadcast_to(np.eye(2), (n, 2, 2)), config, 0)
    assert d.scale.pvalue < 1e-3 and d.label is Label.CREDIBLE


@pytest.mark.parametrize("exponent", [-30, 30])
def test_scale_invariance(exponent):
    """Errors and covariance scaled together: the same label and p-values."""
    rng = np.random.default_rng(10)
    e = rng.standard_normal((200, 2)) * [1.0, 2.0] + [0.3, 0.0]
    cov = np.broadcast_to(np.diag([1.0, 4.0]), (200, 2, 2))
    ref = diagnose_errors(e, cov, rng=0)
    k = 10.0**exponent
    got = diagnose_errors(e * k, cov * k**2, rng=0)
    assert got.label is ref.label and got.elt.pvalue == ref.elt.pvalue
    assert got.scale.pvalue == pytest.approx(ref.scale.pvalue, rel=1e-9)
    assert got.scale.scale_factor == pytest.approx(ref.scale.scale_factor, rel=1e-9)


def test_json_record_equals_the_library_result(tmp_path, capsys):
    rng = np.random.default_rng(11)
    n = 400
    e = rng.standard_normal((n, 2)) * 1.5 + [0.5, 0.0]
    cols = {"truth_0": e[:, 0], "truth_1": e[:, 1], "est_0": 0.0, "est_1": 0.0}
    cols |= {"cov_0_0": 1.0, "cov_0_1": 0.0, "cov_1_1": 1.0}
    import pandas as pd

    path = tmp_path / "log.csv"
    pd.DataFrame(cols).to_csv(path, index=False)
    assert main(["diagnose", str(path), "-f", "json", "--seed", "3"]) == 0
    rec = json.loads(capsys.readouterr().out)["segments"][0]
    from credcli.engine.diagnosis import segment_seed

    d = diagnose_errors(e, np.broadcast_to(np.eye(2), (n, 2, 2)), rng=segment_seed(3, "all"))
    assert rec["label"] == d.label.value == "optimism+bias"
    # the CSV's text need not round-trip the last bit of every error (pandas' parser)
    assert rec["scale_factor"] == pytest.approx(d.scale.scale_factor, rel=1e-12)
    assert [rec["scale_factor_low"], rec["scale_factor_high"]] == pytest.approx(
        [d.scale.scale_factor_low, d.scale.scale_factor_high], rel=1e-12
    )
    low, high = d.scale.equivalence_interval
    assert d.scale.scale_factor_low < low < high < d.scale.scale_factor_high
    assert rec["scale_factor_bounds"] == pytest.approx([low, high], rel=1e-12)
    assert rec["bias"] == pytest.approx(list(d.scale.bias), rel=1e-10, abs=1e-14)
    assert rec["bias_stderr"] == pytest.approx(list(d.scale.bias_stderr), rel=1e-12)
    assert rec["block_length"] == d.block_length and rec["reason"] is None
    assert rec["scale_pvalue"] == pytest.approx(d.scale.pvalue, rel=1e-9)
    assert rec["effective_n"] == pytest.approx(d.effective_n, rel=1e-12)


def test_tail_factor_reads_student_t_tails():
    """Student-t(ν) components: Var(q)/2d = 1 + (d + 2)k/6 with k = 6/(ν − 4); for ν = 5, d = 2
    that is 5 and for ν = 8 it is 2. Normal components give 1."""
    from credcli.engine.scale import tail_factor

    rng = np.random.default_rng(12)
    assert tail_factor(rng.standard_normal((100_000, 2))) == 1.0
    assert tail_factor(rng.standard_t(5, (100_000, 2))) == pytest.approx(5.0, rel=0.2)
    assert tail_factor(rng.standard_t(8, (100_000, 2))) == pytest.approx(2.0, rel=0.2)
    # the ratio is scale-free
    u = rng.standard_t(6, (5_000, 3))
    assert tail_factor(u * 1e-20) == pytest.approx(tail_factor(u), rel=1e-9)


@pytest.mark.parametrize("d", [2, 3])
def test_the_tail_ratio_is_the_same_in_every_frame(d):
    """The tail check pools the principal directions' standardized components; their
    signs were the eigensolver's, and a skewed column's sign moves the 2.5 and 97.5 %
    quantiles the ratio reads. Each column now takes the sign of its skewness, so the
    same residuals in any frame (u → uQᵀ, Q orthogonal: a rotation, a reflection, the
    components reversed, u → −u) read the same quantiles and the same factor."""
    from credcli.engine.scale import standardized, tail_factor, tail_quantiles

    rng = np.random.default_rng(d)
    u = np.c_[rng.exponential(1.0, (400, 1)) ** 2, rng.standard_normal((400, d - 1))]
    u = u - u.mean(axis=0)
    plain = tail_quantiles(standardized(u))
    rotation = np.linalg.qr(rng.standard_normal((d, d)))[0]
    for q in (rotation, np.eye(d)[::-1], -np.eye(d)):
        moved = tail_quantiles(standardized(u @ q.T))
        np.testing.assert_allclose(moved, plain, rtol=1e-10, atol=1e-12)
        assert tail_factor(u @ q.T) == pytest.approx(tail_factor(u), rel=1e-10)


def test_the_tail_gate_keeps_its_size_on_dependent_gaussian_errors():
    """The tail ratio's spread grows with Σρ⁴ under serial dependence (its Hermite rank is
    4). Gaussian AR(2) errors (roots 0.95∠±0.3, 2,000 epochs): with the model's
    quartic_ratio the gate opens in at most its one-sided 10 % (+ 3 s.e. of 300 draws);
    read as independent it opened in about 20 %, and each opening widened the scale
    interval of credible errors. quartic_ratio is (1 + φ⁴)/(1 − φ⁴) for an AR(1)."""
    from types import SimpleNamespace

    from scipy.signal import lfilter

    from credcli.engine import memory as mem
    from credcli.engine.scale import quartic_ratio, standardized, tail_factor

    phi = 0.7
    gamma = mem.autocovariance_of_ar(np.array([phi]), 1.0, 400)
    ar1 = SimpleNamespace(series=(mem.SeriesMemory(np.array([phi]), gamma / gamma[0], math.inf),))
    assert quartic_ratio(ar1, 400) == pytest.approx((1 + phi**4) / (1 - phi**4), rel=1e-9)
    a = np.array([1.0, -2 * 0.95 * math.cos(0.3), 0.95**2])
    gamma = mem.autocovariance_of_ar(-a[1:], 1.0, 2_000)
    series = mem.SeriesMemory(-a[1:], gamma / gamma[0], math.inf)
    ratio = quartic_ratio(SimpleNamespace(series=(series, series)), 2_000)
    rng = np.random.default_rng(21)
    draws = 300
    opened = sum(
        tail_factor(
            standardized(lfilter([1.0], a, rng.standard_normal((5_000, 2)), axis=0)[3_000:]),
            memory_ratio=ratio,
        )
        > 1.0
        for _ in range(draws)
    )
    assert opened / draws <= 0.10 + 3.0 * math.sqrt(0.09 / draws)


def test_heavy_tails_widen_the_scale_reference():
    rng = np.random.default_rng(13)
    u = rng.standard_t(5, (2_000, 2)) * math.sqrt(3 / 5)  # unit variance
    r = scale_test(gls_residuals(u, np.eye(2)), ALPHA_S, np.ones(2))
    # independent unit-variance t5 components: E u⁴ = 9, Var(q) = 2(9 − 1) = 16, factor
    # Var(q)/(2d) = 4 (the elliptical t5 gives 5); a sample estimate is asked for half of 4
    assert r.satterthwaite > 2.0 and r.dof < 2 * 1999 / 2.0
    assert r.scale_factor_low < 1.0 < r.scale_factor_high


def test_the_block_count_checked_is_the_block_count_tested():
    """Subsampled segments: the insufficient-data check counts the blocks the ELT keeps,
    max_epochs // L, not ⌈max_epochs / L⌉ (with L = 571 and a 4000-epoch budget: 7, not 8)."""
    from credcli.engine.elt import tested_blocks, whitened_location_test

    assert tested_blocks(10_000, 571, 4000) == 7 and tested_blocks(3000, 571, 4000) == 6
    assert tested_blocks(100, 1, 4000) == 100 and tested_blocks(9000, 1, 4000) == 4000
    s = np.random.default_rng(0).standard_normal((10_000, 2))
    res = whitened_location_test(s, 99, np.random.default_rng(0), block_length=571, max_epochs=4000)
    assert res.subsampled and res.n_used == 7 * 571
    config = DiagnosisConfig(block_length=571, max_elt_epochs=4000)
    d = diagnose_errors(s, np.broadcast_to(np.eye(2), (10_000, 2, 2)), config, rng=0)
    # the ELT is not run (7 of its 9 blocks, and the reason names the budget); the GLS mean
    # test uses every epoch, in 12 batches of at least 571, and answers the location question
    assert d.elt is None and "ELT not run: its budget of 4000 epochs" in d.reason
    assert "leaves 7 of the 9" in d.reason and d.mean_test.batches == 12
    assert d.label is not Label.INSUFFICIENT and not d.untested


@settings(max_examples=40, deadline=None)
@given(
    n=st.integers(12, 400),
    scale=st.floats(0.2, 5.0),
    k=st.integers(2, 12),
    seed=st.integers(0, 2**16),
)
def test_the_one_sided_bounds_nest_inside_the_interval(n, scale, k, seed):
    """κ's one-sided 1 − α_S bounds (the 1 − 2α_S interval) lie inside its 1 − α_S interval,
    for the χ² reference and for batch means, and each bound is the interval at level
    2α_S: the χ² quantiles at α_S and 1 − α_S, Student's t at 1 − α_S."""
    from credcli.engine.batches import batch_scale

    rng = np.random.default_rng(seed)
    e = rng.standard_normal((n, 2)) * scale
    test = scale_test(gls_residuals(e, np.eye(2)), ALPHA_S)
    low, high = test.equivalence_interval
    assert test.scale_factor_low < low < high < test.scale_factor_high
    nu = 2 * (n - 1)
    assert high == pytest.approx(test.statistic / special.chdtri(nu, 1 - ALPHA_S), rel=1e-12)
    assert low == pytest.approx(test.statistic / special.chdtri(nu, ALPHA_S), rel=1e-12)
    batch = batch_scale(rng.chisquare(2, n) * scale, 2, min(k, n // 2), ALPHA_S)
    b_low, b_high = batch.equivalence_interval
    assert batch.scale_factor_low < b_low < b_high < batch.scale_factor_high
    crit = special.stdtrit(batch.batches - 1, 1 - ALPHA_S / 2)
    one = special.stdtrit(batch.batches - 1, 1 - ALPHA_S)
    log_mid = math.log(b_high * b_low) / 2  # both intervals share the log-scale centre
    assert math.log(b_high) - log_mid == pytest.approx(
        (math.log(batch.scale_factor_high) - log_mid) * one / crit, rel=1e-9
    )
