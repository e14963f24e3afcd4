"""From the files a user has to one EstimatorLog: a credcli log as it is, or an estimate
paired by time with a separate ground truth, with the chosen states' errors.

Every decision taken for the user (format, time unit, pairing, dropped epochs, states and
convention) is kept in the log's ``notes``; the commands print them and record them.
"""

from __future__ import annotations

import contextlib
import dataclasses
from pathlib import Path

import numpy as np

from credcli.engine import lie
from credcli.engine.align import Alignment
from credcli.engine.config import Perturbation, States
from credcli.errors import CredcliError
from credcli.io.aligning import align_log, align_trajectory, fitted_mean
from credcli.io.arrays import load_npz
from credcli.io.formats import read_bag_pair, read_trajectory, sniff_format
from credcli.io.logs import (
    CovKind,
    EstimatorLog,
    LogSchema,
    OtherConvention,
    load_log,
    validated_cov,
)
from credcli.io.pairing import pair
from credcli.io.rosbag import check_bag_path
from credcli.io.schema import InputFormat, ReadOptions
from credcli.io.streams import display_name, needs_copy, readable
from credcli.io.trajectory import Trajectory
from credcli.logid import LogId
from credcli.system import release_free_memory

COVARIANCE_FORMATS = (
    "credcli, ros-csv with field.pose.covariance0..35, a rosbag Odometry or "
    "PoseWithCovarianceStamped topic, or TUM with OpenVINS's 20 columns"
)


def open_log(
    path: str | Path,
    schema: LogSchema | None = None,
    reading: ReadOptions | None = None,
    drop_invalid: bool = False,
) -> EstimatorLog:
    """The log at ``path`` read as ``reading`` says.

    Without a separate truth it is a credcli log with truth and estimate in each row
    (aligned as ``reading.align`` says), an errors-only or innovations log, or an ``.npz``
    of arrays; with one (``reading.truth`` or ``reading.truth_topic``), the estimate is
    paired with its truth by time and the chosen states' errors are taken. ``path`` (or the
    truth) may be a stream: ``-`` for standard input, a pipe or a FIFO, or a compressed
    file (:mod:`credcli.io.streams`), read through a private copy. What reading it freed
    goes back to the system.

    Parameters
    ----------
    path : str or pathlib.Path
        The log (or estimate) file, bag or stream.
    schema : LogSchema, optional
        The column names of a credcli log; default ``LogSchema()``.
    reading : ReadOptions, optional
        How the log is read and paired; default ``ReadOptions()``.
    drop_invalid : bool, default False
        Drop the rows of a credcli log with a NaN, Inf or empty value rather than refuse
        the log.

    Returns
    -------
    EstimatorLog
        The validated log. Its id (:class:`credcli.logid.LogId`) keeps ``path`` as given,
        and its ``notes`` name the stream, not the copy read.

    Raises
    ------
    CredcliError
        The options contradict each other or would be ignored (``align`` for errors given,
        pairing options without a truth, ``innovations`` or ``errors_only`` with a truth or
        a format other than credcli, a pose format without its truth, ``states`` that need
        orientations a credcli log does not have), or the files cannot be read, paired or
        validated.
    """
    reading = reading or ReadOptions()
    with contextlib.ExitStack() as stack:
        local = stack.enter_context(readable(path))
        if reading.truth is not None and needs_copy(reading.truth):
            truth = stack.enter_context(readable(reading.truth))
            reading = dataclasses.replace(reading, truth=str(truth))
        log = _read_log(local, schema, reading, drop_invalid)
        notes = log.notes
        name = log.id.name
        if local != Path(path):
            name = display_name(path)
            notes = tuple(note.replace(str(local), name) for note in log.notes)
        log = dataclasses.replace(log, id=LogId.of(name, path), notes=notes)
    release_free_memory()
    return log


def one_segment(path, schema: LogSchema | None, reading: ReadOptions | None) -> bool:
    """Whether the log at ``path`` is surely one segment, known before it is read: a local
    Parquet credcli log, not paired with a separate truth, whose columns hold neither the
    segment column nor the run column (read from its metadata, no data). False where that
    cannot be told without reading it (other formats, a URL, standard input).

    Parameters
    ----------
    path : str or pathlib.Path
        The log as given.
    schema : LogSchema or None
        Its column names (the segment and run columns).
    reading : ReadOptions or None
        How it is read (a separate truth pairs it).

    Returns
    -------
    bool
        True only where the log has no column that could cut it into segments or runs.
    """
    path = Path(path)
    if (reading is not None and reading.paired) or path.suffix.lower() != ".parquet":
        return False
    if not path.is_file():
        return False
    import pyarrow.parquet as pq

    schema = schema or LogSchema()
    try:
        names = set(pq.ParquetFile(path).schema_arrow.names)
    except (OSError, ValueError):  # the reader says what is wrong with it
        return False
    return schema.segment not in names and schema.run not in names


def _read_log(path: Path, schema, reading, drop_invalid: bool) -> EstimatorLog:
    schema = schema or LogSchema()
    reading = reading or ReadOptions()
    _check_options(reading)
    if reading.innovations:
        if reading.paired:
            raise CredcliError("`innovations` needs no ground truth: drop `truth`/`truth_topic`")
        _only_credcli(path, reading.input_format, "`innovations`")
        return load_log(path, schema, drop_invalid, reading.time_unit, innovations=True)
    if not reading.paired and Path(path).suffix.lower() == ".npz":
        return align_log(load_npz(Path(path)), reading.align)
    if reading.errors_only:
        if reading.paired:
            raise CredcliError("`errors_only` needs no ground truth: drop `truth`/`truth_topic`")
        _only_credcli(path, reading.input_format, "`errors_only`")
        return load_log(path, schema, drop_invalid, reading.time_unit, errors_only=True)
    if not reading.paired:
        fmt = reading.input_format
        if fmt is InputFormat.AUTO:
            fmt = sniff_format(path) if path.exists() else InputFormat.CREDCLI
        if fmt is InputFormat.ROSBAG:
            check_bag_path(path)
        if fmt is not InputFormat.CREDCLI:
            raise CredcliError(
                f"{path}: a {fmt.value} file has no ground truth beside the estimate; name it "
                "with `truth` FILE (or `truth_topic` for a bag)"
            )
        if reading.states not in (None, States.POSITION):
            raise CredcliError(
                f"{path}: `states` {reading.states.value} needs orientations, which a credcli "
                "log does not have; read a pose log (tum, euroc, ros-csv, rosbag) with `truth`"
            )
        return align_log(load_log(path, schema, drop_invalid, reading.time_unit), reading.align)
    return _paired_log(path, schema, reading)


def _check_options(reading: ReadOptions) -> None:
    """Options that would be silently ignored are errors."""
    if reading.align is not Alignment.NONE and (reading.innovations or reading.errors_only):
        kind = "an innovations" if reading.innovations else "an errors-only"
        raise CredcliError(
            f"`align` {reading.align.value} moves an estimate onto its truth; {kind} log has "
            "neither (its errors are given): drop `align`",
            "align",
        )
    if not reading.paired:
        unused = [
            flag
            for flag, given in (
                ("`max_dt`", reading.max_dt is not None),
                ("`time_offset`", reading.time_offset != 0),
                ("`truth_format`", reading.truth_format is not InputFormat.AUTO),
                ("`perturbation`", reading.perturbation is not Perturbation.LEFT),
                ("`topic`", reading.topic is not None),
            )
            if given
        ]
        if unused:
            raise CredcliError(
                f"{', '.join(unused)} appl{'ies' if len(unused) == 1 else 'y'} to a separate "
                "ground truth: give `truth` FILE (or `truth_topic` for a bag)"
            )


def _only_credcli(path: Path, fmt: InputFormat, what: str) -> None:
    if fmt not in (InputFormat.AUTO, InputFormat.CREDCLI):
        raise CredcliError(
            f"{path}: {what} reads credcli logs only; got `input_format` {fmt.value}"
        )


def _paired_log(path: Path, schema: LogSchema, reading: ReadOptions) -> EstimatorLog:
    """An estimate file (or bag topic) paired with its truth by time."""
    truth_path = Path(reading.truth) if reading.truth is not None else path
    both = None  # two topics of one bag are read in one pass
    if truth_path == Path(path):
        both = read_bag_pair(
            path,
            reading.input_format,
            reading.truth_format,
            reading.time_unit,
            reading.topic,
            reading.truth_topic,
        )

    def read(role: str, at: Path, fmt: InputFormat, topic: str | None) -> Trajectory:
        return read_trajectory(at, fmt, role, reading.time_unit, schema, topic)

    estimate = both[0] if both else read("estimate", path, reading.input_format, reading.topic)
    if estimate.cov is None:
        raise CredcliError(
            f"{estimate.source}: has no covariance; the estimate needs one ({COVARIANCE_FORMATS})"
        )
    truth = (
        both[1] if both else read("truth", truth_path, reading.truth_format, reading.truth_topic)
    )
    pairing = pair(estimate, truth, reading.max_dt, reading.time_offset)
    estimate, align_notes = align_trajectory(estimate, truth, pairing, reading)
    keep = pairing.keep
    rows = estimate.rows[keep]
    states, errors, cov, convention, other = _state_errors(estimate, truth, pairing, reading)
    try:
        cov_notes: list[str] = []
        cov = validated_cov(cov, rows, estimate.source, CovKind.FULL, notes=cov_notes)
    except CredcliError as exc:
        if states is States.PLANAR or not estimate.pose:
            raise
        raise CredcliError(
            f"{exc.message} (the {states.value} block of the 6×6 pose covariance; a planar "
            "robot that leaves z, roll and pitch at 0 needs `states` planar)"
        ) from exc
    notes = (*estimate.notes, *truth.notes, pairing.note, *align_notes, convention, *cov_notes)
    return EstimatorLog(
        None,
        None,
        cov,
        time=estimate.time[keep],
        rows=rows,
        id=LogId.of(str(path), path),
        state_errors=errors,
        notes=notes,
        unpaired=pairing.dropped,
        blocks=lie.STATE_BLOCKS.get(states, ()),
        fitted_mean=fitted_mean(reading.align),
        other_convention=other,
    )


def _state_errors(estimate: Trajectory, truth: Trajectory, pairing, reading: ReadOptions):
    """(states, errors, covariance, note on the convention, the errors under the other
    convention or None) of the paired epochs."""
    keep = pairing.keep
    if not (estimate.pose and truth.pose):
        if reading.states not in (None, States.POSITION):
            who = estimate if not estimate.pose else truth
            raise CredcliError(
                f"{who.source}: `states` {reading.states.value} needs orientations, which a "
                "credcli log does not have"
            )
        p_est = estimate.position[keep]
        if p_est.shape[1] != pairing.position.shape[1]:
            raise CredcliError(
                f"{estimate.source}: the estimate has {p_est.shape[1]} components but the truth "
                f"{truth.source} has {pairing.position.shape[1]}: dimensions do not match"
            )
        cov = estimate.cov[keep]
        if cov.shape[1] == 6 and p_est.shape[1] == 3:
            cov = lie.cov_block(cov, States.POSITION)
        return (
            States.POSITION,
            np.ascontiguousarray(pairing.position - p_est),
            cov,
            "errors: truth − estimate of the position vector (world frame)",
            None,
        )
    states = reading.states or States.POSITION
    right = reading.perturbation is Perturbation.RIGHT
    needs_rotation = states in lie.NEEDS_ORIENTATION or right
    r_est = r_true = None
    if needs_rotation:
        for traj in (estimate, truth):
            if traj.quaternion is None:
                raise CredcliError(
                    f"{traj.source}: has no orientation, which `states` {states.value}"
                    f"{' with `perturbation` right' if right else ''} needs"
                )
        from scipy.spatial.transform import Rotation

        r_est = Rotation.from_quat(estimate.quaternion[keep])
        r_true = pairing.rotation
    errors = lie.state_errors(
        states, reading.perturbation, pairing.position, estimate.position[keep], r_true, r_est
    )
    cov = lie.cov_block(estimate.cov[keep], states)
    note = _convention(states, reading.perturbation, estimate.cross_covariance)
    swap = None
    if states is not States.POSITION:
        other = Perturbation.LEFT if right else Perturbation.RIGHT
        swapped = lie.state_errors(
            states, other, pairing.position, estimate.position[keep], r_true, r_est
        )
        swap = OtherConvention(reading.perturbation, other, swapped)
    return states, errors, cov, note, swap


def _convention(states: States, perturbation: Perturbation, cross: bool = True) -> str:
    """The note of the errors taken, and of the covariance blocks read: ``cross`` False
    when the file holds the position and orientation blocks only (OpenVINS's layout)."""
    right = perturbation is Perturbation.RIGHT
    both = (
        "the whole 6×6 covariance"
        if cross
        else "the position and orientation 3×3 blocks of the covariance (the file has no "
        "position–orientation cross-covariance: taken as 0)"
    )
    position = "R_estᵀ(p_true − p_est) (body frame)" if right else "p_true − p_est (world frame)"
    rotation = "Log(R_estᵀ R_true)" if right else "Log(R_true R_estᵀ)"
    parts = {
        States.POSITION: f"position {position}; covariance rows x, y, z",
        States.ORIENTATION: f"orientation {rotation}; covariance rows rx, ry, rz",
        States.POSE: f"position {position} and orientation {rotation}; {both}",
        States.PLANAR: f"planar x, y of {position} and yaw ψ_true − ψ_est wrapped to (−π, π]; "
        "covariance rows x, y, rz",
    }[states]
    return f"errors (`states` {states.value}, `perturbation` {perturbation.value}): {parts}"
