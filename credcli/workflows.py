"""Glue for the commands: file -> EstimatorLog -> segments -> Diagnosis -> Report.

Each function is what one command does, minus option parsing and printing.
"""

from __future__ import annotations

from pathlib import Path

from credcli import segments as seg
from credcli.diagnosis import DiagnosisConfig, MetricsLevel, diagnose_log
from credcli.logs import EstimatorLog, LogSchema, load_log
from credcli.render import Report, config_parameters, diagnose_report


def split(log: EstimatorLog, window: str | None = None, whole: bool = False) -> list[seg.Segment]:
    """Segments of a log: the whole log, fixed windows, or the segment column (in that
    order of precedence); a log without a segment column is one segment."""
    if whole:
        return seg.whole(log.n, log.time)
    if window is not None:
        return seg.by_window(log.n, seg.Window.parse(window), log.time)
    if log.segment is not None:
        return seg.by_column(log.segment, log.time)
    return seg.whole(log.n, log.time)


def segmentation_name(window: str | None, whole: bool) -> str:
    if whole:
        return "whole"
    return f"window:{seg.Window.parse(window)}" if window is not None else "column"


def run_diagnose(
    paths: list[Path],
    schema: LogSchema,
    config: DiagnosisConfig,
    window: str | None = None,
    whole: bool = False,
    seed: int = 0,
    drop_invalid: bool = False,
    progress=None,
) -> Report:
    """Load, segment and diagnose every log; return the `diagnose` report."""
    loaded = [load_log(p, schema, drop_invalid) for p in paths]
    plans = [(log, split(log, window, whole)) for log in loaded]
    total = sum(len(s) for _, s in plans)
    results = []
    for log, segments in plans:
        offset = len(results)
        tick = None if progress is None else (lambda k, o=offset: progress(o + k, total))
        results.extend(diagnose_log(log, segments, config, seed, tick))
    parameters = config_parameters(config) | {
        "seed": seed,
        "segmentation": segmentation_name(window, whole),
        "drop_invalid": drop_invalid,
    }
    logs = [
        {
            "path": log.source,
            "epochs": log.n,
            "dim": log.dim,
            "dropped_rows": log.dropped_rows,
            "segments": len(s),
        }
        for log, s in plans
    ]
    return diagnose_report(results, parameters, logs, config.metrics is MetricsLevel.ALL)
