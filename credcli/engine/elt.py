"""Empirical location test (ELT) of Section III-A, Eqs. (11)–(17).

Tests central symmetry of the whitened errors s_k = Σ̂_k^{-1/2} e_k with the energy
distance between {s_k} and {-s_k} (α = 1) and a sign-flip randomisation null.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from credcli.engine import linalg
from credcli.engine.config import DEFAULT_MAX_EPOCHS
from credcli.engine.flips import FlipOutcome, pair_upper, sign_flip_test
from credcli.engine.rng import RngLike, as_generator
from credcli.errors import CredcliError


@dataclass(frozen=True)
class ELTResult:
    """Outcome of the empirical location test.

    Unpacks like scipy's test results: ``statistic, pvalue = result``.

    Attributes
    ----------
    statistic : float
        T_obs of Eq. (13) on the epochs used.
    pvalue : float
        Randomised p-value of Eq. (16).
    null_distribution : numpy.ndarray
        The sign-flipped statistics T^(b) of Eq. (15), one per flip used, in the order the
        flips were drawn; NaN for a flip that a bound alone showed to be below T_obs
        (``flips_bounded``).
    n_used : int
        Number of epochs in the test (smaller than the segment when subsampled).
    subsampled : bool
        Whether a random subsample of epochs was used to respect the memory budget.
    block_length : int
        Number of consecutive epochs sharing one random sign.
    flips_used : int or None
        Sign flips evaluated: B, or fewer when the test stopped once it could no longer
        reject (``stop_level``); then ``pvalue`` is the sequential p-value h/l, or
        (1 + h)/(B + 1) where that is larger.
    flips_bounded : int
        Of the flips used, those whose statistic an upper bound alone placed below T_obs
        (``credcli.engine.flips``; only with ``stop_level``): they count as in the
        exhaustive test, not exceeding T_obs, and have no value in ``null_distribution``.

    References
    ----------
    P. Yan, L.-T. Hsu and R. Sun, "Credible Uncertainty Quantification under Noise and
    System Model Mismatch", Section III-A, Eqs. (13)-(16).

    Examples
    --------
    >>> e = np.random.default_rng(0).standard_normal((200, 2)) + 0.5  # a bias
    >>> result = location_test(e, np.broadcast_to(np.eye(2), (200, 2, 2)), 999, rng=1)
    >>> statistic, pvalue = result
    >>> result
    ELTResult(statistic=0.3519, pvalue=0.001, n_used=200, block_length=1, B=999)
    """

    statistic: float
    pvalue: float
    null_distribution: np.ndarray
    n_used: int
    subsampled: bool
    block_length: int
    flips_used: int | None = None
    flips_bounded: int = 0

    def __iter__(self):
        """``statistic, pvalue = result``, as for scipy's test results."""
        return iter((self.statistic, self.pvalue))

    def __repr__(self) -> str:
        return (
            f"ELTResult(statistic={self.statistic:.4g}, pvalue={self.pvalue:.4g}, "
            f"n_used={self.n_used}, block_length={self.block_length}, "
            f"B={self.null_distribution.size})"
        )


def whiten(errors: np.ndarray, cov: np.ndarray) -> np.ndarray:
    r"""Whitened errors :math:`s_k = \hat\Sigma_k^{-1/2} e_k`, Eq. (12).

    With the symmetric inverse square root, computed in chunks of epochs
    (:func:`credcli.engine.linalg.by_inverse_chunks`): the numbers of
    ``whitened_by(whitening_factors(cov), errors)``, the whitening the memory's model and
    the NEES read too. Nothing is validated here (``location_test`` does that).

    Parameters
    ----------
    errors : numpy.ndarray, shape (N, d)
        The errors e_k.
    cov : numpy.ndarray, shape (N, d, d)
        The claimed covariances Σ̂_k, symmetric positive definite.

    Returns
    -------
    numpy.ndarray, shape (N, d)
        s_k, one row per epoch; i.i.d. N(0, I_d) for credible Gaussian errors.

    Examples
    --------
    >>> whiten(np.array([[2.0, 3.0]]), np.diag([4.0, 9.0])[None]).tolist()
    [[1.0, 1.0]]
    """
    return linalg.by_inverse_chunks(_whitened, errors, cov, errors.shape[1:])


def _whitened(errors: np.ndarray, factors: np.ndarray) -> np.ndarray:
    """F_k e_k (:func:`credcli.engine.linalg.whitened_by`) in the argument order of
    :func:`credcli.engine.linalg.by_inverse_chunks`."""
    return linalg.whitened_by(factors, errors)


def energy_statistic(s: np.ndarray) -> float:
    r"""T_obs of Eq. (13) with α = 1, directly from the pairwise sums and differences.

    .. math:: T = \frac{2}{N(N-1)}\sum_{i<j}\big(\|s_i+s_j\| - \|s_i-s_j\|\big)

    Parameters
    ----------
    s : numpy.ndarray, shape (N, d)
        The whitened errors (``whiten``), N >= 2.

    Returns
    -------
    float
        T_obs: near 0 for centrally symmetric errors, positive for a mean.

    Examples
    --------
    >>> round(energy_statistic(np.array([[1.0, 0.0], [1.0, 0.0]])), 6)  # one pair, ‖2s‖
    2.0
    """
    n = s.shape[0]
    return float(2.0 * pair_upper(s).sum() / (n * (n - 1)))


def location_test(
    errors: np.ndarray,
    cov: np.ndarray,
    n_flips: int = 1000,
    rng: RngLike = None,
    block_length: int = 1,
    max_epochs: int = DEFAULT_MAX_EPOCHS,
) -> ELTResult:
    """Run the ELT on errors (N, d) with claimed covariances (N, d, d), Eqs. (13)–(16).

    Tests the central symmetry of the whitened errors s_k = Σ̂_k^{-1/2} e_k (H0 of
    Eq. (12)) with the energy distance between {s_k} and {-s_k} (α = 1, Eq. (13)) and a
    sign-flip randomisation null (Eqs. (14)–(15)). The errors and covariances are
    validated as [nees][credcli.engine.metrics.nees] validates them.

    Parameters
    ----------
    errors : array_like, shape (N, d)
        The errors e_k = x_k − x̂_k.
    cov : array_like, shape (N, d, d)
        The claimed covariances Σ̂_k, symmetric positive definite.
    n_flips : int
        B, the number of random sign-flip vectors.
    rng : Generator, SeedSequence, int or None
        Source of the Rademacher signs.
    block_length : int
        Epochs per sign block. Filter errors are autocorrelated; flipping the signs of
        blocks of L consecutive epochs keeps the within-block dependence under H0.
        1 (the paper's test) flips each epoch independently.
    max_epochs : int
        Memory budget. When N exceeds it, a seeded random subsample of ``max_epochs``
        epochs (whole blocks, kept in time order) is tested. Under H0 any subset chosen
        independently of the signs is still centrally symmetric, so the test keeps its level.

    Returns
    -------
    ELTResult
        The p-value is (1 + #{T_b >= T_obs}) / (B + 1), Eq. (16); T_b within a relative
        100 eps of T_obs count as ties (>=). Unpacks as ``statistic, pvalue``.

    Raises
    ------
    CredcliError
        If ``n_flips`` or ``block_length`` is not a positive integer, ``max_epochs``
        is below 2, the shapes do not match, a value is not finite, or a covariance is
        not symmetric positive definite (named with its epoch, ``cov[k]``).

    References
    ----------
    P. Yan, L.-T. Hsu and R. Sun, "Credible Uncertainty Quantification under Noise and
    System Model Mismatch", Section III-A, Eqs. (11)-(17).

    Examples
    --------
    >>> e = np.random.default_rng(0).standard_normal((200, 2))
    >>> cov = np.broadcast_to(np.eye(2), (200, 2, 2))
    >>> round(location_test(e, cov, n_flips=999, rng=1).pvalue, 2)  # centred: no SMM
    0.46
    >>> location_test(e + 0.5, cov, n_flips=999, rng=1).pvalue < 0.05  # a bias
    True
    """
    _check_flips(n_flips, block_length, max_epochs)
    errors, cov = linalg.check_errors_cov(errors, cov)
    linalg.cholesky(cov)  # positive definite, or an error naming the epoch
    s = whiten(errors, cov)
    return whitened_location_test(s, n_flips, as_generator(rng), block_length, max_epochs)


def tested_blocks(n: int, block_length: int, max_epochs: int, runs: int = 1) -> int:
    """Sign blocks the ELT flips for a segment of ``n`` epochs.

    Parameters
    ----------
    n : int
        The segment's epochs.
    block_length : int
        L, epochs per sign block.
    max_epochs : int
        The ELT's memory budget: above it a subsample of whole blocks is tested.
    runs : int
        The independent runs of n/runs epochs the segment pools (default 1); blocks do
        not cross runs.

    Returns
    -------
    int
        runs·⌈(n/runs)/L⌉; when n exceeds ``max_epochs``, at most
        ``max(2, max_epochs // L)`` (the whole blocks of the subsample).

    Examples
    --------
    >>> tested_blocks(1000, 3, 4000), tested_blocks(10_000, 3, 4000)
    (334, 1333)
    """
    n_blocks = runs * math.ceil(n // runs / block_length)
    if n > max_epochs:
        return min(n_blocks, max(2, max_epochs // block_length))
    return n_blocks


tested_blocks.__test__ = False  # not a test: pytest given a module that imports it collects it


def sign_blocks(n: int, block_length: int, runs: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """The sign block of each epoch, and an adjacency key of each block.

    Blocks are L consecutive epochs of one run (the epochs of a run are consecutive,
    n/runs of them); blocks of different runs never share a sign and are never adjacent:
    their keys differ by at least 2.

    Parameters
    ----------
    n : int
        The epochs, a multiple of ``runs``.
    block_length : int
        L, epochs per block (a run's last block may be shorter).
    runs : int
        The independent runs one after the other (default 1).

    Returns
    -------
    blocks : numpy.ndarray of int, shape (n,)
        The block of each epoch, 0 … runs·⌈(n/runs)/L⌉ − 1, in time order.
    keys : numpy.ndarray of int
        One key per block: neighbouring blocks of a run differ by 1, blocks of different
        runs by at least 2 (``separate_blocks`` leaves out pairs whose keys differ by at
        most 1).

    Examples
    --------
    >>> blocks, keys = sign_blocks(6, 2, runs=2)
    >>> blocks.tolist(), keys.tolist()
    ([0, 0, 1, 2, 2, 3], [0, 1, 3, 4])
    """
    per_run = n // runs
    local = np.arange(n) % per_run // block_length
    run = np.arange(n) // per_run
    width = math.ceil(per_run / block_length)
    blocks = run * width + local
    keys = np.arange(runs * width) + np.arange(runs * width) // width
    return blocks, keys


def _check_flips(n_flips, block_length, max_epochs) -> None:
    """The one validation of the ELT's settings, for both public entries."""
    if not (isinstance(n_flips, (int, np.integer)) and n_flips >= 1):
        raise CredcliError(
            f"`n_flips` (the number of sign flips B) must be a positive integer; got {n_flips}",
            "n_flips",
        )
    if not (isinstance(block_length, (int, np.integer)) and block_length >= 1):
        raise CredcliError(
            f"`block_length` must be a positive integer; got {block_length}", "block_length"
        )
    if max_epochs < 2:
        raise CredcliError(
            f"max_epochs (the ELT's memory budget) must allow at least 2 epochs; got {max_epochs}",
            "max_epochs",
        )


def whitened_location_test(
    s: np.ndarray,
    n_flips: int,
    gen: np.random.Generator,
    block_length: int = 1,
    max_epochs: int = DEFAULT_MAX_EPOCHS,
    separate_blocks: bool = False,
    stop_level: float | None = None,
    runs: int = 1,
) -> ELTResult:
    """The ELT on whitened errors s (N, d); see ``location_test``.

    The settings are validated as ``location_test`` validates them; ``s`` is taken as it
    is (clean whitened errors).

    ``separate_blocks``: leave out of the statistic the pairs of epochs in the same or in
    adjacent sign blocks. Pairs within a block do not change under block flips, and pairs
    across a block boundary carry the dependence that block flips cannot reproduce; with
    them left out, the randomisation null keeps its level on serially correlated errors.

    ``stop_level``: stop flipping once the test can no longer reject at this level. All B
    sign vectors are drawn first, exactly as without stopping, and evaluated in order; the
    test rejects iff (1 + h)/(B + 1) < level, i.e. iff the exceedance count h stays below
    h* = ⌈level(B + 1) − 1⌉, so once h* exceedances are seen the decision is the exhaustive
    test's. The p-value is then Besag and Clifford's (1991, Biometrika 78(2)) sequential
    p-value h/l, with h >= h* the count after the l flips evaluated (the stop is checked
    after each batch), raised where needed to (1 + h)/(B + 1) >= level, the least the
    exhaustive p-value can be: h/l alone can fall below the level (12/960 < 0.0127 with
    B = 999), and the decision is read off the p-value; ``flips_used`` is l. A test on course to
    reject (fewer than h*·l/B exceedances after l flips) needs every flip; there, flips that
    a proven upper bound places below T_obs (:mod:`credcli.engine.flips`) are counted without
    their quadratic forms, so h, and the p-value, are the exhaustive test's
    (``flips_bounded``).

    ``runs``: s holds that many independent Monte Carlo runs of N/runs epochs one after
    the other; each run's errors are flipped in their own blocks (``sign_blocks``).

    Parameters
    ----------
    s : numpy.ndarray, shape (N, d)
        The whitened errors (``whiten``).
    n_flips : int
        B, the number of random sign-flip vectors, >= 1.
    gen : numpy.random.Generator
        Source of the Rademacher signs and of the subsample.
    block_length : int
        L, epochs per sign block (default 1: the paper's test).
    max_epochs : int
        The memory budget: above it a random subsample of whole blocks, kept in time
        order, is tested (default ``DEFAULT_MAX_EPOCHS``).
    separate_blocks : bool
        Leave out the pairs in the same or adjacent blocks (above; default False).
    stop_level : float or None
        Stop flipping once the test can no longer reject at this level (above; default
        None: all B flips).
    runs : int
        The independent runs s holds (above; default 1).

    Returns
    -------
    ELTResult
        The statistic, its p-value, the null distribution of the flips used, and how many
        flips were used and bounded.

    Raises
    ------
    CredcliError
        If ``n_flips`` or ``block_length`` is not a positive integer, ``max_epochs`` is
        below 2, or N is not a multiple of ``runs``.
    """
    _check_flips(n_flips, block_length, max_epochs)
    n = s.shape[0]
    if runs < 1 or n % runs:
        raise CredcliError(f"runs: {n} epochs cannot be {runs} runs of equal length", "runs")
    blocks, keys = sign_blocks(n, block_length, runs)
    subsampled = n > max_epochs
    if subsampled:
        keep = tested_blocks(n, block_length, max_epochs, runs)
        chosen = np.sort(gen.choice(blocks[-1] + 1, size=keep, replace=False))
        mask = np.isin(blocks, chosen)
        s, blocks = s[mask], np.searchsorted(chosen, blocks[mask])
    else:
        chosen = np.arange(blocks[-1] + 1)
    return _result(
        sign_flip_test(s, blocks, keys[chosen], n_flips, gen, separate_blocks, stop_level),
        s.shape[0],
        subsampled,
        block_length,
    )


def _result(outcome: FlipOutcome, n_used: int, subsampled: bool, block_length: int) -> ELTResult:
    return ELTResult(
        statistic=outcome.statistic,
        pvalue=outcome.pvalue,
        null_distribution=outcome.null_distribution,
        n_used=n_used,
        subsampled=subsampled,
        block_length=block_length,
        flips_used=outcome.flips_used,
        flips_bounded=outcome.flips_bounded,
    )
