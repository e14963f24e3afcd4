"""The dependence model (credcli.engine.memory): Burg's recursion against statsmodels,
autocovariances and finite-sample moments against closed forms and brute force, the order
chosen by AICc, the estimation error's degrees of freedom against a Monte Carlo, and the
tests built on the model at their level."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.linalg import toeplitz
from scipy.signal import lfilter

from credcli.engine import memory as mem


def _ar(a, n, rng, burn=5000, cols=1):
    """A stationary AR series (n, cols) with denominator polynomial ``a``, unit innovations."""
    return lfilter([1.0], a, rng.standard_normal((n + burn, cols)), axis=0)[burn:]


def test_burg_matches_statsmodels():
    """The coefficients are statsmodels' to 1e-8; the innovation variance is the recursion's
    Π(1 − k_j²)γ̂(0), within 1 % of the one-step prediction error of the fitted filter."""
    from statsmodels.regression.linear_model import burg

    rng = np.random.default_rng(0)
    x = _ar([1, -1.6, 0.8], 3000, rng)[:, 0]
    x = x - x.mean()
    fit = mem.burg(x.reshape(1, 1, -1), 4)
    for order in (1, 2, 4):
        ref_phi, ref_sigma2 = burg(x, order, demean=False)
        phi = fit.coefficients(0, order)
        np.testing.assert_allclose(phi, ref_phi, rtol=1e-8, atol=1e-10)
        residual = lfilter(np.r_[1.0, -phi], [1.0], x)[order:]
        assert fit.variance[0, order] == pytest.approx(np.mean(residual**2), rel=1e-2)
        assert fit.variance[0, order] == pytest.approx(ref_sigma2, rel=1e-2)


def test_burg_pools_segments_as_one_model():
    """Two segments pooled: the same model as statsmodels gets from neither alone, but the
    reflection equals the pooled ratio of sums (checked at order 1 by hand)."""
    rng = np.random.default_rng(1)
    x = _ar([1, -0.7], 400, rng, cols=2).T  # two segments
    x = x - x.mean(axis=1, keepdims=True)
    fit = mem.burg(x[None], 1)
    num = -2.0 * sum(float(seg[1:] @ seg[:-1]) for seg in x)
    den = sum(float(seg[1:] @ seg[1:] + seg[:-1] @ seg[:-1]) for seg in x)
    assert fit.reflection[0, 0] == pytest.approx(num / den, rel=1e-12)


@pytest.mark.parametrize("ar", [[1, -0.9], [1, -1.6, 0.8], [1, -1.9, 0.9025], [1, -0.5, 0.3, -0.2]])
def test_autocovariance_of_ar_matches_statsmodels(ar):
    from statsmodels.tsa.arima_process import arma_acovf

    phi = -np.asarray(ar[1:], dtype=float)
    ours = mem.autocovariance_of_ar(phi, 2.0, 300)
    ref = arma_acovf(np.asarray(ar, float), np.array([1.0]), nobs=300, sigma2=2.0)
    np.testing.assert_allclose(ours, ref, rtol=1e-7, atol=1e-9 * abs(ref[0]))


@pytest.mark.parametrize("ar", [[1, -0.9], [1, -1.6, 0.8], [1, -0.5, 0.3, -0.2]])
def test_the_autocovariance_in_chunks_of_lags_is_the_recursion(ar, monkeypatch):
    """Past RECURSION_CHUNK lags the recursion runs in chunks, each continuing from the
    lags before it: chunks of 7 and 64 lags against statsmodels over 300 lags, and the
    first chunk the bits of one pass."""
    from statsmodels.tsa.arima_process import arma_acovf

    phi = -np.asarray(ar[1:], dtype=float)
    whole = mem.autocovariance_of_ar(phi, 2.0, 300)
    ref = arma_acovf(np.asarray(ar, float), np.array([1.0]), nobs=300, sigma2=2.0)
    for chunk in (7, 64):
        monkeypatch.setattr(mem, "RECURSION_CHUNK", chunk)
        chunked = mem.autocovariance_of_ar(phi, 2.0, 300)
        np.testing.assert_allclose(chunked, ref, rtol=1e-7, atol=1e-9 * abs(ref[0]))
        first = phi.size + 1 + chunk
        np.testing.assert_array_equal(chunked[:first], whole[:first])


def test_a_high_order_autocovariance_over_a_long_segment_holds_no_band_of_its_length():
    """A model of order 53 kept over 2^20 lags (a segment of 2,000,000 epochs keeps that
    many): LAPACK's banded solve held 54 rows of every lag (a peak of 880 MiB as
    tracemalloc counts numpy's allocations; a 2M-epoch segment of such errors peaked at
    1.47 GB of RSS); in chunks the peak is 63 MiB, the result and one chunk's band."""
    import tracemalloc

    phi = mem.ar_coefficients(np.full(53, 0.3) * 0.97 ** np.arange(53))
    lags = 1 << 20
    tracemalloc.start()
    try:
        gamma = mem.autocovariance_of_ar(phi, 1.0, lags)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert np.isfinite(gamma).all() and gamma[0] > 0
    band = 54 * mem.RECURSION_CHUNK * 8
    assert 3 * lags * 8 + 2 * band < 54 * lags * 8 / 4  # (the bound can tell the two apart)
    assert peak < 3 * lags * 8 + 2 * band


def test_ar1_variance_ratio_and_block_loss_closed_form():
    """AR(1): τ = (1 + φ)/(1 − φ) and G/Ω = (τ² − 1)/(2τ) (Politis & White 2004)."""
    phi = 0.9
    gamma = mem.autocovariance_of_ar(np.array([phi]), 1.0, 5000)
    m = mem.SeriesMemory(np.array([phi]), gamma / gamma[0], math.inf)
    tau = (1 + phi) / (1 - phi)
    assert m.variance_ratio == pytest.approx(tau, rel=1e-9)
    assert m.block_loss() == pytest.approx((tau**2 - 1) / (2 * tau), rel=1e-9)


@pytest.mark.parametrize("n", [7, 50, 333])
def test_finite_sample_moments_against_brute_force(n):
    """v_n = 1ᵀR1/n; E and Var of the centred sum of squares = tr(CR), 2 tr((CRC)²)."""
    gamma = mem.autocovariance_of_ar(np.array([1.2, -0.5]), 1.0, 2000)
    rho = gamma / gamma[0]
    m = mem.SeriesMemory(np.array([1.2, -0.5]), rho, math.inf)
    r = toeplitz(rho[:n])
    c = np.eye(n) - np.ones((n, n)) / n
    crc = c @ r @ c
    assert m.mean_ratio(n) == pytest.approx(r.sum() / n, rel=1e-10)
    mean, var = m.centred_square_moments(n)
    assert mean == pytest.approx(np.trace(c @ r), rel=1e-10)
    assert var == pytest.approx(2 * np.trace(crc @ crc), rel=1e-10)


def test_centred_square_moments_against_monte_carlo():
    """The exact moments of a window's centred sum of squares against 20,000 windows of a
    slow AR(1) (φ = 0.98, windows of 40 epochs: centring removes most of the variance)."""
    rng = np.random.default_rng(3)
    phi, n = 0.98, 40
    x = _ar([1, -phi], n * 20_000, rng, burn=2000)[:, 0] * math.sqrt(1 - phi**2)
    w = x.reshape(-1, n)
    ss = ((w - w.mean(axis=1, keepdims=True)) ** 2).sum(axis=1)
    gamma = mem.autocovariance_of_ar(np.array([phi]), 1 - phi**2, 5000)
    mean, var = mem.SeriesMemory(np.array([phi]), gamma, math.inf).centred_square_moments(n)
    se_mean = ss.std() / math.sqrt(ss.size) * math.sqrt(40)  # windows overlap in memory
    assert abs(ss.mean() - mean) < 4 * se_mean
    assert mean < 0.5 * n  # the slow part is removed: far below n − 1
    assert ss.var() == pytest.approx(var, rel=0.15)


@pytest.mark.parametrize(
    ("ar", "ma", "order_at_least"),
    [([1, -1.6, 0.8], [1], 2), ([1, -1.9, 0.9025], [1], 2), ([1, -0.9], [1, -0.5], 2)],
)
def test_sieve_recovers_the_long_run_variance(ar, ma, order_at_least):
    """Oscillating AR(2), smooth AR(2) (lag-1 near 1, τ 78) and ARMA(1,1): τ̂ of 10 series
    of 20,000 epochs within 10 % of the exact τ (median), where a lag-1 AR(1) reading
    is off by 4× or more."""
    from statsmodels.tsa.arima_process import arma_acovf

    rng = np.random.default_rng(4)
    ar, ma = np.asarray(ar, float), np.asarray(ma, float)
    gamma = arma_acovf(ar, ma, nobs=200_000)
    tau = 1 + 2 * gamma[1:].sum() / gamma[0]
    taus, orders = [], []
    for _ in range(10):
        x = lfilter(ma, ar, rng.standard_normal(25_000))[5000:]
        x = x / math.sqrt(gamma[0])
        m = mem.fit_memory(x[:, None], x**2)
        taus.append(m.series[0].variance_ratio)
        orders.append(m.series[0].order)
    assert np.median(taus) == pytest.approx(tau, rel=0.1)
    assert min(orders) >= order_at_least


def test_model_dof_matches_the_spread_of_the_estimate():
    """ν_Ω = 2/Var(log τ̂) from the parametric bootstrap against the spread of log τ̂ over
    200 AR(1) series (φ = 0.8, N = 1,000), within 30 % (the Monte Carlo's own error is
    ~10 %, the bootstrap's 22 %); and the bias-corrected τ̂ is within 10 % of τ = 9."""
    rng = np.random.default_rng(5)
    logs, dofs = [], []
    for _ in range(200):
        x = _ar([1, -0.8], 1000, rng)[:, 0] * 0.6
        m = mem.fit_memory(x[:, None], x**2)
        logs.append(math.log(m.series[0].variance_ratio))
        dofs.append(m.series[0].dof)
    assert np.median(dofs) == pytest.approx(2.0 / np.var(logs), rel=0.3)
    assert math.exp(np.median(logs)) == pytest.approx(9.0, rel=0.1)


@pytest.mark.parametrize("n", [mem.BOOTSTRAP_EPOCHS, 16 * mem.BOOTSTRAP_EPOCHS])
def test_bootstrap_spread_of_long_runs_follows_the_closed_form(n):
    """Var(log τ̂) of an AR(1) fitted as an AR(1) is 4/((1 − φ²)N) to first order
    (τ = (1 + φ)/(1 − φ), Var φ̂ = (1 − φ²)/N): the bootstrap gives it at its full length
    and, 16 times longer, from series of BOOTSTRAP_EPOCHS scaled to N (unscaled it would
    be 16 times too large). Within 60 %: 40 replicates are within ±22 % at one standard
    error."""
    phi = 0.5
    var_log, bias, _ = mem.bootstrap_spread([np.array([phi])], n, 1, seed=3, minimum=1)
    assert var_log[0] == pytest.approx(4.0 / ((1.0 - phi**2) * n), rel=0.6)
    assert abs(bias[0]) < 3.0 * math.sqrt(var_log[0])


def test_principal_directions_separate_a_slow_and_a_white_direction():
    """A slow AR(1) along (1, 1)/√2 and white noise along (1, −1)/√2: the first direction
    found is the slow one, and its τ is the slow one's."""
    rng = np.random.default_rng(6)
    n, phi = 5000, 0.95
    slow = _ar([1, -phi], n, rng)[:, 0] * math.sqrt(1 - phi**2)
    white = rng.standard_normal(n)
    v = np.array([[1, 1], [1, -1]]) / math.sqrt(2)
    s = np.c_[slow, white] @ v.T
    m = mem.fit_memory(s, (s**2).sum(axis=1))
    assert abs(abs(float(m.directions[:, 0] @ v[:, 0])) - 1) < 0.01
    assert m.series[0].variance_ratio == pytest.approx((1 + phi) / (1 - phi), rel=0.3)
    assert m.series[1].variance_ratio < 1.4  # white: AR(1) at least, bias-corrected upwards


def test_a_short_slow_direction_is_found_beside_a_white_one():
    """Issue 30, one slow and one white direction in 50-epoch segments (AR(1) φ 0.98,
    τ 99, along (1, 1)/√2; white noise across it): centring takes most of the slow
    direction's variance, so the long-run covariance's eigenvectors alone mix the two (44
    of 200 segments within 10° of the slow axis, measured); rotated to diagonalise the
    lag-0 and the long-run covariance together, 191 of 200. Here: at least 90 of 100,
    slowest first, and the directions are orthonormal."""
    rng = np.random.default_rng(11)
    v = np.array([[1.0, 1.0], [1.0, -1.0]]) / math.sqrt(2)
    found = 0
    for _ in range(100):
        slow = _ar([1, -0.98], 50, rng, burn=600)[:, 0] * math.sqrt(1 - 0.98**2)
        directions = mem.principal_directions(np.c_[slow, rng.standard_normal(50)] @ v.T)
        np.testing.assert_allclose(directions.T @ directions, np.eye(2), atol=1e-12)
        found += abs(float(directions[:, 0] @ v[:, 0])) > math.cos(math.radians(10))
    assert found >= 90, found


def test_joint_rotation_diagonalises_matrices_with_common_eigenvectors():
    """Three symmetric 5 × 5 matrices with one random orthonormal eigenbasis: the rotation
    found makes each diagonal to 1e-9 (the eigenbasis up to order and sign); with a
    noise matrix added to one, the sum of squared off-diagonal entries at the rotation
    found is no larger than at the true basis (the rotation minimises it)."""
    rng = np.random.default_rng(2)
    q = np.linalg.qr(rng.standard_normal((5, 5)))[0]
    m = np.stack([q @ np.diag(rng.uniform(0.5, 5.0, 5)) @ q.T for _ in range(3)])
    v = mem.joint_rotation(m)
    np.testing.assert_allclose(v.T @ v, np.eye(5), atol=1e-12)
    for k in range(3):
        rotated = v.T @ m[k] @ v
        assert np.max(np.abs(rotated - np.diag(np.diag(rotated)))) < 1e-9

    def off(mats, basis):
        r = np.einsum("ji,kjl,lm->kim", basis, mats, basis)
        return float(np.sum(r**2) - np.sum(np.einsum("kii->ki", r) ** 2))

    noise = rng.standard_normal((5, 5)) * 0.05
    noisy = m.copy()
    noisy[0] += noise + noise.T
    assert off(noisy, mem.joint_rotation(noisy)) <= off(noisy, q) + 1e-12


@settings(max_examples=40, deadline=None)
@given(
    d=st.integers(2, 6),
    seed=st.integers(0, 2**32 - 1),
    constant=st.booleans(),
)
def test_principal_directions_are_orthonormal_for_any_errors(d, seed, constant):
    """Any d, any scales, a component without variance (Γ₀ singular)."""
    rng = np.random.default_rng(seed)
    s = _ar([1, -0.7], 80, rng, burn=50, cols=d) * rng.uniform(0.01, 100.0, d)
    if constant:
        s[:, 0] = 3.0
    directions = mem.principal_directions(s)
    np.testing.assert_allclose(directions.T @ directions, np.eye(d), atol=1e-9)


@settings(max_examples=150, deadline=None)
@given(
    runs=st.integers(1, 3),
    t=st.integers(1, 90),
    width=st.integers(1, 40),
    d=st.integers(1, 3),
    seed=st.integers(0, 2**32 - 1),
)
def test_moving_sums_in_place_are_the_cumulative_sums_differences(runs, t, width, d, seed):
    """The in-place moving sums are, bit for bit, C_{k+w−1} − C_{k−1} of a separate
    cumulative sum (the form principal_directions used before), at every length, the
    lengths shorter than the window included."""
    x = np.random.default_rng(seed).standard_normal((runs, t, d)) * 1e3
    c = np.cumsum(x, axis=1)
    expected = np.empty((runs, max(t - width + 1, 0), d))
    expected[:, :1] = c[:, width - 1 : width]
    np.subtract(c[:, width:], c[:, : max(t - width, 0)], out=expected[:, 1:])
    got = mem.moving_sums(x.copy(), width)
    assert got.shape == expected.shape
    np.testing.assert_array_equal(got, expected)


def test_max_order_follows_schwert():
    assert mem.max_order(100) == 12
    assert mem.max_order(20) == 5  # at most N/4
    assert mem.max_order(10_000) == 38
    assert mem.max_order(10**9) == mem.MAX_ORDER_CAP


def test_burg_in_chunks_equals_burg_in_one_pass(monkeypatch):
    """Burg's in-place update runs in chunks of epochs on long runs; chunks of 7 epochs give
    the reflection coefficients and variances of one chunk, to the bit (the same
    operations on the same numbers, in the same order per epoch)."""
    x = _ar([1, -1.2, 0.5], 300, np.random.default_rng(4)).T.reshape(1, 3, 100)
    x = x - x.mean(axis=2, keepdims=True)
    whole = mem.burg(x, 12)
    monkeypatch.setattr(mem, "BURG_CHUNK", 7)
    chunked = mem.burg(x, 12)
    np.testing.assert_array_equal(whole.reflection, chunked.reflection)
    np.testing.assert_array_equal(whole.variance, chunked.variance)


@pytest.mark.parametrize("lags", [1, 5, 32, 33, 200])
def test_toeplitz_form_equals_the_dense_quadratic_form(lags):
    """The mean test's Cov(Σ g_k), lag by lag up to DIRECT_LAGS and by one FFT convolution
    beyond, against Mᵀ R M with the dense Toeplitz R (lags past the kernel and past N count
    as 0)."""
    from credcli.engine import batches

    gen = np.random.default_rng(lags)
    m = gen.standard_normal((150, 3))
    rho = 0.9 ** np.arange(lags)
    column = np.zeros(150)
    column[: min(lags, 150)] = rho[:150]
    dense = m.T @ toeplitz(column) @ m
    np.testing.assert_allclose(batches.toeplitz_form(m, rho), dense, rtol=1e-12, atol=1e-10)


def test_square_ratios_match_the_sum_of_squared_autocorrelations():
    """τ₂ = Σ_h ρ(h)² (h over all integers) of AR models from their reflection coefficients,
    on each model's own spectral grid, against the autocorrelation recursion summed to
    20,000 lags: white, short and persistent models (largest root modulus 0.1 … 0.97) in
    one call, so that several grid sizes meet."""
    gen = np.random.default_rng(8)
    reflection = np.concatenate(
        [np.zeros((1, 4)), gen.uniform(-0.6, 0.6, (12, 4)), gen.uniform(0.9, 0.97, (4, 4))]
    )
    orders = np.r_[0, gen.integers(1, 5, 12), 1, 2, 3, 4]
    got = mem._square_ratios(reflection, orders)
    for row, order, value in zip(reflection, orders, got):
        a = np.array([1.0])
        for k in row[:order]:  # Levinson's step-up, written out
            a = np.r_[a, 0.0] + k * np.r_[a, 0.0][::-1]
        gamma = mem.autocovariance_of_ar(-a[1:], 1.0, 20_000)
        rho = gamma / gamma[0]
        assert value == pytest.approx(2.0 * np.sum(rho**2) - 1.0, rel=1e-11)


@pytest.mark.parametrize("phi", [0.99, -0.999, 0.999, 0.9999, 0.99999])
def test_square_ratio_of_a_persistent_ar1_is_its_closed_form(phi):
    """τ₂ = Σ_h φ^{2|h|} = (1 + φ²)/(1 − φ²) of an AR(1), however near the unit circle: the
    4,096-point grid left it 10 % off at 0.999 and 60 % off at 0.9999 (its aliasing);
    such models are summed in the time domain (memory._square_sums)."""
    got = mem._square_ratios(np.array([[-phi, 0.0]]), np.array([1]))[0]
    assert got == pytest.approx((1 + phi**2) / (1 - phi**2), rel=1e-9)


def test_square_ratios_near_the_unit_circle_match_a_fine_spectral_grid():
    """Models of order 2–5 with reflection coefficients within 10⁻⁴ … 10⁻² of ±1 (largest
    root modulus 0.986 … 0.9995, oscillating ones included), against mean(f²)/mean(f)² on
    2²² frequencies, whose aliasing (r^G) is below 10⁻³⁰⁰ there. The tolerance is the
    conditioning of such a polynomial, not the sum's: the reflection coefficients and the
    polynomial they give differ in their last bits, which moves τ₂ by up to about 10⁻⁶."""
    gen = np.random.default_rng(12)
    checked = 0
    while checked < 12:
        order = int(gen.integers(2, 6))
        k = gen.uniform(-0.9, 0.9, order)
        near = gen.choice(order, size=int(gen.integers(1, 3)), replace=False)
        k[near] = np.sign(k[near]) * (1 - 10 ** gen.uniform(-4, -2, near.size))
        a = np.array([1.0])
        for kj in k:  # Levinson's step-up, written out
            a = np.r_[a, 0.0] + kj * np.r_[a, 0.0][::-1]
        companion = np.diag(np.ones(order - 1), -1)
        companion[0] = -a[1:]
        if not 0.986 < np.max(np.abs(np.linalg.eigvals(companion))) < 0.9995:
            continue
        points = 1 << 22
        f = 1.0 / np.abs(np.fft.rfft(a, points)) ** 2
        weights = np.r_[1.0, np.full(points // 2 - 1, 2.0), 1.0] / points
        want = (f**2 @ weights) / (f @ weights) ** 2
        got = mem._square_ratios(k[None, :], np.array([order]))[0]
        assert got == pytest.approx(want, rel=1e-5)
        checked += 1


def test_square_sums_equal_the_spectral_ratio_where_both_apply():
    """The time-domain sum (Levinson backwards, then Smith's doubling) against the grid's
    ratio on models the grid resolves (roots within 0.97): two independent computations."""
    gen = np.random.default_rng(9)
    for order in range(1, 6):
        k = np.concatenate([gen.uniform(-0.6, 0.6, (8, order)), gen.uniform(0.9, 0.95, (2, order))])
        want = mem._square_ratios(k, np.full(k.shape[0], order))
        np.testing.assert_allclose(2.0 * mem._square_sums(k) - 1.0, want, rtol=1e-11)


def test_a_unit_root_has_no_finite_square_ratio():
    """A refit on the unit circle (k = ±1: powers of the companion matrix that never die
    out) has τ₂ = ∞, which leaves the bootstrap's spread of τ₂ unbounded."""
    reflection = np.array([[-1.0, 0.0], [0.5, -1.0], [-0.5, 0.0]])
    got = mem._square_ratios(reflection, np.array([1, 2, 1]))
    assert np.isinf(got[:2]).all()
    assert got[2] == pytest.approx((1 + 0.25) / (1 - 0.25), rel=1e-12)


@pytest.mark.parametrize("phi", [[0.5], [1.6, -0.8], [0.3, 0.2, -0.1, 0.05]])
def test_ar_filter_is_the_ar_recursion(phi):
    """x_t = Σ_j φ_j x_{t−j} + z_t from a zero state, per column, against the recursion
    written out; short inputs (fewer epochs than the order) included."""
    phi = np.array(phi)
    z = np.random.default_rng(phi.size).standard_normal((300, 3))
    want = np.zeros_like(z)
    for t in range(z.shape[0]):
        want[t] = z[t] + sum(phi[j] * want[t - 1 - j] for j in range(phi.size) if t - 1 - j >= 0)
    np.testing.assert_allclose(mem.ar_filter(phi, z), want, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(mem.ar_filter(phi, z[:2, 0]), want[:2, 0], rtol=1e-12)


@pytest.mark.parametrize("phi", [[], [0.8], [1.6, -0.8]])
def test_stationary_draws_are_one_draw_taken_in_chunks(phi, monkeypatch):
    """The bootstrap's series, drawn in chunks of whole rows (here one to three rows of 23
    epochs, burn-in included), are the bits of one draw of every row, each filtered from a
    zero state and cut after its burn-in (the recursion written out)."""
    phi = np.array(phi, dtype=float)
    z = np.random.default_rng(9).standard_normal((7, 23))
    want = np.zeros_like(z)
    for t in range(z.shape[1]):
        want[:, t] = z[:, t] + sum(phi[j] * want[:, t - 1 - j] for j in range(phi.size) if t > j)
    monkeypatch.setattr(mem, "DRAWN_AT_ONCE", 60)  # two rows of 23 epochs at a time
    got = mem.stationary_draws(phi, np.random.default_rng(9), 7, 15, 8)
    np.testing.assert_allclose(got, want[:, 8:], rtol=1e-12, atol=1e-12)
    monkeypatch.setattr(mem, "DRAWN_AT_ONCE", 1)  # a row at a time
    again = mem.stationary_draws(phi, np.random.default_rng(9), 7, 15, 8)
    monkeypatch.setattr(mem, "DRAWN_AT_ONCE", 1 << 22)  # all at once
    np.testing.assert_array_equal(
        again, mem.stationary_draws(phi, np.random.default_rng(9), 7, 15, 8)
    )


@pytest.mark.parametrize("phi", [[0.9995], [1.97, -0.9704], [1.2, -0.1, -0.1025]])
def test_a_slow_models_series_start_from_its_stationary_law(phi, monkeypatch):
    """Past EXACT_START_BEYOND epochs of decay, the bootstrap draws no burn-in: the first
    p values are L z (L Lᵀ = Γ_p, the Toeplitz of γ(0) … γ(p − 1)) and the rest follow the
    recursion with the draws as innovations, every value taken from the generator in
    order (in chunks of whole rows, the same bits), and nothing more drawn."""
    phi = np.array(phi)
    p = phi.size
    assert mem.decay_horizon(phi, 0) > mem.EXACT_START_BEYOND
    gamma = mem.autocovariance_of_ar(phi, 1.0, p)
    factor = np.linalg.cholesky(gamma[np.abs(np.subtract.outer(np.arange(p), np.arange(p)))])
    gen, copy = np.random.default_rng(4), np.random.default_rng(4)
    monkeypatch.setattr(mem, "DRAWN_AT_ONCE", 25)  # two rows of 12 epochs at a time
    x = mem.stationary_draws(phi, gen, 5, 12)
    z = copy.standard_normal((5, 12))
    assert gen.standard_normal() == copy.standard_normal()  # no burn-in drawn
    np.testing.assert_allclose(x[:, :p], z[:, :p] @ factor.T, rtol=1e-12)
    innovations = x[:, p:] - sum(phi[j] * x[:, p - 1 - j : 12 - 1 - j] for j in range(p))
    np.testing.assert_allclose(innovations, z[:, p:], rtol=1e-9, atol=1e-9 * np.abs(x).max())
    monkeypatch.setattr(mem, "DRAWN_AT_ONCE", 1 << 22)
    np.testing.assert_array_equal(x, mem.stationary_draws(phi, np.random.default_rng(4), 5, 12))
    # series shorter than the order: the first epochs of the start (L's leading block)
    short = mem.stationary_draws(phi, np.random.default_rng(4), 5, 2)
    z = np.random.default_rng(4).standard_normal((5, 2))
    m = min(p, 2)
    np.testing.assert_allclose(short[:, :m], z[:, :m] @ factor[:m, :m].T, rtol=1e-12)


@pytest.mark.parametrize("phi", [[0.9995], [1.97, -0.9704]])
def test_a_slow_models_series_have_its_autocovariance(phi):
    """Monte Carlo: 4,000 series of 8 epochs of a slow model, each whitened by the
    Cholesky factor of its n × n autocovariance (from ``autocovariance_of_ar``), have
    standardised values of mean square 1 (standard error √(2/32,000) = 0.8 %) and sample
    correlations of zero (standard error 1/√4,000) between every pair of epochs, the
    first epochs' included: the series are stationary from their first value, where a
    burn-in from a zero state short of the decay would leave the first values too small."""
    phi, n, rows = np.array(phi), 8, 4000
    x = mem.stationary_draws(phi, np.random.default_rng(11), rows, n)
    gamma = mem.autocovariance_of_ar(phi, 1.0, n)
    chol = np.linalg.cholesky(gamma[np.abs(np.subtract.outer(np.arange(n), np.arange(n)))])
    w = np.linalg.solve(chol, x.T).T  # iid N(0, 1) under the model
    assert abs(np.mean(w**2) - 1.0) < 4 * np.sqrt(2.0 / w.size)
    assert np.all(np.abs(np.mean(w**2, axis=0) - 1.0) < 4.5 * np.sqrt(2.0 / rows))
    corr = np.corrcoef(w.T)[np.triu_indices(n, 1)]
    assert np.max(np.abs(corr)) < 4.5 / np.sqrt(rows)


def test_a_model_without_a_stationary_factor_takes_the_burn_in():
    """Where Γ_p is singular (a root on the unit circle to working precision), there is no
    stationary law to start from: the factor is None and the series take the burn-in, the
    generator advanced by every value of it."""
    phi = np.array([1.0])
    assert mem.stationary_factor(phi) is None
    assert mem.stationary_factor(np.array([0.6])).tolist() == [[1.25]]  # 1/(1 − 0.36) = 1.25²
    gen, copy = np.random.default_rng(2), np.random.default_rng(2)
    x = mem.stationary_draws(phi, gen, 2, 5)
    z = copy.standard_normal((2, 5 + mem.MAX_BURN_IN))
    np.testing.assert_allclose(x, np.cumsum(z, axis=1)[:, -5:], rtol=1e-9)
    assert gen.standard_normal() == copy.standard_normal()


def test_a_burn_in_is_drawn_in_chunks_and_a_slow_model_draws_none():
    """A burn-in of MAX_BURN_IN epochs, drawn whole for 160 series (40 replicates of four
    directions that share a model), held the white noise and its filtered copy, 2 × 160 ×
    204,096 values (a peak of 510 MiB as tracemalloc counts numpy's allocations); drawn
    in chunks, the kept series and one chunk. A slow model (φ 0.99999, a horizon past
    MAX_BURN_IN) starts from its stationary law and draws no burn-in at all: its whole
    bootstrap stays within the kept series and one chunk too."""
    import tracemalloc

    phi = np.array([0.99999])
    assert mem.decay_horizon(phi, 0) >= mem.MAX_BURN_IN
    held = 8 * (160 * 4096 + 2 * mem.DRAWN_AT_ONCE)  # the kept series and one chunk
    assert 2 * held < 160 * (4096 + mem.MAX_BURN_IN) * 8  # (the bound can tell the two apart)
    peaks = []
    for run in (
        lambda: mem.stationary_draws(phi, np.random.default_rng(1), 160, 4096, mem.MAX_BURN_IN),
        lambda: mem.bootstrap_spread([phi], 4096, 4, seed=1, minimum=1, segments=4),
    ):
        tracemalloc.start()
        try:
            run()
            peaks.append(tracemalloc.get_traced_memory()[1])
        finally:
            tracemalloc.stop()
    assert peaks[0] < 2 * held
    assert peaks[1] < 2 * held


def test_a_pickled_model_leaves_its_answers_behind_and_answers_the_same():
    """Memoised answers are a cache: a model sent between processes (a worker's results)
    carries none of them, and answers every question as before."""
    import pickle

    x = _ar([1, -0.6], 400, np.random.default_rng(5))
    model = mem.fit_memory(x / x.std(), (x[:, 0] / x.std()) ** 2)
    series = model.series[0]
    before = series.test_window(50).copy(), series.centred_square_moments(50)
    sent = pickle.loads(pickle.dumps(model))
    assert "_memo" in series.__dict__ and "_memo" not in sent.series[0].__dict__
    np.testing.assert_array_equal(sent.series[0].test_window(50), before[0])
    assert sent.series[0].centred_square_moments(50) == before[1]


def test_the_scale_tests_model_dof_pools_the_directions_fits(monkeypatch):
    """Each direction's τ₂ is fitted apart, so the model's ν for V = Σ V_i is Satterthwaite's
    (Σ V_i)²/Σ(V_i²/ν_i): twice ν for two equal directions of ν each, four times ν when the
    other direction is known (ν = ∞); it was the least certain direction's ν. (The
    directions' cross-lag term, estimated from these independent errors, is set aside:
    its own test is below.)"""
    from credcli.engine import scale
    from credcli.engine.scale import gls_residuals, memory_scale_test

    monkeypatch.setattr(scale, "cross_lag_variance", lambda residuals, memory: (0.0, 0.0))

    rng = np.random.default_rng(31)
    u = rng.standard_normal((2_000, 2))
    residuals = gls_residuals(u, np.broadcast_to(np.eye(2), (2_000, 2, 2)))
    white = mem.SeriesMemory(np.zeros(0), np.ones(1), math.inf)
    for nus, expected in (((25.0, 25.0), 50.0), ((25.0, math.inf), 100.0)):
        series = tuple(mem.SeriesMemory(np.zeros(0), np.ones(1), math.inf, nu) for nu in nus)
        model = mem.Memory(np.eye(2), series, white, 2_000)
        test = memory_scale_test(residuals, model, 0.05)
        assert test.model_dof == pytest.approx(expected, rel=1e-12)
        # a tail factor scales V and its error alike: ν stays (it was multiplied by f²)
        heavy = memory_scale_test(residuals, model, 0.05, tail=2.0)
        assert heavy.model_dof == pytest.approx(expected, rel=1e-12)


def test_directions_that_share_one_model_share_its_error(monkeypatch):
    """Two directions holding one model (the same object, :func:`memory._common_model`)
    have one estimation error, not two independent ones: the scale test's model ν is that
    model's ν, where two equal but separately fitted models give 2ν (the cross-lag term
    set aside, as above)."""
    from credcli.engine import scale
    from credcli.engine.scale import gls_residuals, memory_scale_test

    monkeypatch.setattr(scale, "cross_lag_variance", lambda residuals, memory: (0.0, 0.0))

    rng = np.random.default_rng(31)
    u = rng.standard_normal((2_000, 2))
    residuals = gls_residuals(u, np.broadcast_to(np.eye(2), (2_000, 2, 2)))
    white = mem.SeriesMemory(np.zeros(0), np.ones(1), math.inf)
    one = mem.SeriesMemory(np.zeros(0), np.ones(1), math.inf, 25.0)
    twin = mem.SeriesMemory(np.zeros(0), np.ones(1), math.inf, 25.0)
    shared = memory_scale_test(residuals, mem.Memory(np.eye(2), (one, one), white, 2_000), 0.05)
    apart = memory_scale_test(residuals, mem.Memory(np.eye(2), (one, twin), white, 2_000), 0.05)
    assert shared.model_dof == pytest.approx(25.0, rel=1e-12)
    assert apart.model_dof == pytest.approx(50.0, rel=1e-12)


def _isotropic_ar1(seed, n=300, phi=0.9):
    """Two independent AR(1) components of unit variance: one memory in every direction."""
    rng = np.random.default_rng(seed)
    return _ar([1, -phi], n, rng, cols=2) * math.sqrt(1 - phi**2)


def test_the_direction_of_least_memory_is_not_fitted_too_little():
    """Two directions of one AR(1) memory (φ = 0.9, τ = 19, N = 300): fitted apart on the
    principal directions, the one of least long-run variance gets too little memory (its
    τ̂ has a median of 0.74 τ over these 40 series); where AICc cannot tell the two
    memories apart it takes their common model, and the median is then 0.87 τ. The
    common model is never taken on a slow and a white direction (the test of principal
    directions above)."""
    tau = 1.9 / 0.1
    lows = []
    for seed in range(40):
        s = _isotropic_ar1(seed)
        s = s - s.mean(axis=0)
        m = mem.fit_memory(s, (s**2).sum(axis=1))
        lows.append(float(np.min(m.variance_ratios)) / tau)
    assert np.median(lows) > 0.8


def test_many_white_directions_share_one_model_not_the_selections_memory():
    """30 independent white directions over 300 epochs: the principal directions are
    ordered by their long-run variance, so the first ones' own fits show memory by
    selection alone (τ̂ 4.6–14.5 on the most persistent before session 37, where the truth
    is 1). Their long-run variances do not stand out of that selection
    (:func:`memory._distinct_directions`), so they share one model: the largest τ̂ stays
    below 1.5 in at least 10 of 12 segments (one in ten may keep a model of its own by the
    test's level)."""
    small = 0
    for seed in range(12):
        s = np.random.default_rng(seed).standard_normal((300, 30))
        s = s - s.mean(axis=0)
        small += float(np.max(mem.fit_memory(s, (s**2).sum(axis=1)).variance_ratios)) < 1.5
    assert small >= 10


def test_one_slow_direction_among_white_ones_keeps_its_own_memory():
    """One AR(1) direction (φ 0.9, τ 19) among 14 white ones over 600 epochs: its long-run
    variance stands out, so it keeps its own model, and the 14 white directions share one
    (two models in at least 10 of 12 segments, the white ones' τ̂ below 1.5); the slow
    direction's τ̂ has a median within 0.6–1.6 of 19. Before session 37 every direction
    kept its own fit (15 models, the white ones' τ̂ up to 4)."""
    shared, slow = 0, []
    for seed in range(12):
        rng = np.random.default_rng(seed)
        s = rng.standard_normal((600, 15))
        s[:, 0] = _ar([1, -0.9], 600, rng)[:, 0] * math.sqrt(1 - 0.81)
        s = s - s.mean(axis=0)
        m = mem.fit_memory(s, (s**2).sum(axis=1))
        ratios = np.sort(m.variance_ratios)[::-1]
        shared += len(m.models()) == 2 and ratios[1] < 1.5
        slow.append(ratios[0])
    assert shared >= 10
    assert 0.6 * 19 < np.median(slow) < 1.6 * 19


def test_one_memory_in_six_directions_is_rarely_split():
    """Six independent AR(1) directions (φ 0.7) over 300 epochs share one memory: the first
    direction stands out of the selection in about :data:`memory.DISTINCT_LEVEL` of the
    segments (40 segments: expected 4, standard error 1.9; bound 10)."""
    split = 0
    for seed in range(40):
        rng = np.random.default_rng(seed)
        s = _ar([1, -0.7], 300, rng, cols=6)
        s = s - s.mean(axis=0)
        split += len(mem.fit_memory(s, (s**2).sum(axis=1)).models()) > 1
    assert split <= 10


def test_the_bootstrap_refits_shared_models_on_all_their_segments():
    """A model fitted on d directions as segments of one series is refitted on d segments
    per replicate: Var(log τ̂*) about halves for two (10 seeds averaged, each from 40
    replicates: the ratio's standard error is about 0.1)."""
    phi = np.array([0.7])
    one = [mem.bootstrap_spread([phi], 300, 4, seed=s, minimum=1)[0][0] for s in range(10)]
    two = [
        mem.bootstrap_spread([phi], 300, 4, seed=s, minimum=1, segments=2)[0][0] for s in range(10)
    ]
    assert 0.35 < np.mean(two) / np.mean(one) < 0.7


def test_the_lowest_frequency_check_skips_a_direction_it_cannot_predict():
    """A model whose correlation is 1 at every lag of the segment predicts no power at
    2π/N (the Fejér kernel's zero), which the sum gives as rounding of either sign: that
    direction is left out (it read "inf× as much" before, p 0), and a white direction
    beside it is checked alone, I/γ₀ against Exp(1)."""
    rng = np.random.default_rng(5)
    n = 300
    x = rng.standard_normal((n, 2))
    flat = mem.SeriesMemory(np.array([0.999]), np.ones(n), 10.0)
    white = mem.SeriesMemory(np.zeros(0), np.ones(1), math.inf)
    variances = np.array([1.3, 0.7])
    alone = mem.Memory(np.eye(2), (flat, flat), white, n)
    assert math.isnan(mem.lowest_frequency_check(x, alone, variances)[0])
    assert mem.lowest_frequency_check(x, alone, variances)[1] == 1.0
    beside = mem.Memory(np.eye(2), (flat, white), white, n)
    ratio, pvalue = mem.lowest_frequency_check(x, beside, variances)
    ordinate = abs(np.sum(x[:, 1] * np.exp(-2j * np.pi * np.arange(n) / n))) ** 2 / n
    assert ratio == pytest.approx(ordinate / 0.7, rel=1e-9)
    assert pvalue == pytest.approx(math.exp(-ordinate / 0.7), rel=1e-9)


@settings(max_examples=30, deadline=None)
@given(
    k=st.integers(1, 4),
    m=st.integers(1, 3),
    t=st.integers(8, 400),
    order=st.integers(1, 6),
    smooth=st.booleans(),
    seed=st.integers(0, 2**32 - 1),
)
def test_the_compiled_burg_update_gives_numpys_bits(k, m, t, order, smooth, seed):
    """Issue 35: Burg's recursion with the compiled update of its prediction errors
    (numba, when installed) gives the reflection coefficients and innovation variances of
    the numpy path bit for bit, on white and on near-unit-root series."""
    from credcli.engine import compiled

    if compiled.burg_update_kernel() is None:
        pytest.skip("numba is not installed (the extra `fast`)")
    rng = np.random.default_rng(seed)
    x = rng.standard_normal((k, m, t))
    if smooth:
        x = np.cumsum(x, axis=2) + 0.1 * x
    x = x - x.mean(axis=2, keepdims=True)
    order = min(order, t // 4)
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(mem, "_update_kernel", lambda work: None)
        want = mem.burg(x, order)
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(mem, "_update_kernel", lambda work: compiled.burg_update_kernel())
        got = mem.burg(x, order)
    np.testing.assert_array_equal(got.reflection, want.reflection)
    np.testing.assert_array_equal(got.variance, want.variance)


def test_a_memory_lists_its_distinct_models_with_the_directions_they_serve():
    """Memory.models: a model object per entry, with the directions holding it (the
    scale test counts a shared model's error once, from this list)."""
    one = mem.SeriesMemory(np.array([0.5]), 0.5 ** np.arange(20), 30.0)
    own = mem.SeriesMemory(np.array([0.2]), 0.2 ** np.arange(20), 40.0)
    white = mem.SeriesMemory(np.zeros(0), np.ones(1), math.inf)
    model = mem.Memory(np.eye(3), (one, own, one), white, 500)
    assert [(m is one, m is own, served) for m, served in model.models()] == [
        (True, False, (0, 2)),
        (False, True, (1,)),
    ]


def test_a_long_run_is_fitted_on_its_first_sieve_epochs(monkeypatch):
    """Beyond SIEVE_EPOCHS epochs the sieve, its bootstrap and its degrees of freedom are
    those of the run's first SIEVE_EPOCHS epochs (same coefficients and model error), its
    autocorrelation covers every lag of the run, and the whole run's fit (default cap, above 4,096 epochs) is another one. One direction,
    so that the principal directions of the run and of its prefix agree. (That segments of
    at most SIEVE_EPOCHS epochs keep their bits is checked on outputs, `make outputs`.)"""
    rng = np.random.default_rng(11)
    s = _ar([1, -0.6], 4096, rng)
    q = np.sum(s * s, axis=1)
    q = q - q.mean()
    whole = mem.fit_memory(s, q)
    monkeypatch.setattr(mem, "SIEVE_EPOCHS", 512)
    capped = mem.fit_memory(s, q)
    prefix = mem.fit_memory(s[:512], q[:512] - q[:512].mean())
    assert capped.epochs == 4096
    for got, ref, full in zip(capped.series, prefix.series, whole.series):
        assert got.order == ref.order >= 1
        np.testing.assert_allclose(got.phi, ref.phi, rtol=1e-9)
        assert got.dof == pytest.approx(ref.dof, rel=1e-9)
        assert got.variance_ratio == pytest.approx(ref.variance_ratio, rel=1e-9)
        # its autocorrelation covers the whole run, the prefix's model only the prefix
        assert got.rho.size >= 4096 > ref.rho.size
        np.testing.assert_allclose(got.rho[: ref.rho.size], ref.rho, rtol=1e-9, atol=1e-15)
        # the whole run's fit is another (and more precise) one
        assert full.dof > 4 * got.dof
        assert not np.array_equal(full.phi, got.phi)


@settings(max_examples=300, deadline=None)
@given(
    st.floats(-1.0, 1.0, allow_nan=False, exclude_max=True, exclude_min=True),
    st.integers(-320, 0),
    st.integers(0, 3000),
)
def test_an_ar1_decay_horizon_is_the_one_of_its_root(phi, exponent, n):
    """The AR(1) shortcut of decay_horizon (its root is φ) gives the horizon the general
    path gives from np.roots, down to subnormal φ, where the root's last bits differ, and
    a horizon counted from the slowest root's decay (a closed form)."""
    phi = phi * 10.0**exponent
    got = mem.decay_horizon(np.array([phi]), n)
    roots = np.abs(np.roots([1.0, -phi]))
    r = float(np.max(roots)) if roots.size else 0.0
    if r <= 0.0:
        assert got == max(n, 2)
        return
    decay = math.log(mem.NEGLIGIBLE) / math.log(min(r, 1.0 - 1e-12))
    assert got == int(min(mem.MAX_HORIZON, max(n, 2, math.ceil(decay) + 2)))


def test_bic_finds_no_memory_where_there_is_none_and_finds_memory_that_is_there():
    """Schwarz's criterion is consistent for the order (Hannan & Quinn 1979), AICc is not:
    on 400 series of 1,000 independent epochs AICc picks some order above 0 in about 28 %
    (binomial s.e. 2.2 %) and BIC in about 1 % (s.e. 0.5 %); on AR(1) φ = 0.2 (N φ² = 40
    against BIC's charge log N = 6.9 per coefficient) BIC finds the memory in every
    series but a few."""
    rng = np.random.default_rng(11)
    x = rng.standard_normal((400, 1, 1000))
    x -= x.mean(axis=2, keepdims=True)
    fit = mem.burg(x, mem.max_order(1000))
    assert np.mean(fit.orders() > 0) > 0.2
    assert np.mean(np.argmin(fit.bic(), axis=1) > 0) < 0.03
    y = lfilter([1.0], [1.0, -0.2], rng.standard_normal((400, 1100)), axis=1)[:, None, 100:]
    y = y - y.mean(axis=2, keepdims=True)
    assert np.mean(np.argmin(mem.burg(y, mem.max_order(1000)).bic(), axis=1) > 0) > 0.97


def test_independent_errors_of_a_thousand_epochs_are_taken_as_white():
    """Whether there is memory at all is BIC's question (with the lag-1 screening on short
    segments): of
    100 segments of 1,000 independent epochs (d = 2: two directions and q, each white by
    BIC in about 99 %) about 97 % are taken as independent (the exact tests), where AICc
    took 34 of these 100 as independent; AR(1) φ = 0.5 errors never are."""
    rng = np.random.default_rng(12)
    white = 0
    for _ in range(100):
        s = rng.standard_normal((1000, 2))
        white += mem.fit_memory(s, np.sum(s**2, axis=1) - 2.0).white
    assert white >= 90
    s = lfilter([math.sqrt(0.75)], [1.0, -0.5], rng.standard_normal((1100, 2)), axis=0)[100:]
    assert not mem.fit_memory(s, np.sum(s**2, axis=1) - 2.0).white


@pytest.mark.parametrize("k", [-300, -201, -30, 0, 7, 199, 201, 300])
def test_mean_free_is_exact_whatever_the_units_of_the_inverse(k):
    """The whitened residuals less s_k ≈ m + L_k⁻¹b are the same bits when every L_k⁻¹ is
    scaled by 2^k (b scales by 2^−k): within SAFE_UNIT the sums are taken on the inverse
    and divided after, beyond it on a rescaled copy; both are exact rescalings. Against
    the least-squares fit of numpy's lstsq on the stacked regressors."""
    rng = np.random.default_rng(4)
    n, d = 60, 2
    a = rng.standard_normal((n, d, d)) * 0.3 + np.eye(d)
    inverse = np.tril(a)
    s = rng.standard_normal((n, d)) + 0.5
    out = mem.mean_free(s, inverse)
    assert np.array_equal(mem.mean_free(s, inverse * 2.0**k), out)
    design = np.concatenate([np.tile(np.eye(d), (n, 1)), inverse.reshape(n * d, d)], axis=1)
    coef = np.linalg.lstsq(design, s.reshape(-1), rcond=None)[0]
    expected = s.reshape(-1) - design @ coef
    np.testing.assert_allclose(out.reshape(-1), expected, rtol=0, atol=1e-12)


def test_the_scale_variance_holds_the_directions_lagged_cross_covariances():
    """x₁ = z_t and x₂ = (z_{t−1} + w_t)/√2 (z, w white): each is white or MA(1) and they are
    uncorrelated at lag 0, but c₁₂(1) = 1/√2. In the principal directions (x₁ ± x₂)/√2,
    R̃_12(±1)² + R̃_21(±1)² = 1/4 at each of the two lags, so
    Σ_{i≠j} Cov(T_i, T_j) = 2 Σ_h (N − |h|) Σ_{i≠j} R̃_ij(h)² = N − 1, against N·2.5 per
    direction (ρ̃_i(1)² = 1/8): a fifth more than the directions' own variances, which
    their models alone leave out. Independent x₂ = w_t: nothing is added."""
    from credcli.engine.scale import cross_lag_variance, gls_residuals

    n = 20_000
    rng = np.random.default_rng(0)
    z, w = rng.standard_normal(n + 1), rng.standard_normal(n)
    for x2, expected in (((z[:-1] + w) / math.sqrt(2.0), n - 1.0), (w, 0.0)):
        u = np.column_stack([z[1:], x2])
        residuals = gls_residuals(u, np.broadcast_to(np.eye(2), (n, 2, 2)))
        model = mem.fit_memory(residuals.whitened, residuals.q)
        cross, spread = cross_lag_variance(residuals, model)
        standard_error = math.sqrt(2.0 * spread)
        assert abs(cross - expected) <= 3.0 * standard_error + 1e-9
        assert standard_error <= 0.03 * n


@pytest.mark.parametrize("n", [8, 1000, 4099])
def test_time_scales_are_the_variances_of_block_means_at_each_scale(n):
    """The time scales' observed ratios (block sums made from the half scale's pairs) are,
    at every scale m, m times the variance of the means of consecutive m-epoch blocks,
    each direction in units of its own variance, computed here by a reshape."""
    rng = np.random.default_rng(n)
    y = _ar([1, -0.6], n, rng, burn=200, cols=2)
    y -= y.mean(axis=0)
    memory = mem.fit_memory(y, np.sum(y * y, axis=1))
    scales = mem.time_scales(y, memory)
    rotated = y @ memory.directions
    variances = [
        float(rotated[:, i] @ rotated[:, i]) / series.centred_square_moments(n)[0]
        for i, series in enumerate(memory.series)
    ]
    assert scales.epochs.size >= 1
    for m, observed in zip(scales.epochs, scales.observed):
        k = n // m
        sums = rotated[: k * m].reshape(k, m, 2).sum(axis=1)
        sums -= sums.mean(axis=0)
        expected = np.mean(np.sum(sums**2, axis=0) / ((k - 1) * m * np.array(variances)))
        assert observed == pytest.approx(expected, rel=1e-12)


def test_a_short_segment_is_screened_alike_in_a_rotated_frame():
    """The lag-1 screening of a short segment (whether the sieve must take memory) read the
    whitened errors axis by axis, so an AR(1) direction at 30° was screened otherwise than
    the same errors turned to put it on an axis (3 of 60 segments got another model and
    label). Along the principal directions, the frame does not matter: the same label and
    the same model's degrees of freedom in both, on every seed."""
    from credcli.engine.diagnosis import diagnose_errors

    n, angle = 50, np.pi / 6
    turn = np.array([[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]])
    cov = np.broadcast_to(np.eye(2), (n, 2, 2))
    for seed in range(60):
        rng = np.random.default_rng(seed)
        z = rng.standard_normal(n)
        x = np.zeros(n)
        for k in range(1, n):
            x[k] = 0.45 * x[k - 1] + np.sqrt(1 - 0.45**2) * z[k]
        e = np.c_[x, rng.standard_normal(n)] @ turn.T
        tilted, aligned = (
            diagnose_errors(e, cov, rng=seed),
            diagnose_errors(e @ turn, cov, rng=seed),
        )
        assert tilted.label is aligned.label, seed
        assert tilted.memory.dof == pytest.approx(aligned.memory.dof, rel=1e-9), seed


def test_each_spectrum_grid_is_the_fewest_points_that_keep_the_aliasing_down():
    """The grid of each AR polynomial (padded with zeros to one width, as the bootstrap's
    refits of several orders are) is the smallest power of two G from 64 to 4,096 with
    G²r^G <= 1e-18, r the largest root modulus found independently by ``np.roots`` of the
    polynomial at its own degree; 0 where none is. Degrees 0 to 6, roots from 0 to 0.999."""
    gen = np.random.default_rng(21)
    width, rows, want = 8, [], []
    for degree in [0, 1, 1, 2, 2, 3, 4, 6] * 6:
        roots = gen.uniform(0.0, 0.999, degree) * np.exp(1j * gen.uniform(0, np.pi, degree))
        roots = np.r_[
            roots[: degree // 2], np.conj(roots[: degree // 2]), roots[degree // 2 * 2 :].real
        ]
        poly = np.real(np.poly(roots)) if degree else np.array([1.0])
        rows.append(np.r_[poly, np.zeros(width - poly.size)])
        r = np.max(np.abs(np.roots(poly))) if degree else 0.0
        fine = (
            [g for g in 64 * 2 ** np.arange(7) if 2 * np.log(g) + g * np.log(r) <= np.log(1e-18)]
            if r > 0
            else [64]
        )
        want.append(fine[0] if fine else 0)
    np.testing.assert_array_equal(mem._grid_points(np.array(rows)), want)


@pytest.mark.parametrize("p", [1, 2, 3, 7, 30])
def test_the_yule_walker_matrix_collects_each_coefficient_at_its_lag(p):
    """A[k, l] = δ_kl − Σ φ_j over j in 1 … p with |k − j| = l, written out entry by entry;
    and γ(0) … γ(p) of a stationary model solve A γ = σ² e_0 (γ from the model's MA(∞)
    weights, summed to 4,000 lags)."""
    phi = np.random.default_rng(p).uniform(-0.9, 0.9, p) / p
    want = np.eye(p + 1)
    for k in range(p + 1):
        for j in range(1, p + 1):
            want[k, abs(k - j)] -= phi[j - 1]
    got = mem._yule_walker_matrix(phi)
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-15)
    psi = mem.ar_filter(phi, np.eye(4000, 1)[:, 0])  # the MA(∞) weights ψ_h
    gamma = np.array([psi[: 4000 - h] @ psi[h:] for h in range(p + 1)])
    np.testing.assert_allclose(got @ gamma, np.eye(p + 1, 1)[:, 0], atol=1e-12)
