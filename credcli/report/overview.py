"""The overview figures of a whole log: the numbers gathered from the log, its segments and
their diagnoses, and drawn by :mod:`credcli.report.plots`.

``Results.plot`` returns these figures; ``--plots`` and ``credcli report`` write them (and
the per-segment figures, capped for windows: :func:`segments_to_draw`).
"""

from __future__ import annotations

import enum
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from credcli.engine.config import Label
from credcli.engine.curves import default_window, running_mean, running_mean_bounds
from credcli.engine.elt import whiten
from credcli.engine.metrics import nees
from credcli.errors import CredcliError
from credcli.report import plots as figs


class PlotKind(str, enum.Enum):
    """The figures of ``Results.plot(kind=...)``.

    Attributes
    ----------
    ERRORS : str
        ``"errors"``: each error component against time with the claimed ±kσ band.
    NEES : str
        ``"nees"``: NEES per epoch and its running mean with the mean's interval.
    WHITENED : str
        ``"whitened"``: the whitened errors against N(0, I).
    TIMELINE : str
        ``"timeline"``: one bar per segment, coloured by its label.
    TIMESCALES : str
        ``"timescales"``: the variance at every averaging time against the memory model.
    ALL : str
        ``"all"``: every kind of :data:`DRAWN`.
    """

    ERRORS = "errors"
    NEES = "nees"
    WHITENED = "whitened"
    TIMELINE = "timeline"
    TIMESCALES = "timescales"
    ALL = "all"

    def __str__(self) -> str:
        return self.value

    @classmethod
    def parse(cls, kind) -> PlotKind:
        """The kind named by ``kind``.

        Parameters
        ----------
        kind : PlotKind or str
            A kind, or its value (``"nees"``).

        Returns
        -------
        PlotKind
            The kind.

        Raises
        ------
        CredcliError
            If ``kind`` names no kind (the message lists them).

        Examples
        --------
        >>> PlotKind.parse("nees") is PlotKind.NEES
        True
        """
        try:
            return cls(kind)
        except ValueError:
            choices = ", ".join(repr(k.value) for k in cls)
            raise CredcliError(f"kind must be one of {choices}; got {kind!r}", "kind") from None


DRAWN = (PlotKind.TIMELINE, PlotKind.ERRORS, PlotKind.NEES, PlotKind.WHITENED)
"""Every kind of ``"all"``, in the order a report shows them."""

FILE_STEMS = {
    PlotKind.TIMELINE: "timeline",
    PlotKind.ERRORS: "errors",
    PlotKind.NEES: "nees_running",
    PlotKind.WHITENED: "whitened_errors",
}
"""The file names of the overview figures (after the log's prefix). A segment's figures end
in ``_nees``, ``_whitened``, ``_timescales`` or ``_scores``, which none of these does: the
names of the two never meet."""

MAX_WINDOW_FIGURES = 6
"""With windows, the per-window figures are drawn for at most this many windows that are
not credible (the overview figures cover the whole run)."""

MAX_SEGMENT_FIGURES = 24
"""Without windows, every segment's figures up to this many segments; past it, this many
segments that are not credible (the overview figures cover the whole log)."""


@dataclass(frozen=True)
class Source:
    """What the overview draws from: the runs of one scenario (one log, or M Monte Carlo
    runs on one time base), the segments of the first run and their diagnoses (pooled over
    the runs, in the order of ``segments``).

    Attributes
    ----------
    runs : tuple of EstimatorLog
        The runs (one log, or M runs on one time base); the first gives the time axis.
    segments : tuple of Segment
        The diagnosed segments of the first run, in the order of ``results``.
    results : tuple of SegmentDiagnosis
        Their diagnoses.
    alpha : float, default 0.05
        The level of the NEES running mean's interval.
    """

    runs: tuple
    segments: tuple
    results: tuple
    alpha: float = 0.05

    @classmethod
    def of(cls, runs, segments, results, alpha: float = 0.05) -> Source:
        """The source of ``results``, each matched to its segment by name.

        Parameters
        ----------
        runs : sequence of EstimatorLog
            The runs (one log, or M runs on one time base).
        segments : sequence of Segment
            The segments of the first run; those without a result are left out.
        results : sequence of SegmentDiagnosis
            The diagnoses to draw; each segment name must be in ``segments``.
        alpha : float, default 0.05
            The level of the NEES running mean's interval.

        Returns
        -------
        Source
            The runs, the segments of ``results`` in their order, and ``results``.

        Raises
        ------
        KeyError
            If a result's segment is not in ``segments``.
        """
        by_name = {segment.name: segment for segment in segments}
        chosen = tuple(by_name[result.segment] for result in results)
        return cls(tuple(runs), chosen, tuple(results), alpha)

    @property
    def time(self) -> np.ndarray | None:
        return self.runs[0].time

    @property
    def x(self) -> np.ndarray:
        time = self.time
        return np.arange(self.runs[0].n, dtype=float) if time is None else np.asarray(time)

    @property
    def xlabel(self) -> str:
        return "epoch" if self.time is None else "time [s]"


def spans(source: Source) -> list[figs.Span]:
    """Each diagnosed segment on the time axis, with its label, κ̂ and ANEES.

    A segment spans from its first epoch to one sampling step (the median) past its last,
    so that consecutive segments meet.

    Parameters
    ----------
    source : Source
        The runs, segments and diagnoses.

    Returns
    -------
    list of Span
        One per segment, in the order of ``source.segments``; in seconds when the log has
        time stamps, else in epochs.
    """
    x = source.x
    step = float(np.median(np.diff(x))) if x.size > 1 else 1.0
    out = []
    for segment, result in zip(source.segments, source.results, strict=True):
        diag = result.diagnosis
        index = np.asarray(segment.index)
        kappa = None if diag.scale is None else float(diag.scale.scale_factor)
        start, end = (float(x[index[0]]), float(x[index[-1]]) + step) if index.size else (0, 0)
        out.append(figs.Span(result.segment, start, end, diag.label.value, kappa, diag.anees))
    return out


def _shaded(source: Source) -> list[tuple]:
    """The (span, segment) pairs to shade behind curves: without a segment holding the
    whole log when there are others (the run after its windows)."""
    n = source.runs[0].n
    pairs = list(zip(spans(source), source.segments))
    whole = [len(segment.index) == n for segment in source.segments]
    if len(pairs) > 1 and any(whole) and not all(whole):
        return [pair for pair, w in zip(pairs, whole) if not w]
    return pairs


def draw(source: Source, kind: PlotKind, k: float = 3.0, window: int | None = None) -> tuple:
    """One overview figure.

    Parameters
    ----------
    source : Source
        The runs, segments and diagnoses.
    kind : PlotKind
        The figure (not ``ALL``).
    k : float, default 3.0
        The half-width of the error band, in claimed standard deviations (``ERRORS``).
    window : int or None, default None
        The running mean's window in epochs (``NEES``); None for the default window of
        the log's length.

    Returns
    -------
    figure : matplotlib.figure.Figure
        The figure, still open.
    data : dict
        The numbers drawn.
    title : str
        Its title.

    Raises
    ------
    CredcliError
        If ``window`` is not between 1 and the log's length, if ``kind`` is
        ``TIMESCALES`` and no segment has a fitted memory, or if ``kind`` is ``ALL``.
    """
    fig, data = _draw(source, kind, k, window)
    return fig, data, fig.get_suptitle()


def _draw(source: Source, kind: PlotKind, k: float, window: int | None) -> tuple:
    runs, x, xlabel = source.runs, source.x, source.xlabel
    m, dim = len(runs), runs[0].dim
    name = _short_source(runs)
    if kind is PlotKind.TIMELINE:
        return figs.draw_timeline(spans(source), xlabel, f"{name}: label per segment")
    if kind is PlotKind.TIMESCALES:
        return _time_scales(source, name)
    pairs = _shaded(source)
    shaded = [span for span, _ in pairs]
    if kind is PlotKind.ERRORS:
        errors = np.stack([r.errors for r in runs])
        sigma = np.stack([np.sqrt(np.diagonal(r.cov, axis1=1, axis2=2)) for r in runs])
        band = k * np.sqrt(np.mean(sigma**2, axis=0))  # kσ for one run
        outside = np.mean(np.abs(errors) > k * sigma, axis=(0, 1))
        what = "" if m == 1 else f" ({m} runs)"
        title = f"{name}: errors and the claimed ±{k:g}σ{what}"
        shown = errors[0] if m == 1 else errors
        return figs.draw_errors(x, shown, band, outside, shaded, k, xlabel, None, title)
    if kind is PlotKind.NEES:
        values = np.mean([nees(r.errors, r.cov) for r in runs], axis=0)
        w = default_window(values.size) if window is None else int(window)
        if not 1 <= w <= values.size:
            raise CredcliError(
                f"window must be between 1 and {values.size} epochs; got {w}", "window"
            )
        bounds = running_mean_bounds(dim, w, source.alpha, m)
        title = f"{name}: NEES and its running mean"
        return figs.draw_nees(
            x,
            values,
            dim,
            running_mean(values, w),
            w,
            bounds,
            source.alpha,
            shaded,
            m,
            xlabel,
            title,
        )
    if kind is PlotKind.WHITENED:
        white = np.concatenate([whiten(r.errors, r.cov) for r in runs])
        colours, labels = None, None
        if white.shape[0] <= figs.MAX_SCATTER:
            per_epoch = np.full(runs[0].n, "#1f77b4", dtype=object)
            by_colour: dict[str, list[str]] = {}
            for span, segment in pairs:
                per_epoch[np.asarray(segment.index)] = figs.label_colour(span.label)
                names = by_colour.setdefault(figs.label_colour(span.label), [])
                if span.label not in names:
                    names.append(span.label)
            labels = {figs.short_title(", ".join(v), 40): c for c, v in by_colour.items()}
            colours = list(np.tile(per_epoch, m))
        title = f"{name}: whitened errors Σ^(-1/2) e"
        return figs.draw_whitened_errors(white, colours, title, labels)
    raise CredcliError(f"kind must be one of {', '.join(repr(k.value) for k in DRAWN)}", "kind")


def _time_scales(source: Source, name: str) -> tuple:
    """κ̂ against averaging time of the longest segment whose memory was fitted (the run's
    own, beside its windows): the variance of m-epoch means of the whitened errors against
    the memory model's prediction and interval."""
    fitted = [
        (len(segment.index), segment, result)
        for segment, result in zip(source.segments, source.results, strict=True)
        if result.diagnosis.time_scales is not None and result.diagnosis.time_scales.epochs.size > 1
    ]
    if not fitted:
        raise CredcliError(
            "kind 'timescales': no segment has a fitted memory (the calibrated rule fits "
            "one on segments long enough for it)",
            "kind",
        )
    _, segment, result = max(fitted, key=lambda item: item[0])
    time = source.runs[0].time
    rate = None
    if time is not None and len(segment.index) > 1:
        span = float(np.ptp(time[np.asarray(segment.index)]))
        rate = (len(segment.index) - 1) / span if span > 0 else None
    fig, data = figs.draw_time_scales(result.diagnosis.time_scales, rate)
    fig.suptitle(f"{name}: variance against averaging time, segment {result.segment}")
    figs.plain_text(fig)
    fig.tight_layout()
    return fig, data


def _short_source(runs: Sequence) -> str:
    name = figs.short_title(runs[0].id.label, 50)
    return name if len(runs) == 1 else f"{name} and {len(runs) - 1} more runs"


def overview_plots(source: Source, prefix: str = "", log_name: str = "") -> list[figs.Plot]:
    """The overview figures as files: ``<prefix>timeline``, ``<prefix>errors``,
    ``<prefix>nees_running``, ``<prefix>whitened_errors`` (see :data:`FILE_STEMS`).

    Parameters
    ----------
    source : Source
        The runs, segments and diagnoses.
    prefix : str, default ""
        The start of every file name (a log's stem when there are several); made safe
        for a file name, and joined to the stem by one ``_``.
    log_name : str, default ""
        The log's label, which names the figures' report section (``"<log_name>:
        overview"``; ``"overview"`` when empty).

    Returns
    -------
    list of Plot
        The figures of :data:`DRAWN`, in that order, drawn with the default ``k`` and
        window.
    """
    stem = figs.safe_name(prefix.rstrip("_")) + "_" if prefix else ""
    group = f"{log_name}: overview" if log_name else "overview"
    out = []
    for kind in DRAWN:
        fig, data, title = draw(source, kind)
        out.append(figs.figure_plot(f"{stem}{FILE_STEMS[kind]}", title, (fig, data), group))
    return out


def segments_to_draw(segments, results, limit: int = MAX_WINDOW_FIGURES):
    """The (segment, result) pairs whose own figures are drawn, in their order, and a note
    on those left out (None when none is). With windows: every segment that is not a
    window and, of the windows, up to ``limit`` that are not credible, misfits before
    windows without a verdict (the overview figures show the whole run). Without windows
    (a segment column), every segment up to :data:`MAX_SEGMENT_FIGURES`; past it, that
    many that are not credible, chosen alike (each segment has up to four figures of its
    own).

    Parameters
    ----------
    segments : sequence of Segment
        The diagnosed segments, in order.
    results : sequence of SegmentDiagnosis
        Their diagnoses, in the same order.
    limit : int, default MAX_WINDOW_FIGURES
        The most windows drawn (without windows, :data:`MAX_SEGMENT_FIGURES` applies).

    Returns
    -------
    pairs : list of tuple
        The (segment, result) pairs to draw, in their order.
    note : str or None
        What was left out and why; None when every pair is drawn.
    """
    pairs = list(zip(segments, results, strict=True))
    capped = [i for i, (segment, _) in enumerate(pairs) if segment.window]
    what = "windows"
    if not capped:
        if len(pairs) <= MAX_SEGMENT_FIGURES:
            return pairs, None
        capped, what, limit = list(range(len(pairs))), "segments", MAX_SEGMENT_FIGURES

    def rank(i: int) -> int:
        label = pairs[i][1].diagnosis.label
        return 0 if label not in (Label.CREDIBLE, Label.INSUFFICIENT) else 1

    candidates = [i for i in capped if pairs[i][1].diagnosis.label is not Label.CREDIBLE]
    chosen = set(sorted(candidates, key=lambda i: (rank(i), i))[:limit])
    keep = [pair for i, pair in enumerate(pairs) if i not in capped or i in chosen]
    if len(chosen) == len(capped):
        return keep, None
    whole = "the whole run" if what == "windows" else "the whole log"
    note = (
        f"figures of {len(chosen)} of {len(capped)} {what} (those not credible, misfits "
        f"first, at most {limit}); {len(capped) - len(chosen)} skipped: the overview "
        f"figures show {whole}"
    )
    return keep, note
