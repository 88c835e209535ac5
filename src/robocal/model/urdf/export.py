"""URDF export: a calibrated model as a URDF whose forward kinematics are the model's.

Two ways (:func:`calibrated_urdf`):

* **With the source URDF** the robot was built from: the file is kept byte for byte
  (links, visuals and meshes, collisions, inertials, limits, transmissions, gazebo and
  ros2_control elements, comments) except the ``xyz``/``rpy`` attributes of the
  ``<origin>`` of each movable joint of the chain, of the first fixed joint after the
  last movable joint (the flange) and, only where the model turns a joint axis against
  its link, the ``<axis>``.  Every link frame rides on its calibrated joint exactly as it
  rode on the nominal one, so meshes stay on their links.
* **Without a source URDF** (a model built from joint geometry, a catalog robot): a
  kinematic URDF of its own, one link per joint frame of the chain (``base_link``,
  ``<joint>_link``..., ``flange``), no geometry.

Joint offsets are folded into the origins (no ``<calibration rising=...>`` tags, which
the drivers ignore): the exported URDF at joint values ``q`` is the model at ``q``.

How the origins are computed
----------------------------
Let ``F_j(q)`` be the model's frame directly after the step of joint ``j`` (it moves
with the child link; its origin is on the joint axis).  The URDF's child link frame of
joint ``j`` is ``L_j(q) = F_j(q) X_j`` with a constant ``X_j`` taken from the *nominal*
model and the source URDF at the zero configuration, ``X_j = F_j^nominal(0)⁻¹ L_j^urdf(0)``
(translation along the joint axis, rotation such that the URDF's axis is the model's
axis).  Then ``L_j(q) = L_j(q_j=0) · Rot(axis_j, q_j)`` and the new ``<origin>`` of joint
``j`` is ``W_parent⁻¹ W_child`` of the calibrated link frames at zero; the fixed joints
between two movable joints keep their origins.  The flange (the model's last robot
frame, before the measured tool ``tcp_*``) is reached by rewriting the origin of the
first fixed joint after the last movable joint; where the model does not hold the
flange's orientation (a model for position measurement), the tip keeps the URDF's
orientation relative to the flange.

What a URDF cannot carry — joint effects (compliance, clearance, backlash: pose- and
load-dependent), a learned residual — is stated in an XML comment after ``<robot>``
(the caller passes the notes and their sizes).

Units: SI (m, rad) in the file, as URDF prescribes.

Reading the source URDF's bytes: :mod:`robocal.model.urdf.source`.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from robocal import spatial
from robocal.model.chain import Model
from robocal.model.flange_tool import split_tool
from robocal.model.urdf.mapping import base_note, map_joints, root_from_base
from robocal.model.urdf.read import URDFError, read_checked
from robocal.model.urdf.source import (
    JointInfo,
    axis_of,
    chain_to,
    default_tip,
    origin_of,
    scan,
    set_attrs,
    urdf_origin,
)
from robocal.model.urdf.xml_text import attr, check_name, comment, own_limits, rpy_from_matrix
from robocal.model.urdf.xml_text import fixed_pair as _fixed_pair
from robocal.model.urdf.xml_text import num as _num
from robocal.model.urdf.xml_text import triple as _triple

__all__ = ["TOOL_PREFIX", "URDFExport", "calibrated_urdf", "rpy_from_matrix", "urdf_origin"]

Array = NDArray[np.float64]
#: Names of the measured tool's steps (the identification appends them after the robot;
#: told by their role, Role.TOOL)
TOOL_PREFIX = "tcp_"
#: How far the nominal model may be from the source URDF (m, rad) before the export
#: refuses: the model was not built from this URDF.
MATCH_TOL = 1e-6


@dataclass(frozen=True)
class URDFExport:
    """An exported URDF.

    Attributes:
        text: the URDF document (str).
        root: the root link's name (the device link when one was added).
        tip: the link at the model's flange (before the measured tool).
        tool_link: the link at the measured tool (``None`` when not added).
        changed: names of the joints whose ``<origin>``/``<axis>`` was rewritten or added.
        notes: what the URDF does not carry, as stated in its comment.
    """

    text: str
    root: str
    tip: str
    tool_link: str | None
    changed: tuple[str, ...]
    notes: tuple[str, ...]


# ---------------------------------------------------------------------- numbers
# ---------------------------------------------------------------------- the chain
@dataclass(frozen=True)
class _Chain:
    """The model split for export: frames at the zero configuration (SI)."""

    F0: Array  # (dof, 4, 4) frame after each joint step at q = 0
    axes: tuple[int, ...]  # local axis index of each joint step
    types: tuple[str, ...]
    T_base_flange0: Array  # robot (no tool steps) at q = 0
    T_flange_tool: Array  # the measured tool steps (constant)


def _split(model: Model) -> _Chain:
    parts = split_tool(model)  # ValueError for tool steps before the robot's end
    robot = dataclasses.replace(parts.robot, bodies=(), joint_effects=())
    q0 = np.zeros(model.dof)
    T_flange_tool = np.eye(4) if parts.T_flange_tool is None else parts.T_flange_tool
    joints = [s for s in model.steps if s.joint is not None]
    return _Chain(
        F0=model.joint_frames(q0),
        axes=tuple(s.axis for s in joints),
        types=tuple(s.joint_type or "" for s in joints),
        T_base_flange0=robot.fk(q0),
        T_flange_tool=T_flange_tool,
    )


def _minimal_rotation(b: Array, a: Array) -> Array:
    """The smallest rotation taking unit vector ``b`` onto unit vector ``a``."""
    v = np.cross(b, a)
    s, c = np.linalg.norm(v), float(np.dot(b, a))
    if s < 1e-300:
        if c > 0:
            return np.eye(3)
        raise ValueError("opposite axes")
    return spatial.rotvec_to_matrix(v / s * math.atan2(s, c))


def _comment(notes: Sequence[str]) -> str:
    title = "robocal: calibrated kinematics (joint origins rewritten; joint offsets folded in)."
    return comment([title, *notes])


def _export_source(
    model: Model,
    nominal: Model,
    path: Path,
    tip: str | None,
    T_device_base: Array | None,
    device_link: str | None,
    tool_link: str | None,
    notes: Sequence[str],
    joint_map: Mapping[str, str] | None = None,
) -> URDFExport:
    read_checked(path)
    data = path.read_bytes()
    joints, links, robot = scan(path, data)
    mapped = map_joints(path, nominal, joints, links, tip, joint_map)
    chain, tip_link = _source_chain(path, mapped.names, joints, links, tip)
    root = chain[0].parent
    # nominal link frames of the URDF at zero, and the calibrated ones, in the URDF's root frame
    nom, cal, B, notes = _in_root(chain, _split(nominal), _split(model), mapped, notes)
    new_origin, new_axis, W_urdf, W_last = _calibrated_joints(path, chain, nom, cal)
    # the flange: the first fixed joint after the last movable joint carries the correction
    after = chain[[j.name for j in chain].index(mapped.names[-1]) + 1 :]
    # the URDF's tip in the nominal model's flange frame: a rotation when the model does not
    # hold the flange orientation (position measurement); it rides on the calibrated flange
    G = spatial.inverse(nom.T_base_flange0) @ W_urdf
    if np.linalg.norm(G[:3, 3]) > MATCH_TOL:
        raise URDFError(
            f"{path}: link {tip_link!r} is {np.linalg.norm(G[:3, 3]) * 1e3:.4g} mm from the nominal "
            "model's flange: give the link the model ends at (tip)"
        )
    G[:3, 3] = 0.0
    T_base_tip = cal.T_base_flange0 @ G
    flange_link: str | None = None
    flange_pair: str | None = None
    if after:
        rest = np.eye(4)
        for j in after[1:]:
            rest = rest @ origin_of(j)
        new_origin[after[0].name] = spatial.inverse(W_last) @ T_base_tip @ spatial.inverse(rest)
    else:
        gap = spatial.inverse(W_last) @ T_base_tip
        if (
            np.linalg.norm(gap[:3, 3]) > 1e-12
            or np.linalg.norm(spatial.matrix_to_rotvec(gap[:3, :3])) > 1e-12
        ):
            # no fixed joint to carry the calibrated flange: a new flange link on the tip
            flange_link = f"{tip_link}_calibrated"
            flange_pair = _fixed_pair(flange_link, tip_link, gap, links, parent_is_new=False)
            notes = [
                *notes,
                f"the calibrated flange is link {flange_link} (the chain ended at {tip_link}, "
                "which has no fixed joint to carry it)",
            ]
    # edit the bytes, last edit first
    edits = _joint_edits(data, joints, new_origin, new_axis)
    additions: list[str] = [] if flange_pair is None else [flange_pair]
    new_root = root
    if device_link is not None:
        additions.append(_device_pair(device_link, root, T_device_base, B, links))
        new_root = device_link
    if tool_link is not None:
        T_tip_tool = spatial.inverse(G) @ cal.T_flange_tool
        parent = tip_link if flange_link is None else flange_link
        additions.append(_fixed_pair(tool_link, parent, T_tip_tool, links, parent_is_new=False))
    end_robot = data.rfind(b"</robot>")
    if additions:
        block = "\n  " + "\n  ".join(additions) + "\n"
        edits.append((end_robot, end_robot, block.encode()))
    comment = "\n  " + _comment(notes).replace("\n", "\n  ")
    edits.append((robot.end, robot.end, comment.encode()))
    return URDFExport(
        text=_apply_edits(path, data, edits),
        root=new_root,
        tip=tip_link if flange_link is None else flange_link,
        tool_link=tool_link,
        changed=tuple(sorted(set(new_origin) | set(new_axis), key=list(joints).index)),
        notes=tuple(notes),
    )


def _in_root(
    chain: list[JointInfo], nom: _Chain, cal: _Chain, mapped, notes: Sequence[str]
) -> tuple[_Chain, _Chain, Array, list[str]]:
    """The nominal and calibrated chains in the URDF's root frame, that frame's transform
    ``B`` from the model's base, and the notes (with the mapping stated)."""
    if not mapped.note:  # the URDF the model was built from: its root is the model's base
        return nom, cal, np.eye(4), list(notes)
    # another description of the robot: its root may sit elsewhere on the base
    B = root_from_base(chain, nom.T_base_flange0)
    return _rebased(nom, B), _rebased(cal, B), B, [*notes, mapped.note + base_note(B, chain[0].parent)]


def _device_pair(name: str, root: str, T_device_base: Array | None, B: Array, links: Sequence[str]) -> str:
    if T_device_base is None:
        raise ValueError("a device link needs T_device_base (the calibration's device frame)")
    return _fixed_pair(name, root, np.asarray(T_device_base, dtype=float) @ spatial.inverse(B), links)


def _rebased(c: _Chain, B: Array) -> _Chain:
    return dataclasses.replace(c, F0=B @ c.F0, T_base_flange0=B @ c.T_base_flange0)


def _source_chain(
    path: Path, names: Sequence[str], joints: dict[str, JointInfo], links: list[str], tip: str | None
) -> tuple[list[JointInfo], str]:
    """The URDF's joints from its root to the tip link (``tip`` or the default), checked to move
    the model's joints ``names`` in order; and the tip link."""
    movable = {n: j for n, j in joints.items() if j.type != "fixed"}
    missing = [n for n in names if n not in movable]
    if missing:
        raise URDFError(
            f"{path}: the model's joint(s) {', '.join(missing)} are not movable joints of this URDF "
            f"(it has {', '.join(movable) or 'none'}): not the URDF the model was built from"
        )
    tip_link = tip or default_tip(joints, movable[names[-1]])
    if tip_link not in links:
        raise URDFError(f"{path}: no link {tip_link!r}; links are {', '.join(links)}")
    chain = chain_to(joints, tip_link)
    chain_movable = [j.name for j in chain if j.type != "fixed"]
    if chain_movable != list(names):
        raise URDFError(
            f"{path}: the chain to {tip_link!r} moves {', '.join(chain_movable)}; the model has "
            f"{', '.join(names)}"
        )
    return chain, tip_link


def _calibrated_joints(
    path: Path, chain: list[JointInfo], nom: _Chain, cal: _Chain
) -> tuple[dict[str, Array], dict[str, Array], Array, Array]:
    """The calibrated origin (and axis, where it changed) of every movable joint of ``chain``,
    the nominal frame of the chain's end in the URDF ``W_urdf`` and the calibrated frame of the
    last movable joint ``W_last`` (base frame, at zero)."""
    W_urdf = np.eye(4)
    W_cal = W_last = np.eye(4)
    new_origin: dict[str, Array] = {}
    new_axis: dict[str, Array] = {}
    k = 0
    for j in chain:
        T_o = origin_of(j)
        if j.type == "fixed":
            W_urdf = W_urdf @ T_o
            W_cal = W_cal @ T_o
            continue
        where = f"{path}: line {j.line}: joint {j.name!r}"
        W_parent_cal = W_cal
        W_urdf = W_urdf @ T_o
        a = axis_of(j)
        X = spatial.inverse(nom.F0[k]) @ W_urdf
        e = np.eye(3)[nom.axes[k]]
        b = X[:3, :3].T @ e  # the model's axis in the URDF child frame
        angle = math.atan2(np.linalg.norm(np.cross(b, a)), float(b @ a))
        off_axis = X[:3, 3] - e * float(e @ X[:3, 3])
        kind_ok = (nom.types[k] == "prismatic") == (j.type == "prismatic")
        if (
            not kind_ok
            or angle > MATCH_TOL
            or (j.type != "prismatic" and np.linalg.norm(off_axis) > MATCH_TOL)
        ):
            raise URDFError(
                f"{where}: the nominal model's joint is {math.degrees(angle):.4g} deg and "
                f"{np.linalg.norm(off_axis) * 1e3:.4g} mm away from the URDF's: not the URDF the model was "
                "built from"
            )
        # X with the URDF's axis exactly (a rotation of at most MATCH_TOL) and its origin on the axis
        Xr = X[:3, :3] @ _minimal_rotation(b, a).T
        Xp = e * float(e @ X[:3, 3]) if j.type != "prismatic" else X[:3, 3]
        X_exact = spatial.homogeneous(Xr, Xp)
        W_cal = W_last = cal.F0[k] @ X_exact
        new_origin[j.name] = spatial.inverse(W_parent_cal) @ W_cal
        axis_cal = X_exact[:3, :3].T @ np.eye(3)[cal.axes[k]]
        if cal.axes[k] != nom.axes[k] or np.linalg.norm(axis_cal - a) > 1e-15:
            new_axis[j.name] = axis_cal
        k += 1
    return new_origin, new_axis, W_urdf, W_last


def _joint_edits(
    data: bytes, joints: dict[str, JointInfo], new_origin: dict[str, Array], new_axis: dict[str, Array]
) -> list[tuple[int, int, bytes]]:
    """Byte edits ``(start, end, new)`` writing the new origins and axes; an origin that did not
    change is dropped from ``new_origin`` and keeps its text as written."""
    edits: list[tuple[int, int, bytes]] = []
    for name, T in list(new_origin.items()):
        j = joints[name]
        if np.abs(T - origin_of(j)).max() < 1e-14:  # unchanged: keep the text as written
            del new_origin[name]
            continue
        rpy = rpy_from_matrix(T[:3, :3])
        values = {"xyz": _triple(T[:3, 3]), "rpy": _triple(rpy)}
        if j.origin is not None:
            tag = data[j.origin.start : j.origin.end]
            edits.append((j.origin.start, j.origin.end, set_attrs(tag, values)))
        else:
            text = f'<origin xyz="{values["xyz"]}" rpy="{values["rpy"]}"/>'
            edits.append((j.element.end, j.element.end, text.encode()))
    for name, a in new_axis.items():
        j = joints[name]
        values = {"xyz": _triple(a)}
        if j.axis is not None:
            tag = data[j.axis.start : j.axis.end]
            edits.append((j.axis.start, j.axis.end, set_attrs(tag, values)))
        else:
            edits.append((j.element.end, j.element.end, f'<axis xyz="{values["xyz"]}"/>'.encode()))
    return edits


def _apply_edits(path: Path, data: bytes, edits: list[tuple[int, int, bytes]]) -> str:
    out = data
    for start, end, new in sorted(edits, key=lambda e: e[0], reverse=True):
        out = out[:start] + new + out[end:]
    try:
        return out.decode("utf-8")
    except UnicodeDecodeError as err:
        line = out[: err.start].count(b"\n") + 1
        raise URDFError(f"{path}: line {line}: not UTF-8 text") from None


def _export_own(
    model: Model,
    T_device_base: Array | None,
    device_link: str | None,
    tool_link: str | None,
    notes: Sequence[str],
) -> URDFExport:
    cal = _split(model)
    joints = [s for s in model.steps if s.joint is not None]
    check_name(model.name, "model name")
    for s in joints:
        assert s.joint is not None
        check_name(s.joint.name, f"model {model.name!r}: joint name")
    names = ["base_link", *(f"{s.joint.name}_link" for s in joints if s.joint), "flange"]
    limits, limits_note = own_limits(model.title, len(joints))
    lines = [
        '<?xml version="1.0"?>',
        f"<robot name={attr(model.name)}>",
        "  " + _comment([*notes, limits_note]).replace("\n", "\n  "),
    ]
    lines += [f"  <link name={attr(n)}/>" for n in names]
    previous = np.eye(4)
    for k, s in enumerate(joints):
        assert s.joint is not None
        T_o = spatial.inverse(previous) @ cal.F0[k]
        previous = cal.F0[k]
        kind = cal.types[k]
        lim = s.joint.limits
        if kind == "revolute" and lim is None:
            kind = "continuous"
        lines.append(f'  <joint name={attr(s.joint.name)} type="{kind}">')
        lines.append(f"    <parent link={attr(names[k])}/>\n    <child link={attr(names[k + 1])}/>")
        lines.append(
            f'    <origin xyz="{_triple(T_o[:3, 3])}" rpy="{_triple(rpy_from_matrix(T_o[:3, :3]))}"/>'
        )
        lines.append(f'    <axis xyz="{_triple(np.eye(3)[cal.axes[k]])}"/>')
        if lim is not None or kind == "prismatic":
            lo, hi = lim if lim is not None else (-1.0, 1.0)
            effort, velocity = limits[k]
            lines.append(
                f'    <limit lower="{_num(lo)}" upper="{_num(hi)}" effort="{_num(effort)}" '
                f'velocity="{_num(velocity)}"/>'
            )
        lines.append("  </joint>")
    T_o = spatial.inverse(previous) @ cal.T_base_flange0
    lines.append('  <joint name="flange_joint" type="fixed">')
    lines.append(f'    <parent link={attr(names[-2])}/>\n    <child link="flange"/>')
    lines.append(f'    <origin xyz="{_triple(T_o[:3, 3])}" rpy="{_triple(rpy_from_matrix(T_o[:3, :3]))}"/>')
    lines.append("  </joint>")
    root = "base_link"
    if device_link is not None:
        if T_device_base is None:
            raise ValueError("a device link needs T_device_base (the calibration's device frame)")
        lines.append("  " + _fixed_pair(device_link, "base_link", np.asarray(T_device_base, float), names))
        root = device_link
    if tool_link is not None:
        lines.append("  " + _fixed_pair(tool_link, "flange", cal.T_flange_tool, names, parent_is_new=False))
    lines.append("</robot>\n")
    return URDFExport(
        text="\n".join(lines),
        root=root,
        tip="flange",
        tool_link=tool_link,
        changed=tuple(s.joint.name for s in joints if s.joint),
        notes=(*notes, limits_note),
    )


def calibrated_urdf(
    model: Model,
    source: str | Path | None = None,
    *,
    nominal: Model | None = None,
    tip: str | None = None,
    T_device_base: Array | None = None,
    device_link: str | None = None,
    tool_link: str | None = None,
    notes: Sequence[str] = (),
    joint_map: Mapping[str, str] | None = None,
) -> URDFExport:
    """A URDF whose forward kinematics are ``model``'s (to rounding, ~1e-15 m).

    Args:
        model: the calibrated model (robot steps, then optionally the measured tool
            ``tcp_*``); its base frame is the URDF's root link frame.
        source: the URDF the model was built from (``None``: a kinematic URDF of its own).
        nominal: the model before calibration (the one built from ``source``); it fixes
            where each URDF link sits on its joint.  Default ``model`` itself.
        tip: the URDF link at the model's flange (default: the last link fixed to the
            last movable joint, e.g. ``tool0``).
        T_device_base: ``(4, 4)`` the measuring device's frame (m) for ``device_link``.
        device_link: name of a new root link at the device frame (fixed joint
            ``<name>_joint`` to the robot's root), or ``None``.
        tool_link: name of a new link at the measured tool (fixed joint from the tip),
            or ``None``.
        notes: lines for the XML comment (what the URDF cannot carry, with sizes).
        joint_map: model joint name -> source URDF joint name, for a URDF whose joint names
            differ (default: by name, else by chain order, checked and stated in the notes).

    Raises:
        URDFError: the source URDF is malformed (file and line named) or is not the one
            the model was built from.
        ValueError: a name that is not a safe URDF name (:mod:`robocal.model.urdf.xml_text`).
    """
    for name, what in ((device_link, "--device-link"), (tool_link, "--tool-link"), (tip, "--tip")):
        if name is not None:
            check_name(name, what)
    for a, b in (joint_map or {}).items():
        check_name(a, "--joint-map"), check_name(b, "--joint-map")
    if source is None:
        return _export_own(model, T_device_base, device_link, tool_link, notes)
    nominal = model if nominal is None else nominal
    if nominal.joint_names != model.joint_names:
        raise ValueError("the nominal and calibrated models have different joints")
    return _export_source(
        model, nominal, Path(source), tip, T_device_base, device_link, tool_link, notes, joint_map
    )
