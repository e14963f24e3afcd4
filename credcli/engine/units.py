"""Exact rescaling: dividing by a power of two changes no digit of a mantissa."""

from __future__ import annotations

import numpy as np

from credcli.engine.linalg import per_column


def power_of_two_unit(a, axis: int | None = None):
    """2^k nearest (in log) to the largest |a|, or 1 where that is 0 or not finite.

    Dividing by it is exact, so every ratio of moments is unchanged, and squares of the
    result cannot overflow or underflow whatever the units of the log (errors of 1e150 σ,
    NEES of 1e300).

    Parameters
    ----------
    a : array_like
        The values.
    axis : int or None
        None (default): one unit for all of ``a``. Otherwise the axis the largest |a| is
        taken along (``axis=0``: one unit per column).

    Returns
    -------
    float or numpy.ndarray
        The power of two: a float when ``axis`` is None, else an array with ``axis``
        removed from the shape of ``a`` (ones for an empty ``a``).

    Examples
    --------
    >>> power_of_two_unit([3.0, -5.0]), power_of_two_unit([[1e-3, 0.0], [2e-3, 0.0]], 0)
    (4.0, array([0.00195312, 1.        ]))
    """
    a = np.asarray(a, dtype=float)
    if a.size == 0:
        return 1.0 if axis is None else np.ones(np.delete(a.shape, axis))
    if axis == 0 and a.ndim == 2:  # a tall array's columns: one fast pass each
        top, bottom = per_column(np.maximum, a), per_column(np.minimum, a)
    else:
        top, bottom = np.max(a, axis=axis), np.min(a, axis=axis)
    peak = np.maximum(top, -bottom)  # max |a|, no |a| array
    ok = np.isfinite(peak) & (peak > 0)
    unit = np.exp2(np.round(np.log2(np.where(ok, peak, 1.0))))
    return float(unit) if axis is None else unit
