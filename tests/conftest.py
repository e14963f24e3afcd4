"""Shared fixtures (the helpers are in ``helpers.py``)."""

from __future__ import annotations

from pathlib import Path
from typing import NamedTuple

import numpy as np
import pytest
from helpers import LOG, run


@pytest.fixture
def rng():
    return np.random.default_rng(12345)


@pytest.fixture(autouse=True)
def one_process_without_jobs(monkeypatch):
    """A command run in a test's process without ``--jobs`` stays in that process.

    The command line's default is a worker per core; ``make test`` already runs a test
    process per core, and a worker spawned from a test process (pyarrow is loaded, so it
    is spawned, not forked) imports numpy, scipy and credcli again: about 3 s of a 2-core
    machine for each in-process ``simulate``, for nothing the test checks. Only the
    default changes: a test about workers gives ``--jobs`` (test_speed_paths.py,
    test_simulate.py), and a command run as a subprocess keeps the real default."""
    from credcli.cli import settings

    given = settings.jobs_value
    monkeypatch.setattr(settings, "jobs_value", lambda jobs: 1 if jobs is None else given(jobs))


class SampleRun(NamedTuple):
    """A run of ``credcli diagnose`` on the sample log, with what it wrote."""

    code: int
    err: str
    report: Path  # the HTML report (--report)
    plots: Path  # the directory of its figures (--plots)


@pytest.fixture(scope="session")
def sample_figures(tmp_path_factory) -> SampleRun:
    """``credcli diagnose LOG --plots DIR --report FILE``: the sample log's 28 figures, as
    PNG files and in its HTML report. Drawn once per test process (about 8 s) for every
    test that reads them; the figures are drawn once for both outputs."""
    where = tmp_path_factory.mktemp("sample")
    report, plots = where / "r.html", where / "figs"
    code, _, err = run("diagnose", LOG, "--plots", plots, "--report", report)
    return SampleRun(code, err, report, plots)
