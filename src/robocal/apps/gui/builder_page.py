"""The model builder page (seed 000 Fig. 4): joints typed into a form, the robot drawn live.

Every field is a ``dcc.Input`` (or radio items) whose id is ``{"kind": "field", "row":
ROW, "key": KEY}`` with ``ROW`` a joint's 0-based index, ``"tcp"`` or ``"meta"``; one
callback reads them all on every keystroke, checks and builds the model
(:mod:`robocal.apps.gui.form`), marks the fields that are wrong and redraws the view
(:func:`robocal.model.view.model_figure` plus the joint axes).  Adding, removing,
moving and loading joints re-render the form (another callback).
"""

from __future__ import annotations

import base64
import binascii
import dataclasses
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from dash import ALL, Dash, Input, Output, State, callback_context, dcc, html, no_update

from robocal.apps.gui.form import (
    TCP_FIELDS,
    BuilderForm,
    FormCheck,
    build_form,
    form_from_catalog,
    form_from_geometry_text,
    form_from_urdf,
    geometry_yaml,
    link_rows,
    model_file_text,
)

__all__ = ["BLANK_JOINT", "builder_figure", "layout", "register"]

BLANK_JOINT = {
    "name": "",
    "type": "revolute",
    "px": "0",
    "py": "0",
    "pz": "0",
    "ax": "0",
    "ay": "0",
    "az": "1",
    "lo": "",
    "hi": "",
}
START = BuilderForm(
    (dict(BLANK_JOINT, name="q1"),),
    {"tx": "0", "ty": "0", "tz": "100", "roll": "", "pitch": "", "yaw": ""},
    "my_robot",
    "",
    "pose",
)
_LABELS = {
    "name": "name",
    "px": "x mm",
    "py": "y mm",
    "pz": "z mm",
    "ax": "axis x",
    "ay": "axis y",
    "az": "axis z",
    "lo": "lower",
    "hi": "upper",
    "tx": "x mm",
    "ty": "y mm",
    "tz": "z mm",
    "roll": "roll °",
    "pitch": "pitch °",
    "yaw": "yaw °",
}


def _fid(row: int | str, key: str) -> dict[str, Any]:
    return {"kind": "field", "row": row, "key": key}


def _input(row: int | str, key: str, value: str, width: str = "5.5em") -> dcc.Input:
    return dcc.Input(
        id=_fid(row, key),
        value=value,
        type="text",
        debounce=False,
        className="field",
        style={"width": width},
        placeholder=_LABELS.get(key, key),
    )


def _joint_row(i: int, row: Mapping[str, str], n: int) -> html.Div:
    cells: list[Any] = [html.Span(f"{i + 1}", className="rownum")]
    cells.append(_input(i, "name", row.get("name", ""), "9em"))
    cells.append(
        dcc.RadioItems(
            id=_fid(i, "type"),
            options=[{"label": "R", "value": "revolute"}, {"label": "P", "value": "prismatic"}],
            value=row.get("type", "revolute"),
            inline=True,
            className="field type",
        )
    )
    cells += [_input(i, k, row.get(k, "")) for k in ("px", "py", "pz")]
    cells += [_input(i, k, row.get(k, ""), "4em") for k in ("ax", "ay", "az")]
    cells += [_input(i, k, row.get(k, ""), "4.5em") for k in ("lo", "hi")]
    buttons = [
        html.Button("↑", id={"kind": "act", "op": "up", "row": i}, disabled=i == 0, title="move up"),
        html.Button("↓", id={"kind": "act", "op": "down", "row": i}, disabled=i == n - 1, title="move down"),
        html.Button("✕", id={"kind": "act", "op": "remove", "row": i}, disabled=n == 1, title="remove"),
    ]
    return html.Div(
        [
            html.Div(cells + buttons, className="joint-row"),
            html.Div(id={"kind": "rowmsg", "row": i}, className="rowmsg"),
        ],
        className="joint",
    )


def render_form(form: BuilderForm) -> list[Any]:
    """The form's components for ``form`` (meta, joints, TCP)."""
    n = len(form.joints)
    widths = (("#", "2.2em"), ("name", "9em"), ("type", "5.6em"), ("x mm", "5.5em"), ("y mm", "5.5em"))
    widths += (("z mm", "5.5em"), ("axis x", "4em"), ("axis y", "4em"), ("axis z", "4em"))
    widths += (("lower", "4.5em"), ("upper", "4.5em"))
    header = html.Div(
        [html.Span(h, style={"width": w, "margin": 0}) for h, w in widths]
        + [html.Span("position: from the previous joint, base axes; limits ° (mm for P)")],
        className="joint-head",
    )
    tcp_row = html.Div(
        [html.Span("TCP", className="rownum")]
        + [_input("tcp", k, form.tcp.get(k, "")) for k in TCP_FIELDS]
        + [html.Span("position rel. to the last joint (mm); roll-pitch-yaw ° (empty: not given)")],
        className="joint-row",
    )
    return [
        html.Div(
            [
                html.Label(["model name ", _input("meta", "name", form.name, "12em")]),
                html.Label(["title ", _input("meta", "title", form.title, "26em")]),
                dcc.RadioItems(
                    id=_fid("meta", "measure"),
                    options=[
                        {"label": "pose measured", "value": "pose"},
                        {"label": "position only", "value": "position"},
                    ],
                    value=form.measure,
                    inline=True,
                    className="field",
                ),
                html.Div(id={"kind": "rowmsg", "row": "meta"}, className="rowmsg"),
            ],
            className="meta",
        ),
        html.Div(
            "Base: the world frame (x, y, z as drawn); joint 1's position is measured from its origin.",
            className="note",
        ),
        header,
        *[_joint_row(i, row, n) for i, row in enumerate(form.joints)],
        tcp_row,
        html.Div(id={"kind": "rowmsg", "row": "tcp"}, className="rowmsg"),
    ]


def layout(catalog: Sequence[str]) -> html.Div:
    """The builder page."""
    upload_style = {"display": "inline-block"}
    return html.Div(
        [
            html.Div(
                [
                    html.Div(
                        [
                            html.Span("start from "),
                            dcc.RadioItems(
                                id="catalog-robot",
                                options=[{"label": n, "value": n} for n in catalog],
                                value=None,
                                inline=True,
                                className="catalog",
                            ),
                            dcc.Upload(
                                html.Button("load geometry YAML"), id="upload-geometry", style=upload_style
                            ),
                            dcc.Upload(html.Button("import URDF"), id="upload-urdf", style=upload_style),
                        ],
                        className="toolbar",
                    ),
                    html.Div(render_form(START), id="form-body"),
                    html.Div(
                        [
                            html.Button("+ add joint", id="add-joint"),
                            html.Button("save geometry YAML", id="save-geometry"),
                            html.Button("build → model file", id="build-model", className="primary"),
                        ],
                        className="toolbar",
                    ),
                    html.Div(id="builder-message", className="message"),
                    dcc.Download(id="download-geometry"),
                    dcc.Download(id="download-model"),
                ],
                className="left",
            ),
            html.Div(
                [
                    dcc.Graph(id="builder-view", style={"height": "560px"}, config={"displaylogo": False}),
                    html.Div(id="builder-count", className="count"),
                    html.Div(id="builder-links"),
                ],
                className="right",
            ),
        ],
        className="page",
    )


# ----------------------------------------------------------------------- reading the form
def form_from_fields(items: Sequence[Mapping[str, Any]]) -> BuilderForm:
    """The form from the callback's ``[{"id": {...}, "value": ...}, ...]`` of every field."""
    rows: dict[int, dict[str, str]] = {}
    tcp: dict[str, str] = {}
    meta: dict[str, str] = {}
    for item in items:
        ident, value = item["id"], item.get("value")
        value = "" if value is None else str(value)
        if ident["row"] == "tcp":
            tcp[ident["key"]] = value
        elif ident["row"] == "meta":
            meta[ident["key"]] = value
        else:
            rows.setdefault(int(ident["row"]), {})[ident["key"]] = value
    joints = tuple(rows[i] for i in sorted(rows))
    return BuilderForm(
        joints, tcp, meta.get("name", ""), meta.get("title", ""), meta.get("measure") or "pose"
    )


def _decode(contents: str) -> str:
    """The text of a ``dcc.Upload`` (a data URL)."""
    try:
        return base64.b64decode(contents.split(",", 1)[1]).decode("utf-8")
    except (IndexError, binascii.Error, UnicodeDecodeError):
        raise ValueError("the file is not UTF-8 text") from None


# ----------------------------------------------------------------------- the view
def builder_figure(result) -> Any:
    """The model's 3D view (:func:`robocal.model.view.model_figure`) with every joint axis
    drawn as a dashed line through its joint, and room around the labels."""
    import plotly.graph_objects as go

    from robocal.model.view import model_figure, padded_scene

    model = result.model
    fig = model_figure(model, title=f"{model.name}: {model.dof} joints, zero position")
    fig.update_layout(
        scene_camera={"eye": {"x": 1.1, "y": -1.25, "z": 0.7}, "center": {"x": 0, "y": 0, "z": -0.1}}
    )
    frames = model.joint_frames(np.zeros(model.dof))
    axes = [s.axis for s in model.steps if s.joint is not None]
    pts = (
        np.concatenate([frames[:, :3, 3], model.fk(np.zeros(model.dof))[None, :3, 3], np.zeros((1, 3))]) * 1e3
    )
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


def _links_table(result) -> tuple[html.Table, str]:
    rows, count = link_rows(result)
    body = []
    for r in rows:
        params = []
        for name, free in r.parameters:
            params.append(html.B(name) if free else html.Span(name, className="dim"))
            params.append(" ")
        status = "ok" if r.verdict == "ok" and r.continuity in ("continuous", "-") else "bad"
        body.append(
            html.Tr(
                [
                    html.Td(r.link),
                    html.Td(r.label),
                    html.Td(r.equation, className="eq"),
                    html.Td(params),
                    html.Td(f"{r.verdict}; {r.continuity}", className=status),
                ]
            )
        )
    head = html.Tr(
        [
            html.Th(h)
            for h in (
                "link",
                "parameterisation",
                "equation",
                "parameters (bold: identified)",
                "rank; continuity",
            )
        ]
    )
    return html.Table([html.Thead(head), html.Tbody(body)], className="links"), count


def _messages(check: FormCheck, ids: Sequence[Mapping[str, Any]]) -> list[Any]:
    per_row: dict[Any, list[str]] = {}
    for (row, _key), message in check.errors.items():
        per_row.setdefault(row, [])
        if message not in per_row[row]:
            per_row[row].append(message)
    return ["; ".join(per_row.get(i["row"], [])) for i in ids]


# ----------------------------------------------------------------------- callbacks
def register(app: Dash) -> None:
    """The builder's callbacks."""
    _register_form(app)
    _register_files(app)


def _register_form(app: Dash) -> None:
    """The joints form: rows added, removed, moved or filled from a file; checked and built live."""

    @app.callback(
        Output("form-body", "children"),
        Output("builder-message", "children", allow_duplicate=True),
        Input("add-joint", "n_clicks"),
        Input({"kind": "act", "op": ALL, "row": ALL}, "n_clicks"),
        Input("catalog-robot", "value"),
        Input("upload-geometry", "contents"),
        Input("upload-urdf", "contents"),
        State("upload-geometry", "filename"),
        State("upload-urdf", "filename"),
        State({"kind": "field", "row": ALL, "key": ALL}, "value"),
        prevent_initial_call=True,
    )
    def restructure(_add, _acts, catalog, geometry, urdf, geometry_name, urdf_name, _values):
        return _restructure(_add, _acts, catalog, geometry, urdf, geometry_name, urdf_name, _values)

    @app.callback(
        Output({"kind": "field", "row": ALL, "key": ALL}, "className"),
        Output({"kind": "rowmsg", "row": ALL}, "children"),
        Output("builder-view", "figure"),
        Output("builder-links", "children"),
        Output("builder-count", "children"),
        Output("builder-message", "children"),
        Input({"kind": "field", "row": ALL, "key": ALL}, "value"),
        State({"kind": "rowmsg", "row": ALL}, "id"),
    )
    def live(_values, message_ids):
        return _live(_values, message_ids)


def _register_files(app: Dash) -> None:
    """The geometry file and the model file of the form, downloaded."""

    @app.callback(
        Output("download-geometry", "data"),
        Output("builder-message", "children", allow_duplicate=True),
        Input("save-geometry", "n_clicks"),
        State({"kind": "field", "row": ALL, "key": ALL}, "value"),
        prevent_initial_call=True,
    )
    def save_geometry(_n, _values):
        return _save_geometry(_n, _values)

    @app.callback(
        Output("download-model", "data"),
        Output("built-model", "data"),
        Output("builder-message", "children", allow_duplicate=True),
        Input("build-model", "n_clicks"),
        State({"kind": "field", "row": ALL, "key": ALL}, "value"),
        prevent_initial_call=True,
    )
    def build_model_file(_n, _values):
        return _build_model_file(_n, _values)


def _restructure(_add, _acts, catalog, geometry, urdf, geometry_name, urdf_name, _values):
    trigger = callback_context.triggered_id
    if trigger is None:
        return no_update, no_update
    form = form_from_fields(callback_context.states_list[-1])
    try:
        if trigger == "add-joint":
            form = dataclasses.replace(form, joints=(*form.joints, dict(BLANK_JOINT)))
        elif isinstance(trigger, dict):
            if not any(a.get("value") for a in callback_context.inputs_list[1] if a["id"] == trigger):
                return no_update, no_update  # a re-rendered button, not a click
            form = dataclasses.replace(form, joints=_edited(form.joints, trigger["op"], int(trigger["row"])))
        elif trigger == "catalog-robot":
            if not catalog:
                return no_update, no_update
            form = form_from_catalog(catalog)
        elif trigger == "upload-geometry":
            form = form_from_geometry_text(_decode(geometry), geometry_name or "the geometry file")
        elif trigger == "upload-urdf":
            form = form_from_urdf(_decode(urdf), urdf_name or "the URDF")
    except (ValueError, KeyError) as err:
        return no_update, html.Span(str(err.args[0] if isinstance(err, KeyError) else err), className="error")
    return render_form(form), ""


def _live(_values, message_ids):
    items = callback_context.inputs_list[0]
    form = form_from_fields(items)
    check, result = build_form(form)
    classes = [
        "field invalid" if (i["id"]["row"], i["id"]["key"]) in check.errors else "field" for i in items
    ]
    messages = _messages(check, message_ids)
    general = html.Span("; ".join(check.general), className="error") if check.general else ""
    if result is None:
        return (
            classes,
            messages,
            no_update,
            no_update,
            "the model is not built: fix the marked fields",
            general,
        )
    table, count = _links_table(result)
    warn = [html.Div(w, className="warning") for w in result.warnings]
    return classes, messages, builder_figure(result), table, [count, *warn], general


def _save_geometry(_n, _values):
    form = form_from_fields(callback_context.states_list[0])
    check, _ = build_form(form)
    if check.geometry is None:
        return no_update, html.Span("fix the marked fields first", className="error")
    name = f"{check.geometry['name']}_geometry.yaml"
    return {"content": geometry_yaml(check.geometry), "filename": name}, f"saved {name}"


def _build_model_file(_n, _values):
    form = form_from_fields(callback_context.states_list[0])
    _check, result = build_form(form)
    if result is None:
        return no_update, no_update, html.Span("fix the marked fields first", className="error")
    text = model_file_text(result)
    name = f"{result.model.name}.yaml"
    stored = {"name": result.model.name, "text": text}
    return (
        {"content": text, "filename": name},
        stored,
        f"built {name}: {len(result.model.free_names)} "
        + ("identifiable parameters; it is offered on the calibration page"),
    )


def _edited(joints: Sequence[Mapping[str, str]], op: str, row: int) -> tuple[Mapping[str, str], ...]:
    rows = list(joints)
    if not 0 <= row < len(rows):
        return tuple(rows)
    if op == "remove" and len(rows) > 1:
        rows.pop(row)
    elif op == "up" and row > 0:
        rows[row - 1], rows[row] = rows[row], rows[row - 1]
    elif op == "down" and row < len(rows) - 1:
        rows[row + 1], rows[row] = rows[row], rows[row + 1]
    return tuple(rows)
