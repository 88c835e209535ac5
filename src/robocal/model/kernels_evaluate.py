"""The fused compiled pass of the chain (numba): tool frames and identification-Jacobian
columns (and joint and tilt columns) in one pass over the poses — by blocks of poses for the
plain identification Jacobian, pose by pose with perturbations.  Layouts, caching and the
numpy reference: :mod:`robocal.model.kernels`.
"""

from __future__ import annotations

import math

import numpy as np

from robocal.model.kernels import (
    BLOCK,
    anchors_block,
    jit,
    pose_forward,
)

__all__ = ["evaluate", "position_columns_transposed"]


@jit
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
    :meth:`~robocal.model.chain.Model._tilt_columns`.  Without perturbations and joint
    columns (the identification Jacobian) by blocks of poses (:func:`_columns_batch`), else
    pose by pose.
    """
    if not (has_pert or want_joint or want_tilt):
        return _columns_batch(
            q, seg, local, offsets, joint_axis, joint_rot, anchor_of, step_axis, step_rot, columns, rows
        )
    return _evaluate_poses(
        q, pert, has_pert, seg, local, offsets, joint_axis, joint_rot, anchor_of, step_axis, step_rot,
        columns, joint_steps, rows, want_joint, want_tilt,
    )  # fmt: skip


@jit
def _column_constants(local, step_axis, steps):
    """Per step of ``steps``: its axis ``a_l`` and ``a_l × o_l`` in its anchor's frame."""
    m = steps.shape[0]
    a_loc = np.empty((m, 3))
    c_loc = np.empty((m, 3))
    for c in range(m):
        s = steps[c]
        k = step_axis[s]
        for r in range(3):
            a_loc[c, r] = local[s, r, k]
        o0, o1, o2 = local[s, 0, 3], local[s, 1, 3], local[s, 2, 3]
        c_loc[c, 0] = a_loc[c, 1] * o2 - a_loc[c, 2] * o1
        c_loc[c, 1] = a_loc[c, 2] * o0 - a_loc[c, 0] * o2
        c_loc[c, 2] = a_loc[c, 0] * o1 - a_loc[c, 1] * o0
    return a_loc, c_loc


@jit
def _columns_batch(
    q, seg, local, offsets, joint_axis, joint_rot, anchor_of, step_axis, step_rot, columns, rows
):
    """:func:`evaluate` without perturbations or joint columns, by blocks of ``BLOCK`` poses
    in structure-of-arrays form (poses innermost: LLVM vectorises every loop over them, as in
    :func:`forward_batch`); the same formulas as :func:`_evaluate_poses`."""
    n, dof = q.shape
    m = columns.shape[0]
    T = np.empty((n, 4, 4))
    J = np.empty((n * rows, m))
    work = _block_work(q, local, step_axis, columns, rows)
    Jb = work[5]
    for start in range(0, n, BLOCK):
        b = _block_columns(
            seg, offsets, joint_axis, joint_rot, anchor_of, step_rot, columns, rows, start, T, work
        )
        for p in range(b):
            row = (start + p) * rows
            for r in range(rows):
                for c in range(m):
                    J[row + r, c] = Jb[c, r, p]
    return T, J, np.zeros((0, dof, 3))


@jit
def position_columns_transposed(
    q, seg, local, offsets, joint_axis, joint_rot, anchor_of, step_axis, step_rot, columns
):
    """Tool frames ``T (n, 4, 4)`` and the position rows' columns of the steps ``columns``
    as rows, ``Jt (len(columns), 3n)``: the transpose of :func:`evaluate`'s ``J`` (position
    rows, no perturbations), the same numbers, written column by column (contiguous) for
    the fits that form normal equations from the columns (no transpose of ``J`` later)."""
    n = q.shape[0]
    m = columns.shape[0]
    T = np.empty((n, 4, 4))
    Jt = np.empty((m, 3 * n))
    work = _block_work(q, local, step_axis, columns, 3)
    Jb = work[5]
    for start in range(0, n, BLOCK):
        b = _block_columns(
            seg, offsets, joint_axis, joint_rot, anchor_of, step_rot, columns, 3, start, T, work
        )
        for c in range(m):
            target = Jt[c]
            for p in range(b):
                i = 3 * (start + p)
                target[i] = Jb[c, 0, p]
                target[i + 1] = Jb[c, 1, p]
                target[i + 2] = Jb[c, 2, p]
    return T, Jt


@jit
def _block_work(q, local, step_axis, columns, rows):
    """The work arrays of :func:`_block_columns`: the joint values transposed ``(dof, n)``,
    the columns' constants (:func:`_column_constants`), a block's tool frames ``F (3, 4,
    w)``, anchors ``A (dof + 1, 3, 4, w)`` (the base, then after each joint), the tool
    point seen from each anchor in its axes ``D (dof + 1, 3, w)`` and the columns
    ``Jb (m, rows, w)``, ``w`` the block's width (at most ``BLOCK`` poses)."""
    n, dof = q.shape
    m = columns.shape[0]
    width = max(1, min(BLOCK, n))  # fewer poses than a block: arrays of their size (less memory to touch)
    a_loc, c_loc = _column_constants(local, step_axis, columns)
    F, A, D = np.empty((3, 4, width)), np.empty((dof + 1, 3, 4, width)), np.empty((dof + 1, 3, width))
    return np.ascontiguousarray(q.T), a_loc, c_loc, F, A, np.empty((m, rows, width)), D


@jit
def _block_columns(seg, offsets, joint_axis, joint_rot, anchor_of, step_rot, columns, rows, start, T, work):
    """Poses ``start ..`` (one block): their tool frames into ``T`` and their columns into
    ``work``'s ``Jb[c, r, p]``; returns the block's number of poses."""
    qt, a_loc, c_loc, F, A, Jb, D = work
    dof, n = qt.shape
    m = columns.shape[0]
    b = min(BLOCK, n - start)
    anchors_block(qt, seg, offsets, joint_axis, joint_rot, start, b, F, A, T, True)
    for a in range(dof + 1):
        for p in range(b):
            d0 = F[0, 3, p] - A[a, 0, 3, p]
            d1 = F[1, 3, p] - A[a, 1, 3, p]
            d2 = F[2, 3, p] - A[a, 2, 3, p]
            for r in range(3):
                D[a, r, p] = A[a, 0, r, p] * d0 + A[a, 1, r, p] * d1 + A[a, 2, r, p] * d2
    for c in range(m):
        s = columns[c]
        a = anchor_of[s]
        al0, al1, al2 = a_loc[c, 0], a_loc[c, 1], a_loc[c, 2]
        if step_rot[s]:
            cl0, cl1, cl2 = c_loc[c, 0], c_loc[c, 1], c_loc[c, 2]
            for p in range(b):
                v0 = al1 * D[a, 2, p] - al2 * D[a, 1, p] - cl0
                v1 = al2 * D[a, 0, p] - al0 * D[a, 2, p] - cl1
                v2 = al0 * D[a, 1, p] - al1 * D[a, 0, p] - cl2
                for r in range(3):
                    Jb[c, r, p] = A[a, r, 0, p] * v0 + A[a, r, 1, p] * v1 + A[a, r, 2, p] * v2
            if rows == 6:
                for r in range(3):
                    for p in range(b):
                        Jb[c, 3 + r, p] = A[a, r, 0, p] * al0 + A[a, r, 1, p] * al1 + A[a, r, 2, p] * al2
        else:
            for r in range(3):
                for p in range(b):
                    Jb[c, r, p] = A[a, r, 0, p] * al0 + A[a, r, 1, p] * al1 + A[a, r, 2, p] * al2
            if rows == 6:
                for r in range(3):
                    for p in range(b):
                        Jb[c, 3 + r, p] = 0.0
    return b


# split into calls, the hot loop would pass and allocate a pose's frames and columns per pose
# long: one compiled loop over the poses that keeps a pose's frames and columns in registers
@jit
def _evaluate_poses(
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
    """:func:`evaluate` pose by pose, the frames in registers (perturbations and joint columns)."""
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
    d_loc = np.empty((dof + 1, 3))
    F = np.empty((3, 4))
    for p in range(n):
        pose_forward(q, pert, p, has_pert, seg, offsets, joint_axis, joint_rot, anchors, F)
        for r in range(3):
            for c in range(4):
                T[p, r, c] = F[r, c]
        T[p, 3, 3] = 1.0
        row = p * rows
        # the tool point seen from each anchor, in the anchor's axes: d_l = Rᵀ (p − p_a); then a
        # rotation column is R (a_l × d_l − a_l × o_l) (a × (p − o) in the anchor's axes)
        for a in range(dof + 1):
            for r in range(3):
                d[r] = F[r, 3] - anchors[a, r, 3]
            for r in range(3):
                d_loc[a, r] = anchors[a, 0, r] * d[0] + anchors[a, 1, r] * d[1] + anchors[a, 2, r] * d[2]
        for c in range(m):
            s = columns[c]
            a = anchor_of[s]
            an = anchors[a]
            al0, al1, al2 = a_loc[c, 0], a_loc[c, 1], a_loc[c, 2]
            if step_rot[s]:
                v0 = al1 * d_loc[a, 2] - al2 * d_loc[a, 1] - c_loc[c, 0]
                v1 = al2 * d_loc[a, 0] - al0 * d_loc[a, 2] - c_loc[c, 1]
                v2 = al0 * d_loc[a, 1] - al1 * d_loc[a, 0] - c_loc[c, 2]
                for r in range(3):
                    J[row + r, c] = an[r, 0] * v0 + an[r, 1] * v1 + an[r, 2] * v2
                if rows == 6:
                    for r in range(3):
                        J[row + 3 + r, c] = an[r, 0] * al0 + an[r, 1] * al1 + an[r, 2] * al2
            else:
                for r in range(3):
                    J[row + r, c] = an[r, 0] * al0 + an[r, 1] * al1 + an[r, 2] * al2
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
