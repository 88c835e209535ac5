"""Batched numerical IK (robocal.measure.ik)."""

import numpy as np
import pytest

import robocal as rc
from robocal.measure.ik import solve_ik
from robocal.measure.ik_starts import random_configurations


@pytest.mark.parametrize("name", ["ur10", "katana450", "puma560", "irb2400", "li2016_3dof"])
def test_position_targets_from_fk_are_reached(name):
    model = rc.robot(name)
    q_true = random_configurations(model, 60, rng=3)
    targets = model.fk(q_true)[:, :3, 3]
    res = solve_ik(model, targets, seed=1)
    assert res.success, res.message
    assert res.position_error.max() < 1e-9
    np.testing.assert_allclose(model.fk(res.q)[:, :3, 3], targets, atol=1e-9)
    lim = model.joint_limits
    assert np.all((res.q >= lim[:, 0]) & (res.q <= lim[:, 1]))


@pytest.mark.parametrize("name", ["ur10", "puma560", "irb2400"])
def test_pose_targets_from_fk_are_reached(name):
    model = rc.robot(name)
    q_true = random_configurations(model, 40, rng=4)
    T = model.fk(q_true)
    res = solve_ik(model, T, seed=2)
    assert res.kind == "pose"
    assert res.success, res.message
    assert res.position_error.max() < 1e-9 and res.angle_error.max() < 1e-9
    err = rc.spatial.pose_error(model.fk(res.q), T)
    assert np.abs(err).max() < 1e-9


def test_axis_targets_for_a_five_axis_arm():
    model = rc.robot("katana450")
    q_true = random_configurations(model, 40, rng=5)
    T = model.fk(q_true)
    res = solve_ik(model, T, kind="axis", seed=3)
    assert res.success, res.message
    T_ik = model.fk(res.q)
    np.testing.assert_allclose(T_ik[:, :3, 3], T[:, :3, 3], atol=1e-9)
    cos = np.einsum("ij,ij->i", T_ik[:, :3, 2], T[:, :3, 2])
    assert np.all(cos > 1 - 1e-12)
    lim = model.joint_limits
    assert np.all((res.q >= lim[:, 0]) & (res.q <= lim[:, 1]))


def test_unreachable_targets_are_reported():
    model = rc.robot("ur10")
    reachable = model.fk(random_configurations(model, 3, rng=0))[:, :3, 3]
    far = np.array([[5.0, 0.0, 0.0], [0.0, 0.0, -4.0]])
    res = solve_ik(model, np.vstack([reachable, far]), restarts=2)
    assert res.reachable.tolist() == [True, True, True, False, False]
    assert res.position_error[3] > 3.0 and res.position_error[4] > 2.0  # the UR10 reaches ~1.4 m
    assert "2 of 5 targets not reached" in res.message


def test_starting_configuration_keeps_the_branch():
    model = rc.robot("ur10")
    q_true = np.radians([[20, -70, 100, -120, -90, 30], [-40, -110, -80, -60, 90, 0]])
    T = model.fk(q_true)
    res = solve_ik(model, T, q0=q_true + 0.05, restarts=0)
    assert res.success
    np.testing.assert_allclose(res.q, q_true, atol=1e-8)
    # the elbow-down twin of the first pose is found from a start near it
    res2 = solve_ik(model, T[:1], q0=np.radians([20, -150, -100, 20, -90, 30]), restarts=0)
    assert res2.success and not np.allclose(res2.q, q_true[:1], atol=1e-3)


def test_joint_limits_are_respected():
    model = rc.robot("katana450")
    q_out = np.radians([[0.0, 130.0, 0.0, 0.0, 0.0]])  # joint 2 beyond its 102 deg limit
    target = model.fk(q_out)
    res = solve_ik(model, target, restarts=4)
    lim = model.joint_limits
    assert np.all((res.q >= lim[:, 0] - 1e-15) & (res.q <= lim[:, 1] + 1e-15))


def test_single_target_and_bad_input():
    model = rc.robot("ur10")
    p = model.fk(np.zeros(6) + 0.3)[:3, 3]
    res = solve_ik(model, p)
    assert res.q.shape == (1, 6) and res.success
    with pytest.raises(ValueError, match=r"\(n, 3\) or frames"):
        solve_ik(model, np.zeros((2, 5)))
    with pytest.raises(ValueError, match="q0 shaped"):
        solve_ik(model, p, q0=np.zeros(5))
    with pytest.raises(ValueError, match="target 1 contains NaN"):
        solve_ik(model, np.array([[0.5, 0, 0], [np.nan, 0, 0]]))
