"""Batched forward kinematics and analytic Jacobian columns of a chain, with numpy.

The numpy path of :class:`robocal.model.chain.Model` (the compiled one is
:mod:`robocal.model.kernels`).  Frames are kept in structure-of-arrays layout ``(3, 4, n)``:
the rows of ``[R | p]`` with the poses last.  Lengths m, angles rad.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from robocal.model.chain_plan import EYE4, Plan

__all__ = [
    "columns",
    "cross_rows",
    "evaluate",
    "forward",
    "perturbation_layout",
    "rotate_rows",
    "tilt_columns",
    "to_homogeneous",
]

Array = NDArray[np.float64]
SMALL_BATCH = 20_000  # steps x poses below which the Jacobian's cross products run over all steps at once


def forward(
    plan: Plan,
    seg_T: Array,
    offsets: Array,
    q: Array,
    perturbations: Array | None,
    keep_anchors: bool,
) -> tuple[Array, Array | None]:
    """Batched FK in structure-of-arrays layout.

    Frames are ``F`` shaped ``(3, 4, n)``: the rows of ``[R | p]`` with the poses
    last, so that every update below is a contiguous vector operation.

    Returns the tool frame and, when asked, the anchor frames ``(dof + 1, 3, 4, n)``:
    anchor 0 is the base (identity), anchor j + 1 the frame just after joint j's step.
    ``seg_T``: the segment transforms of :func:`~robocal.model.chain_plan.segment_data`;
    ``offsets`` ``(dof,)``: the joint steps' values.
    """
    n, dof = q.shape
    qt = q.T + offsets[:, None]  # (dof, n) joint step values
    if perturbations is not None:
        qt = qt + perturbations[:, :, 2].T
    rot = np.array(plan.joint_rot, dtype=bool)
    cos, sin = np.cos(qt[rot]), np.sin(qt[rot])  # one trig call each for all revolute joints
    constant = ~np.all(seg_T == EYE4, axis=(1, 2))  # segments that change the frame
    anchors = None
    if keep_anchors:
        anchors = np.empty((dof + 1, 3, 4, n))
        anchors[0] = EYE4[:3, :, None]
    F = np.empty((3, 4, n))
    F[:] = seg_T[0][:3, :, None]
    r = 0
    for j in range(dof):
        k = plan.joint_axis[j]
        if plan.joint_rot[j]:
            rotate_rows(F, k, cos[r], sin[r])
            r += 1
        else:
            F[:, 3] += F[:, k] * qt[j]
        if perturbations is not None:
            tilt_a, tilt_b = perturbations[:, j, 0], perturbations[:, j, 1]
            rotate_rows(F, (k + 1) % 3, np.cos(tilt_a), np.sin(tilt_a))
            rotate_rows(F, (k + 2) % 3, np.cos(tilt_b), np.sin(tilt_b))
        if anchors is not None:  # keep_anchors
            anchors[j + 1] = F
        if constant[j + 1]:
            F = np.matmul(seg_T[j + 1].T, F)  # each row r of [R | p]: (4, 4)ᵀ @ (4, n)
    return F, anchors


def columns(
    plan: Plan,
    local: Array,
    F: Array,
    anchors: Array,
    perturbations: Array | None,
    steps: Sequence[int] | NDArray[np.intp],
    orientation: bool = True,
    tilt: bool = False,
) -> tuple[Array, ...]:
    """Derivative columns of the tool pose wrt the values of ``steps`` (chain order).

    ``F``, ``anchors``: :func:`forward`'s tool and anchor frames (``keep_anchors``); ``local``:
    the local step frames of :func:`~robocal.model.chain_plan.segment_data`.

    Returns ``F_tool (3, 4, n)`` and ``J (m, 6, n)`` with rows [dp; dω], or
    ``(m, 3, n)`` position rows only when ``orientation`` is false; with ``tilt``
    also the columns of the joint tilts ``(dof, 2, rows, n)`` (δα, δβ; see
    :func:`tilt_columns`).

    For a step hanging off anchor frame (R, p_a) with local axis a_l and local
    origin o_l, the world axis is a = R a_l and origin o = p_a + R o_l, so
    a × (p − o) = a × (p − p_a) − R (a_l × o_l).  All steps at once: each step's
    anchor frame is gathered, ``a`` and ``R (a_l × o_l)`` are three multiply-adds
    over the anchors' rotation columns, and one cross product with ``p − p_a``
    finishes the rotation columns; a translation step's column is ``dp = a, dω = 0``.
    A fixed handful of whole-array operations, whatever the chain's length: at a
    hundred poses the cost is the number of numpy calls, not the arithmetic.
    """
    idx = np.asarray(steps, dtype=np.intp)
    n = F.shape[-1]
    m = len(idx)
    rows = 6 if orientation else 3
    loc = local[idx]
    a_loc = loc[np.arange(m), :3, plan.step_axis[idx]]  # (m, 3) axis in the anchor frame
    c_loc = cross_rows(a_loc, loc[:, :3, 3])  # (m, 3) a_l × o_l
    step_anchor = plan.anchor_of[idx]
    A = np.empty((m, 3, n))  # world axes R a_l
    RC = np.empty((m, 3, n))  # R (a_l × o_l)
    bounds = np.flatnonzero(np.diff(step_anchor)) + 1
    for lo, hi in zip(np.r_[0, bounds], np.r_[bounds, m], strict=True) if m else ():
        # the steps of one anchor are contiguous: one product each for their a and R c,
        # written in place ((3, k, n) views: the rows of R times the vectors)
        R = anchors[step_anchor[lo], :, :3]
        np.matmul(a_loc[lo:hi], R, out=A[lo:hi].transpose(1, 0, 2))
        np.matmul(c_loc[lo:hi], R, out=RC[lo:hi].transpose(1, 0, 2))
    # r = p − p_a, the tool point from each step's anchor origin: for few poses gathered
    # for all steps (one block, fewest numpy calls); for many, one (3, n) vector per
    # anchor broadcast over its steps (least memory traffic)
    if m * n <= SMALL_BATCH:
        blocks = [(0, m, F[None, :, 3] - anchors[step_anchor, :, 3])]
    else:
        blocks = [
            (lo, hi, (F[:, 3] - anchors[step_anchor[lo], :, 3])[None])
            for lo, hi in zip(np.r_[0, bounds], np.r_[bounds, m], strict=True)
        ]
    J = np.empty((m, rows, n))
    for lo, hi, r in blocks:  # a × r, then − R (a_l × o_l) below
        Ab, Jb = A[lo:hi], J[lo:hi]
        np.multiply(Ab[:, 1], r[:, 2], out=Jb[:, 0])
        Jb[:, 0] -= Ab[:, 2] * r[:, 1]
        np.multiply(Ab[:, 2], r[:, 0], out=Jb[:, 1])
        Jb[:, 1] -= Ab[:, 0] * r[:, 2]
        np.multiply(Ab[:, 0], r[:, 1], out=Jb[:, 2])
        Jb[:, 2] -= Ab[:, 1] * r[:, 0]
    J[:, :3] -= RC
    if orientation:
        J[:, 3:] = A
    for c in np.flatnonzero(~plan.step_rot[idx]):  # slices: a boolean mask would copy
        J[c, :3] = A[c]
        if orientation:
            J[c, 3:] = 0.0
    if tilt:
        return F, J, tilt_columns(plan, F, anchors[1:], perturbations, orientation)
    return F, J


def tilt_columns(
    plan: Plan, F: Array, anchors: Array, perturbations: Array | None, orientation: bool
) -> Array:
    """Exact derivatives of the tool pose wrt the joint tilts δα, δβ, ``(dof, 2, rows, n)``.

    After joint ``j`` (axis ``k``, perpendicular axes ``u = k+1``, ``w = k+2``) the
    frame is ``F_j = F Rot_k(θ) Rot_u(δα) Rot_w(δβ)``.  A change of δβ turns the tool
    about ``F_j``'s ``w`` axis; a change of δα about the ``u`` axis of
    ``F Rot_k(θ) Rot_u(δα)``, which is ``cos δβ e_u + sin δβ e_k`` in ``F_j``'s axes.
    Both axes pass through the joint frame's origin.
    """
    n = F.shape[-1]
    rows = 6 if orientation else 3
    out = np.empty((len(anchors), 2, rows, n))
    p_tool = F[:, 3]
    for j, A in enumerate(anchors):
        k = plan.joint_axis[j]
        u, w = (k + 1) % 3, (k + 2) % 3
        a_alpha = A[:, u]
        if perturbations is not None:
            b = perturbations[:, j, 1]
            a_alpha = np.cos(b) * A[:, u] + np.sin(b) * A[:, k]
        r = p_tool - A[:, 3]
        for c, axis in enumerate((a_alpha, A[:, w])):
            out[j, c, :3] = np.cross(axis, r, axis=0)
            if orientation:
                out[j, c, 3:] = axis
    return out


def cross_rows(a: Array, b: Array) -> Array:
    """Row-wise cross products of ``(m, 3)`` arrays (``np.cross`` costs more in set-up
    than in arithmetic for the few dozen rows of a chain)."""
    out = np.empty_like(a)
    out[:, 0] = a[:, 1] * b[:, 2] - a[:, 2] * b[:, 1]
    out[:, 1] = a[:, 2] * b[:, 0] - a[:, 0] * b[:, 2]
    out[:, 2] = a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]
    return out


def rotate_rows(F: Array, axis: int, c: Array, s: Array) -> None:
    """In place ``F[:, :3] <- F[:, :3] @ rot(axis, angle)`` for ``F`` ``(3, 4, n)``.

    ``c``, ``s`` are the angle's cosine and sine per pose ``(n,)``.  Only the two
    columns perpendicular to ``axis`` change: six vector operations instead of a
    batched 3x3 product.
    """
    i, j = (axis + 1) % 3, (axis + 2) % 3
    Fi, Fj = F[:, i], F[:, j]  # (3, n) each
    t = Fi * s
    Fi *= c
    Fi += Fj * s
    Fj *= c
    Fj -= t


def perturbation_layout(tilt: Array, joints: Array) -> Array:
    """Tilt columns ``(dof, 2, rows, n)`` and joint columns ``(n * rows, dof)`` ->
    ``(n * rows, dof, 3)`` in the order (δα, δβ, δθ)."""
    dof, _, rows, n = tilt.shape
    out = np.empty((n, rows, dof, 3))
    out[..., :2] = tilt.transpose(3, 2, 0, 1)
    out[..., 2] = joints.reshape(n, rows, dof)
    return out.reshape(n * rows, dof, 3)


def to_homogeneous(F: Array) -> Array:
    """Structure-of-arrays frames ``(3, 4, n)`` -> homogeneous ``(n, 4, 4)``."""
    n = F.shape[-1]
    T = np.zeros((n, 4, 4))
    T[:, :3, :] = F.transpose(2, 0, 1)
    T[:, 3, 3] = 1.0
    return T


def evaluate(
    model: Any,
    q: Array,
    d: Array | None,
    values: Array | None,
    rows: str,
    jacobian: bool,
    joint_columns: bool,
    perturbation_columns: bool,
) -> tuple[Any, ...]:
    """:meth:`robocal.model.chain.Model.evaluate` of ``model`` with numpy (same arguments,
    checked by it; same returns)."""
    if not jacobian and not joint_columns and not perturbation_columns:
        F, _ = model._forward(q, d, keep_anchors=False, values=values)
        return to_homogeneous(F), None
    free = np.flatnonzero(model.free_mask) if jacobian else np.zeros(0, dtype=np.intp)
    need_joints = joint_columns or perturbation_columns
    joints = model._plan.joint_steps if need_joints else np.zeros(0, dtype=np.intp)
    steps = np.union1d(free, joints)
    F, J, *tilt = model._columns(
        q, d, steps, orientation=rows == "pose", values=values, tilt=perturbation_columns
    )
    J = np.ascontiguousarray(J.transpose(2, 1, 0)).reshape(J.shape[2] * J.shape[1], len(steps))
    J_free = J[:, np.searchsorted(steps, free)] if jacobian else None
    out: tuple[Any, ...] = (to_homogeneous(F), J_free)
    J_joints = J[:, np.searchsorted(steps, joints)]  # (rows, dof); empty without need_joints
    if joint_columns:
        out += (J_joints,)
    if perturbation_columns:
        out += (perturbation_layout(tilt[0], J_joints),)
    return out
