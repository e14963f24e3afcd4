"""Stone Soup: a ``Track`` with its ``GroundTruthPath``, or a tracker's tracks with the truth.

A Stone Soup track is a sequence of Gaussian states (``state_vector`` (n, 1), ``covar``
(n, n), ``timestamp`` a ``datetime``), and so is a ground-truth path, without ``covar``.
credcli pairs the states by timestamp: exactly by default (Stone Soup's simulators stamp the
detections, and so the updates, with the truth's times), or to the nearest truth state within
``tolerance``; it does not interpolate. Times become seconds since 1970 UTC (Stone Soup's
naive ``datetime`` taken as UTC). ``states`` picks the components to diagnose, e.g. (0, 2)
for the positions of a 2-D constant-velocity state (x, vx, y, vy).
"""

from __future__ import annotations

import datetime as _dt
from collections.abc import Iterable, Sequence

import numpy as np

from credcli.errors import CredcliError
from credcli.io.arrays import log_from_arrays
from credcli.io.logs import EstimatorLog


def _path_arrays(path, what: str, covariances: bool):
    """(timestamps as datetime64[ns], vectors (N, n), covariances (N, n, n) or None)."""
    states = list(path)
    if not states:
        raise CredcliError(f"{what}: has no states")
    try:
        stamps = np.array([np.datetime64(s.timestamp, "ns") for s in states])
        vectors = np.stack([np.asarray(s.state_vector, dtype=float).ravel() for s in states])
        covs = np.stack([np.asarray(s.covar, dtype=float) for s in states]) if covariances else None
    except (AttributeError, TypeError, ValueError) as exc:
        raise CredcliError(
            f"{what}: expected Stone Soup states with state_vector"
            + (", covar" if covariances else "")
            + f" and timestamp; {exc}"
        ) from None
    return stamps, vectors, covs


def _pairs(track_stamps, truth_stamps, tolerance) -> tuple[np.ndarray, np.ndarray]:
    """Indices (track, truth) of the paired states: equal stamps, or the nearest truth stamp
    within ``tolerance``."""
    order = np.argsort(truth_stamps, kind="stable")
    sorted_truth = truth_stamps[order]
    right = np.clip(np.searchsorted(sorted_truth, track_stamps), 0, len(sorted_truth) - 1)
    left = np.clip(right - 1, 0, len(sorted_truth) - 1)
    gap_right = np.abs(sorted_truth[right] - track_stamps)
    gap_left = np.abs(sorted_truth[left] - track_stamps)
    nearest = np.where(gap_left <= gap_right, left, right)
    gap = np.minimum(gap_left, gap_right)
    limit = np.timedelta64(0, "ns") if tolerance is None else np.timedelta64(tolerance, "ns")
    keep = gap <= limit
    return np.flatnonzero(keep), order[nearest[keep]]


def _selected(index, n: int) -> np.ndarray:
    index = np.arange(n) if index is None else np.asarray(index, dtype=int)
    if index.ndim != 1 or index.size == 0 or index.min() < 0 or index.max() >= n:
        raise CredcliError(f"states: indices into a state of {n} components; got {list(index)}")
    return index


def log_from_track(
    track,
    truth,
    *,
    states: Sequence[int] | None = None,
    tolerance: _dt.timedelta | None = None,
    source: str = "Stone Soup track",
) -> EstimatorLog:
    """A log of one track's states against its ground-truth path, paired by timestamp.

    Pairs exactly by default, or each track state with the nearest truth state within
    ``tolerance``; track states without a truth state are left out. Times become seconds
    since 1970 UTC.

    Parameters
    ----------
    track : stonesoup.types.track.Track
        Gaussian states (``state_vector``, ``covar``, ``timestamp``).
    truth : stonesoup.types.groundtruth.GroundTruthPath
        The true states (``state_vector``, ``timestamp``).
    states : sequence of int, optional
        The components to diagnose, e.g. (0, 2) for the positions of a 2-D
        constant-velocity state (x, vx, y, vy); all by default.
    tolerance : datetime.timedelta, optional
        Pair with the nearest truth state within this; None: equal timestamps only.
    source : str
        The log's name in messages and records.

    Returns
    -------
    EstimatorLog
        The paired states, with time.

    Raises
    ------
    CredcliError
        If the track or the path has no states, a state lacks ``state_vector``,
        ``covar`` (track) or ``timestamp``, the two differ in their number of components,
        ``states`` are not indices into the state, or no track state has a truth state
        at its timestamp (within ``tolerance``).

    Examples
    --------
    >>> import datetime, numpy as np
    >>> from stonesoup.types.groundtruth import GroundTruthPath, GroundTruthState
    >>> from stonesoup.types.state import GaussianState
    >>> from stonesoup.types.track import Track
    >>> t0 = datetime.datetime(2024, 5, 1)
    >>> times = [t0 + datetime.timedelta(seconds=k) for k in range(20)]
    >>> truth = GroundTruthPath([GroundTruthState([k, 1.0], timestamp=t) for k, t in enumerate(times)])
    >>> track = Track([GaussianState([k + 0.1, 1.0], np.eye(2), timestamp=t) for k, t in enumerate(times)])
    >>> log = log_from_track(track, truth, states=[0])
    >>> log.n, log.dim, float(log.errors[0, 0])
    (20, 1, -0.1)
    """
    t_track, estimate, covs = _path_arrays(track, "track", True)
    t_truth, true, _ = _path_arrays(truth, "truth", False)
    if true.shape[1] != estimate.shape[1]:
        raise CredcliError(
            f"truth: {true.shape[1]} state components, the track has {estimate.shape[1]}"
        )
    index = _selected(states, estimate.shape[1])
    i, j = _pairs(t_track, t_truth, tolerance)
    if i.size == 0:
        within = "" if tolerance is None else f" within {tolerance}"
        raise CredcliError(
            f"{source}: no track state has a ground-truth state at its timestamp{within}; "
            "pass tolerance= to pair with the nearest truth state"
        )
    return log_from_arrays(
        true[j][:, index],
        estimate[i][:, index],
        covs[i][:, index[:, None], index[None, :]],
        time=t_track[i],
        source=source,
    )


def _track_order(track) -> tuple:
    """Tracks in the order of their first timestamp, then length, then first state: a set
    of tracks (as trackers give them) has no order, and a track's id is random."""
    first = min(track, key=lambda s: s.timestamp)
    vector = tuple(np.asarray(first.state_vector, dtype=float).ravel())
    return (first.timestamp, -len(track), vector)


def log_from_tracks(
    tracks: Iterable,
    truths: Iterable,
    *,
    states: Sequence[int] | None = None,
    tolerance: _dt.timedelta | None = None,
    source: str = "Stone Soup tracks",
) -> EstimatorLog:
    """A log of a tracker's tracks, one segment per track, each paired with the ground-truth
    path it follows.

    The segments are ``track 1``, ``track 2``, … in the order of their first timestamps,
    then the longer first. Each track is paired with the path nearest to it (the mean
    distance over ``states`` at their common timestamps), state by state as in
    [log_from_track][credcli.adapters.stonesoup.log_from_track]. Tracks that share no
    timestamp with a path of as many components (or have no states) are left out. A
    tracker without data association ambiguity (a single-target or well-separated
    scenario) is what this pairing assumes; it does not solve assignment between crossing
    targets.

    Parameters
    ----------
    tracks : iterable of stonesoup.types.track.Track
        The tracker's tracks (a set, as trackers give them).
    truths : iterable of stonesoup.types.groundtruth.GroundTruthPath
        The ground-truth paths.
    states : sequence of int, optional
        The components to diagnose; all by default.
    tolerance : datetime.timedelta, optional
        As for [log_from_track][credcli.adapters.stonesoup.log_from_track].
    source : str
        The log's name in messages and records.

    Returns
    -------
    EstimatorLog
        The paired states of every track kept, one segment per track, with time.

    Raises
    ------
    CredcliError
        If there is no ground-truth path, no track shares a timestamp with a path, a
        state lacks what [log_from_track][credcli.adapters.stonesoup.log_from_track]
        reads, or ``states`` are not indices into the state.

    Examples
    --------
    >>> import datetime, numpy as np
    >>> from stonesoup.types.groundtruth import GroundTruthPath, GroundTruthState
    >>> from stonesoup.types.state import GaussianState
    >>> from stonesoup.types.track import Track
    >>> t0 = datetime.datetime(2024, 5, 1)
    >>> times = [t0 + datetime.timedelta(seconds=k) for k in range(10)]
    >>> def path(x0):
    ...     return GroundTruthPath([GroundTruthState([x0 + k, 1.0], timestamp=t)
    ...                             for k, t in enumerate(times)])
    >>> def track(x0):
    ...     return Track([GaussianState([x0 + k + 0.1, 1.0], np.eye(2), timestamp=t)
    ...                   for k, t in enumerate(times)])
    >>> log = log_from_tracks({track(100.0), track(0.0)}, [path(0.0), path(100.0)], states=[0])
    >>> log.n, sorted(set(log.segment)), np.unique(np.round(log.errors[:, 0], 3)).tolist()
    (20, ['track 1', 'track 2'], [-0.1])
    """
    track_list = sorted((t for t in tracks if len(t)), key=_track_order)

    paths = [_path_arrays(p, "truth", False) for p in truths]
    if not paths:
        raise CredcliError("truths: no ground-truth paths")
    parts = []
    for number, track in enumerate(track_list, start=1):
        t_track, estimate, covs = _path_arrays(track, f"track {number}", True)
        index = _selected(states, estimate.shape[1])
        best = None
        for t_truth, true, _ in paths:
            if true.shape[1] != estimate.shape[1]:
                continue
            i, j = _pairs(t_track, t_truth, tolerance)
            if i.size == 0:
                continue
            gap = np.linalg.norm(estimate[i][:, index] - true[j][:, index], axis=1).mean()
            if best is None or gap < best[0]:
                best = (gap, i, j, true)
        if best is None:
            continue
        _, i, j, true = best
        parts.append((f"track {number}", t_track[i], true[j], estimate[i], covs[i]))
    if not parts:
        raise CredcliError(f"{source}: no track shares a timestamp with a ground-truth path")
    index = _selected(states, parts[0][3].shape[1])
    cat = np.concatenate
    return log_from_arrays(
        cat([p[2] for p in parts])[:, index],
        cat([p[3] for p in parts])[:, index],
        cat([p[4] for p in parts])[:, index[:, None], index[None, :]],
        time=cat([p[1] for p in parts]),
        segment=cat([[p[0]] * len(p[1]) for p in parts]),
        source=source,
    )
