"""Normalising the ``rng`` argument once, without global state."""

from __future__ import annotations

import numpy as np

RngLike = np.random.Generator | np.random.SeedSequence | int | None


def as_generator(rng: RngLike) -> np.random.Generator:
    """Return a Generator for a Generator, a SeedSequence, an int seed or None."""
    if isinstance(rng, np.random.Generator):
        return rng
    return np.random.default_rng(rng)
