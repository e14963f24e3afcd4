"""The calibrated rule on the zoo of error processes (benchmarks/zoo.py): decided share,
false alarms and power by family, segment length N and misfit. Measurements with their
binomial standard errors, not tests.

    python benchmarks/memory.py [--quick] [--families a,b] [--lengths 50,300,2000]
                                [--reps R] [--misfits none,small4,large4,bias1] [--seed S]

For each family × N × misfit it draws R cases (R = 100, 30 with --quick; fewer for long
segments, see :func:`reps_for`) and runs ``diagnose_errors(errors, cov, rng=seed)`` with
the default (calibrated) configuration. Cases are paired across misfits: draw r of a family
and N uses one random stream for all four misfits, so the misfits differ only by the misfit
(and a library filter is run once per draw).

Columns: decided = both questions answered (label not insufficient, nothing untested);
credible = label "credible"; false alarm (misfit none) = a label naming a condition;
power (misfits) = the label contains the right condition (optimism for small4, pessimism
for large4, bias for bias1); insufficient = label insufficient-data. Library families are
not exactly credible when right-tuned (truth_factor NaN): their "none" rows are a separate
"right-tuned library" table whose "flagged" is not a false-alarm rate.

``run(families, lengths, reps, misfits, diagnose=...)`` returns the rows as dicts, for
other code to compare another rule: ``diagnose(errors, cov, rng)`` must return an object
with ``.label`` (a :class:`Label`) and ``.untested``.
"""

from __future__ import annotations

import argparse
import functools
import glob
import hashlib
import math
import os
import sys
import time
import zlib
from collections.abc import Callable, Iterable

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

import zoo  # noqa: E402

from credcli.engine.diagnosis import Label, diagnose_errors  # noqa: E402

EXPECTED = {"small4": "optimism", "large4": "pessimism", "bias1": "bias"}
SEED = 20240


def reps_for(n: int, reps: int) -> int:
    """R for segments of n epochs: all R up to 500 epochs, R·500/n beyond (at least 10),
    since a diagnosis costs ~n² beyond a few hundred epochs (the ELT)."""
    if n <= 500:
        return reps
    return max(10, min(reps, int(round(reps * 500 / n))))


def _seeds(family: str, n: int, rep: int, seed: int) -> tuple[np.random.SeedSequence, int]:
    ss = np.random.SeedSequence(entropy=seed, spawn_key=(zlib.crc32(family.encode()), n, rep))
    return ss, int(ss.generate_state(1)[0])


COUNTS = ("decided", "credible", "flagged", "power", "insufficient", "partial")
"""What a cell counts over its cases (see the module doc)."""


def _tally(counts: dict, d, misfit: str) -> None:
    """Count one diagnosis ``d`` of a case with ``misfit`` into ``counts`` (:data:`COUNTS`)."""
    insufficient = d.label is Label.INSUFFICIENT
    counts["insufficient"] += insufficient
    counts["decided"] += (not insufficient) and not d.untested
    counts["partial"] += (not insufficient) and bool(d.untested)
    counts["credible"] += d.label is Label.CREDIBLE
    counts["flagged"] += bool(d.label.conditions)
    counts["power"] += misfit in EXPECTED and EXPECTED[misfit] in d.label.conditions


def _row(family: str, n: int, misfit: str, case, seconds: float, counts: dict, **extra) -> dict:
    """One row of a cell: the family, N, the misfit's case's τ and truth, and the counts."""
    kind = zoo.kind(family)
    return dict(
        family=family,
        kind=kind,
        n=n,
        misfit=misfit,
        tau=case.tau,
        n_over_tau=n / case.tau if case.tau > 0 else float("nan"),
        truth_factor=case.truth_factor,
        library=kind == "library",
        seconds=seconds,
        **extra,
        **counts,
    )


def run(
    families: Iterable[str],
    lengths: Iterable[int],
    reps: int,
    misfits: Iterable[str] = zoo.MISFITS,
    diagnose: Callable = diagnose_errors,
    seed: int = SEED,
    progress: bool = False,
) -> list[dict]:
    """One row per family × N × misfit with the counts over R = reps_for(N, reps) cases."""
    misfits = list(misfits)
    rows = []
    for family in families:
        for n in lengths:
            r = reps_for(n, reps)
            acc = {m: dict.fromkeys(COUNTS, 0) for m in misfits}
            info: dict[str, zoo.Case] = {}
            t0 = time.process_time()
            for rep in range(r):
                ss, diag_seed = _seeds(family, n, rep, seed)
                for m in misfits:
                    case = zoo.make(family, n, np.random.default_rng(ss), m)
                    info.setdefault(m, case)
                    _tally(acc[m], diagnose(case.errors, case.cov, rng=diag_seed), m)
            seconds = time.process_time() - t0
            rows += [
                _row(family, n, m, info[m], seconds / len(misfits), acc[m], reps=r) for m in misfits
            ]
            if progress:
                print(f"  {family} N={n} R={r}: {seconds:.1f}s", file=sys.stderr, flush=True)
    return rows


def run_windows(
    families: Iterable[str],
    lengths: Iterable[int],
    reps: int,
    windows: int,
    misfits: Iterable[str] = zoo.MISFITS,
    seed: int = SEED,
    progress: bool = False,
    config=None,
) -> list[dict]:
    """As :func:`run`, for windows of one run (``credcli diagnose --window``): each case is
    a run of ``windows`` × N epochs, cut into windows of N epochs that are judged against
    the run's dependence model; the counts are per window (``reps`` = R × windows). The
    run's own label is counted apart (``run_flagged``, ``run_power``, ``run_decided``).
    ``config``: the rule's settings (default: the calibrated defaults)."""
    from credcli.api import log_from_arrays
    from credcli.engine.diagnosis import diagnose_segments
    from credcli.segments import split

    misfits = list(misfits)
    rows = []
    for family in families:
        for n in lengths:
            r = max(1, reps_for(n * windows, reps))
            acc = {m: dict.fromkeys(COUNTS, 0) for m in misfits}
            whole = {m: dict.fromkeys(COUNTS, 0) for m in misfits}  # the runs' own labels
            info: dict[str, zoo.Case] = {}
            t0 = time.process_time()
            for rep in range(r):
                ss, diag_seed = _seeds(family, n, rep, seed)
                for m in misfits:
                    case = zoo.make(family, n * windows, np.random.default_rng(ss), m)
                    info.setdefault(m, case)
                    log = log_from_arrays(errors=case.errors, cov=case.cov)
                    plan = split(log, str(n), False)
                    results = diagnose_segments(log, plan, config, seed=diag_seed)
                    for segment, result in zip(plan, results):
                        _tally((acc if segment.window else whole)[m], result.diagnosis, m)
            seconds = time.process_time() - t0
            rows += [
                _row(
                    family,
                    n,
                    m,
                    info[m],
                    seconds / len(misfits),
                    acc[m],
                    reps=r * windows,
                    runs=r,
                    run_flagged=whole[m]["flagged"],
                    run_power=whole[m]["power"],
                    run_decided=whole[m]["decided"],
                )
                for m in misfits
            ]
            if progress:
                print(
                    f"  {family} N={n} × {windows} windows, R={r}: {seconds:.1f}s",
                    file=sys.stderr,
                    flush=True,
                )
    return rows


def _run_lines(rows: list[dict]) -> list[str]:
    """The runs' own labels beside their windows' (:func:`run_windows`)."""
    out = []
    for m in dict.fromkeys(r["misfit"] for r in rows):
        sub = [r for r in rows if r["misfit"] == m and not (m == "none" and r["library"])]
        runs = sum(r["runs"] for r in sub)
        key = "run_flagged" if m == "none" else "run_power"
        what = "false alarms" if m == "none" else f"power ({EXPECTED[m]})"
        k, dec = sum(r[key] for r in sub), sum(r["run_decided"] for r in sub)
        out.append(
            f"- the runs' own labels, misfit {m}: {what} {_pct(k, runs)} %, "
            f"decided {_pct(dec, runs)} % ({runs} runs)"
        )
    return out


def _pct(k: int, n: int) -> str:
    if n == 0:
        return "–"
    p = k / n
    return f"{100 * p:.0f}±{100 * math.sqrt(p * (1 - p) / n):.0f}"


def _pooled(rows: list[dict], key: str, label: str) -> str:
    k, n = sum(r[key] for r in rows), sum(r["reps"] for r in rows)
    return f"{label}: {_pct(k, n)} % ({k}/{n} cases, {len(rows)} cells)"


def _table(rows: list[dict], rate: str, rate_name: str) -> list[str]:
    head = (
        f"| family | N | R | N/τ | truth | decided % | credible % | {rate_name} % "
        "| insufficient % |"
    )
    out = [head, "|" + "---|" * 9]
    for r in rows:
        tf = r["truth_factor"]
        out.append(
            f"| {r['family']}{' †' if r['library'] else ''} | {r['n']} | {r['reps']} "
            f"| {r['n_over_tau']:.3g} | {'–' if math.isnan(tf) else f'{tf:.3g}'} "
            f"| {_pct(r['decided'], r['reps'])} | {_pct(r['credible'], r['reps'])} "
            f"| {_pct(r[rate], r['reps'])} | {_pct(r['insufficient'], r['reps'])} |"
        )
    return out


def report(rows: list[dict]) -> str:
    """The Markdown tables of :func:`run`'s rows, one per misfit."""
    out = []
    for m in dict.fromkeys(r["misfit"] for r in rows):
        sub = [r for r in rows if r["misfit"] == m]
        if m == "none":
            exact = [r for r in sub if not r["library"]]
            lib = [r for r in sub if r["library"]]
            if exact:
                out += ["", "### misfit none: credible by construction", ""]
                out += _table(exact, "flagged", "false alarm")
                long = [r for r in exact if r["n_over_tau"] >= 30]
                out += [
                    "",
                    _pooled(exact, "flagged", "- false alarms over all credible cells"),
                    _pooled(long, "decided", "- decided over cells with N/τ ≥ 30"),
                    _pooled(long, "credible", "- credible over cells with N/τ ≥ 30"),
                ]
            if lib:
                out += [
                    "",
                    "### misfit none: right-tuned library filters (not exactly credible)",
                    "",
                ]
                out += _table(lib, "flagged", "flagged")
                out += ["", _pooled(lib, "flagged", "- flagged over right-tuned library cells")]
        else:
            out += ["", f"### misfit {m}: power = label contains {EXPECTED[m]!r}", ""]
            out += _table(sub, "power", "power")
            long = [r for r in sub if r["n_over_tau"] >= 30]
            exact = [r for r in sub if not r["library"]]
            out += [
                "",
                _pooled(exact, "power", "- power over all exact (non-library) cells"),
                _pooled(long, "power", "- power over cells with N/τ ≥ 30"),
                _pooled(long, "decided", "- decided over cells with N/τ ≥ 30"),
            ]
    out += ["", "† library filter: truth_factor relative to the right-tuned filter (NaN: –)."]
    out += _oracle_table([r for r in rows if r["misfit"] == "none" and not r["library"]])
    return "\n".join(out)


def _oracle_table(rows: list[dict]) -> list[str]:
    """The credible synthetic cells' decided share beside what the scale question alone can
    decide with the dependence known (:func:`zoo.oracle_scale_decided` at α_S): a ceiling
    for any rule that estimates the dependence. ν is the oracle's degrees of freedom, 2N/τ₂
    per direction, τ₂ = Σρ²; N/τ counts the location's information, ν the scale's."""
    from credcli.engine.diagnosis import DiagnosisConfig

    level = DiagnosisConfig().scale_level
    lines = []
    for r in rows:
        rhos = zoo.direction_rhos(r["family"], r["n"])
        if rhos is None:
            continue
        share, nu = zoo.oracle_scale_decided(rhos, r["n"], level)
        decided = _pct(r["decided"], r["reps"])
        lines.append(
            f"| {r['family']} | {r['n']} | {r['n_over_tau']:.3g} | {nu:.3g} | "
            f"{100 * share:.0f} | {decided} |"
        )
    if not lines:
        return []
    head = [
        "",
        f"### The scale question with the dependence known (oracle, α_S = {level:.4f})",
        "",
        "| family | N | N/τ | ν | oracle decided % | decided % |",
        "|---|---|---|---|---|---|",
    ]
    return head + lines


def engine_fingerprint() -> str:
    """Where credcli was imported from and a short hash of its engine's sources, to tell
    which engine a saved table measured."""
    import credcli

    root = os.path.dirname(credcli.__file__)
    h = hashlib.sha256()
    for path in sorted(glob.glob(os.path.join(root, "engine", "*.py"))):
        h.update(os.path.basename(path).encode())
        with open(path, "rb") as f:
            h.update(f.read())
    return f"credcli from {root}, engine sources sha256 {h.hexdigest()[:12]}"


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="R = 30")
    ap.add_argument("--families", help="comma-separated (default: all of zoo.families())")
    ap.add_argument("--lengths", default="50,300,2000")
    ap.add_argument("--reps", type=int, help="R (default 100, 30 with --quick)")
    ap.add_argument("--misfits", default=",".join(zoo.MISFITS))
    ap.add_argument("--seed", type=int, default=SEED)
    ap.add_argument("--slow-errors", default="auto", help="the rule's slow_errors setting")
    ap.add_argument(
        "--windows",
        type=int,
        default=0,
        help="K: each case a run of K windows of N epochs, judged with the run's model",
    )
    args = ap.parse_args(argv)
    fams = args.families.split(",") if args.families else zoo.families()
    lengths = [int(x) for x in args.lengths.split(",")]
    reps = args.reps or (30 if args.quick else 100)
    misfits = args.misfits.split(",")
    t0, w0 = time.process_time(), time.time()
    from credcli.engine.diagnosis import DiagnosisConfig

    config = DiagnosisConfig(slow_errors=args.slow_errors)
    if args.windows:
        rows = run_windows(fams, lengths, reps, args.windows, misfits, args.seed, True, config)
        print(
            f"# Calibrated rule on windows of one run: {len(fams)} families, runs of "
            f"{args.windows} windows of N = {lengths} epochs, R = {reps} runs (fewer for "
            f"long runs, as reps_for), seed {args.seed}; counts per window"
            + ("" if args.slow_errors == "auto" else f"; slow_errors {args.slow_errors}")
        )
    else:
        diagnose = functools.partial(diagnose_errors, config=config)
        rows = run(fams, lengths, reps, misfits, diagnose, seed=args.seed, progress=True)
        print(
            f"# Calibrated rule on the zoo: {len(fams)} families, N = {lengths}, R = {reps} "
            f"(R = {reps_for(max(lengths), reps)} at N = {max(lengths)}), seed {args.seed}"
            + ("" if args.slow_errors == "auto" else f", slow_errors {args.slow_errors}")
        )
    print(f"# {engine_fingerprint()}")
    print(report(rows))
    if args.windows:
        print("\n".join(["", *_run_lines(rows)]))
    print(f"\n{time.process_time() - t0:.0f} s CPU, {time.time() - w0:.0f} s wall")


if __name__ == "__main__":
    main()
