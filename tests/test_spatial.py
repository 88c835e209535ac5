import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from robocal import spatial
from tests.reference import ELEMENTARY, Rx, Ry, Rz, rotvec_of

angles = st.floats(-np.pi, np.pi, allow_nan=False)
finite = st.floats(-10, 10, allow_nan=False)
rotvecs = arrays(float, 3, elements=st.floats(-3.0, 3.0)).filter(lambda v: np.linalg.norm(v) < 3.1)


@pytest.mark.parametrize("motion", spatial.MOTIONS)
def test_elementary_matches_textbook_matrices(motion):
    values = np.linspace(-2.5, 2.5, 7)
    T = spatial.elementary(motion, values)
    assert T.shape == (7, 4, 4)
    for v, Tk in zip(values, T, strict=True):
        np.testing.assert_allclose(Tk, ELEMENTARY[motion](v), atol=1e-15)


def test_elementary_rejects_unknown_motion():
    with pytest.raises(ValueError, match="unknown elementary motion 'Qz'"):
        spatial.elementary("Qz", 1.0)


def test_rot_batched_shapes():
    a = np.zeros((2, 5))
    assert spatial.rotx(a).shape == (2, 5, 3, 3)
    np.testing.assert_allclose(spatial.roty(0.3), Ry(0.3)[:3, :3])
    np.testing.assert_allclose(spatial.rotz(-1.1), Rz(-1.1)[:3, :3])


@settings(max_examples=60, deadline=None)
@given(rotvecs, arrays(float, 3, elements=finite))
def test_inverse_composes_to_identity(rv, p):
    T = spatial.homogeneous(spatial.rotvec_to_matrix(rv), p)
    np.testing.assert_allclose(spatial.compose(T, spatial.inverse(T)), np.eye(4), atol=1e-12)
    np.testing.assert_allclose(spatial.inverse(T), np.linalg.inv(T), atol=1e-10)


@settings(max_examples=60, deadline=None)
@given(rotvecs)
def test_rotvec_and_quaternion_round_trips(rv):
    R = spatial.rotvec_to_matrix(rv)
    np.testing.assert_allclose(spatial.matrix_to_rotvec(R), rv, atol=1e-9)
    np.testing.assert_allclose(rotvec_of(R), rv, atol=1e-7)
    qt = spatial.matrix_to_quaternion(R)
    assert qt[0] >= 0
    np.testing.assert_allclose(np.linalg.norm(qt), 1.0)
    np.testing.assert_allclose(spatial.quaternion_to_matrix(qt), R, atol=1e-12)


def test_quaternion_is_scalar_first():
    q = spatial.matrix_to_quaternion(Rz(np.pi / 2)[:3, :3])
    np.testing.assert_allclose(q, [np.cos(np.pi / 4), 0, 0, np.sin(np.pi / 4)], atol=1e-15)


@settings(max_examples=40, deadline=None)
@given(angles, st.floats(0.05, np.pi - 0.05), angles)
def test_zxz_euler_is_intrinsic_z_x_z(phi, theta, psi):
    """Seed 003 describes orientation by ZXZ Euler angles Phi, theta, Psi."""
    R = (Rz(phi) @ Rx(theta) @ Rz(psi))[:3, :3]
    np.testing.assert_allclose(spatial.euler_to_matrix([phi, theta, psi], "ZXZ"), R, atol=1e-12)
    back = spatial.matrix_to_euler(R, "ZXZ")
    np.testing.assert_allclose(spatial.euler_to_matrix(back, "ZXZ"), R, atol=1e-12)


@settings(max_examples=40, deadline=None)
@given(angles, st.floats(-1.5, 1.5), angles)
def test_extrinsic_xyz_is_seed000_eq1(alpha, beta, gamma):
    """Seed 000 eq. (1): R = Rz(γ) Ry(β) Rx(α)."""
    R = (Rz(gamma) @ Ry(beta) @ Rx(alpha))[:3, :3]
    np.testing.assert_allclose(spatial.euler_to_matrix([alpha, beta, gamma], "xyz"), R, atol=1e-12)
    back = spatial.matrix_to_euler(R, "xyz")
    wrapped = np.angle(np.exp(1j * (back - [alpha, beta, gamma])))  # equal modulo 2π
    np.testing.assert_allclose(wrapped, 0.0, atol=1e-9)
    # intrinsic XYZ is the other order: Rx Ry Rz
    R2 = (Rx(alpha) @ Ry(beta) @ Rz(gamma))[:3, :3]
    np.testing.assert_allclose(spatial.euler_to_matrix([alpha, beta, gamma], "XYZ"), R2, atol=1e-12)


def test_pose_error_position_and_small_angle():
    rng = np.random.default_rng(1)
    T_ref = spatial.homogeneous(spatial.rotvec_to_matrix(rng.normal(size=(4, 3))), rng.normal(size=(4, 3)))
    w = rng.normal(scale=1e-4, size=(4, 3))
    dp = rng.normal(scale=1e-3, size=(4, 3))
    T_act = T_ref.copy()
    T_act[:, :3, :3] = spatial.rotvec_to_matrix(w) @ T_ref[:, :3, :3]
    T_act[:, :3, 3] += dp
    err = spatial.pose_error(T_act, T_ref)
    assert err.shape == (4, 6)
    np.testing.assert_allclose(err[:, :3], dp, atol=1e-15)
    np.testing.assert_allclose(err[:, 3:], w, atol=1e-14)


def test_transl_and_homogeneous_broadcast():
    T = spatial.transl([1, 2], 0, 3)
    assert T.shape == (2, 4, 4)
    np.testing.assert_array_equal(T[1, :3, 3], [2, 0, 3])
    np.testing.assert_array_equal(spatial.homogeneous(), np.eye(4))
    np.testing.assert_allclose(spatial.skew([1, 2, 3]) @ [4, 5, 6], np.cross([1, 2, 3], [4, 5, 6]))


@pytest.mark.filterwarnings("ignore:Gimbal lock detected")  # scipy's, at exactly ±90°
@pytest.mark.parametrize("ry", [0.3, -1.2, np.pi / 2, -np.pi / 2, np.pi / 2 - 1e-6, np.pi / 2 - 2e-3])
@pytest.mark.parametrize(("rz", "rx"), [(0.4, -2.5), (-3.0, 0.0), (0.0, 1.0)])
def test_zyx_angles_rebuild_the_rotation(rz, ry, rx):
    R = spatial.euler_to_matrix([rz, ry, rx], "ZYX")
    angles = spatial.zyx_angles(R)
    assert np.allclose(spatial.euler_to_matrix(np.array(angles), "ZYX"), R, atol=1e-9)
    if abs(abs(ry) - np.pi / 2) > 1e-2:  # away from gimbal lock the angles themselves come back
        assert np.allclose(angles, [rz, ry, rx], atol=1e-12)


def test_chain_product_is_the_product_of_elementaries():
    motions = ["Tx", "Rz", "Ty", "Rx", "Tz", "Ry", "Rz"]
    values = np.random.default_rng(3).normal(size=len(motions))
    expected = spatial.compose(*[spatial.elementary(m, v) for m, v in zip(motions, values, strict=True)])
    assert np.allclose(spatial.chain_product(motions, values), expected, atol=1e-15)
    assert np.array_equal(spatial.chain_product([], []), np.eye(4))
    with pytest.raises(ValueError, match="motion 'Qx'"):
        spatial.chain_product(["Qx"], [1.0])


@pytest.mark.parametrize("angle", [0.0, 1e-10, 1e-4, 0.3, 2.0, 3.0, np.pi - 1e-3, np.pi - 1e-8, np.pi])
def test_matrix_to_rotvec_matches_scipy_from_zero_to_pi(angle):
    """The closed form (and its fallback beyond ~172°) against scipy's quaternion route."""
    from scipy.spatial.transform import Rotation

    axes = np.random.default_rng(7).normal(size=(50, 3))
    axes /= np.linalg.norm(axes, axis=1, keepdims=True)
    R = Rotation.from_rotvec(axes * angle).as_matrix()
    ours, ref = spatial.matrix_to_rotvec(R), Rotation.from_matrix(R).as_rotvec()
    same = np.abs(ours - ref).max(axis=1)
    flipped = np.abs(ours + ref).max(axis=1)  # at exactly π, v and -v are the same rotation
    assert np.all(np.minimum(same, flipped if angle == np.pi else same) < 1e-12)
    assert spatial.matrix_to_rotvec(R[0]).shape == (3,)
    with pytest.raises(ValueError, match=r"\(\.\.\., 3, 3\)"):
        spatial.matrix_to_rotvec(np.eye(4))
