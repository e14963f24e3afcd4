"""The credcli commands. Each declares its options (shared ones as groups,
:mod:`credcli.cli.options`), makes one typed request (:mod:`credcli.cli.settings`), runs
one workflow (:mod:`credcli.workflows`) and emits the result (:mod:`credcli.cli.emit`).

The settings, workflows and emitters are imported inside the commands: they load numpy,
and ``credcli --help`` must not.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Annotated

import typer

from credcli.cli.emit import (
    Progress,
    check_figures,
    check_plotting,
    cluster,
    emit,
    emit_fail_on,
    emit_gate_verdict,
    emit_run,
    emit_uwb,
    fail_on_conditions,
    guard_outputs,
    print_notes,
    stderr_console,
    streamed_writer,
    write_html,
    write_plots,
)
from credcli.cli.options import (
    INPUT,
    LOG_FORMATS,
    OUTPUT,
    SEGMENTS,
    STUDY,
    ConfigOpt,
    LogOptions,
    LogsArg,
    MonteCarloOpt,
    OutputOpt,
    OutputOptions,
    PlotsOpt,
    ReportOpt,
    RuleOptions,
    RunOptions,
    SeedOpt,
    SegmentOptions,
    StudyOptions,
    ThresholdOptions,
    UwbOptions,
    VerdictOptions,
    declare,
    file_name,
    output_name,
)
from credcli.report.formats import OutputFormat
from credcli.studies.settings import CURVE_RUNS
from credcli.version import __version__

app = typer.Typer(
    name="credcli",
    help="Can you trust the covariance your estimator reports, and if not, why not?",
    add_completion=False,
    no_args_is_help=True,
    pretty_exceptions_enable=False,
    rich_markup_mode="markdown",  # help panels; Markdown keeps '[default: …]' as text
)


def examples(*lines: tuple[str, str]) -> str:
    """A command's epilog: example command lines, each with what it does (Markdown).

    Parameters
    ----------
    *lines : tuple of (str, str)
        (command line, what it does), one per example.

    Returns
    -------
    str
        ``**Examples**`` and one Markdown list item per example.

    Examples
    --------
    >>> print(examples(("credcli diagnose log.csv", "one row per segment")))
    **Examples**
    <BLANKLINE>
    - `credcli diagnose log.csv` — one row per segment
    """
    return "**Examples**\n\n" + "\n".join(f"- `{command}` — {what}" for command, what in lines)


def _show_version(value: bool) -> None:
    if value:
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


@app.command(
    epilog=examples(
        (
            "credcli diagnose sample_data/estimator_log.csv",
            "the bundled sample, one row per segment",
        ),
        ("credcli diagnose log.csv --window 10s -f json -o out.json", "10 s windows, as JSON"),
        (
            "credcli diagnose est.txt --truth gt.txt --states pose --fail-on optimism",
            "exit 1 on optimism (CI)",
        ),
    )
)
@declare
def diagnose(
    logs: LogsArg,
    config: ConfigOpt = None,
    segments: SegmentOptions = SegmentOptions(),
    log: LogOptions = LogOptions(),
    rule: RuleOptions = RuleOptions(),
    run: RunOptions = RunOptions(),
    seed: SeedOpt = None,
    out: OutputOptions = OutputOptions(),
    ci: VerdictOptions = VerdictOptions(),
    plots: PlotsOpt = None,
    report_file: ReportOpt = None,
    monte_carlo: MonteCarloOpt = False,
) -> int:
    """Diagnose each segment of one or more estimator logs (calibrated rule by default)."""
    from credcli.ci.reports import summary_wanted
    from credcli.cli.settings import diagnose_request
    from credcli.requests import Kept
    from credcli.workflows import run_diagnose

    conditions = fail_on_conditions(ci)
    inputs = [*logs, config, log.truth]
    written = {"--output": out.output, "--junit": ci.junit, "--summary": ci.summary}
    keep = guard_outputs(written | {"--report": report_file}, inputs, plots)
    check_plotting(plots, report_file)
    figures = plots is not None or report_file is not None
    request = diagnose_request(
        logs,
        config,
        log,
        segments,
        rule,
        seed,
        run,
        monte_carlo=monte_carlo,
        figures=figures,
        keep=Kept.NOTHING if conditions is None else Kept.VERDICTS,  # --fail-on reads them
    )
    # --fail-on's Markdown summary, where it is written, shows the report's tables
    summarised = conditions is not None and summary_wanted(ci.summary)
    whole = plots is not None or report_file is not None or summarised
    write = streamed_writer(out.fmt, out.output, inputs, whole)  # as it is diagnosed
    with cluster(run.scheduler) as runner, Progress("diagnosing segments") as bar:
        result = run_diagnose(request, bar, runner, write)
    if write is None:
        title = "credcli diagnose: " + ", ".join(p.name for p in logs)
        emit_run(result, out, plots, report_file, title, logs, inputs, keep)
    passed = emit_fail_on(result, conditions, ci, inputs)
    return 0 if passed else 1


@app.command(
    epilog=examples(
        (
            "credcli baseline sample_data/estimator_log.csv -o baseline.json",
            "record today's verdicts",
        ),
        (
            "credcli baseline log.csv --window 5s --variant paper -o baseline.json",
            "with other settings, kept in the file",
        ),
    )
)
@declare
def baseline(
    log_file: Annotated[
        Path,
        typer.Argument(
            parser=file_name,
            metavar="LOG",
            help=f"The estimator log to record ({LOG_FORMATS}).",
            show_default=False,
        ),
    ],
    output: OutputOpt = None,
    config: ConfigOpt = None,
    segments: SegmentOptions = SegmentOptions(),
    log: LogOptions = LogOptions(),
    rule: RuleOptions = RuleOptions(),
    run: RunOptions = RunOptions(),
    seed: SeedOpt = None,
) -> int:
    """Record a baseline: the JSON of `diagnose` with a schema version and every parameter."""
    from credcli.cli.settings import diagnose_request
    from credcli.requests import Kept
    from credcli.workflows import run_baseline

    inputs = [log_file, config, log.truth]
    guard_outputs({"--output": output}, inputs)
    request = diagnose_request(
        [log_file], config, log, segments, rule, seed, run, keep=Kept.NOTHING
    )
    write = streamed_writer(OutputFormat.JSON, output, inputs)
    with cluster(run.scheduler) as runner, Progress("diagnosing segments") as bar:
        recorded = run_baseline(request, bar, runner, write)
    if write is None:
        print_notes(recorded)
        emit(recorded, OutputFormat.JSON, output, inputs=inputs)
    return 0


@app.command(
    epilog=examples(
        (
            "credcli gate sample_data/estimator_log_regressed.csv --baseline baseline.json",
            "exit 1 on a regression",
        ),
        (
            "credcli gate new.csv -b baseline.json --junit report.xml --summary report.md",
            "CI reports",
        ),
    )
)
@declare
def gate(
    log: Annotated[
        Path,
        typer.Argument(
            parser=file_name,
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
            parser=file_name,
            metavar="FILE",
            help="Baseline JSON from `credcli baseline`.",
            show_default=False,
            rich_help_panel=INPUT,
        ),
    ],
    thresholds: ThresholdOptions = ThresholdOptions(),
    out: OutputOptions = OutputOptions(),
    ci: VerdictOptions = VerdictOptions(),
    config: ConfigOpt = None,
    plots: PlotsOpt = None,
    truth: Annotated[
        Path | None,
        typer.Option(
            "--truth",
            parser=file_name,
            metavar="FILE",
            help="Ground truth of LOG; needed when the baseline had one (a baseline names no files).",
            rich_help_panel=INPUT,
        ),
    ] = None,
    segments: SegmentOptions = SegmentOptions(),
    rule: RuleOptions = RuleOptions(),
    run: RunOptions = RunOptions(),
    seed: SeedOpt = None,
) -> int:
    """Diagnose LOG with the baseline's parameters and fail (exit 1) on a regression."""
    from credcli.ci.gate import parse_fail_on
    from credcli.cli.settings import gate_request
    from credcli.workflows import run_gate

    conditions = parse_fail_on(ci.fail_on) if ci.fail_on is not None else None
    inputs = [log, baseline_file, config, truth]
    written = {"--output": out.output, "--junit": ci.junit, "--summary": ci.summary}
    keep = guard_outputs(written, inputs, plots)
    check_plotting(plots)
    given = (thresholds, truth, segments, rule, seed, run)
    request = gate_request(log, baseline_file, config, *given, figures=plots is not None)
    with cluster(run.scheduler) as runner, Progress("diagnosing segments") as bar:
        result = run_gate(request, bar, runner)
    check_figures(result.plots, plots, keep)
    emit(result.report, out.fmt, out.output, inputs=inputs)
    write_plots(result.plots, plots, keep)
    passed = emit_gate_verdict(result, request, conditions, ci, str(log), baseline_file, inputs)
    return 0 if passed else 1


@app.command(
    epilog=examples(
        ("credcli simulate --scenario pess+smm --trials 200", "one scenario of Table II"),
        ("credcli simulate --sweep rho=0.1:10:20 -f csv -o sweep.csv", "a sweep, as CSV"),
    )
)
@declare
def simulate(
    scenario: Annotated[
        str,
        typer.Option(
            "--scenario",
            "-s",
            help="all, a label (credible, optimism, …) or alias (cred, opt, pess, opt+smm, "
            "pess+smm); comma-separated for several.",
            rich_help_panel=STUDY,
        ),
    ] = "all",
    study: StudyOptions = StudyOptions(),
    sweep: Annotated[
        list[str] | None,
        typer.Option(
            "--sweep",
            help="Sweep one parameter: rho=0.1:10:20, bias=0:3:13, n=25,50,100, dim=…, B=…, "
            "tau=…, ar=0,0.5,0.9",
            rich_help_panel=STUDY,
        ),
    ] = None,
    curves: Annotated[
        bool,
        typer.Option(
            "--curves",
            help="Print the Fig. 1 curves (mean ES and NLL against ρ and γ) instead.",
            rich_help_panel=STUDY,
        ),
    ] = False,
    curve_runs: Annotated[
        int,
        typer.Option(
            "--curve-runs", help="Monte Carlo runs per curve point.", rich_help_panel=STUDY
        ),
    ] = CURVE_RUNS,
    run: RunOptions = RunOptions(),
    plots: PlotsOpt = None,
    config: ConfigOpt = None,
    rule: RuleOptions = RuleOptions(),
    seed: SeedOpt = None,
    out: OutputOptions = OutputOptions(),
) -> int:
    """The paper's Monte Carlo study (Tables II and III), sweeps and the Fig. 1 curves."""
    from credcli.cli.settings import only_one, simulate_request
    from credcli.workflows import run_simulate

    keep = guard_outputs({"--output": out.output}, [config], plots)
    check_plotting(plots)
    request = simulate_request(
        config,
        study,
        rule,
        seed,
        run,
        scenario=scenario,
        sweep=only_one("--sweep", sweep),
        curves=curves,
        curve_runs=curve_runs,
        figures=plots is not None,
    )
    start = time.perf_counter()
    with cluster(run.scheduler) as runner, Progress("simulating trials", min_total=1) as bar:
        result, summary = run_simulate(request, bar, runner)
    check_figures(result, plots, keep)
    emit(result.report, out.fmt, out.output, inputs=[config])
    write_plots(result, plots, keep)
    stderr_console().print(f"{summary} in {time.perf_counter() - start:.2f} s", highlight=False)
    return 0


@app.command(
    epilog=examples(
        ("credcli uwb sample_data/starloc_grid_uwb.csv", "static periods, self-calibrated anchors"),
        (
            "credcli uwb uwb.csv --anchors markers.csv --std 0.1 --window 5s",
            "known anchors, 5 s windows",
        ),
    )
)
@declare
def uwb(
    file: Annotated[
        Path,
        typer.Argument(
            parser=file_name, metavar="UWB_CSV", help="A STAR-loc uwb.csv.", show_default=False
        ),
    ],
    anchors: Annotated[
        Path | None,
        typer.Option(
            "--anchors",
            parser=file_name,
            metavar="FILE",
            help="Anchor positions (STAR-loc markers CSV); default: self-calibrate from the file.",
            rich_help_panel=INPUT,
        ),
    ] = None,
    window: Annotated[
        str | None,
        typer.Option(
            "--window",
            "-w",
            help="Fixed windows (5s) instead of static periods.",
            rich_help_panel=SEGMENTS,
        ),
    ] = None,
    whole: Annotated[
        bool | None,
        typer.Option("--whole", help="The whole run as one period.", rich_help_panel=SEGMENTS),
    ] = None,
    settings: UwbOptions = UwbOptions(),
    export_log: Annotated[
        Path | None,
        typer.Option(
            "--export-log",
            parser=output_name,
            metavar="FILE",
            help="Write the fixes as a diagnose log (CSV).",
            rich_help_panel=OUTPUT,
        ),
    ] = None,
    plots: PlotsOpt = None,
    report_file: ReportOpt = None,
    config: ConfigOpt = None,
    rule: RuleOptions = RuleOptions(),
    seed: SeedOpt = None,
    out: OutputOptions = OutputOptions(),
) -> int:
    """The paper's UWB pipeline on a STAR-loc uwb.csv (Section V, Table IV)."""
    from credcli.cli.settings import uwb_request
    from credcli.workflows import run_uwb

    inputs = [file, anchors, config]
    written = {"--output": out.output, "--export-log": export_log, "--report": report_file}
    keep = guard_outputs(written, inputs, plots)
    request = uwb_request(
        file,
        config,
        settings,
        anchors,
        SegmentOptions(window, whole),
        rule,
        seed,
        figures=plots is not None or report_file is not None,
    )
    with Progress("diagnosing periods") as bar:
        result, fixes = run_uwb(request, bar)
    emit_uwb(result, fixes, out, plots, report_file, export_log, file, inputs, keep)
    return 0


@app.command(
    epilog=examples(
        (
            "credcli report sample_data/estimator_log.csv -o report.html",
            "table, parameters and figures",
        ),
        ("credcli report run_*.csv --monte-carlo --window 30s -o runs.html", "Monte Carlo runs"),
    )
)
@declare
def report(
    logs: LogsArg,
    output: Annotated[
        Path,
        typer.Option(
            "--output",
            "-o",
            parser=output_name,
            metavar="FILE",
            help="The HTML file to write.",
            show_default=False,
            rich_help_panel=OUTPUT,
        ),
    ],
    config: ConfigOpt = None,
    segments: SegmentOptions = SegmentOptions(),
    log: LogOptions = LogOptions(),
    rule: RuleOptions = RuleOptions(),
    run: RunOptions = RunOptions(),
    seed: SeedOpt = None,
    monte_carlo: MonteCarloOpt = False,
) -> int:
    """Diagnose logs and write one self-contained HTML report (table, parameters, figures)."""
    from credcli.cli.settings import diagnose_request
    from credcli.workflows import run_diagnose

    check_plotting(output)
    inputs = [*logs, config, log.truth]
    guard_outputs({"--output": output}, inputs)
    request = diagnose_request(
        logs, config, log, segments, rule, seed, run, monte_carlo=monte_carlo, figures=True
    )
    with cluster(run.scheduler) as runner, Progress("diagnosing segments") as bar:
        result = run_diagnose(request, bar, runner)
    print_notes(result.report)
    title = "credcli report: " + ", ".join(p.name for p in logs)
    write_html(output, title, result, logs, inputs)
    return 0
