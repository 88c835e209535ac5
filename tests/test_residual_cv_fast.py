"""The learned residual's fast model choice against its slow reference.

The default cross-validation calibrates the physics on all poses only and takes each fold's
physical fit as its linear response (``refit_folds=False``); the reference calibrates the
physics again on every fold.  On small virtual UR10s with and without errors the physics
lacks, both choose the same candidate and their CV errors agree.
"""

from __future__ import annotations

import functools

import numpy as np
import pytest

import robocal as rc
import robocal.identify.residual.cv as cv
import robocal.identify.residual.stage as stage
from robocal.identify.pipeline import calibrate_physics
from robocal.identify.residual.cv import cross_validate_residual, cross_validate_residual_refitted
from robocal.identify.residual.fit import (
    Hyper,
    fit_joint_fourier,
    gram_matrices,
    one_blas_thread_limit,
    posterior_mean,
    residual_template,
)
from tests.test_complete_model import poses, simulate, tilted_ur10
from tests.test_residual import PROBE, _case, _ur10


def _choices(model: rc.Model, data: rc.Measurements, refit_folds: bool, harmonics: tuple[int, ...]):
    """The CV table of ``calibrate_with_residual``'s candidates (on one BLAS thread, as there)."""
    with one_blas_thread_limit():
        return _table(model, data, refit_folds, harmonics)


def _table(model: rc.Model, data: rc.Measurements, refit_folds: bool, harmonics: tuple[int, ...]):
    options = {"tool_guess": PROBE}
    base = calibrate_physics(model, data, "lm", **options)
    joints = list(range(model.dof))
    variants = stage._physics_variants(model, options, "auto")
    fits = stage._PhysicsFits(calibrate_physics, model, data, "lm", variants, "geometry", base)
    usable, _ = fits.usable()
    names = [model.joint_names[j] for j in joints]
    cv_of = cross_validate_residual_refitted if refit_folds else cross_validate_residual
    table, _ = cv_of(data.q, data.position, usable, names, joints, harmonics, 5)
    return table


def _twin_without_errors() -> tuple[rc.Model, rc.Measurements]:
    robot = tilted_ur10(0)  # the 60-pose twin whose choice fixed fold hyperparameters got wrong
    return rc.calibration_model("ur10", "position"), simulate(robot, poses(robot.nominal, 60, 100), seed=200)


@pytest.mark.parametrize("case", ["with errors", "without errors"])
def test_linearised_folds_choose_as_the_refitted_folds(case):
    if case == "with errors":  # 64 training poses, m = 96: the folds' normal equations
        model, (data, _), grid = _ur10(), _case(errors=True, n_train=80, seed=6), (4, 8)
    else:  # 48 training poses, m = 288: the evidence's dual form from each fold's design
        (model, data), grid = _twin_without_errors(), (8, 24)
    fast, slow = _choices(model, data, False, grid), _choices(model, data, True, grid)
    assert fast.chosen == slow.chosen
    if case == "with errors":
        assert "angle errors" in fast.chosen  # the case exercises a residual choice
    else:
        assert "angle errors" not in fast.chosen
    for a, b in zip(fast.candidates, slow.candidates, strict=True):
        assert a.name == b.name
        assert a.cv_mean == pytest.approx(b.cv_mean, rel=0.02)
        assert a.cv_rms == pytest.approx(b.cv_rms, rel=0.02)


def test_fold_normal_equations_give_the_folds_least_squares():
    """All poses' normal equations minus a fold's (one pass over the poses) give the same
    held-out errors as each fold's own least squares of the linearised physics and the
    residual (the design of its training poses)."""
    model, (data, _) = _ur10(), _case(errors=True, n_train=80, seed=6)
    base = calibrate_physics(model, data, "lm", tool_guess=PROBE)
    variants = {"geometry": {"tool_guess": PROBE}}
    fits = stage._PhysicsFits(calibrate_physics, model, data, "lm", variants, "geometry", base)
    full = fits.usable()[1]["geometry"]
    names = tuple(model.joint_names)
    problem = cv._Problem(data.q, data.position, names, tuple(range(6)), (4, 8))  # m = 96 <= 3 x 64
    parts = np.array_split(np.random.default_rng(0).permutation(data.n), 5)
    hypers: dict = {}
    specs, _ = cv._fit_candidates(problem, "geometry", full, True, hypers)
    raws = cv._fold_raws(problem, full, parts)
    assert raws is not None
    fast = cv._fold_errors_of_raws(problem, full, parts, raws, specs, hypers)
    slow = cv._fold_errors(problem, functools.partial(cv._linearised, full), parts, specs, hypers)
    assert set(fast) == {"geometry", "geometry + angle errors H=4", "geometry + angle errors H=8"}
    for name in fast:
        np.testing.assert_allclose(fast[name], slow[name], rtol=1e-3, atol=1e-9)


def test_posterior_mean_is_the_fitted_coefficients():
    """What a fold computes (the mean only) is the full fit's mean for the same hyperparameters."""
    rng = np.random.default_rng(1)
    q = rng.uniform(-np.pi, np.pi, (50, 6))
    P = rng.normal(size=(50, 3, 6, 3))
    r = rng.normal(scale=1e-4, size=(50, 3))
    hyper = Hyper((3e-4, 1e-4), 0.05, 2e-5)
    learned, _ = fit_joint_fourier(q, r, P, ["a", "b"], [1, 2], 4, hyper=hyper)
    template = residual_template(["a", "b"], [1, 2], 4, q)
    normal = gram_matrices(q, r, P, template, [4], None)[4]
    np.testing.assert_allclose(posterior_mean(template, normal, hyper), learned.coefficients, rtol=1e-10)


def test_nested_blas_limits_hold_and_restore():
    threadpoolctl = pytest.importorskip("threadpoolctl")

    def blas_threads() -> list[int]:
        return [i["num_threads"] for i in threadpoolctl.threadpool_info() if i["user_api"] == "blas"]

    before = blas_threads()
    with one_blas_thread_limit():
        with one_blas_thread_limit():
            assert all(n == 1 for n in blas_threads())
        assert all(n == 1 for n in blas_threads())  # the inner exit does not lift the outer limit
    assert blas_threads() == before
