"""URDF import: joint axes and origins at the zero configuration, fed to the builder.

Pinocchio parses the URDF (its urdfdom reader) and places every joint at the zero
configuration; robocal then reads each joint's axis and origin in the base frame and
builds a complete, minimal, singularity-free calibration model from them
(:mod:`robocal.model.builder`).  Only the serial chain from the root to the tip link is
read: robocal checks it and hands Pinocchio a URDF of the chain alone, so what hangs off it
as real descriptions come (gripper fingers coupled by ``<mimic>``, camera and sensor frames,
meshes that are not there) is ignored, and so is a fixed joint's ``<axis>`` (Kinova and KUKA
descriptions write ``xyz="0 0 0"``).  The default tip is the deepest link of the single
longest chain (:func:`default_tip`); a robot that branches into several is refused with the
candidates named.  The links' ``<inertial>`` masses become the model's bodies
(:mod:`robocal.model.urdf.inertials`).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from pathlib import Path
from typing import overload

import numpy as np

from robocal.model.builder import BuildResult, build
from robocal.model.chain import Model
from robocal.model.geometry import GeometryError, JointGeometry, JointType, Measure, Tcp
from robocal.model.urdf.inertials import LinkMasses, UrdfJoint, link_masses

__all__ = [
    "URDFError",
    "build_from_urdf",
    "default_tip",
    "geometry_from_urdf",
    "model_from_urdf",
    "urdf_link_masses",
]

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


def read_checked(path: Path) -> str:
    """The URDF's text, once the file and its tree are checked (:func:`_load`) and the numbers
    of every joint (:func:`_check_numbers`: a URDF edited in place is edited through them)."""
    text, tree = _load(path)
    for j in tree.joints:
        _check_numbers(path, j)
    return text


def _load(path: Path) -> tuple[str, _Tree]:
    """The URDF's text and its tree, checked: a regular file within the size limit, no
    DOCTYPE/ENTITY, well-formed XML, and a tree of named joints between existing links."""
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
    return text, _check_xml(path)


_JOINT_TYPES = {"revolute", "continuous", "prismatic", "fixed", "floating", "planar"}
#: what robocal reads of a chain joint's elements (the rest: dynamics, safety ... is not geometry)
_KEPT = {"origin": ("xyz", "rpy"), "axis": ("xyz",), "limit": ("lower", "upper", "effort", "velocity")}


@dataclass(frozen=True)
class _Tree:
    """A URDF's robot name, links (file order) and joints (file order, each a dict: name,
    type, line, parent and child as (link, line), and its elements as tag -> (attrs, line)),
    and each link's ``<inertial>`` as tag -> (attrs, line) (``inertial`` and its elements)."""

    name: str
    links: list[str]
    joints: list[dict]
    inertials: dict[str, dict[str, tuple[dict, int]]] = field(default_factory=dict)


@overload
def _numbers(text: str, count: int, what: str, line: int) -> tuple[float, ...]: ...
@overload
def _numbers(text: str | None, count: int, what: str, line: int) -> tuple[float, ...] | None: ...
def _numbers(text: str | None, count: int, what: str, line: int) -> tuple[float, ...] | None:
    """``count`` finite numbers from an attribute's text (None: the attribute is absent)."""
    if text is None:
        return None
    try:
        values = tuple(float(v) for v in text.split())
    except ValueError:
        values = ()
    if len(values) != count or not all(np.isfinite(values)):
        raise URDFError(f"line {line}: {what} {text!r} is not {count} finite number{'s' * (count > 1)}")
    return values


def _check_xml(path: Path) -> _Tree:
    """Parse the URDF with expat, entities never declared nor resolved, and check the tree
    (what urdfdom would reject with a message that does not say where): syntax (line,
    column), joints without a name, parent or child link, links that do not exist, a link
    with two parents, loops.  The joints' numbers are checked on the chain only
    (:func:`_check_chain`): what is off the chain is not used."""
    tree = _scan_xml(path)
    _check_joints(path, set(tree.links), tree.joints)
    _check_tree(path, tree.joints)
    return tree


def _scan_xml(path: Path) -> _Tree:
    """The robot's name, link names and joints, checking the syntax on the way."""
    from xml.parsers import expat

    parser = expat.ParserCreate()
    parser.SetParamEntityParsing(expat.XML_PARAM_ENTITY_PARSING_NEVER)
    links: dict[str, None] = {}  # ordered, and the check stays linear in the link count
    joints: list[dict] = []
    joint_names: set[str | None] = set()
    inertials: dict[str, dict[str, tuple[dict, int]]] = {}
    stack: list[str] = []
    robot: list[str] = []

    def refuse(*_):
        raise URDFError(
            f"line {parser.CurrentLineNumber}: DOCTYPE/ENTITY declarations are not allowed in a URDF"
        )

    def start(tag, attrs):
        line = parser.CurrentLineNumber
        parent = stack[-1] if stack else None
        stack.append(tag)
        if tag == "robot" and parent is None:
            robot.append(attrs.get("name", ""))
        elif tag == "link" and parent == "robot":
            name = attrs.get("name", "")
            if name in links:
                raise URDFError(f"line {line}: link {name!r} is defined twice")
            links[name] = None
        elif tag == "joint" and parent == "robot":
            if attrs.get("name") in joint_names:
                raise URDFError(f"line {line}: joint {attrs.get('name')!r} is defined twice")
            joint_names.add(attrs.get("name"))
            joints.append({"name": attrs.get("name"), "type": attrs.get("type"), "line": line, "el": {}})
        elif parent == "joint" and len(stack) == 3 and joints:
            if tag in ("parent", "child"):
                joints[-1][tag] = (attrs.get("link"), line)
            else:
                joints[-1]["el"].setdefault(tag, (dict(attrs), line))
        elif stack[1:3] == ["link", "inertial"] and len(stack) <= 4 and links:
            # a link's <inertial> and its <origin>, <mass>, <inertia> (the first of each)
            inertials.setdefault(next(reversed(links)), {}).setdefault(tag, (dict(attrs), line))

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
    return _Tree(robot[0] if robot else "", list(links), joints, inertials)


def _check_chain_joint(path: Path, j: dict) -> None:
    """Check one joint of the chain to the tip: its numbers, a non-zero axis and limits when it
    moves, no coupling."""
    _check_numbers(path, j)
    where = f"{path}: line {j['line']}: joint {j['name']!r}"
    el = j["el"]
    if "mimic" in el:
        raise URDFError(
            f"{where}: mimics joint {el['mimic'][0].get('joint')!r} and is on the chain to the tip: coupled "
            "(mimic) joints are not supported (robocal would calibrate it as an independent joint); "
            "end the chain before it (--tip), or make it fixed if it does not move"
        )
    if j["type"] in ("revolute", "prismatic") and "limit" not in el:
        raise URDFError(f"{where}: a {j['type']} joint needs <limit lower upper effort velocity>")


def _check_numbers(path: Path, j: dict) -> None:
    """Check joint ``j``'s origin, and its axis (not zero) and limits when it moves; a fixed
    joint's axis is not read (it has none to speak of)."""
    el = j["el"]
    try:
        if "origin" in el:
            attrs, line = el["origin"]
            _numbers(attrs.get("xyz"), 3, "origin xyz", line)
            _numbers(attrs.get("rpy"), 3, "origin rpy", line)
        if j["type"] == "fixed":
            return
        if "axis" in el:
            attrs, line = el["axis"]
            axis = _numbers(attrs.get("xyz"), 3, "axis xyz", line)
            if axis is not None and not any(axis):
                raise URDFError(f"line {line}: joint {j['name']!r}: the axis is zero")
        if "limit" in el:
            attrs, line = el["limit"]
            lo = _numbers(attrs.get("lower", "0"), 1, "limit lower", line)
            hi = _numbers(attrs.get("upper", "0"), 1, "limit upper", line)
            if lo[0] > hi[0]:
                raise URDFError(f"line {line}: joint {j['name']!r}: limit lower {lo[0]:g} > upper {hi[0]:g}")
    except URDFError as err:
        raise URDFError(f"{path}: {err}") from None


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
    if len(joints) > MAX_URDF_ALL_JOINTS:  # the chain walks are per link: keep them bounded
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


def _joint_axis(joint_model) -> tuple[JointType, np.ndarray]:
    """(type, axis in the joint frame) of a Pinocchio 1-DOF joint model."""
    name = joint_model.shortname()
    kind: JointType | None = None
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


def _chain(tree: _Tree, tip: str) -> list[dict]:
    """The joints from the root to link ``tip``, root first."""
    by_child = {j["child"][0]: j for j in tree.joints}
    chain, link = [], tip
    while link in by_child:  # the tree is checked: no loop
        chain.append(by_child[link])
        link = by_child[link]["parent"][0]
    return chain[::-1]


def _movable(chain: list[dict]) -> tuple[str, ...]:
    return tuple(j["name"] for j in chain if j["type"] != "fixed")


def default_tip(path: Path, tree: _Tree) -> str:
    """The link the chain ends at by default: the deepest link of the single longest chain.

    Every leaf link ends a chain; the longest chains move the most joints.  When they all move
    the same joints (they differ in fixed frames only: ``flange`` -> ``tool0``), the deepest
    leaf is the tip.  Chains of the same length that move different joints (two gripper
    fingers, two arms) or equally deep fixed branches are ambiguous: refused, naming the
    candidates, for ``--tip``."""
    parents = {j["parent"][0] for j in tree.joints}
    leaves = [link for link in tree.links if link not in parents]
    chains = {leaf: _chain(tree, leaf) for leaf in leaves}
    longest = max((len(_movable(c)) for c in chains.values()), default=0)
    if longest == 0:
        raise URDFError(f"{path}: the robot has no movable joint")
    best = [leaf for leaf, c in chains.items() if len(_movable(c)) == longest]
    deepest = max(len(chains[leaf]) for leaf in best)
    tips = [leaf for leaf in best if len(chains[leaf]) == deepest]
    if len({_movable(chains[leaf]) for leaf in best}) == 1 and len(tips) == 1:
        return tips[0]
    ranked = sorted(leaves, key=lambda leaf: -len(_movable(chains[leaf])))
    listed = ", ".join(f"{leaf!r} ({len(_movable(chains[leaf]))} joints)" for leaf in ranked[:12])
    more = f" and {len(ranked) - 12} more" if len(ranked) > 12 else ""
    raise URDFError(
        f"{path}: the robot branches into {len(best)} chains of {longest} joints ending at different "
        f"links; choose the tip with --tip LINK (chain ends: {listed}{more})"
    )


def _tip_link(path: Path, tree: _Tree, tip: str | None) -> str:
    """``tip`` as a link name (a joint's name stands for its child link), or the default."""
    if tip is None:
        return default_tip(path, tree)
    if tip in tree.links:
        return tip
    child = {j["name"]: j["child"][0] for j in tree.joints}
    if tip in child:
        return child[tip]
    shown = ", ".join(repr(n) for n in tree.links[:40]) + (" ..." if len(tree.links) > 40 else "")
    raise URDFError(f"{path}: no link {tip!r}; links are {shown}")


def _chain_urdf(tree: _Tree, chain: list[dict]) -> str:
    """A URDF of the chain alone (bare links; each joint's origin, axis and limit): what is
    off the chain (fingers, mimic joints, sensors, meshes) never reaches the URDF reader."""
    from xml.etree import ElementTree as ET

    robot = ET.Element("robot", name=tree.name or "robot")
    for link in [chain[0]["parent"][0], *(j["child"][0] for j in chain)]:
        ET.SubElement(robot, "link", name=link)
    for j in chain:
        joint = ET.SubElement(robot, "joint", name=j["name"], type=j["type"])
        ET.SubElement(joint, "parent", link=j["parent"][0])
        ET.SubElement(joint, "child", link=j["child"][0])
        for tag, keys in _KEPT.items():
            if tag in j["el"] and not (tag == "axis" and j["type"] == "fixed"):
                attrs = j["el"][tag][0]
                ET.SubElement(joint, tag, {k: attrs[k] for k in keys if k in attrs})
    return ET.tostring(robot, encoding="unicode")


def geometry_from_urdf(path: str | Path, tip: str | None = None) -> tuple[str, list[JointGeometry], Tcp]:
    """Joint geometry (name, joints, TCP) of the serial chain from the root to ``tip``.

    Only the chain is read: joints and links off it (gripper fingers with ``<mimic>``,
    sensor frames, meshes) are ignored, and so is a fixed joint's axis.

    Args:
        path: the URDF file.
        tip: name of the link to end at (a joint's name stands for its child link); default:
            the deepest link of the single longest chain (:func:`default_tip`).
    """
    path = Path(path)
    _, tree = _load(path)
    tip_link = _tip_link(path, tree, tip)
    chain = _chain(tree, tip_link)
    return _chain_geometry(path, tree, chain, tip_link)


def _chain_geometry(
    path: Path, tree: _Tree, chain: list[dict], tip_link: str
) -> tuple[str, list[JointGeometry], Tcp]:
    """:func:`geometry_from_urdf` of the ``chain`` of joints to ``tip_link``, checked here."""
    import pinocchio as pin

    if not _movable(chain):
        raise URDFError(f"{path}: link {tip_link!r} is not moved by any joint")
    for joint in chain:
        _check_chain_joint(path, joint)
    try:
        pm = pin.buildModelFromXML(_chain_urdf(tree, chain))
    except (RuntimeError, ValueError) as err:
        raise URDFError(f"{path}: {err}") from None
    data = pm.createData()
    pin.framesForwardKinematics(pm, data, pin.neutral(pm))
    frame_id = pm.getFrameId(tip_link, pin.FrameType.BODY)
    joints: list[JointGeometry] = []
    previous = np.zeros(3)
    for j in range(1, pm.njoints):  # the chain alone: joint j's parent is j - 1
        try:
            kind, local_axis = _joint_axis(pm.joints[j])
        except URDFError as err:
            raise URDFError(f"{path}: joint {pm.names[j]!r}: {err}") from None
        M = data.oMi[j]
        axis = M.rotation @ local_axis
        origin = np.array(M.translation)
        iq = pm.joints[j].idx_q
        limits = None
        if pm.joints[j].nq == 1:  # continuous joints are stored as (cos, sin): no limits
            lo, hi = float(pm.lowerPositionLimit[iq]), float(pm.upperPositionLimit[iq])
            limits = (lo, hi) if np.isfinite(lo) and np.isfinite(hi) and lo < hi else None
        joints.append(JointGeometry(kind, tuple(origin - previous), tuple(axis), pm.names[j], limits))
        previous = origin
    tip_frame = data.oMf[frame_id]
    tcp = Tcp(
        tuple(np.array(tip_frame.translation) - previous), tuple(map(tuple, np.array(tip_frame.rotation)))
    )
    return tree.name or path.stem, joints, tcp


def build_from_urdf(
    path: str | Path,
    measure: Measure = "pose",
    tip: str | None = None,
    name: str | None = None,
) -> BuildResult:
    """Build a complete, minimal, singularity-free calibration model of a URDF robot.

    Returns the builder's :class:`~robocal.model.builder.BuildResult` (``.model`` is the
    model); the continuous joints of the URDF become revolute joints without limits, and the
    links' ``<inertial>`` masses the model's ``bodies`` (:mod:`robocal.model.urdf.inertials`).
    """
    path = Path(path)
    _, tree = _load(path)
    tip_link = _tip_link(path, tree, tip)
    chain = _chain(tree, tip_link)
    robot_name, joints, tcp = _chain_geometry(path, tree, chain, tip_link)
    try:
        built = build(joints, tcp, measure, name=name or robot_name, source=f"URDF {path.name}")
    except GeometryError as err:
        raise URDFError(f"{path}: {err}") from None
    masses = _link_masses(path, tree, chain, built.model)
    return dataclasses.replace(built, model=dataclasses.replace(built.model, bodies=masses.bodies))


def urdf_link_masses(path: str | Path, model: Model, tip: str | None = None) -> LinkMasses:
    """The URDF's link masses (``<inertial>``) as bodies of ``model``, built from its chain to
    ``tip`` (:func:`build_from_urdf` attaches them), with the links left out: on the base, behind
    a movable joint off the chain (:mod:`robocal.model.urdf.inertials`)."""
    path = Path(path)
    _, tree = _load(path)
    return _link_masses(path, tree, _chain(tree, _tip_link(path, tree, tip)), model)


def _link_masses(path: Path, tree: _Tree, chain: list[dict], model: Model) -> LinkMasses:
    """:func:`~robocal.model.urdf.inertials.link_masses` of the URDF's links rigid to the chain;
    a bad ``<inertial>`` (or joint origin) is refused naming the file, the link (joint) and line."""
    joints = [
        UrdfJoint.read(j["name"], j["type"], j["parent"][0], j["child"][0], j["el"], j["line"])
        for j in tree.joints
    ]
    try:
        return link_masses(model, joints, [j["name"] for j in chain], tree.inertials)
    except ValueError as err:
        raise URDFError(f"{path}: {err}") from None


def model_from_urdf(
    path: str | Path, measure: Measure = "pose", tip: str | None = None, name: str | None = None
) -> Model:
    """The calibration model of a URDF robot (see :func:`build_from_urdf`)."""
    return build_from_urdf(path, measure, tip, name).model
