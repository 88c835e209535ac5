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
from robocal.model.chain import Model

__all__ = ["URDFError", "build_from_urdf", "geometry_from_urdf", "model_from_urdf"]

MAX_URDF_BYTES = 20_000_000
#: Movable joints a URDF may have: Pinocchio's work arrays grow faster than the square of
#: the joint count (a 300-joint chain takes 1.8 GB and 2.5 s, 500 joints 8 GB), and a
#: whole humanoid has about 40.
MAX_URDF_JOINTS = 200
#: Joints of any type (fixed ones too): the URDF reader walks the tree recursively, and a
#: chain of 100 000 fixed joints crashes it
MAX_URDF_ALL_JOINTS = 2000

_AXES = {"X": (1.0, 0.0, 0.0), "Y": (0.0, 1.0, 0.0), "Z": (0.0, 0.0, 1.0)}


class URDFError(ValueError):
    """The URDF file cannot be used; the message names the file and the reason."""


def _read_checked(path: Path) -> str:
    if path.exists() and not path.is_file():  # a FIFO or a device would never end
        raise URDFError(f"{path}: not a regular file")
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
    _check_xml(path)
    return text


_JOINT_TYPES = {"revolute", "continuous", "prismatic", "fixed", "floating", "planar"}


def _numbers(text: str | None, count: int, what: str, line: int) -> tuple[float, ...] | None:
    if text is None:
        return None
    try:
        values = tuple(float(v) for v in text.split())
    except ValueError:
        values = ()
    if len(values) != count or not all(np.isfinite(values)):
        raise URDFError(f"line {line}: {what} {text!r} is not {count} finite number{'s' * (count > 1)}")
    return values


def _check_xml(path: Path) -> None:
    """Parse the URDF with expat, entities never declared nor resolved, and check what
    urdfdom would reject with a message that does not say where: syntax (line,
    column), joints without parent or child link, links that do not exist, numbers
    that are not numbers, a zero axis, inverted limits, a revolute or prismatic joint
    without limits."""
    links, joints = _scan_xml(path)
    _check_joints(path, links, joints)
    _check_tree(path, joints)


def _scan_xml(path: Path) -> tuple[set[str], list[dict]]:
    """The robot's link names and its joints (name, type, line, parent, child, limit), checking
    the syntax and each joint element's numbers on the way."""
    from xml.parsers import expat

    parser = expat.ParserCreate()
    parser.SetParamEntityParsing(expat.XML_PARAM_ENTITY_PARSING_NEVER)
    links: set[str] = set()
    joints: list[dict] = []
    joint_names: set[str | None] = set()  # a set: the check stays linear in the joint count
    stack: list[str] = []

    def refuse(*_):
        raise URDFError(
            f"line {parser.CurrentLineNumber}: DOCTYPE/ENTITY declarations are not allowed in a URDF"
        )

    def start(tag, attrs):
        line = parser.CurrentLineNumber
        parent = stack[-1] if stack else None
        stack.append(tag)
        if tag == "link" and parent == "robot":
            name = attrs.get("name", "")
            if name in links:
                raise URDFError(f"line {line}: link {name!r} is defined twice")
            links.add(name)
        elif tag == "joint" and parent == "robot":
            if attrs.get("name") in joint_names:
                raise URDFError(f"line {line}: joint {attrs.get('name')!r} is defined twice")
            joint_names.add(attrs.get("name"))
            joints.append({"name": attrs.get("name"), "type": attrs.get("type"), "line": line})
        elif parent == "joint" and joints:
            _joint_element(joints[-1], tag, attrs, line)

    parser.StartDoctypeDeclHandler = refuse
    parser.EntityDeclHandler = refuse
    parser.StartElementHandler = start
    parser.EndElementHandler = lambda tag: stack.pop()
    try:
        # one buffer: fed in chunks, expat re-scans a long token (a 19 MB comment) per chunk
        parser.Parse(path.read_bytes(), True)
    except expat.ExpatError as err:
        raise URDFError(
            f"{path}: not well-formed XML: {expat.ErrorString(err.code)} (line {err.lineno}, "
            f"column {err.offset + 1})"
        ) from None
    except URDFError as err:
        raise URDFError(f"{path}: {err}") from None
    return links, joints


def _joint_element(j: dict, tag: str, attrs: dict[str, str], line: int) -> None:
    """Record or check one element inside ``<joint>`` ``j``."""
    if tag in ("parent", "child"):
        j[tag] = (attrs.get("link"), line)
    elif tag == "origin":
        _numbers(attrs.get("xyz"), 3, "origin xyz", line)
        _numbers(attrs.get("rpy"), 3, "origin rpy", line)
    elif tag == "axis":
        axis = _numbers(attrs.get("xyz"), 3, "axis xyz", line)
        if axis is not None and not any(axis):
            raise URDFError(f"line {line}: joint {j['name']!r}: the axis is zero")
    elif tag == "mimic":
        raise URDFError(
            f"line {line}: joint {j['name']!r} mimics joint {attrs.get('joint')!r}: coupled (mimic) "
            "joints are not supported (robocal would calibrate it as an independent joint); make it "
            "fixed or remove the <mimic> element if the joint really moves on its own"
        )
    elif tag == "limit":
        lo = _numbers(attrs.get("lower", "0"), 1, "limit lower", line)
        hi = _numbers(attrs.get("upper", "0"), 1, "limit upper", line)
        if lo[0] > hi[0]:
            raise URDFError(f"line {line}: joint {j['name']!r}: limit lower {lo[0]:g} > upper {hi[0]:g}")
        j["limit"] = True


def _check_joints(path: Path, links: set[str], joints: list[dict]) -> None:
    for j in joints:
        where = f"{path}: line {j['line']}: joint {j['name']!r}"
        if not j["name"]:
            raise URDFError(f"{path}: line {j['line']}: a joint without a name")
        if j["type"] not in _JOINT_TYPES:
            raise URDFError(f"{where}: type {j['type']!r} is not one of {', '.join(sorted(_JOINT_TYPES))}")
        for end in ("parent", "child"):
            link = j.get(end, (None,))[0]
            if not link:
                raise URDFError(f"{where}: no <{end} link=...>")
            if link not in links:
                raise URDFError(f"{where}: {end} link {link!r} is not a <link> of the robot")
        if j["type"] in ("revolute", "prismatic") and not j.get("limit"):
            raise URDFError(f"{where}: a {j['type']} joint needs <limit lower upper effort velocity>")
    if len(joints) > MAX_URDF_ALL_JOINTS:  # urdfdom recurses per link: deep chains crash it
        raise URDFError(
            f"{path}: {len(joints)} joints; robocal reads URDFs of up to {MAX_URDF_ALL_JOINTS} "
            "(fixed ones included)"
        )
    movable = sum(j["type"] != "fixed" for j in joints)
    if movable > MAX_URDF_JOINTS:
        raise URDFError(f"{path}: {movable} movable joints; robocal reads URDFs of up to {MAX_URDF_JOINTS}")


def _check_tree(path: Path, joints: list[dict]) -> None:
    """Every link is the child of one joint at most, and the joints form no loop."""
    children: dict[str, str] = {}
    parent_of: dict[str, str] = {}
    for j in joints:
        child = j["child"][0]
        if child in children:
            raise URDFError(
                f"{path}: line {j['line']}: link {child!r} is the child of joints {children[child]!r} and "
                f"{j['name']!r}: a URDF is a tree"
            )
        children[child] = j["name"]
        parent_of[child] = j["parent"][0]
    state: dict[str, int] = {}  # 1: on the current walk to the root, 2: reaches the root
    for start_link in parent_of:
        walk, link = [], start_link
        while link in parent_of and state.get(link) != 2:
            if state.get(link) == 1:
                raise URDFError(f"{path}: the joints form a loop through link {link!r}: a URDF is a tree")
            state[link] = 1
            walk.append(link)
            link = parent_of[link]
        for name in walk:
            state[name] = 2


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
    if name.endswith("Unaligned"):  # the generic JointModel wraps it
        axis = _unaligned_axis(joint_model, kind)
        if not (np.all(np.isfinite(axis)) and np.linalg.norm(axis) > 0):
            raise URDFError(f"joint axis {axis.tolist()} is not a direction")
        return kind, axis
    letter = name[-1]  # RX, RY, RZ, PX ... ; RUBX etc. are continuous joints
    return kind, np.array(_AXES[letter])


def _unaligned_axis(joint_model, kind: str) -> np.ndarray:
    """The axis of an unaligned joint: ``extract().axis`` where Pinocchio exposes it, else
    the joint's motion subspace at its neutral configuration (angular part for a revolute
    joint, linear part for a prismatic one; continuous unaligned joints have no ``axis``)."""
    specific = joint_model.extract()
    if hasattr(specific, "axis"):
        return np.asarray(specific.axis, dtype=float)
    data = joint_model.createData()
    joint_model.calc(data, np.asarray(joint_model.lieGroup().neutral, dtype=float))
    S = np.asarray(data.S, dtype=float).reshape(6)
    return S[3:] if kind == "revolute" else S[:3]


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


def model_from_urdf(
    path: str | Path, measure: str = "pose", tip: str | None = None, name: str | None = None
) -> Model:
    """The calibration model of a URDF robot (see :func:`build_from_urdf`)."""
    return build_from_urdf(path, measure, tip, name).model
