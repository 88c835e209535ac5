"""Streaming normal equations (robocal.identify.streaming) against the dense solver."""

import numpy as np
import pytest

import robocal as rc
from robocal.identify.problem import Problem
from robocal.identify.solvers import levenberg_marquardt
from robocal.identify.streaming import _PositionData, levenberg_marquardt_streaming, refit


@pytest.fixture(scope="module")
def simulated():
    model = rc.calibration_model("ur10")
    true = rc.measure.draw_true_model(model, length=1e-3, angle=np.radians(0.05), seed=2)
    robot = rc.measure.VirtualRobot(model, true, rc.measure.LaserTracker(p_tool_target=np.array([0, 0, 0.1])))
    data = rc.measure.simulate(robot, rc.measure.random_poses(model, 120, seed=4), seed=1)
    return model, data


def test_streaming_lm_equals_the_dense_solver(simulated):
    model, data = simulated
    calibration = rc.calibrate(model, data.subset(np.arange(60)), tool_guess=[0, 0, 0.1])
    chain = calibration.measurement_chain
    rng = np.random.default_rng(3)
    sigma = rng.uniform(0.5e-5, 2e-5, (data.n, 3))
    problem = Problem(chain, data.q, data.position, None, (1 / sigma).reshape(-1), 1.0)
    x0 = chain.free_values + rng.normal(0, 1e-4, len(chain.free_values))  # away from the optimum
    dense = levenberg_marquardt(problem, x0)
    stream, ne = levenberg_marquardt_streaming(_PositionData(chain, data.q, data.position, 1 / sigma, 17), x0)
    assert dense.success and stream.success
    assert stream.evaluations == dense.evaluations and stream.iterations == dense.iterations
    np.testing.assert_allclose(stream.x, dense.x, rtol=0, atol=1e-12 + 1e-9 * np.abs(dense.x).max())
    J = problem.jacobian(stream.x)
    np.testing.assert_allclose(ne.JtJ, J.T @ J, rtol=1e-10, atol=1e-6)


def test_refit_on_all_poses_from_a_subsample_calibration(simulated):
    model, data = simulated
    calibration = rc.calibrate(model, data.subset(np.arange(40)), tool_guess=[0, 0, 0.1])
    fit = refit(calibration, data.q, data.position, chunk=25)
    full = rc.calibrate(model, data, tool_guess=[0, 0, 0.1])
    assert fit.success and fit.n == data.n and fit.names == calibration.names
    # all poses: the dense calibration's fit (its own device-frame start, so compare predictions)
    assert fit.rms_after <= full.rms_after * 1.02
    predicted = fit.chain.fk(data.q)[:, :3, 3]
    dense = full.measurement_chain.fk(data.q)[:, :3, 3]
    assert np.abs(predicted - dense).max() < 3 * fit.residual_std
    assert fit.std.shape == (len(fit.names),) and np.all(fit.std > 0)
    with pytest.raises(ValueError, match="expected"):
        refit(calibration, data.q[:, :5], data.position)
