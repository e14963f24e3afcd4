"""Empirical location test, Eqs. (11)–(17)."""

from __future__ import annotations

import contextlib
import itertools

import numpy as np
import pytest
from helpers import gaussian_segment
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import stats

from credcli.engine import elt, flips
from credcli.errors import CredcliError


def _direct_statistic(s):
    """Eq. (13) by its double sum over i < j."""
    n = len(s)
    total = 0.0
    for i in range(n):
        for j in range(i + 1, n):
            total += np.linalg.norm(s[i] + s[j]) - np.linalg.norm(s[i] - s[j])
    return 2 * total / (n * (n - 1))


def test_whitening_uses_symmetric_inverse_square_root(rng):
    errors, cov = gaussian_segment(rng, n=20, d=3, varying=True)
    s = elt.whiten(errors, cov)
    for e, c, sk in zip(errors, cov, s):
        lam, u = np.linalg.eigh(c)
        inv_sqrt = u @ np.diag(lam**-0.5) @ u.T
        np.testing.assert_allclose(sk, inv_sqrt @ e, rtol=1e-10, atol=1e-12)


def test_quadratic_form_equals_pairwise_formula(rng):
    errors, cov = gaussian_segment(rng, n=40, d=2, bias=[0.3, 0.1], varying=True)
    s = elt.whiten(errors, cov)
    direct = _direct_statistic(s)
    assert elt.energy_statistic(s) == pytest.approx(direct, rel=1e-12)
    result = elt.location_test(errors, cov, n_flips=50, rng=1)
    assert result.statistic == pytest.approx(direct, rel=1e-12)
    # every flipped statistic equals (13) on the flipped set
    gen = np.random.default_rng(7)
    signs = gen.integers(0, 2, size=(50, 40), dtype=np.int8) * 2 - 1
    null = elt.location_test(errors, cov, n_flips=50, rng=7).null_distribution
    for b in range(5):
        assert null[b] == pytest.approx(_direct_statistic(signs[b][:, None] * s), rel=1e-10)


def test_pvalue_matches_exact_enumeration():
    """For N = 10 the sign-flip null can be enumerated (2¹⁰ patterns); the randomised
    p-value with large B agrees with the exact one."""
    rng = np.random.default_rng(5)
    errors, cov = gaussian_segment(rng, n=10, d=2, bias=[0.6, 0.0])
    s = elt.whiten(errors, cov)
    a = flips.pair_matrix(s)
    t_obs = a.sum() / 90
    patterns = np.array(list(itertools.product([-1.0, 1.0], repeat=10)))
    null = np.einsum("bi,ij,bj->b", patterns, a, patterns) / 90
    exact = np.mean(null >= t_obs - 1e-12)
    result = elt.location_test(errors, cov, n_flips=20_000, rng=3)
    assert result.pvalue == pytest.approx(exact, abs=0.01)


def test_pvalue_formula_counts_ties(rng):
    """p = (1 + #{T_b >= T_obs}) / (B + 1), Eq. (16)."""
    errors, cov = gaussian_segment(rng, n=30, d=2)
    r = elt.location_test(errors, cov, n_flips=99, rng=2)
    assert (
        r.pvalue == (1 + np.count_nonzero(r.null_distribution >= r.statistic * (1 - 1e-13))) / 100
    )


def test_pvalues_uniform_under_h0():
    ps = []
    for k in range(300):
        gen = np.random.default_rng(100 + k)
        errors, cov = gaussian_segment(gen, n=60, d=2, varying=True)
        ps.append(elt.location_test(errors, cov, n_flips=199, rng=gen).pvalue)
    ps = np.array(ps)
    assert stats.kstest(ps, "uniform").pvalue > 0.01
    assert 0.02 <= np.mean(ps < 0.05) <= 0.09


def test_power_under_bias():
    rejected = 0
    for k in range(100):
        gen = np.random.default_rng(1000 + k)
        errors, cov = gaussian_segment(gen, n=100, d=2, bias=[0.6, -0.4])
        rejected += elt.location_test(errors, cov, n_flips=299, rng=gen).pvalue < 0.05
    assert rejected >= 95


def test_block_flips_share_a_sign_within_blocks(rng):
    errors, cov = gaussian_segment(rng, n=30, d=2)
    s = elt.whiten(errors, cov)
    a = flips.pair_matrix(s)
    r = elt.location_test(errors, cov, n_flips=40, rng=9, block_length=4)
    gen = np.random.default_rng(9)
    signs = (gen.integers(0, 2, size=(40, 8), dtype=np.int8) * 2 - 1).astype(float)
    xi = np.repeat(signs, 4, axis=1)[:, :30]
    np.testing.assert_allclose(r.null_distribution, np.einsum("bi,ij,bj->b", xi, a, xi) / 870)
    assert r.block_length == 4


def test_block_flips_keep_level_under_autocorrelation():
    """AR(1) errors (φ = 0.9) inflate the false-alarm rate of per-epoch flips; blocks of
    20 epochs bring it back near the nominal 5%."""

    def ar1(gen, n=400, phi=0.9):
        w = gen.normal(size=(n, 2))
        x = np.empty_like(w)
        x[0] = w[0]
        for k in range(1, n):
            x[k] = phi * x[k - 1] + np.sqrt(1 - phi**2) * w[k]
        return x

    eye = np.broadcast_to(np.eye(2), (400, 2, 2))
    per_epoch = blocked = 0
    for k in range(60):
        gen = np.random.default_rng(2000 + k)
        e = ar1(gen)
        per_epoch += elt.location_test(e, eye, 199, rng=k).pvalue < 0.05
        blocked += elt.location_test(e, eye, 199, rng=k, block_length=20).pvalue < 0.05
    assert per_epoch >= 15  # far above the 3 expected at the nominal level
    assert blocked <= 9


def test_subsample_when_over_memory_budget(rng):
    errors, cov = gaussian_segment(rng, n=500, d=2, bias=[0.5, 0])
    r = elt.location_test(errors, cov, n_flips=99, rng=1, max_epochs=120)
    assert r.subsampled and r.n_used == 120 and r.pvalue == 0.01
    r2 = elt.location_test(errors, cov, n_flips=99, rng=1, max_epochs=120)
    assert r2.statistic == r.statistic  # seeded subsample
    full = elt.location_test(errors, cov, n_flips=99, rng=1)
    assert not full.subsampled and full.n_used == 500


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"n_flips": 0}, "positive integer"),
        ({"block_length": 0}, "block_length"),
        ({"max_epochs": 1}, "memory budget"),
    ],
)
def test_invalid_arguments(kwargs, message, rng):
    errors, cov = gaussian_segment(rng, n=20, d=2)
    with pytest.raises(CredcliError, match=message):
        elt.location_test(errors, cov, **kwargs)


def test_fast_product_decides_every_flip_as_float64():
    """The float32 product with its float64 recheck gives the float64 p-value exactly."""
    for k in range(6):
        gen = np.random.default_rng(300 + k)
        errors, cov = gaussian_segment(gen, n=400, d=2, bias=[0.05 * k, 0.0])
        r = elt.location_test(errors, cov, n_flips=500, rng=k)
        a = flips.pair_matrix(elt.whiten(errors, cov))
        signs = np.random.default_rng(k).integers(0, 2, size=(500, 400), dtype=np.int8)
        xi = signs.astype(float) * 2 - 1
        exact = np.einsum("bi,bi->b", xi @ a, xi) / (400 * 399)
        t_obs = a.sum() / (400 * 399)
        expected = (
            1 + np.count_nonzero(exact >= t_obs - 100 * np.finfo(float).eps * abs(t_obs))
        ) / 501
        assert r.pvalue == expected
        np.testing.assert_allclose(
            r.null_distribution, exact, rtol=0, atol=1e-6 * np.abs(exact).max()
        )


def test_large_segments_hold_the_pair_matrix_in_float32_only(monkeypatch):
    """Above STREAM_EPOCHS the ELT keeps A in float32 only (issue 12: memory of long
    segments): the float32 matrix is the rounding of A's upper triangle, 1ᵀA1 and the float64 recheck
    (rows rebuilt a block at a time) agree with the float64 matrix to 1e-13, and the
    p-value, flips used and labels equal those of the float64-matrix path, with and
    without early stopping, near and far from rejection."""
    gen = np.random.default_rng(41)
    n = flips.STREAM_EPOCHS + 150
    s = gen.standard_normal((n, 2))
    a = flips.pair_matrix(s)
    upper32, total, absolute = flips.pair_matrix_float32(s)
    np.testing.assert_array_equal(upper32, np.triu(a, 1).astype(np.float32))
    assert total == pytest.approx(a.sum(), rel=1e-13)
    assert absolute == pytest.approx(np.abs(a).sum(), rel=1e-13)
    xi = gen.choice([-1.0, 1.0], size=(7, n))
    np.testing.assert_allclose(
        flips._exact_quadratic(s, xi), np.einsum("bi,bi->b", xi @ a, xi), rtol=1e-13
    )
    for bias, stop in itertools.product((0.0, 0.05, 0.2), (None, 0.05)):  # p 0.94, 0.047, 0.005
        shifted = s + [bias, 0.0]
        streamed = elt.whitened_location_test(
            shifted, 199, np.random.default_rng(3), stop_level=stop
        )
        with monkeypatch.context() as m:
            m.setattr(flips, "STREAM_EPOCHS", 10**9)
            whole = elt.whitened_location_test(
                shifted, 199, np.random.default_rng(3), stop_level=stop
            )
        assert (streamed.pvalue, streamed.flips_used) == (whole.pvalue, whole.flips_used)
        assert streamed.statistic == pytest.approx(whole.statistic, rel=1e-13)
        np.testing.assert_allclose(streamed.null_distribution, whole.null_distribution, rtol=1e-12)


@pytest.mark.parametrize(
    "sizes", [[3] * 10, [3] * 9 + [1], [2] * 5 + [1] + [2] * 5, [5], [1, 1, 1], [4, 4, 3]]
)
def test_block_sums_equal_reduceat(sizes):
    """The block-summed pair matrix: reshape-sum over equal blocks, reduceat after them,
    equals np.add.reduceat to rounding, for every pattern of block sizes."""
    starts = np.cumsum([0] + sizes[:-1])
    a = np.random.default_rng(len(sizes)).standard_normal((sum(sizes), 6))
    np.testing.assert_allclose(
        flips._block_sums(a, starts), np.add.reduceat(a, starts, axis=0), rtol=0, atol=1e-14
    )


def test_fast_rademacher_signs_are_numpys_draws_bit_for_bit():
    """The ELT's signs come from PCG64's raw outputs (issue 12: 1M signs in ~1 ms instead
    of ~3.5 ms); they equal 2·integers(0, 2) − 1 bit for bit, and leave the generator in
    the same state, whatever the shape and whether a 32-bit word was left buffered; other
    bit generators take numpy's own path."""
    from credcli.engine import rng as _rng

    assert _rng._raw_draws_match()
    shapes = np.random.default_rng(9).integers(1, 60, size=(150, 2))
    for k, shape in enumerate(shapes):
        a, b = np.random.default_rng(k), np.random.default_rng(k)
        for g in (a, b):  # 0 to 3 words drawn before: a buffered word half the time
            g.integers(0, 2**32, size=k % 4, dtype=np.uint32)
        shape = (int(shape[0]), int(shape[1]))
        got = _rng._raw_signs(a, shape)
        want = b.integers(0, 2, size=shape, dtype=np.int8) * 2 - 1
        assert got.dtype == np.int8 and np.array_equal(got, want)
        assert a.bit_generator.state == b.bit_generator.state
        assert a.random() == b.random()
    philox = np.random.Generator(np.random.Philox(3))
    twin = np.random.Generator(np.random.Philox(3))
    assert np.array_equal(
        _rng.rademacher(philox, (5, 7)), twin.integers(0, 2, size=(5, 7), dtype=np.int8) * 2 - 1
    )


@pytest.mark.parametrize("separate", [False, True])
def test_block_flips_null_equals_the_direct_quadratic_forms(separate):
    """With blocks of L = 3 (m = 100 blocks) the flipped statistics are ηᵀA_bη/norm of the
    block-summed matrix, whose diagonal (within-block pairs) is not zero unless pairs in
    the same and adjacent blocks are left out: every null value and the p-value equal a
    direct float64 evaluation with the same signs."""
    s = np.random.default_rng(17).standard_normal((300, 2)) + [0.05, 0.0]
    blocks, keys = elt.sign_blocks(300, 3)
    result = flips.sign_flip_test(s, blocks, keys, 199, np.random.default_rng(2), separate)
    a = flips.pair_matrix(s)
    keep = np.abs(blocks[:, None] - blocks[None, :]) > 1 if separate else ~np.eye(300, dtype=bool)
    signs = np.random.default_rng(2).integers(0, 2, size=(199, 100), dtype=np.int8) * 2 - 1
    xi = signs[:, blocks].astype(float)  # each epoch carries its block's sign
    norm = float(keep.sum())
    direct = np.einsum("bi,bi->b", xi @ (a * keep), xi) / norm
    np.testing.assert_allclose(result.null_distribution, direct, atol=1e-6 * np.abs(direct).max())
    t_obs = (a * keep).sum() / norm
    tie = t_obs - 100 * np.finfo(float).eps * abs(t_obs)
    assert result.pvalue == (1 + np.count_nonzero(direct >= tie)) / 200


def test_squared_norms_that_round_below_zero_count_as_zero(monkeypatch):
    """Repeated and opposite errors: ‖s_i ∓ s_j‖² = ‖s_i‖² + ‖s_j‖² ∓ 2 s_i·s_j rounds
    below zero for some of their pairs; those blocks are computed again with the squares
    clamped, and A equals the pairwise formula. (The Gram form leaves ‖s_i − s_j‖ of a
    repeat at most √(ε(‖s_i‖² + ‖s_j‖²)) ≈ 1e-7 instead of 0.)"""
    rng = np.random.default_rng(5)
    base = rng.normal(size=(100, 3))
    s = np.concatenate([base, base, -base])  # repeats 100 and 200 rows apart
    clamped = []
    pair_block = flips._pair_block

    def spy(*args, clamp):
        clamped.append(clamp)
        pair_block(*args, clamp=clamp)

    monkeypatch.setattr(flips, "_pair_block", spy)
    monkeypatch.setattr(flips, "KERNEL_PAIRS", 10**18)  # the numpy path, whose checks are spied
    a = flips.pair_matrix(s)
    assert True in clamped  # the check found a rounded-negative square in some block
    norms = np.linalg.norm(s, axis=1)
    direct = np.linalg.norm(s[:, None] + s[None], axis=2) - np.linalg.norm(
        s[:, None] - s[None], axis=2
    )
    np.fill_diagonal(direct, 0.0)
    assert np.all(np.isfinite(a))
    np.testing.assert_allclose(a, direct, rtol=1e-12, atol=2e-7)
    i = np.arange(100)
    np.testing.assert_allclose(a[i, i + 100], 2 * norms[i], rtol=0, atol=2e-7)  # ‖2s‖ − 0
    np.testing.assert_allclose(a[i, i + 200], -2 * norms[i], rtol=0, atol=2e-7)  # 0 − ‖2s‖


@pytest.mark.parametrize(
    "sizes",
    [[3] * 70, [2] * 150 + [1], [4] * 60 + [2] * 3 + [4] * 20, [5] * 50, [97, 3, 120], [1] * 130],
)
def test_block_sums_made_by_bands_equal_those_of_the_whole_pair_matrix(sizes):
    """Where every 96-row band of pair_upper ends on a block boundary, the block sums are
    bit for bit the same; elsewhere (blocks of 5, a block longer than a band) they agree to
    rounding."""
    s = np.random.default_rng(len(sizes)).normal(size=(sum(sizes), 2))
    starts = np.r_[0, np.cumsum(sizes)[:-1]]
    whole = flips._block_sums(flips._block_sums(flips.pair_upper(s), starts).T, starts).T
    banded = flips.pair_block_upper(s, starts)
    n = sum(sizes)
    if set(range(96, n, 96)) <= set(starts.tolist()):
        np.testing.assert_array_equal(banded, whole)
    np.testing.assert_allclose(banded, whole, rtol=1e-12, atol=1e-11)
    assert not np.any(np.tril(banded, -1))


@pytest.mark.parametrize("upper", [True, False])
def test_blocked_float32_forms_are_within_their_bound(upper):
    """The second look at flips near T_obs sums Uᵀξ 64 rows of U at a time in float32 and
    adds the parts in float64: every such form is within ``fine_bound`` of the float64
    form, and that bound is far tighter than the one-pass float32 product's."""
    n = 700
    s = np.random.default_rng(5).standard_normal((n, 2))
    u = flips.pair_upper(s)
    a = u if upper else u + u.T
    stats = flips._FlippedStatistics.of_matrix(a, float(a.sum()), upper)
    signs = np.random.default_rng(6).integers(0, 2, size=(200, n), dtype=np.int8) * 2 - 1
    blocked = stats._blocked(np.asfortranarray(signs.T.astype(np.float32)))
    exact = np.einsum("bi,bi->b", signs @ (u + u.T), signs)
    assert np.max(np.abs(blocked - exact)) <= stats.fine_bound
    assert stats.fine_bound * 5 < stats.bound


@pytest.mark.parametrize(
    ("cov", "words"),
    [
        (-np.eye(2), "cov[0] is not positive definite"),
        (np.array([[1.0, 2.0], [2.0, 1.0]]), "cov[0] is not positive definite"),
        (np.eye(3), "cov must have shape"),
    ],
)
def test_location_test_validates_its_inputs(cov, words):
    """A covariance that is not positive definite gave NaN statistics and p = 1/(B + 1),
    which reads as a rejection (a false SMM); now it is an error naming the epoch."""
    e = np.random.default_rng(0).standard_normal((50, 2))
    with pytest.raises(CredcliError, match=words.replace("[", r"\[").replace("]", r"\]")):
        elt.location_test(e, np.broadcast_to(cov, (50, *cov.shape)), n_flips=99, rng=0)


def _pair_paths():
    """The two ways of building the pair matrix: numpy, and numba's compiled kernel (from
    the first pair on); the test is skipped where numba is not installed."""
    from credcli.engine import compiled

    if compiled.pair_band_kernel() is None:
        pytest.skip("numba is not installed (the extra `fast`)")

    @contextlib.contextmanager
    def on(path):
        with pytest.MonkeyPatch.context() as m:
            m.setattr(flips, "KERNEL_PAIRS", 0 if path == "compiled" else 10**18)
            yield

    return on


def _pair_outputs(s, starts):
    upper, upper32, absolute = flips.pair_upper_float32(s)
    streamed32, total, streamed_abs = flips.pair_matrix_float32(s)
    return dict(
        upper=flips.pair_upper(s),
        fused=upper,
        upper32=upper32,
        absolute=absolute,
        streamed32=streamed32,
        total=total,
        streamed_abs=streamed_abs,
        blocks=flips.pair_block_upper(s, starts),
    )


@settings(max_examples=40, deadline=None)
@given(
    n=st.integers(2, 260),
    d=st.integers(1, 4),
    repeats=st.booleans(),
    scale=st.sampled_from([1e-3, 1.0, 1e3]),
    block=st.integers(1, 5),
    seed=st.integers(0, 2**32 - 1),
)
def test_compiled_pair_kernel_gives_numpys_bits(n, d, repeats, scale, block, seed):
    """Issue 35: the compiled kernel writes A's float64 and float32 entries with the bits
    of the numpy path, whose sums it leaves unchanged (1ᵀA1 bit for bit; Σ|A_ij|, summed in
    another order, to 1e-13), also where a square rounds below zero (repeated and opposite
    errors); both equal the pairwise formula ‖s_i + s_j‖ − ‖s_i − s_j‖ computed directly."""
    on = _pair_paths()
    rng = np.random.default_rng(seed)
    s = rng.standard_normal((n, d)) * scale
    if repeats and n >= 3:
        s[n // 3 :: 3] = -s[: len(s[n // 3 :: 3])]  # opposite pairs: squares that round to <= 0
        s[1] = s[0]
    starts = np.arange(0, n, block)
    with on("numpy"):
        want = _pair_outputs(s, starts)
    with on("compiled"):
        got = _pair_outputs(s, starts)
    for key in ("upper", "fused", "upper32", "streamed32", "blocks"):
        np.testing.assert_array_equal(got[key], want[key], err_msg=key)
    assert got["total"] == want["total"]
    for key in ("absolute", "streamed_abs"):
        assert got[key] == pytest.approx(want[key], rel=1e-13, abs=1e-300)
    direct = np.linalg.norm(s[:, None] + s[None], axis=2) - np.linalg.norm(
        s[:, None] - s[None], axis=2
    )
    np.fill_diagonal(direct, 0.0)
    upper = np.triu(direct, 1)
    np.testing.assert_allclose(got["upper"], upper, rtol=1e-10, atol=2e-7 * scale)
    np.testing.assert_array_equal(got["upper32"], got["upper"].astype(np.float32))
    assert got["absolute"] == pytest.approx(np.abs(direct).sum(), rel=1e-6, abs=1e-300)


@pytest.mark.parametrize(
    "n, block_length, separate",
    [(300, 1, False), (300, 3, True), (flips.STREAM_EPOCHS + 60, 1, False)],
)
@pytest.mark.parametrize("bias", [0.0, 0.3])
def test_the_elt_is_the_same_on_both_pair_paths(n, block_length, separate, bias):
    """The whole test, both sides of STREAM_EPOCHS, blocked or not, near and far from
    rejection: statistic, p-value, flips used and bounded and every flipped statistic are
    the same bits whichever path built the pair matrix."""
    on = _pair_paths()
    s = np.random.default_rng(n + block_length).standard_normal((n, 2)) + [bias, 0.0]
    results = []
    for path in ("numpy", "compiled"):
        with on(path):
            results.append(
                elt.whitened_location_test(
                    s, 999, np.random.default_rng(8), block_length, 10**6, separate, 0.05
                )
            )
    numpy_result, compiled_result = results
    assert compiled_result.statistic == numpy_result.statistic
    assert (compiled_result.pvalue, compiled_result.flips_used, compiled_result.flips_bounded) == (
        numpy_result.pvalue,
        numpy_result.flips_used,
        numpy_result.flips_bounded,
    )
    np.testing.assert_array_equal(compiled_result.null_distribution, numpy_result.null_distribution)


@settings(max_examples=60, deadline=None)
@given(
    rows=st.integers(1, 70),
    columns=st.integers(1, 40),
    before=st.integers(0, 3),
    batches=st.lists(st.integers(1, 20), min_size=1, max_size=8),
    seed=st.integers(0, 2**32 - 1),
)
def test_signs_drawn_as_read_are_the_whole_draws_rows(rows, columns, before, batches, seed):
    """Issue 35: the ELT draws only the sign vectors its stopping rule reads; they are the
    rows of the whole draw (numpy's ``integers``) bit for bit, in batches of any size, and
    the generator is left as the whole draw leaves it, however few rows are read."""
    from credcli.engine import rng as _rng

    a, b = np.random.default_rng(seed), np.random.default_rng(seed)
    for g in (a, b):  # a 32-bit word left buffered when ``before`` is odd
        g.integers(0, 2**32, size=before, dtype=np.uint32)
    whole = b.integers(0, 2, size=(rows, columns), dtype=np.int8) * 2 - 1
    lazy = _rng.SignRows(a, (rows, columns))
    assert a.bit_generator.state == b.bit_generator.state
    start = 0
    for size in batches:
        got = lazy.take(start, start + size)
        assert got.dtype == np.int8
        np.testing.assert_array_equal(got, whole[start : start + size])
        start = min(rows, start + size)
    assert a.random() == b.random()
