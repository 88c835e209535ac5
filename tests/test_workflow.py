"""The one use case "calibrate a file into a folder" (robocal.workflow.calibrate_file): the
command line, the GUI's runs and the fleets go through it and save the same result."""

from __future__ import annotations

import dataclasses
import hashlib
import json
import queue
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

import robocal as rc
import robocal.workflow as workflow
from robocal.apps.gui import jobs
from robocal.cli import app
from robocal.measure.dataset.writer import write_measurements
from robocal.measure.measurements import Measurements
from robocal.model.files import save_model

runner = CliRunner()
TOOL_M = (0.001, -0.002, 0.109)
TRACKER = rc.spatial.homogeneous(rc.spatial.rotvec_to_matrix([0.1, 0.2, -2.0]), [1.5, 2.0, -0.2])


@pytest.fixture(scope="module")
def inputs(tmp_path_factory):
    """A UR10 (its complete position model, as a model file) with 0.3 mm / 0.03° errors
    measured at a 109 mm probe by a tracker: 60 poses in m, no noise columns."""
    from robocal.measure.true_model import draw_true_model

    model = rc.calibration_model("ur10", "position")
    true = draw_true_model(model, length=3e-4, angle=np.radians(0.03), seed=2)
    rng = np.random.default_rng(3)
    q = rng.uniform(-np.pi, np.pi, (60, 6))
    T = true.fk(q)
    p = T[:, :3, :3] @ np.array(TOOL_M) + T[:, :3, 3]
    y = p @ TRACKER[:3, :3].T + TRACKER[:3, 3] + rng.normal(scale=1e-5, size=p.shape)
    folder = tmp_path_factory.mktemp("inputs")
    data = write_measurements(Measurements(q=q, position=y), folder / "meas.csv")
    model_file = save_model(model, folder / "ur10_complete.yaml")
    return data, model_file


def _cli(data: Path, model_file: Path, out: Path, *more: str):
    args = ["calibrate", str(model_file), "--data", str(data), "--train-n", "40", "--seed", "4"]
    args += ["--tool", "1,-2,109mm", "--noise", "0.01mm", "--residual", "none", "--out", str(out), *more]
    return runner.invoke(app, args)


def _job(csv: Path, model_file: Path, out: Path, **changes) -> jobs.CalibrationJob:
    options = dict(train_n=40, seed=4, tool_mm=(1.0, -2.0, 109.0), noise_mm=0.01, residual="none")
    job = jobs.CalibrationJob(csv, jobs.read_options(), model_file, out, **options)
    return dataclasses.replace(job, **changes)


def _gui(job: jobs.CalibrationJob) -> list[tuple]:
    """The GUI's run in this process (the page starts it in a child): its reports, in order."""
    job.out.mkdir(parents=True, exist_ok=True)
    reports: queue.Queue = queue.Queue()
    jobs._run(job, reports)
    return [reports.get_nowait() for _ in range(reports.qsize())]


def test_cli_and_gui_save_the_same_calibration_with_its_provenance(inputs, tmp_path):
    data, model_file = inputs
    cli = _cli(data, model_file, tmp_path / "cli")
    assert cli.exit_code == 0, cli.output
    reports = _gui(_job(data, model_file, tmp_path / "gui"))
    assert reports[-1][0] == "done", reports
    a = json.loads((tmp_path / "cli" / "result.json").read_text())
    b = json.loads((tmp_path / "gui" / "result.json").read_text())
    for key in ("n", "rms_before_mm", "rms_after_mm", "condition_number", "iterations"):
        assert a[key] == pytest.approx(b[key], rel=1e-12, abs=1e-15), key
    assert np.allclose(a["covariance"], b["covariance"], rtol=1e-10, atol=0.0)
    assert a["validation"].keys() == b["validation"].keys()
    for key, value in a["validation"].items():  # numbers and lists of numbers (per axis), or words
        other = b["validation"][key]
        assert value == other if isinstance(value, str) else np.allclose(value, other, rtol=1e-12), key
    assert a["validation"]["n"] == 20  # 60 rows, 40 calibrate
    assert a["measured_tool"] == b["measured_tool"]
    assert a["fit_to_noise"]["ratio"] == pytest.approx(b["fit_to_noise"]["ratio"], rel=1e-12)
    for saved in (a, b):  # the GUI's result records where its data came from, as the CLI's
        provenance = saved["provenance"]
        assert provenance["data_sha256"] == hashlib.sha256(data.read_bytes()).hexdigest()
        assert provenance["train_n"] == 40 and provenance["seed"] == 4
        assert provenance["noise_m"] == pytest.approx(1e-5)
    cal_a = rc.CalibrationResult.load(tmp_path / "cli")
    cal_b = rc.CalibrationResult.load(tmp_path / "gui")
    assert np.array_equal(cal_a.estimates, cal_b.estimates)
    for name in ("train.csv", "test.csv", "errors.json", "report.html"):  # what the page shows
        assert (tmp_path / "gui" / name).is_file(), name


def test_cli_gui_and_fleet_go_through_calibrate_file(inputs, tmp_path, monkeypatch):
    data, model_file = inputs
    seen: list[workflow.CalibrateRequest] = []
    real = workflow.calibrate_file

    def spy(request: workflow.CalibrateRequest) -> workflow.SavedRun:
        seen.append(request)
        return real(request)

    monkeypatch.setattr(workflow, "calibrate_file", spy)
    assert _cli(data, model_file, tmp_path / "cli").exit_code == 0
    assert _gui(_job(data, model_file, tmp_path / "gui"))[-1][0] == "done"
    fleet = tmp_path / "fleet"
    fleet.mkdir()
    (fleet / "robot1.csv").write_bytes(data.read_bytes())
    run = rc.study.run_fleet(
        fleet, rc.load_model(model_file), workers=0, calibrate_options={"tool_guess": TOOL_M}
    )
    assert run.calibrated == 1
    assert [r.data.name for r in seen] == ["meas.csv", "meas.csv", "robot1.csv"]
    assert seen[0].fit == seen[1].fit  # the same settings from the option and the control
    saved = rc.CalibrationResult.load(fleet / "calibrated" / "robot1")
    assert saved.provenance is not None and saved.provenance.data_file == str(
        (fleet / "robot1.csv").resolve()
    )


def test_progress_reports_the_stages_in_order(inputs, tmp_path):
    data, model_file = inputs
    stages: list[tuple[str, float]] = []
    notes: list[tuple[str, str]] = []
    request = workflow.CalibrateRequest(
        data, rc.load_model(model_file), tmp_path / "out", fit=workflow.FitOptions(tool_guess_m=TOOL_M),
        train_n=40, report=True, progress=lambda s, f: stages.append((s, f)),
        notify=lambda kind, text: notes.append((kind, text)),
    )  # fmt: skip
    run = workflow.calibrate_file(request)
    # each stage once, in order (the calibrate stage reports the engine's share too)
    assert list(dict.fromkeys(s for s, _ in stages)) == ["read", "calibrate", "validate", "save", "report"]
    fractions = [f for _, f in stages]
    assert fractions == sorted(fractions) and fractions[0] >= 0.0 and fractions[-1] < 1.0
    assert [kind for kind, _ in notes] == ["model"]
    assert run.folder == tmp_path / "out" and (run.folder / "report.html").is_file()
    assert run.validation is not None and run.validation.n == 20 == run.test.n
    assert run.result.provenance == run.provenance


def _error_lines(output: str) -> list[str]:
    return [line for line in output.splitlines() if line.startswith("error:")]


def test_bad_input_is_refused_once_by_name_and_nothing_is_written(inputs, tmp_path):
    data, model_file = inputs
    broken = tmp_path / "broken.csv"
    broken.write_text("q1,q2,q3,q4,q5,q6,x,y,z\n0,0,0,0,0,0,1,2,3\n0,0,zero,0,0,0,1,2,3\n", encoding="utf-8")
    cases = {  # what is wrong: (CLI arguments, GUI job changes, a word each front end names it by)
        "train_n": (["--train-n", "60"], {"train_n": 60}, ("--train-n", "calibration poses")),
        "noise": (["--noise", "2000mm"], {"noise_mm": 2000.0}, ("--noise", "device noise")),
        "file": ([], {"data": broken}, ("broken.csv", "broken.csv")),  # the CLI reads broken.csv instead
    }
    for what, (args, changes, (cli_word, gui_word)) in cases.items():
        out = tmp_path / f"cli_{what}"
        result = _cli(broken if what == "file" else data, model_file, out, *args)
        assert result.exit_code == 2, (what, result.output)
        errors = _error_lines(result.output)
        assert len(errors) == 1 and cli_word in errors[0], (what, result.output)
        assert "Traceback" not in result.output
        assert not (out / "result.json").exists()
        job = _job(data, model_file, tmp_path / f"gui_{what}", **changes)
        reports = _gui(job)
        failures = [r for r in reports if r[0] in ("error", "trace")]
        assert len(failures) == 1 and failures[0][0] == "error", (what, reports)
        assert gui_word in failures[0][1] and str(tmp_path) not in failures[0][1], (what, failures)
        assert not (job.out / "result.json").exists()


def test_request_errors_name_the_field(inputs, tmp_path):
    data, model_file = inputs
    model = rc.load_model(model_file)
    (tmp_path / "taken").mkdir()
    (tmp_path / "taken" / "result.json").write_text("{}")
    for request, field in (
        (workflow.CalibrateRequest(tmp_path / "none.csv", model, tmp_path / "a"), "data"),
        (workflow.CalibrateRequest(tmp_path, model, tmp_path / "a"), "data"),
        (workflow.CalibrateRequest(data, model, tmp_path / "taken"), "out"),
        (workflow.CalibrateRequest(data, model, tmp_path / "a", noise_m=-1.0), "noise_m"),
        (workflow.CalibrateRequest(data, model, tmp_path / "a", train_n=0), "train_n"),
    ):
        with pytest.raises(workflow.CalibrateFileError) as caught:
            workflow.calibrate_file(request)
        assert caught.value.field == field and "\n" not in str(caught.value)
    assert not (tmp_path / "a").exists()
