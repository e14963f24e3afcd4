"""Inputs that are streams: ``-`` (standard input), a pipe, a FIFO, process substitution.

Reading a log looks at a file more than once (its format from the first lines, then the
table; a bag's index, then its messages), and a stream can be read only once. So a stream
is first copied whole into a private temporary file, which is then read as any file and
removed when the reading is done (also on Ctrl-C or SIGTERM). A gzip stream is unpacked as
it is copied. Messages name the stream as the user did (``<stdin>``, ``/dev/fd/63``), never
the temporary copy.
"""

from __future__ import annotations

import contextlib
import gzip
import os
import shutil
import stat
import sys
import tempfile
from collections.abc import Iterator
from pathlib import Path

from credcli.errors import CredcliError
from credcli.io.files import memory_budget

STDIN = "-"
_GZIP_MAGIC = b"\x1f\x8b"
_CHUNK = 1 << 20


def is_stream(path: str | Path) -> bool:
    """``-``, or an existing path that is neither a regular file nor a directory."""
    if str(path) == STDIN:
        return True
    try:
        mode = os.stat(path).st_mode
    except (OSError, ValueError):
        return False
    return not (stat.S_ISREG(mode) or stat.S_ISDIR(mode))


def stream_limit(directory: str) -> int:
    """Bytes a stream's copy may take: half the physical memory (the log must then fit in
    memory) and 90 % of the free space where it is written, whichever is less."""
    try:
        free = shutil.disk_usage(directory).free
    except OSError:
        free = memory_budget()
    return int(min(memory_budget(), 0.9 * free))


def display_name(path: str | Path) -> str:
    return "<stdin>" if str(path) == STDIN else str(path)


def _suffix(head: bytes, name: str) -> str:
    """A suffix the readers recognise, from the first bytes (or the stream's own name)."""
    if head.startswith(b"PAR1"):
        return ".parquet"
    if head.startswith(b"#ROSBAG"):
        return ".bag"
    suffixes = "".join(Path(name).suffixes[-2:]).lower().removesuffix(".gz")
    return suffixes if suffixes in (".csv", ".txt", ".tum") else ".csv"


@contextlib.contextmanager
def readable(path: str | Path) -> Iterator[Path]:
    """``path`` itself, or for a stream a complete private copy of it (removed at the end)."""
    if not is_stream(path):
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
            source = stack.enter_context(open(path, "rb"))  # noqa: SIM115
        if source.peek(2)[:2] == _GZIP_MAGIC:
            source = stack.enter_context(gzip.GzipFile(fileobj=source, mode="rb"))
        directory = stack.enter_context(tempfile.TemporaryDirectory(prefix="credcli-stream-"))
        try:
            first = source.read(_CHUNK)
            local = Path(directory) / f"stream{_suffix(first[:8], name)}"
            limit = stream_limit(directory)
            with open(local, "wb") as out:
                out.write(first)
                copied = len(first)
                while chunk := source.read(_CHUNK):
                    copied += len(chunk)
                    if copied > limit:
                        raise CredcliError(
                            f"{name}: the stream goes on past {limit / 2**30:.3g} GiB (an endless "
                            "input?); credcli keeps a stream's copy within half the memory "
                            "and 90 % of the free space of its temporary directory"
                        )
                    out.write(chunk)
        except EOFError as exc:
            raise CredcliError(
                f"{name}: the gzip stream ends early (truncated?); check how it was written"
            ) from exc
        if local.stat().st_size == 0:
            raise CredcliError(
                f"{name}: the stream carried no data; expected a log (a header row and epoch rows)"
            )
        try:
            yield local
        except CredcliError as exc:
            raise CredcliError(exc.message.replace(str(local), name), exc.parameter) from exc
