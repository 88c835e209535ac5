"""Universal Robots kinematics files: the ``kinematics:`` YAML of the UR ROS description.

The format is the one of ``ur_description``'s ``config/<model>/default_kinematics.yaml``
(Universal_Robots_ROS2_Description, humble/jazzy/rolling; the same layout as the ROS 1
``ur_description`` and the file that ``ur_calibration``'s calibration correction writes
from a robot's factory calibration)::

    kinematics:
      shoulder:  {x: 0, y: 0, z: 0.1273, roll: 0, pitch: 0, yaw: 0}
      upper_arm: {x: 0, y: 0, z: 0, roll: 1.570796327, pitch: 0, yaw: 0}
      forearm:   {...}
      wrist_1:   {...}
      wrist_2:   {...}
      wrist_3:   {...}
      hash: calib_...

Definition (``ur_macro.xacro``): each entry is the ``<origin xyz rpy>`` of a joint in
the frame of the previous joint's child link, the joint turning about its local z:

    U_j(q) = U_{j-1}(q) · Trans(x, y, z) · Rz(yaw) · Ry(pitch) · Rx(roll) · Rz(q_j),

``U_0`` the controller's base frame (``base_link_inertia`` = ``base`` in the
description, x pointing backwards), ``U_6`` the tool flange (``tool0`` is ``wrist_3_link``
turned by the two fixed flange joints, whose rotations cancel).  Units m and rad.

* :func:`ur_kinematics` — a calibrated model -> the six entries.  The model's frames
  after each joint step give ``U_j`` (z along the joint axis); what follows the last
  joint and commutes with it (a translation along and a rotation about its axis) goes
  into ``wrist_3``.  Anything else after the last joint (a tilted flange) the format
  cannot hold; it is returned as ``T_flange_rest`` and stated by the caller.  Each
  ``U_j`` slides along its axis to the height of the next joint's origin, so a DH model
  gives UR's layout (``shoulder.z`` = d1, ``forearm.x`` = a2, ``wrist_1.z`` = d4 ...).
* :func:`read_ur_kinematics` — a factory calibration (or the default file) -> a
  complete, minimal calibration model through the builder (seed 000), with the
  zero configuration of the file.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray

from robocal import spatial
from robocal.model.builder import BuildResult, build
from robocal.model.chain import Model
from robocal.model.flange_tool import split_tool
from robocal.model.geometry import GeometryError, JointGeometry, Measure, Tcp
from robocal.model.urdf.source import urdf_origin
from robocal.model.urdf.xml_text import rpy_from_matrix

__all__ = [
    "UR_JOINTS",
    "UR_SEGMENTS",
    "URKinematics",
    "URKinematicsError",
    "build_from_ur_kinematics",
    "read_ur_kinematics",
    "ur_kinematics",
    "ur_kinematics_fk",
]

Array = NDArray[np.float64]
UR_SEGMENTS = ("shoulder", "upper_arm", "forearm", "wrist_1", "wrist_2", "wrist_3")
UR_JOINTS = (
    "shoulder_pan_joint",
    "shoulder_lift_joint",
    "elbow_joint",
    "wrist_1_joint",
    "wrist_2_joint",
    "wrist_3_joint",
)
_KEYS = ("x", "y", "z", "roll", "pitch", "yaw")
#: Rotations taking a frame's z axis onto its x, y, z axis (the joint step's axis).
_ALIGN = (spatial.roty(math.pi / 2), spatial.rotx(-math.pi / 2), np.eye(3))


class URKinematicsError(ValueError):
    """A UR kinematics file that cannot be used; the message names the file and key."""


@dataclass(frozen=True)
class URKinematics:
    """The six joint origins of a UR kinematics file.

    Attributes:
        segments: ``(6, 6)`` rows ``x, y, z`` (m), ``roll, pitch, yaw`` (rad) for
            ``shoulder .. wrist_3``.
        T_flange_rest: ``(4, 4)`` what the model has after the last joint that the format
            cannot hold (identity when everything fitted): the model's flange in the
            format's ``wrist_3`` frame.
        hash: the ``hash`` entry written.
    """

    segments: Array
    T_flange_rest: Array
    hash: str = ""

    @property
    def flange_rest_mm_deg(self) -> tuple[float, float]:
        """Size of ``T_flange_rest``: translation (mm) and rotation angle (degrees)."""
        T = self.T_flange_rest
        angle = float(np.linalg.norm(spatial.matrix_to_rotvec(T[:3, :3])))
        return float(np.linalg.norm(T[:3, 3]) * 1e3), math.degrees(angle)

    def to_yaml(self) -> str:
        """The file text (numbers with 17 significant digits: exact round trip)."""
        lines = ["kinematics:"]
        for name, row in zip(UR_SEGMENTS, self.segments, strict=True):
            lines.append(f"  {name}:")
            lines += [f"    {k}: {_num(v)}" for k, v in zip(_KEYS, row, strict=True)]
        lines.append(f"  hash: {self.hash or 'robocal_calibration'}")
        return "\n".join(lines) + "\n"


def _num(v: float) -> str:
    return "0" if abs(v) < 1e-15 else repr(float(v))


def ur_kinematics_fk(segments: ArrayLike, q: ArrayLike) -> Array:
    """``(n, 4, 4)`` flange frames ``U_6`` in the UR base frame by the format's definition
    (module docstring); ``segments`` ``(6, 6)``, ``q`` ``(n, 6)`` rad."""
    seg = np.asarray(segments, dtype=float)
    q = np.atleast_2d(np.asarray(q, dtype=float))
    T = np.repeat(np.eye(4)[None], len(q), axis=0)
    for j in range(6):
        T = T @ urdf_origin(seg[j, :3], seg[j, 3:]) @ spatial.homogeneous(spatial.rotz(q[:, j]))
    return T


def ur_kinematics(model: Model, T_base_urbase: ArrayLike | None = None, hash: str = "") -> URKinematics:
    """The UR kinematics entries of a 6-joint revolute model.

    Args:
        model: the (calibrated) model; measured tool steps ``tcp_*`` are left out.
        T_base_urbase: ``(4, 4)`` the UR controller's base frame in the model's base frame
            (default identity: the catalog's DH models are in it; a model built from a
            ROS URDF rooted at ``base_link`` has ``Rz(π)``).
        hash: the ``hash`` entry.
    """
    joints = [s for s in model.steps if s.joint is not None]
    if len(joints) != 6 or any(s.joint_type != "revolute" for s in joints):
        raise ValueError(f"model {model.name!r}: the UR format holds six revolute joints")
    robot = Model(name=model.name, steps=split_tool(model).robot.steps)
    q0 = np.zeros(6)
    B = np.eye(4) if T_base_urbase is None else np.asarray(T_base_urbase, dtype=float)
    B_inv = spatial.inverse(B)
    F = robot.joint_frames(q0)
    U = [B_inv @ F[k] @ spatial.homogeneous(_ALIGN[s.axis]) for k, s in enumerate(joints)]
    # each frame slides along its axis to the height of the next joint (as in UR's files,
    # where the shoulder sits at d1); what commutes with the last joint moves into wrist_3
    for k in range(5):
        U[k] = U[k] @ spatial.transl(z=(spatial.inverse(U[k]) @ U[k + 1])[2, 3])
    C = spatial.inverse(U[5]) @ B_inv @ robot.fk(q0)
    R = C[:3, :3]
    psi = math.atan2(R[1, 0] - R[0, 1], R[0, 0] + R[1, 1])
    U[5] = U[5] @ spatial.homogeneous(spatial.rotz(psi), (0.0, 0.0, C[2, 3]))
    rest = spatial.inverse(U[5]) @ B_inv @ robot.fk(q0)
    rows = []
    previous = np.eye(4)
    for Uj in U:
        T = spatial.inverse(previous) @ Uj
        rows.append([*T[:3, 3], *rpy_from_matrix(T[:3, :3])])
        previous = Uj
    return URKinematics(np.array(rows), rest, hash)


def read_ur_kinematics(
    path: str | Path,
    *,
    measure: Measure = "pose",
    name: str | None = None,
    limits: Mapping[str, tuple[float, float]] | None = None,
) -> Model:
    """The model of :func:`build_from_ur_kinematics`."""
    return build_from_ur_kinematics(path, measure=measure, name=name, limits=limits).model


def build_from_ur_kinematics(
    path: str | Path,
    *,
    measure: Measure = "pose",
    name: str | None = None,
    limits: Mapping[str, tuple[float, float]] | None = None,
) -> BuildResult:
    """A calibration model from a UR kinematics YAML (a factory calibration or the
    description's default), built by seed 000's rules from the joint axes the file puts
    at the zero configuration; its base frame is the UR base frame, its tool the flange
    (``U_6``), its joints ``shoulder_pan_joint`` .. ``wrist_3_joint`` with limits ±2π
    (``limits`` overrides by joint name).

    Raises:
        URKinematicsError: the file is not such a YAML (file and key named).
    """
    from robocal.model.yaml_files import read_yaml

    path = Path(path)
    try:  # its size, entries and nesting are checked before the file is parsed
        data = read_yaml(path, "UR kinematics", URKinematicsError)
    except OSError as err:
        raise URKinematicsError(f"{path}: cannot read: {err.strerror or err}") from None
    kin = data.get("kinematics") if isinstance(data, dict) else None
    if not isinstance(kin, dict):
        raise URKinematicsError(f"{path}: no 'kinematics:' mapping (a UR default_kinematics.yaml)")
    seg = np.zeros((6, 6))
    for j, part in enumerate(UR_SEGMENTS):
        entry = kin.get(part)
        if not isinstance(entry, dict):
            raise URKinematicsError(f"{path}: kinematics.{part} is missing or not a mapping")
        for k, key in enumerate(_KEYS):
            value = entry.get(key)
            if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
                raise URKinematicsError(f"{path}: kinematics.{part}.{key} is {value!r}, not a finite number")
            seg[j, k] = float(value)
    U = ur_kinematics_fk(seg, np.zeros((1, 6)))  # only the flange; the joint frames below
    frames = []
    T = np.eye(4)
    for j in range(6):
        T = T @ urdf_origin(seg[j, :3], seg[j, 3:])
        frames.append(T)
    limits = dict(limits or {})
    geometry = []
    previous = np.zeros(3)
    for j, Tj in enumerate(frames):
        lim = limits.get(UR_JOINTS[j], (-2 * math.pi, 2 * math.pi))
        geometry.append(
            JointGeometry("revolute", tuple(Tj[:3, 3] - previous), tuple(Tj[:3, 2]), UR_JOINTS[j], lim)
        )
        previous = Tj[:3, 3]
    tcp = Tcp(tuple(U[0, :3, 3] - previous), tuple(map(tuple, U[0, :3, :3])))
    label = str(kin.get("hash", "")) or path.name
    try:
        return build(
            geometry,
            tcp,
            measure,
            name=name or "ur_calibrated",
            source=f"UR kinematics {path.name} ({label})",
        )
    except GeometryError as err:
        raise URKinematicsError(f"{path}: {err}") from None
