"""One self-contained HTML file: the tables, the parameters and the plots as data URIs.

No script, no stylesheet link, no font or image fetched: it opens offline and can be
attached to a CI run.
"""

from __future__ import annotations

import base64
import html
import json
import math
import re

from credcli.engine.config import Label
from credcli.engine.diagnosis import SegmentDiagnosis
from credcli.errors import printable
from credcli.report.advice import advice, bias_size, scale_text
from credcli.report.overview import FILE_STEMS, PlotKind
from credcli.report.plots import segment_group
from credcli.report.records import (
    SEGMENT_COLUMNS,
    document_parameters,
    document_segments,
    document_version,
    segment_record,
    shown_label,
)
from credcli.report.render import format_cell
from credcli.report.tables import Report, Table

_STYLE = """
body { font-family: system-ui, -apple-system, "Segoe UI", sans-serif; margin: 2em auto;
       max-width: 1100px; color: #222; padding: 0 1em; }
h1 { font-size: 1.6em; } h2 { font-size: 1.25em; margin-top: 2em; border-bottom: 1px solid #ddd; }
table { border-collapse: collapse; margin: 0.5em 0 1em; font-size: 0.9em; }
th, td { border: 1px solid #ccc; padding: 0.25em 0.6em; text-align: right; }
th { background: #f3f3f3; } td.text, th.text { text-align: left; }
.credible { color: #176f2c; font-weight: 600; } .bad { color: #a33a00; font-weight: 600; }
figure { margin: 1em 0; } figure img { max-width: 100%; border: 1px solid #eee; }
figcaption { font-size: 0.85em; color: #555; } pre { background: #f7f7f7; padding: 0.8em;
overflow-x: auto; font-size: 0.8em; } .note { color: #555; font-size: 0.9em; }
h3 { font-size: 1.05em; margin-top: 1.5em; }
.figs { display: grid; grid-template-columns: repeat(auto-fill, minmax(460px, 1fr));
        gap: 0 1.2em; }
nav ul { margin: 0.3em 0; } nav li { margin: 0.1em 0; } nav ul ul { font-size: 0.92em; }
.counts span { display: inline-block; margin: 0 1em 0.3em 0; }
"""


def _escape(text) -> str:
    """Text for HTML: markup characters escaped, and control characters from the data
    (a segment name's ESC or BEL) shown as their backslash escapes."""
    return html.escape(printable(str(text)))


LABEL_COLOURS = {"credible": "#176f2c", "insufficient-data": "#666666"}
"""A label's colour in HTML (every other label, a misfit: :data:`MISFIT_COLOUR`)."""
MISFIT_COLOUR = "#a33a00"


def label_style(value: str) -> str:
    """The inline style of a label cell: its colour stays where a page's stylesheet is
    dropped (a notebook viewer, a mail).

    Parameters
    ----------
    value : str
        The label as shown; a partial verdict (``"credible (scale untested)"``) is
        coloured as its answered label.

    Returns
    -------
    str
        A CSS declaration: the colour of :data:`LABEL_COLOURS` (:data:`MISFIT_COLOUR` for
        a misfit), in bold.

    Examples
    --------
    >>> label_style("credible (scale untested)")
    'color: #176f2c; font-weight: 600'
    """
    name = value.split(" (")[0]  # "credible (scale untested)" is coloured as credible
    return f"color: {LABEL_COLOURS.get(name, MISFIT_COLOUR)}; font-weight: 600"


def _table_html(table, anchor: str = "") -> str:
    table = table.shown()
    head = "".join(
        f'<th class="{"text" if not c.digits else "num"}">{_escape(c.header)}</th>'
        for c in table.columns
    )
    rows = []
    for row in table.rows:
        cells = []
        for c in table.columns:
            value = row.get(c.key)
            # as the terminal shows it: control characters from the data escaped
            text = _escape(format_cell(c.value(row), c.digits))
            cls, style = "text" if not c.digits else "num", ""
            if c.coloured and isinstance(value, str):
                cls += " credible" if value == Label.CREDIBLE.value else " bad"
                style = f' style="{label_style(value)}"'
            cells.append(f'<td class="{cls}"{style}>{text}</td>')
        rows.append("<tr>" + "".join(cells) + "</tr>")
    caption = f'<p class="note">{_escape(table.caption)}</p>' if table.caption else ""
    return (
        f"<h2{_id(anchor)}>{_escape(table.title)}</h2>\n<table><thead><tr>{head}</tr></thead>"
        f"<tbody>{''.join(rows)}</tbody></table>{caption}"
    )


def results_table(items: list[SegmentDiagnosis], notes: tuple[str, ...] = ()) -> str:
    """Diagnosed segments as an HTML table with ``notes`` and the advice lines below it.

    A notebook's view of ``credcli.api.Results``: the columns and cells ``credcli
    diagnose`` shows, labels coloured inline.

    Parameters
    ----------
    items : list of SegmentDiagnosis
        The diagnosed segments, in order.
    notes : tuple of str, default ()
        Lines shown below the table, before the advice.

    Returns
    -------
    str
        One ``<div>`` holding the table and the notes; text from the data is escaped.
    """
    records = [segment_record(item) for item in items]
    body = _table_html(Table("credcli diagnose", SEGMENT_COLUMNS, records))
    lines = [*notes, *(a for a in (advice(item) for item in items) if a)]
    shown = "".join(f'<p class="note">{_escape(line)}</p>' for line in lines)
    return f"<div>{body}{shown}</div>"


def _id(anchor: str) -> str:
    return f' id="{anchor}"' if anchor else ""


class _Anchors:
    """Unique HTML ids made of a text's safe characters."""

    def __init__(self) -> None:
        self.taken: set[str] = set()

    def __call__(self, text: str) -> str:
        stem = re.sub(r"[^A-Za-z0-9_-]+", "-", text).strip("-").lower()[:60] or "section"
        anchor, k = stem, 1
        while anchor in self.taken:
            k += 1
            anchor = f"{stem}-{k}"
        self.taken.add(anchor)
        return anchor


WORST_SHOWN = 5
"""The segments listed as the worst in a report's overview."""


def _severity(diag) -> float:
    """How far κ̂ is from 1 (|ln κ̂|; 0 without a finite positive κ̂)."""
    kappa = None if diag.scale is None else diag.scale.scale_factor
    return abs(math.log(kappa)) if kappa and math.isfinite(kappa) and kappa > 0 else 0.0


def _summary_html(results, figure_of: dict, several: bool) -> str:
    """Counts per label and the worst segments: the misfits whose κ̂ is farthest from 1,
    each linked to its figures (``figure_of``: a result's position -> their anchor), named
    after its log too when the report holds ``several``."""
    shown_labels = [shown_label(r.diagnosis.label, r.diagnosis.untested) for r in results]
    counts: dict[str, int] = {}
    for label in shown_labels:
        counts[label] = counts.get(label, 0) + 1
    shown = "".join(
        f'<span style="{label_style(label)}">{_escape(label)}: {n}</span>'
        for label, n in sorted(counts.items(), key=lambda item: -item[1])
    )
    parts = [f'<p class="counts">{len(results)} segments — {shown}</p>']
    misfits = [
        (k, r)
        for k, r in enumerate(results)
        if r.diagnosis.label not in (Label.CREDIBLE, Label.INSUFFICIENT)
    ]
    if not misfits:
        parts.append('<p class="note">No segment is a misfit.</p>')
        return "".join(parts)
    worst = sorted(misfits, key=lambda pair: _severity(pair[1].diagnosis), reverse=True)
    worst = worst[:WORST_SHOWN]
    rows = []
    for k, result in worst:
        diag = result.diagnosis
        name = _escape(str(result.segment))
        if several:
            name = f"{_escape(str(result.log))}: {name}"
        anchor = figure_of.get(k)
        if anchor:
            name = f'<a href="#{anchor}">{name}</a>'
        label = shown_labels[k]
        rows.append(
            f'<tr><td class="text">{name}</td><td class="text" style="{label_style(label)}">'
            f"{_escape(label)}</td>"
            f"<td>{_escape(scale_text(diag) or '–')}</td>"
            f"<td>{_escape(format_cell(bias_size(diag), 3))}</td>"
            f"<td>{diag.n}</td></tr>"
        )
    parts.append(
        f"<p>The worst segments ({len(worst)} of {len(misfits)} misfits, by how far κ̂ is from "
        '1):</p><table><thead><tr><th class="text">segment</th><th class="text">label</th>'
        "<th>cov × (interval)</th><th>|bias| [σ]</th><th>N</th></tr></thead>"
        f"<tbody>{''.join(rows)}</tbody></table>"
    )
    return "".join(parts)


def _figure_html(plot) -> str:
    uri = "data:image/png;base64," + base64.b64encode(plot.png).decode("ascii")
    return (
        f'<figure><img src="{uri}" alt="{_escape(plot.title)}">'
        f"<figcaption>{_escape(plot.name)}.png: {_escape(plot.title)}</figcaption>"
        "</figure>"
    )


def build_html(title: str, report: Report, plots, subtitle: str = "", notes=(), results=()) -> str:
    """The report as one self-contained HTML document.

    A table of contents, an overview (the label timeline, counts per label, the worst
    segments), the tables, the figures grouped by log and segment (``Plot.group``) as
    inline PNG data, ``notes`` about the figures, and the parameters.

    Parameters
    ----------
    title : str
        The page's title and first heading.
    report : Report
        The command's report: its tables, notes and document (whose ``segments``,
        ``parameters`` and ``version`` are shown).
    plots : list of Plot
        The figures; those whose name ends in the timeline's stem and whose group is an
        overview go to the overview.
    subtitle : str, default ""
        A line under the title; none when empty.
    notes : sequence of str, default ()
        Notes about the figures, shown above them.
    results : sequence of SegmentDiagnosis, default ()
        The SegmentDiagnosis of the report's segment records, in their order, whose logs'
        ids (``credcli.logid.LogId``) link each worst segment to its figures.

    Returns
    -------
    str
        The HTML document, ending in a newline; text from the data is escaped.
    """
    anchors = _Anchors()
    records = document_segments(report.document)
    timeline_stem = FILE_STEMS[PlotKind.TIMELINE]
    timelines = [p for p in plots if p.name.endswith(timeline_stem) and "overview" in p.group]
    others = [p for p in plots if p not in timelines]
    groups: dict[str, list] = {}
    for plot in others:
        groups.setdefault(plot.group or "figures", []).append(plot)
    group_ids = {group: anchors(f"fig-{group}") for group in groups}
    figure_of = {}  # a record's position -> the anchor of its segment's figures
    several = len({result.log for result in results}) > 1
    for k, result in enumerate(results):
        group = segment_group(result.segment, result.log.label if several else "")
        if group in group_ids:
            figure_of[k] = group_ids[group]
    table_ids = [anchors(f"table-{t.title}") for t in report.tables]
    toc = []
    if records or timelines:
        toc.append('<li><a href="#overview">Overview</a></li>')
    for table, anchor in zip(report.tables, table_ids):
        toc.append(f'<li><a href="#{anchor}">{_escape(table.title)}</a></li>')
    if groups:
        items = "".join(
            f'<li><a href="#{group_ids[g]}">{_escape(g)}</a> ({len(groups[g])})</li>'
            for g in groups
        )
        toc.append(f'<li><a href="#figures">Figures</a><ul>{items}</ul></li>')
    toc.append('<li><a href="#parameters">Parameters</a></li>')
    parts = [
        "<!DOCTYPE html>",
        '<html lang="en"><head><meta charset="utf-8">',
        '<meta name="viewport" content="width=device-width, initial-scale=1">',
        f"<title>{_escape(title)}</title><style>{_STYLE}</style></head><body>",
        f"<h1>{_escape(title)}</h1>",
    ]
    if subtitle:
        parts.append(f'<p class="note">{_escape(subtitle)}</p>')
    parts.append(f'<nav id="contents"><h2>Contents</h2><ul>{"".join(toc)}</ul></nav>')
    if records or timelines:
        parts.append('<section id="overview"><h2>Overview</h2>')
        if records:
            parts.append(_summary_html(results, figure_of, several))
        parts.extend(_figure_html(p) for p in timelines)
        parts.append("</section>")
    for table, anchor in zip(report.tables, table_ids):
        parts.append(_table_html(table, anchor))
    for note in report.notes:
        parts.append(f'<p class="note">{_escape(note)}</p>')
    if groups:
        parts.append('<h2 id="figures">Figures</h2>')
    for note in notes:
        parts.append(f'<p class="note">{_escape(note)}</p>')
    for group, members in groups.items():
        parts.append(f'<section><h3 id="{group_ids[group]}">{_escape(group)}</h3>')
        wide = "overview" in group  # whole-run figures: one to a row
        parts.append(f'<div class="{"wide" if wide else "figs"}">')
        parts.extend(_figure_html(p) for p in members)
        parts.append("</div></section>")
    params = document_parameters(report.document)
    parts.append('<h2 id="parameters">Parameters</h2>')
    parts.append(f"<pre>{_escape(json.dumps(params, indent=2))}</pre>")
    version = document_version(report.document)
    parts.append(f'<p class="note">credcli {_escape(str(version))}</p></body></html>')
    return "\n".join(parts) + "\n"
