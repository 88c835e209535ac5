"""``robocal validate DIR``: error statistics of a calibrated model on (held-out) measurements."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer
from rich.table import Table

from robocal.cli.options import (
    AngleUnit,
    Columns,
    Decimal,
    Incomplete,
    Json,
    LengthUnit,
    Limits,
    Orientation,
    Sep,
    as_cli_text,
)
from robocal.cli.reading import load_result, own_data, read_data
from robocal.console import console, fail, safe
from robocal.safe_output import strict_json

__all__ = ["register"]

CALIBRATION_DIR = typer.Argument(
    metavar="CALIBRATION", help="a calibration output directory (model.yaml, result.json)", show_default=False
)


def stats_table(title: str, stats) -> Table:
    table = Table(title=title, title_justify="left")
    for col in ("poses", "mean mm", "RMS mm", "p95 mm", "max mm", "|x| |y| |z| mean mm", "frame"):
        table.add_column(col, justify="right")
    axes = " ".join(f"{v * 1e3:.4f}" for v in stats.axis_mean_abs)
    table.add_row(
        str(stats.n),
        f"{stats.mean * 1e3:.4f}",
        f"{stats.rms * 1e3:.4f}",
        f"{stats.p95 * 1e3:.4f}",
        f"{stats.max * 1e3:.4f}",
        axes,
        stats.frame,
    )
    return table


def validation_notes(stats, result, frame_note: bool = True) -> tuple[list[str], str | None]:
    """Lines under a validation table (how the device frame was obtained unless
    ``frame_note`` is False, the error the calibration expected) and a warning when the
    error is far from what it should be."""
    frames = {
        "calibrated": "the device frame identified by the calibration was used as it is",
        "refit": "the device frame was refitted to this data (--refit-frame)",
    }
    notes = [frames.get(stats.frame, "")] if frame_note else []
    if frame_note and stats.scoring is not None and stats.scoring != "in-sample":
        notes[0] += f": each row scored with the frame fitted on the other rows ({stats.scoring})"
    if stats.in_sample is not None:
        s = stats.in_sample
        notes.append(
            f"in-sample (the frame fitted and scored on the same {s.n} rows, looks better than it is): "
            f"mean {s.mean * 1e3:.4f} mm, RMS {s.rms * 1e3:.4f} mm"
        )
    if stats.expected_rms is not None:
        notes.append(
            f"the calibration expected an RMS error of {stats.expected_rms * 1e3:.4g} mm here "
            f"({stats.parameter_rms * 1e3:.3g} mm from its parameter"
            + (" and learned-residual" if result.model.residual is not None else "")
            + " uncertainty, the rest "
            + {
                "sigma": "the data's stated noise",
                "sigma+unmodelled": "the data's stated noise and the error its residuals showed beyond noise",
                "residual model": "the noise and error the learned residual left unexplained",
                "registration": "the refitted frame's own uncertainty from these poses and the error "
                "the calibration does not explain",
            }.get(stats.scatter or "", "the scatter of its own residuals")
            + f"); measured {stats.rms * 1e3:.4g} mm"
        )
    warning = None
    if stats.mean > max(20 * result.rms_after, 5e-3):
        warning = (
            f"the mean error is {stats.mean / max(result.rms_after, 1e-12):.0f}x the calibration's own "
            f"RMS residual ({result.rms_after * 1e3:.3g} mm)"
            + (": if the device was moved since, add --refit-frame;" if stats.frame == "calibrated" else ":")
            + " otherwise check the robot, the units and the column mapping"
        )
    elif stats.worse_than_expected:
        warning = (
            f"the error is {stats.rms / stats.expected_rms:.3g}x what the calibration expected: a robot "
            "or device that changed since, or errors the model does not represent in poses unlike the "
            "calibration's"
        )
    if warning:
        notes.append(f"[yellow]warning:[/] {safe(warning)}")
    return notes, warning


def _own_rows(rows, all_rows: bool, directory: Path, path: Path):
    """The rows of the calibration's own file that ``validate`` uses: the held-out ones (all
    with ``--all-rows``), a note saying which, and their label."""
    if rows.test is None and not all_rows:
        raise fail(
            f"{directory}: the calibration used every row of {path.name}: give held-out "
            "measurements with --data (or --all-rows to see the error on the calibration poses)"
        )
    if all_rows:
        note = f"every row of the calibration's own file ({rows.every.n}), its {rows.train.n} calibration"
        return rows.every, note + " rows included", "all"
    note = (
        f"the {rows.test.n} held-out rows of the calibration's own file (split by {rows.how}; "
        f"its {rows.train.n} calibration rows left out; --all-rows: every row)"
    )
    return rows.test, note, "test" if rows.how == "the file's set column" else "held-out"


def validate_command(
    ctx: typer.Context,
    directory: Annotated[Path, CALIBRATION_DIR],
    data_path: Annotated[
        Path | None,
        typer.Option(
            "--data",
            metavar="FILE",
            help="measurement CSV file (default: the calibration's own file, read with its options; "
            "its held-out rows)",
        ),
    ] = None,
    refit_frame: Annotated[
        bool, typer.Option("--refit-frame", help="the device was moved: refit its frame only")
    ] = False,
    as_json: Json = False,
    length_unit: LengthUnit = "m",
    angle_unit: AngleUnit = "rad",
    columns: Columns = None,
    sep: Sep = None,
    decimal: Decimal = ".",
    orientation: Orientation = "auto",
    limits: Limits = "error",
    incomplete: Incomplete = "error",
    all_rows: Annotated[
        bool, typer.Option("--all-rows", help="validate every row, also those marked train in a set column")
    ] = False,
) -> None:
    """Error statistics of a calibrated model on (held-out) measurements; for a constraint
    file (point, plane, pair/distance_mm columns) its own figures: the spread around each
    point, the distance errors, the plane residual."""
    import robocal as rc
    from robocal.cli.constraints import is_constraint_file, validate_constraint_file
    from robocal.identify.constraints.result import is_constraint_folder

    values = dict(length_unit=length_unit, angle_unit=angle_unit, columns=columns, sep=sep, decimal=decimal)
    values |= dict(orientation=orientation, limits=limits, incomplete=incomplete)
    if data_path is not None and is_constraint_file(data_path, None):
        _check_unread(data_path, values, refit_frame=refit_frame, all_rows=all_rows)
        return validate_constraint_file(directory, data_path, angle_unit, distances=None, as_json=as_json)
    if is_constraint_folder(directory):  # tracker rows judging a constraint calibration
        return validate_constraint_calibration(directory, data_path, refit_frame, as_json, values, all_rows)
    result = load_result(directory)
    notes, extra = [], {}
    if data_path is None and result.provenance is None and (directory / "test.csv").is_file():
        data_path = directory / "test.csv"  # the held-out poses written with the result (robocal demo)
        notes.append(f"the held-out poses written with the calibration ({data_path.name})")
    own = own_data(ctx, directory, result, data_path, values)
    if own is not None:
        data_path, rows = own
        data, note, extra["rows"] = _own_rows(rows, all_rows, directory, data_path)
        notes.append(note)
    else:
        assert data_path is not None  # own_data reads the calibration's own file without --data
        data = read_data(data_path, result.model, **values)
    if own is None and data.split is not None and "test" in set(data.split.tolist()) and not all_rows:
        data = data.split_rows("test")
        notes.append(f"the {data.n} rows marked test in the file's set column (--all-rows: every row)")
        extra["rows"] = "test"
    try:
        stats = rc.validate(result, data, refit_frame=refit_frame)
    except ValueError as err:
        raise fail(f"{data_path}: {as_cli_text(str(err))}") from None
    more_notes, warning = validation_notes(stats, result)
    notes += more_notes
    if warning:
        extra["warning"] = warning
    if as_json:
        print(strict_json(stats.to_dict() | extra))
        return
    console.print(stats_table(f"{result.model.name} on {data_path.name} ({data.n} poses)", stats))
    for note in filter(None, notes):
        console.print(note, highlight=False, markup=True)


def _check_unread(data_path: Path, values: dict, refit_frame: bool, all_rows: bool) -> None:
    """The constraint figures read a constraint file's joint columns only: an option they
    would ignore is refused, named (one line)."""
    unread = {"--refit-frame": refit_frame, "--all-rows": all_rows,
              "--columns": values["columns"], "--length-unit": values["length_unit"] != "m",
              "--sep": values["sep"], "--decimal": values["decimal"] != ".",
              "--orientation": values["orientation"] != "auto",
              "--incomplete": values["incomplete"] != "error"}  # fmt: skip
    if given := [name for name, value in unread.items() if value]:
        raise fail(f"{', '.join(given)}: not available for a constraint file ({data_path}): its "
                   "figures read only its joint columns")  # fmt: skip


def validate_constraint_calibration(
    directory: Path, data_path: Path | None, refit_frame: bool, as_json: bool, values: dict, all_rows: bool
) -> None:
    """``robocal validate`` of a constraint calibration folder on a tracker file: the
    position errors of its calibrated robot (its tool, its joints' elastic deflections) in
    the device frame its tracker rows identified, or (``refit_frame``) in a frame fitted to
    the file and scored K-fold; the nominal robot's beside them, as text or JSON."""
    from robocal.cli.report_constraints import load_constraint_folder

    cal = load_constraint_folder(directory)
    kinds = ", ".join(cal.kinds) or "constraint"
    if data_path is None:
        raise fail(
            f"{directory}: a constraint calibration ({kinds}): give the measurements to judge it on with "
            "--data (a constraint file, or a tracker file of x, y, z)"
        )
    if cal.T_device_base is None and not refit_frame:
        raise fail(
            f"{directory}: calibrated from {kinds} rows without tracker rows, so it has no device frame for "
            f"{data_path}: add --refit-frame (the frame fitted to the file, each row scored by a frame "
            "fitted on the others)"
        )
    from robocal.identify.constraints.result import validate_on_tracker

    data = read_data(data_path, cal.model, **values)
    fitted = cal.fitted_tracker_file(data_path)
    notes = _constraint_notes(cal, data_path, fitted)
    extra: dict = {"calibration": "constraint", "kinds": list(cal.kinds)}
    if data.split is not None and "test" in set(data.split.tolist()) and not all_rows:
        data = data.split_rows("test")
        notes.insert(0, f"the {data.n} rows marked test in the file's set column (--all-rows: every row)")
        extra["rows"] = "test"
    try:
        judged = validate_on_tracker(cal, data, refit_frame, fitted)
    except ValueError as err:
        raise fail(f"{data_path}: {as_cli_text(str(err))}") from None
    stats, nominal = judged.after, judged.before
    more_notes, warning = validation_notes(stats, cal.tracker_result())
    extra |= {"warning": warning} if warning else {}
    if as_json:
        doc = stats.to_dict() | extra | {"expected_rms_mm": None, "fitted_file": fitted}
        print(strict_json(doc | {"nominal": None if nominal is None else nominal.to_dict()}))
        return
    console.print(stats_table(f"{safe(cal.model.name)} on {safe(data_path.name)} ({data.n} poses)", stats))
    for note in filter(None, more_notes[:1] + notes + more_notes[1:]):
        console.print(note, highlight=False, markup=True)
    if nominal is not None:
        console.print(stats_table("before calibration (the nominal robot it started from)", nominal))


def _constraint_notes(cal, data_path: Path, fitted: bool) -> list[str]:
    """What a constraint calibration's tracker validation leaves out, and an in-sample file."""
    notes = [
        "a constraint calibration records no covariance of the robot's parameters: the error it "
        "expected here is not available"
    ]
    if not cal.length_measured:
        # fixed points and planes of unknown size leave the arm's scale to the prior (issue 33)
        notes.append(
            "nothing in its data measured a length (no --distance, no ball-bar or tracker rows): its "
            "scale is not calibrated, and position errors grow with the reach"
        )
    if cal.joint_effects:
        notes.append(
            "the joint effects its tilt rows identified (clearance, backlash, compliance) are left out, "
            "as its fit left them out of position rows"
        )
    if fitted:
        notes.append(
            f"[yellow]warning:[/] {safe(data_path.name)} is a tracker file this calibration was fitted to: "
            "in-sample, it looks better than it is; give held-out rows"
        )
    return notes


def register(app: typer.Typer) -> None:
    """Add ``validate`` to the ``robocal`` app."""
    app.command("validate")(validate_command)
