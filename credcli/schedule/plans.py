"""Where the segments are diagnosed: in this process, in local worker processes
(``--jobs``), or on a Dask cluster whose workers read the logs (``--scheduler``). Every
path gives the same results in the same order: each segment's sign flips depend on (seed,
segment name) only."""

from __future__ import annotations

import contextlib
import functools
import itertools
from collections.abc import Iterator
from dataclasses import replace
from pathlib import Path

import numpy as np

from credcli import segments as seg
from credcli.engine import compiled, flips
from credcli.engine.diagnosis import (
    DiagnosisConfig,
    SegmentDiagnosis,
    diagnose_segment,
    innovation_config,
    innovation_whiteness,
    run_model,
)
from credcli.engine.linalg import EPOCH_CHUNK, as_slice
from credcli.engine.metrics import Accuracy
from credcli.engine.short import SegmentResults, ShortSegments, short_segments
from credcli.engine.timing import motion
from credcli.errors import CredcliError
from credcli.io.ingest import open_log
from credcli.logid import LogId, unique_ids
from credcli.schedule.pool import allocator_for, ordered_map, prepare_worker
from credcli.segments import LogSummary, checked_log, log_summary, split

PARALLEL_MIN_EPOCHS = 50_000
"""Below this many epochs in all, segments are diagnosed in this process: starting worker
processes would cost more than it saves (a spawned worker imports numpy and scipy again; a
forked one, see parallel.start_method, starts at once but still costs its set-up and the
transfer of the segments)."""


TASKS_PER_JOB = 32
"""Tasks per worker process: a task holds about total epochs / (TASKS_PER_JOB · jobs)."""

PARALLEL_MIN_BYTES = 2_000_000
"""Logs this large (in all) start the worker processes before they are read."""


def file_size(path) -> int:
    """The size of a file in bytes, to decide whether to start worker processes early.

    Parameters
    ----------
    path : str or Path
        A log's path.

    Returns
    -------
    int
        Its size; 0 where ``stat`` fails (``-`` for standard input, a missing file: the
        reader then says why).
    """
    try:
        return Path(path).stat().st_size
    except OSError:
        return 0


def _diagnose_chunk(task) -> list[SegmentDiagnosis]:
    """Worker: diagnose a chunk of segments of the log ``log_id`` (top level, so processes
    can import it)."""
    log_id, items, config, seed, innovations, runs, blocks = task
    longest = max((errors.shape[0] for _, _, _, errors, *_ in items), default=0)  # (an item: _item)
    allocator_for(longest > EPOCH_CHUNK)
    white_null, level = innovation_config(config) if innovations else (config, None)
    out = []
    for name, t0, t1, e, c, memory, findings, declined, moving, fitted, known in items:
        white = innovation_whiteness(e, c, level) if innovations else None
        # innovations are tested under their white null unless the whiteness test rejects;
        # correlated innovations are then a finding, and the two questions are answered
        # with their memory, at the same share of α
        chosen = (
            white_null
            if white is None or not white.rejected
            else replace(config, alpha=white_null.alpha)
        )
        diag = diagnose_segment(
            e,
            c,
            chosen,
            seed,
            name,
            log_id,
            runs,
            blocks,
            memory,
            findings,
            declined,
            moving,
            fitted,
            known,
        )
        out.append(SegmentDiagnosis(log_id, name, t0, t1, diag, white, innovations))
    return out


def _item(
    segment: seg.Segment,
    log,
    run=None,
    moving=None,
    errors: np.ndarray | None = None,
    accuracy: Accuracy | None = None,
) -> tuple:
    """A segment of ``log`` as a task item: (name, t_start, t_end, errors, covariances, the
    run's dependence model for a window, the run's findings for the run's own segment, why a
    window gets no verdict of its own, its truth's motion (its velocities where its epochs
    are not one stretch of the log) or None, why its mean is no
    evidence or None, its accuracy where it is the whole log's, in order, or None), the
    arrays as views when the segment is contiguous. ``errors``: the log's, when already
    taken; ``accuracy``: the whole log's, when already made (for its summary)."""
    errors = log.errors if errors is None else errors
    cov = log.cov
    whole = segment.index.size == log.n
    fitted = log.fitted_mean if whole else None
    index = as_slice(segment.index)
    # the log's summary has the accuracy of these very errors (the same rows, in order)
    known = accuracy if isinstance(index, slice) and index == slice(0, log.n) else None
    window = run is not None and segment.window
    memory = run.memory if window else None
    declined = run.window_reason if window else None
    findings = run.findings if run is not None and not segment.window else ()  # the run's
    item = (segment.name, segment.t_start, segment.t_end, errors[index], cov[index])
    moving = None if moving is None else moving.part(index)
    return (*item, memory, findings, declined, moving, fitted, known)


def _run_model(log, segments, config: DiagnosisConfig):
    """What a run tells its windows (:func:`credcli.engine.diagnosis.run_model`) when the
    segments are windows of one run; None otherwise."""
    windows = seg.window_indices(segments)
    if not windows:
        return None
    return run_model(log.errors, log.cov, windows, config)


def _short_segments(log, segments, config: DiagnosisConfig) -> ShortSegments | None:
    """The segments of ``log`` too short for a verdict, diagnosed together in this process
    (:func:`credcli.engine.short.short_segments`): no task, no transfer, a few numpy calls
    for a million one-epoch segments. None when there are none, or when their covariances
    fail the check: each is then diagnosed alone, so that the error names its segment."""
    sizes = seg.lengths(segments)
    is_short = sizes < config.min_n(log.dim)
    short = np.flatnonzero(is_short)
    if short.size == 0:
        return None
    if isinstance(segments, seg.Segments):
        every = short.size == len(segments)
        index = segments.rows if every else segments.rows[np.repeat(is_short, sizes)]
        names = segments.names if every else [segments.names[i] for i in short.tolist()]
        t_start = None if segments.t_start is None else segments.t_start[short]
        t_end = None if segments.t_end is None else segments.t_end[short]
    else:
        chosen = [segments[i] for i in short.tolist()]
        if len({s.t_start is None for s in chosen}) > 1:  # an empty one among timed ones
            return None
        index = np.concatenate([np.asarray(s.index) for s in chosen])
        names = [s.name for s in chosen]
        timed = chosen[0].t_start is not None
        t_start = np.array([s.t_start for s in chosen], dtype=float) if timed else None
        t_end = np.array([s.t_end for s in chosen], dtype=float) if timed else None
    try:
        return short_segments(
            log.id, names, t_start, t_end, log.errors[index], log.cov[index], sizes[short], config
        )
    except CredcliError:
        return None


def _long_indices(segments, config: DiagnosisConfig, short: ShortSegments | None, dim: int):
    """The indices of the segments not in ``short`` (all of them when it is None)."""
    if short is None:
        return range(len(segments))
    return np.flatnonzero(seg.lengths(segments) >= config.min_n(dim)).tolist()


def _chunk_tasks(
    plans,
    config: DiagnosisConfig,
    seed: int,
    target: int,
    innovations=False,
    runs=1,
    shorts=None,
    accuracies=None,
):
    """Tasks of consecutive segments of one log, each closing once it holds ``target``
    epochs (one segment per task for target 0); made as they are consumed. ``shorts``: the
    segments of each plan diagnosed already (:func:`_short_segments`), by plan, left out;
    ``accuracies``: the logs' accuracies made already, by log id."""
    items, size, log_id, blocks = [], 0, None, ()
    shorts = shorts or {}
    accuracies = accuracies or {}
    for p, (log, segments) in enumerate(plans):
        todo = _long_indices(segments, config, shorts.get(p), log.dim)
        if not todo:
            continue
        errors = log.errors
        model = None if innovations else _run_model(log, segments, config)
        moving = None if innovations else motion(log.truth, log.time)
        for i in todo:
            segment = segments[i]
            if items and (size >= target or log_id != log.id):
                yield (log_id, items, config, seed, innovations, runs, blocks)
                items, size = [], 0
            log_id, blocks = log.id, log.blocks
            items.append(_item(segment, log, model, moving, errors, accuracies.get(log.id)))
            size += len(segment.index)
    if items:
        yield (log_id, items, config, seed, innovations, runs, blocks)


@contextlib.contextmanager
def kernels_loading(pool):
    """Load the compiled kernels in a thread of this process while the body runs (reading
    the logs), where ``pool``'s workers will be forked from it: numba's start-up (about
    0.4 s) then overlaps the read instead of coming after it, before the fork
    (:func:`_warm_kernels`, which finds them loaded). The thread is joined when the body
    ends, also on an error. Speculative: a log whose ELTs would not repay the kernels
    (:func:`credcli.engine.flips.kernel_repaid`) has them loaded anyway, which changes no
    result (they give the numpy path's bits).

    Parameters
    ----------
    pool : WorkerPool or None
        The workers started before the logs are read; nothing is loaded without forked
        ones.

    Yields
    ------
    None
    """
    thread = compiled.warm_in_background() if pool is not None and pool.forked else None
    try:
        yield
    finally:
        if thread is not None:
            thread.join()


def _warm_kernels(plans, config: DiagnosisConfig, jobs: int) -> None:
    """Load the compiled kernels here, before the ``jobs`` workers fork, where each worker
    would load them anyway (:func:`credcli.engine.flips.kernel_repaid` of its share of
    the ELTs' pairs): then this process pays numba's start-up once instead of every worker
    paying it (:func:`credcli.engine.compiled.warm`). The kernels give the numpy path's
    bits, so the results do not change."""
    pairs = 0
    for _, segments in plans:
        sizes = np.minimum(seg.lengths(segments), config.max_elt_epochs).astype(np.int64)
        pairs += int((sizes * (sizes - 1) // 2).sum())
    if flips.kernel_repaid(pairs // max(jobs, 1)):
        compiled.warm()


def _in_order(plans, shorts: dict, diagnosed: Iterator, config: DiagnosisConfig) -> Iterator:
    """Every plan's results in its segments' order, as ``diagnosed`` yields them: each run
    of consecutive short segments one part (a slice of the plan's :class:`ShortSegments`),
    the others from ``diagnosed``."""
    for p, (log, segments) in enumerate(plans):
        short = shorts.get(p)
        if short is None:
            yield from itertools.islice(diagnosed, len(segments))
            continue
        flags = (seg.lengths(segments) < config.min_n(log.dim)).astype(np.int8)
        edges = np.flatnonzero(np.diff(np.r_[0, flags, 0])).tolist()
        done, at = 0, 0  # short segments taken; segments placed
        for start, stop in zip(edges[::2], edges[1::2]):
            yield from itertools.islice(diagnosed, start - at)
            yield short if stop - start == len(short) else short.take(done, done + stop - start)
            done, at = done + stop - start, stop
        yield from itertools.islice(diagnosed, len(segments) - at)


def _arrived(outputs, done: int, total: int, progress) -> Iterator[SegmentDiagnosis]:
    """The results of each task of ``outputs`` as it arrives, ``progress(done, total)``
    called with each task (``done``: the segments diagnosed before the first)."""
    for out in outputs:
        done += len(out)
        if progress is not None:
            progress(done, total)
        yield from out


def diagnose_plans(
    plans,
    config: DiagnosisConfig,
    seed: int,
    jobs: int = 1,
    progress=None,
    pool=None,
    innovations: bool = False,
    runs: int = 1,
    accuracies=None,
) -> SegmentResults:
    """Every segment of every (log, segments) plan, in order (:func:`diagnosed_parts`,
    held).

    Parameters
    ----------
    plans, config, seed, jobs, progress, pool, innovations, runs, accuracies
        As :func:`diagnosed_parts` takes them.

    Returns
    -------
    SegmentResults
        The results, in the plans' order (:class:`credcli.engine.short.SegmentResults`).
    """
    return SegmentResults(
        tuple(
            diagnosed_parts(
                plans, config, seed, jobs, progress, pool, innovations, runs, accuracies
            )
        )
    )


def diagnosed_parts(
    plans,
    config: DiagnosisConfig,
    seed: int,
    jobs: int = 1,
    progress=None,
    pool=None,
    innovations: bool = False,
    runs: int = 1,
    accuracies=None,
) -> Iterator:
    """Every segment of every (log, segments) plan, in order, each yielded as soon as it
    and those before it are diagnosed: a reader that drops each result holds none. From
    PARALLEL_MIN_EPOCHS on, ``jobs`` processes (``pool`` if given) share the work in
    chunks of about equal epochs; otherwise segments are diagnosed one by one in this
    process. Each segment's sign flips depend on (seed, segment name) only, so the results
    are the same for any ``jobs``.

    Segments too short for a verdict are diagnosed together here (not for innovations),
    and each run of them is one part of the results. The work starts at the first item
    asked for; closing the iterator stops the workers.

    Parameters
    ----------
    plans : list of (EstimatorLog, list of Segment)
        Each log with its segments.
    config : DiagnosisConfig
        The rule's settings.
    seed : int
        The seed of the sign flips.
    jobs : int, default 1
        Worker processes.
    progress : callable, optional
        Called as ``progress(done, total)`` in segments.
    pool : WorkerPool, optional
        Workers started already (while the logs were read); closed here when the work
        stays in this process.
    innovations : bool, default False
        The logs hold innovations: each segment's whiteness is tested, and its errors are
        tested under the white null unless that test rejects.
    runs : int, default 1
        The number of pooled Monte Carlo runs each segment holds.
    accuracies : Mapping of LogId to Accuracy, optional
        The accuracy of each log's errors where it is made already (for the log's
        summary): a segment that is the whole log, its rows in order, takes it instead of
        computing it again.

    Yields
    ------
    SegmentDiagnosis or ShortSegments
        Each segment's result, a run of consecutive segments too short for a verdict as
        one :class:`~credcli.engine.short.ShortSegments`, in the plans' order.
    """
    total_segments = sum(len(s) for _, s in plans)
    total_epochs = sum(log.n for log, _ in plans)
    accuracies = accuracies if runs == 1 else None  # a pooled log is not its runs' log
    parallel = jobs > 1 and total_epochs >= PARALLEL_MIN_EPOCHS and total_segments > 1
    if pool is not None and not parallel:
        pool.close()
        pool = None
    target = max(1, total_epochs // (TASKS_PER_JOB * jobs)) if parallel else 0
    shorts = {}  # segments too short for a verdict: diagnosed here, together
    if not innovations:
        for p, (log, segments) in enumerate(plans):
            short = _short_segments(log, segments, config)
            if short is not None:
                shorts[p] = short
    done = sum(len(short) for short in shorts.values())
    tasks = _chunk_tasks(plans, config, seed, target, innovations, runs, shorts, accuracies)
    warm = functools.partial(_warm_kernels, plans, config, jobs)
    if pool is not None:
        outputs = pool.map(_diagnose_chunk, list(tasks), warm)
    else:
        outputs = ordered_map(_diagnose_chunk, tasks, jobs if parallel else 1, warm)
    try:
        arrived = _arrived(outputs, done, total_segments, progress)
        yield from _in_order(plans, shorts, arrived, config)
    finally:
        outputs.close()


# --- on a Dask cluster: the workers read the logs ----------------------------------------

CLUSTER_TASK_EPOCHS = 5_000
"""Epochs of consecutive segments per cluster task: enough diagnosis per task that Dask's
per-task cost stays small beside it (docs/performance.md, docs/scale.md)."""

_WORKER_LOGS: dict = {}
_WORKER_LOGS_KEPT = 2


def _worker_log(source):
    """(log, segments, errors) of ``source`` in this worker, read once for the tasks that share it
    (the last few are kept, keyed by the file's size and modification time too)."""
    prepare_worker()
    path, schema, reading, drop_invalid, window, whole, min_epochs = source
    try:
        stat = Path(path).stat()
        key = (source, stat.st_size, stat.st_mtime_ns)
    except OSError:
        key = (source, None, None)
    if key not in _WORKER_LOGS:
        log = checked_log(open_log(path, schema, reading, drop_invalid))
        while len(_WORKER_LOGS) >= _WORKER_LOGS_KEPT:
            _WORKER_LOGS.pop(next(iter(_WORKER_LOGS)))
        _WORKER_LOGS[key] = (log, split(log, window, whole, min_epochs), log.errors, {})
    return _WORKER_LOGS[key]


def _plan_task(source) -> tuple[LogId, LogSummary, list[int]]:
    """Worker: the id of a log, its summary and the epochs of each of its segments."""
    log, segments, _, _ = _worker_log(source)
    return log.id, log_summary(log, segments), [len(s.index) for s in segments]


def _segments_task(task) -> list[SegmentDiagnosis]:
    """Worker: diagnose segments [first, stop) of a log, their results tied to ``log_id``
    (the id the client made unique among the command's logs)."""
    source, log_id, first, stop, config, seed, innovations = task
    log, segments, errors, models = _worker_log(source)
    if config not in models:  # the run's model, once per worker and configuration
        models[config] = None if innovations else _run_model(log, segments, config)
    model = models[config]
    if "motion" not in models:  # the truth's, once per worker
        models["motion"] = motion(log.truth, log.time)
    moving = None if innovations else models["motion"]
    items = [_item(segment, log, model, moving, errors) for segment in segments[first:stop]]
    return _diagnose_chunk((log_id, items, config, seed, innovations, 1, log.blocks))


def diagnose_on_cluster(runner, sources, config, seed, innovations, progress=None):
    """Every segment of every log, diagnosed by the cluster's workers: one task per log
    to plan its segments, then one task per run of consecutive segments of about
    CLUSTER_TASK_EPOCHS epochs. The logs' ids are made unique here as
    :func:`credcli.io.logs.with_unique_ids` makes them for logs read in this process.

    Parameters
    ----------
    runner : DaskRunner
        The cluster (`credcli.schedule.cluster.DaskRunner`).
    sources : list of tuple
        One per log: (path, schema, reading options, drop_invalid, window, whole,
        min_epochs), what a worker needs to read and cut it.
    config : DiagnosisConfig
        The rule's settings.
    seed : int
        The seed of the sign flips.
    innovations : bool
        The logs hold innovations (see `diagnose_plans`).
    progress : callable, optional
        Called as ``progress(done, total)`` in segments.

    Returns
    -------
    tuple of (list of SegmentDiagnosis, dict)
        The results in log and segment order, and each log's entry (LogSummary) by its
        id.
    """
    planned = runner.map(_plan_task, sources)
    ids = unique_ids([log_id for log_id, _, _ in planned])
    tasks = []
    for source, log_id, (_, _, sizes) in zip(sources, ids, planned, strict=True):
        first, held = 0, 0
        for k, size in enumerate(sizes):
            held += size
            if held >= CLUSTER_TASK_EPOCHS or k == len(sizes) - 1:
                tasks.append((source, log_id, first, k + 1, config, seed, innovations))
                first, held = k + 1, 0
    counts = [task[3] - task[2] for task in tasks]  # segments per task
    outputs = runner.map(_segments_task, tasks, progress, counts)
    entries = {
        log_id: replace(summary, id=log_id)
        for log_id, (_, summary, _) in zip(ids, planned, strict=True)
    }
    return [r for out in outputs for r in out], entries
