"""The one model representation: a chain of elementary transforms.

A robot model is an ordered tuple of :class:`Step` objects.  Each step is one
elementary motion ``Tx, Ty, Tz, Rx, Ry, Rz`` whose value is a named parameter
(constant, e.g. a DH link length) or a joint variable plus the joint's offset
parameter.  Every convention of the seeds (DH, modified DH, Hayati, Veitschegger,
Schröer's link sets, base and tool frames) is such a sequence, so one forward
kinematics routine and one analytic Jacobian serve them all.

Frames and shapes
-----------------
* ``q`` is ``(n, dof)`` (rad for revolute, m for prismatic joints); a 1-D ``q`` of
  length ``dof`` is one configuration and the leading ``n`` axis is dropped.
* ``T_base_tool = model.fk(q)`` is ``(n, 4, 4)``: the frame at the end of the chain
  expressed in the frame at its start.
* ``model.joint_frames(q)`` is ``(n, dof, 4, 4)``: for each joint the frame directly
  after its joint step (it moves with the joint's child link; its origin is on the
  joint axis).
* Joint perturbations ``(n, dof, 3) = (δα, δβ, δθ)`` model non-geometric effects
  (seed 003 eq. 5.9): δθ is added to the joint variable (rad, or m for a prismatic
  joint), then the child frame is tilted by δα about its first perpendicular axis and
  δβ about its second (x then y for a joint about z; y, z for x; z, x for y).  The
  tilt is expressed in the joint frame, the frame in which joint moments are
  computed.
* ``model.jacobian(q)`` is the identification Jacobian d(tool position)/d(free
  parameters), ``(3n, p)`` with rows ``[x, y, z]`` per pose; ``rows="pose"`` gives
  ``(6n, p)`` with rows ``[x, y, z, ωx, ωy, ωz]`` per pose, where ω is the
  small-rotation vector in the base frame (see :func:`robocal.spatial.pose_error`).
* ``model.joint_jacobian(q)`` is the geometric Jacobian ``(n, 6, dof)``, rows
  ``[v; ω]`` of the tool point in the base frame.

Analytic derivatives (DESIGN.md): for a rotation step about unit axis ``a`` whose
frame has origin ``o``, dp/dvalue = a × (p − o) and dω/dvalue = a; for a translation
step dp/dvalue = a and dω/dvalue = 0, with ``a`` and ``o`` in base coordinates.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from enum import StrEnum
from functools import cached_property
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from robocal.spatial import MOTIONS

__all__ = ["Body", "Joint", "JointEffects", "Model", "Role", "Step"]

Array = NDArray[np.float64]
JointType = Literal["revolute", "prismatic"]


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
        step = object.__new__(Step)
        step.__dict__.update(self.__dict__)
        step.__dict__[field_name] = value
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


@dataclass(frozen=True)
class _Plan:
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


_PLANS: dict[tuple[tuple[str, bool], ...], _Plan] = {}  # compiled plans by chain structure


@dataclass(frozen=True)
class Model:
    """An immutable robot model: a named chain of elementary transforms.

    Build models with the helpers of :mod:`robocal.model.conventions`, load them
    with :func:`robocal.load_model` or take one from the catalog with
    :func:`robocal.robot`.  All values are SI (m, rad).
    """

    name: str
    steps: tuple[Step, ...]
    bodies: tuple[Body, ...] = ()
    title: str = ""
    source: str = ""
    notes: str = field(default="", compare=True)
    joint_effects: tuple[JointEffects, ...] = ()
    # the learned residual (robocal.model.residual.JointAngleResidual) or None
    residual: Any = field(default=None, compare=False)

    def __post_init__(self) -> None:
        _check_name("model", self.name)
        steps = tuple(self.steps)
        object.__setattr__(self, "steps", steps)
        object.__setattr__(self, "bodies", tuple(self.bodies))
        object.__setattr__(self, "joint_effects", tuple(self.joint_effects))
        if not steps:
            raise ValueError(f"model {self.name!r} has no steps")
        for step in steps:
            if not isinstance(step, Step):
                raise TypeError(f"model {self.name!r}: steps must be Step objects, got {step!r}")
        seen: set[str] = set()
        for step in steps:
            if step.name in seen:
                raise ValueError(f"model {self.name!r}: parameter name {step.name!r} is used twice")
            seen.add(step.name)
        joint_names = [s.joint.name for s in steps if s.joint is not None]
        if len(set(joint_names)) < len(joint_names):
            twice = next(n for i, n in enumerate(joint_names) if n in joint_names[:i])
            raise ValueError(f"model {self.name!r}: joint name {twice!r} is used twice")
        for body in self.bodies:
            if body.frame not in seen:
                raise ValueError(
                    f"model {self.name!r}: body {body.name!r} refers to frame {body.frame!r}, "
                    "which is not a step of the chain"
                )
        effect_joints: set[str] = set()
        for effects in self.joint_effects:
            if not isinstance(effects, JointEffects):
                raise TypeError(f"model {self.name!r}: joint_effects must be JointEffects, got {effects!r}")
            if effects.joint not in joint_names:
                raise ValueError(
                    f"model {self.name!r}: joint effects refer to joint {effects.joint!r}, which is not a "
                    f"joint of the chain ({', '.join(joint_names)})"
                )
            if effects.joint in effect_joints:
                raise ValueError(f"model {self.name!r}: joint {effects.joint!r} has joint effects twice")
            effect_joints.add(effects.joint)

    # ------------------------------------------------------------------ parameters
    @property
    def dof(self) -> int:
        """Number of joint variables."""
        return len(self._plan.joint_steps)

    @property
    def joints(self) -> tuple[Joint, ...]:
        return tuple(s.joint for s in self.steps if s.joint is not None)

    @property
    def joint_names(self) -> tuple[str, ...]:
        return tuple(j.name for j in self.joints)

    @property
    def joint_types(self) -> tuple[JointType, ...]:
        return tuple(s.joint_type for s in self.steps if s.joint is not None)

    @property
    def joint_limits(self) -> Array:
        """``(dof, 2)`` lower/upper joint limits; ±inf where unknown."""
        out = np.tile([-np.inf, np.inf], (self.dof, 1))
        for j, joint in enumerate(self.joints):
            if joint.limits is not None:
                out[j] = joint.limits
        return out

    @cached_property
    def names(self) -> tuple[str, ...]:
        """Names of all parameters, in chain order."""
        return tuple(s.name for s in self.steps)

    @property
    def values(self) -> Array:
        """Values (SI) of all parameters, in chain order, shape ``(P,)``."""
        return np.array([s.value for s in self.steps])

    @cached_property
    def free_mask(self) -> NDArray[np.bool_]:
        return np.array([s.free for s in self.steps], dtype=bool)

    @cached_property
    def roles(self) -> dict[str, Role]:
        """Each parameter's :class:`Role`, by name."""
        return {s.name: s.role for s in self.steps}

    def names_with_role(self, role: Role) -> tuple[str, ...]:
        """Names of the parameters with ``role``, in chain order."""
        return tuple(s.name for s in self.steps if s.role is role)

    @cached_property
    def free_names(self) -> tuple[str, ...]:
        """Names of the free parameters, in chain order (the Jacobian's columns)."""
        return tuple(s.name for s in self.steps if s.free)

    @property
    def free_values(self) -> Array:
        """Values (SI) of the free parameters, shape ``(p,)``."""
        return np.array([s.value for s in self.steps if s.free])

    def step(self, name: str) -> Step:
        """The step whose parameter is called ``name``."""
        try:
            return self.steps[self._index[name]]
        except KeyError:
            raise KeyError(f"model {self.name!r} has no parameter {name!r}") from None

    @cached_property
    def _index(self) -> dict[str, int]:
        return {s.name: i for i, s in enumerate(self.steps)}

    def with_free_values(self, x: ArrayLike) -> Model:
        """A new model whose free parameters take the values ``x`` (SI, shape ``(p,)``)."""
        x = np.asarray(x, dtype=float)
        p = int(self.free_mask.sum())
        if x.shape != (p,):
            raise ValueError(f"model {self.name!r} has {p} free parameters, got values shaped {x.shape}")
        return self.with_values(dict(zip(self.free_names, x.tolist(), strict=True)))

    def with_values(self, values: Mapping[str, float]) -> Model:
        """A new model with the named parameters set to new values (SI)."""
        steps = list(self.steps)
        for name, value in values.items():
            i = self._index.get(name)
            if i is None:
                raise KeyError(f"model {self.name!r} has no parameter {name!r}")
            steps[i] = steps[i]._with_value(value)
        return dataclasses.replace(self, steps=tuple(steps))

    def with_free(self, names: Iterable[str] | None = None, free: bool = True) -> Model:
        """A new model with the named parameters (all when ``names`` is None) freed or fixed."""
        selected = set(self.names if names is None else names)
        unknown = selected - set(self.names)
        if unknown:
            raise KeyError(f"model {self.name!r} has no parameter(s) {sorted(unknown)}")
        steps = tuple(s._with_free(free) if s.name in selected else s for s in self.steps)
        return dataclasses.replace(self, steps=steps)

    def fixed(self, names: Iterable[str]) -> Model:
        """A new model with the named parameters fixed (not identified)."""
        return self.with_free(names, free=False)

    # ------------------------------------------------------------------ kinematics
    @cached_property
    def _plan(self) -> _Plan:
        structure = tuple((s.motion, s.joint is not None) for s in self.steps)
        plan = _PLANS.get(structure)
        if plan is None:
            if len(_PLANS) > 256:
                _PLANS.clear()
            plan = _PLANS[structure] = self._compile_plan()
        return plan

    def _compile_plan(self) -> _Plan:
        """The chain's structure for batched evaluation (it depends only on the steps'
        motions and which are joints, so models that differ in values share it)."""
        joint_steps = [i for i, s in enumerate(self.steps) if s.joint is not None]
        anchor_of = np.zeros(len(self.steps), dtype=np.intp)
        segments: list[list[int]] = [[]]
        anchor = 0
        for i, step in enumerate(self.steps):
            if step.joint is not None:
                anchor_of[i] = anchor  # a joint step hangs off the previous anchor's segment end
                anchor += 1
                segments.append([])
            else:
                anchor_of[i] = anchor
                segments[anchor].append(i)
        width = max(max(len(seg) for seg in segments), 1)
        table = np.full((len(segments), width), len(self.steps), dtype=np.intp)
        slot = np.zeros(len(self.steps), dtype=np.intp)
        for a, seg in enumerate(segments):
            table[a, : len(seg)] = seg
            slot[list(seg)] = a * width + np.arange(len(seg))
        return _Plan(
            joint_steps=np.array(joint_steps, dtype=np.intp),
            joint_axis=tuple(self.steps[i].axis for i in joint_steps),
            joint_rot=tuple(self.steps[i].is_rotation for i in joint_steps),
            anchor_of=anchor_of,
            segments=tuple(tuple(s) for s in segments),
            step_axis=np.array([s.axis for s in self.steps], dtype=np.intp),
            step_rot=np.array([s.is_rotation for s in self.steps], dtype=bool),
            segment_table=table,
            segment_slot=slot,
            joint_axis_array=np.array([self.steps[i].axis for i in joint_steps], dtype=np.intp),
            joint_rot_array=np.array([self.steps[i].is_rotation for i in joint_steps], dtype=bool),
            step_joint=np.array([s.joint is not None for s in self.steps], dtype=bool),
        )

    def _check_q(self, q: ArrayLike) -> tuple[Array, bool]:
        q = np.asarray(q, dtype=float)
        single = q.ndim == 1
        if single:
            q = q[None, :]
        if q.ndim != 2 or q.shape[1] != self.dof:
            raise ValueError(
                f"joint values shaped {q.shape if not single else q.shape[1:]} do not fit model "
                f"{self.name!r} with {self.dof} joints; expected (n, {self.dof})"
            )
        if not np.all(np.isfinite(q)):
            bad = np.argwhere(~np.isfinite(q))[0]
            raise ValueError(
                f"joint values contain NaN/inf (pose {bad[0]}, joint {self.joint_names[bad[1]]})"
            )
        return q, single

    def _check_perturbations(self, perturbations: ArrayLike | None, n: int) -> Array | None:
        if perturbations is None:
            return None
        d = np.asarray(perturbations, dtype=float)
        if d.ndim == 2:
            d = d[None]
        if d.shape != (n, self.dof, 3):
            raise ValueError(f"joint perturbations shaped {d.shape}; expected ({n}, {self.dof}, 3)")
        return d

    @cached_property
    def _segments(self) -> tuple[Array, Array]:
        """:meth:`_segment_data` for this model's own values (models are immutable)."""
        return self._segment_data(self.values)

    def _segment_data(self, values: Array) -> tuple[Array, Array]:
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
        plan = self._plan
        E = np.empty((len(values) + 1, 4, 4))
        E[:-1] = _elementaries(plan.step_axis, plan.step_rot, values)
        E[-1] = _EYE4
        X = E[plan.segment_table]  # (dof + 1, L, 4, 4)
        width = X.shape[1]
        d = 1
        while d < width:  # X[:, t] <- X[:, t - d] X[:, t]: running products, earlier steps first
            X[:, d:] = np.matmul(X[:, :-d], X[:, d:])
            d *= 2
        seg_T = X[:, -1].copy()
        before = np.empty_like(X)  # product of the steps before each slot: shifted by one
        before[:, 0] = _EYE4
        before[:, 1:] = X[:, :-1]
        local = np.empty((len(values), 4, 4))
        flat = before.reshape(-1, 4, 4)
        local[:] = flat[plan.segment_slot]
        local[plan.joint_steps] = seg_T[:-1]  # a joint step starts where the previous segment ends
        return seg_T, local

    def _forward(
        self,
        q: Array,
        perturbations: Array | None,
        keep_anchors: bool,
        values: Array | None = None,
        segments: tuple[Array, Array] | None = None,
    ) -> tuple[Array, Array | None]:
        """Batched FK in structure-of-arrays layout.

        Frames are ``F`` shaped ``(3, 4, n)``: the rows of ``[R | p]`` with the poses
        last, so that every update below is a contiguous vector operation.

        Returns the tool frame and, when asked, the anchor frames ``(dof + 1, 3, 4, n)``:
        anchor 0 is the base (identity), anchor j + 1 the frame just after joint j's step.
        ``segments``: :meth:`_segment_data` of ``values`` when the caller has it already.
        """
        plan = self._plan
        if values is None:
            seg_T, _ = self._segments
            offsets = np.array([self.steps[i].value for i in plan.joint_steps])
        else:
            seg_T, _ = self._segment_data(values) if segments is None else segments
            offsets = values[plan.joint_steps]
        n, dof = q.shape
        qt = q.T + offsets[:, None]  # (dof, n) joint step values
        if perturbations is not None:
            qt = qt + perturbations[:, :, 2].T
        rot = np.array(plan.joint_rot, dtype=bool)
        cos = np.cos(qt[rot]) if rot.any() else None  # one trig call for all revolute joints
        sin = np.sin(qt[rot]) if rot.any() else None
        constant = ~np.all(seg_T == _EYE4, axis=(1, 2))  # segments that change the frame
        anchors = None
        if keep_anchors:
            anchors = np.empty((dof + 1, 3, 4, n))
            anchors[0] = _EYE4[:3, :, None]
        F = np.empty((3, 4, n))
        F[:] = seg_T[0][:3, :, None]
        r = 0
        for j in range(dof):
            k = plan.joint_axis[j]
            if plan.joint_rot[j]:
                _rotate_rows(F, k, cos[r], sin[r])
                r += 1
            else:
                F[:, 3] += F[:, k] * qt[j]
            if perturbations is not None:
                tilt_a, tilt_b = perturbations[:, j, 0], perturbations[:, j, 1]
                _rotate_rows(F, (k + 1) % 3, np.cos(tilt_a), np.sin(tilt_a))
                _rotate_rows(F, (k + 2) % 3, np.cos(tilt_b), np.sin(tilt_b))
            if keep_anchors:
                anchors[j + 1] = F
            if constant[j + 1]:
                F = np.matmul(seg_T[j + 1].T, F)  # each row r of [R | p]: (4, 4)ᵀ @ (4, n)
        return F, anchors

    def fk(self, q: ArrayLike, perturbations: ArrayLike | None = None, compiled: bool | None = None) -> Array:
        """Tool frames ``T_base_tool`` shaped ``(n, 4, 4)`` for joint values ``q`` ``(n, dof)``.

        ``perturbations`` ``(n, dof, 3)`` are per-pose joint perturbations (δα, δβ, δθ).
        ``compiled``: use the compiled kernels (:mod:`robocal.model.kernels`; default: when
        numba is installed) or, with False, the numpy code (no numba import).
        """
        if perturbations is None and compiled is not False and type(q) is np.ndarray and q.ndim == 1:
            T = self._fk_one(q, compiled)  # one configuration: the interactive case, a few µs
            if T is not None:
                return T
        q, single = self._check_q(q)
        d = self._check_perturbations(perturbations, len(q))
        kernels = _kernels(compiled)
        if kernels is not None and d is None:
            plan = self._plan
            seg, _, offsets = self._kernel_segments
            qt = np.ascontiguousarray(q.T)
            T = kernels.forward_batch(qt, seg, offsets, plan.joint_axis_array, plan.joint_rot_array)
        elif kernels is not None:
            T = self._kernel_forward(kernels, q, d, keep_anchors=False)[0]
        else:
            F, _ = self._forward(q, d, keep_anchors=False)
            T = _to_homogeneous(F)
        return T[0] if single else T

    def joint_frames(
        self, q: ArrayLike, perturbations: ArrayLike | None = None, compiled: bool | None = None
    ) -> Array:
        """Frames after each joint step, ``(n, dof, 4, 4)`` in the base frame (``compiled``: as
        for :meth:`fk`)."""
        q, single = self._check_q(q)
        d = self._check_perturbations(perturbations, len(q))
        kernels = _kernels(compiled)
        if kernels is not None:
            T = self._kernel_forward(kernels, q, d, keep_anchors=True)[1]
            return T[0] if single else T
        _, anchors = self._forward(q, d, keep_anchors=True)
        T = np.zeros((len(q), self.dof, 4, 4))
        T[:, :, :3, :] = anchors[1:].transpose(3, 0, 1, 2)
        T[:, :, 3, 3] = 1.0
        return T[0] if single else T

    # ------------------------------------------------------- compiled kernels (numba)
    def _fk_one(self, q: Array, compiled: bool | None) -> Array | None:
        """:meth:`fk` of one configuration by :func:`robocal.model.kernels.fk_one`, or None
        when it does not apply (no numba, another shape or type: the general path decides)."""
        kernels = _KERNELS[0] if _KERNELS else _kernels(compiled)
        if kernels is None or q.dtype is not _FLOAT64 or q.strides != (8,):
            return None
        T = np.empty((4, 4))
        return T if kernels.fk_one(q, self._fk_one_data, T) else None

    @cached_property
    def _fk_one_data(self) -> Array:
        """:func:`robocal.model.kernels.pack_one` of this model."""
        from robocal.model import kernels

        plan = self._plan
        seg, _, offsets = self._kernel_segments
        return kernels.pack_one(seg, offsets, plan.joint_axis_array, plan.joint_rot_array)

    @cached_property
    def _kernel_segments(self) -> tuple[Array, Array, Array]:
        """:meth:`_kernel_data` for this model's own values (models are immutable)."""
        from robocal.model import kernels

        return self._kernel_data(kernels, self.values)

    def _kernel_data(self, kernels, values: Array | None) -> tuple[Array, Array, Array]:
        """Segment transforms, local step frames and joint offsets for parameter ``values``."""
        if values is None:
            return self._kernel_segments
        plan = self._plan
        values = np.ascontiguousarray(values, dtype=float)
        seg, local = kernels.segment_data(values, plan.step_axis, plan.step_rot, plan.step_joint, self.dof)
        return seg, local, values[plan.joint_steps]

    def _kernel_perturbations(self, d: Array | None) -> tuple[Array, bool]:
        if d is None:
            return np.zeros((1, self.dof, 3)), False
        return np.ascontiguousarray(d, dtype=float), True

    def _kernel_forward(
        self, kernels, q: Array, d: Array | None, keep_anchors: bool, values: Array | None = None
    ) -> tuple[Array, Array]:
        plan = self._plan
        seg, _, offsets = self._kernel_data(kernels, values)
        pert, has_pert = self._kernel_perturbations(d)
        return kernels.forward(
            np.ascontiguousarray(q),
            pert,
            has_pert,
            seg,
            offsets,
            plan.joint_axis_array,
            plan.joint_rot_array,
            keep_anchors,
        )

    def _kernel_evaluate(
        self,
        kernels,
        q: Array,
        d: Array | None,
        steps: NDArray[np.intp],
        rows: int,
        values: Array | None = None,
        joint_columns: bool = False,
        perturbation_columns: bool = False,
    ) -> tuple[Array, Array, Array]:
        """:func:`robocal.model.kernels.evaluate`: ``T (n, 4, 4)``, the columns of ``steps``
        ``(n * rows, m)`` and the joint/perturbation columns ``(n * rows, dof, 3)``."""
        plan = self._plan
        seg, local, offsets = self._kernel_data(kernels, values)
        pert, has_pert = self._kernel_perturbations(d)
        return kernels.evaluate(
            np.ascontiguousarray(q),
            pert,
            has_pert,
            seg,
            local,
            offsets,
            plan.joint_axis_array,
            plan.joint_rot_array,
            plan.anchor_of,
            plan.step_axis,
            plan.step_rot,
            np.ascontiguousarray(steps, dtype=np.intp),
            plan.joint_steps,
            rows,
            joint_columns or perturbation_columns,
            perturbation_columns,
        )

    def _columns(
        self,
        q: Array,
        perturbations: Array | None,
        steps: Sequence[int],
        orientation: bool = True,
        values: Array | None = None,
        tilt: bool = False,
        segments: tuple[Array, Array] | None = None,
    ) -> tuple[Array, ...]:
        """Derivative columns of the tool pose wrt the values of ``steps`` (chain order).

        Returns ``F_tool (3, 4, n)`` and ``J (m, 6, n)`` with rows [dp; dω], or
        ``(m, 3, n)`` position rows only when ``orientation`` is false; with ``tilt``
        also the columns of the joint tilts ``(dof, 2, rows, n)`` (δα, δβ; see
        :meth:`_tilt_columns`).

        For a step hanging off anchor frame (R, p_a) with local axis a_l and local
        origin o_l, the world axis is a = R a_l and origin o = p_a + R o_l, so
        a × (p − o) = a × (p − p_a) − R (a_l × o_l).  All steps at once: each step's
        anchor frame is gathered, ``a`` and ``R (a_l × o_l)`` are three multiply-adds
        over the anchors' rotation columns, and one cross product with ``p − p_a``
        finishes the rotation columns; a translation step's column is ``dp = a, dω = 0``.
        A fixed handful of whole-array operations, whatever the chain's length: at a
        hundred poses the cost is the number of numpy calls, not the arithmetic.
        """
        plan = self._plan
        steps = np.asarray(steps, dtype=np.intp)
        if segments is None:
            segments = self._segments if values is None else self._segment_data(values)
        n = q.shape[0]
        local = segments[1]
        F, anchors = self._forward(q, perturbations, keep_anchors=True, values=values, segments=segments)
        m = len(steps)
        rows = 6 if orientation else 3
        loc = local[steps]
        a_loc = loc[np.arange(m), :3, plan.step_axis[steps]]  # (m, 3) axis in the anchor frame
        c_loc = _cross_rows(a_loc, loc[:, :3, 3])  # (m, 3) a_l × o_l
        step_anchor = plan.anchor_of[steps]
        A = np.empty((m, 3, n))  # world axes R a_l
        RC = np.empty((m, 3, n))  # R (a_l × o_l)
        bounds = np.flatnonzero(np.diff(step_anchor)) + 1
        for lo, hi in zip(np.r_[0, bounds], np.r_[bounds, m], strict=True) if m else ():
            # the steps of one anchor are contiguous: one product each for their a and R c,
            # written in place ((3, k, n) views: the rows of R times the vectors)
            R = anchors[step_anchor[lo], :, :3]
            np.matmul(a_loc[lo:hi], R, out=A[lo:hi].transpose(1, 0, 2))
            np.matmul(c_loc[lo:hi], R, out=RC[lo:hi].transpose(1, 0, 2))
        # r = p − p_a, the tool point from each step's anchor origin: for few poses gathered
        # for all steps (one block, fewest numpy calls); for many, one (3, n) vector per
        # anchor broadcast over its steps (least memory traffic)
        if m * n <= _SMALL_BATCH:
            blocks = [(0, m, F[None, :, 3] - anchors[step_anchor, :, 3])]
        else:
            blocks = [
                (lo, hi, (F[:, 3] - anchors[step_anchor[lo], :, 3])[None])
                for lo, hi in zip(np.r_[0, bounds], np.r_[bounds, m], strict=True)
            ]
        J = np.empty((m, rows, n))
        for lo, hi, r in blocks:  # a × r, then − R (a_l × o_l) below
            Ab, Jb = A[lo:hi], J[lo:hi]
            np.multiply(Ab[:, 1], r[:, 2], out=Jb[:, 0])
            Jb[:, 0] -= Ab[:, 2] * r[:, 1]
            np.multiply(Ab[:, 2], r[:, 0], out=Jb[:, 1])
            Jb[:, 1] -= Ab[:, 0] * r[:, 2]
            np.multiply(Ab[:, 0], r[:, 1], out=Jb[:, 2])
            Jb[:, 2] -= Ab[:, 1] * r[:, 0]
        J[:, :3] -= RC
        if orientation:
            J[:, 3:] = A
        for c in np.flatnonzero(~plan.step_rot[steps]):  # slices: a boolean mask would copy
            J[c, :3] = A[c]
            if orientation:
                J[c, 3:] = 0.0
        if tilt:
            return F, J, self._tilt_columns(F, anchors[1:], perturbations, orientation)
        return F, J

    def _tilt_columns(
        self, F: Array, anchors: Array, perturbations: Array | None, orientation: bool
    ) -> Array:
        """Exact derivatives of the tool pose wrt the joint tilts δα, δβ, ``(dof, 2, rows, n)``.

        After joint ``j`` (axis ``k``, perpendicular axes ``u = k+1``, ``w = k+2``) the
        frame is ``F_j = F Rot_k(θ) Rot_u(δα) Rot_w(δβ)``.  A change of δβ turns the tool
        about ``F_j``'s ``w`` axis; a change of δα about the ``u`` axis of
        ``F Rot_k(θ) Rot_u(δα)``, which is ``cos δβ e_u + sin δβ e_k`` in ``F_j``'s axes.
        Both axes pass through the joint frame's origin.
        """
        plan = self._plan
        n = F.shape[-1]
        rows = 6 if orientation else 3
        out = np.empty((len(anchors), 2, rows, n))
        p_tool = F[:, 3]
        for j, A in enumerate(anchors):
            k = plan.joint_axis[j]
            u, w = (k + 1) % 3, (k + 2) % 3
            a_alpha = A[:, u]
            if perturbations is not None:
                b = perturbations[:, j, 1]
                a_alpha = np.cos(b) * A[:, u] + np.sin(b) * A[:, k]
            r = p_tool - A[:, 3]
            for c, axis in enumerate((a_alpha, A[:, w])):
                out[j, c, :3] = np.cross(axis, r, axis=0)
                if orientation:
                    out[j, c, 3:] = axis
        return out

    def fk_jacobian(
        self,
        q: ArrayLike,
        rows: Literal["position", "pose"] = "position",
        perturbations: ArrayLike | None = None,
        compiled: bool | None = None,
    ) -> tuple[Array, Array]:
        """Tool frames ``(n, 4, 4)`` and the identification Jacobian in one pass.

        See :meth:`jacobian` for the Jacobian's layout, :meth:`fk` for ``compiled``.
        """
        if rows not in ("position", "pose"):
            raise ValueError(f"rows must be 'position' or 'pose', got {rows!r}")
        q, single = self._check_q(q)
        d = self._check_perturbations(perturbations, len(q))
        free = np.flatnonzero(self.free_mask)
        kernels = _kernels(compiled)
        if kernels is not None:
            T, J, _ = self._kernel_evaluate(kernels, q, d, free, 6 if rows == "pose" else 3)
            return (T[0] if single else T), J
        F, J = self._columns(q, d, free, orientation=rows == "pose")
        J = np.ascontiguousarray(J.transpose(2, 1, 0)).reshape(-1, len(free))
        T = _to_homogeneous(F)
        return (T[0] if single else T), J

    def evaluate(
        self,
        q: ArrayLike,
        values: ArrayLike | None = None,
        rows: Literal["position", "pose"] = "position",
        jacobian: bool = True,
        perturbations: ArrayLike | None = None,
        joint_columns: bool = False,
        perturbation_columns: bool = False,
        compiled: bool | None = None,
    ) -> tuple[Array, ...]:
        """Tool frames and identification Jacobian for other parameter values, without
        building a new model (the inner loop of the solvers).

        Args:
            q: ``(n, dof)`` joint values.
            values: all parameter values ``(P,)`` in chain order (default: the model's).
            rows, perturbations: as for :meth:`jacobian`.
            jacobian: whether to compute the Jacobian (columns: :attr:`free_names`).
            joint_columns: also return the joint Jacobian with the same rows
                (``(3n, dof)`` or ``(6n, dof)``): the derivatives with respect to the
                joint values, and so to the δθ joint perturbations.
            perturbation_columns: also return the derivatives with respect to all
                joint perturbations, ``(3n, dof, 3)`` or ``(6n, dof, 3)`` for (δα, δβ, δθ)
                (see :meth:`perturbation_jacobian`).
            compiled: as for :meth:`fk`.

        Returns:
            ``T (n, 4, 4)``, ``J`` (``(3n, p)`` or ``(6n, p)``) or ``None``, the joint
            columns when asked, and the perturbation columns when asked.
        """
        q, _ = self._check_q(q)
        d = self._check_perturbations(perturbations, len(q))
        v = None if values is None else np.asarray(values, dtype=float)
        if v is not None and v.shape != (len(self.steps),):
            raise ValueError(f"values shaped {v.shape}; model {self.name!r} has {len(self.steps)} parameters")
        kernels = _kernels(compiled)
        if kernels is not None:
            return self._evaluate_compiled(
                kernels, q, d, v, rows, jacobian, joint_columns, perturbation_columns
            )
        if not jacobian and not joint_columns and not perturbation_columns:
            F, _ = self._forward(q, d, keep_anchors=False, values=v)
            return _to_homogeneous(F), None
        free = np.flatnonzero(self.free_mask) if jacobian else np.zeros(0, dtype=np.intp)
        need_joints = joint_columns or perturbation_columns
        joints = self._plan.joint_steps if need_joints else np.zeros(0, dtype=np.intp)
        steps = np.union1d(free, joints)
        F, J, *tilt = self._columns(
            q, d, steps, orientation=rows == "pose", values=v, tilt=perturbation_columns
        )
        J = np.ascontiguousarray(J.transpose(2, 1, 0)).reshape(J.shape[2] * J.shape[1], len(steps))
        J_free = J[:, np.searchsorted(steps, free)] if jacobian else None
        out: tuple[Array, ...] = (_to_homogeneous(F), J_free)
        J_joints = J[:, np.searchsorted(steps, joints)] if need_joints else None
        if joint_columns:
            out += (J_joints,)
        if perturbation_columns:
            out += (_perturbation_layout(tilt[0], J_joints),)
        return out

    def _evaluate_compiled(
        self,
        kernels,
        q: Array,
        d: Array | None,
        v: Array | None,
        rows: str,
        jacobian: bool,
        joint_columns: bool,
        perturbation_columns: bool,
    ) -> tuple[Array, ...]:
        """:meth:`evaluate` by the compiled kernels (same returns)."""
        if not jacobian and not joint_columns and not perturbation_columns:
            return self._kernel_forward(kernels, q, d, keep_anchors=False, values=v)[0], None
        free = np.flatnonzero(self.free_mask) if jacobian else np.zeros(0, dtype=np.intp)
        T, J, P = self._kernel_evaluate(
            kernels, q, d, free, 6 if rows == "pose" else 3, v, joint_columns, perturbation_columns
        )
        out: tuple[Array, ...] = (T, J if jacobian else None)
        if joint_columns:
            out += (np.ascontiguousarray(P[:, :, 2]),)
        if perturbation_columns:
            out += (P,)
        return out

    def jacobian(
        self,
        q: ArrayLike,
        rows: Literal["position", "pose"] = "position",
        perturbations: ArrayLike | None = None,
    ) -> Array:
        """Identification Jacobian wrt the free parameters (SI units).

        Returns ``(3n, p)`` for ``rows="position"`` (rows x, y, z of pose 0, then pose
        1, ...) or ``(6n, p)`` for ``rows="pose"`` (x, y, z, ωx, ωy, ωz per pose).
        Columns follow :attr:`free_names`.
        """
        return self.fk_jacobian(q, rows, perturbations)[1]

    def perturbation_jacobian(
        self,
        q: ArrayLike,
        rows: Literal["position", "pose"] = "position",
        perturbations: ArrayLike | None = None,
    ) -> Array:
        """Derivatives of the tool pose wrt the joint perturbations (δα, δβ, δθ),
        ``(n, 3, dof, 3)`` for position rows or ``(n, 6, dof, 3)`` for pose rows
        ``[x, y, z, ωx, ωy, ωz]`` (ω: small rotation in the base frame), exact at the
        given ``perturbations`` ``(n, dof, 3)`` (default zero).  The δθ column is the
        joint Jacobian; the tilt columns turn the tool about the joint frame's
        perpendicular axes (x, y for a joint about z) through its origin."""
        if rows not in ("position", "pose"):
            raise ValueError(f"rows must be 'position' or 'pose', got {rows!r}")
        q, single = self._check_q(q)
        _, _, P = self.evaluate(
            q, rows=rows, jacobian=False, perturbations=perturbations, perturbation_columns=True
        )
        P = P.reshape(len(q), 3 if rows == "position" else 6, self.dof, 3)
        return P[0] if single else P

    def joint_jacobian(self, q: ArrayLike, perturbations: ArrayLike | None = None) -> Array:
        """Geometric Jacobian of the tool frame origin, ``(n, 6, dof)``, rows ``[v; ω]``
        in the base frame (the 6-vector of linear and angular velocity per unit joint rate)."""
        q, single = self._check_q(q)
        d = self._check_perturbations(perturbations, len(q))
        kernels = _kernels(None)
        if kernels is not None:
            J = self._kernel_evaluate(kernels, q, d, self._plan.joint_steps, 6)[1].reshape(
                len(q), 6, self.dof
            )
            return J[0] if single else J
        _, J = self._columns(q, d, self._plan.joint_steps)
        J = np.ascontiguousarray(J.transpose(2, 1, 0))
        return J[0] if single else J


_EYE4 = np.eye(4)


def _kernels(compiled: bool | None):
    """The compiled kernels module when they are to be used, else None (numpy).

    ``compiled``: True requires them, False never uses them, None uses them when numba is
    installed.  The module (and numba) is imported on first use only.
    """
    if compiled is False:
        return None
    if _KERNELS:
        return _KERNELS[0]
    try:
        from robocal.model import kernels
    except ImportError:
        if compiled:
            raise
        return None
    _KERNELS.append(kernels)
    return kernels


_FLOAT64 = np.dtype(np.float64)
_KERNELS: list = []  # the kernels module once imported (a list: no `global` statement needed)


_SMALL_BATCH = 20_000  # steps x poses below which the Jacobian's cross products run over all steps at once


def _cross_rows(a: Array, b: Array) -> Array:
    """Row-wise cross products of ``(m, 3)`` arrays (``np.cross`` costs more in set-up
    than in arithmetic for the few dozen rows of a chain)."""
    out = np.empty_like(a)
    out[:, 0] = a[:, 1] * b[:, 2] - a[:, 2] * b[:, 1]
    out[:, 1] = a[:, 2] * b[:, 0] - a[:, 0] * b[:, 2]
    out[:, 2] = a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]
    return out


def _rotate_rows(F: Array, axis: int, c: Array, s: Array) -> None:
    """In place ``F[:, :3] <- F[:, :3] @ rot(axis, angle)`` for ``F`` ``(3, 4, n)``.

    ``c``, ``s`` are the angle's cosine and sine per pose ``(n,)``.  Only the two
    columns perpendicular to ``axis`` change: six vector operations instead of a
    batched 3x3 product.
    """
    i, j = (axis + 1) % 3, (axis + 2) % 3
    Fi, Fj = F[:, i], F[:, j]  # (3, n) each
    t = Fi * s
    Fi *= c
    Fi += Fj * s
    Fj *= c
    Fj -= t


def _elementaries(axis: NDArray[np.intp], rotation: NDArray[np.bool_], values: Array) -> Array:
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


def _perturbation_layout(tilt: Array, joints: Array) -> Array:
    """Tilt columns ``(dof, 2, rows, n)`` and joint columns ``(n * rows, dof)`` ->
    ``(n * rows, dof, 3)`` in the order (δα, δβ, δθ)."""
    dof, _, rows, n = tilt.shape
    out = np.empty((n, rows, dof, 3))
    out[..., :2] = tilt.transpose(3, 2, 0, 1)
    out[..., 2] = joints.reshape(n, rows, dof)
    return out.reshape(n * rows, dof, 3)


def _to_homogeneous(F: Array) -> Array:
    """Structure-of-arrays frames ``(3, 4, n)`` -> homogeneous ``(n, 4, 4)``."""
    n = F.shape[-1]
    T = np.zeros((n, 4, 4))
    T[:, :3, :] = F.transpose(2, 0, 1)
    T[:, 3, 3] = 1.0
    return T
