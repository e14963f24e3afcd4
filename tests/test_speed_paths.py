"""The fast paths decide exactly as the slow ones: early-stopped sign flips against all B,
any number of processes against one, the blocked pair matrix against the direct formula."""

from __future__ import annotations

import json
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from credcli.engine import elt, flips
from credcli.engine.config import Label
from credcli.engine.diagnosis import DiagnosisConfig, diagnose_errors
from credcli.engine.elt import whiten, whitened_location_test
from credcli.engine.rng import rademacher
from credcli.report import jsontext

ROOT = Path(__file__).resolve().parents[1]


def _near_alpha_segments():
    """Biased segments whose exhaustive ELT p-value lies near α_L = 0.0253 (stored seeds)."""
    out = []
    for seed in range(400):
        rng = np.random.default_rng([21, seed])
        e = rng.standard_normal((60, 2)) + [0.33, 0.0]
        s = whiten(e, np.broadcast_to(np.eye(2), (60, 2, 2)))
        p = whitened_location_test(s, 1000, np.random.default_rng(seed)).pvalue
        if 0.01 <= p <= 0.06:
            out.append((s, seed, p))
    return out


def test_early_stopping_never_changes_a_decision():
    level = 1 - np.sqrt(0.95)
    cases = _near_alpha_segments()
    assert len(cases) >= 15  # the stored set really sits near the level
    stopped = 0
    for s, seed, p_exact in cases:
        fast = whitened_location_test(s, 1000, np.random.default_rng(seed), stop_level=level)
        assert (fast.pvalue < level) == (p_exact < level), (seed, p_exact, fast.pvalue)
        if fast.flips_used < 1000:
            stopped += 1
            assert fast.pvalue >= level  # a sequential p-value only where it cannot reject
        else:
            assert fast.pvalue == p_exact
    assert stopped >= 3


def test_far_from_significance_stops_after_about_a_hundred_flips():
    rng = np.random.default_rng(5)
    s = rng.standard_normal((500, 2))
    res = whitened_location_test(s, 1000, np.random.default_rng(0), stop_level=0.0253)
    assert res.flips_used <= 256 and res.pvalue >= 0.0253
    full = whitened_location_test(s, 1000, np.random.default_rng(0))
    # the same sign vectors, decided the same way (values may differ in float32 rounding,
    # which the float64 recheck makes irrelevant to every comparison with T_obs)
    used = res.flips_used
    assert full.flips_used == 1000
    spread = float(np.abs(full.null_distribution).max())
    np.testing.assert_allclose(
        full.null_distribution[:used], res.null_distribution, atol=1e-5 * spread
    )
    t = full.statistic
    assert np.array_equal(full.null_distribution[:used] >= t, res.null_distribution >= t)


def test_exact_pvalue_option_gives_the_exhaustive_pvalue():
    rng = np.random.default_rng(6)
    e, cov = rng.standard_normal((300, 2)), np.broadcast_to(np.eye(2), (300, 2, 2))
    one = DiagnosisConfig(block_length=1)  # independent epochs declared: single-epoch signs
    exact = diagnose_errors(e, cov, replace(one, exact_pvalue=True), rng=1)
    fast = diagnose_errors(e, cov, one, rng=1)
    assert exact.elt.flips_used == 1000 and exact.label is fast.label
    p = elt.location_test(e, cov, 1000, rng=1).pvalue  # B flips of the same stream
    assert exact.elt.pvalue == p


@pytest.mark.parametrize("n", [3, 64, 97, 500])
def test_blocked_pair_matrix_equals_the_direct_formula(n):
    s = np.random.default_rng(n).standard_normal((n, 3)) * 7.0
    direct = np.array([[np.linalg.norm(a + b) - np.linalg.norm(a - b) for b in s] for a in s])
    np.fill_diagonal(direct, 0.0)
    a = flips.pair_matrix(s)
    np.testing.assert_allclose(a, direct, rtol=1e-12, atol=1e-12)
    assert np.array_equal(a, a.T)


def test_jobs_do_not_change_the_output(tmp_path, monkeypatch):
    """Two worker processes write the same bytes as one process. The size limits of the
    parallel path are lowered for the test (they are costs, not results): 5,400 epochs in
    18 segments take it, as 50,000 epochs and 2 MB would, and the workers get the tasks."""
    from credcli import workflows
    from credcli.cli import main
    from credcli.schedule import plans as scheduling

    monkeypatch.setattr(scheduling, "PARALLEL_MIN_EPOCHS", 5_000)
    monkeypatch.setattr(workflows, "PARALLEL_MIN_BYTES", 500_000)
    mapped = []  # the tasks each pool was given

    class Pool(workflows.WorkerPool):
        def map(self, func, tasks, before_fork=None):
            mapped.append(len(tasks))
            return super().map(func, tasks, before_fork)

    monkeypatch.setattr(workflows, "WorkerPool", Pool)
    frame = pd.concat([pd.read_csv(ROOT / "sample_data" / "estimator_log.csv")] * 3)
    frame["segment"] = frame["segment"] + "-" + (np.arange(len(frame)) // 1800).astype(str)
    path = tmp_path / "big.csv"
    frame.to_csv(path, index=False)
    assert path.stat().st_size >= workflows.PARALLEL_MIN_BYTES
    outs = []
    for jobs in ("1", "2"):
        out = tmp_path / f"j{jobs}.json"
        assert main(["diagnose", str(path), "-f", "json", "--jobs", jobs, "-o", str(out)]) == 0
        outs.append(out.read_bytes())
    assert len(mapped) == 1 and mapped[0] > 2  # --jobs 2: the segments went to the workers
    assert outs[0] == outs[1]
    assert len(json.loads(outs[0])["segments"]) == 18


def _integer_matrix(n: int, rank: int, noise: int, upper: bool, seed: int):
    """A = VVᵀ + W with small integer V and symmetric integer W (zero diagonal when only
    the strictly upper triangle is given), so every ξᵀAξ is an exact integer."""
    rng = np.random.default_rng(seed)
    v = rng.integers(-3, 4, size=(n, rank))
    w = np.triu(rng.integers(-noise, noise + 1, size=(n, n)), 1 if upper else 0)
    a = v @ v.T + w + np.triu(w, 1).T
    if upper:
        a = np.triu(a, 1)  # A = U + Uᵀ: its diagonal is zero
    return a, v, w


def _exact_forms(a: np.ndarray, upper: bool, signs: np.ndarray) -> np.ndarray:
    """ξᵀAξ in integer arithmetic (int64 holds these: |ξᵀAξ| < 2⁶³)."""
    full = (a + a.T if upper else a).astype(np.int64)
    xi = signs.astype(np.int64)
    return ((xi @ full) * xi).sum(axis=1)


@pytest.mark.parametrize("upper", [True, False])
@pytest.mark.parametrize(
    ("rank", "noise", "exponent", "basis"),
    [
        (1, 0, 0, "range"),
        (2, 0, -40, "range"),
        (8, 0, 30, "range"),
        (3, 2, 0, "range"),
        (20, 1, -3, "range"),
        (4, 0, 0, "random"),
        (20, 3, 0, "random"),
    ],
)
def test_low_rank_bound_is_above_every_exact_form(upper, rank, noise, exponent, basis):
    """The bound against integer-exact forms, with Q spanning A's range (V) or random
    columns; with A = VVᵀ given whole and Q its range the remainder is only the rounding
    allowance, so the bound is also tight there (given as U, A = VVᵀ − diag(VVᵀ) is not
    of low rank)."""
    n = 300
    a, v, _ = _integer_matrix(n, rank, noise, upper, seed=rank + 10 * noise)
    scaled = a.astype(np.float64) * 2.0**exponent  # exact: a power of two
    columns = v.astype(float) if basis == "range" else np.random.default_rng(0).random((n, 6))
    flat = scaled.reshape(-1)
    squares = (2.0 if upper else 1.0) * float(flat @ flat)
    bound = flips._LowRankBound.of_matrix(scaled, upper, columns, squares)
    signs = rademacher(np.random.default_rng(rank), (1000, n))
    signs[0] = 1  # ξ = 1 too, where 1ᵀA1 is largest for a low-rank A
    exact = _exact_forms(a, upper, signs).astype(np.float64) * 2.0**exponent
    bounds = bound(signs.T.astype(np.float32, order="F"))
    assert np.all(bounds >= exact)
    if noise == 0 and basis == "range" and not upper:  # R = 0 up to rounding
        assert np.max(bounds - exact) <= 1e-4 * n * np.sqrt(squares)  # the allowance


@pytest.mark.parametrize(
    ("bias", "block_length", "separate"),
    [
        (0.45, 1, False),
        (0.6, 1, False),
        (1.0, 1, False),
        (2.0, 1, False),
        (0.8, 2, True),
        (1.5, 3, False),
    ],
)
def test_bounded_flips_decide_as_the_exhaustive_test(bias, block_length, separate):
    """With the bound, each flip counts as in the exhaustive test: same p-value and flips,
    the bounded flips' exhaustive values below T_obs, the others' values unchanged."""
    for seed in range(3):
        rng = np.random.default_rng([31, seed])
        s = rng.standard_normal((900, 2)) + [bias, 0.0]
        kw = dict(block_length=block_length, separate_blocks=separate)
        fast = whitened_location_test(s, 1000, np.random.default_rng(seed), stop_level=0.05, **kw)
        full = whitened_location_test(s, 1000, np.random.default_rng(seed), **kw)
        assert (fast.pvalue, fast.flips_used) == (full.pvalue, 1000)
        bounded = np.isnan(fast.null_distribution)
        assert fast.flips_bounded == np.count_nonzero(bounded)
        assert np.all(full.null_distribution[bounded] < full.statistic)
        spread = float(np.abs(full.null_distribution).max())
        np.testing.assert_allclose(
            fast.null_distribution[~bounded], full.null_distribution[~bounded], atol=1e-5 * spread
        )
        if bias >= 1.0:  # strong bias: all flips after the first batch are bounded
            assert fast.flips_bounded == 1000 - flips._FIRST_BATCH


def test_weak_bias_does_not_build_the_bound(monkeypatch):
    """Under the gate the bound is not built (it would certify nothing): the cost stays."""
    built = []
    original = flips._LowRankBound.of_matrix
    monkeypatch.setattr(
        flips._LowRankBound, "of_matrix", lambda *a: built.append(1) or original(*a)
    )
    s = np.random.default_rng(3).standard_normal((900, 2)) + [0.25, 0.0]
    res = whitened_location_test(s, 1000, np.random.default_rng(0), stop_level=0.05)
    assert res.pvalue < 0.05 and res.flips_bounded == 0 and not built
    s = s + [1.0, 0.0]
    res = whitened_location_test(s, 1000, np.random.default_rng(0), stop_level=0.05)
    assert res.flips_bounded > 0 and built == [1]


def test_segments_too_short_for_a_verdict_are_diagnosed_together():
    """Issue 32 item 7: short segments (a log of one-epoch segments) are diagnosed in one
    vectorised pass; each is what diagnosing it alone gives, accuracy included (|e| for
    one epoch), in the log's order among the long segments."""
    from credcli import log_from_arrays
    from credcli.engine.diagnosis import diagnose_segment
    from credcli.schedule.plans import diagnose_plans
    from credcli.segments import split

    rng = np.random.default_rng(5)
    names = ["a"] * 40 + [f"s{i}" for i in range(7)] + ["b"] * 3 + ["c"] * 60
    e = rng.standard_normal((len(names), 2))
    log = log_from_arrays(errors=e, cov=np.eye(2), segment=names)
    plan = split(log)
    config = DiagnosisConfig()
    together = diagnose_plans([(log, plan)], config, seed=3)
    assert [r.segment for r in together] == [s.name for s in plan]
    for result, segment in zip(together, plan, strict=True):
        alone = diagnose_segment(e[segment.index], log.cov[segment.index], config, 3, segment.name)
        assert result.diagnosis.label == alone.label and result.diagnosis.reason == alone.reason
        for field in ("rmse", "mean", "median", "max"):
            got = getattr(result.diagnosis.accuracy, field)
            np.testing.assert_array_equal(got, getattr(alone.accuracy, field))
    one = together[1].diagnosis  # s0: one epoch
    assert one.label.value == "insufficient-data" and one.n == 1
    np.testing.assert_array_equal(one.accuracy.max, np.abs(e[40]))
    assert one.accuracy.rmse_norm == pytest.approx(np.linalg.norm(e[40]), rel=1e-15)


def test_gls_residuals_from_given_inverses_are_those_computed_in_chunks():
    """The diagnosis inverts the Cholesky factors once and hands them to the GLS residuals;
    over several epoch chunks (per-epoch 3 × 3 covariances) that gives what the residuals
    compute themselves, to the bit (the same forward substitution of each matrix)."""
    from credcli.engine.linalg import EPOCH_CHUNK, lower_inverse
    from credcli.engine.scale import gls_residuals

    rng = np.random.default_rng(1)
    n = 2 * EPOCH_CHUNK + 17
    a = rng.standard_normal((n, 3, 3))
    chol = np.linalg.cholesky(a @ a.transpose(0, 2, 1) + np.eye(3))
    e = rng.standard_normal((n, 3))
    own, given = gls_residuals(e, chol), gls_residuals(e, chol, lower_inverse(chol))
    for name in ("mean", "whitened", "precision_sum", "scores"):
        np.testing.assert_array_equal(getattr(own, name), getattr(given, name))


@pytest.mark.parametrize("d", [1, 2, 3, 6, 15])
def test_lower_inverse_inverts_each_factor(d):
    """L⁻¹ by forward substitution (one per segment, issue 35): L·X = I to rounding times
    the condition number, X lower triangular, and for d = 2 the closed form
    [[1/a, 0], [−b/(ac), 1/c]] of L = [[a, 0], [b, c]]."""
    from credcli.engine.linalg import lower_inverse

    rng = np.random.default_rng(d)
    a = rng.standard_normal((500, d, d))
    cov = a @ a.transpose(0, 2, 1) + 0.1 * np.eye(d)
    chol = np.linalg.cholesky(cov)
    x = lower_inverse(chol)
    assert np.all(np.triu(x, 1) == 0.0)
    cond = np.linalg.cond(chol)
    residual = np.abs(chol @ x - np.eye(d)).max(axis=(1, 2))
    assert np.all(residual <= 1e-14 * d * cond)
    if d == 2:
        p, q, r = chol[:, 0, 0], chol[:, 1, 0], chol[:, 1, 1]
        np.testing.assert_allclose(x[:, 1, 0], -q / (p * r), rtol=1e-13)
        np.testing.assert_allclose(x[:, [0, 1], [0, 1]], 1.0 / chol[:, [0, 1], [0, 1]], rtol=1e-15)


def test_nees_from_the_inverse_is_the_triangular_solve_s():
    """The NEES from inverse Cholesky factors (the diagnosis's one inverse per segment, and
    ``metrics.nees`` chunk by chunk) agrees with LAPACK's triangular solve, an independent
    computation, to 1e-12 (Eq. (1)); the diagnosis's ANEES is ``metrics.anees``."""
    from credcli.engine import metrics
    from credcli.engine.diagnosis import diagnose_errors

    rng = np.random.default_rng(4)
    a = rng.standard_normal((3000, 3, 3))
    cov = a @ a.transpose(0, 2, 1) + 0.2 * np.eye(3)
    chol = np.linalg.cholesky(cov)
    e = np.einsum("nij,nj->ni", chol, rng.standard_normal((3000, 3)))
    z = np.linalg.solve(chol, e[:, :, None])[:, :, 0]
    np.testing.assert_allclose(metrics.nees(e, cov), np.einsum("ni,ni->n", z, z), rtol=1e-12)
    shared = np.linalg.cholesky(cov[0])
    z0 = np.linalg.solve(shared, e.T).T
    np.testing.assert_allclose(
        metrics.nees_factored(e, shared), np.einsum("ni,ni->n", z0, z0), rtol=1e-12
    )
    got = diagnose_errors(e, cov, rng=1)
    assert got.anees == pytest.approx(metrics.anees(e, cov), rel=1e-14)


def test_the_pool_threads_errors_after_a_stop_are_quiet_and_others_shown(monkeypatch):
    """After WorkerPool.stop the executor's thread may fail a cancelled future
    (InvalidStateError) or close a pipe end that stop closes at the same moment (EBADF):
    neither is shown; any other error of that thread, or of another thread, still is."""
    import errno
    import threading
    from concurrent.futures import InvalidStateError
    from concurrent.futures.process import _ExecutorManagerThread

    from credcli.schedule import pool as parallel

    shown = []
    monkeypatch.setattr(threading, "excepthook", shown.append)
    parallel._quiet_cancelled_futures()
    pool_thread = object.__new__(_ExecutorManagerThread)

    class Args:
        def __init__(self, error, thread):
            self.exc_type, self.exc_value, self.thread = type(error), error, thread

    quiet = [InvalidStateError("cancelled"), OSError(errno.EBADF, "Bad file descriptor")]
    loud = [OSError(errno.EPIPE, "Broken pipe"), ValueError("x")]
    for error in quiet + loud:
        threading.excepthook(Args(error, pool_thread))
    threading.excepthook(Args(InvalidStateError("x"), threading.current_thread()))
    assert [a.exc_value for a in shown] == [*loud, shown[-1].exc_value]
    assert len(shown) == 3


_SCALARS = (
    st.none()
    | st.booleans()
    | st.integers(min_value=-(10**20), max_value=10**20)
    | st.floats(allow_nan=False, allow_infinity=False)
    | st.text(max_size=8)
    | st.sampled_from(list(Label))  # str enums, as records may hold
)
_DOCUMENTS = st.recursive(
    _SCALARS,
    lambda inner: (
        st.lists(inner, max_size=4)
        | st.tuples(inner, inner)
        | st.dictionaries(st.text(max_size=6), inner, max_size=4)
    ),
    max_leaves=30,
)


@settings(max_examples=300, deadline=None)
@given(
    head=st.dictionaries(st.text(max_size=6), _DOCUMENTS, max_size=3),
    records=st.lists(_DOCUMENTS, max_size=6),
    piece=st.integers(min_value=1, max_value=200),
)
def test_the_streamed_json_is_the_standard_encoders_text(head, records, piece):
    """jsontext writes json.JSONEncoder(indent=2, allow_nan=False)'s bytes for any JSON
    document of the types records hold, its records list streamed in pieces of any size."""
    document = {**head, "segments": records}
    expected = json.JSONEncoder(indent=2, allow_nan=False).encode(document)
    assert "".join(jsontext.iterencode(document, "segments", piece)) == expected
    assert jsontext.encode(records, 3) == json.dumps(records, indent=2).replace("\n", "\n      ")


def test_the_streamed_json_refuses_what_json_refuses():
    for bad in (float("nan"), [1.0, float("inf")], {"a": -float("inf")}):
        with pytest.raises(ValueError, match="not JSON compliant"):
            "".join(jsontext.iterencode({"segments": [bad]}, "segments", 10))
    with pytest.raises(TypeError, match="not JSON serializable"):
        jsontext.encode({"a": {1, 2}})
    assert jsontext.encode({3: 2, 2.5: None, True: "x", None: []}) == json.dumps(
        {3: 2, 2.5: None, True: "x", None: []}, indent=2
    )


def test_a_short_diagnosis_does_not_load_numba():
    """Issue 35: numba's import and first call (~0.3 s of CPU) are paid only once a process
    has built ``KERNEL_PAIRS`` pairs; a diagnosis of a few thousand epochs never loads it."""
    import subprocess
    import sys

    code = (
        "import sys, numpy as np, credcli\n"
        "e = np.random.default_rng(0).standard_normal((3000, 2)) + 0.2\n"
        "credcli.diagnose(e, np.eye(2), rng=0)\n"
        "print('numba' in sys.modules)"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip().splitlines()[-1] == "False"


def test_a_parquet_log_is_diagnosed_without_pandas(tmp_path):
    """Issue 35 (the 2M-epoch segment's 500 MB): a Parquet log is read a column at a time
    by pyarrow, and nothing on its way to the JSON report needs pandas, whose import alone
    holds some 40 MB (since session 36 the check of a CSV's name columns imported it for
    every log: the 2M segment 469 → 511 MiB of RSS)."""
    import subprocess
    import sys

    import pandas as pd

    e = np.random.default_rng(0).standard_normal((400, 2))
    frame = pd.DataFrame({"time": np.arange(400) * 0.1, "truth_0": e[:, 0], "truth_1": e[:, 1]})
    frame = frame.assign(est_0=0.0, est_1=0.0, cov_0_0=1.0, cov_0_1=0.0, cov_1_1=1.0)
    frame.to_parquet(tmp_path / "log.parquet")
    code = (
        "import sys\n"
        "from credcli.cli.edge import main\n"
        f"code = main(['diagnose', {str(tmp_path / 'log.parquet')!r}, '-f', 'json',"
        f" '-o', {str(tmp_path / 'out.json')!r}, '--jobs', '1'])\n"
        "print(code, 'pandas' in sys.modules)"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip().splitlines()[-1] == "0 False"
    assert (tmp_path / "out.json").stat().st_size > 0


_LOADED: list = []  # what a before_fork call loaded in the test's process


def _load() -> None:
    _LOADED.append("kernels")


def _loaded(_) -> int:
    return len(_LOADED)


@pytest.mark.skipif(sys.platform != "linux", reason="workers are forked on Linux only")
def test_what_is_loaded_just_before_the_fork_every_worker_has(monkeypatch):
    """Issue 30 (two workers' numba start-up): ``before_fork`` runs once, here, before the
    workers fork, and every worker then has what it loaded; spawned workers would not
    inherit it, so it is not called for them."""
    from credcli.schedule import pool

    monkeypatch.setattr(pool, "start_method", lambda: "fork")
    _LOADED.clear()
    try:
        assert list(pool.ordered_map(_loaded, range(6), 2, before_fork=_load)) == [1] * 6
        assert _LOADED == ["kernels"]
        _LOADED.clear()
        assert list(pool.ordered_map(_loaded, range(6), 1, before_fork=_load)) == [0] * 6
        monkeypatch.setattr(pool, "start_method", lambda: "spawn")
        assert list(pool.WorkerPool(2).map(_loaded, [], _load)) == [] and _LOADED == []
    finally:
        _LOADED.clear()


def test_the_kernels_are_warmed_before_the_fork_where_each_worker_would_load_them(
    monkeypatch,
):
    """Each worker's share of the ELTs' pairs decides: 1,000 segments of 1,000 epochs give
    two workers 249,750,000 pairs each, above KERNEL_PAIRS (40,000,000); 100 such segments
    among 16 workers give each 3,121,875; an ELT sees at most max_elt_epochs epochs."""
    from credcli.schedule import plans as scheduling
    from credcli.segments import Segments

    calls = []
    monkeypatch.setattr(scheduling.compiled, "warm", lambda: calls.append(1))
    config = DiagnosisConfig()

    def plan(segments, epochs):
        bounds = np.arange(segments + 1) * epochs
        names = [str(i) for i in range(segments)]
        return (None, Segments(names, np.arange(bounds[-1]), bounds, None, None))

    scheduling._warm_kernels([plan(1000, 1000)], config, 2)
    assert calls == [1]
    scheduling._warm_kernels([plan(100, 1000)], config, 16)
    assert calls == [1]
    huge = replace(config, max_elt_epochs=2000)  # one segment of 10^6 epochs: 1,999,000 pairs
    scheduling._warm_kernels([plan(1, 1_000_000)], huge, 2)
    assert calls == [1]
    assert flips.kernel_repaid(40_000_001) and not flips.kernel_repaid(40_000_000)


def test_the_kernels_load_in_a_thread_while_the_logs_are_read_and_before_any_fork(
    monkeypatch, capsys
):
    """With a forked pool, ``kernels_loading`` runs ``compiled.warm`` in another thread
    during its body and joins it when the body ends, also when the body raises; an error
    in the thread is dropped (the warm() that needs the kernels reports it); without a
    pool or with spawned workers nothing is loaded."""
    import importlib.util
    import threading
    import time
    from types import SimpleNamespace

    from credcli.schedule import plans as scheduling

    if importlib.util.find_spec("numba") is None:
        pytest.skip("numba is not installed (the extra `fast`)")
    seen = []

    def slow_warm():
        time.sleep(0.05)
        seen.append(threading.current_thread() is not threading.main_thread())
        return True

    monkeypatch.setattr(scheduling.compiled, "_warm", [False])
    monkeypatch.setattr(scheduling.compiled, "warm", slow_warm)
    forked, spawned = SimpleNamespace(forked=True), SimpleNamespace(forked=False)
    with scheduling.kernels_loading(forked):
        pass
    assert seen == [True]
    with pytest.raises(KeyError), scheduling.kernels_loading(forked):
        raise KeyError("a log that cannot be read")
    assert seen == [True, True]
    for pool in (None, spawned):
        with scheduling.kernels_loading(pool):
            pass
    assert seen == [True, True]

    def failing_warm():
        raise RuntimeError("numba's cache is unreadable")

    monkeypatch.setattr(scheduling.compiled, "warm", failing_warm)
    with scheduling.kernels_loading(forked):
        pass
    assert capsys.readouterr().err == ""
    assert all(t.name != "credcli-kernels" for t in threading.enumerate())


def test_warmed_kernels_are_used_from_the_first_pair_with_numpys_bits():
    """After ``compiled.warm`` (numba loaded), the ELT takes the compiled kernel at once,
    not after KERNEL_PAIRS pairs, and gives the numpy path's bits (in a fresh process, so
    that this one's count of pairs is not involved)."""
    import subprocess

    code = (
        "import numpy as np\n"
        "from credcli.engine import compiled, flips\n"
        "s = np.random.default_rng(3).standard_normal((300, 2))\n"
        "before = flips._band_kernel(300) is None\n"
        "a = flips.pair_matrix(s)\n"
        "print(before, compiled.warm(), flips._band_kernel(300) is not None,"
        " bool(np.array_equal(a, flips.pair_matrix(s))))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    if "False" in out.stdout.split()[1:2]:
        pytest.skip("numba is not installed (the extra `fast`)")
    assert out.stdout.split() == ["True", "True", "True", "True"]


def test_a_report_reads_each_result_as_it_is_diagnosed(monkeypatch):
    """Issue 35 item 3: unless every result is kept (figures, `gate`, the API), `diagnose`
    reads each segment's result into the report before the next segment is diagnosed and
    keeps none, or (``--fail-on``) only its verdict; the report is the one made from the
    held results, notes and records, and the kept verdicts decide and write ``--fail-on``
    as the results do."""
    from credcli import workflows
    from credcli.ci.gate import fail_on_verdict, parse_fail_on
    from credcli.ci.reports import fail_on_cases
    from credcli.engine.diagnosis import SegmentVerdict
    from credcli.io.schema import LogReading
    from credcli.report import builders
    from credcli.requests import DiagnoseRequest, Kept
    from credcli.schedule import plans as scheduling

    events = []
    diagnose, record = scheduling.diagnose_segment, builders.segment_record

    def diagnosed(e, c, config, seed, name, *rest):
        events.append(("diagnosed", name))
        return diagnose(e, c, config, seed, name, *rest)

    def recorded(result):
        events.append(("recorded", result.segment))
        return record(result)

    monkeypatch.setattr(scheduling, "diagnose_segment", diagnosed)
    monkeypatch.setattr(builders, "segment_record", recorded)
    log = ROOT / "sample_data" / "estimator_log.csv"
    runs = {}
    for keep in Kept:
        events.clear()
        request = DiagnoseRequest((log,), LogReading(window="20s"), keep=keep)
        run = workflows.run_diagnose(request)
        names = [r["segment"] for r in run.report.document["segments"]]
        assert len(names) >= 5
        steps = [step for name in names for step in (("diagnosed", name), ("recorded", name))]
        if keep is Kept.RESULTS:  # every segment diagnosed, then every record made
            assert events == steps[::2] + steps[1::2]
        else:
            assert events == steps
        runs[keep] = run
    held = runs[Kept.RESULTS]
    assert runs[Kept.NOTHING].results == []
    verdicts = runs[Kept.VERDICTS].results
    assert all(isinstance(v, SegmentVerdict) for v in verdicts)
    assert list(verdicts) == [r.verdict() for r in held.results]
    labels = {r.diagnosis.label.value for r in held.results}
    fail_on = parse_fail_on(",".join(sorted(labels - {"credible"})) or "optimism")
    for run in runs.values():
        read = run.report
        assert read.notes == held.report.notes and len(read.notes) > 0
        assert list(read.document["segments"]) == list(held.report.document["segments"])
        assert read.document.keys() == held.report.document.keys()
        assert [list(t.rows) for t in read.tables] == [list(t.rows) for t in held.report.tables]
    expected = fail_on_verdict(held.results, fail_on)
    assert not expected[0] and fail_on_verdict(verdicts, fail_on) == expected
    cases = fail_on_cases(verdicts, expected[2], fail_on)
    assert cases == fail_on_cases(held.results, expected[2], fail_on)


_VALUES = st.recursive(
    st.none() | st.booleans() | st.integers() | st.floats(allow_nan=False) | st.text(max_size=3),
    lambda inner: st.lists(inner, max_size=3),
    max_leaves=6,
)


@settings(max_examples=200, deadline=None)
@given(
    st.lists(
        st.sampled_from([st.floats(allow_nan=False), st.integers(-(2**70), 2**70), _VALUES]),
        min_size=1,
        max_size=4,
    ).flatmap(
        lambda kinds: st.lists(
            st.tuples(*[kind | st.none() for kind in kinds]), min_size=1, max_size=6
        )
    )
)
def test_a_record_block_gives_back_each_record_type_for_type(rows):
    """A block of records held as columns (issue 35 item 3: 10⁵ records as 10⁵ dicts held
    half the memory of the report) gives back each record as it was: every float to the
    bit (−0.0 too), an int as an int and a bool as a bool, None where it was, lists as
    lists, by iteration and by index. ``repr`` tells 1 from 1.0 and True, and −0.0 from
    0.0."""
    from credcli.report.records import RecordBlock

    records = [{f"k{j}": v for j, v in enumerate(row)} for row in rows]
    block = RecordBlock.of(records)
    assert repr(list(block)) == repr(records)
    assert repr([block[k] for k in range(len(records))]) == repr(records)
    assert repr(block[-1]) == repr(records[-1]) and len(block) == len(records)


def test_record_blocks_pack_numbers_and_write_every_format_alike(monkeypatch):
    """The report of segments whose records are held in blocks (every 3 here, of
    BLOCK_RECORDS in use) writes the same text in every format as its records held as
    dicts, runs of short segments among them; the numbers of a block are numpy arrays."""
    from credcli import log_from_arrays
    from credcli.report import builders
    from credcli.report.formats import OutputFormat
    from credcli.report.records import RecordBlock
    from credcli.report.render import text_pieces
    from credcli.schedule.plans import diagnose_plans
    from credcli.segments import split

    rng = np.random.default_rng(9)
    names = [*["a"] * 40, "s0", "s1", *["b"] * 30, *["c"] * 50, *["d"] * 25, "s2", *["e"] * 60]
    e = rng.standard_normal((len(names), 2)) + np.where(np.array(names) == "c", 0.8, 0.0)[:, None]
    log = log_from_arrays(errors=e, cov=np.eye(2), segment=names, time=np.arange(len(names)) * 0.1)
    config = DiagnosisConfig()
    results = diagnose_plans([(log, split(log))], config, seed=1)
    texts = {}
    for size in (3, 10**9):
        monkeypatch.setattr(builders, "BLOCK_RECORDS", size)
        report = builders.diagnose_report(results, config, {}, {}, show_all=False)
        blocks = [p for p in report.document["segments"].parts if isinstance(p, RecordBlock)]
        assert bool(blocks) == (size == 3)
        if blocks:
            by_key = dict(zip(blocks[0].keys, blocks[0].columns, strict=True))
            assert by_key["anees"].dtype == np.float64 and by_key["n"].dtype == np.int64
        texts[size] = ["".join(text_pieces(report, fmt, 400)) for fmt in OutputFormat]
    assert texts[3] == texts[10**9]


@pytest.mark.parametrize("keep", ["nothing", "verdicts"])
def test_an_error_while_the_report_reads_stops_the_diagnosis_at_once(monkeypatch, keep):
    """When the report fails while it reads results as they are diagnosed (an error, or
    Ctrl-C, in the main process), the iterator that diagnoses them is closed before the
    error leaves `run_diagnose`, so that worker processes stop then, not when the
    traceback is dropped; no later segment is diagnosed."""
    from credcli import workflows
    from credcli.io.schema import LogReading
    from credcli.report import builders
    from credcli.requests import DiagnoseRequest, Kept
    from credcli.schedule import plans as scheduling

    closed, taken = [], []
    ordered = scheduling.ordered_map

    def watched(*args):
        inner = ordered(*args)
        try:
            for out in inner:
                taken.append(len(out))
                yield out
        finally:
            closed.append(True)
            inner.close()

    def failing(result):
        if len(taken) == 3:
            raise RuntimeError("the report failed")
        return record(result)

    record = builders.segment_record
    monkeypatch.setattr(scheduling, "ordered_map", watched)
    monkeypatch.setattr(builders, "segment_record", failing)
    request = DiagnoseRequest(
        (ROOT / "sample_data" / "estimator_log.csv",), LogReading(window="20s"), keep=Kept(keep)
    )
    with pytest.raises(RuntimeError, match="the report failed") as caught:
        workflows.run_diagnose(request)
    assert closed == [True] and len(taken) == 3  # closed while the traceback is held
    assert caught.traceback  # (held until here)


def test_a_json_file_is_written_as_its_segments_are_diagnosed(monkeypatch):
    """Issue 35 item 3: with ``write`` (`diagnose -f json -o FILE`), the writer has each
    segment's text before the segment after next is diagnosed (the encoder holds one piece
    back), so that at most two are diagnosed ahead of it, and nothing is held after; the
    text is the whole report's, byte for byte, and the verdicts are kept where the request
    asks for them (``Kept.VERDICTS``)."""
    from credcli import workflows
    from credcli.engine.diagnosis import SegmentVerdict
    from credcli.io.schema import LogReading
    from credcli.report import records, render
    from credcli.report.formats import OutputFormat
    from credcli.requests import DiagnoseRequest, Kept
    from credcli.schedule import plans as scheduling

    diagnose, record = scheduling.diagnose_segment, records.segment_record
    counts = {"diagnosed": 0, "recorded": 0, "written": 0}
    ahead: list[int] = []  # segments diagnosed whose text the writer has not had yet

    def diagnosed(e, c, config, seed, name, *rest):
        counts["diagnosed"] += 1
        ahead.append(counts["diagnosed"] - counts["written"])
        return diagnose(e, c, config, seed, name, *rest)

    def recorded(result):
        counts["recorded"] += 1
        return record(result)

    monkeypatch.setattr(scheduling, "diagnose_segment", diagnosed)
    monkeypatch.setattr(records, "segment_record", recorded)
    log = ROOT / "sample_data" / "estimator_log.csv"
    held = workflows.run_diagnose(DiagnoseRequest((log,), LogReading(window="20s")))
    whole = "".join(render.text_pieces(held.report, OutputFormat.JSON))
    names = [r["segment"] for r in json.loads(whole)["segments"]]
    assert len(names) >= 5
    monkeypatch.setattr(render, "TEXT_PIECE", 1)  # a piece as soon as a record's text is made
    monkeypatch.setattr(render, "TEXT_RECORDS", 1)
    written: list[str] = []

    def write(report):
        for piece in render.text_pieces(report, OutputFormat.JSON):
            counts["written"] += sum(f'"segment": "{n}"' in piece for n in names)
            written.append(piece)

    for keep in (Kept.NOTHING, Kept.VERDICTS):
        counts.update(dict.fromkeys(counts, 0))
        ahead.clear()
        written.clear()
        request = DiagnoseRequest((log,), LogReading(window="20s"), keep=keep)
        run = workflows.run_diagnose(request, write=write)
        assert "".join(written) == whole
        assert counts == dict.fromkeys(counts, len(names))
        assert ahead[:2] == [1, 2] and max(ahead) == 2  # the one held back, and this one
        assert list(run.report.document["segments"].parts) == []  # read once, nothing held
    assert all(isinstance(v, SegmentVerdict) for v in run.results)
    assert list(run.results) == [r.verdict() for r in held.results]


def test_gate_keeps_what_it_compares_of_each_segment_and_no_result(monkeypatch, tmp_path):
    """Issue 35 item 3 for `gate`: each segment's record is made once, as the segment is
    diagnosed, and only what the gate compares is kept: at every diagnosis at most the
    one before it is still alive (the encoder-free writer holds none back), and each
    current Snapshot has its diagnosis's label, NCI, ANEES, ELT p-value, untested
    questions and dimension, as a whole run's results say."""
    import gc

    from credcli import workflows
    from credcli.cli import main
    from credcli.cli.options import RuleOptions, RunOptions, SegmentOptions, ThresholdOptions
    from credcli.cli.settings import gate_request
    from credcli.engine.diagnosis import SegmentDiagnosis
    from credcli.io.schema import LogReading
    from credcli.report import records
    from credcli.requests import DiagnoseRequest
    from credcli.schedule import plans as scheduling

    log = ROOT / "sample_data" / "estimator_log.csv"
    baseline = tmp_path / "baseline.json"
    assert main(["baseline", str(log), "--window", "20s", "-o", str(baseline)]) == 0
    window = SegmentOptions(window="20s")
    request = gate_request(
        log, baseline, None, ThresholdOptions(), None, window, RuleOptions(), None, RunOptions()
    )
    diagnose, record = scheduling.diagnose_segment, records.segment_record
    alive: list[int] = []  # SegmentDiagnosis objects alive as each segment is diagnosed
    made = {"records": 0}

    def diagnosed(*args):
        gc.collect()
        alive.append(sum(isinstance(o, SegmentDiagnosis) for o in gc.get_objects()))
        return diagnose(*args)

    def recorded(result):
        made["records"] += 1
        return record(result)

    monkeypatch.setattr(scheduling, "diagnose_segment", diagnosed)
    monkeypatch.setattr(records, "segment_record", recorded)
    gc.collect()
    gc.freeze()  # the objects of earlier tests are neither collected nor counted again
    try:
        gated = workflows.run_gate(request)
    finally:
        gc.unfreeze()
    monkeypatch.setattr(scheduling, "diagnose_segment", diagnose)
    results = workflows.run_diagnose(DiagnoseRequest((log,), LogReading(window="20s"))).results
    assert len(results) >= 5 and made["records"] == len(results)  # the gate's, once each
    assert alive[0] == 0 and max(alive[: len(results)]) <= 1
    current = [c.new for c in gated.comparisons]
    for snapshot, result in zip(current, results, strict=True):
        d = result.diagnosis
        assert (snapshot.segment, snapshot.label, snapshot.untested, snapshot.dim) == (
            result.segment,
            d.label,
            tuple(q.value for q in d.untested),
            d.dim,
        )
        assert (snapshot.nci, snapshot.anees, snapshot.elt_pvalue) == (d.nci, d.anees, d.elt_pvalue)


def test_gate_reads_segments_too_short_for_a_verdict_as_their_baseline_wrote_them(tmp_path):
    """Segments too short for a verdict are diagnosed together and recorded as a batch
    (:class:`credcli.report.records.RecordBatch`); the gate reads each record of the batch
    (``StreamedRecords.dicts``) as the baseline of the same log wrote it."""
    from credcli.cli import main

    e = np.random.default_rng(5).standard_normal((300, 2))
    frame = pd.DataFrame({"time": np.arange(300) * 0.1, "segment": np.arange(300) // 10})
    frame = frame.assign(truth_0=e[:, 0], truth_1=e[:, 1], est_0=0.0, est_1=0.0)
    log = tmp_path / "log.csv"
    frame.assign(cov_0_0=1.0, cov_0_1=0.0, cov_1_1=1.0).to_csv(log, index=False)
    baseline, out = tmp_path / "baseline.json", tmp_path / "gate.json"
    short = ["--min-epochs", "11"]  # every segment of 10 epochs too short
    assert main(["baseline", str(log), *short, "-o", str(baseline)]) == 0
    assert main(["gate", str(log), "-b", str(baseline), *short, "-f", "json", "-o", str(out)]) == 0
    written = json.loads(baseline.read_text())["segments"]
    compared = json.loads(out.read_text())["segments"]
    assert len(written) == 30 and {s["label"] for s in written} == {"insufficient-data"}
    assert [c["label"] for c in compared] == [s["label"] for s in written]
    assert [c["baseline"] for c in compared] == written == [c["current"] for c in compared]


def test_a_segment_that_fails_while_the_json_is_written_leaves_the_file_as_it_was(tmp_path, capsys):
    """A later segment's error while `diagnose -f json -o FILE` streams the document (a
    NEES that overflows) exits 2 with one line naming the segment; the file is as it was,
    and none beside it is left."""
    from credcli.cli import main

    rng = np.random.default_rng(4)
    e = rng.standard_normal((60, 2))
    e[45, 0] = 1e200
    frame = pd.DataFrame({"time": np.arange(60) * 0.1, "segment": ["a"] * 30 + ["b"] * 30})
    frame = frame.assign(truth_0=e[:, 0], truth_1=e[:, 1], est_0=0.0, est_1=0.0)
    log = tmp_path / "log.csv"
    frame.assign(cov_0_0=1.0, cov_0_1=0.0, cov_1_1=1.0).to_csv(log, index=False)
    out = tmp_path / "out.json"
    out.write_text("before\n")
    code = main(["diagnose", str(log), "-f", "json", "-o", str(out)])
    err = capsys.readouterr().err
    assert code == 2 and "segment 'b'" in err and "overflows" in err
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err
    assert out.read_text() == "before\n" and sorted(tmp_path.iterdir()) == [log, out]
    out.unlink()
    assert main(["diagnose", str(log), "-f", "json", "-o", str(out)]) == 2
    assert not out.exists()


def test_json_and_csv_files_are_streamed_where_nothing_else_reads_every_result(tmp_path):
    """`diagnose` streams ``-f json -o FILE`` and ``-f csv -o FILE`` (their columns are
    known before any result, of innovations and pooled Monte Carlo runs too); the
    screen's tables, other formats, figures, a ``--fail-on`` summary (which shows the
    tables), standard output and a device get the whole report."""
    from credcli.cli.emit import streamed_writer
    from credcli.report.formats import OutputFormat

    def streams(fmt, output=tmp_path / "out", whole=False):
        return streamed_writer(fmt, output, (), whole) is not None

    assert streams(OutputFormat.JSON) and streams(OutputFormat.CSV)
    assert not streams(OutputFormat.TABLE) and not streams(OutputFormat.MARKDOWN)
    assert not streams(OutputFormat.JSON, output=None)
    assert not streams(OutputFormat.JSON, output=Path("/dev/null"))
    assert not streams(OutputFormat.JSON, whole=True)  # figures, a --fail-on summary


def test_fail_on_streams_the_file_unless_its_summary_is_written(tmp_path, monkeypatch):
    """``--fail-on`` reads each segment's verdict, which a streamed run keeps; only its
    Markdown summary (``--summary``, $GITHUB_STEP_SUMMARY) reads the report's tables. With
    neither, the JSON file is written as the segments are diagnosed; with either, the whole
    report is made first and the summary shows the segment table. The file, the JUnit
    report and the exit code are the same in every case."""
    from credcli import workflows
    from credcli.cli import main

    streamed: list[bool] = []
    run_diagnose = workflows.run_diagnose

    def spy(request, progress=None, runner=None, write=None):
        streamed.append(write is not None)
        return run_diagnose(request, progress, runner, write)

    monkeypatch.setattr(workflows, "run_diagnose", spy)
    monkeypatch.delenv("GITHUB_STEP_SUMMARY", raising=False)
    log = ROOT / "sample_data" / "estimator_log.csv"
    step = tmp_path / "step.md"
    cases = {"none": [], "summary": ["--summary", str(tmp_path / "s.md")], "step": []}
    outputs = {}
    for case, extra in cases.items():
        if case == "step":
            monkeypatch.setenv("GITHUB_STEP_SUMMARY", str(step))
        out, junit = tmp_path / f"{case}.json", tmp_path / f"{case}.xml"
        argv = ["diagnose", str(log), "--fail-on", "optimism", "-f", "json", "-o", str(out)]
        code = main([*argv, "--junit", str(junit), *extra])
        outputs[case] = (code, out.read_bytes(), junit.read_bytes())
    assert streamed == [True, False, False]
    assert outputs["none"] == outputs["summary"] == outputs["step"]
    assert outputs["none"][0] == 1  # the sample has an optimistic segment
    for summary in (tmp_path / "s.md", step):
        assert "| segment |" in summary.read_text()


@pytest.mark.parametrize("fmt", ["json", "csv"])
def test_a_streamed_file_is_the_whole_reports_text(tmp_path, capsys, fmt):
    """The JSON and CSV files written as the segments are diagnosed are, byte for byte, the
    text of the whole report (standard output), segments too short for a verdict (one
    record batch) among them; with ``--fail-on``, which reads the whole report, too; of
    several logs, whose CSV adds a table of the logs counted as the segments pass; and a
    baseline's file is its standard output's."""
    from credcli.cli import main

    rng = np.random.default_rng(8)
    names = [*["a"] * 40, "s0", "s1", *["b"] * 30, *["c"] * 50, "s2", *["d"] * 25]
    e = rng.standard_normal((len(names), 2)) + np.where(np.array(names) == "c", 0.8, 0.0)[:, None]
    frame = pd.DataFrame({"time": np.arange(len(names)) * 0.1, "segment": names})
    frame = frame.assign(truth_0=e[:, 0], truth_1=e[:, 1], est_0=0.0, est_1=0.0)
    log = tmp_path / "log.csv"
    frame.assign(cov_0_0=1.0, cov_0_1=0.0, cov_1_1=1.0).to_csv(log, index=False)
    out = tmp_path / f"out.{fmt}"
    assert main(["diagnose", str(log), "-f", fmt]) == 0
    whole = capsys.readouterr().out
    assert main(["diagnose", str(log), "-f", fmt, "-o", str(out)]) == 0
    assert out.read_bytes() == whole.encode() and whole.count("s0") >= 1
    out.unlink()  # --fail-on reads the whole report (its summary's tables): the same file
    assert main(["diagnose", str(log), "-f", fmt, "-o", str(out), "--fail-on", "bias"]) == 1
    assert out.read_bytes() == whole.encode()
    other = tmp_path / "other.csv"  # several logs: the log's column, and the logs' table
    frame.assign(truth_0=-e[:, 1], cov_0_0=2.0, cov_0_1=0.0, cov_1_1=1.0).to_csv(other, index=False)
    assert main(["diagnose", str(log), str(other), "-f", fmt]) == 0
    whole = capsys.readouterr().out
    assert main(["diagnose", str(log), str(other), "-f", fmt, "-o", str(out)]) == 0
    assert (
        out.read_bytes() == whole.encode()
        and whole.count("logs compared" if fmt == "csv" else '"path"') == 2
    )
    if fmt == "json":  # a baseline is streamed to its file too
        assert main(["baseline", str(log)]) == 0
        whole = capsys.readouterr().out
        assert main(["baseline", str(log), "-o", str(out)]) == 0
        assert out.read_bytes() == whole.encode() and '"kind": ' in whole


@pytest.mark.parametrize("window", [[], ["--window", "10s"]])
def test_monte_carlo_runs_streamed_are_the_whole_reports_text(capsys, tmp_path, window):
    """Pooled Monte Carlo runs (`--monte-carlo`) are one log's segments: their CSV file,
    written as the segments are diagnosed, is the whole report's text byte for byte (no
    table of the runs as logs), as their JSON is."""
    from helpers import SAMPLE

    from credcli.cli import main

    runs = [str(SAMPLE / "formats" / f"mc_run_{k}.csv") for k in (1, 2, 3)]
    for fmt in ("csv", "json"):
        args = ["diagnose", *runs, "--monte-carlo", *window, "-f", fmt]
        assert main(args) == 0
        whole = capsys.readouterr().out
        out = tmp_path / f"out.{fmt}"
        assert main([*args, "-o", str(out)]) == 0
        assert out.read_bytes() == whole.encode() and "monte-carlo (3 runs)" in whole
        assert "logs compared" not in whole


def test_innovations_streamed_are_the_whole_reports_text(capsys, tmp_path):
    """A log of innovations has the whiteness column and, in every record, the whiteness
    keys (None for a segment too short for the test: N < d + 5), so its CSV's columns are
    known before any result: the CSV and JSON files written as the segments are diagnosed
    are the whole report's text byte for byte, the short segment first or not."""
    import csv
    import io
    import json

    from credcli.cli import main

    rng = np.random.default_rng(5)
    for names in ([*["s"] * 6, *["a"] * 80], [*["a"] * 80, *["s"] * 6]):
        e = rng.standard_normal((len(names), 2))
        frame = pd.DataFrame({"time": np.arange(len(names)) * 0.1, "segment": names})
        frame = frame.assign(innov_0=e[:, 0], innov_1=e[:, 1])
        log = tmp_path / "innov.csv"
        frame.assign(innov_cov_0_0=1.0, innov_cov_0_1=0.0, innov_cov_1_1=1.0).to_csv(
            log, index=False
        )
        for fmt in ("csv", "json"):
            args = ["diagnose", str(log), "--innovations", "-f", fmt]
            assert main(args) == 0
            whole = capsys.readouterr().out
            out = tmp_path / f"out.{fmt}"
            assert main([*args, "-o", str(out)]) == 0
            assert out.read_bytes() == whole.encode()
        rows = {
            r["segment"]: r
            for r in csv.DictReader(io.StringIO(out.with_suffix(".csv").read_text()))
        }
        assert rows["s"]["whiteness_pvalue"] == "" and float(rows["a"]["whiteness_pvalue"]) > 0
        records = {r["segment"]: r for r in json.loads(whole)["segments"]}
        assert records["s"]["whiteness_rejected"] is None and "whiteness_lags" in records["a"]


def test_the_streamed_json_of_no_records_is_an_empty_list():
    """Texts of no record (a streamed document whose results are none) write ``[]``, as
    the encoder writes an empty list."""
    document = {"version": 1, "segments": [], "tail": {"a": 1}}
    expected = json.JSONEncoder(indent=2).encode(document)
    assert "".join(jsontext.iterencode(document, "segments", 1, iter([[], []]))) == expected


def test_the_report_lists_ten_findings_and_correlated_innovations_then_counts_the_rest():
    """The notes read a part at a time (issue 35 item 3) list at most ten findings and ten
    segments with correlated innovations, in order, then say how many more there were;
    the table gets its whiteness column once any segment has the test."""
    from dataclasses import replace

    from credcli import diagnose_log, read_log
    from credcli.engine.whiteness import Whiteness
    from credcli.report import builders

    first = diagnose_log(read_log(ROOT / "sample_data" / "estimator_log.csv"))[0]
    correlated = Whiteness(50.0, 1e-6, 10, 10, 0.01)
    results = [
        replace(
            first,
            segment=f"s{k}",
            diagnosis=replace(first.diagnosis, findings=(f"f{k}a", f"f{k}b")),
            whiteness=correlated if k % 2 else Whiteness(5.0, 0.9, 10, 10, 0.01),
        )
        for k in range(30)
    ]
    report = builders.diagnose_report(results, DiagnosisConfig(), {}, {}, False)
    notes = report.notes
    findings = [f"s{k}: f{k}{x}" for k in range(5) for x in "ab"]
    assert [n for n in notes if ": f" in n] == findings
    assert "... and 50 more finding(s); see the JSON output" in notes
    white = [n for n in notes if "innovations correlated" in n]
    assert [n.split(":")[0] for n in white] == [f"s{k}" for k in range(1, 21, 2)]
    assert "... and 5 more segment(s) with correlated innovations" in notes
    assert "whiteness_pvalue" in [c.key for c in report.tables[0].columns]


@pytest.mark.parametrize("scale", [1e-200, 1.0, 1e200])
def test_closed_form_inverse_square_root_is_eigh_s(scale):
    """Σ^{-1/2} of 2 × 2 covariances in closed form (the ELT's whitening, Eq. (12)): within
    rounding times the condition number of the eigendecomposition's U Λ^{-1/2} Uᵀ, at any
    scale, symmetric, and W Σ W = I."""
    from credcli.engine.linalg import inverse_sqrt_2x2

    rng = np.random.default_rng(3)
    a = rng.standard_normal((2000, 2, 2))
    cov = (a @ a.transpose(0, 2, 1) + 1e-6 * np.eye(2)) * scale
    w = inverse_sqrt_2x2(cov)
    lam, vecs = np.linalg.eigh(cov)
    expected = np.einsum("nij,nj,nkj->nik", vecs, 1.0 / np.sqrt(lam), vecs)
    cond = lam[:, 1] / lam[:, 0]
    error = np.abs(w - expected).max(axis=(1, 2)) / np.abs(expected).max(axis=(1, 2))
    assert np.all(error <= 1e-15 * 50 * cond)
    np.testing.assert_array_equal(w, w.transpose(0, 2, 1))
    identity = np.einsum("nij,njk,nkl->nil", w, cov, w)
    assert np.all(np.abs(identity - np.eye(2)).max(axis=(1, 2)) <= 1e-15 * 50 * cond)


def test_closed_form_inverse_square_root_of_near_singular_covariances_is_finite():
    """Covariances of condition near 1/ε that Cholesky still factors: wherever ``eigh``
    finds both eigenvalues positive, Σ^{-1/2} is finite (the closed form's determinant can
    cancel to zero there, and ``eigh`` takes over)."""
    from credcli.engine.linalg import inverse_sqrt_2x2

    theta = np.random.default_rng(5).uniform(0.0, np.pi, 20_000)
    u = np.stack([np.cos(theta), np.sin(theta)], axis=1)
    cov = u[:, :, None] * u[:, None, :] + 1e-16 * np.eye(2)
    positive = np.linalg.eigvalsh(cov)[:, 0] > 0
    w = inverse_sqrt_2x2(cov[positive])
    assert positive.sum() > 19_000 and np.isfinite(w).all()


def test_the_closed_forms_chunks_of_epochs_give_one_passs_bits(monkeypatch):
    """The 2 × 2 closed forms run over chunks of CACHED_EPOCHS epochs, for speed alone:
    chunks of 7 epochs and one chunk of every epoch give the same bits, near-singular
    epochs (where ``eigh`` takes over) and scales from 1e-30 to 1e30 included."""
    from credcli.engine import linalg

    rng = np.random.default_rng(8)
    a = rng.standard_normal((3000, 2, 2)) * np.exp(rng.uniform(-35, 35, (3000, 1, 1)))
    cov = a @ a.transpose(0, 2, 1)
    u = np.stack([np.cos(rng.uniform(0, np.pi, 300)), np.sin(rng.uniform(0, np.pi, 300))], 1)
    cov[::10] = u[:, :, None] * u[:, None, :] + 1e-16 * np.eye(2)
    monkeypatch.setattr(linalg, "CACHED_EPOCHS", 7)
    chunked = linalg.inverse_sqrt_2x2(cov), *linalg.eigenvalues_2x2(cov)
    monkeypatch.setattr(linalg, "CACHED_EPOCHS", 1 << 20)
    whole = linalg.inverse_sqrt_2x2(cov), *linalg.eigenvalues_2x2(cov)
    assert not np.all(chunked[2] > 0)  # eigh's epochs are among them
    for x, y in zip(chunked, whole):
        np.testing.assert_array_equal(x, y)


@pytest.mark.parametrize("scale", [1e-300, 1.0, 1e300])
def test_closed_form_cholesky_of_2x2_covariances_is_lapacks(scale):
    """The 2 × 2 Cholesky factors in closed form: lower triangular, L Lᵀ = Σ to rounding
    at any scale (correlation near ±1 included), and LAPACK's (``numpy.linalg.cholesky``)
    to rounding where the matrix is well conditioned (near ±1 the last pivot cancels, and
    any two correct factorisations differ there by its conditioning, not by ulps)."""
    from credcli.engine.linalg import cholesky_2x2

    rng = np.random.default_rng(8)
    a = rng.standard_normal((5000, 2, 3))
    cov = a @ a.transpose(0, 2, 1)
    cov[:100, 1, 1] = cov[:100, 1, 0] ** 2 / cov[:100, 0, 0] * (1 + 1e-9)  # ρ² = 1 − 10⁻⁹
    cov[:100, 0, 1] = cov[:100, 1, 0]
    cov = cov * scale
    got, want = cholesky_2x2(cov), np.linalg.cholesky(cov)
    assert np.all(got[:, 0, 1] == 0)
    unit = np.abs(want).max(axis=(1, 2), keepdims=True)
    well = slice(100, None)
    np.testing.assert_allclose(got[well] / unit[well], want[well] / unit[well], atol=1e-12)
    back = np.einsum("nij,nkj->nik", got, got)
    np.testing.assert_allclose(back / (unit * unit), cov / (unit * unit), rtol=0, atol=1e-12)


def test_a_covariance_the_closed_form_cannot_factor_is_named_as_lapacks_would_be():
    """Where a pivot is not positive (Σ₁₁ ≤ 0, |ρ| ≥ 1, NaN) the closed form declines and
    LAPACK decides, as before it: ``cholesky`` names the first epoch that is not positive
    definite (a NaN LAPACK passes through; the validation rejects it before any
    factorisation); a positive definite stack is factored."""
    from credcli.engine.linalg import cholesky, cholesky_2x2
    from credcli.errors import CredcliError

    good = np.broadcast_to(np.array([[4.0, 2.0], [2.0, 5.0]]), (6, 2, 2)).copy()
    np.testing.assert_array_equal(cholesky(good)[0], [[2.0, 0.0], [1.0, 2.0]])
    for bad in ([[-1.0, 0.0], [0.0, 1.0]], [[1.0, 1.0], [1.0, 1.0]], [[np.nan, 0], [0, 1]]):
        stack = good.copy()
        stack[3] = bad
        assert cholesky_2x2(stack) is None
        if np.isnan(stack).any():
            assert np.isnan(cholesky(stack)[3]).any()
            continue
        with pytest.raises(CredcliError, match=r"cov\[3\] is not positive definite"):
            cholesky(stack)


def test_the_in_place_covariance_and_residuals_are_numpys():
    """The mean test's covariance made in the scores' own copy is ``np.cov``'s, and the
    memory's residuals made in place (chunk by chunk) are those made beside the input;
    the input is overwritten only where asked."""
    from credcli.engine.batches import _covariance_overwriting
    from credcli.engine.linalg import lower_inverse
    from credcli.engine.memory import mean_free

    rng = np.random.default_rng(12)
    x = rng.standard_normal((5000, 3)) @ rng.standard_normal((3, 3)) + [1.0, -2.0, 3.0]
    want = np.cov(x, rowvar=False)
    np.testing.assert_allclose(_covariance_overwriting(x.copy()), want, rtol=1e-12)
    a = rng.standard_normal((5000, 2, 2))
    inverse = lower_inverse(np.linalg.cholesky(a @ a.transpose(0, 2, 1) + np.eye(2)))
    s = rng.standard_normal((5000, 2))
    kept = s.copy()
    beside = mean_free(s, inverse)
    np.testing.assert_array_equal(s, kept)
    inside = mean_free(s, inverse, overwrite=True)
    assert inside is s
    np.testing.assert_allclose(inside, beside, rtol=0, atol=1e-12)


def test_a_segment_that_is_the_whole_log_takes_the_summary_accuracy():
    """The accuracy of a whole log is made once, for its summary, and its one segment
    reports those figures; segments that are parts of a log compute their own."""
    from credcli import log_from_arrays
    from credcli.engine import metrics
    from credcli.schedule.plans import diagnose_plans
    from credcli.segments import log_summary, split

    e = np.random.default_rng(4).standard_normal((300, 2)) * [1.0, 3.0]
    whole = log_from_arrays(errors=e, cov=np.eye(2))
    parts = log_from_arrays(errors=e, cov=np.eye(2), segment=np.repeat(["a", "b"], 150))
    config = DiagnosisConfig()
    for log, count in ((whole, 1), (parts, 2)):
        plan = split(log)
        summary = log_summary(log, plan)
        assert len(plan) == count and summary.accuracy.max_norm > 0
        marked = replace(summary.accuracy, max_norm=-1.0)  # no error has this figure
        results = diagnose_plans([(log, plan)], config, seed=1, accuracies={log.id: marked})
        found = [r.diagnosis.accuracy for r in results]
        if count == 1:
            assert found == [marked]
        else:
            own = [metrics.accuracy(e[:150]), metrics.accuracy(e[150:])]
            for got, want in zip(found, own, strict=True):
                assert got.max_norm == want.max_norm > 0
                np.testing.assert_array_equal(got.median, want.median)


def test_a_log_that_is_surely_one_segment_starts_no_workers(tmp_path, monkeypatch):
    """A local Parquet log without a segment or run column is one segment whatever the
    jobs (`io.ingest.one_segment`, read from its metadata): no worker pool is started for
    it, and so no compiled kernels are loaded on speculation; the same log with a segment
    column, or cut into windows, does start one."""
    from credcli import workflows
    from credcli.io.ingest import one_segment
    from credcli.io.schema import LogReading, ReadOptions
    from credcli.requests import DiagnoseRequest

    n = 2_000
    e = np.random.default_rng(3).standard_normal((n, 2))
    frame = pd.DataFrame({"time": np.arange(n) * 0.01, "truth_0": e[:, 0], "truth_1": e[:, 1]})
    frame = frame.assign(est_0=0.0, est_1=0.0, cov_0_0=1.0, cov_0_1=0.0, cov_1_1=1.0)
    one, cut = tmp_path / "one.parquet", tmp_path / "cut.parquet"
    frame.to_parquet(one)
    frame.assign(segment=np.arange(n) // 1_000).to_parquet(cut)
    frame.to_csv(tmp_path / "one.csv", index=False)
    monkeypatch.setattr(workflows, "PARALLEL_MIN_BYTES", 0)  # any log is large enough
    assert one_segment(one, None, None)
    assert not one_segment(cut, None, None)
    assert not one_segment(tmp_path / "one.csv", None, None)  # not told without reading
    assert not one_segment(one, None, ReadOptions(truth=str(one)))  # paired: its own rows
    given = []

    class Pool:  # stands for the workers, started before the log is read
        forked = True

        def __init__(self, jobs, warm=None):
            self.closed = False

        def close(self):
            self.closed = True

        stop = close

    def kernels_loading(pool):  # what the read is given: stop there
        given.append((pool, pool is not None and pool.closed))
        raise RuntimeError("stop here")

    monkeypatch.setattr(workflows, "WorkerPool", Pool)
    monkeypatch.setattr(workflows.scheduling, "kernels_loading", kernels_loading)
    for path, reading in ((one, LogReading()), (cut, LogReading()), (one, LogReading(window="5s"))):
        with pytest.raises(RuntimeError, match="stop here"):
            workflows.run_diagnose(DiagnoseRequest((path,), reading, jobs=2))
    assert given[0] == (None, False)
    assert all(isinstance(pool, Pool) and not closed for pool, closed in given[1:])


_ENTRIES = st.sampled_from([0.0, -0.0, 1.5, -2.25, 3e300, -1e-300, np.inf, -np.inf, np.nan])


@settings(max_examples=200, deadline=None)
@given(
    st.integers(0, 40),
    st.sampled_from([(1,), (2,), (3,), (2, 2), (3, 3), (0,)]),
    st.data(),
)
def test_folds_over_an_epochs_entries_and_a_columns_epochs_are_numpys_reductions(n, shape, data):
    """``per_epoch`` and ``per_column`` give numpy's reductions, NaN and infinities
    included, folded up to FOLDED_ENTRIES entries and numpy's own beyond (the (3, 3)
    case); ``assert_array_equal`` does not tell −0 from 0, which max and min may order
    differently."""
    from credcli.engine.linalg import per_column, per_epoch

    size = n * int(np.prod(shape))
    values = data.draw(st.lists(_ENTRIES, min_size=size, max_size=size))
    a = np.array(values, dtype=float).reshape((n, *shape))
    axes = tuple(range(1, a.ndim))
    for ufunc in (np.logical_and, np.logical_or):
        np.testing.assert_array_equal(per_epoch(ufunc, a > 0), ufunc.reduce(a > 0, axis=axes))
    if shape == (0,):
        return
    for ufunc in (np.maximum, np.minimum):
        np.testing.assert_array_equal(per_epoch(ufunc, a), ufunc.reduce(a, axis=axes))
        if n and a.ndim == 2:
            np.testing.assert_array_equal(per_column(ufunc, a), ufunc.reduce(a, axis=0))


def test_a_tall_arrays_power_of_two_units_are_the_whole_arrays_reductions():
    """The per-column path of ``power_of_two_unit`` gives the units of numpy's reductions,
    a zero, an infinite and a NaN column included."""
    from credcli.engine.units import power_of_two_unit

    a = np.random.default_rng(5).standard_normal((5000, 6)) * [1e-200, 1.0, 3.0, 1e200, 1, 1]
    a[:, 4] = 0.0
    a[7, 5] = np.inf
    a[9, 2] = np.nan
    peak = np.maximum(a.max(axis=0), -a.min(axis=0))
    ok = np.isfinite(peak) & (peak > 0)
    expected = np.exp2(np.round(np.log2(np.where(ok, peak, 1.0))))
    np.testing.assert_array_equal(power_of_two_unit(a, axis=0), expected)
    assert expected[4] == expected[5] == expected[2] == 1.0 and expected[3] > 1e199


def test_tail_quantiles_selected_in_place_are_those_of_a_copy():
    """``overwrite`` reorders the standardized residuals, and gives the same quantiles."""
    from credcli.engine.scale import standardized, tail_quantiles

    u = standardized(np.random.default_rng(8).standard_t(4, size=(10_001, 3)))
    expected = tail_quantiles(u)
    scratch = u.copy()
    np.testing.assert_array_equal(tail_quantiles(scratch, overwrite=True), expected)
    assert not np.array_equal(scratch, u)  # it was the scratch copy that was reordered


def test_a_long_segments_nees_made_again_gives_the_same_bursts(monkeypatch):
    """A segment longer than one chunk of epochs makes its NEES again for the bursts after
    the model's tests (evidence.gather, for its peak memory): the same findings, NEES and
    labels as holding it throughout (the chunk made longer than the segment), here with a
    burst of 200 epochs at 3× the claimed spread planted in 270,000."""
    from credcli.engine import linalg

    rng = np.random.default_rng(5)
    n = linalg.EPOCH_CHUNK + 8_000
    errors = rng.standard_normal((n, 2))
    errors[100_000:100_200] *= 3.0
    cov = np.broadcast_to(np.eye(2), (n, 2, 2))
    again = diagnose_errors(errors, cov, rng=1)
    assert any(f.startswith("burst: epochs 100001") for f in again.findings), again.findings
    monkeypatch.setattr(linalg, "EPOCH_CHUNK", n)
    held = diagnose_errors(errors, cov, rng=1)
    assert held.findings == again.findings
    assert (held.label, held.anees, held.nees_label) == (again.label, again.anees, again.nees_label)


@pytest.mark.parametrize("d", [2, 3])
def test_factors_made_by_chunks_give_the_whole_segments_numbers(d):
    """A long segment makes its whitening factors, NEES, GLS scores and the ELT's whitened
    errors again a chunk of epochs at a time rather than hold them (evidence.gather): over
    several chunks, the bits of the factors made once (linalg.whitening_factors,
    linalg.by_inverse_chunks, scale._per_epoch_scores, elt.whiten), and GLS residuals whose
    scores come from the covariances when read are those made with them."""
    from credcli.engine import linalg, metrics
    from credcli.engine.elt import whiten
    from credcli.engine.scale import _per_epoch_scores, gls_residuals

    rng = np.random.default_rng(d)
    n = linalg.EPOCH_CHUNK + 17
    a = rng.standard_normal((n, d, d))
    cov = a @ a.transpose(0, 2, 1) + 0.1 * np.eye(d)
    e = rng.standard_normal((n, d))
    inverse = linalg.whitening_factors(cov)
    chunked = linalg.by_inverse_chunks(metrics.nees_inverse, e, cov)
    np.testing.assert_array_equal(chunked, metrics.nees_inverse(e, inverse))
    np.testing.assert_array_equal(whiten(e, cov), linalg.whitened_by(inverse, e))
    made = gls_residuals(e, None, inverse)
    np.testing.assert_array_equal(_per_epoch_scores(e, cov), made.scores)
    read = gls_residuals(e, None, inverse, cov)
    for name in ("mean", "whitened", "precision_sum", "scores"):
        np.testing.assert_array_equal(getattr(read, name), getattr(made, name))
    read.release_scores()  # made again when read again: the same numbers
    np.testing.assert_array_equal(read.scores, made.scores)


@pytest.mark.parametrize("d", [1, 2, 3, 6])
def test_whitening_factors_are_symmetric_roots_that_turn_with_the_frame(d):
    """linalg.whitening_factors: F_k symmetric with F_k Σ_k F_k = I (so the NEES is
    ‖F_k e_k‖², as with the Cholesky factor), and for an orthogonal R the factors of
    RΣ_kRᵀ are R F_k Rᵀ, so the whitened errors of Re_k are R F_k e_k: one constant turn of
    the frame, where the inverse Cholesky factors differ from epoch to epoch."""
    from scipy.stats import special_ortho_group

    from credcli.engine import linalg, metrics

    rng = np.random.default_rng(10 + d)
    a = rng.standard_normal((500, d, d))
    cov = a @ a.transpose(0, 2, 1) + 0.05 * np.eye(d)
    f = linalg.whitening_factors(cov)
    eye = np.broadcast_to(np.eye(d), cov.shape)
    np.testing.assert_allclose(f, f.transpose(0, 2, 1), rtol=0, atol=1e-9)
    np.testing.assert_allclose(f @ cov @ f, eye, rtol=0, atol=1e-8)
    e = rng.standard_normal((500, d))
    nees = metrics.nees_factored(e, np.linalg.cholesky(cov))
    np.testing.assert_allclose(metrics.nees_inverse(e, f), nees, rtol=1e-9)
    r = special_ortho_group.rvs(d, random_state=3) if d > 1 else np.array([[-1.0]])
    turned = linalg.whitening_factors(r @ cov @ r.T)
    np.testing.assert_allclose(turned, r @ f @ r.T, rtol=0, atol=1e-8)
    q = linalg.lower_inverse(np.linalg.cholesky(r @ cov @ r.T)) @ r @ np.linalg.cholesky(cov)
    np.testing.assert_allclose(q @ q.transpose(0, 2, 1), eye, rtol=0, atol=1e-8)
    if d > 1:  # L'⁻¹Re_k = Q_k L⁻¹e_k: a turn Q_k of its own at each epoch
        assert np.ptp(q, axis=0).max() > 0.05


def _ar1(rng, n: int, phi: float) -> np.ndarray:
    """Two independent AR(1) series of unit variance, (n, 2), past a burn-in of 200."""
    from scipy.signal import lfilter

    z = rng.standard_normal((n + 200, 2)) * np.sqrt(1.0 - phi * phi)
    return lfilter([1.0], [1.0, -phi], z, axis=0)[200:]


@pytest.mark.parametrize(
    "case", ["credible", "white with a bias", "memory with a bias", "memory, too small"]
)
def test_a_long_segments_route_gives_the_short_routes_diagnosis(monkeypatch, case):
    """Past one chunk of epochs gather frees the inverse factors through the model's fit
    and checks, makes them again only where a test reads them, makes the GLS scores when
    read and the NEES again by chunks (the peak memory of a 2·10⁶-epoch segment): with the
    chunk made shorter than a 3,000-epoch segment, every number of its record is that of
    the route that holds them, for a white model (labelled credible, and bias: its
    long-memory check re-makes the residuals) and an AR(1) model (bias, and optimism
    under a covariance 4× too small)."""
    from credcli.engine import linalg
    from credcli.report.records import diagnosis_record

    rng = np.random.default_rng(len(case))
    n = 3_000
    shape = np.array([[1.0, 0.2], [0.2, 1.5]])
    unit = _ar1(rng, n, 0.6) if case.startswith("memory") else rng.standard_normal((n, 2))
    errors = unit @ np.linalg.cholesky(shape).T
    if "bias" in case:
        errors += np.array([0.3, -0.2])
    scale = 0.25 if "small" in case else 1.0
    cov = np.broadcast_to(scale * shape, (n, 2, 2)).copy()
    cov[::7] *= 1.3  # per-epoch covariances: the per-epoch route
    errors[::7] *= np.sqrt(1.3)
    held = json.dumps(diagnosis_record(diagnose_errors(errors, cov, rng=3)))
    monkeypatch.setattr(linalg, "EPOCH_CHUNK", 1_000)
    freed = json.dumps(diagnosis_record(diagnose_errors(errors, cov, rng=3)))
    assert freed == held


_MAPPED_PROBE = """
import ctypes, sys
import numpy as np
from credcli.schedule import pool

class Info(ctypes.Structure):
    _fields_ = [(f, ctypes.c_size_t) for f in
                "arena ordblks smblks hblks hblkhd usmblks fsmblks uordblks fordblks keepcost".split()]

libc = ctypes.CDLL("libc.so.6")
libc.mallinfo2.restype = Info

def mapped(size):
    a = np.ones(size // 8)  # a fresh array, alive while glibc is asked where it lies
    return libc.mallinfo2().hblkhd >= size

steps = []
pool.allocator_for(False)  # a library caller's process: left as glibc has it
steps.append(mapped(16 << 20))
pool.keep_freed_memory()  # the command line's own process
steps.append(mapped(16 << 20))
pool.allocator_for(True)  # a task holding a segment longer than one chunk of epochs
steps.append(mapped(24 << 20))  # (more than the heap holds free: glibc reuses a hole first)
steps.append(mapped(4 << 20))
pool.allocator_for(False)
steps.append(mapped(32 << 20))
print(steps)
"""


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc's allocator")
def test_the_allocator_maps_a_long_segments_arrays_only_in_credclis_processes():
    """pool.allocator_for: in a process whose allocator credcli set, a task holding a
    segment longer than one chunk of epochs has a 24 MiB array mapped (given back when
    freed) and a 4 MiB one from the heap, while other tasks take 16 and 32 MiB from the
    heap (the 64 MiB threshold); in a library caller's process nothing is changed (glibc
    maps 16 MiB itself). Run in a child: the setting is process-wide."""
    import subprocess

    try:
        import ctypes

        ctypes.CDLL("libc.so.6").mallinfo2  # noqa: B018 (glibc 2.33 or later)
    except (OSError, AttributeError):
        pytest.skip("not glibc 2.33 or later")
    out = subprocess.run(
        [sys.executable, "-c", _MAPPED_PROBE], capture_output=True, text=True, check=True
    ).stdout
    assert out.strip() == "[True, False, True, False, False]"


@pytest.mark.parametrize("d", [2, 3])
def test_covariances_near_singular_for_eigh_are_whitened(d):
    """Positive definite covariances with condition numbers near 1/ε pass the Cholesky
    factorisation, yet ``eigh`` may put the smallest eigenvalue at 0 or below (it did for
    some of these 200 here): their symmetric inverse roots are then made from the Cholesky
    factor's singular values (linalg._inverse_sqrt_factored), whose F L is orthogonal,
    every factor is finite, and the segment is diagnosed (the NEES was NaN, and the
    diagnosis said the error's square overflows)."""
    from credcli.engine import linalg
    from credcli.engine.diagnosis import diagnose_errors

    rng = np.random.default_rng(0)
    drawn: list[np.ndarray] = []
    while len(drawn) < 200:
        q, _r = np.linalg.qr(rng.standard_normal((d, d)))
        lam = np.r_[1.0, rng.uniform(0.5, 2.0, d - 2), 10.0 ** rng.uniform(-19, -15)]
        c = (q * lam) @ q.T
        c = (c + c.T) / 2
        try:
            np.linalg.cholesky(c)
        except np.linalg.LinAlgError:
            continue
        drawn.append(c)
    cov = np.array(drawn)
    assert np.all(np.isfinite(linalg.whitening_factors(cov)))
    f = linalg._inverse_sqrt_factored(cov)
    m = f @ np.linalg.cholesky(cov)
    eye = np.broadcast_to(np.eye(d), cov.shape)
    np.testing.assert_allclose(m @ m.transpose(0, 2, 1), eye, rtol=0, atol=1e-6)
    scale = np.abs(f).max(axis=(1, 2))[:, None, None]
    np.testing.assert_allclose(f / scale, f.transpose(0, 2, 1) / scale, rtol=0, atol=1e-6)
    e = np.einsum("nij,nj->ni", np.linalg.cholesky(cov), rng.standard_normal((200, d)))
    assert diagnose_errors(e, cov, rng=1).label is not None


@pytest.mark.parametrize("d", [3, 6])
def test_graded_covariances_are_whitened_to_working_accuracy(d):
    """A state in mixed units has a graded covariance Σ = DRD, its standard deviations
    orders of magnitude apart. ``eigh`` of such a matrix in a random component order lost
    the small eigenvalues' accuracy (spread 10^5: NEES off by 1e-5 relatively; 10^8: by
    7.7, F Σ F by 130 from I); with the components in decreasing order of variance
    (linalg._inverse_sqrt_eigh) F stays the symmetric root to working accuracy: F Σ F = I
    and the NEES equals the Cholesky factor's, to 1e-8."""
    from credcli.engine import linalg

    rng = np.random.default_rng(7)
    for spread in (1e5, 1e8):
        a = rng.standard_normal((300, d, d + 2))
        c = a @ a.transpose(0, 2, 1)
        root = np.sqrt(np.diagonal(c, axis1=1, axis2=2))
        r = c / root[:, :, None] / root[:, None, :]
        sd = np.array([rng.permutation(spread ** -np.linspace(0, 1, d)) for _ in range(300)])
        cov = r * sd[:, :, None] * sd[:, None, :]
        f = linalg.whitening_factors(cov)
        eye = np.broadcast_to(np.eye(d), cov.shape)
        np.testing.assert_allclose(f @ cov @ f, eye, rtol=0, atol=1e-8)
        scale = np.abs(f).max(axis=(1, 2))[:, None, None]
        np.testing.assert_allclose(f / scale, f.transpose(0, 2, 1) / scale, rtol=0, atol=1e-12)
        e = np.einsum("nij,nj->ni", np.linalg.cholesky(cov), rng.standard_normal((300, d)))
        chol = np.linalg.solve(np.linalg.cholesky(cov), e[:, :, None])[:, :, 0]
        white = np.einsum("nij,nj->ni", f, e)
        np.testing.assert_allclose(np.sum(white**2, 1), np.sum(chol**2, 1), rtol=1e-8)


def test_the_mean_spread_of_a_graded_precision_is_the_unit_free_one():
    """λ_max of S^{-1/2} Cov(G) S^{-1/2} does not depend on the components' units, but
    eigh of a graded S (standard deviations 10^8 apart, d = 6) lost it: 62 % off the same
    problem in one unit. With S and Cov(G) scaled by powers of two near 1/√S_ii it agrees to
    1e-9."""
    from credcli.engine.batches import mean_spread

    rng = np.random.default_rng(3)
    for _ in range(20):
        a, b = rng.standard_normal((6, 8)), rng.standard_normal((6, 9))
        precision, cov_sum = a @ a.T, b @ b.T
        sd = rng.permutation(10.0 ** -np.linspace(0, 8, 6))
        w = np.outer(1.0 / sd, 1.0 / sd)  # the scores' and precisions' units
        want = mean_spread(cov_sum, precision, 1.0, 100)
        got = mean_spread(cov_sum * w, precision * w, 1.0, 100)
        assert got == pytest.approx(want, rel=1e-9)
