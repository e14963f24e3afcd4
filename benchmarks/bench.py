"""`make bench`: measured wall time and peak memory of credcli's main jobs.

Each job runs the real command line in a fresh subprocess (start-up included), a few
times; the best and median wall times and the peak resident memory are printed. These
are measurements, not tests: shared machines are noisy.
"""

from __future__ import annotations

import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]  # the repository
SHARED = ROOT.parent / "shared" / "data" / "starloc"


def _run(args: list[str], repeat: int) -> tuple[list[float], float]:
    """Wall times (s) of `credcli args` and the peak RSS (MiB) of the slowest child."""
    times, peak = [], 0.0
    for _ in range(repeat):
        start = time.perf_counter()
        pid = os.fork()
        if pid == 0:  # child: exec the CLI with output discarded
            devnull = os.open(os.devnull, os.O_WRONLY)
            os.dup2(devnull, 1)
            os.dup2(devnull, 2)
            os.execv(sys.executable, [sys.executable, "-m", "credcli", *args])
        _, status, usage = os.wait4(pid, 0)
        times.append(time.perf_counter() - start)
        if os.waitstatus_to_exitcode(status) not in (0, 1):
            raise SystemExit(f"bench: credcli {' '.join(args)} failed")
        peak = max(peak, usage.ru_maxrss / 1024)
    return times, peak


def big_log(path: Path, segments: int = 100, per_segment: int = 1000, seed: int = 0) -> Path:
    """A d = 2 log of segments × per_segment epochs with mixed planted conditions."""
    import pandas as pd

    from credcli.studies.samples import GOOD_SEGMENTS, estimator_log

    plan = [GOOD_SEGMENTS[k % len(GOOD_SEGMENTS)] for k in range(segments)]
    plan = [type(p)(f"{p.name}-{k:03d}", p.rho, p.bias) for k, p in enumerate(plan)]
    frame = estimator_log(plan, epochs_per_segment=per_segment, seed=seed)
    assert isinstance(frame, pd.DataFrame)
    frame.to_csv(path, index=False)
    return path


def _report(name: str, times: list[float], peak: float, target: str = "") -> None:
    line = (
        f"{name:<58} best {min(times):6.2f} s   median {statistics.median(times):6.2f} s"
        f"   peak RSS {peak:7.1f} MiB"
    )
    print(line + (f"   (target {target})" if target else ""), flush=True)


def main() -> int:
    print(
        f"credcli bench on {os.cpu_count()} CPU(s), Python {sys.version.split()[0]}, "
        f"numpy {np.__version__}"
    )
    with tempfile.TemporaryDirectory() as tmp:
        log = big_log(Path(tmp) / "big.csv")
        times, peak = _run(["diagnose", str(log), "-f", "json"], 3)
        _report("diagnose: 100,000 epochs, 100 segments, B = 1000", times, peak)
        times, peak = _run(["diagnose", str(log), "-f", "json", "--metrics", "all"], 1)
        _report("diagnose --metrics all: same log", times, peak)
        base = Path(tmp) / "baseline.json"
        subprocess.run(
            [sys.executable, "-m", "credcli", "baseline", str(log), "-o", str(base)],
            check=True,
            capture_output=True,
        )
        times, peak = _run(["gate", str(log), "--baseline", str(base)], 3)
        _report("gate: same log against its baseline", times, peak)
    times, peak = _run(["diagnose", str(ROOT / "sample_data" / "estimator_log.csv")], 3)
    _report("diagnose: sample log (1,800 epochs, 6 segments)", times, peak)
    real = SHARED / "loop-2d-fast_s2_uwb.csv"
    if real.exists():
        times, peak = _run(["uwb", str(real), "--window", "5s", "-f", "json"], 5)
        _report("uwb: real loop-2d-fast_s2 (7,725 ranges), --window 5s", times, peak, "<= 2 s")
    else:
        print(f"uwb: skipped, {real} not found (../shared absent)")
    times, peak = _run(["uwb", str(ROOT / "sample_data" / "starloc_grid_uwb.csv"), "-f", "json"], 3)
    _report("uwb: sample grid (12,320 ranges, 6 static periods)", times, peak)
    times, peak = _run(["simulate", "-f", "json"], 5)
    _report("simulate: paper protocol (6 x 50 trials, N=100, B=1000)", times, peak, "<= 2 s")
    for jobs in (1, 2):
        times, peak = _run(["simulate", "--trials", "500", "-f", "json", "--jobs", str(jobs)], 2)
        _report(f"simulate --trials 500 (3,000 trials) --jobs {jobs}", times, peak)
    return 0


if __name__ == "__main__":
    sys.exit(main())
