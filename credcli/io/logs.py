"""Reading estimator logs (CSV or Parquet) into one validated EstimatorLog.

The default column convention needs no options: ``time`` and ``segment`` (optional),
``truth_0 … truth_{d-1}``, ``est_0 … est_{d-1}`` and the claimed covariance as
``cov_i_j`` (full matrix or upper triangle), ``var_i`` or ``std_i``. A LogSchema maps
other layouts onto it.
"""

from __future__ import annotations

import codecs
import collections
import itertools
import re
import sys
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from credcli.engine.config import Perturbation
from credcli.engine.linalg import (
    CORRELATION_FLOOR,
    SYMMETRY_RTOL,
    epoch_chunks,
    index_range,
    per_epoch,
    smallest_correlation_eigenvalue,
)
from credcli.errors import CredcliError
from credcli.io.files import check_covariance_memory
from credcli.io.schema import CovKind, LogSchema, TimeUnit  # noqa: F401 (re-exported)
from credcli.io.streams import TEXT_HEAD, is_compressed, readable
from credcli.io.text import (
    numbers_or_nan,
    read_csv_unmapped,
    read_text_table,
    seconds,
    time_seconds,
)
from credcli.logid import LogId, unique_ids


@dataclass(frozen=True)
class OtherConvention:
    """The errors a pose log would have under the perturbation convention not used.

    Reading takes them; whether they fit the claimed covariance better is the engine's
    question ([convention_warning][credcli.engine.convention.convention_warning]).

    Attributes
    ----------
    used, other : Perturbation
        The convention the log's errors use, and the other one.
    errors : numpy.ndarray, shape (N, d)
        The same epochs' errors under ``other``.
    """

    used: Perturbation
    other: Perturbation
    errors: np.ndarray = field(repr=False)


@dataclass(frozen=True)
class EstimatorLog:
    """One log: truth and estimate (N, d), claimed covariance (N, d, d), optional time and
    segment (N,), and the file row number of each epoch (1-based data rows).

    Frozen. [credcli.read_log][credcli.api.read_log],
    [credcli.log_from_arrays][credcli.api.log_from_arrays] and
    [credcli.log_from_frame][credcli.api.log_from_frame] make it validated; the
    constructor itself checks nothing.

    Attributes
    ----------
    truth, estimate : numpy.ndarray, shape (N, d), or None
        The true and estimated states; None for a log of errors.
    cov : numpy.ndarray, shape (N, d, d)
        The claimed covariances.
    time : numpy.ndarray, shape (N,), or None
        Time stamps in seconds.
    segment : numpy.ndarray, shape (N,), or None
        Each epoch's segment name.
    rows : numpy.ndarray, shape (N,)
        The file row number of each epoch (1-based data rows; 1 … N when not given).
    id : LogId
        Which log this is ([LogId][credcli.logid.LogId]): the file it was read from, its
        name in messages and records, and the stem and label of its figures.
    dropped_rows : int
        Rows dropped as invalid (``drop_invalid``).
    state_errors : numpy.ndarray, shape (N, d), or None
        Errors that are not a difference of vectors (orientations on SO(3), a filter's
        innovations): such logs have no truth or estimate.
    notes : tuple of str
        The decisions taken while reading (unit, format, pairing, convention).
    unpaired : int
        The estimate epochs dropped for want of truth.
    blocks : tuple of (str, tuple of int)
        Named parts of the state whose scale is reported on its own (position and
        orientation of a pose, ``credcli.engine.lie.STATE_BLOCKS``).
    run : numpy.ndarray, shape (N,), or None
        The Monte Carlo run of each epoch when the log pools several
        (``credcli.segments.split_runs``).
    fitted_mean : str or None
        Why the mean of the whole log's errors is no evidence (an alignment fitted it to
        0), or None.
    other_convention : OtherConvention or None
        A pose log's errors under the other perturbation convention, kept from reading
        until the convention check ([checked_log][credcli.segments.checked_log]) has
        compared them; None otherwise.

    Examples
    --------
    >>> from credcli import log_from_arrays
    >>> log = log_from_arrays(np.zeros((5, 2)), np.ones((5, 2)), np.eye(2), time=np.arange(5.0))
    >>> log.n, log.dim, log.errors[0].tolist(), log.rows.tolist()
    (5, 2, [-1.0, -1.0], [1, 2, 3, 4, 5])
    """

    truth: np.ndarray | None
    estimate: np.ndarray | None
    cov: np.ndarray
    time: np.ndarray | None = None
    segment: np.ndarray | None = None
    rows: np.ndarray = field(default=None, repr=False)  # type: ignore[assignment]
    id: LogId = LogId.of("<memory>")
    dropped_rows: int = 0
    state_errors: np.ndarray | None = field(default=None, repr=False)
    notes: tuple[str, ...] = ()
    unpaired: int = 0
    blocks: tuple[tuple[str, tuple[int, ...]], ...] = ()  # named blocks of the state
    run: np.ndarray | None = field(default=None, repr=False)  # Monte Carlo run id per epoch
    # why the mean of the whole log's errors is no evidence (an alignment fitted it to 0)
    fitted_mean: str | None = None
    other_convention: OtherConvention | None = field(default=None, repr=False)

    def __post_init__(self) -> None:
        if self.rows is None:
            object.__setattr__(self, "rows", index_range(1, self.cov.shape[0] + 1))

    @property
    def source(self) -> str:
        """The log's name in messages and records (``str(log.id)``)."""
        return self.id.name

    @property
    def errors(self) -> np.ndarray:
        """The errors e_k = x_k − x̂_k, (N, d) (or the state errors given)."""
        if self.state_errors is not None:
            return self.state_errors
        return self.truth - self.estimate

    @property
    def n(self) -> int:
        """The number of epochs N."""
        return self.cov.shape[0]

    @property
    def dim(self) -> int:
        """The state dimension d."""
        return self.cov.shape[1]


def with_unique_ids(logs: list[EstimatorLog]) -> list[EstimatorLog]:
    """The logs of one command with ids no two share (:func:`credcli.logid.unique_ids`:
    stems, and so figure names, told apart by parent directories, else numbered).

    Parameters
    ----------
    logs : list of EstimatorLog
        The logs, in the order the command was given them.

    Returns
    -------
    list of EstimatorLog
        The same logs (their arrays not copied), each with its id made unique.
    """
    ids = unique_ids([log.id for log in logs])
    return [log if log.id == i else replace(log, id=i) for log, i in zip(logs, ids, strict=True)]


def load_log(
    path: str | Path,
    schema: LogSchema | None = None,
    drop_invalid: bool = False,
    time_unit: TimeUnit = TimeUnit.AUTO,
    innovations: bool = False,
    errors_only: bool | None = None,
) -> EstimatorLog:
    """Read and validate an estimator log from CSV, whitespace-separated text or Parquet.

    The file may be an fsspec URL (:func:`as_url`); a local Parquet file is read one column
    at a time (:class:`ParquetColumns`). A compressed file or a stream is read through
    :func:`credcli.io.ingest.open_log`, which decompresses it first. The table is validated
    by :func:`log_from_frame`.

    Parameters
    ----------
    path : str or pathlib.Path
        The log file, or an fsspec URL (``s3://bucket/log.parquet``).
    schema : LogSchema, optional
        The column names; default ``LogSchema()``, the default convention.
    drop_invalid : bool, default False
        Drop the rows with a NaN, Inf or empty value (counted in ``dropped_rows``) rather
        than refuse the log.
    time_unit : TimeUnit, default TimeUnit.AUTO
        The unit of the time column; ``auto`` decides from its format and magnitude.
    innovations : bool, default False
        The log holds a filter's innovations ``innov_i`` and their covariance
        ``innov_cov_i_j`` (or ``innov_var_i``, ``innov_std_i``) instead of truth and
        estimate.
    errors_only : bool or None, default None
        The log holds errors (``err_i``, or the columns ``schema.truth_columns`` names);
        None: so when it has ``err_0`` and no truth or estimate.

    Returns
    -------
    EstimatorLog
        The validated log; its id names ``path`` as given (the URL for a URL).

    Raises
    ------
    CredcliError
        Naming the file, row and column of the first problem: a missing or empty file,
        missing columns, a non-numeric cell, NaN/Inf (unless ``drop_invalid``), an
        asymmetric or non-positive-definite covariance, mismatched dimensions.
    """
    url = as_url(path)
    path = Path(path)
    schema = schema or LogSchema()
    frame = read_table(path, columnwise=True)
    if url is None:
        frame = _names_as_written(frame, path, (schema.segment, schema.run))
    name = url or str(path)
    log = log_from_frame(frame, schema, name, drop_invalid, time_unit, innovations, errors_only)
    return replace(log, id=LogId.of(name, name))


def _names_as_written(frame, path: Path, columns: tuple[str, ...]):
    r"""``frame`` with its segment and run names as a plain CSV file writes them.

    pandas reads "NA", "NaN", "None", "null", "N/A" and the like as missing in every
    column; in a name column they are names (a region "NA", a mode "None"), and only an
    empty cell is missing. Such a column is read again as text, empty cells alone missing.
    Other files (Parquet keeps its strings; text tables, compressed files) are returned as
    they are.

    Examples
    --------
    >>> import tempfile, pandas as pd
    >>> with tempfile.TemporaryDirectory() as d:
    ...     p = Path(d) / "log.csv"
    ...     _ = p.write_text("time,segment\n0,NA\n1,\n2,b\n")
    ...     _names_as_written(pd.read_csv(p), p, ("segment", "run"))["segment"].tolist()
    ['NA', nan, 'b']
    """
    pandas = sys.modules.get("pandas")  # a DataFrame needs it imported: never import it here
    if pandas is None or not isinstance(frame, pandas.DataFrame):
        return frame  # Parquet, read a column at a time: its strings kept
    if frame.columns.has_duplicates:  # a repeated name: log_from_frame names it
        return frame
    redo = [c for c in columns if c in frame.columns and frame[c].isna().any()]
    if not redo or path.suffix.lower() in (".parquet", ".pq") or not _plain_csv(path):
        return frame
    text = read_csv_unmapped(
        path,
        usecols=redo,
        dtype=str,
        keep_default_na=False,
        na_values=[""],
        skipinitialspace=True,
    )
    if len(text) != len(frame):  # not the table read before: leave it to the checks
        return frame
    return frame.assign(**{c: text[c].to_numpy(dtype=object) for c in redo})


ERRORS_SCHEMA = {"truth_prefix": "err_"}
"""The column prefix of an errors-only log: a library's own error vectors, e_k = err_k."""

INNOVATION_SCHEMA = {
    "truth_prefix": "innov_",
    "cov_prefix": "innov_cov_",
    "var_prefix": "innov_var_",
    "std_prefix": "innov_std_",
}
"""The column prefixes of an innovations log (--innovations)."""


class ParquetColumns:
    """A Parquet file read one column at a time: the loader never holds the file's whole
    table and its numeric copy at once, as ``pandas.read_parquet`` would.

    Numeric and string columns are read through Arrow's buffers (:meth:`floats`,
    :meth:`labels`), without pandas: importing it, which Arrow's ``to_numpy`` does, would
    delay a command's start. Columns of other types are pandas Series (item access), whose
    cells the loader checks one by one.

    Parameters
    ----------
    path : pathlib.Path
        A local Parquet file.

    Attributes
    ----------
    path : pathlib.Path
        The file.
    columns : list of str
        Its column names, in the file's order.
    """

    def __init__(self, path: Path) -> None:
        import pyarrow.parquet as pq

        self.path = path
        self._file = pq.ParquetFile(path)
        self.columns = list(self._file.schema_arrow.names)
        self._rows = self._file.metadata.num_rows

    def __len__(self) -> int:
        return self._rows

    def __getitem__(self, column: str):
        return self._read(column).to_pandas()

    def _read(self, column: str, dictionary: bool = False):
        """The column as an Arrow ChunkedArray; with ``dictionary``, a string column comes
        as Parquet stores it, dictionary-encoded per row group, and is not decoded into a
        string per row and encoded again."""
        import pyarrow as pa
        import pyarrow.parquet as pq

        pa.default_memory_pool().release_unused()  # the columns read before, now copied
        try:
            source = (
                pq.ParquetFile(self.path, read_dictionary=[column]) if dictionary else self._file
            )
            return source.read(columns=[column]).column(0)
        except (OSError, ValueError) as exc:  # pyarrow's errors derive from these
            first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
            raise CredcliError(f"{self.path}: column '{column}' cannot be read: {first}") from exc

    def floats(self, column: str, out: np.ndarray) -> bool:
        """Write an integer or floating-point column into ``out`` as float64.

        Nulls become NaN (as pandas' ``to_numpy(float)`` does); integers beyond 2^53 round.

        Parameters
        ----------
        column : str
            The column's name.
        out : numpy.ndarray, shape (N,)
            Where the values go (a float64 array or view, N the file's rows).

        Returns
        -------
        bool
            True when written; False, with nothing written, for a column of any other type.

        Raises
        ------
        CredcliError
            The column cannot be read.
        """
        import pyarrow as pa

        data = self._read(column)
        if not (pa.types.is_integer(data.type) or pa.types.is_floating(data.type)):
            return False
        start = 0
        for chunk in data.chunks:
            if chunk.type != pa.float64():
                import pyarrow.compute as pc  # only here: slow to import, rarely needed

                chunk = pc.cast(chunk, pa.float64(), safe=False)  # integers beyond 2^53 round
            size = len(chunk)
            out[start : start + size] = _buffer_values(chunk, np.float64)
            if chunk.null_count:
                out[start : start + size][~_valid(chunk)] = np.nan
            start += size
        return True

    def labels(self, column: str) -> tuple[np.ndarray, np.ndarray] | None:
        """A string column (or a dictionary of strings, as pandas writes a categorical).

        Each distinct value of a row group is converted to a Python string once, from the
        dictionary the file stores, not once per row.

        Parameters
        ----------
        column : str
            The column's name.

        Returns
        -------
        tuple of (numpy.ndarray, numpy.ndarray) or None
            An object array of its values, shape (N,) ("" where null), and a boolean array
            of the rows where it is null, shape (N,); None for a column of any other type.

        Raises
        ------
        CredcliError
            The column cannot be read.
        """
        import pyarrow as pa

        kind = self._file.schema_arrow.field(column).type
        if pa.types.is_dictionary(kind):
            kind = kind.value_type
        if not (pa.types.is_string(kind) or pa.types.is_large_string(kind)):
            return None
        values, nulls = [], []
        for chunk in self._read(column, dictionary=True).chunks:
            names = np.array(chunk.dictionary.to_pylist() + [""], dtype=object)
            indices = chunk.indices  # signed or unsigned integers of any width
            width = "i" if pa.types.is_signed_integer(indices.type) else "u"
            width += str(indices.type.bit_width // 8)
            codes = _buffer_values(indices, np.dtype(width)).astype(np.int64)
            missing = ~_valid(indices) if indices.null_count else np.zeros(codes.size, bool)
            codes[missing] = -1  # the "" after the names
            values.append(names[codes])
            nulls.append(missing)
        if not values:
            return np.empty(0, dtype=object), np.zeros(0, dtype=bool)
        return np.concatenate(values), np.concatenate(nulls)


def _valid(array) -> np.ndarray:
    """Which entries of an Arrow array are not null, from its validity bitmap (Arrow's own
    conversions import pandas, and ``pyarrow.compute.fill_null`` does too)."""
    bits = np.frombuffer(array.buffers()[0], dtype=np.uint8)
    return np.unpackbits(bits, bitorder="little")[array.offset : array.offset + len(array)] == 1


def _buffer_values(array, dtype) -> np.ndarray:
    """The values of an Arrow array of fixed-width numbers (whatever its nulls hold), as a
    read-only view of its data buffer."""
    return np.frombuffer(
        array.buffers()[1],
        dtype=dtype,
        count=len(array),
        offset=array.offset * np.dtype(dtype).itemsize,
    )


_URL = re.compile(r"^([a-z][a-z0-9+.-]+):/+(.*)$")


def as_url(path) -> str | None:
    """``path`` as an fsspec URL (``s3://bucket/log.parquet``, ``file:///data/log.csv``).

    A URL that went through pathlib lost a slash; it is put back. A one-letter scheme is a
    Windows drive (``C:/``), not a URL.

    Parameters
    ----------
    path : str or pathlib.Path
        A path or URL.

    Returns
    -------
    str or None
        The URL, or None for a local path.

    Examples
    --------
    >>> as_url(Path("s3://bucket/log.parquet")), as_url("data/log.csv")
    ('s3://bucket/log.parquet', None)
    """
    m = _URL.match(str(path))
    if not m or len(m.group(1)) < 2:  # C:/ on Windows is a drive, not a scheme
        return None
    rest = m.group(2)
    return f"{m.group(1)}://{'/' if m.group(1) == 'file' else ''}{rest}"


def _read_url(url: str):
    """A CSV or Parquet log at an fsspec URL (the filesystem's package must be installed,
    e.g. s3fs for s3://)."""
    import pandas as pd

    try:
        if url.lower().endswith((".parquet", ".pq")):
            frame = pd.read_parquet(url)
        else:
            frame = pd.read_csv(url, skipinitialspace=True)
    except ImportError as exc:
        raise CredcliError(f"{url}: reading this URL needs its fsspec filesystem: {exc}") from exc
    except FileNotFoundError as exc:
        raise CredcliError(f"{url}: file not found") from exc
    except (
        pd.errors.ParserError,
        pd.errors.EmptyDataError,
        UnicodeDecodeError,
        OSError,
        ValueError,
    ) as exc:
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise CredcliError(f"{url}: cannot be read as CSV/Parquet: {first}") from exc
    if len(frame) == 0:
        raise CredcliError(f"{url}: header has no rows below it; expected one row per epoch")
    return frame


def read_table(path: Path, columnwise: bool = False):
    """The table of a CSV, text or Parquet file (or fsspec URL).

    Parameters
    ----------
    path : pathlib.Path
        The file (compressed or not), or an fsspec URL.
    columnwise : bool, default False
        Read a local Parquet file as a :class:`ParquetColumns` (columns read on use,
        without pandas). Without it, a compressed file is read through its decompressed
        copy (``credcli.io.streams.readable``).

    Returns
    -------
    pandas.DataFrame or ParquetColumns
        The table, with at least one row.

    Raises
    ------
    CredcliError
        The file is missing, a directory, empty, UTF-16 or binary text, cannot be parsed,
        or has a header and no rows.
    """
    url = as_url(path)
    if url is not None:
        return _read_url(url)

    if not path.exists():
        raise CredcliError(f"{path}: file not found")
    if path.is_dir():
        raise CredcliError(f"{path}: is a directory, expected a CSV or Parquet file")
    if path.stat().st_size == 0:
        raise CredcliError(f"{path}: file is empty; expected a header row and epoch rows")
    if not columnwise and is_compressed(path):  # read directly, not through an ingest copy
        with readable(path) as local:
            return read_table(local)
    if path.suffix.lower() not in (".parquet", ".pq"):
        _check_text(path)
    if columnwise and path.suffix.lower() in (".parquet", ".pq"):
        try:
            frame = ParquetColumns(path)
        except (OSError, ValueError) as exc:  # pyarrow's errors derive from these
            raise _unreadable(path, exc) from exc
    else:
        frame = _read_frame(path)
    if len(frame) == 0:
        raise CredcliError(f"{path}: header has no rows below it; expected one row per epoch")
    return frame


def _check_text(path: Path) -> None:
    """A text log is UTF-8 (or ASCII) without NUL bytes: UTF-16, with or without its
    byte-order mark, and binary data are named, not misread as columns."""
    with open(path, "rb") as fh:
        head = fh.read(TEXT_HEAD)
    if not head:
        return
    zeros = head.count(b"\x00") / len(head)
    marked = head[:2] in (b"\xff\xfe", b"\xfe\xff")
    if marked or 0.3 < zeros < 0.7:
        how = "" if marked else " without a byte-order mark"
        raise CredcliError(
            f"{path}: is UTF-16 text{how}; save it as UTF-8 (e.g. iconv -f UTF-16 -t UTF-8)"
        )
    if zeros:
        raise CredcliError(
            f"{path}: holds binary data (NUL bytes), not CSV or text; give a CSV, text, "
            "Parquet file or a ROS bag"
        )


def _read_frame(path: Path):
    """A local CSV, text or Parquet file as a pandas DataFrame."""
    import pandas as pd

    try:
        if path.suffix.lower() in (".parquet", ".pq"):
            return pd.read_parquet(path)
        if _plain_csv(path):
            return read_csv_unmapped(path, skipinitialspace=True)
        return read_text_table(path)
    except pd.errors.EmptyDataError as exc:
        raise CredcliError(f"{path}: file is empty; expected a header row and epoch rows") from exc
    except (pd.errors.ParserError, UnicodeDecodeError, OSError, ValueError) as exc:
        raise _unreadable(path, exc) from exc


def _unreadable(path: Path, exc: Exception) -> CredcliError:
    if isinstance(exc, UnicodeDecodeError):
        where = _first_non_utf8(path)
        if where is not None:
            line, byte = where
            return CredcliError(
                f"{path}: line {line}: byte 0x{byte:02x} is not UTF-8 text; save the file as "
                "UTF-8 (e.g. iconv -f LATIN1 -t UTF-8, for Latin-1 text)"
            )
    first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
    return CredcliError(f"{path}: cannot be read as CSV/Parquet: {first}")


def _first_non_utf8(path: Path) -> tuple[int, int] | None:
    """The line (from 1) and value of the file's first byte that is not UTF-8, read a
    megabyte at a time; None where there is none (or the file cannot be read again).
    pandas' own error gives the byte's position in its read buffer, not in the file."""
    decoder = codecs.getincrementaldecoder("utf-8")()
    lines = 1
    try:
        with open(path, "rb") as fh:
            while True:
                chunk = fh.read(1 << 20)
                try:
                    decoder.decode(chunk, final=not chunk)
                except UnicodeDecodeError as exc:
                    # exc.object is the chunk behind the (at most 3) bytes held from the last
                    held = len(exc.object) - len(chunk)
                    before = chunk[: max(0, exc.start - held)]
                    return lines + before.count(b"\n"), exc.object[exc.start]
                if not chunk:
                    return None
                lines += chunk.count(b"\n")
    except OSError:
        return None


def _plain_csv(path: Path) -> bool:
    """Whether the file starts with a comma-separated header line (not a # line)."""
    with open(path, "rb") as fh:
        first = fh.readline(65536).decode("utf-8", errors="replace")
    return "," in first and not first.lstrip().startswith("#")


_ORIENTATION_NAME = re.compile(
    r"(^|[^a-z0-9])(q_?[wxyz]|(quat|quaternion|orientation|rotation)[._]?[wxyz])$", re.I
)


def check_not_orientation(columns, source: str) -> None:
    """Refuse quaternion components by name rather than diagnose them as a vector.

    Names such as qw, q_x, quat_z, orientation.w and rotation_x are refused; other names
    with "rotation" or "orientation" in them (rotation_rate) are left alone.

    Parameters
    ----------
    columns : iterable of str
        The state columns.
    source : str
        The log's name in the message.

    Raises
    ------
    CredcliError
        Some column looks like a quaternion component.
    """
    named = [c for c in columns if _ORIENTATION_NAME.search(str(c))]
    if named:
        raise CredcliError(
            f"{source}: column(s) {', '.join(named)} look like orientation (quaternion) "
            "components, which are not a vector; read the file as a pose (`input_format` "
            "tum/euroc/ros-csv with `truth`) and choose `states` orientation or pose"
        )


_INDEXED = re.compile(r"^(\d+)$")
_MANGLED = re.compile(r"^(.*)\.(\d+)$")


def _mangled(columns: list[str]) -> set[str]:
    """Names pandas renamed because they were repeated in a CSV header ('x' and 'x.1')."""
    present = set(columns)
    out = set()
    for col in columns:
        m = _MANGLED.match(col)
        if m and m.group(1) in present:
            out.add(m.group(1))
    return out


_PAIR = re.compile(r"^(\d+)_(\d+)$")


def _indexed(columns, prefix: str) -> dict[int, str]:
    found = {}
    for col in columns:
        if col.startswith(prefix):
            m = _INDEXED.match(col[len(prefix) :])
            if m:
                found[int(m.group(1))] = col
    return found


def vector_columns(columns, prefix: str, explicit, what: str, source: str) -> list[str]:
    """The columns of a state vector: those named, else ``prefix`` 0 … d−1.

    Parameters
    ----------
    columns : list of str
        The table's columns.
    prefix : str
        The columns' prefix (``truth_``, ``est_``, …), followed by the component's index.
    explicit : sequence of str or None
        The columns by name; when given, they are returned as they are.
    what : str
        What the vector is ("truth", "estimate", "error", "innovation"), for messages.
    source : str
        The log's name in messages.

    Returns
    -------
    list of str
        The d columns, in the order of the components.

    Raises
    ------
    CredcliError
        No column has the prefix (an innovations log read without ``innovations`` is named
        as such), or an index between 0 and the largest one is missing.
    """
    if explicit:
        return list(explicit)
    found = _indexed(columns, prefix)
    if not found and _indexed(columns, "innov_") and prefix != "innov_":
        raise CredcliError(
            f"{source}: no {what} columns, but innovations (innov_0, …): a filter's "
            "innovations log is read with `innovations` (NIS, no ground truth)"
        )
    if not found:
        alone = " (a log of errors alone: `errors_only`)" if what == "estimate" else ""
        raise CredcliError(
            f"{source}: no {what} columns ({prefix}0, {prefix}1, …) found; columns found: "
            f"{_list(columns)}. Name them with the column options or a [columns] config"
            f"{alone}"
        )
    d = max(found) + 1
    if d > len(found):  # a gap: counted, never listed one by one (truth_1000000000000)
        missing = [f"{prefix}{i}" for i in range(min(d, len(found) + 5)) if i not in found]
        more = d - len(found) - len(missing)
        shown = ", ".join(missing) + (f", … ({d - len(found):,} in all)" if more > 0 else "")
        raise CredcliError(f"{source}: missing {what} column(s) {shown}")
    return [found[i] for i in range(d)]


def _list(columns) -> str:
    cols = list(columns)
    text = ", ".join(str(c) for c in cols[:30])
    return text + (f", … ({len(cols)} in all)" if len(cols) > 30 else "")


def cov_layout(columns, schema: LogSchema, d: int, source: str) -> tuple[CovKind, list[str]]:
    """Which covariance columns to read, and how.

    Named columns (``schema.cov_columns``) are read by ``schema.cov_kind``, else by their
    number: d² full, d(d+1)/2 upper triangle, d diagonal (variances). Otherwise the
    columns are found by prefix: ``cov_i_j`` for every i, j (full) or for i <= j (upper),
    else ``var_i``, else ``std_i``; a ``cov_kind`` given must then name that layout.

    Parameters
    ----------
    columns : list of str
        The table's columns.
    schema : LogSchema
        The column names and prefixes.
    d : int
        The state dimension.
    source : str
        The log's name in messages.

    Returns
    -------
    tuple of (CovKind, list of str)
        The layout and its columns, in the order :func:`build_cov` takes them.

    Raises
    ------
    CredcliError
        The named columns do not fit d or ``cov_kind``; a ``cov_i_j`` index is beyond d;
        both ``cov_i_j`` and ``var_i``/``std_i`` columns, or both ``var_i`` and ``std_i``
        columns, are present; ``cov_kind`` is not the layout of the columns found by
        prefix; the ``cov_i_j`` are neither full nor an upper triangle; the
        ``var_i``/``std_i`` do not match d; no covariance column is found.
    """
    if schema.cov_columns:
        cols = list(schema.cov_columns)
        by_len = {d * d: CovKind.FULL, d * (d + 1) // 2: CovKind.UPPER, d: CovKind.VAR}
        if d == 1:
            kind = schema.cov_kind or CovKind.VAR
        elif schema.cov_kind is not None:
            kind = schema.cov_kind
        elif len(cols) in by_len:
            kind = by_len[len(cols)]
        else:
            raise CredcliError(
                f"{source}: {len(cols)} covariance columns given for d = {d}; expected "
                f"{d * d} (full), {d * (d + 1) // 2} (upper triangle) or {d} (diagonal)"
            )
        expected = {CovKind.FULL: d * d, CovKind.UPPER: d * (d + 1) // 2}.get(kind, d)
        if len(cols) != expected:
            raise CredcliError(
                f"{source}: {len(cols)} covariance columns given but a {kind.value} "
                f"covariance for d = {d} needs {expected}"
            )
        return kind, cols
    kind, cols = _found_layout(columns, schema, d, source)
    if schema.cov_kind is not None and schema.cov_kind is not kind:
        raise CredcliError(
            f"{source}: `cov_kind` {schema.cov_kind.value} does not describe the covariance "
            f"columns found ({_list(cols)}, read as {kind.value}); name the columns "
            "with `cov_columns`, or drop `cov_kind`"
        )
    return kind, cols


def _found_layout(columns, schema: LogSchema, d: int, source: str) -> tuple[CovKind, list[str]]:
    """The covariance columns found by their prefixes, and how they store it
    (:func:`cov_layout` without named columns)."""
    pairs = {}
    for col in columns:
        if col.startswith(schema.cov_prefix):
            m = _PAIR.match(col[len(schema.cov_prefix) :])
            if m:
                pairs[(int(m.group(1)), int(m.group(2)))] = col
    if pairs:
        bad = sorted(p for p in pairs if max(p) >= d)
        if bad:
            i, j = bad[0]
            raise CredcliError(
                f"{source}: column {pairs[bad[0]]} refers to index {max(i, j)} but the "
                f"truth/estimate have d = {d}: dimensions do not match"
            )
        others = [
            c
            for prefix in (schema.var_prefix, schema.std_prefix)
            for c in _indexed(columns, prefix).values()
        ]
        if others:
            raise CredcliError(
                f"{source}: both {schema.cov_prefix}i_j and {', '.join(map(str, others[:4]))} "
                "columns: which is the covariance? Name its columns with `cov_columns`"
            )
        full = [(i, j) for i in range(d) for j in range(d)]
        upper = [(i, j) for i in range(d) for j in range(i, d)]
        if all(p in pairs for p in full):
            return CovKind.FULL, [pairs[p] for p in full]
        if all(p in pairs for p in upper):
            return CovKind.UPPER, [pairs[p] for p in upper]
        missing = [f"{schema.cov_prefix}{i}_{j}" for i, j in upper if (i, j) not in pairs]
        raise CredcliError(
            f"{source}: incomplete covariance: missing column(s) {', '.join(missing)} "
            f"(give cov_i_j for every i, j or for i <= j)"
        )
    variances, deviations = (_indexed(columns, p) for p in (schema.var_prefix, schema.std_prefix))
    if variances and deviations:
        shown = [*list(variances.values())[:2], *list(deviations.values())[:2]]
        raise CredcliError(
            f"{source}: both {schema.var_prefix}i and {schema.std_prefix}i columns "
            f"({', '.join(map(str, shown))}, …): which is the covariance? Name its columns "
            "with `cov_columns`"
        )
    for kind, prefix in ((CovKind.VAR, schema.var_prefix), (CovKind.STD, schema.std_prefix)):
        found = _indexed(columns, prefix)
        if found:
            if max(found) + 1 != d or len(found) != d:
                raise CredcliError(
                    f"{source}: {prefix}* columns {sorted(found)} do not match d = {d} "
                    f"(expected {prefix}0 … {prefix}{d - 1}): dimensions do not match"
                )
            return kind, [found[i] for i in range(d)]
    raise CredcliError(
        f"{source}: no covariance columns found (cov_i_j, var_i or std_i); columns found: "
        f"{_list(columns)}"
    )


def log_from_frame(
    frame,
    schema: LogSchema,
    source: str = "<frame>",
    drop_invalid=False,
    time_unit: TimeUnit = TimeUnit.AUTO,
    innovations: bool = False,
    errors_only: bool | None = None,
):
    """Validate a pandas DataFrame into an EstimatorLog (see :func:`load_log`).

    Each group of columns (truth, estimate, covariance, time) is read straight into its own
    float64 array; the covariances are built (:func:`build_cov`) and checked
    (:func:`validated_cov`).

    Parameters
    ----------
    frame : pandas.DataFrame or ParquetColumns
        The table, one row per epoch. Its column names are made strings (in place, for a
        DataFrame).
    schema : LogSchema
        The column names.
    source : str, default "<frame>"
        The log's name in messages, notes and its id.
    drop_invalid : bool, default False
        Drop the rows with a NaN, Inf or empty value rather than refuse the log.
    time_unit : TimeUnit, default TimeUnit.AUTO
        The unit of a numeric time column; ``auto`` decides from its magnitude. Date-times
        become seconds since the Unix epoch.
    innovations : bool, default False
        The table holds a filter's innovations ``innov_i`` and their covariance instead of
        truth and estimate.
    errors_only : bool or None, default None
        The log holds errors ``err_i`` (or the columns ``schema.truth_columns`` names) and
        no truth or estimate; None: so when it has ``err_0`` and no ``truth_`` or ``est_``
        columns.

    Returns
    -------
    EstimatorLog
        The validated log (errors and innovations as its ``state_errors``), with the notes
        of the decisions taken (time unit, errors-only, symmetrised covariances).

    Raises
    ------
    CredcliError
        A repeated column name; missing or mismatched state, covariance, time, segment or
        run columns; a cell that is not a number; NaN/Inf (unless ``drop_invalid``; then
        when every row has one); a negative standard deviation; a covariance that is not symmetric or
        not positive definite; an empty segment or run cell.
    """
    columns = [str(c) for c in frame.columns]
    frame.columns = columns
    counts = collections.Counter(columns)  # linear: a header may have 10⁶ columns
    repeated = sorted({c for c, k in counts.items() if k > 1} | _mangled(columns))
    if repeated:
        raise CredcliError(
            f"{source}: column(s) {', '.join(repeated)} appear more than once in the header; "
            "each column name must be unique"
        )
    if errors_only is None:
        errors_only = _errors_layout(columns, schema) and not innovations
    if innovations or errors_only:
        schema = replace(schema, **(INNOVATION_SCHEMA if innovations else ERRORS_SCHEMA))
        truth_cols = vector_columns(
            columns,
            schema.truth_prefix,
            schema.truth_columns,
            "innovation" if innovations else "error",
            source,
        )
        est_cols = []
    else:
        truth_cols = vector_columns(
            columns, schema.truth_prefix, schema.truth_columns, "truth", source
        )
        est_cols = vector_columns(
            columns, schema.estimate_prefix, schema.estimate_columns, "estimate", source
        )
    check_not_orientation(truth_cols + est_cols, source)
    if len(truth_cols) != len(est_cols) and not (innovations or errors_only):
        if not (schema.truth_columns or schema.estimate_columns):
            short, prefix, what = (
                (est_cols, schema.estimate_prefix, "estimate")
                if len(est_cols) < len(truth_cols)
                else (truth_cols, schema.truth_prefix, "truth")
            )
            d = max(len(truth_cols), len(est_cols))
            missing = ", ".join(f"{prefix}{i}" for i in range(len(short), d))
            raise CredcliError(
                f"{source}: missing {what} column(s) {missing}: truth and estimate must both "
                f"have d = {d} columns (dimensions do not match)"
            )
        raise CredcliError(
            f"{source}: {len(truth_cols)} truth columns but {len(est_cols)} estimate columns: "
            "dimensions do not match"
        )
    d = len(truth_cols)
    kind, cov_cols = cov_layout(columns, schema, d, source)
    time_col = schema.time if schema.time in columns else None
    explicit_time = schema.time != LogSchema.time
    if explicit_time and time_col is None:
        raise CredcliError(
            f"{source}: time column '{schema.time}' not found; columns found: {_list(columns)}"
        )
    seg_col = schema.segment if schema.segment in columns else None
    if schema.segment != LogSchema.segment and seg_col is None:
        raise CredcliError(
            f"{source}: segment column '{schema.segment}' not found; columns found: {_list(columns)}"
        )
    numeric_cols = truth_cols + est_cols + cov_cols + ([time_col] if time_col else [])
    time_note = None
    missing = [c for c in numeric_cols if c not in columns]
    if missing:
        raise CredcliError(
            f"{source}: missing column(s) {', '.join(missing)}; columns found: {_list(columns)}"
        )
    # each group of columns straight into its own array: no whole-table copy beside them
    n = len(frame)
    check_covariance_memory(n, d, source)  # d variance columns make N·d² numbers
    blocks = [np.empty((n, len(cols))) for cols in (truth_cols, est_cols, cov_cols)]
    if time_col:
        blocks.append(np.empty((n, 1)))
    for block, cols in zip(blocks, (truth_cols, est_cols, cov_cols)):
        numeric_columns(frame, cols, source, out=block)
    if time_col:
        time_note = _time_column(frame, time_col, source, blocks[3][:, 0])
    rows = index_range(1, n + 1)
    bad = np.zeros(n, dtype=bool)
    for block in blocks:
        bad |= ~per_epoch(np.logical_and, np.isfinite(block))
    dropped = 0
    if bad.any():
        if not drop_invalid:
            bad_rows = rows[bad]
            shown = ", ".join(str(r) for r in bad_rows[:10])
            more = f" and {bad_rows.size - 10} more" if bad_rows.size > 10 else ""
            first_row = np.concatenate([block[bad_rows[0] - 1] for block in blocks])
            first_col = numeric_cols[int(np.argmax(~np.isfinite(first_row)))]
            raise CredcliError(
                f"{source}: NaN, Inf or empty value in row(s) {shown}{more} (first in column "
                f"'{first_col}'); fix them or pass `drop_invalid` to drop those rows"
            )
        dropped = int(bad.sum())
        blocks, rows = [block[~bad] for block in blocks], rows[~bad]
        if rows.size == 0:
            raise CredcliError(f"{source}: every row has a NaN/Inf value; nothing left to diagnose")
    truth, estimate, cov_values = blocks[:3]
    cov_notes: list[str] = []
    cov = validated_cov(build_cov(cov_values, kind, d), rows, source, kind, notes=cov_notes)
    if kind is CovKind.STD:
        negative = per_epoch(np.logical_or, cov_values < 0)
        if negative.any():
            i = int(np.argmax(negative))
            raise CredcliError(
                f"{source}: row {rows[i]}: a standard deviation (std_i column) is negative; "
                "standard deviations must be >= 0"
            )
    del cov_values
    if schema.run != LogSchema.run and schema.run not in columns:
        raise CredcliError(
            f"{source}: run column '{schema.run}' not found; columns found: {_list(columns)}"
        )
    run = None
    if schema.run in columns:
        run_values, missing_run = _labels(frame, schema.run)
        if missing_run.any():
            first = int(np.argmax(missing_run)) + 1
            raise CredcliError(
                f"{source}: run column '{schema.run}' is empty or NA in row {first}; give "
                "every epoch its Monte Carlo run"
            )
        run = run_values[rows - 1]
    segment = None
    if seg_col is not None:
        seg_values, missing_seg = _labels(frame, seg_col)
        if missing_seg.any():
            first = int(np.argmax(missing_seg)) + 1
            raise CredcliError(
                f"{source}: segment column '{seg_col}' is empty or NA in {int(missing_seg.sum())} "
                f"row(s), first in row {first}; fill in the segment names, or name another "
                "column with `segment_column`"
            )
        segment = seg_values[rows - 1]
    estimate = None if innovations else estimate
    notes = ()
    if dropped:  # a segment or a run that lost every row is named, not gone
        notes = tuple(
            f"{source}: {what}(s) {shown} had a NaN/Inf value in every row: all dropped, not "
            "diagnosed"
            for what, shown in (
                ("run", _lost(run_values if run is not None else None, run)),
                ("segment", _lost(seg_values if segment is not None else None, segment)),
            )
            if shown
        )
    time = None
    if time_col:
        if time_note is None:
            time, note = seconds(blocks[3][:, 0], time_unit, None, f"{source} ({time_col})")
            notes = (*notes, note) if note else notes
        else:  # date-times: seconds since the Unix epoch already
            time, notes = blocks[3][:, 0].copy(), (*notes, time_note)
    if errors_only:
        notes = (
            *notes,
            f"{source}: errors-only log: {', '.join(_ends(truth_cols))} are the errors e_k",
        )
    notes = (*notes, *cov_notes)
    if time is not None:
        notes = (*notes, *_time_back_notes(time, segment, rows, source, run))
    del blocks
    if innovations or errors_only:
        truth, estimate, errors = None, None, truth
    else:
        errors = None
    return EstimatorLog(
        truth,
        estimate,
        cov,
        time,
        segment,
        rows,
        LogId.of(source),
        dropped,
        state_errors=errors,
        notes=notes,
        run=run,
    )


def _lost(every, kept) -> str | None:
    """The labels in ``every`` (a column's values before rows were dropped) that ``kept``
    no longer holds, quoted, at most ten named; None when there are none."""
    if every is None or kept is None:
        return None
    lost = sorted(set(every.tolist()) - set(kept.tolist()), key=str)
    if not lost:
        return None
    more = f" and {len(lost) - 10} more" if len(lost) > 10 else ""
    return ", ".join(repr(str(name)) for name in lost[:10]) + more


def _time_back_notes(time, segment, rows, source: str, run=None) -> tuple[str, ...]:
    """A note where time goes back within a segment of a run (the whole log without a
    segment column; each Monte Carlo run restarts its clock): the errors' memory, the time
    scales and an innovations' whiteness test read the epochs in file order, which is then
    not their order in time (``--window`` refuses such a log; a plain diagnosis reads it,
    and says so)."""
    if not np.any(np.diff(time) < 0):  # the common case: one pass, no grouping
        return ()
    keys = [k for k in (run, segment) if k is not None]
    if not keys:
        order = np.arange(time.size)
        same = np.ones(time.size - 1, dtype=bool)
    else:
        import pandas as pd

        # hashed group codes of (run, segment): no sort of 10⁶ names
        codes = pd.MultiIndex.from_arrays(keys).factorize()[0] if len(keys) > 1 else None
        codes = pd.factorize(keys[0])[0] if codes is None else codes
        order = np.argsort(codes, kind="stable")  # each group's rows, in file order
        same = np.diff(codes[order]) == 0
    back = np.flatnonzero(same & (np.diff(time[order]) < 0))
    if back.size == 0:
        return ()
    k = int(np.min(order[back + 1]))  # the first such row in the file
    where = "".join(
        f" in {name} '{labels[k]}'"
        for name, labels in (("run", run), ("segment", segment))
        if labels is not None
    )
    return (
        f"{source}: time goes back at row {rows[k]}{where} ({back.size} place(s) in all); the "
        "errors' memory, time scales and whiteness test are read in file order",
    )


def _labels(frame, column: str) -> tuple[np.ndarray, np.ndarray]:
    """A column's values as strings (an object array), and which are missing."""
    fast = frame.labels(column) if isinstance(frame, ParquetColumns) else None
    if fast is not None:
        return fast
    series = frame[column]
    try:
        return series.astype(str).to_numpy(), series.isna().to_numpy()
    except UnicodeDecodeError:  # Parquet binary names that are not UTF-8: their bytes escaped
        text = series.map(
            lambda v: v.decode("utf-8", "backslashreplace") if isinstance(v, bytes) else v
        )
        return text.astype(str).to_numpy(), series.isna().to_numpy()


def numeric_columns(frame, cols: list[str], source: str, out: np.ndarray | None = None):
    """The columns ``cols`` of ``frame`` as float64, one column at a time.

    Parameters
    ----------
    frame : pandas.DataFrame or ParquetColumns
        The table.
    cols : list of str
        The columns to read.
    source : str
        The log's name in messages.
    out : numpy.ndarray, shape (N, len(cols)), optional
        Where to write them; default a new array.

    Returns
    -------
    numpy.ndarray, shape (N, len(cols))
        ``out`` (or the new array), missing values as NaN.

    Raises
    ------
    CredcliError
        A cell is not a number (naming its row and column), or a column is of another
        type (booleans, date-times).
    """
    if out is None:
        out = np.empty((len(frame), len(cols)))
    for j, col in enumerate(cols):
        if isinstance(frame, ParquetColumns) and frame.floats(col, out[:, j]):
            continue
        import pandas as pd

        series = frame[col]
        if isinstance(series, pd.DataFrame):  # a name the header gives more than once
            raise CredcliError(
                f"{source}: column '{col}' is named {series.shape[1]} times in the header; "
                "give each column its own name"
            )
        if series.dtype == object or pd.api.types.is_string_dtype(series.dtype):
            # the parser found a cell that is not a number: name the first one
            converted = numbers_or_nan(series)
            bad = converted.isna() & series.notna()
            if bad.any():
                i = int(np.argmax(bad.to_numpy()))
                raise CredcliError(
                    f"{source}: row {i + 1}, column '{col}': '{series.iloc[i]}' is not a number"
                )
            out[:, j] = converted.to_numpy(dtype=float, na_value=np.nan)
        elif pd.api.types.is_numeric_dtype(series.dtype) and not pd.api.types.is_bool_dtype(
            series.dtype
        ):
            out[:, j] = series.to_numpy(dtype=float, na_value=np.nan)
        else:
            raise CredcliError(f"{source}: column '{col}' has type {series.dtype}, not numbers")
    return out


def _errors_layout(columns: list[str], schema: LogSchema) -> bool:
    """Whether a table is an errors-only log: ``err_0`` and no truth or estimate columns."""
    if schema.truth_columns or schema.estimate_columns:
        return False
    prefixes = (schema.truth_prefix, schema.estimate_prefix)
    if any(_indexed(columns, p) for p in prefixes):
        return False
    return f"{ERRORS_SCHEMA['truth_prefix']}0" in columns


def _ends(cols: list[str]) -> list[str]:
    """The first and last of a list of columns (all when at most three)."""
    return cols if len(cols) <= 3 else [cols[0], "…", cols[-1]]


def _time_column(frame, col: str, source: str, out: np.ndarray) -> str | None:
    """Read the time column into ``out``: numbers as they are (None), or date-times
    (datetime64, ISO-8601 strings) as seconds since the Unix epoch (with the note)."""
    if isinstance(frame, ParquetColumns) and frame.floats(col, out):
        return None
    values, note = time_seconds(frame[col], f"{source} ({col})")
    out[:] = values
    return note


def build_cov(values: np.ndarray, kind: CovKind, d: int) -> np.ndarray:
    """(N, d, d) covariances from their columns.

    Parameters
    ----------
    values : numpy.ndarray, shape (N, k)
        The covariance columns in the order :func:`cov_layout` gives: k = d² (full, row
        major), d(d+1)/2 (upper triangle, row major) or d (variances or standard
        deviations).
    kind : CovKind
        The layout.
    d : int
        The state dimension.

    Returns
    -------
    numpy.ndarray, shape (N, d, d)
        The matrices: for the full layout a view of ``values`` when it is contiguous (no
        copy of a large log's covariances), as given (checked by :func:`validated_cov`);
        otherwise a new array, the upper triangle mirrored, the diagonal layouts squared
        (``std``) or as they are (``var``).

    Examples
    --------
    >>> build_cov(np.array([[1.0, 4.0]]), CovKind.STD, 2).tolist()
    [[[1.0, 0.0], [0.0, 16.0]]]
    """
    n = values.shape[0]
    if kind is CovKind.FULL:
        return values.reshape(n, d, d)
    cov = np.zeros((n, d, d))
    if kind is CovKind.UPPER:
        iu = np.triu_indices(d)
        cov[:, iu[0], iu[1]] = values
        cov[:, iu[1], iu[0]] = values
    else:
        with np.errstate(over="ignore"):  # an overflow is reported by validated_cov
            diag = values**2 if kind is CovKind.STD else values
        idx = np.arange(d)
        cov[:, idx, idx] = diag
    return cov


SYMMETRISE_RTOL = 1e-3
"""Relative asymmetry (largest |Σ_ij − Σ_ji| over the largest entry) up to which a claimed
covariance is made symmetric, with a note: a filter's covariance drifts from symmetric in
float arithmetic over many updates. Above it, the matrix is refused as not symmetric (a
wrong column, a transposed layout)."""


MAX_DEVIATION_SPREAD = 1e8
"""Largest ratio of a claimed covariance's largest to smallest standard deviation √Σ_ii
(metres beside 10 nm, kilometres beside 10 µm). The whitening keeps working accuracy on
such graded matrices (:func:`credcli.engine.linalg.whitening_factors`; checked to a ratio
of 10^12); beyond this one the components' units should be changed."""

DEVIATION_RANGE = (1e-150, 1e150)
"""The claimed standard deviations √Σ_ii a log may hold, in its own unit: within them every
result is the same as in any other unit (errors and standard deviations scaled by 10^±145,
d = 1 … 6, 12 … 20,000 epochs: every label and κ̂ unchanged; ``tests/test_edge_signals.py``
at 10^±140). Beyond them the precisions Σ_k⁻¹, summed over the
epochs, or the variances themselves leave double precision's range: with standard
deviations of 1e-153 (d = 3, 300 epochs) the diagnosis failed ("eigenvalues did not
converge", an internal error), with 1e154 it gave κ̂ 0.64 for 0.97."""

PAIRWISE_MAX_D = 16
"""Largest d whose full covariances are checked and symmetrised an entry pair at a time
(no N×d×d temporaries); above it, a chunk of whole matrices at a time."""

_CHUNK_BYTES = 2**24
"""Bytes of one chunk of matrices checked at once above `PAIRWISE_MAX_D` (at least one)."""


def _matrix_chunks(n: int, d: int):
    """Slices of the epochs whose d×d matrices take about `_CHUNK_BYTES` (one at least)."""
    return epoch_chunks(n, max(1, _CHUNK_BYTES // (8 * d * d)))


def validated_cov(
    cov: np.ndarray,
    rows: np.ndarray,
    source: str,
    kind: CovKind = CovKind.FULL,
    epoch=None,
    notes: list[str] | None = None,
) -> np.ndarray:
    """The covariances, exactly symmetric, after checking that each is symmetric and
    positive definite.

    Only a full matrix can be asymmetric: it is checked and made symmetric in place,
    (Σ + Σᵀ)/2, an entry pair at a time (no N×d×d temporaries); the other layouts are
    symmetric as built. Where some matrix was asymmetric past float rounding
    (``SYMMETRY_RTOL``) but within :data:`SYMMETRISE_RTOL`, a note saying how many and how
    much is added to ``notes``.

    Parameters
    ----------
    cov : numpy.ndarray, shape (N, d, d)
        The claimed covariances (float64); a full layout is symmetrised in place.
    rows : numpy.ndarray, shape (N,)
        The file row of each matrix, for messages.
    source : str
        The log's name in messages and the note.
    kind : CovKind, default CovKind.FULL
        The layout the matrices were built from (:func:`build_cov`).
    epoch : callable, optional
        ``epoch(i)`` names the i-th matrix in a message instead of "{source}: row …"
        (arrays: "cov[i]").
    notes : list of str, optional
        Where the note on symmetrised matrices is appended; None: no note.

    Returns
    -------
    numpy.ndarray, shape (N, d, d)
        ``cov`` itself, exactly symmetric.

    Raises
    ------
    CredcliError
        Naming the first bad matrix: a variance that overflows double precision, a relative
        asymmetry above :data:`SYMMETRISE_RTOL`, a variance not positive, a standard deviation
        outside :data:`DEVIATION_RANGE`, standard deviations more than
        :data:`MAX_DEVIATION_SPREAD` times apart, or a correlation matrix whose smallest
        eigenvalue is not above :data:`credcli.engine.linalg.CORRELATION_FLOOR` (not
        positive definite).
    """

    def where(i: int) -> str:
        return epoch(i) if epoch is not None else f"{source}: row {rows[i]}"

    diag = np.diagonal(cov, axis1=1, axis2=2)
    infinite = ~per_epoch(np.logical_and, np.isfinite(diag))
    if infinite.any():
        i = int(np.argmax(infinite))
        what = "the square of a std column" if kind is CovKind.STD else "a variance"
        raise CredcliError(
            f"{where(i)}: {what} overflows double precision (above 1.8e308); "
            "are the covariance columns in the log's units?"
        )
    if kind is CovKind.FULL:
        d = cov.shape[1]
        if d <= PAIRWISE_MAX_D:
            scale = np.abs(cov[:, 0, 0])
            for i, j in itertools.product(range(d), repeat=2):
                np.maximum(scale, np.abs(cov[:, i, j]), out=scale)
            upper = [(i, j) for i in range(d) for j in range(i + 1, d)]
            asym = np.zeros(cov.shape[0])
            for i, j in upper:
                np.maximum(asym, np.abs(cov[:, i, j] - cov[:, j, i]), out=asym)
        else:  # d² pairs would be d² Python steps (d = 3,000: 24 s); whole matrices instead
            scale, asym = np.empty(cov.shape[0]), np.empty(cov.shape[0])
            for sl in _matrix_chunks(cov.shape[0], d):
                scale[sl] = np.abs(cov[sl]).max(axis=(1, 2))
                asym[sl] = np.abs(cov[sl] - cov[sl].transpose(0, 2, 1)).max(axis=(1, 2))
        with np.errstate(invalid="ignore", divide="ignore"):
            relative = np.where(asym > 0, asym / scale, 0.0)
        refused = relative > SYMMETRISE_RTOL
        if refused.any():
            i = int(np.argmax(refused))
            hint = "" if epoch is not None else "; check the cov_i_j columns"
            raise CredcliError(
                f"{where(i)}: covariance is not symmetric (relative asymmetry "
                f"{relative[i]:.2g}, above {SYMMETRISE_RTOL:g}){hint}"
            )
        drifted = relative > SYMMETRY_RTOL
        if drifted.any() and notes is not None:
            notes.append(
                f"{source}: {int(drifted.sum()):,} of {len(cov):,} covariances were not "
                f"symmetric (relative asymmetry up to {relative.max():.2g}, within "
                f"{SYMMETRISE_RTOL:g}): each was replaced by (Σ + Σᵀ)/2"
            )
        if d <= PAIRWISE_MAX_D:
            for i, j in upper:  # halves first: two entries near 1.8e308 do not overflow
                mean = 0.5 * cov[:, i, j] + 0.5 * cov[:, j, i]
                cov[:, i, j] = mean
                cov[:, j, i] = mean
        else:  # the same means (halving is exact); the diagonal stays as it is
            for sl in _matrix_chunks(cov.shape[0], d):
                cov[sl] = 0.5 * cov[sl] + 0.5 * cov[sl].transpose(0, 2, 1)
    smallest = per_epoch(np.minimum, diag)
    if not np.all(smallest > 0):
        i = int(np.argmax(~(smallest > 0)))
        raise CredcliError(
            f"{where(i)}: covariance is not positive definite (a variance is "
            f"{smallest[i]:.3g}); a claimed covariance must be positive definite"
        )
    low, high = DEVIATION_RANGE
    least, most = np.sqrt(smallest), np.sqrt(per_epoch(np.maximum, diag))  # √Σ_ii
    outside = ~((least >= low) & (most <= high))
    if outside.any():
        i = int(np.argmax(outside))
        size = np.sqrt(np.diagonal(cov[i]))
        size = size.min() if size.min() < low else size.max()
        raise CredcliError(
            f"{where(i)}: a claimed standard deviation of {size:.3g} lies outside "
            f"{low:g} … {high:g} of the log's unit; give the log in other units"
        )
    spread = most / least
    wide = spread > MAX_DEVIATION_SPREAD * (1.0 + 1e-12)  # the limit itself, rounded, passes
    if wide.any():
        i = int(np.argmax(wide))
        raise CredcliError(
            f"{where(i)}: the covariance's standard deviations are {spread[i]:.3g} times "
            f"apart, more than {MAX_DEVIATION_SPREAD:g}; give the components in units of "
            "more similar size"
        )
    if kind not in (CovKind.VAR, CovKind.STD) and cov.shape[1] > 1:  # full or upper
        min_eig = smallest_correlation_eigenvalue(cov)
        not_pd = ~(min_eig > CORRELATION_FLOOR)
        if not_pd.any():
            i = int(np.argmax(not_pd))
            raise CredcliError(
                f"{where(i)}: covariance is not positive definite (the smallest eigenvalue "
                f"of its correlation matrix is {min_eig[i]:.3g}, not above "
                f"{CORRELATION_FLOOR:g}); a claimed covariance must be positive definite"
            )
    return cov
