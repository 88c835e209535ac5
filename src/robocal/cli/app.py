"""The ``robocal`` command (Typer + Rich).

Commands:
    robocal robots                    table of the catalog
    robocal robots show NAME          parameter table of one robot (mm, deg)
    robocal fk NAME --q "..." [--deg] tool pose at joint values
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer
from rich.table import Table

from robocal.cli_errors import RobocalGroup
from robocal.console import console, fail, input_problem, safe, warn

if TYPE_CHECKING:
    import numpy as np

    from robocal.model.chain import Model

# Start-up: this module and the command modules it registers import only typer and rich at
# the top; each command imports what it uses (tests/test_cli.py checks that `robocal --help`
# loads none of scipy.stats, Pinocchio, plotly, Dask, scikit-learn).

app = typer.Typer(
    help="robocal: calibration of serial robot arms.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
    cls=RobocalGroup,  # no traceback: an exception a command lets through becomes one line
)
robots_app = typer.Typer(help="The robot catalog.", invoke_without_command=True)
app.add_typer(robots_app, name="robots")


def resolve_model(name_or_path: str) -> Model:
    """A catalog robot by name, or a model file by path (``.yaml``/``.yml``)."""
    from robocal.model.catalog import robot
    from robocal.model.files import ModelFileError, load_model

    path = Path(name_or_path)
    if not name_or_path.strip():
        raise fail("no robot given: a catalog name (robocal robots) or a model file")
    try:
        if path.suffix in (".yaml", ".yml") or path.exists():
            problem = input_problem(path, "model file")
            if problem is not None:
                raise fail(f"model file {problem}" if problem.endswith("does not exist") else problem)
            if _is_geometry_file(path):
                raise fail(
                    f"{path} is a joint-geometry file: build a model from it first, "
                    f"e.g. robocal model build {path} -o model.yaml"
                )
            return load_model(path)
        return robot(name_or_path)
    except (KeyError, ModelFileError) as err:
        raise fail(str(err.args[0] if isinstance(err, KeyError) else err)) from None


def _is_geometry_file(path: Path) -> bool:
    """Whether a YAML file holds joint geometry for the builder (``joints:``) rather than a
    model (``steps:``)."""
    from robocal.model.files import ModelFileError, read_yaml

    try:  # read_yaml: the size and entry limits are checked before the file is parsed
        data = read_yaml(path, "model")
    except (OSError, ModelFileError):
        return False  # the model loader reports it
    return isinstance(data, dict) and "joints" in data and "steps" not in data


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
def robots_show(name: Annotated[str, typer.Argument(help="catalog name or model file")]) -> None:
    """Parameter table of one robot in mm and degrees."""
    m = resolve_model(name)
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

    try:
        values = [float(v) for v in text.replace(",", " ").split()]
    except ValueError:
        raise fail(f"--q {text!r}: joint values must be numbers separated by commas or spaces") from None
    if len(values) != m.dof:
        raise fail(
            f"--q has {len(values)} values but {m.name} has {m.dof} joints ({', '.join(m.joint_names)})"
        )
    q = np.array(values)
    if not np.all(np.isfinite(q)):
        raise fail(f"--q {text!r}: joint values must be finite numbers (no nan or inf)")
    if deg:
        q = np.where(np.array(m.joint_types) == "revolute", np.radians(q), q / 1000.0)
    return q


@app.command()
def fk(
    name: Annotated[str, typer.Argument(help="catalog name or model file")],
    q: Annotated[str, typer.Option("--q", help='joint values, e.g. "0, -90, 90, 0, 90, 0"')],
    deg: Annotated[bool, typer.Option("--deg", help="joint values in degrees (prismatic in mm)")] = False,
    as_json: Annotated[bool, typer.Option("--json", help="print JSON (m, rad) instead of a table")] = False,
) -> None:
    """Tool pose of a robot at the given joint values (rad and m unless --deg)."""
    from robocal import spatial
    from robocal.model.files import strict_json

    m = resolve_model(name)
    qv = _parse_q(q, m, deg)
    limits = m.joint_limits
    outside = [m.joint_names[j] for j in range(m.dof) if not limits[j, 0] <= qv[j] <= limits[j, 1]]
    T = m.fk(qv, compiled=False)  # one pose: numpy's 60 µs beat numba's import and cache load
    quat = spatial.matrix_to_quaternion(T[:3, :3])
    rpy = spatial.matrix_to_euler(T[:3, :3], "xyz")
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


# Command groups of the other calibration steps register themselves here, one line
# each: `from robocal.<package> import <module>; <module>.register(app)`.
# --- registered commands ---
from robocal.model import commands as _model_commands  # noqa: E402

_model_commands.register(app)
from robocal.measure import commands as _measure_commands  # noqa: E402

_measure_commands.register(app)
from robocal.measure import pose_commands as _pose_commands  # noqa: E402

_pose_commands.register(app)
from robocal.identify import commands as _identify_commands  # noqa: E402

_identify_commands.register(app)
from robocal.experiments import commands as _experiment_commands  # noqa: E402

_experiment_commands.register(app)
from robocal.compensate import cli as _compensate_commands  # noqa: E402

_compensate_commands.register(app)
from robocal.compensate import export_cli as _export_commands  # noqa: E402

_export_commands.register(app)
from robocal.evaluate import commands as _evaluate_commands  # noqa: E402

_evaluate_commands.register(app)
from robocal.evaluate import iso9283_commands as _iso9283_commands  # noqa: E402

_iso9283_commands.register(app)
from robocal import study_commands as _study_commands  # noqa: E402

_study_commands.register(app)
from robocal.apps.gui import commands as _gui_commands  # noqa: E402

_gui_commands.register(app)
# --- end of registered commands ---


def main() -> None:  # pragma: no cover - console entry point
    app()


if __name__ == "__main__":  # pragma: no cover
    main()
