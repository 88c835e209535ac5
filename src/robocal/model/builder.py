"""Seed 000: complete, minimal, singularity-free calibration models from joint geometry.

The user describes the robot at its zero position, joint by joint: the type
(revolute/prismatic), the position of the joint relative to the previous joint (base
coordinates) and the axis direction (positive rotation or motion sense), then the
tool centre point.  No DH convention is needed.  The builder

1. places a frame on every joint axis (z along the axis), following seed 000's
   rules: the base frame is the world frame; a frame's origin is the intersection of
   consecutive axes when they intersect, the foot of their common normal when they are
   skew, and the distal joint's position when they are parallel;
2. chooses each link's parameterisation from seed 000's table, eqs. (11)-(27):
   base → first joint (11)-(15), consecutive joints (16)-(23) — DH for ⊥ axes,
   Hayati for ∥ axes — and last joint → TCP (24)-(27), the bracketed orientation
   parameters only when the tool orientation is measured;
3. marks the identifiable parameters ("bold" in the seed): exactly 4R + 2P + 6 for
   full-pose and 4R + 2P + 3 for position measurement (Everett, Driels & Mooring).

Parallel or perpendicular is decided per pair by the angle between the axes: below
``parallel_tolerance`` (default 45°) the pair counts as parallel.  So a nearly
parallel pair gets the Hayati parameterisation and a nearly perpendicular pair gets
DH, each at least 45° away from its singular manifold (seed 000 eqs. 6 and 8).

Which redundant parameter of a pair is fixed is decided by a sequential rank test
over the identification Jacobian at random configurations, in chain order, with the
parameters that seed 000 never marks deferred to the end: the trailing translation
of each link along the next joint axis (it duplicates the next link's offset along
that axis) and the last joint's offset (absorbed by the TCP coordinates).  The test
cannot be fooled by a special geometry: whatever is kept is full rank by
construction, and the count is checked against the formula.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, ValidationError

from robocal import spatial
from robocal.model.chain import Joint, Model, Step
from robocal.model.conventions import SCHROER_SETS
from robocal.model.files import Number
from robocal.units import ANGLE_UNITS, LENGTH_UNITS

__all__ = [
    "BuildResult",
    "GeometryError",
    "JointGeometry",
    "LinkInfo",
    "Tcp",
    "build",
    "build_model",
    "geometry_fk",
    "load_geometry",
]

JointType = Literal["revolute", "prismatic"]
Measure = Literal["position", "pose"]

DEFAULT_PARALLEL_TOLERANCE = math.radians(45.0)


class GeometryError(ValueError):
    """The joint geometry is invalid; the message names the joint."""


@dataclass(frozen=True)
class JointGeometry:
    """One joint at the robot's zero position (SI units).

    Attributes:
        type: ``"revolute"`` or ``"prismatic"``.
        position: origin relative to the previous joint's origin (joint 1: relative to
            the base origin), base coordinates, m.
        axis: direction in base coordinates: positive rotation (right-hand) or motion.
        name: joint name (default ``q1``, ``q2``...).
        limits: ``(lower, upper)`` in rad or m.
    """

    type: JointType
    position: tuple[float, float, float]
    axis: tuple[float, float, float]
    name: str | None = None
    limits: tuple[float, float] | None = None


@dataclass(frozen=True)
class Tcp:
    """The tool centre point at zero: position relative to the last joint's origin (base
    coordinates, m) and optionally its orientation in the base frame (3x3)."""

    position: tuple[float, float, float]
    rotation: tuple[tuple[float, ...], ...] | None = None


@dataclass(frozen=True)
class LinkInfo:
    """How one link was parameterised."""

    index: int  # 0 = base -> joint 1, i = joint i -> joint i+1, n = joint n -> TCP
    kind: str  # e.g. "R⊥R", "B∥R", "R∥TCP"
    equation: int  # seed 000 equation number
    parameters: tuple[str, ...]

    @property
    def label(self) -> str:
        names = {16: "Denavit-Hartenberg", 17: "Hayati"}
        extra = f", {names[self.equation]}" if self.equation in names else ""
        return f"{self.kind} (seed 000 eq. {self.equation}{extra})"


@dataclass(frozen=True)
class BuildResult:
    """The built model and how it was made."""

    model: Model
    links: tuple[LinkInfo, ...]
    measure: Measure
    expected_free: int  # 4R + 2P + 6 (pose) or + 3 (position)
    rank: int  # numeric rank of the identification Jacobian over sampled poses
    dropped: tuple[str, ...] = field(default=())  # parameters fixed as redundant
    warnings: tuple[str, ...] = field(default=())

    @property
    def complete_and_minimal(self) -> bool:
        return self.rank == self.expected_free == len(self.model.free_names)


# --------------------------------------------------------------------- validation
def _unit(v: np.ndarray, what: str) -> np.ndarray:
    norm = float(np.linalg.norm(v))
    if not math.isfinite(norm) or norm < 1e-12:
        raise GeometryError(f"{what}: axis {v.tolist()} has zero length")
    return v / norm


def _normalise(joints: Sequence[JointGeometry | Mapping[str, Any]], tcp) -> tuple[list[JointGeometry], Tcp]:
    if len(joints) < 1:
        raise GeometryError("the robot needs at least one joint")
    out: list[JointGeometry] = []
    for j, raw in enumerate(joints):
        g = raw if isinstance(raw, JointGeometry) else JointGeometry(**dict(raw))
        label = f"joint {j + 1}" + (f" ({g.name})" if g.name else "")
        if g.type not in ("revolute", "prismatic"):
            raise GeometryError(f"{label}: type must be 'revolute' or 'prismatic', got {g.type!r}")
        pos = np.asarray(g.position, dtype=float)
        axis = np.asarray(g.axis, dtype=float)
        if pos.shape != (3,) or axis.shape != (3,):
            raise GeometryError(f"{label}: position and axis must have 3 components")
        if not (np.all(np.isfinite(pos)) and np.all(np.isfinite(axis))):
            raise GeometryError(f"{label}: position/axis contain NaN or inf")
        axis = _unit(axis, label)
        out.append(
            JointGeometry(g.type, tuple(pos.tolist()), tuple(axis.tolist()), g.name or f"q{j + 1}", g.limits)
        )
    names = [g.name for g in out]
    for name in names:
        if names.count(name) > 1:
            raise GeometryError(f"joint name {name!r} is used twice")
    # coincident identical axes: two consecutive revolute joints on the same line
    origin = np.zeros(3)
    origins = []
    for g in out:
        origin = origin + np.asarray(g.position)
        origins.append(origin)
    for j in range(len(out) - 1):
        a, b = out[j], out[j + 1]
        za, zb = np.asarray(a.axis), np.asarray(b.axis)
        if a.type == b.type == "revolute" and abs(abs(za @ zb) - 1) < 1e-12:
            offset = origins[j + 1] - origins[j]
            if np.linalg.norm(offset - (offset @ za) * za) < 1e-9:
                raise GeometryError(
                    f"joint {j + 2} ({b.name}) turns about the same line as joint {j + 1} ({a.name}): "
                    "coincident revolute axes cannot be told apart"
                )
    if tcp is None:
        tcp = Tcp((0.0, 0.0, 0.0))
    elif not isinstance(tcp, Tcp):
        if isinstance(tcp, Mapping):
            tcp = Tcp(tuple(tcp["position"]), tcp.get("rotation"))
        else:
            tcp = Tcp(tuple(np.asarray(tcp, dtype=float).tolist()))
    p = np.asarray(tcp.position, dtype=float)
    if p.shape != (3,) or not np.all(np.isfinite(p)):
        raise GeometryError(f"tcp: position must be 3 finite numbers, got {tcp.position!r}")
    if tcp.rotation is not None:
        R = np.asarray(tcp.rotation, dtype=float)
        if R.shape != (3, 3) or not np.allclose(R @ R.T, np.eye(3), atol=1e-9) or np.linalg.det(R) < 0:
            raise GeometryError("tcp: rotation must be a proper 3x3 rotation matrix")
    return out, tcp


# --------------------------------------------------------------------- geometry
def _absolute(joints: Sequence[JointGeometry]) -> tuple[np.ndarray, np.ndarray]:
    """Absolute joint points ``(n, 3)`` and unit axes ``(n, 3)`` in the base frame."""
    points = np.cumsum([g.position for g in joints], axis=0)
    axes = np.array([g.axis for g in joints], dtype=float)
    return points, axes


def geometry_fk(joints: Sequence[JointGeometry | Mapping[str, Any]], tcp, q: np.ndarray) -> np.ndarray:
    """Tool frames ``(n, 4, 4)`` of the geometry itself, by the product of exponentials.

    An independent reference for the built model: each joint is a screw about (or along)
    its axis line through its point; the tool frame at zero is the TCP position with
    its given orientation (identity when none is given).
    """
    joints, tcp = _normalise(joints, tcp)
    points, axes = _absolute(joints)
    q = np.atleast_2d(np.asarray(q, dtype=float))
    n = len(q)
    T = np.broadcast_to(np.eye(4), (n, 4, 4)).copy()
    for j, g in enumerate(joints):
        if g.type == "revolute":
            R = spatial.rotvec_to_matrix(axes[j] * q[:, j, None])
            p = points[j] - R @ points[j]
        else:
            R = np.broadcast_to(np.eye(3), (n, 3, 3))
            p = axes[j] * q[:, j, None]
        T = T @ spatial.homogeneous(R, p)
    M = spatial.homogeneous(
        np.eye(3) if tcp.rotation is None else np.asarray(tcp.rotation, dtype=float),
        points[-1] + np.asarray(tcp.position),
    )
    return T @ M


def _align_xy(z: np.ndarray) -> tuple[float, float]:
    """Angles (α, β) with Rx(α) Ry(β) e_z = z (Hayati-style alignment of a near-z axis)."""
    beta = math.asin(float(np.clip(z[0], -1.0, 1.0)))
    alpha = math.atan2(-z[1], z[2])
    return alpha, beta


def _align_zx(z: np.ndarray) -> tuple[float, float]:
    """Angles (γ, α) with Rz(γ) Rx(α) e_z = z (DH-style alignment: x along e_z × z)."""
    s = math.hypot(z[0], z[1])
    gamma = math.atan2(z[0], -z[1]) if s > 1e-15 else 0.0
    alpha = math.atan2(s, z[2])
    return gamma, alpha


def _common_normal(c: np.ndarray, z: np.ndarray) -> tuple[float, float, np.ndarray]:
    """Common normal between the local z axis and the line ``c + s z`` (not parallel).

    Returns ``t`` (foot on the z axis at ``t e_z``), ``s`` (foot ``c + s z``) and the
    unit normal ``n = e_z × z / |e_z × z|``.
    """
    b = z[2]
    den = 1.0 - b * b
    d = -c[2]
    e = -(c @ z)
    t = (b * e - d) / den
    s = (e - b * d) / den
    n = np.array([-z[1], z[0], 0.0]) / math.hypot(z[0], z[1])
    return t, s, n


# --------------------------------------------------------------------- link sets
class _ChainBuilder:
    """Accumulates steps and the current frame (base coordinates, at q = 0)."""

    def __init__(self, tolerance: float) -> None:
        self.steps: list[Step] = []
        self.frame = np.eye(4)
        self.cos_tol = math.cos(tolerance)
        self.links: list[LinkInfo] = []
        self.deferred: list[str] = []  # parameters seed 000 never marks

    def local(self, point: np.ndarray, axis: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        R, p = self.frame[:3, :3], self.frame[:3, 3]
        return R.T @ (point - p), R.T @ axis

    def parallel(self, z_local: np.ndarray) -> bool:
        return abs(z_local[2]) >= self.cos_tol

    def add(self, index: int, kind: str, equation: int, names, values, joint: Joint | None = None) -> None:
        motions = SCHROER_SETS[equation]
        if len(names) != len(motions) or len(values) != len(motions):
            raise AssertionError(f"eq. {equation}: {len(motions)} motions, got {len(names)} names")
        for k, (motion, name, value) in enumerate(zip(motions, names, values, strict=True)):
            driven = joint if (k == 0 and equation >= 16) else None
            self.steps.append(Step(motion, name, float(value), joint=driven))
            self.frame = self.frame @ spatial.elementary(motion, value)
        self.links.append(LinkInfo(index, kind, equation, tuple(names)))


def _base_link(b: _ChainBuilder, point: np.ndarray, axis: np.ndarray, kind: JointType) -> None:
    """Base frame → first joint, seed 000 eqs. (11)-(15)."""
    c, z = point, axis
    if kind == "prismatic":
        if abs(z[2]) >= b.cos_tol:  # eq. (12) B ∥ JT
            alpha, beta = _align_xy(z)
            b.add(0, "B∥T", 12, ["base_x", "base_y", "base_z", "base_rx", "base_ry"], [*c, alpha, beta])
        else:  # eq. (11) B ⊥ JT
            gamma, alpha = _align_zx(z)
            b.add(0, "B⊥T", 11, ["base_x", "base_y", "base_z", "base_rz", "base_rx"], [*c, gamma, alpha])
        return
    k = int(np.argmax(np.abs(z)))
    s0 = -c[k] / z[k]
    P = c + s0 * z  # where the axis pierces the base plane normal to the nearest base axis
    if k == 2:  # eq. (15) B ∥ JR
        alpha, beta = _align_xy(z)
        b.add(0, "B∥R", 15, ["base_x", "base_y", "base_rx", "base_ry"], [P[0], P[1], alpha, beta])
    else:
        gamma, alpha = _align_zx(z)
        if k == 0:  # eq. (13) axis near x
            b.add(0, "B⊥R(x)", 13, ["base_y", "base_z", "base_rz", "base_rx"], [P[1], P[2], gamma, alpha])
        else:  # eq. (14) axis near y
            b.add(0, "B⊥R(y)", 14, ["base_x", "base_z", "base_rz", "base_rx"], [P[0], P[2], gamma, alpha])


def _joint_link(
    b: _ChainBuilder, i: int, kind: JointType, joint: Joint, nxt: JointGeometry, point, axis
) -> None:
    """Joint i → joint i+1, seed 000 eqs. (16)-(23).  ``i`` is 1-based."""
    c, z = b.local(point, axis)
    par = b.parallel(z)
    j = i + 1
    if nxt.type == "revolute":
        if not par:
            t, s, n = _common_normal(c, z)
            theta = math.atan2(n[1], n[0])
            foot_b = c + s * z
            a = float((foot_b - np.array([0.0, 0.0, t])) @ n)
            alpha = math.atan2(math.hypot(z[0], z[1]), z[2])
            if kind == "revolute":  # eq. (16) DH
                names = [f"theta{i}", f"d{i}", f"a{i}", f"alpha{i}", f"p{j}"]
                b.add(i, "R⊥R", 16, names, [theta, t, a, alpha, 0.0], joint)
            else:  # eq. (18)
                names = [f"d{i}", f"theta{i}", f"a{i}", f"alpha{i}", f"p{j}"]
                b.add(i, "T⊥R", 18, names, [t, theta, a, alpha, 0.0], joint)
        else:
            s0 = -c[2] / z[2]
            P = c + s0 * z  # axis i+1 pierces the plane z = 0 of frame i
            if kind == "revolute":  # eq. (17) Hayati
                a = math.hypot(P[0], P[1])
                theta = math.atan2(P[1], P[0]) if a > 1e-12 else 0.0
                zr = spatial.rotz(-theta) @ z
                alpha, beta = _align_xy(zr)
                names = [f"theta{i}", f"a{i}", f"alpha{i}", f"beta{i}", f"p{j}"]
                b.add(i, "R∥R", 17, names, [theta, a, alpha, beta, -s0], joint)
            else:  # eq. (19)
                alpha, beta = _align_xy(z)
                names = [f"d{i}", f"x{i}", f"y{i}", f"alpha{i}", f"beta{i}", f"p{j}"]
                b.add(i, "T∥R", 19, names, [0.0, P[0], P[1], alpha, beta, -s0], joint)
        b.deferred.append(f"p{j}")
        return
    # the next joint is prismatic: only its direction matters; its frame sits at its point
    if kind == "revolute":
        if not par:  # eq. (22)
            n = np.array([-z[1], z[0], 0.0]) / math.hypot(z[0], z[1])
            theta = math.atan2(n[1], n[0])
            cr = spatial.rotz(-theta) @ c
            alpha = math.atan2(math.hypot(z[0], z[1]), z[2])
            names = [f"theta{i}", f"x{i}", f"y{i}", f"z{i}", f"alpha{i}"]
            b.add(i, "R⊥T", 22, names, [theta, *cr, alpha], joint)
        else:  # eq. (23)
            alpha, beta = _align_xy(z)
            names = [f"theta{i}", f"x{i}", f"y{i}", f"z{i}", f"alpha{i}", f"beta{i}"]
            b.add(i, "R∥T", 23, names, [0.0, *c, alpha, beta], joint)
    elif not par:  # eq. (20)
        gamma, alpha = _align_zx(z)
        names = [f"d{i}", f"x{i}", f"y{i}", f"theta{i}", f"alpha{i}"]
        b.add(i, "T⊥T", 20, names, [c[2], c[0], c[1], gamma, alpha], joint)
    else:  # eq. (21)
        alpha, beta = _align_xy(z)
        names = [f"d{i}", f"x{i}", f"y{i}", f"alpha{i}", f"beta{i}"]
        b.add(i, "T∥T", 21, names, [c[2], c[0], c[1], alpha, beta], joint)


def _tool_link(
    b: _ChainBuilder, n: int, kind: JointType, joint: Joint, tcp_point, tcp_rotation, measure
) -> None:
    """Last joint → TCP, seed 000 eqs. (24)-(27)."""
    R, p0 = b.frame[:3, :3], b.frame[:3, 3]
    c = R.T @ (tcp_point - p0)
    R_local = np.eye(3) if tcp_rotation is None else R.T @ tcp_rotation
    par = abs(R_local[2, 2]) >= b.cos_tol
    if kind == "revolute":
        equation, kind_label = (27, "R∥TCP") if par else (26, "R⊥TCP")
        names, values = [f"theta{n}", "tool_x", "tool_y", "tool_z"], [0.0, *c]
    else:
        equation, kind_label = (25, "T∥TCP") if par else (24, "T⊥TCP")
        names, values = [f"d{n}", "tool_y", "tool_x"], [c[2], c[1], c[0]]
    motions = SCHROER_SETS[equation]
    if measure == "pose":
        seq = "ZYX" if par else "ZYZ"
        angles = spatial.matrix_to_euler(R_local, seq) if not np.allclose(R_local, np.eye(3)) else np.zeros(3)
        rot_names = ["tool_rz", "tool_ry", "tool_rx"] if par else ["tool_rz", "tool_ry", "tool_rz2"]
        names, values = names + rot_names, values + list(angles)
    else:
        motions = motions[: len(names)]
    for k, (motion, name, value) in enumerate(zip(motions, names, values, strict=True)):
        b.steps.append(Step(motion, name, float(value), joint=joint if k == 0 else None))
        b.frame = b.frame @ spatial.elementary(motion, value)
    b.links.append(LinkInfo(n, kind_label, equation, tuple(names)))
    b.deferred.append(f"{'theta' if kind == 'revolute' else 'd'}{n}")


# --------------------------------------------------------------------- identifiability
def _sample_q(model: Model, n: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    lim = np.clip(model.joint_limits, -np.pi, np.pi)
    lim = np.where(
        np.array(model.joint_types)[:, None] == "prismatic", np.clip(model.joint_limits, -1, 1), lim
    )
    return rng.uniform(lim[:, 0], lim[:, 1], size=(n, model.dof))


def select_identifiable(
    model: Model,
    measure: Measure,
    order: Sequence[str] | None = None,
    n_poses: int = 60,
    seed: int = 0,
    tolerance: float = 1e-7,
) -> tuple[Model, int]:
    """Free exactly an identifiable set of parameters by a sequential rank test.

    Parameters are tried in ``order`` (default: chain order); one is kept when its
    column of the identification Jacobian (rotations scaled by the robot's size so that
    all columns are lengths) is not in the span of the columns kept before it, to a
    relative ``tolerance``.

    Returns:
        the model with the kept parameters free and the rest fixed, and the rank.
    """
    full = model.with_free(None)
    q = _sample_q(full, n_poses, seed)
    T, J = full.fk_jacobian(q, rows="pose" if measure == "pose" else "position")
    size = max(float(np.abs(T[:, :3, 3]).max()), 0.1)
    scale = np.array([size if s.is_rotation else 1.0 for s in full.steps])
    J = J * scale
    if measure == "pose":  # orientation rows in length units too
        J = J.reshape(len(q), 6, -1)
        J[:, 3:] *= size
        J = J.reshape(len(q) * 6, -1)
    # scipy.linalg: imported on use
    from robocal.model.rank import identifiable_subset

    selection = identifiable_subset(
        J, full.names, order="preference", prefer=order, rtol=tolerance, explain=False
    )
    kept_set = set(selection.kept)
    kept = selection.kept
    return full.with_free(None, free=False).with_free(kept_set), len(kept)


# --------------------------------------------------------------------- API
def build(
    joints: Sequence[JointGeometry | Mapping[str, Any]],
    tcp: Tcp | Mapping[str, Any] | Sequence[float] | None = None,
    measure: Measure = "pose",
    name: str = "built",
    parallel_tolerance: float = DEFAULT_PARALLEL_TOLERANCE,
    title: str = "",
    source: str = "",
) -> BuildResult:
    """Build a calibration model from joint geometry (see the module docstring).

    Args:
        joints: the joints from base to tip (:class:`JointGeometry` or mappings with the
            same fields), SI units.
        tcp: the tool centre point (:class:`Tcp`, a mapping with ``position`` and
            optional ``rotation``, or a position), relative to the last joint's origin.
        measure: ``"pose"`` (full-pose measurement) or ``"position"``.
        name: model name.
        parallel_tolerance: axes closer than this angle (rad) count as parallel.
    """
    if measure not in ("position", "pose"):
        raise ValueError(f"measure must be 'position' or 'pose', got {measure!r}")
    if not 0 < parallel_tolerance < math.pi / 2:
        raise ValueError("parallel_tolerance must lie strictly between 0 and 90 degrees")
    geo, tcp = _normalise(joints, tcp)
    points, axes = _absolute(geo)
    b = _ChainBuilder(parallel_tolerance)
    _base_link(b, points[0], axes[0], geo[0].type)
    n = len(geo)
    for i in range(1, n + 1):
        g = geo[i - 1]
        joint = Joint(g.name, tuple(g.limits) if g.limits is not None else None)
        if i < n:
            _joint_link(b, i, g.type, joint, geo[i], points[i], axes[i])
        else:
            rotation = None if tcp.rotation is None else np.asarray(tcp.rotation, dtype=float)
            _tool_link(b, n, g.type, joint, points[-1] + np.asarray(tcp.position), rotation, measure)
    notes = "; ".join(f"link {info.index}: {info.label}" for info in b.links)
    model = Model(name=name, steps=tuple(b.steps), title=title, source=source, notes=notes)
    _check_reproduces(model, geo, tcp, measure)
    deferred = [p for p in b.deferred if p in model.names]
    order = [p for p in model.names if p not in deferred] + deferred
    model, rank = select_identifiable(model, measure, order)
    R = sum(g.type == "revolute" for g in geo)
    P = n - R
    expected = 4 * R + 2 * P + (6 if measure == "pose" else 3)
    dropped = tuple(s.name for s in model.steps if not s.free)
    warnings = []
    if rank < expected:
        reason = ""
        last = geo[-1]
        offset = np.asarray(tcp.position)
        radial = offset - (offset @ axes[-1]) * axes[-1]
        if measure == "position" and last.type == "revolute" and np.linalg.norm(radial) < 1e-9:
            reason = (
                f" The TCP lies on the last joint axis ({last.name}), so that joint's rotation does not "
                "move it: use a target off the axis or measure the orientation too."
            )
        warnings.append(
            f"only {rank} of the {expected} parameters of a complete model (4R + 2P + "
            f"{6 if measure == 'pose' else 3}) are identifiable from {measure} measurements of this "
            f"geometry.{reason}"
        )
    return BuildResult(model, tuple(b.links), measure, expected, rank, dropped, tuple(warnings))


def build_model(
    joints: Sequence[JointGeometry | Mapping[str, Any]],
    tcp: Tcp | Mapping[str, Any] | Sequence[float] | None = None,
    measure: Measure = "pose",
    **options: Any,
) -> Model:
    """The calibration model for a joint geometry; see :func:`build` for the arguments."""
    return build(joints, tcp, measure, **options).model


def _check_reproduces(model: Model, geo, tcp: Tcp, measure: Measure) -> None:
    """Internal consistency: the built chain's frames lie on the given axes at q = 0."""
    points, axes = _absolute(geo)
    frames = model.joint_frames(np.zeros(model.dof))
    for j, F in enumerate(frames):
        z, o = F[:3, 2], F[:3, 3]
        off = o - points[j]
        if np.linalg.norm(z - axes[j]) > 1e-9 or (
            geo[j].type == "revolute" and np.linalg.norm(off - (off @ axes[j]) * axes[j]) > 1e-9
        ):
            raise AssertionError(f"builder bug: frame of joint {j + 1} is not on its axis")
    T = model.fk(np.zeros(model.dof))
    if np.linalg.norm(T[:3, 3] - points[-1] - np.asarray(tcp.position)) > 1e-9:
        raise AssertionError("builder bug: the TCP is not reproduced")
    if measure == "pose" and tcp.rotation is not None and not np.allclose(T[:3, :3], tcp.rotation, atol=1e-9):
        raise AssertionError("builder bug: the TCP orientation is not reproduced")


# --------------------------------------------------------------------- files
_Config = ConfigDict(extra="forbid", allow_inf_nan=False)


class _JointSpec(BaseModel):
    model_config = _Config
    type: Literal["revolute", "prismatic"]
    position: tuple[Number, Number, Number]
    axis: tuple[Number, Number, Number]
    name: str | None = Field(default=None, min_length=1)
    limits: tuple[Number, Number] | None = None


class _TcpSpec(BaseModel):
    model_config = _Config
    position: tuple[Number, Number, Number] = (0.0, 0.0, 0.0)
    rpy: tuple[Number, Number, Number] | None = None  # Rz(yaw) Ry(pitch) Rx(roll), angle unit
    quaternion: tuple[Number, Number, Number, Number] | None = None  # w, x, y, z


class _GeometryFile(BaseModel):
    model_config = _Config
    name: str = Field(min_length=1)
    title: str = ""
    source: str = ""
    unit: Literal["m", "mm"] = "m"
    angle_unit: Literal["rad", "deg"] = "deg"
    measure: Literal["position", "pose"] = "pose"
    parallel_tolerance: Number | None = None  # angle unit
    joints: list[_JointSpec] = Field(min_length=1)
    tcp: _TcpSpec = _TcpSpec()


@dataclass(frozen=True)
class Geometry:
    """A parsed geometry file, ready for :func:`build`."""

    name: str
    joints: tuple[JointGeometry, ...]
    tcp: Tcp
    measure: Measure
    parallel_tolerance: float
    title: str = ""
    source: str = ""

    def build(self, measure: Measure | None = None) -> BuildResult:
        return build(
            self.joints,
            self.tcp,
            measure or self.measure,
            name=self.name,
            parallel_tolerance=self.parallel_tolerance,
            title=self.title,
            source=self.source,
        )


def load_geometry(path: str | Path) -> Geometry:
    """Read a joint-geometry YAML file (``unit: m|mm``, ``angle_unit: deg|rad``).

    Example::

        name: scara
        unit: mm
        joints:
          - {type: revolute, position: [0, 0, 400], axis: [0, 0, 1], limits: [-170, 170]}
          - {type: revolute, position: [350, 0, 0], axis: [0, 0, 1]}
          - {type: prismatic, position: [300, 0, 0], axis: [0, 0, -1], limits: [0, 200]}
          - {type: revolute, position: [0, 0, -50], axis: [0, 0, -1]}
        tcp: {position: [0, 0, -100]}
    """
    from robocal.model.files import format_validation_error, read_yaml

    path = Path(path)
    data = read_yaml(path, "geometry", GeometryError)
    if not isinstance(data, dict):
        raise GeometryError(f"{path}: a geometry file must be a mapping")
    try:
        spec = _GeometryFile.model_validate(data)
    except ValidationError as err:
        raise GeometryError(f"{path}: {format_validation_error(err)}") from None
    L, A = LENGTH_UNITS[spec.unit], ANGLE_UNITS[spec.angle_unit]  # the schema allows m|mm, rad|deg
    joints = []
    for j in spec.joints:
        lim = None
        if j.limits is not None:
            lim = tuple(v * (A if j.type == "revolute" else L) for v in j.limits)
        joints.append(JointGeometry(j.type, tuple(v * L for v in j.position), j.axis, j.name, lim))
    rotation = None
    if spec.tcp.rpy is not None and spec.tcp.quaternion is not None:
        raise GeometryError(f"{path}: tcp: give either rpy or quaternion, not both")
    if spec.tcp.rpy is not None:
        r, p, y = (v * A for v in spec.tcp.rpy)
        rotation = spatial.euler_to_matrix([r, p, y], "xyz")
    elif spec.tcp.quaternion is not None:
        norm = math.sqrt(sum(v * v for v in spec.tcp.quaternion))
        if not abs(norm - 1.0) < 0.01:  # a unit quaternion written with four digits is within 1e-4
            raise GeometryError(
                f"{path}: tcp.quaternion: {list(spec.tcp.quaternion)} has norm {norm:.3g}, not 1 (w, x, y, z)"
            )
        rotation = spatial.quaternion_to_matrix(np.asarray(spec.tcp.quaternion) / norm)
    tcp = Tcp(
        tuple(v * L for v in spec.tcp.position), None if rotation is None else tuple(map(tuple, rotation))
    )
    tol = DEFAULT_PARALLEL_TOLERANCE if spec.parallel_tolerance is None else spec.parallel_tolerance * A
    try:
        _normalise(joints, tcp)
    except GeometryError as err:
        raise GeometryError(f"{path}: {err}") from None
    return Geometry(spec.name, tuple(joints), tcp, spec.measure, tol, spec.title, spec.source)
