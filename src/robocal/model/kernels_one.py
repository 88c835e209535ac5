"""Compiled kernels of one configuration (numba): the tool frame and the geometric joint
Jacobian of a chain at ``q`` ``(dof,)``, called from Python once per configuration (the
interactive case, a robot controller's loop), with few arguments and no allocation.

Entry points: :func:`fk_one` (``Model.fk`` of one configuration), :func:`fk_jacobian_one`,
:func:`fk_into` / :func:`fk_jacobian_into` (the model and the outputs in one array, as
Pinocchio's model / data: :class:`robocal.model.chain_compiled.ChainData`) and
:func:`fk_jacobian_many`.  The numpy code of :class:`robocal.model.chain.Model` is the
reference (``tests/test_kernels.py``, to 1e-12) and Pinocchio an independent one
(``tests/test_pinocchio.py``).
"""

from __future__ import annotations

import math

import numba
import numpy as np

from robocal.model.kernels_math import sincos

__all__ = ["fk_into", "fk_jacobian_into", "fk_jacobian_many", "fk_jacobian_one", "fk_one", "pack_one"]

_jit = numba.njit(cache=True, nogil=True)
# the entry points of one configuration keep the GIL: releasing and taking it back costs
# about 0.05 µs a call, more than the threads it would let run could gain in 0.1 µs
_jit_gil = numba.njit(cache=True)

# One configuration (fk_one, fk_jacobian_one, fk_into, ...): the model packed in one array
# (numba's dispatch costs about 0.03 µs per argument), every joint turned into a z joint at
# packing time (the axis permutation folded into the neighbouring segments, so the tool
# frame is unchanged), and the frame kept in twelve scalars: in a (3, 4) array every store
# makes LLVM reload what it cannot prove unaliased, which doubled the time of a pose.
_HEAD = 2  # packed[0]: dof; packed[1]: offset of the outputs (fk_into / fk_jacobian_into)


@_jit
def _fk_scalar(q, packed, J, jo, jacobian, W, wo):
    """Tool frame rows ``(f00 .. f23)`` of ``q`` and, with ``jacobian``, the geometric Jacobian
    ``(6, dof)`` row-major into ``J[jo:]`` (a flat array: no views, whose reference counts cost
    as much as a joint); ``W[wo:wo + 2 dof]``: room for the joints' sines and cosines, all
    computed first (independent, so they overlap; in the chain's loop each sine's latency
    added to the chain's); the arguments are checked by the caller."""
    dof = np.int64(packed[0])
    o = _HEAD
    f00, f01, f02, f03 = packed[o], packed[o + 1], packed[o + 2], packed[o + 3]
    f10, f11, f12, f13 = packed[o + 4], packed[o + 5], packed[o + 6], packed[o + 7]
    f20, f21, f22, f23 = packed[o + 8], packed[o + 9], packed[o + 10], packed[o + 11]
    kinds = _HEAD + 12 * (dof + 1)
    for j in range(dof):
        W[wo + 2 * j], W[wo + 2 * j + 1] = sincos(q[j] + packed[kinds + j])
    for j in range(dof):
        revolute = packed[kinds + dof + j] != 0.0
        if jacobian:  # the joint's z axis and origin in the base frame, finished below
            w = jo + j
            J[w + 3 * dof], J[w + 4 * dof], J[w + 5 * dof] = (f02, f12, f22) if revolute else (0.0, 0.0, 0.0)
            J[w], J[w + dof], J[w + 2 * dof] = (f03, f13, f23) if revolute else (f02, f12, f22)
        o = _HEAD + 12 * (j + 1)  # the segment after the joint, rows 0 .. 2
        a0, a1, a2, a3 = packed[o], packed[o + 1], packed[o + 2], packed[o + 3]
        b0, b1, b2, b3 = packed[o + 4], packed[o + 5], packed[o + 6], packed[o + 7]
        c0, c1, c2, c3 = packed[o + 8], packed[o + 9], packed[o + 10], packed[o + 11]
        if revolute:  # Rz(theta) @ segment
            s, c = W[wo + 2 * j], W[wo + 2 * j + 1]
            a0, a1, a2, a3, b0, b1, b2, b3 = (
                c * a0 - s * b0, c * a1 - s * b1, c * a2 - s * b2, c * a3 - s * b3,
                s * a0 + c * b0, s * a1 + c * b1, s * a2 + c * b2, s * a3 + c * b3,
            )  # fmt: skip
        else:  # Tz(theta) @ segment
            c3 = c3 + q[j] + packed[kinds + j]
        f00, f01, f02, f03 = (
            f00 * a0 + f01 * b0 + f02 * c0, f00 * a1 + f01 * b1 + f02 * c1,
            f00 * a2 + f01 * b2 + f02 * c2, f00 * a3 + f01 * b3 + f02 * c3 + f03,
        )  # fmt: skip
        f10, f11, f12, f13 = (
            f10 * a0 + f11 * b0 + f12 * c0, f10 * a1 + f11 * b1 + f12 * c1,
            f10 * a2 + f11 * b2 + f12 * c2, f10 * a3 + f11 * b3 + f12 * c3 + f13,
        )  # fmt: skip
        f20, f21, f22, f23 = (
            f20 * a0 + f21 * b0 + f22 * c0, f20 * a1 + f21 * b1 + f22 * c1,
            f20 * a2 + f21 * b2 + f22 * c2, f20 * a3 + f21 * b3 + f22 * c3 + f23,
        )  # fmt: skip
    if jacobian:
        for j in range(dof):
            if packed[kinds + dof + j] != 0.0:  # v = z x (p_tool - o_joint)
                w = jo + j
                d0, d1, d2 = f03 - J[w], f13 - J[w + dof], f23 - J[w + 2 * dof]
                z0, z1, z2 = J[w + 3 * dof], J[w + 4 * dof], J[w + 5 * dof]
                J[w] = z1 * d2 - z2 * d1
                J[w + dof] = z2 * d0 - z0 * d2
                J[w + 2 * dof] = z0 * d1 - z1 * d0
    return f00, f01, f02, f03, f10, f11, f12, f13, f20, f21, f22, f23


@_jit
def _store(f, T):
    """The frame rows ``f`` (12 scalars) into ``T`` ``(4, 4)``, last row ``0 0 0 1``."""
    T[0, 0], T[0, 1], T[0, 2], T[0, 3] = f[0], f[1], f[2], f[3]
    T[1, 0], T[1, 1], T[1, 2], T[1, 3] = f[4], f[5], f[6], f[7]
    T[2, 0], T[2, 1], T[2, 2], T[2, 3] = f[8], f[9], f[10], f[11]
    T[3, 0], T[3, 1], T[3, 2], T[3, 3] = 0.0, 0.0, 0.0, 1.0


@_jit
def _fits(q, packed):
    """Whether ``q`` ``(dof,)`` is finite and of the model's ``dof``."""
    dof = np.int64(packed[0])
    if q.shape[0] != dof:
        return False
    for j in range(dof):  # noqa: SIM110 - a loop: numba compiles no generator here
        if not math.isfinite(q[j]):
            return False
    return True


@_jit_gil
def fk_one(q, packed, T):
    """Tool frame ``T_base_tool`` of one configuration ``q`` ``(dof,)`` (m, rad) written into
    ``T`` ``(4, 4)``; ``packed``: the model (:func:`pack_one`).

    Returns False, leaving ``T`` unset, when ``q`` does not fit the model or holds NaN/inf,
    or ``T`` is not 4 x 4 (the caller's general path then reports it).
    """
    if not _fits(q, packed) or T.shape[0] != 4 or T.shape[1] != 4:
        return False
    _store(_fk_scalar(q, packed, packed, 0, False, np.empty(2 * q.shape[0]), 0), T)
    return True


@_jit
def _copy_jacobian(flat, J):
    """``J`` ``(6, dof)`` from its row-major ``flat`` copy."""
    dof = J.shape[1]
    for r in range(6):
        for j in range(dof):
            J[r, j] = flat[r * dof + j]


@_jit_gil
def fk_jacobian_one(q, packed, T, J):
    """:func:`fk_one` plus the geometric Jacobian of the tool frame's origin into ``J``
    ``(6, dof)``: rows ``[v; ω]`` in the base frame per unit joint rate (as
    :meth:`~robocal.model.chain.Model.joint_jacobian`).  False, leaving both unset, when an
    argument does not fit (``J`` included)."""
    if not _fits(q, packed) or T.shape[0] != 4 or T.shape[1] != 4:
        return False
    if J.shape[0] != 6 or J.shape[1] != q.shape[0]:
        return False
    flat = np.empty(8 * q.shape[0])
    _store(_fk_scalar(q, packed, flat, 0, True, flat, 6 * q.shape[0]), T)
    _copy_jacobian(flat, J)
    return True


@_jit_gil
def fk_into(q, data):
    """:func:`fk_one` with the output in ``data`` (:func:`pack_one` with ``outputs``): two
    arguments, as Pinocchio's ``forwardKinematics(model, data, q)``; the frame is
    ``data[data[1]:][:16]``, a row-major 4 x 4 (:class:`robocal.model.chain_compiled.ChainData`
    keeps a view of it)."""
    out = np.int64(data[1])
    dof = np.int64(data[0])
    if not _fits(q, data) or data.shape[0] < out + 16 + 8 * dof:
        return False
    f = _fk_scalar(q, data, data, 0, False, data, out + 16 + 6 * dof)
    for i in range(12):
        data[out + i] = f[i]
    data[out + 12], data[out + 13], data[out + 14], data[out + 15] = 0.0, 0.0, 0.0, 1.0
    return True


@_jit_gil
def fk_jacobian_into(q, data):
    """:func:`fk_jacobian_one` with the outputs in ``data``: the frame as in :func:`fk_into`,
    then the Jacobian ``(6, dof)`` row-major."""
    dof = np.int64(data[0])
    out = np.int64(data[1])
    if not _fits(q, data) or data.shape[0] < out + 16 + 8 * dof:
        return False
    f = _fk_scalar(q, data, data, out + 16, True, data, out + 16 + 6 * dof)
    for i in range(12):
        data[out + i] = f[i]
    data[out + 12], data[out + 13], data[out + 14], data[out + 15] = 0.0, 0.0, 0.0, 1.0
    return True


@_jit
def fk_jacobian_many(Q, packed, T, J, jacobian):
    """:func:`fk_jacobian_one` of each row of ``Q`` ``(n, dof)`` into ``T`` ``(n, 4, 4)`` and,
    with ``jacobian``, ``J`` ``(n, 6, dof)``.  False, leaving the outputs unset, when the
    shapes do not fit or a joint value is NaN/inf."""
    n = Q.shape[0]
    dof = np.int64(packed[0])
    if Q.shape[1] != dof or T.shape[0] != n or T.shape[1] != 4 or T.shape[2] != 4:
        return False
    if jacobian and (J.shape[0] != n or J.shape[1] != 6 or J.shape[2] != dof):
        return False
    for p in range(n):
        if not _fits(Q[p], packed):
            return False
    flat = np.empty(8 * dof)
    for p in range(n):
        _store(_fk_scalar(Q[p], packed, flat, 0, jacobian, flat, 6 * dof), T[p])
        if jacobian:
            _copy_jacobian(flat, J[p])
    return True


def _z_permutation(axis: int) -> np.ndarray:
    """The rotation ``(4, 4)`` whose z column is ``axis`` (a cyclic permutation of the axes):
    a joint about or along ``axis`` is ``P @ joint_z @ P.T``."""
    P = np.zeros((4, 4))
    for col, row in enumerate(((axis + 1) % 3, (axis + 2) % 3, axis)):
        P[row, col] = 1.0
    P[3, 3] = 1.0
    return P


def pack_one(seg, offsets, joint_axis, joint_rot, outputs: bool = False):
    """The model of the one-configuration kernels in one array: dof, the offset of the
    outputs, the segments' first three rows with every joint turned into a z joint (the
    permutations folded in), the joint offsets and kinds (1 revolute, 0 prismatic); with
    ``outputs``, room for the frame (16), the Jacobian (6 x dof) and the joints' sines and
    cosines (2 x dof) after them."""
    dof = len(offsets)
    seg = np.array(seg, dtype=float)
    for j in range(dof):
        P = _z_permutation(int(joint_axis[j]))
        seg[j] = seg[j] @ P
        seg[j + 1] = P.T @ seg[j + 1]
    model = [seg[:, :3, :].ravel(), np.asarray(offsets, dtype=float), np.asarray(joint_rot, dtype=float)]
    size = _HEAD + sum(len(part) for part in model)
    room = np.full(16 + 8 * dof if outputs else 0, np.nan)
    return np.concatenate([[float(dof), float(size)], *model, room])
