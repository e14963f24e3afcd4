"""Inputs that are streams: ``-`` (standard input), a pipe, a FIFO, process substitution.

Reading a log looks at a file more than once (its format from the first lines, then the
table; a bag's index, then its messages), and a stream can be read only once. So a stream
is first copied whole into a private temporary file, which is then read as any file and
removed when the reading is done (also on Ctrl-C or SIGTERM). A compressed file or stream
(gzip, bzip2, xz) is unpacked the same way, as it is copied, so that what it holds is
measured before it is read: a few megabytes that unpack to more numbers than fit in memory
are refused, not read. Messages name the stream as the user did (``<stdin>``,
``/dev/fd/63``), never the temporary copy.
"""

from __future__ import annotations

import bz2
import contextlib
import gzip
import lzma
import os
import select
import shutil
import stat
import sys
import tempfile
import zlib
from collections.abc import Iterator
from pathlib import Path

from credcli.errors import CredcliError
from credcli.io.files import STDIN, memory_budget  # noqa: F401 (STDIN: its name here)

_CHUNK = 1 << 20
_UNPACKERS = (
    (b"\x1f\x8b", lambda raw: gzip.GzipFile(fileobj=raw, mode="rb")),
    (b"BZh", bz2.BZ2File),
    (b"\xfd7zXZ\x00", lzma.LZMAFile),
)
"""The compressed formats unpacked here, by their first bytes."""
_TEXT_SUFFIXES = (".csv", ".txt", ".tum")
_SEPARATORS = (b",", b"\n", b" ", b"\t")
_LONGEST_FIELD = _CHUNK
"""Bytes a stream's text may hold with no separator: no number, name or line of a log is a
mebibyte long, while unpacked data of one repeated byte (a gzip bomb) run to gigabytes."""
_BYTES_PER_FIELD = 16
"""Memory a text log's field takes as it is read: a float64, and about as much again while
pandas parses."""
TEXT_HEAD = 4096
"""The first bytes of a text log that the readers look at for its encoding."""
_DAMAGED = (EOFError, zlib.error, lzma.LZMAError, gzip.BadGzipFile)
"""What unpacking raises on data that end early or are not what their first bytes say."""


def is_stream(path: str | Path) -> bool:
    """Whether ``path`` is a stream: ``-``, or an existing path that is neither a regular
    file nor a directory (a pipe, a FIFO, ``/dev/fd/63``, a device).

    Parameters
    ----------
    path : str or pathlib.Path
        The path as the user gave it.

    Returns
    -------
    bool
        True for ``-`` and for such a path; False for a regular file, a directory, or a
        path that does not exist or cannot be examined.
    """
    if str(path) == STDIN:
        return True
    try:
        mode = os.stat(path).st_mode
    except (OSError, ValueError):
        return False
    return not (stat.S_ISREG(mode) or stat.S_ISDIR(mode))


WRITER_WAIT = 10.0
"""Seconds a named FIFO may stay silent once opened for reading. Without a writer, opening
it waits for ever (as ``cat`` does); a process that writes one sends its first bytes, or
closes it, well within this."""


def _named_fifo(path: str | Path) -> bool:
    """Whether ``path`` is a FIFO with a name in the file system: not standard input and
    not a pipe that a shell handed over (``/dev/fd/63``, whose writer exists already)."""
    name = str(path)
    if name == STDIN or name.startswith(("/dev/fd/", "/proc/")):
        return False
    try:
        return stat.S_ISFIFO(os.stat(path).st_mode)
    except (OSError, ValueError):
        return False


def open_input(path: str | Path):
    """``path`` opened for reading in binary; a named FIFO must send data or close within
    :data:`WRITER_WAIT` seconds.

    Parameters
    ----------
    path : str or pathlib.Path
        A file, pipe or FIFO.

    Returns
    -------
    io.BufferedReader
        The open file, blocking as usual once data have come.

    Raises
    ------
    CredcliError
        If ``path`` is a named FIFO that no process writes to within :data:`WRITER_WAIT`
        seconds.
    OSError
        As ``open`` raises it (a missing or unreadable path).
    """
    if not _named_fifo(path) or not hasattr(select, "poll"):
        return open(path, "rb")  # noqa: SIM115 (the caller closes it)
    fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK)
    try:
        poller = select.poll()
        poller.register(fd, select.POLLIN | select.POLLHUP)
        if not poller.poll(int(WRITER_WAIT * 1000)):
            raise CredcliError(
                f"{display_name(path)}: a FIFO that no process wrote to within "
                f"{WRITER_WAIT:g} s; start its writer first, or give a file"
            )
        os.set_blocking(fd, True)
        return os.fdopen(fd, "rb")
    except BaseException:
        os.close(fd)
        raise


def _unpacker(head: bytes):
    return next((opener for magic, opener in _UNPACKERS if head.startswith(magic)), None)


def is_compressed(path: str | Path) -> bool:
    """Whether ``path`` is a file whose first bytes are those of gzip, bzip2 or xz.

    Parameters
    ----------
    path : str or pathlib.Path
        The file.

    Returns
    -------
    bool
        True when its first bytes are gzip's, bzip2's or xz's magic; False also for a path
        that cannot be opened.
    """
    try:
        with open(path, "rb") as fh:
            return _unpacker(fh.read(6)) is not None
    except (OSError, ValueError):
        return False


def needs_copy(path: str | Path) -> bool:
    """Whether ``path`` is read through a private copy (:func:`readable`): a stream, or a
    compressed file.

    Parameters
    ----------
    path : str or pathlib.Path
        The path as the user gave it.

    Returns
    -------
    bool
        ``is_stream(path) or is_compressed(path)``.
    """
    return is_stream(path) or is_compressed(path)


def stream_limit(directory: str) -> int:
    """Bytes a stream's copy may take: half the physical memory (the log must then fit in
    memory) and 90 % of the free space where it is written, whichever is less.

    Parameters
    ----------
    directory : str
        The directory the copy is written in.

    Returns
    -------
    int
        min(``memory_budget()``, 0.9 × the free bytes in ``directory``); 0.9 ×
        ``memory_budget()`` when the free space cannot be read.
    """
    try:
        free = shutil.disk_usage(directory).free
    except OSError:
        free = memory_budget()
    return int(min(memory_budget(), 0.9 * free))


def display_name(path: str | Path) -> str:
    """The name messages give ``path``: ``<stdin>`` for ``-``, else the path as given.

    Parameters
    ----------
    path : str or pathlib.Path
        The path as the user gave it.

    Returns
    -------
    str
        Its name in messages.

    Examples
    --------
    >>> display_name("-"), display_name("/dev/fd/63")
    ('<stdin>', '/dev/fd/63')
    """
    return "<stdin>" if str(path) == STDIN else str(path)


def _suffix(head: bytes, name: str) -> str:
    """A suffix the readers recognise, from the first bytes (or the stream's own name)."""
    if head.startswith(b"PAR1"):
        return ".parquet"
    if head.startswith(b"#ROSBAG"):
        return ".bag"
    suffixes = "".join(Path(name).suffixes[-2:]).lower()
    for packed in (".gz", ".bz2", ".xz"):
        suffixes = suffixes.removesuffix(packed)
    return suffixes if suffixes in _TEXT_SUFFIXES else ".csv"


@contextlib.contextmanager
def readable(path: str | Path) -> Iterator[Path]:
    """``path`` itself, or for a stream or a compressed file a complete private copy of it,
    unpacked (removed at the end).

    The copy is written in a private temporary directory, named with a suffix the readers
    recognise (from its first bytes, else from the stream's own name, else ``.csv``), and
    removed when the ``with`` block ends, on an error too. A CredcliError raised in the
    block that names the copy is raised again naming the stream as the user did.

    Parameters
    ----------
    path : str or pathlib.Path
        A file, ``-`` (standard input), a pipe or FIFO, or a gzip, bzip2 or xz file or
        stream.

    Yields
    ------
    pathlib.Path
        A regular, uncompressed file to read: ``path`` itself when it needs no copy.

    Raises
    ------
    CredcliError
        If ``-`` is a terminal or ``path`` a character or block device; if compressed data
        end early or are damaged; if the copy would pass ``stream_limit`` bytes or, for
        text, more fields than fit in memory as numbers; if text holds NUL bytes past its
        first ``TEXT_HEAD`` bytes; or if the stream holds no data.
    """
    if not needs_copy(path):
        yield Path(path)
        return
    name = display_name(path)
    with contextlib.ExitStack() as stack:
        if str(path) == STDIN:
            if sys.stdin is None or sys.stdin.isatty():
                raise CredcliError(
                    "- means standard input, but it is a terminal; pipe a log into it "
                    "(cat log.csv | credcli diagnose -) or name a file"
                )
            source = sys.stdin.buffer
        else:
            mode = os.stat(path).st_mode
            if stat.S_ISCHR(mode) or stat.S_ISBLK(mode):
                raise CredcliError(
                    f"{name}: is a device, not a log; give a file, a pipe or - (standard input)"
                )
            source = stack.enter_context(open_input(path))
        unpacker = _unpacker(source.peek(6)[:6])
        if unpacker is not None:
            source = stack.enter_context(unpacker(source))
        directory = stack.enter_context(tempfile.TemporaryDirectory(prefix="credcli-stream-"))
        try:
            first = source.read(_CHUNK)
            local = Path(directory) / f"stream{_suffix(first[:8], name)}"
            _copy(source, first, local, name, stream_limit(directory))
        except (*_DAMAGED, OSError) as exc:
            if not isinstance(exc, _DAMAGED) and (unpacker is None or exc.errno is not None):
                raise  # bzip2 reports damaged data as an OSError with no errno
            raise CredcliError(
                f"{name}: the compressed stream ends early or is damaged ({exc}); "
                "check how it was written"
            ) from exc
        if local.stat().st_size == 0:
            raise CredcliError(
                f"{name}: holds no data; expected a log (a header row and epoch rows)"
            )
        try:
            yield local
        except CredcliError as exc:
            raise CredcliError(exc.message.replace(str(local), name), exc.parameter) from exc


def _copy(source, first: bytes, local: Path, name: str, limit: int) -> None:
    """Copy ``source`` (``first`` already read from it) to ``local``, stopping with an error
    past ``limit`` bytes or, for text, past the fields that fit in memory as numbers.

    Text whose first bytes hold NUL is copied no further: the readers refuse it from those
    bytes (as UTF-16 or binary). A NUL further on is refused here."""
    text = local.suffix in _TEXT_SUFFIXES
    budget = memory_budget() // _BYTES_PER_FIELD
    fields = copied = run = 0  # run: bytes since the last separator
    with open(local, "wb") as out:
        chunk = first
        while chunk:
            copied += len(chunk)
            if copied > limit:
                raise CredcliError(
                    f"{name}: goes on past {limit / 2**30:.3g} GiB (an endless input?); "
                    "credcli keeps a stream's or compressed file's copy within half the "
                    "memory and 90 % of the free space of its temporary directory"
                )
            if text:
                if b"\x00" in chunk:
                    if chunk is first and b"\x00" in first[:TEXT_HEAD]:
                        out.write(first[:TEXT_HEAD])
                        return
                    raise CredcliError(
                        f"{name}: holds NUL bytes past its first {TEXT_HEAD:,} bytes, so it is "
                        "not CSV or text; check how it was written"
                    )
                fields += sum(chunk.count(sep) for sep in _SEPARATORS)
                run = _unseparated(chunk, run, name)
                if fields > budget:
                    raise CredcliError(
                        f"{name}: unpacks to over {fields:,} fields, more than "
                        f"{memory_budget() / 2**30:.3g} GiB as numbers (half this machine's "
                        "memory); split the log or read it on a larger machine"
                    )
            out.write(chunk)
            chunk = source.read(_CHUNK)


def _unseparated(chunk: bytes, run: int, name: str) -> int:
    """The bytes since the last separator at the end of ``chunk``, ``run`` of them before
    it; an error past :data:`_LONGEST_FIELD`. A stretch inside one chunk is shorter than the
    chunk, so only stretches that cross chunks are measured: exact for a limit of a chunk."""
    first = min((i for i in (chunk.find(sep) for sep in _SEPARATORS) if i >= 0), default=-1)
    if run + (len(chunk) if first < 0 else first) > _LONGEST_FIELD:
        raise CredcliError(
            f"{name}: holds over {_LONGEST_FIELD // 2**20} MiB with no separator (comma, space, "
            "tab or line end), so it is not a log's text; check how it was written"
        )
    if first < 0:
        return run + len(chunk)
    return len(chunk) - 1 - max(chunk.rfind(sep) for sep in _SEPARATORS)
