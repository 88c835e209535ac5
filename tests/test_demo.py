"""``robocal demo``: the virtual robot's model, joint effects, compensation and the whole run."""

import json

import numpy as np
import pytest
from typer.testing import CliRunner

import robocal as rc
from robocal.cli import app
from robocal.demo import GravityCompliance, compensate_positions, complete_model, geometry_of
from robocal.model.dynamics import gravity_torques

runner = CliRunner()


@pytest.mark.parametrize("name", ["ur10", "puma560", "irb2400"])
def test_complete_model_reproduces_the_catalog_robot(name):
    catalog = rc.robot(name)
    built = complete_model(name, "position")
    q = np.random.default_rng(0).uniform(-2, 2, (20, catalog.dof))
    np.testing.assert_allclose(built.fk(q)[:, :3, 3], catalog.fk(q)[:, :3, 3], atol=1e-12)
    joints, tcp = geometry_of(catalog)
    assert len(joints) == catalog.dof and len(tcp.position) == 3


@pytest.mark.parametrize("name", ["ur10", "puma560"])
def test_complete_model_carries_the_masses_over(name):
    catalog = rc.robot(name)
    built = complete_model(name)
    q = np.random.default_rng(1).uniform(-2, 2, (10, catalog.dof))
    np.testing.assert_allclose(gravity_torques(built, q), gravity_torques(catalog, q), atol=1e-9)


def test_robot_without_masses_gets_a_payload():
    built = complete_model("irb2400", payload=5.0)
    assert [b.name for b in built.bodies] == ["payload"]
    tau = gravity_torques(built, np.zeros((1, 6)))
    assert abs(tau[0, 1]) > 1.0  # the payload loads the shoulder


def test_gravity_compliance_turns_joints_against_their_holding_torque():
    model = complete_model("ur10")
    q = np.random.default_rng(2).uniform(-2, 2, (5, 6))
    d = GravityCompliance({"shoulder_lift": 1e-5})(model, q)
    tau = gravity_torques(model, q)
    np.testing.assert_allclose(d[:, 1, 2], -1e-5 * tau[:, 1])
    assert np.all(d[:, [0, 2, 3, 4, 5], :] == 0) and np.all(d[:, :, :2] == 0)


def test_fallback_compensation_lands_on_the_targets(monkeypatch):
    model = complete_model("ur10")
    true = rc.measure.draw_true_model(model, length=1e-3, angle=np.radians(0.1), seed=3)
    robot = rc.measure.VirtualRobot(
        model,
        true,
        rc.measure.LaserTracker(p_tool_target=np.array([0, 0, 0.1])),
        GravityCompliance({"elbow": 6e-6}),
    )
    q = rc.measure.random_poses(model, 40, seed=5)
    result = rc.calibrate(
        model, rc.measure.simulate(robot, q, seed=1), tool_guess=[0, 0, 0.1], compliance=["elbow"]
    )
    q_nom = q[:4]
    targets = result.predict(q_nom, frame=np.eye(4))[:, :3, 3] + 2e-3  # 2 mm away from where it is
    monkeypatch.delattr(rc, "compensate_targets", raising=False)
    q_c, method = compensate_positions(result, targets, q_nom)
    assert method.startswith("inverse kinematics on the calibrated model")
    reached = result.predict(q_c, frame=np.eye(4))[:, :3, 3]
    assert np.abs(reached - targets).max() < 1e-6


def test_demo_command_runs_end_to_end(tmp_path):
    out = tmp_path / "demo"
    res = runner.invoke(app, ["demo", "--out", str(out), "--quick", "--json", "--n", "40"])
    assert res.exit_code == 0, res.output
    numbers = json.loads(res.output)
    held = numbers["held_out"]
    assert held["after"]["mean_mm"] < 0.1 * held["before"]["mean_mm"]
    assert held["after"]["mean_mm"] < held["geometric"]["mean_mm"]  # the joint effects matter
    # ... and the residuals said so: the geometric model leaves error beyond the tracker noise
    fit = numbers["fit_to_noise"]
    assert fit["geometric calibration"]["ratio"] > 2 > 1.3 > fit["geometry + joint compliance"]["ratio"]
    iso = numbers["iso9283"]
    assert iso["compensated commands"]["AP_max_mm"] < 0.1 * iso["nominal commands"]["AP_max_mm"]
    assert numbers["seconds"] > 0  # reported (its size: benchmarks, not a test on a shared machine)
    for name in ("report.html", "result.json", "model.yaml", "train.csv", "test.csv", "evaluation.json"):
        assert (out / name).is_file(), name
    page = (out / "report.html").read_text(encoding="utf-8")
    for ident in ("iso9283", "joint-effects", "compensation"):
        assert f"<section id='{ident}'>" in page
    assert "The calibration expected an RMS error of" in page and ": as expected.</p>" in page
    res = runner.invoke(app, ["report", str(out), "-o", str(tmp_path / "again.html")])
    assert res.exit_code == 0, res.output
    assert "<section id='iso9283'>" in (tmp_path / "again.html").read_text(encoding="utf-8")
    # validate without --data: the held-out poses written beside the result
    res = runner.invoke(app, ["validate", str(out), "--json"])
    assert res.exit_code == 0, res.output
    stats = json.loads(res.output)
    assert stats["n"] == numbers["held_out"]["after"]["n"]
    assert abs(stats["mean_mm"] - held["after"]["mean_mm"]) < 1e-6


def test_demo_rejects_unknown_robots():
    res = runner.invoke(app, ["demo", "nonesuch"])
    assert res.exit_code == 2 and "unknown robot" in res.output


def test_reproduce_seed000_builds_the_seed_models_and_calibrates_from_15_poses(tmp_path):
    from robocal.experiments import get

    numbers = get("seed000")(out=tmp_path, quick=True, verbose=False)
    assert set(numbers["robots"]) == {"puma560", "irb2400"}
    for r in numbers["robots"].values():
        assert r["all_links_match_the_seed"]
        assert [row["seed_equation"] for row in r["links"]] == [15, 16, 17, 16, 16, 16, 27]
        assert r["identified_parameters"] == r["jacobian_rank"] == numbers["seed"]["parameters_6dof_pose"]
        assert r["built_check"]["ok"] and 2 in r["catalog_dh_check"]["singular_links"]  # DH of parallel axes
        fifteen = r["fifteen_points"]
        assert fifteen["poses"] == 15
        assert fifteen["built (seed 000)"]["held_out_mean_mm"] < 0.05  # far below the seed's 0.5 mm
        assert fifteen["built (seed 000)"]["held_out_before_mean_mm"] > 1.0
    assert (tmp_path / "seed000.json").is_file() and (tmp_path / "puma560_report.html").is_file()
    json.loads((tmp_path / "seed000.json").read_text())


def test_demo_writes_to_the_home_directory_by_default_never_the_working_directory(tmp_path, monkeypatch):
    """The README's first command must leave a checkout clean: the default --out is ~/robocal-demo."""
    monkeypatch.setenv("HOME", str(tmp_path))
    earlier = tmp_path / "robocal-demo"
    earlier.mkdir()
    (earlier / "report.html").write_text("an earlier demo")
    res = runner.invoke(app, ["demo"])
    assert res.exit_code == 2 and str(earlier) in " ".join(res.output.split()) and "--force" in res.output


def test_the_log_reuses_the_tool_test_cube_moved_to_the_flange():
    """The simulated ISO log's cube is the demo's test cube (robot with its tool) moved back
    by the fixed tool orientation times the tool offset: the bare robot reaches its ISO
    poses, and each flange position plus R·tool is the tool's."""
    from robocal.demo import _Demo
    from robocal.measure.poses import iso9283_poses

    demo = _Demo("ur10", 0, True, 5)
    demo.build_model()
    demo.draw_robot()
    demo.plan_poses(20, 20)
    cube = demo._flange_cube()
    assert cube is not None and cube.side == demo.iso.cube.side
    flange = iso9283_poses(demo.nominal, cube, seed=0)
    R = np.asarray(demo.iso.orientation)
    np.testing.assert_allclose(flange.positions + R @ demo.tool, demo.iso.positions, atol=1e-12)
    T = demo.nominal.fk(flange.q)
    np.testing.assert_allclose(T[:, :3, 3], flange.positions, atol=1e-6)  # reached
