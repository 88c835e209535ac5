"""An inclinometer's mount stated once, whatever chain is calibrated (issue 33).

A person fixes an inclinometer on a link and notes how it sits.  What they can state
without knowing any chain's frames is its orientation with the robot at home (every
joint at zero), against the robot's base: mounted level there (the two channels'
axes horizontal), with its ``x`` axis along the base's ``x`` (the file's
``home_rx_deg, home_ry_deg, home_rz_deg`` = 0, 0, 0), or turned about the vertical by
ψ (0, 0, ψ).  That is a physical orientation of the sensor on its link
(``R_base_sensor`` at home); it is resolved against a chain's *nominal* robot at home
into that chain's joint frame (``R_joint_sensor = R_base_joint(0)ᵀ R_base_sensor``),
so two chains of the same robot (the catalog chain, its complete position model) carry
the same sensors.

The older statement, angles about the link's joint-frame axes (``mount_r*_deg``, none:
the joint frame itself), depends on the chain whose frames they are in: the complete
model of the Katana turns joints 4 and 5's frames by 180° about their axes, so the same
angles there describe sensors whose channels read the opposite sign.
:func:`mounts_at_home` restates them at home through the chain they were written for (the
robot's own chain: the catalog's, a model file's), after which they too are the same
sensors in any chain.

Angles: rad, fixed axes x, y, z in that order (``R = Rz Ry Rx``, scipy's ``"xyz"``).
"""

from __future__ import annotations

import dataclasses

import numpy as np
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation

from robocal.measure.constraints.data_set import ConstraintSet
from robocal.model.chain import Model

__all__ = ["axis_shifts", "home_frames", "loads_about", "mounts_at_home", "mounts_in"]

Array = NDArray[np.float64]


def home_frames(model: Model) -> Array:
    """``(dof, 3, 3)`` each joint frame's orientation in ``model``'s base at home (all
    joints zero; the frame after each joint step, as :meth:`Model.joint_frames`)."""
    return np.asarray(model.joint_frames(np.zeros((1, model.dof)))[0, :, :3, :3], dtype=float)


def _as_matrices(angles: Array) -> Array:
    return np.asarray(Rotation.from_euler("xyz", angles).as_matrix(), dtype=float).reshape(-1, 3, 3)


def _as_angles(matrices: Array) -> Array:
    angles = np.asarray(Rotation.from_matrix(matrices).as_euler("xyz"), dtype=float).reshape(-1, 3)
    return np.where(np.abs(angles) < 1e-12, 0.0, angles)  # level: 0, not 1e-17, in a file


def mounts_in(data: ConstraintSet, model: Model) -> ConstraintSet:
    """``data`` with every mount stated at home (``tilt_home``) resolved into ``model``'s
    joint frames (``tilt_mount`` angles about the joint-frame axes): ``model`` is the
    nominal robot of the chain about to be calibrated or judged (its values at the start,
    not a calibrated copy's, so that the sensor stays where the person put it).  Rows
    already in joint frames are kept; no home row: ``data`` itself."""
    rows = np.flatnonzero(data.tilt_home)
    if not len(rows):
        return data
    R_base_joint = home_frames(model)[data.tilt_link[rows]]
    R_joint_sensor = np.einsum("nji,njk->nik", R_base_joint, _as_matrices(data.tilt_mount[rows]))
    mount = data.tilt_mount.copy()
    mount[rows] = _as_angles(R_joint_sensor)
    return dataclasses.replace(data, tilt_mount=mount, tilt_home=np.zeros(data.n, dtype=bool))


def mounts_at_home(data: ConstraintSet, model: Model) -> ConstraintSet:
    """``data`` with every tilt row's mount stated at home: rows whose angles are about
    ``model``'s joint-frame axes (none: the joint frame itself) become the sensor's
    orientation in the base frame with every joint of ``model`` at zero.  ``model``: the
    chain those angles were written for (the robot's own chain)."""
    rows = np.flatnonzero(data.tilted & ~data.tilt_home)
    if not len(rows):
        return data
    R_base_joint = home_frames(model)[data.tilt_link[rows]]
    R_base_sensor = R_base_joint @ _as_matrices(data.tilt_mount[rows])
    mount = data.tilt_mount.copy()
    mount[rows] = _as_angles(R_base_sensor)
    return dataclasses.replace(data, tilt_mount=mount, tilt_home=data.tilted.copy())


def axis_shifts(robot: Model, frames: Model) -> Array:
    """``(dof,)`` how far (m) along each joint's axis ``frames``' joint frame origin lies
    from ``robot``'s, at home: two chains of one robot place a joint's frame at different
    points of its axis (the Katana's complete model moves joint 5's by 0.147 m).  A joint
    whose axes do not lie on one line (another robot) is not shifted (0)."""
    zero = np.zeros((1, robot.dof))
    here, there = robot.joint_frames(zero)[0], frames.joint_frames(zero)[0]
    axes = [s.axis for s in robot.steps if s.joint is not None]
    shifts = np.zeros(robot.dof)
    R = home_frames(robot)
    for j, k in enumerate(axes):
        e = R[j][:, k]
        d = there[j, :3, 3] - here[j, :3, 3]
        t = float(e @ d)
        same_line = np.linalg.norm(d - t * e) < 1e-9 and abs(abs(e @ there[j, :3, k]) - 1) < 1e-9
        shifts[j] = t if same_line else 0.0
    return shifts


def loads_about(robot: Model, q: Array, frames: Model | None = None) -> Array:
    """Seed 003's load moments ``(n, dof, 3)`` (:func:`robocal.model.joints.load_moments`)
    of ``robot`` at ``q``, the bending moments taken about ``frames``' joint frame origins
    (:func:`axis_shifts`; None: ``robot``'s own).  A bending moment depends on the point of
    the axis it is taken about; the effects (Table 5.2) are stated with the robot's own
    chain's points, so a fit in another chain of it (the complete model of a mixed
    tracker and tilt fit) takes them about the same points and identifies the same effects.
    The axial moment is the same about every point of the axis."""
    from robocal.model.dynamics import joint_wrenches
    from robocal.model.joints import load_moments

    eta = load_moments(robot, q)
    if frames is None or frames.dof != robot.dof:
        return eta
    shifts = axis_shifts(robot, frames)
    if not shifts.any():
        return eta
    W = joint_wrenches(robot, q)  # support force in each joint frame; η = −(support moment)
    axes = [s.axis for s in robot.steps if s.joint is not None]
    for j, k in enumerate(axes):
        u, w = (k + 1) % 3, (k + 2) % 3
        # about p + t·e_k: M' = M − t e_k × f, so η' = η + t e_k × f (e_k × e_u = e_w)
        eta[:, j, 0] -= shifts[j] * W[:, j, w]
        eta[:, j, 1] += shifts[j] * W[:, j, u]
    return eta
