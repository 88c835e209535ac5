"""Compiled start values of a calibration (numba): the alternating closed-form fits of the
device frame and the tool of :func:`robocal.identify.stages.initial_frames_and_tools`.

The fits work on a few hundred numbers (3x3 cross-covariances, one 3-vector per pose); in
numpy each of the ~20 calls of a round costs more than its arithmetic (200 µs for one
100-pose robot).  Here one call runs every round for every robot, pose by pose, with LAPACK's
SVD (numba's ``np.linalg.svd``) for the 3x3 matrices.  The numpy implementation is the
reference (``tests/test_start_kernels.py`` holds the kernel to it to 1e-12).

Compiled with ``cache=True`` (see :mod:`robocal.model.kernels`); this module imports numba,
so it is imported only on first use (the ``robocal`` command starts without it).

Units: m; frames ``(4, 4)`` homogeneous, device frame ``T_device_base`` maps base to device
coordinates, the tool maps tool to flange coordinates.
"""

from __future__ import annotations

import numba
import numpy as np

__all__ = ["COLLINEAR", "NON_FINITE_POINTS", "OK", "SVD_FAILED", "frames_and_tools"]

_jit = numba.njit(cache=True, nogil=True)

#: statuses of :func:`frames_and_tools`; ``COLLINEAR + k``: robot ``k``'s points are collinear
OK, NON_FINITE_POINTS, SVD_FAILED, COLLINEAR = 0, 1, 2, 3


@_jit
def _finite3(A):
    for i in range(3):
        for j in range(3):
            if not np.isfinite(A[i, j]):
                return False
    return True


@_jit
def _det3(A):
    return (
        A[0, 0] * (A[1, 1] * A[2, 2] - A[1, 2] * A[2, 1])
        - A[0, 1] * (A[1, 0] * A[2, 2] - A[1, 2] * A[2, 0])
        + A[0, 2] * (A[1, 0] * A[2, 1] - A[1, 1] * A[2, 0])
    )


@_jit
def _centred_cross_covariance(T_flange, y, t_tool, P, p0, q0):
    """The cross-covariance ``(3, 3)`` of the tool points ``P = R_f t_tool + p_f`` (written
    to ``P`` ``(n, 3)``) and ``y`` ``(n, 3)`` about their means (written to ``p0``, ``q0``)."""
    n = y.shape[0]
    p0[:] = 0.0
    q0[:] = 0.0
    for i in range(n):
        for r in range(3):
            v = T_flange[i, r, 3]
            for c in range(3):
                v += T_flange[i, r, c] * t_tool[c]
            P[i, r] = v
            p0[r] += v
            q0[r] += y[i, r]
    p0 /= n
    q0 /= n
    H = np.zeros((3, 3))
    for i in range(n):
        for r in range(3):
            a = P[i, r] - p0[r]
            for c in range(3):
                H[r, c] += a * (y[i, c] - q0[c])
    return H / n


@_jit
def _rigid_fit(T_flange, y, t_tool, P, T_out):
    """Kabsch/Horn: ``T_out`` <- the rigid transform mapping the tool points
    ``R_f t_tool + p_f`` onto ``y`` ``(n, 3)`` (least squares, unweighted; ``P`` ``(n, 3)``
    scratch).  Returns OK, SVD_FAILED (non-finite cross-covariance) or COLLINEAR."""
    p0 = np.empty(3)
    q0 = np.empty(3)
    H = _centred_cross_covariance(T_flange, y, t_tool, P, p0, q0)
    if not _finite3(H):
        return SVD_FAILED
    U, s, Vt = np.linalg.svd(H)
    if s[1] <= 1e-12 * max(s[0], 1e-300):
        return COLLINEAR
    d = np.sign(_det3(Vt) * _det3(U))  # det(V Uᵀ): V's last column flipped for a reflection
    R = np.empty((3, 3))
    for r in range(3):
        for c in range(3):
            R[r, c] = Vt[0, r] * U[c, 0] + Vt[1, r] * U[c, 1] + d * Vt[2, r] * U[c, 2]
    for r in range(3):
        t = q0[r]
        for c in range(3):
            T_out[r, c] = R[r, c]
            t -= R[r, c] * p0[c]
        T_out[r, 3] = t
        T_out[3, r] = 0.0
    T_out[3, 3] = 1.0
    return OK


@_jit
def _tool_point(T_flange, y, T_frame, T_tool):
    """``T_tool[:3, 3]`` <- the mean over the poses of ``R_fᵀ (R0ᵀ (y - t0) - p_f)``: the
    least-squares tool point of ``y = R0 (R_f t + p_f) + t0`` (device frame ``R0, t0``)."""
    n = y.shape[0]
    t = np.zeros(3)
    b = np.zeros(3)
    for i in range(n):
        for c in range(3):
            v = 0.0
            for r in range(3):
                v += (y[i, r] - T_frame[r, 3]) * T_frame[r, c]
            b[c] = v - T_flange[i, c, 3]
        for c in range(3):
            t[c] += T_flange[i, 0, c] * b[0] + T_flange[i, 1, c] * b[1] + T_flange[i, 2, c] * b[2]
    for c in range(3):
        T_tool[c, 3] = t[c] / n


@_jit
def _tool_rotation(T_flange, orientation, T_frame, T_tool):
    """``T_tool[:3, :3]`` <- the nearest rotation to ``Σ (R0 R_f)ᵀ R_measured``.
    Returns OK or SVD_FAILED (non-finite sum)."""
    n = orientation.shape[0]
    M = np.zeros((3, 3))
    R = np.zeros((3, 3))
    for i in range(n):
        for r in range(3):  # R = R0 R_f
            for c in range(3):
                R[r, c] = (
                    T_frame[r, 0] * T_flange[i, 0, c]
                    + T_frame[r, 1] * T_flange[i, 1, c]
                    + T_frame[r, 2] * T_flange[i, 2, c]
                )
        for r in range(3):
            for c in range(3):
                M[r, c] += (
                    R[0, r] * orientation[i, 0, c]
                    + R[1, r] * orientation[i, 1, c]
                    + R[2, r] * orientation[i, 2, c]
                )
    if not _finite3(M):
        return SVD_FAILED
    U, _, Vt = np.linalg.svd(M)
    d = -1.0 if _det3(U) * _det3(Vt) < 0 else 1.0  # det(U Vᵀ) < 0: U's last column flipped
    for r in range(3):
        for c in range(3):
            T_tool[r, c] = U[r, 0] * Vt[0, c] + U[r, 1] * Vt[1, c] + d * U[r, 2] * Vt[2, c]
    return OK


@_jit
def frames_and_tools(
    T_flange, position, orientation, has_orientation, T_frame, T_tool, fit_frame, fit_tool, rounds
):
    """The alternating fits of ``K`` robots, in place: ``T_frame`` and ``T_tool``
    ``(K, 4, 4)`` hold the starts (or the known frame or tool) and receive the fits.

    ``T_flange`` ``(K, n, 4, 4)``, ``position`` ``(K, n, 3)`` (m), ``orientation``
    ``(K, n, 3, 3)`` when ``has_orientation``.  Each round fits every robot's frame (when
    ``fit_frame``), then every robot's tool (when ``fit_tool``); ``rounds`` rounds when both
    are fitted, else one.  Returns a status: OK, NON_FINITE_POINTS (``position`` has NaN or
    inf and the frame is fitted), SVD_FAILED or ``COLLINEAR + k`` (the first robot ``k`` of
    the first round whose points are (nearly) collinear); the fits are then incomplete.
    """
    if fit_frame and not _all_finite(position):
        return NON_FINITE_POINTS
    P = np.empty((position.shape[1], 3))
    for _ in range(rounds if (fit_frame and fit_tool) else 1):
        if fit_frame:
            status = _fit_frames(T_flange, position, T_tool, P, T_frame)
            if status != OK:
                return status
        if fit_tool:
            for k in range(position.shape[0]):
                _tool_point(T_flange[k], position[k], T_frame[k], T_tool[k])
                if has_orientation:
                    status = _tool_rotation(T_flange[k], orientation[k], T_frame[k], T_tool[k])
                    if status != OK:
                        return status
    return OK


@_jit
def _all_finite(x):
    return np.isfinite(x).all()


@_jit
def _fit_frames(T_flange, position, T_tool, P, T_frame):
    """Every robot's device frame (:func:`_rigid_fit`); a failed SVD is reported before a
    collinear robot, the first collinear one as ``COLLINEAR + k`` (as numpy's batch did)."""
    failed, collinear = False, -1
    for k in range(position.shape[0]):
        status = _rigid_fit(T_flange[k], position[k], T_tool[k, :3, 3], P, T_frame[k])
        failed |= status == SVD_FAILED
        if status == COLLINEAR and collinear < 0:
            collinear = k
    if failed:
        return SVD_FAILED
    if collinear >= 0:
        return COLLINEAR + collinear
    return OK
