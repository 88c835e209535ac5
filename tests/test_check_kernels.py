"""The compiled checks of the data (robocal.identify.kernels.check) against the numpy
expressions they replace, and the messages of robocal.identify.guards.check_data."""

from __future__ import annotations

import numpy as np
import pytest

import robocal as rc
from robocal.identify.guards import CalibrationGuardError, check_data
from robocal.identify.kernels.check import data_ranges, position_errors
from robocal.measure.measurements import Measurements


@pytest.mark.parametrize("n", [1, 2, 57])
def test_data_ranges_match_numpy(n):
    rng = np.random.default_rng(n)
    q, y = rng.normal(size=(n, 6)), rng.normal(size=(n, 3))
    finite_q, finite_y, q_range, spread = data_ranges(q, y)
    assert finite_q and finite_y
    np.testing.assert_array_equal(q_range, q.max(axis=0) - q.min(axis=0))
    assert spread == np.max(y.max(axis=0) - y.min(axis=0))
    for bad in (np.nan, np.inf, -np.inf):
        q2, y2 = q.copy(), y.copy()
        q2[n // 2, 3], y2[n - 1, 1] = bad, bad
        assert data_ranges(q2, y)[:2] == (False, True)
        assert data_ranges(q, y2)[:2] == (True, False)


def test_check_data_names_the_rows_that_are_not_finite_and_data_that_does_not_move():
    robot = rc.robot("ur10")
    rng = np.random.default_rng(0)
    q = rng.uniform(-2, 2, (20, 6))
    y = robot.fk(q)[:, :3, 3]
    assert check_data(robot, Measurements(q=q, position=y)) == []
    q_bad = q.copy()
    q_bad[[4, 9], 2] = np.nan
    with pytest.raises(CalibrationGuardError, match=r"joint values are NaN or inf in row\(s\) 5, 10"):
        check_data(robot, Measurements(q=q_bad, position=y))
    y_bad = y.copy()
    y_bad[7, 0] = np.inf
    with pytest.raises(CalibrationGuardError, match=r"positions are NaN or inf in row\(s\) 8"):
        check_data(robot, Measurements(q=q, position=y_bad))
    still = q.copy()
    still[:, 5] = 0.3
    assert check_data(robot, Measurements(q=still, position=y)) == [
        f"joint(s) {robot.joint_names[5]} do not move in the data"
    ]
    with pytest.raises(CalibrationGuardError, match="the same joint values"):
        check_data(robot, Measurements(q=np.tile(q[:1], (5, 1)), position=y[:5]))
    with pytest.raises(CalibrationGuardError, match="do not change"):
        check_data(robot, Measurements(q=q, position=np.tile(y[:1], (20, 1))))


@pytest.mark.parametrize("rows", [3, 6])
def test_position_errors_match_numpy(rows):
    rng = np.random.default_rng(rows)
    r, sigma = rng.normal(scale=1e-4, size=(40, rows)), rng.uniform(1e-5, 3e-5, (40, 3))
    errors, median, squares, chi2, noise = position_errors(r, sigma)
    p = r[:, :3]
    np.testing.assert_allclose(errors, np.linalg.norm(p, axis=1), rtol=1e-15)
    assert median == np.median(errors)
    assert squares == pytest.approx(float(np.sum(p * p)), rel=1e-14)
    assert chi2 == pytest.approx(float(np.sum((p / np.maximum(sigma, 1e-300)) ** 2)), rel=1e-14)
    assert noise == pytest.approx(float(np.sum(sigma * sigma)), rel=1e-14)
    no_sigma = position_errors(r, np.zeros((0, 3)))
    np.testing.assert_array_equal(no_sigma[0], errors)
    assert no_sigma[1:3] == (median, squares) and no_sigma[3:] == (0.0, 0.0)


def test_fit_to_noise_from_sums_is_the_numpy_formula():
    from scipy.stats import chi2 as chi2_distribution

    from robocal.identify.noise_check import fit_to_noise  # re-exported from noise_check

    rng = np.random.default_rng(5)
    sigma = rng.uniform(1e-5, 3e-5, (60, 3))
    r = rng.normal(size=(60, 3)) * sigma * 1.3
    fit = fit_to_noise(r, sigma, 12)
    dof = 180 - 12
    chi2 = float(np.sum((r / sigma) ** 2))
    assert fit.dof == dof and fit.ratio == pytest.approx(np.sqrt(chi2 / dof), rel=1e-13)
    assert fit.p_value == pytest.approx(chi2_distribution.sf(chi2, dof), rel=1e-9)
    noise_ms = float(np.sum(sigma**2)) / 60 * dof / 180
    assert fit.noise_rms == pytest.approx(np.sqrt(noise_ms), rel=1e-13)
    unmodelled = np.sqrt(max(float(np.sum(r**2)) / 60 - noise_ms, 0.0)) if fit.p_value < 1e-3 else 0.0
    assert fit.unmodelled_rms == pytest.approx(unmodelled, rel=1e-12, abs=1e-300)


def test_the_outliers_from_the_kernel_sums_are_those_of_outlier_poses():
    from robocal.identify.diagnose import _outliers, outlier_poses

    rng = np.random.default_rng(11)
    r = rng.normal(scale=2e-5, size=(50, 3))
    r[[7, 31]] *= 40.0  # two glitches
    for sigma in (None, np.full((50, 3), 2e-5), np.full((50, 3), 4e-4)):  # the last: noise hides them
        errors, median, _, _, noise = position_errors(r, np.zeros((0, 3)) if sigma is None else sigma)
        found = _outliers(errors, median, None if sigma is None else noise)
        assert found == outlier_poses(errors, sigma)
        assert found == ([] if sigma is not None and sigma[0, 0] > 1e-4 else [7, 31])
