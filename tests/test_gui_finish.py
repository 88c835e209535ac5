"""Issue 36's last items: the engine's LM passes reach the GUI, failed runs keep their message.

- A streamed fit (above the streaming threshold, lowered here) calls ``iteration(evaluations,
  rms)`` after each pass of its LM; the result is the callback-free run's (to 1e-10); the use
  case forwards it; the GUI's job turns it into the stage's text.
- A failed run's message is written in its record: a second server lists it as
  ``failed: <message>`` (escaped, no server path) and shows it when it is opened.
"""

from __future__ import annotations

import itertools
import json
import queue as queue_module
import time

import numpy as np

import robocal as rc
from robocal.apps.gui.jobs import CalibrationJob, JobRunner, JobState, _apply, read_options, request_of
from robocal.identify.streaming_calibrate import Streaming
from robocal.measure.measurements import Measurements
from robocal.workflow import CalibrateRequest, FitOptions, calibrate_file

STREAM = Streaming(threshold=1000, subsample=900, chunk=700)  # several chunks, a real subsample
PROBE = np.array([0.0, 0.0, 0.1])


def _tracker_data(n: int, seed: int = 1) -> tuple[rc.Model, Measurements]:
    """UR10 poses in its limits, positions of a true robot ±1 mm / ±0.05° off, 20 µm noise."""
    model = rc.calibration_model("ur10")
    true = rc.measure.draw_true_model(model, length=1e-3, angle=np.radians(0.05), seed=seed)
    rng = np.random.default_rng(seed + 1)
    lim = np.clip(model.joint_limits, -np.pi, np.pi)
    q = rng.uniform(lim[:, 0], lim[:, 1], (n, model.dof))
    T = true.fk(q)
    position = T[:, :3, :3] @ PROBE + T[:, :3, 3] + rng.normal(0, 20e-6, (n, 3))
    return model, Measurements(q=q, position=position)


def test_the_streamed_lm_reports_each_pass_and_changes_nothing():
    model, data = _tracker_data(1500)
    seen: list[tuple[int, float]] = []
    plain = rc.calibrate(model, data, tool_guess=PROBE, streaming=STREAM)
    watched = rc.calibrate(
        model, data, tool_guess=PROBE, streaming=STREAM, iteration=lambda k, r: seen.append((k, r))
    )
    assert watched.diagnostics.streaming is not None
    np.testing.assert_allclose(watched.estimates, plain.estimates, rtol=0, atol=1e-10)
    assert seen, "the streamed LM made no report"
    evaluations = [k for k, _ in seen]
    assert evaluations == list(range(2, 2 + len(seen)))  # one report per pass after the first
    rms = [r for _, r in seen]
    assert all(b <= a for a, b in itertools.pairwise(rms))  # the best point's RMS never rises
    assert 5e-6 < rms[-1] < 1e-4  # the 20 µm noise's RMS per axis, in metres
    dense: list[tuple[int, float]] = []
    rc.calibrate(model, data, tool_guess=PROBE, streaming=Streaming(threshold=None), iteration=dense.append)
    assert dense == []  # the dense fit (milliseconds) does not call it


def test_the_use_case_forwards_the_passes(tmp_path):
    model, data = _tracker_data(1200, seed=3)
    csv = tmp_path / "many.csv"
    rc.write_measurements(data, csv)
    seen: list[tuple[int, float]] = []
    fit = FitOptions(tool_guess_m=tuple(PROBE), more={"streaming": STREAM})
    request = CalibrateRequest(csv, model, None, fit=fit, iteration=lambda k, r: seen.append((k, r)))
    run = calibrate_file(request)
    assert run.result.diagnostics.streaming is not None and len(seen) >= 1


def test_the_gui_job_shows_the_pass_in_the_stage_text(tmp_path):
    q: queue_module.Queue = queue_module.Queue()
    model_file = tmp_path / "ur10.yaml"
    rc.save_model(rc.calibration_model("ur10"), model_file)
    request = request_of(CalibrationJob(tmp_path / "a.csv", read_options(), model_file, tmp_path / "out"), q)
    request.iteration(3, 0.000153)
    kind, *payload = q.get_nowait()
    state = JobState(stage="calibrate", text="calibrating", status="running")
    _apply(state, kind, payload)
    assert "3" in state.text and "0.1530 mm" in state.text


def test_a_failed_runs_message_outlives_the_runner(tmp_path):
    """The record keeps the message (no server path); a new runner's state and list carry it."""
    workdir = tmp_path / "work"
    bad = workdir / "uploads" / "bad.csv"
    bad.parent.mkdir(parents=True)
    bad.write_text("q1,q2\n1,2\n")
    model_file = workdir / "ur10.yaml"
    rc.save_model(rc.calibration_model("ur10"), model_file)
    runner = JobRunner(workdir / "runs")
    job = CalibrationJob(bad, read_options(), model_file, workdir / "runs" / "r1", train_n=None)
    runner.start(job, "r1", "s", "ur10 <b>")
    state = runner.state("r1")
    for _ in range(600):  # a hang guard (the child process reads and refuses the file)
        state = runner.state("r1")
        if state is not None and not state.active:
            break
        time.sleep(0.1)
    assert state is not None and state.status == "error" and "bad.csv" in (state.error or ""), state
    record = json.loads((workdir / "runs" / "r1.run.json").read_text())
    assert record["error"] and str(workdir) not in record["error"]
    again = JobRunner(workdir / "runs")
    info = next(i for i in again.runs_list() if i.run_id == "r1")
    assert info.status == "error" and info.error == record["error"]
    reopened = again.state("r1")
    assert reopened is not None and reopened.error == record["error"]
