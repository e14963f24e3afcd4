"""Issue 32: names from the data reach the terminal, CSV and JUnit made safe."""

from __future__ import annotations

import csv
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from credcli.cli import main
from credcli.errors import CredcliError, printable

NAMES = (
    "ok",
    '=HYPERLINK("http://x")',
    "bad\x1b]0;title\x07",
    "two\ncredcli: PASS: forged",
    "cr\rrow",
    "c1\x9bcsi",
)


@pytest.fixture(scope="module")
def evil_log(tmp_path_factory):
    """A Parquet log whose segment names carry control codes, a formula and a newline;
    the second segment's covariance is 9× too small (a failing segment)."""
    gen = np.random.default_rng(0)
    rows = []
    for i, name in enumerate(NAMES):
        e = gen.standard_normal((60, 2)) * (3.0 if i == 1 else 1.0)
        rows += [
            {"time": i * 10 + k * 0.1, "segment": name, "truth_0": 0.0, "truth_1": 0.0}
            | {"est_0": -e[k, 0], "est_1": -e[k, 1], "std_0": 1.0, "std_1": 1.0}
            for k in range(60)
        ]
    path = tmp_path_factory.mktemp("evil") / "evil.parquet"
    pd.DataFrame(rows).to_parquet(path, index=False)
    return path


def _controls(text: str) -> set[str]:
    return {c for c in text if (ord(c) < 32 and c != "\n") or 0x7F <= ord(c) <= 0x9F}


def test_printable_escapes_every_control_character():
    assert printable("a\x1b[31mb\nc\rd\x00e\x9bf\u2028g") == (
        "a\\x1b[31mb\\nc\\rd\\x00e\\x9bf\\u2028g"
    )
    assert printable("plain [brackets] and ünïcode") == "plain [brackets] and ünïcode"


def test_names_reach_the_terminal_escaped_and_one_verdict_line(evil_log, capsys, tmp_path):
    junit = tmp_path / "j.xml"
    code = main(["diagnose", str(evil_log), "--fail-on", "noncredible", "--junit", str(junit)])
    out, err = capsys.readouterr()
    assert code == 1
    assert not _controls(out) and not _controls(err), (_controls(out), _controls(err))
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("credcli: FAIL:"), lines
    assert "two\\ncredcli: PASS: forged" in out
    ET.parse(junit)  # valid XML, control characters written as #xNN
    assert "#x1B" in junit.read_text()


def test_markdown_and_the_summary_escape_control_characters(evil_log, capsys, tmp_path):
    """A held-out case: segment names' ESC and BEL reached the Markdown output and the
    --summary file raw."""
    assert main(["diagnose", str(evil_log), "-f", "markdown"]) == 0
    assert _controls(capsys.readouterr().out) == set()
    summary = tmp_path / "s.md"
    assert (
        main(["diagnose", str(evil_log), "--fail-on", "optimism", "--summary", str(summary)]) == 1
    )
    capsys.readouterr()
    assert _controls(summary.read_text()) == set() and "\\x1b" in summary.read_text()


def test_csv_is_rfc4180_and_never_a_formula(evil_log, capsys, tmp_path):
    (tmp_path / "a[").mkdir()
    path = tmp_path / "a[" / "]b.csv"  # brackets in a path are not Rich markup
    assert main(["diagnose", str(evil_log), "-f", "csv", "-o", str(path)]) == 0
    assert "wrote" in capsys.readouterr().err
    with path.open(newline="") as f:
        rows = list(csv.DictReader(f))
    assert [r["segment"] for r in rows] == ["ok", "'" + NAMES[1], *NAMES[2:]]
    assert all(not r["segment"].startswith(("=", "+", "-", "@")) for r in rows)
    assert rows[0]["n"] == "60" and float(rows[0]["scale_factor"]) > 0  # numbers stay numbers


def test_no_csv_cell_reads_as_a_formula_lists_of_numbers_included(tmp_path):
    """A list cell such as ``bias`` is written "-0.0715 -0.3579": text to a spreadsheet,
    which reads a text starting with '-' as a formula (=-0.07-0.35). Every cell of the
    sample's CSV and of a log of one-epoch segments (the batched writer) is checked."""
    from helpers import ROOT

    rng = np.random.default_rng(3)
    short = tmp_path / "short.csv"
    e = rng.standard_normal((40, 2)) - 3.0  # negative means: lists starting with '-'
    rows = ["time,segment,truth_0,truth_1,est_0,est_1,cov_0_0,cov_0_1,cov_1_1"]
    rows += [f"{k},s{k},{a},{b},0,0,1,0,1" for k, (a, b) in enumerate(e)]
    short.write_text("\n".join(rows) + "\n")
    for log in (ROOT / SAMPLE_LOG, short):
        out = tmp_path / f"{log.stem}.out.csv"
        assert main(["diagnose", str(log), "-f", "csv", "-o", str(out)]) == 0
        with out.open(newline="") as f:
            cells = [c for row in csv.reader(f) for c in row]
        lists = [c for c in cells if " " in c and c.lstrip("'-").replace(".", "", 1)[:1].isdigit()]
        assert lists, "the CSV has list cells"
        assert not [c for c in cells if c and (c[0] in "=+@\t\r" or (c[0] == "-" and " " in c))]


def test_full_width_formula_signs_get_the_apostrophe_too(tmp_path):
    """'＝cmd()' (U+FF1D) was written bare; an East Asian spreadsheet may read it as '='."""
    path = tmp_path / "fw.csv"
    rows = ["time,segment,truth_0,truth_1,est_0,est_1,cov_0_0,cov_0_1,cov_1_1"]
    rows += [f"{k},＝cmd(),{k % 3},0,0,0,1,0,1" for k in range(30)]
    path.write_text("\n".join(rows) + "\n", encoding="utf-8")
    out = tmp_path / "o.csv"
    assert main(["diagnose", str(path), "-f", "csv", "-o", str(out)]) == 0
    with out.open(newline="", encoding="utf-8") as f:
        assert [r["segment"] for r in csv.DictReader(f)] == ["'＝cmd()"]


SAMPLE_LOG = "sample_data/estimator_log.csv"


@pytest.mark.parametrize(
    "args",
    [
        ("--alpha", "1e-308"),
        ("--alpha", "5e-324"),
        ("--window", "99999999999999999999"),
        ("--window", "999999999999999999999s"),
    ],
)
def test_extreme_settings_are_usage_errors(args, capsys, monkeypatch):
    """Issue 32 item 8: exit 2 with one line, not an internal error (exit 3)."""
    from helpers import ROOT

    monkeypatch.chdir(ROOT)
    code = main(["diagnose", SAMPLE_LOG, *args])
    err = capsys.readouterr().err
    assert code == 2 and len(err.strip().splitlines()) == 1, err
    assert "internal error" not in err


def test_deeply_nested_baseline_and_config_are_usage_errors(tmp_path, capsys, monkeypatch):
    from helpers import ROOT

    monkeypatch.chdir(ROOT)
    deep = tmp_path / "deep.json"
    deep.write_text("[" * 100_000 + "]" * 100_000)
    assert main(["gate", SAMPLE_LOG, "--baseline", str(deep)]) == 2
    assert "nested too deeply" in capsys.readouterr().err
    toml = tmp_path / "deep.toml"
    toml.write_text("a = " + "[" * 100_000 + "]" * 100_000)
    assert main(["diagnose", SAMPLE_LOG, "--config", str(toml)]) == 2
    assert "nested too deeply" in capsys.readouterr().err


def test_file_names_that_are_not_utf8(tmp_path, capsys, monkeypatch):
    """A log and outputs whose names are not valid UTF-8 (bytes held as surrogates):
    written, with the name escaped inside them."""
    import os
    import shutil

    from helpers import ROOT

    monkeypatch.chdir(ROOT)
    base = os.fsencode(tmp_path)
    log = os.fsdecode(base + b"/log\xff.csv")
    shutil.copy(SAMPLE_LOG, log)
    csv_out = os.fsdecode(base + b"/out\xff.csv")
    junit = os.fsdecode(base + b"/j\xff.xml")
    code = main(["diagnose", log, "-f", "csv", "-o", csv_out, "--junit", junit, "--fail-on", "smm"])
    assert code == 1, capsys.readouterr().err
    assert "\\udcff" in Path(csv_out).read_bytes().decode("utf-8")
    ET.parse(junit)


def test_a_baseline_never_names_the_files_credcli_reads(tmp_path, capsys, monkeypatch):
    """Issue 32 item 2: a committed baseline pointing its truth at a secret file made the
    gate read it (a line of it in the error); now the gate reads only files the command
    line names, and says so."""
    import json

    from helpers import ROOT

    monkeypatch.chdir(ROOT)
    formats = ROOT / "sample_data" / "formats"
    estimate, truth = formats / "openvins_estimate.txt", formats / "tum_groundtruth.txt"
    base = tmp_path / "base.json"
    assert main(["baseline", str(estimate), "--truth", str(truth), "-o", str(base)]) == 0
    secret = tmp_path / "secret.txt"
    secret.write_text("TOKEN=hunter2\n")
    doc = json.loads(base.read_text())
    doc["parameters"]["input"]["truth"] = str(secret)
    base.write_text(json.dumps(doc))
    capsys.readouterr()
    assert main(["gate", str(estimate), "--baseline", str(base)]) == 2
    err = capsys.readouterr().err
    assert "hunter2" not in err and "give the new log's truth with --truth" in err
    assert main(["gate", str(estimate), "--baseline", str(base), "--truth", str(truth)]) == 0


def test_the_gate_names_a_reading_setting_that_differs_from_the_baseline(tmp_path, capsys):
    """Issue 32 item 2: the gate reads the new log as the baseline's was; a config whose
    [input] or [columns] says otherwise is named, not silently overridden."""
    from helpers import ROOT

    log, base = str(ROOT / SAMPLE_LOG), tmp_path / "base.json"
    assert main(["baseline", log, "-o", str(base)]) == 0
    for table, line, shown in (
        ("input", 'time_unit = "ms"', "[input] time_unit: baseline 'auto', now 'ms'"),
        ("columns", 'time = "t"', "[columns] time: baseline 'time', now 't'"),
        ("input", 'time_unit = "auto"', None),
    ):
        config = tmp_path / "c.toml"
        config.write_text(f"[{table}]\n{line}\n")
        capsys.readouterr()
        code = main(["gate", log, "-b", str(base), "--config", str(config)])
        err = capsys.readouterr().err
        assert (code, shown is None or shown in err) == (2 if shown else 0, True), err


def test_a_plain_tcp_scheduler_off_this_machine_is_refused(capsys, monkeypatch):
    """Issue 32 item 1: results come back by pickle, so an unauthenticated remote scheduler
    could run code in credcli; refused before any connection (exit 2) unless opted in."""
    pytest.importorskip("distributed")
    from helpers import ROOT

    from credcli.schedule.cluster import REMOTE_OPT_IN

    monkeypatch.chdir(ROOT)
    monkeypatch.delenv(REMOTE_OPT_IN, raising=False)
    assert main(["diagnose", SAMPLE_LOG, "--scheduler", "tcp://192.0.2.7:8786"]) == 2
    err = capsys.readouterr().err
    assert "use tls://" in err and REMOTE_OPT_IN in err


def test_the_scheduler_from_the_environment_is_announced(capsys, monkeypatch):
    pytest.importorskip("distributed")
    from helpers import ROOT

    monkeypatch.chdir(ROOT)
    monkeypatch.setenv("CREDCLI_SCHEDULER", "tcp://127.0.0.1:1")  # nothing listens there
    assert main(["diagnose", SAMPLE_LOG]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert lines[0].endswith("(CREDCLI_SCHEDULER)") and "cannot connect" in lines[1]


@pytest.mark.parametrize("unnamed", [True, False], ids=["O_TMPFILE", "named-temporary"])
def test_outputs_never_follow_a_symlink_and_keep_a_files_mode(
    unnamed, tmp_path, capsys, monkeypatch
):
    """Issue 32 item 3: a symbolic link at the output's name is refused (exit 2) and the
    file it points to untouched; replacing a 0600 report keeps it 0600; with an unnamed
    O_TMPFILE and with the named temporary file used where there is none."""
    import os
    import stat

    from helpers import ROOT

    from credcli.io import files

    if not unnamed:
        monkeypatch.setattr(files, "_write_unnamed", lambda *args: False)
    monkeypatch.chdir(ROOT)
    outside = tmp_path / "outside.txt"
    outside.write_text("keep me\n")
    link = tmp_path / "report.json"
    link.symlink_to(outside)
    assert main(["diagnose", SAMPLE_LOG, "-f", "json", "-o", str(link)]) == 2
    assert "symbolic link" in capsys.readouterr().err
    assert outside.read_text() == "keep me\n" and link.is_symlink()
    private = tmp_path / "private.json"
    private.write_text("{}")
    os.chmod(private, 0o600)
    assert main(["diagnose", SAMPLE_LOG, "-f", "json", "-o", str(private)]) == 0
    assert stat.S_IMODE(private.stat().st_mode) == 0o600
    assert private.read_text().startswith("{") and len(private.read_text()) > 100
    assert not [p for p in tmp_path.iterdir() if p.name.endswith(".tmp")]


def test_a_directory_swapped_while_writing_is_not_followed(tmp_path, monkeypatch):
    """Issue 32 item 3: once the output's directory is open, every step works relative to
    it; an attacker who swaps the directory for a link mid-write does not redirect it."""
    from credcli.io import files

    out, outside = tmp_path / "out", tmp_path / "outside"
    out.mkdir()
    outside.mkdir()
    real = files._mode

    def swapped(*args):
        mode = real(*args)
        out.rename(tmp_path / "moved")
        out.symlink_to(outside)
        return mode

    monkeypatch.setattr(files, "_mode", swapped)
    files.write_atomic(out / "report.json", "{}")
    assert list(outside.iterdir()) == []
    assert (tmp_path / "moved" / "report.json").read_text() == "{}"


def _npy_header(shape) -> bytes:
    import struct

    text = f"{{'descr': '<f8', 'fortran_order': False, 'shape': {shape}, }}"
    text += " " * (64 - (10 + len(text) + 1) % 64) + "\n"
    return b"\x93NUMPY\x01\x00" + struct.pack("<H", len(text)) + text.encode()


def test_an_npz_that_declares_more_than_it_holds_is_refused_before_allocating(tmp_path, capsys):
    """Issue 32 item 6: 588 bytes declaring 10¹³ floats ended in "Unable to allocate
    72.8 TiB" (exit 3)."""
    import zipfile

    path = tmp_path / "lying.npz"
    with zipfile.ZipFile(path, "w") as z:
        for name in ("truth", "estimate", "cov"):
            z.writestr(f"{name}.npy", _npy_header((10**13,)))
    assert main(["diagnose", str(path)]) == 2
    assert "declares 80,000,000,000,000 bytes" in capsys.readouterr().err


def test_an_npz_that_inflates_past_the_memory_budget_is_refused(tmp_path, capsys, monkeypatch):
    from credcli.io import arrays

    path = tmp_path / "bomb.npz"
    n = 200_000
    np.savez_compressed(path, truth=np.zeros((n, 2)), estimate=np.zeros((n, 2)), cov=np.eye(2))
    monkeypatch.setattr(arrays, "memory_budget", lambda: 2**20)  # 1 MiB here
    assert main(["diagnose", str(path)]) == 2
    assert "more than the" in capsys.readouterr().err


def test_npz_arrays_that_fit_no_one_log_are_refused_before_any_is_read(
    tmp_path, capsys, monkeypatch
):
    """A 4 MB .npz whose truth declared 2²⁸ epochs beside two of the estimate was unpacked
    whole (22 s, 4.7 GB) before the lengths were compared; unknown arrays were read too.
    Shapes that fit some log (a transposed one, which the reader names) are still read."""
    import zipfile

    n = 4096
    with zipfile.ZipFile(tmp_path / "x.npz", "w", compression=zipfile.ZIP_DEFLATED) as z:
        z.writestr("truth.npy", _npy_header((n, 2)) + bytes(16 * n))
        z.writestr("estimate.npy", _npy_header((2, 2)) + bytes(32))
        z.writestr("cov.npy", _npy_header((2, 2)) + bytes(32))
    np.savez(tmp_path / "junk.npz", errors=np.zeros((5, 2)), cov=np.eye(2), junk=np.zeros(9))
    monkeypatch.setattr(np.lib.npyio.NpzFile, "__getitem__", lambda *a: pytest.fail("read"))
    assert main(["diagnose", str(tmp_path / "x.npz")]) == 2
    err = capsys.readouterr().err
    assert "fit no one number of epochs" in err and f"truth ({n}, 2)" in err, err
    assert main(["diagnose", str(tmp_path / "junk.npz")]) == 2
    assert "unknown array(s) junk" in capsys.readouterr().err
    monkeypatch.undo()
    np.savez(tmp_path / "t.npz", errors=np.zeros((2, 30)), cov=np.eye(2))
    assert main(["diagnose", str(tmp_path / "t.npz")]) == 2
    assert "is transposed" in capsys.readouterr().err
    for cov in (np.ones(30), np.ones((30, 1)), np.ones((30, 1, 1)), np.eye(1)):
        np.savez(tmp_path / "one.npz", errors=np.zeros(30), cov=cov, time=np.arange(30.0))
        assert main(["diagnose", str(tmp_path / "one.npz"), "-f", "json"]) == 0, cov.shape
        capsys.readouterr()


def test_a_header_gap_is_one_short_line(tmp_path, capsys):
    """A 55-byte header naming truth_1000000000000 took 1.76 GB and a header gap to
    truth_1000000 a 13.9 MB error line; both are one short line now."""
    for index in (10**6, 10**12):
        path = tmp_path / f"gap{index}.csv"
        path.write_text(f"time,truth_0,truth_{index},est_0,est_1,var_0,var_1\n0,1,1,1,1,1,1\n")
        assert main(["diagnose", str(path)]) == 2
        err = capsys.readouterr().err
        assert len(err) < 300 and f"({index - 1:,} in all)" in err, err


def test_endless_and_device_inputs_end_with_one_line(tmp_path, capsys, monkeypatch):
    """Issue 32 item 7: /dev/zero as input hung (and filled TMPDIR); an endless pipe is
    cut at the stream budget."""
    import os
    import threading

    from credcli.io import streams

    assert main(["diagnose", "/dev/zero"]) == 2
    assert "is a device, not a log" in capsys.readouterr().err
    fifo = tmp_path / "endless"
    os.mkfifo(fifo)
    monkeypatch.setattr(streams, "stream_limit", lambda directory: 2**20)

    def feed():
        try:
            with open(fifo, "wb") as out:
                for _ in range(16):  # 4 MiB of a log's rows, past the 1 MiB budget
                    out.write(b"0,1,1,1,1,1,1\n" * 20_000)
        except BrokenPipeError:
            pass

    writer = threading.Thread(target=feed, daemon=True)
    writer.start()
    assert main(["diagnose", str(fifo)]) == 2
    assert "goes on past" in capsys.readouterr().err
    writer.join(timeout=10)


def test_a_fifo_that_no_process_writes_is_one_line_not_a_hang(tmp_path, capsys, monkeypatch):
    """A named FIFO as log, truth or baseline with no writer waited for ever (opening it
    blocks); now it has WRITER_WAIT seconds to send data, and a late writer still works."""
    import os
    import threading

    from credcli.io import streams

    monkeypatch.setattr(streams, "WRITER_WAIT", 0.3)
    sample = Path(__file__).parents[1] / "sample_data" / "estimator_log.csv"
    fifo = tmp_path / "log.csv"
    os.mkfifo(fifo)
    for args in (
        ["diagnose", str(fifo)],
        ["gate", str(sample), "--baseline", str(fifo)],
    ):
        assert main(args) == 2
        err = capsys.readouterr().err
        assert "a FIFO that no process wrote to within 0.3 s" in err and err.count("\n") == 1

    def late_writer():
        with open(fifo, "wb") as out:
            out.write(sample.read_bytes())

    monkeypatch.setattr(streams, "WRITER_WAIT", 30.0)
    writer = threading.Thread(target=late_writer, daemon=True)
    writer.start()
    assert main(["diagnose", str(fifo), "-f", "json"]) == 0
    writer.join(timeout=10)
    assert '"label"' in capsys.readouterr().out


def test_the_step_summary_is_checked_before_any_work(tmp_path, capsys, monkeypatch):
    """A FIFO as $GITHUB_STEP_SUMMARY blocked forever, after the outputs were written; an
    input named there would have been appended to."""
    import os

    from helpers import ROOT

    monkeypatch.chdir(ROOT)
    fifo = tmp_path / "summary"
    os.mkfifo(fifo)
    out = tmp_path / "out.json"
    monkeypatch.setenv("GITHUB_STEP_SUMMARY", str(fifo))
    assert main(["diagnose", SAMPLE_LOG, "--fail-on", "smm", "-f", "json", "-o", str(out)]) == 2
    assert "not a regular file" in capsys.readouterr().err and not out.exists()
    monkeypatch.setenv("GITHUB_STEP_SUMMARY", str(ROOT / SAMPLE_LOG))
    assert main(["diagnose", SAMPLE_LOG, "--fail-on", "smm"]) == 2
    assert "is also an input" in capsys.readouterr().err


def test_a_bad_time_is_named_from_one_vectorised_pass():
    """Issue 32 item 8: one bad ISO time among many took 13–16 s to report (70 s on a
    million rows here; 3 s now, measured): the first bad value is still the one named."""
    from credcli.errors import CredcliError
    from credcli.io.text import time_seconds

    stamps = [f"2024-05-01T12:00:{k % 60:02d}Z" for k in range(5000)]
    stamps[1234], stamps[4000] = "12:00 yesterday", "later"
    with pytest.raises(CredcliError, match=r"row 1235: '12:00 yesterday' is neither"):
        time_seconds(stamps, "time")


def _short_log(path: Path, gen, segment: str | None = None, scale: float = 1.0) -> Path:
    """A log of one short segment (few figures to draw), named ``segment`` if given, its
    errors ``scale`` times what its covariance claims."""
    path.parent.mkdir(parents=True, exist_ok=True)
    e = gen.standard_normal((60, 2)) * scale
    head, cell = ("segment,", f"{segment},") if segment is not None else ("", "")
    rows = "".join(f"{cell}{k / 10},0,0,{-a},{-b},1,1\n" for k, (a, b) in enumerate(e))
    path.write_text(f"{head}time,truth_0,truth_1,est_0,est_1,std_0,std_1\n" + rows)
    return path


def test_two_logs_with_one_stem_get_figure_names_of_their_own(tmp_path):
    """Two logs with one stem (a/run.csv, b/run.csv) wrote one set of figures over the
    other, then stopped with a collision (issue 32): each log's figures, titles, groups
    and JUnit cases are now named by the parent directory that tells them apart (issue
    34, LogId)."""
    pytest.importorskip("matplotlib")
    from credcli.report.overview import FILE_STEMS
    from credcli.requests import DiagnoseRequest
    from credcli.workflows import run_diagnose

    gen = np.random.default_rng(5)
    logs = [str(_short_log(tmp_path / part / "run.csv", gen)) for part in ("a", "b")]
    figures, junit = tmp_path / "figs", tmp_path / "junit.xml"
    args = ["diagnose", *logs, "--plots", str(figures), "--fail-on", "smm"]
    assert main([*args, "--junit", str(junit)]) == 0
    names = sorted(p.stem for p in figures.iterdir())
    mine = {part: [n for n in names if n.startswith(f"{part}_run_")] for part in "ab"}
    assert len(mine["a"]) + len(mine["b"]) == len(names)
    for kind in FILE_STEMS.values():  # the overview of each log, side by side
        assert {f"a_run_{kind}", f"b_run_{kind}"} <= set(names)
    assert [n[2:] for n in mine["a"]] == [n[2:] for n in mine["b"]]  # the same figures
    classes = {case.get("classname") for case in ET.parse(junit).getroot().iter("testcase")}
    assert classes == {"credcli.diagnose.a_run", "credcli.diagnose.b_run"}
    run = run_diagnose(DiagnoseRequest(tuple(logs), figures=True))
    assert {p.group for p in run.plots} >= {"a/run.csv: overview", "b/run.csv: overview"}
    assert [str(r.log) for r in run.results] == logs  # messages and records: the paths
    assert len({r.log for r in run.results}) == 2


def test_the_html_report_links_each_log_with_one_stem_to_its_own_figures(tmp_path):
    """The report's worst segments link to their figures: two logs with one stem were
    one section (their figures mixed), and then, told apart by label, were not linked."""
    pytest.importorskip("matplotlib")
    import re

    gen = np.random.default_rng(5)
    logs = [str(_short_log(tmp_path / p / "run.csv", gen, "s", 3.0)) for p in ("a", "b")]
    html = tmp_path / "report.html"
    assert main(["report", *logs, "-o", str(html)]) == 0
    links = re.findall(r'<td class="text"><a href="#([^"]+)">([^<]+)</a></td>', html.read_text())
    assert sorted(links) == [
        ("fig-a-run-csv-segment-s", f"{logs[0]}: s"),
        ("fig-b-run-csv-segment-s", f"{logs[1]}: s"),
    ]


def test_a_figure_name_collision_is_an_error_and_overwrites_nothing(tmp_path, capsys):
    """Names that still meet (log x.csv's segment y_z and log x_y.csv's segment z both
    give x_y_z) are an error before any figure is written: nothing is overwritten."""
    pytest.importorskip("matplotlib")
    gen = np.random.default_rng(5)
    logs = [_short_log(tmp_path / "x.csv", gen, "y_z"), _short_log(tmp_path / "x_y.csv", gen, "z")]
    figures = tmp_path / "figs"
    assert main(["diagnose", *map(str, logs), "--plots", str(figures)]) == 2
    assert "two figures would both be" in capsys.readouterr().err
    assert not figures.exists() or not list(figures.iterdir())


def test_huge_anchor_and_marker_ids_are_usage_errors(tmp_path, capsys):
    """An id past 2**53 was cast to a wrong id (exit 0, a note on a cast) or crashed."""
    from helpers import ROOT

    grid = (ROOT / "sample_data" / "starloc_grid_uwb.csv").read_text().splitlines()
    header = grid[0].split(",")
    col = header.index("to_id")
    rows = [grid[0]]
    for line in grid[1:]:
        cells = line.split(",")
        cells[col] = "99999999999999999999999" if cells[col] == "4" else cells[col]
        rows.append(",".join(cells))
    log = tmp_path / "ids.csv"
    log.write_text("\n".join(rows) + "\n")
    assert main(["uwb", str(log)]) == 2
    assert "is not an integer id" in capsys.readouterr().err
    markers = tmp_path / "markers.csv"
    markers.write_text(",x,y,z\n99999999999999999999999,1,2,3\n11,1,2,0.5\n")
    grid_log = str(ROOT / "sample_data" / "starloc_grid_uwb.csv")
    assert main(["uwb", grid_log, "--anchors", str(markers)]) == 2
    assert "is not an integer id" in capsys.readouterr().err


@pytest.mark.parametrize(
    "frame",
    [(2**62).to_bytes(8, "little") + bytes(16), b"\x01\x00\x00\x00\x00\x00\x00\x00\x05"],
    ids=["huge", "short"],
)
def test_a_peer_that_is_no_scheduler_is_a_usage_error(frame, capsys, monkeypatch):
    """Issue 32 item 8: a fake scheduler sending a huge or a short frame ended in exit 3."""
    import socket
    import threading

    pytest.importorskip("distributed")
    from helpers import ROOT

    monkeypatch.chdir(ROOT)
    server = socket.socket()
    server.bind(("127.0.0.1", 0))
    server.listen(4)

    def answer():
        while True:
            try:
                conn, _ = server.accept()
            except OSError:
                return
            try:
                conn.sendall(frame)
                conn.recv(65536)
            except OSError:
                pass
            conn.close()

    threading.Thread(target=answer, daemon=True).start()
    try:
        address = f"tcp://127.0.0.1:{server.getsockname()[1]}"
        assert main(["diagnose", SAMPLE_LOG, "--scheduler", address]) == 2
    finally:
        server.close()
    assert "does not speak Dask's protocol" in capsys.readouterr().err


def test_compressed_logs_read_as_their_text(tmp_path, capsys, monkeypatch):
    """gzip, bzip2 and xz logs are unpacked into a measured private copy: the same verdicts
    as the plain log (one cut short: test_edge_signals)."""
    import bz2
    import gzip
    import json
    import lzma

    from helpers import ROOT

    plain = (ROOT / SAMPLE_LOG).read_bytes()

    def verdicts(path) -> list:
        assert main(["diagnose", str(path), "-f", "json"]) == 0
        return [
            (s["segment"], s["label"], s["anees"])
            for s in json.loads(capsys.readouterr().out)["segments"]
        ]

    expected = verdicts(ROOT / SAMPLE_LOG)
    for suffix, pack in ((".gz", gzip.compress), (".bz2", bz2.compress), (".xz", lzma.compress)):
        path = tmp_path / f"log.csv{suffix}"
        path.write_bytes(pack(plain))
        assert verdicts(path) == expected, suffix


def test_a_compressed_log_that_unpacks_past_memory_is_refused(tmp_path, capsys, monkeypatch):
    """Issue 32 item 5: a few megabytes of gzip that unpack to more numbers than fit in
    memory are refused while they are unpacked, not parsed; so is NUL padding."""
    import gzip

    from credcli.io import streams

    monkeypatch.setattr(streams, "memory_budget", lambda: 2**24)  # 16 MiB here: 1 Mi fields
    bomb = tmp_path / "bomb.csv.gz"
    bomb.write_bytes(gzip.compress(b"truth_0,est_0,var_0\n" + b"0,0,1\n" * 600_000))
    assert main(["diagnose", str(bomb)]) == 2
    err = capsys.readouterr().err
    assert "bomb.csv.gz: unpacks to over" in err and err.count("\n") == 1, err
    padded = tmp_path / "padded.csv.gz"
    padded.write_bytes(gzip.compress(b"truth_0,est_0,var_0\n0,0,1\n" * 1000 + bytes(1 << 21)))
    assert main(["diagnose", str(padded)]) == 2
    assert "holds NUL bytes past its first 4,096 bytes" in capsys.readouterr().err


def test_a_compressed_field_without_end_is_refused_as_it_is_unpacked(tmp_path, capsys):
    """A 4 MB gzip of one 4 GiB line of zeros was unpacked whole and handed to pandas
    (exit 2 after 33-40 s and 4.3 GB, "C error: out of memory"). A stretch of over 1 MiB
    with no separator is refused while it is unpacked, whether it crosses two chunks or
    many; names and lines up to that length are read."""
    import gzip

    from credcli.io import streams

    header = b"time,truth_0,est_0,var_0\n"
    rows = b"".join(b"%d,0,0.5,1\n" % i for i in range(40))
    limit = streams._LONGEST_FIELD
    for where, body in (
        ("in one line", header + b"0" * (3 * limit)),
        ("across a chunk edge", header + rows + b"7" * (limit - 200) + b"9" * 400 + b",1\n"),
    ):
        path = tmp_path / "bomb.csv.gz"
        path.write_bytes(gzip.compress(body, compresslevel=1))
        assert main(["diagnose", str(path)]) == 2, where
        err = capsys.readouterr().err
        assert "MiB with no separator" in err and err.count("\n") == 1, (where, err)
    named = b"time,truth_0,est_0,var_0,segment\n" + b"".join(
        b"%d,0,0.5,1,%s\n" % (i, b"s" * (limit - 100)) for i in range(40)
    )
    path = tmp_path / "long-names.csv.gz"
    path.write_bytes(gzip.compress(named, compresslevel=1))
    assert main(["diagnose", str(path), "-f", "json"]) == 0
    capsys.readouterr()


def test_a_log_is_read_without_mapping_it(tmp_path, monkeypatch):
    """Issue 32 item 5: pandas maps a large CSV named by path into memory, and a log cut
    short while it was read killed credcli with SIGBUS; it is read through a file object."""
    import mmap

    from credcli.io.logs import read_table

    path = tmp_path / "big.csv"  # past the 5 MB where pandas 3.1 starts to map and thread
    rows = np.random.default_rng(1).standard_normal((180_000, 4)).round(6)
    pd.DataFrame(rows, columns=["truth_0", "est_0", "var_0", "time"]).to_csv(path, index=False)
    assert path.stat().st_size > 6 * 2**20

    class Refused(mmap.mmap):  # a class still, for pandas' isinstance checks
        def __new__(cls, *args, **kwargs):
            raise AssertionError("the log was mapped into memory")

    monkeypatch.setattr(mmap, "mmap", Refused)
    frame = read_table(path)
    assert frame.shape == (180_000, 4) and np.allclose(frame.to_numpy(), rows)


def test_held_out_style_cases_are_usage_errors(tmp_path, capsys, monkeypatch):
    """Cases of a 312-case adversarial corpus that were exit 0 (or unsafe): a column named
    twice, two covariance layouts at once, --jobs past any machine, a window that cuts the
    time span into more windows than int64 counts."""
    from helpers import ROOT

    monkeypatch.chdir(ROOT)
    log = ROOT / SAMPLE_LOG
    both = tmp_path / "both.csv"
    lines = log.read_text().splitlines()
    both.write_text("\n".join([lines[0] + ",var_0,var_1", *(x + ",100,100" for x in lines[1:])]))
    huge = tmp_path / "huge.csv"
    rows = [f"{1e300 * (1 + k / 1000)!r},0,0,{k % 3 - 1},{k % 5 - 2},1,1" for k in range(50)]
    huge.write_text("\n".join(["time,truth_0,truth_1,est_0,est_1,var_0,var_1", *rows]) + "\n")
    cases = (
        (
            ["--truth-columns", "truth_0,truth_0", "--estimate-columns", "est_0,est_1"],
            log,
            "--truth-columns names column 'truth_0' twice",
        ),
        ([], both, "both cov_i_j and var_0, var_1 columns"),
        (["--jobs", "99999999999999999999999"], log, "at most 1,024"),
        (["--window", "5s"], huge, "more than 1e+12 windows"),
    )
    for args, path, message in cases:
        assert main(["diagnose", str(path), *args]) == 2
        err = capsys.readouterr().err
        assert message in err and err.count("\n") == 1, err


def test_a_library_warning_and_an_html_cell_never_carry_a_raw_control_character(capsys):
    """matplotlib's "Glyph 27 (\\x1b) missing" warning quoted a segment name's ESC on
    stderr; the HTML report's cells held it raw."""
    import warnings

    from credcli.cli.edge import note_warnings
    from credcli.engine.diagnosis import Diagnosis, Label, SegmentDiagnosis
    from credcli.logid import LogId
    from credcli.report.html import results_table

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        warnings.warn("Glyph 27 (\x1b) missing from font(s)", UserWarning, stacklevel=1)
    note_warnings(caught, debug=False)
    err = capsys.readouterr().err
    assert _controls(err) == set() and "\\x1b" in err
    item = SegmentDiagnosis(
        LogId.of("x"), "a\x1b]0;t\x07", None, None, Diagnosis(Label.CREDIBLE, 1, 1)
    )
    html = results_table([item])
    assert _controls(html) == set() and "\\x1b" in html


@pytest.mark.parametrize("unnamed", [True, False], ids=["O_TMPFILE", "named-temporary"])
def test_an_output_name_of_many_bytes_per_character_is_written(unnamed, tmp_path, monkeypatch):
    """A valid 249-byte name of two-byte characters was refused ("the file name is too
    long"): its temporary name took 200 characters, 400 bytes, past the 255-byte limit."""
    from credcli.io import files

    if not unnamed:
        monkeypatch.setattr(files, "_write_unnamed", lambda *args: False)
    for name in ("\u00e9" * 122 + ".json", "\u4e2d" * 80 + ".json"):
        path = tmp_path / name
        files.write_atomic(path, "{}")
        assert path.read_text() == "{}"
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(
        ["\u00e9" * 122 + ".json", "\u4e2d" * 80 + ".json"]
    )


def test_figures_never_overwrite_an_input_nor_go_through_a_link(tmp_path, capsys, monkeypatch):
    """--plots . beside a config named timeline.png replaced the config with a figure (and
    the -o output with another); a --plots that is a symbolic link wrote the figures where
    it points; --plots and --report on one path wrote every figure, then failed (exit 2
    with two lines). Each is refused before anything is written."""
    pytest.importorskip("matplotlib")
    monkeypatch.chdir(tmp_path)
    log = str(_short_log(tmp_path / "log.csv", np.random.default_rng(5)))
    config = tmp_path / "timeline.png"
    config.write_text("[diagnosis]\nseed = 0\n")
    args = ["diagnose", log, "-f", "json", "-o", "out.json"]
    assert main([*args, "--config", "timeline.png", "--plots", "."]) == 2
    err = capsys.readouterr().err
    assert "would overwrite timeline.png" in err and err.count("\n") == 1, err
    assert config.read_text() == "[diagnosis]\nseed = 0\n"
    assert main(["diagnose", log, "-f", "json", "-o", "errors.png", "--plots", "."]) == 2
    assert "would overwrite errors.png" in capsys.readouterr().err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["log.csv", "timeline.png"]
    outside = tmp_path / "outside"
    outside.mkdir()
    (tmp_path / "figs").symlink_to(outside)
    assert main([*args, "--plots", "figs"]) == 2
    assert "--plots figs: is a symbolic link" in capsys.readouterr().err
    assert main([*args, "--plots", "x", "--report", "x"]) == 2
    err = capsys.readouterr().err
    assert "--plots and --report are the same path" in err and err.count("\n") == 1, err
    assert list(outside.iterdir()) == [] and not (tmp_path / "x").exists()
    assert not (tmp_path / "out.json").exists()


def test_csv_on_standard_output_escapes_what_a_terminal_would_obey(evil_log, capsys, tmp_path):
    """CSV on stdout carried a segment name's ESC, BEL and CR raw to the terminal (and a
    file name's undecodable bytes to an encoder that refuses them: exit 3 under a strict
    UTF-8 locale); each cell is escaped there now, while a CSV file keeps the names as
    they are (test_csv_is_rfc4180_and_never_a_formula)."""
    import os
    import shutil

    from helpers import ROOT

    assert main(["diagnose", str(evil_log), "-f", "csv"]) == 0
    out = capsys.readouterr().out
    assert not _controls(out.replace("\r\n", "\n")), _controls(out)
    rows = list(csv.DictReader(out.splitlines()))
    assert [r["segment"] for r in rows] == [
        "ok",
        "'" + NAMES[1],
        "bad\\x1b]0;title\\x07",
        "two\\ncredcli: PASS: forged",
        "cr\\rrow",
        "c1\\x9bcsi",
    ]
    log = os.fsdecode(os.fsencode(tmp_path) + b"/log\xff.csv")
    shutil.copy(ROOT / SAMPLE_LOG, log)
    assert main(["diagnose", log, str(evil_log), "-f", "csv"]) == 0
    out = capsys.readouterr().out
    assert "log\\udcff.csv" in out and out.encode("utf-8")  # no lone surrogate left
    clean = ROOT / SAMPLE_LOG
    assert main(["diagnose", str(clean), "-f", "csv"]) == 0  # no such cell: as it was
    from credcli.report.formats import OutputFormat
    from credcli.report.render import to_text
    from credcli.requests import DiagnoseRequest
    from credcli.workflows import run_diagnose

    expected = to_text(run_diagnose(DiagnoseRequest((str(clean),))).report, OutputFormat.CSV)
    assert capsys.readouterr().out == expected


def test_a_baseline_that_is_a_device_or_far_too_large_is_refused_unread(
    tmp_path, capsys, monkeypatch
):
    """A committed baseline that is a symbolic link to /dev/zero was read whole: 22 GB of
    memory until the kernel killed credcli (or another process). Refused before reading;
    a baseline through a pipe (<(git show …)) is still read."""
    from helpers import ROOT

    from credcli.io import files

    monkeypatch.chdir(ROOT)
    link = tmp_path / "baseline.json"
    link.symlink_to("/dev/zero")
    assert main(["gate", SAMPLE_LOG, "-b", str(link)]) == 2
    err = capsys.readouterr().err
    assert "is a device, not a baseline JSON file" in err and err.count("\n") == 1, err
    big = tmp_path / "big.json"
    assert main(["baseline", SAMPLE_LOG, "-o", str(big)]) == 0
    monkeypatch.setattr(files, "memory_budget", lambda: 16 * 1024)  # 1 KiB for a baseline
    assert main(["gate", SAMPLE_LOG, "-b", str(big)]) == 2
    assert "more than the 1 KiB a baseline JSON file may take" in capsys.readouterr().err


def test_covariances_that_would_not_fit_in_memory_are_refused_before_allocating(
    tmp_path, capsys, monkeypatch
):
    """40 rows of d = 3,000 variance columns (a 2.9 MB CSV) took 11.8 GB and 75 s; 20 rows
    of d = 6,000 would have taken 23 GB. The N·d² covariances are checked against the
    memory budget before they are made, for a CSV and for an .npz of variances alike."""
    from credcli.io import files

    monkeypatch.setattr(files, "memory_budget", lambda: 2**21)  # 2 MiB here
    d = 40  # 60 epochs: 0.73 MiB of covariances, about 4 times that to diagnose them
    gen = np.random.default_rng(2)
    frame = pd.DataFrame(gen.standard_normal((60, d)), columns=[f"est_{i}" for i in range(d)])
    frame = frame.assign(**{f"truth_{i}": 0.0 for i in range(d)})
    frame = frame.assign(**{f"var_{i}": 1.0 for i in range(d)})
    frame.to_csv(tmp_path / "wide.csv", index=False)
    np.savez(
        tmp_path / "wide.npz",
        truth=np.zeros((60, d)),
        estimate=frame.iloc[:, :d],
        cov=np.ones((60, d)),
    )
    for name in ("wide.csv", "wide.npz"):
        assert main(["diagnose", str(tmp_path / name)]) == 2
        err = capsys.readouterr().err
        assert "60 epochs of dimension d = 40 make 750 KiB of covariance matrices" in err, err
        assert err.count("\n") == 1
    monkeypatch.setattr(files, "memory_budget", lambda: 2**22)  # 4 MiB: diagnosed
    assert main(["diagnose", str(tmp_path / "wide.csv")]) == 0


@pytest.mark.parametrize("scheme", ["ws", "WS", "ucx"])
def test_other_plaintext_schedulers_off_this_machine_are_refused(scheme, capsys, monkeypatch):
    """ws:// (and ucx://) carry the pickled results as unauthenticated as tcp://, but went
    to Dask as they were: a connection attempt to any host (10 s), not a refusal."""
    pytest.importorskip("distributed")
    from helpers import ROOT

    from credcli.schedule.cluster import REMOTE_OPT_IN

    monkeypatch.chdir(ROOT)
    monkeypatch.delenv(REMOTE_OPT_IN, raising=False)
    assert main(["diagnose", SAMPLE_LOG, "--scheduler", f"{scheme}://192.0.2.7:8786"]) == 2
    err = capsys.readouterr().err
    assert "a plaintext scheduler off this machine" in err and REMOTE_OPT_IN in err, err


def test_a_name_that_reads_as_mathtext_is_drawn_as_text(tmp_path, capsys):
    """A segment named '$\\frac{a$' ended --plots and report in exit 3: matplotlib parsed
    the figure titles and legends as mathtext."""
    pytest.importorskip("matplotlib")
    log = str(_short_log(tmp_path / "m.csv", np.random.default_rng(5), "$\\frac{a$", 3.0))
    assert main(["diagnose", log, "--plots", str(tmp_path / "figs")]) == 0
    assert main(["report", log, "-o", str(tmp_path / "r.html")]) == 0
    assert "internal error" not in capsys.readouterr().err
    assert any(p.name.endswith("_nees.png") for p in (tmp_path / "figs").iterdir())


def test_curve_runs_past_any_machine_are_a_usage_error(capsys):
    """--curve-runs 10¹⁵ ended in exit 3 ("Unable to allocate 14.2 PiB"); a million runs
    in d = 64 in exit 2 after 5 GB, with a numpy note after the error line."""
    for args, words in (
        (["--curve-runs", "999999999999999"], "--curve-runs must be 1 … 1,000,000"),
        (["--curve-runs", "1000000", "--dim", "64"], "would need 122 GiB"),
    ):
        assert main(["simulate", "--curves", *args]) == 2
        err = capsys.readouterr().err
        assert words in err and err.count("\n") == 1, err


def test_an_error_line_is_not_followed_by_the_runs_notes(capsys, monkeypatch):
    """A warning recorded before an error (numpy's overflow) was printed as a note after
    the error line: exit 2 with two lines. The notes of a failed run show under --debug."""
    import warnings

    from credcli.cli import settings
    from credcli.errors import CredcliError

    def failing(*args, **kwargs):
        warnings.warn("overflow encountered in multiply", RuntimeWarning, stacklevel=1)
        raise CredcliError("the log is bad")

    monkeypatch.setattr(settings, "diagnose_request", failing)
    assert main(["diagnose", "x.csv"]) == 2
    assert capsys.readouterr().err == "credcli: error: the log is bad\n"
    assert main(["--debug", "diagnose", "x.csv"]) == 2
    assert "overflow encountered in multiply" in capsys.readouterr().err


def test_a_local_cluster_of_more_workers_than_cores_can_take_is_refused(capsys, monkeypatch):
    """--scheduler local:100000 started worker processes until it was killed (past 60 s,
    its scratch directory left behind); refused before any is started."""
    pytest.importorskip("distributed")
    from helpers import ROOT

    from credcli.schedule import cluster

    monkeypatch.chdir(ROOT)
    monkeypatch.setattr(cluster, "_local_cluster", lambda workers: pytest.fail("started"))
    assert main(["diagnose", SAMPLE_LOG, "--scheduler", "local:100000"]) == 2
    err = capsys.readouterr().err
    assert f"at most {cluster.max_local_workers()} local workers" in err and err.count("\n") == 1


def test_wide_full_covariances_are_checked_a_matrix_at_a_time(monkeypatch):
    """Two epochs of one 3,000 × 3,000 covariance (an .npz) took 52 s: the symmetry check
    went an entry pair at a time, 9 million Python steps. Above d = 16 whole matrices are
    checked, with the same result and the same note as pair by pair."""
    import itertools

    from credcli.io import logs

    gen = np.random.default_rng(0)
    d, n = 40, 30
    a = gen.standard_normal((n, d, d))
    cov = a @ a.transpose(0, 2, 1) + d * np.eye(d) + 1e-3 * gen.standard_normal((n, d, d))
    pairwise, notes = cov.copy(), []
    with monkeypatch.context() as m:
        m.setattr(logs, "PAIRWISE_MAX_D", 10**9, raising=False)
        logs.validated_cov(pairwise, np.arange(n), "x", notes=notes)

    class NoPairs:
        def product(self, *args, **kwargs):
            raise AssertionError("an entry pair at a time")

    whole, whole_notes = cov.copy(), []
    monkeypatch.setattr(logs, "itertools", NoPairs())
    logs.validated_cov(whole, np.arange(n), "x", notes=whole_notes)
    monkeypatch.setattr(logs, "itertools", itertools)
    assert np.array_equal(whole, pairwise) and whole_notes == notes and len(notes) == 1
    assert np.array_equal(whole, whole.transpose(0, 2, 1))


@pytest.mark.parametrize(
    "env, shown",
    [
        ({"PYTHONIOENCODING": "ascii"}, "cov \\xd7 (interval)"),
        ({"LC_ALL": "C", "LANG": "C", "PYTHONUTF8": "0"}, "cov \\xd7 (interval)"),
    ],
    ids=["ascii", "C-locale"],
)
def test_an_output_stream_that_cannot_encode_a_character_gets_its_escape(env, shown, tmp_path):
    """Under LC_ALL=C (or PYTHONIOENCODING=ascii) the table's × ended in exit 3
    (UnicodeEncodeError); what the stream cannot encode is written as its backslash escape
    (a file name's undecodable bytes too)."""
    import os
    import shutil
    import subprocess
    import sys

    from helpers import ROOT

    shutil.copy(ROOT / SAMPLE_LOG, os.fsdecode(os.fsencode(tmp_path) + b"/log\xff.csv"))
    proc = subprocess.run(
        [
            sys.executable,
            "-m",
            "credcli",
            "diagnose",
            b"log\xff.csv",
            ROOT / SAMPLE_LOG,
            "-f",
            "markdown",
        ],
        capture_output=True,
        cwd=tmp_path,
        env={**os.environ, "PYTHONPATH": str(ROOT), **env},
    )
    assert proc.returncode == 0, proc.stderr
    out = proc.stdout.decode("ascii")
    row = next(line for line in out.splitlines() if "cruise" in line)
    assert shown in out and "log\\\\udcff.csv" in row, row


def test_a_log_name_that_is_not_utf8_is_drawn_escaped(tmp_path, capsys):
    """A log whose name is not valid UTF-8 (held as surrogates) ended --plots and report in
    exit 3: matplotlib refused the title that named it."""
    pytest.importorskip("matplotlib")
    import os

    base = os.fsencode(tmp_path)
    log = os.fsdecode(base + b"/log\xff.csv")
    _short_log(Path(log), np.random.default_rng(5), "s", 3.0)
    assert main(["diagnose", log, "--plots", os.fsdecode(base + b"/figs")]) == 0
    assert main(["report", log, "-o", os.fsdecode(base + b"/r.html")]) == 0
    assert "internal error" not in capsys.readouterr().err


def test_binary_names_that_are_not_utf8_and_repeated_header_words(tmp_path, capsys):
    """Two exit 3s: a Parquet segment column of bytes that are not UTF-8
    (UnicodeDecodeError), and a TUM file whose comment line repeats a word ('# t 1 1 1 …':
    the columns, read by those words, came back as a table)."""
    import pyarrow as pa
    import pyarrow.parquet as pq
    from helpers import ROOT

    from credcli.errors import CredcliError
    from credcli.io.logs import numeric_columns

    gen = np.random.default_rng(1)
    e = gen.standard_normal((40, 2))
    table = pa.table(
        {
            "segment": pa.array([b"\xff\x1b]0;x\x07"] * 40, pa.binary()),
            **{f"truth_{i}": np.zeros(40) for i in range(2)},
            **{f"est_{i}": e[:, i] for i in range(2)},
            **{f"var_{i}": np.ones(40) for i in range(2)},
        }
    )
    pq.write_table(table, tmp_path / "bytes.parquet")
    assert main(["diagnose", str(tmp_path / "bytes.parquet"), "-f", "json"]) == 0
    assert '"segment": "\\\\xff\\u001b]0;x\\u0007"' in capsys.readouterr().out
    formats = ROOT / "sample_data" / "formats"
    lines = (formats / "openvins_estimate.txt").read_text().splitlines()
    lines[0] = "# t 1 1 1 q q q q " + " ".join(["p"] * 12)
    (tmp_path / "est.txt").write_text("\n".join(lines) + "\n")
    args = ["diagnose", str(tmp_path / "est.txt"), "--truth", str(formats / "tum_groundtruth.txt")]
    assert main([*args, "-f", "json"]) == 0
    original = ["diagnose", str(formats / "openvins_estimate.txt"), *args[2:], "-f", "json"]
    ours = capsys.readouterr().out
    assert main(original) == 0
    same = capsys.readouterr().out
    assert ours.replace(str(tmp_path / "est.txt"), "X") == same.replace(original[1], "X")
    frame = pd.DataFrame([[1.0, 2.0]], columns=["a", "a"])
    with pytest.raises(CredcliError, match="column 'a' is named 2 times in the header"):
        numeric_columns(frame, ["a"], "f.csv")


def test_a_step_summary_that_is_a_link_is_refused_and_never_followed(tmp_path, capsys, monkeypatch):
    """$GITHUB_STEP_SUMMARY naming a symbolic link appended the summary to the file it
    points to; refused before any work, and the append itself does not follow a link."""
    from helpers import ROOT

    from credcli.ci import reports

    monkeypatch.chdir(ROOT)
    outside = tmp_path / "outside.md"
    outside.write_text("keep me\n")
    link = tmp_path / "summary.md"
    link.symlink_to(outside)
    monkeypatch.setenv("GITHUB_STEP_SUMMARY", str(link))
    assert main(["diagnose", SAMPLE_LOG, "--fail-on", "smm"]) == 2
    assert "is a symbolic link" in capsys.readouterr().err
    monkeypatch.setattr(reports, "check_step_summary", lambda path: None)  # a link made late
    with pytest.raises(CredcliError, match="cannot append the summary"):
        reports.append_step_summary("# summary\n")
    assert outside.read_text() == "keep me\n"


def test_errors_that_drift_without_a_finite_memory_are_declined_not_a_crash(capsys):
    """Smooth trajectories taken as errors (`--truth-columns` on positions): the fitted AR
    model has a root on the unit circle to working precision, where its Yule–Walker system
    is singular (issue 32: exit 3, "LinAlgError: Singular matrix")."""
    import credcli

    t = np.linspace(0.0, 30.0, 300)
    errors = np.column_stack([50.0 * np.cos(t / 10.0), 3.0 * t + 0.1 * t**2])
    result = credcli.diagnose(errors, np.diag(np.mean(errors**2, axis=0)), seed=1)
    assert result.label.value == "insufficient-data"
    sample = Path(__file__).parents[1] / "sample_data" / "estimator_log.csv"
    args = ["diagnose", str(sample), "--errors-only", "--truth-columns", "truth_0,truth_1"]
    assert main(args) == 0
    assert "no finite memory" in capsys.readouterr().out


def _credible_csv(path: Path, dim: int = 2) -> Path:
    """A 300-epoch credible CSV log of dimension ``dim`` in segments ``a`` and ``b``."""
    e = np.random.default_rng(dim).standard_normal((300, dim))
    frame = pd.DataFrame({"time": np.arange(300) * 0.1, "segment": np.repeat(["a", "b"], 150)})
    frame = frame.assign(**{f"truth_{i}": 0.0 for i in range(dim)})
    frame = frame.assign(**{f"est_{i}": e[:, i] for i in range(dim)})
    frame.assign(**{f"var_{i}": 1.0 for i in range(dim)}).to_csv(path, index=False)
    return path


def test_npz_segment_labels_of_non_utf8_bytes_are_read_as_escaped_text(tmp_path):
    """A .npz whose segment labels are bytes that are not UTF-8 (once exit 3, a
    UnicodeDecodeError): read, the bytes kept as \\xNN escapes."""
    from helpers import run

    e = np.random.default_rng(1).standard_normal((60, 2))
    path = tmp_path / "x.npz"
    np.savez(
        path,
        truth=e,
        estimate=np.zeros((60, 2)),
        cov=np.broadcast_to(np.eye(2), (60, 2, 2)),
        segment=np.array([b"\xff\x1b"] * 60),
    )
    code, out, err = run("diagnose", path, "-f", "json")
    assert code == 0, err
    assert '"segment": "\\\\xff\\u001b"' in out


def test_a_huge_config_file_is_refused_before_it_is_read(tmp_path):
    """A sparse 1 TiB config (once exit 3, MemoryError) is bad input: one line, exit 2."""
    from helpers import error_line, run

    config = tmp_path / "c.toml"
    with open(config, "wb") as handle:
        handle.write(b"[diagnosis]\n")
        handle.truncate(1 << 40)
    log = _credible_csv(tmp_path / "log.csv")
    code, _, err = run("diagnose", log, "--config", config)
    assert "too large for a config file" in error_line(code, err)


def test_a_closed_standard_output_is_bad_usage_not_a_crash(tmp_path, monkeypatch, capsys):
    """Started with stdout closed (``credcli … >&-``, sys.stdout None; once exit 3, an
    AttributeError): exit 2 naming -o."""
    import sys

    log = _credible_csv(tmp_path / "log.csv")
    monkeypatch.setattr(sys, "stdout", None)
    code = main(["diagnose", str(log), "-f", "json"])
    err = capsys.readouterr().err
    assert code == 2 and "standard output is closed" in err and "-o FILE" in err


def test_gate_refuses_a_log_of_another_dimension(tmp_path):
    """A d = 3 log gated against a d = 2 baseline with the same segment names once passed
    (exit 0, 'no regression'): its labels describe other states, so it is bad input."""
    from helpers import error_line, run

    baseline = tmp_path / "b.json"
    assert run("baseline", _credible_csv(tmp_path / "d2.csv"), "-o", baseline)[0] == 0
    code, _, err = run("gate", _credible_csv(tmp_path / "d3.csv", dim=3), "-b", baseline)
    assert "d = 2 states, the new log's d = 3" in error_line(code, err)
    assert run("gate", tmp_path / "d2.csv", "-b", baseline)[0] == 0


def test_verdict_lines_cut_long_segment_names(tmp_path):
    """A 100,000-character segment name once made a 100,000-character verdict line."""
    from helpers import run

    e = 3.0 * np.random.default_rng(2).standard_normal((200, 2))  # optimism
    frame = pd.DataFrame({"segment": ["s" * 100_000] * 200, "truth_0": 0.0, "truth_1": 0.0})
    frame = frame.assign(est_0=e[:, 0], est_1=e[:, 1], var_0=1.0, var_1=1.0)
    frame.to_parquet(tmp_path / "log.parquet", index=False)
    code, _, err = run(
        "diagnose", tmp_path / "log.parquet", "--fail-on", "noncredible", "-o", tmp_path / "o.json"
    )
    verdict = [line for line in err.splitlines() if "FAIL" in line]
    assert code == 1 and len(verdict) == 1 and len(verdict[0]) < 300, err[:400]
    assert "(100,000 characters)" in verdict[0]


def test_an_encrypted_npz_member_is_bad_input(tmp_path):
    """A .npz whose members are flagged encrypted (once exit 3, zipfile's RuntimeError)."""
    import io

    from helpers import error_line, run

    buffer = io.BytesIO()
    np.savez(buffer, truth=np.zeros((30, 2)), estimate=np.ones((30, 2)), cov=np.eye(2))
    data = bytearray(buffer.getvalue())
    for signature, offset in ((b"PK\x03\x04", 6), (b"PK\x01\x02", 8)):  # flag bit 0: encrypted
        at = data.find(signature)
        while at >= 0:
            data[at + offset] |= 1
            at = data.find(signature, at + 4)
    (tmp_path / "x.npz").write_bytes(bytes(data))
    code, _, err = run("diagnose", tmp_path / "x.npz")
    assert "encrypted" in error_line(code, err)


def test_truth_quaternions_of_huge_components_are_normalised(tmp_path):
    """A TUM truth whose quaternion w components are 1e300 (once exit 3: the norm
    overflowed to inf, the quaternion to zero): read as the unit quaternions they are."""
    import re

    from helpers import run

    formats = Path(__file__).parents[1] / "sample_data" / "formats"
    truth = (formats / "tum_groundtruth.txt").read_text()
    (tmp_path / "t.txt").write_text(re.sub(r"(?m)(?<=\d) (\S+)$", " 1e300", truth))
    code, _, err = run(
        "diagnose",
        formats / "openvins_estimate.txt",
        "--truth",
        tmp_path / "t.txt",
        "--states",
        "pose",
        "-f",
        "json",
    )
    assert code == 0, err


def test_settings_that_exclude_each_other_are_refused_not_one_silently_dropped(tmp_path):
    """--window with --whole (once: --window silently ignored), var_i beside std_i columns
    (once: var_i silently read) and a --cov-kind the columns found do not have (once:
    silently ignored) are each exit 2 with one line; a command-line --whole over a
    config's window is the command line's choice."""
    from helpers import error_line, run

    log = _credible_csv(tmp_path / "log.csv")
    code, _, err = run("diagnose", log, "--window", "40", "--whole")
    assert "--window and --whole exclude each other" in error_line(code, err)
    config = tmp_path / "c.toml"
    config.write_text('[segments]\nwindow = "40"\nwhole = true\n')
    code, _, err = run("diagnose", log, "--config", config)
    assert "sets both window and whole" in error_line(code, err)
    code, out, err = run("diagnose", log, "--config", config, "--whole", "-f", "csv")
    assert code == 0 and out.count("\n") == 2, err  # a header and the one segment "all"
    frame = pd.read_csv(log)
    frame.assign(std_0=1.0, std_1=1.0).to_csv(tmp_path / "both.csv", index=False)
    code, _, err = run("diagnose", tmp_path / "both.csv")
    assert "both var_i and std_i columns" in error_line(code, err)
    code, _, err = run("diagnose", log, "--cov-kind", "std")
    assert "--cov-kind std does not describe" in error_line(code, err)
    assert run("diagnose", log, "--cov-kind", "var", "-f", "json")[0] == 0


def test_an_output_under_another_output_or_a_file_is_refused_before_anything_is_written(
    tmp_path, monkeypatch
):
    """--plots under -o's file, --summary under --junit's, -o under an existing file (each
    once failed only after the other outputs were written: exit 2 with two lines and a
    file left behind), and a figure whose name is --summary's (once silently replaced)."""
    from helpers import error_line, run

    monkeypatch.chdir(tmp_path)
    log = _credible_csv(tmp_path / "log.csv")
    code, _, err = run("diagnose", log, "-f", "json", "-o", "o.json", "--plots", "o.json/figs")
    assert "lies under --output" in error_line(code, err) and not Path("o.json").exists()
    code, _, err = run(
        "diagnose", log, "--fail-on", "noncredible", "--junit", "j.xml", "--summary", "j.xml/s.md"
    )
    assert "lies under --junit" in error_line(code, err) and not Path("j.xml").exists()
    Path("afile").write_text("kept")
    code, _, err = run("diagnose", log, "-f", "json", "-o", "afile/o.json")
    assert "is a file, not a directory" in error_line(code, err)
    assert Path("afile").read_text() == "kept"
    pytest.importorskip("matplotlib")
    code, _, err = run(
        "diagnose",
        log,
        "--fail-on",
        "noncredible",
        "--summary",
        "figs/timeline.png",
        "--plots",
        "figs",
    )
    assert "would overwrite figs/timeline.png" in error_line(code, err)
    assert not Path("figs/timeline.png").exists()


def test_integers_beyond_the_float_range_are_bad_input_in_configs_and_baselines(tmp_path):
    """A 401-digit integer where a number is expected once overflowed on conversion (exit
    3, OverflowError): in a config's [diagnosis], a baseline segment's NCI and a
    baseline's integer n_flips."""
    import json
    import re

    from helpers import error_line, run

    big = "1" + "0" * 400
    log = _credible_csv(tmp_path / "log.csv")
    (tmp_path / "c.toml").write_text(f"[diagnosis]\ntau_nci = {big}\n")
    code, _, err = run("diagnose", log, "--config", tmp_path / "c.toml")
    assert "tau_nci must be a number" in error_line(code, err)
    assert run("baseline", log, "-o", tmp_path / "b.json")[0] == 0
    text = (tmp_path / "b.json").read_text()
    nci = re.sub(r'"nci": [^,]+,', f'"nci": {big},', text, count=1)
    (tmp_path / "nci.json").write_text(nci)
    code, _, err = run("gate", log, "-b", tmp_path / "nci.json")
    assert "'nci' must be a number or null" in error_line(code, err)
    assert json.loads(text)["parameters"]["n_flips"] > 0
    flips = re.sub(r'"n_flips": \d+', f'"n_flips": {big}', text, count=1)
    (tmp_path / "flips.json").write_text(flips)
    code, _, err = run("gate", log, "-b", tmp_path / "flips.json")
    assert "n_flips must be an integer" in error_line(code, err)


def test_a_ros2_bag_with_a_fifo_a_huge_metadata_or_bad_compression_is_bad_input(tmp_path):
    """A bag directory whose .db3 is a FIFO (once a hang), whose metadata.yaml is 1 TiB
    (once MemoryError, exit 3) or claims a compression its data do not have (once
    ZstdError, exit 3): each exit 2 with one line."""
    import os
    import shutil

    pytest.importorskip("rosbags")
    from helpers import error_line, run

    source = Path(__file__).parents[1] / "sample_data" / "formats" / "odom_ros2"
    args = ("--topic", "/odom", "--truth-topic", "/ground_truth")
    fifo = shutil.copytree(source, tmp_path / "fifo")
    database = next(fifo.glob("*.db3"))
    database.unlink()
    os.mkfifo(database)
    code, _, err = run("diagnose", fifo, *args)
    assert "not a regular file" in error_line(code, err)
    huge = shutil.copytree(source, tmp_path / "huge")
    with open(huge / "metadata.yaml", "r+b") as handle:
        handle.truncate(1 << 40)
    code, _, err = run("diagnose", huge, *args)
    assert "too large for a bag's metadata" in error_line(code, err)
    import re

    packed = shutil.copytree(source, tmp_path / "packed")
    meta = (packed / "metadata.yaml").read_text()
    meta = re.sub(r"compression_format: .*", "compression_format: zstd", meta)
    meta = re.sub(r"compression_mode: .*", "compression_mode: FILE", meta)
    (packed / "metadata.yaml").write_text(meta)
    code, _, err = run("diagnose", packed, *args)
    assert "cannot be read as a ROS bag" in error_line(code, err)


def test_a_bad_mplbackend_does_not_stop_the_figures(tmp_path):
    """MPLBACKEND=nonexistent once failed matplotlib's import (exit 3); credcli draws with
    Agg whatever the backend. In a child process: matplotlib is imported fresh."""
    import os
    import subprocess
    import sys

    pytest.importorskip("matplotlib")
    log = _credible_csv(tmp_path / "log.csv")
    env = dict(os.environ, MPLBACKEND="nonexistent")
    env["PYTHONPATH"] = str(Path(__file__).parents[1])
    done = subprocess.run(
        [sys.executable, "-m", "credcli", "diagnose", str(log), "--plots", str(tmp_path / "f")],
        env=env,
        capture_output=True,
        cwd=tmp_path,
        timeout=120,
    )
    assert done.returncode == 0, done.stderr.decode()[-300:]
    assert any((tmp_path / "f").glob("*.png"))


def test_an_output_in_a_missing_directory_is_refused_before_the_others_are_written(
    tmp_path, monkeypatch
):
    """-o o.json with --junit nodir/j.xml once wrote o.json, then failed (exit 2, two
    lines)."""
    from helpers import error_line, run

    monkeypatch.chdir(tmp_path)
    log = _credible_csv(tmp_path / "log.csv")
    code, _, err = run(
        "diagnose",
        log,
        "-f",
        "json",
        "-o",
        "o.json",
        "--fail-on",
        "noncredible",
        "--junit",
        "nodir/j.xml",
    )
    assert "does not exist" in error_line(code, err) and not Path("o.json").exists()


def test_baselines_with_a_float_schema_version_or_a_negative_anees_are_refused(tmp_path):
    """ "schema_version": 1.0 and an ANEES of −1 were once read as a version-1 baseline
    and as a value (shown as an improvement)."""
    import json

    from helpers import error_line, run

    log = _credible_csv(tmp_path / "log.csv")
    assert run("baseline", log, "-o", tmp_path / "b.json")[0] == 0
    doc = json.loads((tmp_path / "b.json").read_text())
    (tmp_path / "v.json").write_text(json.dumps(doc | {"schema_version": 1.0}))
    code, _, err = run("gate", log, "-b", tmp_path / "v.json")
    assert "schema version 1.0 is not supported" in error_line(code, err)
    doc["segments"][0]["anees"] = -1.0
    (tmp_path / "a.json").write_text(json.dumps(doc))
    code, _, err = run("gate", log, "-b", tmp_path / "a.json")
    assert "'anees' must be >= 0" in error_line(code, err)


def test_a_long_scheduler_address_is_cut_in_its_note(tmp_path, monkeypatch):
    """CREDCLI_SCHEDULER of 5,000 characters once made a 5,000-character note line."""
    from helpers import run

    monkeypatch.setenv("CREDCLI_SCHEDULER", "tcp://" + "a" * 5000 + ":1")
    code, _, err = run("diagnose", _credible_csv(tmp_path / "log.csv"))
    assert code == 2 and max(len(line) for line in err.splitlines()) <= 600, err[:300]


def test_an_empty_truth_in_a_config_is_bad_input(tmp_path):
    """[input] truth = "" was read as the current directory (".: not a ROS2 bag")."""
    from helpers import error_line, run

    formats = Path(__file__).parents[1] / "sample_data" / "formats"
    (tmp_path / "c.toml").write_text('[input]\ntruth = ""\n')
    code, _, err = run(
        "diagnose", formats / "openvins_estimate.txt", "--config", tmp_path / "c.toml"
    )
    assert "is empty; name the ground-truth file" in error_line(code, err)
