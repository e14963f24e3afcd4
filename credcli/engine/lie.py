"""Errors of pose states: positions in R³ and orientations on SO(3), vectorised over epochs.

Conventions (docs/formats.md, "Conventions", has them with the equations):

- ROS orders a pose covariance x, y, z, then rotations about x, y, z, row-major (REP 103,
  geometry_msgs/PoseWithCovariance); the rotations are about the fixed (parent) axes.
- ``left`` perturbation: R_true = Exp(δ) R_est, so δ = Log(R_true R_estᵀ), a world-frame
  rotation, and the position error p_true − p_est is in the world frame.
- ``right`` perturbation: R_true = R_est Exp(δ), so δ = Log(R_estᵀ R_true), a body-frame
  rotation, and the position error R_estᵀ(p_true − p_est) is in the estimate's body frame.
- ``planar``: x, y and yaw; the yaw error is ψ_true − ψ_est wrapped to (−π, π], the same
  for both perturbations (planar rotations commute); the position error follows the
  perturbation as above, with the planar rotation by ψ_est.

The Lie-group notation follows Solà, Deray and Atchuthan, "A micro Lie theory for state
estimation in robotics" (2018), Eqs. (25)–(26) for the right and left ⊖.
"""

from __future__ import annotations

import numpy as np

from credcli.engine.config import Perturbation, States

COV_INDEX = {
    States.POSITION: (0, 1, 2),
    States.ORIENTATION: (3, 4, 5),
    States.POSE: (0, 1, 2, 3, 4, 5),
    States.PLANAR: (0, 1, 5),
}
"""Rows/columns of the ROS 6×6 pose covariance that each choice of states keeps."""

STATE_BLOCKS = {
    States.POSE: (("position", (0, 1, 2)), ("orientation", (3, 4, 5))),
    States.PLANAR: (("position", (0, 1)), ("heading", (2,))),
}
"""Named blocks of the error vector (indices into it) whose scale is reported separately:
a filter may be right about its position and wrong about its attitude."""

NEEDS_ORIENTATION = {States.ORIENTATION, States.POSE, States.PLANAR}
"""States that need orientations (planar: for the yaw, and the right perturbation)."""


def wrap_angle(x: np.ndarray) -> np.ndarray:
    """Angles wrapped to (−π, π]."""
    return np.pi - np.mod(np.pi - np.asarray(x, dtype=float), 2.0 * np.pi)


def yaw(rot) -> np.ndarray:
    """Heading ψ of scipy Rotations: the first angle of the intrinsic Z-Y-X Euler sequence."""
    m = rot.as_matrix()
    return np.arctan2(m[:, 1, 0], m[:, 0, 0])


def state_errors(
    states: States,
    perturbation: Perturbation,
    p_true: np.ndarray | None,
    p_est: np.ndarray | None,
    r_true=None,
    r_est=None,
) -> np.ndarray:
    """Errors (N, d) of the chosen states: positions (N, 3) and scipy Rotations (N)."""
    states, perturbation = States(states), Perturbation(perturbation)
    right = perturbation is Perturbation.RIGHT
    parts = []
    if states in (States.POSITION, States.POSE):
        dp = p_true - p_est
        if right:  # R_estᵀ (p_true − p_est), in the estimate's body frame
            dp = r_est.apply(dp, inverse=True)
        parts.append(dp)
    if states in (States.ORIENTATION, States.POSE):
        relative = r_est.inv() * r_true if right else r_true * r_est.inv()
        parts.append(relative.as_rotvec())
    if states is States.PLANAR:
        psi_est = yaw(r_est)
        dxy = p_true[:, :2] - p_est[:, :2]
        if right:
            c, s = np.cos(psi_est), np.sin(psi_est)
            dxy = np.stack([c * dxy[:, 0] + s * dxy[:, 1], -s * dxy[:, 0] + c * dxy[:, 1]], 1)
        parts.append(np.c_[dxy, wrap_angle(yaw(r_true) - psi_est)])
    return np.ascontiguousarray(np.concatenate(parts, axis=1))


def cov_block(cov6: np.ndarray, states: States) -> np.ndarray:
    """The (N, d, d) block of ROS-ordered (N, 6, 6) covariances for ``states``."""
    idx = np.asarray(COV_INDEX[States(states)])
    return np.ascontiguousarray(cov6[:, idx[:, None], idx[None, :]])
