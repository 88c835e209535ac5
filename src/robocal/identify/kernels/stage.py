"""Compiled kernels (numba) of the linear algebra between the fits of a calibration:
the normalised normal matrix and its inverse (:func:`normal_inverse`), the screening of
hopeless unknowns before the first fit (:func:`screen`) and the covariance of a fit
(:func:`covariance`, :func:`normal_covariance`), called by :mod:`robocal.identify.stages`
and the fused kernels.  Screening and the covariance after Levenberg-Marquardt work from
the normal equations ``JᵀJ`` the solver forms anyway: one product over the rows per
evaluation.

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

from robocal.identify import rules
from robocal.model.rank_kernels import cholesky

__all__ = [
    "condition_number",
    "covariance",
    "normal_covariance",
    "normal_inverse",
    "normalised",
    "prune_candidate",
    "screen",
    "variance_factor",
]

_jit = numba.njit(cache=True, nogil=True, error_model="numpy")

# the decision rules of robocal.identify.rules, compiled: the one definition that the
# staged pipeline (from Python), the fused kernels and the screening below all call
prune_candidate = _jit(rules.prune_candidate)
variance_factor = _jit(rules.variance_factor)
condition_number = _jit(rules.condition_number)
# the thresholds of a numerically singular normal matrix are Rules fields too
# (screen_singular, covariance_singular), passed in by the callers


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
def _tridiagonal(A):
    """The diagonal ``d`` ``(p,)`` and subdiagonal ``e`` ``(p,)`` (``e[i]`` couples ``i − 1`` and
    ``i``; ``e[0] = 0``) of a tridiagonal matrix similar to the symmetric ``A`` ``(p, p)``
    (Householder reflections from the last row up, EISPACK's ``tred1``; the lower triangle is
    read, no transformation kept)."""
    p = A.shape[0]
    a = A.copy()
    d, e = np.empty(p), np.zeros(p)
    for i in range(p - 1, 0, -1):
        scale = 0.0
        for k in range(i):
            scale += abs(a[i, k])
        if i == 1 or scale == 0.0:
            e[i] = a[i, i - 1]
            continue
        h = 0.0
        for k in range(i):
            a[i, k] /= scale
            h += a[i, k] * a[i, k]
        f = a[i, i - 1]
        g = -math.sqrt(h) if f >= 0.0 else math.sqrt(h)
        e[i] = scale * g
        h -= f * g
        a[i, i - 1] = f - g
        f = 0.0
        for j in range(i):  # p = A u / h (kept in e), K = uᵀp / 2h
            g = 0.0
            for k in range(j + 1):
                g += a[j, k] * a[i, k]
            for k in range(j + 1, i):
                g += a[k, j] * a[i, k]
            e[j] = g / h
            f += e[j] * a[i, j]
        hh = f / (h + h)
        for j in range(i):  # A ← A − u qᵀ − q uᵀ with q = p − K u
            f = a[i, j]
            g = e[j] - hh * f
            e[j] = g
            for k in range(j + 1):
                a[j, k] -= f * e[k] + g * a[i, k]
    for i in range(p):
        d[i] = a[i, i]
    e[0] = 0.0
    return d, e


@_jit
def _outer_root(d, e, x):
    """The eigenvalue of the symmetric tridiagonal ``(d, e)`` nearest ``x``, a point outside
    its spectrum (a Gershgorin bound), by Laguerre's iteration on ``det(T − xI)``: all its
    roots are real, so the iterates move monotonically towards that root from ``x``'s side,
    cubically near it, with ``T − xI`` definite on the way (its LDLᵀ pivots ``q`` keep their
    sign: no pivoting).  NaN when it did not settle in 100 steps."""
    p = len(d)
    for _ in range(100):
        g = h = 0.0  # f'/f and the derivative of f'/f, summed over the pivots
        q = dq = ddq = 1.0
        for i in range(p):
            c = e[i] * e[i]
            if i == 0:
                q, dq, ddq = d[0] - x, -1.0, 0.0
            else:
                prev, dprev, ddprev = q, dq, ddq
                q = d[i] - x - c / prev
                dq = -1.0 + c * dprev / (prev * prev)
                ddq = c * (ddprev / (prev * prev) - 2.0 * dprev * dprev / (prev * prev * prev))
            if q == 0.0:  # x is an eigenvalue (to round-off)
                return x
            ratio = dq / q
            g += ratio
            h += ddq / q - ratio * ratio
        big_h = -h  # G² − f''/f = −(f'/f)'
        root = math.sqrt(max((p - 1) * (p * big_h - g * g), 0.0))
        denominator = g + root if g >= 0.0 else g - root
        if denominator == 0.0 or not math.isfinite(denominator):
            return x
        step = p / denominator
        x_new = x - step
        if abs(step) <= 4.440892098500626e-16 * max(abs(x_new), 1e-300) or x_new == x:
            return x_new
        x = x_new
    return np.nan


@_jit
def extreme_eigenvalues(A):
    """The smallest and the largest eigenvalue of the symmetric ``A`` ``(p, p)``, ascending, as
    a ``(2,)`` array (``(0,)`` for ``p = 0``): what a condition number and a singularity test
    read of ``np.linalg.eigvalsh``, to round-off (~1e-16 of the largest).  Written out: LAPACK's
    ``dsyevd`` spends ~20 µs of calls on the 27 x 27 normal matrix of a calibration, the
    Householder tridiagonalisation and two Laguerre iterations from its Gershgorin bounds
    (:func:`_outer_root`) a few; LAPACK's when an iteration does not settle."""
    p = A.shape[0]
    if p == 0:
        return np.zeros(0)
    d, e = _tridiagonal(A)
    low, high = np.inf, -np.inf
    for i in range(p):
        radius = abs(e[i]) + (abs(e[i + 1]) if i + 1 < p else 0.0)
        low, high = min(low, d[i] - radius), max(high, d[i] + radius)
    out = np.empty(2)
    out[0], out[1] = _outer_root(d, e, low), _outer_root(d, e, high)
    if not (math.isfinite(out[0]) and math.isfinite(out[1])):
        lam = np.linalg.eigvalsh(A)
        out[0], out[1] = lam[0], lam[p - 1]
    return out


@_jit
def normalised(G):
    """The column norms of a normal matrix ``G = JᵀJ`` ``(p, p)`` (the square roots of its
    diagonal; 1 for a zero column) and the normal matrix of the unit-norm columns,
    ``A = G / (norms normsᵀ)``."""
    p = G.shape[0]
    norms = np.empty(p)
    for a in range(p):
        norms[a] = math.sqrt(G[a, a]) if G[a, a] > 0.0 else 1.0
    A = np.empty((p, p))
    for a in range(p):
        for b in range(p):
            A[a, b] = G[a, b] / (norms[a] * norms[b])
    return norms, A


@_jit
def normal_inverse(J, singular):
    """``J`` ``(m, p)`` with unit-norm columns, the column norms (a zero column's is 1),
    the ascending eigenvalues of ``A = JnᵀJn`` and its inverse; the last value is False
    when ``A`` is numerically singular (eigenvalue ratio ≤ ``singular``) or its
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
    ok = p > 0 and lam[0] > singular * lam[p - 1] and _spd_inverse(A, inverse)
    return Jn, norms, lam, inverse, ok


@_jit
def median(v):
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
def _norm1(A):
    """The 1-norm (largest absolute column sum) of ``A`` ``(p, p)``."""
    largest = 0.0
    for b in range(A.shape[1]):
        s = 0.0
        for a in range(A.shape[0]):
            s += abs(A[a, b])
        largest = max(largest, s)
    return largest


@_jit
def screen(G, g, rr, m, scale, screening, columns, sigmas):
    """The screening of :func:`robocal.identify.stages.screen_unidentifiable` from the
    normal equations of the weighted problem — ``G = JᵀJ`` ``(p, p)``, ``g = Jᵀr`` ``(p,)``,
    ``rr = rᵀr`` over ``m`` rows — the tool displacement per unit ``scale`` ``(p,)`` and its
    ``screening`` settings ``(max_std, max_std_ratio, margin, known_noise, singular, _)``
    (:meth:`robocal.identify.rules.Rules.screening`).
    The dropped columns and their σ (m) go to ``columns[:count]`` and ``sigmas[:count]``,
    worst first.  Returns ``count``.

    Each round works on the block of the columns still in: no product over the rows
    again.  The one-step residual's squares are ``rr − gₙᵀA⁻¹gₙ`` (``gₙ`` and ``A`` of the
    unit-norm columns; at the start values the residuals are well above what one step
    leaves, so the difference keeps its digits).  A numerically singular block — its
    Cholesky factorisation fails, or the 1-norm condition number ``‖A‖₁‖A⁻¹‖₁`` (at most
    ``p`` times the eigenvalue ratio's inverse) reaches ``1 / singular`` — is left to the
    fit and its checks."""
    max_std, max_std_ratio, margin, known_noise, singular, _ = screening
    p = G.shape[0]
    keep = np.ones(p, dtype=np.bool_)
    count = 0
    while p - count > 1:
        k = p - count
        live = np.empty(k, dtype=np.intp)
        n_live = 0
        for a in range(p):
            if keep[a]:
                live[n_live] = a
                n_live += 1
        Gk = np.empty((k, k))
        for a in range(k):
            for b in range(k):
                Gk[a, b] = G[live[a], live[b]]
        norms, A = normalised(Gk)
        inverse = np.empty((k, k))
        if not _spd_inverse(A, inverse) or _norm1(A) * _norm1(inverse) >= 1.0 / singular:
            break
        # with a stated noise (weights 1/σ) the variance is 1: far from the solution the
        # one-step residual still holds nonlinear error (2° errors inflated σ 10-50x)
        s2 = 1.0
        if not known_noise:
            explained = 0.0
            for a in range(k):
                ga = g[live[a]] / norms[a]
                for b in range(k):
                    explained += ga * inverse[a, b] * (g[live[b]] / norms[b])
            s2 = max(rr - explained, 0.0) / max(m - k, 1)
        move = np.empty(k)
        for a in range(k):
            move[a] = math.sqrt(s2 * inverse[a, a]) / norms[a] * scale[live[a]]
        worst = prune_candidate(move, max_std, max_std_ratio, margin)
        if worst == rules.NO_CANDIDATE:
            break
        columns[count] = live[worst]
        sigmas[count] = move[worst]
        keep[live[worst]] = False
        count += 1
    return count


@_jit
def _sandwich(Jn, row_s2, inverse):
    """``A⁻¹ Jnᵀ diag(σ̂²) Jn A⁻¹`` ``(p, p)`` (loops: numba's matrix products in several
    memory layouts cost seconds of compilation)."""
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
def covariance(J, row_s2, uniform, singular):
    """Covariance, standard deviations, correlations and the condition number
    (:func:`condition_number` of the unit-norm normal matrix) of a fit with weighted
    Jacobian ``J`` ``(m, p)`` and variance factors ``row_s2`` ``(m,)`` per row (``uniform``:
    all equal, σ̂²(JᵀJ)⁻¹ by :func:`normal_covariance`; otherwise the sandwich
    ``(JᵀJ)⁻¹ Jᵀ diag(σ̂²) J (JᵀJ)⁻¹``).  The last value is False when the normal matrix's
    eigenvalue ratio is ≤ ``singular`` (:attr:`robocal.identify.rules.Rules.covariance_singular`)
    or it is not positive definite (the caller uses the SVD; the condition number is then inf)."""
    if uniform:
        return normal_covariance(np.dot(J.T, J), row_s2[0], singular)
    p = J.shape[1]
    Jn, norms, lam, inverse, ok = normal_inverse(J, singular)
    if not ok:
        return np.empty((p, p)), np.empty(p), np.zeros((p, p)), np.inf, False
    return _in_units(_sandwich(Jn, row_s2, inverse), norms, lam)


@_jit
def normal_covariance(G, s2, singular):
    """:func:`covariance` with one variance ``s2`` for all rows, from the normal matrix
    ``G = JᵀJ`` ``(p, p)`` of the weighted Jacobian (a solver's last one: no product over
    the rows again)."""
    p = G.shape[0]
    norms, A = normalised(G)
    lam = extreme_eigenvalues(A)  # the condition number and the test read the extremes only
    inverse = np.empty((p, p))
    if not (p > 0 and lam[0] > singular * lam[1] and _spd_inverse(A, inverse)):  # (smallest, largest)
        return np.empty((p, p)), np.empty(p), np.zeros((p, p)), np.inf, False
    return _in_units(s2 * inverse, norms, lam)


@_jit
def _in_units(cov, norms, lam):
    """The covariance ``cov`` of the unit-norm columns in the columns' own units, its
    standard deviations, correlations and the condition number from ``lam``."""
    p = len(norms)
    for a in range(p):
        for b in range(p):
            cov[a, b] /= norms[a] * norms[b]
    std = np.empty(p)
    for a in range(p):
        std[a] = math.sqrt(max(cov[a, a], 0.0))
    corr = np.zeros((p, p))
    for a in range(p):
        for b in range(p):
            outer = std[a] * std[b]
            if outer > 0.0:
                corr[a, b] = cov[a, b] / outer
    return cov, std, corr, condition_number(lam), True
