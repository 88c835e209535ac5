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

The joint geometry and its checks live in :mod:`robocal.model.geometry`, geometry files in
:mod:`robocal.model.geometry_file`; this module re-exports their public names.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from robocal import spatial
from robocal.model.chain import Model
from robocal.model.conventions import SCHROER_SETS
from robocal.model.geometry import (
    DEFAULT_PARALLEL_TOLERANCE,
    GeometryError,
    JointGeometry,
    JointType,
    Measure,
    Tcp,
    absolute,
    align_xy,
    align_zx,
    common_normal,
    geometry_fk,
    normalise,
)
from robocal.model.geometry_file import read_geometry_file
from robocal.model.steps import Joint, Step

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
        return f"{self.kind} (Motta 2005 eq. {self.equation}{extra})"


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
            alpha, beta = align_xy(z)
            b.add(0, "B∥T", 12, ["base_x", "base_y", "base_z", "base_rx", "base_ry"], [*c, alpha, beta])
        else:  # eq. (11) B ⊥ JT
            gamma, alpha = align_zx(z)
            b.add(0, "B⊥T", 11, ["base_x", "base_y", "base_z", "base_rz", "base_rx"], [*c, gamma, alpha])
        return
    k = int(np.argmax(np.abs(z)))
    s0 = -c[k] / z[k]
    P = c + s0 * z  # where the axis pierces the base plane normal to the nearest base axis
    if k == 2:  # eq. (15) B ∥ JR
        alpha, beta = align_xy(z)
        b.add(0, "B∥R", 15, ["base_x", "base_y", "base_rx", "base_ry"], [P[0], P[1], alpha, beta])
    else:
        gamma, alpha = align_zx(z)
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
            t, s, n = common_normal(c, z)
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
                alpha, beta = align_xy(zr)
                names = [f"theta{i}", f"a{i}", f"alpha{i}", f"beta{i}", f"p{j}"]
                b.add(i, "R∥R", 17, names, [theta, a, alpha, beta, -s0], joint)
            else:  # eq. (19)
                alpha, beta = align_xy(z)
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
            alpha, beta = align_xy(z)
            names = [f"theta{i}", f"x{i}", f"y{i}", f"z{i}", f"alpha{i}", f"beta{i}"]
            b.add(i, "R∥T", 23, names, [0.0, *c, alpha, beta], joint)
    elif not par:  # eq. (20)
        gamma, alpha = align_zx(z)
        names = [f"d{i}", f"x{i}", f"y{i}", f"theta{i}", f"alpha{i}"]
        b.add(i, "T⊥T", 20, names, [c[2], c[0], c[1], gamma, alpha], joint)
    else:  # eq. (21)
        alpha, beta = align_xy(z)
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
    if measure == "pose" or tcp_rotation is not None:
        # the flange's orientation is kept for position measurements too (fixed steps the
        # position rank test never frees): a tool, probe or orientation target given in the
        # flange frame then means the same here as on the controller
        seq = "ZYX" if par else "ZYZ"
        angles = spatial.matrix_to_euler(R_local, seq) if not np.allclose(R_local, np.eye(3)) else np.zeros(3)
        rot_names = ["tool_rz", "tool_ry", "tool_rx"] if par else ["tool_rz", "tool_ry", "tool_rz2"]
        names, values = names + rot_names, values + list(angles)
    else:
        motions = motions[: len(names)]
    for k, (motion, name, value) in enumerate(zip(motions, names, values, strict=True)):
        free = measure == "pose" or not name.startswith("tool_r")
        b.steps.append(Step(motion, name, float(value), free=free, joint=joint if k == 0 else None))
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
    geo, tcp = normalise(joints, tcp)
    points, axes = absolute(geo)
    b = _ChainBuilder(parallel_tolerance)
    _base_link(b, points[0], axes[0], geo[0].type)
    n = len(geo)
    for i in range(1, n + 1):
        g = geo[i - 1]
        assert g.name is not None  # named by _normalise
        joint = Joint(g.name, g.limits)  # Joint checks and stores (lower, upper)
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
    points, axes = absolute(geo)
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
    if tcp.rotation is not None and not np.allclose(T[:3, :3], tcp.rotation, atol=1e-9):
        raise AssertionError("builder bug: the TCP orientation is not reproduced")


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
    return Geometry(*read_geometry_file(path))
