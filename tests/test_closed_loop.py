"""Closed loops with the DEFAULT calibration path (complete model, residual auto): a virtual
true robot executes what the controller does with robocal's output (nominal model -> joints
-> true FK) and lands within 3x the calibration's expected error."""

import numpy as np
import pytest

import robocal as rc
from robocal.compensate.compensation import compensate_targets
from robocal.compensate.safety import sigma_min
from robocal.measure import LaserTracker, VirtualRobot, draw_true_model, random_poses, simulate

TOOL = np.array([0.0, 0.0, 0.1])


def _calibrated(name: str, n: int = 60):
    nominal = rc.robot(name)
    true = draw_true_model(nominal, length=0.5e-3, angle=np.radians(0.05), seed=4)
    robot = VirtualRobot(nominal, true, LaserTracker(p_tool_target=TOOL))
    data = simulate(robot, random_poses(nominal, n, seed=2), seed=2)
    result = rc.calibrate(rc.calibration_model(name, "position"), data, residual="auto", tool_guess=TOOL)
    return robot, result


@pytest.mark.parametrize("name", ["ur10"])
def test_targets_and_joint_program_land_within_3x_expected_error(name):
    robot, result = _calibrated(name)
    q = random_poses(robot.nominal, 40, seed=9)
    q = q[sigma_min(robot.nominal, q, None, "pose") > 0.05][:12]
    # Cartesian targets in the cell (tracker) frame: where the true tool point should go
    goal = robot.device.predict(robot.T_base_tool(q)).position
    comp = compensate_targets(result, goal, frame="measurement", q0=q)
    assert comp.success, comp.refused
    # the controller commands comp.q; the true robot's tool point lands at
    landed = robot.device.predict(robot.T_base_tool(comp.q)).position
    error = np.linalg.norm(landed - goal, axis=1)
    expected = np.maximum(comp.expected_error_after, 2e-5)  # m; the tracker's noise floor
    assert np.all(error <= 3 * expected), (error, comp.expected_error_after)
    before = np.linalg.norm(robot.device.predict(robot.T_base_tool(comp.q_nominal)).position - goal, axis=1)
    assert error.mean() < before.mean() / 5
