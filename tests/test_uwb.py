"""The UWB pipeline: packets, WLS, anchors, static periods, and the real STAR-loc file."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest
from helpers import SAMPLE, SHARED

from credcli.cli import main
from credcli.segments import static_periods
from credcli.studies import uwb
from credcli.studies.samples import STARLOC_ANCHORS

GRID = SAMPLE / "starloc_grid_uwb.csv"
REAL = SHARED / "data" / "starloc" / "loop-2d-fast_s2_uwb.csv"
real_file = pytest.mark.skipif(
    not REAL.exists(), reason=f"real STAR-loc data not found at {REAL} (../shared absent)"
)


def _run(capsys, *args):
    code = main([str(a) for a in args])
    out, err = capsys.readouterr()
    return code, out, err


def _ranges(time, anchor, tag=None, rng_value=1.0):
    n = len(time)
    return uwb.RangeLog(
        source="t",
        time=np.asarray(time, float),
        range=np.full(n, rng_value),
        std=np.full(n, 0.1),
        tag=np.ones(n, int) if tag is None else np.asarray(tag),
        anchor=np.asarray(anchor),
        tag_pos=np.zeros((n, 3)),
        rig_pos=np.zeros((n, 3)),
        gt_range=np.full(n, rng_value),
        range_column="range_calib",
    )


def test_packets_group_distinct_anchors_within_the_window():
    r = _ranges([0.0, 0.01, 0.02, 0.025, 0.05, 0.06, 0.07, 0.2, 0.21], [1, 2, 2, 3, 4, 5, 6, 7, 8])
    p = uwb.make_packets(r, window=0.03, min_anchors=3)
    rows = [list(row[row >= 0]) for row in p.rows]
    # first packet: rows 0..3 within 0.03 s, the repeated anchor 2 kept once
    assert rows == [[0, 1, 3], [4, 5, 6]]  # rows 7, 8 have only two anchors: dropped
    per_tag = uwb.make_packets(
        _ranges([0, 0.001, 0.002, 0.003], [1, 2, 3, 4], tag=[1, 2, 1, 2]), 0.03, 2
    )
    assert sorted(map(tuple, (r[r >= 0] for r in per_tag.rows))) == [(0, 2), (1, 3)]


def _packet_log(true_xy, height, anchors, ranges_value, std):
    n = len(anchors)
    return uwb.RangeLog(
        source="t",
        time=np.linspace(0, 0.02, n),
        range=np.asarray(ranges_value),
        std=np.asarray(std),
        tag=np.ones(n, int),
        anchor=np.arange(1, n + 1),
        tag_pos=np.tile([*true_xy, height], (n, 1)),
        rig_pos=np.zeros((n, 3)),
        gt_range=np.asarray(ranges_value),
        range_column="range_calib",
    )


def test_wls_recovers_position_and_covariance():
    anchor_xyz = np.array([[-3, -3, 2.0], [3, -3, 1.0], [3, 3, 2.5], [-3, 3, 0.8]])
    true = np.array([0.7, -0.4])
    height = 1.1
    exact = np.linalg.norm(anchor_xyz - np.r_[true, height], axis=1)
    std = np.array([0.1, 0.2, 0.1, 0.3])
    anchors = [uwb.Anchor(i + 1, a, "markers", 0.0, 1) for i, a in enumerate(anchor_xyz)]
    log = _packet_log(true, height, anchors, exact, std)
    fixes = uwb.solve_packets(log, uwb.make_packets(log, 0.03, 3), anchors)
    np.testing.assert_allclose(fixes.estimate[0], true, atol=1e-9)
    h = (true - anchor_xyz[:, :2]) / exact[:, None]
    np.testing.assert_allclose(fixes.cov[0], np.linalg.inv(h.T @ np.diag(std**-2) @ h), rtol=1e-8)
    # with noisy ranges the solution is the weighted least-squares minimum (gradient zero)
    noisy = exact + np.array([0.05, -0.12, 0.03, 0.2])
    log = _packet_log(true, height, anchors, noisy, std)
    est = uwb.solve_packets(log, uwb.make_packets(log, 0.03, 3), anchors).estimate[0]
    d = np.linalg.norm(anchor_xyz - np.r_[est, height], axis=1)
    jac = (est - anchor_xyz[:, :2]) / d[:, None]
    np.testing.assert_allclose(jac.T @ ((noisy - d) / std**2), 0, atol=1e-9)


def test_static_periods_of_the_grid_sample():
    r = uwb.read_starloc(GRID)
    periods, speed = static_periods(r.time, r.rig_pos)
    assert [p.name for p in periods] == ["P1", "P2", "P3", "P4", "P5", "P6"]
    # dwell 6 s at each stop; the speed window (±0.1 s) trims ~0.1 s at each end
    for p in periods:
        assert 5.6 <= p.t_end - p.t_start <= 6.0
    assert speed.max() == pytest.approx(0.4, rel=0.05)  # the rig's travel speed


def test_self_calibrated_anchors_of_the_grid_sample():
    for a in uwb.calibrate_anchors(uwb.read_starloc(GRID)):
        np.testing.assert_allclose(a.position, STARLOC_ANCHORS[a.id], atol=1e-5)
        assert a.rms < 1e-5


def test_markers_file(tmp_path, capsys):
    markers = tmp_path / "markers.csv"
    pd.DataFrame([(k, *v) for k, v in STARLOC_ANCHORS.items()], columns=["", "x", "y", "z"]).to_csv(
        markers, index=False
    )
    code, out, _ = _run(capsys, "uwb", GRID, "--anchors", markers, "-f", "json")
    assert code == 0
    doc = json.loads(out)
    assert {a["source"] for a in doc["anchors"]} == {"markers"}
    assert max(a["rms_mm"] for a in doc["anchors"]) < 0.01
    code, _, err = _run(
        capsys, "uwb", GRID, "--anchors", SHARED / "data" / "starloc" / "uwb_markers_v3.csv"
    )
    if (SHARED / "data" / "starloc" / "uwb_markers_v3.csv").exists():
        assert code == 2 and "no marker for anchor id(s) 5, 6, 7, 10" in err


def test_grid_sample_is_pessimism_plus_bias_in_every_period(capsys):
    code, out, _ = _run(capsys, "uwb", GRID, "-f", "json")
    assert code == 0
    doc = json.loads(out)
    assert [s["segment"] for s in doc["segments"]] == ["P1", "P2", "P3", "P4", "P5", "P6"]
    assert all(s["label"] == "pessimism+bias" for s in doc["segments"])
    assert set(doc) >= {"parameters", "version", "segments", "anchors", "ranges"}
    # range-level evidence: reported std about twice the empirical one (Fig. 5)
    ratios = [r["std_ratio"] for r in doc["ranges"]]
    assert len(ratios) == 48 and 0.4 < np.median(ratios) < 0.6
    assert all(s["t_start"] is not None and s["t_end"] > s["t_start"] for s in doc["segments"])


def test_export_log_reruns_with_diagnose(tmp_path, capsys):
    exported = tmp_path / "fixes.csv"
    _, out, _ = _run(capsys, "uwb", GRID, "-f", "json", "--export-log", exported)
    uwb_segments = json.loads(out)["segments"]
    code, out, _ = _run(capsys, "diagnose", exported, "-f", "json")
    assert code == 0
    again = json.loads(out)["segments"]
    assert len(again) == len(uwb_segments) > 0
    keys = ["segment", "n", "label", "elt_pvalue", "nci", "anees", "nees_label", "nci_label"]
    for a, b in zip(uwb_segments, again):
        for k in keys:
            assert (
                a[k] == pytest.approx(b[k], rel=1e-12) if isinstance(a[k], float) else a[k] == b[k]
            )


def test_setup_s5_files(tmp_path, capsys):
    frame = pd.read_csv(GRID).drop(columns=["std", "range_calib", "bias_calib"])
    s5 = tmp_path / "s5_uwb.csv"
    frame.to_csv(s5, index=False)
    code, _, err = _run(capsys, "uwb", s5)
    assert code == 2 and "no 'std' column" in err and "--std VALUE" in err
    code, out, _ = _run(capsys, "uwb", s5, "--std", "0.1", "-f", "json")
    assert code == 0
    doc = json.loads(out)
    assert doc["parameters"]["std"] == 0.1 and len(doc["segments"]) == 6


def test_raw_range_column(capsys):
    _, out, _ = _run(capsys, "uwb", GRID, "--range-column", "range", "-f", "json")
    ranges = json.loads(out)["ranges"]
    # raw ranges carry the extra 8 cm offset of the generator
    assert np.mean([r["mean_error"] for r in ranges]) > 0.08


def test_no_static_period_says_so(tmp_path, capsys):
    frame = pd.read_csv(GRID)
    frame["x"] = frame["x"] + 0.5 * frame["time_s"]  # the rig never stops
    moving = tmp_path / "moving.csv"
    frame.to_csv(moving, index=False)
    code, _, err = _run(capsys, "uwb", moving)
    assert code == 2 and "no static period found" in err and "--window 5s" in err


def test_a_ground_truth_too_large_to_calibrate_from_is_named(tmp_path, capsys):
    """A gt_range of 1e308 (a corrupt cell) made the anchor's linearised fit overflow, and
    numpy's least squares failed (exit 3): the anchor, the size and --anchors are named."""
    frame = pd.read_csv(GRID)
    frame.loc[5, "gt_range"] = 1e308
    corrupt = tmp_path / "corrupt.csv"
    frame.to_csv(corrupt, index=False)
    code, _, err = _run(capsys, "uwb", corrupt)
    anchor = int(frame.loc[5, "to_id"])
    assert code == 2 and err.count("\n") == 1
    assert f"anchor {anchor}: its ground truth" in err and "1e+308" in err and "--anchors" in err


def test_not_a_starloc_file(capsys):
    code, _, err = _run(capsys, "uwb", SAMPLE / "estimator_log.csv")
    assert code == 2 and "not a STAR-loc uwb.csv: missing column(s) time_s" in err


@real_file
def test_real_file_end_to_end_with_windows(tmp_path, capsys):
    exported = tmp_path / "fixes.csv"
    code, out, _ = _run(
        capsys, "uwb", REAL, "--window", "5s", "-f", "json", "--export-log", exported
    )
    assert code == 0
    doc = json.loads(out)
    assert len(doc["segments"]) == 7
    # the reported noise is optimistic (facts of the data README): every window's ANEES > 1
    assert all(s["anees"] > 1 for s in doc["segments"])
    assert exported.stat().st_size > 0


@real_file
def test_real_file_self_calibrated_anchors_within_1mm():
    ranges = uwb.read_starloc(REAL)
    anchors = uwb.calibrate_anchors(ranges)
    assert [a.id for a in anchors] == [4, 5, 6, 7, 9, 10, 11, 12]
    assert max(a.rms for a in anchors) < 1e-3
    # README: consistent with uwb_markers_v1 under another id mapping (horizontal positions)
    v1 = uwb.read_markers(SHARED / "data" / "starloc" / "uwb_markers_v1.csv")
    for a in anchors:
        nearest = min(np.linalg.norm(a.position[:2] - p[:2]) for p in v1.values())
        assert nearest < 0.01


@real_file
def test_real_file_range_table_matches_the_data_readme(capsys):
    # the README's facts are of every row: no screening
    _, out, _ = _run(capsys, "uwb", REAL, "--whole", "--screen", "none", "-f", "json")
    ranges = json.loads(out)["ranges"]
    assert len(ranges) == 8
    means = [r["mean_error"] for r in ranges]
    assert -0.011 <= min(means) <= -0.009 and 0.34 <= max(means) <= 0.35
    assert sum(r["std_error"] > r["median_std"] for r in ranges) == 6


@real_file
def test_real_file_has_no_static_period(capsys):
    code, _, err = _run(capsys, "uwb", REAL)
    assert code == 2 and "no static period found" in err


def test_real_s5_windows_print_as_a_table(capsys):
    """The real loop-2d_s5 run in 5-s windows, as a user first runs it (a table): every
    window prints, with its interval or "(no interval)" (the latter is checked on
    synthetic windows in test_dependence_verdicts), not as an internal error."""
    s5 = SHARED / "data" / "starloc" / "loop-2d_s5_uwb.csv"
    if not s5.exists():
        pytest.skip("the STAR-loc data are not beside the repository")
    code, out, err = _run(capsys, "uwb", s5, "--window", "5s", "--std", "0.1")
    assert code == 0, err
    assert "Table IV" in out and all(f"w{k:03d}" in out for k in range(1, 14))


@pytest.mark.parametrize("cell", ["", "nan", "inf"])
def test_a_marker_without_a_finite_position_is_named(tmp_path, cell):
    from credcli.errors import CredcliError
    from credcli.io.starloc import read_markers

    path = tmp_path / "markers.csv"
    path.write_text(f",x,y,z\n10,1.0,2.0,0.5\n11,3.0,{cell},0.5\n")
    with pytest.raises(CredcliError, match="row 2: marker 11 has a position that is not"):
        read_markers(path)


def test_a_marker_given_twice_is_an_error(tmp_path):
    """Two positions for one anchor id: which one ranged is unknown (it was taken silently,
    the last one winning)."""
    from credcli.errors import CredcliError
    from credcli.io.starloc import read_markers

    path = tmp_path / "markers.csv"
    path.write_text(",x,y,z\n10,1.0,2.0,0.5\n11,3.0,1.0,0.5\n10,1.5,2.0,0.5\n")
    with pytest.raises(CredcliError, match="marker id 10 is given twice \\(rows 1 and 3\\)"):
        read_markers(path)
