"""A calibrated robot = robot chain, T_flange_tool, T_device_base, residual (issue 32 item 5):
the result's accessors compose to the saved model and measurement chain, and the measured
tool is told apart from the robot in one module only."""

import dataclasses
import re
from pathlib import Path

import numpy as np
import pytest

import robocal as rc
from robocal import spatial
from robocal.measure import LaserTracker, OpticalCMM, VirtualRobot, draw_true_model, random_poses, simulate
from robocal.model.flange_tool import split_tool
from robocal.model.steps import Role, Step

SRC = Path(__file__).resolve().parents[1] / "src" / "robocal"
FRAME = spatial.homogeneous(spatial.rotvec_to_matrix([0.1, -0.2, 0.7]), [1.8, -0.4, 0.2])
TOOL = np.array([0.01, 0.02, 0.12])


def _calibrate(measure: str, tool: bool) -> rc.CalibrationResult:
    model = rc.calibration_model(rc.robot("ur10"), measure)
    true = draw_true_model(model, length=1e-3, angle=np.radians(0.1), seed=5)
    target = TOOL if tool else np.zeros(3)
    if measure == "pose":
        device = OpticalCMM(T_device_base=FRAME, p_tool_target=target, working_range=None)
    else:
        device = LaserTracker(T_device_base=FRAME, p_tool_target=target)
    data = simulate(VirtualRobot(model, true, device), random_poses(model, 60, seed=2), seed=2)
    return rc.calibrate(model, data, **({"tool_guess": TOOL} if tool else {"tool": None}))


CASES = [("position", True), ("position", False), ("pose", True), ("pose", False)]


@pytest.fixture(scope="module", params=CASES, ids=lambda p: f"{p[0]}-{'tool' if p[1] else 'flange'}")
def result(request):
    return _calibrate(*request.param)


def test_the_accessors_compose_to_the_model_and_the_measurement_chain(result):
    q = random_poses(result.model, 25, seed=9)
    has_tool = result.T_flange_tool is not None
    assert has_tool == any(s.role is Role.TOOL for s in result.model.steps)
    assert not any(s.role is Role.TOOL for s in result.robot.steps)
    assert result.robot.residual is result.model.residual
    # robot ∘ tool = the saved model (robot + tool)
    tool = np.eye(4) if result.T_flange_tool is None else result.T_flange_tool
    np.testing.assert_allclose(result.robot.fk(q) @ tool, result.model.fk(q), rtol=0, atol=1e-12)
    # frame ∘ robot ∘ tool = the fit's measurement chain
    composed = result.compose_measurement_chain()
    np.testing.assert_allclose(composed.fk(q), result.measurement_chain.fk(q), rtol=0, atol=1e-12)
    np.testing.assert_allclose(
        result.T_device_base @ result.robot.fk(q) @ tool, composed.fk(q), rtol=0, atol=1e-12
    )


def test_a_tool_point_and_a_tool_frame_are_told_apart(result):
    if result.T_flange_tool is None:
        assert result.robot.steps == result.model.steps
        return
    # a position calibration's tool is a point (no rotation), a pose calibration's a frame
    rotation = result.T_flange_tool[:3, :3]
    if result.measure == "position":
        np.testing.assert_array_equal(rotation, np.eye(3))
    np.testing.assert_allclose(result.T_flange_tool[:3, 3], TOOL, atol=2e-3)


def test_split_then_join_gives_the_model_back():
    result = _calibrate("position", True)
    parts = split_tool(result.model)
    assert parts.on(parts.robot) == result.model
    assert split_tool(parts.robot).steps == ()  # the robot alone has no tool to split off


def test_a_tool_step_before_the_robot_s_end_is_refused():
    robot = rc.robot("ur5")
    odd = dataclasses.replace(robot, steps=(Step("Tz", "probe_z", 0.01, role=Role.TOOL), *robot.steps))
    with pytest.raises(ValueError, match="probe_z"):
        split_tool(odd)


# a strip of the measured tool: a filter of a model's steps by the tool role
STRIP = re.compile(r"role\s+is\s+(?:not\s+)?Role\.TOOL")


def test_the_measured_tool_is_split_off_in_one_module_only():
    texts = {str(path.relative_to(SRC)): path.read_text(encoding="utf-8") for path in SRC.rglob("*.py")}
    assert sorted(name for name, text in texts.items() if STRIP.search(text)) == ["model/flange_tool.py"]
    assert sorted(name for name, text in texts.items() if "def split_tool(" in text) == [
        "model/flange_tool.py"
    ]
    # the pipeline's and the batch's start from a calibrated model go through it too
    assert "split_tool(model)" in texts["identify/problem_setup.py"]
