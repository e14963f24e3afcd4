"""The reading option ``align``: an estimate read in its own world frame moved onto the
truth's (:mod:`credcli.engine.align` has the math), with its claimed covariance, and a
note saying what was done and what it costs the verdict."""

from __future__ import annotations

import dataclasses

import numpy as np

from credcli.engine import lie
from credcli.engine.align import (
    Alignment,
    Transform,
    covariance_map,
    origin,
    transform_covariance,
    umeyama,
)
from credcli.engine.config import Perturbation, States
from credcli.errors import CredcliError
from credcli.io.logs import EstimatorLog
from credcli.io.schema import ReadOptions
from credcli.io.trajectory import Trajectory


def fitted_mean(alignment: Alignment) -> str | None:
    """Why the whole log's location question cannot be answered after ``alignment``: the
    least-squares fit of a translation (se3, sim3) makes the mean of the aligned errors 0
    exactly (Umeyama's t = μ − s R μ̂), so no bias can show in the log as a whole; a window
    of it still can. None for none and origin (which fixes the first epoch, not the mean).

    Parameters
    ----------
    alignment : Alignment
        The ``align`` option.

    Returns
    -------
    str or None
        The reason, as the report gives it; None for ``none`` and ``origin``.
    """
    if alignment in (Alignment.SE3, Alignment.SIM3):
        return (
            f"align {alignment.value} fitted the mean of these errors to 0, so a bias cannot "
            "show in the whole log (windows of it still can)"
        )
    return None


def align_log(log: EstimatorLog, alignment: Alignment) -> EstimatorLog:
    """A credcli log (truth and estimate in each row, d = 2 or 3 positions) with its
    estimate and covariance moved into the truth's frame: one transform for the whole
    log, every segment. Logs without an estimate (errors only) and logs of several Monte
    Carlo runs (each its own frame) are refused.

    Parameters
    ----------
    log : EstimatorLog
        A log with truth and estimate, d = 2 or 3 positions, of one run.
    alignment : Alignment
        ``none`` (the log is given back as it is), ``origin`` (the first estimate onto the
        first truth, translation only), ``se3`` or ``sim3`` (Umeyama's fit to every
        epoch).

    Returns
    -------
    EstimatorLog
        The log with its estimate moved to s R x̂ + t and its covariance to s² R Σ Rᵀ, a
        note saying what was fitted and what it costs the verdict, and for ``se3`` and
        ``sim3`` its ``fitted_mean`` set (:func:`fitted_mean`).

    Raises
    ------
    CredcliError
        For a log without an estimate, a log of several Monte Carlo runs, or a state that
        is not 2-D or 3-D.

    References
    ----------
    S. Umeyama, "Least-squares estimation of transformation parameters between two point
    patterns," IEEE Trans. Pattern Anal. Mach. Intell., vol. 13, no. 4, pp. 376–380, 1991.
    """
    alignment = Alignment(alignment)
    if alignment is Alignment.NONE:
        return log
    if log.truth is None or log.estimate is None:
        raise CredcliError(
            f"{log.id}: `align` {alignment.value} moves an estimate onto its truth; this "
            "log holds errors only: drop `align`",
            "align",
        )
    if log.run is not None:
        raise CredcliError(
            f"{log.id}: `align` fits one frame to the whole log, but it holds several "
            "Monte Carlo runs, each in a frame of its own: align each run's log by itself",
            "align",
        )
    d = log.truth.shape[1]
    if d not in (2, 3):
        raise CredcliError(
            f"{log.id}: `align` moves 2-D or 3-D positions; the log's state has {d} "
            "components (read a pose file with `truth` for poses)",
            "align",
        )
    if alignment is Alignment.ORIGIN:
        transform = origin(log.truth[0], log.estimate[0])
    else:
        transform = umeyama(log.truth, log.estimate, alignment is Alignment.SIM3)
    cov = transform_covariance(log.cov, covariance_map(transform, d))
    note = _alignment_note(alignment, transform, d, log.n, False, "s² R Σ Rᵀ")
    return dataclasses.replace(
        log,
        estimate=transform.apply(log.estimate),
        cov=cov,
        notes=(*log.notes, note),
        fitted_mean=fitted_mean(alignment),
    )


def align_trajectory(
    estimate: Trajectory, truth: Trajectory, pairing, reading: ReadOptions
) -> tuple[Trajectory, tuple[str, ...]]:
    """The estimate moved into the truth's frame by the transform ``reading.align`` fits to
    the paired epochs, and the note that says so (none when ``align`` is none).

    Positions become s R p̂ + t and orientations R R̂; the 6×6 pose covariance becomes
    J Σ Jᵀ with J = diag(s R, R) for the left perturbation (world-frame errors) and
    diag(s I, I) for the right one (body-frame errors, which a change of world frame only
    scales); a position covariance s² R Σ Rᵀ. ``states`` planar fits a rotation about z
    and an x, y translation (SE(2), Sim(2)) to x, y, so that the heading stays a heading.
    ``origin`` moves the first paired pose onto the truth's (its rotation too where both
    have orientations) and fits nothing else.

    Parameters
    ----------
    estimate : Trajectory
        The estimate, with its covariance.
    truth : Trajectory
        The truth it is paired with.
    pairing : Pairing
        Which estimate epochs have truth, and the truth interpolated to them
        (:func:`credcli.io.pairing.pair`); the transform is fitted to these epochs.
    reading : ReadOptions
        Its ``align``, ``states`` and ``perturbation`` are used.

    Returns
    -------
    estimate : Trajectory
        Every epoch of the estimate (paired or not) moved by the transform; the estimate
        itself when ``align`` is none, or when the truth's positions have another dimension
        (the errors' dimension check then reports it, naming both files).
    notes : tuple of str
        The note on the alignment, or none.

    References
    ----------
    S. Umeyama, "Least-squares estimation of transformation parameters between two point
    patterns," IEEE Trans. Pattern Anal. Mach. Intell., vol. 13, no. 4, pp. 376–380, 1991.
    """
    alignment = reading.align
    if alignment is Alignment.NONE:
        return estimate, ()
    keep = pairing.keep
    p_true, p_est = pairing.position, estimate.position[keep]
    if p_true.shape[1] != p_est.shape[1]:
        return estimate, ()  # the errors' dimension check says so, with both files
    pose = estimate.pose and truth.pose and estimate.quaternion is not None
    planar = reading.states is States.PLANAR and pose and pairing.rotation is not None
    rotations = None
    if pose and estimate.quaternion is not None:
        from scipy.spatial.transform import Rotation

        rotations = Rotation.from_quat(estimate.quaternion)
    first = int(np.argmax(keep))  # the first paired epoch
    if planar:
        if alignment is Alignment.ORIGIN:
            angle = float(
                lie.yaw(pairing.rotation[:1])[0] - lie.yaw(rotations[first : first + 1])[0]
            )
            c, s = np.cos(angle), np.sin(angle)
            plane = origin(p_true[0, :2], p_est[0, :2], np.array([[c, -s], [s, c]]), np.eye(2))
        else:
            plane = umeyama(p_true[:, :2], p_est[:, :2], alignment is Alignment.SIM3)
        transform = _embedded(plane, p_est.shape[1])
        fitted_dim = 2
    else:
        if alignment is Alignment.ORIGIN:
            use_rotation = rotations is not None and pairing.rotation is not None
            transform = origin(
                p_true[0],
                p_est[0],
                pairing.rotation[0].as_matrix() if use_rotation else None,
                rotations[first].as_matrix() if use_rotation else None,
            )
        else:
            transform = umeyama(p_true, p_est, alignment is Alignment.SIM3)
        fitted_dim = transform.dim
    world = not (pose and reading.perturbation is Perturbation.RIGHT)
    cov = transform_covariance(
        estimate.cov, covariance_map(transform, estimate.cov.shape[1], world)
    )
    position = transform.apply(estimate.position)
    quaternion = estimate.quaternion
    if rotations is not None and transform.dim == 3:
        from scipy.spatial.transform import Rotation

        quaternion = (Rotation.from_matrix(transform.rotation) * rotations).as_quat()
    moved = dataclasses.replace(estimate, position=position, quaternion=quaternion, cov=cov)
    if estimate.cov.shape[1] == 2 * transform.dim:
        how = "diag(s R, R)" if world else "diag(s I, I) (body-frame errors)"
        how = f"J Σ Jᵀ with J = {how}"
    else:
        how = "s² R Σ Rᵀ"
    with_rotation = planar or rotations is not None and pairing.rotation is not None
    note = _alignment_note(alignment, transform, fitted_dim, int(keep.sum()), with_rotation, how)
    return moved, (note,)


def _embedded(plane: Transform, dim: int) -> Transform:
    """A planar transform acting on x, y of ``dim``-D positions (z kept, scaled by s)."""
    if dim == 2:
        return plane
    rotation = np.eye(dim)
    rotation[:2, :2] = plane.rotation
    translation = np.zeros(dim)
    translation[:2] = plane.translation
    return Transform(rotation, translation, plane.scale)


def _alignment_note(
    alignment: Alignment,
    transform: Transform,
    dim: int,
    epochs: int,
    with_rotation: bool,
    covariance: str,
) -> str:
    """What ``align`` did, with its parameters, and what it costs the verdict."""
    moved = (
        f"rotation {transform.angle_degrees:.3g}°, translation norm "
        f"{float(np.linalg.norm(transform.translation)):.4g}"
    )
    if alignment is Alignment.SIM3:
        moved += f", scale {transform.scale:.6g}"
    group = {
        (Alignment.SE3, 3): "SE(3)",
        (Alignment.SE3, 2): "SE(2)",
        (Alignment.SIM3, 3): "Sim(3)",
        (Alignment.SIM3, 2): "Sim(2)",
    }
    if alignment is Alignment.ORIGIN:
        what = "translation and rotation" if with_rotation else "translation only"
        return (
            f"`align` origin: moved the estimate's first paired pose onto the truth's "
            f"({what}; {moved}); its covariance moved with it ({covariance}); no parameter "
            "is fitted to the rest of the run, but the first epoch's error is 0 by "
            "construction, so errors near the start are smaller than the estimator's own"
        )
    fitted = alignment.fitted_parameters(dim)
    return (
        f"`align` {alignment.value}: moved the estimate into the truth's frame by the "
        f"{group[alignment, dim]} transform of Umeyama (1991) fitted to {epochs} paired "
        f"epochs ({moved}); its covariance moved with it ({covariance}); alignment removes "
        f"error: {fitted} degrees of freedom were fitted to these errors, so a credible "
        "verdict after alignment is a weaker claim than without it"
    )
