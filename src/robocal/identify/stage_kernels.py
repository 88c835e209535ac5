"""Compiled kernels (numba) of the linear algebra between the fits of a calibration:
the normalised normal matrix and its inverse (:func:`normal_inverse`), the screening of
hopeless unknowns before the first fit (:func:`screen`) and the covariance of a fit
(:func:`covariance`), called by :mod:`robocal.identify.stages`.

The matrices are small (for a 100-pose UR10, 300 x 27 Jacobians and 27 x 27 normal
matrices): numpy spent about forty calls of fixed cost on each screening round and
covariance, several times the arithmetic, which is why they are compiled.  The numpy
versions they replace are the reference ``tests/test_stage_kernels.py`` holds them to.

The inverse of the normal matrix comes from a Cholesky factorisation written out here:
numba offers no ``potri`` and its ``np.linalg.cholesky`` raises on a matrix that is not
positive definite, which a kernel cannot catch cheaply (the factorisation is
:func:`robocal.model.rank_kernels.cholesky`).  Compiled with ``cache=True`` (see
:mod:`robocal.model.kernels`); this module imports numba, so :mod:`robocal.identify.stages`
imports it on first use only.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from robocal.model.rank_kernels import cholesky

__all__ = ["covariance", "normal_inverse", "screen"]

_jit = numba.njit(cache=True, nogil=True, error_model="numpy")

# an eigenvalue ratio at or below this: the normal matrix is numerically singular
SINGULAR = 1e-14


@_jit
def _spd_inverse(A, inverse):
    """``inverse`` ``(p, p)`` of the symmetric ``A`` from its Cholesky factor ``L``
    (``A⁻¹ = L⁻ᵀ L⁻¹``); False when ``A`` is not positive definite."""
    p = A.shape[0]
    L = np.zeros((p, p))
    if not cholesky(A, L):
        return False
    Li = np.zeros((p, p))  # L⁻¹, lower triangular, by forward substitution
    for j in range(p):
        Li[j, j] = 1.0 / L[j, j]
        for i in range(j + 1, p):
            t = 0.0
            for k in range(j, i):
                t -= L[i, k] * Li[k, j]
            Li[i, j] = t / L[i, i]
    for i in range(p):  # (L⁻ᵀ L⁻¹)_ij = Σ_k≥max(i,j) Li[k, i] Li[k, j]
        for j in range(i + 1):
            t = 0.0
            for k in range(i, p):
                t += Li[k, i] * Li[k, j]
            inverse[i, j] = t
            inverse[j, i] = t
    return True


@_jit
def normal_inverse(J):
    """``J`` ``(m, p)`` with unit-norm columns, the column norms (a zero column's is 1),
    the ascending eigenvalues of ``A = JnᵀJn`` and its inverse; the last value is False
    when ``A`` is numerically singular (eigenvalue ratio ≤ :data:`SINGULAR`) or its
    factorisation failed: then the inverse is not computed."""
    m, p = J.shape
    norms = np.empty(p)
    for j in range(p):
        s = 0.0
        for i in range(m):
            s += J[i, j] * J[i, j]
        norms[j] = math.sqrt(s) if s > 0.0 else 1.0
    Jn = np.empty((m, p))
    for i in range(m):
        for j in range(p):
            Jn[i, j] = J[i, j] / norms[j]
    A = np.dot(Jn.T, Jn)  # BLAS: the one product here large enough to need it
    lam = np.linalg.eigvalsh(A)
    inverse = np.empty((p, p))
    ok = p > 0 and lam[0] > SINGULAR * lam[p - 1] and _spd_inverse(A, inverse)
    return Jn, norms, lam, inverse, ok


@_jit
def _median(v):
    """The median of a short vector, by insertion sort (numba's ``np.sort`` costs most of
    a second of compilation)."""
    s = v.copy()
    n = len(s)
    for i in range(1, n):
        x = s[i]
        j = i - 1
        while j >= 0 and s[j] > x:
            s[j + 1] = s[j]
            j -= 1
        s[j + 1] = x
    return 0.5 * (s[(n - 1) // 2] + s[n // 2])


@_jit
def _squares(e):
    s = 0.0
    for x in e:
        s += x * x
    return s


@_jit
def _one_step_residual(r, Jn, inverse):
    """``r − Jn A⁻¹ Jnᵀ r``: the residual after one Gauss-Newton step (loops: numba's
    matrix-vector products in several memory layouts cost seconds of compilation)."""
    m, p = Jn.shape
    g = np.zeros(p)
    for i in range(m):
        for a in range(p):
            g[a] += Jn[i, a] * r[i]
    step = np.zeros(p)
    for a in range(p):
        for b in range(p):
            step[a] += inverse[a, b] * g[b]
    e = r.copy()
    for i in range(m):
        for a in range(p):
            e[i] -= Jn[i, a] * step[a]
    return e


@_jit
def screen(r, J, scale, max_std, max_std_ratio, margin, known_noise, columns, sigmas):
    """The screening of :func:`robocal.identify.stages.screen_unidentifiable`: weighted
    residuals ``r`` ``(m,)``, Jacobian ``J`` ``(m, p)``, tool displacement per unit
    ``scale`` ``(p,)``.  The dropped columns and their σ (m) go to ``columns[:count]`` and
    ``sigmas[:count]``, worst first.  Returns ``count``, or −1 − count when a normal
    matrix passed the singularity test but its factorisation failed (the caller finishes
    with numpy)."""
    m, p = J.shape
    keep = np.ones(p, dtype=np.bool_)
    count = 0
    while p - count > 1:
        live = np.empty(p - count, dtype=np.intp)
        k = 0
        for a in range(p):
            if keep[a]:
                live[k] = a
                k += 1
        Jk = np.empty((m, len(live)))
        for i in range(m):
            for a in range(len(live)):
                Jk[i, a] = J[i, live[a]]
        Jn, norms, lam, inverse, ok = normal_inverse(Jk)
        if lam[0] <= SINGULAR * lam[len(lam) - 1]:  # the fit and its checks decide
            break
        if not ok:
            return -1 - count
        e = _one_step_residual(r, Jn, inverse)
        # with a stated noise (weights 1/σ) the variance is 1: far from the solution the
        # one-step residual still holds nonlinear error (2° errors inflated σ 10-50x)
        s2 = 1.0 if known_noise else _squares(e) / max(m - len(live), 1)
        move = np.empty(len(live))
        for a in range(len(live)):
            move[a] = math.sqrt(s2 * inverse[a, a]) / norms[a] * scale[live[a]]
        worst = np.argmax(move)
        if move[worst] <= margin * max(max_std, max_std_ratio * _median(move)):
            break
        columns[count] = live[worst]
        sigmas[count] = move[worst]
        keep[live[worst]] = False
        count += 1
    return count


@_jit
def _sandwich(Jn, row_s2, inverse):
    """``A⁻¹ Jnᵀ diag(σ̂²) Jn A⁻¹`` ``(p, p)`` (loops, as :func:`_one_step_residual`)."""
    m, p = Jn.shape
    middle = np.zeros((p, p))
    for i in range(m):
        for a in range(p):
            w = Jn[i, a] * row_s2[i]
            for b in range(p):
                middle[a, b] += w * Jn[i, b]
    left = np.zeros((p, p))
    for a in range(p):
        for k in range(p):
            for b in range(p):
                left[a, b] += inverse[a, k] * middle[k, b]
    out = np.zeros((p, p))
    for a in range(p):
        for k in range(p):
            for b in range(p):
                out[a, b] += left[a, k] * inverse[k, b]
    return out


@_jit
def covariance(J, row_s2, uniform):
    """Covariance, standard deviations, correlations and the normal matrix's eigenvalues of
    a fit with weighted Jacobian ``J`` ``(m, p)`` and variance factors ``row_s2`` ``(m,)``
    per row (``uniform``: all equal, σ̂²(JᵀJ)⁻¹; otherwise the sandwich
    ``(JᵀJ)⁻¹ Jᵀ diag(σ̂²) J (JᵀJ)⁻¹``).  The last value is False when the normal matrix's
    eigenvalue ratio is ≤ 1e-12 or it is not positive definite (the caller uses the SVD)."""
    p = J.shape[1]
    Jn, norms, lam, inverse, ok = normal_inverse(J)
    std = np.empty(p)
    corr = np.zeros((p, p))
    if not ok or not lam[0] > 1e-12 * lam[p - 1]:
        return np.empty((p, p)), std, corr, lam, False
    cov = row_s2[0] * inverse if uniform else _sandwich(Jn, row_s2, inverse)
    for a in range(p):
        for b in range(p):
            cov[a, b] /= norms[a] * norms[b]
    for a in range(p):
        std[a] = math.sqrt(max(cov[a, a], 0.0))
    for a in range(p):
        for b in range(p):
            outer = std[a] * std[b]
            if outer > 0.0:
                corr[a, b] = cov[a, b] / outer
    return cov, std, corr, lam, True
