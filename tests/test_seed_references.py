"""Catalog FK against the seeds' own matrices and independent DH implementations."""

import numpy as np
import pytest

import robocal as rc
from tests.reference import Rx, Ry, Rz, Tr, dh_fk

D = np.pi / 180


def seed001_0A4(t1: float, t2: float, t3: float) -> np.ndarray:
    """Seed 001 appendix: 0A4 = 0A1 1A2 2A3 3A4, typed in entry by entry (m)."""
    c1, s1 = np.cos(t1), np.sin(t1)
    c2, s2 = np.cos(np.pi / 2 + t2), np.sin(np.pi / 2 + t2)
    c3, s3 = np.cos(t3), np.sin(t3)
    A1 = np.array([[c1, 0, s1, 0], [s1, 0, -c1, 0], [0, 1, 0, 0.076], [0, 0, 0, 1]])
    A2 = np.array([[c2, -s2, 0, 0.4 * c2], [s2, c2, 0, 0.4 * s2], [0, 0, 1, 0], [0, 0, 0, 1]])
    A3 = np.array([[c3, 0, s3, 0], [s3, 0, -c3, 0], [0, 1, 0, -0.012], [0, 0, 0, 1]])
    A4 = np.array([[1, 0, 0, 0], [0, 0, -1, 0], [0, 1, 0, 0.3543], [0, 0, 0, 1]])
    return A1 @ A2 @ A3 @ A4


@pytest.mark.parametrize("q_deg", [(0, 0, 0), (30, -20, 45), (-90, 60, -30), (145, 10, 100), (12.5, -77, 3)])
def test_seed001_arm_equals_its_appendix_matrices(q_deg):
    q = np.array(q_deg) * D
    T = rc.robot("li2016_3dof").fk(q)
    np.testing.assert_allclose(T, seed001_0A4(*q), atol=1e-15)


def test_seed001_arm_position_at_zero():
    # by hand from 0A4 at zero: x = 0.3543, y = 0.012, z = 0.076 + 0.4
    np.testing.assert_allclose(
        rc.robot("li2016_3dof").fk(np.zeros(3))[:3, 3], [0.3543, 0.012, 0.476], atol=1e-15
    )


def katana_thesis(q: np.ndarray) -> np.ndarray:
    """Seed 003 eqs. 4.2-4.7 at nominal values (mm), base offset [55 55 201.5] mm."""
    t1, t2, t3, t4, t5 = q
    T03 = Rz(t1) @ Rx(90 * D) @ Rz(t2) @ Tr(x=190)
    T34 = Rx(0) @ Ry(0) @ Rz(t3) @ Tr(x=139)
    T45 = Rz(t4) @ Ry(0) @ Rx(-90 * D) @ Tr(z=147.3)
    T56 = Rz(t5) @ Ry(0) @ Rx(90 * D) @ Tr(z=200)
    T = Tr(55, 55, 201.5) @ T03 @ T34 @ T45 @ T56
    T[:3, 3] /= 1000.0
    return T


def test_katana_zero_pose():
    T = rc.robot("katana450").fk(np.zeros(5))
    # by hand: x = 55 + 190 + 139, y = 55 - 200 (end link along -y), z = 201.5 + 147.3
    np.testing.assert_allclose(T[:3, 3], [0.384, -0.145, 0.3488], atol=1e-15)
    np.testing.assert_allclose(T[:3, :3], Rx(90 * D)[:3, :3], atol=1e-15)


def test_katana_equals_thesis_equations():
    model = rc.robot("katana450")
    q = np.random.default_rng(7).uniform(model.joint_limits[:, 0], model.joint_limits[:, 1], (50, 5))
    for qk, T in zip(q, model.fk(q), strict=True):
        np.testing.assert_allclose(T, katana_thesis(qk), atol=1e-15)
    assert model.dof == 5
    np.testing.assert_allclose(np.degrees(model.joint_limits[1]), [-30, 102])


UR10_DH = np.array(
    [  # theta offset, d, a, alpha (m, rad): Universal Robots CB3 table
        [0, 0.1273, 0, np.pi / 2],
        [0, 0, -0.612, 0],
        [0, 0, -0.5723, 0],
        [0, 0.163941, 0, np.pi / 2],
        [0, 0.1157, 0, -np.pi / 2],
        [0, 0.0922, 0, 0],
    ]
)


def test_ur10_matches_independent_dh_at_1000_configurations():
    model = rc.robot("ur10")
    q = np.random.default_rng(10).uniform(-2 * np.pi, 2 * np.pi, (1000, 6))
    T = model.fk(q)
    expected = np.stack([dh_fk(UR10_DH, qk) for qk in q])
    assert np.abs(T[:, :3, 3] - expected[:, :3, 3]).max() < 1e-12  # m
    assert np.abs(T[:, :3, :3] - expected[:, :3, :3]).max() < 1e-12


def test_ur10_joint_frames_match_partial_dh_products():
    model = rc.robot("ur10")
    q = np.random.default_rng(11).uniform(-3, 3, (20, 6))
    frames = model.joint_frames(q)
    for k in range(len(q)):
        T = np.eye(4)
        for j in range(6):
            # the joint frame is after Rz(θ_j + q_j), before Tz(d) Tx(a) Rx(α)
            np.testing.assert_allclose(frames[k, j], T @ Rz(q[k, j]), atol=1e-13)
            theta, d, a, alpha = UR10_DH[j]
            T = T @ Rz(theta + q[k, j]) @ Tr(z=d) @ Tr(x=a) @ Rx(alpha)
