"""The fast paths decide exactly as the slow ones: early-stopped sign flips against all B,
any number of processes against one, the blocked pair matrix against the direct formula."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from credcli.engine import elt
from credcli.engine.diagnosis import DiagnosisConfig, diagnose_errors
from credcli.engine.elt import whiten, whitened_location_test

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
    exact = diagnose_errors(e, cov, DiagnosisConfig(exact_pvalue=True), rng=1)
    fast = diagnose_errors(e, cov, rng=1)
    assert exact.elt.flips_used == 1000 and exact.label is fast.label
    p = elt.location_test(e, cov, 1000, rng=1).pvalue  # B flips of the same stream
    assert exact.elt.pvalue == p


@pytest.mark.parametrize("n", [3, 64, 97, 500])
def test_blocked_pair_matrix_equals_the_direct_formula(n):
    s = np.random.default_rng(n).standard_normal((n, 3)) * 7.0
    direct = np.array([[np.linalg.norm(a + b) - np.linalg.norm(a - b) for b in s] for a in s])
    np.fill_diagonal(direct, 0.0)
    a = elt.pair_matrix(s)
    np.testing.assert_allclose(a, direct, rtol=1e-12, atol=1e-12)
    assert np.array_equal(a, a.T)


def test_jobs_do_not_change_the_output(tmp_path):
    from credcli.cli import main

    frame = pd.concat([pd.read_csv(ROOT / "sample_data" / "estimator_log.csv")] * 30)
    frame["segment"] = frame["segment"] + "-" + (np.arange(len(frame)) // 1800).astype(str)
    path = tmp_path / "big.csv"
    frame.to_csv(path, index=False)  # 54,000 epochs in 180 segments: parallel from 50,000
    outs = []
    for jobs in ("1", "2"):
        out = tmp_path / f"j{jobs}.json"
        assert main(["diagnose", str(path), "-f", "json", "--jobs", jobs, "-o", str(out)]) == 0
        outs.append(out.read_bytes())
    assert outs[0] == outs[1]
    assert len(json.loads(outs[0])["segments"]) == 180
