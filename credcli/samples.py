"""Generators of the bundled sample data (``make sample-data``).

``estimator_log`` makes a 2-D tracking log with one segment per planted condition:
the error of each epoch is drawn from N(μ, Σ_k) and the claimed covariance is ρ Σ_k, with
Σ_k an ellipse that turns with time (as a filter's covariance would).

The diagnosis is a statistical test, so a given draw can be a false alarm (about 5% per
segment for the ELT). The default seed is one whose six segments all receive their planted
label with the default settings (31 of the seeds 0–39 do); tests/test_samples.py checks it.
"""

from __future__ import annotations

import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np


@dataclass(frozen=True)
class PlantedSegment:
    name: str
    rho: float  # claimed / true covariance scale
    bias: tuple[float, float]  # mean error μ in units of the true std


GOOD_SEGMENTS = (
    PlantedSegment("cruise", 1.0, (0.0, 0.0)),
    PlantedSegment("turn", 0.35, (0.0, 0.0)),
    PlantedSegment("hover", 3.0, (0.0, 0.0)),
    PlantedSegment("gps-multipath", 1.0, (1.2, -0.9)),
    PlantedSegment("tunnel", 4.0, (1.0, 1.0)),
    PlantedSegment("urban", 0.3, (0.9, -0.8)),
)


def estimator_log(
    segments=GOOD_SEGMENTS, epochs_per_segment: int = 300, rate_hz: float = 10.0, seed: int = 1
):
    """A pandas DataFrame in credcli's default log format (time, segment, truth_*, est_*,
    cov_i_j upper triangle)."""
    import pandas as pd

    rng = np.random.default_rng(seed)
    frames = []
    t0 = 0.0
    for seg in segments:
        n = epochs_per_segment
        t = t0 + np.arange(n) / rate_hz
        angle = 0.05 * t
        truth = np.c_[50.0 * np.cos(angle), 50.0 * np.sin(angle)]
        sig = np.array([1.5, 0.6])  # true 1-σ along and across track (m)
        c, s = np.cos(angle), np.sin(angle)
        rot = np.stack([np.c_[c, -s], np.c_[s, c]], axis=1)  # (n, 2, 2)
        true_cov = rot @ np.diag(sig**2) @ np.swapaxes(rot, 1, 2)
        chol = np.linalg.cholesky(true_cov)
        white = rng.standard_normal((n, 2))
        error = np.einsum("nij,nj->ni", chol, white + np.asarray(seg.bias))
        estimate = truth - error  # e = x - x̂
        claimed = seg.rho * true_cov
        frames.append(
            pd.DataFrame(
                {
                    "time": np.round(t, 3),
                    "segment": seg.name,
                    "truth_0": truth[:, 0],
                    "truth_1": truth[:, 1],
                    "est_0": estimate[:, 0],
                    "est_1": estimate[:, 1],
                    "cov_0_0": claimed[:, 0, 0],
                    "cov_0_1": claimed[:, 0, 1],
                    "cov_1_1": claimed[:, 1, 1],
                }
            )
        )
        t0 = t[-1] + 1.0 / rate_hz
    return pd.concat(frames, ignore_index=True)


def write_samples(outdir: Path) -> list[Path]:
    """Write every sample file into ``outdir``; return their paths."""
    outdir.mkdir(parents=True, exist_ok=True)
    log = estimator_log()
    written = [outdir / "estimator_log.csv", outdir / "estimator_log.parquet"]
    log.to_csv(written[0], index=False)
    log.to_parquet(written[1], index=False)
    return written


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    outdir = Path(argv[0] if argv else "sample_data")
    for path in write_samples(outdir):
        print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
