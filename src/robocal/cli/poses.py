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

import math
from pathlib import Path
from typing import Annotated

import numpy as np
import typer
from rich.table import Table

from robocal.choices import IndexName, PoseMethod, TargetKind
from robocal.cli import options
from robocal.cli.options import Force, Robot, length_vector, out_option, resolve_model
from robocal.console import console, err_console, fail, refuse_overwrite, safe

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
    str,
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
    if rows not in ("position", "pose"):
        raise fail(f"--rows {rows!r}: expected 'position' or 'pose'")
    box = _region(region)
    meta = {"robot": m.name, "method": method, "seed": str(seed)}
    try:
        if method == "random":
            from robocal.measure.poses import random_poses

            q = random_poses(m, n or 30, seed=seed)
        elif method == "optimal":
            q = _optimal(m, n or 30, pool, index, rows, seed, meta)
        elif method == "iso9283":
            q = _iso9283(m, n, kind, box, seed, meta)
        else:
            q = _diagonal(m, n or 118, kind, box, seed)
    except ValueError as err:
        raise fail(str(err)) from None
    path = write_poses(out, q, model=m, metadata=meta)
    console.print(f"wrote {len(q)} poses of {m.name} to {path}", highlight=False)


def _optimal(m, count: int, pool: int, index: str, rows: str, seed: int, meta: dict) -> np.ndarray:
    """``--method optimal``: ``count`` poses of a random pool maximising ``index``; the
    observability table printed."""
    from robocal.identify.observability_indices import identifiable_parameters, observability
    from robocal.identify.pose_selection import select_poses
    from robocal.measure.poses import random_poses

    if pool < count:
        raise fail(f"--pool {pool} is smaller than --n {count}")
    candidates = random_poses(m, pool, seed=seed)
    sub = identifiable_parameters(m, candidates, rows=rows)  # type: ignore[arg-type]
    with console.status(f"selecting {count} of {pool} poses by {index}..."):
        sel = select_poses(m, candidates, count, index=index, rows=rows, params=sub.kept)  # type: ignore[arg-type]
    baseline = observability(m, candidates[:count], rows=rows, params=sel.params)  # type: ignore[arg-type]
    table = Table(title=f"observability of {count} poses ({len(sel.params)} identifiable parameters)")
    for col in ("index", "optimal", f"first {count} of the pool"):
        table.add_column(col, justify="right")
    for name in ("O1", "O2", "O3", "O4", "O5"):
        table.add_row(name, f"{sel.indices_all[name]:.4g}", f"{baseline[name]:.4g}")
    console.print(table)
    meta.update({"index": index, "pool": str(pool), "value": repr(sel.value)})
    for d in sub.dropped:
        console.print(f"[dim]not identifiable: {safe(d)}[/]", highlight=False, markup=True)
    return sel.q


def _iso9283(m, n: int | None, kind: TargetKind | None, box, seed: int, meta: dict) -> np.ndarray:
    """``--method iso9283``: P1..P5 on the largest cube's diagonal plane."""
    from robocal.measure.poses import iso9283_poses

    if n not in (None, 5):
        err_console.print("[yellow]note:[/] --method iso9283 always gives the 5 poses P1..P5", markup=True)
    with console.status("searching the largest ISO 9283 cube..."):
        iso = iso9283_poses(m, kind=kind, seed=seed, region=box)
    c = iso.cube
    console.print(
        f"cube centre [{', '.join(f'{v * 1e3:.1f}' for v in c.center)}] mm, side {c.side * 1e3:.1f} mm, "
        f"plane C1-C2-C7-C8, constraint {iso.info['kind']}",
        highlight=False,
    )
    meta.update(
        {
            "cube_center_mm": " ".join(f"{v * 1e3:.3f}" for v in c.center),
            "cube_side_mm": f"{c.side * 1e3:.3f}",
        }
    )
    return iso.q


def _diagonal(m, n: int, kind: TargetKind | None, box, seed: int) -> np.ndarray:
    """``--method diagonal``: the thesis' poses on the cube's diagonal planes (seed 003)."""
    from robocal.measure.diagonal_poses import diagonal_plane_poses

    with console.status("building the diagonal-plane poses..."):
        ps = diagonal_plane_poses(m, n=n, kind=kind or "position", region=box, seed=seed)
    if not ps.reachable.all():
        raise fail(f"{int((~ps.reachable).sum())} of the diagonal-plane poses are not reachable")
    min_change_rad = ps.info["min_joint_change_rad"]
    assert isinstance(min_change_rad, float)  # diagonal_plane_poses' record
    console.print(
        f"{len(ps.q)} poses ({ps.info['boundary_poses']} near the boundary), smallest joint change "
        f"between consecutive poses {math.degrees(min_change_rad):.1f} deg",
        highlight=False,
    )
    return ps.q


def register(app: typer.Typer) -> None:
    """Add ``robocal poses`` to the application."""
    app.command("poses")(poses_command)
