"""Compiled kernels of the Levenberg-Marquardt iteration (numba) of
:func:`robocal.identify.solvers.levenberg_marquardt_batch`.

One iteration of that solver is: :func:`propose` (column scaling, scaled normal equations,
damped Cholesky step, predicted decrease, stop tests), one evaluation of the residuals and
Jacobians at the trial points (a Python callback), :func:`accept` (cost, gain ratio,
acceptance, Nielsen's damping update).  The arithmetic is small (for a 100-pose UR10, 300
rows and 27 columns: one ``JᵀJ`` and a 27 x 27 Cholesky per problem); numpy would spend
about 25 calls of overhead per iteration on it, which is why it is compiled here.  The
numpy version, ``tests/reference_lm.py``'s ``levenberg_marquardt_batch_numpy``, is the
reference ``tests/test_lm_kernels.py`` holds these kernels to.

The state of the ``K`` problems is kept at their batch indices (no compaction): ``ids[:n]``
lists the problems still running, in batch order; the trial points and the evaluations of
one iteration are packed in that order (row ``i`` is problem ``ids[i]``).

Written by hand (no library offers this iteration over a batch with a callback between its
halves); the Cholesky factorisation (:func:`robocal.model.rank_kernels.cholesky`) is written
out because a failed one is the test for positive definiteness here.  Compiled with
``cache=True`` (see :mod:`robocal.model.kernels`); this module imports numba, so
:mod:`robocal.identify.solvers` imports it on first use only.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from robocal.model.rank_kernels import cholesky as _cholesky

__all__ = ["accept", "damped_step", "propose", "start"]

# error_model="numpy": a division by zero gives inf/NaN as in numpy (the gain ratio of a zero
# predicted decrease), not a ZeroDivisionError
_jit = numba.njit(cache=True, nogil=True, error_model="numpy")

# μ is raised tenfold while A + μI is not positive definite; past this it never will be
# (A holds NaN or inf): the problem stops unconverged instead of looping for ever
_MU_LIMIT = 1e300


@_jit
def damped_step(A, g, mu, M, L, step):
    """``step = −(A + μI)⁻¹ g`` for a normal matrix ``A`` ``(p, p)`` and gradient ``g`` ``(p,)``,
    ``μ`` raised tenfold (at least to 1e-12) while ``A + μI`` is not positive definite.
    ``M``, ``L``: ``(p, p)`` work space.  Returns the ``μ`` used, NaN when no ``μ`` below
    1e300 made it positive definite (then ``step`` is NaN)."""
    p = A.shape[0]
    while True:
        for i in range(p):
            for j in range(i + 1):
                M[i, j] = A[i, j]
            M[i, i] += mu
        if _cholesky(M, L):
            break
        mu = max(mu * 10.0, 1e-12)
        if not mu < _MU_LIMIT:
            for a in range(p):
                step[a] = np.nan
            return np.nan
    for i in range(p):  # L y = −g, then Lᵀ step = y
        t = -g[i]
        for k in range(i):
            t -= L[i, k] * step[k]
        step[i] = t / L[i, i]
    for i in range(p - 1, -1, -1):
        t = step[i]
        for k in range(i + 1, p):
            t -= L[k, i] * step[k]
        step[i] = t / L[i, i]
    return mu


@_jit
def _normal_equations(J, r, i, transposed, G, Jr):
    """``G = JᵢᵀJᵢ`` ``(p, p)`` and ``Jr = Jᵢᵀrᵢ`` ``(p,)`` of problem row ``i`` of a stack of
    Jacobians ``J``: ``(n, m, p)``, or ``(n, p, m)`` (each one transposed) with
    ``transposed`` (both C-ordered)."""
    if transposed:
        _gram(J[i], r[i], G, Jr)
    else:  # one pass to the transposed layout: the products then run along contiguous rows
        Ji = J[i]
        m, p = Ji.shape
        Jt = np.empty((p, m))
        for k in range(m):
            for a in range(p):
                Jt[a, k] = Ji[k, a]
        _gram(Jt, r[i], G, Jr)


# Reassociation lets LLVM vectorise the sums over the rows (round-off differs from BLAS's
# order in the last bits); NaN and inf still propagate (no "nnan"/"ninf"): a Jacobian with
# them must fail the damped Cholesky factorisation as before.
@numba.njit(cache=True, nogil=True, error_model="numpy", fastmath={"reassoc", "contract"})
def _gram(Jt, r, G, Jr):
    """``G = Jt Jtᵀ`` ``(p, p)`` and ``Jr = Jt r`` ``(p,)`` of a transposed Jacobian ``Jt``
    ``(p, m)``: the lower triangle only, mirrored (half of a general product's work;
    BLAS's ``syrk`` is not reachable from a cached numba kernel), two rows of ``G`` per
    pass over the rows of ``Jt``."""
    p, m = Jt.shape
    for a in range(p):
        s = 0.0
        for k in range(m):
            s += Jt[a, k] * r[k]
        Jr[a] = s
    for a in range(0, p - 1, 2):  # rows a and a + 1 of the lower triangle
        for b in range(a + 1):
            s0 = s1 = 0.0
            for k in range(m):
                v = Jt[b, k]
                s0 += Jt[a, k] * v
                s1 += Jt[a + 1, k] * v
            G[a, b] = G[b, a] = s0
            G[a + 1, b] = G[b, a + 1] = s1
        s1 = 0.0
        for k in range(m):
            s1 += Jt[a + 1, k] * Jt[a + 1, k]
        G[a + 1, a + 1] = s1
    if p % 2:  # the last row of an odd size
        a = p - 1
        for b in range(a + 1):
            s0 = 0.0
            for k in range(m):
                s0 += Jt[a, k] * Jt[b, k]
            G[a, b] = G[b, a] = s0


@_jit
def _copy1(src, dst):
    for a in range(dst.shape[0]):
        dst[a] = src[a]


@_jit
def _squares(r, i):
    """``Σ r[i]²``."""
    c = 0.0
    for j in range(r.shape[1]):
        c += r[i, j] * r[i, j]
    return c


@_jit
def start(r, J, transposed, cost, G, Jr):
    """State of ``K`` problems from their first residuals ``r`` ``(K, m)`` and Jacobians
    ``J`` (as :func:`_normal_equations`): ``cost`` ``(K,)`` ``Σ r²``, ``G`` ``(K, p, p)``
    ``JᵀJ`` and ``Jr`` ``(K, p)`` ``Jᵀr``."""
    for k in range(r.shape[0]):
        cost[k] = _squares(r, k)
        _normal_equations(J, r, k, transposed, G[k], Jr[k])


# the kernels take the batch's state arrays as arguments (numba has no objects), as the
# chain's kernels (robocal.model.kernels*) do
@_jit
def propose(  # noqa: PLR0913
    ids, n, x, cost, G, Jr, D, mu, evaluations, success, tolerance, max_evaluations, x_new, predicted
):
    """The step of each running problem ``ids[:n]`` from its state; stop the converged ones
    and those out of evaluations.

    State (at batch indices ``k``): ``x`` ``(K, p)``, ``cost`` ``(K,)`` (``Σ r²``), ``G``
    ``(K, p, p)`` and ``Jr`` ``(K, p)``: ``JᵀJ`` and ``Jᵀr`` of the weighted residuals and
    Jacobian at ``x``, column scales ``D`` ``(K, p)`` (start at 0: the largest column norms
    met so far, 1 for a column that was always zero), damping ``mu`` ``(K,)`` (NaN: not
    started; then ``1e-6`` times the largest diagonal of the scaled normal matrix),
    ``evaluations`` ``(K,)``.  Each step solves ``(J_sᵀJ_s + μI) δ_s = −J_sᵀ r`` with
    ``J_s = J D⁻¹``; the predicted decrease is ``−δ_s·(2 J_sᵀr + J_sᵀJ_s δ_s)``.  A problem
    stops when that is below ``tolerance`` times its cost, or ``|δ_s| ≤ tolerance (|D x| +
    tolerance)``, or its cost is 0 (``success[k]`` True), or when it has used
    ``max_evaluations`` or no damping makes its normal matrix positive definite (NaN or
    inf in it) (``success[k]`` False).

    The problems still running are moved to the front of ``ids`` (order kept); their trial
    points ``x + δ_s / D`` go to ``x_new[:count]`` (packed) and their predicted decreases to
    ``predicted[k]``.  Returns ``count``.
    """
    p = x.shape[1]
    A = np.empty((p, p))
    M = np.empty((p, p))
    L = np.zeros((p, p))
    g = np.empty(p)
    inverse = np.empty(p)
    step = np.empty(p)
    count = 0
    for i in range(n):
        k = ids[i]
        for a in range(p):  # MINPACK's scaling: the largest column norm so far
            d = max(D[k, a], math.sqrt(G[k, a, a]))
            D[k, a] = d if d != 0.0 else 1.0
            inverse[a] = 1.0 / D[k, a]
        for a in range(p):
            g[a] = Jr[k, a] * inverse[a]
            for b in range(p):
                A[a, b] = G[k, a, b] * (inverse[a] * inverse[b])
        mu_k = mu[k]
        if math.isnan(mu_k):  # Nielsen's start for a good start point
            mu_k = 0.0
            for a in range(p):
                mu_k = max(mu_k, A[a, a])
            mu_k *= 1e-6
        mu_k = damped_step(A, g, mu_k, M, L, step)
        mu[k] = mu_k
        pred = 0.0
        step_sq = 0.0
        x_sq = 0.0
        for a in range(p):
            As = 0.0
            for b in range(p):
                As += A[a, b] * step[b]
            pred -= step[a] * (2.0 * g[a] + As)
            step_sq += step[a] * step[a]
            x_sq += (D[k, a] * x[k, a]) ** 2
        predicted[k] = pred
        small_step = math.sqrt(step_sq) <= tolerance * (math.sqrt(x_sq) + tolerance)
        converged = pred <= tolerance * cost[k] or small_step or cost[k] == 0.0
        if converged or evaluations[k] >= max_evaluations or math.isnan(mu_k):
            success[k] = converged
            continue
        ids[count] = k
        for a in range(p):
            x_new[count, a] = x[k, a] + step[a] / D[k, a]
        count += 1
    return count


@_jit
def accept(  # noqa: PLR0913
    ids, n, x_new, r_new, J_new, transposed, x, cost, G, Jr, mu, nu, predicted, evaluations, accepted, rms
):
    """Take the evaluations ``r_new`` ``(n, m)``, ``J_new`` (as :func:`_normal_equations`) at
    the trial points ``x_new[:n]`` of problems ``ids[:n]`` (packed, as :func:`propose` left
    them) where they lower the cost (gain ratio ``ρ`` = actual / predicted decrease > 0), and
    update the damping by Nielsen's rule: ``μ·max(1/3, 1 − (2ρ − 1)³)``, ``ν = 2`` after an
    accepted step, ``μ·ν``, ``ν ← 2ν`` after a refused one.  State as in :func:`propose`;
    ``nu`` ``(K,)``.  The accepted problems go to ``accepted[:, :count]`` (row 0: batch
    index, row 1: row in ``r_new``) and their new RMS residuals ``√(cost / m)`` to
    ``rms[:count]``.  Returns ``count``."""
    m = max(r_new.shape[1], 1)
    count = 0
    for i in range(n):
        k = ids[i]
        evaluations[k] += 1
        c = _squares(r_new, i)
        rho = (cost[k] - c) / predicted[k]
        if rho > 0.0:
            _copy1(x_new[i], x[k])
            cost[k] = c
            _normal_equations(J_new, r_new, i, transposed, G[k], Jr[k])
            mu[k] *= max(1.0 / 3.0, 1.0 - (2.0 * rho - 1.0) ** 3)
            nu[k] = 2.0
            accepted[0, count] = k
            accepted[1, count] = i
            rms[count] = math.sqrt(c / m)
            count += 1
        else:
            mu[k] *= nu[k]
            nu[k] *= 2.0
    return count
