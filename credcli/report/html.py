"""One self-contained HTML file: the tables, the parameters and the plots as data URIs.

No script, no stylesheet link, no font or image fetched: it opens offline and can be
attached to a CI run.
"""

from __future__ import annotations

import base64
import html
import json

from credcli.engine.config import Label
from credcli.errors import printable
from credcli.report.render import SEGMENT_COLUMNS, Report, Table, advice, format_cell

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
"""


LABEL_COLOURS = {"credible": "#176f2c", "insufficient-data": "#666666"}
"""A label's colour in HTML (every other label, a misfit: :data:`MISFIT_COLOUR`)."""
MISFIT_COLOUR = "#a33a00"


def label_style(value: str) -> str:
    """The inline style of a label cell: its colour stays where a page's stylesheet is
    dropped (a notebook viewer, a mail)."""
    name = value.split(" (")[0]  # "credible (scale untested)" is coloured as credible
    return f"color: {LABEL_COLOURS.get(name, MISFIT_COLOUR)}; font-weight: 600"


def _table_html(table) -> str:
    table = table.shown()
    head = "".join(
        f'<th class="{"text" if not c.digits else "num"}">{html.escape(c.header)}</th>'
        for c in table.columns
    )
    rows = []
    for row in table.rows:
        cells = []
        for c in table.columns:
            value = row.get(c.key)
            # as the terminal shows it: control characters from the data escaped
            text = html.escape(printable(format_cell(c.value(row), c.digits)))
            cls, style = "text" if not c.digits else "num", ""
            if c.key in ("label", "nees_label", "nci_label") and isinstance(value, str):
                cls += " credible" if value == Label.CREDIBLE.value else " bad"
                style = f' style="{label_style(value)}"'
            cells.append(f'<td class="{cls}"{style}>{text}</td>')
        rows.append("<tr>" + "".join(cells) + "</tr>")
    caption = f'<p class="note">{html.escape(table.caption)}</p>' if table.caption else ""
    return (
        f"<h2>{html.escape(table.title)}</h2>\n<table><thead><tr>{head}</tr></thead>"
        f"<tbody>{''.join(rows)}</tbody></table>{caption}"
    )


def records_table(records: list[dict], notes: tuple[str, ...] = ()) -> str:
    """Segment records as an HTML table with the advice lines and ``notes`` below it (a
    notebook's view of :class:`credcli.api.Results`): the columns and cells ``credcli
    diagnose`` shows, labels coloured inline."""
    body = _table_html(Table("credcli diagnose", SEGMENT_COLUMNS, records))
    lines = [*notes, *(a for a in (advice(r) for r in records) if a)]
    shown = "".join(f'<p class="note">{html.escape(line)}</p>' for line in lines)
    return f"<div>{body}{shown}</div>"


def build_html(title: str, report: Report, plots, subtitle: str = "") -> str:
    """The report as one HTML document."""
    parts = [
        "<!DOCTYPE html>",
        '<html lang="en"><head><meta charset="utf-8">',
        '<meta name="viewport" content="width=device-width, initial-scale=1">',
        f"<title>{html.escape(title)}</title><style>{_STYLE}</style></head><body>",
        f"<h1>{html.escape(title)}</h1>",
    ]
    if subtitle:
        parts.append(f'<p class="note">{html.escape(subtitle)}</p>')
    for table in report.tables:
        parts.append(_table_html(table))
    for note in report.notes:
        parts.append(f'<p class="note">{html.escape(note)}</p>')
    if plots:
        parts.append("<h2>Figures</h2>")
    for plot in plots:
        uri = "data:image/png;base64," + base64.b64encode(plot.png).decode("ascii")
        parts.append(
            f'<figure><img src="{uri}" alt="{html.escape(plot.title)}">'
            f"<figcaption>{html.escape(plot.name)}.png: {html.escape(plot.title)}</figcaption></figure>"
        )
    params = report.document.get("parameters", {})
    parts.append("<h2>Parameters</h2>")
    parts.append(f"<pre>{html.escape(json.dumps(params, indent=2))}</pre>")
    version = report.document.get("version", "")
    parts.append(f'<p class="note">credcli {html.escape(str(version))}</p></body></html>')
    return "\n".join(parts) + "\n"
