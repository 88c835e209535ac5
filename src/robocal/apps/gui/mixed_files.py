"""More than one file in one fit (issue 33 item 3 in the GUI): a tracker CSV with a socket
file, or two constraint files, calibrated together as ``robocal calibrate --data a --data b``
does (:func:`robocal.workflow.constraints.calibrate_constraint_files`: the constraint files'
points and planes numbered in the order given, each kind's noise estimated in the fit).

The page's first file is opened as before; the files added here follow it in the fit.  Each
is kept as an upload of its own (``workdir/data/<token>``); the list lives in the tab's
session storage, so that a reload keeps it.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

from dash import Dash, Input, Output, State, callback_context, dcc, html, no_update

__all__ = ["controls", "more_paths", "register"]


def controls() -> html.Div:
    """The "add a file to the same fit" upload, the list of added files and a clear button."""
    return html.Div(
        [
            dcc.Upload(html.Button("add a file to the same fit"), id="upload-more", multiple=True),
            html.Button("clear added files", id="more-clear", className="secondary"),
            html.Div(id="more-names", className="hint"),
            dcc.Store(id="more-files", storage_type="session"),
        ],
        className="more-files",
    )


def register(app: Dash, save_upload: Callable[[str, str], dict[str, Any]]) -> None:
    """The callbacks; ``save_upload(contents, filename)`` keeps one upload (``token`` and
    ``label``, or ``error``) as the page's first file is kept."""

    @app.callback(
        Output("more-files", "data"),
        Input("upload-more", "contents"),
        Input("more-clear", "n_clicks"),
        State("upload-more", "filename"),
        State("more-files", "data"),
        prevent_initial_call=True,
    )
    def added(contents, _clear, names, current):
        if callback_context.triggered_id == "more-clear":
            return []
        if not contents:
            return no_update
        kept = list(current or [])
        for content, name in zip(contents, names or [None] * len(contents), strict=True):
            kept.append(save_upload(content, name))
        return kept

    @app.callback(Output("more-names", "children"), Input("more-files", "data"))
    def names(files):
        if not files:
            return "one file: add a tracker or another constraint file to calibrate them together"
        items = [
            html.Li(f["error"], className="error")
            if "error" in f
            else html.Li(f["label"], **{"data-token": f["token"]})
            for f in files
        ]
        return [html.Span("calibrated together with the file above:"), html.Ul(items, id="more-list")]


def more_paths(
    files: list[dict[str, Any]] | None, data_file: Callable[[str | None], Path | None]
) -> tuple[Path, ...]:
    """The added files' paths in the order added; ValueError naming one that is not there."""
    paths = []
    for f in files or []:
        if "error" in f:
            raise ValueError(f"added file: {f['error']}")
        path = data_file(f.get("token"))
        if path is None:
            raise ValueError(f"added file {f.get('label', '?')}: not on this server any more; add it again")
        paths.append(path)
    return tuple(paths)
