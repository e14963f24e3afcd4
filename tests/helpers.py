"""Helpers the test modules share: paths, credcli run in-process, one-line errors, seeded
data as in the paper's Section IV-A. Imported as ``from helpers import ...`` (pytest puts
``tests/`` on the path); fixtures stay in ``conftest.py``."""

from __future__ import annotations

import contextlib
import fcntl
import io
import json
import os
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
SHARED = ROOT.parent / "shared"
SAMPLE = ROOT / "sample_data"
LOG = SAMPLE / "estimator_log.csv"
UWB = SAMPLE / "starloc_grid_uwb.csv"


def run(*args) -> tuple[int, str, str]:
    """credcli in-process: (exit code, stdout, stderr)."""
    from credcli.cli import main

    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main([str(a) for a in args])
    return code, out.getvalue(), err.getvalue()


def error_line(code: int, err: str, expected_code: int = 2) -> str:
    """The run failed with ``expected_code`` and one line on stderr, without a traceback."""
    assert code == expected_code, err
    assert "Traceback" not in err
    lines = [line for line in err.splitlines() if line.strip()]
    assert len(lines) == 1, err
    return lines[0]


def gaussian_segment(rng, n=200, d=2, rho=1.0, bias=None, varying=False):
    """Errors e_k ~ N(bias, Σ_k) and claimed covariances ρΣ_k, as in Section IV-A."""
    q, _ = np.linalg.qr(rng.normal(size=(d, d)))
    lam = rng.uniform(0.5, 2.0, d)
    base = (q * lam) @ q.T
    if varying:
        scales = rng.uniform(0.5, 2.0, n)
        true_cov = base[None] * scales[:, None, None]
    else:
        true_cov = np.broadcast_to(base, (n, d, d)).copy()
    chol = np.linalg.cholesky(true_cov)
    errors = np.einsum("nij,nj->ni", chol, rng.normal(size=(n, d)))
    if bias is not None:
        errors = errors + np.asarray(bias, dtype=float)
    return errors, rho * true_cov


def once_per_run(tmp_path_factory, name: str, make) -> dict:
    """``make(directory)`` (a JSON-able dict) once per test run: the first test process
    (pytest-xdist worker) to ask makes it under a lock, the others wait for it and read
    it. ``directory`` is the run's own, shared by its workers (xdist's documented way)."""
    if os.environ.get("PYTEST_XDIST_WORKER") is None:  # one process: nothing to share
        return make(tmp_path_factory.mktemp(name))
    directory = tmp_path_factory.getbasetemp().parent / name
    with open(f"{directory}.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)  # released when the file closes
        made = directory / "made.json"
        if not made.exists():
            directory.mkdir(exist_ok=True)
            made.write_text(json.dumps(make(directory)))
        return json.loads(made.read_text())
