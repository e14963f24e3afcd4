"""Reports for CI pages: JUnit XML (one test case per segment) and Markdown summaries."""

from __future__ import annotations

import os
import re
import stat
import xml.etree.ElementTree as ET
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path

from credcli.engine.short import SegmentResults, ShortSegments
from credcli.errors import CredcliError
from credcli.report.records import json_value, shown_label
from credcli.report.render import OutputFormat, format_cell, markdown_text, to_text


@dataclass(frozen=True)
class Case:
    """One JUnit test case: a segment, and why it failed (None when it passed).

    Attributes
    ----------
    name : str
        The test case's name: the segment's name.
    classname : str
        The test case's class: the command and the log's stem
        (``credcli.diagnose.<stem>``, ``credcli.gate.<stem>``: the command, then the log).
    failure : str or None
        Why it failed, the failure's message; None when it passed.
    details : str, default ""
        More text: the failure's body, or the passing case's ``system-out``.
    """

    name: str
    classname: str
    failure: str | None
    details: str = ""


_NOT_XML = re.compile("[^\t\n\r\x20-\ud7ff\ue000-\ufffd\U00010000-\U0010ffff]")


def xml_text(text: str) -> str:
    r"""``text`` with the characters XML 1.0 forbids written as ``#xNN``.

    Those are most C0 controls, lone surrogates and U+FFFE/U+FFFF; pytest writes them
    the same way, and the document stays valid.

    Parameters
    ----------
    text : str
        A name or message from the data.

    Returns
    -------
    str
        ``text`` with each forbidden character replaced.

    Examples
    --------
    >>> xml_text("run\x07 1\tok")
    'run#x07 1\tok'
    """
    return _NOT_XML.sub(lambda m: f"#x{ord(m.group()):02X}", text)


@dataclass(frozen=True)
class CaseBatch:
    """JUnit test cases that differ only in their names (a run of segments too short for
    a verdict, :class:`credcli.engine.short.ShortSegments`): one :class:`Case` per name.

    Attributes
    ----------
    names : sequence of str
        The cases' names.
    classname, failure, details
        What every case has, as a :class:`Case`.
    """

    names: Sequence[str]
    classname: str
    failure: str | None
    details: str = ""

    def __len__(self) -> int:
        return len(self.names)

    def __iter__(self) -> Iterator[Case]:
        for name in self.names:
            yield Case(name, self.classname, self.failure, self.details)


def junit_xml(suite: str, cases: list[Case | CaseBatch]) -> str:
    """A JUnit XML document with one <testsuite>; failures carry their reason.

    Names and messages from the data pass through :func:`xml_text`.

    Parameters
    ----------
    suite : str
        The test suite's name.
    cases : list of Case or CaseBatch
        The test cases, in order.

    Returns
    -------
    str
        The indented XML document, with its declaration and a final newline.

    Examples
    --------
    >>> cases = [Case("cruise", "credcli.diagnose.log", None), Case("urban", "x", "bias")]
    >>> print(junit_xml("log", cases).splitlines()[1])
    <testsuites name="credcli" tests="2" failures="1">
    """
    return "".join(junit_pieces(suite, cases))


def junit_pieces(suite: str, cases: list[Case | CaseBatch]) -> Iterator[str]:
    """:func:`junit_xml` in pieces, the cases a few thousand at a time: the document is
    ElementTree's (indented by ``ET.indent``) around a placeholder case, each case
    ElementTree's at its depth, and a batch's cases one case's text with each name in it
    (10⁶ one-epoch segments are not 10⁶ elements in one tree).

    Parameters
    ----------
    suite : str
        The test suite's name.
    cases : list of Case or CaseBatch
        The test cases, in order.

    Yields
    ------
    str
        Consecutive pieces of the document.
    """
    sizes = [len(c) if isinstance(c, CaseBatch) else 1 for c in cases]
    tests = sum(sizes)
    failures = sum(n for c, n in zip(cases, sizes) if c.failure is not None)
    root = ET.Element("testsuites", name="credcli", tests=str(tests), failures=str(failures))
    node = ET.SubElement(
        root,
        "testsuite",
        name=xml_text(suite),
        tests=str(tests),
        failures=str(failures),
        errors="0",
        skipped="0",
    )
    header = '<?xml version="1.0" encoding="UTF-8"?>\n'
    if not tests:
        ET.indent(root)
        yield header + ET.tostring(root, encoding="unicode") + "\n"
        return
    ET.SubElement(node, "testcase")  # where the cases go
    ET.indent(root)
    head, tail = ET.tostring(root, encoding="unicode").split("<testcase />")
    between = head[head.rindex("\n") :]  # a case's indent, as ET.indent makes it
    yield header + head
    before = ""
    for texts in _case_texts(cases):
        yield before + between.join(texts)
        before = between
    yield tail + "\n"


CASE_LEVEL = 2
"""The depth of a test case in the document (testsuites, testsuite, testcase)."""


def _case_element(case: Case, name: str) -> ET.Element:
    """A case's element, indented at its depth, named ``name`` (as the document writes it)."""
    tc = ET.Element("testcase", name=name, classname=xml_text(case.classname))
    if case.failure is not None:
        message = xml_text(case.failure)
        fail = ET.SubElement(tc, "failure", message=message, type="CredibilityRegression")
        fail.text = xml_text(case.details or case.failure)
    elif case.details:
        ET.SubElement(tc, "system-out").text = xml_text(case.details)
    ET.indent(tc, level=CASE_LEVEL)
    return tc


def _case_text(case: Case) -> str:
    return ET.tostring(_case_element(case, xml_text(case.name)), encoding="unicode")


CASES_AT_ONCE = 4096
"""Cases of a batch written at a time."""

_PLACEHOLDER = "\ue000"
"""A name no case has, where a batch's template takes each name (a private-use character,
which XML allows and ElementTree writes as it is)."""

_ATTRIBUTE_ESCAPED = frozenset('&<>"\r\n\t')
"""Characters ElementTree may write otherwise in an attribute value."""


def _case_texts(cases) -> Iterator[list[str]]:
    """The text of each case in lists of consecutive cases; a batch's from its first
    case's text with each name in its place."""
    singles: list[str] = []
    for case in cases:
        if not isinstance(case, CaseBatch):
            singles.append(_case_text(case))
            continue
        if singles:
            yield singles
            singles = []
        template = ET.tostring(_case_element(next(iter(case)), _PLACEHOLDER), encoding="unicode")
        parts = template.split(_PLACEHOLDER)
        for start in range(0, len(case), CASES_AT_ONCE):
            names = case.names[start : start + CASES_AT_ONCE]
            if len(parts) != 2:  # the placeholder is in the case's own text: case by case
                yield [
                    _case_text(Case(n, case.classname, case.failure, case.details)) for n in names
                ]
                continue
            joined = "".join(names)
            if _NOT_XML.search(joined) or not _ATTRIBUTE_ESCAPED.isdisjoint(joined):
                names = list(map(_attribute_text, names))
            yield [parts[0] + name + parts[1] for name in names]
    if singles:
        yield singles


def _attribute_text(name: str) -> str:
    """A case's name as the document writes it in its attribute (:func:`xml_text`, then
    ElementTree's escapes)."""
    text = ET.tostring(ET.Element("a", v=xml_text(name)), encoding="unicode")
    return text[len('<a v="') : -len('" />')]


def check_step_summary(path: str) -> None:
    """Check that $GITHUB_STEP_SUMMARY is a regular file or a new one (GitHub's always is).

    A FIFO with no reader would block the run forever, a device is not a summary, and a
    symbolic link would send the summary to the file it points to.

    Parameters
    ----------
    path : str
        The value of $GITHUB_STEP_SUMMARY.

    Raises
    ------
    CredcliError
        If ``path`` exists and is a symbolic link or not a regular file, or cannot be
        examined.
    """
    try:
        mode = os.lstat(path).st_mode
    except FileNotFoundError:
        return
    except OSError as exc:
        raise CredcliError(f"GITHUB_STEP_SUMMARY={path}: {exc.strerror}") from exc
    if stat.S_ISLNK(mode):
        raise CredcliError(
            f"GITHUB_STEP_SUMMARY={path}: is a symbolic link; credcli does not write through "
            "links (GitHub's summary file never is one)"
        )
    if not stat.S_ISREG(mode):
        raise CredcliError(
            f"GITHUB_STEP_SUMMARY={path}: not a regular file; the job summary is appended "
            "to a file (unset the variable outside GitHub Actions)"
        )


def summary_wanted(summary: Path | None) -> bool:
    """Whether a CI run's Markdown summary is written: to ``summary`` (``--summary``), or
    to $GITHUB_STEP_SUMMARY when that is set (:func:`append_step_summary`).

    Parameters
    ----------
    summary : Path or None
        ``--summary``.

    Returns
    -------
    bool
        True where the summary, which shows the report's tables, is read.
    """
    return summary is not None or bool(os.environ.get("GITHUB_STEP_SUMMARY"))


def append_step_summary(markdown: str) -> None:
    """Append to $GITHUB_STEP_SUMMARY when it is set (GitHub Actions' job summary).

    Nothing happens when the variable is unset or empty.

    Parameters
    ----------
    markdown : str
        The summary; a final newline is added when it has none.

    Raises
    ------
    CredcliError
        If the file is not a regular one (:func:`check_step_summary`) or cannot be
        appended to.
    """
    path = os.environ.get("GITHUB_STEP_SUMMARY")
    if not path:
        return
    check_step_summary(path)
    flags = os.O_WRONLY | os.O_APPEND | os.O_CREAT | getattr(os, "O_NOFOLLOW", 0)
    try:  # never through a link planted at the name after the check
        with os.fdopen(os.open(path, flags, 0o666), "a", encoding="utf-8") as fh:
            fh.write(markdown if markdown.endswith("\n") else markdown + "\n")
    except OSError as exc:
        raise CredcliError(
            f"GITHUB_STEP_SUMMARY={path}: cannot append the summary: {exc.strerror}"
        ) from exc


def gate_cases(comparisons, thresholds, log: str) -> list[Case]:
    """One JUnit case per segment the gate compared.

    Parameters
    ----------
    comparisons : list of SegmentComparison
        The gate's comparisons (``credcli.ci.gate.compare``).
    thresholds : Thresholds
        The gate's thresholds (whether new or missing segments fail).
    log : str
        The log's path or name; its stem names the cases' class
        (``credcli.gate.<stem>``, as ``credcli.diagnose.<stem>`` for diagnose).

    Returns
    -------
    list of Case
        In the order of ``comparisons``; a failing case's message is its reasons, every
        case's details its reasons and improvements.
    """
    cases = []
    for c in comparisons:
        failed = c.failed_with(thresholds)
        details = "; ".join(c.reasons + c.improvements)
        cases.append(
            Case(
                c.segment,
                f"credcli.gate.{_classname(os.path.splitext(os.path.basename(log))[0])}",
                "; ".join(c.reasons) if failed else None,
                details,
            )
        )
    return cases


def fail_on_cases(results, failing: list[int], fail_on) -> list[Case | CaseBatch]:
    """One JUnit case per diagnosed segment (:class:`credcli.engine.diagnosis.SegmentDiagnosis`),
    a run of segments too short for a verdict one :class:`CaseBatch`.

    Parameters
    ----------
    results : SegmentResults or sequence of SegmentDiagnosis or SegmentVerdict
        The diagnosed segments, or what was kept of them (their ``verdict()``), in order.
    failing : list of int
        The indices of the failing ones.
    fail_on : FailOn
        The conditions they failed on.

    Returns
    -------
    list of Case or CaseBatch
        In the order of ``results``, classed by their log's stem
        (``credcli.diagnose.<stem>``); the details give the label, ELT p-value, NCI and
        ANEES.
    """
    bad = set(failing)
    listed = str(fail_on)
    cases: list[Case | CaseBatch] = []
    k = 0
    for part in results.parts if isinstance(results, SegmentResults) else results:
        if not isinstance(part, ShortSegments):
            cases.append(_fail_on_case(part.verdict(), k in bad, listed))
            k += 1
            continue
        failed = {i in bad for i in range(k, k + len(part))}
        if len(failed) == 1:  # one case's text with each name
            case = _fail_on_case(part[0].verdict(), failed.pop(), listed)
            cases.append(CaseBatch(part.names, case.classname, case.failure, case.details))
        else:
            cases.extend(
                _fail_on_case(r.verdict(), i in bad, listed) for i, r in enumerate(part, start=k)
            )
        k += len(part)
    return cases


def _fail_on_case(verdict, failed: bool, listed: str) -> Case:
    label = shown_label(verdict.label, verdict.untested)
    return Case(
        verdict.segment,
        f"credcli.diagnose.{_classname(verdict.log.stem)}",
        f"label {label} matches --fail-on {listed}" if failed else None,
        f"label {label}, ELT p {_cell(verdict.elt_pvalue)}, NCI {_cell(verdict.nci)} dB, "
        f"ANEES {_cell(verdict.anees)}",
    )


def _cell(value) -> str:
    return format_cell(json_value(value), 3)


def _classname(stem: str) -> str:
    """A JUnit class name from a log's stem (unique among the logs of one command)."""
    return "".join(ch if ch.isalnum() or ch in "_-" else "_" for ch in stem) or "log"


def summary_markdown(heading: str, verdict: str, report, context: str = "") -> str:
    """The Markdown summary of a CI run.

    A heading, the verdict in bold, the context if any, then the report's own tables (the
    same ones the other output formats show).

    Parameters
    ----------
    heading : str
        The section's heading (a level-2 Markdown heading).
    verdict : str
        The one-line verdict.
    report : Report
        The command's report, rendered as ``--format markdown`` renders it.
    context : str, default ""
        A line between the verdict and the tables (the baseline and thresholds); none
        when empty.

    Returns
    -------
    str
        The Markdown text; every text from the data is escaped.
    """
    parts = [f"## {markdown_text(heading)}", "", f"**{markdown_text(verdict)}**", ""]
    if context:
        parts += [markdown_text(context), ""]
    parts.append(to_text(report, OutputFormat.MARKDOWN))
    return "\n".join(parts)
