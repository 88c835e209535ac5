"""Parameter estimation methods on a calibration :class:`~robocal.identify.problem.Problem`.

=============  =========================================================================
``lm``         Levenberg-Marquardt on the analytic Jacobian (:func:`levenberg_marquardt`;
               scipy's ``least_squares(method="trf")`` when a robust loss is asked
               for), columns scaled by the Jacobian's norms, rows weighted by the
               measurement uncertainty.
``pinv``       Seed 003 eq. 3.6: the classic iterated pseudo-inverse
               ΔE = (JᵀJ)⁻¹JᵀΔP over all poses, repeated until the correction moves the
               tool by less than the measurement resolution.  ``per_pose=True``: the
               thesis' own use of eq. 3.6, ΔE = Jᵢᵀ(JᵢJᵢᵀ)⁻¹ΔPᵢ iterated at each pose,
               then the best-fit set (:mod:`robocal.identify.influence`).
``bounded``    Seed 001 eq. 4: minimise Σ_j |X_j − X'_j| (sum of distances, not of
               squares) with |δd|, |δL| ≤ 5 mm and |δθ|, |δα| ≤ 2°.  Solved by
               iteratively reweighted least squares (Weiszfeld's scheme for sums of
               distances), each round a bounded weighted least-squares problem for
               scipy's ``least_squares(method="trf")`` — trust-region reflective is the
               scipy least-squares routine that honours bounds.  (Seed 001 used MATLAB's
               fmincon on the same objective.)
``influence``  Seed 003 ch. 3 (eqs. 3.7-3.8, :mod:`robocal.identify.influence`): per
               pose an influence vector k from the thesis' test deviations (+0.05°,
               +0.1 mm), relative to the most influential parameter; per pose the
               correction ΔE = C·k∘Jᵢᵀ(JᵢJᵢᵀ)⁻¹ΔP iterated (C < 1) until the pose's error
               is below the resolution; the per-pose sets combined into one
               (``combine="mean"``, ``"best"`` or ``"fit"``); ``passes=1`` is the
               thesis' single pass, the default repeats it until the set stops moving.
=============  =========================================================================
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

from robocal.identify.solve_result import BatchSolveResult, SolveResult
from robocal.model.kernel_mode import compiled_wanted

__all__ = [
    "METHODS",
    "BatchSolveResult",
    "SolveResult",
    "levenberg_marquardt",
    "levenberg_marquardt_batch",
    "solve",
]

Array = NDArray[np.float64]


def _lm(
    problem,
    x0: Array,
    *,
    loss: str = "linear",
    f_scale: float = 1.0,
    max_iterations: int = 200,
    tolerance: float = 1e-10,
) -> SolveResult:
    if loss != "linear":  # robust losses: scipy's trust-region reflective, which supports them
        from scipy.optimize import least_squares  # on use: reading a calibration needs none of it

        res = least_squares(
            problem.residual,
            x0,
            jac=problem.jacobian,
            method="trf",
            x_scale="jac",
            loss=loss,
            f_scale=f_scale,
            ftol=1e-12,
            xtol=1e-12,
            gtol=1e-12,
            max_nfev=max_iterations,
        )
        return SolveResult(res.x, bool(res.status > 0), res.message, int(res.njev or res.nfev), int(res.nfev))
    # a nearly unidentifiable parameter (pruned afterwards) can make the first fit creep
    # along a flat valley for a few hundred steps: MINPACK's budget, 200 (p + 1) evaluations
    return levenberg_marquardt(
        problem, x0, max_iterations=max_iterations * (len(x0) + 1), tolerance=tolerance
    )


def levenberg_marquardt(
    problem, x0: Array, *, max_iterations: int = 200, tolerance: float = 1e-10
) -> SolveResult:
    """Levenberg-Marquardt on one problem: :func:`levenberg_marquardt_batch` with a batch of one.

    ``problem`` gives weighted residuals ``problem.residual(x)`` ``(m,)`` and their
    Jacobian ``problem.jacobian(x)`` ``(m, p)``; ``max_iterations`` counts evaluations."""

    def evaluate(x: Array, _which: NDArray[np.intp]) -> tuple[Array, Array]:
        return problem.residual(x[0])[None], problem.jacobian(x[0])[None]

    fit = levenberg_marquardt_batch(
        evaluate, np.asarray(x0, dtype=float)[None], max_evaluations=max_iterations, tolerance=tolerance
    )
    return fit.result(0)


def levenberg_marquardt_batch(
    evaluate: Callable[[Array, NDArray[np.intp]], tuple[Array, Array]],
    x0: Array,
    *,
    max_evaluations: int = 200,
    tolerance: float = 1e-10,
) -> BatchSolveResult:
    """Levenberg-Marquardt with Moré's column scaling and Nielsen's damping update, for
    ``K`` independent problems at once (one problem: :func:`levenberg_marquardt`).

    Written here rather than calling MINPACK (scipy's ``method="lm"``) because a
    calibration's residuals and Jacobian come out of one kinematic pass: evaluating them
    together at every trial point, and stopping as soon as the *predicted* gain of the
    next step is negligible (without evaluating that step), takes about half the passes
    MINPACK's separate function and Jacobian calls need (``benchmarks/bench_calibrate.py``);
    and because a study evaluates many robots' residuals in one batched pass.

    Each iteration solves ``(J_sᵀJ_s + μI) δ_s = −J_sᵀ r`` with ``J_s = J D⁻¹`` (``D``:
    the largest column norms met so far, MINPACK's scaling) by Cholesky; ``μ`` starts at
    ``1e-6`` times the largest diagonal (Nielsen's choice for a good start: a calibration
    starts from the nominal model) and follows the gain ratio ``ρ`` (actual over
    predicted decrease): ``μ ← μ·max(1/3, 1 − (2ρ − 1)³)`` on success, ``μ ← μ·ν,
    ν ← 2ν`` on failure (Nielsen 1999, "Damping parameter in Marquardt's method",
    IMM-REP-1999-05).  Every problem follows its own steps and damping; only the
    evaluations are shared.

    A problem stops when the predicted decrease of its next step is below ``tolerance``
    times its cost, or the step is below ``tolerance`` relative to the scaled
    parameters, or after ``max_evaluations`` evaluations; unconverged also when no damping
    makes its normal matrix positive definite (NaN or inf in its Jacobian).

    Compiled (:mod:`robocal.identify.kernels.lm`): an iteration is one kernel call before
    the evaluation (scaling, normal equations, damped Cholesky step, stop tests) and one
    after it (gain ratio, acceptance, damping).  It agrees with the numpy iteration
    (``tests/reference_lm.py``, the tests' reference) to round-off; ``JᵀJ`` is formed
    before the scaling, so Jacobian entries must stay within about 1e±150.

    Args:
        evaluate: ``evaluate(x, which)`` → weighted residuals ``(k, m)`` and Jacobians
            ``(k, m, p)`` of problems ``which`` ``(k,)`` (indices into the batch) at
            ``x`` ``(k, p)``.  The arrays it returns are kept (not copied) for the result:
            it must not write into them afterwards.
        x0: ``(K, p)`` start values.
    """
    if not compiled_wanted():  # numba's cache cold: the same iteration in numpy
        return _numpy_batch(evaluate, x0, max_evaluations, tolerance)
    import robocal.identify.kernels.lm as kernels  # numba: imported on first use

    x = np.array(x0, dtype=float)
    K, p = x.shape
    ids = np.arange(K)  # the problems still running are ids[:n] (batch order); state at batch indices
    r, J = evaluate(x, ids)
    r, J, Jc, transposed = _packed(r, J)
    m = max(r.shape[1], 1)
    cost, G, Jr = np.empty(K), np.empty((K, p, p)), np.empty((K, p))  # Σ r², JᵀJ, Jᵀr at x
    kernels.start(r, Jc, transposed, cost, G, Jr)
    histories = [[math.sqrt(c / m)] for c in cost.tolist()]
    last = [(r, J, k) for k in range(K)]  # each problem's evaluation at x: (r, J, row)
    D, mu, nu, x_new = np.zeros((K, p)), np.full(K, np.nan), np.full(K, 2.0), np.empty((K, p))
    evaluations, success, predicted, rms = np.ones(K, np.intp), np.zeros(K, bool), np.empty(K), np.empty(K)
    accepted = np.empty((2, K), dtype=np.intp)  # the accepted problems' (batch index, row)
    tolerance, max_evaluations = float(tolerance), int(max_evaluations)
    n = K
    while True:
        n = kernels.propose(ids, n, x, cost, G, Jr, D, mu, evaluations, success, tolerance, max_evaluations,
                            x_new, predicted)  # fmt: skip
        if not n:
            break
        r, J = evaluate(x_new[:n], ids[:n].copy())
        r, J, Jc, transposed = _packed(r, J)
        count = kernels.accept(ids, n, x_new, r, Jc, transposed, x, cost, G, Jr, mu, nu, predicted,
                               evaluations, accepted, rms)  # fmt: skip
        for k, i, value in zip(*accepted[:, :count].tolist(), rms[:count].tolist(), strict=True):
            histories[k].append(value)
            last[k] = (r, J, i)
    r, J = _gathered(last, r, J)
    iterations = np.array([len(h) for h in histories], dtype=np.intp)
    return BatchSolveResult(x, r, J, success, iterations, evaluations, max_evaluations, histories)


def _numpy_batch(
    evaluate: Callable[[Array, NDArray[np.intp]], tuple[Array, Array]],
    x0: Array,
    max_evaluations: int,
    tolerance: float,
) -> BatchSolveResult:
    """:func:`levenberg_marquardt_batch` by its numpy path (the process computes with numpy:
    :mod:`robocal.model.kernel_mode`)."""
    from robocal.identify.kernels.numpy_lm import levenberg_marquardt_batch_numpy

    return levenberg_marquardt_batch_numpy(evaluate, x0, max_evaluations=max_evaluations, tolerance=tolerance)


def _packed(r, J) -> tuple[Array, Array, Array, bool]:
    """Residuals ``(n, m)`` and Jacobians ``(n, m, p)`` as float64, and the Jacobians as the
    kernels take them: C-ordered ``(n, m, p)``, or ``(n, p, m)`` (``True``: each transposed,
    the Fortran order numpy's column stacks and the chain's Jacobians come in)."""
    r, J = np.ascontiguousarray(r, dtype=np.float64), np.asarray(J, dtype=np.float64)
    if J.flags.c_contiguous:
        return r, J, J, False
    Jt = J.transpose(0, 2, 1)
    if Jt.flags.c_contiguous:
        return r, J, Jt, True
    return r, J, np.ascontiguousarray(J), False


def _gathered(last: list[tuple[Array, Array, int]], r: Array, J: Array) -> tuple[Array, Array]:
    """``(K, m)`` residuals and ``(K, m, p)`` Jacobians from each problem's ``(r, J, row)``
    (one problem's first rows: no copy; no problems: ``r``, ``J``)."""
    if not last:
        return r, J
    if len(last) == 1 and last[0][2] == 0 and len(last[0][0]) == 1:
        return last[0][0], last[0][1]
    return np.stack([r[i] for r, _, i in last]), np.stack([J[i] for _, J, i in last])


def _pinv(problem, x0: Array, *, resolution: float = 1e-5, max_iterations: int = 100) -> SolveResult:
    """Seed 003 eq. 3.6, iterated: Gauss-Newton with the pseudo-inverse of J."""
    x = x0.copy()
    history = []
    move_scale = problem.free_scale  # a correction as a tool displacement
    for it in range(1, max_iterations + 1):
        r = problem.residual(x)
        J = problem.jacobian(x)
        history.append(float(np.sqrt(np.mean(r * r))))
        norms = np.linalg.norm(J, axis=0)
        norms[norms == 0] = 1.0
        dx = -np.linalg.lstsq(J / norms, r, rcond=None)[0] / norms  # = -(JᵀJ)⁻¹Jᵀ r
        x = x + dx
        if np.max(np.abs(dx) * move_scale) < resolution:
            return SolveResult(x, True, f"correction below the resolution {resolution * 1e3:g} mm", it, it)
    return SolveResult(
        x, False, f"no convergence in {max_iterations} iterations", max_iterations, max_iterations
    )


def _bounded(
    problem,
    x0: Array,
    *,
    bounds: tuple[Array, Array] | None = None,
    tolerance: float = 1e-7,
    max_iterations: int = 500,
    max_rounds: int = 200,
) -> SolveResult:
    """Seed 001 eq. 4: min Σ_j |e_j| (sum of the poses' error distances) under bounds.

    Iteratively reweighted least squares (Weiszfeld's scheme for sums of distances): each
    round solves the bounded weighted least-squares problem Σ_j |e_j|² / d_j, with d_j the
    distances of the previous round, by scipy's trust-region reflective ``least_squares``;
    a majorise-minimise iteration, so Σ_j |e_j| decreases every round.  It starts from the
    bounded least-squares solution and stops when the sum changes by less than
    ``tolerance`` (relative).  The result is clipped to the bounds (never beyond them).

    Its objective is not the RMS error: when a minority of poses carries an error the
    model cannot describe (a backlash that reverses along the measured path), the
    minimum fits the majority and leaves the minority with the whole error, and the RMS
    error can end above the start's (the divergence guard checks the sum of distances).
    """
    lo, hi = bounds if bounds is not None else (np.full_like(x0, -np.inf), np.full_like(x0, np.inf))
    width = problem.rows

    def distances(x):
        return np.linalg.norm(problem.residual(x).reshape(-1, width), axis=1)

    def weighted_fit(x, w):
        from scipy.optimize import least_squares

        def fun(z):
            return (problem.residual(z).reshape(-1, width) * w[:, None]).reshape(-1)

        def jac(z):
            return problem.jacobian(z) * np.repeat(w, width)[:, None]

        return least_squares(
            fun,
            x,
            jac=jac,
            bounds=(lo, hi),
            method="trf",
            x_scale="jac",
            ftol=1e-10,
            xtol=1e-10,
            gtol=1e-10,
            max_nfev=max_iterations,
        )

    fit = weighted_fit(np.clip(x0, lo, hi), np.ones(len(problem.q)))  # bounded least squares
    x, evaluations = fit.x, int(fit.nfev)
    d = distances(x)
    floor = 1e-9 * max(float(np.median(d)), 1e-300)  # a zero distance would get infinite weight
    total = float(d.sum())
    for rounds in range(1, max_rounds + 1):
        fit = weighted_fit(x, 1.0 / np.sqrt(np.maximum(d, floor)))
        evaluations += int(fit.nfev)
        d_new = distances(fit.x)
        new_total = float(d_new.sum())
        if new_total <= total:  # Weiszfeld never increases the sum; guard against round-off
            x, d = fit.x, d_new
        if abs(total - new_total) <= tolerance * total:
            message = f"sum of distances converged ({rounds} reweighting rounds)"
            return SolveResult(np.clip(x, lo, hi), True, message, rounds, evaluations)
        total = min(total, new_total)
    message = f"sum of distances still changing after {max_rounds} rounds"
    return SolveResult(np.clip(x, lo, hi), False, message, max_rounds, evaluations)


def _pinv_or_per_pose(problem, x0: Array, *, per_pose: bool = False, **options) -> SolveResult:
    if per_pose:  # seed 003 eq. 3.6 as the thesis applies it: per pose, then the best-fit set
        from robocal.identify.influence import solve_per_pose

        return solve_per_pose(problem, x0, influence=False, **options)
    return _pinv(problem, x0, **options)


def _influence(problem, x0: Array, *, per_pose: bool = True, **options) -> SolveResult:
    """Seed 003 ch. 3 (:mod:`robocal.identify.influence`; always per pose)."""
    from robocal.identify.influence import solve_per_pose

    return solve_per_pose(problem, x0, influence=True, **options)


METHODS: dict[str, Callable[..., SolveResult]] = {
    "lm": _lm,
    "pinv": _pinv_or_per_pose,
    "bounded": _bounded,
    "influence": _influence,
}


def solve(problem, x0: Array, method: str = "lm", **options) -> SolveResult:
    """Run ``method`` on ``problem`` from ``x0`` (the free parameter values).

    Raises:
        ValueError: an unknown method.
        TypeError: an option the method does not take (named; not silently dropped).
    """
    if method not in METHODS:
        raise ValueError(f"unknown method {method!r}; choose one of {', '.join(METHODS)}")
    return METHODS[method](problem, np.asarray(x0, dtype=float), **options)
