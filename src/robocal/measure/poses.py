"""Pose sets: what to measure.

* :func:`random_poses` — random configurations within the joint limits (seeded),
  optionally with the tool point inside a Cartesian box, away from singular
  configurations.
* :class:`Cube`, :func:`largest_cube`, :func:`iso9283_poses` — the ISO 9283:1998 test
  cube and its poses P1–P5 (:mod:`robocal.measure.cube`).
* :func:`diagonal_plane_poses` — the thesis' measurement set (seed 003 §3.4, §4.4.2):
  poses on the cube's diagonal planes plus poses near the workspace boundary, ordered
  so that every joint moves between consecutive poses (:func:`order_all_joints_move`).
* :func:`plane_grid`, :func:`poses_for_points` — calibration-plate style grids of
  points and the configurations that reach them.
* :func:`write_poses`, :func:`read_poses` — a poses file is a measurement CSV with
  joint columns only (:mod:`robocal.measure.dataset.read`).

The cube lives in :mod:`robocal.measure.cube`, :class:`PoseSet` and the ordering in
:mod:`robocal.measure.pose_set`, seed 003's set in :mod:`robocal.measure.diagonal_poses`;
this module re-exports them.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from robocal.choices import AngleUnit
from robocal.measure.cube import (
    CUBE_CORNERS,
    DIAGONAL_PLANES,
    Cube,
    constraint,
    largest_cube,
    solve,
)
from robocal.measure.cube import TOOL_DOWN as TOOL_DOWN
from robocal.measure.dataset.read import read_measurements
from robocal.measure.dataset.writer import write_measurements
from robocal.measure.diagonal_poses import diagonal_plane_poses
from robocal.measure.ik import solve_ik
from robocal.measure.ik_starts import TargetKind, random_configurations
from robocal.measure.measurements import Measurements
from robocal.measure.pose_set import PoseSet, order_all_joints_move, position_sigma_min
from robocal.model.chain import Model

__all__ = [
    "CUBE_CORNERS",
    "DIAGONAL_PLANES",
    "Cube",
    "IsoPoses",
    "PoseSet",
    "diagonal_plane_poses",
    "iso9283_poses",
    "largest_cube",
    "order_all_joints_move",
    "plane_grid",
    "poses_for_points",
    "position_sigma_min",
    "random_poses",
    "read_poses",
    "write_poses",
]

Array = NDArray[np.float64]


@dataclass(frozen=True, kw_only=True)
class IsoPoses(PoseSet):
    """ISO 9283 poses P1..P5 plus their cube, plane, tool orientation (3x3, base frame) and
    what the targets fix of the tool (``kind``)."""

    cube: Cube
    plane: int = 1
    orientation: Array
    kind: TargetKind


def iso9283_poses(
    model: Model,
    cube: Cube | None = None,
    *,
    plane: int = 1,
    fraction: float = 0.1,
    kind: TargetKind | None = None,
    orientation: ArrayLike | None = None,
    tool_axis: int = 2,
    seed: int = 0,
    **search: object,
) -> IsoPoses:
    """ISO 9283 test poses P1..P5 on a diagonal plane of the (largest) test cube.

    Args:
        model: the robot.
        cube: the test cube; found by :func:`largest_cube` (with ``kind``,
            ``orientation``, ``tool_axis`` and ``**search``) when None.
        plane: the diagonal plane (1: C1-C2-C7-C8, 2: C2-C3-C8-C5, 3: C3-C4-C5-C6,
            4: C4-C1-C6-C7).
        fraction: P2..P5 distance from the corners as a fraction of the diagonal.
        kind, orientation, tool_axis: the fixed tool orientation (see
            :func:`largest_cube`).
        seed: IK seed.

    Returns:
        :class:`IsoPoses` with ``q`` ``(5, dof)``: P1 is solved first; P2..P5 start from
        P1's configuration so that all five share its configuration branch.

    Raises:
        ValueError: when a pose is not reachable with the imposed orientation.
    """
    con = constraint(model, kind, orientation, tool_axis)
    if cube is None:
        cube = largest_cube(model, kind=con.kind, orientation=con.R, tool_axis=tool_axis, seed=seed, **search)  # type: ignore[arg-type]
    points = cube.iso_points(plane, fraction)
    ok1, q1 = solve(model, con, points[:1], None, restarts=20, seed=seed)
    ok, q = solve(model, con, points[1:], np.repeat(q1, 4, axis=0), restarts=20, seed=seed)
    reachable = np.concatenate([ok1, ok])
    q = np.vstack([q1, q])
    if not reachable.all():
        bad = [f"P{i + 1}" for i in np.flatnonzero(~reachable)]
        raise ValueError(
            f"ISO 9283 pose(s) {', '.join(bad)} of cube centre {np.round(cube.center, 4).tolist()} m, "
            f"side {cube.side:.4f} m are not reachable by {model.name!r} with the imposed orientation"
        )
    return IsoPoses(
        q=q,
        positions=points,
        labels=("P1", "P2", "P3", "P4", "P5"),
        reachable=reachable,
        info={"plane": plane, "fraction": fraction, "kind": con.kind, "side_m": cube.side},
        cube=cube,
        plane=plane,
        orientation=con.R,
        kind=con.kind,
    )


def _inner_limits(model: Model, margin: float) -> Array:
    if not 0 <= margin < 0.5:
        raise ValueError(f"margin must be a fraction of the joint range in [0, 0.5), got {margin!r}")
    lim = model.joint_limits.copy()
    span = lim[:, 1] - lim[:, 0]
    finite = np.isfinite(span)
    lim[finite, 0] += margin * span[finite]
    lim[finite, 1] -= margin * span[finite]
    return lim


def random_poses(
    model: Model,
    n: int,
    *,
    seed: int | np.random.Generator | None = 0,
    box: ArrayLike | None = None,
    min_sigma: float = 0.01,
    rows: Literal["position", "pose"] = "position",
    margin: float = 0.0,
    max_candidates: int = 200_000,
) -> Array:
    """``(n, dof)`` random configurations within the joint limits, away from singularities.

    Candidates are drawn uniformly (seeded; revolute joints with limits wider than
    [-π, π] in [-π, π], see :func:`~robocal.measure.ik.random_configurations`) and
    rejected when

    * the smallest singular value of the joint Jacobian's position rows (``rows``) is
      below ``min_sigma`` (m/rad), i.e. near a singular configuration;
    * a joint lies within ``margin`` (fraction of its range) of a limit;
    * ``box`` ``(2, 3)`` (lower, upper corners in m, base frame) is given and the tool
      point lies outside it.

    When a small box rejects most candidates, the remaining poses are found by IK of
    random points in the box from random starts.

    Raises:
        ValueError: when fewer than ``n`` acceptable poses are found among
            ``max_candidates`` candidates.
    """
    n = int(n)
    if n < 0:
        raise ValueError(f"number of poses must be >= 0, got {n}")
    rng = np.random.default_rng(seed)
    lim = _inner_limits(model, margin)
    if box is not None:
        box = np.asarray(box, dtype=float)
        if box.shape != (2, 3) or np.any(box[0] > box[1]):
            raise ValueError(f"box must be (2, 3) lower/upper corners (m), got {np.asarray(box).tolist()!r}")

    def accept(q: Array) -> NDArray[np.bool_]:
        ok = np.all((q >= lim[:, 0]) & (q <= lim[:, 1]), axis=1)
        if box is not None:
            p = model.fk(q)[:, :3, 3]
            ok &= np.all((p >= box[0]) & (p <= box[1]), axis=1)
        if min_sigma > 0 and ok.any():
            ok[ok] = position_sigma_min(model, q[ok], rows) >= min_sigma
        return ok

    found: list[Array] = []
    count, tried = 0, 0
    batch = max(4 * n, 1000)
    while count < n and tried < max_candidates:
        q = random_configurations(model, batch, rng)
        tried += batch
        good = q[accept(q)]
        found.append(good)
        count += len(good)
        rate = count / tried
        if box is not None and tried >= 5 * batch and rate * (max_candidates - tried) < n - count:
            break  # a small box: rejection would not finish, switch to IK
    ik_tried = 0
    while count < n and ik_tried < max_candidates and box is not None:
        k = max(2 * (n - count), 200)
        pts = box[0] + rng.random((k, 3)) * (box[1] - box[0])
        res = solve_ik(model, pts, kind="position", restarts=2, seed=rng)
        ik_tried += k
        good = res.q[res.reachable]
        good = good[accept(good)]
        found.append(good)
        count += len(good)
    tried += ik_tried
    if count < n:
        raise ValueError(
            f"found only {count} of {n} acceptable random poses of {model.name!r} among {tried} "
            f"candidates (min_sigma={min_sigma} m/rad, margin={margin}, "
            f"box={None if box is None else box.tolist()})"
        )
    return np.vstack(found)[:n]


# ------------------------------------------------------------------------ plates and grids
def plane_grid(
    center: ArrayLike,
    size: float | ArrayLike,
    shape: tuple[int, int],
    *,
    normal: ArrayLike = (0.0, 0.0, 1.0),
    x_axis: ArrayLike | None = None,
) -> Array:
    """``(a*b, 3)`` points of a rectangular grid on a plane (a calibration plate), m.

    Args:
        center: ``(3,)`` centre of the grid (m).
        size: side lengths ``(sx, sy)`` (m) between the outer points, or one for both.
        shape: ``(a, b)`` points along the grid's x and y axes; rows vary y fastest.
        normal: plate normal (any length).
        x_axis: direction of the grid's x axis (projected onto the plane); default the
            base x axis (or y when the normal is along x).
    """
    c = np.asarray(center, dtype=float).reshape(3)
    sx, sy = np.broadcast_to(np.asarray(size, dtype=float), (2,))
    a, b = (int(v) for v in shape)
    if a < 1 or b < 1:
        raise ValueError(f"grid shape must be positive, got {shape!r}")
    nrm = np.asarray(normal, dtype=float)
    if np.linalg.norm(nrm) == 0:
        raise ValueError("plate normal must be non-zero")
    nrm = nrm / np.linalg.norm(nrm)
    if x_axis is None:
        x_axis = (1.0, 0.0, 0.0) if abs(nrm[0]) < 0.9 else (0.0, 1.0, 0.0)
    x = np.asarray(x_axis, dtype=float)
    x = x - nrm * (x @ nrm)
    if np.linalg.norm(x) < 1e-9:
        raise ValueError(f"x_axis {np.asarray(x_axis).tolist()} is parallel to the plate normal")
    x /= np.linalg.norm(x)
    y = np.cross(nrm, x)
    u = np.linspace(-sx / 2, sx / 2, a) if a > 1 else np.zeros(1)
    v = np.linspace(-sy / 2, sy / 2, b) if b > 1 else np.zeros(1)
    U, V = np.meshgrid(u, v, indexing="ij")
    return c + U.reshape(-1, 1) * x + V.reshape(-1, 1) * y


def poses_for_points(
    model: Model,
    points: ArrayLike,
    *,
    kind: TargetKind = "position",
    orientation: ArrayLike | None = None,
    tool_axis: int = 2,
    q0: ArrayLike | None = None,
    seed: int = 0,
) -> PoseSet:
    """Configurations reaching ``points`` ``(n, 3)`` (m), on one configuration branch.

    The first point is solved from ``q0`` (or random starts), every other point starts
    from the first point's solution (random restarts only where that fails), so a
    plate's poses share a configuration.  Unreached points are flagged in
    ``reachable``, not dropped.
    """
    pts = np.asarray(points, dtype=float).reshape(-1, 3)
    con = constraint(model, kind, orientation, tool_axis)
    res0 = solve_ik(model, con.targets(pts[:1]), kind=con.kind, q0=q0, seed=seed, tool_axis=tool_axis)
    res = solve_ik(model, con.targets(pts), kind=con.kind, q0=res0.q[0], seed=seed, tool_axis=tool_axis)
    return PoseSet(
        q=res.q,
        positions=pts,
        labels=tuple(f"point{i + 1}" for i in range(len(pts))),
        reachable=res.reachable,
        info={"kind": con.kind},
    )


# ------------------------------------------------------------------------ files
def write_poses(
    path: str | Path,
    poses: PoseSet | ArrayLike,
    *,
    model: Model | None = None,
    metadata: Mapping[str, str] | None = None,
) -> Path:
    """Write a poses file (measurement CSV with joint columns ``q1..qN`` only, SI), atomically.

    With ``model``, the joint count and limits are checked first.
    """
    q = poses.q if isinstance(poses, PoseSet) else np.asarray(poses, dtype=float)
    if q.ndim != 2:
        raise ValueError(f"poses must be (n, dof) joint values, got shape {q.shape}")
    meta = {str(k): str(v) for k, v in (metadata or {}).items()}
    if model is not None:
        _check_against(model, q, str(path))
        meta.setdefault("robot", model.name)
        meta.setdefault("joints", " ".join(model.joint_names))
    return write_measurements(Measurements(q=q, metadata=meta), path)


def read_poses(path: str | Path, model: Model | None = None, *, angle_unit: AngleUnit = "rad") -> Array:
    """``(n, dof)`` joint values from a poses (or measurement) CSV, checked against ``model``."""
    data = read_measurements(path, angle_unit=angle_unit, dof=None if model is None else model.dof)
    if model is not None:
        _check_against(model, data.q, str(path))
    return data.q


def _check_against(model: Model, q: Array, where: str) -> None:
    if q.shape[1] != model.dof:
        raise ValueError(f"{where}: {q.shape[1]} joint columns, but {model.name!r} has {model.dof} joints")
    lim = model.joint_limits
    bad = np.argwhere((q < lim[:, 0] - 1e-12) | (q > lim[:, 1] + 1e-12))
    if len(bad):
        i, j = bad[0]
        raise ValueError(
            f"{where}: pose {i + 1}, joint {model.joint_names[j]} = {q[i, j]:.6g} is outside its limits "
            f"[{lim[j, 0]:.6g}, {lim[j, 1]:.6g}]"
        )
