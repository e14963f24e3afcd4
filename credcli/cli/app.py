"""The credcli command line: options in, library calls, a renderer out.

Errors raised as CredcliError (and usage errors) become one line on stderr and exit 2.
"""

from __future__ import annotations

import enum
import errno
import re
import sys
from pathlib import Path
from typing import Annotated

import typer

from credcli.ci.thresholds import Thresholds
from credcli.engine.config import AUTO, DiagnosisConfig, MetricsLevel, SrdForm, Variant
from credcli.errors import CredcliError
from credcli.io.schema import CovKind, InputFormat, LogSchema, Perturbation, States, TimeUnit
from credcli.report.formats import OutputFormat
from credcli.studies.settings import CURVE_RUNS, RobustLoss, SimulationConfig, UwbSettings

app = typer.Typer(
    name="credcli",
    help="Can you trust the covariance your estimator reports, and if not, why not?",
    add_completion=False,
    no_args_is_help=True,
    pretty_exceptions_enable=False,
    rich_markup_mode=None,
)

_D = DiagnosisConfig()
_S = SimulationConfig()
_U = UwbSettings()
_T = Thresholds()
_L = LogSchema()


def _range(pair) -> str:
    return f"{pair[0]:g}:{pair[1]:g}"


def _show_version(value: bool) -> None:
    if value:
        from credcli import __version__

        print(f"credcli {__version__}")
        raise typer.Exit(0)


@app.callback()
def _root(
    version: Annotated[
        bool,
        typer.Option("--version", callback=_show_version, is_eager=True, help="Show the version."),
    ] = False,
    debug: Annotated[
        bool,
        typer.Option("--debug", help="Show the traceback of an internal error (exit code 3)."),
    ] = False,
) -> None:
    """Can you trust the covariance your estimator reports, and if not, why not?"""


LOG_FORMATS = (
    "credcli CSV/Parquet (also .gz), TUM, OpenVINS, EuRoC, ros-csv, ROS1 bag, ROS2 bag "
    "(with --truth for a separate ground truth), or innovations (--innovations)"
)


def _file_name(text: str) -> Path:
    """A path typed on the command line; never empty (``Path("")`` would read ``.``)."""
    if not text:
        raise typer.BadParameter("an empty file name; give a path")
    return Path(text)


def _output_name(text: str) -> Path:
    """A file to write: not empty, and not a name ending in '/' (a directory)."""
    if text.endswith("/"):
        raise typer.BadParameter(f"{text!r} ends with '/', a directory; give a file name")
    return _file_name(text)


# Options shared by the commands that diagnose (declared once, reused).
ConfigOpt = Annotated[
    Path | None,
    typer.Option(
        "--config", parser=_file_name, metavar="FILE", help="TOML config file (see configs/)."
    ),
]
FormatOpt = Annotated[
    OutputFormat, typer.Option("--format", "-f", help="Output format.", case_sensitive=False)
]
OutputOpt = Annotated[
    Path | None,
    typer.Option(
        "--output",
        "-o",
        parser=_output_name,
        metavar="FILE",
        help="Write the output to FILE (atomically).",
    ),
]
SeedOpt = Annotated[
    int | None, typer.Option("--seed", help=f"Seed of the ELT sign flips [default: {_S.seed}].")
]
TauOpt = Annotated[
    float | None,
    typer.Option(
        "--tau",
        help="calibrated (default): the smallest covariance misfit worth a label, "
        "|10 log10 κ̂| > τ dB; paper and ks: the NCI threshold of Algorithm 1 "
        f"[default: {_D.tau_nci}].",
    ),
]
AlphaOpt = Annotated[
    float | None,
    typer.Option(
        "--alpha",
        help="calibrated (default): the false-alarm level per segment, split by Šidák "
        "between the location and the scale test; paper and ks: the ELT's level "
        f"[default: {_D.alpha}].",
    ),
]
COpt = Annotated[
    float | None, typer.Option("--probe-factor", "-c", help=f"Probe scale c > 1 [default: {_D.c}].")
]
FlipsOpt = Annotated[
    int | None, typer.Option("--flips", "-B", help=f"ELT sign flips B [default: {_D.n_flips}].")
]
BlockOpt = Annotated[
    str | None,
    typer.Option(
        "--block-length",
        help="Epochs per ELT sign block, or auto (estimated from the serial dependence in the "
        f"calibrated variant; 1 in paper and ks) [default: {_D.block_length}].",
    ),
]
VariantOpt = Annotated[
    Variant | None,
    typer.Option(
        "--variant",
        help="Decision rule: calibrated (level-α tests, dependence-aware), ks (the authors' "
        f"code) or paper (Algorithm 1 as printed) [default: {_D.variant.value}].",
    ),
]
SrdOpt = Annotated[
    SrdForm | None,
    typer.Option(
        "--srd-form",
        help=f"SRD of Eq. (19): printed or absolute [default: {_D.srd_form.value}].",
    ),
]
MetricsOpt = Annotated[
    MetricsLevel | None,
    typer.Option(
        "--metrics",
        help="needed: probes only where Algorithm 1 uses them; all: always "
        f"[default: {_D.metrics.value}].",
    ),
]
SchedulerOpt = Annotated[
    str | None,
    typer.Option(
        "--scheduler",
        envvar="CREDCLI_SCHEDULER",
        help="Run on a Dask cluster: its scheduler's address (tcp://host:8786), or local:N "
        "for N local workers (needs credcli[dask]; docs/scale.md).",
    ),
]
JobsOpt = Annotated[
    int | None,
    typer.Option(
        "--jobs",
        "-j",
        help="Worker processes for the segments (same output for any value; used from "
        "50,000 epochs on) [default: the number of cores].",
    ),
]
ExactOpt = Annotated[
    bool | None,
    typer.Option(
        "--exact-pvalue",
        help="Evaluate all B sign flips (default: stop once the ELT cannot reject; the label "
        "is the same, the p-value then sequential).",
    ),
]
KsAlphaOpt = Annotated[
    float | None,
    typer.Option(
        "--ks-alpha", help=f"Level of the KS check of the ks variant [default: {_D.ks_alpha}]."
    ),
]
NeesAlphaOpt = Annotated[
    float | None,
    typer.Option(
        "--nees-alpha",
        help=f"Level of the NEES baseline's χ² test [default: {_D.nees_alpha}].",
    ),
]
MinEpochsOpt = Annotated[
    int | None,
    typer.Option("--min-epochs", help=f"Smallest segment diagnosed [default: {_D.min_epochs}]."),
]
MaxEltOpt = Annotated[
    int | None,
    typer.Option(
        "--max-elt-epochs", help=f"ELT memory budget in epochs [default: {_D.max_elt_epochs}]."
    ),
]


def _block_length(text: str | None) -> int | str | None:
    """--block-length: 'auto' or a positive integer."""
    if text is None or text.strip().lower() == AUTO:
        return None if text is None else AUTO
    try:
        value = int(text)
    except ValueError:
        value = 0
    if value < 1:
        raise CredcliError(f"--block-length: expected auto or an integer >= 1; got '{text}'")
    return value


def _diagnosis_cli(
    tau,
    alpha,
    c,
    flips,
    block,
    variant,
    srd_form,
    metrics,
    min_epochs,
    max_elt,
    ks_alpha=None,
    nees_alpha=None,
    exact=None,
):
    block = _block_length(block)
    return {
        "ks_alpha": ks_alpha,
        "nees_alpha": nees_alpha,
        "exact_pvalue": exact,
        "tau_nci": tau,
        "alpha": alpha,
        "c": c,
        "n_flips": flips,
        "block_length": block,
        "variant": variant,
        "srd_form": srd_form,
        "metrics": metrics,
        "min_epochs": min_epochs,
        "max_elt_epochs": max_elt,
    }


def _emit(report, fmt: OutputFormat, output: Path | None, inputs=()) -> None:
    """Print a report to stdout (Rich tables when a terminal) or write it to a file."""
    from credcli.io.files import write_atomic
    from credcli.report.render import rich_table, to_text

    if output is not None:
        write_atomic(output, to_text(report, fmt), inputs)
        _stderr().print(f"wrote {output}", highlight=False)
        return
    if fmt is OutputFormat.TABLE:
        from rich.console import Console

        console = Console()
        fit: int | None = console.width  # a terminal: hide columns that do not fit
        if not console.is_terminal:  # a log or a pipe: $COLUMNS if given, else every column
            fit = _given_width()
            console = Console(width=fit or UNLIMITED_WIDTH, soft_wrap=fit is None)
        for table in report.tables:
            console.print(rich_table(table, fit))
        for note in report.notes:
            console.print(note, markup=False, highlight=False)
        return
    sys.stdout.write(to_text(report, fmt))


UNLIMITED_WIDTH = 10_000
"""Width of text output that is not a terminal and was given no $COLUMNS: tables keep every
column (a CI log scrolls sideways, it does not lose the "why")."""


def _given_width() -> int | None:
    import os

    try:
        width = int(os.environ.get("COLUMNS", ""))
    except ValueError:
        return None
    return width if width > 0 else None


def _stderr():
    """Messages on stderr, never wrapped off a terminal (a CI log keeps each on one line)."""
    from rich.console import Console

    console = Console(stderr=True)
    if not console.is_terminal:
        console = Console(stderr=True, soft_wrap=True, width=_given_width() or UNLIMITED_WIDTH)
    return console


class _Progress:
    """A Rich progress bar on stderr, shown only on a terminal and for runs of at least
    ``min_total`` steps. Called as ``progress(done, total)``."""

    def __init__(self, description: str, min_total: int = 10) -> None:
        self.description = description
        self.min_total = min_total
        self._bar = None
        self._task = None
        self._show = _stderr().is_terminal

    def __enter__(self):
        return self

    def __call__(self, done: int, total: int) -> None:
        if self._bar is None and self._show and total >= self.min_total:
            from rich.progress import Progress

            self._bar = Progress(console=_stderr(), transient=True)
            self._bar.start()
            self._task = self._bar.add_task(self.description, total=total)
        if self._bar is not None:
            self._bar.update(self._task, completed=done)

    def __exit__(self, *exc) -> None:
        if self._bar is not None:
            self._bar.stop()


FailOnOpt = Annotated[
    str | None,
    typer.Option(
        "--fail-on",
        help="Exit 1 if a segment fails any of these (comma-separated): a condition "
        "(optimism, pessimism, smm: every label containing it), a combined label "
        "(optimism+smm: that label only), insufficient-data, untested (a partial verdict), "
        "or noncredible (all but a complete credible).",
    ),
]
MonteCarloOpt = Annotated[
    bool,
    typer.Option(
        "--monte-carlo",
        help="The logs are independent runs of one scenario: pool them, and test the "
        "per-epoch ANEES.",
    ),
]
LogsArg = Annotated[
    list[Path],
    typer.Argument(
        parser=_file_name,
        metavar="LOG...",
        help=f"Estimator logs: {LOG_FORMATS}; '-' reads standard input.",
        show_default=False,
    ),
]
WindowOpt = Annotated[
    str | None,
    typer.Option(
        "--window", "-w", help="Split into windows: a duration (5s, 250ms) or an epoch count (200)."
    ),
]
WholeOpt = Annotated[bool | None, typer.Option("--whole", help="Diagnose each log as one segment.")]
TimeColOpt = Annotated[
    str | None, typer.Option("--time-column", help=f"Time column [default: {_L.time}].")
]
SegColOpt = Annotated[
    str | None,
    typer.Option("--segment-column", help=f"Segment column [default: {_L.segment}]."),
]
TruthColsOpt = Annotated[
    str | None, typer.Option("--truth-columns", help="Truth columns, comma-separated.")
]
EstColsOpt = Annotated[
    str | None, typer.Option("--estimate-columns", help="Estimate columns, comma-separated.")
]
CovColsOpt = Annotated[
    str | None,
    typer.Option(
        "--cov-columns",
        help="Covariance columns, comma-separated: d² (full), d(d+1)/2 (upper) or d.",
    ),
]
CovKindOpt = Annotated[
    CovKind | None, typer.Option("--cov-kind", help="How --cov-columns store the covariance.")
]
DropOpt = Annotated[
    bool | None, typer.Option("--drop-invalid", help="Drop rows with NaN/Inf instead of failing.")
]
TruthOpt = Annotated[
    Path | None,
    typer.Option(
        "--truth",
        parser=_file_name,
        metavar="FILE",
        help="Ground truth in a separate file (or bag), paired by time.",
    ),
]
InputFormatOpt = Annotated[
    InputFormat | None,
    typer.Option("--input-format", help="Format of the logs [default: auto, from the file]."),
]
TruthFormatOpt = Annotated[
    InputFormat | None,
    typer.Option("--truth-format", help="Format of --truth [default: auto, from the file]."),
]
TopicOpt = Annotated[
    str | None,
    typer.Option(
        "--topic", help="Bag topic of the estimate (Odometry or PoseWithCovarianceStamped)."
    ),
]
TruthTopicOpt = Annotated[
    str | None,
    typer.Option(
        "--truth-topic", help="Bag topic of the truth (PoseStamped, Odometry, TransformStamped)."
    ),
]
TimeUnitOpt = Annotated[
    TimeUnit | None,
    typer.Option("--time-unit", help="Unit of the stamps [default: auto, said in a note]."),
]
MaxDtOpt = Annotated[
    float | None,
    typer.Option(
        "--max-dt",
        help="Interpolate truth only across gaps up to this (s) [default: 2.5 × its median period].",
    ),
]
TimeOffsetOpt = Annotated[
    float | None,
    typer.Option("--time-offset", help="Seconds added to the estimate stamps [default: 0]."),
]
StatesOpt = Annotated[
    States | None,
    typer.Option(
        "--states",
        help="Errors of pose logs: position, orientation, pose or planar [default: position].",
    ),
]
PerturbationOpt = Annotated[
    Perturbation | None,
    typer.Option(
        "--perturbation",
        help="Orientation error convention (docs/formats.md: Conventions) [default: left].",
    ),
]
ErrorsOnlyOpt = Annotated[
    bool | None,
    typer.Option(
        "--errors-only",
        help="The logs hold errors e_k (err_i, or the columns --truth-columns names) and "
        "their covariance, no truth or estimate (found by itself for err_i columns).",
    ),
]
InnovationsOpt = Annotated[
    bool | None,
    typer.Option(
        "--innovations", help="The logs hold innovations innov_i and innov_cov_i_j: NIS, no truth."
    ),
]
JunitOpt = Annotated[
    Path | None,
    typer.Option(
        "--junit",
        parser=_output_name,
        metavar="FILE",
        help="Write a JUnit XML report (one case per segment).",
    ),
]
PlotsOpt = Annotated[
    Path | None,
    typer.Option(
        "--plots",
        parser=_file_name,
        metavar="DIR",
        help="Write PNG figures into this directory (needs credcli[plots]).",
    ),
]
SummaryOpt = Annotated[
    Path | None,
    typer.Option(
        "--summary",
        parser=_output_name,
        metavar="FILE",
        help="Write a Markdown summary (also appended to $GITHUB_STEP_SUMMARY when set).",
    ),
]


def _diagnose_setup(params: dict) -> dict:
    """Settings of a diagnosis run from a command's parameters (its ``locals()``): command
    line > config file > defaults. diagnose, baseline and report declare the same options
    (Typer needs each declared); this reads them in one place."""
    from credcli.cli.settings import (
        build_diagnosis_config,
        build_reading,
        build_schema,
        load_config,
        segment_settings,
        split_list,
    )

    cfg = load_config(params["config"])
    columns = _columns(*(params[k] for k in _COLUMN_PARAMS))
    for key in ("truth_columns", "estimate_columns", "cov_columns"):
        columns[key] = split_list(columns[key])
    schema = build_schema(cfg, columns)
    method = _diagnosis_cli(*(params[k] for k in _METHOD_PARAMS))
    dconf, seed = build_diagnosis_config(cfg, method, params["seed"])
    window, whole = segment_settings(cfg, params["window"], params["whole"])
    return {
        "schema": schema,
        "config": dconf,
        "seed": seed,
        "window": window,
        "whole": whole,
        "drop_invalid": bool(params["drop_invalid"]),
        "reading": build_reading(cfg, _reading(*(params[k] for k in _READING_PARAMS))),
    }


_COLUMN_PARAMS = (
    "time_column",
    "segment_column",
    "truth_columns",
    "estimate_columns",
    "cov_columns",
    "cov_kind",
)
_METHOD_PARAMS = (
    "tau",
    "alpha",
    "probe_factor",
    "flips",
    "block_length",
    "variant",
    "srd_form",
    "metrics",
    "min_epochs",
    "max_elt_epochs",
    "ks_alpha",
    "nees_alpha",
    "exact_pvalue",
)
_READING_PARAMS = (
    "truth",
    "input_format",
    "truth_format",
    "topic",
    "truth_topic",
    "time_unit",
    "max_dt",
    "time_offset",
    "states",
    "perturbation",
    "innovations",
    "errors_only",
)
"""The parameter names of a command's column, method and reading options, in the order
_columns, _diagnosis_cli and _reading take them."""


def _columns(time_column, segment_column, truth_columns, estimate_columns, cov_columns, cov_kind):
    """The column options of a command, by LogSchema field name."""
    return {
        "time": time_column,
        "segment": segment_column,
        "truth_columns": truth_columns,
        "estimate_columns": estimate_columns,
        "cov_columns": cov_columns,
        "cov_kind": cov_kind,
    }


def _reading(
    truth,
    input_format,
    truth_format,
    topic,
    truth_topic,
    time_unit,
    max_dt,
    time_offset,
    states,
    perturbation,
    innovations,
    errors_only,
) -> dict:
    """The reading options of a command, by ReadOptions field name."""
    return {
        "truth": None if truth is None else str(truth),
        "input_format": input_format,
        "truth_format": truth_format,
        "topic": topic,
        "truth_topic": truth_topic,
        "time_unit": time_unit,
        "max_dt": max_dt,
        "time_offset": time_offset,
        "states": states,
        "perturbation": perturbation,
        "innovations": innovations,
        "errors_only": errors_only,
    }


def _print_notes(report) -> None:
    """The decisions taken while reading the logs, one ``credcli: note:`` line each."""
    for log in report.document.get("logs", []):
        for note in log.get("notes", []):
            print(f"credcli: note: {note}", file=sys.stderr)


def _cluster(scheduler: str | None):
    """A DaskRunner for --scheduler (closed on exit), or a context of None."""
    import contextlib

    if not scheduler:
        return contextlib.nullcontext(None)
    from credcli.cluster import DaskRunner

    console = _stderr()

    def announce(text: str) -> None:  # on a terminal, as the progress bar; quiet in CI
        console.print(f"credcli: {text}", highlight=False, markup=False)

    return DaskRunner(scheduler, announce if console.is_terminal else None)


class ScreenMode(str, enum.Enum):
    ALL = "all"
    NONE = "none"


def _id_pairs(text: str | None, flag: str, kind) -> tuple:
    """'4=1,5=2' -> ((4, 1), (5, 2)) with values of ``kind``."""
    if not text:
        return ()
    out = []
    for item in text.split(","):
        key, sep, value = item.partition("=")
        try:
            if not sep:
                raise ValueError(item)
            out.append((int(key), kind(value)))
        except ValueError as exc:
            raise CredcliError(
                f"{flag}: expected ID=VALUE pairs separated by commas (e.g. 4=1,5=2); got '{item}'"
            ) from exc
    return tuple(out)


def _std_settings(text: str | None) -> dict:
    """--std: a value, ID=VALUE pairs (with an optional plain default among them), or
    'estimate'."""
    from credcli.studies.settings import STD_ESTIMATE

    if text is None:
        return {}
    if text.strip().lower() == STD_ESTIMATE:
        return {"std_estimate": True}
    default = [t for t in text.split(",") if "=" not in t]
    pairs = ",".join(t for t in text.split(",") if "=" in t)
    try:
        value = float(default[0]) if default else None
    except ValueError as exc:
        raise CredcliError(
            f"--std: expected metres (0.1), ID=VALUE pairs (4=0.1,9=0.12) or 'estimate'; got '{text}'"
        ) from exc
    if len(default) > 1:
        raise CredcliError(f"--std: at most one default value; got '{text}'")
    return {"std": value, "std_by_anchor": _id_pairs(pairs, "--std", float)}


def _jobs(jobs: int | None) -> int:
    """--jobs: given, or the number of cores."""
    from credcli.parallel import default_jobs

    if jobs is None:
        return default_jobs()
    if jobs < 1:
        raise CredcliError(f"--jobs must be >= 1; got {jobs}")
    return jobs


def _write_html(path: Path, title: str, run, sources, inputs) -> None:
    from credcli.io.files import write_atomic
    from credcli.report.html import build_html

    html = build_html(title, run.report, run.plots, ", ".join(map(str, sources)))
    write_atomic(path, html, inputs)
    _stderr().print(f"wrote {path} ({len(run.plots)} figures)", highlight=False)


def _guard(outputs: dict, inputs, plots: Path | None = None) -> None:
    """Before any work: no output may be an input or another output, or a directory; the
    --plots directory may not be an input file."""
    from credcli.io.files import check_outputs

    check_outputs(outputs, [p for p in inputs if p is not None])
    if plots is not None and plots.exists() and not plots.is_dir():
        raise CredcliError(f"--plots {plots}: exists and is not a directory")


def _check_plotting(*wanted) -> None:
    if any(w is not None for w in wanted):
        from credcli.report.plots import require_plotting

        require_plotting()


def _write_plots(run, directory: Path | None) -> None:
    """Write the figures of a Run (or a list of figures) into ``directory``, if given."""
    if directory is None:
        return
    from credcli.report.plots import write_plots

    paths = write_plots(run if isinstance(run, list) else run.plots, directory)
    _stderr().print(f"wrote {len(paths)} figure(s) to {directory}", highlight=False)


def _write_ci_reports(
    junit: Path | None, summary: Path | None, cases, markdown: str, inputs
) -> None:
    from credcli.ci.reports import append_step_summary, junit_xml
    from credcli.io.files import write_atomic

    if junit is not None:
        write_atomic(junit, junit_xml("credcli", cases), inputs)
    if summary is not None:
        write_atomic(summary, markdown, inputs)
    append_step_summary(markdown)


@app.command()
def diagnose(
    logs: LogsArg,
    config: ConfigOpt = None,
    window: WindowOpt = None,
    whole: WholeOpt = None,
    time_column: TimeColOpt = None,
    segment_column: SegColOpt = None,
    truth_columns: TruthColsOpt = None,
    estimate_columns: EstColsOpt = None,
    cov_columns: CovColsOpt = None,
    cov_kind: CovKindOpt = None,
    drop_invalid: DropOpt = None,
    truth: TruthOpt = None,
    input_format: InputFormatOpt = None,
    truth_format: TruthFormatOpt = None,
    topic: TopicOpt = None,
    truth_topic: TruthTopicOpt = None,
    time_unit: TimeUnitOpt = None,
    max_dt: MaxDtOpt = None,
    time_offset: TimeOffsetOpt = None,
    states: StatesOpt = None,
    perturbation: PerturbationOpt = None,
    innovations: InnovationsOpt = None,
    errors_only: ErrorsOnlyOpt = None,
    tau: TauOpt = None,
    alpha: AlphaOpt = None,
    probe_factor: COpt = None,
    flips: FlipsOpt = None,
    block_length: BlockOpt = None,
    variant: VariantOpt = None,
    srd_form: SrdOpt = None,
    metrics: MetricsOpt = None,
    min_epochs: MinEpochsOpt = None,
    max_elt_epochs: MaxEltOpt = None,
    ks_alpha: KsAlphaOpt = None,
    nees_alpha: NeesAlphaOpt = None,
    exact_pvalue: ExactOpt = None,
    jobs: JobsOpt = None,
    scheduler: SchedulerOpt = None,
    seed: SeedOpt = None,
    fmt: FormatOpt = OutputFormat.TABLE,
    output: OutputOpt = None,
    fail_on: FailOnOpt = None,
    junit: JunitOpt = None,
    summary: SummaryOpt = None,
    plots: PlotsOpt = None,
    report_file: Annotated[
        Path | None,
        typer.Option(
            "--report",
            parser=_output_name,
            metavar="FILE",
            help="Also write a self-contained HTML report.",
        ),
    ] = None,
    monte_carlo: MonteCarloOpt = False,
) -> int:
    """Diagnose each segment of one or more estimator logs (calibrated rule by default)."""
    from credcli.ci.gate import fail_on_verdict, parse_fail_on
    from credcli.workflows import run_diagnose

    conditions = parse_fail_on(fail_on) if fail_on is not None else None
    if (junit or summary) and conditions is None:
        raise CredcliError(
            "--junit and --summary report a verdict: give --fail-on too (e.g. --fail-on noncredible)"
        )
    inputs = [*logs, config, truth]
    outputs = {"--output": output, "--junit": junit, "--summary": summary, "--report": report_file}
    _guard(outputs, inputs, plots)
    _check_plotting(plots, report_file)
    setup = _diagnose_setup(locals())
    with _cluster(scheduler) as runner, _Progress("diagnosing segments") as bar:
        run = run_diagnose(
            logs,
            progress=bar,
            plots=plots is not None or report_file is not None,
            jobs=_jobs(jobs),
            monte_carlo=monte_carlo,
            runner=runner,
            **setup,
        )
    report = run.report
    _print_notes(report)
    _emit(report, fmt, output, inputs=inputs)
    _write_plots(run, plots)
    if report_file is not None:
        _write_html(
            report_file, "credcli diagnose: " + ", ".join(p.name for p in logs), run, logs, inputs
        )
    if conditions is None:
        return 0
    from credcli.ci.reports import fail_on_cases, summary_markdown

    records = report.document["segments"]
    passed, verdict, failing = fail_on_verdict(run.results, conditions)
    _write_ci_reports(
        junit,
        summary,
        fail_on_cases(records, failing, conditions),
        summary_markdown("credcli diagnose", verdict, report),
        inputs,
    )
    print(f"credcli: {verdict}", file=sys.stderr)
    return 0 if passed else 1


@app.command()
def baseline(
    log: Annotated[
        Path,
        typer.Argument(
            parser=_file_name,
            metavar="LOG",
            help=f"The estimator log to record ({LOG_FORMATS}).",
            show_default=False,
        ),
    ],
    output: OutputOpt = None,
    config: ConfigOpt = None,
    window: WindowOpt = None,
    whole: WholeOpt = None,
    time_column: TimeColOpt = None,
    segment_column: SegColOpt = None,
    truth_columns: TruthColsOpt = None,
    estimate_columns: EstColsOpt = None,
    cov_columns: CovColsOpt = None,
    cov_kind: CovKindOpt = None,
    drop_invalid: DropOpt = None,
    truth: TruthOpt = None,
    input_format: InputFormatOpt = None,
    truth_format: TruthFormatOpt = None,
    topic: TopicOpt = None,
    truth_topic: TruthTopicOpt = None,
    time_unit: TimeUnitOpt = None,
    max_dt: MaxDtOpt = None,
    time_offset: TimeOffsetOpt = None,
    states: StatesOpt = None,
    perturbation: PerturbationOpt = None,
    innovations: InnovationsOpt = None,
    errors_only: ErrorsOnlyOpt = None,
    tau: TauOpt = None,
    alpha: AlphaOpt = None,
    probe_factor: COpt = None,
    flips: FlipsOpt = None,
    block_length: BlockOpt = None,
    variant: VariantOpt = None,
    srd_form: SrdOpt = None,
    metrics: MetricsOpt = None,
    min_epochs: MinEpochsOpt = None,
    max_elt_epochs: MaxEltOpt = None,
    ks_alpha: KsAlphaOpt = None,
    nees_alpha: NeesAlphaOpt = None,
    exact_pvalue: ExactOpt = None,
    jobs: JobsOpt = None,
    scheduler: SchedulerOpt = None,
    seed: SeedOpt = None,
) -> int:
    """Record a baseline: the JSON of `diagnose` with a schema version and every parameter."""
    from credcli.workflows import run_baseline

    inputs = [log, config, truth]
    _guard({"--output": output}, inputs)
    setup = _diagnose_setup(locals())
    with _cluster(scheduler) as runner, _Progress("diagnosing segments") as bar:
        recorded = run_baseline(log, progress=bar, jobs=_jobs(jobs), runner=runner, **setup)
    _print_notes(recorded)
    _emit(recorded, OutputFormat.JSON, output, inputs=inputs)
    return 0


@app.command()
def gate(
    log: Annotated[
        Path,
        typer.Argument(
            parser=_file_name,
            metavar="LOG",
            help=f"The estimator log to check ({LOG_FORMATS}).",
            show_default=False,
        ),
    ],
    baseline_file: Annotated[
        Path,
        typer.Option(
            "--baseline",
            "-b",
            parser=_file_name,
            metavar="FILE",
            help="Baseline JSON from `credcli baseline`.",
            show_default=False,
        ),
    ],
    max_nci_increase: Annotated[
        float,
        typer.Option("--max-nci-increase", help="Fail when |NCI| grows by more than this (dB)."),
    ] = _T.max_nci_increase,
    max_anees_ratio: Annotated[
        float,
        typer.Option(
            "--max-anees-ratio",
            help="Fail when ANEES moves further from 1 by more than this factor.",
        ),
    ] = _T.max_anees_ratio,
    allow_new_segments: Annotated[
        bool,
        typer.Option(
            "--allow-new-segments", help="New or missing segments are reported, not failures."
        ),
    ] = _T.allow_new_segments,
    junit: JunitOpt = None,
    summary: SummaryOpt = None,
    fmt: FormatOpt = OutputFormat.TABLE,
    output: OutputOpt = None,
    config: ConfigOpt = None,
    plots: PlotsOpt = None,
    truth: Annotated[
        Path | None,
        typer.Option(
            "--truth",
            parser=_file_name,
            metavar="FILE",
            help="Ground truth of LOG [default: the baseline's --truth].",
        ),
    ] = None,
    window: WindowOpt = None,
    whole: WholeOpt = None,
    tau: TauOpt = None,
    alpha: AlphaOpt = None,
    probe_factor: COpt = None,
    flips: FlipsOpt = None,
    block_length: BlockOpt = None,
    variant: VariantOpt = None,
    srd_form: SrdOpt = None,
    metrics: MetricsOpt = None,
    min_epochs: MinEpochsOpt = None,
    max_elt_epochs: MaxEltOpt = None,
    ks_alpha: KsAlphaOpt = None,
    nees_alpha: NeesAlphaOpt = None,
    exact_pvalue: ExactOpt = None,
    jobs: JobsOpt = None,
    scheduler: SchedulerOpt = None,
    seed: SeedOpt = None,
    fail_on: FailOnOpt = None,
) -> int:
    """Diagnose LOG with the baseline's parameters and fail (exit 1) on a regression."""
    from credcli.ci.gate import Thresholds, gate_fail_on, parse_fail_on
    from credcli.ci.reports import gate_cases, summary_markdown
    from credcli.cli.settings import gate_requests, load_config
    from credcli.workflows import run_gate

    thresholds = Thresholds(max_nci_increase, max_anees_ratio, allow_new_segments)
    inputs = [log, baseline_file, config, truth]
    _guard({"--output": output, "--junit": junit, "--summary": summary}, inputs, plots)
    _check_plotting(plots)
    cli = {
        k: (v.value if hasattr(v, "value") else v)
        for k, v in _diagnosis_cli(
            tau,
            alpha,
            probe_factor,
            flips,
            block_length,
            variant,
            srd_form,
            metrics,
            min_epochs,
            max_elt_epochs,
            ks_alpha,
            nees_alpha,
            exact_pvalue,
        ).items()
    }
    cli |= {"seed": seed, "window": window, "whole": whole}
    requested = gate_requests(load_config(config), cli)
    with _cluster(scheduler) as runner, _Progress("diagnosing segments") as bar:
        report, comparisons, passed, verdict, figures = run_gate(
            log,
            baseline_file,
            thresholds,
            requested,
            bar,
            plots=plots is not None,
            jobs=_jobs(jobs),
            truth=truth,
            runner=runner,
        )
    if fail_on is not None:
        passed, verdict = gate_fail_on(comparisons, parse_fail_on(fail_on), passed, verdict)
    _emit(report, fmt, output, inputs=inputs)
    _write_plots(figures, plots)
    _write_ci_reports(
        junit,
        summary,
        gate_cases(comparisons, thresholds, str(log)),
        summary_markdown(
            f"credcli gate: {log}",
            verdict,
            report,
            f"Baseline `{baseline_file}`; {thresholds.describe()}.",
        ),
        inputs,
    )
    print(f"credcli: {verdict}", file=sys.stderr)
    return 0 if passed else 1


@app.command()
def simulate(
    scenario: Annotated[
        str,
        typer.Option(
            "--scenario",
            "-s",
            help="all, a label (credible, optimism, …) or alias (cred, opt, pess, opt+smm, pess+smm); comma-separated for several.",
        ),
    ] = "all",
    trials: Annotated[
        int | None, typer.Option("--trials", help=f"Trials per scenario [default: {_S.trials}].")
    ] = None,
    n: Annotated[
        int | None, typer.Option("--n", help=f"Epochs per trial [default: {_S.n}].")
    ] = None,
    dim: Annotated[
        int | None, typer.Option("--dim", help=f"State dimension d [default: {_S.dim}].")
    ] = None,
    rho_optimism: Annotated[
        str | None,
        typer.Option(
            "--rho-optimism",
            help=f"ρ range of optimism, lo:hi [default: {_range(_S.rho_optimism)}].",
        ),
    ] = None,
    rho_pessimism: Annotated[
        str | None,
        typer.Option(
            "--rho-pessimism",
            help=f"ρ range of pessimism, lo:hi [default: {_range(_S.rho_pessimism)}].",
        ),
    ] = None,
    bias: Annotated[
        str | None,
        typer.Option("--bias", help=f"‖μ‖ range of SMM, lo:hi [default: {_range(_S.bias)}]."),
    ] = None,
    eigenvalues: Annotated[
        str | None,
        typer.Option(
            "--eigenvalues",
            help=f"Range of the eigenvalues of Σ_true [default: {_range(_S.eigenvalues)}].",
        ),
    ] = None,
    sweep: Annotated[
        str | None,
        typer.Option(
            "--sweep",
            help="Sweep one parameter: rho=0.1:10:20, bias=0:3:13, n=25,50,100, dim=…, B=…, tau=…, ar=0,0.5,0.9",
        ),
    ] = None,
    curves: Annotated[
        bool,
        typer.Option(
            "--curves", help="Print the Fig. 1 curves (mean ES and NLL against ρ and γ) instead."
        ),
    ] = False,
    curve_runs: Annotated[
        int, typer.Option("--curve-runs", help="Monte Carlo runs per curve point.")
    ] = CURVE_RUNS,
    ar: Annotated[
        float | None,
        typer.Option(
            "--ar",
            help="AR(1) coefficient φ of the whitened errors in time (marginal covariance "
            f"unchanged) [default: {_S.ar:g}].",
        ),
    ] = None,
    noise: Annotated[
        str | None,
        typer.Option(
            "--noise",
            help=f"Error distribution: gaussian or student-t:NU [default: {_S.noise}].",
        ),
    ] = None,
    jobs: Annotated[
        int | None,
        typer.Option(
            "--jobs",
            "-j",
            help="Worker processes (same output for any value) [default: the number of cores].",
        ),
    ] = None,
    scheduler: SchedulerOpt = None,
    plots: PlotsOpt = None,
    config: ConfigOpt = None,
    tau: TauOpt = None,
    alpha: AlphaOpt = None,
    probe_factor: COpt = None,
    flips: FlipsOpt = None,
    block_length: BlockOpt = None,
    variant: VariantOpt = None,
    srd_form: SrdOpt = None,
    ks_alpha: KsAlphaOpt = None,
    nees_alpha: NeesAlphaOpt = None,
    exact_pvalue: ExactOpt = None,
    seed: SeedOpt = None,
    fmt: FormatOpt = OutputFormat.TABLE,
    output: OutputOpt = None,
) -> int:
    """The paper's Monte Carlo study (Tables II and III), sweeps and the Fig. 1 curves."""
    import time

    from credcli.cli.settings import build_simulation_config, load_config
    from credcli.workflows import run_simulate

    jobs = _jobs(jobs)
    _guard({"--output": output}, [config], plots)
    if curve_runs < 1:
        raise CredcliError(f"--curve-runs must be >= 1; got {curve_runs}")
    _check_plotting(plots)
    cfg = load_config(config)
    sim = build_simulation_config(
        cfg,
        {
            "trials": trials,
            "n": n,
            "dim": dim,
            "rho_optimism": rho_optimism,
            "rho_pessimism": rho_pessimism,
            "bias": bias,
            "eigenvalues": eigenvalues,
            "seed": seed,
            "ar": ar,
            "noise": noise,
        },
        _diagnosis_cli(
            tau,
            alpha,
            probe_factor,
            flips,
            block_length,
            variant,
            srd_form,
            None,
            None,
            None,
            ks_alpha,
            nees_alpha,
            exact_pvalue,
        ),
    )
    start = time.perf_counter()
    with _cluster(scheduler) as runner, _Progress("simulating trials", min_total=1) as bar:
        run, summary = run_simulate(
            sim,
            scenario,
            sweep=sweep,
            curves=curves,
            curve_runs=curve_runs,
            jobs=jobs,
            runner=runner,
            progress=bar,
            plots=plots is not None,
        )
    _emit(run.report, fmt, output, inputs=[config])
    _write_plots(run, plots)
    _stderr().print(f"{summary} in {time.perf_counter() - start:.2f} s", highlight=False)
    return 0


@app.command()
def uwb(
    file: Annotated[
        Path,
        typer.Argument(
            parser=_file_name, metavar="UWB_CSV", help="A STAR-loc uwb.csv.", show_default=False
        ),
    ],
    anchors: Annotated[
        Path | None,
        typer.Option(
            "--anchors",
            help="Anchor positions (STAR-loc markers CSV); default: self-calibrate from the file.",
        ),
    ] = None,
    window: Annotated[
        str | None,
        typer.Option("--window", "-w", help="Fixed windows (5s) instead of static periods."),
    ] = None,
    whole: Annotated[bool, typer.Option("--whole", help="The whole run as one period.")] = False,
    range_column: Annotated[
        str, typer.Option("--range-column", help="range_calib (calibrated) or range (raw).")
    ] = _U.range_column,
    std: Annotated[
        str | None,
        typer.Option(
            "--std",
            help="Range std in m: one value (files without a std column, s5), per anchor "
            "(4=0.1,9=0.12, over the column), or 'estimate' (from the data; the verdict is then "
            "about the estimated model).",
        ),
    ] = None,
    screen: Annotated[
        ScreenMode,
        typer.Option(
            "--screen",
            help="Drop stale packets and packets failing the residual test (all), or nothing (none).",
        ),
    ] = ScreenMode.ALL,
    residual_level: Annotated[
        float,
        typer.Option("--residual-level", help="Level of the per-packet residual test."),
    ] = _U.residual_level,
    robust: Annotated[
        RobustLoss,
        typer.Option(
            "--robust", help="Position solve: none (WLS) or huber (downweights outliers)."
        ),
    ] = _U.robust,
    anchor_map: Annotated[
        str | None,
        typer.Option(
            "--anchor-map", help="Map the log's anchor ids to the markers' ids: LOG_ID=MARKER_ID,…"
        ),
    ] = None,
    max_speed: Annotated[
        float, typer.Option("--max-speed", help="Static: speed below this (m/s).")
    ] = _U.max_speed,
    min_static: Annotated[
        float, typer.Option("--min-static", help="Static: for at least this long (s).")
    ] = _U.min_static,
    packet_window: Annotated[
        float, typer.Option("--packet-window", help="Packet: distinct anchors within this (s).")
    ] = _U.packet_window,
    min_anchors: Annotated[
        int, typer.Option("--min-anchors", help="Anchors per 2-D fix.")
    ] = _U.min_anchors,
    export_log: Annotated[
        Path | None,
        typer.Option(
            "--export-log",
            parser=_output_name,
            metavar="FILE",
            help="Write the fixes as a diagnose log (CSV).",
        ),
    ] = None,
    plots: PlotsOpt = None,
    report_file: Annotated[
        Path | None,
        typer.Option(
            "--report",
            parser=_output_name,
            metavar="FILE",
            help="Write a self-contained HTML report.",
        ),
    ] = None,
    config: ConfigOpt = None,
    tau: TauOpt = None,
    alpha: AlphaOpt = None,
    probe_factor: COpt = None,
    flips: FlipsOpt = None,
    block_length: BlockOpt = None,
    variant: VariantOpt = None,
    srd_form: SrdOpt = None,
    metrics: MetricsOpt = None,
    ks_alpha: KsAlphaOpt = None,
    nees_alpha: NeesAlphaOpt = None,
    exact_pvalue: ExactOpt = None,
    seed: SeedOpt = None,
    fmt: FormatOpt = OutputFormat.TABLE,
    output: OutputOpt = None,
) -> int:
    """The paper's UWB pipeline on a STAR-loc uwb.csv (Section V, Table IV)."""
    from credcli.cli.settings import build_diagnosis_config, load_config
    from credcli.io.files import write_atomic
    from credcli.studies.uwb import UwbSettings
    from credcli.workflows import export_log_text, run_uwb

    inputs = [file, anchors, config]
    _guard({"--output": output, "--export-log": export_log, "--report": report_file}, inputs, plots)
    cfg = load_config(config)
    dconf, seed = build_diagnosis_config(
        cfg,
        _diagnosis_cli(
            tau,
            alpha,
            probe_factor,
            flips,
            block_length,
            variant,
            srd_form,
            metrics,
            None,
            None,
            ks_alpha,
            nees_alpha,
            exact_pvalue,
        ),
        seed,
    )
    settings = UwbSettings(
        range_column=range_column,
        packet_window=packet_window,
        min_anchors=min_anchors,
        max_speed=max_speed,
        min_static=min_static,
        screen=screen is ScreenMode.ALL,
        residual_level=residual_level,
        robust=robust,
        anchor_map=_id_pairs(anchor_map, "--anchor-map", int),
        **_std_settings(std),
    )
    with _Progress("diagnosing periods") as bar:
        result, run = run_uwb(
            file,
            settings,
            dconf,
            anchors,
            window,
            whole,
            seed,
            bar,
            plots=plots is not None or report_file is not None,
        )
    for warning in run.notes:  # anchors that disagree with the log's ground truth
        print(f"credcli: warning: {warning}", file=sys.stderr)
    if export_log is not None:
        write_atomic(export_log, export_log_text(run.log), inputs)
        _stderr().print(f"wrote {export_log} ({run.log.n} fixes)", highlight=False)
    _emit(result.report, fmt, output, inputs=inputs)
    _write_plots(result, plots)
    if report_file is not None:
        from credcli.report.html import build_html

        write_atomic(
            report_file,
            build_html(f"credcli uwb: {file.name}", result.report, result.plots, str(file)),
            inputs,
        )
        _stderr().print(f"wrote {report_file}", highlight=False)
    return 0


@app.command()
def report(
    logs: LogsArg,
    output: Annotated[
        Path,
        typer.Option(
            "--output",
            "-o",
            parser=_output_name,
            metavar="FILE",
            help="The HTML file to write.",
            show_default=False,
        ),
    ],
    config: ConfigOpt = None,
    window: WindowOpt = None,
    whole: WholeOpt = None,
    time_column: TimeColOpt = None,
    segment_column: SegColOpt = None,
    truth_columns: TruthColsOpt = None,
    estimate_columns: EstColsOpt = None,
    cov_columns: CovColsOpt = None,
    cov_kind: CovKindOpt = None,
    drop_invalid: DropOpt = None,
    truth: TruthOpt = None,
    input_format: InputFormatOpt = None,
    truth_format: TruthFormatOpt = None,
    topic: TopicOpt = None,
    truth_topic: TruthTopicOpt = None,
    time_unit: TimeUnitOpt = None,
    max_dt: MaxDtOpt = None,
    time_offset: TimeOffsetOpt = None,
    states: StatesOpt = None,
    perturbation: PerturbationOpt = None,
    innovations: InnovationsOpt = None,
    errors_only: ErrorsOnlyOpt = None,
    tau: TauOpt = None,
    alpha: AlphaOpt = None,
    probe_factor: COpt = None,
    flips: FlipsOpt = None,
    block_length: BlockOpt = None,
    variant: VariantOpt = None,
    srd_form: SrdOpt = None,
    metrics: MetricsOpt = None,
    min_epochs: MinEpochsOpt = None,
    max_elt_epochs: MaxEltOpt = None,
    ks_alpha: KsAlphaOpt = None,
    nees_alpha: NeesAlphaOpt = None,
    exact_pvalue: ExactOpt = None,
    jobs: JobsOpt = None,
    scheduler: SchedulerOpt = None,
    seed: SeedOpt = None,
    monte_carlo: MonteCarloOpt = False,
) -> int:
    """Diagnose logs and write one self-contained HTML report (table, parameters, figures)."""
    from credcli.workflows import run_diagnose

    _check_plotting(output)
    inputs = [*logs, config, truth]
    _guard({"--output": output}, inputs)
    setup = _diagnose_setup(locals())
    with _cluster(scheduler) as runner, _Progress("diagnosing segments") as bar:
        run = run_diagnose(
            logs,
            progress=bar,
            plots=True,
            jobs=_jobs(jobs),
            monte_carlo=monte_carlo,
            runner=runner,
            **setup,
        )
    _print_notes(run.report)
    _write_html(output, "credcli report: " + ", ".join(p.name for p in logs), run, logs, inputs)
    return 0


def _click_exception_types() -> tuple[type, ...]:
    """Click's exception base: vendored by typer >= 0.2x, the click package before."""
    types: list[type] = []
    try:
        from typer._click.exceptions import ClickException as Vendored

        types.append(Vendored)
    except ImportError:
        pass
    try:
        from click import ClickException

        types.append(ClickException)
    except ImportError:
        pass
    return tuple(types)


def main(argv: list[str] | None = None) -> int:
    """Entry point: run the app and turn every outcome into an exit code.

    0 ok; 1 a regression verdict (gate, --fail-on); 2 bad input or usage, one line on
    stderr; 3 an internal error, one line (the traceback with --debug); 130 interrupted.
    Warnings (numpy's among them) are never printed raw: each distinct one becomes a
    ``credcli: note:`` line on stderr at the end, with its source under --debug.
    """
    import warnings

    from credcli.parallel import keep_freed_memory, single_threaded_blas

    single_threaded_blas()  # before numpy loads; a user's own setting wins
    _terminate_on_signals()
    args = list(sys.argv[1:] if argv is None else argv)
    if "--help" not in args and not app_commands().isdisjoint(args):
        keep_freed_memory()  # this process is credcli's own: it may tune its allocator
    debug = (
        "--debug" in args[: next((i for i, a in enumerate(args) if a in app_commands()), len(args))]
    )
    command = typer.main.get_command(app)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            code = _run(command, args, debug)
        finally:
            _note_warnings(caught, debug)
    return code


class Terminated(BaseException):
    """SIGTERM or SIGHUP arrived: unwinds like Ctrl-C (temporary files removed, workers
    stopped), but is not a KeyboardInterrupt, which Click would report as an abort."""

    def __init__(self, signum: int) -> None:
        super().__init__(signum)
        self.signum = signum


def _terminate_on_signals() -> None:
    """SIGTERM and SIGHUP end a run as Ctrl-C does, with exit 128 + the signal's number."""
    import signal

    def handler(signum, frame):
        raise Terminated(signum)

    for name in ("SIGTERM", "SIGHUP"):
        if hasattr(signal, name):
            signal.signal(getattr(signal, name), handler)


def app_commands() -> set[str]:
    return {c.name or c.callback.__name__ for c in app.registered_commands}


_LIBRARY_CHATTER = (DeprecationWarning, PendingDeprecationWarning, FutureWarning)


def _note_warnings(caught, debug: bool) -> None:
    """Each distinct warning once, as a ``credcli: note:`` line. numpy's floating-point
    warnings ("overflow encountered in matmul") are one line in the user's terms, with
    numpy's words in brackets; where they came from only under --debug."""
    seen: dict[str, None] = {}
    floating: dict[str, None] = {}
    for w in caught:
        if issubclass(w.category, _LIBRARY_CHATTER) and not debug:
            continue  # a library's notice to its own callers, not about the user's data
        message = str(w.message).splitlines()[0] if str(w.message) else ""
        where = f" ({w.filename}:{w.lineno})" if debug else ""
        if issubclass(w.category, RuntimeWarning) and " encountered in " in message:
            floating[message + where] = None
        else:
            seen[f"{w.category.__name__}: {message}{where}"] = None
    if floating:
        print(
            "credcli: note: some numbers overflowed or were undefined while computing "
            f"({'; '.join(floating)}); the log's values may be far outside the range of its "
            "claimed covariances, so read the affected figures with care",
            file=sys.stderr,
        )
    for text in seen:
        print(f"credcli: note: {text}", file=sys.stderr)


def _run(command, args: list[str], debug: bool) -> int:
    try:
        result = command.main(args=args, prog_name="credcli", standalone_mode=False)
    except CredcliError as exc:
        _traceback(debug)
        print(f"credcli: error: {one_line(flag_names(exc.message))}", file=sys.stderr)
        return 2
    except _click_exception_types() as exc:
        ctx = getattr(exc, "ctx", None)
        if type(exc).__name__ == "NoArgsIsHelpError" and ctx is not None:
            print(ctx.get_help())
            return 0
        hint = f" (see 'credcli {ctx.info_name} --help')" if ctx is not None and ctx.parent else ""
        print(f"credcli: error: {exc.format_message()}{hint}", file=sys.stderr)
        return 2 if getattr(exc, "exit_code", 2) in (1, 2) else exc.exit_code
    except Terminated as exc:
        import signal

        print(f"credcli: terminated ({signal.Signals(exc.signum).name})", file=sys.stderr)
        return 128 + exc.signum
    except (typer.Abort, KeyboardInterrupt) as exc:
        if isinstance(exc.__context__, EOFError):  # Click turns an EOFError into an Abort
            _traceback(debug)
            print(
                "credcli: error: an input ended early (a truncated compressed file?)",
                file=sys.stderr,
            )
            return 2
        print("credcli: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:
        _silence_stdout()
        return 0
    except SystemExit as exc:  # Typer's answer to a closed pipe (EPIPE) is sys.exit(1)
        if exc.code == 1:
            _silence_stdout()
            return 0
        return int(exc.code or 0)
    except OSError as exc:
        from credcli.io.files import USER_ERRNOS, describe_os_error

        if exc.errno not in USER_ERRNOS:
            return _internal_error(exc, debug)
        _traceback(debug)
        if exc.filename is None and exc.errno == errno.ENOSPC:
            _silence_stdout()  # so that Python's own flush at exit does not fail again
        print(f"credcli: error: {describe_os_error(exc)}", file=sys.stderr)
        return 2
    except MemoryError as exc:
        if not _raised_by_credcli(exc):  # a library's (Dask reading a bad frame, say)
            return _internal_error(exc, debug)
        _traceback(debug)
        print(
            "credcli: error: not enough memory for this run; use fewer --flips, a smaller "
            "--max-elt-epochs or shorter segments",
            file=sys.stderr,
        )
        return 2
    except Exception as exc:  # noqa: BLE001 (the outer edge: one line, or the traceback)
        return _internal_error(exc, debug)
    if result == 130:  # Typer turns KeyboardInterrupt into a silent Exit(130)
        print("credcli: interrupted", file=sys.stderr)
    return int(result or 0)


def _raised_by_credcli(exc: BaseException) -> bool:
    """Whether the innermost frame of the traceback is credcli's own code (an allocation
    of ours, sized by the user's settings)."""
    import os

    tb = exc.__traceback__
    while tb is not None and tb.tb_next is not None:
        tb = tb.tb_next
    package = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    return tb is not None and os.path.abspath(tb.tb_frame.f_code.co_filename).startswith(package)


def _internal_error(exc: BaseException, debug: bool) -> int:
    from credcli.io.files import shown

    _traceback(debug)
    first = str(exc).strip().splitlines()[0] if str(exc).strip() else ""
    print(
        f"credcli: internal error: {type(exc).__name__}{': ' + shown(first, 300) if first else ''}"
        "; run with --debug for the traceback",
        file=sys.stderr,
    )
    return 3


FLAG_NAMES = {
    "max_dt": "--max-dt",
    "time_offset": "--time-offset",
    "n_flips": "--flips",
    "tau_nci": "--tau",
    "alpha": "--alpha",
    "c": "--probe-factor",
    "block_length": "--block-length",
    "variant": "--variant",
    "min_epochs": "--min-epochs",
    "max_elt_epochs": "--max-elt-epochs",
    "ks_alpha": "--ks-alpha",
    "nees_alpha": "--nees-alpha",
    "max_nci_increase": "--max-nci-increase",
    "max_anees_ratio": "--max-anees-ratio",
    "fail_on": "--fail-on",
    "plots": "--plots",
    "window": "--window",
    "scenario": "--scenario",
    "sweep": "--sweep",
    "seed": "--seed",
    "trials": "--trials",
    "n": "--n",
    "dim": "--dim",
    "std": "--std",
    "packet_window": "--packet-window",
    "min_anchors": "--min-anchors",
    "max_speed": "--max-speed",
    "min_static": "--min-static",
}
"""Library parameter names and the flags that set them."""

_LEADING_PARAMETER = re.compile(r"^(invalid setting: )?([a-z_]+)\b")


def flag_names(message: str) -> str:
    """A library message names a parameter first ("n_flips 5 is too few …"); on the command
    line it names the flag ("--flips 5 is too few …"). Messages about files are untouched."""
    m = _LEADING_PARAMETER.match(message)
    if m and m[2] in FLAG_NAMES:
        return message[: m.start(2)] + FLAG_NAMES[m[2]] + message[m.end(2) :]
    return message


def one_line(message: str) -> str:
    """A message as one line: a newline in it (a file name's, a library's) is escaped."""
    return message.replace("\r", "\\r").replace("\n", "\\n")


def _traceback(debug: bool) -> None:
    if debug:
        import traceback

        traceback.print_exc()


def _silence_stdout() -> None:
    """After a closed pipe (credcli … | head), stop Python from failing again at exit."""
    import os

    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError):
        pass


def entry() -> None:
    sys.exit(main())
