"""Records: a Diagnosis as a flat, JSON-safe dict, and a baseline file read back into
typed values. The only place that knows the keys of a segment record and of a baseline;
the renderers, the CI gate and the Python API's ``to_dict``/``to_frame`` all read them
from here."""

from __future__ import annotations

import dataclasses
import enum
import json
import math
import typing
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from credcli.engine.config import DiagnosisConfig
from credcli.engine.diagnosis import Diagnosis, Label, SegmentDiagnosis
from credcli.engine.short import PartSequence, SegmentResults, ShortSegments
from credcli.errors import CredcliError, plain
from credcli.io.checks import SEGMENT_HINTS, check_types, diagnosis_hints
from credcli.io.schema import LogReading, LogSchema, ReadOptions
from credcli.io.streams import open_input
from credcli.report.jsontext import ListColumn

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
    config: DiagnosisConfig, seed: int, reading: LogReading, segmentation: str
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

    Returns
    -------
    dict
        The config's fields, then ``seed``, ``segmentation``, ``window``, ``whole``,
        ``drop_invalid``, ``columns`` and ``input`` (the last two objects of their own).
    """
    return config_record(config) | {
        "seed": seed,
        "segmentation": segmentation,
        "window": reading.window,
        "whole": reading.whole,
        "drop_invalid": reading.drop_invalid,
        "columns": _settings_record(reading.schema),
        "input": _settings_record(reading.options),
    }


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
        the ``whiteness_*`` keys of the innovations' whiteness test when there is one.
    """
    rec = {
        "log": str(result.log),
        "segment": result.segment,
        "t_start": result.t_start,
        "t_end": result.t_end,
    } | diagnosis_record(result.diagnosis)
    white = result.whiteness
    if white is not None:
        rec |= {
            "whiteness_statistic": white.statistic,
            "whiteness_pvalue": white.pvalue,
            "whiteness_lags": white.lags,
            "whiteness_level": white.level,
            "whiteness_rejected": white.rejected,
        }
    return rec


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


class Records(PartSequence):
    """The records of results, in order (:func:`segment_records`): a sequence of dicts, held
    as parts, one dict per SegmentDiagnosis and one :class:`RecordBatch` per run of segments
    too short for a verdict. Item k is the record of result k.

    Parameters
    ----------
    parts : tuple
        Dicts and RecordBatch, in order.
    """

    RUN = RecordBatch

    def keys(self) -> list[str]:
        """Every key of the records, in the order they first appear.

        Returns
        -------
        list of str
            The keys.
        """
        keys: dict[str, None] = {}
        for part in self.parts:
            keys.update(dict.fromkeys(part.shared if isinstance(part, RecordBatch) else part))
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
    return Records(
        tuple(
            RecordBatch(part) if isinstance(part, ShortSegments) else segment_record(part)
            for part in parts
        )
    )


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
    """

    segment: str
    label: Label
    nci: float | None
    anees: float | None
    elt_pvalue: float | None
    record: dict = field(repr=False, compare=False, default_factory=dict)
    untested: tuple[str, ...] = ()

    @classmethod
    def from_record(cls, rec: dict) -> Snapshot:
        """The snapshot of a baseline's segment record.

        Parameters
        ----------
        rec : dict
            The segment record, as checked by :func:`read_baseline`.

        Returns
        -------
        Snapshot
            Its name, answered label, NCI, ANEES and ELT p-value, the record itself, and its
            ``untested`` questions (a baseline written before partial verdicts has no
            ``untested``: nothing was).
        """
        return cls(
            rec["segment"],
            record_label(rec),
            rec.get("nci"),
            rec.get("anees"),
            rec.get("elt_pvalue"),
            rec,
            tuple(rec.get("untested") or ()),
        )

    @classmethod
    def from_result(cls, result: SegmentDiagnosis) -> Snapshot:
        """The snapshot of a segment diagnosed now.

        Parameters
        ----------
        result : SegmentDiagnosis
            The segment's diagnosis.

        Returns
        -------
        Snapshot
            Its name, label, NCI, ANEES, ELT p-value, :func:`segment_record` and its
            ``untested`` questions.
        """
        d = result.diagnosis
        untested = tuple(q.value for q in d.untested)
        return cls(
            result.segment, d.label, d.nci, d.anees, d.elt_pvalue, segment_record(result), untested
        )


def _check_baseline(doc: dict, source: str) -> None:
    """Refuse a file that is not a credcli baseline of a known schema version."""
    if not isinstance(doc, dict) or doc.get("kind") != BASELINE_KIND:
        raise CredcliError(
            f"{source}: not a credcli baseline (make one with `credcli baseline LOG -o FILE`)"
        )
    version = doc.get("schema_version")
    if version != BASELINE_SCHEMA_VERSION:
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
        for key in ("nci", "anees", "elt_pvalue"):
            value = rec.get(key)
            if value is not None and (
                isinstance(value, bool) or not isinstance(value, (int, float))
            ):
                raise CredcliError(f"{where}: '{key}' must be a number or null; got {value!r}")


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
    return Baseline(str(path), config, seed, reading, segments)
