"""Issue 24: logs from arrays and DataFrames, errors-only and .npz inputs, date-time columns,
Monte Carlo runs from Python, the notebook view and the pytest helpers. Each path is checked
against the command line on the same data (the same records), or against a closed form."""

from __future__ import annotations

import json
import math
from html.parser import HTMLParser

import numpy as np
import pandas as pd
import pytest
from helpers import error_line, run

import credcli
from credcli.errors import CredcliError
from credcli.testing import assert_credible, assert_label


@pytest.fixture
def arrays():
    """Two segments of 300 epochs, d = 2, rotating covariances; the second 4× optimistic."""
    rng = np.random.default_rng(40)
    n = 600
    angle = np.linspace(0, np.pi, n)
    rot = np.stack([[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]]).transpose(
        2, 0, 1
    )
    cov = rot @ np.diag([4.0, 0.25]) @ rot.transpose(0, 2, 1)
    chol = np.linalg.cholesky(cov)
    scale = np.r_[np.ones(300), 2.0 * np.ones(300)][:, None]
    errors = scale * np.einsum("nij,nj->ni", chol, rng.standard_normal((n, 2)))
    truth = rng.normal(size=(n, 2)) * 10
    time = pd.Timestamp("2024-05-01T12:00:00Z") + pd.to_timedelta(np.arange(n) * 0.1, unit="s")
    return {
        "truth": truth,
        "estimate": truth - errors,
        "errors": errors,
        "cov": cov,
        "time": time,
        "segment": np.repeat(["calm", "gusty"], 300),
    }


def _records(results) -> list[dict]:
    return [{k: v for k, v in r.items() if k != "log"} for r in results.to_dict()]


def test_arrays_give_the_cli_records(tmp_path, arrays):
    """truth/estimate and errors alone give the same diagnosis; the log written by
    write_log, read by `credcli diagnose`, gives the same JSON records."""
    both = credcli.log_from_arrays(
        arrays["truth"],
        arrays["estimate"],
        arrays["cov"],
        time=arrays["time"],
        segment=arrays["segment"],
    )
    alone = credcli.log_from_arrays(
        arrays["cov"], errors=arrays["errors"], segment=arrays["segment"]
    )
    a, b = credcli.diagnose_log(both), credcli.diagnose_log(alone)
    assert [r.diagnosis.label.value for r in a] == ["credible", "optimism"]
    assert [r.diagnosis.label for r in a] == [r.diagnosis.label for r in b]
    for x, y in zip(a, b):
        assert x.diagnosis.scale.scale_factor == pytest.approx(y.diagnosis.scale.scale_factor)
    for name in ("log.parquet", "log.csv"):
        path = credcli.write_log(both, tmp_path / name)
        code, out, err = run("diagnose", path, "-f", "json")
        assert code == 0, err
        segments = json.loads(out)["segments"]
        expected = _records(a)
        assert len(segments) == len(expected) == 2
        for got, want in zip(segments, expected):
            assert got["label"] == want["label"] and got["n"] == want["n"]
            assert got["scale_factor"] == pytest.approx(want["scale_factor"], rel=1e-12)
            assert got["t_start"] == pytest.approx(want["t_start"], abs=1e-6)
    # the time column is seconds since 1970 UTC: 2024-05-01T12:00Z is 1714564800
    assert a[0].t_start == pytest.approx(1714564800.0, abs=1e-6)
    assert any("1970-01-01 00:00 UTC" in note for note in both.notes)


def test_errors_only_and_npz_files_through_the_cli(tmp_path, arrays):
    frame = pd.DataFrame({"err_0": arrays["errors"][:, 0], "err_1": arrays["errors"][:, 1]})
    frame["cov_0_0"], frame["cov_0_1"], frame["cov_1_1"] = (
        arrays["cov"][:, 0, 0],
        arrays["cov"][:, 0, 1],
        arrays["cov"][:, 1, 1],
    )
    frame["segment"] = arrays["segment"]
    frame.to_csv(tmp_path / "e.csv", index=False, float_format="%.17g")
    np.savez(
        tmp_path / "e.npz", errors=arrays["errors"], cov=arrays["cov"], segment=arrays["segment"]
    )
    docs = []
    for name in ("e.csv", "e.npz"):
        code, out, err = run("diagnose", tmp_path / name, "-f", "json")
        assert code == 0, err
        docs.append(json.loads(out)["segments"])
    assert (
        "errors-only log: err_0, err_1 are the errors e_k" in run("diagnose", tmp_path / "e.csv")[2]
    )
    assert (
        [s["label"] for s in docs[0]] == [s["label"] for s in docs[1]] == ["credible", "optimism"]
    )
    for x, y in zip(*docs):
        assert x["scale_factor"] == pytest.approx(y["scale_factor"], rel=1e-12)
    np.savez(tmp_path / "typo.npz", erors=arrays["errors"], cov=arrays["cov"])
    line = error_line(*run("diagnose", tmp_path / "typo.npz")[::2])
    assert "unknown array(s) erors" in line and "typo.npz" in line
    np.savez(tmp_path / "two.npz", errors=arrays["errors"], err=arrays["errors"], cov=arrays["cov"])
    line = error_line(*run("diagnose", tmp_path / "two.npz")[::2])  # one was silently kept
    assert "arrays errors and err are two names of `errors`" in line, line
    assert error_line(*run("diagnose", tmp_path / "none.npz")[::2]).endswith(
        "none.npz: file not found"
    )


def test_iso_times_in_a_csv_make_windows_in_seconds(tmp_path, arrays):
    stamps = arrays["time"].strftime("%Y-%m-%dT%H:%M:%S.%fZ")
    frame = pd.DataFrame({"time": stamps, "err_0": arrays["errors"][:, 0]})
    frame["err_1"], frame["var_0"], frame["var_1"] = arrays["errors"][:, 1], 1.0, 1.0
    frame.to_csv(tmp_path / "iso.csv", index=False)
    code, out, err = run("diagnose", tmp_path / "iso.csv", "--window", "15s", "-f", "json")
    assert code == 0, err
    segments = json.loads(out)["segments"]
    assert [s["n"] for s in segments] == [150, 150, 150, 150, 600]  # 10 Hz, 15 s windows; run
    assert "date-times read as seconds since 1970-01-01 00:00 UTC" in err
    frame.loc[7, "time"] = "yesterday"
    frame.to_csv(tmp_path / "bad.csv", index=False)
    line = error_line(*run("diagnose", tmp_path / "bad.csv")[::2])
    assert "'yesterday'" in line and "ISO-8601" in line and "bad.csv (time)" in line


def test_log_from_frame_with_named_columns(arrays):
    frame = pd.DataFrame(
        {
            "t": arrays["time"],
            "ex": arrays["errors"][:, 0],
            "ey": arrays["errors"][:, 1],
            "sxx": arrays["cov"][:, 0, 0],
            "sxy": arrays["cov"][:, 0, 1],
            "syy": arrays["cov"][:, 1, 1],
            "leg": arrays["segment"],
        }
    )
    log = credcli.log_from_frame(
        frame, errors=["ex", "ey"], cov=["sxx", "sxy", "syy"], time="t", segment="leg"
    )
    np.testing.assert_allclose(log.errors, arrays["errors"], rtol=0, atol=0)
    np.testing.assert_allclose(log.cov, arrays["cov"], rtol=1e-15)
    assert sorted(set(log.segment)) == ["calm", "gusty"]
    assert list(frame.columns)[0] == "t"  # the caller's frame is not renamed
    with pytest.raises(CredcliError, match="column 'ex'"):
        credcli.log_from_frame(frame.assign(ex="x"), errors=["ex", "ey"], cov=["sxx", "sxy", "syy"])


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"errors": "e", "cov": np.eye(2), "truth": "e"}, "not both"),
        ({"truth": "e", "cov": np.eye(2)}, "both truth and estimate"),
        ({"errors": "nan", "cov": np.eye(2)}, r"errors\[5, 1\] is nan"),
        ({"errors": "e", "cov": "asym"}, r"cov\[3\]: covariance is not symmetric"),
        ({"errors": "e", "cov": "npd"}, r"cov\[0\]: covariance is not positive definite"),
        ({"errors": "e", "cov": np.eye(3)}, r"errors: d = 2, but cov is 3 × 3"),
        ({"errors": "e", "cov": np.ones((10, 3))}, "errors: d = 2, but cov is 3 × 3"),
        (
            {"truth": "e", "estimate": "e", "cov": np.ones((4, 2, 2))},
            "truth: 10 epochs, expected 4",
        ),
        ({"errors": "e", "cov": np.ones((10, 2, 3))}, r"cov: expected shape \(N, d, d\)"),
        ({"errors": "e", "cov": np.ones((10, 3, 3))}, r"errors: d = 2, but cov is 3 × 3"),
        (
            {"truth": "e", "estimate": "e", "cov": np.ones((4, 2, 2))},
            r"truth: 10 epochs, expected 4",
        ),
        ({"truth": "e", "estimate": "short", "cov": np.eye(2)}, "estimate: 4 epochs"),
        ({"errors": "e", "cov": np.eye(2), "time": "short"}, r"time: expected shape \(10,\)"),
    ],
)
def test_array_errors_name_the_argument(kwargs, message):
    e = np.arange(20.0).reshape(10, 2)
    values = {
        "e": e,
        "nan": np.where(np.arange(20).reshape(10, 2) == 11, np.nan, e),
        "short": e[:4] if "estimate" in kwargs else np.arange(4.0),
        "asym": np.broadcast_to(np.eye(2), (10, 2, 2)).copy(),
        "npd": np.ones((10, 2, 2)),
    }
    values["asym"][3, 0, 1] = 0.5
    args = {k: values[v] if isinstance(v, str) else v for k, v in kwargs.items()}
    with pytest.raises(CredcliError, match=message):
        credcli.log_from_arrays(**args)


def test_monte_carlo_from_python_is_the_cli_monte_carlo(tmp_path):
    rng = np.random.default_rng(41)
    cov = np.broadcast_to(np.diag([1.0, 4.0]), (200, 2, 2))
    runs = [
        credcli.log_from_arrays(
            cov, errors=rng.standard_normal((200, 2)) * [1.0, 2.0], time=np.arange(200) * 0.1
        )
        for _ in range(8)
    ]
    mc = credcli.diagnose_monte_carlo(runs, segments="10s")
    paths = [credcli.write_log(r, tmp_path / f"run_{k}.csv") for k, r in enumerate(runs)]
    code, out, err = run("diagnose", *paths, "--monte-carlo", "--window", "10s", "-f", "json")
    assert code == 0, err
    doc = json.loads(out)
    assert [s["label"] for s in doc["segments"]] == [r.diagnosis.label.value for r in mc]
    assert [s["n"] for s in doc["segments"]] == [800, 800]
    assert doc["monte_carlo"]["fraction_inside"] == pytest.approx(float(mc.anees.inside.mean()))
    # the per-epoch ANEES is the mean NEES over runs: here the squared errors over d
    nees = np.stack([(r.errors**2 / [1.0, 4.0]).sum(axis=1) for r in runs])
    np.testing.assert_allclose(mc.anees.anees, nees.mean(axis=0), rtol=1e-12)


class _Cells(HTMLParser):
    def __init__(self):
        super().__init__()
        self.rows, self._row, self._in = [], None, False

    def handle_starttag(self, tag, attrs):
        if tag == "tr":
            self._row = []
        elif tag in ("td", "th"):
            self._in = True

    def handle_endtag(self, tag):
        if tag == "tr":
            self.rows.append(self._row)
        elif tag in ("td", "th"):
            self._in = False

    def handle_data(self, data):
        if self._in and self._row is not None:
            self._row.append(data)


def test_results_show_as_a_table_in_a_notebook(arrays):
    log = credcli.log_from_arrays(arrays["cov"], errors=arrays["errors"], segment=arrays["segment"])
    results = credcli.diagnose_log(log)
    parser = _Cells()
    parser.feed(results._repr_html_())
    header, *rows = parser.rows
    assert header[:4] == ["segment", "N", "d", "label"]
    assert [r[:4] for r in rows] == [
        ["calm", "300", "2", "credible"],
        ["gusty", "300", "2", "optimism"],
    ]
    assert "gusty: multiply the covariance by" in results._repr_html_()


def test_assert_credible_passes_a_right_filter_and_shows_the_table_otherwise(arrays):
    calm = slice(0, 300)
    assert_credible(errors=arrays["errors"][calm], cov=arrays["cov"][calm])
    with pytest.raises(AssertionError) as info:
        assert_credible(errors=arrays["errors"], cov=arrays["cov"], segment=arrays["segment"])
    text = str(info.value)
    assert text.startswith("not credible at α = 0.05: gusty: optimism")
    assert "┃ segment" in text and "gusty: multiply the covariance by" in text
    assert_label("optimism", errors=arrays["errors"][300:], cov=arrays["cov"][300:])
    with pytest.raises(AssertionError, match="expected smm"):
        assert_label("smm", errors=arrays["errors"][300:], cov=arrays["cov"][300:])
    with pytest.raises(ValueError):
        assert_label("biased", errors=arrays["errors"], cov=arrays["cov"])


def test_assert_credible_refuses_an_undecided_segment_unless_allowed():
    e = np.random.default_rng(42).standard_normal((5, 2))  # too short for any verdict
    with pytest.raises(AssertionError, match="insufficient-data"):
        assert_credible(errors=e, cov=np.eye(2))
    assert_credible(errors=e, cov=np.eye(2), allow_untested=True)


def test_assert_credible_fails_a_right_filter_at_about_alpha():
    """Its level: 300 seeds of a correct covariance (N = 200, d = 2, independent): failures
    at most α + 1 % + 2 s.e.; with the covariance 2× too small, nearly always (100 seeds:
    each failure renders its table, the costly part)."""
    rng = np.random.default_rng(43)
    cov = np.eye(2)
    fails = too_small = 0
    for k in range(300):
        e = rng.standard_normal((200, 2))
        try:
            assert_credible(errors=e, cov=cov, seed=k)
        except AssertionError:
            fails += 1
        if k >= 100:
            continue
        try:
            assert_credible(errors=e * math.sqrt(2), cov=cov, seed=k)
        except AssertionError:
            too_small += 1
    assert fails / 300 <= 0.06 + 2 * math.sqrt(0.05 * 0.95 / 300), fails
    assert too_small / 100 >= 0.9, too_small


def test_run_ids_pool_monte_carlo_runs_in_python_and_on_the_command_line(tmp_path):
    """M runs stacked in one array with run ids: diagnose_log pools them as
    diagnose_monte_carlo does with M separate logs; the written file, with its run column,
    is refused without --monte-carlo and pooled with it, to the same records."""
    rng = np.random.default_rng(44)
    m, n = 6, 150
    errors = rng.standard_normal((m * n, 2)) * 1.5  # covariance 2.25× too small
    time = np.tile(np.arange(n) * 0.1, m)
    run_ids = np.repeat([f"r{k}" for k in range(m)], n)
    stacked = credcli.log_from_arrays(np.eye(2), errors=errors, time=time, run=run_ids)
    separate = [
        credcli.log_from_arrays(np.eye(2), errors=errors[k * n : (k + 1) * n], time=time[:n])
        for k in range(m)
    ]
    pooled, reference = credcli.diagnose_log(stacked), credcli.diagnose_monte_carlo(separate)
    assert isinstance(pooled, credcli.MonteCarloResults) and pooled.anees.runs == m
    assert [r.diagnosis.label for r in pooled] == [r.diagnosis.label for r in reference]
    assert pooled[0].diagnosis.n == m * n and pooled[0].diagnosis.label.value == "optimism"
    path = credcli.write_log(stacked, tmp_path / "runs.csv")
    line = error_line(*run("diagnose", path)[::2])
    assert "holds 6 Monte Carlo runs" in line and "--monte-carlo" in line
    code, out, err = run("diagnose", path, "--monte-carlo", "-f", "json")
    assert code == 0, err
    doc = json.loads(out)
    assert doc["monte_carlo"]["runs"] == m
    assert doc["segments"][0]["scale_factor"] == pytest.approx(
        pooled[0].diagnosis.scale.scale_factor, rel=1e-12
    )
    frame = pd.read_csv(path).rename(columns={"run": "trial"})
    assert credcli.log_from_frame(frame, run="trial").run[0] == "r0"
    with pytest.raises(CredcliError, match="run column 'replica' not found"):
        credcli.log_from_frame(frame, run="replica")


@pytest.mark.parametrize(
    "call, parameter, message",
    [
        (lambda e, c: credcli.nees(e, c), "cov", r"cov\[2\] is not positive definite"),
        (lambda e, c: credcli.nci(e, c), "cov", r"cov\[2\] is not positive definite"),
        (lambda e, c: credcli.diagnose(e, c, seed=0), "cov", r"cov\[2\]: covariance is not pos"),
    ],
)
def test_public_entries_name_the_bad_argument(call, parameter, message):
    """Issue 23, point 4: a non-positive-definite covariance is a CredcliError (a
    ValueError) naming the argument and the epoch, not numpy's LinAlgError."""
    e = np.random.default_rng(45).standard_normal((40, 2))
    cov = np.broadcast_to(np.eye(2), (40, 2, 2)).copy()
    cov[2] = [[1.0, 2.0], [2.0, 1.0]]  # symmetric, indefinite
    with pytest.raises(ValueError, match=message) as info:
        call(e, cov)
    assert isinstance(info.value, CredcliError) and info.value.parameter == parameter


def test_an_asymmetric_covariance_and_bad_flips_are_refused():
    from credcli.engine.elt import whitened_location_test

    e = np.random.default_rng(46).standard_normal((40, 2))
    asym = np.array([[1.0, 0.5], [0.0, 1.0]])
    with pytest.raises(CredcliError, match=r"cov\[0\]: covariance is not symmetric"):
        credcli.diagnose(e, asym, rng=0)
    with pytest.raises(CredcliError, match=r"errors\[3, 1\] is not finite"):
        credcli.nees(
            np.where(np.arange(80).reshape(40, 2) == 7, np.nan, e), np.eye(2)[None].repeat(40, 0)
        )
    with pytest.raises(
        CredcliError, match="`n_flips` .* must be a positive integer; got 0"
    ) as info:
        whitened_location_test(e, 0, np.random.default_rng(0))
    assert info.value.parameter == "n_flips"


def test_errors_only_flag_with_named_columns(tmp_path):
    e = np.random.default_rng(47).standard_normal((300, 2)) * 2.0
    frame = pd.DataFrame({"ex": e[:, 0], "ey": e[:, 1], "var_0": 1.0, "var_1": 1.0})
    frame.to_csv(tmp_path / "named.csv", index=False, float_format="%.17g")
    args = ("diagnose", tmp_path / "named.csv", "--truth-columns", "ex,ey")
    line = error_line(*run(*args)[::2])
    assert "no estimate columns" in line and "--errors-only" in line
    code, out, err = run(*args, "--errors-only", "-f", "json")
    assert code == 0, err
    (seg,) = json.loads(out)["segments"]
    assert seg["label"] == "optimism" and 3.0 < seg["scale_factor"] < 5.3  # 4: ±5 s.e.
    assert "errors-only log: ex, ey are the errors e_k" in err
    line = error_line(*run(*args, "--errors-only", "--truth", tmp_path / "named.csv")[::2])
    assert "--errors-only needs no ground truth" in line


def test_split_runs_keep_what_the_file_said_once():
    """The runs of a Monte Carlo log keep its fitted-mean reason and their own epochs of
    the other convention's errors; the file's dropped and unpaired rows are counted once
    (they were dropped from every run)."""
    from dataclasses import replace as _replace

    from credcli.engine.config import Perturbation
    from credcli.io.logs import EstimatorLog, OtherConvention
    from credcli.segments import split_runs

    n = 6
    errors = np.arange(2 * n, dtype=float).reshape(n, 2)
    other = OtherConvention(Perturbation.LEFT, Perturbation.RIGHT, -errors)
    log = EstimatorLog(
        None,
        None,
        np.broadcast_to(np.eye(2), (n, 2, 2)).copy(),
        state_errors=errors,
        run=np.array(["b", "a", "b", "a", "b", "a"]),
        dropped_rows=3,
        unpaired=2,
        fitted_mean="aligned",
        other_convention=other,
    )
    runs = split_runs(log)
    assert [r.n for r in runs] == [3, 3]
    assert sum(r.dropped_rows for r in runs) == 3 and sum(r.unpaired for r in runs) == 2
    assert all(r.fitted_mean == "aligned" for r in runs)
    for r in runs:
        np.testing.assert_array_equal(r.other_convention.errors, -r.errors)
    plain = _replace(log, run=None)
    assert split_runs(plain)[0] is plain
