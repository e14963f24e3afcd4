"""Text tables and time: reading a comma- or whitespace-separated table, and stamps in
seconds (a unit decided once, with a note; date-times as seconds since the Unix epoch).

Shared by the log reader (:mod:`credcli.io.logs`), the navigation formats
(:mod:`credcli.io.formats`) and logs from arrays (:mod:`credcli.io.arrays`), below all of
them, so that none imports another in a cycle.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from credcli.errors import CredcliError
from credcli.io.schema import TimeUnit

_SNIFF_BYTES = 65536


def head_lines(path: Path) -> list[str]:
    """The first lines of a file, from its first 64 KiB decoded as UTF-8 (undecodable bytes
    replaced), for sniffing its format and header.

    When the file is longer than that, the last line read (cut short) is dropped.

    Parameters
    ----------
    path : pathlib.Path
        The file.

    Returns
    -------
    list of str
        Its first lines, without their line ends.

    Raises
    ------
    CredcliError
        If the file cannot be read.
    """
    try:
        with open(path, "rb") as fh:
            head = fh.read(_SNIFF_BYTES)
    except OSError as exc:
        raise CredcliError(f"{path}: cannot be read ({exc.strerror})") from exc
    text = head.decode("utf-8", errors="replace")
    lines = text.splitlines()
    return lines[:-1] if len(head) == _SNIFF_BYTES and len(lines) > 1 else lines


def read_csv_unmapped(path: Path, **options):
    """``pandas.read_csv`` of ``path`` through an open file rather than its name.

    Given a name, pandas (3.1 on) maps a large file into memory to parse it in threads; a
    file cut short while it is read (a log still being rewritten) then kills the process
    with SIGBUS. Through a file object it reads with plain reads: a file cut short is a
    short read and an error message, not a signal. The cost is one parsing thread.

    Parameters
    ----------
    path : pathlib.Path
        The file.
    **options
        Passed on to ``pandas.read_csv``.

    Returns
    -------
    pandas.DataFrame
        What ``pandas.read_csv`` returns.
    """
    import pandas as pd

    with open(path, "rb") as fh:
        return pd.read_csv(fh, **options)


def numeric_line(line: str) -> bool:
    """Whether every field of ``line`` (comma- or whitespace-separated) is a number.

    Parameters
    ----------
    line : str
        One line of a text table.

    Returns
    -------
    bool
        True when ``float`` reads every field (``nan`` and ``inf`` included, and a line
        without fields); False for a header or any other word.

    Examples
    --------
    >>> numeric_line("1.5, 2e3 nan"), numeric_line("# time x")
    (True, False)
    """
    try:
        [float(x) for x in line.replace(",", " ").split()]
    except ValueError:
        return False
    return True


def read_text_table(path: Path):
    """A text table as a DataFrame: comma- or whitespace-separated, with the header on
    the first line or on the last ``#`` line above the data (``# time truth_0 …``);
    other ``#`` lines are comments. A table without a header gets columns 0, 1, …

    The separator is a comma when the first data line holds one, else whitespace.

    Parameters
    ----------
    path : pathlib.Path
        The text file.

    Returns
    -------
    pandas.DataFrame
        One row per data line, its columns named by the header.

    Raises
    ------
    CredcliError
        If the file has no data rows, cannot be parsed as a table, or its header names a
        different number of columns than its rows hold.
    """
    import pandas as pd

    lines = head_lines(path)
    first = next((i for i, ln in enumerate(lines) if ln.strip() and not _comment(ln)), None)
    if first is None:
        raise CredcliError(f"{path}: no data rows (only blank or # comment lines)")
    names = None
    skip = first
    if not numeric_line(lines[first]):  # a header line
        names, skip = _fields(lines[first]), first + 1
    else:
        above = [ln for ln in lines[:first] if _comment(ln) and ln.strip("# \t")]
        if above and not numeric_line(above[-1].lstrip("#")):
            names = _fields(above[-1].lstrip("#"))
    probe = lines[skip] if skip < len(lines) else lines[first]
    sep = "," if "," in probe else r"\s+"
    try:
        frame = read_csv_unmapped(
            path,
            sep=sep,
            skiprows=skip,
            header=None,
            comment="#",
            skipinitialspace=True,
            skip_blank_lines=True,
            engine="c",
        )
    except pd.errors.EmptyDataError as exc:
        raise CredcliError(
            f"{path}: header has no rows below it; expected one row per epoch"
        ) from exc
    except (pd.errors.ParserError, UnicodeDecodeError, ValueError) as exc:
        first_line = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise CredcliError(f"{path}: cannot be read as a text table: {first_line}") from exc
    if names is not None:
        if len(names) != frame.shape[1]:
            raise CredcliError(
                f"{path}: the header names {len(names)} columns but the rows have "
                f"{frame.shape[1]}; check the separator (comma or whitespace) and the header"
            )
        frame.columns = names
    if len(frame) == 0:
        raise CredcliError(f"{path}: header has no rows below it; expected one row per epoch")
    return frame


def _comment(line: str) -> bool:
    return line.lstrip().startswith("#")


def _fields(line: str) -> list[str]:
    parts = line.split(",") if "," in line else line.split()
    return [p.strip() for p in parts]


# ------------------------------------------------------------------------- time units


_INTEGER_UNITS = ((1e17, TimeUnit.NS), (1e14, TimeUnit.US), (1e11, TimeUnit.MS))
"""Integer stamps at least this large are epoch times in this unit (1e11 s would be the
year 5138; epoch ns are about 1.7e18, µs 1.7e15, ms 1.7e12)."""


def decide_unit(raw: np.ndarray, unit: TimeUnit, native: TimeUnit | None, what: str):
    """(seconds per stamp unit, note) for stamps ``raw``: the given unit, the format's own
    (``native``), or by magnitude for integer stamps.

    With ``unit`` auto and no ``native`` unit, whole-number stamps whose largest magnitude
    is at least 1e17, 1e14 or 1e11 are epoch nanoseconds, microseconds or milliseconds
    (``_INTEGER_UNITS``); any other stamps are seconds.

    Parameters
    ----------
    raw : numpy.ndarray
        The stamps as read.
    unit : TimeUnit
        The unit given (``time_unit``); ``auto`` to decide.
    native : TimeUnit or None
        The format's own unit (nanoseconds for EuRoC and ROS CSV), taken under ``auto``.
    what : str
        The source, as the note names it.

    Returns
    -------
    scale : float
        Seconds per unit of ``raw``.
    note : str or None
        How the unit was decided; None when it was given, or when auto kept seconds.

    Examples
    --------
    >>> decide_unit(np.array([1.7e18, 1.7e18 + 1e6]), TimeUnit.AUTO, None, "t")[0]
    1e-09
    """
    unit = TimeUnit(unit)
    if unit is not TimeUnit.AUTO:
        return unit.seconds, None
    if native is not None:
        return native.seconds, f"{what}: stamps read as {native.value} (the format's unit)"
    finite = raw[np.isfinite(raw)]
    if finite.size and np.all(finite == np.round(finite)):
        peak = float(np.max(np.abs(finite)))
        for bound, candidate in _INTEGER_UNITS:
            if peak >= bound:
                return candidate.seconds, (
                    f"{what}: integer stamps near {peak:.3g} read as epoch {candidate.value} "
                    "(`time_unit` auto; give `time_unit` to override)"
                )
    return 1.0, None


def seconds(raw: np.ndarray, unit: TimeUnit, native: TimeUnit | None, what: str):
    """Stamps in seconds and the note on the unit decided (:func:`decide_unit`).

    Parameters
    ----------
    raw : numpy.ndarray
        The stamps as read.
    unit : TimeUnit
        The unit given (``time_unit``); ``auto`` to decide.
    native : TimeUnit or None
        The format's own unit, taken under ``auto``.
    what : str
        The source, as the note names it.

    Returns
    -------
    seconds : numpy.ndarray
        The stamps in seconds (``raw`` itself when they are seconds already).
    note : str or None
        How the unit was decided, or None.
    """
    scale, note = decide_unit(raw, unit, native, what)
    return raw * scale if scale != 1.0 else raw, note


# ------------------------------------------------------------------------ date-times


ISO_TIME_NOTE = (
    "{what}: date-times read as seconds since 1970-01-01 00:00 UTC (times without a zone "
    "taken as UTC)"
)
"""The note of a time column given as datetime64 or ISO-8601 strings."""


def time_seconds(values, what: str) -> tuple[np.ndarray, str | None]:
    """Seconds (float64) from numbers, numpy datetime64, pandas timestamps or ISO-8601
    strings, and the note to show when they were date-times (None for numbers).

    Date-times become seconds since the Unix epoch in UTC, rounded once to float64 (a
    resolution of 0.24 µs at today's dates); times without a zone are taken as UTC. A value
    that is neither a number nor a date-time is an error naming ``what`` and the first such
    value. Missing values are NaN.

    Parameters
    ----------
    values : array_like or pandas.Series, shape (N,)
        Numbers, datetime64, pandas timestamps, or ISO-8601 strings (numbers written as
        text are read as numbers).
    what : str
        The column's name, for the note and the error.

    Returns
    -------
    seconds : numpy.ndarray of float64, shape (N,)
        The times in seconds.
    note : str or None
        ``ISO_TIME_NOTE`` for date-times; None for numbers.

    Raises
    ------
    CredcliError
        If a value is neither a number nor an ISO-8601 date-time.

    Examples
    --------
    >>> t, note = time_seconds(["2024-05-01T12:00:00Z", "2024-05-01T12:00:00.25Z"], "time")
    >>> t - t[0], note is not None
    (array([0.  , 0.25]), True)
    >>> time_seconds(np.array([0.0, 0.1]), "time")[1] is None
    True
    """
    import pandas as pd

    array = values if isinstance(values, pd.Series) else np.asarray(values)
    dtype = array.dtype
    if pd.api.types.is_numeric_dtype(dtype) and not pd.api.types.is_bool_dtype(dtype):
        return np.asarray(array, dtype=float), None
    series = pd.Series(array)
    if not pd.api.types.is_datetime64_any_dtype(series.dtype):
        numbers = numbers_or_nan(series)
        if numbers.notna().sum() == series.notna().sum():
            return numbers.to_numpy(dtype=float, na_value=np.nan), None
    try:
        stamps = pd.to_datetime(series, utc=True, format="ISO8601")
    except (ValueError, TypeError, OverflowError):
        # the first value that is not a date-time, in one vectorised pass (not a parse per
        # row)
        coerced = pd.to_datetime(series, utc=True, format="ISO8601", errors="coerce")
        no_date = coerced.isna() & series.notna()
        wrong = np.flatnonzero(no_date.to_numpy())
        if not pd.api.types.is_datetime64_any_dtype(series.dtype):
            # a column of numbers with one word names the word (numbers among date-times,
            # the first number)
            words = np.flatnonzero((no_date & numbers.isna()).to_numpy())
            wrong = words if words.size else wrong
        shown = f" row {int(wrong[0]) + 1}: '{series.iloc[int(wrong[0])]}'" if wrong.size else ""
        raise CredcliError(
            f"{what}:{shown or ' a value'} is neither a number nor an ISO-8601 date-time such "
            "as 2024-05-01T12:00:00.25Z"
        ) from None
    nanoseconds = stamps.to_numpy(dtype="datetime64[ns]").astype(np.int64)
    # whole seconds and the fraction apart: one rounding, not two (ns as a float loses 256 ns)
    whole, fraction = np.divmod(nanoseconds, 1_000_000_000)
    seconds = whole.astype(float) + fraction / 1e9
    seconds[stamps.isna().to_numpy()] = np.nan
    return seconds, ISO_TIME_NOTE.format(what=what)


def numbers_or_nan(series):
    """``pd.to_numeric(series, errors="coerce")``: each cell as a float, NaN where it is not a
    number; an integer of more digits than a float holds is ±inf, not pandas' OverflowError
    (a CSV column of integers with one of 400 digits is read as Python ints).

    Parameters
    ----------
    series : pandas.Series
        Cells of any type.

    Returns
    -------
    pandas.Series
        Floats, of the same index.
    """
    import pandas as pd

    try:
        return pd.to_numeric(series, errors="coerce")
    except OverflowError:
        return pd.Series([_float_or_nan(v) for v in series], index=series.index, dtype=float)


def _float_or_nan(value) -> float:
    """One cell as a float (:func:`numbers_or_nan`'s rare path)."""
    try:
        return float(value)
    except OverflowError:  # an int beyond float64
        return math.inf if value > 0 else -math.inf
    except (TypeError, ValueError):
        return math.nan
