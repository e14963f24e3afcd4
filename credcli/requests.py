"""What a command asks for, typed: every setting resolved (command line > config file >
defaults, ``credcli.cli.settings``) before any work starts. The workflows take these;
the Python API may build them directly."""

from __future__ import annotations

import enum
from dataclasses import dataclass
from pathlib import Path

from credcli.ci.thresholds import Thresholds
from credcli.engine.config import DiagnosisConfig
from credcli.io.schema import LogReading
from credcli.report.records import Baseline
from credcli.studies.settings import CURVE_RUNS, SimulationConfig, UwbSettings


class Kept(str, enum.Enum):
    """What a `diagnose` run keeps of each segment's result once the report has read it."""

    RESULTS = "results"  # every result: the figures and the Python API read them
    VERDICTS = "verdicts"  # each segment's verdict (SegmentVerdict): --fail-on reads them
    NOTHING = "nothing"  # the report alone: memory holds a record a segment


@dataclass(frozen=True)
class DiagnoseRequest:
    """Diagnose ``logs`` (``diagnose``, ``baseline``, ``report``).

    Attributes
    ----------
    logs : tuple of Path
        The estimator logs.
    reading : LogReading
        How the logs are read and cut into segments.
    config : DiagnosisConfig
        How a segment is judged.
    seed : int, default 0
        The seed of the sign flips (each segment's come from the seed and its name).
    jobs : int, default 1
        Local worker processes that share the segments (same output for any value).
    monte_carlo : bool, default False
        The logs are runs of one scenario, pooled segment by segment.
    figures : bool, default False
        Draw the plots too.
    keep : Kept, default Kept.RESULTS
        What the Run keeps of each segment's result ([Kept][credcli.requests.Kept];
        every result when ``figures``). Short of RESULTS, each result is read into the
        report as it is diagnosed and dropped, so that memory holds a record a segment,
        not a result.
    """

    logs: tuple[Path, ...]
    reading: LogReading = LogReading()
    config: DiagnosisConfig = DiagnosisConfig()
    seed: int = 0
    jobs: int = 1
    monte_carlo: bool = False
    figures: bool = False
    keep: Kept = Kept.RESULTS


@dataclass(frozen=True)
class SimulateRequest:
    """The Monte Carlo study of ``config`` on ``scenario`` (a comma-separated list), or a
    ``sweep`` of one parameter, or the Fig. 1 ``curves`` (``curve_runs`` runs a point).

    Attributes
    ----------
    config : SimulationConfig
        The study's design, its seed and its rule.
    scenario : str, default "all"
        ``all``, labels or aliases, comma-separated.
    sweep : str or None
        One parameter swept, e.g. ``rho=0.1:10:20``; None for the study itself.
    curves : bool, default False
        The Fig. 1 curves instead.
    curve_runs : int
        Monte Carlo runs per curve point.
    jobs : int, default 1
        Local worker processes that share the trials (same output for any value).
    figures : bool, default False
        Draw the plots too.
    """

    config: SimulationConfig = SimulationConfig()
    scenario: str = "all"
    sweep: str | None = None
    curves: bool = False
    curve_runs: int = CURVE_RUNS
    jobs: int = 1
    figures: bool = False


@dataclass(frozen=True)
class UwbRequest:
    """The UWB pipeline on a STAR-loc ``file``: fixes with ``settings``, segments (static
    periods, or ``window`` / ``whole``), diagnosed with ``config``.

    Attributes
    ----------
    file : Path
        The STAR-loc ``uwb.csv``.
    settings : UwbSettings
        How ranges become fixes.
    config : DiagnosisConfig
        How a period is judged.
    anchors : Path or None
        The anchors' positions (a markers CSV); None: self-calibrated from the file.
    window : str or None
        Fixed windows (a duration) instead of static periods.
    whole : bool, default False
        The whole run as one period.
    seed : int, default 0
        The seed of the sign flips.
    figures : bool, default False
        Draw the plots too.
    """

    file: Path
    settings: UwbSettings = UwbSettings()
    config: DiagnosisConfig = DiagnosisConfig()
    anchors: Path | None = None
    window: str | None = None
    whole: bool = False
    seed: int = 0
    figures: bool = False


@dataclass(frozen=True)
class GateRequest:
    """``diagnose`` (the baseline's settings on the new log) compared with ``baseline``
    segment by segment under ``thresholds``.

    Attributes
    ----------
    diagnose : DiagnoseRequest
        The new log, read and diagnosed with the baseline's settings.
    baseline : Baseline
        The baseline, read and checked.
    thresholds : Thresholds
        When the gate fails.
    """

    diagnose: DiagnoseRequest
    baseline: Baseline
    thresholds: Thresholds = Thresholds()
