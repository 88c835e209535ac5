"""Constraint measurements (issue 33): fixed points, planes, distances; their Jacobians,
identifiable sets, recovery at the Cramér-Rao bound, files and the real Panda recordings."""

from __future__ import annotations

import dataclasses
import re
from pathlib import Path

import numpy as np
import pytest

import robocal as rc
from robocal import spatial
from robocal.identify.constraints.fit import (
    build_constraint_problem,
    calibrate_constraints,
    constraint_figures,
    kind_identifiable,
)
from robocal.identify.options import Pruning
from robocal.measure.constraints.data import (
    ConstraintFileError,
    constraint_kind,
    parse_distance,
    read_constraints,
    write_constraints,
)
from robocal.measure.constraints.data_set import ConstraintSet
from robocal.measure.constraints.sim import simulate_constraints
from robocal.measure.ik_starts import random_configurations
from robocal.measure.true_model import draw_true_model

BASE = {"base_x", "base_y", "base_rx", "base_ry", "theta1", "d1"}  # the complete model's base frame
PANDA = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "ball_in_socket"


@pytest.fixture(scope="module")
def ur10():
    return rc.calibration_model("ur10")


def _with_distance(data: ConstraintSet, points) -> ConstraintSet:
    return dataclasses.replace(
        data, point_pairs=[[0, 1]], point_length=[float(np.linalg.norm(points[0] - points[1]))]
    )


def _mixed(ur10) -> ConstraintSet:
    """Every kind in one set: points, unknown and known planes, pairs, tracker rows, a known distance."""
    rng = np.random.default_rng(5)
    n = 16
    q = rng.uniform(-2, 2, (n, ur10.dof))
    point = np.array([0, 0, 1, 1] + [-1] * 12)
    plane = np.array([-1] * 4 + [0, 0, 0, 1, 1, 1] + [-1] * 6)
    position = np.full((n, 3), np.nan)
    position[10:13] = rng.normal(size=(3, 3))
    known = np.array([[np.nan] * 4, [0.0, 0.6, 0.8, 0.1]])
    return ConstraintSet(q, point, plane, position=position, pairs=[[12, 13], [14, 15]],
                         pair_length=[0.3, 0.4], point_pairs=[[0, 1]], point_length=[0.05],
                         known_planes=known, sigma=2e-5)  # fmt: skip


def test_jacobian_matches_finite_differences_for_every_kind(ur10):
    problem = build_constraint_problem(ur10, _mixed(ur10), tool=np.array([0.01, 0.0, 0.1]))
    x = problem.x0 + np.random.default_rng(1).normal(scale=1e-3, size=len(problem.x0))
    J = problem.jacobian(x)
    h = 1e-7
    fd = np.column_stack(
        [(problem.residual(x + h * e) - problem.residual(x - h * e)) / (2 * h) for e in np.eye(len(x))]
    )
    assert J.shape == fd.shape and J.shape[0] == 4 * 3 + 6 + 2 + 3 * 3 + 1
    np.testing.assert_allclose(J, fd, atol=1e-4 * np.abs(fd).max())
    fixed = problem.fix(["point0_x", "plane0_d"])
    assert len(fixed.x0) == len(x) - 2
    np.testing.assert_allclose(
        fixed.jacobian(fixed.x0), problem.jacobian(problem.x0)[:, fixed.keep[problem.keep]]
    )


@pytest.mark.parametrize(
    ("kind", "distance", "unseen"),
    [
        ("point", False, 7),  # the base frame (6) and the scale
        ("point", True, 6),  # a known distance between the points fixes the scale
        ("plane", False, 7),
        ("distance", False, 6),  # lengths fix the scale; no absolute position
    ],
)
def test_identifiable_set_per_kind(ur10, kind, distance, unseen):
    n = 80 if kind == "distance" else 40  # a pair is one equation: 40 pairs for 19 unknowns
    data, truth = simulate_constraints(ur10, kind, n, count=3 if kind == "plane" else 2, seed=3)
    if distance:
        data = _with_distance(data, truth.points)
    kept, dropped = kind_identifiable(ur10, data)
    names = {d.name for d in dropped}
    assert len(dropped) == unseen, [d.name for d in dropped]
    assert BASE & names == BASE if kind != "plane" else len(BASE & names) >= 5
    assert not names & set(kept)
    assert not any(n.startswith(("point", "plane")) for n in names)  # the scene's unknowns are kept


def test_tracker_rows_fix_the_scale_and_calibrate_with_the_sockets(ur10):
    """Mixed data: 12 poses measured by a tracker (in its own frame) and 30 socket poses."""
    true = draw_true_model(ur10, seed=2)
    data, _ = simulate_constraints(true, "point", 30, sigma=1e-5, seed=4)
    T = np.eye(4)
    T[:3, :3] = spatial.rotz(0.3)
    T[:3, 3] = [1.0, -0.5, 0.2]
    q_tracked = random_configurations(ur10, 12, rng=9)  # other poses: at the sockets a tracker sees 2 points
    p = true.fk(q_tracked)[:, :3, 3] @ T[:3, :3].T + T[:3, 3]
    none = -np.ones(12, dtype=int)
    position = np.vstack([np.full((data.n, 3), np.nan), p])
    mixed = ConstraintSet(np.vstack([data.q, q_tracked]), np.concatenate([data.point, none]),
                          np.concatenate([data.plane, none]), position=position, sigma=1e-5)  # fmt: skip
    _, dropped = kind_identifiable(ur10, data)
    assert len(dropped) == 7  # sockets alone: the base frame and the scale
    _, dropped = kind_identifiable(ur10, mixed)
    assert {d.name for d in dropped} == BASE  # the tracker's frame takes the base; the scale is seen
    result = calibrate_constraints(ur10, mixed)
    assert result.success and set(result.kinds) == {"point", "tracker"}
    np.testing.assert_allclose(result.T_device_base, T, atol=2e-3)  # up to the true robot's base error
    assert result.figures.point_spread.max() < 5e-5


def _monte_carlo(ur10, kind: str, runs: int, n: int) -> np.ndarray:
    """z = (estimate - truth) / σ over ``runs`` simulations of the same true robot (σ: the
    Cramér-Rao bound, (JᵀJ)⁻¹ at the estimate with the stated noise)."""
    count = 3 if kind == "plane" else 2
    probe, truth0 = simulate_constraints(ur10, kind, n, count=count, seed=100)
    if kind == "point":
        probe = _with_distance(probe, truth0.points)
    kept, unseen = kind_identifiable(ur10, probe)
    gauge = tuple(d.name for d in unseen)  # every run fixes the same ones (the scale's pick can vary)
    true = draw_true_model(ur10, length="1mm", angle="0.1deg", params=list(kept), seed=7)
    values = dict(zip(true.names, true.values, strict=True))
    z = []
    for run in range(runs):
        data, truth = simulate_constraints(true, kind, n, sigma=2e-5, count=count, seed=run)
        if kind == "point":
            data = _with_distance(data, truth.points)
        result = calibrate_constraints(ur10, data, known_noise=True, fixed=gauge)
        assert result.success
        robot = [k for k, name in enumerate(result.names) if name in values]
        assert {result.names[k] for k in robot} == set(kept)
        est, std = result.estimates[robot], result.std[robot]
        z.append((est - np.array([values[result.names[k]] for k in robot])) / std)
    return np.array(z)


@pytest.mark.parametrize("kind", ["point", "plane", "distance"])
def test_recovers_the_true_robot_at_the_cramer_rao_bound(ur10, kind):
    z = _monte_carlo(ur10, kind, runs=12, n=80 if kind == "distance" else 40)
    rms = np.sqrt(np.mean(z**2))
    assert rms <= 1.2, f"{kind}: RMS error {rms:.2f} x the Cramér-Rao bound"
    assert np.abs(z).max() < 5.0


@pytest.mark.slow
@pytest.mark.parametrize("kind", ["point", "plane", "distance"])
def test_cramer_rao_per_parameter(ur10, kind):
    z = _monte_carlo(ur10, kind, runs=60, n=120 if kind == "distance" else 60)
    per_parameter = np.sqrt(np.mean(z**2, axis=0))
    assert per_parameter.max() <= 1.2 * 1.3, per_parameter  # 60 runs: ±13 % on a ratio of σ
    assert np.sqrt(np.mean(z**2)) <= 1.2


def test_unidentifiable_parameters_are_held_not_invented(ur10):
    data, _ = simulate_constraints(ur10, "plane", 40, count=3, seed=8)
    result = calibrate_constraints(ur10, data)
    not_seen = {d.name for d in result.dropped if d.reason in ("redundant", "no effect")}
    assert len(not_seen) == 7 and not not_seen & set(result.names)
    given = dict(zip(ur10.names, ur10.values, strict=True))
    calibrated = dict(zip(result.model.names, result.model.values, strict=True))
    assert all(calibrated[name] == given[name] for name in not_seen)
    assert any("not identifiable" in line for line in result.summary_lines())


def test_csv_round_trip_and_kind(tmp_path, ur10):
    data = _mixed(ur10)
    path = tmp_path / "mixed.csv"
    write_constraints(data, path)
    assert constraint_kind(path) == "point"
    back = read_constraints(path, ur10.dof, distances=[(0, 1, 0.05)], sigma=2e-5)
    np.testing.assert_array_equal(back.q, data.q)
    np.testing.assert_array_equal(back.point, data.point)
    np.testing.assert_array_equal(back.plane, data.plane)
    np.testing.assert_array_equal(back.pairs, data.pairs)
    np.testing.assert_allclose(back.pair_length, data.pair_length)
    np.testing.assert_array_equal(back.tracked, data.tracked)
    assert back.kinds == data.kinds


@pytest.mark.parametrize(
    ("body", "where"),
    [
        ("q1,q2,q3,q4,q5,q6,point\n0,0,0,0,0,0,0\n0,0,x,0,0,0,0\n", r"row 3, column q3"),
        ("q1,q2,q3,q4,q5,q6,point\n0,0,0,0,0,0,-1\n", r"row 2, column point"),
        ("q1,q2,q3,q4,q5,q6,pair,distance_mm\n0,0,0,0,0,0,0,300\n", r"pair 0 has 1 rows"),
        ("q1,q2,q3,q4,q5,q6,pair,distance_mm\n0,0,0,0,0,0,0,300\n1,0,0,0,0,0,0,301\n", r"pair 0"),
        ("q1,q2,q3,q4,q5,point\n0,0,0,0,0,0\n", r"q6"),
        ("q1,q2,q3,q4,q5,q6,point\n0,0,0,0,0,0,1\n", r"point 0 has no row"),
        ("q1,q2,q3,q4,q5,q6,point\n0,0,0,0,0,0,0,7\n", r"row 2: 8 cells"),
    ],
)
def test_bad_files_are_refused_by_row_and_column(tmp_path, body, where):
    path = tmp_path / "bad.csv"
    path.write_text(body)
    with pytest.raises(ConstraintFileError, match=where):
        read_constraints(path, 6)


def test_distance_option():
    assert parse_distance("0,1=50mm") == (0, 1, pytest.approx(0.05))
    for bad in ("0,1=50", "0=50mm", "1,1=50mm", "0,1=-5mm", "a,b=5mm"):
        with pytest.raises(ValueError):
            parse_distance(bad)


# ---------------------------------------------------------------------- the real Panda recordings
def panda_model():
    """The Panda's complete position model to the ball centre from MUKCa's URDF; the
    finger's ``<mimic>`` (off the chain) removed first if ``model build`` refuses it."""
    import tempfile

    from robocal.model.urdf.read import URDFError, model_from_urdf

    urdf = PANDA / "urdf" / "panda.urdf"
    try:
        return model_from_urdf(urdf, measure="position", tip="ball_link")
    except URDFError:
        text = re.sub(r"<mimic[^>]*/>", "", urdf.read_text())
        with tempfile.TemporaryDirectory() as folder:
            path = Path(folder) / "panda.urdf"
            path.write_text(text)
            return model_from_urdf(path, measure="position", tip="ball_link")


def panda_placement(name: str) -> ConstraintSet:
    folder = PANDA / "panda_1" / name
    q = [np.loadtxt(folder / f"hole_{k}.csv", delimiter=",") for k in (0, 1)]
    label = np.repeat([0, 1], [len(q[0]), len(q[1])])
    return ConstraintSet(np.vstack(q), label, -np.ones(len(label), dtype=int), point_pairs=[[0, 1]],
                         point_length=[0.05], sigma=1e-4)  # fmt: skip


@pytest.mark.skipif(not PANDA.is_dir(), reason="the ball-in-socket recordings are not here")
def test_panda_ball_in_socket_held_out_placements():
    model = panda_model()
    result = calibrate_constraints(model, panda_placement("front"), pruning=Pruning())
    assert {d.name for d in result.dropped} >= BASE  # fixed points cannot see the base frame
    for held_out in ("right", "back-high"):
        data = panda_placement(held_out)
        nominal, calibrated = constraint_figures(model, data), constraint_figures(result.model, data)
        assert nominal.point_spread.min() > 5e-3  # the nominal URDF: 8-11 mm
        assert calibrated.point_spread.max() < nominal.point_spread.min() / 4
        assert abs(calibrated.point_distance_error[0]) < abs(nominal.point_distance_error[0])


# ---------------------------------------------------------------------- the command line
def test_cli_simulate_calibrate_validate_each_kind(tmp_path):
    import json

    from typer.testing import CliRunner

    from robocal.cli.app import app

    runner = CliRunner()
    for kind in ("point", "plane", "distance"):
        data = tmp_path / f"{kind}.csv"
        args = [
            "simulate",
            "ur10",
            "--kind",
            kind,
            "--n",
            "80",
            "--count",
            "3",
            "--seed",
            "1",
            "-o",
            str(data),
        ]
        assert runner.invoke(app, [*args, "--noise", "0.01mm"]).exit_code == 0
        assert constraint_kind(data) == kind
        truth = json.loads(data.with_name(data.name + ".truth.json").read_text())
        out = tmp_path / f"cal_{kind}"
        extra = []
        if kind == "point":
            a, b, d = truth["point_distances_m"][0]
            extra = ["--distance", f"{a},{b}={d * 1e3:.6f}mm"]
        run = runner.invoke(app, ["calibrate", "ur10", "--data", str(data), "-o", str(out), *extra])
        assert run.exit_code == 0, run.output
        doc = json.loads((out / "constraints.json").read_text())
        assert doc["measurements"] == [kind] and doc["success"]
        unseen = {d["name"] for d in doc["not_identifiable"] if d["reason"] in ("redundant", "no effect")}
        assert unseen >= BASE or (kind == "plane" and len(unseen) == 7)
        assert doc["rms_after_m"] < 3e-5 < doc["rms_before_m"]
        again = runner.invoke(app, ["calibrate", "ur10", "--data", str(data), "-o", str(out), *extra])
        assert again.exit_code == 2 and "--force" in again.output  # a result is not replaced silently
        check = runner.invoke(app, ["validate", str(out), "--data", str(data)])
        assert check.exit_code == 0, check.output
        calibrated = check.output.split("before calibration")[0]  # the nominal robot's figures follow
        numbers = [float(x) for x in re.findall(r"(-?\d+\.\d+) mm", calibrated)]
        assert numbers and max(abs(x) for x in numbers) < 0.05  # spread, distance error, plane residual


def test_cli_refuses_bad_constraint_input_in_one_line(tmp_path):
    from typer.testing import CliRunner

    from robocal.cli.app import app

    runner = CliRunner()
    bad = tmp_path / "bad.csv"
    bad.write_text("q1,q2,q3,q4,q5,q6,point\n1,2,3,4,5,x,0\n")
    run = runner.invoke(app, ["calibrate", "ur10", "--data", str(bad), "-o", str(tmp_path / "out")])
    assert run.exit_code == 2 and "row 2, column q6" in run.output and "Traceback" not in run.output
    assert not (tmp_path / "out").exists()
    good = tmp_path / "good.csv"
    good.write_text("q1,q2,q3,q4,q5,q6,point\n" + "".join(f"{k * 0.1},1,2,3,4,5,0\n" for k in range(8)))
    run = runner.invoke(
        app, ["calibrate", "ur10", "--data", str(good), "-o", str(tmp_path / "o2"), "--distance", "0,1=50"]
    )
    assert run.exit_code == 2 and "unit" in run.output
    run = runner.invoke(
        app, ["calibrate", "ur10", "--data", str(good), "-o", str(tmp_path / "o3"), "--distance", "0,1=5mm"]
    )
    assert run.exit_code == 2 and "point" in run.output  # the file has point 0 only


@pytest.mark.parametrize("kind", ["point", "plane", "distance"])
def test_pose_planning_on_each_kinds_jacobian(ur10, kind):
    from robocal.identify.constraints.poses import select_constraint_poses

    pool, _ = simulate_constraints(
        ur10, kind, 240 if kind == "distance" else 120, sigma=1e-9, count=3, seed=2
    )
    n = 30
    chosen = select_constraint_poses(ur10, pool, n, index="O1")
    assert chosen.indices["O1"] > chosen.baseline["O1"] > 0  # better than as many taken at random
    assert not BASE & set(chosen.params)  # over what this kind can see
    assert chosen.data.kinds == (kind,)
    # the plan's configurations satisfy the constraint on the nominal robot, so recording them works
    figures = constraint_figures(ur10, chosen.data)
    assert max([*figures.point_spread, *figures.plane_rms, *np.abs(figures.pair_error)]) < 1e-6


def test_cli_poses_writes_a_constraint_plan(tmp_path):
    from typer.testing import CliRunner

    from robocal.cli.app import app

    out = tmp_path / "plan.csv"
    args = [
        "poses",
        "ur10",
        "--method",
        "optimal",
        "--rows",
        "plane",
        "--n",
        "30",
        "--pool",
        "90",
        "-o",
        str(out),
    ]
    run = CliRunner().invoke(app, args)
    assert run.exit_code == 0, run.output
    assert constraint_kind(out) == "plane"
    assert read_constraints(out, 6).n == 30
