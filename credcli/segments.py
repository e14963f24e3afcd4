"""Segmentation stages: a segment column, fixed windows, static periods, or the whole log."""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

from credcli.errors import CredcliError


@dataclass(frozen=True)
class Segment:
    """A named set of epochs (indices into the log, in time order)."""

    name: str
    index: np.ndarray
    t_start: float | None = None
    t_end: float | None = None


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
                f"--window '{text}' is not a duration like 5s, 250ms, 2min or an epoch count like 200"
            )
        value, unit = float(m.group(1)), m.group(2)
        if value <= 0:
            raise CredcliError(f"--window must be positive; got '{text}'")
        if unit is None:
            if value != int(value):
                raise CredcliError(f"--window '{text}': an epoch count must be a whole number")
            return cls(value, False)
        return cls(value * {"ms": 1e-3, "s": 1.0, "min": 60.0}[unit], True)

    def __str__(self) -> str:
        return f"{self.length:g}s" if self.seconds else f"{int(self.length)}"


def _span(time: np.ndarray | None, index: np.ndarray) -> tuple[float | None, float | None]:
    if time is None or index.size == 0:
        return None, None
    return float(time[index].min()), float(time[index].max())


def by_column(values: np.ndarray, time: np.ndarray | None = None) -> list[Segment]:
    """One segment per distinct value, in order of first appearance."""
    _, first, inverse = np.unique(values, return_index=True, return_inverse=True)
    order = np.argsort(first, kind="stable")
    groups = np.argsort(inverse, kind="stable")
    bounds = np.cumsum(np.bincount(inverse))
    segments = []
    for g in order:
        idx = groups[(bounds[g - 1] if g else 0) : bounds[g]]
        segments.append(Segment(str(values[first[g]]), idx, *_span(time, idx)))
    return segments


def by_window(n: int, window: Window, time: np.ndarray | None) -> list[Segment]:
    """Consecutive windows of a fixed duration (from the first time) or epoch count.

    Windows are named ``w001``, ``w002``, … in time order; empty duration windows are skipped
    (their numbers are kept so names stay tied to the time span).
    """
    if window.seconds:
        if time is None:
            raise CredcliError(
                f"--window {window} needs a time column; use an epoch count (e.g. --window 200) "
                "or name the time column"
            )
        if np.any(np.diff(time) < 0):
            raise CredcliError(
                "the time column is not sorted; sort the log by time to use --window"
            )
        k = np.floor((time - time[0]) / window.length).astype(np.int64)
    else:
        k = np.arange(n) // int(window.length)
    bounds = np.flatnonzero(np.diff(k)) + 1
    starts = np.r_[0, bounds]
    stops = np.r_[bounds, n]
    width = max(3, len(str(int(k[-1]) + 1)))
    return [
        Segment(f"w{int(k[a]) + 1:0{width}d}", np.arange(a, b), *_span(time, np.arange(a, b)))
        for a, b in zip(starts, stops)
    ]


def whole(n: int, time: np.ndarray | None) -> list[Segment]:
    idx = np.arange(n)
    return [Segment("all", idx, *_span(time, idx))]


def static_periods(
    time: np.ndarray, position: np.ndarray, max_speed: float = 0.1, min_duration: float = 4.0
) -> list[Segment]:
    """Periods where the speed from ``position`` (N, 3) stays below ``max_speed`` for at least
    ``min_duration`` seconds (Section V-A). Speed is the finite difference over each
    sample step; periods are named ``P1``, ``P2``, … in time order.
    """
    order = np.argsort(time, kind="stable")
    t, p = time[order], position[order]
    dt = np.diff(t)
    step = np.linalg.norm(np.diff(p, axis=0), axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        speed = np.where(dt > 0, step / np.where(dt > 0, dt, 1.0), 0.0)
    slow = np.r_[speed < max_speed, False]  # sample i is slow if the step to i+1 is slow
    edges = np.diff(np.r_[0, slow.astype(np.int8), 0])
    starts = np.flatnonzero(edges == 1)
    stops = np.flatnonzero(edges == -1)  # exclusive; the last slow step ends at sample stop
    segments = []
    for a, b in zip(starts, stops):
        t0, t1 = t[a], t[min(b, len(t) - 1)]
        if t1 - t0 >= min_duration:
            idx = order[a : b + 1] if b < len(t) else order[a:b]
            segments.append(Segment(f"P{len(segments) + 1}", np.sort(idx), float(t0), float(t1)))
    return segments
