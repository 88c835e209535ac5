"""One self-contained HTML report per calibration.

:func:`write_report` turns a :class:`~robocal.identify.calibrate.CalibrationResult`
(or a directory written by :meth:`CalibrationResult.save`) and, when given, the
calibration and held-out measurements and an *evaluation* (ISO 9283 poses and paths,
compensation, the truth of a simulation) into one HTML file with these sections:

1. summary — the numbers that matter, before and after;
2. robot and model — interactive 3D view with the joint frames
   (:func:`robocal.model.view.model_figure`), how every link is parameterised;
3. data — where the measured poses lie in the workspace, the joint ranges covered;
4. identifiability — dropped parameters and why, condition number, observability
   indices O1-O5, singular values;
5. parameters — estimates with their deltas and σ (and the true deltas of a
   simulation);
6. residuals — before and after: histograms, per-pose bars, 3D error vectors;
7. held-out validation — statistics, histograms, the seeds' min / max / average
   table with the improvement in per cent and its 95 % confidence interval;
8. ISO 9283 — pose accuracy AP and repeatability RP at P1-P5, path accuracy AT and
   repeatability RT (:mod:`robocal.evaluate.metrics`);
9. joint effects — identified joint compliances and what they move the tool by;
10. compensation — the method, and the path errors with nominal and compensated
    commands;
11. provenance.

plotly.js is embedded once (``include_plotlyjs=True`` for the first figure), so the
file works offline and makes no external request.  "Before calibration" is the
nominal robot with the device frame and tool fitted to the calibration data (the
start of the identification), the same reference as ``rms_before``.

The *evaluation* is plain JSON-able data (SI units), as ``robocal demo`` writes to
``evaluation.json``::

    {"iso_poses": {"labels": [...], "commanded": (5, 3), "cube": {"center", "side", "plane"},
                   "cycles": n, "cases": {name: (5, n, 3) attained positions}},
     "paths": [{"name": str, "commanded": (m, 3), "cases": {name: (n, k, 3)}}],
     "compensation": {"method": str, ...},
     "comparison": [{"model": str, **ValidationStats.to_dict()}],
     "truth": {"parameter_deltas": {name: value}, "compliance_rad_per_Nm": {joint: c}},
     "timings_s": {step: seconds},
     "iso9283": Iso9283Results.to_dict() of a measurement log (robocal iso9283 --json)}

Positions of ``iso_poses`` and ``paths`` are in the robot's base frame (m).
"""

from __future__ import annotations

import datetime as _dt
import html
import json
import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from robocal.evaluate.metrics import (
    ERROR_QUANTITIES,
    ErrorTable,
    PoseErrors,
    error_table,
    improvement,
    iso9283_pose_characteristics,
    path_accuracy,
    pose_errors,
)
from robocal.identify.calibrate import COMPLIANCE_PREFIX, CalibrationResult
from robocal.identify.problem import FRAME_PREFIX, TOOL_PREFIX
from robocal.identify.validate import ValidationStats, validate
from robocal.measure.dataset import Measurements
from robocal.model.chain import Model

__all__ = ["before_validation", "build_report", "start_chain", "write_report"]

Array = NDArray[np.float64]

BEFORE = "#d95f02"  # orange-red: before calibration / nominal commands
AFTER = "#1b6ca8"  # blue: after calibration
GEOMETRIC = "#7f7f7f"
COMPENSATED = "#1a9850"  # green: compensated commands
CASE_COLOURS = {"nominal commands": BEFORE, "compensated commands": COMPENSATED}
LEGEND_BELOW = {"orientation": "h", "y": -0.3, "yanchor": "top", "x": 0}
PLOT_CONFIG = {"displaylogo": False, "responsive": True, "toImageButtonOptions": {"format": "png"}}


# ---------------------------------------------------------------------- before / after


def _points3d(points: Array, **style: Any):
    """A plotly 3D scatter of ``(n, 3)`` points (mm) with the given trace style."""
    import plotly.graph_objects as go

    return go.Scatter3d(x=points[:, 0], y=points[:, 1], z=points[:, 2], **style)


def start_chain(result: CalibrationResult) -> Model | None:
    """The measurement chain at the identification's start values: the nominal robot
    with the device frame and the tool fitted in closed form (None for results saved
    without their measurement chain)."""
    chain = result.measurement_chain
    if chain is None:
        return None
    names = set(chain.names)
    return chain.with_values(
        {n: float(v) for n, v in zip(result.names, result.nominal, strict=True) if n in names}
    )


def _stats(predicted: Array, data: Measurements, label: str) -> ValidationStats:
    """Error statistics of predicted tool frames ``(n, 4, 4)`` (device frame) on ``data``."""
    from robocal.identify.validate import validation_statistics

    return validation_statistics(predicted, data, label)


def before_validation(result: CalibrationResult, data: Measurements) -> ValidationStats | None:
    """Errors of the start model (nominal robot, fitted frame and tool) on ``data``."""
    chain = start_chain(result)
    if chain is None or data.position is None or data.dof != result.model.dof:
        return None
    return _stats(chain.fk(data.q), data, "start fit")


def _base_errors(result: CalibrationResult, stats: ValidationStats) -> PoseErrors:
    """Error vectors of ``stats`` rotated from the device frame into the robot base frame."""
    return PoseErrors(stats.error_vectors @ result.frame[:3, :3])


# ---------------------------------------------------------------------- formatting
def _e(text: Any) -> str:
    return html.escape(str(text))


def _f(value: float | None, digits: int = 3) -> str:
    if value is None or not np.isfinite(value):
        return "–"
    text = f"{value:.{digits}f}"
    return text[1:] if text.startswith("-") and float(text) == 0 else text


def _g(value: float | None, digits: int = 3) -> str:
    if value is None or not np.isfinite(value):
        return "–"
    return f"{value:.{digits}g}"


def _table(header: Sequence[str], rows: Sequence[Sequence[Any]], cls: str = "", caption: str = "") -> str:
    """An HTML table; cells are escaped unless they are ``_Raw``; numeric-looking cells right-aligned."""
    head = "".join(f"<th>{_e(h)}</th>" for h in header)
    body = []
    for row in rows:
        cells = []
        for cell in row:
            text = cell.html if isinstance(cell, _Raw) else _e(cell)
            plain = cell.html if isinstance(cell, _Raw) else str(cell)
            numeric = plain.replace(".", "", 1).replace("−", "").replace("-", "", 1).replace("+", "").strip()
            numeric = numeric.replace(" ", "").replace("%", "").replace("±", "").replace("–", "")
            cells.append(f"<td class='num'>{text}</td>" if numeric.isdigit() else f"<td>{text}</td>")
        body.append("<tr>" + "".join(cells) + "</tr>")
    cap = f"<caption>{_e(caption)}</caption>" if caption else ""
    return f"<table class='{cls}'>{cap}<thead><tr>{head}</tr></thead><tbody>{''.join(body)}</tbody></table>"


class _Raw:
    """Table cell holding HTML that must not be escaped."""

    def __init__(self, html_text: str) -> None:
        self.html = html_text


class _Figures:
    """Collects plotly figures; the first one carries plotly.js."""

    def __init__(self) -> None:
        self.count = 0

    def html(self, fig, name: str, height: int | None = None) -> str:
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
        return f"<div class='figure' data-figure='{_e(name)}'>{div}</div>"


# ---------------------------------------------------------------------- figures
def _cube_edges(center: Array, side: float) -> Array:
    from robocal.measure.poses import CUBE_CORNERS

    c = np.asarray(center) + side * (CUBE_CORNERS - 0.5)
    edges = [(0, 1), (1, 2), (2, 3), (3, 0), (4, 5), (5, 6), (6, 7), (7, 4), (0, 4), (1, 5), (2, 6), (3, 7)]
    pts = []
    for a, b in edges:
        pts += [c[a], c[b], [np.nan] * 3]
    return np.array(pts)


def _fig_coverage(result: CalibrationResult, sets: Sequence[tuple[str, Measurements, str]], ev: Mapping):
    import plotly.graph_objects as go

    fig = go.Figure()
    for name, data, colour in sets:
        p = result.model.fk(data.q)[:, :3, 3] * 1e3
        fig.add_trace(
            _points3d(
                p,
                mode="markers",
                name=f"{name} ({data.n})",
                marker={
                    "size": 3.5 if name.startswith("calib") else 2.5,
                    "color": colour,
                    "opacity": 0.9 if name.startswith("calib") else 0.5,
                },
            )
        )
    iso = ev.get("iso_poses")
    if iso:
        cube = iso.get("cube")
        if cube:
            e = _cube_edges(np.asarray(cube["center"]), cube["side"]) * 1e3
            fig.add_trace(
                _points3d(
                    e,
                    mode="lines",
                    name="ISO 9283 cube",
                    line={"color": "#555", "width": 2},
                )
            )
        c = np.asarray(iso["commanded"]) * 1e3
        fig.add_trace(
            _points3d(
                c,
                mode="markers+text",
                text=iso["labels"],
                name="P1–P5",
                marker={"size": 5, "color": "#000", "symbol": "diamond"},
            )
        )
    for path in ev.get("paths", []):
        c = np.asarray(path["commanded"]) * 1e3
        fig.add_trace(
            _points3d(
                c,
                mode="lines",
                name=path["name"],
                line={"color": COMPENSATED, "width": 4},
            )
        )
    fig.add_trace(
        go.Scatter3d(
            x=[0],
            y=[0],
            z=[0],
            mode="markers+text",
            text=["base"],
            name="robot base",
            marker={"size": 6, "color": "#444", "symbol": "square"},
        )
    )
    fig.update_layout(
        scene={
            "aspectmode": "data",
            "xaxis_title": "x mm",
            "yaxis_title": "y mm",
            "zaxis_title": "z mm",
            "camera": {"eye": {"x": 1.6, "y": -1.6, "z": 0.9}},
        },
        margin={"l": 0, "r": 0, "t": 30, "b": 0},
        legend={"orientation": "h"},
        title="measured tool positions in the robot base frame",
    )
    return fig


def _fig_joint_coverage(model: Model, sets: Sequence[tuple[str, Measurements, str]]):
    import plotly.graph_objects as go

    fig = go.Figure()
    revolute = np.array(model.joint_types) == "revolute"
    for name, data, colour in sets:
        q = np.where(revolute, np.degrees(data.q), data.q * 1e3)
        x = np.repeat(np.array(model.joint_names)[None], len(q), axis=0).reshape(-1)
        fig.add_trace(go.Box(x=x, y=q.reshape(-1), name=name, marker_color=colour, boxpoints=False))
    lim = model.joint_limits
    lim = np.where(revolute[:, None], np.degrees(lim), lim * 1e3)
    finite = np.all(np.isfinite(lim), axis=1)
    if finite.any():
        names = np.array(model.joint_names)[finite]
        for k, label in ((0, "lower limit"), (1, "upper limit")):
            fig.add_trace(
                go.Scatter(
                    x=names,
                    y=lim[finite, k],
                    mode="markers",
                    name=label,
                    marker={"symbol": "line-ew-open", "size": 22, "color": "#999"},
                )
            )
    fig.update_layout(
        boxmode="group",
        yaxis_title="joint value (deg; mm for prismatic)",
        title="joint ranges covered",
        legend=LEGEND_BELOW,
        margin={"t": 40, "b": 90},
    )
    return fig


def _fig_singular_values(sigma: Array, names: Sequence[str]):
    import plotly.graph_objects as go

    fig = go.Figure(
        go.Bar(
            x=[f"σ{k + 1}" for k in range(len(sigma))],
            y=sigma,
            marker_color=AFTER,
            hovertemplate="%{x}: %{y:.3g}<extra></extra>",
        )
    )
    fig.update_layout(
        yaxis={"type": "log", "dtick": 1, "title": "singular value (unit-norm columns)"},
        title=f"singular values, {len(names)} parameters",
        margin={"t": 60, "l": 70},
    )
    return fig


def _fig_parameters(rows: Sequence[dict[str, Any]]):
    import plotly.graph_objects as go
    from plotly.subplots import make_subplots

    lengths = [r for r in rows if r["kind"] == "length"]
    angles = [r for r in rows if r["kind"] == "angle"]
    fig = make_subplots(
        rows=1, cols=2, column_widths=[0.5, 0.5], subplot_titles=("lengths: Δ mm", "angles: Δ deg")
    )
    for col, group in ((1, lengths), (2, angles)):
        if not group:
            continue
        x = [r["name"] for r in group]
        fig.add_trace(
            go.Bar(
                x=x,
                y=[r["delta"] for r in group],
                name="identified Δ ± 3σ",
                marker_color=AFTER,
                error_y={"type": "data", "array": [3 * r["std"] for r in group], "color": "#333"},
                showlegend=col == 1,
            ),
            row=1,
            col=col,
        )
        truth = [r.get("true") for r in group]
        if any(t is not None for t in truth):
            fig.add_trace(
                go.Scatter(
                    x=x,
                    y=truth,
                    mode="markers",
                    name="true Δ (simulation)",
                    marker={"symbol": "x", "size": 9, "color": BEFORE},
                    showlegend=col == 1,
                ),
                row=1,
                col=col,
            )
    fig.update_layout(
        title="robot parameters: identified change from nominal",
        legend=LEGEND_BELOW,
        margin={"t": 60, "b": 90},
    )
    return fig


def _fig_hist_pair(before: Array | None, after: Array, title: str, after_label: str = "after calibration"):
    import plotly.graph_objects as go
    from plotly.subplots import make_subplots

    cols = 2 if before is not None else 1
    titles = ("before calibration", after_label) if before is not None else (after_label,)
    fig = make_subplots(rows=1, cols=cols, subplot_titles=titles)
    if before is not None:
        fig.add_trace(
            go.Histogram(x=before * 1e3, marker_color=BEFORE, name="before", nbinsx=30), row=1, col=1
        )
    fig.add_trace(go.Histogram(x=after * 1e3, marker_color=AFTER, name="after", nbinsx=30), row=1, col=cols)
    for c in range(1, cols + 1):
        fig.update_xaxes(title_text="position error mm", row=1, col=c)
    fig.update_yaxes(title_text="poses", row=1, col=1)
    fig.update_layout(title=title, showlegend=False, bargap=0.05, margin={"t": 60})
    return fig


def _fig_per_pose(before: Array | None, after: Array, title: str):
    import plotly.graph_objects as go

    x = np.arange(1, len(after) + 1)
    fig = go.Figure()
    if before is not None:
        fig.add_trace(go.Bar(x=x, y=before * 1e3, name="before calibration", marker_color=BEFORE))
    fig.add_trace(go.Bar(x=x, y=after * 1e3, name="after calibration", marker_color=AFTER))
    fig.update_layout(
        barmode="group",
        yaxis={"type": "log", "dtick": 1},  # decades only: minor labels read "2, 1, 5"
        xaxis_title="pose",
        yaxis_title="position error mm (log)",
        title=title,
        legend=LEGEND_BELOW,
        margin={"t": 40, "b": 90},
        bargap=0.15,
    )
    return fig


def _arrow_scale(points: Array, vectors: Array) -> float:
    size = float(np.ptp(points, axis=0).max()) if len(points) > 1 else 1.0
    longest = float(np.linalg.norm(vectors, axis=1).max()) if len(vectors) else 0.0
    if longest <= 0:
        return 1.0
    raw = 0.2 * size / longest
    decade = 10 ** math.floor(math.log10(raw))
    return float(decade * max(m for m in (1, 2, 5) if m * decade <= raw))


def _fig_error_vectors(points: Array, before: Array | None, after: Array, title: str):
    import plotly.graph_objects as go

    fig = go.Figure()
    p = points * 1e3
    fig.add_trace(
        _points3d(
            p,
            mode="markers",
            name="measured position",
            marker={"size": 2, "color": "#444"},
        )
    )
    for label, vec, colour, visible in (
        ("before", before, BEFORE, "legendonly"),
        ("after", after, AFTER, True),
    ):
        if vec is None:
            continue
        k = _arrow_scale(points, vec)
        tips = p + vec * 1e3 * k
        seg = np.stack([p, tips, np.full_like(p, np.nan)], axis=1).reshape(-1, 3)
        fig.add_trace(
            _points3d(
                seg,
                mode="lines",
                visible=visible,
                name=f"error {label} calibration × {k:g}",
                line={"color": colour, "width": 4},
            )
        )
    fig.update_layout(
        title=title,
        legend={"orientation": "h"},
        margin={"l": 0, "r": 0, "t": 40, "b": 0},
        scene={
            "aspectmode": "data",
            "xaxis_title": "x mm",
            "yaxis_title": "y mm",
            "zaxis_title": "z mm",
            "camera": {"eye": {"x": 1.6, "y": -1.6, "z": 0.9}},
        },
    )
    return fig


def _fig_path_errors(paths: Sequence[dict[str, Any]]):
    import plotly.graph_objects as go
    from plotly.subplots import make_subplots

    fig = make_subplots(rows=1, cols=len(paths), subplot_titles=[p["name"] for p in paths])
    for col, path in enumerate(paths, start=1):
        c = np.asarray(path["commanded"])
        s = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(c, axis=0), axis=1))] * 1e3
        for case, pa in path["accuracy"].items():
            fig.add_trace(
                go.Scatter(
                    x=s,
                    y=pa.at * 1e3,
                    mode="lines",
                    name=case,
                    showlegend=col == 1,
                    line={"color": CASE_COLOURS.get(case, AFTER), "width": 2},
                ),
                row=1,
                col=col,
            )
        fig.update_xaxes(title_text="along the path mm", row=1, col=col)
    fig.update_yaxes(type="log", dtick=1, title_text="distance mm (log)", row=1, col=1)
    for col in range(2, len(paths) + 1):
        fig.update_yaxes(type="log", dtick=1, row=1, col=col)
    fig.update_layout(
        title="path accuracy along the test paths (barycentre of the cycles, ISO 9283 §8.2)",
        legend=LEGEND_BELOW,
        margin={"t": 60, "b": 90},
    )
    return fig


def _fig_compliance(displacement: Array):
    import plotly.graph_objects as go

    fig = go.Figure(go.Histogram(x=displacement * 1e3, marker_color=AFTER, nbinsx=30))
    fig.update_layout(
        xaxis_title="tool displacement caused by the identified joint effects mm",
        yaxis_title="poses",
        title="size of the joint effects over the poses",
        margin={"t": 40},
    )
    return fig


# ---------------------------------------------------------------------- sections
def _model_choice_section(result: CalibrationResult, figs: Any) -> str:
    """The cross-validation table and, when chosen, the learned joint angle errors."""
    import plotly.graph_objects as go

    from robocal.identify.residual import SELECTION_SE, CVTable

    table = CVTable.from_dict(result.metadata["cv"])
    rows = [
        [
            c.name + (" (chosen)" if c.name == table.chosen else ""),
            f"{c.cv_mean * 1e3:.4f}",
            f"{c.cv_rms * 1e3:.4f}",
            f"{c.fit_seconds * 1e3:.0f}",
        ]
        for c in table.candidates
    ]
    body = _table(["candidate", "CV mean mm", "CV RMS mm", "fit ms"], rows)
    learned = result.model.residual
    if learned is not None:
        fig = go.Figure()
        for k, (name, j) in enumerate(zip(learned.joints, learned.joint_index, strict=True)):
            lo, hi = np.clip(result.model.joint_limits[j], -math.pi, math.pi)
            q = np.zeros((400, result.model.dof))
            q[:, j] = np.linspace(lo, hi, 400)
            fig.add_trace(
                go.Scatter(
                    x=np.degrees(q[:, j]), y=learned.angle_errors(q)[:, k] * 1e6, name=name, mode="lines"
                )
            )
        fig.update_layout(
            xaxis_title="joint angle (°)", yaxis_title="learned angle error δθ (µrad)", margin={"t": 30}
        )
        body += figs.html(fig, "residual", 380)
        body += (
            f"<p class='note'>{learned.harmonics} harmonics per revolution; what remains: "
            f"σ {learned.noise_std * 1e3:.4f} mm per axis (the evidence's estimate).</p>"
        )
    return _section(
        "model-choice",
        "Model choice",
        body,
        f"{table.folds}-fold cross-validation on the calibration poses compared the physical model "
        "(geometry, and geometry with joint compliance when the model has masses), alone and with learned "
        "per-joint angle errors (a Fourier series in the joint's own angle, fitted with the geometry under "
        f"a Gaussian-process prior). It chose <b>{_e(table.chosen)}</b>: the simplest candidate whose CV "
        f"error is within {SELECTION_SE:g} standard errors (over the poses) of the lowest. Held-out poses "
        "played no part in the choice.",
    )


def _section(ident: str, title: str, body: str, intro: str = "") -> str:
    lead = f"<p class='intro'>{intro}</p>" if intro else ""
    return f"<section id='{ident}'><h2>{_e(title)}</h2>{lead}{body}</section>"


def _stats_rows(rows: Sequence[tuple[str, ValidationStats | Mapping[str, Any] | None]]) -> list[list[Any]]:
    out = []
    for name, s in rows:
        if s is None:
            continue
        d = s.to_dict() if isinstance(s, ValidationStats) else s
        axes = " / ".join(_f(v) for v in d.get("axis_mean_abs_mm", [])) or "–"
        out.append([name, d["n"], _f(d["mean_mm"]), _f(d["rms_mm"]), _f(d["p95_mm"]), _f(d["max_mm"]), axes])
    return out


STATS_HEADER = ("model", "poses", "mean mm", "RMS mm", "p95 mm", "max mm", "|x| / |y| / |z| mean mm")


def _seed_table_html(table: ErrorTable, caption: str) -> str:
    header = ["", "quantity", *table.cases]
    imp_cases = list(table.improvements)
    header += [f"improvement ({c}) %" for c in imp_cases]
    rows = []
    for stat, arr in (("minimum", table.minimum), ("maximum", table.maximum), ("average", table.average)):
        for i, q in enumerate(table.quantities):
            unit = " °" if q in ERROR_QUANTITIES[4:] else " mm"
            row: list[Any] = [stat if i == 0 else "", q + unit]
            row += [table.display(i, arr[i, j]) for j in range(len(table.cases))]
            for c in imp_cases:
                imp = table.improvements[c].get(q)
                row.append(
                    f"{imp.percent:.1f} ({imp.percent_low:.1f} to {imp.percent_high:.1f})"
                    if (stat == "average" and imp is not None)
                    else ""
                )
            rows.append(row)
    return _table(header, rows, "seed", caption)


def _parameter_rows(result: CalibrationResult, truth: Mapping[str, float]) -> list[dict[str, Any]]:
    rot = {s.name: s.is_rotation for s in (result.measurement_chain or result.model).steps}
    rows = []
    for n, v0, v, s in zip(result.names, result.nominal, result.estimates, result.std, strict=True):
        if n.startswith(COMPLIANCE_PREFIX):
            continue
        is_rot = rot.get(n, False)
        f = math.degrees(1) if is_rot else 1e3
        true = truth.get(n)
        rows.append(
            {
                "name": n,
                "kind": "angle" if is_rot else "length",
                "unit": "deg" if is_rot else "mm",
                "group": "device frame"
                if n.startswith(FRAME_PREFIX)
                else ("tool" if n.startswith(TOOL_PREFIX) else "robot"),
                "start": v0 * f,
                "estimate": v * f,
                "delta": (v - v0) * f,
                "std": s * f,
                "true": None if true is None else true * f,
            }
        )
    return rows


def _effect_estimates(result: CalibrationResult) -> dict[str, dict[str, tuple[float, float | None]]]:
    """Joint effects other than compliance (``CalibrationResult.effect_estimates`` where this
    robocal has it), ``{joint: {field: (value, σ or None)}}``."""
    method = getattr(result, "effect_estimates", None)
    if method is None:
        return {}
    try:
        return dict(method() or {})
    except (AttributeError, KeyError, ImportError, ValueError):  # a result of another robocal version
        return {}


def _observability(
    result: CalibrationResult, data: Measurements
) -> tuple[dict[str, float], Array, tuple[str, ...]] | None:
    from robocal.identify.observability import observability, scaled_jacobian, singular_values

    chain = result.measurement_chain
    if chain is None or not chain.free_names or data.dof != result.model.dof:
        return None
    rows = "pose" if result.measure == "pose" else "position"
    idx = observability(chain, data.q, rows=rows, scale="tolerance").as_dict()
    Js, _, names = scaled_jacobian(chain, data.q, rows=rows, scale="norm")
    return idx, singular_values(Js), names


# ---------------------------------------------------------------------- the report
CSS = (
    f":root {{ --before: {BEFORE}; --after: {AFTER}; --comp: {COMPENSATED}; }}\n"
    + """
* { box-sizing: border-box; }
body {
  font-family: system-ui, -apple-system, "Segoe UI", sans-serif;
  margin: 0;
  color: #1f2328;
  background: #f6f7f9;
}
header { background: #1f2933; color: #fff; padding: 1.4rem 2rem 1rem; }
header h1 { margin: 0 0 .3rem; font-size: 1.6rem; font-weight: 600; }
header p { margin: 0; color: #c9d1d9; }
nav {
  position: sticky;
  top: 0;
  z-index: 10;
  background: #fff;
  border-bottom: 1px solid #d0d7de;
  padding: .45rem 2rem;
}
nav a {
  color: #1b6ca8;
  text-decoration: none;
  margin-right: 1.1rem;
  font-size: .9rem;
  white-space: nowrap;
}
nav a:hover { text-decoration: underline; }
main { max-width: 1250px; margin: 0 auto; padding: 1rem 2rem 3rem; }
section {
  background: #fff;
  border: 1px solid #d0d7de;
  border-radius: 8px;
  padding: 1rem 1.4rem 1.2rem;
  margin: 1.2rem 0;
}
h2 { font-size: 1.25rem; margin: .2rem 0 .6rem; }
h3 { font-size: 1.02rem; margin: 1.1rem 0 .4rem; }
p.intro, p.note { color: #57606a; font-size: .92rem; max-width: 62rem; }
.cards { display: grid; grid-template-columns: repeat(auto-fit, minmax(210px, 1fr)); gap: .8rem; }
.card { border: 1px solid #d0d7de; border-radius: 8px; padding: .7rem .9rem; background: #fbfcfd; }
.card .label { font-size: .8rem; color: #57606a; text-transform: uppercase; letter-spacing: .03em; }
.card .value {
  font-size: 1.35rem;
  font-weight: 600;
  margin-top: .2rem;
  font-variant-numeric: tabular-nums;
}
.card .sub { font-size: .85rem; color: #57606a; }
.before { color: var(--before); } .after { color: var(--after); } .comp { color: var(--comp); }
table { border-collapse: collapse; font-size: .86rem; margin: .4rem 0 .8rem; }
caption {
  caption-side: top;
  text-align: left;
  color: #57606a;
  font-size: .85rem;
  padding-bottom: .3rem;
}
th { background: #f0f3f6; font-weight: 600; text-align: left; }
td, th { border-bottom: 1px solid #e1e4e8; padding: .25rem .65rem; vertical-align: top; }
td.num { text-align: right; font-variant-numeric: tabular-nums; white-space: nowrap; }
tr:hover td { background: #f6f8fa; }
.grid2 { display: grid; grid-template-columns: 1fr 1fr; gap: 1rem; }
@media (max-width: 900px) { .grid2 { grid-template-columns: 1fr; } }
.figure { margin: .4rem 0 .8rem; }
code { background: #f0f3f6; padding: 0 .25rem; border-radius: 3px; }
footer { color: #57606a; font-size: .8rem; text-align: center; padding: 1rem; }
"""
)


def build_report(
    result: CalibrationResult,
    *,
    data: Measurements | None = None,
    test_data: Measurements | None = None,
    evaluation: Mapping[str, Any] | None = None,
    title: str | None = None,
) -> str:
    """The report as one HTML string (see the module docstring)."""
    from robocal import __version__
    from robocal.model.view import model_figure

    ev = dict(evaluation or {})
    figs = _Figures()
    model = result.model
    truth = ev.get("truth", {})
    sections: list[tuple[str, str, str]] = []  # (id, nav label, html)
    for name, d in (("calibration data", data), ("held-out data", test_data)):
        if d is not None and d.dof != model.dof:
            raise ValueError(
                f"{name} has {d.dof} joint columns but model {model.name!r} has {model.dof} joints"
            )

    train_after = validate(result, data) if data is not None and data.position is not None else None
    train_before = before_validation(result, data) if data is not None else None
    test_after = (
        validate(result, test_data) if test_data is not None and test_data.position is not None else None
    )
    test_before = before_validation(result, test_data) if test_data is not None else None
    stored_validation = result.metadata.get("validation") if isinstance(result.metadata, dict) else None

    # ISO 9283 characteristics from the evaluation
    iso = ev.get("iso_poses")
    iso_chars = {}
    if iso:
        for case, attained in iso["cases"].items():
            iso_chars[case] = iso9283_pose_characteristics(iso["commanded"], attained, iso["labels"])
    paths = []
    for path in ev.get("paths", []):
        acc = {case: path_accuracy(path["commanded"], attained) for case, attained in path["cases"].items()}
        paths.append({**path, "accuracy": acc})

    # ---- summary
    cards = []
    if test_after is not None:
        ref = test_before
        sub = f"{test_after.n} held-out poses"
        value = f"<span class='after'>{_f(test_after.mean * 1e3)} mm</span>"
        if ref is not None:
            value = f"<span class='before'>{_f(ref.mean * 1e3)}</span> → " + value
            imp = improvement(ref.errors, test_after.errors)
            sub += f"; {imp.percent:.1f} % smaller (95 % CI {imp.percent_low:.1f}–{imp.percent_high:.1f})"
        cards.append(("mean error on held-out poses", value, sub))
    elif stored_validation:
        cards.append(
            (
                "mean error on held-out poses",
                f"<span class='after'>{_f(stored_validation['mean_mm'])} mm</span>",
                f"{stored_validation['n']} held-out poses (stored)",
            )
        )
    cards.append(
        (
            "RMS error on calibration poses",
            f"<span class='before'>{_f(result.rms_before * 1e3)}</span> → <span class='after'>"
            f"{_f(result.rms_after * 1e3, 4)} mm</span>",
            f"{result.n} poses, {result.method}, {result.iterations} "
            f"iterations, {result.seconds * 1e3:.0f} ms",
        )
    )
    n_geo = sum(not n.startswith(COMPLIANCE_PREFIX) for n in result.names)
    n_eff = len(result.names) - n_geo
    cards.append(
        (
            "identified parameters",
            f"{n_geo}" + (f" + {n_eff} compliances" if n_eff else ""),
            f"{len(result.dropped)} not identified; condition number {_g(result.condition_number)}",
        )
    )
    if iso_chars:
        vals = {case: max(a.AP for a in ch.accuracy) for case, ch in iso_chars.items()}
        text = " → ".join(
            f"<span class='{'before' if 'nominal' in c else 'comp'}'>{_f(v * 1e3)}</span>"
            for c, v in vals.items()
        )
        cards.append(("ISO 9283 AP, worst of P1–P5", text + " mm", " → ".join(vals)))
    if paths:
        p0 = paths[0]
        vals = {case: pa.AT for case, pa in p0["accuracy"].items()}
        text = " → ".join(
            f"<span class='{'before' if 'nominal' in c else 'comp'}'>{_f(v * 1e3)}</span>"
            for c, v in vals.items()
        )
        cards.append((f"ISO 9283 AT, {p0['name']}", text + " mm", " → ".join(vals)))
    card_html = "".join(
        f"<div class='card'><div class='label'>{_e(label)}</div><div class='value'>{value}</div>"
        f"<div class='sub'>{_e(sub)}</div></div>"
        for label, value, sub in cards
    )
    status = "converged" if result.success else "NOT CONVERGED"
    message = result.message
    if message.lower().startswith(status.lower() + ":"):  # the solver's message may say it already
        message = message[len(status) + 1 :].strip()
    summary = f"<div class='cards'>{card_html}</div>"
    summary += (
        f"<p class='note'>{_e(model.name)}: {result.measure} measurements, method {result.method} ({status}: "
        f"{_e(message)}). Before calibration = the nominal "
        "model with the device frame and tool fitted "
        "to the calibration data, the starting point of the identification.</p>"
    )
    sections.append(("summary", "Summary", _section("summary", "Summary", summary)))

    # ---- robot and model
    fig = model_figure(model, title=f"{model.name} at zero joint values (calibrated)")
    links = [
        n.strip().removesuffix(" calibrated") for n in model.notes.split(";") if n.strip().startswith("link")
    ]
    body = figs.html(fig, "model", 560)
    info = [
        ["robot", model.title or model.name],
        ["joints", f"{model.dof} ({''.join('R' if t == 'revolute' else 'P' for t in model.joint_types)})"],
        ["steps (elementary transforms)", len(model.steps)],
        ["mass properties", "yes" if model.bodies else "no"],
    ]
    body += "<div class='grid2'><div>" + _table(["", ""], info) + "</div><div>"
    if links:
        body += _table(["link parameterisation (seed 000)"], [[n] for n in links])
    body += "</div></div>"
    if model.source:
        body += f"<p class='note'>source: {_e(model.source)}</p>"
    sections.append(
        (
            "model",
            "Robot & model",
            _section(
                "model",
                "Robot and model",
                body,
                "The calibrated chain at zero joint values: every joint frame "
                "(x red, y green, z blue), the base and the "
                "measured tool point. Drag to rotate.",
            ),
        )
    )

    # ---- model choice and the learned residual
    if "cv" in result.metadata:
        sections.append(("model-choice", "Model choice", _model_choice_section(result, figs)))

    # ---- data
    sets = [
        (n, d, c)
        for n, d, c in (("calibration poses", data, AFTER), ("held-out poses", test_data, GEOMETRIC))
        if d is not None
    ]
    if sets:
        body = figs.html(_fig_coverage(result, sets, ev), "coverage", 600)
        body += figs.html(_fig_joint_coverage(model, sets), "joint-coverage", 380)
        rows = []
        for name, d, _ in sets:
            p = model.fk(d.q)[:, :3, 3] * 1e3
            ext = " × ".join(f"{v:.0f}" for v in np.ptp(p, axis=0))
            sig = "–" if d.sigma is None else f"{np.median(d.sigma) * 1e3:.4f}"
            rows.append([name, d.n, d.observes, ext, sig, d.metadata.get("device", "–")])
        body += _table(["set", "poses", "observed", "extent x × y × z mm", "median σ mm", "device"], rows)
    else:
        body = "<p class='note'>No measurements were given to the report.</p>"
    sections.append(
        (
            "data",
            "Data",
            _section(
                "data",
                "Data: pose coverage",
                body,
                "Where the measured poses put the tool (computed with the "
                "calibrated model) and how much of each "
                "joint's range they use. Good coverage makes every parameter observable.",
            ),
        )
    )

    # ---- identifiability
    body = ""
    obs = _observability(result, data) if data is not None else None
    rows = [
        ["condition number (column-scaled Jacobian)", _g(result.condition_number)],
        ["identified parameters", len(result.names)],
        ["not identified", len(result.dropped)],
    ]
    if obs:
        idx = obs[0]
        rows += [
            [f"{k} ({desc})", _g(v)]
            for (k, v), desc in zip(
                idx.items(),
                (
                    "D-optimal, geometric mean of σ / √n",
                    "inverse condition number",
                    "smallest singular value",
                    "noise amplification σ²min/σmax",
                    "A-optimal",
                ),
                strict=True,
            )
        ]
    body += "<div class='grid2'><div>" + _table(["identifiability", "value"], rows)
    body += (
        "<p class='note'>O1–O5 from the Jacobian with columns scaled by the expected parameter errors "
        "(0.1 mm, 0.05°; Sun &amp; Hollerbach 2008): larger is better.</p></div><div>"
    )
    if obs:
        body += figs.html(_fig_singular_values(obs[1], obs[2]), "singular-values", 340)
    body += "</div></div>"
    if result.dropped:
        drows = []
        for d in result.dropped:
            why = {
                "redundant": "redundant",
                "no effect": "no effect on the measurements",
                "poorly identifiable": "poorly identifiable",
                "unphysical": "outside its physical range (≥ 0)",
                "undetermined": "not told from zero by the data",
            }.get(d.reason, d.reason)
            detail = ", ".join(f"{n} ({c:+.3g})" for n, c in d.absorbed_by) if d.absorbed_by else ""
            if d.sigma is not None:
                detail = f"σ {d.sigma * 1e3:.3g} mm as tool displacement; kept at its start value"
            detail = getattr(d, "detail", "") or detail
            drows.append([d.name, why, detail])
        body += _table(["parameter not identified", "reason", "absorbed by (coefficient) / detail"], drows)
    corr = result.high_correlations
    if corr:
        body += _table(
            ["parameter", "parameter", "correlation"],
            [[a, b, f"{r:+.3f}"] for a, b, r in corr],
            caption="pairs correlated above 0.9",
        )
    sections.append(
        (
            "identifiability",
            "Identifiability",
            _section(
                "identifiability",
                "Identifiability",
                body,
                "Which parameters these measurements can determine. A "
                "redundant parameter is absorbed by the ones "
                "listed (its column is their combination); a poorly "
                "identifiable one would move the tool by more than "
                "0.5 mm at one σ and is left at its start value.",
            ),
        )
    )

    # ---- parameters
    prow = _parameter_rows(result, truth.get("parameter_deltas", {}))
    has_truth = any(r["true"] is not None for r in prow)
    header = ["parameter", "group", "unit", "start", "estimate", "Δ", "σ", "|Δ|/σ"] + (
        ["true Δ"] if has_truth else []
    )
    rows = []
    for r in prow:
        digits = 4 if r["unit"] == "mm" else 5
        ratio = abs(r["delta"]) / r["std"] if r["std"] > 0 else float("nan")
        row = [
            r["name"],
            r["group"],
            r["unit"],
            _f(r["start"], digits),
            _f(r["estimate"], digits),
            f"{r['delta']:+.{digits}f}",
            _f(r["std"], digits),
            _f(ratio, 1),
        ]
        if has_truth:
            row.append("–" if r["true"] is None else f"{r['true']:+.{digits}f}")
        rows.append(row)
    robot_rows = [r for r in prow if r["group"] == "robot"]
    body = figs.html(_fig_parameters(robot_rows), "parameters", 420) if robot_rows else ""
    body += _table(header, rows)
    if has_truth:
        body += (
            "<p class='note'>True Δ: the simulation's parameter errors. A parameter whose true error is "
            "absorbed by another (see Identifiability) is compared with a combination, not itself.</p>"
        )
    sections.append(
        (
            "parameters",
            "Parameters",
            _section(
                "parameters",
                "Identified parameters",
                body,
                "Estimates with their change from the start values and one "
                "standard deviation σ from the residual "
                "scatter (σ̂²(JᵀWJ)⁻¹). Lengths in mm, angles in degrees; "
                "device-frame corrections and the tool point "
                "are identified with the robot.",
            ),
        )
    )

    # ---- residuals
    if train_after is not None:
        before_e = train_before.errors if train_before is not None else None
        body = _table(
            STATS_HEADER,
            _stats_rows([("before calibration", train_before), ("after calibration", train_after)]),
            caption=f"position error on the {train_after.n} calibration poses",
        )
        body += figs.html(
            _fig_hist_pair(before_e, train_after.errors, "residuals on the calibration poses"),
            "residual-histogram",
            340,
        )
        body += figs.html(
            _fig_per_pose(before_e, train_after.errors, "residual per calibration pose"),
            "residual-per-pose",
            340,
        )
        points = data.position @ result.frame[:3, :3] - result.frame[:3, 3] @ result.frame[:3, :3]
        vb = _base_errors(result, train_before).delta if train_before is not None else None
        body += figs.html(
            _fig_error_vectors(
                points,
                vb,
                _base_errors(result, train_after).delta,
                "residual vectors at the calibration poses (robot base frame, exaggerated)",
            ),
            "error-vectors",
            560,
        )
    else:
        body = (
            f"<p class='note'>RMS on the {result.n} calibration poses: {_f(result.rms_before * 1e3, 4)} mm "
            f"before, {_f(result.rms_after * 1e3, 4)} mm after. Pass the calibration data for plots.</p>"
        )
    sections.append(
        (
            "residuals",
            "Residuals",
            _section(
                "residuals",
                "Residuals before and after",
                body,
                "Predicted minus measured tool positions on the poses used "
                "for the calibration. Arrows are magnified "
                "by the factor in the legend; click 'error before "
                "calibration' to show the errors of the nominal model.",
            ),
        )
    )

    # ---- validation
    if test_after is not None:
        comparison = ev.get("comparison")
        if comparison:
            rows = _stats_rows([(c["model"], c) for c in comparison if "n" in c])
        else:
            rows = _stats_rows([("before calibration", test_before), ("after calibration", test_after)])
        body = _table(
            STATS_HEADER,
            rows,
            caption=f"position error on {test_after.n} held-out poses (not used by the calibration)",
        )
        if test_after.expected_rms is not None:
            verdict = (
                "more than 1.5× the expectation: the robot or device changed, or the model misses "
                "errors the calibration poses did not show"
                if test_after.worse_than_expected
                else "as expected"
            )
            body += (
                "<p class='note'>The calibration expected an RMS error of "
                f"{_f(test_after.expected_rms * 1e3, 4)} mm "
                f"on these poses ({_f(test_after.parameter_rms * 1e3, 4)} mm from the uncertainty of its "
                f"parameters, propagated through the Jacobian; the rest measurement noise and any error "
                f"its residuals showed beyond it); measured {_f(test_after.rms * 1e3, 4)} mm: {verdict}.</p>"
            )
        body += figs.html(
            _fig_hist_pair(
                test_before.errors if test_before is not None else None,
                test_after.errors,
                "errors on the held-out poses",
            ),
            "validation-histogram",
            340,
        )
        if test_before is not None:
            table = error_table(
                {
                    "before calibration": _base_errors(result, test_before),
                    "after calibration": _base_errors(result, test_after),
                }
            )
            body += "<h3>The seeds' table: minimum, maximum and average errors</h3>"
            body += _seed_table_html(
                table,
                "robot base frame; improvement of the average with its 95 % confidence "
                "interval (paired, delta method)",
            )
        if test_data.orientation is not None and test_before is not None:
            body += _orientation_table(result, test_data)
    elif stored_validation:
        body = _table(STATS_HEADER, _stats_rows([("after calibration (stored)", stored_validation)]))
    else:
        body = "<p class='note'>No held-out measurements were given.</p>"
    sections.append(
        (
            "validation",
            "Validation",
            _section(
                "validation",
                "Held-out validation",
                body,
                "The honest test: poses the calibration never saw, "
                "predicted with the calibrated device frame.",
            ),
        )
    )

    # ---- ISO 9283
    if iso_chars or paths:
        body = ""
        if iso_chars:
            rows = []
            for case, ch in iso_chars.items():
                for r in ch.rows():
                    rows.append(
                        [
                            case if r["pose"] == ch.labels[0] else "",
                            r["pose"],
                            r["n"],
                            _f(r["AP_mm"]),
                            f"{r['APx_mm']:+.3f}",
                            f"{r['APy_mm']:+.3f}",
                            f"{r['APz_mm']:+.3f}",
                            _f(r["RP_mm"]),
                        ]
                    )
            cube = iso.get("cube", {})
            caption = (
                f"pose accuracy AP and repeatability RP (mm) at P1–P5, {iso.get('cycles', '?')} cycles; "
                f"cube side {cube.get('side', float('nan')) * 1e3:.0f} mm, "
                f"diagonal plane {cube.get('plane', 1)}"
            )
            body += _table(
                ["commands", "pose", "cycles", "AP", "APx", "APy", "APz", "RP"], rows, caption=caption
            )
        if paths:
            rows = []
            for path in paths:
                for case, pa in path["accuracy"].items():
                    rows.append(
                        [
                            path["name"],
                            case,
                            pa.n_cycles,
                            _f(pa.AT * 1e3),
                            _f(pa.RT * 1e3),
                            _f(float(np.nanmean(pa.at)) * 1e3),
                        ]
                    )
            body += _table(
                ["path", "commands", "cycles", "AT mm", "RT mm", "mean distance mm"],
                rows,
                caption="path accuracy AT and repeatability RT (ISO 9283 §8.2–8.3)",
            )
        body += (
            "<p class='note'>AP: distance from the commanded position to the barycentre of the attained "
            "positions; RP = l̄ + 3 S_l; AT: largest distance from the commanded path to the barycentre of "
            "the attained paths in the normal planes; RT = max(l̄ᵢ + 3 S_lᵢ). Attained positions: "
            "measured by the device, mapped into the robot base frame with the calibrated frame.</p>"
        )
        sections.append(
            (
                "iso9283",
                "ISO 9283",
                _section(
                    "iso9283",
                    "ISO 9283 performance",
                    body,
                    "Pose and path characteristics of ISO 9283:1998 in the "
                    "largest test cube of the workspace, with the "
                    "nominal joint commands and with commands compensated by the calibrated model.",
                ),
            )
        )

    elif ev.get("iso_error"):
        sections.append(
            (
                "iso9283",
                "ISO 9283",
                _section(
                    "iso9283",
                    "ISO 9283 performance",
                    f"<p class='note'>Not measured: {_e(ev['iso_error'])}</p>",
                ),
            )
        )

    # ---- joint effects
    other = _effect_estimates(result)
    held = [d for d in result.dropped if d.reason in ("unphysical", "undetermined")]
    if result.compliance or other or held:
        body = ""
        if result.compliance:
            comp_idx = {
                n.removeprefix(COMPLIANCE_PREFIX): k
                for k, n in enumerate(result.names)
                if n.startswith(COMPLIANCE_PREFIX)
            }
            true_c = truth.get("compliance_rad_per_Nm", {})
            rows = []
            for joint, c in result.compliance.items():
                s = result.std[comp_idx[joint]] if joint in comp_idx else float("nan")
                k = 1 / c if c > 0 else float("nan")
                row = [joint, f"{c * 1e6:.3f}", _f(s * 1e6), _g(k / 1e3, 4)]
                if true_c:
                    row.append(f"{true_c.get(joint, 0.0) * 1e6:.3f}")
                rows.append(row)
            header = ["joint", "compliance µrad/(N·m)", "σ", "stiffness kN·m/rad"] + (
                ["true µrad/(N·m)"] if true_c else []
            )
            body += _table(header, rows, caption="joint compliance under gravity: δθ = −c τ(q)")
        if other:
            rows = [
                [joint, name, f"{value:.6g}", "–" if sigma is None else f"{sigma:.3g}"]
                for joint, fields in other.items()
                for name, (value, sigma) in fields.items()
            ]
            body += _table(
                ["joint", "effect parameter", "value (SI)", "σ"],
                rows,
                caption="joint effects of the calibrated model (clearance tilt, backlash, stiffness: "
                "robocal.model.joints); σ – where predicted, not identified",
            )
        if held:  # physically >= 0 and told from zero by the data, or not identified
            body += _table(
                ["joint effect", "not identified because"],
                [[d.name, d.detail or d.reason] for d in held],
                caption="joint effects below zero or within 3σ of it: kept at their start values",
            )
        q_eff = test_data.q if test_data is not None else (data.q if data is not None else None)
        pert = result.joint_perturbations(q_eff) if q_eff is not None else None
        if pert is not None:
            disp = np.linalg.norm(model.fk(q_eff, pert)[:, :3, 3] - model.fk(q_eff)[:, :3, 3], axis=1)
            body += figs.html(_fig_compliance(disp), "joint-effects", 320)
            body += (
                "<p class='note'>The identified joint effects move the tool by "
                f"{_f(disp.mean() * 1e3)} mm on average and up to {_f(disp.max() * 1e3)} mm over these "
                "poses: errors a geometric model cannot represent.</p>"
            )
        sections.append(
            (
                "joint-effects",
                "Joint effects",
                _section(
                    "joint-effects",
                    "Joint effects",
                    body,
                    "Non-geometric errors of the joints, identified with the geometry. Compliance under "
                    "gravity: each joint gives way by δθ = −c τ(q), τ the torque holding the arm against "
                    "gravity (Pinocchio, from the model's masses).",
                ),
            )
        )

    # ---- compensation
    comp = ev.get("compensation")
    if comp or paths:
        body = ""
        if comp:
            body += _table(
                ["compensation", ""],
                [["method", comp.get("method", "–")]]
                + [
                    [k.replace("_", " "), _g(v, 4) if isinstance(v, float) else v]
                    for k, v in comp.items()
                    if k != "method"
                ],
            )
        if paths:
            body += figs.html(_fig_path_errors(paths), "compensation-paths", 380)
        sections.append(
            (
                "compensation",
                "Compensation",
                _section(
                    "compensation",
                    "Compensation",
                    body,
                    "Joint commands corrected so that the calibrated robot (with "
                    "its joint effects) puts the tool on the "
                    "target, compared with the nominal commands on the same targets.",
                ),
            )
        )

    # ---- the fourteen ISO 9283 characteristics of a measurement log (robocal iso9283)
    if ev.get("iso9283"):
        sections.append(("iso9283", "ISO 9283 log", _iso9283_section(ev["iso9283"])))

    # ---- provenance
    rows = [
        ["robocal", __version__],
        ["written", _dt.datetime.now().isoformat(timespec="seconds")],
        ["method", result.method],
        ["iterations", result.iterations],
        ["calibration time", f"{result.seconds * 1e3:.1f} ms"],
        ["residual σ", f"{result.residual_std * 1e3:.4f} mm"],
    ]
    if result.fit_to_noise is not None:
        rows.append(["residuals against the stated noise", result.fit_to_noise.summary()])
    rows += [["warning", w] for w in result.metadata.get("warnings", [])]
    for key in ("data_file", "data_sha256", "train_n", "seed", "source"):
        if key in result.metadata:
            rows.append([key.replace("_", " "), result.metadata[key]])
    for step, sec in ev.get("timings_s", {}).items():
        rows.append([f"time: {step}", f"{sec:.2f} s"])
    sections.append(
        ("provenance", "Provenance", _section("provenance", "Provenance", _table(["", ""], rows)))
    )

    nav = "".join(f"<a href='#{ident}'>{_e(label)}</a>" for ident, label, _ in sections)
    heading = title or f"Calibration report: {model.name}"
    sub = f"{_e(model.title or model.name)} · {result.measure} measurements · {result.n} calibration poses"
    if test_data is not None:
        sub += f" · {test_data.n} held-out poses"
    return f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8">
<meta name="viewport" content="width=device-width, initial-scale=1">
<title>{_e(heading)}</title>
<style>{CSS}</style></head><body>
<header><h1>{_e(heading)}</h1><p>{sub}</p></header>
<nav>{nav}</nav>
<main>
{"".join(s for _, _, s in sections)}
</main>
<footer>robocal {__version__} — self-contained report: no external resources.</footer>
</body></html>
"""


def _iso9283_section(iso: Mapping[str, Any]) -> str:
    """The table of ``robocal iso9283 --json`` (``Iso9283Results.to_dict()``)."""
    rows = [
        [c["number"], f"{c['name']} ({c['symbols']})", c["clause"], c["summary"], c["cycles"]]
        for c in iso.get("characteristics", [])
    ]
    intro = (
        f"From the measurement log {_e(iso.get('source', '?'))} (limit band "
        f"{_e(iso.get('limit_band_mm', '?'))} mm); clauses of ISO 9283:1998, read as docs/iso9283.md states."
    )
    body = _table(["#", "characteristic", "clause", "result", "cycles (ISO)"], rows)
    return _section("iso9283", "ISO 9283 characteristics of a measurement log", body, intro)


def _orientation_table(result: CalibrationResult, data: Measurements) -> str:
    """Seed table with orientation errors (x-y-z angles) for pose measurements."""
    from robocal import spatial

    chain = start_chain(result)
    if chain is None:
        return ""
    T_base_device = spatial.inverse(result.frame)
    measured = T_base_device @ spatial.homogeneous(data.orientation, data.position)
    cases = {
        "before calibration": pose_errors(T_base_device @ chain.fk(data.q), measured, "xyz"),
        "after calibration": pose_errors(T_base_device @ result.predict(data.q), measured, "xyz"),
    }
    return "<h3>With orientation</h3>" + _seed_table_html(
        error_table(cases), "predicted minus measured; ΔΦ Δθ ΔΨ as rotations about the base x, y, z axes"
    )


def _load_dir(
    directory: Path,
) -> tuple[CalibrationResult, Measurements | None, Measurements | None, dict | None]:
    from robocal.measure.dataset import read_measurements

    if not (directory / "result.json").is_file():
        raise FileNotFoundError(f"{directory} holds no calibration result (result.json)")
    result = CalibrationResult.load(directory)
    train = read_measurements(directory / "train.csv") if (directory / "train.csv").is_file() else None
    test = read_measurements(directory / "test.csv") if (directory / "test.csv").is_file() else None
    ev = None
    if (directory / "evaluation.json").is_file():
        ev = json.loads((directory / "evaluation.json").read_text(encoding="utf-8"))
    return result, train, test, ev


def write_report(
    result_or_dir: CalibrationResult | str | Path,
    out_path: str | Path,
    *,
    data: Measurements | None = None,
    test_data: Measurements | None = None,
    evaluation: Mapping[str, Any] | None = None,
    title: str | None = None,
    run_id: str | None = None,
) -> Path:
    """Write the self-contained HTML report of a calibration to ``out_path`` (atomically).

    Args:
        result_or_dir: a :class:`CalibrationResult`, or a directory written by
            :meth:`CalibrationResult.save`; from a directory, ``train.csv``,
            ``test.csv`` and ``evaluation.json`` beside ``result.json`` are used when
            the corresponding argument is None.
        out_path: the HTML file to write.
        data: the calibration measurements (residual plots, pose coverage,
            observability indices).
        test_data: held-out measurements (validation section, the seeds' table).
        evaluation: ISO 9283 poses and paths, compensation, truth, timings (see the
            module docstring).
        title: the report's heading.
        run_id: the run id of the result folder the report belongs to (default: that of
            ``result_or_dir/result.json``), stamped as ``<meta name="robocal-run">``
            (:mod:`robocal.outdir`).

    Returns:
        ``out_path``.
    """
    from robocal.model.files import atomic_write_text
    from robocal.outdir import is_run_id, read_run_id, run_id_meta

    if isinstance(result_or_dir, CalibrationResult):
        result = result_or_dir
        saved = result.metadata.get("saved_run_id")  # set by save() and load()
        run_id = run_id if run_id is not None else (saved if is_run_id(saved) else None)
    else:
        run_id = run_id if run_id is not None else read_run_id(Path(result_or_dir) / "result.json")
        result, d_train, d_test, d_ev = _load_dir(Path(result_or_dir))
        data = data if data is not None else d_train
        test_data = test_data if test_data is not None else d_test
        evaluation = evaluation if evaluation is not None else d_ev
    page = build_report(result, data=data, test_data=test_data, evaluation=evaluation, title=title)
    if run_id is not None:
        head = '<meta charset="utf-8">'
        page = page.replace(head, head + "\n" + run_id_meta(run_id), 1)
    return atomic_write_text(out_path, page)
