"""Generators of the bundled sample data (``make sample-data``).

``estimator_log`` makes a 2-D tracking log with one segment per planted condition:
the error of each epoch is drawn from N(μ, Σ_k) and the claimed covariance is ρ Σ_k, with
Σ_k an ellipse that turns with time (as a filter's covariance would).

The diagnosis is a statistical test, so a given draw can be a false alarm (about 5% per
segment for the ELT). The default seed is one whose six segments all receive their planted
label with the default settings; tests/test_samples.py checks it.
"""

from __future__ import annotations

import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from credcli.studies.pose_samples import write_pose_samples


@dataclass(frozen=True)
class PlantedSegment:
    """One segment of a sample log and the condition planted in it.

    Attributes
    ----------
    name : str
        The segment's name (the log's ``segment`` column).
    rho : float
        Claimed over true covariance scale ρ: below 1 optimism, above 1 pessimism.
    bias : tuple of float
        Mean error μ (2,), in units of the true std (added to the whitened errors, so it
        turns with the covariance's axes); zero for no bias.
    offset : tuple of float, default (0, 0)
        A constant error (2,) in the log's units (m), added to every epoch's error: a
        bias that stays put while the covariance turns.
    """

    name: str
    rho: float  # claimed / true covariance scale
    bias: tuple[float, float]  # mean error μ in units of the true std
    offset: tuple[float, float] = (0.0, 0.0)  # constant error in metres


GOOD_SEGMENTS = (
    PlantedSegment("cruise", 1.0, (0.0, 0.0)),
    PlantedSegment("turn", 0.35, (0.0, 0.0)),
    PlantedSegment("hover", 3.0, (0.0, 0.0)),
    PlantedSegment("gps-multipath", 1.0, (1.2, -0.9)),
    PlantedSegment("tunnel", 4.0, (0.0, 0.0), offset=(6.0, 0.0)),
    PlantedSegment("urban", 0.3, (0.9, -0.8)),
)


REGRESSED_SEGMENTS = (
    PlantedSegment("cruise", 0.4, (0.0, 0.0)),  # credible -> optimism
    GOOD_SEGMENTS[1],
    PlantedSegment("hover", 3.0, (0.0, 0.0), offset=(5.0, 0.0)),  # pessimism -> pessimism+smm
    *GOOD_SEGMENTS[3:],
)
"""The sample log after a change that broke two segments (for `credcli gate`). The random
draws are the same as for GOOD_SEGMENTS, so the other segments are unchanged."""


def estimator_log(
    segments=GOOD_SEGMENTS, epochs_per_segment: int = 300, rate_hz: float = 10.0, seed: int = 1
):
    """A 2-D tracking log with one segment per planted condition, in credcli's default
    log format.

    The truth moves on a circle of radius 50 m at 0.05 rad/s; the true error covariance
    Σ_k has 1-σ axes of 1.5 m and 0.6 m turning with the heading. Each epoch's error is
    e_k = L_k z_k + Σ_k^{1/2} μ + o, L_k L_kᵀ = Σ_k, z_k ~ N(0, I), with o the segment's
    constant offset, and the claimed covariance is ρ Σ_k. The bias μ is the mean of the
    whitened errors Σ_k^{-1/2} e_k (the engine's whitening, which turns with the state's
    frame): L_k μ would be a mean of the Cholesky-whitened errors, whose frame depends on
    the components' order and turns with Σ_k, so that in any other frame its mean would
    vary through the segment. Segments follow each other in time, one epoch interval
    apart.

    Parameters
    ----------
    segments : sequence of PlantedSegment
        The segments, in order (default ``GOOD_SEGMENTS``).
    epochs_per_segment : int
        Epochs in each segment (default 300).
    rate_hz : float
        Epoch rate in Hz (default 10).
    seed : int
        Seed of the errors (default 1: every segment of ``GOOD_SEGMENTS`` gets its
        planted label).

    Returns
    -------
    pandas.DataFrame
        Columns time (s, rounded to the ms), segment, truth_0, truth_1, est_0, est_1 and
        the claimed covariance's upper triangle cov_0_0, cov_0_1, cov_1_1; one row per
        epoch.

    Examples
    --------
    >>> log = estimator_log(GOOD_SEGMENTS[:2], epochs_per_segment=3)
    >>> list(log.columns)
    ['time', 'segment', 'truth_0', 'truth_1', 'est_0', 'est_1', 'cov_0_0', 'cov_0_1', 'cov_1_1']
    >>> log["time"].tolist(), log["segment"].unique().tolist()
    ([0.0, 0.1, 0.2, 0.3, 0.4, 0.5], ['cruise', 'turn'])
    """
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
        root = rot @ np.diag(sig) @ np.swapaxes(rot, 1, 2)  # Σ_k^{1/2}
        white = rng.standard_normal((n, 2))
        error = np.einsum("nij,nj->ni", chol, white) + seg.offset
        error += np.einsum("nij,j->ni", root, np.asarray(seg.bias))
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


ERRORS_SEGMENTS = (GOOD_SEGMENTS[0], GOOD_SEGMENTS[1])
"""The errors-only sample's segments: an honest covariance, then one 0.35 times too small."""


def errors_log(segments=ERRORS_SEGMENTS, epochs_per_segment: int = 100, seed: int = 2):
    """The errors-only layout (``--errors-only``): time, segment, the errors ``err_i``
    (e = x - x̂) and the claimed covariance, as a filter library that knows its own errors
    would write them; the draws of ``estimator_log``, without truth or estimate.

    Parameters
    ----------
    segments : sequence of PlantedSegment
        The segments, in order (default ``ERRORS_SEGMENTS``).
    epochs_per_segment : int
        Epochs in each segment (default 100).
    seed : int
        Seed of the errors, as for :func:`estimator_log` (default 2).

    Returns
    -------
    pandas.DataFrame
        Columns time, segment, err_0, err_1, cov_0_0, cov_0_1, cov_1_1; one row per epoch
        (10 Hz).
    """
    log = estimator_log(segments, epochs_per_segment, seed=seed)
    errors = log[["truth_0", "truth_1"]].to_numpy() - log[["est_0", "est_1"]].to_numpy()
    frame = log[["time", "segment"]].copy()
    frame["err_0"], frame["err_1"] = errors[:, 0], errors[:, 1]
    return frame.join(log[["cov_0_0", "cov_0_1", "cov_1_1"]])


def write_samples(outdir: Path) -> list[Path]:
    """Write every sample file into ``outdir``; return their paths.

    The files are estimator_log.csv and .parquet, estimator_log_regressed.csv (for
    ``credcli gate``), errors_only.csv, starloc_grid_uwb.csv and, under ``formats/``, the
    pose-format samples of :func:`credcli.studies.pose_samples.write_pose_samples`.

    Parameters
    ----------
    outdir : pathlib.Path
        The directory to write into (created with its parents if missing; files in it
        are overwritten).

    Returns
    -------
    list of pathlib.Path
        The files written (the ROS2 bag as its directory), in the order written.
    """
    outdir.mkdir(parents=True, exist_ok=True)
    log = estimator_log()
    written = [outdir / "estimator_log.csv", outdir / "estimator_log.parquet"]
    log.to_csv(written[0], index=False)
    log.to_parquet(written[1], index=False)
    written.append(outdir / "estimator_log_regressed.csv")
    estimator_log(REGRESSED_SEGMENTS).to_csv(written[-1], index=False)
    written.append(outdir / "errors_only.csv")
    errors_log().to_csv(written[-1], index=False)
    written.append(outdir / "starloc_grid_uwb.csv")
    starloc_log().to_csv(written[-1], index=False)

    written.extend(write_pose_samples(outdir / "formats"))
    return written


def main(argv: list[str] | None = None) -> int:
    """Entry point of ``python -m credcli.studies.samples [OUTDIR]`` (``make sample-data``).

    Writes the samples with :func:`write_samples` and prints one ``wrote PATH`` line per
    file.

    Parameters
    ----------
    argv : list of str, optional
        The arguments; the first, if any, is the output directory (default
        ``sample_data``). ``sys.argv[1:]`` when None.

    Returns
    -------
    int
        The exit status, 0.
    """
    argv = sys.argv[1:] if argv is None else argv
    outdir = Path(argv[0] if argv else "sample_data")
    for path in write_samples(outdir):
        print(f"wrote {path}")
    return 0


STARLOC_ANCHORS = {  # id: (x, y, z) in m, a layout like STAR-loc's eight anchors
    4: (-3.06, -3.05, 2.01),
    5: (0.20, -0.89, 2.84),
    6: (3.00, 2.96, 0.94),
    7: (-2.97, 3.08, 0.82),
    9: (2.99, -3.00, 2.07),
    10: (-3.06, 0.00, 1.22),
    11: (-3.03, 3.04, 2.07),
    12: (2.99, 2.98, 2.20),
}


def starloc_log(
    seed: int = 3,
    stops=((-1.5, -1.0), (0.0, -1.0), (1.5, -1.0), (1.5, 1.0), (0.0, 1.0), (-1.5, 1.0)),
    dwell_s: float = 6.0,
    speed: float = 0.4,
    rate_hz: float = 220.0,
    noise_std: float = 0.04,
    std_factor: float = 2.0,
    antenna_offset: tuple[float, float] = (0.15, -0.10),
    bias_range: tuple[float, float] = (0.0, 0.03),
):
    """A synthetic STAR-loc ``uwb.csv``: a grid trajectory with static stops, two tags on the
    rig, eight anchors ranged in turn at ``rate_hz`` (alternating tags), range biases per
    anchor, true range noise ``noise_std`` and a reported std ``std_factor`` times larger.

    The range bias of an anchor has two parts: the projection on the line of sight of a
    horizontal ``antenna_offset`` between the UWB antenna and the tracked tag position (so
    it differs per anchor and per stop, and shifts every fix the same way: SMM), and a small
    fixed bias per anchor drawn from ``bias_range``. The diagnosis of every stop should be
    pessimism+smm, as Table IV for the real grid_s3 run.

    Parameters
    ----------
    seed : int
        Seed of the time jitter, the biases and the noise (default 3).
    stops : sequence of (float, float)
        The rig's static stops (x, y) in m, visited in order along straight lines
        (default: a 3 × 2 grid).
    dwell_s : float
        Time at each stop in s (default 6).
    speed : float
        The rig's speed between stops in m/s (default 0.4).
    rate_hz : float
        Range rows per second, over both tags (default 220).
    noise_std : float
        True std of the range noise in m (default 0.04).
    std_factor : float
        Reported std over ``noise_std`` (each row's ``std`` is that times U[0.9, 1.1])
        (default 2: pessimism).
    antenna_offset : tuple of float
        Horizontal offset (x, y) in m of the UWB antenna from the tracked tag position
        (default (0.15, −0.10)).
    bias_range : tuple of float
        Range (lo, hi) in m of the uniform fixed bias of each anchor (default (0, 0.03)).

    Returns
    -------
    pandas.DataFrame
        The STAR-loc columns (time_s, range, from_id (tag), to_id (anchor), the rig pose
        x … rot_z, tag_pos_*, bias, gt_range, range_calib, bias_calib, std), rounded to
        6 decimals; ``range`` carries a further 0.08 m offset and 1 cm of noise that
        ``range_calib`` does not. Anchor positions are ``STARLOC_ANCHORS``.
    """
    import pandas as pd

    rng = np.random.default_rng(seed)
    # rig trajectory: dwell at each stop, move in a straight line between stops
    legs, t = [], 0.0
    for k, stop in enumerate(stops):
        legs.append((t, t + dwell_s, np.array(stop), np.array(stop)))
        t += dwell_s
        if k + 1 < len(stops):
            nxt = np.array(stops[k + 1])
            dur = float(np.linalg.norm(nxt - np.array(stop)) / speed)
            legs.append((t, t + dur, np.array(stop), nxt))
            t += dur
    n = int(t * rate_hz)
    time = np.sort(np.arange(n) / rate_hz + rng.uniform(-2e-4, 2e-4, n))
    time -= time[0]
    rig = np.zeros((n, 3))
    for t0, t1, p0, p1 in legs:
        sel = (time >= t0) & (time < t1) if t1 < t else (time >= t0)
        frac = ((time[sel] - t0) / (t1 - t0))[:, None]
        rig[sel, :2] = p0 + frac * (p1 - p0)
    rig[:, 2] = 1.0 + 0.02 * np.sin(0.3 * time)
    tag = np.where(np.arange(n) % 2 == 0, 1, 2)
    offsets = {1: np.array([0.2, 0.1, 0.0]), 2: np.array([-0.2, -0.1, 0.05])}
    tag_pos = rig + np.stack([offsets[k] for k in tag])
    ids = np.array(sorted(STARLOC_ANCHORS))
    anchor = ids[(np.arange(n) // 2) % ids.size]
    anchor_pos = np.array([STARLOC_ANCHORS[a] for a in anchor])
    gt_range = np.linalg.norm(tag_pos - anchor_pos, axis=1)
    antenna = tag_pos + np.r_[antenna_offset, 0.0]
    geometric = np.linalg.norm(antenna - anchor_pos, axis=1) - gt_range
    anchor_bias = dict(zip(ids, rng.uniform(*bias_range, ids.size)))
    bias_calib = (
        geometric + np.array([anchor_bias[a] for a in anchor]) + noise_std * rng.standard_normal(n)
    )
    range_calib = gt_range + bias_calib
    raw = range_calib + 0.08 + 0.01 * rng.standard_normal(n)
    reported = std_factor * noise_std * rng.uniform(0.9, 1.1, n)
    frame = pd.DataFrame(
        {
            "time_s": time,
            "range": raw,
            "from_id": tag,
            "to_id": anchor,
            "x": rig[:, 0],
            "y": rig[:, 1],
            "z": rig[:, 2],
            "w": 1.0,
            "rot_x": 0.0,
            "rot_y": 0.0,
            "rot_z": 0.0,
            "tag_pos_x": tag_pos[:, 0],
            "tag_pos_y": tag_pos[:, 1],
            "tag_pos_z": tag_pos[:, 2],
            "bias": raw - gt_range,
            "gt_range": gt_range,
            "range_calib": range_calib,
            "bias_calib": bias_calib,
            "std": reported,
        }
    )
    return frame.round(6)


if __name__ == "__main__":
    sys.exit(main())
