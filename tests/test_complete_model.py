"""The complete model by default: rc.calibration_model for every catalog robot, the
parameterisation warnings, and the simulated UR10 whose parallel axes are tilted."""

import json
import math

import numpy as np
import pytest
from typer.testing import CliRunner

import robocal as rc
from robocal.cli import app
from robocal.measure.dataset.writer import write_measurements
from robocal.measure.devices import LaserTracker
from robocal.measure.simulate import VirtualRobot, simulate
from robocal.measure.true_model import draw_true_model
from robocal.model.complete import geometry_from_model
from robocal.model.dynamics import gravity_torques
from robocal.model.singularity import check_model, parameterisation_warnings
from robocal.model.view import step_frames

TRACKER = rc.spatial.homogeneous(rc.spatial.rotvec_to_matrix([0.2, -0.1, 2.5]), [2.2, -1.1, 0.4])
PROBE = np.array([0.0, 0.0, 0.109])  # the T-Mac probe, 109 mm from the flange


def flat(text):
    """Output without Rich's line wrapping."""
    return " ".join(text.split())


def poses(model, n, seed):
    lim = np.clip(model.joint_limits, -np.pi, np.pi)
    return np.random.default_rng(seed).uniform(lim[:, 0], lim[:, 1], (n, model.dof))


def identification_rank(model, q, measure):
    """Numeric rank of the identification Jacobian (rotation columns and orientation rows
    in length units of the robot's size, as the builder scales them)."""
    T, J = model.fk_jacobian(q, rows=measure)
    size = max(float(np.abs(T[:, :3, 3]).max()), 0.1)
    free = [s for s in model.steps if s.free]
    J = J * np.array([size if s.is_rotation else 1.0 for s in free])
    if measure == "pose":
        J = J.reshape(len(q), 6, -1)
        J[:, 3:] *= size
        J = J.reshape(6 * len(q), -1)
    sv = np.linalg.svd(J, compute_uv=False)
    return int(np.sum(sv > 1e-9 * sv[0]))


@pytest.mark.parametrize("name", rc.robots())
def test_calibration_model_of_every_catalog_robot(name):
    catalog = rc.robot(name)
    model = rc.calibration_model(name, "pose")
    assert model.name == f"{catalog.name}_complete"
    assert "catalog model" in model.source and model.title
    assert model.joint_names == catalog.joint_names and model.joint_types == catalog.joint_types
    assert np.array_equal(model.joint_limits, catalog.joint_limits)
    R = sum(t == "revolute" for t in model.joint_types)
    expected = 4 * R + 2 * (model.dof - R) + 6
    q = poses(model, 60, seed=1)
    assert len(model.free_names) == expected
    assert identification_rank(model, q, "pose") == expected
    assert check_model(model, "pose").ok
    # the same robot: FK (pose), and the same gravity torques from the carried bodies
    T0, T1 = catalog.fk(q), model.fk(q)
    assert np.abs(T1[:, :3, 3] - T0[:, :3, 3]).max() < 1e-9
    assert np.abs(T1[:, :3, :3] - T0[:, :3, :3]).max() < 1e-9
    position = rc.calibration_model(name, "position")
    assert np.abs(position.fk(q)[:, :3, 3] - T0[:, :3, 3]).max() < 1e-9
    # the flange where the robot has it for position models too: a tool, probe or
    # orientation target in the flange frame means the same as on the controller
    assert np.abs(position.fk(q)[:, :3, :3] - T0[:, :3, :3]).max() < 1e-9
    assert not any(position.step(n).free for n in position.names if n.startswith("tool_r"))
    assert model.joint_effects == catalog.joint_effects
    assert len(model.bodies) == len(catalog.bodies)
    if catalog.bodies:
        for m in (model, position):
            assert np.abs(gravity_torques(m, q[:10]) - gravity_torques(catalog, q[:10])).max() < 1e-9
            assert [(b.name, b.mass) for b in m.bodies] == [(b.name, b.mass) for b in catalog.bodies]


def test_bodies_are_re_expressed_with_their_inertia():
    """A body with a full inertia tensor on a frame that the built model does not have keeps
    its world pose: same com and inertia in the base frame at any q."""
    import dataclasses

    from robocal.model.steps import Body

    catalog = rc.robot("ur10")
    body = Body("probe", "alpha3", 1.5, (0.1, -0.02, 0.05), (0.02, 0.03, 0.04, 0.001, -0.002, 0.003))
    catalog = dataclasses.replace(catalog, bodies=(*catalog.bodies, body))
    model = rc.calibration_model(catalog, "position")
    assert model.name == "ur10_complete"
    carried = model.bodies[-1]
    assert carried.frame != "alpha3" and carried.frame in model.names
    q = poses(model, 3, seed=5)
    for qk in q:
        F_old = step_frames(catalog, qk)[1 + catalog.names.index("alpha3")]
        F_new = step_frames(model, qk)[1 + model.names.index(carried.frame)]

        def world(b, F):
            Ixx, Iyy, Izz, Ixy, Ixz, Iyz = b.inertia
            inertia = np.array([[Ixx, Ixy, Ixz], [Ixy, Iyy, Iyz], [Ixz, Iyz, Izz]])
            return F[:3, :3] @ b.com + F[:3, 3], F[:3, :3] @ inertia @ F[:3, :3].T

        (c0, I0), (c1, I1) = world(body, F_old), world(carried, F_new)
        assert np.abs(c0 - c1).max() < 1e-12 and np.abs(I0 - I1).max() < 1e-12
    assert np.abs(gravity_torques(model, q) - gravity_torques(catalog, q)).max() < 1e-9
    assert np.abs(model.fk(q)[:, :3, 3] - catalog.fk(q)[:, :3, 3]).max() < 1e-12


def test_geometry_from_model_reads_axes_about_any_local_axis():
    """Joints about the x or y axis of their step, and a prismatic joint: the geometry
    reproduces the chain, and so does the model built from it."""
    from robocal.model.chain import Model
    from robocal.model.geometry import geometry_fk
    from robocal.model.steps import Joint, Step

    steps = (
        Step("Tz", "h", 0.3),
        Step("Rx", "j1", 0.1, joint=Joint("a", (-3, 3))),
        Step("Ty", "l1", 0.4),
        Step("Ry", "j2", -0.2, joint=Joint("b", (-2, 2))),
        Step("Tx", "l2", 0.25),
        Step("Rz", "tw", 0.3),
        Step("Tx", "j3", 0.05, joint=Joint("c", (0.0, 0.2))),
        Step("Tz", "l3", 0.1),
        Step("Rz", "j4", 0.0, joint=Joint("d", (-3, 3))),
        Step("Tx", "tool", 0.07),
    )
    model = Model("odd", steps)
    joints, tcp = geometry_from_model(model)
    assert [g.name for g in joints] == ["a", "b", "c", "d"]
    assert [g.type for g in joints] == ["revolute", "revolute", "prismatic", "revolute"]
    assert joints[2].limits == (0.0, 0.2)
    q = poses(model, 20, seed=2)
    q[:, 2] = np.random.default_rng(3).uniform(0, 0.2, 20)
    assert np.abs(geometry_fk(joints, tcp, q) - model.fk(q)).max() < 1e-12
    for measure in ("position", "pose"):
        built = rc.calibration_model(model, measure)
        assert np.abs(built.fk(q)[:, :3, 3] - model.fk(q)[:, :3, 3]).max() < 1e-12
    assert np.abs(rc.calibration_model(model, "pose").fk(q) - model.fk(q)).max() < 1e-12


def test_parameterisation_warnings():
    dh = rc.robot("ur10")
    warnings = parameterisation_warnings(dh, "position")  # its time: benchmarks/bench_checks.py
    assert len(warnings) == 1
    text = warnings[0]
    # the links between the parallel axes of joints 2, 3 and 4 (DH singular there)
    assert "link 2 (shoulder_lift → elbow" in text and "link 3 (elbow → wrist_1" in text
    assert "shoulder_lift, elbow, wrist_1" in text  # their tilts cannot be followed
    assert "link 1 " not in text and "link 4 " not in text
    assert "rc.calibration_model('ur10', 'position')" in text and "robocal calibrate ur10" in text
    for measure in ("position", "pose"):
        assert parameterisation_warnings(rc.calibration_model("ur10", measure), measure) == []
    # a model that is not in the catalog gets the generic fix
    import dataclasses

    other = dataclasses.replace(dh, name="my_arm")
    assert "rc.calibration_model(model, 'pose')" in parameterisation_warnings(other, "pose")[0]


# ------------------------------------------------------------------ the simulated UR10
def tilted_ur10(seed):
    """A UR10 twin (complete model) with 0.05° Hayati β tilts of joints 2 and 3 and small
    errors elsewhere, measured by a tracker in an unknown frame at the 109 mm probe."""
    nominal = rc.calibration_model("ur10", "position")
    true = draw_true_model(nominal, length=0.2e-3, angle=math.radians(0.01), seed=seed)
    tilt = math.radians(0.05)
    true = true.with_values(
        {"beta2": nominal.step("beta2").value + tilt, "beta3": nominal.step("beta3").value + tilt}
    )
    return VirtualRobot(nominal, true, LaserTracker(T_device_base=TRACKER, p_tool_target=PROBE, sigma=20e-6))


def probe_positions(robot, q):
    T = robot.T_base_tool(q)
    p = T[:, :3, :3] @ PROBE + T[:, :3, 3]
    return p @ TRACKER[:3, :3].T + TRACKER[:3, 3]


def test_tilted_parallel_axes_complete_model_reaches_the_cramer_rao_bound():
    """60 training poses, 500 held-out, over 5 twins: the complete model's held-out RMS
    (against the true probe positions) is the Cramér-Rao bound (the RMS its parameter
    covariance predicts); the plain DH chain is far from it."""
    squares = {"complete": [], "dh": [], "bound": []}
    for seed in range(5):
        robot = tilted_ur10(seed)
        train = simulate(robot, poses(robot.nominal, 60, 100 + seed), seed=200 + seed)
        q = poses(robot.nominal, 500, 300 + seed)
        y = probe_positions(robot, q)
        for key, model in (("complete", rc.calibration_model("ur10", "position")), ("dh", rc.robot("ur10"))):
            result = rc.calibrate(model, train, tool_guess=[0, 0, 0.109])
            error = np.linalg.norm(result.predict(q)[:, :3, 3] - y, axis=1)
            squares[key].append(np.mean(error**2))
            if key == "complete":
                squares["bound"].append(np.mean(result.position_uncertainty(q) ** 2))
    bound = math.sqrt(np.mean(squares["bound"]))
    complete = math.sqrt(np.mean(squares["complete"])) / bound
    dh = math.sqrt(np.mean(squares["dh"])) / bound
    print(f"held-out RMS / Cramér-Rao bound: complete {complete:.2f}, plain DH {dh:.1f}")
    assert 0.8 < complete <= 1.15, complete
    assert dh > 5, dh


def test_tilted_parallel_axes_through_the_cli(tmp_path):
    """The same scenario through ``robocal calibrate ur10`` (complete by default)
    and ``robocal validate``; ``--chain catalog`` warns and is far worse."""
    robot = tilted_ur10(0)
    write_measurements(simulate(robot, poses(robot.nominal, 60, 100), seed=200), tmp_path / "train.csv")
    write_measurements(simulate(robot, poses(robot.nominal, 500, 300), seed=400), tmp_path / "test.csv")
    runner = CliRunner()
    rms = {}
    for chain in ("complete", "catalog"):
        out = tmp_path / chain
        args = ["calibrate", "ur10", "--data", str(tmp_path / "train.csv"), "--tool", "0,0,109mm"]
        args += ["--residual", "none"]  # the physical model, whose covariance gives the bound
        args += ["--out", str(out)] + (["--chain", "catalog"] if chain == "catalog" else [])
        result = runner.invoke(app, args)
        assert result.exit_code == 0, result.output
        if chain == "complete":
            assert "model: ur10_complete, the complete model built from ur10's joint geometry" in flat(
                result.output
            )
            assert "warning: the ur10 chain" not in flat(result.output)
        else:
            assert "model: ur10, the catalog's chain (--chain catalog)" in flat(result.output)
            assert "link 2 (shoulder_lift → elbow" in flat(result.stdout)
        saved = rc.load_model(out / "model.yaml")
        assert saved.name == ("ur10_complete" if chain == "complete" else "ur10")
        result = runner.invoke(app, ["validate", str(out), "--data", str(tmp_path / "test.csv"), "--json"])
        assert result.exit_code == 0, result.output
        stats = json.loads(result.stdout)
        rms[chain] = stats["rms_mm"]
        if chain == "complete":
            assert stats["rms_mm"] <= 1.15 * stats["expected_rms_mm"], stats
    assert rms["catalog"] > 5 * rms["complete"], rms


def test_cli_chain_choice_for_pose_data_and_model_files(tmp_path):
    """Orientations in the file: the complete model for pose measurements (unless
    --measure position); a model file is calibrated as it is, with the warnings, or its
    complete model with --chain complete; --chain catalog is refused with --model."""
    import dataclasses

    from robocal.measure.measurements import Measurements

    robot = tilted_ur10(1)
    q = poses(robot.nominal, 60, 7)
    T = robot.T_base_tool(q)
    position = (T[:, :3, :3] @ PROBE + T[:, :3, 3]) @ TRACKER[:3, :3].T + TRACKER[:3, 3]
    orientation = TRACKER[:3, :3] @ T[:, :3, :3]
    data = write_measurements(
        Measurements(q=q, position=position, orientation=orientation), tmp_path / "p.csv"
    )
    runner = CliRunner()
    base = ["calibrate", "--data", str(data), "--tool", "0,0,109mm", "--residual", "none"]
    result = runner.invoke(app, [*base, "ur10", "--out", str(tmp_path / "a")])
    assert result.exit_code == 0, result.output
    assert "model: ur10_complete, the complete model built from ur10's joint geometry for pose" in flat(
        result.output
    )
    result = runner.invoke(app, [*base, "ur10", "--measure", "position", "--out", str(tmp_path / "b")])
    assert result.exit_code == 0, result.output
    assert "for position measurements" in flat(result.output)
    path = rc.save_model(dataclasses.replace(rc.robot("ur10"), name="my_ur10"), tmp_path / "my_ur10.yaml")
    result = runner.invoke(app, [*base, str(path), "--out", str(tmp_path / "c")])
    assert result.exit_code == 0, result.output
    assert "model: my_ur10, the model file's chain as it is" in flat(result.output)
    assert "warning: the my_ur10 chain cannot describe" in flat(result.stdout)
    assert "rc.calibration_model(model, 'pose')" in flat(result.stdout)
    result = runner.invoke(app, [*base, str(path), "--chain", "complete", "--out", str(tmp_path / "d")])
    assert result.exit_code == 0, result.output
    assert "model: my_ur10_complete" in flat(result.output) and "warning: the" not in flat(result.output)
    result = runner.invoke(app, [*base, str(path), "--chain", "catalog", "--out", str(tmp_path / "e")])
    assert result.exit_code != 0 and "--chain catalog is for a catalog ROBOT" in flat(result.output)
    result = runner.invoke(app, [*base, "ur10", "--chain", "dh", "--out", str(tmp_path / "f")])
    # a choice of robocal.choices: Typer's usage error names the option and the value
    assert result.exit_code == 2 and "--chain" in flat(result.output) and "dh" in flat(result.output)


def test_fleet_calibrates_the_complete_model_by_default(tmp_path):
    robot = tilted_ur10(2)
    folder = tmp_path / "fleet"
    folder.mkdir()
    for k in range(2):
        write_measurements(simulate(robot, poses(robot.nominal, 40, 10 + k), seed=k), folder / f"r{k}.csv")
    runner = CliRunner()
    base = ["fleet", "ur10", str(folder), "--workers", "0", "--tool", "0,0,109mm", "--no-progress"]
    base += ["--residual", "none"]
    result = runner.invoke(app, [*base, "--out", str(tmp_path / "complete")])
    assert result.exit_code == 0, result.output
    assert "the complete model built from ur10's joint geometry" in flat(result.output)
    assert rc.load_model(tmp_path / "complete" / "r1" / "model.yaml").name == "ur10_complete"
    result = runner.invoke(app, [*base, "--chain", "catalog", "--out", str(tmp_path / "catalog")])
    assert result.exit_code == 0, result.output
    assert rc.load_model(tmp_path / "catalog" / "r1" / "model.yaml").name == "ur10"


def test_model_build_takes_a_catalog_name_or_a_model_file(tmp_path):
    runner = CliRunner()
    result = runner.invoke(
        app, ["model", "build", "ur10", "--measure", "position", "-o", str(tmp_path / "a.yaml")]
    )
    assert result.exit_code == 0, result.output
    assert "R∥R (Motta 2005 eq. 17, Hayati)" in result.output
    assert rc.load_model(tmp_path / "a.yaml") == rc.calibration_model("ur10", "position")
    path = rc.save_model(rc.robot("puma560"), tmp_path / "puma.yaml")
    result = runner.invoke(app, ["model", "build", str(path), "-o", str(tmp_path / "b.yaml")])
    assert result.exit_code == 0, result.output
    built = rc.load_model(tmp_path / "b.yaml")
    assert built.name == "puma560_complete" and len(built.free_names) == 30
    assert built.bodies == rc.calibration_model(rc.robot("puma560"), "pose").bodies
    result = runner.invoke(app, ["model", "build", "no_such_robot", "-o", str(tmp_path / "c.yaml")])
    assert result.exit_code != 0 and "nor is it a catalog robot" in flat(result.output)
