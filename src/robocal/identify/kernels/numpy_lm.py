"""The numpy path of :func:`robocal.identify.solvers.levenberg_marquardt_batch`: the same
Levenberg-Marquardt iteration, one numpy call per operation on the stack of running problems
(the problems that stop are compacted out).  Used while numba's cache is cold
(:mod:`robocal.model.kernel_mode`), and the reference the compiled kernels
(:mod:`robocal.identify.kernels.lm`) are tested against (``tests/test_lm_kernels.py``) and
timed against (``benchmarks/bench_lm.py``).  For the small matrices of a calibration
(hundreds of rows, tens of columns) the calls' overhead, not their arithmetic, sets the time.
No numba here.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

from robocal.identify.solve_result import BatchSolveResult

__all__ = ["damped_steps", "levenberg_marquardt_batch_numpy"]

Array = NDArray[np.float64]


def levenberg_marquardt_batch_numpy(
    evaluate: Callable[[Array, NDArray[np.intp]], tuple[Array, Array]],
    x0: Array,
    *,
    max_evaluations: int = 200,
    tolerance: float = 1e-10,
) -> BatchSolveResult:
    """:func:`~robocal.identify.solvers.levenberg_marquardt_batch` in numpy (the same
    iteration and arguments, one numpy call per operation on the batch)."""
    x = np.array(x0, dtype=float)
    K = len(x)
    ids = np.arange(K)  # the problems still running; their state below, compacted as they stop
    r, J = evaluate(x, ids)
    r, J = np.array(r, dtype=float), np.array(J, dtype=float)
    m = max(r.shape[1], 1)
    cost = _squares(r)
    histories = [[math.sqrt(c / m)] for c in cost.tolist()]
    D = _column_norms(J)
    D[D == 0] = 1.0
    mu = np.full(K, np.nan)
    nu = np.full(K, 2.0)
    evaluations = np.ones(K, dtype=np.intp)
    done = BatchSolveResult(x.copy(), r.copy(), J.copy(), np.zeros(K, dtype=bool), np.zeros(K, dtype=np.intp),
                            np.zeros(K, dtype=np.intp), max_evaluations, histories)  # fmt: skip
    while len(ids):
        D = np.maximum(D, _column_norms(J))
        A, g = _scaled_normal_equations(J, r, D)
        _start_damping(mu, A)
        step, mu = damped_steps(A, g, mu)
        predicted = -np.sum(step * (2.0 * g + (A @ step[:, :, None])[..., 0]), axis=1)
        small_step = _norms(step) <= tolerance * (_norms(D * x) + tolerance)
        converged = (predicted <= tolerance * cost) | small_step | (cost == 0.0)
        stop = converged | (evaluations >= max_evaluations)
        if stop.any():  # record the stopped ones, keep the others
            _record(done, ids, stop, x, r, J, converged, evaluations)
            going = ~stop
            ids, x, r, J, cost, D, mu, nu, evaluations, step, predicted = (
                a[going] for a in (ids, x, r, J, cost, D, mu, nu, evaluations, step, predicted)
            )
            if not len(ids):
                break
        x_new = x + step / D
        r_new, J_new = evaluate(x_new, ids)
        evaluations = evaluations + 1
        cost_new = _squares(r_new)
        rho = (cost - cost_new) / predicted
        better = rho > 0
        x, r, J, cost = _accepted(better, (x, r, J, cost), (x_new, r_new, J_new, cost_new))
        mu, nu = _nielsen_damping(better, rho, mu, nu)
        for k, c in zip(ids[better].tolist(), cost_new[better].tolist(), strict=True):
            histories[k].append(math.sqrt(c / m))
    done.iterations[:] = [len(h) for h in histories]
    return done


def _scaled_normal_equations(J: Array, r: Array, D: Array) -> tuple[Array, Array]:
    """``A = J_sᵀJ_s`` ``(k, p, p)`` and ``g = J_sᵀ r`` ``(k, p)`` with ``J_s = J D⁻¹`` for the
    Jacobians ``J`` ``(k, m, p)``, residuals ``r`` ``(k, m)`` and column scales ``D`` ``(k, p)``."""
    Js = J / D[:, None, :]
    JsT = Js.transpose(0, 2, 1)
    return JsT @ Js, (JsT @ r[:, :, None])[..., 0]


def _start_damping(mu: Array, A: Array) -> None:
    """In place: ``μ`` of the problems without one yet (NaN) is ``1e-6`` times the largest
    diagonal of their ``A`` (Nielsen's choice for a good start)."""
    fresh = np.isnan(mu)
    if fresh.any():
        mu[fresh] = 1e-6 * np.max(np.diagonal(A[fresh], axis1=1, axis2=2), axis=1)


def _record(
    done: BatchSolveResult,
    ids: NDArray[np.intp],
    stop: NDArray[np.bool_],
    x: Array,
    r: Array,
    J: Array,
    converged: NDArray[np.bool_],
    evaluations: NDArray[np.intp],
) -> None:
    """Write the state of the problems that ``stop`` into ``done`` (at their batch indices)."""
    f, k = np.flatnonzero(stop), ids[stop]
    done.x[k], done.r[k], done.J[k] = x[f], r[f], J[f]
    done.success[k], done.evaluations[k] = converged[f], evaluations[f]


def _accepted(
    better: NDArray[np.bool_], old: tuple[Array, Array, Array, Array], new: tuple[Array, Array, Array, Array]
) -> tuple[Array, Array, Array, Array]:
    """``(x, r, J, cost)``: the trial point's where its step was ``better``, else the old."""
    if better.all():
        return new
    x, r, J, cost = old
    x_new, r_new, J_new, cost_new = new
    return (
        np.where(better[:, None], x_new, x),
        np.where(better[:, None], r_new, r),
        np.where(better[:, None, None], J_new, J),
        np.where(better, cost_new, cost),
    )


def _nielsen_damping(better: NDArray[np.bool_], rho: Array, mu: Array, nu: Array) -> tuple[Array, Array]:
    """Nielsen's update of ``(μ, ν)``: ``μ·max(1/3, 1 − (2ρ − 1)³)`` and ``ν = 2`` after an
    accepted step, ``μ·ν`` and ``2ν`` after a refused one."""
    if better.all():
        return mu * np.maximum(1.0 / 3.0, 1.0 - (2.0 * rho - 1.0) ** 3), np.full_like(nu, 2.0)
    with np.errstate(over="ignore", invalid="ignore"):  # the unused branch of a refused step
        mu = np.where(better, mu * np.maximum(1.0 / 3.0, 1.0 - (2.0 * rho - 1.0) ** 3), mu * nu)
    return mu, np.where(better, 2.0, nu * 2.0)


def _squares(r: Array) -> Array:
    """``(k,)`` sums of squares of the rows of ``r`` ``(k, m)``."""
    return np.einsum("km,km->k", r, r)


def _norms(v: Array) -> Array:
    """``(k,)`` Euclidean norms of the rows of ``v`` ``(k, p)``."""
    return np.sqrt(np.einsum("kp,kp->k", v, v))


def _column_norms(J: Array) -> Array:
    """``(k, p)`` Euclidean norms of the columns of a stack of matrices ``J`` ``(k, m, p)``."""
    return np.sqrt(np.einsum("kmp,kmp->kp", J, J))


def damped_steps(A: Array, g: Array, mu: Array) -> tuple[Array, Array]:
    """Steps ``δ = −(A + μI)⁻¹ g`` for a stack of normal matrices ``A`` ``(k, p, p)``,
    raising ``μ`` ``(k,)`` tenfold (at least to 1e-12) where ``A + μI`` is not positive
    definite (its Cholesky factorisation fails)."""
    eye = np.eye(A.shape[-1])
    mu = mu.copy()
    damped = A + mu[:, None, None] * eye
    try:
        np.linalg.cholesky(damped)
    except np.linalg.LinAlgError:  # some are not positive definite: one at a time (rare)
        for i in range(len(A)):
            while True:
                try:
                    np.linalg.cholesky(damped[i])
                    break
                except np.linalg.LinAlgError:
                    mu[i] = max(mu[i] * 10.0, 1e-12)
                    damped[i] = A[i] + mu[i] * eye
    # numpy has no batched triangular solve: one batched LU solve of the positive definite
    # matrices (as accurate here, and cheaper than two general solves with the factor)
    return np.asarray(np.linalg.solve(damped, -g[..., None])[..., 0], dtype=np.float64), mu
