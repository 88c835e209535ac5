"""The compiled Levenberg-Marquardt iteration (robocal.identify.kernels.lm) against its numpy
reference (tests/reference_lm.py: levenberg_marquardt_batch_numpy): the same steps, stops,
histories and solutions, for one problem and for a batch whose problems stop at different
iterations; and the damped Cholesky step where the damped matrix is not positive definite."""

from __future__ import annotations

import numpy as np
import pytest

import robocal.identify.kernels.lm as lm_kernels
from robocal.identify.solvers import levenberg_marquardt, levenberg_marquardt_batch
from tests.reference_lm import damped_steps, levenberg_marquardt_batch_numpy


class _Exponentials:
    """r(x) = x0 exp(x1 t) + x2 - y (40 points); ``duplicate``: a fourth unknown added to
    x2 (two equal columns: a singular normal matrix)."""

    def __init__(self, seed: int, duplicate: bool = False) -> None:
        rng = np.random.default_rng(seed)
        self.t = np.linspace(0.0, 2.0, 40)
        truth = np.array([1.5, -0.7, 0.2]) + 0.1 * rng.normal(size=3)
        self.y = truth[0] * np.exp(truth[1] * self.t) + truth[2] + 1e-3 * rng.normal(size=40)
        self.duplicate = duplicate

    def residual(self, x: np.ndarray) -> np.ndarray:
        offset = x[2] + x[3] if self.duplicate else x[2]
        return x[0] * np.exp(x[1] * self.t) + offset - self.y

    def jacobian(self, x: np.ndarray) -> np.ndarray:
        e = np.exp(x[1] * self.t)
        columns = [e, x[0] * self.t * e, np.ones_like(self.t)]
        return np.column_stack(columns + columns[2:] if self.duplicate else columns)


class _Rosenbrock:
    """r = (10 (x1 - x0²), 1 - x0): a curved valley (refused steps, damping raised)."""

    def residual(self, x: np.ndarray) -> np.ndarray:
        return np.array([10.0 * (x[1] - x[0] ** 2), 1.0 - x[0]])

    def jacobian(self, x: np.ndarray) -> np.ndarray:
        return np.array([[-20.0 * x[0], 10.0], [-1.0, 0.0]])


def _batch_evaluate(problems, calls=None, fortran=False):
    def evaluate(x, which):
        if calls is not None:
            calls.append((x.copy(), np.array(which)))
        r = np.stack([problems[k].residual(xk) for k, xk in zip(which, x, strict=True)])
        J = np.stack([problems[k].jacobian(xk) for k, xk in zip(which, x, strict=True)])
        return r, (np.asfortranarray(J.transpose(0, 2, 1)).transpose(0, 2, 1) if fortran else J)

    return evaluate


def _assert_same(fast, ref, rtol=1e-9):
    np.testing.assert_array_equal(fast.success, ref.success)
    np.testing.assert_array_equal(fast.iterations, ref.iterations)
    np.testing.assert_array_equal(fast.evaluations, ref.evaluations)
    for h_fast, h_ref in zip(fast.histories, ref.histories, strict=True):
        np.testing.assert_allclose(h_fast, h_ref, rtol=rtol)
    np.testing.assert_allclose(fast.x, ref.x, rtol=rtol, atol=1e-12)
    np.testing.assert_allclose(fast.r, ref.r, rtol=rtol, atol=1e-12)
    np.testing.assert_allclose(fast.J, ref.J, rtol=rtol, atol=1e-12)
    assert fast.x.shape == ref.x.shape and fast.J.shape == ref.J.shape


@pytest.mark.parametrize("fortran", [False, True], ids=["C-ordered J", "Fortran-ordered J"])
def test_a_batch_stopping_at_different_iterations_follows_the_numpy_iteration(fortran):
    problems = [_Exponentials(seed) for seed in range(5)]
    x0 = np.array([[1.0, 0.0, 0.0], [2.0, -1.0, 0.5], [0.5, 0.3, -0.2], [5.0, -3.0, 2.0], [3.0, -2.0, 1.0]])
    calls_fast, calls_ref = [], []
    fast = levenberg_marquardt_batch(_batch_evaluate(problems, calls_fast, fortran), x0, max_evaluations=200)
    ref = levenberg_marquardt_batch_numpy(_batch_evaluate(problems, calls_ref), x0, max_evaluations=200)
    _assert_same(fast, ref)
    assert fast.success.all() and len(set(fast.evaluations.tolist())) > 2  # stopped at different times
    # the same evaluations: the same problems, packed in the same order, at the same points
    assert [w.tolist() for _, w in calls_fast] == [w.tolist() for _, w in calls_ref]
    for (x_fast, _), (x_ref, _) in zip(calls_fast, calls_ref, strict=True):
        np.testing.assert_allclose(x_fast, x_ref, rtol=1e-9, atol=1e-12)


def test_one_problem_with_refused_steps_follows_the_numpy_iteration():
    problem = _Rosenbrock()
    x0 = np.array([[-1.2, 1.0]])
    evaluate = _batch_evaluate([problem])
    fast = levenberg_marquardt_batch(evaluate, x0, max_evaluations=500, tolerance=1e-12)
    ref = levenberg_marquardt_batch_numpy(evaluate, x0, max_evaluations=500, tolerance=1e-12)
    _assert_same(fast, ref)
    assert fast.success[0] and fast.evaluations[0] > fast.iterations[0] + 1  # some steps were refused
    np.testing.assert_allclose(fast.x[0], [1.0, 1.0], atol=1e-6)
    one = levenberg_marquardt(problem, x0[0], max_iterations=500, tolerance=1e-12)
    assert (one.iterations, one.evaluations, one.success) == (fast.iterations[0], fast.evaluations[0], True)
    np.testing.assert_allclose(one.history, ref.histories[0], rtol=1e-9)
    assert one.J is not None and one.J.shape == (2, 2)


def test_budget_stops_and_mixed_outcomes_follow_the_numpy_iteration():
    problems = [_Exponentials(0), _Rosenbrock(), _Exponentials(1, duplicate=True)]
    x0s = [np.array([5.0, -3.0, 2.0]), np.array([-1.2, 1.0]), np.array([1.0, 0.0, 0.0, 0.0])]
    for budget in (1, 2, 3, 7, 200):
        for problem, x0 in zip(problems, x0s, strict=True):
            evaluate = _batch_evaluate([problem])
            fast = levenberg_marquardt_batch(evaluate, x0[None], max_evaluations=budget)
            ref = levenberg_marquardt_batch_numpy(evaluate, x0[None], max_evaluations=budget)
            _assert_same(fast, ref, rtol=1e-8)
            assert fast.evaluations[0] <= budget
            assert fast.result(0).message == ref.result(0).message


def test_an_empty_batch_returns_an_empty_result():
    def evaluate(x, which):
        return np.zeros((len(x), 4)), np.zeros((len(x), 4, 2))

    fit = levenberg_marquardt_batch(evaluate, np.zeros((0, 2)))
    assert fit.x.shape == (0, 2) and fit.J.shape == (0, 4, 2) and fit.histories == []
    assert fit.success.shape == fit.iterations.shape == fit.evaluations.shape == (0,)


def test_a_singular_normal_matrix_is_damped_as_in_numpy():
    """Two equal columns: only the damping keeps the normal matrix positive definite; a zero
    Jacobian: the start damping is 0 and is raised to 1e-12."""
    problems = [_Exponentials(seed, duplicate=True) for seed in range(3)]
    x0 = np.array([[1.0, 0.0, 0.0, 0.0], [2.0, -1.0, 0.5, -0.5], [0.5, 0.3, -0.2, 0.1]])
    evaluate = _batch_evaluate(problems)
    _assert_same(
        levenberg_marquardt_batch(evaluate, x0, max_evaluations=400),
        levenberg_marquardt_batch_numpy(evaluate, x0, max_evaluations=400),
        rtol=1e-7,
    )

    def flat(x, which):
        return np.ones((len(x), 5)), np.zeros((len(x), 5, 2))

    fast = levenberg_marquardt_batch(flat, np.array([[1.0, 2.0]]))
    ref = levenberg_marquardt_batch_numpy(flat, np.array([[1.0, 2.0]]))
    _assert_same(fast, ref)
    assert fast.success[0] and fast.evaluations[0] == 1


def test_the_damped_step_raises_the_damping_until_positive_definite_as_numpy():
    rng = np.random.default_rng(3)
    A = np.array([[1.0, 2.0, 0.0], [2.0, 1.0, 0.5], [0.0, 0.5, 3.0]])  # eigenvalues about -1.1 .. 3.1
    cases = [(A, 1e-6), (np.zeros((3, 3)), 0.0), (A @ A.T, 1e-3)]
    for M, mu in cases:
        g = rng.normal(size=3)
        step_ref, mu_ref = damped_steps(M[None], g[None], np.array([mu]))
        step = np.empty(3)
        mu_fast = lm_kernels.damped_step(M, g, mu, np.empty((3, 3)), np.zeros((3, 3)), step)
        assert mu_fast == mu_ref[0]
        np.testing.assert_allclose(step, step_ref[0], rtol=1e-12, atol=1e-15)
    assert lm_kernels.damped_step(A, g, 1e-6, np.empty((3, 3)), np.zeros((3, 3)), step) == pytest.approx(10.0)


def test_a_jacobian_with_nan_stops_unconverged_instead_of_looping():
    """No damping makes a normal matrix with NaN positive definite: the problem stops, not
    converged (the numpy iteration would raise μ for ever); the others go on."""
    good = _Exponentials(0)

    def evaluate(x, which):
        r = np.stack([good.residual(xk) for xk in x])
        J = np.stack([good.jacobian(xk) for xk in x])
        J[which == 1] = np.nan
        return r, J

    fit = levenberg_marquardt_batch(evaluate, np.array([[1.0, 0.0, 0.0], [1.0, 0.0, 0.0]]))
    assert fit.success.tolist() == [True, False]
    assert fit.evaluations[1] == 1 and fit.result(1).message.startswith("stopped: NaN or inf")
