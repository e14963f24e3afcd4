"""Glue for the commands: file -> EstimatorLog -> segments -> Diagnosis -> Report.

Each function is what one command does, minus option parsing and printing.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Generator
from dataclasses import dataclass, field

import numpy as np

from credcli import segments as seg
from credcli.ci.gate import check_same_dimension, compare, verdict_line
from credcli.engine.curves import segment_curves
from credcli.engine.diagnosis import Label, MetricsLevel, diagnose_segments
from credcli.engine.short import SegmentResults, ShortSegments
from credcli.errors import CredcliError
from credcli.io.ingest import one_segment, open_log
from credcli.io.logs import EstimatorLog, with_unique_ids
from credcli.io.streams import display_name, is_stream
from credcli.report import plots as figs
from credcli.report.builders import (
    curves_report,
    diagnose_report,
    gate_report,
    simulate_report,
    streamed_diagnose_report,
    sweep_report,
    uwb_report,
)
from credcli.report.overview import Source, overview_plots, segments_to_draw
from credcli.report.records import (
    SEGMENTS,
    Snapshot,
    baseline_document,
    diagnose_parameters,
    document_parameters,
    simulate_parameters,
    uwb_parameters,
)
from credcli.report.tables import Report
from credcli.requests import DiagnoseRequest, GateRequest, Kept, SimulateRequest, UwbRequest
from credcli.schedule import plans as scheduling
from credcli.schedule.plans import (
    PARALLEL_MIN_BYTES,
    diagnose_on_cluster,
    diagnose_plans,
    diagnosed_parts,
    file_size,
)
from credcli.schedule.pool import WorkerPool
from credcli.segments import log_summary, monte_carlo_plan, split, split_runs
from credcli.studies import simulate as sim
from credcli.studies import uwb


def segmentation_name(window: str | None, whole: bool) -> str:
    """How the logs were cut, as the report's parameters record it.

    Parameters
    ----------
    window : str or None
        The window (a duration or an epoch count), or None.
    whole : bool
        Each log one segment.

    Returns
    -------
    str
        ``"whole"``, ``"window:<the parsed window>"`` or ``"column"`` (the segment column).
    """
    if whole:
        return "whole"
    return f"window:{seg.Window.parse(window)}" if window is not None else "column"


@dataclass(frozen=True)
class Run:
    """What a command produced: the report, and the plots when they were asked for.

    Attributes
    ----------
    report : Report
        The command's tables and JSON document.
    plots : list of Plot
        The figures (empty unless asked for).
    results : list of SegmentDiagnosis
        The diagnosed segments, in report order, as the request keeps them
        (``DiagnoseRequest.keep``: every result, their verdicts (SegmentVerdict) or
        none); empty for `simulate`.
    notes : tuple of str
        About the figures: the windows whose figures were skipped.
    """

    report: Report
    plots: list = field(default_factory=list)
    results: list = field(default_factory=list)  # SegmentDiagnosis, in report order
    notes: tuple[str, ...] = ()  # about the figures: the windows whose figures were skipped


def run_diagnose(request: DiagnoseRequest, progress=None, runner=None, write=None) -> Run:
    """Load, segment and diagnose every log of ``request``; return the `diagnose` report
    (and the figures, when asked for). Local worker processes share the segments; the
    output is the same for any number. Monte Carlo runs (``request.monte_carlo``) are
    pooled segment by segment (see :func:`monte_carlo_plan`) and the report adds
    Bar-Shalom's per-epoch ANEES test.

    With ``write``, the report is the document alone
    (:func:`credcli.report.builders.streamed_diagnose_report`), handed to ``write`` before
    any segment is diagnosed: the segments are diagnosed as ``write`` writes it, and each
    record is dropped once written, so that the memory does not grow with the number of
    segments.

    Parameters
    ----------
    request : DiagnoseRequest
        The logs and every setting.
    progress : callable, optional
        Called as ``progress(done, total)`` as segments are diagnosed.
    runner : DaskRunner, optional
        A `credcli.schedule.cluster.DaskRunner`: the segments are diagnosed on a Dask cluster whose
        workers read the logs themselves. None: in this process and local workers.
    write : callable, optional
        Called once as ``write(report)`` with the streamed report, to write its JSON or
        CSV (:func:`credcli.report.render.text_pieces`); None: the report is made whole.

    Returns
    -------
    Run
        The report (with ``write``: the streamed one, already written), the figures (when
        ``request.figures``), the results in report order as ``request.keep`` keeps them
        (every result with the figures; otherwise each is dropped once the report has read
        it) and the notes about the figures.

    Raises
    ------
    CredcliError
        If a log cannot be read or diagnosed; with ``runner``, also for Monte Carlo runs
        or a log read from a stream.
    """
    paths, config, seed = request.logs, request.config, request.seed
    reading = request.reading
    schema, options, drop_invalid = reading.schema, reading.options, reading.drop_invalid
    window, whole, monte_carlo = reading.window, reading.whole, request.monte_carlo
    keep = Kept.RESULTS if request.figures else request.keep
    if runner is not None:
        if monte_carlo:
            raise CredcliError("`monte_carlo` runs on this machine: drop `scheduler`")

        streamed = [p for p in [*paths, options.truth] if p is not None and is_stream(p)]
        if streamed:
            raise CredcliError(
                f"{display_name(streamed[0])}: a stream (stdin, pipe or FIFO) cannot be read by "
                "`scheduler`'s workers, which read each log themselves; save it to a file or "
                "drop `scheduler`"
            )
        sources = [
            (str(p), schema, options, drop_invalid, window, whole, config.min_epochs) for p in paths
        ]
        results, logs = diagnose_on_cluster(
            runner, sources, config, seed, options.innovations, progress
        )
        plans = None
        mc = None
    else:
        results, logs, plans, mc = _diagnose_here(request, progress, keep is Kept.RESULTS)
    segmentation = segmentation_name(window, whole)  # valid: the logs were cut with it
    parameters = diagnose_parameters(
        config, seed, reading, segmentation, monte_carlo=mc is not None
    )
    show_all = config.metrics is MetricsLevel.ALL
    verdicts: list = []  # what is kept of each result, when its verdict is
    parts = _keeping_verdicts(results, verdicts) if keep is Kept.VERDICTS else results
    try:
        if write is None:
            report = diagnose_report(parts, config, parameters, logs, show_all, mc)  # reads them
        else:  # the segments are diagnosed as their records are written
            innovations = reading.options.innovations
            report = streamed_diagnose_report(
                parts, config, parameters, logs, show_all, innovations, mc
            )
            write(report)
    finally:  # an error or Ctrl-C while the report reads them: the workers stop now
        for source in (parts, results):
            if isinstance(source, Generator):
                source.close()
    figures, notes = [], []
    plots = request.figures
    if plots and plans is None:  # the cluster read the logs; the figures need them here
        loaded = [seg.checked_log(open_log(p, schema, options, drop_invalid)) for p in paths]
        loaded = with_unique_ids(loaded)
        if monte_carlo:  # a log with a run column holds several runs
            loaded = [run for log in loaded for run in split_runs(log)]
        plans = [(log, split(log, window, whole, config.min_epochs)) for log in loaded]
    if plots and mc is not None:
        group = "Monte Carlo runs: overview"
        figures.append(dataclasses.replace(figs.anees_plot("monte_carlo_anees", mc), group=group))
        source = Source.of([log for log, _ in plans], plans[0][1], results, config.nees_alpha)
        figures.extend(overview_plots(source, "", "Monte Carlo runs"))
    elif plots:
        k = 0
        for log, segments in plans:
            mine = results[k : k + len(segments)]
            k += len(segments)
            several = len(plans) > 1
            prefix = f"{log.id.stem}_" if several else ""
            log_name = log.id.label if several else ""
            source = Source.of([log], segments, mine, config.nees_alpha)
            figures.extend(overview_plots(source, prefix, log_name))
            drawn, note = segments_to_draw(source.segments, source.results)
            if note:
                notes.append(f"{log_name}: {note}" if several else note)
            chosen = [result for _, result in drawn]
            figures.extend(segment_figures(log, chosen, segments, prefix, log_name))
    kept = {Kept.RESULTS: results, Kept.VERDICTS: SegmentResults(tuple(verdicts))}
    return Run(report, figures, kept.get(keep, []), tuple(notes))


def _keeping_verdicts(parts, verdicts: list):
    """``parts`` (results, and runs of short segments) as they come, each one's verdict
    (:meth:`SegmentDiagnosis.verdict`; a run of short segments as it is) added to
    ``verdicts`` on the way."""
    for part in parts:
        verdicts.append(part if isinstance(part, ShortSegments) else part.verdict())
        yield part


def segment_figures(
    log: EstimatorLog, results, segments, prefix: str = "", log_name: str = ""
) -> list:
    """The figures of a log's diagnosed segments, from the curves the engine computes.

    Parameters
    ----------
    log : EstimatorLog
        The log the segments belong to.
    results : list of SegmentDiagnosis
        The segments to draw, in order.
    segments : list of Segment
        The log's segments (looked up by the results' names for their epochs).
    prefix : str, default ""
        Prefix of the figures' file names (a log's stem when there are several).
    log_name : str, default ""
        The log's name in the figures' groups ("" for one log).

    Returns
    -------
    list of Plot
        The figures of every segment in ``results``.
    """
    by_name = {s.name: s for s in segments}
    errors = log.errors  # computed once: a property
    curves, times = [], []
    for result in results:
        index = by_name[result.segment].index
        decided = result.diagnosis.label is not Label.INSUFFICIENT
        c = result.diagnosis.config.c if decided else None
        curves.append(segment_curves(errors[index], log.cov[index], c))
        times.append(None if log.time is None else log.time[index])
    return figs.segment_plots(results, curves, times, log.dim, prefix, log_name)


def _diagnose_here(request: DiagnoseRequest, progress, keep: bool):
    """Read and diagnose the logs in this process and ``request.jobs`` local worker
    processes; returns (results, log entries, plans, Monte Carlo test or None), the
    results held when ``keep``, else an iterator that diagnoses them as it is read
    (:func:`credcli.schedule.plans.diagnosed_parts`)."""
    paths, config, jobs, reading = request.logs, request.config, request.jobs, request.reading
    window, whole, monte_carlo = reading.window, reading.whole, request.monte_carlo
    pool = None
    if jobs > 1 and sum(file_size(p) for p in paths) >= PARALLEL_MIN_BYTES:
        pool = WorkerPool(jobs, warm=scheduling.__name__)  # workers import while the logs are read
        # one log that is surely one segment has nothing to share among workers: no pool,
        # and no compiled kernels loaded on speculation (about 90 MB and 0.4 s of CPU); asked
        # after the pool chose fork or spawn, since the question loads pyarrow
        if len(paths) == 1 and window is None:
            if whole or one_segment(paths[0], reading.schema, reading.options):
                pool.close()  # forked workers start at the first task: none has
                pool = None
    try:
        with scheduling.kernels_loading(pool):
            loaded = [
                seg.checked_log(open_log(p, reading.schema, reading.options, reading.drop_invalid))
                for p in paths
            ]
        loaded = with_unique_ids(loaded)
        if monte_carlo:  # a log with a run column holds several runs
            loaded = [run for log in loaded for run in split_runs(log)]
        plans = [(log, split(log, window, whole, config.min_epochs)) for log in loaded]
        if monte_carlo:
            plans = [(log, seg.without_run(segments)) for log, segments in plans]
    except BaseException:
        if pool is not None:
            pool.stop()
        raise
    logs = {log.id: log_summary(log, segments) for log, segments in plans}
    runs, mc, diagnosed = 1, None, plans
    # a segment that is a whole log takes the accuracy its summary has (not for pooled runs)
    accuracies = {i: summary.accuracy for i, summary in logs.items()}
    if monte_carlo:
        diagnosed, mc = monte_carlo_plan(loaded, plans, config.alpha)
        runs, accuracies = len(loaded), None
    diagnose = diagnose_plans if keep else diagnosed_parts
    innovations = reading.options.innovations
    results = diagnose(
        diagnosed, config, request.seed, jobs, progress, pool, innovations, runs, accuracies
    )
    return results, logs, plans, mc


def run_simulate(request: SimulateRequest, progress=None, runner=None) -> tuple[Run, str]:
    """The `simulate` report (and plots) and a one-line summary.

    One of: the Fig. 1 curves (``request.curves``), a sweep of one parameter
    (``request.sweep``), or the Monte Carlo study of Tables II and III.

    Parameters
    ----------
    request : SimulateRequest
        The study's design and every setting.
    progress : callable, optional
        Called as ``progress(done, total)`` as trials finish.
    runner : DaskRunner, optional
        Trials on a Dask cluster (`credcli.schedule.cluster.DaskRunner`); None: local processes.

    Returns
    -------
    tuple of (Run, str)
        The Run (report and figures) and the summary line.

    Raises
    ------
    CredcliError
        If a scenario or the sweep is invalid.
    """
    config, sweep, curves, curve_runs = (
        request.config,
        request.sweep,
        request.curves,
        request.curve_runs,
    )
    jobs, plots = request.jobs, request.figures
    scenarios = sim.parse_scenarios(request.scenario)
    spec = None if sweep is None or curves else sim.Sweep.parse(sweep)
    # the settings the trials are judged by (slow_errors resolved from ar), unless a sweep
    # varies ar, which resolves it point by point
    shown = config
    if spec is None or spec.parameter is not sim.SweepParameter.AR:
        shown = dataclasses.replace(config, diagnosis=config.judged_by)
    parameters = simulate_parameters(  # the curves, a sweep or the study: one of them
        shown,
        scenarios,
        curve_runs=curve_runs if curves else None,
        sweep=None if curves else sweep,
    )

    figures = []
    if plots or curves:
        rhos = np.round(np.geomspace(0.1, 10.0, 21), 6)
        gammas = np.round(np.linspace(0.0, 3.0, 13), 6)
        by_rho, by_gamma = sim.fig1_curves(rhos, gammas, curve_runs, config.dim, config.seed)
        if plots:
            figures.append(figs.curves_plot(by_rho, by_gamma))
    if curves:
        return Run(curves_report(by_rho, by_gamma, curve_runs, parameters), figures), (
            f"Fig. 1 curves: {len(by_rho)} values of ρ and {len(by_gamma)} of γ, {curve_runs} runs each"
        )
    if spec is not None:
        points = sim.run_sweep(spec, config, scenarios, jobs, progress, runner)
        n_trials = sum(p.trials for p in points)
        if plots:
            figures.append(figs.sweep_plot(spec, points))
        return Run(sweep_report(spec, points, parameters), figures), (
            f"sweep of {spec.parameter.value} over {len(spec.values)} values: {n_trials} trials"
        )
    study = sim.run_study(config, scenarios, jobs, progress, runner)
    if plots:
        figures.insert(0, figs.confusion_plot(study))
    paper_protocol = (
        dataclasses.replace(
            config,
            seed=0,
            diagnosis=dataclasses.replace(config.diagnosis, variant=sim.Variant.CALIBRATED),
        )
        == sim.SimulationConfig()
    )
    chosen = sim.Method(config.diagnosis.variant.value)
    mean = float(np.mean(list(study.accuracy[chosen].values())))
    summary = (
        f"{len(scenarios)} scenario(s) x {config.trials} trials: {chosen.value} variant "
        f"{100 * mean:.1f}% correct on average"
    )
    return Run(simulate_report(study, parameters, paper_protocol), figures), summary


def run_uwb(request: UwbRequest, progress=None):
    """The `uwb` pipeline: positioning, segmentation, diagnosis.

    Parameters
    ----------
    request : UwbRequest
        The ``uwb.csv`` and every setting.
    progress : callable, optional
        Called as ``progress(done, total)`` as periods are diagnosed.

    Returns
    -------
    tuple of (Run, UwbRun)
        The Run (report, figures when ``request.figures``, results, notes) and the
        pipeline's fixes and anchors.

    Raises
    ------
    CredcliError
        If the file cannot be read or no fix falls in any period.
    """
    path, settings, config, anchors = (
        request.file,
        request.settings,
        request.config,
        request.anchors,
    )
    window, whole, seed = request.window, request.whole, request.seed
    run = uwb.run_pipeline(path, settings, anchors, window, whole)
    if not run.segments:
        raise CredcliError(f"{path}: no fix falls in any period; try `window` 5s or `whole`")
    results = diagnose_segments(run.log, run.segments, config, seed, progress)
    segmentation = "static" if not (window or whole) else segmentation_name(window, whole)
    parameters = uwb_parameters(config, seed, segmentation, settings, anchors)
    figures, notes = [], ()
    if request.figures:  # the fixes' overview (timeline, errors, NEES) as diagnose draws it
        source = Source.of([run.log], run.segments, results, config.nees_alpha)
        drawn, note = segments_to_draw(source.segments, source.results)
        chosen = [result for _, result in drawn]
        figures = [
            *figs.uwb_plots(run),
            *overview_plots(source),
            *segment_figures(run.log, chosen, run.segments),
        ]
        notes = (note,) if note else ()
    checks = uwb.range_checks(run, results, config.tau_nci)
    return Run(uwb_report(run, results, checks, parameters), figures, results, notes), run


def run_baseline(request: DiagnoseRequest, progress=None, runner=None, write=None) -> Report:
    """`diagnose` on one log, marked as a baseline of the current schema version.

    Parameters
    ----------
    request : DiagnoseRequest
        The log and every setting.
    progress : callable, optional
        Called as ``progress(done, total)`` as segments are diagnosed.
    runner : DaskRunner, optional
        A Dask cluster to diagnose on (see `run_diagnose`).
    write : callable, optional
        Called once as ``write(report)`` with the baseline's streamed report, written as
        its segments are diagnosed (see `run_diagnose`); None: the report is made whole.

    Returns
    -------
    Report
        The diagnose report, its document marked ``command: baseline`` with the baseline's
        kind and schema version (with ``write``: the streamed one, already written).
    """

    def marked(report: Report) -> Report:
        return dataclasses.replace(report, document=baseline_document(report.document))

    streamed = None if write is None else lambda report: write(marked(report))
    return marked(run_diagnose(request, progress, runner, streamed).report)


@dataclass(frozen=True)
class GateRun:
    """What `gate` produced: the report, the comparison of every segment, the verdict.

    Attributes
    ----------
    report : Report
        The gate's tables and JSON document.
    comparisons : list of SegmentComparison
        Each segment, baseline against new.
    passed : bool
        Whether the gate passed under the thresholds.
    verdict : str
        The one-line verdict.
    plots : list of Plot
        The new log's figures (empty unless asked for).
    """

    report: Report
    comparisons: list
    passed: bool
    verdict: str
    plots: list = field(default_factory=list)


def run_gate(request: GateRequest, progress=None, runner=None) -> GateRun:
    """Diagnose the new log with the baseline's settings and compare segment by segment.

    Each segment's record is made once, as the segment is diagnosed, and kept as what the
    gate compares (a :class:`Snapshot`); the results themselves are not held (unless the
    figures need them), so that a log of many segments holds a record each, as its
    baseline does.

    Parameters
    ----------
    request : GateRequest
        The new log's diagnosis request, the baseline and the thresholds.
    progress : callable, optional
        Called as ``progress(done, total)`` as segments are diagnosed.
    runner : DaskRunner, optional
        A Dask cluster to diagnose on (see `run_diagnose`).

    Returns
    -------
    GateRun
        The report, the comparisons, the verdict and the figures.
    """
    current: list[Snapshot] = []

    def compared(report: Report) -> None:  # what gate compares, kept as each is diagnosed
        current.extend(map(Snapshot.from_record, report.document[SEGMENTS].dicts()))

    run = run_diagnose(request.diagnose, progress, runner, write=compared)
    baseline, thresholds = request.baseline, request.thresholds
    check_same_dimension(baseline, current)
    comparisons = compare(list(baseline.segments), current, thresholds, baseline.config.elt_level)
    passed, verdict = verdict_line(comparisons, thresholds)
    parameters = document_parameters(run.report.document)
    report = gate_report(comparisons, parameters, baseline.source, passed, verdict)
    return GateRun(report, comparisons, passed, verdict, run.plots)
