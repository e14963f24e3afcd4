"""τ̂ of an AICc AR sieve against the best ARMA(p, 1) of the long-memory choice, per zoo family.

    python benchmarks/arma_tau.py [--reps 20] [--seed 99] [--families kf-cv-10hz,...]

A lead measured, not in the rule (docs/measured.md, session 28): would the ARMA(p, 1) that
``credcli.engine.longmemory._moving_average_fits`` fits as fractional noise's competitor be
a better estimate of the errors' memory than the sieve? On the first whitened axis of each
credible segment, centred: the sieve is Burg's AR of least AICc, τ̂ = σ²_u / (A(1)² γ̂(0));
the ARMA is the grid's (θ, p) of least AICc, τ̂ = σ²_u (1 + θ)² / (A(1)² γ̂(0)). Printed per
family and length: the true τ, the median and 10–90 % range of each τ̂, and the median of
AICc(ARMA) − AICc(sieve).
"""

from __future__ import annotations

import argparse
import math
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

import memory as memory_bench  # noqa: E402  (benchmarks/memory.py: the zoo's seeds)
import zoo  # noqa: E402

from credcli.engine import longmemory, memory  # noqa: E402

FAMILIES = (
    "kf-cv-10hz,kf-cv-100hz,kf-ca-10hz,kf-rw-10hz,ar1-0.9,ar2-complex,arma11,"
    "slow-white-0.95-0.5,gtsam-pose2-smoother"
)


def taus(x: np.ndarray, p_max: int) -> tuple[float, float, float]:
    """(sieve τ̂, ARMA τ̂, AICc(ARMA) − AICc(sieve)) of one series."""
    x = x - x.mean()
    t = x.size
    gamma0 = float(x.var())
    fit = memory.burg(x.reshape(1, 1, t), p_max)
    aicc = fit.aicc()[0]
    p = int(np.argmin(aicc))
    phi = fit.coefficients(0, p)
    sieve = fit.variance[0, p] / (1.0 - phi.sum()) ** 2 / gamma0
    cost, models = longmemory._moving_average_fits(x.reshape(1, t), p_max)
    theta, phi_arma = models[0]
    u = longmemory.ar_filter(np.array([-theta]), x.reshape(t, 1)).ravel()
    refit = memory.burg(u.reshape(1, 1, t), p_max)
    arma = refit.variance[0, phi_arma.size] * (1.0 + theta) ** 2 / (1.0 - phi_arma.sum()) ** 2
    return float(sieve), float(arma / gamma0), float(cost[0] - aicc[p])


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--reps", type=int, default=20)
    ap.add_argument("--seed", type=int, default=99)
    ap.add_argument("--families", default=FAMILIES)
    args = ap.parse_args(argv)
    print(f"# sieve and ARMA(p, 1) τ̂, first whitened axis, R = {args.reps}, seed {args.seed}")
    print("| family | N | τ | sieve τ̂ median [10 %, 90 %] | ARMA τ̂ median [10 %, 90 %] | ΔAICc |")
    print("|---|---|---|---|---|---|")
    for family in args.families.split(","):
        for n in (300, 2000):
            rows, tau = [], math.nan
            for rep in range(args.reps):
                ss, _ = memory_bench._seeds(family, n, rep, args.seed)
                case = zoo.make(family, n, np.random.default_rng(ss), "none")
                tau = case.tau
                p_max = max(1, min(int(10 * math.log10(n)), n // 10))
                rows.append(taus(zoo.whiten(case.errors, case.cov)[:, 0], p_max))
            r = np.array(rows)
            cells = [
                f"{np.median(r[:, j]):.3g} [{np.quantile(r[:, j], 0.1):.3g}, "
                f"{np.quantile(r[:, j], 0.9):.3g}]"
                for j in (0, 1)
            ]
            print(
                f"| {family} | {n} | {tau:.3g} | {cells[0]} | {cells[1]} | "
                f"{np.median(r[:, 2]):.2f} |"
            )


if __name__ == "__main__":
    main()
