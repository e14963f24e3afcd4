"""Compiled kernels, with numba (``pip install credcli[fast]``): the pair matrix of the
ELT (Eq. (14)), where one pass over a band of rows writes A's float64 and float32 entries
and sums |A_ij| where numpy makes about ten passes; and the update of Burg's prediction
errors (:func:`credcli.engine.memory.burg`), one pass per order where numpy makes five.
:mod:`credcli.engine.flips` and :mod:`credcli.engine.memory` use them once a process has
done enough of that work to repay numba's start-up, and numpy before that or without
numba; both paths give the same bits. numba is imported here only, when that first
happens (never on the command line's start-up path).
"""

from __future__ import annotations

import functools
import importlib.util
import math
import threading

_warm = [False]  # warm() ran in this process or in the parent it was forked from


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


def _burg_update(f, b, kappa, p):  # pragma: no cover
    k, m, t = f.shape
    for i in range(k):
        c = kappa[i]
        for j in range(m):
            for s in range(t - 1, p - 1, -1):
                old = f[i, j, s]
                f[i, j, s] = old + c * b[i, j, s - 1]
                b[i, j, s] = b[i, j, s - 1] + c * old


@functools.lru_cache(maxsize=1)
def burg_update_kernel():
    """The compiled update of Burg's prediction errors, or None where numba cannot be
    imported.

    Returns
    -------
    callable or None
        ``kernel(f, b, kappa, p)``: for every series i, segment and epoch s >= p, from the
        last epoch back, f[i, ·, s] += κ_i b[i, ·, s − 1] and b[i, ·, s] = b[i, ·, s − 1] +
        κ_i f[i, ·, s] (its value before), on whole C-ordered (k, m, T) arrays: the numpy
        path of :func:`credcli.engine.memory.burg` in one pass, each entry the same two
        correctly rounded operations (a product, then a sum), so the same bits.
    """
    try:
        import numba
    except ImportError:  # the numpy path
        return None
    return numba.njit(cache=True, nogil=True, error_model="numpy")(_burg_update)


def warm() -> bool:
    """Load both kernels and call each once on a few entries, so that they are ready in
    this process and in every process forked from it.

    numba's import and the load of each kernel's compiled code at its first call cost
    about 0.7 s of CPU in each process that uses them; worker processes forked after this
    call inherit the loaded kernels instead of each paying for them. The calls take the
    argument types of :mod:`credcli.engine.flips` and :mod:`credcli.engine.memory`
    (C-ordered float64 arrays, a float32 matrix, integers), whose compiled code they load.

    Returns
    -------
    bool
        Whether the kernels are loaded (False where numba cannot be imported).
    """
    pair, update = pair_band_kernel(), burg_update_kernel()
    if pair is None or update is None:
        return False
    if not _warm[0]:
        import numpy as np

        sq = np.ones(4)
        pair(sq, np.zeros((2, 4)), 2, 0, np.empty((2, 4)), 0, 0, np.empty((4, 4), np.float32))
        pair(sq, np.zeros((2, 4)), 2, 0, np.empty((2, 4)), 0, 0, np.zeros((0, 0), np.float32))
        update(np.zeros((1, 1, 4)), np.zeros((1, 1, 4)), np.zeros(1), 1)
        _warm[0] = True
    return True


def warm_in_background():
    """Start :func:`warm` in a thread of this process, so that numba's start-up overlaps
    work that releases the interpreter (reading a log with Arrow). The caller joins the
    thread before any process forks (no thread may run through a fork). An error in the
    thread is dropped: :func:`warm`, called again where the kernels are wanted, reports it.

    Returns
    -------
    threading.Thread or None
        The started thread; None where numba is not installed.
    """
    if _warm[0] or importlib.util.find_spec("numba") is None:
        return None
    thread = threading.Thread(target=_warm_quietly, name="credcli-kernels", daemon=True)
    thread.start()
    return thread


def _warm_quietly() -> None:
    try:
        warm()
    except Exception:  # noqa: BLE001 - reported by the warm() that needs the kernels
        pass


def warmed() -> bool:
    """Whether :func:`warm` loaded the kernels in this process (or in its parent before
    this process was forked).

    Returns
    -------
    bool
        True once :func:`warm` has run: a caller need not wait until the kernels repay
        their load.
    """
    return _warm[0]
