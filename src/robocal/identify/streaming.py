"""Calibration at scale: Levenberg-Marquardt on normal equations accumulated over chunks of
poses, so that memory is O(p² + chunk) instead of O(n·p) — a million poses in well under a
gigabyte (``benchmarks/bench_streaming.py``).

The dense solver (:func:`robocal.identify.solvers.levenberg_marquardt`) only ever uses the
Jacobian through ``JᵀJ``, ``Jᵀr`` and ``rᵀr`` (its column scaling is the square root of
``diag(JᵀJ)``), so the same iteration runs on those sums: :func:`levenberg_marquardt_streaming`
is that solver step for step (same scaling, damping updates and stopping rules; the tests hold
the two to each other), with each pass over the poses one chunk at a time.  A trial point costs
a residual pass (forward kinematics only); the normal equations are accumulated at accepted
points, as the dense solver computes the Jacobian there.

:func:`refit` is the large-data path of a calibration: the structure of the fit (which
parameters are identifiable, the device frame, the tool, the start values) comes from an
ordinary :func:`robocal.calibrate` on a subsample, and the refit estimates the same parameters
from all poses, with their covariance from the accumulated ``JᵀJ``.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import Protocol

import numpy as np
import scipy.linalg
from numpy.typing import ArrayLike, NDArray

from robocal.identify.problem import Problem
from robocal.identify.rules import Rules, condition_number
from robocal.identify.solve_result import SolveResult
from robocal.identify.stages import Covariance, residual_variance
from robocal.model.chain import Model

__all__ = [
    "DEFAULT_CHUNK",
    "ChunkedProblem",
    "NormalEquations",
    "StreamingFit",
    "levenberg_marquardt_streaming",
    "refit",
    "streamed_covariance",
]

Array = NDArray[np.float64]

#: poses per chunk: a position chunk's Jacobian is 3 · chunk · p doubles (about 20 MB at p = 40)
DEFAULT_CHUNK = 20_000


@dataclass(frozen=True)
class NormalEquations:
    """Sums over all poses of a weighted position fit at one parameter point.

    Attributes:
        JtJ: ``(p, p)`` ``Jᵀ J`` of the weighted residuals' Jacobian (columns: the chain's
            free parameters, SI units).
        Jtr: ``(p,)`` ``Jᵀ r``.
        cost: ``rᵀ r`` (weighted residuals; m² for unit weights).
        rows: number of residuals (3 per pose).
        position_normal, position_cost, position_rows: the same sums over the position rows
            alone (pose measurements: the orientation rows are the rest; None: every row
            is a position row).
    """

    JtJ: Array
    Jtr: Array
    cost: float
    rows: int
    position_normal: Array | None = None
    position_cost: float | None = None
    position_rows: int | None = None


class StreamedSums(Protocol):
    """What :func:`levenberg_marquardt_streaming` evaluates: the weighted cost and the
    normal equations at a parameter point, one pass over the poses each."""

    def cost(self, x: Array) -> float: ...

    def normal_equations(self, x: Array) -> NormalEquations: ...


class _PositionData:
    """Joint values, measured positions (m, device frame) and weights (1/σ, per row) of a
    position calibration, evaluated one chunk of poses at a time."""

    def __init__(self, chain: Model, q: Array, position: Array, weights: Array, chunk: int) -> None:
        self.chain, self.q, self.position, self.weights, self.chunk = chain, q, position, weights, chunk
        self.free = chain.free_mask

    def _values(self, x: Array) -> Array:
        v = self.chain.values.copy()
        v[self.free] = x
        return v

    def _chunks(self) -> Iterator[slice]:
        for lo in range(0, len(self.q), self.chunk):
            yield slice(lo, min(lo + self.chunk, len(self.q)))

    def cost(self, x: Array) -> float:
        """``rᵀ r`` at ``x`` (forward kinematics only)."""
        values, total = self._values(x), 0.0
        for s in self._chunks():
            T, _ = self.chain.evaluate(self.q[s], values, jacobian=False)
            r = (T[:, :3, 3] - self.position[s]) * self.weights[s]
            total += float(np.einsum("ij,ij->", r, r))
        return total

    def normal_equations(self, x: Array) -> NormalEquations:
        """:class:`NormalEquations` at ``x``, one chunk's Jacobian in memory at a time."""
        values = self._values(x)
        p = int(self.free.sum())
        JtJ, Jtr, total = np.zeros((p, p)), np.zeros(p), 0.0
        for s in self._chunks():
            T, J = self.chain.evaluate(self.q[s], values)
            w = self.weights[s].reshape(-1)
            r = (T[:, :3, 3] - self.position[s]).reshape(-1) * w
            J *= w[:, None]
            JtJ += J.T @ J
            Jtr += J.T @ r
            total += float(r @ r)
        return NormalEquations(JtJ, Jtr, total, 3 * len(self.q))


def levenberg_marquardt_streaming(
    data: StreamedSums,
    x0: Array,
    *,
    max_iterations: int = 200,
    tolerance: float = 1e-10,
    progress: Callable[[int, float], None] | None = None,
) -> tuple[SolveResult, NormalEquations]:
    """:func:`~robocal.identify.solvers.levenberg_marquardt` on accumulated normal equations.

    With ``N = JᵀJ`` and ``D`` the largest column norms met so far (``√diag N``), the scaled
    system of the dense solver is ``A = N / (D Dᵀ)``, ``g = Jᵀr / D``; the step, the
    predicted decrease, Nielsen's damping update and the stopping rules are the dense
    solver's.  Returns the solver's result and the normal equations at the solution.
    ``progress(evaluations, rms)``, when given, is called after each pass over the data
    (each costs seconds at a million poses) with the passes so far and the RMS of the
    weighted residuals at the best point so far (m for unit weights); it changes nothing.
    """
    x = np.array(x0, dtype=float)
    ne = data.normal_equations(x)
    cost = ne.cost
    history = [math.sqrt(cost / max(ne.rows, 1))]
    D = np.sqrt(np.diag(ne.JtJ)).copy()
    D[D == 0] = 1.0
    mu, nu = None, 2.0
    evaluations = 1
    eye = np.eye(len(x))
    while True:
        D = np.maximum(D, np.sqrt(np.diag(ne.JtJ)))
        A = ne.JtJ / np.outer(D, D)
        g = ne.Jtr / D
        if mu is None:
            mu = 1e-6 * float(np.max(np.diag(A)))
        while True:
            try:
                step = -scipy.linalg.cho_solve(scipy.linalg.cho_factor(A + mu * eye), g)
                break
            except np.linalg.LinAlgError:
                mu = max(mu * 10.0, 1e-12)
        predicted = -float(step @ (2.0 * g + A @ step))
        small_step = np.linalg.norm(step) <= tolerance * (np.linalg.norm(D * x) + tolerance)
        if predicted <= tolerance * cost or small_step or cost == 0.0:
            message = "converged: the next step would not improve the fit"
            return SolveResult(x, True, message, len(history), evaluations, history), ne
        if evaluations >= max_iterations:
            message = f"no convergence in {max_iterations} evaluations"
            return SolveResult(x, False, message, len(history), evaluations, history), ne
        x_new = x + step / D
        cost_new = data.cost(x_new)
        evaluations += 1
        rho = (cost - cost_new) / predicted
        if rho > 0:
            x, ne = x_new, data.normal_equations(x_new)
            cost = ne.cost
            history.append(math.sqrt(cost / max(ne.rows, 1)))
            mu *= max(1.0 / 3.0, 1.0 - (2.0 * rho - 1.0) ** 3)
            nu = 2.0
        else:
            mu *= nu
            nu *= 2.0
        if progress is not None:
            progress(evaluations, history[-1])


@dataclass(frozen=True)
class StreamingFit:
    """The parameters of a calibration estimated from all poses by :func:`refit`.

    Attributes:
        chain: the measurement chain at the estimates (device frame, robot, tool).
        names: the estimated parameters (those of the subsample's calibration).
        estimates, start, std: their values (SI), start values (the subsample's estimates)
            and standard deviations (from ``σ̂² (JᵀJ)⁻¹``).
        covariance: ``(p, p)``.
        residual_std: σ̂ of the weighted residuals (m for unit weights).
        rms_after: RMS position error (m) over all poses at the estimates.
        n: poses used; chunk: poses per chunk.
        success, message, iterations, evaluations: the solver's record.
        seconds: wall time of the refit.
    """

    chain: Model
    names: tuple[str, ...]
    estimates: Array
    start: Array
    std: Array
    covariance: Array
    residual_std: float
    rms_after: float
    n: int
    chunk: int
    success: bool
    message: str
    iterations: int
    evaluations: int
    seconds: float


def refit(
    calibration,
    q: ArrayLike,
    position: ArrayLike,
    sigma: ArrayLike | None = None,
    *,
    chunk: int = DEFAULT_CHUNK,
    max_iterations: int = 200,
    tolerance: float = 1e-10,
) -> StreamingFit:
    """Estimate a calibration's parameters again from (many) more poses, streaming.

    Args:
        calibration: a :class:`~robocal.identify.calibrate.CalibrationResult` of a position
            calibration without joint effects or learned residual (typically on a
            subsample of ``q``): its measurement chain, its estimated parameters and their
            values as the start.
        q: ``(n, dof)`` joint values (rad, m).
        position: ``(n, 3)`` measured positions (m, device frame).
        sigma: ``(n, 3)`` position standard deviations (m), weights ``1/σ``; default unit
            weights.
        chunk: poses per chunk (memory: about ``3 · chunk · p`` doubles for the Jacobian).

    Raises:
        ValueError: for a pose calibration, joint-effect or residual parameters, or shapes
            that do not fit.
    """
    t0 = time.perf_counter()
    chain = calibration.measurement_chain
    if chain is None or calibration.measure != "position":
        raise ValueError("refit needs a position calibration with its measurement chain")
    if tuple(chain.free_names) != tuple(calibration.names) or calibration.model.residual is not None:
        raise ValueError(
            "refit estimates geometric parameters only: this calibration has joint-effect or residual "
            f"parameters ({', '.join(n for n in calibration.names if n not in set(chain.free_names))})"
        )
    q = np.ascontiguousarray(q, dtype=float)
    position = np.asarray(position, dtype=float)
    if q.ndim != 2 or q.shape[1] != chain.dof or position.shape != (len(q), 3):
        raise ValueError(
            f"q shaped {q.shape} and position {position.shape}: expected (n, {chain.dof}) and (n, 3)"
        )
    if chunk < 1:
        raise ValueError(f"chunk must be a positive number of poses, got {chunk}")
    weights = (
        np.ones((len(q), 3)) if sigma is None else 1.0 / np.maximum(np.asarray(sigma, dtype=float), 1e-12)
    )
    if weights.shape != (len(q), 3):
        raise ValueError(f"sigma shaped {weights.shape}; expected ({len(q)}, 3)")
    data = _PositionData(chain, q, position, weights, int(chunk))
    x0 = chain.free_values
    result, ne = levenberg_marquardt_streaming(data, x0, max_iterations=max_iterations, tolerance=tolerance)
    x = result.x
    dof_resid = max(ne.rows - len(x), 1)
    s2 = ne.cost / dof_resid
    covariance = np.asarray(s2 * np.linalg.pinv(ne.JtJ), dtype=float)
    fitted = chain.with_free_values(x)
    unweighted = (
        ne.cost if sigma is None else _PositionData(chain, q, position, np.ones((len(q), 3)), chunk).cost(x)
    )
    return StreamingFit(
        chain=fitted,
        names=tuple(chain.free_names),
        estimates=x,
        start=x0,
        std=np.sqrt(np.maximum(np.diag(covariance), 0.0)),
        covariance=covariance,
        residual_std=math.sqrt(s2),
        rms_after=math.sqrt(unweighted / len(q)),
        n=len(q),
        chunk=int(chunk),
        success=result.success,
        message=result.message,
        iterations=result.iterations,
        evaluations=result.evaluations,
        seconds=time.perf_counter() - t0,
    )


class ChunkedProblem:
    """A calibration :class:`~robocal.identify.problem.Problem` over ``n`` poses, built and
    evaluated one chunk of poses at a time (``problem_of(slice)`` builds a chunk's problem:
    its joint values, measurements, weights, joint-effect patterns and known
    perturbations; all chunks share the unknowns ``x``).  Memory: one chunk's Jacobian
    ``(rows · chunk, p)``; the sums are ``(p, p)``.

    A trial point's cost is the pass that also gives its normal equations (a pass with
    the Jacobian costs little more than forward kinematics, and an accepted trial needs
    them): the last pass is kept for the solver's next question.  With ``keep_residuals``
    the last pass's unweighted residuals ``(n, rows)`` are kept too (:meth:`residuals_at`:
    the fit's residuals per pose without another pass over the poses)."""

    def __init__(
        self,
        problem_of: Callable[[slice], Problem],
        n: int,
        chunk: int = DEFAULT_CHUNK,
        keep_residuals: bool = False,
    ) -> None:
        if chunk < 1:
            raise ValueError(f"chunk must be a positive number of poses, got {chunk}")
        self.problem_of, self.n, self.chunk = problem_of, int(n), int(chunk)
        self.passes = 0
        self._last: tuple[bytes, NormalEquations] | None = None
        self._keep_residuals = keep_residuals
        self._residuals: Array | None = None  # the last pass's, (n, rows), at self._last's x

    def chunks(self) -> Iterator[slice]:
        """The slices of poses, in order."""
        for lo in range(0, self.n, self.chunk):
            yield slice(lo, min(lo + self.chunk, self.n))

    def cost(self, x: Array) -> float:
        """``rᵀ r`` of the weighted residuals at ``x``."""
        return self.normal_equations(x).cost

    def residuals_at(self, x: Array) -> Array | None:
        """``(n, rows)`` predicted minus measured (m, rad; unweighted) at ``x`` when the last
        pass was at ``x`` and kept them (``keep_residuals``), else None."""
        last = self._last
        if self._residuals is None or last is None or last[0] != np.asarray(x, dtype=float).tobytes():
            return None
        return self._residuals

    def normal_equations(self, x: Array) -> NormalEquations:
        """:class:`NormalEquations` at ``x`` (the position rows' sums too)."""
        x = np.asarray(x, dtype=float)
        key = x.tobytes()
        if self._last is not None and self._last[0] == key:
            return self._last[1]
        self.passes += 1
        self._last = None  # until this pass is complete
        p = len(x)
        JtJ, Jtr, normal_p = np.zeros((p, p)), np.zeros(p), np.zeros((p, p))
        cost = cost_p = 0.0
        rows = rows_p = 0
        for s in self.chunks():
            problem = self.problem_of(s)
            r, J = problem.residual(x), problem.jacobian(x)
            if self._keep_residuals:
                self._keep(s, problem.residual(x, weighted=False).reshape(s.stop - s.start, -1))
            JtJ += J.T @ J
            Jtr += J.T @ r
            cost += float(r @ r)
            rows += len(r)
            if problem.rows == 6:  # the position rows apart: their own variance factor
                keep = np.tile(np.arange(6) < 3, len(r) // 6)
                Jp, rp = J[keep], r[keep]
                normal_p += Jp.T @ Jp
                cost_p += float(rp @ rp)
                rows_p += len(rp)
        if rows_p == 0:
            ne = NormalEquations(JtJ, Jtr, cost, rows)
        else:
            ne = NormalEquations(JtJ, Jtr, cost, rows, normal_p, cost_p, rows_p)
        self._last = (key, ne)
        return ne

    def _keep(self, s: slice, residuals: Array) -> None:
        if self._residuals is None or self._residuals.shape[1] != residuals.shape[1]:
            self._residuals = np.empty((self.n, residuals.shape[1]))
        self._residuals[s] = residuals


def streamed_covariance(ne: NormalEquations, known_noise: bool, rules: Rules) -> Covariance:
    """The :class:`~robocal.identify.stages.Covariance` of a fit from its accumulated normal
    equations: the rule of :func:`robocal.identify.stages.uncertainty` (σ̂² per row group
    by :func:`~robocal.identify.stages.residual_variance` at ``rules.significance``; pose
    measurements: the sandwich of the two groups), on ``JᵀJ`` instead of ``J``.  Columns
    scaled to unit norm before the (pseudo-)inverse; the condition number is
    :func:`robocal.identify.rules.condition_number` of the scaled ``JᵀJ``'s eigenvalues (the
    one definition every engine reports)."""
    significance = rules.significance
    p = len(ne.Jtr)
    norms = np.sqrt(np.maximum(np.diag(ne.JtJ), 1e-300))
    outer = np.outer(norms, norms)
    N = ne.JtJ / outer
    lam = np.linalg.eigvalsh(N)
    cond = condition_number(lam)
    inverse = np.linalg.pinv(N, hermitian=True)
    if ne.position_normal is None or ne.position_cost is None or ne.position_rows is None:
        s2 = residual_variance(ne.cost, ne.rows - p, known_noise, significance)
        cov = s2 * inverse / outer
    else:  # two groups of rows, each with its share of the degrees of freedom
        rows_p, rows_w = ne.position_rows, ne.rows - ne.position_rows
        s2 = residual_variance(ne.position_cost, rows_p - p * rows_p / ne.rows, known_noise, significance)
        dof_w = rows_w - p * rows_w / ne.rows
        s2_w = residual_variance(ne.cost - ne.position_cost, dof_w, False, significance)
        middle = (s2 * ne.position_normal + s2_w * (ne.JtJ - ne.position_normal)) / outer
        cov = inverse @ middle @ inverse / outer
    cov = 0.5 * (cov + cov.T)
    std = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = np.where(np.outer(std, std) > 0, cov / np.outer(std, std), 0.0)
    return Covariance(float(s2), cov, std, corr, cond)
