"""Compiled start values of a calibration (numba): the alternating closed-form fits of the
device frame and the tool of :func:`robocal.identify.stages.initial_frames_and_tools`.

The fits work on a few hundred numbers (3x3 cross-covariances, one 3-vector per pose); in
numpy each of the ~20 calls of a round costs more than its arithmetic (200 µs for one
100-pose robot).  Here one call runs every round for every robot.  The sums over the poses
that the fits need are linear in the unknowns of the other fit, so they are taken once
(:func:`_moments`) and each round works on 3x3x3 moments, independent of the pose count;
its 3x3 SVDs are one-sided Jacobi (:func:`_nearest_rotation`).  The numpy implementation is the
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


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _divide(a, n):
    """``a /= n`` in place, for a 1-D view (loops: numba's in-place array operators compile
    their shape checks and error messages); NaN for ``n = 0``, as numpy's."""
    for i in range(len(a)):
        a[i] /= n


@_jit
def _all_finite(a):
    for x in a.ravel():  # noqa: SIM110 - a loop compiles; all() of a generator does not
        if not np.isfinite(x):
            return False
    return True


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


# The 3x3 SVDs by hand: numba's np.linalg.svd (LAPACK gesdd) costs ~3 µs a call here (layout
# copies, a workspace query, allocations), two thirds of the start values; one-sided Jacobi
# (Hestenes 1958; Demmel & Veselić 1992 for its accuracy) on 3 columns takes ~0.3 µs and agrees
# with LAPACK's polar factor to ~1e-14.  LAPACK still decides the rank-deficient cases.
_EPS = 2.220446049250313e-16


@_jit
def _jacobi_columns(G, V):
    """One-sided Jacobi in place: rotate pairs of columns of ``G`` ``(3, 3)`` (and of ``V``,
    accumulating the rotations) until they are orthogonal to round-off, so that the input is
    ``G Vᵀ`` with ``G = U diag(s)``: ``s`` the column norms of ``G`` (at most 30 sweeps;
    3x3 matrices take 3-6)."""
    for _ in range(30):
        rotated = False
        for p in range(2):
            for q in range(p + 1, 3):
                a = G[0, p] * G[0, p] + G[1, p] * G[1, p] + G[2, p] * G[2, p]
                b = G[0, q] * G[0, q] + G[1, q] * G[1, q] + G[2, q] * G[2, q]
                g = G[0, p] * G[0, q] + G[1, p] * G[1, q] + G[2, p] * G[2, q]
                if abs(g) <= _EPS * np.sqrt(a * b):
                    continue
                rotated = True
                zeta = (b - a) / (2.0 * g)
                t = np.copysign(1.0, zeta) / (abs(zeta) + np.sqrt(1.0 + zeta * zeta))
                c = 1.0 / np.sqrt(1.0 + t * t)
                sn = c * t
                for r in range(3):
                    x, y = G[r, p], G[r, q]
                    G[r, p], G[r, q] = c * x - sn * y, sn * x + c * y
                    x, y = V[r, p], V[r, q]
                    V[r, p], V[r, q] = c * x - sn * y, sn * x + c * y
        if not rotated:
            return


@_jit
def _nearest_rotation(A, R):
    """``R`` <- the rotation nearest to ``A`` ``(3, 3)`` (Frobenius norm), ``U diag(1, 1,
    det(U Vᵀ)) Vᵀ`` for ``A = U diag(s) Vᵀ``, written as ``u0 v0ᵀ + u1 v1ᵀ + (u0 × u1)(v0 ×
    v1)ᵀ`` from the two largest singular triplets (the third and its sign are not needed).
    Returns the two largest singular values ``s0 >= s1``; ``R`` is not written when
    ``s1 <= 1e-12 s0`` (rank below 2: the nearest rotation is not determined)."""
    scale = 0.0
    for r in range(3):
        for c in range(3):
            scale = max(scale, abs(A[r, c]))
    if scale == 0.0:
        return 0.0, 0.0
    G = A / scale
    V = np.eye(3)
    _jacobi_columns(G, V)
    s = np.sqrt(G[0] * G[0] + G[1] * G[1] + G[2] * G[2])
    i0 = 0 if s[0] >= s[1] and s[0] >= s[2] else (1 if s[1] >= s[2] else 2)
    i1 = (i0 + 1) % 3 if s[(i0 + 1) % 3] >= s[(i0 + 2) % 3] else (i0 + 2) % 3
    if s[i1] <= 1e-12 * s[i0]:
        return s[i0] * scale, s[i1] * scale
    u = np.empty((3, 3))
    v = np.empty((3, 3))
    for r in range(3):
        u[r, 0], u[r, 1] = G[r, i0] / s[i0], G[r, i1] / s[i1]
        v[r, 0], v[r, 1] = V[r, i0], V[r, i1]
    for a, b, c in ((0, 1, 2), (1, 2, 0), (2, 0, 1)):
        u[a, 2] = u[b, 0] * u[c, 1] - u[c, 0] * u[b, 1]
        v[a, 2] = v[b, 0] * v[c, 1] - v[c, 0] * v[b, 1]
    for r in range(3):
        for c in range(3):
            R[r, c] = u[r, 0] * v[c, 0] + u[r, 1] * v[c, 1] + u[r, 2] * v[c, 2]
    return s[i0] * scale, s[i1] * scale


@_jit
def _moments(T_flange, y, orientation, has_orientation, m3, m33, m333, m3333):
    """The pose sums of one robot the fits need, with the flange rotations ``R_i``, positions
    ``p_i`` (``T_flange`` ``(n, 4, 4)``) and the measured points ``y`` ``(n, 3)`` about their
    mean ``q0`` (``d_i = y_i - q0``), all divided by ``n`` but the last:

    * ``m3`` ``(3, 3)``: ``q0``, ``p̄ = mean p_i`` and ``S = mean R_iᵀ p_i``;
    * ``m33`` ``(2, 3, 3)``: ``R̄ = mean R_i`` and ``B = mean p_i d_iᵀ``;
    * ``m333`` ``(3, 3, 3)``: ``A[c] = mean R_i[:, c] d_iᵀ``;
    * ``m3333`` ``(3, 3, 3, 3)`` (pose data): ``D[r, j, k, c] = Σ R_i[j, r] O_i[k, c]`` with
      the measured rotations ``O_i`` ``(n, 3, 3)`` (a sum: none for no poses, as numpy's).
    """
    n = y.shape[0]
    for i in range(n):
        for k in range(3):
            m3[0, k] += y[i, k]
    _divide(m3[0].ravel(), n)
    d = np.empty(3)
    for i in range(n):
        for k in range(3):
            d[k] = y[i, k] - m3[0, k]
        for r in range(3):
            p = T_flange[i, r, 3]
            m3[1, r] += p
            for c in range(3):
                R = T_flange[i, r, c]
                m33[0, r, c] += R
                m3[2, c] += R * p
                for k in range(3):
                    m333[c, r, k] += R * d[k]
            for k in range(3):
                m33[1, r, k] += p * d[k]
        if has_orientation:
            for r in range(3):
                for j in range(3):
                    R = T_flange[i, j, r]
                    for k in range(3):
                        for c in range(3):
                            m3333[r, j, k, c] += R * orientation[i, k, c]
    _divide(m3[1:].ravel(), n)
    _divide(m33.ravel(), n)
    _divide(m333.ravel(), n)


@_jit
def _rigid_fit(m3, m33, m333, t_tool, T_out):
    """Kabsch/Horn: ``T_out`` <- the rigid transform mapping the tool points
    ``P_i = R_i t_tool + p_i`` onto the measured ``y_i`` (least squares, unweighted).
    Their cross-covariance ``mean (P_i - p0)(y_i - q0)ᵀ`` is ``Σ_c t_c A[c] + B`` and
    ``p0 = R̄ t + p̄`` (:func:`_moments`).
    Returns OK, SVD_FAILED (non-finite cross-covariance) or COLLINEAR."""
    H = m33[1].copy()
    p0 = m3[1].copy()
    for c in range(3):
        H += t_tool[c] * m333[c]
        for r in range(3):
            p0[r] += m33[0, r, c] * t_tool[c]
    if not _finite3(H):
        return SVD_FAILED
    Rt = np.empty((3, 3))  # Kabsch: R = V diag(1, 1, det(V Uᵀ)) Uᵀ for H = U S Vᵀ, i.e. Rtᵀ
    s0, s1 = _nearest_rotation(H, Rt)
    if s1 <= 1e-12 * max(s0, 1e-300):
        return COLLINEAR
    for r in range(3):
        t = m3[0, r]
        for c in range(3):
            T_out[r, c] = Rt[c, r]
            t -= Rt[c, r] * p0[c]
        T_out[r, 3] = t
        T_out[3, r] = 0.0
    T_out[3, 3] = 1.0
    return OK


@_jit
def _tool_point(m3, m33, m333, T_frame, T_tool):
    """``T_tool[:3, 3]`` <- the least-squares tool point of ``y_i = R0 (R_i t + p_i) + t0``
    (device frame ``R0, t0``): ``mean R_iᵀ (R0ᵀ (y_i - t0) - p_i)``, which is
    ``Σ_jk R0[k, j] A[c, j, k] + R̄ᵀ R0ᵀ (q0 - t0) - S`` (:func:`_moments`)."""
    e = np.zeros(3)  # R0ᵀ (q0 - t0)
    for j in range(3):
        for k in range(3):
            e[j] += T_frame[k, j] * (m3[0, k] - T_frame[k, 3])
    for c in range(3):
        t = -m3[2, c]
        for j in range(3):
            t += m33[0, j, c] * e[j]
            for k in range(3):
                t += T_frame[k, j] * m333[c, j, k]
        T_tool[c, 3] = t


@_jit
def _tool_rotation(m3333, T_frame, T_tool):
    """``T_tool[:3, :3]`` <- the nearest rotation to ``M = Σ (R0 R_i)ᵀ O_i``, which is
    ``M[r, c] = Σ_jk R0[k, j] D[r, j, k, c]`` (:func:`_moments`).
    Returns OK or SVD_FAILED (non-finite sum)."""
    M = np.zeros((3, 3))
    for r in range(3):
        for j in range(3):
            for k in range(3):
                R0 = T_frame[k, j]
                for c in range(3):
                    M[r, c] += R0 * m3333[r, j, k, c]
    if not _finite3(M):
        return SVD_FAILED
    R = np.empty((3, 3))
    s0, s1 = _nearest_rotation(M, R)
    if s1 <= 1e-12 * max(s0, 1e-300):  # rank below 2: as LAPACK's SVD resolves it
        U, _, Vt = np.linalg.svd(M)
        d = -1.0 if _det3(U) * _det3(Vt) < 0 else 1.0  # det(U Vᵀ) < 0: U's last column flipped
        for r in range(3):
            for c in range(3):
                R[r, c] = U[r, 0] * Vt[0, c] + U[r, 1] * Vt[1, c] + d * U[r, 2] * Vt[2, c]
    for r in range(3):  # loops: numba's slice assignment compiles its shape checks
        for c in range(3):
            T_tool[r, c] = R[r, c]
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
    K = position.shape[0]
    d = 3 if has_orientation else 0  # m3333 only for pose data
    m3, m33 = np.zeros((K, 3, 3)), np.zeros((K, 2, 3, 3))  # the sums of _moments
    m333, m3333 = np.zeros((K, 3, 3, 3)), np.zeros((K, d, d, d, d))
    if fit_frame or fit_tool:
        for k in range(K):
            _moments(
                T_flange[k],
                position[k],
                orientation[k % len(orientation)],
                has_orientation and fit_tool,
                m3[k],
                m33[k],
                m333[k],
                m3333[k],
            )
    for _ in range(rounds if (fit_frame and fit_tool) else 1):
        if fit_frame:
            status = _fit_frames(m3, m33, m333, T_tool, T_frame)
            if status != OK:
                return status
        if fit_tool:
            for k in range(K):
                _tool_point(m3[k], m33[k], m333[k], T_frame[k], T_tool[k])
                if has_orientation:
                    status = _tool_rotation(m3333[k], T_frame[k], T_tool[k])
                    if status != OK:
                        return status
    return OK


@_jit
def _fit_frames(m3, m33, m333, T_tool, T_frame):
    """Every robot's device frame (:func:`_rigid_fit`); a failed SVD is reported before a
    collinear robot, the first collinear one as ``COLLINEAR + k`` (as numpy's batch did)."""
    failed, collinear = False, -1
    for k in range(len(m3)):
        status = _rigid_fit(m3[k], m33[k], m333[k], T_tool[k, :3, 3], T_frame[k])
        failed |= status == SVD_FAILED
        if status == COLLINEAR and collinear < 0:
            collinear = k
    if failed:
        return SVD_FAILED
    if collinear >= 0:
        return COLLINEAR + collinear
    return OK
