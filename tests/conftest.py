"""Shared fixtures (the helpers are in ``helpers.py``)."""

from __future__ import annotations

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


@pytest.fixture(scope="session")
def sample_html_report(tmp_path_factory):
    """(exit code, stderr, path) of ``credcli diagnose LOG --report``: the sample log's
    28-figure HTML report, built once per test process for the tests that read it."""
    path = tmp_path_factory.mktemp("report") / "r.html"
    code, _, err = run("diagnose", LOG, "--report", path)
    return code, err, path
