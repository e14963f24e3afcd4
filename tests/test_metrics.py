"""Metrics of Section II against closed forms, scipy and independent computations."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import gaussian_segment
from scipy import integrate, special, stats

from credcli.engine import metrics, quadrature


def test_nees_matches_explicit_inverse(rng):
    errors, cov = gaussian_segment(rng, n=50, d=3, varying=True)
    expected = np.array([e @ np.linalg.inv(c) @ e for e, c in zip(errors, cov)])
    np.testing.assert_allclose(metrics.nees(errors, cov), expected, rtol=1e-12)


@pytest.mark.parametrize("rho", [0.25, 1.0, 4.0])
def test_mean_nees_is_d_over_rho(rho):
    """E[ε] = d/ρ under pure scaling, Eq. (3); checked within 5 standard errors."""
    rng = np.random.default_rng(1)
    d, n = 3, 200_000
    errors, cov = gaussian_segment(rng, n=n, d=d, rho=rho)
    eps = metrics.nees(errors, cov)
    # ε ρ ~ χ²_d, so sd(mean ε) = sqrt(2d)/ρ/sqrt(n)
    assert abs(eps.mean() - d / rho) < 5 * np.sqrt(2 * d) / rho / np.sqrt(n)
    assert metrics.anees(errors, cov) == pytest.approx(eps.mean() / d)


@pytest.mark.parametrize("rho", [0.1, 0.5, 2.0, 10.0])
def test_nci_is_minus_10_log10_rho_under_pure_scaling(rho, rng):
    """Eq. (5): with M = Σ known, NCI = −10 log10 ρ exactly, epoch by epoch."""
    errors, cov = gaussian_segment(rng, n=100, d=2, rho=rho, varying=True)
    assert metrics.nci(errors, cov, mse=cov / rho) == pytest.approx(-10 * np.log10(rho), abs=1e-10)


def test_nci_accepts_one_mse_matrix_or_one_per_epoch(rng):
    errors, cov = gaussian_segment(rng, n=50, d=3, rho=2.0, varying=True)
    mse = metrics.mse_matrix(errors)
    shared = metrics.nci(errors, cov, mse=mse)
    per_epoch = metrics.nci(errors, cov, mse=np.broadcast_to(mse, cov.shape))
    assert shared == pytest.approx(per_epoch, rel=1e-12)
    assert metrics.nci(errors, cov) == shared  # the default estimates the same matrix


def test_nci_leaves_out_epochs_whose_error_is_exactly_zero(rng):
    """An epoch with e_k = 0 (a filter started at the truth) has ε_k = ε*_k = 0 and no
    ratio in Eq. (4): the NCI is the mean over the other epochs, computed here term by term
    with explicit inverses; NaN when every error is zero. (It was NaN, with a warning that
    numbers overflowed, for one zero epoch.)"""
    errors, cov = gaussian_segment(rng, n=60, d=2, rho=2.0, varying=True)
    errors[[0, 17, 41]] = 0.0
    mse = metrics.mse_matrix(errors)
    terms = [
        np.log10(e @ np.linalg.inv(c) @ e) - np.log10(e @ np.linalg.inv(mse) @ e)
        for e, c in zip(errors, cov)
        if np.any(e != 0)
    ]
    with np.errstate(all="raise"):
        nci = metrics.nci(errors, cov, mse=mse)
    assert len(terms) == 57
    assert nci == pytest.approx(10 * np.mean(terms), rel=1e-10)
    assert np.isnan(metrics.nci(np.zeros((5, 2)), cov[:5], mse=np.eye(2)))


def test_nci_with_estimated_mse_is_close_to_closed_form(rng):
    errors, cov = gaussian_segment(rng, n=5000, d=2, rho=3.0)
    assert metrics.nci(errors, cov) == pytest.approx(-10 * np.log10(3.0), abs=0.1)


def test_nci_non_negative_under_bias(rng):
    """Appendix A: with Σ̂ = Σ and M = Σ + μμᵀ every term of (4) is >= 0."""
    for _ in range(20):
        bias = rng.normal(size=2) * 2
        errors, cov = gaussian_segment(rng, n=200, d=2, bias=bias)
        mse = cov[0] + np.outer(bias, bias)
        eps = metrics.nees(errors, cov)
        eps_star = metrics.nees(errors, np.broadcast_to(mse, cov.shape))
        assert np.all(eps >= eps_star * (1 - 1e-12))
        assert metrics.nci(errors, cov, mse=mse) >= 0


def test_mse_matrix_is_covariance_plus_outer_mean(rng):
    errors = rng.normal(size=(40, 3)) + 1.0
    expected = np.cov(errors.T) + np.outer(errors.mean(0), errors.mean(0))
    np.testing.assert_allclose(metrics.mse_matrix(errors), expected, rtol=1e-12)


def test_nll_matches_scipy_logpdf(rng):
    errors, cov = gaussian_segment(rng, n=30, d=3, varying=True)
    expected = [-stats.multivariate_normal(np.zeros(3), c).logpdf(e) for e, c in zip(errors, cov)]
    np.testing.assert_allclose(metrics.gaussian_nll(errors, cov), expected, rtol=1e-12)
    scaled = [-stats.multivariate_normal(np.zeros(3), 2 * c).logpdf(e) for e, c in zip(errors, cov)]
    np.testing.assert_allclose(metrics.gaussian_nll(errors, cov, scale=2.0), scaled, rtol=1e-12)


@pytest.mark.parametrize("rho", [0.3, 1.0, 3.0])
def test_expected_nll_eq8(rho):
    """E[NLL] = ½(d/ρ + d ln ρ + ln|Σ| + d ln 2π), Eq. (8), within 5 standard errors."""
    rng = np.random.default_rng(2)
    d, n = 2, 200_000
    errors, cov = gaussian_segment(rng, n=n, d=d, rho=rho)
    nll = metrics.gaussian_nll(errors, cov)
    true_logdet = np.linalg.slogdet(cov[0] / rho)[1]
    expected = 0.5 * (d / rho + d * np.log(rho) + true_logdet + d * np.log(2 * np.pi))
    assert abs(nll.mean() - expected) < 5 * nll.std() / np.sqrt(n)


def _crps_gaussian(mu, sigma, y):
    z = (y - mu) / sigma
    return sigma * (
        z * (2 * special.ndtr(z) - 1)
        + 2 * np.exp(-z * z / 2) / np.sqrt(2 * np.pi)
        - 1 / np.sqrt(np.pi)
    )


def test_energy_score_d1_is_gaussian_crps(rng):
    """In d = 1 the energy score is the CRPS, with the closed form of Gneiting & Raftery (2007)."""
    errors = rng.normal(size=(200, 1)) * 3
    sigma = rng.uniform(0.1, 5, 200)
    cov = (sigma**2)[:, None, None]
    # predictive N(x̂, σ²) at truth x = x̂ + e
    np.testing.assert_allclose(
        metrics.energy_score(errors, cov), _crps_gaussian(0.0, sigma, errors[:, 0]), rtol=1e-9
    )


def test_expected_norm_d1_folded_normal(rng):
    m = rng.normal(size=50) * 2
    s = rng.uniform(0.01, 3, 50)
    folded = s * np.sqrt(2 / np.pi) * np.exp(-(m**2) / (2 * s**2)) + m * (
        1 - 2 * special.ndtr(-m / s)
    )
    got = metrics.expected_norm(m[:, None], (s**2)[:, None, None])
    np.testing.assert_allclose(got, folded, rtol=1e-9)


def test_expected_norm_d2_zero_mean_is_elliptic_integral(rng):
    """E‖W‖ for W ~ N(0, diag(a², b²)), a >= b, is √(2/π)·a·E(1 − b²/a²)."""
    a = rng.uniform(0.1, 5, 40)
    b = a * rng.uniform(1e-4, 1, 40)
    rot = rng.uniform(0, np.pi, 40)
    c, s = np.cos(rot), np.sin(rot)
    r = np.stack([np.c_[c, -s], np.c_[s, c]], axis=1)
    cov = r @ (np.eye(2) * np.c_[a**2, b**2][:, None, :]) @ np.swapaxes(r, 1, 2)
    expected = np.sqrt(2 / np.pi) * a * special.ellipe(1 - b**2 / a**2)
    np.testing.assert_allclose(metrics.expected_norm(np.zeros((40, 2)), cov), expected, rtol=1e-9)


def test_expected_norm_d2_with_mean_against_polar_quadrature():
    """Independent reference: the 2-D Gaussian density integrated in polar coordinates."""
    mean = np.array([0.7, -1.3])
    cov = np.array([[2.0, 0.6], [0.6, 0.5]])
    inv = np.linalg.inv(cov)
    norm = 1 / (2 * np.pi * np.sqrt(np.linalg.det(cov)))

    def density(r, th):
        x = np.array([r * np.cos(th), r * np.sin(th)]) - mean
        return norm * np.exp(-0.5 * x @ inv @ x)

    ref, _ = integrate.dblquad(
        lambda r, th: r * r * density(r, th), 0, 2 * np.pi, 0, 40, epsabs=1e-12
    )
    got = metrics.expected_norm(mean[None], cov[None])[0]
    assert got == pytest.approx(ref, rel=1e-8)


def test_energy_score_against_million_sample_monte_carlo():
    rng = np.random.default_rng(3)
    d = 3
    errors = rng.normal(size=(1, d))
    a = rng.normal(size=(d, d))
    cov = (a @ a.T + np.eye(d))[None]
    m = 1_000_000
    y = rng.multivariate_normal(np.zeros(d), cov[0], size=m)  # Y − x̂
    y2 = rng.multivariate_normal(np.zeros(d), cov[0], size=m)
    first = np.linalg.norm(y - errors[0], axis=1)  # ‖Y − x‖ with x = x̂ + e
    second = np.linalg.norm(y - y2, axis=1)
    mc = first.mean() - 0.5 * second.mean()
    se = np.sqrt(first.var() / m + 0.25 * second.var() / m)
    got = metrics.energy_score(errors, cov)[0]
    assert abs(got - mc) < 5 * se


def test_energy_score_is_non_negative_and_scale_equivariant(rng):
    errors, cov = gaussian_segment(rng, n=100, d=4, varying=True)
    es = metrics.energy_score(errors, cov)
    assert np.all(es > 0)
    # ES(kx̂, k²Σ̂; kx) = k·ES (energy score is homogeneous of degree 1 in distance)
    np.testing.assert_allclose(metrics.energy_score(3 * errors, 9 * cov), 3 * es, rtol=1e-9)


def test_energy_score_invariant_to_rotation(rng):
    errors, cov = gaussian_segment(rng, n=50, d=3)
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    rotated = metrics.energy_score(errors @ q.T, q @ cov @ q.T)
    np.testing.assert_allclose(rotated, metrics.energy_score(errors, cov), rtol=1e-9)


def test_fig1_asymmetry_es_penalises_pessimism_nll_optimism():
    """Fig. 1a and Appendix B: at scale ρ and 1/ρ, ES is larger for pessimism (ρ > 1)
    and NLL is larger for optimism (ρ < 1)."""
    rng = np.random.default_rng(4)
    errors = rng.normal(size=(20_000, 2))
    eye = np.broadcast_to(np.eye(2), (20_000, 2, 2))
    for rho in (2.0, 4.0, 8.0):
        es_pess = metrics.energy_score(errors, eye, rho).mean()
        es_opt = metrics.energy_score(errors, eye, 1 / rho).mean()
        nll_pess = metrics.gaussian_nll(errors, eye, rho).mean()
        nll_opt = metrics.gaussian_nll(errors, eye, 1 / rho).mean()
        assert es_pess > es_opt
        assert nll_opt > nll_pess
    # ES is minimised at ρ = 1 (propriety) along the curve of Fig. 1a
    curve = [metrics.energy_score(errors, eye, r).mean() for r in (0.5, 0.8, 1.0, 1.25, 2.0)]
    assert int(np.argmin(curve)) == 2


def test_probes_nll_closed_form(rng):
    """Δ∓NLL from Eq. (7): ½((c^{±1} − 1)·mean ε ∓ d ln c)."""
    errors, cov = gaussian_segment(rng, n=300, d=2, rho=0.5)
    c = 2.0
    p = metrics.probes(errors, cov, c)
    eps = metrics.nees(errors, cov).mean()
    assert p.delta_nll_minus == pytest.approx(0.5 * ((c - 1) * eps - 2 * np.log(c)), rel=1e-10)
    assert p.delta_nll_plus == pytest.approx(0.5 * ((1 / c - 1) * eps + 2 * np.log(c)), rel=1e-10)
    es = [metrics.energy_score(errors, cov, s).mean() for s in (1 / c, 1.0, c)]
    assert p.delta_es_minus == pytest.approx(es[0] - es[1], rel=1e-10)
    assert p.delta_es_plus == pytest.approx(es[2] - es[1], rel=1e-10)
    assert p.srd_nll == pytest.approx(
        (c * abs(p.delta_nll_minus) - abs(p.delta_nll_plus)) / abs(p.delta_nll_plus)
    )


def test_srd_absolute_form():
    assert metrics.srd(-0.1, 1.0, 2.0) == pytest.approx(-0.8)
    assert metrics.srd(-0.1, 1.0, 2.0, absolute=True) == pytest.approx(0.8)


def test_shape_errors_are_reported():
    from credcli.errors import CredcliError

    with pytest.raises(CredcliError, match="cov must have shape"):
        metrics.nees(np.zeros((3, 2)), np.zeros((3, 3, 3)))


def test_expected_norm_against_the_30_digit_reference():
    """Issue 12: the energy score's quadrature stays within 1e-9 relative of a 30-digit
    mpmath reference (tests/data/make_expected_norm_reference.py), eigenvalue ratios to
    1e14, zero and large means, d = 1, 2, 3, 6; for the diagonal covariance of the
    reference, and for the same Gaussian turned by random rotations (the Householder
    reduction then has work to do), the mean's signs drawn at random."""
    import json
    from pathlib import Path

    cases = json.loads(
        (Path(__file__).parent / "data" / "expected_norm_reference.json").read_text()
    )
    rng = np.random.default_rng(12)
    worst = 0.0
    for case in cases:
        lam, nu2 = np.array(case["lam"]), np.array(case["nu2"])
        ref, d = float(case["expected_norm"]), lam.size
        got = metrics.expected_norm(np.sqrt(nu2)[None], np.diag(lam)[None])[0]
        worst = max(worst, abs(got - ref) / ref)
        for _ in range(3):
            q, _ = np.linalg.qr(rng.standard_normal((d, d)))
            mean = q @ (np.sqrt(nu2) * rng.choice([-1.0, 1.0], d))
            got = metrics.expected_norm(mean[None], ((q * lam) @ q.T)[None])[0]
            worst = max(worst, abs(got - ref) / ref)
        if not np.any(nu2):
            worst = max(worst, abs(quadrature.centred_norm(np.diag(lam)[None])[0] - ref) / ref)
    assert worst <= 1e-9, worst


def test_expected_norm_window_ends_early_only_where_the_rest_is_negligible():
    """Each epoch's quadrature window ends at the first candidate node where the neglected
    part is provably below 1e-13; against the whole grid (every node evaluated) the
    difference stays below 1e-12 relative, for well- and ill-conditioned covariances and
    means from 0 to 1e3 standard deviations."""
    rng = np.random.default_rng(5)
    for d in (2, 3, 6):
        n = 2000
        a = rng.standard_normal((n, d, d)) * 10.0 ** rng.uniform(-4, 2, (n, 1, d))
        cov = a @ np.swapaxes(a, 1, 2) + 1e-12 * np.eye(d)
        mean = rng.standard_normal((n, d)) * 10.0 ** rng.uniform(-3, 3, (n, 1))
        mean[::4] = 0.0
        diag, off2, unit = quadrature._tridiagonal(cov, mean)
        mean2 = np.einsum("ni,ni->n", mean, mean) / unit
        got = quadrature._norm_tridiagonal(diag, off2, mean2)
        scale = diag.sum(axis=0) + mean2
        alpha, beta = 2 * diag / scale, 4 * off2 / scale**2
        ends = quadrature._window_ends(alpha, beta, mean2 / scale)
        assert np.unique(ends).size > 1  # the test exercises early ends
        full = quadrature._QUAD_U.size
        second = 1 + 0.5 * (alpha**2).sum(0) + beta.sum(0) + 2 * mean2 / scale * alpha[0]
        whole = quadrature._window_sum(alpha, beta, mean2 / scale, full) + quadrature._UPPER[full]
        whole += quadrature._LOW_FIRST - 0.5 * quadrature._LOW_SECOND * second
        np.testing.assert_allclose(got, whole * np.sqrt(scale), rtol=1e-12, atol=0)


def test_expected_norm_in_one_dimension_is_the_folded_normal_mean():
    """d = 1 is closed: E|W| = σ√(2/π)e^{−μ²/2σ²} + |μ|erf(|μ|/σ√2), checked against
    scipy's foldnorm, and |μ| for σ = 0."""
    from scipy import stats

    mu = np.array([0.0, 0.3, -2.0, 7.5, 1e3, 4.0])
    sd = np.array([1.0, 2.0, 0.5, 1.0, 3.0, 0.0])
    got = metrics.expected_norm(mu[:, None], (sd**2)[:, None, None])
    ref = [stats.foldnorm(abs(m) / s, scale=s).mean() if s else abs(m) for m, s in zip(mu, sd)]
    np.testing.assert_allclose(got, ref, rtol=1e-12)


def test_centred_norm_with_a_zero_eigenvalue_is_the_one_dimensional_norm():
    """A degenerate 2-D Gaussian N(0, diag(0, σ²)) has E‖W‖ = σ√(2/π), whichever axis; so
    does a rank-one 3-D one; and N(0, 0) has 0."""
    cov = np.array([np.diag([0.0, 4.0]), np.diag([4.0, 0.0]), np.zeros((2, 2))])
    np.testing.assert_allclose(
        quadrature.centred_norm(cov), [2 * np.sqrt(2 / np.pi), 2 * np.sqrt(2 / np.pi), 0.0]
    )
    u = np.array([1.0, 2.0, 2.0]) / 3.0
    rank_one = np.array([4.0 * np.outer(u, u), np.zeros((3, 3))])
    np.testing.assert_allclose(
        quadrature.centred_norm(rank_one), [2 * np.sqrt(2 / np.pi), 0.0], rtol=1e-9, atol=1e-300
    )


@pytest.mark.parametrize("d", [1, 2, 3, 6])
def test_energy_score_is_scale_free_at_extreme_scales(d):
    """ES(c·e, c²Σ) = c·ES(e, Σ) for c = 1e±120 (covariances near 1e±240): the closed
    2×2 eigenvalues are taken on each matrix scaled to O(1) (before, a product of two
    entries underflowed to 0 and the 2-D spread term took the smaller eigenvalue as 0),
    and the Householder reduction works in units of the trace."""
    rng = np.random.default_rng(d)
    a = rng.standard_normal((50, d, d))
    cov = a @ np.swapaxes(a, 1, 2) + 0.3 * np.eye(d)
    e = rng.standard_normal((50, d))
    base = metrics.energy_score(e, cov)
    for c in (1e-120, 1e120):
        np.testing.assert_allclose(metrics.energy_score(c * e, c * c * cov), c * base, rtol=1e-12)


def test_accuracy_is_evos_first_figures_per_component_and_of_the_norm(capsys, monkeypatch):
    """Issue 33 item 4: RMSE, mean, median and max error beside credibility, against a
    plain computation, and in every output (JSON, CSV, Markdown, the table)."""
    import json
    import math
    import statistics

    from credcli.cli import main
    from credcli.engine.metrics import accuracy

    e = np.random.default_rng(3).standard_normal((101, 3)) * [1.0, 2.0, 0.5] + [0.3, 0, 0]
    a = accuracy(e)
    rows = e.tolist()
    norms = [math.sqrt(sum(x * x for x in r)) for r in rows]
    for i in range(3):
        column = [r[i] for r in rows]
        assert a.rmse[i] == pytest.approx(math.sqrt(sum(x * x for x in column) / 101), rel=1e-12)
        assert a.mean[i] == pytest.approx(statistics.fmean(column), rel=1e-12)
        assert a.median[i] == pytest.approx(statistics.median(abs(x) for x in column))
        assert a.max[i] == max(abs(x) for x in column)
    assert a.rmse_norm == pytest.approx(math.sqrt(sum(n * n for n in norms) / 101), rel=1e-12)
    assert a.rmse_norm == pytest.approx(math.sqrt((a.rmse**2).sum()), rel=1e-12)
    assert (a.median_norm, a.max_norm) == (statistics.median(norms), max(norms))
    assert a.mean_norm == pytest.approx(statistics.fmean(norms), rel=1e-12)
    from helpers import ROOT

    log = "sample_data/estimator_log.csv"
    monkeypatch.chdir(ROOT)
    assert main(["diagnose", log, "-f", "json"]) == 0
    first = json.loads(capsys.readouterr().out)["segments"][0]
    assert first["rmse"] == pytest.approx(math.sqrt(sum(v**2 for v in first["rmse_by_component"])))
    for fmt, header in (("csv", "error_norm_max"), ("markdown", "RMSE"), ("table", "RMSE")):
        assert main(["diagnose", log, "-f", fmt]) == 0
        assert header in capsys.readouterr().out


def test_logs_are_compared_by_their_accuracy(tmp_path, capsys, monkeypatch):
    """Issue 33 item 4, across runs as evo_res: each log's entry carries the accuracy of all
    its epochs, and two or more logs get a table side by side."""
    import json

    import pandas as pd
    from helpers import ROOT

    from credcli.cli import main

    monkeypatch.chdir(ROOT)
    logs = ["sample_data/estimator_log.csv", "sample_data/estimator_log_regressed.csv"]
    assert main(["diagnose", *logs, "-f", "json"]) == 0
    entries = json.loads(capsys.readouterr().out)["logs"]
    for path, entry in zip(logs, entries):
        frame = pd.read_csv(path)
        e = frame[["truth_0", "truth_1"]].to_numpy() - frame[["est_0", "est_1"]].to_numpy()
        norms = np.linalg.norm(e, axis=1)
        assert entry["rmse"] == pytest.approx(np.sqrt(np.mean(norms**2)), rel=1e-12)
        assert entry["error_norm_max"] == pytest.approx(norms.max(), rel=1e-12)
        assert entry["error_mean"] == pytest.approx(e.mean(axis=0).tolist(), rel=1e-12)
    assert main(["diagnose", *logs, "-f", "markdown"]) == 0
    markdown = capsys.readouterr().out
    assert "### logs compared" in markdown and "| 1800 | 1 of 6 |" in markdown


@pytest.mark.parametrize(
    "lengths", [[1, 2, 3, 4, 1, 2], [1, 2, 3, 4, 5, 1000, 999], [100_000], [5000, 4001, 1, 2]]
)
def test_grouped_accuracy_equals_numpy_per_group(lengths):
    """Both ways of taking grouped medians (one sort for many short groups, a partition per
    group for long ones) and the grouped sums give each group's numpy figures."""
    lengths = np.array(lengths)
    errors = np.random.default_rng(len(lengths)).standard_normal((lengths.sum(), 3))
    starts = np.r_[0, np.cumsum(lengths)[:-1]]
    for a, start, length in zip(metrics.grouped_accuracy(errors, lengths), starts, lengths):
        e = errors[start : start + length]
        norms = np.linalg.norm(e, axis=1)
        np.testing.assert_array_equal(a.median, np.median(np.abs(e), axis=0))
        assert a.median_norm == pytest.approx(np.median(norms), rel=1e-12)
        np.testing.assert_allclose(a.rmse, np.sqrt(np.mean(e**2, axis=0)), rtol=1e-12)
        assert a.max_norm == pytest.approx(norms.max(), rel=1e-12)


def test_accuracy_of_errors_whose_squares_leave_float64_is_exact():
    """A group of errors of 2^700 or 2^-700 (their squares over- or underflow) has the
    figures of the same errors at unit scale times 2^±700, to the bit, beside a group at
    unit scale whose figures are untouched; RMSE and the norms were inf or 0 before."""
    e = np.random.default_rng(5).standard_normal((12, 2))
    plain = metrics.grouped_accuracy(e, np.array([4, 8]))
    for shift in (700, -700):
        scaled = e.copy()
        scaled[4:] *= 2.0**shift
        ones, far = metrics.grouped_accuracy(scaled, np.array([4, 8]))
        for name in (
            "rmse",
            "mean",
            "median",
            "max",
            "rmse_norm",
            "mean_norm",
            "median_norm",
            "max_norm",
        ):
            np.testing.assert_array_equal(getattr(ones, name), getattr(plain[0], name))
            np.testing.assert_array_equal(
                getattr(far, name), np.multiply(getattr(plain[1], name), 2.0**shift)
            )


@pytest.mark.parametrize("func", [metrics.expected_norm, metrics.energy_score])
def test_a_covariance_that_is_not_positive_definite_is_named(func):
    """E‖W‖ of an indefinite "covariance" is not a number to return (it gave 0 before);
    a singular one is a degenerate Gaussian and stays allowed."""
    from credcli.errors import CredcliError

    cov = np.array([np.eye(2), np.diag([1.0, -1.0])])
    with pytest.raises(CredcliError, match=r"cov\[1\] is not positive semidefinite"):
        func(np.zeros((2, 2)), cov)
    assert np.all(np.isfinite(func(np.ones((2, 2)), np.array([np.eye(2), np.zeros((2, 2))]))))


def test_curve_scales_hold_each_scale_once():
    """geomspace(1/4, 4, 17) holds 2 less one ulp; with c = 2 it was listed twice."""
    from credcli.engine.curves import PROBE_CURVE_SCALES, curve_scales

    for c in (1.5, 2.0, 3.0, 4.0):
        scales = curve_scales(c)
        assert np.all(np.diff(np.log(scales)) > 1e-6)  # no two within a part in a million
        for s in (1 / c, 1.0, c):
            assert s in scales  # the probes themselves, exactly
        lo, hi, _ = PROBE_CURVE_SCALES
        assert scales[0] == min(lo, 1 / c) and scales[-1] == max(hi, c)


def test_argument_errors_of_engine_helpers_are_credcli_errors():
    from credcli.engine.correlation import block_length
    from credcli.engine.curves import running_mean
    from credcli.engine.whiteness import portmanteau
    from credcli.errors import CredcliError

    with pytest.raises(CredcliError, match="lags must be between"):
        portmanteau(np.random.default_rng(0).standard_normal((20, 2)), lags=20)
    with pytest.raises(CredcliError, match="running mean's window must be between"):
        running_mean(np.ones(3), 4)
    with pytest.raises(CredcliError, match="loss must be in"):
        block_length(2.0, loss=1.5)


def test_a_long_groups_median_column_by_column_is_the_row_partitions(monkeypatch):
    """From COLUMN_PARTITION rows a group's median is taken column by column: the same
    order statistics, to the bit, as one partition of its rows (ties, NaN and −0 among
    them), and numpy's median where there is no NaN."""
    rng = np.random.default_rng(9)
    values = np.round(rng.standard_normal((metrics.COLUMN_PARTITION + 1001, 3)), 1)
    values[::97, 0] = -0.0
    lengths = np.array([values.shape[0] - 5, 5])
    starts = np.r_[0, lengths[0]]
    columns = metrics._grouped_median(list(values.T), starts, lengths)
    np.testing.assert_array_equal(columns[0], np.median(values[: lengths[0]], axis=0))
    values[::501, 2] = np.nan
    columns = metrics._grouped_median(list(values.T), starts, lengths)
    monkeypatch.setattr(metrics, "COLUMN_PARTITION", 10**9)
    rows = metrics._grouped_median(list(values.T), starts, lengths)
    np.testing.assert_array_equal(columns, rows)
    assert np.array_equal(np.signbit(columns), np.signbit(rows))
