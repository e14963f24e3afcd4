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
    """Angles wrapped to (−π, π].

    Parameters
    ----------
    x : array_like
        Angles in radians.

    Returns
    -------
    numpy.ndarray
        x + 2πk in (−π, π], elementwise (π stays π, −π becomes π).

    Examples
    --------
    >>> np.round(wrap_angle([3 * np.pi / 2, -np.pi, 0.5]), 6).tolist()
    [-1.570796, 3.141593, 0.5]
    """
    return np.pi - np.mod(np.pi - np.asarray(x, dtype=float), 2.0 * np.pi)


def yaw(rot) -> np.ndarray:
    """Heading ψ of scipy Rotations: the first angle of the intrinsic Z-Y-X Euler sequence.

    Parameters
    ----------
    rot : scipy.spatial.transform.Rotation
        N rotations (a stack, not a single rotation).

    Returns
    -------
    numpy.ndarray, shape (N,)
        ψ = atan2(R₁₀, R₀₀) in radians, in [−π, π].
    """
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
    """Errors (N, d) of the chosen states: positions (N, 3) and scipy Rotations (N).

    The conventions are the module docstring's: the truth minus the estimate, in the world
    frame (``left``) or in the estimate's body frame (``right``).

    Parameters
    ----------
    states : States or str
        Which errors: ``position`` (d = 3), ``orientation`` (d = 3), ``pose`` (positions
        then rotation vectors, d = 6) or ``planar`` (x, y, yaw; d = 3).
    perturbation : Perturbation or str
        ``left`` (world frame) or ``right`` (body frame).
    p_true, p_est : numpy.ndarray or None, shape (N, 3)
        True and estimated positions; not read for ``orientation``.
    r_true, r_est : scipy.spatial.transform.Rotation or None
        True and estimated orientations (N rotations); needed for ``orientation``,
        ``pose`` and ``planar`` (``NEEDS_ORIENTATION``), and ``r_est`` for ``position``
        with ``right`` too.

    Returns
    -------
    numpy.ndarray, shape (N, d)
        The errors, C-contiguous, in the order of the ROS covariance block that
        ``cov_block`` takes for the same ``states``.

    Raises
    ------
    ValueError
        If ``states`` or ``perturbation`` is not one of its names.
    """
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
    """The (N, d, d) block of ROS-ordered (N, 6, 6) covariances for ``states``.

    Parameters
    ----------
    cov6 : numpy.ndarray, shape (N, 6, 6)
        Pose covariances in ROS order: x, y, z, then rotations about x, y, z.
    states : States or str
        Which block (``COV_INDEX``): ``position`` rows 0–2, ``orientation`` 3–5,
        ``pose`` all six, ``planar`` x, y and the rotation about z.

    Returns
    -------
    numpy.ndarray, shape (N, d, d)
        The rows and columns of ``cov6`` kept, C-contiguous (a copy).

    Examples
    --------
    >>> cov6 = np.diag(np.arange(1.0, 7.0))[None]
    >>> np.diagonal(cov_block(cov6, "planar"), axis1=1, axis2=2).tolist()
    [[1.0, 2.0, 6.0]]
    """
    idx = np.asarray(COV_INDEX[States(states)])
    return np.ascontiguousarray(cov6[:, idx[:, None], idx[None, :]])
