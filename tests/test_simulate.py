"""Virtual robot: drawn true models, joint effects, declared noise statistics, truth files, CLI."""

import math

import numpy as np
import pytest
from typer.testing import CliRunner

import robocal as rc
from robocal import spatial
from robocal.cli import app
from robocal.measure.dataset.read import read_measurements
from robocal.measure.dataset.writer import write_measurements
from robocal.measure.devices import Camera, LaserTracker, OpticalCMM
from robocal.measure.joint_effects import EncoderNoise, PayloadCompliance
from robocal.measure.measurements import Measurements
from robocal.measure.simulate import VirtualRobot, load_truth, save_simulation, simulate, truth_path
from robocal.measure.true_model import draw_true_model, parse_quantity

runner = CliRunner()
N = 20_000


@pytest.fixture(scope="module")
def ur10():
    return rc.robot("ur10")


@pytest.fixture(scope="module")
def q_many(ur10):
    return np.random.default_rng(0).uniform(-math.pi, math.pi, (N, ur10.dof))


def residual(robot: VirtualRobot, data: Measurements):
    """Observation minus the noise-free observation of the true robot."""
    return data.position - robot.device.predict(robot.T_base_tool(data.q)).position


# ------------------------------------------------------------------ quantities and true models
def test_parse_quantity():
    assert parse_quantity("0.02mm", "length") == pytest.approx(2e-5)
    assert parse_quantity("20 um", "length") == pytest.approx(2e-5)
    assert parse_quantity("20µm", "length") == pytest.approx(2e-5)
    assert parse_quantity("0.05deg", "angle") == pytest.approx(math.radians(0.05))
    assert parse_quantity("1e-3", "length") == 1e-3 and parse_quantity(0.5, "angle") == 0.5
    with pytest.raises(ValueError, match=r"is not a length such as 0\.02mm"):
        parse_quantity("0.02 furlong", "length")
    with pytest.raises(ValueError, match="is not a angle"):
        parse_quantity("1mm", "angle")


def test_draw_true_model_tolerances_overrides_and_seed(ur10):
    a = draw_true_model(ur10, seed=4)
    b = draw_true_model(ur10, seed=4)
    assert a == b and a != draw_true_model(ur10, seed=5)
    delta = a.values - ur10.values
    rot = np.array([s.is_rotation for s in ur10.steps])
    assert np.all(np.abs(delta[rot]) <= math.radians(0.05)) and np.all(np.abs(delta[~rot]) <= 0.5e-3)
    assert np.all(delta[ur10.free_mask] != 0) and np.all(delta[~ur10.free_mask] == 0)
    assert a.free_names == ur10.free_names and a.joint_limits.tolist() == ur10.joint_limits.tolist()
    big = draw_true_model(ur10, {"theta2": "5deg", "d1": 0.0}, seed=4)
    d = dict(zip(ur10.names, big.values - ur10.values, strict=True))
    assert math.radians(0.05) < abs(d["theta2"]) <= math.radians(5) and d["d1"] == 0.0
    with pytest.raises(KeyError, match="has no parameter 'theta9'"):
        draw_true_model(ur10, {"theta9": 0.1})


def test_draw_true_model_normal_distribution(ur10):
    """normal: 1-sigma = tol; pooled over 400 draws of the 12 length parameters."""
    lengths = [n for n, s in zip(ur10.names, ur10.steps, strict=True) if s.free and not s.is_rotation]
    idx = [ur10.names.index(n) for n in lengths]
    rng = np.random.default_rng(7)
    dev = np.array(
        [
            (draw_true_model(ur10, distribution="normal", seed=rng).values - ur10.values)[idx]
            for _ in range(400)
        ]
    )
    assert dev.std() == pytest.approx(0.5e-3, rel=0.05)


# ------------------------------------------------------------------ declared noise statistics
def test_isotropic_tracker_noise_statistics(ur10, q_many):
    """Zero-error robot: the residual std per axis is sigma within 3 % over 20,000 poses."""
    robot = VirtualRobot(ur10, ur10, LaserTracker(sigma=20e-6))
    data = simulate(robot, q_many, seed=1)
    r = residual(robot, data)
    np.testing.assert_allclose(r.std(axis=0), 20e-6, rtol=0.03)
    np.testing.assert_allclose(r.mean(axis=0), 0, atol=3 * 20e-6 / math.sqrt(N) * 1.5)
    np.testing.assert_allclose(data.sigma, 20e-6)


def test_distance_dependent_tracker_noise_scales_with_distance(ur10, q_many):
    dev = LaserTracker(sigma=5e-6, sigma_per_m=10e-6)
    robot = VirtualRobot(ur10, ur10, dev)
    data = simulate(robot, q_many, seed=2)
    r = residual(robot, data)
    d = np.linalg.norm(dev.predict(robot.T_base_tool(q_many)).position, axis=1)
    np.testing.assert_allclose(data.sigma[:, 0], 5e-6 + 10e-6 * d)
    np.testing.assert_allclose((r / data.sigma).std(axis=0), 1.0, rtol=0.03)
    near, far = d < np.quantile(d, 0.25), d > np.quantile(d, 0.75)
    ratio = r[far].std() / r[near].std()
    assert ratio == pytest.approx(data.sigma[far, 0].mean() / data.sigma[near, 0].mean(), rel=0.05)
    assert ratio > 1.2


def test_optical_cmm_position_and_orientation_statistics(ur10, q_many):
    """Three markers on a 50 mm circle, sigma per coordinate: the Kabsch fit gives the
    centroid's sigma/sqrt(3) per axis, sigma/(r sqrt 3) about the markers' normal and
    sigma sqrt(2)/(r sqrt 3) about the in-plane axes."""
    sigma, r = 10e-6, 0.05
    dev = OpticalCMM(sigma=sigma)
    robot = VirtualRobot(ur10, ur10, dev)
    data = simulate(robot, q_many, seed=3)
    truth = dev.predict(robot.T_base_tool(q_many))
    np.testing.assert_allclose((data.position - truth.position).std(axis=0), sigma / math.sqrt(3), rtol=0.03)
    local = spatial.matrix_to_rotvec(np.swapaxes(truth.orientation, 1, 2) @ data.orientation)
    expected = sigma / (r * math.sqrt(3)) * np.array([math.sqrt(2), math.sqrt(2), 1.0])
    np.testing.assert_allclose(local.std(axis=0), expected, rtol=0.03)


def test_camera_statistics_follow_the_declared_sigma(ur10, q_many):
    robot = VirtualRobot(ur10, ur10, Camera())
    data = simulate(robot, q_many, seed=4)
    r = residual(robot, data)
    np.testing.assert_allclose((r / data.sigma).std(axis=0), 1.0, rtol=0.04)


def test_same_seed_same_measurements(ur10):
    true = draw_true_model(ur10, seed=1)
    robot = VirtualRobot(ur10, true, OpticalCMM())
    q = np.random.default_rng(1).uniform(-1, 1, (50, 6))
    a, b, c = simulate(robot, q, 11), simulate(robot, q, 11), simulate(robot, q, 12)
    np.testing.assert_array_equal(a.position, b.position)
    np.testing.assert_array_equal(a.orientation, b.orientation)
    assert not np.array_equal(a.position, c.position)


def test_true_errors_show_in_the_measurements(ur10):
    true = draw_true_model(ur10, seed=8)
    dev = LaserTracker(sigma=0.0)
    q = np.random.default_rng(3).uniform(-2, 2, (200, 6))
    data = simulate(VirtualRobot(ur10, true, dev), q, seed=0)
    nominal = dev.predict(ur10.fk(q)).position
    err = np.linalg.norm(data.position - nominal, axis=1)
    assert 1e-4 < np.median(err) < 5e-3  # ±0.5 mm, ±0.05° on a 1.3 m arm: about a millimetre


def test_simulate_rejects_commands_outside_the_limits(ur10):
    robot = VirtualRobot(ur10, ur10, LaserTracker())
    q = np.zeros((3, 6))
    q[2, 1] = 7.0
    with pytest.raises(ValueError, match=r"pose 2: joint shoulder_lift = 7 is outside the limits"):
        simulate(robot, q)


# ------------------------------------------------------------------ joint effects
def test_payload_compliance_on_joint_2(ur10):
    """Gravity-proportional compliance: joint 2 gives way by m g L / k where L is the
    horizontal lever arm, so the stretched-out arm sags and the upright one does not."""
    mass, k = 10.0, 2.0e4
    effect = PayloadCompliance(mass, {2: k})
    stretched = np.zeros((1, 6))  # UR10 zero pose: arm horizontal, flange at x = a2 + a3
    upright = np.array([[0.0, -math.pi / 2, 0.0, -math.pi / 2, 0.0, 0.0]])
    d = effect(ur10, np.vstack([stretched, upright]))
    assert d.shape == (2, 6, 3)
    assert np.count_nonzero(np.delete(d.reshape(2, -1), 3 * 1 + 2, axis=1)) == 0  # only δθ2
    frame2 = ur10.joint_frames(stretched)[0, 1]
    np.testing.assert_allclose(np.abs(frame2[:3, 2]), [0, 1, 0], atol=1e-12)  # joint 2 axis: base y
    T = ur10.fk(stretched)[0]
    lever = abs(T[0, 3] - frame2[0, 3])  # horizontal distance across the axis
    assert lever == pytest.approx(0.612 + 0.5723)
    assert abs(d[0, 1, 2]) == pytest.approx(mass * 9.81 * lever / k, rel=1e-12)
    assert abs(d[1, 1, 2]) < 1e-9
    robot = VirtualRobot(ur10, ur10, LaserTracker(sigma=0.0), joint_effects=effect)
    sag = robot.T_base_tool(stretched)[0, 2, 3] - T[2, 3]
    assert sag == pytest.approx(-lever * abs(d[0, 1, 2]), rel=1e-3)  # the tool drops
    by_name = PayloadCompliance(mass, {"shoulder_lift": k})
    np.testing.assert_array_equal(by_name(ur10, stretched), d[:1])


def test_encoder_noise_and_summed_effects(ur10):
    q = np.random.default_rng(0).uniform(-1, 1, (N, 6))
    enc = EncoderNoise(1e-4, seed=3)
    d = enc(ur10, q)
    assert d[:, :, :2].max() == 0 and d[:, :, 2].std() == pytest.approx(1e-4, rel=0.02)
    robot = VirtualRobot(ur10, ur10, LaserTracker(), joint_effects=[enc, enc])
    np.testing.assert_array_equal(robot.perturbations(q), 2 * d)

    def bad(model, q):
        return np.zeros((len(q), model.dof))

    with pytest.raises(ValueError, match=r"returned shape \(20000, 6\); expected \(20000, 6, 3\)"):
        VirtualRobot(ur10, ur10, LaserTracker(), joint_effects=bad).perturbations(q)


# ------------------------------------------------------------------ truth files
def test_truth_round_trips(tmp_path, ur10):
    true = draw_true_model(ur10, seed=2)
    dev = LaserTracker(p_tool_target=[0.0, 0.0, 0.109], sigma=15e-6, sigma_per_m=6e-6)
    effect = PayloadCompliance(2.0, {2: 3e4, "elbow": 2e4})
    robot = VirtualRobot(ur10, true, dev, joint_effects=[effect, EncoderNoise(1e-5, 4)])
    q = np.random.default_rng(1).uniform(-2, 2, (30, 6))
    data = simulate(robot, q, seed=6)
    csv, truth_file = save_simulation(robot, data, tmp_path / "meas.csv", seed=6, note="test")
    assert truth_file == truth_path(csv) == tmp_path / "meas.truth.yaml"
    assert (tmp_path / "meas.true_model.yaml").is_file() and (tmp_path / "meas.nominal_model.yaml").is_file()
    truth = load_truth(csv)
    assert truth.true == true and truth.nominal == ur10 and truth.seed == 6
    assert truth.device.to_dict() == dev.to_dict() and truth.data_file == "meas.csv"
    assert truth.joint_effects == (effect, EncoderNoise(1e-5, 4))
    assert truth.deviations == pytest.approx(dict(zip(ur10.names, true.values - ur10.values, strict=True)))
    again = simulate(truth.virtual_robot(), q, seed=6)  # the truth reproduces the data exactly
    np.testing.assert_array_equal(again.position, data.position)
    back = read_measurements(csv, model=ur10)
    np.testing.assert_array_equal(back.position, data.position)
    np.testing.assert_array_equal(back.sigma, data.sigma)
    assert back.metadata["device"] == "laser-tracker" and back.metadata["seed"] == "6"


def test_load_truth_errors(tmp_path):
    with pytest.raises(FileNotFoundError, match="truth file not found"):
        load_truth(tmp_path / "none.csv")
    (tmp_path / "x.truth.yaml").write_text("a: 1\n")
    with pytest.raises(ValueError, match="not a robocal truth file"):
        load_truth(tmp_path / "x.truth.yaml")


# ------------------------------------------------------------------ CLI
def _poses(tmp_path, ur10, n=40):
    q = np.random.default_rng(5).uniform(-2, 2, (n, ur10.dof))
    return write_measurements(Measurements(q=q), tmp_path / "poses.csv"), q


def test_cli_simulate_writes_data_and_truth(tmp_path, ur10):
    poses, q = _poses(tmp_path, ur10)
    args = ["simulate", "ur10", "--poses", str(poses), "--device", "laser-tracker", "--noise", "0.02mm",
            "--seed", "1", "--tool-offset", "0,0,109mm", "--tol", "theta2=0.2deg"]  # fmt: skip
    result = runner.invoke(app, [*args, "-o", str(tmp_path / "meas.csv")])
    assert result.exit_code == 0, result.output
    assert "meas.csv" in result.output and "meas.truth.yaml" in result.output
    data = read_measurements(tmp_path / "meas.csv", model=ur10)
    np.testing.assert_array_equal(data.q, q)
    np.testing.assert_allclose(data.sigma, 2e-5)
    truth = load_truth(tmp_path / "meas.truth.yaml")
    assert truth.device.sigma == pytest.approx(2e-5) and truth.device.sigma_per_m == 0.0
    np.testing.assert_allclose(truth.device.p_tool_target, [0, 0, 0.109])
    assert math.radians(0.05) < abs(truth.deviations["theta2"]) <= math.radians(0.2)
    again = runner.invoke(app, [*args, "-o", str(tmp_path / "again.csv")])
    assert again.exit_code == 0, again.output
    data2 = read_measurements(tmp_path / "again.csv", model=ur10)
    np.testing.assert_array_equal(data2.position, data.position)  # same seed, same file
    assert load_truth(tmp_path / "again.csv").true == truth.true


def test_cli_simulate_pose_device_and_device_pose(tmp_path, ur10):
    poses, _ = _poses(tmp_path, ur10, 10)
    out = tmp_path / "cmm.csv"
    result = runner.invoke(
        app, ["simulate", "ur10", "--poses", str(poses), "--device", "optical-cmm", "--seed", "3",
              "--device-pose", "4000,0,500mm,0,0,180deg", "-o", str(out)],
    )  # fmt: skip
    assert result.exit_code == 0, result.output
    data = read_measurements(out)
    assert data.observes == "pose"
    truth = load_truth(out)
    np.testing.assert_allclose(truth.device.T_base_device[:3, 3], [4.0, 0.0, 0.5], atol=1e-12)


def test_cli_simulate_reports_errors_cleanly(tmp_path, ur10):
    poses, _ = _poses(tmp_path, ur10, 5)
    result = runner.invoke(
        app, ["simulate", "ur10", "--poses", str(poses), "--device", "plate", "-o", "x.csv"]
    )
    assert result.exit_code == 2 and "plan the poses to touch" in result.output
    result = runner.invoke(
        app, ["simulate", "ur10", "--poses", str(poses), "--device", "lidar", "-o", "x.csv"]
    )
    assert result.exit_code == 2 and "unknown device 'lidar'" in result.output
    bad = tmp_path / "bad.csv"
    bad.write_text("q1,q2\n0.1,0.2\n")
    result = runner.invoke(app, ["simulate", "ur10", "--poses", str(bad), "-o", str(tmp_path / "y.csv")])
    assert result.exit_code == 2 and "missing joint column(s) q3 (elbow)" in result.output


def test_cli_simulate_wants_units_on_its_quantities(tmp_path, ur10):
    poses, _ = _poses(tmp_path, ur10)
    base = ["simulate", "ur10", "--poses", str(poses), "-o", str(tmp_path / "m.csv")]
    for extra, text in [
        (["--noise", "0.02"], "--noise 0.02: give the unit, e.g. 0.02mm"),
        (["--length-tol", "0.5"], "--length-tol 0.5: give the unit, e.g. 0.5mm"),
        (["--angle-tol", "0.05"], "--angle-tol 0.05: give the unit, e.g. 0.05deg"),
        (["--tol", "theta2=0.2"], "--tol theta2=0.2: give the unit"),
    ]:
        result = runner.invoke(app, [*base, *extra])
        assert result.exit_code == 2 and text in result.output, result.output
        assert not (tmp_path / "m.csv").exists()
