"""Joint effects the tilt rows cannot tell apart are held together, not folded into one.

When the pruning finds a joint effect poorly identifiable (its σ as a tool displacement
beyond the thresholds, :func:`robocal.identify.stages.poorly_identifiable`), fixing it
alone and refitting moves what it carried onto its partners: three clearances of parallel
joints whose sum only is seen end up as one clearance equal to the sum (on the thesis'
Katana with joint-frame sensors, ``clearance_q3`` 0.056° ± 0.0006° against 0.017°:
67σ off, an invented number).  :func:`poorly_separated` therefore names every joint
effect that takes part in a poorly determined combination with it; the fit holds them all
at their start values (zero) and reports each as not identifiable, naming the others.

The combinations are the eigenvectors of the joint effects' covariance in the pruning's
units (σ times the tool displacement per unit, m²) whose standard deviation is beyond the
pruning's absolute threshold; an effect loading such a vector by more than
:data:`LOADING` of its length is a member.

The geometry first: when the worst unknown is a parameter of the chain and its poorly
determined combination holds joint effects, the *effects* are held and the chain's
parameter stays free (:func:`geometry_partners`).  A clearance whose bending moment keeps
one side at every row turns its link as a fixed tilt of the joint's axis does (a UR10's
parallel joints under gravity: ``clearance_shoulder_lift``, ``clearance_elbow`` and
``clearance_wrist_1`` lie within 0.0006 of a unit column of the geometry's span, with
``alpha1``); holding ``alpha1`` instead left the geometry without the tilt it needs
(0.0093° RMS against 0.001° noise), the clearances held beside it.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from robocal.model.joints import effect_of
from robocal.model.rank import Dropped

__all__ = ["LOADING", "geometry_partners", "group_dropped", "held_for", "held_groups", "poorly_separated"]

Array = NDArray[np.float64]
#: a member's share of a poorly determined combination (a unit vector's component)
LOADING = 0.2


def poorly_separated(
    names: list[str] | tuple[str, ...], worst: int, cov: Array, scale: Array, max_std: float
) -> list[int]:
    """The indices (into ``names``) held with ``names[worst]``: itself and, when it is a
    joint effect, the other joint effects that share a poorly determined combination with
    it (module docstring).  ``cov`` ``(p, p)``: the fit's covariance; ``scale`` ``(p,)``:
    each unknown's tool displacement per unit (m); ``max_std``: the pruning's threshold (m)."""
    if effect_of(names[worst]) is None:
        return [worst]
    effects = [k for k, n in enumerate(names) if effect_of(n) is not None]
    s = scale[effects]
    block = cov[np.ix_(effects, effects)] * np.outer(s, s)
    values, vectors = np.linalg.eigh(block)
    me = effects.index(worst)
    group = {me}
    for value, v in zip(values, vectors.T, strict=True):
        if np.sqrt(max(value, 0.0)) > max_std and abs(v[me]) > LOADING:
            group |= set(np.flatnonzero(np.abs(v) > LOADING).tolist())
    return sorted(effects[k] for k in group)


def geometry_partners(
    names: list[str] | tuple[str, ...], worst: int, cov: Array, scale: Array, max_std: float,
    robot: NDArray[np.bool_] | None = None,
) -> list[int]:  # fmt: skip
    """The joint effects (indices into ``names``) sharing a poorly determined combination
    with the chain's parameter ``names[worst]`` (the covariance ``cov`` of the unknowns
    ``robot`` marks, None: all, in the pruning's units as :func:`poorly_separated`); empty
    when ``names[worst]`` is a joint effect or none does."""
    if effect_of(names[worst]) is not None:
        return []
    rows = np.arange(len(names)) if robot is None else np.flatnonzero(robot)
    if worst not in rows or not any(effect_of(names[k]) is not None for k in rows):
        return []
    s = scale[rows]
    values, vectors = np.linalg.eigh(cov[np.ix_(rows, rows)] * np.outer(s, s))
    me = int(np.flatnonzero(rows == worst)[0])
    out: set[int] = set()
    for value, v in zip(values, vectors.T, strict=True):
        if np.sqrt(max(value, 0.0)) > max_std and abs(v[me]) > LOADING:
            out |= {int(rows[k]) for k in np.flatnonzero(np.abs(v) > LOADING) if effect_of(names[rows[k]])}
    return sorted(out)


def held_for(
    names: list[str], worst: int, sigma: float, cov: Array, scale: Array, max_std: float,
    robot: NDArray[np.bool_] | None = None, hints: dict[str, str] | None = None,
) -> tuple[list[int], list[Dropped]]:  # fmt: skip
    """What the pruning holds for its worst unknown ``names[worst]`` (σ ``sigma``, m) and
    the records saying so: the joint effects it trades with when it is the chain's
    (:func:`geometry_partners`: the geometry stays free), else it with the effects it
    cannot be told from (:func:`poorly_separated`).  ``hints``: a sentence per effect
    name saying what poses would separate it
    (:func:`~robocal.identify.constraints.tilt_rows.fixed_tilt_hints`)."""
    partners = geometry_partners(names, worst, cov, scale, max_std, robot)
    if not partners:
        held = poorly_separated(names, worst, cov, scale, max_std)
        return held, group_dropped(names, held, sigma, hints)
    out = []
    for k in partners:
        detail = (
            f"trades against {names[worst]} (the geometry, kept): the rows determine their combination, "
            "not the joint effect; held at zero rather than taking the geometry's value"
        )
        own = float(np.sqrt(max(cov[k, k], 0.0)) * scale[k])
        hint = (hints or {}).get(names[k])
        detail += f"; {hint}" if hint else ""
        out.append(Dropped(names[k], "poorly identifiable", sigma=own, detail=detail))
    return partners, out


def group_dropped(
    names: list[str], members: list[int], sigma: float, hints: dict[str, str] | None = None
) -> list[Dropped]:
    """The :class:`Dropped` records of a group held together (each names the others; a
    member's ``hints`` sentence, what poses would separate it, added)."""
    hints = hints or {}
    if len(members) == 1:
        hint = hints.get(names[members[0]])
        return [Dropped(names[members[0]], "poorly identifiable", sigma=sigma, detail=hint or "")]
    out = []
    for k in members:
        others = ", ".join(names[j] for j in members if j != k)
        detail = (
            f"cannot be told apart from {others}: the rows determine a combination of them, not each; "
            "all held at zero rather than one of them taking the combination's value"
        )
        hint = hints.get(names[k])
        detail += f"; {hint}" if hint else ""
        out.append(Dropped(names[k], "poorly identifiable", sigma=sigma, detail=detail))
    return out


def held_groups(
    names: list[str], found: list[tuple[int, float]], cov: Array | None, scale: Array, max_std: float,
    robot: NDArray[np.bool_] | None = None, hints: dict[str, str] | None = None,
) -> list[Dropped]:  # fmt: skip
    """The unknowns screened out before a fit (``found``: ``(index, σ in m)``), each joint
    effect with its partners (:func:`poorly_separated` on ``cov``, the covariance at the
    start; groups that share a member merged), a chain's parameter that trades with joint
    effects by those effects instead (:func:`held_for`: the geometry first), as
    :class:`Dropped` records."""
    groups: list[tuple[set[int], float]] = []
    traded: dict[str, Dropped] = {}
    for index, sigma in found:
        if cov is not None and geometry_partners(names, index, cov, scale, max_std, robot):
            traded |= {d.name: d for d in held_for(names, index, sigma, cov, scale, max_std, robot, hints)[1]}
            continue
        members = {index} if cov is None else set(poorly_separated(names, index, cov, scale, max_std))
        joined = [g for g in groups if g[0] & members]
        for g in joined:
            groups.remove(g)
            members |= g[0]
        groups.append((members, max([sigma, *(g[1] for g in joined)])))
    out = [d for members, sigma in groups for d in group_dropped(names, sorted(members), sigma, hints)]
    held = {d.name for d in out}
    return out + [d for name, d in traded.items() if name not in held]
