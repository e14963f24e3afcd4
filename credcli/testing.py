"""Assertions for an estimator's test suite: the in-Python counterpart of ``credcli gate``.

A filter's unit test runs the filter on a simulated scenario, then asks whether the
covariance it reports can be trusted::

    from credcli.testing import assert_credible, assert_label

    def test_my_ekf_is_credible():
        truth, estimate, cov = run_my_ekf(seed=1)
        assert_credible(truth - estimate, cov)        # as np.testing: actual first
        assert_credible(truth=truth, estimate=estimate, cov=cov)

    def test_a_bias_is_seen_as_a_model_mismatch():
        assert_label("bias", biased_errors, cov)

Each call diagnoses with the calibrated rule at a stated level (``alpha``, 0.05 by default:
a correctly tuned filter fails at most about 5 % of seeds per segment) and a fixed ``seed``
for the sign flips, so a test is deterministic. On failure the ``AssertionError`` holds the
diagnosis table and the advice lines that ``credcli diagnose`` prints.
"""

from __future__ import annotations

from collections.abc import Sequence

from credcli.api import Results, diagnose_log, log_from_arrays
from credcli.engine.config import SMM_CONDITION
from credcli.engine.diagnosis import DiagnosisConfig, Label
from credcli.io.logs import EstimatorLog
from credcli.io.records import config_record
from credcli.report.formats import OutputFormat
from credcli.report.render import diagnose_report, to_text

__all__ = ["assert_credible", "assert_label", "diagnosis_text"]


def _results(log, cov, segments, alpha: float, seed: int, arrays: dict) -> Results:
    """``log`` is an EstimatorLog, or the errors (N, d) when ``cov`` is given beside it."""
    if log is not None and not isinstance(log, EstimatorLog):
        if cov is None:
            raise TypeError(
                f"log: expected an EstimatorLog, or errors (N, d) with cov; got "
                f"{type(log).__name__} and no cov"
            )
        if "errors" in arrays:
            raise TypeError("errors: given twice (first argument and errors=)")
        log, arrays["errors"] = None, log
    if cov is not None:
        arrays["cov"] = cov
    if log is None:
        if "cov" not in arrays:
            raise TypeError("give a log, or arrays with cov")
        log = log_from_arrays(**arrays)
    elif arrays:
        raise TypeError(f"give a log or arrays, not both (got {', '.join(sorted(arrays))})")
    return diagnose_log(log, segments, DiagnosisConfig(alpha=alpha), seed)


def diagnosis_text(results: Results, alpha: float) -> str:
    """The diagnosis table and its advice lines, as ``credcli diagnose`` prints them."""
    config = DiagnosisConfig(alpha=alpha)
    report = diagnose_report(list(results), config, config_record(config), [], show_all=False)
    return to_text(report, OutputFormat.TABLE)


def assert_credible(
    log=None,
    cov=None,
    *,
    segments: str | Sequence | None = None,
    alpha: float = 0.05,
    seed: int = 0,
    allow_untested: bool = False,
    **arrays,
) -> Results:
    """Assert that every segment is credible at level ``alpha``; return the results.

    Give a log ([credcli.read_log][credcli.api.read_log],
    [credcli.log_from_arrays][credcli.api.log_from_arrays], an adapter's); or errors and
    covariances, ``assert_credible(errors, cov)`` as ``np.testing`` takes the actual value
    first; or the arrays of [credcli.log_from_arrays][credcli.api.log_from_arrays] as
    keywords (``cov=`` with ``truth=``/``estimate=`` or ``errors=``, and optionally
    ``time=``, ``segment=``).
    ``segments`` as in [credcli.diagnose_log][credcli.api.diagnose_log] ("whole", "5s", …).

    A segment passes when its label is credible with both questions answered. With
    ``allow_untested``, a segment the data cannot decide (``insufficient-data``, or
    credible with one question untested) passes too; by default it fails, because a test
    that cannot see a misfit is not evidence of its absence.

    Raises
    ------
    AssertionError
        With the diagnosis table and advice lines, naming the failing segments.
    """
    results = _results(log, cov, segments, alpha, seed, dict(arrays))
    failing = []
    for r in results:
        d = r.diagnosis
        undecided = d.label is Label.INSUFFICIENT or (d.label is Label.CREDIBLE and d.untested)
        if undecided and allow_untested:
            continue
        if d.label is not Label.CREDIBLE or d.untested:
            failing.append(f"{r.segment}: {_shown(d)}")
    if failing:
        raise AssertionError(
            f"not credible at α = {alpha:g}: {'; '.join(failing)}\n"
            + diagnosis_text(results, alpha)
        )
    return results


def assert_label(
    expected: str | Label,
    log=None,
    cov=None,
    *,
    segments: str | Sequence | None = None,
    alpha: float = 0.05,
    seed: int = 0,
    **arrays,
) -> Results:
    """Assert that every segment gets the label ``expected`` ("optimism", "bias",
    "pessimism+asymmetric", …; a [credcli.Label][credcli.engine.config.Label] too), e.g. that a planted fault is
    seen as what it is. A label in the paper's terms ("smm", "optimism+smm") accepts any
    location condition in its place (bias, asymmetric or smm;
    [Label.paper][credcli.engine.config.Label.paper]). Arguments as for
    [assert_credible][credcli.testing.assert_credible] (``assert_label("bias", errors,
    cov)``); return the results.

    Raises
    ------
    AssertionError
        With the diagnosis table and advice lines.
    ValueError
        If ``expected`` is not a label.
    """
    label = Label(expected)
    results = _results(log, cov, segments, alpha, seed, dict(arrays))

    def right(got: Label) -> bool:
        return got is label or (label.location == SMM_CONDITION and got.paper is label)

    wrong = [f"{r.segment}: {_shown(r.diagnosis)}" for r in results if not right(r.diagnosis.label)]
    if wrong:
        raise AssertionError(
            f"expected {label.value} at α = {alpha:g}: {'; '.join(wrong)}\n"
            + diagnosis_text(results, alpha)
        )
    return results


def _shown(diagnosis) -> str:
    untested = " and ".join(q.value for q in diagnosis.untested)
    return diagnosis.label.value + (f" ({untested} untested)" if untested else "")
