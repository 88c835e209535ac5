"""Exports that are right or refused (issues 31 item 4 and 38): the default calibration path
(complete model, residual auto) exported as URDF and UR kinematics and read back at random
configurations with a tool point off the flange's axes; a hybrid calibration exports its
best physics-only calibration; names validated and escaped (every export parses); a
hand-edited model.yaml or an implausible device frame is refused; joint names mapped."""

import dataclasses
import json
import math
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

import robocal as rc
from robocal import spatial
from robocal.cli import app
from robocal.compensate.export import export_urdf, kinematic_part
from robocal.identify.result import CalibrationResult
from robocal.model.steps import Role
from robocal.model.ur_kinematics import read_ur_kinematics, ur_kinematics_fk
from robocal.model.urdf.read import build_from_urdf
from robocal.model.urdf.xml_text import attr, check_name, comment_text

DATA = Path(__file__).parent / "data"
UR10_URDF = DATA / "ur10.urdf"
REAL = Path(__file__).parents[2] / "shared" / "data" / "ur10_laser_tracker" / "measurements_grid.csv"
runner = CliRunner()
P_TOOL = np.array([0.100, 0.050, 0.100])  # an off-axis tool point on the flange (m)


def _calibrate(name, residual="auto", seed=0):
    """The default path: the complete model for position measurements, residual chosen by CV."""
    from robocal.measure import LaserTracker, VirtualRobot, draw_true_model, random_poses, simulate

    nominal = rc.calibration_model(name, "position")
    probe = np.array([0.0, 0.0, 0.1])
    true = draw_true_model(nominal, length=5e-4, angle=np.radians(0.05), seed=seed)
    robot = VirtualRobot(nominal, true, LaserTracker(p_tool_target=probe))
    data = simulate(robot, random_poses(nominal, 60, seed=seed), seed=seed)
    return rc.calibrate(nominal, data, tool_guess=probe, residual=residual)


@pytest.fixture(scope="module")
def folders(tmp_path_factory):
    """Saved default calibrations of four catalog robots, and a UR10 with a learned residual."""
    out = {}
    for name in ("ur10", "ur5", "kr16", "irb2400", "puma560"):
        out[name] = tmp_path_factory.mktemp(name) / "cal"
        _calibrate(name).save(out[name])
    hybrid = _calibrate("ur10", residual="joint_fourier", seed=3)
    out["hybrid"] = tmp_path_factory.mktemp("hybrid") / "cal"
    hybrid.save(out["hybrid"])
    return out


def _robot_flange(model, q):
    """``(n, 4, 4)`` the model's flange (without the measured tool steps) at ``q``."""
    robot = dataclasses.replace(
        model, steps=tuple(s for s in model.steps if s.role is not Role.TOOL), joint_effects=(), bodies=()
    )
    return robot.fk(q)


def _pin_fk(path, frame, q):
    """test_export's Pinocchio frames, skipped (this test alone) without Pinocchio."""
    pytest.importorskip("pinocchio")
    from tests.test_export import _pin_fk as frames

    return frames(path, frame, q)


def _angle_deg(Ra, Rb):
    return np.degrees(np.linalg.norm(spatial.matrix_to_rotvec(Ra @ np.swapaxes(Rb, 1, 2)), axis=1))


def _tool_points(T):
    return T[:, :3, :3] @ P_TOOL + T[:, :3, 3]


def _q(model, n=25, seed=5):
    from robocal.measure.ik_starts import random_configurations

    return random_configurations(model, n, np.random.default_rng(seed))


def _export(args):
    res = runner.invoke(app, ["export", *map(str, args)])
    return res.exit_code, " ".join(res.output.split())


# ---------------------------------------------------------------------- closed loops
@pytest.mark.parametrize("name", ["ur10", "kr16", "irb2400", "puma560"])
def test_default_calibration_urdf_closed_loop(folders, tmp_path, name):
    """Read back by robocal's URDF reader and by Pinocchio: the tool point at (100, 50, 100) mm
    on the flange agrees with the calibrated physics-only model to 1e-6 m, and the flange is
    turned as the robot's (the flange rotated by 180 deg put the point 225-286 mm away)."""
    result = CalibrationResult.load(folders[name])
    physics = kinematic_part(result).calibrated
    out = tmp_path / f"{name}.urdf"
    code, text = _export(
        ["urdf", folders[name], "--device-link", "tracker", "--tool-link", "probe", "-o", out]
    )
    assert code == 0, text
    ET.parse(out)
    q = _q(physics.model)
    want = _robot_flange(physics.model, q)
    nominal = _robot_flange(rc.robot(name), q)
    read_back = build_from_urdf(out, tip="flange").model  # rooted at the device link
    for got in (read_back.fk(q), _pin_fk(out, "flange", q)):
        got = spatial.inverse(physics.frame) @ got
        assert np.abs(_tool_points(got) - _tool_points(want)).max() < 1e-6
        assert _angle_deg(got[:, :3, :3], nominal[:, :3, :3]).max() < 1.0
        assert np.linalg.norm(_tool_points(got) - _tool_points(nominal), axis=1).max() < 10e-3
    probe = _pin_fk(out, "probe", q)
    assert np.abs(probe[:, :3, 3] - physics.predict(q)[:, :3, 3]).max() < 1e-6


@pytest.mark.parametrize("name", ["ur10", "ur5"])
def test_default_calibration_ur_kinematics_closed_loop(folders, tmp_path, name):
    """The UR kinematics file read back (by the format's FK and by robocal's reader): tool
    point at 1e-6 m of the physics-only model, flange turned as the robot's."""
    result = CalibrationResult.load(folders[name])
    physics = kinematic_part(result).calibrated
    out = tmp_path / "kin.yaml"
    code, text = _export(["ur-kinematics", folders[name], "-o", out])
    assert code == 0, text
    import yaml

    entries = yaml.safe_load(out.read_text())["kinematics"]
    seg = np.array(
        [[entries[k][a] for a in ("x", "y", "z", "roll", "pitch", "yaw")] for k in entries if k != "hash"]
    )
    q = _q(physics.model)
    want = _robot_flange(physics.model, q)
    rest = np.eye(4)
    from robocal.compensate.export import export_ur_kinematics

    rest = export_ur_kinematics(physics).T_flange_rest
    got = ur_kinematics_fk(seg, q) @ rest
    assert np.abs(_tool_points(got) - _tool_points(want)).max() < 1e-6
    nominal = _robot_flange(rc.robot(name), q)
    assert _angle_deg(got[:, :3, :3], nominal[:, :3, :3]).max() < 1.0
    back = read_ur_kinematics(out, measure="pose")
    assert np.abs(_tool_points(back.fk(q) @ rest) - _tool_points(want)).max() < 1e-6


def test_hybrid_exports_the_physics_only_calibration_and_says_so(folders, tmp_path):
    """A calibration with a learned residual exports the physics-only calibration stored with
    it (not the hybrid's physical part), and states both CV errors."""
    result = CalibrationResult.load(folders["hybrid"])
    assert result.model.residual is not None
    physics = kinematic_part(result).calibrated
    assert physics.model.residual is None
    hybrid_part = dataclasses.replace(result.model, residual=None)
    q = _q(physics.model)
    assert np.abs(physics.model.fk(q)[:, :3, 3] - hybrid_part.fk(q)[:, :3, 3]).max() > 1e-9
    out = tmp_path / "h.urdf"
    code, text = _export(["urdf", folders["hybrid"], "--urdf", UR10_URDF, "--device-link", "t", "-o", out])
    assert code == 0, text
    assert "physics-only" in text and "mapped by chain order" in text
    got = _pin_fk(out, "tool0", q)
    want = physics.frame @ _robot_flange(physics.model, q)
    assert np.abs(_tool_points(got) - _tool_points(want)).max() < 1e-6
    assert "physics-only" in out.read_text()
    kin = tmp_path / "k.yaml"
    code, text = _export(["ur-kinematics", folders["hybrid"], "-o", kin])
    assert code == 0 and "physics-only" in text


def test_hybrid_without_a_physics_only_calibration_is_refused(folders, tmp_path):
    result = CalibrationResult.load(folders["hybrid"])
    bare = result.replace(records={k: v for k, v in result.records.items() if k != "physics_only"})
    with pytest.raises(ValueError, match="learned residual"):
        export_urdf(bare)
    model_file = tmp_path / "hybrid.yaml"
    rc.save_model(result.model, model_file)
    code, _ = _export(["urdf", model_file, "-o", tmp_path / "x.urdf"])
    assert code == 2 and not (tmp_path / "x.urdf").exists()
    code, _ = _export(["ur-kinematics", model_file, "-o", tmp_path / "x.yaml"])
    assert code == 2 and not (tmp_path / "x.yaml").exists()


@pytest.mark.skipif(not REAL.is_file(), reason="the real UR10 series is not here")
def test_real_ur10_physics_only_export_beats_the_hybrids_physical_part(tmp_path):
    """Real data, default path: the exported kinematics predict the held-out poses better than
    the hybrid's physical part would (measured 0.417 vs 0.505 mm mean)."""
    cols = "q1=shoulder_pan_joint,q2=shoulder_lift_joint,q3=elbow_joint,q4=wrist_1_joint,"
    cols += "q5=wrist_2_joint,q6=wrist_3_joint,x=measurement_x,y=measurement_y,z=measurement_z"
    read = dict(length_unit="mm", sep=";", decimal=",", columns=cols, orientation="none")
    nominal = rc.calibration_model("ur10", "position")
    data = rc.read_measurements(REAL, model=nominal, **read)
    train = np.random.default_rng(0).choice(data.n, 100, replace=False)
    test = np.setdiff1d(np.arange(data.n), train)
    result = rc.calibrate(nominal, data.subset(train), tool_guess=[0, 0, 0.109], residual="auto")
    if result.model.residual is None:
        pytest.skip("CV chose the physics alone")
    physics = kinematic_part(result).calibrated

    def mean_mm(res, model):
        p = (res.frame @ model.fk(data.q[test]))[:, :3, 3]
        return float(np.linalg.norm(p - data.position[test], axis=1).mean() * 1e3)

    exported = mean_mm(physics, physics.model)
    assert exported < mean_mm(result, dataclasses.replace(result.model, residual=None))


# ---------------------------------------------------------------------- names and XML
@pytest.mark.parametrize(
    "option, value",
    [
        ("--device-link", 'dev"/><link name="evil'),
        ("--tool-link", "a&b<c"),
        ("--tool-link", "probe><gazebo><plugin"),
        ("--tip", 'tool0"'),
    ],
)
def test_unsafe_names_in_options_are_refused(folders, tmp_path, option, value):
    out = tmp_path / "x.urdf"
    code, text = _export(["urdf", folders["ur10"], option, value, "-o", out])
    assert code == 2 and option in text
    assert not out.exists()


def test_unsafe_model_or_joint_names_are_refused_not_pasted(tmp_path):
    model = rc.robot("ur10")
    for bad in (
        dataclasses.replace(model, name='x"><link name="evil"/><robot name="y'),
        model.with_joint_names({"elbow": 'elbow"/><joint name="evil'})
        if hasattr(model, "with_joint_names")
        else None,
    ):
        if bad is None:
            continue
        path = tmp_path / "m.yaml"
        rc.save_model(bad, path)
        out = tmp_path / "m.urdf"
        code, _ = _export(["urdf", path, "-o", out])
        assert code == 2 and not out.exists()


def test_names_from_a_source_urdf_are_escaped(tmp_path):
    """A source URDF's link names are written back escaped (they were parsed, so ``&quot;``
    came back as a quote): the export parses and has no injected element."""
    text = UR10_URDF.read_text().replace('"base_link"', '"base&amp;link"')
    src = tmp_path / "amp.urdf"
    src.write_text(text)
    nominal = build_from_urdf(src, measure="position").model
    result_model = dataclasses.replace(nominal, steps=nominal.steps)
    from robocal.model.urdf.export import calibrated_urdf

    ex = calibrated_urdf(result_model, src, T_device_base=np.eye(4), device_link="world")
    root = ET.fromstring(ex.text)
    assert {link.get("name") for link in root.iter("link")} >= {"base&link", "world"}


def test_name_checks_and_escaping():
    assert check_name("tool0", "--tip") == "tool0"
    for bad in ("", "-x", "a b", "a&b", 'a"b', "a<b", "x" * 201):
        with pytest.raises(ValueError, match="--tip"):
            check_name(bad, "--tip")
    value = 'x&"<>y'
    assert ET.fromstring("<a b=" + attr(value) + "/>").get("b") == value
    for text in ("a--b", "a---", "-->", "x\x00y"):
        ET.fromstring(f"<r><!-- {comment_text(text)} --></r>")


def test_every_export_parses(folders, tmp_path):
    for name in ("ur10", "kr16", "irb2400", "puma560", "hybrid"):
        for extra in ([], ["--device-link", "world", "--tool-link", "tcp"]):
            out = tmp_path / f"{name}{len(extra)}.urdf"
            code, text = _export(["urdf", folders[name], *extra, "-o", out])
            assert code == 0, text
            ET.parse(out)
    out = tmp_path / "src.urdf"
    code, text = _export(["urdf", folders["ur10"], "--urdf", UR10_URDF, "--tool-link", "p", "-o", out])
    assert code == 0, text
    ET.parse(out)


# ---------------------------------------------------------------------- files that disagree
def _copy(folder, tmp_path):
    import shutil

    dst = tmp_path / "cal"
    shutil.copytree(folder, dst)
    return dst


def test_hand_edited_model_yaml_is_refused(folders, tmp_path):
    cal = _copy(folders["ur10"], tmp_path)
    path = cal / "model.yaml"
    text = path.read_text()
    i = text.index("value: ", text.index("param: d4") if "param: d4" in text else text.index("value: ") + 1)
    j = text.index("\n", i)
    path.write_text(text[:i] + "value: 0.2" + text[j:])
    for args in (["urdf", cal, "-o", tmp_path / "x.urdf"], ["ur-kinematics", cal, "-o", tmp_path / "x.yaml"]):
        code, text_out = _export(args)
        assert code == 2 and "model.yaml" in text_out
    assert not (tmp_path / "x.urdf").exists() and not (tmp_path / "x.yaml").exists()


def test_edited_model_without_a_digest_is_refused_by_its_parameters(folders, tmp_path):
    cal = _copy(folders["ur10"], tmp_path)
    data = json.loads((cal / "result.json").read_text())
    data.pop("model_sha256")
    name = next(p["name"] for p in data["parameters"] if not p["name"].startswith("frame_"))
    p = next(p for p in data["parameters"] if p["name"] == name)
    p["estimate"] += 1e-3
    (cal / "result.json").write_text(json.dumps(data))
    code, text = _export(["urdf", cal, "-o", tmp_path / "x.urdf"])
    assert code == 2 and name in text and not (tmp_path / "x.urdf").exists()


@pytest.mark.parametrize("value", [1e308, float("nan"), 5e3])
def test_implausible_device_frame_is_refused(folders, tmp_path, value):
    cal = _copy(folders["ur10"], tmp_path)
    data = json.loads((cal / "result.json").read_text())
    data["frame"]["T_device_base"][0][3] = value
    (cal / "result.json").write_text(json.dumps(data).replace("NaN", "NaN"))
    out = tmp_path / "x.urdf"
    code, text = _export(["urdf", cal, "--device-link", "tracker", "-o", out])
    assert code == 2 and "T_device_base" in text
    assert not out.exists()


# ---------------------------------------------------------------------- joint names and limits
def test_joint_map_by_option_and_refusals(folders, tmp_path):
    names = rc.robot("ur10").joint_names
    mapping = ",".join(f"{n}={n}_joint" for n in names)
    out = tmp_path / "m.urdf"
    code, text = _export(["urdf", folders["ur10"], "--urdf", UR10_URDF, "--joint-map", mapping, "-o", out])
    assert code == 0 and "--joint-map" in text
    swapped = mapping.replace("wrist_1=wrist_1_joint", "wrist_1=wrist_2_joint").replace(
        "wrist_2=wrist_2_joint", "wrist_2=wrist_1_joint"
    )
    for bad in (swapped, "nonsense", "elbow=elbow_joint,elbow=wrist_1_joint", "x=y"):
        out = tmp_path / "bad.urdf"
        code, _ = _export(["urdf", folders["ur10"], "--urdf", UR10_URDF, "--joint-map", bad, "-o", out])
        assert code == 2 and not out.exists()


def test_chain_order_refuses_another_robot(folders, tmp_path):
    """KR 16's joints mapped by chain order onto a UR10 URDF: same count and kinds, axes
    disagree: refused."""
    out = tmp_path / "x.urdf"
    code, _ = _export(["urdf", folders["kr16"], "--urdf", UR10_URDF, "-o", out])
    assert code == 2 and not out.exists()


def test_kinematic_urdf_limits_are_the_catalogs(folders, tmp_path):
    out = tmp_path / "ur10.urdf"
    assert _export(["urdf", folders["ur10"], "-o", out])[0] == 0
    limits = [j.find("limit") for j in ET.parse(out).getroot().iter("joint") if j.get("type") != "fixed"]
    assert all(float(lim.get("effort")) > 0 and float(lim.get("velocity")) > 0 for lim in limits)
    model = rc.robot("kr16")
    out = tmp_path / "kr16.urdf"
    code, text = _export(["urdf", folders["kr16"], "-o", out])
    assert code == 0 and "NOT known" in text
    joints = [j for j in ET.parse(out).getroot().iter("joint") if j.get("type") != "fixed"]
    for j, step in zip(joints, [s for s in model.steps if s.joint is not None], strict=True):
        lo, hi = step.joint.limits
        assert math.isclose(float(j.find("limit").get("lower")), lo, abs_tol=1e-9)
        assert math.isclose(float(j.find("limit").get("upper")), hi, abs_tol=1e-9)
