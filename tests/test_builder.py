"""Seed 000's model builder: geometry in, complete-minimal-continuous model out."""

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest

import robocal as rc
from robocal.model.builder import build, build_model, load_geometry
from robocal.model.geometry import GeometryError, JointGeometry, Tcp, geometry_fk
from robocal.model.singularity import check_model

GEOMETRY = Path(__file__).resolve().parents[1] / "examples" / "geometry"
FILES = sorted(p.stem for p in GEOMETRY.glob("*.yaml"))
CATALOG_TWIN = {"puma560": "puma560", "irb2400": "irb2400", "irb2000": "irb2000", "irb6400r": "irb6400r"}
GENERIC_TCP = Tcp((0.05, -0.03, 0.12))  # off every axis: the complete count is reachable


def expected_count(joints, measure):
    R = sum(j.type == "revolute" for j in joints)
    return 4 * R + 2 * (len(joints) - R) + (6 if measure == "pose" else 3)


def random_q(model, n, seed=0):
    lim = np.clip(model.joint_limits, -np.pi, np.pi)
    lim = np.where(
        np.array(model.joint_types)[:, None] == "prismatic", np.clip(model.joint_limits, -0.5, 0.5), lim
    )
    return np.random.default_rng(seed).uniform(lim[:, 0], lim[:, 1], (n, model.dof))


def test_shipped_geometries_cover_the_seed_examples():
    assert {"puma560", "irb2400", "irb2000", "irb6400r", "gantry_ppp_rrr", "scara_rrpr"} <= set(FILES)


@pytest.mark.parametrize("name", FILES)
@pytest.mark.parametrize("measure", ["pose", "position"])
def test_built_model_reproduces_the_geometry(name, measure):
    g = load_geometry(GEOMETRY / f"{name}.yaml")
    model = g.build(measure).model
    q = random_q(model, 50)
    T, G = model.fk(q), geometry_fk(g.joints, g.tcp, q)
    assert np.abs(T[:, :3, 3] - G[:, :3, 3]).max() < 1e-9
    if measure == "pose" and g.tcp.rotation is not None:
        assert np.abs(T[:, :3, :3] - G[:, :3, :3]).max() < 1e-9
    # the tool z axis follows the last joint's z when no TCP orientation is given
    if g.tcp.rotation is None:
        np.testing.assert_allclose(T[:, :3, 2], model.joint_frames(q)[:, -1, :3, 2], atol=1e-12)


@pytest.mark.parametrize("name", sorted(CATALOG_TWIN))
def test_built_model_equals_the_catalog_model(name):
    built = load_geometry(GEOMETRY / f"{name}.yaml").build("pose").model
    catalog = rc.robot(CATALOG_TWIN[name])
    q = random_q(catalog, 100, seed=1)
    assert np.abs(built.fk(q) - catalog.fk(q)).max() < 1e-9


@pytest.mark.parametrize("name", FILES)
@pytest.mark.parametrize("measure", ["pose", "position"])
def test_identified_set_is_complete_and_minimal(name, measure):
    g = load_geometry(GEOMETRY / f"{name}.yaml")
    result = dataclasses.replace(g, tcp=GENERIC_TCP).build(measure)
    n = expected_count(g.joints, measure)
    assert result.expected_free == n
    assert len(result.model.free_names) == n == result.rank
    assert result.complete_and_minimal and not result.warnings
    # full column rank over fresh poses, with all columns scaled to unit norm
    J = result.model.jacobian(random_q(result.model, 80, seed=5), rows=measure)
    J = J / np.linalg.norm(J, axis=0)
    s = np.linalg.svd(J, compute_uv=False)
    assert s[-1] / s[0] > 1e-6


@pytest.mark.parametrize("name", FILES)
def test_built_models_pass_the_singularity_check(name):
    model = load_geometry(GEOMETRY / f"{name}.yaml").build("pose").model
    assert check_model(model).ok


def test_robot_specific_parameterisations():
    links = [info.kind for info in load_geometry(GEOMETRY / "irb2400.yaml").build().links]
    assert links == ["B∥R", "R⊥R", "R∥R", "R⊥R", "R⊥R", "R⊥R", "R∥TCP"]
    scara = [info.equation for info in load_geometry(GEOMETRY / "scara_rrpr.yaml").build().links]
    assert scara == [15, 17, 23, 19, 27]
    gantry = [info.equation for info in load_geometry(GEOMETRY / "gantry_ppp_rrr.yaml").build().links]
    assert gantry == [11, 20, 20, 19, 16, 16, 27]


def random_robot(rng, n):
    """A random serial robot: random types, skew/parallel/perpendicular axes, offsets."""
    joints = []
    prev = None
    for j in range(n):
        kind = "prismatic" if rng.random() < 0.25 else "revolute"
        choice = rng.random()
        if prev is not None and choice < 0.3:
            axis = prev + rng.normal(scale=0.02, size=3)  # nearly parallel
        elif prev is not None and choice < 0.5:
            axis = np.cross(prev, rng.normal(size=3))  # perpendicular
        else:
            axis = rng.normal(size=3)  # skew at any angle
        axis /= np.linalg.norm(axis)
        joints.append(JointGeometry(kind, tuple(rng.normal(scale=0.3, size=3)), tuple(axis), f"j{j}"))
        prev = axis
    return joints


@pytest.mark.parametrize("seed", range(12))
def test_random_robots_are_reproduced_complete_and_continuous(seed):
    rng = np.random.default_rng(seed)
    joints = random_robot(rng, int(rng.integers(2, 7)))
    tcp = Tcp(
        tuple(rng.normal(scale=0.1, size=3)),
        tuple(map(tuple, rc.spatial.rotvec_to_matrix(rng.normal(size=3)))),
    )
    for measure in ("pose", "position"):
        result = build(joints, tcp, measure)
        model = result.model
        q = rng.uniform(-2, 2, (30, len(joints)))
        T, G = model.fk(q), geometry_fk(joints, tcp, q)
        assert np.abs(T[:, :3, 3] - G[:, :3, 3]).max() < 1e-9
        if measure == "pose":
            assert np.abs(T[:, :3, :3] - G[:, :3, :3]).max() < 1e-9
        assert len(model.free_names) == result.rank == expected_count(joints, measure)
        assert check_model(model, measure).ok


def test_parameters_move_continuously_with_the_geometry():
    """Seed 000's point: a 1e-6 rad tilt of a parallel axis moves the parameters by O(1e-6)."""
    g = load_geometry(GEOMETRY / "irb2400.yaml")
    base = g.build("pose").model
    for j in range(len(g.joints)):
        for tilt in ([1e-6, 0, 0], [0, 0, 1e-6]):
            joints = list(g.joints)
            axis = np.asarray(joints[j].axis) + np.array(tilt)
            joints[j] = dataclasses.replace(joints[j], axis=tuple(axis / np.linalg.norm(axis)))
            moved = dataclasses.replace(g, joints=tuple(joints)).build("pose").model
            assert moved.names == base.names
            change = np.abs(moved.values - base.values)
            # an angle at ±π may come out at the other end of the circle: the same rotation
            angular = np.array([st.is_rotation for st in base.steps])
            change[angular] = np.abs(np.angle(np.exp(1j * (moved.values - base.values)[angular])))
            assert change.max() < 1e-5, (j, tilt, base.names[int(change.argmax())])


def test_nearly_parallel_axes_count_as_parallel():
    tilt = math.radians(2.0)
    joints = [
        JointGeometry("revolute", (0, 0, 0), (0, 0, 1)),
        JointGeometry("revolute", (0, 0, 0.5), (0, 1, 0)),
        JointGeometry("revolute", (0.6, 0, 0), (0, math.cos(tilt), math.sin(tilt))),
        JointGeometry("revolute", (0.5, 0, 0), (0, 1, 0)),
    ]
    links = build(joints, GENERIC_TCP).links
    assert [info.kind for info in links[1:4]] == ["R⊥R", "R∥R", "R∥R"]
    # with a 10° tolerance the 2° pair still counts as parallel, with 1° it does not
    assert build(joints, GENERIC_TCP, parallel_tolerance=math.radians(1)).links[2].kind == "R⊥R"


@pytest.mark.parametrize(
    ("joints", "message"),
    [
        ([], "at least one joint"),
        ([{"type": "revolute", "position": (0, 0, 0), "axis": (0, 0, 0)}], "joint 1: axis .* zero length"),
        ([{"type": "revolute", "position": (0, 0, float("nan")), "axis": (0, 0, 1)}], "joint 1: .*NaN"),
        ([{"type": "spherical", "position": (0, 0, 0), "axis": (0, 0, 1)}], "joint 1: type must be"),
        (
            [
                {"type": "revolute", "position": (0, 0, 0), "axis": (0, 0, 1), "name": "a"},
                {"type": "revolute", "position": (0, 0, 0.3), "axis": (0, 0, -1), "name": "b"},
            ],
            r"joint 2 \(b\) turns about the same line as joint 1 \(a\)",
        ),
    ],
)
def test_invalid_geometry_names_the_joint(joints, message):
    with pytest.raises(GeometryError, match=message):
        build_model(joints, (0, 0, 0.1))


def test_geometry_file_errors_name_the_file_and_field(tmp_path):
    path = tmp_path / "g.yaml"
    path.write_text("name: g\njoints:\n  - {type: revolute, position: [0, 0], axis: [0, 0, 1]}\n")
    with pytest.raises(GeometryError, match=r"g\.yaml: joints\[0\]\.position"):
        load_geometry(path)
    path.write_text("name: g\njoints:\n  - {type: revolute, position: [0, 0, 0], axis: [0, 0, 0]}\n")
    with pytest.raises(GeometryError, match=r"g\.yaml: joint 1: axis"):
        load_geometry(path)


def test_tcp_on_the_last_axis_is_explained():
    g = load_geometry(GEOMETRY / "puma560.yaml")  # the flange lies on axis 6
    result = g.build("position")
    assert result.rank < result.expected_free
    assert "lies on the last joint axis (q6)" in result.warnings[0]


def test_rc_build_model_is_the_public_entry_point():
    model = rc.build_model(
        [
            {"type": "revolute", "position": (0, 0, 0.3), "axis": (0, 0, 1)},
            {"type": "revolute", "position": (0.4, 0, 0), "axis": (0, 0, 1)},
        ],
        tcp=(0.3, 0.02, -0.1),
        measure="position",
    )
    assert len(model.free_names) == 4 * 2 + 3
