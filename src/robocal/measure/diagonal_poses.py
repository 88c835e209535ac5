"""Seed 003's measurement poses: the cube's diagonal planes plus poses near the workspace boundary."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from robocal.measure.cube import (
    CUBE_CORNERS,
    DIAGONAL_PLANES,
    Constraint,
    Cube,
    check_plane,
    constraint,
    largest_cube,
    solve,
    unique_rows,
    unit_plane_grid,
)
from robocal.measure.cube import TOOL_DOWN as TOOL_DOWN
from robocal.measure.ik import solve_ik
from robocal.measure.ik_starts import TargetKind, random_configurations
from robocal.measure.pose_set import PoseSet, order_all_joints_move, position_sigma_min
from robocal.model.chain import Model

Array = NDArray[np.float64]


# ------------------------------------------------------------------------ thesis poses
def _ray_limits(
    model: Model, con: Constraint, origin: Array, directions: Array, s_max: Array, seed: int
) -> Array:
    """Farthest reachable distance (m) from ``origin`` along each unit direction, by
    bisection on IK reachability (the first boundary crossing it brackets)."""
    lo, hi = np.zeros(len(directions)), np.asarray(s_max, dtype=float).copy()
    ok, q0 = solve(model, con, origin[None], None, restarts=20, seed=seed)
    if not ok[0]:
        raise ValueError(f"ray origin {origin.tolist()} m is not reachable by {model.name!r}")
    seeds = np.repeat(q0, len(directions), axis=0)
    while True:
        todo = np.flatnonzero(hi - lo > 1e-3)
        if not len(todo):
            return lo
        mid = 0.5 * (lo[todo] + hi[todo])
        ok, q = solve(model, con, origin + mid[:, None] * directions[todo], seeds[todo], 2, seed)
        lo[todo[ok]] = mid[ok]
        seeds[todo[ok]] = q[ok]
        hi[todo[~ok]] = mid[~ok]


def diagonal_plane_poses(  # noqa: PLR0913 - keyword-only options of a public function
    model: Model,
    cube: Cube | None = None,
    *,
    n: int = 118,
    grid: int = 5,
    planes: Sequence[int] = (1, 2, 3, 4),
    boundary_fraction: float = 0.95,
    kind: TargetKind = "position",
    orientation: ArrayLike | None = None,
    tool_axis: int = 2,
    region: ArrayLike | None = None,
    solutions: int = 8,
    min_sigma: float = 0.01,
    seed: int = 0,
) -> PoseSet:
    """The thesis' measurement poses (seed 003 §3.4, §4.4.2, Fig. 4.8), as we read them.

    Seed 003: "118 poses ... are chosen on the diagonal planes within the largest cube
    of the robot's workspace, and some of the poses are selected close to workspace
    boundary.  The measurement is sequenced such that all five joints angles have to
    be changed when moving from one pose to another"; the figure shows varied tool
    orientations.  The thesis does not list the points, so we build them:

    1. the cube: ``cube`` or :func:`largest_cube` (``kind``, ``orientation``, ``region``);
    2. a ``grid x grid`` lattice on each diagonal plane in ``planes`` (shared points
       once: 73 points for a 5 x 5 grid on the four planes);
    3. the remaining ``n - grid points`` *near-boundary poses*: rays from the cube's
       centre in the diagonal planes (round robin over the planes, evenly spread
       angles), each pose at ``boundary_fraction`` of the distance at which the ray
       leaves the reachable workspace (and ``region``);
    4. joint values by IK (``kind``; position only by default, so the orientation
       varies as in the thesis' figure) from ``solutions`` random starts per point,
       one reached solution drawn at random (seeded) among those whose position
       Jacobian's smallest singular value is at least ``min_sigma`` (m/rad);
    5. the order from :func:`order_all_joints_move`, starting at the cube's centre.

    Returns:
        :class:`PoseSet` with labels ``"plane"`` (lattice) or ``"boundary"`` and
        ``info["min_joint_change_rad"]``, the smallest joint change between consecutive
        poses.
    """
    con = constraint(model, kind, orientation, tool_axis)
    planes = tuple(check_plane(p) for p in planes)
    if not 0 < boundary_fraction <= 1:
        raise ValueError(f"boundary_fraction must be in (0, 1], got {boundary_fraction!r}")
    if cube is None:
        cube = largest_cube(
            model, kind=con.kind, orientation=con.R, tool_axis=tool_axis, region=region, seed=seed
        )
    rng = np.random.default_rng(seed)
    lattice = _plane_lattice(cube, planes, grid)
    n_b = int(n) - len(lattice)
    if n_b < 0:
        raise ValueError(
            f"a {grid} x {grid} grid on {len(planes)} diagonal plane(s) has {len(lattice)} points, "
            f"more than n={n}; use a smaller grid"
        )
    points, labels = [lattice], ["plane"] * len(lattice)
    if n_b:
        points.append(_boundary_points(model, con, cube, planes, n_b, region, boundary_fraction, rng, seed))
        labels += ["boundary"] * n_b
    pts = np.vstack(points)
    q, reachable, good = _pick_solutions(model, con, pts, solutions, min_sigma, rng)
    order, min_change = order_all_joints_move(q, start=0)
    return PoseSet(
        q=q[order],
        positions=pts[order],
        labels=tuple(labels[i] for i in order),
        reachable=reachable[order],
        info={
            "cube_center_m": cube.center.tolist(),
            "cube_side_m": cube.side,
            "grid": grid,
            "planes": planes,
            "boundary_poses": n_b,
            "min_joint_change_rad": min_change,
            "well_conditioned": int(good.sum()),
        },
    )


def _boundary_points(
    model: Model,
    con: Constraint,
    cube: Cube,
    planes: tuple[int, ...],
    n_b: int,
    region: ArrayLike | None,
    boundary_fraction: float,
    rng: np.random.Generator,
    seed: int,
) -> Array:
    """``(n_b, 3)`` near-boundary points (m): rays from the cube's centre in the diagonal
    planes (round robin, evenly spread angles), each at ``boundary_fraction`` of the distance
    at which it leaves the reachable workspace (and ``region``)."""
    dirs_list = []
    per_plane = -(-n_b // len(planes))
    for b in range(n_b):
        c = CUBE_CORNERS[list(DIAGONAL_PLANES[planes[b % len(planes)]])]
        e1 = (c[1] - c[0]) / np.linalg.norm(c[1] - c[0])
        e2 = (c[3] - c[0]) / np.linalg.norm(c[3] - c[0])
        phi = 2 * np.pi * ((b // len(planes)) + 0.5) / per_plane
        dirs_list.append(np.cos(phi) * e1 + np.sin(phi) * e2)
    dirs = np.array(dirs_list)
    reach = model.fk(random_configurations(model, 4000, rng))[:, :3, 3]
    bound = np.array([reach.min(axis=0), reach.max(axis=0)])
    if region is not None:
        region = np.asarray(region, dtype=float)
        bound = np.array([np.maximum(bound[0], region[0]), np.minimum(bound[1], region[1])])
    with np.errstate(divide="ignore", invalid="ignore"):  # distance to leave the box
        t = np.where(dirs > 0, (bound[1] - cube.center) / dirs, (bound[0] - cube.center) / dirs)
    s_max = np.nanmin(np.where(np.isfinite(t) & (t > 0), t, np.inf), axis=1)
    s = _ray_limits(model, con, cube.center, dirs, s_max, seed)
    return cube.center + boundary_fraction * s[:, None] * dirs


def _pick_solutions(
    model: Model, con: Constraint, pts: Array, solutions: int, min_sigma: float, rng: np.random.Generator
) -> tuple[Array, NDArray[np.bool_], NDArray[np.bool_]]:
    """IK from ``solutions`` random starts per point; per point one reached solution drawn at
    random among those with position σ_min >= ``min_sigma``. Returns ``q`` ``(m, dof)``,
    reached ``(m,)`` and well conditioned ``(m,)``."""
    m = len(pts)
    starts = random_configurations(model, m * solutions, rng)
    res = solve_ik(
        model,
        con.targets(np.tile(pts, (solutions, 1))),
        kind=con.kind,
        q0=starts,
        restarts=2,
        seed=rng,
        tool_axis=con.tool_axis,
    )
    Q = res.q.reshape(solutions, m, model.dof)
    ok = res.reachable.reshape(solutions, m)
    sig = position_sigma_min(model, res.q).reshape(solutions, m)
    good = ok & (sig >= min_sigma)
    pref = np.where(good, 2, np.where(ok, 1, 0)) + rng.random((solutions, m))  # random among the best class
    pick = np.argmax(pref, axis=0)
    return Q[pick, np.arange(m)], ok[pick, np.arange(m)], good[pick, np.arange(m)]


def _plane_lattice(cube: Cube, planes: tuple[int, ...], grid: int) -> Array:
    """A ``grid x grid`` lattice on each diagonal plane (shared points once), centre first, m."""
    unit = unique_rows(np.vstack([unit_plane_grid(p, (grid, grid)) for p in planes]))
    centre_first = np.argsort(np.abs(unit - 0.5).sum(axis=1), kind="stable")
    return cube.at(unit[centre_first])
