"""Commands as declarations: option groups declared once, one settings merge (command line >
config file > defaults) for every command, and errors that name the parameter's source."""

from __future__ import annotations

import ast
import dataclasses
import functools
import inspect
import json
from pathlib import Path
from typing import Annotated

import pytest
import typer
from helpers import SAMPLE, error_line, run

from credcli.cli.app import app
from credcli.cli.edge import _flags, flag_names
from credcli.cli.options import GROUPS, RuleOptions, SegmentOptions, declare
from credcli.errors import NAMED, CredcliError, plain

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
    unknown = {
        m[1]: module
        for module, text in _message_strings()
        for m in NAMED.finditer(text)
        if m[1] not in flags
    }
    assert unknown == {}


@functools.cache
def _parsed(path: Path) -> ast.Module:
    """The syntax tree of a source file, parsed once for the checks below (read, never
    changed)."""
    return ast.parse(path.read_text())


def _message_strings():
    """(module, text) of every string constant outside cli/ that is not a docstring."""
    for path in (ROOT / "credcli").rglob("*.py"):
        if "cli" in path.parts:
            continue
        tree = _parsed(path)
        docstrings = {
            id(node.value)
            for node in ast.walk(tree)
            if isinstance(node, ast.Expr) and isinstance(node.value, ast.Constant)
        }
        for node in ast.walk(tree):
            if isinstance(node, ast.Constant) and isinstance(node.value, str):
                if id(node) not in docstrings:
                    yield path.name, node.value


def test_no_flag_is_spelled_below_the_command_line():
    """Issue 34 item 3: notes and messages below cli/ name parameters (```max_dt```), so
    that a Python caller reads its own arguments' names in ``log.notes``; the edge shows
    each as its flag. A flag spelled in the library would reach Python users as is."""
    import re

    flag = re.compile(r"(?<![\w-])--[a-z][a-z0-9-]+")
    spelled = {(module, m[0]) for module, text in _message_strings() for m in flag.finditer(text)}
    allowed = {("reports.py", "--fail-on")}  # JUnit files are a CI artefact of the CLI
    assert spelled - allowed == set()


def test_notes_name_parameters_in_python_and_flags_on_the_command_line(capsys):
    import credcli
    from credcli.cli import main

    estimate, truth = (
        ROOT / "sample_data/formats/odom_ros.csv",
        ROOT / "sample_data/formats/euroc_groundtruth.csv",
    )
    log = credcli.read_log(estimate, truth=truth, perturbation="right")
    paired = next(n for n in log.notes if n.startswith("paired"))
    assert "`max_dt` " in paired and "--max-dt" not in paired
    assert main(["diagnose", str(estimate), "--truth", str(truth), "--perturbation", "right"]) == 0
    err = capsys.readouterr().err
    assert "--max-dt " in err and "`max_dt`" not in err and "--states position" in err


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


LAZY_IMPORTS = {
    # optional extras: absent from a plain install
    "matplotlib": "the [plots] extra",
    "rosbags": "the [ros] extra",
    "dask": "the [dask] extra",
    "distributed": "the [dask] extra",
    "filterpy": "the [filterpy] extra",
    "stonesoup": "the [stonesoup] extra",
    "numba": "the [fast] extra; 0.3 s of CPU, loaded once a process has built many pairs",
    "credcli.adapters": "the adapters import the optional libraries",
    # heavy, and needed only by some paths
    "pandas": "0.2-0.4 s to import; only text tables, exports and frames need it",
    "pyarrow": "only Parquet files",
    "scipy": "scipy.special, .signal, .spatial and .stats only where used",
    "threadpoolctl": "only where worker processes limit BLAS threads",
    "multiprocessing": "only with worker processes (--jobs > 1)",
    "concurrent.futures": "only with worker processes (--jobs > 1)",
    "ctypes": "only to tune glibc's allocator when a command runs",
    # one of two, by version
    "tomllib": "Python >= 3.11; tomli before",
    "tomli": "Python < 3.11",
    "click": "the click package before typer vendored it",
    "typer._click": "typer >= 0.2x vendors click",
    # start-up: a command loads no numpy, Rich, tempfile or socket before it runs (`--help`
    # loads Rich, through Typer, to draw its panels)
    "numpy": "start-up: studies/settings.py holds the defaults --help shows",
    "rich": "start-up: tables and progress bars load Rich when they print",
}
"""Why a module may be imported inside a function: each is optional, heavy, or kept off
the start-up path. Every other import is at the top of its module (no hidden cycles)."""

START_UP = ("cli",)
"""Packages on the start-up path (every command and --help): they import credcli's own
numerical modules (settings, workflows, reports, files, cluster) inside the commands."""


def test_function_local_imports_are_lazy_for_a_stated_reason():
    found = {}
    for path in (ROOT / "credcli").rglob("*.py"):
        relative = path.relative_to(ROOT / "credcli")
        tree = _parsed(path)
        for function in ast.walk(tree):
            if not isinstance(function, (ast.FunctionDef, ast.AsyncFunctionDef)):
                continue
            for node in ast.walk(function):
                if isinstance(node, ast.ImportFrom):
                    names = [node.module or ""]
                elif isinstance(node, ast.Import):
                    names = [a.name for a in node.names]
                else:
                    continue
                for name in names:
                    allowed = any(name == m or name.startswith(m + ".") for m in LAZY_IMPORTS)
                    own = name.startswith("credcli") and relative.parts[0] in START_UP
                    if not (allowed or own):
                        found[f"{relative}:{node.lineno}"] = name
    assert found == {}


def _module_imports() -> dict[str, set[str]]:
    """credcli module -> the credcli modules it imports at its top level."""
    modules = {}
    for path in (ROOT / "credcli").rglob("*.py"):
        parts = path.relative_to(ROOT).with_suffix("").parts
        modules[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path
    graph: dict[str, set[str]] = {name: set() for name in modules}
    for name, path in modules.items():
        for node in _parsed(path).body:
            if isinstance(node, ast.ImportFrom) and (node.module or "").startswith("credcli"):
                for alias in node.names:
                    child = f"{node.module}.{alias.name}"
                    graph[name].add(child if child in modules else node.module)
            elif isinstance(node, ast.Import):
                graph[name] |= {a.name for a in node.names if a.name.startswith("credcli")}
    return graph


LAYERS = (
    ("credcli.errors", "credcli.version", "credcli.system", "credcli.logid"),
    ("credcli.engine",),
    ("credcli.io", "credcli.segments", "credcli.adapters"),
    ("credcli.schedule",),  # where work runs: plans, pool, cluster
    ("credcli.studies",),
    ("credcli.report", "credcli.ci", "credcli.requests"),
    ("credcli.workflows",),
    ("credcli.cli", "credcli.api", "credcli.testing"),
    ("credcli", "credcli.__main__"),
)
"""The house's floors, lowest first (issue 34): a module imports only from its own floor
or below, so data flows one way: cli → workflows → report/ci → studies → where work runs
→ io/segments → engine → errors."""


def _floor(module: str) -> int:
    owner = max(
        (
            name
            for floor in LAYERS
            for name in floor
            if module == name or module.startswith(name + ".")
        ),
        key=len,
    )
    return next(i for i, floor in enumerate(LAYERS) if owner in floor)


def test_imports_go_down_the_layers():
    """Every import of a credcli module, at the top, inside a function or under
    TYPE_CHECKING, goes to the importer's floor of :data:`LAYERS` or one below."""
    upward = []
    for path in (ROOT / "credcli").rglob("*.py"):
        parts = path.relative_to(ROOT).with_suffix("").parts
        name = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
        for node in ast.walk(_parsed(path)):
            if isinstance(node, ast.ImportFrom) and (node.module or "").startswith("credcli"):
                targets = [node.module]
                if node.module == "credcli":  # from credcli import x: the module x
                    targets = [f"credcli.{alias.name}" for alias in node.names]
            elif isinstance(node, ast.Import):
                targets = [a.name for a in node.names if a.name.startswith("credcli")]
            else:
                continue
            upward += [
                f"{name}:{node.lineno} -> {target}"
                for target in targets
                if _floor(target) > _floor(name)
            ]
    assert upward == []
    assert _floor("credcli.io.starloc") < _floor("credcli.studies.settings")  # read as meant


def test_no_import_cycles():
    graph = _module_imports()
    state: dict[str, int] = {}  # 1: on the path, 2: done
    cycles = []

    def visit(name: str, path: list[str]) -> None:
        state[name] = 1
        for other in sorted(graph.get(name, ())):
            if state.get(other) == 1:
                cycles.append(path[path.index(other) :] + [other])
            elif other not in state:
                visit(other, path + [other])
        state[name] = 2

    for name in sorted(graph):
        if name not in state:
            visit(name, [name])
    assert cycles == []
    assert "credcli.engine.elt" in graph["credcli.engine.diagnosis"]  # the graph is read


READER_ENGINE = {
    "credcli.engine.linalg",  # the one validation of a covariance, chunks of epochs
    "credcli.engine.config",  # the names of choices (States, Perturbation, Alignment)
    "credcli.engine.lie",  # the errors of a pose: SO(3)/SE(3) differences
    "credcli.engine.align",  # Umeyama's alignment of an estimate onto its truth
}
"""What the readers (credcli.io) may use of the engine: validation, names, and the geometry
that turns two trajectories into errors; no test, scale or diagnosis (issue 34, item 1)."""


def test_readers_only_read():
    used = {
        f"{name} -> {target}"
        for name, targets in _all_imports().items()
        if name.startswith("credcli.io")
        for target in targets
        if target.startswith("credcli.engine") and target not in READER_ENGINE
    }
    assert used == set()


RECORDS_MODULE = "credcli/report/records.py"
"""The only module that knows the keys of credcli's JSON (issue 34, item 2)."""

KEYED_PLACES = (
    "credcli/report",
    "credcli/ci",
    "credcli/cli",
    "credcli/workflows.py",
    "credcli/api.py",
    "credcli/testing.py",
)
"""Where records are built, rendered, gated and handed to users: above the engine, which
knows no JSON keys at all (STYLE.md), and the readers, whose keys are a file's columns."""

NOT_RECORD_KEYS = {
    ("credcli/cli/settings.py", "*"): "the TOML config file's tables and settings: "
    "configuration read in (and the typed settings built from it), not a record written",
    ("credcli/report/plots.py", "*"): "Plot.data, the numbers a figure drew, handed to "
    "Python callers, and matplotlib's keyword dicts; no JSON document holds them",
    ("credcli/ci/gate.py", "columns"): "the config's [columns] table, by name",
    ("credcli/ci/gate.py", "input"): "the config's [input] table, by name",
    ("credcli/cli/app.py", "--*"): "an output path by the flag that gave it, for the guard "
    "that no output overwrites an input",
    ("credcli/cli/emit.py", "GITHUB_STEP_SUMMARY"): "the step summary's path among the "
    "outputs the guard checks",
    **{
        ("credcli/cli/options.py", field): "a settings field by the option that sets it "
        "(FIELD_OPTIONS)"
        for field in ("tau_nci", "n_flips", "c", "time", "segment")
    },
    ("credcli/cli/options.py", "return"): "a function's annotations",
    **{
        ("credcli/report/advice.py", condition): "LOCATION_MEANING, keyed by a label's "
        "location condition: a label's value, not a key"
        for condition in ("bias", "asymmetric")
    },
    **{
        ("credcli/report/html.py", label): "LABEL_COLOURS, keyed by a label's value"
        for label in ("credible", "insufficient-data")
    },
    **{
        ("credcli/report/render.py", status): "the Rich style of a gate's status cell, keyed "
        "by its value"
        for status in ("regressed", "improved", "unchanged")
    },
    ("credcli/api.py", "truth"): "read_log's keyword options (ReadOptions fields)",
    ("credcli/api.py", "window"): "the segmenter's settings by their Python name (errors)",
    ("credcli/api.py", "whole"): "the segmenter's settings by their Python name (errors)",
    ("credcli/api.py", "text/html"): "IPython's display formatter of a MIME type",
    ("credcli/api.py", "truth_columns"): "LogSchema fields, given to LogSchema.updated",
    ("credcli/api.py", "estimate_columns"): "LogSchema fields, given to LogSchema.updated",
    ("credcli/api.py", "cov_columns"): "LogSchema fields, given to LogSchema.updated",
    ("credcli/testing.py", "errors"): "diagnose's keyword arguments",
    ("credcli/testing.py", "cov"): "diagnose's keyword arguments",
}
"""String keys in KEYED_PLACES that name no JSON record key, each with why: (module, key),
or (module, "*") for a module whose string keys are all of another kind (the config file,
the figures' data), or "--*" for command-line flags. Every entry must still be needed."""


NOT_MAPPINGS_OF_RECORDS = ("os.environ", "sys.modules")
"""Mappings whose keys are never record keys: environment variables, imported modules."""


def literal_keys(tree: ast.AST):
    """(line, how, key) of each string literal a module uses as a mapping's key: a
    subscript ``x["key"]``, ``x.get("key")`` (and ``pop``, ``setdefault``), a dict display's
    key ``{"key": ...}`` and a table column ``Column("key", ...)``. Reads of ``os.environ``
    and ``sys.modules`` (environment variables, imported modules) are not of records."""
    for node in ast.walk(tree):
        if isinstance(node, ast.Subscript):
            if ast.unparse(node.value) in NOT_MAPPINGS_OF_RECORDS:
                continue
            key, how = node.slice, "subscript"
        elif isinstance(node, ast.Call) and node.args:
            func = node.func
            name = func.attr if isinstance(func, ast.Attribute) else getattr(func, "id", "")
            if name not in ("get", "pop", "setdefault", "Column"):
                continue
            if (
                isinstance(func, ast.Attribute)
                and ast.unparse(func.value) in NOT_MAPPINGS_OF_RECORDS
            ):
                continue
            key, how = node.args[0], name
        elif isinstance(node, ast.Dict):
            for key in node.keys:
                if isinstance(key, ast.Constant) and isinstance(key.value, str):
                    yield key.lineno, "dict", key.value
            continue
        else:
            continue
        if isinstance(key, ast.Constant) and isinstance(key.value, str):
            yield node.lineno, how, key.value


def _exemptions(path: str, key: str) -> list[tuple[str, str]]:
    """The entries of NOT_RECORD_KEYS that exempt ``key`` in ``path``."""
    patterns = ("*", key, "--*") if key.startswith("--") else ("*", key)
    return [(path, p) for p in patterns if (path, p) in NOT_RECORD_KEYS]


def test_only_records_name_json_keys():
    """JSON keys are spelled in credcli/report/records.py only: the builders, renderers,
    the gate, the commands and the API use its functions, columns and constants (issue 34:
    results typed until the last moment). A string key elsewhere is either a record key
    (move it to records) or listed in NOT_RECORD_KEYS with why it is not one."""
    found, used = [], set()
    for place in KEYED_PLACES:
        paths = [ROOT / place] if place.endswith(".py") else (ROOT / place).rglob("*.py")
        for path in sorted(paths):
            rel = path.relative_to(ROOT).as_posix()
            if rel == RECORDS_MODULE:
                continue
            for line, how, key in literal_keys(_parsed(path)):
                exemptions = _exemptions(rel, key)
                used.update(exemptions)
                if not exemptions:
                    found.append(f"{rel}:{line} {how} {key!r}")
    assert found == []
    assert used == set(NOT_RECORD_KEYS)  # every exemption is still needed
    keys = {key for _, _, key in literal_keys(_parsed(ROOT / RECORDS_MODULE))}
    assert {"scale_factor", "segments", "parameters", "published", "status"} <= keys  # read


def test_renderers_only_format():
    """The renderers format a Report: no study, segmentation, reader or diagnosis is
    imported by render.py (or tables.py); the builders make the Report from them."""
    imports = _all_imports()
    allowed = ("credcli.errors", "credcli.engine.config", "credcli.report.")
    for name in ("credcli.report.render", "credcli.report.tables"):
        assert imports[name], name  # read
        outside = {t for t in imports[name] if t != "credcli.report" and not t.startswith(allowed)}
        assert outside == set(), name
    assert "credcli.report.builders" not in imports["credcli.report.render"]


def _all_imports() -> dict[str, set[str]]:
    """credcli module -> every credcli module it imports (anywhere in it), by module name."""
    out = {}
    for path in (ROOT / "credcli").rglob("*.py"):
        parts = path.relative_to(ROOT).with_suffix("").parts
        name = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
        targets = set()
        for node in ast.walk(_parsed(path)):
            if isinstance(node, ast.ImportFrom) and (node.module or "").startswith("credcli"):
                base = node.module
                targets |= {
                    f"{base}.{a.name}" if base == "credcli.engine" else base for a in node.names
                }
            elif isinstance(node, ast.Import):
                targets |= {a.name for a in node.names if a.name.startswith("credcli")}
        out[name] = targets
    return out
