"""What the calibration poses covered in joint space (robocal.identify.coverage): recorded
with every calibration, and commands outside it named by compensate (issue 34 item 3)."""

import math

import numpy as np

import robocal as rc
from robocal.identify.coverage import COVER_RAD, JointCoverage, coverage_warnings, joint_coverage
from robocal.measure import LaserTracker, VirtualRobot, draw_true_model, random_poses, simulate

TOOL = np.array([0.05, 0.0, 0.1])


def test_joint_coverage_names_joints_beyond_every_pose_on_the_circle():
    model = rc.robot("ur10")
    q = np.zeros((3, 6))
    q[:, 1] = [-1.0, -0.95, -0.5]  # shoulder_lift: two islands
    q[:, 0] = [math.pi - 0.02, 0.3, 0.3]  # shoulder_pan near +pi covers -pi + 0.05 too
    cov = joint_coverage(model, q)
    assert len(cov.intervals[1]) == 2
    inside = np.zeros(6)
    inside[:2] = [-math.pi + 0.05, -0.7]  # pan: 0.07 rad from pi - 0.02 across the wrap
    why = cov.outside(np.array([inside, [0.3, -0.75, 0, 0, 0, 0], [0.3, -1.3, 0, 0, 0, 0]]))
    assert "shoulder_pan" not in why[0] and "shoulder_lift" in why[0]  # -0.7: 0.2 rad from -0.5
    assert why[1].startswith("shoulder_lift") and "0.2 rad" in why[1]
    assert "shoulder_lift" in why[2] and "0.3 rad" in why[2]
    assert cov.outside(np.array([[0.3, -0.97, 0, 0, 0, 0]])) == [""]
    assert cov.outside(np.array([[0.3 + 2 * math.pi, -0.5, 0, 0, 0, 0]])) == [""]  # a winding is no gap
    again = JointCoverage.from_dict(cov.to_dict())
    assert again == cov


def test_every_calibration_records_its_coverage_and_compensate_names_targets_outside(tmp_path):
    nominal = rc.robot("ur10")
    true = draw_true_model(nominal, length=0.5e-3, angle=np.radians(0.05), seed=2)
    robot = VirtualRobot(nominal, true, LaserTracker(p_tool_target=TOOL))
    q = random_poses(nominal, 60, seed=4)
    q[:, 1] = np.random.default_rng(0).uniform(-1.6, -1.0, len(q))  # the shoulder in 0.6 rad only
    data = simulate(robot, q, seed=4)
    result = rc.calibrate(rc.calibration_model("ur10", "position"), data, tool_guess=TOOL, residual="none")
    cov = JointCoverage.from_dict(result.records["coverage"])
    assert cov.joint_names == nominal.joint_names
    saved = rc.CalibrationResult.load(result.save(tmp_path / "cal") and tmp_path / "cal")
    q_in, q_out = q[:2].copy(), q[:2].copy()
    q_out[:, 1] = -0.4  # 0.6 rad beyond every pose's shoulder
    assert coverage_warnings(saved, q_in, ["a", "b"]) == []
    (line,) = coverage_warnings(saved, q_out, ["a", "b"])
    assert line.startswith("2 of 2") and "shoulder_lift" in line and f"{COVER_RAD:g} rad" in line
