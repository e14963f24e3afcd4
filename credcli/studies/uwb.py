"""The UWB pipeline of Section V on STAR-loc ``uwb.csv`` logs.

file -> RangeLog -> anchors (markers file or self-calibration) -> packets of near-simultaneous
ranges -> 2-D WLS fixes with claimed covariance (HᵀWH)⁻¹ -> EstimatorLog -> segments
(static periods, windows or whole) -> diagnosis per segment, plus range-level statistics.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from credcli import segments as seg
from credcli.engine.config import Label, Question
from credcli.errors import CredcliError
from credcli.io.logs import EstimatorLog
from credcli.io.starloc import RangeLog, read_markers, read_starloc  # noqa: F401 (re-exported)
from credcli.logid import LogId
from credcli.studies.settings import (
    RobustLoss,
    UwbSettings,  # noqa: F401 (re-exported)
)


@dataclass(frozen=True)
class Anchor:
    """An anchor's position and where it came from.

    Attributes
    ----------
    id : int
        The anchor's id in the log (``to_id``).
    position : numpy.ndarray, shape (3,)
        Its position (m).
    source : str
        "markers" (from a markers file) or "self-calibrated" (fitted to the log).
    rms : float
        RMS of ‖tag_pos − a‖ − gt_range over the anchor's rows (m).
    n : int
        Rows of this anchor in the log.
    """

    id: int
    position: np.ndarray  # (3,)
    source: str  # "markers" or "self-calibrated"
    rms: float  # RMS of ‖tag_pos − a‖ − gt_range over the anchor's rows (m)
    n: int  # rows of this anchor

    def disagrees(self, limit: float) -> bool:
        """Whether this is a markers position whose distances to the ground-truth tag
        positions disagree with the log's gt_range by more than ``limit`` (m) RMS.

        Parameters
        ----------
        limit : float
            The largest RMS disagreement accepted (m).

        Returns
        -------
        bool
            True for a markers anchor with ``rms`` above ``limit``; always False for a
            self-calibrated one.
        """
        return self.source == "markers" and self.rms > limit


def _residual_rms(points: np.ndarray, ranges: np.ndarray, a: np.ndarray) -> float:
    return float(np.sqrt(np.mean((np.linalg.norm(points - a, axis=1) - ranges) ** 2)))


def _fit_anchor(points: np.ndarray, ranges: np.ndarray, start: np.ndarray) -> np.ndarray:
    """Levenberg–Marquardt for min_a Σ(‖p_k − a‖ − r_k)² from ``start``."""
    a = start.astype(float).copy()
    lam = 1e-3
    cost = np.sum((np.linalg.norm(points - a, axis=1) - ranges) ** 2)
    for _ in range(100):
        diff = a - points
        dist = np.linalg.norm(diff, axis=1)
        jac = diff / np.maximum(dist, 1e-12)[:, None]
        res = ranges - dist
        normal = jac.T @ jac
        grad = jac.T @ res
        step = np.linalg.solve(normal + lam * np.diag(np.diag(normal) + 1e-12), grad)
        trial = a + step
        new_cost = np.sum((np.linalg.norm(points - trial, axis=1) - ranges) ** 2)
        if new_cost < cost:
            a, cost, lam = trial, new_cost, lam * 0.3
            if np.linalg.norm(step) < 1e-10:
                break
        else:
            lam *= 10
            if lam > 1e10:
                break
    return a


def calibrate_anchors(ranges: RangeLog) -> list[Anchor]:
    """Anchor positions from the file's own ground truth: per anchor, least squares of
    ‖tag_pos − a‖ = gt_range over its rows.

    For a nearly planar tag trajectory the height is ambiguous up to a mirror about the
    tag plane, so the fit starts from the linearised solution and from heights above and
    below the tags, and keeps the smallest residual.

    Parameters
    ----------
    ranges : RangeLog
        The log, with ground-truth tag positions and ranges.

    Returns
    -------
    list of Anchor
        One self-calibrated anchor per anchor id of the log, in id order.

    Notes
    -----
    Each start is refined by Levenberg–Marquardt on
    min_a Σ_k (‖p_k − a‖ − r_k)²; the linearised start solves 2 p_kᵀa − ‖a‖² = ‖p_k‖² − r_k²
    by least squares in (a, ‖a‖²).
    """
    anchors = []
    for anchor_id in np.unique(ranges.anchor):
        rows = ranges.anchor == anchor_id
        pts, r = ranges.tag_pos[rows], ranges.gt_range[rows]
        # linearised: 2 pᵀa − |a|² = |p|² − r²
        design = np.c_[2 * pts, -np.ones(len(pts))]
        with np.errstate(over="ignore", invalid="ignore"):
            target = np.sum(pts**2, axis=1) - r**2
        if not (np.all(np.isfinite(target)) and np.all(np.isfinite(design))):
            size = float(np.max(np.abs(np.c_[pts, r])))
            raise CredcliError(
                f"{ranges.source}: anchor {int(anchor_id)}: its ground truth (tag positions, "
                f"gt_range) reaches {size:.3g} m, too large to self-calibrate the anchor from "
                "(squares overflow); check those columns, or give the anchors in a file, `anchors`"
            )
        sol, *_ = np.linalg.lstsq(design, target, rcond=None)
        plane = float(np.mean(pts[:, 2]))
        starts = [sol[:3]] + [
            np.array([sol[0], sol[1], plane + dz]) for dz in (-3.0, -1.5, -0.5, 0.5, 1.5, 3.0)
        ]
        fits = [_fit_anchor(pts, r, s) for s in starts]
        rms = [_residual_rms(pts, r, a) for a in fits]
        best = int(np.argmin(rms))
        anchors.append(
            Anchor(int(anchor_id), fits[best], "self-calibrated", rms[best], int(rows.sum()))
        )
    return anchors


def anchors_from_markers(
    ranges: RangeLog,
    markers: dict[int, np.ndarray],
    path: str,
    anchor_map: tuple[tuple[int, int], ...] = (),
) -> list[Anchor]:
    """Anchors from a markers file; ``anchor_map`` maps the log's anchor ids to marker ids
    (ids not in it are looked up as they are).

    Parameters
    ----------
    ranges : RangeLog
        The log; its ground truth gives each anchor's ``rms``.
    markers : dict of int to numpy.ndarray
        Marker id to position (3,) (m), as :func:`read_markers` gives them.
    path : str
        The markers file, for messages.
    anchor_map : tuple of (int, int)
        (log id, marker id) pairs (default none).

    Returns
    -------
    list of Anchor
        One "markers" anchor per anchor id of the log, in id order.

    Raises
    ------
    CredcliError
        If an anchor id of the log has no marker.
    """
    mapping = dict(anchor_map)
    used = np.unique(ranges.anchor)
    missing = [int(a) for a in used if mapping.get(int(a), int(a)) not in markers]
    if missing:
        raise CredcliError(
            f"{path}: no marker for anchor id(s) {', '.join(map(str, missing))} of {ranges.source} "
            f"(markers have {', '.join(map(str, sorted(markers)))}); map the log's ids with "
            "`anchor_map` LOG_ID=MARKER_ID,… or drop `anchors` to self-calibrate the anchors"
        )
    out = []
    for anchor_id in used:
        rows = ranges.anchor == anchor_id
        a = markers[mapping.get(int(anchor_id), int(anchor_id))]
        rms = _residual_rms(ranges.tag_pos[rows], ranges.gt_range[rows], a)
        out.append(Anchor(int(anchor_id), np.asarray(a, float), "markers", rms, int(rows.sum())))
    return out


def anchor_warnings(anchors: list[Anchor], limit: float) -> list[str]:
    """Given anchors whose distances to the ground-truth tag positions disagree with the
    log's gt_range by more than ``limit`` (m) RMS: wrong markers or a wrong id map.

    Parameters
    ----------
    anchors : list of Anchor
        The anchors.
    limit : float
        The largest RMS disagreement accepted (m) (``UwbSettings.anchor_rms_warn``).

    Returns
    -------
    list of str
        One warning per anchor that :meth:`Anchor.disagrees`; empty when none does.
    """
    bad = [a for a in anchors if a.disagrees(limit)]
    return [
        f"anchor {a.id}: the markers disagree with the log's gt_range by {1000 * a.rms:.0f} mm "
        f"RMS (more than {1000 * limit:.0f} mm): a wrong markers file or id map? Check "
        "`anchor_map`, or drop `anchors` to self-calibrate from the log"
        for a in bad
    ]


@dataclass(frozen=True)
class Packets:
    """Groups of range rows: ``rows[k]`` are the row indices of packet k, padded with -1.

    Attributes
    ----------
    rows : numpy.ndarray of int64, shape (M, K)
        The range rows of each packet, one per anchor, in time order; K is the largest
        packet's size.
    tag : numpy.ndarray of int64, shape (M,)
        The tag of each packet.
    """

    rows: np.ndarray  # (M, K)
    tag: np.ndarray  # (M,)


def make_packets(ranges: RangeLog, window: float = 0.03, min_anchors: int = 3) -> Packets:
    """Packets of near-simultaneous ranges per tag: a packet starts at the first range not
    yet used and takes the later ranges of the same tag within ``window`` seconds, keeping
    the first range of each anchor. Packets with fewer than ``min_anchors`` distinct anchors
    are dropped. The loop is over packets (not range rows), each found by a binary search.

    Parameters
    ----------
    ranges : RangeLog
        The log, sorted by time.
    window : float
        Packet window in s (default 0.03, the paper's).
    min_anchors : int
        Fewest distinct anchors of a packet kept (default 3).

    Returns
    -------
    Packets
        The packets kept, per tag in tag order, then in time order.
    """
    groups = []
    tags = []
    for tag in np.unique(ranges.tag):
        idx = np.flatnonzero(ranges.tag == tag)
        t = ranges.time[idx]
        start = 0
        while start < idx.size:
            stop = int(np.searchsorted(t, t[start] + window, side="right"))
            members = idx[start:stop]
            _, first = np.unique(ranges.anchor[members], return_index=True)
            if first.size >= min_anchors:
                groups.append(members[np.sort(first)])
                tags.append(tag)
            start = stop
    width = max((g.size for g in groups), default=min_anchors)
    rows = np.full((len(groups), width), -1, dtype=np.int64)
    for k, g in enumerate(groups):
        rows[k, : g.size] = g
    return Packets(rows, np.asarray(tags, dtype=np.int64))


@dataclass(frozen=True)
class Fixes:
    """Position fixes, one per packet kept (sorted by time), and why the others were not.

    ``dropped`` counts packets by reason: ``stale`` (a range vector repeated from an
    earlier packet), ``residual`` (the residual test), ``ambiguous`` (two minima the data
    cannot tell apart), ``ill-conditioned`` (HᵀWH with condition number above
    MAX_CONDITION) and ``no convergence``; each packet under its first reason in that order.
    ``moved`` counts fixes where the Gauss–Newton solution was not the global minimum and
    the global one was kept. ``screened_rows`` marks the range rows of packets dropped as
    stale or by the residual test (left out of the range-level evidence too).

    Attributes
    ----------
    time : numpy.ndarray, shape (M,)
        Time of each fix: the mean time of its packet's ranges (s).
    tag : numpy.ndarray, shape (M,)
        The tag of each fix.
    estimate : numpy.ndarray, shape (M, 2)
        The solved 2-D position (m).
    truth : numpy.ndarray, shape (M, 2)
        The ground-truth 2-D tag position: the mean over the packet's rows (m).
    cov : numpy.ndarray, shape (M, 2, 2)
        The claimed covariance (HᵀWH)⁻¹ at the solution (m²).
    dropped : dict of str to int
        Packets dropped, by reason (see above).
    moved : int
        Fixes kept whose global minimum was not the Gauss–Newton solution of the first
        start.
    screened_rows : numpy.ndarray of bool or None
        Per range row of the log, whether its packet was dropped as stale or by the
        residual test.
    residual_scale : float or None
        The run's robust residual scale (median of RSS over its χ² median); None without
        screening or without a packet to screen.
    """

    time: np.ndarray
    tag: np.ndarray
    estimate: np.ndarray  # (M, 2)
    truth: np.ndarray  # (M, 2)
    cov: np.ndarray  # (M, 2, 2) = (HᵀWH)⁻¹
    dropped: dict = field(default_factory=dict)
    moved: int = 0
    screened_rows: np.ndarray | None = None
    residual_scale: float | None = None

    @property
    def dropped_total(self) -> int:
        """Packets dropped, for every reason."""
        return int(sum(self.dropped.values()))


MAX_CONDITION = 1e4
"""Fixes whose HᵀWH has a larger condition number are dropped: the geometry leaves one
direction nearly unobserved (anchors almost on a line through the tag)."""

AMBIGUITY_DISTANCE = 0.1
"""Two local minima farther apart than this (m) ..."""

AMBIGUITY_COST = 3.841458820694124
"""... whose weighted costs differ by less than this (χ²₁'s 95 % quantile) make a fix
ambiguous: the ranges cannot tell the two positions apart."""

HUBER_K = 1.345
"""Huber's tuning constant, in standard deviations (95 % efficiency at the Gaussian)."""

STARTS = 5
"""Starts of the global-minimum check: the anchors' centroid and four points around it."""


def repeated_packets(ranges: RangeLog, packets: Packets) -> np.ndarray:
    """Packets whose range vector (anchor ids and ranges, exactly, at the log's resolution:
    the centimetre for STAR-loc s5 files) repeats an earlier packet of the same tag.

    Parameters
    ----------
    ranges : RangeLog
        The log.
    packets : Packets
        Its packets.

    Returns
    -------
    numpy.ndarray of bool, shape (M,)
        True for a packet whose tag, anchors (in any order) and ranges equal those of a
        packet that starts earlier.
    """
    rows = packets.rows
    valid = rows >= 0
    safe = np.where(valid, rows, 0)
    anchor = np.where(valid, ranges.anchor[safe], -1)
    quantum = _resolution(ranges.range)
    steps = np.where(valid, np.round(ranges.range[safe] / quantum), 0).astype(np.int64)
    order = np.argsort(anchor, axis=1, kind="stable")  # the same anchors in any order
    keys = np.c_[
        packets.tag,
        np.take_along_axis(anchor, order, axis=1),
        np.take_along_axis(steps, order, axis=1),
    ]
    time = np.where(valid, ranges.time[safe], np.inf).min(axis=1)
    by_time = np.argsort(time, kind="stable")
    _, first = np.unique(keys[by_time], axis=0, return_index=True)
    repeated = np.ones(len(keys), dtype=bool)
    repeated[by_time[first]] = False
    return repeated


def _resolution(values: np.ndarray) -> float:
    """The coarsest of 1 cm, 1 mm, …, 1 µm that every value is a multiple of (1 µm if none)."""
    for quantum in (1e-2, 1e-3, 1e-4, 1e-5):
        if np.all(np.abs(values / quantum - np.round(values / quantum)) < 1e-6):
            return quantum
    return 1e-6


STALE_JUMP = 3.0
"""A repeated packet is stale when its fix is more than this many standard deviations
(of its claimed covariance, largest axis) from the median of its neighbours' fixes."""

NEIGHBOURS = 3
"""Fixes of the same tag on each side that a repeated packet is compared with."""


def _jump(pos: np.ndarray, tag: np.ndarray, time: np.ndarray, scale: np.ndarray) -> np.ndarray:
    """Distance of each fix from the median of its NEIGHBOURS fixes of the same tag on each
    side (itself left out), in units of ``scale``."""
    out = np.zeros(len(pos))
    for t in np.unique(tag):
        idx = np.flatnonzero(tag == t)
        idx = idx[np.argsort(time[idx], kind="stable")]
        p = pos[idx]
        k = idx.size
        offsets = [o for o in range(-NEIGHBOURS, NEIGHBOURS + 1) if o]
        near = np.clip(np.arange(k)[:, None] + np.array(offsets), 0, k - 1)  # (k, 2N)
        median = np.median(p[near], axis=1)
        out[idx] = np.linalg.norm(p - median, axis=1) / scale[idx]
    return out


def _gauss_newton(pos, anchor_xy, dz2, weight, meas, iterations, robust):
    """Gauss–Newton (iteratively reweighted with Huber's weights when ``robust``) from
    ``pos`` for every packet at once; returns the positions and whether each converged."""
    step = np.full_like(pos, np.inf)
    w = weight
    for _ in range(max(1, iterations)):
        if robust is RobustLoss.HUBER:
            dist = np.sqrt(np.sum((pos[:, None, :] - anchor_xy) ** 2, axis=2) + dz2)
            z = np.abs(meas - dist) * np.sqrt(weight)
            w = weight * np.minimum(1.0, HUBER_K / np.maximum(z, 1e-12))
        normal, grad, good = _normal_equations(pos, anchor_xy, dz2, w, meas, 1e-12)
        step = np.zeros_like(pos)
        step[good] = np.linalg.solve(normal[good], grad[good][..., None])[..., 0]
        pos = pos + step
        if np.max(np.abs(step)) < 1e-9:
            break
    converged = np.isfinite(pos).all(axis=1) & (np.max(np.abs(step), axis=1) < 1e-6)
    return pos, converged


def _cost(pos, anchor_xy, dz2, weight, meas):
    dist = np.sqrt(np.sum((pos[:, None, :] - anchor_xy) ** 2, axis=2) + dz2)
    return np.sum(weight * (meas - dist) ** 2, axis=1)


def solve_packets(
    ranges: RangeLog,
    packets: Packets,
    anchors: list[Anchor],
    settings: UwbSettings | None = None,
) -> Fixes:
    """The 2-D tag position of every packet, checked and screened.

    Weighted least squares with weights 1/std² and the tag height fixed at the ground-truth
    height (mean over the packet's rows): Gauss–Newton from the linearised solution, and,
    as a check of the global minimum, from STARTS more points; the lowest cost wins
    (``moved`` counts the fixes it changed). A fix is dropped when another minimum is as
    good (AMBIGUITY_*), when HᵀWH is ill-conditioned (MAX_CONDITION), or when no start
    converged. With ``settings.screen``, stale packets are dropped: a range vector repeated
    from an earlier packet (:func:`repeated_packets`) whose fix jumps more than STALE_JUMP
    standard deviations away from its neighbours' (a re-sent old measurement; a static tag
    that measures the same ranges again does not jump),
    and so are packets whose residual sum of squares fails the χ²_{m−2} test at
    ``settings.residual_level``, after scaling by the run's robust residual scale (the
    median of RSS over its χ² median), so that a wrong claimed std does not decide which
    packets go. The claimed covariance is (HᵀWH)⁻¹ at the solution, with the claimed
    weights (also under ``--robust huber``, which only downweights outliers in the solve).

    Parameters
    ----------
    ranges : RangeLog
        The log: ranges, their stds, ground-truth tag positions and times.
    packets : Packets
        Its packets (:func:`make_packets`).
    anchors : list of Anchor
        The anchors; every anchor id of the packets must be among them.
    settings : UwbSettings, optional
        ``wls_iterations``, ``robust``, ``screen`` and ``residual_level``; the defaults
        when None.

    Returns
    -------
    Fixes
        The fixes kept, sorted by time, with the counts of those dropped.
    """
    from scipy import special

    settings = settings or UwbSettings()
    rows = packets.rows
    valid = rows >= 0
    safe = np.where(valid, rows, 0)
    ids = np.array([a.id for a in anchors])
    order = np.argsort(ids)
    positions = np.array([a.position for a in anchors])[order]
    anchor_pos = positions[np.searchsorted(ids[order], ranges.anchor[safe])]  # (M, K, 3)
    weight = np.where(valid, 1.0 / ranges.std[safe] ** 2, 0.0)
    meas = np.where(valid, ranges.range[safe], 0.0)
    count = valid.sum(axis=1)
    tag_pos = np.where(valid[..., None], ranges.tag_pos[safe], 0.0).sum(axis=1) / count[:, None]
    time = np.where(valid, ranges.time[safe], 0.0).sum(axis=1) / count
    height = tag_pos[:, 2]
    axy = anchor_pos[..., :2]
    dz2 = np.where(valid, (height[:, None] - anchor_pos[..., 2]) ** 2, 0.0)
    centroid = np.where(valid[..., None], axy, 0.0).sum(axis=1) / count[:, None]
    linear = _linear_start(axy, meas**2 - dz2, weight)
    start = np.where(np.isfinite(linear).all(axis=1)[:, None], linear, centroid)
    spread = np.sqrt(
        np.where(valid, np.sum((axy - centroid[:, None, :]) ** 2, axis=2), 0.0).sum(axis=1) / count
    )
    offsets = [np.zeros(2), *(np.array(v) for v in ((1, 0), (-1, 0), (0, 1), (0, -1)))]
    starts = [start] + [centroid + 0.5 * spread[:, None] * o for o in offsets[:STARTS]]
    m = len(rows)
    tile = len(starts)
    solved, converged = _gauss_newton(
        np.concatenate(starts),
        np.tile(axy, (tile, 1, 1)),
        np.tile(dz2, (tile, 1)),
        np.tile(weight, (tile, 1)),
        np.tile(meas, (tile, 1)),
        settings.wls_iterations,
        settings.robust,
    )
    solved = solved.reshape(tile, m, 2)
    converged = converged.reshape(tile, m)
    cost = np.stack([_cost(solved[k], axy, dz2, weight, meas) for k in range(tile)])
    cost = np.where(converged, cost, np.inf)
    best = np.argmin(cost, axis=0)
    pos = solved[best, np.arange(m)]
    best_cost = cost[best, np.arange(m)]
    any_converged = np.isfinite(best_cost)
    primary = np.where(converged[0], cost[0], 0.0)  # inf where the first start failed
    moved = (
        any_converged
        & converged[0]
        & (np.linalg.norm(pos - solved[0], axis=1) > 1e-3)
        & (best_cost < primary - 1e-9 * (1 + primary))
    )
    far = np.linalg.norm(solved - pos[None], axis=2) > AMBIGUITY_DISTANCE
    with np.errstate(invalid="ignore"):  # inf − inf for packets where nothing converged
        close = cost - best_cost[None] < AMBIGUITY_COST
    ambiguous = np.any(far & close, axis=0)
    normal, _, well_posed = _normal_equations(
        np.where(any_converged[:, None], pos, centroid), axy, dz2, weight, meas, 1e-9
    )
    eig = np.linalg.eigvalsh(normal)
    condition = eig[:, 1] / np.maximum(eig[:, 0], 1e-300)
    ill = ~well_posed | (condition > MAX_CONDITION)
    stale = np.zeros(m, bool)
    if settings.screen:
        sigma = np.sqrt(1.0 / np.maximum(eig[:, 0], 1e-300))  # largest std of the fix
        jump = _jump(np.where(any_converged[:, None], pos, centroid), packets.tag, time, sigma)
        stale = repeated_packets(ranges, packets) & (jump > STALE_JUMP)
    residual = np.zeros(m, bool)
    scale = None
    dof = count - 2
    if settings.screen:
        usable = any_converged & ~stale & (dof >= 1)
        if usable.any():
            medians = special.chdtri(dof[usable], 0.5)
            scale = float(np.median(best_cost[usable] / medians))
            pvalue = special.chdtrc(np.maximum(dof, 1), best_cost / max(scale, 1e-300))
            residual = usable & (pvalue < settings.residual_level)
    reasons = {
        "stale": stale,
        "residual": residual,
        "ambiguous": ambiguous,
        "ill-conditioned": ill,
        "no convergence": ~any_converged,
    }
    dropped, taken = {}, np.zeros(m, bool)
    for name, mask in reasons.items():
        dropped[name] = int((mask & ~taken).sum())
        taken |= mask
    keep = ~taken
    screened = np.zeros(ranges.time.size, bool)
    bad_rows = rows[stale | residual]
    screened[bad_rows[bad_rows >= 0]] = True
    cov = np.linalg.inv(normal[keep])
    order = np.argsort(time[keep], kind="stable")
    return Fixes(
        time=time[keep][order],
        tag=packets.tag[keep][order],
        estimate=pos[keep][order],
        truth=tag_pos[keep][order, :2],
        cov=cov[order],
        dropped=dropped,
        moved=int((moved & keep).sum()),
        screened_rows=screened,
        residual_scale=scale,
    )


def _normal_equations(pos, anchor_xy, dz2, weight, meas, rcond: float):
    """HᵀWH, HᵀW(r − ρ(p)) and whether HᵀWH is well conditioned (det above ``rcond`` times
    the product of its diagonal), at the positions ``pos`` of every packet."""
    diff = pos[:, None, :] - anchor_xy
    dist = np.sqrt(np.sum(diff**2, axis=2) + dz2)
    jac = diff / np.maximum(dist, 1e-9)[..., None]
    normal = np.einsum("mki,mk,mkj->mij", jac, weight, jac)
    grad = np.einsum("mki,mk,mk->mi", jac, weight, meas - dist)
    diag = normal[:, 0, 0] * normal[:, 1, 1]
    det = diag - normal[:, 0, 1] ** 2
    return normal, grad, det > rcond * np.maximum(diag, 1e-300)


def _linear_start(anchor_xy: np.ndarray, horiz2: np.ndarray, weight: np.ndarray) -> np.ndarray:
    """Closed-form start: subtracting the first anchor's equation from the others gives
    2(a_i − a_1)ᵀp = h_1² − h_i² + |a_i|² − |a_1|², linear in p (weighted LS per packet)."""
    a1 = anchor_xy[:, :1, :]
    rows = 2.0 * (anchor_xy[:, 1:, :] - a1)
    rhs = (
        (horiz2[:, :1] - horiz2[:, 1:])
        + np.sum(anchor_xy[:, 1:, :] ** 2, axis=2)
        - np.sum(a1**2, axis=2)
    )
    w = weight[:, 1:]
    normal = np.einsum("mki,mk,mkj->mij", rows, w, rows)
    rhs_n = np.einsum("mki,mk,mk->mi", rows, w, rhs)
    out = np.full(rhs_n.shape, np.nan)
    det = np.linalg.det(normal)
    good = np.abs(det) > 1e-12
    out[good] = np.linalg.solve(normal[good], rhs_n[good][..., None])[..., 0]
    return out


@dataclass(frozen=True)
class RangeStats:
    """Range-level evidence of one period and anchor (Figs. 4 and 5 as numbers), on the
    ranges left after screening: error e = range − gt_range.

    Attributes
    ----------
    segment : str
        The period's name.
    anchor : int
        The anchor id.
    n : int
        Ranges of this anchor in the period.
    mean_error : float
        The range bias: mean of e (m).
    std_error : float
        Classical empirical std of e (m; NaN for a single range).
    median_std : float
        Median reported std (m).
    bias_stderr : float
        Standard error of the mean, ``std_error`` / √n (m; NaN for a single range).
    robust_std : float
        1.4826 × median absolute deviation of e (m).
    beyond_3sigma : float
        Fraction of ranges with |e − mean| above 3 times their reported std.
    """

    segment: str
    anchor: int
    n: int
    mean_error: float  # the range bias: mean of e (m)
    std_error: float  # classical empirical std of e (m)
    median_std: float  # median reported std (m)
    bias_stderr: float = float("nan")  # standard error of the mean (m)
    robust_std: float = float("nan")  # 1.4826 × median absolute deviation of e (m)
    beyond_3sigma: float = float("nan")  # fraction of |e − mean| above 3 reported std

    @property
    def std_ratio(self) -> float:
        """Empirical over reported std: > 1 means the reported noise is optimistic."""
        return self.std_error / self.median_std

    @property
    def robust_ratio(self) -> float:
        """Robust empirical over reported std."""
        return self.robust_std / self.median_std


def range_stats(
    ranges: RangeLog, spans: list[tuple[str, float, float]], screened: np.ndarray | None = None
) -> list[RangeStats]:
    """The range-level evidence of every period, per anchor.

    Parameters
    ----------
    ranges : RangeLog
        The log.
    spans : list of (str, float, float)
        The periods: name, first and last time (s, both included).
    screened : numpy.ndarray of bool, optional
        Per range row, whether to leave it out (``Fixes.screened_rows``); none left out
        when None.

    Returns
    -------
    list of RangeStats
        Per period in order, one item per anchor with ranges in it, in id order.
    """
    out = []
    err = ranges.range_error
    kept = np.ones(err.size, bool) if screened is None else ~screened
    for name, t0, t1 in spans:
        in_span = (ranges.time >= t0) & (ranges.time <= t1) & kept
        for anchor_id in np.unique(ranges.anchor[in_span]):
            rows = in_span & (ranges.anchor == anchor_id)
            e = err[rows]
            sd = float(e.std(ddof=1)) if e.size > 1 else float("nan")
            reported = float(np.median(ranges.std[rows]))
            out.append(
                RangeStats(
                    name,
                    int(anchor_id),
                    int(rows.sum()),
                    float(e.mean()),
                    sd,
                    reported,
                    bias_stderr=sd / np.sqrt(e.size) if e.size > 1 else float("nan"),
                    robust_std=1.4826 * float(np.median(np.abs(e - np.median(e)))),
                    beyond_3sigma=float(np.mean(np.abs(e - e.mean()) > 3 * ranges.std[rows])),
                )
            )
    return out


RANGE_BIAS_Z = 3.0
"""A range bias counts as evidence of SMM when |mean| > 3 standard errors."""


def range_verdict(stats: list[RangeStats], tau_db: float) -> tuple[str, str]:
    """The label the range-level evidence of one period points to, and why: noise from the
    robust spread against the reported std (pooled over anchors, the same relevance floor
    τ dB on the variance as the position-level rule), SMM from any anchor's range bias
    beyond RANGE_BIAS_Z standard errors.

    Parameters
    ----------
    stats : list of RangeStats
        The period's items, one per anchor (at least one).
    tau_db : float
        The relevance floor τ in dB on the variance (``DiagnosisConfig.tau_nci``).

    Returns
    -------
    label : str
        The label's text: optimism when the pooled spread ratio is above τ dB,
        pessimism when below −τ dB, with smm when an anchor is biased.
    why : str
        The pooled spread ratio and the largest bias, for the report.

    Notes
    -----
    The pooled ratio is the geometric mean of the anchors' ``robust_std / median_std``
    weighted by their ``n``, r̄; its level is 20 log₁₀ r̄ dB (10 log₁₀ of the variance
    ratio).
    """
    n = np.array([s.n for s in stats], float)
    ratio = float(np.exp(np.sum(n * np.log([max(s.robust_ratio, 1e-12) for s in stats])) / n.sum()))
    db = 20.0 * np.log10(ratio)  # of the variance
    noise = "optimism" if db > tau_db else "pessimism" if db < -tau_db else None
    biased = [s for s in stats if abs(s.mean_error) > RANGE_BIAS_Z * s.bias_stderr]
    label = Label.compose(noise, bool(biased)).value
    worst = max(stats, key=lambda s: abs(s.mean_error))
    why = f"range spread {ratio:.2g}× the reported std, bias up to {worst.mean_error:+.3f} m"
    return label, why


@dataclass(frozen=True)
class RangeCheck:
    """The range-level evidence of one period beside its position-level verdict:
    ``label`` the ranges point to (None: no ranges in the period), ``why``, and whether
    the two agree (None: no range label, or no position-level verdict).

    Attributes
    ----------
    segment : str
        The period's name.
    label : str or None
        The label the ranges point to (:func:`range_verdict`); None without ranges.
    why : str
        Why (empty without ranges).
    agrees : bool or None
        Whether the position-level label agrees (:func:`answers_agree`); None without a
        range label or when the period was insufficient-data.
    """

    segment: str
    label: str | None
    why: str
    agrees: bool | None


def answers_agree(label, other: str, untested) -> bool:
    """Whether two labels agree on the questions the first one answered: its noise part
    unless the scale is untested, its location part unless the location is (in the
    paper's terms: a bias or an asymmetry is SMM).

    Parameters
    ----------
    label : Label or str
        The first label (the position-level verdict).
    other : str
        The label it is compared with (the range-level one).
    untested : collection of str
        The values of the questions (``Question``) the first label left unanswered.

    Returns
    -------
    bool
        Whether the two labels, as the paper's, have the same conditions among those
        asked.

    Examples
    --------
    >>> answers_agree("pessimism+bias", "pessimism+smm", [])
    True
    >>> answers_agree("credible", "optimism+smm", ["scale"])
    False
    >>> answers_agree("smm", "optimism+smm", ["scale"])
    True
    """
    asked = set()
    if Question.SCALE.value not in untested:
        asked |= {Label.OPTIMISM.value, Label.PESSIMISM.value}
    if Question.LOCATION.value not in untested:
        asked.add(Label.SMM.value)
    return Label(label).paper.conditions & asked == Label(other).paper.conditions & asked


def range_checks(run: UwbRun, results, tau_db: float) -> list[RangeCheck]:
    """The range-level evidence of each diagnosed period (:func:`range_verdict`) and
    whether the position-level label agrees with it.

    Parameters
    ----------
    run : UwbRun
        The pipeline's output, with its ``range_stats``.
    results : list of SegmentDiagnosis
        The position-level diagnosis of each period.
    tau_db : float
        The relevance floor τ in dB (``DiagnosisConfig.tau_nci``).

    Returns
    -------
    list of RangeCheck
        One per result, in order.
    """
    checks = []
    for result in results:
        mine = [s for s in run.range_stats if s.segment == result.segment]
        label, why = range_verdict(mine, tau_db) if mine else (None, "")
        diagnosis = result.diagnosis
        agrees = None
        if label and diagnosis.label is not Label.INSUFFICIENT:
            untested = [q.value for q in diagnosis.untested]
            agrees = answers_agree(diagnosis.label, label, untested)
        checks.append(RangeCheck(result.segment, label, why, agrees))
    return checks


@dataclass(frozen=True)
class UwbRun:
    """Everything the `uwb` command computed.

    Attributes
    ----------
    ranges : RangeLog
        The log as read.
    anchors : list of Anchor
        The anchors used.
    fixes : Fixes
        Every fix kept, and the packets dropped.
    log : EstimatorLog
        The fixes inside the segments, with the segment names.
    segments : list of Segment
        The segments (``credcli.segments.Segment``) over ``log``.
    range_stats : list of RangeStats
        The range-level evidence of each period and anchor.
    packets : int
        Packets formed (before any was dropped).
    notes : tuple of str
        Warnings for the report (e.g. anchors that disagree with the log).
    settings : UwbSettings
        The settings the pipeline ran with.
    """

    ranges: RangeLog
    anchors: list[Anchor]
    fixes: Fixes
    log: EstimatorLog  # the fixes inside the segments, with the segment names
    segments: list  # credcli.segments.Segment over `log`
    range_stats: list[RangeStats]
    packets: int
    notes: tuple[str, ...] = ()
    settings: UwbSettings = field(default_factory=UwbSettings)


def merge_short_tail(segments: list, window: str) -> list:
    """Windows with the last one merged into the one before when it is shorter than half a
    window (in time, or in epochs for a count): a 1-fix tail is not a period.

    Parameters
    ----------
    segments : list of Segment
        Consecutive windows, in time order.
    window : str
        The window length they were made with (``5s``, ``200``; see
        ``credcli.segments.Window``).

    Returns
    -------
    list of Segment
        ``segments``, or with the last two as one segment under the first one's name.
    """
    if len(segments) < 2:
        return segments
    w = seg.Window.parse(window)
    last, before = segments[-1], segments[-2]
    if w.seconds:
        short = (last.t_end - last.t_start) < w.length / 2
    else:
        short = len(last.index) < w.length / 2
    if not short:
        return segments
    merged = seg.Segment(before.name, np.r_[before.index, last.index], before.t_start, last.t_end)
    return [*segments[:-2], merged]


def position_log(
    ranges: RangeLog, fixes: Fixes, window: str | None, whole: bool, settings: UwbSettings
):
    """Assign fixes to static periods (default), windows or the whole run; returns the
    EstimatorLog of the fixes kept and its segments, and the segment time spans.

    Parameters
    ----------
    ranges : RangeLog
        The log: the rig's positions give the static periods, its source the log's name.
    fixes : Fixes
        The fixes.
    window : str or None
        A window length (``5s``, ``200``): consecutive windows of the run, a short tail
        merged (:func:`merge_short_tail`).
    whole : bool
        The whole run as one segment ``all`` (over ``window``).
    settings : UwbSettings
        ``max_speed`` and ``min_static`` of the static periods.

    Returns
    -------
    log : EstimatorLog
        The fixes in the segments (every fix with ``window`` or ``whole``; those inside a
        static period otherwise), their segment names as the segment column.
    segments : list of Segment
        The segments over ``log``; a static period's segment spans the whole period,
        not only its fixes.
    spans : list of (str, float, float)
        Each segment's or period's name, first and last time (for :func:`range_stats`).

    Raises
    ------
    CredcliError
        If static periods are asked for and there is none.
    """
    if whole or window is not None:
        n = fixes.time.size
        segments = (
            seg.whole(n, fixes.time)
            if whole
            else merge_short_tail(seg.by_window(n, seg.Window.parse(window), fixes.time), window)
        )
        names = np.empty(n, dtype=object)
        for s in segments:  # one assignment per segment
            names[s.index] = s.name
        log = EstimatorLog(
            fixes.truth,
            fixes.estimate,
            fixes.cov,
            fixes.time,
            names.astype(str),
            id=LogId.of(ranges.source, ranges.source),
        )
        return log, segments, [(s.name, s.t_start, s.t_end) for s in segments]
    periods, _ = seg.static_periods(
        ranges.time, ranges.rig_pos, settings.max_speed, settings.min_static
    )
    if not periods:
        raise CredcliError(
            f"{ranges.source}: no static period found (rig speed below {settings.max_speed:g} m/s "
            f"for at least {settings.min_static:g} s); the rig may move the whole time: use "
            "`window` 5s for fixed windows, or `whole`"
        )
    period_of = np.full(fixes.time.size, -1)
    for k, p in enumerate(periods):
        period_of[(fixes.time >= p.t_start) & (fixes.time <= p.t_end)] = k
    inside = period_of >= 0
    names = np.array([p.name for p in periods])[period_of[inside]]
    log = EstimatorLog(
        fixes.truth[inside],
        fixes.estimate[inside],
        fixes.cov[inside],
        fixes.time[inside],
        names,
        id=LogId.of(ranges.source, ranges.source),
    )
    segments = seg.by_column(names, log.time)
    by_name = {p.name: p for p in periods}
    segments = [
        seg.Segment(s.name, s.index, by_name[s.name].t_start, by_name[s.name].t_end)
        for s in segments
    ]
    spans = [(p.name, p.t_start, p.t_end) for p in periods]
    return log, segments, spans


def run_pipeline(
    path: str | Path,
    settings: UwbSettings = UwbSettings(),
    anchors_path: str | Path | None = None,
    window: str | None = None,
    whole: bool = False,
) -> UwbRun:
    """Read, calibrate or read anchors, packetise, solve, screen and segment (no diagnosis).

    Parameters
    ----------
    path : str or pathlib.Path
        The STAR-loc ``uwb.csv``.
    settings : UwbSettings
        The pipeline's settings (default: the paper's Section V-A, with screening).
    anchors_path : str or pathlib.Path, optional
        A markers file with the anchor positions; without it the anchors are
        self-calibrated from the log (:func:`calibrate_anchors`).
    window : str, optional
        Fixed windows (``5s``, ``200``) instead of the static periods.
    whole : bool
        The whole run as one segment (default False).

    Returns
    -------
    UwbRun
        Everything computed, ready to diagnose per segment.

    Raises
    ------
    CredcliError
        If the file or the markers cannot be read, ``anchor_map`` is given without
        markers, a log's anchor has no marker, no packet has enough anchors, every packet
        is dropped, or no static period is found.
    """
    ranges = read_starloc(path, settings.reading)
    notes = []
    if anchors_path is not None:
        anchors = anchors_from_markers(
            ranges, read_markers(anchors_path), str(anchors_path), settings.anchor_map
        )
        notes.extend(anchor_warnings(anchors, settings.anchor_rms_warn))
    else:
        if settings.anchor_map:
            raise CredcliError("`anchor_map` maps ids to a markers file: give `anchors` FILE")
        anchors = calibrate_anchors(ranges)
    packets = make_packets(ranges, settings.packet_window, settings.min_anchors)
    if packets.rows.shape[0] == 0:
        raise CredcliError(
            f"{ranges.source}: no packet has {settings.min_anchors} distinct anchors within "
            f"{settings.packet_window:g} s; try a longer `packet_window`"
        )
    fixes = solve_packets(ranges, packets, anchors, settings)
    if fixes.time.size == 0:
        raise CredcliError(
            f"{ranges.source}: every packet was dropped ({dropped_text(fixes)}); try "
            "`screen` none or a longer `packet_window`"
        )
    log, segments, spans = position_log(ranges, fixes, window, whole, settings)
    stats = range_stats(ranges, spans, fixes.screened_rows)
    return UwbRun(
        ranges, anchors, fixes, log, segments, stats, packets.rows.shape[0], tuple(notes), settings
    )


def dropped_text(fixes: Fixes) -> str:
    """The packets dropped, by reason ("3 stale, 1 residual"), or "none".

    Parameters
    ----------
    fixes : Fixes
        The fixes and their ``dropped`` counts.

    Returns
    -------
    str
        The nonzero counts with their reasons, comma-separated, in ``dropped``'s order.

    Examples
    --------
    >>> empty = np.zeros(0)
    >>> dropped = {"stale": 3, "residual": 1, "ambiguous": 0}
    >>> dropped_text(Fixes(empty, empty, empty, empty, empty, dropped))
    '3 stale, 1 residual'
    >>> dropped_text(Fixes(empty, empty, empty, empty, empty))
    'none'
    """
    return ", ".join(f"{v} {k}" for k, v in fixes.dropped.items() if v) or "none"
