"""Names and text written into a URDF: validated and escaped, never pasted.

A name (link, joint, robot) comes from an option, a model file or a source URDF; pasted
into XML unescaped, ``dev"/><link name="evil`` would add links and joints (a
``<gazebo><plugin>`` is loaded as code) and ``a&b<c`` would make the file invalid.
:func:`check_name` refuses a name outside :data:`NAME_PATTERN` (the characters ROS
names and URDF tools use) with one line naming where it came from; :func:`attr` escapes
what is written in any case (:func:`xml.sax.saxutils.quoteattr`); :func:`comment` makes
notes safe inside ``<!-- -->``.
"""

from __future__ import annotations

import math
import re
from collections.abc import Iterable, Sequence
from xml.sax.saxutils import quoteattr

import numpy as np
from numpy.typing import NDArray

from robocal import spatial

__all__ = [
    "NAME_PATTERN",
    "PUBLISHED_LIMITS",
    "attr",
    "check_name",
    "comment",
    "comment_text",
    "fixed_pair",
    "num",
    "own_limits",
    "rpy_from_matrix",
    "triple",
]

Array = NDArray[np.float64]

#: A URDF name robocal writes: letters, digits, ``_ . - /`` (ROS names and namespaces),
#: at most 200 characters, not starting with ``-`` or ``.``.
NAME_PATTERN = re.compile(r"[A-Za-z0-9_/][A-Za-z0-9_./-]{0,199}")
# characters XML 1.0 does not allow at all (control characters but tab, newline, return)
_NOT_XML = re.compile("[\x00-\x08\x0b\x0c\x0e-\x1f\ufffe\uffff]")


def check_name(name: str, what: str) -> str:
    """``name`` when it is a safe URDF name; ValueError naming ``what`` (e.g. ``"--device-link"``)
    otherwise."""
    if not isinstance(name, str) or NAME_PATTERN.fullmatch(name) is None:
        raise ValueError(
            f"{what} {name!r}: a URDF name takes letters, digits and _ . - / only (up to 200, "
            "not starting with - or .)"
        )
    return name


def check_names(names: Iterable[str], what: str) -> None:
    """:func:`check_name` for each of ``names``."""
    for n in names:
        check_name(n, what)


def attr(value: str) -> str:
    """``value`` as a quoted XML attribute value (``&``, ``<``, ``>`` and quotes escaped)."""
    return quoteattr(_NOT_XML.sub("?", str(value)))


def comment_text(text: str) -> str:
    """``text`` safe inside an XML comment: no ``--``, no trailing ``-``, no characters XML
    forbids."""
    text = _NOT_XML.sub("?", text)
    while "--" in text:
        text = text.replace("--", "-")
    return text[:-1] + "_" if text.endswith("-") else text


def comment(lines: Sequence[str], indent: str = "") -> str:
    """An XML comment of ``lines`` (each made safe by :func:`comment_text`)."""
    return indent + "<!-- " + f"\n{indent}     ".join(comment_text(n) for n in lines) + " -->"


def num(v: float) -> str:
    """A number for a URDF attribute (shortest exact repr; ``0`` below 1e-15)."""
    if abs(v) < 1e-15:
        return "0"
    text = repr(float(v))
    return text[:-2] if text.endswith(".0") else text


def triple(values: Iterable[float]) -> str:
    return " ".join(num(v) for v in values)


#: Joint effort (N·m) and velocity (rad/s) limits as the manufacturers' ROS descriptions
#: publish them (Universal Robots ``ur_description`` ``config/<model>/joint_limits.yaml``,
#: from the UR user manuals and UR's "Max. joint torques" article), by the catalog title's
#: start; robocal's catalog holds position limits only.
PUBLISHED_LIMITS: dict[str, tuple[tuple[float, float], ...]] = {
    "Universal Robots UR10 ": ((330.0, 2.0944),) * 2 + ((150.0, 3.1416),) + ((56.0, 3.1416),) * 3,
    "Universal Robots UR5 ": ((150.0, 3.1416),) * 3 + ((28.0, 3.1416),) * 3,
}  # fmt: skip


def published_limits(title: str, dof: int) -> tuple[tuple[float, float], ...] | None:
    """``(effort, velocity)`` per joint of the robot ``title`` (:data:`PUBLISHED_LIMITS`), or None."""
    for start, limits in PUBLISHED_LIMITS.items():
        if title.startswith(start) and len(limits) == dof:
            return limits
    return None


def rpy_from_matrix(R: Array) -> tuple[float, float, float]:
    """URDF roll, pitch, yaw (rad) of a rotation ``R = Rz(yaw) Ry(pitch) Rx(roll)``.

    Accurate to rounding even at pitch = ±90° (the UR URDFs' ``rpy="0 1.5707... 0"``):
    roll from ``R[2, 1:]``, then pitch and yaw from ``R Rx(roll)ᵀ = Rz(yaw) Ry(pitch)``,
    whose entries used are of order one.
    """
    R = np.asarray(R, dtype=float)
    roll = math.atan2(R[2, 1], R[2, 2])
    M = R @ spatial.rotx(roll).T
    pitch = math.atan2(-M[2, 0], M[2, 2])
    yaw = math.atan2(-M[0, 1], M[1, 1])
    return roll, pitch, yaw


def fixed_pair(new: str, existing: str, T: Array, links: Sequence[str], parent_is_new: bool = True) -> str:
    """A new link and the fixed joint attaching it (``new`` is the parent when
    ``parent_is_new``, i.e. a new root)."""
    if new in links:
        raise ValueError(f"link {new!r} exists already in the URDF; choose another name")
    parent, child = (new, existing) if parent_is_new else (existing, new)
    rpy = rpy_from_matrix(T[:3, :3])
    return (  # names escaped: `existing` comes from the source URDF as parsed
        f'<link name={attr(new)}/>\n  <joint name={attr(new + "_joint")} type="fixed">\n'
        f"    <parent link={attr(parent)}/>\n    <child link={attr(child)}/>\n"
        f'    <origin xyz="{triple(T[:3, 3])}" rpy="{triple(rpy)}"/>\n  </joint>'
    )


def own_limits(title: str, dof: int) -> tuple[tuple[tuple[float, float], ...], str]:
    """``(effort, velocity)`` per joint for a kinematic URDF, and the note saying where they
    came from: the manufacturer's published values where robocal knows them, else zeros
    stated as unknown (URDF requires the attributes; MoveIt reads velocity 0 as unbounded)."""
    published = published_limits(title, dof)
    if published is not None:
        return published, (
            "joint limits: positions from robocal's catalog, effort (N m) and velocity (rad/s) as "
            "the manufacturer's ROS description publishes them"
        )
    return ((0.0, 0.0),) * dof, (
        "joint limits: positions from the model (robocal's catalog); effort and velocity are NOT "
        'known to robocal and written as effort="0" velocity="0": set the manufacturer\'s values'
    )
