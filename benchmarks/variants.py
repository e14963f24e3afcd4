"""Synthetic families of the zoo's shapes with other parameters (issue 30's held-out check:
sets "built the same way" as the zoo, never tuned on), with the oracle beside each cell.

    python benchmarks/variants.py [--lengths 50,300,2000] [--reps 60] [--seed 4242]
        [--slow-errors auto] [--set variants|third|fourth|fifth]

Each variant is one of ``zoo.py``'s synthetic shapes (AR(1), oscillating AR(2), ARMA(1,1),
slow + white mixtures, ARFIMA, a slow and a white direction, rotating and resized
covariances) at parameters the zoo does not use. For each length, ``reps`` credible
segments (``reps // 3`` above 300 epochs) are diagnosed with the default configuration, and
where N/τ >= 30 the same segments again with the covariance 4× too small and too large and
with a 1σ bias (paired, as in ``memory.py``). The columns: false alarms (a label naming a
misfit on a credible segment), decided (both questions answered), the oracle's share
decided (the scale question with the dependence known, ``zoo.oracle_scale_decided``: what
the data can decide), and the three powers.
"""

from __future__ import annotations

import argparse
import functools
import math
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import zoo  # noqa: E402
from zoo import Synthetic  # noqa: E402


def _ar2(radius: float, angle: float) -> tuple[float, float]:
    """AR(2) coefficients with complex roots of modulus ``radius`` at ±``angle``."""
    return (2.0 * radius * math.cos(angle), -radius * radius)


def _arma_family(phi: tuple, theta: tuple = ()) -> Synthetic:
    return Synthetic(
        lambda n, rng: zoo.arma(phi, theta, n, 2, rng),
        zoo.fixed_cov,
        lambda n: zoo.arma_tau(phi, theta),
        zoo.arma_rhos(phi, theta),
    )


def _slow_white_family(phi: float, white: float) -> Synthetic:
    return Synthetic(
        zoo.slow_white(phi, white),
        zoo.fixed_cov,
        lambda n: (1.0 - white) * zoo.arma_tau((phi,), ()) + white,
        zoo.slow_white_rho(phi, white),
    )


def _arfima_family(fraction: float) -> Synthetic:
    return Synthetic(
        lambda n, rng: zoo.arfima(fraction, n, 2, rng),
        zoo.fixed_cov,
        lambda n: zoo.arfima_tau_n(fraction, n),
        zoo.both_directions(functools.partial(zoo.arfima_rho, fraction)),
    )


def _slow_and_white_dirs(phi: float) -> Synthetic:
    return Synthetic(
        lambda n, rng: np.c_[zoo.arma((phi,), (), n, 1, rng), rng.standard_normal((n, 1))],
        zoo.fixed_cov,
        lambda n: zoo.arma_tau((phi,), ()),
        lambda n: [zoo.arma_rho((phi,), (), n), zoo.white_rho(n)],
    )


def _moving_cov(cov, phi: float) -> Synthetic:
    return Synthetic(
        zoo.ar_errors((phi,)), cov, lambda n: zoo.arma_tau((phi,), ()), zoo.arma_rhos((phi,))
    )


VARIANTS: dict[str, Synthetic] = {
    "ar1-0.7": _arma_family((0.7,)),
    "ar1-0.95": _arma_family((0.95,)),
    "ar2-0.9∠0.8": _arma_family(_ar2(0.9, 0.8)),
    "ar2-0.97∠0.15": _arma_family(_ar2(0.97, 0.15)),
    "ar2-0.8∠1.5": _arma_family(_ar2(0.8, 1.5)),
    "arma-0.95,-0.3": _arma_family((0.95,), (-0.3,)),
    "arma-0.7,0.5": _arma_family((0.7,), (0.5,)),
    "arma-0.8,-0.7": _arma_family((0.8,), (-0.7,)),
    "slow-white-0.97-0.4": _slow_white_family(0.97, 0.4),
    "slow-white-0.9-0.7": _slow_white_family(0.9, 0.7),
    "slow-white-0.995-0.2": _slow_white_family(0.995, 0.2),
    "arfima-0.2": _arfima_family(0.2),
    "arfima-0.4": _arfima_family(0.4),
    "slow-and-white-dirs-0.95": _slow_and_white_dirs(0.95),
    "rotating-cov-0.7": _moving_cov(zoo.rotating_cov, 0.7),
    "resized-cov-0.95": _moving_cov(zoo.resized_cov, 0.95),
    # session 23: a slow part of 10–15 % under white noise, and the ARMA(1, 1) that such a
    # mixture is (nearly cancelling roots): one segment's offset, and memory BIC misses
    "slow-white-0.98-0.85": _slow_white_family(0.98, 0.85),
    "slow-white-0.95-0.9": _slow_white_family(0.95, 0.9),
    "arma-0.95,-0.9": _arma_family((0.95,), (-0.9,)),
    # session 24: four of twelve families first run on seed 8080, kept where they showed a
    # weakness there: a slow part of 25–40 % whose bias a fractional alternative vetoes at
    # 2,000 epochs (1σ found 9 and 14 of 20), long memory beyond the zoo's (false alarms
    # 12 and 10 of 60 at 50 and 300 epochs), and an ARMA(1, 1) between the zoo's two
    "slow-white-0.97-0.75": _slow_white_family(0.97, 0.75),
    "slow-white-0.93-0.6": _slow_white_family(0.93, 0.6),
    "arfima-0.35": _arfima_family(0.35),
    "arma-0.9,-0.6": _arma_family((0.9,), (-0.6,)),
}
"""Twenty-three families the zoo does not hold, each a shape it does hold at other
parameters."""

THIRD: dict[str, Synthetic] = {
    "ar1-0.6": _arma_family((0.6,)),
    "ar2-0.9∠0.4": _arma_family(_ar2(0.9, 0.4)),
    "arma-0.85,0.3": _arma_family((0.85,), (0.3,)),
    "arma-0.8,-0.5": _arma_family((0.8,), (-0.5,)),
    "slow-white-0.96-0.8": _slow_white_family(0.96, 0.8),
    "slow-white-0.99-0.5": _slow_white_family(0.99, 0.5),
    "arfima-0.25": _arfima_family(0.25),
    "slow-and-white-dirs-0.97": _slow_and_white_dirs(0.97),
    "rotating-cov-0.9": _moving_cov(zoo.rotating_cov, 0.9),
    "resized-cov-0.8": _moving_cov(zoo.resized_cov, 0.8),
}
"""Session 25's third set (run with ``--seed 9191``): ten families at parameters neither the
zoo nor :data:`VARIANTS` uses, first run after the rule they measure was written."""

FOURTH: dict[str, Synthetic] = {
    "iid": _arma_family(()),
    "ar1-0.8": _arma_family((0.8,)),
    "ar2-0.85∠1.0": _arma_family(_ar2(0.85, 1.0)),
    "ar2-0.95∠0.3": _arma_family(_ar2(0.95, 0.3)),
    "arma-0.9,0.4": _arma_family((0.9,), (0.4,)),
    "arma-0.9,-0.8": _arma_family((0.9,), (-0.8,)),
    "slow-white-0.98-0.7": _slow_white_family(0.98, 0.7),
    "slow-white-0.96-0.9": _slow_white_family(0.96, 0.9),
    "slow-white-0.92-0.5": _slow_white_family(0.92, 0.5),
    "arfima-0.3": _arfima_family(0.3),
    "slow-and-white-dirs-0.9": _slow_and_white_dirs(0.9),
    "rotating-cov-0.5": _moving_cov(zoo.rotating_cov, 0.5),
}
"""Session 27's fourth set (run with ``--seed 777``): twelve more families at new
parameters, on which the slow readings' threshold (``rules.SLOW_READING_FIT``) was chosen
together with the other two."""

FIFTH: dict[str, Synthetic] = {
    "iid": _arma_family(()),
    "ar1-0.85": _arma_family((0.85,)),
    "ar2-0.92∠0.5": _arma_family(_ar2(0.92, 0.5)),
    "ar2-0.9∠1.2": _arma_family(_ar2(0.9, 1.2)),
    "arma-0.85,-0.5": _arma_family((0.85,), (-0.5,)),
    "arma-0.6,0.6": _arma_family((0.6,), (0.6,)),
    "slow-white-0.97-0.6": _slow_white_family(0.97, 0.6),
    "slow-white-0.99-0.4": _slow_white_family(0.99, 0.4),
    "slow-white-0.94-0.8": _slow_white_family(0.94, 0.8),
    "arfima-0.28": _arfima_family(0.28),
    "slow-and-white-dirs-0.93": _slow_and_white_dirs(0.93),
    "rotating-cov-0.8": _moving_cov(zoo.rotating_cov, 0.8),
    "resized-cov-0.9": _moving_cov(zoo.resized_cov, 0.9),
    # the slowest mixture of issue 30's table, which no other set holds
    "slow-white-0.998-0.1": _slow_white_family(0.998, 0.1),
}
"""Session 30's fifth set (run with ``--seed 2468``): fourteen families at parameters no
other set uses, first run on an engine not changed after (nothing was chosen on it)."""

SIXTH: dict[str, Synthetic] = {
    "iid": _arma_family(()),
    "ar1-0.75": _arma_family((0.75,)),
    "ar2-0.88∠0.7": _arma_family(_ar2(0.88, 0.7)),
    "ar2-0.96∠0.2": _arma_family(_ar2(0.96, 0.2)),
    "arma-0.75,-0.4": _arma_family((0.75,), (-0.4,)),
    "arma-0.5,0.8": _arma_family((0.5,), (0.8,)),
    "slow-white-0.985-0.8": _slow_white_family(0.985, 0.8),
    "slow-white-0.95-0.7": _slow_white_family(0.95, 0.7),
    "slow-white-0.9-0.85": _slow_white_family(0.9, 0.85),
    "arfima-0.22": _arfima_family(0.22),
    "arfima-0.33": _arfima_family(0.33),
    "slow-and-white-dirs-0.85": _slow_and_white_dirs(0.85),
    "rotating-cov-0.6": _moving_cov(zoo.rotating_cov, 0.6),
    "resized-cov-0.7": _moving_cov(zoo.resized_cov, 0.7),
}
"""Session 38's sixth set (run with ``--seed 1357``): fourteen families at parameters no
other set uses, run once on the engine as it stood, nothing chosen on it."""

SEVENTH: dict[str, Synthetic] = {
    "iid": _arma_family(()),
    "ar1-0.7": _arma_family((0.7,)),
    "ar2-0.93∠0.9": _arma_family(_ar2(0.93, 0.9)),
    "ar2-0.8∠2.0": _arma_family(_ar2(0.8, 2.0)),
    "arma-0.95,-0.7": _arma_family((0.95,), (-0.7,)),
    "arma-0.7,0.5": _arma_family((0.7,), (0.5,)),
    "slow-white-0.975-0.65": _slow_white_family(0.975, 0.65),
    "slow-white-0.995-0.2": _slow_white_family(0.995, 0.2),
    "slow-white-0.9-0.6": _slow_white_family(0.9, 0.6),
    "arfima-0.27": _arfima_family(0.27),
    "arfima-0.38": _arfima_family(0.38),
    "slow-and-white-dirs-0.95": _slow_and_white_dirs(0.95),
    "rotating-cov-0.7": _moving_cov(zoo.rotating_cov, 0.7),
    "resized-cov-0.6": _moving_cov(zoo.resized_cov, 0.6),
}
"""Session 40's seventh set (run with ``--seed 8642``): fourteen families at parameters no
other set uses, among them a strongly oscillating AR(2) (roots near −0.33 ± 0.73i), the
slowest long memory of any set (d 0.38) and a slow part of 80 % at 0.995; run once on the
engine as it stood, nothing chosen on it."""

SETS = {
    "variants": VARIANTS,
    "third": THIRD,
    "fourth": FOURTH,
    "fifth": FIFTH,
    "sixth": SIXTH,
    "seventh": SEVENTH,
}

EXPECTED = {"small4": "optimism", "large4": "pessimism", "bias1": "bias"}


def main() -> None:
    from credcli.engine.config import DiagnosisConfig
    from credcli.engine.diagnosis import diagnose_errors

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--lengths", default="50,300,2000")
    ap.add_argument("--reps", type=int, default=60)
    ap.add_argument("--seed", type=int, default=4242)
    ap.add_argument("--slow-errors", default="auto", help="the rule's slow_errors setting")
    ap.add_argument("--set", choices=tuple(SETS), default="variants", help="the families")
    args = ap.parse_args()
    config = DiagnosisConfig(slow_errors=args.slow_errors)
    families = SETS[args.set]
    zoo.SYNTHETIC.update(families)  # zoo.make finds a family by its name there
    level = DiagnosisConfig().scale_level
    lengths = [int(n) for n in args.lengths.split(",")]
    print(
        f"# Synthetic variants, N = {args.lengths}, R = {args.reps} (R/3 at 2000), seed {args.seed}"
        + ("" if args.slow_errors == "auto" else f", slow_errors {args.slow_errors}")
        + ("" if args.set == "variants" else f", set {args.set}")
    )
    print()
    print(
        "| family | N | R | N/τ | false alarms | decided | oracle decided % | ×¼ / ×4 / 1σ found |"
    )
    print("|---|---|---|---|---|---|---|---|")
    start = time.process_time()
    alarms_all = cells_all = decided_all = cells_decidable = 0
    found_all = dict.fromkeys(EXPECTED, 0)
    for index, (name, family) in enumerate(families.items()):
        for n in lengths:
            reps = args.reps if n <= 300 else max(1, args.reps // 3)
            ratio = n / family.tau(n)
            oracle, _ = zoo.oracle_scale_decided(family.rhos(n), n, level)
            misfits = ["none", *(EXPECTED if ratio >= 30 else ())]
            alarms = decided = 0
            found = dict.fromkeys(EXPECTED, 0)
            for misfit in misfits:
                for rep in range(reps):
                    rng = np.random.default_rng([args.seed, rep, n, index])
                    case = zoo.make(name, n, rng, misfit)
                    result = diagnose_errors(case.errors, case.cov, config, rng=rep)
                    label = result.label.value
                    if misfit == "none":
                        alarms += bool(result.label.conditions)
                        decided += not result.untested and label != "insufficient-data"
                    else:
                        found[misfit] += EXPECTED[misfit] in label
            power = " / ".join(str(found[m]) for m in EXPECTED) if ratio >= 30 else "–"
            print(
                f"| {name} | {n} | {reps} | {ratio:.3g} | {alarms} | {decided} | "
                f"{100 * oracle:.0f} | {power} |",
                flush=True,
            )
            alarms_all, cells_all = alarms_all + alarms, cells_all + reps
            if ratio >= 30:
                decided_all, cells_decidable = decided_all + decided, cells_decidable + reps
                for m in EXPECTED:
                    found_all[m] += found[m]
    print()
    print(f"- false alarms over all cells: {alarms_all} of {cells_all}")
    print(f"- decided at N/τ ≥ 30: {decided_all} of {cells_decidable}")
    found_text = " / ".join(str(found_all[m]) for m in EXPECTED)
    print(f"- found at N/τ ≥ 30 (×¼ / ×4 / 1σ): {found_text} of {cells_decidable} each")
    print(f"- CPU {time.process_time() - start:.0f} s")


if __name__ == "__main__":
    main()
