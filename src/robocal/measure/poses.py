"""Pose sets: what to measure.

* :func:`random_poses` — random configurations within the joint limits (seeded),
  optionally with the tool point inside a Cartesian box, away from singular
  configurations.
* :class:`Cube`, :func:`largest_cube`, :func:`iso9283_poses` — the ISO 9283:1998 test
  cube and its poses P1–P5 (see below).
* :func:`diagonal_plane_poses` — the thesis' measurement set (seed 003 §3.4, §4.4.2):
  poses on the cube's diagonal planes plus poses near the workspace boundary, ordered
  so that every joint moves between consecutive poses (:func:`order_all_joints_move`).
* :func:`plane_grid`, :func:`poses_for_points` — calibration-plate style grids of
  points and the configurations that reach them.
* :func:`write_poses`, :func:`read_poses` — a poses file is a measurement CSV with
  joint columns only (:mod:`robocal.measure.dataset`).

ISO 9283 test cube (as we read the standard)
--------------------------------------------
ISO 9283:1998 §6.2 (seed 003 §3.4 and §4.4.2 only cite the standard, via Johnsrud
2014, and say "the largest cube of the robot's workspace" and "diagonal planes"; the
positions below are the standard's): a cube with edges parallel to the base frame, of
the largest volume that fits in the part of the working space of greatest use.  Its
corners are numbered here

    C1 (0,0,0)  C2 (1,0,0)  C3 (1,1,0)  C4 (0,1,0)      (bottom face, z = 0)
    C5 (0,0,1)  C6 (1,0,1)  C7 (1,1,1)  C8 (0,1,1)      (top face, z = 1)

in units of the side, from the cube's minimum corner, so that the four *diagonal
planes* of the standard — each the rectangle through two opposite edges — are
C1-C2-C7-C8 (plane 1), C2-C3-C8-C5 (2), C3-C4-C5-C6 (3) and C4-C1-C6-C7 (4).  The
test poses lie on one of them (plane 1 by default): P1 at the centre of the cube
(the intersection of the plane's diagonals), P2–P5 on the plane's diagonals at 10 %
of the diagonal's length from the corners (the standard allows 10 ± 2 %), P2 near
the plane's first corner (C1 for plane 1), then P3, P4, P5 near the next corners in
the order listed.  All five are reached with one fixed tool orientation.

"Largest cube" is defined numerically (:func:`largest_cube`): an axis-aligned cube
whose check points — a 5 x 5 grid on each of its diagonal planes (corners, edges,
centre) and each plane's P1–P5 — are all reached by the IK with the imposed tool
orientation, inside the joint limits.  A seeded point cloud classified by the IK
gives candidate centres (largest cube free of unreachable cloud points, which also
sees holes off the planes at the cloud's spacing); the side is then maximised by
bisection for the best candidates and the centre refined by a compass search.  The
search is a heuristic: different seeds give sides within a few per cent.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from robocal import spatial
from robocal.measure.dataset import Measurements, read_measurements, write_measurements
from robocal.measure.ik import TargetKind, random_configurations, solve_ik
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

#: Unit-cube corners C1..C8 (rows), in units of the side from the minimum corner.
CUBE_CORNERS = np.array(
    [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]], dtype=float
)
#: ISO 9283 diagonal planes: corner indices (0-based, C1 = 0) in cyclic order.
DIAGONAL_PLANES: dict[int, tuple[int, int, int, int]] = {
    1: (0, 1, 6, 7),  # C1-C2-C7-C8
    2: (1, 2, 7, 4),  # C2-C3-C8-C5
    3: (2, 3, 4, 5),  # C3-C4-C5-C6
    4: (3, 0, 5, 6),  # C4-C1-C6-C7
}
#: Default fixed tool orientation: tool z pointing down (−z of the base), tool x along base x.
TOOL_DOWN = np.diag([1.0, -1.0, -1.0])


def _check_plane(plane: int) -> int:
    if plane not in DIAGONAL_PLANES:
        raise ValueError(f"diagonal plane must be 1, 2, 3 or 4 (ISO 9283 C1-C2-C7-C8 ...), got {plane!r}")
    return int(plane)


# ------------------------------------------------------------------------ the cube
@dataclass(frozen=True)
class Cube:
    """An axis-aligned cube in the base frame.

    Attributes:
        center: ``(3,)`` centre (m).
        side: edge length (m).
    """

    center: Array
    side: float

    def __post_init__(self) -> None:
        c = np.asarray(self.center, dtype=float)
        if c.shape != (3,) or not np.all(np.isfinite(c)):
            raise ValueError(f"cube centre must be 3 finite numbers (m), got {self.center!r}")
        if not (np.isfinite(self.side) and self.side > 0):
            raise ValueError(f"cube side must be positive (m), got {self.side!r}")
        object.__setattr__(self, "center", c)
        object.__setattr__(self, "side", float(self.side))

    def at(self, unit: ArrayLike) -> Array:
        """Points ``(..., 3)`` (m) at unit-cube coordinates ``(..., 3)`` (0..1 per axis)."""
        return self.center + self.side * (np.asarray(unit, dtype=float) - 0.5)

    @property
    def corners(self) -> Array:
        """``(8, 3)`` corners C1..C8 (m), numbered as in the module docstring."""
        return self.at(CUBE_CORNERS)

    def plane_corners(self, plane: int = 1) -> Array:
        """``(4, 3)`` corners of an ISO 9283 diagonal plane, in cyclic order (m)."""
        return self.corners[list(DIAGONAL_PLANES[_check_plane(plane)])]

    def plane_points(self, plane: int = 1, shape: tuple[int, int] = (5, 5)) -> Array:
        """``(a*b, 3)`` grid on a diagonal plane (m), ``shape = (a, b)`` points along
        the plane's first edge (a cube edge) and its second edge (a face diagonal)."""
        return self.at(_unit_plane_grid(plane, shape))

    def iso_points(self, plane: int = 1, fraction: float = 0.1) -> Array:
        """``(5, 3)`` ISO 9283 positions P1..P5 on a diagonal plane (m).

        P1 is the cube's centre; P2..P5 lie on the plane's diagonals at ``fraction``
        (ISO 9283: 0.10 ± 0.02) of the diagonal's length from the plane's corners.
        """
        return self.at(_unit_iso_points(plane, fraction))


def _unit_plane_grid(plane: int, shape: tuple[int, int]) -> Array:
    a, b = (int(v) for v in shape)
    if a < 2 or b < 2:
        raise ValueError(f"plane grid shape must be at least (2, 2), got {shape!r}")
    c = CUBE_CORNERS[list(DIAGONAL_PLANES[_check_plane(plane)])]
    s, t = np.meshgrid(np.linspace(0, 1, a), np.linspace(0, 1, b), indexing="ij")
    s, t = s.reshape(-1, 1), t.reshape(-1, 1)
    # bilinear map of the rectangle c0 -> c1 (edge) and c0 -> c3 (face diagonal)
    return c[0] + s * (c[1] - c[0]) + t * (c[3] - c[0])


def _unit_iso_points(plane: int, fraction: float) -> Array:
    if not 0 < fraction < 0.5:
        raise ValueError(f"ISO 9283 fraction of the diagonal must be in (0, 0.5), got {fraction!r}")
    c = CUBE_CORNERS[list(DIAGONAL_PLANES[_check_plane(plane)])]
    opposite = c[[2, 3, 0, 1]]  # the diagonals are c0-c2 and c1-c3
    return np.vstack([[0.5, 0.5, 0.5], c + fraction * (opposite - c)])


def _unique_rows(points: Array, decimals: int = 9) -> Array:
    _, first = np.unique(np.round(points, decimals), axis=0, return_index=True)
    return points[np.sort(first)]


def _check_points(planes: Sequence[int], grid: int, fraction: float = 0.1) -> Array:
    """Unit-cube check points: a grid x grid lattice on each plane plus its P1..P5."""
    pts = [_unit_plane_grid(p, (grid, grid)) for p in planes]
    pts += [_unit_iso_points(p, fraction) for p in planes]
    return _unique_rows(np.vstack(pts))


def _frames(points: Array, R: Array) -> Array:
    return spatial.homogeneous(np.broadcast_to(R, (len(points), 3, 3)), points)


@dataclass(frozen=True)
class _Constraint:
    kind: TargetKind
    R: Array
    tool_axis: int

    def targets(self, points: Array) -> Array:
        return points if self.kind == "position" else _frames(points, self.R)


def _constraint(
    model: Model, kind: TargetKind | None, orientation: ArrayLike | None, tool_axis: int
) -> _Constraint:
    if kind is None:
        kind = "pose" if model.dof >= 6 else "axis"
    if kind not in ("position", "pose", "axis"):
        raise ValueError(f"kind must be 'position', 'pose' or 'axis', got {kind!r}")
    R = TOOL_DOWN if orientation is None else np.asarray(orientation, dtype=float)
    if R.shape != (3, 3) or not np.allclose(R @ R.T, np.eye(3), atol=1e-6) or np.linalg.det(R) < 0:
        raise ValueError(f"orientation must be a 3x3 rotation matrix, got {np.asarray(orientation)!r}")
    return _Constraint(kind, R, tool_axis)


def _solve(
    model: Model, con: _Constraint, points: Array, q0: Array | None, restarts: int, seed: int
) -> tuple[NDArray[np.bool_], Array]:
    res = solve_ik(
        model,
        con.targets(points),
        kind=con.kind,
        q0=q0,
        restarts=restarts,
        seed=seed,
        tool_axis=con.tool_axis,
        max_iter=60,
    )
    return res.reachable, res.q


def _bisect_sides(
    model: Model,
    con: _Constraint,
    unit: Array,
    centers: Array,
    seeds: Array,
    lo: Array,
    hi: Array,
    resolution: float,
    seed: int,
) -> tuple[Array, Array]:
    """Largest feasible side in ``[lo, hi]`` for each centre ``(K, 3)``, by bisection.

    A side is feasible when every check point (``unit``, unit-cube coordinates) is
    reached.  ``seeds`` ``(K, P, dof)`` are the check points' configurations at side
    ``lo`` (feasible); IK starts from the configurations at the last feasible side, so
    the cube stays on one configuration branch where it can.  Returns the sides
    ``(K,)`` and the check points' configurations ``(K, P, dof)``.
    """
    P, dof = len(unit), model.dof
    lo = np.asarray(lo, dtype=float).copy()
    hi = np.asarray(hi, dtype=float).copy()
    seeds = np.array(seeds, dtype=float)
    offsets = unit - 0.5
    while True:
        todo = np.flatnonzero(hi - lo > resolution)
        if not len(todo):
            return lo, seeds
        mid = 0.5 * (lo[todo] + hi[todo])
        pts = (centers[todo, None, :] + mid[:, None, None] * offsets[None]).reshape(-1, 3)
        ok, q = _solve(model, con, pts, seeds[todo].reshape(-1, dof), restarts=1, seed=seed)
        ok = ok.reshape(len(todo), P).all(axis=1)
        q = q.reshape(len(todo), P, dof)
        good, bad = todo[ok], todo[~ok]
        lo[good] = mid[ok]
        seeds[good] = q[ok]
        hi[bad] = mid[~ok]


def _chebyshev_clearance(centers: Array, blocked: Array, box: Array) -> Array:
    """Half the side of the largest axis-aligned cube centred at each centre that
    contains no blocked point and stays in ``box`` (m)."""
    out = np.minimum((centers - box[0]).min(axis=1), (box[1] - centers).min(axis=1))
    for lo in range(0, len(centers), 1024):
        c = centers[lo : lo + 1024]
        if len(blocked):
            d = np.abs(c[:, None, :] - blocked[None, :, :]).max(axis=2).min(axis=1)
            out[lo : lo + 1024] = np.minimum(out[lo : lo + 1024], d)
    return out


def largest_cube(
    model: Model,
    *,
    kind: TargetKind | None = None,
    orientation: ArrayLike | None = None,
    tool_axis: int = 2,
    planes: Sequence[int] = (1, 2, 3, 4),
    region: ArrayLike | None = None,
    center: ArrayLike | None = None,
    samples: int = 4000,
    candidates: int = 4,
    resolution: float = 2e-3,
    seed: int = 0,
) -> Cube:
    """The largest axis-aligned cube whose diagonal planes the tool reaches with a fixed orientation.

    The search has two stages.  (1) A seeded cloud of ``samples`` points in the
    workspace's bounding box (or ``region``) is classified reachable/unreachable by
    the IK; for each reachable sample the largest cube centred there that contains
    no unreachable sample gives a coarse estimate (this sees holes anywhere in the
    volume, at the cloud's spacing).  (2) For the ``candidates`` best, well-separated
    centres the side is maximised by bisection on IK reachability of check points (a
    5 x 5 grid on each diagonal plane in ``planes`` plus each plane's P1..P5), and the
    best centre is refined by a compass search (moves of the centre along ±x, ±y, ±z
    with halving steps, each with its own bisection on the side).

    Args:
        model: the robot.
        kind: orientation constraint of every check point: ``"pose"`` (position and the
            full ``orientation``, default for 6+ joints), ``"axis"`` (position and the
            direction of tool axis ``tool_axis``, default below 6 joints: a 5-DOF arm
            cannot hold a full orientation over a volume) or ``"position"``.
        orientation: ``(3, 3)`` fixed tool rotation in the base frame; default tool z
            down, tool x along base x (:data:`TOOL_DOWN`).
        tool_axis: tool axis imposed by ``kind="axis"`` (0, 1, 2 = x, y, z).
        planes: diagonal planes (1..4) whose check points must be reachable.
        region: ``(2, 3)`` lower/upper corners (m) of a box the cube must lie in, e.g.
            to keep it in front of the robot; default the workspace's bounding box
            (from 4000 random configurations).
        center: fix the centre ``(3,)`` (m) and maximise the side only.
        samples: size of the stage-1 point cloud.
        candidates: number of stage-1 centres refined in stage 2.
        resolution: side resolution (m) of the bisection; the centre search stops at
            steps of ``2 * resolution``.
        seed: seed of the point cloud and of the IK restarts.

    Returns:
        The cube (centre and side in m).
    """
    con = _constraint(model, kind, orientation, tool_axis)
    planes = tuple(_check_plane(p) for p in planes)
    if resolution <= 0:
        raise ValueError(f"resolution must be positive (m), got {resolution!r}")
    rng = np.random.default_rng(seed)
    unit = _check_points(planes, 5)
    P, dof = len(unit), model.dof
    reach = model.fk(random_configurations(model, 4000, rng))[:, :3, 3]
    box = np.array([reach.min(axis=0), reach.max(axis=0)])
    if region is not None:
        region = np.asarray(region, dtype=float)
        if region.shape != (2, 3) or np.any(region[0] > region[1]):
            raise ValueError(f"region must be (2, 3) lower/upper corners (m), got {region.tolist()!r}")
        box = np.array([np.maximum(box[0], region[0]), np.minimum(box[1], region[1])])
        if np.any(box[0] >= box[1]):
            raise ValueError(f"region {region.tolist()} does not overlap the workspace of {model.name!r}")
    if center is not None:
        centers = np.asarray(center, dtype=float).reshape(1, 3)
        ok, q_c = _solve(model, con, centers, None, restarts=20, seed=seed)
        if not ok[0]:
            raise ValueError(
                f"cube centre {centers[0].tolist()} m is not reachable by {model.name!r} "
                f"with the imposed tool orientation ({con.kind})"
            )
        hi = np.array([2.0 * float(np.minimum(centers[0] - box[0], box[1] - centers[0]).min())])
        if hi[0] <= 0:
            raise ValueError(f"cube centre {centers[0].tolist()} m lies outside the search box")
    else:
        cloud = box[0] + rng.random((int(samples), 3)) * (box[1] - box[0])
        ok, q_cloud = _solve(model, con, cloud, None, restarts=6, seed=seed)
        if not ok.any():
            raise ValueError(
                f"no reachable point found for {model.name!r} with the imposed tool orientation "
                f"({con.kind}); try kind='position' or another orientation"
            )
        spacing = float(np.prod(box[1] - box[0]) / samples) ** (1 / 3)
        half = _chebyshev_clearance(cloud[ok], cloud[~ok], box)
        order = np.argsort(-half)
        picked: list[int] = []
        for i in order:  # best centres, at least a coarse cube's half side apart
            if all(np.abs(cloud[ok][i] - cloud[ok][j]).max() > max(half[i], spacing) for j in picked):
                picked.append(int(i))
            if len(picked) == candidates:
                break
        centers = cloud[ok][picked]
        q_c = q_cloud[ok][picked]
        limit = 2.0 * np.minimum(centers - box[0], box[1] - centers).min(axis=1)
        hi = np.minimum(2.0 * half[picked] + 2.0 * spacing, limit)
    K = len(centers)
    seeds = np.repeat(q_c[:, None, :], P, axis=1)  # side 0: every check point is the centre
    sides, q_pts = _bisect_sides(model, con, unit, centers, seeds, np.zeros(K), hi, resolution, seed)
    best = int(np.argmax(sides))
    c, L, q_best = centers[best], float(sides[best]), q_pts[best]
    if center is None:  # compass search on the centre, bisection on the side at each trial
        step = max(L / 8, 2 * resolution)
        moves = np.vstack([np.eye(3), -np.eye(3)])
        while step >= 2 * resolution:
            # a cube moved by `step` and shrunk by 2 step lies inside the current one:
            # feasible in the workspace, and its check points start from the current ones
            trial = c + step * moves
            lo = max(L - 2 * step, 0.0)
            room = 2.0 * np.minimum(trial - box[0], box[1] - trial).min(axis=1)  # cube stays in box
            pts = (trial[:, None, :] + lo * (unit - 0.5)[None]).reshape(-1, 3)
            ok, q_t = _solve(model, con, pts, np.tile(q_best, (len(trial), 1)), 1, seed)
            ok = ok.reshape(len(trial), P).all(axis=1) & (room > lo)
            improved = False
            if ok.any():
                n_ok = int(ok.sum())
                s, q_s = _bisect_sides(
                    model,
                    con,
                    unit,
                    trial[ok],
                    q_t.reshape(len(trial), P, dof)[ok],
                    np.full(n_ok, lo),
                    np.minimum(room[ok], L + 2 * step),
                    resolution,
                    seed,
                )
                j = int(np.argmax(s))
                if s[j] > L + resolution:
                    c, L, q_best, improved = trial[ok][j], float(s[j]), q_s[j], True
            if not improved:
                step /= 2
    return Cube(c, L)


# ------------------------------------------------------------------------ ISO 9283 poses
@dataclass(frozen=True)
class PoseSet:
    """Joint configurations to measure, with what they were built for.

    Attributes:
        q: ``(n, dof)`` joint values (rad or m).
        positions: ``(n, 3)`` nominal tool positions (m) in the base frame.
        labels: ``(n,)`` one label per pose (``"P1"``..``"P5"``, ``"plane"``, ``"boundary"``, ``"point3"``).
        reachable: ``(n,)`` whether the IK reached each target.
        info: extra description (strings and numbers).
    """

    q: Array
    positions: Array
    labels: tuple[str, ...]
    reachable: NDArray[np.bool_]
    info: Mapping[str, object] = field(default_factory=dict)

    def __len__(self) -> int:
        return len(self.q)

    def to_measurements(self, metadata: Mapping[str, str] | None = None) -> Measurements:
        """A poses :class:`Measurements` (joint columns only)."""
        meta = {str(k): str(v) for k, v in (metadata or {}).items()}
        return Measurements(q=self.q, metadata=meta)


@dataclass(frozen=True)
class IsoPoses(PoseSet):
    """ISO 9283 poses P1..P5 plus their cube, plane and tool orientation."""

    cube: Cube | None = None
    plane: int = 1
    orientation: Array | None = None


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
    con = _constraint(model, kind, orientation, tool_axis)
    if cube is None:
        cube = largest_cube(model, kind=con.kind, orientation=con.R, tool_axis=tool_axis, seed=seed, **search)  # type: ignore[arg-type]
    points = cube.iso_points(plane, fraction)
    ok1, q1 = _solve(model, con, points[:1], None, restarts=20, seed=seed)
    ok, q = _solve(model, con, points[1:], np.repeat(q1, 4, axis=0), restarts=20, seed=seed)
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
    )


# ------------------------------------------------------------------------ random poses
def position_sigma_min(model: Model, q: ArrayLike, rows: Literal["position", "pose"] = "position") -> Array:
    """Smallest singular value ``(n,)`` of the joint Jacobian's position rows (m/rad).

    It is the smallest tool-point speed per unit joint rate over all directions of
    joint motion: zero at a singular configuration.  ``rows="pose"`` uses all six
    rows (mixing m/rad and rad/rad).
    """
    J = model.joint_jacobian(np.atleast_2d(np.asarray(q, dtype=float)))
    if rows == "position":
        J = J[:, :3]
    elif rows != "pose":
        raise ValueError(f"rows must be 'position' or 'pose', got {rows!r}")
    return np.linalg.svd(J, compute_uv=False)[:, -1]


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


# ------------------------------------------------------------------------ ordering
def order_all_joints_move(q: ArrayLike, start: int = 0) -> tuple[NDArray[np.intp], float]:
    """Order poses so that every joint moves between consecutive poses (seed 003 §3.4).

    Maximises the bottleneck ``min over consecutive pairs of min over joints |Δq_j|``:
    a greedy path from ``start`` (always to the unvisited pose whose smallest joint
    change is largest), then 2-opt segment reversals that remove the current
    bottleneck pair while every new pair is better, until none helps.

    Args:
        q: ``(n, dof)`` configurations (rad or m).
        start: index of the first pose.

    Returns:
        The order (indices into ``q``) and the achieved bottleneck (rad or m).
    """
    q = np.asarray(q, dtype=float)
    if q.ndim != 2:
        raise ValueError(f"configurations must be (n, dof), got shape {q.shape}")
    n = len(q)
    if n <= 1:
        return np.arange(n), float("inf")
    if not 0 <= start < n:
        raise ValueError(f"start index {start} out of range for {n} poses")
    S = np.abs(q[:, None, :] - q[None, :, :]).min(axis=2)  # (n, n) smallest joint change
    order = [start]
    free = np.ones(n, dtype=bool)
    free[start] = False
    for _ in range(n - 1):
        cand = np.flatnonzero(free)
        nxt = cand[np.argmax(S[order[-1], cand])]
        order.append(int(nxt))
        free[nxt] = False
    path = np.array(order)
    for _ in range(10 * n):
        edges = S[path[:-1], path[1:]]
        i = int(np.argmin(edges))  # bottleneck pair (path[i], path[i+1])
        worst = edges[i]
        best_gain, best_move = worst, None
        # reverse path[i+1 .. b]: new pairs (path[i], path[b]) and (path[i+1], path[b+1])
        b = np.arange(i + 1, n)
        first = S[path[i], path[b]]
        second = np.where(b + 1 < n, S[path[i + 1], path[np.minimum(b + 1, n - 1)]], np.inf)
        old = np.where(b + 1 < n, edges[np.minimum(b, n - 2)], np.inf)
        gain = np.minimum(first, second)
        valid = (gain > worst) & (np.minimum(gain, old) >= np.minimum(worst, old)) & (b > i + 1)
        if valid.any():
            k = int(np.argmax(np.where(valid, gain, -np.inf)))
            best_gain, best_move = gain[k], (i + 1, int(b[k]))
        # reverse path[a .. i]: new pairs (path[a-1], path[i]) and (path[a], path[i+1])
        a = np.arange(1, i + 1)  # the start stays first
        first = S[path[a - 1], path[i]]
        second = S[path[a], path[i + 1]]
        gain = np.minimum(first, second)
        valid = (gain > worst) & (a < i)
        if valid.any():
            k = int(np.argmax(np.where(valid, gain, -np.inf)))
            if gain[k] > best_gain:
                best_gain, best_move = gain[k], (int(a[k]), i)
        if best_move is None:
            break
        lo, hi = best_move
        new = path.copy()
        new[lo : hi + 1] = path[lo : hi + 1][::-1]
        if S[new[:-1], new[1:]].min() < worst:  # never make the bottleneck worse
            break
        path = new
    return path, float(S[path[:-1], path[1:]].min())


# ------------------------------------------------------------------------ thesis poses
def _ray_limits(
    model: Model, con: _Constraint, origin: Array, directions: Array, s_max: Array, seed: int
) -> Array:
    """Farthest reachable distance (m) from ``origin`` along each unit direction, by
    bisection on IK reachability (the first boundary crossing it brackets)."""
    lo, hi = np.zeros(len(directions)), np.asarray(s_max, dtype=float).copy()
    ok, q0 = _solve(model, con, origin[None], None, restarts=20, seed=seed)
    if not ok[0]:
        raise ValueError(f"ray origin {origin.tolist()} m is not reachable by {model.name!r}")
    seeds = np.repeat(q0, len(directions), axis=0)
    while True:
        todo = np.flatnonzero(hi - lo > 1e-3)
        if not len(todo):
            return lo
        mid = 0.5 * (lo[todo] + hi[todo])
        ok, q = _solve(model, con, origin + mid[:, None] * directions[todo], seeds[todo], 2, seed)
        lo[todo[ok]] = mid[ok]
        seeds[todo[ok]] = q[ok]
        hi[todo[~ok]] = mid[~ok]


def diagonal_plane_poses(
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
    con = _constraint(model, kind, orientation, tool_axis)
    planes = tuple(_check_plane(p) for p in planes)
    if not 0 < boundary_fraction <= 1:
        raise ValueError(f"boundary_fraction must be in (0, 1], got {boundary_fraction!r}")
    if cube is None:
        cube = largest_cube(
            model, kind=con.kind, orientation=con.R, tool_axis=tool_axis, region=region, seed=seed
        )
    rng = np.random.default_rng(seed)
    unit = _unique_rows(np.vstack([_unit_plane_grid(p, (grid, grid)) for p in planes]))
    centre_first = np.argsort(np.abs(unit - 0.5).sum(axis=1), kind="stable")
    lattice = cube.at(unit[centre_first])
    n_b = int(n) - len(lattice)
    if n_b < 0:
        raise ValueError(
            f"a {grid} x {grid} grid on {len(planes)} diagonal plane(s) has {len(lattice)} points, "
            f"more than n={n}; use a smaller grid"
        )
    points, labels = [lattice], ["plane"] * len(lattice)
    if n_b:
        dirs = []
        per_plane = -(-n_b // len(planes))
        for b in range(n_b):
            c = CUBE_CORNERS[list(DIAGONAL_PLANES[planes[b % len(planes)]])]
            e1 = (c[1] - c[0]) / np.linalg.norm(c[1] - c[0])
            e2 = (c[3] - c[0]) / np.linalg.norm(c[3] - c[0])
            phi = 2 * np.pi * ((b // len(planes)) + 0.5) / per_plane
            dirs.append(np.cos(phi) * e1 + np.sin(phi) * e2)
        dirs = np.array(dirs)
        reach = model.fk(random_configurations(model, 4000, rng))[:, :3, 3]
        bound = np.array([reach.min(axis=0), reach.max(axis=0)])
        if region is not None:
            region = np.asarray(region, dtype=float)
            bound = np.array([np.maximum(bound[0], region[0]), np.minimum(bound[1], region[1])])
        with np.errstate(divide="ignore", invalid="ignore"):  # distance to leave the box
            t = np.where(dirs > 0, (bound[1] - cube.center) / dirs, (bound[0] - cube.center) / dirs)
        s_max = np.nanmin(np.where(np.isfinite(t) & (t > 0), t, np.inf), axis=1)
        s = _ray_limits(model, con, cube.center, dirs, s_max, seed)
        points.append(cube.center + boundary_fraction * s[:, None] * dirs)
        labels += ["boundary"] * n_b
    pts = np.vstack(points)
    m = len(pts)
    starts = random_configurations(model, m * solutions, rng)
    res = solve_ik(
        model,
        con.targets(np.tile(pts, (solutions, 1))),
        kind=con.kind,
        q0=starts,
        restarts=2,
        seed=rng,
        tool_axis=tool_axis,
    )
    Q = res.q.reshape(solutions, m, model.dof)
    ok = res.reachable.reshape(solutions, m)
    sig = position_sigma_min(model, res.q).reshape(solutions, m)
    good = ok & (sig >= min_sigma)
    pref = np.where(good, 2, np.where(ok, 1, 0)) + rng.random((solutions, m))  # random among the best class
    pick = np.argmax(pref, axis=0)
    q = Q[pick, np.arange(m)]
    reachable = ok[pick, np.arange(m)]
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
            "well_conditioned": int(good[pick, np.arange(m)].sum()),
        },
    )


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
    con = _constraint(model, kind, orientation, tool_axis)
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


def read_poses(path: str | Path, model: Model | None = None, *, angle_unit: str = "rad") -> Array:
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
