"""Filters from public estimator libraries, run as their users run them, for the measured
tables of issue 24 and the adapters' tests: filterpy's ``KalmanFilter`` and Stone Soup's
Kalman predictor/updater (and its single-target tracker), on a 2-D constant-velocity
target, in the four cases of :data:`LIBRARY_TUNINGS`.

The truth follows the nearly-constant-velocity model (white-noise acceleration of spectral
density q per axis; Bar-Shalom et al. 2001, Sec. 6.3.2) and is measured in position with
noise R = r I. The filter's Q, R and P0 are the true ones times the tuning's factors; the
"bias" case adds an unmodelled constant offset to the x measurements. The libraries are
imported on use (extras ``filterpy`` and ``stonesoup``).
"""

from __future__ import annotations

import datetime as _dt

import numpy as np

from credcli.engine.config import Label
from credcli.engine.rng import RngLike, as_generator
from credcli.io.logs import EstimatorLog
from credcli.studies.filters import TUNINGS, FilterTuning

LIBRARY_TUNINGS = TUNINGS | {"bias": FilterTuning(bias=1.0)}
"""The four cases of the per-library tables: those of the EKF study, with the unmodelled
bias a 1σ (of R) offset on the x measurements."""

EXPECTED = {
    "right": Label.CREDIBLE.value,
    "too-small": Label.OPTIMISM.value,
    "too-large": Label.PESSIMISM.value,
    "bias": Label.BIAS.value,
}
"""What each case should be called."""

Q_DENSITY = 0.05
R_VARIANCE = 0.75
DT = 1.0
P0 = np.diag([R_VARIANCE, 1.0, R_VARIANCE, 1.0])
"""The true initial uncertainty (P0 of a correctly tuned filter)."""


def cv_matrices(dt: float = DT, q: float = Q_DENSITY) -> tuple[np.ndarray, np.ndarray]:
    r"""F and Q of a 2-D nearly-constant-velocity state (x, vx, y, vy).

    Parameters
    ----------
    dt : float
        Time step in s (default ``DT``, 1 s).
    q : float
        Spectral density of the white-noise acceleration per axis (default
        ``Q_DENSITY``).

    Returns
    -------
    F : numpy.ndarray, shape (4, 4)
        The transition matrix, block diagonal in (x, vx) and (y, vy).
    Q : numpy.ndarray, shape (4, 4)
        The process noise covariance, block diagonal.

    Notes
    -----
    Per axis (Bar-Shalom et al. 2001, Sec. 6.3.2)

    .. math::

        F_1 = \begin{pmatrix} 1 & \Delta t \\ 0 & 1 \end{pmatrix},\quad
        Q_1 = q \begin{pmatrix} \Delta t^3/3 & \Delta t^2/2 \\
        \Delta t^2/2 & \Delta t \end{pmatrix}.

    Examples
    --------
    >>> f, q = cv_matrices(dt=1.0, q=3.0)
    >>> f[:2, :2].tolist(), q[:2, :2].tolist()
    ([[1.0, 1.0], [0.0, 1.0]], [[1.0, 1.5], [1.5, 3.0]])
    """
    f1 = np.array([[1.0, dt], [0.0, 1.0]])
    q1 = q * np.array([[dt**3 / 3, dt**2 / 2], [dt**2 / 2, dt]])
    z = np.zeros((2, 2))
    return np.block([[f1, z], [z, f1]]), np.block([[q1, z], [z, q1]])


def cv_truth(steps: int, seed: RngLike = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A true nearly-constant-velocity path, its position measurements and the filter's
    initial state.

    The truth starts at (0, 1, 0, 1) and follows :func:`cv_matrices`' model; the
    measurements are its positions plus N(0, ``R_VARIANCE`` I) noise.

    Parameters
    ----------
    steps : int
        Number of epochs (one per ``DT``).
    seed : RngLike
        Seed or generator of the process noise, the measurement noise and the initial
        error (default 0).

    Returns
    -------
    truth : numpy.ndarray, shape (steps, 4)
        True states (x, vx, y, vy).
    z : numpy.ndarray, shape (steps, 2)
        Position measurements (x, y), without bias.
    x0 : numpy.ndarray, shape (4,)
        The filter's initial state: the first true state plus an error drawn from
        N(0, ``P0``).
    """
    rng = as_generator(seed)
    f, q = cv_matrices()
    chol = np.linalg.cholesky(q)
    x = np.empty((steps, 4))
    x[0] = [0.0, 1.0, 0.0, 1.0]
    kicks = rng.standard_normal((steps, 4)) @ chol.T
    for k in range(1, steps):  # a study's generator, not a hot path
        x[k] = f @ x[k - 1] + kicks[k]
    z = x[:, [0, 2]] + np.sqrt(R_VARIANCE) * rng.standard_normal((steps, 2))
    x0 = x[0] + np.sqrt(np.diag(P0)) * rng.standard_normal(4)
    return x, z, x0


def filterpy_run(tuning: FilterTuning, seed: RngLike = 0, steps: int = 300) -> EstimatorLog:
    """filterpy's KalmanFilter with a Saver, as its documentation runs it.

    An update at the first epoch, then a prediction and an update at each later one; the
    log is made by :func:`credcli.adapters.filterpy.log_from_saver`.

    Parameters
    ----------
    tuning : FilterTuning
        The filter's factors on Q, R and P0, and the unmodelled offset added to the x
        measurements in standard deviations of R (e.g. a value of :data:`LIBRARY_TUNINGS`).
    seed : RngLike
        Seed or generator of the truth and the measurements (:func:`cv_truth`) (default 0).
    steps : int
        Number of epochs, one per ``DT`` (default 300).

    Returns
    -------
    EstimatorLog
        The filter's posterior states (all four) and covariances against the truth, named
        "filterpy".
    """
    from filterpy.common import Saver
    from filterpy.kalman import KalmanFilter

    from credcli.adapters.filterpy import log_from_saver

    truth, z, x0 = cv_truth(steps, seed)
    z = z + [tuning.bias * np.sqrt(R_VARIANCE), 0.0]
    f, q = cv_matrices()
    kf = KalmanFilter(dim_x=4, dim_z=2)
    kf.F, kf.Q = f, q * tuning.q_factor
    kf.H = np.array([[1.0, 0, 0, 0], [0, 0, 1.0, 0]])
    kf.R = R_VARIANCE * tuning.r_factor * np.eye(2)
    kf.x = x0[:, None].copy()
    kf.P = P0 * tuning.p0_factor
    saver = Saver(kf)
    for k in range(steps):
        if k:
            kf.predict()
        kf.update(z[k])
        saver.save()
    return log_from_saver(saver, truth, time=np.arange(steps) * DT, source="filterpy")


def stonesoup_run(tuning: FilterTuning, seed: RngLike = 0, steps: int = 300) -> EstimatorLog:
    """Stone Soup's KalmanPredictor and KalmanUpdater over its own models, the loop of its
    Kalman filter tutorial; the truth and detections drawn as for :func:`filterpy_run`.

    The log is made by :func:`credcli.adapters.stonesoup.log_from_track`.

    Parameters
    ----------
    tuning : FilterTuning
        The filter's factors on Q, R and P0, and the unmodelled offset added to the x
        measurements in standard deviations of R (e.g. a value of :data:`LIBRARY_TUNINGS`).
    seed : RngLike
        Seed or generator of the truth and the measurements (:func:`cv_truth`) (default 0).
    steps : int
        Number of epochs, one per ``DT`` (default 300).

    Returns
    -------
    EstimatorLog
        The filter's posterior states (all four) and covariances against the truth, named
        "stonesoup".
    """
    from stonesoup.models.measurement.linear import LinearGaussian
    from stonesoup.models.transition.linear import (
        CombinedLinearGaussianTransitionModel,
        ConstantVelocity,
    )
    from stonesoup.predictor.kalman import KalmanPredictor
    from stonesoup.types.detection import Detection
    from stonesoup.types.groundtruth import GroundTruthPath, GroundTruthState
    from stonesoup.types.hypothesis import SingleHypothesis
    from stonesoup.types.state import GaussianState
    from stonesoup.types.track import Track
    from stonesoup.updater.kalman import KalmanUpdater

    from credcli.adapters.stonesoup import log_from_track

    truth_x, z, x0 = cv_truth(steps, seed)
    z = z + [tuning.bias * np.sqrt(R_VARIANCE), 0.0]
    start = _dt.datetime(2024, 5, 1)
    times = [start + _dt.timedelta(seconds=k * DT) for k in range(steps)]
    truth = GroundTruthPath([GroundTruthState(x, timestamp=t) for x, t in zip(truth_x, times)])
    q = Q_DENSITY * tuning.q_factor
    transition = CombinedLinearGaussianTransitionModel([ConstantVelocity(q), ConstantVelocity(q)])
    measurement = LinearGaussian(4, (0, 2), R_VARIANCE * tuning.r_factor * np.eye(2))
    predictor, updater = KalmanPredictor(transition), KalmanUpdater(measurement)
    prior = GaussianState(x0[:, None], P0 * tuning.p0_factor, timestamp=times[0])
    track = Track()
    for k, t in enumerate(times):
        detection = Detection(z[k][:, None], timestamp=t, measurement_model=measurement)
        predicted = predictor.predict(prior, timestamp=t) if k else prior
        prior = updater.update(SingleHypothesis(predicted, detection))
        track.append(prior)
    return log_from_track(track, truth, source="stonesoup")


def stonesoup_tracker_run(seed: int = 0, steps: int = 300) -> EstimatorLog:
    """Stone Soup's SingleTargetTracker (nearest-neighbour association, measurement
    initiator, deleter) on its own single-target simulator, right tuning: the tracks and
    ground-truth paths a tracker user has, paired by :func:`log_from_tracks`.

    Parameters
    ----------
    seed : int
        Seed of the simulator's transition model; the measurement model and the detection
        simulator take ``seed + 1`` and ``seed + 2`` (default 0).
    steps : int
        Number of simulated epochs, one per ``DT`` (default 300).

    Returns
    -------
    EstimatorLog
        One segment per track, each against the ground-truth path it follows, named
        "stonesoup tracker".
    """
    from stonesoup.dataassociator.neighbour import NearestNeighbour
    from stonesoup.deleter.time import UpdateTimeStepsDeleter
    from stonesoup.hypothesiser.distance import DistanceHypothesiser
    from stonesoup.initiator.simple import SimpleMeasurementInitiator
    from stonesoup.measures import Mahalanobis
    from stonesoup.models.measurement.linear import LinearGaussian
    from stonesoup.models.transition.linear import (
        CombinedLinearGaussianTransitionModel,
        ConstantVelocity,
    )
    from stonesoup.predictor.kalman import KalmanPredictor
    from stonesoup.simulator.simple import (
        SimpleDetectionSimulator,
        SingleTargetGroundTruthSimulator,
    )
    from stonesoup.tracker.simple import SingleTargetTracker
    from stonesoup.types.array import CovarianceMatrix, StateVector
    from stonesoup.types.state import GaussianState
    from stonesoup.updater.kalman import KalmanUpdater

    from credcli.adapters.stonesoup import log_from_tracks

    start = _dt.datetime(2024, 5, 1)
    transition = CombinedLinearGaussianTransitionModel(
        [ConstantVelocity(Q_DENSITY), ConstantVelocity(Q_DENSITY)], seed=seed
    )
    measurement = LinearGaussian(4, (0, 2), R_VARIANCE * np.eye(2), seed=seed + 1)
    initial = GaussianState(StateVector([0, 1, 0, 1]), CovarianceMatrix(np.zeros((4, 4))), start)
    truths = SingleTargetGroundTruthSimulator(
        transition_model=transition,
        initial_state=initial,
        timestep=_dt.timedelta(seconds=DT),
        number_steps=steps,
    )
    detector = SimpleDetectionSimulator(
        groundtruth=truths,
        measurement_model=measurement,
        meas_range=np.array([[-1e9, 1e9], [-1e9, 1e9]]),
        detection_probability=1.0,
        clutter_rate=0.0,
        seed=seed + 2,
    )
    predictor, updater = KalmanPredictor(transition), KalmanUpdater(measurement)
    hypothesiser = DistanceHypothesiser(predictor, updater, Mahalanobis(), missed_distance=5)
    prior = GaussianState(StateVector([0, 0, 0, 0]), CovarianceMatrix(np.diag([0, 1, 0, 1])), start)
    tracker = SingleTargetTracker(
        initiator=SimpleMeasurementInitiator(prior, measurement_model=measurement),
        deleter=UpdateTimeStepsDeleter(time_steps_since_update=3),
        detector=detector,
        data_associator=NearestNeighbour(hypothesiser),
        updater=updater,
    )
    tracks: set = set()
    for _, current in tracker:
        tracks.update(current)
    return log_from_tracks(tracks, truths.groundtruth_paths, source="stonesoup tracker")
