"""`credcli diagnose` end to end: formats, determinism, JSON equal to the library."""

from __future__ import annotations

import csv
import io
import json
import subprocess
import sys

import numpy as np
import pytest
from helpers import SAMPLE, error_line, run

from credcli import DiagnosisConfig
from credcli.cli import main
from credcli.engine.diagnosis import diagnose_segments
from credcli.io.logs import load_log
from credcli.segments import split

LOG = SAMPLE / "estimator_log.csv"
REQUIRED = {
    "segment",
    "n",
    "dim",
    "label",
    "elt_statistic",
    "elt_pvalue",
    "nci",
    "nci_centered",
    "anees",
    "nees_label",
    "nci_label",
    "nll",
    "es",
    "delta_nll_minus",
    "delta_nll_plus",
    "delta_es_minus",
    "delta_es_plus",
    "srd_nll",
    "srd_es",
}


def _run(capsys, *args):
    code = main([str(a) for a in args])
    out, err = capsys.readouterr()
    return code, out, err


def test_json_equals_library_result(capsys):
    code, out, _ = _run(capsys, "diagnose", LOG, "-f", "json", "--seed", "3", "--metrics", "all")
    assert code == 0
    doc = json.loads(out)
    assert set(doc) >= {"parameters", "version", "segments"}
    assert doc["parameters"]["seed"] == 3 and doc["parameters"]["n_flips"] == 1000
    log = load_log(LOG)
    results = diagnose_segments(log, split(log), DiagnosisConfig(metrics="all"), seed=3)
    assert [s["segment"] for s in doc["segments"]] == [r.segment for r in results]
    for rec, res in zip(doc["segments"], results):
        assert REQUIRED <= set(rec)
        d = res.diagnosis
        assert rec["label"] == d.label.value
        assert rec["elt_pvalue"] == d.elt.pvalue and rec["elt_statistic"] == d.elt.statistic
        assert rec["nci"] == d.nci and rec["nci_centered"] == d.nci_centered
        assert rec["anees"] == d.anees and "cov_scale" not in rec  # one name: anees
        assert rec["nees_label"] == d.nees_label.value and rec["nci_label"] == d.nci_label.value
        assert rec["nll"] == d.scores.nll and rec["es"] == d.scores.es
        assert rec["delta_es_plus"] == d.probes.delta_es_plus and rec["srd_nll"] == d.probes.srd_nll


def test_sample_log_labels_differ_and_values_are_null_when_not_computed(capsys):
    code, out, _ = _run(capsys, "diagnose", LOG, "-f", "json")
    doc = json.loads(out)
    labels = [s["label"] for s in doc["segments"]]
    assert labels == [
        "credible",
        "optimism",
        "pessimism",
        "bias",
        "pessimism+bias",
        "optimism+bias",
    ]
    cruise = doc["segments"][0]
    assert cruise["delta_nll_minus"] is None and cruise["nll"] is None  # probes not needed
    assert all(s["delta_nll_minus"] is None for s in doc["segments"])  # calibrated: no probes
    _, out, _ = _run(capsys, "diagnose", LOG, "-f", "json", "--variant", "ks")
    urban = json.loads(out)["segments"][-1]
    assert urban["delta_nll_minus"] is not None  # ks: optimism+smm goes through the probes


@pytest.mark.parametrize("fmt", ["table", "csv", "json", "markdown"])
def test_same_seed_same_bytes(tmp_path, capsys, fmt):
    outs = []
    for k in range(2):
        path = tmp_path / f"out{k}.{fmt}"
        assert _run(capsys, "diagnose", LOG, "-f", fmt, "--seed", "11", "-o", path)[0] == 0
        outs.append(path.read_bytes())
    assert outs[0] == outs[1] and len(outs[0]) > 100
    path = tmp_path / "other"
    _run(capsys, "diagnose", LOG, "-f", "json", "--seed", "12", "-o", path)
    if fmt == "json":
        assert path.read_bytes() != outs[0]


def test_csv_holds_every_key(capsys):
    _, out, _ = _run(capsys, "diagnose", LOG, "-f", "csv")
    rows = list(csv.DictReader(io.StringIO(out)))
    _, js, _ = _run(capsys, "diagnose", LOG, "-f", "json")
    keys = list(json.loads(js)["segments"][0])
    assert len(rows) == 6 and list(rows[0]) == keys and REQUIRED <= set(keys)
    assert float(rows[1]["nci"]) > 0.5


def test_markdown_and_table(capsys):
    _, out, _ = _run(capsys, "diagnose", LOG, "-f", "markdown")
    assert out.startswith("### credcli diagnose") and "| hover | 300 | 2 | pessimism |" in out
    _, out, _ = _run(capsys, "diagnose", LOG)
    for word in ("segment", "ELT p", "NCI", "ANEES", "NEES baseline", "optimism+bias"):
        assert word in out


def test_window_by_epochs_and_duration(capsys):
    _, out, _ = _run(capsys, "diagnose", LOG, "-f", "json", "--window", "600")
    segs = json.loads(out)["segments"]
    assert [s["segment"] for s in segs] == ["w001", "w002", "w003", "run"]  # and the run
    assert [s["n"] for s in segs] == [600, 600, 600, 1800]
    _, out, _ = _run(capsys, "diagnose", LOG, "-f", "json", "--window", "45s")
    segs = json.loads(out)["segments"]
    assert [s["n"] for s in segs] == [450, 450, 450, 450, 1800]
    assert segs[1]["t_start"] == pytest.approx(45.0)
    _, out, _ = _run(capsys, "diagnose", LOG, "-f", "json", "--whole")
    assert json.loads(out)["segments"][0]["n"] == 1800


def test_insufficient_data_segment(capsys):
    _, out, _ = _run(capsys, "diagnose", LOG, "-f", "json", "--window", "299")
    last = json.loads(out)["segments"][-2]  # the last window; the run follows
    assert last["n"] == 1800 - 6 * 299 and last["label"] == "insufficient-data"
    assert last["elt_pvalue"] is None


def test_output_is_atomic_and_never_over_an_input(tmp_path, capsys):
    copy = tmp_path / "log.csv"
    copy.write_bytes(LOG.read_bytes())
    code, _, err = _run(capsys, "diagnose", copy, "-o", copy)
    assert code == 2 and "is also an input" in err
    assert copy.read_bytes() == LOG.read_bytes()
    out = tmp_path / "result.json"
    assert _run(capsys, "diagnose", copy, "-f", "json", "-o", out)[0] == 0
    assert json.loads(out.read_text())["segments"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["log.csv", "result.json"]  # no temp left
    code, _, err = _run(capsys, "diagnose", copy, "-o", tmp_path / "no" / "dir.json")
    assert code == 2 and "does not exist" in err


def test_bad_options_are_one_line(capsys):
    code, _, err = _run(capsys, "diagnose", LOG, "--window", "abc")
    assert code == 2 and err.startswith("credcli: error: --window 'abc'") and err.count("\n") == 1
    code, _, err = _run(capsys, "diagnose", LOG, "--tau", "-1")
    assert code == 2 and "--tau must be finite and > 0" in err
    code, _, err = _run(capsys, "diagnose", LOG, "--format", "xml")
    assert code == 2 and err.count("\n") == 1


def test_parquet_sample_gives_same_labels(capsys):
    """The same records from the CSV and the Parquet sample: words equal, numbers to 1e-9
    (pandas < 2.1 parses CSV text to within an ulp, not to the nearest double)."""
    import pandas as pd

    _, a, _ = _run(capsys, "diagnose", LOG, "-f", "csv")
    _, b, _ = _run(capsys, "diagnose", SAMPLE / "estimator_log.parquet", "-f", "csv")
    left, right = (pd.read_csv(io.StringIO(t)).drop(columns="log") for t in (a, b))
    assert list(left["label"]) == list(right["label"]) and len(left) == 6
    numeric = pd.api.types.is_numeric_dtype
    lists = [
        k
        for k in left
        if not numeric(left[k])
        and left[k].astype(str).str.fullmatch(r"'?[-+.\deE]+( [-+.\deE]+)+").all()
    ]
    assert {"bias", "bias_stderr", "direction_factors"} <= set(lists)
    for key in lists:  # lists: space-separated numbers ('-' first: after an apostrophe)
        for frame in (left, right):
            frame[key] = [np.array(v.lstrip("'").split(), dtype=float) for v in frame[key]]
        np.testing.assert_allclose(
            np.stack(left.pop(key)), np.stack(right.pop(key)), rtol=1e-9, atol=1e-12
        )
    pd.testing.assert_frame_equal(left, right, rtol=1e-9)


def test_console_script_runs_as_subprocess():
    proc = subprocess.run(
        [sys.executable, "-m", "credcli", "diagnose", str(LOG), "-f", "json"],
        capture_output=True,
        text=True,
        check=False,
    )
    assert proc.returncode == 0, proc.stderr
    assert len(json.loads(proc.stdout)["segments"]) == 6
    proc = subprocess.run(
        [sys.executable, "-m", "credcli", "diagnose", "missing.csv"],
        capture_output=True,
        text=True,
        check=False,
    )
    assert proc.returncode == 2 and proc.stderr == "credcli: error: missing.csv: file not found\n"


def test_multiple_logs_have_a_log_column(tmp_path, capsys):
    _, out, _ = _run(capsys, "diagnose", LOG, SAMPLE / "estimator_log.parquet", "-f", "json")
    doc = json.loads(out)
    assert len(doc["segments"]) == 12 and len(doc["logs"]) == 2
    assert np.unique([s["log"] for s in doc["segments"]]).size == 2


def test_only_the_command_line_tunes_its_allocator(monkeypatch, tmp_path, capsys):
    """keep_freed_memory changes a process-wide malloc setting: the command line does it
    for a command it runs, not for --help, and the library never does."""
    import credcli
    from credcli.schedule import pool as parallel

    calls = []
    monkeypatch.setattr(parallel, "keep_freed_memory", lambda: calls.append(True))
    assert main(["--help"]) == 0
    assert main(["diagnose", "--help"]) == 0
    assert calls == []
    credcli.diagnose_log(load_log(LOG))
    assert calls == []
    assert main(["diagnose", str(LOG), "-f", "json", "-o", str(tmp_path / "d.json")]) == 0
    assert calls == [True]


def test_the_subsample_note_names_the_log_among_several(tmp_path, capsys):
    """Two logs with the same segment names: the ELT-subsample note named segments only."""
    import shutil

    a, b = tmp_path / "a.csv", tmp_path / "b.csv"
    shutil.copy(LOG, a)
    shutil.copy(LOG, b)
    code, out, err = _run(capsys, "diagnose", str(a), str(b), "--max-elt-epochs", "100")
    assert code == 0, err
    text = "".join((out + err).split())  # the notes wrap at the terminal's width, anywhere
    note = text[text.index("randomsubsample") :]
    assert f"{a}:cruise" in note and f"{b}:cruise" in note
    code, out, err = _run(capsys, "diagnose", str(a), "--max-elt-epochs", "100")
    assert "segment(s)cruise,turn" in "".join((out + err).split())  # one log: as before


def test_standard_input_given_twice_is_refused(monkeypatch):
    """'-' twice: the second read found no data and said "<stdin>: holds no data"."""
    monkeypatch.setattr("sys.stdin", io.TextIOWrapper(io.BytesIO(b"time,truth_0\n")))
    code, _, err = run("diagnose", "-", "-")
    assert "'-' (standard input) is given 2 times" in error_line(code, err)


def test_a_config_files_bad_setting_is_named_as_the_config_s(tmp_path):
    """A bad seed or a missing truth file that a config file gave said only "the seed must
    be …" or "nope.csv: file not found", as if typed on the command line."""
    config = tmp_path / "c.toml"
    config.write_text("[diagnosis]\nseed = -1\n")
    code, _, err = run("diagnose", SAMPLE / "estimator_log.csv", "--config", config)
    assert error_line(code, err).startswith("credcli: error: config [diagnosis] seed:")
    code, _, err = run("diagnose", SAMPLE / "estimator_log.csv", "--seed", "-1")
    assert error_line(code, err).startswith("credcli: error: --seed:")
    config.write_text(f'[input]\ntruth = "{tmp_path / "nope.csv"}"\n')
    code, _, err = run("diagnose", SAMPLE / "estimator_log.csv", "--config", config)
    line = error_line(code, err)
    assert "config [input] truth:" in line and "nope.csv: file not found" in line


def test_standard_input_as_log_and_truth_is_refused(monkeypatch):
    """'-' for the log and for --truth: the second read found no data."""
    monkeypatch.setattr("sys.stdin", io.TextIOWrapper(io.BytesIO(b"time,truth_0\n")))
    code, _, err = run("diagnose", "-", "--truth", "-")
    assert "'-' (standard input) is given 2 times" in error_line(code, err)
