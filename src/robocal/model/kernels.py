"""Compiled kernels of the chain (numba): forward kinematics, joint frames and the fused
tool-frame + identification-Jacobian pass, one pose at a time in registers.

The numpy code of :class:`robocal.model.chain.Model` (``_forward``, ``_columns``) is the
reference: these kernels compute the same quantities with the same formulas (see its
docstrings), and ``tests/test_kernels.py`` holds them to it to 1e-12.  numpy's batched form
pays one call per step and per chain operation, which dominates for one configuration
(62 µs) and for the hundred poses of a calibration; compiled, a pose costs its arithmetic.

The kernels are compiled with ``cache=True``: the first use after installation compiles
them (a few seconds) and writes the machine code next to this file (or in numba's user cache
directory when that is read-only); later processes load it from there.  This module imports
numba, so it is itself imported only by the calls that use it (the ``robocal`` command starts
without it).

Layouts: frames ``(n, 4, 4)``; Jacobians pose-major, row ``pose * rows + r`` with ``rows`` 3
(x, y, z) or 6 (x, y, z, ωx, ωy, ωz), as :meth:`~robocal.model.chain.Model.evaluate` returns.
"""

from __future__ import annotations

import math

import numba
import numpy as np

__all__ = ["evaluate", "forward", "segment_data"]

_jit = numba.njit(cache=True, nogil=True)


@_jit
def _rotate(F, axis, c, s):
    """``F[:, :3] <- F[:, :3] @ rot(axis, angle)`` for a ``(3, 4)`` frame (as chain._rotate_rows)."""
    i = (axis + 1) % 3
    j = (axis + 2) % 3
    for r in range(3):
        fi = F[r, i]
        fj = F[r, j]
        F[r, i] = fi * c + fj * s
        F[r, j] = fj * c - fi * s


@_jit
def _times_segment(F, S):
    """``F <- F @ S`` in place for a ``(3, 4)`` frame and a ``(4, 4)`` rigid transform."""
    for r in range(3):
        f0, f1, f2 = F[r, 0], F[r, 1], F[r, 2]
        F[r, 0] = f0 * S[0, 0] + f1 * S[1, 0] + f2 * S[2, 0]
        F[r, 1] = f0 * S[0, 1] + f1 * S[1, 1] + f2 * S[2, 1]
        F[r, 2] = f0 * S[0, 2] + f1 * S[1, 2] + f2 * S[2, 2]
        F[r, 3] = f0 * S[0, 3] + f1 * S[1, 3] + f2 * S[2, 3] + F[r, 3]


@_jit
def segment_data(values, step_axis, step_rot, step_joint, dof):
    """Constant segment transforms ``(dof + 1, 4, 4)`` and each step's local frame
    ``(P, 4, 4)`` (as :meth:`~robocal.model.chain.Model._segment_data`)."""
    P = values.shape[0]
    seg = np.zeros((dof + 1, 4, 4))
    local = np.zeros((P, 4, 4))
    cur = np.eye(4)
    a = 0
    for i in range(P):
        local[i] = cur
        if step_joint[i]:
            seg[a] = cur
            a += 1
            cur = np.eye(4)
        elif step_rot[i]:
            _rotate(cur, step_axis[i], math.cos(values[i]), math.sin(values[i]))
        else:
            k = step_axis[i]
            for r in range(3):
                cur[r, 3] += cur[r, k] * values[i]
    seg[a] = cur
    return seg, local


@_jit
def _pose_forward(q, pert, p, has_pert, seg, offsets, joint_axis, joint_rot, anchors, F):
    """Frames of pose ``p``: the anchors into ``anchors`` ``(dof + 1, 3, 4)`` (0: the base,
    j + 1: after joint j) and the tool frame into ``F`` ``(3, 4)``."""
    dof = q.shape[1]
    for r in range(3):
        for c in range(4):
            F[r, c] = seg[0, r, c]
            anchors[0, r, c] = 1.0 if r == c else 0.0
    for j in range(dof):
        k = joint_axis[j]
        theta = q[p, j] + offsets[j]
        if has_pert:
            theta = theta + pert[p, j, 2]
        if joint_rot[j]:
            _rotate(F, k, math.cos(theta), math.sin(theta))
        else:
            for r in range(3):
                F[r, 3] += F[r, k] * theta
        if has_pert:
            _rotate(F, (k + 1) % 3, math.cos(pert[p, j, 0]), math.sin(pert[p, j, 0]))
            _rotate(F, (k + 2) % 3, math.cos(pert[p, j, 1]), math.sin(pert[p, j, 1]))
        for r in range(3):
            for c in range(4):
                anchors[j + 1, r, c] = F[r, c]
        _times_segment(F, seg[j + 1])


@_jit
def forward(q, pert, has_pert, seg, offsets, joint_axis, joint_rot, keep_anchors):
    """Tool frames ``(n, 4, 4)`` and, when asked, the frames after each joint
    ``(n, dof, 4, 4)`` (else an empty array)."""
    n, dof = q.shape
    T = np.zeros((n, 4, 4))
    frames = np.zeros((n if keep_anchors else 0, dof, 4, 4))
    anchors = np.empty((dof + 1, 3, 4))
    F = np.empty((3, 4))
    for p in range(n):
        _pose_forward(q, pert, p, has_pert, seg, offsets, joint_axis, joint_rot, anchors, F)
        for r in range(3):
            for c in range(4):
                T[p, r, c] = F[r, c]
        T[p, 3, 3] = 1.0
        if keep_anchors:
            for j in range(dof):
                for r in range(3):
                    for c in range(4):
                        frames[p, j, r, c] = anchors[j + 1, r, c]
                frames[p, j, 3, 3] = 1.0
    return T, frames


@_jit
def evaluate(
    q,
    pert,
    has_pert,
    seg,
    local,
    offsets,
    joint_axis,
    joint_rot,
    anchor_of,
    step_axis,
    step_rot,
    columns,
    joint_steps,
    rows,
    want_joint,
    want_tilt,
):
    """Tool frames and derivative columns in one pass over the poses.

    Returns ``T (n, 4, 4)``; ``J (n * rows, m)``: the columns of the steps ``columns``
    (chain order); and ``P (n * rows, dof, 3)``: with ``want_joint`` the joint columns in
    ``P[..., 2]``, with ``want_tilt`` also the tilt columns (δα, δβ) in ``P[..., :2]``
    (empty when neither).  Formulas: :meth:`~robocal.model.chain.Model._columns` and
    :meth:`~robocal.model.chain.Model._tilt_columns`.
    """
    n, dof = q.shape
    m = columns.shape[0]
    T = np.zeros((n, 4, 4))
    J = np.empty((n * rows, m))
    P = np.zeros((n * rows if (want_joint or want_tilt) else 0, dof, 3))
    anchors = np.empty((dof + 1, 3, 4))
    # per column: the axis a_l and a_l x o_l in its anchor's frame (constant over poses)
    a_loc = np.empty((m, 3))
    c_loc = np.empty((m, 3))
    for c in range(m):
        s = columns[c]
        k = step_axis[s]
        for r in range(3):
            a_loc[c, r] = local[s, r, k]
        o0, o1, o2 = local[s, 0, 3], local[s, 1, 3], local[s, 2, 3]
        c_loc[c, 0] = a_loc[c, 1] * o2 - a_loc[c, 2] * o1
        c_loc[c, 1] = a_loc[c, 2] * o0 - a_loc[c, 0] * o2
        c_loc[c, 2] = a_loc[c, 0] * o1 - a_loc[c, 1] * o0
    jl = np.empty((dof, 3))  # the same for the joint steps
    jc = np.empty((dof, 3))
    for j in range(dof):
        s = joint_steps[j]
        k = step_axis[s]
        for r in range(3):
            jl[j, r] = local[s, r, k]
        o0, o1, o2 = local[s, 0, 3], local[s, 1, 3], local[s, 2, 3]
        jc[j, 0] = jl[j, 1] * o2 - jl[j, 2] * o1
        jc[j, 1] = jl[j, 2] * o0 - jl[j, 0] * o2
        jc[j, 2] = jl[j, 0] * o1 - jl[j, 1] * o0
    A = np.empty(3)
    RC = np.empty(3)
    d = np.empty(3)
    F = np.empty((3, 4))
    for p in range(n):
        _pose_forward(q, pert, p, has_pert, seg, offsets, joint_axis, joint_rot, anchors, F)
        for r in range(3):
            for c in range(4):
                T[p, r, c] = F[r, c]
        T[p, 3, 3] = 1.0
        row = p * rows
        for c in range(m):
            s = columns[c]
            an = anchors[anchor_of[s]]
            for r in range(3):
                A[r] = an[r, 0] * a_loc[c, 0] + an[r, 1] * a_loc[c, 1] + an[r, 2] * a_loc[c, 2]
            if step_rot[s]:
                for r in range(3):
                    RC[r] = an[r, 0] * c_loc[c, 0] + an[r, 1] * c_loc[c, 1] + an[r, 2] * c_loc[c, 2]
                    d[r] = F[r, 3] - an[r, 3]
                J[row, c] = A[1] * d[2] - A[2] * d[1] - RC[0]
                J[row + 1, c] = A[2] * d[0] - A[0] * d[2] - RC[1]
                J[row + 2, c] = A[0] * d[1] - A[1] * d[0] - RC[2]
                if rows == 6:
                    for r in range(3):
                        J[row + 3 + r, c] = A[r]
            else:
                for r in range(3):
                    J[row + r, c] = A[r]
                    if rows == 6:
                        J[row + 3 + r, c] = 0.0
        if not (want_joint or want_tilt):
            continue
        for j in range(dof):  # joint columns (δθ): the joint step's column
            s = joint_steps[j]
            an = anchors[anchor_of[s]]
            for r in range(3):
                A[r] = an[r, 0] * jl[j, 0] + an[r, 1] * jl[j, 1] + an[r, 2] * jl[j, 2]
            if step_rot[s]:
                for r in range(3):
                    RC[r] = an[r, 0] * jc[j, 0] + an[r, 1] * jc[j, 1] + an[r, 2] * jc[j, 2]
                    d[r] = F[r, 3] - an[r, 3]
                P[row, j, 2] = A[1] * d[2] - A[2] * d[1] - RC[0]
                P[row + 1, j, 2] = A[2] * d[0] - A[0] * d[2] - RC[1]
                P[row + 2, j, 2] = A[0] * d[1] - A[1] * d[0] - RC[2]
                if rows == 6:
                    for r in range(3):
                        P[row + 3 + r, j, 2] = A[r]
            else:
                for r in range(3):
                    P[row + r, j, 2] = A[r]
            if not want_tilt:
                continue
            an = anchors[j + 1]  # tilts turn about the joint frame's perpendicular axes
            k = joint_axis[j]
            u = (k + 1) % 3
            w = (k + 2) % 3
            for r in range(3):
                d[r] = F[r, 3] - an[r, 3]
            for t in range(2):
                if t == 0:
                    cb = math.cos(pert[p, j, 1]) if has_pert else 1.0
                    sb = math.sin(pert[p, j, 1]) if has_pert else 0.0
                    for r in range(3):
                        A[r] = cb * an[r, u] + sb * an[r, k] if has_pert else an[r, u]
                else:
                    for r in range(3):
                        A[r] = an[r, w]
                P[row, j, t] = A[1] * d[2] - A[2] * d[1]
                P[row + 1, j, t] = A[2] * d[0] - A[0] * d[2]
                P[row + 2, j, t] = A[0] * d[1] - A[1] * d[0]
                if rows == 6:
                    for r in range(3):
                        P[row + 3 + r, j, t] = A[r]
    return T, J, P
