"""The UWB pipeline of Section V on STAR-loc ``uwb.csv`` logs.

file -> RangeLog -> anchors (markers file or self-calibration) -> packets of near-simultaneous
ranges -> 2-D WLS fixes with claimed covariance (HᵀWH)⁻¹ -> EstimatorLog -> segments
(static periods, windows or whole) -> diagnosis per segment, plus range-level statistics.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from credcli.errors import CredcliError
from credcli.io.logs import EstimatorLog
from credcli.studies.settings import UwbSettings  # noqa: F401 (re-exported)


@dataclass(frozen=True)
class RangeLog:
    """One STAR-loc uwb.csv: one range per row, sorted by time."""

    source: str
    time: np.ndarray
    range: np.ndarray
    std: np.ndarray
    tag: np.ndarray
    anchor: np.ndarray
    tag_pos: np.ndarray  # (N, 3) ground-truth tag position
    rig_pos: np.ndarray  # (N, 3) ground-truth rig position
    gt_range: np.ndarray
    range_column: str
    notes: tuple[str, ...] = ()

    @property
    def range_error(self) -> np.ndarray:
        return self.range - self.gt_range


_REQUIRED = ("time_s", "from_id", "to_id", "tag_pos_x", "tag_pos_y", "tag_pos_z", "gt_range")


def read_starloc(path: str | Path, settings: UwbSettings = UwbSettings()) -> RangeLog:
    """Read and validate a STAR-loc ``uwb.csv``.

    Without ``range_calib`` (setup s5) the raw ``range`` column is used, with a note.
    Without ``std`` a fixed ``settings.std`` is required.
    """
    from credcli.io.logs import numeric_columns, read_table

    path = Path(path)
    frame = read_table(path)
    columns = [str(c) for c in frame.columns]
    frame.columns = columns
    source = str(path)
    missing = [c for c in _REQUIRED if c not in columns]
    if missing:
        raise CredcliError(
            f"{source}: not a STAR-loc uwb.csv: missing column(s) {', '.join(missing)}; "
            f"columns found: {', '.join(columns[:30])}"
        )
    notes = []
    range_column = settings.range_column
    if range_column not in columns:
        if range_column == UwbSettings.range_column and "range" in columns:
            notes.append(f"{source}: no '{range_column}' column (setup s5?): using raw 'range'")
            range_column = "range"
        else:
            raise CredcliError(
                f"{source}: range column '{range_column}' not found; columns found: "
                f"{', '.join(columns[:30])}"
            )
    if settings.std is None and "std" not in columns:
        raise CredcliError(
            f"{source}: no 'std' column (setup s5 runs do not report one); give the range "
            "standard deviation in metres with --std VALUE, e.g. --std 0.1"
        )
    rig_cols = ["x", "y", "z"] if all(c in columns for c in ("x", "y", "z")) else None
    numeric = list(_REQUIRED) + [range_column]
    numeric += [] if settings.std is not None else ["std"]
    numeric += rig_cols or []
    values = numeric_columns(frame, numeric, source)
    bad = ~np.isfinite(values).all(axis=1)
    if bad.any():
        rows = np.flatnonzero(bad)[:10] + 1
        raise CredcliError(
            f"{source}: NaN, Inf or empty value in row(s) {', '.join(map(str, rows))}"
            f"{' and more' if bad.sum() > 10 else ''}"
        )
    col = {name: values[:, i] for i, name in enumerate(numeric)}
    std = np.full(len(frame), settings.std) if settings.std is not None else col["std"]
    if np.any(std <= 0):
        row = int(np.argmax(std <= 0)) + 1
        raise CredcliError(f"{source}: row {row}, column 'std': a reported std must be > 0")
    for name in ("from_id", "to_id"):
        fractional = col[name] != np.round(col[name])
        if fractional.any():
            row = int(np.argmax(fractional)) + 1
            raise CredcliError(
                f"{source}: row {row}, column '{name}': {col[name][row - 1]:g} is not an integer id"
            )
    order = np.argsort(col["time_s"], kind="stable")
    tag_pos = np.c_[col["tag_pos_x"], col["tag_pos_y"], col["tag_pos_z"]]
    rig_pos = np.c_[col["x"], col["y"], col["z"]] if rig_cols else tag_pos
    return RangeLog(
        source=source,
        time=col["time_s"][order],
        range=col[range_column][order],
        std=std[order],
        tag=col["from_id"][order].astype(np.int64),
        anchor=col["to_id"][order].astype(np.int64),
        tag_pos=tag_pos[order],
        rig_pos=rig_pos[order],
        gt_range=col["gt_range"][order],
        range_column=range_column,
        notes=tuple(notes),
    )


@dataclass(frozen=True)
class Anchor:
    """An anchor's position and where it came from."""

    id: int
    position: np.ndarray  # (3,)
    source: str  # "markers" or "self-calibrated"
    rms: float  # RMS of ‖tag_pos − a‖ − gt_range over the anchor's rows (m)
    n: int  # rows of this anchor


def read_markers(path: str | Path) -> dict[int, np.ndarray]:
    """Anchor positions from a STAR-loc markers file (first column the id, then x, y, z)."""
    from credcli.io.logs import read_table

    path = Path(path)
    frame = read_table(path)
    cols = [str(c) for c in frame.columns]
    if not all(c in cols for c in ("x", "y", "z")):
        raise CredcliError(
            f"{path}: a markers file needs an id column and x, y, z; found {', '.join(cols)}"
        )
    try:
        ids = frame[cols[0]].astype(np.int64).to_numpy()
        xyz = frame[["x", "y", "z"]].to_numpy(dtype=float)
    except (TypeError, ValueError) as exc:
        raise CredcliError(f"{path}: markers must be numbers: {exc}") from exc
    return {int(i): p for i, p in zip(ids, xyz)}


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
    """
    anchors = []
    for anchor_id in np.unique(ranges.anchor):
        rows = ranges.anchor == anchor_id
        pts, r = ranges.tag_pos[rows], ranges.gt_range[rows]
        # linearised: 2 pᵀa − |a|² = |p|² − r²
        design = np.c_[2 * pts, -np.ones(len(pts))]
        sol, *_ = np.linalg.lstsq(design, np.sum(pts**2, axis=1) - r**2, rcond=None)
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
    ranges: RangeLog, markers: dict[int, np.ndarray], path: str
) -> list[Anchor]:
    used = np.unique(ranges.anchor)
    missing = [int(a) for a in used if int(a) not in markers]
    if missing:
        raise CredcliError(
            f"{path}: no marker for anchor id(s) {', '.join(map(str, missing))} of {ranges.source} "
            f"(markers have {', '.join(map(str, sorted(markers)))}); s1/s2 runs use other ids: "
            "drop --anchors to self-calibrate the anchors from the file"
        )
    out = []
    for anchor_id in used:
        rows = ranges.anchor == anchor_id
        a = markers[int(anchor_id)]
        rms = _residual_rms(ranges.tag_pos[rows], ranges.gt_range[rows], a)
        out.append(Anchor(int(anchor_id), np.asarray(a, float), "markers", rms, int(rows.sum())))
    return out


@dataclass(frozen=True)
class Packets:
    """Groups of range rows: ``rows[k]`` are the row indices of packet k, padded with -1."""

    rows: np.ndarray  # (M, K)
    tag: np.ndarray  # (M,)


def make_packets(ranges: RangeLog, window: float = 0.03, min_anchors: int = 3) -> Packets:
    """Packets of near-simultaneous ranges per tag: a packet starts at the first range not
    yet used and takes the later ranges of the same tag within ``window`` seconds, keeping
    the first range of each anchor. Packets with fewer than ``min_anchors`` distinct anchors
    are dropped. The loop is over packets (not range rows), each found by a binary search.
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
    """WLS solutions, one per packet (sorted by time)."""

    time: np.ndarray
    tag: np.ndarray
    estimate: np.ndarray  # (M, 2)
    truth: np.ndarray  # (M, 2)
    cov: np.ndarray  # (M, 2, 2) = (HᵀWH)⁻¹
    dropped: int  # packets without a usable solution (degenerate geometry, no convergence)


def solve_packets(
    ranges: RangeLog, packets: Packets, anchors: list[Anchor], iterations: int = 20
) -> Fixes:
    """Iterative WLS for the 2-D tag position of every packet at once.

    The tag height is the ground-truth height (mean over the packet's rows); weights are
    1/std²; the start is the linearised least-squares solution; Gauss–Newton iterations
    follow. The claimed covariance is (HᵀWH)⁻¹ at the solution, with H the Jacobian of the
    ranges with respect to (x, y).
    """
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
    dz2 = (height[:, None] - anchor_pos[..., 2]) ** 2
    pos = _linear_start(anchor_pos[..., :2], meas**2 - dz2, weight)
    ok = np.isfinite(pos).all(axis=1)
    pos = np.where(ok[:, None], pos, anchor_pos[:, 0, :2])
    step = np.full_like(pos, np.inf)
    for _ in range(max(1, iterations)):
        normal, grad, good = _normal_equations(pos, anchor_pos[..., :2], dz2, weight, meas, 1e-12)
        step = np.zeros_like(pos)
        step[good] = np.linalg.solve(normal[good], grad[good][..., None])[..., 0]
        pos = pos + step
        if np.max(np.abs(step)) < 1e-9:
            break
    normal, _, well_posed = _normal_equations(pos, anchor_pos[..., :2], dz2, weight, meas, 1e-9)
    keep = well_posed & np.isfinite(pos).all(axis=1) & (np.max(np.abs(step), axis=1) < 1e-6)
    cov = np.linalg.inv(normal[keep])
    order = np.argsort(time[keep], kind="stable")
    return Fixes(
        time=time[keep][order],
        tag=packets.tag[keep][order],
        estimate=pos[keep][order],
        truth=tag_pos[keep][order, :2],
        cov=cov[order],
        dropped=int((~keep).sum()),
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
    """Range-level evidence of one period and anchor (Figs. 4 and 5 as numbers)."""

    segment: str
    anchor: int
    n: int
    mean_error: float  # mean of range − gt_range (m)
    std_error: float  # empirical std of the range errors (m)
    median_std: float  # median reported std (m)

    @property
    def std_ratio(self) -> float:
        """Empirical over reported std: > 1 means the reported noise is optimistic."""
        return self.std_error / self.median_std


def range_stats(ranges: RangeLog, spans: list[tuple[str, float, float]]) -> list[RangeStats]:
    out = []
    err = ranges.range_error
    for name, t0, t1 in spans:
        in_span = (ranges.time >= t0) & (ranges.time <= t1)
        for anchor_id in np.unique(ranges.anchor[in_span]):
            rows = in_span & (ranges.anchor == anchor_id)
            e = err[rows]
            out.append(
                RangeStats(
                    name,
                    int(anchor_id),
                    int(rows.sum()),
                    float(e.mean()),
                    float(e.std(ddof=1)) if e.size > 1 else float("nan"),
                    float(np.median(ranges.std[rows])),
                )
            )
    return out


@dataclass(frozen=True)
class UwbRun:
    """Everything the `uwb` command computed."""

    ranges: RangeLog
    anchors: list[Anchor]
    fixes: Fixes
    log: EstimatorLog  # the fixes inside the segments, with the segment names
    segments: list  # credcli.segments.Segment over `log`
    range_stats: list[RangeStats]
    packets: int


def position_log(
    ranges: RangeLog, fixes: Fixes, window: str | None, whole: bool, settings: UwbSettings
):
    """Assign fixes to static periods (default), windows or the whole run; returns the
    EstimatorLog of the fixes kept and its segments, and the segment time spans."""
    from credcli import segments as seg

    if whole or window is not None:
        n = fixes.time.size
        segments = (
            seg.whole(n, fixes.time)
            if whole
            else seg.by_window(n, seg.Window.parse(window), fixes.time)
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
            source=ranges.source,
        )
        return log, segments, [(s.name, s.t_start, s.t_end) for s in segments]
    periods, _ = seg.static_periods(
        ranges.time, ranges.rig_pos, settings.max_speed, settings.min_static
    )
    if not periods:
        raise CredcliError(
            f"{ranges.source}: no static period found (rig speed below {settings.max_speed:g} m/s "
            f"for at least {settings.min_static:g} s); the rig may move the whole time: use "
            "--window 5s for fixed windows, or --whole"
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
        source=ranges.source,
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
    """Read, calibrate or read anchors, packetise, solve and segment (no diagnosis)."""
    ranges = read_starloc(path, settings)
    if anchors_path is not None:
        anchors = anchors_from_markers(ranges, read_markers(anchors_path), str(anchors_path))
    else:
        anchors = calibrate_anchors(ranges)
    packets = make_packets(ranges, settings.packet_window, settings.min_anchors)
    if packets.rows.shape[0] == 0:
        raise CredcliError(
            f"{ranges.source}: no packet has {settings.min_anchors} distinct anchors within "
            f"{settings.packet_window:g} s; try a longer --packet-window"
        )
    fixes = solve_packets(ranges, packets, anchors, settings.wls_iterations)
    log, segments, spans = position_log(ranges, fixes, window, whole, settings)
    stats = range_stats(ranges, spans)
    return UwbRun(ranges, anchors, fixes, log, segments, stats, packets.rows.shape[0])
