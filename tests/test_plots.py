"""Figures and the HTML report: valid PNGs whose data are the computed numbers."""

from __future__ import annotations

import base64
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

from helpers import SAMPLE, error_line, run  # noqa: E402

from credcli import DiagnosisConfig  # noqa: E402
from credcli.cli import main  # noqa: E402
from credcli.engine import metrics  # noqa: E402
from credcli.engine.diagnosis import diagnose_segments  # noqa: E402
from credcli.engine.elt import whiten  # noqa: E402
from credcli.io.logs import load_log  # noqa: E402
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


def test_segment_plots_are_pngs_of_the_computed_numbers():
    """The figures of one segment ("turn") hold its computed numbers; every segment's
    figures are valid PNGs in test_diagnose_plots_option_writes_files."""
    log = load_log(LOG)
    segments = split(log)
    results = diagnose_segments(log, segments, DiagnosisConfig(metrics="all"), seed=0)
    seg, res = segments[1], results[1]
    assert seg.name == res.segment == "turn"
    figs = segment_figures(log, [res], segments)
    assert len(figs) == 4  # nees, whitened, time scales, scores
    for fig in figs:
        _check_png(fig.png)
    by_name = {f.name: f for f in figs}
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


def test_diagnose_plots_option_writes_files(sample_figures):
    """``diagnose --plots DIR --report FILE`` (the shared run): the files are the report's
    images."""
    code, err = sample_figures.code, sample_figures.err
    assert code == 0 and "wrote 28 figure(s)" in err  # 4 per segment, 4 of the whole log
    files = sorted(sample_figures.plots.glob("*.png"))
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
    html = sample_figures.report.read_text()
    inline = re.findall(r'src="data:image/png;base64,([^"]+)"', html)
    assert sorted(base64.b64decode(i) for i in inline) == sorted(f.read_bytes() for f in files)


def _keep_drawn(monkeypatch, name: str) -> list:
    """The return values of ``plots.<name>`` while the test runs (the command's figures)."""
    drawn, draw = [], getattr(plots, name)

    def keep(*args, **kwargs):
        drawn.append(draw(*args, **kwargs))
        return drawn[-1]

    monkeypatch.setattr(plots, name, keep)
    return drawn


def test_simulate_plots(tmp_path, capsys, monkeypatch):
    drawn = _keep_drawn(monkeypatch, "confusion_plot")
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
    (fig,) = drawn  # the figure the command wrote, of the study its JSON reports
    assert (tmp_path / "confusion_matrix.png").read_bytes() == fig.png
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


def test_uwb_plots_and_report(tmp_path, capsys, monkeypatch):
    drawn = _keep_drawn(monkeypatch, "uwb_plots")
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
        "timeline.png",  # the fixes' overview, as diagnose draws it
        "errors.png",
        "nees_running.png",
    } <= names
    ranges = json.loads(out)["ranges"]
    (figures,) = drawn  # the command's figures of its pipeline run
    fig5 = next(p for p in figures if p.name == "uwb_reported_std")
    assert (tmp_path / "figs" / "uwb_reported_std.png").read_bytes() == fig5.png
    table = {(r["segment"], r["anchor"]): r["std_error"] for r in ranges}
    for period, values in fig5.data["std"].items():
        for anchor, empirical in zip(fig5.data["anchors"], values["empirical"]):
            assert empirical == pytest.approx(table[(period, anchor)])
    html = report.read_text()
    assert html.count('src="data:image/png;base64,') == len(names)


def _assert_self_contained(html: str) -> None:
    assert html.startswith("<!DOCTYPE html>")
    assert not re.search(r'(src|href)="(https?:)?//', html)  # nothing fetched from a network
    assert "<script" not in html
    assert html.count("<img") == html.count('src="data:image/png;base64,')  # every image inline


def test_report_is_self_contained(sample_figures):
    """The sample log's report (the shared ``diagnose --report`` run; the `report` command
    writes the same page: test_report_overview_contents_and_capped_windows)."""
    code, err = sample_figures.code, sample_figures.err
    assert code == 0 and "28 figures" in err
    html = sample_figures.report.read_text()
    _assert_self_contained(html)
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
def test_report_renders_in_a_headless_browser(tmp_path, sample_figures):
    out = sample_figures.report
    assert sample_figures.code == 0, sample_figures.err
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
    assert "credcli diagnose" in proc.stdout


def test_without_matplotlib_a_one_line_hint(tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "matplotlib", None)  # `import matplotlib` fails
    line = error_line(*run("diagnose", LOG, "--plots", tmp_path)[::2])
    assert "pip install 'credcli[plots]'" in line
    assert list(tmp_path.iterdir()) == []


# --- Results.plot, the overview figures, the report's overview ------------------------


def _small_log(n=240, d=2, seed=3):
    """A log with time, varying claimed covariances and an optimistic stretch."""
    import credcli

    gen = np.random.default_rng(seed)
    scales = np.linspace(0.5, 2.0, n)
    cov = np.eye(d)[None] * scales[:, None, None]
    cov[:, 0, 1] = cov[:, 1, 0] = 0.2 * scales
    errors = np.einsum("nij,nj->ni", np.linalg.cholesky(cov), gen.normal(size=(n, d)))
    errors[n // 2 :] *= 2.0  # the covariance claims too little here
    return credcli.log_from_arrays(cov, errors=errors, time=0.1 * np.arange(n))


@pytest.fixture(scope="module")
def small():
    import credcli

    log = _small_log()
    return log, credcli.diagnose_log(log, "60")  # four windows and the run


def _by_gid(fig, gid):
    found = [a for ax in fig.axes for a in [*ax.lines, *ax.patches] if a.get_gid() == gid]
    assert found, gid
    return found


def _close(*figures):
    import matplotlib.pyplot as plt

    for fig in figures:
        plt.close(fig)


def test_plot_errors_band_is_k_root_diagonal(small):
    log, results = small
    fig = results.plot("errors", k=2.5)
    assert len(fig.axes) == log.dim  # one subplot per component
    for i in range(log.dim):
        (upper,) = _by_gid(fig, f"band_upper_{i}")
        (lower,) = _by_gid(fig, f"band_lower_{i}")
        (error,) = _by_gid(fig, f"error_{i}")
        np.testing.assert_allclose(upper.get_ydata(), 2.5 * np.sqrt(log.cov[:, i, i]))
        np.testing.assert_allclose(lower.get_ydata(), -2.5 * np.sqrt(log.cov[:, i, i]))
        np.testing.assert_array_equal(error.get_ydata(), log.errors[:, i])
        np.testing.assert_array_equal(error.get_xdata(), log.time)
    _close(fig)


@pytest.mark.parametrize("kind", ["errors", "whitened", "timeline"])
def test_a_plot_window_is_refused_by_a_kind_without_a_running_mean(small, kind):
    """Only the NEES figure has a running mean: a window given to another kind was
    dropped without a word; now it is an error naming the argument."""
    from credcli.errors import CredcliError

    _, results = small
    with pytest.raises(CredcliError, match="window is the running mean's length"):
        results.plot(kind, window=7)
    _close(*results.plot("all", window=7).values())


def test_plot_nees_running_mean_and_its_chi2_interval(small):
    import pandas as pd

    log, results = small
    fig = results.plot("nees", window=7)
    (line,) = _by_gid(fig, "running_mean")
    expected = pd.Series(metrics.nees(log.errors, log.cov)).rolling(7).mean().dropna()
    np.testing.assert_allclose(line.get_ydata(), expected.to_numpy())
    np.testing.assert_array_equal(line.get_xdata(), log.time[6:])  # at each window's end
    (band,) = _by_gid(fig, "running_interval")  # χ²_{wd}/w at α = nees_alpha = 0.05
    assert band.get_y() == pytest.approx(stats.chi2.ppf(0.025, 14) / 7)
    assert band.get_y() + band.get_height() == pytest.approx(stats.chi2.ppf(0.975, 14) / 7)
    windows = [r for r in results if r.segment != "run"]  # the run is not drawn over them
    for j, r in enumerate(windows):
        (mean,) = _by_gid(fig, f"segment_mean_{j}")
        np.testing.assert_allclose(mean.get_ydata(), log.dim * r.diagnosis.anees)
    _close(fig)


def test_plot_timeline_one_bar_per_segment_in_its_label_colour(small):
    from matplotlib.colors import to_rgba

    log, results = small
    fig = results.plot("timeline")
    bars = _by_gid(fig, "timeline")
    assert len(bars) == len(results)
    for bar, r in zip(bars, results):
        assert bar.get_facecolor() == to_rgba(plots.label_colour(r.diagnosis.label))
    assert plots.label_colour("credible") == "#2ca02c"
    assert plots.label_colour("insufficient-data") == "#9e9e9e"
    assert plots.label_colour("optimism+bias") == plots.PLOT_MISFIT_COLOUR
    run, first = bars[-1], bars[0]
    assert run.get_y() != first.get_y()  # the run overlaps its windows: a row of its own
    assert run.get_x() == 0.0 and run.get_width() == pytest.approx(0.1 * log.n)
    _close(fig)


def test_plot_whitened_errors_and_chi2_circles(small):
    log, results = small
    fig = results.plot("whitened")
    points = fig.axes[0].collections[0].get_offsets()
    np.testing.assert_allclose(points, whiten(log.errors, log.cov))
    for p in plots.WHITENED_CONTOURS:
        (circle,) = _by_gid(fig, f"contour_{p:g}")
        radius = np.hypot(circle.get_xdata(), circle.get_ydata())
        np.testing.assert_allclose(radius, np.sqrt(stats.chi2.ppf(p, 2)), rtol=1e-3)
    _close(fig)


def test_plot_kinds_all_and_bad(small):
    from matplotlib.figure import Figure

    _, results = small
    every = results.plot("all")
    assert list(every) == ["timeline", "errors", "nees", "whitened"]
    assert all(isinstance(f, Figure) for f in every.values())
    _close(*every.values())
    from credcli.errors import CredcliError

    for kwargs, name in (({"kind": "bad"}, "kind"), ({"kind": "nees", "window": 0}, "window")):
        with pytest.raises(CredcliError, match=f"^{name} must be") as info:
            results.plot(**kwargs)
        assert info.value.parameter == name  # Python-only names: no backticks (no flag)
    assert "'timeline'" in str(pytest.raises(CredcliError, results.plot, "bad").value)


def test_plot_monte_carlo_runs_average_nees():
    import pandas as pd

    import credcli

    runs = [_small_log(n=60, seed=s) for s in range(4)]
    mc = credcli.diagnose_monte_carlo(runs)
    fig = mc.plot("nees", window=5)
    (line,) = _by_gid(fig, "running_mean")
    expected = pd.Series(mc.anees.anees).rolling(5).mean().dropna()
    np.testing.assert_allclose(line.get_ydata(), expected.to_numpy())
    (band,) = _by_gid(fig, "running_interval")  # χ²_{wMd}/(wM)
    assert band.get_y() == pytest.approx(stats.chi2.ppf(0.025, 5 * 4 * 2) / 20)
    errors = mc.plot("errors")
    (upper,) = _by_gid(errors, "band_upper_0")  # 3 × the RMS of the runs' σ
    rms = np.sqrt(np.mean([r.cov[:, 0, 0] for r in runs], axis=0))
    np.testing.assert_allclose(upper.get_ydata(), 3 * rms)
    assert len([ln for ln in errors.axes[0].lines if "_run_" in str(ln.get_gid())]) == 4
    _close(fig, errors)


def test_overview_file_names_never_meet_segment_figure_names():
    from credcli.report.overview import FILE_STEMS

    for stem in FILE_STEMS.values():
        assert not stem.endswith(("_nees", "_whitened", "_timescales", "_scores"))


def test_window_figures_capped_with_a_note():
    from credcli.engine.config import Label
    from credcli.engine.diagnosis import SegmentDiagnosis
    from credcli.report.overview import segments_to_draw
    from credcli.segments import Segment

    def result(name, label):
        diag = type("D", (), {"label": Label(label)})()
        return SegmentDiagnosis("log", name, None, None, diag)

    labels = ["credible", "insufficient-data", "optimism", "credible", "bias", "pessimism"]
    segments = [Segment(f"w{i}", np.arange(i, i + 1), window=True) for i in range(6)]
    segments.append(Segment("run", np.arange(6)))
    results = [result(s.name, lab) for s, lab in zip(segments, [*labels, "optimism"])]
    kept, note = segments_to_draw(segments, results, limit=3)
    assert [s.name for s, _ in kept] == ["w2", "w4", "w5", "run"]  # misfits first, in order
    assert note.startswith("figures of 3 of 6 windows") and "3 skipped" in note
    kept, note = segments_to_draw(segments[-1:], results[-1:])
    assert note is None and len(kept) == 1
    # a segment column: every segment up to MAX_SEGMENT_FIGURES, then the misfits only
    from credcli.report.overview import MAX_SEGMENT_FIGURES

    many = [Segment(f"s{i}", np.arange(i, i + 1)) for i in range(MAX_SEGMENT_FIGURES + 6)]
    labels = ["optimism" if i % 10 == 3 else "credible" for i in range(len(many))]
    kept, note = segments_to_draw(many, [result(s.name, lab) for s, lab in zip(many, labels)])
    assert [s.name for s, _ in kept] == ["s3", "s13", "s23"]
    assert note.startswith(f"figures of 3 of {len(many)} segments") and "whole log" in note
    kept, note = segments_to_draw(many[:MAX_SEGMENT_FIGURES], [result("x", "credible")] * 24)
    assert note is None and len(kept) == MAX_SEGMENT_FIGURES


def test_report_overview_contents_and_capped_windows(tmp_path, capsys):
    import credcli

    log = _small_log(n=300)
    csv = tmp_path / "windows.csv"
    credcli.write_log(log, csv)
    out = tmp_path / "report.html"
    code, _, err = _run(capsys, "report", csv, "--window", "30", "-o", out)
    assert code == 0, err
    html = out.read_text()
    _assert_self_contained(html)
    assert '<section id="overview"><h2>Overview</h2>' in html
    assert html.index('id="overview"') < html.index('id="table-')  # the overview comes first
    overview = html[html.index('id="overview"') : html.index("</section>")]
    assert "timeline.png" in overview and "11 segments" in overview
    anchors = re.findall(r'href="#([^"]+)"', html)
    ids = set(re.findall(r'id="([^"]+)"', html))
    assert len(anchors) > 4 and set(anchors) <= ids  # every link of the contents lands
    results = credcli.diagnose_log(credcli.read_log(csv), "30")  # as the command, seed 0
    windows = [r for r in results if r.segment != "run"]
    drawn = [r for r in windows if r.diagnosis.label != "credible"][:6]
    assert f"figures of {len(drawn)} of {len(windows)} windows" in html
    assert html.count("<h3 id=") == 1 + len(drawn) + 1  # overview, drawn windows, the run


def test_results_plot_credibility_at_every_time_scale():
    """Issue 33 item 3: κ̂ against averaging time from Python: the observed and predicted
    curves are the longest fitted segment's TimeScales; without a fitted memory, a
    ValueError naming the kind."""
    import credcli
    from credcli.engine.diagnosis import Variant

    log = credcli.read_log(LOG)
    results = credcli.diagnose_log(log, segments="whole")
    scales = results[0].diagnosis.time_scales
    fig = results.plot("timescales")
    lines = {line.get_label(): line for line in fig.axes[0].get_lines()}
    np.testing.assert_array_equal(lines["observed"].get_ydata(), scales.observed)
    np.testing.assert_array_equal(lines["memory model v_m"].get_ydata(), scales.predicted)
    paper = credcli.diagnose_log(log, config=DiagnosisConfig(variant=Variant.PAPER))
    with pytest.raises(ValueError, match="kind 'timescales': no segment has a fitted memory"):
        paper.plot("timescales")
