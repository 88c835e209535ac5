"""``robocal export``: the calibrated robot in the formats the robot's software reads.

    robocal export urdf DIR [--urdf ORIGINAL.urdf] [--tip LINK] [--device-link NAME]
                            [--tool-link NAME] -o OUT.urdf
    robocal export ur-kinematics DIR [--base-rz-pi] -o calibration.yaml

``DIR`` is a calibration directory (``model.yaml`` + ``result.json``) or a model file.
``export urdf`` rewrites the joint origins of ``--urdf`` (the URDF the model was built
from) and keeps everything else; without ``--urdf`` it writes a kinematic URDF of its
own.  What the file cannot carry (joint effects, a learned residual) is printed with its
size and stated in an XML comment.  ``export ur-kinematics`` writes the UR ROS
description's ``default_kinematics.yaml`` format.  Exit status 2 on bad input (nothing
written).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Annotated

import typer

from robocal.console import console, err_console, fail, refuse_overwrite

__all__ = ["register"]

export_app = typer.Typer(help="Export a calibration: calibrated URDF, UR kinematics.", no_args_is_help=True)


@export_app.command("urdf")
def urdf_command(
    source: Annotated[Path, typer.Argument(help="calibration directory (result.json) or model .yaml")],
    out: Annotated[Path, typer.Option("-o", "--out", help="the URDF to write")],
    urdf: Annotated[
        Path | None, typer.Option("--urdf", help="the URDF the model was built from (kept but for origins)")
    ] = None,
    tip: Annotated[
        str | None, typer.Option("--tip", help="link at the model's flange (default: last)")
    ] = None,
    device_link: Annotated[
        str | None, typer.Option("--device-link", help="add the device frame as a new root link of this name")
    ] = None,
    tool_link: Annotated[
        str | None, typer.Option("--tool-link", help="add the measured tool as a link of this name")
    ] = None,
    force: Annotated[bool, typer.Option("--force", help="overwrite an existing output")] = False,
) -> None:
    """A URDF whose forward kinematics are the calibrated model's (joint offsets folded into origins)."""
    refuse_overwrite(out, force, "URDF")
    from robocal.compensate.cli import _load
    from robocal.compensate.export import export_urdf
    from robocal.identify.calibrate import CalibrationResult
    from robocal.model.files import atomic_write_text
    from robocal.model.urdf import URDFError

    calibrated = _load(source)
    if device_link is not None and not isinstance(calibrated, CalibrationResult):
        raise fail(f"--device-link needs a calibration directory (its device frame); {source} is a model")
    try:
        ex, missing = export_urdf(calibrated, urdf, tip=tip, device_link=device_link, tool_link=tool_link)
    except FileNotFoundError as err:
        raise fail(str(err)) from None
    except (URDFError, ValueError) as err:
        raise fail(str(err)) from None
    atomic_write_text(out, ex.text)
    what = f"{urdf.name} with {len(ex.changed)} joint origins calibrated" if urdf else "a kinematic URDF"
    console.print(f"wrote {out}: {what}; root {ex.root}, flange {ex.tip}", highlight=False)
    if ex.tool_link:
        console.print(f"measured tool: link {ex.tool_link}", highlight=False)
    for m in missing:
        err_console.print(f"[yellow]note:[/] {m.note}", highlight=False)


@export_app.command("ur-kinematics")
def ur_kinematics_command(
    source: Annotated[Path, typer.Argument(help="calibration directory (result.json) or model .yaml")],
    out: Annotated[Path, typer.Option("-o", "--out", help="the YAML to write")],
    base_rz_pi: Annotated[
        bool,
        typer.Option(
            "--base-rz-pi", help="the model's base is a ROS base_link (the UR base turned by 180 deg about z)"
        ),
    ] = False,
    force: Annotated[bool, typer.Option("--force", help="overwrite an existing output")] = False,
) -> None:
    """The calibrated kinematics as a UR description default_kinematics.yaml."""
    refuse_overwrite(out, force, "kinematics file")
    from robocal import spatial
    from robocal.compensate.cli import _load
    from robocal.compensate.export import export_ur_kinematics, left_out

    calibrated = _load(source)
    base = spatial.homogeneous(spatial.rotz(math.pi)) if base_rz_pi else None
    try:
        kin = export_ur_kinematics(calibrated, None, T_base_urbase=base)
    except ValueError as err:
        raise fail(f"{source}: {err}") from None
    from robocal.model.files import atomic_write_text

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
        )
    for m in left_out(calibrated):
        err_console.print(f"[yellow]note:[/] {m.note}", highlight=False)


def register(app: typer.Typer) -> None:
    """Add ``export`` to the ``robocal`` app."""
    app.add_typer(export_app, name="export")
