"""Target numbers to SI values and back, each language in its own units and written precision."""

from __future__ import annotations

import math
import re
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from robocal import spatial
from robocal.compensate.programs.syntax import (
    DEG,
    Array,
    ProgramError,
    ProgramTarget,
    decimals_of,
)
from robocal.units import ANGLE_UNITS, LENGTH_UNITS


# ---------------------------------------------------------------------- values
@dataclass(frozen=True)
class Units:
    length: float  # SI per file unit
    angle: float
    length_decimals: int
    angle_decimals: int


UNITS = {
    "urscript": Units(1.0, 1.0, 7, 7),
    "krl": Units(LENGTH_UNITS["mm"], ANGLE_UNITS["deg"], 4, 5),
    "rapid": Units(LENGTH_UNITS["mm"], ANGLE_UNITS["deg"], 4, 5),
}


def read_value(t: ProgramTarget, u: Units, joint_types: Sequence[str], csv_pose_quat: bool) -> Array:
    v = np.array([k.value for k in t.tokens])
    bad = [k.text for k in t.tokens if not math.isfinite(k.value)]
    if bad:
        raise ProgramError(f"{t.file}: line {t.line}: target {t.name}: {bad[0]} is not a finite number")
    if t.kind == "joint":
        return v * np.array([u.angle if jt == "revolute" else u.length for jt in joint_types])
    p = v[:3] * u.length
    if t.style == "urscript":
        R = spatial.rotvec_to_matrix(v[3:6])
    elif t.style == "krl":
        R = spatial.rotz(v[3] * DEG) @ spatial.roty(v[4] * DEG) @ spatial.rotx(v[5] * DEG)
    elif len(v) == 7:  # rapid, csv with a quaternion (scalar first)
        n = np.linalg.norm(v[3:7])
        if n < 1e-9:
            raise ProgramError(f"{t.file}: line {t.line}: target {t.name}: the quaternion is zero")
        R = spatial.quaternion_to_matrix(v[3:7] / n)
    else:
        R = None
    return spatial.homogeneous(R, p) if R is not None else spatial.homogeneous(p=p)


def write_values(
    t: ProgramTarget, u: Units, value: Array, joint_types: Sequence[str]
) -> list[tuple[float, int]]:
    """New numbers (file units) with the decimals to write, for ``t``'s tokens."""
    old = np.array([k.value for k in t.tokens])
    if t.kind == "joint":
        f = np.array([u.angle if jt == "revolute" else u.length for jt in joint_types])
        d = [u.angle_decimals if jt == "revolute" else u.length_decimals for jt in joint_types]
        return list(zip(value / f, d, strict=True))
    T = value
    out = [(float(c), u.length_decimals) for c in T[:3, 3] / u.length]
    if len(t.tokens) == 3:
        return out
    if t.style == "urscript":
        rv = spatial.matrix_to_rotvec(T[:3, :3])
        th = np.linalg.norm(rv)
        if th > 1e-9 and float(rv @ old[3:6]) < 0 and abs(th - math.pi) < 0.5:  # the other side of π
            rv = -rv / th * (2 * math.pi - th)
        out += [(float(c), u.angle_decimals) for c in rv]
    elif t.style == "krl":
        rz, ry, rx = spatial.zyx_angles(T[:3, :3])
        angles = np.degrees([rz, ry, rx])
        angles = old[3:6] + (angles - old[3:6] + 180.0) % 360.0 - 180.0  # nearest to the written angle
        # KRL wants -180..180; what rounds to ±180 at the written resolution stays as written
        beyond = np.abs(angles) > 180.0 + 0.5 * 10.0**-u.angle_decimals
        angles = np.where(beyond, angles - 360.0 * np.sign(angles), angles)
        out += [(float(c), u.angle_decimals) for c in angles]
    else:
        qv = spatial.matrix_to_quaternion(T[:3, :3])
        if float(qv @ old[3:7]) < 0:
            qv = -qv
        qv = qv * np.linalg.norm(old[3:7])  # as normalised as the file's (6 decimals rarely are)
        out += [(float(c), 9) for c in qv]
    return out


def format_value(value: float, token: str, decimals: int) -> str:
    d = max(decimals_of(token), decimals)
    text = f"{value:.{d}f}"
    if "." in text and "." not in token:
        text = text.rstrip("0").rstrip(".") if d > 0 else text
    if text in ("-0", "-0.0") or re.fullmatch(r"-0\.0*", text):
        text = text[1:]
    return text
