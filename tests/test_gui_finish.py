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
import urllib.request
from pathlib import Path

import numpy as np
import pytest

import robocal as rc
from robocal.apps.gui.jobs import (
    CalibrationJob,
    JobRunner,
    JobState,
    RunInfo,
    _apply,
    read_options,
    request_of,
)
from robocal.identify.streaming_calibrate import Streaming
from robocal.measure.measurements import Measurements
from robocal.workflow import CalibrateRequest, FitOptions, calibrate_file
from tests.test_gui import _radio, browser, gui_url  # noqa: F401 (fixtures)

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


def test_the_run_list_shows_a_failed_runs_message_as_text():
    from robocal.apps.gui.runs_page import _run_table

    info = RunInfo("r1", "s", "bad.csv", "ur10", 0.0, "error", 1.0, "bad.csv: row 2 <b>&amp;</b>")
    table = _run_table([info], "other", None)
    cell = table.children[1].children[0].children[3]
    # a plain string child: React writes it as text (escaped), never as markup
    assert cell.children == "failed: bad.csv: row 2 <b>&amp;</b>"


@pytest.fixture(scope="module")
def two_files(tmp_path_factory):
    """A two-socket file and a tracker file of one true UR10 (m and rad), written in this
    process as ``robocal simulate --kind point --also-tracker`` writes them (two CLI processes
    cost ~5 s of start-up on a loaded machine)."""
    from robocal.measure.constraints.data import write_constraints
    from robocal.measure.constraints.sim import simulate_constraints, simulate_tracker_rows
    from robocal.measure.true_model import draw_true_model

    where = tmp_path_factory.mktemp("mixed")
    true = draw_true_model(rc.calibration_model("ur10"), length=5e-4, angle=np.radians(0.05), seed=1)
    sockets, _ = simulate_constraints(true, "point", 60, count=2, seed=1)
    track, sock = where / "track.csv", where / "sock.csv"
    write_constraints(sockets, sock)
    write_constraints(simulate_tracker_rows(true, 60, sigma=1e-5, seed=2), track)
    return sock, track


def test_a_socket_file_and_a_tracker_file_calibrate_together(browser, gui_url, two_files):  # noqa: F811
    """The page's second file joins the first in one fit, as ``--data a --data b``: the saved
    constraints.json names the tracker file and each kind's noise."""
    sock, track = two_files
    context = browser.new_context(viewport={"width": 1024, "height": 900})
    pg = context.new_page()
    try:
        pg.goto(gui_url)
        pg.get_by_text("Calibration", exact=True).click()
        pg.locator("#upload-csv input[type=file]").set_input_files(str(sock))
        pg.locator("#upload-more input[type=file]").set_input_files(str(track))
        pg.locator("#more-list", has_text="track.csv").wait_for(timeout=30_000)
        _radio(pg, "cal-model", "ur10")
        pg.locator("#con-fieldset").wait_for(state="visible", timeout=60_000)
        pg.click("#cal-run")
        pg.locator("#constraint-figures").wait_for(timeout=240_000)
        recorded = pg.locator("#cal-report a", has_text="constraints.json").get_attribute("href")
        with urllib.request.urlopen(gui_url.rstrip("/") + recorded, timeout=30) as r:
            doc = json.loads(r.read())
        assert [Path(t["path"]).name for t in doc["tracker_data"]] == ["track.csv"]
        assert set(doc["noise_per_kind_m"]) >= {"tracker"}
        assert "tracker rows alone" in pg.locator("#cal-results").inner_text()
    finally:
        context.close()
