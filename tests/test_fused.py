"""The compiled stages (robocal.identify.fused) against the staged pipeline they replace
for position calibrations with Levenberg-Marquardt: the same identifiable set, screened and
pruned unknowns, estimates, σ, fit and checks, to round-off."""

from __future__ import annotations

import numpy as np
import pytest

import robocal as rc
import robocal.identify.kernels.fused as fused_kernels
from robocal.identify import fused
from robocal.identify.options import Pruning, Weights
from robocal.identify.stages import chi2_bounds, residual_variance
from robocal.measure import LaserTracker, VirtualRobot, draw_true_model, simulate
from robocal.measure.poses import random_poses

TOOL = np.array([0.05, 0.0, 0.109])


def _data(name: str, n: int, seed: int, sigma: float = 20e-6):
    model = rc.robot(name)
    device = LaserTracker(p_tool_target=TOOL, sigma=sigma)
    true = draw_true_model(model, seed=seed)
    poses = random_poses(model, n, seed=seed + 1)
    return model, simulate(VirtualRobot(model, true, device), poses, seed=seed + 2)


def _staged(monkeypatch, model, data, **options):
    with monkeypatch.context() as m:
        m.setattr(fused, "applies", lambda *args: False)
        return rc.calibrate(model, data, **options)


def _assert_same(fused_result, staged):
    a, b = fused_result, staged
    assert a.names == b.names

    def dropped(r):
        return [(d.name, d.reason, d.absorbed_by) for d in r.dropped], [d.sigma or 0.0 for d in r.dropped]

    assert dropped(a)[0] == dropped(b)[0]
    np.testing.assert_allclose(dropped(a)[1], dropped(b)[1], rtol=1e-9)
    np.testing.assert_allclose(a.estimates, b.estimates, rtol=1e-11, atol=1e-13)
    np.testing.assert_allclose(a.std, b.std, rtol=1e-9)
    np.testing.assert_allclose(a.covariance, b.covariance, rtol=1e-8, atol=1e-30)
    np.testing.assert_allclose(a.residuals, b.residuals, rtol=1e-9, atol=1e-13)
    assert a.condition_number == pytest.approx(b.condition_number, rel=1e-9)
    assert (a.success, a.message, a.iterations) == (b.success, b.message, b.iterations)
    assert a.diagnostics.evaluations == b.diagnostics.evaluations
    assert [(w.code, w.message) for w in a.warnings] == [(w.code, w.message) for w in b.warnings]


@pytest.mark.parametrize(
    ("name", "n", "seed", "options"),
    [
        ("ur10", 40, 1, {}),  # stated noise: the χ² test decides the variance
        ("ur10", 60, 2, {"weights": Weights("none")}),  # the variance estimated
        ("puma560", 50, 3, {}),
        # tight thresholds: unknowns screened before the fit and pruned after it
        ("ur10", 30, 4, {"pruning": Pruning(max_std=1e-7, max_std_ratio=1.3)}),
        ("irb2400", 80, 5, {"level": 1}),
    ],
)
def test_fused_stages_agree_with_the_staged_pipeline(monkeypatch, name, n, seed, options):
    model, data = _data(name, n, seed)
    calls = []
    original = fused.fit
    monkeypatch.setattr(fused, "fit", lambda *args: calls.append(1) or original(*args))
    result = rc.calibrate(model, data, **options)
    assert calls, "the compiled stages did not run"
    _assert_same(result, _staged(monkeypatch, model, data, **options))
    if options.get("pruning"):
        assert sum(d.reason == "poorly identifiable" for d in result.dropped) >= 2


def test_singular_covariance_falls_back_to_the_staged_functions(monkeypatch):
    """A status other than OK (a nearly singular covariance) leaves the state to the
    staged screening, fit and pruning: the same result."""
    model, data = _data("ur10", 40, 6)
    monkeypatch.setattr(fused_kernels, "OK", -1)  # every fused fit reports "not OK"
    result = rc.calibrate(model, data)
    _assert_same(result, _staged(monkeypatch, model, data))


def test_fused_stages_apply_only_to_position_lm_without_joint_effects():
    model, data = _data("ur10", 30, 7)
    seen = []
    original = fused.applies

    def spy(*args):
        seen.append(original(*args))
        return seen[-1]

    with pytest.MonkeyPatch.context() as m:
        m.setattr(fused, "applies", spy)
        rc.calibrate(model, data)
        rc.calibrate(model, data, loss="soft_l1")
        rc.calibrate(model, data, method="pinv")
    assert seen == [True, False, False]


def test_chi2_bounds_give_the_tail_probabilities_test():
    """The variance factor's χ² test by the bounds equals the test by tail probabilities."""
    import scipy.special

    rng = np.random.default_rng(0)
    for dof in (1.0, 4.0, 57.0, 2961.0):
        low, high = chi2_bounds(np.array([dof]))
        assert scipy.special.chdtrc(dof, high[0]) == pytest.approx(1e-3)
        assert scipy.special.chdtrc(dof, low[0]) == pytest.approx(1 - 1e-3)
        for chi2 in dof * rng.uniform(0.0, 3.0, 50):
            upper = scipy.special.chdtrc(dof, chi2)
            rejected = upper < 1e-3 or 1 - upper < 1e-3
            assert residual_variance(chi2, dof, True) == (chi2 / dof if rejected else 1.0)


def test_fused_kernels_pass_no_constants_to_the_shared_kernels():
    # numba compiles a kernel called with a constant (False, 3) a second time for that
    # literal: seconds of first-use compilation the staged path's Python calls would not
    # share (a warm cache hides it, so the source is checked)
    import ast
    import inspect

    shared = {
        "position_columns_transposed",
        "segment_data",
        "start",
        "propose",
        "accept",
        "screen",
        "normal_covariance",
        "_median",
    }
    tree = ast.parse(inspect.getsource(fused_kernels))
    calls = [c for c in ast.walk(tree) if isinstance(c, ast.Call) and getattr(c.func, "id", None) in shared]
    assert {c.func.id for c in calls} >= shared - {"_median"}
    constants = [(c.func.id, c.lineno) for c in calls for a in c.args if isinstance(a, ast.Constant)]
    assert not constants


def test_preference_puts_the_device_frame_then_the_tool_then_the_rest_in_chain_order():
    from robocal.identify.problem import measurement_chain
    from robocal.identify.stages import preference_columns, preference_order
    from robocal.model.steps import Role

    chain = measurement_chain(rc.robot("ur10"), np.eye(4), np.eye(4), "position", True)
    names = (*chain.free_names, "compliance_j2")  # an effect coefficient: no role, last
    order = preference_order(names, chain.roles)
    roles = [chain.roles.get(x) for x in order]
    n_device = roles.count(Role.DEVICE)
    n_tool = roles.count(Role.TOOL)
    assert n_device >= 6 and n_tool == 3
    assert set(roles[:n_device]) == {Role.DEVICE} and set(roles[n_device : n_device + n_tool]) == {Role.TOOL}
    assert order[-1] == "compliance_j2"
    rest = [x for x in names if chain.roles.get(x) not in (Role.DEVICE, Role.TOOL)]
    assert order[n_device + n_tool :] == rest  # chain order kept
    assert [names[i] for i in preference_columns(names, chain.roles)] == order


def test_first_pass_flags_a_jacobian_that_is_not_finite(monkeypatch):
    # the fused rank test hands such a problem to the staged one (which, here, sees the real
    # values: the NaN is only in the fused kernel's copy)
    model, data = _data("ur10", 20, 7)
    seen = []
    original = fused_kernels.first_pass

    def first_pass(data, values, *rest):
        bad = values.copy()
        bad[-1] = np.nan  # a tool coordinate: every row of the Jacobian is NaN
        out = original(data, bad, *rest)
        seen.append(out[-1])
        return out

    monkeypatch.setattr(fused_kernels, "first_pass", first_pass)
    monkeypatch.setattr(fused, "preference_subset", lambda *a: pytest.fail("a NaN Jacobian was rank-tested"))
    assert rc.calibrate(model, data).success
    assert seen == [False]


def _merged_reference(values, half):
    """The union of [v - half, v + half], one value at a time (the loop coverage replaced)."""
    out: list[list[float]] = []
    for v in np.sort(values[np.isfinite(values)]):
        if out and v - half <= out[-1][1]:
            out[-1][1] = float(v + half)
        else:
            out.append([float(v - half), float(v + half)])
    return tuple((lo, hi) for lo, hi in out)


def test_joint_coverage_is_the_union_of_the_poses_neighbourhoods():
    """The coverage every calibration records (numpy, not a loop over the poses): the same
    intervals as the one-value-at-a-time union, with ties, NaN, wrapped angles, no poses."""
    from robocal.identify.coverage import COVER_RAD, joint_coverage

    model = rc.robot("ur10")
    rng = np.random.default_rng(5)
    for k in range(200):
        q = rng.uniform(-7.0, 7.0, (int(rng.integers(0, 40)), model.dof))
        if k % 3 == 0:
            q = np.round(q * 5) / 5  # ties and touching neighbourhoods (0.2 apart = 2 x 0.1)
        if k % 4 == 0 and len(q):
            q[rng.integers(0, len(q)), rng.integers(0, model.dof)] = np.nan
        got = joint_coverage(model, q)
        wrapped = np.remainder(q + np.pi, 2 * np.pi) - np.pi
        assert got.intervals == tuple(_merged_reference(wrapped[:, j], COVER_RAD) for j in range(model.dof))


def test_measured_tool_derivative_is_exact():
    """The measured tool's point derivative (analytic, not finite differences): central
    differences of the chain product for rotations and translations; for a tool of
    translations its covariance is the fit's covariance block of those parameters."""
    from robocal import spatial
    from robocal.identify.measured_tool import _point_and_derivative, measured_tool

    rng = np.random.default_rng(2)
    for _ in range(50):
        motions = [str(m) for m in rng.choice(spatial.MOTIONS, int(rng.integers(1, 6)))]
        v = rng.normal(size=len(motions))
        p, J = _point_and_derivative(motions, v.tolist())
        np.testing.assert_allclose(p, spatial.chain_product(motions, v)[:3, 3], rtol=0, atol=1e-14)
        for k in range(len(v)):
            h = np.zeros(len(v))
            h[k] = 1e-6
            fd = (spatial.chain_product(motions, v + h) - spatial.chain_product(motions, v - h))[:3, 3] / 2e-6
            np.testing.assert_allclose(J[:, k], fd, rtol=0, atol=1e-8)
    model, data = _data("ur10", 40, 3)
    result = rc.calibrate(model, data, tool_guess=TOOL)
    tool = measured_tool(result)
    cols = [result.names.index(f"tcp_{a}") for a in "xyz"]
    np.testing.assert_array_equal(tool.covariance_m2, np.asarray(result.covariance)[np.ix_(cols, cols)])
