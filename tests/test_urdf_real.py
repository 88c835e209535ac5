"""``robocal model build`` on public robot descriptions as they come (issue 33 item 5).

The URDFs in tests/data/urdf/ are expanded xacros of public description packages (sources and
licences in its README): grippers with ``<mimic>`` fingers, fixed joints with ``<axis xyz="0 0
0"/>``, camera and sensor frames branching off the chain, meshes referenced and absent.  Only
the chain from the root to the tip is read; the model's forward kinematics must be the URDF's
own (Pinocchio on the whole file) at random configurations.
"""

from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

import robocal as rc
from robocal.cli.app import app
from robocal.model.urdf.read import URDFError, build_from_urdf, default_tip, geometry_from_urdf

pin = pytest.importorskip("pinocchio")

from tests.test_urdf import _pin_tip_pose as _pin_pose  # noqa: E402  (after the skip)

DATA = Path(__file__).parent / "data" / "urdf"
runner = CliRunner()

# file, tip (None: the default), the chain's joint count, identified parameters (pose)
CASES = [
    ("gen3_lite.urdf", "tool_frame", 6, 30),  # zero axes on fixed joints, mimic fingers
    ("iiwa14.urdf", None, 7, 34),  # zero axes on fixed joints
    ("panda_franka.urdf", "panda_hand_tcp", 7, 34),  # mimic finger, self-collision frames
    ("ur5e.urdf", None, 6, 30),  # base / ft_frame / flange -> tool0 branches
    ("xarm6.urdf", "link_tcp", 6, 30),  # gripper of six joints, five of them mimic
    ("m10ia.urdf", None, 6, 30),
    ("kr16_2.urdf", None, 6, 30),
]


@pytest.mark.parametrize(("name", "tip", "dof", "free"), CASES)
def test_public_description_builds_with_the_urdf_forward_kinematics(name, tip, dof, free):
    path = DATA / name
    result = build_from_urdf(path, measure="pose", tip=tip)
    model = result.model
    assert model.dof == dof and len(model.free_names) == result.rank == free
    end = tip or "tool0"  # every default here is the ROS tool0
    names = list(model.joint_names)
    rng = np.random.default_rng(7)
    for q in rng.uniform(-2.5, 2.5, (8, dof)):
        np.testing.assert_allclose(model.fk(q[None])[0], _pin_pose(path, end, names, q), atol=1e-10)


def test_default_tip_is_the_deepest_link_of_the_single_longest_chain():
    """UR5e: base, ft_frame and flange -> tool0 hang off the chain; tool0 is the deepest."""
    from robocal.model.urdf.read import _load

    assert default_tip(DATA / "ur5e.urdf", _load(DATA / "ur5e.urdf")[1]) == "tool0"


@pytest.mark.parametrize(
    ("name", "ends"),
    [
        ("panda_franka.urdf", ("panda_leftfinger", "panda_rightfinger", "panda_hand_tcp")),
        ("gen3_lite.urdf", ("right_finger_dist_link", "left_finger_dist_link", "tool_frame")),
    ],
)
def test_branching_grippers_are_refused_naming_the_chain_ends(name, ends):
    """Two fingers make two longest chains moving different joints: no tip is guessed."""
    with pytest.raises(URDFError, match="--tip") as info:
        geometry_from_urdf(DATA / name)
    assert all(repr(end) in str(info.value) for end in ends)


@pytest.mark.parametrize(
    ("name", "tip"), [("gen3_lite.urdf", "right_finger_dist_link"), ("xarm6.urdf", "left_finger")]
)
def test_a_mimic_joint_on_the_chain_is_refused_by_name(name, tip):
    with pytest.raises(URDFError, match="mimic"):
        geometry_from_urdf(DATA / name, tip=tip)


def test_cli_model_build_of_the_gen3_lite_and_the_iiwa(tmp_path):
    out = tmp_path / "gen3_lite.yaml"
    args = ["model", "build", str(DATA / "gen3_lite.urdf"), "-o", str(out)]
    refused = runner.invoke(app, args)
    assert refused.exit_code == 2 and not out.exists()
    assert "tool_frame" in refused.output and "Traceback" not in refused.output
    built = runner.invoke(app, [*args, "--tip", "tool_frame"])
    assert built.exit_code == 0, built.output
    assert rc.load_model(out).dof == 6
    out7 = tmp_path / "iiwa.yaml"
    built = runner.invoke(app, ["model", "build", str(DATA / "iiwa14.urdf"), "-o", str(out7)])
    assert built.exit_code == 0, built.output
    assert rc.load_model(out7).dof == 7


def _hand_written(tmp_path: Path, extra: str = "") -> Path:
    """A 3-joint arm with what real descriptions have: a continuous joint, fixed joints with a
    zero axis, a package:// mesh that is not there, a camera branch, and a gripper whose
    second finger mimics the first."""
    path = tmp_path / "arm.urdf"

    def link(name: str) -> str:
        return (
            f'<link name="{name}"><visual><geometry><mesh filename="package://nowhere/{name}.stl"/>'
            "</geometry></visual></link>"
        )

    def joint(name, kind, parent, child, xyz, axis="0 0 1", more=""):
        return (
            f'<joint name="{name}" type="{kind}"><parent link="{parent}"/><child link="{child}"/>'
            f'<origin xyz="{xyz}" rpy="0.1 0 0"/><axis xyz="{axis}"/>{more}</joint>'
        )

    lim = '<limit lower="-2" upper="2" effort="1" velocity="1"/>'
    links = ["world", "base", "l1", "l2", "l3", "flange", "tool0", "camera", "finger_a", "finger_b"]
    path.write_text(
        '<?xml version="1.0"?><robot name="arm">'
        + "".join(map(link, links))
        + joint("world_joint", "fixed", "world", "base", "0 0 0", axis="0 0 0")
        + joint("j1", "revolute", "base", "l1", "0 0 0.3", more=lim)
        + joint("j2", "revolute", "l1", "l2", "0.1 0 0.2", axis="0 1 0", more=lim)
        + joint("j3", "continuous", "l2", "l3", "0.4 0 0", axis="1 0 0")
        + joint("flange_joint", "fixed", "l3", "flange", "0.1 0 0", axis="0 0 0")
        + joint("tool_joint", "fixed", "flange", "tool0", "0 0 0.05", axis="0 0 0")
        + joint("camera_joint", "fixed", "l3", "camera", "0 0.05 0", axis="0 0 0")
        + joint("finger_a_joint", "prismatic", "flange", "finger_a", "0 0 0.01", axis="0 1 0", more=lim)
        + joint(
            "finger_b_joint",
            "prismatic",
            "flange",
            "finger_b",
            "0 0 0.01",
            axis="0 -1 0",
            more=lim + '<mimic joint="finger_a_joint"/>',
        )
        + extra
        + "</robot>"
    )
    return path


def test_hand_written_arm_with_the_features_of_real_descriptions(tmp_path):
    path = _hand_written(tmp_path)
    with pytest.raises(URDFError, match="--tip"):  # finger_a (4 joints) vs finger_b (4 joints)
        geometry_from_urdf(path)
    model = build_from_urdf(path, tip="tool0").model
    assert list(model.joint_names) == ["j1", "j2", "j3"]
    rng = np.random.default_rng(11)
    for q in rng.uniform(-3, 3, (10, 3)):
        np.testing.assert_allclose(
            model.fk(q[None])[0], _pin_pose(path, "tool0", ["j1", "j2", "j3"], q), atol=1e-12
        )
    # a joint's name stands for its child link
    by_joint = build_from_urdf(path, tip="tool_joint").model
    np.testing.assert_allclose(by_joint.fk(np.zeros((1, 3))), model.fk(np.zeros((1, 3))), atol=1e-15)
    with pytest.raises(URDFError, match="mimic"):
        geometry_from_urdf(path, tip="finger_b")
    # off the chain nothing is read: a camera origin that is not numbers does not matter
    odd = tmp_path / "odd.urdf"
    odd.write_text(path.read_text().replace('<origin xyz="0 0.05 0"', '<origin xyz="${cam_y} 0.05 0"'))
    assert build_from_urdf(odd, tip="tool0").model.dof == 3
    # on the chain, a movable joint's zero axis is refused (j2's axis made zero)
    bad = tmp_path / "bad.urdf"
    bad.write_text(path.read_text().replace('<axis xyz="0 1 0"/><limit', '<axis xyz="0 0 0"/><limit', 1))
    with pytest.raises(URDFError, match="joint 'j2': the axis is zero"):
        geometry_from_urdf(bad, tip="tool0")


def test_equally_deep_fixed_branches_are_refused(tmp_path):
    """tool0 and a second tool frame at the same depth off the same joints: ambiguous."""
    extra = (
        '<link name="tool1"/><joint name="tool1_joint" type="fixed"><parent link="flange"/>'
        '<child link="tool1"/><origin xyz="0 0 0.2"/></joint>'
    )
    text = _hand_written(tmp_path, extra).read_text()
    # without the gripper the longest chains are tool0 and tool1, 3 joints each, equally deep
    for finger in ("finger_a", "finger_b"):
        start = text.index(f'<joint name="{finger}_joint"')
        text = text[:start] + text[text.index("</joint>", start) + len("</joint>") :]
    path = tmp_path / "two_tools.urdf"
    path.write_text(text)
    with pytest.raises(URDFError, match=r"'tool0'.*'tool1'|'tool1'.*'tool0'"):
        geometry_from_urdf(path)
    assert build_from_urdf(path, tip="tool1").model.dof == 3
