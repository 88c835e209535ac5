"""Compiled kernels (numba) of the fused stages of a position calibration
(:mod:`robocal.identify.fused`): the first evaluation with the rank test's unit-norm
columns (:func:`first_pass`), and screening, Levenberg-Marquardt, covariance and pruning
in one call (:func:`fit`).

They compose the kernels the staged pipeline calls one by one — the chain's fused
evaluation (:func:`robocal.model.kernels_evaluate.evaluate`), the screening and the
covariance (:mod:`robocal.identify.kernels.stage`), the Levenberg-Marquardt iteration
(:mod:`robocal.identify.kernels.lm`) — in the order of
:func:`robocal.identify.pipeline._calibrate_once`, so that the ~40 Python calls between
them (Problem objects, evaluations through the model, checks) are not paid: about half
of a 100-pose calibration.  The staged pipeline is the reference
``tests/test_fused.py`` holds this to.

The measurement chain reaches the kernels as ``data``, a tuple ``(q, position, weights,
step_axis, step_rot, step_joint, joint_axis, joint_rot, anchor_of, joint_steps)``: joint
values ``(n, dof)``, measured positions ``(n, 3)`` (m), row weights ``(3n,)`` (1/σ) and the
chain plan's arrays (:class:`robocal.model.chain_plan.Plan`).  Unknowns are indexed by
their column among the chain's free steps (``free_steps``, step indices).  Compiled with
``cache=True`` (see :mod:`robocal.model.kernels`); imported on first use only.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from robocal.identify.kernels.lm import accept, propose, start
from robocal.identify.kernels.stage import normal_covariance, prune_candidate, screen, variance_factor
from robocal.identify.rules import NO_CANDIDATE
from robocal.model.kernels import segment_data
from robocal.model.kernels_evaluate import position_columns_transposed

__all__ = ["OK", "SINGULAR", "first_pass", "fit"]

_jit = numba.njit(cache=True, nogil=True, error_model="numpy")
# inlined into the caller by numba (see _fit_once)
_inline = numba.njit(inline="always", cache=True, nogil=True, error_model="numpy")

OK = 0  # the fit's statuses
SINGULAR = 1  # a covariance's normal matrix is nearly singular: the staged pipeline takes over
NOT_FINITE = 2  # the first Jacobian has NaN or inf (the staged rank test says so)


# A kernel called with a constant (``False``, ``3``) is compiled for that constant (numba
# types it as a literal), apart from the run-time booleans and integers the staged pipeline
# passes from Python: seconds of compilation twice over.  The kernels this module shares
# with the staged pipeline get their flags through these, typed as run-time values.
@numba.njit("boolean(boolean)", cache=True, nogil=True)
def _flag(value):
    return value


@numba.njit("intp(intp)", cache=True, nogil=True)
def _count(value):
    return value


@_inline
def _evaluate(data, values, columns):
    """Tool frames ``(n, 4, 4)``, predicted minus measured positions ``(3n,)`` and the
    unweighted Jacobian columns ``(3n, len(columns))`` of the chain at ``values``, in Fortran
    order (each column contiguous: the sums over rows below run along them)."""
    q, position, _, step_axis, step_rot, step_joint, joint_axis, joint_rot, anchor_of, joint_steps = data
    n, dof = q.shape
    seg, local = segment_data(values, step_axis, step_rot, step_joint, dof)
    offsets = np.empty(len(joint_steps))
    for j in range(len(joint_steps)):
        offsets[j] = values[joint_steps[j]]
    T, Jt = position_columns_transposed(q, seg, local, offsets, joint_axis, joint_rot, anchor_of, step_axis,
                                        step_rot, columns)  # fmt: skip
    r = np.empty(3 * n)
    for i in range(n):
        for c in range(3):
            r[3 * i + c] = T[i, c, 3] - position[i, c]
    return T, r, Jt.T


@_jit
def _weighted_transposed(r, J, weights):
    """``(1, m)`` weighted residuals and ``(1, p, m)`` weighted Jacobian, transposed: the
    layout the LM kernels' normal equations take without a copy (``transposed``)."""
    m, p = J.shape
    rw = np.empty((1, m))
    Jwt = np.empty((1, p, m))
    for i in range(m):
        rw[0, i] = r[i] * weights[i]
    for a in range(p):  # along J's columns (contiguous in its Fortran order)
        for i in range(m):
            Jwt[0, a, i] = J[i, a] * weights[i]
    return rw, Jwt


@_jit
def _squared_norms(St, row):
    """``Σ St[row[a]]²`` for each ``a``, each sum in row order (as numpy's along a Jacobian's
    rows: the staged rank test's norms, to the bit), four sums at a time: one serial sum
    waits on each addition (36 x 300 of them, ~8 us), four interleaved ones do not."""
    p, m = len(row), St.shape[1]
    norm = np.zeros(p)
    a = 0
    while a + 4 <= p:
        c0, c1, c2, c3 = St[row[a]], St[row[a + 1]], St[row[a + 2]], St[row[a + 3]]
        s0 = s1 = s2 = s3 = 0.0
        for i in range(m):
            s0 += c0[i] * c0[i]
            s1 += c1[i] * c1[i]
            s2 += c2[i] * c2[i]
            s3 += c3[i] * c3[i]
        norm[a], norm[a + 1], norm[a + 2], norm[a + 3] = s0, s1, s2, s3
        a += 4
    for b in range(a, p):
        s, column = 0.0, St[row[b]]
        for i in range(m):
            s += column[i] * column[i]
        norm[b] = s
    return norm


@_jit
def first_pass(data, values, free_steps, length_scale, preference):
    """The evaluation at the start values and the rank test's columns.

    Returns the tool frames, the unweighted residuals ``(m,)`` and Jacobian ``(m, p)``,
    the norms ``(p,)`` of the scaled Jacobian's columns (weighted, each unknown as a tool
    displacement: angles times the robot's size ``length_scale``, as
    :attr:`robocal.identify.problem.Problem.free_scale`), which of them are zero (≤ 1e-12 of the largest), the
    non-zero columns in ``preference`` order, those columns with unit norm as a
    ``(k, m)`` array (the transpose of the ``(m, k)`` matrix the test takes, in Fortran
    order) and whether the Jacobian is finite (as :func:`robocal.model.rank.identifiable_subset`).
    The QR stays with LAPACK's ``geqrf`` outside: numba's ``qr`` also forms ``Q``, which
    doubles its cost (100 µs against 50 µs for the 300 x 36 columns of a UR10)."""
    T, r, J = _evaluate(data, values, free_steps)
    weights, step_rot = data[2], data[4]
    m, p = J.shape
    free_scale = np.empty(p)
    for a in range(p):
        free_scale[a] = length_scale if step_rot[free_steps[a]] else 1.0
    # the scaled weighted columns, each contiguous, as rows in test order (``preference``
    # first, any other column after it): the sums below run along them, and the unit-norm
    # columns overwrite them in place (no second (p, m) array)
    row = np.full(p, -1, dtype=np.intp)
    for b in range(len(preference)):
        row[preference[b]] = b
    n_rows = len(preference)
    for a in range(p):
        if row[a] < 0:
            row[a] = n_rows
            n_rows += 1
    St = np.empty((p, m))
    for a in range(p):  # one contiguous row written at a time (faster than scattering along J's rows)
        target, scale = St[row[a]], free_scale[a]
        for i in range(m):
            target[i] = J[i, a] * weights[i] * scale
    norm = _squared_norms(St, row)
    largest = total = 0.0
    for a in range(p):
        total += norm[a]
        norm[a] = math.sqrt(norm[a])
        largest = max(largest, norm[a])
    # a NaN or inf anywhere makes the sum of squares one (so would squares past 1e308: the
    # staged rank test then looks at each value)
    finite = math.isfinite(total)
    zero = norm <= 1e-12 * max(largest, 1e-300)
    k = 0
    ordered = np.empty(p, dtype=np.intp)
    for b in range(len(preference)):  # row k <= b: a row is read before it is overwritten
        a = preference[b]
        if not zero[a]:
            ordered[k] = a
            source, target, n_a = St[b], St[k], norm[a]
            if k == b:  # in place (every row, unless a zero column came before): vectorised
                for i in range(m):
                    source[i] = source[i] / n_a
            else:
                for i in range(m):
                    target[i] = source[i] / n_a
            k += 1
    return T, r, J, norm, zero, ordered[:k], St[:k], finite


@_jit
def _columns_of(J, live):
    """``J[:, live]`` in Fortran order, as :func:`_evaluate`'s."""
    out = np.empty((len(live), J.shape[0]))
    for a in range(len(live)):
        out[a] = J[:, live[a]]
    return out.T


@_inline
def _point_square(J, i, a):
    """The squared length of column ``a``'s point rows ``i .. i + 2``."""
    return J[i, a] * J[i, a] + J[i + 1, a] * J[i + 1, a] + J[i + 2, a] * J[i + 2, a]


@_jit
def _displacement_scale(J):
    """:func:`robocal.identify.stages.tool_displacement_scale` of position rows ``(3n, p)``."""
    m, p = J.shape
    scale = np.zeros(p)
    a = 0
    while a + 4 <= p:  # four columns at a time (each max waits on the one before), contiguous
        s0 = s1 = s2 = s3 = 0.0
        for i in range(0, m, 3):
            s0 = max(s0, _point_square(J, i, a))
            s1 = max(s1, _point_square(J, i, a + 1))
            s2 = max(s2, _point_square(J, i, a + 2))
            s3 = max(s3, _point_square(J, i, a + 3))
        scale[a], scale[a + 1], scale[a + 2], scale[a + 3] = s0, s1, s2, s3
        a += 4
    for b in range(a, p):
        for i in range(0, m, 3):
            scale[b] = max(scale[b], _point_square(J, i, b))
    for a in range(p):
        scale[a] = math.sqrt(scale[a])
    return scale


@_jit
def _values(values0, free_steps, live, x):
    values = values0.copy()
    for a in range(len(live)):
        values[free_steps[live[a]]] = x[a]
    return values


@_jit
def _uncertainty(chi2, G, m, chi2_low, chi2_high, known_noise, singular):
    """:func:`robocal.identify.stages.uncertainty` of ``m`` position rows from their weighted
    ``Σr²`` (``chi2``) and normal matrix ``G`` ``(p, p)``: σ̂², covariance, standard
    deviations, correlations, condition number and whether the normal matrix is regular
    enough (else the staged pipeline's SVD path).  ``chi2_low``/``chi2_high`` ``[p]``: the χ²
    test's bounds for ``p`` unknowns (the rule: :func:`robocal.identify.rules.variance_factor`);
    ``singular``: :attr:`robocal.identify.rules.Rules.covariance_singular`."""
    p = G.shape[0]
    s2 = variance_factor(chi2, float(m - p), known_noise, chi2_low[p], chi2_high[p])
    cov, std, corr, cond, ok = normal_covariance(G, s2, singular)
    return s2, cov, std, corr, cond, ok


@_jit
def _without(a, k):
    out = np.empty(len(a) - 1, dtype=a.dtype)
    for i in range(len(a) - 1):
        out[i] = a[i] if i < k else a[i + 1]
    return out


@_inline
def _fit_once(data, values0, free_steps, live, x0, first, normal, settings, chi2_bounds):
    """One fit from ``x0`` over ``live`` (``first``: the evaluation at the start values, all
    free columns; ``normal``: the weighted normal equations there, ``(JᵀJ, Jᵀr, rᵀr, at)``,
    over the columns ``at`` indexes (``at[c]``: the row of free column ``c``); ``settings``:
    ``(budget, tolerance, known_noise, covariance_singular)``) and its covariance from the last
    normal matrix:
    :func:`robocal.identify.solvers.levenberg_marquardt_batch` for one problem, the
    evaluations inside, then :func:`_uncertainty`.  Returns the solution, success,
    evaluations, the RMS history, the last accepted evaluation (frames, unweighted and
    weighted residuals and Jacobian), the covariance and whether it is regular.

    Inlined (as :func:`_evaluate`): numba links the code of every compiled function a
    kernel calls into it and optimises the whole again, so each level of functions above
    the chain evaluation costs 1-2 s of first-use compilation."""
    budget, tolerance, known_noise, singular = settings
    G0, g0, rr0, at = normal
    weights = data[2]
    m, p = len(weights), len(live)
    max_evaluations = budget * (p + 1)
    columns = np.empty(p, dtype=np.intp)
    for a in range(p):
        columns[a] = free_steps[live[a]]
    x = np.empty((1, p))
    cost, G, Jr = np.full(1, rr0), np.empty((1, p, p)), np.empty((1, p))
    for a in range(p):
        x[0, a] = x0[a]
        Jr[0, a] = g0[at[live[a]]]
        for b in range(p):
            G[0, a, b] = G0[at[live[a]], at[live[b]]]
    ids = np.zeros(1, dtype=np.intp)
    history = np.empty(max_evaluations + 1)
    history[0] = math.sqrt(cost[0] / max(m, 1))
    h = 1
    D, mu, nu, x_new = np.zeros((1, p)), np.full(1, np.nan), np.full(1, 2.0), np.empty((1, p))
    evaluations, success = np.ones(1, dtype=np.intp), np.zeros(1, dtype=np.bool_)
    predicted, rms, accepted = np.empty(1), np.empty(1), np.empty((2, 1), dtype=np.intp)
    # the last accepted evaluation, with the weighted arrays its normal equations were formed
    # from (the result's: not weighted a second time)
    last = (first[0], first[1], np.empty((0, m)).T, np.empty((1, m)), np.empty((1, 0, m)))
    while True:
        n = propose(ids, _count(1), x, cost, G, Jr, D, mu, evaluations, success, tolerance, max_evaluations,
                    x_new, predicted)  # fmt: skip
        if n == 0:
            break
        T2, r2, J2 = _evaluate(data, _values(values0, free_steps, live, x_new[0]), columns)
        rw2, Jwt2 = _weighted_transposed(r2, J2, weights)
        count = accept(ids, n, x_new, rw2, Jwt2, _flag(True), x, cost, G, Jr, mu, nu, predicted, evaluations,
                       accepted, rms)  # fmt: skip
        if count:
            history[h] = rms[0]
            h += 1
            last = (T2, r2, J2, rw2, Jwt2)
    if h == 1:  # no step taken: the evaluation at the start
        J_start = _columns_of(first[2], live)
        rw0, Jwt0 = _weighted_transposed(first[1], J_start, weights)
        last = (first[0], first[1], J_start, rw0, Jwt0)
    T, r, J, rw, Jwt = last
    low, high = chi2_bounds
    s2, cov, std, corr, cond, ok = _uncertainty(cost[0], G[0], m, low, high, known_noise, singular)
    # the weighted Jacobian (m, p) as the transpose of the (p, m) rows: a view, no copy
    return (x[0].copy(), success[0], evaluations[0], history[:h].copy(), (T, r, J, rw[0], Jwt[0].T),
            (s2, cov, std, corr, cond), ok)  # fmt: skip


@_jit
def fit(data, values0, free_steps, live, first, screening, chi2_bounds, budget, tolerance):
    """Screening, the fit, its covariance and pruning (the staged pipeline's ``_screen``,
    ``_solve`` and ``_prune``) over the unknowns ``live`` (free-column indices, chain
    order) the rank test kept.

    ``first``: :func:`first_pass`'s frames, residuals and Jacobian (all free columns);
    ``screening``: the rules (:meth:`robocal.identify.rules.Rules.screening`); ``chi2_bounds``:
    the χ² test's bounds by number of unknowns (:func:`_uncertainty`); ``budget``:
    evaluations per unknown plus one (each fit may use ``budget × (p + 1)``).

    Returns the status, the screened and the pruned columns and their σ (m), the final
    unknowns, their start and fitted values, success, evaluations of the last fit and of
    all fits, its RMS history, the last evaluation (frames, unweighted residuals and
    Jacobian, weighted ones), the covariance (σ̂², covariance, σ, correlations, condition
    number) and the first Jacobian's columns of the final unknowns."""
    max_std, max_std_ratio, _, known_noise, _, covariance_singular = screening
    _, r0, J0 = first
    settings = (budget, tolerance, known_noise, covariance_singular)
    # the weighted normal equations at the start values over the rank test's columns: the
    # screening's, and every fit's start (their blocks)
    J_live = _columns_of(J0, live)
    rw0, Jwt0 = _weighted_transposed(r0, J_live, data[2])
    p = len(live)
    rr0, G0, g0 = np.empty(1), np.empty((1, p, p)), np.empty((1, p))
    start(rw0, Jwt0, _flag(True), rr0, G0, g0)  # the solver's state at the start values
    at = np.full(J0.shape[1], -1, dtype=np.intp)
    for a in range(p):
        at[live[a]] = a
    normal = (G0[0], g0[0], rr0[0], at)
    cols, sigmas = np.empty(p, dtype=np.intp), np.empty(p)
    count = screen(G0[0], g0[0], rr0[0], len(r0), _displacement_scale(J_live), screening, cols, sigmas)
    keep = np.ones(p, dtype=np.bool_)
    screened = np.empty(count, dtype=np.intp)
    for c in range(count):
        screened[c] = live[cols[c]]
        keep[cols[c]] = False
    live = live[keep]
    x0 = np.empty(len(live))
    for a in range(len(live)):
        x0[a] = values0[free_steps[live[a]]]
    # the fit, then pruning (after a converged fit: at most one unknown fewer than it had)
    # with one call site of the inlined fit: each one is compiled on first use (4 s each)
    pruned, pruned_sigma = np.empty(len(live), dtype=np.intp), np.empty(len(live))
    n_pruned, total, max_pruned = 0, 0, -1
    while True:
        fitted = _fit_once(data, values0, free_steps, live, x0, first, normal, settings, chi2_bounds)
        x, success, evaluations, history, last, cov, ok = fitted
        total += evaluations
        if max_pruned < 0:  # the first fit
            max_pruned = len(x) - 1 if success else 0
        std = cov[2]
        if n_pruned >= max_pruned or not ok or len(std) < 2:
            break
        move = std * _displacement_scale(last[2])
        worst = prune_candidate(move, max_std, max_std_ratio, 1.0)  # the rule after a fit: margin 1
        if worst == NO_CANDIDATE:
            break
        pruned[n_pruned], pruned_sigma[n_pruned] = live[worst], move[worst]
        n_pruned += 1
        live, x0 = _without(live, worst), _without(x0, worst)
    status = OK if ok else SINGULAR
    # the first Jacobian's columns of the final unknowns: the rank test's when none was
    # screened or pruned (the unknowns only ever shrink), a copy of fewer columns otherwise
    J_final = J_live if len(live) == J_live.shape[1] else _columns_of(J0, live)
    return (status, screened, sigmas[:count].copy(), pruned[:n_pruned].copy(), pruned_sigma[:n_pruned].copy(),
            live, x0, x, success, evaluations, total, history, last, cov, J_final)  # fmt: skip
