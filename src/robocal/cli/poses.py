"""The ``robocal poses`` command: pose sets to measure, written as a poses CSV.

Commands:
    robocal poses ROBOT --method random|optimal|iso9283|diagonal --n N [--seed S]
                  [--index O1] [--pool 2000] [--rows position|pose] [--kind pose|axis|position]
                  [--region "xmin,ymin,zmin,xmax,ymax,zmax"] -o poses.csv

``random``: random configurations within the joint limits, away from singularities.
``optimal``: ``--n`` poses selected from a seeded random pool of ``--pool`` poses by
greedy construction and exchanges maximising ``--index`` (O1 by default).
``iso9283``: ISO 9283 P1..P5 on the largest test cube's diagonal plane C1-C2-C7-C8,
one fixed tool orientation (tool z down).  ``diagonal``: the thesis' set (seed 003):
``--n`` (118) poses on the cube's diagonal planes and near the workspace boundary,
ordered so that all joints move between consecutive poses.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Literal, cast

import numpy as np
import typer
from rich.table import Table

from robocal.choices import IndexName, PoseMethod, PoseRows, TargetKind
from robocal.cli import options
from robocal.cli.options import Force, Robot, length_vector, out_option, resolve_model
from robocal.console import console, err_console, fail, refuse_overwrite, safe

if TYPE_CHECKING:
    from robocal.identify.pose_plan import PosePlan

__all__ = ["MAX_POOL", "MAX_POSES", "register"]

#: at most this many poses per command (a measurement campaign has tens to thousands)
MAX_POSES = 100_000
#: at most this many candidates for --method optimal (its Jacobians: ~0.1 GB per 100 000)
MAX_POOL = 100_000


def _region(text: str | None) -> np.ndarray | None:
    if text is None:
        return None
    box = length_vector(text, 6, "--region").reshape(2, 3)
    if np.any(box[0] >= box[1]):
        raise fail(f"--region {text!r}: each minimum must be below its maximum")
    return box


MethodOption = Annotated[
    PoseMethod,
    typer.Option("--method", metavar="random|optimal|iso9283|diagonal", help="how to choose the poses"),
]
NOption = Annotated[
    int | None,
    typer.Option(
        "--n",
        min=1,
        max=MAX_POSES,
        metavar="N",
        help="number of poses (random/optimal: 30, diagonal: 118; iso9283: 5 fixed)",
    ),
]
IndexOption = Annotated[
    IndexName,
    typer.Option(
        "--index", metavar="O1..O5", help="index maximised by --method optimal", case_sensitive=False
    ),
]
PoolOption = Annotated[
    int,
    typer.Option("--pool", min=1, max=MAX_POOL, metavar="N", help="candidate pool size for --method optimal"),
]
RowsOption = Annotated[
    PoseRows,
    typer.Option(
        "--rows",
        metavar="position|pose|point|plane|distance|tilt",
        help="the quantities that will be measured (point, plane, distance: configurations at a socket, "
        "on a plate, ball-bar pairs; with the constraint labels; tilt: inclinometers on every link)",
    ),
]
KindOption = Annotated[
    TargetKind | None,
    typer.Option("--kind", metavar="position|pose|axis", help="iso9283/diagonal: the IK constraint"),
]
RegionOption = Annotated[
    str | None,
    typer.Option(
        "--region",
        metavar='"xmin,ymin,zmin,xmax,ymax,zmax"',
        help='box the cube must lie in, with a unit, e.g. "300,-400,200,900,400,800mm"',
    ),
]


def poses_command(
    robot: Robot,
    out: Annotated[Path, out_option("poses CSV to write (SI units)")],
    method: MethodOption = "random",
    n: NOption = None,
    seed: Annotated[int, options.seed()] = 0,
    index: IndexOption = "O1",
    pool: PoolOption = 2000,
    rows: RowsOption = "position",
    kind: KindOption = None,
    region: RegionOption = None,
    force: Force = False,
) -> None:
    """Choose poses to measure and write them as a poses CSV (joint columns only, rad/m)."""
    from robocal.measure.poses import write_poses

    refuse_overwrite(out, force, "poses file")
    m = resolve_model(robot)
    if rows == "tilt":  # inclinometer readings (robocal.cli.inclinometer)
        from robocal.cli.inclinometer import plan_tilt_poses

        return plan_tilt_poses(m, out, n=n or 30, pool=pool, index=index, seed=seed)
    if rows in ("point", "plane", "distance"):  # a socket, a plate, a ball-bar (robocal.cli.constraints)
        from robocal.cli.constraints import plan_constraint_poses

        return plan_constraint_poses(m, rows, out, n=n or 30, pool=pool, index=index, seed=seed)
    box = _region(region)
    if method == "iso9283" and n not in (None, 5):
        err_console.print("[yellow]note:[/] --method iso9283 always gives the 5 poses P1..P5", markup=True)
    if method == "optimal" and pool < (n or 30):
        raise fail(f"--pool {pool} is smaller than --n {n or 30}")
    from robocal.identify.pose_plan import plan_poses

    try:
        with console.status(f"planning {method} poses..."):
            measured = cast(Literal["position", "pose"], rows)
            plan = plan_poses(m, method, n, seed=seed, index=index, pool=pool, rows=measured, kind=kind,
                              region=box)  # fmt: skip
    except ValueError as err:
        raise fail(str(err)) from None
    _print_plan(plan)
    path = write_poses(out, plan.q, model=m, metadata=plan.metadata)
    console.print(f"wrote {len(plan.q)} poses of {m.name} to {path}", highlight=False)


def _print_plan(plan: PosePlan) -> None:
    """The plan's lines: ``optimal``'s observability table and what it cannot identify."""
    if plan.indices:
        count = len(plan.q)
        table = Table(title=f"observability of {count} poses ({plan.n_params} identifiable parameters)")
        for col in ("index", "optimal", f"first {count} of the pool"):
            table.add_column(col, justify="right")
        for name in ("O1", "O2", "O3", "O4", "O5"):
            table.add_row(name, f"{plan.indices[name]:.4g}", f"{plan.reference[name]:.4g}")
        console.print(table)
    for line in plan.notes:
        console.print(safe(line), highlight=False)
    for d in plan.not_identifiable:
        console.print(f"[dim]not identifiable: {safe(d)}[/]", highlight=False, markup=True)


def register(app: typer.Typer) -> None:
    """Add ``robocal poses`` to the application."""
    app.command("poses")(poses_command)
