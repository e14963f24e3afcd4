"""The edge under signals, streams, odd files and extreme numbers (issue 21): every run ends
with the promised exit code and one specific line, and leaves no file or process behind."""

from __future__ import annotations

import gzip
import json
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from helpers import LOG, error_line, once_per_run, run

ROOT = Path(__file__).resolve().parents[1]
FORMATS = ROOT / "sample_data" / "formats"
CREDCLI = [sys.executable, "-m", "credcli"]
IN_A_TERMINAL = [
    sys.executable,
    "-c",
    "import os, signal, sys; signal.signal(signal.SIGINT, signal.SIG_DFL); "
    "os.execv(sys.executable, [sys.executable, '-m', 'credcli', *sys.argv[1:]])",
]
"""``credcli`` as a terminal starts it in the foreground, where Ctrl-C reaches it: SIGINT
not ignored. A background job of a non-interactive shell (``pytest ... &`` in a script)
starts with SIGINT ignored, every process it starts inherits that, and a Python started
so keeps it ignored: the Ctrl-C tests would then wait for a whole run and fail with exit
0, whatever credcli does. The same process after ``exec`` (the same pid)."""


@pytest.fixture(scope="module")
def long_log(tmp_path_factory) -> Path:
    """1,600,000 credible epochs in 1,600 segments: a run of many seconds, with worker
    processes, however fast the diagnosis becomes (400 segments ended within the tests'
    waits once the ELT's rechecks got cheaper). Written once per test run, whichever
    test process asks first (:func:`once_per_run`)."""
    return Path(once_per_run(tmp_path_factory, "long_log", _write_long_log)["path"])


def _write_long_log(where: Path) -> dict:
    rng = np.random.default_rng(0)
    n = 1_600_000
    errors = rng.standard_normal((n, 2))
    frame = pd.DataFrame(
        {
            "time": np.arange(n) * 0.1,
            "segment": np.repeat(np.arange(n // 1000), 1000).astype(str),
            "truth_0": errors[:, 0],
            "truth_1": errors[:, 1],
            "est_0": 0.0,
            "est_1": 0.0,
            "cov_0_0": 1.0,
            "cov_0_1": 0.0,
            "cov_1_1": 1.0,
        }
    )
    path = where / "long.parquet"
    frame.to_parquet(path)
    return {"path": str(path)}


def _children(pid: int) -> set[int]:
    found = set()
    for task in Path(f"/proc/{pid}/task").glob("*"):
        try:
            found |= {int(c) for c in (task / "children").read_text().split()}
        except OSError:
            pass
    return found


def _alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return False
    return state != "Z"


@pytest.mark.skipif(sys.platform != "linux", reason="reads /proc")
@pytest.mark.parametrize("signum", [signal.SIGTERM, signal.SIGINT])
def test_a_signal_stops_workers_and_leaves_nothing(tmp_path, long_log, signum):
    out = tmp_path / "out.json"
    proc = subprocess.Popen(
        [*IN_A_TERMINAL, "diagnose", long_log, "-f", "json", "-o", out, "--jobs", "2"],
        stderr=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
        start_new_session=True,
    )
    workers: set[int] = set()
    deadline = time.monotonic() + 60
    while len(workers) < 2 and time.monotonic() < deadline and proc.poll() is None:
        workers |= _children(proc.pid)
        time.sleep(0.05)
    assert len(workers) >= 2, "the workers never started"
    time.sleep(0.5)
    os.killpg(proc.pid, signum) if signum == signal.SIGINT else proc.send_signal(signum)
    _, err = proc.communicate(timeout=60)
    expected = 143 if signum == signal.SIGTERM else 130
    assert proc.returncode == expected, err
    lines = [line for line in err.splitlines() if line.strip()]
    assert len(lines) == 1 and "Traceback" not in err, err
    assert ("terminated" if signum == signal.SIGTERM else "interrupted") in lines[0]
    time.sleep(0.5)
    assert not [pid for pid in workers if _alive(pid)], "worker processes outlived the run"
    assert list(tmp_path.iterdir()) == []


@pytest.mark.skipif(not hasattr(os, "O_TMPFILE"), reason="Linux's O_TMPFILE")
def test_an_output_has_no_name_until_it_is_complete(tmp_path, monkeypatch):
    """Written unnamed: a SIGKILL while writing cannot leave a temporary file behind."""
    import credcli.io.files as files

    seen = []
    real = files.os.link

    def link(src, dst, **kw):
        seen.append(sorted(p.name for p in tmp_path.iterdir()))  # just before the name
        return real(src, dst, **kw)

    monkeypatch.setattr(files.os, "link", link)
    files.write_atomic(tmp_path / "out.json", "{}\n")
    assert seen == [[]]
    assert [p.name for p in tmp_path.iterdir()] == ["out.json"]
    assert (tmp_path / "out.json").read_text() == "{}\n"


def test_an_existing_output_is_replaced_whole(tmp_path):
    from credcli.io.files import write_atomic

    target = tmp_path / "out.txt"
    target.write_text("old")
    write_atomic(target, "new")
    assert target.read_text() == "new" and [p.name for p in tmp_path.iterdir()] == ["out.txt"]
    assert target.stat().st_mode & 0o777 == 0o666 & ~_umask()


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


# --- streams as inputs -----------------------------------------------------------------------


def _json_labels(text: str) -> list:
    return [(s["segment"], s["label"]) for s in json.loads(text)["segments"]]


def _run_on_stdin(data: bytes, *args) -> tuple[int, str, str]:
    """credcli in process with ``data`` on a pipe as its standard input, as a shell's
    ``cat log.csv | credcli diagnose -`` gives it (read through ``sys.stdin``)."""
    read, write = os.pipe()

    def feed():
        try:
            with open(write, "wb") as pipe:
                pipe.write(data)
        except BrokenPipeError:  # the command stopped reading
            pass

    writer = threading.Thread(target=feed)
    writer.start()
    saved = sys.stdin
    try:
        with open(read) as sys.stdin:
            return run(*args)
    finally:
        sys.stdin = saved
        writer.join(10)


def test_stdin_is_dash():
    expected = _json_labels(run("diagnose", LOG, "-f", "json")[1])
    code, out, err = _run_on_stdin(LOG.read_bytes(), "diagnose", "-", "-f", "json")
    assert code == 0, err
    assert _json_labels(out) == expected
    assert json.loads(out)["logs"][0]["path"] == "<stdin>"


def test_gzip_stdin_and_parquet_stdin():
    expected = _json_labels(run("diagnose", LOG, "-f", "json")[1])
    for data in (gzip.compress(LOG.read_bytes()), LOG.with_suffix(".parquet").read_bytes()):
        code, out, err = _run_on_stdin(data, "diagnose", "-", "-f", "json")
        assert code == 0, err
        assert _json_labels(out) == expected


def test_a_fifo_is_read_like_a_file(tmp_path):
    """As `credcli diagnose <(zcat log.csv.gz)` gives it: a pipe read once."""
    fifo = tmp_path / "fifo"
    os.mkfifo(fifo)
    writer = threading.Thread(target=lambda: fifo.write_bytes(LOG.read_bytes()))
    writer.start()
    code, out, err = run("diagnose", fifo, "-f", "json")
    writer.join(10)
    assert code == 0, err
    assert _json_labels(out) == _json_labels(run("diagnose", LOG, "-f", "json")[1])


def test_empty_stdin_is_a_message_not_file_is_empty():
    line = error_line(*_run_on_stdin(b"", "diagnose", "-")[::2])
    assert "<stdin>" in line and "no data" in line


def test_truncated_gzip_is_exit_2_not_interrupted(tmp_path):
    path = tmp_path / "log.csv.gz"
    path.write_bytes(gzip.compress(LOG.read_bytes())[:4000])
    assert "ends early" in error_line(*run("diagnose", path)[::2])
    fifo = tmp_path / "fifo"
    os.mkfifo(fifo)
    writer = threading.Thread(target=lambda: fifo.write_bytes(path.read_bytes()))
    writer.start()
    line = error_line(*run("diagnose", fifo)[::2])
    writer.join(10)
    assert "ends early" in line and str(fifo) in line


# --- outputs and names -----------------------------------------------------------------------


def test_a_fifo_output_without_reader_is_refused_at_once(tmp_path):
    fifo = tmp_path / "fifo"
    os.mkfifo(fifo)
    start = time.monotonic()
    line = error_line(*run("diagnose", LOG, "-o", fifo)[::2])
    assert "no process is reading" in line and time.monotonic() - start < 30


@pytest.mark.parametrize(
    "args, words",
    [
        (["-o", "nowhere/"], "ends with '/'"),
        (["-o", ""], "empty file name"),
        (["-o", "a" * 300], "too long"),
        (["-o", "a/" * 3000 + "x"], "too long"),
    ],
)
def test_bad_output_names_are_one_line(tmp_path, monkeypatch, args, words):
    monkeypatch.chdir(tmp_path)
    line = error_line(*run("diagnose", LOG, *args)[::2])
    assert words in line and len(line) < 600
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("name, words", [("", "empty file name"), ("x" * 100_000, "too long")])
def test_bad_input_names_are_one_line(name, words):
    line = error_line(*run("diagnose", name)[::2])
    assert words in line and len(line) < 600


def test_stdout_on_a_full_device_is_exit_2():
    with open("/dev/full", "w") as full:
        proc = subprocess.run(
            [*CREDCLI, "diagnose", LOG, "-f", "json"], stdout=full, stderr=subprocess.PIPE
        )
    line = error_line(proc.returncode, proc.stderr.decode())
    assert "standard output" in line and "no space left" in line


def test_a_newline_in_a_file_name_stays_on_one_line(tmp_path):
    line = error_line(*run("diagnose", tmp_path / "new\nline.csv")[::2])
    assert "new\\nline.csv" in line


# --- numbers ---------------------------------------------------------------------------------


@pytest.fixture
def overflowing(tmp_path) -> Path:
    frame = pd.read_csv(LOG)
    frame.loc[frame.segment == "cruise", "truth_0"] *= 1e300
    path = tmp_path / "huge.csv"
    frame.to_csv(path, index=False)
    return path


@pytest.mark.parametrize("fmt", ["table", "json", "csv", "markdown"])
def test_errors_whose_squares_overflow_are_exit_2_in_every_format(overflowing, fmt):
    line = error_line(*run("diagnose", overflowing, "-f", fmt)[::2])
    assert "segment 'cruise'" in line and "overflows" in line


def test_baseline_of_overflowing_errors_is_exit_2(overflowing, tmp_path):
    line = error_line(*run("baseline", overflowing, "-o", tmp_path / "b.json")[::2])
    assert "overflows" in line and not (tmp_path / "b.json").exists()


def test_errors_and_covariances_at_the_edge_of_the_range_scale_out(tmp_path):
    """Errors of 1e145 with covariances of 1e290 (standard deviations within
    DEVIATION_RANGE, 1e-150 … 1e150): whitened, they are ordinary numbers."""
    frame = pd.read_csv(LOG)
    frame[["truth_0", "truth_1", "est_0", "est_1"]] *= 1e145
    frame[["cov_0_0", "cov_0_1", "cov_1_1"]] *= 1e290
    path = tmp_path / "scaled.csv"
    frame.to_csv(path, index=False)
    code, out, err = run("diagnose", path, "-f", "json")
    assert code == 0, err
    assert _json_labels(out) == _json_labels(run("diagnose", LOG, "-f", "json")[1])


def test_a_std_whose_square_overflows_is_named(tmp_path):
    frame = pd.read_csv(LOG).drop(columns=["cov_0_1"])
    frame = frame.rename(columns={"cov_0_0": "std_0", "cov_1_1": "std_1"})
    frame["std_0"] = 1e300
    path = tmp_path / "std.csv"
    frame.to_csv(path, index=False)
    line = error_line(*run("diagnose", path)[::2])
    assert "row 1" in line and "overflows" in line and "positive definite" not in line


def test_json_output_takes_non_finite_numbers():
    from credcli.report.render import OutputFormat, json_safe, to_text
    from credcli.report.tables import Report

    doc = {"a": [1.0, float("inf")], "b": {"c": float("nan")}}
    assert json.loads(to_text(Report([], doc), OutputFormat.JSON)) == {
        "a": [1.0, None],
        "b": {"c": None},
    }

    assert json_safe({"a": [1.0, float("inf")], "b": (float("nan"),)}) == {
        "a": [1.0, None],
        "b": [None],
    }


def test_numpy_warnings_are_one_note_without_source_paths(capsys):
    from credcli.cli.edge import note_warnings as _note_warnings

    class W:
        def __init__(self, message, category=RuntimeWarning):
            self.message, self.category = message, category
            self.filename, self.lineno = "/x/credcli/engine/metrics.py", 117

    _note_warnings(
        [W("overflow encountered in matmul")] * 3 + [W("invalid value encountered in divide")],
        False,
    )
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "credcli/engine" not in err[0]
    assert "overflow encountered in matmul; invalid value encountered in divide" in err[0]


def test_resource_warnings_are_for_debug_only(capsys):
    """An unclosed file (a signal that arrived while a module was imported) is Python's
    notice to developers, hidden by default: no note without --debug, so a terminated run
    still says one line."""
    from credcli.cli.edge import note_warnings

    class W:
        message, category = "unclosed file <_io.BufferedReader name='x.pyc'>", ResourceWarning
        filename, lineno = "x.py", 1

    note_warnings([W()], False)
    assert capsys.readouterr().err == ""
    note_warnings([W()], True)
    assert "ResourceWarning: unclosed file" in capsys.readouterr().err


# --- messages --------------------------------------------------------------------------------


def test_utf16_without_bom_is_named(tmp_path):
    path = tmp_path / "u16.csv"
    path.write_bytes(LOG.read_text().encode("utf-16-le"))
    assert "UTF-16" in error_line(*run("diagnose", path)[::2])


def test_utf16_with_bom_is_named_too(tmp_path):
    path = tmp_path / "u16.csv"
    path.write_bytes(LOG.read_text().encode("utf-16"))
    line = error_line(*run("diagnose", path)[::2])
    assert "UTF-16" in line and "without" not in line


def test_a_covariance_list_of_the_wrong_length_names_its_row(tmp_path):
    frame = pd.read_csv(FORMATS / "odom_ros.csv")
    cols = [f"field.pose.covariance{k}" for k in range(36)]
    frame["field.pose.covariance"] = [str(list(r)) for r in frame[cols].to_numpy()]
    frame = frame.drop(columns=cols)
    frame.loc[5, "field.pose.covariance"] = "[1, 2, 3]"
    path = tmp_path / "odom.csv"
    frame.to_csv(path, index=False)
    line = error_line(*run("diagnose", path, "--truth", FORMATS / "euroc_groundtruth.csv")[::2])
    assert "data row 6 holds 3" in line


@pytest.mark.parametrize(
    "flag, value, words",
    [("--max-dt", "-1", "--max-dt must be > 0"), ("--time-offset", "nan", "--time-offset must")],
)
def test_reading_flags_are_named_as_flags(flag, value, words):
    args = [FORMATS / "odom_ros.csv", "--truth", FORMATS / "euroc_groundtruth.csv", flag, value]
    line = error_line(*run("diagnose", *args)[::2])
    assert words in line and "config" not in line


def test_the_config_key_is_named_when_the_config_set_it(tmp_path):
    config = tmp_path / "c.toml"
    config.write_text("[input]\nmax_dt = -1\n")
    args = [FORMATS / "odom_ros.csv", "--truth", FORMATS / "euroc_groundtruth.csv"]
    line = error_line(*run("diagnose", *args, "--config", config)[::2])
    assert "config [input]: max_dt" in line


def test_bad_ros2_metadata_is_one_line(tmp_path):
    import shutil

    bag = tmp_path / "bag"
    shutil.copytree(FORMATS / "odom_ros2", bag)
    (bag / "metadata.yaml").write_text("rosbag2_bagfile_information: {version: [\n")
    line = error_line(
        *run("diagnose", bag, "--topic", "/odom", "--truth-topic", "/ground_truth")[::2]
    )
    assert "metadata.yaml is not valid YAML" in line


@pytest.mark.parametrize("extra", [[], ["--truth-topic", "/gt"]])
def test_a_directory_that_is_not_a_bag(tmp_path, extra):
    line = error_line(*run("diagnose", tmp_path, *extra)[::2])
    assert "not a ROS2 bag directory (no metadata.yaml)" in line


def test_an_innovations_log_without_the_flag_gets_a_hint():
    assert "--innovations" in error_line(*run("diagnose", FORMATS / "innovations.csv")[::2])


def test_a_window_without_unit_says_what_was_read():
    line = error_line(*run("diagnose", LOG, "--window", "2")[::2])
    assert "read as 2 epochs" in line and "2s" in line
    code, _, err = run("diagnose", LOG, "--window", "100")
    assert code == 0, err


def test_duplicate_columns_in_a_wide_header(tmp_path):
    frame = pd.read_csv(LOG).iloc[:20]
    extra = pd.DataFrame(np.zeros((20, 20_000)), columns=[f"x{k}" for k in range(20_000)])
    wide = pd.concat([frame, extra], axis=1)
    path = tmp_path / "wide.csv"
    wide.to_csv(path, index=False)
    text = path.read_text().replace("x19999", "x7", 1)
    path.write_text(text)
    assert "x7 appear more than once" in error_line(*run("diagnose", path)[::2])


# --- output formats --------------------------------------------------------------------------


def _markdown_tables(text: str) -> list[list[list[str]]]:
    """Every table of a Markdown text as rows of cell texts, read by a real parser."""
    from markdown_it import MarkdownIt

    tokens = MarkdownIt("commonmark").enable("table").parse(text)
    tables, row = [], None
    for tok in tokens:
        if tok.type == "table_open":
            tables.append([])
        elif tok.type == "tr_open":
            row = []
        elif tok.type == "inline" and row is not None:
            row.append(tok.content)
        elif tok.type == "tr_close":
            tables[-1].append(row)
            row = None
    return tables


def _unescape(cell: str) -> str:
    import re

    return re.sub(r"\\(.)", r"\1", cell)


def test_markdown_output_is_a_table_a_parser_reads(tmp_path):
    frame = pd.read_csv(LOG)
    frame["segment"] = frame["segment"].str.replace("cruise", "run_1|*x*")
    path = tmp_path / "log.csv"
    frame.to_csv(path, index=False)
    code, out, err = run("diagnose", path, "-f", "markdown")
    assert code == 0, err
    (table,) = _markdown_tables(out)
    header, rows = table[0], table[1:]
    records = json.loads(run("diagnose", path, "-f", "json")[1])["segments"]
    assert len(rows) == len(records) == 6
    assert "|bias| [σ]" in [_unescape(h) for h in header]
    assert all(len(r) == len(header) for r in rows)
    segment, label = header.index("segment"), header.index("label")
    assert [(_unescape(r[segment]), r[label]) for r in rows] == [
        (rec["segment"], rec["label"]) for rec in records
    ]


def test_the_step_summary_is_markdown_with_the_same_table(tmp_path):
    summary = tmp_path / "summary.md"
    code, _, _ = run("diagnose", LOG, "--fail-on", "optimism+smm", "--summary", summary)
    assert code == 1
    (table,) = _markdown_tables(summary.read_text())
    assert len(table) == 7 and "|bias| [σ]" in [_unescape(h) for h in table[0]]


# --- what a newcomer meets -------------------------------------------------------------------


def test_default_config_is_generated_and_current():
    from credcli.cli.settings import default_config_text

    assert (ROOT / "configs" / "default.toml").read_text() == default_config_text(), (
        "run `make config`"
    )


@pytest.mark.parametrize(
    "args",
    [
        ["diagnose", LOG, "-f", "json"],
        ["simulate", "--trials", "5", "-f", "json"],
        ["baseline", LOG],
        ["uwb", ROOT / "sample_data" / "starloc_grid_uwb.csv", "-f", "json"],
    ],
)
def test_loading_the_default_config_changes_nothing(args):
    config = ROOT / "configs" / "default.toml"
    plain = run(*args)
    configured = run(*args, "--config", config)
    assert plain[0] == configured[0] == 0, configured[2]
    strip = (lambda text: text.replace(str(config), "")) if args[0] != "baseline" else str
    assert strip(configured[1]) == plain[1]


def test_gate_with_the_default_config_changes_nothing(tmp_path):
    config = ROOT / "configs" / "default.toml"
    baseline = tmp_path / "b.json"
    assert run("baseline", LOG, "-o", baseline)[0] == 0
    plain = run("gate", LOG, "--baseline", baseline, "-f", "json")
    assert plain[0] == 0, plain[2]
    assert run("gate", LOG, "--baseline", baseline, "-f", "json", "--config", config) == plain


def test_the_default_config_sets_every_setting():
    """Each field of the settings classes appears in the file, set or commented out."""
    import dataclasses

    from credcli.ci.thresholds import Thresholds
    from credcli.engine.config import DiagnosisConfig
    from credcli.io.schema import LogSchema, ReadOptions
    from credcli.studies.settings import SimulationConfig, UwbSettings

    text = (ROOT / "configs" / "default.toml").read_text()
    for cls in (LogSchema, ReadOptions, DiagnosisConfig, SimulationConfig, UwbSettings, Thresholds):
        for f in dataclasses.fields(cls):
            if f.name not in ("diagnosis", "seed"):
                assert f"\n{f.name} = " in text or f"\n# {f.name} = " in text, f.name


def test_memory_error_is_blamed_on_settings_only_when_ours(monkeypatch):
    import credcli.engine.evidence as evidence

    namespace: dict = {}  # a function whose code is credcli's file, as an allocation of ours
    exec(
        compile("def ours(*a, **k):\n    raise MemoryError\n", evidence.__file__, "exec"),
        namespace,
    )
    monkeypatch.setattr(evidence, "ks_chi2_pvalue", namespace["ours"])
    assert "--flips" in error_line(*run("diagnose", LOG)[::2])

    def foreign(*args, **kwargs):
        return np.ones(2**40)  # raised inside numpy's own Python code (16 TiB)

    monkeypatch.setattr(evidence, "ks_chi2_pvalue", foreign)
    line = error_line(*run("diagnose", LOG)[::2], expected_code=3)
    assert "internal error: MemoryError" in line


def test_a_port_where_no_scheduler_answers_fails_within_the_timeout():
    import socket

    from credcli.errors import CredcliError
    from credcli.schedule.cluster import probe_scheduler

    with socket.socket() as server:  # accepts, never writes: an HTTP server, say
        server.bind(("127.0.0.1", 0))
        server.listen(1)
        port = server.getsockname()[1]
        start = time.monotonic()
        with pytest.raises(CredcliError, match=f"127.0.0.1:{port}: no answer"):
            probe_scheduler(f"tcp://127.0.0.1:{port}", seconds=1.0)
        assert time.monotonic() - start < 10


def test_an_http_answer_is_not_a_scheduler():
    import socket

    from credcli.errors import CredcliError
    from credcli.schedule.cluster import probe_scheduler

    with socket.socket() as server:
        server.bind(("127.0.0.1", 0))
        server.listen(1)
        port = server.getsockname()[1]

        def answer():
            conn, _ = server.accept()
            conn.sendall(b"HTTP/1.1 400 Bad Request\r\n\r\n")
            conn.close()

        thread = threading.Thread(target=answer)
        thread.start()
        with pytest.raises(CredcliError, match="an HTTP server answers there"):
            probe_scheduler(f"127.0.0.1:{port}", seconds=5.0)
        thread.join(5)


def test_html_cells_are_formatted_as_the_terminal_shows_them(sample_figures):
    code, err, report = sample_figures.code, sample_figures.err, sample_figures.report
    assert code == 0, err
    html = report.read_text()
    cruise = json.loads(run("diagnose", LOG, "-f", "json")[1])["segments"][0]
    kappa, low, high = (
        cruise[k] for k in ("scale_factor", "scale_factor_low", "scale_factor_high")
    )
    assert "&lt;0.001" in html and f"{kappa:.3g} ({low:.3g}–{high:.3g})" in html
    assert f"{kappa:.6g}" not in html and "e-1" not in html.split("<h2>Parameters")[0]


def test_gate_fail_on_and_report_monte_carlo(tmp_path):
    baseline = tmp_path / "b.json"
    assert run("baseline", LOG, "-o", baseline)[0] == 0
    code, _, err = run("gate", LOG, "--baseline", baseline, "--fail-on", "pess+smm")
    assert code == 1 and "1 segment(s) match --fail-on pessimism+smm: tunnel" in err
    assert run("gate", LOG, "--baseline", baseline, "--fail-on", "insufficient-data")[0] == 0
    runs = [FORMATS / f"mc_run_{k}.csv" for k in (1, 2, 3)]
    plain = run("diagnose", *runs, "--monte-carlo", "-f", "json")
    assert plain[0] == 0, plain[2]
    report = tmp_path / "mc.html"
    code, _, err = run("report", *runs, "--monte-carlo", "-o", report)
    assert code == 0, err
    assert "Monte Carlo: 3 runs" in report.read_text()


def test_output_off_a_terminal_keeps_every_column(tmp_path, monkeypatch):
    baseline = tmp_path / "b.json"
    assert run("baseline", LOG, "-o", baseline)[0] == 0
    regressed = ROOT / "sample_data" / "estimator_log_regressed.csv"
    monkeypatch.setenv("COLUMNS", "250")
    code, out, _ = run("gate", regressed, "--baseline", baseline)
    assert code == 1 and "why" in out.splitlines()[2] and "not shown at this width" not in out
    monkeypatch.delenv("COLUMNS")
    code, out, _ = run("gate", regressed, "--baseline", baseline)
    assert "label credible -> optimism" in out


def test_the_other_perturbation_convention_is_named_when_it_fits_far_better():
    args = [FORMATS / "odom_ros.csv", "--truth", FORMATS / "euroc_groundtruth.csv"]
    code, _, err = run("diagnose", *args, "--states", "pose")
    assert code == 0 and "--perturbation right fits the claimed covariance far better" in err
    code, _, err = run("diagnose", *args, "--states", "pose", "--perturbation", "right")
    assert code == 0 and "WARNING" not in err


def test_smm_advice_says_what_it_means_and_where_to_look():
    code, out, _ = run("diagnose", LOG)
    assert "gps-multipath: bias (1.04, -1)" in out and "look first at component 0" in out
    assert "bias: the errors have a mean that no covariance allows for" in out


def test_help_names_the_formats_and_the_rules():
    code, out, _ = run("diagnose", "--help")
    text = " ".join(out.replace("│", " ").split())  # the words of the help panels
    assert code == 0 and "TUM, OpenVINS, EuRoC, ros-csv, ROS1 bag, ROS2 bag" in text
    assert "the false-alarm level per segment" in text and "'-' reads standard input" in text


def _catches(pid: int, signum: int) -> bool:
    """Whether process ``pid`` has a handler for ``signum`` (its SigCgt mask in /proc)."""
    try:
        status = Path(f"/proc/{pid}/status").read_text()
    except OSError:
        return False
    caught = next(
        (line.split()[1] for line in status.splitlines() if line.startswith("SigCgt")), "0"
    )
    return bool(int(caught, 16) >> (signum - 1) & 1)


@pytest.mark.skipif(sys.platform != "linux", reason="reads /proc")
def test_sighup_ends_a_run_like_sigterm(tmp_path, long_log):
    proc = subprocess.Popen(
        [*CREDCLI, "diagnose", long_log, "-f", "json", "-o", tmp_path / "o.json", "--jobs", "1"],
        stderr=subprocess.PIPE,
        text=True,
    )
    deadline = time.monotonic() + 60  # until its handler is installed, however busy the machine
    while not _catches(proc.pid, signal.SIGHUP) and time.monotonic() < deadline:
        time.sleep(0.05)
    time.sleep(0.5)  # into the run
    assert proc.poll() is None, "the run ended before the signal"
    proc.send_signal(signal.SIGHUP)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 129 and err.strip() == "credcli: terminated (SIGHUP)", err
    assert list(tmp_path.iterdir()) == []


@pytest.mark.skipif(sys.platform != "linux", reason="reads /proc")
def test_ctrl_c_on_a_local_dask_cluster_is_one_line_and_leaves_nothing(tmp_path, long_log):
    pytest.importorskip("distributed")
    scratch = tmp_path / "tmp"
    scratch.mkdir()
    env = {**os.environ, "TMPDIR": str(scratch)}
    proc = subprocess.Popen(
        [
            *IN_A_TERMINAL,
            "diagnose",
            long_log,
            "--scheduler",
            "local:2",
            "-f",
            "json",
            "-o",
            tmp_path / "out.json",
        ],
        stderr=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
        start_new_session=True,
        env=env,
    )
    deadline = time.monotonic() + 60
    while len(_children(proc.pid)) < 2 and time.monotonic() < deadline:
        time.sleep(0.1)
    time.sleep(3.0)  # the workers run tasks
    os.killpg(proc.pid, signal.SIGINT)  # as a terminal sends it: to the whole group
    _, err = proc.communicate(timeout=90)
    lines = [line for line in err.splitlines() if line.strip()]
    assert proc.returncode == 130 and lines == ["credcli: interrupted"], err
    assert not (tmp_path / "out.json").exists()
    assert list(scratch.iterdir()) == [], "Dask's scratch space was left behind"


def _bytes(n: int) -> bytes:
    return b"x" * n


def test_stopping_workers_killed_mid_result_returns():
    """A worker killed while it sent a result left half a message in the result pipe, and
    the executor's reader waited for the rest for ever: SIGTERM hung a run (1 in ~15 signal
    tests under load). Killed while sending 64 MB results, the pool now stops at once."""
    import threading

    from credcli.schedule.pool import WorkerPool

    pool = WorkerPool(2)
    for _ in range(4):
        pool.executor.submit(_bytes, 64 << 20)
    time.sleep(0.6)  # the workers are sending their results
    stopped = threading.Event()
    threading.Thread(target=lambda: (pool.stop(), stopped.set()), daemon=True).start()
    assert stopped.wait(20), "stopping the pool hung"


@pytest.mark.parametrize("scale", [1e-153, 1e154])
def test_standard_deviations_beyond_double_precisions_reach_are_refused(tmp_path, scale):
    """Errors and standard deviations scaled by 1e-153 failed as an internal error
    ("eigenvalues did not converge": the precisions' sum overflowed), by 1e154 gave a
    wrong κ̂ (d = 3); now both are exit 2, naming the row and the range."""
    rng = np.random.default_rng(1)
    e = rng.standard_normal((300, 3)) * scale
    frame = pd.DataFrame({f"truth_{i}": e[:, i] for i in range(3)})
    for i in range(3):
        frame[f"est_{i}"] = 0.0
        frame[f"var_{i}"] = scale * scale * (1.0 + 0.2 * i)
    path = tmp_path / "extreme.csv"
    frame.to_csv(path, index=False)
    line = error_line(*run("diagnose", path)[::2])
    assert "row 1" in line and "lies outside 1e-150 … 1e+150" in line


def test_results_are_the_same_in_any_unit_within_the_range():
    """Errors and standard deviations scaled by 10^±140 (d = 3, correlated, a bias): the
    same label and κ̂, to 1e-9, as in the log's own unit."""
    import credcli

    rng = np.random.default_rng(5)
    a = rng.standard_normal((3, 5))
    cov = a @ a.T / 5
    e = rng.standard_normal((300, 3)) @ np.linalg.cholesky(cov).T + [0.3, 0.0, 0.0]
    one = credcli.diagnose(e, cov, seed=1)
    for scale in (1e-140, 1e140):
        other = credcli.diagnose(e * scale, cov * scale * scale, seed=1)
        assert (other.label, other.untested) == (one.label, one.untested)
        assert other.scale.scale_factor == pytest.approx(one.scale.scale_factor, rel=1e-9)


@pytest.mark.skipif(
    not Path("/proc/self").is_dir(), reason="needs /proc, where no file can be made"
)
@pytest.mark.parametrize(
    "extra",
    [
        ["--plots", "/proc/credcli-figures"],
        ["--report", "/proc/credcli.html"],
        ["--fail-on", "bias", "--junit", "/proc/credcli.xml"],
        ["--fail-on", "bias", "--summary", "/proc/credcli.md"],
    ],
)
def test_an_output_that_cannot_be_written_stops_the_run_before_any_is(tmp_path, extra):
    """-o was written (replacing the file there) and only then a side output in a place
    that takes no file failed, with two lines on stderr. Every output's place is tried
    before any work: exit 2, one line naming the option, -o's file untouched."""
    out = tmp_path / "m.json"
    out.write_text("ORIG")
    code, _, err = run("diagnose", LOG, "-f", "json", "-o", out, *extra)
    line = error_line(code, err)
    assert extra[-2] in line and "cannot write in /proc" in line
    assert out.read_text() == "ORIG"


def _innovations_log(path, rows):
    head = "time,innov_0,innov_1,innov_cov_0_0,innov_cov_0_1,innov_cov_1_1\n"
    path.write_text(
        head + "".join(f"{k},{float(a)!r},{float(b)!r},{s},{c},{t}\n" for k, a, b, s, c, t in rows)
    )
    return path


def test_an_innovation_covariance_in_the_upper_layout_is_checked(tmp_path):
    """A singular or indefinite S given as its upper triangle (innov_cov_0_0, _0_1, _1_1)
    reached the whitening and failed there as an internal error (exit 3); it is refused
    when the log is read, by row, as a full matrix is."""
    rng = np.random.default_rng(8)
    for off in (1.0, 2.0):
        rows = [(k, rng.normal(), rng.normal(), 1, off, 1) for k in range(60)]
        path = _innovations_log(tmp_path / f"s{off}.csv", rows)
        line = error_line(*run("diagnose", path, "--innovations")[::2])
        assert "row 1: covariance is not positive definite" in line and "correlation" in line


def test_innovations_that_span_fewer_dimensions_are_declined_not_an_error(tmp_path):
    """Collinear innovations (innov_0 = innov_1) have a singular sample covariance, and
    Hosking's portmanteau statistic inverts it: the run failed as an internal error
    (exit 3). The whiteness test is not run there, and the segment is insufficient-data
    with its reason."""
    rng = np.random.default_rng(8)
    rows = [(k, x, x, 1, 0, 1) for k, x in enumerate(rng.normal(size=60))]
    path = _innovations_log(tmp_path / "collinear.csv", rows)
    code, out, err = run("diagnose", path, "--innovations", "-f", "json")
    assert code == 0, err
    record = json.loads(out)["segments"][0]
    assert record["label"] == "insufficient-data"
    assert "fewer than d dimensions" in record["reason"]


def test_errors_equal_in_two_components_are_insufficient_data_whatever_the_rounding():
    """Two equal columns make the MSE matrix singular, but its Cholesky factorisation
    passed by rounding on 7 of 40 such segments, which then read "bias" or "credible"
    (their sample covariance inverted). The correlation matrix's smallest eigenvalue says
    singular on all 40."""
    import credcli

    for seed in range(40):
        x = np.random.default_rng(seed).normal(size=60)
        diagnosis = credcli.diagnose(np.c_[x, x], np.eye(2), seed=1)
        assert diagnosis.label.value == "insufficient-data"
        assert "fewer than d dimensions" in diagnosis.reason


def test_a_time_cell_that_is_no_time_is_named_by_row(tmp_path):
    """A numeric time column with one word in row 31 was refused quoting its first, valid
    value ('1') and no row."""
    rows = "".join(f"{k},0,0.{k},1\n" for k in range(1, 31))
    path = tmp_path / "t.csv"
    path.write_text("time,truth_0,est_0,var_0\n" + rows + "abc,0,1,1\n")
    line = error_line(*run("diagnose", path)[::2])
    assert "(time): row 31: 'abc' is neither a number nor an ISO-8601 date-time" in line


def test_a_csv_that_is_not_utf8_is_named_by_line_and_byte(tmp_path):
    """A Latin-1 byte in line 52 was reported at pandas' buffer position ("position 0")
    with no fix; now its line, its byte and the way to convert the file."""
    rows = b"".join(b"%d,0,1,1\n" % k for k in range(50))
    path = tmp_path / "latin1.csv"
    path.write_bytes(b"time,truth_0,est_0,var_0\n" + rows + b"50,0,1,1 \xe9\n")
    line = error_line(*run("diagnose", path)[::2])
    assert "line 52: byte 0xe9 is not UTF-8 text; save the file as UTF-8" in line


def test_an_unsorted_time_column_under_a_window_names_the_log_and_row(tmp_path):
    """With several logs the message did not say which, nor where the time went back."""
    rows = "0,0,1,1\n1,0,1,1\n3,0,1,1\n2,0,1,1\n" + "".join(f"{k},0,1,1\n" for k in range(4, 40))
    path = tmp_path / "unsorted.csv"
    path.write_text("time,truth_0,est_0,var_0\n" + rows)
    line = error_line(*run("diagnose", path, "--window", "5s")[::2])
    assert "unsorted.csv" in line and "goes back at row 4" in line


def test_a_seed_beyond_64_bits_in_a_config_says_so(tmp_path):
    """It said "seed must be an integer; got int 99999999999999999999"."""
    config = tmp_path / "c.toml"
    config.write_text("[diagnosis]\nseed = 99999999999999999999\n")
    line = error_line(*run("diagnose", LOG, "--config", config)[::2])
    assert "seed must be an integer within ±2^63 (64 bits); got 99999999999999999999" in line
