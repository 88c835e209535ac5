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

__all__ = ["fk_one", "forward", "forward_batch", "leading_frame", "segment_data", "static_wrenches"]

_jit = numba.njit(cache=True, nogil=True)


# sin and cos on |r| <= π/4 after a two-part Cody-Waite reduction by π/2: fdlibm's minimax
# coefficients (k_sin.c, k_cos.c, e_rem_pio2.c; Sun Microsystems, freely distributable).
# libm's scalar sin and cos cost 25-30 ns a pair here; this branch-free form is vectorised
# over the poses by LLVM (AVX2/AVX-512) and agrees with numpy to a few 1e-16 for the joint
# angles of a robot (|x| < 1e5 rad).
_S = (
    -1.66666666666666324348e-01,
    8.33333333332248946124e-03,
    -1.98412698298579493134e-04,
    2.75573137070700676789e-06,
    -2.50507602534068634195e-08,
    1.58969099521155010221e-10,
)
_C = (
    4.16666666666666019037e-02,
    -1.38888888887411972484e-03,
    2.48015872894767294178e-05,
    -2.75573143513906633035e-07,
    2.08757232129817482790e-09,
    -1.13596475577881948265e-11,
)
_PIO2_1, _PIO2_1T, _INVPIO2 = (
    1.57079632673412561417e00,
    6.07710050650619224932e-11,
    6.36619772367581382433e-01,
)


@_jit
def _sincos(x):
    n = math.floor(x * _INVPIO2 + 0.5)
    r = (x - n * _PIO2_1) - n * _PIO2_1T
    z = r * r
    s = r + r * z * (_S[0] + z * (_S[1] + z * (_S[2] + z * (_S[3] + z * (_S[4] + z * _S[5])))))
    c = 1.0 - 0.5 * z + z * z * (_C[0] + z * (_C[1] + z * (_C[2] + z * (_C[3] + z * (_C[4] + z * _C[5])))))
    k = np.int64(n) & 3
    swap = (k & 1) == 1
    sin = c if swap else s
    cos = s if swap else c
    sign_sin = 1.0 - (k & 2)
    sign_cos = 1.0 - ((k + 1) & 2)
    return sin * sign_sin, cos * sign_cos


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
        _copy44(cur, local[i])
        if step_joint[i]:
            _copy44(cur, seg[a])
            a += 1
            cur = np.eye(4)
        else:
            _times_step(cur, step_axis[i], step_rot[i], values[i])
    _copy44(cur, seg[a])
    return seg, local


@_jit
def _times_step(F, axis, rotation, value):
    """``F <- F @ step`` in place for a constant step (a rotation about or a translation
    along local ``axis`` by ``value``)."""
    if rotation:
        _rotate(F, axis, math.cos(value), math.sin(value))
    else:
        for r in range(3):
            F[r, 3] += F[r, axis] * value


@_jit
def leading_frame(values, step_axis, step_rot, n):
    """The product ``(4, 4)`` of the first ``n`` steps' transforms at ``values``, none of them
    a joint (as :func:`robocal.spatial.chain_product`: a calibration's device frame)."""
    cur = np.eye(4)
    for i in range(n):
        _times_step(cur, step_axis[i], step_rot[i], values[i])
    return cur


@_jit
def _copy44(src, dst):
    """``dst[...] = src`` for 4 x 4 frames (a loop: numba's slice assignment compiles its
    shape checks and error messages, a third of a second)."""
    for r in range(4):
        for c in range(4):
            dst[r, c] = src[r, c]


@_jit
def _pose_forward(q, pert, p, has_pert, seg, offsets, joint_axis, joint_rot, anchors, F, store=True):
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
            sin, cos = _sincos(theta)
            _rotate(F, k, cos, sin)
        else:
            for r in range(3):
                F[r, 3] += F[r, k] * theta
        if has_pert:
            sin, cos = _sincos(pert[p, j, 0])
            _rotate(F, (k + 1) % 3, cos, sin)
            sin, cos = _sincos(pert[p, j, 1])
            _rotate(F, (k + 2) % 3, cos, sin)
        if store:
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
        _pose_forward(q, pert, p, has_pert, seg, offsets, joint_axis, joint_rot, anchors, F, keep_anchors)
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


_BLOCK = 256  # poses per block of forward_batch: its frames (3 x 4 x 256 doubles, 24 KB) stay in L1


@_jit
def forward_batch(qt, seg, offsets, joint_axis, joint_rot):
    """Tool frames ``(n, 4, 4)`` of many configurations, ``qt`` ``(dof, n)`` (q transposed).

    Structure of arrays over a block of poses: the frames' rows are ``(3, 4, block)`` with the
    poses innermost, each joint and segment one loop over the block that LLVM vectorises (as
    numpy's batched code, without its temporaries and passes over memory); a block small
    enough for the L1 cache keeps the time per pose flat in n and under other processes'
    cache traffic."""
    n = qt.shape[1]
    T = np.empty((n, 4, 4))
    F = np.empty((3, 4, _BLOCK))
    A = np.empty((1, 3, 4, _BLOCK))
    for start in range(0, n, _BLOCK):
        _anchors_block(qt, seg, offsets, joint_axis, joint_rot, start, min(_BLOCK, n - start), F, A, T, False)
    return T


@_jit
def fk_one(q, packed, T):
    """One configuration ``q`` ``(dof,)`` into ``T`` ``(4, 4)``.

    ``packed`` holds the model (:func:`pack_one`, few arguments: numba's dispatch costs about
    0.2 µs per argument).  Returns False, leaving ``T`` unset, when ``q`` does not fit the
    model or holds NaN/inf (the caller's general path then reports it).
    """
    dof = np.int64(packed[0])
    if q.shape[0] != dof:
        return False
    for j in range(dof):
        if not math.isfinite(q[j]):
            return False
    seg = packed[1 : 1 + 16 * (dof + 1)].reshape((dof + 1, 4, 4))
    base = 1 + 16 * (dof + 1)
    F = np.empty((3, 4))
    for r in range(3):
        for c in range(4):
            F[r, c] = seg[0, r, c]
    for j in range(dof):
        k = np.int64(packed[base + dof + j])
        theta = q[j] + packed[base + j]
        if packed[base + 2 * dof + j] != 0.0:
            sin, cos = _sincos(theta)
            _rotate(F, k, cos, sin)
        else:
            for r in range(3):
                F[r, 3] += F[r, k] * theta
        _times_segment(F, seg[j + 1])
    for r in range(3):
        for c in range(4):
            T[r, c] = F[r, c]
        T[3, r] = 0.0
    T[3, 3] = 1.0
    return True


def pack_one(seg, offsets, joint_axis, joint_rot):
    """The model data of :func:`fk_one` in one array: dof, the segments, offsets, axes, kinds."""
    dof = len(offsets)
    return np.concatenate(
        [[float(dof)], seg.ravel(), offsets, joint_axis.astype(float), joint_rot.astype(float)]
    )


@_jit
def _anchors_block(qt, seg, offsets, joint_axis, joint_rot, start, b, F, A, T, keep):
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
                s, c = _sincos(qt[j, start + p] + off)
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


@_jit
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
        _pose_forward(q, pert, p, False, seg, offsets, joint_axis, joint_rot, anchors, F)
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
