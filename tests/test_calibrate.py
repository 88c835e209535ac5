"""Identification: convergence, the truth about uncertainty, and held-out validation."""

import dataclasses
import json
import math
from pathlib import Path

import numpy as np
import pytest

import robocal as rc
from robocal.identify.result import CalibrationResult
from robocal.identify.stages import screen_unidentifiable
from robocal.measure.devices import LaserTracker
from robocal.measure.measurements import Measurements
from robocal.measure.simulate import VirtualRobot, simulate
from robocal.measure.true_model import draw_true_model
from robocal.model.builder import load_geometry
from robocal.model.geometry import Tcp

GEOMETRY = Path(__file__).resolve().parents[1] / "examples" / "geometry"
TRACKER = rc.spatial.homogeneous(rc.spatial.rotvec_to_matrix([0.2, -0.1, 2.5]), [2.2, -1.1, 0.4])
TOOL = np.array([0.02, -0.01, 0.11])


@pytest.fixture(scope="module")
def irb2400():
    """A complete, minimal model (built from geometry) of an IRB 2400 whose TCP is off the
    last axis (where a probe would be), so that all 4R + 3 parameters are identifiable."""
    g = load_geometry(GEOMETRY / "irb2400.yaml")
    return dataclasses.replace(g, tcp=Tcp((0.03, -0.02, 0.12))).build("position").model


def poses(model, n, seed):
    lim = np.clip(model.joint_limits, -np.pi, np.pi)
    return np.random.default_rng(seed).uniform(lim[:, 0], lim[:, 1], (n, model.dof))


ANGLE_TOL = math.radians(0.05)


def virtual(model, seed, length=0.5e-3, angle=ANGLE_TOL, noise=20e-6, effects=None, params="free"):
    true = draw_true_model(model, length=length, angle=angle, seed=seed, params=params)
    device = LaserTracker(T_device_base=TRACKER, p_tool_target=TOOL, sigma=noise)
    return VirtualRobot(model, true, device, effects)


def true_positions(robot, q):
    """Noise-free positions of the target in the tracker frame."""
    T = robot.T_base_tool(q)
    p = T[:, :3, :3] @ TOOL + T[:, :3, 3]
    return p @ TRACKER[:3, :3].T + TRACKER[:3, 3]


def held_out_error(result, robot, q):
    y = true_positions(robot, q)
    return np.linalg.norm(result.predict(q)[:, :3, 3] - y, axis=1)


@pytest.mark.parametrize("method", ["lm", "pinv", "bounded", "influence"])
def test_every_method_converges_from_large_errors(irb2400, method):
    """Errors up to 5 mm and 2° on every identified parameter (seed 001's premise: its
    bounds are ±5 mm, ±2°), unknown tracker frame and tool."""
    q = poses(irb2400, 80, seed=4)
    identified = rc.calibrate(irb2400, simulate(virtual(irb2400, seed=0), q, seed=1)).names
    params = [name for name in identified if name in irb2400.names]
    assert len(params) >= 18
    robot = virtual(irb2400, seed=3, length=5e-3, angle=math.radians(2.0), noise=10e-6, params=params)
    data = simulate(robot, q, seed=5)
    result = rc.calibrate(irb2400, data, method=method, tool_guess=[0, 0, 0.1])
    assert result.success, result.message
    error = held_out_error(result, robot, poses(irb2400, 300, seed=6))
    assert result.rms_before > 5e-3  # millimetres of error to start with
    assert error.mean() < 3e-5, (method, error.mean())
    assert result.rms_after < 3e-5


def test_dropped_parameters_say_what_absorbs_them():
    model = rc.robot("ur10")
    robot = virtual(model, seed=1)
    data = simulate(robot, poses(model, 60, seed=2), seed=3)
    result = rc.calibrate(model, data, tool_guess=[0, 0, 0.1])
    dropped = {d.name: d for d in result.dropped}
    assert dropped["theta1"].reason == "redundant"
    assert dropped["theta1"].absorbed_by[0][0] == "frame_rz"
    assert dropped["d1"].absorbed_by[0][0] == "frame_z"
    assert "absorbed by frame_rz" in result.summary()
    # a plain DH model of parallel axes: the d's along the parallel axes absorb each other
    assert dropped["d3"].reason == "redundant"


def cramer_rao_run(model, seed, n_train=60, noise=20e-6):
    robot = virtual(model, seed=seed, noise=noise)
    data = simulate(robot, poses(model, n_train, seed=seed + 100), seed=seed + 200)
    result = rc.calibrate(model, data, tool_guess=[0, 0, 0.1])
    q_test = poses(model, 200, seed=seed + 300)
    # the predicted measurement against the noise-free truth, in the tracker frame
    err2 = np.sum((result.predict(q_test)[:, :3, 3] - true_positions(robot, q_test)) ** 2, axis=1)
    predicted = np.trace(result.position_covariance(q_test), axis1=1, axis2=2)
    return err2.mean(), predicted.mean(), result, robot


def test_held_out_error_matches_the_cramer_rao_prediction(irb2400):
    """Mean squared error at held-out poses = trace(J Cov Jᵀ), within 10% (Monte Carlo)."""
    runs = [cramer_rao_run(irb2400, seed) for seed in range(40)]
    actual = np.mean([r[0] for r in runs])
    predicted = np.mean([r[1] for r in runs])
    assert abs(actual / predicted - 1) < 0.10, (actual, predicted)


def test_true_parameters_are_recovered_within_three_sigma(irb2400):
    _, _, result, robot = cramer_rao_run(irb2400, seed=7, n_train=100)
    truth = {s.name: s.value for s in robot.true.steps}
    # the model's own tool point is absorbed by the fitted target point: its error moves there
    for k, c in enumerate("xyz"):
        truth[f"tcp_{c}"] = TOOL[k] + robot.true.step(f"tool_{c}").value - irb2400.step(f"tool_{c}").value
    z = [
        (est - truth[name]) / sd
        for name, est, sd in zip(result.names, result.estimates, result.std, strict=True)
        if name in truth
    ]
    assert len(z) >= 20
    assert np.max(np.abs(z)) < 3.5 and np.mean(np.abs(np.array(z)) < 3) > 0.95


def test_parameter_uncertainty_agrees_with_monte_carlo(irb2400):
    """Same true robot, 60 noise draws: the spread of estimates matches the reported σ."""
    robot = virtual(irb2400, seed=11)
    q = poses(irb2400, 60, seed=12)
    estimates, sigmas = [], []
    for k in range(60):
        result = rc.calibrate(irb2400, simulate(robot, q, seed=1000 + k), tool_guess=[0, 0, 0.1])
        estimates.append(result.estimates)
        sigmas.append(result.std)
    ratio = np.std(estimates, axis=0) / np.mean(sigmas, axis=0)
    # the frame_* corrections are relative to each run's own Kabsch start frame, so their
    # spread across runs is not that of one estimate: compare the robot and tool parameters
    robot_and_tool = np.array([not n.startswith("frame_") for n in result.names])
    ratio = ratio[robot_and_tool]
    assert len(ratio) >= 20
    assert np.all((ratio > 0.6) & (ratio < 1.5)), ratio
    assert abs(np.median(ratio) - 1) < 0.15


def test_predicted_uncertainty_is_larger_outside_the_measured_region(irb2400):
    _, _, result, _ = cramer_rao_run(irb2400, seed=2)
    inside = result.position_uncertainty(poses(irb2400, 50, seed=5))
    assert np.all(inside > 0) and inside.mean() < 5e-5
    far = np.zeros((1, irb2400.dof))
    far[0, 1] = irb2400.joint_limits[1, 1]  # the arm stretched to its limit
    assert result.position_uncertainty(far)[0] > 0


def test_robust_loss_resists_outliers(irb2400):
    robot = virtual(irb2400, seed=21)
    data = simulate(robot, poses(irb2400, 80, seed=22), seed=23)
    bad = data.position.copy()
    bad[:6] += np.random.default_rng(0).normal(scale=3e-3, size=(6, 3))  # six gross outliers
    data = dataclasses.replace(data, position=bad)
    q_test = poses(irb2400, 200, seed=24)
    plain = held_out_error(rc.calibrate(irb2400, data, tool_guess=[0, 0, 0.1]), robot, q_test)
    robust = held_out_error(
        rc.calibrate(irb2400, data, tool_guess=[0, 0, 0.1], loss="soft_l1", f_scale=1e-4), robot, q_test
    )
    assert robust.mean() < 0.5 * plain.mean()


def test_per_row_sigma_weights_the_fit(irb2400):
    robot = virtual(irb2400, seed=31, noise=5e-6)
    data = simulate(robot, poses(irb2400, 80, seed=32), seed=33)
    noisy = data.position.copy()
    noisy[:20] += np.random.default_rng(1).normal(scale=5e-4, size=(20, 3))  # 20 poor rows
    sigma = np.full((data.n, 3), 5e-6)
    sigma[:20] = 5e-4
    q_test = poses(irb2400, 200, seed=34)
    unweighted = rc.calibrate(irb2400, dataclasses.replace(data, position=noisy), tool_guess=[0, 0, 0.1])
    weighted = rc.calibrate(
        irb2400, dataclasses.replace(data, position=noisy, sigma=sigma), tool_guess=[0, 0, 0.1]
    )
    assert (
        held_out_error(weighted, robot, q_test).mean()
        < 0.5 * held_out_error(unweighted, robot, q_test).mean()
    )


def gravity_sag(model, compliances):
    """A virtual robot's joint effect: joint j gives way by c_j τ_j(q) under its gravity load."""
    from robocal.model.dynamics import gravity_torques

    def sag(true_model, q):
        tau = gravity_torques(model, q)
        pert = np.zeros((len(q), model.dof, 3))
        for name, c in compliances.items():
            j = model.joint_names.index(name)
            pert[:, j, 2] = -c * tau[:, j]
        return pert

    return sag


def test_joint_compliance_is_identified():
    """A UR10 whose joints give way under gravity: c_j τ_j(q), recovered from positions."""
    model = rc.robot("ur10")
    c_true = {"shoulder_lift": 2e-6, "elbow": 4e-6, "wrist_1": 1e-5}
    robot = virtual(model, seed=41, noise=10e-6, effects=gravity_sag(model, c_true))
    data = simulate(robot, poses(model, 150, seed=42), seed=43)
    result = rc.calibrate(model, data, tool_guess=[0, 0, 0.1], compliance=list(c_true))
    for name, c in c_true.items():
        k = result.names.index("compliance_" + name)
        assert abs(result.estimates[k] - c) < 4 * result.std[k] + 0.1 * c
    geometric = rc.calibrate(model, data, tool_guess=[0, 0, 0.1])
    q_test = poses(model, 200, seed=44)
    assert (
        held_out_error(result, robot, q_test).mean() < 0.5 * held_out_error(geometric, robot, q_test).mean()
    )


def test_validate_reports_the_statistics_and_the_frame():
    model = rc.robot("ur10")
    q = poses(model, 40, seed=1)
    T = model.fk(q)
    offsets = np.zeros((40, 3))
    offsets[:, 0] = np.linspace(0, 1e-3, 40)  # errors 0 .. 1 mm along x
    data = Measurements(q=q, position=T[:, :3, 3] + offsets)
    stats = rc.validate(model, data, frame=np.eye(4))
    assert stats.frame == "given" and stats.n == 40
    assert stats.mean == pytest.approx(0.5e-3) and stats.max == pytest.approx(1e-3)
    assert stats.p95 == pytest.approx(np.percentile(np.linspace(0, 1e-3, 40), 95))
    assert stats.axis_mean_abs[1] == pytest.approx(0.0)
    assert set(stats.to_dict()) >= {"n", "mean_mm", "rms_mm", "max_mm", "p95_mm"}
    # the same data seen from a moved device: refitting the frame recovers the errors' spread
    moved = Measurements(q=q, position=(T[:, :3, 3] + offsets) @ TRACKER[:3, :3].T + TRACKER[:3, 3])
    refit = rc.validate(model, moved)
    assert refit.frame == "refit" and refit.mean < stats.mean


def test_result_save_and_load_round_trip(tmp_path, irb2400):
    robot = virtual(irb2400, seed=51)
    data = simulate(robot, poses(irb2400, 50, seed=52), seed=53)
    result = rc.calibrate(irb2400, data, tool_guess=[0, 0, 0.1])
    result.save(tmp_path / "out")
    saved = json.loads((tmp_path / "out" / "result.json").read_text())
    assert saved["n"] == 50 and saved["parameters"][0]["name"] == result.names[0]
    residuals = np.array(saved["residuals_mm"])
    assert residuals.shape == (50, 3)
    assert np.sqrt(np.mean(np.sum(residuals**2, axis=1))) == pytest.approx(result.rms_after * 1e3, rel=1e-4)
    again = CalibrationResult.load(tmp_path / "out")
    assert again.model == result.model
    np.testing.assert_allclose(again.frame, result.frame)
    np.testing.assert_allclose(again.std, result.std)
    np.testing.assert_allclose(again.predict(data.q), result.predict(data.q))


def test_cross_validation_folds(irb2400):
    robot = virtual(irb2400, seed=61)
    data = simulate(robot, poses(irb2400, 60, seed=62), seed=63)
    folds = rc.cross_validate(irb2400, data, k=3, tool_guess=[0, 0, 0.1])
    assert len(folds) == 3 and sum(f.n for f in folds) == 60
    assert all(f.mean < 1e-4 for f in folds)


def test_bad_calibration_input_is_explained(irb2400):
    data = Measurements(q=np.zeros((5, 5)), position=np.zeros((5, 3)))
    with pytest.raises(ValueError, match="5 joint columns"):
        rc.calibrate(irb2400, data)
    with pytest.raises(ValueError, match="unknown method 'newton'"):
        rc.calibrate(irb2400, Measurements(q=np.zeros((5, 6)), position=np.zeros((5, 3))), method="newton")
    with pytest.raises(ValueError, match="no positions"):
        rc.calibrate(irb2400, Measurements(q=np.zeros((5, 6))))


def test_screening_finds_a_hopeless_unknown_before_the_fit():
    rng = np.random.default_rng(4)
    J = rng.normal(size=(300, 5))
    r = rng.normal(size=300)  # unit-variance residuals (weighted)
    scale = np.full(5, 1e-4)  # σ as tool displacement: about 1e-4 / sqrt(300) m each
    assert screen_unidentifiable(r, J, scale) == []
    # a sixth unknown almost indistinguishable from the first: both σ explode, and once
    # the worse one is fixed the other is determined again
    J6 = np.column_stack([J, J[:, 0] + 1e-5 * rng.normal(size=300)])
    found = screen_unidentifiable(r, J6, np.full(6, 1e-4))
    assert len(found) == 1 and found[0][0] in (0, 5) and found[0][1] > 10 * 5e-4
    # well above the threshold but not ten times: left to the pruning after the fit
    J6 = np.column_stack([J, J[:, 0] + 0.1 * rng.normal(size=300)])
    assert screen_unidentifiable(r, J6, np.full(6, 1e-1), max_std_ratio=5.0) == []


def test_plain_dh_ur10_drops_the_wrist_pair_without_wandering():
    """θ5/α5 of the catalog's DH UR10 are nearly unidentifiable from 50 random poses: they
    are screened out before the fit, which then converges in a few iterations."""
    ur10 = rc.robot("ur10")
    q = rc.measure.poses.random_poses(ur10, 50, seed=3)
    device = LaserTracker(p_tool_target=np.array([0.0, 0.0, 0.109]), sigma=20e-6)
    data = simulate(VirtualRobot(ur10, draw_true_model(ur10, seed=3), device), q, seed=4)
    result = rc.calibrate(ur10, data, tool_guess=[0, 0, 0.109])
    poor = [d.name for d in result.dropped if d.reason == "poorly identifiable"]
    assert {"theta5", "alpha5"} & set(poor)
    assert result.success and result.iterations <= 10
    assert result.rms_after < 0.04e-3  # 20 µm per axis: about 35 µm in 3D


def test_saved_result_explains_what_was_dropped(tmp_path):
    ur10 = rc.robot("ur10")
    q = rc.measure.poses.random_poses(ur10, 50, seed=3)
    device = LaserTracker(p_tool_target=np.array([0.0, 0.0, 0.109]), sigma=20e-6)
    data = simulate(VirtualRobot(ur10, draw_true_model(ur10, seed=3), device), q, seed=4)
    result = rc.calibrate(ur10, data, tool_guess=[0, 0, 0.109])
    result.save(tmp_path / "out")
    again = CalibrationResult.load(tmp_path / "out")
    assert [str(d) for d in again.dropped] == [str(d) for d in result.dropped]
    poor = [d for d in again.dropped if d.reason == "poorly identifiable"]
    assert poor and all(d.sigma > 5e-4 for d in poor) and "mm as tool displacement" in str(poor[0])
    redundant = [d for d in again.dropped if d.reason == "redundant"]
    assert redundant and all(d.absorbed_by for d in redundant)


def test_predicted_uncertainty_includes_the_joint_compliances():
    """Compliance calibrations: held-out MSE = trace(J Cov Jᵀ) with the compliance
    coefficients' columns in J (Monte Carlo over 25 virtual UR10s), within 15 %.  Every
    compliance well above 3σ (wrist_1: σ ≈ 9 µrad/N·m at 60 poses), so that each is
    identified in every twin: one held at zero as undetermined adds a bias the covariance
    of the others does not describe."""
    model = rc.robot("ur10")
    c_true = {"shoulder_lift": 2e-6, "elbow": 4e-6, "wrist_1": 6e-5}
    actual, predicted = [], []
    for seed in range(25):
        robot = virtual(model, seed=500 + seed, effects=gravity_sag(model, c_true))
        data = simulate(robot, poses(model, 60, seed=600 + seed), seed=700 + seed)
        result = rc.calibrate(model, data, tool_guess=[0, 0, 0.1], compliance=list(c_true))
        assert {"compliance_" + n for n in c_true} <= set(result.names)
        q_test = poses(model, 200, seed=800 + seed)
        err = result.predict(q_test)[:, :3, 3] - true_positions(robot, q_test)
        actual.append(np.mean(np.sum(err**2, axis=1)))
        predicted.append(np.mean(np.trace(result.position_covariance(q_test), axis1=1, axis2=2)))
    assert abs(np.mean(actual) / np.mean(predicted) - 1) < 0.15, (np.mean(actual), np.mean(predicted))


def test_compliance_columns_of_the_prediction_match_finite_differences():
    """The joint-effect columns of position_covariance's J: d predicted position / d
    compliance, against changing the calibrated robot's compliance and predicting again."""
    model = rc.robot("ur10")
    c_true = {"shoulder_lift": 2e-6, "elbow": 4e-6, "wrist_1": 6e-5}  # identified: well above 3σ
    robot = virtual(model, seed=5, effects=gravity_sag(model, c_true))
    data = simulate(robot, poses(model, 60, seed=6), seed=7)
    result = rc.calibrate(model, data, tool_guess=[0, 0, 0.1], compliance=list(c_true))
    names = [n for n in result.names if n.startswith("compliance_")]
    assert len(names) == 3
    q = poses(model, 20, seed=8)
    columns = result._effect_columns(result.measurement_chain, q, result.joint_perturbations(q), names)
    h = 1e-7  # rad/(N·m): a few µm at the tool
    for k, name in enumerate(names):
        joint = name.removeprefix("compliance_")
        effects = tuple(
            dataclasses.replace(e, compliance=e.compliance + h) if e.joint == joint else e
            for e in result.model.joint_effects
        )
        shifted = dataclasses.replace(result, model=dataclasses.replace(result.model, joint_effects=effects))
        fd = (shifted.predict(q)[:, :3, 3] - result.predict(q)[:, :3, 3]) / h
        np.testing.assert_allclose(columns[:, :, k], fd, rtol=1e-4, atol=1e-6 * np.abs(fd).max())


def test_fit_to_noise_of_gaussian_residuals_and_of_an_unmodelled_error():
    from robocal.identify.noise_check import fit_to_noise

    rng = np.random.default_rng(8)
    sigma = np.full((400, 3), 2e-5)
    clean = fit_to_noise(rng.normal(scale=2e-5, size=(400, 3)), sigma, 0)
    assert 0.95 < clean.ratio < 1.05 and clean.p_value > 1e-3 and clean.warning() is None
    assert clean.noise_rms == pytest.approx(2e-5 * np.sqrt(3))
    # a 0.1 mm error per axis the model did not represent
    offset = rng.choice([-1.0, 1.0], size=(400, 3)) * 1e-4
    bad = fit_to_noise(rng.normal(scale=2e-5, size=(400, 3)) + offset, sigma, 0)
    assert bad.warning() is not None and "does not represent" in bad.warning()
    assert bad.unmodelled_rms == pytest.approx(1e-4 * np.sqrt(3), rel=0.05)
    # residuals far below the stated noise: sigma overstated
    low = fit_to_noise(rng.normal(scale=5e-6, size=(400, 3)), sigma, 0)
    assert low.warning() is not None and "too large" in low.warning()
    # parameters spent on the residuals reduce the degrees of freedom
    assert fit_to_noise(rng.normal(scale=2e-5, size=(400, 3)), sigma, 30).dof == 1170


def test_calibration_tells_when_the_model_does_not_explain_the_data():
    """Joints that give way under gravity, calibrated without compliance: the residuals
    are far above the 20 µm noise and the unexplained error estimated from them is close
    to the held-out error against the truth; with compliance the model explains them."""
    model = rc.robot("ur10")
    c_true = {"shoulder_lift": 4e-6, "elbow": 8e-6}
    robot = virtual(model, seed=31, effects=gravity_sag(model, c_true))
    data = simulate(robot, poses(model, 100, seed=32), seed=33)
    geometric = rc.calibrate(model, data, tool_guess=[0, 0, 0.1])
    noise = geometric.fit_to_noise
    assert noise.ratio > 3 and any("does not represent" in w for w in geometric.metadata["warnings"])
    q_test = poses(model, 2000, seed=34)
    held_out = np.sqrt(np.mean(held_out_error(geometric, robot, q_test) ** 2))
    assert 0.7 * held_out < noise.unmodelled_rms < held_out
    assert "does not represent" in geometric.summary()
    # validation expects that unexplained error too: measured data of the same robot
    stats = rc.validate(geometric, simulate(robot, q_test, seed=35))
    assert stats.scatter == "sigma+unmodelled" and 0.8 < stats.rms / stats.expected_rms < 1.3
    compliant = rc.calibrate(model, data, tool_guess=[0, 0, 0.1], compliance=list(c_true))
    assert compliant.fit_to_noise.warning() is None and compliant.fit_to_noise.ratio < 1.2
    assert "down to the measurement noise" in compliant.summary()


def test_orientations_read_with_the_wrong_euler_convention_are_named(irb2400):
    """Pose data whose rotations were converted with extrinsic instead of intrinsic Euler
    angles: the calibration says the orientation convention is the likely cause."""
    from robocal.measure.devices import OpticalCMM

    robot = VirtualRobot(irb2400, draw_true_model(irb2400, seed=71), OpticalCMM())
    data = simulate(robot, poses(irb2400, 60, seed=72), seed=73)
    assert data.orientation is not None
    angles = rc.spatial.matrix_to_euler(data.orientation, "XYZ")
    wrong = dataclasses.replace(data, orientation=rc.spatial.euler_to_matrix(angles, "xyz"))
    try:
        messages = rc.calibrate(irb2400, wrong).metadata["warnings"]
    except ValueError as err:  # the fit may also give up on such data
        messages = [str(err)]
    assert any("orientation convention" in m for m in messages), messages
    right = rc.calibrate(irb2400, data)
    assert not any("orientation convention" in m for m in right.metadata["warnings"])


def test_validation_states_the_error_the_calibration_expected(irb2400):
    """Held-out RMS against the calibration's expectation (propagated parameter covariance
    plus the data's noise): equal on average when the model explains the data, well
    below the error when the robot has changed since."""
    ratios = []
    for seed in range(4):
        robot = virtual(irb2400, seed=900 + seed)
        data = simulate(robot, poses(irb2400, 60, seed=910 + seed), seed=920 + seed)
        test = simulate(robot, poses(irb2400, 1000, seed=930 + seed), seed=940 + seed)
        result = rc.calibrate(irb2400, data, tool_guess=[0, 0, 0.1])
        stats = rc.validate(result, test)
        cov = result.position_covariance(test.q)
        assert stats.parameter_rms == pytest.approx(np.sqrt(np.mean(np.trace(cov, axis1=1, axis2=2))))
        assert stats.scatter == "sigma" and not stats.worse_than_expected
        ratios.append(stats.rms / stats.expected_rms)
    assert 0.9 < np.mean(ratios) < 1.1, ratios
    changed = virtual(irb2400, seed=999)  # another robot's errors, same device
    stats = rc.validate(result, simulate(changed, poses(irb2400, 500, seed=950), seed=951))
    assert stats.worse_than_expected and stats.to_dict()["expected_rms_mm"] < 0.5 * stats.rms * 1e3


def test_wrist_rotations_near_the_probe_are_kept_and_nothing_is_biased():
    """A probe 0.1 m from the flange, near its axis: θ5/α5 move it by a short lever arm.
    Judged by the robot's size they were pruned and d5/a5 absorbed their errors (a5 at
    100σ); judged by how far they move the probe they are kept and every robot
    parameter is recovered within 3.5σ."""
    nominal = rc.robot("irb6400r")
    true = draw_true_model(nominal, seed=100)
    frame = rc.spatial.homogeneous(rc.spatial.rotz(0.1823), [2.377, 0.799, -0.304])
    device = LaserTracker(T_device_base=frame, p_tool_target=[0.0045, 0.0094, 0.1])
    truth = dict(zip(true.names, true.values, strict=True))
    for pose_seed in (200, 202, 206):
        q = rc.measure.poses.random_poses(nominal, 100, seed=pose_seed)
        result = rc.calibrate(nominal, simulate(VirtualRobot(nominal, true, device), q, seed=pose_seed + 100))
        assert not [d for d in result.dropped if d.reason == "poorly identifiable"]
        expected = dict(truth)  # a redundant parameter's error moves the one that absorbs it
        for d in result.dropped:
            for name, coefficient in d.absorbed_by:
                if name in expected:
                    expected[name] += coefficient * (
                        truth[d.name] - nominal.values[nominal.names.index(d.name)]
                    )
        rows = zip(result.names, result.estimates, result.std, strict=True)
        z = {n: (e - expected[n]) / s for n, e, s in rows if n in truth}
        assert len(z) >= 15 and max(np.abs(list(z.values()))) < 3.5, z


def test_residual_variance_uses_the_stated_noise_unless_the_residuals_reject_it():
    from robocal.identify.stages import residual_variance

    assert residual_variance(3.0, 2, known=True) == 1.0  # two degrees of freedom say little
    assert residual_variance(3.0, 2, known=False) == 1.5
    assert residual_variance(2000.0, 300, known=True) == pytest.approx(2000 / 300)  # rejected: too large
    assert residual_variance(100.0, 300, known=True) == pytest.approx(100 / 300)  # rejected: too small
    assert [residual_variance(chi2, 300, known=True) for chi2 in (290.0, 900.0)] == [1.0, pytest.approx(3.0)]


def test_pose_measurements_get_an_honest_covariance():
    """Orientation rows weighted by a choice (0.1 m/rad), not by their noise: each group of
    rows gets its own variance, and the predicted held-out error matches the actual one
    (one pooled variance predicted twice the error)."""
    from robocal.measure.devices import OpticalCMM

    model = rc.robot("ur10")
    actual, predicted = [], []
    for seed in range(6):
        device = OpticalCMM(p_tool_target=[0.02, -0.01, 0.1])
        robot = VirtualRobot(model, draw_true_model(model, seed=seed), device)
        data = simulate(robot, poses(model, 100, seed=10 + seed), seed=20 + seed)
        q_test = poses(model, 500, seed=30 + seed)
        result = rc.calibrate(model, data)
        truth = VirtualRobot(model, robot.true, device.with_noise(0.0))
        test = simulate(truth, q_test, seed=40 + seed)
        actual.append(np.mean(np.sum((result.predict(q_test)[:, :3, 3] - test.position) ** 2, axis=1)))
        predicted.append(np.mean(np.trace(result.position_covariance(q_test), axis1=1, axis2=2)))
    assert 0.7 < np.sqrt(np.mean(actual) / np.mean(predicted)) < 1.2


def test_few_poses_for_many_unknowns_are_warned_about(irb2400):
    robot = virtual(irb2400, seed=81)
    data = simulate(robot, poses(irb2400, 12, seed=82), seed=83)
    result = rc.calibrate(irb2400, data, tool_guess=[0, 0, 0.1])
    assert any("so little redundancy" in w for w in result.metadata["warnings"])
    many = rc.calibrate(
        irb2400, simulate(robot, poses(irb2400, 40, seed=84), seed=85), tool_guess=[0, 0, 0.1]
    )
    assert not any("so little redundancy" in w for w in many.metadata["warnings"])


@pytest.fixture(scope="module")
def ur10_bounded_case():
    """UR10 with 5 mm / 2° errors: d2 carries d3 and d4 as well and needs more than its
    own ±5 mm."""
    model = rc.robot("ur10")
    frame = rc.spatial.inverse(rc.spatial.homogeneous(rc.spatial.rotz(2.0), [1.5, -2.0, 0.4]))
    device = LaserTracker(T_device_base=frame, p_tool_target=[0.02, -0.01, 0.1])
    true = draw_true_model(model, length=5e-3, angle=math.radians(2), seed=5)
    data = simulate(
        VirtualRobot(model, true, device), rc.measure.poses.random_poses(model, 100, seed=1), seed=2
    )
    q_test = rc.measure.poses.random_poses(model, 300, seed=3)
    test = simulate(VirtualRobot(model, true, device.with_noise(0.0)), q_test, seed=4)
    return model, data, test


def _bound_width(result, name):
    rot = {s.name: s.is_rotation for s in result.model.steps}
    return math.radians(2.0) if rot[name] else 5e-3


def _named_at_bounds(warnings):
    """The parameters the at-bound warning names (none without the warning)."""
    text = [w for w in warnings if "ended at" in w]
    assert len(text) <= 1
    return set(text[0].split(" ended at")[0].split(", ")) if text else set()


def test_bounded_fit_keeps_every_parameter_within_seed001s_bounds_by_default(ur10_bounded_case):
    """Seed 001: |δd|, |δL| ≤ 5 mm and |δθ|, |δα| ≤ 2° on every identified robot parameter;
    exactly the parameters at a bound are listed (metadata and warning), none is beyond."""
    model, data, _ = ur10_bounded_case
    result = rc.calibrate(model, data, method="bounded")
    assert not any(w.startswith("bounds='widened'") for w in result.metadata["warnings"])
    at = result.metadata["at_bounds"]
    assert "d2" in at  # it would need more than ±5 mm
    for name, x, x0 in zip(result.names, result.estimates, result.nominal, strict=True):
        if name not in model.names:
            continue
        width = _bound_width(result, name)
        assert abs(x - x0) <= width, name  # never beyond
        at_bound = width - abs(x - x0) <= 1e-6 * 2 * width
        assert at_bound == (name in at), (name, (x - x0), width)
    assert _named_at_bounds(result.metadata["warnings"]) == set(at)


def test_bounded_fit_widens_bounds_of_absorbing_parameters_only_when_asked(ur10_bounded_case):
    model, data, test = ur10_bounded_case
    result = rc.calibrate(model, data, method="bounded", bounds="widened")
    d2 = result.names.index("d2")
    assert abs(result.estimates[d2] - result.nominal[d2]) > 5e-3  # beyond the parameter's own ±5 mm
    assert rc.validate(result, test).rms < 30e-6
    widened = [w for w in result.metadata["warnings"] if w.startswith("bounds='widened'")]
    assert len(widened) == 1 and "d2 ±" in widened[0]
    assert result.metadata["at_bounds"] == [] and _named_at_bounds(result.metadata["warnings"]) == set()
    x0 = result.nominal
    tight = rc.calibrate(model, data, method="bounded", bounds=(x0 - 1e-4, x0 + 1e-4))
    assert _named_at_bounds(tight.metadata["warnings"]) == set(tight.metadata["at_bounds"]) != set()
    with pytest.raises(ValueError, match="bounds must be one of default, widened"):
        rc.calibrate(model, data, method="bounded", bounds="wide")


def test_parameters_at_bounds_lists_exactly_those_at_a_bound():
    from robocal.identify.bounds import parameters_at_bounds

    names = ["at_lower", "at_upper", "inside", "beyond", "one_sided", "free"]
    lo = np.array([-1.0, -1.0, -1.0, -1.0, 0.0, -np.inf])
    hi = np.array([1.0, 1.0, 1.0, 1.0, np.inf, np.inf])
    x = np.array([-1.0, 1.0 - 1e-7, 1.0 - 1e-4, 1.5, 1e-9, 0.0])
    assert parameters_at_bounds(names, x, lo, hi) == ["at_lower", "at_upper", "beyond", "one_sided"]


def test_joint_effects_taken_from_the_model_are_named():
    model = rc.robot("katana450")  # carries seed 003's Table 5.2 clearance and backlash
    data = simulate(virtual(model, seed=1), poses(model, 60, seed=2), seed=3)
    result = rc.calibrate(model, data, tool_guess=[0, 0, 0.1], compliance=True)
    named = [w for w in result.metadata["warnings"] if "predicted as known, not identified" in w]
    assert named and "clearance (q1" in named[0] and "backlash (q1" in named[0] and "--level 3" in named[0]
    geometric = rc.calibrate(model, data, tool_guess=[0, 0, 0.1])  # no joint effects at all
    assert not any("predicted as known" in w for w in geometric.metadata["warnings"])


def test_influence_method_weighs_pose_rows_like_the_others():
    """Orientation rows in radians next to positions in metres: unweighted, the influence
    method was 6x worse than lm on an optical CMM.  Weighted as lm, its best-fit set by
    least squares ("fit") is lm's; the thesis' per-pose sets averaged ("mean") weigh each
    pose by (JᵢJᵢᵀ)⁻¹, which is not the noise's weighting: as the per-pose pseudo-inverse,
    a few times lm's error on noise alone (the tool's rotations are corrected too)."""
    from robocal.measure.devices import OpticalCMM

    model = rc.robot("ur10")
    device = OpticalCMM(p_tool_target=[0.02, -0.01, 0.1])
    robot = VirtualRobot(model, draw_true_model(model, seed=3), device)
    data = simulate(robot, poses(model, 100, seed=4), seed=5)
    test = simulate(
        VirtualRobot(model, robot.true, device.with_noise(0.0)), poses(model, 300, seed=6), seed=7
    )
    lm = rc.validate(rc.calibrate(model, data), test).rms
    fit = rc.validate(rc.calibrate(model, data, method="influence", combine="fit"), test).rms
    influence = rc.validate(rc.calibrate(model, data, method="influence"), test).rms
    per_pose = rc.validate(rc.calibrate(model, data, method="pinv", per_pose=True), test).rms
    assert fit < 2 * lm, (fit, lm)
    assert influence < 2 * per_pose and influence < 10 * lm, (influence, per_pose, lm)


def test_glitches_are_named_and_a_robust_loss_down_weights_them(irb2400):
    robot = virtual(irb2400, seed=91)
    clean = simulate(robot, poses(irb2400, 80, seed=92), seed=93)
    result = rc.calibrate(irb2400, clean, tool_guess=[0, 0, 0.1])
    assert result.metadata["outlier_poses"] == [] and not any(
        "glitches" in w for w in result.metadata["warnings"]
    )
    position = clean.position.copy()
    position[[7, 40]] += [3e-3, -2e-3, 1e-3]  # two tracker glitches of ~3.7 mm
    glitchy = dataclasses.replace(clean, position=position)
    result = rc.calibrate(irb2400, glitchy, tool_guess=[0, 0, 0.1])
    assert result.metadata["outlier_poses"] == [7, 40]
    assert any(
        "2 pose(s) with residuals far beyond" in w and "--loss soft_l1" in w
        for w in result.metadata["warnings"]
    )
    robust = rc.calibrate(irb2400, glitchy, tool_guess=[0, 0, 0.1], loss="soft_l1", f_scale=1e-4)
    q_test = poses(irb2400, 500, seed=94)
    assert held_out_error(robust, robot, q_test).mean() < 0.5 * held_out_error(result, robot, q_test).mean()
