"""URDF import through Pinocchio into the builder."""

from pathlib import Path

import numpy as np
import pytest

import robocal as rc
from robocal.model.urdf.read import URDFError, build_from_urdf, geometry_from_urdf

pin = pytest.importorskip("pinocchio")
UR10_URDF = Path(__file__).parent / "data" / "ur10.urdf"
PANDA_URDF = Path(__file__).parents[1].parent / "shared" / "data" / "ball_in_socket" / "urdf" / "panda.urdf"


def test_urdf_model_reproduces_pinocchio_fk():
    result = build_from_urdf(UR10_URDF, measure="pose")
    model = result.model
    assert len(model.free_names) == result.rank == 30
    pm = pin.buildModelFromUrdf(str(UR10_URDF))
    data = pm.createData()
    tool = pm.getFrameId("tool0")
    q = np.random.default_rng(0).uniform(-3, 3, (25, 6))
    T = model.fk(q)
    for k in range(len(q)):
        qp = np.concatenate([q[k, :5], [np.cos(q[k, 5]), np.sin(q[k, 5])]])  # wrist_3 is continuous
        pin.framesForwardKinematics(pm, data, qp)
        np.testing.assert_allclose(data.oMf[tool].homogeneous, T[k], atol=1e-12)


def test_urdf_joints_names_and_limits():
    name, joints, tcp = geometry_from_urdf(UR10_URDF)
    assert name == "ur10_urdf"
    assert [j.name for j in joints][:2] == ["shoulder_pan_joint", "shoulder_lift_joint"]
    assert joints[2].limits == pytest.approx((-3.1416, 3.1416))
    assert joints[5].limits is None  # continuous
    np.testing.assert_allclose(tcp.position, [0, 0.0922, 0], atol=1e-12)


def test_rc_model_from_urdf_and_tip_choice():
    model = rc.model_from_urdf(UR10_URDF, measure="position", tip="wrist_2_link")
    assert model.dof == 5
    with pytest.raises(URDFError, match="no link 'nope'"):
        geometry_from_urdf(UR10_URDF, tip="nope")


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ('<?xml version="1.0"?><!DOCTYPE r [<!ENTITY a "aaaa">]><robot name="r"/>', "DOCTYPE/ENTITY"),
        ("<html></html>", "not a URDF"),
        ('<robot name="r"><link name="a"/></robot>', "no movable joint"),
    ],
)
def test_bad_urdf_files_are_rejected(tmp_path, text, message):
    path = tmp_path / "bad.urdf"
    path.write_text(text)
    with pytest.raises(URDFError, match=message) as info:
        build_from_urdf(path)
    assert str(path) in str(info.value)


def test_continuous_joint_with_an_oblique_axis(tmp_path):
    """Pinocchio models it as JointModelRevoluteUnboundedUnaligned, which has no ``axis``
    attribute: the axis comes from the joint's motion subspace (found by fuzzing)."""
    path = tmp_path / "oblique.urdf"
    path.write_text(
        '<robot name="r"><link name="a"/><link name="b"/><link name="c"/>'
        '<joint name="j1" type="continuous"><parent link="a"/><child link="b"/>'
        '<origin xyz="0.1 0 0.2"/><axis xyz="0 0.6 0.8"/></joint>'
        '<joint name="j2" type="fixed"><parent link="b"/><child link="c"/><origin xyz="0.3 0 0"/></joint>'
        "</robot>"
    )
    _, joints, _ = geometry_from_urdf(path, tip="c")
    assert len(joints) == 1 and joints[0].type == "revolute"
    np.testing.assert_allclose(joints[0].axis, [0.0, 0.6, 0.8], atol=1e-12)


def _pin_tip_pose(path: Path, tip: str, names: list[str], q: np.ndarray) -> np.ndarray:
    """Pinocchio's pose of link ``tip`` of the whole URDF with joints ``names`` at ``q`` (rad)
    and every other joint at its neutral value."""
    pm = pin.buildModelFromUrdf(str(path))
    data = pm.createData()
    qp = pin.neutral(pm)
    for name, value in zip(names, q, strict=True):
        jm = pm.joints[pm.getJointId(name)]
        qp[jm.idx_q : jm.idx_q + jm.nq] = [np.cos(value), np.sin(value)] if jm.nq == 2 else [value]
    pin.framesForwardKinematics(pm, data, qp)
    return data.oMf[pm.getFrameId(tip, pin.FrameType.BODY)].homogeneous


@pytest.mark.skipif(not PANDA_URDF.is_file(), reason="the shared ball-in-socket data is not here")
def test_panda_with_an_off_chain_mimic_finger_builds_to_the_ball():
    """Issue 33 item 5: the finger's <mimic> is off the chain to the ball: ignored.  Without
    --tip the two fingers make two 8-joint chains: refused, naming the candidates."""
    with pytest.raises(URDFError, match="--tip") as info:
        geometry_from_urdf(PANDA_URDF)
    assert "ball_link" in str(info.value) and "panda_leftfinger" in str(info.value)
    model = build_from_urdf(PANDA_URDF, tip="ball_link").model
    names = [f"panda_joint{i}" for i in range(1, 8)]
    assert model.dof == 7 and list(model.joint_names) == names
    q = np.random.default_rng(3).uniform(-2.8, 2.8, (20, 7))
    T = model.fk(q)
    for k in range(len(q)):
        np.testing.assert_allclose(T[k], _pin_tip_pose(PANDA_URDF, "ball_link", names, q[k]), atol=1e-12)
    with pytest.raises(URDFError, match="mimic"):  # the coupled finger on the chain: refused
        geometry_from_urdf(PANDA_URDF, tip="panda_rightfinger")
    _, joints, _ = geometry_from_urdf(PANDA_URDF, tip="panda_leftfinger")
    assert [j.type for j in joints][-1] == "prismatic"
