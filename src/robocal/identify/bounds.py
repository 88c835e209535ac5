"""Bounds of ``method="bounded"`` (seed 001: ±5 mm on lengths, ±2° on angles around the
nominal robot parameters), widened for parameters that absorb redundant ones, and which
parameters ended at a bound.  Units: SI (m, rad)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from robocal.identify.problem import Problem
from robocal.model.chain import Model
from robocal.model.rank import Dropped

__all__ = ["AT_BOUND_TOLERANCE", "bounded_method_bounds", "default_bounds", "parameters_at_bounds"]

Array = NDArray[np.float64]

#: a parameter is at a bound when it is within this fraction of the bounds' width of it
AT_BOUND_TOLERANCE = 1e-6

#: Seed 001's bounds around the nominal robot parameters: ±5 mm on lengths, ±2° on angles.
SEED001_LENGTH_BOUND = 5e-3
SEED001_ANGLE_BOUND = math.radians(2.0)


def _widen_for_absorbed(
    lo: Array,
    hi: Array,
    names: Sequence[str],
    dropped: Sequence[Dropped],
    chain: Model,
    length: float,
    robot: set[str],
    length_bound: float = SEED001_LENGTH_BOUND,
    angle_bound: float = SEED001_ANGLE_BOUND,
) -> tuple[Array, Array]:
    """Seed 001's bounds of the kept parameters widened by those of the redundant
    parameters they absorb: with d3 dropped, d2 carries d2 + d3 and may need ±10 mm
    (the coefficients of ``absorbed_by`` are in tool-displacement units, rotations times
    the robot's ``length``)."""
    rotation = {s.name: s.is_rotation for s in chain.steps}
    scale = {n: length if rotation.get(n, False) else 1.0 for n in rotation}
    index = {n: k for k, n in enumerate(names)}
    lo, hi = lo.copy(), hi.copy()
    for d in dropped:
        if d.reason != "redundant" or d.name not in robot:
            continue
        width = (angle_bound if rotation.get(d.name, False) else length_bound) * scale[d.name]
        for name, coefficient in d.absorbed_by:
            k = index.get(name)
            if k is not None and name in robot and np.isfinite(lo[k]):
                extra = abs(coefficient) * width / scale[name]
                lo[k], hi[k] = lo[k] - extra, hi[k] + extra
    return lo, hi


def default_bounds(
    names: Sequence[str],
    rotation: Sequence[bool],
    nominal: Array,
    length: float = SEED001_LENGTH_BOUND,
    angle: float = SEED001_ANGLE_BOUND,
    robot: set[str] | None = None,
) -> tuple[Array, Array]:
    """Seed 001's bounds: ±5 mm on lengths and ±2° on angles around the nominal robot
    parameters (those in ``robot``, default: all but ``frame_*``/``tcp_*``); the device
    frame, the tool and effect coefficients are left free."""
    lo, hi = np.full(len(names), -np.inf), np.full(len(names), np.inf)
    for k, (name, rot) in enumerate(zip(names, rotation, strict=True)):
        if robot is not None and name not in robot:
            continue
        w = angle if rot else length
        lo[k], hi[k] = nominal[k] - w, nominal[k] + w
    return lo, hi


def parameters_at_bounds(
    names: Sequence[str], x: Array, lo: Array, hi: Array, tolerance: float = AT_BOUND_TOLERANCE
) -> list[str]:
    """The parameters at a bound: within ``tolerance`` times the bounds' width (or times
    1 m or 1 rad for a one-sided bound) of their lower or upper bound.  A value beyond its
    bound counts as at it (the bounded solver clips its result, so none is); one strictly
    inside by more than the tolerance does not."""
    out = []
    for name, v, a, b in zip(names, x, lo, hi, strict=True):
        width = b - a if np.isfinite(b - a) else 1.0
        near = tolerance * width
        if (np.isfinite(a) and v - a <= near) or (np.isfinite(b) and b - v <= near):
            out.append(name)
    return out


def bounded_method_bounds(
    bounds: Any,
    problem: Problem,
    dropped: Sequence[Dropped],
    length: float,
    robot: set[str],
) -> tuple[Array, Array, str | None]:
    """``(lower, upper)`` over the free parameters of ``problem`` for ``method="bounded"``
    (SI), and a note when they were widened (:data:`BOUNDS_CHOICES`)."""
    names, x0 = problem.free_names, problem.x0
    if bounds is None:
        return np.full(len(x0), -np.inf), np.full(len(x0), np.inf), None
    if isinstance(bounds, str):
        rot = [s.is_rotation for s in problem.chain.steps if s.free] + [False] * problem.n_effects
        lo, hi = default_bounds(names, rot, x0, robot=robot)
        if bounds == "default":
            return lo, hi, None
        wide_lo, wide_hi = _widen_for_absorbed(lo, hi, names, dropped, problem.chain, length, robot)
        changed = [
            f"{n} ±{_bound_text(n, h - v, r)}"
            for n, v, h, h0, r in zip(names, x0, wide_hi, hi, rot, strict=True)
            if h != h0
        ]
        note = (
            "bounds='widened': Li et al. 2016's ±5 mm / ±2° widened for the parameters that absorb redundant "
            f"ones: {', '.join(changed) or 'none absorbs any'}"
        )
        return wide_lo, wide_hi, note
    lo, hi = (np.asarray(b, dtype=float) for b in bounds)
    if lo.shape != x0.shape or hi.shape != x0.shape:
        raise ValueError(f"bounds must be two arrays over the {len(x0)} estimated parameters {names}")
    return lo, hi, None


def _bound_text(name: str, half_width: float, rotation: bool) -> str:
    """A bound's half width in mm or degrees."""
    return f"{math.degrees(half_width):.3g}°" if rotation else f"{half_width * 1e3:.3g} mm"
