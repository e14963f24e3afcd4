"""Where work runs, in one room: in this process, in local worker processes, or on a Dask
cluster.

- :mod:`credcli.schedule.plans`: which segments of which logs are diagnosed where
  (``--jobs``, ``--scheduler``), with results in the same order on every path;
- :mod:`credcli.schedule.pool`: the local worker processes (one BLAS thread each,
  results in task order);
- :mod:`credcli.schedule.cluster`: the Dask client (``--scheduler``, the ``credcli[dask]``
  extra), imported only when a scheduler is named.
"""
