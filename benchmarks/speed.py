"""Issue 35's speed targets in plain-pass units: each workload timed side by side with the
least work the method needs, in one run, interleaved.

    python benchmarks/speed.py [--rounds R] [--only NAME,...]

The plain pass (:func:`plain_pass`) reads the same Parquet log, forms the errors, factors
every claimed covariance (Cholesky), whitens and sums the NEES per segment: what a
hand-written NEES loop over the log costs, with nothing of the rule. It runs in its own
subprocess with compiled bytecode, as credcli does (an installed package is compiled);
credcli runs as ``python -m credcli diagnose LOG -f json -o OUT``. Rounds alternate
plain, credcli, plain, credcli, … so that a machine whose speed drifts (shared machines
vary 2–3× within minutes) drifts for both. Each row prints the median wall and CPU (user +
system of the child) of both, their ratios ("units"), credcli's peak RSS, and the target.
Measurements, not tests.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(Path(__file__).parent))

import bench  # noqa: E402  (log builders, bytecode)


def plain_pass(path: str) -> None:
    """Read the log, whiten the errors by the Cholesky factors of their covariances and
    sum the NEES per segment (one vectorised pass; the reference unit)."""
    import pyarrow.parquet as pq

    table = pq.read_table(path)
    names = table.column_names
    d = sum(1 for c in names if c.startswith("truth_"))
    truth = np.column_stack([table.column(f"truth_{i}").to_numpy() for i in range(d)])
    est = np.column_stack([table.column(f"est_{i}").to_numpy() for i in range(d)])
    e = truth - est
    cov = np.empty((e.shape[0], d, d))
    for i in range(d):
        for j in range(i, d):
            cov[:, i, j] = cov[:, j, i] = table.column(f"cov_{i}_{j}").to_numpy()
    chol = np.linalg.cholesky(cov)
    z = np.linalg.solve(chol, e[..., None])[..., 0]
    nees = np.einsum("ni,ni->n", z, z)
    if "segment" in names:
        codes = table.column("segment").to_pandas().factorize()[0]
        sums = np.bincount(codes, weights=nees)
    else:
        sums = np.array([nees.sum()])
    print(f"{sums.size} segments, mean NEES {float(sums.sum()) / e.shape[0]:.4f}")


def _child(argv: list[str]) -> tuple[float, float, float]:
    """(wall s, CPU s, peak RSS MiB) of one subprocess."""
    start = time.perf_counter()
    proc = subprocess.Popen(argv, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - start
    err = proc.stderr.read().decode(errors="replace") if proc.stderr else ""
    if os.waitstatus_to_exitcode(status) not in (0, 1):
        raise SystemExit(f"speed: {' '.join(argv)} failed: {err.strip()[-300:]}")
    return wall, usage.ru_utime + usage.ru_stime, usage.ru_maxrss / 1024


def diagnose_argv(log: str, out: str, options: tuple[str, ...] = ()) -> list[str]:
    """The measured command line: ``credcli diagnose LOG -f json -o OUT [OPTIONS]`` in a
    child."""
    return [sys.executable, "-m", "credcli", "diagnose", log, "-f", "json", "-o", out, *options]


def medians(runs: dict[str, list[tuple[float, float, float]]]) -> dict:
    """Per name: the median wall and CPU seconds of its runs (:func:`_child`) and their
    largest peak RSS (MiB)."""
    return {
        k: (
            statistics.median(r[0] for r in v),
            statistics.median(r[1] for r in v),
            max(r[2] for r in v),
        )
        for k, v in runs.items()
    }


def _log(path, errors: np.ndarray, step: float, cov: np.ndarray, segment=None) -> Path:
    """Write ``errors`` (N, d) as a Parquet log: the time every ``step`` s, the segment
    column where given, truth = errors, estimate 0 and the one claimed covariance ``cov``
    at every epoch."""
    import pandas as pd

    n, d = errors.shape
    columns = {"time": np.arange(n) * step}
    if segment is not None:
        columns["segment"] = segment
    columns |= {f"truth_{i}": errors[:, i] for i in range(d)}
    columns |= {f"est_{i}": np.zeros(n) for i in range(d)}
    columns |= {f"cov_{i}_{j}": np.full(n, cov[i, j]) for i in range(d) for j in range(i, d)}
    pd.DataFrame(columns).to_parquet(path)
    return Path(path)


def _ten_epoch_segments(path, segments: int = 100_000) -> Path:
    """``segments`` segments of 10 epochs, d = 2, credible (issue 35: per-segment cost)."""
    n = segments * 10
    e = np.random.default_rng(1).standard_normal((n, 2))
    return _log(path, e, 0.1, np.eye(2), segment=np.arange(n) // 10)


def _wide(path, d: int, n: int = 100_000, segments: int = 10) -> Path:
    """``n`` credible epochs of dimension ``d`` in ``segments`` segments, identity-scaled
    covariances with a fixed random shape (issue 35: the cost's growth with d)."""
    rng = np.random.default_rng(d)
    a = rng.standard_normal((d, d))
    shape = a @ a.T / d + np.eye(d)
    e = rng.standard_normal((n, d)) @ np.linalg.cholesky(shape).T
    return _log(path, e, 0.01, shape, segment=np.arange(n) * segments // n)


def _slow_errors(path, n: int, d: int, phi: float = 0.99999) -> Path:
    """``n`` epochs of d independent AR(1) directions with a root near 1 (φ = 0.99999, a
    slowly drifting error), scaled to the claimed identity: a burn-in for the bootstrap's
    series would be MAX_BURN_IN epochs for every one (memory.stationary_draws, which
    starts such a model's series from its stationary law since session 39)."""
    from credcli.engine.memory import ar_filter

    burn = 20_000  # the drift's start forgotten, as in a run already under way
    e = ar_filter(np.array([phi]), np.random.default_rng(d).standard_normal((burn + n, d)))[burn:]
    return _log(path, e / e.std(axis=0), 0.1, np.eye(d))


def _arma_segment(path, n: int = 2_000_000) -> Path:
    """One segment of ``n`` epochs, d = 2, of ARMA(1, 1) errors (φ 0.98, θ −0.93: nearly
    cancelling roots, a slow part under fast noise, whose AR sieve takes an order near 50)
    scaled to the claimed identity: the 2M row's segment with the memory of a filter's
    errors."""
    import zoo

    e = zoo.arma((0.98,), (-0.93,), n, 2, np.random.default_rng(12))
    return _log(path, e / e.std(axis=0), 0.01, np.eye(2))


@dataclass(frozen=True)
class Workload:
    name: str
    build: str  # a call of this module or bench's, run in a child, returning the path
    target: str
    options: tuple[str, ...] = ()  # more of diagnose's options


WORKLOADS = (
    Workload(
        "1M epochs, 1,000 segments, d = 2",
        "bench._parquet_log({tmp!r} + '/million.parquet', 1000, 1000)",
        "<= 8 units wall, <= 12 CPU",
    ),
    Workload(
        "one 2M-epoch segment, d = 2",
        "bench._one_segment({tmp!r} + '/one.parquet')",
        "<= 3 units, <= 500 MB",
    ),
    Workload(
        "100,000 ten-epoch segments, d = 2",
        "speed._ten_epoch_segments({tmp!r} + '/ten.parquet')",
        "<= 30 s CPU, <= 1 GB",
    ),
    Workload(
        "10^6 one-epoch segments, d = 2",
        "bench._one_epoch_segments({tmp!r} + '/tiny.parquet')",
        "well under 60 s wall (JSON <= 20-30 s), < 2 GB",
    ),
    Workload("100,000 epochs, d = 3", "speed._wide({tmp!r} + '/d3.parquet', 3)", "d growth"),
    Workload("100,000 epochs, d = 15", "speed._wide({tmp!r} + '/d15.parquet', 15)", "d^1.5"),
    Workload(
        "one 2M-epoch segment of ARMA(1, 1) errors, d = 2",
        "speed._arma_segment({tmp!r} + '/arma.parquet')",
        "<= 500 MB as the 2M row (not issue 35's log)",
    ),
    Workload(
        "slow errors: 100-epoch windows of a 36,000-epoch run, d = 2",
        "speed._slow_errors({tmp!r} + '/slow2.parquet', 36_000, 2)",
        "memory: < 500 MB",
        ("--window", "100"),
    ),
    Workload(
        "slow errors: 20,000 epochs, d = 20",
        "speed._slow_errors({tmp!r} + '/slow20.parquet', 20_000, 20)",
        "memory: < 1 GB",
    ),
)


def _build(call: str) -> str:
    code = (
        f"import sys; sys.path.insert(0, {str(Path(__file__).parent)!r}); "
        f"import bench, speed; print(str({call}))"
    )
    out = subprocess.run([sys.executable, "-c", code], check=True, capture_output=True)
    return out.stdout.decode().strip().splitlines()[-1]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--rounds", type=int, default=2, help="interleaved pairs per workload")
    ap.add_argument("--only", help="comma-separated workload names (substrings)")
    args = ap.parse_args(argv)
    bench._compile_bytecode()
    chosen = [
        w for w in WORKLOADS if not args.only or any(s in w.name for s in args.only.split(","))
    ]
    print(f"credcli speed in plain-pass units, {os.cpu_count()} CPU(s), {args.rounds} rounds")
    header = "| workload | plain wall / CPU | credcli wall / CPU | units wall / CPU | peak RSS | target |"
    print(header + "\n|---|---|---|---|---|---|", flush=True)
    plain = [sys.executable, "-c", "import sys, speed; speed.plain_pass(sys.argv[1])"]
    env_path = str(Path(__file__).parent)
    os.environ["PYTHONPATH"] = os.pathsep.join(
        filter(None, [env_path, os.environ.get("PYTHONPATH")])
    )
    for work in chosen:
        with tempfile.TemporaryDirectory() as tmp:
            log = _build(work.build.format(tmp=tmp))
            out = str(Path(tmp) / "out.json")
            runs: dict[str, list[tuple[float, float, float]]] = {"plain": [], "credcli": []}
            for _ in range(args.rounds):
                runs["plain"].append(_child([*plain, log]))
                runs["credcli"].append(_child(diagnose_argv(log, out, work.options)))
                os.unlink(out)
            med = medians(runs)
            (pw, pc, _), (cw, cc, peak) = med["plain"], med["credcli"]
            print(
                f"| {work.name} | {pw:.2f} s / {pc:.2f} s | {cw:.2f} s / {cc:.2f} s | "
                f"{cw / pw:.1f} / {cc / pc:.1f} | {peak:.0f} MiB | {work.target} |",
                flush=True,
            )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
