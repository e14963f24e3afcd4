"""filterpy's Kalman filters: a ``Saver`` or ``batch_filter``'s arrays, with the truth.

filterpy keeps the state as a column (dim_x, 1) and its covariance ``P`` (dim_x, dim_x);
``Saver.save()`` appends both after each step (posterior ``x``/``P``, and the priors
``x_prior``/``P_prior``), and ``KalmanFilter.batch_filter(zs)`` returns the posterior
means (N, dim_x, 1) and covariances (N, dim_x, dim_x) first. credcli diagnoses the states
``states`` (indices into the state vector; all by default) against the truth.

>>> import numpy as np
>>> from filterpy.kalman import KalmanFilter
>>> from filterpy.common import Saver
>>> kf = KalmanFilter(dim_x=2, dim_z=1)
>>> kf.F, kf.H, kf.R, kf.Q = np.array([[1.0, 1.0], [0.0, 1.0]]), np.array([[1.0, 0.0]]), 1.0, 0.01 * np.eye(2)
>>> saver = Saver(kf)
>>> for z in np.arange(30.0):
...     kf.predict(); kf.update(z); saver.save()
>>> truth = np.c_[np.arange(30.0), np.ones(30)]
>>> log_from_saver(saver, truth).dim, log_from_saver(saver, truth, states=[0]).dim
(2, 1)
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from credcli.errors import CredcliError
from credcli.io.arrays import log_from_arrays
from credcli.io.logs import EstimatorLog


def log_from_saver(
    saver,
    truth,
    *,
    states: Sequence[int] | None = None,
    prior: bool = False,
    time=None,
    segment=None,
    source: str = "filterpy Saver",
) -> EstimatorLog:
    """A log from a ``filterpy.common.Saver`` of a Kalman filter and the true states.

    Parameters
    ----------
    saver : filterpy.common.Saver
        The filter's Saver, before or after its ``to_array()``, with ``save()`` called
        after each step.
    truth : array_like, shape (N, dim_x) or (N, len(states))
        The true states ((N, dim_x, 1) columns too).
    states : sequence of int, optional
        The indices of the states to diagnose; all by default.
    prior : bool
        Diagnose the predictions (``x_prior``/``P_prior``) instead of the posteriors.
    time, segment : array_like, shape (N,), optional
        As for [credcli.log_from_arrays][credcli.api.log_from_arrays].
    source : str
        The log's name in messages and records.

    Returns
    -------
    EstimatorLog
        The chosen states of the estimates against the truth, with their block of ``P``.

    Raises
    ------
    CredcliError
        If the Saver holds no ``x``/``P`` (or ``x_prior``/``P_prior``), and as
        [log_from_batch][credcli.adapters.filterpy.log_from_batch] for the arrays.

    Examples
    --------
    >>> import numpy as np
    >>> from filterpy.kalman import KalmanFilter
    >>> from filterpy.common import Saver
    >>> kf = KalmanFilter(dim_x=2, dim_z=1)
    >>> kf.F, kf.H = np.array([[1.0, 1.0], [0.0, 1.0]]), np.array([[1.0, 0.0]])
    >>> kf.R, kf.Q = 1.0, 0.01 * np.eye(2)
    >>> saver = Saver(kf)
    >>> for z in np.arange(30.0):
    ...     kf.predict(); kf.update(z); saver.save()
    >>> truth = np.c_[np.arange(30.0), np.ones(30)]
    >>> log = log_from_saver(saver, truth, prior=True)
    >>> log.n, log.dim
    (30, 2)
    """
    names = ("x_prior", "P_prior") if prior else ("x", "P")
    saved = []
    for name in names:
        values = getattr(saver, name, None)
        if values is None or len(values) == 0:
            raise CredcliError(
                f"saver: no saved '{name}'; create the Saver on the filter and call save() "
                "after each step"
            )
        saved.append(values)
    return log_from_batch(*saved, truth, states=states, time=time, segment=segment, source=source)


def log_from_batch(
    means,
    covariances,
    truth,
    *,
    states: Sequence[int] | None = None,
    time=None,
    segment=None,
    source: str = "filterpy batch_filter",
) -> EstimatorLog:
    """A log from filterpy's arrays: ``batch_filter``'s first two results, or an RTS
    smoother's, and the true states.

    Parameters
    ----------
    means : array_like, shape (N, dim_x, 1) or (N, dim_x)
        The state estimates.
    covariances : array_like, shape (N, dim_x, dim_x)
        Their covariances ``P``.
    truth : array_like, shape (N, dim_x) or (N, len(states))
        The true states ((N, dim_x, 1) or (N,) too).
    states : sequence of int, optional
        The indices of the states to diagnose; all by default.
    time, segment : array_like, shape (N,), optional
        As for [credcli.log_from_arrays][credcli.api.log_from_arrays].
    source : str
        The log's name in messages and records.

    Returns
    -------
    EstimatorLog
        The chosen states of the estimates against the truth, with their block of the
        covariances.

    Raises
    ------
    CredcliError
        If the shapes of ``means`` and ``covariances`` do not match, ``states`` are not
        indices into the state, ``truth`` has neither shape, and as
        [credcli.log_from_arrays][credcli.api.log_from_arrays] for the values.

    Examples
    --------
    >>> import numpy as np
    >>> from filterpy.kalman import KalmanFilter
    >>> kf = KalmanFilter(dim_x=2, dim_z=1)
    >>> kf.F, kf.H = np.array([[1.0, 1.0], [0.0, 1.0]]), np.array([[1.0, 0.0]])
    >>> kf.R, kf.Q = 1.0, 0.01 * np.eye(2)
    >>> means, covariances, _, _ = kf.batch_filter(np.arange(30.0))
    >>> truth = np.c_[np.arange(30.0), np.ones(30)]
    >>> log = log_from_batch(means, covariances, truth, states=[1])  # the velocity
    >>> log.n, log.dim, log.source
    (30, 1, 'filterpy batch_filter')
    """
    means = np.asarray(means, dtype=float)
    if means.ndim == 3 and means.shape[2] == 1:
        means = means[:, :, 0]
    covariances = np.asarray(covariances, dtype=float)
    if means.ndim != 2 or covariances.shape != (means.shape[0], means.shape[1], means.shape[1]):
        raise CredcliError(
            f"means and covariances: expected (N, dim_x, 1) and (N, dim_x, dim_x); got "
            f"{means.shape} and {covariances.shape}"
        )
    dim_x = means.shape[1]
    index = np.arange(dim_x) if states is None else np.asarray(states, dtype=int)
    if index.ndim != 1 or index.size == 0 or index.min() < 0 or index.max() >= dim_x:
        raise CredcliError(f"states: indices into a state of dim_x = {dim_x}; got {list(index)}")
    truth = np.asarray(truth, dtype=float)
    if truth.ndim == 3 and truth.shape[2] == 1:
        truth = truth[:, :, 0]
    if truth.ndim == 1:
        truth = truth[:, None]
    if truth.ndim == 2 and truth.shape[1] == dim_x and index.size != dim_x:
        truth = truth[:, index]
    if truth.shape != (means.shape[0], index.size):
        raise CredcliError(
            f"truth: expected ({means.shape[0]}, {dim_x}) or ({means.shape[0]}, {index.size}) "
            f"for the chosen states; got {truth.shape}"
        )
    return log_from_arrays(
        truth,
        means[:, index],
        covariances[:, index[:, None], index[None, :]],
        time=time,
        segment=segment,
        source=source,
    )
