"""Generators of the pose-format samples (``make sample-data``): estimates and separately
recorded ground truth in TUM, OpenVINS, EuRoC, ROS CSV and ROS bag layouts, an
innovations log and three Monte Carlo runs, each with planted conditions.

A pose error δ = (δp, δθ) ~ N(μ, Σ) is drawn per estimate epoch and applied in the chosen
convention (see credcli.engine.lie): left, R_true = Exp(δθ) R_est and p_true − p_est = δp;
right, R_true = R_est Exp(δθ) and p_true − p_est = R_est δp. The claimed covariance is
ρΣ. The truth is sampled at its own, faster rate from the same smooth trajectory, so
interpolating it to the estimate stamps adds an error far below the planted noise.

What each file plants (tests/test_formats.py checks the labels):

- ``tum_groundtruth.txt`` (100 Hz) and ``openvins_estimate.txt`` (20 Hz, 20 columns):
  position credible, orientation optimism (claimed 0.25 Σ).
- ``euroc_groundtruth.csv`` (100 Hz, ns) and ``odom_ros.csv`` (Odometry, 20 Hz, ns):
  position smm (a 1.5 σ bias along x), orientation credible; right perturbation.
- ``odom.bag`` (ROS1) and ``odom_ros2/`` (ROS2), topics /odom (Odometry, 20 Hz) and
  /ground_truth (PoseStamped, 50 Hz): pose pessimism (claimed 4 Σ), planar pessimism.
- ``innovations.csv``: segments good (credible, white), optimistic (S 0.3× too small),
  biased (smm) and correlated (credible scale, AR(1) innovations that fail the whiteness
  test).
- ``mc_run_1.csv`` … ``mc_run_3.csv``: one scenario, three runs: credible for 30 s, then
  the claimed covariance drops to 0.3× (optimism).
"""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np

EPOCH = 1_700_000_000.0  # the runs start at this UNIX time (s)

POSITION_STD = np.array([0.05, 0.08, 0.03])  # m
ORIENTATION_STD = np.array([0.010, 0.012, 0.020])  # rad


def true_cov() -> np.ndarray:
    """Σ of the planted pose error (ROS order), with a correlated x–y position block.

    Returns
    -------
    numpy.ndarray, shape (6, 6)
        The covariance of (δp, δθ) = (x, y, z, rotation x, y, z): stds ``POSITION_STD``
        (m) and ``ORIENTATION_STD`` (rad), correlation 0.4 between x and y and −0.3
        between the rotations about x and z.
    """
    std = np.r_[POSITION_STD, ORIENTATION_STD]
    corr = np.eye(6)
    corr[0, 1] = corr[1, 0] = 0.4
    corr[3, 5] = corr[5, 3] = -0.3
    return corr * np.outer(std, std)


def trajectory(t: np.ndarray):
    """Positions (N, 3) and scipy Rotations of a smooth figure-of-eight with heading along
    the velocity and small roll and pitch.

    Parameters
    ----------
    t : numpy.ndarray, shape (N,)
        Times in s from the start of the run.

    Returns
    -------
    p : numpy.ndarray, shape (N, 3)
        Positions (m): x = 10 cos ωt, y = 6 sin 2ωt, z = 1.5 + 0.3 sin(ωt/2), with
        ω = 2π/60 s (one loop a minute).
    rotation : scipy.spatial.transform.Rotation
        N orientations: yaw along the horizontal velocity, pitch 0.03 cos 0.3t and roll
        0.05 sin 0.5t (rad).
    """
    from scipy.spatial.transform import Rotation

    w = 2 * np.pi / 60.0
    p = np.c_[10 * np.cos(w * t), 6 * np.sin(2 * w * t), 1.5 + 0.3 * np.sin(0.5 * w * t)]
    v = np.c_[-10 * w * np.sin(w * t), 12 * w * np.cos(2 * w * t)]
    yaw = np.arctan2(v[:, 1], v[:, 0])
    euler = np.c_[yaw, 0.03 * np.cos(0.3 * t), 0.05 * np.sin(0.5 * t)]
    return p, Rotation.from_euler("ZYX", euler)


def planted_estimate(t, cov, rho=1.0, mean=None, right=False, seed=0):
    """Estimate positions, Rotations and claimed covariances (N, 6, 6) at stamps ``t``.

    A pose error δ = (δp, δθ) ~ N(``mean``, ``cov``) per stamp is applied to the true
    pose of :func:`trajectory` in the chosen convention (see the module docstring).

    Parameters
    ----------
    t : numpy.ndarray, shape (N,)
        The estimate's stamps in s from the start of the run.
    cov : numpy.ndarray, shape (6, 6)
        The true covariance Σ of δ (ROS order).
    rho : float
        Claimed over true covariance scale: the claim is ρΣ (default 1.0).
    mean : array_like, shape (6,), optional
        The mean μ of δ (a planted bias); zero when None.
    right : bool
        Right perturbation (R_true = R_est Exp(δθ), p_true − p_est = R_est δp) instead of
        left (R_true = Exp(δθ) R_est, p_true − p_est = δp) (default False).
    seed : int
        Seed of the errors (default 0).

    Returns
    -------
    p_est : numpy.ndarray, shape (N, 3)
        Estimated positions (m).
    r_est : scipy.spatial.transform.Rotation
        N estimated orientations.
    claimed : numpy.ndarray, shape (N, 6, 6)
        The claimed covariances ρΣ.
    """
    from scipy.spatial.transform import Rotation

    rng = np.random.default_rng(seed)
    n = t.size
    mean = np.zeros(6) if mean is None else np.asarray(mean, float)
    delta = mean + rng.standard_normal((n, 6)) @ np.linalg.cholesky(cov).T
    p_true, r_true = trajectory(t)
    step = Rotation.from_rotvec(delta[:, 3:])
    if right:
        r_est = r_true * step.inv()
        p_est = p_true - r_est.apply(delta[:, :3])
    else:
        r_est = step.inv() * r_true
        p_est = p_true - delta[:, :3]
    claimed = np.broadcast_to(rho * cov, (n, 6, 6)).copy()
    return p_est, r_est, claimed


def quaternions(rotation) -> np.ndarray:
    """x, y, z, w with w >= 0: q and −q are one rotation, and scipy releases differ in the
    sign they return, so the samples fix it (the files are the same with any scipy).

    Parameters
    ----------
    rotation : scipy.spatial.transform.Rotation
        N rotations (a stack, not a single one).

    Returns
    -------
    numpy.ndarray, shape (N, 4)
        Unit quaternions (x, y, z, w), each with w >= 0.
    """
    q = rotation.as_quat()
    return q * np.where(q[:, 3:] < 0, -1.0, 1.0)


def _stamps(duration: float, rate: float, start: float = 0.0) -> np.ndarray:
    return start + np.arange(int(round(duration * rate))) / rate


def write_tum_openvins(outdir: Path) -> list[Path]:
    """Write the TUM truth and the OpenVINS estimate: position credible, orientation
    optimism (the true orientation covariance is 4× the claim), left perturbation.

    Parameters
    ----------
    outdir : pathlib.Path
        An existing directory; files in it are overwritten.

    Returns
    -------
    list of pathlib.Path
        ``tum_groundtruth.txt`` (100 Hz for 120 s: timestamp tx ty tz qx qy qz qw) and
        ``openvins_estimate.txt`` (20 Hz for 119 s: the pose, then the upper triangles of
        the orientation and the position covariances, 20 columns).
    """
    t_true = _stamps(120.0, 100.0)
    t_est = _stamps(119.0, 20.0, 0.0123)
    p, r = trajectory(t_true)
    q = quaternions(r)
    truth = outdir / "tum_groundtruth.txt"
    rows = np.c_[EPOCH + t_true, p, q]
    header = "# timestamp tx ty tz qx qy qz qw"
    np.savetxt(truth, rows, fmt="%.6f", header=header[2:], comments="# ")
    cov = true_cov()
    cov[3:, 3:] /= 0.25  # the truth is 4× the claim: orientation optimism
    p_est, r_est, claimed = planted_estimate(t_est, cov, seed=12)
    claimed[:, 3:, 3:] *= 0.25
    iu = np.triu_indices(3)
    rot_block = claimed[:, 3:, 3:][:, iu[0], iu[1]]
    pos_block = claimed[:, :3, :3][:, iu[0], iu[1]]
    est = outdir / "openvins_estimate.txt"
    np.savetxt(
        est,
        np.c_[EPOCH + t_est, p_est, quaternions(r_est), rot_block, pos_block],
        fmt=["%.6f"] + ["%.9g"] * 19,
        header="timestamp(s) tx ty tz qx qy qz qw Pr11 Pr12 Pr13 Pr22 Pr23 Pr33 "
        "Pt11 Pt12 Pt13 Pt22 Pt23 Pt33",
        comments="# ",
    )
    return [truth, est]


def write_euroc_ros_csv(outdir: Path) -> list[Path]:
    """Write the EuRoC truth and a ROS CSV Odometry estimate: position smm (a 1.5 σ bias
    along x), orientation credible, right perturbation.

    Parameters
    ----------
    outdir : pathlib.Path
        An existing directory; files in it are overwritten.

    Returns
    -------
    list of pathlib.Path
        ``euroc_groundtruth.csv`` (100 Hz for 120 s, ns stamps, quaternion w first) and
        ``odom_ros.csv`` (20 Hz for 119 s: ``rostopic echo -p`` columns of
        nav_msgs/Odometry, received 2 ms after each stamp).
    """
    import pandas as pd

    t_true = _stamps(120.0, 100.0)
    t_est = _stamps(119.0, 20.0, 0.0071)
    p, r = trajectory(t_true)
    q = quaternions(r)
    ns = (np.int64(EPOCH) * 10**9 + np.round(t_true * 1e9).astype(np.int64)).astype(np.int64)
    truth = outdir / "euroc_groundtruth.csv"
    cols = ["#timestamp", "p_RS_R_x [m]", "p_RS_R_y [m]", "p_RS_R_z [m]"]
    cols += ["q_RS_w []", "q_RS_x []", "q_RS_y []", "q_RS_z []"]
    frame = pd.DataFrame(np.c_[p, q[:, 3], q[:, :3]], columns=cols[1:])
    frame.insert(0, cols[0], ns)
    frame.to_csv(truth, index=False, float_format="%.9f")
    cov = true_cov()
    bias = np.r_[1.5 * POSITION_STD[0], 0, 0, 0, 0, 0]
    p_est, r_est, claimed = planted_estimate(t_est, cov, mean=bias, right=True, seed=22)
    est_ns = np.int64(EPOCH) * 10**9 + np.round(t_est * 1e9).astype(np.int64)
    out = {"%time": est_ns + 2_000_000, "field.header.seq": np.arange(t_est.size)}
    out["field.header.stamp"] = est_ns
    out["field.header.frame_id"] = "odom"
    out["field.child_frame_id"] = "base_link"
    for k, axis in enumerate("xyz"):
        out[f"field.pose.pose.position.{axis}"] = p_est[:, k]
    for k, axis in enumerate("xyzw"):
        out[f"field.pose.pose.orientation.{axis}"] = quaternions(r_est)[:, k]
    for k in range(36):
        out[f"field.pose.covariance{k}"] = claimed.reshape(-1, 36)[:, k]
    est = outdir / "odom_ros.csv"
    pd.DataFrame(out).to_csv(est, index=False, float_format="%.10g")
    return [truth, est]


def bag_messages(duration=60.0, seed=33):
    """Stamps, poses and covariances of the bag samples: estimate 20 Hz, truth 50 Hz.

    The estimate's true error covariance is Σ/4 and its claim Σ (:func:`true_cov`):
    pessimism, left perturbation.

    Parameters
    ----------
    duration : float
        Length of the truth in s; the estimate covers ``duration`` − 1 s from 0.011 s
        (default 60).
    seed : int
        Seed of the estimate's errors (default 33).

    Returns
    -------
    truth : tuple of numpy.ndarray
        Stamps (s from the start, (N,)), positions (N, 3) and quaternions (N, 4)
        (x, y, z, w) of the truth.
    estimate : tuple of numpy.ndarray
        Stamps (M,), positions (M, 3), quaternions (M, 4) and claimed covariances
        (M, 6, 6) of the estimate.
    """
    t_true = _stamps(duration, 50.0)
    t_est = _stamps(duration - 1.0, 20.0, 0.011)
    p_true, r_true = trajectory(t_true)
    cov = true_cov()
    p_est, r_est, claimed = planted_estimate(t_est, cov / 4.0, seed=seed)
    claimed *= 4.0  # the claim is 4× the truth: pessimism
    return (t_true, p_true, quaternions(r_true)), (t_est, p_est, quaternions(r_est), claimed)


def write_bag(path: Path, version: int, estimate, truth) -> Path:
    """A ROS1 .bag (version 1) or ROS2 bag directory (version 2) with /odom (Odometry)
    and /ground_truth (PoseStamped), written with rosbags.

    Stamps are ``EPOCH`` plus the given times; each Odometry message is recorded 1 ms
    after its stamp, each PoseStamped at its stamp; frame ``map``, child frame
    ``base_link``, zero twist.

    Parameters
    ----------
    path : pathlib.Path
        The bag file (ROS1) or directory (ROS2); an existing one is replaced.
    version : int
        1 for ROS1 (Noetic types), 2 for ROS2 (Humble types, rosbag2 format version 8).
    estimate : tuple of numpy.ndarray
        Stamps, positions, quaternions (x, y, z, w) and covariances (M, 6, 6) of /odom,
        as :func:`bag_messages` gives them.
    truth : tuple of numpy.ndarray
        Stamps, positions and quaternions of /ground_truth.

    Returns
    -------
    pathlib.Path
        ``path``.
    """
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS1_NOETIC if version == 1 else Stores.ROS2_HUMBLE)
    T = store.types
    odometry, pose_stamped = "nav_msgs/msg/Odometry", "geometry_msgs/msg/PoseStamped"

    def header(seq, t):
        ns = int(round((EPOCH + t) * 1e9))
        stamp = T["builtin_interfaces/msg/Time"](sec=ns // 10**9, nanosec=ns % 10**9)
        if version == 1:
            return T["std_msgs/msg/Header"](seq=seq, stamp=stamp, frame_id="map"), ns
        return T["std_msgs/msg/Header"](stamp=stamp, frame_id="map"), ns

    def pose(p, q):
        point = T["geometry_msgs/msg/Point"](x=p[0], y=p[1], z=p[2])
        quat = T["geometry_msgs/msg/Quaternion"](x=q[0], y=q[1], z=q[2], w=q[3])
        return T["geometry_msgs/msg/Pose"](position=point, orientation=quat)

    zero = T["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0)
    twist = T["geometry_msgs/msg/TwistWithCovariance"](
        twist=T["geometry_msgs/msg/Twist"](linear=zero, angular=zero), covariance=np.zeros(36)
    )
    messages = []
    t_est, p_est, q_est, claimed = estimate
    for k in range(t_est.size):
        h, ns = header(k, t_est[k])
        pwc = T["geometry_msgs/msg/PoseWithCovariance"](
            pose=pose(p_est[k], q_est[k]), covariance=claimed[k].ravel().copy()
        )
        msg = T[odometry](header=h, child_frame_id="base_link", pose=pwc, twist=twist)
        messages.append((ns + 1_000_000, "/odom", odometry, msg))
    t_true, p_true, q_true = truth
    for k in range(t_true.size):
        h, ns = header(k, t_true[k])
        messages.append(
            (
                ns,
                "/ground_truth",
                pose_stamped,
                T[pose_stamped](header=h, pose=pose(p_true[k], q_true[k])),
            )
        )
    messages.sort(key=lambda m: m[0])
    if version == 1:
        from rosbags.rosbag1 import Writer

        path.unlink(missing_ok=True)
        writer = Writer(path)
        serialize = store.serialize_ros1
    else:
        from rosbags.rosbag2 import Writer

        shutil.rmtree(path, ignore_errors=True)
        writer = Writer(path, version=8)
        serialize = store.serialize_cdr
    with writer:
        conns = {
            topic: writer.add_connection(topic, kind, typestore=store)
            for topic, kind in (("/odom", odometry), ("/ground_truth", pose_stamped))
        }
        for ns, topic, kind, msg in messages:
            writer.write(conns[topic], ns, serialize(msg, kind))
    return path


def innovations_log(seed: int = 0, n: int = 600, rate: float = 10.0):
    """A 2-D innovations log (credcli's innov_i, innov_cov_i_j) with four segments.

    The innovations are ν_k = L(z_k + μ) with L Lᵀ = S, S = [[0.5, 0.1], [0.1, 0.3]];
    the segments are ``good`` (claim S), ``optimistic`` (claim 0.3 S), ``biased``
    (μ = (0.9, −0.6)) and ``correlated`` (z_k AR(1) with φ = 0.6 and unit variance).

    Parameters
    ----------
    seed : int
        Seed of the innovations (default 0).
    n : int
        Epochs per segment (default 600).
    rate : float
        Epoch rate in Hz (default 10).

    Returns
    -------
    pandas.DataFrame
        Columns time, segment, innov_0, innov_1, innov_cov_0_0, innov_cov_0_1,
        innov_cov_1_1; the segments follow each other in time.
    """
    import pandas as pd

    rng = np.random.default_rng(seed)
    s_true = np.array([[0.5, 0.1], [0.1, 0.3]])
    chol = np.linalg.cholesky(s_true)
    frames, t0 = [], 0.0
    for name, claim, bias, phi in (
        ("good", 1.0, (0.0, 0.0), 0.0),
        ("optimistic", 0.3, (0.0, 0.0), 0.0),
        ("biased", 1.0, (0.9, -0.6), 0.0),
        ("correlated", 1.0, (0.0, 0.0), 0.6),
    ):
        white = rng.standard_normal((n, 2))
        if phi:  # AR(1) with unit marginal variance: same S, correlated in time
            from scipy.signal import lfilter

            white = lfilter([np.sqrt(1 - phi**2)], [1, -phi], white, axis=0)
        nu = (white + np.asarray(bias)) @ chol.T
        t = t0 + np.arange(n) / rate
        frames.append(
            pd.DataFrame(
                {
                    "time": np.round(t, 3),
                    "segment": name,
                    "innov_0": nu[:, 0],
                    "innov_1": nu[:, 1],
                    "innov_cov_0_0": claim * s_true[0, 0],
                    "innov_cov_0_1": claim * s_true[0, 1],
                    "innov_cov_1_1": claim * s_true[1, 1],
                }
            )
        )
        t0 = t[-1] + 1.0 / rate
    return pd.concat(frames, ignore_index=True)


def monte_carlo_runs(runs: int = 3, seed: int = 1, duration: float = 60.0, rate: float = 20.0):
    """``runs`` credcli logs of one 2-D scenario on one time base: credible for the first
    half, then the claimed covariance falls to 0.3× the true one.

    Parameters
    ----------
    runs : int
        Number of runs (default 3).
    seed : int
        Seed; run r draws from ``default_rng([seed, r])`` (default 1).
    duration : float
        Length of each run in s (default 60).
    rate : float
        Epoch rate in Hz (default 20).

    Returns
    -------
    list of pandas.DataFrame
        One log per run, columns time, truth_0, truth_1, est_0, est_1, cov_0_0, cov_0_1,
        cov_1_1 (no segment column).
    """
    import pandas as pd

    t = np.round(_stamps(duration, rate), 6)
    truth = np.c_[20 * np.cos(0.1 * t), 20 * np.sin(0.1 * t)]
    sigma = np.array([[0.4, 0.1], [0.1, 0.2]])
    chol = np.linalg.cholesky(sigma)
    claim = np.where(t < duration / 2, 1.0, 0.3)[:, None, None] * sigma
    out = []
    for run in range(runs):
        rng = np.random.default_rng([seed, run])
        est = truth - rng.standard_normal((t.size, 2)) @ chol.T
        out.append(
            pd.DataFrame(
                {
                    "time": t,
                    "truth_0": truth[:, 0],
                    "truth_1": truth[:, 1],
                    "est_0": est[:, 0],
                    "est_1": est[:, 1],
                    "cov_0_0": claim[:, 0, 0],
                    "cov_0_1": claim[:, 0, 1],
                    "cov_1_1": claim[:, 1, 1],
                }
            )
        )
    return out


def write_pose_samples(outdir: Path) -> list[Path]:
    """Every pose-format sample in ``outdir``; returns their paths.

    Parameters
    ----------
    outdir : pathlib.Path
        The directory (created with its parents if missing; files in it are
        overwritten).

    Returns
    -------
    list of pathlib.Path
        The files written, in order: the TUM/OpenVINS and EuRoC/ROS CSV pairs,
        ``odom.bag``, ``odom_ros2``, ``innovations.csv``, ``mc_run_1.csv`` ….
    """
    outdir.mkdir(parents=True, exist_ok=True)
    written = write_tum_openvins(outdir) + write_euroc_ros_csv(outdir)
    truth, estimate = bag_messages()
    written.append(write_bag(outdir / "odom.bag", 1, estimate, truth))
    written.append(write_bag(outdir / "odom_ros2", 2, estimate, truth))
    written.append(outdir / "innovations.csv")
    innovations_log().to_csv(written[-1], index=False, float_format="%.9g")
    for k, frame in enumerate(monte_carlo_runs(), start=1):
        written.append(outdir / f"mc_run_{k}.csv")
        frame.to_csv(written[-1], index=False, float_format="%.9g")
    return written
