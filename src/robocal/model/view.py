"""A self-contained interactive 3D view of a model: skeleton, frames, parameter table.

Like seed 000's Figs. 5-6: the chain drawn through the origin of every elementary
step, each joint frame's x/y/z axes (red/green/blue) with its label, the base and tool
frames, and the parameter table beneath.  plotly.js is embedded, so the HTML file
works offline and makes no external request.
"""

from __future__ import annotations

import html
import math
from pathlib import Path

import numpy as np

from robocal.model.chain import Model
from robocal.outdir import atomic_write_text
from robocal.spatial import elementary

__all__ = ["model_figure", "padded_scene", "step_frames", "write_model_view"]

AXIS_COLOURS = ("#d62728", "#2ca02c", "#1f77b4")  # x red, y green, z blue


def step_frames(model: Model, q: np.ndarray | None = None) -> np.ndarray:
    """Frames after every step at one configuration, ``(P + 1, 4, 4)`` (first: base)."""
    q = np.zeros(model.dof) if q is None else np.asarray(q, dtype=float)
    frames = [np.eye(4)]
    j = 0
    for step in model.steps:
        value = step.value
        if step.joint is not None:
            value += q[j]
            j += 1
        frames.append(frames[-1] @ elementary(step.motion, value))
    return np.array(frames)


def model_figure(model: Model, q: np.ndarray | None = None, title: str | None = None):
    """A plotly figure of the model at ``q`` (default: zero), lengths in mm."""
    import plotly.graph_objects as go

    frames = step_frames(model, q)
    pts = frames[:, :3, 3] * 1000.0
    size = max(float(np.ptp(pts, axis=0).max()), 100.0)
    arrow = 0.08 * size
    fig = go.Figure()
    fig.add_trace(
        go.Scatter3d(
            x=pts[:, 0],
            y=pts[:, 1],
            z=pts[:, 2],
            mode="lines+markers",
            line={"color": "#444", "width": 6},
            marker={"size": 2, "color": "#444"},
            name="chain",
            hovertext=["base"] + [s.name for s in model.steps],
            hoverinfo="text",
        )
    )
    labelled: list[tuple[str, np.ndarray]] = [("base", frames[0])]
    for k, step in enumerate(model.steps):
        if step.joint is not None:
            labelled.append((step.joint.name, frames[k + 1]))
    labelled.append(("tool", frames[-1]))
    for axis in range(3):
        xs, ys, zs = [], [], []
        for _, F in labelled:
            o = F[:3, 3] * 1000.0
            e = o + arrow * F[:3, axis]
            xs += [o[0], e[0], None]
            ys += [o[1], e[1], None]
            zs += [o[2], e[2], None]
        fig.add_trace(
            go.Scatter3d(
                x=xs,
                y=ys,
                z=zs,
                mode="lines",
                line={"color": AXIS_COLOURS[axis], "width": 5},
                name=f"{'xyz'[axis]} axes",
                hoverinfo="skip",
            )
        )
    origins, names = _merged_labels([(name, F[:3, 3] * 1000.0) for name, F in labelled], 0.02 * size)
    fig.add_trace(
        go.Scatter3d(
            x=origins[:, 0],
            y=origins[:, 1],
            z=origins[:, 2],
            mode="text",
            text=names,
            textposition="top center",
            name="frames",
        )
    )
    fig.update_layout(
        title=title or f"{model.name}: {model.title}" if model.title else (title or model.name),
        scene=padded_scene(np.vstack([pts, origins]), pad=0.2 * size)
        | {"camera": {"eye": {"x": 1.0, "y": -1.0, "z": 0.6}, "center": {"x": 0, "y": 0, "z": -0.05}}},
        margin={"l": 0, "r": 0, "t": 40, "b": 0},
        legend={"orientation": "h"},
        height=640,
    )
    return fig


def _merged_labels(labels: list[tuple[str, np.ndarray]], tol_mm: float) -> tuple[np.ndarray, list[str]]:
    """Frame labels ``(name, origin mm)`` with those at (nearly) the same origin joined into
    one ("base, shoulder_pan"), so that they do not print over each other."""
    origins: list[np.ndarray] = []
    names: list[str] = []
    for name, o in labels:
        for k, other in enumerate(origins):
            if np.linalg.norm(o - other) <= tol_mm:
                names[k] += f", {name}"
                break
        else:
            origins.append(o)
            names.append(name)
    return np.array(origins), names


def padded_scene(points_mm: np.ndarray, pad: float) -> dict:
    """A 3D scene whose axes span ``points_mm`` ``(n, 3)`` plus ``pad`` (mm) on every side,
    in true proportions: labels next to the outermost points stay inside the scene, where
    plotly would clip them at the data's edge (``aspectmode="data"`` fits the box tightly)."""
    lo, hi = points_mm.min(axis=0) - pad, points_mm.max(axis=0) + pad
    span = hi - lo
    ratio = span / span.max()
    scene: dict = {"aspectmode": "manual", "aspectratio": dict(zip("xyz", map(float, ratio), strict=True))}
    for k, axis in enumerate("xyz"):
        scene[f"{axis}axis"] = {"range": [float(lo[k]), float(hi[k])], "title": f"{axis} mm"}
    return scene


def _parameter_table(model: Model) -> str:
    rows = []
    for i, s in enumerate(model.steps):
        value = math.degrees(s.value) if s.is_rotation else s.value * 1000.0
        unit = "deg" if s.is_rotation else "mm"
        joint = ""
        if s.joint is not None:
            joint = f"{html.escape(s.joint.name)} ({s.joint_type})"
        rows.append(
            f"<tr><td>{i}</td><td>{s.motion}</td><td>{html.escape(s.name)}</td>"
            f"<td class='num'>{value:.4f}</td><td>{unit}</td><td>{'yes' if s.free else 'no'}</td>"
            f"<td>{joint}</td></tr>"
        )
    return (
        "<table><thead><tr><th>#</th><th>motion</th><th>parameter</th><th>value</th><th>unit</th>"
        "<th>identified</th><th>joint</th></tr></thead><tbody>" + "".join(rows) + "</tbody></table>"
    )


def write_model_view(model: Model, path: str | Path, q: np.ndarray | None = None) -> Path:
    """Write the interactive view of ``model`` (at ``q``) to a self-contained HTML file."""
    fig = model_figure(model, q)
    plot = fig.to_html(full_html=False, include_plotlyjs=True, div_id="model-view")
    notes = "".join(f"<li>{html.escape(n.strip())}</li>" for n in model.notes.split(";") if n.strip())
    free = len(model.free_names)
    page = f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8">
<title>{html.escape(model.name)} — robocal model</title>
<style>
body {{ font-family: system-ui, sans-serif; margin: 1.5rem; color: #222; }}
table {{ border-collapse: collapse; font-size: 0.9rem; }}
td, th {{ border-bottom: 1px solid #ddd; padding: 0.2rem 0.6rem; text-align: left; }}
td.num {{ text-align: right; font-variant-numeric: tabular-nums; }}
.meta {{ color: #555; }}
</style></head><body>
<h1>{html.escape(model.name)}</h1>
<p class="meta">{html.escape(model.title)}<br>{model.dof} joints, {len(model.steps)} parameters,
{free} identified (free). Frames: x red, y green, z blue; lengths in mm; zero configuration.</p>
{plot}
<h2>Links</h2><ul>{notes or "<li>(no link notes)</li>"}</ul>
<h2>Parameters</h2>
{_parameter_table(model)}
<p class="meta">{html.escape(model.source)}</p>
</body></html>
"""
    return atomic_write_text(path, page)
