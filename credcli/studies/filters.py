"""Filter logs to develop the rule on: an extended Kalman filter's errors and covariances,
with the long memory, rotating covariances and export rates of real filter output.

``ekf_runs`` simulates M independent runs of a target moving with nearly constant
velocity (white-noise acceleration of intensity ``q``), tracked by an EKF from range and
bearing measurements of a sensor at the origin (noise std ``range_std`` and
``bearing_std``). The filter's own model may be mistuned (its q, R and P0 scaled) or miss a
range bias; its error e_k = x_k − x̂_k and claimed covariance P_k of the position are the
log. With slow dynamics the Kalman gain is small, so the errors stay correlated for
seconds (hundreds of epochs at 100 Hz), and P_k turns as the bearing to the target turns,
as in real filter output.

``thinned`` exports a run at a lower rate (every k-th epoch, as a logger at 10 Hz would),
for the rate-invariance checks. ``rotating_bias_log`` makes claimed covariances that rotate
and are strongly anisotropic, with errors drawn from them plus a constant bias, which
changes sign in whitened space.

The runs are simulated together (arrays over runs); the loop is over time steps, which a
filter needs.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from credcli.engine.rng import RngLike, as_generator


@dataclass(frozen=True)
class FilterTuning:
    """The filter's model against the truth's: factors on q, R and P0, and a bias in the
    measurements that the filter does not model.

    Attributes
    ----------
    q_factor : float
        Factor on the process noise Q the filter uses (default 1.0: the true Q).
    r_factor : float
        Factor on the measurement noise R the filter uses (default 1.0).
    p0_factor : float
        Factor on the initial covariance P0 the filter starts from (default 1.0).
    bias : float
        Constant offset added to the measurements, which the filter does not model, in
        the study's own unit: metres of range in :func:`ekf_runs`, standard deviations of
        R on the x measurement in :mod:`credcli.studies.libraries` (default 0.0).
    """

    q_factor: float = 1.0
    r_factor: float = 1.0
    p0_factor: float = 1.0
    bias: float = 0.0


TUNINGS = {
    "right": FilterTuning(),
    "too-small": FilterTuning(0.25, 0.25, 0.25),
    "too-large": FilterTuning(4.0, 4.0, 4.0),
    "bias": FilterTuning(bias=0.5),
}
"""The four cases of the measured tables: right tuning, Q/R/P0 4× too small (optimism),
4× too large (pessimism), an unmodelled range bias (smm)."""


@dataclass(frozen=True)
class FilterRuns:
    """M runs of N epochs of a filter's position errors and claimed covariances.

    Attributes
    ----------
    errors : numpy.ndarray, shape (M, N, 2)
        Position errors e_k = x_k − x̂_k of each run.
    cov : numpy.ndarray, shape (M, N, 2, 2)
        The filter's claimed position covariances P_k.
    time : numpy.ndarray, shape (N,)
        Epoch times in s, shared by the runs.
    """

    errors: np.ndarray
    cov: np.ndarray
    time: np.ndarray

    def thinned(self, every: int) -> FilterRuns:
        """Every ``every``-th epoch: the same runs exported at a lower rate.

        Parameters
        ----------
        every : int
            Keep epochs 0, ``every``, 2 ``every``, … (as a logger at 1/``every`` of the
            filter's rate would).

        Returns
        -------
        FilterRuns
            The same runs with N / ``every`` epochs (rounded up).

        Examples
        --------
        >>> runs = ekf_runs(runs=2, rate_hz=10.0, duration_s=2.0)
        >>> slow = runs.thinned(5)
        >>> runs.errors.shape, slow.errors.shape, slow.cov.shape, np.round(slow.time, 6).tolist()
        ((2, 20, 2), (2, 4, 2), (2, 4, 2, 2), [0.1, 0.6, 1.1, 1.6])
        """
        return FilterRuns(self.errors[:, ::every], self.cov[:, ::every], self.time[::every])


def ekf_runs(
    runs: int = 20,
    rate_hz: float = 100.0,
    duration_s: float = 60.0,
    tuning: FilterTuning = FilterTuning(),
    q: float = 0.01,
    range_std: float = 0.5,
    bearing_std: float = 0.01,
    seed: RngLike = 0,
) -> FilterRuns:
    r"""M EKF runs of a range-bearing tracker (see the module docstring).

    The target starts 60 m from the sensor at 2 m/s across the line of sight, its true
    initial state drawn from N(x̄_0, P0) with P0 = diag(4, 4, 0.25, 0.25) (m², m²/s²); the
    filter starts at x̄_0 with ``tuning.p0_factor`` P0. Each epoch is a prediction and an
    update (Joseph form); the error and the position block of P are recorded after the
    update.

    Parameters
    ----------
    runs : int
        Number M of independent runs (default 20).
    rate_hz : float
        Filter rate in Hz: the time step is 1 / ``rate_hz`` (default 100).
    duration_s : float
        Length of each run in s; N = round(``duration_s`` × ``rate_hz``) epochs
        (default 60).
    tuning : FilterTuning
        The filter's factors on q, R and P0 and the unmodelled range bias (m)
        (default: the true model).
    q : float
        True acceleration noise intensity of the nearly-constant-velocity model (m²/s³)
        (default 0.01).
    range_std : float
        True range noise std in m (default 0.5).
    bearing_std : float
        True bearing noise std in rad (default 0.01).
    seed : RngLike
        Seed or generator of the truth, the initial error and the measurement noise
        (default 0).

    Returns
    -------
    FilterRuns
        Position errors (M, N, 2), claimed position covariances (M, N, 2, 2) and times
        (k + 1) / ``rate_hz`` (N,): epoch k is recorded after the update of step k + 1
        (the truth starts at time 0).

    Notes
    -----
    The truth and the filter share the discrete white-noise-acceleration model

    .. math::

        F = \begin{pmatrix} I & \Delta t\, I \\ 0 & I \end{pmatrix},\quad
        Q = q \begin{pmatrix} \Delta t^3/3\, I & \Delta t^2/2\, I \\
        \Delta t^2/2\, I & \Delta t\, I \end{pmatrix},

    the filter with ``tuning.q_factor`` Q and ``tuning.r_factor`` R; the measurement is
    z = (‖p‖ + bias, atan2(p_y, p_x)) + v, v ~ N(0, diag(range_std², bearing_std²)), and
    the EKF linearises it at the prediction (bearing innovations wrapped to [−π, π)).
    """
    rng = as_generator(seed)
    dt = 1.0 / rate_hz
    n = int(round(duration_s * rate_hz))
    f = np.eye(4)
    f[0, 2] = f[1, 3] = dt
    qd = q * np.array(
        [
            [dt**3 / 3, 0, dt**2 / 2, 0],
            [0, dt**3 / 3, 0, dt**2 / 2],
            [dt**2 / 2, 0, dt, 0],
            [0, dt**2 / 2, 0, dt],
        ]
    )
    r = np.diag([range_std**2, bearing_std**2])
    p0 = np.diag([4.0, 4.0, 0.25, 0.25])
    x = np.tile([60.0, 0.0, 0.0, 2.0], (runs, 1)) + rng.standard_normal((runs, 4)) @ np.sqrt(p0)
    xh = np.tile([60.0, 0.0, 0.0, 2.0], (runs, 1))
    p = np.broadcast_to(p0 * tuning.p0_factor, (runs, 4, 4)).copy()
    qf, rf = qd * tuning.q_factor, r * tuning.r_factor
    chol_q, chol_r = np.linalg.cholesky(qd + 1e-18 * np.eye(4)), np.sqrt(np.diag(r))
    errors = np.empty((runs, n, 2))
    cov = np.empty((runs, n, 2, 2))
    eye = np.eye(4)
    for k in range(n):
        x = x @ f.T + rng.standard_normal((runs, 4)) @ chol_q.T
        xh = xh @ f.T
        p = f @ p @ f.T + qf
        rho = np.hypot(x[:, 0], x[:, 1])
        z = np.c_[rho + tuning.bias, np.arctan2(x[:, 1], x[:, 0])]
        z += rng.standard_normal((runs, 2)) * chol_r
        rho_h = np.hypot(xh[:, 0], xh[:, 1])
        h = np.zeros((runs, 2, 4))
        h[:, 0, 0], h[:, 0, 1] = xh[:, 0] / rho_h, xh[:, 1] / rho_h
        h[:, 1, 0], h[:, 1, 1] = -xh[:, 1] / rho_h**2, xh[:, 0] / rho_h**2
        innov = z - np.c_[rho_h, np.arctan2(xh[:, 1], xh[:, 0])]
        innov[:, 1] = (innov[:, 1] + np.pi) % (2 * np.pi) - np.pi
        ph = p @ np.swapaxes(h, 1, 2)
        s = h @ ph + rf
        gain = np.linalg.solve(s, np.swapaxes(ph, 1, 2)).swapaxes(1, 2)
        xh = xh + np.einsum("mij,mj->mi", gain, innov)
        ikh = eye - gain @ h
        p = ikh @ p @ np.swapaxes(ikh, 1, 2) + gain @ rf @ np.swapaxes(gain, 1, 2)
        errors[:, k] = (x - xh)[:, :2]
        cov[:, k] = p[:, :2, :2]
    return FilterRuns(errors, cov, np.arange(1, n + 1) * dt)  # epoch k is after k + 1 steps


def rotating_bias_log(
    n: int = 2000,
    bias_sigma: float = 1.0,
    anisotropy: float = 20.0,
    turns: float = 3.0,
    seed: RngLike = 0,
) -> tuple[np.ndarray, np.ndarray]:
    """Errors e_k ~ N(b, Σ_k) and claimed Σ_k, with Σ_k rotating and a constant bias b.

    Σ_k has axes of std ``anisotropy`` and 1 turning ``turns`` times over the segment;
    b is ``bias_sigma`` times the small axis's std along the first coordinate. In whitened
    space the bias turns with Σ_k, so its mean is near zero: the ELT sees little, the GLS
    mean test sees it all.

    Parameters
    ----------
    n : int
        Number of epochs (default 2000).
    bias_sigma : float
        The bias along the first coordinate, in units of the small axis's std (1)
        (default 1.0).
    anisotropy : float
        Std of the large axis of Σ_k; the small one is 1 (default 20).
    turns : float
        Number of full turns of Σ_k's axes over the ``n`` epochs (default 3).
    seed : RngLike
        Seed or generator of the errors (default 0).

    Returns
    -------
    errors : numpy.ndarray, shape (n, 2)
        The errors e_k, drawn from N(b, Σ_k).
    cov : numpy.ndarray, shape (n, 2, 2)
        The claimed covariances Σ_k = R(θ_k) diag(``anisotropy``², 1) R(θ_k)ᵀ,
        θ_k = 2π ``turns`` k / ``n``.
    """
    rng = as_generator(seed)
    angle = 2 * np.pi * turns * np.arange(n) / n
    c, s = np.cos(angle), np.sin(angle)
    rot = np.stack([np.c_[c, -s], np.c_[s, c]], axis=1)
    cov = rot @ np.diag([anisotropy**2, 1.0]) @ np.swapaxes(rot, 1, 2)
    chol = np.linalg.cholesky(cov)
    errors = np.einsum("nij,nj->ni", chol, rng.standard_normal((n, 2)))
    return errors + np.array([bias_sigma, 0.0]), cov


def ar1_errors(n: int, d: int, phi: float, seed: RngLike = 0) -> np.ndarray:
    """Stationary AR(1) errors with unit variance, independent across components.

    e_k = φ e_{k−1} + √(1 − φ²) z_k with z_k ~ N(0, I), started from the stationary law
    (e_0 = z_0), filtered in one pass (no loop over time).

    Parameters
    ----------
    n : int
        Number of epochs.
    d : int
        Dimension (independent components).
    phi : float
        The AR(1) coefficient φ, in (−1, 1).
    seed : RngLike
        Seed or generator of the innovations z_k (default 0).

    Returns
    -------
    numpy.ndarray, shape (n, d)
        The errors e_k.

    Notes
    -----
    Their correlation time (the integrated autocorrelation, the factor by which the
    variance of a mean grows) is (1 + φ)/(1 − φ) epochs; with φ = 0.99, 199.

    Examples
    --------
    >>> e = ar1_errors(20_000, 2, 0.5, seed=1)
    >>> e.shape, bool(abs(e.var() - 1) < 0.05)
    ((20000, 2), True)
    >>> bool(abs(np.corrcoef(e[1:, 0], e[:-1, 0])[0, 1] - 0.5) < 0.03)
    True
    """
    from scipy.signal import lfilter

    z = as_generator(seed).standard_normal((n, d))
    c = float(np.sqrt(1.0 - phi**2))
    return lfilter([c], [1.0, -phi], z, axis=0, zi=(1.0 - c) * z[:1])[0]
