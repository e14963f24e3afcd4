"""Pairing an estimate with a separately recorded ground truth by time.

The truth is interpolated to each estimate stamp t (after adding ``time_offset``) from the
truth samples just before and just after t (``pandas.merge_asof``, backward and forward):
linearly for positions and by SLERP (scipy's ``Slerp``) for orientations, and only when
those two samples are at most ``max_dt`` apart (default 2.5 × the median truth period).
An estimate stamp equal to a truth stamp takes that sample. Estimate epochs outside the
truth's span or across a longer gap are dropped, and counted.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from credcli.errors import CredcliError
from credcli.io.trajectory import Trajectory

MAX_DT_FACTOR = 2.5


@dataclass(frozen=True)
class Pairing:
    """Which estimate epochs have truth, and the truth interpolated to them.

    Attributes
    ----------
    keep : numpy.ndarray of bool, shape (N_est,)
        Whether each estimate epoch has truth (n of them do).
    position : numpy.ndarray, shape (n, k)
        The truth's positions (or vectors) at the kept estimate stamps.
    rotation : scipy.spatial.transform.Rotation or None
        The truth's orientations at the kept stamps (n of them); None for a truth without
        orientations.
    max_dt : float
        The widest gap (s) allowed between the two truth samples an epoch is
        interpolated from: as given, or 2.5 × the median truth period.
    dropped : int
        The estimate epochs without truth.
    note : str
        The note that says how many epochs were paired, how, and how many dropped.
    """

    keep: np.ndarray  # (N_est,) bool
    position: np.ndarray  # (n, k) truth at the kept estimate stamps
    rotation: object | None  # scipy Rotation (n) or None
    max_dt: float
    dropped: int
    note: str


def pair(estimate: Trajectory, truth: Trajectory, max_dt: float | None, time_offset: float):
    """Interpolate ``truth`` to the (offset) estimate stamps; see the module docstring.

    Parameters
    ----------
    estimate : Trajectory
        The estimate, sorted by time.
    truth : Trajectory
        The truth, sorted by time, with distinct stamps.
    max_dt : float or None
        The widest gap (s) between the truth samples around an estimate stamp; None:
        ``MAX_DT_FACTOR`` (2.5) × the median truth period.
    time_offset : float
        Seconds added to the estimate stamps before pairing.

    Returns
    -------
    Pairing
        The kept epochs, the truth at them, and the note.

    Raises
    ------
    CredcliError
        If the truth has fewer than two epochs, the two sets of stamps do not overlap, or
        no estimate epoch has truth samples within ``max_dt`` on both sides.

    Examples
    --------
    >>> from credcli.io.schema import InputFormat
    >>> def track(t, x):
    ...     t, rows = np.asarray(t, float), np.arange(1, len(t) + 1)
    ...     return Trajectory(t, np.c_[x], None, None, rows, "t", InputFormat.CREDCLI)
    >>> p = pair(track([0.5, 1.5, 9.0], [0, 0, 0]), track([0, 1, 2], [0, 10, 20]), None, 0.0)
    >>> p.keep.tolist(), p.position[:, 0].tolist(), p.dropped
    ([True, True, False], [5.0, 15.0], 1)
    """
    import pandas as pd

    t_est = estimate.time + float(time_offset)
    t_true = truth.time
    if t_true.size < 2:
        raise CredcliError(f"{truth.source}: the truth has {t_true.size} epoch(s); need at least 2")
    period = float(np.median(np.diff(t_true)))
    if max_dt is None:
        max_dt = MAX_DT_FACTOR * period
        chosen = f"`max_dt` {max_dt:.6g} s (2.5 × the median truth period {period:.6g} s)"
    else:
        chosen = f"`max_dt` {max_dt:.6g} s"
    lo, hi = float(t_true[0]), float(t_true[-1])
    if t_est[-1] < lo or t_est[0] > hi:
        raise CredcliError(
            f"{estimate.source}: its stamps ({_span(t_est)}) do not overlap the truth's "
            f"({_span(t_true)} in {truth.source}); check `time_offset` and `time_unit`"
        )
    left = pd.DataFrame({"t": t_est, "k": np.arange(t_est.size)})
    right = pd.DataFrame({"t": t_true, "i": np.arange(t_true.size, dtype=float)})
    before = pd.merge_asof(left, right, on="t", direction="backward")["i"].to_numpy()
    after = pd.merge_asof(left, right, on="t", direction="forward")["i"].to_numpy()
    have = np.isfinite(before) & np.isfinite(after)
    i0 = np.where(have, before, 0).astype(np.int64)
    i1 = np.where(have, after, 0).astype(np.int64)
    exact = have & (i0 == i1)
    gap = t_true[i1] - t_true[i0]
    keep = exact | (have & (gap <= max_dt))
    dropped = int(t_est.size - keep.sum())
    if not keep.any():
        raise CredcliError(
            f"{estimate.source}: no estimate epoch has truth samples within `max_dt` "
            f"{max_dt:.6g} s on both sides (the truth period is {period:.6g} s); "
            "raise `max_dt`, or check `time_offset` and `time_unit`"
        )
    i0, i1 = i0[keep], i1[keep]
    span = t_true[i1] - t_true[i0]
    w = np.divide(t_est[keep] - t_true[i0], span, out=np.zeros(i0.size), where=span > 0)
    position = truth.position[i0] + w[:, None] * (truth.position[i1] - truth.position[i0])
    rotation = None
    if truth.quaternion is not None:
        from scipy.spatial.transform import Rotation, Slerp

        # only the truth samples that bracket a kept stamp: consecutive in the truth, they
        # stay consecutive in this subset, so the interpolation is the same
        used = np.union1d(i0, i1)
        if used.size == 1:  # every stamp on the same truth sample
            rotation = Rotation.from_quat(truth.quaternion[i0])
        else:
            slerp = Slerp(t_true[used], Rotation.from_quat(truth.quaternion[used]))
            rotation = slerp(np.clip(t_est[keep], t_true[used[0]], t_true[used[-1]]))
    note = (
        f"paired {int(keep.sum())} of {t_est.size} estimate epochs with truth from "
        f"{truth.source} (linear/SLERP interpolation, {chosen}"
        + (f", `time_offset` {time_offset:g} s" if time_offset else "")
        + f"); {dropped} without truth dropped"
    )
    return Pairing(keep, position, rotation, float(max_dt), dropped, note)


def _span(t: np.ndarray) -> str:
    """The first and last stamps, to the microsecond where they are of a clock's size (a
    stamp shifted by 1e300 s is written in 15 digits, not 300)."""
    return f"{_stamp(t[0])} … {_stamp(t[-1])} s"


def _stamp(value: float) -> str:
    return f"{value:.6f}" if abs(value) < 1e12 else f"{value:.15g}"
