"""Command-line commands of the measurement step (registered on the ``robocal`` app).

Commands:
    robocal data check FILE [ROBOT] [--length-unit mm] [--angle-unit deg] [--sep ";"]
                       [--decimal ","] [--columns "q1=shoulder_pan_joint,..."]
                       [--orientation euler:XYZ:deg] [--limits error|warn|ignore]
        every problem of a measurement file (exit code 1 if any error), or a summary
    robocal data sockets PLACEMENT/ -o sockets.csv [--deg]
        ball-in-socket recordings (hole_0.csv, hole_1.csv ...) as a constraint CSV
    robocal simulate ROBOT --poses POSES.csv --device laser-tracker --noise 0.02mm --seed 1
                     -o meas.csv
        simulated measurements of a robot with drawn errors, and their truth beside them
    robocal simulate ROBOT --log -o LOG.csv [--seed 1] [--noise 0.005mm]
        a simulated ISO 9283 measurement log and its truth (robocal.evaluate.iso9283.sim)
"""

from __future__ import annotations

import math
import re
import warnings
from collections import defaultdict
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import numpy as np
import typer
from rich.table import Table
from rich.text import Text

from robocal import spatial
from robocal.choices import Distribution
from robocal.cli.constraints import TILT_MOUNT_HELP
from robocal.cli.options import (
    CONTEXT,
    AngleUnit,
    Columns,
    Decimal,
    Force,
    Incomplete,
    LengthUnit,
    Limits,
    Orientation,
    Robot,
    Sep,
    as_cli_text,
    length_vector,
    out_option,
    resolve_model,
)
from robocal.cli.sockets import data_sockets
from robocal.console import console, err_console, fail, refuse_overwrite, safe
from robocal.measure.devices import DEVICES, make_device

if TYPE_CHECKING:  # the readers and the simulator are imported by the commands that use them
    from robocal.measure.measurements import Measurements, Problem

__all__ = ["register"]

#: simulate: tolerances of the drawn true robot may be at most 0.1 m and 10 degrees (a real
#: robot's errors are below a few mm and tenths of a degree)
MAX_LENGTH_TOL = 0.1
MAX_ANGLE_TOL = math.radians(10.0)

data_app = typer.Typer(
    help="Measurement files: check them before a calibration.", no_args_is_help=True, context_settings=CONTEXT
)


def _model(name: str | None):
    return None if name is None else resolve_model(name)


# ------------------------------------------------------------------ data check
def _rows_text(rows: list[int | None], limit: int = 6) -> str:
    rows = [r for r in rows if r is not None]
    if not rows:
        return "-"
    shown = ", ".join(str(r) for r in rows[:limit])
    return shown + (f" … ({len(rows)} rows)" if len(rows) > limit else "")


def _problem_table(problems: list[Problem], title: str) -> Table:
    from robocal.measure.measurements import PROBLEM_CODES

    groups: dict[tuple, list[Problem]] = defaultdict(list)
    for p in problems:
        groups[(p.severity, p.code, p.column)].append(p)
    table = Table(title=title, title_justify="left", show_lines=True)
    for col in ("severity", "problem", "column", "rows", "first message"):
        table.add_column(col, overflow="fold")
    order = sorted(groups, key=lambda k: (k[0] != "error", min(p.row or 0 for p in groups[k])))
    for key in order:
        items = groups[key]
        severity, code, column = key
        style = "bold red" if severity == "error" else "yellow"
        table.add_row(
            Text(severity, style),
            Text.from_markup(f"{safe(code)}\n[dim]{safe(PROBLEM_CODES.get(code, ''))}[/]"),
            column or "-",
            _rows_text([p.row for p in items]),
            as_cli_text(items[0].message),
        )
    return table


def _summary(data: Measurements, path: Path, model, length_unit: str, angle_unit: str) -> list[str]:
    """Print the column table of a clean file; return the facts to print under it."""
    table = Table(title=f"{path}: {data.n} rows, clean", title_justify="left")
    for heading in ("column", "meaning", "min", "max", "unit"):
        table.add_column(heading, justify="right" if heading in ("min", "max") else "left")
    types = model.joint_types if model is not None else ("revolute",) * data.dof
    names = model.joint_names if model is not None else data.joint_names
    for j in range(data.dof):
        scale, unit = (math.pi / 180, "deg") if types[j] == "revolute" else (1e-3, "mm")
        col = data.q[:, j] / scale
        table.add_row(data.joint_names[j], f"joint {names[j]}", f"{col.min():.3f}", f"{col.max():.3f}", unit)
    if data.position is not None:
        for k, axis in enumerate("xyz"):
            col = data.position[:, k] * 1000
            table.add_row(axis, "position (device frame)", f"{col.min():.3f}", f"{col.max():.3f}", "mm")
    if data.sigma is not None:
        s = data.sigma * 1000
        table.add_row("sx sy sz", "standard deviation", f"{s.min():.4f}", f"{s.max():.4f}", "mm")
    if data.temperature is not None:
        t = data.temperature
        table.add_row("temperature", "", f"{t.min():.2f}", f"{t.max():.2f}", "°C")
    console.print(table)
    facts = [
        f"read as: lengths in {length_unit}, angles in {angle_unit} (shown in mm and deg)",
        f"observes: {data.observes}",
    ]
    if data.orientation is not None:
        facts.append(f"orientation: {data.metadata.get('read_orientation', '?')}")
    if data.split is not None:
        n_train = int(np.sum(data.split == "train"))
        facts.append(f"split: {n_train} train, {data.n - n_train} test")
    if model is not None:
        facts.append(f"robot: {model.name} ({model.dof} joints), all joint values within its limits")
    if "unused_columns" in data.metadata:
        facts.append(f"not used: {data.metadata['unused_columns']} (map columns with --columns)")
    if "rows_left_out" in data.metadata:
        facts.append(f"left out: {data.metadata['rows_left_out']} incomplete row(s) (--incomplete drop)")
    return facts


@data_app.command("check")
def data_check(
    file: Annotated[Path, typer.Argument(metavar="FILE", help="measurement or poses CSV file")],
    robot: Annotated[
        str | None,
        typer.Argument(
            metavar="ROBOT",
            help="catalog name (robocal robots) or model file (.yaml): checks joint count, types, limits",
            show_default=False,
        ),
    ] = None,
    length_unit: LengthUnit = "m",
    angle_unit: AngleUnit = "rad",
    sep: Sep = None,
    decimal: Decimal = ".",
    columns: Columns = None,
    orientation: Orientation = "auto",
    limits: Limits = "error",
    incomplete: Incomplete = "error",
) -> None:
    """List every problem of a measurement file, or summarise it if it is clean."""
    from robocal.measure.dataset.options import ReaderOptions
    from robocal.measure.dataset.read import check_measurements, read_measurements

    model = _model(robot)
    options = ReaderOptions(length_unit=length_unit, angle_unit=angle_unit, sep=sep, decimal=decimal,
                            columns=columns, orientation=orientation, limits=limits,
                            incomplete=incomplete)  # fmt: skip
    try:
        problems = check_measurements(file, model, options=options)
    except (ValueError, KeyError) as err:
        raise fail(as_cli_text(str(err.args[0] if isinstance(err, KeyError) else err))) from None
    errors = [p for p in problems if p.severity == "error"]
    warns = [p for p in problems if p.severity == "warning"]
    if problems:
        console.print(_problem_table(problems, f"{file}: {len(errors)} error(s), {len(warns)} warning(s)"))
    if errors:
        console.print(
            f"[bold red]{len(errors)} error(s)[/]: the file cannot be used as read; first: "
            f"{safe(as_cli_text(str(errors[0])))}",
            highlight=False,
            markup=True,
            soft_wrap=True,
        )
        raise typer.Exit(code=1)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        data = read_measurements(file, model=model, options=options)
    for fact in _summary(data, file, model, length_unit, angle_unit):
        console.print(fact, highlight=False)


@data_app.command("tilt")
def data_tilt(
    file: Annotated[Path, typer.Argument(metavar="READINGS", help="inclinometer readings CSV")],
    robot: Annotated[str, typer.Argument(metavar="ROBOT", help="catalog name or model file (.yaml)")],
    exact_geometry: Annotated[
        bool, typer.Option("--exact-geometry", help="take the geometry as exact: fit no angle of it")
    ] = False,
    json_out: Annotated[Path | None, typer.Option("--json", metavar="FILE", help="estimates (SI)")] = None,
    force: Force = False,
) -> None:
    """Identify clearance, backlash and stiffness from inclinometer readings (docs/inclinometer.md)."""
    from robocal.cli.inclinometer import identify_tilt_file

    identify_tilt_file(file, robot, exact_geometry, json_out, force)


data_app.command("sockets")(data_sockets)  # ball-in-socket recordings -> a constraint CSV


# -------------------------------------------------------------------- simulate
NOISE_HELP = (
    "the device's main noise, 1σ with a unit, e.g. 0.02mm: laser-tracker per axis (no distance term), "
    "optical-cmm per marker coordinate, camera across the line of sight (3x along it), plate touching "
    "error, pen in the paper plane (1/10 of it out of the plane); default: the device's own"
)


PosesOption = Annotated[
    Path | None, typer.Option("--poses", metavar="FILE", help="poses CSV: joint columns q1..qN (rad, m)")
]
OutOption = Annotated[Path | None, out_option("measurements CSV to write (with --log: the ISO 9283 log)")]
DeviceOption = Annotated[
    str, typer.Option("--device", metavar="DEVICE", help=f"one of: {', '.join(DEVICES)}, inclinometer")
]
SeedOption = Annotated[
    int | None, typer.Option("--seed", min=0, metavar="N", help="seed of the drawn errors and the noise")
]
LengthTolOption = Annotated[
    str, typer.Option("--length-tol", metavar="LENGTH", help="tolerance of length parameters, e.g. 0.5mm")
]
AngleTolOption = Annotated[
    str, typer.Option("--angle-tol", metavar="ANGLE", help="tolerance of angle parameters, e.g. 0.05deg")
]
TolOption = Annotated[
    list[str] | None,
    typer.Option("--tol", metavar="NAME=VALUE", help="per-parameter tolerance, e.g. theta2=0.2deg"),
]
DistributionOption = Annotated[
    Distribution,
    typer.Option("--distribution", metavar="uniform|normal", help="uniform in ±tol, or normal (σ = tol)"),
]
DevicePoseOption = Annotated[
    str | None,
    typer.Option(
        "--device-pose",
        metavar='"x,y,z,roll,pitch,yaw"',
        help='device pose in the robot base with units, e.g. "2000,0,500mm,0,0,180deg" (Rz Ry Rx)',
    ),
]
ToolOffsetOption = Annotated[
    str | None,
    typer.Option(
        "--tool-offset", metavar='"x,y,z"', help='observed point in the tool frame, e.g. "0,0,109mm"'
    ),
]
TrainOption = Annotated[
    float | None,
    typer.Option("--train", metavar="FRACTION", help="fraction of rows labelled train (the rest test)"),
]
LogOption = Annotated[
    bool, typer.Option("--log", help="instead: write a simulated ISO 9283 log (docs/iso9283.md) to -o")
]
KindOption = Annotated[
    str | None,
    typer.Option(
        "--kind",
        metavar="point|plane|distance|tilt",
        help="instead: constraint measurements (no tracker: ball in socket, plane touches, ball-bar "
        "pairs, inclinometer readings) at N configurations of the true robot, to -o; the truth beside them",
    ),
]
CountOption = Annotated[
    int, typer.Option("--count", min=1, metavar="K", help="--kind: fixed points or planes")
]
PoseCountOption = Annotated[int, typer.Option("--n", min=4, metavar="N", help="--kind: configurations")]
LengthOption = Annotated[
    str, typer.Option("--length", metavar="LENGTH", help="--kind distance: the pairs' length")
]
PLACEMENTS_HELP = "--kind: K placements of the scene, one true robot (OUT, OUT.placement2.csv ...: held-out)"
PlacementsOption = Annotated[
    int, typer.Option("--placements", min=1, max=20, metavar="K", help=PLACEMENTS_HELP)
]
ALSO_TRACKER_HELP = "--kind: also N tracker rows of the same true robot in OUT.tracker.csv (truth shared)"
AlsoTrackerOption = Annotated[int, typer.Option("--also-tracker", min=0, metavar="N", help=ALSO_TRACKER_HELP)]
TiltMountOption = Annotated[str, typer.Option("--mount", metavar="joint|level", help=TILT_MOUNT_HELP)]


def simulate_command(
    robot: Robot,
    poses: PosesOption = None,
    out: OutOption = None,
    device: DeviceOption = "laser-tracker",
    noise: Annotated[str | None, typer.Option("--noise", metavar="LENGTH", help=NOISE_HELP)] = None,
    seed: SeedOption = None,
    length_tol: LengthTolOption = "0.5mm",
    angle_tol: AngleTolOption = "0.05deg",
    tol: TolOption = None,
    distribution: DistributionOption = "uniform",
    device_pose: DevicePoseOption = None,
    tool_offset: ToolOffsetOption = None,
    train: TrainOption = None,
    force: Force = False,
    log: LogOption = False,
    kind: KindOption = None,
    n: PoseCountOption = 60,
    count: CountOption = 2,
    length: LengthOption = "300mm",
    placements: PlacementsOption = 1,
    also_tracker: AlsoTrackerOption = 0,
    mount: TiltMountOption = "joint",
) -> None:
    """Simulate measurements of ROBOT with randomly drawn errors; write the truth beside them."""
    if kind is not None:  # fixed points, planes, distances (robocal.cli.constraints)
        options = (n, count, length, noise, seed, length_tol, angle_tol, placements, also_tracker, mount)
        return _simulate_constraints(robot, kind, poses, out, force, options)
    if log:
        if poses is not None or out is None:
            raise fail("--log writes an ISO 9283 log of its own test poses to -o FILE: drop --poses")
        from robocal.cli.iso9283 import simulate_log_command

        return simulate_log_command(robot, out, seed, noise, force)
    if poses is None or out is None:
        raise fail("give --poses POSES.csv and -o OUT.csv (or --log -o LOG.csv for an ISO 9283 log)")
    from robocal.measure.measurements import MeasurementFileError

    refuse_overwrite(out, force, "measurement file")
    model = _model(robot)
    if device == "inclinometer":  # tilt readings of the links, not tool positions
        drawn = (tol, length_tol, angle_tol, distribution)
        return _simulate_inclinometer(model, poses, out, noise, seed, drawn)
    if device not in DEVICES:
        raise fail(f"--device: unknown device {device!r}; known: {', '.join(DEVICES)}")
    tolerances = _tolerances(tol or [])
    try:
        dev = _device(device, noise, device_pose, tool_offset)
        true, length, angle = _true_model(model, tolerances, length_tol, angle_tol, distribution, seed)
        vr, data = _simulate(model, true, dev, poses, seed, train)
        info = {
            "command": "robocal simulate",
            "poses": str(poses),
            "length_tol": length,
            "angle_tol": angle,
            "tolerances": {k: str(v) for k, v in tolerances.items()},
            "distribution": distribution,
            "model_seed": "none" if seed is None else f"[{seed}, 1]",
        }
        from robocal.measure.simulate import save_simulation

        data_path, truth = save_simulation(vr, data, out, seed, **info)
    except MeasurementFileError as err:
        raise fail(str(err)) from None
    except (ValueError, KeyError) as err:
        raise fail(str(err.args[0] if isinstance(err, KeyError) else err)) from None
    dev_all = np.abs(np.array(list(_deviations(model, true))))
    rows = f"{data.n} rows, {dev.kind}: {', '.join(dev.columns)}"
    console.print(f"wrote {data_path} ({rows}) and the truth {truth}", highlight=False, soft_wrap=True)
    console.print(
        f"true robot: {len(dev_all)} parameters drawn ({distribution}, ±{length_tol}, ±{angle_tol}); "
        f"device noise {_noise_text(dev)}",
        highlight=False,
        soft_wrap=True,
    )


def _simulate_inclinometer(
    model, poses, out, noise, seed, drawn: tuple[list[str] | None, str, str, Distribution]
) -> None:
    """``simulate --device inclinometer``; ``drawn``: --tol, --length-tol, --angle-tol, --distribution."""
    from robocal.cli.inclinometer import simulate_inclinometer

    tol, length_tol, angle_tol, distribution = drawn
    draw = lambda: _true_model(model, _tolerances(tol or []), length_tol, angle_tol, distribution, seed)[0]  # noqa: E731
    simulate_inclinometer(model, draw, poses, out, noise, seed)


def _simulate_constraints(robot, kind: str, poses, out, force: bool, options: tuple) -> None:
    """``simulate --kind``: :func:`robocal.cli.constraints.simulate_constraint_command`."""
    from robocal.cli.constraints import simulate_constraint_command

    simulate_constraint_command(lambda: _model(robot), kind, poses, out, force, options)


def _tolerances(items: list[str]) -> dict[str, str]:
    """``--tol NAME=VALUE`` options as a dict."""
    tolerances = {}
    for item in items:
        if "=" not in item:
            raise fail(f"--tol {item!r}: expected NAME=VALUE, e.g. theta2=0.2deg")
        name, value = item.split("=", 1)
        tolerances[name.strip()] = value.strip()
    return tolerances


def _device(device: str, noise: str | None, device_pose: str | None, tool_offset: str | None):
    """The measuring device of ``--device`` with ``--noise``, ``--device-pose``, ``--tool-offset``."""
    from robocal.measure.measurements import MAX_SIGMA
    from robocal.measure.true_model import parse_quantity_option

    kwargs = {}
    if device_pose is not None:
        from robocal.units import parse_quantities

        v = np.array(parse_quantities(device_pose, ["length"] * 3 + ["angle"] * 3, "--device-pose"))
        T_base_device = spatial.homogeneous(spatial.euler_to_matrix(v[3:], "xyz"), v[:3])
        kwargs["T_device_base"] = spatial.inverse(T_base_device)
    if tool_offset is not None:
        kwargs["p_tool_target"] = length_vector(tool_offset, 3, "--tool-offset")
    dev = make_device(device, **kwargs)
    if noise is not None:
        sigma = parse_quantity_option(noise, "length", "--noise")
        if not 0 <= sigma <= MAX_SIGMA:
            raise ValueError(f"--noise {noise}: a standard deviation between 0 and {MAX_SIGMA * 1e3:g} mm")
        dev = dev.with_noise(sigma)
    return dev


def _true_model(
    model, tolerances: dict, length_tol: str, angle_tol: str, distribution: Distribution, seed: int | None
):
    """The drawn true robot, and the length and angle tolerances in m and rad."""
    from robocal.measure.true_model import draw_true_model, parse_quantity_option

    length = parse_quantity_option(length_tol, "length", "--length-tol")
    angle = parse_quantity_option(angle_tol, "angle", "--angle-tol")
    if not 0 <= length <= MAX_LENGTH_TOL:
        raise ValueError(f"--length-tol {length_tol}: between 0 and {MAX_LENGTH_TOL * 1e3:g} mm")
    if not 0 <= angle <= MAX_ANGLE_TOL:
        raise ValueError(f"--angle-tol {angle_tol}: between 0 and {math.degrees(MAX_ANGLE_TOL):g} deg")
    for name, value in tolerances.items():
        if not re.search(r"[A-Za-zµμ°]\s*$", value) and float(value or "nan") != 0.0:
            raise ValueError(f"--tol {name}={value}: give the unit, e.g. {name}={value}mm or {value}deg")
    model_rng = np.random.default_rng(None if seed is None else [seed, 1])
    true = draw_true_model(
        model,
        tolerances,
        length=length,
        angle=angle,
        distribution=distribution,
        seed=model_rng,
    )
    return true, length, angle


def _simulate(model, true, dev, poses: Path, seed: int | None, train: float | None):
    """The virtual robot and its simulated measurements at the poses of ``--poses``."""
    from robocal.measure.dataset.read import read_measurements
    from robocal.measure.simulate import VirtualRobot, simulate

    q = read_measurements(poses, model=model)
    if q.position is not None:
        err_console.print(
            f"[yellow]note:[/] {safe(poses)} has measured positions; only its joint values are used",
            highlight=False,
            markup=True,
        )
    vr = VirtualRobot(model, true, dev)
    with np.errstate(all="ignore"):
        data = simulate(vr, q, seed)
    arrays = [a for a in (data.position, data.orientation, data.sigma) if a is not None]
    if not all(np.all(np.isfinite(a)) for a in arrays):
        raise ValueError(
            "the simulated measurements are not finite: the --tol, --length-tol, --angle-tol or --noise "
            "values are too large for this robot; give those of a real robot, e.g. 0.5mm and 0.05deg"
        )
    if train is not None:
        if not 0 < train <= 1:
            raise ValueError(f"--train {train}: expected a fraction in (0, 1]")
        data = data.with_split(max(1, round(train * data.n)), seed)
    return vr, data


def _deviations(model, true):
    for a, b in zip(model.values, true.values, strict=True):
        if a != b:
            yield b - a


def _noise_text(dev) -> str:
    d = dev.to_dict()
    parts = [
        f"{k}={v * 1000:g} mm" if k != "sigma_per_m" else f"{k}={v * 1000:g} mm/m"
        for k, v in d.items()
        if k.startswith("sigma") and isinstance(v, float)
    ]
    return ", ".join(parts) or "-"


def register(app: typer.Typer) -> None:
    """Add ``data check``, ``data tilt``, ``data sockets`` and ``simulate`` to the ``robocal`` app."""
    app.add_typer(data_app, name="data")
    app.command("simulate")(simulate_command)
