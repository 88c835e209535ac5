"""Pose planning for constraint measurements: which configurations to record at a socket,
on a plate or with a ball-bar (O1-O5 on each kind's own Jacobian).

The candidates satisfy the constraint on the nominal robot (the tool point in a socket, on
a plane, a pair a bar's length apart: :func:`robocal.measure.constraints.sim.simulate_constraints`
without noise).  A candidate's rows are those of
:class:`~robocal.identify.constraints.model.ConstraintProblem`
— the robot's parameters *and* the scene's unknowns (the socket's position, the plane), so
the information a pose brings is what is left after the scene is estimated with the robot
— over the identifiable set of the whole pool, each column scaled to a tool displacement.
Greedy construction: at each step, of the candidates with the largest D-optimal gain
(``log det(I + J_u M⁻¹ J_uᵀ)``) the one that maximises the chosen index.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from robocal.identify.constraints.fit import build_constraint_problem, identifiable
from robocal.identify.observability_indices import (
    INDICES,
    ObservabilityIndices,
    observability_indices,
    singular_values,
)
from robocal.measure.constraints.data_set import ConstraintSet
from robocal.model.chain import Model

__all__ = [
    "ConstraintPoseSelection",
    "greedy_blocks",
    "select_constraint_poses",
    "select_tilt_configurations",
]

Array = NDArray[np.float64]


@dataclass(frozen=True)
class ConstraintPoseSelection:
    """Chosen configurations and their observability.

    Attributes:
        data: the chosen configurations with their constraint labels (a plan to record).
        index: the index maximised; value: its value; indices: O1..O5 of the choice.
        baseline: O1..O5 of as many candidates taken in pool order (a random choice).
        params: the unknowns the indices are over (identifiable robot and scene unknowns).
    """

    data: ConstraintSet
    index: str
    value: float
    indices: ObservabilityIndices
    baseline: ObservabilityIndices
    params: tuple[str, ...]


def _units(pool: ConstraintSet) -> list[NDArray[np.intp]]:
    """The candidates: one pose for points and planes, one pair (two poses) for distances."""
    if len(pool.pairs):
        return [np.asarray(pair, dtype=np.intp) for pair in pool.pairs]
    return [np.array([i], dtype=np.intp) for i in range(pool.n)]


def _unit_rows(pool: ConstraintSet, units: list[NDArray[np.intp]]) -> list[NDArray[np.intp]]:
    """Each unit's rows in the problem's residual (points: 3 per pose, planes: 1, pairs: 1)."""
    if len(pool.pairs):
        return [np.array([k]) for k in range(len(units))]
    width = 3 if pool.n_points else 1
    return [np.arange(width * u[0], width * u[0] + width) for u in units]


def _subset(pool: ConstraintSet, units: list[NDArray[np.intp]], chosen: list[int]) -> ConstraintSet:
    rows = np.concatenate([units[k] for k in chosen])
    where = {int(r): i for i, r in enumerate(rows)}
    pairs = [[where[int(a)], where[int(b)]] for a, b in pool.pairs if int(a) in where]
    lengths = [float(pool.pair_length[k]) for k, (a, _) in enumerate(pool.pairs) if int(a) in where]
    return ConstraintSet(pool.q[rows], pool.point[rows], pool.plane[rows],
                         pairs=np.array(pairs, dtype=np.intp).reshape(-1, 2),
                         pair_length=np.array(lengths), point_pairs=pool.point_pairs,
                         point_length=pool.point_length,
                         known_planes=pool.known_planes, sigma=pool.sigma)  # fmt: skip


def select_constraint_poses(
    model: Model, pool: ConstraintSet, n: int, *, index: str = "O1", shortlist: int = 16
) -> ConstraintPoseSelection:
    """Choose ``n`` candidates (poses; pairs for distances) of ``pool`` maximising ``index``.

    Raises:
        ValueError: an unknown index, or ``n`` outside 1..candidates.
    """
    if index not in INDICES:
        raise ValueError(f"index must be one of {', '.join(INDICES)}, got {index!r}")
    units = _units(pool)
    if not 1 <= n <= len(units):
        raise ValueError(f"cannot choose {n} of {len(units)} candidates")
    problem = build_constraint_problem(model, pool)
    selection = identifiable(problem)
    problem = problem.fix(selection.dropped_names)
    J = problem.jacobian(problem.x0) * problem.free_scale
    extra = np.arange(sum(len(r) for r in _unit_rows(pool, units)), len(J))  # known distances: always in
    blocks = [J[r] for r in _unit_rows(pool, units)]
    chosen, indices, baseline = greedy_blocks(blocks, n, index, shortlist, base=J[extra])
    plan = _subset(pool, units, chosen)
    return ConstraintPoseSelection(plan, index, float(indices[index]), indices, baseline, problem.free_names)


def select_tilt_configurations(
    model: Model,
    pool: ConstraintSet,
    n: int,
    tilt_kinds: tuple[str, ...] = ("clearance", "backlash", "compliance"),
) -> ConstraintSet:
    """The tilt rows of ``n`` configurations of ``pool`` (inclinometer rows only) chosen
    greedily for the largest ``log det`` of the information (D-optimal, :func:`greedy_blocks`)
    on ``model``'s identifiable unknowns: the thesis' choice of configurations that flip
    one joint's moments at a time, made by the readings' own Jacobian.  Rows whose contact
    side is unknown (:func:`~robocal.identify.constraints.tilt_rows.unclear_contact`) are
    no candidates."""
    from robocal.identify.constraints.tilt_rows import unclear_contact

    if pool.kinds != ("tilt",):
        raise ValueError("select_tilt_configurations takes inclinometer rows only")
    pool = pool.select(~unclear_contact(model, pool))
    problem = build_constraint_problem(model, pool, tilt_kinds=tilt_kinds)
    problem = problem.fix(identifiable(problem).dropped_names)
    J = problem.jacobian(problem.x0) * problem.free_scale  # tilt rows only: the data's order
    config = np.unique(pool.q, axis=0, return_inverse=True)[1].reshape(-1)
    units = [np.flatnonzero(config == k) for k in range(int(config.max()) + 1)]
    if not 1 <= n <= len(units):
        raise ValueError(f"cannot choose {n} of {len(units)} configurations")
    chosen = greedy_blocks([J[u] for u in units], n)[0]
    return pool.select(np.isin(config, chosen))


def greedy_blocks(
    blocks: list[Array], n: int, index: str = "O1", shortlist: int = 16, base: Array | None = None
) -> tuple[list[int], ObservabilityIndices, ObservabilityIndices]:
    """Choose ``n`` of the candidates' row blocks (each ``(r_k, p)``, columns scaled alike):
    at each step, of the ``shortlist`` candidates with the largest D-optimal gain
    ``log det(I + J_k M⁻¹ J_kᵀ)`` the one that maximises ``index`` (O1: the gain itself).
    ``base``: rows always in (known distances).  Returns the chosen candidates in order,
    O1..O5 of the choice and of the first ``n`` candidates (a random choice's baseline)."""
    p = blocks[0].shape[1]
    base = np.zeros((0, p)) if base is None else base
    ridge = 1e-9 * float(np.mean([np.sum(b * b) for b in blocks]))
    M = ridge * np.eye(p) + base.T @ base
    chosen: list[int] = []
    free = np.ones(len(blocks), dtype=bool)
    for _ in range(n):
        Minv = np.linalg.inv(M)
        candidates = np.flatnonzero(free)
        gain = np.array(
            [
                np.linalg.slogdet(np.eye(len(blocks[k])) + blocks[k] @ Minv @ blocks[k].T)[1]
                for k in candidates
            ]
        )
        best = candidates[np.argsort(gain)[::-1][: max(shortlist, 1)]]
        if index != "O1":
            scores = [
                _index(np.vstack([base, *[blocks[c] for c in chosen], blocks[k]]), len(chosen) + 1, p)[index]
                for k in best
            ]
            best = best[np.argsort(scores)[::-1]]
        k = int(best[0])
        chosen.append(k)
        free[k] = False
        M = M + blocks[k].T @ blocks[k]
    indices = _index(np.vstack([base, *[blocks[k] for k in chosen]]), n, p)
    baseline = _index(np.vstack([base, *blocks[:n]]), n, p)
    return chosen, indices, baseline


def _index(J: Array, n: int, p: int) -> ObservabilityIndices:
    return observability_indices(singular_values(J), n, p)
