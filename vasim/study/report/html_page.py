"""The study report as one self-contained HTML file (``vasim report``).

The content model is a few frozen dataclasses: a :class:`ReportDoc` holds
:class:`Section` s, each a sequence of blocks (:class:`Paragraph`, :class:`Notes`,
:class:`TableBlock`, :class:`FigureBlock`, :class:`TextList`). :func:`render_html` turns it
into one HTML page with no external resource: figures are embedded as base64 PNG
(``data:`` URIs), style is inline, there is no script.

Escaping (**the rule**): every string of the content model -- titles, notes, table cells,
column names, free-text answers, subject codes -- is *text* and goes through
:func:`html.escape` (quotes included) when rendered; only this module's own tags are markup.
A questionnaire comment ``<script>alert(1)</script>`` is therefore shown as typed and never
runs.

Example:
    >>> import pandas as pd
    >>> doc = ReportDoc(title="t", meta=(("db", "s.sqlite"),), sections=(
    ...     Section("q", "Questionnaires", (TextList("comments", ("<b>hi</b>",)),)),))
    >>> html = render_html(doc)
    >>> "&lt;b&gt;hi&lt;/b&gt;" in html and "<b>hi</b>" not in html
    True
"""

from __future__ import annotations

import base64
import html
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Literal

import numpy as np
import pandas as pd

Display = Literal["full", "details", "csv"]


@dataclass(frozen=True)
class Paragraph:
    """A paragraph of plain text (escaped)."""

    text: str


@dataclass(frozen=True)
class Notes:
    """What is missing, excluded or approximate in a section (shown in a highlighted box).

    Attributes:
        items: one sentence each. title: the box's heading.
    """

    items: tuple[str, ...]
    title: str = "Missing data and exclusions"


@dataclass(frozen=True)
class TextList:
    """A titled list of texts shown verbatim (escaped), e.g. free-text comments.

    Attributes:
        title: heading. items: the texts (line breaks kept). empty: shown when no item.
    """

    title: str
    items: tuple[str, ...]
    empty: str = "none"


@dataclass(frozen=True)
class TableBlock:
    """A table of the report; ``name`` is its CSV file ``tables/<name>.csv`` (or empty).

    Attributes:
        name: CSV stem under ``tables/`` ("" when the table is only shown).
        title: heading. data: the table (full precision; the HTML rounds floats to 4
            significant digits). caption: what the rows are and where the numbers come from.
        display: ``"full"`` shown in the page, ``"details"`` shown folded, ``"csv"`` only a
            link to the CSV (large per-trial tables).
        columns: the columns shown in the page (None: all); the CSV keeps every column.
    """

    name: str
    title: str
    data: pd.DataFrame = field(repr=False)
    caption: str = ""
    display: Display = "full"
    columns: tuple[str, ...] | None = None


@dataclass(frozen=True)
class FigureBlock:
    """A figure embedded as PNG.

    Attributes:
        name: identifier (also the anchor). title: heading. png: the PNG bytes.
        caption: what is plotted and which table holds its numbers.
    """

    name: str
    title: str
    png: bytes = field(repr=False)
    caption: str = ""


Block = Paragraph | Notes | TextList | TableBlock | FigureBlock


@dataclass(frozen=True)
class Section:
    """One section of the report.

    Attributes:
        key: anchor id (letters, digits, '-', '_'). title: heading.
        blocks: the content in order.
    """

    key: str
    title: str
    blocks: tuple[Block, ...]


@dataclass(frozen=True)
class ReportDoc:
    """The whole report.

    Attributes:
        title: page title. meta: ``(label, value)`` rows of the header (database, protocol,
            generation time, ...). sections: in order.
    """

    title: str
    meta: tuple[tuple[str, str], ...]
    sections: tuple[Section, ...]


_CSS = """
body{font-family:system-ui,-apple-system,"Segoe UI",Roboto,sans-serif;margin:0 auto;
max-width:1180px;padding:1.5em;color:#1b1b1b;line-height:1.45}
h1{font-size:1.6em;margin-bottom:.2em}h2{border-bottom:2px solid #0072B2;padding-bottom:.2em;
margin-top:2.2em}h3{margin-top:1.6em;font-size:1.08em}
table{border-collapse:collapse;font-size:.82em;margin:.4em 0 1em 0}
th,td{border:1px solid #ccc;padding:.22em .5em;text-align:right;vertical-align:top}
th{background:#eef3f8}td.t{text-align:left;white-space:pre-wrap}
.meta td{text-align:left}.notes{background:#fff6e0;border-left:4px solid #E69F00;
padding:.5em 1em;margin:.8em 0}.notes h4{margin:.2em 0}.caption{color:#444;font-size:.88em}
figure{margin:1em 0}figure img{max-width:100%;height:auto;border:1px solid #ddd}
nav ol{columns:2}details summary{cursor:pointer;color:#0072B2}
ul.texts li{white-space:pre-wrap;margin-bottom:.4em}.csv{font-size:.85em}
"""


def esc(text: object) -> str:
    """``html.escape(str(text), quote=True)``: any value as safe HTML text.

    >>> esc('<script>alert("1")</script>')
    '&lt;script&gt;alert(&quot;1&quot;)&lt;/script&gt;'
    """
    return html.escape(str(text), quote=True)


def format_value(v: object) -> str:
    """A table cell as text: floats to 4 significant digits (integers from 1e4 to 1e9),
    missing as an en dash.

    >>> format_value(0.000123456), format_value(12345.678), format_value(float("nan"))
    ('0.0001235', '12346', '–')
    """
    if v is None or v is pd.NA or v is pd.NaT:
        return "–"
    if isinstance(v, bool | np.bool_):
        return "yes" if v else "no"
    if isinstance(v, int | np.integer):
        return str(int(v))
    if isinstance(v, float | np.floating):
        f = float(v)
        if math.isnan(f):
            return "–"
        if math.isinf(f):
            return "inf" if f > 0 else "-inf"
        if 1e4 <= abs(f) < 1e9 or (f == int(f) and abs(f) < 1e4):
            return f"{f:.0f}"
        return f"{f:.4g}"
    return str(v)


def table_html(df: pd.DataFrame, columns: Sequence[str] | None = None) -> str:
    """An HTML table of ``df`` (escaped; numbers right-aligned, text left-aligned)."""
    cols = list(columns) if columns is not None else [str(c) for c in df.columns]
    cols = [c for c in cols if c in df.columns]
    head = "".join(f"<th>{esc(c)}</th>" for c in cols)
    rows = []
    for rec in df[cols].itertuples(index=False, name=None):
        cells = []
        for v in rec:
            is_text = isinstance(v, str)
            cls = ' class="t"' if is_text else ""
            cells.append(f"<td{cls}>{esc(format_value(v))}</td>")
        rows.append("<tr>" + "".join(cells) + "</tr>")
    return f"<table><thead><tr>{head}</tr></thead><tbody>{''.join(rows)}</tbody></table>"


def _block_html(b: Block) -> str:
    if isinstance(b, Paragraph):
        return f"<p>{esc(b.text)}</p>"
    if isinstance(b, Notes):
        if not b.items:
            return ""
        items = "".join(f"<li>{esc(t)}</li>" for t in b.items)
        return f'<div class="notes"><h4>{esc(b.title)}</h4><ul>{items}</ul></div>'
    if isinstance(b, TextList):
        body = ("".join(f"<li>{esc(t)}</li>" for t in b.items) if b.items
                else f"<li><em>{esc(b.empty)}</em></li>")
        return f'<h3>{esc(b.title)}</h3><ul class="texts">{body}</ul>'
    if isinstance(b, FigureBlock):
        data = base64.b64encode(b.png).decode("ascii")
        return (f'<figure id="fig-{esc(b.name)}"><h3>{esc(b.title)}</h3>'
                f'<img alt="{esc(b.title)}" src="data:image/png;base64,{data}">'
                f'<figcaption class="caption">{esc(b.caption)}</figcaption></figure>')
    # TableBlock
    csv = (f'<div class="csv">CSV: <a href="tables/{esc(b.name)}.csv">tables/{esc(b.name)}.csv'
           f"</a> ({len(b.data)} rows)</div>" if b.name else "")
    cap = f'<p class="caption">{esc(b.caption)}</p>' if b.caption else ""
    anchor = f' id="tab-{esc(b.name)}"' if b.name else ""
    head = f"<h3{anchor}>{esc(b.title)}</h3>"
    if b.data.empty:
        return f"{head}{cap}<p><em>empty table</em></p>{csv}"
    if b.display == "csv":
        return f"{head}{cap}{csv}"
    tab = table_html(b.data, b.columns)
    if b.display == "details":
        tab = f"<details><summary>show {len(b.data)} rows</summary>{tab}</details>"
    return f"{head}{cap}{tab}{csv}"


def render_html(doc: ReportDoc) -> str:
    """The report as one self-contained HTML page (UTF-8 text).

    Args:
        doc: the report content.

    Returns:
        The page; every text of ``doc`` is escaped, figures are inline PNG.
    """
    meta = "".join(f"<tr><th>{esc(k)}</th><td>{esc(v)}</td></tr>" for k, v in doc.meta)
    nav = "".join(f'<li><a href="#{esc(s.key)}">{esc(s.title)}</a></li>' for s in doc.sections)
    body = []
    for s in doc.sections:
        blocks = "".join(_block_html(b) for b in s.blocks)
        body.append(f'<section id="{esc(s.key)}"><h2>{esc(s.title)}</h2>{blocks}</section>')
    return (
        "<!DOCTYPE html>\n"
        f'<html lang="en"><head><meta charset="utf-8"><title>{esc(doc.title)}</title>'
        '<meta name="viewport" content="width=device-width, initial-scale=1">'
        f"<style>{_CSS}</style></head><body>"
        f'<h1>{esc(doc.title)}</h1><table class="meta">{meta}</table>'
        f"<nav><h2>Contents</h2><ol>{nav}</ol></nav>{''.join(body)}</body></html>\n"
    )


__all__ = [
    "Block",
    "FigureBlock",
    "Notes",
    "Paragraph",
    "ReportDoc",
    "Section",
    "TableBlock",
    "TextList",
    "esc",
    "format_value",
    "render_html",
    "table_html",
]
