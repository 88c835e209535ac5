"""Monte Carlo studies and fleets (robocal.study): the batched engine against rc.calibrate,
resumable tables, crashed tasks and killed workers, the CLI."""

from __future__ import annotations

import csv
import os
import re
import signal
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

import robocal as rc
from robocal import study
from robocal.cli import app
from robocal.identify.batch import calibrate_batch
from robocal.identify.calibrate import initial_frame_and_tool
from robocal.identify.guards import CalibrationGuardError
from robocal.measure import LaserTracker, VirtualRobot, draw_true_model, simulate
from robocal.measure.poses import random_poses
from robocal.study import StudyConfig, StudyError, run_fleet, run_study

TOOL = np.array([0.0, 0.0, 0.109])


@pytest.fixture(scope="module")
def ur10():
    return rc.robot("ur10")


@pytest.fixture(scope="module")
def batch(ur10):
    """Six virtual UR10s measured at the same 50 poses, and two at poses of their own."""
    q = random_poses(ur10, 50, seed=11)
    device = LaserTracker(p_tool_target=TOOL)
    data = []
    for k in range(8):
        robot = VirtualRobot(ur10, draw_true_model(ur10, seed=100 + k), device)
        qk = q if k < 6 else random_poses(ur10, 50, seed=200 + k)
        data.append(simulate(robot, qk, seed=300 + k))
    return data, calibrate_batch(ur10, data, tool_guess=TOOL)


def _assert_same_calibration(fit, ref, q_test):
    """The batched engine's fit equals rc.calibrate's to round-off (1e-10)."""
    assert fit.names == ref.names
    assert len(fit.dropped) == len(ref.dropped)
    for a, b in zip(fit.dropped, ref.dropped, strict=True):  # names, reasons, absorbing parameters, σ
        assert (a.name, a.reason) == (b.name, b.reason)
        assert [n for n, _ in a.absorbed_by] == [n for n, _ in b.absorbed_by]
        np.testing.assert_allclose([c for _, c in a.absorbed_by], [c for _, c in b.absorbed_by], atol=1e-10)
        assert a.residual == pytest.approx(b.residual, abs=1e-10)
        assert (a.sigma is None) == (b.sigma is None)
        # σ of a parameter screened out or pruned as poorly identifiable: from a nearly singular
        # normal matrix (the reason it is dropped), whose round-off it amplifies
        assert a.sigma is None or a.sigma == pytest.approx(b.sigma, rel=1e-6)
    assert fit.success == ref.success and fit.iterations == ref.iterations
    np.testing.assert_allclose(fit.estimates, ref.estimates, rtol=1e-10, atol=1e-12)
    assert np.max(np.abs(fit.estimates - ref.estimates) / ref.std) < 1e-9  # was 1e-4 σ with two engines
    np.testing.assert_allclose(fit.start, ref.nominal, rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(fit.std, ref.std, rtol=1e-10, atol=0)
    np.testing.assert_allclose(fit.covariance, ref.covariance, rtol=1e-10, atol=1e-10 * np.max(ref.std) ** 2)
    for name in ("rms_before", "rms_after", "residual_std", "condition_number"):
        assert getattr(fit, name) == pytest.approx(getattr(ref, name), rel=1e-10, abs=0), name
    # predictions at held-out poses: rc.validate's numbers
    np.testing.assert_allclose(fit.predict(q_test), ref.predict(q_test)[:, :3, 3], rtol=0, atol=1e-12)


def test_batched_engine_matches_rc_calibrate(ur10, batch):
    data, fits = batch
    q_test = random_poses(ur10, 30, seed=5)
    for d, fit in zip(data, fits, strict=True):
        ref = rc.calibrate(ur10, d, tool_guess=TOOL)
        assert fit.success
        _assert_same_calibration(fit, ref, q_test)


def test_batched_start_values_are_rc_calibrates(ur10, batch):
    from robocal.identify.stages import initial_frames_and_tools

    data, _ = batch
    T0 = rc.spatial.homogeneous(p=TOOL)
    T_flange = np.stack([ur10.fk(d.q) for d in data])
    T_frame, T_tool = initial_frames_and_tools(T_flange, np.stack([d.position for d in data]), T_tool=T0)
    for k, d in enumerate(data):
        F, T = initial_frame_and_tool(ur10, d, "position", T0, True, True)
        np.testing.assert_allclose(T_frame[k], F, rtol=0, atol=1e-15)
        np.testing.assert_allclose(T_tool[k], T, rtol=0, atol=1e-15)


def test_batch_rejects_mixed_pose_counts_and_wrong_joints(ur10, batch):
    data, _ = batch
    with pytest.raises(ValueError, match=r"data\[1\] has 49 poses"):
        calibrate_batch(ur10, [data[0], data[1].subset(np.arange(49))])
    with pytest.raises(ValueError, match="joint columns"):
        calibrate_batch(rc.robot("li2016_3dof"), data[:1])
    assert calibrate_batch(ur10, []) == []


# ------------------------------------------------------------------ studies
def _config(**changes) -> StudyConfig:
    base = dict(
        name="t",
        robot="ur10",
        robots=6,
        seed=3,
        tool=(0.0, 0.0, 109.0),
        pose_sets=[{"name": "r30", "kind": "random", "n": 30}, {"name": "r15", "kind": "random", "n": 15}],
        devices=[{"name": "t20", "kind": "laser-tracker", "noise": "0.02mm"}],
        validation={"n": 40},
        chunk=4,
    )
    base.update(changes)
    return StudyConfig.model_validate(base)


def _rows(path: Path) -> list[dict[str, str]]:
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


NUMERIC = ("rms_before_mm", "rms_after_mm", "val_rms_mm", "true_rms_mm", "condition_number")


def test_study_resumes_from_its_table_and_is_deterministic(tmp_path):
    out = tmp_path / "s"
    first = run_study(_config(), out, workers=0, robots=3)
    assert (first.computed, first.resumed, first.errors) == (6, 0, 0)
    second = run_study(_config(), out, workers=0)
    assert (second.computed, second.resumed) == (6, 6)
    again = run_study(_config(), out, workers=0)
    assert again.computed == 0 and again.calibrations_per_second == 0.0
    rows = _rows(out / "results.csv")
    assert len(rows) == 12 and len({r["case"] for r in rows}) == 12
    assert all(r["status"] == "ok" and r["engine"] == "batched" for r in rows)
    # the same rows as a study run in one go, chunked differently
    fresh = _rows(run_study(_config(chunk=5), tmp_path / "fresh", workers=0).out / "results.csv")
    by_case = {r["case"]: r for r in fresh}
    for r in rows:
        for col in NUMERIC:
            assert float(r[col]) == pytest.approx(float(by_case[r["case"]][col]), rel=1e-6), col
    assert (out / "summary.png").stat().st_size > 1000
    groups = {(g["pose_set"], g["device"]): g for g in second.summary["groups"]}
    assert groups["r30", "t20"]["ok"] == 6
    # more poses, better calibration: a sanity check of the numbers
    assert groups["r30", "t20"]["true_rms_mm"]["mean"] < groups["r15", "t20"]["true_rms_mm"]["mean"]


ALL_NUMBERS = (
    "n_poses",
    "n_params",
    "iterations",
    "rms_before_mm",
    "rms_after_mm",
    "residual_std_mm",
    "condition_number",
    "val_n",
    "val_mean_mm",
    "val_rms_mm",
    "val_p95_mm",
    "val_max_mm",
    "true_rms_mm",
    "true_max_mm",
)


def test_study_engines_agree(tmp_path):
    """One engine: the batched rows are rc.calibrate's to 1e-10, and a case the guards
    refuse (6 poses for a UR10 with its device frame and tool) fails in both with the
    same reason."""
    sets = [*_config().pose_sets, {"name": "p6", "kind": "random", "n": 6}]
    a = _rows(run_study(_config(robots=3, pose_sets=sets), tmp_path / "a", workers=0).out / "results.csv")
    b = run_study(_config(robots=3, engine="calibrate", pose_sets=sets), tmp_path / "b", workers=0)
    assert b.engine == "calibrate"
    by_case = {r["case"]: r for r in _rows(b.out / "results.csv")}
    assert len(a) == len(by_case) == 9
    for r in a:
        other = by_case[r["case"]]
        assert r["engine"] == "batched" and other["engine"] == "calibrate"
        if r["pose_set"] == "p6":
            assert r["status"] == other["status"] == "failed"
            assert r["message"] == other["message"] and "measure at least" in r["message"]
            continue
        assert (r["status"], r["dropped"]) == (other["status"], other["dropped"]) == ("ok", other["dropped"])
        for col in ALL_NUMBERS:
            assert float(r[col]) == pytest.approx(float(other[col]), rel=1e-10, abs=0), col


@pytest.mark.parametrize("engine", ["batched", "calibrate"])
def test_too_few_poses_fail_with_the_guards_reason(tmp_path, engine):
    """3 or 6 poses for a UR10 with its device frame and tool: fewer equations than
    identifiable parameters.  Both engines refuse (status failed, the guard's reason),
    not status ok with a residual of 1e-13 mm; failed cases are not recomputed on resume."""
    config = _config(
        robots=2,
        engine=engine,
        pose_sets=[
            {"name": "p3", "kind": "random", "n": 3},
            {"name": "p6", "kind": "random", "n": 6},
            {"name": "p30", "kind": "random", "n": 30},
        ],
    )
    run = run_study(config, tmp_path / "s", workers=0)
    assert run.engine == engine and run.errors == 0
    rows = _rows(tmp_path / "s" / "results.csv")
    for r in rows:
        if r["pose_set"] == "p30":
            assert r["status"] == "ok", r["message"]
            continue
        n = int(r["pose_set"][1:])
        assert r["status"] == "failed" and r["engine"] == engine and r["n_poses"] == str(n)
        assert r["message"].startswith(f"{n} distinct poses give {3 * n} equations for the ")
        assert "measure at least" in r["message"]
        assert r["rms_after_mm"] == r["true_rms_mm"] == ""
    groups = {g["pose_set"]: g for g in run.summary["groups"]}
    assert (groups["p3"]["failed"], groups["p6"]["failed"], groups["p30"]["failed"]) == (2, 2, 0)
    assert groups["p3"]["ok"] == 0 and groups["p30"]["ok"] == 2
    again = run_study(config, tmp_path / "s", workers=0)
    assert again.computed == 0 and again.resumed == 6


def test_rank_deficient_poses_fail_in_the_batched_engine_as_in_rc_calibrate(ur10):
    """Poses that never move the last joint: rc.calibrate refuses them (rank-deficient),
    and so does the batched engine, with the same message; the other robots of the batch
    are calibrated."""
    q = random_poses(ur10, 30, seed=31)
    still = q.copy()
    still[:, 5] = 0.3
    device = LaserTracker(p_tool_target=TOOL)
    robots = [VirtualRobot(ur10, draw_true_model(ur10, seed=600 + k), device) for k in range(2)]
    good, bad = simulate(robots[0], q, seed=1), simulate(robots[1], still, seed=2)
    with pytest.raises(CalibrationGuardError) as refused:
        rc.calibrate(ur10, bad, tool_guess=TOOL)
    fit, failure = calibrate_batch(ur10, [good, bad], tool_guess=TOOL)
    assert isinstance(failure, CalibrationGuardError) and str(failure) == str(refused.value)
    assert "rank-deficient" in str(failure)
    _assert_same_calibration(fit, rc.calibrate(ur10, good, tool_guess=TOOL), q[:5])


def test_study_with_the_learned_residual_runs_rc_calibrate(tmp_path):
    """residual: auto runs the calibrate engine with the CV model choice; virtual robots
    without unmodelled errors keep the physics, so the rows equal the physical ones."""
    physics = _rows(
        run_study(_config(robots=2, engine="calibrate"), tmp_path / "p", workers=0).out / "results.csv"
    )
    run = run_study(_config(robots=2, residual="auto"), tmp_path / "h", workers=0)
    assert run.engine == "calibrate"
    hybrid = {r["case"]: r for r in _rows(run.out / "results.csv")}
    assert all(r["status"] == "ok" for r in hybrid.values())
    for r in physics:
        assert float(hybrid[r["case"]]["true_rms_mm"]) == pytest.approx(float(r["true_rms_mm"]), rel=0.05)
    with pytest.raises(StudyError, match="residual 'none'"):
        run_study(_config(robots=2, residual="auto", engine="batched"), tmp_path / "b", workers=0)


def test_truncated_table_is_repaired_on_resume(tmp_path):
    out = tmp_path / "s"
    run_study(_config(robots=2), out, workers=0)
    path = out / "results.csv"
    text = path.read_text()
    path.write_text(text + text.splitlines()[-1][:25])  # a row cut short by a crash
    run = run_study(_config(robots=3), out, workers=0)
    assert run.computed == 2 and run.resumed == 4
    rows = _rows(path)
    assert len(rows) == 6 and all(r["status"] == "ok" for r in rows)


def test_study_refuses_another_configuration_without_force(tmp_path):
    out = tmp_path / "s"
    run_study(_config(robots=1), out, workers=0)
    with pytest.raises(StudyError, match=r"another configuration.*--force"):
        run_study(_config(robots=1, seed=4), out, workers=0)
    run = run_study(_config(robots=1, seed=4), out, workers=0, force=True)
    assert run.computed == 2 and run.resumed == 0 and len(_rows(out / "results.csv")) == 2


def test_failing_case_reports_its_input_and_is_retried(tmp_path, monkeypatch):
    original = study.tasks._simulate_case

    def broken(chunk, k):
        if k == 1 and chunk.pose_set == "r15":
            raise ValueError("the virtual tracker lost the beam")
        return original(chunk, k)

    monkeypatch.setattr(study.tasks, "_simulate_case", broken)
    out = tmp_path / "s"
    run = run_study(_config(robots=3), out, workers=0)
    assert run.errors == 1
    bad = [r for r in _rows(out / "results.csv") if r["status"] == "error"]
    assert len(bad) == 1
    assert "lost the beam" in bad[0]["message"]
    assert (
        "robot 1" in bad[0]["message"] and "'r15'" in bad[0]["message"] and "[3, 0, 1]" in bad[0]["message"]
    )
    monkeypatch.setattr(study.tasks, "_simulate_case", original)
    again = run_study(_config(robots=3), out, workers=0)
    assert again.computed == 1 and again.errors == 0
    assert (
        study.Table(out / "results.csv", study.RESULT_COLUMNS, "case").rows[bad[0]["case"]]["status"] == "ok"
    )


def test_a_failed_task_becomes_error_rows(tmp_path, monkeypatch):
    def crash(chunk):
        raise MemoryError("worker ran out of memory")

    monkeypatch.setattr(study.run, "run_chunk", crash)  # as run_study submits it
    run = run_study(_config(robots=2), tmp_path / "s", workers=0)
    rows = _rows(tmp_path / "s" / "results.csv")
    assert run.errors == 4 and all(r["status"] == "error" for r in rows)
    assert "task failed: MemoryError" in rows[0]["message"] and "robots 0-1 of pose set" in rows[0]["message"]


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"colour": "red"}, "colour: Extra inputs are not permitted"),
        ({"robots": 0}, "robots: Input should be greater than or equal to 1"),
        ({"pose_sets": [{"name": "a", "n": 5}, {"name": "a", "n": 6}]}, "a used twice"),
        ({"max_std": "0.5 parsec"}, "max_std"),
        ({"robot": "no_such_robot"}, "no_such_robot"),
        ({"devices": [{"name": "d", "kind": "sonar"}]}, "unknown device kind 'sonar'"),
        ({"pose_sets": [{"name": "a", "kind": "random"}]}, r"pose_sets\[0\] \(a\): kind 'random' needs 'n'"),
        ({"engine": "batched", "method": "pinv"}, "engine 'batched' needs method 'lm'"),
    ],
)
def test_bad_study_files_are_rejected_with_the_field(tmp_path, change, message):
    import yaml

    doc = _config().model_dump(mode="json")
    doc.update(change)
    path = tmp_path / "bad.yaml"
    path.write_text(yaml.safe_dump(doc))
    with pytest.raises(StudyError, match=message):
        cfg = study.load_study_config(path)
        run_study(cfg, tmp_path / "out", workers=0)


def test_study_on_a_dask_client(tmp_path):
    """The Dask path (submit, as_completed, the rows written by the client) on an in-process cluster."""
    import logging

    from distributed import Client, LocalCluster

    config = _config(robots=3, chunk=1)
    reference = {
        r["case"]: r for r in _rows(run_study(config, tmp_path / "ref", workers=0).out / "results.csv")
    }
    with (
        LocalCluster(
            n_workers=2, processes=False, dashboard_address=None, silence_logs=logging.ERROR
        ) as cluster,
        Client(cluster) as client,
    ):
        run = run_study(config, tmp_path / "dask", client=client)
    assert run.workers == 2 and run.computed == 6
    rows = _rows(tmp_path / "dask" / "results.csv")
    assert {r["case"] for r in rows} == set(reference)
    for r in rows:
        assert float(r["true_rms_mm"]) == pytest.approx(float(reference[r["case"]]["true_rms_mm"]), rel=1e-9)


@pytest.mark.slow
def test_study_on_dask_survives_a_killed_worker(tmp_path):
    """A worker process killed mid-study: its task is rerun elsewhere, no finished row is lost."""
    import logging

    from distributed import Client, LocalCluster

    config = _config(robots=12, chunk=2)
    reference = {
        r["case"]: r for r in _rows(run_study(config, tmp_path / "ref", workers=0).out / "results.csv")
    }
    with (
        LocalCluster(
            n_workers=2, threads_per_worker=1, dashboard_address=None, silence_logs=logging.ERROR
        ) as cluster,
        Client(cluster) as client,
    ):
        pids = list(client.run(os.getpid).values())
        killed = []

        def progress(done, total):
            if not killed and done >= 4:
                os.kill(pids[0], signal.SIGKILL)
                killed.append(pids[0])

        run = run_study(config, tmp_path / "dask", client=client, progress=progress)
    assert killed and run.workers == 2
    rows = _rows(tmp_path / "dask" / "results.csv")
    assert len(rows) == len(reference) == 24 and {r["case"] for r in rows} == set(reference)
    for r in rows:
        assert r["status"] == "ok", r["message"]
        for col in NUMERIC:
            assert float(r[col]) == pytest.approx(float(reference[r["case"]][col]), rel=1e-9)


# ------------------------------------------------------------------ fleets
@pytest.fixture
def fleet_dir(tmp_path, ur10):
    d = tmp_path / "fleet"
    d.mkdir()
    q = random_poses(ur10, 40, seed=1)
    device = LaserTracker(p_tool_target=TOOL)
    for k in range(3):
        robot = VirtualRobot(ur10, draw_true_model(ur10, seed=k), device)
        data = simulate(robot, q, seed=k)
        if k == 0:
            data = data.with_split(30, seed=0)
        rc.write_measurements(data, d / f"robot{k}.csv")
    (d / "broken.csv").write_text("q1,q2,q3,q4,q5,q6,x,y,z\n0,0,0,0,0,0,1,2\n")
    return d


def test_fleet_calibrates_every_file_and_resumes(fleet_dir, ur10):
    run = run_fleet(fleet_dir, ur10, workers=0, calibrate_options={"tool_guess": TOOL})
    assert (run.calibrated, run.errors, run.resumed) == (3, 1, 0)
    rows = {r["file"]: r for r in run.rows}
    assert rows["robot0.csv"]["status"] == "ok" and float(rows["robot0.csv"]["val_rms_mm"]) < 0.1
    assert rows["robot1.csv"]["val_n"] == ""  # no test rows in that file
    assert rows["broken.csv"]["status"] == "error"
    assert "broken.csv: row 2: has 8 cells but the header has 9" in rows["broken.csv"]["message"]
    result = rc.CalibrationResult.load(fleet_dir / "calibrated" / "robot1")
    assert result.rms_after < 5e-5
    again = run_fleet(fleet_dir, ur10, workers=0, calibrate_options={"tool_guess": TOOL})
    assert (again.calibrated, again.errors, again.resumed) == (0, 1, 3)  # the broken file is retried
    # a changed file is not recalibrated over its previous result without force
    (fleet_dir / "robot2.csv").write_text(
        (fleet_dir / "robot2.csv").read_text().replace("# units", "# note: x\n# units")
    )
    skipped = run_fleet(fleet_dir, ur10, workers=0, calibrate_options={"tool_guess": TOOL})
    assert skipped.skipped == ["robot2.csv"] and skipped.calibrated == 0
    forced = run_fleet(fleet_dir, ur10, workers=0, calibrate_options={"tool_guess": TOOL}, force=True)
    assert forced.calibrated == 3 and not forced.skipped


def test_fleet_of_an_empty_folder_is_an_error(tmp_path, ur10):
    with pytest.raises(StudyError, match="no files match"):
        run_fleet(tmp_path, ur10, workers=0)
    with pytest.raises(StudyError, match="is not a directory"):
        run_fleet(tmp_path / "nope", ur10, workers=0)


# ------------------------------------------------------------------ the commands
LAST_LINE = re.compile(r"^calibrations/s: \d+(\.\d+)?$")


def test_study_command_prints_the_throughput_last(tmp_path):
    import yaml

    cfg = tmp_path / "study.yaml"
    cfg.write_text(yaml.safe_dump(_config(robots=2).model_dump(mode="json")))
    result = CliRunner().invoke(app, ["study", str(cfg), "--out", str(tmp_path / "o"), "--workers", "0"])
    assert result.exit_code == 0, result.output
    assert LAST_LINE.match(result.output.strip().splitlines()[-1])
    result = CliRunner().invoke(app, ["study", str(tmp_path / "missing.yaml"), "--out", str(tmp_path / "o")])
    assert result.exit_code == 2 and "does not exist" in result.output and "Traceback" not in result.output


def test_fleet_command(fleet_dir):
    result = CliRunner().invoke(
        app,
        ["fleet", "ur10", str(fleet_dir), "--workers", "0", "--tool", "0,0,109mm", "--no-progress"],
    )
    assert result.exit_code == 0, result.output
    assert LAST_LINE.match(result.output.strip().splitlines()[-1])
    assert "broken.csv" in result.output and "Traceback" not in result.output


def test_example_study_runs_its_first_robots(tmp_path):
    """examples/study_ur10.yaml: the complete model built from geometry, random and O1-optimal
    pose sets, two tracker noises; its first two robots end to end."""
    config = study.load_study_config(Path(__file__).parents[1] / "examples" / "study_ur10.yaml")
    assert config.robots == 1000 and all(s.n == 50 for s in config.pose_sets)
    assert len(study.study_cases(config)) == 4000
    run = run_study(config, tmp_path / "ex", workers=0, robots=2)
    assert run.computed == 8 and run.errors == 0 and run.engine == "batched"
    rows = _rows(tmp_path / "ex" / "results.csv")
    assert {r["status"] for r in rows} == {"ok"}
    noise = {
        g["device"]: g["true_rms_mm"]["mean"] for g in run.summary["groups"] if g["pose_set"] == "random50"
    }
    assert noise["tracker-20um"] < noise["tracker-50um"]  # more noise, larger error


@pytest.mark.slow
def test_example_study_of_1000_ur10s_on_two_workers(tmp_path):
    config = study.load_study_config(Path(__file__).parents[1] / "examples" / "study_ur10.yaml")
    run = run_study(config, tmp_path / "ur10", workers=2)
    assert run.computed == 4000 and run.errors == 0
    assert all(g["ok"] == 1000 for g in run.summary["groups"])


def test_batched_engine_prunes_like_rc_calibrate_with_noisy_data(ur10):
    """1 mm noise: every σ is large, so the absolute threshold alone would prune
    parameters that rc.calibrate keeps (its threshold is relative to the median σ too)."""
    q = random_poses(ur10, 50, seed=21)
    device = LaserTracker(p_tool_target=TOOL, sigma=1e-3)
    data = [
        simulate(VirtualRobot(ur10, draw_true_model(ur10, seed=400 + k), device), q, seed=500 + k)
        for k in range(3)
    ]
    q_test = random_poses(ur10, 30, seed=5)
    for d, fit in zip(data, calibrate_batch(ur10, data, tool_guess=TOOL), strict=True):
        _assert_same_calibration(fit, rc.calibrate(ur10, d, tool_guess=TOOL), q_test)
