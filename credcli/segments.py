"""Segmentation stages: a segment column, fixed windows, static periods, or the whole log;
and Monte Carlo runs: split by their run ids, pooled segment by segment."""

from __future__ import annotations

import re
from collections.abc import Iterator, Sequence
from dataclasses import dataclass

import numpy as np

from credcli.engine.metrics import Accuracy, accuracy
from credcli.engine.montecarlo import anees_test
from credcli.errors import CredcliError
from credcli.io.logs import EstimatorLog
from credcli.logid import LogId


@dataclass(frozen=True)
class Segment:
    """A named set of epochs (indices into the log, in time order)."""

    name: str
    index: np.ndarray
    t_start: float | None = None
    t_end: float | None = None
    window: bool = False  # a window of the run: judged against the run's dependence model


MAX_WINDOW = 1e12
"""The longest window accepted (epochs or seconds): past it no log has two windows, and an
epoch count no longer fits the integers segmentation uses."""


@dataclass(frozen=True)
class Window:
    """A window length: seconds (``5s``, ``250ms``) or a number of epochs (``200``)."""

    length: float
    seconds: bool

    @classmethod
    def parse(cls, text: str) -> Window:
        m = re.fullmatch(r"\s*(\d+(?:\.\d*)?|\.\d+)\s*(ms|s|min)?\s*", str(text))
        if not m:
            raise CredcliError(
                f"`window` '{text}' is not a duration like 5s, 250ms, 2min or an epoch count like 200"
            )
        value, unit = float(m.group(1)), m.group(2)
        if value <= 0:
            raise CredcliError(f"`window` must be positive; got '{text}'", "window")
        if not value < MAX_WINDOW:
            raise CredcliError(
                f"`window` '{text}' is longer than any log ({MAX_WINDOW:.0e} epochs or "
                "seconds at most); give a window shorter than the log, or no window",
                "window",
            )
        if unit is None:
            if value != int(value):
                raise CredcliError(
                    f"`window` '{text}': an epoch count must be a whole number", "window"
                )
            return cls(value, False)
        return cls(value * {"ms": 1e-3, "s": 1.0, "min": 60.0}[unit], True)

    def __str__(self) -> str:
        return f"{self.length:g}s" if self.seconds else f"{int(self.length)}"


def _span(time: np.ndarray | None, index: np.ndarray) -> tuple[float | None, float | None]:
    if time is None or index.size == 0:
        return None, None
    return float(time[index].min()), float(time[index].max())


@dataclass(frozen=True, eq=False)
class Segments(Sequence):
    """Segments of one log as columns: item k is segment k's :class:`Segment`, made when it
    is asked for. A log of 10⁶ one-epoch segments is a few arrays and its names, not 10⁶
    Segment objects with an index array each.

    Attributes
    ----------
    names : list of str
        The segments' names.
    rows : numpy.ndarray
        The rows of every segment, one segment after another.
    bounds : numpy.ndarray
        Segment k's rows are ``rows[bounds[k]:bounds[k + 1]]`` (int, one more than the
        segments).
    t_start, t_end : numpy.ndarray or None
        Each segment's first and last time stamps; None for a log without time.
    """

    names: list[str]
    rows: np.ndarray
    bounds: np.ndarray
    t_start: np.ndarray | None
    t_end: np.ndarray | None

    def __len__(self) -> int:
        return len(self.names)

    def __getitem__(self, k):
        if isinstance(k, slice):
            return [self[i] for i in range(*k.indices(len(self)))]
        k = range(len(self))[k]  # an IndexError past the end, as a list's
        index = self.rows[self.bounds[k] : self.bounds[k + 1]]
        if self.t_start is None:
            return Segment(self.names[k], index)
        return Segment(self.names[k], index, float(self.t_start[k]), float(self.t_end[k]))

    def __iter__(self) -> Iterator[Segment]:
        return map(self.__getitem__, range(len(self)))

    @property
    def lengths(self) -> np.ndarray:
        """Each segment's epochs."""
        return np.diff(self.bounds)


def lengths(segments: Sequence[Segment]) -> np.ndarray:
    """Each segment's epochs, without making the items of :class:`Segments`.

    Parameters
    ----------
    segments : sequence of Segment
        A list of segments or :class:`Segments`.

    Returns
    -------
    numpy.ndarray
        The epochs of each (int).
    """
    if isinstance(segments, Segments):
        return segments.lengths
    return np.array([len(s.index) for s in segments], dtype=np.int64)


def window_indices(segments: Sequence[Segment]) -> list[np.ndarray]:
    """The index of each window of a run among ``segments`` (none in :class:`Segments`,
    whose segments come from a column), without making the items of :class:`Segments`.

    Parameters
    ----------
    segments : sequence of Segment
        A list of segments or :class:`Segments`.

    Returns
    -------
    list of numpy.ndarray
        The rows of each segment that is a window (``Segment.window``).
    """
    if isinstance(segments, Segments):
        return []
    return [s.index for s in segments if s.window]


def _names(values: np.ndarray) -> list[str]:
    """``str`` of each value, as ``str(values[k])`` writes it: a list's items where those
    are the same (text, integers, booleans), each numpy scalar otherwise (floats)."""
    if values.dtype.kind in "OUiub":
        return list(map(str, values.tolist()))
    return [str(v) for v in values]


def by_column(values: np.ndarray, time: np.ndarray | None = None) -> Segments:
    """One segment per distinct value, in order of first appearance.

    A log's segments are usually runs of consecutive rows, so the runs of equal values are
    found first and only each run's first value is sorted (a million rows in 1,000 runs:
    about 20 ms, against 0.3-0.4 s for sorting every row's value). The segments are
    columns (:class:`Segments`): a million one-epoch segments take a few numpy calls."""
    n = len(values)
    if n == 0:
        return Segments([], np.zeros(0, dtype=np.int64), np.zeros(1, dtype=np.int64), None, None)
    starts = np.flatnonzero(np.r_[True, values[1:] != values[:-1]])
    stops = np.r_[starts[1:], n]
    _, first_run, run_group = np.unique(values[starts], return_index=True, return_inverse=True)
    if first_run.size == starts.size:  # each value one run: the segments are the runs
        index = np.arange(n)
        bounds = np.r_[starts, n]
        names = _names(values[starts])
    else:
        order = np.argsort(starts[first_run], kind="stable")  # by first appearance
        rank = np.empty_like(order)
        rank[order] = np.arange(order.size)
        segment_of_row = np.repeat(rank[run_group.reshape(-1)], stops - starts)
        index = np.argsort(segment_of_row, kind="stable")
        bounds = np.r_[0, np.cumsum(np.bincount(segment_of_row, minlength=order.size))]
        names = _names(values[starts[first_run[order]]])
    if time is None:
        return Segments(names, index, bounds, None, None)
    span = time[index]
    return Segments(
        names,
        index,
        bounds,
        np.minimum.reduceat(span, bounds[:-1]),
        np.maximum.reduceat(span, bounds[:-1]),
    )


def by_window(n: int, window: Window, time: np.ndarray | None) -> list[Segment]:
    """Consecutive windows of a fixed duration (from the first time) or epoch count.

    Windows are named ``w001``, ``w002``, … in time order; empty duration windows are skipped
    (their numbers are kept so names stay tied to the time span).
    """
    if window.seconds:
        if time is None:
            raise CredcliError(
                f"`window` {window} needs a time column; use an epoch count (e.g. `window` 200) "
                "or name the time column"
            )
        if np.any(np.diff(time) < 0):
            raise CredcliError(
                "the time column is not sorted; sort the log by time to use `window`"
            )
        with np.errstate(over="ignore", invalid="ignore"):
            index = np.floor((time - time[0]) / window.length)
        if not np.isfinite(index[-1]) or index[-1] >= MAX_WINDOW:
            raise CredcliError(
                f"`window` {window} cuts the time column's span ({time[-1] - time[0]:.3g} s) into "
                f"more than {MAX_WINDOW:.0e} windows; check the time column's unit "
                "(`time_unit`) or give a longer window"
            )
        k = index.astype(np.int64)
    else:
        k = np.arange(n) // int(window.length)
    bounds = np.flatnonzero(np.diff(k)) + 1
    starts = np.r_[0, bounds]
    stops = np.r_[bounds, n]
    width = max(3, len(str(int(k[-1]) + 1)))
    return [
        Segment(f"w{int(k[a]) + 1:0{width}d}", np.arange(a, b), *_span(time, np.arange(a, b)), True)
        for a, b in zip(starts, stops)
    ]


def whole(n: int, time: np.ndarray | None) -> list[Segment]:
    """The whole log as one segment, "all"."""
    idx = np.arange(n)
    return [Segment("all", idx, *_span(time, idx))]


_whole_log = whole  # for split(), whose flag of the same name shadows it


SPEED_LAG_S = 0.1
"""Half-width of the centred difference used for speeds (s). Mocap positions at ~220 Hz
with near-coincident rows make one-step differences noisy; ±0.1 s does not."""


def static_periods(
    time: np.ndarray, position: np.ndarray, max_speed: float = 0.1, min_duration: float = 4.0
) -> tuple[list[Segment], np.ndarray]:
    """Static periods of Section V-A: the 3-D speed of ``position`` (N, 3), sorted by
    ``time``, stays below ``max_speed`` for at least ``min_duration`` s.

    The speed is the centred difference over ±SPEED_LAG_S (positions interpolated in time).
    Returns the periods, named P1, P2, … (index: the rows), and the speed of every row.
    """
    t = time
    ahead = np.stack([np.interp(t + SPEED_LAG_S, t, position[:, i]) for i in range(3)], axis=1)
    behind = np.stack([np.interp(t - SPEED_LAG_S, t, position[:, i]) for i in range(3)], axis=1)
    span = np.minimum(t + SPEED_LAG_S, t[-1]) - np.maximum(t - SPEED_LAG_S, t[0])
    speed = np.linalg.norm(ahead - behind, axis=1) / np.maximum(span, 1e-9)
    edges = np.diff(np.r_[0, (speed < max_speed).astype(np.int8), 0])
    starts, stops = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
    out = []
    for a, b in zip(starts, stops):
        if t[b - 1] - t[a] >= min_duration:
            out.append(Segment(f"P{len(out) + 1}", np.arange(a, b), float(t[a]), float(t[b - 1])))
    return out, speed


def without_run(segments: list[Segment]) -> list[Segment]:
    """``segments`` without the whole-run segment that :func:`split` adds after windows
    (Monte Carlo runs are the replicates; their windows are pooled across runs)."""
    return [s for s in segments if s.window or s.name != RUN_SEGMENT]


RUN_SEGMENT = "run"
"""The name of the whole run, diagnosed after its windows (``window``): one dependence model
is fitted on it and every window is judged against that model."""


def split(
    log, window: str | None = None, whole: bool = False, min_epochs: int = 0
) -> list[Segment]:
    """Segments of a log: the whole log, fixed windows, or the segment column (in that
    order of precedence); a log without a segment column is one segment.

    Duration windows none of which holds ``min_epochs`` epochs are an error: that is
    a unit mistake (nanosecond stamps read as seconds) or a window far too short. A log of
    several Monte Carlo runs (a run column) is refused: its runs are pooled, not
    concatenated (:func:`monte_carlo_plan`)."""
    if log.run is not None and len(set(log.run)) > 1:
        raise CredcliError(
            f"{log.id}: holds {len(set(log.run))} Monte Carlo runs (a run column); "
            "diagnose them pooled with `monte_carlo` (credcli.diagnose_monte_carlo in Python)"
        )
    if whole:
        return _whole_log(log.n, log.time)
    if window is not None:
        parsed = Window.parse(window)
        out = by_window(log.n, parsed, log.time)
        largest = max(len(s.index) for s in out)
        if parsed.seconds and largest < min_epochs and log.n >= min_epochs:
            step = float(np.median(np.diff(log.time))) if log.n > 1 else float("nan")
            raise CredcliError(
                f"{log.id}: `window` {parsed} gives {len(out)} windows of at most "
                f"{largest} epoch(s), fewer than `min_epochs` {min_epochs}; the median time "
                f"step is {step:.6g} s: if the stamps are not seconds, give `time_unit` "
                "(ms, us or ns), else use a longer window"
            )
        if not parsed.seconds and largest < min_epochs and log.n >= min_epochs:
            raise CredcliError(
                f"{log.id}: `window` {parsed} was read as {parsed} epochs per window "
                f"(a number without a unit counts epochs), fewer than `min_epochs` "
                f"{min_epochs}; write a duration such as {parsed}s, or at least {min_epochs} "
                "epochs"
            )
        if len(out) > 1:  # the run's own verdict beside its windows
            out.append(Segment(RUN_SEGMENT, np.arange(log.n), *_span(log.time, np.arange(log.n))))
        return out
    if log.segment is not None:
        return by_column(log.segment, log.time)
    return _whole_log(log.n, log.time)


def split_runs(log: EstimatorLog) -> list[EstimatorLog]:
    """The Monte Carlo runs of a log with run ids, in the order they first appear; each
    keeps its epochs in order (time, segments, rows, notes). A log without run ids is one
    run."""
    if log.run is None:
        return [log]
    names, first = np.unique(log.run, return_index=True)
    out = []
    for name in names[np.argsort(first)]:
        index = np.flatnonzero(log.run == name)
        out.append(
            EstimatorLog(
                None if log.truth is None else log.truth[index],
                None if log.estimate is None else log.estimate[index],
                log.cov[index],
                time=None if log.time is None else log.time[index],
                segment=None if log.segment is None else log.segment[index],
                rows=log.rows[index],
                id=log.id.run(name),
                state_errors=None if log.state_errors is None else log.state_errors[index],
                notes=log.notes,
                blocks=log.blocks,
            )
        )
    return out


def pool_runs(runs: list[EstimatorLog], segments) -> tuple[EstimatorLog, list]:
    """M runs on one time base as one log whose segment k holds the epochs of segment k of
    every run, run after run (so that the ELT flips each run in its own blocks), and those
    pooled segments."""
    m, n = len(runs), runs[0].n
    order = np.concatenate([run * n + s.index for s in segments for run in range(m)])
    errors = np.concatenate([log.errors for log in runs])[order]
    cov = np.concatenate([log.cov for log in runs])[order]
    pooled = EstimatorLog(
        None, None, cov, id=LogId.of(f"monte-carlo ({m} runs)"), state_errors=errors
    )
    starts = np.cumsum([0] + [m * len(s.index) for s in segments])
    pooled_segments = [
        Segment(s.name, np.arange(a, b), s.t_start, s.t_end)
        for s, a, b in zip(segments, starts[:-1], starts[1:])
    ]
    return pooled, pooled_segments


def monte_carlo_plan(loaded: list[EstimatorLog], plans, alpha: float):
    """Pool M runs of one scenario: one plan whose segment k holds the epochs of segment k
    of every run, run after run (so that the ELT flips each run in its own blocks), and
    the per-epoch ANEES test (:func:`credcli.engine.montecarlo.anees_test`)."""
    if len(loaded) < 2:
        raise CredcliError("`monte_carlo` needs at least two runs (logs) of the scenario")
    base = loaded[0]
    for log in loaded[1:]:
        same_time = (log.time is None) == (base.time is None) and (
            log.time is None
            or (log.n == base.n and np.allclose(log.time, base.time, rtol=0, atol=1e-6))
        )
        if log.n != base.n or log.dim != base.dim or not same_time:
            raise CredcliError(
                f"{log.id}: `monte_carlo` runs need one time base: {log.n} epochs of "
                f"d = {log.dim} against {base.n} of d = {base.dim} in {base.id}"
                + ("" if log.n != base.n or log.dim != base.dim else ", and different stamps")
            )
    segments = plans[0][1]
    mc = anees_test(
        [log.errors for log in loaded], [log.cov for log in loaded], alpha, base.time, segments
    )
    return [pool_runs(loaded, segments)], mc


@dataclass(frozen=True)
class LogSummary:
    """What a report says of one whole log beside its segments: its id, size, what reading
    it dropped, its notes, and the accuracy over all its epochs (evo's figures for the
    whole trajectory, to compare logs as ``evo_res`` does). Typed until the report writes
    it (:func:`credcli.report.records.log_record`)."""

    id: LogId
    epochs: int
    dim: int
    dropped_rows: int
    unpaired_epochs: int | None
    segments: int
    notes: tuple[str, ...]
    accuracy: Accuracy | None


def log_summary(log: EstimatorLog, segments) -> LogSummary:
    """The :class:`LogSummary` of ``log`` cut into ``segments``."""
    return LogSummary(
        log.id,
        log.n,
        log.dim,
        log.dropped_rows,
        log.unpaired,
        len(segments),
        tuple(log.notes),
        accuracy(log.errors) if log.n else None,
    )
