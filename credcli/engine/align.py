"""Aligning an estimate that lives in its own world frame (VIO, SLAM) with the truth's.

An estimator that fixes its own world frame at start-up (a visual-inertial odometry, a
SLAM system) reports positions x̂_k in a frame that differs from the truth's by an
unknown rigid (SE(d)) or similarity (Sim(d)) transform, and, for a monocular system, by a
scale. Before its errors mean anything, the estimate is moved into the truth's frame,
x̂'_k = s R x̂_k + t, as evo does (``--align``, ``--correct_scale``, ``--align_origin``):

- ``origin``: the transform that maps the estimate's first pose onto the truth's first
  pose, T = T_true,0 T_est,0⁻¹ (rotation too when both have orientations, otherwise a
  translation only): nothing is fitted to the rest of the run.
- ``se3``: the rotation and translation of Umeyama's closed form (below), d(d + 1)/2
  parameters fitted to the whole run (6 in 3-D, 3 in the plane).
- ``sim3``: the same with a scale, d(d + 1)/2 + 1 parameters (7 in 3-D, 4 in the plane).

The claimed covariance of the estimate moves with it: the alignment is a change of frame
of the estimate, so for x̂' = s R x̂ + t the covariance of its world-frame error is
s² R Σ Rᵀ (:func:`covariance_map`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from credcli.engine.config import Alignment  # noqa: F401 (re-exported)
from credcli.engine.units import power_of_two_unit
from credcli.errors import CredcliError


@dataclass(frozen=True)
class Transform:
    """The similarity transform x ↦ s R x + t.

    Attributes
    ----------
    rotation : numpy.ndarray
        R (d, d), a rotation (det +1).
    translation : numpy.ndarray
        t (d,).
    scale : float
        s > 0 (default 1: a rigid transform).
    """

    rotation: np.ndarray
    translation: np.ndarray
    scale: float = 1.0

    @property
    def dim(self) -> int:
        """d, the dimension the transform acts in."""
        return self.rotation.shape[0]

    @property
    def angle_degrees(self) -> float:
        """The rotation's angle, in degrees: atan2(R₁₀, R₀₀) in the plane, arccos((tr R −
        1)/2) in 3-D."""
        r = self.rotation
        if self.dim == 2:
            return float(np.degrees(np.arctan2(r[1, 0], r[0, 0])))
        cos = np.clip((np.trace(r) - 1.0) / 2.0, -1.0, 1.0)
        return float(np.degrees(np.arccos(cos)))

    def apply(self, points: np.ndarray) -> np.ndarray:
        """s R x_k + t for each row x_k of ``points``.

        Parameters
        ----------
        points : numpy.ndarray, shape (N, d)
            The points x_k, one per row.

        Returns
        -------
        numpy.ndarray, shape (N, d)
            The moved points.
        """
        return self.scale * points @ self.rotation.T + self.translation


def umeyama(truth: np.ndarray, estimate: np.ndarray, with_scale: bool = False) -> Transform:
    r"""The similarity (or rigid) transform that best maps ``estimate`` onto ``truth``.

    Umeyama, "Least-squares estimation of transformation parameters between two point
    patterns", IEEE TPAMI 13(4), 1991: the R, t and s (``with_scale``; else s = 1) that
    minimise

    .. math:: \sum_k \lVert x_k - (s R \hat x_k + t) \rVert^2

    over the paired positions x_k (truth) and x̂_k (estimate). With the means μ_x, μ_x̂,
    the variance σ²_x̂ = (1/n) Σ‖x̂_k − μ_x̂‖² and the cross-covariance
    Σ_xx̂ = (1/n) Σ (x_k − μ_x)(x̂_k − μ_x̂)ᵀ = U D Vᵀ (its SVD; Eq. 38):

    - R = U S Vᵀ with S = diag(1, …, 1, det(U) det(V)) (Eqs. 39–40, 43): the reflection
      fix, which keeps det R = +1 when the best orthogonal matrix is a reflection;
    - s = tr(D S) / σ²_x̂ (Eq. 42);
    - t = μ_x − s R μ_x̂ (Eq. 41).

    Parameters
    ----------
    truth, estimate : (N, d) arrays, d = 2 or 3
        Paired positions.
    with_scale : bool
        Fit the scale s (Sim(d)); otherwise s = 1 (SE(d)).

    Returns
    -------
    Transform
        R, t and s, the transform to apply to the estimate (``Transform.apply``).

    Raises
    ------
    CredcliError
        On arrays of different or unsupported shapes, non-finite values, or positions that
        do not determine a rotation (the estimate's centred positions must span at least
        d − 1 dimensions: a line in 3-D or a single point leaves a rotation free).

    Examples
    --------
    >>> x_hat = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 2.0]])
    >>> x = x_hat @ np.array([[0.0, -1.0], [1.0, 0.0]]).T + [3.0, 4.0]
    >>> fit = umeyama(x, x_hat)
    >>> round(fit.angle_degrees, 6), np.round(fit.translation, 6).tolist()
    (90.0, [3.0, 4.0])
    """
    x = np.asarray(truth, dtype=float)
    x_hat = np.asarray(estimate, dtype=float)
    if x.ndim != 2 or x.shape != x_hat.shape or x.shape[1] not in (2, 3):
        raise CredcliError(
            f"`align` needs paired 2-D or 3-D positions of one shape; got truth {x.shape} "
            f"and estimate {x_hat.shape}",
            "align",
        )
    if not (np.isfinite(x).all() and np.isfinite(x_hat).all()):
        raise CredcliError("`align`: the positions must be finite", "align")
    top = max(float(np.max(np.abs(x), initial=0.0)), float(np.max(np.abs(x_hat), initial=0.0)))
    if top > 1e150:  # sums of squares (and of 1e308s, the means) would overflow: fit in one
        # exact power-of-two unit for both, which leaves R and s as they are; t back after
        unit = power_of_two_unit(np.concatenate([x, x_hat]))
        try:
            fit = _umeyama(x / unit, x_hat / unit, with_scale)
        except CredcliError as exc:  # one position so far off leaves the rest a point
            raise CredcliError(
                f"{exc.message} (a position reaches {top:.3g}: is one diverged or corrupt?)",
                exc.parameter,
            ) from exc
        return Transform(fit.rotation, fit.translation * unit, fit.scale)
    spread_hat = float(np.max(np.abs(x_hat - x_hat.mean(axis=0)), initial=0.0))
    if with_scale and (0.0 < spread_hat < 1e-150 or spread_hat > 1e150):
        # σ²_x̂ would under- or overflow: fit in exact power-of-two units, s and t back after
        unit, unit_hat = power_of_two_unit(x), power_of_two_unit(x_hat - x_hat.mean(axis=0))
        fit = _umeyama(x / unit, x_hat / unit_hat, with_scale)
        return Transform(fit.rotation, fit.translation * unit, fit.scale * unit / unit_hat)
    return _umeyama(x, x_hat, with_scale)


def _umeyama(x: np.ndarray, x_hat: np.ndarray, with_scale: bool) -> Transform:
    """The core of :func:`umeyama` on clean (N, d) arrays."""
    n, d = x.shape
    mu_x, mu_hat = x.mean(axis=0), x_hat.mean(axis=0)
    xc, hc = x - mu_x, x_hat - mu_hat
    var_hat = float(np.einsum("ij,ij->", hc, hc)) / n
    cross = xc.T @ hc / n  # Σ_xx̂, Eq. (38)
    u, singular, vt = np.linalg.svd(cross)
    spread = np.linalg.svd(hc, compute_uv=False)
    if n < d or spread[d - 2] <= 1e-9 * max(spread[0], 1e-300):
        raise CredcliError(
            f"`align` cannot fit a rotation: the estimate's {n} position(s) do not span "
            f"{'a plane' if d == 3 else 'a line'} (they must move in at least {d - 1} "
            "directions); use `align` origin, or none",
            "align",
        )
    signs = np.ones(d)
    signs[-1] = np.sign(np.linalg.det(u) * np.linalg.det(vt)) or 1.0  # Eq. (43)
    rotation = (u * signs) @ vt  # R = U S Vᵀ, Eq. (40)
    scale = float(singular @ signs) / var_hat if with_scale else 1.0  # Eq. (42)
    if not scale > 0:
        raise CredcliError(
            f"`align` sim3 found a scale {scale:.3g}: the estimate does not follow the truth's "
            "shape; use `align` se3",
            "align",
        )
    translation = mu_x - scale * rotation @ mu_hat  # Eq. (41)
    return Transform(rotation, translation, scale)


def origin(
    p_true: np.ndarray,
    p_est: np.ndarray,
    r_true: np.ndarray | None = None,
    r_est: np.ndarray | None = None,
) -> Transform:
    """The transform T = T_true T_est⁻¹ that maps the estimate's pose onto the truth's.

    R = R_true R_estᵀ, t = p_true − R p_est (evo's ``align_origin``); nothing is fitted to
    the rest of the run.

    Parameters
    ----------
    p_true, p_est : numpy.ndarray, shape (d,)
        The truth's and the estimate's first positions.
    r_true, r_est : numpy.ndarray or None, shape (d, d)
        Their rotation matrices. Without both, R = I and T is the translation
        p_true − p_est alone.

    Returns
    -------
    Transform
        R and t, with s = 1.

    Examples
    --------
    >>> origin(np.array([1.0, 2.0]), np.array([0.5, 0.0])).translation.tolist()
    [0.5, 2.0]
    """
    p_true, p_est = np.asarray(p_true, dtype=float), np.asarray(p_est, dtype=float)
    d = p_true.shape[0]
    rotation = np.eye(d) if r_true is None or r_est is None else r_true @ r_est.T
    return Transform(rotation, p_true - rotation @ p_est)


def covariance_map(transform: Transform, size: int, world: bool = True) -> np.ndarray:
    """The matrix J that moves the claimed covariance with the estimate: Σ' = J Σ Jᵀ.

    With x̂' = s R x̂ + t and R̂' = R R̂:

    - ``world`` (left perturbation, R_true = Exp(δ) R̂): the world-frame position error
      scales and turns, δp' = s R δp, and so does the rotation error, Exp(δ') R R̂ =
      R Exp(δ) R̂ gives δ' = R δ: J = diag(s R, R);
    - body frame (right perturbation, R_true = R̂ Exp(δ)): R̂'ᵀ(p − p̂') = s R̂ᵀ(p − p̂) and
      δ' = δ: J = diag(s I, I).

    The position–orientation cross block becomes s R Σ_pθ Rᵀ (world) or s Σ_pθ (body).

    Parameters
    ----------
    transform : Transform
        The alignment applied to the estimate.
    size : int
        The covariance's size: d for a position covariance, J = s R (world) or s I
        (body); 2d = 6 in 3-D for a pose covariance, positions then rotation vectors
        (ROS order).
    world : bool
        Whether the errors are in the world frame (left perturbation; default) or in the
        estimate's body frame (right perturbation).

    Returns
    -------
    numpy.ndarray, shape (size, size)
        J (``transform_covariance`` applies it).

    Raises
    ------
    CredcliError
        For any other ``size`` (named as the ``align`` parameter).
    """
    d = transform.dim
    rotation = transform.rotation if world else np.eye(d)
    if size == d:
        return transform.scale * rotation
    if size == 2 * d and d == 3:
        jac = np.zeros((size, size))
        jac[:d, :d] = transform.scale * rotation
        jac[d:, d:] = rotation
        return jac
    raise CredcliError(
        f"`align` moves a {d}-D position or a 3-D pose covariance; got a {size}×{size} one",
        "align",
    )


def transform_covariance(cov: np.ndarray, jacobian: np.ndarray) -> np.ndarray:
    """J Σ_k Jᵀ for each covariance Σ_k, symmetrised against rounding.

    Parameters
    ----------
    cov : numpy.ndarray, shape (N, m, m)
        The covariances Σ_k.
    jacobian : numpy.ndarray, shape (m, m)
        J (``covariance_map``).

    Returns
    -------
    numpy.ndarray, shape (N, m, m)
        (J Σ_k Jᵀ + (J Σ_k Jᵀ)ᵀ)/2, C-contiguous.

    Examples
    --------
    >>> j = covariance_map(Transform(np.eye(2), np.zeros(2), 2.0), 2)
    >>> transform_covariance(np.eye(2)[None], j).tolist()
    [[[4.0, 0.0], [0.0, 4.0]]]
    """
    out = np.einsum("ij,njk,lk->nil", jacobian, cov, jacobian)
    return np.ascontiguousarray(0.5 * (out + np.swapaxes(out, 1, 2)))
