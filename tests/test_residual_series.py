"""The learned residual's Fourier series by recurrences (robocal.model.residual): the basis by
Chebyshev's three-term recurrence and the angle errors by Clenshaw's summation must equal the
series written out with np.cos / np.sin of h·q, to 1e-12, at every harmonic the CV grid uses,
near the recurrences' worst angles (0 and ±π) and across the blocks angle_errors works in.
Also: a streamed calibration's per-pose residuals, kept from its last pass, are the calibrated
robot's predictions minus the measurements."""

import numpy as np
import pytest

import robocal as rc
from robocal.identify.options import CalibrationOptions
from robocal.identify.streaming import ChunkedProblem
from robocal.identify.streaming_calibrate import Streaming, chunk_problems
from robocal.measure.measurements import Measurements
from robocal.model.residual import SERIES_CHUNK, JointAngleResidual, fourier_basis, fourier_series


def _angles(n, k, seed=0):
    """Angles (rad) ``(n, k)``: uniform over two turns, plus the recurrences' worst cases."""
    rng = np.random.default_rng(seed)
    q = rng.uniform(-2 * np.pi, 2 * np.pi, (n, k))
    worst = np.array([0.0, 1e-9, -1e-9, np.pi, -np.pi, np.pi - 1e-9, 2 * np.pi, 0.5 * np.pi])
    q[: len(worst)] = worst[:, None]
    return q


def _written_out(q, coef):
    """``Σ_h a cos(h q) + b sin(h q)`` ``(n, k)`` with np.cos / np.sin of h·q, harmonic by harmonic."""
    h = np.arange(1, coef.shape[1] + 1)
    hq = q[:, :, None] * h  # (n, k, H)
    return np.sum(np.cos(hq) * coef[:, :, 0] + np.sin(hq) * coef[:, :, 1], axis=2)


@pytest.mark.parametrize("harmonics", [1, 2, 8, 48, 64])
def test_basis_recurrence_equals_cos_and_sin_of_h_q(harmonics):
    q = _angles(3000, 4)
    B = fourier_basis(q, harmonics)
    h = np.arange(1, harmonics + 1)
    assert B.shape == (3000, 4, 2 * harmonics)
    np.testing.assert_allclose(B[:, :, 0::2], np.cos(q[:, :, None] * h), rtol=0, atol=1e-12)
    np.testing.assert_allclose(B[:, :, 1::2], np.sin(q[:, :, None] * h), rtol=0, atol=1e-12)


@pytest.mark.parametrize("harmonics", [1, 3, 24, 64])
def test_clenshaw_series_equals_the_series_written_out(harmonics):
    q = _angles(3000, 3, seed=1)
    coef = np.random.default_rng(2).normal(0.0, 1.0, (3, harmonics, 2))
    total = np.abs(coef).sum(axis=(1, 2))  # the bound's scale per joint
    got = fourier_series(np.cos(q), np.sin(q), coef)
    assert np.all(np.abs(got - _written_out(q, coef)) <= 1e-12 * total)
    # one harmonic alone is that harmonic's cosine / sine
    unit = np.zeros_like(coef)
    unit[:, -1, 1] = 1.0
    np.testing.assert_allclose(fourier_series(np.cos(q), np.sin(q), unit), np.sin(harmonics * q), atol=1e-12)


def _learned(harmonics, joints=(1, 2, 4), seed=3):
    k, m = len(joints), len(joints) * 2 * harmonics
    rng = np.random.default_rng(seed)
    return JointAngleResidual(
        joints=tuple(f"j{j}" for j in joints), joint_index=tuple(joints), harmonics=harmonics,
        coefficients=rng.normal(0.0, 1e-4, m), covariance=np.zeros((m, m)), noise_std=1e-5,
        amplitudes=(1e-4,) * k, length_scale=0.05,
    )  # fmt: skip


@pytest.mark.parametrize("covered", [False, True])
def test_angle_errors_equal_the_faded_series_written_out(covered):
    n = 2 * SERIES_CHUNK + 37  # several blocks, the last one short
    q = _angles(n, 6, seed=4)
    learned = _learned(48)
    if covered:  # a gap in every joint's coverage: the angle errors fade there, all but the first harmonics
        inside = q[np.all(np.abs(q) < 2.0, axis=1) | (np.arange(n) < 8)]
        learned = learned.covering(inside[np.abs(inside[:, 1]) > 0.5])
        assert learned.global_harmonics == 2
    coef = learned.coefficients.reshape(3, 48, 2)
    angles = q[:, list(learned.joint_index)]
    g = learned.global_harmonics if covered else 0
    fading = coef.copy()
    fading[:, :g] = 0.0
    expected = _written_out(angles, coef[:, :g]) + _written_out(angles, fading) * learned.fade(q)
    got = learned.angle_errors(q)
    assert got.shape == (n, 3)
    assert np.abs(got - expected).max() <= 1e-12 * np.abs(coef).sum()
    if covered:  # the fade is real: some poses lose their higher harmonics
        assert np.any(learned.fade(q) < 1.0) and np.any(learned.fade(q) == 1.0)
    # perturbations carry them as δθ of their joints, nothing else
    P = learned.perturbations(q[:100], 6)
    np.testing.assert_array_equal(P[:, list(learned.joint_index), 2], got[:100])
    assert not np.any(np.delete(P, list(learned.joint_index), axis=1)) and not np.any(P[:, :, :2])


def _tracker_data(n, seed=7):
    model = rc.calibration_model("ur10")
    true = rc.measure.draw_true_model(model, length=1e-3, angle=np.radians(0.05), seed=seed)
    rng = np.random.default_rng(seed)
    lim = np.clip(model.joint_limits, -np.pi, np.pi)
    q = rng.uniform(lim[:, 0], lim[:, 1], (n, model.dof))
    T = true.fk(q)
    position = T[:, :3, :3] @ np.array([0.0, 0.0, 0.1]) + T[:, :3, 3]
    sigma = np.tile(rng.uniform(10e-6, 40e-6, (n, 1)), (1, 3))  # per-pose weights 1/σ
    position = position + rng.normal(0.0, 1.0, (n, 3)) * sigma
    return model, Measurements(q=q, position=position, sigma=sigma)


def test_streamed_residuals_from_the_last_pass_are_the_predictions_minus_the_measurements():
    model, data = _tracker_data(1400)
    streaming = Streaming(threshold=1000, subsample=600, chunk=500)
    result = rc.calibrate(model, data, tool_guess=[0.0, 0.0, 0.1], streaming=streaming)
    assert result.diagnostics.streaming is not None and result.model.residual is None
    predicted = result.predict(data.q)[:, :3, 3]
    np.testing.assert_allclose(result.residuals, predicted - data.position, rtol=0, atol=1e-12)
    assert result.rms_after == pytest.approx(np.sqrt(np.mean(np.sum(result.residuals**2, axis=1))), rel=1e-12)


def test_chunked_problem_keeps_residuals_only_for_its_last_point():
    model, data = _tracker_data(1100, seed=8)
    reference = rc.calibrate(model, data, tool_guess=[0.0, 0.0, 0.1])
    problems = chunk_problems(reference, data, CalibrationOptions())
    x = np.asarray(reference.estimates, dtype=float)
    kept = ChunkedProblem(problems, data.n, 400, keep_residuals=True)
    kept.normal_equations(x)
    np.testing.assert_allclose(kept.residuals_at(x), reference.residuals, rtol=0, atol=1e-12)
    moved = x + 1e-6
    kept.normal_equations(moved)
    assert kept.residuals_at(x) is None and kept.residuals_at(moved) is not None
    plain = ChunkedProblem(problems, data.n, 400)
    plain.normal_equations(x)
    assert plain.residuals_at(x) is None
