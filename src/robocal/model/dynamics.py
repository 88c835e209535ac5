"""Rigid-body models for Pinocchio built from a chain (joint wrenches build on this).

Pinocchio does the dynamics (RNEA and friends); this module only translates the
chain: constant steps are folded into joint placements, each joint step becomes a
Pinocchio revolute or prismatic joint about the step's axis (its offset folded into
the placement, since a rotation or translation about one axis composes additively),
and each :class:`~robocal.model.chain.Body` is attached to the joint that moves it.
The chain's end is the operational frame ``"tool"``.
"""

from __future__ import annotations

import numpy as np

from robocal.model.chain import Model
from robocal.spatial import elementary

__all__ = ["TOOL_FRAME", "to_pinocchio"]

TOOL_FRAME = "tool"


def _se3(T: np.ndarray):
    import pinocchio as pin

    return pin.SE3(np.ascontiguousarray(T[:3, :3]), np.ascontiguousarray(T[:3, 3]))


def to_pinocchio(model: Model, gravity: np.ndarray | None = None):
    """A ``pinocchio.Model`` equivalent to ``model`` at its current parameter values.

    Joint ``j`` of robocal is Pinocchio joint ``j + 1`` (0 is the universe); the
    Pinocchio configuration vector equals robocal's ``q``.  Bodies before the first
    joint are fixed to the universe and carry no dynamics.

    Args:
        model: the chain.
        gravity: gravity vector in the base frame (m/s²), default ``[0, 0, -9.81]``.
    """
    import pinocchio as pin  # imported lazily: a heavy import few commands need

    joint_models = {
        "Rx": pin.JointModelRX,
        "Ry": pin.JointModelRY,
        "Rz": pin.JointModelRZ,
        "Tx": pin.JointModelPX,
        "Ty": pin.JointModelPY,
        "Tz": pin.JointModelPZ,
    }
    pm = pin.Model()
    pm.name = model.name
    parent = 0
    placement = np.eye(4)  # from the parent joint frame to the current step
    frame_of_step: dict[str, tuple[int, np.ndarray]] = {}
    for step in model.steps:
        if step.joint is None:
            placement = placement @ elementary(step.motion, step.value)
            frame_of_step[step.name] = (parent, placement.copy())
            continue
        placement = placement @ elementary(step.motion, step.value)  # the joint offset
        limits = step.joint.limits or (-np.inf, np.inf)
        parent = pm.addJoint(
            parent,
            joint_models[step.motion](),
            _se3(placement),
            step.joint.name,
            np.array([np.inf]),
            np.array([np.inf]),
            np.array([limits[0]]),
            np.array([limits[1]]),
        )
        placement = np.eye(4)
        frame_of_step[step.name] = (parent, placement.copy())
    pm.addFrame(pin.Frame(TOOL_FRAME, parent, 0, _se3(placement), pin.FrameType.OP_FRAME))
    for body in model.bodies:
        joint, T = frame_of_step[body.frame]
        if joint == 0:
            continue
        Ixx, Iyy, Izz, Ixy, Ixz, Iyz = body.inertia or (0.0,) * 6
        inertia = np.array([[Ixx, Ixy, Ixz], [Ixy, Iyy, Iyz], [Ixz, Iyz, Izz]])
        pm.appendBodyToJoint(joint, pin.Inertia(body.mass, np.array(body.com), inertia), _se3(T))
    pm.gravity = pin.Motion(
        np.array([0.0, 0.0, -9.81]) if gravity is None else np.asarray(gravity, float), np.zeros(3)
    )
    return pm


def gravity_torques(model, q: np.ndarray, gravity: np.ndarray | None = None) -> np.ndarray:
    """Static joint torques (N·m, or N for prismatic joints) that hold ``model`` against
    gravity at joint values ``q`` ``(n, dof)``: Pinocchio's generalized gravity, ``(n, dof)``.

    Needs the model's mass properties (:class:`~robocal.model.chain.Body`).
    """
    import pinocchio as pin

    if not model.bodies:
        raise ValueError(f"model {model.name!r} has no mass properties (bodies) to compute gravity torques")
    pm = to_pinocchio(model, gravity)
    data = pm.createData()
    q = np.atleast_2d(np.asarray(q, dtype=float))
    return np.array([pin.computeGeneralizedGravity(pm, data, qk) for qk in q])
