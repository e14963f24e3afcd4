"""Logs from arrays, and logs as the canonical table: where a notebook and the CLI meet.

:func:`log_from_arrays` validates arrays into an :class:`~credcli.io.logs.EstimatorLog`,
naming the argument and the epoch of the first problem; :func:`log_table` and
:func:`write_log` give a log back as the columns ``credcli diagnose`` reads (CSV or
Parquet), so that a log made in Python can be diagnosed, gated and shared from the command
line. Date-time columns are converted by :func:`credcli.io.text.time_seconds`.
"""

from __future__ import annotations

import io
import zipfile
from pathlib import Path

import numpy as np

from credcli.errors import CredcliError
from credcli.io.files import check_covariance_memory, memory_budget, shown, write_atomic
from credcli.io.logs import EstimatorLog, validated_cov
from credcli.io.text import time_seconds
from credcli.logid import LogId


def _refuse_complex(name: str, value) -> None:
    """Complex numbers are refused: casting would drop their imaginary parts with only a
    warning; so are booleans, which are no errors or covariances (a mask passed by
    mistake would be read as 0 and 1)."""
    if np.iscomplexobj(value):
        raise CredcliError(f"{name}: complex numbers; expected real numbers")
    if np.asarray(value).dtype.kind == "b":
        raise CredcliError(f"{name}: booleans; expected real numbers")


def _matrix(name: str, value, n: int | None, d: int | None = None) -> np.ndarray:
    """An (N, d) float array from ``value`` ((N,) is d = 1; (N, d, 1) column vectors, as
    filterpy's ``batch_filter`` returns its means, are taken as (N, d)), or an error naming
    ``name``;
    ``n`` and ``d``, where known, are what the other arguments say (a transposed array is
    named as such)."""
    _refuse_complex(name, value)
    try:
        array = np.asarray(value, dtype=float)
    except (TypeError, ValueError) as exc:
        raise CredcliError(f"{name}: expected numbers, shape (N, d); {exc}") from None
    if array.ndim == 1:
        array = array[:, None]
    if array.ndim == 3 and array.shape[2] == 1:  # column vectors, as filterpy keeps x
        array = array[:, :, 0]
    if array.ndim != 2 or array.shape[0] == 0 or array.shape[1] == 0:
        raise CredcliError(
            f"{name}: expected shape (N, d) (or (N, d, 1) column vectors) with N, d >= 1; "
            f"got {array.shape}"
        )

    def fits(shape) -> bool:
        return (n is None or shape[0] == n) and (d is None or shape[1] == d)

    if not fits(array.shape) and fits(array.shape[::-1]):
        raise CredcliError(
            f"{name}: shape {array.shape} is transposed: expected (N, d) = "
            f"({n if n is not None else 'N'}, {d if d is not None else 'd'}), one row per "
            f"epoch; pass {name}.T"
        )
    if n is not None and array.shape[0] != n:
        raise CredcliError(f"{name}: {array.shape[0]} epochs, expected {n} as in the others")
    if d is not None and array.shape[1] != d:
        raise CredcliError(
            f"{name}: d = {array.shape[1]}, but cov is {d} × {d}: the dimensions must match"
        )
    bad = ~np.isfinite(array)
    if bad.any():
        k, i = np.argwhere(bad)[0]
        raise CredcliError(f"{name}[{k}, {i}] is {array[k, i]}: every value must be finite")
    return array


def _cov_array(cov) -> np.ndarray:
    _refuse_complex("cov", cov)
    try:
        return np.asarray(cov, dtype=float)
    except (TypeError, ValueError) as exc:
        raise CredcliError(f"cov: expected numbers, shape (N, d, d); {exc}") from None


def _cov_shape(array: np.ndarray) -> tuple[int | None, int]:
    """(N, d) as the claimed covariances tell them (None where they do not): (N, d, d);
    one (d, d) matrix; (N, d) variances; (N,) variances of d = 1."""
    if array.ndim not in (1, 2, 3) or (array.ndim == 3 and array.shape[1] != array.shape[2]):
        raise CredcliError(
            f"cov: expected shape (N, d, d), one (d, d) matrix for every epoch, or variances "
            f"(N, d); got {array.shape}"
        )
    if array.ndim == 3:
        return array.shape[0], array.shape[2]
    if array.ndim == 2:
        return (None, array.shape[0]) if array.shape[0] == array.shape[1] else array.shape
    return array.shape[0], 1


def _covariances(array: np.ndarray, n: int, d: int, notes: list[str] | None = None) -> np.ndarray:
    """(N, d, d) claimed covariances from (N, d, d), one shared (d, d), (N, d) variances
    (d ≠ N), or (N,) variances for d = 1; a note on symmetrised ones goes to ``notes``."""
    check_covariance_memory(n, d, "cov")
    if array.ndim == 1 and d == 1:
        array = array[:, None, None]
    if array.shape == (d, d):
        array = np.broadcast_to(array, (n, d, d))
    elif array.shape == (n, d):  # variances, one row per epoch (inf·0 would be NaN)
        diagonal = np.zeros((n, d, d), dtype=np.result_type(array, float))
        diagonal[:, np.arange(d), np.arange(d)] = array
        array = diagonal
    if array.shape != (n, d, d):
        raise CredcliError(
            f"cov: expected shape (N, d, d) = ({n}, {d}, {d}), one ({d}, {d}) matrix for "
            f"every epoch, or variances ({n}, {d}); got {array.shape}"
        )
    bad = ~np.isfinite(array).all(axis=(1, 2))
    if bad.any():
        k = int(np.argmax(bad))
        raise CredcliError(f"cov[{k}] has a NaN or Inf value: every value must be finite")
    try:
        return validated_cov(
            np.array(array), np.arange(n), "cov", epoch=lambda k: f"cov[{k}]", notes=notes
        )
    except CredcliError as exc:
        raise CredcliError(exc.message, exc.parameter or "cov") from exc


def error_arrays(errors, cov) -> tuple[np.ndarray, np.ndarray]:
    """``errors`` (N, d) and ``cov`` as :func:`log_from_arrays` takes them, checked and
    given back as (N, d) and (N, d, d).

    Parameters
    ----------
    errors : array_like, shape (N, d)
        The errors e_k ((N,) for d = 1; (N, d, 1) column vectors are taken as (N, d)).
    cov : array_like, shape (N, d, d), (d, d) or (N, d)
        The claimed covariances: one per epoch, one (d, d) for every epoch, or variances.

    Returns
    -------
    errors : numpy.ndarray, shape (N, d)
        The errors as floats.
    cov : numpy.ndarray, shape (N, d, d)
        The covariances, exactly symmetric, each checked symmetric and positive definite.

    Raises
    ------
    CredcliError
        For complex numbers, an array of the wrong shape (a transposed one named as such),
        a value that is not finite, or a covariance that is not symmetric positive
        definite, naming the argument and the epoch.

    Examples
    --------
    >>> e, c = error_arrays(np.zeros((3, 2)), np.ones((3, 2)))
    >>> e.shape, c.shape, c[0].tolist()
    ((3, 2), (3, 2, 2), [[1.0, 0.0], [0.0, 1.0]])
    """
    array = _cov_array(cov)
    n, d = _cov_shape(array)
    matrix = _matrix("errors", errors, n, d)
    return matrix, _covariances(array, *matrix.shape)


def log_from_arrays(
    truth=None,
    estimate=None,
    cov=None,
    *,
    errors=None,
    time=None,
    segment=None,
    run=None,
    source: str = "<arrays>",
) -> EstimatorLog:
    """An estimator log from arrays.

    Give ``truth`` and ``estimate``, or ``errors`` alone, with the claimed covariances
    ``cov``. Every array is checked here, and an error names the argument and the epoch
    (and a transposed array as such). The form of credcli 0.1, ``log_from_arrays(cov,
    errors=...)``, is still read.

    Parameters
    ----------
    truth, estimate : array_like, shape (N, d), optional
        The true and estimated states; the errors are e_k = x_k − x̂_k.
    cov : array_like, shape (N, d, d), (d, d) or (N, d)
        The claimed covariances: one per epoch, one (d, d) for every epoch, or variances.
    errors : array_like, shape (N, d), optional
        The errors, instead of ``truth`` and ``estimate``: what a library's own error map
        gives (a Lie group's ⊖, a tracker's innovation); credcli uses it as it is.
    time : array_like, shape (N,), optional
        Seconds, datetime64 or ISO-8601 strings (converted once, with a note).
    segment : array_like, shape (N,), optional
        Each epoch's segment name.
    run : array_like, shape (N,), optional
        The Monte Carlo run of each epoch when the arrays hold several runs one after the
        other ([credcli.diagnose_monte_carlo][credcli.api.diagnose_monte_carlo] pools
        them).
    source : str
        The log's name in messages and records.

    Returns
    -------
    EstimatorLog
        The validated log.

    Raises
    ------
    CredcliError
        If ``errors`` is given with ``truth`` or ``estimate``, if neither ``errors`` nor
        both ``truth`` and ``estimate`` are given, if ``cov`` is missing, or for an array
        of the wrong shape or with a value that is not finite (naming the argument and the
        epoch).

    Examples
    --------
    >>> import numpy as np
    >>> truth = np.zeros((300, 2))
    >>> estimate = np.random.default_rng(0).standard_normal((300, 2))
    >>> log = log_from_arrays(truth, estimate, np.eye(2), segment=["a"] * 150 + ["b"] * 150)
    >>> log.n, log.dim, sorted(set(log.segment))
    (300, 2, ['a', 'b'])
    >>> log_from_arrays(errors=estimate, cov=np.ones((300, 2))).dim  # variances (N, d)
    2
    """
    if errors is not None and truth is not None and estimate is None and cov is None:
        truth, cov = None, truth  # credcli 0.1: log_from_arrays(cov, errors=...)
    if errors is not None and (truth is not None or estimate is not None):
        raise CredcliError("give errors, or truth and estimate, not both")
    if errors is None and (truth is None or estimate is None):
        raise CredcliError("give errors (N, d), or both truth and estimate (N, d)")
    if cov is None:
        raise CredcliError(
            "cov: give the claimed covariances: (N, d, d), one (d, d) matrix for every "
            "epoch, or variances (N, d)"
        )
    cov_array = _cov_array(cov)
    n_cov, d_cov = _cov_shape(cov_array)
    if errors is not None:
        state_errors = _matrix("errors", errors, n_cov, d_cov)
        truth_arr = estimate_arr = None
        n, d = state_errors.shape
    else:
        truth_arr = _matrix("truth", truth, n_cov, d_cov)
        n, d = truth_arr.shape
        estimate_arr = _matrix("estimate", estimate, n, d)
        state_errors = None
    cov_notes: list[str] = []
    covariances = _covariances(cov_array, n, d, cov_notes)
    notes: tuple[str, ...] = ()
    seconds = None
    if time is not None:
        seconds, note = time_seconds(time, "time")
        if seconds.shape != (n,):
            raise CredcliError(f"time: expected shape ({n},); got {seconds.shape}")
        if not np.isfinite(seconds).all():
            k = int(np.argmax(~np.isfinite(seconds)))
            raise CredcliError(f"time[{k}] is missing or not finite")
        notes = (note,) if note else ()
    notes = (*notes, *cov_notes)
    labels = _labels("segment", segment, n)
    runs = _labels("run", run, n)
    return EstimatorLog(
        truth_arr,
        estimate_arr,
        covariances,
        time=seconds,
        segment=labels,
        id=LogId.of(source),
        state_errors=state_errors,
        notes=notes,
        run=runs,
    )


def _labels(name: str, values, n: int) -> np.ndarray | None:
    """(N,) labels as strings, or None."""
    if values is None:
        return None
    values = np.asarray(values)
    try:
        if values.dtype.kind == "S":  # bytes: UTF-8, other bytes kept as \xNN escapes
            values = np.char.decode(values, "utf-8", errors="backslashreplace")
        labels = values.astype(str).astype(object)
    except (TypeError, ValueError, UnicodeError) as exc:
        raise CredcliError(
            f"{name}: labels of dtype {values.dtype} cannot be read as text; give strings or "
            "integers"
        ) from exc
    if labels.shape != (n,):
        raise CredcliError(f"{name}: expected shape ({n},); got {labels.shape}")
    missing = _missing_labels(values)
    if missing.any():  # as a log file's empty or NA cell: no segment or run named "nan"
        first = int(np.argmax(missing))
        raise CredcliError(
            f"{name}: epoch {first} has no label ({values[first]}); give every epoch one",
            name,
        )
    return labels


def _missing_labels(values: np.ndarray) -> np.ndarray:
    """(N,) bool: None, NaN, pandas' NA or NaT among ``values`` (any dtype)."""
    import pandas as pd

    if values.dtype.kind in "US":
        return np.zeros(values.shape, dtype=bool)
    return np.asarray(pd.isna(values), dtype=bool).reshape(values.shape)


def log_table(log: EstimatorLog):
    """A log as the canonical table ``credcli diagnose`` reads: ``time`` and ``segment``
    when the log has them, ``truth_i``/``est_i`` (or ``err_i`` for an errors-only log) and
    the upper triangle ``cov_i_j``, i <= j; ``run`` for a log of Monte Carlo runs. Values
    are written to full precision.

    Parameters
    ----------
    log : EstimatorLog
        The log.

    Returns
    -------
    pandas.DataFrame
        One row per epoch, in the columns above (in that order).

    Examples
    --------
    >>> log = log_from_arrays(errors=np.zeros((4, 2)), cov=np.eye(2))
    >>> list(log_table(log).columns)
    ['err_0', 'err_1', 'cov_0_0', 'cov_0_1', 'cov_1_1']
    """
    import pandas as pd

    d = log.dim
    columns: dict = {"time": log.time} if log.time is not None else {}
    if log.segment is not None:
        columns["segment"] = log.segment
    if log.run is not None:
        columns["run"] = log.run
    if log.truth is not None and log.estimate is not None:
        columns |= {f"truth_{i}": log.truth[:, i] for i in range(d)}
        columns |= {f"est_{i}": log.estimate[:, i] for i in range(d)}
    else:
        errors = log.errors
        columns |= {f"err_{i}": errors[:, i] for i in range(d)}
    columns |= {f"cov_{i}_{j}": log.cov[:, i, j] for i in range(d) for j in range(i, d)}
    return pd.DataFrame(columns)


def log_csv(log: EstimatorLog) -> str:
    """``log`` as the CSV text of its canonical table (``log_table``): every float as its
    shortest exact representation (it reads back to the same bits).

    Parameters
    ----------
    log : EstimatorLog
        The log.

    Returns
    -------
    str
        The CSV text: a header row, then one row per epoch.
    """
    return log_table(log).to_csv(index=False)


def write_log(log: EstimatorLog, path: str | Path, inputs=()) -> Path:
    """Write ``log`` as its canonical table, for ``credcli diagnose`` and ``credcli gate``.

    The table (``log_table``) holds ``time`` and ``segment`` when the log has them,
    ``truth_i``/``est_i`` (or ``err_i`` for an errors-only log), the upper triangle
    ``cov_i_j``, i <= j, and ``run`` for a log of Monte Carlo runs, to full precision.
    It is written atomically (no half-written file).

    Parameters
    ----------
    log : EstimatorLog
        The log to write.
    path : str or pathlib.Path
        Parquet for a ``.parquet`` or ``.pq`` name, else CSV (``log_csv``).
    inputs : sequence of paths
        Files that must not be overwritten (the log's own inputs).

    Returns
    -------
    pathlib.Path
        ``path``.

    Raises
    ------
    CredcliError
        If ``path`` is one of ``inputs``, a directory, or cannot be written.

    Examples
    --------
    >>> import tempfile
    >>> from pathlib import Path
    >>> from credcli import read_log
    >>> log = log_from_arrays(errors=np.ones((20, 2)), cov=np.eye(2), segment=["a"] * 20)
    >>> with tempfile.TemporaryDirectory() as folder:
    ...     path = write_log(log, Path(folder) / "log.csv")
    ...     back = read_log(path)
    >>> back.n, back.dim, float(back.errors[0, 1]), back.segment[0]
    (20, 2, 1.0, 'a')
    """
    path = Path(path)
    if path.suffix.lower() in (".parquet", ".pq"):
        buffer = io.BytesIO()
        log_table(log).to_parquet(buffer, index=False)
        write_atomic(path, buffer.getvalue(), inputs)
    else:
        write_atomic(path, log_csv(log), inputs)
    return path


NPZ_NAMES = {
    "truth": ("truth",),
    "estimate": ("estimate", "est"),
    "errors": ("errors", "err"),
    "cov": ("cov",),
    "time": ("time", "t"),
    "segment": ("segment",),
    "run": ("run",),
}
"""The arrays of a credcli ``.npz`` log, by argument of :func:`log_from_arrays`, with the
names each may have in the file."""
_NPZ_ARGUMENTS = {alias: arg for arg, aliases in NPZ_NAMES.items() for alias in aliases}
"""Each name an ``.npz`` array may have, to its argument of :func:`log_from_arrays`."""


def _shape_fits(argument: str, shape: tuple, n: int, d: int) -> bool:
    """Whether an array for ``argument`` of :func:`log_from_arrays` of ``shape`` can be
    read as a log of ``n`` epochs in ``d`` dimensions, as that function reads it (a
    transposed (d, N) array too, which it names as such)."""
    if argument == "cov":
        return shape in ((n, d, d), (d, d), (n, d), (d, n)) or shape == (n,) and d == 1
    if argument in ("time", "segment", "run"):
        return shape == (n,)
    return shape in ((n,), (n, d), (d, n), (n, d, 1)) and (len(shape) > 1 or d == 1)


def _check_npz_shapes(path: Path, shapes: dict[str, tuple]) -> None:
    """Refuse arrays whose declared shapes fit no one number of epochs N and dimension d
    (one array of 2²⁸ epochs beside others of 2), before any is read."""
    known = {name: shape for name, shape in shapes.items() if name in _NPZ_ARGUMENTS}
    # no array of a log has more than three axes: the candidates are a few dozen sizes
    sizes = {int(size) for shape in known.values() if len(shape) <= 3 for size in shape}
    if not known or any(
        all(_shape_fits(_NPZ_ARGUMENTS[name], shape, n, d) for name, shape in known.items())
        for n in sizes
        for d in sizes | {1}
    ):
        return
    listed = ", ".join(f"{name} {tuple(shape)}" for name, shape in known.items())
    raise CredcliError(
        f"{path}: its arrays' shapes fit no one number of epochs N and dimension d "
        f"({shown(listed)}); a log's arrays are (N, d), (N, d, d) or (d, d), and (N,)"
    )


def _check_npz_sizes(path: Path) -> None:
    """Refuse, before anything is allocated, an ``.npz`` whose arrays declare more bytes
    than they hold (a 588-byte file declaring 10¹³ floats), more than this machine has
    memory for together (a zip bomb: 4 MB of zeros inflating to 15 GB), or shapes that fit
    no one log (4 GiB of one array beside two epochs of the others). Other faults are left
    for ``np.load`` to report."""
    try:
        archive = zipfile.ZipFile(path)
    except zipfile.BadZipFile as exc:  # np.load would leave its file open on this
        raise CredcliError(f"{path}: not a readable .npz file ({exc})") from None
    except OSError:
        return  # np.load reports it
    shapes: dict[str, tuple] = {}
    with archive:
        budget = memory_budget()
        total = sum(info.file_size for info in archive.infolist())
        if total > budget:
            raise CredcliError(
                f"{path}: its arrays inflate to {total / 2**30:.3g} GiB, more than the "
                f"{budget / 2**30:.3g} GiB of memory credcli may use here"
            )
        for info in archive.infolist():
            try:
                with archive.open(info) as member:
                    fmt = np.lib.format
                    read = {(1, 0): fmt.read_array_header_1_0, (2, 0): fmt.read_array_header_2_0}
                    shape, _, dtype = read[fmt.read_magic(member)](member)
            except (
                OSError,
                ValueError,
                KeyError,
                zipfile.BadZipFile,
                RuntimeError,
                NotImplementedError,
            ):
                continue  # np.load reports it
            declared = int(np.prod(shape, dtype=object)) * dtype.itemsize
            if declared > info.file_size:
                raise CredcliError(
                    f"{path}: array {shown(info.filename)} declares {declared:,} bytes of "
                    f"data but holds {info.file_size:,}; the file is damaged or not a log"
                )
            shapes[info.filename.removesuffix(".npy")] = tuple(shape)
    _check_npz_shapes(path, shapes)


def load_npz(path: Path) -> EstimatorLog:
    """A log from a NumPy ``.npz`` file of named arrays (:data:`NPZ_NAMES`): ``truth`` and
    ``estimate`` or ``errors`` (N, d), ``cov`` (N, d, d) or (d, d), optional ``time``,
    ``segment`` and ``run`` (N,). Other names are an error, so that a typo is not silently
    ignored.

    The arrays are checked as :func:`log_from_arrays` checks its arguments; pickled arrays
    are not read.

    Parameters
    ----------
    path : pathlib.Path
        The ``.npz`` file.

    Returns
    -------
    EstimatorLog
        The log, named by ``path``.

    Raises
    ------
    CredcliError
        If the file is missing, is not a readable ``.npz``, declares more data than it
        holds or than fits in memory, holds an unknown array, two names of one array
        (``estimate`` and ``est``) or no ``cov``, or if its arrays are not a valid log
        (the message names the file).
    """
    if not path.exists():
        raise CredcliError(f"{path}: file not found")
    _check_npz_sizes(path)
    try:
        with np.load(path, allow_pickle=False) as data:
            unknown = sorted(set(data.files) - set(_NPZ_ARGUMENTS))
            if unknown:  # refused before any array is read
                raise CredcliError(
                    f"{path}: unknown array(s) {shown(', '.join(unknown))}; a credcli .npz "
                    "holds " + ", ".join(a for aliases in NPZ_NAMES.values() for a in aliases[:1])
                )
            arrays = {name: data[name] for name in data.files}
    except (
        OSError,
        ValueError,
        EOFError,
        zipfile.BadZipFile,
        RuntimeError,
        NotImplementedError,
    ) as exc:
        # RuntimeError: an encrypted member; NotImplementedError: a compression numpy's
        # zipfile does not unpack
        first = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise CredcliError(f"{path}: not a readable .npz file ({first})") from None
    if "cov" not in arrays:
        raise CredcliError(f"{path}: no 'cov' array (N, d, d): the claimed covariances")
    kwargs: dict = {}
    for name, value in arrays.items():
        if _NPZ_ARGUMENTS[name] in kwargs:
            both = " and ".join(a for a in NPZ_NAMES[_NPZ_ARGUMENTS[name]] if a in arrays)
            raise CredcliError(
                f"{path}: arrays {both} are two names of `{_NPZ_ARGUMENTS[name]}`; keep one of them"
            )
        kwargs[_NPZ_ARGUMENTS[name]] = value
    try:
        return log_from_arrays(source=str(path), **kwargs)
    except CredcliError as exc:
        raise CredcliError(f"{path}: {exc.message}") from exc
