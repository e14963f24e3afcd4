"""A candidate the rule does not use yet: the AR sieve's long-run variance corrected by a
kernel estimate of its residuals' spectrum at frequency zero (prewhitening and
recolouring, Andrews & Monahan 1992, Econometrica 60(4)), measured on zoo families.

    python benchmarks/prewhitened.py [--reps 40] [--seed 4] [--width 4] [--kernel parzen]

Per segment, each whitened component is fitted by Burg's AR sieve (order by AICc, at
least 1), its residuals u_t = A(B)x_t are formed, and

    c = (γ̂_u(0) + 2 Σ_{0<h<M} k(h/M) γ̂_u(h)) / γ̂_u(0),   M = ``width`` · τ̂_AR,

with the Parzen (or Bartlett) kernel k. The sieve reads the long-run variance as
σ²_u/A(1)², as if u were white; c is the ratio of u's spectrum at zero to its variance, so
τ̂_AR·c is the prewhitened kernel estimate of τ. The recoloured autocorrelation (the AR
part's autocovariance convolved with the kernel-weighted residual autocovariance) keeps
the sieve's short lags and corrects its tail; its τ and Σρ² (which sets the scale test's
variance) are the last columns, with the Kalman filters' exact Σρ² along the same
direction (:func:`kf_truth`). The table gives, for the component of largest τ̂_AR,
medians over the segments, with c's 10 % and 90 % quantiles, beside the family's τ.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import cross_terms  # noqa: E402
import kf_variants  # noqa: E402
import memory as zoo_memory  # noqa: E402
import zoo  # noqa: E402

CASES = (
    ("iid", 300),
    ("ar1-0.5", 300),
    ("ar1-0.9", 2000),
    ("ar2-complex", 300),
    ("arma11", 2000),
    ("slow-white-0.95-0.5", 2000),
    ("kf-cv-10hz", 600),
    ("kf-cv-10hz-q-x10", 198),
    ("kf-cv-100hz", 2000),
    ("kf-ca-10hz", 2000),
    ("kf-rw-10hz", 300),
)


def _kernel(z: np.ndarray, kind: str) -> np.ndarray:
    if kind == "bartlett":
        return 1.0 - z
    return np.where(z <= 0.5, 1.0 - 6.0 * z**2 + 6.0 * z**3, 2.0 * (1.0 - z) ** 3)


def correction(x: np.ndarray, width: float, kind: str) -> tuple[float, ...]:
    """(τ̂_AR, c, τ and Σρ² of the recoloured autocorrelation, the sieve's Σρ²) of one
    series (see the module doc)."""
    from credcli.engine import memory

    x = x - x.mean()
    n = x.size
    fit = memory.burg((x / x.std())[None, None, :], memory.max_order(n))
    p = int(fit.orders(1)[0])
    phi = fit.coefficients(0, p)
    tau = float(np.exp(memory._log_tau(phi, 1.0)))
    u = x[p:] - sum(phi[j] * x[p - 1 - j : n - 1 - j] for j in range(p))
    m = int(min(max(width * tau, 4.0), u.size / 5))
    gamma = np.array([u[: u.size - h] @ u[h:] / u.size for h in range(m)])
    tapered = gamma * _kernel(np.arange(m) / m, kind) / gamma[0]
    c = float(tapered[0] + 2.0 * np.sum(tapered[1:]))
    # recoloured: the AR part's autocovariance convolved with the tapered residual one
    span = memory.decay_horizon(phi, 1)
    lags = 4 * (span + m) + 64
    ar = memory.autocovariance_of_ar(phi, 1.0, span)
    noise = np.zeros(lags)
    noise[:m] = tapered
    both = np.convolve(np.concatenate([noise[:0:-1], noise]), np.concatenate([ar[:0:-1], ar]))
    rho = both[lags + span - 2 : 2 * lags + span - 2]
    rho = rho / rho[0]
    sieve = memory.autocovariance_of_ar(phi, 1.0, lags)
    sieve = sieve / sieve[0]
    return (
        tau,
        c,
        float(1.0 + 2.0 * rho[1:].sum()),
        float(1.0 + 2.0 * np.sum(rho[1:] ** 2)),
        float(1.0 + 2.0 * np.sum(sieve[1:] ** 2)),
    )


def kf_truth(family: str) -> tuple[float, float]:
    """τ and Σρ² of a Kalman family's whitened error along its direction of largest
    long-run variance, exactly (:func:`cross_terms.lagged_covariances`, whose directions
    come in increasing long-run variance)."""
    r = cross_terms.lagged_covariances(family)
    rho = r[:, -1, -1] / r[0, -1, -1]
    return float(1.0 + 2.0 * rho[1:].sum()), float(1.0 + 2.0 * np.sum(rho[1:] ** 2))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--reps", type=int, default=40)
    ap.add_argument("--seed", type=int, default=4)
    ap.add_argument("--width", type=float, default=4.0)
    ap.add_argument("--kernel", choices=("parzen", "bartlett"), default="parzen")
    args = ap.parse_args()
    zoo.KF_MODELS.update(kf_variants.VARIANTS)
    print(
        f"# prewhitened kernel correction: {args.kernel}, M = {args.width:g} τ̂_AR, "
        f"{args.reps} segments, seed {args.seed}"
    )
    print()
    print(
        "| family | N | τ | τ̂_AR | c [10 %, 90 %] | τ̂_AR·c | recoloured τ "
        "| Σρ² sieve, recoloured | Σρ² true |"
    )
    print("|---|---|---|---|---|---|---|---|---|")
    for family, n in CASES:
        rows = []
        for rep in range(args.reps):
            seeds, _ = zoo_memory._seeds(family, n, rep, args.seed)
            case = zoo.make(family, n, np.random.default_rng(seeds), "none")
            white = case.errors @ np.linalg.inv(np.linalg.cholesky(case.cov[0])).T
            pairs = [
                correction(white[:, i], args.width, args.kernel) for i in range(white.shape[1])
            ]
            rows.append(max(pairs))
        tau_ar, c, recoloured, squares, sieve_squares = np.array(rows).T
        true_squares = f"{kf_truth(family)[1]:.3g}" if zoo.kind(family) == "kf" else "–"
        low, high = np.quantile(c, [0.1, 0.9])
        print(
            f"| {family} | {n} | {case.tau:.3g} | {np.median(tau_ar):.3g} | "
            f"{np.median(c):.2f} [{low:.2f}, {high:.2f}] | {np.median(tau_ar * c):.3g} | "
            f"{np.median(recoloured):.3g} | {np.median(sieve_squares):.3g}, "
            f"{np.median(squares):.3g} | {true_squares} |",
            flush=True,
        )


if __name__ == "__main__":
    main()
