"""What a command shows and writes: reports on stdout or to files, notes and progress on
stderr, figures, HTML and CI reports; and the checks on output paths made before any work.

Imports inside the functions are lazy on purpose: Rich, numpy (through the report
modules) and Dask load only when a command runs, so that ``credcli --help`` stays fast.
"""

from __future__ import annotations

import contextlib
import csv
import dataclasses
import io
import os
import re
import stat
import sys
from collections.abc import Callable
from pathlib import Path

from credcli.cli.flags import flag_names
from credcli.errors import CredcliError, printable, shortened
from credcli.report.formats import OutputFormat


def emit(report, fmt: OutputFormat, output: Path | None, inputs=()) -> None:
    """Print a report to stdout (Rich tables when a terminal) or write it to a file; its
    notes name options as the command line does (:func:`credcli.cli.flags.flag_names`).

    Off a terminal, tables are as wide as $COLUMNS if given, else keep every column.

    Parameters
    ----------
    report : Report
        The report to show.
    fmt : OutputFormat
        Its format (``--format``).
    output : Path or None
        The file to write it to (atomically, ``--output``); None for stdout.
    inputs : iterable of Path, optional
        The command's input files, which ``output`` may not overwrite.
    """
    from credcli.io.files import STDIN, write_atomic
    from credcli.report.render import rich_table, text_pieces

    report = dataclasses.replace(report, notes=[flag_names(n) for n in report.notes])
    if output is not None:
        pieces = text_pieces(report, fmt)
        if fmt is OutputFormat.CSV and _is_screen(output):  # -o /dev/stdout, /dev/tty
            pieces = map(terminal_csv, pieces)
        write_atomic(output, pieces, inputs)
        if str(output) != STDIN:  # standard output, as without -o: no note
            stderr_console().print(printable(f"wrote {output}"), highlight=False, markup=False)
        return
    if sys.stdout is None:  # started with its descriptor closed (credcli … >&-)
        raise CredcliError("standard output is closed; pass -o FILE to write the report to a file")
    if fmt is OutputFormat.TABLE:
        from rich.console import Console

        console = Console(highlight=False)
        fit: int | None = console.width  # a terminal: hide columns that do not fit
        if not console.is_terminal:  # a log or a pipe: $COLUMNS if given, else every column
            fit = _given_width()
            console = Console(width=fit or UNLIMITED_WIDTH, soft_wrap=fit is None, highlight=False)
        for table in report.tables:
            console.print(rich_table(table, fit))
        for note in report.notes:
            console.print(printable(note), markup=False, highlight=False)
        return
    for piece in text_pieces(report, fmt):
        sys.stdout.write(terminal_csv(piece) if fmt is OutputFormat.CSV else piece)


def _is_screen(path: Path) -> bool:
    """Whether ``path`` is this process's standard output or error, or a terminal: where
    text is shown rather than kept (``-o /dev/stdout``)."""
    try:
        target = os.stat(path)
    except (OSError, ValueError):
        return False
    if stat.S_ISREG(target.st_mode) or stat.S_ISDIR(target.st_mode):
        return False
    for fd in (1, 2):
        with contextlib.suppress(OSError):
            mine = os.fstat(fd)
            if (mine.st_dev, mine.st_ino) == (target.st_dev, target.st_ino):
                return True
    return stat.S_ISCHR(target.st_mode) and os.path.realpath(path).startswith(
        ("/dev/tty", "/dev/pts/")
    )


_CSV_UNSAFE = re.compile(r'[\x00-\x1f\x7f-\x9f\u2028\u2029\ud800-\udfff"]')
"""What may put a control character, a line break or an undecodable name of a CSV cell on
the terminal: a control character, or a quote (a quoted cell may hold CR and LF)."""


def terminal_csv(text: str) -> str:
    """CSV for standard output: each cell's control characters, line breaks and lone
    surrogates escaped (:func:`credcli.errors.printable`), so that a segment or file name
    can neither drive the terminal nor start a line of its own. A file (``--output``)
    keeps the cells as they are.

    Parameters
    ----------
    text : str
        CSV, rows ending in CRLF (RFC 4180).

    Returns
    -------
    str
        ``text`` itself when no cell holds such a character; else the same CSV with each
        such cell escaped.
    """
    if _CSV_UNSAFE.search(text.replace("\r\n", "")) is None:
        return text
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\r\n")
    for row in csv.reader(io.StringIO(text, newline="")):
        writer.writerow([printable(cell) for cell in row])
    return buf.getvalue()


UNLIMITED_WIDTH = 10_000
"""Width of text output that is not a terminal and was given no $COLUMNS: tables keep every
column (a CI log scrolls sideways, it does not lose the "why")."""


def _given_width() -> int | None:
    """$COLUMNS as a positive integer, or None when it is unset or not one."""
    try:
        width = int(os.environ.get("COLUMNS", ""))
    except ValueError:
        return None
    return width if width > 0 else None


def stderr_console():
    """Messages on stderr, never wrapped off a terminal (a CI log keeps each on one line).

    Returns
    -------
    rich.console.Console
        A console on stderr; off a terminal, soft-wrapped at $COLUMNS or
        `UNLIMITED_WIDTH`.
    """
    from rich.console import Console

    console = Console(stderr=True, highlight=False)
    if not console.is_terminal:
        console = Console(
            stderr=True, soft_wrap=True, width=_given_width() or UNLIMITED_WIDTH, highlight=False
        )
    return console


class Progress:
    """A Rich progress bar on stderr, shown only on a terminal and for runs of at least
    ``min_total`` steps. Called as ``progress(done, total)``; a context manager, which
    stops the bar on exit.

    Parameters
    ----------
    description : str
        The bar's text, e.g. ``"diagnosing segments"``.
    min_total : int, default 10
        The smallest number of steps that shows a bar.
    """

    def __init__(self, description: str, min_total: int = 10) -> None:
        self.description = description
        self.min_total = min_total
        self._bar = None
        self._task = None
        self._show = stderr_console().is_terminal

    def __enter__(self):
        return self

    def __call__(self, done: int, total: int) -> None:
        if self._bar is None and self._show and total >= self.min_total:
            from rich.progress import Progress as RichProgress

            self._bar = RichProgress(console=stderr_console(), transient=True)
            self._bar.start()
            self._task = self._bar.add_task(self.description, total=total)
        if self._bar is not None:
            self._bar.update(self._task, completed=done)

    def __exit__(self, *exc) -> None:
        if self._bar is not None:
            self._bar.stop()


def print_notes(report) -> None:
    """The decisions taken while reading the logs, one ``credcli: note:`` line each.

    Parameters
    ----------
    report : Report
        A diagnose report; the notes of each entry of its document's ``logs`` go to
        stderr, options named as flags.
    """
    from credcli.report.records import log_notes

    for note in log_notes(report.document):
        print(printable(f"credcli: note: {flag_names(note)}"), file=sys.stderr)


SCHEDULER_ENV = "CREDCLI_SCHEDULER"
"""The environment variable that gives --scheduler when the option is not given."""


def cluster(scheduler: str | None):
    """A DaskRunner for --scheduler, or for ``CREDCLI_SCHEDULER`` when the option is not
    given (said in one line on stderr: never a silent redirection), closed on exit; or a
    context of None.

    Parameters
    ----------
    scheduler : str or None
        ``--scheduler``: a scheduler's address or ``local:N``; None or empty for
        $CREDCLI_SCHEDULER, else no cluster.

    Returns
    -------
    DaskRunner or contextlib.nullcontext
        A context manager that gives the runner (which announces the cluster on a
        terminal), or None when no scheduler is named.

    Raises
    ------
    CredcliError
        If Dask is missing or the scheduler cannot be reached (`credcli.schedule.cluster`).
    """
    if not scheduler:
        scheduler = os.environ.get(SCHEDULER_ENV) or None
        if scheduler is not None:
            shown = shortened(scheduler)
            note = f"credcli: note: running on the Dask scheduler {shown} ({SCHEDULER_ENV})"
            print(printable(note), file=sys.stderr)
    if not scheduler:
        return contextlib.nullcontext(None)
    from credcli.schedule.cluster import DaskRunner

    console = stderr_console()

    def announce(text: str) -> None:  # on a terminal, as the progress bar; quiet in CI
        console.print(printable(f"credcli: {text}"), highlight=False, markup=False)

    return DaskRunner(scheduler, announce if console.is_terminal else None)


def write_html(path: Path, title: str, run, sources, inputs) -> None:
    """Write a Run's self-contained HTML report and say so on stderr.

    Parameters
    ----------
    path : Path
        The HTML file (written atomically).
    title : str
        The page's title.
    run : Run
        A diagnosed Run: its report, figures, notes and results.
    sources : iterable
        The logs, shown comma-separated as the subtitle.
    inputs : iterable of Path
        The command's input files, which ``path`` may not overwrite.
    """
    from credcli.io.files import STDIN, write_atomic
    from credcli.report.html import build_html

    subtitle = ", ".join(map(str, sources))
    html = build_html(title, run.report, run.plots, subtitle, run.notes, run.results)
    write_atomic(path, html, inputs)
    if str(path) != STDIN:
        stderr_console().print(
            printable(f"wrote {path} ({len(run.plots)} figures)"), highlight=False, markup=False
        )


def guard_outputs(outputs: dict, inputs, plots: Path | None = None) -> list[Path]:
    """Before any work: no output may be an input or another output, or a directory, or
    lie under a file; the --plots directory may not be an input file, and is made now when
    another output is to be written in it. $GITHUB_STEP_SUMMARY, when set, is checked as an
    output too.

    Parameters
    ----------
    outputs : dict
        Option name (``"--output"``) -> the path it writes, or None.
    inputs : iterable of Path or None
        The command's input files (None entries are skipped).
    plots : Path or None, optional
        The ``--plots`` directory.

    Returns
    -------
    list of Path
        The inputs and every output (the step summary included), which no figure may
        overwrite (the ``keep`` of :func:`check_figures`).

    Raises
    ------
    CredcliError
        If an output is an input, another output or a directory, or lies under a file, or
        ``plots`` is a symbolic link, exists and is not a directory, or is an input's or an
        output's path.
    """
    from credcli.ci.reports import check_step_summary
    from credcli.io.files import check_directory_output, check_outputs, check_writable

    summary = os.environ.get("GITHUB_STEP_SUMMARY")
    if summary:  # appended at the end of a run: checked, like every output, first
        check_step_summary(summary)
        outputs = outputs | {"GITHUB_STEP_SUMMARY": Path(summary)}
    check_outputs(outputs, [p for p in inputs if p is not None], plots)
    for name, path in outputs.items():  # every place can take a file: none fails after
        if path is not None:  # another output was written
            check_writable(name, Path(path), append=name == "GITHUB_STEP_SUMMARY")
    if plots is not None:
        check_directory_output("--plots", plots, outputs, inputs)
        check_writable("--plots", plots, directory=True)
        where = Path(os.path.abspath(plots))
        inside = [
            p
            for p in outputs.values()
            if p is not None and Path(os.path.abspath(p)).parent == where
        ]
        if inside:  # made now, so that an output written before the figures finds it
            plots.mkdir(parents=True, exist_ok=True)
    return [Path(p) for p in (*inputs, *outputs.values()) if p is not None]


def check_plotting(*wanted) -> None:
    """Before any work: fail with the install hint when figures are asked for and
    matplotlib is missing.

    Parameters
    ----------
    *wanted : Path or None
        The options that write figures (``--plots``, ``--report``); figures are asked
        for when any is not None.

    Raises
    ------
    CredcliError
        If figures are asked for and matplotlib is not installed.
    """
    if any(w is not None for w in wanted):
        from credcli.report.plots import require_plotting

        require_plotting()


def check_figures(run, directory: Path | None, keep=()) -> None:
    """Before any output is written: the figures of a Run (or a list of figures) can all be
    written into ``directory`` (:func:`credcli.report.plots.check_plots`), if given.

    Parameters
    ----------
    run : Run or list
        A Run (its ``plots``), or the figures themselves.
    directory : Path or None
        ``--plots``; None checks nothing.
    keep : iterable of Path, optional
        The command's inputs and other outputs, which no figure may overwrite.
    """
    if directory is None:
        return
    from credcli.report.plots import check_plots

    check_plots(run if isinstance(run, list) else run.plots, directory, keep)


def write_plots(run, directory: Path | None, keep=()) -> None:
    """Write the figures of a Run (or a list of figures) into ``directory``, if given.

    Says on stderr how many were written, and then the Run's notes about its figures.

    Parameters
    ----------
    run : Run or list
        A Run (its ``plots`` and ``notes``), or the figures themselves.
    directory : Path or None
        ``--plots``; None writes nothing.
    keep : iterable of Path, optional
        The command's inputs and other outputs, which no figure may overwrite (checked
        before any figure is written).
    """
    if directory is None:
        return
    from credcli.report.plots import write_plots as write_figures

    paths = write_figures(run if isinstance(run, list) else run.plots, directory, keep)
    stderr_console().print(
        printable(f"wrote {len(paths)} figure(s) to {directory}"), highlight=False, markup=False
    )
    for note in () if isinstance(run, list) else getattr(run, "notes", ()):
        print(printable(f"credcli: note: {note}"), file=sys.stderr)


def _write_ci_reports(
    junit: Path | None, summary: Path | None, cases, markdown: Callable[[], str], inputs
) -> None:
    """The JUnit XML of ``cases`` to ``junit`` and the Markdown summary to ``summary`` (each
    if given) and to $GITHUB_STEP_SUMMARY when that is set; ``markdown()`` makes the
    summary, only where it is written (it reads the report's tables)."""
    from credcli.ci.reports import append_step_summary, junit_pieces, summary_wanted
    from credcli.io.files import write_atomic

    if junit is not None:
        write_atomic(junit, junit_pieces("credcli", cases), inputs)
    if not summary_wanted(summary):
        return
    text = markdown()
    if summary is not None:
        write_atomic(summary, text, inputs)
    append_step_summary(text)


def emit_run(
    run, out, plots: Path | None, report_file: Path | None, title, sources, inputs, keep=()
):
    """What `diagnose` shows of a Run: the reading notes, the report (``out``: its format
    and file), the figures into ``plots`` and an HTML report into ``report_file``.

    Parameters
    ----------
    run : Run
        The diagnosed Run.
    out : OutputOptions
        ``--format`` and ``--output``.
    plots : Path or None
        ``--plots``.
    report_file : Path or None
        ``--report``.
    title : str
        The HTML report's title.
    sources : iterable
        The logs, the HTML report's subtitle.
    inputs : iterable of Path
        The command's input files, which no output may overwrite.
    keep : iterable of Path, optional
        The command's other outputs (:func:`guard_outputs`), which no figure may overwrite
        either.
    """
    keep = [*inputs, out.output, report_file, *keep]
    check_figures(run, plots, keep)
    print_notes(run.report)
    emit(run.report, out.fmt, out.output, inputs=inputs)
    write_plots(run, plots, keep)
    if report_file is not None:
        write_html(report_file, title, run, sources, inputs)


def streamed_writer(fmt: OutputFormat, output: Path | None, inputs, whole: bool = False):
    """How `diagnose` (and `baseline`, whose file is JSON) writes its JSON or CSV file while
    its segments are diagnosed, or None where the whole report is needed first.

    ``-f json -o FILE`` and ``-f csv -o FILE`` are written as the results arrive
    (:func:`credcli.workflows.run_diagnose`'s ``write``), so that the memory does not grow
    with the number of segments; the file is complete or absent, as always
    (:func:`credcli.io.files.write_atomic`). The tables on the screen and their notes, and
    a device or FIFO, which would show half a document if a later segment failed, get the
    whole report, and so does a command whose other outputs read every result (``whole``).

    Parameters
    ----------
    fmt : OutputFormat
        ``--format``.
    output : Path or None
        ``--output``.
    inputs : iterable of Path
        The command's input files, which the output may not overwrite.
    whole : bool, default False
        Another output reads every result: the figures (``--plots``, ``--report``), or
        ``--fail-on``'s Markdown summary where it is written (``--summary``,
        $GITHUB_STEP_SUMMARY), which shows the tables.

    Returns
    -------
    callable or None
        ``write(report)``: the reading notes on stderr, then the report to the file, then
        "wrote FILE" (:func:`emit`); None.
    """
    from credcli.io.streams import is_stream

    if whole or output is None or is_stream(output):
        return None
    if fmt not in (OutputFormat.JSON, OutputFormat.CSV):
        return None

    def write(report) -> None:
        print_notes(report)
        emit(report, fmt, output, inputs=inputs)

    return write


def fail_on_conditions(ci):
    """The --fail-on conditions (None without --fail-on), checked before any work.

    Parameters
    ----------
    ci : VerdictOptions
        ``--fail-on``, ``--junit`` and ``--summary``.

    Returns
    -------
    FailOn or None
        The parsed conditions.

    Raises
    ------
    CredcliError
        If a condition is unknown, or ``--junit`` or ``--summary`` is given without
        ``--fail-on``.
    """
    from credcli.ci.gate import parse_fail_on

    conditions = parse_fail_on(ci.fail_on) if ci.fail_on is not None else None
    if (ci.junit or ci.summary) and conditions is None:
        raise CredcliError(
            "--junit and --summary report a verdict: give --fail-on too (e.g. --fail-on noncredible)"
        )
    return conditions


def emit_fail_on(run, conditions, ci, inputs) -> bool:
    """The --fail-on verdict of a diagnosed Run: JUnit and Markdown reports, one line on
    stderr; whether it passed (True without --fail-on).

    Parameters
    ----------
    run : Run
        The diagnosed Run.
    conditions : FailOn or None
        The --fail-on conditions (`fail_on_conditions`); None: nothing is checked.
    ci : VerdictOptions
        Where the JUnit and Markdown reports go.
    inputs : iterable of Path
        The command's input files, which no report may overwrite.

    Returns
    -------
    bool
        Whether no segment fails the conditions.
    """
    if conditions is None:
        return True
    from credcli.ci.gate import fail_on_verdict
    from credcli.ci.reports import fail_on_cases, summary_markdown

    passed, verdict, failing = fail_on_verdict(run.results, conditions)
    verdict = flag_names(verdict)
    _write_ci_reports(
        ci.junit,
        ci.summary,
        fail_on_cases(run.results, failing, conditions),
        lambda: summary_markdown("credcli diagnose", verdict, run.report),
        inputs,
    )
    print(printable(f"credcli: {verdict}"), file=sys.stderr)
    return passed


def emit_gate_verdict(run, request, conditions, ci, log: str, baseline, inputs) -> bool:
    """The verdict of `gate` (a GateRun), failed also by a label matching --fail-on:
    JUnit and Markdown reports, one line on stderr; whether it passed.

    Parameters
    ----------
    run : GateRun
        The gate's result.
    request : GateRequest
        The gate's request (its thresholds).
    conditions : FailOn or None
        The --fail-on conditions, or None.
    ci : VerdictOptions
        Where the JUnit and Markdown reports go.
    log : str
        The new log, as the reports name it.
    baseline : Path
        The baseline file, named in the Markdown summary.
    inputs : iterable of Path
        The command's input files, which no report may overwrite.

    Returns
    -------
    bool
        Whether the gate passed.
    """
    from credcli.ci.gate import gate_fail_on
    from credcli.ci.reports import gate_cases, summary_markdown

    passed, verdict = run.passed, run.verdict
    if conditions is not None:
        passed, verdict = gate_fail_on(run.comparisons, conditions, passed, verdict)
    verdict = flag_names(verdict)
    thresholds = request.thresholds
    context = f"Baseline `{baseline}`; {thresholds.describe()}."
    _write_ci_reports(
        ci.junit,
        ci.summary,
        gate_cases(run.comparisons, thresholds, log),
        lambda: summary_markdown(f"credcli gate: {log}", verdict, run.report, context),
        inputs,
    )
    print(printable(f"credcli: {verdict}"), file=sys.stderr)
    return passed


def emit_uwb(
    run, fixes, out, plots, report_file, export_log, source: Path, inputs, keep=()
) -> None:
    """What `uwb` shows: warnings about the anchors, the fixes as a diagnose log
    (``export_log``), the report, the figures and an HTML report.

    Parameters
    ----------
    run : Run
        The diagnosed periods.
    fixes : UwbRun
        The pipeline's fixes: their log and the notes about the anchors.
    out : OutputOptions
        ``--format`` and ``--output``.
    plots : Path or None
        ``--plots``.
    report_file : Path or None
        ``--report``.
    export_log : Path or None
        ``--export-log``: the fixes as a diagnose log (CSV).
    source : Path
        The ``uwb.csv``, named in the HTML report.
    inputs : iterable of Path
        The command's input files, which no output may overwrite.
    keep : iterable of Path, optional
        The command's other outputs (:func:`guard_outputs`), which no figure may overwrite
        either.
    """
    from credcli.io.arrays import log_csv
    from credcli.io.files import write_atomic
    from credcli.report.html import build_html

    keep = [*inputs, out.output, export_log, report_file, *keep]
    check_figures(run, plots, keep)
    for warning in fixes.notes:  # anchors that disagree with the log's ground truth
        print(printable(f"credcli: warning: {flag_names(warning)}"), file=sys.stderr)
    if export_log is not None:
        write_atomic(export_log, log_csv(fixes.log), inputs)
        stderr_console().print(
            printable(f"wrote {export_log} ({fixes.log.n} fixes)"), highlight=False, markup=False
        )
    emit(run.report, out.fmt, out.output, inputs=inputs)
    write_plots(run, plots, keep)
    if report_file is not None:
        title = f"credcli uwb: {source.name}"
        html = build_html(title, run.report, run.plots, str(source), results=run.results)
        write_atomic(report_file, html, inputs)
        stderr_console().print(printable(f"wrote {report_file}"), highlight=False, markup=False)
