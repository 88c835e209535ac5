"""What the builder page shows of a valid form: the model's 3D view and its link table
(parameterisation, equation, each parameter's value in mm or degrees), built once per geometry."""

from __future__ import annotations

import collections
import threading
from typing import Any

import numpy as np
from dash import html

from robocal.apps.gui.form import BuilderForm, FormCheck, build_form, check_form, link_rows
from robocal.model.builder import BuildResult

__all__ = ["builder_figure", "built_result", "built_view"]


# ----------------------------------------------------------------------- the view
def builder_figure(result, q: np.ndarray | None = None) -> Any:
    """The model's 3D view (:func:`robocal.model.view.model_figure`) at joint values ``q``
    ``(dof,)`` (rad / m; None: zero) with every joint axis drawn as a dashed line through
    its joint, and room around the labels."""
    import plotly.graph_objects as go

    from robocal.model.view import model_figure, padded_scene

    model = result.model
    posed = q is not None and bool(np.any(q))
    q = np.zeros(model.dof) if q is None else np.asarray(q, dtype=float)
    where = "posed by the sliders" if posed else "zero position"
    fig = model_figure(model, q, title=f"{model.name}: {model.dof} joints, {where}")
    fig.update_layout(
        scene_camera={"eye": {"x": 1.1, "y": -1.25, "z": 0.7}, "center": {"x": 0, "y": 0, "z": -0.1}}
    )
    frames = model.joint_frames(q)
    axes = [s.axis for s in model.steps if s.joint is not None]
    pts = np.concatenate([frames[:, :3, 3], model.fk(q)[None, :3, 3], np.zeros((1, 3))]) * 1e3
    size = max(float(np.ptp(pts, axis=0).max()), 100.0)
    xs, ys, zs = [], [], []
    for F, k in zip(frames, axes, strict=True):
        o, u = F[:3, 3] * 1e3, F[:3, k]
        a, b = o - 0.18 * size * u, o + 0.18 * size * u
        xs += [a[0], b[0], None]
        ys += [a[1], b[1], None]
        zs += [a[2], b[2], None]
    fig.add_trace(
        go.Scatter3d(
            x=xs, y=ys, z=zs, mode="lines", name="joint axes",
            line={"color": "#9467bd", "width": 3, "dash": "dash"}, hoverinfo="skip",
        )
    )  # fmt: skip
    fig.update_layout(
        height=560,
        uirevision="builder",
        scene=padded_scene(pts, pad=0.25 * size),  # labels stay inside
    )
    return fig


def _links_table(result: BuildResult) -> tuple[html.Table, str]:
    rows, count = link_rows(result)
    body = []
    for r in rows:
        params: list[Any] = []
        for (name, free), value in zip(r.parameters, r.values, strict=True):
            label = html.B(name) if free else html.Span(name, className="dim")
            params.append(html.Span([label, " = ", html.Span(value, className="num")], className="param"))
        status = "ok" if r.verdict == "ok" and r.continuity in ("continuous", "-") else "bad"
        body.append(
            html.Tr(
                [
                    html.Td(r.link),
                    html.Td(r.label),
                    html.Td(r.equation, className="eq"),
                    html.Td(params, className="params"),
                    html.Td(f"{r.verdict}; {r.continuity}", className=status),
                ]
            )
        )
    titles = (
        "link",
        "parameterisation",
        "equation",
        "parameters at the start (bold: identified)",
        "rank; continuity",
    )
    head = html.Tr([html.Th(h) for h in titles])
    return html.Table([html.Thead(head), html.Tbody(body)], className="links"), count


#: the views of the last few geometries built (YAML text -> (view, build)), most recent last
_VIEWS: collections.OrderedDict[str, tuple[tuple[Any, Any, Any], BuildResult]] = collections.OrderedDict()
_VIEWS_LOCK = threading.Lock()


def built_view(form: BuilderForm, geometry_text: str) -> tuple[FormCheck, tuple[Any, Any, Any] | None]:
    """The model of a valid form drawn (figure, link table, count line), or None with the
    builder's refusal in the check.  A geometry built once is not built again: an edit that
    leaves it as it was (``100`` -> ``100.0``, or back to the last valid value) costs nothing."""
    with _VIEWS_LOCK:
        cached = _VIEWS.get(geometry_text)
        if cached is not None:
            _VIEWS.move_to_end(geometry_text)
    if cached is not None:
        return check_form(form), cached[0]
    check, result = build_form(form)
    if result is None:
        return check, None
    table, count = _links_table(result)
    warn = [html.Div(w, className="warning") for w in result.warnings]
    view = (builder_figure(result), table, [count, *warn])
    with _VIEWS_LOCK:
        _VIEWS[geometry_text] = (view, result)
        while len(_VIEWS) > 16:
            _VIEWS.popitem(last=False)
    return check, view


def built_result(geometry_text: str) -> BuildResult | None:
    """The model built for ``geometry_text`` by :func:`built_view` while it is among the last
    few built (None after that: the caller builds it again)."""
    with _VIEWS_LOCK:
        cached = _VIEWS.get(geometry_text)
    return None if cached is None else cached[1]
