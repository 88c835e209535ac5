"""Where the arm is: joint axis lines, the wrist centre and the arm's sides (front/back,
elbow up/down) that KUKA's status, ABB's configuration data and robocal's safety checks name."""

from __future__ import annotations

import numpy as np

from robocal.model.chain import Model
from robocal.spatial import Array

__all__ = ["arm_sides", "axis_line", "wrist_centre"]


def axis_line(F: Array, model: Model, j: int) -> tuple[Array, Array]:
    """A point (m) and the unit direction of joint ``j``'s axis in the base frame."""
    axis = [s for s in model.steps if s.joint is not None][j].axis
    return F[j][:3, 3], F[j][:3, axis]


def wrist_centre(F: Array, model: Model) -> Array:
    """The wrist centre (m): the point of axis 5 nearest axis 4 (where they cross)."""
    p4, a4 = axis_line(F, model, 3)
    p5, a5 = axis_line(F, model, 4)
    c = float(a4 @ a5)
    d = p5 - p4
    if abs(1 - c * c) < 1e-12:
        return p5
    t = (c * (a4 @ d) - a5 @ d) / (1 - c * c)
    return p5 + t * a5


def arm_sides(model: Model, q: Array) -> tuple[float, float]:
    """Where the wrist centre is, as signed distances (m; ~0 on a boundary).

    ``front``: in front of axis 1 (> 0) or behind it (overhead), measured along the
    direction the wrist centre has from axis 1 at the zero position, turned with axis 1.
    ``elbow``: ``((p3 - p2) x (w - p3)) . a3`` — > 0 when axis 3 is beyond the angle that
    stretches the arm (wrist centre on the line of axes 2 and 3), i.e. elbow up."""
    F = model.joint_frames(q)
    F0 = model.joint_frames(np.zeros(model.dof))
    p1, a1 = axis_line(F0, model, 0)
    h0 = wrist_centre(F0, model) - p1
    h0 -= (h0 @ a1) * a1
    front = 0.0
    w = wrist_centre(F, model)
    if np.linalg.norm(h0) > 1e-9:
        local = F0[0][:3, :3].T @ (h0 / np.linalg.norm(h0))
        front = float((w - F[0][:3, 3]) @ (F[0][:3, :3] @ local))
    p2, _ = axis_line(F, model, 1)
    p3, a3 = axis_line(F, model, 2)
    elbow = float(np.cross(p3 - p2, w - p3) @ a3)
    return front, elbow
