"""Two versions of credcli side by side on the same logs: the old and new tree's command
lines interleaved (old, new, old, new, …), so that a machine whose speed drifts drifts for
both. Each tree's bytecode is written first, as an installed package has it.

    python benchmarks/versus.py OLD_TREE [NEW_TREE] [--rounds R] [--only NAME,...]
    make bench-versus BASE=<commit> [ONLY=NAME,...]

OLD_TREE and NEW_TREE are checkouts (a directory holding ``credcli/``; NEW_TREE defaults to
this repository), e.g. ``git worktree add --detach /tmp/old <commit>``. Each row prints the
median wall and CPU (user + system of the child) of both, new/old ratios, and both peak
RSS. Measurements, not tests.
"""

from __future__ import annotations

import argparse
import compileall
import os
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent))

import speed  # noqa: E402  (workloads, _child, _build)

ROOT = Path(__file__).resolve().parents[1]
SAMPLE = ROOT / "sample_data" / "estimator_log.csv"
EXTRA = (
    speed.Workload("the bundled sample log", repr(str(SAMPLE)), "start-up"),
    speed.Workload(
        "2k ten-epoch segments, d = 2",
        "speed._ten_epoch_segments({tmp!r} + '/ten2k.parquet', 2000)",
        "per-segment cost",
    ),
)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("old", help="the old tree (a directory holding credcli/)")
    ap.add_argument("new", nargs="?", default=str(ROOT), help="the new tree (default: here)")
    ap.add_argument("--rounds", type=int, default=2, help="interleaved pairs per workload")
    ap.add_argument("--only", help="comma-separated workload names (substrings)")
    args = ap.parse_args(argv)
    trees = {"old": Path(args.old).resolve(), "new": Path(args.new).resolve()}
    for tree in trees.values():
        if not (tree / "credcli").is_dir():
            raise SystemExit(f"versus: {tree} holds no credcli/; pass a checkout")
        compileall.compile_dir(tree / "credcli", quiet=1)
    workloads = EXTRA + speed.WORKLOADS
    chosen = [
        w for w in workloads if not args.only or any(s in w.name for s in args.only.split(","))
    ]
    print(f"credcli new ({trees['new']}) against old ({trees['old']}), {os.cpu_count()} CPU(s)")
    print(
        "| workload | old wall / CPU | new wall / CPU | new/old wall / CPU | peak RSS old / new |"
    )
    print("|---|---|---|---|---|", flush=True)
    for work in chosen:
        with tempfile.TemporaryDirectory() as tmp:
            log = speed._build(work.build.format(tmp=tmp))
            runs: dict[str, list] = {"old": [], "new": []}
            os.chdir(tmp)  # run from a checkout, `python -m credcli` imports that checkout
            for _ in range(args.rounds):
                for name, tree in trees.items():
                    os.environ["PYTHONPATH"] = str(tree)
                    out = str(Path(tmp) / f"{name}.json")
                    runs[name].append(speed._child(speed.diagnose_argv(log, out, work.options)))
                    os.unlink(out)
            os.chdir(ROOT)
            wall, cpu, peak = ({k: m[i] for k, m in speed.medians(runs).items()} for i in range(3))
            print(
                f"| {work.name} | {wall['old']:.2f} s / {cpu['old']:.2f} s | "
                f"{wall['new']:.2f} s / {cpu['new']:.2f} s | "
                f"{wall['new'] / wall['old']:.2f} / {cpu['new'] / cpu['old']:.2f} | "
                f"{peak['old']:.0f} / {peak['new']:.0f} MiB |",
                flush=True,
            )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
