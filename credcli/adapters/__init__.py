"""Logs from the estimator libraries people use, each an optional extra imported on use:

- :mod:`credcli.adapters.filterpy`: a ``filterpy.common.Saver`` or the arrays of
  ``KalmanFilter.batch_filter`` with the truth (``pip install credcli[filterpy]``);
- :mod:`credcli.adapters.stonesoup`: a Stone Soup ``Track`` with its ``GroundTruthPath``,
  or a tracker's tracks with the ground truth paths (``pip install credcli[stonesoup]``).

Each returns an :class:`~credcli.io.logs.EstimatorLog` for :func:`credcli.diagnose_log`,
:func:`credcli.testing.assert_credible` or :func:`credcli.write_log`. The adapters read the
libraries' objects by their documented attributes and do not import the libraries.
"""
