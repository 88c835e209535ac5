"""Joint wrenches (robocal.model.dynamics) against hand-computed cases and an
independent implementation of seed 003's static recursion, eq. 4.21."""

import dataclasses

import numpy as np
import pytest

import robocal as rc
from robocal.model.chain import Model
from robocal.model.dynamics import Payload, gravity_torques, joint_moments, joint_wrenches, to_pinocchio
from robocal.model.steps import Body, Joint, Step

pin = pytest.importorskip("pinocchio")
G = 9.81


def one_link(mass=2.0, com=(0.3, 0.0, 0.0), axis="Rz"):
    steps = (Step(axis, "theta1", 0.0, joint=Joint("q1")), Step("Tx", "a1", 0.5))
    return Model("one", steps, bodies=(Body("link1", "theta1", mass, com),))


def test_single_link_static_hand_cases():
    m = one_link()
    # gravity in the joint's plane: the joint torque holds m g l
    W = joint_wrenches(m, [0.0], gravity=[0, -G, 0])[0]
    np.testing.assert_allclose(W, [0, 2 * G, 0, 0, 0, 2 * G * 0.3], atol=1e-12)
    # horizontal arm on a vertical axis: the bearings carry m g l about y, no torque
    W = joint_wrenches(m, [0.0], gravity=[0, 0, -G])[0]
    np.testing.assert_allclose(W, [0, 0, 2 * G, 0, -2 * G * 0.3, 0], atol=1e-12)
    # turned by 90°: the same wrench in the joint frame (it turns with the link)
    np.testing.assert_allclose(joint_wrenches(m, [np.pi / 2], gravity=[0, 0, -G])[0], W, atol=1e-12)
    # a payload at the link's end adds its weight at 0.5 m
    W = joint_wrenches(m, [0.0], gravity=[0, 0, -G], payload=Payload(1.0))[0]
    np.testing.assert_allclose(W[3:], [0, -(2 * 0.3 + 1 * 0.5) * G, 0], atol=1e-12)
    # ... and a payload centre off the tool frame's origin
    W = joint_wrenches(m, [0.0], gravity=[0, 0, -G], payload=Payload(1.0, (0.1, 0.0, 0.0)))[0]
    np.testing.assert_allclose(W[4], -(2 * 0.3 + 1 * 0.6) * G, atol=1e-12)


def test_single_link_dynamic_hand_case():
    """A point mass at (r, 0, h) turning about a vertical axis, no gravity: the joint
    applies F = m a = m (−ω² r, r α, 0) at the mass, moment (r, 0, h) × F."""
    m, r, h, w, a = 1.5, 0.4, 0.2, 3.0, 2.0
    model = one_link(mass=m, com=(r, 0.0, h))
    W = joint_wrenches(model, [0.3], [w], [a], gravity=[0, 0, 0])[0]  # one pose, joint 1
    F = m * np.array([-(w**2) * r, r * a, 0.0])
    np.testing.assert_allclose(W[:3], F, atol=1e-12)
    np.testing.assert_allclose(W[3:], np.cross([r, 0.0, h], F), atol=1e-12)
    np.testing.assert_allclose(W[4], -m * w**2 * r * h)  # the bearings carry the swing
    np.testing.assert_allclose(W[5], m * r**2 * a)  # the torque: I α of a point mass


def test_horizontal_two_link_arm():
    """Two links along x on parallel y axes under gravity −z (a horizontal arm)."""
    L1, c1, c2, m1, m2 = 0.6, 0.3, 0.25, 4.0, 2.0
    steps = (
        Step("Ry", "theta1", 0.0, joint=Joint("q1")),
        Step("Tx", "a1", L1),
        Step("Ry", "theta2", 0.0, joint=Joint("q2")),
        Step("Tx", "a2", 0.5),
    )
    bodies = (Body("link1", "theta1", m1, (c1, 0, 0)), Body("link2", "theta2", m2, (c2, 0, 0)))
    arm = Model("arm", steps, bodies=bodies)
    W = joint_wrenches(arm, [0.0, 0.0])
    # holding torques about y: a positive rotation about y lowers the arm, so the joints
    # hold it with negative torques
    np.testing.assert_allclose(W[:, 4], [-G * (m1 * c1 + m2 * (L1 + c2)), -G * m2 * c2], atol=1e-12)
    np.testing.assert_allclose(W[:, 2], [G * (m1 + m2), G * m2], atol=1e-12)
    np.testing.assert_allclose(W[:, [0, 1, 3, 5]], 0, atol=1e-12)
    np.testing.assert_allclose(W[:, 4], gravity_torques(arm, [[0.0, 0.0]])[0], atol=1e-12)


def _prefix_frame(model, q, step_index):
    """Frame after step ``step_index`` (base frame), from a prefix of the chain."""
    steps = model.steps[: step_index + 1]
    sub = Model("prefix", steps)
    return sub.fk(q[:, : sub.dof])


def thesis_static_moments(model, q, gravity, payload=None):
    """Seed 003 eq. 4.21, written independently of Pinocchio:

        [F_i]_i = R_i^{i+1} [F_{i+1}]_{i+1} + m_i R_0^iᵀ g
        [η_i]_i = R_i^{i+1} [η_{i+1}]_{i+1} + [r_i]_i × R_i^{i+1} [F_{i+1}]_{i+1} + [s_i]_i × m_i R_0^iᵀ g

    from the tool back to the base; frame i is the joint frame (after joint i's step),
    link i carries the bodies moved by joint i (and the payload for the last link);
    F and η are the load (force and moment) the links beyond joint i put on it.
    Returns η (n, dof, 3) and F (n, dof, 3) in the joint frames.
    """
    n, dof = q.shape
    frames = model.joint_frames(q)
    joint_step = [i for i, s in enumerate(model.steps) if s.joint is not None]
    index = {s.name: i for i, s in enumerate(model.steps)}
    masses = [[] for _ in range(dof)]  # (mass, centre in base) per link
    for b in model.bodies:
        i = index[b.frame]
        link = max(k for k, js in enumerate(joint_step) if js <= i) if i >= joint_step[0] else None
        if link is None:
            continue
        T = _prefix_frame(model, q, i)
        masses[link].append((b.mass, T[:, :3, :3] @ np.array(b.com) + T[:, :3, 3]))
    if payload is not None:
        T = model.fk(q)
        masses[-1].append((payload.mass, T[:, :3, :3] @ np.array(payload.com) + T[:, :3, 3]))
    g = np.asarray(gravity, dtype=float)
    eta = np.zeros((n, dof, 3))
    force = np.zeros((n, dof, 3))
    for k in range(n):
        F_next = np.zeros(3)
        eta_next = np.zeros(3)
        for i in range(dof - 1, -1, -1):
            R_i, o_i = frames[k, i, :3, :3], frames[k, i, :3, 3]
            m_i = sum(m for m, _ in masses[i])
            s_i = np.zeros(3)
            if m_i > 0:
                c = sum(m * c[k] for m, c in masses[i]) / m_i
                s_i = R_i.T @ (c - o_i)
            g_i = R_i.T @ g
            if i < dof - 1:
                R_next = frames[k, i + 1, :3, :3]
                R_rel = R_i.T @ R_next  # R_i^{i+1}
                r_i = R_i.T @ (frames[k, i + 1, :3, 3] - o_i)
                F_rel, eta_rel = R_rel @ F_next, R_rel @ eta_next
            else:
                r_i, F_rel, eta_rel = np.zeros(3), np.zeros(3), np.zeros(3)
            F_i = F_rel + m_i * g_i
            eta_i = eta_rel + np.cross(r_i, F_rel) + np.cross(s_i, m_i * g_i)
            eta[k, i], force[k, i] = eta_i, F_i
            F_next, eta_next = F_i, eta_i
    return eta, force


@pytest.mark.parametrize("name", ["katana450", "ur10", "puma560"])
def test_wrenches_equal_the_thesis_static_recursion(name):
    model = rc.robot(name)
    rng = np.random.default_rng(3)
    lim = np.clip(model.joint_limits, -np.pi, np.pi)
    q = rng.uniform(lim[:, 0], lim[:, 1], (6, model.dof))
    for gravity, payload in (
        ([0, 0, -9.81], None),
        ([3.0, -2.0, -8.0], Payload(0.5, (0.01, -0.02, 0.05))),  # a tilted base, a payload
    ):
        eta, force = thesis_static_moments(model, q, gravity, payload)
        W = joint_wrenches(model, q, gravity=gravity, payload=payload)
        # Pinocchio's support wrench is the negative of the load (eq. 4.21's η)
        np.testing.assert_allclose(W[..., 3:], -eta, atol=1e-10)
        np.testing.assert_allclose(W[..., :3], -force, atol=1e-10)
        moments = joint_moments(model, q, gravity=gravity, payload=payload)
        np.testing.assert_allclose(moments, -eta, atol=1e-10)


def test_dynamic_wrenches_agree_with_pinocchio_rnea_torques():
    model = rc.robot("katana450")
    rng = np.random.default_rng(5)
    q, qd, qdd = rng.uniform(-1, 1, (3, 4, model.dof))
    W = joint_wrenches(model, q, qd, qdd)
    pm = to_pinocchio(model)
    data = pm.createData()
    for k in range(len(q)):
        tau = pin.rnea(pm, data, q[k], qd[k], qdd[k])
        np.testing.assert_allclose(W[k, :, 5], tau, atol=1e-12)  # every Katana joint turns about z
    # motion changes the bearing moments too, not only the torques
    static = joint_wrenches(model, q)
    assert np.abs(W[..., 3:5] - static[..., 3:5]).max() > 1e-3
    # one pose as a 1-D q gives (dof, 6)
    assert joint_wrenches(model, q[0]).shape == (model.dof, 6)


def test_wrench_input_errors():
    with pytest.raises(ValueError, match="no mass properties"):
        joint_wrenches(rc.robot("irb2400"), np.zeros(6))
    model = rc.robot("katana450")
    with pytest.raises(ValueError, match="velocities shaped"):
        joint_wrenches(model, np.zeros((2, 5)), np.zeros((3, 5)))
    with pytest.raises(ValueError, match="payload mass"):
        Payload(-1.0)
    # a payload alone is enough mass
    bare = dataclasses.replace(rc.robot("katana450"), bodies=())
    W = joint_wrenches(bare, np.zeros(5), payload=Payload(1.0))
    assert np.abs(W).max() > 0


@pytest.mark.parametrize("name", ["katana450", "ur10", "puma560"])
@pytest.mark.parametrize("compiled", [True, False], ids=["compiled", "numpy"])
def test_static_pass_equals_pinocchio_rnea(name, compiled, monkeypatch):
    """The static wrenches in one pass (compiled kernel, and the numpy code) and the gravity
    torques against Pinocchio's RNEA and generalized gravity, pose by pose, with a tilted
    gravity and a payload off the tool axis."""
    from robocal.model import chain
    from robocal.model.dynamics import _rnea_wrenches, _static_wrenches

    if not compiled:
        monkeypatch.setattr(chain, "kernels_loader", lambda compiled=None: None)

    model = rc.robot(name)
    rng = np.random.default_rng(11)
    lim = np.clip(model.joint_limits, -np.pi, np.pi)
    q = rng.uniform(lim[:, 0], lim[:, 1], (20, model.dof))
    zero = np.zeros_like(q)
    for gravity, payload in (
        (None, None),
        ([1.5, -2.0, -9.0], Payload(2.5, (0.03, -0.01, 0.12), (0.01, 0.02, 0.03, 0.0, 0.0, 0.0))),
    ):
        reference = _rnea_wrenches(model, q, zero, zero, gravity, payload)
        np.testing.assert_allclose(_static_wrenches(model, q, gravity, payload), reference, rtol=0, atol=1e-9)
        np.testing.assert_allclose(
            joint_wrenches(model, q, zero, zero, gravity=gravity, payload=payload),
            reference,
            rtol=0,
            atol=1e-9,
        )
    pm = to_pinocchio(model)
    data = pm.createData()
    tau = np.array([pin.computeGeneralizedGravity(pm, data, qk) for qk in q])
    np.testing.assert_allclose(gravity_torques(model, q), tau, rtol=0, atol=1e-9)
