"""Where the calibrated rule declines a bias because a memory the data support as well
(the model's alternative: long memory, or an ARMA(p, 1) with more memory) does not find
it (``credcli.engine.evidence._held_under_alternative``), on credible segments (each a
false alarm prevented) and under a 1σ bias (each a detection given up), with r, the
radius of the alternative's confidence region over the fitted model's. A measurement for
choosing that rule, not a test.

    python benchmarks/alternative_declines.py [--set zoo|variants|third|fourth|fifth]
        [--seed S] [--families a,b] [--lengths 50,300,2000] [--reps R]
        [--below 1.1,1.2,1.5]

For each threshold t of ``--below``: how many declines with r < t there are on credible
segments and under the bias (what a rule that declined only where r >= t would give
back as false alarms and as detections), and where.
"""

from __future__ import annotations

import argparse
import sys
from collections import Counter
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import memory  # noqa: E402
import variants  # noqa: E402
import zoo  # noqa: E402


def main() -> None:
    from credcli.engine import batches, evidence
    from credcli.engine.diagnosis import diagnose_errors

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--set", default="zoo", choices=("zoo", *variants.SETS))
    ap.add_argument("--seed", type=int)
    ap.add_argument("--families", help="comma-separated (default: the whole set)")
    ap.add_argument("--lengths", default="50,300,2000")
    ap.add_argument("--reps", type=int, help="R (default: the zoo's 30, the variants' 60)")
    ap.add_argument("--below", default="1.1,1.2,1.5")
    args = ap.parse_args()
    declines: list[dict] = []
    case: dict = {}
    held = evidence._held_under_alternative

    def measured(plan, gls, model, inverse):
        out = held(plan, gls, model, inverse)
        if out is not plan:  # declined: the alternative's region against the model's
            other, _ = batches.memory_mean_test(gls, model.alternative, evidence._read(inverse))
            level = plan.mean_level
            r = other.bias_bound(0.0, level) / plan.mean_test.bias_bound(0.0, level)
            declines.append(dict(case, r=r))
        return out

    evidence._held_under_alternative = measured
    if args.set == "zoo":
        families, seed = zoo.families(), memory.SEED if args.seed is None else args.seed
    else:
        chosen = variants.SETS[args.set]
        zoo.SYNTHETIC.update(chosen)
        families, seed = list(chosen), 4242 if args.seed is None else args.seed
    if args.families:
        families = [f for f in families if f in args.families.split(",")]
    lengths = [int(n) for n in args.lengths.split(",")]
    for family in families:
        for n in lengths:
            if args.set == "zoo":
                reps = memory.reps_for(n, args.reps or 30)
            else:
                reps = (args.reps or 60) if n <= 300 else max(1, (args.reps or 60) // 3)
            for rep in range(reps):
                if args.set == "zoo":
                    entropy, diagnosis_seed = memory._seeds(family, n, rep, seed)
                else:  # variants.py's streams
                    index = list(variants.SETS[args.set]).index(family)
                    entropy, diagnosis_seed = [seed, rep, n, index], rep
                for misfit in ("none", "bias1"):
                    case = dict(family=family, n=n, misfit=misfit)
                    made = zoo.make(family, n, np.random.default_rng(entropy), misfit)
                    diagnose_errors(made.errors, made.cov, rng=diagnosis_seed)
    print(f"# declined biases, set {args.set}, seed {seed}, lengths {args.lengths}")
    for misfit, what in (("none", "credible segments"), ("bias1", "under a 1σ bias")):
        rs = sorted(d["r"] for d in declines if d["misfit"] == misfit)
        quantiles = (
            [round(rs[int(q * (len(rs) - 1))], 2) for q in (0, 0.25, 0.5, 0.75, 1)] if rs else []
        )
        print(f"- {what}: {len(rs)} declined; r at 0 / 25 / 50 / 75 / 100 %: {quantiles}")
    for t in (float(v) for v in args.below.split(",")):
        for misfit, what in (("none", "false alarms back"), ("bias1", "detections back")):
            cells = Counter(
                (d["family"], d["n"]) for d in declines if d["misfit"] == misfit and d["r"] < t
            )
            where = ", ".join(f"{f} at {n}: {k}" for (f, n), k in sorted(cells.items()))
            print(f"- r < {t:g}: {what} {sum(cells.values())} ({where})")


if __name__ == "__main__":
    main()
