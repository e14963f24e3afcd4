"""Pictures of the evidence (matplotlib, Agg backend; an optional extra).

Every function returns a Plot: the PNG bytes and the data that was drawn, so that tests
can check a figure against the numbers it claims to show.
"""

from __future__ import annotations

import io
import re
import zlib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from credcli.errors import CredcliError
from credcli.io.files import write_atomic
from credcli.report.formats import format_pvalue
from credcli.studies.simulate import CONFUSION_LABELS

INSTALL_HINT = "pip install 'credcli[plots]' (or pip install matplotlib)"


@dataclass(frozen=True)
class Plot:
    name: str  # file name without extension
    title: str
    png: bytes
    data: dict = field(repr=False)


def _pyplot():
    try:
        import matplotlib
    except ModuleNotFoundError as exc:
        raise CredcliError(
            f"figures need matplotlib, which is not installed: {INSTALL_HINT}"
        ) from exc
    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt

    return plt


def require_plotting() -> None:
    """Fail early, with the install hint, when matplotlib is missing."""
    _pyplot()


def _finish(fig, name: str, title: str, data: dict) -> Plot:
    plt = _pyplot()
    fig.suptitle(title)
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=100, metadata={"Software": None})
    plt.close(fig)
    return Plot(name, title, buf.getvalue(), data)


MAX_STEM = 80
"""Longest file-name stem taken from a segment name (file systems allow 255 bytes)."""


def safe_name(text: str) -> str:
    """A file-name stem for ``text``: itself when it is short and made of safe characters;
    otherwise the safe characters, cut to MAX_STEM, and a checksum of the whole name, so
    that names differing only in unsafe characters ('a b', 'a/b') stay apart."""
    text = str(text)
    stem = re.sub(r"[^A-Za-z0-9_.-]+", "_", text[: 4 * MAX_STEM]).strip("_.") or "segment"
    if stem == text and len(stem) <= MAX_STEM:
        return stem
    return f"{stem[:MAX_STEM]}-{zlib.crc32(text.encode()):08x}"


def short_title(text: str, limit: int = 80) -> str:
    text = str(text)
    return text if len(text) <= limit else text[: limit - 1] + "…"


def write_plots(plots: list[Plot], directory: Path) -> list[Path]:
    """Write each plot as DIR/<name>.png (atomically); create DIR if needed."""
    directory = Path(directory)
    if directory.exists() and not directory.is_dir():
        raise CredcliError(f"`plots` {directory}: exists and is not a directory", "plots")
    seen: set[str] = set()
    for plot in plots:  # before any is written: a collision never overwrites a figure
        if plot.name in seen:
            raise CredcliError(
                f"`plots`: two figures would both be {directory / plot.name}.png (two logs "
                "with one file stem, or segment names that map to one file name); give "
                "each log its own `plots` directory or rename the segments",
                "plots",
            )
        seen.add(plot.name)
    directory.mkdir(parents=True, exist_ok=True)
    paths = []
    for plot in plots:
        path = directory / f"{plot.name}.png"
        write_atomic(path, plot.png)
        paths.append(path)
    return paths


# --- diagnose: one segment -------------------------------------------------------------


def nees_plot(name: str, time, nees: np.ndarray, dim: int, title: str) -> Plot:
    """NEES per epoch with the two-sided 95% χ²_d bounds, and the ANEES (mean NEES / d)
    with the 95% bounds of the mean (χ²_{Nd} / N)."""
    from scipy import special

    plt = _pyplot()
    n = nees.size
    x = np.arange(n) if time is None else np.asarray(time)
    lower, upper = special.chdtri(dim, 0.975), special.chdtri(dim, 0.025)
    mean_lower = special.chdtri(n * dim, 0.975) / n
    mean_upper = special.chdtri(n * dim, 0.025) / n
    mean = float(nees.mean())
    fig, ax = plt.subplots(figsize=(8, 3.6))
    ax.plot(x, nees, ".", ms=3, color="tab:blue", label="NEES ε_k")
    ax.axhline(upper, color="tab:red", ls="--", lw=1, label=f"95% bounds of χ²_{dim}")
    ax.axhline(lower, color="tab:red", ls="--", lw=1)
    ax.axhline(
        mean, color="black", lw=1.5, label=f"mean NEES = {mean:.3g} (ANEES {mean / dim:.3g})"
    )
    ax.axhspan(mean_lower, mean_upper, color="tab:green", alpha=0.2, label="95% band of the mean")
    ax.set_yscale("log")
    ax.set_xlabel("time [s]" if time is not None else "epoch")
    ax.set_ylabel("NEES")
    ax.legend(loc="best", fontsize=8, framealpha=0.9)
    data = {
        "x": x,
        "nees": nees,
        "lower": lower,
        "upper": upper,
        "mean_nees": mean,
        "anees": mean / dim,
        "mean_lower": mean_lower,
        "mean_upper": mean_upper,
    }
    return _finish(fig, name, title, data)


def time_scales_plot(name: str, scales, rate_hz: float | None, title: str) -> Plot:
    """The variance of the whitened errors at every averaging time (m times the variance
    of m-epoch means, per direction in its own units) against the dependence model's
    prediction and its interval (:class:`credcli.engine.memory.TimeScales`): where the
    points leave the band, the errors vary more slowly than the model explains."""
    plt = _pyplot()
    m = np.asarray(scales.epochs, dtype=float)
    x = m / rate_hz if rate_hz else m
    fig, ax = plt.subplots(figsize=(6.5, 3.8))
    ax.fill_between(
        x, scales.low, scales.high, color="tab:green", alpha=0.2, label="model's interval"
    )
    ax.plot(x, scales.predicted, color="tab:green", lw=1.5, label="memory model v_m")
    ax.plot(x, scales.observed, "o-", color="tab:blue", ms=4, label="observed")
    ax.axhline(1.0, color="gray", lw=0.8, ls=":", label="independent errors")
    tested = np.asarray(scales.tested, dtype=bool)
    if tested.any():
        ax.axvline(x[tested][0], color="gray", lw=0.8, ls="--", label="checked from here")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("averaging time [s]" if rate_hz else "averaging time [epochs]")
    ax.set_ylabel("m · Var(mean of m epochs)")
    ax.legend(loc="best", fontsize=8, framealpha=0.9)
    data = {
        "epochs": m,
        "observed": np.asarray(scales.observed),
        "predicted": np.asarray(scales.predicted),
        "low": np.asarray(scales.low),
        "high": np.asarray(scales.high),
    }
    return _finish(fig, name, title, data)


def anees_plot(name: str, mc) -> Plot:
    """Per-epoch ANEES over Monte Carlo runs with its two-sided χ²_{Md}/M bounds."""
    plt = _pyplot()
    x = np.arange(mc.anees.size) if mc.time is None else np.asarray(mc.time)
    fig, ax = plt.subplots(figsize=(8, 3.6))
    ax.plot(x, mc.anees, ".", ms=3, color="tab:blue", label=f"average NEES over {mc.runs} runs")
    for bound in (mc.lower, mc.upper):
        ax.axhline(bound, color="tab:red", ls="--", lw=1)
    ax.plot([], [], color="tab:red", ls="--", lw=1, label=f"{100 * (1 - mc.level):g}% bounds")
    ax.set_yscale("log")
    ax.set_xlabel("time [s]" if mc.time is not None else "epoch")
    ax.set_ylabel("ANEES")
    ax.legend(loc="best", fontsize=8, framealpha=0.9)
    data = {"x": x, "anees": mc.anees, "lower": mc.lower, "upper": mc.upper}
    title = f"ANEES over {mc.runs} runs: {100 * float(mc.inside.mean()):.1f}% inside the bounds"
    return _finish(fig, name, title, data)


def whitened_plot(name: str, s: np.ndarray, pvalue: float | None, title: str) -> Plot:
    """The ELT's picture: whitened errors s_k and their mirror image −s_k (Eq. (12))."""
    plt = _pyplot()
    d = s.shape[1]
    fig, ax = plt.subplots(figsize=(5, 5))
    ptxt = format_pvalue(pvalue)
    if d == 1:
        bins = np.linspace(-max(np.abs(s).max(), 1e-9), max(np.abs(s).max(), 1e-9), 31)
        ax.hist(s[:, 0], bins=bins, alpha=0.6, label="s_k")
        ax.hist(-s[:, 0], bins=bins, alpha=0.6, label="−s_k")
        ax.set_xlabel("whitened error")
        ax.set_ylabel("epochs")
        shown = s[:, :1]
    else:
        shown = s[:, :2]
        ax.plot(
            -shown[:, 0],
            -shown[:, 1],
            "o",
            mfc="none",
            ms=4,
            color="tab:orange",
            label="−s_k (mirror)",
        )
        ax.plot(shown[:, 0], shown[:, 1], ".", ms=4, color="tab:blue", label="s_k")
        m = shown.mean(axis=0)
        ax.plot(*m, "k*", ms=14, label=f"mean ({m[0]:.2f}, {m[1]:.2f})")
        lim = float(np.abs(shown).max()) * 1.05 or 1.0
        ax.set_xlim(-lim, lim)
        ax.set_ylim(-lim, lim)
        ax.set_aspect("equal")
        ax.axhline(0, color="grey", lw=0.5)
        ax.axvline(0, color="grey", lw=0.5)
        ax.set_xlabel("s_k,1 (whitened, unitless)")
        ax.set_ylabel("s_k,2 (whitened, unitless)")
        if d > 2:
            ax.text(
                0.02, 0.02, f"first two of d = {d} components", transform=ax.transAxes, fontsize=8
            )
    ax.set_title(f"ELT p = {ptxt}", fontsize=10)
    ax.legend(loc="upper right", fontsize=8)
    return _finish(fig, name, title, {"s": shown, "mirror": -shown, "pvalue": pvalue})


def scale_plot(name: str, scales: np.ndarray, curves: dict, c: float, title: str) -> Plot:
    """Mean NLL and mean ES against the covariance scale, for the claimed predictive and
    the centred one F̃ (Section III-C), with the probes at 1/c, 1, c. ``curves`` maps
    "claimed" and "centred" to (mean NLL, mean ES) arrays over ``scales``."""
    plt = _pyplot()
    probe_idx = [int(np.argmin(np.abs(scales - p))) for p in (1.0 / c, 1.0, c)]
    fig, axes = plt.subplots(1, 2, figsize=(9, 3.6))
    for ax, k, label in ((axes[0], 0, "mean NLL"), (axes[1], 1, "mean ES")):
        ax.plot(scales, curves["claimed"][k], "-", color="tab:blue", label="claimed N(x̂, sΣ̂)")
        ax.plot(scales, curves["centred"][k], "--", color="tab:purple", label="centred F̃(s)")
        ax.plot(
            scales[probe_idx],
            curves["centred"][k][probe_idx],
            "o",
            color="tab:red",
            label=f"probes at 1/c, 1, c (c = {c:g})",
        )
        ax.set_xscale("log")
        ax.set_xticks([0.25, 0.5, 1, 2, 4], ["1/4", "1/2", "1", "2", "4"])
        ax.minorticks_off()
        ax.set_xlabel("covariance scale s")
        ax.set_ylabel(label)
        ax.legend(fontsize=8)
    data = {
        "scales": scales,
        "nll": curves["claimed"][0],
        "es": curves["claimed"][1],
        "nll_centred": curves["centred"][0],
        "es_centred": curves["centred"][1],
        "probe_scales": scales[probe_idx],
    }
    return _finish(fig, name, title, data)


def segment_plots(results, curves, times, dim: int, prefix: str = "") -> list[Plot]:
    """The pictures of every diagnosed segment (NEES, whitened errors, the variance at every
    averaging time where the memory model was read, the scores): ``curves`` (the engine's
    :class:`credcli.engine.curves.SegmentCurves`) and ``times`` (stamps or None) in the
    order of ``results``."""
    plots = []
    for res, numbers, time in zip(results, curves, times, strict=True):
        diag = res.diagnosis
        stem = safe_name(f"{prefix}{res.segment}")
        head = f"{short_title(res.segment)}: {diag.label.value} (N = {diag.n})"
        plots.append(nees_plot(f"{stem}_nees", time, numbers.nees, dim, head))
        plots.append(whitened_plot(f"{stem}_whitened", numbers.whitened, diag.elt_pvalue, head))
        if diag.time_scales is not None and diag.time_scales.epochs.size > 1:
            rate = None
            if time is not None and len(time) > 1 and np.ptp(time) > 0:
                rate = (len(time) - 1) / float(np.ptp(time))
            plots.append(time_scales_plot(f"{stem}_timescales", diag.time_scales, rate, head))
        if numbers.scores is not None:
            scores = numbers.scores
            curves_by_kind = {"claimed": scores.claimed, "centred": scores.centred}
            plots.append(
                scale_plot(f"{stem}_scores", scores.scales, curves_by_kind, diag.config.c, head)
            )
    return plots


# --- simulate ------------------------------------------------------------------------


def confusion_plot(study) -> Plot:

    plt = _pyplot()
    rows = study.scenarios
    counts = np.array([[study.confusion[t][lab] for lab in CONFUSION_LABELS] for t in rows])
    fig, ax = plt.subplots(figsize=(7, 0.6 * len(rows) + 2))
    im = ax.imshow(counts, cmap="Blues", vmin=0)
    short = ["Credible", "O", "P", "SMM", "O+SMM", "P+SMM", "insuff."]
    ax.set_xticks(range(len(CONFUSION_LABELS)), short)
    ax.set_yticks(range(len(rows)), [r.value for r in rows])
    ax.set_xlabel("diagnosed label")
    ax.set_ylabel("true scenario")
    for i in range(counts.shape[0]):
        for j in range(counts.shape[1]):
            ax.text(
                j,
                i,
                str(counts[i, j]),
                ha="center",
                va="center",
                color="white" if counts[i, j] > counts.max() / 2 else "black",
            )
    fig.colorbar(im, ax=ax, label="trials")
    return _finish(
        fig,
        "confusion_matrix",
        f"Table III: confusion matrix of the {study.variant.value} variant",
        {"counts": counts, "rows": [r.value for r in rows]},
    )


def curves_plot(by_rho, by_gamma) -> Plot:
    plt = _pyplot()
    rho = np.array([p.rho for p in by_rho])
    gamma = np.array([p.gamma for p in by_gamma])
    data = {
        "rho": rho,
        "es_rho": np.array([p.mean_es for p in by_rho]),
        "expected_es_rho": np.array([p.expected_es for p in by_rho]),
        "gamma": gamma,
        "es_gamma": np.array([p.mean_es for p in by_gamma]),
        "expected_es_gamma": np.array([p.expected_es for p in by_gamma]),
    }
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.8))
    axes[0].plot(rho, data["es_rho"], "o", ms=4, label="sample mean")
    axes[0].plot(rho, data["expected_es_rho"], "-", label="exact expectation")
    axes[0].set_xscale("log")
    axes[0].axvline(1.0, color="grey", lw=0.5)
    axes[0].set_xlabel("covariance scale ρ (< 1 optimism, > 1 pessimism)")
    axes[0].set_ylabel("mean ES")
    axes[0].set_title("(a) ES against ρ", fontsize=10)
    axes[1].plot(gamma, data["es_gamma"], "o", ms=4, label="sample mean")
    axes[1].plot(gamma, data["expected_es_gamma"], "-", label="exact expectation")
    axes[1].set_xlabel("bias γ (μ = γ·[1, 1])")
    axes[1].set_ylabel("mean ES")
    axes[1].set_title("(b) ES against γ", fontsize=10)
    for ax in axes:
        ax.legend(fontsize=8)
    return _finish(fig, "fig1_energy_score", "Fig. 1: energy score under scaling and bias", data)


def sweep_plot(sweep, points) -> Plot:
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(8, 4))
    data = {}
    for truth in dict.fromkeys(p.truth for p in points):
        mine = [p for p in points if p.truth is truth]
        x = np.array([p.value for p in mine])
        y = 100 * np.array([p.accuracy[next(iter(p.accuracy))] for p in mine])  # calibrated
        ax.plot(x, y, "o-", label=truth.value)
        data[truth.value] = (x, y)
    if sweep.parameter.value in ("rho", "B") and min(sweep.values) > 0:
        ax.set_xscale("log")
    ax.set_ylim(-5, 105)
    ax.set_xlabel(sweep.parameter.value)
    ax.set_ylabel(f"accuracy, {next(iter(points[0].accuracy)).value} variant [%]")
    ax.legend(fontsize=8, title="true label")
    return _finish(
        fig, f"sweep_{sweep.parameter.value}", f"Accuracy against {sweep.parameter.value}", data
    )


# --- uwb -----------------------------------------------------------------------------


def _period_colours(n: int):
    plt = _pyplot()
    cmap = plt.get_cmap("tab10")
    return [cmap(k % 10) for k in range(n)]


def uwb_plots(run) -> list[Plot]:
    """Figs. 3a, 3b, 4 and 5 of the paper for a UWB run."""
    plt = _pyplot()
    ranges, log = run.ranges, run.log
    spans = [(s.name, s.t_start, s.t_end) for s in run.segments]
    colours = _period_colours(len(spans))
    plots = []

    # Fig. 3a: rig position over time, periods shaded
    fig, ax = plt.subplots(figsize=(9, 3.6))
    for i, axis in enumerate("xyz"):
        ax.plot(ranges.time, ranges.rig_pos[:, i], lw=1, label=axis)
    for (name, t0, t1), col in zip(spans, colours):
        ax.axvspan(t0, t1, color=col, alpha=0.2)
        ax.text((t0 + t1) / 2, ax.get_ylim()[1], name, ha="center", va="top", fontsize=8)
    ax.set_xlabel("time [s]")
    ax.set_ylabel("rig position [m]")
    ax.legend(fontsize=8, loc="lower right")
    plots.append(
        _finish(
            fig,
            "uwb_positions_over_time",
            "Fig. 3a: rig position and the periods",
            {"time": ranges.time, "position": ranges.rig_pos, "spans": spans},
        )
    )

    # Fig. 3b: trajectory, fixes and truth per period
    fig, ax = plt.subplots(figsize=(6.5, 6))
    for k, tag in enumerate(np.unique(ranges.tag)):
        path = ranges.tag_pos[ranges.tag == tag]
        ax.plot(
            path[:, 0],
            path[:, 1],
            "-",
            color="lightgrey",
            lw=1,
            label="tag paths (truth)" if k == 0 else None,
        )
    per_period = {}
    for seg, col in zip(run.segments, colours):
        est, truth = log.estimate[seg.index], log.truth[seg.index]
        ax.plot(est[:, 0], est[:, 1], "o", ms=2, color=col, alpha=0.5)
        # one star per distinct truth position (each tag of a static rig), to 1 cm
        spots = np.unique(np.round(truth, 2), axis=0)
        if len(spots) > 8:  # a moving window: show its mean truth only
            spots = truth.mean(axis=0, keepdims=True)
        ax.plot(
            spots[:, 0],
            spots[:, 1],
            "*",
            ms=14,
            color=col,
            mec="black",
            ls="none",
            label=f"{seg.name} truth",
        )
        per_period[seg.name] = {"estimate": est, "truth": truth, "truth_marks": spots}
    anchors = np.array([a.position for a in run.anchors])
    ax.plot(anchors[:, 0], anchors[:, 1], "k^", ms=8, label="anchors")
    for a in run.anchors:
        ax.annotate(
            str(a.id), a.position[:2], textcoords="offset points", xytext=(4, 4), fontsize=8
        )
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.legend(fontsize=7, loc="best")
    plots.append(
        _finish(
            fig,
            "uwb_trajectory",
            "Fig. 3b: fixes (circles) and truth (stars) per period",
            {"periods": per_period, "anchors": anchors},
        )
    )

    # Figs. 4 and 5: per period and anchor
    anchor_ids = sorted({a.id for a in run.anchors})
    n = len(spans)
    cols = min(3, n) or 1
    rows = int(np.ceil(n / cols)) or 1
    err = ranges.range_error
    box_data, std_data = {}, {}
    fig4, axes4 = plt.subplots(rows, cols, figsize=(4 * cols, 3 * rows), squeeze=False)
    fig5, axes5 = plt.subplots(rows, cols, figsize=(4 * cols, 3 * rows), squeeze=False)
    for k, (name, t0, t1) in enumerate(spans):
        ax4, ax5 = axes4[k // cols][k % cols], axes5[k // cols][k % cols]
        in_span = (ranges.time >= t0) & (ranges.time <= t1)
        errs = [err[in_span & (ranges.anchor == a)] for a in anchor_ids]
        stds = [ranges.std[in_span & (ranges.anchor == a)] for a in anchor_ids]
        ax4.boxplot(errs, tick_labels=[str(a) for a in anchor_ids], showfliers=False)
        ax4.axhline(0, color="grey", lw=0.5)
        ax4.set_title(name, fontsize=9)
        ax4.set_xlabel("anchor")
        ax4.set_ylabel("range error [m]")
        empirical = np.array([e.std(ddof=1) if e.size > 1 else np.nan for e in errs])
        ax5.boxplot(stds, tick_labels=[str(a) for a in anchor_ids], showfliers=False)
        ax5.plot(np.arange(1, len(anchor_ids) + 1), empirical, "r*", ms=10, label="empirical std")
        ax5.set_title(name, fontsize=9)
        ax5.set_xlabel("anchor")
        ax5.set_ylabel("std [m]")
        box_data[name] = errs
        std_data[name] = {"reported": stds, "empirical": empirical}
        if k == 0:
            ax5.legend(fontsize=7)
    for k in range(n, rows * cols):
        axes4[k // cols][k % cols].axis("off")
        axes5[k // cols][k % cols].axis("off")
    plots.append(
        _finish(
            fig4,
            "uwb_range_errors",
            f"Fig. 4: range errors ({ranges.range_column} − gt_range)",
            {"anchors": anchor_ids, "errors": box_data},
        )
    )
    plots.append(
        _finish(
            fig5,
            "uwb_reported_std",
            "Fig. 5: reported std (boxes) and empirical std (stars)",
            {"anchors": anchor_ids, "std": std_data},
        )
    )
    return plots
