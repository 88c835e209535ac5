"""Multi-file outputs written all or none (issue 17): simulations, filtered KRL programs,
study summaries and the report stamped with its result's run id."""

import errno
import os
import sys
from pathlib import Path

import numpy as np
import pytest

import robocal as rc
from robocal import outdir
from robocal.measure.dataset.read import read_measurements
from robocal.measure.dataset.writer import write_measurements
from robocal.measure.devices import LaserTracker
from robocal.measure.simulate import VirtualRobot, load_truth, save_simulation, simulate
from robocal.measure.true_model import draw_true_model

SIM_FILES = ("meas.csv", "meas.truth.yaml", "meas.true_model.yaml", "meas.nominal_model.yaml")


def _snapshot(folder: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted(folder.iterdir()) if p.is_file()}


def _disk_full(*args, **kwargs):
    raise OSError(errno.ENOSPC, "No space left on device")


def _fail_replace_onto(monkeypatch, name: str) -> None:
    """Make the rename onto a file called ``name`` fail with a full disk."""
    real = os.replace

    def replace(src, dst, *args, **kwargs):
        if Path(dst).name == name:
            raise OSError(errno.ENOSPC, "No space left on device", str(dst))
        return real(src, dst, *args, **kwargs)

    monkeypatch.setattr(os, "replace", replace)


# ------------------------------------------------------------------ the helper
def test_write_together_writes_all_or_keeps_the_earlier_files(tmp_path, monkeypatch):
    a, b = tmp_path / "p.src", tmp_path / "p.dat"
    outdir.write_together({a: b"new src", b: b"new dat"})
    assert a.read_bytes() == b"new src" and b.read_bytes() == b"new dat"
    before = _snapshot(tmp_path)
    _fail_replace_onto(monkeypatch, "p.dat")  # the second rename fails: the first is undone
    with pytest.raises(OSError) as info:
        outdir.write_together({a: b"newer src", b: b"newer dat"})
    assert info.value.errno == errno.ENOSPC
    assert _snapshot(tmp_path) == before  # no temporaries, no backups, no mix
    monkeypatch.undo()
    c = tmp_path / "fresh" / "q.src"
    _fail_replace_onto(monkeypatch, "q.dat")
    with pytest.raises(OSError):
        outdir.write_together({c: b"x", c.with_suffix(".dat"): b"y"})
    assert list((tmp_path / "fresh").iterdir()) == []  # nothing, not half of it


# ------------------------------------------------------------------ simulate
@pytest.fixture(scope="module")
def sim():
    ur10 = rc.robot("ur10")
    dev = LaserTracker(p_tool_target=[0.0, 0.0, 0.1], sigma=15e-6)
    q = np.random.default_rng(1).uniform(-2, 2, (12, 6))
    robots = [VirtualRobot(ur10, draw_true_model(ur10, seed=s), dev) for s in (1, 2)]
    return [(r, simulate(r, q, seed=3)) for r in robots]


def test_simulation_files_carry_one_run_id(tmp_path, sim):
    robot, data = sim[0]
    save_simulation(robot, data, tmp_path / "meas.csv", seed=3)
    assert sorted(_snapshot(tmp_path)) == sorted(SIM_FILES)  # no temporaries or lock left
    ids = {outdir.read_run_id(tmp_path / name) for name in SIM_FILES}
    assert len(ids) == 1 and None not in ids
    assert load_truth(tmp_path / "meas.csv").true == robot.true
    # measurements read from a simulation and written again do not claim its run id
    write_measurements(read_measurements(tmp_path / "meas.csv"), tmp_path / "copy.csv")
    assert outdir.read_run_id(tmp_path / "copy.csv") is None


@pytest.mark.parametrize("fail", ["write-csv", "rename-truth", "rename-csv"])
def test_failed_simulation_leaves_the_earlier_one(tmp_path, sim, monkeypatch, fail):
    (robot1, data1), (robot2, data2) = sim
    save_simulation(robot1, data1, tmp_path / "meas.csv", seed=3)
    before = _snapshot(tmp_path)
    if fail == "write-csv":
        monkeypatch.setattr(sys.modules["robocal.measure.simulate"], "write_measurements", _disk_full)
    else:
        _fail_replace_onto(monkeypatch, "meas.truth.yaml" if fail == "rename-truth" else "meas.csv")
    with pytest.raises(OSError):
        save_simulation(robot2, data2, tmp_path / "meas.csv", seed=3)
    monkeypatch.undo()
    assert _snapshot(tmp_path) == before
    assert load_truth(tmp_path / "meas.csv").true == robot1.true


def test_failed_first_simulation_leaves_nothing(tmp_path, sim, monkeypatch):
    robot, data = sim[0]
    _fail_replace_onto(monkeypatch, "meas.truth.yaml")
    with pytest.raises(OSError):
        save_simulation(robot, data, tmp_path / "meas.csv", seed=3)
    assert list(tmp_path.iterdir()) == []


def test_load_truth_refuses_measurements_of_another_simulation(tmp_path, sim):
    (robot1, data1), (robot2, data2) = sim
    save_simulation(robot1, data1, tmp_path / "a" / "meas.csv", seed=3)
    save_simulation(robot2, data2, tmp_path / "b" / "meas.csv", seed=3)
    (tmp_path / "a" / "meas.csv").write_bytes((tmp_path / "b" / "meas.csv").read_bytes())
    with pytest.raises(outdir.FolderMixedError, match=r"meas\.csv \(run [0-9a-f]+\).*different simulations"):
        load_truth(tmp_path / "a" / "meas.csv")


# ------------------------------------------------------------------ filter (KRL .src + .dat)
EXAMPLES = Path(__file__).resolve().parents[1] / "examples" / "programs"


def _krl_program(folder: Path) -> Path:
    folder.mkdir()
    for name in ("pick.src", "pick.dat", "$config.dat"):
        (folder / name).write_bytes((EXAMPLES / name).read_bytes())
    return folder / "pick.src"


@pytest.mark.parametrize("fail", ["write-dat", "rename-dat", "rename-src"])
def test_filtered_krl_program_is_written_both_or_neither(tmp_path, monkeypatch, fail):
    from robocal.compensate.programs.filter_file import filter_program_file

    kr16 = rc.robot("kr16")
    program = _krl_program(tmp_path / "in")
    out = tmp_path / "out" / "pick.src"
    out.parent.mkdir()
    out.write_text("; an earlier program\n")
    out.with_suffix(".dat").write_text("; its earlier data\n")
    before = _snapshot(out.parent)
    if fail == "write-dat":
        real = outdir.atomic_write_bytes

        def write(path, data):
            if ".pick.dat." in Path(path).name:
                raise OSError(errno.ENOSPC, "No space left on device")
            return real(path, data)

        monkeypatch.setattr(outdir, "atomic_write_bytes", write)
    else:
        _fail_replace_onto(monkeypatch, "pick.dat" if fail == "rename-dat" else "pick.src")
    with pytest.raises(OSError):
        filter_program_file(program, kr16, out)
    monkeypatch.undo()
    assert _snapshot(out.parent) == before
    filter_program_file(program, kr16, out)  # and then it works, the pair stamped with one run id
    from robocal.compensate.programs.krl import krl_run_id

    written = {n: b.decode("latin-1") for n, b in _snapshot(out.parent).items()}
    assert sorted(written) == ["pick.dat", "pick.src"]
    run_ids = {krl_run_id(text) for text in written.values()}
    assert len(run_ids) == 1 and None not in run_ids
    for name, text in written.items():  # the same program as the example, but for the stamp
        stamp = f";robocal run: {run_ids.pop() if run_ids else krl_run_id(text)}"
        lines = [ln for ln in text.splitlines() if not ln.startswith(";robocal run: ")]
        assert lines == (EXAMPLES / name).read_bytes().decode("latin-1").splitlines(), name
        assert stamp in text


def test_failed_first_filter_leaves_neither_file(tmp_path, monkeypatch):
    from robocal.compensate.programs.filter_file import filter_program_file

    program = _krl_program(tmp_path / "in")
    out = tmp_path / "out" / "pick.src"
    _fail_replace_onto(monkeypatch, "pick.dat")
    with pytest.raises(OSError):
        filter_program_file(program, rc.robot("kr16"), out)
    assert list(out.parent.iterdir()) == []


# ------------------------------------------------------------------ study summaries
def _study_config(robots: int):
    from robocal.study import StudyConfig

    return StudyConfig.model_validate(
        dict(
            name="t",
            robot="ur10",
            robots=robots,
            seed=3,
            tool=(0.0, 0.0, 109.0),
            pose_sets=[{"name": "r30", "kind": "random", "n": 30}],
            devices=[{"name": "t20", "kind": "laser-tracker", "noise": "0.02mm"}],
            validation={"n": 20},
            chunk=4,
        )
    )


def test_study_summary_and_plot_are_written_together(tmp_path, monkeypatch):
    import json

    from PIL import Image

    from robocal.study import StudyError, read_study_summary, run_study

    out = tmp_path / "s"
    first = run_study(_study_config(2), out, workers=0)
    summary = json.loads((out / "summary.json").read_text())
    assert summary["run_id"] == first.summary["run_id"] and summary["groups"][0]["cases"] == 2
    assert Image.open(out / "summary.png").info["Description"] == f"robocal run: {summary['run_id']}"
    before = {n: (out / n).read_bytes() for n in ("summary.json", "summary.png")}
    _fail_replace_onto(monkeypatch, "summary.png")  # a full disk between the two files
    with pytest.raises(OSError):
        run_study(_study_config(3), out, workers=0)
    monkeypatch.undo()
    assert {n: (out / n).read_bytes() for n in ("summary.json", "summary.png")} == before
    assert not [p.name for p in out.iterdir() if p.name.endswith(".tmp")]
    third = run_study(_study_config(3), out, workers=0)  # resumes, and now writes both
    summary = json.loads((out / "summary.json").read_text())
    assert third.resumed == 3 and summary["groups"][0]["cases"] == 3
    assert Image.open(out / "summary.png").info["Description"] == f"robocal run: {summary['run_id']}"
    assert read_study_summary(out) == summary and outdir.read_run_id(out / "summary.png") == summary["run_id"]
    (out / "summary.png").write_bytes(before["summary.png"])  # the plot of the earlier run: refused
    with pytest.raises(StudyError, match=r"summary\.json is run [0-9a-f]+ but .*summary\.png is run"):
        read_study_summary(out)


# ------------------------------------------------------------------ the report carries its result's run id
def test_report_carries_the_run_id_and_a_foreign_report_is_refused(tmp_path):
    from robocal.evaluate.report import write_report
    from robocal.identify.result import CalibrationResult

    ur10 = rc.robot("ur10")
    dev = LaserTracker(p_tool_target=[0.0, 0.0, 0.1], sigma=15e-6)
    q = np.random.default_rng(5).uniform(-2, 2, (40, 6))
    data = simulate(VirtualRobot(ur10, draw_true_model(ur10, seed=7), dev), q, seed=8)
    result = rc.calibrate(ur10, data)

    def with_report(stage: Path) -> None:  # as `robocal calibrate --report` does
        run_id = outdir.read_run_id(stage / "result.json")
        write_report(result, stage / "report.html", data=data, run_id=run_id)

    for name in ("a", "b"):
        result.save(tmp_path / name, also=with_report)
    run_a = outdir.read_run_id(tmp_path / "a" / "result.json")
    assert run_a and outdir.read_run_id(tmp_path / "a" / "report.html") == run_a
    assert f'<meta name="robocal-run" content="{run_a}">' in (tmp_path / "a" / "report.html").read_text()
    CalibrationResult.load(tmp_path / "a")  # consistent
    # a report written from a result folder takes that folder's run id
    write_report(tmp_path / "a", tmp_path / "elsewhere.html")
    assert outdir.read_run_id(tmp_path / "elsewhere.html") == run_a
    # b's report beside a's result: refused, naming the report
    (tmp_path / "a" / "report.html").write_bytes((tmp_path / "b" / "report.html").read_bytes())
    with pytest.raises(outdir.FolderMixedError, match=r"report\.html \(run [0-9a-f]+\)"):
        CalibrationResult.load(tmp_path / "a")
    with pytest.raises(ValueError, match="not a run id"):
        outdir.run_id_meta('"><script>')
    # the library's way, as the GUI does: save, then write the report from the object (or
    # from the result loaded again): it belongs to the saved files
    result = result.save(tmp_path / "c")  # the result as saved: it carries the files' run id
    write_report(result, tmp_path / "c" / "report.html", data=data)
    loaded = CalibrationResult.load(tmp_path / "c")
    write_report(loaded, tmp_path / "c" / "report.html", data=data)
    CalibrationResult.load(tmp_path / "c")
    # a report of another result written into the folder is still refused
    write_report(CalibrationResult.load(tmp_path / "b"), tmp_path / "c" / "report.html", data=data)
    with pytest.raises(outdir.FolderMixedError, match=r"report\.html"):
        CalibrationResult.load(tmp_path / "c")


def test_simulation_killed_between_its_renames_is_refused_then_replaced(tmp_path, sim):
    import subprocess
    import textwrap

    (robot1, data1), _ = sim
    save_simulation(robot1, data1, tmp_path / "meas.csv", seed=3)
    script = textwrap.dedent(
        f"""
        import numpy as np, robocal as rc
        from robocal.measure.devices import LaserTracker
        from robocal.measure.simulate import VirtualRobot, draw_true_model, save_simulation, simulate
        ur10 = rc.robot("ur10")
        robot = VirtualRobot(ur10, draw_true_model(ur10, seed=9), LaserTracker(sigma=15e-6))
        q = np.random.default_rng(1).uniform(-2, 2, (12, 6))
        save_simulation(robot, simulate(robot, q, seed=3), {str(tmp_path / "meas.csv")!r}, seed=3)
        """
    )
    env = dict(os.environ, ROBOCAL_TEST_KILL_AT="set-renaming")
    proc = subprocess.run([sys.executable, "-c", script], env=env, capture_output=True, timeout=120)
    assert proc.returncode == -9, proc.stderr.decode()
    assert any(p.name.endswith(".tmp") for p in tmp_path.iterdir())  # what the killed writer left
    with pytest.raises(outdir.FolderMixedError, match=r"meas\.true_model\.yaml"):
        load_truth(tmp_path / "meas.csv")  # a new true model beside the earlier truth: refused
    save_simulation(robot1, data1, tmp_path / "meas.csv", seed=3)  # the next writer cleans up
    assert sorted(_snapshot(tmp_path)) == sorted(SIM_FILES)
    assert load_truth(tmp_path / "meas.csv").true == robot1.true
