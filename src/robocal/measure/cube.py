"""The ISO 9283 test cube: the largest cube of the workspace and its diagonal planes.

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

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from robocal import spatial
from robocal.measure.ik import solve_ik
from robocal.measure.ik_starts import TargetKind, random_configurations
from robocal.model.chain import Model

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


def check_plane(plane: int) -> int:
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
        return self.corners[list(DIAGONAL_PLANES[check_plane(plane)])]

    def plane_points(self, plane: int = 1, shape: tuple[int, int] = (5, 5)) -> Array:
        """``(a*b, 3)`` grid on a diagonal plane (m), ``shape = (a, b)`` points along
        the plane's first edge (a cube edge) and its second edge (a face diagonal)."""
        return self.at(unit_plane_grid(plane, shape))

    def iso_points(self, plane: int = 1, fraction: float = 0.1) -> Array:
        """``(5, 3)`` ISO 9283 positions P1..P5 on a diagonal plane (m).

        P1 is the cube's centre; P2..P5 lie on the plane's diagonals at ``fraction``
        (ISO 9283: 0.10 ± 0.02) of the diagonal's length from the plane's corners.
        """
        return self.at(_unit_iso_points(plane, fraction))


def unit_plane_grid(plane: int, shape: tuple[int, int]) -> Array:
    a, b = (int(v) for v in shape)
    if a < 2 or b < 2:
        raise ValueError(f"plane grid shape must be at least (2, 2), got {shape!r}")
    c = CUBE_CORNERS[list(DIAGONAL_PLANES[check_plane(plane)])]
    s, t = np.meshgrid(np.linspace(0, 1, a), np.linspace(0, 1, b), indexing="ij")
    s, t = s.reshape(-1, 1), t.reshape(-1, 1)
    # bilinear map of the rectangle c0 -> c1 (edge) and c0 -> c3 (face diagonal)
    return c[0] + s * (c[1] - c[0]) + t * (c[3] - c[0])


def _unit_iso_points(plane: int, fraction: float) -> Array:
    if not 0 < fraction < 0.5:
        raise ValueError(f"ISO 9283 fraction of the diagonal must be in (0, 0.5), got {fraction!r}")
    c = CUBE_CORNERS[list(DIAGONAL_PLANES[check_plane(plane)])]
    opposite = c[[2, 3, 0, 1]]  # the diagonals are c0-c2 and c1-c3
    return np.vstack([[0.5, 0.5, 0.5], c + fraction * (opposite - c)])


def unique_rows(points: Array, decimals: int = 9) -> Array:
    _, first = np.unique(np.round(points, decimals), axis=0, return_index=True)
    return points[np.sort(first)]


def _check_points(planes: Sequence[int], grid: int, fraction: float = 0.1) -> Array:
    """Unit-cube check points: a grid x grid lattice on each plane plus its P1..P5."""
    pts = [unit_plane_grid(p, (grid, grid)) for p in planes]
    pts += [_unit_iso_points(p, fraction) for p in planes]
    return unique_rows(np.vstack(pts))


def _frames(points: Array, R: Array) -> Array:
    return spatial.homogeneous(np.broadcast_to(R, (len(points), 3, 3)), points)


@dataclass(frozen=True)
class Constraint:
    kind: TargetKind
    R: Array
    tool_axis: int

    def targets(self, points: Array) -> Array:
        return points if self.kind == "position" else _frames(points, self.R)


def constraint(
    model: Model, kind: TargetKind | None, orientation: ArrayLike | None, tool_axis: int
) -> Constraint:
    if kind is None:
        kind = "pose" if model.dof >= 6 else "axis"
    if kind not in ("position", "pose", "axis"):
        raise ValueError(f"kind must be 'position', 'pose' or 'axis', got {kind!r}")
    R = TOOL_DOWN if orientation is None else np.asarray(orientation, dtype=float)
    if R.shape != (3, 3) or not np.allclose(R @ R.T, np.eye(3), atol=1e-6) or np.linalg.det(R) < 0:
        raise ValueError(f"orientation must be a 3x3 rotation matrix, got {np.asarray(orientation)!r}")
    return Constraint(kind, R, tool_axis)


def solve(
    model: Model, con: Constraint, points: Array, q0: Array | None, restarts: int, seed: int
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
    con: Constraint,
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
        reached, q = solve(model, con, pts, seeds[todo].reshape(-1, dof), restarts=1, seed=seed)
        ok = np.all(reached.reshape(len(todo), P), axis=1)  # every check point reached
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


def largest_cube(  # noqa: PLR0913 - keyword-only search options of a public function
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
    con = constraint(model, kind, orientation, tool_axis)
    planes = tuple(check_plane(p) for p in planes)
    if resolution <= 0:
        raise ValueError(f"resolution must be positive (m), got {resolution!r}")
    rng = np.random.default_rng(seed)
    unit = _check_points(planes, 5)
    box = _search_box(model, region, rng)
    if center is not None:
        centers, q_c, hi = _fixed_centre(model, con, box, center, seed)
    else:
        centers, q_c, hi = _cloud_candidates(model, con, box, int(samples), candidates, rng, seed)
    seeds = np.repeat(q_c[:, None, :], len(unit), axis=1)  # side 0: every check point is the centre
    sides, q_pts = _bisect_sides(
        model, con, unit, centers, seeds, np.zeros(len(centers)), hi, resolution, seed
    )
    best = int(np.argmax(sides))
    if center is not None:
        return Cube(centers[best], float(sides[best]))
    return _compass_search(
        model, con, unit, box, (centers[best], float(sides[best]), q_pts[best]), resolution, seed
    )


def _search_box(model: Model, region: ArrayLike | None, rng: np.random.Generator) -> Array:
    """``(2, 3)`` corners (m) of the workspace's bounding box, cut to ``region``."""
    reach = model.fk(random_configurations(model, 4000, rng))[:, :3, 3]
    box = np.array([reach.min(axis=0), reach.max(axis=0)])
    if region is None:
        return box
    region = np.asarray(region, dtype=float)
    if region.shape != (2, 3) or np.any(region[0] > region[1]):
        raise ValueError(f"region must be (2, 3) lower/upper corners (m), got {region.tolist()!r}")
    box = np.array([np.maximum(box[0], region[0]), np.minimum(box[1], region[1])])
    if np.any(box[0] >= box[1]):
        raise ValueError(f"region {region.tolist()} does not overlap the workspace of {model.name!r}")
    return box


def _fixed_centre(
    model: Model, con: Constraint, box: Array, center: ArrayLike, seed: int
) -> tuple[Array, Array, Array]:
    """The given centre ``(1, 3)``, its configuration ``(1, dof)`` and the side's upper bound ``(1,)``."""
    centers = np.asarray(center, dtype=float).reshape(1, 3)
    ok, q_c = solve(model, con, centers, None, restarts=20, seed=seed)
    if not ok[0]:
        raise ValueError(
            f"cube centre {centers[0].tolist()} m is not reachable by {model.name!r} "
            f"with the imposed tool orientation ({con.kind})"
        )
    hi = np.array([2.0 * float(np.minimum(centers[0] - box[0], box[1] - centers[0]).min())])
    if hi[0] <= 0:
        raise ValueError(f"cube centre {centers[0].tolist()} m lies outside the search box")
    return centers, q_c, hi


def _cloud_candidates(
    model: Model,
    con: Constraint,
    box: Array,
    samples: int,
    candidates: int,
    rng: np.random.Generator,
    seed: int,
) -> tuple[Array, Array, Array]:
    """Stage 1: the best well-separated centres ``(K, 3)`` of a reachability point cloud, their
    configurations ``(K, dof)`` and upper bounds of their sides ``(K,)`` (m)."""
    cloud = box[0] + rng.random((samples, 3)) * (box[1] - box[0])
    ok, q_cloud = solve(model, con, cloud, None, restarts=6, seed=seed)
    if not ok.any():
        raise ValueError(
            f"no reachable point found for {model.name!r} with the imposed tool orientation "
            f"({con.kind}); try kind='position' or another orientation"
        )
    spacing = float(np.prod(box[1] - box[0]) / samples) ** (1 / 3)
    half = _chebyshev_clearance(cloud[ok], cloud[~ok], box)
    picked: list[int] = []
    for i in np.argsort(-half):  # best centres, at least a coarse cube's half side apart
        if all(np.abs(cloud[ok][i] - cloud[ok][j]).max() > max(half[i], spacing) for j in picked):
            picked.append(int(i))
        if len(picked) == candidates:
            break
    centers = cloud[ok][picked]
    limit = 2.0 * np.minimum(centers - box[0], box[1] - centers).min(axis=1)
    return centers, q_cloud[ok][picked], np.minimum(2.0 * half[picked] + 2.0 * spacing, limit)


def _compass_search(
    model: Model,
    con: Constraint,
    unit: Array,
    box: Array,
    start: tuple[Array, float, Array],
    resolution: float,
    seed: int,
) -> Cube:
    """Stage 2's centre refinement: compass moves of the centre ``c`` (side ``L``, check-point
    configurations ``q_best``), a bisection on the side at each trial."""
    c, L, q_best = start
    P, dof = len(unit), model.dof
    step = max(L / 8, 2 * resolution)
    moves = np.vstack([np.eye(3), -np.eye(3)])
    while step >= 2 * resolution:
        # a cube moved by `step` and shrunk by 2 step lies inside the current one:
        # feasible in the workspace, and its check points start from the current ones
        trial = c + step * moves
        lo = max(L - 2 * step, 0.0)
        room = 2.0 * np.minimum(trial - box[0], box[1] - trial).min(axis=1)  # cube stays in box
        pts = (trial[:, None, :] + lo * (unit - 0.5)[None]).reshape(-1, 3)
        ok, q_t = solve(model, con, pts, np.tile(q_best, (len(trial), 1)), 1, seed)
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
