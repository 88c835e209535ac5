"""Result folders as transactions (robocal.outdir): a writer killed at every step, a full
disk, two writers at once: the folder always holds one complete result, never a mix."""

from __future__ import annotations

import contextlib
import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest
from typer.testing import CliRunner

from robocal import outdir
from robocal.folder_lock import FolderBusyError
from robocal.outdir import transaction
from robocal.run_ids import FolderMixedError, check_consistent, read_run_id

OWNED = ("a.yaml", "b.yaml", "result.json", "old_only.txt")

#: a writer that loads robocal/outdir.py alone (no robocal import: fast), writes a result
#: tagged argv[2] into argv[1] (argv[3] times, waiting for the lock)
WRITER = textwrap.dedent(
    f"""
    import importlib.util, sys
    spec = importlib.util.spec_from_file_location("outdir", {str(Path(outdir.__file__))!r})
    outdir = importlib.util.module_from_spec(spec)
    sys.modules["outdir"] = outdir
    spec.loader.exec_module(outdir)
    target, tag, times = sys.argv[1], sys.argv[2], int(sys.argv[3])
    for k in range(times):
        with outdir.transaction(target, {OWNED!r}, wait_s=30) as st:
            for name in ("a.yaml", "b.yaml"):
                (st.path / name).write_text(outdir.run_id_line(st.run_id) + "tag: " + tag + "\\n")
            (st.path / "result.json").write_text('{{"run_id": "%s", "tag": "%s"}}' % (st.run_id, tag))
            if tag == "old":
                (st.path / "old_only.txt").write_text("x")
    """
)


def _write(target: Path, tag: str, times: int = 1, **env: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-c", WRITER, str(target), tag, str(times)],
        env={**os.environ, **env},
        capture_output=True,
        text=True,
        timeout=120,
    )


def _state(target: Path) -> str:
    """'old' or 'new...' when the folder holds exactly one complete result (asserted)."""
    names = sorted(os.listdir(target))
    tag = json.loads((target / "result.json").read_text())["tag"]
    written = ["a.yaml", "b.yaml", "result.json"] + (["old_only.txt"] if tag == "old" else [])
    assert names == sorted([*written, "notes.txt", outdir.MANIFEST]), names
    # the manifest lists the files robocal wrote (with their run id), not the user's notes
    assert outdir.robocal_names(target, names) == {*written, outdir.MANIFEST}
    check_consistent(target, ("a.yaml", "b.yaml"))
    assert read_run_id(target / "a.yaml") is not None
    for name in ("a.yaml", "b.yaml"):
        assert (target / name).read_text().endswith(f"tag: {tag}\n")
    assert (target / "notes.txt").read_text() == "mine"  # a file the writer does not own is kept
    return tag


def _write_here(target: Path, tag: str) -> None:
    """What WRITER does, in this process."""
    with transaction(target, OWNED) as st:
        for name in ("a.yaml", "b.yaml"):
            (st.path / name).write_text(outdir.run_id_line(st.run_id) + f"tag: {tag}\n")
        (st.path / "result.json").write_text(json.dumps({"run_id": st.run_id, "tag": tag}))
        if tag == "old":
            (st.path / "old_only.txt").write_text("x")


@pytest.fixture
def old(tmp_path) -> Path:
    target = tmp_path / "res"
    _write_here(target, "old")
    (target / "notes.txt").write_text("mine")
    return target


@pytest.mark.parametrize(
    ("step", "exchange"),
    [(s, True) for s in outdir.STEPS if s != "parked"] + [(s, False) for s in outdir.STEPS],
)
def test_a_writer_killed_at_any_step_leaves_one_complete_result(old, step, exchange):
    env = {"ROBOCAL_TEST_KILL_AT": step} | ({} if exchange else {"ROBOCAL_TEST_NO_EXCHANGE": "1"})
    done = _write(old, "new", **env)
    assert done.returncode == -9, done.stderr  # killed where asked
    outdir.restore(old)  # what a reader does first (puts back a result parked mid-swap)
    before_swap = outdir.STEPS.index(step) < outdir.STEPS.index("swapped")
    assert _state(old) == ("old" if before_swap else "new")
    # the next writer cleans what the killed one left
    _write_here(old, "next")
    assert _state(old) == "next"
    assert sorted(os.listdir(old.parent)) == ["res"]


def test_two_writers_at_once_leave_one_complete_result(old):
    procs = [
        subprocess.Popen(
            [sys.executable, "-c", WRITER, str(old), tag, "8"], stderr=subprocess.PIPE, text=True
        )
        for tag in ("w1", "w2")
    ]
    seen = set()
    while any(p.poll() is None for p in procs):
        # a reader racing the swap may see files of two runs: it says so, never uses them
        with contextlib.suppress(FileNotFoundError, FolderMixedError, AssertionError, json.JSONDecodeError):
            seen.add(_state(old))
    for p in procs:
        assert p.wait() == 0, p.stderr.read()
    assert _state(old) in ("w1", "w2")
    assert sorted(os.listdir(old.parent)) == ["res"]


def test_a_second_writer_stops_with_a_clear_message(tmp_path):
    target = tmp_path / "res"
    with (
        outdir._lock(target.resolve(), 0.0),
        pytest.raises(FolderBusyError, match=rf"{target} is being written by another robocal process \(pid"),
        transaction(target, OWNED),
    ):
        pass
    assert not target.exists()


def test_the_calibrate_command_refuses_a_folder_being_written(tmp_path):
    import numpy as np

    from robocal.cli import app
    from robocal.measure import LaserTracker, VirtualRobot, draw_true_model, simulate
    from robocal.measure.dataset.writer import write_measurements
    from robocal.measure.poses import random_poses
    from robocal.model.catalog import robot

    ur10 = robot("ur10")
    virtual = VirtualRobot(
        ur10, draw_true_model(ur10, seed=1), LaserTracker(p_tool_target=np.array([0, 0, 0.1]))
    )
    write_measurements(simulate(virtual, random_poses(ur10, 20, seed=1), seed=1), tmp_path / "m.csv")
    out = tmp_path / "cal"
    args = [
        "calibrate",
        "ur10",
        "--data",
        str(tmp_path / "m.csv"),
        "--out",
        str(out),
        "--residual",
        "none",
    ]
    with outdir._lock(out, 0.0):
        result = CliRunner().invoke(app, args)
    assert result.exit_code == 2
    assert result.stderr.startswith(
        f"error: {out} is being written by another robocal process (pid {os.getpid()})"
    )
    assert not out.exists() and sorted(os.listdir(tmp_path)) == ["m.csv"]


def test_an_exception_in_the_block_changes_nothing(old):
    with pytest.raises(OSError, match="disk full"), transaction(old, OWNED) as st:
        (st.path / "a.yaml").write_text("half")
        raise OSError(28, "disk full")
    assert _state(old) == "old"
    assert sorted(os.listdir(old.parent)) == ["res"]


def test_stale_files_of_the_earlier_result_are_dropped(old):
    _write_here(old, "new")
    assert not (old / "old_only.txt").exists() and _state(old) == "new"


def test_the_working_directory_is_written_in_place(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "notes.txt").write_text("mine")
    (tmp_path / "old_only.txt").write_text("stale")
    with transaction(tmp_path, OWNED) as st:
        (st.path / "a.yaml").write_text(outdir.run_id_line(st.run_id))
        (st.path / "b.yaml").write_text(outdir.run_id_line(st.run_id))
        (st.path / "result.json").write_text(json.dumps({"run_id": st.run_id, "tag": "x"}))
    # old_only.txt has an owned name but robocal did not write it: kept (never a user's file deleted)
    assert sorted(os.listdir(tmp_path)) == [
        outdir.MANIFEST,
        "a.yaml",
        "b.yaml",
        "notes.txt",
        "old_only.txt",
        "result.json",
    ]
    check_consistent(tmp_path, ("a.yaml", "b.yaml"))


def test_a_mixed_folder_is_named_file_by_file(old):
    (old / "b.yaml").write_text(outdir.run_id_line("ab" * 16))
    with pytest.raises(FolderMixedError, match=r"but b\.yaml \(run abab"):
        check_consistent(old, ("a.yaml", "b.yaml"))


def test_a_folder_with_sub_folders_is_written_in_place_and_kept(tmp_path):
    home = tmp_path / "home"
    (home / "projects").mkdir(parents=True)
    (home / "projects" / "big.bin").write_bytes(b"x" * 1000)
    (home / "old_only.txt").write_text("stale")
    inode = home.stat().st_ino
    with transaction(home, OWNED) as st:
        (st.path / "a.yaml").write_text(outdir.run_id_line(st.run_id))
        (st.path / "result.json").write_text(json.dumps({"run_id": st.run_id}))
    assert home.stat().st_ino == inode  # not renamed, nothing copied
    assert sorted(os.listdir(home)) == [outdir.MANIFEST, "a.yaml", "old_only.txt", "projects", "result.json"]
    assert (home / "projects" / "big.bin").stat().st_size == 1000


def test_a_killed_single_file_writer_leaves_nothing_the_next_one_keeps(tmp_path):
    from robocal.outdir import atomic_write_text

    target = tmp_path / "poses.csv"
    killed = subprocess.Popen([sys.executable, "-c", "pass"])
    killed.wait()  # a process id that no longer runs
    (tmp_path / f".poses.csv.{killed.pid}.abc123.tmp").write_text("half")
    (tmp_path / f".poses.csv.{os.getppid()}.def456.tmp").write_text("a live writer's")
    atomic_write_text(target, "q1\n0\n")
    assert sorted(os.listdir(tmp_path)) == [f".poses.csv.{os.getppid()}.def456.tmp", "poses.csv"]
