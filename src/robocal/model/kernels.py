"""Compiled kernels of the chain (numba): forward kinematics, joint frames and joint loads,
one pose at a time in registers (the fused tool-frame + identification-Jacobian pass is in
:mod:`robocal.model.kernels_evaluate`).

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

from robocal.model.kernels_math import sincos

__all__ = [
    "fk_into",
    "fk_jacobian_into",
    "fk_jacobian_many",
    "fk_jacobian_one",
    "fk_one",
    "forward",
    "forward_batch",
    "leading_frame",
    "pack_one",
    "segment_data",
    "static_wrenches",
]

jit = numba.njit(cache=True, nogil=True)


# _sincos: fdlibm's sin and cos, vectorisable over the poses (robocal.model.kernels_math)


@jit
def _rotate(F, axis, c, s):
    """``F[:, :3] <- F[:, :3] @ rot(axis, angle)`` for a ``(3, 4)`` frame (as chain._rotate_rows)."""
    i = (axis + 1) % 3
    j = (axis + 2) % 3
    for r in range(3):
        fi = F[r, i]
        fj = F[r, j]
        F[r, i] = fi * c + fj * s
        F[r, j] = fj * c - fi * s


@jit
def _times_segment(F, S):
    """``F <- F @ S`` in place for a ``(3, 4)`` frame and a ``(4, 4)`` rigid transform."""
    for r in range(3):
        f0, f1, f2 = F[r, 0], F[r, 1], F[r, 2]
        F[r, 0] = f0 * S[0, 0] + f1 * S[1, 0] + f2 * S[2, 0]
        F[r, 1] = f0 * S[0, 1] + f1 * S[1, 1] + f2 * S[2, 1]
        F[r, 2] = f0 * S[0, 2] + f1 * S[1, 2] + f2 * S[2, 2]
        F[r, 3] = f0 * S[0, 3] + f1 * S[1, 3] + f2 * S[2, 3] + F[r, 3]


@jit
def segment_data(values, step_axis, step_rot, step_joint, dof):
    """Constant segment transforms ``(dof + 1, 4, 4)`` and each step's local frame
    ``(P, 4, 4)`` (as :func:`robocal.model.chain_plan.segment_data`)."""
    P = values.shape[0]
    seg = np.zeros((dof + 1, 4, 4))
    local = np.zeros((P, 4, 4))
    cur = np.eye(4)
    a = 0
    for i in range(P):
        _copy44(cur, local[i])
        if step_joint[i]:
            _copy44(cur, seg[a])
            a += 1
            cur = np.eye(4)
        else:
            _times_step(cur, step_axis[i], step_rot[i], values[i])
    _copy44(cur, seg[a])
    return seg, local


@jit
def _times_step(F, axis, rotation, value):
    """``F <- F @ step`` in place for a constant step (a rotation about or a translation
    along local ``axis`` by ``value``)."""
    if rotation:
        _rotate(F, axis, math.cos(value), math.sin(value))
    else:
        for r in range(3):
            F[r, 3] += F[r, axis] * value


@jit
def leading_frame(values, step_axis, step_rot, n):
    """The product ``(4, 4)`` of the first ``n`` steps' transforms at ``values``, none of them
    a joint (as :func:`robocal.spatial.chain_product`: a calibration's device frame)."""
    cur = np.eye(4)
    for i in range(n):
        _times_step(cur, step_axis[i], step_rot[i], values[i])
    return cur


@jit
def _copy44(src, dst):
    """``dst[...] = src`` for 4 x 4 frames (a loop: numba's slice assignment compiles its
    shape checks and error messages, a third of a second)."""
    for r in range(4):
        for c in range(4):
            dst[r, c] = src[r, c]


@jit
def pose_forward(q, pert, p, has_pert, seg, offsets, joint_axis, joint_rot, anchors, F, store=True):
    """Frames of pose ``p``: the anchors into ``anchors`` ``(dof + 1, 3, 4)`` (0: the base,
    j + 1: after joint j; only with ``store``) and the tool frame into ``F`` ``(3, 4)``."""
    dof = q.shape[1]
    for r in range(3):
        for c in range(4):
            F[r, c] = seg[0, r, c]
            if store:
                anchors[0, r, c] = 1.0 if r == c else 0.0
    for j in range(dof):
        k = joint_axis[j]
        theta = q[p, j] + offsets[j]
        if has_pert:
            theta = theta + pert[p, j, 2]
        if joint_rot[j]:
            sin, cos = sincos(theta)
            _rotate(F, k, cos, sin)
        else:
            for r in range(3):
                F[r, 3] += F[r, k] * theta
        if has_pert:
            sin, cos = sincos(pert[p, j, 0])
            _rotate(F, (k + 1) % 3, cos, sin)
            sin, cos = sincos(pert[p, j, 1])
            _rotate(F, (k + 2) % 3, cos, sin)
        if store:
            for r in range(3):
                for c in range(4):
                    anchors[j + 1, r, c] = F[r, c]
        _times_segment(F, seg[j + 1])


@jit
def forward(q, pert, has_pert, seg, offsets, joint_axis, joint_rot, keep_anchors):
    """Tool frames ``(n, 4, 4)`` and, when asked, the frames after each joint
    ``(n, dof, 4, 4)`` (else an empty array)."""
    n, dof = q.shape
    T = np.zeros((n, 4, 4))
    frames = np.zeros((n if keep_anchors else 0, dof, 4, 4))
    anchors = np.empty((dof + 1, 3, 4))
    F = np.empty((3, 4))
    for p in range(n):
        pose_forward(q, pert, p, has_pert, seg, offsets, joint_axis, joint_rot, anchors, F, keep_anchors)
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


BLOCK = 256  # poses per block of forward_batch: its frames (3 x 4 x 256 doubles, 24 KB) stay in L1


@jit
def forward_batch(qt, seg, offsets, joint_axis, joint_rot):
    """Tool frames ``(n, 4, 4)`` of many configurations, ``qt`` ``(dof, n)`` (q transposed).

    Structure of arrays over a block of poses: the frames' rows are ``(3, 4, block)`` with the
    poses innermost, each joint and segment one loop over the block that LLVM vectorises (as
    numpy's batched code, without its temporaries and passes over memory); a block small
    enough for the L1 cache keeps the time per pose flat in n and under other processes'
    cache traffic."""
    n = qt.shape[1]
    T = np.empty((n, 4, 4))
    F = np.empty((3, 4, BLOCK))
    A = np.empty((1, 3, 4, BLOCK))
    for start in range(0, n, BLOCK):
        anchors_block(qt, seg, offsets, joint_axis, joint_rot, start, min(BLOCK, n - start), F, A, T, False)
    return T


@jit
def anchors_block(qt, seg, offsets, joint_axis, joint_rot, start, b, F, A, T, keep):
    """Poses ``start .. start + b``: the tool frames into ``F`` ``(3, 4, block)`` and ``T``; with
    ``keep`` the anchors (the base, then the frame after each joint) into ``A``
    ``(dof + 1, 3, 4, block)``."""
    dof = qt.shape[0]
    for r in range(3):
        for c in range(4):
            v = seg[0, r, c]
            e = 1.0 if r == c else 0.0
            for p in range(b):
                F[r, c, p] = v
            if keep:
                for p in range(b):
                    A[0, r, c, p] = e
    for j in range(dof):
        k = joint_axis[j]
        i1 = (k + 1) % 3
        i2 = (k + 2) % 3
        off = offsets[j]
        if joint_rot[j]:
            for p in range(b):
                s, c = sincos(qt[j, start + p] + off)
                for r in range(3):
                    fi = F[r, i1, p]
                    fj = F[r, i2, p]
                    F[r, i1, p] = fi * c + fj * s
                    F[r, i2, p] = fj * c - fi * s
        else:
            for p in range(b):
                t = qt[j, start + p] + off
                for r in range(3):
                    F[r, 3, p] += F[r, k, p] * t
        if keep:
            for r in range(3):
                for c in range(4):
                    for p in range(b):
                        A[j + 1, r, c, p] = F[r, c, p]
        S = seg[j + 1]
        for r in range(3):
            for p in range(b):
                f0, f1, f2, f3 = F[r, 0, p], F[r, 1, p], F[r, 2, p], F[r, 3, p]
                F[r, 0, p] = f0 * S[0, 0] + f1 * S[1, 0] + f2 * S[2, 0]
                F[r, 1, p] = f0 * S[0, 1] + f1 * S[1, 1] + f2 * S[2, 1]
                F[r, 2, p] = f0 * S[0, 2] + f1 * S[1, 2] + f2 * S[2, 2]
                F[r, 3, p] = f0 * S[0, 3] + f1 * S[1, 3] + f2 * S[2, 3] + f3
    for p in range(b):
        for r in range(3):
            for c in range(4):
                T[start + p, r, c] = F[r, c, p]
        T[start + p, 3, 0] = 0.0
        T[start + p, 3, 1] = 0.0
        T[start + p, 3, 2] = 0.0
        T[start + p, 3, 3] = 1.0


@jit
def static_wrenches(q, seg, offsets, joint_axis, joint_rot, joints, masses, centres, g):
    """Support wrenches at rest ``(n, dof, 6)`` (as
    :func:`robocal.model.dynamics._static_wrenches`, its formulas): for each pose the joint
    frames, then the masses' sums from the tool back, each rotated into its joint frame."""
    n, dof = q.shape
    out = np.empty((n, dof, 6))
    anchors = np.empty((dof + 1, 3, 4))
    F = np.empty((3, 4))
    pert = np.zeros((1, dof, 3))
    b = joints.shape[0]
    for p in range(n):
        pose_forward(q, pert, p, False, seg, offsets, joint_axis, joint_rot, anchors, F)
        M = 0.0
        S0 = S1 = S2 = 0.0
        k = b - 1  # the masses are sorted by joint
        for j in range(dof - 1, -1, -1):
            A = anchors[j + 1]
            while k >= 0 and joints[k] == j:
                m = masses[k]
                c0, c1, c2 = centres[k, 0], centres[k, 1], centres[k, 2]
                S0 += m * (A[0, 0] * c0 + A[0, 1] * c1 + A[0, 2] * c2 + A[0, 3])
                S1 += m * (A[1, 0] * c0 + A[1, 1] * c1 + A[1, 2] * c2 + A[1, 3])
                S2 += m * (A[2, 0] * c0 + A[2, 1] * c1 + A[2, 2] * c2 + A[2, 3])
                M += m
                k -= 1
            l0, l1, l2 = S0 - M * A[0, 3], S1 - M * A[1, 3], S2 - M * A[2, 3]  # Σ m (c − o_j)
            f0, f1, f2 = -M * g[0], -M * g[1], -M * g[2]
            n0 = l2 * g[1] - l1 * g[2]  # lever × (−g)
            n1 = l0 * g[2] - l2 * g[0]
            n2 = l1 * g[0] - l0 * g[1]
            for c in range(3):  # Rᵀ v: column c of R dotted with v
                out[p, j, c] = A[0, c] * f0 + A[1, c] * f1 + A[2, c] * f2
                out[p, j, 3 + c] = A[0, c] * n0 + A[1, c] * n1 + A[2, c] * n2
    return out


# the one-configuration kernels (their own module for its size)
from robocal.model.kernels_one import (  # noqa: E402
    fk_into,
    fk_jacobian_into,
    fk_jacobian_many,
    fk_jacobian_one,
    fk_one,
    pack_one,
)
