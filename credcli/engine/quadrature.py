"""The quadrature kernel of the energy score: E‖W‖ for W ~ N(m, S) per epoch (Eq. (10)'s
two expectations), by a Householder reduction to tridiagonal form and a trapezoidal rule in
log t with analytic tails; closed forms for d = 1 and for centred d = 2. It takes clean
arrays; :mod:`credcli.engine.metrics` validates them.
"""

from __future__ import annotations

import numpy as np

from credcli.engine.linalg import eigenvalues_2x2, epoch_chunks

# The energy score's Gaussian norm moments E‖W‖ (see `credcli.engine.metrics.expected_norm`) are a trapezoidal
# rule in u = log t, in units where E[Q] = 1 (Q = ‖W‖²). The integrand is analytic in the
# strip |Im u| < pi and bounded on |Im u| = pi/2, so the discretisation error of the step
# h = 0.5 is O(exp(-pi^2 / h)), ~5e-9 before the constant.
# Below the grid the rule is continued analytically with 1 - E[exp(-tQ)] = t - t^2 E[Q^2]/2
# (the next term, at most 15 t^3 / 6, adds < 3e-12 below u = -10); above the epoch's
# window end c the integrand is taken as 1, an error of at most E[exp(-t_c Q)] times the
# weight beyond c (E[exp(-tQ)] falls with t), kept below _TAIL_TOLERANCE (calls of up to
# _QUAD_CHUNK_ELEMENTS / 81 = 404 epochs take the whole grid: less overhead). Both
# continuations are geometric series. Against the 30-digit mpmath reference in tests/data
# (48 cases, d = 1, 2, 3, 6, eigenvalue ratios to 1e14, zero and large means, rotated or
# not) the worst relative error is asserted below 1e-9 (the measured one: docs/measured.md).
_QUAD_H = 0.5
_QUAD_U = np.arange(-10.0, 30.0 + _QUAD_H / 2, _QUAD_H)
_QUAD_T = np.exp(_QUAD_U)
_QUAD_INV_T = np.exp(-_QUAD_U)
_QUAD_W = _QUAD_H * np.exp(-_QUAD_U / 2) / (2.0 * np.sqrt(np.pi))
_HALF_STEP = np.exp(-_QUAD_H / 2)
_LOW_FIRST = _QUAD_W[0] * _QUAD_T[0] * _HALF_STEP / (1.0 - _HALF_STEP)  # sum of W t below
_LOW_SECOND = _QUAD_W[0] * _QUAD_T[0] ** 2 * _HALF_STEP**3 / (1.0 - _HALF_STEP**3)  # W t^2
_UPPER = np.append(np.cumsum(_QUAD_W[::-1])[::-1], 0.0) + _QUAD_W[-1] * _HALF_STEP / (
    1.0 - _HALF_STEP
)  # _UPPER[c]: the weight of every node from c on, the grid's continuation included
_TAIL_TOLERANCE = 1e-12  # absolute, in units where E‖W‖ >= 1/sqrt(3)
_LOG_TOLERANCE = np.log(_TAIL_TOLERANCE)
_LOG_UPPER = np.log(_UPPER)
_WINDOW_ENDS = np.arange(np.searchsorted(_QUAD_U, 2.0), _QUAD_U.size, 3)  # every 1.5 from u = 2
_RESCALE = 8  # pivots multiplied before the product is brought back by t^8
_T_POWERS = _QUAD_T[None, :] ** np.arange(_RESCALE + 1)[:, None]
_QUAD_CHUNK_ELEMENTS = 32_768  # epochs x nodes per block: the block stays in cache
_TRIDIAGONAL_CHUNK = 4096  # epochs per block of the Householder reduction


def expected_norms(
    mean: np.ndarray, cov: np.ndarray, scales, centred: np.ndarray | None = None
) -> list[np.ndarray]:
    """E‖W‖ for W ~ N(m_k, sS_k), for each scale s: one reduction serves every scale.

    The kernel of ``credcli.engine.metrics.expected_norm`` (its docstring has the method):
    a closed form (the folded normal) for d = 1, else a Householder reduction of each S_k
    to tridiagonal form, its first vector along m_k, and a trapezoidal rule in log t.
    The arrays are taken as clean (``credcli.engine.metrics`` validates them).

    Parameters
    ----------
    mean : numpy.ndarray, shape (N, d)
        The means m_k.
    cov : numpy.ndarray, shape (N, d, d)
        The covariances S_k, symmetric positive (semi-)definite.
    scales : iterable of float
        The factors s on the covariances, each > 0.
    centred : numpy.ndarray or None, shape (N,)
        When given (d >= 2), filled in place with E‖N(0, S_k)‖ from the same reduction
        (det(I + 2tS) does not depend on the basis); not written for d = 1.

    Returns
    -------
    list of numpy.ndarray
        One array (N,) of E‖W‖ per scale, in the order of ``scales``.

    Examples
    --------
    >>> cov = np.broadcast_to(np.eye(3), (1, 3, 3))
    >>> en = expected_norms(np.zeros((1, 3)), cov, (1.0, 4.0))  # χ₃'s mean 2√(2/π), twice it
    >>> [round(float(x[0]), 6) for x in en], round(float(2 * np.sqrt(2 / np.pi)), 6)
    ([1.595769, 3.191538], 1.595769)
    """
    n, d = mean.shape
    if d == 1:
        sd = np.sqrt(cov[:, 0, 0])
        return [_norm_1d(mean[:, 0], np.sqrt(s) * sd) for s in scales]
    outs = [np.empty(n) for _ in scales]
    for sl in epoch_chunks(n):
        diag, off2, unit = _tridiagonal(cov[sl], mean[sl])
        mean2 = np.einsum("ni,ni->n", mean[sl], mean[sl]) / unit
        root = np.sqrt(unit)
        for s, out in zip(scales, outs):
            out[sl] = _norm_tridiagonal(s * diag, (s * s) * off2, mean2) * root
        if centred is not None:
            centred[sl] = _norm_tridiagonal(diag, off2, np.zeros_like(mean2)) * root
    return outs


def _norm_1d(mean: np.ndarray, sd: np.ndarray) -> np.ndarray:
    """E|W| for W ~ N(m, σ²): σ√(2/π)·exp(−m²/2σ²) + |m|·erf(|m|/σ√2) (folded normal)."""
    from scipy import special

    m = np.abs(mean)
    z = m / np.where(sd > 0, sd, 1.0)
    folded = sd * np.sqrt(2.0 / np.pi) * np.exp(-0.5 * z * z) + m * special.erf(z / np.sqrt(2))
    return np.where(sd > 0, folded, m)


def _tridiagonal(
    cov: np.ndarray, start: np.ndarray | None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Householder reduction T_k = Q_kᵀ S_k Q_k per epoch, with Q_k e₁ along ``start_k``
    when given (Golub & Van Loan, Matrix Computations, Sec. 8.3.1).

    Returns the diagonal (d, n) and squared off-diagonal (d − 1, n) of T_k in units of
    tr S_k, and tr S_k (1 where it is 0). Epochs are on the last axis, so every step is
    a contiguous vector operation; blocks of epochs stay in cache.
    """
    n, d = cov.shape[:2]
    trace = np.einsum("nii->n", cov)
    unit = np.where(trace > 0, trace, 1.0)
    diag = np.empty((d, n))
    off2 = np.empty((max(d - 1, 0), n))
    for sl in epoch_chunks(n, _TRIDIAGONAL_CHUNK):
        a = np.divide(np.moveaxis(cov[sl], 0, -1), unit[sl], out=np.empty((d, d, len(unit[sl]))))
        for k in range(-1 if start is not None else 0, d - 2):
            if k < 0:  # the reflection taking start to e_1 (scaled first: no overflow)
                x = start[sl].T
                x = x / np.where(np.any(x != 0, axis=0), np.abs(x).max(axis=0), 1.0)
            else:  # the column below the diagonal: its squared norm is T's off-diagonal
                x = a[k + 1 :, k]
            norm2 = np.einsum("in,in->n", x, x)
            if k >= 0:
                off2[k, sl] = norm2
            v = x / np.sqrt(np.where(norm2 > 0, norm2, 1.0))
            v[0] += np.where(v[0] < 0, -1.0, 1.0)  # v = u + sign(u_0)e_1: no cancellation
            beta = 2.0 / np.einsum("in,in->n", v, v)
            block = a[k + 1 :, k + 1 :]  # H B H with H = I − βvvᵀ, B symmetric
            p = np.einsum("ijn,jn->in", block, v)
            p *= beta
            p -= (0.5 * beta * np.einsum("in,in->n", v, p)) * v
            block -= v[:, None] * p[None]
            block -= p[:, None] * v[None]
        if d >= 2:
            off2[d - 2, sl] = a[d - 1, d - 2] ** 2
        diag[:, sl] = np.einsum("iin->in", a)
    return diag, off2, unit


def _norm_tridiagonal(diag: np.ndarray, off2: np.ndarray, mean2: np.ndarray) -> np.ndarray:
    """E‖W‖ for W ~ N(√mean2·e₁, T), T tridiagonal with ``diag`` (d, n) and squared
    off-diagonals ``off2`` (d − 1, n): the quadrature of :func:`expected_norm`."""
    scale = diag.sum(axis=0) + mean2  # E[Q]; work with E[Q'] = 1
    positive = scale > 0
    scale = np.where(positive, scale, 1.0)
    alpha = diag * (2.0 / scale)  # I + 2tT' = I + t·tridiag(alpha, sqrt(beta))
    beta = off2 * (4.0 / scale**2)
    mean2 = mean2 / scale
    second = 1.0 + 0.5 * np.einsum("in,in->n", alpha, alpha) + beta.sum(axis=0)
    second += 2.0 * mean2 * alpha[0]  # E[Q'^2] = 1 + 2 tr T'^2 + 4 m'^T T' m'
    out = _LOW_FIRST - 0.5 * _LOW_SECOND * second
    if mean2.size * _QUAD_U.size <= _QUAD_CHUNK_ELEMENTS:  # one block: the whole grid
        out += _window_sum(alpha, beta, mean2, _QUAD_U.size) + _UPPER[-1]
        return np.where(positive, out * np.sqrt(scale), 0.0)
    ends = _window_ends(alpha, beta, mean2)  # else each epoch's own window, grouped
    out += _UPPER[ends]
    order = np.argsort(ends, kind="stable")
    for group in np.split(order, np.flatnonzero(np.diff(ends[order])) + 1):
        end = int(ends[group[0]])
        step = max(1, _QUAD_CHUNK_ELEMENTS // end)
        for i in range(0, group.size, step):  # blocks of epochs, not a per-epoch loop
            idx = group[i : i + step]
            out[idx] += _window_sum(alpha[:, idx], beta[:, idx], mean2[idx], end)
    return np.where(positive, out * np.sqrt(scale), 0.0)


def _window_sum(alpha: np.ndarray, beta: np.ndarray, mean2: np.ndarray, end: int) -> np.ndarray:
    """Σ_{j < end} w_j (1 − E[exp(−t_j Q')]) per epoch.

    With g̃ = g/t the bottom-up pivots of I + t·tridiag(alpha, √beta) are
    g̃_d = 1/t + α_d and g̃_k = 1/t + α_k − β_k/g̃_{k+1}; det = t^d Πg̃_k and the mean's
    quadratic form is mean2/g̃_1. Four vector operations per level and node."""
    d, r = alpha.shape
    inv_t = _QUAD_INV_T[:end]
    pivot = np.add(alpha[d - 1, :, None], inv_t)
    product = pivot.copy()
    other, ratio = np.empty_like(pivot), np.empty_like(pivot)
    pending = 1
    for k in range(d - 2, -1, -1):
        np.add(alpha[k, :, None], inv_t, out=other)
        np.divide(beta[k, :, None], pivot, out=ratio)
        other -= ratio
        product *= other
        pivot, other = other, pivot
        pending += 1
        if pending == _RESCALE:  # Π g̃ t stays within range for any d
            product *= _T_POWERS[pending, :end]
            pending = 0
    product *= _T_POWERS[pending, :end]
    log_phi = np.log(product, out=product)
    log_phi *= -0.5
    if np.any(mean2):
        np.divide(mean2[:, None], pivot, out=ratio)
        log_phi -= ratio
    return -(np.expm1(log_phi, out=log_phi) @ _QUAD_W[:end])


def _window_ends(alpha: np.ndarray, beta: np.ndarray, mean2: np.ndarray) -> np.ndarray:
    """Per epoch, the first node c from _WINDOW_ENDS on with E[exp(−t_c Q')]·(weight from c
    on) below _TAIL_TOLERANCE (the whole grid if none): nodes from c on then count as 1.
    The bound falls with c, so a bisection over the 19 candidates finds c (five
    evaluations of the pivot recurrence)."""
    low = np.zeros(alpha.shape[1], dtype=np.intp)
    high = np.full(alpha.shape[1], _WINDOW_ENDS.size)
    while np.any(low < high):
        mid = (low + high) // 2
        node = _WINDOW_ENDS[np.minimum(mid, _WINDOW_ENDS.size - 1)]
        small = _log_phi(alpha, beta, mean2, node) + _LOG_UPPER[node] <= _LOG_TOLERANCE
        small &= mid < high
        high = np.where(small, mid, high)
        low = np.where(small | (low >= high), low, mid + 1)
    ends = np.full(low.shape, _QUAD_U.size)
    found = low < _WINDOW_ENDS.size
    ends[found] = _WINDOW_ENDS[low[found]]
    return ends


def _log_phi(alpha: np.ndarray, beta: np.ndarray, mean2: np.ndarray, node: np.ndarray):
    """log E[exp(−tQ')] at each epoch's own node t = t_node (the pivots of I + t·T')."""
    d = alpha.shape[0]
    inv_t = _QUAD_INV_T[node]
    pivot = alpha[d - 1] + inv_t
    log_det = np.log(pivot)
    for k in range(d - 2, -1, -1):
        pivot = alpha[k] + inv_t - beta[k] / pivot
        log_det += np.log(pivot)
    return -0.5 * (log_det + d * _QUAD_U[node]) - mean2 / pivot


def centred_norm(cov: np.ndarray) -> np.ndarray:
    """E‖W‖ for W ~ N(0, S), per epoch.

    Closed forms for d = 1 (√(2/π)σ) and d = 2 (√(2/π)·√a·E(1 − b/a), a >= b the
    eigenvalues, E the complete elliptic integral of the second kind), the quadrature of
    ``credcli.engine.metrics.expected_norm`` otherwise.

    Parameters
    ----------
    cov : numpy.ndarray, shape (N, d, d)
        The covariances S_k, symmetric positive (semi-)definite.

    Returns
    -------
    numpy.ndarray, shape (N,)
        E‖W_k‖; 0 where S_k is 0.

    Examples
    --------
    >>> round(float(centred_norm(np.eye(2)[None])[0]), 6)  # √(π/2)
    1.253314
    """
    n, d = cov.shape[:2]
    if d == 1:
        return np.sqrt(2.0 / np.pi * cov[:, 0, 0])
    if d == 2:
        from scipy import special

        big, small = eigenvalues_2x2(cov)
        positive = big > 0
        big = np.where(positive, big, 1.0)
        small = np.clip(small, 0.0, big)  # a PSD matrix's rounding can make it -0
        return np.sqrt(2.0 / np.pi * big) * special.ellipe(1.0 - small / big) * positive
    return expected_norms(np.zeros((n, d)), cov, (1.0,))[0]
