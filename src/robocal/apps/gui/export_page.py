"""The calibration page's last part: compensate an uploaded targets CSV with the run's saved
calibration (``rc.compensate_targets``) and export the calibrated URDF or UR kinematics
(``robocal.compensate.export``), for a tracker run and for a constraint run (fixed points,
planes, distances, inclinometers, mixed with tracker files) alike.

The same functions and checks as ``robocal compensate`` / ``robocal export`` on the run's
folder (:func:`saved_calibration`): a folder whose files disagree or whose numbers cannot be a
robot's is refused by name on the page and nothing is handed out; a constraint calibration
compensates targets in the robot base only (it has no device frame), from the robot it
started from, and every export and compensation states its nominal base."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

from dash import Dash, Input, Output, State, dcc, html, no_update

from robocal.apps.gui.calibrate_views import compensate, radio, row
from robocal.apps.gui.columns_view import gui_words
from robocal.apps.gui.jobs import public_text, read_options

__all__ = ["Saved", "fieldset", "register", "saved_calibration"]


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


@dataclass(frozen=True)
class Saved:
    """A run's saved calibration as the exports and the compensation use it.

    Attributes:
        calibrated: the tracker run's :class:`~robocal.identify.result.CalibrationResult`, or a
            constraint run's calibrated :class:`~robocal.model.chain.Model` (its end: the point
            the constraints held; no device frame).
        nominal: the constraint run's robot before calibration (the controller's model of its
            compensation and the URDF's comparison), None for a tracker run (the result's own).
        base_note: for a constraint run, what stays nominal and why (its base frame); "" else.
    """

    calibrated: Any
    nominal: Any = None
    base_note: str = ""

    @property
    def name(self) -> str:
        return str(getattr(self.calibrated, "model", self.calibrated).name)


def saved_calibration(run: Path | None) -> Saved:
    """The run folder's calibration with the command line's checks (``robocal export``'s
    ``_load_checked``): a ``model.yaml`` edited after the calibration, a value that cannot be a
    robot's, a constraint folder whose files disagree: ValueError naming the file."""
    from robocal.compensate.export import check_exportable, check_result_files
    from robocal.identify.constraints.result import is_constraint_folder, load_constraint_calibration
    from robocal.identify.result import CalibrationResult
    from robocal.model.yaml_files import ModelFileError

    if run is not None and is_constraint_folder(run):
        cal = load_constraint_calibration(run)  # model.yaml and constraints.json checked together
        check_exportable(cal.model)
        return Saved(cal.model, cal.nominal, cal.base_note())
    if run is None or not (run / "result.json").is_file():
        raise ValueError("calibrate first")
    try:
        result = CalibrationResult.load(run)
    except (OSError, KeyError, ModelFileError) as err:
        raise ValueError(f"cannot read the calibration result: {err}") from None
    check_result_files(run, result)
    check_exportable(result)
    return Saved(result)


def _compensate_or_export(
    workdir: Path, targets: str | None, reading: _TargetsReading, run_id: str | None
) -> tuple[Any, Any]:
    from dash import callback_context

    trigger = callback_context.triggered_id
    try:
        saved = saved_calibration(None if run_id is None else workdir / "runs" / run_id)
        if trigger == "upload-targets" and targets is not None:
            return _compensate(saved, targets, reading)
        if trigger == "export-urdf":
            return _urdf(saved)
        return _ur_kinematics(saved)
    except ValueError as err:
        message = gui_words(public_text(str(err), workdir))  # no server path on the page
        return no_update, html.Span(message, className="error", id="export-error")


def _compensate(saved: Saved, targets: str, reading: _TargetsReading) -> tuple[Any, Any]:
    """The targets' compensated commands, as ``robocal compensate --targets`` makes them (a
    constraint run: its start robot the controller's model, targets in the robot base only)."""
    if saved.nominal is not None and reading.frame != "base":
        raise ValueError(
            "targets frame device: a constraint calibration has no measuring device's frame; "
            "give the targets in the robot base"
        )
    sep = read_options(sep=reading.sep)["sep"]
    r = reading
    download, message = compensate(saved.calibrated, targets, r.filename, r.unit, r.frame, sep, r.decimal,
                                    nominal=saved.nominal)  # fmt: skip
    return download, "; ".join(m for m in (message, saved.base_note and f"note: {saved.base_note}") if m)


def _urdf(saved: Saved) -> tuple[Any, Any]:
    from robocal.compensate.export import export_urdf

    notes = (saved.base_note,) if saved.base_note else ()
    ex, _ = export_urdf(saved.calibrated, nominal=saved.nominal, notes=notes)  # notes: what it leaves out
    text = "; ".join(ex.notes) or "everything calibrated is carried"
    return {"content": ex.text, "filename": f"{saved.name}_calibrated.urdf"}, f"URDF written; {text}"


def _ur_kinematics(saved: Saved) -> tuple[Any, Any]:
    from robocal.compensate.export import export_ur_kinematics, kinematic_part, left_out

    part = kinematic_part(saved.calibrated)
    kin = export_ur_kinematics(part.calibrated)
    notes = [*part.notes, *(m.note for m in left_out(part.calibrated))]
    mm, deg = kin.flange_rest_mm_deg
    if mm > 1e-6 or deg > 1e-6:  # as robocal export ur-kinematics says it
        notes.append(f"the calibrated flange is {mm:.4f} mm / {deg:.5f} deg from the format's wrist_3 frame, "
                     "which the format cannot hold: add it to the controller's TCP")  # fmt: skip
    if saved.base_note:
        notes.append(saved.base_note)
    text = "UR kinematics written" + (f"; {'; '.join(notes)}" if notes else "")
    return {"content": kin.to_yaml(), "filename": "default_kinematics.yaml"}, text
