"""``robocal model build | show | check``: the builder, the 3D view and the singularity check."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer
from rich.table import Table
from rich.text import Text

from robocal.cli.options import CONTEXT, Force, Robot, measure_option, out_option, resolve_model
from robocal.console import console, fail, input_problem, refuse_overwrite, safe, warn

if TYPE_CHECKING:
    from robocal.model.chain import Model
    from robocal.model.geometry import Measure

__all__ = ["register"]

#: ``--measure``'s choices, typed
_MEASURES: dict[str, Measure] = {"position": "position", "pose": "pose"}


def _measure(value: str) -> Measure:
    """``--measure`` checked: ``position`` or ``pose``."""
    if value not in _MEASURES:
        raise fail(f"--measure must be 'position' or 'pose', got {value!r}")
    return _MEASURES[value]


def _is_ur_kinematics(path: Path) -> bool:
    """Whether a YAML file is a UR kinematics file (a top-level ``kinematics:`` mapping)."""
    from robocal.model.yaml_files import ModelFileError, read_yaml

    try:  # read_yaml: the size and entry limits are checked before the file is parsed
        data = read_yaml(path, "model")
    except (OSError, ModelFileError):  # too large, not YAML ...: said when it is read as geometry
        return False
    return isinstance(data, dict) and isinstance(data.get("kinematics"), dict)


model_app = typer.Typer(
    help="Build, view and check calibration models.", no_args_is_help=True, context_settings=CONTEXT
)


GeometryOption = Annotated[
    Path,
    typer.Argument(
        metavar="GEOMETRY",
        help="joint-geometry YAML file, URDF file, or a model (catalog name or model YAML file) whose "
        "joint geometry is read from its chain (rc.calibration_model)",
    ),
]
MeasureOption = Annotated[
    str | None, measure_option("the measured quantities (default: the file's, else pose)")
]
TipOption = Annotated[
    str | None,
    typer.Option(
        "--tip",
        metavar="LINK",
        help="URDF: link to end the chain at (a joint's name stands for its child link); only the chain "
        "from the root to it is read (off it: grippers, <mimic> joints, sensor frames are ignored). "
        "Default: the deepest link of the single longest chain; refused, naming the chain ends, when "
        "the robot branches (two gripper fingers, camera frames)",
    ),
]


@model_app.command("build")
def build_command(
    geometry: GeometryOption,
    out: Annotated[Path, out_option("model file to write (YAML)")],
    measure: MeasureOption = None,
    tip: TipOption = None,
    force: Force = False,
) -> None:
    """Build a complete, minimal, singularity-free model from joint geometry (Motta 2005, seed 000)."""
    refuse_overwrite(out, force, "model file")
    from robocal.model.builder import load_geometry
    from robocal.model.files import save_model
    from robocal.model.geometry import GeometryError
    from robocal.model.urdf.read import URDFError, build_from_urdf

    chosen = None if measure is None else _measure(measure)  # None: the geometry file's
    from robocal.model.catalog import is_geometry_file, robots

    catalog = not geometry.is_file() and str(geometry).lower() in robots()
    if not geometry.is_file() and not catalog:
        problem = input_problem(geometry, "geometry, URDF or model file") or f"{geometry} cannot be read"
        if problem.endswith("does not exist"):
            problem += " (nor is it a catalog robot: robocal robots)"
        raise fail(problem)
    try:
        if geometry.suffix.lower() == ".urdf":
            result = build_from_urdf(geometry, chosen or "pose", tip)
        elif not catalog and _is_ur_kinematics(geometry):  # a UR factory calibration (kinematics YAML)
            from robocal.model.ur_kinematics import URKinematicsError, build_from_ur_kinematics

            try:
                result = build_from_ur_kinematics(geometry, measure=chosen or "pose")
            except URKinematicsError as err:
                raise fail(str(err)) from None
        elif catalog or not is_geometry_file(geometry):  # a chain: build from its joint geometry
            from robocal.model.complete import build_complete

            chain = resolve_model(str(geometry))
            origin = f"the catalog model {chain.name!r}" if catalog else None
            result = build_complete(chain, chosen or "pose", origin)
        else:
            result = load_geometry(geometry).build(chosen)
    except (GeometryError, URDFError, ValueError) as err:
        raise fail(str(err)) from None
    model = result.model
    table = Table(title=f"{model.name}: links", title_justify="left")
    for col in ("link", "parameterisation", "parameters (identified in bold)"):
        table.add_column(col)
    free = set(model.free_names)
    for info in result.links:
        params = Text.from_markup(
            " ".join(f"[bold]{safe(p)}[/]" if p in free else f"[dim]{safe(p)}[/]" for p in info.parameters)
        )
        table.add_row(str(info.index), info.label, params)
    console.print(table)
    R = model.joint_types.count("revolute")
    P = model.dof - R
    console.print(
        f"{result.measure} measurement: {len(model.free_names)} identified parameters "
        f"(4R + 2P + {6 if result.measure == 'pose' else 3} = {result.expected_free} for R={R}, P={P}); "
        f"Jacobian rank {result.rank}",
        highlight=False,
    )
    for warning in result.warnings:
        warn(warning)
    if geometry.suffix.lower() == ".urdf":
        console.print(_masses_line(geometry, model, tip), highlight=False)
    save_model(model, out)
    console.print(f"wrote {out}", highlight=False)


def _masses_line(urdf: Path, model: Model, tip: str | None) -> str:
    """One line: how many link masses the model carries from the URDF's ``<inertial>``."""
    from robocal.model.urdf.read import urdf_link_masses

    masses = urdf_link_masses(urdf, model, tip)
    if not masses.bodies:
        return (
            "link masses: none read (no <inertial> with a mass on the moving links): joint compliance "
            "(--effects compliance) needs a model file with bodies"
        )
    parts = [f"link masses: {len(masses.bodies)} read from the URDF's <inertial> ({masses.mass_kg:.4g} kg)"]
    if masses.off_chain:
        parts.append(f"{len(masses.off_chain)} behind joints off the chain taken at their zero")
    if masses.on_base:
        parts.append(f"on the base, no joint load: {', '.join(safe(n) for n in masses.on_base)}")
    return "; ".join(parts)


@model_app.command("show")
def show_command(
    robot: Robot,
    out: Annotated[Path, out_option("HTML file to write")],
    force: Force = False,
) -> None:
    """Write a self-contained interactive 3D view of a model with its parameter table."""
    refuse_overwrite(out, force, "view")
    from robocal.model.view import write_model_view

    model = resolve_model(robot)
    write_model_view(model, out)
    console.print(f"wrote {out}", highlight=False)


@model_app.command("check")
def check_command(
    robot: Robot,
    measure: Annotated[str, measure_option("the measured quantities")] = "pose",
) -> None:
    """Check a model for parameterisation singularities and discontinuities (exit 1 if any)."""
    from robocal.model.singularity import check_model

    chosen = _measure(measure)
    model = resolve_model(robot)
    result = check_model(model, chosen)
    table = Table(title=f"{model.name}: link parameterisations", title_justify="left")
    for col in ("link", "parameters", "places", "rank", "verdict"):
        table.add_column(col)
    colours = {"ok": "green", "near-singular": "yellow", "singular": "red"}
    for link in result.links:
        verdict = Text(link.verdict, colours[link.verdict])
        table.add_row(
            str(link.index), " ".join(link.parameters), link.target, f"{link.rank}/{link.needed}", verdict
        )
    console.print(table)
    cont = Table(title="continuity (axis tilted by 1e-6 rad)", title_justify="left")
    for col in ("joint", "max parameter change / tilt", "unrepresentable part", "verdict"):
        cont.add_column(col)
    for c in result.continuity:
        verdict = Text("continuous", "green") if c.continuous else Text("jumps / cannot follow", "red")
        cont.add_row(c.joint, f"{c.parameter_change:.3g}", f"{c.residual:.2e}", verdict)
    console.print(cont)
    full = result.identification_rank == result.identification_columns
    console.print(
        f"identification Jacobian ({measure}): rank {result.identification_rank} of "
        f"{result.identification_columns} free parameters, condition number {result.condition_number:.3g}"
        + ("" if full else " [red](rank deficient)[/]"),
        highlight=False,
        markup=True,
    )
    if result.ok:
        console.print("[bold green]verdict: complete, minimal and continuous[/]", markup=True)
    else:
        console.print("[bold red]verdict: singular or discontinuous parameterisation[/]", markup=True)
        for link in result.links:
            if link.verdict != "ok":
                console.print(f"  link {link.index}: {link.explanation}", highlight=False)
        raise typer.Exit(code=1)


def register(app: typer.Typer) -> None:
    """Add the ``model`` command group to the ``robocal`` app."""
    app.add_typer(model_app, name="model")
