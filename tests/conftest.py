"""Shared fixtures: seeded data generators and paths."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
SHARED = ROOT.parent / "shared"
SAMPLE = ROOT / "sample_data"


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


@pytest.fixture
def rng():
    return np.random.default_rng(12345)
