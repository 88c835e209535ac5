"""The default calibration's extra cost over the physics alone (issue 35, session 16).

The learned residual's evidence is maximised by the package's own bounded quasi-Newton
minimiser (:mod:`robocal.identify.residual.boxmin`), so the default command never imports
:mod:`scipy.optimize` (0.12 s of CPU a process): it must find what L-BFGS-B finds.  The fits
on all poses start from the optimum of another variant or of fewer harmonics: the same
optimum, in fewer evaluations.
"""

from __future__ import annotations

import subprocess
import sys
import textwrap

import numpy as np
import pytest
from scipy.optimize import minimize

import robocal.identify.residual.fit as fit
from robocal.identify.residual.boxmin import minimize_in_box


def _rosenbrock(x: np.ndarray) -> tuple[float, np.ndarray]:
    f = 100.0 * (x[1] - x[0] ** 2) ** 2 + (1.0 - x[0]) ** 2
    g = np.array([-400.0 * x[0] * (x[1] - x[0] ** 2) - 2.0 * (1.0 - x[0]), 200.0 * (x[1] - x[0] ** 2)])
    return float(f), g


def test_the_box_minimiser_finds_an_unconstrained_minimum():
    found = minimize_in_box(_rosenbrock, np.array([-1.2, 1.0]), np.full(2, -5.0), np.full(2, 5.0), ftol=1e-14)
    assert found.x == pytest.approx([1.0, 1.0], abs=1e-4)


def test_the_box_minimiser_stops_on_an_active_bound_as_l_bfgs_b():
    """A quadratic whose minimum lies outside the box: the box's nearest point in its metric,
    with the gradient pushing outwards on the held variable only."""
    rng = np.random.default_rng(4)
    M = rng.normal(size=(5, 5))
    H = M @ M.T + 5 * np.eye(5)
    centre = np.array([3.0, -0.2, 0.1, 2.5, 0.0])

    def quadratic(x):
        d = x - centre
        return float(0.5 * d @ H @ d), H @ d

    lower, upper = np.full(5, -1.0), np.full(5, 1.0)
    found = minimize_in_box(quadratic, np.zeros(5), lower, upper, ftol=1e-15, gtol=1e-10)
    reference = minimize(
        quadratic, np.zeros(5), jac=True, method="L-BFGS-B", bounds=list(zip(lower, upper, strict=True)),
        options={"ftol": 1e-15, "gtol": 1e-10},
    )  # fmt: skip
    assert found.x == pytest.approx(reference.x, abs=1e-6)
    assert found.f <= reference.fun + 1e-9
    held = (found.x <= lower) | (found.x >= upper)
    assert held.any()  # the case is one with an active bound
    assert np.max(np.abs(quadratic(found.x)[1][~held])) < 1e-6


def test_a_function_that_cannot_decrease_ends_at_the_start():
    flat = minimize_in_box(lambda x: (0.0, np.zeros(3)), np.ones(3), np.zeros(3), np.full(3, 2.0))
    assert np.array_equal(flat.x, np.ones(3)) and flat.evaluations == 1


@pytest.fixture(scope="module")
def normal_equations():
    """The normal equations of 24 harmonics of a UR10 twin with transmission errors (300 poses)."""
    from tests.test_residual_warm_start import _normal, transmission_case

    case = transmission_case.__wrapped__()
    return _normal(case, slice(None))


def _lbfgsb_evidence(template, normal) -> np.ndarray:
    """The evidence's optimum by scipy's L-BFGS-B (what robocal used before), tight tolerance."""
    groups, freq = fit.layout(template)
    k = len(template.joints)
    theta0 = np.r_[np.full(k, np.log(2e-4)), np.log(0.02), np.log(np.sqrt(normal.rr / normal.N))]
    scales = [(np.log(1e-4), np.log(2.0)), (np.log(1e-7), np.log(1e-2))]  # ℓ and σ
    bounds = [(np.log(1e-9), np.log(fit.MAX_AMPLITUDE))] * k + scales
    args = (normal.G, normal.b, normal.rr, normal.N, groups, freq)
    opt = minimize(fit.nll_and_grad, theta0, args=args, jac=True, method="L-BFGS-B", bounds=bounds,
                   options={"ftol": 1e-14, "gtol": 1e-9, "maxiter": 1000})  # fmt: skip
    return opt.x


def _theta(h: fit.Hyper) -> np.ndarray:
    return np.r_[np.log(h.amplitudes), np.log(h.length_scale), np.log(h.noise)]


def test_the_evidence_has_l_bfgs_bs_optimum(normal_equations):
    template, normal = normal_equations
    groups, freq = fit.layout(template)
    args = (normal.G, normal.b, normal.rr, normal.N, groups, freq)
    reference = _lbfgsb_evidence(template, normal)
    found = _theta(fit.evidence(template, normal, None))
    best = fit.nll_and_grad(reference, *args)[0]
    # ftol 1e-8 of |−log E|: as close to the optimum as L-BFGS-B with the same tolerance
    assert fit.nll_and_grad(found, *args)[0] - best < 1e-7 * abs(best)
    assert np.exp(found[-1]) == pytest.approx(np.exp(reference[-1]), rel=1e-3)  # the noise σ


def test_the_default_calibration_does_not_import_scipy_optimize():
    """A twin with transmission errors the physics lacks: the default chooses a learned
    residual, in a process that never loads :mod:`scipy.optimize`."""
    code = textwrap.dedent(
        """
        import sys
        from tests.test_residual import _calibrate, _case
        train, _ = _case(errors=True, n_train=120, seed=1)
        assert "scipy.optimize" not in sys.modules
        result = _calibrate(train, "auto")
        print(result.diagnostics.cv["chosen"])
        print("scipy.optimize" in sys.modules)
        """
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr
    chosen, loaded = done.stdout.strip().splitlines()[-2:]
    assert "angle errors" in chosen
    assert loaded == "False"


def test_a_fit_on_all_poses_from_another_variants_optimum_ends_at_the_same_optimum_sooner(monkeypatch):
    """``cv._warm_start``: a physical variant's fit of 24 harmonics starts from another
    variant's optimum with as many (here: the optimum on 90 % of the poses, residuals that
    differ a little, with its curvature as the CV keeps it) and reaches the neutral start's
    optimum in fewer evaluations; the optimum of fewer harmonics is no start (local optima)."""
    from robocal.identify.residual.curvature import with_curvature
    from robocal.identify.residual.cv import _warm_start
    from tests.test_residual_warm_start import _normal, transmission_case

    case = transmission_case.__wrapped__()
    template, normal = _normal(case, slice(None), H=24)
    other_template, other_normal = _normal(case, slice(0, 270), H=24)
    other = fit.evidence(other_template, other_normal, None)
    other = with_curvature(other, other_normal, *fit.layout(other_template))
    assert _warm_start({"geometry + angle errors H=8": other}, 24) is None  # fewer harmonics: no start
    start = _warm_start({"geometry + angle errors H=24": other}, 24)
    assert start is other
    calls = [0]
    nll, parts = fit.nll_and_grad, fit.nll_parts

    def counted(*args):
        calls[0] += 1
        return parts(*args)

    monkeypatch.setattr(fit, "nll_parts", counted)  # the search's evaluations
    found = {}
    for label, begin in (("neutral", None), ("warm", start)):
        calls[0] = 0
        found[label] = (_theta(fit.evidence(template, normal, begin)), calls[0])
    args = (normal.G, normal.b, normal.rr, normal.N, *fit.layout(template))
    neutral, warm = (nll(found[k][0], *args)[0] for k in ("neutral", "warm"))
    assert warm == pytest.approx(neutral, rel=1e-7)
    assert found["warm"][1] < found["neutral"][1]


def test_effect_columns_from_the_identified_kinds_only_equal_all_kinds():
    """``CalibrationResult._effect_columns`` forms the patterns of the identified effects'
    kinds and joints only (the validation's expected error at 11,611 poses: 0.064 -> 0.042 s);
    the columns equal those picked out of every kind's patterns."""
    import robocal as rc
    from robocal.model.joints import EFFECT_KINDS, effect_basis, effect_of
    from tests.test_residual_warm_start import TOOL, twin

    model, _, train = twin.__wrapped__()  # a UR10 twin with compliant shoulder and elbow
    result = rc.calibrate(model, train, tool_guess=TOOL, compliance=True, residual="none")
    effects = [n for n in result.names if effect_of(n) is not None]
    assert effects  # compliance identified
    q = train.q[:50]
    B, names, _ = effect_basis(
        result.robot, q, kinds=EFFECT_KINDS, gravity=np.asarray(result.gravity), payload=result.payload
    )
    P = result.measurement_chain.perturbation_jacobian(q, "position", result.joint_perturbations(q))
    expected = np.einsum("nrjc,knjc->nrk", P, B[[names.index(n) for n in effects]])
    columns = result.position_columns(q)[:, :, [result.names.index(n) for n in effects]]
    np.testing.assert_allclose(columns, expected, rtol=1e-12, atol=1e-15)


def test_the_cli_enters_a_stage_once_whatever_the_engines_progress(monkeypatch):
    """The engine reports its progress within the calibrate stage (the CV after each fold and
    variant: 14 reports at 5 folds, two variants); the command's stage view enters the
    kernels' first-use check (9 cache indexes read) and its spinner once per stage."""
    import contextlib

    import robocal.identify.kernel_cache as kernel_cache
    from robocal.cli.calibrate import _Stages

    entered = []

    @contextlib.contextmanager
    def counted(console):
        entered.append(1)
        yield

    monkeypatch.setattr(kernel_cache, "first_use", counted)
    with _Stages("test") as stages:
        stages.enter("read", 0.0)
        for fraction in np.linspace(0.05, 0.8, 16):
            stages.enter("calibrate", float(fraction))
        stages.enter("validate", 0.8)
    assert len(entered) == 1


@pytest.mark.parametrize("case", ["compliance", "learned residual"])
def test_the_mean_position_variance_is_the_mean_trace_of_the_covariances(case):
    """``validate.mean_position_variance`` hands its perturbations and perturbation Jacobian to
    ``position_columns`` (no second joint-load or chain pass at the held-out poses): the
    same number as the mean trace of ``position_covariance``, which forms its own."""
    import robocal as rc
    from robocal.identify.validate import mean_position_variance

    if case == "compliance":
        from tests.test_residual_warm_start import TOOL, twin

        model, _, train = twin.__wrapped__()
        result = rc.calibrate(model, train, tool_guess=TOOL, compliance=True, residual="none")
    else:
        from tests.test_residual import PROBE, _case, _ur10

        train, _ = _case(errors=True, n_train=120, seed=1)
        result = rc.calibrate(_ur10(), train, tool_guess=PROBE, residual="auto")
        assert result.model.residual is not None
    q = train.q[::3]
    expected = float(np.mean(np.trace(result.position_covariance(q), axis1=1, axis2=2)))
    assert mean_position_variance(result, q) == pytest.approx(expected, rel=1e-9)
    given = mean_position_variance(result, q, result.joint_perturbations(q))
    assert given == pytest.approx(expected, rel=1e-9)


def test_the_box_minimiser_reaches_l_bfgs_bs_minimum_of_ill_conditioned_quadratics_in_a_box():
    """Projected BFGS on random quadratics (condition 1e4) whose minimum lies outside the box:
    the step of the free variables solves their own Hessian block, and a step the box cuts
    until it no longer descends restarts from steepest descent (27 of 300 stopped short
    before both)."""
    short = []
    for seed in range(300):
        rng = np.random.default_rng(seed)
        Q = np.linalg.qr(rng.normal(size=(7, 7)))[0]
        A = Q @ np.diag(np.logspace(0, 4, 7)) @ Q.T
        c = rng.normal(size=7) * 3

        def f(x, A=A, c=c):
            return 0.5 * (x - c) @ A @ (x - c), A @ (x - c)

        x0 = rng.uniform(-1, 1, 7)
        x0[0] = -1.0
        bounds = [(-1.0, 1.0)] * 7
        options = {"ftol": 1e-15, "gtol": 1e-10, "maxiter": 2000}
        best = minimize(f, x0, jac=True, method="L-BFGS-B", bounds=bounds, options=options).fun
        found = minimize_in_box(f, x0, -np.ones(7), np.ones(7)).f
        if found - best > 1e-4 * max(1.0, abs(best)):
            short.append(seed)
    assert not short


def test_a_forced_48_harmonic_fit_reaches_the_evidence_optimum():
    """A 60-pose twin (seed 1) with 48 harmonics forced: the old projected step stopped 91
    nats short of the evidence's optimum and held out 93 µm against 34 µm."""
    import robocal as rc
    from tests.test_residual import PROBE, _case, _ur10

    train, test = _case(errors=True, n_train=60, seed=1)
    errors = []
    for harmonics in (24, 48):
        result = rc.calibrate(
            _ur10(), train, tool_guess=PROBE, residual="joint_fourier", residual_harmonics=(harmonics,)
        )
        errors.append(np.linalg.norm(result.predict(test.q)[:, :3, 3] - test.position, axis=1).mean())
    assert errors[1] < 1.05 * errors[0]
