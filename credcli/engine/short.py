"""Segments too short for a verdict, diagnosed together and kept as columns; and the
results of a log's segments, in which each run of such segments is one part.

A log of 10⁶ one-epoch segments has 10⁶ insufficient-data results that differ only in
their name, time span, length and accuracy. :class:`ShortSegments` holds them as a few
arrays (about 100 bytes a segment, against some 2 kB for a SegmentDiagnosis with its
Diagnosis and Accuracy), made by a few numpy calls (:func:`short_segments`), and makes a
segment's SegmentDiagnosis only when it is asked for; the report writes a run of them as
columns (:class:`credcli.report.records.RecordBatch`).
"""

from __future__ import annotations

import bisect
import itertools
from collections.abc import Iterator, Sequence
from dataclasses import dataclass

import numpy as np

from credcli.engine import linalg, metrics
from credcli.engine.config import DiagnosisConfig, Label
from credcli.engine.diagnosis import Diagnosis, SegmentDiagnosis, too_short_reason
from credcli.logid import LogId


class ColumnRows(Sequence):
    """A sequence of rows held as columns, one per name in ``names``: indexing makes the
    k-th row (:meth:`row`) on demand, a slice the list of its rows, an index past the end
    an IndexError, as a list's."""

    names: list[str]

    def __len__(self) -> int:
        return len(self.names)

    def __getitem__(self, k):
        if isinstance(k, slice):
            return [self.row(i) for i in range(*k.indices(len(self)))]
        return self.row(range(len(self))[k])

    def row(self, k: int):
        """The k-th row, 0 <= k < len(self).

        Parameters
        ----------
        k : int
            Its index.

        Returns
        -------
        object
            The row.
        """
        raise NotImplementedError


@dataclass(frozen=True, eq=False)
class ShortSegments(ColumnRows):
    """Consecutive segments of one log, each too short for a verdict (fewer epochs than
    ``config.min_n(dim)``): insufficient-data, with the reason and their accuracy, as
    columns. Item k is segment k's :class:`~credcli.engine.diagnosis.SegmentDiagnosis`,
    the same as diagnosing it alone (:func:`credcli.engine.diagnosis.diagnose_segment`).

    Attributes
    ----------
    log : LogId
        The log the segments belong to.
    names : sequence of str
        The segments' names.
    t_start, t_end : numpy.ndarray or None
        Each segment's first and last time stamps; None for a log without time.
    n : numpy.ndarray
        Each segment's epochs (int).
    dim : int
        The state dimension d.
    config : DiagnosisConfig
        The settings of the diagnosis (the reason names its minimum).
    accuracy : AccuracyColumns
        Each segment's accuracy (:func:`credcli.engine.metrics.accuracy_columns`).
    """

    log: LogId
    names: Sequence[str]
    t_start: np.ndarray | None
    t_end: np.ndarray | None
    n: np.ndarray
    dim: int
    config: DiagnosisConfig
    accuracy: metrics.AccuracyColumns

    def row(self, k: int) -> SegmentDiagnosis:
        """The k-th segment's result (``insufficient-data``, its reason, its accuracy).

        Parameters
        ----------
        k : int
            Its index.

        Returns
        -------
        SegmentDiagnosis
            Its result, as a segment diagnosed alone would give it.
        """
        n = int(self.n[k])
        diagnosis = Diagnosis(
            Label.INSUFFICIENT,
            n,
            self.dim,
            reason=self.reason(n),
            config=self.config,
            accuracy=self.accuracy[k],
        )
        t_start = None if self.t_start is None else float(self.t_start[k])
        t_end = None if self.t_end is None else float(self.t_end[k])
        return SegmentDiagnosis(self.log, self.names[k], t_start, t_end, diagnosis)

    def __iter__(self) -> Iterator[SegmentDiagnosis]:
        return map(self.row, range(len(self)))

    def reason(self, n: int) -> str:
        """Why a segment of ``n`` epochs has no verdict.

        Parameters
        ----------
        n : int
            The segment's epochs.

        Returns
        -------
        str
            The reason of its insufficient-data result.
        """
        return too_short_reason(n, self.dim, self.config)

    def take(self, start: int, stop: int) -> ShortSegments:
        """Segments ``start`` to ``stop``.

        Parameters
        ----------
        start, stop : int
            The segments.

        Returns
        -------
        ShortSegments
            Those segments (the columns as views).
        """
        part = slice(start, stop)
        return ShortSegments(
            self.log,
            self.names[part],
            None if self.t_start is None else self.t_start[part],
            None if self.t_end is None else self.t_end[part],
            self.n[part],
            self.dim,
            self.config,
            self.accuracy.take(start, stop),
        )


def short_segments(
    log: LogId,
    names: Sequence[str],
    t_start: np.ndarray | None,
    t_end: np.ndarray | None,
    errors: np.ndarray,
    cov: np.ndarray,
    lengths: np.ndarray,
    config: DiagnosisConfig,
) -> ShortSegments:
    """Consecutive segments too short for a verdict, checked and measured together as
    :func:`credcli.engine.diagnosis.too_short_batch` does.

    Parameters
    ----------
    log : LogId
        Their log.
    names : sequence of str
        Their names.
    t_start, t_end : numpy.ndarray or None
        Their first and last time stamps (None for a log without time).
    errors : numpy.ndarray, shape (N, d)
        Their errors, one segment after another.
    cov : numpy.ndarray, shape (N, d, d)
        Their claimed covariances, likewise.
    lengths : array_like of int
        Each segment's epochs, all below ``config.min_n(d)``.
    config : DiagnosisConfig
        The settings of the diagnosis.

    Returns
    -------
    ShortSegments
        Their insufficient-data results, as columns.

    Raises
    ------
    CredcliError
        When an error or a covariance is not valid (diagnose each segment alone to name
        it).
    """
    errors, cov = linalg.check_errors_cov(errors, cov)
    linalg.cholesky(cov)
    lengths = np.asarray(lengths, dtype=np.int64)
    accuracy = metrics.accuracy_columns(errors, lengths)
    return ShortSegments(log, names, t_start, t_end, lengths, errors.shape[1], config, accuracy)


class PartSequence(Sequence):
    """A sequence held as parts, in order: single items, and runs (parts of the class
    ``RUN``) whose items are made when asked for. Item k is found by bisection on the
    parts' cumulative lengths.

    Parameters
    ----------
    parts : tuple
        Single items and runs, in order.
    """

    RUN: type | tuple[type, ...] = tuple  # the class(es) of a run; a subclass names its own

    def __init__(self, parts: tuple) -> None:
        self.parts = tuple(parts)
        sizes = (len(p) if isinstance(p, self.RUN) else 1 for p in self.parts)
        self._ends = list(itertools.accumulate(sizes))

    def __len__(self) -> int:
        return self._ends[-1] if self._ends else 0

    def __getitem__(self, k):
        if isinstance(k, slice):
            return [self[i] for i in range(*k.indices(len(self)))]
        k = range(len(self))[k]
        p = bisect.bisect_right(self._ends, k)
        part = self.parts[p]
        if isinstance(part, self.RUN):
            return part[k - (self._ends[p] - len(part))]
        return part

    def __iter__(self) -> Iterator:
        for part in self.parts:
            if isinstance(part, self.RUN):
                yield from part
            else:
                yield part


class SegmentResults(PartSequence):
    """The results of segments, in order: a sequence of
    :class:`~credcli.engine.diagnosis.SegmentDiagnosis` held as ``parts``, each one
    SegmentDiagnosis or a :class:`ShortSegments` run, whose items are made when asked for.
    The report reads the parts (:func:`credcli.report.records.segment_records`).

    Parameters
    ----------
    parts : tuple
        SegmentDiagnosis and ShortSegments, in the segments' order.
    """

    RUN = ShortSegments

    def verdicts(self) -> Iterator[tuple[Label, tuple]]:
        """Each segment's label and untested questions, in order, without making the
        segments' results.

        Returns
        -------
        iterator of (Label, tuple of Question)
            ``(diagnosis.label, diagnosis.untested)`` of each segment.
        """
        return itertools.chain.from_iterable(
            itertools.repeat((Label.INSUFFICIENT, ()), len(part))
            if isinstance(part, ShortSegments)
            else ((v.label, v.untested) for v in (part.verdict(),))
            for part in self.parts
        )
