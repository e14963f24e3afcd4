"""Bar-Shalom's per-epoch ANEES test over M Monte Carlo runs (Bar-Shalom, Li and
Kirubarajan, *Estimation with Applications to Tracking and Navigation*, 2001, Sec. 5.4.2):
the average NEES over runs ε̄_k (not divided by d), with M ε̄_k ~ χ²_{Md} for a consistent
filter, inside [χ²_{Md}(α/2), χ²_{Md}(1 − α/2)] / M at a fraction 1 − α of the epochs."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import special

from credcli.engine.metrics import cholesky, nees_factored


@dataclass(frozen=True)
class MonteCarlo:
    """The per-epoch ANEES of M runs and its two-sided χ² bounds at level ``level``;
    ``segments``: the fraction of each segment's epochs inside them."""

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
        return (self.anees >= self.lower) & (self.anees <= self.upper)


def anees_test(errors, covs, level: float, time=None, segments=()) -> MonteCarlo:
    """The ANEES test of M runs on one time base: ``errors`` (M, N, d) and ``covs``
    (M, N, d, d) as sequences of the runs' arrays; ``segments`` (objects with ``name`` and
    ``index``) get the fraction of their epochs inside the bounds.

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
