"""Column layouts of estimator logs and how logs are read (plain Python: the command line
reads its defaults)."""

from __future__ import annotations

import enum
from dataclasses import dataclass, replace

from credcli.engine.config import Alignment, Perturbation, States
from credcli.errors import CredcliError


class CovKind(str, enum.Enum):
    """How the claimed covariance is stored (``LogSchema.cov_kind``).

    Attributes
    ----------
    FULL : "full"
        ``cov_i_j`` for every i, j.
    UPPER : "upper"
        ``cov_i_j`` for i <= j.
    VAR : "var"
        ``var_i``, a diagonal covariance.
    STD : "std"
        ``std_i``, a diagonal covariance.
    """

    FULL = "full"  # cov_i_j for every i, j
    UPPER = "upper"  # cov_i_j for i <= j
    VAR = "var"  # var_i, a diagonal covariance
    STD = "std"  # std_i, a diagonal covariance


@dataclass(frozen=True)
class LogSchema:
    """Column names of a log. Explicit column lists win over prefixes.

    Frozen; pass it as ``columns=`` of [credcli.read_log][credcli.api.read_log].

    Parameters
    ----------
    time, segment, run : str
        The time column, the segment column and the column of Monte Carlo run ids.
    truth_prefix, estimate_prefix : str
        The prefixes of the state columns (``truth_0``, ``est_0``, …).
    cov_prefix, var_prefix, std_prefix : str
        The prefixes of the covariance columns: ``cov_i_j``, ``var_i`` or ``std_i``.
    truth_columns, estimate_columns : tuple of str
        The state columns by name, one per component, in place of the prefixes.
    cov_columns : tuple of str
        The covariance columns by name, read by their length: d² entries are the full
        matrix in row-major order, d(d+1)/2 the upper triangle in row-major order, d the
        diagonal (variances, or standard deviations when ``cov_kind`` is ``std``).
    cov_kind : CovKind or None
        How the covariance is stored; None: from the columns found.

    Examples
    --------
    >>> schema = LogSchema().updated(time="t", cov_columns=["vx", "vy"], segment=None)
    >>> schema.time, schema.cov_columns, schema.segment
    ('t', ('vx', 'vy'), 'segment')
    """

    time: str = "time"
    segment: str = "segment"
    run: str = "run"  # Monte Carlo run ids (diagnose --monte-carlo pools them)
    truth_prefix: str = "truth_"
    estimate_prefix: str = "est_"
    cov_prefix: str = "cov_"
    var_prefix: str = "var_"
    std_prefix: str = "std_"
    truth_columns: tuple[str, ...] = ()
    estimate_columns: tuple[str, ...] = ()
    cov_columns: tuple[str, ...] = ()
    cov_kind: CovKind | None = None

    def updated(self, **changes) -> LogSchema:
        """A copy with the given non-None fields changed (for CLI > config > defaults).

        Parameters
        ----------
        **changes
            Fields and their new values; None leaves a field as it is.

        Returns
        -------
        LogSchema
            The changed copy.

        Raises
        ------
        CredcliError
            If a column list names one column twice.
        ValueError
            If ``cov_kind`` is not one of the names of ``CovKind``.
        TypeError
            If a name is not a field of LogSchema.
        """
        changes = {k: v for k, v in changes.items() if v is not None}
        for key in ("truth_columns", "estimate_columns", "cov_columns"):
            if key in changes:
                changes[key] = tuple(changes[key])
                twice = sorted({c for c in changes[key] if changes[key].count(c) > 1})
                if twice:
                    raise CredcliError(
                        f"`{key}` names column '{twice[0]}' twice; each column is one component",
                        key,
                    )
        if "cov_kind" in changes:
            changes["cov_kind"] = CovKind(changes["cov_kind"])
        return replace(self, **changes)


class InputFormat(str, enum.Enum):
    """File layouts a log (or its ground truth) may come in."""

    AUTO = "auto"  # from the extension and the header, said in a note
    CREDCLI = "credcli"  # the column convention above; CSV, whitespace text or Parquet
    TUM = "tum"  # timestamp tx ty tz qx qy qz qw [+ OpenVINS's 12 covariance columns]
    EUROC = "euroc"  # #timestamp, p_RS_R_x [m], …, q_RS_w [], … (ns)
    ROS_CSV = "ros-csv"  # rostopic echo -p / bag-to-CSV exports (field.pose.pose.position.x, …)
    ROSBAG = "rosbag"  # ROS1 .bag file or ROS2 bag directory (needs credcli[ros])


class TimeUnit(str, enum.Enum):
    """Unit of a time column; ``auto`` decides from the format and the magnitude."""

    AUTO = "auto"
    S = "s"
    MS = "ms"
    US = "us"
    NS = "ns"

    @property
    def seconds(self) -> float:
        return {"s": 1.0, "ms": 1e-3, "us": 1e-6, "ns": 1e-9}[self.value]


@dataclass(frozen=True)
class ReadOptions:
    """How logs are read and paired with a separate ground truth (CLI > [input] > these).

    ``max_dt`` None: 2.5 × the median truth period. ``time_offset`` (s) is added to the
    estimate stamps. ``states`` None: ``position`` for pose data, the vector itself for a
    credcli log. ``align``: how the estimate's world frame is moved onto the truth's
    before errors are taken (:mod:`credcli.engine.align`; docs/formats.md, "Aligning
    frames").

    Attributes
    ----------
    truth : str or None
        A separate ground-truth file or bag; None when the truth is in the estimate's rows
        (or is ``truth_topic`` of the estimate's bag).
    input_format, truth_format : InputFormat
        The layouts of the log and of the truth; ``auto`` (the default) sniffs them.
    topic, truth_topic : str or None
        The bag topics of the estimate and the truth; None: the only one of a usable type.
    time_unit : TimeUnit
        The unit of the stamps; ``auto`` decides from the format and the magnitude.
    max_dt : float or None
        The widest gap (s) between the truth samples an estimate stamp is interpolated
        from; None: 2.5 × the median truth period.
    time_offset : float
        Seconds added to the estimate stamps before pairing.
    states : States or None
        Which error of a pose log is diagnosed; None: ``position`` for pose data, the
        vector itself for a credcli log.
    perturbation : Perturbation
        Where the orientation error acts: ``left`` (world frame, the default) or
        ``right`` (body frame).
    innovations : bool
        The log holds a filter's innovations and their covariance S (NIS, no truth).
    errors_only : bool
        The log holds errors (``err_i``, or the truth columns named), not truth and
        estimate.
    align : Alignment
        How the estimate's world frame is moved onto the truth's: ``none`` (the default),
        ``origin``, ``se3`` or ``sim3``.

    Raises
    ------
    CredcliError
        If ``max_dt`` is not positive or ``time_offset`` is not a number.
    ValueError
        If a format, unit, perturbation, alignment or ``states`` is not one of its names.
    """

    truth: str | None = None
    input_format: InputFormat = InputFormat.AUTO
    truth_format: InputFormat = InputFormat.AUTO
    topic: str | None = None
    truth_topic: str | None = None
    time_unit: TimeUnit = TimeUnit.AUTO
    max_dt: float | None = None
    time_offset: float = 0.0
    states: States | None = None
    perturbation: Perturbation = Perturbation.LEFT
    innovations: bool = False
    errors_only: bool = False  # the log holds errors (err_i or the truth columns named)
    align: Alignment = Alignment.NONE

    def __post_init__(self) -> None:
        for name, kind in (
            ("input_format", InputFormat),
            ("truth_format", InputFormat),
            ("time_unit", TimeUnit),
            ("perturbation", Perturbation),
            ("align", Alignment),
        ):
            object.__setattr__(self, name, kind(getattr(self, name)))
        if self.states is not None:
            object.__setattr__(self, "states", States(self.states))
        if self.max_dt is not None and not self.max_dt > 0:
            raise CredcliError(f"`max_dt` must be > 0 seconds; got {self.max_dt}", "max_dt")
        if not isinstance(self.time_offset, (int, float)) or self.time_offset != self.time_offset:
            raise CredcliError(
                f"`time_offset` must be a number of seconds; got {self.time_offset}", "time_offset"
            )

    @property
    def paired(self) -> bool:
        """Whether the truth comes from elsewhere than the estimate's rows."""
        return self.truth is not None or self.truth_topic is not None

    def updated(self, **changes) -> ReadOptions:
        """A copy with the given non-None fields changed (for CLI > config > defaults).

        Parameters
        ----------
        **changes
            Fields and their new values; None leaves a field as it is.

        Returns
        -------
        ReadOptions
            The changed copy, checked as a new one is.
        """
        return replace(self, **{k: v for k, v in changes.items() if v is not None})


@dataclass(frozen=True)
class LogReading:
    """How logs are read and cut into segments: the column layout, the reading options,
    whether rows with NaN/Inf are dropped, and the segmentation (``window`` a duration or
    an epoch count; ``whole``: each log one segment; neither: the segment column).

    Attributes
    ----------
    schema : LogSchema
        The column names of the logs.
    options : ReadOptions
        How the logs are read and paired with a separate ground truth.
    drop_invalid : bool
        Drop the rows with a NaN, Inf or empty value (counted, with a note) rather than
        refuse the log.
    window : str or None
        The windows' length: a duration (``5s``, ``250ms``, ``2min``) or an epoch count
        (``200``); None for no windows.
    whole : bool
        Each log one segment, whatever its segment column.
    """

    schema: LogSchema = LogSchema()
    options: ReadOptions = ReadOptions()
    drop_invalid: bool = False
    window: str | None = None
    whole: bool = False


@dataclass(frozen=True)
class RangeReading:
    """How a STAR-loc ``uwb.csv`` is read (the reader's part of the UWB settings,
    :class:`credcli.studies.settings.UwbSettings`): the ``range_column``; ``std``, a fixed
    range std (m) for files without a ``std`` column; ``std_by_anchor``, one per anchor id
    (over ``std`` and the column); ``std_estimate``: each anchor's estimated from the data.

    Attributes
    ----------
    range_column : str
        The range column; the default, ``range_calib``, falls back to the raw ``range``
        (with a note) in files without it (setup s5).
    std : float or None
        A fixed range std (m), for files without a ``std`` column; where there is one, it
        replaces the column.
    std_by_anchor : tuple of (int, float)
        A range std (m) per anchor id, over ``std`` and the column.
    std_estimate : bool
        Estimate each anchor's std from the data: 1.4826 × the median absolute deviation
        of range − gt_range.
    """

    range_column: str = "range_calib"
    std: float | None = None
    std_by_anchor: tuple[tuple[int, float], ...] = ()
    std_estimate: bool = False
