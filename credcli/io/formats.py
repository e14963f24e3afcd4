"""Pose and vector trajectories from the file layouts navigation people have.

Each reader returns a :class:`Trajectory`: stamps in seconds, positions (or the vector of
a credcli log), unit quaternions (x, y, z, w) where the format has them, and the claimed
covariance where it has one (ROS order x, y, z, rotations about x, y, z for pose formats).
Every decision taken for the user (the format, the time unit) is a note that the command
prints and records.

Layouts: TUM RGB-D (``timestamp tx ty tz qx qy qz qw``, seconds; 20 columns are OpenVINS
ov_eval's, with the upper triangles of the rotation then the position covariance), EuRoC
MAV ground truth (``#timestamp, p_RS_R_x [m], …, q_RS_w [], …``, nanoseconds), ROS CSV
exports of nav_msgs/Odometry, geometry_msgs/PoseWithCovarianceStamped, PoseStamped and
TransformStamped (``rostopic echo -p``: ``field.header.stamp`` in ns,
``field.pose.pose.position.x``, ``field.pose.covariance0`` … ``35``), and credcli's own.
"""

from __future__ import annotations

import re
from dataclasses import replace
from pathlib import Path

import numpy as np

from credcli.errors import CredcliError
from credcli.io import logs
from credcli.io.logs import numeric_columns
from credcli.io.rosbag import read_bag, read_bag_topics
from credcli.io.schema import InputFormat, LogSchema, TimeUnit
from credcli.io.text import (
    head_lines,
    numeric_line,
    read_text_table,
    seconds,
)
from credcli.io.trajectory import Trajectory

BAG_SUFFIXES = (".bag", ".db3", ".mcap")


# ---------------------------------------------------------------------------- sniffing


def sniff_format(path: Path) -> InputFormat:
    """The format of ``path`` from its extension and its first lines.

    In order: a directory or a ``.bag``, ``.db3`` or ``.mcap`` file is a ROS bag; Parquet
    and ``.npz`` are credcli logs; then the first 64 KiB of text decide: ``p_RS_R_x``
    (EuRoC), a ROS field name such as ``field.header.stamp`` (ROS CSV), credcli's
    ``truth_``/``est_``/``innov_``/``err_`` columns, a first data line of 8 or 20 numbers
    (TUM); anything else is read as a credcli log.

    Parameters
    ----------
    path : pathlib.Path
        The file or bag directory; it must exist.

    Returns
    -------
    InputFormat
        The format, never ``auto``.

    Raises
    ------
    CredcliError
        If a text file cannot be read.
    """
    if path.is_dir() or path.suffix.lower() in BAG_SUFFIXES:
        return InputFormat.ROSBAG
    if path.suffix.lower() in (".parquet", ".pq", ".npz"):
        return InputFormat.CREDCLI
    lines = head_lines(path)
    text = "\n".join(lines)
    if "p_RS_R_x" in text:
        return InputFormat.EUROC
    if re.search(
        r"(^|[,\s])(field\.)?(header\.stamp|pose\.pose\.position\.x|"
        r"pose\.position\.x|transform\.translation\.x)",
        text,
    ):
        return InputFormat.ROS_CSV
    if re.search(r"(^|[,\s#])(truth_|est_|innov_|err_)\d", text):
        return InputFormat.CREDCLI
    data = [ln for ln in lines if ln.strip() and not ln.lstrip().startswith("#")]
    if data and len(data[0].replace(",", " ").split()) in (8, 20) and numeric_line(data[0]):
        return InputFormat.TUM
    return InputFormat.CREDCLI


# ----------------------------------------------------------------------------- readers


def read_trajectory(
    path: Path,
    fmt: InputFormat,
    role: str,
    time_unit: TimeUnit = TimeUnit.AUTO,
    schema: LogSchema | None = None,
    topic: str | None = None,
) -> Trajectory:
    """One trajectory: the estimate (``role`` "estimate", with its covariance) or the
    truth (``role`` "truth") of a log in format ``fmt`` (``auto``: sniffed, and said).

    The trajectory is checked: finite values, non-zero quaternions (normalised), epochs
    sorted by time (a note says when they were not) and, for a truth, distinct stamps.

    Parameters
    ----------
    path : pathlib.Path
        The file, or a ROS2 bag directory.
    fmt : InputFormat
        Its format; ``auto`` to sniff it (:func:`sniff_format`).
    role : str
        ``"estimate"`` or ``"truth"``.
    time_unit : TimeUnit
        The unit of its stamps; ``auto`` (the default) decides from the format and the
        magnitude.
    schema : LogSchema or None
        The column names of a credcli log (default: ``LogSchema()``).
    topic : str or None
        The bag topic to read (None: the only one of a usable type); only for bags.

    Returns
    -------
    Trajectory
        Stamps in seconds, positions (or a credcli log's vector), quaternions and the
        claimed covariance where the format has them, and the notes on what was decided.

    Raises
    ------
    CredcliError
        If the file is missing or empty, is a directory but not read as a bag, has a
        ``topic`` but is not a bag, or cannot be read as its format (missing columns,
        NaN or Inf values, zero quaternions, repeated stamps).
    """
    path = Path(path)
    fmt, notes = _format_of(path, fmt, role, topic)
    if fmt is InputFormat.ROSBAG:
        traj = read_bag(path, topic, role, time_unit)
    elif path.is_dir():
        raise CredcliError(
            f"{path}: is a directory; only a ROS2 bag may be (use --{_flag(role)}-format rosbag)"
        )
    elif path.stat().st_size == 0:
        raise CredcliError(f"{path}: file is empty; expected a header row and epoch rows")
    elif fmt is InputFormat.CREDCLI:
        traj = _credcli(path, role, time_unit, schema or LogSchema())
    else:
        frame = read_text_table(path)
        reader = {InputFormat.TUM: _tum, InputFormat.EUROC: _euroc, InputFormat.ROS_CSV: _ros_csv}
        traj = reader[fmt](frame, path, time_unit)
    return _finished(traj, role, notes)


def read_bag_pair(
    path: Path,
    fmt: InputFormat,
    truth_fmt: InputFormat,
    time_unit: TimeUnit,
    topic: str | None,
    truth_topic: str | None,
) -> tuple[Trajectory, Trajectory] | None:
    """The estimate and the truth as two topics of the one bag at ``path``, read in one
    pass (:func:`credcli.io.rosbag.read_bag_topics`); None when ``path`` is not read as
    a bag for both.

    Parameters
    ----------
    path : pathlib.Path
        The bag file or ROS2 bag directory.
    fmt, truth_fmt : InputFormat
        The formats given for the estimate and the truth (``auto``: sniffed).
    time_unit : TimeUnit
        The ``time_unit`` given (bag stamps are seconds and nanoseconds; another unit
        only adds a note).
    topic, truth_topic : str or None
        The estimate's and the truth's topics (None: the only one of a usable type).

    Returns
    -------
    tuple of (Trajectory, Trajectory) or None
        The estimate and the truth, checked as by :func:`read_trajectory`; None when
        ``path`` is not a bag for both.

    Raises
    ------
    CredcliError
        If ``path`` does not exist, a topic is given for a file that is not a bag, or the
        bag or a topic cannot be read.
    """
    path = Path(path)
    fmt, notes = _format_of(path, fmt, "estimate", topic)
    truth_fmt, truth_notes = _format_of(path, truth_fmt, "truth", truth_topic)
    if fmt is not InputFormat.ROSBAG or truth_fmt is not InputFormat.ROSBAG:
        return None
    requests = [(topic, "estimate"), (truth_topic, "truth")]
    estimate, truth = read_bag_topics(path, requests, time_unit)
    return _finished(estimate, "estimate", notes), _finished(truth, "truth", truth_notes)


def _format_of(path: Path, fmt: InputFormat, role: str, topic: str | None):
    """The format of a file that exists (``auto``: sniffed, with the note that says so)."""
    if not path.exists():
        raise CredcliError(f"{path}: file not found")
    notes = []
    fmt = InputFormat(fmt)
    if fmt is InputFormat.AUTO:
        fmt = sniff_format(path)
        notes.append(f"{path}: read as {fmt.value} (--{_flag(role)}-format auto)")
    if topic is not None and fmt is not InputFormat.ROSBAG:
        flag = "`topic`" if role == "estimate" else "`truth_topic`"
        raise CredcliError(f"{path}: {flag} applies to bags, and this is a {fmt.value} file")
    return fmt, notes


def _finished(traj: Trajectory, role: str, notes: list[str]) -> Trajectory:
    traj = _checked(traj, role)
    return _with(traj, notes=tuple(notes) + traj.notes)


def _flag(role: str) -> str:
    return "truth" if role == "truth" else "input"


def _with(traj: Trajectory, **changes) -> Trajectory:

    return replace(traj, **changes)


def _column_values(frame, cols, source: str) -> np.ndarray:
    return numeric_columns(frame, list(cols), source)


def _tum(frame, path: Path, unit: TimeUnit) -> Trajectory:
    width = frame.shape[1]
    if width not in (8, 20):
        raise CredcliError(
            f"{path}: a TUM file has 8 columns (timestamp tx ty tz qx qy qz qw), or 20 with "
            f"OpenVINS's covariance columns; found {width}"
        )
    if len(set(frame.columns)) < width:  # a comment line's words, not names: by position
        frame = frame.set_axis([f"column {k + 1}" for k in range(width)], axis=1)
    values = _column_values(frame, list(frame.columns), str(path))
    time, note = seconds(values[:, 0], unit, None, str(path))
    cov = None
    if width == 20:  # Pr11 Pr12 Pr13 Pr22 Pr23 Pr33 Pt11 … Pt33 (ov_eval's layout)
        iu = np.triu_indices(3)
        cov = np.zeros((len(values), 6, 6))
        for offset, block in ((8, slice(3, 6)), (14, slice(0, 3))):
            sub = np.zeros((len(values), 3, 3))
            sub[:, iu[0], iu[1]] = values[:, offset : offset + 6]
            sub[:, iu[1], iu[0]] = values[:, offset : offset + 6]
            cov[:, block, block] = sub
    traj = _pose(time, values[:, 1:4], values[:, 4:8], cov, path, InputFormat.TUM, note)
    return traj if cov is None else _with(traj, cross_covariance=False)


def _euroc(frame, path: Path, unit: TimeUnit) -> Trajectory:
    by_name = {re.sub(r"[#\s]|\[.*?\]", "", str(c)).lower(): c for c in frame.columns}
    wanted = [
        "timestamp",
        "p_rs_r_x",
        "p_rs_r_y",
        "p_rs_r_z",
        "q_rs_x",
        "q_rs_y",
        "q_rs_z",
        "q_rs_w",
    ]
    missing = [w for w in wanted if w not in by_name]
    if missing:
        raise CredcliError(
            f"{path}: EuRoC ground truth needs the columns #timestamp, p_RS_R_x/y/z and "
            f"q_RS_w/x/y/z; missing {', '.join(missing)}"
        )
    values = _column_values(frame, [by_name[w] for w in wanted], str(path))
    time, note = seconds(values[:, 0], unit, TimeUnit.NS, str(path))
    return _pose(time, values[:, 1:4], values[:, 4:8], None, path, InputFormat.EUROC, note)


_ROS_POSITION = ("pose.pose.position.", "pose.position.", "transform.translation.")
_ROS_ORIENTATION = ("pose.pose.orientation.", "pose.orientation.", "transform.rotation.")
_ROS_COV = re.compile(r"^pose\.covariance[._]?(\d+)$")


def _ros_csv(frame, path: Path, unit: TimeUnit) -> Trajectory:
    names = {re.sub(r"^field\.", "", str(c)): c for c in frame.columns}
    source = str(path)
    time, note = _ros_stamps(frame, names, path, unit)
    position = quaternion = None
    for prefix in _ROS_POSITION:
        cols = [prefix + a for a in "xyz"]
        if all(c in names for c in cols):
            position = _column_values(frame, [names[c] for c in cols], source)
            break
    for prefix in _ROS_ORIENTATION:
        cols = [prefix + a for a in "xyzw"]
        if all(c in names for c in cols):
            quaternion = _column_values(frame, [names[c] for c in cols], source)
            break
    if position is None:
        raise CredcliError(
            f"{path}: no position columns (field.pose.pose.position.x/y/z, "
            "field.pose.position.x/y/z or field.transform.translation.x/y/z)"
        )
    cov = None
    found = {int(m.group(1)): c for n, c in names.items() if (m := _ROS_COV.match(n))}
    if not found and "pose.covariance" in names:  # one column of "[c0, c1, …, c35]" lists
        cov = _list_column(frame[names["pose.covariance"]], 36, path).reshape(-1, 6, 6)
    if found:
        if sorted(found) != list(range(36)):
            raise CredcliError(
                f"{path}: a ROS pose covariance has the 36 columns field.pose.covariance0 … 35; "
                f"found {len(found)}"
            )
        cov = _column_values(frame, [found[i] for i in range(36)], source).reshape(-1, 6, 6)
    return _pose(time, position, quaternion, cov, path, InputFormat.ROS_CSV, note)


def _list_column(series, width: int, path: Path) -> np.ndarray:
    """A column whose cells are lists written as text ("[0.1, 0.0, …]" or "(…)"); a cell
    of another length or with a word in it is named by its data row."""
    text = series.astype(str).str.strip("[]() ").str.replace(",", " ").str.split()
    lengths = text.str.len().to_numpy()
    wrong = np.flatnonzero(lengths != width)
    if wrong.size:
        k = int(wrong[0])
        raise CredcliError(
            f"{path}: column '{series.name}' must hold {width} numbers per row; data row "
            f"{k + 1} holds {int(lengths[k])}"
            + (f" ({wrong.size} rows in all)" if wrong.size > 1 else "")
        )
    try:
        return np.array(text.tolist(), dtype=float)
    except ValueError as exc:
        for k, cells in enumerate(text):
            try:
                np.array(cells, dtype=float)
            except ValueError:
                raise CredcliError(
                    f"{path}: column '{series.name}', data row {k + 1}: not a list of numbers "
                    f"({exc})"
                ) from exc
        raise


def _ros_stamps(frame, names: dict, path: Path, unit: TimeUnit):
    source = str(path)
    for sec, nsec in (
        ("header.stamp.secs", "header.stamp.nsecs"),
        ("header.stamp.sec", "header.stamp.nanosec"),
    ):
        if sec in names and nsec in names:
            parts = _column_values(frame, [names[sec], names[nsec]], source)
            return parts[:, 0] + 1e-9 * parts[:, 1], None
    for col in ("header.stamp", "%time", "time"):
        if col in names:
            raw = _column_values(frame, [names[col]], source)[:, 0]
            return seconds(raw, unit, TimeUnit.NS, f"{path} ({names[col]})")
    raise CredcliError(
        f"{path}: no stamp column (field.header.stamp, header.stamp.sec + nanosec, or %time)"
    )


def _pose(time, position, quaternion, cov, path, fmt, note) -> Trajectory:
    return Trajectory(
        time=np.asarray(time, dtype=float),
        position=np.ascontiguousarray(position, dtype=float),
        quaternion=None if quaternion is None else np.ascontiguousarray(quaternion, float),
        cov=cov,
        rows=np.arange(1, len(time) + 1),
        source=str(path),
        format=fmt,
        notes=(note,) if note else (),
    )


def _credcli(path: Path, role: str, unit: TimeUnit, schema: LogSchema) -> Trajectory:
    """The estimate (est_i and the covariance) or the truth (truth_i) of a credcli log."""
    frame = logs.read_table(path, columnwise=True)
    columns = [str(c) for c in frame.columns]
    frame.columns = columns
    source = str(path)
    if schema.time not in columns:
        raise CredcliError(
            f"{path}: no time column '{schema.time}'; pairing with a separate truth needs "
            "stamps (name the column with `time_column`)"
        )
    if role == "truth":
        cols = logs.vector_columns(
            columns, schema.truth_prefix, schema.truth_columns, "truth", source
        )
    else:
        cols = logs.vector_columns(
            columns, schema.estimate_prefix, schema.estimate_columns, "estimate", source
        )
    logs.check_not_orientation(cols, source)
    d = len(cols)
    cov = cov_cols = None
    if role != "truth":
        kind, cov_cols = logs.cov_layout(columns, schema, d, source)
    values = _column_values(frame, [schema.time, *cols, *(cov_cols or [])], source)
    rows = np.arange(1, len(values) + 1)
    bad = ~np.isfinite(values).all(axis=1)
    if bad.any():
        i = int(np.argmax(bad))
        raise CredcliError(f"{path}: row {rows[i]}: NaN, Inf or empty value; fix or remove the row")
    cov_notes: list[str] = []
    if cov_cols:
        cov_values = logs.build_cov(values[:, 1 + d :], kind, d)
        cov = logs.validated_cov(cov_values, rows, source, kind, notes=cov_notes)
    time, note = seconds(values[:, 0], unit, None, source)
    return Trajectory(
        time=time,
        position=np.ascontiguousarray(values[:, 1 : 1 + d]),
        quaternion=None,
        cov=cov,
        rows=rows,
        source=source,
        format=InputFormat.CREDCLI,
        pose=False,
        notes=(*((note,) if note else ()), *cov_notes),
    )


# ------------------------------------------------------------------------- validation


QUATERNION_NORM_NOTE = 1e-3
"""A written quaternion whose norm is further than this from 1 gets a note when it is
normalised (rounding in a text file stays far below it; a norm of 2 is a wrong column or
scale)."""


def _checked(traj: Trajectory, role: str) -> Trajectory:
    """Finite values, non-zero quaternions (normalised), a covariance for an estimate, and
    epochs sorted by time (a note says when they were not)."""
    src = traj.source
    parts = {"time": traj.time[:, None], "position": traj.position}
    if traj.quaternion is not None:
        parts["orientation"] = traj.quaternion
    if traj.cov is not None:
        parts["covariance"] = traj.cov.reshape(traj.cov.shape[0], -1)
    bad = {name: ~np.isfinite(values).all(axis=1) for name, values in parts.items()}
    where = np.logical_or.reduce(list(bad.values()))
    if where.any():
        i = int(np.argmax(where))
        what = next(name for name, rows in bad.items() if rows[i])
        raise CredcliError(
            f"{src}: row {traj.rows[i]}: NaN, Inf or empty value in the {role}'s {what}; fix or "
            "remove the row"
        )
    quaternion = traj.quaternion
    if quaternion is not None:
        with np.errstate(over="ignore"):
            norm = np.linalg.norm(quaternion, axis=1)
        huge = np.isinf(norm)  # components near 1e300: scaled by the largest one first
        if huge.any():
            peak = np.max(np.abs(quaternion[huge]), axis=1)
            quaternion = quaternion.copy()
            quaternion[huge] /= peak[:, None]
            norm[huge] = np.linalg.norm(quaternion[huge], axis=1)
        zero = ~(norm > 1e-9)
        if zero.any():
            i = int(np.argmax(zero))
            raise CredcliError(
                f"{src}: row {traj.rows[i]}: zero-norm quaternion; an orientation needs a unit "
                "quaternion (x, y, z, w)"
            )
        quaternion = quaternion / norm[:, None]
    notes = list(traj.notes)
    if quaternion is not None:
        off = np.flatnonzero(np.abs(norm - 1.0) > QUATERNION_NORM_NOTE)
        if off.size:  # not a unit quaternion as written: normalised, and said so
            notes.append(
                f"{src}: {off.size} quaternion(s) of norm far from 1 (first in row "
                f"{traj.rows[off[0]]}: {norm[off[0]]:.6g}) were normalised; check the "
                "orientation columns' order and units"
            )
    order = None
    if np.any(np.diff(traj.time) < 0):
        order = np.argsort(traj.time, kind="stable")
        notes.append(f"{src}: {role} epochs were not in time order; sorted by stamp")
    t = traj.time if order is None else traj.time[order]
    repeated = np.flatnonzero(np.diff(t) == 0)
    if repeated.size:  # truth: no interpolation; estimates: one epoch counted twice
        rows = traj.rows if order is None else traj.rows[order]
        why = "to interpolate" if role == "truth" else "(an epoch logged twice counts twice)"
        stamp = float(t[repeated[0]])
        step = float(np.spacing(stamp))  # seconds in float64 resolve no finer than this
        resolution = f" (to float64's {step:.2g} s here)" if step >= 1e-9 else ""
        raise CredcliError(
            f"{src}: rows {rows[repeated[0]]} and {rows[repeated[0] + 1]} have the same stamp "
            f"{stamp:.15g} s{resolution}; {role} stamps must be distinct {why}"
        )
    if order is None:
        return _with(traj, quaternion=quaternion, notes=tuple(notes))
    return _with(
        traj,
        time=traj.time[order],
        position=traj.position[order],
        quaternion=None if quaternion is None else quaternion[order],
        cov=None if traj.cov is None else traj.cov[order],
        rows=traj.rows[order],
        notes=tuple(notes),
    )
