"""What a command asks for, typed: every setting resolved (command line > config file >
defaults, ``credcli.cli.settings``) before any work starts. The workflows take these;
the Python API may build them directly."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from credcli.ci.thresholds import Thresholds
from credcli.engine.config import DiagnosisConfig
from credcli.io.schema import LogReading
from credcli.report.records import Baseline
from credcli.studies.settings import CURVE_RUNS, SimulationConfig, UwbSettings


@dataclass(frozen=True)
class DiagnoseRequest:
    """Diagnose ``logs`` (``diagnose``, ``baseline``, ``report``). ``jobs`` local worker
    processes share the segments (same output for any value); ``monte_carlo``: the logs
    are runs of one scenario, pooled; ``figures``: draw the plots too."""

    logs: tuple[Path, ...]
    reading: LogReading = LogReading()
    config: DiagnosisConfig = DiagnosisConfig()
    seed: int = 0
    jobs: int = 1
    monte_carlo: bool = False
    figures: bool = False


@dataclass(frozen=True)
class SimulateRequest:
    """The Monte Carlo study of ``config`` on ``scenario`` (a comma-separated list), or a
    ``sweep`` of one parameter, or the Fig. 1 ``curves`` (``curve_runs`` runs a point)."""

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
    periods, or ``window`` / ``whole``), diagnosed with ``config``."""

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
    segment by segment under ``thresholds``."""

    diagnose: DiagnoseRequest
    baseline: Baseline
    thresholds: Thresholds = Thresholds()
