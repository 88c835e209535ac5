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
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from robocal.model.joints import effect_of
from robocal.model.rank import Dropped

__all__ = ["LOADING", "group_dropped", "held_groups", "poorly_separated"]

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


def group_dropped(names: list[str], members: list[int], sigma: float) -> list[Dropped]:
    """The :class:`Dropped` records of a group held together (each names the others)."""
    if len(members) == 1:
        return [Dropped(names[members[0]], "poorly identifiable", sigma=sigma)]
    out = []
    for k in members:
        others = ", ".join(names[j] for j in members if j != k)
        detail = (
            f"cannot be told apart from {others}: the rows determine a combination of them, not each; "
            "all held at zero rather than one of them taking the combination's value"
        )
        out.append(Dropped(names[k], "poorly identifiable", sigma=sigma, detail=detail))
    return out


def held_groups(
    names: list[str], found: list[tuple[int, float]], cov: Array | None, scale: Array, max_std: float
) -> list[Dropped]:
    """The unknowns screened out before a fit (``found``: ``(index, σ in m)``), each joint
    effect with its partners (:func:`poorly_separated` on ``cov``, the covariance at the
    start; groups that share a member merged), as :class:`Dropped` records."""
    groups: list[tuple[set[int], float]] = []
    for index, sigma in found:
        members = {index} if cov is None else set(poorly_separated(names, index, cov, scale, max_std))
        joined = [g for g in groups if g[0] & members]
        for g in joined:
            groups.remove(g)
            members |= g[0]
        groups.append((members, max([sigma, *(g[1] for g in joined)])))
    return [d for members, sigma in groups for d in group_dropped(names, sorted(members), sigma)]
