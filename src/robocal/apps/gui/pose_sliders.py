"""The builder's joint sliders (issue 36 item 3): one slider per joint of the built model,
within its limits (degrees for a revolute joint, mm for a prismatic one), posing the 3D view.

Moving a slider sends one cheap request: the model built for the form's geometry is taken
from the builder's cache (:func:`robocal.apps.gui.builder_views.built_result`) and only drawn
at the new joint values; the form is not read, checked or built again.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from dash import ALL, Dash, Input, Output, State, dcc, html, no_update

from robocal.apps.gui.builder_views import builder_figure, built_result
from robocal.model.builder import BuildResult

__all__ = ["joint_sliders", "joint_values_si", "register", "slider_range"]

#: the range of a revolute joint without limits, or wider than half a turn either way (degrees):
#: ±180° reaches every pose, and ±360° put both ends of a UR joint's slider at the zero pose
TURN_DEG = 180.0
#: the range either way of a prismatic joint without limits (mm)
STROKE_MM = 1000.0


def slider_range(joint_type: str, limits: Sequence[float]) -> tuple[float, float]:
    """A slider's range from a joint's ``limits`` (lower, upper; rad or m, ±inf unknown):
    degrees for a revolute joint (within ±180°), mm for a prismatic one (within ±1000 mm)."""
    scale, bound = (1e3, STROKE_MM) if joint_type == "prismatic" else (180.0 / np.pi, TURN_DEG)
    lo, hi = (float(np.clip(v * scale, -bound, bound)) for v in limits)
    return (round(lo, 1), round(hi, 1)) if hi > lo else (-bound, bound)


def joint_sliders(result: BuildResult | None) -> list[Any]:
    """One labelled slider per joint of the built model, at zero (or the limit nearest it)."""
    if result is None:
        return []
    model = result.model
    rows: list[Any] = [html.Div("pose the view (no rebuild):", className="dim")]
    for j, (name, kind, limits) in enumerate(
        zip(model.joint_names, model.joint_types, model.joint_limits, strict=True)
    ):
        lo, hi = slider_range(kind, limits)
        unit = "mm" if kind == "prismatic" else "°"
        slider = dcc.Slider(
            id={"kind": "pose", "joint": j},
            min=lo,
            max=hi,
            value=float(np.clip(0.0, lo, hi)),
            step=0.5,
            marks={lo: f"{lo:g}", hi: f"{hi:g}"},
            tooltip={"placement": "bottom", "always_visible": False},
            updatemode="mouseup",  # one request per move, not one per pixel dragged
        )
        label = html.Span(f"{name} ({unit})", className="slider-label")
        rows.append(html.Div([label, html.Div(slider, className="slider-track")], className="slider-row"))
    return rows


def joint_values_si(result: BuildResult, values: Sequence[float | None]) -> np.ndarray:
    """The sliders' ``values`` (degrees / mm, None as zero) as joint values ``(dof,)`` (rad / m)."""
    kinds = result.model.joint_types
    raw = np.array([0.0 if v is None else float(v) for v in values])
    return np.where(np.array(kinds) == "prismatic", raw * 1e-3, np.deg2rad(raw))


#: in the browser: the sliders' values into ``builder-pose`` only when they differ from the pose
#: drawn (Dash also fires on sliders inserted by a rebuild, all at zero: no request then)
_MOVED_JS = """function(values, drawn) {
  const same = drawn ? JSON.stringify(values) === JSON.stringify(drawn) : values.every(v => !v);
  return same ? dash_clientside.no_update : values;
}"""


def register(app: Dash) -> None:
    """The slider callbacks: a moved slider's values (in the browser), then the cached model
    drawn at them (one request)."""
    app.clientside_callback(
        _MOVED_JS,
        Output("builder-pose", "data"),
        Input({"kind": "pose", "joint": ALL}, "value"),
        State("builder-pose", "data"),
        prevent_initial_call=True,
    )

    @app.callback(
        Output("builder-view", "figure", allow_duplicate=True),
        Output("builder-message", "children", allow_duplicate=True),
        Input("builder-pose", "data"),
        State("builder-geometry", "data"),
        prevent_initial_call=True,
    )
    def pose(values: list[float | None] | None, geometry_text: str | None) -> tuple[Any, Any]:
        result = built_result(geometry_text) if geometry_text else None
        if result is None or values is None or len(values) != result.model.dof:
            # the model left the cache (many geometries since): drawn again on the next edit
            return no_update, "the sliders' model is no longer in memory: edit a field to draw it again"
        return builder_figure(result, joint_values_si(result, values)), no_update
