"""Pose sets to measure, planned once for ``robocal poses`` and the GUI's planning page.

:func:`plan_poses` runs the sequence both front ends need (random configurations, the
optimal subset of a seeded pool by an observability index, ISO 9283 P1..P5 on the largest
cube, the thesis' diagonal planes) and returns a :class:`PosePlan` holding the configurations,
the poses file's metadata and the lines a front end shows; it prints nothing.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from robocal.choices import TargetKind
from robocal.identify.observability_indices import INDICES, IndexName, identifiable_parameters, observability
from robocal.model.chain import Model

__all__ = ["PLAN_METHODS", "PosePlan", "plan_indices", "plan_poses"]

#: the planning methods (``robocal poses --method``)
PLAN_METHODS = ("random", "optimal", "iso9283", "diagonal")

PlanRows = Literal["position", "pose"]


@dataclass(frozen=True)
class PosePlan:
    """A planned pose set.

    Attributes:
        q: ``(n, dof)`` joint values in measuring order (rad / m).
        metadata: the poses file's header entries (robot, method, seed, index, cube ...).
        indices: the observability indices O1..O5 of the set (``optimal`` only; others:
            :func:`plan_indices`).
        reference: the same indices of the pool's first ``n`` (``optimal`` only).
        n_params: the identifiable parameters the indices are computed for (0: none computed).
        notes: lines for the user (the cube, the diagonal set's joint motion).
        not_identifiable: the parameters the pool cannot identify, with why (``optimal``).
    """

    q: NDArray[np.float64]
    metadata: dict[str, str]
    indices: dict[str, float] = field(default_factory=dict)
    reference: dict[str, float] = field(default_factory=dict)
    n_params: int = 0
    notes: tuple[str, ...] = ()
    not_identifiable: tuple[str, ...] = ()


def plan_poses(
    model: Model,
    method: str,
    n: int | None = None,
    *,
    seed: int = 0,
    index: IndexName = "O1",
    pool: int = 2000,
    rows: PlanRows = "position",
    kind: TargetKind | None = None,
    region: NDArray[np.float64] | None = None,
) -> PosePlan:
    """The poses ``robocal poses ROBOT --method METHOD`` writes.

    Args:
        model: the robot (nominal).
        method: one of :data:`PLAN_METHODS`.
        n: number of poses (None: 30 for random/optimal, 118 for diagonal; iso9283 gives 5).
        seed: seed of the random draws.
        index: the index ``optimal`` maximises.
        pool: random candidates ``optimal`` chooses from (>= n).
        rows: the quantities measured (position or pose rows of the Jacobian).
        kind: iso9283 / diagonal: the IK constraint (``position``, ``pose``, ``axis``).
        region: ``(2, 3)`` box (m, robot base) the cube must lie in, or None.

    Raises:
        ValueError: a method not known, a pool smaller than ``n``, unreachable poses.
    """
    meta = {"robot": model.name, "method": method, "seed": str(seed)}
    if method == "random":
        from robocal.measure.poses import random_poses

        return PosePlan(random_poses(model, n or 30, seed=seed), meta)
    if method == "optimal":
        return _optimal(model, n or 30, pool, index, rows, seed, meta)
    if method == "iso9283":
        return _iso9283(model, kind, region, seed, meta)
    if method == "diagonal":
        return _diagonal(model, n or 118, kind, region, seed, meta)
    raise ValueError(f"method {method!r}: one of {', '.join(PLAN_METHODS)}")


def plan_indices(model: Model, q: NDArray[np.float64], rows: PlanRows = "position") -> dict[str, float]:
    """O1..O5 of the pose set ``q`` over the parameters it identifies."""
    sub = identifiable_parameters(model, q, rows=rows)
    found = observability(model, q, rows=rows, params=sub.kept)
    return {k: float(found[k]) for k in INDICES}


def _optimal(
    model: Model, count: int, pool: int, index: IndexName, rows: PlanRows, seed: int, meta: dict[str, str]
) -> PosePlan:
    """``count`` poses of a seeded random pool maximising ``index`` (greedy and exchanges)."""
    from robocal.identify.pose_selection import select_poses
    from robocal.measure.poses import random_poses

    if pool < count:
        raise ValueError(f"a pool of {pool} candidates cannot give {count} poses; raise the pool")
    candidates = random_poses(model, pool, seed=seed)
    sub = identifiable_parameters(model, candidates, rows=rows)
    sel = select_poses(model, candidates, count, index=index, rows=rows, params=sub.kept)
    baseline = observability(model, candidates[:count], rows=rows, params=sel.params)
    meta = meta | {"index": index, "pool": str(pool), "value": repr(sel.value)}
    return PosePlan(
        sel.q, meta,
        indices={k: float(sel.indices_all[k]) for k in INDICES},
        reference={k: float(baseline[k]) for k in INDICES},
        n_params=len(sel.params), not_identifiable=tuple(str(d) for d in sub.dropped),
    )  # fmt: skip


def _iso9283(
    model: Model, kind: TargetKind | None, region: NDArray[np.float64] | None, seed: int, meta: dict[str, str]
) -> PosePlan:
    """ISO 9283 P1..P5 on the largest cube's diagonal plane C1-C2-C7-C8."""
    from robocal.measure.poses import iso9283_poses

    iso = iso9283_poses(model, kind=kind, seed=seed, region=region)
    c = iso.cube
    meta = meta | {"cube_center_mm": " ".join(f"{v * 1e3:.3f}" for v in c.center),
                   "cube_side_mm": f"{c.side * 1e3:.3f}"}  # fmt: skip
    note = (
        f"cube centre [{', '.join(f'{v * 1e3:.1f}' for v in c.center)}] mm, side {c.side * 1e3:.1f} mm, "
        f"plane C1-C2-C7-C8, constraint {iso.info['kind']}"
    )
    return PosePlan(iso.q, meta, notes=(note,))


def _diagonal(
    model: Model, n: int, kind: TargetKind | None, region: NDArray[np.float64] | None, seed: int,
    meta: dict[str, str],
) -> PosePlan:  # fmt: skip
    """The thesis' poses on the cube's diagonal planes and near the boundary (seed 003)."""
    from robocal.measure.diagonal_poses import diagonal_plane_poses

    ps = diagonal_plane_poses(model, n=n, kind=kind or "position", region=region, seed=seed)
    if not ps.reachable.all():
        raise ValueError(f"{int((~ps.reachable).sum())} of the diagonal-plane poses are not reachable")
    min_change_rad = ps.info["min_joint_change_rad"]
    assert isinstance(min_change_rad, float)  # diagonal_plane_poses' record
    note = (
        f"{len(ps.q)} poses ({ps.info['boundary_poses']} near the boundary), smallest joint change "
        f"between consecutive poses {math.degrees(min_change_rad):.1f} deg"
    )
    return PosePlan(ps.q, meta, notes=(note,))
