"""Issue 35, item 1: the ELT before and after the fused pair-matrix pass, old and new
interleaved in one run.

    python benchmarks/elt_kernel.py OLD_TREE [--rounds R] [--log LOG]

OLD_TREE is a copy of credcli from before (``git archive <ref> credcli | tar -x -C DIR``).
Per ELT, N = 1,000, 2,048 and 4,000 single-epoch blocks (d = 2, B = 1,000, the stopping
rule of ``diagnose``), a credible segment (stops after 64 flips) and a biased one (all
flips, the low-rank bound): each tree runs in its own subprocess, alternating old, new,
old, new, … so that a machine whose speed drifts drifts for both; the new tree is timed
with the compiled kernel from the first pair (its import and first call are paid by a
warm-up call outside the timing) and with numpy only. With ``--log``: ``credcli diagnose
LOG -f json`` of each tree, wall and CPU (user + system of the child and its workers).
Prints medians and old/new ratios. Measurements, not tests.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

CHILD = r"""
import sys, time, json
import numpy as np
from credcli.engine import flips
from credcli.engine.elt import whitened_location_test
n, bias, mode, reps = int(sys.argv[1]), float(sys.argv[2]), sys.argv[3], int(sys.argv[4])
if hasattr(flips, "KERNEL_PAIRS"):
    flips.KERNEL_PAIRS = 0 if mode == "kernel" else 10**18
s = np.random.default_rng(n).standard_normal((n, 2)) + [bias, 0.0]
level = 1 - np.sqrt(0.95)
run = lambda: whitened_location_test(s, 1000, np.random.default_rng(1), stop_level=level)
start = time.perf_counter()
first = run()  # numba's import and first call, when used
first_call = time.perf_counter() - start
walls, cpus = [], []
for _ in range(reps):
    w, c = time.perf_counter(), time.process_time()
    result = run()
    walls.append(time.perf_counter() - w); cpus.append(time.process_time() - c)
print(json.dumps(dict(wall=min(walls), cpu=min(cpus), first=first_call,
                      p=result.pvalue, used=result.flips_used, t=result.statistic)))
"""


def _elt(tree: str, n: int, bias: float, mode: str, reps: int) -> dict:
    import json

    env = dict(os.environ, PYTHONPATH=tree, OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1")
    out = subprocess.run(
        [sys.executable, "-c", CHILD, str(n), str(bias), mode, str(reps)],
        env=env,
        capture_output=True,
        text=True,
        check=True,
        cwd="/",
    )
    return json.loads(out.stdout.strip().splitlines()[-1])


def _diagnose(tree: str, log: str, out: str) -> tuple[float, float]:
    env = dict(os.environ, PYTHONPATH=tree)
    start = time.perf_counter()
    proc = subprocess.Popen(
        [sys.executable, "-m", "credcli", "diagnose", log, "-f", "json", "-o", out],
        env=env,
        cwd="/",
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    _, _, usage = os.wait4(proc.pid, 0)
    return time.perf_counter() - start, usage.ru_utime + usage.ru_stime


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("old", help="a copy of credcli from before")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--reps", type=int, default=3, help="timed calls per child (best kept)")
    ap.add_argument("--log", help="also time `credcli diagnose LOG -f json`")
    args = ap.parse_args(argv)
    new = str(ROOT)
    print(
        f"ELT old/new, {os.cpu_count()} CPU(s), load {os.getloadavg()[0]:.1f}, "
        f"{args.rounds} rounds interleaved, best of {args.reps} calls per child"
    )
    print(
        "| N | segment | old wall / CPU | new (kernel) | new (numpy) | ratio old/kernel wall / CPU | old/numpy CPU | numba first call |"
    )
    print("|---|---|---|---|---|---|---|---|", flush=True)
    for n in (1000, 2048, 4000):
        for bias, name in ((0.0, "credible (64 flips)"), (0.2, "biased (1,000 flips)")):
            runs: dict[str, list[dict]] = {"old": [], "kernel": [], "numpy": []}
            for _ in range(args.rounds):
                runs["old"].append(_elt(args.old, n, bias, "numpy", args.reps))
                runs["kernel"].append(_elt(new, n, bias, "kernel", args.reps))
                runs["numpy"].append(_elt(new, n, bias, "numpy", args.reps))
            same = {(r["p"], r["used"], r["t"]) for v in runs.values() for r in v}
            assert len(same) == 1, same  # the same p-value, flips and statistic, bit for bit
            med = {
                k: {f: statistics.median(r[f] for r in v) for f in ("wall", "cpu", "first")}
                for k, v in runs.items()
            }
            o, k, p = med["old"], med["kernel"], med["numpy"]
            print(
                f"| {n} | {name} | {1e3 * o['wall']:.1f} / {1e3 * o['cpu']:.1f} ms "
                f"| {1e3 * k['wall']:.1f} / {1e3 * k['cpu']:.1f} ms "
                f"| {1e3 * p['wall']:.1f} / {1e3 * p['cpu']:.1f} ms "
                f"| {o['wall'] / k['wall']:.2f} / {o['cpu'] / k['cpu']:.2f} "
                f"| {o['cpu'] / p['cpu']:.2f} | {k['first'] - k['wall']:.2f} s |",
                flush=True,
            )
    if args.log:
        times: dict[str, list[tuple[float, float]]] = {"old": [], "new": []}
        for _ in range(args.rounds):
            for name, tree in (("old", args.old), ("new", new)):
                times[name].append(_diagnose(tree, args.log, f"/tmp/elt_kernel_{name}.json"))
        same = (
            Path("/tmp/elt_kernel_old.json").read_bytes()
            == Path("/tmp/elt_kernel_new.json").read_bytes()
        )
        med = {
            k: (statistics.median(t[0] for t in v), statistics.median(t[1] for t in v))
            for k, v in times.items()
        }
        (ow, oc), (nw, nc) = med["old"], med["new"]
        print(
            f"\ndiagnose {args.log}: old {ow:.2f} s wall / {oc:.2f} s CPU, new {nw:.2f} s / "
            f"{nc:.2f} s, ratio {ow / nw:.2f} / {oc / nc:.2f}; JSON byte-identical: {same}"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
