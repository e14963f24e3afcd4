"""Shared fixtures (the helpers are in ``helpers.py``)."""

from __future__ import annotations

import os
from pathlib import Path
from typing import NamedTuple

import numpy as np
import pytest
import threadpoolctl
from helpers import LOG, once_per_run, run
from hypothesis import settings

from credcli.schedule.pool import single_threaded_blas

# The property tests draw their examples from a seed fixed by each test's source under
# `make test` (CI included), so that a run passes or fails whatever the day: a failure
# there is a change of the code, never a new draw. `make fuzz` runs them with fresh random
# examples (and Hypothesis' example database), to look further; what it finds is kept as
# an @example beside the test.
settings.register_profile("repeatable", derandomize=True, database=None)
settings.register_profile("fuzz", derandomize=False)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "repeatable"))

# One BLAS thread in each test process, as the command line and its workers have
# (credcli.schedule.pool): make test runs a test process per core, and a second BLAS
# thread per process only contends for the cores. The thread variables reach the BLAS
# libraries loaded from here on (scipy's); numpy's is loaded already, and is limited.
single_threaded_blas()
threadpoolctl.threadpool_limits(1, user_api="blas")


def pytest_collection_modifyitems(items):
    """Mark the property tests ``property``, so that ``make fuzz`` selects them."""
    from hypothesis import is_hypothesis_test

    for item in items:
        if is_hypothesis_test(getattr(item, "obj", None)):
            item.add_marker(pytest.mark.property)


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
    PNG files and in its HTML report. Drawn once per test run (about 8 s; see
    :func:`once_per_run`) for every test that reads them; the figures are drawn once for
    both outputs."""

    def make(where: Path) -> dict:
        report, plots = where / "r.html", where / "figs"
        code, _, err = run("diagnose", LOG, "--plots", plots, "--report", report)
        return {"code": code, "err": err, "report": str(report), "plots": str(plots)}

    made = once_per_run(tmp_path_factory, "sample_figures", make)
    return SampleRun(made["code"], made["err"], Path(made["report"]), Path(made["plots"]))
