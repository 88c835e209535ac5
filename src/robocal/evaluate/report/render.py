"""The page: every section rendered from the report data, in order, around the template."""

from __future__ import annotations

from robocal.evaluate.report import markup as m
from robocal.evaluate.report import sections, sections_eval
from robocal.evaluate.report.data import ReportData

__all__ = ["render_report"]


def _subtitle(r: ReportData) -> str:
    model = r.facts.model
    text = f"{m.e(model.title or model.name)} · {m.e(r.facts.measure)} measurements"
    text += f" · {r.n_calibration} calibration poses"
    if r.n_held_out is not None:
        text += f" · {r.n_held_out} held-out poses"
    return text


def render_report(r: ReportData) -> str:
    """The report as one self-contained HTML page (plotly.js embedded once)."""
    figs = m.Figures()
    rendered = [render(r, figs) for render in (*sections.SECTIONS, *sections_eval.SECTIONS)]
    shown = [s for s in rendered if s is not None]
    return m.page(
        r.title,
        _subtitle(r),
        [(ident, label) for ident, label, _ in shown],
        "".join(html for _, _, html in shown),
        r.version,
    )
