"""What credcli asks of the operating system below every other module: the C library, and
giving freed memory back (read by the readers and by the worker processes alike)."""

from __future__ import annotations

import functools
import sys


def release_free_memory() -> None:
    """Give back to the system what reading a log freed: Arrow's allocator keeps freed
    buffers for reuse, and glibc keeps freed heap chunks below its adaptive trim threshold,
    where the diagnosis's large arrays (mapped afresh) cannot reuse them: the peak memory
    that follows is lower (docs/performance.md)."""
    if "pyarrow" in sys.modules:
        sys.modules["pyarrow"].default_memory_pool().release_unused()
    try:
        libc().malloc_trim(0)
    except (OSError, AttributeError):  # not glibc
        pass


@functools.lru_cache(maxsize=1)
def libc():
    """The C library (found once; ``find_library`` runs ``ldconfig``, so glibc's usual name
    is tried first)."""
    import ctypes

    try:
        return ctypes.CDLL("libc.so.6")
    except OSError:
        import ctypes.util

        return ctypes.CDLL(ctypes.util.find_library("c"))
