"""The URDF a model was built from, as bytes: its joints with their elements' byte ranges and
origins, the chain to a tip and in-place attribute edits (for :mod:`robocal.model.urdf.export`)."""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from robocal.model.urdf.inertials import urdf_transform
from robocal.model.urdf.read import URDFError

Array = NDArray[np.float64]


urdf_origin = urdf_transform  # the 4x4 transform of a URDF <origin xyz rpy> (m, rad)


# ---------------------------------------------------------------------- the source URDF
@dataclass
class _Element:
    tag: str
    start: int  # byte index of "<"
    end: int  # byte index after the start tag's ">"
    line: int
    attrs: dict[str, str]


@dataclass
class JointInfo:
    name: str
    type: str
    line: int
    element: _Element
    parent: str = ""
    child: str = ""
    origin: _Element | None = None
    axis: _Element | None = None


def _tag_end(data: bytes, start: int) -> int:
    """Byte index after the ``>`` closing the start tag at ``start`` (quotes respected)."""
    quote = None
    for i in range(start + 1, len(data)):
        ch = data[i : i + 1]
        if quote:
            if ch == quote:
                quote = None
        elif ch in (b'"', b"'"):
            quote = ch
        elif ch == b">":
            return i + 1
    raise URDFError("unterminated tag")  # pragma: no cover - expat refused it before


def scan(path: Path, data: bytes) -> tuple[dict[str, JointInfo], list[str], _Element]:
    """Joints (in file order) with their element positions, the links, the ``<robot>``."""
    from xml.parsers import expat

    parser = expat.ParserCreate()
    parser.SetParamEntityParsing(expat.XML_PARAM_ENTITY_PARSING_NEVER)
    joints: dict[str, JointInfo] = {}
    links: list[str] = []
    stack: list[str] = []
    robot: list[_Element] = []

    def start(tag, attrs):
        i = parser.CurrentByteIndex
        el = _Element(tag, i, _tag_end(data, i), parser.CurrentLineNumber, dict(attrs))
        parent = stack[-1] if stack else None
        stack.append(tag)
        if tag == "robot" and parent is None:
            robot.append(el)
        elif tag == "link" and parent == "robot":
            links.append(attrs.get("name", ""))
        elif tag == "joint" and parent == "robot":
            name = attrs.get("name", "")
            joints[name] = JointInfo(name, attrs.get("type", ""), el.line, el)
        elif parent == "joint" and len(stack) == 3 and joints:
            j = joints[next(reversed(joints))]
            if tag == "parent":
                j.parent = attrs.get("link", "")
            elif tag == "child":
                j.child = attrs.get("link", "")
            elif tag == "origin":
                j.origin = el
            elif tag == "axis":
                j.axis = el

    parser.StartElementHandler = start
    parser.EndElementHandler = lambda tag: stack.pop()
    parser.Parse(data, True)
    if not robot:
        raise URDFError(f"{path}: no <robot> root element")
    return joints, links, robot[0]


def origin_of(j: JointInfo) -> Array:
    if j.origin is None:
        return np.eye(4)
    xyz = [float(v) for v in j.origin.attrs.get("xyz", "0 0 0").split()]
    rpy = [float(v) for v in j.origin.attrs.get("rpy", "0 0 0").split()]
    return urdf_origin(xyz, rpy)


def axis_of(j: JointInfo) -> Array:
    a = np.array([float(v) for v in (j.axis.attrs.get("xyz", "1 0 0") if j.axis else "1 0 0").split()])
    return a / np.linalg.norm(a)


def set_attrs(tag: bytes, values: dict[str, str]) -> bytes:
    """The start tag ``tag`` with attributes set (replaced in place, or appended)."""
    for key, value in values.items():
        pattern = re.compile(rb"(\s" + key.encode() + rb"\s*=\s*)([\"'])(.*?)\2", re.S)
        m = pattern.search(tag)
        if m:
            q = m.group(2)
            tag = tag[: m.start()] + m.group(1) + q + value.encode() + q + tag[m.end() :]
        else:
            close = len(tag) - (2 if tag.endswith(b"/>") else 1)
            sep = b"" if tag[close - 1 : close].isspace() else b" "
            tag = (
                tag[:close]
                + sep
                + f'{key}="{value}"'.encode()
                + (b" " if tag.endswith(b"/>") else b"")
                + tag[close:]
            )
    return tag


def chain_to(joints: dict[str, JointInfo], tip: str) -> list[JointInfo]:
    by_child = {j.child: j for j in joints.values()}
    chain, link = [], tip
    while link in by_child:
        j = by_child[link]
        chain.append(j)
        link = j.parent
    return chain[::-1]


def default_tip(joints: dict[str, JointInfo], last_movable: JointInfo) -> str:
    """The link where the chain ends: the deepest link reached from the last movable joint's
    child through fixed joints only (``tool0`` in the ROS descriptions; of equally deep ones,
    the last found), as :func:`robocal.model.urdf.read.default_tip` ends the chain."""
    depth = {last_movable.child: 0}
    tip = last_movable.child
    changed = True
    while changed:
        changed = False
        for j in joints.values():
            if j.type == "fixed" and j.parent in depth and j.child not in depth:
                depth[j.child] = depth[j.parent] + 1
                changed = True
    for link, d in depth.items():
        if d >= depth[tip]:
            tip = link
    return tip
