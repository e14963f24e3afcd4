"""Bar-Shalom's per-epoch ANEES test over M Monte Carlo runs (Bar-Shalom, Li and
Kirubarajan, *Estimation with Applications to Tracking and Navigation*, 2001, Sec. 5.4.2):
the average NEES over runs ε̄_k (not divided by d), with M ε̄_k ~ χ²_{Md} for a consistent
filter, inside [χ²_{Md}(α/2), χ²_{Md}(1 − α/2)] / M at a fraction 1 − α of the epochs."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import special

from credcli.engine.linalg import cholesky
from credcli.engine.metrics import nees_factored


@dataclass(frozen=True)
class MonteCarlo:
    """The per-epoch ANEES of M runs and its two-sided χ² bounds at level ``level``.

    Attributes
    ----------
    runs : int
        M, the number of Monte Carlo runs.
    dim : int
        d, the state dimension.
    level : float
        α: the bounds hold a consistent filter's ANEES with probability 1 − α per epoch.
    time : numpy.ndarray or None
        The runs' common time stamps (N,), as given (None: none).
    anees : numpy.ndarray
        ε̄_k (N,), the NEES averaged over the runs at each epoch (not divided by d).
    lower, upper : float
        χ²_{Md}(α/2) / M and χ²_{Md}(1 − α/2) / M, the bounds on ε̄_k.
    segments : dict
        Segment name -> the fraction of the segment's epochs with ε̄_k inside the bounds.
    """

    runs: int
    dim: int
    level: float
    time: np.ndarray | None
    anees: np.ndarray
    lower: float
    upper: float
    segments: dict

    @property
    def inside(self) -> np.ndarray:
        """Whether each epoch's ANEES is inside [lower, upper] (N,)."""
        return (self.anees >= self.lower) & (self.anees <= self.upper)


def anees_test(errors, covs, level: float, time=None, segments=()) -> MonteCarlo:
    """The ANEES test of M runs on one time base (Bar-Shalom et al. 2001, Sec. 5.4.2).

    Each run's NEES ε_k is computed as ``credcli.engine.metrics.nees`` does (Cholesky
    factors; the covariances must be positive definite), averaged over the runs at each
    epoch into ε̄_k, and compared with the χ²_{Md} bounds of the module docstring.

    Parameters
    ----------
    errors : sequence of array_like
        The M runs' errors, each (N, d): (M, N, d) as a sequence of the runs' arrays.
    covs : sequence of array_like
        The M runs' claimed covariances, each (N, d, d).
    level : float
        α, the two-sided level of the per-epoch bounds.
    time : array_like or None
        The common time stamps (N,), kept in the result for plotting (default None).
    segments : iterable
        Objects with a ``name`` and an ``index`` (into the N epochs); each gets the
        fraction of its epochs inside the bounds (default: none).

    Returns
    -------
    MonteCarlo
        The per-epoch ANEES, its bounds and the segments' fractions inside them.

    Raises
    ------
    CredcliError
        If a covariance is not positive definite (``credcli.engine.linalg.cholesky``).

    Notes
    -----
    For a consistent filter M ε̄_k ~ χ²_{Md}, so ε̄_k lies in
    [χ²_{Md}(α/2), χ²_{Md}(1 − α/2)] / M at a fraction 1 − α of the epochs.

    References
    ----------
    Y. Bar-Shalom, X. R. Li and T. Kirubarajan, *Estimation with Applications to Tracking
    and Navigation*, Wiley, 2001, Sec. 5.4.2.

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> e = [rng.standard_normal((500, 2)) for _ in range(20)]
    >>> c = [np.broadcast_to(np.eye(2), (500, 2, 2))] * 20
    >>> mc = anees_test(e, c, 0.05)
    >>> round(float(mc.inside.mean()), 2), round(mc.lower, 2), round(mc.upper, 2)
    (0.96, 1.22, 2.97)
    """
    nees = np.stack([nees_factored(e, cholesky(c)) for e, c in zip(errors, covs)])
    m, d = nees.shape[0], np.shape(errors[0])[1]
    anees = nees.mean(axis=0)
    lower = float(special.chdtri(m * d, 1 - level / 2) / m)
    upper = float(special.chdtri(m * d, level / 2) / m)
    inside = (anees >= lower) & (anees <= upper)
    fractions = {s.name: float(inside[s.index].mean()) for s in segments}
    return MonteCarlo(m, d, level, time, anees, lower, upper, fractions)
