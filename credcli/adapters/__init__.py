"""Logs from the estimator libraries people use, each an optional extra imported on use:

- ``credcli.adapters.filterpy``: a ``filterpy.common.Saver`` or the arrays of
  ``KalmanFilter.batch_filter`` with the truth (``pip install credcli[filterpy]``);
- ``credcli.adapters.stonesoup``: a Stone Soup ``Track`` with its ``GroundTruthPath``,
  or a tracker's tracks with the ground truth paths (``pip install credcli[stonesoup]``).

Each returns an ``EstimatorLog`` (``credcli.io.logs``) for ``credcli.diagnose_log``,
``credcli.testing.assert_credible`` or ``credcli.write_log``. The adapters read the
libraries' objects by their documented attributes and do not import the libraries.
"""
