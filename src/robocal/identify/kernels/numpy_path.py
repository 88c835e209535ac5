"""The numpy path of the compiled kernels between the fits: start values
(:func:`frames_and_tools`), the normal matrix's inverse (:func:`normal_inverse`), screening
(:func:`screen`) and the covariance (:func:`covariance`), with the compiled kernels' names,
arguments and returns, so that a caller takes either module
(:mod:`robocal.identify.kernels.start` and :mod:`robocal.identify.kernels.stage`; the
decision rules are :mod:`robocal.identify.rules`' own functions).

Used while numba's cache is cold (:mod:`robocal.model.kernel_mode`): the first command after
installing runs these instead of compiling for half a minute.  The same arithmetic as the
kernels up to round-off (BLAS and LAPACK instead of loops; ``tests/test_cold_path.py`` holds
whole calibrations on both paths to 1e-10).  No numba here.  Units: SI (m, rad).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from robocal.identify import rules

__all__ = [
    "COLLINEAR",
    "NON_FINITE_POINTS",
    "OK",
    "SVD_FAILED",
    "condition_number",
    "covariance",
    "frames_and_tools",
    "normal_covariance",
    "normal_inverse",
    "prune_candidate",
    "screen",
    "variance_factor",
]

Array = NDArray[np.float64]
#: statuses of :func:`frames_and_tools`, as :mod:`robocal.identify.kernels.start`'s
OK, NON_FINITE_POINTS, SVD_FAILED, COLLINEAR = 0, 1, 2, 3
_COLLINEAR_RATIO = 1e-12  # a rigid fit's second singular value at most this of the first
prune_candidate = rules.prune_candidate
variance_factor = rules.variance_factor
condition_number = rules.condition_number


class _CollinearError(Exception):
    """Robot ``args[0]``'s points are (nearly) collinear."""


# ---------------------------------------------------------------------- start values
def _nearest_rotations(M: Array) -> Array:
    """The nearest rotations ``(..., 3, 3)`` to matrices ``M`` (SVD, det +1)."""
    U, _, Vt = np.linalg.svd(M)
    flip = np.linalg.det(U @ Vt) < 0
    U[flip, :, -1] *= -1
    return U @ Vt


def _rigid_fits(P: Array, Q: Array) -> Array:
    """``(K, 4, 4)`` least-squares rigid transforms mapping ``P`` onto ``Q`` (``(K, n, 3)``,
    Kabsch/Horn)."""
    K, n = P.shape[:2]
    p0, q0 = P.mean(axis=1), Q.mean(axis=1)
    H = np.swapaxes(P - p0[:, None], 1, 2) @ (Q - q0[:, None]) / n
    U, s, Vt = np.linalg.svd(H)
    degenerate = s[:, 1] <= _COLLINEAR_RATIO * np.maximum(s[:, 0], 1e-300)
    if np.any(degenerate):
        raise _CollinearError(int(np.flatnonzero(degenerate)[0]))
    V, Ut = np.swapaxes(Vt, 1, 2), np.swapaxes(U, 1, 2)
    V[:, :, 2] *= np.sign(np.linalg.det(V @ Ut))[:, None]
    T = np.zeros((K, 4, 4))
    T[:, :3, :3] = V @ Ut
    T[:, :3, 3] = q0 - (T[:, :3, :3] @ p0[..., None])[..., 0]
    T[:, 3, 3] = 1.0
    return T


def frames_and_tools(
    T_flange: Array,
    position: Array,
    orientation: Array,
    has_orientation: bool,
    T_frame: Array,
    T_tool: Array,
    fit_frame: bool,
    fit_tool: bool,
    rounds: int,
) -> int:
    """:func:`robocal.identify.kernels.start.frames_and_tools` in numpy: the alternating
    fits of the device frames and tools ``(K, 4, 4)`` of ``K`` robots, in place in
    ``T_frame`` and ``T_tool``, from end frames ``(K, n, 4, 4)``, positions ``(K, n, 3)`` and
    orientations ``(K, n, 3, 3)`` (when ``has_orientation``).  Returns the kernel's status:
    OK, NON_FINITE_POINTS, SVD_FAILED or ``COLLINEAR + k``."""
    if fit_frame and not np.all(np.isfinite(position)):
        return NON_FINITE_POINTS
    try:
        _alternate(T_flange, position, orientation if has_orientation else None, T_frame, T_tool,
                   fit_frame, fit_tool, rounds)  # fmt: skip
    except np.linalg.LinAlgError:
        return SVD_FAILED
    except _CollinearError as collinear:
        return COLLINEAR + int(collinear.args[0])
    return OK


def _alternate(
    T_flange: Array,
    position: Array,
    orientation: Array | None,
    T_frame: Array,
    T_tool: Array,
    fit_frame: bool,
    fit_tool: bool,
    rounds: int,
) -> None:
    """The rounds of :func:`frames_and_tools` (raises for a failed SVD or collinear points)."""
    n = T_flange.shape[1]
    R_f, p_f = T_flange[..., :3, :3], T_flange[..., :3, 3]
    R_fT = np.swapaxes(R_f, -1, -2)
    for _ in range(rounds if (fit_frame and fit_tool) else 1):
        if fit_frame:
            p_base = (R_f @ T_tool[:, None, :3, 3:])[..., 0] + p_f
            T_frame[...] = _rigid_fits(p_base, position)
        if fit_tool:
            R0, t0 = T_frame[:, :3, :3], T_frame[:, :3, 3]
            b = (position - t0[:, None, :]) @ R0 - p_f
            T_tool[:, :3, 3] = (R_fT @ b[..., None]).sum(axis=1)[..., 0] / n
            if orientation is not None:
                R = R0[:, None] @ R_f
                T_tool[:, :3, :3] = _nearest_rotations(np.einsum("anji,anjk->aik", R, orientation))


# ---------------------------------------------------------------------- normal equations
def _spd_inverse(A: Array) -> Array | None:
    """The inverse of the symmetric positive definite ``A`` ``(p, p)`` from its Cholesky
    factor; None when ``A`` is not positive definite."""
    try:
        L = np.linalg.cholesky(A)
    except np.linalg.LinAlgError:
        return None
    Li = np.linalg.inv(L)
    return Li.T @ Li


def _normalised(G: Array) -> tuple[Array, Array]:
    """Column norms (1 for a zero column) and the unit-norm normal matrix of ``G = JᵀJ``."""
    d = np.diag(G)
    norms = np.where(d > 0.0, np.sqrt(np.where(d > 0.0, d, 1.0)), 1.0)
    return norms, G / np.outer(norms, norms)


def normal_inverse(J: Array, singular: float) -> tuple[Array, Array, Array, Array, bool]:
    """:func:`robocal.identify.kernels.stage.normal_inverse` in numpy: ``Jn``, the column
    norms, the ascending eigenvalues of ``JnᵀJn``, its inverse, and whether it is not
    numerically singular (eigenvalue ratio above ``singular``; else no inverse)."""
    p = J.shape[1]
    s = np.einsum("ij,ij->j", J, J)
    norms = np.asarray(np.where(s > 0.0, np.sqrt(np.where(s > 0.0, s, 1.0)), 1.0), dtype=np.float64)
    Jn = J / norms
    A = Jn.T @ Jn
    lam = np.asarray(np.linalg.eigvalsh(A), dtype=np.float64)
    inverse = np.empty((p, p))
    ok = p > 0 and lam[0] > singular * lam[p - 1]
    spd = None
    if ok and (spd := _spd_inverse(A)) is not None:
        inverse = spd
    return Jn, norms, lam, inverse, bool(ok and spd is not None)


def screen(
    G: Array, g: Array, rr: float, m: int, scale: Array, screening: tuple, columns: Array, sigmas: Array
) -> int:
    """:func:`robocal.identify.kernels.stage.screen` in numpy (same arguments, the same
    rounds on the normal equations): the screened columns and their σ into ``columns`` and
    ``sigmas``; returns their count."""
    max_std, max_std_ratio, margin, known_noise, singular, _ = screening
    p = G.shape[0]
    keep = np.ones(p, dtype=bool)
    count = 0
    while p - count > 1:
        live = np.flatnonzero(keep)
        norms, A = _normalised(G[np.ix_(live, live)])
        inverse = _spd_inverse(A)
        if inverse is None or np.abs(A).sum(0).max() * np.abs(inverse).sum(0).max() >= 1.0 / singular:
            break
        s2 = 1.0  # a stated noise: as the kernel (its comment says why)
        if not known_noise:
            gn = g[live] / norms
            s2 = max(rr - float(gn @ inverse @ gn), 0.0) / max(m - len(live), 1)
        move = np.sqrt(s2 * np.diag(inverse)) / norms * scale[live]
        worst = rules.prune_candidate(move, max_std, max_std_ratio, margin)
        if worst == rules.NO_CANDIDATE:
            break
        columns[count], sigmas[count] = live[worst], move[worst]
        keep[live[worst]] = False
        count += 1
    return count


# ---------------------------------------------------------------------- covariance
Covariances = tuple[Array, Array, Array, float, bool]  # cov, std, corr, condition number, ok


def _in_units(cov: Array, norms: Array, lam: Array) -> Covariances:
    """The covariance of the unit-norm columns in the columns' units, σ, correlations and
    the condition number from the eigenvalues ``lam``."""
    cov = cov / np.outer(norms, norms)
    std = np.sqrt(np.maximum(np.diag(cov), 0.0))
    outer = np.outer(std, std)
    corr = np.where(outer > 0.0, cov / np.where(outer > 0.0, outer, 1.0), 0.0)
    return cov, std, corr, condition_number(lam), True


def _failed(p: int) -> Covariances:
    return np.empty((p, p)), np.empty(p), np.zeros((p, p)), np.inf, False


def normal_covariance(G: Array, s2: float, singular: float) -> Covariances:
    """:func:`robocal.identify.kernels.stage.normal_covariance` in numpy."""
    p = G.shape[0]
    norms, A = _normalised(G)
    lam = np.asarray(np.linalg.eigvalsh(A), dtype=np.float64)
    inverse = _spd_inverse(A) if p > 0 and lam[0] > singular * lam[p - 1] else None
    if inverse is None:
        return _failed(p)
    return _in_units(s2 * inverse, norms, lam)


def covariance(J: Array, row_s2: Array, uniform: bool, singular: float) -> Covariances:
    """:func:`robocal.identify.kernels.stage.covariance` in numpy: σ̂²(JᵀJ)⁻¹ (``uniform``)
    or the sandwich ``(JᵀJ)⁻¹ Jᵀ diag(σ̂²) J (JᵀJ)⁻¹``."""
    if uniform:
        return normal_covariance(J.T @ J, float(row_s2[0]), singular)
    Jn, norms, lam, inverse, ok = normal_inverse(J, singular)
    if not ok:
        return _failed(J.shape[1])
    return _in_units(inverse @ (Jn.T @ (Jn * row_s2[:, None])) @ inverse, norms, lam)
