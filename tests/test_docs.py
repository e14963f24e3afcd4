"""The documentation renders: no raw Sphinx roles in the API reference, no dead relative
link in docs/ or the README, and every command's --help in panels with examples.

Nothing is built: the docstrings are read as mkdocstrings reads them (griffe), the links
against the files and headings they name, the help in-process.
"""

from __future__ import annotations

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
