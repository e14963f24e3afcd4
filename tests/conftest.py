"""Shared fixtures (the helpers are in ``helpers.py``)."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import LOG, run


@pytest.fixture
def rng():
    return np.random.default_rng(12345)


@pytest.fixture(scope="session")
def sample_html_report(tmp_path_factory):
    """(exit code, stderr, path) of ``credcli diagnose LOG --report``: the sample log's
    28-figure HTML report, built once per test process for the tests that read it."""
    path = tmp_path_factory.mktemp("report") / "r.html"
    code, _, err = run("diagnose", LOG, "--report", path)
    return code, err, path
