"""Catalog FK against Pinocchio's own forward kinematics (an independent algorithm)."""

import numpy as np
import pytest

import robocal as rc
from robocal.model.dynamics import TOOL_FRAME, to_pinocchio

pin = pytest.importorskip("pinocchio")


@pytest.mark.parametrize("name", rc.robots())
def test_fk_and_joint_frames_equal_pinocchio(name):
    model = rc.robot(name)
    pm = to_pinocchio(model)
    data = pm.createData()
    assert pm.nq == model.dof
    tool = pm.getFrameId(TOOL_FRAME)
    rng = np.random.default_rng(0)
    lim = np.clip(model.joint_limits, -np.pi, np.pi)
    q = rng.uniform(lim[:, 0], lim[:, 1], (20, model.dof))
    T = model.fk(q)
    frames = model.joint_frames(q)
    for k in range(len(q)):
        pin.framesForwardKinematics(pm, data, q[k])
        np.testing.assert_allclose(data.oMf[tool].homogeneous, T[k], atol=1e-13)
        for j in range(model.dof):
            np.testing.assert_allclose(data.oMi[j + 1].homogeneous, frames[k, j], atol=1e-13)


@pytest.mark.parametrize("name", rc.robots())
def test_joint_jacobian_equals_pinocchio(name):
    model = rc.robot(name)
    pm = to_pinocchio(model)
    data = pm.createData()
    tool = pm.getFrameId(TOOL_FRAME)
    q = np.random.default_rng(1).uniform(-1, 1, (5, model.dof))
    J = model.joint_jacobian(q)
    for k in range(len(q)):
        pin.computeJointJacobians(pm, data, q[k])
        pin.updateFramePlacements(pm, data)
        Jp = pin.getFrameJacobian(pm, data, tool, pin.ReferenceFrame.LOCAL_WORLD_ALIGNED)
        np.testing.assert_allclose(J[k], Jp, atol=1e-12)


def test_bodies_carry_the_catalog_masses():
    model = rc.robot("ur10")
    pm = to_pinocchio(model)
    masses = [pm.inertias[j].mass for j in range(1, pm.njoints)]
    np.testing.assert_allclose(masses, [b.mass for b in model.bodies])
    # the upper arm's centre of mass, seen from joint 2, is its DH-frame com moved
    # through Tz(d2) Tx(a2) Rx(alpha2): x = a2 + 0.38, z = 0.158
    np.testing.assert_allclose(pm.inertias[2].lever, [-0.612 + 0.38, 0.0, 0.158], atol=1e-15)


@pytest.mark.parametrize("name", rc.robots())
def test_direct_entry_points_equal_pinocchio(name):
    """robocal.model.chain_compiled.direct: the frame and the joint Jacobian of one
    configuration, and of many, as Pinocchio computes them."""
    pytest.importorskip("numba")
    from robocal.model.chain_compiled import direct

    model = rc.robot(name)
    d = direct(model)
    pm = to_pinocchio(model)
    data = pm.createData()
    tool = pm.getFrameId(TOOL_FRAME)
    lim = np.clip(model.joint_limits, -np.pi, np.pi)
    q = np.random.default_rng(2).uniform(lim[:, 0], lim[:, 1], (10, model.dof))
    Ts, Js = np.empty((len(q), 4, 4)), np.empty((len(q), 6, model.dof))
    assert d.fk_many(q, d.data, Ts, Js, True)
    for k in range(len(q)):
        Jp = pin.computeFrameJacobian(pm, data, q[k], tool, pin.ReferenceFrame.LOCAL_WORLD_ALIGNED)
        pin.updateFramePlacement(pm, data, tool)
        assert d.fk_jacobian(q[k], d.data)
        for T, J in ((d.T, d.J), (Ts[k], Js[k])):
            np.testing.assert_allclose(T, data.oMf[tool].homogeneous, atol=1e-13)
            np.testing.assert_allclose(J, Jp, atol=1e-12)
