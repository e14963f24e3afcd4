"""The sign-flip kernel of the ELT: the pair matrix A of Eq. (14) (‖s_i + s_j‖ − ‖s_i − s_j‖,
dense, by blocks of epochs, or streamed in float32), the flipped statistics ξ_bᵀAξ_b of
Eq. (15) with a proven upper bound that settles most flips of a test on course to reject,
and the randomisation p-value of Eq. (16), exhaustive or sequential. It takes clean whitened
errors; :mod:`credcli.engine.elt` validates and whitens.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np
from scipy.linalg import blas  # here, not in the flips: forked workers find it loaded

from credcli.engine import compiled
from credcli.engine.rng import SignRows
from credcli.engine.units import power_of_two_unit

PVALUE_RTOL = 100 * np.finfo(float).eps
"""Flipped statistics within this relative distance of T_obs count as ties (>=)."""


@dataclass(frozen=True)
class FlipOutcome:
    """The statistic, its randomisation p-value and null distribution, and how many flips
    were evaluated and bounded (``credcli.engine.elt.ELTResult`` describes each).

    Attributes
    ----------
    statistic : float
        T_obs of Eq. (13).
    pvalue : float
        The randomisation p-value of Eq. (16), or the sequential one when the flips
        stopped early.
    null_distribution : numpy.ndarray
        The flipped statistics of Eq. (15) in the order drawn, one per flip used; NaN for
        a flip that a bound alone placed below T_obs.
    flips_used : int
        The flips evaluated (B unless stopped early).
    flips_bounded : int
        Of those, the flips settled by the bound alone (the NaNs).
    """

    statistic: float
    pvalue: float
    null_distribution: np.ndarray
    flips_used: int
    flips_bounded: int


_FLOAT32_EPOCHS = 64  # from this many flipped blocks on, the flips run in float32
_PAIR_ROWS = 96  # rows per block: three 96×N float64 blocks stay in cache for N ~ 1000
STREAM_EPOCHS = 2048
"""Above this many flipped epochs the pair matrix is held in float32 only (4000 epochs:
64 MB instead of 192 MB for float64 and its float32 copy)."""


def pair_matrix(s: np.ndarray) -> np.ndarray:
    r"""A_ij = ‖s_i + s_j‖ − ‖s_i − s_j‖ with a zero diagonal.

    Then Eq. (13) is :math:`T = \xi^\top A \xi / (N(N-1))` with ξ = 1, and every sign
    flip ξ gives the randomised statistic of Eq. (15) by the same quadratic form.
    A = U + Uᵀ with U its strictly upper triangle (``pair_upper``).

    Parameters
    ----------
    s : numpy.ndarray, shape (N, d)
        The whitened errors.

    Returns
    -------
    numpy.ndarray, shape (N, N)
        A, symmetric, float64.

    Examples
    --------
    >>> pair_matrix(np.array([[1.0], [2.0]])).tolist()  # ‖3‖ − ‖−1‖ = 2
    [[0.0, 2.0], [2.0, 0.0]]
    """
    upper = pair_upper(s)
    return upper + upper.T


def pair_upper(s: np.ndarray) -> np.ndarray:
    """The strictly upper triangle U of the pair matrix A (zeros elsewhere; A = U + Uᵀ).

    ‖s_i ± s_j‖² = ‖s_i‖² + ‖s_j‖² ± 2 s_i·s_j, computed a block of rows at a time so
    that the intermediate arrays stay in cache, for j > i only; a square that rounds below
    zero counts as zero.

    Parameters
    ----------
    s : numpy.ndarray, shape (N, d)
        The whitened errors.

    Returns
    -------
    numpy.ndarray, shape (N, N)
        U, float64: U_ij = ‖s_i + s_j‖ − ‖s_i − s_j‖ for j > i, 0 on and below the
        diagonal.
    """
    n = s.shape[0]
    out = np.zeros((n, n))
    for _ in _pair_rows(s, out):
        pass
    return out


def pair_upper_float32(s: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """U of ``pair_upper`` in float64 and rounded to float32, with Σ|A_ij|, in one pass
    over its bands of rows (no pass over the N×N matrix to round or sum it).

    Parameters
    ----------
    s : numpy.ndarray, shape (N, d)
        The whitened errors.

    Returns
    -------
    upper : numpy.ndarray, shape (N, N)
        U, float64, bit for bit ``pair_upper(s)``.
    upper32 : numpy.ndarray of float32, shape (N, N)
        U rounded to float32.
    absolute : float
        Σ|A_ij| = 2·Σ|U_ij|, summed in float64 (in an order of its own: the rounding
        bound it serves has a margin for that).
    """
    n = s.shape[0]
    out, out32 = np.zeros((n, n)), np.zeros((n, n), dtype=np.float32)
    absolute = 2.0 * sum(band[4] for band in _pair_rows(s, out, out32=out32))
    return out, out32, absolute


def _zero_lower(rows: np.ndarray) -> None:
    """Zero the lower triangle and the diagonal of the leading square of a block of rows
    that starts on the diagonal."""
    k = rows.shape[0]
    rows[:, :k][_lower_mask(k)] = 0.0


@functools.lru_cache(maxsize=8)
def _lower_mask(k: int) -> np.ndarray:
    return np.tri(k, dtype=bool)


def pair_block_upper(s: np.ndarray, starts: np.ndarray) -> np.ndarray:
    """M, the sums of the strictly upper triangle U of the pair matrix over blocks of epochs.

    M_bc = Σ U_ij over i in block b, j in block c; A_b = M + Mᵀ is the block-summed pair
    matrix. M is made from bands of whole blocks of rows: the N×N matrix is never held.
    Bands are ``_PAIR_ROWS`` rows where the blocks divide it, so U's entries are the ones
    ``pair_upper`` gives, summed in the same order.

    Parameters
    ----------
    s : numpy.ndarray, shape (N, d)
        The whitened errors.
    starts : numpy.ndarray of int, shape (m,)
        The first epoch of each block of consecutive epochs, increasing from 0.

    Returns
    -------
    numpy.ndarray, shape (m, m)
        M, float64; zero below the diagonal (its diagonal holds the within-block sums).
    """
    n = s.shape[0]
    bounds = np.r_[starts, n]
    out = np.zeros((starts.size, starts.size))
    bands, first = [], 0  # whole blocks, at most _PAIR_ROWS rows unless one block is longer
    for b in range(1, starts.size + 1):
        if b == starts.size or bounds[b + 1] - bounds[first] > _PAIR_ROWS:
            bands.append((first, b))
            first = b
    row_bands = [(int(bounds[b0]), int(bounds[b1])) for b0, b1 in bands]
    for (b0, b1), (start, _, plus, _, _) in zip(bands, _pair_rows(s, bands=row_bands)):
        by_row = _block_sums(plus, starts[b0:b1] - start)
        out[b0:b1, b0:] = _block_sums(by_row.T, starts[b0:] - start).T
    return out


KERNEL_PAIRS = 40_000_000
"""Pairs of epochs a process builds with numpy before it turns to the compiled kernel
(:func:`credcli.engine.compiled.pair_band_kernel`, when numba is installed): numba's
import and first call, about 0.3 s of CPU, are repaid by then (the kernel saves about
6 ns a pair; figures in docs/performance.md). A short diagnosis never loads numba."""

_pairs_built = [0]  # pairs this process has built (forked workers start from their parent's)


def _band_kernel(n: int):
    """The compiled band kernel, once this process has built ``KERNEL_PAIRS`` pairs or
    where it is loaded already (:func:`credcli.engine.compiled.warm`); None before that, or
    without numba (the numpy path, the same bits)."""
    _pairs_built[0] += n * (n - 1) // 2
    if _pairs_built[0] <= KERNEL_PAIRS and not compiled.warmed():
        return None
    return compiled.pair_band_kernel()


def kernel_repaid(pairs: int) -> bool:
    """Whether a process that builds ``pairs`` pairs of epochs turns to the compiled kernel
    (more than :data:`KERNEL_PAIRS`), and so pays numba's start-up anyway.

    Parameters
    ----------
    pairs : int
        Pairs of epochs, Σ N(N − 1)/2 over the ELTs a process will run.

    Returns
    -------
    bool
        True above :data:`KERNEL_PAIRS`.
    """
    return pairs > KERNEL_PAIRS


def _pair_rows(
    s: np.ndarray, out: np.ndarray | None = None, bands=None, out32=None, sums: bool = False
):
    """Blocks of rows of A's strictly upper triangle: (start, stop, A[start:stop, start:],
    the block's sum (NaN in the compiled kernel's path unless ``sums``), the sum of its
    absolute values) in float64 with zeros on and below
    the diagonal of its leading k×k square, written into ``out`` when given (the block is
    then a view of it) and rounded into ``out32`` (float32, N×N) when given (the sum of
    absolute values is 0.0 without it). ``bands``: the (start, stop) of the blocks,
    _PAIR_ROWS rows each by default.

    A squared norm ‖s_i ± s_j‖² computed as ‖s_i‖² + ‖s_j‖² ± 2 s_i·s_j can round below
    zero when s_j ≈ ∓s_i; its square root is then NaN, which the block's sum shows, and
    that block is computed again with the squares clamped at zero. The result is that of
    clamping every square, with two passes fewer per block. The compiled kernel
    (:func:`_band_kernel`) clamps every square and gives the same bits: the same
    correctly rounded operations on the same operands, in the same order."""
    n = s.shape[0]
    kernel = _band_kernel(n)
    sq = np.ascontiguousarray(np.einsum("ni,ni->n", s, s))
    twice = 2.0 * s  # exact: 2 s_i·s_j is then one product, bit for bit
    # ‖s_i‖² + ‖s_j‖² as the product [‖s_i‖², 1]·[1, ‖s_j‖²]: the same sum, faster than
    # numpy's broadcast addition (products with 1 are exact; one rounding either way)
    sq_ones = np.stack([sq, np.ones(n)], axis=1)
    ones_sq = np.stack([np.ones(n), sq])
    if bands is None:
        bands = [(a, min(n, a + _PAIR_ROWS)) for a in range(0, n, _PAIR_ROWS)]
    rows = max(stop - start for start, stop in bands)
    minus = np.empty((rows, n))
    two_gram = np.empty((rows, n))
    spare = np.empty((rows, n)) if out is None else None
    no32 = np.zeros((0, 0), dtype=np.float32)
    for start, stop in bands:
        k, width = stop - start, n - start
        g, m = two_gram[:k, :width], minus[:k, :width]
        plus = spare[:k, :width] if out is None else out[start:stop, start:]
        band32 = None if out32 is None else out32[start:stop, start:]
        np.matmul(twice[start:stop], s[start:].T, out=g)
        if kernel is not None:
            row0, col0, whole = (0, 0, spare) if out is None else (start, start, out)
            absolute = kernel(
                sq, two_gram, k, start, whole, row0, col0, no32 if out32 is None else out32
            )
            yield start, stop, plus, float(plus.sum()) if sums else math.nan, absolute
            continue
        sums = (sq_ones[start:stop], ones_sq[:, start:])
        _pair_block(*sums, g, m, plus, clamp=False)
        total = float(plus.sum())
        if math.isnan(total):
            _pair_block(*sums, g, m, plus, clamp=True)
            total = float(plus.sum())
        absolute = 0.0
        if band32 is not None:
            band32[...] = plus
            absolute = float(np.abs(plus, out=m).sum())
        yield start, stop, plus, total, absolute


def _pair_block(sq_ones, ones_sq, two_gram, minus, plus, clamp: bool) -> None:
    """plus := ‖s_i + s_j‖ − ‖s_i − s_j‖ from the squared norms (as the factors
    [‖s_i‖², 1] and [1, ‖s_j‖²]) and 2 s_i·s_j, strictly upper; ``clamp``: squared norms
    that rounded below zero count as zero."""
    np.matmul(sq_ones, ones_sq, out=minus)  # ‖s_i‖² + ‖s_j‖²
    np.add(minus, two_gram, out=plus)  # ‖s_i + s_j‖²
    minus -= two_gram  # ‖s_i − s_j‖²
    for sq_norm in (plus, minus):
        if clamp:
            np.maximum(sq_norm, 0.0, out=sq_norm)
        with np.errstate(invalid="ignore"):
            np.sqrt(sq_norm, out=sq_norm)
    plus -= minus
    _zero_lower(plus)


def pair_matrix_float32(s: np.ndarray) -> tuple[np.ndarray, float, float]:
    """The strictly upper triangle of A (``pair_matrix``) rounded to float32, with 1ᵀA1 and
    Σ|A_ij| summed in float64 from its float64 rows, which are never held all at once.

    Parameters
    ----------
    s : numpy.ndarray, shape (N, d)
        The whitened errors.

    Returns
    -------
    upper : numpy.ndarray of float32, shape (N, N)
        U rounded to float32, zeros on and below the diagonal.
    total : float
        1ᵀA1 = 2·1ᵀU1, in float64.
    absolute : float
        Σ|A_ij| = 2·Σ|U_ij|, in float64.
    """
    n = s.shape[0]
    out = np.zeros((n, n), dtype=np.float32)
    total = absolute = 0.0
    for _, _, _, block_sum, block_abs in _pair_rows(s, out32=out, sums=True):  # each pair once
        total += 2.0 * block_sum
        absolute += 2.0 * block_abs
    return out, total, absolute


def _exact_dense(a: np.ndarray, factor: float, xi: np.ndarray) -> np.ndarray:
    """factor · ξ_bᵀaξ_b in float64 for rows ξ_b (float ±1): ξᵀAξ from A (factor 1) or from
    its strictly upper triangle (factor 2)."""
    return factor * np.einsum("bi,bi->b", xi @ a, xi)


def _exact_quadratic(s: np.ndarray, xi: np.ndarray) -> np.ndarray:
    """ξ_bᵀAξ_b in float64 for rows ξ_b (float ±1), A's rows rebuilt a block at a time."""
    values = np.zeros(xi.shape[0])
    for start, stop, plus, _, _ in _pair_rows(s):
        values += 2.0 * np.einsum("bi,bi->b", xi[:, start:stop], xi[:, start:] @ plus.T)
    return values


class _FlippedStatistics:
    """ξ_bᵀ A ξ_b for rows ξ_b of ±1 signs, exact where it matters; A is prepared once for
    every batch of flips.

    ``observed`` is 1ᵀA1, the unnormalised observed statistic.

    The flips run in float32 on the strictly upper triangle U of A (A = D + U + Uᵀ, so
    ξᵀAξ = tr D + 2ξᵀUξ; D is 0 but for the block sums of block flips) with BLAS's
    triangular product, which reads only that triangle and does half the multiply-adds
    of a full product, B·N²/2, in single precision. Rounding of U to
    float32 and the float32 inner products change each ξᵀAξ by at most
    (u + γ_N(1 + u))·Σ|A_ij| with u = 2⁻²⁴ and γ_N = Nu/(1 − Nu) (standard bounds for
    inner products in any order; the final sum runs in float64 and the products with ±1
    are exact); every flip within that bound of the observed value is recomputed in
    float64, so each comparison T_b >= T_obs is decided exactly as in float64.

    Built with :meth:`streamed` (large N), A is held in float32 only and the float64
    recheck rebuilds A's rows a block at a time from the whitened errors.
    """

    def __init__(
        self, observed: float, exact, upper32=None, trace=0.0, abs_sum=0.0, dense=None
    ) -> None:
        """``exact``: ξ_bᵀAξ_b in float64 for rows ξ_b (float ±1); ``upper32``: U in float32
        (None: float64 throughout, for small problems); ``trace``: tr A; ``abs_sum``:
        Σ|A_ij|, for the rounding bound; ``dense``: (a, upper, basis), A in float64 as for
        :meth:`of_matrix` and a function giving the columns of a :class:`_LowRankBound`."""
        self.observed, self.exact, self.upper32, self.trace = observed, exact, upper32, trace
        self.dense = dense
        self.low_rank: _LowRankBound | bool | None = None  # built at first need; False: never
        if upper32 is not None:
            self.bound = _float32_bound(upper32.shape[0], abs_sum)
            self.fine_bound = _float32_bound(min(upper32.shape[0], PRODUCT_ROWS), abs_sum)

    @classmethod
    def of_matrix(
        cls, a: np.ndarray, observed: float, upper: bool = False, basis=None, rounded=None
    ) -> _FlippedStatistics:
        """From A, or with ``upper`` its strictly upper triangle U (then 1ᵀA1 = 2·1ᵀU1);
        ``basis()``: the columns Q of a :class:`_LowRankBound` span (None: no bound);
        ``rounded``: (U in float32, Σ|A_ij|) when already made (``pair_upper_float32``)."""
        exact = functools.partial(_exact_dense, a, 2.0 if upper else 1.0)
        if a.shape[0] < _FLOAT32_EPOCHS:  # small problems: float64 throughout
            return cls(observed, exact)
        # U: the strictly upper triangle, ξᵀAξ = tr A + 2ξᵀUξ (the triangular product reads
        # only that triangle, the blocked one of _blocked every entry it is given)
        if rounded is not None and upper:
            upper32, abs_sum = rounded
        else:
            upper32 = a.astype(np.float32) if upper else np.triu(a.astype(np.float32), 1)
            np.fill_diagonal(upper32, 0.0)
            abs_sum = _abs_sum(a) * (2.0 if upper else 1.0)
        trace = 0.0 if upper else float(np.trace(a))
        dense = None if basis is None else (a, upper, basis)
        return cls(observed, exact, upper32, trace, abs_sum, dense)

    @classmethod
    def streamed(cls, s: np.ndarray) -> _FlippedStatistics:
        """From whitened errors s (N, d), with A in float32 only (:func:`pair_matrix_float32`);
        the float64 recheck rebuilds A's rows."""
        upper32, observed, abs_sum = pair_matrix_float32(s)
        return cls(observed, functools.partial(_exact_quadratic, s), upper32, 0.0, abs_sum)

    def __call__(self, signs: np.ndarray, below: float | None = None) -> np.ndarray:
        """ξ_bᵀAξ_b for the rows of ``signs``. ``below``: where a :class:`_LowRankBound`
        shows a flip's value to be < ``below`` in either evaluation (float32, or the
        float64 recheck; both within ``self.bound`` of the exact form), it is NaN instead."""
        if self.upper32 is None:
            return self.exact(signs.astype(np.float64))
        xi = signs.T.astype(np.float32, order="F")  # (N, b), a column per flip
        low_rank = self._low_rank(below) if below is not None else None
        if low_rank is None:
            return self._products(signs, xi)
        open_ = np.flatnonzero(low_rank(xi) >= below - self.bound)
        if open_.size == signs.shape[0]:  # the bound decides nothing here: drop it
            self.low_rank = False
            return self._products(signs, xi)
        values = np.full(signs.shape[0], np.nan)
        if open_.size:
            values[open_] = self._products(signs[open_], np.asfortranarray(xi[:, open_]))
        return values

    def _low_rank(self, below: float) -> _LowRankBound | None:
        """The bound, built at the first call that can use it: only for a float64 A of at
        least _BOUND_MIN_SIZE rows and ``below`` > _BOUND_GATE·N·‖A‖_F. The gate is the top
        of the bound's remainder N·‖R‖_F measured on the ELT's pair matrix: below it the
        bound certifies little, and its build is not repaid (figures in
        docs/measured.md)."""
        if self.low_rank is None:
            self.low_rank = False
            if self.dense is not None and self.dense[0].shape[0] >= _BOUND_MIN_SIZE:
                a, upper, basis = self.dense
                flat = a.reshape(-1)
                squares = (2.0 if upper else 1.0) * float(np.dot(flat, flat))  # ‖A‖_F²
                if below > _BOUND_GATE * a.shape[0] * math.sqrt(squares):
                    self.low_rank = _LowRankBound.of_matrix(a, upper, basis(), squares)
        return self.low_rank or None

    def _products(self, signs: np.ndarray, xi: np.ndarray) -> np.ndarray:
        """The float32 forms 2ξᵀUξ + tr A of the columns of xi (the rows of signs), with the
        float64 recheck of those within the rounding bound of the observed value."""
        # U's C-ordered buffer read in Fortran order is Uᵀ, lower triangular: Uᵀξ per column
        product = blas.strmm(1.0, self.upper32.T, xi, side=0, lower=1)
        values = self._forms(product, xi)
        close = np.flatnonzero(np.abs(values - self.observed) <= self.bound)
        if close.size and self.fine_bound < self.bound:  # a second, tighter look
            values[close] = self._blocked(np.asfortranarray(xi[:, close]))
            close = close[np.abs(values[close] - self.observed) <= self.fine_bound]
        if close.size:
            values[close] = self.exact(signs[close].astype(np.float64))
        return values

    def _blocked(self, xi: np.ndarray) -> np.ndarray:
        """2ξᵀUξ + tr A of the columns of xi with Uᵀξ summed :data:`PRODUCT_ROWS` rows of U
        at a time in float32 and the partial sums added in float64: within
        ``fine_bound`` of the exact form."""
        n, upper = xi.shape[0], self.upper32
        product = np.zeros(xi.shape)
        for start in range(0, n, PRODUCT_ROWS):
            stop = min(n, start + PRODUCT_ROWS)
            product[start:] += upper[start:stop, start:].T @ xi[start:stop]
        return self._forms(product, xi)

    def _forms(self, product: np.ndarray, xi: np.ndarray) -> np.ndarray:
        """2ξᵀUξ + tr A of each column from Uᵀξ (``product``, overwritten) and ξ; the sum
        over epochs in float64."""
        product *= xi  # exact: a sign change
        values = product.sum(axis=0, dtype=np.float64)
        values *= 2.0
        values += self.trace
        return values


def _block_sums(a: np.ndarray, starts: np.ndarray) -> np.ndarray:
    """Sums of the rows of ``a`` over the blocks beginning at ``starts``: a reshape-sum
    over the longest stretch of equal blocks (faster than ``np.add.reduceat``),
    ``reduceat`` for the blocks after it (shorter ones: a run's or the subsample's last
    block)."""
    sizes = np.diff(np.r_[starts, a.shape[0]])
    equal = int(np.argmax(sizes != sizes[0])) if np.any(sizes != sizes[0]) else sizes.size
    width = int(sizes[0])
    head = a[: equal * width].reshape(equal, width, *a.shape[1:]).sum(axis=1)
    if equal == sizes.size:
        return head
    tail = np.add.reduceat(a[equal * width :], starts[equal:] - equal * width, axis=0)
    return np.concatenate([head, tail])


def _gamma(n: int, u: float) -> float:
    """γ_n = nu/(1 − nu): the relative error bound of n roundings in sequence with unit
    roundoff u (Higham, Accuracy and Stability of Numerical Algorithms, Lemma 3.1)."""
    return n * u / (1 - n * u)


_F32_UNIT, _F64_UNIT = 2.0**-24, 2.0**-53


def _float32_bound(n: int, abs_sum: float) -> float:
    """The largest error of a flipped form computed in float32 with inner products of at
    most ``n`` terms: U rounded to float32 (u·Σ|A|) and the products (γ_n·(1 + u)·Σ|A|);
    the float64 sums after them add at most (n + N)·2⁻⁵³ relative, inside the 1 % margin."""
    u = _F32_UNIT
    return (u + _gamma(n, u) * (1 + u)) * abs_sum * 1.01


PRODUCT_ROWS = 64
"""Rows of U per float32 product in the second look at flips close to T_obs
(:meth:`_FlippedStatistics._products`): each inner product then sums at most this many
terms, so its rounding bound is γ_64 instead of γ_N (16 times tighter at N = 1,000, 60
times at 4,000), and few flips are left for the float64 recheck."""


_BOUND_MIN_SIZE = 256  # below, the flips cost less than building the bound
_BOUND_GATE = 0.12


class _LowRankBound:
    r"""Upper bounds on ξᵀAξ for batches of sign vectors ξ ∈ {±1}ᴺ, at a cost of N·k per
    flip instead of the N²/2 of the form itself.

    For any N×k matrix Q and symmetric k×k matrix C, with M = QCQᵀ and R = A − M,

    .. math:: \xi^\top A\xi = c^\top C c + \xi^\top R\,\xi
              \le c^\top C c + N\,\lambda_{\max}(R) \le c^\top C c + N\,\|R\|_F,
              \qquad c = Q^\top\xi,

    since ‖ξ‖² = N. This holds whatever Q and C are; they only decide how tight it is.
    Q is an orthonormal basis of given columns (:func:`_bound_basis`) and C = QᵀAQ, so M
    holds A's few large eigenvalues. ‖R‖_F² = ‖A‖_F² − 2⟨A, M⟩ + ‖M‖_F², with
    ⟨A, M⟩ = Σ(QᵀAQ)∘C and ‖M‖_F² = tr(GCGC), G = QᵀQ: one float64 product AQ, no N×N
    temporary.

    Rounding is bounded, never assumed away (γ_n of :func:`_gamma`):

    - ‖R‖_F²: each term is a sum of products with at most n = N² + 2N + k² + 4k + 2
      roundings in sequence, so its error is at most
      γ_n(‖A‖_F² + 2‖Q‖_F²‖A‖_F‖C‖_F + ‖Q‖_F⁴‖C‖_F²), doubled for adding the terms;
    - c in float32 from Q rounded to float32: |ĉ − c| ≤ δ = (u₃₂ + γ_N(u₃₂)(1 + u₃₂))·|Q|ᵀ1,
      so |cᵀCc − ĉᵀCĉ| ≤ (2|ĉ| + δ)ᵀ|C|δ, plus γ_2k·|ĉ|ᵀ|C||ĉ| for forming ĉᵀCĉ.

    Norms in these bounds are inflated by 1 %, the sum by 1e-12 relative.

    On the ELT's pair matrix of whitened errors N·‖R‖_F is a small fraction of N·‖A‖_F
    (docs/measured.md), and a strongly rejecting segment's 1ᵀA1 is several times it, so
    the flips are certified below it.
    """

    def __init__(self, q32, c, delta, remainder) -> None:
        self.q32, self.c, self.abs_c, self.remainder = q32, c, np.abs(c), remainder
        self.delta, self.abs_c_delta = delta, self.abs_c @ delta

    @classmethod
    def of_matrix(cls, a: np.ndarray, upper: bool, basis: np.ndarray, squares: float):
        """From A in float64 (its strictly upper triangle U when ``upper``), columns
        (N, k) whose span Q is to hold A's large eigenvalues, and ‖A‖_F² (one dot
        product of A's entries)."""
        n, k = basis.shape
        q = np.linalg.qr(basis)[0]
        aq = _symmetric_apply(blas.dtrmm, a, q) if upper else a @ q
        p = q.T @ aq  # QᵀAQ
        c = 0.5 * (p + p.T)
        g = q.T @ q
        remainder2 = squares - 2.0 * float(np.vdot(p, c)) + float(np.trace(g @ c @ g @ c))
        q2, c_norm = 1.01 * float(np.trace(g)), 1.01 * float(np.linalg.norm(c))
        a_norm = 1.01 * math.sqrt(squares)
        rounding = 2.0 * _gamma(n * n + 2 * n + k * k + 4 * k + 2, _F64_UNIT)
        rounding *= a_norm**2 + 2.0 * q2 * a_norm * c_norm + (q2 * c_norm) ** 2
        remainder = n * math.sqrt(max(remainder2 + rounding, 0.0)) * (1 + 1e-12)
        u = _F32_UNIT
        delta = 1.01 * (u + _gamma(n, u) * (1 + u)) * np.abs(q).sum(axis=0)
        return cls(q.astype(np.float32), c, delta, remainder)

    def __call__(self, xi32: np.ndarray) -> np.ndarray:
        """Upper bounds on ξᵀAξ for the columns of xi32 (N, b), float32 ±1."""
        c = (xi32.T @ self.q32).astype(np.float64)  # (b, k)
        quadratic = ((c @ self.c) * c).sum(axis=1)
        size = np.abs(c)
        error = (2.0 * size + self.delta) @ self.abs_c_delta
        error += _gamma(2 * self.c.shape[0], _F64_UNIT) * ((size @ self.abs_c) * size).sum(1)
        slack = 1.01 * error + self.remainder
        return quadratic + slack + 1e-12 * (np.abs(quadratic) + slack)


def _bound_basis(s: np.ndarray, starts: np.ndarray | None = None) -> np.ndarray:
    """Columns s_i, s_i/‖s_i‖ and s_i‖s_i‖ (0 where s_i = 0), summed over the sign blocks
    beginning at ``starts`` when given: a basis for the leading eigenvectors of the pair
    matrix A_ij = ‖s_i + s_j‖ − ‖s_i − s_j‖ (of its block sums BᵀAB with block sums BᵀF).

    A_ij is odd in s_i and in s_j, so its eigenvectors are odd functions of s; near
    ‖s_j‖ ≪ ‖s_i‖ it is 2s_i·s_j/‖s_i‖. These columns leave a remainder ‖R‖_F/‖A‖_F as
    small as the range of a Gaussian sketch does (Halko, Martinsson & Tropp 2011, SIAM
    Review 53(2), Alg. 4.1), which also costs a product with A (figures in
    docs/measured.md)."""
    norms = np.sqrt(np.einsum("ni,ni->n", s, s))[:, None]
    unit = np.divide(s, norms, out=np.zeros_like(s), where=norms > 0)
    columns = np.hstack([s, unit, s * norms])
    return columns if starts is None else _block_sums(columns, starts)


def _symmetric_apply(trmm, upper: np.ndarray, x: np.ndarray) -> np.ndarray:
    """(U + Uᵀ)x for U strictly upper triangular in C order, with two triangular products
    (``blas.strmm`` or ``blas.dtrmm``, as the dtype) that read only U."""
    lower = upper.T  # U's buffer in Fortran order: Uᵀ, lower triangular
    x = np.asfortranarray(x)
    return trmm(1.0, lower, x, side=0, lower=1) + trmm(1.0, lower, x, side=0, lower=1, trans_a=1)


def _abs_sum(a: np.ndarray, rows: int = 256) -> float:
    """Σ|a_ij|, a block of rows at a time (no N×N temporary)."""
    return float(sum(np.abs(a[i : i + rows]).sum() for i in range(0, a.shape[0], rows)))


_FIRST_BATCH = 64  # flips evaluated before the first stopping check; batches then double


def _stop_count(level: float | None, n_flips: int) -> int | None:
    """h*: the smallest exceedance count at which (1 + h)/(B + 1) >= level."""
    if level is None:
        return None
    return max(0, math.ceil(level * (n_flips + 1) - 1 - 1e-12))


def sign_flip_test(
    s,
    blocks,
    block_ids,
    n_flips,
    gen,
    separate_blocks=False,
    stop_level=None,
) -> FlipOutcome:
    """Flip B sign vectors of the blocks: T_obs, its null distribution and p-value.

    With blocks of L > 1 epochs the N×N pair matrix is summed into an m×m block matrix
    first: ξᵀAξ = ηᵀA_bη for block signs η, so the flips cost m²B instead of N²B. The
    statistic is homogeneous of degree 1 in s, so it is computed on s/2^k and multiplied
    back, exactly. With more than ``STREAM_EPOCHS`` single-epoch blocks (and no
    ``separate_blocks``) the pair matrix is held in float32 only. The inputs are taken as
    clean (``credcli.engine.elt`` checks them).

    Parameters
    ----------
    s : numpy.ndarray, shape (N, d)
        The whitened errors.
    blocks : numpy.ndarray of int, shape (N,)
        The sign block of each epoch, 0 … m − 1, non-decreasing (m = N: one epoch each).
    block_ids : numpy.ndarray of int, shape (m,)
        The adjacency key of each block (``credcli.engine.elt.sign_blocks``); read only
        with ``separate_blocks``.
    n_flips : int
        B, the number of sign vectors drawn.
    gen : numpy.random.Generator
        Source of the Rademacher signs (``credcli.engine.rng.rademacher``); it advances
        as for all B vectors, but the vectors are drawn as far as the flips go
        (``credcli.engine.rng.SignRows``).
    separate_blocks : bool
        Leave out of the statistic the pairs of epochs in the same or adjacent blocks
        (keys at most 1 apart); T is then normalised by the number of pairs kept.
    stop_level : float or None
        Stop once the test can no longer reject at this level; flips of a test on course
        to reject may then be settled by a proven bound (None: all B, exactly).

    Returns
    -------
    FlipOutcome
        T_obs, its p-value (1 + h)/(B + 1) with h the flips >= T_obs (the larger of
        h/l and (1 + h)/(B + 1) when stopped after l flips), the flipped statistics and
        the counts of flips used and bounded.
    """
    n = s.shape[0]
    unit = power_of_two_unit(s)
    n_blocks = int(blocks[-1]) + 1
    flips = dict(n_flips=n_flips, gen=gen, unit=unit, stop_level=stop_level)
    scaled = s / unit
    if n_blocks == n > STREAM_EPOCHS and not separate_blocks:  # a large matrix: float32 only
        flipped = _FlippedStatistics.streamed(scaled)
        return _flip(flipped, float(n * (n - 1)), n, **flips)
    if n_blocks == n and not separate_blocks:  # flips on U itself (A = U + Uᵀ)
        if n >= _FLOAT32_EPOCHS:  # U in float64 and float32 in one pass
            upper, *rounded = pair_upper_float32(scaled)
        else:
            upper, rounded = pair_upper(scaled), None
        basis = functools.partial(_bound_basis, scaled)
        observed = 2.0 * float(upper.sum())
        flipped = _FlippedStatistics.of_matrix(upper, observed, True, basis, rounded)
        return _flip(flipped, float(n * (n - 1)), n, **flips)
    if n_blocks < n:  # A_b = M + Mᵀ with M the block sums of U
        starts = np.flatnonzero(np.r_[True, blocks[1:] != blocks[:-1]])
        upper = pair_block_upper(scaled, starts)
        sizes = np.diff(np.r_[starts, n]).astype(float)
    else:
        starts = None
        upper = pair_upper(scaled)
        sizes = np.ones(n)
    a = upper + upper.T
    del upper
    if separate_blocks:
        ids = np.asarray(block_ids)
        near = np.abs(ids[:, None] - ids[None, :]) <= 1
        a[near] = 0.0
        norm = float(sizes @ np.where(near, 0.0, 1.0) @ sizes)
    else:
        norm = float(n * (n - 1))
    basis = functools.partial(_bound_basis, scaled, starts)
    flipped = _FlippedStatistics.of_matrix(a, float(a.sum()), basis=basis)
    return _flip(flipped, norm, n_blocks, **flips)


def _flip(
    flipped: _FlippedStatistics,
    norm: float,
    n_blocks: int,
    *,
    n_flips: int,
    gen: np.random.Generator,
    unit: float,
    stop_level: float | None,
) -> FlipOutcome:
    """T_obs = 1ᵀA1/norm and B sign flips of it, stopped once the decision at
    ``stop_level`` is certain, the flips of a test on course to reject bounded where the
    bound decides them (see :func:`credcli.engine.elt.whitened_location_test`)."""
    total = flipped.observed
    scale = norm if norm > 0 else 1.0  # no pairs left: a is zero and so is the statistic
    t_obs = total / scale
    signs = SignRows(gen, (n_flips, n_blocks))  # drawn as far as the flips go
    threshold = t_obs - PVALUE_RTOL * abs(t_obs)
    stop = _stop_count(stop_level, n_flips)
    parts, count, used, batch = [], 0, 0, _FIRST_BATCH if stop is not None else n_flips
    below = None
    while used < n_flips:
        chunk = flipped(signs.take(used, used + batch), below) / scale
        parts.append(chunk)
        count += int(np.count_nonzero(chunk >= threshold))
        used += chunk.size
        batch *= 2
        if stop is not None and count >= stop and used < n_flips:
            break
        if stop is not None and threshold > 0 and count * n_flips < stop * used:
            # on course to reject, so every flip is needed; one that a bound places below
            # threshold·scale·(1 − 4u) gives v/scale < threshold after rounding too
            below = threshold * scale * (1.0 - 4.0 * _F64_UNIT)
        else:
            below = None
    null = np.concatenate(parts) * unit
    if used < n_flips:
        # Besag & Clifford's sequential p-value h/l, and never below (1 + h)/(B + 1), the
        # smallest p-value the exhaustive test could still give: h >= h* puts that at or
        # above the level, so the decision, read off the p-value, is the exhaustive test's
        # (h/l alone can fall below it: 12/960 = 0.0125 < 0.0127 with B = 999)
        pvalue = max(count / used, (1 + count) / (n_flips + 1))
    else:
        pvalue = (1 + count) / (n_flips + 1)
    return FlipOutcome(t_obs * unit, pvalue, null, used, int(np.count_nonzero(np.isnan(null))))
