"""Files robocal did not write are never written through, replaced or deleted (issue 38,
items 2 and 4): a lock file planted as a link, a user's ``.NAME.old`` or ``.NAME.v1.staging``,
a user's model or report in the output folder, fleet names that would leave the output
folder, a study file that would open a network connection, and an empty HOME."""

from __future__ import annotations

import json
import os
import re
from pathlib import Path

import pytest

from robocal import outdir
from robocal.folder_lock import FolderBusyError
from robocal.outdir import transaction
from robocal.run_ids import ForeignFileError

OWNED = ("model.yaml", "result.json", "report.html")


def _write_result(target: Path, tag: str = "x") -> str:
    """A result as a calibration writes one: every file stamped with the run id."""
    with transaction(target, OWNED) as st:
        (st.path / "model.yaml").write_text(outdir.run_id_line(st.run_id) + f"tag: {tag}\n")
        (st.path / "result.json").write_text(json.dumps({"run_id": st.run_id, "tag": tag}))
    return st.run_id


# ------------------------------------------------------------------ locks never follow links
@pytest.mark.parametrize("kind", ["symlink", "hardlink"])
def test_a_lock_file_planted_as_a_link_is_refused_and_its_target_untouched(tmp_path, kind):
    victim = tmp_path / "victim.txt"
    victim.write_text("precious\n")
    lock = tmp_path / ".cal.lock"
    (os.symlink if kind == "symlink" else os.link)(victim, lock)
    with pytest.raises(ForeignFileError, match=r"\.cal\.lock"):
        _write_result(tmp_path / "cal")
    assert victim.read_text() == "precious\n"
    assert not (tmp_path / "cal").exists()
    assert os.path.lexists(lock)  # refused, not removed: it is not robocal's


def test_a_dangling_lock_link_creates_nothing_where_it_points(tmp_path):
    lock = tmp_path / ".cal.lock"
    os.symlink(tmp_path / "elsewhere.txt", lock)
    with pytest.raises(ForeignFileError):
        outdir.check_not_busy(tmp_path / "cal")
    with pytest.raises(ForeignFileError):
        _write_result(tmp_path / "cal")
    assert not (tmp_path / "elsewhere.txt").exists()


def test_a_lock_link_stops_every_locking_writer(tmp_path):
    """A set of files (measurements and their truth) takes the same lock."""
    victim = tmp_path / "victim.txt"
    victim.write_text("precious\n")
    os.symlink(victim, tmp_path / ".a.csv.lock")
    with pytest.raises(ForeignFileError):
        outdir.write_together({tmp_path / "a.csv": b"x\n", tmp_path / "b.csv": b"y\n"})
    assert victim.read_text() == "precious\n"
    assert not (tmp_path / "a.csv").exists() and not (tmp_path / "b.csv").exists()


def test_the_calibrate_command_names_a_planted_lock_in_one_line(tmp_path):
    from typer.testing import CliRunner

    from robocal.cli import app

    victim = tmp_path / "victim.txt"
    victim.write_text("precious\n")
    os.symlink(victim, tmp_path / ".cal.lock")
    data = tmp_path / "m.csv"
    data.write_text("q1,q2,q3,q4,q5,q6,x,y,z\n")
    args = ["calibrate", "ur10", "--data", str(data), "--out", str(tmp_path / "cal")]
    result = CliRunner().invoke(app, args)
    assert result.exit_code == 2
    assert "Traceback" not in result.output and ".cal.lock" in result.stderr
    assert victim.read_text() == "precious\n"


def test_a_busy_folder_is_still_reported_as_busy(tmp_path):
    with outdir._lock(tmp_path / "cal", 0.0), pytest.raises(FolderBusyError):
        outdir.check_not_busy(tmp_path / "cal")


# ------------------------------------------------------------------ leftovers: only robocal's
def test_a_users_old_and_staging_folders_are_never_moved_or_deleted(tmp_path):
    user_old = tmp_path / ".cal.old"
    user_old.mkdir()
    (user_old / "keep.txt").write_text("mine")
    user_staging = tmp_path / ".cal.v1.staging"
    user_staging.mkdir()
    (user_staging / "keep.txt").write_text("mine too")
    _write_result(tmp_path / "cal")
    assert (user_old / "keep.txt").read_text() == "mine"
    assert (user_staging / "keep.txt").read_text() == "mine too"
    assert sorted(os.listdir(tmp_path / "cal")) == [outdir.MANIFEST, "model.yaml", "result.json"]


def test_a_link_named_like_a_leftover_is_not_followed(tmp_path):
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    (elsewhere / "keep.txt").write_text("mine")
    os.symlink(elsewhere, tmp_path / ".cal.0123456789ab.staging")
    os.symlink(elsewhere, tmp_path / ".cal.0123456789ab.old")
    _write_result(tmp_path / "cal")
    assert (elsewhere / "keep.txt").read_text() == "mine"
    assert not (tmp_path / "cal" / "keep.txt").exists()


def test_a_killed_writers_leftovers_are_still_cleaned(tmp_path):
    leftover = tmp_path / ".cal.0123456789ab.staging"
    leftover.mkdir()
    (leftover / "model.yaml").write_text("half")
    _write_result(tmp_path / "cal")
    assert not leftover.exists()


# ------------------------------------------------------------------ the user's files in the output folder
def test_a_users_model_in_the_output_folder_is_never_replaced(tmp_path):
    folder = tmp_path / "m"
    folder.mkdir()
    (folder / "model.yaml").write_text("robocal_model: 1\nname: mine\n")
    (folder / "report.html").write_text("<p>my report</p>")
    with pytest.raises(ForeignFileError, match=r"model\.yaml"):
        _write_result(folder)
    assert (folder / "model.yaml").read_text() == "robocal_model: 1\nname: mine\n"
    assert (folder / "report.html").read_text() == "<p>my report</p>"
    assert sorted(os.listdir(tmp_path)) == ["m"]  # no staging folder left


def test_a_users_file_under_an_owned_name_the_result_does_not_write_is_kept(tmp_path):
    folder = tmp_path / "m"
    folder.mkdir()
    (folder / "report.html").write_text("<p>my report</p>")
    _write_result(folder)
    _write_result(folder, "again")  # the earlier result's files are replaced, the user's kept
    assert (folder / "report.html").read_text() == "<p>my report</p>"
    assert json.loads((folder / "result.json").read_text())["tag"] == "again"


def test_files_robocal_wrote_without_a_run_id_are_replaced_by_the_manifest(tmp_path):
    """Files a writer does not stamp (an experiment's plots) are robocal's by the manifest."""
    target = tmp_path / "exp"
    for tag in ("one", "two"):
        with transaction(target, ("plot.txt",)) as st:
            (st.path / "plot.txt").write_text(tag)
    assert (target / "plot.txt").read_text() == "two"


def test_an_output_link_to_no_folder_is_refused(tmp_path):
    victim = tmp_path / "victim.txt"
    victim.write_text("precious\n")
    os.symlink(victim, tmp_path / "cal")
    with pytest.raises(ForeignFileError):
        _write_result(tmp_path / "cal")
    assert os.path.islink(tmp_path / "cal") and victim.read_text() == "precious\n"


def test_the_calibrate_command_refuses_to_replace_its_input_model(tmp_path):
    """``calibrate m/model.yaml --out m --report``: the input model and the user's report stay."""
    import numpy as np
    from typer.testing import CliRunner

    from robocal.cli import app
    from robocal.measure import LaserTracker, VirtualRobot, draw_true_model, simulate
    from robocal.measure.dataset.writer import write_measurements
    from robocal.measure.poses import random_poses
    from robocal.model.catalog import robot
    from robocal.model.files import save_model

    ur10 = robot("ur10")
    folder = tmp_path / "m"
    folder.mkdir()
    save_model(ur10, folder / "model.yaml")
    (folder / "report.html").write_text("<p>my report</p>")
    before = {p.name: p.read_bytes() for p in folder.iterdir()}
    virtual = VirtualRobot(
        ur10, draw_true_model(ur10, seed=1), LaserTracker(p_tool_target=np.array([0, 0, 0.1]))
    )
    write_measurements(simulate(virtual, random_poses(ur10, 30, seed=1), seed=1), tmp_path / "d.csv")
    args = ["calibrate", str(folder / "model.yaml"), "--data", str(tmp_path / "d.csv")]
    result = CliRunner().invoke(app, [*args, "--out", str(folder), "--report", "--residual", "none"])
    assert result.exit_code == 2, result.output
    assert "model.yaml" in result.stderr and "Traceback" not in result.output
    assert {p.name: p.read_bytes() for p in folder.iterdir()} == before
    assert sorted(os.listdir(tmp_path)) == ["d.csv", "m"]


# ------------------------------------------------------------------ Dask: consent and caps
def _study_file(tmp_path: Path, **dask) -> Path:
    import yaml

    doc = {
        "robocal_study": 1,
        "name": "t",
        "robot": "ur10",
        "robots": 2,
        "seed": 3,
        "pose_sets": [{"name": "r30", "kind": "random", "n": 30}],
        "devices": [{"name": "t20", "kind": "laser-tracker", "noise": "0.02mm"}],
        "validation": {"n": 40},
        "dask": dask,
    }
    path = tmp_path / "study.yaml"
    path.write_text(yaml.safe_dump(doc))
    return path


def test_a_study_files_scheduler_opens_no_connection_without_the_command_line(tmp_path):
    import socket

    from typer.testing import CliRunner

    from robocal.cli import app

    with socket.socket() as listener:
        listener.bind(("127.0.0.1", 0))
        listener.listen(1)
        listener.settimeout(0.5)
        port = listener.getsockname()[1]
        config = _study_file(tmp_path, scheduler=f"tcp://127.0.0.1:{port}")
        args = ["study", str(config), "--out", str(tmp_path / "s"), "--no-progress"]
        result = CliRunner().invoke(app, args)
        assert result.exit_code == 2
        assert "--scheduler" in result.stderr and "Traceback" not in result.output
        with pytest.raises(TimeoutError):  # nobody knocked
            listener.accept()
    assert not (tmp_path / "s").exists()  # refused before anything was written


def test_local_workers_are_capped_before_anything_is_written(tmp_path):
    from robocal.study import StudyError, run_study
    from robocal.study.cluster import max_local_workers

    config = _study_file(tmp_path)
    with pytest.raises(StudyError, match=str(max_local_workers())):
        run_study(config, tmp_path / "s", workers=100_000)
    assert not (tmp_path / "s").exists()
    with pytest.raises(StudyError, match="--workers"):
        run_study(config, tmp_path / "s", workers=max_local_workers() + 1)


def test_a_refused_scheduler_port_ends_with_one_clear_error(tmp_path):
    import socket

    from robocal.study import StudyError
    from robocal.study.cluster import executor_for

    with socket.socket() as probe:  # a port nobody listens on
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    with pytest.raises(StudyError, match=f"tcp://127.0.0.1:{port}"):
        executor_for(None, f"tcp://127.0.0.1:{port}")


# ------------------------------------------------------------------ fleets: names inside --out, tables
@pytest.fixture
def one_file_fleet(tmp_path):
    """A folder with one good measurement file (robot0.csv) of a UR10 with a 100 mm tool."""
    import numpy as np

    from robocal.measure import LaserTracker, VirtualRobot, draw_true_model, simulate
    from robocal.measure.dataset.writer import write_measurements
    from robocal.measure.poses import random_poses
    from robocal.model.catalog import robot

    ur10 = robot("ur10")
    folder = tmp_path / "in"
    folder.mkdir()
    virtual = VirtualRobot(
        ur10, draw_true_model(ur10, seed=1), LaserTracker(p_tool_target=np.array([0, 0, 0.1]))
    )
    write_measurements(simulate(virtual, random_poses(ur10, 30, seed=1), seed=1), folder / "robot0.csv")
    return folder


@pytest.mark.parametrize("name", ["...csv", "..csv", ".hidden.csv"])
def test_a_fleet_file_whose_result_folder_would_leave_the_output_is_refused(tmp_path, one_file_fleet, name):
    from robocal.model.catalog import robot
    from robocal.study import StudyError, run_fleet

    (one_file_fleet / name).write_bytes((one_file_fleet / "robot0.csv").read_bytes())
    before = sorted(os.listdir(tmp_path))
    with pytest.raises(StudyError, match=re.escape(name[: -len(".csv")])):
        run_fleet(one_file_fleet, robot("ur10"), tmp_path / "out", pattern="*csv", workers=0)
    assert not (tmp_path / "model.yaml").exists() and not (tmp_path / "result.json").exists()
    assert sorted(os.listdir(tmp_path)) == before  # nothing written, not even the table


def test_a_fleet_result_folder_that_is_a_link_is_refused(tmp_path, one_file_fleet):
    from robocal.model.catalog import robot
    from robocal.study import StudyError, run_fleet

    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    (tmp_path / "out").mkdir()
    os.symlink(elsewhere, tmp_path / "out" / "robot0")
    with pytest.raises(StudyError, match="symbolic link"):
        run_fleet(one_file_fleet, robot("ur10"), tmp_path / "out", workers=0)
    assert os.listdir(elsewhere) == []


def test_fleet_force_never_deletes_a_users_table(tmp_path, one_file_fleet):
    from robocal.model.catalog import robot
    from robocal.study import StudyError, run_fleet

    out = tmp_path / "out"
    out.mkdir()
    (out / "fleet.csv").write_text("my,own,table\n1,2,3\n")
    with pytest.raises(StudyError, match=r"fleet\.csv"):
        run_fleet(one_file_fleet, robot("ur10"), out, workers=0, force=True)
    assert (out / "fleet.csv").read_text() == "my,own,table\n1,2,3\n"


def test_a_fleet_result_folder_holding_a_users_model_gets_an_error_row(tmp_path, one_file_fleet):
    """The file's result is not saved over the user's model; the fleet goes on and says why."""
    from robocal.model.catalog import robot
    from robocal.study import run_fleet

    out = tmp_path / "out"
    (out / "robot0").mkdir(parents=True)
    (out / "robot0" / "model.yaml").write_text("mine\n")
    run = run_fleet(one_file_fleet, robot("ur10"), out, workers=0)
    assert (run.calibrated, run.errors) == (0, 1)
    assert run.rows[0]["status"] == "error" and "model.yaml" in run.rows[0]["message"]
    assert (out / "robot0" / "model.yaml").read_text() == "mine\n"
    assert sorted(os.listdir(out / "robot0")) == ["model.yaml"]


# ------------------------------------------------------------------ studies: the user's files in --out
def test_a_study_never_replaces_a_users_study_yaml_or_summary(tmp_path):
    from robocal.study import StudyError, run_study

    config = _study_file(tmp_path)
    for name, text in (("study.yaml", "robots: 2\nmine: true\n"), ("summary.json", '{"mine": 1}')):
        out = tmp_path / f"out_{name}"
        out.mkdir()
        (out / name).write_text(text)
        for force in (False, True):
            with pytest.raises(StudyError, match=re.escape(name)):
                run_study(config, out, workers=0, force=force)
        assert sorted(os.listdir(out)) == [name] and (out / name).read_text() == text


def test_study_force_never_deletes_a_users_results_table(tmp_path):
    from robocal.study import StudyError, run_study

    config = _study_file(tmp_path)
    out = tmp_path / "out"
    out.mkdir()
    (out / "results.csv").write_text("my,own,table\n")
    with pytest.raises(StudyError, match=r"results\.csv"):
        run_study(config, out, workers=0, force=True)
    assert (out / "results.csv").read_text() == "my,own,table\n"


def test_a_study_resumes_and_restarts_in_its_own_folder(tmp_path):
    """What robocal wrote stays robocal's: the same study resumes; --force starts another over."""
    import yaml

    from robocal.study import run_study

    config = _study_file(tmp_path)
    first = run_study(config, tmp_path / "out", workers=0)
    again = run_study(config, tmp_path / "out", workers=0)
    assert (first.computed, again.resumed, again.computed) == (2, 2, 0)
    other = yaml.safe_load(config.read_text()) | {"seed": 4}
    config.write_text(yaml.safe_dump(other))
    forced = run_study(config, tmp_path / "out", workers=0, force=True)
    assert (forced.computed, forced.resumed) == (2, 0)


# ------------------------------------------------------------------ the demo's default folder
@pytest.mark.parametrize("home", ["", "/", "relative/home", "/no/such/home"])
def test_the_demo_never_writes_to_the_root_without_a_usable_home(tmp_path, monkeypatch, home):
    from typer.testing import CliRunner

    from robocal.cli import app
    from robocal.demo.folder import default_folder

    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("HOME", home)
    with pytest.raises(ValueError, match="--out"):
        default_folder()
    existed = Path("/robocal-demo").exists()
    result = CliRunner().invoke(app, ["demo", "--quick"])
    assert result.exit_code == 2 and "--out" in result.stderr
    assert Path("/robocal-demo").exists() == existed and os.listdir(tmp_path) == []


def test_the_demo_folder_is_in_a_usable_home(tmp_path, monkeypatch):
    from robocal.demo.folder import default_folder

    monkeypatch.setenv("HOME", str(tmp_path))
    assert default_folder() == tmp_path / "robocal-demo"


# ------------------------------------------------------------------ a run's own input in its output folder
def test_an_input_inside_the_output_folder_is_never_dropped_or_replaced(tmp_path):
    """``--data cal/train.csv --out cal --force``: train.csv (robocal's, of an earlier run)
    is this run's input: kept, and a result that would write its own input is refused."""
    owned = ("result.json", "train.csv")
    target = tmp_path / "cal"
    with transaction(target, owned) as st:  # an earlier run wrote train.csv
        (st.path / "train.csv").write_text(outdir.run_id_line(st.run_id) + "q1\n0\n")
        (st.path / "result.json").write_text(json.dumps({"run_id": st.run_id}))
    data = (target / "train.csv").read_text()
    with transaction(target, owned) as st:  # this run read it and writes a result without it
        result = {"run_id": st.run_id, "data_file": str(target / "train.csv")}
        (st.path / "result.json").write_text(json.dumps(result))
    assert (target / "train.csv").read_text() == data
    with pytest.raises(ForeignFileError, match="input"), transaction(target, owned) as st:
        (st.path / "train.csv").write_text("replaced\n")
        (st.path / "result.json").write_text(json.dumps({"run_id": st.run_id, "provenance": result}))
    assert (target / "train.csv").read_text() == data
