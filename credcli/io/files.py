"""Files: TOML configs in, outputs written safely.

Outputs never clobber an input and never leave a half-written file: a regular file is
written unnamed (O_TMPFILE) or to a temporary file beside it, and renamed over the target,
each step relative to the open output directory and never through a symbolic link at the
final name (:func:`write_atomic`); anything else that already exists (a device such as /dev/null, a
FIFO, /dev/stdout on a pipe or terminal) is written directly, since renaming over it would
replace it with a regular file. An OSError about the user's files is described in one line
(:func:`describe_os_error`).
"""

from __future__ import annotations

import contextlib
import errno
import os
import secrets
import stat
import sys
from collections.abc import Iterable
from pathlib import Path

from credcli.errors import CredcliError, shortened

STDIN = "-"
"""The name of standard input as a log, and of standard output as an output file."""

MAX_CONFIG_BYTES = 1 << 20
"""Largest config file read (1 MiB; credcli's every setting fits in a few kB)."""


def read_toml(path: str | Path) -> dict:
    """A TOML file's tables; a missing, non-UTF-8 or invalid file is a CredcliError.

    Parameters
    ----------
    path : str or pathlib.Path
        The config file.

    Returns
    -------
    dict
        Its tables, as ``tomllib`` reads them.

    Raises
    ------
    CredcliError
        If ``path`` is a directory or not a file, cannot be read, is larger than
        :data:`MAX_CONFIG_BYTES`, is not UTF-8, is not valid TOML, or is nested too deeply
        to parse.
    """
    try:
        import tomllib
    except ModuleNotFoundError:  # Python 3.10
        import tomli as tomllib
    path = Path(path)
    if path.is_dir():
        raise CredcliError(f"{path}: is a directory, expected a TOML config file")
    if not path.is_file():
        if path.exists():
            raise CredcliError(
                f"{path}: is not a regular file (a device, FIFO or socket); give the TOML "
                "config file itself"
            )
        raise CredcliError(f"{path}: config file not found")
    try:
        with open(path, "rb") as handle:
            data = handle.read(MAX_CONFIG_BYTES + 1)
        if len(data) > MAX_CONFIG_BYTES:
            raise CredcliError(
                f"{path}: larger than {MAX_CONFIG_BYTES // 1024} KiB, too large for a config "
                "file; a config has a few flat tables of settings"
            )
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise CredcliError(
            f"{path}: not UTF-8 text (byte {exc.start}); save the config as UTF-8"
        ) from exc
    except OSError as exc:
        raise CredcliError(f"{path}: cannot be read ({exc.strerror})") from exc
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise CredcliError(f"{path}: not valid TOML: {exc}") from exc
    except RecursionError as exc:
        raise CredcliError(
            f"{path}: nested too deeply to be a config file; a config has flat tables"
        ) from exc


def memory_budget() -> int:
    """Bytes an input may take once read: half of the machine's physical memory.

    Returns
    -------
    int
        Half the physical memory in bytes; 8 GiB where the system does not say.
    """
    try:
        return int(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES") // 2)
    except (ValueError, OSError, AttributeError):
        return 8 * 2**30


def check_small_input(path: str | Path, what: str, share: int = 16) -> None:
    """Refuse, before it is read whole, a file read into memory at once (a baseline) that
    is a device (``/dev/zero`` never ends) or a regular file larger than
    ``memory_budget() // share`` bytes. A pipe or FIFO (``<(git show …)``) is read as it is.

    Parameters
    ----------
    path : str or pathlib.Path
        The file, as the user named it.
    what : str
        What it should be, for the message (``"baseline JSON file"``).
    share : int, default 16
        The part of the memory budget the file's text may take: parsed, it takes several
        times its size.

    Raises
    ------
    CredcliError
        If ``path`` is a character or block device, or a regular file past the limit.
        A path that cannot be examined is left for the reader to report.
    """
    try:
        info = os.stat(path)
    except (OSError, ValueError):
        return
    if stat.S_ISCHR(info.st_mode) or stat.S_ISBLK(info.st_mode):
        raise CredcliError(f"{shown(path)}: is a device, not a {what}; give the {what}")
    limit = memory_budget() // share
    if stat.S_ISREG(info.st_mode) and info.st_size > limit:
        raise CredcliError(
            f"{shown(path)}: {_size(info.st_size)}, more than the {_size(limit)} a {what} may "
            f"take on this machine (1/{share} of half its memory, since it is read whole); "
            f"is it the {what}?"
        )


def _size(n: int) -> str:
    """A number of bytes in words: ``1.5 GiB``, ``730 MiB``, ``12 KiB``, ``300 bytes``."""
    for unit, power in (("GiB", 30), ("MiB", 20), ("KiB", 10)):
        if n >= 2**power:
            return f"{n / 2**power:.3g} {unit}"
    return f"{n} bytes"


COV_COPIES = 4
"""Copies of a log's (N, d, d) covariances held at once while it is read and diagnosed
(measured: 4.0 × peak at d = 1,000 and d = 3,000)."""


def check_covariance_memory(n: int, d: int, source: str) -> None:
    """Refuse, before they are allocated, covariances that would not fit in the memory
    budget: N epochs of dimension d take N·d² numbers, which a few megabytes of a header
    of d variance columns can ask for (40 rows of d = 3,000: a 2.9 MB file, 12 GB).

    Parameters
    ----------
    n : int
        The epochs.
    d : int
        The state dimension.
    source : str
        The log, for the message.

    Raises
    ------
    CredcliError
        If `COV_COPIES` copies of the (N, d, d) covariances exceed :func:`memory_budget`.
    """
    one = n * d * d * 8
    budget = memory_budget()
    if COV_COPIES * one > budget:
        raise CredcliError(
            f"{source}: {n:,} epochs of dimension d = {d:,} make {_size(one)} of covariance "
            f"matrices, and diagnosing them takes about {COV_COPIES} times that, more than the "
            f"{_size(budget)} credcli may use here (half this machine's memory); split the "
            "log, or diagnose it on a larger machine"
        )


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def _same_file(a: Path, b: Path) -> bool:
    try:
        return a.resolve() == b.resolve() or (a.exists() and b.exists() and a.samefile(b))
    except OSError:
        return False


def _is_stream(path: Path) -> bool:
    """``-`` (standard output), or an existing target that is not a regular file or
    directory (device, FIFO, socket)."""
    if str(path) == STDIN:
        return True
    try:
        mode = path.stat().st_mode
    except OSError:
        return False
    return not (stat.S_ISREG(mode) or stat.S_ISDIR(mode))


def check_outputs(outputs: dict[str, Path | None], inputs=(), plots: Path | None = None) -> None:
    """Refuse before any work: an output that is an input, two outputs on one path, or an
    output that is a directory. ``outputs`` maps an option name to its path (or None).

    A device or FIFO (``/dev/stdout``, ``/dev/null``) may be given more than once, and may
    be an input too.

    Parameters
    ----------
    outputs : dict of str to pathlib.Path or None
        Each output's option name (as messages name it) and its path; None for an output
        not asked for.
    inputs : iterable of paths
        The command's input files (None items are skipped).
    plots : pathlib.Path, optional
        The ``--plots`` directory, which credcli creates: an output may be written in it.

    Raises
    ------
    CredcliError
        If an output is a directory, is one of ``inputs``, is the same file as another
        output, lies under a file (:func:`check_not_under_file`), or is in a directory that
        does not exist (other than ``plots``).
    """
    given = [(name, Path(p)) for name, p in outputs.items() if p is not None]
    for name, path in given:
        if path.is_dir():
            raise CredcliError(f"{name} {path}: is a directory; give a file name")
        check_not_under_file(name, path, outputs)
        parent = Path(os.path.abspath(path)).parent
        if not parent.is_dir() and not (
            plots is not None and parent == Path(os.path.abspath(plots))
        ):
            raise CredcliError(
                f"{name} {shown(path)}: directory {shown(parent)} does not exist; create it first"
            )
        for src in inputs:
            if src is not None and _same_file(path, Path(src)) and not _is_stream(path):
                raise CredcliError(
                    f"{name} {path}: is also an input ({src}); refusing to overwrite it, "
                    "choose another file"
                )
    for i, (name, path) in enumerate(given):
        for other, path2 in given[i + 1 :]:
            if _same_file(path, path2) and not _is_stream(path):
                raise CredcliError(
                    f"{name} and {other} are the same file ({path}); give each its own file"
                )


def check_not_under_file(name: str, path: Path, outputs: dict) -> None:
    """Refuse, before any work, an output whose path lies under a file: an existing
    ancestor that is not a directory, or an ancestor that another output will write
    (``--plots out.json/figs`` beside ``-o out.json``), which would fail only after the
    other outputs were written.

    Parameters
    ----------
    name : str
        The option's name, as messages give it.
    path : pathlib.Path
        The output's path.
    outputs : dict of str to pathlib.Path or None
        Every output of the command, by option name (None for one not asked for).

    Raises
    ------
    CredcliError
        If an ancestor of ``path`` is an existing non-directory or another output's path.
    """
    others = {
        Path(os.path.abspath(p)): other
        for other, p in outputs.items()
        if p is not None and other != name
    }
    for parent in Path(os.path.abspath(path)).parents:
        if parent in others:
            raise CredcliError(
                f"{name} {shown(path)}: lies under {others[parent]} {shown(parent)}, a file "
                "credcli writes; give each output its own place"
            )
        if parent.exists():
            if not parent.is_dir():
                raise CredcliError(
                    f"{name} {shown(path)}: {shown(parent)} is a file, not a directory; give "
                    "a path in a directory"
                )
            return  # an existing directory: what is above it exists as directories


def check_directory_output(name: str, directory: Path, outputs: dict, inputs=()) -> None:
    """Refuse, before any work, a directory that outputs are written into (``--plots``)
    when it is a symbolic link (it would be followed), an existing file, an input, or the
    path of another output.

    Parameters
    ----------
    name : str
        The option's name, as messages give it (``--plots``).
    directory : pathlib.Path
        The directory.
    outputs : dict of str to pathlib.Path or None
        The command's other outputs, by option name (None for one not asked for).
    inputs : iterable of paths
        The command's input files (None items are skipped).

    Raises
    ------
    CredcliError
        If ``directory`` is a symbolic link, exists and is not a directory, lies under a
        file (:func:`check_not_under_file`), or is the same path as an input or another
        output.
    """
    if directory.is_symlink():
        raise CredcliError(
            f"{name} {shown(directory)}: is a symbolic link; credcli does not write through "
            "links (give the directory's real path, or remove the link)"
        )
    if directory.exists() and not directory.is_dir():
        raise CredcliError(f"{name} {directory}: exists and is not a directory")
    check_not_under_file(name, directory, outputs)
    for other, path in outputs.items():
        if path is not None and _same_file(directory, Path(path)):
            raise CredcliError(
                f"{name} and {other} are the same path ({directory}); give each its own"
            )
    for src in inputs:
        if src is not None and _same_file(directory, Path(src)):
            raise CredcliError(f"{name} {directory}: is also an input ({src})")


def check_writable(name: str, path: Path, directory: bool = False, append: bool = False) -> None:
    """Refuse, before any work, an output that cannot be written where it is to go: a file
    is written beside its name and renamed over it (:func:`write_atomic`), and a directory
    (``--plots``) is made with its parents, so what must take a new file is ``path``'s
    directory, or ``path`` itself when it is an existing directory, or else the nearest
    directory that exists. That is tried by making (and removing) an empty file there: the
    permission bits do not tell (a root process passes them, an immutable directory or a
    read-only mount refuses all the same). Without this, an output that failed after
    another was written left the run half done: ``-o`` replaced, then ``--plots`` refused.

    Parameters
    ----------
    name : str
        The option's name, as messages give it.
    path : pathlib.Path
        The output (a file, or with ``directory`` a directory to write into).
    directory : bool, default False
        Whether ``path`` is a directory that outputs are written into.
    append : bool, default False
        Whether ``path`` is appended to where it exists ($GITHUB_STEP_SUMMARY): an
        existing file is then opened for appending (nothing written), its directory not
        tried.

    Raises
    ------
    CredcliError
        If no file can be made there, naming the option, the place and the reason.
    """
    if not directory and _is_stream(path):
        return
    if append and Path(path).is_file():
        try:
            os.close(os.open(path, os.O_WRONLY | os.O_APPEND | getattr(os, "O_NOFOLLOW", 0)))
        except OSError as exc:
            raise CredcliError(
                f"{name} {shown(path)}: cannot be appended to ({_os_reason(exc)})"
            ) from exc
        return
    place = Path(os.path.abspath(path))
    if not directory:
        place = place.parent
    while not place.is_dir() and place != place.parent:
        place = place.parent
    probe = place / _temporary_name("credcli-probe")
    try:
        fd = os.open(
            probe, os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_NOFOLLOW", 0), 0o600
        )
    except OSError as exc:
        raise CredcliError(
            f"{name} {shown(path)}: cannot write in {shown(place)} ({_os_reason(exc)}); "
            "choose another place"
        ) from exc
    os.close(fd)
    with contextlib.suppress(OSError):
        os.unlink(probe)


def check_new_file(name: str, path: Path, keep=()) -> None:
    """Refuse, before it is written, an output ``path`` that is a directory or one of
    ``keep`` (the command's inputs and other outputs): for outputs whose names are known
    only once the work is done (the figures of ``--plots``).

    Parameters
    ----------
    name : str
        The option that writes it, as messages give it.
    path : pathlib.Path
        The file to be written.
    keep : iterable of paths
        Files that must not be overwritten (None items are skipped).

    Raises
    ------
    CredcliError
        If ``path`` is a directory or the same file as one of ``keep``.
    """
    if path.is_dir():
        raise CredcliError(f"{name}: {path} would replace a directory; give another {name}")
    for other in keep:
        if other is not None and _same_file(path, Path(other)) and not _is_stream(path):
            raise CredcliError(
                f"{name}: {path} would overwrite {other}, an input or another output of this "
                f"command; give another {name} directory"
            )


def write_atomic(path: str | Path, text: str | bytes | Iterable[str], inputs=()) -> None:
    """Write ``text`` to ``path``: atomically for a regular file, directly for a device,
    FIFO or /dev/stdout; refuse to overwrite ``inputs``. ``text`` may be pieces of text
    (an iterable of str), written as they come: a large output is never held whole.

    A regular file is written unnamed first (Linux's ``O_TMPFILE``), given a name only when
    it is complete and at once renamed over the target, so that even SIGKILL leaves no
    temporary file behind; elsewhere it is a named temporary file beside the target, removed
    on any error or signal that Python sees. Every step after the directory is opened works
    relative to that open directory (``dir_fd``), and a symbolic link at the final name is
    refused, never followed: a link planted in an output directory, or a directory swapped
    while credcli writes, cannot send the write to a file outside it. A file replaced keeps
    its permission bits; a new one gets those ``open`` would give it.

    Parameters
    ----------
    path : str or pathlib.Path
        The output file.
    text : str, bytes or iterable of str
        What to write: text (as UTF-8; a file name's undecodable bytes, held as
        surrogates, are written as backslash escapes), bytes, or pieces of text written
        one after another.
    inputs : iterable of paths
        Files that must not be overwritten (:func:`check_outputs`).

    Raises
    ------
    CredcliError
        If ``path`` is a directory, one of ``inputs`` or a symbolic link, if its directory
        does not exist, or if it cannot be written (an OSError, described).
    """
    path = Path(path)
    check_outputs({"output": path}, inputs)
    # a name that is not valid UTF-8 (a file name's bytes, held as surrogates) is written
    # as its backslash escape rather than failing the whole output
    if isinstance(text, str):
        data: bytes | Iterable[bytes] = text.encode("utf-8", "backslashreplace")
    elif isinstance(text, bytes):
        data = text
    else:
        data = (piece.encode("utf-8", "backslashreplace") for piece in text)
    try:
        if _is_stream(path):
            _write_stream(path, data)
            return
        parent = path.parent
        if not parent.is_dir():
            raise CredcliError(f"{path}: directory {parent.resolve()} does not exist")
        directory = os.open(parent, os.O_RDONLY | getattr(os, "O_DIRECTORY", 0))
        try:
            if stat.S_ISLNK(_lstat_mode(path.name, directory)):
                raise CredcliError(
                    f"{shown(path)}: is a symbolic link; credcli does not write through links "
                    "(give the file's real path, or remove the link)"
                )
            mode = _mode(path.name, directory)
            if not _write_unnamed(directory, path.name, data, mode):
                _write_named(directory, path, data, mode)
        finally:
            os.close(directory)
    except OSError as exc:
        if isinstance(exc, BrokenPipeError) and str(path) == STDIN:
            raise  # a reader that stopped reading (| head): as without -o, not an error
        raise CredcliError(f"{path}: cannot be written ({_os_reason(exc)})") from exc


def shown(name: object, limit: int = 120) -> str:
    r"""A file name as a message shows it: on one line (a newline in it is escaped) and,
    past ``limit`` characters, shortened in the middle.

    Parameters
    ----------
    name : object
        The name (a path, or anything ``str`` takes).
    limit : int
        The longest name shown whole (120 characters by default); a longer one keeps its
        first ``limit`` − 40 and last 39 characters and says its length.

    Returns
    -------
    str
        The name with backslashes, control characters and non-ASCII characters
        backslash-escaped (Python's ``unicode_escape``), shortened past ``limit``.

    Examples
    --------
    >>> shown("out\nreport.json")
    'out\\nreport.json'
    """
    return shortened(
        str(name).encode("unicode_escape", "backslashreplace").decode("ascii", "replace"), limit
    )


USER_ERRNOS = frozenset(
    getattr(errno, name)
    for name in (
        "ENOSPC",
        "EDQUOT",
        "ENAMETOOLONG",
        "EROFS",
        "EACCES",
        "EPERM",
        "ENXIO",
        "ENOENT",
        "ENOTDIR",
        "EISDIR",
        "ELOOP",
        "EFBIG",
        "EMFILE",
        "ENFILE",
        "EIO",
        "ESTALE",
    )
    if hasattr(errno, name)
)
"""Errors of the user's files and devices (exit 2), not of credcli (exit 3)."""


def describe_os_error(exc: OSError) -> str:
    """One line for an OSError about the user's files: which file, what happened.

    Parameters
    ----------
    exc : OSError
        The error.

    Returns
    -------
    str
        ``"<file>: <reason>"``: the file as :func:`shown` shows it (``standard output``
        when the error names none), and the reason, with what to do for a name too long,
        a full device or a FIFO without a reader.
    """
    where = shown(exc.filename) if exc.filename is not None else "standard output"
    return f"{where}: {_os_reason(exc)}"


def _os_reason(exc: OSError) -> str:
    """Why an OSError happened, in words; what to do for a few common cases."""
    if exc.errno == errno.ENAMETOOLONG:
        return "the file name or path is too long for this system; choose a shorter one"
    if exc.errno == errno.ENOSPC:
        return "no space left on the device; free some or write elsewhere"
    if exc.errno == errno.ENXIO:
        return "a FIFO that no process is reading; start the reader first"
    return exc.strerror or type(exc).__name__


def _write_data(fh, data) -> None:
    """``data``: bytes, or pieces of bytes written one after another."""
    if isinstance(data, bytes):
        fh.write(data)
        return
    for piece in data:
        fh.write(piece)


def _write_stream(path: Path, data) -> None:
    """Standard output (``-``), a device, FIFO or terminal. A FIFO with no reader is
    refused at once (opening it for writing would wait for one forever)."""
    if str(path) == STDIN:
        if sys.stdout is None:  # started with its descriptor closed (credcli … >&-)
            raise CredcliError(f"{path}: standard output is closed; give a file name")
        sys.stdout.flush()
        binary = getattr(sys.stdout, "buffer", None)
        if binary is None:  # a text stream with no bytes beneath (redirected in Python)
            for piece in [data] if isinstance(data, bytes) else data:
                sys.stdout.write(piece.decode("utf-8"))
            return
        _write_data(binary, data)
        binary.flush()
        return
    fd = os.open(path, os.O_WRONLY | getattr(os, "O_NONBLOCK", 0))
    try:
        os.set_blocking(fd, True)
        with os.fdopen(fd, "wb", closefd=False) as fh:
            _write_data(fh, data)
    finally:
        os.close(fd)


def _lstat_mode(name: str, directory: int) -> int:
    """The mode of ``name`` in the open ``directory`` (0 if there is none), links unfollowed."""
    try:
        return os.lstat(name, dir_fd=directory).st_mode
    except FileNotFoundError:
        return 0


def _mode(name: str, directory: int) -> int:
    """The mode of the file replacing ``name``: the existing file's own (a 0600 report
    stays 0600), else the mode open() would give a new file."""
    existing = _lstat_mode(name, directory)
    if stat.S_ISREG(existing):
        return stat.S_IMODE(existing)
    return 0o666 & ~_umask()


def _write_unnamed(directory: int, name: str, data, mode: int) -> bool:
    """Write through an unnamed ``O_TMPFILE`` in the open ``directory``, linked to a
    temporary name and renamed over ``name`` once complete. False where the platform or file
    system has no such files (the caller then uses a named temporary file)."""
    flag = getattr(os, "O_TMPFILE", None)
    if flag is None or not os.path.isdir("/proc/self/fd"):
        return False
    try:
        fd = os.open(".", flag | os.O_WRONLY, 0o600, dir_fd=directory)
        os.fchmod(fd, mode)
    except OSError as exc:
        if exc.errno in (errno.EOPNOTSUPP, errno.EISDIR, errno.EINVAL, errno.ENOENT):
            return False
        raise
    try:
        with os.fdopen(fd, "wb", closefd=False) as fh:
            _write_data(fh, data)
        temporary = _temporary_name(name)
        try:  # a dir_fd makes CPython call linkat(), which follows the /proc link
            os.link(f"/proc/self/fd/{fd}", temporary, dst_dir_fd=directory)
        except OSError:  # a file system without linkat of such files: dropped on close
            return False
    finally:
        os.close(fd)
    try:
        os.replace(temporary, name, src_dir_fd=directory, dst_dir_fd=directory)
    except BaseException:
        os.unlink(temporary, dir_fd=directory)
        raise
    return True


def _temporary_name(name: str) -> str:
    """A hidden name beside ``name``, at most 214 bytes: its first 200 bytes whole characters
    (a file system limits a name to 255 bytes, not characters: 200 characters of ``é`` are
    400)."""
    stem = name[:200]
    while len(os.fsencode(stem)) > 200:
        stem = stem[:-1]
    return f".{stem}.{secrets.token_hex(4)}.tmp"


def _write_named(directory: int, path: Path, data, mode: int) -> None:
    """A named temporary file in the open ``directory``, created exclusively (a name that
    is already there, a link included, is never opened), renamed over ``path``'s name."""
    temporary = _temporary_name(path.name)
    flags = os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_NOFOLLOW", 0)
    try:
        fd = os.open(temporary, flags, 0o600, dir_fd=directory)
    except OSError as exc:
        raise CredcliError(
            f"{path}: cannot write in {path.parent} ({_os_reason(exc)}); choose another place"
        ) from exc
    try:
        os.fchmod(fd, mode)
        with os.fdopen(fd, "wb") as fh:
            _write_data(fh, data)
        os.replace(temporary, path.name, src_dir_fd=directory, dst_dir_fd=directory)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(temporary, dir_fd=directory)
        raise
