"""STAR-loc UWB logs: a ``uwb.csv`` of ranges (one per row) and the anchor markers file.

The columns and their meaning are those of the dataset's README (``../shared/data/starloc``);
the pipeline that turns ranges into position fixes is :mod:`credcli.studies.uwb`.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from credcli.errors import CredcliError
from credcli.io.logs import numeric_columns, read_table
from credcli.io.schema import RangeReading


@dataclass(frozen=True)
class RangeLog:
    """One STAR-loc uwb.csv: one range per row, sorted by time.

    Attributes
    ----------
    source : str
        The file, as given.
    time : numpy.ndarray, shape (N,)
        The rows' ``time_s`` stamps (s).
    range : numpy.ndarray, shape (N,)
        The measured ranges (m), from ``range_column``.
    std : numpy.ndarray, shape (N,)
        The claimed std of each range (m): the ``std`` column, or as the settings give or
        estimate it.
    tag : numpy.ndarray of int64, shape (N,)
        The tag id of each range (``from_id``).
    anchor : numpy.ndarray of int64, shape (N,)
        The anchor id of each range (``to_id``).
    tag_pos : numpy.ndarray, shape (N, 3)
        The ground-truth tag position (m).
    rig_pos : numpy.ndarray, shape (N, 3)
        The ground-truth rig position (m): the ``x``, ``y``, ``z`` columns, or ``tag_pos``
        in files without them.
    gt_range : numpy.ndarray, shape (N,)
        The ground-truth range (m).
    range_column : str
        The column the ranges were read from (``range_calib``, or ``range`` in files
        without it).
    notes : tuple of str
        The decisions taken while reading (the range column, the std).
    """

    source: str
    time: np.ndarray
    range: np.ndarray
    std: np.ndarray
    tag: np.ndarray
    anchor: np.ndarray
    tag_pos: np.ndarray  # (N, 3) ground-truth tag position
    rig_pos: np.ndarray  # (N, 3) ground-truth rig position
    gt_range: np.ndarray
    range_column: str
    notes: tuple[str, ...] = ()

    @property
    def range_error(self) -> np.ndarray:
        return self.range - self.gt_range


MAX_ID = 2.0**53
"""Anchor, tag and marker ids are whole numbers no larger than this (exact as float64 and
as int64); a larger one would be cast to a wrong id without a word."""


_REQUIRED = ("time_s", "from_id", "to_id", "tag_pos_x", "tag_pos_y", "tag_pos_z", "gt_range")


def read_starloc(path: str | Path, settings: RangeReading = RangeReading()) -> RangeLog:
    """Read and validate a STAR-loc ``uwb.csv``.

    Without ``range_calib`` (setup s5) the raw ``range`` column is used, with a note.
    Without ``std`` a fixed ``settings.std`` is required (or ``std_by_anchor`` for every
    anchor, or ``std_estimate``).

    Parameters
    ----------
    path : str or pathlib.Path
        The ``uwb.csv`` file.
    settings : RangeReading
        The range column and where the range std comes from (default: ``range_calib``
        and the file's ``std`` column).

    Returns
    -------
    RangeLog
        The ranges, their std and ground truth, sorted by time (stable).

    Raises
    ------
    CredcliError
        If a required column is missing (``time_s``, ``from_id``, ``to_id``,
        ``tag_pos_x/y/z``, ``gt_range``, the range column), no std is given, a value is
        NaN, Inf or empty, a std is not positive, or an id is not a whole number up to
        ``MAX_ID``.
    """
    path = Path(path)
    frame = read_table(path)
    columns = [str(c) for c in frame.columns]
    frame.columns = columns
    source = str(path)
    missing = [c for c in _REQUIRED if c not in columns]
    if missing:
        raise CredcliError(
            f"{source}: not a STAR-loc uwb.csv: missing column(s) {', '.join(missing)}; "
            f"columns found: {', '.join(columns[:30])}"
        )
    notes = []
    range_column = settings.range_column
    if range_column not in columns:
        if range_column == RangeReading.range_column and "range" in columns:
            notes.append(f"{source}: no '{range_column}' column (setup s5?): using raw 'range'")
            range_column = "range"
        else:
            raise CredcliError(
                f"{source}: range column '{range_column}' not found; columns found: "
                f"{', '.join(columns[:30])}"
            )
    std_given = settings.std is not None or settings.std_by_anchor or settings.std_estimate
    if not std_given and "std" not in columns:
        raise CredcliError(
            f"{source}: no 'std' column (setup s5 runs do not report one); give the range "
            "standard deviation in metres with `std` VALUE (e.g. `std` 0.1), per anchor "
            "(`std` 4=0.1,9=0.12) or `std` estimate"
        )
    rig_cols = ["x", "y", "z"] if all(c in columns for c in ("x", "y", "z")) else None
    numeric = list(_REQUIRED) + [range_column]
    numeric += ["std"] if "std" in columns and settings.std is None else []
    numeric += rig_cols or []
    values = numeric_columns(frame, numeric, source)
    bad = ~np.isfinite(values).all(axis=1)
    if bad.any():
        rows = np.flatnonzero(bad)[:10] + 1
        raise CredcliError(
            f"{source}: NaN, Inf or empty value in row(s) {', '.join(map(str, rows))}"
            f"{' and more' if bad.sum() > 10 else ''}"
        )
    col = {name: values[:, i] for i, name in enumerate(numeric)}
    std, std_notes = _range_std(col, settings, source, range_column)
    notes.extend(std_notes)
    if np.any(std <= 0):
        row = int(np.argmax(std <= 0)) + 1
        raise CredcliError(f"{source}: row {row}, column 'std': a reported std must be > 0")
    for name in ("from_id", "to_id"):
        fractional = (col[name] != np.round(col[name])) | ~(np.abs(col[name]) <= MAX_ID)
        if fractional.any():
            row = int(np.argmax(fractional)) + 1
            raise CredcliError(
                f"{source}: row {row}, column '{name}': {col[name][row - 1]:g} is not an integer "
                f"id (ids are whole numbers up to {MAX_ID:.0e})"
            )
    order = np.argsort(col["time_s"], kind="stable")
    tag_pos = np.c_[col["tag_pos_x"], col["tag_pos_y"], col["tag_pos_z"]]
    rig_pos = np.c_[col["x"], col["y"], col["z"]] if rig_cols else tag_pos
    return RangeLog(
        source=source,
        time=col["time_s"][order],
        range=col[range_column][order],
        std=std[order],
        tag=col["from_id"][order].astype(np.int64),
        anchor=col["to_id"][order].astype(np.int64),
        tag_pos=tag_pos[order],
        rig_pos=rig_pos[order],
        gt_range=col["gt_range"][order],
        range_column=range_column,
        notes=tuple(notes),
    )


def _range_std(col: dict, settings: RangeReading, source: str, range_column: str):
    """The claimed std of every range row: the ``std`` column or ``--std``, overridden per
    anchor by ``std_by_anchor``, or estimated per anchor (``std_estimate``: 1.4826 × the
    median absolute deviation of range − gt_range, robust to stale packets and outliers)."""
    n = col["to_id"].size
    anchor = col["to_id"].astype(np.int64)
    notes = []
    if settings.std_estimate:
        err = col[range_column] - col["gt_range"]
        std = np.empty(n)
        parts = []
        for a in np.unique(anchor):
            rows = anchor == a
            e = err[rows]
            std[rows] = max(1.4826 * float(np.median(np.abs(e - np.median(e)))), 1e-4)
            parts.append(f"{a}: {std[rows][0]:.3g}")
        notes.append(
            f"{source}: range std estimated per anchor from the data (1.4826 MAD of range − "
            f"gt_range, m): {', '.join(parts)}; the verdict is about this estimated noise "
            "model, not a reported one"
        )
        return std, notes
    std = np.full(n, settings.std) if settings.std is not None else col.get("std")
    given = dict(settings.std_by_anchor)
    if given:
        missing = sorted(set(np.unique(anchor).tolist()) - set(given))
        if missing and std is None:
            raise CredcliError(
                f"{source}: `std` gives no std for anchor(s) {', '.join(map(str, missing))} "
                "and the file has no std column; give one for every anchor, or a default"
            )
        std = np.full(n, np.nan) if std is None else std.copy()
        for a, value in given.items():
            std[anchor == a] = value
    return std, notes


def read_markers(path: str | Path) -> dict[int, np.ndarray]:
    """Anchor positions from a STAR-loc markers file (first column the id, then x, y, z).

    Parameters
    ----------
    path : str or pathlib.Path
        The markers file: its first column the ids, and columns ``x``, ``y``, ``z``.

    Returns
    -------
    dict of int to numpy.ndarray
        Each marker id's position, shape (3,).

    Raises
    ------
    CredcliError
        If the file has no ``x``, ``y``, ``z`` columns, a value is not a number, a position
        is not finite (NaN, an empty cell, inf), an id is not a whole number up to
        ``MAX_ID``, or an id is given twice.
    """
    path = Path(path)
    frame = read_table(path)
    cols = [str(c) for c in frame.columns]
    if not all(c in cols for c in ("x", "y", "z")):
        raise CredcliError(
            f"{path}: a markers file needs an id column and x, y, z; found {', '.join(cols)}"
        )
    try:
        raw = frame[cols[0]].to_numpy(dtype=float)
        xyz = frame[["x", "y", "z"]].to_numpy(dtype=float)
    except (TypeError, ValueError, OverflowError) as exc:
        raise CredcliError(f"{path}: markers must be numbers: {exc}") from exc
    wrong = (raw != np.round(raw)) | ~(np.abs(raw) <= MAX_ID)
    if wrong.any():
        row = int(np.argmax(wrong)) + 1
        raise CredcliError(
            f"{path}: row {row}: marker id {raw[row - 1]:g} is not an integer id (ids are "
            f"whole numbers up to {MAX_ID:.0e})"
        )
    bad = ~np.isfinite(xyz).all(axis=1)
    if bad.any():
        row = int(np.argmax(bad)) + 1
        raise CredcliError(
            f"{path}: row {row}: marker {int(raw[row - 1])} has a position that is not a "
            "finite number; give x, y, z of every anchor"
        )
    ids = raw.astype(np.int64)
    unique, counts = np.unique(ids, return_counts=True)
    if np.any(counts > 1):  # two positions for one anchor: which one ranged is unknown
        twice = int(unique[np.argmax(counts > 1)])
        rows = np.flatnonzero(ids == twice)[:2] + 1
        raise CredcliError(
            f"{path}: marker id {twice} is given twice (rows {rows[0]} and {rows[1]}); give "
            "each anchor one position"
        )
    return {int(i): p for i, p in zip(ids, xyz)}
