"""Constraint files in the calibration page: fixed points, planes, distances, inclinometers
(no tracker needed).

A file with a ``point``, ``plane`` or ``pair``/``distance_mm`` column, or ``link``, ``axis`` and
``tilt_deg`` (an inclinometer's readings)
(:func:`robocal.measure.constraints.data.constraint_kind`) is recognised on upload; the page
then shows the kind's options (known distances between points as a small table, the level)
and a run calibrates it with :func:`robocal.workflow.constraints.calibrate_constraint_files`,
the command line's use case.  The results view shows the kind's figures before and after
(spread around each point, known-distance errors, plane residuals, pair errors, each
inclinometer channel's RMS residual in degrees), what the
data cannot identify and why, and the identified parameters.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from dash import html
from dash.dash_table import DataTable

from robocal.apps.gui.calibrate_views import radio, row
from robocal.apps.gui.constraint_job import FIGURES_FILE

__all__ = ["constraint_file_kind", "distances_of", "fieldset", "preview", "results_view"]


def constraint_file_kind(path: Path | None) -> str | None:
    """``point``, ``plane``, ``distance`` or ``tilt`` for a constraint file, else None."""
    from robocal.measure.constraints.data import constraint_kind

    if path is None:
        return None
    try:
        return constraint_kind(path)
    except (OSError, ValueError):
        return None


def fieldset() -> html.Fieldset:
    """The kind's options, shown when the file is a constraint file."""
    table = DataTable(  # type: ignore[operator]  # dash re-exports the class under its module's name
        id="con-distances",
        columns=[
            {"name": "point a", "id": "a", "type": "numeric"},
            {"name": "point b", "id": "b", "type": "numeric"},
            {"name": "distance mm", "id": "mm", "type": "numeric"},
        ],
        data=[{"a": None, "b": None, "mm": None} for _ in range(3)],
        editable=True,
        persistence=True,
        persisted_props=["data"],
        persistence_type="session",
        style_table={"width": "24em"},
    )
    return html.Fieldset(
        [
            html.Legend("constraint file (fixed points, planes, distances, inclinometers)"),
            html.Div(id="con-kind", className="hint"),
            row(
                "level",
                radio("con-level", ("2", "1"), "2", ("kinematic", "joint offsets")),
                "what to identify",
            ),
            html.Div("known distances between fixed points (empty rows are ignored)", className="hint"),
            table,
        ],
        id="con-fieldset",
        style={"display": "none"},
    )


def distances_of(rows: list[dict[str, Any]] | None) -> tuple[tuple[int, int, float], ...]:
    """The table's filled rows as ``(a, b, metres)``; ValueError naming the row and column."""
    out = []
    for k, r in enumerate(rows or [], start=1):
        cells = [r.get(c) for c in ("a", "b", "mm")]
        if all(c in (None, "") for c in cells):
            continue
        try:
            a, b, mm = (float(c) for c in cells)  # type: ignore[arg-type]  # None: TypeError
        except (TypeError, ValueError):
            raise ValueError(
                f"known distances, row {k}: give point a, point b and the distance in mm"
            ) from None
        if a != int(a) or b != int(b) or min(a, b) < 0 or a == b:
            raise ValueError(f"known distances, row {k}: points are two different whole numbers 0, 1, ...")
        if not 0 < mm < 1e5:
            raise ValueError(f"known distances, row {k}: a distance in mm above 0, not {mm:g}")
        out.append((int(a), int(b), mm * 1e-3))
    return tuple(out)


def preview(path: Path, dof: int | None, angle_unit: str) -> list[Any]:
    """The file's rows per point / plane / pair, or the reader's one-line problem (``dof``:
    the chosen robot's joints; None: the file's ``q1..qN`` columns)."""
    import re

    from robocal.measure.constraints.data import read_constraints

    try:
        if dof is None:
            with path.open(encoding="utf-8", errors="replace") as f:
                header = next((line for line in f if not line.startswith("#")), "")
            dof = sum(1 for c in header.split(",") if re.fullmatch(r"q\d+", c.strip()))
        data = read_constraints(path, dof, angle_unit=angle_unit)
    except ValueError as err:
        return [html.Div(str(err).replace(str(path), path.name), className="error", id="csv-error")]
    counts = [f"point {k}: {int((data.point == k).sum())} poses" for k in range(data.n_points)]
    counts += [f"plane {k}: {int((data.plane == k).sum())} poses" for k in range(data.n_planes)]
    if len(data.pairs):
        counts.append(f"{len(data.pairs)} pairs of known distance")
    counts += _tilt_counts(data)
    summary = (
        f"{path.name}: {data.n} rows, {data.q.shape[1]} joints, constraint file ({', '.join(data.kinds)})"
    )
    return [html.Div(summary, className="ok", id="csv-summary"), html.Ul([html.Li(c) for c in counts])]


def _tilt_counts(data: Any) -> list[str]:
    """Readings per inclinometer (link, joint number from 1 as in the file) and its axes."""
    from robocal.measure.constraints.data import TILT_AXES

    link = getattr(data, "tilt_link", None)
    if link is None or not (link >= 0).any():
        return []
    out = []
    for k in sorted({int(v) for v in link if v >= 0}):
        axes = sorted({TILT_AXES[int(a)] for a in data.tilt_axis[link == k]})
        out.append(f"inclinometer on link {k + 1} ({', '.join(axes)}): {int((link == k).sum())} readings")
    return out


_FIGURE_ROWS = (
    ("point_spread", "point {k}: RMS spread around its centroid, mm"),
    ("point_distance_error", "known distance {k}: error, mm"),
    ("plane_rms", "plane {k}: RMS residual, mm"),
    ("pair_error", "pair {k}: distance error, mm"),
)


def _figures_table(before: dict | None, after: dict | None) -> html.Table:
    rows = []
    for key, label in _FIGURE_ROWS:
        values = (after or {}).get(key, [])
        if key == "pair_error" and len(values) > 12:  # many pairs: their RMS, one row
            rms = lambda v: (sum(x * x for x in v) / len(v)) ** 0.5  # noqa: E731
            cells = [rms((before or {}).get(key) or [float("nan")]), rms(values)]
            rows.append(_figure_row(f"{len(values)} pairs: RMS distance error, mm", *cells))
            continue
        for k, v in enumerate(values):
            b = (before or {}).get(key, [])
            rows.append(_figure_row(label.format(k=k), b[k] if k < len(b) else None, v))
    rows += _tilt_rows(before or {}, after or {})
    head = html.Tr([html.Th(h) for h in ("figure", "nominal", "calibrated")])
    basis = (after or {}).get("tilt_basis")  # what predicted the inclinometer readings after
    caption = (
        [html.Caption(f"inclinometer readings after calibration: {basis}", id="tilt-basis")] if basis else []
    )
    return html.Table(
        [*caption, html.Thead(head), html.Tbody(rows)], id="constraint-figures", className="stats"
    )


def _tilt_rows(before: dict, after: dict) -> list[html.Tr]:
    """One row per inclinometer channel: its readings' RMS residual in degrees (a folder
    written before the inclinometer had none)."""
    was = dict(zip(before.get("tilt_channels", []), before.get("tilt_deg", []), strict=True))
    channels = zip(after.get("tilt_channels", []), after.get("tilt_deg", []), strict=True)
    return [
        _figure_row(f"inclinometer {name}: RMS residual, deg", was.get(name), v, digits=5)
        for name, v in channels
    ]


def _figure_row(label: str, before: float | None, after: float, digits: int = 3) -> html.Tr:
    cell = lambda v: html.Td("" if v is None else f"{v:.{digits}f}", className="num")  # noqa: E731
    return html.Tr([html.Td(label), cell(before), cell(after)])


def results_view(out: Path) -> list[Any]:
    """The constraint calibration saved in ``out`` as the page shows it."""
    from robocal.identify.constraints.result import load_constraint_calibration

    cal = load_constraint_calibration(out)
    doc = json.loads((out / FIGURES_FILE).read_text(encoding="utf-8"))
    dropped = [html.Li(f"{d['name']}: {d['reason']}") for d in doc["dropped"]]
    params = [
        html.Tr([html.Td(n), html.Td(f"{v:.6g}", className="num"), html.Td(f"{s:.3g}", className="num")])
        for n, v, s in zip(cal.names, cal.estimates, cal.std, strict=True)
        if not n.startswith(("point", "plane"))
    ]
    head = html.Tr([html.Th(h) for h in ("parameter", "estimate (m, rad)", "σ")])
    return [
        html.H3("result (constraint calibration)"),
        html.Div(f"{cal.model.name}: {doc['n']} poses, {', '.join(doc['kinds'])}", id="result-head"),
        html.Pre("\n".join(doc["summary"] + doc["each_kind"]), className="cv", id="constraint-summary"),
        html.H4("the kind's figures, before and after"),
        _figures_table(doc["before"], doc["after"]),
        html.H4("not identified, and why"),
        html.Div(cal.base_note(), className="hint") if cal.unseen else "",
        html.Ul(dropped or [html.Li("none")], id="dropped"),
        html.H4("identified parameters (σ: one standard deviation)"),
        html.Table([html.Thead(head), html.Tbody(params)], className="params", id="param-table"),
    ]
