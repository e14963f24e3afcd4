"""Work spread over local processes, with results in task order.

Each worker is a process with one BLAS thread (``threadpoolctl``; the thread variables are
also set before a spawn, since OpenBLAS reads them when it loads): the products of one
segment or one trial are small, and several BLAS threads per process would only fight over
the cores. Workers are forked where that is safe (:func:`start_method`), so that they start
with this process's modules loaded instead of importing them again. Results come back in
the order of the tasks, whatever finishes first, so the output is the same for any number
of processes.
"""

from __future__ import annotations

import contextlib
import errno
import importlib
import os
import signal
import sys
import threading
from collections.abc import Callable, Iterable, Iterator

from credcli.system import libc

_BLAS_THREAD_VARIABLES = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")


def single_threaded_blas() -> None:
    """Ask BLAS for one thread, unless the user set a number: every product credcli runs is
    per segment or per trial, and the cores are shared by processes (``--jobs``), not by
    BLAS threads. Effective only before numpy is imported (the command line sets it first)."""
    for key in _BLAS_THREAD_VARIABLES:
        os.environ.setdefault(key, "1")


def default_jobs() -> int:
    """The number of cores this process may use.

    Returns
    -------
    int
        The cores in this process's affinity mask (Linux), else ``os.cpu_count()``; at
        least 1.
    """
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not on Linux
        return max(1, os.cpu_count() or 1)


def _set_up_worker() -> None:
    """A worker's set-up: one BLAS thread, freed memory kept for reuse."""
    keep_freed_memory()
    try:
        from threadpoolctl import threadpool_limits

        threadpool_limits(1, user_api="blas")
    except ImportError:  # the environment variables set before the spawn still hold
        pass


PR_SET_PDEATHSIG = 1  # linux/prctl.h


def _set_up_pool_worker() -> None:
    """The set-up of a worker process this process started (not a Dask worker, whose
    signals are its nanny's): :func:`follow_parent`, then :func:`_set_up_worker`."""
    follow_parent()
    _set_up_worker()


def follow_parent() -> None:
    """A worker's signals: it ends with its parent, even one killed by SIGKILL (Linux's
    ``PR_SET_PDEATHSIG``), dies at once on SIGTERM (a forked worker would otherwise inherit
    the command line's handler), and ignores Ctrl-C, which the terminal sends to the whole
    process group: the parent stops the work and reports it once, instead of every worker
    printing its own traceback."""
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    if sys.platform == "linux":
        try:
            libc().prctl(PR_SET_PDEATHSIG, int(signal.SIGKILL), 0, 0, 0)
        except (OSError, AttributeError):
            pass


def _import_threadpoolctl() -> None:
    """Load threadpoolctl here, so that forked workers do not each import it."""
    try:
        import threadpoolctl  # noqa: F401
    except ImportError:
        pass


_LIMITED = []

MMAP_THRESHOLD = 64 << 20
"""glibc allocations below this come from the heap, not from a fresh mmap (bytes), while a
task's segments are no longer than one chunk of epochs (:func:`allocator_for`)."""

LONG_MMAP_THRESHOLD = 8 << 20
"""The threshold while a task holding a segment longer than one chunk of epochs
(:data:`credcli.engine.linalg.EPOCH_CHUNK`) is diagnosed: its arrays of N numbers (2·10⁶
epochs, d = 2: 15–61 MiB) are mapped and given back when freed; under 64 MiB they came
from the heap, and the holes they left were kept (the 2·10⁶-epoch segment peaked at
561 MiB resident, 50–120 MiB of the heap free by malloc's own count). Not for shorter
segments: those of 2,000–4,000 epochs, whose N × N pairs were then mapped afresh each
time, took 3–6 % more wall time (docs/performance.md)."""

_OWNED = []  # non-empty in a process whose allocator credcli set (copied into forked workers)


def keep_freed_memory() -> None:
    """Keep the memory of freed arrays below a threshold in glibc's heap, for the next ones:
    in the processes credcli owns (the command line's and the workers'), not a library
    caller's. The threshold is :data:`MMAP_THRESHOLD` until a task sets it
    (:func:`allocator_for`).

    By default glibc maps a fresh block for each array above a threshold it adapts, and
    gives the top of its heap back to the system once more than twice that is free: the
    diagnosis's temporaries (the pair matrix, its float32 copy, the flipped products: a
    few MiB per segment, made and freed segment after segment) would be mapped again each
    time, and touching fresh pages costs about as much as the arithmetic
    (docs/performance.md). A larger array is still mapped and unmapped. This also undoes
    ``MALLOC_TRIM_THRESHOLD_``, which Dask's nannies set to 64 KiB (and which slows the
    diagnosis in Dask workers). Not glibc: nothing to do."""
    _OWNED[:] = [True]
    _set_threshold(MMAP_THRESHOLD)


def allocator_for(long_segments: bool) -> None:
    """Set the threshold for a task, in a process whose allocator credcli set
    (:func:`keep_freed_memory`); elsewhere nothing.

    Parameters
    ----------
    long_segments : bool
        The task holds a segment longer than one chunk of epochs: the threshold is then
        :data:`LONG_MMAP_THRESHOLD`, else :data:`MMAP_THRESHOLD`.
    """
    if _OWNED:
        _set_threshold(LONG_MMAP_THRESHOLD if long_segments else MMAP_THRESHOLD)


def _set_threshold(threshold: int) -> None:
    try:
        c = libc()
        c.mallopt(-3, threshold)  # M_MMAP_THRESHOLD
        c.mallopt(-1, 2 * threshold)  # M_TRIM_THRESHOLD
    except (OSError, AttributeError):
        pass


def prepare_worker() -> None:
    """On a worker's first task (Dask's workers have no initializer): one BLAS thread, and
    freed memory kept for reuse (:func:`keep_freed_memory`)."""
    if not _LIMITED:
        _set_up_worker()
        _LIMITED.append(True)


@contextlib.contextmanager
def one_blas_thread():
    """BLAS limited to one thread in this process, for work made of many small products
    (one segment, one trial), where extra BLAS threads only contend for the cores."""
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:
        yield
        return
    with threadpool_limits(1, user_api="blas"):
        yield


def start_method() -> str:
    """``fork`` on Linux while this process runs one thread and has not loaded pyarrow
    (whose C++ thread pools are invisible to ``threading``), else ``spawn``.

    A forked worker starts at once with every module of this process loaded; a spawned one
    first imports numpy, scipy and the engine again, CPU time taken from the work itself
    on a machine of few cores (docs/performance.md). Forking a process with other threads
    could copy a lock one of them holds, so then the workers are spawned. Buffered output
    is flushed first, so that no worker writes it a second time when it exits.

    Returns
    -------
    str
        ``"fork"`` or ``"spawn"``, a multiprocessing start method.
    """
    if sys.platform != "linux" or threading.active_count() != 1 or "pyarrow" in sys.modules:
        return "spawn"
    for stream in (sys.stdout, sys.stderr):
        if stream is not None:
            stream.flush()
    return "fork"


def _warm_up(module: str) -> None:
    """Worker: import a module now, so that it is loaded when the first task arrives."""
    importlib.import_module(module)


class WorkerPool:
    """Worker processes with one BLAS thread each, started (and, when spawned, warmed up by
    importing ``warm``) before the work is known, e.g. while the main process reads logs.

    Parameters
    ----------
    jobs : int
        The number of worker processes.
    warm : str or None, optional
        A module each spawned worker imports at once (forked workers have it already).
    """

    def __init__(self, jobs: int, warm: str | None = None) -> None:
        import multiprocessing as mp
        from concurrent.futures import ProcessPoolExecutor

        method = start_method()
        self.forked = method == "fork"
        if method == "fork":
            _import_threadpoolctl()
        saved = {k: os.environ.get(k) for k in _BLAS_THREAD_VARIABLES}
        os.environ.update({k: "1" for k in _BLAS_THREAD_VARIABLES})
        try:
            self.executor = ProcessPoolExecutor(
                max_workers=jobs, mp_context=mp.get_context(method), initializer=_set_up_pool_worker
            )
            if warm and method == "spawn":  # a forked worker has this process's modules
                for _ in range(jobs):
                    self.executor.submit(_warm_up, warm)
        finally:
            for key, value in saved.items():
                if value is None:
                    os.environ.pop(key, None)
                else:
                    os.environ[key] = value

    def map(self, func: Callable, tasks: list, before_fork: Callable | None = None) -> Iterator:
        """Results in task order; the workers are shut down at the end, and stopped at once
        when the map ends early (an error, Ctrl-C, SIGTERM).

        Parameters
        ----------
        func : callable
            A top-level function (the workers import it).
        tasks : list
            Its arguments, one task each.
        before_fork : callable, optional
            Called here, with no arguments, just before forked workers start (at the first
            task): what it loads, every worker has without loading it again. Not called
            where the workers are spawned.

        Yields
        ------
        object
            ``func(task)`` for each task, in task order.
        """
        try:
            if before_fork is not None and self.forked:
                before_fork()
            yield from self.executor.map(func, tasks)
        except BaseException:
            self.stop()
            raise
        finally:
            self.close()

    def close(self) -> None:
        """Shut the workers down, waiting for their current tasks; tasks not yet started
        are cancelled."""
        self.executor.shutdown(cancel_futures=True)

    def stop(self) -> None:
        """End the workers now, without waiting for their current tasks.

        A worker killed while it sends a result leaves half a message in the result pipe,
        whose reader (the executor's thread) would wait for the rest for ever; a task being
        written to a worker killed before it read it blocks its writer for ever: this
        process holds the other end of both pipes, so a SIGTERM could hang a run. Once the
        workers are dead, this process's own ends are closed, so the reader meets the end
        of the pipe and the writer a broken pipe, and the shutdown returns. The executor's
        thread may then fail the futures already cancelled or close a pipe end twice: those
        errors are not shown (:func:`_quiet_cancelled_futures`)."""
        _quiet_cancelled_futures()
        processes = list(getattr(self.executor, "_processes", {}).values())
        for process in processes:
            if process.is_alive():
                process.kill()
        for process in processes:
            process.join(timeout=10)
        ends = (("_result_queue", "_writer"), ("_call_queue", "_reader"))
        for queue, end in ends:
            pipe = getattr(getattr(self.executor, queue, None), end, None)
            if pipe is not None:
                pipe.close()
        self.executor.shutdown(wait=True, cancel_futures=True)


def _quiet_cancelled_futures() -> None:
    """Do not show the two errors the process pool's thread may raise after
    :meth:`WorkerPool.stop`: the InvalidStateError of Python 3.11 when it fails a future
    already cancelled (fixed in later Pythons, which ignore it), and EBADF when it closes
    the call pipe's end that ``stop`` is closing at the same moment; either would show as
    a thread traceback. Every other exception of any thread is shown as before."""
    from concurrent.futures import InvalidStateError
    from concurrent.futures.process import _ExecutorManagerThread

    shown = threading.excepthook
    if getattr(shown, "_credcli_quiet", False):
        return

    def hook(args) -> None:
        if isinstance(args.thread, _ExecutorManagerThread) and (
            args.exc_type is InvalidStateError
            or (isinstance(args.exc_value, OSError) and args.exc_value.errno == errno.EBADF)
        ):
            return
        shown(args)

    hook._credcli_quiet = True
    threading.excepthook = hook


def ordered_map(
    func: Callable, tasks: Iterable, jobs: int, before_fork: Callable | None = None
) -> Iterator:
    """``map(func, tasks)`` in ``jobs`` worker processes (in this process for jobs <= 1).

    ``func`` must be a top-level function (workers import it). Every task is submitted at
    once; the iterator yields results in task order and shuts the workers down at the end,
    or when it is closed early (an error, Ctrl-C).

    Parameters
    ----------
    func : callable
        A top-level function.
    tasks : iterable
        Its arguments, one task each; taken as they come when run in this process.
    jobs : int
        The number of worker processes; at most one per task is started. With
        ``jobs <= 1`` or a single task, the tasks run here with BLAS on one thread.
    before_fork : callable, optional
        As :meth:`WorkerPool.map` takes it (not called when the tasks run here).

    Yields
    ------
    object
        ``func(task)`` for each task, in task order.
    """
    if jobs > 1:
        tasks = list(tasks)
    if jobs <= 1 or len(tasks) <= 1:  # in this process, taking the tasks as they come
        with one_blas_thread():
            yield from map(func, tasks)
        return
    yield from WorkerPool(min(jobs, len(tasks))).map(func, tasks, before_fork)
