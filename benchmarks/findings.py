"""Issue 31: what the location findings name, measured (not a test).

    python benchmarks/findings.py [--reps R] [--seed S]

Independent errors, d = 2, claimed covariance exactly the errors' own, by shape:

- ``skewed``: each component a centred unit exponential (zero mean, unit variance, skew 2;
  non-line-of-sight ranges look like this). The right finding is ``asymmetric``; ``bias``
  is a false claim of a mean, whose rate is the mean test's level share.
- ``bias 0.5σ`` / ``bias 1σ``: Gaussian errors with a constant bias of that many σ along
  the first axis. The right finding is ``bias``.
- ``skewed + bias 1σ``: both; ``bias`` is right (the mean is what a fix removes first).

Columns: the share of segments whose label's location condition is each of bias,
asymmetric, smm, or none, with binomial standard errors.
"""

from __future__ import annotations

import argparse
import math
import time

import numpy as np

from credcli.engine.diagnosis import diagnose_errors

SHAPES = ("skewed", "bias 0.5σ", "bias 1σ", "skewed + bias 1σ")
LENGTHS = (100, 300, 1000)
CONDITIONS = ("bias", "asymmetric", "smm", None)


def draw(shape: str, n: int, gen: np.random.Generator) -> np.ndarray:
    """Errors (n, 2) of ``shape``, unit covariance."""
    if shape.startswith("skewed"):
        e = gen.exponential(size=(n, 2)) - 1.0
    else:
        e = gen.standard_normal((n, 2))
    if "bias" in shape:
        e[:, 0] += float(shape.split("bias ")[1].rstrip("σ"))
    return e


def measure(reps: int, seed: int) -> list[str]:
    cov = {n: np.broadcast_to(np.eye(2), (n, 2, 2)) for n in LENGTHS}
    out = [
        f"# `python benchmarks/findings.py --reps {reps} --seed {seed}`: location findings, "
        "d = 2, independent errors, correct covariance",
        "",
        "| errors | N | R | bias % | asymmetric % | smm % | none % |",
        "|---|---|---|---|---|---|---|",
    ]
    for shape in SHAPES:
        for n in LENGTHS:
            counts = dict.fromkeys(CONDITIONS, 0)
            for r in range(reps):
                gen = np.random.default_rng([seed, SHAPES.index(shape), n, r])
                d = diagnose_errors(draw(shape, n, gen), cov[n], rng=r)
                counts[d.label.location] += 1
            cells = [_pct(counts[c], reps) for c in CONDITIONS]
            out.append(f"| {shape} | {n} | {reps} | " + " | ".join(cells) + " |")
    return out


def _pct(k: int, n: int) -> str:
    p = k / n
    return f"{100 * p:.0f}±{100 * math.sqrt(p * (1 - p) / n):.0f}"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--reps", type=int, default=100)
    ap.add_argument("--seed", type=int, default=31)
    args = ap.parse_args()
    t0, c0 = time.perf_counter(), time.process_time()
    print("\n".join(measure(args.reps, args.seed)))
    print(f"\n{time.process_time() - c0:.0f} s CPU, {time.perf_counter() - t0:.0f} s wall")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
