"""Link masses from a URDF's ``<inertial>`` elements, as the bodies of a model built from it.

Joint compliance on position rows (:mod:`robocal.identify.constraints.position_effects`) and
the gravity torques (:func:`robocal.model.dynamics.gravity_torques`) need each link's mass and
centre of mass (:class:`~robocal.model.steps.Body`).  A URDF states them per link, in the
link's frame (``<inertial><origin xyz rpy/><mass value/><inertia .../></inertial>``).  Each
link is rigidly fixed to the frame after the last joint step before it, so its body is
attached to that step with the centre (and inertia) restated in that frame at q = 0, where
the URDF's link frames are the products of the joints' origins.

Which links count: those on the chain from the root to the tip and everything hanging from
them (fixed-joint chains merge into the link they hang from: a gripper base, the tool's ball
after the tip).  Links behind a movable joint off the chain (a gripper's fingers) are taken at
that joint's zero (:attr:`LinkMasses.off_chain`): their mass loads the arm wherever they
are, only their centre moves by their travel.  Links before the first movable joint of the
chain sit on the base and load no joint (:attr:`LinkMasses.on_base`, not made bodies, as
:func:`robocal.model.dynamics.gravity_torques` leaves such bodies out).  Every positive mass
is kept, placeholders too (Kinova's 0.0001 kg): they are what the URDF states and change
nothing that matters.
Units: kg, m, kg·m²; gravity is the caller's (URDF: z up).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from robocal import spatial
from robocal.model.chain import Model
from robocal.model.steps import Body

__all__ = [
    "Inertial",
    "LinkMasses",
    "UrdfJoint",
    "link_masses",
    "origin_of",
    "parse_inertial",
    "urdf_transform",
]

Array = NDArray[np.float64]
#: an element's children as the URDF reader keeps them: tag -> (attributes, line) (for an
#: ``<inertial>``: ``inertial`` itself and its ``origin``, ``mass`` and ``inertia``)
Elements = Mapping[str, tuple[Mapping[str, str], int]]

#: a URDF ``<inertia>``'s attributes (:class:`Body` orders them Ixx, Iyy, Izz, Ixy, Ixz, Iyz)
_INERTIA_KEYS = ("ixx", "ixy", "ixz", "iyy", "iyz", "izz")


def urdf_transform(xyz: Sequence[float] | Array, rpy: Sequence[float] | Array) -> Array:
    """The 4x4 transform of a URDF ``<origin xyz rpy>`` (m, rad; ``R = Rz(y) Ry(p) Rx(r)``)."""
    r, p, y = rpy
    return spatial.homogeneous(spatial.rotz(y) @ spatial.roty(p) @ spatial.rotx(r), xyz)


@dataclass(frozen=True)
class Inertial:
    """One link's ``<inertial>``: its mass (kg), the centre-of-mass frame in the link frame
    (4x4, m) and the inertia about the centre in that frame, ``(3, 3)`` kg·m², or None."""

    link: str
    mass: float
    origin: Array
    inertia: Array | None = None


@dataclass(frozen=True)
class UrdfJoint:
    """What the masses need of one URDF joint: its name, type, parent and child links and
    its origin (4x4, the child's frame in the parent's at the joint's zero; None when its
    numbers are unreadable, ``problem`` says why: a joint off the chain with unexpanded xacro
    only matters when a mass hangs from it)."""

    name: str
    type: str
    parent: str
    child: str
    origin: Array | None
    problem: str = ""

    @classmethod
    def read(
        cls,
        name: str,
        type: str,
        parent: str,
        child: str,
        elements: Elements,
        line: int,
    ) -> UrdfJoint:
        """The joint from its elements (tag -> (attributes, line)), its origin read if it can be."""
        try:
            return cls(name, type, parent, child, origin_of(elements, line))
        except ValueError as err:
            return cls(name, type, parent, child, None, f"joint {name!r}: {err}")


@dataclass(frozen=True)
class LinkMasses:
    """A URDF's link masses on a model: ``bodies`` on its joint steps; the names of the links
    with mass on the base (before the first joint: no joint load, left out) and of the bodies
    behind a movable joint off the chain (taken at that joint's zero)."""

    bodies: tuple[Body, ...]
    on_base: tuple[str, ...] = ()
    off_chain: tuple[str, ...] = ()

    @property
    def mass_kg(self) -> float:
        """Total mass of the bodies (kg)."""
        return float(sum(b.mass for b in self.bodies))


def _finite(text: str | None, count: int, what: str, line: int) -> tuple[float, ...]:
    try:
        values = tuple(float(v) for v in (text or "").split())
    except ValueError:
        values = ()
    if len(values) != count or not all(np.isfinite(values)):
        raise ValueError(f"line {line}: {what} {text!r} is not {count} finite number{'s' * (count > 1)}")
    return values


def origin_of(elements: Elements, line: int) -> Array:
    """The 4x4 transform of an element's ``<origin>`` (``elements``: tag -> (attributes, line);
    none: identity); ValueError naming the line for numbers that are not 3 finite ones."""
    attrs, line = elements.get("origin", ({}, line))
    xyz = _finite(attrs.get("xyz", "0 0 0"), 3, "origin xyz", line)
    rpy = _finite(attrs.get("rpy", "0 0 0"), 3, "origin rpy", line)
    return urdf_transform(xyz, rpy)


def parse_inertial(link: str, elements: Elements) -> Inertial:
    """A link's ``<inertial>`` from its elements (tag -> (attributes, line): ``inertial``,
    ``origin``, ``mass``, ``inertia``); ValueError of one line naming the link and line for a
    missing, negative or non-finite mass, a malformed origin or inertia."""
    where = f"link {link!r}"
    line = elements["inertial"][1]
    if "mass" not in elements:
        raise ValueError(f"{where}: line {line}: an <inertial> without <mass value=...>")
    attrs, line = elements["mass"]
    try:
        (mass,) = _finite(attrs.get("value"), 1, "mass value", line)
        if mass < 0:
            raise ValueError(f"line {line}: mass value {mass!r} is negative")
        origin = origin_of(elements, line)
        inertia = None
        if "inertia" in elements:
            attrs, line = elements["inertia"]
            ixx, ixy, ixz, iyy, iyz, izz = (_finite(attrs.get(k), 1, k, line)[0] for k in _INERTIA_KEYS)
            inertia = np.array([[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]])
    except ValueError as err:
        raise ValueError(f"{where}: {err}") from None
    return Inertial(link, mass, origin, inertia)


#: a link's place: its segment (0 = the base, k = moved by the chain's k-th movable joint), its
#: frame in the root frame at q = 0 (None: a joint above it is unreadable), whether a movable
#: joint off the chain is above it, and the unreadable joint's problem
_Place = tuple[int, Array | None, bool, str]


def _link_frames(joints: Sequence[UrdfJoint], chain: Sequence[str]) -> dict[str, _Place]:
    """Each link carried by the chain (:data:`_Place`): the chain's links first, then what
    hangs from them (breadth first: the tree is checked, no loop), every joint off the chain
    at its zero."""
    by_name = {j.name: j for j in joints}
    root = by_name[chain[0]].parent
    frames: dict[str, _Place] = {root: (0, np.eye(4), False, "")}
    segment = 0
    for name in chain:  # the chain's origins are checked (geometry_from_urdf)
        j = by_name[name]
        segment += j.type != "fixed"
        frames[j.child] = (segment, _child_frame(frames[j.parent][1], j), False, j.problem)
    children: dict[str, list[UrdfJoint]] = {}
    for j in joints:
        children.setdefault(j.parent, []).append(j)
    queue = list(frames)
    while queue:
        link = queue.pop(0)
        segment, T, moving, problem = frames[link]
        for j in children.get(link, ()):
            if j.child not in frames:
                T_child = _child_frame(T, j)
                frames[j.child] = (segment, T_child, moving or j.type != "fixed", problem or j.problem)
                queue.append(j.child)
    return frames


def _child_frame(T_parent: Array | None, joint: UrdfJoint) -> Array | None:
    """The joint's child frame at its zero (root frame), None when it cannot be placed."""
    return None if T_parent is None or joint.origin is None else T_parent @ joint.origin


def _body(inertial: Inertial, frame: str, F_root_step: Array, T_root_link: Array) -> Body:
    """The link's mass as a :class:`Body` on step ``frame`` (its frame ``F_root_step`` at q = 0)."""
    T = np.linalg.solve(F_root_step, T_root_link @ inertial.origin)  # step frame <- centre frame
    x, y, z = T[:3, 3].tolist()
    inertia = None
    if inertial.inertia is not None:
        I = T[:3, :3] @ inertial.inertia @ T[:3, :3].T  # noqa: E741 - the inertia tensor's usual name
        inertia = (I[0, 0], I[1, 1], I[2, 2], I[0, 1], I[0, 2], I[1, 2])
    return Body(inertial.link, frame, inertial.mass, (x, y, z), inertia)


def link_masses(
    model: Model, joints: Sequence[UrdfJoint], chain: Sequence[str], inertials: Mapping[str, Elements]
) -> LinkMasses:
    """The URDF's positive link masses as bodies of ``model`` (built from the chain: its base is
    the URDF's root frame and its joints are the chain's movable joints, in order).

    Args:
        model: the model built from the URDF's chain.
        joints: every joint of the URDF.
        chain: the names of the joints from the root to the tip, root first.
        inertials: each link's ``<inertial>`` elements (:data:`Elements`), by link name; those
            of links the joints carry are read (:func:`parse_inertial`: ValueError of one line
            naming the link when one is bad), those on the base only listed when readable.
    """
    steps = [s.name for s in model.steps if s.joint is not None]
    F = model.joint_frames(np.zeros(model.dof))  # (dof, 4, 4): after each joint step, q = 0
    frames = _link_frames(joints, chain)
    bodies, on_base, off_chain = [], [], []
    for link, elements in inertials.items():
        if link not in frames:
            continue
        segment, T_root_link, moving, problem = frames[link]
        if segment == 0:  # loads no joint: what the file states there does not matter
            if _base_mass(link, elements) > 0:
                on_base.append(link)
            continue
        inertial = parse_inertial(link, elements)
        if inertial.mass <= 0:
            continue
        if T_root_link is None:
            raise ValueError(f"link {link!r} has a mass and hangs from {problem}")
        bodies.append(_body(inertial, steps[segment - 1], F[segment - 1], T_root_link))
        if moving:
            off_chain.append(link)
    return LinkMasses(tuple(bodies), tuple(on_base), tuple(off_chain))


def _base_mass(link: str, elements: Elements) -> float:
    """The mass of a link on the base (kg; 0 when unreadable: it loads no joint)."""
    try:
        return parse_inertial(link, elements).mass
    except ValueError:
        return 0.0
