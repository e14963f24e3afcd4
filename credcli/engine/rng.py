"""Normalising the ``rng`` argument once, without global state."""

from __future__ import annotations

import sys

import numpy as np

from credcli.errors import CredcliError

RngLike = np.random.Generator | np.random.SeedSequence | int | None


def as_generator(rng: RngLike) -> np.random.Generator:
    """Return a Generator for a Generator, a SeedSequence, an int seed or None.

    Parameters
    ----------
    rng : numpy.random.Generator, numpy.random.SeedSequence, int or None
        A Generator is returned as it is (its state is shared, not copied); anything else
        seeds a new one by ``numpy.random.default_rng`` (None: fresh entropy).

    Returns
    -------
    numpy.random.Generator
        The generator to draw from.

    Raises
    ------
    CredcliError
        For anything else (a negative or fractional seed, a string), naming the seed.

    Examples
    --------
    >>> gen = np.random.default_rng(0)
    >>> as_generator(gen) is gen, as_generator(7).random() == as_generator(7).random()
    (True, True)
    """
    if isinstance(rng, np.random.Generator):
        return rng
    try:
        return np.random.default_rng(rng)
    except (TypeError, ValueError) as exc:  # numpy's own words name no argument
        raise CredcliError(
            "the seed must be a non-negative integer, a numpy Generator or SeedSequence, or "
            f"None; got {rng!r}",
            "seed",
        ) from exc


def check_seed(seed) -> int:
    """``seed`` as a non-negative int, the seed of every segment's sign flips
    (:func:`credcli.engine.diagnosis.diagnose_segments`).

    Parameters
    ----------
    seed : int
        The seed (a numpy integer too; not a bool).

    Returns
    -------
    int
        The seed.

    Raises
    ------
    CredcliError
        Naming ``seed``, for anything but a non-negative integer.

    Examples
    --------
    >>> check_seed(7), check_seed(np.int64(3))
    (7, 3)
    """
    if isinstance(seed, (int, np.integer)) and not isinstance(seed, bool) and seed >= 0:
        return int(seed)
    raise CredcliError(f"the seed must be a non-negative integer; got {seed!r}", "seed")


def rademacher(gen: np.random.Generator, shape: tuple[int, int]) -> np.ndarray:
    """±1 signs (int8), bit for bit ``2 * gen.integers(0, 2, shape, dtype=np.int8) - 1``,
    leaving ``gen`` in the same state, faster (the signs are bits of the raw 64-bit
    outputs, read by whole-array operations).

    numpy draws bounded int8 values from 32-bit words, four bytes per word, low byte first,
    by Lemire's multiply-shift, which for {0, 1} is (2·byte) >> 8, the byte's top bit, and
    never rejects; PCG64's 32-bit words are the low then the high half of each 64-bit output
    (the high half kept for the next draw). So the signs are the top bits of the bytes of
    the raw 64-bit outputs. Another bit generator, a big-endian machine, or a numpy whose
    draws this does not reproduce (checked once per process) falls back to
    ``gen.integers``.

    Parameters
    ----------
    gen : numpy.random.Generator
        The generator; it advances exactly as ``gen.integers`` would advance it.
    shape : tuple of int
        (rows, columns) of the signs, e.g. (B flips, blocks).

    Returns
    -------
    numpy.ndarray of int8, shape ``shape``
        The signs, each -1 or +1.

    Examples
    --------
    >>> a, b = np.random.default_rng(3), np.random.default_rng(3)
    >>> signs = rademacher(a, (4, 5))
    >>> bool(np.array_equal(signs, 2 * b.integers(0, 2, (4, 5), dtype=np.int8) - 1))
    True
    >>> a.random() == b.random()  # the same state after
    True
    """
    if not _raw_draws_match():
        return _integers_signs(gen, shape)
    return _raw_signs(gen, shape)


def _integers_signs(gen: np.random.Generator, shape) -> np.ndarray:
    signs = gen.integers(0, 2, size=shape, dtype=np.int8)
    signs *= 2
    signs -= 1
    return signs


def _raw_signs(gen: np.random.Generator, shape) -> np.ndarray:
    bitgen = gen.bit_generator
    if type(bitgen) is not np.random.PCG64:
        return _integers_signs(gen, shape)
    count = shape[0] * shape[1]
    words = -(-count // 4)  # 32-bit words numpy draws for ``count`` bytes
    state = bitgen.state
    buffered = [np.uint32(state["uinteger"])] if state["has_uint32"] and words else []
    fresh = words - len(buffered)
    raw = bitgen.random_raw(-(-fresh // 2)).view(np.uint32)  # low half, then high half
    stream = np.concatenate([np.array(buffered, dtype=np.uint32), raw[:fresh]])
    signs = (stream.view(np.uint8)[:count] >> 7).view(np.int8).reshape(shape)
    signs *= 2
    signs -= 1
    state = bitgen.state
    if fresh % 2:  # numpy keeps the last output's high half for the next draw
        state["has_uint32"], state["uinteger"] = 1, int(raw[fresh])
    elif fresh:  # ... and leaves the last high half it used in place
        state["has_uint32"], state["uinteger"] = 0, int(raw[fresh - 1])
    else:
        state["has_uint32"] = 0
    bitgen.state = state
    return signs


_MATCH: list[bool] = []


def _raw_draws_match() -> bool:
    """Whether :func:`_raw_signs` reproduces ``gen.integers`` on this numpy (once)."""
    if not _MATCH:
        ok = sys.byteorder == "little"
        for first, shape in ((0, (3, 5)), (1, (2, 7)), (3, (4, 4)), (0, (1, 1))):
            if not ok:
                break
            a, b = np.random.default_rng(7), np.random.default_rng(7)
            for g in (a, b):
                g.integers(0, 2**32, size=first, dtype=np.uint32)  # a word left buffered
            ok = (
                np.array_equal(_raw_signs(a, shape), _integers_signs(b, shape))
                and a.integers(0, 2**31, 5).tolist() == b.integers(0, 2**31, 5).tolist()
                and a.random() == b.random()
            )
        _MATCH.append(ok)
    return _MATCH[0]


class SignRows:
    """The rows of ``rademacher(gen, shape)``, drawn only as far as they are read.

    ``gen`` is left at once in the state the whole draw leaves it in (PCG64 jumps ahead
    by ``advance``), so what is drawn from it next does not depend on how many rows are
    read; the rows come from a copy of its bit generator, bit for bit those of the whole
    draw. The stopping rule of the ELT reads 64 of B = 1,000 sign vectors on most segments
    that do not reject. Where :func:`rademacher` falls back to ``gen.integers``, every row
    is drawn here at once.

    Parameters
    ----------
    gen : numpy.random.Generator
        The generator; it advances exactly as ``rademacher(gen, shape)`` advances it.
    shape : tuple of int
        (rows, columns) of the signs, e.g. (B flips, blocks).

    Examples
    --------
    >>> a, b = np.random.default_rng(3), np.random.default_rng(3)
    >>> rows = SignRows(a, (6, 5))
    >>> bool(np.array_equal(rows.take(2, 4), rademacher(b, (6, 5))[2:4]))
    True
    >>> a.random() == b.random()  # the same state after
    True
    """

    def __init__(self, gen: np.random.Generator, shape: tuple[int, int]) -> None:
        self.shape = shape
        bitgen = gen.bit_generator
        if not _raw_draws_match() or type(bitgen) is not np.random.PCG64:
            self._all = rademacher(gen, shape)
            return
        self._all = None
        count = shape[0] * shape[1]
        words = -(-count // 4)
        state = bitgen.state
        buffered = [np.uint32(state["uinteger"])] if state["has_uint32"] and words else []
        self._bytes = np.array(buffered, dtype=np.uint32).view(np.uint8)
        fresh = words - len(buffered)
        self._raw_left = -(-fresh // 2)  # 64-bit outputs the whole draw takes
        self._copy = np.random.PCG64()
        self._copy.state = state
        if self._raw_left:  # the last output's high half is what numpy keeps or leaves
            bitgen.advance(self._raw_left - 1)
            last = bitgen.random_raw(1).view(np.uint32)
        final = bitgen.state
        if fresh % 2:
            final["has_uint32"], final["uinteger"] = 1, int(last[1])
        elif fresh:
            final["has_uint32"], final["uinteger"] = 0, int(last[1])
        else:
            final["has_uint32"] = 0
        bitgen.state = final

    def take(self, start: int, stop: int) -> np.ndarray:
        """Rows ``start`` to ``stop`` (int8 ±1, shape (stop − start, columns)).

        Parameters
        ----------
        start, stop : int
            The rows, 0 <= start <= stop (clipped to the rows there are).

        Returns
        -------
        numpy.ndarray of int8
            Those rows of ``rademacher(gen, shape)``.
        """
        rows, columns = self.shape
        stop = min(stop, rows)
        if self._all is not None:
            return self._all[start:stop]
        needed = stop * columns
        if self._bytes.size < needed:  # draw on, at least doubling what is held
            want = min(max(needed, 2 * self._bytes.size), rows * columns)
            raw = -(-(want - self._bytes.size) // 8)
            raw = min(raw, self._raw_left)
            self._raw_left -= raw
            fresh = self._copy.random_raw(raw).view(np.uint8)
            self._bytes = np.concatenate([self._bytes, fresh])
        signs = (self._bytes[start * columns : needed] >> 7).view(np.int8)
        signs = signs.reshape(stop - start, columns)
        signs *= 2
        signs -= 1
        return signs
