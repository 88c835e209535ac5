"""``robocal export``: the calibrated robot in the formats the robot's software reads.

    robocal export urdf DIR [--urdf ORIGINAL.urdf] [--joint-map a=b,...] [--tip LINK]
                            [--device-link NAME] [--tool-link NAME] -o OUT.urdf
    robocal export ur-kinematics DIR [--base-rz-pi] -o calibration.yaml
    robocal filter DIR PROGRAM [--tool x,y,z,rx,ry,rz] [--probe x,y,z]
                           [--config-dat PATH] [--partial] [--strict] -o OUT

``DIR`` is a calibration directory (``model.yaml`` + ``result.json``) or a model file.
``export urdf`` rewrites the joint origins of ``--urdf`` (the URDF the model was built
from) and keeps everything else; without ``--urdf`` it writes a kinematic URDF of its
own.  What the file cannot carry (joint effects, a learned residual) is printed with its
size and stated in an XML comment.  ``export ur-kinematics`` writes the UR ROS
description's ``default_kinematics.yaml`` format.  Both carry a calibration without a
learned residual; for a hybrid one (``--residual auto`` chose the residual) the best
physics-only calibration stored with it, both CV errors stated.  A ``model.yaml`` edited
after the calibration, a non-finite or implausible value or device frame, or a name that
is not a safe URDF name is refused.  Exit status 2 on bad input (nothing written).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Annotated

import typer

from robocal.choices import AngleUnit, LengthUnit
from robocal.cli.compensate import CALIBRATION, PartialOption
from robocal.cli.options import CONTEXT, Force, frame_option, out_option, resolve_model
from robocal.console import console, err_console, fail, refuse_overwrite, safe, warn

__all__ = ["register"]

export_app = typer.Typer(
    help="Export a calibration: calibrated URDF, UR kinematics.",
    no_args_is_help=True,
    context_settings=CONTEXT,
)


@export_app.command("urdf")
def urdf_command(
    source: Annotated[Path, CALIBRATION],
    out: Annotated[Path, out_option("the URDF to write")],
    urdf: Annotated[
        Path | None,
        typer.Option(
            "--urdf", metavar="FILE", help="the URDF the model was built from (kept but for origins)"
        ),
    ] = None,
    tip: Annotated[
        str | None, typer.Option("--tip", metavar="LINK", help="link at the model's flange (default: last)")
    ] = None,
    device_link: Annotated[
        str | None,
        typer.Option(
            "--device-link", metavar="NAME", help="add the device frame as a new root link of this name"
        ),
    ] = None,
    tool_link: Annotated[
        str | None,
        typer.Option("--tool-link", metavar="NAME", help="add the measured tool as a link of this name"),
    ] = None,
    joint_map: Annotated[
        str | None,
        typer.Option(
            "--joint-map",
            metavar="a=b,...",
            help="model joint = URDF joint, for a URDF whose joint names differ (default: by chain order)",
        ),
    ] = None,
    force: Force = False,
) -> None:
    """A URDF whose forward kinematics are the calibrated model's (joint offsets folded into origins)."""
    refuse_overwrite(out, force, "URDF")
    from robocal.compensate.export import export_urdf
    from robocal.identify.result import CalibrationResult
    from robocal.model.urdf.read import URDFError
    from robocal.outdir import atomic_write_text

    calibrated = _load_checked(source)
    constraint = _constraint_calibration(source)
    if device_link is not None and not isinstance(calibrated, CalibrationResult):
        what = "a constraint calibration (no measuring device)" if constraint else "a model"
        raise fail(f"--device-link needs a calibration directory (its device frame); {source} is {what}")
    mapping = _joint_map(joint_map)
    extra = {} if constraint is None else {"nominal": constraint.nominal, "notes": (constraint.base_note(),)}
    try:
        ex, _ = export_urdf(
            calibrated,
            urdf,
            tip=tip,
            device_link=device_link,
            tool_link=tool_link,
            joint_map=mapping,
            **extra,
        )
    except FileNotFoundError as err:
        raise fail(str(err)) from None
    except (URDFError, ValueError) as err:
        raise fail(str(err)) from None
    atomic_write_text(out, ex.text)
    what = f"{urdf.name} with {len(ex.changed)} joint origins calibrated" if urdf else "a kinematic URDF"
    console.print(f"wrote {out}: {what}; root {ex.root}, flange {ex.tip}", highlight=False)
    if ex.tool_link:
        console.print(f"measured tool: link {ex.tool_link}", highlight=False)
    for note in ex.notes:  # what the URDF leaves out (with sizes), and where the flange went
        err_console.print(f"[yellow]note:[/] {safe(note)}", highlight=False, markup=True)


@export_app.command("ur-kinematics")
def ur_kinematics_command(
    source: Annotated[Path, CALIBRATION],
    out: Annotated[Path, out_option("the YAML to write")],
    base_rz_pi: Annotated[
        bool,
        typer.Option(
            "--base-rz-pi", help="the model's base is a ROS base_link (the UR base turned by 180 deg about z)"
        ),
    ] = False,
    force: Force = False,
) -> None:
    """The calibrated kinematics as a UR description default_kinematics.yaml."""
    refuse_overwrite(out, force, "kinematics file")
    from robocal import spatial
    from robocal.compensate.export import export_ur_kinematics, kinematic_part, left_out

    calibrated = _load_checked(source)
    base = spatial.homogeneous(spatial.rotz(math.pi)) if base_rz_pi else None
    try:
        part = kinematic_part(calibrated)
        kin = export_ur_kinematics(part.calibrated, None, T_base_urbase=base)
    except ValueError as err:
        raise fail(f"{source}: {err}") from None
    from robocal.outdir import atomic_write_text

    atomic_write_text(out, kin.to_yaml())
    console.print(
        f"wrote {out}: UR kinematics (ur_description default_kinematics.yaml format)", highlight=False
    )
    mm, deg = kin.flange_rest_mm_deg
    if mm > 1e-6 or deg > 1e-6:
        err_console.print(
            f"[yellow]note:[/] the calibrated flange is {mm:.4f} mm / {deg:.5f} deg from the format's "
            "wrist_3 frame, which the format cannot hold: add it to the controller's TCP",
            highlight=False,
            markup=True,
        )
    for note in (*part.notes, *(m.note for m in left_out(part.calibrated))):
        err_console.print(f"[yellow]note:[/] {safe(note)}", highlight=False, markup=True)
    constraint = _constraint_calibration(source)
    if constraint is not None and constraint.unseen:
        err_console.print(f"[yellow]note:[/] {safe(constraint.base_note())}", highlight=False, markup=True)


def _constraint_calibration(source: Path):
    """The constraint calibration in folder ``source`` (:mod:`robocal.cli.report_constraints`), or None."""
    from robocal.identify.constraints.result import is_constraint_folder

    if not is_constraint_folder(source):
        return None
    from robocal.cli.report_constraints import load_constraint_folder

    return load_constraint_folder(source)


def _load_checked(source: Path):
    """The calibration (or model) to export, refused when its files disagree (a hand-edited
    ``model.yaml``) or its numbers cannot be a robot's (a 1e308 device frame)."""
    from robocal.cli.compensate import load
    from robocal.compensate.export import check_exportable, check_result_files
    from robocal.identify.result import CalibrationResult

    constraint = _constraint_calibration(source)
    calibrated = load(source) if constraint is None else constraint.model
    try:
        if isinstance(calibrated, CalibrationResult):
            check_result_files(source, calibrated)
        check_exportable(calibrated, f"{source}: ")
    except ValueError as err:
        raise fail(str(err)) from None
    return calibrated


def _joint_map(text: str | None) -> dict[str, str] | None:
    """``--joint-map "a=b,c=d"`` (model joint = URDF joint) -> a dict."""
    if text is None:
        return None
    pairs = [p.split("=") for p in text.split(",") if p.strip()]
    if not pairs or any(len(p) != 2 or not p[0].strip() or not p[1].strip() for p in pairs):
        raise fail(f"--joint-map {text!r}: give model_joint=urdf_joint pairs separated by commas")
    mapping = {a.strip(): b.strip() for a, b in pairs}
    if len(mapping) != len(pairs) or len(set(mapping.values())) != len(mapping):
        raise fail(f"--joint-map {text!r}: a joint named twice")
    return mapping


# a tool this far from the flange is a length in the wrong unit (e.g. 0,0,109m): refused
# rather than filtered with a tool metres long
_TOOL_REACH_M = 5.0


def _frame_option(text: str | None, what: str):
    """``"x,y,z,rx,ry,rz"`` with units (``"0,0,109mm,0,0,90deg"``, rotation vector) -> 4x4."""
    if text is None:
        return None
    T = frame_option(text, what)
    if what != "--base":
        _check_reach(T[:3, 3], text, what)
    return T


def _probe_option(text: str | None):
    """``--probe``: ``"x,y,z"`` with a unit on the flange, or a whole frame ``"x,y,z,rx,ry,rz"``."""
    if text is None:
        return None
    T = frame_option(text, "--probe", position_only=True)
    _check_reach(T[:3, 3], text, "--probe")
    return T if len(text.split(",")) == 6 else list(T[:3, 3])


def _check_reach(v, text: str, what: str) -> None:
    """Exit 2 for a tool point (``v[:3]``, m; a rotation vector may follow) farther than
    :data:`_TOOL_REACH_M` from the flange."""
    import numpy as np

    distance = float(np.linalg.norm(v[:3]))
    if distance > _TOOL_REACH_M:
        raise fail(f"{what} {text!r}: {distance:g} m from the flange; check the unit (e.g. 0,0,109mm)")


ProgramOption = Annotated[
    Path,
    typer.Argument(
        metavar="PROGRAM", help="robot program: .script, .src (+ .dat), .mod, .csv", show_default=False
    ),
]
ToolOption = Annotated[
    str | None,
    typer.Option(
        "--tool",
        metavar='"x,y,z,rx,ry,rz"',
        help='the program\'s tool on the flange with units, e.g. "0,0,109mm,0,0,90deg" (rotation vector)',
    ),
]
BaseOption = Annotated[
    str | None,
    typer.Option(
        "--base",
        metavar='"x,y,z,rx,ry,rz"',
        help='the targets\' frame in the robot base with units, e.g. "500,0,0mm,0,0,90deg"',
    ),
]
ProbeOption = Annotated[
    str | None,
    typer.Option(
        "--probe",
        metavar='"x,y,z[,rx,ry,rz]"',
        help='the measured tool (probe) as built, e.g. "0,0,109mm" (default: the one the calibration '
        "identified; a different one is refused)",
    ),
]
NominalOption = Annotated[
    str | None,
    typer.Option("--nominal", metavar="ROBOT", help="the controller's model: catalog name or .yaml"),
]
LengthUnitOption = Annotated[
    LengthUnit, typer.Option("--length-unit", metavar="m|mm|um", help="CSV programs: m | mm | um")
]
AngleUnitOption = Annotated[
    AngleUnit, typer.Option("--angle-unit", metavar="rad|deg", help="CSV programs: rad | deg")
]
StrictOption = Annotated[
    bool, typer.Option("--strict", help="exit 1 on any warning too (statements untouched, other frames)")
]
ConfigDatOption = Annotated[
    Path | None,
    typer.Option(
        "--config-dat",
        metavar="FILE",
        help="KRL: $config.dat of TOOL_DATA/BASE_DATA (default: next to it)",
    ),
]


def filter_command(
    calibration: Annotated[Path, CALIBRATION],
    program: ProgramOption,
    out: Annotated[Path, out_option("the filtered program (KRL: and its .dat)")],
    tool: ToolOption = None,
    base: BaseOption = None,
    probe: ProbeOption = None,
    nominal: NominalOption = None,
    length_unit: LengthUnitOption = "m",
    angle_unit: AngleUnitOption = "rad",
    strict: StrictOption = False,
    force: Force = False,
    config_dat: ConfigDatOption = None,
    partial: PartialOption = False,
) -> None:
    """Correct every target of a robot program through a calibration; everything else stays byte-identical.

    Each target is corrected, damped near a singularity or refused (left as written, exit 1 unless --partial).

    The same bound as compensate: a joint moves at most 1.5 |e| / sigma_min, 0.05 to 5 deg.

    The per-target table is printed and written beside the output (OUT.table.csv)."""
    from robocal.compensate.result import table_path

    refuse_overwrite(out, force, "program")
    refuse_overwrite(table_path(out), force, "per-target table")

    from robocal.cli.compensate import load
    from robocal.compensate.programs.filter_file import filter_program_file, language_of
    from robocal.compensate.programs.syntax import ProgramError

    try:
        language = language_of(program)
    except ProgramError as err:
        raise fail(str(err)) from None
    if language_of(out) != language and not (language == "krl" and out.suffix.lower() == ".src"):
        raise fail(f"-o {out}: write a {language} program with the suffix of {program.name}")
    calibrated = load(calibration)
    nominal_model = None if nominal is None else resolve_model(nominal)
    if nominal is None and _constraint_calibration(calibration) is not None:
        from robocal.cli.report_constraints import constraint_nominal

        nominal_model = constraint_nominal(calibration, required=True)  # the program's robot
    from robocal.identify.measured_tool import probe_for

    try:  # the calibration's measured tool unless --probe says otherwise; a disagreeing one refused
        probe_value = probe_for(calibrated, _probe_option(probe), "--probe")
    except ValueError as err:
        raise fail(str(err)) from None
    try:
        result = filter_program_file(
            program,
            calibrated,
            out,
            nominal=nominal_model,
            tool=_frame_option(tool, "--tool"),
            base=_frame_option(base, "--base"),
            probe=probe_value,
            length_unit=length_unit,
            angle_unit=angle_unit,
            config_dat=config_dat,
            require_probe=True,
            overwrite=force,
        )
    except ProgramError as err:
        raise fail(str(err)) from None
    except ValueError as err:
        raise fail(f"{program}: {err}") from None
    _print_filtered(result, program, out, language, tool is None and config_dat is None)
    from robocal.cli.compensate import finish_filtered

    finish_filtered(result, out, partial, strict)


def _print_filtered(result, program: Path, out: Path, language: str, no_frames_given: bool) -> None:
    """What ``filter`` corrected, wrote and left untouched."""
    import numpy as np

    n = len(result.targets)
    ok = np.isfinite(result.error_after_mm) & result.reachable
    left = ~result.changed & ~(result.reachable & result.branch_kept)
    console.print(
        f"{program.name}: {n} targets ({language}), {int(result.changed.sum())} corrected, "
        f"{n - int(result.changed.sum()) - int(left.sum())} already within the written resolution, "
        f"{int(left.sum())} left as written (see the warnings); "
        f"{len(result.unsupported)} statements untouched (listed); "
        + (
            f"predicted error {np.nanmax(result.error_before_mm[ok]):.3f} mm (max) before; "
            f"corrected onto the calibrated model within {np.nanmax(result.error_after_mm[ok]):.1e} mm, "
            "so expect the calibration's accuracy (robocal validate)"
            if ok.any() and np.isfinite(result.error_before_mm[ok]).any()
            else "no predicted errors"
        ),
        highlight=False,
    )
    written = [out] + ([out.with_suffix(".dat")] if len(result.texts) > 1 else [])
    console.print(f"wrote {', '.join(map(str, written))}", highlight=False)
    if language == "krl" and no_frames_given and not (program.parent / "$config.dat").is_file():
        err_console.print(
            "[yellow]note:[/] no $config.dat next to the program: TOOL_DATA/BASE_DATA are not read and the "
            "targets are taken as flange poses in the robot base; give --config-dat or --tool/--base",
            highlight=False,
            markup=True,
        )
    for u in result.unsupported:
        err_console.print(
            f"[yellow]untouched:[/] {safe(u.file)}: line {u.line}: {safe(u.text)} ({safe(u.reason)})",
            highlight=False,
            markup=True,
        )
    for p in result.problems:
        warn(p)


def register(app: typer.Typer) -> None:
    """Add ``export`` and ``filter`` to the ``robocal`` app."""
    app.add_typer(export_app, name="export")
    app.command("filter")(filter_command)
