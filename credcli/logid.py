"""A log's identity: where it was read from, the name messages show, and the stem and
label its figures are named and titled by.

``LogId`` sits on the lowest floor, beside ``credcli.errors``, because two floors
carry it: the readers (``credcli.io``), which make a log, and the engine, whose
``SegmentDiagnosis`` says which log a segment belongs to and which imports nothing above
``errors``. It knows a path as text only: it opens nothing and asks the file system
nothing, so the engine still knows nothing about files.
"""

from __future__ import annotations

import os
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path


@dataclass(frozen=True)
class LogId:
    """Which log a result belongs to: its path, its name in messages and records, and the
    stem and label of its figures.

    Two logs are one log only when all four agree; a command makes the stems (and so the
    ids) of its logs unique ([unique_ids][credcli.logid.unique_ids]), so results are
    grouped by their ``LogId``, not by a name that two logs may share. ``str(log_id)`` is
    the name, so a message written as ``f"{log_id}: …"`` reads as it always did.

    Attributes
    ----------
    path : str or None
        The file (or URL, or ``-`` for standard input) as it was given; None for a log
        made in memory (from arrays, a DataFrame, a filter library's objects).
    name : str
        The log's name in messages and records: the path as given, ``<stdin>``, or the
        name a caller chose (``"<arrays>"``, ``"filterpy Saver"``).
    stem : str
        The start of its figures' file names: the name's stem (``run`` for ``a/run.csv``),
        unless another log of the same command has it too
        ([unique_ids][credcli.logid.unique_ids]). It is not yet a safe file name:
        ``credcli.report.plots.safe_name`` makes it one.
    label : str
        The short name its figures are titled and grouped by: the name's last part
        (``run.csv``), made unique with the stem.

    Examples
    --------
    >>> log_id = LogId.of("data/a/run.csv", "data/a/run.csv")
    >>> log_id.stem, log_id.label, f"{log_id}: row 3"
    ('run', 'run.csv', 'data/a/run.csv: row 3')
    """

    path: str | None
    name: str
    stem: str
    label: str

    @classmethod
    def of(cls, name: str, path: str | os.PathLike | None = None) -> LogId:
        """The id of a log called ``name`` (read from ``path``, or made in memory), its
        stem and label taken from the name's last part.

        Parameters
        ----------
        name : str
            The log's name in messages and records.
        path : str, path-like or None
            The file it was read from, as given; None for a log made in memory.

        Returns
        -------
        LogId
            Its stem and label not yet checked against other logs'
            ([unique_ids][credcli.logid.unique_ids]).

        Examples
        --------
        >>> LogId.of("<arrays>")
        LogId(path=None, name='<arrays>', stem='<arrays>', label='<arrays>')
        """
        name = str(name)
        last = Path(name)
        return cls(None if path is None else os.fspath(path), name, last.stem, last.name)

    def run(self, run: str) -> LogId:
        """The id of Monte Carlo run ``run`` of this log (``log.csv (run 3)``): its path,
        and its name and label followed by the run.

        Parameters
        ----------
        run : str
            The run's id, as the log's run column gives it.

        Returns
        -------
        LogId
            The same path; name and label ``"<name> (run <run>)"``, stem
            ``"<stem>_run<run>"``.

        Examples
        --------
        >>> LogId.of("mc.csv", "mc.csv").run("3")
        LogId(path='mc.csv', name='mc.csv (run 3)', stem='mc_run3', label='mc.csv (run 3)')
        """
        name, label = f"{self.name} (run {run})", f"{self.label} (run {run})"
        return LogId(self.path, name, f"{self.stem}_run{run}", label)

    def __str__(self) -> str:
        return self.name


def unique_ids(ids: Sequence[LogId]) -> list[LogId]:
    """``ids`` (the logs of one command, in order) with stems, and so figure names, that
    no two share.

    A stem that one log alone has stays as it is. Logs that share a stem take, all of
    them, the fewest parent directories of their paths (of their names, for logs without
    a path) that tell the most of them apart, joined by ``_`` in the stem and ``/`` in
    the label: ``a/run.csv`` and ``b/run.csv`` become ``a_run`` and ``b_run``, labelled
    ``a/run.csv`` and ``b/run.csv``. A stem still shared after that (one file given
    twice, logs made in memory, a stem so made that another log has) is numbered in
    command order: a log that had its stem alone keeps it, else the first log does, and
    the others take ``-2``, ``-3``, … (the first number no stem uses), their labels too
    where those are shared (`` (2)``, …). The rule reads the ids only: the same logs in
    the same order get the same names.

    Parameters
    ----------
    ids : sequence of LogId
        The logs' ids, in the order the command was given them.

    Returns
    -------
    list of LogId
        The same logs, in the same order, no two with one stem.

    Examples
    --------
    >>> ids = [LogId.of(p, p) for p in ("a/run.csv", "b/run.csv", "c/other.csv")]
    >>> [i.stem for i in unique_ids(ids)]
    ['a_run', 'b_run', 'other']
    >>> [i.label for i in unique_ids([ids[0], ids[0]])]
    ['run.csv', 'run.csv (2)']
    """
    ids = list(ids)
    out = list(ids)
    shared: dict[str, list[int]] = {}
    for k, log_id in enumerate(out):
        shared.setdefault(log_id.stem, []).append(k)
    alone = {stem for stem, members in shared.items() if len(members) == 1}
    for members in shared.values():
        if len(members) > 1:
            depth = _depth([_parents(out[k]) for k in members])
            for k in members:
                out[k] = _with_parents(out[k], depth)
    labels = Counter(log_id.label for log_id in out)
    taken = {log_id.stem for log_id in out} | set(shared)
    seen = set(alone)  # kept as they are
    for k, log_id in enumerate(out):
        if ids[k].stem in alone:
            continue
        if log_id.stem in seen:
            number = 2
            while f"{log_id.stem}-{number}" in taken:
                number += 1
            stem = f"{log_id.stem}-{number}"
            label = f"{log_id.label} ({number})" if labels[log_id.label] > 1 else log_id.label
            taken.add(stem)
            out[k] = replace(log_id, stem=stem, label=label)
        seen.add(out[k].stem)
    return out


def _parents(log_id: LogId) -> tuple[str, ...]:
    """The directories above the log's file, outermost first, without the root."""
    where = Path(log_id.path if log_id.path is not None else log_id.name)
    return tuple(part for part in where.parent.parts if part != where.anchor)


def _depth(parents: list[tuple[str, ...]]) -> int:
    """The fewest trailing parents that tell the most of ``parents`` apart."""
    deepest = max(len(p) for p in parents)
    apart = [len({p[max(len(p) - depth, 0) :] for p in parents}) for depth in range(deepest + 1)]
    return apart.index(max(apart))


def _with_parents(log_id: LogId, depth: int) -> LogId:
    if depth == 0:
        return log_id
    tail = _parents(log_id)[-depth:]
    if not tail:
        return log_id
    stem = "_".join((*tail, log_id.stem))
    label = "/".join((*tail, log_id.label))
    return replace(log_id, stem=stem, label=label)
