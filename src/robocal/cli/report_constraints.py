"""A constraint calibration's folder on the command line: ``robocal report`` of it, and the
loading that ``export``, ``compensate`` and ``filter`` share (:mod:`robocal.cli.constraints`
writes the folder: ``model.yaml`` and ``constraints.json``, no ``result.json``).

The report judges the calibration file (the recorded one, when it is still there unchanged,
or ``--data``) and a held-out file (``--test-data``) by each kind's own figures, before and
after (:mod:`robocal.evaluate.report.constraint_sections`).
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

from robocal.console import console, err_console, fail, safe

__all__ = ["constraint_nominal", "constraint_report", "load_constraint_folder", "note_constraint_base"]


def load_constraint_folder(directory: Path):
    """The :class:`~robocal.identify.constraints.result.ConstraintCalibration` in
    ``directory`` (exit 2 with one line when it cannot be read or its files disagree)."""
    from robocal.identify.constraints.result import load_constraint_calibration

    try:
        return load_constraint_calibration(directory)
    except ValueError as err:
        raise fail(str(err)) from None


def constraint_nominal(directory: Path, required: bool):
    """The robot a constraint calibration in ``directory`` started from (the default
    ``--nominal`` of compensate and filter: the program's robot); exit 2 when ``required``
    (a joint program to correct) and the folder does not record it."""
    nominal = load_constraint_folder(directory).nominal
    if nominal is None and required:
        raise fail(
            f"{directory}: this constraint calibration does not record the robot it started from; "
            "give the controller's model with --nominal ROBOT"
        )
    return nominal


def note_constraint_base(cal, use: str) -> None:
    """Say on stderr, once, that ``use`` (e.g. "the URDF") holds the nominal base, and that
    the arm's scale was not measured when nothing in the data measured a length."""
    if cal.unseen:
        err_console.print(f"[yellow]note:[/] {use}: {safe(cal.base_note())}", highlight=False, markup=True)
    if not cal.length_measured and "tilt" not in cal.kinds:
        err_console.print(
            f"[yellow]note:[/] {use}: nothing in the calibration's data measured a length (no "
            "--distance, ball-bar or tracker rows): the arm's overall scale rests on a nominal length, "
            "and its error grows with the reach",
            highlight=False,
            markup=True,
        )


def _read(path: Path, cal, angle_unit: str):
    from robocal.measure.constraints.data import ConstraintFileError, read_constraints

    try:
        return read_constraints(path, cal.model.dof, angle_unit=angle_unit, distances=list(cal.distances))
    except ConstraintFileError as err:
        raise fail(str(err)) from None


def _recorded_file(cal) -> tuple[Path | None, str]:
    """The calibration's own file when it is still there unchanged, else why not."""
    from robocal.identify.result_io import file_hash

    recorded = cal.data_path
    if recorded is None:
        return None, "the calibration does not record its file: give --data FILE for its figures"
    candidates = [recorded] if recorded.is_absolute() else [recorded, cal.directory.parent / recorded]
    for path in candidates:
        if path.is_file():
            if cal.data_sha256 is None or file_hash(path) == cal.data_sha256:
                return path, ""
            return None, (
                f"the calibration file {path} has changed since the calibration (not its recorded "
                "SHA-256): its figures are not shown; give --data FILE"
            )
    return None, f"the calibration file {recorded} is not found: give --data FILE for its figures"


def _tracker(cal, path: Path, values: dict):
    """``cal`` judged on the tracker file ``path``: in the device frame its tracker rows
    identified, else in a frame fitted to the file and scored K-fold (the report has no
    --refit-frame: a calibration without a frame can only be judged so)."""
    from robocal.cli.options import as_cli_text
    from robocal.cli.reading import read_data
    from robocal.identify.constraints.result import validate_on_tracker

    data = read_data(path, cal.model, **values)
    try:
        judged = validate_on_tracker(cal, data, cal.T_device_base is None, cal.fitted_tracker_file(path))
    except ValueError as err:
        raise fail(f"{path}: {as_cli_text(str(err))}") from None
    return dataclasses.replace(judged, source=path.name)


def constraint_report(
    directory: Path,
    out: Path,
    data_path: Path | None,
    test_path: Path | None,
    angle_unit: str | None,
    title: str | None,
    values: dict | None = None,
) -> None:
    """Write the HTML report of the constraint calibration in ``directory`` to ``out``.

    ``angle_unit``: the joint unit of the files (None: the one the calibration recorded);
    ``test_path`` a constraint file or a tracker file (read with the reader options
    ``values``: its position errors, :func:`_tracker`)."""
    from robocal.evaluate.report.constraint_collect import collect_constraint_report
    from robocal.evaluate.report.constraint_sections import write_constraint_report
    from robocal.measure.constraints.data import constraint_kind

    cal = load_constraint_folder(directory)
    unit = angle_unit or cal.angle_unit or "rad"
    missing = []
    if data_path is None:
        data_path, why = _recorded_file(cal)
        missing += [why] if why else []
    data = None if data_path is None else _read(data_path, cal, unit)
    tracker = None
    if test_path is not None and test_path.is_file() and constraint_kind(test_path) is None:
        tracker, test_path = _tracker(cal, test_path, dict(values or {}, angle_unit=unit)), None
    test = None if test_path is None else _read(test_path, cal, unit)
    if test is None and tracker is None:
        missing.append("no held-out file: give --test-data FILE (another placement) to judge the calibration")
    names = (data_path.name if data_path else "", test_path.name if test_path else "")
    report = collect_constraint_report(cal, data, test, sources=names, missing=tuple(missing), title=title,
                                       tracker=tracker)  # fmt: skip
    try:
        with console.status("writing the report ..."):
            path = write_constraint_report(report, out)
    except (OSError, ValueError) as err:
        raise fail(f"{out}: {err}") from None
    console.print(f"wrote {path}", highlight=False)
    for why in missing:
        err_console.print(f"[yellow]note:[/] {safe(why)}", highlight=False, markup=True)
