"""`make bench`, part 3: the calibrated rule on filter-like logs (issue 22). Measurements
with their binomial standard errors, not tests.

- an EKF (credcli.studies.filters.ekf_runs: range and bearing, slow dynamics, correlation
  times of seconds) tuned right, with Q/R/P0 4× too small or too large, or an unmodelled
  range bias, exported at 100 Hz and 10 Hz: labels, and how often the κ interval covers 1
  where the tuning is right;
- AR(1) errors with φ = 0.99 (100-epoch correlation time) at two rates: coverage and false
  alarms;
- claimed covariances that rotate and are 20× anisotropic, with and without a constant 1σ
  bias: how often smm is found, by the GLS mean test and by the ELT;
- short windows (120 epochs) of AR(1) φ = 0.95 errors with the covariance 9× too large:
  complete, partial and no verdicts;
- anisotropic mismatch: whitened variances (1, 0.25) and (4, 0.25).
"""

from __future__ import annotations

import math
import sys
import time
from collections import Counter

import numpy as np

from credcli.engine.diagnosis import Label, diagnose_errors
from credcli.studies.filters import TUNINGS, ar1_errors, ekf_runs, rotating_bias_log


def _shown(d) -> str:
    return d.label.value + (
        f" ({'+'.join(q.value for q in d.untested)} untested)" if d.untested else ""
    )


def _se(p: float, n: int) -> float:
    return 100 * math.sqrt(max(p * (1 - p), 1e-12) / n)


def ekf_table(runs: int = 20) -> None:
    print(f"EKF (range + bearing, 60 s), {runs} runs per case; labels at each export rate:")
    print(f"{'case':<11}{'rate':>6}  {'labels':<60}{'κ covers 1':>11}")
    for name, tuning in TUNINGS.items():
        sim = ekf_runs(runs=runs, tuning=tuning, seed=2026)
        for every, rate in ((1, "100 Hz"), (10, "10 Hz")):
            r = sim.thinned(every)
            diags = [diagnose_errors(r.errors[m], r.cov[m], rng=m) for m in range(runs)]
            labels = Counter(_shown(d) for d in diags)
            covers = sum(d.scale.scale_factor_low <= 1 <= d.scale.scale_factor_high for d in diags)
            text = ", ".join(f"{k} {v}" for k, v in labels.most_common())
            print(f"{name:<11}{rate:>6}  {text:<60}{covers:>6}/{runs}")


def long_memory_table(segments: int = 200) -> None:
    rng = np.random.default_rng(7)
    fast = [ar1_errors(6000, 2, 0.99, rng) for _ in range(segments)]
    print(f"\nAR(1) φ = 0.99, correct covariance, {segments} segments of 60 s:")
    print(
        f"{'rate':<8}{'N':>6}{'κ covers 1':>12}{'± s.e.':>8}{'not credible':>14}{'± s.e.':>8}{'partial':>9}{'none':>6}"
    )
    for every, rate in ((1, "100 Hz"), (10, "10 Hz")):
        diags = [
            diagnose_errors(e[::every], np.broadcast_to(np.eye(2), (len(e[::every]), 2, 2)), rng=k)
            for k, e in enumerate(fast)
        ]
        cover = np.mean([d.scale.scale_factor_low <= 1 <= d.scale.scale_factor_high for d in diags])
        bad = np.mean([d.label not in (Label.CREDIBLE, Label.INSUFFICIENT) for d in diags])
        partial = sum(d.partial for d in diags)
        none = sum(d.label is Label.INSUFFICIENT for d in diags)
        print(
            f"{rate:<8}{6000 // every:>6}{100 * cover:>11.1f}%{_se(cover, segments):>8.1f}{100 * bad:>13.1f}%{_se(bad, segments):>8.1f}{partial:>9}{none:>6}"
        )


def rotating_table(segments: int = 100) -> None:
    print(f"\nRotating 20× anisotropic covariance, N = 2000, {segments} segments:")
    for bias in (0.0, 1.0):
        diags = [
            diagnose_errors(*rotating_bias_log(2000, bias, seed=s), rng=s) for s in range(segments)
        ]
        smm = sum(d.label.location is not None for d in diags)
        mean = sum(
            d.mean_test is not None and d.mean_test.pvalue < d.config.mean_level for d in diags
        )
        elt = sum(d.elt is not None and d.elt.pvalue < d.config.elt_level for d in diags)
        print(f"  bias {bias:g}σ: smm {smm}/{segments} (GLS mean test {mean}, ELT {elt})")


def short_windows_table(segments: int = 200) -> None:
    rng = np.random.default_rng(8)
    diags = [
        diagnose_errors(
            ar1_errors(120, 2, 0.95, rng) / 3.0, np.broadcast_to(np.eye(2), (120, 2, 2)), rng=k
        )
        for k in range(segments)
    ]
    labels = Counter(_shown(d) for d in diags)
    print(
        f"\nShort windows: 120 epochs of AR(1) φ = 0.95, covariance 9× too large, {segments} windows:"
    )
    print("  " + ", ".join(f"{k} {v}" for k, v in labels.most_common()))


def anisotropic_table(segments: int = 200) -> None:
    print(f"\nAnisotropic mismatch (whitened variances per axis), N = 300, {segments} segments:")
    rng = np.random.default_rng(9)
    for variances in ((1.0, 0.25), (4.0, 0.25), (0.25, 0.25)):
        diags = [
            diagnose_errors(
                rng.standard_normal((300, 2)) * np.sqrt(variances),
                np.broadcast_to(np.eye(2), (300, 2, 2)),
                rng=k,
            )
            for k in range(segments)
        ]
        labels = Counter(_shown(d) for d in diags)
        print(f"  {variances}: " + ", ".join(f"{k} {v}" for k, v in labels.most_common()))


def main() -> int:
    start = time.perf_counter()
    ekf_table()
    long_memory_table()
    rotating_table()
    short_windows_table()
    anisotropic_table()
    print(f"\n({time.perf_counter() - start:.0f} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
