"""A robot's joint geometry (axes and points in the base frame at q = 0, the tool centre point):
its checks, its forward kinematics and the common normals of neighbouring axes; the chain built
from it: :mod:`robocal.model.builder`."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np

from robocal import choices, spatial

JointType = Literal["revolute", "prismatic"]


Measure = choices.Measure  # the one table of choices (robocal.choices)


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


# --------------------------------------------------------------------- validation
def _unit(v: np.ndarray, what: str) -> np.ndarray:
    norm = float(np.linalg.norm(v))
    if not math.isfinite(norm) or norm < 1e-12:
        raise GeometryError(f"{what}: axis {v.tolist()} has zero length")
    return v / norm


def normalise(joints: Sequence[JointGeometry | Mapping[str, Any]], tcp) -> tuple[list[JointGeometry], Tcp]:
    if len(joints) < 1:
        raise GeometryError("the robot needs at least one joint")
    out = [_checked_joint(j, raw) for j, raw in enumerate(joints)]
    names = [g.name for g in out]
    for name in names:
        if names.count(name) > 1:
            raise GeometryError(f"joint name {name!r} is used twice")
    _check_coincident(out)
    return out, _checked_tcp(tcp)


def _checked_joint(j: int, raw: JointGeometry | Mapping[str, Any]) -> JointGeometry:
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
    return JointGeometry(g.type, tuple(pos.tolist()), tuple(axis.tolist()), g.name or f"q{j + 1}", g.limits)


def _check_coincident(joints: list[JointGeometry]) -> None:
    """Coincident identical axes: two consecutive revolute joints on the same line."""
    origins = np.cumsum([np.asarray(g.position) for g in joints], axis=0)
    for j in range(len(joints) - 1):
        a, b = joints[j], joints[j + 1]
        za, zb = np.asarray(a.axis), np.asarray(b.axis)
        if a.type == b.type == "revolute" and abs(abs(za @ zb) - 1) < 1e-12:
            offset = origins[j + 1] - origins[j]
            if np.linalg.norm(offset - (offset @ za) * za) < 1e-9:
                raise GeometryError(
                    f"joint {j + 2} ({b.name}) turns about the same line as joint {j + 1} ({a.name}): "
                    "coincident revolute axes cannot be told apart"
                )


def _checked_tcp(tcp: Tcp | Mapping[str, Any] | Sequence[float] | None) -> Tcp:
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
    return tcp


# --------------------------------------------------------------------- geometry
def absolute(joints: Sequence[JointGeometry]) -> tuple[np.ndarray, np.ndarray]:
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
    joints, tcp = normalise(joints, tcp)
    points, axes = absolute(joints)
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


def align_xy(z: np.ndarray) -> tuple[float, float]:
    """Angles (α, β) with Rx(α) Ry(β) e_z = z (Hayati-style alignment of a near-z axis)."""
    beta = math.asin(float(np.clip(z[0], -1.0, 1.0)))
    alpha = math.atan2(-z[1], z[2])
    return alpha, beta


def align_zx(z: np.ndarray) -> tuple[float, float]:
    """Angles (γ, α) with Rz(γ) Rx(α) e_z = z (DH-style alignment: x along e_z × z)."""
    s = math.hypot(z[0], z[1])
    gamma = math.atan2(z[0], -z[1]) if s > 1e-15 else 0.0
    alpha = math.atan2(s, z[2])
    return gamma, alpha


def common_normal(c: np.ndarray, z: np.ndarray) -> tuple[float, float, np.ndarray]:
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
