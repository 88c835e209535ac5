"""The calibration's overhead cut in the compiled kernels and the model layer (issue 35):
the symmetric normal equations of the Levenberg-Marquardt kernels, the first pass's
contiguous columns, the rank test's absorbers and the steps' copies give what the
general code gave."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import robocal as rc
import robocal.identify.kernels.fused as fused_kernels
from robocal.identify.kernels import lm
from robocal.measure import LaserTracker, VirtualRobot, draw_true_model, simulate
from robocal.measure.poses import random_poses
from robocal.model import rank
from robocal.model.steps import Joint, Role, Step


def _reference_absorbers(norm, names, kept_cols, red_cols, coef, unexplained, threshold):
    """The absorbers as listed before (one Python sort per redundant column)."""
    listed = {c: [] for c in red_cols}
    for j, c in enumerate(red_cols):
        for kk, a in enumerate(kept_cols):
            if abs(coef[kk, j]) > threshold:
                listed[c].append((-abs(coef[kk, j]), kk, a, coef[kk, j]))
    return {
        c: rank.Dropped(
            names[c],
            "redundant",
            tuple((names[a], v * norm[c] / norm[a]) for _, _, a, v in sorted(pairs)),
            float(unexplained[j]),
        )
        for j, (c, pairs) in enumerate(listed.items())
    }


@pytest.mark.parametrize("p", [1, 2, 7, 8])
@pytest.mark.parametrize("transposed", [False, True])
def test_normal_equations_equal_the_general_product(p, transposed):
    rng = np.random.default_rng(p)
    J = rng.normal(size=(2, 41, p)) * np.logspace(0, 3, p)
    r = rng.normal(size=(2, 41))
    stack = np.ascontiguousarray(J.transpose(0, 2, 1)) if transposed else J
    cost, G, Jr = np.empty(2), np.empty((2, p, p)), np.empty((2, p))
    lm.start(r, stack, transposed, cost, G, Jr)
    for k in range(2):
        np.testing.assert_allclose(G[k], J[k].T @ J[k], rtol=1e-13, atol=1e-9)
        np.testing.assert_allclose(Jr[k], J[k].T @ r[k], rtol=1e-13, atol=1e-12)
        assert np.array_equal(G[k], G[k].T)  # mirrored, not computed twice
    np.testing.assert_allclose(cost, np.sum(r**2, axis=1), rtol=1e-14)


def test_a_nan_in_the_jacobian_still_stops_the_problem_unconverged():
    # NaN must reach the normal matrix (no "nnan" in the sums' fast-math flags): the damped
    # Cholesky factorisation then fails for every μ and the problem stops unconverged
    rng = np.random.default_rng(3)
    J = rng.normal(size=(1, 30, 4))
    J[0, 7, 2] = np.nan
    r = rng.normal(size=(1, 30))
    cost, G, Jr = np.empty(1), np.empty((1, 4, 4)), np.empty((1, 4))
    lm.start(r, J, False, cost, G, Jr)
    assert np.isnan(G[0, 2]).all() and np.isnan(G[0, :, 2]).all() and np.isnan(Jr[0, 2])
    step = np.empty(4)
    mu = lm.damped_step(G[0], Jr[0], 1e-3, np.empty((4, 4)), np.zeros((4, 4)), step)
    assert np.isnan(mu) and np.isnan(step).all()


def test_absorbers_listed_largest_first_ties_in_test_order():
    names = ("a", "b", "c", "d", "e", "f")
    norm = np.array([1.0, 2.0, 0.5, 4.0, 1.5, 3.0])
    kept_cols, red_cols = [0, 2, 3, 5], [4, 1]
    coef = np.array([[0.5, -0.02], [-0.5, 0.9], [0.04, -0.9], [0.7, 0.3]])  # ties: ±0.5, ±0.9
    unexplained = np.array([1e-9, 2e-9])
    got = rank._absorbers(norm, names, kept_cols, red_cols, coef, unexplained, 0.05)
    assert got == _reference_absorbers(norm, names, kept_cols, red_cols, coef, unexplained, 0.05)
    assert [a for a, _ in got[4].absorbed_by] == ["f", "a", "c"]  # 0.7, then the tie 0.5/-0.5 in test order
    assert [a for a, _ in got[1].absorbed_by] == ["c", "d", "f"]
    assert got[4].absorbed_by[0][1] == pytest.approx(0.7 * 1.5 / 3.0)


def test_absorbers_on_random_rank_tests_equal_the_reference():
    rng = np.random.default_rng(11)
    for _ in range(20):
        k, d = rng.integers(1, 9), rng.integers(1, 5)
        coef = np.round(rng.normal(size=(k, d)), 1)  # rounded: ties happen
        norm = rng.uniform(0.1, 3.0, k + d)
        cols = rng.permutation(k + d).tolist()
        names = tuple(f"p{i}" for i in range(k + d))
        args = (norm, names, cols[:k], cols[k:], coef, rng.uniform(0, 1e-8, d), 0.05)
        assert rank._absorbers(*args) == _reference_absorbers(*args)


def test_the_rank_test_of_a_calibration_names_the_same_absorbers():
    # two columns exact combinations of earlier ones: each dropped, absorbed by those it is made of
    model = rc.calibration_model("ur10")
    rng = np.random.default_rng(5)
    J = rng.normal(size=(90, 4))
    A = np.column_stack([J, J[:, 0] + 2 * J[:, 1], J[:, 2] - J[:, 3] * 0.3])
    A = A / np.linalg.norm(A, axis=0)
    names = model.names[:6]
    subset = rank.preference_subset(A, list(range(6)), np.ones(6), np.zeros(6, dtype=bool), names)
    assert subset.kept == names[:4]
    assert [d.name for d in subset.dropped] == list(names[4:])
    for d in subset.dropped:
        assert d.reason == "redundant" and d.residual < 1e-10
    assert {a for a, _ in subset.dropped[0].absorbed_by} == {names[0], names[1]}
    assert {a for a, _ in subset.dropped[1].absorbed_by} == {names[2], names[3]}


def test_a_step_copy_is_a_checked_step_with_the_new_value():
    step = Step("Rz", "theta2", 0.1, free=True, bounds=(-1.0, 1.0), joint=Joint("q2", (-3.0, 3.0)))
    moved = step._with_value(0.25)
    assert moved == Step("Rz", "theta2", 0.25, free=True, bounds=(-1.0, 1.0), joint=Joint("q2", (-3.0, 3.0)))
    assert hash(moved) == hash(Step("Rz", "theta2", 0.25, bounds=(-1.0, 1.0), joint=Joint("q2", (-3.0, 3.0))))
    assert step.value == 0.1 and moved.role is Role.KINEMATIC
    fixed = moved._with_free(False)
    assert (fixed.free, fixed.value, moved.free) == (False, 0.25, True)
    with pytest.raises(AttributeError):
        fixed.value = 1.0  # still frozen
    with pytest.raises(ValueError, match="theta2"):
        step._with_value(float("nan"))


@pytest.mark.parametrize("sigma", [20e-6, None])
def test_the_fused_fit_returns_its_last_evaluation_weighted_and_its_covariance(monkeypatch, sigma):
    # the fit weights each evaluation straight into the transposed layout of the LM kernels
    # and hands the result those of the last accepted evaluation (not weighted a second
    # time): they must be its residuals and Jacobian weighted, and the covariance σ̂²(JᵀJ)⁻¹
    # of that Jacobian
    data, result, ((data_tuple, *_), out) = _spied_fit(monkeypatch, stated_noise=sigma is not None)
    weights = data_tuple[2]
    T, r, J, rw, Jw = out[12]
    np.testing.assert_array_equal(rw, r * weights)
    np.testing.assert_array_equal(Jw, J * weights[:, None])
    s2, cov = out[13][0], out[13][1]
    np.testing.assert_allclose(cov, s2 * np.linalg.inv(Jw.T @ Jw), rtol=1e-7, atol=0)
    np.testing.assert_allclose(result.residuals.ravel(), r, rtol=0, atol=1e-15)
    np.testing.assert_allclose(T[:, :3, 3] - data.position, r.reshape(-1, 3), rtol=0, atol=1e-15)


def _spied_fit(monkeypatch, n_poses=40, stated_noise=True):
    """The data, the result, and the arguments and result of the one fused fit of a
    simulated UR10 calibration (``stated_noise`` False: the variance estimated)."""
    model = rc.robot("ur10")
    device = LaserTracker(p_tool_target=np.array([0.05, 0.0, 0.109]), sigma=20e-6)
    robot = VirtualRobot(model, draw_true_model(model, seed=3), device)
    data = simulate(robot, random_poses(model, n_poses, seed=4), seed=5)
    if not stated_noise:
        data = dataclasses.replace(data, sigma=None)
    seen = []
    original = fused_kernels.fit

    def spy(*args):
        seen.append((args, original(*args)))
        return seen[-1][1]

    monkeypatch.setattr(fused_kernels, "fit", spy)
    result = rc.calibrate(model, data)
    assert len(seen) == 1
    return data, result, seen[0]


def test_a_fit_without_an_accepted_step_returns_the_start_weighted(monkeypatch):
    # no evaluation budget: no step is taken, and the result's evaluation is the first
    # pass's over the live columns, weighted as the accepted ones are
    _, _, (args, _) = _spied_fit(monkeypatch)
    data, values0, free_steps, live, first = args[:5]
    out = fused_kernels.fit(data, values0, free_steps, live, first, args[5], args[6], 0, args[8])
    assert out[8] == 0 and len(out[11]) == 1  # not converged, the start's RMS only
    T, r, J, rw, Jw = out[12]
    weights, final = data[2], out[5]
    np.testing.assert_array_equal(T, first[0])
    np.testing.assert_array_equal(r, first[1])
    np.testing.assert_array_equal(J, first[2][:, final])
    np.testing.assert_array_equal(rw, first[1] * weights)
    np.testing.assert_array_equal(Jw, first[2][:, final] * weights[:, None])


@pytest.mark.parametrize("scale, partial", [(1.7, False), (1.7, True), (0.0, False)])
def test_the_first_pass_unit_columns_are_the_scaled_weighted_columns(monkeypatch, scale, partial):
    # the sums of squares run along the scaled columns written as rows in test order, and
    # the unit-norm columns overwrite those rows (moved up past zero columns: a length scale
    # of 0 makes every angle's column zero; a preference may leave columns out)
    _, _, (args, _) = _spied_fit(monkeypatch)
    data, values0, free_steps = args[:3]
    step_rot = data[4]
    preference = np.arange(len(free_steps))[::-1].copy()
    if partial:
        preference = preference[::2].copy()
    first = fused_kernels.first_pass(data, values0, free_steps, scale, preference)
    J, norm, zero, ordered, At, finite = first[2:]
    assert finite
    free_scale = np.where(step_rot[free_steps], scale, 1.0)
    S = J * data[2][:, None] * free_scale
    np.testing.assert_allclose(norm, np.sqrt(np.sum(S**2, axis=0)), rtol=1e-14, atol=0)
    assert np.array_equal(zero, norm <= 1e-12 * norm.max())
    if scale == 0.0:  # a zero column before a non-zero one in test order: rows move up
        in_order = zero[preference]
        assert in_order.any() and not in_order[np.argmax(in_order) :].all()
    assert np.array_equal(ordered, [a for a in preference if not zero[a]])
    np.testing.assert_array_equal(At, (S[:, ordered] / norm[ordered]).T)


@pytest.mark.parametrize("seed", range(4))
def test_the_rank_kernel_skipping_r_zeros_fits_dropped_columns_as_numpy(seed):
    # the kernel's products skip the rows below each column of R (zeros there): the kept
    # mask, the dropped columns' coefficients and what they leave as the dense numpy form
    from robocal.model import rank_kernels

    rng = np.random.default_rng(seed)
    B = rng.normal(size=(60, 9))
    A = np.column_stack([B, B[:, :4] @ rng.normal(size=(4, 3)), rng.normal(size=(60, 2))])
    A = A[:, rng.permutation(A.shape[1])]
    A /= np.linalg.norm(A, axis=0)
    qr = np.asfortranarray(np.linalg.qr(A, mode="raw")[0].T)
    diag, keep, coefs, left, explained = rank_kernels.sequential_test(qr, 1e-7)
    ref = rank.sequential_test_numpy(qr, 1e-7)
    assert explained and ref[4] and keep.sum() == 11
    assert np.array_equal(keep, ref[1]) and np.array_equal(diag, ref[0])
    np.testing.assert_allclose(coefs, ref[2], rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(left, ref[3], rtol=0, atol=1e-12)
    np.testing.assert_allclose(A[:, keep] @ coefs, A[:, ~keep], rtol=0, atol=1e-10)
