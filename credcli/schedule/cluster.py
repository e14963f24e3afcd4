"""Work on a Dask distributed cluster (``--scheduler``; the ``credcli[dask]`` extra).

Imported only when ``--scheduler`` is given: without it nothing of Dask is loaded and
``--jobs`` uses local processes (credcli.schedule.pool).

- ``--scheduler tcp://host:8786`` (or ``CREDCLI_SCHEDULER``) connects a
  ``distributed.Client`` to a running scheduler (``dask scheduler`` and ``dask worker``);
- ``--scheduler local:N`` starts a ``LocalCluster`` of N single-threaded worker processes
  on the loopback interface, for the dashboard on one machine.

Results come back in task order whatever the order tasks finish in, and every random
stream is derived per unit of work (segment name, or trial number), so the output is
byte-identical to the local run for any number of workers. Tasks of a worker that dies are
run again on the others (the scheduler's ``distributed.scheduler.allowed-failures``, 3 by
default); an error raised by a task (a bad log) is not retried: it cancels the rest and is
raised here as it was raised there.

**Trust.** Results come back from the workers by pickle, so a scheduler and its workers can
run code in this process: connect only to a cluster you control. Plain ``tcp://`` is
unauthenticated and unencrypted (so are ``ws://`` and ``ucx://``); credcli refuses such a
scheduler that is not on the loopback interface unless :data:`REMOTE_OPT_IN` is set to 1
(which names the risk). For anything off this machine use ``tls://`` with certificates
(Dask's ``distributed.comm.tls`` settings), which credcli passes to Dask as it is.
"""

from __future__ import annotations

import ipaddress
import logging
import os
import re
import signal
import socket
import struct
import sys
import tempfile
from collections.abc import Callable

from credcli.errors import CredcliError

INSTALL_HINT = "pip install 'credcli[dask]' (dask and distributed)"
CONNECT_TIMEOUT = "10s"

_LOCAL = re.compile(r"^local:(\d+)$")


CONNECT_SECONDS = 10.0
REMOTE_OPT_IN = "CREDCLI_ALLOW_PLAINTEXT_REMOTE_SCHEDULER"
"""Set to 1 to connect to a plain tcp:// scheduler off the loopback interface: anyone on
the path can then read the logs and run code in credcli (pickled results)."""


def _check_loopback(host: str, address: str) -> None:
    """Refuse a plain-TCP scheduler ``host`` (of ``address``, for the message) that is not
    loopback, unless opted in (`REMOTE_OPT_IN`)."""
    if os.environ.get(REMOTE_OPT_IN) == "1":
        return
    try:
        found = {info[4][0] for info in socket.getaddrinfo(host, None)}
    except OSError as exc:
        raise CredcliError(f"`scheduler` {address}: cannot resolve {host} ({exc})") from exc
    remote = sorted(a for a in found if not ipaddress.ip_address(a.split("%")[0]).is_loopback)
    if remote:
        raise CredcliError(
            f"`scheduler` {address}: a plaintext scheduler off this machine ({remote[0]}) "
            "is unauthenticated and its workers can run code in credcli; use tls:// with "
            f"certificates (docs/scale.md), or set {REMOTE_OPT_IN}=1 to accept the risk"
        )


PLAINTEXT_SCHEMES = ("ws://", "ucx://")
"""Dask's schemes other than tcp:// that carry the pickled results without TLS: refused off
the loopback interface as plain tcp:// is (wss:// and tls:// are Dask's TLS)."""

_TCP = re.compile(r"^(?:tcp://)?\[?([^\]/]+?)\]?(?::(\d+))?/?$")


def probe_scheduler(address: str, seconds: float = CONNECT_SECONDS) -> None:
    """Refuse an address where no Dask scheduler answers, within ``seconds``.

    A scheduler writes its handshake as soon as a connection opens (distributed's
    ``Listener.on_connection``), and a client waits for it without a time limit: an HTTP
    server there never writes first (the client would hang), or it answers the client's
    own handshake with "HTTP/1.1 400" (which Dask reads as a frame length and fails on
    with a MemoryError). So the first bytes are read here, with a deadline. Only plain TCP
    addresses are probed (tls://, ucx:// and others go to Dask as they are).

    Parameters
    ----------
    address : str
        The scheduler's address, ``tcp://host:port`` or ``host:port`` (port 8786 by
        default).
    seconds : float, default `CONNECT_SECONDS`
        How long to wait for the connection and for the first bytes.

    Raises
    ------
    CredcliError
        If the address is malformed, a plain tcp:// host is off the loopback interface
        without `REMOTE_OPT_IN`, nothing answers in time, the connection fails or is
        closed at once, or an HTTP server answers.
    """
    text = address.strip()
    if text.lower().startswith(PLAINTEXT_SCHEMES):  # as unauthenticated as tcp://
        scheme, rest = text.split("://", 1)
        m = _TCP.match("tcp://" + rest)
        if not m:
            raise CredcliError(f"`scheduler` {address}: expected {scheme}://host:port")
        _check_loopback(m.group(1), address)
        return  # Dask's own connection reports the rest
    m = _TCP.match(text)
    if text.count("://") and not text.startswith("tcp://"):
        return
    if not m:
        raise CredcliError(f"`scheduler` {address}: expected tcp://host:port or local:N")
    host, port = m.group(1), int(m.group(2) or 8786)
    _check_loopback(host, address)
    try:
        with socket.create_connection((host, port), timeout=seconds) as sock:
            sock.settimeout(seconds)
            first = sock.recv(8)
    except TimeoutError:
        raise CredcliError(
            f"`scheduler` {address}: no answer from a Dask scheduler within {seconds:g} s "
            "(something else listens there, or a firewall holds the connection)"
        ) from None
    except OSError as exc:
        raise CredcliError(
            f"`scheduler` {address}: cannot connect ({exc.strerror or exc}); start one with "
            "`dask scheduler` and `dask worker ADDRESS`, or use local:N"
        ) from exc
    if first.startswith(b"HTTP") or first[:1] in (b"<", b"{"):
        raise CredcliError(
            f"`scheduler` {address}: an HTTP server answers there, not a Dask scheduler "
            "(the dashboard's port? the scheduler's is 8786 by default)"
        )
    if not first:
        raise CredcliError(
            f"`scheduler` {address}: the connection was closed at once; not a Dask scheduler"
        )


TLS_SETTINGS = (
    "distributed.comm.tls.ca-file, .client.cert and .client.key (or the variables "
    "DASK_DISTRIBUTED__COMM__TLS__CA_FILE, __CLIENT__CERT, __CLIENT__KEY)"
)


def _check_tls(address: str) -> None:
    """A ``tls://`` scheduler needs this client's certificates, which Dask reads from its
    configuration (``distributed.comm.tls``): the authority that signed the cluster's
    certificates, and a certificate and key for this client (Dask's TLS is mutual)."""
    if not address.strip().lower().startswith("tls://"):
        return
    from distributed.security import Security

    security = Security()
    missing = [
        name
        for name, value in (
            ("ca-file", security.tls_ca_file),
            ("client.cert", security.tls_client_cert),
        )
        if not value
    ]
    if missing:
        raise CredcliError(
            f"`scheduler` {address}: tls:// needs this client's certificates, and Dask's "
            f"configuration has no {' or '.join(missing)}; set {TLS_SETTINGS}"
        )


LOCAL_PER_CORE = 4
"""Most local:N workers per core: each is a process with its own memory, all started
before any work (local:100000 started processes until it was stopped)."""


def max_local_workers() -> int:
    """The most workers ``local:N`` may start: `LOCAL_PER_CORE` per core.

    Returns
    -------
    int
        ``LOCAL_PER_CORE`` × the cores of this machine (1 core where it does not say).
    """
    return LOCAL_PER_CORE * (os.cpu_count() or 1)


def _local_cluster(workers: int):
    """A LocalCluster whose processes leave Ctrl-C to this one (the terminal sends it to the
    whole process group: each worker would print its own traceback), keep their scratch files
    in a directory removed on close, and whose semaphores the resource tracker does not
    warn about when a signal ends the run."""
    import dask
    from distributed import LocalCluster

    quiet = "ignore::UserWarning:multiprocessing.resource_tracker"
    if quiet not in sys.warnoptions:  # the tracker process takes this process's -W options
        sys.warnoptions.append(quiet)
    scratch = tempfile.TemporaryDirectory(prefix="credcli-dask-")
    dask.config.set({"temporary-directory": scratch.name})  # the scheduler's scratch too
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)  # inherited by the nannies
    try:
        cluster = LocalCluster(
            n_workers=workers,
            threads_per_worker=1,
            processes=True,
            host="127.0.0.1",
            dashboard_address="127.0.0.1:0",
            local_directory=scratch.name,
            silence_logs=logging.CRITICAL,  # task errors are reported here, once
        )
    except BaseException:
        scratch.cleanup()
        raise
    finally:
        signal.signal(signal.SIGINT, previous)
    cluster._credcli_scratch = scratch  # removed with the cluster (DaskRunner.close)
    return cluster


def _kind(exc: BaseException) -> str:
    """An exception's name, with its module unless built in (struct.error, not error)."""
    kind = type(exc)
    return kind.__name__ if kind.__module__ == "builtins" else f"{kind.__module__}.{kind.__name__}"


class DaskRunner:
    """A connection to a cluster that maps a top-level function over tasks, in order.

    A context manager: closed on exit.

    Parameters
    ----------
    address : str
        ``local:N`` for a LocalCluster of N single-threaded worker processes on the
        loopback interface, or a scheduler's address (probed first, `probe_scheduler`).
    announce : callable, optional
        Called once with a line naming the workers and the dashboard.

    Raises
    ------
    CredcliError
        If Dask is not installed, ``local:N`` has N < 1 or is malformed, or the scheduler
        cannot be reached, is not a Dask scheduler, or lacks this client's TLS
        certificates.
    """

    def __init__(self, address: str, announce: Callable[[str], None] | None = None) -> None:
        try:
            from distributed import Client
        except ImportError as exc:
            raise CredcliError(f"`scheduler` needs Dask: {INSTALL_HINT}") from exc
        self.cluster = None
        local = _LOCAL.match(address.strip())
        try:
            if local:
                workers = int(local.group(1))
                if workers < 1:
                    raise CredcliError(f"`scheduler` local:N needs N >= 1; got {address}")
                if workers > max_local_workers():  # each a process, all started at once
                    raise CredcliError(
                        f"`scheduler` {address}: at most {max_local_workers()} local workers "
                        f"({LOCAL_PER_CORE} per core of this machine); a cluster across "
                        "machines is tls://host:port"
                    )
                self.cluster = _local_cluster(workers)
                self.client = Client(self.cluster)
            elif address.strip().startswith("local:"):  # not localhost:8786, an address
                raise CredcliError(f"`scheduler` {address}: expected local:N, e.g. local:2")
            else:
                probe_scheduler(address)
                _check_tls(address)
                self.client = Client(address, timeout=CONNECT_TIMEOUT)
        except CredcliError:
            self.close()
            raise
        except (OSError, TimeoutError, ValueError) as exc:
            self.close()
            raise CredcliError(
                f"`scheduler` {address}: cannot connect ({type(exc).__name__}: {exc}); start "
                "one with `dask scheduler` and `dask worker ADDRESS`, or use local:N"
            ) from exc
        except (MemoryError, EOFError, OverflowError, TypeError, KeyError, struct.error) as exc:
            # what a peer that is no Dask scheduler sends (a short frame, a frame length of
            # 2**63) fails inside distributed's protocol code: a bad address, not a bug here
            self.close()
            raise CredcliError(
                f"`scheduler` {address}: the peer does not speak Dask's protocol "
                f"({_kind(exc)}: {str(exc)[:120]}); check the address"
            ) from exc
        if announce is not None:
            workers = len(self.client.scheduler_info().get("workers", {}))
            link = self.client.dashboard_link
            announce(f"Dask: {workers} worker(s) at {address}; dashboard {link}")

    def map(
        self, func: Callable, tasks: list, progress: Callable | None = None, weights=None
    ) -> list:
        """``[func(t) for t in tasks]`` on the cluster, in task order.

        Parameters
        ----------
        func : callable
            A top-level function (the workers import it).
        tasks : list
            Its arguments, one task each.
        progress : callable, optional
            Called as ``progress(done, total)`` as tasks finish, counting each task as its
            weight.
        weights : iterable of int, optional
            Each task's weight (default 1: tasks; e.g. segments or trials per task).

        Returns
        -------
        list
            ``func(task)`` for each task, in task order.

        Raises
        ------
        Exception
            The first error a task raised, as it was raised there; the other tasks are
            cancelled.
        """
        from distributed import as_completed

        weights = [1] * len(tasks) if weights is None else list(weights)
        total = sum(weights)
        futures = self.client.map(func, tasks, pure=False)
        index = {f.key: k for k, f in enumerate(futures)}
        results: list = [None] * len(futures)
        done = 0
        try:
            for future, result in as_completed(futures, with_results=True):
                k = index[future.key]
                results[k] = result
                done += weights[k]
                if progress is not None:
                    progress(done, total)
        except BaseException:
            self.client.cancel(futures)
            raise
        return results

    def close(self) -> None:
        """Close the client, and the LocalCluster with its scratch directory if this
        runner started one."""
        client = getattr(self, "client", None)
        if client is not None:
            client.close()
        if self.cluster is not None:
            try:
                self.cluster.close()
            finally:
                self.cluster._credcli_scratch.cleanup()

    def __enter__(self) -> DaskRunner:
        return self

    def __exit__(self, *exc) -> None:
        self.close()
