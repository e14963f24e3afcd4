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
    """Wall times (s) of `credcli args` and the peak RSS (MiB) of the largest child.

    Children are started by subprocess (vfork/posix_spawn), not os.fork: a forked child's
    peak RSS would include this process's own memory before the exec."""
    times, peak = [], 0.0
    for _ in range(repeat):
        start = time.perf_counter()
        proc = subprocess.Popen(
            [sys.executable, "-m", "credcli", *args],
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        )
        _, status, usage = os.wait4(proc.pid, 0)
        proc.returncode = os.waitstatus_to_exitcode(status)
        times.append(time.perf_counter() - start)
        if proc.returncode not in (0, 1):
            raise SystemExit(f"bench: credcli {' '.join(args)} failed")
        peak = max(peak, usage.ru_maxrss / 1024)
    return times, peak


def big_log(path, segments: int = 100, per_segment: int = 1000, seed: int = 0) -> Path:
    """A d = 2 log of segments × per_segment epochs with mixed planted conditions."""
    import pandas as pd

    from credcli.studies.samples import GOOD_SEGMENTS, estimator_log

    plan = [GOOD_SEGMENTS[k % len(GOOD_SEGMENTS)] for k in range(segments)]
    plan = [type(p)(f"{p.name}-{k:03d}", p.rho, p.bias) for k, p in enumerate(plan)]
    frame = estimator_log(plan, epochs_per_segment=per_segment, seed=seed)
    assert isinstance(frame, pd.DataFrame)
    frame.to_csv(path, index=False)
    return Path(path)


ROWS: list[tuple[str, str, str, str]] = []


def _report(name: str, times: list[float], peak: float, target: str = "") -> None:
    wall = f"{min(times):.2f} s" + (
        f" (median {statistics.median(times):.2f})" if len(times) > 1 else ""
    )
    ROWS.append((name, wall, f"{peak:.0f} MiB" if peak else "—", target))
    print(f"{name:<62} {wall:<22} {ROWS[-1][2]:>9}   {target}", flush=True)


def _parquet_log(path, segments: int, per_segment: int) -> Path:
    import pandas as pd

    path = Path(path)
    csv = big_log(path.with_suffix(".csv"), segments, per_segment)
    pd.read_csv(csv).to_parquet(path)
    csv.unlink()
    return path


def _one_segment(path, n: int = 2_000_000) -> Path:
    import pandas as pd

    path = Path(path)
    rng = np.random.default_rng(0)
    e = rng.standard_normal((n, 2))
    frame = pd.DataFrame({"time": np.arange(n) * 0.01, "truth_0": e[:, 0], "truth_1": e[:, 1]})
    frame = frame.assign(est_0=0.0, est_1=0.0, cov_0_0=1.0, cov_0_1=0.0, cov_1_1=1.0)
    frame.to_parquet(path)
    return path


def _pose_hour(directory) -> str:
    """A 1-hour TUM truth at 200 Hz and an OpenVINS estimate at 20 Hz (72,000 epochs)."""
    from credcli.studies import pose_samples as ps

    directory = Path(directory)
    t_true = np.arange(3600 * 200) / 200.0
    p, r = ps.trajectory(t_true)
    truth = directory / "truth_1h.txt"
    np.savetxt(truth, np.c_[ps.EPOCH + t_true, p, r.as_quat()], fmt="%.6f")
    t_est = 0.013 + np.arange(3599 * 20) / 20.0
    p_est, r_est, claimed = ps.planted_estimate(t_est, ps.true_cov(), seed=1)
    iu = np.triu_indices(3)
    blocks = [claimed[:, 3:, 3:][:, iu[0], iu[1]], claimed[:, :3, :3][:, iu[0], iu[1]]]
    est = directory / "estimate_1h.txt"
    np.savetxt(
        est, np.column_stack([ps.EPOCH + t_est, p_est, r_est.as_quat(), *blocks]), fmt="%.9f"
    )
    return f"{est} {truth}"


def _big_bag(path, megabytes: float = 100.0) -> str:
    """A ROS1 bag of about ``megabytes`` MB of Odometry (20 Hz) and PoseStamped truth."""
    from credcli.studies import pose_samples as ps

    seconds = megabytes * 1e6 / (20 * 760 + 50 * 130)  # bytes per second of bag
    truth, estimate = ps.bag_messages(duration=seconds)
    ps.write_bag(Path(path), 1, estimate, truth)
    return str(path)


def _bag_rate(path: str) -> str:
    """MB/s of reading both topics of the bag in one pass, as `diagnose --topic
    --truth-topic` does (file size over wall time), best of 3."""
    from credcli.io.rosbag import read_bag_topics

    size = Path(path).stat().st_size
    requests = [("/odom", "estimate"), ("/ground_truth", "truth")]
    best = min(_timed(lambda: read_bag_topics(Path(path), requests, "auto")) for _ in range(3))
    return f"{size / 1e6:.0f} {size / 1e6 / best:.1f}"


def _dask_overhead(tasks: int = 2000) -> str:
    """Seconds per trivial task on local:1 and local:2 (the cluster's own cost per task)."""
    from credcli.schedule.cluster import DaskRunner

    out = []
    for workers in (1, 2):
        with DaskRunner(f"local:{workers}") as runner:
            runner.map(abs, list(range(50)))  # warm up
            out.append(_timed(lambda r=runner: r.map(abs, list(range(tasks)))) / tasks)
    return " ".join(f"{x:.6f}" for x in out)


def _dask_rows(tmp: Path) -> None:
    """Issue 13: 8 logs of 1,000,000 epochs on local:2, --jobs 2 and --jobs 1; a sweep of
    20 points; the cost per task."""
    import shutil

    first = Path(_in_child(f"_parquet_log({str(tmp / 'fleet0.parquet')!r}, 1000, 1000)"))
    fleet = [first] + [tmp / f"fleet{k}.parquet" for k in range(1, 8)]
    for path in fleet[1:]:
        shutil.copyfile(first, path)
    logs = [str(p) for p in fleet]
    outputs = {}
    for name, extra in (
        ("--scheduler local:2", ["--scheduler", "local:2"]),
        ("--scheduler local:1", ["--scheduler", "local:1"]),
        ("--jobs 2", ["--jobs", "2"]),
        ("--jobs 1", ["--jobs", "1"]),
    ):
        out = tmp / f"fleet_{len(outputs)}.json"
        times, peak = _run(["diagnose", *logs, "-f", "json", "-o", str(out), *extra], 1)
        outputs[name] = out.read_bytes()
        _report(f"diagnose 8 logs x 1,000,000 epochs, {name}", times, peak)
    same = len(set(outputs.values())) == 1
    print(f"  outputs of the four runs byte-identical: {'yes' if same else 'NO'}")
    values = ",".join(f"{v:.2f}" for v in np.linspace(0.0, 0.95, 20))
    sweep = ["simulate", "--scenario", "credible", "--trials", "500", "--sweep", f"ar={values}"]
    for name, extra in (
        ("--scheduler local:2", ["--scheduler", "local:2"]),
        ("--jobs 2", ["--jobs", "2"]),
        ("--jobs 1", ["--jobs", "1"]),
    ):
        times, peak = _run([*sweep, "-f", "json", *extra], 1)
        _report(f"simulate: sweep of 20 points x 500 trials, {name}", times, peak)
    one, two = (float(x) for x in _in_child("_dask_overhead()").split())
    ROWS.append(
        (
            "Dask cost per trivial task, local:1 / local:2",
            f"{1e3 * one:.2f} / {1e3 * two:.2f} ms",
            "—",
            "",
        )
    )
    print(f"{ROWS[-1][0]:<62} {ROWS[-1][1]:<22}", flush=True)


def _in_child(call: str) -> str:
    """Run ``bench.<call>`` in a fresh Python and return what it prints: this process must
    stay small, since a child's peak RSS on Linux includes its parent's at the exec."""
    code = f"import sys; sys.path.insert(0, {str(Path(__file__).parent)!r}); import bench; print(bench.{call})"
    return subprocess.run(
        [sys.executable, "-c", code], check=True, capture_output=True, text=True
    ).stdout.strip()


def _labels(path: Path) -> list[str]:
    import json

    return [s["label"] for s in json.loads(path.read_text())["segments"]]


def _energy_score_rate(d: int, n: int) -> float:
    from credcli.engine.metrics import energy_score

    rng = np.random.default_rng(0)
    e = rng.standard_normal((n, d))
    a = rng.standard_normal((n, d, d))
    cov = a @ np.swapaxes(a, 1, 2) + 0.1 * np.eye(d)
    energy_score(e[:1000], cov[:1000])
    best = min(_timed(lambda: energy_score(e, cov)) for _ in range(3))
    return n / best


def _timed(func) -> float:
    start = time.perf_counter()
    func()
    return time.perf_counter() - start


def _under_load(args: list[str], repeat: int, envs: list[dict | None]) -> list[list[float]]:
    """Wall times of `credcli args` under each environment of ``envs`` (None: this one),
    while two busy processes hold both cores; the environments take turns, in an order
    reversed every other round (ABBA), so that both lists see the same moments of a
    machine whose speed drifts and neither always runs first."""
    hogs = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(2)]
    try:
        times: list[list[float]] = [[] for _ in envs]
        for round_ in range(repeat):
            order = list(enumerate(envs))
            for k, env in order if round_ % 2 == 0 else order[::-1]:
                start = time.perf_counter()
                subprocess.run(
                    [sys.executable, "-m", "credcli", *args],
                    check=True,
                    capture_output=True,
                    env=None if env is None else os.environ | env,
                )
                times[k].append(time.perf_counter() - start)
        return times
    finally:
        for hog in hogs:
            hog.kill()


def _compile_bytecode() -> None:
    """Write credcli's bytecode before timing anything, as ``pip install`` does for an
    installed package. Where PYTHONDONTWRITEBYTECODE is set (this machine sets it), an
    editable checkout would otherwise compile its 31 imported modules again in every
    run: 0.1–0.2 s more per command, which is not what a user's install pays."""
    import compileall

    compileall.compile_dir(ROOT / "credcli", quiet=1)


def _one_epoch_segments(path, n: int = 1_000_000) -> Path:
    """A log of ``n`` one-epoch segments (issue 21: per-segment set-up is the cost)."""
    import pandas as pd

    path = Path(path)
    e = np.random.default_rng(0).standard_normal((n, 2))
    frame = pd.DataFrame({"time": np.arange(n) * 0.1, "segment": np.arange(n).astype(str)})
    frame = frame.assign(truth_0=e[:, 0], truth_1=e[:, 1], est_0=0.0, est_1=0.0)
    frame.assign(cov_0_0=1.0, cov_0_1=0.0, cov_1_1=1.0).to_parquet(path)
    return path


def main() -> int:
    _compile_bytecode()
    if sys.argv[1:] == ["dask"]:  # make bench-dask: the issue 13 rows only
        with tempfile.TemporaryDirectory() as tmp:
            _dask_rows(Path(tmp))
        return 0
    print(
        f"credcli bench on {os.cpu_count()} CPU(s), Python {sys.version.split()[0]}, "
        f"numpy {np.__version__}"
    )
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        million = Path(_in_child(f"_parquet_log({str(tmp / 'million.parquet')!r}, 1000, 1000)"))
        out = tmp / "million.json"
        times, peak = _run(["diagnose", str(million), "-f", "json", "-o", str(out)], 3)
        _report(
            "diagnose: 1,000,000 epochs, 1,000 segments (Parquet)", times, peak, "<= 10 s, <= 1 GB"
        )
        exact = tmp / "exact.json"
        times, peak = _run(
            ["diagnose", str(million), "-f", "json", "-o", str(exact), "--exact-pvalue"], 1
        )
        same = _labels(out) == _labels(exact)
        _report(
            f"  same with --exact-pvalue (all B): labels identical: {'yes' if same else 'NO'}",
            times,
            peak,
            "every label identical",
        )
        tiny = Path(_in_child(f"_one_epoch_segments({str(tmp / 'tiny.parquet')!r})"))
        times, peak = _run(["diagnose", str(tiny)], 1)
        _report("diagnose: 1,000,000 one-epoch segments (table)", times, peak, "about 1 min")
        tiny.unlink()
        one = Path(_in_child(f"_one_segment({str(tmp / 'one.parquet')!r})"))
        times, peak = _run(["diagnose", str(one), "-f", "json"], 1)
        _report("diagnose: one segment of 2,000,000 epochs", times, peak, "<= 600 MB")
        log = Path(_in_child(f"big_log({str(tmp / 'big.csv')!r})"))
        times, peak = _run(["diagnose", str(log), "-f", "json"], 3)
        _report(
            "diagnose: 100,000 epochs, 100 segments (CSV)", times, peak, "<= 4.9 s (0.1 + 20 %)"
        )
        times, peak = _run(["diagnose", str(log), "-f", "json", "--metrics", "all"], 1)
        _report("diagnose --metrics all: same log", times, peak)
        base = tmp / "baseline.json"
        subprocess.run(
            [sys.executable, "-m", "credcli", "baseline", str(log), "-o", str(base)],
            check=True,
            capture_output=True,
        )
        times, peak = _run(["gate", str(log), "--baseline", str(base)], 3)
        _report("gate: same log against its baseline", times, peak)
        est, truth = _in_child(f"_pose_hour({str(tmp)!r})").split()
        times, peak = _run(
            [
                "diagnose",
                est,
                "--truth",
                truth,
                "--window",
                "60s",
                "--states",
                "pose",
                "-f",
                "json",
            ],
            3,
        )
        _report(
            "diagnose --truth: 1 h, 200 Hz TUM truth, 20 Hz estimate, 60 s windows",
            times,
            peak,
            "<= 3 s",
        )
        bag = _in_child(f"_big_bag({str(tmp / 'big.bag')!r})")
        size, rate = _in_child(f"_bag_rate({bag!r})").split()
        ROWS.append(
            (
                f"read a {size} MB ROS1 bag (Odometry + PoseStamped)",
                f"{rate} MB/s",
                "—",
                ">= 50 MB/s",
            )
        )
        print(f"{ROWS[-1][0]:<62} {ROWS[-1][1]:<22} {'—':>9}   {ROWS[-1][3]}", flush=True)
    times, peak = _run(["diagnose", str(ROOT / "sample_data" / "estimator_log.csv")], 3)
    _report("diagnose: sample log (1,800 epochs, 6 segments)", times, peak)
    for d, target in ((2, 1e6), (6, 3e5)):
        rate = float(_in_child(f"_energy_score_rate({d}, {400_000 if d == 2 else 100_000})"))
        ROWS.append(
            (
                f"energy score, d = {d} (metrics.energy_score)",
                f"{rate / 1e6:.2f} M epochs/s",
                "—",
                f">= {target / 1e6:g} M/s",
            )
        )
        print(f"{ROWS[-1][0]:<62} {ROWS[-1][1]:<22} {'—':>9}   {ROWS[-1][3]}", flush=True)
    for args in (["--help"], ["--version"]):
        times, peak = _run(args, 5)
        _report(f"credcli {args[0]}", times, peak, "<= 0.3 s")
    real = SHARED / "loop-2d-fast_s2_uwb.csv"
    if real.exists():
        times, peak = _run(["uwb", str(real), "--window", "5s", "-f", "json"], 5)
        _report("uwb: real loop-2d-fast_s2 (7,725 ranges), --window 5s", times, peak, "<= 2 s")
    else:
        print(f"uwb: skipped, {real} not found (../shared absent)")
    times, peak = _run(["uwb", str(ROOT / "sample_data" / "starloc_grid_uwb.csv"), "-f", "json"], 3)
    _report("uwb: sample grid (12,320 ranges, 6 static periods)", times, peak)
    times, peak = _run(["simulate", "-f", "json"], 5)
    _report("simulate: paper protocol (authors' code: about 100 s)", times, peak, "<= 1.0 s")
    loaded, pinned = _under_load(
        ["simulate", "-f", "json"], 5, [None, {"OPENBLAS_NUM_THREADS": "1"}]
    )
    _report("  same, both cores busy", loaded, 0.0, "no slower than the next line")
    _report("  same, both cores busy, OPENBLAS_NUM_THREADS=1", pinned, 0.0)
    for jobs in (1, 2):
        times, peak = _run(["simulate", "--trials", "500", "-f", "json", "--jobs", str(jobs)], 2)
        _report(f"simulate --trials 500 (3,000 trials) --jobs {jobs}", times, peak)
    with tempfile.TemporaryDirectory() as tmp:
        _dask_rows(Path(tmp))
    print("\n| workload | wall | peak RSS | target |\n|---|---|---|---|")
    for row in ROWS:
        print("| " + " | ".join(row) + " |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
