"""Measuring devices (frames, layouts, noise models, range checks) and the rigid-fit helper."""

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from robocal import spatial
from robocal.measure.device_base import look_at
from robocal.measure.devices import (
    DEVICES,
    Camera,
    LaserTracker,
    OpticalCMM,
    device_from_dict,
    make_device,
    marker_triangle,
)
from robocal.measure.plates import CalibrationPlate, PenOnPaper, plate_points


def random_transforms(n, rng, scale=1.0):
    return spatial.homogeneous(
        spatial.rotvec_to_matrix(rng.normal(size=(n, 3))), scale * rng.normal(size=(n, 3))
    )


# ------------------------------------------------------------ fit_rigid_transform
def test_fit_rigid_transform_recovers_batched_transforms():
    rng = np.random.default_rng(0)
    P = rng.normal(size=(6, 3))
    T = random_transforms(50, rng)
    Q = np.einsum("nij,kj->nki", T[:, :3, :3], P) + T[:, None, :3, 3]
    np.testing.assert_allclose(spatial.fit_rigid_transform(P, Q), T, atol=1e-12)  # layout broadcasts
    np.testing.assert_allclose(spatial.fit_rigid_transform(np.broadcast_to(P, Q.shape), Q), T, atol=1e-12)


def test_fit_rigid_transform_matches_scipy_on_noisy_points():
    rng = np.random.default_rng(1)
    P = rng.normal(size=(8, 3))
    T = random_transforms(1, rng)[0]
    Q = P @ T[:3, :3].T + T[:3, 3] + 0.05 * rng.normal(size=P.shape)
    F = spatial.fit_rigid_transform(P, Q)
    R_ref, _ = Rotation.align_vectors(Q - Q.mean(axis=0), P - P.mean(axis=0))
    np.testing.assert_allclose(F[:3, :3], R_ref.as_matrix(), atol=1e-10)
    np.testing.assert_allclose(F[:3, 3], Q.mean(axis=0) - F[:3, :3] @ P.mean(axis=0), atol=1e-12)


def test_fit_rigid_transform_three_points_never_reflects_and_weights_work():
    P = marker_triangle(0.05)
    mirrored = P * [1.0, 1.0, -1.0]  # coplanar points: a mirror image is a rotation too
    F = spatial.fit_rigid_transform(P, mirrored)
    assert np.linalg.det(F[:3, :3]) == pytest.approx(1.0)
    Q = P + [0.0, 0.0, 0.1]
    Q[0] += [5.0, 0.0, 0.0]  # an outlier with zero weight is ignored
    F = spatial.fit_rigid_transform(
        np.vstack([P, [[0, 0, 1.0]]]), np.vstack([Q, [[0, 0, 1.1]]]), [0, 1, 1, 1]
    )
    np.testing.assert_allclose(F[:3, 3], [0, 0, 0.1], atol=1e-12)


def test_fit_rigid_transform_rejects_degenerate_input():
    line = np.array([[0.0, 0, 0], [1, 0, 0], [2, 0, 0]])
    with pytest.raises(ValueError, match="collinear"):
        spatial.fit_rigid_transform(line, line + 1)
    with pytest.raises(ValueError, match="at least 3 points"):
        spatial.fit_rigid_transform(line[:2], line[:2])
    with pytest.raises(ValueError, match=r"\(\.\.\., m, 3\)"):
        spatial.fit_rigid_transform(line, line[:, :2])


# ------------------------------------------------------------ frames
def test_device_frame_is_applied_as_hand_computed():
    # base -> device: p_dev = Rz(90°) p_base + (2, 1, 0.5)
    T_device_base = spatial.homogeneous(spatial.rotz(math.pi / 2), [2.0, 1.0, 0.5])
    dev = LaserTracker(T_device_base=T_device_base, p_tool_target=[0.0, 0.0, 0.1], sigma=0.0)
    T_base_tool = spatial.homogeneous(spatial.rotx(math.pi), [0.1, 0.2, 0.3])  # tool z points down
    # target in base: (0.1, 0.2, 0.3) + 0.1 * (0, 0, -1) = (0.1, 0.2, 0.2); Rz(90°): (x, y, z) -> (-y, x, z)
    expected = np.array([-0.2 + 2.0, 0.1 + 1.0, 0.2 + 0.5])
    np.testing.assert_allclose(dev.predict(T_base_tool[None]).position[0], expected, atol=1e-15)
    np.testing.assert_allclose(dev.observe(T_base_tool[None], 0).position[0], expected, atol=1e-15)
    np.testing.assert_allclose(dev.T_base_device @ T_device_base, np.eye(4), atol=1e-15)


def test_pose_devices_report_the_target_frame():
    rng = np.random.default_rng(2)
    T = random_transforms(5, rng, 0.3)
    cmm = OpticalCMM(sigma=0.0, p_tool_target=[0.01, 0.02, 0.2], working_range=None)
    obs = cmm.observe(T, rng)
    F = cmm.T_device_base @ T @ spatial.transl(0.01, 0.02, 0.2)
    np.testing.assert_allclose(obs.position, F[:, :3, 3], atol=1e-12)
    np.testing.assert_allclose(obs.orientation, F[:, :3, :3], atol=1e-12)
    assert cmm.columns == ("x", "y", "z", "qw", "qx", "qy", "qz") and cmm.measures == "pose"
    assert LaserTracker().columns == ("x", "y", "z")


def test_look_at_points_z_at_the_target():
    T = look_at([2.0, 0.0, 1.0], [0.0, 0.0, 1.0])
    np.testing.assert_allclose(T[:3, 2], [-1, 0, 0], atol=1e-15)
    np.testing.assert_allclose(T[:3, :3] @ T[:3, :3].T, np.eye(3), atol=1e-15)
    assert np.linalg.det(T[:3, :3]) == pytest.approx(1.0)


# ------------------------------------------------------------ laser tracker
def test_laser_tracker_distance_dependent_sigma_and_line_of_sight():
    dev = LaserTracker(T_device_base=np.eye(4), sigma=15e-6, sigma_per_m=6e-6)
    T = spatial.transl([1.0, 5.0], 0.0, 0.0)  # targets 1 m and 5 m away on +x, tool z up
    obs = dev.observe(T, 0)
    np.testing.assert_allclose(obs.sigma[:, 0], [21e-6, 45e-6])
    looking = LaserTracker(T_device_base=np.eye(4), acceptance_angle=math.radians(45))
    facing = spatial.homogeneous(spatial.roty(-math.pi / 2), [2.0, 0, 0])  # tool z towards the tracker
    looking.observe(facing[None], 0)
    away = spatial.homogeneous(spatial.roty(-math.pi / 2 + math.radians(50)), [2.0, 0, 0])
    with pytest.raises(ValueError, match=r"turns 50\.0 deg away from the line of sight.*pose\(s\) 0"):
        looking.observe(away[None], 0)


# ------------------------------------------------------------ optical CMM and camera
def test_optical_cmm_defaults_follow_seed_003():
    cmm = OpticalCMM()
    assert cmm.sigma == 0.01e-3 and cmm.working_range == (2.0, 7.0) and len(cmm.markers) == 3
    np.testing.assert_allclose(cmm.markers.mean(axis=0), 0, atol=1e-15)  # TCP = centroid of the LEDs
    near = spatial.inverse(cmm.T_device_base) @ spatial.transl(0, 0, 1.0)  # 1 m in front of it
    with pytest.raises(ValueError, match=r"outside the working range 2-7 m"):
        cmm.observe(near[None], 0)


def test_marker_layout_validation():
    with pytest.raises(ValueError, match="collinear"):
        OpticalCMM(markers=[[0, 0, 0], [1, 0, 0], [2, 0, 0]])
    with pytest.raises(ValueError, match=r"\(m >= 3, 3\)"):
        Camera(markers=[[0, 0, 0], [1, 0, 0]])


def test_camera_noise_is_larger_along_the_line_of_sight():
    cam = Camera(T_device_base=np.eye(4), sigma=0.1e-3, depth_ratio=4.0)
    n = 20000
    T = np.broadcast_to(spatial.transl(0.0, 0.0, 2.0), (n, 4, 4))  # straight ahead: line of sight = z
    obs = cam.observe(T, 5)
    err = obs.position - [0.0, 0.0, 2.0]
    expected = np.array([0.1e-3, 0.1e-3, 0.4e-3]) / math.sqrt(3)  # centroid of 3 markers
    np.testing.assert_allclose(err.std(axis=0), expected, rtol=0.03)
    np.testing.assert_allclose(obs.sigma[0], expected, rtol=1e-3)  # the per-row sigma near the axis
    behind = spatial.transl(0.0, 0.0, -2.0)
    with pytest.raises(ValueError, match="behind the camera"):
        cam.observe(behind[None], 0)
    narrow = Camera(T_device_base=np.eye(4), half_fov=math.radians(10))
    with pytest.raises(ValueError, match="outside the field of view"):
        narrow.observe(spatial.transl(1.0, 0.0, 2.0)[None], 0)


# ------------------------------------------------------------ plate
def test_plate_layout_and_tilt_from_seed_001():
    pts = plate_points()
    assert pts.shape == (33, 3) and np.all(pts[:, 2] == 0)
    np.testing.assert_allclose(np.linalg.norm(pts[:24], axis=1), 0.10)
    assert np.ptp(pts[24:, 1]) == 0 and np.ptp(pts[24:, 0]) == pytest.approx(0.24)
    plate = CalibrationPlate.tilted(center=[0.5, 0.1, 0.05])
    normal = plate.T_base_device[:3, 2]
    tilt = math.degrees(math.acos(normal[2]))
    assert tilt == pytest.approx(
        math.degrees(math.acos(math.cos(math.radians(11.7)) * math.cos(math.radians(11.8))))
    )
    np.testing.assert_allclose(plate.T_base_device[:3, 3], [0.5, 0.1, 0.05])
    np.testing.assert_allclose(plate.points_base[:24].mean(axis=0), [0.5, 0.1, 0.05], atol=1e-15)


def test_plate_observes_touched_points_and_rejects_others():
    plate = CalibrationPlate.tilted(sigma=0.0, p_tool_target=[0, 0, 0.05])
    tip_base = plate.points_base
    T = spatial.homogeneous(spatial.rotx(math.pi), tip_base + [0.0, 0.0, 0.05])  # tool z down, tip 5 cm below
    obs = plate.observe(T, 0)
    np.testing.assert_allclose(obs.position, plate.points, atol=1e-12)
    k, d = plate.nearest(obs.position)
    np.testing.assert_array_equal(k, np.arange(33))
    assert d.max() < 1e-12
    T_far = T.copy()
    T_far[7, 2, 3] += 0.02
    with pytest.raises(ValueError, match=r"20\.0 mm from the nearest plate point at pose\(s\) 7"):
        plate.observe(T_far, 0)


# ------------------------------------------------------------ pen on paper
def test_pen_on_paper_noise_and_checks():
    pen = PenOnPaper(T_device_base=np.eye(4))
    assert (pen.sigma_xy, pen.sigma_z) == (0.1e-3, 0.01e-3)
    pts = PenOnPaper.circle_points(0.05)
    np.testing.assert_allclose(pts[:, :2], [[0.05, 0], [0, 0.05], [-0.05, 0], [0, -0.05]], atol=1e-15)
    n = 20000
    T = np.broadcast_to(spatial.transl(0.02, -0.03, 0.001), (n, 4, 4))
    obs = pen.observe(T, 3)
    np.testing.assert_allclose(
        (obs.position - [0.02, -0.03, 0.001]).std(axis=0), [1e-4, 1e-4, 1e-5], rtol=0.03
    )
    with pytest.raises(ValueError, match=r"off the 297 x 210 mm sheet at pose\(s\) 0"):
        pen.observe(spatial.transl(0.2, 0, 0)[None], 0)
    with pytest.raises(ValueError, match=r"15\.0 mm from the paper .* ±10 mm travel"):
        pen.observe(spatial.transl(0, 0, 0.015)[None], 0)


def test_default_paper_is_a_45_degree_plane():
    normal = PenOnPaper().T_base_device[:3, 2]
    assert math.degrees(math.acos(normal[2])) == pytest.approx(45.0)


# ------------------------------------------------------------ registry and files
@pytest.mark.parametrize("name", list(DEVICES))
def test_devices_round_trip_through_dicts(name):
    dev = make_device(name)
    again = device_from_dict(dev.to_dict())
    assert type(again) is type(dev) and again.to_dict() == dev.to_dict()
    noisy = dev.with_noise(1e-3)
    assert noisy.to_dict() != dev.to_dict()
    assert device_from_dict(noisy.to_dict()).to_dict() == noisy.to_dict()


def test_registry_errors():
    with pytest.raises(KeyError, match="unknown device 'lidar'"):
        make_device("lidar")
    with pytest.raises(ValueError, match="unknown field"):
        device_from_dict({"type": "laser-tracker", "colour": "red"})
    with pytest.raises(ValueError, match="sigma must be finite and >= 0"):
        LaserTracker(sigma=-1.0)
    with pytest.raises(ValueError, match="not a rotation matrix"):
        LaserTracker(T_device_base=np.diag([1.0, 1.0, -1.0, 1.0]))


def test_observe_is_reproducible_by_seed():
    rng = np.random.default_rng(9)
    T = random_transforms(10, rng, 0.3)
    cam = Camera()
    a, b, c = cam.observe(T, 1), cam.observe(T, 1), cam.observe(T, 2)
    np.testing.assert_array_equal(a.position, b.position)
    np.testing.assert_array_equal(a.orientation, b.orientation)
    assert not np.array_equal(a.position, c.position)
