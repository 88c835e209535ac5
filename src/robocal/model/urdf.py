"""URDF import: joint axes and origins at the zero configuration, fed to the builder.

Pinocchio parses the URDF (its urdfdom reader) and places every joint at the zero
configuration; robocal then reads each joint's axis and origin in the base frame and
builds a complete, minimal, singularity-free calibration model from them
(:mod:`robocal.model.builder`).  Only the serial chain from the root to the tip frame
is used.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from robocal.model.builder import BuildResult, GeometryError, JointGeometry, Tcp, build

__all__ = ["URDFError", "build_from_urdf", "geometry_from_urdf", "model_from_urdf"]

MAX_URDF_BYTES = 20_000_000

_AXES = {"X": (1.0, 0.0, 0.0), "Y": (0.0, 1.0, 0.0), "Z": (0.0, 0.0, 1.0)}


class URDFError(ValueError):
    """The URDF file cannot be used; the message names the file and the reason."""


def _read_checked(path: Path) -> str:
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such URDF file")
    size = path.stat().st_size
    if size > MAX_URDF_BYTES:
        raise URDFError(f"{path}: {size} bytes is too large for a URDF (limit {MAX_URDF_BYTES})")
    text = path.read_text(encoding="utf-8", errors="replace")
    upper = text.upper()
    # URDF needs no document type; entity declarations are how XML bombs and external
    # file reads get in, so refuse them before any XML parser sees the file.
    if "<!DOCTYPE" in upper or "<!ENTITY" in upper:
        raise URDFError(f"{path}: DOCTYPE/ENTITY declarations are not allowed in a URDF")
    if "<robot" not in text:
        raise URDFError(f"{path}: not a URDF (no <robot> element)")
    return text


def _joint_axis(joint_model) -> tuple[str, np.ndarray]:
    """(type, axis in the joint frame) of a Pinocchio 1-DOF joint model."""
    name = joint_model.shortname()
    kind = None
    if name.startswith("JointModelR"):
        kind = "revolute"
    elif name.startswith("JointModelP"):
        kind = "prismatic"
    if kind is None or joint_model.nv != 1:
        raise URDFError(f"joint type {name} is not a 1-DOF revolute or prismatic joint")
    if name.endswith("Unaligned"):
        return kind, np.asarray(joint_model.axis, dtype=float)
    letter = name[-1]  # RX, RY, RZ, PX ... ; RUBX etc. are continuous joints
    return kind, np.array(_AXES[letter])


def geometry_from_urdf(path: str | Path, tip: str | None = None) -> tuple[str, list[JointGeometry], Tcp]:
    """Joint geometry (name, joints, TCP) of the serial chain from the root to ``tip``.

    Args:
        path: the URDF file.
        tip: name of the frame (link) to end at; default: the frame of the deepest joint
            that comes last in the file (e.g. ``tool0`` when present).
    """
    import pinocchio as pin

    path = Path(path)
    _read_checked(path)
    try:
        pm = pin.buildModelFromUrdf(str(path))
    except (RuntimeError, ValueError) as err:
        raise URDFError(f"{path}: {err}") from None
    data = pm.createData()
    q0 = pin.neutral(pm)
    pin.framesForwardKinematics(pm, data, q0)
    if pm.njoints < 2:
        raise URDFError(f"{path}: the robot has no movable joint")
    if tip is None:
        # the last body frame attached to the deepest joint
        deepest = max(range(1, pm.njoints), key=lambda j: (_depth(pm, j), j))
        candidates = [f for f in range(pm.nframes) if pm.frames[f].parentJoint == deepest]
        frame_id = candidates[-1]
    else:
        if not pm.existFrame(tip):
            names = sorted({f.name for f in pm.frames})
            raise URDFError(f"{path}: no frame {tip!r}; frames are {', '.join(names)}")
        frame_id = pm.getFrameId(tip)
    chain = []
    j = pm.frames[frame_id].parentJoint
    while j > 0:
        chain.append(j)
        j = pm.parents[j]
    chain.reverse()
    if not chain:
        raise URDFError(f"{path}: frame {pm.frames[frame_id].name!r} is not moved by any joint")
    joints: list[JointGeometry] = []
    previous = np.zeros(3)
    for j in chain:
        try:
            kind, local_axis = _joint_axis(pm.joints[j])
        except URDFError as err:
            raise URDFError(f"{path}: joint {pm.names[j]!r}: {err}") from None
        M = data.oMi[j]
        axis = M.rotation @ local_axis
        origin = np.array(M.translation)
        idx = pm.joints[j].idx_q
        limits = None
        if pm.joints[j].nq == 1:  # continuous joints are stored as (cos, sin): no limits
            lo, hi = float(pm.lowerPositionLimit[idx]), float(pm.upperPositionLimit[idx])
            limits = (lo, hi) if np.isfinite(lo) and np.isfinite(hi) and lo < hi else None
        joints.append(JointGeometry(kind, tuple(origin - previous), tuple(axis), pm.names[j], limits))
        previous = origin
    tip_frame = data.oMf[frame_id]
    tcp = Tcp(
        tuple(np.array(tip_frame.translation) - previous), tuple(map(tuple, np.array(tip_frame.rotation)))
    )
    return pm.name or path.stem, joints, tcp


def _depth(pm, j: int) -> int:
    d = 0
    while j > 0:
        j = pm.parents[j]
        d += 1
    return d


def build_from_urdf(
    path: str | Path,
    measure: str = "pose",
    tip: str | None = None,
    name: str | None = None,
) -> BuildResult:
    """Build a complete, minimal, singularity-free calibration model of a URDF robot.

    Returns the builder's :class:`~robocal.model.builder.BuildResult` (``.model`` is the
    model); the continuous joints of the URDF become revolute joints without limits.
    """
    robot_name, joints, tcp = geometry_from_urdf(path, tip)
    try:
        return build(joints, tcp, measure, name=name or robot_name, source=f"URDF {Path(path).name}")
    except GeometryError as err:
        raise URDFError(f"{path}: {err}") from None


def model_from_urdf(path: str | Path, measure: str = "pose", tip: str | None = None, name: str | None = None):
    """The calibration model of a URDF robot (see :func:`build_from_urdf`)."""
    return build_from_urdf(path, measure, tip, name).model
