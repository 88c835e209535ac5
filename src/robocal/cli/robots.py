"""``robocal robots`` (the catalog), ``robocal robots show ROBOT`` (one robot's parameters in mm
and degrees) and ``robocal fk ROBOT --q "q1,...,qn"`` (the tool pose at joint values)."""

from __future__ import annotations

import math
import warnings
from typing import TYPE_CHECKING, Annotated

import typer
from rich.table import Table

from robocal.cli.options import CONTEXT, Json, Robot, parse_vector, resolve_model
from robocal.console import console, safe, warn

if TYPE_CHECKING:
    import numpy as np

    from robocal.model.chain import Model

__all__ = ["register"]

robots_app = typer.Typer(help="The robot catalog.", invoke_without_command=True, context_settings=CONTEXT)


def _fmt(value: float, digits: int = 4) -> str:
    text = f"{value:.{digits}f}".rstrip("0").rstrip(".")
    return "0" if text in ("-0", "") else text


def _display(step_unit: str, value: float) -> str:
    return _fmt(math.degrees(value)) if step_unit == "rad" else _fmt(value * 1000.0)


@robots_app.callback()
def robots_list(ctx: typer.Context) -> None:
    """List the catalog robots (use `robocal robots show NAME` for one)."""
    if ctx.invoked_subcommand is not None:
        return
    from robocal.model.catalog import robot, robots

    table = Table(title="robocal catalog", title_justify="left")
    for col in ("name", "robot", "joints", "parameters", "mass data"):
        table.add_column(col)
    for name in robots():
        m = robot(name)
        types = "".join("R" if t == "revolute" else "P" for t in m.joint_types)
        table.add_row(name, m.title, f"{m.dof} ({types})", str(len(m.steps)), "yes" if m.bodies else "-")
    console.print(table)


@robots_app.command("show")
def robots_show(robot: Robot) -> None:
    """Parameter table of one robot in mm and degrees."""
    m = resolve_model(robot)
    console.print(f"[bold]{safe(m.name)}[/] — {safe(m.title)}", highlight=False, markup=True)
    if m.source:
        console.print(f"[dim]source: {safe(m.source)}[/]", highlight=False, markup=True)
    table = Table(show_lines=False)
    for col in ("#", "motion", "parameter", "value", "unit", "free", "joint", "limits"):
        table.add_column(col, justify="right" if col in ("#", "value") else "left")
    for i, s in enumerate(m.steps):
        unit = "deg" if s.is_rotation else "mm"
        joint, limits = "", ""
        if s.joint is not None:
            joint = f"{s.joint.name} ({s.joint_type})"
            if s.joint.limits is not None:
                limits = " .. ".join(_display(s.unit, v) for v in s.joint.limits)
        table.add_row(
            str(i),
            s.motion,
            s.name,
            _display(s.unit, s.value),
            unit,
            "yes" if s.free else "no",
            joint,
            limits,
        )
    console.print(table)
    if m.bodies:
        bodies = Table(title="mass properties", title_justify="left")
        for col in ("body", "frame", "mass kg", "com mm", "inertia kg·m² (xx yy zz xy xz yz)"):
            bodies.add_column(col)
        for b in m.bodies:
            inertia = " ".join(_fmt(v, 6) for v in b.inertia) if b.inertia else "-"
            com = " ".join(_fmt(v * 1000) for v in b.com)
            bodies.add_row(b.name, b.frame, _fmt(b.mass), com, inertia)
        console.print(bodies)


def _parse_q(text: str, m: Model, deg: bool) -> np.ndarray:
    import numpy as np

    q = parse_vector(text, m.dof, "--q", f"{m.dof} joint values of {m.name}: {', '.join(m.joint_names)}")
    if not deg:  # "0,-90,90,0,90,0" read as radians: refused (beyond the limits, within them in degrees)
        from robocal.cli.options import refuse_degrees_as_radians

        refuse_degrees_as_radians(q, m, "--q", text, "--deg")
    if deg:
        q = np.where(np.array(m.joint_types) == "revolute", np.radians(q), q / 1000.0)
    return q


def fk(
    robot: Robot,
    q: Annotated[
        str, typer.Option("--q", metavar='"q1,...,qn"', help='joint values, e.g. "0, -90, 90, 0, 90, 0"')
    ],
    deg: Annotated[bool, typer.Option("--deg", help="joint values in degrees (prismatic in mm)")] = False,
    as_json: Json = False,
) -> None:
    """Tool pose of a robot at the given joint values (rad and m unless --deg)."""
    from robocal import spatial
    from robocal.safe_output import strict_json

    m = resolve_model(robot)
    qv = _parse_q(q, m, deg)
    limits = m.joint_limits
    outside = [m.joint_names[j] for j in range(m.dof) if not limits[j, 0] <= qv[j] <= limits[j, 1]]
    T = m.fk(qv, compiled=False)  # one pose: numpy's 60 µs beat numba's import and cache load
    quat = spatial.matrix_to_quaternion(T[:3, :3])
    rpy = spatial.matrix_to_euler(T[:3, :3], "xyz")
    with warnings.catch_warnings():  # gimbal lock (e.g. a tool along the base z): angle 3 is 0
        warnings.simplefilter("ignore", UserWarning)
        zxz = spatial.matrix_to_euler(T[:3, :3], "ZXZ")
    if as_json:
        print(
            strict_json(
                {
                    "robot": m.name,
                    "q": qv.tolist(),
                    "T": T.tolist(),
                    "position_m": T[:3, 3].tolist(),
                    "quaternion_wxyz": quat.tolist(),
                    "rpy_xyz_rad": rpy.tolist(),
                    "zxz_rad": zxz.tolist(),
                    "outside_limits": outside,
                }
            )
        )
        return
    console.print(f"[bold]{safe(m.name)}[/] tool frame in the base frame", highlight=False, markup=True)
    table = Table(show_header=False)
    for _ in range(4):
        table.add_column(justify="right")
    for r in range(4):
        table.add_row(*[f"{T[r, c] * (1000 if c == 3 and r < 3 else 1):.6f}" for c in range(4)])
    console.print(table)
    p = T[:3, 3] * 1000
    console.print(f"position mm      x {p[0]:.4f}  y {p[1]:.4f}  z {p[2]:.4f}", highlight=False)
    console.print("quaternion wxyz  " + "  ".join(f"{v:.6f}" for v in quat), highlight=False)
    console.print(
        "roll-pitch-yaw   " + "  ".join(f"{math.degrees(v):.4f}" for v in rpy) + "  deg (Rz Ry Rx)",
        highlight=False,
    )
    console.print(
        "ZXZ Euler        " + "  ".join(f"{math.degrees(v):.4f}" for v in zxz) + "  deg",
        highlight=False,
    )
    if outside:
        warn(f"outside joint limits: {', '.join(outside)}")


def register(app: typer.Typer) -> None:
    app.command("fk")(fk)
    app.add_typer(robots_app, name="robots")
