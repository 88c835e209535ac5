"""A chain's structure compiled for batched evaluation, and its constant segment transforms.

The plan of a :class:`robocal.model.chain.Model` depends only on its steps' motions and which
of them are joints, so models that differ in values share one (cached by structure).
"""

from __future__ import annotations

import dataclasses
import functools
import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from robocal.model.steps import Step

__all__ = [
    "EYE4", "Plan", "check_perturbations", "check_q", "elementaries", "plan_of", "read_only", "segment_data"
]  # fmt: skip

Array = NDArray[np.float64]
EYE4 = np.eye(4)


@dataclass(frozen=True)
class Plan:
    """Structure of a chain, compiled once per model for batched evaluation."""

    joint_steps: NDArray[np.intp]  # (dof,) step index of each joint
    joint_axis: tuple[int, ...]  # local axis of each joint step
    joint_rot: tuple[bool, ...]  # revolute?
    anchor_of: NDArray[np.intp]  # (P,) anchor frame index of each step (0 = base, j+1 = after joint j)
    segments: tuple[tuple[int, ...], ...]  # constant steps after anchor a, for a = 0..dof
    step_axis: NDArray[np.intp]  # (P,)
    step_rot: NDArray[np.bool_]  # (P,)
    segment_table: NDArray[np.intp]  # (dof + 1, L) steps of each segment, padded with P (identity)
    segment_slot: NDArray[np.intp]  # (P,) flat index a * L + t of each constant step in the table
    joint_axis_array: NDArray[np.intp]  # (dof,) joint_axis for the compiled kernels
    joint_rot_array: NDArray[np.bool_]  # (dof,)
    step_joint: NDArray[np.bool_]  # (P,) is step i a joint step?


_PLANS: dict[tuple[tuple[str, bool], ...], Plan] = {}  # compiled plans by chain structure


def plan_of(steps: Sequence[Step]) -> Plan:
    """The (cached) plan of a chain of ``steps``."""
    structure = tuple((s.motion, s.joint is not None) for s in steps)
    plan = _PLANS.get(structure)
    if plan is None:
        if len(_PLANS) > 256:
            _PLANS.clear()
        plan = _PLANS[structure] = compile_plan(steps)
    return plan


def compile_plan(steps: Sequence[Step]) -> Plan:
    """The chain's structure for batched evaluation (it depends only on the steps'
    motions and which are joints, so models that differ in values share it)."""
    joint_steps = [i for i, s in enumerate(steps) if s.joint is not None]
    anchor_of = np.zeros(len(steps), dtype=np.intp)
    segments: list[list[int]] = [[]]
    anchor = 0
    for i, step in enumerate(steps):
        if step.joint is not None:
            anchor_of[i] = anchor  # a joint step hangs off the previous anchor's segment end
            anchor += 1
            segments.append([])
        else:
            anchor_of[i] = anchor
            segments[anchor].append(i)
    width = max(max(len(seg) for seg in segments), 1)
    table = np.full((len(segments), width), len(steps), dtype=np.intp)
    slot = np.zeros(len(steps), dtype=np.intp)
    for a, seg in enumerate(segments):
        table[a, : len(seg)] = seg
        slot[list(seg)] = a * width + np.arange(len(seg))
    return Plan(
        joint_steps=np.array(joint_steps, dtype=np.intp),
        joint_axis=tuple(steps[i].axis for i in joint_steps),
        joint_rot=tuple(steps[i].is_rotation for i in joint_steps),
        anchor_of=anchor_of,
        segments=tuple(tuple(s) for s in segments),
        step_axis=np.array([s.axis for s in steps], dtype=np.intp),
        step_rot=np.array([s.is_rotation for s in steps], dtype=bool),
        segment_table=table,
        segment_slot=slot,
        joint_axis_array=np.array([steps[i].axis for i in joint_steps], dtype=np.intp),
        joint_rot_array=np.array([steps[i].is_rotation for i in joint_steps], dtype=bool),
        step_joint=np.array([s.joint is not None for s in steps], dtype=bool),
    )


def segment_data(plan: Plan, values: Array) -> tuple[Array, Array]:
    """Constant segment transforms and each step's local frame for parameter ``values``.

    Returns:
        segment transforms ``C_a`` ``(dof + 1, 4, 4)`` (the product of the constant
        steps after anchor a, for a = 0..dof), and ``local`` ``(P, 4, 4)``: the frame
        just before step i expressed in its anchor frame.

    All segments at once: their elementary transforms in one padded table
    ``(dof + 1, L, 4, 4)`` (padding: identity), multiplied into running products by a
    Hillis-Steele prefix scan, log2(L) batched matrix products instead of one
    small product per step (this runs at every solver iteration).
    """
    E = np.empty((len(values) + 1, 4, 4))
    E[:-1] = elementaries(plan.step_axis, plan.step_rot, values)
    E[-1] = EYE4
    X = E[plan.segment_table]  # (dof + 1, L, 4, 4)
    width = X.shape[1]
    d = 1
    while d < width:  # X[:, t] <- X[:, t - d] X[:, t]: running products, earlier steps first
        X[:, d:] = np.matmul(X[:, :-d], X[:, d:])
        d *= 2
    seg_T = X[:, -1].copy()
    before = np.empty_like(X)  # product of the steps before each slot: shifted by one
    before[:, 0] = EYE4
    before[:, 1:] = X[:, :-1]
    local = np.empty((len(values), 4, 4))
    flat = before.reshape(-1, 4, 4)
    local[:] = flat[plan.segment_slot]
    local[plan.joint_steps] = seg_T[:-1]  # a joint step starts where the previous segment ends
    return seg_T, local


def elementaries(axis: NDArray[np.intp], rotation: NDArray[np.bool_], values: Array) -> Array:
    """The elementary 4x4 transforms of all steps at once, ``(P, 4, 4)``.

    Built with a few vectorised assignments instead of one small matrix per step,
    because a model's constant transforms are rebuilt at every solver iteration.
    """
    P = len(values)
    E = np.zeros((P, 4, 4))
    E[:, [0, 1, 2, 3], [0, 1, 2, 3]] = 1.0
    idx = np.arange(P)
    t = ~rotation
    E[idx[t], axis[t], 3] = values[t]
    r = idx[rotation]
    k = axis[rotation]
    i, j = (k + 1) % 3, (k + 2) % 3
    c, s = np.cos(values[rotation]), np.sin(values[rotation])
    E[r, i, i] = c
    E[r, j, j] = c
    E[r, i, j] = -s
    E[r, j, i] = s
    return E


def check_q(q: ArrayLike, model: Any) -> tuple[Array, bool]:
    """Joint values ``(n, dof)`` as floats and whether one configuration ``(dof,)`` was given;
    ValueError naming the shape or the first NaN/inf (pose, joint) when they do not fit
    ``model`` (:class:`~robocal.model.chain.Model`)."""
    dof = model.dof
    q = np.asarray(q, dtype=float)
    single = q.ndim == 1
    if single:
        q = q[None, :]
    if q.ndim != 2 or q.shape[1] != dof:
        raise ValueError(
            f"joint values shaped {q.shape if not single else q.shape[1:]} do not fit model "
            f"{model.name!r} with {dof} joints; expected (n, {dof})"
        )
    if not math.isfinite(float(q.sum())) and not np.isfinite(q).all():  # a finite sum: all finite
        bad = np.argwhere(~np.isfinite(q))[0]
        raise ValueError(f"joint values contain NaN/inf (pose {bad[0]}, joint {model.joint_names[bad[1]]})")
    return q, single


def check_perturbations(perturbations: ArrayLike | None, n: int, dof: int) -> Array | None:
    """Joint perturbations as floats ``(n, dof, 3)`` (a 2-D one for one pose), or None."""
    if perturbations is None:
        return None
    d = np.asarray(perturbations, dtype=float)
    if d.ndim == 2:
        d = d[None]
    if d.shape != (n, dof, 3):
        raise ValueError(f"joint perturbations shaped {d.shape}; expected ({n}, {dof}, 3)")
    return d


def read_only(a: NDArray) -> NDArray:
    """``a``, made read-only: an array a model caches and hands out (models are immutable)."""
    a.flags.writeable = False
    return a


@functools.cache
def _field_names(cls: type) -> tuple[str, ...]:
    """The dataclass ``cls``'s field names (``dataclasses.fields`` costs ~5 µs a call)."""
    return tuple(f.name for f in dataclasses.fields(cls))


def derived_copy(model: Any, steps: tuple, shared: tuple[str, ...], **changes: Any) -> Any:
    """A copy of the (frozen dataclass) ``model`` with other ``steps`` (and fields
    ``changes``) that the caller knows keep the chain's invariants — checked steps, unique
    names, bodies and joint effects on its own frames and joints (:func:`check_chain`) — so
    the copy skips ``__post_init__``; it keeps the ``shared`` cached properties of ``model``
    (its plan, names, index...) instead of working them out again (only for steps whose
    names, motions and joints are ``model``'s own).  The solvers derive several models per
    calibration."""
    cls: type = type(model)  # a class is hashable (mypy sees type[Any] otherwise)
    derived: Any = object.__new__(cls)
    own = model.__dict__
    # one pass over the fields and the shared properties (a cached property not yet worked
    # out is not in the dict); a field is always there
    fields = {name: own[name] for name in _copied_names(cls, shared) if name in own}
    fields["steps"] = steps
    if changes:
        fields.update(changes)
    derived.__dict__.update(fields)
    return derived


@functools.cache
def _copied_names(cls: type, shared: tuple[str, ...]) -> tuple[str, ...]:
    """The names :func:`derived_copy` copies: the dataclass ``cls``'s fields, then ``shared``."""
    return _field_names(cls) + tuple(name for name in shared if name not in _field_names(cls))


def with_free_values_copy(model: Any, x: Array, shared: tuple[str, ...]) -> Any:
    """:func:`derived_copy` of ``model`` whose free steps take the (checked, finite) values
    ``x`` ``(p,)``: only the free steps are copied, and the copy's ``values`` are ``model``'s
    with ``x`` written in (the floats its steps hold: no second pass over the steps)."""
    steps = list(model.steps)
    mask = model.free_mask
    new, set_ = object.__new__, object.__setattr__
    for i, v in zip(mask.nonzero()[0].tolist(), x.tolist(), strict=True):  # mask: 1-D
        fields = steps[i].__dict__.copy()  # Step._copy_with inline (some thirty steps a calibration)
        fields["value"] = v
        steps[i] = step = new(Step)
        set_(step, "__dict__", fields)
    derived = derived_copy(model, tuple(steps), shared)
    values = model.values.copy()
    values[mask] = x
    derived.__dict__["values"] = read_only(values)
    return derived


def with_free_copy(model: Any, at: list[int], free: bool, shared: tuple[str, ...]) -> Any:
    """:func:`derived_copy` of ``model`` with the steps ``at`` (indices) freed or fixed
    (``free``): only those copied; the copy's ``free_mask`` and ``free_names`` are
    ``model``'s with those flags changed (not worked out again from the steps)."""
    steps = list(model.steps)
    for i in at:
        steps[i] = steps[i]._with_free(free)
    derived = derived_copy(model, tuple(steps), shared)
    derived.__dict__["free_mask"], derived.__dict__["free_names"] = _flags(model, at, free)
    return derived


def _flags(model: Any, at: list[int], free: bool) -> tuple[NDArray[np.bool_], tuple[str, ...]]:
    """``model``'s free mask (read-only) and free names with the steps ``at`` freed or fixed."""
    mask = model.free_mask.copy()
    mask[at] = free
    return read_only(mask), tuple(itertools.compress(model.names, mask.tolist()))
