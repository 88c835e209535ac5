"""Rigid-body models for Pinocchio built from a chain, and the wrenches at the joints.

Pinocchio does the dynamics (RNEA and friends); this module only translates the
chain: constant steps are folded into joint placements, each joint step becomes a
Pinocchio revolute or prismatic joint about the step's axis (its offset folded into
the placement, since a rotation or translation about one axis composes additively),
and each :class:`~robocal.model.chain.Body` is attached to the joint that moves it.
The chain's end is the operational frame ``"tool"``.

Joint wrenches (seed 003 eqs. 4.21 and 5.14): :func:`joint_wrenches` gives, at every
joint, the full force and moment the joint transmits from its parent link to its
child link — the moment about the joint axis is the joint torque, the two others are
carried by the bearings — in the joint frame (the frame right after the joint step,
:meth:`~robocal.model.chain.Model.joint_frames`; Pinocchio's joint frame ``j + 1``),
for static poses (gravity in any direction, a payload) and along trajectories
(velocities and accelerations: the dynamic recursion of eq. 5.14).  Along trajectories it is
Pinocchio's recursive Newton-Euler algorithm (``pin.rnea``) with the per-joint forces
``data.f[j + 1]`` it leaves behind; for static poses (the calibration's case, every pose of
every load pass) it is the same sum in one vectorised pass over all poses from robocal's
own joint frames (:func:`_static_wrenches`; the tests hold it to RNEA).

Sign: these are *support* wrenches (what the joint applies to hold and move the
link: Craig's ``n_i`` and ``f_i``, eq. 5.14).  Seed 003's static eq. 4.21 writes the
moment of the loads (gravity) on the joint instead, ``η = −n``; the joint effects of
:mod:`robocal.model.joints` deflect along that load moment.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from robocal.model.chain import Model
from robocal.model.chain_plan import check_q, elementaries
from robocal.spatial import elementary

__all__ = ["TOOL_FRAME", "Payload", "gravity_torques", "joint_moments", "joint_wrenches", "to_pinocchio"]

Array = NDArray[np.float64]

TOOL_FRAME = "tool"


def _se3(T: np.ndarray):
    import pinocchio as pin

    return pin.SE3(np.ascontiguousarray(T[:3, :3]), np.ascontiguousarray(T[:3, 3]))


def to_pinocchio(model: Model, gravity: ArrayLike | None = None):  # -> pinocchio.Model
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
    if not model.bodies:
        raise ValueError(f"model {model.name!r} has no mass properties (bodies) to compute gravity torques")
    q_arr, _ = check_q(np.atleast_2d(np.asarray(q, dtype=float)), model)
    W = _static_wrenches(model, q_arr, gravity, None)
    plan = model._plan
    component = np.array(
        [k + (3 if rot else 0) for k, rot in zip(plan.joint_axis, plan.joint_rot, strict=True)]
    )
    return W[:, np.arange(model.dof), component]  # the moment (force) along each joint's axis


@dataclass(frozen=True)
class Payload:
    """A load carried by the tool (a rigid body fixed to the chain's end).

    Attributes:
        mass: kg.
        com: centre of mass (m) in the tool frame.
        inertia: ``(Ixx, Iyy, Izz, Ixy, Ixz, Iyz)`` (kg·m²) about the centre of mass,
            tool axes; ``None``: a point mass.
    """

    mass: float
    com: tuple[float, float, float] = (0.0, 0.0, 0.0)
    inertia: tuple[float, float, float, float, float, float] | None = None

    def __post_init__(self) -> None:
        mass = float(self.mass)
        if not (np.isfinite(mass) and mass >= 0):
            raise ValueError(f"payload mass {self.mass!r} must be finite and >= 0 (kg)")
        com = tuple(float(v) for v in self.com)
        if len(com) != 3 or not np.all(np.isfinite(com)):
            raise ValueError(f"payload com must be 3 finite numbers (m, tool frame), got {self.com!r}")
        object.__setattr__(self, "mass", mass)
        object.__setattr__(self, "com", com)
        if self.inertia is not None:
            inertia = tuple(float(v) for v in self.inertia)
            if len(inertia) != 6 or not np.all(np.isfinite(inertia)):
                raise ValueError("payload inertia must be 6 finite numbers (Ixx, Iyy, Izz, Ixy, Ixz, Iyz)")
            object.__setattr__(self, "inertia", inertia)


def _joint_rates(value: ArrayLike | None, shape: tuple[int, int], what: str) -> Array:
    if value is None:
        return np.zeros(shape)
    a = np.asarray(value, dtype=float)
    if a.ndim == 1:
        a = a[None]
    if a.shape != shape:
        raise ValueError(f"joint {what} shaped {a.shape}; expected {shape} like q")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"joint {what} contain NaN or inf")
    return a


def joint_wrenches(
    model: Model,
    q: ArrayLike,
    qd: ArrayLike | None = None,
    qdd: ArrayLike | None = None,
    *,
    gravity: ArrayLike | None = None,
    payload: Payload | None = None,
) -> Array:
    """Force and moment transmitted by every joint, in its joint frame, ``(n, dof, 6)``.

    Rows ``[fx, fy, fz, ηx, ηy, ηz]``: the force (N) and the moment (N·m) about the
    joint frame's origin that joint ``j`` applies to the links beyond it (support
    wrench, eq. 5.14's ``f_i``, ``n_i``), expressed in the frame right after the joint
    step (``model.joint_frames(q)[:, j]``).  The component along the joint axis is the
    joint torque (force for a prismatic joint); the others are carried by the
    bearings.  Seed 003's eq. 4.21 load moment is ``−η``.

    Static poses (``qd``, ``qdd`` zero or not given): one vectorised pass over all poses
    from the chain's joint frames; otherwise Pinocchio's recursive Newton-Euler algorithm on
    :func:`to_pinocchio`'s model (one C++ call per pose).

    Args:
        model: the chain with mass properties (``model.bodies``).
        q: ``(n, dof)`` joint values (rad, m); ``(dof,)`` for one pose.
        qd, qdd: joint velocities (rad/s, m/s) and accelerations (rad/s², m/s²) like
            ``q``; default zero (static poses).
        gravity: gravity in the robot's base frame (m/s²), default ``[0, 0, -9.81]``.
        payload: a load fixed to the tool frame.

    Returns:
        ``(n, dof, 6)`` (``(dof, 6)`` for a 1-D ``q``).
    """
    if not model.bodies and (payload is None or payload.mass == 0):
        raise ValueError(f"model {model.name!r} has no mass properties (bodies) to compute joint wrenches")
    q_arr = np.asarray(q, dtype=float)
    single = q_arr.ndim == 1
    q_arr, _ = check_q(q_arr, model)
    shape = q_arr.shape
    v = _joint_rates(qd, shape, "velocities")
    a = _joint_rates(qdd, shape, "accelerations")
    if v.any() or a.any():
        out = _rnea_wrenches(model, q_arr, v, a, gravity, payload)
    else:  # at rest: all poses at once (tests/test_dynamics.py holds it to RNEA)
        out = _static_wrenches(model, q_arr, gravity, payload)
    return out[0] if single else out


def _rnea_wrenches(
    model: Model, q: Array, v: Array, a: Array, gravity: ArrayLike | None, payload: Payload | None
) -> Array:
    """:func:`joint_wrenches` by Pinocchio's RNEA, one call per pose ``(n, dof, 6)``: the
    dynamic case, and the reference of :func:`_static_wrenches` in the tests."""
    import pinocchio as pin

    pm = to_pinocchio(model, gravity)
    if payload is not None and payload.mass > 0:
        tool = pm.frames[pm.getFrameId(TOOL_FRAME)]
        Ixx, Iyy, Izz, Ixy, Ixz, Iyz = payload.inertia or (0.0,) * 6
        inertia = np.array([[Ixx, Ixy, Ixz], [Ixy, Iyy, Iyz], [Ixz, Iyz, Izz]])
        pm.appendBodyToJoint(
            tool.parentJoint, pin.Inertia(payload.mass, np.array(payload.com), inertia), tool.placement
        )
    data = pm.createData()
    dof = model.dof
    out = np.empty((len(q), dof, 6))
    for k in range(len(q)):  # one Pinocchio RNEA per pose (C++; a few µs)
        pin.rnea(pm, data, q[k], v[k], a[k])
        for j in range(dof):
            out[k, j] = data.f[j + 1].vector
    return out


def _mass_points(model: Model, payload: Payload | None) -> tuple[NDArray[np.intp], Array, Array]:
    """The chain's masses as points fixed to joint frames: the joint each hangs from, its
    mass (kg) and its centre (m) in that joint's frame, ``(b,)``, ``(b,)``, ``(b, 3)``.

    Bodies before the first joint are left out, as in :func:`to_pinocchio`; a payload hangs
    from the last joint at the tool frame.
    """

    plan = model._plan
    seg_T, local = model._segments  # frames before each step in their joint's frame (cached)
    steps = np.array([model._index[b.frame] for b in model.bodies], dtype=np.intp)
    # the frame after each body's step in its joint's frame: local @ the step's own transform
    # (identity for a joint step: the joint frame itself)
    after = local[steps] @ elementaries(plan.step_axis[steps], plan.step_rot[steps], model.values[steps])
    after[plan.step_joint[steps]] = np.eye(4)
    masses = [b.mass for b in model.bodies]
    centres = [T[:3, :3] @ np.asarray(b.com) + T[:3, 3] for T, b in zip(after, model.bodies, strict=True)]
    hung = (plan.anchor_of[steps] - 1 + plan.step_joint[steps]).tolist()  # the joint each body hangs from
    if payload is not None and payload.mass > 0:
        hung.append(model.dof - 1)
        masses.append(payload.mass)
        centres.append(seg_T[-1][:3, :3] @ np.asarray(payload.com) + seg_T[-1][:3, 3])
    keep = [k for k, j in enumerate(hung) if j >= 0]  # bodies before the first joint: fixed
    joints = np.array([hung[k] for k in keep], dtype=np.intp)
    masses = [masses[k] for k in keep]
    centres = [centres[k] for k in keep]
    return joints, np.array(masses), np.array(centres).reshape(-1, 3)


def _static_wrenches(model: Model, q: Array, gravity: ArrayLike | None, payload: Payload | None) -> Array:
    """:func:`joint_wrenches` at rest for all poses in one vectorised pass, ``(n, dof, 6)``.

    At rest every mass only needs holding against gravity, so the support wrench at joint
    ``j`` is the sum over the masses beyond it: force ``f = −M_j g`` and moment
    ``(S_j − M_j o_j) × (−g)`` about the joint frame's origin ``o_j``, with ``M_j`` the mass
    beyond joint ``j`` and ``S_j`` its first moment ``Σ m c`` (centres in the base frame),
    both running sums from the tool back; then rotated into the joint frame.  This is what
    RNEA computes with zero velocities and accelerations (Featherstone, *Rigid Body Dynamics
    Algorithms*, 2008, sect. 5.3), written over the poses so that a calibration's load pass
    costs a few µs per pose instead of one Pinocchio call and model per pose.  With numba
    the same sums run compiled (:func:`robocal.model.kernels.static_wrenches`), else in numpy
    below; the tests hold both to RNEA.
    """
    g = np.array([0.0, 0.0, -9.81]) if gravity is None else np.asarray(gravity, dtype=float)
    if g.shape != (3,) or not np.all(np.isfinite(g)):
        raise ValueError(f"gravity must be 3 finite numbers (m/s², base frame), got {gravity!r}")
    joints, masses, centres = _mass_points(model, payload)
    n, dof = q.shape
    from robocal.model.chain import kernels_loader

    kernels = kernels_loader(None)
    if kernels is not None:  # compiled: one pass per pose, no numpy call per joint
        order = np.argsort(joints, kind="stable")
        plan = model._plan
        seg, _, offsets = model._kernel_segments
        return kernels.static_wrenches(
            np.ascontiguousarray(q),
            seg,
            offsets,
            plan.joint_axis_array,
            plan.joint_rot_array,
            np.ascontiguousarray(joints[order]),
            np.ascontiguousarray(masses[order]),
            np.ascontiguousarray(centres[order]),
            g,
        )
    _, anchors = model._forward(q, None, keep_anchors=True)  # (dof + 1, 3, 4, n), [R | p] rows
    assert anchors is not None  # keep_anchors
    frames = anchors[1:]  # the frame after joint j: (dof, 3, 4, n)
    R, o = frames[:, :, :3], frames[:, :, 3]  # (dof, 3, 3, n), (dof, 3, n)
    # masses and first moments hanging from each joint, then summed from the tool back
    M = np.zeros(dof)
    S = np.zeros((dof, 3, n))
    for joint, mass, centre in zip(joints, masses, centres, strict=True):
        M[joint] += mass
        S[joint] += mass * (
            R[joint, :, 0] * centre[0] + R[joint, :, 1] * centre[1] + R[joint, :, 2] * centre[2]
        )
        S[joint] += mass * o[joint]
    M = np.cumsum(M[::-1])[::-1]  # beyond each joint: running sums from the tool back
    S = np.cumsum(S[::-1], axis=0)[::-1]
    lever = S - M[:, None, None] * o  # (dof, 3, n): Σ m (c − o_j)
    moment = np.empty_like(lever)  # lever × (−g)
    moment[:, 0] = lever[:, 2] * g[1] - lever[:, 1] * g[2]
    moment[:, 1] = lever[:, 0] * g[2] - lever[:, 2] * g[0]
    moment[:, 2] = lever[:, 1] * g[0] - lever[:, 0] * g[1]
    out = np.empty((n, dof, 6))
    # into the joint frames: component k is column k of R dotted with the vector
    force = -g[None, :, None] * M[:, None, None]  # (dof, 3, 1)
    out[..., :3] = (R * force[:, :, None]).sum(axis=1).transpose(2, 0, 1)
    out[..., 3:] = (R * moment[:, :, None]).sum(axis=1).transpose(2, 0, 1)
    return out


def joint_moments(
    model: Model,
    q: ArrayLike,
    qd: ArrayLike | None = None,
    qdd: ArrayLike | None = None,
    *,
    gravity: ArrayLike | None = None,
    payload: Payload | None = None,
) -> Array:
    """The moment part ``[ηx, ηy, ηz]`` (N·m) of :func:`joint_wrenches`, ``(n, dof, 3)``."""
    return joint_wrenches(model, q, qd, qdd, gravity=gravity, payload=payload)[..., 3:]
