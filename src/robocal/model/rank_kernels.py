"""Compiled kernels (numba) of the sequential rank test
(:func:`robocal.model.rank._sequential_rank_test`) and the Cholesky factorisation the
calibration's kernels share (:func:`cholesky`).

:func:`sequential_test` reads the rank decision off the QR of the unit-norm columns and
fits each dropped column in the kept ones, by the normal equations on the ``p x p``
triangle ``R`` (``A = QR`` with orthonormal ``Q``: the same coefficients and residual
norms as on ``A``, a tenth of the work).  For the 300 x 36 scaled Jacobian of a 100-pose
UR10 the arithmetic is a few µs; numpy's column selections, products, solve and norms
cost about 100 µs of calls, which is why it is compiled.  The numpy form it replaced is the
reference ``tests/test_stage_kernels.py`` holds it to.

The Cholesky factorisation is written out because a failed one is the test for positive
definiteness here (numba's ``np.linalg.cholesky`` raises, which a kernel cannot catch
cheaply).  Compiled with ``cache=True`` (see :mod:`robocal.model.kernels`); imported on
first use only (it imports numba).
"""

from __future__ import annotations

import math

import numba
import numpy as np

__all__ = ["cholesky", "sequential_test"]

_jit = numba.njit(cache=True, nogil=True, error_model="numpy")


@_jit
def cholesky(M, L):
    """Lower factor ``L`` of ``M`` ``(p, p)`` (only the lower triangle of ``M`` is read);
    False when ``M`` is not positive definite (a pivot is not > 0, or NaN; as LAPACK's potrf)."""
    p = M.shape[0]
    for j in range(p):
        s = M[j, j]
        for k in range(j):
            s -= L[j, k] * L[j, k]
        if not s > 0.0:
            return False
        d = math.sqrt(s)
        L[j, j] = d
        for i in range(j + 1, p):
            t = M[i, j]
            for k in range(j):
                t -= L[i, k] * L[j, k]
            L[i, j] = t / d
    return True


@_jit
def _columns(qr, cols, d):
    """Columns ``cols`` of the upper triangle of ``qr``'s first ``d`` rows, ``(d, len(cols))``."""
    out = np.zeros((d, len(cols)))
    for a in range(len(cols)):
        c = cols[a]
        for i in range(min(c + 1, d)):
            out[i, a] = qr[i, c]
    return out


@_jit
def _products(X, Y, rows):
    """``XᵀY`` of two small ``(d, ·)`` matrices whose column ``a`` of ``X`` is zero past row
    ``rows[a]`` (columns of ``R``: those rows are skipped, a zero term leaves a sum as it
    is) (loops: numba's BLAS products in several memory layouts cost seconds of
    compilation, and these are p x p)."""
    out = np.zeros((X.shape[1], Y.shape[1]))
    for i in range(X.shape[0]):
        for a in range(X.shape[1]):
            if i > rows[a]:
                continue
            x = X[i, a]
            for b in range(Y.shape[1]):
                out[a, b] += x * Y[i, b]
    return out


@_jit
def _split(keep):
    """The indices of the True and of the False entries of ``keep`` (loops: numba's
    ``flatnonzero`` costs a fifth of a second to compile)."""
    n = 0
    for k in range(len(keep)):
        n += keep[k]
    true, false = np.empty(n, dtype=np.intp), np.empty(len(keep) - n, dtype=np.intp)
    a = b = 0
    for k in range(len(keep)):
        if keep[k]:
            true[a] = k
            a += 1
        else:
            false[b] = k
            b += 1
    return true, false


@_jit
def _cholesky_solve(L, B, X):
    """``X`` ``(n, k)`` with ``L Lᵀ X = B`` for the lower factor ``L`` ``(n, n)``."""
    n = L.shape[0]
    for j in range(B.shape[1]):  # L y = b, then Lᵀ x = y
        for i in range(n):
            t = B[i, j]
            for k in range(i):
                t -= L[i, k] * X[k, j]
            X[i, j] = t / L[i, i]
        for i in range(n - 1, -1, -1):
            t = X[i, j]
            for k in range(i + 1, n):
                t -= L[k, i] * X[k, j]
            X[i, j] = t / L[i, i]


@_jit
def sequential_test(qr, tolerance):
    """The sequential rank test from ``qr`` ``(m, p)``, LAPACK's packed QR (``geqrf``) of
    unit-norm columns in test order: ``|R_kk|`` ``(p,)`` (0 past ``min(m, p)``), the mask
    of kept columns (``|R_kk| > tolerance``), the coefficients ``(kept, dropped)`` of the
    dropped columns in the kept ones, the norms ``(dropped,)`` of what they leave, and
    whether the verdicts stand: False when some dropped column leaves more than
    ``tolerance``, or the kept columns' normal matrix is not positive definite (or none is
    kept while some is dropped; then the coefficients are not computed)."""
    m, p = qr.shape
    d = min(m, p)
    diag = np.zeros(p)
    for k in range(d):
        diag[k] = abs(qr[k, k])
    keep = diag > tolerance
    kept, dropped = _split(keep)
    coefs = np.zeros((len(kept), len(dropped)))
    left = np.zeros(len(dropped))
    if len(dropped) == 0:
        return diag, keep, coefs, left, True
    if len(kept) == 0:
        return diag, keep, coefs, left, False
    RK, RD = _columns(qr, kept, d), _columns(qr, dropped, d)
    n = len(kept)
    G, B = _products(RK, RK, kept), _products(RK, RD, kept)
    L = np.zeros((n, n))
    if not cholesky(G, L):
        return diag, keep, coefs, left, False
    _cholesky_solve(L, B, coefs)
    explained = True
    for j in range(len(dropped)):  # what the fit leaves: RD − RK coefs
        s = 0.0
        for i in range(d):
            t = RD[i, j]
            for k in range(n):
                if kept[k] >= i:  # RK's column k is zero below its own row
                    t -= RK[i, k] * coefs[k, j]
            s += t * t
        left[j] = math.sqrt(s)
        explained = explained and left[j] <= tolerance
    return diag, keep, coefs, left, explained
