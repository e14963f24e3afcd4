"""Real logs in (issue 11): formats, pairing by time, time units, Lie-group errors, NIS
and Monte Carlo runs. Numbers are checked against closed forms and the planted samples."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest
from helpers import ROOT, error_line, run
from scipy.spatial.transform import Rotation

from credcli.engine import elt, lie
from credcli.engine.config import Perturbation, States
from credcli.engine.whiteness import portmanteau
from credcli.io.formats import Trajectory, read_trajectory, sniff_format
from credcli.io.pairing import pair
from credcli.io.schema import InputFormat, TimeUnit

FORMATS = ROOT / "sample_data" / "formats"


def labels(*args) -> list[str]:
    code, out, err = run("diagnose", *map(str, args), "-f", "json")
    assert code == 0, err
    return [s["label"] for s in json.loads(out)["segments"]]


# --- planted samples -------------------------------------------------------------------


def test_tum_truth_with_openvins_estimate():
    pair_args = (FORMATS / "openvins_estimate.txt", "--truth", FORMATS / "tum_groundtruth.txt")
    # two 60 s windows and the whole run (judged with its own memory model)
    assert labels(*pair_args, "--window", "60s") == ["credible"] * 3
    assert labels(*pair_args, "--window", "60s", "--states", "orientation") == ["optimism"] * 3


def test_ros_csv_odometry_with_euroc_truth_right_perturbation():
    args = (FORMATS / "odom_ros.csv", "--truth", FORMATS / "euroc_groundtruth.csv")
    right = ("--perturbation", "right", "--window", "60s")
    assert labels(*args, *right) == ["bias"] * 3  # two windows and the run
    assert labels(*args, *right, "--states", "orientation") == ["credible"] * 3


@pytest.mark.parametrize("bag", ["odom.bag", "odom_ros2"])
def test_ros1_and_ros2_bags_with_both_topics(bag):
    topics = ("--topic", "/odom", "--truth-topic", "/ground_truth", "--window", "60s")
    assert labels(FORMATS / bag, *topics, "--states", "pose") == ["pessimism"]
    assert labels(FORMATS / bag, *topics, "--states", "planar") == ["pessimism"]


def test_innovations_labels_and_whiteness():
    code, out, err = run("diagnose", FORMATS / "innovations.csv", "--innovations", "-f", "json")
    assert code == 0, err
    segs = {s["segment"]: s for s in json.loads(out)["segments"]}
    assert {k: s["label"] for k, s in segs.items()} == {
        "good": "credible",
        "optimistic": "optimism",
        "biased": "bias",
        "correlated": "credible",
    }
    white = {k: s["whiteness_pvalue"] for k, s in segs.items()}
    assert white["correlated"] < 1e-6 and min(white["good"], white["biased"]) > 0.05


def test_monte_carlo_runs(tmp_path):
    runs = sorted(FORMATS.glob("mc_run_*.csv"))
    code, out, err = run(
        "diagnose", *runs, "--monte-carlo", "--window", "30s", "-f", "json", "--plots", tmp_path
    )
    assert code == 0, err
    doc = json.loads(out)
    assert [s["label"] for s in doc["segments"]] == ["credible", "optimism"]
    assert [s["n"] for s in doc["segments"]] == [3 * 600, 3 * 600]
    mc = doc["monte_carlo"]
    from scipy import stats

    assert mc["lower"] == pytest.approx(stats.chi2.ppf(0.025, 6) / 3, rel=1e-12)
    assert mc["upper"] == pytest.approx(stats.chi2.ppf(0.975, 6) / 3, rel=1e-12)
    # credible half: about 95 % inside (binomial s.e. 0.9 %); claimed 0.3×: far fewer
    assert abs(mc["segments"]["w001"] - 0.95) < 4 * np.sqrt(0.95 * 0.05 / 600)
    assert mc["segments"]["w002"] < 0.6
    assert (tmp_path / "monte_carlo_anees.png").exists()


def test_monte_carlo_anees_is_the_mean_nees_over_runs(tmp_path):
    from credcli.io.logs import load_log
    from credcli.segments import monte_carlo_plan, split

    runs = sorted(FORMATS.glob("mc_run_*.csv"))
    logs = [load_log(p) for p in runs]
    _, mc = monte_carlo_plan(logs, [(logs[0], split(logs[0]))], 0.05)
    direct = np.mean(
        [np.einsum("ni,nij,nj->n", g.errors, np.linalg.inv(g.cov), g.errors) for g in logs],
        axis=0,
    )
    np.testing.assert_allclose(mc.anees, direct, rtol=1e-10)


def test_monte_carlo_needs_one_time_base(tmp_path):
    runs = sorted(FORMATS.glob("mc_run_*.csv"))
    short = pd.read_csv(runs[1]).iloc[:-5]
    short.to_csv(tmp_path / "short.csv", index=False)
    line = error_line(*run("diagnose", runs[0], tmp_path / "short.csv", "--monte-carlo")[::2])
    assert "one time base" in line


# --- conventions: a planted perturbation comes back --------------------------------------


def _poses(n, rng):
    return rng.normal(size=(n, 3)) * 5, Rotation.random(n, random_state=rng)


@pytest.mark.parametrize("perturbation", ["left", "right"])
def test_pose_perturbation_round_trip(perturbation):
    rng = np.random.default_rng(1)
    n = 20000
    p_est, r_est = _poses(n, rng)
    a = rng.normal(size=(6, 6)) * 0.05
    cov = a @ a.T + np.diag([0.01] * 3 + [0.001] * 3)
    delta = rng.multivariate_normal(np.zeros(6), cov, size=n)
    step = Rotation.from_rotvec(delta[:, 3:])
    if perturbation == "left":
        r_true, p_true = step * r_est, p_est + delta[:, :3]
    else:
        r_true, p_true = r_est * step, p_est + r_est.apply(delta[:, :3])
    e = lie.state_errors(States.POSE, Perturbation(perturbation), p_true, p_est, r_true, r_est)
    np.testing.assert_allclose(e, delta, atol=1e-10)  # exactly the planted δ
    sample = np.cov(e.T)
    se = np.sqrt((cov**2 + np.outer(np.diag(cov), np.diag(cov))) / n)  # s.e. of each entry
    assert np.all(np.abs(sample - cov) < 5 * se)
    # the diagnosis of the whole run with the claimed covariance: credible
    from credcli import diagnose

    assert diagnose(e[:2000], cov, rng=0).label.value == "credible"


@pytest.mark.parametrize("perturbation", ["left", "right"])
def test_planar_perturbation_round_trip(perturbation):
    rng = np.random.default_rng(2)
    n = 5000
    yaw = rng.uniform(-np.pi, np.pi, n)
    p_est = np.c_[rng.normal(size=(n, 2)) * 10, np.zeros(n)]
    r_est = Rotation.from_euler("z", yaw[:, None])
    cov = np.array([[0.04, 0.01, 0.0], [0.01, 0.02, 0.002], [0.0, 0.002, 0.3]])
    delta = rng.multivariate_normal(np.zeros(3), cov, size=n)
    r_true = Rotation.from_euler("z", (yaw + delta[:, 2])[:, None])
    c, s = np.cos(yaw), np.sin(yaw)
    if perturbation == "right":  # body-frame offset rotated into the world
        dxy = np.c_[c * delta[:, 0] - s * delta[:, 1], s * delta[:, 0] + c * delta[:, 1]]
    else:
        dxy = delta[:, :2]
    p_true = p_est + np.c_[dxy, np.zeros(n)]
    e = lie.state_errors(States.PLANAR, Perturbation(perturbation), p_true, p_est, r_true, r_est)
    wrapped = delta.copy()
    wrapped[:, 2] = lie.wrap_angle(delta[:, 2])
    np.testing.assert_allclose(e, wrapped, atol=1e-9)
    assert np.all(e[:, 2] > -np.pi) and np.all(e[:, 2] <= np.pi)


def test_wrap_angle_range():
    x = np.array([np.pi, -np.pi, 3 * np.pi, 0.5, -0.5 - 2 * np.pi])
    np.testing.assert_allclose(lie.wrap_angle(x), [np.pi, np.pi, np.pi, 0.5, -0.5])


def test_cov_block_takes_ros_rows():
    cov6 = np.arange(36.0).reshape(1, 6, 6)
    np.testing.assert_array_equal(
        lie.cov_block(cov6, States.PLANAR)[0], cov6[0][np.ix_([0, 1, 5], [0, 1, 5])]
    )
    np.testing.assert_array_equal(lie.cov_block(cov6, States.ORIENTATION)[0], cov6[0, 3:, 3:])


# --- pairing -----------------------------------------------------------------------------


def _traj(t, position, quaternion=None, cov=None, source="x"):
    return Trajectory(
        np.asarray(t, float),
        np.asarray(position, float),
        quaternion,
        cov,
        np.arange(1, len(t) + 1),
        source,
        InputFormat.TUM,
    )


def test_pairing_interpolates_linearly_and_by_slerp():
    t_true = np.arange(0.0, 10.0, 0.1)
    omega = np.array([0.0, 0.0, 0.3])  # constant angular velocity: SLERP is exact
    truth = _traj(
        t_true,
        np.c_[2 * t_true, -t_true + 1, np.zeros_like(t_true)],
        Rotation.from_rotvec(t_true[:, None] * omega).as_quat(),
    )
    t_est = np.array([-1.0, 0.05, 0.1, 3.333, 9.9, 12.0])
    est = _traj(t_est, np.zeros((6, 3)))
    p = pair(est, truth, None, 0.0)
    assert p.keep.tolist() == [False, True, True, True, True, False] and p.dropped == 2
    kept = t_est[p.keep]
    np.testing.assert_allclose(
        p.position, np.c_[2 * kept, -kept + 1, np.zeros_like(kept)], atol=1e-12
    )
    np.testing.assert_allclose(p.rotation.as_rotvec(), kept[:, None] * omega, atol=1e-12)
    assert p.max_dt == pytest.approx(0.25)


def test_pairing_respects_max_dt_and_offset():
    t_true = np.r_[np.arange(0.0, 5.0, 0.1), np.arange(8.0, 10.0, 0.1)]  # a 3 s gap
    truth = _traj(t_true, np.c_[t_true, t_true, t_true])
    est = _traj(np.array([1.0, 6.0, 9.0]), np.zeros((3, 3)))
    p = pair(est, truth, None, 0.0)
    assert p.keep.tolist() == [True, False, True]
    shifted = pair(est, truth, None, 0.05)  # stamps + 0.05 s
    np.testing.assert_allclose(shifted.position[:, 0], [1.05, 9.05])


def test_pairing_errors_name_the_cause():
    truth = _traj(np.arange(0.0, 1.0, 0.5), np.zeros((2, 3)))
    with pytest.raises(Exception, match="do not overlap"):
        pair(_traj(np.array([5.0, 6.0]), np.zeros((2, 3))), truth, None, 0.0)
    with pytest.raises(Exception, match="raise `max_dt`"):
        pair(_traj(np.array([0.25]), np.zeros((1, 3))), truth, 0.1, 0.0)


# --- formats and units -------------------------------------------------------------------


def test_sniffing_and_notes():
    assert sniff_format(FORMATS / "tum_groundtruth.txt") is InputFormat.TUM
    assert sniff_format(FORMATS / "euroc_groundtruth.csv") is InputFormat.EUROC
    assert sniff_format(FORMATS / "odom_ros.csv") is InputFormat.ROS_CSV
    assert sniff_format(FORMATS / "odom.bag") is InputFormat.ROSBAG
    assert sniff_format(FORMATS / "odom_ros2") is InputFormat.ROSBAG
    assert sniff_format(FORMATS / "mc_run_1.csv") is InputFormat.CREDCLI
    code, _, err = run(
        "diagnose", FORMATS / "odom_ros.csv", "--truth", FORMATS / "euroc_groundtruth.csv"
    )
    assert code == 0
    for said in ("read as ros-csv", "read as euroc", "stamps read as ns", "paired 2380 of 2380"):
        assert said in err


def test_formats_agree_on_the_same_poses(tmp_path):
    """The EuRoC truth and the TUM truth hold the same trajectory; so does a ROS1 bag."""
    euroc = read_trajectory(FORMATS / "euroc_groundtruth.csv", InputFormat.AUTO, "truth")
    tum = read_trajectory(FORMATS / "tum_groundtruth.txt", InputFormat.AUTO, "truth")
    np.testing.assert_allclose(euroc.time, tum.time, atol=1e-6)
    np.testing.assert_allclose(euroc.position, tum.position, atol=1e-6)
    np.testing.assert_allclose(np.abs(np.sum(euroc.quaternion * tum.quaternion, 1)), 1, atol=1e-6)
    bag = read_trajectory(FORMATS / "odom.bag", InputFormat.AUTO, "estimate", topic="/odom")
    ros2 = read_trajectory(FORMATS / "odom_ros2", InputFormat.AUTO, "estimate", topic="/odom")
    np.testing.assert_array_equal(bag.cov, ros2.cov)
    np.testing.assert_array_equal(bag.time, ros2.time)


def test_bag_fast_path_equals_deserializing_each_message():
    from rosbags.highlevel import AnyReader

    from credcli.io import rosbag

    with AnyReader([FORMATS / "odom.bag"]) as reader:
        conns = [c for c in reader.connections if c.topic == "/odom"]
        raws = [bytes(r) for _, _, r in reader.messages(connections=conns)]
        fast = rosbag._fast(reader, raws, conns[0].msgtype)
        slow = rosbag._slow(reader, raws, conns[0].msgtype)
    assert fast is not None
    for a, b in zip(fast, slow):
        np.testing.assert_array_equal(a, b)


def _credcli_frame(n=400, seed=0, t0=0.0, dt=0.1):
    rng = np.random.default_rng(seed)
    e = rng.standard_normal((n, 2))
    return pd.DataFrame(
        {
            "time": t0 + dt * np.arange(n),
            "truth_0": 0.0,
            "truth_1": 0.0,
            "est_0": -e[:, 0],
            "est_1": -e[:, 1],
            "var_0": 1.0,
            "var_1": 1.0,
        }
    )


def test_whitespace_and_hash_header_credcli(tmp_path):
    frame = _credcli_frame()
    path = tmp_path / "log.txt"
    with open(path, "w") as fh:
        fh.write("# produced by a filter\n# " + " ".join(frame.columns) + "\n")
        frame.to_csv(fh, sep=" ", header=False, index=False)
    code, out, err = run("diagnose", path, "-f", "json")
    assert code == 0, err
    ref = run("diagnose", _csv(tmp_path, frame), "-f", "json")[1]
    assert (
        json.loads(out)["segments"][0]["elt_statistic"]
        == json.loads(ref)["segments"][0]["elt_statistic"]
    )


def _csv(tmp_path, frame, name="log.csv"):
    path = tmp_path / name
    frame.to_csv(path, index=False)
    return path


def test_nanosecond_stamps_are_recognised(tmp_path):
    frame = _credcli_frame()
    frame["time"] = (1_700_000_000 * 10**9 + (frame["time"] * 1e9).round()).astype(np.int64)
    path = _csv(tmp_path, frame)
    code, out, err = run("diagnose", path, "--window", "20s", "-f", "json")
    assert code == 0, err
    assert "read as epoch ns" in err
    assert [s["n"] for s in json.loads(out)["segments"]] == [200, 200, 400]  # and the run


def test_a_unit_mistake_is_an_error_not_a_thousand_windows(tmp_path):
    frame = _credcli_frame()
    frame["time"] = (frame["time"] * 1e9).round().astype(np.int64)  # ns from 0: not epoch
    line = error_line(*run("diagnose", _csv(tmp_path, frame), "--window", "20s")[::2])
    assert "--time-unit" in line and "--min-epochs" in line
    code, out, _ = run(
        "diagnose", _csv(tmp_path, frame), "--window", "20s", "--time-unit", "ns", "-f", "json"
    )
    assert code == 0 and len(json.loads(out)["segments"]) == 3  # two windows, the run


def test_ros_csv_with_sec_and_nanosec_columns(tmp_path):
    frame = pd.read_csv(FORMATS / "odom_ros.csv")
    stamp = frame.pop("field.header.stamp")
    frame.insert(1, "header.stamp.sec", stamp // 10**9)
    frame.insert(2, "header.stamp.nanosec", stamp % 10**9)
    frame.columns = [c.removeprefix("field.") for c in frame.columns]
    path = _csv(tmp_path, frame)
    args = ("--truth", FORMATS / "euroc_groundtruth.csv", "--perturbation", "right")
    assert labels(path, *args, "--window", "60s") == labels(
        FORMATS / "odom_ros.csv", *args, "--window", "60s"
    )


# --- bad input: exit 2, one line ---------------------------------------------------------


def _tum(tmp_path, rows, name="t.txt"):
    path = tmp_path / name
    np.savetxt(path, rows, fmt="%.9f")
    return path


@pytest.mark.parametrize(
    "args, expected",
    [
        (["--truth", "{tmp}/late.txt"], "do not overlap"),
        (["--truth", FORMATS / "tum_groundtruth.txt", "--max-dt", "0.001"], "raise --max-dt"),
        (["--truth", FORMATS / "tum_groundtruth.txt", "--max-dt", "-1"], "--max-dt must be > 0"),
        (
            [
                "--truth",
                FORMATS / "tum_groundtruth.txt",
                "--states",
                "orientation",
                "--input-format",
                "credcli",
            ],
            None,
        ),
    ],
)
def test_pairing_bad_input(tmp_path, args, expected):
    truth = pd.read_csv(FORMATS / "tum_groundtruth.txt", sep=" ", comment="#", header=None)
    truth[0] += 10_000
    np.savetxt(tmp_path / "late.txt", truth.to_numpy(), fmt="%.6f")
    args = [str(a).replace("{tmp}", str(tmp_path)) for a in args]
    code, _, err = run("diagnose", FORMATS / "openvins_estimate.txt", *args)
    line = error_line(code, err)
    if expected:
        assert expected in line


def test_bag_without_the_topic(tmp_path):
    line = error_line(
        *run(
            "diagnose", FORMATS / "odom.bag", "--topic", "/nope", "--truth-topic", "/ground_truth"
        )[::2]
    )
    assert "no topic /nope" in line and "/odom (nav_msgs/msg/Odometry)" in line
    line = error_line(
        *run(
            "diagnose", FORMATS / "odom.bag", "--topic", "/ground_truth", "--truth-topic", "/odom"
        )[::2]
    )
    assert "PoseStamped" in line


def test_missing_rosbags_is_a_clear_error(monkeypatch):
    import builtins

    real = builtins.__import__

    def no_rosbags(name, *a, **k):
        if name.startswith("rosbags"):
            raise ImportError(name)
        return real(name, *a, **k)

    monkeypatch.setattr(builtins, "__import__", no_rosbags)
    line = error_line(*run("diagnose", FORMATS / "odom.bag", "--truth-topic", "/ground_truth")[::2])
    assert "credcli[ros]" in line


def test_zero_quaternion_and_nonfinite_name_the_row(tmp_path):
    rows = np.loadtxt(FORMATS / "tum_groundtruth.txt")[:500]
    bad = rows.copy()
    bad[7, 4:8] = 0.0
    line = error_line(
        *run("diagnose", FORMATS / "openvins_estimate.txt", "--truth", _tum(tmp_path, bad))[::2]
    )
    assert "row 8" in line and "zero-norm quaternion" in line
    bad = rows.copy()
    bad[3, 2] = np.nan
    line = error_line(
        *run("diagnose", FORMATS / "openvins_estimate.txt", "--truth", _tum(tmp_path, bad))[::2]
    )
    assert "row 4" in line


def test_orientation_from_a_log_without_one(tmp_path):
    path = _csv(tmp_path, _credcli_frame())
    line = error_line(*run("diagnose", path, "--states", "orientation")[::2])
    assert "orientations" in line
    tum_truth = _tum(
        tmp_path, np.c_[0.1 * np.arange(500), np.zeros((500, 3)), np.tile([0, 0, 0, 1.0], (500, 1))]
    )
    frame = _credcli_frame(n=400)
    frame["truth_2"] = frame["est_2"] = 0.0
    frame["var_2"] = 1.0
    line = error_line(
        *run("diagnose", _csv(tmp_path, frame, "e.csv"), "--truth", tum_truth, "--states", "pose")[
            ::2
        ]
    )
    assert "orientations" in line


def test_tum_estimate_without_covariance(tmp_path):
    line = error_line(
        *run(
            "diagnose", FORMATS / "tum_groundtruth.txt", "--truth", FORMATS / "tum_groundtruth.txt"
        )[::2]
    )
    assert "has no covariance" in line


def test_quaternion_columns_are_not_a_vector(tmp_path):
    frame = _credcli_frame().rename(columns={"truth_0": "truth_qw", "est_0": "est_qw"})
    path = _csv(tmp_path, frame)
    line = error_line(
        *run(
            "diagnose",
            path,
            "--truth-columns",
            "truth_qw,truth_1",
            "--estimate-columns",
            "est_qw,est_1",
            "--cov-columns",
            "var_0,var_1",
        )[::2]
    )
    assert "quaternion" in line


def test_only_quaternion_component_names_are_refused():
    from credcli.errors import CredcliError
    from credcli.io.logs import check_not_orientation

    for name in ("truth_qw", "q_x", "quat_z", "orientation.w", "rotation_x", "qx"):
        with pytest.raises(CredcliError, match="quaternion"):
            check_not_orientation([name], "log")
    check_not_orientation(["rotation_rate", "orientation_yaw", "est_0", "x"], "log")


def test_pose_format_without_truth(tmp_path):
    line = error_line(*run("diagnose", FORMATS / "odom_ros.csv")[::2])
    assert "--truth" in line


# --- whiteness and Monte Carlo blocks ----------------------------------------------------


def test_portmanteau_is_ljung_box_for_one_series():
    from statsmodels.stats.diagnostic import acorr_ljungbox

    x = np.random.default_rng(3).standard_normal(250)
    x[1:] += 0.3 * x[:-1]
    mine = portmanteau(x[:, None], 8)
    ref = acorr_ljungbox(x, lags=[8])
    n = x.size
    assert mine.statistic * (n + 2) / n == pytest.approx(float(ref.lb_stat.iloc[0]), rel=1e-12)


def test_portmanteau_multivariate_against_a_direct_sum():
    w = np.random.default_rng(4).standard_normal((120, 3))
    got = portmanteau(w, 5)
    n = len(w)
    wc = w - w.mean(0)
    c0 = wc.T @ wc / n
    total = 0.0
    for k in range(1, 6):
        ck = sum(np.outer(wc[t], wc[t - k]) for t in range(k, n)) / n
        total += np.trace(ck.T @ np.linalg.inv(c0) @ ck @ np.linalg.inv(c0)) / (n - k)
    assert got.statistic == pytest.approx(n * n * total, rel=1e-10)
    assert got.dof == 45


def test_portmanteau_size():
    """White innovations reject at about the nominal 5 % (binomial s.e. 0.7 % at 1000)."""
    rng = np.random.default_rng(5)
    p = np.array([portmanteau(rng.standard_normal((200, 2))).pvalue for _ in range(1000)])
    rate = float(np.mean(p < 0.05))
    assert abs(rate - 0.05) < 3 * np.sqrt(0.05 * 0.95 / 1000)


def test_monte_carlo_blocks_stay_within_runs():
    blocks, keys = elt.sign_blocks(30, 4, runs=3)  # 10 epochs per run: blocks of 4, 4, 2
    assert (
        blocks.tolist()
        == [0] * 4 + [1] * 4 + [2] * 2 + [3] * 4 + [4] * 4 + [5] * 2 + [6] * 4 + [7] * 4 + [8] * 2
    )
    assert np.all(np.diff(keys)[[2, 5]] >= 2)  # run boundaries are never adjacent
    assert elt.tested_blocks(30, 4, 10_000, runs=3) == 9
    same, _ = elt.sign_blocks(30, 4)
    np.testing.assert_array_equal(same, np.arange(30) // 4)


# --- config, baseline and gate, API ------------------------------------------------------


def test_input_table_of_a_config_equals_the_flags(tmp_path):
    config = tmp_path / "c.toml"
    config.write_text(
        f'[input]\ntruth = "{FORMATS / "euroc_groundtruth.csv"}"\nperturbation = "right"\n'
        'states = "orientation"\n'
    )
    flags = labels(
        FORMATS / "odom_ros.csv",
        "--truth",
        FORMATS / "euroc_groundtruth.csv",
        "--perturbation",
        "right",
        "--states",
        "orientation",
    )
    assert labels(FORMATS / "odom_ros.csv", "--config", config) == flags
    config.write_text('[input]\nstates = "sideways"\n')
    line = error_line(*run("diagnose", FORMATS / "odom_ros.csv", "--config", config)[::2])
    assert "states" in line


def test_gate_reads_like_its_baseline(tmp_path):
    base = tmp_path / "b.json"
    args = ("--truth", FORMATS / "euroc_groundtruth.csv", "--perturbation", "right")
    code, _, err = run("baseline", FORMATS / "odom_ros.csv", *args, "--window", "60s", "-o", base)
    assert code == 0, err
    recorded = json.loads(base.read_text())["parameters"]["input"]
    assert recorded["perturbation"] == "right" and recorded["truth"].endswith(
        "euroc_groundtruth.csv"
    )
    # the baseline keeps the reading settings (perturbation, window), never the truth's
    # path: the command line names the truth again (issue 32)
    code, _, err = run("gate", FORMATS / "odom_ros.csv", "--baseline", base)
    assert code == 2 and "give the new log's truth with --truth" in err
    code, out, err = run(
        "gate", FORMATS / "odom_ros.csv", "--baseline", base, "--truth", args[1], "-f", "json"
    )
    assert code == 0, err
    assert {c["status"] for c in json.loads(out)["segments"]} == {"unchanged"}
    # the same estimate against a truth 0.5 m off in x (10 σ): --truth replaces the
    # baseline's truth, and the gate fails
    truth = pd.read_csv(FORMATS / "euroc_groundtruth.csv")
    truth["p_RS_R_x [m]"] += 0.5
    moved = tmp_path / "moved.csv"
    truth.to_csv(moved, index=False)
    code, _, err = run("gate", FORMATS / "odom_ros.csv", "--baseline", base, "--truth", moved)
    assert code == 1 and "FAIL: 3 of 3 segment(s) regressed" in err  # 2 windows, the run


def test_innovations_take_no_truth():
    line = error_line(
        *run(
            "diagnose",
            FORMATS / "innovations.csv",
            "--innovations",
            "--truth",
            FORMATS / "mc_run_1.csv",
        )[::2]
    )
    assert "--innovations needs no ground truth" in line


def test_api_read_log_takes_the_reading_options():
    import credcli

    log = credcli.read_log(
        FORMATS / "odom.bag", topic="/odom", truth_topic="/ground_truth", states="planar"
    )
    assert log.dim == 3 and log.n == 1180 and any("planar" in n for n in log.notes)
    results = credcli.diagnose_log(log, "60s")
    assert [r.diagnosis.label.value for r in results] == ["pessimism"]
    with pytest.raises(credcli.CredcliError):
        credcli.read_log(FORMATS / "odom.bag", states="sideways")


@pytest.mark.parametrize(
    "args, expected",
    [
        (["--max-dt", "0.1"], "--max-dt applies to a separate ground truth"),
        (
            ["--time-offset", "0.5", "--perturbation", "right"],
            "--time-offset, --perturbation apply",
        ),
        (["--topic", "/odom"], "--topic applies to a separate ground truth"),
        (["--time-unit", "days"], "--time-unit"),
        (["--states", "sideways"], "--states"),
    ],
)
def test_options_that_would_be_ignored_are_errors(tmp_path, args, expected):
    line = error_line(*run("diagnose", FORMATS / "mc_run_1.csv", *args)[::2])
    assert expected in line


def test_truth_topic_on_a_text_truth_is_an_error():
    line = error_line(
        *run(
            "diagnose",
            FORMATS / "odom_ros.csv",
            "--truth",
            FORMATS / "euroc_groundtruth.csv",
            "--truth-topic",
            "/gt",
        )[::2]
    )
    assert "--truth-topic applies to bags" in line


def test_bag_without_header_stamps_uses_receive_times(monkeypatch):
    from credcli.io import rosbag

    real = rosbag._decode
    stamped = read_trajectory(FORMATS / "odom.bag", InputFormat.ROSBAG, "estimate", topic="/odom")

    def unstamped(reader, raws, msgtype):
        sec, nsec, p, q, c = real(reader, raws, msgtype)
        return sec * 0, nsec * 0, p, q, c

    monkeypatch.setattr(rosbag, "_decode", unstamped)
    traj = rosbag.read_bag(FORMATS / "odom.bag", "/odom", "estimate", "auto")
    late = traj.time - stamped.time  # the sample bag records /odom 1 ms after its stamp
    np.testing.assert_allclose(late, 1e-3, rtol=0, atol=1e-6)
    assert "no header stamps" in traj.notes[0]


def test_ros_csv_with_the_covariance_as_one_list_column(tmp_path):
    frame = pd.read_csv(FORMATS / "odom_ros.csv")
    cov_cols = [f"field.pose.covariance{k}" for k in range(36)]
    frame["field.pose.covariance"] = [
        "[" + ", ".join(repr(float(v)) for v in row) + "]" for row in frame[cov_cols].to_numpy()
    ]
    path = _csv(tmp_path, frame.drop(columns=cov_cols))
    args = (
        "--truth",
        FORMATS / "euroc_groundtruth.csv",
        "--perturbation",
        "right",
        "--window",
        "60s",
    )
    a = run("diagnose", path, *args, "-f", "json")
    b = run("diagnose", FORMATS / "odom_ros.csv", *args, "-f", "json")
    assert a[0] == 0
    strip = [{k: v for k, v in s.items() if k != "log"} for s in json.loads(a[1])["segments"]]
    assert strip == [
        {k: v for k, v in s.items() if k != "log"} for s in json.loads(b[1])["segments"]
    ]


def test_a_planar_robots_zero_z_variance_suggests_planar(tmp_path):
    frame = pd.read_csv(FORMATS / "odom_ros.csv")
    for k in (14, 21, 28):  # z, roll and pitch variances of a planar robot: 0
        frame[f"field.pose.covariance{k}"] = 0.0
    path = _csv(tmp_path, frame)
    line = error_line(*run("diagnose", path, "--truth", FORMATS / "euroc_groundtruth.csv")[::2])
    assert "--states planar" in line
    assert labels(path, "--truth", FORMATS / "euroc_groundtruth.csv", "--states", "planar")


@pytest.mark.parametrize("bag", ["odom.bag", "odom_ros2"])
def test_two_topics_of_one_bag_are_read_in_one_pass(bag, monkeypatch):
    """--topic and --truth-topic of one bag: the bag is opened once, and both trajectories
    equal those read one at a time (notes included)."""
    from rosbags.highlevel import AnyReader

    from credcli.io.formats import read_bag_pair

    opened = []
    original = AnyReader.open
    monkeypatch.setattr(AnyReader, "open", lambda self: opened.append(1) or original(self))
    path, auto = FORMATS / bag, InputFormat.AUTO
    pair = read_bag_pair(path, auto, auto, TimeUnit.AUTO, "/odom", "/ground_truth")
    assert opened == [1]
    alone = (
        read_trajectory(path, auto, "estimate", topic="/odom"),
        read_trajectory(path, auto, "truth", topic="/ground_truth"),
    )
    for a, b in zip(pair, alone):
        assert a.source == b.source and a.notes == b.notes
        for field in ("time", "position", "quaternion", "cov", "rows"):
            np.testing.assert_array_equal(getattr(a, field), getattr(b, field))
    assert read_bag_pair(FORMATS / "odom_ros.csv", auto, auto, TimeUnit.AUTO, None, None) is None
    opened.clear()  # and diagnose reads such a bag in one pass too
    assert labels(path, "--topic", "/odom", "--truth-topic", "/ground_truth") == ["pessimism"]
    assert opened == [1]


def test_the_note_says_which_covariance_blocks_were_read():
    """OpenVINS's 20-column TUM holds the rotation and position 3×3 blocks only: the note
    says the cross-covariance was not read; a ROS odometry CSV has the whole 6×6."""
    ov = ("diagnose", FORMATS / "openvins_estimate.txt", "--truth", FORMATS / "tum_groundtruth.txt")
    code, _, err = run(*ov, "--states", "pose")
    assert code == 0 and "no position–orientation cross-covariance" in err
    assert "whole 6×6" not in err
    ros = ("diagnose", FORMATS / "odom_ros.csv", "--truth", FORMATS / "euroc_groundtruth.csv")
    code, _, err = run(*ros, "--states", "pose", "--perturbation", "right")
    assert code == 0 and "the whole 6×6 covariance" in err


def test_one_run_given_twice_is_not_pooled(tmp_path):
    """Monte Carlo runs are pooled as independent draws: one log given twice (or a copy of
    it) counted its epochs twice, halved the standard errors and turned a credible segment
    into a bias, without a note."""
    one = sorted(FORMATS.glob("mc_run_*.csv"))[0]
    copy = tmp_path / "copy.csv"
    copy.write_bytes(one.read_bytes())
    for runs in ((one, one), (one, copy)):
        code, _, err = run("diagnose", *runs, "--monte-carlo")
        line = error_line(code, err)
        assert "its errors are those of" in line and "give each run once" in line


def test_an_estimate_logged_twice_is_an_error(tmp_path):
    """Two estimates with one stamp count one epoch twice; repeated truth stamps were an
    error already, repeated estimate stamps were read as more epochs. A covariance cell
    that is not a number is named as the covariance's (it was "in the estimate")."""
    lines = (FORMATS / "openvins_estimate.txt").read_text().splitlines(keepends=True)
    head = [line for line in lines if line.startswith("#")]
    body = [line for line in lines if line.strip() and not line.startswith("#")]
    twice = tmp_path / "twice.txt"
    twice.write_text("".join([*head, body[0], *body]))
    code, _, err = run("diagnose", twice, "--truth", FORMATS / "tum_groundtruth.txt")
    line = error_line(code, err)
    assert "have the same stamp 1700000000.0123 s" in line
    assert "estimate stamps must be distinct" in line
    cells = body[3].split()
    cells[-1] = "nan"
    holed = tmp_path / "holed.txt"
    holed.write_text("".join([*head, *body[:3], " ".join(cells) + "\n", *body[4:]]))
    code, _, err = run("diagnose", holed, "--truth", FORMATS / "tum_groundtruth.txt")
    assert "NaN, Inf or empty value in the estimate's covariance" in error_line(code, err)


def test_stamps_shifted_out_of_reach_are_written_short(tmp_path):
    """An offset of 1e300 s printed both stamps in 300 digits."""
    code, _, err = run(
        "diagnose",
        FORMATS / "openvins_estimate.txt",
        "--truth",
        FORMATS / "tum_groundtruth.txt",
        "--time-offset",
        "1e300",
    )
    line = error_line(code, err)
    assert "its stamps (1e+300 … 1e+300 s) do not overlap" in line and len(line) < 300


def test_a_quaternion_far_from_unit_norm_is_noted(tmp_path):
    """Quaternions of norm 2 (a wrong column or scale) were normalised without a word."""
    lines = (FORMATS / "openvins_estimate.txt").read_text().splitlines(keepends=True)
    head = [line for line in lines if line.startswith("#")]
    body = [line for line in lines if line.strip() and not line.startswith("#")]
    cells = body[5].split()
    cells[4:8] = [f"{2 * float(c):.9g}" for c in cells[4:8]]
    doubled = tmp_path / "doubled.txt"
    doubled.write_text("".join([*head, *body[:5], " ".join(cells) + "\n", *body[6:]]))
    code, _, err = run("diagnose", doubled, "--truth", FORMATS / "tum_groundtruth.txt")
    assert code == 0, err
    assert "1 quaternion(s) of norm far from 1 (first in row 6: 2)" in err
    code, _, err = run(
        "diagnose", FORMATS / "openvins_estimate.txt", "--truth", FORMATS / "tum_groundtruth.txt"
    )
    assert code == 0 and "quaternion(s) of norm" not in err


def test_a_run_copied_in_its_last_bits_is_not_pooled_as_another(tmp_path):
    """A copy of a run with truth and estimate shifted alike (its errors equal to rounding)
    passed a check of identical bytes and was pooled as an independent run."""
    one = sorted(FORMATS.glob("mc_run_*.csv"))[0]
    frame = pd.read_csv(one)
    for column in [c for c in frame.columns if c.startswith(("truth_", "est_"))]:
        frame[column] = frame[column] + 1000.125
    shifted = tmp_path / "shifted.csv"
    frame.to_csv(shifted, index=False)
    code, _, err = run("diagnose", one, shifted, "--monte-carlo")
    assert "its errors are those of" in error_line(code, err)
    others = sorted(FORMATS.glob("mc_run_*.csv"))
    code, _, err = run("diagnose", *others, "--monte-carlo")
    assert code == 0, err
