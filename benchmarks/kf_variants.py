"""Kalman filters the zoo does not hold, measured at a given N/τ (issue 30's held-out check:
families "built the same way" as the zoo's, never tuned on).

    python benchmarks/kf_variants.py [--ratios 30,60] [--reps 60] [--seed 99]

Each variant is a steady-state linear filter of ``zoo.py`` (its error recursion, started
from the stationary law, so credible by construction) at another rate or noise level than
the zoo's. For each variant and each ratio r, ``reps`` segments of N = round(r·τ) epochs
(at least 50) are diagnosed with the default configuration; the table gives the false
alarms (a label naming a misfit) and the segments decided (both questions answered).
"""

from __future__ import annotations

import argparse
import sys
import time
import zlib
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import zoo  # noqa: E402

VARIANTS = {
    "kf-cv-50hz": (lambda: zoo.cv_model(50.0), 50.0),
    "kf-cv-10hz-q-x10": (lambda: zoo.cv_model(10.0, q=5.0), 10.0),
    "kf-ca-10hz-r-x0.1": (lambda: zoo.ca_model(10.0, r=0.1), 10.0),
    "kf-ca-1hz": zoo.KF_MODELS["kf-ca-1hz"],
    "kf-ca-100hz": zoo.KF_MODELS["kf-ca-100hz"],
    "kf-rw-1hz": zoo.KF_MODELS["kf-rw-1hz"],
    "kf-rw-100hz": zoo.KF_MODELS["kf-rw-100hz"],
}
"""The first three are not in the zoo; the last four are the zoo's, at N/τ = 30 and 60
rather than at its fixed lengths."""


def main() -> None:
    from credcli.engine.diagnosis import diagnose_errors

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--ratios", default="30,60")
    ap.add_argument("--reps", type=int, default=60)
    ap.add_argument("--seed", type=int, default=99)
    args = ap.parse_args()
    zoo.KF_MODELS.update(VARIANTS)
    ratios = [float(r) for r in args.ratios.split(",")]
    print(
        f"# Kalman filter variants at N/τ = {args.ratios}, {args.reps} segments, seed {args.seed}"
    )
    print()
    print("| variant | τ | N | N/τ | false alarms | decided |")
    print("|---|---|---|---|---|---|")
    start = time.process_time()
    for name in VARIANTS:
        tau = zoo.filter_of(name).tau
        for ratio in ratios:
            n = max(50, int(round(ratio * tau)))
            alarms = decided = 0
            for rep in range(args.reps):
                key = (zlib.crc32(name.encode()), n, rep)
                rng = np.random.default_rng(np.random.SeedSequence(args.seed, spawn_key=key))
                case = zoo.make(name, n, rng, "none")
                d = diagnose_errors(case.errors, case.cov, rng=rep)
                alarms += bool(d.label.conditions)
                decided += not d.untested and d.label.value != "insufficient-data"
            print(
                f"| {name} | {tau:.3g} | {n} | {n / tau:.3g} | {alarms} of {args.reps} "
                f"| {decided} of {args.reps} |",
                flush=True,
            )
    print()
    print(f"{time.process_time() - start:.0f} s CPU")


if __name__ == "__main__":
    main()
