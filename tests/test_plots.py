"""Figures and the HTML report: valid PNGs whose data are the computed numbers."""

from __future__ import annotations

import json
import re
import shutil
import struct
import subprocess
import sys

import numpy as np
import pytest
from scipy import stats

pytest.importorskip("matplotlib", reason="matplotlib (credcli[plots]) not installed")

from conftest import SAMPLE  # noqa: E402

from credcli import DiagnosisConfig, load_log  # noqa: E402
from credcli.cli import main  # noqa: E402
from credcli.engine import metrics  # noqa: E402
from credcli.engine.diagnosis import diagnose_log  # noqa: E402
from credcli.engine.elt import whiten  # noqa: E402
from credcli.report import plots  # noqa: E402
from credcli.segments import split  # noqa: E402
from credcli.studies import simulate as sim  # noqa: E402
from credcli.workflows import segment_figures  # noqa: E402

LOG = SAMPLE / "estimator_log.csv"
GRID = SAMPLE / "starloc_grid_uwb.csv"


def _png_size(data: bytes) -> tuple[int, int]:
    assert data[:8] == b"\x89PNG\r\n\x1a\n", "not a PNG"
    assert data[12:16] == b"IHDR"
    return struct.unpack(">II", data[16:24])


def _check_png(data: bytes) -> None:
    width, height = _png_size(data)
    assert 300 <= width <= 3000 and 200 <= height <= 3000
    assert 5_000 < len(data) < 2_000_000
    assert data.rstrip().endswith(b"IEND\xaeB`\x82")


def _run(capsys, *args):
    code = main([str(a) for a in args])
    out, err = capsys.readouterr()
    return code, out, err


@pytest.fixture(scope="module")
def sample_plots():
    log = load_log(LOG)
    segments = split(log)
    results = diagnose_log(log, segments, DiagnosisConfig(metrics="all"), seed=0)
    return log, segments, results, segment_figures(log, results, segments)


def test_segment_plots_are_pngs_of_the_computed_numbers(sample_plots):
    log, segments, results, figs = sample_plots
    assert len(figs) == 4 * len(segments)  # nees, whitened, time scales, scores
    for fig in figs:
        _check_png(fig.png)
    by_name = {f.name: f for f in figs}
    seg, res = segments[1], results[1]  # "turn"
    scales = by_name["turn_timescales"].data
    np.testing.assert_array_equal(scales["observed"], res.diagnosis.time_scales.observed)
    np.testing.assert_array_equal(scales["epochs"], res.diagnosis.time_scales.epochs)
    errors, cov = log.errors[seg.index], log.cov[seg.index]
    nees = by_name["turn_nees"].data
    np.testing.assert_array_equal(nees["nees"], metrics.nees(errors, cov))
    np.testing.assert_array_equal(nees["x"], log.time[seg.index])
    assert nees["lower"] == pytest.approx(stats.chi2.ppf(0.025, 2))
    assert nees["upper"] == pytest.approx(stats.chi2.ppf(0.975, 2))
    assert nees["anees"] == pytest.approx(res.diagnosis.anees)
    assert nees["mean_upper"] == pytest.approx(stats.chi2.ppf(0.975, 600) / 300)
    white = by_name["turn_whitened"].data
    np.testing.assert_allclose(white["s"], whiten(errors, cov))
    np.testing.assert_allclose(white["mirror"], -whiten(errors, cov))
    assert white["pvalue"] == res.diagnosis.elt_pvalue
    scores = by_name["turn_scores"].data
    probes, claimed = res.diagnosis.probes, res.diagnosis.scores
    i = {float(s): k for k, s in enumerate(scores["scales"])}
    assert scores["es_centred"][i[0.5]] - scores["es_centred"][i[1.0]] == pytest.approx(
        probes.delta_es_minus
    )
    assert scores["nll_centred"][i[2.0]] - scores["nll_centred"][i[1.0]] == pytest.approx(
        probes.delta_nll_plus
    )
    assert scores["es"][i[1.0]] == pytest.approx(claimed.es)
    assert scores["scales"].min() == 0.25 and scores["scales"].max() == 4.0


def test_whitened_plot_other_dimensions():
    gen = np.random.default_rng(0)
    one = plots.whitened_plot("d1", gen.normal(size=(50, 1)), 0.3, "d = 1")
    _check_png(one.png)
    five = plots.whitened_plot("d5", gen.normal(size=(50, 5)), 0.3, "d = 5")
    assert five.data["s"].shape == (50, 2)


def test_diagnose_plots_option_writes_files(tmp_path, capsys):
    code, _, err = _run(capsys, "diagnose", LOG, "--plots", tmp_path / "figs")
    assert code == 0 and "wrote 28 figure(s)" in err  # 4 per segment, 4 of the whole log
    files = sorted((tmp_path / "figs").glob("*.png"))
    assert len(files) == 28 and {f.name for f in files} >= {
        "cruise_nees.png",
        "urban_scores.png",
        "timeline.png",
        "errors.png",
        "nees_running.png",
        "whitened_errors.png",
    }
    for f in files:
        _check_png(f.read_bytes())


def test_simulate_plots(tmp_path, capsys):
    code, out, _ = _run(
        capsys,
        "simulate",
        "--trials",
        "8",
        "--plots",
        tmp_path,
        "-f",
        "json",
        "--curve-runs",
        "500",
    )
    assert code == 0
    assert sorted(p.name for p in tmp_path.iterdir()) == [
        "confusion_matrix.png",
        "fig1_energy_score.png",
    ]
    study = sim.run_study(sim.SimulationConfig(trials=8), sim.parse_scenarios("all"))
    fig = plots.confusion_plot(study)
    confusion = json.loads(out)["confusion"]
    np.testing.assert_array_equal(
        fig.data["counts"], [list(row.values()) for row in confusion.values()]
    )
    code, _, err = _run(
        capsys, "simulate", "--sweep", "n=20,60", "--trials", "4", "--plots", tmp_path
    )
    assert code == 0, err
    _check_png((tmp_path / "sweep_n.png").read_bytes())


def test_curves_plot_data():
    by_rho, by_gamma = sim.fig1_curves([0.5, 1.0, 2.0], [0.0, 1.0], runs=300)
    fig = plots.curves_plot(by_rho, by_gamma)
    _check_png(fig.png)
    np.testing.assert_array_equal(fig.data["expected_es_rho"], [p.expected_es for p in by_rho])


def test_uwb_plots_and_report(tmp_path, capsys):
    report = tmp_path / "uwb.html"
    code, out, _ = _run(
        capsys, "uwb", GRID, "--plots", tmp_path / "figs", "--report", report, "-f", "json"
    )
    assert code == 0
    names = {p.name for p in (tmp_path / "figs").iterdir()}
    assert {
        "uwb_positions_over_time.png",
        "uwb_trajectory.png",
        "uwb_range_errors.png",
        "uwb_reported_std.png",
        "P1_nees.png",
    } <= names
    ranges = json.loads(out)["ranges"]
    from credcli.studies import uwb

    run = uwb.run_pipeline(GRID)
    fig5 = next(p for p in plots.uwb_plots(run) if p.name == "uwb_reported_std")
    table = {(r["segment"], r["anchor"]): r["std_error"] for r in ranges}
    for period, values in fig5.data["std"].items():
        for anchor, empirical in zip(fig5.data["anchors"], values["empirical"]):
            assert empirical == pytest.approx(table[(period, anchor)])
    html = report.read_text()
    assert html.count('src="data:image/png;base64,') == len(names)


def test_report_is_self_contained(tmp_path, capsys):
    out = tmp_path / "report.html"
    code, _, err = _run(capsys, "report", LOG, "-o", out)
    assert code == 0 and "28 figures" in err
    html = out.read_text()
    assert html.startswith("<!DOCTYPE html>")
    assert not re.search(r'(src|href)="(https?:)?//', html)  # nothing fetched from a network
    assert "<script" not in html
    assert html.count('src="data:image/png;base64,') == 28
    assert "optimism+bias" in html and "&quot;n_flips&quot;: 1000" in html


def _find_browser():
    for name in ("chromium", "chromium-browser", "google-chrome"):
        path = shutil.which(name)
        if path:
            return path
    return None


@pytest.mark.skipif(
    _find_browser() is None,
    reason="no headless browser: install Debian's chromium to run the HTML render test",
)
def test_report_renders_in_a_headless_browser(tmp_path, capsys):
    out = tmp_path / "report.html"
    assert _run(capsys, "report", LOG, "-o", out)[0] == 0
    # a probe script (added to a copy only) records how many images decoded after load
    probe = (
        "<script>window.addEventListener('load',()=>{const i=[...document.images];"
        "document.body.setAttribute('data-images',i.filter(x=>x.complete&&x.naturalWidth>0)"
        ".length+'/'+i.length);});</script></body>"
    )
    page = tmp_path / "probe.html"
    page.write_text(out.read_text().replace("</body>", probe))
    proc = subprocess.run(
        [
            _find_browser(),
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--disable-quic",
            "--no-first-run",
            "--disable-background-networking",
            "--disable-component-update",
            "--disable-sync",
            f"--user-data-dir={tmp_path / 'profile'}",
            "--virtual-time-budget=10000",
            "--dump-dom",
            page.as_uri(),
        ],
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert 'data-images="28/28"' in proc.stdout
    assert "credcli report" in proc.stdout


def test_without_matplotlib_a_one_line_hint(tmp_path):
    code = (
        "import sys; sys.modules['matplotlib'] = None\n"
        "from credcli.cli import main\n"
        f"sys.exit(main(['diagnose', {str(LOG)!r}, '--plots', {str(tmp_path)!r}]))\n"
    )
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=False)
    assert proc.returncode == 2
    assert proc.stderr.count("\n") == 1
    assert "pip install 'credcli[plots]'" in proc.stderr
    assert list(tmp_path.iterdir()) == []
