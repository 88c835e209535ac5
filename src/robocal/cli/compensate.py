"""``robocal compensate``: corrected joint commands for an off-line program.

    robocal compensate DIR --targets FILE.csv [--frame base|measurement] [--length-unit mm] -o corrected.csv
    robocal compensate DIR --program FILE.csv [--angle-unit deg] -o corrected.csv

``DIR`` is a calibration output directory (``robocal calibrate --out DIR``: ``model.yaml``
and ``result.json``) or a calibrated model file (``.yaml``; base frame only; the
errors "before" are those its joint effects cause, none without).  ``--targets`` is a
CSV of Cartesian targets ``name,x,y,z``
(+ ``qw,qx,qy,qz`` for tool orientations) in the robot's base frame or in the
measurement (cell) frame identified by the calibration; ``--program`` a joint program
``[name,]q1..qN`` computed with the nominal model (the calibration-filter use).  The
output (``-o``, CSV or ``.json``) holds ``name``, the corrected ``q1..qN``, the nominal
``nominal_q1..nominal_qN``, ``predicted_error_before_mm`` (the calibrated model's error
at the nominal commands), ``predicted_error_after_mm`` (what the IK left against the
calibrated model), ``expected_error_after_mm`` (the calibration's uncertainty and
unexplained error at the corrected commands), ``reachable`` and ``status``.  Every run
prints a per-target table (predicted error before, correction, largest joint change,
configuration, status and reason) and writes it beside the output as ``OUT.table.csv``.
A target that cannot be corrected safely (:mod:`robocal.compensate.safety`: unreachable,
a joint change beyond the calibration's bound, another configuration) is *refused*: its
nominal command is written as is, it is named with its reason, and the exit status is 1
unless ``--partial`` accepts partial output; 2 on bad input.  The bound is per target,
``1.5 |e| / sigma_min`` (``|e|`` the predicted error at the nominal command, m and rad;
``sigma_min`` the Jacobian's smallest singular value), between 0.05° and 5°: about 1° or
less where a calibrated arm is well conditioned.  Near a singularity (``sigma_min < 0.02``)
the correction is damped, each joint within ``|e| / 0.04`` and 0.1 rad.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer
from rich.table import Table

from robocal.choices import AngleUnit, Frame, LengthUnit, TargetKind
from robocal.cli.options import Decimal, Force, Json, Sep, joint_values, out_option, resolve_model
from robocal.console import console, err_console, fail, input_problem, refuse_overwrite, safe
from robocal.safe_output import strict_json

__all__ = ["register"]

#: the calibration (a result folder or a model file) that compensate, filter and export read
CALIBRATION = typer.Argument(
    metavar="CALIBRATION", help="calibration directory (result.json) or model .yaml", show_default=False
)


def load(source: Path):
    """A CalibrationResult from a directory, or a Model from a model file."""
    from robocal.identify.result import CalibrationResult
    from robocal.model.files import load_model
    from robocal.model.yaml_files import ModelFileError
    from robocal.outdir import restore

    restore(source)  # a writer killed mid-swap on a system without atomic exchange
    if source.is_dir():
        if not (source / "result.json").is_file() and (source / "constraints.json").is_file():
            from robocal.cli.report_constraints import load_constraint_folder, note_constraint_base

            constraint = load_constraint_folder(source)  # its calibrated robot, its base nominal: say so
            note_constraint_base(constraint, "corrected relative to the nominal base")
            return constraint.model
        if not (source / "result.json").is_file():
            raise fail(
                f"{source} holds no calibration result (result.json); run robocal calibrate --out {source}"
            )
        try:
            return CalibrationResult.load(source)
        except (OSError, ValueError, KeyError, ModelFileError) as err:
            raise fail(f"{source}: cannot read the calibration result: {err}") from None
    if source.is_file():
        from robocal.compensate.compensation import model_perturbations

        try:
            model = load_model(source)
            model_perturbations(model)  # joint effects it states must be computable
        except (OSError, ModelFileError) as err:
            raise fail(str(err)) from None
        except ValueError as err:
            raise fail(f"{source}: {err}") from None
        return model
    problem = input_problem(source, "calibration directory or model file") or f"{source} cannot be read"
    raise fail(problem + (" (a calibration directory or a model file)" if problem.endswith("exist") else ""))


TargetsOption = Annotated[
    Path | None,
    typer.Option("--targets", metavar="FILE", help="CSV of Cartesian targets name,x,y,z[,qw,qx,qy,qz]"),
]
ProgramOption = Annotated[
    Path | None,
    typer.Option(
        "--program",
        metavar="FILE",
        help="CSV joint program q1..qN (+ optional name) from the nominal model",
    ),
]
FrameOption = Annotated[
    Frame,
    typer.Option("--frame", metavar="base|measurement", help="base | measurement: the frame of the targets"),
]
LengthUnitOption = Annotated[
    LengthUnit,
    typer.Option("--length-unit", metavar="m|mm|um", help="m | mm | um: target positions, prismatic joints"),
]
AngleUnitOption = Annotated[
    AngleUnit,
    typer.Option(
        "--angle-unit",
        metavar="rad|deg",
        help="rad | deg: joint values in --program, --q0 and the output",
    ),
]
KindOption = Annotated[
    TargetKind | None,
    typer.Option(
        "--kind",
        metavar="position|pose|axis",
        help="position | pose | axis (default from the file / robot)",
    ),
]
NominalOption = Annotated[
    str | None,
    typer.Option("--nominal", metavar="ROBOT", help="the controller's model: catalog name or .yaml"),
]
PartialOption = Annotated[
    bool,
    typer.Option(
        "--partial",
        help="accept partial output: exit 0 although targets were refused (left as written)",
    ),
]
Q0Option = Annotated[
    str | None,
    typer.Option(
        "--q0",
        metavar='"q1,...,qn"',
        help='configuration choosing the branch, e.g. "0,-90,90,0,90,0deg" (no unit: --angle-unit)',
    ),
]


def compensate_command(
    source: Annotated[Path, CALIBRATION],
    targets: TargetsOption = None,
    program: ProgramOption = None,
    out: Annotated[Path | None, out_option("output file: .csv or .json")] = None,
    frame: FrameOption = "base",
    length_unit: LengthUnitOption = "m",
    angle_unit: AngleUnitOption = "rad",
    kind: KindOption = None,
    nominal: NominalOption = None,
    q0: Q0Option = None,
    sep: Sep = None,
    decimal: Decimal = ".",
    as_json: Json = False,
    force: Force = False,
    partial: PartialOption = False,
) -> None:
    """Corrected joint commands that bring the calibrated robot onto an off-line program's targets.

    Each target is corrected, damped near a singularity or refused (left as written, exit 1 unless --partial).

    Bound: a joint moves at most 1.5 |e| / sigma_min, 0.05 to 5 deg (about 1 deg where well conditioned).

    Damped: sigma_min < 0.02, each joint within |e| / 0.04 and 0.1 rad.  Table: OUT.table.csv beside -o."""
    if out is not None:
        refuse_overwrite(out, force, "output file")
        from robocal.compensate.result import table_path

        refuse_overwrite(table_path(out), force, "per-target table")
    from robocal.identify.result import CalibrationResult

    if (targets is None) == (program is None):
        raise fail("give exactly one of --targets FILE (Cartesian) or --program FILE (joint program)")
    if out is not None and out.suffix.lower() not in (".csv", ".json", ".txt"):
        raise fail(f"-o {out}: the output must be a .csv or .json file")
    calibrated = load(source)
    model = calibrated.model if isinstance(calibrated, CalibrationResult) else calibrated
    if frame == "measurement" and not isinstance(calibrated, CalibrationResult):
        raise fail(
            f"--frame measurement needs a calibration directory with a device frame; {source} has none"
        )
    nominal_model = _checked_nominal(calibrated, nominal)
    nominal_model = _constraint_start(source, program is not None) if nominal_model is None else nominal_model
    q_start = None if q0 is None else joint_values(q0, model, "--q0", angle_unit, length_unit)
    reader = dict(length_unit=length_unit, angle_unit=angle_unit, sep=sep, decimal=decimal)
    if targets is not None:
        result, source_file = _compensate_targets(
            calibrated, targets, nominal_model, kind, frame, q_start, reader
        )
    elif program is not None:
        result, source_file = _filter_program(calibrated, model, program, nominal_model, kind, reader)
    else:  # pragma: no cover - exactly one of them was given (checked above)
        raise fail("give --targets FILE or --program FILE")
    if out is not None:
        from robocal.compensate.result import table_path

        result.write(out, angle_unit=angle_unit, length_unit=length_unit)
        result.write_table(table_path(out))
    if as_json:
        print(strict_json(result.to_dict(angle_unit, length_unit)))
    else:
        _print(result, model.name, source_file)
        print_target_table(result.table())
        if out is not None:
            console.print(f"wrote {out} and its per-target table {table_path(out).name}", highlight=False)
    from robocal.identify.coverage import coverage_warnings
    from robocal.identify.measured_tool import orientation_warnings

    flanks = [f"{name}: {note}" for name, note in zip(result.names, result.flank_notes, strict=False) if note]
    for line in (  # what the poses left open, and where they never went; flanks not known
        *result.notes,
        *flanks,
        *orientation_warnings(calibrated, result.q, result.names),
        *coverage_warnings(calibrated, result.q, result.names),
    ):
        err_console.print(f"[yellow]warning:[/] {safe(line)}", highlight=False, markup=True)
    finish(result.table(), partial)


def finish_filtered(result, out: Path, partial: bool, strict: bool) -> None:
    """``filter``'s end, compensate's rule: the per-target table printed and written beside
    ``out``; refused targets (already named with file, line and reason) exit 1 unless
    ``--partial``; ``--strict``: any other warning exits 1 too."""
    from robocal.compensate.result import table_csv, table_path
    from robocal.outdir import atomic_write_text

    rows = list(result.table)
    print_target_table(rows)
    atomic_write_text(table_path(out), table_csv(rows))
    console.print(f"wrote the per-target table {table_path(out).name}", highlight=False)
    finish(rows, partial, listed=True)
    if strict and result.problems:
        raise typer.Exit(code=1)


def finish(rows: list[dict], partial: bool, listed: bool = False) -> None:
    """Name every refused target with its reason (``listed``: already named); exit 1 when
    there is one, unless ``--partial``."""
    refused = [r for r in rows if r["status"] == "refused"]
    for r in rows:
        if r["status"] == "damped":
            console.print(f"damped: {safe(r['name'])}: {safe(r['reason'])}", highlight=False)
    for r in refused if not listed else ():
        err_console.print(
            f"[yellow]refused:[/] {safe(r['name'])}: {safe(r['reason'])} (left as written)",
            highlight=False,
            markup=True,
        )
    unreached = [r["name"] for r in refused if "reach" in r["reason"]]
    if unreached:
        err_console.print(
            f"[yellow]warning:[/] {len(unreached)} target(s) not reached: {safe(', '.join(unreached[:10]))}"
            + (" ..." if len(unreached) > 10 else ""),
            highlight=False,
            markup=True,
        )
    if refused and not partial:
        err_console.print(
            f"error: {len(refused)} of {len(rows)} target(s) refused; the output holds them as written "
            "(--partial accepts that)",
            highlight=False,
        )
        raise typer.Exit(code=1)


#: rows of the per-target table printed in full; refused and damped rows always are
_PRINTED_ROWS = 30


def print_target_table(rows: list[dict]) -> None:
    """The per-target table (:meth:`robocal.compensate.result.Compensation.table`)."""
    flagged = [r for r in rows if r["status"] != "corrected"]
    shown = flagged + [r for r in rows if r["status"] == "corrected"][: max(0, _PRINTED_ROWS - len(flagged))]
    order = {id(r): k for k, r in enumerate(rows)}
    shown.sort(key=lambda r: order[id(r)])
    table = Table(title="per target", title_justify="left")
    for col in ("target", "before mm", "correction mm", "largest joint change", "configuration", "status"):
        table.add_column(col, justify="left" if col in ("target", "configuration", "status") else "right")

    def num(v, digits: int = 4) -> str:
        return "-" if v is None else f"{v:.{digits}f}"

    for r in shown:
        change = (
            "-" if r["largest_joint_change"] is None else f"{r['largest_joint_change']:.4f} {r['joint_unit']}"
        )
        table.add_row(
            safe(r["name"]), num(r["error_before_mm"]), num(r["correction_mm"]),
            safe(f"{change} {r['joint']}"), safe(r["configuration"]), safe(r["status"]),
        )  # fmt: skip
    console.print(table)
    if len(shown) < len(rows):
        more = len(rows) - len(shown)
        console.print(f"  ({more} more corrected targets in the table file)", highlight=False)


def _constraint_start(source: Path, required: bool):
    """A constraint calibration's start model (the default ``--nominal``), else None."""
    if not (source.is_dir() and (source / "constraints.json").is_file()):
        return None
    from robocal.cli.report_constraints import constraint_nominal

    return constraint_nominal(source, required)


def _checked_nominal(calibrated, nominal: str | None):
    """``--nominal`` as a model, refused when it is not the calibration's robot (another
    robot's model would turn every target into nonsense)."""
    if nominal is None:
        return None
    from robocal.compensate.programs.frames import check_nominal
    from robocal.compensate.programs.syntax import ProgramError

    model = resolve_model(nominal)
    try:
        check_nominal(calibrated, model)
    except ProgramError as err:
        raise fail(f"--nominal {nominal}: {err}") from None
    return model


def _compensate_targets(calibrated, targets: Path, nominal_model, kind, frame: str, q_start, reader: dict):
    """``--targets``: joint commands for Cartesian targets; the result and the file read."""
    from robocal.compensate.compensation import compensate_targets
    from robocal.compensate.ik_options import IKOptions
    from robocal.compensate.target_files import TargetFileError, read_targets

    try:
        tgt = read_targets(
            targets, length_unit=reader["length_unit"], sep=reader["sep"], decimal=reader["decimal"]
        )
        if kind == "position" and tgt.kind == "pose":
            values = tgt.values[:, :3, 3]
        elif kind in ("pose", "axis") and tgt.kind == "position":
            raise fail(f"--kind {kind} needs orientation columns qw,qx,qy,qz in {targets}")
        else:
            values = tgt.values
        with console.status(f"compensating {len(tgt.names)} targets ..."):
            result = compensate_targets(
                calibrated,
                values,
                nominal_model,
                kind=kind or "auto",
                frame=frame,
                q0=q_start,
                names=tgt.names,
                ik=IKOptions(),  # the command line's IK settings: the defaults, one value
            )
    except TargetFileError as err:
        raise fail(str(err)) from None
    except ValueError as err:
        raise fail(f"{targets}: {err}") from None
    return result, targets


def _filter_program(calibrated, model, program: Path, nominal_model, kind, reader: dict):
    """``--program``: a nominal joint program corrected; the result and the file read."""
    from robocal.compensate.compensation import filter_program
    from robocal.compensate.ik_options import IKOptions
    from robocal.compensate.target_files import TargetFileError, read_program

    try:
        names, q = read_program(program, model.dof, joint_types=model.joint_types, **reader)
        with console.status(f"filtering {len(names)} program points ..."):
            result = filter_program(calibrated, q, nominal_model, kind=kind, names=names, ik=IKOptions())
    except TargetFileError as err:
        raise fail(str(err)) from None
    except ValueError as err:
        raise fail(f"{program}: {err}") from None
    return result, program


def _print(result, robot: str, source: Path) -> None:
    s = result.summary()
    console.print(
        f"[bold]{safe(robot)}[/] — {s['n']} {result.kind} targets from {safe(source.name)}: "
        f"{s['reachable']} reached, {s['branch_kept']} in the nominal configuration",
        highlight=False,
        markup=True,
    )
    table = Table(
        title=f"position error of the real robot at the {s['reachable']} reached targets",
        title_justify="left",
    )
    for col in (
        "commands",
        "mean mm",
        "max mm",
        *(("mean deg", "max deg") if result.kind != "position" else ()),
    ):
        table.add_column(col, justify="left" if col == "commands" else "right")

    def cell(v) -> str:
        return "-" if v is None else f"{v:.4f}"

    before = ["nominal (before), as the calibrated model predicts", *_cells(s, "error_before_mm", cell)]
    after = ["compensated (after), expected from its uncertainty"]
    after += _cells(s, "expected_error_after_mm", cell)
    if result.kind != "position":
        before += _cells(s, "angle_before_deg", cell)
        after += ["-", "-"]
    table.add_row(*before)
    table.add_row(*after)
    console.print(table)
    if s["expected_error_after_mm"]["mean"] is None:
        console.print(
            "  (a bare model file or a constraint calibration carries no uncertainty here: a tracker "
            "calibration folder gives the error to expect after compensation)",
            highlight=False,
        )


def _cells(summary: dict, key: str, cell) -> list[str]:
    return [cell(summary[key]["mean"]), cell(summary[key]["max"])]


def register(app: typer.Typer) -> None:
    """Add ``compensate`` to the ``robocal`` app."""
    app.command("compensate")(compensate_command)
