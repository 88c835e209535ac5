"""The report's plotly figures, from its section data (positions in mm, base frame).

Log axes show decades only (``dtick=1``): plotly's minor labels on a log axis read
"2, 1, 5".  3D scenes that carry text labels are padded
(:func:`robocal.model.view.padded_scene`) so the labels are not clipped at the data's edge.
Text from data reaches plotly through :func:`~robocal.evaluate.report.markup.plot_text`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from robocal.evaluate.report.data import CoverageData, LearnedCurve, ParameterRow, PathData
from robocal.evaluate.report.markup import AFTER, BEFORE, COMPENSATED, plot_text

__all__ = [
    "compliance_figure",
    "coverage_figure",
    "error_vectors_figure",
    "histogram_pair_figure",
    "joint_coverage_figure",
    "learned_residual_figure",
    "parameters_figure",
    "path_errors_figure",
    "per_pose_figure",
    "singular_values_figure",
]

Array = np.ndarray
CASE_COLOURS = {"nominal commands": BEFORE, "compensated commands": COMPENSATED}
LEGEND_BELOW = {"orientation": "h", "y": -0.3, "yanchor": "top", "x": 0}
CAMERA = {"eye": {"x": 1.6, "y": -1.6, "z": 0.9}}
LOG_AXIS = {"type": "log", "dtick": 1}  # decades only


def _points3d(points: Array, **style: Any) -> Any:
    """A plotly 3D scatter of ``(n, 3)`` points (mm) with the given trace style."""
    import plotly.graph_objects as go

    return go.Scatter3d(x=points[:, 0], y=points[:, 1], z=points[:, 2], **style)


def _scene_points(cov: CoverageData) -> Array:
    """Every point the coverage figure draws (mm), NaN separators left out."""
    pts = [s.position_base_mm for s in cov.sets] + [np.zeros((1, 3))] + [p for _, p in cov.paths_mm]
    for extra in (cov.iso_points_mm, cov.cube_edges_mm):
        if extra is not None:
            pts.append(extra)
    every = np.vstack(pts)
    return every[np.all(np.isfinite(every), axis=1)]


def coverage_figure(cov: CoverageData) -> Any:
    """Measured tool positions, the ISO 9283 cube with P1-P5, the test paths and the base."""
    import plotly.graph_objects as go

    from robocal.model.view import padded_scene

    fig = go.Figure()
    for s in cov.sets:
        calib = s.name.startswith("calib")
        marker = {"size": 3.5 if calib else 2.5, "color": s.colour, "opacity": 0.9 if calib else 0.5}
        fig.add_trace(_points3d(s.position_base_mm, mode="markers", name=f"{s.name} ({s.n})", marker=marker))
    if cov.cube_edges_mm is not None:
        edges = _points3d(
            cov.cube_edges_mm, mode="lines", name="ISO 9283 cube", line={"color": "#555", "width": 2}
        )
        fig.add_trace(edges)
    if cov.iso_points_mm is not None:
        marker = {"size": 5, "color": "#000", "symbol": "diamond"}
        labels = [plot_text(x) for x in cov.iso_labels]
        fig.add_trace(
            _points3d(cov.iso_points_mm, mode="markers+text", text=labels, name="P1–P5", marker=marker)
        )
    for name, points in cov.paths_mm:
        fig.add_trace(
            _points3d(points, mode="lines", name=plot_text(name), line={"color": COMPENSATED, "width": 4})
        )
    base = {"size": 6, "color": "#444", "symbol": "square"}
    fig.add_trace(
        _points3d(np.zeros((1, 3)), mode="markers+text", text=["base"], name="robot base", marker=base)
    )
    points = _scene_points(cov)
    size = float(np.ptp(points, axis=0).max()) if len(points) > 1 else 1000.0
    fig.update_layout(
        scene=padded_scene(points, pad=0.08 * max(size, 1.0)) | {"camera": CAMERA},
        margin={"l": 0, "r": 0, "t": 30, "b": 0},
        legend={"orientation": "h"},
        title="measured tool positions in the robot base frame",
    )
    return fig


def joint_coverage_figure(cov: CoverageData) -> Any:
    """Box plots of the joint values of each pose set, with the joint limits."""
    import plotly.graph_objects as go

    fig = go.Figure()
    names = np.array([plot_text(n) for n in cov.joint_names])
    for s in cov.sets:
        x = np.repeat(names[None], len(s.joint_display), axis=0).reshape(-1)
        fig.add_trace(
            go.Box(x=x, y=s.joint_display.reshape(-1), name=s.name, marker_color=s.colour, boxpoints=False)
        )
    lim = cov.limits_display
    finite = np.all(np.isfinite(lim), axis=1)
    for k, label in ((0, "lower limit"), (1, "upper limit")):
        if finite.any():
            marker = {"symbol": "line-ew-open", "size": 22, "color": "#999"}
            fig.add_trace(
                go.Scatter(x=names[finite], y=lim[finite, k], mode="markers", name=label, marker=marker)
            )
    fig.update_layout(
        boxmode="group",
        yaxis_title="joint value (deg; mm for prismatic)",
        title="joint ranges covered",
        legend=LEGEND_BELOW,
        margin={"t": 40, "b": 90},
    )
    return fig


def singular_values_figure(sigma: Array) -> Any:
    """Singular values of the column-scaled Jacobian on a decade axis.  The title sits
    above the plot area and its margin leaves room for plotly's tool bar."""
    import plotly.graph_objects as go

    bars = go.Bar(
        x=[f"σ{k + 1}" for k in range(len(sigma))],
        y=sigma,
        marker_color=AFTER,
        hovertemplate="%{x}: %{y:.3g}<extra></extra>",
    )
    fig = go.Figure(bars)
    fig.update_layout(
        yaxis=LOG_AXIS | {"title": "singular value (unit-norm columns)"},
        title={"text": f"singular values, {len(sigma)} parameters", "y": 0.97, "yanchor": "top"},
        margin={"t": 70, "l": 70},
    )
    return fig


def parameters_figure(rows: Sequence[ParameterRow]) -> Any:
    """Identified changes of the robot's lengths (mm) and angles (deg) with ±3σ bars."""
    import plotly.graph_objects as go
    from plotly.subplots import make_subplots

    fig = make_subplots(
        rows=1, cols=2, column_widths=[0.5, 0.5], subplot_titles=("lengths: Δ mm", "angles: Δ deg")
    )
    for col, kind in ((1, "length"), (2, "angle")):
        group = [r for r in rows if r.kind == kind]
        if not group:
            continue
        x = [plot_text(r.name) for r in group]
        error = {"type": "data", "array": [3 * r.std for r in group], "color": "#333"}
        bars = go.Bar(
            x=x, y=[r.delta for r in group], name="identified Δ ± 3σ", marker_color=AFTER, error_y=error
        )
        fig.add_trace(bars.update(showlegend=col == 1), row=1, col=col)
        truth = [r.true_delta for r in group]
        if any(t is not None for t in truth):
            marker = {"symbol": "x", "size": 9, "color": BEFORE}
            true = go.Scatter(x=x, y=truth, mode="markers", name="true Δ (simulation)", marker=marker)
            fig.add_trace(true.update(showlegend=col == 1), row=1, col=col)
    fig.update_layout(
        title="robot parameters: identified change from nominal",
        legend=LEGEND_BELOW,
        margin={"t": 60, "b": 90},
    )
    return fig


def histogram_pair_figure(before: Array | None, after: Array, title: str) -> Any:
    """Histograms of position errors (m in, mm shown), before and after calibration."""
    import plotly.graph_objects as go
    from plotly.subplots import make_subplots

    cols = 2 if before is not None else 1
    titles = ("before calibration", "after calibration") if before is not None else ("after calibration",)
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


def per_pose_figure(before: Array | None, after: Array, title: str) -> Any:
    """The error of every pose (m in, mm shown) on a decade axis."""
    import plotly.graph_objects as go

    x = np.arange(1, len(after) + 1)
    fig = go.Figure()
    if before is not None:
        fig.add_trace(go.Bar(x=x, y=before * 1e3, name="before calibration", marker_color=BEFORE))
    fig.add_trace(go.Bar(x=x, y=after * 1e3, name="after calibration", marker_color=AFTER))
    fig.update_layout(
        barmode="group",
        yaxis=LOG_AXIS | {"title": "position error mm (log)"},
        xaxis_title="pose",
        title=title,
        legend=LEGEND_BELOW,
        margin={"t": 40, "b": 90},
        bargap=0.15,
    )
    return fig


def arrow_scale(points: Array, vectors: Array) -> float:
    """A round magnification (1, 2, 5 × 10^k) that draws the longest vector at about a
    fifth of the points' extent."""
    size = float(np.ptp(points, axis=0).max()) if len(points) > 1 else 1.0
    longest = float(np.linalg.norm(vectors, axis=1).max()) if len(vectors) else 0.0
    if longest <= 0 or size <= 0:
        return 1.0
    raw = 0.2 * size / longest
    decade = 10 ** math.floor(math.log10(raw))
    return float(decade * max(m for m in (1, 2, 5) if m * decade <= raw))


def error_vectors_figure(points: Array, before: Array | None, after: Array, title: str) -> Any:
    """Error vectors (m) at the measured positions (m), magnified; before hidden at first."""
    import plotly.graph_objects as go

    fig = go.Figure()
    p = points * 1e3
    fig.add_trace(_points3d(p, mode="markers", name="measured position", marker={"size": 2, "color": "#444"}))
    for label, vec, colour, visible in (
        ("before", before, BEFORE, "legendonly"),
        ("after", after, AFTER, True),
    ):
        if vec is None:
            continue
        k = arrow_scale(points, vec)
        seg = np.stack([p, p + vec * 1e3 * k, np.full_like(p, np.nan)], axis=1).reshape(-1, 3)
        line = {"color": colour, "width": 4}
        name = f"error {label} calibration × {k:g}"
        fig.add_trace(_points3d(seg, mode="lines", visible=visible, name=name, line=line))
    scene = {"aspectmode": "data", "xaxis_title": "x mm", "yaxis_title": "y mm", "zaxis_title": "z mm"}
    fig.update_layout(
        title=title,
        legend={"orientation": "h"},
        margin={"l": 0, "r": 0, "t": 40, "b": 0},
        scene=scene | {"camera": CAMERA},
    )
    return fig


def path_errors_figure(paths: Sequence[PathData]) -> Any:
    """The distance of the attained barycentre from each test path, per command case."""
    import plotly.graph_objects as go
    from plotly.subplots import make_subplots

    fig = make_subplots(rows=1, cols=len(paths), subplot_titles=[plot_text(p.name) for p in paths])
    for col, path in enumerate(paths, start=1):
        for case, pa in path.accuracy.items():
            line = {"color": CASE_COLOURS.get(case, AFTER), "width": 2}
            trace = go.Scatter(x=path.along_mm, y=pa.at * 1e3, mode="lines", name=plot_text(case), line=line)
            fig.add_trace(trace.update(showlegend=col == 1), row=1, col=col)
        fig.update_xaxes(title_text="along the path mm", row=1, col=col)
        fig.update_yaxes(**LOG_AXIS, row=1, col=col)
    fig.update_yaxes(title_text="distance mm (log)", row=1, col=1)
    fig.update_layout(
        title="path accuracy along the test paths (barycentre of the cycles, ISO 9283 §8.2)",
        legend=LEGEND_BELOW,
        margin={"t": 60, "b": 90},
    )
    return fig


def compliance_figure(displacement: Array) -> Any:
    """Histogram of the tool displacement (m in, mm shown) the joint effects cause."""
    import plotly.graph_objects as go

    fig = go.Figure(go.Histogram(x=displacement * 1e3, marker_color=AFTER, nbinsx=30))
    fig.update_layout(
        xaxis_title="tool displacement caused by the identified joint effects mm",
        yaxis_title="poses",
        title="size of the joint effects over the poses",
        margin={"t": 40},
    )
    return fig


def learned_residual_figure(curves: Sequence[LearnedCurve]) -> Any:
    """The learned angle error of each joint over its range (µrad)."""
    import plotly.graph_objects as go

    fig = go.Figure()
    for c in curves:
        fig.add_trace(go.Scatter(x=c.angle_deg, y=c.error_urad, name=plot_text(c.joint), mode="lines"))
    fig.update_layout(
        xaxis_title="joint angle (°)", yaxis_title="learned angle error δθ (µrad)", margin={"t": 30}
    )
    return fig
