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
from credcli.errors import CredcliError
from credcli.io.logs import EstimatorLog
from credcli.report.builders import diagnose_report
from credcli.report.formats import OutputFormat
from credcli.report.records import config_record
from credcli.report.render import to_text

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
    """The diagnosis table and its advice lines, as ``credcli diagnose`` prints them.

    Parameters
    ----------
    results : Results
        The diagnoses, as [credcli.diagnose_log][credcli.api.diagnose_log] gives them.
    alpha : float
        The level they were diagnosed at (the calibrated rule's ``alpha``).

    Returns
    -------
    str
        The table and the advice lines: what an assertion's failure message holds.
    """
    config = DiagnosisConfig(alpha=alpha)
    report = diagnose_report(list(results), config, config_record(config), {}, show_all=False)
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

    The calibrated rule decides, with a fixed ``seed`` for the sign flips, so the test is
    deterministic. A segment passes when its label is credible with both questions
    answered.

    Parameters
    ----------
    log : EstimatorLog or array_like, optional
        A log ([credcli.read_log][credcli.api.read_log],
        [credcli.log_from_arrays][credcli.api.log_from_arrays], an adapter's); or the
        errors (N, d) with ``cov``, ``assert_credible(errors, cov)`` as ``np.testing``
        takes the actual value first.
    cov : array_like, optional
        The claimed covariances, beside errors: (N, d, d), (d, d) or variances (N, d).
    segments : None, "whole", a window such as "5s", or a list of Segment
        As in [credcli.diagnose_log][credcli.api.diagnose_log].
    alpha : float
        The calibrated rule's overall false-alarm level: a correctly tuned filter fails at
        most about this fraction of seeds per segment.
    seed : int
        The seed of the sign flips.
    allow_untested : bool
        Let a segment the data cannot decide (``insufficient-data``, or credible with one
        question untested) pass too; by default it fails, because a test that cannot see a
        misfit is not evidence of its absence.
    **arrays
        The arrays of [credcli.log_from_arrays][credcli.api.log_from_arrays] as keywords
        (``cov=`` with ``truth=``/``estimate=`` or ``errors=``, and optionally ``time=``,
        ``segment=``), instead of ``log``.

    Returns
    -------
    Results
        The diagnoses, when every segment passes.

    Raises
    ------
    AssertionError
        With the diagnosis table and advice lines, naming the failing segments.
    TypeError
        If the log or the arrays are given wrongly: arrays without ``cov``, errors given
        twice, a log and arrays both.
    CredcliError
        For invalid arrays or settings (from [credcli.log_from_arrays][credcli.api.log_from_arrays]
        and [credcli.diagnose_log][credcli.api.diagnose_log]).

    Examples
    --------
    >>> import numpy as np
    >>> errors = np.random.default_rng(0).standard_normal((500, 2))
    >>> assert_credible(errors, np.eye(2))
    Results([all: credible])
    >>> assert_credible(2.0 * errors, np.eye(2))  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    AssertionError: not credible at α = 0.05: all: optimism
    ...
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
    """Assert that every segment gets the label ``expected``; return the results.

    E.g. that a planted fault is seen as what it is. A label in the paper's terms
    ("smm", "optimism+smm") accepts any location condition in its place (bias, asymmetric
    or smm; [Label.paper][credcli.engine.config.Label.paper]).

    Parameters
    ----------
    expected : str or Label
        "optimism", "bias", "pessimism+asymmetric", …; a
        [credcli.Label][credcli.engine.config.Label] too.
    log, cov, segments, alpha, seed, **arrays
        As for [assert_credible][credcli.testing.assert_credible]
        (``assert_label("bias", errors, cov)``).

    Returns
    -------
    Results
        The diagnoses, when every segment has the label.

    Raises
    ------
    AssertionError
        With the diagnosis table and advice lines.
    CredcliError
        If ``expected`` is not a label (naming ``expected``).
    TypeError
        If the log or the arrays are given wrongly (as for ``assert_credible``).
    CredcliError
        For invalid arrays or settings.

    Examples
    --------
    >>> import numpy as np
    >>> errors = np.random.default_rng(0).standard_normal((500, 2))
    >>> assert_label("optimism", 2.0 * errors, np.eye(2))
    Results([all: optimism])
    >>> assert_label("smm", errors + 0.5, np.eye(2))  # a bias is the paper's SMM
    Results([all: bias])
    """
    try:
        label = Label(expected)
    except ValueError:
        names = ", ".join(v.value for v in Label)
        raise CredcliError(
            f"expected {expected!r} is not a label; one of {names}", "expected"
        ) from None
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
