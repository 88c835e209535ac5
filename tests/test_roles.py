"""Parameter roles are a field of the chain's steps (robocal.model.chain.Role), set where
steps are built, stored in model files, derived from the name for older files, and what
the code tests instead of name prefixes."""

from __future__ import annotations

import dataclasses
import re
from pathlib import Path

import numpy as np
import pytest
import yaml

import robocal as rc
from robocal.identify.problem import measurement_chain
from robocal.model.conventions import frame6, model_from_steps
from robocal.model.files import load_model, model_from_dict, model_to_dict, save_model
from robocal.model.joints import effect_of
from robocal.model.steps import Role, Step
from robocal.model.yaml_files import ModelFileError

SRC = Path(__file__).resolve().parents[1] / "src" / "robocal"


def test_the_measurement_chain_marks_device_frame_tool_and_robot():
    robot = rc.robot("ur10")
    chain = measurement_chain(robot, np.eye(4), np.eye(4), "pose", fit_frame=True)
    axes = ("x", "y", "z", "rz", "ry", "rx")
    device = tuple(f"frame0_{c}" for c in axes) + tuple(f"frame_{c}" for c in axes)  # start, correction
    assert chain.names_with_role(Role.DEVICE) == device
    assert chain.names_with_role(Role.TOOL) == tuple(f"tcp_{c}" for c in axes)
    assert chain.names_with_role(Role.KINEMATIC) == robot.names
    T = np.eye(4)
    T[:3, 3] = [1.0, 2.0, 0.5]  # a given device frame: fixed frame0_* steps only
    position = measurement_chain(robot, T, np.eye(4), "position", fit_frame=False)
    assert position.names_with_role(Role.DEVICE) == tuple(f"frame0_{c}" for c in axes)
    assert position.names_with_role(Role.TOOL) == ("tcp_x", "tcp_y", "tcp_z")


def test_measurement_chains_of_one_robot_share_its_structure_and_keep_their_own_values():
    robot = rc.robot("ur10")
    T_a, T_b = np.eye(4), np.eye(4)
    T_a[:3, 3], T_b[:3, 3] = [1.0, 2.0, 0.5], [-0.3, 0.4, 0.1]
    tool = np.eye(4)
    tool[:3, 3] = [0.01, 0.02, 0.15]
    a = measurement_chain(robot, T_a, tool, "position", fit_frame=True)
    b = measurement_chain(robot, T_b, tool, "position", fit_frame=True)
    assert a._plan is b._plan and a.free_names is b.free_names  # worked out once, for the robot
    assert [a.values[a._index[f"frame0_{c}"]] for c in "xyz"] == [1.0, 2.0, 0.5]
    assert [b.values[b._index[f"frame0_{c}"]] for c in "xyz"] == [-0.3, 0.4, 0.1]
    assert [b.values[b._index[f"tcp_{c}"]] for c in "xyz"] == [0.01, 0.02, 0.15]
    np.testing.assert_allclose(b.fk(np.zeros(6)), T_b @ robot.fk(np.zeros(6)) @ tool, atol=1e-12)
    other = dataclasses.replace(robot, name="ur10b")  # another robot: its own chain
    assert measurement_chain(other, T_a, tool, "position", fit_frame=True).name == "ur10b+measurement"


def test_roles_are_stored_and_read_back(tmp_path):
    robot = rc.robot("ur5")
    # a tool not named tcp_* and a robot step that happens to be: the roles, not the names, count
    probe = frame6("probe", 0.0, 0.0, 0.1, free=False, role=Role.TOOL)
    odd = [Step("Tz", "tcp_spacer", 0.01, role=Role.KINEMATIC)]
    model = model_from_steps("ur5+probe", [*odd, *robot.steps, *probe])
    path = save_model(model, tmp_path / "m.yaml")
    data = yaml.safe_load(path.read_text())
    stored = {s["param"]: s.get("role") for s in data["chain"]}
    assert stored["probe_x"] == "tool" and stored["tcp_spacer"] == "kinematic"
    assert stored["d1"] is None  # the robot's own steps stay as they were
    again = load_model(path)
    assert again == model
    assert again.roles["probe_rx"] is Role.TOOL and again.roles["tcp_spacer"] is Role.KINEMATIC


def test_older_files_without_roles_take_them_from_the_names():
    data = model_to_dict(measurement_chain(rc.robot("ur10"), np.eye(4), np.eye(4), "position", True))
    for step in data["chain"]:
        step.pop("role", None)
    model = model_from_dict(data, "old.yaml")
    assert model.roles["frame_rz"] is Role.DEVICE and model.roles["tcp_y"] is Role.TOOL
    assert model.roles["theta2"] is Role.KINEMATIC


def test_an_unknown_role_is_refused_naming_the_step():
    data = model_to_dict(rc.robot("ur10"))
    data["chain"][3]["role"] = "gripper"
    with pytest.raises(ModelFileError, match=r"bad\.yaml.*chain.*role"):
        model_from_dict(data, "bad.yaml")
    with pytest.raises(ValueError, match="step 'x': role 'gripper' is not one of kinematic, tool, device"):
        Step("Tx", "x", role="gripper")


def test_a_tool_is_stripped_by_its_role_not_its_name():
    from robocal.identify.problem_setup import without_measured_tool as _without_measured_tool

    robot = rc.robot("ur10")
    model = model_from_steps("ur10+probe", [*robot.steps, *frame6("probe", 0, 0, 0.1, role=Role.TOOL)])
    stripped, T_tool = _without_measured_tool(model)
    assert stripped.names == robot.names
    np.testing.assert_allclose(T_tool[:3, 3], [0, 0, 0.1])


def test_joint_effect_coefficients_are_read_in_one_place():
    assert effect_of("compliance_q2") == ("compliance", "q2")
    assert effect_of("radial_compliance_wrist_1") == ("radial", "wrist_1")
    assert effect_of("backlash_q1") == ("backlash", "q1")
    assert effect_of("theta2") is None


def test_no_role_is_told_by_a_name_prefix_any_more():
    """Role tests go through Step.role (and effect_of for joint-effect coefficients): a
    ``startswith`` on a role prefix outside the one reader of each is a regression."""
    prefix = re.compile(
        r"""startswith\(\s*\(?\s*(?:["'](?:tcp_|frame_|frame0_|compliance_|radial_compliance_|clearance_|"""
        r"""backlash_)|[A-Z_]*PREFIX)"""
    )
    # Role.from_name, effect_of; tilt_record.zero_channel reads the inclinometer channel zeros'
    # names (unknowns of the tilt rows, not steps of a chain: they have no role)
    allowed = {"model/steps.py", "model/joints.py", "identify/constraints/tilt_record.py"}
    found = [
        f"{path.relative_to(SRC)}:{n}"
        for path in sorted(SRC.rglob("*.py"))
        if str(path.relative_to(SRC)) not in allowed
        for n, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1)
        if prefix.search(line)
    ]
    assert not found, f"role tests by name prefix: {found}"


def test_the_model_package_exports_role_and_its_other_names():
    import robocal.model as m

    for name in m.__all__:  # "calibration_model" was once exported letter by letter
        assert getattr(m, name) is not None, name
    assert m.Role is Role
