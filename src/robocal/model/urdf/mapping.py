"""A source URDF's joints matched to a model's: by name, by ``--joint-map`` or by chain order,
and where the model's base sits in the URDF's root (for :mod:`robocal.model.urdf.export`).

Another description of the same robot (the ROS ``ur_description`` for a catalog UR10) names
its joints differently (``shoulder_pan_joint`` for ``shoulder_pan``) and may root the chain
elsewhere (``base_link`` is the controller's base turned by 180° about z).  The joints are
matched by chain order only when exactly one chain of the URDF moves as many joints of the
same kinds; the export then checks every joint axis against the model's (1e-6 m, rad) and
states the mapping.  Units: m, rad.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from robocal import spatial
from robocal.model.chain import Model
from robocal.model.urdf.read import URDFError
from robocal.model.urdf.source import JointInfo, chain_to, origin_of

__all__ = ["Mapped", "base_note", "chain_order", "map_joints", "root_from_base"]

Array = NDArray[np.float64]


@dataclass(frozen=True)
class Mapped:
    """The source URDF's joint names in the model's joint order, and how they were found
    (``note`` empty: the model's own names)."""

    names: tuple[str, ...]
    note: str = ""


def map_joints(
    path: Path,
    model: Model,
    joints: dict[str, JointInfo],
    links: list[str],
    tip: str | None,
    joint_map: Mapping[str, str] | None,
) -> Mapped:
    """The URDF joints moving the model's joints: by ``joint_map`` (model name -> URDF
    name), by name, or — when the names differ — by chain order (the one chain of the URDF
    with as many movable joints, of the same kinds; its axes are checked afterwards)."""
    names = model.joint_names
    movable = [n for n, j in joints.items() if j.type != "fixed"]
    if joint_map:
        unknown = sorted(set(joint_map) - set(names))
        if unknown:
            raise URDFError(f"--joint-map: {', '.join(unknown)} not joint(s) of model {model.name!r}")
        mapped = tuple(joint_map.get(n, n) for n in names)
        how = "--joint-map"
    elif all(n in movable for n in names):
        return Mapped(tuple(names))
    else:
        mapped = chain_order(path, len(names), joints, links, tip)
        how = "chain order (same number and kinds of joints; axes checked)"
    kinds = [s.joint_type == "prismatic" for s in model.steps if s.joint is not None]
    for n, m, prismatic in zip(names, mapped, kinds, strict=True):
        if m in joints and (joints[m].type == "prismatic") != prismatic:
            raise URDFError(f"{path}: joint {m!r} is {joints[m].type}; the model's joint {n!r} is not")
    pairs = ", ".join(f"{n}={m}" for n, m in zip(names, mapped, strict=True) if n != m)
    return Mapped(mapped, f"joints mapped by {how}: {pairs}")


def chain_order(
    path: Path, dof: int, joints: dict[str, JointInfo], links: list[str], tip: str | None
) -> tuple[str, ...]:
    """The movable joints of the URDF's chain (to ``tip``, or to each leaf link) with ``dof``
    movable joints; refused when there is none or more than one."""
    parents = {j.parent for j in joints.values()}
    ends = [tip] if tip is not None else [link for link in links if link not in parents]
    found = {
        tuple(j.name for j in chain_to(joints, end) if j.type != "fixed") for end in ends if end in links
    }
    found = {c for c in found if len(c) == dof}
    if len(found) != 1:
        what = "no chain" if not found else f"{len(found)} chains"
        raise URDFError(
            f"{path}: the model's joint names are not this URDF's, and {what} of it move(s) {dof} joints: "
            "give --joint-map model_joint=urdf_joint,... (and --tip LINK)"
        )
    return found.pop()


def root_from_base(chain: list[JointInfo], T_base_flange0: Array) -> Array:
    """The model's base frame in the URDF's root frame, from the chain's end at zero (where
    the nominal model's flange is): another description of the same robot may root it
    elsewhere (the ROS UR ``base_link`` is the controller's base turned by 180° about z)."""
    W_tip = np.eye(4)
    for j in chain:
        W_tip = W_tip @ origin_of(j)
    return W_tip @ spatial.inverse(T_base_flange0)


def base_note(B: Array, root: str) -> str:
    if np.abs(B - np.eye(4)).max() < 1e-12:
        return ""
    angle = math.degrees(np.linalg.norm(spatial.matrix_to_rotvec(B[:3, :3])))
    return (
        f"; the model's base is the URDF root {root} moved by {np.linalg.norm(B[:3, 3]) * 1e3:.4g} mm "
        f"and turned by {angle:.4g} deg (the device link, if any, is placed accordingly)"
    )
