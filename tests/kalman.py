"""A 2-D constant-velocity Kalman filter, for tests on real filter errors.

Truth: x_{k+1} = F x_k + w_k (+ a constant acceleration when asked), w_k ~ N(0, Q);
measurements y_k = H x_k + v_k, v_k ~ N(0, R). The filter runs with its own Q_f, R_f.
Returned: position errors (truth − estimate) and the filter's position covariance.
"""

from __future__ import annotations

import numpy as np


def cv_model(dt: float, q: float):
    f1 = np.array([[1.0, dt], [0.0, 1.0]])
    q1 = q * np.array([[dt**3 / 3, dt**2 / 2], [dt**2 / 2, dt]])
    # state order (px, vx, py, vy)
    f = np.kron(np.eye(2), f1)
    qm = np.kron(np.eye(2), q1)
    h = np.kron(np.eye(2), np.array([[1.0, 0.0]]))
    return f, qm, h


def run_filter(
    n: int,
    seed: int,
    q: float = 0.1,
    r: float = 1.0,
    filter_scale: float = 1.0,
    acceleration: float = 0.0,
    dt: float = 1.0,
    burn_in: int = 50,
):
    """Position errors (n, 2) and covariances (n, 2, 2) of a CV filter after ``burn_in``.

    ``filter_scale`` multiplies the Q and R the filter assumes (1: exactly right);
    ``acceleration`` adds an unmodelled constant acceleration to the truth (both axes).
    """
    rng = np.random.default_rng(seed)
    f, qm, h = cv_model(dt, q)
    rm = r * np.eye(2)
    qf, rf = filter_scale * qm, filter_scale * rm
    total = n + burn_in
    x = np.zeros(4)
    xh = np.zeros(4)
    p = np.eye(4) * 10.0
    acc = np.array([0.5 * dt**2, dt, 0.5 * dt**2, dt]) * acceleration
    chol_q = np.linalg.cholesky(qm)
    errors = np.empty((total, 2))
    covs = np.empty((total, 2, 2))
    idx = [0, 2]
    for k in range(total):
        x = f @ x + chol_q @ rng.standard_normal(4) + acc
        y = h @ x + np.sqrt(r) * rng.standard_normal(2)
        xh = f @ xh
        p = f @ p @ f.T + qf
        s = h @ p @ h.T + rf
        gain = np.linalg.solve(s, h @ p).T
        xh = xh + gain @ (y - h @ xh)
        p = (np.eye(4) - gain @ h) @ p
        p = 0.5 * (p + p.T)
        errors[k] = (x - xh)[idx]
        covs[k] = p[np.ix_(idx, idx)]
    return errors[burn_in:], covs[burn_in:]
