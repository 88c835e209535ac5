"""HTML building blocks of the report: escaping, number formats, tables, sections, figures
and the page around them (its style sheet and template are package data)."""

from __future__ import annotations

import html
import math
from collections.abc import Sequence
from functools import cache
from importlib import resources
from string import Template
from typing import Any

__all__ = [
    "AFTER",
    "BEFORE",
    "COMPENSATED",
    "GEOMETRIC",
    "Figures",
    "Raw",
    "e",
    "f",
    "g",
    "note",
    "page",
    "plot_text",
    "report_css",
    "section",
    "table",
]

BEFORE = "#d95f02"  # orange-red: before calibration / nominal commands
AFTER = "#1b6ca8"  # blue: after calibration
GEOMETRIC = "#7f7f7f"
COMPENSATED = "#1a9850"  # green: compensated commands
PLOT_CONFIG = {"displaylogo": False, "responsive": True, "toImageButtonOptions": {"format": "png"}}


@cache
def _asset(name: str) -> str:
    """A text file shipped in this package (``report.css``, ``page.html``)."""
    return resources.files(__package__).joinpath(name).read_text(encoding="utf-8")


def report_css() -> str:
    """The report's style sheet (package data ``report.css``)."""
    return _asset("report.css")


def e(text: Any) -> str:
    """``text`` as HTML text: every string from data passes through here."""
    return html.escape(str(text))


def plot_text(text: Any) -> str:
    """``text`` for a plotly label: plotly reads a small HTML subset (``<b>``, ``<a>``) in
    labels and decodes entities, so data is escaped to be shown as it is."""
    return html.escape(str(text), quote=False)


def _finite(value: float | None) -> bool:
    return value is not None and math.isfinite(value)


def f(value: float | None, digits: int = 3) -> str:
    """Fixed-point text, "–" for an absent or non-finite value (never "nan", "None", "-0.000")."""
    if not _finite(value):
        return "–"
    text = f"{value:.{digits}f}"
    return text[1:] if text.startswith("-") and float(text) == 0 else text


def g(value: float | None, digits: int = 3) -> str:
    """Significant-digit text, "–" for an absent or non-finite value."""
    return f"{value:.{digits}g}" if _finite(value) else "–"


class Raw:
    """A table cell holding HTML that must not be escaped (built from escaped parts)."""

    def __init__(self, html_text: str) -> None:
        self.html = html_text


def _numeric(text: str) -> bool:
    plain = text.replace(".", "", 1).replace("−", "").replace("-", "", 1).replace("+", "").strip()
    plain = plain.replace(" ", "").replace("%", "").replace("±", "").replace("–", "")
    return plain.isdigit()


def table(header: Sequence[str], rows: Sequence[Sequence[Any]], cls: str = "", caption: str = "") -> str:
    """An HTML table; cells are escaped unless :class:`Raw`; numeric-looking cells
    right-aligned.  No rows, no table: an empty table is never shown."""
    if not rows:
        return ""
    head = "".join(f"<th>{e(h)}</th>" for h in header)
    body = []
    for row in rows:
        cells = []
        for cell in row:
            text = cell.html if isinstance(cell, Raw) else e(cell)
            plain = cell.html if isinstance(cell, Raw) else str(cell)
            cells.append(f"<td class='num'>{text}</td>" if _numeric(plain) else f"<td>{text}</td>")
        body.append("<tr>" + "".join(cells) + "</tr>")
    cap = f"<caption>{e(caption)}</caption>" if caption else ""
    return f"<table class='{cls}'>{cap}<thead><tr>{head}</tr></thead><tbody>{''.join(body)}</tbody></table>"


def note(text_html: str) -> str:
    """A note paragraph (``text_html`` already escaped where it holds data)."""
    return f"<p class='note'>{text_html}</p>"


def section(ident: str, title: str, body: str, intro: str = "") -> str:
    """A report section; ``intro`` is trusted HTML (escape data in it)."""
    lead = f"<p class='intro'>{intro}</p>" if intro else ""
    return f"<section id='{e(ident)}'><h2>{e(title)}</h2>{lead}{body}</section>"


class Figures:
    """Turns plotly figures into HTML; the first one carries plotly.js (once per page)."""

    def __init__(self) -> None:
        self.count = 0

    def html(self, fig: Any, name: str, height: int | None = None) -> str:
        if height is not None:
            fig.update_layout(height=height)
        fig.update_layout(template="plotly_white", font={"family": "system-ui, sans-serif", "size": 12})
        div = fig.to_html(
            full_html=False,
            include_plotlyjs=self.count == 0,
            config=PLOT_CONFIG,
            div_id=f"fig-{name}",
        )
        self.count += 1
        return f"<div class='figure' data-figure='{e(name)}'>{div}</div>"


def page(
    title: str, subtitle_html: str, nav: Sequence[tuple[str, str]], sections_html: str, version: str
) -> str:
    """The whole page from the template ``page.html``: ``nav`` is ``(section id, label)``."""
    links = "".join(f"<a href='#{e(ident)}'>{e(label)}</a>" for ident, label in nav)
    return Template(_asset("page.html")).substitute(
        title=e(title),
        css=report_css(),
        subtitle=subtitle_html,
        nav=links,
        sections=sections_html,
        version=e(version),
    )
