"""The controller's own solutions for a file of Cartesian targets, in one configuration.

A file of targets is one program: the robot goes from one to the next, and a wrist or elbow
flip between neighbours is never intended.  :func:`nominal_solutions` solves the nominal
model's IK for every target from one reference configuration — ``q0`` (``--q0``) or the
first target's solution — chains a target not reached from it on the previous target's
solution, and then holds every solution in the reference's configuration
(:func:`robocal.compensate.safety.same_configuration`: front/back, elbow, wrist side),
solving again from starts in it.  A target reachable only in another configuration is
refused when the user chose the configuration (``q0``) and keeps it otherwise.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from robocal.choices import TargetKind
from robocal.compensate import safety
from robocal.compensate.ik_options import IKOptions
from robocal.measure.ik import IKResult, solve_ik
from robocal.model.chain import Model

__all__ = ["hold_configuration", "nominal_solutions"]

Array = NDArray[np.float64]


def nominal_solutions(
    model: Model, T: Array, q0: ArrayLike | None, options: IKOptions, kind: TargetKind
) -> tuple[IKResult, tuple[str, ...]]:
    """The nominal IK of targets ``T`` ``(n, 4, 4)`` of ``kind`` in one configuration, and
    per target why its nominal command is refused (empty: it is not); ``q0``: ``(dof,)`` the
    chosen configuration, ``(n, dof)`` one start per target, or None; ``options``: the IK's
    settings (its ``restarts`` here only)."""
    ik, restarts = options.solve_ik_keywords(kind), options.restarts
    asked = q0 is not None and np.asarray(q0).ndim == 1  # the user chose the configuration
    if q0 is None and len(T) > 1:
        q0, nom = _reference(model, T, restarts, ik)
    else:
        nom = solve_ik(model, T, q0=q0, restarts=0, **ik)
    nom = _chained(model, T, nom, restarts, ik)
    if q0 is None or np.asarray(q0).ndim != 1:
        return nom, ()
    nom, held = hold_configuration(model, T, nom, np.asarray(q0, dtype=float), ik)
    return nom, (held if asked else ())


#: random starts for the first target's other solutions, tried as the file's configuration
#: when ``q0`` is not given
REFERENCE_TRIES = 8


def _reference(model: Model, T: Array, restarts: int, ik: dict[str, Any]) -> tuple[Array, IKResult]:
    """The file's configuration when the user gave none, and every target solved from it:
    among the first target's solutions in different configurations (the IK's own, and from
    :data:`REFERENCE_TRIES` random starts), the one from which the most targets are solved
    in that configuration (joint limits can keep the others out of the first solution
    found, e.g. a PUMA 560's); for tool frames only."""
    first = solve_ik(model, T[:1], q0=None, restarts=restarts, **ik)

    def solved(c: Array) -> tuple[Array, IKResult, int]:
        res = solve_ik(model, T, q0=c, restarts=0, **ik)
        return c, res, int(np.sum(res.reachable & safety.same_configuration(model, res.q, c)))

    own = solved(first.q[0])
    if ik.get("kind") != "pose" or not first.reachable[0] or own[2] == len(T):
        # the IK's own choice: it holds them all, or the targets leave the orientation free
        # (position or axis targets: a correction may then drift along the free rotations)
        return own[0], own[1]
    lim = np.clip(model.joint_limits, -np.pi, np.pi)
    starts = np.random.default_rng(0).uniform(lim[:, 0], lim[:, 1], (REFERENCE_TRIES, model.dof))
    others = solve_ik(model, np.repeat(T[:1], REFERENCE_TRIES, axis=0), q0=starts, restarts=0, **ik)
    candidates = [own]
    for q, ok in zip(others.q, others.reachable, strict=True):
        if ok and not any(safety.same_configuration(model, q[None], c[0])[0] for c in candidates):
            candidates.append(solved(q))
    best = max(candidates, key=lambda c: c[2])  # the first of equals: the IK's own first choice
    return best[0], best[1]


def _chained(model: Model, T: Array, nom: IKResult, restarts: int, ik: dict[str, Any]) -> IKResult:
    """Targets not reached from the common start: each from the solution of the previous
    target reached (in file order, the configuration the robot comes from), then restarts."""
    q, ok = nom.q.copy(), nom.reachable.copy()
    for i in np.flatnonzero(~ok):
        before = np.flatnonzero(ok[:i])
        if len(before):
            one = solve_ik(model, T[i : i + 1], q0=q[before[-1]], restarts=0, **ik)
            q[i], ok[i] = one.q[0], one.reachable[0]
    todo = np.flatnonzero(~ok)
    if len(todo) and restarts:
        more = solve_ik(model, T[todo], q0=q[todo], restarts=restarts, **ik)
        q[todo], ok[todo] = more.q, more.reachable
    return dataclasses.replace(nom, q=q, reachable=ok)


def hold_configuration(
    model: Model, T: Array, nom: IKResult, q_ref: Array, ik: dict[str, Any]
) -> tuple[IKResult, tuple[str, ...]]:
    """Every nominal solution in ``q_ref``'s configuration (``--q0`` or the first target's):
    a target the local IK solved in another one is solved again from the previous target in
    the configuration, from ``q_ref`` and from starts scattered about it; one that stays in
    another configuration gets its reason (refused: the file asked for one configuration)."""
    q, reached = nom.q.copy(), nom.reachable
    ok = reached & safety.same_configuration(model, q, q_ref)
    rng = np.random.default_rng(0)
    for i in np.flatnonzero(reached & ~ok):
        previous = [q[j] for j in np.flatnonzero(ok[:i])[-1:]]
        starts = (*previous, q_ref, *(q_ref + rng.normal(0.0, 0.3, (6, model.dof))))
        tries: list[tuple[Array | None, int, int]] = [(s, 0, 0) for s in starts]
        # then the IK's own starts (the pool's nearest tool frames, random ones) under other seeds
        tries += [(None, 4, k) for k in range(8)]
        for start, restarts, seed in tries:
            one = solve_ik(model, T[i : i + 1], q0=start, restarts=restarts, **(ik | {"seed": seed}))
            if one.reachable[0] and safety.same_configuration(model, one.q, q_ref)[0]:
                q[i], ok[i] = one.q[0], True
                break
    wanted, found = safety.configurations(model, q_ref[None])[0], safety.configurations(model, q)
    reasons = tuple(
        "" if ok[i] or not reached[i] else (
            f"reachable by the controller's model only in configuration {found[i]}, "
            f"not the file's {wanted} (--q0 or the first target)"
        )
        for i in range(len(T))
    )  # fmt: skip
    return dataclasses.replace(nom, q=q), reasons
