"""One tool, one set of units (issue 31 items 1 and 5): lengths on the command line carry
their unit, joint values in degrees are not read as radians, the measured tool a
calibration identifies is stored with it and used (a disagreeing one refused), a start value
the fit moved far is reported, and what the poses could not determine is warned about in
the calibration and again where a later command depends on it."""

from __future__ import annotations

import dataclasses
import json
import math

import numpy as np
import pytest
from typer.testing import CliRunner

import robocal as rc
from robocal import spatial
from robocal.cli.app import app
from robocal.identify.measured_tool import (
    MeasuredTool,
    check_tool,
    measured_tool,
    orientation_warnings,
    probe_for,
)
from robocal.measure.devices import LaserTracker
from robocal.measure.poses import poses_for_points, random_poses
from robocal.measure.simulate import VirtualRobot, simulate
from robocal.measure.true_model import draw_true_model
from robocal.units import parse_quantities

runner = CliRunner()
TOOL = np.array([0.0, 0.0, 0.1])  # the probe as built, m
EXAMPLES = rc.__file__.rsplit("/src/", 1)[0] + "/examples/programs"


def _text(res) -> str:
    return " ".join(res.output.split())


# ---------------------------------------------------------------------- units
def test_a_unit_closes_the_values_before_it():
    assert parse_quantities("0,0,109mm", ["length"] * 3, "--tool") == pytest.approx([0, 0, 0.109])
    assert parse_quantities("0,0,0.109m", ["length"] * 3, "--tool") == pytest.approx([0, 0, 0.109])
    frame = parse_quantities("0,0,100mm,0,0,90deg", ["length"] * 3 + ["angle"] * 3, "--tool")
    assert frame == pytest.approx([0, 0, 0.1, 0, 0, math.pi / 2])
    assert parse_quantities("5um,1 mm,0", ["length"] * 3, "x") == pytest.approx([5e-6, 1e-3, 0])


@pytest.mark.parametrize(
    ("text", "kinds", "says"),
    [
        ("0,0,109", ["length"] * 3, "add the unit"),  # mm or m? refused, not guessed
        ("0,0,0.1m,0,0,1.5", ["length"] * 3 + ["angle"] * 3, "add the unit"),
        ("0,0,109deg", ["length"] * 3, "not a length unit"),
        ("1,2mm", ["length"] * 3, "3 comma-separated values"),
        ("0,0,x mm", ["length"] * 3, "not a number"),
    ],
)
def test_a_bare_or_wrong_length_is_refused_in_one_line(text, kinds, says):
    with pytest.raises(ValueError, match=says) as err:
        parse_quantities(text, kinds, "--tool")
    assert str(err.value).startswith(f"--tool {text!r}") and "\n" not in str(err.value)


def test_bare_zeros_and_a_bare_unit_by_kind_are_accepted():
    assert parse_quantities("0,0,0", ["length"] * 3, "--probe") == [0.0, 0.0, 0.0]
    q = parse_quantities("0,-90,90", ["angle"] * 3, "--q0", bare={"angle": "deg"})
    assert q == pytest.approx([0, -math.pi / 2, math.pi / 2])


@pytest.mark.parametrize(
    "args",
    [
        ["calibrate", "ur10", "--data", "d.csv", "--tool", "0,0,109", "-o", "out"],
        ["simulate", "ur10", "--poses", "q.csv", "--tool-offset", "0,0,109", "-o", "sim.csv"],
        ["simulate", "ur10", "--poses", "q.csv", "--device-pose", "2000,0,500,0,0,180", "-o", "sim.csv"],
        ["poses", "ur10", "--method", "iso9283", "--region", "300,-400,200,900,400,800", "-o", "p.csv"],
    ],
)
def test_every_length_option_refuses_a_bare_number(args, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    rows = [f"{0.1 * k},0.2,0.3,0.4,0.5,0.6" for k in range(3)]
    (tmp_path / "d.csv").write_text("q1,q2,q3,q4,q5,q6,x,y,z\n" + "".join(f"{r},1,2,3\n" for r in rows))
    (tmp_path / "q.csv").write_text("q1,q2,q3,q4,q5,q6\n" + "".join(f"{r}\n" for r in rows))
    res = runner.invoke(app, args)
    assert res.exit_code == 2 and "add the unit" in _text(res) and "Traceback" not in res.output
    assert sorted(p.name for p in tmp_path.iterdir()) == ["d.csv", "q.csv"]  # nothing written


def test_q0_in_degrees_is_refused_or_understood(tmp_path):
    """The help's own example "0,-90,90,0,90,0" is not read as radians."""
    model = tmp_path / "ur10.yaml"
    rc.save_model(rc.robot("ur10"), model)
    targets = tmp_path / "t.csv"
    targets.write_text("name,x,y,z\np,0.6,-0.2,0.4\n")
    base = ["compensate", str(model), "--targets", str(targets), "--kind", "position"]
    res = runner.invoke(app, [*base, "--q0", "0,-90,90,0,90,0"])
    assert res.exit_code == 2 and "looks like degrees" in _text(res) and "--q0" in _text(res)
    solutions = []
    for q0, extra in (("0,-90,90,0,90,0deg", []), ("0,-90,90,0,90,0", ["--angle-unit", "deg"])):
        out = tmp_path / f"c{len(extra)}.csv"
        res = runner.invoke(app, [*base, "--q0", q0, *extra, "-o", str(out)])
        assert res.exit_code == 0, res.output
        header, row = (line.split(",") for line in out.read_text().splitlines()[:2])
        q = np.array([float(row[header.index(f"q{j}")]) for j in range(1, 7)])
        solutions.append(np.radians(q) if extra else q)
    assert np.all(np.abs(solutions[0]) <= 2 * math.pi)  # a configuration, not -90 rad
    assert np.allclose(solutions[0], solutions[1], atol=1e-6)  # "deg" and --angle-unit deg: one reading


# ---------------------------------------------------------------------- the measured tool
@pytest.fixture(scope="module")
def cal(tmp_path_factory):
    """A UR10 calibrated on simulated tracker data with a wrong stated tool (120 mm, the
    probe is at 100 mm), saved."""
    nominal = rc.robot("ur10")
    true = draw_true_model(nominal, seed=3)
    robot = VirtualRobot(nominal, true, LaserTracker(p_tool_target=TOOL))
    data = simulate(robot, random_poses(nominal, 120, seed=1), seed=1)
    model = rc.calibration_model("ur10", "position")
    result = rc.calibrate(model, data, tool_guess=[0.0, 0.0, 0.12])
    folder = tmp_path_factory.mktemp("cal") / "cal"
    return result.save(folder), folder


def test_the_identified_tool_is_stored_and_a_far_start_value_reported(cal):
    result, folder = cal
    tool = measured_tool(result)
    assert tool is not None and np.linalg.norm(np.asarray(tool.position_m) - TOOL) < 1.5e-3
    assert tool.given_m == pytest.approx((0.0, 0.0, 0.12))
    assert "tool-start" in {w.code for w in result.warnings}  # 20 mm from the fit
    assert any("120.00" in w.message for w in result.warnings if w.code == "tool-start")
    assert "120.00" in result.summary()
    saved = json.loads((folder / "result.json").read_text())
    assert saved["measured_tool"]["position_mm"] == pytest.approx(list(np.asarray(tool.position_m) * 1e3))
    assert saved["measured_tool"]["given_mm"] == pytest.approx([0, 0, 120])
    assert "tool-start" in saved["warning_codes"]
    from robocal.identify.result import CalibrationResult

    again = measured_tool(CalibrationResult.load(folder))
    assert again is not None and again.given_m == pytest.approx(tool.given_m)
    assert MeasuredTool.from_dict(tool.to_dict()).position_m == pytest.approx(tool.position_m)


def test_no_report_when_the_start_value_agrees(cal):
    result, _ = cal
    tool = measured_tool(result, given_m=np.asarray(measured_tool(result).position_m) + [0, 0, 1e-4])
    from robocal.identify.measured_tool import tool_start_warnings

    assert tool_start_warnings(tool) == []


def test_a_disagreeing_tool_is_refused_naming_both(cal):
    result, _ = cal
    tool = measured_tool(result)
    with pytest.raises(ValueError, match="disagrees") as err:
        check_tool(tool, [0.0, 0.0, 0.12], "--probe")
    assert "120.00" in str(err.value) and f"{tool.position_m[2] * 1e3:.2f}" in str(err.value)
    check_tool(tool, np.asarray(tool.position_m) + [0, 0, 3e-4], "--probe")  # within the floor
    T = probe_for(result, None)  # the stated 120 mm is refused: default, the identified tool
    assert np.allclose(np.asarray(T)[:3, 3], tool.position_m)


def test_a_stated_tool_within_the_flange_tolerance_is_the_default_probe(cal):
    """Within 2 mm the stated tool is the tool as built and the difference is the flange's
    (position measurements cannot separate them): the filter's default probe is the stated one."""
    result, _ = cal
    tool = measured_tool(result)
    near = np.asarray(tool.position_m) + [0.0, 0.0, 1.2e-3]
    stated = dataclasses.replace(tool, given_m=tuple(near))
    records = {**result.records, "measured_tool": stated.to_dict()}
    T = probe_for(dataclasses.replace(result, records=records), None)
    assert np.allclose(np.asarray(T)[:3, 3], near)
    check_tool(tool, near, "--probe")  # accepted: within the flange's tolerance
    with pytest.raises(ValueError, match="disagrees"):
        check_tool(tool, np.asarray(tool.position_m) + [0.0, 0.0, 2.5e-3], "--probe")


def test_filter_uses_the_identified_tool_and_refuses_another(cal, tmp_path):
    _, folder = cal
    out = tmp_path / "pick.script"
    args = ["filter", str(folder), f"{EXAMPLES}/pick.script", "-o", str(out)]
    res = runner.invoke(app, [*args, "--probe", "0,0,120mm"])
    assert res.exit_code == 2 and "120.00" in _text(res) and not out.exists()
    res = runner.invoke(app, args)
    assert res.exit_code == 0, res.output
    before = float(_text(res).split("predicted error ")[1].split(" mm")[0])
    assert before < 10.0  # the robot's error, not the 20 mm between the stated and measured tool


def test_compensate_before_is_the_robots_error_not_a_tool_change(cal):
    from robocal.compensate.compensation import nominal_model

    result, _ = cal
    nominal = nominal_model(result)
    q = random_poses(rc.robot("ur10"), 20, seed=5)
    moved = np.linalg.norm(result.model.fk(q)[:, :3, 3] - nominal.fk(q)[:, :3, 3], axis=1)
    assert moved.max() < 10e-3  # the UR10's errors: ±0.5 mm, ±0.05° per parameter; not 20 mm


# ---------------------------------------------------------------------- what the poses left open
@pytest.fixture(scope="module")
def one_orientation(tmp_path_factory):
    """ISO-cube-like poses: the tool pointing down within 0.1° at every pose."""
    nominal = rc.robot("ur10")
    rng = np.random.default_rng(0)
    points = np.array([0.6, -0.2, 0.4]) + rng.uniform(-0.25, 0.25, (80, 3))
    down = np.diag([1.0, -1.0, -1.0])
    q = []
    for k in range(8):
        R = spatial.rotvec_to_matrix(rng.normal(0, np.radians(0.1), 3)) @ down
        poses = poses_for_points(nominal, points[k * 10 : (k + 1) * 10], kind="pose", orientation=R)
        q.append(poses.q[poses.reachable])
    robot = VirtualRobot(nominal, draw_true_model(nominal, seed=2), LaserTracker(p_tool_target=TOOL))
    data = simulate(robot, np.vstack(q), seed=1)
    result = rc.calibrate(rc.calibration_model("ur10", "position"), data, tool_guess=TOOL)
    folder = tmp_path_factory.mktemp("iso") / "cal"
    return result.save(folder), folder


def test_parameters_the_poses_could_not_determine_are_warned(one_orientation):
    result, folder = one_orientation
    undetermined = [w.message for w in result.warnings if w.code == "undetermined"]
    assert undetermined, result.warning_texts
    poor = [d.name for d in result.dropped if d.reason == "poorly identifiable"]
    assert poor and all(name in undetermined[0] for name in poor)
    assert undetermined[0] in result.summary()
    assert "undetermined" in json.loads((folder / "result.json").read_text())["warning_codes"]
    from robocal.evaluate.report.facts import report_data_from_result

    assert undetermined[0] in report_data_from_result(result).warnings


def test_a_later_command_warns_for_another_tool_orientation(one_orientation, tmp_path):
    result, folder = one_orientation
    nominal = rc.robot("ur10")
    assert orientation_warnings(result, np.zeros((0, 6)), []) == []
    targets = tmp_path / "t.csv"
    targets.write_text(
        "name,x,y,z,qw,qx,qy,qz\ndown,0.6,-0.2,0.4,0,1,0,0\nside,0.7,-0.2,0.4,0.7071068,0,0.7071068,0\n"
    )
    out = tmp_path / "c.csv"
    res = runner.invoke(app, ["compensate", str(folder), "--targets", str(targets), "-o", str(out)])
    text = _text(res)
    assert "did not cover" in text and "side" in text.split("did not cover")[1]
    assert "down" not in text.split("did not cover")[1].split(";")[0]
    # a calibration that determined everything says nothing
    data = simulate(
        VirtualRobot(nominal, nominal, LaserTracker(p_tool_target=TOOL)),
        random_poses(nominal, 60, seed=4),
        seed=4,
    )
    varied = rc.calibrate(rc.calibration_model("ur10", "position"), data, tool_guess=TOOL)
    side = np.array([[0.0, -1.2, 1.5, 0.0, 0.3, 0.0]])
    assert orientation_warnings(varied, side, ["side"]) == []


def test_fk_refuses_degrees_read_as_radians():
    res = runner.invoke(app, ["fk", "ur10", "--q", "0,-90,90,0,90,0"])
    assert res.exit_code == 2 and "looks like degrees" in _text(res) and "--deg" in _text(res)
    res = runner.invoke(app, ["fk", "ur10", "--q", "0,-90,90,0,90,0", "--deg", "--json"])
    assert res.exit_code == 0
    T = rc.robot("ur10").fk(np.radians([0, -90, 90, 0, 90, 0]))
    np.testing.assert_allclose(json.loads(res.output)["T"], T, atol=1e-12)
