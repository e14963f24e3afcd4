"""Which perturbation convention the claimed covariance fits: the check behind the
warning a pose log gets when its errors under the other convention fit far better.

A body-frame (right) error read in the world frame (left) turns with the attitude: a
constant bias no longer looks constant, and the label is confidently wrong (optimism
instead of smm). Reading a log only takes its errors under both conventions; the
comparison, a scale estimate, is the engine's.
"""

from __future__ import annotations

import numpy as np

from credcli.engine.config import Perturbation
from credcli.engine.scale import gls_residuals

CONVENTION_RATIO = 1.25
"""How much closer to 1 the other convention's covariance factor κ̂ must be (as a factor,
on a log scale) before the warning is given: noise moves ln κ̂ by about
√(2/((N − 1)d)), 0.01 on a 2,000-epoch pose log, so 1.25 (0.22) is far beyond it."""


def centred_scale(errors: np.ndarray, cov: np.ndarray) -> float:
    """κ̂ of the scale test: the NEES of GLS-centred errors over (N − 1)d.

    Parameters
    ----------
    errors : numpy.ndarray, shape (N, d)
        The errors.
    cov : numpy.ndarray, shape (N, d, d)
        The claimed covariances, positive definite.

    Returns
    -------
    float
        How far the claimed covariance is from the errors once a constant mean is removed
        (1 when it fits).

    Raises
    ------
    numpy.linalg.LinAlgError
        When a covariance is not positive definite.
    """
    residuals = gls_residuals(errors, np.linalg.cholesky(cov))
    n, d = errors.shape
    return float(residuals.q.sum() / max(1, (n - 1) * d))


def convention_warning(
    errors: np.ndarray,
    swapped: np.ndarray,
    cov: np.ndarray,
    used: Perturbation,
    other: Perturbation,
) -> str:
    """A warning when the errors under the other perturbation convention fit the claimed
    covariance far better (by :data:`CONVENTION_RATIO`) than under the one used.

    Parameters
    ----------
    errors, swapped : numpy.ndarray, shape (N, d)
        The same epochs' errors under the convention used and under the other one.
    cov : numpy.ndarray, shape (N, d, d)
        The claimed covariances.
    used, other : Perturbation
        The two conventions, as named in the warning.

    Returns
    -------
    str
        The warning, or "" when the convention used fits as well, or when the covariance
        cannot be factored (it is checked, with its message, by the diagnosis).

    Examples
    --------
    Errors of scale 1 under the other convention and of scale 2 under the one used:

    >>> rng = np.random.default_rng(0)
    >>> e = rng.standard_normal((500, 2))
    >>> cov = np.broadcast_to(np.eye(2), (500, 2, 2))
    >>> convention_warning(2 * e, e, cov, Perturbation.LEFT, Perturbation.RIGHT)[:48]
    '`perturbation` right fits the claimed covariance'
    >>> convention_warning(e, 2 * e, cov, Perturbation.LEFT, Perturbation.RIGHT)
    ''
    """
    try:
        fit_used, fit_other = centred_scale(errors, cov), centred_scale(swapped, cov)
    except (np.linalg.LinAlgError, ValueError):
        return ""
    misfit = abs(np.log(fit_used)) - abs(np.log(fit_other))
    if not np.isfinite(misfit) or misfit < np.log(CONVENTION_RATIO):
        return ""
    return (
        f"`perturbation` {other.value} fits the claimed covariance far better "
        f"(covariance factor {fit_other:.3g} against {fit_used:.3g} with {used.value}): "
        "check which convention the estimator's covariance uses"
    )
