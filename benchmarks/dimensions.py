"""Many dimensions: labels by state dimension d on independent errors and on linear Kalman
filters with d = 6 … 16 outputs (session 34: the mean test under a fitted model, and a
principal direction beyond the credible margin).

    python benchmarks/dimensions.py [--reps 20] [--seed 34]

Families, each with the claimed covariance exact ("none") and misfit:

- ``iid-d``: independent N(0, I) errors of d = 2, 6, 15, 30 components, claim I, over
  100, 300 and 1,000 epochs (N >= 3d);
- ``kf-cv-k``: a steady-state constant-velocity Kalman filter of k axes at 10 Hz
  (positions measured, with a correlated measurement noise), its positions and velocities
  reported (d = 2k = 6, 12, 16), over 600 and 2,000 epochs; the errors drawn exactly from
  the filter's error recursion (``zoo.linear_kf``), τ its exact integrated correlation time.

Misfits: ``small4`` / ``large4`` (the claim 4× too small / large), ``bias1`` (a 1σ bias,
``zoo._bias_vector``), ``dir-small4`` / ``dir-large4`` (the claim 4× too small / large
along one random direction of the whitened errors only, the others right: the classic
overconfidence of a filter in one unobservable direction). Per cell, counts of R: decided
(both questions answered), a label naming a misfit (false alarms under "none"), and a
label naming the misfit made (power).
"""

from __future__ import annotations

import argparse
import sys
import time
from collections import Counter
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import zoo  # noqa: E402

MISFITS = ("none", "small4", "large4", "bias1", "dir-small4", "dir-large4")
EXPECTED = {
    "small4": "optimism",
    "large4": "pessimism",
    "bias1": "bias",
    "dir-small4": "optimism",
    "dir-large4": "pessimism",
}


def cv_model(axes: int, rate: float = 10.0, q: float = 0.5):
    """A constant-velocity model of ``axes`` axes: positions measured with a correlated
    noise (a fixed random shape per number of axes), positions and velocities reported."""
    dt = 1.0 / rate
    f1 = np.array([[1.0, dt], [0.0, 1.0]])
    q1 = q * np.array([[dt**3 / 3, dt**2 / 2], [dt**2 / 2, dt]])
    h = np.kron(np.eye(axes), np.array([[1.0, 0.0]]))
    a = np.random.default_rng(axes).standard_normal((axes, axes))
    r = a @ a.T / axes + np.eye(axes)
    return np.kron(np.eye(axes), f1), np.kron(np.eye(axes), q1), h, r, np.eye(2 * axes)


def _direction_misfit(cov: np.ndarray, factor: float, rng) -> np.ndarray:
    """The claim divided by ``factor`` along one random direction of its whitened frame:
    Σ̂ = Σ^{1/2} (I + (1/factor − 1) v vᵀ) Σ^{1/2}."""
    d = cov.shape[-1]
    v = rng.standard_normal(d)
    v /= np.linalg.norm(v)
    w, u = np.linalg.eigh(cov[0])
    root = (u * np.sqrt(w)) @ u.T
    shape = np.eye(d) + (1.0 / factor - 1.0) * np.outer(v, v)
    return np.broadcast_to(root @ shape @ root, cov.shape)


def case(family: str, n: int, misfit: str, rng) -> tuple[np.ndarray, np.ndarray, float]:
    """(errors, claimed covariances, τ) of one case; the errors do not depend on the
    misfit (paired cases)."""
    if family.startswith("iid"):
        d = int(family.split("-")[1])
        errors, cov, tau = rng.standard_normal((n, d)), np.broadcast_to(np.eye(d), (n, d, d)), 1.0
    else:
        kf = zoo.linear_kf(cv_model(int(family.split("-")[2])))
        errors = zoo.kf_errors(kf, n, rng)
        d = errors.shape[1]
        cov, tau = np.broadcast_to(kf.claimed, (n, d, d)), kf.tau
    direction = np.random.default_rng(rng.integers(2**63))  # drawn for every misfit alike
    if misfit == "small4":
        cov = cov / 4.0
    elif misfit == "large4":
        cov = cov * 4.0
    elif misfit == "bias1":
        errors = errors + zoo._bias_vector(np.asarray(cov))
    elif misfit.startswith("dir-"):
        cov = _direction_misfit(cov, 4.0 if misfit == "dir-small4" else 0.25, direction)
    return errors, np.ascontiguousarray(cov), tau


CELLS = [(f"iid-{d}", n) for d in (2, 6, 15, 30) for n in (100, 300, 1000) if n >= 3 * d]
CELLS += [(f"kf-cv-{k}", n) for k in (3, 6, 8) for n in (600, 2000)]


def main() -> None:
    from credcli.engine.diagnosis import diagnose_errors

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--reps", type=int, default=20)
    ap.add_argument("--seed", type=int, default=34)
    args = ap.parse_args()
    print(f"# labels by dimension, R = {args.reps}, seed {args.seed}")
    print()
    print("| family | d | N | N/τ | misfit | decided | names a misfit | found |")
    print("|---|---|---|---|---|---|---|---|")
    start = time.process_time()
    totals: Counter = Counter()
    for index, (family, n) in enumerate(CELLS):
        for misfit in MISFITS:
            counts: Counter = Counter()
            for rep in range(args.reps):
                rng = np.random.default_rng([args.seed, index, rep])
                errors, cov, tau = case(family, n, misfit, rng)
                result = diagnose_errors(errors, cov, rng=rep)
                label = result.label.value
                counts["decided"] += not result.untested and label != "insufficient-data"
                counts["misfit"] += bool(result.label.conditions)
                counts["found"] += misfit in EXPECTED and EXPECTED[misfit] in label
            found = str(counts["found"]) if misfit in EXPECTED else "–"
            d = errors.shape[1]
            print(
                f"| {family} | {d} | {n} | {n / tau:.3g} | {misfit} | {counts['decided']} | "
                f"{counts['misfit']} | {found} |",
                flush=True,
            )
            totals[misfit, "decided"] += counts["decided"]
            totals[misfit, "misfit"] += counts["misfit"]
            totals[misfit, "found"] += counts["found"]
    cases = len(CELLS) * args.reps
    print()
    for misfit in MISFITS:
        what = "false alarms" if misfit == "none" else "found"
        key = "misfit" if misfit == "none" else "found"
        print(
            f"- {misfit}: decided {totals[misfit, 'decided']} of {cases}, "
            f"{what} {totals[misfit, key]} of {cases}"
        )
    print(f"- CPU {time.process_time() - start:.0f} s")


if __name__ == "__main__":
    main()
