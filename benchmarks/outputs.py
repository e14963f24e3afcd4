"""Outputs of many credcli commands from one source tree, and their comparison with another
tree's: what a change that claims "no behaviour change" (or "labels identical") is checked
against. Not a test: it reads ../shared and takes about 30 s a tree.

    python benchmarks/outputs.py write TREE DIR     # every command's stdout, stderr, code
    python benchmarks/outputs.py compare DIR_A DIR_B

``TREE`` is a directory holding a ``credcli`` package (a checkout, or
``git archive REV credcli | tar -x -C TREE``); each command runs as ``python -m credcli``
with ``PYTHONPATH=TREE`` from a temporary directory. ``compare`` prints the files that
differ; for JSON documents it says whether every segment's label is the same and which
keys differ, in how many segments, by how much (relative). The timing at the end of
`simulate`'s summary line is left out of the comparison.
"""

from __future__ import annotations

import json
import math
import os
import re
import subprocess
import sys
import tempfile
from collections import Counter
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SAMPLE = ROOT / "sample_data"
FORMATS = SAMPLE / "formats"
STARLOC = ROOT.parent / "shared" / "data" / "starloc"

COMMANDS: dict[str, list[str]] = {
    "diag_table": ["diagnose", f"{SAMPLE}/estimator_log.csv"],
    "diag_json": ["diagnose", f"{SAMPLE}/estimator_log.csv", "-f", "json"],
    "diag_csv": ["diagnose", f"{SAMPLE}/estimator_log.csv", "-f", "csv"],
    "diag_md": ["diagnose", f"{SAMPLE}/estimator_log.csv", "-f", "markdown"],
    "diag_parquet": ["diagnose", f"{SAMPLE}/estimator_log.parquet", "-f", "json"],
    "diag_regressed": ["diagnose", f"{SAMPLE}/estimator_log_regressed.csv", "-f", "json"],
    "errors_only": ["diagnose", f"{SAMPLE}/errors_only.csv", "--errors-only", "-f", "json"],
    "paper": ["diagnose", f"{SAMPLE}/estimator_log.csv", "--variant", "paper", "-f", "json"],
    "ks": ["diagnose", f"{SAMPLE}/estimator_log.csv", "--variant", "ks", "-f", "json"],
    "exact": ["diagnose", f"{SAMPLE}/estimator_log.csv", "--exact-pvalue", "-f", "json"],
    "window": ["diagnose", f"{SAMPLE}/estimator_log.csv", "--window", "20s", "-f", "json"],
    "jobs2": ["diagnose", f"{SAMPLE}/estimator_log.csv", "-f", "json", "--jobs", "2"],
    "mc": [
        "diagnose",
        *(f"{FORMATS}/mc_run_{k}.csv" for k in (1, 2, 3)),
        "--monte-carlo",
        "-f",
        "json",
    ],
    "mc_windows": [
        "diagnose",
        *(f"{FORMATS}/mc_run_{k}.csv" for k in (1, 2, 3)),
        "--monte-carlo",
        "--window",
        "10s",
        "-f",
        "json",
    ],
    "innovations": ["diagnose", f"{FORMATS}/innovations.csv", "--innovations", "-f", "json"],
    "tum": [
        "diagnose",
        f"{FORMATS}/openvins_estimate.txt",
        "--truth",
        f"{FORMATS}/tum_groundtruth.txt",
        "--states",
        "pose",
        "-f",
        "json",
    ],
    "no_truth": ["diagnose", f"{FORMATS}/odom_ros.csv", "-f", "json"],  # exit 2
    "uwb_grid": ["uwb", f"{SAMPLE}/starloc_grid_uwb.csv", "-f", "json"],
    "uwb_s5": ["uwb", f"{STARLOC}/loop-2d_s5_uwb.csv", "--std", "0.1", "--window", "5s"],
    "uwb_s2": [
        "uwb",
        f"{STARLOC}/loop-2d-fast_s2_uwb.csv",
        "--std",
        "0.1",
        "--window",
        "5s",
        "-f",
        "json",
    ],
    "simulate": ["simulate", "--trials", "60", "--jobs", "1", "-f", "json"],
    "simulate_pess_smm": ["simulate", "--scenario", "pess+smm", "--trials", "100", "--jobs", "2"],
}
"""Each output's name and the command that makes it (the README's kinds of use)."""

_TIMING = re.compile(r" in [0-9.]+ s$", re.MULTILINE)


def write(tree: Path, out: Path) -> None:
    """Run every command of :data:`COMMANDS` with ``tree``'s credcli into ``out``."""
    out.mkdir(parents=True, exist_ok=True)
    env = dict(os.environ, PYTHONPATH=str(tree.resolve()))
    with tempfile.TemporaryDirectory() as cwd:
        for name, args in COMMANDS.items():
            done = subprocess.run(
                [sys.executable, "-m", "credcli", *args], cwd=cwd, env=env, capture_output=True
            )
            (out / f"{name}.out").write_bytes(done.stdout)
            (out / f"{name}.err").write_bytes(_TIMING.sub(" in … s", done.stderr.decode()).encode())
            (out / f"{name}.rc").write_text(f"{done.returncode}\n")
            print(f"{name}: exit {done.returncode}", flush=True)


def _relative(a, b) -> float:
    """The largest relative difference of two JSON values (inf where they differ in kind)."""
    if isinstance(a, (int, float)) and isinstance(b, (int, float)):
        return 0.0 if a == b else abs(a - b) / max(abs(a), abs(b), 1e-300)
    if isinstance(a, list) and isinstance(b, list) and len(a) == len(b):
        return max([_relative(x, y) for x, y in zip(a, b)], default=0.0)
    return 0.0 if a == b else math.inf


def _segments(document) -> list:
    return document.get("segments", []) if isinstance(document, dict) else []


def json_differences(a: bytes, b: bytes) -> list[str]:
    """What differs between two JSON documents of `diagnose` or `uwb`: the labels, then each
    segment key that differs, in how many segments and by how much."""
    try:
        first, second = json.loads(a), json.loads(b)
    except ValueError:
        return []
    left, right = _segments(first), _segments(second)
    same = [s.get("label") for s in left] == [s.get("label") for s in right]
    lines = [f"  {len(left)} and {len(right)} segments, labels {'identical' if same else 'DIFFER'}"]
    counts, worst = Counter(), {}
    for x, y in zip(left, right):
        for key in dict.fromkeys([*x, *y]):
            if x.get(key) != y.get(key):
                counts[key] += 1
                worst[key] = max(worst.get(key, 0.0), _relative(x.get(key), y.get(key)))
    lines += [f"  {k}: {c} segment(s), relative {worst[k]:.2g}" for k, c in counts.most_common()]
    return lines


def compare(a: Path, b: Path) -> int:
    """Print the outputs that differ between two directories of :func:`write`; 1 if any."""
    names = sorted({p.name for p in a.iterdir()} | {p.name for p in b.iterdir()})
    differ = 0
    for name in names:
        left, right = a / name, b / name
        if left.exists() and right.exists() and left.read_bytes() == right.read_bytes():
            continue
        differ += 1
        print(f"{name} differs")
        if left.exists() and right.exists() and name.endswith(".out"):
            for line in json_differences(left.read_bytes(), right.read_bytes()):
                print(line)
    print(f"{len(names) - differ} of {len(names)} files identical")
    return 1 if differ else 0


def main(argv: list[str] | None = None) -> int:
    args = sys.argv[1:] if argv is None else argv
    if len(args) == 3 and args[0] == "write":
        write(Path(args[1]), Path(args[2]))
        return 0
    if len(args) == 3 and args[0] == "compare":
        return compare(Path(args[1]), Path(args[2]))
    print(__doc__.split("\n\n")[1], file=sys.stderr)
    return 2


if __name__ == "__main__":
    raise SystemExit(main())
