"""Settings from a TOML config file and the command line: CLI over config over defaults."""

from __future__ import annotations

import dataclasses
import typing
from pathlib import Path

from credcli.engine.diagnosis import DiagnosisConfig
from credcli.errors import CredcliError
from credcli.io.checks import SEGMENT_HINTS, check_types, diagnosis_hints
from credcli.io.files import read_toml
from credcli.io.logs import LogSchema
from credcli.io.schema import ReadOptions

CONFIG_SECTIONS = ("columns", "input", "diagnosis", "segments", "simulate")
"""The tables a config file may hold; any other table is an error, never silently ignored."""


KEY_ALIASES = {"tau": "tau_nci", "flips": "n_flips", "probe_factor": "c"}
"""Config keys spelled as the command-line flags, beside the field names."""


def load_config(path: str | Path | None) -> dict:
    """The config file's tables (empty when no file is given)."""
    if path is None:
        return {}
    data = read_toml(path)
    unknown = sorted(set(data) - set(CONFIG_SECTIONS))
    if unknown:
        raise CredcliError(
            f"{path}: unknown table(s) or key(s) {', '.join(unknown)}; a config holds only the "
            f"tables [{'], ['.join(CONFIG_SECTIONS)}]"
        )
    for name, table in data.items():
        if not isinstance(table, dict):
            raise CredcliError(
                f"{path}: '{name}' must be a table ([{name}] with keys below it); "
                f"got {name} = {table!r}"
            )
    return {name: {KEY_ALIASES.get(k, k): v for k, v in t.items()} for name, t in data.items()}


def merged(section: dict, cli: dict, allowed, where: str, hints: dict | None = None) -> dict:
    """Config values (type-checked against ``hints``) overridden by CLI values that were
    given (not None)."""
    unknown = sorted(set(section) - set(allowed))
    if unknown:
        raise CredcliError(
            f"{where}: unknown key(s) {', '.join(unknown)}; allowed: {', '.join(sorted(allowed))}"
        )
    if hints is not None:
        check_types(section, hints, where)
    out = dict(section)
    out.update({k: v for k, v in cli.items() if v is not None})
    return out


def _table(config: dict, section: str, cls, cli: dict, where: str) -> dict:
    """The fields of dataclass ``cls`` from the config's ``[section]`` (type-checked),
    overridden by the command line."""
    return merged(
        config.get(section, {}),
        cli,
        cls.__dataclass_fields__,
        where,
        typing.get_type_hints(cls),
    )


def build_schema(config: dict, cli: dict, where: str = "config [columns]") -> LogSchema:
    values = _table(config, "columns", LogSchema, cli, where)
    try:
        return LogSchema().updated(**values)
    except CredcliError:
        raise  # already a message for the user (a ValueError too)
    except ValueError as exc:
        raise CredcliError(f"{where}: {exc}") from exc


def build_reading(config: dict, cli: dict, where: str = "config [input]") -> ReadOptions:
    """How logs are read: [input] of the config, overridden by the command line."""
    values = _table(config, "input", ReadOptions, cli, where)
    if values.get("truth") is not None:
        values["truth"] = str(values["truth"])
    try:
        return ReadOptions(**values)
    except CredcliError:
        raise
    except ValueError as exc:
        name = str(exc).split(" ", 1)[0]
        if cli.get(name) is not None or name not in config.get("input", {}):
            raise CredcliError(str(exc)) from exc  # the command line's value: its flag
        raise CredcliError(f"{where}: {exc}") from exc


def segment_settings(
    config: dict, window: str | None, whole: bool | None
) -> tuple[str | None, bool]:
    """``--window`` and ``--whole`` from the command line, else from [segments]."""
    values = _segments(config, {"window": window, "whole": whole})
    return values.get("window"), bool(values.get("whole", False))


def _segments(config: dict, cli: dict) -> dict:
    return merged(
        config.get("segments", {}), cli, SEGMENT_HINTS, "config [segments]", SEGMENT_HINTS
    )


def _diagnosis(config: dict, cli: dict) -> dict:
    hints = diagnosis_hints()
    return merged(config.get("diagnosis", {}), cli, hints, "config [diagnosis]", hints)


def build_diagnosis_config(
    config: dict, cli: dict, seed: int | None = None
) -> tuple[DiagnosisConfig, int]:
    """The DiagnosisConfig and the seed (default 0) from [diagnosis] and the CLI."""
    values = _diagnosis(config, cli | {"seed": seed})
    seed_value = values.pop("seed", 0)
    if not isinstance(seed_value, int) or seed_value < 0:
        raise CredcliError(f"the seed must be a non-negative integer; got {seed_value!r}")
    try:
        return DiagnosisConfig(**values), seed_value
    except CredcliError:
        raise
    except (TypeError, ValueError) as exc:
        raise CredcliError(f"invalid diagnosis setting: {exc}") from exc


def parse_range(text, what: str) -> tuple[float, float] | None:
    """'lo:hi' (or a 2-list from a config file) -> (lo, hi)."""
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
    if lo > hi:
        raise CredcliError(f"{what}: lower end {lo:g} is above the upper end {hi:g}")
    return lo, hi


def build_simulation_config(config: dict, cli: dict, diagnosis_cli: dict):
    """SimulationConfig from [simulate], [diagnosis] and the CLI."""
    from credcli.studies.simulate import SimulationConfig

    fields = {f.name for f in dataclasses.fields(SimulationConfig)} - {"diagnosis"}
    values = merged(
        config.get("simulate", {}),
        cli,
        fields,
        "config [simulate]",
        typing.get_type_hints(SimulationConfig),
    )
    for key in ("rho_optimism", "rho_pessimism", "bias", "eigenvalues"):
        if key in values:
            values[key] = parse_range(values[key], f"--{key.replace('_', '-')}")
    diagnosis, seed = build_diagnosis_config(config, diagnosis_cli, values.pop("seed", None))
    try:
        return SimulationConfig(**values, seed=seed, diagnosis=diagnosis)
    except TypeError as exc:
        raise CredcliError(f"invalid simulation setting: {exc}") from exc


def split_list(text: str | None) -> tuple[str, ...] | None:
    """'a,b, c' -> ('a', 'b', 'c'); None stays None."""
    if text is None:
        return None
    items = tuple(t.strip() for t in text.split(",") if t.strip())
    if not items:
        raise CredcliError(f"expected a comma-separated list of column names; got '{text}'")
    return items


def gate_requests(config: dict, cli: dict) -> dict:
    """What `gate` was asked for: [diagnosis] and [segments] of its config, overridden by
    the command line; each must equal the baseline's parameter of the same name."""
    out = _diagnosis(config, {}) | _segments(config, {})
    out.update({k: v for k, v in cli.items() if v is not None})
    return out


def _toml_value(value) -> str | None:
    """A default as TOML, or None for a setting that is unset by default."""
    import enum
    import json

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
    the settings dataclasses themselves (``make config`` writes it; a test checks it)."""
    from credcli.studies.simulate import SimulationConfig

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
    return "\n".join(lines).rstrip() + "\n"


def main() -> int:
    """``python -m credcli.cli.settings``: print configs/default.toml."""
    import sys

    sys.stdout.write(default_config_text())
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
