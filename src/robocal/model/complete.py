"""A robot's calibration model: the complete, minimal, continuous chain of seed 000,
built from the joint geometry of any chain (a catalog robot's DH table, a model file).

The catalog describes robots the way their makers publish them (standard or modified
DH, ...), which is the right description for the controller but not for calibration:
DH is singular for parallel axes (UR10 joints 2-4, the shoulder and elbow of most
industrial arms), so a tiny tilt of such an axis cannot be represented and the
identification goes wrong (seed 000 eqs. 6-8).  :func:`calibration_model` reads every
joint's axis line and the tool at q = 0 from the chain (:func:`geometry_from_model`)
and lets seed 000's builder (:func:`robocal.model.builder.build`) make the calibration
model from it; the mass properties and the joint effects are carried over unchanged
(the bodies re-expressed in frames of the same links), so the complete model is the
same robot: same FK, same gravity torques.
"""

from __future__ import annotations

import dataclasses
from functools import cache, lru_cache
from typing import Literal

import numpy as np

from robocal.model.builder import BuildResult, build
from robocal.model.chain import Model
from robocal.model.geometry import JointGeometry, Tcp
from robocal.model.steps import Body, JointType

__all__ = ["build_complete", "calibration_model", "geometry_from_model"]

Measure = Literal["position", "pose"]


def geometry_from_model(model: Model) -> tuple[list[JointGeometry], Tcp]:
    """The joint geometry of a chain at q = 0, as :func:`~robocal.model.builder.build` takes it.

    Every joint's axis line is read from its frame at q = 0 (the frame right after the
    joint step: the step's local x, y or z axis is the direction of rotation or motion,
    its origin a point on the line); the joint's name, type and limits are kept.  The
    tool is the chain's end frame at q = 0 (position relative to the last joint's point,
    orientation in the base frame).  Joint offsets and conventions are forgotten: only
    the geometry is left, so building from it gives the same robot at every q.
    """
    if model.dof == 0:
        raise ValueError(f"model {model.name!r} has no joints")
    frames = model.joint_frames(np.zeros(model.dof))
    joint_steps = [(s, s.joint) for s in model.steps if s.joint is not None]
    joints = []
    previous = np.zeros(3)
    for F, (step, joint) in zip(frames, joint_steps, strict=True):
        point = F[:3, 3]
        x, y, z = (point - previous).tolist()
        ax, ay, az = F[:3, step.axis].tolist()
        kind: JointType = "revolute" if step.is_rotation else "prismatic"  # Step.joint_type of a joint
        joints.append(JointGeometry(kind, (x, y, z), (ax, ay, az), joint.name, joint.limits))
        previous = point
    T = model.fk(np.zeros(model.dof))
    tcp = Tcp(tuple((T[:3, 3] - previous).tolist()), tuple(map(tuple, T[:3, :3].tolist())))
    return joints, tcp


def _link_of_steps(model: Model) -> dict[str, int]:
    """Which link each step's frame is attached to: 0 = the base, j = moved by joint j (1-based)."""
    link, out = 0, {}
    for step in model.steps:
        if step.joint is not None:
            link += 1
        out[step.name] = link
    return out


def _body_frames(model: Model) -> dict[int, str]:
    """The step frame that carries each link's bodies in the built model: the last step
    before the next joint (a frame on the next joint's axis, like a DH link frame) and, for
    the last link, its joint step (on the last axis, independent of the tool)."""
    link_of = _link_of_steps(model)
    chosen: dict[int, str] = {}
    for step in model.steps:
        link = link_of[step.name]
        if link < model.dof or step.joint is not None:
            chosen[link] = step.name
    return chosen


def _carry_bodies(source: Model, target: Model) -> tuple[Body, ...]:
    """``source``'s bodies re-expressed in frames of ``target`` attached to the same links."""
    if not source.bodies:
        return ()
    from robocal.model.view import step_frames  # frames after every step at q = 0

    old_frames = dict(zip(source.names, step_frames(source)[1:], strict=True))
    new_frames = dict(zip(target.names, step_frames(target)[1:], strict=True))
    old_link, chosen = _link_of_steps(source), _body_frames(target)
    bodies = []
    for body in source.bodies:
        frame = chosen[old_link[body.frame]]
        T = np.linalg.inv(new_frames[frame]) @ old_frames[body.frame]  # new frame <- old frame
        R = T[:3, :3]
        com = R @ np.asarray(body.com) + T[:3, 3]
        inertia = None
        if body.inertia is not None:
            Ixx, Iyy, Izz, Ixy, Ixz, Iyz = body.inertia
            I_new = R @ np.array([[Ixx, Ixy, Ixz], [Ixy, Iyy, Iyz], [Ixz, Iyz, Izz]]) @ R.T
            d = np.diag(I_new).tolist()
            inertia = (d[0], d[1], d[2], float(I_new[0, 1]), float(I_new[0, 2]), float(I_new[1, 2]))
        x, y, z = com.tolist()
        bodies.append(dataclasses.replace(body, frame=frame, com=(x, y, z), inertia=inertia))
    return tuple(bodies)


@cache
def _catalog_calibration_model(name: str, measure: Measure) -> Model:
    from robocal.model.catalog import robot

    return _complete(robot(name), measure, f"the catalog model {name!r}")


def build_complete(model: Model, measure: Measure = "pose", origin: str | None = None) -> BuildResult:
    """:func:`robocal.model.builder.build` on ``model``'s joint geometry, with the model's
    bodies (re-expressed) and joint effects on the built model; the links and rank as
    the builder reports them (:func:`calibration_model` returns its ``model``)."""
    origin = origin or f"the model {model.name!r}"
    joints, tcp = geometry_from_model(model)
    note = f"built by the rules of Motta 2005 (seed 000) from the joint geometry of {origin}"
    title = f"{model.title or model.name} — complete model ({measure})"
    source = f"{note}; {model.source}".strip().rstrip(";") if model.source else note
    built = build(joints, tcp, measure, name=f"{model.name}_complete", title=title, source=source)
    # built.warnings: a chain that ends on its last joint axis (at the flange) measured in
    # position only leaves that joint's offset to the tool calibrate adds; nothing to do here
    complete = dataclasses.replace(
        built.model,
        bodies=_carry_bodies(model, built.model),
        joint_effects=model.joint_effects,
    )
    return dataclasses.replace(built, model=complete)


def _complete(model: Model, measure: Measure, origin: str) -> Model:
    return build_complete(model, measure, origin).model


def calibration_model(model_or_name: Model | str, measure: Measure = "position") -> Model:
    """The model to calibrate a robot with: the documented way to get it.

    The complete, minimal, continuous chain of seed 000 (DH for perpendicular axes,
    Hayati for parallel ones; exactly 4R + 2P + 6 identifiable parameters for ``"pose"``
    measurements, 4R + 2P + 3 for ``"position"``), built from the joint geometry of a
    catalog robot (by name, e.g. ``"ur10"``) or of any model, named ``"<name>_complete"``.
    The joint names and limits, the mass properties (re-expressed in the new link
    frames) and the joint effects are carried over: it is the same robot, FK and gravity
    torques included, only parameterised so that every small real deviation has a small
    parameter change to describe it.

    ``rc.robot(name)`` still returns the catalog's chain as published (e.g. plain DH),
    which is what a controller uses; ``robocal calibrate NAME`` calibrates this
    model by default (``--chain catalog`` for the published chain).

    Args:
        model_or_name: a catalog robot's name or a :class:`~robocal.model.chain.Model`.
        measure: ``"position"`` (only the tool's position is measured) or ``"pose"``
            (its orientation too): decides the tool's parameters and which are free.
    """
    if measure not in ("position", "pose"):
        raise ValueError(f"measure must be 'position' or 'pose', got {measure!r}")
    if isinstance(model_or_name, str):
        from robocal.model.catalog import robot

        return _catalog_calibration_model(robot(model_or_name).name, measure)
    if not isinstance(model_or_name, Model):
        raise TypeError(f"calibration_model takes a Model or a catalog robot's name, got {model_or_name!r}")
    return _model_calibration_model(model_or_name, measure)


@lru_cache(maxsize=16)
def _model_calibration_model(model: Model, measure: Measure) -> Model:
    """Models are immutable (and hashable), so a fleet of files of one robot builds once."""
    return _complete(model, measure, f"the model {model.name!r}")
