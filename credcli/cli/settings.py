"""Settings from a TOML config file and the command line, merged one way for every
command: command line > config file > defaults. Each command's option groups
(:mod:`credcli.cli.options`) become one typed request (:mod:`credcli.requests`) here.

A config file's tables: [columns] and [input] (how logs are read), [segments],
[diagnosis] (the rule and the seed), [simulate], [uwb] and [gate].
"""

from __future__ import annotations

import dataclasses
import enum
import json
import math
import sys
import typing
from pathlib import Path

from credcli.ci.gate import check_same_parameters, check_same_reading
from credcli.ci.thresholds import Thresholds
from credcli.cli.options import (
    FIELD_OPTIONS,
    LogOptions,
    RuleOptions,
    RunOptions,
    ScreenMode,
    SegmentOptions,
    StudyOptions,
    ThresholdOptions,
    UwbOptions,
)
from credcli.engine.config import AUTO
from credcli.engine.diagnosis import DiagnosisConfig
from credcli.engine.rng import check_seed
from credcli.errors import CredcliError, plain
from credcli.io.checks import SEGMENT_HINTS, check_types, diagnosis_hints
from credcli.io.files import STDIN, check_small_input, read_toml
from credcli.io.logs import LogSchema
from credcli.io.schema import LogReading, ReadOptions
from credcli.report.records import read_baseline
from credcli.requests import DiagnoseRequest, GateRequest, Kept, SimulateRequest, UwbRequest
from credcli.schedule.pool import default_jobs
from credcli.studies.settings import STD_ESTIMATE, SimulationConfig, UwbSettings

KEY_ALIASES = {
    option: field
    for field, option in FIELD_OPTIONS.items()
    if field in DiagnosisConfig.__dataclass_fields__
}
"""[diagnosis] keys spelled as the command-line flags (tau, flips, probe_factor), beside
the field names."""


def _simulate_hints() -> dict:
    hints = typing.get_type_hints(SimulationConfig)
    del hints["diagnosis"]  # [diagnosis] is its own table
    return hints


CONFIG_TABLES = {
    "columns": typing.get_type_hints(LogSchema),
    "input": typing.get_type_hints(ReadOptions),
    "diagnosis": diagnosis_hints(),
    "segments": SEGMENT_HINTS,
    "simulate": _simulate_hints(),
    "uwb": typing.get_type_hints(UwbSettings),
    "gate": typing.get_type_hints(Thresholds),
}
"""Each table a config file may hold: its keys and their types (the fields of the
settings dataclass it sets). Any other table or key is an error, never silently ignored."""

CONFIG_SECTIONS = tuple(CONFIG_TABLES)


def load_config(path: str | Path | None) -> dict:
    """The config file's tables (empty when no file is given), every key and value
    checked, whichever command reads them: a typo is an error, never ignored.

    Parameters
    ----------
    path : str, Path or None
        The TOML config file (``--config``), or None for no file.

    Returns
    -------
    dict
        Table name -> {key: value} for each table the file holds (of `CONFIG_TABLES`);
        [diagnosis] keys spelled as flags (``tau``, ``flips``, ``probe_factor``) are
        renamed to their field names (`KEY_ALIASES`).

    Raises
    ------
    CredcliError
        If the file is missing, unreadable or not valid TOML, holds an unknown table or
        key, a table that is not a table, or a value of the wrong type.
    """
    if path is None:
        return {}
    data = read_toml(path)
    unknown = sorted(set(data) - set(CONFIG_SECTIONS))
    if unknown:
        raise CredcliError(
            f"{path}: unknown table(s) or key(s) {', '.join(unknown)}; a config holds only the "
            f"tables [{'], ['.join(CONFIG_SECTIONS)}]"
        )
    out = {}
    for name, table in data.items():
        if not isinstance(table, dict):
            raise CredcliError(
                f"{path}: '{name}' must be a table ([{name}] with keys below it); "
                f"got {name} = {table!r}"
            )
        table = {KEY_ALIASES.get(k, k): v for k, v in table.items()}
        hints, where = CONFIG_TABLES[name], f"config [{name}]"
        wrong = sorted(set(table) - set(hints))
        if wrong:
            raise CredcliError(
                f"{where}: unknown key(s) {', '.join(wrong)}; allowed: {', '.join(sorted(hints))}"
            )
        check_types(table, hints, where)
        out[name] = table
    return out


def merged(config: dict, section: str, cli: dict) -> dict:
    """The values of ``[section]`` of a loaded config, overridden by the command line's
    given (not None) values: command line > config file. The defaults are the settings
    dataclass's own.

    Parameters
    ----------
    config : dict
        A loaded config (`load_config`).
    section : str
        The table's name, e.g. ``"diagnosis"``.
    cli : dict
        The command line's values by field name; None means not given.

    Returns
    -------
    dict
        The table's values with every given command-line value over them.
    """
    out = dict(config.get(section, {}))
    out.update({k: v for k, v in cli.items() if v is not None})
    return out


def built(cls, values: dict, config: dict, section: str, given: dict):
    """``cls(**values)``, the settings of ``[section]`` under the command line's ``given``
    values. A bad value names its source: a config file's table and key, or (through the
    parameter in the message) the command line's flag.

    Parameters
    ----------
    cls : type
        The settings dataclass to build.
    values : dict
        Its keyword arguments (`merged` values).
    config : dict
        The loaded config, to tell whether a bad value came from the file.
    section : str
        The config table ``values`` came from.
    given : dict
        The command line's values by field name (None: not given).

    Returns
    -------
    object
        The ``cls`` instance.

    Raises
    ------
    CredcliError
        If ``cls`` refuses a value: prefixed with ``config [section]:`` when the value
        came from the config file and not the command line; a TypeError or ValueError
        of ``cls`` becomes ``invalid <section> setting: …``.
    """
    try:
        return cls(**values)
    except CredcliError as exc:
        name = exc.parameter
        if name is not None and given.get(name) is None and name in config.get(section, {}):
            message = plain(exc.message).removeprefix("invalid setting: ")
            raise CredcliError(f"config [{section}]: {message}", name) from exc
        raise
    except (TypeError, ValueError) as exc:
        raise CredcliError(f"invalid {section} setting: {exc}") from exc


def build_schema(config: dict, cli: dict) -> LogSchema:
    """The column layout: [columns] of the config, overridden by the command line.

    Parameters
    ----------
    config : dict
        A loaded config (`load_config`).
    cli : dict
        The command line's column settings by LogSchema field name (None: not given).

    Returns
    -------
    LogSchema
        The default layout updated with those values.

    Raises
    ------
    CredcliError
        If the layout is invalid (a ValueError is prefixed with ``config [columns]:``).
    """
    values = merged(config, "columns", cli)
    try:
        return LogSchema().updated(**values)
    except CredcliError:
        raise  # already a message for the user (a ValueError too)
    except ValueError as exc:
        raise CredcliError(f"config [columns]: {exc}") from exc


def build_reading(config: dict, cli: dict) -> ReadOptions:
    """How logs are read: [input] of the config, overridden by the command line.

    Parameters
    ----------
    config : dict
        A loaded config (`load_config`).
    cli : dict
        The command line's values by ReadOptions field name (None: not given).

    Returns
    -------
    ReadOptions
        The reading options (``truth`` as a string).

    Raises
    ------
    CredcliError
        If a value is invalid (see `built`), or the config's truth file does not exist.
    """
    values = merged(config, "input", cli)
    if values.get("truth") is not None:
        values["truth"] = truth_name(values["truth"])
        named = values["truth"]  # where the config names it, the message says so
        local = named != STDIN and "://" not in named
        if cli.get("truth") is None and local and not Path(named).exists():
            raise CredcliError(
                f"config [input] truth: {values['truth']}: file not found (a relative path is "
                "read from the working directory)"
            )
    return built(ReadOptions, values, config, "input", cli)


def truth_name(value) -> str:
    """A ``truth`` setting as the path text it names.

    Parameters
    ----------
    value : object
        The setting (a path or a string, from the command line or a config).

    Returns
    -------
    str
        Its text.

    Raises
    ------
    CredcliError
        If it is empty or blank: ``Path("")`` would be the current directory.
    """
    name = str(value)
    if not name.strip():
        raise CredcliError("`truth` is empty; name the ground-truth file or bag")
    return name


def segment_settings(
    config: dict, window: str | None, whole: bool | None
) -> tuple[str | None, bool]:
    """``--window`` and ``--whole`` from the command line, else from [segments]. They
    exclude each other; one given on the command line replaces the other in the config.

    Parameters
    ----------
    config : dict
        A loaded config (`load_config`).
    window : str or None
        ``--window`` (None: not given).
    whole : bool or None
        ``--whole`` (None: not given).

    Returns
    -------
    tuple of (str or None, bool)
        The window and whether each log is one segment (default False).

    Raises
    ------
    CredcliError
        If both are given on the command line, or both in the config and neither on the
        command line.
    """
    values = merged(config, "segments", {"window": window, "whole": whole})
    chosen, one = values.get("window"), bool(values.get("whole", False))
    if chosen is not None and one:  # the command line's choice over the config's
        if window is not None and whole:
            raise CredcliError("`window` and `whole` exclude each other; give one of them")
        if window is None and not whole:
            raise CredcliError(
                "the config's [segments] sets both window and whole, which exclude each "
                "other; keep one of them"
            )
        chosen, one = (window, False) if window is not None else (None, True)
    return chosen, one


def build_diagnosis_config(
    config: dict, cli: dict, seed: int | None = None, seed_source: str = "--seed"
) -> tuple[DiagnosisConfig, int]:
    """The DiagnosisConfig and the seed (default 0) from [diagnosis] and the CLI.

    Parameters
    ----------
    config : dict
        A loaded config (`load_config`).
    cli : dict
        The rule's values by DiagnosisConfig field name (`rule_values`; None: not given).
    seed : int or None, optional
        ``--seed`` (None: from [diagnosis], else 0).
    seed_source : str, default "--seed"
        Where ``seed`` came from, for the message of a bad one.

    Returns
    -------
    tuple of (DiagnosisConfig, int)
        The configuration and the seed.

    Raises
    ------
    CredcliError
        If the seed is not a non-negative integer, or a rule setting is invalid.
    """
    values = merged(config, "diagnosis", cli | {"seed": seed})
    try:
        seed_value = check_seed(values.pop("seed", 0))
    except CredcliError as exc:  # the API's check, with where the seed came from
        where = seed_source if seed is not None else "config [diagnosis] seed"
        raise CredcliError(f"{where}: {exc.message}") from exc
    return built(DiagnosisConfig, values, config, "diagnosis", cli), seed_value


def split_list(text: str | None) -> tuple[str, ...] | None:
    """'a,b, c' -> ('a', 'b', 'c'); None stays None.

    Parameters
    ----------
    text : str or None
        Comma-separated column names.

    Returns
    -------
    tuple of str, or None
        The names, stripped, empty items left out.

    Raises
    ------
    CredcliError
        If ``text`` holds no name.
    """
    if text is None:
        return None
    items = tuple(t.strip() for t in text.split(",") if t.strip())
    if not items:
        raise CredcliError(f"expected a comma-separated list of column names; got '{text}'")
    return items


def block_length_value(text: str | None) -> int | str | None:
    """--block-length: 'auto' or a positive integer.

    Parameters
    ----------
    text : str or None
        The option's text (None: not given).

    Returns
    -------
    int, str or None
        The integer, ``"auto"`` (any case, spaces around it ignored), or None.

    Raises
    ------
    CredcliError
        If ``text`` is neither ``auto`` nor an integer >= 1.
    """
    if text is None or text.strip().lower() == AUTO:
        return None if text is None else AUTO
    try:
        value = int(text)
    except ValueError:
        value = 0
    if value < 1:
        raise CredcliError(f"--block-length: expected auto or an integer >= 1; got '{text}'")
    return value


def jobs_value(jobs: int | None) -> int:
    """--jobs: given, or the number of cores.

    Parameters
    ----------
    jobs : int or None
        ``--jobs`` (None: not given).

    Returns
    -------
    int
        ``jobs``, or the number of cores this process may use (`default_jobs`).

    Raises
    ------
    CredcliError
        If ``jobs`` is below 1 or above `MAX_JOBS`.
    """
    if jobs is None:
        return default_jobs()
    if jobs < 1:
        raise CredcliError(f"--jobs must be >= 1; got {jobs}")
    if jobs > MAX_JOBS:
        raise CredcliError(
            f"--jobs {jobs} is more processes than credcli starts (at most {MAX_JOBS:,}; this "
            f"machine has {default_jobs()} cores)"
        )
    return jobs


MAX_JOBS = 1024
"""Most worker processes --jobs may ask for: each is a process, forked at once."""


def rule_values(rule: RuleOptions) -> dict:
    """The rule options by DiagnosisConfig field name (None where not given).

    Parameters
    ----------
    rule : RuleOptions
        The rule's options from the command line.

    Returns
    -------
    dict
        Field name -> value, flags renamed to fields (``flips`` is ``n_flips``), the
        block length parsed (`block_length_value`).
    """
    values = {KEY_ALIASES.get(k, k): v for k, v in dataclasses.asdict(rule).items()}
    values["block_length"] = block_length_value(rule.block_length)
    return values


def log_reading(config: dict, log: LogOptions, segments: SegmentOptions) -> LogReading:
    """How logs are read and cut: [columns], [input] and [segments] under the command line.

    Parameters
    ----------
    config : dict
        A loaded config (`load_config`).
    log : LogOptions
        The reading options from the command line.
    segments : SegmentOptions
        ``--window`` and ``--whole``.

    Returns
    -------
    LogReading
        The column layout, the reading options, ``drop_invalid`` and the segmentation.
    """
    schema = build_schema(
        config,
        {
            "time": log.time_column,
            "segment": log.segment_column,
            "truth_columns": split_list(log.truth_columns),
            "estimate_columns": split_list(log.estimate_columns),
            "cov_columns": split_list(log.cov_columns),
            "cov_kind": log.cov_kind,
        },
    )
    window, whole = segment_settings(config, segments.window, segments.whole)
    given = {f.name: getattr(log, f.name) for f in dataclasses.fields(ReadOptions)}
    return LogReading(schema, build_reading(config, given), bool(log.drop_invalid), window, whole)


def diagnose_request(
    logs,
    config_file: Path | None,
    log: LogOptions,
    segments: SegmentOptions,
    rule: RuleOptions,
    seed: int | None,
    run: RunOptions,
    *,
    monte_carlo: bool = False,
    figures: bool = False,
    keep: Kept = Kept.RESULTS,
) -> DiagnoseRequest:
    """What `diagnose`, `baseline` and `report` ask for.

    Parameters
    ----------
    logs : sequence of Path
        The logs to diagnose.
    config_file : Path or None
        ``--config``.
    log : LogOptions
        How the logs are read.
    segments : SegmentOptions
        How they are cut.
    rule : RuleOptions
        How a segment is judged.
    seed : int or None
        ``--seed`` (None: from [diagnosis], else 0).
    run : RunOptions
        ``--jobs`` (the scheduler is the command's).
    monte_carlo : bool, default False
        The logs are runs of one scenario, pooled (``--monte-carlo``).
    figures : bool, default False
        Draw the figures too.
    keep : Kept, default Kept.RESULTS
        What is kept of each segment's result once it is in the report.

    Returns
    -------
    DiagnoseRequest
        Every setting resolved (command line > config file > defaults).

    Raises
    ------
    CredcliError
        If the config file or a setting is invalid, or '-' is given more than once.
    """
    read_once([*logs, log.truth])
    config = load_config(config_file)
    diagnosis, seed_value = build_diagnosis_config(config, rule_values(rule), seed)
    reading = log_reading(config, log, segments)
    jobs = jobs_value(run.jobs)
    return DiagnoseRequest(
        tuple(logs), reading, diagnosis, seed_value, jobs, monte_carlo, figures, keep
    )


def gate_request(
    log: Path,
    baseline_file: Path,
    config_file: Path | None,
    thresholds: ThresholdOptions,
    truth: Path | None,
    segments: SegmentOptions,
    rule: RuleOptions,
    seed: int | None,
    run: RunOptions,
    *,
    figures: bool = False,
) -> GateRequest:
    """What `gate` asks for: LOG diagnosed with the baseline's settings, which every
    setting given (command line or [diagnosis] and [segments]) must equal.

    Parameters
    ----------
    log : Path
        The new log.
    baseline_file : Path
        The baseline JSON (``--baseline``).
    config_file : Path or None
        ``--config``.
    thresholds : ThresholdOptions
        When the gate fails (over [gate] of the config).
    truth : Path or None
        The new log's ground truth (``--truth``; else [input] truth of the config).
    segments : SegmentOptions
        ``--window`` and ``--whole``, which must equal the baseline's.
    rule : RuleOptions
        Rule settings, which must equal the baseline's.
    seed : int or None
        ``--seed``, which must equal the baseline's.
    run : RunOptions
        ``--jobs``.
    figures : bool, default False
        Draw the figures too.

    Returns
    -------
    GateRequest
        The diagnosis of ``log`` with the baseline's reading, configuration and seed, the
        baseline, and the thresholds.

    Raises
    ------
    CredcliError
        If the baseline cannot be read, a given setting differs from the baseline's, the
        baseline had a separate ground truth and none is given, or '-' is given twice.
    """
    read_once([log, truth])
    config = load_config(config_file)
    given = dataclasses.asdict(thresholds)
    limits = built(Thresholds, merged(config, "gate", given), config, "gate", given)
    given = rule_values(rule) | {"seed": seed, "window": segments.window, "whole": segments.whole}
    requested = config.get("diagnosis", {}) | config.get("segments", {})
    requested.update({k: v for k, v in given.items() if v is not None})
    jobs = jobs_value(run.jobs)
    check_small_input(baseline_file, "baseline JSON file")  # read whole: never /dev/zero
    baseline = read_baseline(baseline_file)
    check_same_parameters(baseline, requested)
    check_same_reading(
        baseline,
        {
            "columns": (build_schema(config, {}), list(config.get("columns", {}))),
            "input": (build_reading(config, {}), list(config.get("input", {}))),
        },
    )
    if truth is None and config.get("input", {}).get("truth") is not None:
        truth = Path(truth_name(config["input"]["truth"]))  # the user's config, not the baseline
    reading = baseline.reading
    recorded_truth = reading.options.truth
    # a baseline carries settings, never paths: only the command line names files to read
    reading = dataclasses.replace(
        reading,
        options=dataclasses.replace(reading.options, truth=None if truth is None else str(truth)),
    )
    if recorded_truth is not None and truth is None:
        raise CredcliError(
            f"{baseline_file}: the baseline was recorded with a separate ground truth "
            f"('{Path(recorded_truth).name}'); a baseline never names the files credcli reads: "
            "give the new log's truth with `truth`"
        )
    diagnose = DiagnoseRequest(  # gate keeps what it compares (workflows.run_gate)
        (log,), reading, baseline.config, baseline.seed, jobs, figures=figures, keep=Kept.NOTHING
    )
    return GateRequest(diagnose, baseline, limits)


def parse_range(text, what: str) -> tuple[float, float] | None:
    """'lo:hi' (or a 2-list from a config file) -> (lo, hi).

    Parameters
    ----------
    text : str, list, tuple or None
        The range.
    what : str
        Where it came from, for the error message (a parameter or a config key).

    Returns
    -------
    tuple of (float, float), or None
        ``(lo, hi)``; None for None.

    Raises
    ------
    CredcliError
        If ``text`` is not two numbers, or ``lo > hi``.
    """
    if text is None:
        return None
    if isinstance(text, (list, tuple)):
        parts = list(text)
    else:
        parts = str(text).split(":")
    try:
        lo, hi = (float(p) for p in parts)
    except (TypeError, ValueError) as exc:
        raise CredcliError(f"{what}: expected a range lo:hi, got '{text}'") from exc
    if not (math.isfinite(lo) and math.isfinite(hi)):
        raise CredcliError(f"{what}: the ends of a range must be finite numbers, got '{text}'")
    if lo > hi:
        raise CredcliError(f"{what}: lower end {lo:g} is above the upper end {hi:g}")
    return lo, hi


def read_once(paths) -> None:
    """A CredcliError where standard input ('-') is among ``paths`` more than once (the
    logs, ``--truth``): it is read once, and a second read would find no data.

    Parameters
    ----------
    paths : sequence of Path or None
        The inputs read as logs or truth (None: not given).

    Raises
    ------
    CredcliError
        If '-' is given more than once.
    """
    stdin = sum(path is not None and str(path) == STDIN for path in paths)
    if stdin > 1:
        raise CredcliError(f"'-' (standard input) is given {stdin} times; it can be read once")


def only_one(option: str, values: list[str] | None) -> str | None:
    """The one value of an option that takes one, given as a list so that a repeated
    option is an error rather than its last value silently replacing the others.

    Parameters
    ----------
    option : str
        The option's name, for the message (``--sweep``).
    values : list of str or None
        What the command line gave.

    Returns
    -------
    str or None
        The value; None where the option was not given.

    Raises
    ------
    CredcliError
        If the option was given more than once.

    Examples
    --------
    >>> only_one("--sweep", ["rho=1,2"]), only_one("--sweep", None)
    ('rho=1,2', None)
    """
    if not values:
        return None
    if len(values) > 1:
        raise CredcliError(f"{option} is given {len(values)} times; give it once")
    return values[0]


def simulate_request(
    config_file: Path | None,
    study: StudyOptions,
    rule: RuleOptions,
    seed: int | None,
    run: RunOptions,
    *,
    scenario: str,
    sweep: str | None,
    curves: bool,
    curve_runs: int,
    figures: bool = False,
) -> SimulateRequest:
    """What `simulate` asks for: [simulate] and [diagnosis] under the command line.

    Parameters
    ----------
    config_file : Path or None
        ``--config``.
    study : StudyOptions
        The study's design from the command line.
    rule : RuleOptions
        How a trial is judged.
    seed : int or None
        ``--seed`` (None: [simulate] seed, else [diagnosis] seed, else 0).
    run : RunOptions
        ``--jobs``.
    scenario : str
        ``--scenario``: all, labels or aliases, comma-separated.
    sweep : str or None
        ``--sweep``.
    curves : bool
        ``--curves``: the Fig. 1 curves instead.
    curve_runs : int
        ``--curve-runs``: Monte Carlo runs per curve point.
    figures : bool, default False
        Draw the figures too.

    Returns
    -------
    SimulateRequest
        Every setting resolved (command line > config file > defaults).

    Raises
    ------
    CredcliError
        If ``curve_runs`` is below 1, a sweep is asked with the curves, a range is not
        ``lo:hi``, or a setting is invalid.
    """
    jobs = jobs_value(run.jobs)
    if curve_runs < 1:
        raise CredcliError(f"--curve-runs must be >= 1; got {curve_runs}")
    if curves and sweep is not None:  # the curves are a table of their own: one or the other
        raise CredcliError("--sweep and --curves make different tables; give one of them")
    config = load_config(config_file)
    given = dataclasses.asdict(study)
    values = merged(config, "simulate", given | {"seed": seed})
    for key in ("rho_optimism", "rho_pessimism", "bias", "eigenvalues"):
        if key in values:
            where = f"`{key}`" if given[key] is not None else f"config [simulate] {key}"
            values[key] = parse_range(values[key], where)
    source = "--seed" if seed is not None else "config [simulate] seed"
    diagnosis, seed_value = build_diagnosis_config(
        config, rule_values(rule), values.pop("seed", None), source
    )
    values |= {"seed": seed_value, "diagnosis": diagnosis}
    sim = built(SimulationConfig, values, config, "simulate", given)
    if curves:
        check_curve_runs(curve_runs, sim.dim)
    return SimulateRequest(sim, scenario, sweep, curves, curve_runs, jobs, figures)


MAX_CURVE_RUNS = 1_000_000
"""Most --curve-runs: the paper's curves take 5,000; a million take about a minute."""


def check_curve_runs(runs: int, dim: int) -> None:
    """Refuse, before any draw, Fig. 1 curves of more runs than :data:`MAX_CURVE_RUNS` or
    whose per-point arrays (runs × d × d numbers, a few at once) would not fit in memory.

    Parameters
    ----------
    runs : int
        ``--curve-runs``.
    dim : int
        The dimension d.

    Raises
    ------
    CredcliError
        If ``runs`` is past :data:`MAX_CURVE_RUNS`, or 4 arrays of runs × d² float64
        exceed :func:`credcli.io.files.memory_budget`.
    """
    from credcli.io.files import memory_budget

    if runs > MAX_CURVE_RUNS:
        raise CredcliError(f"--curve-runs must be 1 … {MAX_CURVE_RUNS:,}; got {runs:,}")
    need, budget = 4 * runs * dim * dim * 8, memory_budget()
    if need > budget:
        raise CredcliError(
            f"--curve-runs {runs:,} in d = {dim} would need {need / 2**30:.3g} GiB, more than "
            f"the {budget / 2**30:.3g} GiB credcli may use here; use fewer runs or a smaller "
            "--dim"
        )


def id_pairs(text: str | None, flag: str, kind) -> tuple:
    """'4=1,5=2' -> ((4, 1), (5, 2)) with values of ``kind``.

    Parameters
    ----------
    text : str or None
        ``ID=VALUE`` pairs separated by commas.
    flag : str
        The option, for the error message.
    kind : callable
        Converts each value (``int``, ``float``).

    Returns
    -------
    tuple of (int, object) pairs
        Empty for None or an empty ``text``.

    Raises
    ------
    CredcliError
        If an item is not ``ID=VALUE`` with an integer ID and a value ``kind`` takes.
    """
    if not text:
        return ()
    out = []
    for item in text.split(","):
        key, sep, value = item.partition("=")
        try:
            if not sep:
                raise ValueError(item)
            out.append((int(key), kind(value)))
        except ValueError as exc:
            raise CredcliError(
                f"{flag}: expected ID=VALUE pairs separated by commas (e.g. 4=1,5=2); got '{item}'"
            ) from exc
    return tuple(out)


def std_settings(text: str | None) -> dict:
    """--std: a value, ID=VALUE pairs (with an optional plain default among them), or
    'estimate'; by UwbSettings field name.

    Parameters
    ----------
    text : str or None
        ``--std`` (None: not given).

    Returns
    -------
    dict
        ``{}`` for None; ``{"std_estimate": True}`` for 'estimate'; else ``std`` (the
        plain value, or None) and ``std_by_anchor`` (the pairs).

    Raises
    ------
    CredcliError
        If the plain value is not a number, or more than one is given.
    """
    if text is None:
        return {}
    if text.strip().lower() == STD_ESTIMATE:
        return {"std_estimate": True}
    default = [t for t in text.split(",") if "=" not in t]
    pairs = ",".join(t for t in text.split(",") if "=" in t)
    try:
        value = float(default[0]) if default else None
    except ValueError as exc:
        raise CredcliError(
            f"--std: expected metres (0.1), ID=VALUE pairs (4=0.1,9=0.12) or 'estimate'; got '{text}'"
        ) from exc
    if len(default) > 1:
        raise CredcliError(f"--std: at most one default value; got '{text}'")
    return {"std": value, "std_by_anchor": id_pairs(pairs, "--std", float)}


def uwb_request(
    file: Path,
    config_file: Path | None,
    uwb: UwbOptions,
    anchors: Path | None,
    segments: SegmentOptions,
    rule: RuleOptions,
    seed: int | None,
    *,
    figures: bool = False,
) -> UwbRequest:
    """What `uwb` asks for: [uwb], [segments] and [diagnosis] under the command line.

    Parameters
    ----------
    file : Path
        The STAR-loc ``uwb.csv``.
    config_file : Path or None
        ``--config``.
    uwb : UwbOptions
        The pipeline's settings from the command line.
    anchors : Path or None
        ``--anchors`` (None: self-calibrated).
    segments : SegmentOptions
        ``--window`` and ``--whole`` (neither: static periods).
    rule : RuleOptions
        How a period is judged.
    seed : int or None
        ``--seed`` (None: from [diagnosis], else 0).
    figures : bool, default False
        Draw the figures too.

    Returns
    -------
    UwbRequest
        Every setting resolved (command line > config file > defaults).

    Raises
    ------
    CredcliError
        If the config file or a setting is invalid.
    """
    config = load_config(config_file)
    diagnosis, seed_value = build_diagnosis_config(config, rule_values(rule), seed)
    given = {
        "range_column": uwb.range_column,
        "packet_window": uwb.packet_window,
        "min_anchors": uwb.min_anchors,
        "max_speed": uwb.max_speed,
        "min_static": uwb.min_static,
        "screen": None if uwb.screen is None else uwb.screen is ScreenMode.ALL,
        "residual_level": uwb.residual_level,
        "robust": uwb.robust,
        "anchor_map": id_pairs(uwb.anchor_map, "--anchor-map", int) or None,
    } | std_settings(uwb.std)
    values = merged(config, "uwb", given)
    for key in ("anchor_map", "std_by_anchor"):  # lists of [id, value] pairs in a file
        if key in values:
            values[key] = tuple(tuple(pair) for pair in values[key])
    settings = built(UwbSettings, values, config, "uwb", given)
    window, whole = segment_settings(config, segments.window, segments.whole)
    return UwbRequest(file, settings, diagnosis, anchors, window, whole, seed_value, figures)


def _toml_value(value) -> str | None:
    """A default as TOML, or None for a setting that is unset by default."""
    if isinstance(value, enum.Enum):
        value = value.value
    if value is None:
        return None
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (int, float)):
        return repr(value)
    if isinstance(value, str):
        return json.dumps(value, ensure_ascii=False)
    if isinstance(value, (tuple, list)):
        return "[" + ", ".join(_toml_value(v) or '""' for v in value) + "]"
    raise TypeError(f"no TOML form for {value!r}")


def _section(name: str, values: dict[str, object], unset_examples: dict[str, str]) -> list[str]:
    lines = [f"[{name}]"]
    for key, value in values.items():
        text = _toml_value(value)
        if text is None or text == "[]":
            lines.append(f"# {key} = {unset_examples.get(key, '...')}  # unset by default")
        else:
            lines.append(f"{key} = {text}")
    return lines + [""]


def default_config_text() -> str:
    """configs/default.toml: every setting a config file takes, at its default, made from
    the settings dataclasses themselves (``make config`` writes it; a test checks it).

    Returns
    -------
    str
        The file's text: one table per settings class; a setting unset by default is a
        comment with an example value.
    """

    def defaults(cls, skip=()) -> dict:
        instance = cls()
        return {
            f.name: getattr(instance, f.name) for f in dataclasses.fields(cls) if f.name not in skip
        }

    simulate = defaults(SimulationConfig, skip=("diagnosis",))
    simulate.pop("seed")  # the seed is [diagnosis] seed, shared by the commands
    examples = {
        "truth_columns": '["x", "y"]',
        "estimate_columns": '["xh", "yh"]',
        "cov_columns": '["pxx", "pxy", "pyy"]',
        "cov_kind": '"upper"',
        "truth": '"groundtruth.csv"',
        "topic": '"/odom"',
        "truth_topic": '"/ground_truth"',
        "max_dt": "0.05",
        "states": '"pose"',
        "window": '"5s"',
        "std": "0.1",
        "std_by_anchor": "[[4, 0.1], [9, 0.12]]",
        "anchor_map": "[[1, 4], [2, 9]]",
    }
    lines = [
        "# Every setting credcli reads from a config file, at its default value.",
        "#   credcli diagnose log.csv --config configs/default.toml",
        "# Precedence: command-line options > this file > built-in defaults.",
        "# Generated from the settings classes by `make config`; do not edit by hand.",
        "",
    ]
    lines += _section("columns", defaults(LogSchema), examples)
    lines += _section("input", defaults(ReadOptions), examples)
    lines += _section("diagnosis", defaults(DiagnosisConfig) | {"seed": 0}, examples)
    lines += _section("segments", {"window": None, "whole": False}, examples)
    lines += _section("simulate", simulate, examples)
    lines += _section("uwb", defaults(UwbSettings), examples)
    lines += _section("gate", defaults(Thresholds), examples)
    return "\n".join(lines).rstrip() + "\n"


def main() -> int:
    """``python -m credcli.cli.settings``: print configs/default.toml.

    Returns
    -------
    int
        The exit code, 0.
    """
    sys.stdout.write(default_config_text())
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
