"""Alignment of an estimate kept in its own world frame (issue 33 item 5): Umeyama's closed
form against known transforms, scipy and brute force; logs moved by a known SE(3)/Sim(3)
are credible only once aligned, with the covariance moved as s² R Σ Rᵀ; the option on the
command line, in a config, in the Python API, in the JSON parameters and in the gate."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest
from helpers import ROOT, error_line, run
from scipy.spatial.transform import Rotation

from credcli import read_log
from credcli.engine.align import Alignment, Transform, covariance_map, origin, umeyama
from credcli.errors import CredcliError

FORMATS = ROOT / "sample_data" / "formats"
ESTIMATE, TRUTH = FORMATS / "openvins_estimate.txt", FORMATS / "tum_groundtruth.txt"


def rotation(d: int, seed: int) -> np.ndarray:
    if d == 3:
        return Rotation.random(random_state=seed).as_matrix()
    angle = np.random.default_rng(seed).uniform(-np.pi, np.pi)
    return np.array([[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]])


def cost(fit: Transform, x: np.ndarray, x_hat: np.ndarray) -> float:
    return float(((x - fit.apply(x_hat)) ** 2).sum())


# --- Umeyama's closed form -----------------------------------------------------------------


@pytest.mark.parametrize("d", [2, 3])
@pytest.mark.parametrize("with_scale", [False, True])
def test_umeyama_recovers_a_known_transform_from_noiseless_points(d, with_scale):
    rng = np.random.default_rng(d)
    for seed in range(20):
        x_hat = rng.normal(size=(50, d)) * [3.0, 1.0, 0.5][:d]
        r, t = rotation(d, seed), rng.normal(size=d) * 10
        s = rng.uniform(0.2, 5.0) if with_scale else 1.0
        fit = umeyama(s * x_hat @ r.T + t, x_hat, with_scale)
        np.testing.assert_allclose(fit.rotation, r, atol=1e-10)
        np.testing.assert_allclose(fit.translation, t, atol=1e-10)
        assert fit.scale == pytest.approx(s, abs=1e-10)
        assert np.linalg.det(fit.rotation) == pytest.approx(1.0, abs=1e-12)


@pytest.mark.parametrize("d", [2, 3])
def test_the_reflection_fix_recovers_rotations_of_degenerate_point_sets(d):
    """Points on a plane in 3-D (a ground robot) or on a line in 2-D: Σ_xx̂ has rank d − 1,
    its SVD is free to return det(U) det(V) = −1, and only S = diag(1, …, det U det V)
    (Umeyama's Eq. 43) gives back the rotation rather than a reflection."""
    rng = np.random.default_rng(7)
    flipped = 0
    for seed in range(40):
        x_hat = np.zeros((30, d))
        x_hat[:, : d - 1] = rng.normal(size=(30, d - 1))
        r, t, s = rotation(d, seed), rng.normal(size=d), rng.uniform(0.5, 2.0)
        x = s * x_hat @ r.T + t
        u, _, vt = np.linalg.svd((x - x.mean(0)).T @ (x_hat - x_hat.mean(0)))
        flipped += np.linalg.det(u) * np.linalg.det(vt) < 0
        fit = umeyama(x, x_hat, with_scale=True)
        np.testing.assert_allclose(fit.rotation, r, atol=1e-10)
        np.testing.assert_allclose(fit.translation, t, atol=1e-10)
        assert fit.scale == pytest.approx(s, abs=1e-10)
    assert flipped > 0  # the fix was needed, not only present


def test_a_mirrored_pattern_gets_the_best_proper_rotation():
    """Truth = the estimate mirrored (det −1): the best orthogonal map is a reflection;
    Umeyama returns a rotation (det +1) whose cost no rotation beats (scipy's Kabsch)."""
    rng = np.random.default_rng(3)
    x_hat = rng.normal(size=(40, 3)) * [3.0, 2.0, 1.0]
    x = x_hat * [1.0, 1.0, -1.0] + [1.0, 2.0, 3.0]
    fit = umeyama(x, x_hat)
    assert np.linalg.det(fit.rotation) == pytest.approx(1.0)
    centred, centred_hat = x - x.mean(0), x_hat - x_hat.mean(0)
    kabsch, _ = Rotation.align_vectors(centred, centred_hat)
    np.testing.assert_allclose(fit.rotation, kabsch.as_matrix(), atol=1e-9)
    for seed in range(200):  # no rotation (with its best translation) does better
        other = Rotation.random(random_state=seed).as_matrix()
        best_t = x.mean(0) - other @ x_hat.mean(0)
        assert cost(fit, x, x_hat) <= cost(Transform(other, best_t), x, x_hat) + 1e-9


def test_umeyama_equals_scipy_kabsch_and_the_planar_closed_form_on_noisy_points():
    rng = np.random.default_rng(11)
    x_hat = rng.normal(size=(100, 3)) * [5.0, 3.0, 1.0]
    x = x_hat @ rotation(3, 1).T + [4.0, -2.0, 1.0] + rng.normal(scale=0.3, size=(100, 3))
    fit = umeyama(x, x_hat)
    expected, _ = Rotation.align_vectors(x - x.mean(0), x_hat - x_hat.mean(0))
    np.testing.assert_allclose(fit.rotation, expected.as_matrix(), atol=1e-9)
    np.testing.assert_allclose(fit.translation, x.mean(0) - fit.rotation @ x_hat.mean(0))
    # in the plane the best angle is atan2(Σ x̂ × x, Σ x̂ · x) of the centred points
    a, b = x_hat[:, :2] - x_hat[:, :2].mean(0), x[:, :2] - x[:, :2].mean(0)
    angle = np.arctan2((a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]).sum(), (a * b).sum())
    planar = umeyama(x[:, :2], x_hat[:, :2])
    assert planar.angle_degrees == pytest.approx(np.degrees(angle), abs=1e-9)


@pytest.mark.parametrize("d", [2, 3])
def test_no_small_change_of_r_t_or_s_lowers_the_sim3_cost(d):
    rng = np.random.default_rng(5 + d)
    x_hat = rng.normal(size=(80, d)) * 2
    x = 1.7 * x_hat @ rotation(d, 2).T + 3 + rng.normal(scale=0.5, size=(80, d))
    fit = umeyama(x, x_hat, with_scale=True)
    best = cost(fit, x, x_hat)
    for step in (1e-2, 1e-4):
        for k in range(50):
            if d == 3:
                axis = Rotation.random(random_state=100 + k).as_rotvec()
                turn = Rotation.from_rotvec(axis / np.linalg.norm(axis) * step).as_matrix()
            else:
                turn = _planar(step * (k - 25) / 25)
            r = turn @ fit.rotation
            for candidate in (
                Transform(r, fit.translation, fit.scale),
                Transform(fit.rotation, fit.translation + step * rng.normal(size=d), fit.scale),
                Transform(fit.rotation, fit.translation, fit.scale * (1 + step * (k - 25) / 25)),
            ):
                assert cost(candidate, x, x_hat) >= best - 1e-9


def _planar(angle: float) -> np.ndarray:
    return np.array([[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]])


def test_degrees_of_freedom_and_degenerate_inputs():
    assert [Alignment(a).fitted_parameters(3) for a in ("none", "origin", "se3", "sim3")] == [
        0,
        0,
        6,
        7,
    ]
    assert Alignment.SE3.fitted_parameters(2) == 3 and Alignment.SIM3.fitted_parameters(2) == 4
    line = np.c_[np.arange(10.0), 2 * np.arange(10.0), np.zeros(10)]  # a line in 3-D
    with pytest.raises(CredcliError, match="`align` cannot fit a rotation") as info:
        umeyama(line, line)
    assert info.value.parameter == "align"
    with pytest.raises(CredcliError, match="2-D or 3-D"):
        umeyama(np.zeros((5, 4)), np.zeros((5, 4)))
    # origin: T_true T_est⁻¹ maps the estimate's pose onto the truth's
    r_true, r_est = rotation(3, 1), rotation(3, 2)
    fit = origin(np.array([1.0, 2, 3]), np.array([-1.0, 0, 5]), r_true, r_est)
    np.testing.assert_allclose(fit.apply(np.array([[-1.0, 0, 5]]))[0], [1, 2, 3])
    np.testing.assert_allclose(fit.rotation @ r_est, r_true, atol=1e-12)


@pytest.mark.parametrize("with_scale", [False, True])
def test_positions_whose_squares_overflow_are_fitted_in_a_power_of_two(with_scale):
    """Positions of 2^520 (their squares overflow) give the fit of the same positions at
    unit scale: the same R and s, t times 2^520; one position of 1e308 among ordinary ones
    is named (it was numpy's "SVD did not converge", exit 3)."""
    rng = np.random.default_rng(4)
    x_hat = rng.standard_normal((40, 3))
    x = 1.5 * x_hat @ rotation(3, 8).T + [1.0, -2.0, 0.5] + 0.01 * rng.standard_normal((40, 3))
    plain, far = umeyama(x, x_hat, with_scale), umeyama(x * 2.0**520, x_hat * 2.0**520, with_scale)
    np.testing.assert_allclose(far.rotation, plain.rotation, rtol=0, atol=1e-12)
    np.testing.assert_allclose(far.translation, plain.translation * 2.0**520, rtol=1e-12)
    assert far.scale == pytest.approx(plain.scale, rel=1e-12)
    x_hat[7] = [1e308, 0.0, 0.0]
    with pytest.raises(CredcliError, match="a position reaches 1e[+]308") as info:
        umeyama(x, x_hat, with_scale)
    assert info.value.parameter == "align"


def test_covariance_map_by_perturbation():
    fit = Transform(rotation(3, 4), np.zeros(3), 2.0)
    left, right = covariance_map(fit, 6, world=True), covariance_map(fit, 6, world=False)
    np.testing.assert_allclose(left[:3, :3], 2.0 * fit.rotation)
    np.testing.assert_allclose(left[3:, 3:], fit.rotation)
    np.testing.assert_allclose(right, np.diag([2.0, 2, 2, 1, 1, 1]))
    np.testing.assert_allclose(covariance_map(fit, 3), 2.0 * fit.rotation)


# --- a log in its own frame ---------------------------------------------------------------


def moved_log(path, scale: float, seed: int = 2024, n: int = 600):
    """A credcli log whose estimate lives in a frame moved by a known Sim(3): truth x_k on
    a 3-D curve, errors e_k ~ N(0, Σ_w) in the truth's frame, x̂_k = (R0ᵀ(x_k − e_k −
    t0))/s and the honest claimed covariance in the estimate's frame, R0ᵀ Σ_w R0 / s²."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) * 0.1
    x = np.c_[10 * np.cos(0.05 * t), 6 * np.sin(0.1 * t), 0.3 * t]
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    sigma_w = q @ np.diag([0.04, 0.09, 0.01]) @ q.T
    errors = rng.multivariate_normal(np.zeros(3), sigma_w, size=n)
    r0, t0 = rotation(3, 9), np.array([50.0, -20.0, 3.0])
    x_hat = (x - errors - t0) @ r0 / scale
    sigma_e = r0.T @ sigma_w @ r0 / scale**2
    frame = pd.DataFrame({"time": t})
    for i in range(3):
        frame[f"truth_{i}"], frame[f"est_{i}"] = x[:, i], x_hat[:, i]
    for i in range(3):
        for j in range(3):
            frame[f"cov_{i}_{j}"] = sigma_e[i, j]
    frame.to_csv(path, index=False)
    return x, x_hat, sigma_e, sigma_w


def labels(*args) -> tuple[list[str], str, dict]:
    code, out, err = run("diagnose", *map(str, args), "--whole", "-f", "json")
    assert code == 0, err
    doc = json.loads(out)
    return [s["label"] for s in doc["segments"]], err, doc


@pytest.mark.parametrize(("align", "scale"), [("se3", 1.0), ("sim3", 0.8)])
def test_a_moved_log_is_credible_only_once_aligned(tmp_path, align, scale):
    path = tmp_path / "moved.csv"
    x, x_hat, sigma_e, sigma_w = moved_log(path, scale)
    unaligned, _, _ = labels(path)
    assert unaligned[0] != "credible"  # tens of metres of bias against a 0.3 m σ
    aligned, err, doc = labels(path, "--align", align)
    # the fit made the whole log's mean error 0: its location question stays open
    assert aligned == ["credible (location untested)"]
    assert "fitted the mean of these errors to 0" in doc["segments"][0]["reason"]
    assert f"credcli: note: --align {align}:" in err
    assert f"{7 if align == 'sim3' else 6} degrees of freedom" in err
    assert doc["parameters"]["input"]["align"] == align
    # the log read by Python: estimate and covariance moved by the fitted transform
    log = read_log(path, align=align)
    fit = umeyama(x, x_hat, with_scale=align == "sim3")
    np.testing.assert_allclose(log.estimate, fit.apply(x_hat), atol=1e-9)
    expected = fit.scale**2 * fit.rotation @ sigma_e @ fit.rotation.T
    np.testing.assert_allclose(log.cov, np.broadcast_to(expected, log.cov.shape), atol=1e-12)
    np.testing.assert_allclose(log.cov[0], sigma_w, rtol=0.05, atol=1e-3)  # ≈ the truth's Σ
    assert fit.scale == pytest.approx(scale, rel=1e-2)  # x = s R x̂ + t


def test_se3_cannot_absorb_a_scale(tmp_path):
    path = tmp_path / "scaled.csv"
    moved_log(path, 0.8)
    assert labels(path, "--align", "se3")[0] != ["credible"]
    assert labels(path, "--align", "sim3")[0] == ["credible (location untested)"]


def test_origin_translates_a_position_log_onto_its_first_epoch(tmp_path):
    path = tmp_path / "shifted.csv"
    x, x_hat, sigma_e, _ = moved_log(path, 1.0)
    log = read_log(path, align="origin")
    np.testing.assert_allclose(log.estimate, x_hat - x_hat[0] + x[0], atol=1e-12)
    np.testing.assert_allclose(log.cov[0], sigma_e, atol=1e-15)  # R = I, s = 1
    assert "translation only" in log.notes[-1] and "first epoch's error is 0" in log.notes[-1]


# --- a pose file in its own frame ----------------------------------------------------------


def rotated_openvins(path, r0: np.ndarray, t0: np.ndarray) -> np.ndarray:
    """The OpenVINS sample moved into a frame T0⁻¹: p' = R0ᵀ(p − t0), R' = R0ᵀ R, and
    both 3×3 covariance blocks (left perturbation, world frame) R0ᵀ Σ R0."""
    data = np.loadtxt(ESTIMATE)
    out = data.copy()
    out[:, 1:4] = (data[:, 1:4] - t0) @ r0
    out[:, 4:8] = (Rotation.from_matrix(r0.T) * Rotation.from_quat(data[:, 4:8])).as_quat()
    iu = np.triu_indices(3)
    for start in (8, 14):  # Pr (rotation), then Pt (position), upper triangles
        block = np.zeros((len(data), 3, 3))
        block[:, iu[0], iu[1]] = data[:, start : start + 6]
        block = block + np.triu(block, 1).transpose(0, 2, 1)
        out[:, start : start + 6] = (r0.T @ block @ r0)[:, iu[0], iu[1]]
    header = ESTIMATE.read_text().splitlines()[0]
    np.savetxt(path, out, fmt="%.12f", header=header[2:], comments="# ")
    return data


def test_a_rotated_openvins_estimate_is_credible_again_after_se3(tmp_path):
    path = tmp_path / "rotated.txt"
    r0, t0 = Rotation.from_euler("zyx", [40, 5, -3], degrees=True).as_matrix(), np.ones(3)
    rotated_openvins(path, r0, t0)
    assert labels(ESTIMATE, "--truth", TRUTH)[0] == ["credible"]  # the planted sample
    assert labels(path, "--truth", TRUTH)[0] != ["credible"]
    aligned, err, _ = labels(path, "--truth", TRUTH, "--align", "se3")
    assert aligned == ["credible (location untested)"] and "SE(3) transform of Umeyama" in err
    # the errors are truth − the fitted transform of the file's positions, exactly
    plain = read_log(path, truth=str(TRUTH))
    p_hat = np.loadtxt(path)[:, 1:4]
    p_true = plain.errors + p_hat
    fit = umeyama(p_true, p_hat)
    np.testing.assert_allclose(fit.rotation, r0, atol=2e-3)  # the planted frame, to noise
    log = read_log(path, truth=str(TRUTH), align="se3")
    np.testing.assert_allclose(log.errors, p_true - fit.apply(p_hat), atol=1e-9)
    np.testing.assert_allclose(
        log.cov, fit.rotation @ plain.cov @ fit.rotation.T, atol=1e-12
    )  # s² R Σ Rᵀ with s = 1


@pytest.mark.parametrize("perturbation", ["left", "right"])
def test_pose_covariance_follows_the_perturbation(tmp_path, perturbation):
    """Left: both blocks turn with R (diag(R, R)); right: body-frame errors, unchanged."""
    path = tmp_path / "rotated.txt"
    r0 = Rotation.from_euler("z", 70, degrees=True).as_matrix()
    rotated_openvins(path, r0, np.zeros(3))
    args = {"truth": str(TRUTH), "states": "pose", "perturbation": perturbation}
    plain, log = read_log(path, **args), read_log(path, **args, align="se3")
    p_hat = np.loadtxt(path)[:, 1:4]
    fit = umeyama(read_log(path, truth=str(TRUTH)).errors + p_hat, p_hat)
    jac = np.kron(np.eye(2), fit.rotation) if perturbation == "left" else np.eye(6)
    np.testing.assert_allclose(log.cov, jac @ plain.cov @ jac.T, atol=1e-12)
    # with the planted frame taken out, the orientation errors are the sample's again
    sample = read_log(ESTIMATE, **args)
    assert np.abs(log.errors[:, 3:] - sample.errors[:, 3:]).max() < 5e-3


def test_planar_alignment_fits_se2_and_keeps_the_heading_variance(tmp_path):
    path = tmp_path / "rotated.txt"
    rotated_openvins(path, Rotation.from_euler("z", -25, degrees=True).as_matrix(), np.ones(3))
    args = {"truth": str(TRUTH), "states": "planar"}
    plain, log = read_log(path, **args), read_log(path, **args, align="se3")
    assert "SE(2) transform" in log.notes[3] and "3 degrees of freedom" in log.notes[3]
    np.testing.assert_allclose(log.cov[:, 2, 2], plain.cov[:, 2, 2], atol=1e-15)
    assert "rotation -25" in log.notes[3] or "rotation 25" in log.notes[3]
    assert np.abs(log.errors[:, 2]).max() < np.abs(plain.errors[:, 2]).max()


# --- the option on the command line, in a config, in the gate -----------------------------


def test_align_on_the_command_line_and_in_a_config(tmp_path):
    path = tmp_path / "moved.csv"
    moved_log(path, 1.0)
    config = tmp_path / "c.toml"
    config.write_text('[input]\nalign = "se3"\n')
    flags, err_flags, doc_flags = labels(path, "--align", "se3")
    from_config, err_config, doc_config = labels(path, "--config", config)
    assert from_config == flags and err_config == err_flags
    assert doc_config["segments"] == doc_flags["segments"]
    line = error_line(*run("diagnose", path, "--align", "se4")[::2])
    assert "--align" in line
    config.write_text('[input]\nalign = "se4"\n')
    line = error_line(*run("diagnose", path, "--config", config)[::2])
    assert "align" in line


def test_align_is_refused_where_there_is_no_estimate():
    line = error_line(
        *run("diagnose", FORMATS / "innovations.csv", "--innovations", "--align", "se3")[::2]
    )
    assert "--align se3 moves an estimate onto its truth" in line
    line = error_line(
        *run("diagnose", ROOT / "sample_data" / "errors_only.csv", "--align", "origin")[::2]
    )
    assert "--align" in line and "errors only" in line
    with pytest.raises(CredcliError, match="`align` origin moves an estimate"):
        read_log(ROOT / "sample_data" / "errors_only.csv", errors_only=True, align="origin")


def test_the_gate_names_a_differing_align(tmp_path):
    path, base = tmp_path / "moved.csv", tmp_path / "base.json"
    moved_log(path, 1.0)
    code, _, err = run("baseline", path, "--whole", "--align", "se3", "-o", base)
    assert code == 0, err
    assert json.loads(base.read_text())["parameters"]["input"]["align"] == "se3"
    config = tmp_path / "c.toml"
    config.write_text('[input]\nalign = "none"\n')
    line = error_line(*run("gate", path, "-b", base, "--config", config)[::2])
    assert "[input] align: baseline 'se3', now 'none'" in line
    assert run("gate", path, "-b", base)[0] == 0  # read as the baseline was: aligned


def test_windows_of_an_aligned_log_still_answer_the_location_question(tmp_path):
    """After se3 the mean of the whole log's errors is 0 by construction (Umeyama's
    t = μ − s R μ̂), so the run's own verdict leaves the location open; its windows' means
    are not fitted, and their location question is answered."""
    path = tmp_path / "moved.csv"
    moved_log(path, 1.0)
    code, out, err = run("diagnose", path, "--align", "se3", "--window", "150", "-f", "json")
    assert code == 0, err
    segments = {s["segment"]: s for s in json.loads(out)["segments"]}
    assert segments.pop("run")["label"] == "credible (location untested)"
    assert [s["label"] for s in segments.values()] == ["credible"] * 4


def test_without_location_keeps_the_noise_condition():
    from credcli.engine.diagnosis import Diagnosis, Label, Question, without_location

    found = without_location(Diagnosis(Label.OPTIMISM_BIAS, 100, 2, smm_detected=True), "fitted")
    assert (found.label, found.untested, found.reason) == (
        Label.OPTIMISM,
        (Question.LOCATION,),
        "fitted",
    )
    scale_open = Diagnosis(Label.BIAS, 100, 2, untested=(Question.SCALE,), reason="short")
    assert without_location(scale_open, "fitted").label is Label.INSUFFICIENT
    assert without_location(scale_open, "fitted").reason == "short; fitted"


@pytest.mark.parametrize("units", [1e-300, 1e200])
def test_umeyama_fits_a_scale_whatever_the_estimate_units(units):
    """Estimate positions in units of 1e-300 (or 1e200) of the truth's: σ²_x̂ once
    underflowed to 0 (ZeroDivisionError, exit 3). The fit is made in power-of-two units,
    s and t scaled back: s·units = 2.5, R and t as for units of 1."""
    gen = np.random.default_rng(3)
    x_hat = gen.standard_normal((50, 3))
    r = np.linalg.qr(gen.standard_normal((3, 3)))[0]
    r[:, 0] *= np.sign(np.linalg.det(r))
    fit = umeyama(2.5 * x_hat @ r.T + [1.0, 2.0, 3.0], x_hat * units, with_scale=True)
    assert fit.scale * units == pytest.approx(2.5, rel=1e-12)
    np.testing.assert_allclose(fit.rotation, r, atol=1e-12)
    np.testing.assert_allclose(fit.translation, [1.0, 2.0, 3.0], atol=1e-12)
