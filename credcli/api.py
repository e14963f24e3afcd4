"""The Python API: one obvious path from a file, a DataFrame or arrays to results.

Examples
--------
>>> import credcli
>>> log = credcli.read_log("sample_data/estimator_log.csv")
>>> results = credcli.diagnose_log(log)              # the log's segments, calibrated rule
>>> [r.diagnosis.label.value for r in results][:3]
['credible', 'optimism', 'pessimism']
>>> results.to_frame().loc[1, ["segment", "label"]].tolist()
['turn', 'optimism']
>>> round(results.to_dict()[1]["scale_factor"], 2)   # multiply the covariance by this
3.08
"""

from __future__ import annotations

import contextlib
import sys
from collections.abc import Iterable, Sequence
from pathlib import Path

import numpy as np

from credcli import segments as seg
from credcli.engine.diagnosis import (
    Diagnosis,
    DiagnosisConfig,
    Label,
    SegmentDiagnosis,
    diagnose_errors,
    diagnose_segments,
    given_config,
)
from credcli.engine.rng import RngLike, check_seed
from credcli.errors import CredcliError
from credcli.io import logs
from credcli.io.arrays import error_arrays, log_from_arrays, write_log
from credcli.io.ingest import open_log
from credcli.io.logs import EstimatorLog, LogSchema
from credcli.io.schema import ReadOptions
from credcli.logid import LogId
from credcli.report.html import results_table
from credcli.report.overview import DRAWN, PlotKind, Source, draw
from credcli.report.records import segment_record
from credcli.schedule.plans import diagnose_plans
from credcli.segments import monte_carlo_plan, split, split_runs, without_run

__all__ = [
    "MonteCarloResults",
    "Results",
    "diagnose",
    "diagnose_log",
    "diagnose_monte_carlo",
    "log_from_arrays",
    "log_from_frame",
    "read_log",
    "write_log",
]


class Results(Sequence):
    """The diagnoses of a log's segments, in order.

    A sequence of ``SegmentDiagnosis`` (``results[i].diagnosis`` is a
    [Diagnosis][credcli.engine.diagnosis.Diagnosis]); ``to_dict`` and ``to_frame`` give the
    same records as ``credcli diagnose --format json`` / ``csv``; ``plot`` draws them.

    Results made by [diagnose_log][credcli.api.diagnose_log] keep a reference to the log
    and its segments (no copy) for ``plot``.

    Parameters
    ----------
    items : list of SegmentDiagnosis
        The segments' diagnoses, in order.
    source : Source, optional
        The log, its segments and their diagnoses, for ``plot``; None for results made by
        hand (``plot`` then raises).

    Examples
    --------
    >>> results = diagnose_log(read_log("sample_data/estimator_log.csv"))
    >>> len(results), results[1].segment, str(results[1].diagnosis.label)
    (6, 'turn', 'optimism')
    """

    def __init__(self, items: list[SegmentDiagnosis], source: Source | None = None) -> None:
        self._items = list(items)
        self._source = source

    def __getitem__(self, index):
        return self._items[index]

    def __len__(self) -> int:
        return len(self._items)

    def __repr__(self) -> str:
        labels = ", ".join(f"{r.segment}: {r.diagnosis.label.value}" for r in self._items[:4])
        more = f", … ({len(self)} in all)" if len(self) > 4 else ""
        return f"Results([{labels}{more}])"

    @property
    def labels(self) -> list[Label]:
        """Each segment's label, in order.

        A [Label][credcli.engine.config.Label] equals its text:
        ``results.labels == ["credible", "optimism"]``.
        """
        return [r.diagnosis.label for r in self._items]

    def to_dict(self) -> list[dict]:
        """One JSON-safe record per segment.

        Returns
        -------
        list of dict
            The records of ``credcli diagnose --format json``, one per segment, in order.

        Examples
        --------
        >>> results = diagnose_log(read_log("sample_data/estimator_log.csv"))
        >>> record = results.to_dict()[1]
        >>> record["segment"], record["label"], round(record["scale_factor"], 2)
        ('turn', 'optimism', 3.08)
        """
        return [segment_record(r) for r in self._items]

    def to_frame(self):
        """The records as a pandas DataFrame.

        Returns
        -------
        pandas.DataFrame
            One row per segment and one column per record key (the records of
            [to_dict][credcli.api.Results.to_dict], as ``credcli diagnose --format csv``).

        Examples
        --------
        >>> frame = diagnose_log(read_log("sample_data/estimator_log.csv")).to_frame()
        >>> frame.loc[5, ["segment", "label"]].tolist()
        ['urban', 'optimism+bias']
        """
        import pandas as pd

        return pd.DataFrame(self.to_dict())

    def plot(self, kind: str = "errors", *, k: float = 3.0, window: int | None = None):
        """Figures of the whole log.

        Parameters
        ----------
        kind : "errors", "nees", "whitened", "timeline", "timescales" or "all"
            ``errors``: each component of e_k against time with the claimed ±kσ band
            (σ = √Σ_k,ii), one subplot per component, segments shaded in their label's
            colour. ``nees``: NEES per epoch (a 2-D histogram above 3,000 epochs), its
            running mean over ``window`` epochs with the 1 − α interval of that mean
            (χ²_{wd}/w, assuming independent epochs) and each segment's mean NEES
            (d · ANEES). ``whitened``: whitened errors Σ_k^{-1/2} e_k (first two
            components) with the unit circle and the 95 % and 99 % circles of χ²₂.
            ``timeline``: one bar per segment coloured by its label, with κ̂.
            ``timescales``: credibility at every time scale: m times the variance of
            m-epoch means of the whitened errors against the memory model's prediction
            and interval, for the longest segment with a fitted memory (where the points
            leave the band, the claim stops holding at that averaging time).
        k : float
            The band's width in standard deviations (``errors``).
        window : int, optional
            The running mean's length in epochs (``nees``); N/50, from 10 to 500, if None.

        Returns
        -------
        matplotlib.figure.Figure or dict of str to matplotlib.figure.Figure
            The figure of ``kind``; for ``kind="all"``, a dict of the figures by kind
            (``errors``, ``nees``, ``timeline`` and ``whitened``: ``timescales`` is drawn
            only when asked for).

        Raises
        ------
        CredcliError
            If ``kind`` is not one of the kinds above, ``k`` is not a positive number,
            ``window`` is not between 1 and N or is given to a kind without a running mean
            (not ``nees`` or ``all``), the results hold no log (made by hand, not
            by [diagnose_log][credcli.api.diagnose_log]), or, for ``timescales``, no
            segment has a fitted memory.

        Examples
        --------
        >>> results = diagnose_log(read_log("sample_data/estimator_log.csv"))
        >>> fig = results.plot("timeline")
        >>> type(fig).__name__
        'Figure'
        """
        kind = PlotKind.parse(kind)
        if self._source is None:
            raise CredcliError(
                "plot: these results hold no log (made by hand); use credcli.diagnose_log"
            )
        if not (isinstance(k, int | float) and np.isfinite(k) and k > 0):
            raise CredcliError(f"k must be a positive number; got {k!r}", "k")
        if window is not None and kind not in (PlotKind.NEES, PlotKind.ALL):
            raise CredcliError(
                f"window is the running mean's length of the 'nees' figure; '{kind}' has "
                "none: leave it out",
                "window",
            )
        if kind is PlotKind.ALL:
            return {str(one): draw(self._source, one, k, window)[0] for one in DRAWN}
        return draw(self._source, kind, k, window)[0]

    def _repr_html_(self) -> str:
        """The diagnosis table in a notebook: the columns ``credcli diagnose`` shows, the
        labels coloured, the advice lines below."""
        return results_table(list(self), self._notes())

    def _notes(self) -> tuple[str, ...]:
        return ()


class MonteCarloResults(Results):
    """The diagnoses of M pooled Monte Carlo runs, segment by segment.

    Each segment holds that segment of every run (``credcli diagnose --monte-carlo``);
    made by [diagnose_monte_carlo][credcli.api.diagnose_monte_carlo]. A
    [Results][credcli.api.Results] otherwise.

    Parameters
    ----------
    items : list of SegmentDiagnosis
        The pooled segments' diagnoses, in order.
    anees : MonteCarlo
        The per-epoch ANEES test over the runs.
    source : Source, optional
        The runs, their segments and the diagnoses, for ``plot``.

    Attributes
    ----------
    anees : MonteCarlo
        The per-epoch ANEES test over the runs (Bar-Shalom et al. 2001, Sec. 5.4.2,
        ``credcli.engine.montecarlo.anees_test``): ``runs`` (M), ``anees`` (the mean NEES
        of the M runs at each epoch), its two-sided χ² bounds ``lower`` and ``upper`` at
        ``level``, ``inside`` (each epoch's mean NEES within them) and ``segments`` (the
        fraction of each segment's epochs inside).

    References
    ----------
    Y. Bar-Shalom, X. R. Li and T. Kirubarajan, *Estimation with Applications to Tracking
    and Navigation*, Wiley, 2001, Sec. 5.4.2.
    """

    def __init__(self, items: list[SegmentDiagnosis], anees, source: Source | None = None) -> None:
        super().__init__(items, source)
        self.anees = anees

    def __repr__(self) -> str:
        return f"MonteCarloResults({self._notes()[0]}; {super().__repr__()})"

    def _notes(self) -> tuple[str, ...]:
        inside = float(self.anees.inside.mean())
        return (
            f"{self.anees.runs} runs; per-epoch ANEES inside its {1 - self.anees.level:.0%} "
            f"interval at {inside:.1%} of epochs",
        )


def _diagnosis_html(diagnosis: Diagnosis) -> str:
    return results_table([SegmentDiagnosis(LogId.of("<arrays>"), "all", None, None, diagnosis)])


def _register_notebook_views() -> None:
    """In IPython or Jupyter, a Diagnosis and a SegmentDiagnosis display as the table
    ``credcli diagnose`` prints (the engine's dataclasses know nothing of HTML: the view is
    registered here, with the notebook's own formatter)."""
    module = sys.modules.get("IPython")
    shell = module.get_ipython() if module is not None else None
    if shell is None:
        return
    formatter = shell.display_formatter.formatters["text/html"]
    formatter.for_type(Diagnosis, _diagnosis_html)
    formatter.for_type(SegmentDiagnosis, lambda r: results_table([r]))


_register_notebook_views()


def read_log(
    path: str | Path,
    columns: LogSchema | None = None,
    drop_invalid: bool = False,
    **reading,
) -> EstimatorLog:
    """Read and validate an estimator log; see [Logs and options](formats.md).

    The decisions taken while reading (unit, format, pairing, convention) are in the log's
    ``notes``.

    Parameters
    ----------
    path : str or pathlib.Path
        The log: CSV, whitespace-separated text, Parquet, a credcli ``.npz``, or the other
        formats of [Logs and options](formats.md); ``-`` for standard input.
    columns : LogSchema, optional
        The column layout, for logs that do not follow credcli's column names.
    drop_invalid : bool
        Drop the rows with NaN or Inf instead of refusing the log.
    **reading
        The fields of ``credcli.io.schema.ReadOptions`` (the command line's reading
        options): ``truth``, ``input_format``, ``truth_format``, ``topic``,
        ``truth_topic``, ``time_unit``, ``max_dt``, ``time_offset``, ``states``,
        ``perturbation``, ``align``, ``innovations``, ``errors_only``. ``align``
        (``"origin"``, ``"se3"``, ``"sim3"``) moves an estimate kept in its own world
        frame onto the truth's first, with its covariance.

    Returns
    -------
    EstimatorLog
        The validated log.

    Raises
    ------
    CredcliError
        For an unknown or invalid reading option, and for a problem with the file, named
        by file, row and column: a missing or empty file, missing columns, a non-numeric
        cell, NaN/Inf (unless ``drop_invalid``), an asymmetric or non-positive-definite
        covariance, mismatched dimensions.

    Examples
    --------
    >>> log = read_log("sample_data/formats/odom_ros.csv", perturbation="right",
    ...                truth="sample_data/formats/euroc_groundtruth.csv")
    >>> log.n, log.dim, log.unpaired
    (2380, 3, 0)
    """
    if reading.get("truth") is not None:
        reading["truth"] = str(reading["truth"])
    try:
        options = ReadOptions(**reading)
    except CredcliError:
        raise
    except (TypeError, ValueError) as exc:
        raise CredcliError(f"read_log: {exc}") from exc
    return seg.checked_log(open_log(path, columns, options, drop_invalid))


def diagnose_log(
    log: EstimatorLog,
    segments: str | Sequence[seg.Segment] | None = None,
    config: DiagnosisConfig | None = None,
    seed: int = 0,
) -> Results:
    """Diagnose every segment of ``log``.

    A log with Monte Carlo run ids is diagnosed as its runs pooled
    ([diagnose_monte_carlo][credcli.api.diagnose_monte_carlo]).

    Parameters
    ----------
    log : EstimatorLog
        From [read_log][credcli.api.read_log], [log_from_arrays][credcli.api.log_from_arrays]
        or [log_from_frame][credcli.api.log_from_frame].
    segments : None, "whole", a window such as "5s" or "200", or a list of Segment
        None: the log's segment column (the whole log when it has none). A log of Monte
        Carlo runs takes None, "whole" or a window.
    config : DiagnosisConfig, optional
        The calibrated rule with its defaults when not given.
    seed : int
        Each segment's sign flips come from (seed, segment name): the same as the CLI's.

    Returns
    -------
    Results
        One diagnosis per segment, in order ([MonteCarloResults][credcli.api.MonteCarloResults]
        for a log of Monte Carlo runs).

    Raises
    ------
    TypeError
        If ``log`` is not an EstimatorLog (arrays go to [diagnose][credcli.api.diagnose]),
        or ``config`` is neither a DiagnosisConfig nor None.
    CredcliError
        For a window that cannot be read, a list of segments given with a log of Monte
        Carlo runs, or a segment whose arrays are invalid (the error names the log and the
        segment).

    Examples
    --------
    >>> results = diagnose_log(read_log("sample_data/estimator_log.csv"))
    >>> results.labels[:3] == ["credible", "optimism", "pessimism"]
    True
    >>> len(diagnose_log(read_log("sample_data/estimator_log.csv"), segments="whole"))
    1
    """
    _check_log(log)
    seed = check_seed(seed)
    if log.run is not None:
        if not (segments is None or isinstance(segments, str)):
            raise CredcliError(
                "segments: a log of Monte Carlo runs takes None, 'whole' or a window"
            )
        return diagnose_monte_carlo(log, segments, config, seed)
    if segments is None or isinstance(segments, str):
        whole = segments == "whole"
        with _python_names():
            plan = split(log, None if segments is None or whole else segments, whole)
    else:
        plan = _given_segments(segments, log.n)
    items = diagnose_segments(log, plan, config, seed)
    alpha = given_config(config).nees_alpha
    return Results(items, Source.of([log], plan, items, alpha))


def _given_segments(segments, n: int) -> list[seg.Segment]:
    """A list of Segment checked against a log of ``n`` epochs: at least one, each a
    Segment whose epochs are in the log (a CredcliError naming ``segments`` otherwise)."""
    forms = "None, 'whole', a window such as '5s' or '200', or a list of Segment"
    if isinstance(segments, (bytes, dict, np.ndarray)) or not isinstance(segments, Iterable):
        raise CredcliError(f"segments: expected {forms}; got {type(segments).__name__}", "segments")
    plan = list(segments)
    if not plan:
        raise CredcliError(
            f"segments: an empty list, nothing to diagnose; give {forms}", "segments"
        )
    if isinstance(segments, seg.Segments):  # split's columns: every row checked at once
        rows = segments.rows
        if rows.size and (rows.min() < 0 or rows.max() >= n):
            raise CredcliError(
                f"segments: epochs beyond this log of {n} (segments of another log?)", "segments"
            )
        return plan
    for k, item in enumerate(plan):
        if not isinstance(item, seg.Segment):
            raise CredcliError(
                f"segments[{k}]: expected a Segment (credcli.segments.split makes them); got {type(item).__name__}",
                "segments",
            )
        index = np.asarray(item.index)
        if index.dtype.kind == "b" or index.size == 0:
            what = "a boolean mask; give epoch indices" if index.size else "no epochs"
            raise CredcliError(f"segments[{k}] ({item.name!r}): {what}", "segments")
        if index.dtype.kind not in "iu" or index.min() < 0 or index.max() >= n:
            raise CredcliError(
                f"segments[{k}] ({item.name!r}): its epochs are not in this log of {n} epochs "
                "(a segment of another log?)",
                "segments",
            )
    return plan


def _check_log(log) -> None:
    if not isinstance(log, EstimatorLog):
        hint = (
            "; for arrays use credcli.diagnose(errors, cov) or credcli.log_from_arrays"
            if isinstance(log, np.ndarray)
            else ""
        )
        raise TypeError(
            f"log: expected an EstimatorLog (read_log, log_from_arrays, log_from_frame); "
            f"got {type(log).__name__}{hint}"
        )


_PYTHON_NAMES = {"window": "segments", "whole": "segments"}
"""The settings of the segmenter as the Python API names them."""


@contextlib.contextmanager
def _python_names():
    """Errors of the segmenter name the Python argument (``segments``), not the setting the
    command line and config files call ``window``."""
    try:
        yield
    except CredcliError as exc:
        message = exc.message
        for setting, argument in _PYTHON_NAMES.items():
            message = message.replace(f"`{setting}`", f"`{argument}`")
        named = _PYTHON_NAMES.get(exc.parameter, exc.parameter)
        if named is None and message != exc.message:
            named = "segments"
        raise CredcliError(message, named) from exc


def log_from_frame(
    frame,
    *,
    truth: Sequence[str] | None = None,
    estimate: Sequence[str] | None = None,
    errors: Sequence[str] | None = None,
    cov: Sequence[str] | None = None,
    time: str | None = None,
    segment: str | None = None,
    run: str | None = None,
    source: str = "<frame>",
) -> EstimatorLog:
    """A log from a pandas DataFrame, validated as ``credcli diagnose`` validates a file.

    By default the columns are found by their names as in a credcli log (``truth_i``,
    ``est_i`` or ``err_i``; ``cov_i_j``, ``var_i`` or ``std_i``; ``time``; ``segment``).
    Name them instead with the keywords below.

    Parameters
    ----------
    frame : pandas.DataFrame
        The log, one row per epoch (not modified).
    truth, estimate : sequence of str, optional
        The columns of the true and estimated states, one per component.
    errors : sequence of str, optional
        The columns of the errors, instead of ``truth`` and ``estimate``.
    cov : sequence of str, optional
        The covariance columns: d² entries row-major, d(d+1)/2 the upper triangle, or d
        variances.
    time : str, optional
        The time column: seconds, datetime64 or ISO-8601 strings.
    segment : str, optional
        The segment column.
    run : str, optional
        The column of Monte Carlo run ids.
    source : str
        The log's name in messages and records.

    Returns
    -------
    EstimatorLog
        The validated log.

    Raises
    ------
    CredcliError
        If ``errors`` is given with ``truth`` or ``estimate``, a column named twice, and
        for a problem in the data, named by column and row.

    Examples
    --------
    >>> import numpy as np, pandas as pd
    >>> e = np.random.default_rng(0).standard_normal((200, 2))
    >>> df = pd.DataFrame({"ex": e[:, 0], "ey": e[:, 1], "vx": 1.0, "vy": 1.0})
    >>> log_from_frame(df, errors=["ex", "ey"], cov=["vx", "vy"]).dim
    2
    """
    changes = {"truth_columns": truth or errors, "estimate_columns": estimate, "cov_columns": cov}
    schema = LogSchema().updated(**changes, time=time, segment=segment, run=run)
    errors_only = True if errors is not None else None
    if errors is not None and (truth is not None or estimate is not None):
        raise CredcliError("give errors, or truth and estimate, not both")
    return logs.log_from_frame(frame.copy(deep=False), schema, source, errors_only=errors_only)


def diagnose_monte_carlo(
    runs: Sequence[EstimatorLog] | EstimatorLog,
    segments: str | None = None,
    config: DiagnosisConfig | None = None,
    seed: int = 0,
) -> MonteCarloResults:
    """Diagnose M Monte Carlo runs of one scenario together, as ``credcli diagnose
    --monte-carlo``.

    Segment k of the result pools segment k of every run (the ELT flips each run in its
    own blocks), and ``anees`` is the per-epoch ANEES test over the runs (Bar-Shalom et
    al. 2001, Sec. 5.4.2). The runs must share one time base.

    Parameters
    ----------
    runs : sequence of EstimatorLog, or EstimatorLog
        A list of logs, one per run, or one log with run ids (``run=`` of
        [log_from_arrays][credcli.api.log_from_arrays], a ``run`` column).
    segments : None, "whole" or a window such as "5s" or "200"
        As for [diagnose_log][credcli.api.diagnose_log], applied to the first run.
    config : DiagnosisConfig, optional
        The calibrated rule with its defaults when not given; its ``alpha`` is also the
        level of the ANEES test.
    seed : int
        As for [diagnose_log][credcli.api.diagnose_log].

    Returns
    -------
    MonteCarloResults
        The pooled segments' diagnoses and the ANEES test (``anees``).

    Raises
    ------
    TypeError
        If a run is not an EstimatorLog.
    CredcliError
        For fewer than two runs, runs of different lengths, dimensions or time stamps, or
        a window that cannot be read.

    References
    ----------
    Y. Bar-Shalom, X. R. Li and T. Kirubarajan, *Estimation with Applications to Tracking
    and Navigation*, Wiley, 2001, Sec. 5.4.2.

    Examples
    --------
    >>> import numpy as np
    >>> rng = np.random.default_rng(0)
    >>> runs = [log_from_arrays(np.eye(2), errors=rng.standard_normal((100, 2)))
    ...         for _ in range(10)]
    >>> mc = diagnose_monte_carlo(runs)
    >>> mc[0].diagnosis.n, mc.anees.runs
    (1000, 10)
    """
    config = given_config(config)
    seed = check_seed(seed)
    runs = split_runs(runs) if isinstance(runs, EstimatorLog) else list(runs)
    for log in runs:
        _check_log(log)
    whole = segments == "whole"
    with _python_names():
        plans = [
            (log, without_run(split(log, None if segments is None or whole else segments, whole)))
            for log in runs[:1]
        ]
    pooled, anees = monte_carlo_plan(runs, plans, config.alpha)
    results = diagnose_plans(pooled, config, seed, runs=len(runs))
    source = Source.of(runs, plans[0][1], results, config.nees_alpha)
    return MonteCarloResults(results, anees, source)


def diagnose(
    errors: np.ndarray,
    cov: np.ndarray,
    config: DiagnosisConfig | None = None,
    seed: RngLike = None,
    *,
    rng: RngLike = None,
) -> Diagnosis:
    """Diagnose one segment of errors with their claimed covariances.

    Parameters
    ----------
    errors : array_like, shape (N, d)
        The errors e_k = x_k − x̂_k.
    cov : array_like, shape (N, d, d), (d, d) or (N, d)
        The claimed covariances: one per epoch, one (d, d) for every epoch, or variances.
    config : DiagnosisConfig, optional
        The calibrated rule with its defaults when not given.
    seed : int, numpy.random.Generator or None
        Fixes the sign flips of the location test: the same seed, the same diagnosis.
    rng : int, numpy.random.Generator or None
        The older name of ``seed``.

    Returns
    -------
    Diagnosis
        The label and every number behind it.

    Raises
    ------
    TypeError
        If ``config`` is neither a DiagnosisConfig nor None.
    CredcliError
        If both ``seed`` and ``rng`` are given, or for invalid arrays (shapes, non-finite
        values, a covariance that is not symmetric positive definite), naming the argument
        and the epoch.

    Examples
    --------
    >>> import numpy as np, credcli
    >>> e = np.random.default_rng(0).standard_normal((400, 2)) * 2.0
    >>> d = credcli.diagnose(e, np.eye(2), seed=0)
    >>> str(d.label), round(d.scale.scale_factor, 1)
    ('optimism', 4.0)
    """
    if seed is not None and rng is not None:
        raise CredcliError("give seed or its older name rng, not both")
    errors, cov = error_arrays(errors, cov)
    return diagnose_errors(errors, cov, config, seed if seed is not None else rng)
