"""Pictures of the evidence (matplotlib, Agg backend; an optional extra).

Every function returns a Plot: the PNG bytes and the data that was drawn, so that tests
can check a figure against the numbers it claims to show.
"""

from __future__ import annotations

import dataclasses
import io
import math
import os
import re
import sys
import zlib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from credcli.errors import CredcliError
from credcli.io.files import check_directory_output, check_new_file, write_atomic
from credcli.report.formats import format_pvalue
from credcli.studies.simulate import CONFUSION_LABELS

INSTALL_HINT = "pip install 'credcli[plots]' (or pip install matplotlib)"


@dataclass(frozen=True)
class Plot:
    """A drawn figure: its PNG bytes and the numbers it shows.

    Attributes
    ----------
    name : str
        The file name without its extension (:func:`write_plots` adds ``.png``).
    title : str
        The figure's title.
    png : bytes
        The PNG image (100 dpi, without a ``Software`` entry).
    data : dict
        The numbers drawn, by name, so that a test can check the figure against them.
    group : str, default ""
        The section of a report it belongs to: a log's overview, a segment
        (:func:`segment_group`).
    """

    name: str  # file name without extension
    title: str
    png: bytes
    data: dict = field(repr=False)
    group: str = ""  # the section of a report it belongs to: a log's overview, a segment


def _pyplot():
    if "matplotlib" not in sys.modules:  # credcli draws with Agg whatever the user's backend;
        os.environ.pop("MPLBACKEND", None)  # a bad one would fail matplotlib's import
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


def _whitened_axes(ax, lim: float) -> None:
    """Square axes of ±``lim`` around 0 for whitened errors (unitless), with the axes drawn."""
    ax.set_xlim(-lim, lim)
    ax.set_ylim(-lim, lim)
    ax.set_aspect("equal")
    ax.axhline(0, color="grey", lw=0.5)
    ax.axvline(0, color="grey", lw=0.5)
    ax.set_xlabel("s_k,1 (whitened, unitless)")
    ax.set_ylabel("s_k,2 (whitened, unitless)")


def plain_text(fig):
    """Every title, label, legend and annotation of ``fig`` drawn as the text it is, never
    as mathtext: a segment or log name such as ``$\\frac{a$`` made matplotlib fail (exit 3).
    Dollar signs are escaped (``\\$``, drawn as ``$``); text without one, and the tick
    labels (a log axis's ``10^{1}`` is mathtext; names given as tick labels are escaped
    where they are given, :func:`draw_timeline`), are left as they are.

    Parameters
    ----------
    fig : matplotlib.figure.Figure
        The figure, before it is laid out or drawn.

    Returns
    -------
    matplotlib.figure.Figure
        ``fig``.
    """
    for text in _texts(fig):
        value = text.get_text()
        if _SURROGATE.search(value):  # a file name's undecodable bytes: no font draws them
            text.set_text(value := drawable(value))
        if "$" in value and not getattr(text, "_credcli_plain", False):
            text.set_text(value.replace("$", "\\$"))
            text._credcli_plain = True  # escaped once, however often the figure is finished
    return fig


def _texts(fig) -> list:
    """Every Text of ``fig`` but the axes' tick labels and offset texts, which each axis'
    formatter writes when the figure is drawn: of an axis, its label only. The ticks are
    left to the drawing, which makes them."""
    from matplotlib.axis import Axis
    from matplotlib.text import Text

    found, artists = [], [fig]
    while artists:
        artist = artists.pop()
        if isinstance(artist, Axis):
            found.append(artist.label)
            continue
        if isinstance(artist, Text):
            found.append(artist)
        artists.extend(artist.get_children())
    return found


_SURROGATE = re.compile("[\ud800-\udfff]")


def drawable(text: str) -> str:
    r"""``text`` with each lone surrogate (a file name's byte that is not UTF-8) as its
    backslash escape, which matplotlib can draw (it refuses the string otherwise).

    Parameters
    ----------
    text : str
        A name from the data or a file name.

    Returns
    -------
    str
        ``text``, its lone surrogates written ``\udcff``.

    Examples
    --------
    >>> drawable("log\udcff.csv")
    'log\\udcff.csv'
    """
    return _SURROGATE.sub(lambda m: f"\\u{ord(m.group()):04x}", text)


def _finish(fig, name: str, title: str, data: dict, group: str = "") -> Plot:
    plt = _pyplot()
    fig.suptitle(title)
    plain_text(fig)
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=100, metadata={"Software": None})
    plt.close(fig)
    return Plot(name, title, buf.getvalue(), data, group)


MAX_STEM = 80
"""Longest file-name stem taken from a segment name (file systems allow 255 bytes)."""


def safe_name(text: str) -> str:
    """A file-name stem for ``text``.

    ``text`` itself when it is short and made of safe characters (letters, digits,
    ``_.-``); otherwise the safe characters (each run of others as one ``_``), cut to
    :data:`MAX_STEM`, and a CRC-32 of the whole name, so that names differing only in
    unsafe characters ('a b', 'a/b') stay apart.

    Parameters
    ----------
    text : str
        A segment's or log's name (anything ``str`` accepts).

    Returns
    -------
    str
        The stem; ``"segment"`` (with the checksum) when no safe character is left.

    Examples
    --------
    >>> safe_name("cruise"), safe_name("a b"), safe_name("a/b")
    ('cruise', 'a_b-806c5cd3', 'a_b-07f4401c')
    """
    text = str(text)
    stem = re.sub(r"[^A-Za-z0-9_.-]+", "_", text[: 4 * MAX_STEM]).strip("_.") or "segment"
    if stem == text and len(stem) <= MAX_STEM:
        return stem
    return f"{stem[:MAX_STEM]}-{zlib.crc32(text.encode()):08x}"


def short_title(text: str, limit: int = 80) -> str:
    """``text`` cut to ``limit`` characters for a title or a legend, ending in "…" when cut.

    Parameters
    ----------
    text : str
        The text (anything ``str`` accepts).
    limit : int, default 80
        The most characters kept, the ellipsis included.

    Returns
    -------
    str
        ``text``, or its first ``limit - 1`` characters and "…".

    Examples
    --------
    >>> short_title("a long segment name", 10)
    'a long se…'
    """
    text = str(text)
    return text if len(text) <= limit else text[: limit - 1] + "…"


def check_plots(plots: list[Plot], directory: Path, keep=()) -> None:
    """Check, before any figure (or any other output) is written, that :func:`write_plots`
    can write every plot into ``directory``.

    Parameters
    ----------
    plots : list of Plot
        The figures.
    directory : Path
        The directory DIR (a str is accepted).
    keep : iterable of paths, optional
        Files no figure may overwrite: the command's inputs and other outputs (a config
        named ``timeline.png`` in DIR); None items are skipped.

    Raises
    ------
    CredcliError
        If ``directory`` is a symbolic link or exists and is not a directory, if two plots
        have the same name, or if a figure would replace a directory or one of ``keep``.
    """
    directory = Path(directory)
    keep = [k for k in keep if k is not None]
    check_directory_output("`plots`", directory, {})
    seen: set[str] = set()
    for plot in plots:
        if plot.name in seen:
            raise CredcliError(
                f"`plots`: two figures would both be {directory / plot.name}.png (segment "
                "names that map to one file name, or a log's stem and segment name that read "
                "as another log's: x + y_z, x_y + z); give each log its own `plots` "
                "directory or rename the segments",
                "plots",
            )
        seen.add(plot.name)
        check_new_file("`plots`", directory / f"{plot.name}.png", keep)


def write_plots(plots: list[Plot], directory: Path, keep=()) -> list[Path]:
    """Write each plot as DIR/<name>.png (atomically); create DIR if needed.

    Every name is checked before any file is written (:func:`check_plots`), so that a
    collision never overwrites a figure, and no figure overwrites one of ``keep``.

    Parameters
    ----------
    plots : list of Plot
        The figures.
    directory : Path
        The directory DIR (a str is accepted).
    keep : iterable of paths, optional
        Files no figure may overwrite (None items are skipped).

    Returns
    -------
    list of Path
        The files written, in the order of ``plots``.

    Raises
    ------
    CredcliError
        As :func:`check_plots`.
    """
    directory = Path(directory)
    check_plots(plots, directory, keep)
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
    with the 95% bounds of the mean (χ²_{Nd} / N).

    Parameters
    ----------
    name : str
        The file name without extension.
    time : array_like of shape (N,) or None
        The epochs' time stamps in seconds; None to number the epochs.
    nees : ndarray of shape (N,)
        The NEES ε_k of each epoch.
    dim : int
        The state's dimension d.
    title : str
        The figure's title.

    Returns
    -------
    Plot
        The figure; its data holds ``x``, ``nees``, the bounds ``lower`` and ``upper``,
        ``mean_nees``, ``anees`` and the mean's bounds ``mean_lower`` and ``mean_upper``.

    Notes
    -----
    ε_k = e_kᵀ Σ̂_k⁻¹ e_k (Eq. (1)) is χ²_d when e_k ~ N(0, Σ̂_k), and the sum of N
    independent ones χ²_{Nd}, so the mean NEES lies in the central 95 % of χ²_{Nd} / N.

    References
    ----------
    P. Yan, L.-T. Hsu and R. Sun, "Credible Uncertainty Quantification under Noise and
    System Model Mismatch", Eq. (1).
    """
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
    ax.axhline(upper, color="tab:red", ls="--", lw=1, label=f"95% bounds of χ²({dim})")
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
    """The variance of the whitened errors at every averaging time against the dependence
    model's prediction and its interval.

    The variance is m times the variance of m-epoch means, per direction in its own units
    (``credcli.engine.memory.TimeScales``): where the points leave the band, the errors
    vary more slowly than the model explains.

    Parameters
    ----------
    name : str
        The file name without extension.
    scales : TimeScales
        The observed and predicted variances at each averaging time.
    rate_hz : float or None
        The epochs per second, to show averaging times in seconds; None for epochs.
    title : str
        The figure's title.

    Returns
    -------
    Plot
        The figure; its data as :func:`draw_time_scales` gives it.
    """
    fig, data = draw_time_scales(scales, rate_hz)
    return _finish(fig, name, title, data)


def draw_time_scales(scales, rate_hz: float | None) -> tuple:
    """The figure of :func:`time_scales_plot` and its numbers, without a title.

    Parameters
    ----------
    scales : TimeScales
        The observed and predicted variances at each averaging time, the model's
        interval and the scales that are checked.
    rate_hz : float or None
        The epochs per second, to show averaging times in seconds; None (or 0) for
        epochs.

    Returns
    -------
    figure : matplotlib.figure.Figure
        The figure, still open.
    data : dict
        ``epochs``, ``observed``, ``predicted``, ``low`` and ``high``, as arrays.
    """
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
    from matplotlib.ticker import FormatStrFormatter, NullFormatter  # 0.6, not 6×10⁻¹

    ax.xaxis.set_major_formatter(FormatStrFormatter("%g"))
    ax.xaxis.set_minor_formatter(NullFormatter())  # labelled minors of a decade collide
    ax.yaxis.set_major_formatter(FormatStrFormatter("%g"))
    ax.yaxis.set_minor_formatter(FormatStrFormatter("%g"))
    ax.legend(loc="best", fontsize=8, framealpha=0.9)
    data = {
        "epochs": m,
        "observed": np.asarray(scales.observed),
        "predicted": np.asarray(scales.predicted),
        "low": np.asarray(scales.low),
        "high": np.asarray(scales.high),
    }
    return fig, data


def anees_plot(name: str, mc) -> Plot:
    """Per-epoch ANEES over Monte Carlo runs with its two-sided χ²_{Md}/M bounds.

    Parameters
    ----------
    name : str
        The file name without extension.
    mc : MonteCarlo
        The ANEES test of the runs (``credcli.engine.montecarlo.MonteCarlo``).

    Returns
    -------
    Plot
        The figure, titled with the share of epochs inside the bounds; its data holds
        ``x``, ``anees``, ``lower`` and ``upper``.
    """
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
    """The ELT's picture: whitened errors s_k and their mirror image −s_k (Eq. (12)).

    For d = 1, histograms of s_k and −s_k; otherwise the first two components of both
    as points, with their mean.

    Parameters
    ----------
    name : str
        The file name without extension.
    s : ndarray of shape (N, d)
        The whitened errors s_k.
    pvalue : float or None
        The ELT's p-value, shown above the axes; None when the test was not run.
    title : str
        The figure's title.

    Returns
    -------
    Plot
        The figure; its data holds ``s`` (the components shown), ``mirror`` and
        ``pvalue``.

    Notes
    -----
    The ELT tests H₀: the law of {s_k} equals the law of {−s_k} (Eq. (12)): errors free
    of a system-model bias are symmetric about zero, so the two clouds overlap.

    References
    ----------
    P. Yan, L.-T. Hsu and R. Sun, "Credible Uncertainty Quantification under Noise and
    System Model Mismatch", Eqs. (12)-(16).
    """
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
        _whitened_axes(ax, lim)
        if d > 2:
            ax.text(
                0.02, 0.02, f"first two of d = {d} components", transform=ax.transAxes, fontsize=8
            )
    ax.set_title(f"ELT p = {ptxt}", fontsize=10)
    ax.legend(loc="upper right", fontsize=8)
    return _finish(fig, name, title, {"s": shown, "mirror": -shown, "pvalue": pvalue})


def scale_plot(name: str, scales: np.ndarray, curves: dict, c: float, title: str) -> Plot:
    """Mean NLL and mean ES against the covariance scale, for the claimed predictive and
    the centred one F̃ (Section III-C), with the probes at 1/c, 1, c.

    Parameters
    ----------
    name : str
        The file name without extension.
    scales : ndarray
        The covariance scales s, increasing.
    curves : dict
        Maps ``"claimed"`` and ``"centred"`` to (mean NLL, mean ES) arrays over
        ``scales``.
    c : float
        The probe factor (the probes are the scales nearest 1/c, 1 and c).
    title : str
        The figure's title.

    Returns
    -------
    Plot
        The figure; its data holds ``scales``, ``nll``, ``es``, ``nll_centred``,
        ``es_centred`` and ``probe_scales``.

    Notes
    -----
    The probes are the differences Δ⁻ and Δ⁺ of the centred scores at 1/c and c from
    their value at 1 (Eq. (18)), whose asymmetry (Eq. (19)) tells optimism from SMM.

    References
    ----------
    P. Yan, L.-T. Hsu and R. Sun, "Credible Uncertainty Quantification under Noise and
    System Model Mismatch", Section III-C, Eqs. (18)-(19).
    """
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


def segment_group(segment: str, log_name: str = "") -> str:
    """The report section of a segment's figures: ``segment NAME``, after its log's label
    (``LogId.label``) when a report holds several logs.

    Parameters
    ----------
    segment : str
        The segment's name.
    log_name : str, default ""
        The log's label; empty for a report of one log.

    Returns
    -------
    str
        The section's name.

    Examples
    --------
    >>> segment_group("urban"), segment_group("urban", "run2")
    ('segment urban', 'run2: segment urban')
    """
    return f"{log_name}: segment {segment}" if log_name else f"segment {segment}"


def segment_plots(
    results, curves, times, dim: int, prefix: str = "", log_name: str = ""
) -> list[Plot]:
    """The pictures of every diagnosed segment.

    For each segment: NEES (:func:`nees_plot`), whitened errors (:func:`whitened_plot`),
    the variance at every averaging time where the memory model was read
    (:func:`time_scales_plot`) and the scores where it has a verdict (:func:`scale_plot`).
    Each plot's ``group`` names its segment (after ``log_name``).

    Parameters
    ----------
    results : sequence of SegmentDiagnosis
        The diagnosed segments.
    curves : sequence of SegmentCurves
        The engine's curves of each (``credcli.engine.curves.SegmentCurves``), in the
        order of ``results``.
    times : sequence of (ndarray or None)
        The time stamps of each segment's epochs (None for a log without time), in the
        order of ``results``.
    dim : int
        The state's dimension d.
    prefix : str, default ""
        The start of every file name (a log's stem when there are several).
    log_name : str, default ""
        The log's label, for the plots' ``group``; empty for one log.

    Returns
    -------
    list of Plot
        Two to four figures per segment, named ``<prefix><segment>_nees``, ``_whitened``,
        ``_timescales`` and ``_scores`` (made safe by :func:`safe_name`).
    """
    plots = []
    for res, numbers, time in zip(results, curves, times, strict=True):
        start = len(plots)
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
        group = segment_group(res.segment, log_name)
        plots[start:] = [dataclasses.replace(p, group=group) for p in plots[start:]]
    return plots


# --- simulate ------------------------------------------------------------------------


def confusion_plot(study) -> Plot:
    """Table III as a picture: the trials of each true scenario by the label diagnosed.

    Parameters
    ----------
    study : StudyResult
        The simulation study (``credcli.studies.simulate.StudyResult``); its confusion
        counts are those of ``study.variant``.

    Returns
    -------
    Plot
        ``confusion_matrix``; its data holds ``counts`` (scenarios × the labels of
        ``CONFUSION_LABELS``) and ``rows`` (the scenarios).

    References
    ----------
    P. Yan, L.-T. Hsu and R. Sun, "Credible Uncertainty Quantification under Noise and
    System Model Mismatch", Table III.
    """
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
    """Fig. 1 of the paper: the mean energy score against the covariance scale ρ and
    against the bias γ, the sample mean beside the exact expectation.

    Parameters
    ----------
    by_rho : sequence of CurvePoint
        The points of Fig. 1a (ES against ρ, γ = 0).
    by_gamma : sequence of CurvePoint
        The points of Fig. 1b (ES against γ, ρ = 1).

    Returns
    -------
    Plot
        ``fig1_energy_score``; its data holds ``rho``, ``es_rho``, ``expected_es_rho``,
        ``gamma``, ``es_gamma`` and ``expected_es_gamma``.

    References
    ----------
    P. Yan, L.-T. Hsu and R. Sun, "Credible Uncertainty Quantification under Noise and
    System Model Mismatch", Eq. (10) and Fig. 1.
    """
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
    """Diagnosis accuracy against a swept parameter, one line per true label.

    Parameters
    ----------
    sweep : Sweep
        The swept parameter and its values (a log axis for ``rho`` and ``B`` when every
        value is positive).
    points : sequence of SweepPoint
        The accuracy at each value and true label; the first method of each point's
        ``accuracy`` (the calibrated variant) is drawn.

    Returns
    -------
    Plot
        ``sweep_<parameter>``; its data maps each true label to its (values, accuracy
        in %) arrays.
    """
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
    """Figs. 3a, 3b, 4 and 5 of the paper for a UWB run.

    Parameters
    ----------
    run : UwbRun
        What the ``uwb`` command computed (``credcli.studies.uwb.UwbRun``).

    Returns
    -------
    list of Plot
        ``uwb_positions_over_time`` (Fig. 3a: the rig's position, periods shaded),
        ``uwb_trajectory`` (Fig. 3b: fixes and truth per period), ``uwb_range_errors``
        (Fig. 4: range errors per period and anchor) and ``uwb_reported_std`` (Fig. 5:
        reported against empirical standard deviations).

    References
    ----------
    P. Yan, L.-T. Hsu and R. Sun, "Credible Uncertainty Quantification under Noise and
    System Model Mismatch", Section V, Figs. 3-5.
    """
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


# --- the whole run: overview figures ---------------------------------------------------

PLOT_LABEL_COLOURS = {"credible": "#2ca02c", "insufficient-data": "#9e9e9e", "pessimism": "#ff7f0e"}
"""A label's colour in figures: credible green, insufficient grey, pessimism (a covariance
too large: safe but wasteful) orange, every other misfit red (:data:`PLOT_MISFIT_COLOUR`)."""
PLOT_MISFIT_COLOUR = "#d62728"
_COLOUR_ORDER = [
    *(PLOT_LABEL_COLOURS[k] for k in ("credible", "pessimism")),
    PLOT_MISFIT_COLOUR,
    PLOT_LABEL_COLOURS["insufficient-data"],
]
"""The order of the colours in a legend: the good news first."""

MAX_SCATTER = 3000
"""Above this many points a scatter saturates: the figures draw a 2-D histogram instead."""
MAX_SPAN_TEXT = 12
"""Segments named in a figure at most (more would overlap: the timeline names them)."""
MAX_SPAN_LINES = 40
"""Segments whose boundaries and mean NEES a figure marks at most (more are clutter)."""


def label_colour(label: str) -> str:
    """The figure colour of a label (its text, or a Label).

    Parameters
    ----------
    label : str or Label
        The label; a partial verdict (``"credible (scale untested)"``) takes the colour
        of its answered label.

    Returns
    -------
    str
        A colour of :data:`PLOT_LABEL_COLOURS`, or :data:`PLOT_MISFIT_COLOUR`.

    Examples
    --------
    >>> label_colour("credible"), label_colour("optimism+bias") == PLOT_MISFIT_COLOUR
    ('#2ca02c', True)
    """
    return PLOT_LABEL_COLOURS.get(str(label).split(" (")[0], PLOT_MISFIT_COLOUR)


@dataclass(frozen=True)
class Span:
    """A diagnosed segment on the time axis.

    Attributes
    ----------
    name : str
        The segment's name.
    start, end : float
        Where it starts and ends on the time axis (seconds, or epochs).
    label : str
        Its label as shown.
    kappa : float or None, default None
        Its covariance scale estimate κ̂; None when not estimated.
    anees : float or None, default None
        Its ANEES; None when not computed.
    """

    name: str
    start: float
    end: float
    label: str
    kappa: float | None = None
    anees: float | None = None


def _titled(fig, title: str):
    fig.suptitle(title)
    plain_text(fig)
    fig.tight_layout()
    return fig


def _figure(**kwargs):
    """A new figure and its axes, on the backend already chosen (a notebook's inline one
    for ``Results.plot``; Agg for the command line, which chose it first)."""
    try:
        import matplotlib.pyplot as plt
    except ModuleNotFoundError as exc:
        raise CredcliError(
            f"figures need matplotlib, which is not installed: {INSTALL_HINT}"
        ) from exc
    return plt.subplots(**kwargs)


def _shade_spans(ax, spans: list[Span], name_them: bool) -> None:
    """Each segment shaded faintly in its label's colour (neighbours of one colour as one
    stretch); boundaries marked and segments named on top when there are few."""
    stretch = None
    for span in [*spans, None]:
        colour = None if span is None else label_colour(span.label)
        if stretch and (span is None or colour != stretch[2] or span.start != stretch[1]):
            ax.axvspan(stretch[0], stretch[1], color=stretch[2], alpha=0.08, lw=0)
            stretch = None
        if span is not None:
            stretch = (stretch[0] if stretch else span.start, span.end, colour)
    if len(spans) <= MAX_SPAN_LINES:
        for span in spans:
            ax.axvline(span.start, color="grey", lw=0.4, alpha=0.6)
    if name_them and len(spans) <= MAX_SPAN_TEXT:
        for span in spans:
            ax.text(
                (span.start + span.end) / 2,
                1.0,
                short_title(span.name, 16),
                transform=ax.get_xaxis_transform(),
                ha="center",
                va="bottom",
                fontsize=7,
                color="#444",
                clip_on=False,
            )


def draw_errors(
    x: np.ndarray,
    errors: np.ndarray,
    band: np.ndarray,
    outside: np.ndarray,
    spans: list[Span],
    k: float = 3.0,
    xlabel: str = "time [s]",
    components: list[str] | None = None,
    title: str = "",
):
    """Each error component e_k,i against time with the claimed ±kσ band, one subplot per
    component, the segments shaded in their label's colour.

    Parameters
    ----------
    x : ndarray of shape (N,)
        The time axis (seconds, or epochs).
    errors : ndarray of shape (N, d) or (M, N, d)
        The errors; for M Monte Carlo runs, one thin line each.
    band : ndarray of shape (N, d)
        The band's half-width kσ_k,i with σ_k,i = √Σ_k,ii; for runs, the root mean square
        over them.
    outside : ndarray of shape (d,)
        The share of epochs outside their own band, per component (shown in the legend
        beside the share expected, P(|z| > k)).
    spans : list of Span
        The segments to shade.
    k : float, default 3.0
        The band's width in standard deviations.
    xlabel : str, default "time [s]"
        The x axis's label.
    components : list of str or None, default None
        The components' names; None for ``e_1``, ``e_2``, ….
    title : str, default ""
        The figure's title.

    Returns
    -------
    figure : matplotlib.figure.Figure
        The figure, still open.
    data : dict
        ``x``, ``errors``, ``band``, ``k`` and ``outside``.
    """
    runs = errors if errors.ndim == 3 else errors[None]
    m, n, d = runs.shape
    names = components or [f"e_{i + 1}" for i in range(d)]
    fig, axes = _figure(nrows=d, ncols=1, sharex=True, figsize=(10, 1.2 + 1.9 * d), squeeze=False)
    expected = math.erfc(k / math.sqrt(2.0))  # P(|z| > k), z ~ N(0, 1)
    dense = m * n > MAX_SCATTER  # a dense line is a blot: drawn light, under the band's edges
    sigma_text = "claimed" if m == 1 else f"claimed (RMS over {m} runs)"
    for i, ax in enumerate(axes[:, 0]):
        _shade_spans(ax, spans, name_them=i == 0)
        ax.fill_between(x, -band[:, i], band[:, i], color="tab:blue", alpha=0.15, lw=0)
        (upper,) = ax.plot(x, band[:, i], color="tab:blue", lw=1, gid=f"band_upper_{i}", zorder=4)
        ax.plot(x, -band[:, i], color="tab:blue", lw=1, gid=f"band_lower_{i}", zorder=4)
        upper.set_label(
            f"±{k:g}σ {sigma_text}: {100 * outside[i]:.2g} % outside, "
            f"{100 * expected:.2g} % expected"
        )
        for r in range(m):
            ax.plot(
                x,
                runs[r, :, i],
                color="#444" if dense else "black",
                lw=0.3 if dense else 0.8,
                alpha=0.6 if dense else 1.0,
                gid=f"error_{i}" if m == 1 else f"error_{i}_run_{r}",
                label=(names[i] if m == 1 else f"{names[i]}, {m} runs") if r == 0 else None,
                zorder=3,
            )
        ax.axhline(0, color="grey", lw=0.5)
        ax.set_ylabel(f"{names[i]} [state units]")
        ax.legend(loc="upper right", fontsize=7, framealpha=0.85)
    axes[-1, 0].set_xlabel(xlabel)
    data = {"x": x, "errors": errors, "band": band, "k": k, "outside": outside}
    return _titled(fig, title), data


def draw_nees(
    x: np.ndarray,
    nees: np.ndarray,
    dim: int,
    running: np.ndarray,
    window: int,
    bounds: tuple[float, float],
    alpha: float,
    spans: list[Span],
    runs: int = 1,
    xlabel: str = "time [s]",
    title: str = "",
):
    """NEES per epoch, its running mean with that mean's interval, the expected value d
    and each segment's mean NEES.

    The points become a 2-D histogram when there are more than :data:`MAX_SCATTER`.

    Parameters
    ----------
    x : ndarray of shape (N,)
        The time axis (seconds, or epochs).
    nees : ndarray of shape (N,)
        The NEES of each epoch; with ``runs`` > 1, averages over Monte Carlo runs
        (χ²_{Md}/M each).
    dim : int
        The state's dimension d, the NEES's expected value.
    running : ndarray of shape (N - window + 1,)
        The running mean over ``window`` epochs, drawn at each window's last epoch.
    window : int
        The running mean's window in epochs.
    bounds : tuple of float
        The 1 − α interval (low, high) of the running mean (χ²_{wd}/w under independent
        epochs).
    alpha : float
        The interval's level α, for its legend.
    spans : list of Span
        The segments to shade; each one's mean NEES d · ANEES is drawn (up to
        :data:`MAX_SPAN_LINES` segments).
    runs : int, default 1
        The number of Monte Carlo runs averaged.
    xlabel : str, default "time [s]"
        The x axis's label.
    title : str, default ""
        The figure's title.

    Returns
    -------
    figure : matplotlib.figure.Figure
        The figure, still open.
    data : dict
        ``x``, ``nees``, ``running``, ``running_x``, ``window``, ``bounds``,
        ``segment_mean`` (d · ANEES per span, or None) and ``running_inside`` (the share
        of the running mean inside ``bounds``).

    References
    ----------
    P. Yan, L.-T. Hsu and R. Sun, "Credible Uncertainty Quantification under Noise and
    System Model Mismatch", Eqs. (1)-(2).
    """
    n = nees.size
    fig, ax = _figure(figsize=(10, 4.2))
    _shade_spans(ax, spans, name_them=True)
    what = "NEES ε_k" if runs == 1 else f"NEES averaged over {runs} runs"
    positive = np.maximum(nees, 1e-12)  # a log axis: an exact zero is drawn at its floor
    if n > MAX_SCATTER:
        hb = ax.hexbin(
            x,
            positive,
            yscale="log",
            bins="log",
            gridsize=(90, 30),
            cmap="Blues",
            mincnt=1,
            linewidths=0,
        )
        fig.colorbar(hb, ax=ax, label=f"epochs per cell ({what})", pad=0.01)
    else:
        ax.plot(x, positive, ".", ms=2.5, color="tab:blue", alpha=0.45, label=what)
    ax.axhline(dim, color="grey", lw=0.8, ls=":", label=f"expected value d = {dim}")
    ax.axhspan(
        *bounds,
        gid="running_interval",
        color="tab:green",
        alpha=0.18,
        lw=0,
        label=f"{100 * (1 - alpha):g} % interval of the running mean "
        f"(χ²({window * runs * dim})/{window * runs}, independent epochs)",
    )
    xr = x[window - 1 :]
    ax.plot(
        xr,
        running,
        color="black",
        lw=1.2,
        gid="running_mean",
        zorder=4,
        label=f"running mean over {window} epochs",
    )
    named = len(spans) <= MAX_SPAN_TEXT
    for j, span in enumerate(spans):
        if span.anees is None or len(spans) > MAX_SPAN_LINES:  # many: the running mean tells
            continue
        ax.plot(
            [span.start, span.end],
            [dim * span.anees] * 2,
            color=label_colour(span.label),
            lw=1.8,
            ls="--",
            gid=f"segment_mean_{j}",
            zorder=3,
            label="segment mean NEES = d · ANEES" if j == 0 else None,
        )
        if named:
            ax.annotate(
                f"ANEES {span.anees:.3g}",
                ((span.start + span.end) / 2, dim * span.anees),
                textcoords="offset points",
                xytext=(0, 7),
                ha="center",
                fontsize=7,
                color=label_colour(span.label),
                bbox={"boxstyle": "round,pad=0.15", "fc": "white", "ec": "none", "alpha": 0.8},
                zorder=5,
            )
    low, high = np.quantile(positive, [0.01, 0.99])
    if high > 30 * low:  # NEES of single epochs spans decades; averages over runs do not
        ax.set_yscale("log")
    ax.set_xlabel(xlabel)
    ax.set_ylabel("NEES")
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.14), fontsize=7, frameon=False, ncol=3)
    running_inside = float(np.mean((running >= bounds[0]) & (running <= bounds[1])))
    data = {
        "x": x,
        "nees": nees,
        "running": running,
        "running_x": xr,
        "window": window,
        "bounds": bounds,
        "segment_mean": [None if s.anees is None else dim * s.anees for s in spans],
        "running_inside": running_inside,
    }
    return _titled(fig, title), data


WHITENED_CONTOURS = (0.3935, 0.95, 0.99)
"""The χ²₂ probabilities of the circles drawn on whitened errors (the first is the unit
circle)."""


def draw_whitened_errors(
    s: np.ndarray, colours: list[str] | None = None, title: str = "", labels: dict | None = None
):
    """Whitened errors s_k = Σ_k^{-1/2} e_k, first two components, with circles holding
    39 % (the unit circle), 95 % and 99 % of N(0, I₂) and the share observed inside each.

    For d = 1, a histogram against the N(0, 1) density. A 2-D histogram replaces the
    points above :data:`MAX_SCATTER`; points beyond the axes are counted.

    Parameters
    ----------
    s : ndarray of shape (N, d)
        The whitened errors.
    colours : list of str or None, default None
        A colour per point (its segment's label colour); None for one colour.
    title : str, default ""
        The figure's title.
    labels : dict or None, default None
        The legend of ``colours``: a text (the labels of a colour) to its colour.

    Returns
    -------
    figure : matplotlib.figure.Figure
        The figure, still open.
    data : dict
        ``s`` (the components drawn); for d > 1 also ``radii`` and ``inside`` (each
        circle's radius and observed share) and ``beyond`` (points outside the axes).

    Notes
    -----
    When e_k ~ N(0, Σ_k), s_k ~ N(0, I), so |s_k|² of two components is χ²₂ and a
    circle of radius r holds 1 − exp(−r²/2) of the points (:data:`WHITENED_CONTOURS`).
    """
    n, d = s.shape
    fig, ax = _figure(figsize=(7, 6.6) if d > 1 else (7, 4))
    data: dict = {"s": s[:, : min(d, 2)]}
    if d == 1:
        lim = max(4.0, float(np.quantile(np.abs(s[:, 0]), 0.995)) * 1.05)
        bins = np.linspace(-lim, lim, 61)
        ax.hist(
            np.clip(s[:, 0], -lim, lim),
            bins=bins,
            density=True,
            color="tab:blue",
            alpha=0.6,
            label="whitened error s_k",
        )
        grid = np.linspace(-lim, lim, 400)
        ax.plot(
            grid,
            np.exp(-(grid**2) / 2) / np.sqrt(2 * np.pi),
            color="black",
            lw=1.2,
            label="N(0, 1)",
        )
        ax.set_xlabel("s_k (whitened, unitless)")
        ax.set_ylabel("density")
        ax.legend(fontsize=8)
        return _titled(fig, title), data
    pair = s[:, :2]
    radius2 = np.einsum("ni,ni->n", pair, pair)
    lim = max(4.0, float(np.quantile(np.abs(pair), 0.995)) * 1.05)
    beyond = int(np.sum(np.any(np.abs(pair) > lim, axis=1)))
    if n > MAX_SCATTER:
        hb = ax.hexbin(
            pair[:, 0],
            pair[:, 1],
            bins="log",
            gridsize=60,
            cmap="Blues",
            mincnt=1,
            extent=(-lim, lim, -lim, lim),
            linewidths=0,
        )
        fig.colorbar(hb, ax=ax, label="epochs per cell", shrink=0.8)
    else:
        ax.scatter(pair[:, 0], pair[:, 1], s=5, c=colours or "tab:blue", alpha=0.45, lw=0)
        for label, colour in (labels or {}).items():  # the colours' meaning
            ax.scatter([], [], s=12, c=colour, label=f"epochs of {label} segments")
    theta = np.linspace(0, 2 * np.pi, 361)
    radii, shares = [], []
    for p, style in zip(WHITENED_CONTOURS, (":", "--", "-")):
        r = float(np.sqrt(-2 * np.log1p(-p)))  # the χ²₂ quantile: 1 − exp(−r²/2) = p
        inside = float(np.mean(radius2 <= r * r))
        ax.plot(
            r * np.cos(theta),
            r * np.sin(theta),
            color="black",
            ls=style,
            lw=1,
            gid=f"contour_{p:g}",
            label=f"{100 * p:.3g} % of χ²₂ (r = {r:.2f}): {100 * inside:.1f} % inside",
        )
        radii.append(r)
        shares.append(inside)
    _whitened_axes(ax, lim)
    notes = []
    if d > 2:
        notes.append(f"first two of d = {d} components")
    if beyond:
        notes.append(f"{beyond} of {n} epochs beyond the axes")
    if notes:
        ax.text(0.02, 0.02, "; ".join(notes), transform=ax.transAxes, fontsize=8)
    ax.legend(loc="upper right", fontsize=7, framealpha=0.85)
    data.update(radii=radii, inside=shares, beyond=beyond)
    return _titled(fig, title), data


def _lanes(spans: list[Span]) -> list[int]:
    """A row for each span: the first row where it overlaps no span already placed (the
    windows of a run share a row; the run itself gets its own)."""
    ends: list[float] = []
    lanes = []
    for span in spans:
        for row, end in enumerate(ends):
            if span.start >= end:
                ends[row] = span.end
                lanes.append(row)
                break
        else:
            ends.append(span.end)
            lanes.append(len(ends) - 1)
    return lanes


def draw_timeline(spans: list[Span], xlabel: str = "time [s]", title: str = ""):
    """One bar per segment over its time, coloured by its label, with κ̂ written in bars
    wide enough to hold it; overlapping segments (windows and their run) on separate rows.

    Parameters
    ----------
    spans : list of Span
        The segments.
    xlabel : str, default "time [s]"
        The x axis's label.
    title : str, default ""
        The figure's title.

    Returns
    -------
    figure : matplotlib.figure.Figure
        The figure, still open.
    data : dict
        Per span ``starts``, ``ends``, ``lanes`` (its row), ``colours``, ``labels`` and
        ``kappa``, and ``bars`` (the number of bars drawn).
    """
    from matplotlib.patches import Patch

    lanes = _lanes(spans)
    rows = max(lanes) + 1 if lanes else 1
    fig, ax = _figure(figsize=(11, 1.9 + 0.55 * max(rows, len(set(s.label for s in spans)) / 3)))
    total = (max(s.end for s in spans) - min(s.start for s in spans)) if spans else 1.0
    total = total or 1.0
    colours = [label_colour(s.label) for s in spans]
    widths = [max(s.end - s.start, total * 1e-3) for s in spans]
    bars = ax.barh(
        lanes,
        widths,
        left=[s.start for s in spans],
        height=0.7,
        color=colours,
        edgecolor="white",
        lw=0.8 if len(spans) <= MAX_SPAN_LINES else 0,  # many: edges would stripe the row
        gid="timeline",
    )
    for span, lane, width in zip(spans, lanes, widths):
        kappa = (
            "κ̂ –" if span.kappa is None or not np.isfinite(span.kappa) else (f"κ̂ {span.kappa:.2g}")
        )
        room = width / total
        if room > 0.09:  # the name, the label (the colour merges misfits) and κ̂
            text = f"{short_title(span.name, 18)}\n{short_title(span.label, 18)}\n{kappa}"
        elif room > 0.035:
            text = kappa.replace("κ̂ ", "")
        else:
            continue
        ax.text(
            span.start + width / 2,
            lane,
            text,
            ha="center",
            va="center",
            fontsize=7,
            color="white" if span.label != "insufficient-data" else "black",
        )
    counts: dict[str, dict[str, int]] = {}  # colour -> label -> segments: one entry a colour
    for span in sorted(spans, key=lambda s: _COLOUR_ORDER.index(label_colour(s.label))):
        mine = counts.setdefault(label_colour(span.label), {})
        mine[span.label] = mine.get(span.label, 0) + 1
    handles = [
        Patch(
            color=colour,
            label=", ".join(short_title(lab, 24) for lab in labels) + f" ({sum(labels.values())})",
        )
        for colour, labels in counts.items()
    ]
    ax.legend(
        handles=handles, loc="center left", bbox_to_anchor=(1.01, 0.5), fontsize=8, frameon=False
    )
    names = []
    for row in range(rows):
        mine = [s for s, lane in zip(spans, lanes) if lane == row]
        names.append(short_title(mine[0].name, 14) if len(mine) == 1 else f"{len(mine)} segments")
    names = [drawable(n).replace("$", "\\$") for n in names]  # no mathtext
    ax.set_yticks(range(rows), names, fontsize=8)
    ax.set_ylim(rows - 0.5, -0.5)
    ax.set_xlabel(xlabel)
    data = {
        "starts": [s.start for s in spans],
        "ends": [s.end for s in spans],
        "lanes": lanes,
        "colours": colours,
        "labels": [s.label for s in spans],
        "kappa": [s.kappa for s in spans],
        "bars": len(bars.patches),
    }
    return _titled(fig, title), data


def figure_plot(name: str, title: str, drawn, group: str = "") -> Plot:
    """A drawn figure as a Plot: its PNG bytes; the figure is closed.

    Parameters
    ----------
    name : str
        The file name without extension.
    title : str
        The figure's title (already drawn on it).
    drawn : tuple
        The figure and its numbers, as the ``draw_*`` functions return them.
    group : str, default ""
        The report section it belongs to.

    Returns
    -------
    Plot
        The PNG bytes (100 dpi) and the numbers.
    """
    fig, data = drawn
    plt = _pyplot()
    plain_text(fig)
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=100, metadata={"Software": None})
    plt.close(fig)
    return Plot(name, title, buf.getvalue(), data, group)
