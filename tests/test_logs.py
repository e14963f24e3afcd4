"""Log loading: layouts, config mapping, and every bad-input case (one line, exit 2)."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from helpers import ROOT

from credcli.cli import main
from credcli.cli.settings import build_schema, load_config
from credcli.errors import CredcliError
from credcli.io.logs import LogSchema, load_log


def _frame(n=30, d=2, seed=0):
    gen = np.random.default_rng(seed)
    a = gen.normal(size=(n, d, d))
    cov = a @ np.swapaxes(a, 1, 2) + np.eye(d)
    truth = gen.normal(size=(n, d))
    est = truth + gen.normal(size=(n, d))
    cols = {"time": np.arange(n) * 0.1}
    cols |= {f"truth_{i}": truth[:, i] for i in range(d)}
    cols |= {f"est_{i}": est[:, i] for i in range(d)}
    return pd.DataFrame(cols), cov


def _with_cov(frame, cov, kind):
    frame = frame.copy()
    d = cov.shape[1]
    for i in range(d):
        for j in range(d):
            if kind == "full" or (kind == "upper" and j >= i):
                frame[f"cov_{i}_{j}"] = cov[:, i, j]
    if kind in ("var", "std"):
        for i in range(d):
            frame[f"{kind}_{i}"] = cov[:, i, i] if kind == "var" else np.sqrt(cov[:, i, i])
    return frame


@pytest.mark.parametrize("d", [1, 2, 3])
@pytest.mark.parametrize("kind", ["full", "upper"])
def test_full_and_upper_layouts(tmp_path, d, kind):
    frame, cov = _frame(d=d)
    path = tmp_path / "log.csv"
    _with_cov(frame, cov, kind).to_csv(path, index=False)
    log = load_log(path)
    assert log.dim == d and log.n == 30
    np.testing.assert_allclose(log.cov, cov, rtol=1e-14)
    np.testing.assert_allclose(
        log.errors,
        frame[[f"truth_{i}" for i in range(d)]].to_numpy()
        - frame[[f"est_{i}" for i in range(d)]].to_numpy(),
    )


@pytest.mark.parametrize("kind", ["var", "std"])
def test_diagonal_layouts(tmp_path, kind):
    frame, cov = _frame(d=3)
    path = tmp_path / "log.csv"
    _with_cov(frame, cov, kind).to_csv(path, index=False)
    log = load_log(path)
    np.testing.assert_allclose(
        log.cov, np.eye(3) * np.diagonal(cov, axis1=1, axis2=2)[:, None, :], rtol=1e-14
    )


def test_parquet_equals_csv(tmp_path):
    frame, cov = _frame()
    frame = _with_cov(frame, cov, "upper")
    frame["segment"] = ["a"] * 15 + ["b"] * 15
    frame.to_csv(tmp_path / "log.csv", index=False)
    frame.to_parquet(tmp_path / "log.parquet", index=False)
    a, b = load_log(tmp_path / "log.csv"), load_log(tmp_path / "log.parquet")
    # CSV text is parsed back to the nearest double by pandas >= 2.1, within an ulp before
    np.testing.assert_allclose(a.cov, b.cov, rtol=1e-15, atol=0)
    np.testing.assert_array_equal(a.segment, b.segment)
    np.testing.assert_allclose(a.time, b.time, rtol=1e-15, atol=0)


def _loaded_both_ways(path, drop_invalid):
    """load_log (Arrow's buffers) and the same file through pandas.read_parquet: the log's
    arrays, or the error message."""
    from credcli.io.logs import log_from_frame

    out = []
    for read in (
        lambda: load_log(path, drop_invalid=drop_invalid),
        lambda: log_from_frame(pd.read_parquet(path), LogSchema(), str(path), drop_invalid),
    ):
        try:
            log = read()
        except CredcliError as exc:
            out.append(exc.message)
            continue
        out.append([log.truth, log.estimate, log.cov, log.time, log.segment, log.rows])
    return out


@pytest.mark.parametrize(
    "case",
    [
        "float",
        "int",
        "float32",
        "null_float",
        "null_int",
        "null_segment",
        "int_segment",
        "category_segment",
        "bool",
        "text",
    ],
)
@pytest.mark.parametrize("drop_invalid", [False, True])
def test_parquet_columns_read_from_arrow_equal_pandas(tmp_path, case, drop_invalid):
    import pyarrow as pa
    import pyarrow.parquet as pq

    frame, cov = _frame(n=40)
    frame = _with_cov(frame, cov, "upper")
    frame["segment"] = np.repeat(["a", "b", "a", "c"], 10)
    if case == "int":
        frame["truth_0"] = np.arange(40) * 3 - 7
    elif case == "float32":
        frame["est_1"] = frame["est_1"].astype(np.float32)
    elif case == "null_float":
        frame.loc[[3, 17], "cov_0_0"] = np.nan
    elif case == "null_int":
        frame["truth_1"] = pd.array(np.arange(40), dtype="Int64")
        frame.loc[5, "truth_1"] = pd.NA
    elif case == "null_segment":
        frame["segment"] = frame["segment"].astype(object)
        frame.loc[12, "segment"] = None
    elif case == "int_segment":
        frame["segment"] = np.repeat([4, 2, 4, 9], 10)
    elif case == "category_segment":  # stored as an Arrow dictionary column
        frame["segment"] = frame["segment"].astype("category")
    elif case == "bool":
        frame["est_0"] = frame.index % 2 == 0
    elif case == "text":
        frame["est_0"] = frame["est_0"].astype(str)
        frame.loc[21, "est_0"] = "n/a"
    path = tmp_path / "log.parquet"
    # row groups of 7 rows: each column is read as several chunks
    pq.write_table(pa.Table.from_pandas(frame, preserve_index=False), path, row_group_size=7)
    fast, slow = _loaded_both_ways(path, drop_invalid)
    if isinstance(slow, str):
        assert fast == slow
        return
    for a, b in zip(fast, slow):
        if a is None:
            assert b is None
        else:
            assert a.dtype == b.dtype or a.dtype.kind == b.dtype.kind == "O"
            np.testing.assert_array_equal(a, b)


def test_custom_layout_from_config_and_cli_precedence(tmp_path):
    frame, cov = _frame()
    renamed = pd.DataFrame(
        {
            "t": frame["time"],
            "x_true": frame["truth_0"],
            "y_true": frame["truth_1"],
            "x_est": frame["est_0"],
            "y_est": frame["est_1"],
            "pxx": cov[:, 0, 0],
            "pxy": cov[:, 0, 1],
            "pyy": cov[:, 1, 1],
            "other_x": frame["truth_0"] + 1.0,
        }
    )
    path = tmp_path / "custom.csv"
    renamed.to_csv(path, index=False)
    config = tmp_path / "layout.toml"
    config.write_text(
        '[columns]\ntime = "t"\ntruth_columns = ["x_true", "y_true"]\n'
        'estimate_columns = ["x_est", "y_est"]\ncov_columns = ["pxx", "pxy", "pyy"]\n'
    )
    log = load_log(path, build_schema(load_config(config), {}))
    np.testing.assert_allclose(log.cov, cov)
    np.testing.assert_allclose(log.time, frame["time"])
    # CLI over config: --truth-columns replaces the config's truth columns
    schema = build_schema(load_config(config), {"truth_columns": ("other_x", "y_true")})
    shifted = load_log(path, schema)
    np.testing.assert_allclose(shifted.truth[:, 0], log.truth[:, 0] + 1.0)


def test_bundled_config_example_maps_its_layout(tmp_path):
    """configs/custom-layout.toml documents a renamed layout; it must load such a file."""
    frame, cov = _frame()
    pd.DataFrame(
        {
            "t": frame["time"],
            "run": "r1",
            "x": frame["truth_0"],
            "y": frame["truth_1"],
            "x_hat": frame["est_0"],
            "y_hat": frame["est_1"],
            "sigma_x": np.sqrt(cov[:, 0, 0]),
            "sigma_y": np.sqrt(cov[:, 1, 1]),
        }
    ).to_csv(tmp_path / "nav.csv", index=False)
    layout = build_schema(load_config(ROOT / "configs" / "custom-layout.toml"), {})
    log = load_log(tmp_path / "nav.csv", layout)
    np.testing.assert_allclose(np.diagonal(log.cov, axis1=1, axis2=2)[:, 0], cov[:, 0, 0])
    assert set(log.segment) == {"r1"}


# --- bad input: each case gives one specific line on stderr and exit code 2 ------------


def _run(capsys, *args):
    code = main(list(map(str, args)))
    out, err = capsys.readouterr()
    return code, out, err


def _write(tmp_path, text, name="bad.csv"):
    path = tmp_path / name
    path.write_text(text)
    return path


GOOD_HEADER = "time,truth_0,truth_1,est_0,est_1,var_0,var_1\n"
GOOD_ROW = "0.0,1,2,1.1,2.1,0.5,0.5\n"


@pytest.mark.parametrize(
    "text, expected",
    [
        ("", "file is empty"),
        (GOOD_HEADER, "header has no rows"),
        ("time,truth_0,est_0\n1,2,3\n", "no covariance columns found"),
        (
            "time,truth_0,truth_1,est_0,var_0,var_1\n" + "1,2,3,4,5,6\n",
            "missing estimate column(s) est_1",
        ),
        (
            "time,truth_0,truth_1,est_0,est_1,est_2,var_0,var_1\n1,2,3,4,5,6,7,8\n",
            "dimensions do not match",
        ),
        (
            "time,truth_0,truth_1,est_0,est_1,var_0,var_1,var_2\n1,2,3,4,5,6,7,8\n",
            "do not match d = 2",
        ),
        (
            GOOD_HEADER + GOOD_ROW + "0.1,1,abc,1,2,0.5,0.5\n",
            "row 2, column 'truth_1': 'abc' is not a number",
        ),
        (
            GOOD_HEADER + GOOD_ROW + "0.1,1,nan,1,2,0.5,0.5\n" + "0.2,1,2,inf,2,0.5,0.5\n",
            "NaN, Inf or empty value in row(s) 2, 3",
        ),
        (GOOD_HEADER + GOOD_ROW + "0.1,1,2,1,2,,0.5\n", "row(s) 2 (first in column 'var_0')"),
        (
            GOOD_HEADER + GOOD_ROW + "0.1,1,2,1,2,-0.5,0.5\n",
            "row 2: covariance is not positive definite",
        ),
        (
            "truth_0,truth_1,est_0,est_1,cov_0_0,cov_0_1,cov_1_0,cov_1_1\n1,2,1,2,1,0.5,0.1,1\n",
            "row 1: covariance is not symmetric",
        ),
        (
            "truth_0,truth_1,est_0,est_1,cov_0_0,cov_1_1\n1,2,1,2,1,1\n",
            "incomplete covariance: missing column(s) cov_0_1",
        ),
        (
            "truth_0,est_0,cov_0_0,cov_1_1\n1,2,1,1\n",
            "refers to index 1 but the truth/estimate have d = 1",
        ),
        ("x,y\n1,2\n", "no truth columns (truth_0, truth_1, …) found; columns found: x, y"),
    ],
)
def test_bad_input_one_line_exit_2(tmp_path, capsys, text, expected):
    path = _write(tmp_path, text)
    code, out, err = _run(capsys, "diagnose", path)
    assert code == 2
    assert expected in err
    assert err.count("\n") == 1 and "Traceback" not in err
    assert str(path) in err
    assert out == ""


def test_missing_file(tmp_path, capsys):
    code, _, err = _run(capsys, "diagnose", tmp_path / "nope.csv")
    assert code == 2 and "nope.csv: file not found" in err


def test_unknown_column_option_names_it(tmp_path, capsys):
    path = _write(tmp_path, GOOD_HEADER + GOOD_ROW * 3)
    code, _, err = _run(capsys, "diagnose", path, "--truth-columns", "tx,ty")
    assert code == 2 and "missing column(s) tx, ty; columns found: time, truth_0" in err
    code, _, err = _run(capsys, "diagnose", path, "--time-column", "stamp")
    assert code == 2 and "time column 'stamp' not found" in err


def test_drop_invalid_reports_count(tmp_path, capsys):
    gen = np.random.default_rng(0)
    rows = "".join(
        f"{k / 10},{k},{k},{k + gen.normal()},{k + gen.normal()},1,1\n" for k in range(20)
    )
    path = _write(tmp_path, GOOD_HEADER + rows + "9,1,nan,1,1,1,1\n" + "9.1,1,1,inf,1,1,1\n")
    code, out, err = _run(capsys, "diagnose", path, "--drop-invalid", "-f", "json")
    assert code == 0
    import json

    doc = json.loads(out)
    assert doc["logs"][0]["dropped_rows"] == 2 and doc["segments"][0]["n"] == 20


def test_degenerate_segment_is_insufficient_and_the_others_are_diagnosed(tmp_path, capsys):
    """Errors constant in one segment (a singular MSE) decide nothing there, and end
    nothing else: the other segment gets its verdict (issue 31, item 9)."""
    import json

    gen = np.random.default_rng(3)
    header = "time,segment,truth_0,truth_1,est_0,est_1,std_0,std_1\n"
    flat = "".join(f"{k / 10},flat,{k},{k},{k + 0.5},{k - 0.3},1,1\n" for k in range(20))
    noisy = "".join(
        f"{2 + k / 10},noisy,{k},{k},{k + gen.normal()},{k + gen.normal()},1,1\n"
        for k in range(200)
    )
    path = _write(tmp_path, header + flat + noisy)
    code, out, _ = _run(capsys, "diagnose", path, "-f", "json")
    assert code == 0
    by_name = {s["segment"]: s for s in json.loads(out)["segments"]}
    assert by_name["flat"]["label"] == "insufficient-data"
    assert "span fewer than d dimensions" in by_name["flat"]["reason"]
    assert by_name["noisy"]["label"] != "insufficient-data"


def test_invalid_config_file(tmp_path, capsys):
    path = _write(tmp_path, GOOD_HEADER + GOOD_ROW)
    cfg = _write(tmp_path, "[diagnosis]\ntaux = 1\n", "c.toml")
    code, _, err = _run(capsys, "diagnose", path, "--config", cfg)
    assert code == 2 and "unknown key(s) taux" in err
    cfg = _write(tmp_path, "[diagnosis\n", "c2.toml")
    code, _, err = _run(capsys, "diagnose", path, "--config", cfg)
    assert code == 2 and "not valid TOML" in err


def test_config_tables_and_keys_that_nothing_reads_are_errors(tmp_path, capsys):
    path = _write(tmp_path, GOOD_HEADER + GOOD_ROW)
    cfg = _write(tmp_path, "[plots]\ndpi = 200\n", "c.toml")
    code, _, err = _run(capsys, "diagnose", path, "--config", cfg)
    assert code == 2 and "unknown table(s) or key(s) plots" in err
    # a table that diagnose does not read is still checked: a typo there is an error too
    cfg = _write(tmp_path, "[uwb]\nmax_sped = 0.2\n", "c1.toml")
    code, _, err = _run(capsys, "diagnose", path, "--config", cfg)
    assert code == 2 and "config [uwb]: unknown key(s) max_sped; allowed: " in err
    cfg = _write(tmp_path, '[segments]\nwindw = "5s"\n', "c2.toml")
    code, _, err = _run(capsys, "diagnose", path, "--config", cfg)
    assert code == 2 and "config [segments]: unknown key(s) windw" in err


def test_api_raises_credcli_error(tmp_path):
    with pytest.raises(CredcliError, match="file not found"):
        load_log(tmp_path / "x.csv")
    assert LogSchema().updated(time=None).time == "time"


def test_two_by_two_positive_definiteness_matches_eigvalsh():
    """The closed-form smallest eigenvalue 1 − |ρ| of 2×2 correlation matrices decides as
    eigvalsh of the correlation matrix does, from 1e-250 to 1e250, with the variances up to
    10^6 apart, and near the 1e-12 threshold (cases within 0.1 % of it not asked)."""
    from credcli.io.logs import CORRELATION_FLOOR, CovKind, validated_cov

    rng = np.random.default_rng(0)
    for exponent in (-250, 0, 250):
        gap = rng.choice([1e-14, 1e-12, 1e-10, 0.3], 2000)
        rho = rng.choice([-1.0, 1.0], 2000) * (1.0 - gap)
        sd = 10.0 ** rng.uniform(-3, 3, (2000, 2))
        cov = np.empty((2000, 2, 2))
        cov[:, 0, 0], cov[:, 1, 1] = sd[:, 0] ** 2, sd[:, 1] ** 2
        cov[:, 0, 1] = cov[:, 1, 0] = rho * sd[:, 0] * sd[:, 1]
        cov *= 10.0**exponent
        rows = np.arange(1, 2001)
        for k in range(0, 2000, 7):
            one = cov[k : k + 1]
            root = np.sqrt(np.diagonal(one, axis1=1, axis2=2))[0]
            eig = np.linalg.eigvalsh(one[0] / np.outer(root, root))[0]
            if abs(eig / CORRELATION_FLOOR - 1.0) < 1e-3:
                continue
            try:
                validated_cov(one.copy(), rows[k : k + 1], "x", CovKind.FULL)
                accepted = True
            except CredcliError:
                accepted = False
            assert accepted == (eig > CORRELATION_FLOOR), (exponent, k, eig)


def test_a_covariance_is_refused_for_what_it_is():
    """A variance not positive, standard deviations more than 10^8 apart, and components
    correlated ±1 are each refused by name; a graded but positive definite covariance
    (standard deviations 10^7 apart, as metres beside 0.1 µrad) is not (it was: its
    smallest eigenvalue is below 1e-12 of its largest entry)."""
    from credcli.io.logs import CovKind, validated_cov

    rows = np.arange(1, 2)
    graded = np.diag([1e2, 1e2, 1e-12])
    graded[0, 2] = graded[2, 0] = 0.5 * 1e1 * 1e-6
    validated_cov(graded[None].copy(), rows, "x", CovKind.FULL)
    cases = [
        (
            np.diag([1.0, 0.0, 1.0]),
            r"row 1: covariance is not positive definite \(a variance is 0\)",
        ),
        (np.diag([1.0, 1e-17, 1.0]), r"standard deviations are 3.16e\+08 times apart"),
        (np.array([[1.0, 2.0, 0], [2.0, 4.0, 0], [0, 0, 1.0]]), r"of its correlation matrix is"),
    ]
    for cov, message in cases:
        with pytest.raises(CredcliError, match=message):
            validated_cov(cov[None].copy(), rows, "x", CovKind.FULL)
    with pytest.raises(CredcliError, match=r"a variance is -1"):
        validated_cov(np.diag([1.0, -1.0])[None].copy(), rows, "x", CovKind.VAR)


def test_a_segment_that_loses_every_row_is_named(tmp_path, capsys):
    """--drop-invalid that empties a segment says so (it only counted the rows before, and
    the segment was gone from the table without a word)."""
    gen = np.random.default_rng(1)
    header = "time,segment,truth_0,truth_1,est_0,est_1,cov_0_0,cov_0_1,cov_1_1\n"
    rows = [
        f"{k / 10},{'turn' if k >= 40 else 'cruise'},{gen.normal()},{gen.normal()},0,"
        f"{'nan' if k >= 40 else 0},1,0,1\n"
        for k in range(80)
    ]
    path = _write(tmp_path, header + "".join(rows))
    code, out, err = _run(capsys, "diagnose", path, "--drop-invalid", "-f", "json")
    assert code == 0, err
    assert "segment(s) 'turn' had a NaN/Inf value in every row" in err
    import json

    doc = json.loads(out)
    assert [s["segment"] for s in doc["segments"]] == ["cruise"]
    assert any("'turn'" in note for note in doc["logs"][0]["notes"])


def test_time_that_goes_back_within_a_segment_is_noted(tmp_path, capsys):
    """The memory and the whiteness test read the epochs in file order: where time goes
    back within a segment (not between segments) a note says so (it was silent)."""
    gen = np.random.default_rng(2)

    def log(times, names):
        header = "time,segment,truth_0,truth_1,est_0,est_1,cov_0_0,cov_0_1,cov_1_1\n"
        rows = "".join(
            f"{t},{s},{gen.normal()},{gen.normal()},0,0,1,0,1\n" for t, s in zip(times, names)
        )
        return _write(tmp_path, header + rows, f"{len(times)}-{names[0]}.csv")

    restart = log([k / 10 for k in range(60)] * 2, ["a"] * 60 + ["b"] * 60)
    code, _, err = _run(capsys, "diagnose", restart)
    assert code == 0 and "time goes back" not in err
    times = [k / 10 for k in range(60)]
    times[30], times[31] = times[31], times[30]
    swapped = log(times + [6 + k / 10 for k in range(60)], ["b"] * 120)
    code, _, err = _run(capsys, "diagnose", swapped)
    assert code == 0
    assert "time goes back at row 32 in segment 'b' (1 place(s) in all)" in err


def test_monte_carlo_runs_in_one_file_restart_their_clock_without_a_note(tmp_path, capsys):
    """Each run restarts its time: no note that time goes back (it was given, once per
    run); a run that --drop-invalid empties is named, as a segment is."""
    gen = np.random.default_rng(3)
    header = "time,run,truth_0,truth_1,est_0,est_1,cov_0_0,cov_0_1,cov_1_1\n"
    rows = "".join(
        f"{k / 10},{r},{'nan' if r == 2 else gen.normal()},{gen.normal()},0,0,1,0,1\n"
        for r in range(3)
        for k in range(60)
    )
    path = _write(tmp_path, header + rows, "runs.csv")
    code, _, err = _run(capsys, "diagnose", path, "--monte-carlo", "--drop-invalid")
    assert code == 0, err
    assert "time goes back" not in err
    assert err.count("run(s) '2' had a NaN/Inf value in every row") == 1
