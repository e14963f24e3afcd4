"""A compiled kernel for the pair matrix of the ELT (Eq. (14)), with numba (``pip install
credcli[fast]``): one pass over a band of rows writes A's float64 and float32 entries and
sums |A_ij|, where numpy makes about ten passes. :mod:`credcli.engine.flips` uses it once a
process has built enough pairs to repay numba's start-up, and numpy before that or without
numba; both give the same bits. numba is imported here only, when that first happens (never
on the command line's start-up path).
"""

from __future__ import annotations

import functools
import math


@functools.lru_cache(maxsize=1)
def pair_band_kernel():
    """The compiled band kernel, or None where numba cannot be imported.

    Returns
    -------
    callable or None
        ``kernel(sq, two_gram, k, start, plus, row0, col0, out32) -> float``: for the
        rows i = start + r (r < k) and columns j = start + c (c < N − start) of the pair
        matrix A of Eq. (14), with g = two_gram[r, c] = 2 s_i·s_j and m = sq[i] + sq[j],
        ``plus[row0 + r, col0 + c]`` = √max(m + g, 0) − √max(m − g, 0) for c > r and 0
        for c <= r; the same rounded to float32 in ``out32[i, j]`` (when it has rows),
        and the sum of their absolute values (0.0 without ``out32``). Arrays are whole
        C-ordered ones, not views, so that the loops vectorise. Each entry takes the IEEE operations of the numpy
        path (``credcli.engine.flips``) in the same order, each rounded once, so the bits
        are the same; compiled without fast-math (no reassociation, no fused
        multiply-add).
    """
    try:
        import numba
    except ImportError:  # the numpy path
        return None
    # cache=True: compiled once per machine (numba keeps the cache beside this file, or in
    # its user-wide cache directory where the package is read-only)
    return numba.njit(cache=True, nogil=True, error_model="numpy")(_pair_band)


def _pair_band(sq, two_gram, k, start, plus, row0, col0, out32):  # pragma: no cover
    width = sq.size - start
    write32 = out32.shape[0] > 0
    absolute = 0.0
    for r in range(k):
        si = sq[start + r]
        p = row0 + r
        for c in range(min(r + 1, width)):
            plus[p, col0 + c] = 0.0
            if write32:
                out32[start + r, start + c] = 0.0
        for c in range(r + 1, width):
            m = si + sq[start + c]
            g = two_gram[r, c]
            plus[p, col0 + c] = math.sqrt(max(m + g, 0.0)) - math.sqrt(max(m - g, 0.0))
        if write32:  # four partial sums of |A_ij|: no chain of dependent additions
            i = start + r
            a0 = a1 = a2 = a3 = 0.0
            c = r + 1
            while c + 4 <= width:
                v0, v1 = plus[p, col0 + c], plus[p, col0 + c + 1]
                v2, v3 = plus[p, col0 + c + 2], plus[p, col0 + c + 3]
                out32[i, start + c], out32[i, start + c + 1] = v0, v1
                out32[i, start + c + 2], out32[i, start + c + 3] = v2, v3
                a0 += abs(v0)
                a1 += abs(v1)
                a2 += abs(v2)
                a3 += abs(v3)
                c += 4
            while c < width:
                out32[i, start + c] = plus[p, col0 + c]
                a0 += abs(plus[p, col0 + c])
                c += 1
            absolute += (a0 + a1) + (a2 + a3)
    return absolute
