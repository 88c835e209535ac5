"""The calibrated robot leaves robocal: URDF export (checked with Pinocchio) and UR
kinematics (checked with an FK written here from the format's definition)."""

import dataclasses
import re
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

import robocal as rc
from robocal import spatial
from robocal.cli import app
from robocal.model.steps import Step
from robocal.model.ur_kinematics import URKinematicsError, read_ur_kinematics, ur_kinematics
from robocal.model.urdf.export import calibrated_urdf
from robocal.model.urdf.read import URDFError, build_from_urdf
from robocal.model.urdf.xml_text import rpy_from_matrix

pin = pytest.importorskip("pinocchio")
DATA = Path(__file__).parent / "data"
UR10_URDF = DATA / "ur10.urdf"
ARM7_URDF = DATA / "arm7.urdf"
runner = CliRunner()
TOOL_STEPS = (Step("Tx", "tcp_x", 0.012), Step("Ty", "tcp_y", -0.02), Step("Tz", "tcp_z", 0.105))


def _calibrated(nominal, seed, scale=1e-3):
    """``nominal`` with every free parameter moved (mm / mrad) and a measured tool."""
    rng = np.random.default_rng(seed)
    model = nominal.with_free_values(nominal.free_values + rng.normal(0, scale, len(nominal.free_values)))
    return dataclasses.replace(model, steps=(*model.steps, *TOOL_STEPS))


def _pin_fk(path, frame, q):
    """Frames ``(n, 4, 4)`` of ``frame`` in the URDF's root by Pinocchio, ``q`` in URDF order
    of the model's joints (continuous joints as cos, sin)."""
    pm = pin.buildModelFromUrdf(str(path))
    data = pm.createData()
    fid = pm.getFrameId(frame)
    out = []
    for qk in q:
        qp = []
        for j in range(1, pm.njoints):
            v = qk[pm.joints[j].idx_v]
            qp += [np.cos(v), np.sin(v)] if pm.joints[j].nq == 2 else [v]
        pin.framesForwardKinematics(pm, data, np.array(qp))
        out.append(data.oMf[fid].homogeneous)
    return np.array(out)


def _agree(T_a, T_b, tol=1e-9):
    """Largest position (m) and rotation (rad) difference."""
    dp = np.linalg.norm(T_a[:, :3, 3] - T_b[:, :3, 3], axis=1).max()
    dr = np.linalg.norm(spatial.matrix_to_rotvec(T_a[:, :3, :3] @ np.swapaxes(T_b[:, :3, :3], 1, 2)), axis=1)
    assert dp < tol and dr.max() < tol, (dp, dr.max())
    return dp, dr.max()


def test_rpy_is_exact_at_gimbal_lock():
    for angles in (
        [0.1, np.pi / 2, -0.3],
        [0.2, -np.pi / 2 + 1e-9, 0.4],
        [3.0, 0.2, -3.0],
        [0, 1.570796325, 0],
    ):
        R = spatial.rotz(angles[2]) @ spatial.roty(angles[1]) @ spatial.rotx(angles[0])
        r, p, y = rpy_from_matrix(R)
        np.testing.assert_allclose(spatial.rotz(y) @ spatial.roty(p) @ spatial.rotx(r), R, atol=1e-15)


@pytest.mark.parametrize("measure", ["pose", "position"])
def test_ur10_urdf_round_trip_with_device_and_tool(tmp_path, measure):
    nominal = build_from_urdf(UR10_URDF, measure=measure).model
    model = _calibrated(nominal, 1)
    T_device_base = spatial.homogeneous(spatial.rotvec_to_matrix([0.01, -0.02, 2.5]), [2.0, 1.5, -0.3])
    ex = calibrated_urdf(
        model,
        UR10_URDF,
        nominal=nominal,
        T_device_base=T_device_base,
        device_link="tracker",
        tool_link="probe",
        notes=["compliance contributes up to 0.12 mm"],
    )
    out = tmp_path / "ur10_calibrated.urdf"
    out.write_text(ex.text)
    q = np.random.default_rng(2).uniform(-3, 3, (40, 6))
    _agree(_pin_fk(out, "probe", q), T_device_base @ model.fk(q))
    if measure == "pose":  # the flange (tool0) is the model without the measured tool
        robot = dataclasses.replace(model, steps=model.steps[: -len(TOOL_STEPS)])
        _agree(_pin_fk(out, "tool0", q), T_device_base @ robot.fk(q))
    assert ex.root == "tracker" and ex.tip == "tool0"
    assert "compliance contributes up to 0.12 mm" in ex.text
    assert "<calibration" not in ex.text


def test_nominal_model_leaves_the_urdf_byte_identical_but_for_the_comment():
    nominal = build_from_urdf(UR10_URDF).model
    ex = calibrated_urdf(nominal, UR10_URDF, nominal=nominal)
    assert ex.changed == ()
    original = UR10_URDF.read_text()
    assert re.sub(r"\n  <!-- robocal:.*?-->", "", ex.text, flags=re.S) == original


def _tree(text, skip_comment=True):
    """Every element (tag, attributes, text) in document order, comments included, with the
    joint origins and axes of the kinematic chain left out."""
    parser = ET.XMLParser(target=ET.TreeBuilder(insert_comments=True))
    root = ET.fromstring(text, parser=parser)
    rows = []
    for joint_parent in [root]:
        for el in joint_parent.iter():
            if el.tag is ET.Comment:
                if skip_comment and el.text.strip().startswith("robocal:"):
                    continue
                rows.append(("comment", el.text))
                continue
            rows.append((el.tag, tuple(sorted(el.attrib.items())), (el.text or "").strip()))
    for joint in root.findall("joint"):
        for sub in joint.findall("origin") + joint.findall("axis"):
            rows.remove((sub.tag, tuple(sorted(sub.attrib.items())), (sub.text or "").strip()))
    return rows


def test_arm7_round_trip_hayati_tilts_and_every_element_kept(tmp_path):
    built = build_from_urdf(ARM7_URDF)
    nominal = built.model
    assert {"beta2", "beta3"} <= set(nominal.free_names)  # parallel pairs: Hayati β
    model = _calibrated(nominal, 5)
    model = model.with_values({"beta2": 2e-3, "beta3": -1.5e-3})  # tilts DH cannot hold
    ex = calibrated_urdf(model, ARM7_URDF, nominal=nominal, tool_link="tcp")
    out = tmp_path / "arm7_calibrated.urdf"
    out.write_text(ex.text)
    q = np.random.default_rng(3).uniform(-2, 2, (40, 7))
    dp, dr = _agree(_pin_fk(out, "tcp", q), model.fk(q))
    assert dp < 1e-12 and dr < 1e-12
    # links, meshes, inertials, limits, dynamics, transmissions, gazebo, ros2_control, comments
    assert _tree(ex.text) == _tree(ARM7_URDF.read_text()) + [
        ("link", (("name", "tcp"),), ""),
        ("joint", (("name", "tcp_joint"), ("type", "fixed")), ""),
        ("parent", (("link", "flange"),), ""),
        ("child", (("link", "tcp"),), ""),
    ]
    # byte for byte: only origin tags differ (besides the comment and the added pair)
    text = re.sub(r"\n  <!-- robocal:.*?-->", "", ex.text, flags=re.S)
    text = re.sub(r'\n  <link name="tcp"/>.*?</joint>\n', "", text, flags=re.S)
    new_lines, old_lines = text.splitlines(), ARM7_URDF.read_text().splitlines()
    assert len(new_lines) == len(old_lines)
    changed = [(a, b) for a, b in zip(old_lines, new_lines, strict=True) if a != b]
    assert len(changed) == 8 and all(a.strip().startswith("<origin") for a, _ in changed)


def test_arm7_world_link_and_axis_of_non_z_joints(tmp_path):
    nominal = build_from_urdf(ARM7_URDF).model
    model = _calibrated(nominal, 9, scale=3e-3)
    model = dataclasses.replace(model, steps=model.steps[: -len(TOOL_STEPS)])
    ex = calibrated_urdf(model, ARM7_URDF, nominal=nominal)
    out = tmp_path / "a.urdf"
    out.write_text(ex.text)
    q = np.random.default_rng(4).uniform(-2, 2, (20, 7))
    _agree(_pin_fk(out, "flange", q), model.fk(q))
    assert ex.root == "world"


def test_chain_ending_at_a_moving_link_gets_a_calibrated_flange_link(tmp_path):
    text = ARM7_URDF.read_text()
    start = text.index('  <joint name="flange_fixed"')
    text = text[:start] + text[text.index("</joint>", start) + len("</joint>\n") :]
    text = text.replace('  <link name="flange"/>\n', "")
    source = tmp_path / "arm7_no_flange.urdf"
    source.write_text(text)
    nominal = build_from_urdf(source).model
    model = _calibrated(nominal, 21)
    ex = calibrated_urdf(model, source, nominal=nominal, tool_link="tcp")
    assert ex.tip == "link7_calibrated"
    out = tmp_path / "out.urdf"
    out.write_text(ex.text)
    q = np.random.default_rng(9).uniform(-2, 2, (20, 7))
    _agree(_pin_fk(out, "tcp", q), model.fk(q))
    robot = dataclasses.replace(model, steps=model.steps[: -len(TOOL_STEPS)])
    _agree(_pin_fk(out, "link7_calibrated", q), robot.fk(q))


@pytest.mark.parametrize("name", ["puma560", "ur10", "irb2400", "katana450"])
def test_catalog_robot_gets_a_kinematic_urdf_of_its_own(tmp_path, name):
    model = _calibrated(rc.robot(name), 7)
    ex = calibrated_urdf(model, tool_link="tcp")
    out = tmp_path / f"{name}.urdf"
    out.write_text(ex.text)
    q = np.random.default_rng(5).uniform(-2, 2, (30, model.dof))
    _agree(_pin_fk(out, "tcp", q), model.fk(q))


def test_puma560_with_tilted_parallel_axes(tmp_path):
    """PUMA 560 rebuilt by the builder (its ∥ pair gets a Hayati β), calibrated with a tilt."""
    from robocal.model.builder import build
    from robocal.model.geometry import JointGeometry, Tcp

    puma = rc.robot("puma560")
    F = puma.joint_frames(np.zeros(6))
    previous = np.zeros(3)
    joints = []
    for k in range(6):
        joints.append(
            JointGeometry("revolute", tuple(F[k, :3, 3] - previous), tuple(F[k, :3, 2]), f"j{k + 1}")
        )
        previous = F[k, :3, 3]
    T = puma.fk(np.zeros(6))
    nominal = build(joints, Tcp(tuple(T[:3, 3] - previous), tuple(map(tuple, T[:3, :3]))), name="puma").model
    betas = [n for n in nominal.free_names if n.startswith("beta")]
    assert betas
    model = _calibrated(nominal, 11).with_values({betas[0]: 3e-3})
    ex = calibrated_urdf(model, tool_link="tcp")
    out = tmp_path / "puma.urdf"
    out.write_text(ex.text)
    q = np.random.default_rng(6).uniform(-2, 2, (30, 6))
    _agree(_pin_fk(out, "tcp", q), model.fk(q))


def test_malformed_or_foreign_urdf_is_refused_naming_file_and_line(tmp_path):
    bad = tmp_path / "bad.urdf"
    bad.write_text(UR10_URDF.read_text().replace('<origin xyz="0 0 0.5723"', '<origin xyz="0 0 zz"'))
    nominal = build_from_urdf(UR10_URDF).model
    with pytest.raises(URDFError, match=r"bad\.urdf: line 31: origin xyz"):
        calibrated_urdf(nominal, bad, nominal=nominal)
    broken = tmp_path / "broken.urdf"
    broken.write_text(UR10_URDF.read_text().replace("</joint>", "</jont>", 1))
    with pytest.raises(URDFError, match=r"broken\.urdf: not well-formed XML.*line 18"):
        calibrated_urdf(nominal, broken, nominal=nominal)
    with pytest.raises(URDFError, match=r"arm7\.urdf: the model's joint"):
        calibrated_urdf(nominal, ARM7_URDF, nominal=nominal)


@pytest.fixture(scope="module")
def calibration(tmp_path_factory):
    """A UR10 built from its URDF, calibrated on simulated laser-tracker data (saved)."""
    from robocal.measure import LaserTracker, VirtualRobot, draw_true_model, random_poses, simulate

    nominal = build_from_urdf(UR10_URDF, measure="position").model
    tool = np.array([0.01, 0.02, 0.1])
    true = draw_true_model(nominal, length=2e-3, angle=np.radians(0.2), seed=3)
    robot = VirtualRobot(nominal, true, LaserTracker(p_tool_target=tool))
    result = rc.calibrate(
        nominal, simulate(robot, random_poses(nominal, 80, seed=1), seed=1), tool_guess=tool
    )
    folder = tmp_path_factory.mktemp("export") / "cal"
    result.save(folder)
    return folder, result


def test_cli_export_urdf_round_trip(calibration, tmp_path):
    folder, result = calibration
    out = tmp_path / "calibrated.urdf"
    args = ["export", "urdf", str(folder), "--urdf", str(UR10_URDF), "--device-link", "tracker"]
    res = runner.invoke(app, [*args, "--tool-link", "probe", "-o", str(out)])
    assert res.exit_code == 0, res.output
    q = np.random.default_rng(8).uniform(-3, 3, (20, 6))
    _agree(_pin_fk(out, "probe", q), result.frame @ result.model.fk(q))
    own = tmp_path / "own.urdf"
    assert runner.invoke(app, ["export", "urdf", str(folder), "-o", str(own)]).exit_code == 0
    _agree(_pin_fk(own, "flange", q), result.model.fk(q) @ _tool_inverse(result.model))


def _tool_inverse(model):
    steps = [s for s in model.steps if s.name.startswith("tcp_")]
    return spatial.inverse(spatial.chain_product([s.motion for s in steps], [s.value for s in steps]))


def test_cli_malformed_urdf_writes_nothing(calibration, tmp_path):
    folder, _ = calibration
    bad = tmp_path / "bad.urdf"
    bad.write_text(UR10_URDF.read_text().replace('rpy="0 0 0"/><axis xyz="0 0 1"/>', 'rpy="0 0"/>', 1))
    out = tmp_path / "never.urdf"
    res = runner.invoke(app, ["export", "urdf", str(folder), "--urdf", str(bad), "-o", str(out)])
    assert res.exit_code == 2
    assert "bad.urdf: line 16" in " ".join(res.output.split())
    assert not out.exists()


def test_cli_states_joint_effects_left_out(tmp_path):
    model = rc.robot("katana450")
    path = tmp_path / "katana.yaml"
    rc.save_model(model, path)
    res = runner.invoke(app, ["export", "urdf", str(path), "-o", str(tmp_path / "k.urdf")])
    assert res.exit_code == 0, res.output
    text = " ".join(res.output.split())
    assert re.search(r"joint effects .* contributes up to \d+\.\d+ mm", text)
    assert "contributes up to" in (tmp_path / "k.urdf").read_text()


# ---------------------------------------------------------------------- UR kinematics
def _ur_fk(entries, q):
    """FK straight from the format: per joint translate xyz, rotate Rz(yaw) Ry(pitch) Rx(roll),
    then rotate about z by q."""

    def rx(a):
        c, s = np.cos(a), np.sin(a)
        return np.array([[1, 0, 0, 0], [0, c, -s, 0], [0, s, c, 0], [0, 0, 0, 1.0]])

    def ry(a):
        c, s = np.cos(a), np.sin(a)
        return np.array([[c, 0, s, 0], [0, 1, 0, 0], [-s, 0, c, 0], [0, 0, 0, 1.0]])

    def rz(a):
        c, s = np.cos(a), np.sin(a)
        return np.array([[c, -s, 0, 0], [s, c, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1.0]])

    out = []
    for qk in q:
        T = np.eye(4)
        for j, name in enumerate(["shoulder", "upper_arm", "forearm", "wrist_1", "wrist_2", "wrist_3"]):
            e = entries[name]
            D = np.eye(4)
            D[:3, 3] = [e["x"], e["y"], e["z"]]
            T = T @ D @ rz(e["yaw"]) @ ry(e["pitch"]) @ rx(e["roll"]) @ rz(qk[j])
        out.append(T)
    return np.array(out)


def test_ur_kinematics_of_the_catalog_ur10_is_urs_layout():
    import yaml

    kin = yaml.safe_load(ur_kinematics(rc.robot("ur10")).to_yaml())["kinematics"]
    assert kin["shoulder"]["z"] == pytest.approx(0.1273)
    assert kin["upper_arm"]["roll"] == pytest.approx(np.pi / 2)
    assert kin["forearm"]["x"] == pytest.approx(-0.612)
    assert kin["wrist_1"]["x"] == pytest.approx(-0.5723) and kin["wrist_1"]["z"] == pytest.approx(0.163941)


def test_calibrated_ur_kinematics_match_the_model_by_the_formats_fk(tmp_path):
    import yaml

    model = _calibrated(rc.robot("ur10"), 13, scale=1e-3)
    kin = ur_kinematics(model)
    entries = yaml.safe_load(kin.to_yaml())["kinematics"]
    q = np.random.default_rng(1).uniform(-3, 3, (30, 6))
    robot = dataclasses.replace(model, steps=model.steps[: -len(TOOL_STEPS)])
    _agree(_ur_fk(entries, q) @ kin.T_flange_rest, robot.fk(q))
    # the DH flange (d6 along, θ6 about the last axis) fits the format; a6 and α6 do not
    mm, deg = kin.flange_rest_mm_deg
    assert 0 < mm < 5 and 0 < deg < 0.5


def test_read_ur_factory_calibration_as_starting_model(tmp_path):
    entries = {
        "shoulder": {"x": 0, "y": 0, "z": 0.1273184, "roll": 0, "pitch": 0, "yaw": 3.1e-5},
        "upper_arm": {"x": 1.2e-4, "y": 0, "z": 0, "roll": 1.5712, "pitch": 0, "yaw": 2.2e-6},
        "forearm": {"x": -0.61207, "y": 0, "z": 0, "roll": 4e-4, "pitch": -3e-4, "yaw": 1e-5},
        "wrist_1": {"x": -0.57226, "y": 2e-4, "z": 0.16391, "roll": 2e-3, "pitch": -1e-3, "yaw": -2e-6},
        "wrist_2": {"x": 1e-5, "y": -0.115702, "z": 1e-6, "roll": 1.57082, "pitch": 0, "yaw": 1e-6},
        "wrist_3": {"x": 1e-6, "y": 0.09219, "z": -2e-6, "roll": 1.570790, "pitch": 3.14159, "yaw": 3.14159},
    }
    path = tmp_path / "calibration.yaml"
    import yaml

    path.write_text(yaml.safe_dump({"kinematics": {**entries, "hash": "calib_123"}}))
    model = read_ur_kinematics(path)
    assert model.joint_names[0] == "shoulder_pan_joint" and len(model.free_names) == 30
    q = np.random.default_rng(2).uniform(-3, 3, (30, 6))
    _agree(model.fk(q), _ur_fk(entries, q))
    # and back: the written file reproduces the same FK
    back = yaml.safe_load(ur_kinematics(model).to_yaml())["kinematics"]
    _agree(_ur_fk(back, q), model.fk(q))
    # the CLI builds a model file from it
    out = tmp_path / "model.yaml"
    res = runner.invoke(app, ["model", "build", str(path), "-o", str(out)])
    assert res.exit_code == 0, res.output
    _agree(rc.load_model(out).fk(q), model.fk(q))


def test_bad_ur_kinematics_file_names_the_key(tmp_path):
    path = tmp_path / "k.yaml"
    path.write_text("kinematics:\n  shoulder: {x: 0, y: 0, z: 0.1, roll: 0, pitch: 0, yaw: oops}\n")
    with pytest.raises(URKinematicsError, match=r"k\.yaml: kinematics\.shoulder\.yaw is 'oops'"):
        read_ur_kinematics(path)


def test_cli_export_ur_kinematics(tmp_path):
    import yaml

    model = _calibrated(rc.robot("ur10"), 17)
    src = tmp_path / "m.yaml"
    rc.save_model(model, src)
    out = tmp_path / "calibration.yaml"
    res = runner.invoke(app, ["export", "ur-kinematics", str(src), "-o", str(out)])
    assert res.exit_code == 0, res.output
    assert "cannot hold" in " ".join(res.output.split())
    entries = yaml.safe_load(out.read_text())["kinematics"]
    q = np.random.default_rng(3).uniform(-3, 3, (10, 6))
    kin = ur_kinematics(model)
    _agree(_ur_fk(entries, q) @ kin.T_flange_rest, model.fk(q) @ _tool_inverse(model))
