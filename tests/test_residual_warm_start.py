"""The learned residual's physical fits with the joint loads of a calibrated geometry.

Under compliance alone (``δθ = -c τ(q)``) the load passes of a physical fit from the nominal
geometry only approach the loads of the calibrated one; the residual stage has such a geometry
already (the plain fit of the same poses, or the chosen variant's for its refit) and takes
its loads in one pass (``stage.warm_loads``).  A UR10 twin whose geometry is 1 mm / 0.1° off
its nominal and whose shoulder and elbow give way under gravity: the one pass lands where the
passes from the nominal loads converge, the default calibration chooses and predicts as
before, with fewer physical fits.
"""

from __future__ import annotations

import numpy as np
import pytest

import robocal as rc
import robocal.identify.pipeline as pipeline
import robocal.identify.residual.stage as stage
from robocal.identify.pipeline import calibrate_physics

TOOL = [0.0, 0.0, 0.1]


@pytest.fixture(scope="module")
def twin():
    """``(model, robot, train)``: the compliant UR10 twin measured at 150 poses."""
    from robocal.demo import GravityCompliance, complete_model
    from robocal.measure import LaserTracker, VirtualRobot, draw_true_model, random_poses, simulate

    model = complete_model("ur10")
    true = draw_true_model(model, length=1e-3, angle=np.radians(0.1), seed=4)
    robot = VirtualRobot(
        model,
        true,
        LaserTracker(p_tool_target=np.array(TOOL)),
        GravityCompliance({"shoulder_lift": 4e-6, "elbow": 6e-6}),
    )
    return model, robot, simulate(robot, random_poses(model, 150, seed=11), seed=12)


def _shift_in_sigma(a: rc.CalibrationResult, b: rc.CalibrationResult) -> float:
    """The largest change of a parameter between two fits of the same unknowns, in ``a``'s σ."""
    assert a.names == b.names
    return float(np.max(np.abs(a.estimates - b.estimates) / a.std))


def test_one_pass_from_a_calibrated_geometry_lands_where_the_passes_converge(twin):
    model, _, train = twin
    passes = calibrate_physics(model, train, "lm", tool_guess=TOOL, compliance=True)  # from nominal loads
    assert (passes.diagnostics.load_passes or 1) >= 2  # the case needs the passes
    plain = calibrate_physics(model, train, "lm", tool_guess=TOOL)
    options = stage.warm_loads(model, {"tool_guess": TOOL, "compliance": True}, plain)
    warm = calibrate_physics(model, train, "lm", **options)
    cold = calibrate_physics(model, train, "lm", tool_guess=TOOL, compliance=True, load_passes=1)
    # the nominal loads in one pass stop short of the passes; the calibrated geometry's do not
    assert _shift_in_sigma(passes, cold) > 1e-3
    assert _shift_in_sigma(passes, warm) < 0.1 * _shift_in_sigma(passes, cold)
    assert warm.rms_after == pytest.approx(passes.rms_after, rel=1e-4)


def test_warm_loads_only_for_effects_that_ignore_the_loads_sign(twin):
    model, _, train = twin
    plain = calibrate_physics(model, train, "lm", tool_guess=TOOL)
    warm = stage.warm_loads(model, {"compliance": True}, plain)
    assert warm["load_passes"] == 1
    calibrated = dict(zip(plain.model.names, plain.model.values, strict=True))
    geometry = warm["load_geometry"]
    assert geometry.joint_names == model.joint_names
    moved = [n for n in model.names if n in calibrated and calibrated[n] != model.step(n).value]
    assert moved and all(geometry.step(n).value == calibrated[n] for n in moved)
    # backlash and clearance take the side of the load's sign: their passes are kept
    for options in ({"effects": "identify"}, {"compliance": True, "effects": ["backlash"]}, {"level": 3}):
        assert stage.warm_loads(model, options, plain) is options
    assert stage.warm_loads(model, {"compliance": False}, plain) == {"compliance": False}


def test_the_default_calibration_chooses_and_predicts_as_with_the_load_passes(twin, monkeypatch):
    """``residual="auto"`` with the warm loads against the same stage with the passes from the
    nominal loads (``warm_loads`` replaced by the identity): the same CV table and choice, the
    same calibrated parameters and held-out predictions to a small share of their σ, with
    fewer physical fits."""
    model, _, train = twin
    fits: list[int] = []
    once = pipeline._calibrate_once

    def counted(*args, **kw):
        fits.append(1)
        return once(*args, **kw)

    monkeypatch.setattr(pipeline, "_calibrate_once", counted)
    warm = rc.calibrate(model, train, tool_guess=TOOL, residual="auto")
    warm_fits = len(fits)
    monkeypatch.setattr(stage, "warm_loads", lambda model, options, fitted: options)
    fits.clear()
    passes = rc.calibrate(model, train, tool_guess=TOOL, residual="auto")
    assert warm_fits < len(fits)
    a, b = warm.diagnostics.cv, passes.diagnostics.cv
    assert a["chosen"] == b["chosen"] and "compliance" in a["chosen"]
    for x, y in zip(a["candidates"], b["candidates"], strict=True):
        assert x["name"] == y["name"]
        assert x["cv_mean_mm"] == pytest.approx(y["cv_mean_mm"], rel=1e-3)
    assert _shift_in_sigma(passes, warm) < 0.05
    from robocal.measure import random_poses

    q = random_poses(model, 300, seed=13)  # poses the calibration has not seen
    moved = np.linalg.norm(warm.predict(q)[:, :3, 3] - passes.predict(q)[:, :3, 3], axis=1)
    assert moved.max() < 0.05 * warm.residual_std


# ------------------------------------------------------------------ the folds' evidence fits
@pytest.fixture(scope="module")
def transmission_case():
    """``(q, residuals, P, J)`` of the physical fit of a UR10 twin with transmission errors the
    physics lacks (``tests/test_residual.py``'s), 300 poses."""
    from robocal.identify.residual.cv import PhysicalFit
    from tests.test_residual import PROBE, _case, _ur10

    (data, _), model = _case(errors=True, n_train=300, seed=3), _ur10()
    base = calibrate_physics(model, data, "lm", tool_guess=PROBE)
    p, P, J = PhysicalFit(base, np.empty(0), np.empty(0), np.empty(0)).predict(data.q)
    return data.q, data.position - p, P, J


def _normal(case, rows, H: int = 24):
    from robocal.identify.residual.fit import gram_matrices, residual_template

    q, r, P, J = (x[rows] for x in case)
    template = residual_template([f"j{i}" for i in range(6)], list(range(6)), H, q)
    return template, gram_matrices(q, r, P, template, [H], J)[H]


def test_the_evidence_curvature_is_the_hessians_diagonal(transmission_case):
    from robocal.identify.residual.curvature import evidence_curvature
    from robocal.identify.residual.fit import evidence, layout, nll_and_grad

    template, normal = _normal(transmission_case, slice(None))
    groups, freq = layout(template)
    hyper = evidence(template, normal, None)
    theta = np.r_[np.log(hyper.amplitudes), np.log(hyper.length_scale), np.log(hyper.noise)]
    theta = theta + np.random.default_rng(0).normal(0, 0.3, theta.size)  # off the optimum too
    args = (normal.G, normal.b, normal.rr, normal.N, groups, freq)
    h = evidence_curvature(theta, normal.G, normal.b, normal.rr, groups, freq)
    step = 1e-5
    for i in range(theta.size):
        e = np.zeros_like(theta)
        e[i] = step
        fd = (nll_and_grad(theta + e, *args)[1][i] - nll_and_grad(theta - e, *args)[1][i]) / (2 * step)
        assert h[i] == pytest.approx(fd, rel=1e-5, abs=1e-6 * np.abs(h).max())


def test_fold_fits_from_the_curvature_end_nearer_their_optimum_in_fewer_evaluations(
    transmission_case, monkeypatch
):
    """Each fold's evidence maximisation from the hyperparameters found on all poses, as the
    cross-validation runs it (its tolerance), with and without the start's curvature: with
    it, fewer evaluations over the folds and the folds' ``−log E`` nearer their own optimum
    (found with a tight tolerance)."""
    import robocal.identify.residual.fit as fit
    from robocal.identify.residual.curvature import with_curvature
    from robocal.identify.residual.cv import FOLD_FTOL

    template, normal = _normal(transmission_case, slice(None))
    hyper = fit.evidence(template, normal, None)
    curved = with_curvature(hyper, normal, *fit.layout(template))
    assert curved == hyper and curved.curvature is not None  # the same hyperparameters
    calls = [0]
    nll, parts = fit.nll_and_grad, fit.nll_parts

    def counted(*args):
        calls[0] += 1
        return parts(*args)

    monkeypatch.setattr(fit, "nll_parts", counted)  # the search's evaluations (gradient on demand)
    n = len(transmission_case[0])
    totals, gaps = {"plain": 0, "curved": 0}, {"plain": [], "curved": []}
    for held in np.array_split(np.random.default_rng(1).permutation(n), 5):
        fold, fold_normal = _normal(transmission_case, np.setdiff1d(np.arange(n), held))
        args = (fold_normal.G, fold_normal.b, fold_normal.rr, fold_normal.N, *fit.layout(fold))

        def value(h: fit.Hyper, args: tuple = args) -> float:
            return nll(np.r_[np.log(h.amplitudes), np.log(h.length_scale), np.log(h.noise)], *args)[0]

        best = value(fit.evidence(fold, fold_normal, curved, ftol=1e-12))  # the fold's own optimum
        for label, start in (("plain", hyper), ("curved", curved)):
            calls[0] = 0
            found = fit.evidence(fold, fold_normal, start, ftol=FOLD_FTOL)
            totals[label] += calls[0]
            gaps[label].append(value(found) - best)
    assert totals["curved"] < totals["plain"]  # 10 against 21
    assert np.mean(gaps["curved"]) < 0.7 * np.mean(gaps["plain"])  # 0.10 against 0.25
    assert min(gaps["curved"]) > -1e-6 * abs(best)  # no lower than the optimum: the same problem
