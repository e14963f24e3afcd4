"""Work on a Dask distributed cluster (``--scheduler``; the ``credcli[dask]`` extra).

Imported only when ``--scheduler`` is given: without it nothing of Dask is loaded and
``--jobs`` uses local processes (credcli.parallel).

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
"""

from __future__ import annotations

import logging
import re
from collections.abc import Callable

from credcli.errors import CredcliError

INSTALL_HINT = "pip install 'credcli[dask]' (dask and distributed)"
CONNECT_TIMEOUT = "10s"

_LOCAL = re.compile(r"^local:(\d+)$")


class DaskRunner:
    """A connection to a cluster that maps a top-level function over tasks, in order."""

    def __init__(self, address: str, announce: Callable[[str], None] | None = None) -> None:
        try:
            from distributed import Client, LocalCluster
        except ImportError as exc:
            raise CredcliError(f"--scheduler needs Dask: {INSTALL_HINT}") from exc
        self.cluster = None
        local = _LOCAL.match(address.strip())
        try:
            if local:
                workers = int(local.group(1))
                if workers < 1:
                    raise CredcliError(f"--scheduler local:N needs N >= 1; got {address}")
                self.cluster = LocalCluster(
                    n_workers=workers,
                    threads_per_worker=1,
                    processes=True,
                    host="127.0.0.1",
                    dashboard_address="127.0.0.1:0",
                    silence_logs=logging.CRITICAL,  # task errors are reported here, once
                )
                self.client = Client(self.cluster)
            elif address.strip().startswith("local:"):  # not localhost:8786, an address
                raise CredcliError(f"--scheduler {address}: expected local:N, e.g. local:2")
            else:
                self.client = Client(address, timeout=CONNECT_TIMEOUT)
        except CredcliError:
            self.close()
            raise
        except (OSError, TimeoutError, ValueError) as exc:
            self.close()
            raise CredcliError(
                f"--scheduler {address}: cannot connect ({type(exc).__name__}: {exc}); start "
                "one with `dask scheduler` and `dask worker ADDRESS`, or use local:N"
            ) from exc
        if announce is not None:
            workers = len(self.client.scheduler_info().get("workers", {}))
            link = self.client.dashboard_link
            announce(f"Dask: {workers} worker(s) at {address}; dashboard {link}")

    def map(
        self, func: Callable, tasks: list, progress: Callable | None = None, weights=None
    ) -> list:
        """``[func(t) for t in tasks]`` on the cluster, in task order. ``progress(done,
        total)`` is called as tasks finish, counting each task as its weight (default 1:
        tasks; e.g. segments or trials per task)."""
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
        client = getattr(self, "client", None)
        if client is not None:
            client.close()
        if self.cluster is not None:
            self.cluster.close()

    def __enter__(self) -> DaskRunner:
        return self

    def __exit__(self, *exc) -> None:
        self.close()
