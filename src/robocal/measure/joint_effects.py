"""Joint effects of a virtual robot: callables ``effect(model, q) -> (n, dof, 3)`` joint
perturbations (δα, δβ, δθ) passed to ``true_model.fk(q, perturbations=...)`` (seed 003 eq. 5.9;
see :mod:`robocal.model.chain`).  Two examples: :class:`EncoderNoise` and
:class:`PayloadCompliance` (a gravity-proportional joint deflection); clearance, backlash and
full compliance models plug in the same way.

Part of :mod:`robocal.measure.simulate`, which re-exports them.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from robocal.model.chain import Model

__all__ = ["EncoderNoise", "JointEffect", "PayloadCompliance", "effect_from_dict"]

Array = NDArray[np.float64]

#: ``effect(model, q (n, dof)) -> (n, dof, 3)`` joint perturbations (δα, δβ, δθ) in rad
#: (δθ in m for a prismatic joint).
JointEffect = Callable[[Model, Array], Array]


@dataclass(frozen=True)
class EncoderNoise:
    """Joint effect: normal joint-reading errors δθ with 1-sigma ``sigma`` (rad, m for a
    prismatic joint), drawn from ``seed`` (the same q count gives the same errors)."""

    sigma: float
    seed: int = 0

    def __call__(self, model: Model, q: Array) -> Array:
        q = np.atleast_2d(q)
        d = np.zeros((len(q), model.dof, 3))
        d[:, :, 2] = np.random.default_rng(self.seed).normal(0.0, self.sigma, (len(q), model.dof))
        return d

    def to_dict(self) -> dict[str, Any]:
        return {"type": "encoder-noise", "sigma": float(self.sigma), "seed": int(self.seed)}


@dataclass(frozen=True)
class PayloadCompliance:
    """Joint effect: joints deflected by the gravity moment of a payload at the tool.

    For each joint j with a stiffness ``k_j`` (N·m/rad; N/m for a prismatic joint) the
    payload ``mass`` (kg) at ``p_tool_load`` (m, tool frame) under ``gravity`` (m/s²,
    base frame) exerts the moment ``τ_j = a_j · ((c − o_j) × m g)`` about the joint axis
    (unit ``a_j`` through ``o_j``; a force ``a_j · m g`` for a prismatic joint), and the
    joint gives way by ``δθ_j = τ_j / k_j``.  The link masses are ignored: a first
    example of the hook (seed 003 ch. 5 computes the full moments by Newton-Euler).

    Attributes:
        mass: payload (kg).
        stiffness: by joint name or 1-based joint number, e.g. ``{2: 5e4}``.
        p_tool_load: payload centre in the tool frame (m).
        gravity: gravity vector in the base frame (m/s²).
    """

    mass: float
    stiffness: Mapping[str | int, float]
    p_tool_load: tuple[float, float, float] = (0.0, 0.0, 0.0)
    gravity: tuple[float, float, float] = (0.0, 0.0, -9.81)

    def _joints(self, model: Model) -> list[tuple[int, float]]:
        out = []
        for key, k in self.stiffness.items():
            if isinstance(key, str):
                if key not in model.joint_names:
                    raise KeyError(f"PayloadCompliance: model {model.name!r} has no joint {key!r}")
                j = model.joint_names.index(key)
            else:
                j = int(key) - 1
                if not 0 <= j < model.dof:
                    raise KeyError(f"PayloadCompliance: joint number {key} is not in 1..{model.dof}")
            if not (math.isfinite(k) and k > 0):
                raise ValueError(f"PayloadCompliance: stiffness of joint {key} must be > 0, got {k}")
            out.append((j, float(k)))
        return out

    def __call__(self, model: Model, q: Array) -> Array:
        q = np.atleast_2d(q)
        frames = model.joint_frames(q)  # (n, dof, 4, 4), origin on each joint axis
        T = model.fk(q)
        c = T[:, :3, :3] @ np.asarray(self.p_tool_load, dtype=float) + T[:, :3, 3]
        force = self.mass * np.asarray(self.gravity, dtype=float)
        axes = [s.axis for s in model.steps if s.joint is not None]
        d = np.zeros((len(q), model.dof, 3))
        for j, k in self._joints(model):
            a = frames[:, j, :3, axes[j]]
            if model.joint_types[j] == "revolute":
                moment = np.cross(c - frames[:, j, :3, 3], force)
                d[:, j, 2] = np.einsum("ni,ni->n", a, moment) / k
            else:
                d[:, j, 2] = a @ force / k
        return d

    def to_dict(self) -> dict[str, Any]:
        return {
            "type": "payload-compliance",
            "mass": float(self.mass),
            "stiffness": {k: float(v) for k, v in self.stiffness.items()},
            "p_tool_load": [float(v) for v in self.p_tool_load],
            "gravity": [float(v) for v in self.gravity],
        }


_EFFECTS: dict[str, type] = {"encoder-noise": EncoderNoise, "payload-compliance": PayloadCompliance}


def effect_from_dict(data: Mapping[str, Any]) -> JointEffect | None:
    data = dict(data)
    if data.get("type") == "joint-tilting":  # seed 003's joint model (robocal.model.joints)
        from robocal.model.joints import JointTilting

        return JointTilting.from_dict(data)
    cls = _EFFECTS.get(data.pop("type", None))
    if cls is None:
        return None
    for key in ("p_tool_load", "gravity"):
        if key in data:
            data[key] = tuple(data[key])
    return cls(**data)
