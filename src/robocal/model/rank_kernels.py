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

__all__ = ["cholesky", "gram_sequential_test", "sequential_test"]

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


#: the Gram test's margins (:func:`gram_sequential_test`): a column is kept on the normal
#: equations' evidence when its squared distance to the kept columns before it is at least
#: ``KEEP_SQUARED`` (1e-3 as a distance: 10⁴ times the rank tolerance) and well above what
#: the round-off of ``AᵀA`` and its factorisation can move it by; it is dropped when the
#: residual of its fit in those columns, formed in the ``m`` rows, is at most ``DROP_FACTOR``
#: times the tolerance.  Anything between goes to the QR.
KEEP_SQUARED = 1e-6
DROP_FACTOR = 1e-2
#: the round-off bound of a Schur complement per unit of ``(1 + Σ|c|)²`` (``c``: the
#: column's coefficients in the kept ones; the bound grows with them), 10³ times the
#: backward error of forming and factoring ``AᵀA`` for a few hundred rows
ROUNDOFF_SQUARED = 1e-10


@numba.njit(cache=True, nogil=True, error_model="numpy", fastmath={"reassoc", "contract"})
def _gram_rows(At):
    """``At Atᵀ`` ``(k, k)`` of the rows of ``At`` ``(k, m)`` (the lower triangle, mirrored;
    two rows of it per pass over the rows of ``At``, as :func:`robocal.identify.kernels.lm`'s
    ``_gram``; reassociated sums: round-off differs from BLAS in the last bits, NaN and inf
    still propagate)."""
    k, m = At.shape
    G = np.empty((k, k))
    for a in range(0, k - 1, 2):
        row0, row1 = At[a], At[a + 1]
        for b in range(a + 1):
            other = At[b]
            s0 = s1 = 0.0
            for i in range(m):
                v = other[i]
                s0 += row0[i] * v
                s1 += row1[i] * v
            G[a, b] = G[b, a] = s0
            G[a + 1, b] = G[b, a + 1] = s1
        s1 = 0.0
        for i in range(m):
            s1 += row1[i] * row1[i]
        G[a + 1, a + 1] = s1
    if k % 2:
        a = k - 1
        row0 = At[a]
        for b in range(a + 1):
            other = At[b]
            s0 = 0.0
            for i in range(m):
                s0 += row0[i] * other[i]
            G[a, b] = G[b, a] = s0
    return G


@numba.njit(cache=True, nogil=True, error_model="numpy", fastmath={"reassoc", "contract"})
def _residual_norm(At, j, rows, c, n):
    """``‖At[j] − Σ_a c[a] At[rows[a]]‖`` over the first ``n`` of ``rows`` (a column's fit in
    others, formed in the ``m`` rows: no cancellation; two rows per pass)."""
    m = At.shape[1]
    r = At[j].copy()
    for a in range(0, n - 1, 2):
        c0, c1, row0, row1 = c[a], c[a + 1], At[rows[a]], At[rows[a + 1]]
        for i in range(m):
            r[i] -= c0 * row0[i] + c1 * row1[i]
    if n % 2:
        c0, row0 = c[n - 1], At[rows[n - 1]]
        for i in range(m):
            r[i] -= c0 * row0[i]
    s = 0.0
    for i in range(m):
        s += r[i] * r[i]
    return math.sqrt(s)


@_jit
def _back_solve(L, kept, n, row, c):
    """``c`` ``(n,)`` with ``L_Kᵀ c = L[row, :n]``: the coefficients of column ``row`` in the
    first ``n`` kept columns, from its row of the factor."""
    for a in range(n - 1, -1, -1):
        t = L[row, a]
        for b in range(a + 1, n):
            t -= L[kept[b], a] * c[b]
        c[a] = t / L[kept[a], a]


@_jit
def gram_sequential_test(At, tolerance):
    """:func:`sequential_test` from the normal equations of the unit-norm columns, the rows of
    ``At`` ``(k, m)`` in test order, without their QR (the QR of a 300 x 36 Jacobian costs
    ~45 µs; ``AᵀA`` and its factorisation about a fifth of it).

    One left-looking Cholesky factorisation of ``AᵀA`` over the columns kept so far gives each
    column's squared distance ``s`` to the kept columns before it.  A column is kept when
    ``s ≥`` :data:`KEEP_SQUARED` and ``s`` is far above the round-off bound
    :data:`ROUNDOFF_SQUARED` ``· (1 + Σ|c|)²``; otherwise its fit in those columns is formed in
    the ``m`` rows, and it is dropped when what that leaves is at most :data:`DROP_FACTOR` ×
    ``tolerance`` (any fit's residual bounds the distance from above: a drop is proved).  A
    dropped column's coefficients are that fit's (0 for the kept columns after it) and what it
    leaves that fit's residual norm, in :func:`sequential_test`'s layout.

    Returns :func:`sequential_test`'s values (``|R_kk|``: ``√s`` of a kept column, its fit's
    residual for a dropped one) and whether every verdict was decided with these margins (and
    ``m ≥ 4k``: with few rows the QR's verdicts also depend on the directions of round-off in
    the dropped columns); when not, the caller runs the QR (:func:`sequential_test`)."""
    k, m = At.shape
    diag = np.zeros(k)
    keep = np.zeros(k, dtype=np.bool_)
    empty = np.zeros((0, 0)), np.zeros(0)
    if m < 4 * k or k == 0:
        return diag, keep, empty[0], empty[1], False
    G = _gram_rows(At)
    L = np.zeros((k, k))  # row j: column j's entries against the kept columns (their positions)
    kept = np.empty(k, dtype=np.intp)
    C = np.zeros((k, k))  # row j: a dropped column's coefficients in the kept columns before it
    n = 0
    for j in range(k):
        c = C[j]
        s = G[j, j]
        for a in range(n):
            i = kept[a]
            t = G[j, i]
            for b in range(a):
                t -= L[j, b] * L[i, b]
            L[j, a] = t / L[i, a]
            s -= L[j, a] * L[j, a]
        _back_solve(L, kept, n, j, c)
        size = 1.0
        for a in range(n):
            size += abs(c[a])
        if s >= KEEP_SQUARED and s >= ROUNDOFF_SQUARED * size * size:
            L[j, n] = math.sqrt(s)
            kept[n] = j
            n += 1
            keep[j] = True
            diag[j] = math.sqrt(s)
            continue
        left = _residual_norm(At, j, kept, c, n)
        if not left <= DROP_FACTOR * tolerance:
            return diag, keep, empty[0], empty[1], False
        diag[j] = left
    return _absorbed(C, n, diag, keep, tolerance)


@_jit
def _absorbed(C, n, diag, keep, tolerance):
    """The dropped columns' coefficients ``(n, dropped)`` in the ``n`` kept columns and what
    they leave, from each one's fit in the kept columns before it (``C`` ``(k, k)``: row ``j``
    its coefficients; the kept columns after it take 0: it lies within ``DROP_FACTOR ×
    tolerance`` of those before) and the norm of that fit's residual (``diag``): the end of
    :func:`gram_sequential_test`."""
    k = len(keep)
    coefs = np.zeros((n, k - n))
    left = np.zeros(k - n)
    d = 0
    for j in range(k):
        if keep[j]:
            continue
        for a in range(n):
            coefs[a, d] = C[j, a]
        left[d] = diag[j]
        d += 1
    return diag, keep, coefs, left, True
