"""What the scale test's per-direction model leaves out: the lagged cross-covariances between
principal directions, exactly, for the zoo's Kalman filters.

    python benchmarks/cross_terms.py

For Gaussian errors the variance of the centred sum of squares T = Σ_k ‖x_k‖² of N
whitened epochs is about 2N Σ_h tr(R(h) R(h)ᵀ), R(h) the lag-h covariance of x_k. The
memory model (``credcli.engine.memory``) fits one series per principal direction (the
directions in which R(0) = I and the long-run covariance are both diagonal) and its scale
test adds the directions' variances, 2N Σ_h Σ_i R_ii(h)², as if the directions were
independent at every lag. The table gives both sums, from the filters' exact error
recursion R(h) = W C Aʰ P Cᵀ Wᵀ, and their ratio: the factor by which the test's variance
is too small (its interval too narrow) when the scale test reads the directions alone.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import kf_variants  # noqa: E402
import zoo  # noqa: E402


def lagged_covariances(family: str, lags: int = 20_000) -> np.ndarray:
    """R(0) … R(lags − 1) of a Kalman family's whitened errors (W the claimed
    covariance's inverse Cholesky factor), rotated to its principal directions."""
    kf = zoo.filter_of(family)
    w = np.linalg.inv(np.linalg.cholesky(kf.claimed))
    left, power = w @ kf.C, kf.P_true @ kf.C.T @ w.T
    out = np.empty((lags, kf.C.shape[0], kf.C.shape[0]))
    for h in range(lags):
        out[h] = left @ power
        power = kf.A @ power
    long_run = out[0] + out[1:].sum(axis=0) + out[1:].sum(axis=0).T
    # R(0) = P_true's block in claimed units, which is I for a right-tuned filter
    _, vectors = np.linalg.eigh(np.linalg.solve(out[0], (long_run + long_run.T) / 2))
    return np.einsum("ai,hab,bj->hij", vectors, out, vectors)


def main() -> None:
    zoo.KF_MODELS.update(kf_variants.VARIANTS)
    print("# the centred sum of squares' variance: per-direction against full (exact)")
    print()
    print("| family | τ | Σ_h Σ_i R_ii(h)² | Σ_h tr R(h)R(h)ᵀ | ratio |")
    print("|---|---|---|---|---|")
    for family in zoo.KF_MODELS:  # the zoo's filters and, added above, the variants
        r = lagged_covariances(family)
        diagonal = np.einsum("hii->hi", r) ** 2
        per_direction = float(diagonal[0].sum() + 2.0 * diagonal[1:].sum())
        full = float(np.sum(r[0] ** 2) + 2.0 * np.sum(r[1:] ** 2))
        tau = zoo.filter_of(family).tau
        print(
            f"| {family} | {tau:.3g} | {per_direction:.3g} | {full:.3g} | {full / per_direction:.3f} |"
        )


if __name__ == "__main__":
    main()
