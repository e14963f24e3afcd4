"""The Python API: the examples of docs/python.md run, and the API gives what the CLI gives."""

from __future__ import annotations

import doctest
import json
import os
from pathlib import Path

import numpy as np
import pytest

import credcli
from credcli.cli import main

ROOT = Path(__file__).resolve().parents[1]


def test_python_api_page_runs(monkeypatch):
    monkeypatch.chdir(ROOT)
    failures, tried = doctest.testfile(
        str(ROOT / "docs" / "python.md"),
        module_relative=False,
        optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE,
    )
    assert tried >= 10 and failures == 0


def test_to_dict_equals_the_cli_json(capsys):
    log = credcli.read_log(ROOT / "sample_data" / "estimator_log.csv")
    records = credcli.diagnose_log(log, seed=4).to_dict()
    assert (
        main(
            [
                "diagnose",
                str(ROOT / "sample_data" / "estimator_log.csv"),
                "-f",
                "json",
                "--seed",
                "4",
            ]
        )
        == 0
    )
    cli = json.loads(capsys.readouterr().out)["segments"]
    assert len(records) == len(cli) == 6  # a truncated document fails here, not silently
    for a, b in zip(records, cli):
        a = dict(a, log=os.path.basename(a["log"]))
        b = dict(b, log=os.path.basename(b["log"]))
        assert a == b


def test_segments_argument():
    log = credcli.read_log(ROOT / "sample_data" / "estimator_log.csv")
    assert len(credcli.diagnose_log(log, "whole")) == 1
    assert len(credcli.diagnose_log(log, "30s")) == 7  # 1,800 epochs at 10 Hz, and the run
    assert len(credcli.diagnose_log(log, "300")) == 7


def test_short_reprs_and_unpacking():
    e = np.random.default_rng(0).standard_normal((200, 2))
    d = credcli.diagnose(e, np.eye(2), rng=0)
    assert len(repr(d)) < 120 and len(repr(d.elt)) < 120 and len(repr(d.scale)) < 120
    statistic, pvalue = d.elt
    assert (statistic, pvalue) == (d.elt.statistic, d.elt.pvalue)


def test_the_command_line_starts_without_the_numeric_stack():
    """`credcli --help` and `--version` import no numpy, scipy, pandas or numba (start-up)."""
    import subprocess
    import sys

    code = (  # a fresh interpreter: this one has loaded them all
        "import sys, credcli, credcli.cli, credcli.cli.edge\n"
        "assert credcli.cli.main(['--help']) == credcli.cli.main(['--version']) == 0\n"
        "print(sorted(m for m in ('numpy', 'scipy', 'pandas', 'matplotlib', 'numba')"
        " if m in sys.modules))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    *help_text, loaded = out.stdout.strip().splitlines()
    assert loaded == "[]"
    assert "diagnose" in "".join(help_text) and "--debug" in "".join(help_text)


def _errors(n=300, d=2, seed=1, scale=1.0):
    return np.random.default_rng(seed).standard_normal((n, d)) * scale


def test_one_obvious_api():
    """Issue 33 item 2: labels read as text, arrays taken positionally as np.testing takes
    them, variances (N, d), one seed name."""
    from credcli.testing import assert_credible, assert_label

    assert str(credcli.Label.CREDIBLE) == "credible" and f"{credcli.Label.OPTIMISM}" == "optimism"
    e = _errors()
    truth, estimate = np.zeros_like(e), -e
    by_position = credcli.log_from_arrays(truth, estimate, np.eye(2))
    assert np.array_equal(
        by_position.errors, credcli.log_from_arrays(errors=e, cov=np.eye(2)).errors
    )
    columns = credcli.log_from_arrays(truth[:, :, None], estimate[:, :, None], np.eye(2))
    assert np.array_equal(columns.errors, by_position.errors)  # filterpy's (N, d, 1) means
    variances = credcli.log_from_arrays(errors=e, cov=np.tile([1.0, 4.0], (300, 1)))
    assert np.array_equal(variances.cov[5], np.diag([1.0, 4.0]))
    assert credcli.log_from_arrays(np.eye(2), errors=e).n == 300  # credcli 0.1's form
    results = credcli.diagnose_log(credcli.log_from_arrays(errors=e * 2, cov=np.eye(2)))
    assert results.labels == ["optimism"] and results.labels[0] is credcli.Label.OPTIMISM
    assert assert_credible(e, np.eye(2)).labels == ["credible"]
    assert assert_label("optimism", e * 2, np.eye(2)).labels == ["optimism"]
    try:
        assert_credible(e * 2, np.eye(2))
    except AssertionError as failure:
        assert "optimism" in str(failure) and "credcli diagnose" in str(failure)
    else:
        raise AssertionError("a 4x optimistic covariance passed")
    a, b = credcli.diagnose(e, np.eye(2), seed=3), credcli.diagnose(e, np.eye(2), rng=3)
    assert a.elt_pvalue == b.elt_pvalue


def test_python_errors_name_python_arguments():
    """Issue 33 item 2: a transposed array is named as such (it was blamed on cov); a
    non-log is a TypeError naming `log`; the segmenter names `segments`, not `window`."""
    import pytest

    e = _errors()
    with pytest.raises(credcli.CredcliError, match=r"truth: shape \(2, 300\) is transposed"):
        credcli.log_from_arrays(np.zeros((2, 300)), -e, np.eye(2))
    with pytest.raises(credcli.CredcliError, match=r"errors: shape \(2, 300\) is transposed"):
        credcli.diagnose(e.T, np.eye(2))
    with pytest.raises(credcli.CredcliError, match=r"estimate: shape \(2, 300\) is transposed"):
        credcli.log_from_arrays(np.zeros((300, 2)), e.T, np.broadcast_to(np.eye(2), (300, 2, 2)))
    with pytest.raises(TypeError, match="log: expected an EstimatorLog .* got ndarray"):
        credcli.diagnose_log(np.zeros((10, 2)))
    log = credcli.log_from_arrays(errors=e, cov=np.eye(2))
    with pytest.raises(credcli.CredcliError, match="`segments` 5s needs a time column") as info:
        credcli.diagnose_log(log, segments="5s")
    assert "window" not in str(info.value) and info.value.parameter == "segments"


def test_a_variance_of_inf_is_named_without_a_warning():
    """(N, d) variances with an inf are refused by the epoch, as a matrix with one is; the
    diagonal matrices were made as inf·0 = NaN first, with numpy's RuntimeWarning."""
    import warnings

    import pytest

    variances = np.ones((300, 2))
    variances[7, 1] = np.inf
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(credcli.CredcliError, match=r"cov\[7\] has a NaN or Inf value"):
            credcli.diagnose(_errors(), variances)


def test_a_covariance_with_entries_near_the_float64_limit_is_named():
    """A 3×3 covariance whose off-diagonal pair is 1e308: not positive definite, said by
    the epoch (symmetrising it as (a + b)/2 overflowed to inf, and numpy's eigenvalue
    routine failed: exit 3)."""
    import pytest

    cov = np.broadcast_to(np.eye(3), (300, 3, 3)).copy()
    cov[9, 0, 2] = cov[9, 2, 0] = 1e308
    errors = np.random.default_rng(2).standard_normal((300, 3))
    with pytest.raises(credcli.CredcliError, match=r"cov\[9\]: covariance is not positive"):
        credcli.diagnose(errors, cov)


def test_a_config_that_is_not_a_diagnosis_config_is_a_type_error():
    """``config="paper"`` or a dict failed as an AttributeError inside the engine."""
    import pytest

    e = _errors()
    log = credcli.log_from_arrays(errors=e, cov=np.eye(2))
    runs = credcli.log_from_arrays(errors=e, cov=np.eye(2), run=np.arange(300) // 150)
    calls = [
        lambda config: credcli.diagnose(e, np.eye(2), config),
        lambda config: credcli.diagnose_log(log, None, config),
        lambda config: credcli.diagnose_log(runs, None, config),
        lambda config: credcli.diagnose_variants(e, np.eye(2)[None].repeat(300, 0), ["ks"], config),
    ]
    for call in calls:
        with pytest.raises(TypeError, match="config: expected a DiagnosisConfig or None; got str"):
            call("paper")
    with pytest.raises(TypeError, match=r"got dict \(DiagnosisConfig\(\*\*settings\) makes one\)"):
        credcli.diagnose(e, np.eye(2), {"variant": "paper"})


def test_near_symmetric_covariances_are_symmetrised_with_a_note(tmp_path):
    """Issue 33 item 6: a filter's covariance that drifts from symmetric by the relative
    4.6e-4 measured on Stone Soup's default updater is made symmetric with one note; past
    1e-3 it is refused, from Python and from a file."""
    import pytest

    e = _errors()
    cov = np.broadcast_to([[2.0, 0.5], [0.5, 1.0]], (300, 2, 2)).copy()
    cov[::3, 0, 1] += 4.6e-4 * 2.0
    log = credcli.log_from_arrays(errors=e, cov=cov)
    (note,) = log.notes
    assert "100 of 300 covariances were not symmetric" in note and "0.00046" in note
    assert np.array_equal(log.cov, log.cov.transpose(0, 2, 1))
    assert log.cov[0, 0, 1] == pytest.approx(0.5 + 2.3e-4 * 2.0)
    path = credcli.write_log(log, tmp_path / "drift.csv")
    frame = __import__("pandas").read_csv(path)
    frame["cov_1_0"] = frame["cov_0_1"] + 4.6e-4 * 2.0 * (np.arange(300) % 3 == 0)
    frame["cov_0_1"] = frame["cov_0_1"].where(np.arange(300) % 3 != 0, 0.5)
    frame.to_csv(path, index=False)
    assert any("covariances were not symmetric" in n for n in credcli.read_log(path).notes)
    cov[7, 0, 1] += 2e-3 * 2.0
    with pytest.raises(credcli.CredcliError, match=r"cov\[7\]: .*asymmetry 0.002, above 0.001"):
        credcli.log_from_arrays(errors=e, cov=cov)


def test_bad_choices_in_the_python_api_name_their_parameter():
    """assert_label's expected label, diagnose_variants' variants and probes' c are
    CredcliErrors naming the parameter (they were bare ValueErrors or named nothing); a
    name in backticks is one the command line turns into a flag, so only c has them."""
    import numpy as np

    from credcli.engine.diagnosis import diagnose_variants
    from credcli.engine.metrics import probes
    from credcli.errors import CredcliError
    from credcli.testing import assert_label

    e = np.random.default_rng(0).standard_normal((50, 2))
    cov = np.broadcast_to(np.eye(2), (50, 2, 2))
    for call, name in (
        (lambda: assert_label("nonsense", e, np.eye(2)), "expected"),
        (lambda: diagnose_variants(e, cov, ["calibrated", "nonsense"]), "variants"),
        (lambda: probes(e, cov, c=0.5), "c"),
    ):
        with pytest.raises(CredcliError, match=rf"\b{name}\b") as info:
            call()
        assert info.value.parameter == name


def test_a_state_in_mixed_units_is_diagnosed_as_in_one_unit():
    """A pose whose position is in metres (σ 30–50 m) and attitude in radians (σ 2–5
    µrad), standard deviations 2.5·10⁷ apart: diagnosed as the same errors and
    covariances in one unit (each component divided by its σ), with the same label and
    statistics to 1e-9 (it was refused: "not positive definite", its smallest eigenvalue
    below 1e-12 of its largest entry). Correlated components, the claim growing over time
    (Σ_k = c_k·DRD), a bias on the second run."""
    rng = np.random.default_rng(11)
    sd = np.array([30.0, 30.0, 50.0, 2e-6, 2e-6, 5e-6])
    a = rng.standard_normal((6, 8))
    c = a @ a.T
    r = c / np.sqrt(np.outer(np.diag(c), np.diag(c)))
    grow = np.linspace(1.0, 3.0, 500)[:, None, None]
    for bias in (0.0, 0.4):
        w = rng.standard_normal((500, 6)) @ np.linalg.cholesky(r).T * np.sqrt(grow[:, :, 0])
        w[:, 3] += bias * np.sqrt(grow[:, 0, 0])
        one = credcli.diagnose(w, grow * r, seed=3)
        mixed = credcli.diagnose(w * sd, grow * r * np.outer(sd, sd), seed=3)
        assert (mixed.label, mixed.untested) == (one.label, one.untested)
        for name in ("anees", "elt_pvalue"):
            assert getattr(mixed, name) == pytest.approx(getattr(one, name), rel=1e-9)
        assert mixed.scale.scale_factor == pytest.approx(one.scale.scale_factor, rel=1e-9)
        assert mixed.mean_test.pvalue == pytest.approx(one.mean_test.pvalue, rel=1e-9, abs=1e-300)
        assert mixed.mean_test.spread == pytest.approx(one.mean_test.spread, rel=1e-9)


@pytest.mark.parametrize("seed", [-1, 1.5, "a"])
def test_a_bad_seed_is_a_credcli_error_naming_the_seed(seed):
    """numpy's own ValueError or TypeError ("expected non-negative integer") named no
    argument and was no CredcliError; the command line already said which."""
    with pytest.raises(credcli.CredcliError, match="the seed must be") as info:
        credcli.diagnose(_errors(), np.eye(2), seed=seed)
    assert info.value.parameter == "seed"


def test_the_api_refuses_what_diagnoses_nothing_or_cannot_be_read(tmp_path):
    """A test of the estimator that saw no data must not pass; a seed, a list of segments
    or a label the command line would refuse is a CredcliError naming the argument (an
    empty list of segments passed assert_credible, and the others ended in numpy's or
    Python's own errors)."""
    from credcli.errors import CredcliError
    from credcli.segments import split
    from credcli.testing import assert_credible, assert_label

    errors = np.random.default_rng(0).standard_normal((400, 2))
    log = credcli.log_from_arrays(errors=errors, cov=np.eye(2))
    other = credcli.log_from_arrays(errors=np.zeros((1000, 2)) + 0.1, cov=np.eye(2))
    refused = {
        "empty list": (lambda: assert_credible(5 * errors, np.eye(2), segments=[]), "segments"),
        "empty, label": (
            lambda: assert_label("optimism", errors, np.eye(2), segments=[]),
            "segments",
        ),
        "negative seed": (lambda: assert_credible(errors, np.eye(2), seed=-1), "seed"),
        "fractional seed": (lambda: credcli.diagnose_log(log, seed=1.5), "seed"),
        "boolean seed": (lambda: credcli.diagnose_log(log, seed=True), "seed"),
        "a string": (lambda: assert_credible(errors, np.eye(2), segments=["a"]), "segments"),
        "an int": (lambda: credcli.diagnose_log(log, segments=5), "segments"),
        "another log's": (lambda: credcli.diagnose_log(log, segments=split(other)), "segments"),
        "NaN run": (
            lambda: credcli.log_from_arrays(
                errors=errors, cov=np.eye(2), run=np.r_[np.full(200, np.nan), np.zeros(200)]
            ),
            "run",
        ),
        "None segment": (
            lambda: credcli.log_from_arrays(
                errors=errors, cov=np.eye(2), segment=["a"] * 399 + [None]
            ),
            "segment",
        ),
    }
    for case, (call, parameter) in refused.items():
        with pytest.raises(CredcliError) as caught:
            call()
        assert caught.value.parameter == parameter, case
    named = credcli.log_from_arrays(errors=errors, cov=np.eye(2), segment=[1] * 200 + [2] * 200)
    assert [r.segment for r in credcli.diagnose_log(named, seed=np.int64(3))] == ["1", "2"]


def test_booleans_are_not_errors_or_covariances():
    """A mask passed by mistake was read as errors of 0 and 1."""
    from credcli.errors import CredcliError

    with pytest.raises(CredcliError, match="errors: booleans"):
        credcli.diagnose(np.ones((50, 2), dtype=bool), np.eye(2))
    with pytest.raises(CredcliError, match="cov: booleans"):
        credcli.log_from_arrays(errors=np.zeros((50, 2)), cov=np.ones((2, 2), dtype=bool))


def test_a_segment_without_epochs_or_with_a_mask_is_named():
    """An empty index ended in numpy's IndexError; a boolean mask was called "not in this
    log"."""
    import dataclasses

    from credcli.errors import CredcliError
    from credcli.segments import split

    log = credcli.log_from_arrays(
        errors=np.random.default_rng(0).standard_normal((300, 2)), cov=np.eye(2)
    )
    whole = list(split(log))[0]
    with pytest.raises(CredcliError, match="no epochs"):
        credcli.diagnose_log(log, [dataclasses.replace(whole, index=np.array([], dtype=int))])
    with pytest.raises(CredcliError, match="a boolean mask; give epoch indices"):
        credcli.diagnose_log(log, [dataclasses.replace(whole, index=np.ones(300, dtype=bool))])


def test_a_direction_interval_at_the_float_limit_raises_no_warning():
    """Six dimensions over 20 epochs: a direction's upper end near the largest float,
    widened for the selection, overflowed to ∞ with a RuntimeWarning that the command line
    turned into a note blaming the data."""
    import warnings

    errors = np.random.default_rng(6021).standard_normal((20, 6))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        credcli.diagnose(errors, np.eye(6), seed=0)
