"""Records: the only module that knows the keys of credcli's JSON.

A Diagnosis as a flat, JSON-safe dict (:func:`segment_record`), each command's document
(:func:`diagnose_document`, :func:`simulate_document`, ...) and its ``parameters``, the rows
of the tables people read and the columns that show them (:data:`SEGMENT_COLUMNS`, ...), the
accessors of a document's parts (:func:`document_parameters`, :func:`log_notes`), and a
baseline file read back into typed values (:func:`read_baseline`). The builders, the
renderers, the CI gate and the Python API's ``to_dict``/``to_frame`` read every key from
here.
"""

from __future__ import annotations

import dataclasses
import enum
import itertools
import json
import math
import typing
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from credcli.engine.config import DiagnosisConfig, Question
from credcli.engine.diagnosis import Diagnosis, Label, SegmentDiagnosis
from credcli.engine.short import PartSequence, SegmentResults, ShortSegments
from credcli.errors import CredcliError, plain, shortened
from credcli.io.checks import SEGMENT_HINTS, check_types, diagnosis_hints, is_number
from credcli.io.schema import LogReading, LogSchema, ReadOptions
from credcli.io.streams import open_input
from credcli.report.formats import format_interval
from credcli.report.jsontext import ListColumn
from credcli.report.tables import Column
from credcli.version import __version__

BASELINE_SCHEMA_VERSION = 1
BASELINE_KIND = "credcli-baseline"


def json_value(x):
    """A JSON-safe scalar: enums to their value, NaN/Inf to None.

    Parameters
    ----------
    x : object
        A value of a record: None, a number, an enum or any other JSON-ready value.

    Returns
    -------
    object
        ``x.value`` for an enum, None for None and for a non-finite float (Python or numpy),
        ``x`` itself otherwise.

    Examples
    --------
    >>> json_value(float("nan")), json_value(Label.CREDIBLE), json_value(2.5)
    (None, 'credible', 2.5)
    """
    if x is None:
        return None
    if type(x) is float:  # the common case first: a record has dozens (10⁶ segments)
        return x if math.isfinite(x) else None
    if isinstance(x, enum.Enum):
        return x.value
    if isinstance(x, float) and not math.isfinite(x):
        return None
    return x


def shown_label(label: Label, untested) -> str:
    """The label as every output shows it.

    A partial verdict names the question it leaves open ("credible (scale untested)"), so
    that a script reading only ``label`` never takes a partial credible for a pass; the
    answered half alone is ``label_answered``.

    Parameters
    ----------
    label : Label
        The answered label.
    untested : iterable of Question or str
        The questions the segment leaves open ("scale", "location"); empty for a full
        verdict.

    Returns
    -------
    str
        The label's text, followed by "(… untested)" naming the open questions (joined by
        "and") when there are any and the label is not ``insufficient-data``.

    Examples
    --------
    >>> shown_label(Label.CREDIBLE, ["scale"]), shown_label(Label.OPTIMISM, [])
    ('credible (scale untested)', 'optimism')
    """
    names = [q if isinstance(q, str) else q.value for q in untested]
    if not names or label is Label.INSUFFICIENT:
        return label.value
    return f"{label.value} ({' and '.join(names)} untested)"


def record_label(rec: dict) -> Label:
    """The answered label of a segment record.

    Parameters
    ----------
    rec : dict
        A segment record (:func:`segment_record`, or a baseline's segment).

    Returns
    -------
    Label
        Its ``label_answered``, or its ``label`` where it has none (a baseline written
        before partial verdicts were shown has only ``label``).

    Examples
    --------
    >>> record_label({"label": "credible (scale untested)", "label_answered": "credible"})
    <Label.CREDIBLE: 'credible'>
    """
    return Label(rec.get("label_answered") or rec["label"])


_SCORE_KEYS = ("nll", "es", "nll_minus", "nll_plus", "es_minus", "es_plus")
_PROBE_KEYS = (
    "delta_nll_minus",
    "delta_nll_plus",
    "delta_es_minus",
    "delta_es_plus",
    "srd_nll",
    "srd_es",
)


def diagnosis_record(diag: Diagnosis) -> dict:
    """The flat, JSON-safe record of one Diagnosis; its key order is the CSV column order.

    ``nll``, ``es`` and the ``*_minus``/``*_plus`` scores come from ``diag.scores`` (the
    claimed predictive); ``delta_*`` and ``srd_*`` from ``diag.probes`` (the centred one).
    The scale test's numbers (``scale_*``, ``bias*``) and the dependence estimates
    (``block_length``, ``effective_n``, ``autocorrelation``) follow; ``reason`` says why a
    segment is ``insufficient-data``, or why a question is in ``untested`` ("scale",
    "location": a partial verdict, whose label answers only the other question).
    ``mean_*`` is the GLS mean test of the calibrated rule (``mean_batches`` K of its batch
    means, 0 for Hotelling's test of independent epochs); ``scale_batches`` likewise.
    ``memory_*``: the dependence model the calibrated rule used (fitted on this segment or
    on the ``run`` it is a window of): AR order, τ per principal direction, ν_Ω.
    ``time_scale_*``: the variance of the whitened errors at each averaging time (epochs)
    against the model's prediction and interval, and the check's p-value
    (:class:`credcli.engine.memory.TimeScales`). ``findings``: what the data show beside
    the label (a slowly varying error across the windows of a run, a divergence, bursts,
    a time offset). ``time_offset``: the lag of the estimate behind the truth, in the time
    column's unit, where one explains the misfit (:mod:`credcli.engine.timing`), with
    ``time_offset_stderr``. Accuracy, as evo prints it first (:class:`credcli.engine.metrics.
    Accuracy`): ``rmse`` and ``error_norm_mean``/``_median``/``_max`` of the error's norm;
    per component ``rmse_by_component``, ``error_mean`` (signed), ``error_median`` and
    ``error_max`` (of |e_i|), in the units of the states.

    Parameters
    ----------
    diag : Diagnosis
        The diagnosis of one segment.

    Returns
    -------
    dict
        The record, str -> JSON-safe value (None for NaN, Inf and whatever the diagnosis
        did not compute; enums as their values; vectors as lists of floats).
    """
    elt = diag.elt
    sc = diag.scale
    dirs = diag.directions
    mean = diag.mean_test
    rec = {
        "n": diag.n,
        "dim": diag.dim,
        "label": shown_label(diag.label, diag.untested),
        "label_answered": diag.label,
        "untested": [q.value for q in diag.untested],
        "mean_statistic": None if mean is None else mean.statistic,
        "mean_pvalue": None if mean is None else mean.pvalue,
        "mean_batches": None if mean is None else mean.batches,
        "elt_statistic": diag.elt_statistic,
        "elt_pvalue": diag.elt_pvalue,
        "elt_n_used": None if elt is None else elt.n_used,
        "elt_subsampled": None if elt is None else elt.subsampled,
        "elt_flips_used": None if elt is None else elt.flips_used,
        "smm_detected": diag.smm_detected,
        "nci": diag.nci,
        "nci_centered": diag.nci_centered,
        "anees": diag.anees,
        "ks_pvalue": diag.ks_pvalue,
        "nees_label": diag.nees_label,
        "nci_label": diag.nci_label,
    }
    for source, keys in ((diag.scores, _SCORE_KEYS), (diag.probes, _PROBE_KEYS)):
        rec.update({k: None if source is None else getattr(source, k) for k in keys})
    rec |= {
        "scale_factor": None if sc is None else sc.scale_factor,
        "scale_factor_low": None if sc is None else sc.scale_factor_low,
        "scale_factor_high": None if sc is None else sc.scale_factor_high,
        "scale_factor_bounds": _floats(None if sc is None else sc.equivalence_interval),
        "scale_pvalue": None if sc is None else sc.pvalue,
        "scale_batches": None if sc is None else sc.batches,
        "bias": None if sc is None else _floats(sc.bias),
        "bias_stderr": None if sc is None else _floats(sc.bias_stderr),
        "bias_mahalanobis": None if sc is None else sc.bias_mahalanobis,
        "direction_factors": _floats(None if dirs is None else dirs.factors),
        "direction_factors_low": _floats(None if dirs is None else dirs.low),
        "direction_factors_high": _floats(None if dirs is None else dirs.high),
        "directions": None if dirs is None else [_floats(v) for v in dirs.vectors.T],
        "scale_by_direction": diag.by_direction,
        "sphericity_pvalue": None if dirs is None else dirs.sphericity_pvalue,
        "block_names": [b.name for b in diag.blocks] or None,
        "block_factors": _floats([b.factor for b in diag.blocks] or None),
        "block_factors_low": _floats([b.low for b in diag.blocks] or None),
        "block_factors_high": _floats([b.high for b in diag.blocks] or None),
        "block_length": diag.block_length,
        "effective_n": diag.effective_n,
        "autocorrelation": diag.autocorrelation,
        "reason": diag.reason,
    }
    memory, scales = diag.memory, diag.time_scales
    rec |= {
        "memory_source": diag.memory_source,
        "memory_orders": None if memory is None else [m.order for m in memory.series],
        "memory_fractions": _floats(
            None if memory is None else [m.fraction for m in memory.series]
        ),
        "memory_variance_ratios": _floats(None if memory is None else memory.variance_ratios),
        "memory_dof": None if memory is None else memory.dof,
        "time_scale_epochs": None if scales is None else [int(m) for m in scales.epochs],
        "time_scale_observed": _floats(None if scales is None else scales.observed),
        "time_scale_predicted": _floats(None if scales is None else scales.predicted),
        "time_scale_low": _floats(None if scales is None else scales.low),
        "time_scale_high": _floats(None if scales is None else scales.high),
        "time_scale_pvalue": None if scales is None else scales.pvalue,
        "time_scale_lowest_ratio": None if scales is None else scales.lowest_ratio,
        "time_scale_lowest_pvalue": None if scales is None else scales.lowest_pvalue,
        "findings": list(diag.findings) or None,
        "time_offset": None if diag.time_offset is None else diag.time_offset.seconds,
        "time_offset_stderr": None if diag.time_offset is None else diag.time_offset.stderr,
    }
    rec |= accuracy_record(diag.accuracy)
    for key, value in rec.items():  # most values are None, ints, text or lists already
        if value is not None and value.__class__ not in _JSON_READY:
            rec[key] = json_value(value)
    return rec


_JSON_READY = frozenset({int, str, bool, list})
"""Values a record holds as they are (a float may be NaN, an enum is its value)."""


ACCURACY_KEYS = {
    "rmse": "rmse_norm",
    "error_norm_mean": "mean_norm",
    "error_norm_median": "median_norm",
    "error_norm_max": "max_norm",
    "rmse_by_component": "rmse",
    "error_mean": "mean",
    "error_median": "median",
    "error_max": "max",
}
"""The accuracy keys of a record, each with its :class:`credcli.engine.metrics.Accuracy`
field: a number for the norm's figures, a list (one per component) for the others."""


def accuracy_record(acc) -> dict:
    """The accuracy keys of a segment's record and of a log's entry.

    Parameters
    ----------
    acc : Accuracy or None
        The accuracy (:class:`credcli.engine.metrics.Accuracy`); None: every key null.

    Returns
    -------
    dict
        ``rmse``, ``error_norm_mean``, ``error_norm_median``, ``error_norm_max`` (of the
        error's norm) and ``rmse_by_component``, ``error_mean``, ``error_median``,
        ``error_max`` (lists, one per component), in the units of the states.
    """
    if acc is None:
        return dict.fromkeys(ACCURACY_KEYS)
    return {
        key: value if isinstance(value := getattr(acc, name), float) else _floats(value)
        for key, name in ACCURACY_KEYS.items()
    }


def config_record(config: DiagnosisConfig) -> dict:
    """Every DiagnosisConfig setting as JSON-safe values, by field name.

    Parameters
    ----------
    config : DiagnosisConfig
        The settings of the diagnosis.

    Returns
    -------
    dict
        Field name -> value, through :func:`json_value` (enums as their values).
    """
    return {f.name: json_value(getattr(config, f.name)) for f in dataclasses.fields(config)}


def _settings_record(settings) -> dict:
    """A settings dataclass (LogSchema, ReadOptions) as JSON-safe values: tuples as lists,
    enums as their values."""
    out = {}
    for f in dataclasses.fields(settings):
        value = getattr(settings, f.name)
        out[f.name] = list(value) if isinstance(value, tuple) else getattr(value, "value", value)
    return out


def diagnose_parameters(
    config: DiagnosisConfig,
    seed: int,
    reading: LogReading,
    segmentation: str,
    monte_carlo: bool = False,
) -> dict:
    """The ``parameters`` of a diagnose (and baseline) document.

    :func:`read_baseline` reads them back.

    Parameters
    ----------
    config : DiagnosisConfig
        The settings of the diagnosis: every field, as :func:`config_record` gives it.
    seed : int
        The seed of the run's random numbers.
    reading : LogReading
        How the logs were read and cut: its ``window``, ``whole`` and ``drop_invalid``, its
        column names (``columns``) and its reading options (``input``).
    segmentation : str
        How the logs were cut into segments, as the document names it
        (:func:`credcli.workflows.segmentation_name`).
    monte_carlo : bool, default False
        Whether the logs are Monte Carlo runs pooled segment by segment.

    Returns
    -------
    dict
        The config's fields, then ``seed``, ``segmentation``, ``window``, ``whole``,
        ``drop_invalid``, ``columns`` and ``input`` (the last two objects of their own),
        and ``monte_carlo`` (true) for Monte Carlo runs.
    """
    parameters = config_record(config) | {
        "seed": seed,
        "segmentation": segmentation,
        "window": reading.window,
        "whole": reading.whole,
        "drop_invalid": reading.drop_invalid,
        "columns": _settings_record(reading.schema),
        "input": _settings_record(reading.options),
    }
    if monte_carlo:
        parameters["monte_carlo"] = True
    return parameters


def uwb_segment_record(result: SegmentDiagnosis, check) -> dict:
    """A period of `uwb`: its segment record and the range-level evidence beside it.

    Parameters
    ----------
    result : SegmentDiagnosis
        The period's position-level diagnosis.
    check : RangeCheck
        The range-level evidence of the period (:class:`credcli.studies.uwb.RangeCheck`).

    Returns
    -------
    dict
        :func:`segment_record` of ``result``, then ``range_label`` and ``range_agrees``.
    """
    return segment_record(result) | {"range_label": check.label, "range_agrees": check.agrees}


def range_record(stats) -> dict:
    """The range errors of one anchor in one period.

    Parameters
    ----------
    stats : RangeStats
        The range-level evidence (:class:`credcli.studies.uwb.RangeStats`).

    Returns
    -------
    dict
        Its fields by name, in metres; a NaN standard deviation, standard error or ratio is
        None.
    """
    return {
        "segment": stats.segment,
        "anchor": stats.anchor,
        "n": stats.n,
        "mean_error": stats.mean_error,
        "bias_stderr": json_value(stats.bias_stderr),
        "std_error": json_value(stats.std_error),
        "robust_std": stats.robust_std,
        "median_std": stats.median_std,
        "std_ratio": json_value(stats.std_ratio),
        "robust_ratio": json_value(stats.robust_ratio),
        "beyond_3sigma": stats.beyond_3sigma,
    }


def anchor_record(anchor, mismatch: bool) -> dict:
    """An anchor of `uwb` and whether its markers position disagrees with the log.

    Parameters
    ----------
    anchor : Anchor
        The anchor (:class:`credcli.studies.uwb.Anchor`).
    mismatch : bool
        Whether its markers position disagrees with the log's gt_range.

    Returns
    -------
    dict
        ``id``, its position ``x``, ``y``, ``z`` (m), ``source``, ``rms_mm`` (its RMS in
        mm), ``rows`` and ``check`` ("MISMATCH" or "ok").
    """
    return {
        "id": anchor.id,
        "x": float(anchor.position[0]),
        "y": float(anchor.position[1]),
        "z": float(anchor.position[2]),
        "source": anchor.source,
        "rms_mm": 1000 * anchor.rms,
        "rows": anchor.n,
        "check": "MISMATCH" if mismatch else "ok",
    }


def comparison_record(comparison) -> dict:
    """A segment of `gate`: its status, the labels then and now, why, and both records.

    Parameters
    ----------
    comparison : SegmentComparison
        The segment's baseline against the segment now
        (:class:`credcli.ci.gate.SegmentComparison`).

    Returns
    -------
    dict
        ``segment``, ``status``, ``baseline_label`` and ``label`` (the answered labels, None
        for a new or a missing segment), ``reasons``, ``improvements``, and the segment
        records ``baseline`` and ``current`` (None where there is none).
    """
    old, new = comparison.old, comparison.new
    return {
        "segment": comparison.segment,
        "status": comparison.status.value,
        "baseline_label": None if old is None else old.label.value,
        "label": None if new is None else new.label.value,
        "reasons": list(comparison.reasons),
        "improvements": list(comparison.improvements),
        "baseline": None if old is None else old.record,
        "current": None if new is None else new.record,
    }


def _floats(values) -> list | None:
    return None if values is None else [json_value(float(v)) for v in values]


def segment_record(result: SegmentDiagnosis) -> dict:
    """The record of a segment: where it is, its diagnosis, and the innovations' whiteness.

    Parameters
    ----------
    result : SegmentDiagnosis
        The segment's diagnosis.

    Returns
    -------
    dict
        ``log``, ``segment``, ``t_start`` and ``t_end``, then :func:`diagnosis_record`, then
        for innovations the ``whiteness_*`` keys (:data:`WHITENESS_KEYS`) of their
        whiteness test, None where the segment is too short for one.
    """
    rec = {
        "log": str(result.log),
        "segment": result.segment,
        "t_start": result.t_start,
        "t_end": result.t_end,
    } | diagnosis_record(result.diagnosis)
    white = result.whiteness
    if white is not None:
        values = (white.statistic, white.pvalue, white.lags, white.level, white.rejected)
        rec |= dict(zip(WHITENESS_KEYS, values))
    elif result.innovations:
        rec |= dict.fromkeys(WHITENESS_KEYS)
    return rec


WHITENESS_KEYS = (
    "whiteness_statistic",
    "whiteness_pvalue",
    "whiteness_lags",
    "whiteness_level",
    "whiteness_rejected",
)
"""The keys of the innovations' whiteness test in a segment record (:func:`segment_record`)."""


BATCH_KEYS = frozenset({"segment", "t_start", "t_end", "n", "reason", *ACCURACY_KEYS})
"""The keys whose values may differ between the records of a :class:`RecordBatch`."""


@dataclass(frozen=True, eq=False)
class RecordBatch(Sequence):
    """The records of a run of segments too short for a verdict
    (:class:`credcli.engine.short.ShortSegments`) as one record they share and the columns
    of the keys whose values differ: the segment, its times, its length and reason, its
    accuracy. Item k is :func:`segment_record` of segment k; the renderers write a batch
    from :meth:`columns` a chunk at a time, without a dict per record.

    Attributes
    ----------
    segments : ShortSegments
        The segments.
    shared : dict
        The first segment's record; every record has its keys, in its order, and its
        values but at the keys of :meth:`columns`.
    """

    segments: ShortSegments
    shared: dict = field(init=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "shared", segment_record(self.segments[0]))

    def __len__(self) -> int:
        return len(self.segments)

    def __getitem__(self, k):
        if isinstance(k, slice):
            return [self[i] for i in range(*k.indices(len(self)))]
        return segment_record(self.segments[k])

    def __iter__(self) -> Iterator[dict]:
        return map(self.__getitem__, range(len(self)))

    def columns(self, start: int = 0, stop: int | None = None, keys=BATCH_KEYS) -> dict:
        """The values of records ``start`` to ``stop`` at the keys where they differ.

        Parameters
        ----------
        start, stop : int
            The records (``stop`` None: to the last).
        keys : collection of str
            The keys wanted (by default every key that may differ, :data:`BATCH_KEYS`).

        Returns
        -------
        dict of str to sequence
            Key to each record's value (a list, or a ListColumn for list values), JSON-safe
            as in its record: record k is ``shared | {key: values[k - start]}`` (a key not
            given is shared).
        """
        short = self.segments
        part = slice(start, len(short) if stop is None else stop)
        out: dict[str, list] = {}
        lists = _Lists()
        if "segment" in keys:
            out["segment"] = list(short.names[part])
        if short.t_start is not None and "t_start" in keys:
            out["t_start"] = lists.of(short.t_start[part], False)
        if short.t_end is not None and "t_end" in keys:
            out["t_end"] = lists.of(short.t_end[part], False)
        n = short.n[part]
        if n.size and (n.min() != short.n[0] or n.max() != short.n[0]):
            if "n" in keys:
                out["n"] = n.tolist()
            if "reason" in keys:
                reasons = {v: short.reason(v) for v in np.unique(n).tolist()}
                out["reason"] = [reasons[v] for v in n.tolist()]
        accuracy = short.accuracy
        for key, name in ACCURACY_KEYS.items():
            if key in keys:
                out[key] = lists.of(getattr(accuracy, name)[part], True)
        return out


class _Lists:
    """Arrays as columns of record values: a list of numbers, or for 2-D a
    :class:`~credcli.report.jsontext.ListColumn` (a list per record, held by position); each
    non-finite number None where ``json``, as :func:`json_value` and :func:`_floats` make
    them. Arrays of the same bits give the same column: a one-epoch segment's RMSE, median
    and largest error are its |e|, and a writer that meets one column twice writes its
    numbers once."""

    def __init__(self) -> None:
        self.made: list[tuple[np.ndarray, bool, list]] = []

    def of(self, values: np.ndarray, json: bool):
        bits = values.view(np.uint64)
        for seen, seen_json, made in self.made:
            if seen_json == json and seen.shape == bits.shape and np.array_equal(seen, bits):
                return made
        if values.ndim == 1:
            out = values.tolist()
            if json:
                for k in np.flatnonzero(~np.isfinite(values)).tolist():
                    out[k] = None
        else:  # a list per record, held by position (no list per record)
            out = ListColumn([self.of(values[:, j], json) for j in range(values.shape[1])])
        self.made.append((bits, json, out))
        return out


BLOCK_RECORDS = 1024
"""Consecutive records of a report packed into one :class:`RecordBlock` (the report of
10⁵ segments holds them as columns, not as 10⁵ dicts)."""

_PACKED_KINDS = {"f": float, "i": int, "b": bool}
"""The numpy kinds a column of record values is packed as, with the one Python type every
value (or element of a nested list) must have."""


@dataclass(frozen=True, eq=False)
class _Missing:
    """A packed column with None at some records: ``values`` holds the others (zeros at
    the missing ones)."""

    values: np.ndarray
    missing: np.ndarray

    def tolist(self) -> list:
        out = self.values.tolist()
        for k in np.flatnonzero(self.missing).tolist():
            out[k] = None
        return out

    def item(self, k: int):
        return None if self.missing[k] else self.values[k].tolist()


def _packed(values: list):
    """``values`` as one numpy array when each is a float, each an int (within int64) or
    each a bool, or each a list of such of one shape (nested lists alike): the array's
    ``tolist()`` gives the values back, bit for bit and type for type; such values with
    None at some records as a :class:`_Missing`. Anything else (strings, mixed types,
    ragged lists, None at every record) as it is."""
    present = [v for v in values if v is not None]
    if len(present) < len(values):
        packed = _packed(present) if present else present
        if not isinstance(packed, np.ndarray):
            return values
        missing = np.fromiter((v is None for v in values), bool, len(values))
        full = np.zeros((len(values), *packed.shape[1:]), dtype=packed.dtype)
        full[~missing] = packed
        return _Missing(full, missing)
    try:
        array = np.array(values)
    except (ValueError, OverflowError):  # ragged lists, a too large int
        return values
    kind = _PACKED_KINDS.get(array.dtype.kind)
    if kind is None or (kind is not bool and array.dtype.itemsize != 8):
        return values
    leaves = values
    for _ in range(array.ndim - 1):  # every container a list, every leaf of the one type
        if any(type(v) is not list for v in leaves):
            return values
        leaves = [x for v in leaves for x in v]
    if any(type(v) is not kind for v in leaves):
        return values
    return array


def _column(column) -> list:
    """A column of a :class:`RecordBlock` as the list of its values."""
    return column.tolist() if isinstance(column, (np.ndarray, _Missing)) else column


def _value(column, k: int):
    """Value k of a column of a :class:`RecordBlock`."""
    if isinstance(column, np.ndarray):
        return column[k].tolist()
    return column.item(k) if isinstance(column, _Missing) else column[k]


@dataclass(frozen=True, eq=False)
class RecordBlock(Sequence):
    """Consecutive records with the same keys held as columns: a numpy array per key whose
    values are numbers of one type or lists of them of one shape, None at some records
    allowed (:func:`_packed`), else the list of values. Item k is record k as the dict it
    was made from, equal key for key and value for value; a record's numbers take 8 bytes
    each instead of a float object and a dict slot.

    Attributes
    ----------
    keys : tuple of str
        Every record's keys, in order.
    columns : tuple
        Each key's values: a numpy array, a list, or a numpy array with the records whose
        value is None.
    size : int
        The number of records.
    """

    keys: tuple[str, ...]
    columns: tuple
    size: int

    @classmethod
    def of(cls, records: list[dict]) -> RecordBlock:
        """The block of ``records``, which share their keys in one order.

        Parameters
        ----------
        records : list of dict
            At least one record.

        Returns
        -------
        RecordBlock
            The records as columns.
        """
        keys = tuple(records[0])
        columns = tuple(_packed([r[k] for r in records]) for k in keys)
        return cls(keys, columns, len(records))

    def __len__(self) -> int:
        return self.size

    def __getitem__(self, k):
        if isinstance(k, slice):
            return [self[i] for i in range(*k.indices(len(self)))]
        k = range(self.size)[k]
        return dict(zip(self.keys, (_value(c, k) for c in self.columns), strict=True))

    def __iter__(self) -> Iterator[dict]:
        for values in zip(*map(_column, self.columns), strict=True):
            yield dict(zip(self.keys, values, strict=True))


def record_blocks(records: list[dict]) -> list[RecordBlock]:
    """``records`` as blocks (:class:`RecordBlock`), one per run of consecutive records
    with the same keys in the same order.

    Parameters
    ----------
    records : list of dict
        Records, in order.

    Returns
    -------
    list of RecordBlock
        Their blocks, in order.
    """
    groups = itertools.groupby(records, key=tuple)  # a dict's tuple is its keys, in order
    return [RecordBlock.of(list(group)) for _, group in groups]


class Records(PartSequence):
    """The records of results, in order (:func:`segment_records`): a sequence of dicts, held
    as parts, one dict per SegmentDiagnosis (or a :class:`RecordBlock` of consecutive ones)
    and one :class:`RecordBatch` per run of segments too short for a verdict. Item k is the
    record of result k.

    Parameters
    ----------
    parts : tuple
        Dicts, RecordBlock and RecordBatch, in order.
    """

    RUN = (RecordBatch, RecordBlock)

    def keys(self) -> list[str]:
        """Every key of the records, in the order they first appear.

        Returns
        -------
        list of str
            The keys.
        """
        keys: dict[str, None] = {}
        for part in self.parts:
            if isinstance(part, RecordBatch):
                keys.update(dict.fromkeys(part.shared))
            else:
                keys.update(dict.fromkeys(part.keys if isinstance(part, RecordBlock) else part))
        return list(keys)


def segment_records(results) -> Records:
    """The records of ``results`` in order (:func:`segment_record` of each), a run of
    segments too short for a verdict as one :class:`RecordBatch`.

    Parameters
    ----------
    results : SegmentResults or sequence of SegmentDiagnosis
        The results.

    Returns
    -------
    Records
        Their records.
    """
    parts = results.parts if isinstance(results, SegmentResults) else tuple(results)
    return Records(tuple(_record_part(part) for part in parts))


def _record_part(part):
    """The record of a SegmentDiagnosis, or a run of segments too short for a verdict as
    one :class:`RecordBatch`."""
    return RecordBatch(part) if isinstance(part, ShortSegments) else segment_record(part)


class StreamedRecords:
    """The records of results made as the results arrive and read once: a document written
    while its segments are diagnosed holds a record only until it is written, so that its
    memory does not grow with the number of segments.

    ``parts`` is an iterator of the parts :class:`Records` holds (a dict per
    SegmentDiagnosis, a :class:`RecordBatch` per run of segments too short for a verdict),
    each made when the writer asks for it; a second reading finds none left.

    Parameters
    ----------
    results : SegmentResults or iterable of SegmentDiagnosis and ShortSegments
        The results, in report order: typically a generator that diagnoses them as it is
        read.
    """

    def __init__(self, results) -> None:
        source = results.parts if isinstance(results, SegmentResults) else results
        self.parts: Iterator = map(_record_part, source)

    def keys(self) -> list[str]:
        """The keys of the first record, in order; it is made now and stays first in
        :attr:`parts`. They are every record's keys (:func:`segment_record`: each diagnosis
        has every key, None where it has no value; a log of innovations has the whiteness
        keys in every record).

        Returns
        -------
        list of str
            The keys; none when there are no records.
        """
        first = next(self.parts, None)
        if first is None:
            return []
        self.parts = itertools.chain([first], self.parts)
        return list(first.shared if isinstance(first, RecordBatch) else first)

    def dicts(self) -> Iterator[dict]:
        """Each record as a dict, in order, made as it is read (a run of segments too short
        for a verdict one record at a time): a reader that keeps less than the record
        itself holds no more than that.

        Yields
        ------
        dict
            A segment record (:func:`segment_record`).
        """
        for part in self.parts:
            yield from part if isinstance(part, RecordBatch) else (part,)


def log_record(summary) -> dict:
    """The report's entry for one log: its path, size, dropped rows, notes and accuracy.

    Parameters
    ----------
    summary : LogSummary
        What the report says of the whole log (:class:`credcli.segments.LogSummary`).

    Returns
    -------
    dict
        ``path``, ``epochs``, ``dim``, ``dropped_rows``, ``unpaired_epochs``, ``segments``,
        ``notes``, then :func:`accuracy_record` over all its epochs; JSON-safe.
    """
    info = {
        "path": summary.id.name,
        "epochs": summary.epochs,
        "dim": summary.dim,
        "dropped_rows": summary.dropped_rows,
        "unpaired_epochs": summary.unpaired_epochs,
        "segments": summary.segments,
        "notes": list(summary.notes),
    }
    info |= accuracy_record(summary.accuracy)
    return {k: json_value(v) for k, v in info.items()}


def monte_carlo_record(mc) -> dict:
    """The JSON record of the per-epoch ANEES test.

    Parameters
    ----------
    mc : MonteCarlo
        The test (:class:`credcli.engine.montecarlo.MonteCarlo`).

    Returns
    -------
    dict
        ``runs`` (M), ``dof`` (M·d), ``confidence`` (1 − α), the bounds ``lower`` and
        ``upper``, ``fraction_inside`` (of the epochs), ``mean_anees`` and the fraction
        inside per segment (``segments``).
    """
    return {
        "runs": mc.runs,
        "dof": mc.runs * mc.dim,
        "confidence": 1.0 - mc.level,
        "lower": mc.lower,
        "upper": mc.upper,
        "fraction_inside": float(mc.inside.mean()),
        "mean_anees": float(mc.anees.mean()),
        "segments": mc.segments,
    }


# --- documents: the JSON each command writes -------------------------------------------

SEGMENTS = "segments"
"""The key of a document's list of segment records: the JSON writer streams it a record at
a time (:func:`credcli.report.render.text_pieces`)."""


def diagnose_document(
    parameters: dict,
    logs: list[dict],
    segments: Records | StreamedRecords,
    monte_carlo: dict | None = None,
) -> dict:
    """The JSON document of `credcli diagnose`.

    Parameters
    ----------
    parameters : dict
        The run's settings (:func:`diagnose_parameters`).
    logs : list of dict
        Each log's entry (:func:`log_record`), in order.
    segments : Records or StreamedRecords
        The segments' records (:func:`segment_records`), or their records as a writer reads
        them.
    monte_carlo : dict, optional
        The per-epoch ANEES test (:func:`monte_carlo_record`); None: none.

    Returns
    -------
    dict
        ``version``, ``command`` (``"diagnose"``), ``parameters``, ``logs``, ``segments``
        and, when given, ``monte_carlo``.
    """
    document = {
        "version": __version__,
        "command": "diagnose",
        "parameters": parameters,
        "logs": logs,
        SEGMENTS: segments,
    }
    if monte_carlo is not None:
        document["monte_carlo"] = monte_carlo
    return document


def baseline_document(document: dict) -> dict:
    """A diagnose document marked as a baseline of the current schema version.

    Parameters
    ----------
    document : dict
        The document of `credcli diagnose` (:func:`diagnose_document`); not changed.

    Returns
    -------
    dict
        A copy whose ``command`` is ``"baseline"``, with ``kind`` (:data:`BASELINE_KIND`)
        and ``schema_version`` (:data:`BASELINE_SCHEMA_VERSION`) added: what
        :func:`read_baseline` reads back.
    """
    return {
        **document,
        "command": "baseline",
        "kind": BASELINE_KIND,
        "schema_version": BASELINE_SCHEMA_VERSION,
    }


def document_parameters(document: dict) -> dict:
    """The settings a document was made with.

    Parameters
    ----------
    document : dict
        A command's JSON document.

    Returns
    -------
    dict
        Its ``parameters``; empty where it has none.
    """
    return document.get("parameters", {})


def document_version(document: dict) -> str:
    """The credcli version that wrote a document.

    Parameters
    ----------
    document : dict
        A command's JSON document.

    Returns
    -------
    str
        Its ``version``; "" where it has none.
    """
    return document.get("version", "")


def document_segments(document: dict) -> Sequence:
    """A document's segment records.

    Parameters
    ----------
    document : dict
        A command's JSON document.

    Returns
    -------
    sequence of dict
        Its ``segments`` (:data:`SEGMENTS`); empty where it has none.
    """
    return document.get(SEGMENTS, [])


def log_notes(document: dict) -> Iterator[str]:
    """The decisions taken while reading the logs of a diagnose document.

    Parameters
    ----------
    document : dict
        A command's JSON document.

    Yields
    ------
    str
        The ``notes`` of each entry of its ``logs`` (:func:`log_record`), in order; none
        where it has no logs.
    """
    for log in document.get("logs", []):
        yield from log.get("notes", [])


def simulate_parameters(config, scenarios, curve_runs: int | None = None, sweep=None) -> dict:
    """The ``parameters`` of a `simulate` document.

    Parameters
    ----------
    config : SimulationConfig
        The study's design and its diagnosis settings
        (:class:`credcli.studies.settings.SimulationConfig`).
    scenarios : sequence of Label
        The scenarios run.
    curve_runs : int, optional
        Monte Carlo runs per point of the Fig. 1 curves, when they are the output.
    sweep : str, optional
        The sweep, as given (``rho=0.1:10:20``), when one is the output.

    Returns
    -------
    dict
        ``scenarios``, ``trials``, ``n``, ``dim``, the ranges ``rho_optimism``,
        ``rho_pessimism``, ``bias`` and ``eigenvalues``, ``seed``, ``ar``, ``noise``, every
        DiagnosisConfig field (:func:`config_record`), then ``curve_runs`` and ``sweep``
        where given.
    """
    parameters = {
        "scenarios": [s.value for s in scenarios],
        "trials": config.trials,
        "n": config.n,
        "dim": config.dim,
        "rho_optimism": list(config.rho_optimism),
        "rho_pessimism": list(config.rho_pessimism),
        "bias": list(config.bias),
        "eigenvalues": list(config.eigenvalues),
        "seed": config.seed,
        "ar": config.ar,
        "noise": config.noise,
    } | config_record(config.diagnosis)
    if curve_runs is not None:
        parameters |= {"curve_runs": curve_runs}
    if sweep is not None:
        parameters |= {"sweep": sweep}
    return parameters


def simulate_document(parameters: dict, study, labels) -> dict:
    """The JSON document of the Monte Carlo study (Tables II and III).

    Parameters
    ----------
    parameters : dict
        The study's settings (:func:`simulate_parameters`).
    study : StudyResult
        The study (:func:`credcli.studies.simulate.run_study`).
    labels : sequence of Label
        The diagnosed labels of the confusion matrix, in order.

    Returns
    -------
    dict
        ``version``, ``command``, ``parameters``, ``accuracy`` (method -> scenario ->
        fraction), ``confusion_variant`` and ``confusion`` (true label -> diagnosed label
        -> count).
    """
    return {
        "version": __version__,
        "command": "simulate",
        "parameters": parameters,
        "accuracy": {
            m.value: {s.value: acc[s] for s in study.scenarios} for m, acc in study.accuracy.items()
        },
        "confusion_variant": study.variant.value,
        "confusion": {
            t.value: {lab.value: study.confusion[t][lab] for lab in labels} for t in study.scenarios
        },
    }


def accuracy_row(scenario: str, percents: dict, published: float | None = None) -> dict:
    """A row of Table II: a scenario's accuracy per method, in percent.

    Parameters
    ----------
    scenario : str
        The true label.
    percents : dict of str to float or None
        Method name -> accuracy in percent, in the table's order.
    published : float, optional
        The paper's accuracy in percent; None: the row has no ``published``.

    Returns
    -------
    dict
        ``scenario``, a key per method, then ``published`` when given.
    """
    row = {"scenario": scenario} | percents
    if published is not None:
        row["published"] = published
    return row


def confusion_row(scenario: str, counts: dict) -> dict:
    """A row of Table III: how often each label was diagnosed for one true label.

    Parameters
    ----------
    scenario : str
        The true label.
    counts : dict of str to int
        Diagnosed label -> count, in the table's order.

    Returns
    -------
    dict
        ``scenario``, then a key per diagnosed label.
    """
    return {"scenario": scenario} | counts


def sweep_row(point, percents: dict) -> dict:
    """A row of a sweep: one value of the swept parameter and one true label.

    Parameters
    ----------
    point : SweepPoint
        The point (:class:`credcli.studies.simulate.SweepPoint`).
    percents : dict of str to float or None
        Method name -> accuracy in percent.

    Returns
    -------
    dict
        ``value``, ``scenario``, ``trials``, then a key per method.
    """
    return {"value": point.value, "scenario": point.truth.value, "trials": point.trials} | percents


def sweep_document(parameters: dict, sweep, points) -> dict:
    """The JSON document of ``simulate --sweep``.

    Parameters
    ----------
    parameters : dict
        The study's settings (:func:`simulate_parameters`).
    sweep : Sweep
        The parameter swept and its values (:class:`credcli.studies.simulate.Sweep`).
    points : list of SweepPoint
        The accuracy of every method at each value, per true label.

    Returns
    -------
    dict
        ``version``, ``command``, ``parameters`` and ``sweep``: the ``parameter``, its
        ``values`` and the ``points`` (``value``, ``scenario``, ``trials``, ``accuracy``
        as fractions).
    """
    return {
        "version": __version__,
        "command": "simulate",
        "parameters": parameters,
        "sweep": {
            "parameter": sweep.parameter.value,
            "values": list(sweep.values),
            "points": [
                {
                    "value": p.value,
                    "scenario": p.truth.value,
                    "trials": p.trials,
                    "accuracy": {m.value: a for m, a in p.accuracy.items()},
                }
                for p in points
            ],
        },
    }


def curve_records(points) -> list[dict]:
    """The points of a Fig. 1 curve as records.

    Parameters
    ----------
    points : list of CurvePoint
        The points (:class:`credcli.studies.simulate.CurvePoint`).

    Returns
    -------
    list of dict
        Each point's fields by name.
    """
    return [dataclasses.asdict(p) for p in points]


def curves_document(parameters: dict, by_rho, by_gamma) -> dict:
    """The JSON document of ``simulate --curves``.

    Parameters
    ----------
    parameters : dict
        The study's settings (:func:`simulate_parameters`).
    by_rho, by_gamma : list of CurvePoint
        Fig. 1a (against ρ) and Fig. 1b (against γ).

    Returns
    -------
    dict
        ``version``, ``command``, ``parameters`` and ``curves`` (``rho`` and ``gamma``:
        :func:`curve_records`).
    """
    return {
        "version": __version__,
        "command": "simulate",
        "parameters": parameters,
        "curves": {"rho": curve_records(by_rho), "gamma": curve_records(by_gamma)},
    }


def uwb_parameters(
    config: DiagnosisConfig, seed: int, segmentation: str, settings, anchors
) -> dict:
    """The ``parameters`` of a `uwb` document.

    Parameters
    ----------
    config : DiagnosisConfig
        The diagnosis settings (every field, :func:`config_record`).
    seed : int
        The seed of the run's random numbers.
    segmentation : str
        How the fixes were cut into periods.
    settings : UwbSettings
        The pipeline's settings (:class:`credcli.studies.settings.UwbSettings`), every
        field by name.
    anchors : path or None
        The anchors file; None: the anchors were self-calibrated.

    Returns
    -------
    dict
        The config's fields, ``seed``, ``segmentation``, the pipeline's settings and
        ``anchors``.
    """
    return (
        config_record(config)
        | {"seed": seed, "segmentation": segmentation}
        | {f.name: getattr(settings, f.name) for f in dataclasses.fields(settings)}
        | {"anchors": str(anchors) if anchors else "self-calibrated"}
    )


def uwb_document(parameters: dict, segments, anchors, ranges, run, notes) -> dict:
    """The JSON document of `credcli uwb`.

    Parameters
    ----------
    parameters : dict
        The diagnosis and pipeline settings (:func:`uwb_parameters`).
    segments : list of dict
        Each period's record (:func:`uwb_segment_record`).
    anchors : list of dict
        Each anchor's record (:func:`anchor_record`).
    ranges : list of dict
        The range errors per period and anchor (:func:`range_record`).
    run : UwbRun
        The pipeline's run (:class:`credcli.studies.uwb.UwbRun`): its packets and fixes.
    notes : list of str
        The report's notes.

    Returns
    -------
    dict
        ``version``, ``command``, ``parameters``, ``segments``, ``anchors``, ``ranges``,
        ``screening`` (packets, fixes, what was dropped and moved, the residual scale) and
        ``notes``.
    """
    return {
        "version": __version__,
        "command": "uwb",
        "parameters": parameters,
        SEGMENTS: segments,
        "anchors": anchors,
        "ranges": ranges,
        "screening": {
            "packets": run.packets,
            "fixes": int(run.fixes.time.size),
            "dropped": run.fixes.dropped,
            "moved_to_global_minimum": run.fixes.moved,
            "residual_scale": run.fixes.residual_scale,
        },
        "notes": notes,
    }


def gate_row(
    segment: str, status: str, labels: str, nci: str, anees: str, elt: str, why: str
) -> dict:
    """A row of the gate's table: one segment then and now, as text.

    Parameters
    ----------
    segment : str
        The segment's name.
    status : str
        What became of it (unchanged, improved, regressed, new, missing).
    labels, nci, anees, elt : str
        Its label, NCI, ANEES and ELT p-value as "baseline → now".
    why : str
        Why it changed.

    Returns
    -------
    dict
        The row, by the keys of :data:`GATE_COLUMNS`.
    """
    return {
        "segment": segment,
        "status": status,
        "labels": labels,
        "nci": nci,
        "anees": anees,
        "elt": elt,
        "why": why,
    }


def gate_document(
    baseline: str, parameters: dict, passed: bool, verdict: str, segments: list[dict]
) -> dict:
    """The JSON document of `credcli gate`.

    Parameters
    ----------
    baseline : str
        The baseline file's path, as given.
    parameters : dict
        The new diagnosis's settings.
    passed : bool
        Whether no segment fails the gate.
    verdict : str
        The verdict line.
    segments : list of dict
        Each segment compared (:func:`comparison_record`).

    Returns
    -------
    dict
        ``version``, ``command``, ``baseline``, ``parameters``, ``passed``, ``verdict``
        and ``segments``.
    """
    return {
        "version": __version__,
        "command": "gate",
        "baseline": baseline,
        "parameters": parameters,
        "passed": passed,
        "verdict": verdict,
        SEGMENTS: segments,
    }


def compared_log_row(entry: dict, credible: str) -> dict:
    """A row of the logs compared side by side.

    Parameters
    ----------
    entry : dict
        The log's entry (:func:`log_record`).
    credible : str
        How many of its segments are credible ("3 of 5").

    Returns
    -------
    dict
        ``entry`` with ``credible``.
    """
    return entry | {"credible": credible}


# --- columns: which key each table shows, and how --------------------------------------


def _label_text(rec: dict) -> str:
    """The label as tables show it: the record's ``label``, already the shown label
    (:func:`shown_label`)."""
    return str(rec["label"])


def scale_interval(rec: dict) -> str | None:
    """The ``cov ×`` cell of a segment record: κ̂ with its interval.

    Parameters
    ----------
    rec : dict
        A segment record ([segment_record][credcli.report.records.segment_record]).

    Returns
    -------
    str or None
        '2.3 (1.9–2.8)'; '2.3 (no interval)' where the data hold too few batches for one
        (the segment's reason says why); None when no scale was estimated.
    """
    if rec.get("scale_factor") is None:
        return None
    return format_interval(
        rec["scale_factor"], rec.get("scale_factor_low"), rec.get("scale_factor_high")
    )


NAME_LIMIT = 60
"""Longest segment or log name shown in a table cell (JSON and CSV keep the whole name)."""

SEGMENT_COLUMNS = (
    Column("segment", "segment", 0, limit=NAME_LIMIT, rank=0),
    Column("n", "N", 0, keep=True, rank=0),
    Column("dim", "d", 0, keep=True, rank=0),
    Column("label", "label", 0, keep=True, rank=0, show=_label_text, coloured=True),
    Column("scale_factor", "cov × (interval)", 0, show=scale_interval, rank=1),
    Column("scale_pvalue", "scale p", 3, pvalue=True, rank=3),
    Column("elt_pvalue", "ELT p", 3, pvalue=True, rank=2),
    Column("bias_mahalanobis", "|bias| [σ]", 3, rank=3),
    Column("rmse", "RMSE", 4, rank=4),
    Column("block_length", "L", 0, rank=4),
    Column("nci", "NCI [dB]", 3, rank=5),
    Column("anees", "ANEES", 4, rank=5),
    Column("nees_label", "NEES baseline", 0, rank=6, coloured=True),
    Column("nci_label", "NCI baseline", 0, rank=6, coloured=True),
)

SEGMENT_COLUMNS_ALL = SEGMENT_COLUMNS + (
    Column("nci_centered", "NCI centred", 3),
    Column("nll", "NLL", 4),
    Column("es", "ES", 4),
    Column("delta_nll_minus", "ΔNLL−", 3),
    Column("delta_nll_plus", "ΔNLL+", 3),
    Column("delta_es_minus", "ΔES−", 3),
    Column("delta_es_plus", "ΔES+", 3),
    Column("srd_nll", "SRD NLL", 3),
    Column("srd_es", "SRD ES", 3),
)


WHITENESS_COLUMN = Column("whiteness_pvalue", "white p", 3, pvalue=True, rank=2)
"""The innovations' portmanteau p-value (--innovations), after the ELT's."""

LOG_NAME_COLUMN = Column("log", "log", 0, limit=NAME_LIMIT)
"""The log of each segment, first, when a report holds several logs."""

LOG_COLUMNS = (
    Column("path", "log", 0, limit=NAME_LIMIT, rank=0),
    Column("epochs", "N", 0, keep=True, rank=0),
    Column("credible", "credible", 0, keep=True, rank=0),
    Column("rmse", "RMSE", 4, rank=1),
    Column("error_norm_mean", "mean ‖e‖", 4, rank=2),
    Column("error_norm_median", "median ‖e‖", 4, rank=2),
    Column("error_norm_max", "max ‖e‖", 4, rank=2),
)
"""The logs side by side (as evo_res compares results): accuracy over all epochs of each
log, and how many of its segments are credible (:func:`compared_log_row`)."""

_METHOD_HEADERS = {
    "calibrated": "calibrated [%]",
    "ks": "ks [%]",
    "paper": "paper rule [%]",
    "nees": "NEES [%]",
    "nci": "NCI [%]",
}

_SHORT = {
    Label.CREDIBLE.value: "Credible",
    Label.OPTIMISM.value: "O",
    Label.PESSIMISM.value: "P",
    Label.SMM.value: "SMM",
    Label.OPTIMISM_SMM.value: "O+SMM",
    Label.PESSIMISM_SMM.value: "P+SMM",
    Label.INSUFFICIENT.value: "insuff.",
}


def _method_columns(methods) -> tuple[Column, ...]:
    return tuple(Column(m.value, _METHOD_HEADERS[m.value], 3) for m in methods)


def accuracy_columns(methods, published: bool) -> tuple[Column, ...]:
    """The columns of Table II (:func:`accuracy_row`).

    Parameters
    ----------
    methods : iterable of Method
        The methods, in order.
    published : bool
        Whether the rows have the paper's accuracy.

    Returns
    -------
    tuple of Column
        The scenario, each method's accuracy in percent, then the published one.
    """
    cols = (Column("scenario", "scenario", 0),) + _method_columns(methods)
    if published:
        cols += (Column("published", "published [%]", 3),)
    return cols


def confusion_columns(labels) -> tuple[Column, ...]:
    """The columns of Table III (:func:`confusion_row`).

    Parameters
    ----------
    labels : iterable of Label
        The diagnosed labels, in order.

    Returns
    -------
    tuple of Column
        The true label, then a count per diagnosed label (headed by its short name).
    """
    return (Column("scenario", "true \\ diagnosed", 0),) + tuple(
        Column(lab.value, _SHORT[lab.value], 0) for lab in labels
    )


def sweep_columns(parameter: str, methods) -> tuple[Column, ...]:
    """The columns of a sweep's table (:func:`sweep_row`).

    Parameters
    ----------
    parameter : str
        The swept parameter's name (the first column's heading).
    methods : iterable of Method
        The methods, in order.

    Returns
    -------
    tuple of Column
        The value, the true label, the trials, then each method's accuracy in percent.
    """
    return (
        Column("value", parameter, 4),
        Column("scenario", "true label", 0),
        Column("trials", "trials", 0),
    ) + _method_columns(methods)


def _curve_columns(x: str) -> tuple[Column, ...]:
    return (
        Column(x, "ρ" if x == "rho" else "γ", 4),
        Column("mean_es", "mean ES", 5),
        Column("expected_es", "E[ES] exact", 5),
        Column("mean_nll", "mean NLL", 5),
        Column("expected_nll", "E[NLL] exact", 5),
    )


CURVE_COLUMNS_RHO = _curve_columns("rho")
"""The columns of Fig. 1a (:func:`curve_records` against ρ)."""
CURVE_COLUMNS_GAMMA = _curve_columns("gamma")
"""The columns of Fig. 1b (:func:`curve_records` against γ)."""

UWB_COLUMNS = (
    Column("segment", "period", 0, limit=NAME_LIMIT, rank=0),
    Column("t_start", "t start [s]", 4, rank=3),
    Column("t_end", "t end [s]", 4, rank=3),
    Column("n", "fixes", 0, keep=True, rank=0),
    Column("label", "label", 0, keep=True, rank=0, show=_label_text, coloured=True),
    Column("scale_factor", "cov × (interval)", 0, show=scale_interval, rank=1),
    Column("elt_pvalue", "ELT p", 3, pvalue=True, rank=2),
    Column("bias_mahalanobis", "|bias| [σ]", 3, rank=3),
    Column("rmse", "RMSE", 4, rank=4),
    Column("range_label", "range evidence", 0, rank=1),
    Column("range_agrees", "agrees", 0, rank=1),
    Column("nees_label", "NEES", 0, rank=5, coloured=True),
    Column("nci_label", "NCI", 0, rank=5, coloured=True),
    Column("nci", "NCI [dB]", 3, rank=6),
    Column("anees", "ANEES", 4, rank=6),
)
"""Table IV of `uwb`: a period's diagnosis with the range-level evidence beside it
(:func:`uwb_segment_record`)."""

RANGE_COLUMNS = (
    Column("segment", "period", 0),
    Column("anchor", "anchor", 0),
    Column("n", "ranges", 0),
    Column("mean_error", "bias [m]", 3),
    Column("bias_stderr", "± s.e. [m]", 2),
    Column("std_error", "std [m]", 3),
    Column("robust_std", "robust std [m]", 3),
    Column("median_std", "reported std [m]", 3),
    Column("robust_ratio", "robust / reported", 3),
    Column("beyond_3sigma", "beyond 3σ", 2),
)
"""The range errors of `uwb` per period and anchor (:func:`range_record`)."""

ANCHOR_COLUMNS = (
    Column("id", "anchor", 0),
    Column("x", "x [m]", 4),
    Column("y", "y [m]", 4),
    Column("z", "z [m]", 4),
    Column("source", "source", 0),
    Column("rms_mm", "gt_range RMS [mm]", 3),
    Column("check", "check", 0),
    Column("rows", "ranges", 0),
)
"""The anchors of `uwb` (:func:`anchor_record`)."""

GATE_COLUMNS = (
    Column("segment", "segment", 0, limit=NAME_LIMIT),
    Column("status", "status", 0, coloured=True),
    Column("labels", "label (baseline → now)", 0),
    Column("nci", "NCI [dB]", 0),
    Column("anees", "ANEES", 0),
    Column("elt", "ELT p", 0),
    Column("why", "why", 0, wrap=60),
)
"""The gate's table (:func:`gate_row`)."""


# --- a baseline read back: typed values for the gate -----------------------------------


@dataclass(frozen=True)
class Snapshot:
    """What the gate compares of one segment, typed.

    Attributes
    ----------
    segment : str
        The segment's name.
    label : Label
        Its answered label.
    nci, anees, elt_pvalue : float or None
        Its NCI, ANEES and ELT p-value (None where not computed).
    record : dict
        The whole segment record, kept only to be reported (not compared, not shown in the
        repr).
    untested : tuple of str
        The questions its verdict leaves open ("scale", "location").
    dim : int or None
        The state dimension d of its errors (None in a record that does not say).
    """

    segment: str
    label: Label
    nci: float | None
    anees: float | None
    elt_pvalue: float | None
    record: dict = field(repr=False, compare=False, default_factory=dict)
    untested: tuple[str, ...] = ()
    dim: int | None = None

    @classmethod
    def from_record(cls, rec: dict) -> Snapshot:
        """The snapshot of a segment record: a baseline's, or one made now.

        Parameters
        ----------
        rec : dict
            The segment record: a baseline's, as checked by :func:`read_baseline`, or
            :func:`segment_record` of a segment diagnosed now.

        Returns
        -------
        Snapshot
            Its name, answered label, NCI, ANEES and ELT p-value, the record itself, its
            ``untested`` questions (a baseline written before partial verdicts has no
            ``untested``: nothing was) and its dimension.
        """
        return cls(
            rec["segment"],
            record_label(rec),
            rec.get("nci"),
            rec.get("anees"),
            rec.get("elt_pvalue"),
            rec,
            tuple(rec.get("untested") or ()),
            rec.get("dim") if type(rec.get("dim")) is int else None,
        )


def _check_baseline(doc: dict, source: str) -> None:
    """Refuse a file that is not a credcli baseline of a known schema version."""
    if not isinstance(doc, dict) or doc.get("kind") != BASELINE_KIND:
        raise CredcliError(
            f"{source}: not a credcli baseline (make one with `credcli baseline LOG -o FILE`)"
        )
    version = doc.get("schema_version")
    if type(version) is not int or version != BASELINE_SCHEMA_VERSION:  # 1.0 is not 1
        raise CredcliError(
            f"{source}: baseline schema version {version!r} is not supported (this credcli reads "
            f"version {BASELINE_SCHEMA_VERSION}); record the baseline again with this version"
        )
    for key in ("parameters", "segments"):
        if key not in doc:
            raise CredcliError(f"{source}: baseline has no '{key}'; record it again")
    if not isinstance(doc["parameters"], dict) or not isinstance(doc["segments"], list):
        raise CredcliError(
            f"{source}: baseline 'parameters' must be an object and 'segments' a list; "
            "record it again"
        )
    labels = {lab.value for lab in Label}
    questions = [q.value for q in Question]
    for k, rec in enumerate(doc["segments"], start=1):
        where = f"{source}: segment {k}"
        if not isinstance(rec, dict) or not isinstance(rec.get("segment"), str):
            raise CredcliError(f"{where}: needs a 'segment' name (a string); record it again")
        where = f"{source}: segment '{rec['segment']}'"
        label = rec.get("label")
        answered = rec.get("label_answered", label)
        untested = rec.get("untested") or []
        if (
            not isinstance(label, str)
            or not isinstance(answered, str)
            or answered not in labels
            or not isinstance(untested, list)
            or label not in (shown_label(Label(answered), [str(q) for q in untested]), answered)
        ):  # a baseline written before partial labels were shown has the bare label
            got = "no label" if "label" not in rec else f"label {rec['label']!r}"
            raise CredcliError(
                f"{where}: {got}; a label is one of {', '.join(sorted(labels))}, with its "
                "untested questions in brackets, and agrees with 'label_answered'"
            )
        if not all(isinstance(q, str) and q in questions for q in untested):
            raise CredcliError(
                f"{where}: 'untested' lists questions, each one of {', '.join(questions)}; "
                f"got {shortened(repr(untested))}; record it again"
            )
        for key in ("nci", "anees", "elt_pvalue"):
            value = rec.get(key)
            if value is not None and not is_number(value):
                raise CredcliError(
                    f"{where}: '{key}' must be a number or null; got {shortened(repr(value))}"
                )
        for key in ("anees", "elt_pvalue"):  # a mean of squares, and a probability
            value = rec.get(key)
            if value is not None and not value >= 0:
                raise CredcliError(f"{where}: '{key}' must be >= 0 or null; got {value!r}")


SEGMENTATION_SETTINGS = ("seed", "window", "whole", "drop_invalid")
"""A baseline's settings beside its DiagnosisConfig fields."""


@dataclass(frozen=True)
class Baseline:
    """A baseline file (``credcli baseline``), read and checked once: the settings it was
    made with, typed, and its segments as :class:`Snapshot`.

    Attributes
    ----------
    source : str
        The file's path, as given.
    config : DiagnosisConfig
        The diagnosis settings the baseline was made with.
    seed : int
        The seed it was made with.
    reading : LogReading
        How its logs were read and cut into segments.
    segments : tuple of Snapshot
        Its segments, in the file's order.
    """

    source: str
    config: DiagnosisConfig
    seed: int
    reading: LogReading
    segments: tuple[Snapshot, ...]

    def setting(self, name: str):
        """A setting as the baseline was made with it.

        Parameters
        ----------
        name : str
            A DiagnosisConfig field, or ``seed``, ``window``, ``whole`` or
            ``drop_invalid``.

        Returns
        -------
        object
            The setting's value.
        """
        if name == "seed":
            return self.seed
        if name in SEGMENTATION_SETTINGS:
            return getattr(self.reading, name)
        return getattr(self.config, name)


def read_baseline(path: str | Path) -> Baseline:
    """Read a baseline JSON file and check every key it must have.

    Parameters
    ----------
    path : str or pathlib.Path
        The baseline file (``credcli baseline LOG -o FILE``).

    Returns
    -------
    Baseline
        Its settings, typed, and its segments.

    Raises
    ------
    CredcliError
        The file is missing, a directory, unreadable, not JSON (NaN and Infinity included)
        or not a credcli baseline; its schema version is not
        :data:`BASELINE_SCHEMA_VERSION`; ``parameters`` or ``segments`` are missing or of
        the wrong type; a segment has no name, a label that is not one of the labels, or an
        NCI, ANEES or ELT p-value that is not a number or null; a parameter is missing or
        of the wrong type, or the seed is negative. Each message names the file; one about
        the baseline's content says to record it again.
    """

    def non_finite(word: str):
        raise ValueError(f"'{word}' is not a number JSON allows")

    try:
        with open_input(path) as fh:
            doc = json.loads(fh.read().decode("utf-8"), parse_constant=non_finite)
    except CredcliError:
        raise  # a FIFO with no writer (open_input): its own message
    except FileNotFoundError as exc:
        raise CredcliError(f"{path}: baseline file not found") from exc
    except IsADirectoryError as exc:
        raise CredcliError(f"{path}: is a directory, expected a baseline JSON file") from exc
    except OSError as exc:
        raise CredcliError(f"{path}: cannot be read ({exc.strerror})") from exc
    except (ValueError, UnicodeDecodeError) as exc:  # JSONDecodeError is a ValueError
        raise CredcliError(f"{path}: not valid JSON ({exc})") from exc
    except RecursionError as exc:
        raise CredcliError(
            f"{path}: nested too deeply to be a credcli baseline; record it again"
        ) from exc
    _check_baseline(doc, str(path))
    params = doc["parameters"]
    fields = {f.name for f in dataclasses.fields(DiagnosisConfig)}
    try:
        hints = diagnosis_hints() | SEGMENT_HINTS | {"window": str | None, "drop_invalid": bool}
        check_types(params, hints, "baseline parameters")
        if not isinstance(params.get("columns"), dict):
            raise CredcliError("baseline parameters: 'columns' must be an object")
        check_types(params["columns"], typing.get_type_hints(LogSchema), "baseline columns")
        if params["seed"] < 0:
            raise CredcliError("baseline parameters: seed must be >= 0")
        config = DiagnosisConfig(**{k: v for k, v in params.items() if k in fields})
        schema = LogSchema().updated(**params["columns"])
        recorded = params.get("input", {})  # baselines before 0.2 have none
        if not isinstance(recorded, dict):
            raise CredcliError("baseline parameters: 'input' must be an object")
        check_types(recorded, typing.get_type_hints(ReadOptions), "baseline input")
        reading = LogReading(
            schema,
            ReadOptions(**recorded),
            params["drop_invalid"],
            params["window"],
            params["whole"],
        )
        seed = params["seed"]
    except CredcliError as exc:
        raise CredcliError(f"{path}: {plain(exc.message)}; record the baseline again") from exc
    except (KeyError, TypeError, ValueError) as exc:
        raise CredcliError(
            f"{path}: baseline parameters are incomplete ({exc}); record it again"
        ) from exc
    segments = tuple(Snapshot.from_record(r) for r in doc["segments"])
    if not segments:  # nothing a log could be compared with
        raise CredcliError(f"{path}: the baseline holds no segments; record it again from a log")
    return Baseline(str(path), config, seed, reading, segments)
