"""Calibrate once, re-register later: ``robocal register`` and ``validate --refit-frame``'s
honest scoring (issue 34 item 4) on virtual robots whose device was moved."""

import csv
import dataclasses
import json
import math
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

import robocal as rc
from robocal import spatial
from robocal.cli import app
from robocal.identify.register import fit_frame, frozen_robot, score_registration
from robocal.measure import LaserTracker, VirtualRobot, draw_true_model, random_poses, simulate

runner = CliRunner()
TOOL = np.array([0.0, 0.02, 0.1])
FIRST = spatial.homogeneous(spatial.rotvec_to_matrix([0.0, 0.0, 0.5]), [2.0, 0.3, 0.1])
MOVED = spatial.homogeneous(spatial.rotvec_to_matrix([0.02, -0.01, 2.0]), [-1.5, 1.2, 0.3])


def _cell(name: str, tool=TOOL):
    """A calibrated virtual robot (device at FIRST) and the same robot seen from MOVED."""
    model = rc.calibration_model(rc.robot(name), "position")
    true = draw_true_model(model, length=1e-3, angle=np.radians(0.1), seed=3)
    robot = VirtualRobot(model, true, LaserTracker(T_device_base=FIRST, p_tool_target=TOOL))
    result = rc.calibrate(model, simulate(robot, random_poses(model, 150, seed=1), seed=1), tool_guess=TOOL)
    moved = VirtualRobot(model, true, LaserTracker(T_device_base=MOVED, p_tool_target=tool))
    return model, result, moved


@pytest.fixture(scope="module")
def ur10():
    return _cell("ur10")


@pytest.fixture(scope="module")
def saved(ur10, tmp_path_factory):
    """The UR10's calibration saved, and 30 + 200 poses of the moved device as CSV (m)."""
    model, result, moved = ur10
    folder = tmp_path_factory.mktemp("register")
    result.save(folder / "cal")
    rc.write_measurements(simulate(moved, random_poses(model, 30, seed=50), seed=50), folder / "few.csv")
    rc.write_measurements(simulate(moved, random_poses(model, 200, seed=51), seed=51), folder / "rest.csv")
    return folder


def _best_frame(model, result, robot, tool=False):
    """The frame the frozen robot fits best to the moved device without noise (3,000 poses):
    what a registration should recover (the calibration's own base offset included)."""
    q = random_poses(model, 3000, seed=999)
    p = robot.device.predict(robot.T_base_tool(q)).position
    return fit_frame(frozen_robot(result, rc.Measurements(q=q, position=p)), p, tool).T_device_base


@pytest.mark.parametrize("name", ["ur10", "kr16"])
def test_the_frame_is_recovered_within_its_predicted_sigma(name, ur10):
    model, result, moved = ur10 if name == "ur10" else _cell(name)
    best = _best_frame(model, result, moved)
    chi2, ratios = [], []
    for seed in range(20):
        data = simulate(moved, random_poses(model, 30, seed=100 + seed), seed=100 + seed)
        robot = frozen_robot(result, data)
        fit = fit_frame(robot, data.position)
        miss = np.linalg.inv(fit.T_device_base) @ best  # the correction that would take the fit to the best
        dx = np.r_[miss[:3, 3], spatial.zyx_angles(miss[:3, :3])]
        chi2.append(dx @ np.linalg.solve(fit.scaled_covariance, dx) / 6)
        ratios.append(score_registration(robot, data.position).ratio)
    # the normalised error's spread ~1: the predicted σ is the frame's real uncertainty
    assert 0.7 < math.sqrt(np.mean(chi2)) < 1.4
    # the K-fold's expected RMS error matches the one it measured on rows it did not fit
    assert 0.8 < np.mean(ratios) < 1.25


def test_the_tool_point_is_refitted_with_the_frame(ur10):
    model, result, _ = ur10
    changed = TOOL + [0.0, 0.003, -0.002]  # another probe on the same robot
    moved = VirtualRobot(model, _cell_true(model), LaserTracker(T_device_base=MOVED, p_tool_target=changed))
    data = simulate(moved, random_poses(model, 30, seed=7), seed=7)
    robot = frozen_robot(result, data)
    frame_only = score_registration(robot, data.position)
    with_tool = score_registration(robot, data.position, tool=True)
    fit = fit_frame(robot, data.position, tool=True)
    # the tool's change explained: mm of error left without it, the calibration's accuracy with it
    assert with_tool.rms < 0.3 * frame_only.rms
    identified_before = result.model.step("tcp_y").value
    assert abs(fit.tool[1] - identified_before - 0.003) < 5 * math.sqrt(fit.scaled_covariance[7, 7]) + 5e-5
    assert 0.6 < with_tool.ratio < 1.6


def _cell_true(model):
    return draw_true_model(model, length=1e-3, angle=np.radians(0.1), seed=3)


def test_register_writes_a_calibration_that_compensates(ur10, saved, tmp_path):
    model, _, moved = ur10
    new = tmp_path / "new"
    args = ["register", str(saved / "cal"), "--data", str(saved / "few.csv"), "--out", str(new), "--json"]
    out = runner.invoke(app, args)
    assert out.exit_code == 0, out.output
    summary = json.loads(out.output)
    held_out, in_sample = summary["held_out"], summary["in_sample"]
    assert held_out["scoring"] == "5-fold" and held_out["n"] == 30
    assert held_out["rms_mm"] > in_sample["rms_mm"]  # scored on rows it did not fit: larger
    assert 0.6 < held_out["expected_over_measured"] < 1.6
    written = json.loads((new / "result.json").read_text())
    source = json.loads((saved / "cal" / "result.json").read_text())
    inherited = written["registered_from"]
    assert inherited["run_id"] == source["run_id"] and inherited["rows"] == 30
    assert inherited["refitted"] == ["device frame"]
    assert written["coverage"] == source["coverage"] and written["run_id"] != source["run_id"]
    # the registered folder predicts the moved device's held-out poses as the score said
    stats = json.loads(
        runner.invoke(app, ["validate", str(new), "--data", str(saved / "rest.csv"), "--json"]).output
    )
    assert stats["frame"] == "calibrated" and stats["rms_mm"] < 2 * held_out["expected_rms_mm"]
    # targets in the moved device's frame, compensated and executed on the virtual robot
    q = random_poses(model, 12, seed=8)
    q = q[np.linalg.svd(model.joint_jacobian(q), compute_uv=False)[:, -1] > 0.05][:6]
    targets = moved.device.predict(moved.T_base_tool(q)).position
    _write_targets(targets, tmp_path / "targets.csv")
    args = ["compensate", str(new), "--targets", str(tmp_path / "targets.csv"), "--frame", "measurement"]
    out = runner.invoke(app, [*args, "--length-unit", "mm", "-o", str(tmp_path / "q.csv")])
    assert out.exit_code == 0, out.output
    with open(tmp_path / "q.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    q_cmd = np.array([[float(r[f"q{j}"]) for j in range(1, 7)] for r in rows])
    reached = moved.device.predict(moved.T_base_tool(q_cmd)).position
    # the calibration's accuracy and the frame's: closed loop on the moved device
    assert np.linalg.norm(reached - targets, axis=1).max() < 0.3e-3
    # the source calibration's frame puts these targets metres away: refused, not sent
    args[1] = str(saved / "cal")
    assert runner.invoke(app, [*args, "--length-unit", "mm", "-o", str(tmp_path / "old.csv")]).exit_code != 0


def _write_targets(p, path):
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["name", "x", "y", "z"])
        for i, row in enumerate(p * 1e3):
            w.writerow([f"P{i + 1}", *(f"{v:.6f}" for v in row)])


def _rows(src, dst, rows):
    """The header and the given data rows of CSV ``src`` written to ``dst``."""
    lines = [line for line in src.read_text().splitlines() if not line.startswith("#")]
    dst.write_text("\n".join([lines[0], *(lines[1 + i] for i in rows)]) + "\n")
    return dst


def test_register_refuses_by_name(ur10, saved, tmp_path):
    cal, few = saved / "cal", saved / "few.csv"

    def refused(args, what):
        out = runner.invoke(app, ["register", *map(str, args)])
        text = " ".join(out.output.split())
        assert out.exit_code == 2 and text.startswith("error: ") and "Traceback" not in text, out.output
        assert what in text, text
        return text

    new = tmp_path / "new"
    refused([cal, "--data", _rows(few, tmp_path / "three.csv", range(3)), "--out", new], "at least 4")
    refused(
        [cal, "--data", _rows(few, tmp_path / "five.csv", range(5)), "--out", new, "--tool"], "at least 6"
    )
    same = tmp_path / "same.csv"  # one pose measured eight times
    model, _, moved = ur10
    rc.write_measurements(simulate(moved, np.repeat(random_poses(model, 1, seed=3), 8, axis=0), seed=2), same)
    refused([cal, "--data", same, "--out", new], "degenerate")
    turned = np.repeat(random_poses(model, 1, seed=3), 8, axis=0)
    turned[:, 0] = np.linspace(-1.0, 1.0, 8)  # only the base joint turns: one tool tilt, its length unseen
    rc.write_measurements(simulate(moved, turned, seed=2), tmp_path / "turned.csv")
    refused([cal, "--data", tmp_path / "turned.csv", "--out", new, "--tool"], "degenerate")
    refused([cal, "--data", few, "--out", cal], "calibration folder itself")
    foreign = tmp_path / "notes"
    foreign.mkdir()
    (foreign / "notes.txt").write_text("mine")
    refused([cal, "--data", few, "--out", foreign], "not a robocal calibration")
    refused([cal, "--data", few, "--out", new, "--holdout", "0.95"], "--holdout")
    three_joints = tmp_path / "3dof.csv"
    three_joints.write_text("q1,q2,q3,x,y,z\n" + "\n".join(f"0.{i},0.2,0.3,1,{i},2" for i in range(8)) + "\n")
    refused([cal, "--data", three_joints, "--out", new], "q4")
    assert not new.exists() and (foreign / "notes.txt").read_text() == "mine"
    # a result is replaced only with --force
    assert runner.invoke(app, ["register", str(cal), "--data", str(few), "--out", str(new)]).exit_code == 0
    refused([cal, "--data", few, "--out", new], "--force")


def test_validate_refit_frame_is_scored_on_rows_it_did_not_fit(saved):
    args = ["validate", str(saved / "cal"), "--data", str(saved / "few.csv"), "--refit-frame", "--json"]
    stats = json.loads(runner.invoke(app, args).output)
    assert stats["frame"] == "refit" and stats["scoring"] == "5-fold"
    assert stats["rms_mm"] > stats["in_sample"]["rms_mm"]
    assert 0.6 < stats["expected_rms_mm"] / stats["rms_mm"] < 1.6


REAL = (
    Path(__file__).resolve().parents[2] / "shared" / "data" / "ur10_laser_tracker" / "measurements_grid.csv"
)
COLUMNS = (
    "q1=shoulder_pan_joint,q2=shoulder_lift_joint,q3=elbow_joint,q4=wrist_1_joint,q5=wrist_2_joint,"
    "q6=wrist_3_joint,x=measurement_x,y=measurement_y,z=measurement_z"
)


def _real_days(tmp_path):
    """Series A split by day: the first four days and the last (one file each)."""
    header, *lines = REAL.read_text().splitlines()
    last = [line for line in lines if line.startswith("20200718")]
    first = [line for line in lines if not line.startswith("20200718")]
    paths = tmp_path / "first.csv", tmp_path / "last.csv"
    for path, rows in zip(paths, (first, last), strict=True):
        path.write_text("\n".join([header, *rows]) + "\n")
    reader = dict(length_unit="mm", sep=";", decimal=",", orientation="none", columns=COLUMNS)
    return [rc.read_measurements(p, **reader) for p in paths]


@pytest.mark.slow
@pytest.mark.skipif(
    not REAL.is_file(), reason="the real UR10 data (../shared/data/ur10_laser_tracker) is absent"
)
def test_real_ur10_calibrated_on_the_first_days_registered_on_the_last(tmp_path):
    """Series A: calibrated on 300 poses of the first four days (default model choice),
    re-registered on 20 / 50 poses of the last day, scored on the rest of that day."""
    first, last = _real_days(tmp_path)
    train = first.subset(np.random.default_rng(0).permutation(first.n)[:300])
    sigma = np.full((train.n, 3), 0.03e-3)  # the tracker's noise, as --noise 0.03mm
    model = rc.calibration_model(rc.robot("ur10"), "position")
    train = dataclasses.replace(train, sigma=sigma)
    result = rc.calibrate(model, train, tool_guess=[0, 0, 0.109], residual="auto")  # the CLI's default
    last = dataclasses.replace(last, sigma=np.full((last.n, 3), 0.03e-3))
    for m in (20, 50):
        for seed in range(3):
            order = np.random.default_rng(seed).permutation(last.n)
            few, rest = last.subset(order[:m]), last.subset(order[m:])
            robot = frozen_robot(result, few)
            score = score_registration(robot, few.position)
            fit = fit_frame(robot, few.position)
            held = frozen_robot(result, rest)
            e = np.linalg.norm(fit.predict(held) - rest.position, axis=1)
            rms, expected = np.sqrt(np.mean(e**2)), np.sqrt(np.mean(fit.expected_ms(held)))
            print(
                f"{m} poses, seed {seed}: rest mean {e.mean() * 1e3:.3f} RMS {rms * 1e3:.3f} "
                f"p95 {np.percentile(e, 95) * 1e3:.3f} max {e.max() * 1e3:.3f} mm, "
                f"expected {expected * 1e3:.3f} (ratio {expected / rms:.2f}); K-fold RMS "
                f"{score.rms * 1e3:.3f} expected {score.expected_rms * 1e3:.3f} (ratio {score.ratio:.2f})"
            )
            assert e.mean() < 0.2e-3
            assert 0.8 < expected / rms < 1.3 and 0.7 < score.ratio < 1.5


def test_written_files_names_only_the_files_in_the_folder(tmp_path):
    """The "wrote" line lists what is there, sidecars included, and nothing that is not."""
    from robocal.cli.reading import written_files

    (tmp_path / "model.yaml").write_text("x")
    (tmp_path / "result.json").write_text("{}")
    (tmp_path / "residuals.npz").write_bytes(b"")
    line = written_files(tmp_path)
    assert line.startswith(str(tmp_path))
    assert "residuals.npz" in line and "model.yaml" in line
    assert "report.html" not in line and "measurement_model.yaml" not in line
