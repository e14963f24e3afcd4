"""Commands as declarations: option groups declared once, one settings merge (command line >
config file > defaults) for every command, and errors that name the parameter's source."""

from __future__ import annotations

import ast
import dataclasses
import inspect
import json
from pathlib import Path
from typing import Annotated

import pytest
import typer
from conftest import SAMPLE

from credcli.cli.app import app
from credcli.cli.edge import _flags, flag_names
from credcli.cli.options import GROUPS, RuleOptions, SegmentOptions, declare
from credcli.errors import NAMED, CredcliError, plain
from tests.test_edges import error_line, run

ROOT = Path(__file__).resolve().parents[1]
LOG = SAMPLE / "estimator_log.csv"
REGRESSED = SAMPLE / "estimator_log_regressed.csv"
GRID = SAMPLE / "starloc_grid_uwb.csv"


def _options(command: str) -> dict[str, str]:
    """A command's options: parameter name -> long flag."""
    click_command = typer.main.get_command(app).commands[command]
    return {
        p.name: next(o for o in p.opts if o.startswith("--"))
        for p in click_command.params
        if getattr(p, "param_type_name", "") == "option"
    }


def test_no_option_is_declared_in_two_groups():
    names = [f.name for group in GROUPS for f in dataclasses.fields(group)]
    assert len(names) == len(set(names))


def test_declare_spreads_a_group_and_gathers_it_back():
    @declare
    def command(
        x: Annotated[int, typer.Option("--x")] = 1,
        segments: SegmentOptions = SegmentOptions(),
        y: Annotated[int, typer.Option("--y")] = 2,
    ) -> tuple:
        return x, segments, y

    assert list(inspect.signature(command).parameters) == ["x", "window", "whole", "y"]
    assert command(x=3, window="5s", whole=None, y=4) == (3, SegmentOptions("5s", None), 4)

    def twice(
        segments: SegmentOptions = SegmentOptions(), window: Annotated[str, typer.Option()] = ""
    ):
        return segments

    with pytest.raises(TypeError, match="window declared twice"):
        declare(twice)


@pytest.mark.parametrize("command", ["diagnose", "baseline", "gate", "simulate", "uwb", "report"])
def test_every_command_takes_the_same_rule_options(command):
    rule = {f.name for f in dataclasses.fields(RuleOptions)} | {"seed", "config"}
    assert rule <= set(_options(command))


def test_an_option_has_one_flag_in_every_command():
    seen: dict[str, str] = {}
    for command in ("diagnose", "baseline", "gate", "simulate", "uwb", "report"):
        for name, flag in _options(command).items():
            assert seen.setdefault(name, flag) == flag, name


def test_library_messages_name_only_parameters_the_command_line_has():
    """Every backticked name in a message outside cli/ becomes a flag on the command line
    (a name without an option would be shown in backticks)."""
    flags = _flags()
    unknown = {}
    for path in (ROOT / "credcli").rglob("*.py"):
        if "cli" in path.parts:
            continue
        tree = ast.parse(path.read_text())
        docstrings = {
            id(node.value)
            for node in ast.walk(tree)
            if isinstance(node, ast.Expr) and isinstance(node.value, ast.Constant)
        }
        for node in ast.walk(tree):
            if isinstance(node, ast.Constant) and isinstance(node.value, str):
                if id(node) not in docstrings:
                    for m in NAMED.finditer(node.value):
                        if m[1] not in flags:
                            unknown[m[1]] = path.name
    assert unknown == {}


def test_flag_names_and_plain():
    message = "invalid setting: `n_flips` 5 is too few; see `tau_nci` and `alpha`, not `nope`"
    assert flag_names(message) == (
        "invalid setting: --flips 5 is too few; see --tau and --alpha, not `nope`"
    )
    assert (
        plain(message) == "invalid setting: n_flips 5 is too few; see tau_nci and alpha, not nope"
    )


def test_library_errors_carry_the_parameter():
    from credcli.engine.config import DiagnosisConfig
    from credcli.io.schema import ReadOptions
    from credcli.studies.settings import UwbSettings

    for make, name in (
        (lambda: DiagnosisConfig(alpha=2.0), "alpha"),
        (lambda: DiagnosisConfig(n_flips=5), "n_flips"),
        (lambda: ReadOptions(max_dt=-1.0), "max_dt"),
        (lambda: UwbSettings(min_anchors=2), "min_anchors"),
    ):
        with pytest.raises(CredcliError) as caught:
            make()
        assert caught.value.parameter == name and f"`{name}`" in caught.value.message


def _config(tmp_path, text: str) -> Path:
    path = tmp_path / "c.toml"
    path.write_text(text)
    return path


@pytest.mark.parametrize(
    ("table", "command", "flag", "expected"),
    [
        (
            "[diagnosis]\nalpha = 2.0",
            ["diagnose", LOG],
            ["--alpha", "2"],
            "alpha must be in (0, 1)",
        ),
        ("[input]\nmax_dt = -1.0", ["diagnose", LOG], ["--max-dt", "-1"], "max_dt must be > 0"),
        ("[uwb]\nmin_anchors = 2", ["uwb", GRID], ["--min-anchors", "2"], "min_anchors must be"),
        ("[simulate]\ntrials = 0", ["simulate"], ["--trials", "0"], "trials must be 1"),
        ("[gate]\nmax_anees_ratio = 0.5", ["gate", LOG, "-b", LOG], None, "max_anees_ratio"),
    ],
)
def test_a_bad_setting_names_its_source(tmp_path, table, command, flag, expected):
    """From a config file: the table and key; from the command line: the flag."""
    section = table.split("]")[0][1:]
    config = _config(tmp_path, table + "\n")
    line = error_line(*run(*command, "--config", config)[::2])
    assert f"config [{section}]: {expected}" in line, line
    if flag is not None:
        line = error_line(*run(*command, *flag)[::2])
        assert f"{flag[0]} " in line and expected.split(" ", 1)[1] in line, line
        assert "config" not in line


def _json(*args) -> dict:
    code, out, err = run(*args, "-f", "json")
    assert code == 0, err
    return json.loads(out)


def test_uwb_reads_its_settings_from_a_config_file(tmp_path):
    """[uwb] sets what the options set; an option overrides the file."""
    config = _config(tmp_path, "[uwb]\nscreen = false\nmax_speed = 0.15\nmin_static = 3.0\n")
    from_file = _json("uwb", GRID, "--config", config)
    from_flags = _json("uwb", GRID, "--screen", "none", "--max-speed", "0.15", "--min-static", "3")
    assert from_file == from_flags
    assert from_file["parameters"]["screen"] is False
    assert from_file["parameters"]["max_speed"] == 0.15
    overridden = _json("uwb", GRID, "--config", config, "--screen", "all")
    assert overridden["parameters"]["screen"] is True
    assert overridden["parameters"]["max_speed"] == 0.15


def test_gate_reads_its_thresholds_from_a_config_file(tmp_path):
    baseline = tmp_path / "b.json"
    assert run("baseline", LOG, "-o", baseline)[0] == 0
    gate = ("gate", REGRESSED, "-b", baseline, "-f", "json")
    strict = run(*gate)
    assert strict[0] == 1
    config = _config(tmp_path, "[gate]\nmax_nci_increase = 100.0\nmax_anees_ratio = 100.0\n")
    by_flags = run(*gate, "--max-nci-increase", "100", "--max-anees-ratio", "100")
    by_file = run(*gate, "--config", config)
    assert by_file == by_flags
    assert by_file[1] != strict[1]  # the thresholds took effect: fewer reasons to fail
    # the command line wins over the file
    assert (
        run(*gate, "--config", config, "--max-nci-increase", "1", "--max-anees-ratio", "1.25")
        == strict
    )
