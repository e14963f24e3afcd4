"""Records: a Diagnosis as a flat, JSON-safe dict. The only place that knows the keys of a
segment record; the renderers, the CI gate and the Python API's ``to_dict``/``to_frame``
all read them from here."""

from __future__ import annotations

import enum
import math

from credcli.engine.diagnosis import Diagnosis, SegmentDiagnosis


def json_value(x):
    """JSON-safe scalar: enums to their value, NaN/Inf to None."""
    if x is None:
        return None
    if type(x) is float:  # the common case first: a record has dozens (10⁶ segments)
        return x if math.isfinite(x) else None
    if isinstance(x, enum.Enum):
        return x.value
    if isinstance(x, float) and not math.isfinite(x):
        return None
    return x


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
    means, 0 for the exact F test of independent epochs); ``scale_batches`` likewise.
    """
    elt = diag.elt
    sc = diag.scale
    dirs = diag.directions
    mean = diag.mean_test
    rec = {
        "n": diag.n,
        "dim": diag.dim,
        "label": diag.label,
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
        "cov_scale": diag.cov_scale,
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
        "bias": None if sc is None else [float(v) for v in sc.bias],
        "bias_stderr": None if sc is None else [float(v) for v in sc.bias_stderr],
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
    return {k: json_value(v) for k, v in rec.items()}


def _floats(values) -> list | None:
    return None if values is None else [json_value(float(v)) for v in values]


def segment_record(result: SegmentDiagnosis) -> dict:
    """The record of a segment: where it is, then :func:`diagnosis_record`, then the
    innovations' whiteness test when there is one."""
    rec = {
        "log": result.log,
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
        }
    return rec


def log_info(log, segments) -> dict:
    """The report's entry for one log."""
    return {
        "path": log.source,
        "epochs": log.n,
        "dim": log.dim,
        "dropped_rows": log.dropped_rows,
        "unpaired_epochs": log.unpaired,
        "segments": len(segments),
        "notes": list(log.notes),
    }


def monte_carlo_record(mc) -> dict:
    """The JSON record of the per-epoch ANEES test (:class:`credcli.engine.montecarlo.MonteCarlo`)."""
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
