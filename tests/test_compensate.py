"""Compensation: corrected joint commands, calibration filter, paths, program files."""

import dataclasses
import json

import numpy as np
import pytest

import robocal as rc
from robocal import spatial
from robocal.compensate import (
    TargetFileError,
    compensate_cartesian_path,
    compensate_path,
    compensate_targets,
    filter_program,
    nominal_model,
    read_program,
    read_targets,
)
from robocal.compensate.safety import sigma_min
from robocal.measure import (
    LaserTracker,
    VirtualRobot,
    draw_true_model,
    line_path,
    random_poses,
    simulate,
)
from robocal.model.dynamics import gravity_torques

TOOL = np.array([0.0, 0.0, 0.1])


def _closed_loop(robot, result, n_targets=150, seed=7):
    """Targets in the cell frame, compensated with ``result``, executed and measured on
    the virtual robot: mean measured residual after and before (m), the compensation."""
    q_reach = random_poses(robot.nominal, n_targets, seed=seed)
    # away from singular configurations, where corrections are damped or refused (test_safe_commands)
    q_reach = q_reach[sigma_min(robot.nominal, q_reach, None, "pose") > 0.05]
    targets = robot.device.predict(robot.T_base_tool(q_reach)).position  # reachable by the real arm
    comp = compensate_targets(result, targets, frame="measurement")
    after = simulate(robot, comp.q, seed=seed + 1).position
    before = simulate(robot, comp.q_nominal, seed=seed + 2).position
    return (
        np.linalg.norm(after - targets, axis=1).mean(),
        np.linalg.norm(before - targets, axis=1).mean(),
        comp,
    )


# ---------------------------------------------------------------- closed loop (issue acceptance)
@pytest.fixture(scope="module")
def ur10_geometric():
    """A UR10 with 2 mm / 0.2° errors, calibrated on 100 tracker poses, held-out on 200."""
    nominal = rc.robot("ur10")
    true = draw_true_model(nominal, length=2e-3, angle=np.radians(0.2), seed=3)
    robot = VirtualRobot(nominal, true, LaserTracker(p_tool_target=TOOL))
    data = simulate(robot, random_poses(nominal, 300, seed=1), seed=1)
    result = rc.calibrate(nominal, data.subset(np.arange(100)), tool_guess=TOOL)
    held_out = rc.validate(result, data.subset(np.arange(100, 300)))
    return robot, result, held_out


def test_closed_loop_residual_falls_to_the_held_out_error(ur10_geometric):
    robot, result, held_out = ur10_geometric
    after, before, comp = _closed_loop(robot, result)
    assert comp.success, comp.message
    assert before > 1e-3  # millimetre-level errors before compensation
    assert after <= 1.2 * held_out.mean, (after, held_out.mean)
    assert after <= before / 5
    # the predicted errors agree with what the executed commands did
    assert abs(comp.summary()["error_before_mm"]["mean"] - before * 1e3) < 0.05
    assert comp.error_after.max() < 1e-6


class _GravityCompliance:
    """The real arm gives way under its own weight: δθ_j = −c_j τ_j(q)."""

    def __init__(self, c):
        self.c = np.asarray(c, dtype=float)

    def __call__(self, model, q):
        d = np.zeros((len(q), model.dof, 3))
        d[:, :, 2] = -self.c * gravity_torques(model, q)
        return d


@pytest.fixture(scope="module")
def ur10_compliant():
    nominal = rc.robot("ur10")
    true = draw_true_model(nominal, length=2e-3, angle=np.radians(0.2), seed=4)
    effect = _GravityCompliance([0, 2e-5, 3e-5, 2e-5, 0, 0])  # up to ~2.4 mrad at the shoulder
    robot = VirtualRobot(nominal, true, LaserTracker(p_tool_target=TOOL), joint_effects=effect)
    data = simulate(robot, random_poses(nominal, 300, seed=2), seed=2)
    result = rc.calibrate(nominal, data.subset(np.arange(100)), tool_guess=TOOL, compliance=True)
    held_out = rc.validate(result, data.subset(np.arange(100, 300)))
    return robot, result, held_out


def test_closed_loop_with_joint_effects_iterates_to_the_fixed_point(ur10_compliant):
    robot, result, held_out = ur10_compliant
    after, before, comp = _closed_loop(robot, result, seed=9)
    assert comp.success, comp.message
    assert after <= 1.2 * held_out.mean, (after, held_out.mean)
    assert after <= before / 5
    # ignoring the joint effects leaves the compliance uncorrected
    targets = robot.device.predict(robot.T_base_tool(comp.q)).position
    geometric = compensate_targets(result, targets, frame="measurement", joint_effects=lambda q: None)
    measured = simulate(robot, geometric.q, seed=3).position
    assert np.linalg.norm(measured - targets, axis=1).mean() > 5 * held_out.mean


# ---------------------------------------------------------------- exactness, branches, limits
def test_commands_reach_targets_on_the_calibrated_model_in_the_nominal_branch():
    nominal = rc.robot("puma560")
    real = draw_true_model(nominal, length=2e-3, angle=np.radians(0.2), seed=5)
    q_ref = random_poses(nominal, 40, seed=4)
    q_ref = q_ref[sigma_min(nominal, q_ref, None, "pose") > 0.05]  # not damped (test_safe_commands)
    T = nominal.fk(q_ref)
    comp = compensate_targets(real, T, nominal, q0=q_ref, restarts=0)
    assert comp.success, comp.message
    assert np.abs(spatial.pose_error(real.fk(comp.q), T)).max() < 1e-9
    # the correction is small and keeps the configuration: elbow (q3) and wrist (q5) signs
    assert comp.joint_change.max() < 0.2
    assert np.array_equal(np.sign(comp.q[:, [2, 4]]), np.sign(comp.q_nominal[:, [2, 4]]))
    np.testing.assert_allclose(comp.q_nominal, q_ref, atol=1e-6)  # the nominal IK kept q0's branch
    assert comp.error_before.min() > 1e-4 and comp.error_after.max() < 1e-6


def test_position_targets_and_errors_before():
    nominal = rc.robot("li2016_3dof")
    real = draw_true_model(nominal, length=3e-3, angle=np.radians(1.0), seed=1)
    q = np.array([[0.1, -1.0, 0.2], [-0.3, -0.8, 0.4]])
    p = nominal.fk(q)[:, :3, 3]
    comp = compensate_targets(real, p, nominal, q0=q)
    np.testing.assert_allclose(real.fk(comp.q)[:, :3, 3], p, atol=1e-9)
    expected_before = np.linalg.norm(real.fk(comp.q_nominal)[:, :3, 3] - p, axis=1)
    np.testing.assert_allclose(comp.error_before, expected_before, rtol=1e-9)
    assert comp.kind == "position" and np.all(comp.angle_after == 0)
    # a bare model with no nominal model: the errors before are unknown
    alone = compensate_targets(real, p, q0=q)
    assert np.isnan(alone.error_before).all() and alone.success


def test_unreachable_and_joint_limit_targets_are_flagged():
    nominal = rc.robot("ur10")
    real = draw_true_model(nominal, length=2e-3, angle=np.radians(0.2), seed=6)
    q = np.radians([[0, -90, 90, 0, 90, 0], [10, -80, 70, 10, 80, 0]])
    p = nominal.fk(q)[:, :3, 3]
    far = np.array([[3.0, 0.0, 0.0]])
    comp = compensate_targets(real, np.vstack([p, far]), nominal, q0=q[0])
    assert comp.reachable.tolist() == [True, True, False]
    assert not comp.success and "not reached: 3" in comp.message
    # a pose target whose correction needs joint 1 beyond a limit placed at the nominal value
    T = nominal.fk(q[:1])
    free = compensate_targets(real, T, nominal, q0=q[:1])
    assert free.success and abs(free.q[0, 0] - q[0, 0]) > 1e-5
    up = free.q[0, 0] > q[0, 0]
    limits = (q[0, 0] - 1.0, q[0, 0]) if up else (q[0, 0], q[0, 0] + 1.0)

    def limited(model):
        steps = tuple(
            dataclasses.replace(s, joint=dataclasses.replace(s.joint, limits=limits))
            if s.joint is not None and s.joint.name == model.joint_names[0]
            else s
            for s in model.steps
        )
        return dataclasses.replace(model, steps=steps)

    limited = compensate_targets(limited(real), T, limited(nominal), q0=q[:1])
    assert limits[0] <= limited.q[0, 0] <= limits[1]
    assert not limited.reachable[0] and limited.error_after[0] > 1e-5


def test_measurement_frame_targets(ur10_geometric):
    robot, result, _ = ur10_geometric
    q = random_poses(robot.nominal, 10, seed=12)
    p_base = result.model.fk(q)[:, :3, 3]
    p_cell = p_base @ result.frame[:3, :3].T + result.frame[:3, 3]
    a = compensate_targets(result, p_cell, frame="measurement", q0=q)
    b = compensate_targets(result, p_base, frame="base", q0=q)
    np.testing.assert_allclose(a.q, b.q, atol=1e-8)
    np.testing.assert_allclose(a.targets[:, :3, 3], b.targets[:, :3, 3], atol=1e-12)
    with pytest.raises(ValueError, match="needs a CalibrationResult"):
        compensate_targets(result.model, p_cell, frame="measurement")
    with pytest.raises(ValueError, match="frame must be"):
        compensate_targets(result, p_cell, frame="tracker")


def test_nominal_model_of_a_result(ur10_geometric):
    _, result, _ = ur10_geometric
    nom = nominal_model(result)
    catalog = rc.robot("ur10")
    for name in catalog.names:
        assert nom.step(name).value == pytest.approx(catalog.step(name).value, abs=1e-15)
    assert [s.name for s in nom.steps if s.name.startswith("tcp_")] == ["tcp_x", "tcp_y", "tcp_z"]
    # a nominal model without the tool gets the calibrated tool appended
    q = random_poses(catalog, 5, seed=3)
    T = result.model.fk(q)
    comp = compensate_targets(result, T[:, :3, 3], catalog, q0=q)
    assert comp.success
    assert np.abs(comp.error_before).max() < 0.02  # the nominal robot with the calibrated tool


def test_errors_name_the_problem():
    model = rc.robot("ur10")
    with pytest.raises(ValueError, match="positions"):
        compensate_targets(model, np.zeros((3, 2)))
    with pytest.raises(ValueError, match="target 1 contains NaN"):
        compensate_targets(model, np.array([[0.5, 0, 0.5], [np.nan, 0, 0]]))
    with pytest.raises(ValueError, match="has 3 joints"):
        compensate_targets(model, np.zeros((1, 3)), rc.robot("li2016_3dof"))
    with pytest.raises(TypeError, match="CalibrationResult or a Model"):
        compensate_targets("ur10", np.zeros((1, 3)))
    with pytest.raises(ValueError, match=r"expected \(n, 6\)"):
        filter_program(model, np.zeros((2, 5)))


# ---------------------------------------------------------------- calibration filter
def test_filter_program_puts_the_real_tool_where_the_nominal_program_meant(ur10_compliant):
    robot, result, _ = ur10_compliant
    program = random_poses(robot.nominal, 60, seed=21)
    # away from singular configurations (near them the corrected pose may lie outside the
    # nominal branch's reach: flagged, see test_unreachable_and_joint_limit_targets_are_flagged)
    sigma_min = np.linalg.svd(robot.nominal.joint_jacobian(program), compute_uv=False)[:, -1]
    program = program[sigma_min > 0.05][:30]
    out = filter_program(result, program)
    assert out.kind == "pose" and out.success, out.message
    meant = nominal_model(result).fk(program)
    real = result.predict(out.q, frame=np.eye(4))  # the calibrated robot, joint effects included
    err = spatial.pose_error(real, meant)
    assert np.abs(err[:, :3]).max() < 1e-8 and np.abs(err[:, 3:]).max() < 1e-8
    assert out.error_before.mean() > 1e-3
    np.testing.assert_array_equal(out.q_nominal, program)


# ---------------------------------------------------------------- paths
def _ur10_line(n=120):
    nominal = rc.robot("ur10")
    q0 = np.radians([0, -90, 90, -90, -90, 0])
    T0 = nominal.fk(q0)
    P = line_path(T0[:3, 3] + [-0.3, -0.2, -0.1], T0[:3, 3] + [0.3, 0.2, 0.2], n)
    T = np.repeat(T0[None], n, axis=0)
    T[:, :3, 3] = P
    return nominal, q0, T


def test_path_correction_by_ik_and_by_eq_5_22_is_smooth():
    nominal, q0, T = _ur10_line()
    real = draw_true_model(nominal, length=2e-3, angle=np.radians(0.2), seed=3)
    ik = compensate_cartesian_path(real, T, nominal, method="ik", q0=q0)
    assert ik.success and ik.smooth, ik.summary()
    assert np.abs(spatial.pose_error(real.fk(ik.q), T)).max() < 1e-9
    one = compensate_cartesian_path(real, T, nominal, method="jacobian", q0=q0)
    three = compensate_cartesian_path(real, T, nominal, method="jacobian", q0=q0, iterations=3)
    assert one.error_before.mean() > 3e-3
    assert one.error_after.max() < 0.01 * one.error_before.max()  # one linear step: ~1 % left
    assert three.error_after.max() < 1e-9
    np.testing.assert_allclose(three.q, ik.q, atol=1e-8)
    for path in (ik, one):
        # no jumps: the corrected path bends like the nominal one
        d2_nominal = np.abs(np.diff(path.q_nominal, 2, axis=0)).max()
        d2_corrected = np.abs(np.diff(path.q, 2, axis=0)).max()
        assert d2_corrected < 1.05 * d2_nominal
        assert path.correction_step.max() < 0.01 * np.abs(path.correction).max() + 1e-6


def test_eq_5_22_matches_an_independent_pseudo_inverse_step():
    """Δθ = Jᵀ (J Jᵀ)⁻¹ (P_pred − P_theor) with J by finite differences (5-axis arm, 3 rows)."""
    nominal = rc.robot("katana450")
    # the geometry alone: a bare model's stated joint effects (the catalog Katana's) deflect its
    # commands too (compensation.model_perturbations), which these formulas leave out
    real = dataclasses.replace(
        draw_true_model(nominal, length=1e-3, angle=np.radians(0.1), seed=2), joint_effects=()
    )
    q = np.radians([[10, 40, -60, 30, 20], [-20, 60, -80, 40, -10]])
    P = nominal.fk(q)[:, :3, 3]
    out = compensate_path(real, q, nominal, method="jacobian", kind="position")
    for i in range(len(q)):
        h = 1e-7
        J = np.stack(
            [(real.fk(q[i] + h * e)[:3, 3] - real.fk(q[i] - h * e)[:3, 3]) / (2 * h) for e in np.eye(5)],
            axis=1,
        )
        dtheta = J.T @ np.linalg.solve(J @ J.T, real.fk(q[i])[:3, 3] - P[i])
        np.testing.assert_allclose(out.q[i], q[i] - dtheta, atol=1e-9)
    with pytest.raises(ValueError, match="not 'axis'"):
        compensate_path(real, q, nominal, method="jacobian", kind="axis")


def test_joint_path_of_a_five_axis_arm_with_axis_targets():
    nominal = rc.robot("katana450")
    # the geometry alone: a bare model's stated joint effects (the catalog Katana's) deflect its
    # commands too (compensation.model_perturbations), which these formulas leave out
    real = dataclasses.replace(
        draw_true_model(nominal, length=1e-3, angle=np.radians(0.1), seed=2), joint_effects=()
    )
    s = np.linspace(0, 1, 60)[:, None]
    q_path = np.radians([10, 50, -70, 20, 10]) + s * np.radians([30, 10, -10, 20, 30])
    out = compensate_path(real, q_path, nominal, kind="axis")
    assert out.success and out.smooth, out.message
    T = nominal.fk(q_path)
    T_real = real.fk(out.q)
    np.testing.assert_allclose(T_real[:, :3, 3], T[:, :3, 3], atol=1e-9)
    np.testing.assert_allclose(np.einsum("ij,ij->i", T_real[:, :3, 2], T[:, :3, 2]), 1.0, atol=1e-12)


# ---------------------------------------------------------------- files
def test_read_targets_units_orientation_and_separators(tmp_path):
    f = tmp_path / "t.csv"
    f.write_text("# cell program\nname;x;y;z;qw;qx;qy;qz\nA;100,5;-20;300;1;0;0;0\nB;0;0;250;0;0;0;2\n")
    t = read_targets(f, length_unit="mm", decimal=",")
    assert t.names == ("A", "B") and t.kind == "pose"
    np.testing.assert_allclose(t.values[:, :3, 3], [[0.1005, -0.02, 0.3], [0, 0, 0.25]])
    np.testing.assert_allclose(t.values[1, :3, :3], np.diag([-1.0, -1.0, 1.0]), atol=1e-15)  # normalised
    g = tmp_path / "p.csv"
    g.write_text("x,y,z\n1,2,3\n")
    p = read_targets(g)
    assert p.kind == "position" and p.names == ("1",) and p.values.shape == (1, 3)


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("name,x,y\nA,1,2\n", "missing column"),
        ("name,x,y,z\nA,1,two,3\n", r"row 2, column 'y': 'two' is not a number"),
        ("name,x,y,z,qw,qx\nA,1,2,3,1,0\n", "needs all of qw, qx, qy, qz"),
        ("name,x,y,z,qw,qx,qy,qz\nA,1,2,3,0,0,0,0\n", "row 2, columns qw..qz: the quaternion is zero"),
        ("name,x,y,z\nA,1,2\n", "row 2: 3 fields"),
        ("name,x,y,z\n", "no targets"),
    ],
)
def test_read_targets_errors_name_row_and_column(tmp_path, text, match):
    f = tmp_path / "bad.csv"
    f.write_text(text)
    with pytest.raises(TargetFileError, match=match) as err:
        read_targets(f)
    assert str(f) in str(err.value)


def test_read_program(tmp_path):
    f = tmp_path / "prog.csv"
    f.write_text("name,q1,q2,q3\nhome,0,90,-45\n")
    names, q = read_program(f, 3, angle_unit="deg")
    assert names == ("home",)
    np.testing.assert_allclose(q, np.radians([[0, 90, -45]]))
    with pytest.raises(TargetFileError, match="missing joint column"):
        read_program(f, 4)
    with pytest.raises(TargetFileError, match="q3 but the robot has 2"):
        read_program(f, 2)


def test_write_csv_and_json(tmp_path):
    nominal = rc.robot("li2016_3dof")
    real = draw_true_model(nominal, length=3e-3, angle=np.radians(1.0), seed=1)
    q = np.array([[0.1, -1.0, 0.2], [-0.3, -0.8, 0.4]])
    comp = compensate_targets(real, nominal.fk(q)[:, :3, 3], nominal, q0=q, names=["a", "b"])
    path = comp.write(tmp_path / "out.csv", angle_unit="deg")
    lines = path.read_text().splitlines()
    assert lines[0] == (
        "name,q1,q2,q3,nominal_q1,nominal_q2,nominal_q3,predicted_error_before_mm,"
        "predicted_error_after_mm,expected_error_after_mm,reachable,status"
    )
    row = lines[1].split(",")
    assert row[0] == "a" and row[-2] == "true" and row[-1] == "corrected"
    np.testing.assert_allclose([float(v) for v in row[1:4]], np.degrees(comp.q[0]), rtol=1e-10)
    assert float(row[7]) == pytest.approx(comp.error_before[0] * 1e3, rel=1e-5)
    assert row[9] == "nan"  # a bare model carries no uncertainty to expect an error from
    data = json.loads(comp.write(tmp_path / "out.json").read_text())
    assert data["targets"][1]["name"] == "b" and data["units"]["revolute"] == "rad"
    assert data["summary"]["reachable"] == 2
    assert not list(tmp_path.glob(".*.tmp"))
