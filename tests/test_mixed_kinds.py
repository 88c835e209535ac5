"""Mixed measurement kinds in one fit (issue 33): tracker positions with socket poses, each
kind weighted by its own noise; the union's identifiable set; simulated held-out
placements; inclinometer pose planning."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

import robocal as rc
from robocal import spatial
from robocal.identify.constraints.fit import calibrate_constraints, kind_identifiable
from robocal.measure.constraints.data import read_constraints, write_constraints
from robocal.measure.constraints.data_set import ConstraintSet, merge_sets
from robocal.measure.constraints.sim import simulate_constraints, simulate_tracker_rows
from robocal.measure.true_model import draw_true_model

BASE = {"base_x", "base_y", "base_rx", "base_ry", "theta1", "d1"}  # the complete model's base frame
SOCKET_SIGMA, TRACKER_SIGMA = 5e-5, 2e-5  # m: a ball seated by hand, a laser tracker


@pytest.fixture(scope="module")
def ur10():
    return rc.calibration_model("ur10")


@pytest.fixture(scope="module")
def frame():
    T = np.eye(4)
    T[:3, :3] = spatial.rotz(0.3)
    T[:3, 3] = [1.0, -0.5, 0.2]
    return T


@pytest.fixture(scope="module")
def true(ur10):
    return draw_true_model(ur10, length="1mm", angle="0.1deg", seed=7)


def _sets(true, frame, run: int) -> tuple[ConstraintSet, ConstraintSet, ConstraintSet]:
    """60 socket rows (two sockets), 30 tracker rows, and both in one set."""
    sockets, _ = simulate_constraints(true, "point", 60, sigma=SOCKET_SIGMA, seed=run)
    tracker = simulate_tracker_rows(true, 30, sigma=TRACKER_SIGMA, T_device_base=frame, seed=1000 + run)
    return sockets, tracker, dataclasses.replace(merge_sets(sockets, tracker), tracker_sigma=TRACKER_SIGMA)


def _scaled(names, values, size: float = 1.0) -> np.ndarray:
    """Angles (rad) times the robot's size (m): every error as a tool displacement."""
    return np.array([v * (size if n.startswith(("alpha", "beta", "theta", "frame_r")) else 1.0)
                     for n, v in zip(names, values, strict=True)])  # fmt: skip


def test_union_identifies_what_each_kind_alone_cannot(ur10, true, frame):
    sockets, tracker, mixed = _sets(true, frame, 0)
    alone_s, dropped_s = kind_identifiable(ur10, sockets)
    alone_t, _ = kind_identifiable(ur10, tracker)
    union, dropped = kind_identifiable(ur10, mixed)
    assert {d.name for d in dropped} == BASE  # the tracker's frame takes the base
    assert len(dropped_s) == 7  # two sockets alone: the base frame and the scale
    assert set(alone_s) < set(union) and set(alone_t) <= set(union)


def test_mixed_recovers_the_truth_better_than_either_alone_at_the_cramer_rao_bound(ur10, true, frame):
    values = dict(zip(true.names, true.values, strict=True))
    errors: dict[str, list[np.ndarray]] = {"sockets": [], "tracker": [], "mixed": []}
    z, bound = [], {}
    for run in range(10):
        sockets, tracker, mixed = _sets(true, frame, run)
        for name, data in (("sockets", sockets), ("tracker", tracker), ("mixed", mixed)):
            result = calibrate_constraints(ur10, data, known_noise=True)
            assert result.success
            robot = [k for k, n in enumerate(result.names) if n in values]
            names = [result.names[k] for k in robot]
            err = result.estimates[robot] - np.array([values[n] for n in names])
            errors[name].append(dict(zip(names, _scaled(names, err), strict=True)))
            bound[name] = dict(zip(names, _scaled(names, result.std[robot]), strict=True))
            if name == "mixed":
                z.append(err / result.std[robot])
    z_all = np.array(z)
    assert np.sqrt(np.mean(z_all**2)) <= 1.2 and np.abs(z_all).max() < 5.0  # at the Cramér-Rao bound
    common = set(errors["sockets"][0]) & set(errors["tracker"][0]) & set(errors["mixed"][0])
    assert len(common) >= 15

    def rms(name: str) -> float:
        return float(np.sqrt(np.mean([[e[c] ** 2 for c in common] for e in errors[name]])))

    assert rms("mixed") < rms("tracker") < rms("sockets")
    for alone in ("sockets", "tracker"):  # the bound itself: no parameter worse with more data
        assert all(bound["mixed"][c] <= bound[alone][c] * (1 + 1e-6) for c in common)


def test_each_kind_gets_its_own_noise_from_the_residuals(ur10, true, frame):
    estimates = []
    for run in range(4):
        _, _, mixed = _sets(true, frame, run)
        stated_wrong = dataclasses.replace(mixed, sigma=1e-4, tracker_sigma=1e-4)  # one σ for both
        result = calibrate_constraints(ur10, stated_wrong)
        kinds = dict(result.kind_sigma)
        estimates.append([kinds["point"], kinds["tracker"]])
        assert any("noise per kind" in line for line in result.summary_lines())
    mean = np.mean(estimates, axis=0)
    np.testing.assert_allclose(mean, [SOCKET_SIGMA, TRACKER_SIGMA], rtol=0.15)


def test_merge_renumbers_points_and_pairs(ur10):
    a, _ = simulate_constraints(ur10, "point", 8, count=2, seed=1)
    b, _ = simulate_constraints(ur10, "distance", 8, seed=2)
    c, _ = simulate_constraints(ur10, "point", 6, count=3, seed=3)
    merged = merge_sets(a, b, c)
    assert merged.n == a.n + b.n + c.n and merged.n_points == 5
    np.testing.assert_array_equal(merged.point[a.n + b.n :], c.point + 2)
    np.testing.assert_array_equal(merged.pairs, b.pairs + a.n)
    back = merged.select(merged.point < 0)
    assert back.n == b.n and back.kinds == ("distance",)
    np.testing.assert_allclose(back.q, b.q)
    with pytest.raises(ValueError, match="joint"):
        merge_sets(a, ConstraintSet(np.zeros((2, 5)), [0, 0], [-1, -1]))


def test_one_file_with_tracker_and_socket_rows(tmp_path, ur10, true, frame):
    _, _, mixed = _sets(true, frame, 0)
    path = tmp_path / "mixed.csv"
    write_constraints(mixed, path)
    back = read_constraints(path, ur10.dof)
    assert back.kinds == ("point", "tracker") and int(back.tracked.sum()) == 30
    result = calibrate_constraints(ur10, back)
    assert result.success and len(result.kind_sigma) == 2
    np.testing.assert_allclose(result.T_device_base[:3, 3], frame[:3, 3], atol=5e-3)


def _write_tracker(path, data: ConstraintSet) -> None:
    rows = ["q1,q2,q3,q4,q5,q6,x,y,z"]
    rows += [",".join(repr(float(v)) for v in [*q, *p]) for q, p in zip(data.q, data.positions, strict=True)]
    path.write_text("\n".join(rows) + "\n")


def test_cli_calibrates_a_tracker_file_with_a_socket_file(tmp_path, true, frame):
    from typer.testing import CliRunner

    from robocal.cli.app import app

    sockets, tracker, _ = _sets(true, frame, 1)
    write_constraints(sockets, tmp_path / "sockets.csv")
    _write_tracker(tmp_path / "tracker.csv", tracker)
    out = tmp_path / "cal"
    args = [
        "calibrate",
        "ur10",
        "--data",
        str(tmp_path / "tracker.csv"),
        "--data",
        str(tmp_path / "sockets.csv"),
    ]
    run = CliRunner().invoke(app, [*args, "-o", str(out)])
    assert run.exit_code == 0, run.output
    doc = json.loads((out / "constraints.json").read_text())
    assert doc["measurements"] == ["point", "tracker"] and doc["success"]
    assert doc["data"].endswith("sockets.csv") and doc["tracker_data"][0]["path"].endswith("tracker.csv")
    unseen = {d["name"] for d in doc["not_identifiable"] if d["reason"] in ("redundant", "no effect")}
    assert unseen == BASE  # the union sees the scale; sockets alone would not
    assert set(doc["noise_per_kind_m"]) == {"point", "tracker"}
    assert "constraint rows alone" in run.output and "tracker rows alone" in run.output
    np.testing.assert_allclose(np.array(doc["T_device_base"])[:3, 3], frame[:3, 3], atol=5e-3)
    report = CliRunner().invoke(app, ["report", str(out), "-o", str(tmp_path / "r.html")])
    assert report.exit_code == 0, report.output


def test_cli_refuses_several_files_without_a_constraint_file(tmp_path, true, frame):
    from typer.testing import CliRunner

    from robocal.cli.app import app

    _, tracker, _ = _sets(true, frame, 2)
    _write_tracker(tmp_path / "a.csv", tracker)
    _write_tracker(tmp_path / "b.csv", tracker)
    args = ["calibrate", "ur10", "--data", str(tmp_path / "a.csv"), "--data", str(tmp_path / "b.csv")]
    run = CliRunner().invoke(app, [*args, "-o", str(tmp_path / "cal")])
    assert run.exit_code != 0 and "constraint file" in run.output and "Traceback" not in run.output
    assert not (tmp_path / "cal" / "constraints.json").exists()


# ---------------------------------------------------------------------- inclinometer planning
@pytest.fixture(scope="module")
def katana():
    from robocal.cli.options import resolve_model

    return resolve_model("katana450")


def _sensors(model):
    from robocal.measure.inclinometer import Inclinometer

    return tuple(Inclinometer.level_at(model, j) for j in model.joint_names)


def test_tilt_planning_beats_a_random_choice_on_the_tilt_jacobian(katana):
    from robocal.identify.tilt_identification import identify_tilt
    from robocal.identify.tilt_poses import select_tilt_poses, tilt_candidates
    from robocal.measure.inclinometer import simulate_readings
    from robocal.measure.poses import random_poses

    sensors = _sensors(katana)
    pool = random_poses(katana, 200, seed=3)
    plan = select_tilt_poses(katana, pool, 12, sensors, index="O1")
    assert plan.q.shape == (12, katana.dof) and tilt_candidates(katana, plan.q, sensors).all()  # all readable
    assert plan.indices["O1"] > plan.baseline["O1"]
    assert "compliance_q1" in plan.not_seen  # a rotation about the vertical: no inclinometer sees it
    random = pool[tilt_candidates(katana, pool, sensors)][:12]
    sigma = {}
    for name, q in (("plan", plan.q), ("random", random)):
        data = simulate_readings(katana, q, sensors, np.random.default_rng(0))
        fit = identify_tilt(katana, data, sensors)
        sigma[name] = dict(zip(fit.names, fit.sigma, strict=True))
    common = set(sigma["plan"]) & set(sigma["random"])
    ratio = np.array([sigma["plan"][n] / sigma["random"][n] for n in common])
    assert np.exp(np.mean(np.log(ratio))) < 1.0  # the Cramér-Rao bound is smaller on the plan's readings


def test_cli_poses_rows_tilt_feeds_the_inclinometer_simulation(tmp_path):
    from typer.testing import CliRunner

    from robocal.cli.app import app

    runner = CliRunner()
    poses = tmp_path / "tilt_poses.csv"
    run = runner.invoke(app, ["poses", "katana450", "--rows", "tilt", "--n", "10", "--pool", "150",
                              "--index", "O3", "-o", str(poses)])  # fmt: skip
    assert run.exit_code == 0, run.output
    assert "O3" in run.output and "not identifiable: compliance_q1" in run.output
    readings = tmp_path / "tilt.csv"
    sim = runner.invoke(app, ["simulate", "katana450", "--device", "inclinometer", "--poses", str(poses),
                              "-o", str(readings), "--seed", "2"])  # fmt: skip
    assert sim.exit_code == 0, sim.output
    fit = runner.invoke(app, ["data", "tilt", str(readings), "katana450"])
    assert fit.exit_code == 0 and "clearance_q2" in fit.output
    small = runner.invoke(app, ["poses", "katana450", "--rows", "tilt", "--n", "50", "--pool", "20",
                                "-o", str(tmp_path / "x.csv")])  # fmt: skip
    assert small.exit_code != 0 and "--pool" in small.output and not (tmp_path / "x.csv").exists()


# ---------------------------------------------------------------------- held-out placements
def test_simulate_placements_share_the_true_robot_and_validate_held_out(tmp_path):
    import re

    from typer.testing import CliRunner

    from robocal.cli.app import app

    runner = CliRunner()
    data = tmp_path / "sockets.csv"
    args = ["simulate", "ur10", "--kind", "point", "--n", "40", "--seed", "4", "--noise", "0.02mm"]
    run = runner.invoke(app, [*args, "--placements", "2", "-o", str(data)])
    assert run.exit_code == 0, run.output
    held_out = tmp_path / "sockets.placement2.csv"
    truth = json.loads((tmp_path / "sockets.csv.truth.json").read_text())
    first, second = truth["placements"]
    assert second["file"] == held_out.name and read_constraints(held_out, 6).n == second["rows"]
    np.testing.assert_allclose(first["point_distances_m"], second["point_distances_m"])  # one tool, moved
    assert np.linalg.norm(np.subtract(first["points_m"], second["points_m"])) > 0.1  # elsewhere
    a, b, d = truth["point_distances_m"][0]
    out = tmp_path / "cal"
    cal = runner.invoke(app, ["calibrate", "ur10", "--data", str(data), "--distance", f"{a},{b}={d * 1e3}mm",
                              "-o", str(out)])  # fmt: skip
    assert cal.exit_code == 0, cal.output
    check = runner.invoke(app, ["validate", str(out), "--data", str(held_out)])
    assert check.exit_code == 0, check.output
    after, before = check.output.split("before calibration")
    spread = [float(x) for x in re.findall(r"RMS spread (\d+\.\d+) mm", after)]
    nominal = [float(x) for x in re.findall(r"RMS spread (\d+\.\d+) mm", before)]
    assert len(spread) == 2 and max(spread) < 0.1 < min(nominal)  # the calibration holds elsewhere
    again = runner.invoke(app, [*args, "--placements", "3", "-o", str(data)])
    assert again.exit_code != 0 and "--force" in again.output
    assert not (tmp_path / "sockets.placement3.csv").exists()  # nothing half-written
