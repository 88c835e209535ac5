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
    h = COVER_RAD
    q = np.zeros((3, 6))
    q[:, 1] = [-1.0, -1.0 + h, -1.0 + 4 * h]  # shoulder_lift: two islands, a gap of h between
    q[:, 0] = [math.pi - h / 4, 0.3, 0.3]  # shoulder_pan near +pi covers -pi + h / 2 too
    cov = joint_coverage(model, q)
    assert len(cov.intervals[1]) == 2
    gap = -1.0 + 2.5 * h  # 1.5 h from the neighbouring poses' values: 0.5 h beyond the cover
    why = cov.outside(np.array([[-math.pi + h / 2, gap, 0, 0, 0, 0], [0.3, -1.0 - 2 * h, 0, 0, 0, 0]]))
    assert "shoulder_pan" not in why[0] and why[0].startswith("shoulder_lift")
    assert f"{1.5 * h:.2g} rad" in why[0] and f"{2 * h:.2g} rad" in why[1]
    assert cov.outside(np.array([[0.3, -1.0 + 2 * h, 0, 0, 0, 0]])) == [""]
    assert cov.outside(np.array([[0.3 + 2 * math.pi, -1.0, 0, 0, 0, 0]])) == [""]  # a winding is no gap
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
    q_out[:, 1] = -0.2  # 0.8 rad beyond every pose's shoulder
    assert coverage_warnings(saved, q_in, ["a", "b"]) == []
    (line,) = coverage_warnings(saved, q_out, ["a", "b"])
    assert line.startswith("2 of 2") and "shoulder_lift" in line and f"{COVER_RAD:g} rad" in line


def test_filter_names_program_targets_outside_the_coverage(tmp_path):
    """A joint program whose target needs a shoulder value no calibration pose came near:
    the filter says so (a warning: exit 1 with --strict), the covered target is silent."""
    from typer.testing import CliRunner

    from robocal.cli import app

    nominal = rc.robot("ur10")
    true = draw_true_model(nominal, length=0.5e-3, angle=np.radians(0.05), seed=2)
    robot = VirtualRobot(nominal, true, LaserTracker(p_tool_target=TOOL))
    q = random_poses(nominal, 60, seed=4)
    q[:, 1] = np.random.default_rng(0).uniform(-1.6, -1.0, len(q))
    result = rc.calibrate(
        rc.calibration_model("ur10", "position"), simulate(robot, q, seed=4), tool_guess=TOOL, residual="none"
    )
    result.save(tmp_path / "cal")
    inside, outside = q[3].copy(), q[3].copy()
    outside[1] = -0.2
    program = tmp_path / "prog.csv"
    program.write_text(
        "name,q1,q2,q3,q4,q5,q6\n" + "\n".join(f"{n}," + ",".join(f"{v:.6f}" for v in row)
                                               for n, row in (("near", inside), ("far", outside))) + "\n"
    )  # fmt: skip
    run = CliRunner().invoke(
        app, ["filter", str(tmp_path / "cal"), str(program), "-o", str(tmp_path / "o.csv")]
    )
    assert run.exit_code == 0, run.output
    text = " ".join(run.output.split())
    assert "1 of 2 target(s)" in text and "far" in text and "shoulder_lift" in text
    strict = ["filter", str(tmp_path / "cal"), str(program), "-o", str(tmp_path / "s.csv"), "--strict"]
    assert CliRunner().invoke(app, strict).exit_code == 1
