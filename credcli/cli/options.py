"""Every command-line option, declared once, and the groups the commands share.

A command lists its groups (:class:`LogOptions`, :class:`RuleOptions`, …) as parameters;
:func:`declare` spreads each group into its options for Typer and hands the command one
frozen dataclass per group. The defaults shown in ``--help`` are read from the settings
dataclasses; an option left out is None, so that a config file can set it
(:mod:`credcli.cli.settings`).
"""

from __future__ import annotations

import dataclasses
import enum
import functools
import inspect
import typing
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated

import typer

from credcli.ci.thresholds import Thresholds
from credcli.engine.config import DiagnosisConfig, MetricsLevel, SlowErrors, SrdForm, Variant
from credcli.io.schema import (
    Alignment,
    CovKind,
    InputFormat,
    LogSchema,
    Perturbation,
    States,
    TimeUnit,
)
from credcli.report.formats import OutputFormat
from credcli.studies.settings import RobustLoss, SimulationConfig, UwbSettings

FIELD_OPTIONS = {
    "tau_nci": "tau",
    "n_flips": "flips",
    "c": "probe_factor",
    "time": "time_column",
    "segment": "segment_column",
}
"""Settings fields set by an option of another name (DiagnosisConfig.n_flips is --flips,
LogSchema.time is --time-column); every other field is set by the option of its name."""

# The panels of --help; each option names its panel where it is declared.
INPUT = "Input"
COLUMNS = "Columns"
SEGMENTS = "Segments"
RULE = "Rule"
OUTPUT = "Output"
CI = "CI"
RUN = "Run"
STUDY = "Study"
UWB = "UWB"

_D = DiagnosisConfig()
_S = SimulationConfig()
_U = UwbSettings()
_T = Thresholds()
_L = LogSchema()


def _range_text(pair) -> str:
    """A (lo, hi) range as the command line writes it, ``lo:hi``."""
    return f"{pair[0]:g}:{pair[1]:g}"


LOG_FORMATS = (
    "credcli CSV/Parquet (also gzip, bzip2, xz), TUM, OpenVINS, EuRoC, ros-csv, ROS1 bag, ROS2 bag "
    "(with --truth for a separate ground truth), or innovations (--innovations)"
)


def file_name(text: str) -> Path:
    """A path typed on the command line; never empty (``Path("")`` would read ``.``).

    Parameters
    ----------
    text : str
        The argument as typed.

    Returns
    -------
    Path
        The path.

    Raises
    ------
    typer.BadParameter
        If ``text`` is empty.
    """
    if not text:
        raise typer.BadParameter("an empty file name; give a path")
    return Path(text)


def _directory_name(text: str) -> Path:
    """:func:`file_name` for a directory to write into (``--plots``), which refuses ``-``
    too: it names standard output for a file, and has no directory."""
    if text == "-":
        raise typer.BadParameter("'-' is standard output, not a directory; give a directory")
    return file_name(text)


def output_name(text: str) -> Path:
    """A file to write: not empty, and not a name ending in '/' (a directory).

    Parameters
    ----------
    text : str
        The argument as typed.

    Returns
    -------
    Path
        The path.

    Raises
    ------
    typer.BadParameter
        If ``text`` is empty or ends with '/'.
    """
    if text.endswith("/"):
        raise typer.BadParameter(f"{text!r} ends with '/', a directory; give a file name")
    return file_name(text)


# Options shared by the commands that diagnose (declared once, reused).
ConfigOpt = Annotated[
    Path | None,
    typer.Option(
        "--config",
        parser=file_name,
        metavar="FILE",
        help="TOML config file (see configs/).",
        rich_help_panel=INPUT,
    ),
]
FormatOpt = Annotated[
    OutputFormat,
    typer.Option(
        "--format", "-f", help="Output format.", case_sensitive=False, rich_help_panel=OUTPUT
    ),
]
OutputOpt = Annotated[
    Path | None,
    typer.Option(
        "--output",
        "-o",
        parser=output_name,
        metavar="FILE",
        help="Write the output to FILE (atomically).",
        rich_help_panel=OUTPUT,
    ),
]
SeedOpt = Annotated[
    int | None,
    typer.Option(
        "--seed", help=f"Seed of the ELT sign flips [default: {_S.seed}].", rich_help_panel=RULE
    ),
]
TauOpt = Annotated[
    float | None,
    typer.Option(
        "--tau",
        help="calibrated (default): the smallest covariance misfit worth a label, "
        "|10 log10 κ̂| > τ dB; paper and ks: the NCI threshold of Algorithm 1 "
        f"[default: {_D.tau_nci}].",
        rich_help_panel=RULE,
    ),
]
AlphaOpt = Annotated[
    float | None,
    typer.Option(
        "--alpha",
        help="calibrated (default): the false-alarm level per segment, split by Šidák "
        "between the location and the scale test; paper and ks: the ELT's level "
        f"[default: {_D.alpha}].",
        rich_help_panel=RULE,
    ),
]
COpt = Annotated[
    float | None,
    typer.Option(
        "--probe-factor", "-c", help=f"Probe scale c > 1 [default: {_D.c}].", rich_help_panel=RULE
    ),
]
FlipsOpt = Annotated[
    int | None,
    typer.Option(
        "--flips", "-B", help=f"ELT sign flips B [default: {_D.n_flips}].", rich_help_panel=RULE
    ),
]
BlockOpt = Annotated[
    str | None,
    typer.Option(
        "--block-length",
        help="Epochs per ELT sign block, or auto (estimated from the serial dependence in the "
        f"calibrated variant; 1 in paper and ks) [default: {_D.block_length}].",
        rich_help_panel=RULE,
    ),
]
VariantOpt = Annotated[
    Variant | None,
    typer.Option(
        "--variant",
        help="Decision rule: calibrated (level-α tests, dependence-aware), ks (the authors' "
        f"code) or paper (Algorithm 1 as printed) [default: {_D.variant.value}].",
        rich_help_panel=RULE,
    ),
]
SrdOpt = Annotated[
    SrdForm | None,
    typer.Option(
        "--srd-form",
        help=f"SRD of Eq. (19): printed or absolute [default: {_D.srd_form.value}].",
        rich_help_panel=RULE,
    ),
]
MetricsOpt = Annotated[
    MetricsLevel | None,
    typer.Option(
        "--metrics",
        help="needed: probes only where Algorithm 1 uses them; all: always "
        f"[default: {_D.metrics.value}].",
        rich_help_panel=RULE,
    ),
]
SchedulerOpt = Annotated[
    str | None,
    typer.Option(
        "--scheduler",
        help="Run on a Dask cluster: its scheduler's address (tcp://host:8786 on this "
        "machine, tls://host:8786 elsewhere), or local:N for N local workers (needs "
        "credcli[dask]; docs/scale.md). Default: $CREDCLI_SCHEDULER, announced on stderr.",
        rich_help_panel=RUN,
    ),
]
JobsOpt = Annotated[
    int | None,
    typer.Option(
        "--jobs",
        "-j",
        help="Worker processes (same output for any value; a log is shared among them from "
        "50,000 epochs on) [default: the number of cores].",
        rich_help_panel=RUN,
    ),
]
ExactOpt = Annotated[
    bool | None,
    typer.Option(
        "--exact-pvalue",
        help="Evaluate all B sign flips (default: stop once the ELT cannot reject; the label "
        "is the same, the p-value then sequential).",
        rich_help_panel=RULE,
    ),
]
SlowErrorsOpt = Annotated[
    SlowErrors | None,
    typer.Option(
        "--slow-errors",
        help="Whether the errors may hold memory slower than a segment: possible (an "
        "offset the claimed covariance covers is insufficient-data, since a bias and such "
        "an error give the same data, and so are a short segment's bias and a pessimism "
        "such an error fits well), excluded (it is a bias: pessimism+bias), expected (a "
        "pessimism, or a bias such an error explains at the mean test's level, is declined "
        "too), or auto (possible for a log; simulate knows its draws) "
        f"[default: {_D.slow_errors.value}].",
        rich_help_panel=RULE,
    ),
]
KsAlphaOpt = Annotated[
    float | None,
    typer.Option(
        "--ks-alpha",
        help=f"Level of the KS check of the ks variant [default: {_D.ks_alpha}].",
        rich_help_panel=RULE,
    ),
]
NeesAlphaOpt = Annotated[
    float | None,
    typer.Option(
        "--nees-alpha",
        help=f"Level of the NEES baseline's χ² test [default: {_D.nees_alpha}].",
        rich_help_panel=RULE,
    ),
]
MinEpochsOpt = Annotated[
    int | None,
    typer.Option(
        "--min-epochs",
        help=f"Smallest segment diagnosed [default: {_D.min_epochs}].",
        rich_help_panel=RULE,
    ),
]
MaxEltOpt = Annotated[
    int | None,
    typer.Option(
        "--max-elt-epochs",
        help=f"ELT memory budget in epochs [default: {_D.max_elt_epochs}].",
        rich_help_panel=RULE,
    ),
]


FailOnOpt = Annotated[
    str | None,
    typer.Option(
        "--fail-on",
        help="Exit 1 if a segment fails any of these (comma-separated): a condition "
        "(optimism, pessimism, smm: every label containing it), a combined label "
        "(optimism+smm: that label only), insufficient-data, untested (a partial verdict), "
        "or noncredible (all but a complete credible).",
        rich_help_panel=CI,
    ),
]
MonteCarloOpt = Annotated[
    bool,
    typer.Option(
        "--monte-carlo",
        help="The logs are independent runs of one scenario: pool them, and test the "
        "per-epoch ANEES.",
        rich_help_panel=SEGMENTS,
    ),
]
LogsArg = Annotated[
    list[Path],
    typer.Argument(
        parser=file_name,
        metavar="LOG...",
        help=f"Estimator logs: {LOG_FORMATS}; '-' reads standard input.",
        show_default=False,
    ),
]
WindowOpt = Annotated[
    str | None,
    typer.Option(
        "--window",
        "-w",
        help="Split into windows: a duration (5s, 250ms) or an epoch count (200).",
        rich_help_panel=SEGMENTS,
    ),
]
WholeOpt = Annotated[
    bool | None,
    typer.Option("--whole", help="Diagnose each log as one segment.", rich_help_panel=SEGMENTS),
]
TimeColOpt = Annotated[
    str | None,
    typer.Option(
        "--time-column", help=f"Time column [default: {_L.time}].", rich_help_panel=COLUMNS
    ),
]
SegColOpt = Annotated[
    str | None,
    typer.Option(
        "--segment-column", help=f"Segment column [default: {_L.segment}].", rich_help_panel=COLUMNS
    ),
]
TruthColsOpt = Annotated[
    str | None,
    typer.Option(
        "--truth-columns", help="Truth columns, comma-separated.", rich_help_panel=COLUMNS
    ),
]
EstColsOpt = Annotated[
    str | None,
    typer.Option(
        "--estimate-columns", help="Estimate columns, comma-separated.", rich_help_panel=COLUMNS
    ),
]
CovColsOpt = Annotated[
    str | None,
    typer.Option(
        "--cov-columns",
        help="Covariance columns, comma-separated: d² (full), d(d+1)/2 (upper) or d.",
        rich_help_panel=COLUMNS,
    ),
]
CovKindOpt = Annotated[
    CovKind | None,
    typer.Option(
        "--cov-kind", help="How --cov-columns store the covariance.", rich_help_panel=COLUMNS
    ),
]
DropOpt = Annotated[
    bool | None,
    typer.Option(
        "--drop-invalid", help="Drop rows with NaN/Inf instead of failing.", rich_help_panel=INPUT
    ),
]
TruthOpt = Annotated[
    Path | None,
    typer.Option(
        "--truth",
        parser=file_name,
        metavar="FILE",
        help="Ground truth in a separate file (or bag), paired by time.",
        rich_help_panel=INPUT,
    ),
]
InputFormatOpt = Annotated[
    InputFormat | None,
    typer.Option(
        "--input-format",
        help="Format of the logs [default: auto, from the file].",
        rich_help_panel=INPUT,
    ),
]
TruthFormatOpt = Annotated[
    InputFormat | None,
    typer.Option(
        "--truth-format",
        help="Format of --truth [default: auto, from the file].",
        rich_help_panel=INPUT,
    ),
]
TopicOpt = Annotated[
    str | None,
    typer.Option(
        "--topic",
        help="Bag topic of the estimate (Odometry or PoseWithCovarianceStamped).",
        rich_help_panel=INPUT,
    ),
]
TruthTopicOpt = Annotated[
    str | None,
    typer.Option(
        "--truth-topic",
        help="Bag topic of the truth (PoseStamped, Odometry, TransformStamped).",
        rich_help_panel=INPUT,
    ),
]
TimeUnitOpt = Annotated[
    TimeUnit | None,
    typer.Option(
        "--time-unit",
        help="Unit of the stamps [default: auto, said in a note].",
        rich_help_panel=INPUT,
    ),
]
MaxDtOpt = Annotated[
    float | None,
    typer.Option(
        "--max-dt",
        help="Interpolate truth only across gaps up to this (s) [default: 2.5 × its median period].",
        rich_help_panel=INPUT,
    ),
]
TimeOffsetOpt = Annotated[
    float | None,
    typer.Option(
        "--time-offset",
        help="Seconds added to the estimate stamps [default: 0].",
        rich_help_panel=INPUT,
    ),
]
StatesOpt = Annotated[
    States | None,
    typer.Option(
        "--states",
        help="Errors of pose logs: position, orientation, pose or planar [default: position].",
        rich_help_panel=INPUT,
    ),
]
PerturbationOpt = Annotated[
    Perturbation | None,
    typer.Option(
        "--perturbation",
        help="Orientation error convention (docs/formats.md: Conventions) [default: left].",
        rich_help_panel=INPUT,
    ),
]
AlignOpt = Annotated[
    Alignment | None,
    typer.Option(
        "--align",
        help="Move an estimate in its own world frame (VIO, SLAM) onto the truth's: origin "
        "(first pose), se3 or sim3 (Umeyama fit; fitting removes error, docs/formats.md: "
        "Aligning frames) [default: none].",
        rich_help_panel=INPUT,
    ),
]
ErrorsOnlyOpt = Annotated[
    bool | None,
    typer.Option(
        "--errors-only",
        help="The logs hold errors e_k (err_i, or the columns --truth-columns names) and "
        "their covariance, no truth or estimate (found by itself for err_i columns).",
        rich_help_panel=INPUT,
    ),
]
InnovationsOpt = Annotated[
    bool | None,
    typer.Option(
        "--innovations",
        help="The logs hold innovations innov_i and innov_cov_i_j: NIS, no truth.",
        rich_help_panel=INPUT,
    ),
]
JunitOpt = Annotated[
    Path | None,
    typer.Option(
        "--junit",
        parser=output_name,
        metavar="FILE",
        help="Write a JUnit XML report (one case per segment).",
        rich_help_panel=CI,
    ),
]
PlotsOpt = Annotated[
    Path | None,
    typer.Option(
        "--plots",
        parser=_directory_name,
        metavar="DIR",
        help="Write PNG figures into this directory (needs credcli[plots]).",
        rich_help_panel=OUTPUT,
    ),
]
SummaryOpt = Annotated[
    Path | None,
    typer.Option(
        "--summary",
        parser=output_name,
        metavar="FILE",
        help="Write a Markdown summary (also appended to $GITHUB_STEP_SUMMARY when set).",
        rich_help_panel=CI,
    ),
]


ReportOpt = Annotated[
    Path | None,
    typer.Option(
        "--report",
        parser=output_name,
        metavar="FILE",
        help="Also write a self-contained HTML report.",
        rich_help_panel=OUTPUT,
    ),
]


class ScreenMode(str, enum.Enum):
    """``--screen``: drop stale packets and packets failing the residual test (``all``), or
    nothing (``none``)."""

    ALL = "all"
    NONE = "none"


# The groups. Field order is the order of --help; a field's name is its parameter name.


@dataclass(frozen=True)
class SegmentOptions:
    """How a log is cut into segments: [segments] of a config file.

    Attributes
    ----------
    window : str or None
        ``--window``: windows of a duration (5s, 250ms) or an epoch count (200).
    whole : bool or None
        ``--whole``: each log one segment.
    """

    window: WindowOpt = None
    whole: WholeOpt = None


@dataclass(frozen=True)
class LogOptions:
    """How a log is read: [columns] and [input] of a config file, and --drop-invalid.

    Each field is its option (``time_column`` is ``--time-column``); None where not given.

    Attributes
    ----------
    time_column, segment_column : str or None
        The time and segment columns.
    truth_columns, estimate_columns, cov_columns : str or None
        The truth, estimate and covariance columns, comma-separated.
    cov_kind : CovKind or None
        How the covariance columns store the covariance.
    drop_invalid : bool or None
        Drop rows with NaN/Inf instead of failing.
    truth : Path or None
        Ground truth in a separate file (or bag), paired by time.
    input_format, truth_format : InputFormat or None
        The formats of the logs and of ``truth`` (default: from the file).
    topic, truth_topic : str or None
        The bag topics of the estimate and of the truth.
    time_unit : TimeUnit or None
        The unit of the stamps (default: detected, said in a note).
    max_dt : float or None
        The longest gap (s) across which truth is interpolated.
    time_offset : float or None
        Seconds added to the estimate stamps.
    states : States or None
        The errors of pose logs: position, orientation, pose or planar.
    perturbation : Perturbation or None
        The orientation error convention.
    align : Alignment or None
        How an estimate in its own world frame is moved onto the truth's.
    innovations : bool or None
        The logs hold innovations and their covariances (NIS, no truth).
    errors_only : bool or None
        The logs hold errors and their covariance, no truth or estimate.
    """

    time_column: TimeColOpt = None
    segment_column: SegColOpt = None
    truth_columns: TruthColsOpt = None
    estimate_columns: EstColsOpt = None
    cov_columns: CovColsOpt = None
    cov_kind: CovKindOpt = None
    drop_invalid: DropOpt = None
    truth: TruthOpt = None
    input_format: InputFormatOpt = None
    truth_format: TruthFormatOpt = None
    topic: TopicOpt = None
    truth_topic: TruthTopicOpt = None
    time_unit: TimeUnitOpt = None
    max_dt: MaxDtOpt = None
    time_offset: TimeOffsetOpt = None
    states: StatesOpt = None
    perturbation: PerturbationOpt = None
    align: AlignOpt = None
    innovations: InnovationsOpt = None
    errors_only: ErrorsOnlyOpt = None


@dataclass(frozen=True)
class RuleOptions:
    """How a segment is judged: [diagnosis] of a config file (the seed is its own option).

    Each field is its option (``probe_factor`` is ``--probe-factor``) and sets the
    DiagnosisConfig field of its name, except ``tau`` (``tau_nci``), ``probe_factor``
    (``c``) and ``flips`` (``n_flips``); None where not given.

    Attributes
    ----------
    tau : float or None
        The calibrated rule's smallest misfit worth a label (dB); the NCI threshold of
        paper and ks.
    alpha : float or None
        The calibrated rule's false-alarm level per segment; the ELT's level in paper
        and ks.
    probe_factor : float or None
        The probe scale c > 1.
    flips : int or None
        The ELT's sign flips B.
    block_length : str or None
        Epochs per ELT sign block, or ``auto``.
    variant : Variant or None
        The decision rule: calibrated, ks or paper.
    srd_form : SrdForm or None
        The SRD of Eq. (19): printed or absolute.
    metrics : MetricsLevel or None
        Probes only where Algorithm 1 uses them (needed), or always (all).
    min_epochs : int or None
        The smallest segment diagnosed.
    max_elt_epochs : int or None
        The ELT's memory budget in epochs.
    ks_alpha : float or None
        The level of the ks variant's KS check.
    nees_alpha : float or None
        The level of the NEES baseline's chi-squared test.
    exact_pvalue : bool or None
        Evaluate all B sign flips instead of stopping once the ELT cannot reject.
    slow_errors : SlowErrors or None
        Whether the errors may hold memory slower than a segment (auto, possible,
        excluded).
    """

    tau: TauOpt = None
    alpha: AlphaOpt = None
    probe_factor: COpt = None
    flips: FlipsOpt = None
    block_length: BlockOpt = None
    variant: VariantOpt = None
    srd_form: SrdOpt = None
    metrics: MetricsOpt = None
    min_epochs: MinEpochsOpt = None
    max_elt_epochs: MaxEltOpt = None
    ks_alpha: KsAlphaOpt = None
    nees_alpha: NeesAlphaOpt = None
    exact_pvalue: ExactOpt = None
    slow_errors: SlowErrorsOpt = None


@dataclass(frozen=True)
class RunOptions:
    """Where the work runs: local processes or a Dask cluster.

    Attributes
    ----------
    jobs : int or None
        ``--jobs``: worker processes (default: the number of cores).
    scheduler : str or None
        ``--scheduler``: a Dask scheduler's address, or ``local:N``.
    """

    jobs: JobsOpt = None
    scheduler: SchedulerOpt = None


@dataclass(frozen=True)
class OutputOptions:
    """What is printed or written, in which format.

    Attributes
    ----------
    fmt : OutputFormat
        ``--format`` (default: a table).
    output : Path or None
        ``--output``: the file to write (default: stdout).
    """

    fmt: FormatOpt = OutputFormat.TABLE
    output: OutputOpt = None


@dataclass(frozen=True)
class VerdictOptions:
    """A CI verdict: exit 1 on the conditions of --fail-on, JUnit and Markdown reports.

    Attributes
    ----------
    fail_on : str or None
        ``--fail-on``: the conditions, comma-separated.
    junit : Path or None
        ``--junit``: the JUnit XML report (one case per segment).
    summary : Path or None
        ``--summary``: the Markdown summary.
    """

    fail_on: FailOnOpt = None
    junit: JunitOpt = None
    summary: SummaryOpt = None


def _default(value) -> str:
    return f"[default: {getattr(value, 'value', value)}]"


@dataclass(frozen=True)
class ThresholdOptions:
    """When the gate fails: [gate] of a config file.

    Attributes
    ----------
    max_nci_increase : float or None
        Fail when |NCI| grows by more than this (dB).
    max_anees_ratio : float or None
        Fail when ANEES moves further from 1 by more than this factor.
    allow_new_segments : bool or None
        New or missing segments are reported, not failures.
    """

    max_nci_increase: Annotated[
        float | None,
        typer.Option(
            "--max-nci-increase",
            help="Fail when |NCI| grows by more than this (dB) "
            + _default(_T.max_nci_increase)
            + ".",
            rich_help_panel=CI,
        ),
    ] = None
    max_anees_ratio: Annotated[
        float | None,
        typer.Option(
            "--max-anees-ratio",
            help="Fail when ANEES moves further from 1 by more than this factor "
            + _default(_T.max_anees_ratio)
            + ".",
            rich_help_panel=CI,
        ),
    ] = None
    allow_new_segments: Annotated[
        bool | None,
        typer.Option(
            "--allow-new-segments",
            help="New or missing segments are reported, not failures.",
            rich_help_panel=CI,
        ),
    ] = None


@dataclass(frozen=True)
class StudyOptions:
    """The Monte Carlo study's design: [simulate] of a config file.

    Attributes
    ----------
    trials : int or None
        Trials per scenario.
    n : int or None
        Epochs per trial.
    dim : int or None
        The state dimension d.
    rho_optimism, rho_pessimism : str or None
        The ranges of ρ for optimism and pessimism, ``lo:hi``.
    bias : str or None
        The range of the mean error's norm ‖μ‖ for SMM, ``lo:hi``.
    eigenvalues : str or None
        The range of the eigenvalues of Σ_true, ``lo:hi``.
    ar : float or None
        The AR(1) coefficient φ of the whitened errors in time.
    noise : str or None
        The error distribution: ``gaussian`` or ``student-t:NU``.
    """

    trials: Annotated[
        int | None,
        typer.Option(
            "--trials", help=f"Trials per scenario {_default(_S.trials)}.", rich_help_panel=STUDY
        ),
    ] = None
    n: Annotated[
        int | None,
        typer.Option("--n", help=f"Epochs per trial {_default(_S.n)}.", rich_help_panel=STUDY),
    ] = None
    dim: Annotated[
        int | None,
        typer.Option("--dim", help=f"State dimension d {_default(_S.dim)}.", rich_help_panel=STUDY),
    ] = None
    rho_optimism: Annotated[
        str | None,
        typer.Option(
            "--rho-optimism",
            help=f"ρ range of optimism, lo:hi {_default(_range_text(_S.rho_optimism))}.",
            rich_help_panel=STUDY,
        ),
    ] = None
    rho_pessimism: Annotated[
        str | None,
        typer.Option(
            "--rho-pessimism",
            help=f"ρ range of pessimism, lo:hi {_default(_range_text(_S.rho_pessimism))}.",
            rich_help_panel=STUDY,
        ),
    ] = None
    bias: Annotated[
        str | None,
        typer.Option(
            "--bias",
            help=f"‖μ‖ range of SMM, lo:hi {_default(_range_text(_S.bias))}.",
            rich_help_panel=STUDY,
        ),
    ] = None
    eigenvalues: Annotated[
        str | None,
        typer.Option(
            "--eigenvalues",
            help=f"Range of the eigenvalues of Σ_true {_default(_range_text(_S.eigenvalues))}.",
            rich_help_panel=STUDY,
        ),
    ] = None
    ar: Annotated[
        float | None,
        typer.Option(
            "--ar",
            help="AR(1) coefficient φ of the whitened errors in time (marginal covariance "
            f"unchanged) {_default(f'{_S.ar:g}')}.",
            rich_help_panel=STUDY,
        ),
    ] = None
    noise: Annotated[
        str | None,
        typer.Option(
            "--noise",
            help=f"Error distribution: gaussian or student-t:NU {_default(_S.noise)}.",
            rich_help_panel=STUDY,
        ),
    ] = None


@dataclass(frozen=True)
class UwbOptions:
    """The UWB pipeline's settings: [uwb] of a config file.

    Attributes
    ----------
    range_column : str or None
        ``range_calib`` (calibrated) or ``range`` (raw).
    std : str or None
        The range std in m: one value, per-anchor ``ID=VALUE`` pairs, or ``estimate``.
    screen : ScreenMode or None
        Which packets are dropped.
    residual_level : float or None
        The level of the per-packet residual test.
    robust : RobustLoss or None
        The position solve: none (WLS) or huber.
    anchor_map : str or None
        The log's anchor ids mapped to the markers' ids, ``LOG_ID=MARKER_ID,…``.
    max_speed : float or None
        Static periods: speed below this (m/s).
    min_static : float or None
        Static periods: at least this long (s).
    packet_window : float or None
        A packet: distinct anchors within this (s).
    min_anchors : int or None
        Anchors per 2-D fix.
    """

    range_column: Annotated[
        str | None,
        typer.Option(
            "--range-column",
            help=f"range_calib (calibrated) or range (raw) {_default(_U.range_column)}.",
            rich_help_panel=UWB,
        ),
    ] = None
    std: Annotated[
        str | None,
        typer.Option(
            "--std",
            help="Range std in m: one value (files without a std column, s5), per anchor "
            "(4=0.1,9=0.12, over the column), or 'estimate' (from the data; the verdict is then "
            "about the estimated model).",
            rich_help_panel=UWB,
        ),
    ] = None
    screen: Annotated[
        ScreenMode | None,
        typer.Option(
            "--screen",
            help="Drop stale packets and packets failing the residual test (all), or nothing "
            f"(none) {_default(ScreenMode.ALL if _U.screen else ScreenMode.NONE)}.",
            rich_help_panel=UWB,
        ),
    ] = None
    residual_level: Annotated[
        float | None,
        typer.Option(
            "--residual-level",
            help=f"Level of the per-packet residual test {_default(_U.residual_level)}.",
            rich_help_panel=UWB,
        ),
    ] = None
    robust: Annotated[
        RobustLoss | None,
        typer.Option(
            "--robust",
            help="Position solve: none (WLS) or huber (downweights outliers) "
            f"{_default(_U.robust)}.",
            rich_help_panel=UWB,
        ),
    ] = None
    anchor_map: Annotated[
        str | None,
        typer.Option(
            "--anchor-map",
            help="Map the log's anchor ids to the markers' ids: LOG_ID=MARKER_ID,…",
            rich_help_panel=UWB,
        ),
    ] = None
    max_speed: Annotated[
        float | None,
        typer.Option(
            "--max-speed",
            help=f"Static: speed below this (m/s) {_default(_U.max_speed)}.",
            rich_help_panel=UWB,
        ),
    ] = None
    min_static: Annotated[
        float | None,
        typer.Option(
            "--min-static",
            help=f"Static: for at least this long (s) {_default(_U.min_static)}.",
            rich_help_panel=UWB,
        ),
    ] = None
    packet_window: Annotated[
        float | None,
        typer.Option(
            "--packet-window",
            help=f"Packet: distinct anchors within this (s) {_default(_U.packet_window)}.",
            rich_help_panel=UWB,
        ),
    ] = None
    min_anchors: Annotated[
        int | None,
        typer.Option(
            "--min-anchors",
            help=f"Anchors per 2-D fix {_default(_U.min_anchors)}.",
            rich_help_panel=UWB,
        ),
    ] = None


GROUPS = (
    SegmentOptions,
    LogOptions,
    RuleOptions,
    RunOptions,
    OutputOptions,
    VerdictOptions,
    ThresholdOptions,
    StudyOptions,
    UwbOptions,
)
"""Every option group (a test checks that no two share an option name)."""


def declare(command):
    """A command whose parameters may be option groups, made into one Typer can read.

    Each parameter annotated with a group dataclass is replaced, in place, by the group's
    fields (their Typer options, in field order); when the command runs, those options are
    gathered back into one frozen instance of the group. Other parameters pass unchanged.

    Parameters
    ----------
    command : callable
        A command function; parameters annotated with a group dataclass are spread.

    Returns
    -------
    callable
        The wrapped command, whose signature lists every option as a keyword-only
        parameter.

    Raises
    ------
    TypeError
        If two parameters or group fields share a name.
    """
    hints = typing.get_type_hints(command, include_extras=True)
    spread: list[inspect.Parameter] = []
    groups: dict[str, tuple[type, tuple[str, ...]]] = {}
    for param in inspect.signature(command).parameters.values():
        hint = hints[param.name]
        if isinstance(hint, type) and dataclasses.is_dataclass(hint):
            fields = typing.get_type_hints(hint, include_extras=True)
            names = tuple(f.name for f in dataclasses.fields(hint))
            spread += [
                inspect.Parameter(
                    f.name,
                    inspect.Parameter.KEYWORD_ONLY,
                    default=f.default,
                    annotation=fields[f.name],
                )
                for f in dataclasses.fields(hint)
            ]
            groups[param.name] = (hint, names)
        else:
            spread.append(param.replace(kind=inspect.Parameter.KEYWORD_ONLY, annotation=hint))
    taken = [p.name for p in spread]
    twice = sorted({n for n in taken if taken.count(n) > 1})
    if twice:
        raise TypeError(f"{command.__name__}: option(s) {', '.join(twice)} declared twice")

    @functools.wraps(command)
    def gathered(**given):
        for name, (group, names) in groups.items():
            given[name] = group(**{n: given.pop(n) for n in names})
        return command(**given)

    gathered.__signature__ = inspect.Signature(spread, return_annotation=hints.get("return"))
    gathered.__annotations__ = {p.name: p.annotation for p in spread}
    return gathered
