"""Segmentation stages: a segment column, fixed windows, static periods, or the whole log;
and Monte Carlo runs: split by their run ids, pooled segment by segment."""

from __future__ import annotations

import re
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, replace

import numpy as np

from credcli.engine.convention import convention_warning
from credcli.engine.linalg import index_range
from credcli.engine.metrics import Accuracy, accuracy
from credcli.engine.montecarlo import anees_test
from credcli.engine.short import ColumnRows
from credcli.errors import CredcliError
from credcli.io.logs import EstimatorLog
from credcli.logid import LogId


@dataclass(frozen=True)
class Segment:
    """A named set of epochs (indices into the log, in time order).

    Attributes
    ----------
    name : str
        The segment's name: a value of the segment column, ``w001``, ``w002``, … for
        windows, ``run`` for the whole run beside its windows (``RUN_SEGMENT``), ``all``
        for the whole log, ``P1``, ``P2``, … for static periods.
    index : numpy.ndarray of int, shape (n,)
        Its epochs' indices into the log, increasing.
    t_start, t_end : float or None
        The first and last time stamps of its epochs; None for a log without time.
    window : bool
        True for a window of a run (``window``): it is judged against the run's
        dependence model, fitted on the whole run, rather than a model of its own.
    """

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
    """A window length: seconds (``5s``, ``250ms``) or a number of epochs (``200``).

    Attributes
    ----------
    length : float
        The length: seconds when ``seconds``, else a whole number of epochs.
    seconds : bool
        Whether ``length`` is a duration in seconds (else an epoch count).

    Examples
    --------
    >>> Window.parse("2min"), str(Window.parse("200"))
    (Window(length=120.0, seconds=True), '200')
    """

    length: float
    seconds: bool

    @classmethod
    def parse(cls, text: str) -> Window:
        """The window that ``text`` gives: a duration or an epoch count.

        Parameters
        ----------
        text : str
            A positive number followed by ``ms``, ``s`` or ``min`` (a duration), or a
            whole number without a unit (an epoch count); blanks around it are allowed.

        Returns
        -------
        Window
            The duration in seconds, or the epoch count.

        Raises
        ------
        CredcliError
            If ``text`` is not of that form, is not positive, is ``MAX_WINDOW`` or more,
            or is an epoch count that is not a whole number.
        """
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
class Segments(ColumnRows):
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

    def row(self, k: int) -> Segment:
        """The k-th segment.

        Parameters
        ----------
        k : int
            Its index.

        Returns
        -------
        Segment
            Its name, epoch indices and time span.
        """
        index = self.rows[self.bounds[k] : self.bounds[k + 1]]
        if self.t_start is None:
            return Segment(self.names[k], index)
        return Segment(self.names[k], index, float(self.t_start[k]), float(self.t_end[k]))

    def __iter__(self) -> Iterator[Segment]:
        return map(self.row, range(len(self)))

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
    found first and only each run's first value is sorted, not every row's value: O(N +
    R log R) for R runs. The segments are columns (:class:`Segments`): a million one-epoch
    segments take a few numpy calls.

    Parameters
    ----------
    values : numpy.ndarray, shape (N,)
        Each epoch's segment value (a log's segment column).
    time : numpy.ndarray, shape (N,), optional
        The epochs' time stamps, for each segment's ``t_start`` and ``t_end``.

    Returns
    -------
    Segments
        One segment per distinct value, named ``str(value)``, its index the rows that hold
        the value; in the order the values first appear.

    Examples
    --------
    >>> [(s.name, s.index.tolist()) for s in by_column(np.array(["b", "b", "a", "b"]))]
    [('b', [0, 1, 3]), ('a', [2])]
    """
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

    Windows are named ``w001``, ``w002``, … in time order (at least three digits); empty
    duration windows are skipped (their numbers are kept so names stay tied to the time
    span). The last window may be shorter than the others.

    Parameters
    ----------
    n : int
        The number of epochs N of the log.
    window : Window
        The windows' length, in seconds or epochs.
    time : numpy.ndarray, shape (N,), or None
        The time stamps in seconds, sorted; a duration window needs them.

    Returns
    -------
    list of Segment
        The windows in time order, each with ``window`` True.

    Raises
    ------
    CredcliError
        For a duration window: if ``time`` is None or not sorted, or if the window would
        cut the time span into ``MAX_WINDOW`` windows or more.

    Examples
    --------
    >>> [(s.name, s.index.tolist()) for s in by_window(5, Window.parse("2"), None)]
    [('w001', [0, 1]), ('w002', [2, 3]), ('w003', [4])]
    >>> [s.name for s in by_window(3, Window.parse("1s"), np.array([0.0, 0.5, 2.5]))]
    ['w001', 'w003']
    """
    if window.seconds:
        if time is None:
            raise CredcliError(
                f"`window` {window} needs a time column; use an epoch count (e.g. `window` 200) "
                "or name the time column"
            )
        back = np.flatnonzero(np.diff(time) < 0)
        if back.size:
            raise CredcliError(
                f"the time column is not sorted (it goes back at row {int(back[0]) + 2}); "
                "sort the log by time to use `window`"
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
        Segment(
            f"w{int(k[a]) + 1:0{width}d}", index_range(a, b), *_span(time, index_range(a, b)), True
        )
        for a, b in zip(starts, stops)
    ]


def whole(n: int, time: np.ndarray | None) -> list[Segment]:
    """The whole log as one segment, "all".

    Parameters
    ----------
    n : int
        The number of epochs N of the log.
    time : numpy.ndarray, shape (N,), or None
        The time stamps, for the segment's span.

    Returns
    -------
    list of Segment
        One segment, ``all``, holding epochs 0 … N − 1.
    """
    idx = index_range(0, n)
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

    The speed is the centred difference over ±h, h = ``SPEED_LAG_S`` (positions
    interpolated in time; the span is shortened at the ends of the log):

        v_k = ‖p(t_k + h) − p(t_k − h)‖ / (min(t_k + h, t_N) − max(t_k − h, t_1)).

    A period is a run of consecutive rows with v_k < ``max_speed`` whose first and last
    stamps are at least ``min_duration`` apart.

    Parameters
    ----------
    time : numpy.ndarray, shape (N,)
        The stamps in seconds, sorted.
    position : numpy.ndarray, shape (N, 3)
        The positions (m), e.g. the ground-truth tag positions of a STAR-loc log.
    max_speed : float
        The speed (m/s) below which the tag is static; 0.1 as in the paper.
    min_duration : float
        The shortest static period (s); 4 as in the paper.

    Returns
    -------
    periods : list of Segment
        The static periods in time order, named ``P1``, ``P2``, … (index: their rows).
    speed : numpy.ndarray, shape (N,)
        The speed v_k of every row (m/s).

    References
    ----------
    The paper, Section V-A: static periods are those "where the tag's three-dimensional
    velocity remains below 0.1 m/s for a minimum duration of 4 seconds".
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
            out.append(Segment(f"P{len(out) + 1}", index_range(a, b), float(t[a]), float(t[b - 1])))
    return out, speed


def without_run(segments: list[Segment]) -> list[Segment]:
    """``segments`` without the whole-run segment that :func:`split` adds after windows
    (Monte Carlo runs are the replicates; their windows are pooled across runs).

    Parameters
    ----------
    segments : list of Segment
        The segments of one log, as :func:`split` gives them.

    Returns
    -------
    list of Segment
        The same segments, in order, without the one named ``RUN_SEGMENT`` that is not a
        window.
    """
    return [s for s in segments if s.window or s.name != RUN_SEGMENT]


RUN_SEGMENT = "run"
"""The name of the whole run, diagnosed after its windows (``window``): one dependence model
is fitted on it and every window is judged against that model."""


def split(
    log, window: str | None = None, whole: bool = False, min_epochs: int = 0
) -> list[Segment]:
    """Segments of a log: the whole log, fixed windows, or the segment column (in that
    order of precedence); a log without a segment column is one segment.

    A log cut into more than one window also gets the whole run as its last segment
    (``RUN_SEGMENT``), on which one dependence model is fitted for its windows. Windows
    none of which holds ``min_epochs`` epochs are an error (when the log itself has that
    many): for duration windows that is a unit mistake (nanosecond stamps read as seconds)
    or a window far too short; for a number without a unit, an epoch count meant as a
    duration. A log of several Monte Carlo runs (a run column) is refused: its runs are
    pooled, not concatenated (:func:`monte_carlo_plan`).

    Parameters
    ----------
    log : EstimatorLog
        The log to cut.
    window : str or None
        The windows' length, as :meth:`Window.parse` reads it (``5s``, ``250ms``,
        ``200``); None for no windows.
    whole : bool
        Each log one segment, ``all``, whatever its segment column (wins over
        ``window``).
    min_epochs : int
        The fewest epochs a segment is diagnosed with; 0 (the default) checks nothing.

    Returns
    -------
    list of Segment
        The log's segments.

    Raises
    ------
    CredcliError
        If the log holds several Monte Carlo runs, if ``window`` cannot be read or cut
        (:meth:`Window.parse`, :func:`by_window`), or if no window holds ``min_epochs``
        epochs.
    """
    if log.run is not None and len(set(log.run)) > 1:
        raise CredcliError(
            f"{log.id}: holds {len(set(log.run))} Monte Carlo runs (a run column); "
            "diagnose them pooled with `monte_carlo` (credcli.diagnose_monte_carlo in Python)"
        )
    if whole:
        return _whole_log(log.n, log.time)
    if window is not None:
        parsed = Window.parse(window)
        try:
            out = by_window(log.n, parsed, log.time)
        except CredcliError as exc:  # which log, where several are read
            raise CredcliError(f"{log.id}: {exc.message}", exc.parameter) from None
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
            out.append(
                Segment(RUN_SEGMENT, index_range(0, log.n), *_span(log.time, index_range(0, log.n)))
            )
        return out
    if log.segment is not None:
        return by_column(log.segment, log.time)
    return _whole_log(log.n, log.time)


def split_runs(log: EstimatorLog) -> list[EstimatorLog]:
    """The Monte Carlo runs of a log with run ids, in the order they first appear; each
    keeps its epochs in order (time, segments, rows, notes). A log without run ids is one
    run.

    Parameters
    ----------
    log : EstimatorLog
        A log whose ``run`` ids may name several runs.

    Returns
    -------
    list of EstimatorLog
        One log per run id, identified by ``log.id.run(id)`` (:meth:`LogId.run`); ``[log]``
        itself for a log without run ids. Each keeps the log's notes, blocks, fitted-mean
        reason and its own epochs of the other convention's errors; the file's counts of
        dropped and unpaired rows go with the first run, so that the runs add up to them.
    """
    if log.run is None:
        return [log]
    names, first = np.unique(log.run, return_index=True)
    out = []
    other = log.other_convention
    for k, name in enumerate(names[np.argsort(first)]):
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
                # the file's counts, not any run's: kept once, so that the runs add up
                dropped_rows=log.dropped_rows if k == 0 else 0,
                state_errors=None if log.state_errors is None else log.state_errors[index],
                notes=log.notes if k == 0 else (),  # the file's, said once
                unpaired=log.unpaired if k == 0 else 0,
                blocks=log.blocks,
                fitted_mean=log.fitted_mean,
                other_convention=None
                if other is None
                else replace(other, errors=other.errors[index]),
            )
        )
    return out


def pool_runs(runs: list[EstimatorLog], segments) -> tuple[EstimatorLog, list]:
    """M runs on one time base as one log whose segment k holds the epochs of segment k of
    every run, run after run (so that the ELT flips each run in its own blocks), and those
    pooled segments.

    Parameters
    ----------
    runs : list of EstimatorLog
        The M runs, each of the same N epochs and dimension (:func:`monte_carlo_plan`
        checks).
    segments : list of Segment
        The segments of one run; their indices hold for every run.

    Returns
    -------
    pooled : EstimatorLog
        A log of errors (``state_errors``) and covariances alone, named
        ``monte-carlo (M runs)``: segment by segment, run after run.
    pooled_segments : list of Segment
        Segment k's M × n_k epochs in ``pooled``, with its name and time span (not
        windows).
    """
    m, n = len(runs), runs[0].n
    order = np.concatenate([run * n + s.index for s in segments for run in range(m)])
    errors = np.concatenate([log.errors for log in runs])[order]
    cov = np.concatenate([log.cov for log in runs])[order]
    pooled = EstimatorLog(
        None, None, cov, id=LogId.of(f"monte-carlo ({m} runs)"), state_errors=errors
    )
    starts = np.cumsum([0] + [m * len(s.index) for s in segments])
    pooled_segments = [
        Segment(s.name, index_range(a, b), s.t_start, s.t_end)
        for s, a, b in zip(segments, starts[:-1], starts[1:])
    ]
    return pooled, pooled_segments


def monte_carlo_plan(loaded: list[EstimatorLog], plans, alpha: float):
    """Pool M runs of one scenario: one plan whose segment k holds the epochs of segment k
    of every run, run after run (so that the ELT flips each run in its own blocks), and
    the per-epoch ANEES test (:func:`credcli.engine.montecarlo.anees_test`).

    Parameters
    ----------
    loaded : list of EstimatorLog
        The M ≥ 2 runs, on one time base: the same number of epochs and dimension, and
        stamps within 1e-6 s of the first run's (or no stamps in any).
    plans : list of (EstimatorLog, list of Segment)
        The runs' plans (a log and its segments); the first plan's segments are used for
        every run.
    alpha : float
        The level of the ANEES test's two-sided bounds.

    Returns
    -------
    plans : list of (EstimatorLog, list of Segment)
        One plan: the pooled log and its pooled segments (:func:`pool_runs`).
    anees : MonteCarlo
        The ANEES test of the runs, with the fraction of each segment's epochs inside
        the bounds.

    Raises
    ------
    CredcliError
        If there are fewer than two runs, or a run's number of epochs, dimension or
        stamps differ from the first run's.

    Notes
    -----
    With ε_{j,k} the NEES (eq. (1)) of run j at epoch k, ANEES_k = (1/M) Σ_j ε_{j,k} is
    inside its bounds when χ²_{Md}(α/2)/M ≤ ANEES_k ≤ χ²_{Md}(1 − α/2)/M, χ²_{Md}(q) the
    q-quantile of the chi-squared law with Md degrees of freedom (Bar-Shalom's test).
    """
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
    _distinct_runs(loaded)
    segments = plans[0][1]
    mc = anees_test(
        [log.errors for log in loaded], [log.cov for log in loaded], alpha, base.time, segments
    )
    return [pool_runs(loaded, segments)], mc


SAME_RUN = 1e-6
"""Two Monte Carlo runs whose errors differ nowhere by more than this times their RMS are
one run given twice (a copy in another precision or with truth and estimate shifted
alike differs in its last bits; independent runs differ by about their RMS)."""


def _distinct_runs(loaded: list[EstimatorLog]) -> None:
    """A CredcliError where two runs hold the same errors, to :data:`SAME_RUN`: the runs
    are pooled as independent draws of the scenario, and one run given twice (the same log
    named twice, a copy) would count its epochs twice and halve every standard error
    without a note. Runs are ordered by the sum of their errors, and each is compared with
    its two next in that order (a copy's sum is the original's, to rounding)."""
    sums, rms = np.empty(len(loaded)), np.empty(len(loaded))
    for k, log in enumerate(loaded):  # one run's errors at a time: M runs are not all held
        e = np.asarray(log.errors, dtype=float)
        sums[k], rms[k] = float(np.sum(e)), float(np.sqrt(np.mean(e * e)))
    order = np.argsort(sums, kind="stable")
    for a, i in enumerate(order):
        for j in order[a + 1 : a + 3]:
            scale = max(rms[i], rms[j])
            gap = np.abs(np.asarray(loaded[i].errors, float) - np.asarray(loaded[j].errors, float))
            if np.max(gap) <= SAME_RUN * scale:
                first, second = sorted((int(i), int(j)))
                raise CredcliError(
                    f"{loaded[second].id}: its errors are those of {loaded[first].id}, epoch "
                    f"for epoch (to {SAME_RUN:g} of their RMS); `monte_carlo` pools "
                    "independent runs, so give each run once"
                )


@dataclass(frozen=True)
class LogSummary:
    """What a report says of one whole log beside its segments: its id, size, what reading
    it dropped, its notes, and the accuracy over all its epochs (evo's figures for the
    whole trajectory, to compare logs as ``evo_res`` does). Typed until the report writes
    it (:func:`credcli.report.records.log_record`).

    Attributes
    ----------
    id : LogId
        Which log.
    epochs : int
        Its number of epochs N.
    dim : int
        The dimension d of its errors.
    dropped_rows : int
        The rows dropped as invalid while reading (``drop_invalid``).
    unpaired_epochs : int or None
        The estimate epochs dropped for want of truth (pairing with a separate truth).
    segments : int
        The number of segments it was cut into.
    notes : tuple of str
        The decisions taken while reading it (unit, format, pairing, convention).
    accuracy : Accuracy or None
        The accuracy of all its errors (RMSE, mean, median and maximum, per component and
        of the norm); None for a log without epochs.
    """

    id: LogId
    epochs: int
    dim: int
    dropped_rows: int
    unpaired_epochs: int | None
    segments: int
    notes: tuple[str, ...]
    accuracy: Accuracy | None


def log_summary(log: EstimatorLog, segments) -> LogSummary:
    """The :class:`LogSummary` of ``log`` cut into ``segments``.

    Parameters
    ----------
    log : EstimatorLog
        The whole log.
    segments : list of Segment
        Its segments (only their number is kept).

    Returns
    -------
    LogSummary
        Its id, size, what reading dropped, its notes and its accuracy.
    """
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


def checked_log(log: EstimatorLog) -> EstimatorLog:
    """The log as read, with a warning note when the claimed covariance fits its errors
    under the other perturbation convention far better
    ([convention_warning][credcli.engine.convention.convention_warning]).

    Parameters
    ----------
    log : EstimatorLog
        A log just read ([open_log][credcli.io.ingest.open_log]).

    Returns
    -------
    EstimatorLog
        The same log (its arrays not copied) without the other convention's errors, its
        notes ending with the warning if there is one.
    """
    swap = log.other_convention
    if swap is None:
        return log
    warning = convention_warning(log.errors, swap.errors, log.cov, swap.used, swap.other)
    notes = (*log.notes, f"WARNING: {warning}") if warning else log.notes
    return replace(log, notes=notes, other_convention=None)
