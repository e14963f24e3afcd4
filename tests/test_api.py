"""The Python API: the examples of docs/python.md run, and the API gives what the CLI gives."""

from __future__ import annotations

import doctest
import json
import os
from pathlib import Path

import numpy as np

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
    """`credcli --help` and `--version` import no numpy, scipy or pandas (start-up)."""
    import subprocess
    import sys

    code = (
        "import sys, credcli, credcli.cli, credcli.cli.edge; "
        "print(sorted(m for m in ('numpy', 'scipy', 'pandas', 'matplotlib') if m in sys.modules))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"
    help_text = subprocess.run(
        [sys.executable, "-m", "credcli", "--help"], capture_output=True, text=True, check=True
    ).stdout
    assert "diagnose" in help_text and "--debug" in help_text
