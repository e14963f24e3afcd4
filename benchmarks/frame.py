"""Whether a label depends on the frame the state is written in: each synthetic segment of
the zoo and the held-out sets diagnosed as it is and again with its errors and
covariances in another frame, e → Re, Σ → RΣRᵀ, for a constant R: the components'
order reversed (a permutation), a random rotation, or other units (R diagonal, each
component's unit changed by a factor 10^u, u uniform in [−3, 3]). A measurement, not a
test.

    python benchmarks/frame.py [--frame permutation|rotation|units] [--lengths 50,300]
        [--reps 2] [--seed 9]

Every statistic of the paper is invariant under such an R: the NEES, the GLS mean and
its Mahalanobis size, and the ELT, whose whitened errors Σ^{-1/2}e (Eq. (12), the
symmetric root) turn by R. What is not: a step that reads the whitened errors axis by
axis, or whitens them with the Cholesky factor, L_k⁻¹e_k, which differs from Σ_k^{-1/2}e_k
by an orthogonal Q_k that changes from epoch to epoch when the covariances do. Other
units are the reverse case: the Cholesky factor of DΣD is D L, so L_k⁻¹e_k does not change,
while the symmetric root's whitened errors turn by a Q_k that changes with Σ_k (no
whitening follows both rotations and changes of units: together they make every
invertible R, and Σ^{-1/2} is the only root that turns with rotations). The
table counts, per family, the segments whose label changes (of the cases run: lengths ×
no misfit, a 1σ bias, ×¼ and ×4 × reps).
"""

from __future__ import annotations

import argparse
import sys
from collections import Counter
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import variants  # noqa: E402
import zoo  # noqa: E402

MISFITS = ("none", "bias1", "small4", "large4")


def _frame(kind: str, d: int, seed: int) -> np.ndarray:
    """A constant R: the components' order reversed, a uniformly random rotation, or
    units changed by factors 10^u, u uniform in [−3, 3]."""
    if kind == "permutation":
        return np.eye(d)[::-1]
    if kind == "units":
        return np.diag(10.0 ** np.random.default_rng(seed).uniform(-3.0, 3.0, d))
    q, r = np.linalg.qr(np.random.default_rng(seed).standard_normal((d, d)))
    q = q * np.sign(np.diag(r))
    if np.linalg.det(q) < 0:
        q[:, 0] = -q[:, 0]
    return q


def main() -> None:
    from credcli.engine.config import DiagnosisConfig
    from credcli.engine.diagnosis import diagnose_errors

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--frame", default="permutation", choices=("permutation", "rotation", "units"))
    ap.add_argument("--lengths", default="50,300")
    ap.add_argument("--reps", type=int, default=2)
    ap.add_argument("--seed", type=int, default=9)
    args = ap.parse_args()
    families = {}
    for name in variants.SETS:
        families.update(variants.SETS[name])
    zoo.SYNTHETIC.update(families)
    names = list(zoo.SYNTHETIC)
    lengths = [int(n) for n in args.lengths.split(",")]
    config = DiagnosisConfig()
    changed: Counter = Counter()
    cases: Counter = Counter()
    examples = []
    for index, name in enumerate(names):
        for n in lengths:
            for misfit in MISFITS:
                for rep in range(args.reps):
                    rng = np.random.default_rng([args.seed, rep, n, index])
                    case = zoo.make(name, n, rng, misfit)
                    d = case.errors.shape[1]
                    cov = np.broadcast_to(case.cov, (n, d, d))
                    rot = _frame(args.frame, d, args.seed + 1000 * index + rep)
                    before = diagnose_errors(case.errors, cov, config, rng=rep)
                    after = diagnose_errors(case.errors @ rot.T, rot @ cov @ rot.T, config, rng=rep)
                    cases[name] += 1
                    if before.label is not after.label:
                        changed[name] += 1
                        examples.append(
                            f"{name} N={n} {misfit} rep {rep}: {before.label.value} -> "
                            f"{after.label.value}"
                        )
    print(
        f"# labels in another frame ({args.frame}), lengths {args.lengths}, "
        f"{args.reps} rep(s) of {', '.join(MISFITS)}, seed {args.seed}"
    )
    print()
    print("| family | cases | label changed |")
    print("|---|---|---|")
    for name in names:
        if changed[name]:
            print(f"| {name} | {cases[name]} | {changed[name]} |")
    print()
    print(f"- every other family: no label changed ({len(names) - len(changed)} families)")
    print(f"- all: {sum(changed.values())} of {sum(cases.values())} labels changed")
    for line in examples:
        print(f"  - {line}")


if __name__ == "__main__":
    main()
