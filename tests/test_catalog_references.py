"""Catalog robots checked against independent references.

Every reference chain below is plain numpy written from the source's own numbers
(URDF joint origins and axes, published DH tables, simulator joint frames); none of
it goes through robocal's loader or DH builder.  Lengths in the references are in
metres unless the name says ``_MM``.
"""

from __future__ import annotations

import numpy as np
import pytest

import robocal as rc
from tests.reference import dh_matrix as dh_std
from tests.reference import mdh_matrix as dh_mod

PI = np.pi
DEG = PI / 180.0
INCH = 0.0254


# --------------------------------------------------------------------------- helpers
def rot(axis, angle: float) -> np.ndarray:
    """Homogeneous rotation by ``angle`` about a unit ``axis`` (Rodrigues)."""
    k = np.asarray(axis, dtype=float)
    k = k / np.linalg.norm(k)
    K = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    T = np.eye(4)
    T[:3, :3] = np.eye(3) + np.sin(angle) * K + (1.0 - np.cos(angle)) * (K @ K)
    return T


def rx(a: float) -> np.ndarray:
    return rot((1, 0, 0), a)


def ry(a: float) -> np.ndarray:
    return rot((0, 1, 0), a)


def rz(a: float) -> np.ndarray:
    return rot((0, 0, 1), a)


def tr(x: float, y: float, z: float) -> np.ndarray:
    T = np.eye(4)
    T[:3, 3] = (x, y, z)
    return T


def origin(xyz, rpy=(0.0, 0.0, 0.0)) -> np.ndarray:
    """URDF <origin xyz rpy>: translation, then Rz(yaw) Ry(pitch) Rx(roll)."""
    r, p, y = rpy
    return tr(*xyz) @ rz(y) @ ry(p) @ rx(r)


def urdf_fk(joints, tool: np.ndarray, q) -> np.ndarray:
    """Product of URDF revolute joints ``(origin 4x4, axis)`` and a fixed tool frame."""
    T = np.eye(4)
    for (place, axis), qi in zip(joints, q, strict=True):
        T = T @ place @ rot(axis, qi)
    return T @ tool


def random_q(model, n: int, seed: int) -> np.ndarray:
    """``n`` configurations uniformly inside the model's joint limits."""
    lim = np.asarray(model.joint_limits)
    return np.random.default_rng(seed).uniform(lim[:, 0], lim[:, 1], size=(n, model.dof))


def assert_poses(ours: np.ndarray, ref: np.ndarray, pos_tol: float, rot_tol: float = 1e-12) -> None:
    ours, ref = np.asarray(ours), np.asarray(ref)
    np.testing.assert_allclose(ours[..., :3, 3], ref[..., :3, 3], rtol=0, atol=pos_tol)
    np.testing.assert_allclose(ours[..., :3, :3], ref[..., :3, :3], rtol=0, atol=rot_tol)


def assert_limits_deg(model, expected_deg) -> None:
    np.testing.assert_allclose(
        np.asarray(model.joint_limits), np.radians(np.asarray(expected_deg, dtype=float)), rtol=0, atol=1e-12
    )


# ----------------------------------------------------------------- PUMA 560 (RTB)
# Corke's Robotics Toolbox, models/DH/Puma560.py (Corke & Armstrong-Helouvry 1994):
# d1 = 26.45 in, a2 = 0.4318, d3 = 0.15005, a3 = 0.0203, d4 = 0.4318 m,
# alpha = 90, 0, -90, 90, -90, 0 deg, all theta offsets 0.
PUMA_D1 = 26.45 * INCH
PUMA_DH = [  # (d, a, alpha)
    (PUMA_D1, 0.0, 90 * DEG),
    (0.0, 0.4318, 0.0),
    (0.15005, 0.0203, -90 * DEG),
    (0.4318, 0.0, 90 * DEG),
    (0.0, 0.0, -90 * DEG),
    (0.0, 0.0, 0.0),
]
PUMA_LIMITS_DEG = [(-160, 160), (-45, 225), (-225, 45), (-110, 170), (-100, 100), (-266, 266)]
# RTB link data: mass m (kg), r (m, DH link frame), I = [Ixx Iyy Izz Ixy Iyz Ixz] (kg m^2).
PUMA_BODIES_RTB = [
    (0.0, (0, 0, 0), (0, 0.35, 0, 0, 0, 0)),
    (17.4, (-0.3638, 0.006, 0.2275), (0.13, 0.524, 0.539, 0, 0, 0)),
    (4.8, (-0.0203, -0.0141, 0.070), (0.066, 0.086, 0.0125, 0, 0, 0)),
    (0.82, (0, 0.019, 0), (1.8e-3, 1.3e-3, 1.8e-3, 0, 0, 0)),
    (0.34, (0, 0, 0), (0.3e-3, 0.4e-3, 0.3e-3, 0, 0, 0)),
    (0.09, (0, 0, 0.032), (0.15e-3, 0.15e-3, 0.04e-3, 0, 0, 0)),
]


def puma_reference(q) -> np.ndarray:
    T = np.eye(4)
    for (d, a, alpha), qi in zip(PUMA_DH, q, strict=True):
        T = T @ dh_std(qi, d, a, alpha)
    return T


def rtb_to_ours_inertia(I_rtb):
    """RTB [Ixx Iyy Izz Ixy Iyz Ixz] -> robocal [Ixx Iyy Izz Ixy Ixz Iyz]."""
    ixx, iyy, izz, ixy, iyz, ixz = I_rtb
    return (ixx, iyy, izz, ixy, ixz, iyz)


def test_puma560_matches_robotics_toolbox():
    rtb = pytest.importorskip("roboticstoolbox")
    ref = rtb.models.DH.Puma560()
    model = rc.robot("puma560")
    q = np.random.default_rng(560).uniform(-PI, PI, size=(100, 6))
    ours = model.fk(q)
    theirs = np.array([ref.fkine(qi).A for qi in q])
    np.testing.assert_allclose(ours, theirs, rtol=0, atol=1e-12)
    np.testing.assert_allclose(np.asarray(model.joint_limits), np.asarray(ref.qlim).T, rtol=0, atol=1e-12)
    # mass properties, with RTB's inertia order converted
    for body, link, i in zip(model.bodies, ref.links, range(1, 7), strict=True):
        assert body.frame == f"alpha{i}"
        assert body.mass == pytest.approx(link.m, abs=0)
        np.testing.assert_allclose(body.com, np.ravel(link.r), rtol=0, atol=1e-15)
        Ir = np.asarray(link.I)  # 3x3 about the centre of mass
        np.testing.assert_allclose(
            body.inertia, [Ir[0, 0], Ir[1, 1], Ir[2, 2], Ir[0, 1], Ir[0, 2], Ir[1, 2]], rtol=0, atol=1e-15
        )


def test_puma560_against_published_table():
    model = rc.robot("puma560")
    q = np.random.default_rng(1).uniform(-PI, PI, size=(50, 6))
    ref = np.array([puma_reference(qi) for qi in q])
    np.testing.assert_allclose(model.fk(q), ref, rtol=0, atol=1e-12)
    # wrist centre in three named poses, worked out by hand from the table (m):
    #   qz = 0:            (a2 + a3, -d3, d1 + d4)     'L' pose, forearm up
    #   qr = (0, 90, -90): (a3, -d3, d1 + a2 + d4)     upper arm vertical
    #   qs = (0, 0, -90):  (a2 + d4, -d3, d1 - a3)     arm stretched along x
    cases = {
        (0, 0, 0): (0.4521, -0.15005, 1.10363),
        (0, 90, -90): (0.0203, -0.15005, 1.53543),
        (0, 0, -90): (0.8636, -0.15005, 0.65153),
    }
    for q3, p in cases.items():
        qd = np.radians([*q3, 0, 0, 0])[None]
        np.testing.assert_allclose(model.fk(qd)[0, :3, 3], p, rtol=0, atol=1e-12)
    assert_limits_deg(model, PUMA_LIMITS_DEG)
    for body, (m, r, I_rtb) in zip(model.bodies, PUMA_BODIES_RTB, strict=True):
        assert body.mass == m
        np.testing.assert_allclose(body.com, r, rtol=0, atol=1e-15)
        np.testing.assert_allclose(body.inertia, rtb_to_ours_inertia(I_rtb), rtol=0, atol=1e-15)


# --------------------------------------------------------- PUMA 560, Craig's MDH
# Craig, Introduction to Robotics, Table 3.4: alpha_{i-1} = 0, -90, 0, -90, 90, -90;
# a_{i-1} = 0, 0, a2, a3, 0, 0; d_i = 0, 0, d3, d4, 0, 0.  Numbers as in puma560; the
# catalogue adds theta2 = 180 deg so that q is puma560's joint vector.
CRAIG = [  # (alpha_{i-1}, a_{i-1}, theta offset, d_i)
    (0.0, 0.0, 0.0, 0.0),
    (-90 * DEG, 0.0, 180 * DEG, 0.0),
    (0.0, 0.4318, 0.0, 0.15005),
    (-90 * DEG, 0.0203, 0.0, 0.4318),
    (90 * DEG, 0.0, 0.0, 0.0),
    (-90 * DEG, 0.0, 0.0, 0.0),
]


def craig_reference(q) -> np.ndarray:
    T = np.eye(4)
    for (alpha, a, off, d), qi in zip(CRAIG, q, strict=True):
        T = T @ dh_mod(alpha, a, qi + off, d)
    return T


def test_puma560_mdh_against_craig_table():
    model = rc.robot("puma560_mdh")
    q = np.random.default_rng(2).uniform(-PI, PI, size=(50, 6))
    np.testing.assert_allclose(model.fk(q), [craig_reference(qi) for qi in q], rtol=0, atol=1e-12)
    # Craig's base frame is at the shoulder (no d1); frame 6 is the wrist centre.
    # q = 0: wrist centre at (-(a2 + a3), d3, d4) in Craig's base frame (m).
    np.testing.assert_allclose(model.fk(np.zeros((1, 6)))[0, :3, 3], (-0.4521, 0.15005, 0.4318), atol=1e-12)
    assert_limits_deg(model, PUMA_LIMITS_DEG)


def test_puma560_mdh_is_the_same_robot_as_puma560():
    std, mdh = rc.robot("puma560"), rc.robot("puma560_mdh")
    q = np.random.default_rng(3).uniform(-PI, PI, size=(100, 6))
    Ts, Tm = std.fk(q), mdh.fk(q)
    # Find the constant base transform from the data (least squares on the wrist
    # centres), then assert it is Tz(d1) Rz(180 deg) and that it maps every pose.
    P, C = Ts[:, :3, 3], Tm[:, :3, 3]
    pc, cc = P.mean(0), C.mean(0)
    U, _, Vt = np.linalg.svd((C - cc).T @ (P - pc))
    R = Vt.T @ np.diag([1, 1, np.linalg.det(Vt.T @ U.T)]) @ U.T
    B = np.eye(4)
    B[:3, :3], B[:3, 3] = R, pc - R @ cc
    expected_B = tr(0, 0, PUMA_D1) @ rz(PI)
    np.testing.assert_allclose(B, expected_B, rtol=0, atol=1e-12)
    np.testing.assert_allclose(Ts, expected_B @ Tm, rtol=0, atol=1e-12)  # whole pose, same tool frame
    np.testing.assert_allclose(np.asarray(std.joint_limits), np.asarray(mdh.joint_limits), atol=0)


# -------------------------------------------------------------------------- ABB
ABB_TOOL0 = ry(PI / 2)  # ROS-Industrial ABB: tool0 = flange rotated Ry(90 deg)


def abb_urdf(j2_xyz, j3_xyz, j4_xyz, j5_xyz, j6_xyz, flange_xyz=(0, 0, 0)):
    """ROS-Industrial ABB 6-axis layout: axes z, y, y, x, y, x."""
    ax = [(0, 0, 1), (0, 1, 0), (0, 1, 0), (1, 0, 0), (0, 1, 0), (1, 0, 0)]
    xyz = [(0, 0, 0), j2_xyz, j3_xyz, j4_xyz, j5_xyz, j6_xyz]
    return [(origin(o), a) for o, a in zip(xyz, ax, strict=True)], origin(flange_xyz) @ ABB_TOOL0


# ros-industrial/abb, abb_irb120_support/urdf/irb120_3_58_macro.xacro
IRB120_URDF = abb_urdf((0, 0, 0.29), (0, 0, 0.27), (0, 0, 0.07), (0.302, 0, 0), (0.072, 0, 0))
# ros-industrial/abb, abb_irb2400_support/urdf/irb2400_macro.xacro
IRB2400_URDF = abb_urdf((0.1, 0, 0.615), (0, 0, 0.705), (0.258, 0, 0.135), (0.497, 0, 0), (0.085, 0, 0))
# ros-industrial/abb, abb_irb2400_support/urdf/irb2400_12_155_macro.xacro (same robot,
# wrist centre written as one 0.755 step and the flange offset on tool0)
IRB2400_155_URDF = abb_urdf(
    (0.1, 0, 0.615), (0, 0, 0.705), (0, 0, 0.135), (0.755, 0, 0), (0, 0, 0), (0.085, 0, 0)
)

# q = 0 (calibration position: upper arm vertical, forearm horizontal) flange in the
# base frame, from the dimension drawings / URDF numbers (mm):
ABB_ZERO_FLANGE_MM = {
    # IRB 120: x = 302 + 72, z = 290 + 270 + 70
    "irb120": (374.0, 0.0, 630.0),
    # IRB 2400: x = 100 + 755 + 85, z = 615 + 705 + 135
    "irb2400": (940.0, 0.0, 1455.0),
    # IRB 6400R/2.5-150 (robotkinematicscatalogue): x = 240 + 1175 + 200, z = 800 + 1050 + 225
    "irb6400r": (1615.0, 0.0, 2075.0),
    # IRB 2000 (MRcore): x = 850 + 150, z = 780 + 710 + 125
    "irb2000": (1000.0, 0.0, 1615.0),
}
ABB_LIMITS_DEG = {
    # ABB product specifications (see the YAML sources)
    "irb120": [(-165, 165), (-110, 110), (-110, 70), (-160, 160), (-120, 120), (-400, 400)],
    "irb2400": [(-180, 180), (-100, 110), (-60, 65), (-200, 200), (-120, 120), (-400, 400)],
    "irb6400r": [(-180, 180), (-70, 85), (-28, 110), (-300, 300), (-120, 120), (-300, 300)],
    "irb2000": [(-180, 180), (-100, 100), (-60, 60), (-200, 200), (-120, 120), (-200, 200)],
}


@pytest.mark.parametrize("name", sorted(ABB_ZERO_FLANGE_MM))
def test_abb_zero_pose_and_limits(name):
    model = rc.robot(name)
    T0 = model.fk(np.zeros((1, 6)))[0]
    np.testing.assert_allclose(T0[:3, 3] * 1000.0, ABB_ZERO_FLANGE_MM[name], rtol=0, atol=1e-9)
    # ABB tool0 at the calibration position: z along base x (out of the flange),
    # x pointing down, y along base y.
    np.testing.assert_allclose(T0[:3, :3], [[0, 0, 1], [0, 1, 0], [-1, 0, 0]], atol=1e-12)
    assert_limits_deg(model, ABB_LIMITS_DEG[name])


@pytest.mark.parametrize(
    ("name", "urdf"),
    [("irb120", IRB120_URDF), ("irb2400", IRB2400_URDF), ("irb2400", IRB2400_155_URDF)],
)
def test_abb_matches_ros_industrial_urdf(name, urdf):
    model = rc.robot(name)
    joints, tool = urdf
    q = random_q(model, 20, seed=120)
    assert_poses(model.fk(q), [urdf_fk(joints, tool, qi) for qi in q], pos_tol=1e-9)


def test_irb6400r_matches_catalogue_modified_dh():
    # robotkinematicscatalogue 1.1.2, ABB_IRB_6400R_25_150.py, modified DH rows
    # (alpha, a, d, theta offset), mm and rad; joint variables added to theta.
    rows = [
        (0, 0, 800, 0),
        (-PI / 2, 240, 0, -PI / 2),
        (0, 1050, 0, 0),
        (-PI / 2, 225, 1175, 0),
        (PI / 2, 0, 0, 0),
        (-PI / 2, 0, 200, PI),
    ]
    model = rc.robot("irb6400r")
    q = random_q(model, 20, seed=6400)
    ref = []
    for qi in q:
        T = np.eye(4)
        for (alpha, a, d, off), qj in zip(rows, qi, strict=True):
            T = T @ dh_mod(alpha, a / 1000.0, qj + off, d / 1000.0)
        ref.append(T)
    assert_poses(model.fk(q), ref, pos_tol=1e-9)


def test_irb2000_matches_mrcore_simulator():
    # github mhernando/MRCore, src/sim/manipulators/aseairb2000sim.cpp: each joint
    # frame is placed in the previous joint's frame by setRelativePosition /
    # setRelativeOrientation, and turns about its own z; TCP at z = 0.15 m of joint 6.
    places = [
        np.eye(4),
        tr(0, 0, 0.78) @ rx(-PI / 2),
        tr(0, -0.71, 0) @ rz(PI / 2),
        tr(-0.125, 0, 0) @ rx(PI / 2),
        tr(0, 0, 0.85) @ rx(-PI / 2),
        rx(PI / 2),
    ]
    tcp = tr(0, 0, 0.15)
    model = rc.robot("irb2000")
    q = random_q(model, 20, seed=2000)
    ref = [urdf_fk([(P, (0, 0, 1)) for P in places], tcp, qi) for qi in q]
    assert_poses(model.fk(q), ref, pos_tol=1e-9)


# ------------------------------------------------------------------------- KUKA
# ros-industrial/kuka_experimental, kuka_kr16_support/urdf/kr16_2_macro.xacro
KR16_URDF = (
    [
        (origin((0, 0, 0.675)), (0, 0, -1)),
        (origin((0.26, 0, 0)), (0, 1, 0)),
        (origin((0.68, 0, 0)), (0, 1, 0)),
        (origin((0.67, 0, -0.035)), (-1, 0, 0)),
        (origin((0, 0, 0)), (0, 1, 0)),
        (origin((0, 0, 0)), (-1, 0, 0)),
    ],
    origin((0.158, 0, 0), (0, PI / 2, 0)),  # joint_a6-tool0
)


def test_kr16_zero_pose_and_limits():
    model = rc.robot("kr16")
    T0 = model.fk(np.zeros((1, 6)))[0]
    # q = 0 (KUKA zero, arm stretched along x): x = 260 + 680 + 670 + 158,
    # z = 675 - 35 mm (URDF / KR 16-2 dimension drawing).
    np.testing.assert_allclose(T0[:3, 3] * 1000.0, (1768.0, 0.0, 640.0), rtol=0, atol=1e-9)
    np.testing.assert_allclose(T0[:3, :3], [[0, 0, 1], [0, 1, 0], [-1, 0, 0]], atol=1e-12)
    # KR 16-2 ranges: A1 +-185, A2 -155/+35, A3 -130/+154, A4 +-350, A5 +-130, A6 +-350
    assert_limits_deg(model, [(-185, 185), (-155, 35), (-130, 154), (-350, 350), (-130, 130), (-350, 350)])


def test_kr16_matches_ros_industrial_urdf():
    model = rc.robot("kr16")
    q = random_q(model, 20, seed=16)
    joints, tool = KR16_URDF
    assert_poses(model.fk(q), [urdf_fk(joints, tool, qi) for qi in q], pos_tol=1e-9)


# --------------------------------------------------------------------------- UR5
# Universal Robots DH table for the UR5 (CB3), metres.
UR5_DH = [  # (d, a, alpha)
    (0.089159, 0.0, PI / 2),
    (0.0, -0.425, 0.0),
    (0.0, -0.39225, 0.0),
    (0.10915, 0.0, PI / 2),
    (0.09465, 0.0, -PI / 2),
    (0.0823, 0.0, 0.0),
]
# ros-industrial/universal_robot, ur_description/urdf/ur5.urdf.xacro (the file writes
# pi = 3.14159265; the exact value is meant and used here).
UR5_URDF_JOINTS = [
    (origin((0, 0, 0.089159)), (0, 0, 1)),
    (origin((0, 0.13585, 0), (0, PI / 2, 0)), (0, 1, 0)),
    (origin((0, -0.1197, 0.425)), (0, 1, 0)),
    (origin((0, 0, 0.39225), (0, PI / 2, 0)), (0, 1, 0)),
    (origin((0, 0.10915 + 0.1197 - 0.13585, 0)), (0, 0, 1)),  # wrist_1_length = d4 - elbow - shoulder offsets
    (origin((0, 0, 0.09465)), (0, 1, 0)),
]
UR5_URDF_TOOL0 = origin((0, 0.0823, 0), (-PI / 2, 0, 0))
UR5_BASE_LINK_TO_BASE = origin((0, 0, 0), (0, 0, -PI))  # joint base_link-base_fixed_joint


def test_ur5_zero_pose_limits_and_bodies():
    model = rc.robot("ur5")
    T0 = model.fk(np.zeros((1, 6)))[0]
    # q = 0 from the DH table (mm): x = a2 + a3, y = -(d4 + d6), z = d1 - d5
    np.testing.assert_allclose(T0[:3, 3] * 1000.0, (-817.25, -191.45, -5.491), rtol=0, atol=1e-9)
    assert_limits_deg(model, [(-360, 360)] * 6)
    # urcontrol.conf (quoted in ur5.urdf.xacro): masses and DH-frame centres of mass
    masses = [3.7, 8.393, 2.275, 1.219, 1.219, 0.1879]
    coms = [
        (0, -0.02561, 0.00193),
        (0.2125, 0, 0.11336),
        (0.11993, 0, 0.0265),
        (0, -0.0018, 0.01634),
        (0, 0.0018, 0.01634),
        (0, 0, -0.001159),
    ]
    assert [b.mass for b in model.bodies] == masses
    assert [b.frame for b in model.bodies] == [f"alpha{i}" for i in range(1, 7)]
    np.testing.assert_allclose([b.com for b in model.bodies], coms, rtol=0, atol=1e-15)


def test_ur5_against_dh_table_and_urdf():
    model = rc.robot("ur5")
    q = random_q(model, 20, seed=5)
    ours = model.fk(q)
    table = []
    for qi in q:
        T = np.eye(4)
        for (d, a, alpha), qj in zip(UR5_DH, qi, strict=True):
            T = T @ dh_std(qj, d, a, alpha)
        table.append(T)
    np.testing.assert_allclose(ours, table, rtol=0, atol=1e-12)
    # URDF: UR 'Base' frame = base_link rotated by -pi about z; tool0 = UR all-zero TCP
    base_inv = np.linalg.inv(UR5_BASE_LINK_TO_BASE)
    ref = [base_inv @ urdf_fk(UR5_URDF_JOINTS, UR5_URDF_TOOL0, qi) for qi in q]
    assert_poses(ours, ref, pos_tol=1e-9)


# ------------------------------------------------------------------ all new files
NEW = ["irb120", "irb2000", "irb2400", "irb6400r", "kr16", "puma560", "puma560_mdh", "ur5"]


@pytest.mark.parametrize("name", NEW)
def test_catalog_entry_is_documented(name):
    assert name in rc.robots()
    model = rc.robot(name)
    assert model.name == name
    assert model.dof == 6
    assert model.source and model.title
    assert np.asarray(model.joint_limits).shape == (6, 2)
