"""The parts of a chain: its steps, joints, bodies and their roles.

A :class:`Step` is one elementary motion ``Tx, Ty, Tz, Rx, Ry, Rz`` whose value is a named
parameter (SI: m or rad); a :class:`Joint` drives a step; a :class:`Body` carries a link's mass
properties; :class:`JointEffects` are a joint's non-geometric parameters; a :class:`Role` says
what a step stands for.  :class:`robocal.model.chain.Model` chains them (and re-exports them).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import StrEnum
from typing import Literal

from robocal.spatial import MOTIONS

__all__ = ["Body", "Joint", "JointEffects", "JointType", "Role", "Step", "check_chain"]

JointType = Literal["revolute", "prismatic"]
# bound once: a calibration derives some fifty steps (Step._copy_with)
_new, _set = object.__new__, object.__setattr__


def _check_name(kind: str, name: str) -> None:
    if not isinstance(name, str) or not name.strip():
        raise ValueError(f"{kind} name must be a non-empty string, got {name!r}")


class Role(StrEnum):
    """What a step of the chain stands for (:attr:`Step.role`).

    * ``KINEMATIC``: the robot's own geometry (base, links, joint offsets, flange): what a
      calibration corrects and a calibrated model carries to the controller.
    * ``TOOL``: the tool, from the flange to the measured point or frame (the ``tcp_*``
      steps a calibration appends; stripped for the robot's own kinematics).
    * ``DEVICE``: the measuring device's frame relative to the robot base (the ``frame0_*``
      start and ``frame_*`` correction a calibration prepends).
    """

    KINEMATIC = "kinematic"
    TOOL = "tool"
    DEVICE = "device"

    @classmethod
    def from_name(cls, name: str) -> Role:
        """The role of a step from its name alone: how robocal told roles before they were
        stored; used for steps built without one (model files without ``role`` entries)."""
        if name.startswith("tcp_"):
            return cls.TOOL
        if name.startswith(("frame_", "frame0_")):
            return cls.DEVICE
        return cls.KINEMATIC


@dataclass(frozen=True)
class Joint:
    """A joint variable driving one step of the chain.

    Attributes:
        name: unique joint name (e.g. ``"q1"`` or ``"shoulder_pan_joint"``).
        limits: ``(lower, upper)`` on the commanded joint value ``q`` (rad or m), or
            ``None`` when unknown.
    """

    name: str
    limits: tuple[float, float] | None = None

    def __post_init__(self) -> None:
        _check_name("joint", self.name)
        if self.limits is not None:
            lo, hi = (float(v) for v in self.limits)
            if not (math.isfinite(lo) and math.isfinite(hi)) or lo > hi:
                raise ValueError(f"joint {self.name!r}: limits {self.limits} must be finite, lower <= upper")
            object.__setattr__(self, "limits", (lo, hi))


@dataclass(frozen=True)
class Step:
    """One elementary transform of the chain.

    Attributes:
        motion: ``"Tx" | "Ty" | "Tz" | "Rx" | "Ry" | "Rz"``.
        name: the parameter's unique name (``"d1"``, ``"alpha2"``, ``"theta3"``...).
        value: nominal value in SI (m or rad).  For a joint step it is the joint
            offset: the transform is ``motion(q + value)``.
        free: whether identification may change the value.
        bounds: optional ``(lower, upper)`` on the value (SI) for bounded solvers.
        joint: the joint variable driving this step, or ``None`` for a constant.
        role: what the step stands for (:class:`Role`): the robot's geometry, the tool or
            the measuring device's frame.  Not given (None): :meth:`Role.from_name`, so
            that ``Step("Tx", "tcp_x")`` is a tool step as it always was; always a
            :class:`Role` once constructed.
    """

    motion: str
    name: str
    value: float = 0.0
    free: bool = True
    bounds: tuple[float, float] | None = None
    joint: Joint | None = None
    role: Role | None = None

    def __post_init__(self) -> None:
        if self.motion not in MOTIONS:
            raise ValueError(f"step {self.name!r}: motion {self.motion!r} is not one of {MOTIONS}")
        _check_name("parameter", self.name)
        value = float(self.value)
        if not math.isfinite(value):
            raise ValueError(f"parameter {self.name!r}: value {self.value!r} is not finite")
        object.__setattr__(self, "value", value)
        object.__setattr__(self, "free", bool(self.free))
        try:
            role = Role.from_name(self.name) if self.role is None else Role(self.role)
        except ValueError:
            raise ValueError(
                f"step {self.name!r}: role {self.role!r} is not one of {', '.join(r.value for r in Role)}"
            ) from None
        object.__setattr__(self, "role", role)
        if self.bounds is not None:
            lo, hi = (float(v) for v in self.bounds)
            if math.isnan(lo) or math.isnan(hi) or lo > hi:
                raise ValueError(f"parameter {self.name!r}: bounds {self.bounds} need lower <= upper")
            object.__setattr__(self, "bounds", (lo, hi))

    def _with_value(self, value: float) -> Step:
        """This step with another value.  Only the value needs checking, so the copy skips
        ``__post_init__``: solvers and results derive many models per calibration."""
        value = float(value)
        if not math.isfinite(value):
            raise ValueError(f"parameter {self.name!r}: value {value!r} is not finite")
        return self._copy_with("value", value)

    def _with_free(self, free: bool) -> Step:
        """This step freed or fixed (a checked copy, as :meth:`_with_value`)."""
        return self._copy_with("free", bool(free))

    def _copy_with(self, field_name: str, value: object) -> Step:
        fields = self.__dict__.copy()
        fields[field_name] = value
        step = _new(Step)
        _set(step, "__dict__", fields)  # the copied fields as its own (a frozen dataclass)
        return step

    @property
    def axis(self) -> int:
        """Index 0, 1, 2 of the local axis x, y, z."""
        return "xyz".index(self.motion[1])

    @property
    def is_rotation(self) -> bool:
        return self.motion[0] == "R"

    @property
    def unit(self) -> str:
        """SI unit of the value: ``"rad"`` or ``"m"``."""
        return "rad" if self.is_rotation else "m"

    @property
    def joint_type(self) -> JointType | None:
        if self.joint is None:
            return None
        return "revolute" if self.is_rotation else "prismatic"


@dataclass(frozen=True)
class Body:
    """Mass properties of one rigid link (for joint wrenches, seed 003 ch. 4-5).

    Attributes:
        name: link name.
        frame: name of the step after which the body's frame is taken; the centre of
            mass and inertia are expressed in that frame.  The body is the link the
            frame belongs to (the one moved by the last joint before that step).
        mass: kg.
        com: centre of mass (m) in ``frame``.
        inertia: ``(Ixx, Iyy, Izz, Ixy, Ixz, Iyz)`` in kg·m² about the centre of
            mass, axes of ``frame``; ``None`` when unpublished.
    """

    name: str
    frame: str
    mass: float
    com: tuple[float, float, float] = (0.0, 0.0, 0.0)
    inertia: tuple[float, float, float, float, float, float] | None = None

    def __post_init__(self) -> None:
        _check_name("body", self.name)
        if not (math.isfinite(self.mass) and self.mass >= 0):
            raise ValueError(f"body {self.name!r}: mass {self.mass!r} must be finite and >= 0")
        com = tuple(float(v) for v in self.com)
        if len(com) != 3 or not all(map(math.isfinite, com)):
            raise ValueError(f"body {self.name!r}: com must be 3 finite numbers, got {self.com!r}")
        object.__setattr__(self, "com", com)
        object.__setattr__(self, "mass", float(self.mass))
        if self.inertia is not None:
            inertia = tuple(float(v) for v in self.inertia)
            if len(inertia) != 6 or not all(map(math.isfinite, inertia)):
                raise ValueError(f"body {self.name!r}: inertia must be 6 finite numbers")
            object.__setattr__(self, "inertia", inertia)


@dataclass(frozen=True)
class JointEffects:
    """Non-geometric parameters of one joint (seed 003 ch. 4-5, Table 5.2), SI units.

    They turn the joint's load into the joint perturbations (δα, δβ, δθ) of the
    chain (see :mod:`robocal.model.joints` for the equations):

    Attributes:
        joint: the joint's name.
        clearance_tilt: ``C_cle_tilt`` (rad), the angle by which the shaft can tilt in
            its housing (eq. 4.11); the tilt is split between the two axes
            perpendicular to the joint axis by the ratio of the moments about them
            (eqs. 5.16-5.18).
        backlash: ``δθ_bkl`` (rad; m for a prismatic joint): the joint turns by
            ``±backlash`` with the sign of the load moment about its axis (eq. 5.19).
        compliance: axial compliance ``1/k_z`` (rad/(N·m); m/N for a prismatic joint):
            the joint gives way by ``compliance × load moment`` (eqs. 4.15, 5.19).
        radial_compliance: ``1/k_r`` (rad/(N·m)): elastic tilt about the two
            perpendicular axes, ``compliance × load moment`` about each (seed 003 names
            it and neglects it; optional).
        shaft_length: ``L`` (m), the length of the shaft in its housing, or None.  With
            ``clearance_tilt`` it gives the radial clearance ``r = (L/2) tan C`` (eq.
            5.15); the tilt itself does not depend on it.

    Identified values may come out slightly negative when an effect is below the
    measurement noise; they are kept as they are (finite values only).
    """

    joint: str
    clearance_tilt: float = 0.0
    backlash: float = 0.0
    compliance: float = 0.0
    radial_compliance: float = 0.0
    shaft_length: float | None = None

    def __post_init__(self) -> None:
        _check_name("joint", self.joint)
        for name in ("clearance_tilt", "backlash", "compliance", "radial_compliance"):
            value = float(getattr(self, name))
            if not math.isfinite(value):
                raise ValueError(f"joint effects of {self.joint!r}: {name} {value!r} is not finite")
            object.__setattr__(self, name, value)
        if abs(self.clearance_tilt) >= math.pi / 2:
            raise ValueError(
                f"joint effects of {self.joint!r}: clearance_tilt {self.clearance_tilt!r} rad must be "
                "smaller than 90°"
            )
        if self.shaft_length is not None:
            length = float(self.shaft_length)
            if not (math.isfinite(length) and length > 0):
                raise ValueError(
                    f"joint effects of {self.joint!r}: shaft_length {self.shaft_length!r} must be > 0 (m)"
                )
            object.__setattr__(self, "shaft_length", length)

    @property
    def stiffness(self) -> float:
        """Axial stiffness ``k_z = 1/compliance`` (N·m/rad; inf for a rigid joint)."""
        return math.inf if self.compliance == 0 else 1.0 / self.compliance

    @property
    def clearance_radius(self) -> float | None:
        """Radial clearance ``r = (L/2) tan C`` (m, seed 003 eq. 5.15), None without ``shaft_length``."""
        if self.shaft_length is None:
            return None
        return 0.5 * self.shaft_length * math.tan(self.clearance_tilt)


def check_chain(
    name: str, steps: tuple[Step, ...], bodies: tuple[Body, ...], joint_effects: tuple[JointEffects, ...]
) -> None:
    """Raise ValueError/TypeError naming what is wrong with model ``name``'s chain: no steps, a
    non-step, a parameter or joint name used twice, a body on an unknown frame, joint effects of
    an unknown joint or given twice."""
    _check_name("model", name)
    if not steps:
        raise ValueError(f"model {name!r} has no steps")
    for step in steps:
        if not isinstance(step, Step):
            raise TypeError(f"model {name!r}: steps must be Step objects, got {step!r}")
    seen: set[str] = set()
    for step in steps:
        if step.name in seen:
            raise ValueError(f"model {name!r}: parameter name {step.name!r} is used twice")
        seen.add(step.name)
    joint_names = [s.joint.name for s in steps if s.joint is not None]
    if len(set(joint_names)) < len(joint_names):
        twice = next(n for i, n in enumerate(joint_names) if n in joint_names[:i])
        raise ValueError(f"model {name!r}: joint name {twice!r} is used twice")
    for body in bodies:
        if body.frame not in seen:
            raise ValueError(
                f"model {name!r}: body {body.name!r} refers to frame {body.frame!r}, "
                "which is not a step of the chain"
            )
    effect_joints: set[str] = set()
    for effects in joint_effects:
        if not isinstance(effects, JointEffects):
            raise TypeError(f"model {name!r}: joint_effects must be JointEffects, got {effects!r}")
        if effects.joint not in joint_names:
            raise ValueError(
                f"model {name!r}: joint effects refer to joint {effects.joint!r}, which is not a "
                f"joint of the chain ({', '.join(joint_names)})"
            )
        if effects.joint in effect_joints:
            raise ValueError(f"model {name!r}: joint {effects.joint!r} has joint effects twice")
        effect_joints.add(effects.joint)
