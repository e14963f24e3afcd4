"""The documentation renders: no raw Sphinx roles in the API reference, no dead relative
link in docs/ or the README, every command's --help in panels with examples, and every
public docstring in numpydoc form.

Nothing is built: the docstrings are read as mkdocstrings reads them (griffe), the links
against the files and headings they name, the help in-process.
"""

from __future__ import annotations

import ast
import re
import unicodedata
from pathlib import Path

import pytest
from helpers import ROOT

from credcli.cli.edge import app_commands, main

ROLE = re.compile(r":(func|class|attr|mod|meth|data|obj):`")
LINK = re.compile(r"\]\(([^)\s]+)\)")
FENCE = re.compile(r"^(```|~~~).*?^\1", re.M | re.S)
PANEL = re.compile(r"^╭─ (.+?) ─", re.M)
PAGES = sorted((ROOT / "docs").glob("*.md")) + [ROOT / "README.md"]


def rendered_objects(reference: Path):
    """Every object docs/reference.md renders: its ``::: credcli...`` targets and their
    public members, chosen as mkdocstrings-python does with the site's options (names
    not starting with '_', a docstring, not inherited, imported ones only if public)."""
    griffe = pytest.importorskip("griffe", reason="the docs extra (mkdocstrings) reads docstrings")
    package = griffe.load("credcli", search_paths=[str(ROOT)], docstring_parser="numpy")
    seen: set[str] = set()

    def walk(obj):
        if obj.path in seen:
            return
        seen.add(obj.path)
        yield obj
        target = obj.final_target if obj.is_alias else obj
        for name, member in target.members.items():
            if name.startswith("_") or member.inherited or not member.has_docstrings:
                continue
            if member.is_module or (member.is_imported and not member.is_public):
                continue  # submodules are not shown; imports only when exported
            yield from walk(member)

    for path in re.findall(r"^::: (credcli\S*)", reference.read_text(), re.M):
        yield from walk(
            package[path.removeprefix("credcli").lstrip(".")] if "." in path else package
        )


def raw_roles(objects) -> list[str]:
    """'object: line' for each Sphinx role left in a docstring (mkdocstrings shows them raw)."""
    return [
        f"{obj.path}: {line.strip()}"
        for obj in objects
        if obj.docstring is not None
        for line in obj.docstring.value.splitlines()
        if ROLE.search(line)
    ]


def slug(heading: str) -> str:
    """A heading's anchor as mkdocs makes it (Python-Markdown's toc slugify): the text
    without Markdown code marks, ASCII, punctuation dropped, lower case, spaces to '-'."""
    text = unicodedata.normalize("NFKD", heading.replace("`", "")).encode("ascii", "ignore")
    text = re.sub(r"[^\w\s-]", "", text.decode()).strip().lower()
    return re.sub(r"[-\s]+", "-", text)


def anchors(page: Path) -> set[str]:
    text = FENCE.sub("", page.read_text())
    return {slug(h) for h in re.findall(r"^#{1,6}\s+(.+?)\s*#*$", text, re.M)}


def dead_links(pages) -> list[str]:
    """'page: target' for each relative link whose file, or heading, does not exist."""
    dead = []
    for page in pages:
        for target in LINK.findall(FENCE.sub("", page.read_text())):
            if re.match(r"[a-z]+:", target):
                continue  # http:, https:, mailto:
            path, _, anchor = target.partition("#")
            file = (page.parent / path).resolve() if path else page
            if not file.exists():
                dead.append(f"{page.name}: {target} (no such file)")
            elif anchor and file.suffix == ".md" and anchor not in anchors(file):
                dead.append(f"{page.name}: {target} (no such heading in {file.name})")
    return dead


def help_text(command: str, capsys) -> str:
    assert main([command, "--help"]) == 0
    return capsys.readouterr().out


def test_the_api_reference_shows_no_raw_sphinx_role():
    objects = list(rendered_objects(ROOT / "docs" / "reference.md"))
    assert len(objects) > 50  # the targets and their members were found
    assert raw_roles(objects) == []


def test_a_role_in_a_rendered_docstring_is_found(tmp_path):
    griffe = pytest.importorskip("griffe")
    module = tmp_path / "credcli_role_probe.py"
    module.write_text('def f():\n    """See :func:`g`."""\n')
    probe = griffe.load("credcli_role_probe", search_paths=[str(tmp_path)])
    assert raw_roles([probe["f"]]) == ["credcli_role_probe.f: See :func:`g`."]


def test_relative_links_in_the_docs_and_readme_reach_a_file_and_heading():
    assert dead_links(PAGES) == []


def test_a_dead_link_or_anchor_is_found(tmp_path):
    (tmp_path / "there.md").write_text("# A page\n\n## The `calibrated` rule: step 5\n")
    page = tmp_path / "page.md"
    page.write_text(
        "[ok](there.md#the-calibrated-rule-step-5) [gone](missing.md) "
        "[bad](there.md#no-such) [web](https://example.org/x.md)\n```\n[code](nope.md)\n```\n"
    )
    assert dead_links([page]) == [
        "page.md: missing.md (no such file)",
        "page.md: there.md#no-such (no such heading in there.md)",
    ]


@pytest.mark.parametrize("command", sorted(app_commands()))
def test_every_command_help_has_panels_and_examples(command, capsys):
    text = help_text(command, capsys)
    panels = set(PANEL.findall(text)) - {"Arguments", "Options"}
    assert len(panels) >= 2, f"credcli {command} --help: panels {sorted(panels)}"
    assert "Example" in text


SECTION = re.compile(r"^(\w[\w ]*)\n-{3,}$", re.M)
ITEM = re.compile(r"^\*{0,2}(\w+(?:\s*,\s*\*{0,2}\w+)*)\s*(?::|$)")
FIELDS = ("Attributes", "Parameters")  # a dataclass documents its fields in either


def sections(doc: str) -> dict[str, set[str]]:
    """A numpydoc docstring's sections, each with the names its items give at the
    section's own indent ('a, b : int' gives both)."""
    heads = list(SECTION.finditer(doc))
    out = {}
    for head, nxt in zip(heads, [*heads[1:], None], strict=False):
        body = doc[head.end() : nxt.start() if nxt else len(doc)]
        names = set()
        for line in body.splitlines():
            item = ITEM.match(line) if line and not line[0].isspace() else None
            if item:
                names |= {n.strip().lstrip("*") for n in item.group(1).split(",")}
        out[head.group(1)] = names
    return out


def _decorators(node) -> set[str]:
    return {ast.unparse(d).split("(")[0].split(".")[-1] for d in node.decorator_list}


def _function_gaps(fn, where: str) -> list[str]:
    if {"property", "cached_property", "overload"} & _decorators(fn):
        return []
    doc = ast.get_docstring(fn)
    if not doc:
        return [f"{where}: no docstring"]
    found = sections(doc)
    args = fn.args
    names = [a.arg for a in args.posonlyargs + args.args + args.kwonlyargs]
    names += [a.arg for a in (args.vararg, args.kwarg) if a is not None]
    names = [n for n in names if n not in ("self", "cls")]
    gaps = []
    if names:
        missing = [n for n in names if n not in found.get("Parameters", set())]
        if missing:
            gaps.append(f"{where}: Parameters lacks {', '.join(missing)}")
    returns = fn.returns is not None and ast.unparse(fn.returns) not in ("None", "NoReturn")
    if returns and not {"Returns", "Yields"} & found.keys():
        gaps.append(f"{where}: no Returns section")
    return gaps


def _class_gaps(cls, where: str) -> list[str]:
    doc = ast.get_docstring(cls)
    if not doc:
        return [f"{where}: no docstring"]
    if not ({"dataclass", "NamedTuple"} & (_decorators(cls) | {ast.unparse(b) for b in cls.bases})):
        return []
    fields = [
        s.target.id
        for s in cls.body
        if isinstance(s, ast.AnnAssign)
        and isinstance(s.target, ast.Name)
        and not s.target.id.startswith("_")
        and "ClassVar" not in ast.unparse(s.annotation)
    ]
    documented = set().union(*(sections(doc).get(k, set()) for k in FIELDS))
    missing = [f for f in fields if f not in documented]
    return [f"{where}: Attributes lacks {', '.join(missing)}"] if missing else []


def numpydoc_gaps(paths, root: Path = ROOT) -> list[str]:
    """'file:line name: what is missing' for each public definition in ``paths`` whose
    docstring is not in numpydoc form: a public function names every parameter under
    Parameters and, if it returns a value, has Returns (or Yields); a public dataclass or
    NamedTuple names every field under Attributes (or Parameters). Properties, overloads
    and the CLI's command functions (their docstrings are --help text) are exempt."""
    gaps = []
    for path in paths:
        tree = ast.parse(path.read_text())
        rel = path.relative_to(root)
        for node in tree.body:
            if getattr(node, "name", "_").startswith("_"):
                continue
            where = f"{rel}:{node.lineno} {node.name}"
            if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
                if path.parent.name != "cli" or "declare" not in _decorators(node):
                    gaps += _function_gaps(node, where)
            elif isinstance(node, ast.ClassDef):
                gaps += _class_gaps(node, where)
                for member in node.body:
                    if isinstance(member, ast.FunctionDef) and not member.name.startswith("_"):
                        gaps += _function_gaps(member, f"{where}.{member.name}")
    return gaps


def test_public_docstrings_are_numpydoc():
    gaps = numpydoc_gaps(sorted((ROOT / "credcli").rglob("*.py")))
    assert not gaps, f"{len(gaps)} public docstrings not in numpydoc form:\n" + "\n".join(gaps)


def test_a_docstring_gap_is_found(tmp_path):
    module = tmp_path / "credcli" / "m.py"
    module.parent.mkdir()
    module.write_text(
        '''
from dataclasses import dataclass

def good(a, b=1):
    """Sum.

    Parameters
    ----------
    a, b : int
        The terms.

    Returns
    -------
    int
    """
    return a + b

def bad(a, *, c) -> int:
    """Sum.

    Parameters
    ----------
    a : int
        Only this one.
    """

@dataclass
class Point:
    """A point.

    Attributes
    ----------
    x : float
    """

    x: float
    y: float
'''
    )
    gaps = [g.split(" ", 1)[1] for g in numpydoc_gaps([module], tmp_path)]
    assert gaps == [
        "bad: Parameters lacks c",
        "bad: no Returns section",
        "Point: Attributes lacks y",
    ]


def test_every_exported_name_is_on_the_reference_page():
    """Each name ``credcli`` exports (its lazy ``_EXPORTS``) is rendered by
    docs/reference.md, under its own module or the one that defines it."""
    import importlib

    import credcli

    rendered = set()
    for obj in rendered_objects(ROOT / "docs" / "reference.md"):
        rendered.add(obj.path)
        if obj.is_alias:
            rendered.add(obj.final_target.path)
    missing = []
    for name, module in credcli._EXPORTS.items():
        value = getattr(importlib.import_module(module), name)
        home = f"{value.__module__}.{value.__qualname__}"
        if not {f"{module}.{name}", home} & rendered:
            missing.append(name)
    assert missing == []
