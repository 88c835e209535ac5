"""One engine: the batched solver and stages equal the one-robot ones (robocal.identify.stages,
robocal.identify.solvers.levenberg_marquardt_batch)."""

from __future__ import annotations

import numpy as np

from robocal.identify.solvers import levenberg_marquardt, levenberg_marquardt_batch


class _Exponentials:
    """r(x) = x0 exp(x1 t) + x2 - y: a small nonlinear least-squares problem."""

    def __init__(self, seed: int) -> None:
        rng = np.random.default_rng(seed)
        self.t = np.linspace(0.0, 2.0, 40)
        truth = np.array([1.5, -0.7, 0.2]) + 0.1 * rng.normal(size=3)
        self.y = truth[0] * np.exp(truth[1] * self.t) + truth[2] + 1e-3 * rng.normal(size=40)

    def residual(self, x: np.ndarray) -> np.ndarray:
        return x[0] * np.exp(x[1] * self.t) + x[2] - self.y

    def jacobian(self, x: np.ndarray) -> np.ndarray:
        e = np.exp(x[1] * self.t)
        return np.column_stack([e, x[0] * self.t * e, np.ones_like(self.t)])


def test_batched_levenberg_marquardt_is_the_one_problem_solver_per_problem():
    problems = [_Exponentials(seed) for seed in range(5)]
    x0 = np.array([[1.0, 0.0, 0.0], [2.0, -1.0, 0.5], [0.5, 0.3, -0.2], [1.0, -0.5, 0.0], [3.0, -2.0, 1.0]])

    def evaluate(x, which):
        r = np.stack([problems[k].residual(xk) for k, xk in zip(which, x, strict=True)])
        J = np.stack([problems[k].jacobian(xk) for k, xk in zip(which, x, strict=True)])
        return r, J

    batch = levenberg_marquardt_batch(evaluate, x0, max_evaluations=200)
    iterations = set()
    for k, p in enumerate(problems):
        one = levenberg_marquardt(p, x0[k], max_iterations=200)
        assert one.success and batch.success[k]
        # the problems follow their own steps and damping, whatever else is in the batch
        assert (batch.iterations[k], batch.evaluations[k]) == (one.iterations, one.evaluations)
        np.testing.assert_allclose(batch.x[k], one.x, rtol=1e-12, atol=1e-14)
        np.testing.assert_allclose(batch.r[k], p.residual(one.x), rtol=0, atol=1e-12)
        iterations.add(int(batch.evaluations[k]))
    assert len(iterations) > 1  # they stopped at different evaluations: the compaction was exercised


def test_batched_levenberg_marquardt_stops_at_its_budget():
    p = _Exponentials(0)

    def evaluate(x, which):
        return p.residual(x[0])[None].repeat(len(x), 0), p.jacobian(x[0])[None].repeat(len(x), 0)

    fit = levenberg_marquardt_batch(evaluate, np.array([[10.0, 3.0, -5.0]]), max_evaluations=3)
    assert not fit.success[0] and fit.evaluations[0] == 3
    assert fit.result(0).message == "no convergence in 3 evaluations"
