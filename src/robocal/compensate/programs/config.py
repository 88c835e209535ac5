"""Arm configurations written in programs: KUKA status/turn and ABB ``cf1, cf4, cf6, cfx``."""

from __future__ import annotations

import math

import numpy as np

from robocal.compensate.arm_geometry import arm_sides
from robocal.compensate.programs.syntax import (
    Array,
    ProgramTarget,
)
from robocal.model.chain import Model

# ---------------------------------------------------------------------- configurations
_EPS_DEG = 1e-6  # degrees: an axis at a boundary (0, ±90 ...) meets either side
_EPS_M = 1e-6  # m: a wrist centre on a boundary (axis 1, the lower arm's line) meets either side


def _digit(value: float, eps: float, negative_bit: int) -> set[int]:
    """The bit values a signed quantity allows: ``negative_bit`` when < 0 (both near 0)."""
    if abs(value) < eps:
        return {0, 1}
    return {negative_bit if value < 0 else 1 - negative_bit}


def status_bits(model: Model, q: Array) -> list[set[int]]:
    """KUKA status bits 0, 1, 2 that joint values ``q`` (rad) allow: bit 0 set when the
    wrist centre is behind axis 1 (overhead), bit 1 set when A3 >= phi (the angle that
    stretches the arm; elbow up), bit 2 set when A5 <= 0."""
    front, elbow = arm_sides(model, q)
    a5 = math.degrees(q[4])
    return [_digit(front, _EPS_M, 1), _digit(elbow, _EPS_M, 0), _digit(a5, _EPS_DEG, 1)]


def cfx_bits(model: Model, q: Array) -> list[set[int]]:
    """ABB ``cfx`` = 4 b2 + 2 b1 + b0 for a 6-axis arm: b2 set when the wrist centre is
    behind axis 1, b1 set when it is behind the lower arm (elbow down), b0 set when axis 5
    is negative."""
    front, elbow = arm_sides(model, q)
    a5 = math.degrees(q[4])
    return [_digit(a5, _EPS_DEG, 1), _digit(elbow, _EPS_M, 1), _digit(front, _EPS_M, 1)]


def _status(model: Model, q: Array) -> int:
    """KUKA status ``S`` (bits 0-2, see :func:`_status_bits`) of joint values ``q`` (rad)."""
    return sum(min(b) << k for k, b in enumerate(status_bits(model, q)))


def _cfx(model: Model, q: Array) -> int:
    """ABB ``cfx`` (see :func:`_cfx_bits`) of joint values ``q`` (rad)."""
    return sum(min(b) << k for k, b in enumerate(cfx_bits(model, q)))


def _abb_digits(t: ProgramTarget) -> tuple[int, ...]:
    """ABB's written ``cf1, cf4, cf6[, cfx]`` (the RAPID reader keeps a confdata only when
    all four are integers; only KUKA's ``(T, S)`` may hold a missing ``None``)."""
    return tuple(c for c in t.config or () if c is not None)


def config_changes(t: ProgramTarget, q: Array, model: Model | None = None) -> list[str]:
    """How joint values ``q`` (rad) differ from the target's written configuration: one
    entry per bit or digit (``[]``: they meet it).  Without ``model`` the status / cfx
    is not checked."""
    if t.config is None or len(q) < 6:
        return []
    deg = np.degrees(q[:6])
    eps = _EPS_DEG
    out = []
    if t.style == "krl":
        turn, status = t.config
        if turn is not None:
            for j in range(6):
                if abs(deg[j]) >= eps and (deg[j] < 0) != bool(turn >> j & 1):
                    out.append(f"T bit {j} (A{j + 1} {'<' if deg[j] < 0 else '>='} 0)")
        if status is not None and model is not None:
            names = ("overhead", "A3 >= phi", "A5 <= 0")
            for k, allowed in enumerate(status_bits(model, q)):
                if status >> k & 1 not in allowed:
                    out.append(f"S bit {k} ({names[k]}) {status >> k & 1} -> {min(allowed)}")
        return out
    digits = _abb_digits(t)
    for j, cf, name in zip((0, 3, 5), digits[:3], ("cf1", "cf4", "cf6"), strict=True):
        if not math.floor((deg[j] - eps) / 90.0) <= cf <= math.floor((deg[j] + eps) / 90.0):
            out.append(f"{name} {cf} -> {math.floor(deg[j] / 90.0)}")
    if len(digits) > 3 and model is not None:
        cfx = digits[3]
        bits = cfx_bits(model, q)
        if not 0 <= cfx < 8 or any(cfx >> k & 1 not in b for k, b in enumerate(bits)):
            out.append(f"cfx {cfx} -> {sum(min(b) << k for k, b in enumerate(bits))}")
    return out


def config_ok(t: ProgramTarget, q: Array, model: Model | None = None) -> bool:
    """Whether joint values ``q`` (rad) meet the target's written configuration."""
    return not config_changes(t, q, model)


def config_starts(t: ProgramTarget, model: Model, rng: np.random.Generator, n: int) -> Array:
    """``(n, dof)`` starting configurations within the limits that meet the configuration."""
    lim = model.joint_limits
    lo, hi = np.maximum(lim[:, 0], -math.pi), np.minimum(lim[:, 1], math.pi)
    q = rng.uniform(lo, hi, (n, model.dof))
    if t.config is None or model.dof < 6:
        return q
    if t.style == "krl":
        turn, status = t.config
        for j in range(6):
            if turn is not None:
                negative = bool(turn >> j & 1)
                q[:, j] = np.where(negative, -np.abs(q[:, j]), np.abs(q[:, j]))
        if status is not None:
            q[:, 4] = np.where(status >> 2 & 1, -np.abs(q[:, 4]), np.abs(q[:, 4]))
    else:
        digits = _abb_digits(t)
        for j, cf in zip((0, 3, 5), digits[:3], strict=True):
            q[:, j] = np.radians(90.0 * (cf + rng.uniform(0.1, 0.9, n)))
        if len(digits) > 3:
            q[:, 4] = np.where(digits[3] & 1, -np.abs(q[:, 4]), np.abs(q[:, 4]))
    return np.clip(q, lim[:, 0], lim[:, 1])
