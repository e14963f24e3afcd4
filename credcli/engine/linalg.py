"""Per-epoch linear algebra every layer may use: the one validation of errors and
claimed covariances, their Cholesky factors, closed-form 2×2 eigenvalues, the chunks of
epochs that keep temporaries bounded on long segments, an index as a slice, and fast exact
reductions of tall arrays (over an epoch's few entries, or column by column).

Readers (``credcli.io``) use it to check a covariance as they read it; the engine uses it
at every public entry. It imports nothing of credcli but ``errors``.
"""

from __future__ import annotations

import math
from collections.abc import Iterator

import numpy as np

from credcli.errors import CredcliError

EPOCH_CHUNK = 262_144
"""Epochs per chunk of per-epoch linear algebra: temporaries stay bounded on long segments."""
CACHED_EPOCHS = 16_384
"""Epochs per chunk of the 2 × 2 closed forms (:func:`eigenvalues_2x2`,
:func:`inverse_sqrt_2x2`): each of their twenty-odd vector operations then reads and writes
arrays of 128 kB, which stay in cache, where chunks of :data:`EPOCH_CHUNK` went to memory
for every one (2^21 epochs: 0.29 → 0.15 s a pass, docs/performance.md). Every operation is
per epoch, so the chunks give the same bits."""


def epoch_chunks(n: int, size: int = EPOCH_CHUNK) -> Iterator[slice]:
    """Slices of at most ``size`` epochs covering range(n).

    Parameters
    ----------
    n : int
        The number of epochs.
    size : int, default EPOCH_CHUNK
        The most epochs in one slice.

    Yields
    ------
    slice
        ``slice(start, start + size)`` for start = 0, size, 2·size, … below ``n``.

    Examples
    --------
    >>> list(epoch_chunks(5, 2))
    [slice(0, 2, None), slice(2, 4, None), slice(4, 6, None)]
    """
    for start in range(0, n, size):
        yield slice(start, start + size)


SYMMETRY_RTOL = 1e-6
"""Largest relative asymmetry |Σ_ij − Σ_ji| / max|Σ| of a claimed covariance."""


def index_range(start: int, stop: int) -> np.ndarray:
    """``np.arange(start, stop)`` in 32-bit integers where they hold every value, else in
    64-bit: a long log's row numbers and its segments' epoch indices in half the memory
    (2·10⁶ epochs: 7.6 MiB each), the same values.

    Parameters
    ----------
    start, stop : int
        The first value and one past the last.

    Returns
    -------
    numpy.ndarray of int32 or int64, shape (stop − start,)
        start, start + 1, …, stop − 1.

    Examples
    --------
    >>> index_range(2, 5).tolist(), index_range(0, 3).dtype.name
    ([2, 3, 4], 'int32')
    >>> index_range(2**31 - 1, 2**31 + 1).tolist(), index_range(2**31 - 1, 2**31 + 1).dtype.name
    ([2147483647, 2147483648], 'int64')
    """
    small = stop - 1 <= np.iinfo(np.int32).max and start >= np.iinfo(np.int32).min
    return np.arange(start, stop, dtype=np.int32 if small else np.int64)


def as_slice(index: np.ndarray) -> slice | np.ndarray:
    """``index`` as a slice when it is a contiguous increasing range, else as it is.

    Parameters
    ----------
    index : numpy.ndarray of int
        Epochs.

    Returns
    -------
    slice or numpy.ndarray
        ``slice(first, last + 1)``, or ``index`` itself.

    Examples
    --------
    >>> as_slice(np.array([3, 4, 5])), as_slice(np.array([3, 5])).tolist()
    (slice(3, 6, None), [3, 5])
    """
    size = index.size
    if size == 1:  # one epoch: no difference to take (a log of 10⁶ one-epoch segments)
        return slice(int(index[0]), int(index[0]) + 1)
    if size and index[-1] - index[0] + 1 == size and np.all(np.diff(index) == 1):
        return slice(int(index[0]), int(index[-1]) + 1)
    return index


FOLDED_ENTRIES = 8
"""Most entries per epoch (or columns) that :func:`per_epoch` (:func:`per_column`) fold
one by one; wider arrays take numpy's own reduction, faster there (break-even near 36)."""


def per_epoch(ufunc: np.ufunc, a: np.ndarray) -> np.ndarray:
    """``ufunc.reduce`` over every axis of ``a`` but the first (the epochs'), as a fold over
    the few entries of an epoch: for ``maximum``, ``minimum``, ``logical_and`` and
    ``logical_or`` numpy's own values (they do not depend on the order, but for the sign of
    a zero, which numpy's reduction of such short rows takes in the same order), in a
    fraction of its time on tall arrays, where numpy's reduction over a short axis makes an
    inner loop of two or four entries per epoch (docs/performance.md). Above
    :data:`FOLDED_ENTRIES` entries, numpy's reduction itself.

    Parameters
    ----------
    ufunc : numpy.ufunc
        A binary ufunc.
    a : numpy.ndarray, shape (N, ...)
        The entries of each epoch.

    Returns
    -------
    numpy.ndarray, shape (N,)
        The reduction of each epoch's entries.

    Examples
    --------
    >>> per_epoch(np.maximum, np.array([[[1.0, -2.0], [3.0, 0.5]]])).tolist()
    [3.0]
    """
    flat = a.reshape(a.shape[0], math.prod(a.shape[1:]))
    if not 0 < flat.shape[1] <= FOLDED_ENTRIES:  # none (numpy's identity), or many
        return ufunc.reduce(flat, axis=1)
    out = flat[:, 0].copy()
    for j in range(1, flat.shape[1]):
        ufunc(out, flat[:, j], out=out)
    return out


def per_column(ufunc: np.ufunc, a: np.ndarray) -> np.ndarray:
    """``ufunc.reduce(a, axis=0)`` of a tall (N, m) array, column by column: for
    ``maximum`` and ``minimum`` numpy's own values (they do not depend on the order, but for
    the sign of a zero), in a fraction of its time, where numpy's reduction over the epochs
    makes an inner loop of m entries per epoch; above :data:`FOLDED_ENTRIES` columns,
    numpy's reduction itself.

    Parameters
    ----------
    ufunc : numpy.ufunc
        ``numpy.maximum`` or ``numpy.minimum``.
    a : numpy.ndarray, shape (N, m), N >= 1
        The columns.

    Returns
    -------
    numpy.ndarray, shape (m,)
        Each column's reduction.

    Examples
    --------
    >>> per_column(np.minimum, np.array([[1.0, 5.0], [-2.0, 7.0]])).tolist()
    [-2.0, 5.0]
    """
    if a.shape[1] > FOLDED_ENTRIES:
        return ufunc.reduce(a, axis=0)
    return np.array([ufunc.reduce(a[:, j]) for j in range(a.shape[1])], dtype=a.dtype)


def check_errors_cov(errors: np.ndarray, cov: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The one validation of (errors, cov) for every public entry of the engine.

    Shapes (N, d) and (N, d, d) ((N,) is d = 1), finite values, symmetric covariances (to
    ``SYMMETRY_RTOL``). Positive definiteness is checked where the covariances are
    factored (``cholesky``). Errors name the argument and the epoch.

    Parameters
    ----------
    errors : array_like, shape (N, d) or (N,)
        The errors e_k.
    cov : array_like, shape (N, d, d) or (N,)
        The claimed covariances Σ̂_k ((N,): variances, d = 1).

    Returns
    -------
    errors : numpy.ndarray, shape (N, d)
        The errors as float64, (N,) made (N, 1).
    cov : numpy.ndarray, shape (N, d, d)
        The covariances as float64, (N,) made (N, 1, 1).

    Raises
    ------
    CredcliError
        For arrays of the wrong or mismatched shapes, a value that is not finite (naming
        its index), or a covariance that is not symmetric (naming its epoch).

    Examples
    --------
    >>> e, c = check_errors_cov([1.0, 2.0], [4.0, 4.0])
    >>> e.shape, c.shape
    ((2, 1), (2, 1, 1))
    """
    errors = np.asarray(errors, dtype=float)
    cov = np.asarray(cov, dtype=float)
    if errors.ndim == 1:
        errors = errors[:, None]
    if cov.ndim == 1:
        cov = cov[:, None, None]
    if errors.ndim != 2 or cov.ndim != 3:
        raise CredcliError(
            f"errors must have shape (N, d) and cov (N, d, d); got {errors.shape} and {cov.shape}",
            "errors" if errors.ndim != 2 else "cov",
        )
    n, d = errors.shape
    if cov.shape != (n, d, d):
        raise CredcliError(
            f"cov must have shape (N, d, d) = ({n}, {d}, {d}) to match errors; got {cov.shape}",
            "cov",
        )
    for name, values in (("errors", errors), ("cov", cov)):
        bad = ~np.isfinite(values)
        if bad.any():
            where = ", ".join(str(int(i)) for i in np.argwhere(bad)[0])
            raise CredcliError(f"{name}[{where}] is not finite", name)
    # an exactly symmetric stack (as every reader builds it) needs no tolerance: one
    # comparison instead of four passes over the N×d×d values
    if d > 1 and not np.array_equal(cov, cov.transpose(0, 2, 1)):
        scale = np.abs(cov).max(axis=(1, 2))
        asym = np.abs(cov - cov.transpose(0, 2, 1)).max(axis=(1, 2)) > SYMMETRY_RTOL * scale
        if asym.any():
            k = int(np.argmax(asym))
            raise CredcliError(
                f"cov[{k}] is not symmetric (relative asymmetry above {SYMMETRY_RTOL:g})", "cov"
            )
    return errors, cov


def cholesky(matrices: np.ndarray, name: str = "cov") -> np.ndarray:
    """Cholesky factors of (N, d, d) (or (d, d)) positive definite matrices: a stack of
    2 × 2 float64 matrices in closed form (:func:`cholesky_2x2`), others by LAPACK.

    Parameters
    ----------
    matrices : numpy.ndarray, shape (N, d, d) or (d, d)
        Symmetric matrices.
    name : str
        The argument the matrices came from, for the error (default ``"cov"``).

    Returns
    -------
    numpy.ndarray
        The lower-triangular factors L with L Lᵀ = the matrix, in the shape given.

    Raises
    ------
    CredcliError
        If a matrix is not positive definite, naming ``name`` and the first such epoch
        (``cov[k]``).
    """
    values = np.asarray(matrices)
    if values.ndim == 3 and values.shape[1:] == (2, 2) and values.dtype == np.float64:
        factors = cholesky_2x2(values)  # LAPACK's numbers without its call per matrix
        if factors is not None:
            return factors
    try:
        return np.linalg.cholesky(matrices)
    except np.linalg.LinAlgError:
        stack = np.asarray(matrices, dtype=float).reshape(-1, *np.shape(matrices)[-2:])
        k = next(
            (i for i in range(stack.shape[0]) if not _factorable(stack[i])), 0
        )  # only on failure: find the first one
        where = f"{name}[{k}]" if np.ndim(matrices) == 3 else name
        raise CredcliError(
            f"{where} is not positive definite (a claimed covariance must be)", name
        ) from None


def cholesky_2x2(cov: np.ndarray) -> np.ndarray | None:
    """Cholesky factors of symmetric 2×2 matrices in closed form, or None where one is
    not positive definite.

    L = [[l₁₁, 0], [l₂₁, l₂₂]] with l₁₁ = √Σ₁₁, l₂₁ = Σ₂₁·(1/l₁₁) and
    l₂₂ = √(Σ₂₂ − l₂₁²): the operations of LAPACK's unblocked factorisation (``potf2``,
    which scales the column by the reciprocal of its pivot), reading the lower triangle as
    ``numpy.linalg.cholesky`` does, in three vector operations per epoch where numpy makes
    one LAPACK call per matrix (issue 35: 0.035–0.22 s against 0.11–0.26 s on 2·10⁶
    matrices, docs/performance.md). A matrix is positive definite here exactly where
    LAPACK finds it so: both pivots positive (NaN is not).

    Parameters
    ----------
    cov : numpy.ndarray, shape (N, 2, 2)
        Symmetric matrices.

    Returns
    -------
    numpy.ndarray, shape (N, 2, 2), or None
        The lower-triangular factors, L Lᵀ = Σ; None when a pivot is not positive (the
        caller finds and names that epoch).

    Examples
    --------
    >>> cholesky_2x2(np.array([[[4.0, 2.0], [2.0, 5.0]]])).tolist()
    [[[2.0, 0.0], [1.0, 2.0]]]
    >>> cholesky_2x2(np.array([[[1.0, 2.0], [2.0, 1.0]]])) is None
    True
    """
    out = np.zeros(cov.shape)
    for sl in epoch_chunks(cov.shape[0]):  # bounded temporaries
        with np.errstate(invalid="ignore"):  # √ of a negative Σ₁₁ is NaN: caught below
            first = np.sqrt(cov[sl, 0, 0], out=out[sl, 0, 0])
        if not np.all(first > 0):
            return None
        lower = np.multiply(cov[sl, 1, 0], 1.0 / first, out=out[sl, 1, 0])
        pivot = cov[sl, 1, 1] - lower * lower
        if not np.all(pivot > 0):
            return None
        np.sqrt(pivot, out=out[sl, 1, 1])
    return out


def lower_inverse(chol: np.ndarray) -> np.ndarray:
    """L⁻¹ of lower-triangular factors, by forward substitution over the d rows, each row
    a batched product over the epochs (no per-matrix LAPACK call, no pivoting).

    From L X = I, row by row: X_ii = 1/L_ii and X_ij = −(Σ_{j<=k<i} L_ik X_kj)/L_ii for
    j < i (X is lower triangular). One such inverse per segment serves the NEES, the GLS
    residuals and the memory's residuals (issue 35: one factorisation per segment); it
    costs d batched products over the epochs where ``numpy.linalg.inv`` factors every
    matrix again.

    Parameters
    ----------
    chol : numpy.ndarray, shape (N, d, d)
        Lower-triangular factors with a positive diagonal (:func:`cholesky`).

    Returns
    -------
    numpy.ndarray, shape (N, d, d)
        Their inverses, lower triangular.

    Examples
    --------
    >>> lower_inverse(np.array([[[2.0, 0.0], [1.0, 4.0]]])).tolist()
    [[[0.5, 0.0], [-0.125, 0.25]]]
    """
    n, d, _ = chol.shape
    out = np.zeros(chol.shape)
    for sl in epoch_chunks(n):  # bounded temporaries
        lower, inverse = chol[sl], out[sl]
        for i in range(d):
            inverse[:, i, i] = 1.0 / lower[:, i, i]
            if i:
                row = np.einsum("nk,nkj->nj", lower[:, i, :i], inverse[:, :i, :i])
                inverse[:, i, :i] = -row / lower[:, i, i, None]
    return out


def whitening_factors(cov: np.ndarray) -> np.ndarray:
    """F_k = Σ_k^{-1/2} of positive definite (N, d, d) matrices, a chunk of epochs at a
    time (:func:`inverse_sqrt`): the one whitening of a segment's errors, read by the NEES,
    the GLS residuals, the memory's model and the ELT (Eq. (12)).

    Any F_k with F_kᵀF_k = Σ_k⁻¹ gives the same NEES and GLS mean, but the series
    F_k(e_k − μ) that the memory is fitted on depends on the choice. The symmetric root
    turns with the state's frame (e → Re, Σ → RΣRᵀ gives F → RFRᵀ, so the whitened errors
    turn by the one constant R), where the inverse Cholesky factor L_k⁻¹ = Q_kΣ_k^{-1/2}
    adds an orthogonal Q_k that changes with Σ_k and with the components' order: with it,
    13 and 6 of 1,104 labels changed under a reversed order and a rotation, with this
    root none (``benchmarks/frame.py``, docs/measured.md).

    Parameters
    ----------
    cov : numpy.ndarray, shape (N, d, d)
        Positive definite matrices (checked already).

    Returns
    -------
    numpy.ndarray, shape (N, d, d)
        Σ_k^{-1/2}, symmetric.

    Examples
    --------
    >>> f = whitening_factors(np.array([[[2.0, 1.0], [1.0, 2.0]]]))
    >>> f[0].round(4).tolist()
    [[0.7887, -0.2113], [-0.2113, 0.7887]]
    >>> ((f[0] @ np.array([[2.0, 1.0], [1.0, 2.0]]) @ f[0]).round(12) + 0.0).tolist()  # no -0.0
    [[1.0, 0.0], [0.0, 1.0]]
    """
    out = np.empty(cov.shape)
    for sl in epoch_chunks(cov.shape[0]):
        out[sl] = inverse_sqrt(cov[sl])
    return out


def by_inverse_chunks(func, errors: np.ndarray, cov: np.ndarray, trailing=()) -> np.ndarray:
    """``func(e, F)`` of each chunk of epochs, with F_k = Σ_k^{-1/2} made there from ``cov``
    (:func:`whitening_factors`' numbers): what a per-epoch function of the whitening
    factors gives on the whole segment, without its N × d × d factors held.

    Parameters
    ----------
    func : callable
        ``func(errors, inverse)`` of a chunk's (n, d) errors and (n, d, d) factors, an
        array of n rows.
    errors : numpy.ndarray, shape (N, d)
        The errors e_k.
    cov : numpy.ndarray, shape (N, d, d)
        The claimed covariances (positive definite: checked already).
    trailing : tuple of int, default ()
        The shape of ``func``'s row.

    Returns
    -------
    numpy.ndarray, shape (N, *trailing)
        The rows of every chunk, in order.

    Examples
    --------
    >>> cov = np.array([[[4.0, 0.0], [0.0, 1.0]]])
    >>> whiten = lambda e, inverse: whitened_by(inverse, e)
    >>> by_inverse_chunks(whiten, np.array([[2.0, 3.0]]), cov, (2,)).tolist()
    [[1.0, 3.0]]
    """
    out = np.empty((errors.shape[0], *trailing))
    for sl in epoch_chunks(errors.shape[0]):
        out[sl] = func(errors[sl], inverse_sqrt(cov[sl]))
    return out


def whitened_by(inverse: np.ndarray, vectors: np.ndarray) -> np.ndarray:
    """F_k v_k for every epoch k: the vectors whitened by factors F_k with
    F_kᵀF_k = Σ_k⁻¹ (:func:`whitening_factors`, or :func:`lower_inverse`'s L_k⁻¹).

    Parameters
    ----------
    inverse : numpy.ndarray, shape (N, d, d) or (d, d)
        F_k per epoch, or one shared.
    vectors : numpy.ndarray, shape (N, d) or (d,)
        v_k per epoch, or one v at every epoch.

    Returns
    -------
    numpy.ndarray, shape (N, d), or (d,) for one inverse and one vector
        F_k v_k, a row per epoch.
    """
    if inverse.ndim == 2:
        return vectors @ inverse.T
    spec = "nij,nj->ni" if vectors.ndim == 2 else "nij,j->ni"
    return np.einsum(spec, inverse, vectors)


SEMIDEFINITE_RTOL = 1e-12
"""A symmetric matrix counts as positive semidefinite when no eigenvalue is below
−SEMIDEFINITE_RTOL × its largest eigenvalue magnitude (rounding of a singular covariance)."""


def check_semidefinite(matrices: np.ndarray, name: str = "cov") -> None:
    """Raise unless every matrix of (N, d, d) symmetric ones is positive semidefinite.

    For the moments of N(m, S) that stay defined when S is singular (E‖W‖ of a point mass
    is ‖m‖), where :func:`cholesky` would refuse a singular S.

    Parameters
    ----------
    matrices : numpy.ndarray, shape (N, d, d)
        Symmetric matrices.
    name : str
        The argument the matrices came from, for the error (default ``"cov"``).

    Raises
    ------
    CredcliError
        If a matrix has an eigenvalue below −:data:`SEMIDEFINITE_RTOL` times its largest
        eigenvalue magnitude, naming the first such epoch (``cov[k]``).

    Examples
    --------
    >>> check_semidefinite(np.array([np.eye(2), np.zeros((2, 2))]))  # a point mass is fine
    >>> check_semidefinite(np.array([np.diag([1.0, -1.0])]))
    Traceback (most recent call last):
    ...
    credcli.errors.CredcliError: cov[0] is not positive semidefinite (it has a negative eigenvalue)
    """
    values = np.linalg.eigvalsh(matrices)
    bad = values[:, 0] < -SEMIDEFINITE_RTOL * np.abs(values).max(axis=1)
    if bad.any():
        k = int(np.argmax(bad))
        raise CredcliError(
            f"{name}[{k}] is not positive semidefinite (it has a negative eigenvalue)", name
        )


def _factorable(matrix: np.ndarray) -> bool:
    try:
        np.linalg.cholesky(matrix)
    except np.linalg.LinAlgError:
        return False
    return True


CORRELATION_FLOOR = 1e-12
"""Smallest eigenvalue a claimed covariance's (or a segment's MSE matrix's) correlation
matrix D^{-1/2}ΣD^{-1/2} (D its diagonal) must exceed: below it two components are
correlated ±1 to working precision. Read on the correlation matrix, the test is free of the
components' units: a state that mixes metres and radians has a graded covariance whose own
smallest eigenvalue is tiny beside its largest entry, and is positive definite all the
same."""


def smallest_correlation_eigenvalue(cov: np.ndarray) -> np.ndarray:
    """The smallest eigenvalue of each matrix's correlation matrix D^{-1/2}ΣD^{-1/2}: 1 − |ρ|
    in closed form for d = 2, else ``eigvalsh`` a chunk of epochs at a time (bounded
    temporaries). Each entry is divided by √Σ_ii·√Σ_jj, which neither overflows nor
    underflows where the variances are far apart.

    Parameters
    ----------
    cov : numpy.ndarray, shape (N, d, d)
        Symmetric matrices with positive diagonals, d >= 2.

    Returns
    -------
    numpy.ndarray, shape (N,)
        The smallest eigenvalues; not above :data:`CORRELATION_FLOOR` where two components
        are correlated ±1 to working precision.

    Examples
    --------
    >>> smallest_correlation_eigenvalue(np.array([[[4.0, 1.0], [1.0, 1.0]]])).tolist()
    [0.5]
    """
    root = np.sqrt(np.diagonal(cov, axis1=1, axis2=2))
    if cov.shape[1] == 2:
        return 1.0 - np.abs(cov[:, 0, 1] / root[:, 0] / root[:, 1])
    out = np.empty(cov.shape[0])
    for sl in epoch_chunks(cov.shape[0]):
        r = root[sl]
        out[sl] = np.linalg.eigvalsh(cov[sl] / r[:, :, None] / r[:, None, :])[:, 0]
    return out


def eigenvalues_2x2(cov: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The larger and the smaller eigenvalue of symmetric 2×2 matrices, in closed form.

    Each matrix is scaled to O(1) by its largest entry (no underflow or overflow at any
    scale): the larger eigenvalue is mean + hypot(half difference, off-diagonal), the
    smaller det / larger (no cancellation between the two roots).

    Parameters
    ----------
    cov : numpy.ndarray, shape (N, 2, 2)
        Symmetric matrices.

    Returns
    -------
    big, small : numpy.ndarray, shape (N,)
        The larger and the smaller eigenvalue of each; ``small`` <= 0 when the matrix is
        not positive definite.

    Examples
    --------
    >>> big, small = eigenvalues_2x2(np.array([[[2.0, 1.0], [1.0, 2.0]]]))
    >>> big.tolist(), small.tolist()
    ([3.0], [1.0])
    """
    n = cov.shape[0]
    big, small = np.empty(n), np.empty(n)
    for sl in epoch_chunks(n, CACHED_EPOCHS):  # temporaries in cache
        p, q, r = cov[sl, 0, 0], cov[sl, 0, 1], cov[sl, 1, 1]
        unit = np.maximum(np.maximum(np.abs(p), np.abs(q)), np.abs(r))
        unit = np.where(unit > 0, unit, 1.0)
        p, q, r = p / unit, q / unit, r / unit
        larger = 0.5 * (p + r) + np.hypot(0.5 * (p - r), q)
        det = p * r - q * q
        big[sl] = unit * larger
        small[sl] = unit * np.divide(det, larger, out=np.zeros_like(det), where=larger > 0)
    return big, small


def inverse_sqrt_2x2(cov: np.ndarray) -> np.ndarray:
    """The symmetric inverse square roots Σ^{-1/2} of positive definite 2×2 matrices, in
    closed form.

    For A = [[p, q], [q, r]] with s = √det A and t = √(tr A + 2s), √A = (A + sI)/t
    (Cayley–Hamilton: (A + sI)² = A² + 2sA + s²I = (tr A + 2s)A), and since
    det(A + sI) = s·t², A^{-1/2} = [[r + s, −q], [−q, p + s]]/(s·t). Each matrix is first
    scaled by a power of 4 near its largest entry (exactly: no overflow or underflow at any
    scale, and no rounding from the scaling), and det A taken as
    the product of the closed-form eigenvalues (:func:`eigenvalues_2x2`), so no
    cancellation beyond theirs. Five vector operations per epoch where ``eigh`` makes a
    LAPACK call (issue 35). Where that smaller eigenvalue is not positive (a condition
    number near 1/ε, which a Cholesky factor may still pass), ``eigh`` takes over.

    Parameters
    ----------
    cov : numpy.ndarray, shape (N, 2, 2)
        Symmetric positive definite matrices.

    Returns
    -------
    numpy.ndarray, shape (N, 2, 2)
        Σ_k^{-1/2}, symmetric, with Σ^{-1/2} Σ Σ^{-1/2} = I.

    Examples
    --------
    >>> w = inverse_sqrt_2x2(np.array([[[4.0, 0.0], [0.0, 9.0]], [[2.0, 1.0], [1.0, 2.0]]]))
    >>> np.abs(w[0]).round(12).tolist()
    [[0.5, 0.0], [0.0, 0.333333333333]]
    >>> (w[1] @ np.array([[2.0, 1.0], [1.0, 2.0]]) @ w[1]).round(12).tolist()
    [[1.0, 0.0], [0.0, 1.0]]
    """
    out = np.empty(cov.shape)
    for sl in epoch_chunks(cov.shape[0], CACHED_EPOCHS):  # temporaries in cache
        out[sl] = _inverse_sqrt_2x2(cov[sl])
    return out


def _inverse_sqrt_2x2(cov: np.ndarray) -> np.ndarray:
    """:func:`inverse_sqrt_2x2` of one chunk of epochs."""
    _, exponent = np.frexp(per_epoch(np.maximum, np.abs(cov)))
    unit = np.ldexp(1.0, exponent + exponent % 2)  # 4^k: exact scaling, exact √unit
    big, small = eigenvalues_2x2(cov)
    p, q, r = cov[:, 0, 0] / unit, cov[:, 0, 1] / unit, cov[:, 1, 1] / unit
    out = np.empty(cov.shape)
    with np.errstate(divide="ignore", invalid="ignore"):  # the lost epochs, made below
        root = np.sqrt(big / unit) * np.sqrt(small / unit)  # √det of the scaled matrix
        denominator = root * np.sqrt(p + r + 2.0 * root) * np.sqrt(unit)
        out[:, 0, 0] = (r + root) / denominator
        out[:, 1, 1] = (p + root) / denominator
        out[:, 0, 1] = out[:, 1, 0] = -q / denominator
    # near-singular (condition near 1/ε): det's cancellation leaves no positive root
    lost = ~(small > 0)
    if lost.any():
        out[lost] = _inverse_sqrt_eigh(cov[lost])  # (and, where eigh fails too, Cholesky)
    return out


GRADED_SPREAD = 16.0
"""Ratio of a covariance's largest to smallest standard deviation √Σ_ii beyond which
:func:`_inverse_sqrt_eigh` takes its components in decreasing order of variance. Below it
``eigh`` is accurate in any order (spread 10, random order: the NEES within 1e-13
relatively), and ordering every matrix would cost 12–22 % of the whitening at d = 3–15
(100,000 epochs), so only the graded ones are ordered (and their bits alone change)."""


def _inverse_sqrt_eigh(cov: np.ndarray) -> np.ndarray:
    """U Λ^{-1/2} Uᵀ from ``eigh``, a graded matrix's (:data:`GRADED_SPREAD`) with its
    components in decreasing order of variance; where an eigenvalue comes out not
    positive, from the Cholesky factor (:func:`_inverse_sqrt_factored`).

    A state that mixes units (metres beside radians) has a graded covariance, Σ = DRD with
    D's entries orders of magnitude apart. ``eigh`` keeps a graded matrix's small
    eigenvalues and their vectors to working accuracy when the large variances come first,
    not otherwise: R well conditioned, d = 6, standard deviations spread over 10^5 in a
    random order, the NEES of the root's whitened errors was off by up to 1.4·10⁻⁵
    relatively and F Σ F by 8·10⁻⁵ from I; over 10^8, by 7.7 and 130. Permuting the
    components first (exact, and undone exactly) leaves both within 2·10⁻¹⁰ up to 10^12
    (``tests/test_speed_paths.py``). The result is the same matrix: the permutation is
    orthogonal and the root commutes with it."""
    variances = np.diagonal(cov, axis1=1, axis2=2)
    graded = variances.max(axis=1) / variances.min(axis=1) > GRADED_SPREAD**2
    if not graded.any():
        return _root_by_eigh(cov)
    out = np.empty(cov.shape)
    out[~graded] = _root_by_eigh(cov[~graded])
    order = np.argsort(-variances[graded], axis=1, kind="stable")  # ties in their own order
    out[graded] = _root_by_eigh(cov[graded], order)
    return out


def _root_by_eigh(cov: np.ndarray, order: np.ndarray | None = None) -> np.ndarray:
    """U Λ^{-1/2} Uᵀ of each matrix from ``eigh`` of P Σ Pᵀ, its components taken in
    ``order`` (None: as they are), with U's rows put back; the Cholesky factor's where an
    eigenvalue comes out not positive."""
    if order is None:
        lam, vecs = np.linalg.eigh(cov)
    else:
        epochs = np.arange(cov.shape[0])[:, None, None]
        lam, vecs = np.linalg.eigh(cov[epochs, order[:, :, None], order[:, None, :]])
        # Pᵀ U: the rows back in the components' order, so F = Pᵀ U Λ^{-1/2} Uᵀ P
        vecs = np.take_along_axis(vecs, np.argsort(order, axis=1)[:, :, None], axis=1)
    lost = ~(lam[:, 0] > 0)
    with np.errstate(divide="ignore", invalid="ignore"):
        out = np.einsum("nij,nj,nkj->nik", vecs, 1.0 / np.sqrt(lam), vecs)
    if lost.any():
        out[lost] = _inverse_sqrt_factored(cov[lost])
    return out


def _inverse_sqrt_factored(cov: np.ndarray) -> np.ndarray:
    """Σ^{-1/2} = W S⁻¹ Wᵀ from the singular values S and left singular vectors W of the
    Cholesky factor L = W S Vᵀ (Σ = L Lᵀ = W S² Wᵀ).

    A positive definite matrix whose condition number is near 1/ε passes the Cholesky
    factorisation, yet ``eigh`` may return its smallest eigenvalue as 0 or below (an
    absolute error of ε·λ_max); L's singular values, the eigenvalues' square roots, have
    the condition number's square root and keep their relative accuracy. Without this, such
    a covariance's NEES was NaN and read as an overflow.
    """
    w, sv, _ = np.linalg.svd(np.linalg.cholesky(cov))
    return np.einsum("nij,nj,nkj->nik", w, 1.0 / sv, w)


def inverse_sqrt(cov: np.ndarray) -> np.ndarray:
    """The symmetric inverse square roots Σ_k^{-1/2} = U Λ^{-1/2} Uᵀ of positive definite
    matrices: the segment's whitening (:func:`whitening_factors`; the ELT's, Eq. (12)) and
    the time offset's.

    Parameters
    ----------
    cov : numpy.ndarray, shape (N, d, d)
        Symmetric positive definite matrices.

    Returns
    -------
    numpy.ndarray, shape (N, d, d)
        Σ_k^{-1/2}: in closed form for d = 1 and d = 2 (:func:`inverse_sqrt_2x2`), from
        ``eigh`` otherwise.
    """
    if cov.shape[-1] == 1:
        return 1.0 / np.sqrt(cov)
    return inverse_sqrt_2x2(cov) if cov.shape[-1] == 2 else _inverse_sqrt_eigh(cov)
