"""What a diagnosis tells its user, in words: the advice line of a segment that is not
credible (the covariance factor, per direction or block; the bias and the component to look
at first; a time offset to fix first), the scale with its interval, and what each location
condition means. Read from the typed Diagnosis, never from a record."""

from __future__ import annotations

import math

from credcli.engine.config import SMM_CONDITION, Label
from credcli.engine.diagnosis import SegmentDiagnosis
from credcli.report.formats import format_interval, format_number, format_pvalue

NOISE_CONDITIONS = frozenset({Label.OPTIMISM.value, Label.PESSIMISM.value})
"""The conditions of a label that a covariance factor answers."""


def _finite(x) -> float | None:
    """A number as the records give it: None when it is missing, NaN or infinite."""
    return None if x is None or not math.isfinite(x) else float(x)


def _finites(values) -> list[float | None]:
    return [_finite(float(v)) for v in values]


def scale_text(diag) -> str | None:
    """κ̂ with its interval, as the ``cov ×`` cell shows it, from a Diagnosis.

    Parameters
    ----------
    diag : Diagnosis
        A segment's diagnosis.

    Returns
    -------
    str or None
        '2.3 (1.9–2.8)', '2.3 (no interval)', or None when no finite κ̂ was estimated.
    """
    sc = diag.scale
    factor = None if sc is None else _finite(sc.scale_factor)
    if factor is None:
        return None
    return format_interval(factor, _finite(sc.scale_factor_low), _finite(sc.scale_factor_high))


def bias_size(diag) -> float | None:
    """The GLS mean's size in standard deviations (``|bias| [σ]``), or None.

    Parameters
    ----------
    diag : Diagnosis
        A segment's diagnosis.

    Returns
    -------
    float or None
        √(μ̂ᵀ W̄ μ̂) of the scale test; None when there is none or it is not finite.
    """
    return None if diag.scale is None else _finite(diag.scale.bias_mahalanobis)


def advice(item: SegmentDiagnosis) -> str | None:
    """What a user acts on for a segment that is not credible, in one line.

    Parameters
    ----------
    item : SegmentDiagnosis
        A diagnosed segment.

    Returns
    -------
    str or None
        "segment: what to do": the covariance factor (per direction or block where they
        differ), the bias and the component to look at first, a time offset to fix first,
        or why there is no verdict; None for a credible segment with both questions
        answered.
    """
    diag = item.diagnosis
    label, untested = diag.label, [q.value for q in diag.untested]
    if label is Label.CREDIBLE and not untested:
        return None
    if label is Label.INSUFFICIENT:
        return f"{item.segment}: no verdict: {diag.reason}"
    noise = bool(label.conditions & NOISE_CONDITIONS)
    sc = diag.scale
    parts = []
    offset = None if diag.time_offset is None else _finite(diag.time_offset.seconds)
    if offset is not None:  # the cause to fix first
        which = "lags" if offset > 0 else "leads"
        parts.append(
            f"the estimate {which} the truth by {format_number(abs(offset))} s: fix the "
            "time stamps before the covariance"
        )
    if untested:
        parts.append(f"{' and '.join(untested)} untested: {diag.reason}")
    if diag.by_direction:
        parts.append(direction_advice(diag))
    elif noise:
        parts.append(f"multiply the covariance by {scale_text(diag)}")
    if diag.blocks and noise:
        parts.append(block_advice(diag))
    location = label.location
    if location in ("bias", SMM_CONDITION):
        bias = ", ".join(format_number(b) for b in _finites(sc.bias))
        parts.append(f"bias ({bias}) in the log's units, {format_number(bias_size(diag))} σ")
        parts.append(_smm_hint(diag))
    elif location == "asymmetric":
        mean = diag.mean_test
        parts.append(
            f"errors not symmetric about zero (ELT p {format_pvalue(_finite(diag.elt_pvalue))}) "
            f"with no mean found (mean test p "
            f"{format_pvalue(None if mean is None else _finite(mean.pvalue))}; "
            f"mean {format_number(bias_size(diag))} σ)"
        )
    return f"{item.segment}: " + "; ".join(p for p in parts if p)


def _factors(factors, low, high) -> list[str]:
    """Each factor with its interval, "f (low–high)"."""
    return [
        f"{format_number(f)} ({format_number(lo)}–{format_number(hi)})"
        for f, lo, hi in zip(_finites(factors), _finites(low), _finites(high))
    ]


def direction_advice(diag) -> str:
    """The matrix correction of a scale decided along principal directions.

    Parameters
    ----------
    diag : Diagnosis
        A diagnosis whose noise label comes from its directions (``by_direction``).

    Returns
    -------
    str
        The factor (interval) along each direction of the whitened errors, for Σ̂_k to
        become L_k Ŝ L_kᵀ.
    """
    dirs = diag.directions
    parts = [
        f"{factor} along ({', '.join(format_number(c) for c in _finites(v))})"
        for factor, v in zip(_factors(dirs.factors, dirs.low, dirs.high), dirs.vectors.T)
    ]
    return (
        "the misfit differs between directions; multiply the covariance, in whitened "
        "coordinates, by " + ", ".join(parts) + " (Σ̂_k → L_k Ŝ L_kᵀ)"
    )


def block_advice(diag) -> str:
    """The factor (interval) of each named block of the state.

    Parameters
    ----------
    diag : Diagnosis
        A diagnosis with named blocks (a pose's position and orientation).

    Returns
    -------
    str
        "by block: position f (low–high), …": the blocks of the covariance to correct,
        when they differ.
    """
    blocks = diag.blocks
    factors = _factors(
        [b.factor for b in blocks], [b.low for b in blocks], [b.high for b in blocks]
    )
    return "by block: " + ", ".join(f"{b.name} {f}" for b, f in zip(blocks, factors))


def _smm_hint(diag) -> str:
    """What an SMM finding means for the estimator, and the axis to look at first: the
    component whose mean is the most standard errors from zero."""
    sc = diag.scale
    bias = [] if sc is None else _finites(sc.bias)
    stderr = [] if sc is None else _finites(sc.bias_stderr)
    ratios = [
        abs(b) / s if s else 0.0 for b, s in zip(bias, stderr) if b is not None and s is not None
    ]
    if not ratios or max(ratios) == 0:
        return ""
    k = max(range(len(ratios)), key=ratios.__getitem__)
    return f"look first at component {k} ({format_number(ratios[k])} standard errors from 0)"


LOCATION_MEANING = {
    "bias": (
        "bias: the errors have a mean that no covariance allows for, so retuning the noise "
        "will not fix it (unless a finding names an error slower than the segment, which "
        "the claim may cover); look for a model mismatch: an unmodelled sensor bias, lever "
        "arm, time offset, frame or motion model"
    ),
    "asymmetric": (
        "asymmetric: the errors are not symmetric about zero though the mean test finds no "
        "mean: skewed errors or outliers on one side (non-line-of-sight or multipath ranges, "
        "a one-sided fault), which a Gaussian covariance cannot describe; look at the "
        "measurement model's tails, or gate the outliers"
    ),
    SMM_CONDITION: (
        "smm: the errors are not symmetric about zero (the paper's system-model mismatch), "
        "and no mean test could run to tell a bias from skewed errors; look for a model "
        "mismatch: an unmodelled sensor bias, lever arm, time offset, frame or motion model"
    ),
}
"""What each location condition means for the estimator (the advice's last lines)."""
