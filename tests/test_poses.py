"""Pose sets (robocal.measure.poses)."""

import numpy as np
import pytest

import robocal as rc
from robocal.measure.cube import Cube
from robocal.measure.diagonal_poses import diagonal_plane_poses
from robocal.measure.ik import solve_ik
from robocal.measure.pose_set import order_all_joints_move, position_sigma_min
from robocal.measure.poses import (
    iso9283_poses,
    plane_grid,
    poses_for_points,
    random_poses,
    read_poses,
    write_poses,
)

ABOVE_TABLE = np.array([[-1.0, -1.0, 0.0], [1.0, 1.0, 1.0]])  # Katana: cube above its base plate


def _inside_limits(model, q):
    lim = model.joint_limits
    return bool(np.all((q >= lim[:, 0]) & (q <= lim[:, 1])))


def test_random_poses_are_seeded_inside_limits_and_regular():
    model = rc.robot("katana450")
    q = random_poses(model, 200, seed=3, min_sigma=0.02, margin=0.05)
    assert q.shape == (200, 5)
    np.testing.assert_array_equal(q, random_poses(model, 200, seed=3, min_sigma=0.02, margin=0.05))
    assert not np.array_equal(q, random_poses(model, 200, seed=4, min_sigma=0.02, margin=0.05))
    lim = model.joint_limits
    span = lim[:, 1] - lim[:, 0]
    assert np.all((q >= lim[:, 0] + 0.05 * span) & (q <= lim[:, 1] - 0.05 * span))
    assert position_sigma_min(model, q).min() >= 0.02


def test_random_poses_in_a_box():
    model = rc.robot("ur10")
    box = np.array([[-0.2, -0.8, 0.2], [0.2, -0.6, 0.4]])
    q = random_poses(model, 300, seed=1, box=box)
    p = model.fk(q)[:, :3, 3]
    assert np.all((p >= box[0]) & (p <= box[1]))
    with pytest.raises(ValueError, match="box must be"):
        random_poses(model, 3, box=[[0, 0, 0]])


def test_cube_geometry_follows_iso_9283():
    cube = Cube(center=np.array([1.0, 2.0, 3.0]), side=2.0)
    c = cube.corners
    np.testing.assert_allclose(c[0], [0, 1, 2])  # C1: minimum corner
    np.testing.assert_allclose(c[6], [2, 3, 4])  # C7: maximum corner
    for plane in (1, 2, 3, 4):
        r = cube.plane_corners(plane)
        # a rectangle through two opposite edges: sides L and L sqrt(2), through the centre
        sides = np.linalg.norm(np.diff(np.vstack([r, r[:1]]), axis=0), axis=1)
        np.testing.assert_allclose(np.sort(sides), [2, 2, 2 * np.sqrt(2), 2 * np.sqrt(2)])
        np.testing.assert_allclose(r.mean(axis=0), cube.center)
        P = cube.iso_points(plane)
        np.testing.assert_allclose(P[0], cube.center)
        diag = np.linalg.norm(r[2] - r[0])
        for k in range(4):  # P2..P5: 10 % of the diagonal from corner k, on that diagonal
            np.testing.assert_allclose(np.linalg.norm(P[k + 1] - r[k]), 0.1 * diag)
            opposite = r[(k + 2) % 4]
            np.testing.assert_allclose(np.cross(P[k + 1] - r[k], opposite - r[k]), 0, atol=1e-12)
    np.testing.assert_allclose(cube.plane_corners(1), c[[0, 1, 6, 7]])  # C1-C2-C7-C8
    with pytest.raises(ValueError, match="diagonal plane must be"):
        cube.iso_points(5)


@pytest.fixture(scope="module")
def ur10_iso():
    return iso9283_poses(rc.robot("ur10"))


def test_iso9283_poses_ur10(ur10_iso):
    model = rc.robot("ur10")
    iso = ur10_iso
    assert iso.q.shape == (5, 6) and iso.reachable.all() and iso.labels[0] == "P1"
    assert _inside_limits(model, iso.q)
    T = model.fk(iso.q)
    np.testing.assert_allclose(T[:, :3, 3], iso.positions, atol=1e-6)
    np.testing.assert_allclose(T[:, :3, :3], np.broadcast_to(iso.orientation, (5, 3, 3)), atol=1e-6)
    np.testing.assert_allclose(iso.positions, iso.cube.iso_points(1))
    assert 0.6 < iso.cube.side < 1.3  # the UR10 reaches 1.3 m; a tool-down cube is ~0.9 m
    # the whole measuring plane is reachable with the same orientation
    grid = iso.cube.plane_points(1, (6, 6))
    frames = rc.spatial.homogeneous(np.broadcast_to(iso.orientation, (36, 3, 3)), grid)
    assert solve_ik(model, frames).success


def test_iso9283_poses_katana_keep_the_tool_axis():
    model = rc.robot("katana450")
    iso = iso9283_poses(model, region=ABOVE_TABLE)
    assert iso.info["kind"] == "axis" and iso.reachable.all()
    assert _inside_limits(model, iso.q)
    assert iso.cube.side > 0.08 and iso.cube.corners[:, 2].min() >= 0
    T = model.fk(iso.q)
    np.testing.assert_allclose(T[:, :3, 3], iso.positions, atol=1e-6)
    np.testing.assert_allclose(T[:, :3, 2], np.tile([0.0, 0.0, -1.0], (5, 1)), atol=1e-6)


def test_thesis_diagonal_plane_poses():
    model = rc.robot("katana450")
    # the frontal cube of seed 003 §5.4-5.5: side 200 mm around the circle's centre
    # [0 -300 139.2893] mm of the nominal base, which sits at [55 55 201.5] mm
    cube = Cube(center=np.array([0.055, -0.245, 0.3407893]), side=0.2)
    ps = diagonal_plane_poses(model, cube, region=ABOVE_TABLE, seed=2)
    assert len(ps) == 118 and ps.reachable.all()
    assert ps.labels.count("boundary") == 45 and ps.labels.count("plane") == 73
    assert _inside_limits(model, ps.q)
    np.testing.assert_allclose(model.fk(ps.q)[:, :3, 3], ps.positions, atol=1e-6)
    # every joint moves between consecutive poses
    dq = np.abs(np.diff(ps.q, axis=0))
    assert dq.min() > np.radians(2) and ps.info["min_joint_change_rad"] == pytest.approx(dq.min(axis=1).min())
    # lattice poses lie on a diagonal plane of the cube (unit coords: z = y, z = 1 - x, ...)
    u = (ps.positions[np.array(ps.labels) == "plane"] - cube.center) / cube.side + 0.5
    on_plane = np.isclose(u[:, 2], u[:, 1]) | np.isclose(u[:, 2], 1 - u[:, 0])
    on_plane |= np.isclose(u[:, 2], 1 - u[:, 1]) | np.isclose(u[:, 2], u[:, 0])
    assert on_plane.all() and np.all((u > -1e-9) & (u < 1 + 1e-9))
    # near-boundary poses lie outside the cube, farther from its centre
    b = ps.positions[np.array(ps.labels) == "boundary"]
    assert np.median(np.linalg.norm(b - cube.center, axis=1)) > cube.side


def test_order_all_joints_move():
    # two joints; the natural order has joint 2 standing still between neighbours
    q = np.array([[0, 0], [1, 0], [2, 1], [3, 1], [4, 2], [5, 2]], dtype=float)
    order, worst = order_all_joints_move(q)
    assert sorted(order.tolist()) == list(range(6)) and order[0] == 0
    assert worst >= 1.0
    assert np.abs(np.diff(q[order], axis=0)).min() == worst


def test_plane_grid():
    pts = plane_grid([0.5, 0, 0.2], (0.4, 0.2), (5, 3), normal=(0, 0, 2))
    assert pts.shape == (15, 3)
    np.testing.assert_allclose(pts[:, 2], 0.2)
    np.testing.assert_allclose(pts.min(axis=0)[:2], [0.3, -0.1])
    np.testing.assert_allclose(pts.max(axis=0)[:2], [0.7, 0.1])
    # a plate in front of the UR10, reached tool-down on one configuration branch
    model = rc.robot("ur10")
    plate = poses_for_points(model, pts + [0, -0.6, 0], kind="pose", orientation=np.diag([1.0, -1, -1]))
    assert plate.reachable.all() and plate.labels[0] == "point1"
    np.testing.assert_allclose(model.fk(plate.q)[:, :3, 3], pts + [0, -0.6, 0], atol=1e-6)
    assert np.abs(plate.q - plate.q[0]).max() < 1.5  # no branch switch across a 0.4 m plate


def test_poses_file_round_trip(tmp_path):
    model = rc.robot("ur10")
    q = random_poses(model, 7, seed=0)
    path = write_poses(tmp_path / "poses.csv", q, model=model, metadata={"method": "random"})
    text = path.read_text()
    assert "# robot: ur10" in text and "x" not in text.splitlines()[-8].split(",")
    np.testing.assert_array_equal(read_poses(path, model), q)
    bad = q.copy()
    bad[3, 1] = 7.0  # beyond the UR10's 2π limit
    with pytest.raises(ValueError, match="pose 4, joint shoulder_lift"):
        write_poses(tmp_path / "bad.csv", bad, model=model)
    with pytest.raises(ValueError, match="5 joints"):
        write_poses(tmp_path / "bad.csv", q, model=rc.robot("katana450"))


def test_poses_command_writes_a_poses_file(tmp_path):
    from typer.testing import CliRunner

    from robocal.cli import app

    runner = CliRunner()
    out = tmp_path / "opt.csv"
    result = runner.invoke(
        app,
        ["poses", "ur10", "--method", "optimal", "--n", "12", "--pool", "300", "--seed", "3", "-o", str(out)],
    )
    assert result.exit_code == 0, result.output
    assert "O1" in result.output and "not identifiable: theta6" in result.output
    q = read_poses(out, rc.robot("ur10"))
    assert q.shape == (12, 6)
    assert "# index: O1" in out.read_text()
    result = runner.invoke(app, ["poses", "katana450", "--n", "4", "-o", str(tmp_path / "r.csv")])
    assert result.exit_code == 0 and read_poses(tmp_path / "r.csv").shape == (4, 5)
    result = runner.invoke(app, ["poses", "ur10", "--index", "O9", "-o", str(tmp_path / "x.csv")])
    assert result.exit_code == 2 and "O9" in result.output
