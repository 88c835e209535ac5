"""The calibration page's last part: compensate an uploaded targets CSV with the run's saved
result (``rc.compensate_targets``) and export the calibrated URDF or UR kinematics
(``robocal.compensate.export``)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

from dash import Dash, Input, Output, State, dcc, html, no_update

from robocal.apps.gui.calibrate_views import compensate, radio, row
from robocal.apps.gui.columns_view import gui_words
from robocal.apps.gui.jobs import read_options

__all__ = ["fieldset", "register"]


def fieldset() -> html.Fieldset:
    """The controls: a targets CSV to compensate (its unit, frame, separator, decimal mark), the exports."""
    return html.Fieldset(
        [
            html.Legend("compensate targets and export (after a calibration)"),
            dcc.Upload(
                html.Button("compensate a targets CSV (name, x, y, z [, qw..qz])"), id="upload-targets"
            ),
            row("targets in", radio("targets-unit", ("m", "mm"), "mm")),
            row("separator", radio("targets-sep", ("auto", ";", ",", "tab"), "auto")),
            row("decimal mark", radio("targets-decimal", (".", ","), ".")),
            row(
                "targets frame",
                radio("targets-frame", ("base", "measurement"), "base", ("robot base", "device")),
            ),
            html.Div(
                [
                    html.Button("calibrated URDF", id="export-urdf"),
                    html.Button("UR kinematics YAML", id="export-ur"),
                ],
                className="toolbar",
            ),
            html.Div(id="export-message", className="message"),
        ]
    )


def register(app: Dash, workdir: Path) -> None:
    """Compensation of uploaded targets and the exports, from the saved result."""

    @app.callback(
        Output("cal-download", "data"),
        Output("export-message", "children"),
        Input("upload-targets", "contents"),
        Input("export-urdf", "n_clicks"),
        Input("export-ur", "n_clicks"),
        State("upload-targets", "filename"),
        State("targets-unit", "value"),
        State("targets-frame", "value"),
        State("targets-sep", "value"),
        State("targets-decimal", "value"),
        State("cal-run-id", "data"),
        prevent_initial_call=True,
    )
    def compensate_or_export(
        targets: str | None,
        _urdf: int | None,
        _ur: int | None,
        filename: str | None,
        unit: str,
        frame: str,
        sep: str,
        decimal: str,
        run_id: str | None,
    ) -> tuple[Any, Any]:
        reading = _TargetsReading(filename, unit, frame, sep, decimal)
        return _compensate_or_export(workdir, targets, reading, run_id)


@dataclass(frozen=True)
class _TargetsReading:
    """How the page reads an uploaded targets CSV: its name, length unit (``m``/``mm``), frame
    (``base``/``measurement``), separator (``auto``, ``tab`` or the character) and decimal mark."""

    filename: str | None
    unit: str
    frame: str
    sep: str
    decimal: str


def _compensate_or_export(
    workdir: Path, targets: str | None, reading: _TargetsReading, run_id: str | None
) -> tuple[Any, Any]:
    from dash import callback_context

    from robocal.identify.result import CalibrationResult

    trigger = callback_context.triggered_id
    if run_id is not None and (workdir / "runs" / run_id / "constraints.json").is_file():
        text = "a constraint calibration: compensate and export it with robocal compensate / export"
        return no_update, html.Span(text, className="error")
    if run_id is None or not (workdir / "runs" / run_id / "result.json").is_file():
        return no_update, html.Span("calibrate first", className="error")
    result = CalibrationResult.load(workdir / "runs" / run_id)
    try:
        if trigger == "upload-targets" and targets is not None:
            sep = read_options(sep=reading.sep)["sep"]
            r = reading
            return compensate(result, targets, r.filename, r.unit, r.frame, sep, r.decimal)
        if trigger == "export-urdf":
            from robocal.compensate.export import export_urdf

            ex, _ = export_urdf(result)  # its notes: the physics-only fit used, what it leaves out
            notes = "; ".join(ex.notes) or "everything calibrated is carried"
            return {"content": ex.text, "filename": f"{result.model.name}_calibrated.urdf"}, notes
        from robocal.compensate.export import export_ur_kinematics, kinematic_part, left_out

        part = kinematic_part(result)
        kin = export_ur_kinematics(part.calibrated)
        notes = "; ".join((*part.notes, *(m.note for m in left_out(part.calibrated))))
        return {"content": kin.to_yaml(), "filename": "default_kinematics.yaml"}, (
            f"UR kinematics written; {notes}" if notes else "UR kinematics written"
        )
    except ValueError as err:
        return no_update, html.Span(gui_words(str(err)), className="error", id="export-error")
