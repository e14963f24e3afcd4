"""Files: TOML configs in, outputs written safely.

Outputs never clobber an input and never leave a half-written file: a regular file is
written to a temporary file beside it and renamed over the target; anything else that
already exists (a device such as /dev/null, a FIFO, /dev/stdout on a pipe or terminal) is
written directly, since renaming over it would replace it with a regular file.
"""

from __future__ import annotations

import os
import stat
import tempfile
from pathlib import Path

from credcli.errors import CredcliError


def read_toml(path: str | Path) -> dict:
    """A TOML file's tables; a missing, non-UTF-8 or invalid file is a CredcliError."""
    try:
        import tomllib
    except ModuleNotFoundError:  # Python 3.10
        import tomli as tomllib
    path = Path(path)
    if path.is_dir():
        raise CredcliError(f"{path}: is a directory, expected a TOML config file")
    if not path.is_file():
        raise CredcliError(f"{path}: config file not found")
    try:
        text = path.read_bytes().decode("utf-8")
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
    """An existing target that is not a regular file or directory (device, FIFO, socket)."""
    try:
        mode = path.stat().st_mode
    except OSError:
        return False
    return not (stat.S_ISREG(mode) or stat.S_ISDIR(mode))


def check_outputs(outputs: dict[str, Path | None], inputs=()) -> None:
    """Refuse before any work: an output that is an input, two outputs on one path, or an
    output that is a directory. ``outputs`` maps an option name to its path (or None)."""
    given = [(name, Path(p)) for name, p in outputs.items() if p is not None]
    for name, path in given:
        if path.is_dir():
            raise CredcliError(f"{name} {path}: is a directory; give a file name")
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


def write_atomic(path: str | Path, text: str | bytes, inputs=()) -> None:
    """Write ``text`` to ``path``: atomically for a regular file (temporary file, then
    rename), directly for a device, FIFO or /dev/stdout; refuse to overwrite ``inputs``."""
    path = Path(path)
    check_outputs({"output": path}, inputs)
    data = text.encode() if isinstance(text, str) else text
    if _is_stream(path):
        try:
            with open(path, "wb") as fh:
                fh.write(data)
        except OSError as exc:
            raise CredcliError(f"{path}: cannot be written ({exc.strerror})") from exc
        return
    target = path.resolve()
    if not target.parent.is_dir():
        raise CredcliError(f"{path}: directory {target.parent} does not exist")
    try:
        fd, tmp = tempfile.mkstemp(
            dir=target.parent, prefix=f".{target.name[:200]}.", suffix=".tmp"
        )
    except OSError as exc:
        raise CredcliError(
            f"{path}: cannot write in {target.parent} ({exc.strerror}); choose another place"
        ) from exc
    try:
        os.fchmod(fd, 0o666 & ~_umask())  # mkstemp makes 0600; give the usual mode
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
        os.replace(tmp, target)
    except OSError as exc:
        Path(tmp).unlink(missing_ok=True)
        raise CredcliError(f"{path}: cannot be written ({exc.strerror})") from exc
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
