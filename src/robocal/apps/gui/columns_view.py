"""The calibration page's column mapping: each column of the measurement file and its role.

The header is read with the reader's own CSV code (:func:`robocal.csvfile.read_head`, the
page's separator and decimal mark); each column gets a role (joint 1..N, x y z, qw..qz,
rx ry rz, sx sy sz, set, temperature, ignore), prefilled by the reader's guess
(:func:`robocal.measure.dataset.columns.guess_columns`: UR ``actual_q_0..``, ROS
``shoulder_pan_joint`` ..., ``q1..qN``, a device's ``measurement_x`` ...).  The roles become
the reader's ``columns=`` renames; the reader's messages are reworded to name the page's
controls (:func:`gui_words`).
"""

from __future__ import annotations

import re
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from dash import ALL, Dash, Input, Output, State, dcc, html, no_update

__all__ = [
    "IGNORE",
    "MAX_JOINTS",
    "column_roles",
    "gui_words",
    "mapping_table",
    "register",
    "renames_from_roles",
]

IGNORE = "ignore"
#: joint roles offered (joint 1 .. joint MAX_JOINTS)
MAX_JOINTS = 12
_NAMED = ("x", "y", "z", "qw", "qx", "qy", "qz", "rx", "ry", "rz", "sx", "sy", "sz", "set", "temperature")
_LABELS = {"set": "set (train/test)", "temperature": "temperature"}


def _role_options(n_columns: int) -> list[dict[str, str]]:
    joints = [{"label": f"joint {j}", "value": f"q{j}"} for j in range(1, min(MAX_JOINTS, n_columns) + 1)]
    named = [{"label": _LABELS.get(r, r), "value": r} for r in _NAMED]
    return [{"label": IGNORE, "value": IGNORE}, *joints, *named]


def column_roles(header: Sequence[str]) -> list[str]:
    """Each column's role as the reader would take it: its own name when that is a robocal
    name, else the reader's guess, else ``ignore``."""
    from robocal.measure.dataset.columns import guess_columns

    by_column = {column: role for role, column in guess_columns(header).items()}
    own = set(_NAMED) | {f"q{j}" for j in range(1, MAX_JOINTS + 1)}
    return [name if name in own else by_column.get(name, IGNORE) for name in header]


def renames_from_roles(header: Sequence[str], roles: Sequence[str | None]) -> str:
    """The reader's ``columns=`` text of the chosen roles (``"q1=shoulder_pan_joint,..."``).

    Raises:
        ValueError: naming the column mapping: a role given to two columns, joints not
            numbered 1..N, or a column named as a robocal name left out (the reader reads
            a column by its name).
    """
    chosen: dict[str, str] = {}
    for column, role in zip(header, roles, strict=True):
        role = role or IGNORE
        if role == IGNORE:
            if column in _NAMED or re.fullmatch(r"q\d+", column):
                raise ValueError(
                    f"column mapping: column {column!r} is read as {column} by its name; "
                    f"give it that role (or rename it in the file to leave it out)"
                )
            continue
        if role in chosen:
            raise ValueError(f"column mapping: {role} is given to both {chosen[role]!r} and {column!r}")
        chosen[role] = column
    joints = sorted(int(r[1:]) for r in chosen if re.fullmatch(r"q\d+", r))
    if joints and joints != list(range(1, len(joints) + 1)):
        missing = sorted(set(range(1, max(joints) + 1)) - set(joints))
        raise ValueError(f"column mapping: joint {missing[0]} has no column (joints are numbered 1..N)")
    return ",".join(f"{role}={column}" for role, column in chosen.items() if role != column)


def _first_row(path: Path, sep: str | None, decimal: str) -> tuple[list[str], list[str]]:
    """The header and the first data row (cells as written) with the page's options."""
    from robocal import csvfile

    head = csvfile.read_head(path, sep=sep, decimal=decimal)
    chunk = next(csvfile.iter_chunks(head, chunk_bytes=8192), None)
    row = chunk.rows[0] if chunk is not None and chunk.rows else []
    return head.header, row


def mapping_table(path: Path, sep: str | None, decimal: str) -> list[Any]:
    """The mapping control of the file: one row per column (name, its first value, a role
    drop-down prefilled by the reader's guess); or the reason the header cannot be read."""
    from robocal import csvfile

    try:
        header, first = _first_row(path, sep, decimal)
    except (csvfile.CsvError, OSError) as err:
        return [html.Div(f"the header cannot be read: {gui_words(str(err))}", className="error")]
    roles = column_roles(header)
    options = _role_options(len(header))
    rows = []
    for k, (name, role) in enumerate(zip(header, roles, strict=True)):
        sample = first[k].strip() if k < len(first) else ""
        dropdown = dcc.Dropdown(
            id={"kind": "colrole", "col": k},
            options=options,
            value=role,
            clearable=False,
            searchable=False,
            persistence=f"{path.parent.name}:{name}",  # kept over a reload, per uploaded file
            persistence_type="session",
            className="role",
        )
        cells = [html.Td(name, className="colname"), html.Td(sample[:24], className="num"), html.Td(dropdown)]
        rows.append(html.Tr(cells))
    head = html.Tr([html.Th("file column"), html.Th("first value"), html.Th("read as")])
    return [
        html.Table([html.Thead(head), html.Tbody(rows)], className="colmap", id="column-table"),
        dcc.Store(id="column-header", data=header),
    ]


def register(app: Dash, data_file: Callable[[str | None], Path | None]) -> None:
    """The mapping's callbacks: the table drawn for the uploaded file (``data_file``: its
    path from the page's token) and the roles turned into the reader's renames."""
    from robocal.apps.gui.jobs import read_options

    @app.callback(
        Output("column-map", "children"),
        Output("column-header", "data"),
        Input("csv-file", "data"),
        Input("opt-sep", "value"),
        Input("opt-decimal", "value"),
    )
    def column_map(file: dict[str, Any] | None, sep: str, decimal: str) -> tuple[Any, Any]:
        path = data_file((file or {}).get("token"))
        if path is None:
            return [], None
        separator = read_options(sep=sep, decimal=decimal)["sep"]
        children = mapping_table(path, separator, decimal)
        header = children[-1].data if len(children) == 2 else None
        return children[:1], header

    @app.callback(
        Output("column-renames", "data"),
        Output("column-message", "children"),
        Input({"kind": "colrole", "col": ALL}, "value"),
        State("column-header", "data"),
    )
    def column_renames(roles: list[str | None], header: list[str] | None) -> tuple[Any, Any]:
        if not header or len(roles) != len(header):
            return no_update, ""
        try:
            columns = renames_from_roles(header, roles)
        except ValueError as err:
            return {"error": str(err)}, html.Span(str(err), className="error", id="column-error")
        cli = f"command line: --columns {columns}" if columns else "command line: no --columns needed"
        return {"columns": columns}, html.Span(cli, className="hint", id="columns-cli")


#: the reader's option names (the command line's and the Python API's) -> the page's controls
_CONTROL_WORDS = (
    (r"pass decimal=','", "choose decimal mark ','"),
    (r"pass decimal='\.'", "choose decimal mark '.'"),
    (r"decimal=(',|'\.')", r"decimal mark \1"),
    (r"pass length_unit='(\w+)'", r"choose lengths: \1"),
    (r"length_unit='(\w+)'", r"lengths \1"),
    (r"angle_unit='(\w+)'", r"angles: \1"),
    (r"pass limits='warn'", "choose joint limits: warn"),
    (r"limits='(\w+)'", r"joint limits: \1"),
    (r"incomplete='drop'", "incomplete rows: drop"),
    (r"rename with e\.g\. columns=\{[^}]*\}", "choose the joints' columns in the column mapping"),
    (r"or renames such as columns=\{[^}]*\}", "or choose the joints' columns in the column mapping"),
    (r"\(given for '(\w+)' in columns=\)", r"(chosen as \1 in the column mapping)"),
    (r"extra=", "extra columns"),
    (r"orientation='([^']*)'", r"orientation \1"),
    (r"\bpass\b", "choose"),
)


def gui_words(text: str) -> str:
    """A reader's message with its option names (``decimal=','``, ``columns={...}``) replaced
    by the page's controls (decimal mark, the column mapping)."""
    for pattern, replacement in _CONTROL_WORDS:
        text = re.sub(pattern, replacement, text)
    return text
