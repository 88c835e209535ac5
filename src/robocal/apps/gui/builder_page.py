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

from dash import ALL, Dash, Input, Output, State, callback_context, dcc, html, no_update

from robocal.apps.gui import pose_sliders
from robocal.apps.gui.builder_views import builder_figure, built_result, built_view
from robocal.apps.gui.form import (
    TCP_FIELDS,
    BuilderForm,
    FormCheck,
    build_form,
    check_form,
    form_from_catalog,
    form_from_geometry_text,
    form_from_urdf,
    geometry_yaml,
    model_file_text,
)

__all__ = ["BLANK_JOINT", "builder_figure", "layout", "register"]  # builder_figure: as before

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


#: a field's value is sent when the user presses Enter or leaves the field, not on every key:
#: the model is checked and built once per edit.  (Dash's timed debounce is not used: its timer
#: fires after "+ add joint" has re-rendered the form, on a box that no longer exists, and a
#: value typed just before the click would be lost.)
FIELD_DEBOUNCE = True


def _input(row: int | str, key: str, value: str) -> dcc.Input:
    # the box is as wide as its text (CSS field-sizing): "-1.547337813e-09" shows in full
    return dcc.Input(
        id=_fid(row, key),
        value=value,
        type="text",
        debounce=FIELD_DEBOUNCE,
        className="field",
        placeholder=_LABELS.get(key, key),
    )


#: the joint table's columns: (heading, what the column holds)
_JOINT_COLUMNS = (
    ("#", "joint number"),
    ("name", "the joint's name"),
    ("type", "R revolute, P prismatic"),
    ("x mm", "position from the previous joint, base axes"),
    ("y mm", "position from the previous joint, base axes"),
    ("z mm", "position from the previous joint, base axes"),
    ("axis x", "axis direction, base axes"),
    ("axis y", "axis direction, base axes"),
    ("axis z", "axis direction, base axes"),
    ("lower", "lower limit, deg (mm for P)"),
    ("upper", "upper limit, deg (mm for P)"),
    ("", ""),
)
_TCP_HEAD = ("", "", "", "x mm", "y mm", "z mm", "roll °", "pitch °", "yaw °", "", "", "")


def _head_row(titles: Sequence[str], hints: Sequence[str] = ()) -> html.Tr:
    hints = tuple(hints) or ("",) * len(titles)
    return html.Tr([html.Th(t, title=h or None) for t, h in zip(titles, hints, strict=True)])


def _message_row(row: int | str) -> html.Tr:
    cell = html.Td(html.Div(id={"kind": "rowmsg", "row": row}, className="rowmsg"), colSpan=12)
    return html.Tr(cell, className="msgrow")


def _joint_row(i: int, row: Mapping[str, str], n: int) -> list[html.Tr]:
    cells: list[Any] = [
        html.Td(f"{i + 1}", className="rownum"),
        html.Td(_input(i, "name", row.get("name", ""))),
    ]
    cells.append(
        html.Td(
            dcc.RadioItems(
                id=_fid(i, "type"),
                options=[{"label": "R", "value": "revolute"}, {"label": "P", "value": "prismatic"}],
                value=row.get("type", "revolute"),
                inline=True,
                className="field type",
            )
        )
    )
    cells += [html.Td(_input(i, k, row.get(k, ""))) for k in ("px", "py", "pz", "ax", "ay", "az", "lo", "hi")]
    buttons = [
        html.Button("↑", id={"kind": "act", "op": "up", "row": i}, disabled=i == 0, title="move up"),
        html.Button("↓", id={"kind": "act", "op": "down", "row": i}, disabled=i == n - 1, title="move down"),
        html.Button("✕", id={"kind": "act", "op": "remove", "row": i}, disabled=n == 1, title="remove"),
    ]
    cells.append(html.Td(buttons, className="acts"))
    return [html.Tr(cells, className="joint-row"), _message_row(i)]


def _tcp_rows(tcp: Mapping[str, str]) -> list[html.Tr]:
    cells = [html.Td("TCP", className="rownum"), html.Td("tool point", className="hint"), html.Td("")]
    cells += [html.Td(_input("tcp", k, tcp.get(k, ""))) for k in TCP_FIELDS]
    cells += [html.Td(""), html.Td(""), html.Td("")]
    return [html.Tr(cells, className="joint-row"), _message_row("tcp")]


def render_form(form: BuilderForm) -> list[Any]:
    """The form's components for ``form``: the model's name and title, then one table whose
    columns line up at every width (joints, then the TCP under its own headings)."""
    n = len(form.joints)
    body: list[html.Tr] = []
    for i, row in enumerate(form.joints):
        body += _joint_row(i, row, n)
    table = html.Table(
        [
            html.Thead(_head_row([c for c, _ in _JOINT_COLUMNS], [h for _, h in _JOINT_COLUMNS])),
            html.Tbody(body),
            html.Tbody([html.Tr(_head_row(_TCP_HEAD).children, className="subhead"), *_tcp_rows(form.tcp)]),
        ],
        className="joint-table",
        id="joint-table",
    )
    return [
        html.Div(
            [
                html.Label(["model name ", _input("meta", "name", form.name)]),
                html.Label(["title ", _input("meta", "title", form.title)]),
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
            "Base: the world frame (x, y, z as drawn). Each joint's position is measured from the "
            "previous joint (joint 1's from the base origin), in base axes; limits in ° (mm for P). "
            "The TCP's position is relative to the last joint (mm), its roll-pitch-yaw in ° "
            "(empty: not given). Enter or Tab applies a field.",
            className="note",
        ),
        table,
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
                    html.Div(id="builder-sliders", className="sliders"),
                    dcc.Store(id="builder-geometry"),
                    dcc.Store(id="builder-pose"),
                    html.Div(id="builder-count", className="count"),
                    html.Div(id="builder-links"),
                ],
                className="right",
            ),
        ],
        className="page builder",
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
    pose_sliders.register(app)


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
        Output("builder-sliders", "children"),
        Output("builder-geometry", "data"),
        Input({"kind": "field", "row": ALL, "key": ALL}, "value"),
        State({"kind": "rowmsg", "row": ALL}, "id"),
    )
    def live(_values: list[Any], message_ids: list[dict[str, Any]]) -> tuple[Any, ...]:
        return _live(callback_context.inputs_list[0], message_ids)


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


def _live(items: Sequence[Mapping[str, Any]], message_ids: Sequence[Mapping[str, Any]]) -> tuple[Any, ...]:
    """Check every field (cheap) and, when the form is valid, show its model (built once per
    geometry, :func:`_built_view`)."""
    form = form_from_fields(items)
    check = check_form(form)
    view, text = None, None
    if check.ok and check.geometry is not None:
        text = geometry_yaml(check.geometry)
        check, view = built_view(form, text)
    classes = [
        "field invalid" if (i["id"]["row"], i["id"]["key"]) in check.errors else "field" for i in items
    ]
    messages = _messages(check, message_ids)
    general = html.Span("; ".join(check.general), className="error") if check.general else ""
    if view is None:
        return (
            classes,
            messages,
            no_update,
            no_update,
            "the model is not built: fix the marked fields",
            general,
            no_update,
            no_update,
        )
    sliders = pose_sliders.joint_sliders(built_result(text)) if text else []
    return classes, messages, *view, general, sliders, text


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
