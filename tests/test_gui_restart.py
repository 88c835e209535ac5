"""``robocal gui --workdir DIR``: runs survive a server restart, and the run's stages reach the page.

The server is started with a work dir, a run is calibrated in Chromium and the server is
stopped with SIGTERM; a second server on the same work dir lists the run, opens its result
and serves its report.  A run that was cut off (its record still says running, as after a
kill) is listed as interrupted, never as running.
"""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

from robocal.apps.gui.jobs import STAGES, CalibrationJob, JobRunner, read_options
from tests.test_gui import _free_port, _need_browser, _radio, browser  # noqa: F401 (fixtures)
from tests.test_gui_runs import sim_csv  # noqa: F401 (fixture)


def _serve(port: int, workdir: Path, log: Path) -> subprocess.Popen:
    """``robocal gui --workdir`` on ``port``, once it answers."""
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1")
    cmd = [sys.executable, "-m", "robocal.cli", "gui", "--port", str(port), "--no-browser"]
    with log.open("a") as out:
        proc = subprocess.Popen(
            [*cmd, "--workdir", str(workdir)], stdout=out, stderr=subprocess.STDOUT, env=env
        )
    deadline = time.monotonic() + 60  # a hang guard
    while time.monotonic() < deadline:
        with socket.socket() as s:
            if s.connect_ex(("127.0.0.1", port)) == 0:
                return proc
        if proc.poll() is not None:
            pytest.fail(f"robocal gui exited: {log.read_text()}")
        time.sleep(0.2)
    proc.kill()
    pytest.fail(f"robocal gui did not start: {log.read_text()}")


def _stop(proc: subprocess.Popen, log: Path) -> None:
    proc.send_signal(signal.SIGTERM)
    try:
        code = proc.wait(timeout=30)
    except subprocess.TimeoutExpired:
        proc.kill()
        pytest.fail("robocal gui did not stop on SIGTERM")
    assert code == 0, log.read_text()


def test_a_run_survives_a_restart_and_a_cut_off_run_is_interrupted(browser, sim_csv, tmp_path):  # noqa: F811
    workdir, log = tmp_path / "work", tmp_path / "server.log"
    port = _free_port()
    server = _serve(port, workdir, log)
    context = browser.new_context(viewport={"width": 1400, "height": 1000})
    try:
        pg = context.new_page()
        pg.goto(f"http://127.0.0.1:{port}/")
        pg.get_by_text("Calibration", exact=True).click()
        pg.locator("#upload-csv input[type=file]").set_input_files(str(sim_csv))
        _radio(pg, "cal-model", "ur10")
        pg.locator("#csv-summary").wait_for(timeout=60_000)
        pg.fill("#cal-train-n", "40")
        pg.click("#cal-run")
        pg.locator("#held-out").wait_for(timeout=240_000)
        # every stage of the use case arrives in the page, in the use case's order
        shown = pg.locator("#cal-stages .stage")
        keys = [shown.nth(i).get_attribute("data-stage") for i in range(shown.count())]
        assert keys == [key for key, _, _ in STAGES]
        run_id = pg.locator("#run-table tbody tr").first.get_attribute("data-run")
    finally:
        context.close()
        _stop(server, log)
    assert (workdir / "runs" / run_id / "result.json").is_file()  # kept: the work dir is the user's
    # a run whose server was killed (its record still says running)
    cut = dict(
        json.loads((workdir / "runs" / f"{run_id}.run.json").read_text()), run_id="cutoff1", status="running"
    )
    (workdir / "runs" / "cutoff1.run.json").write_text(json.dumps(cut))

    port = _free_port()
    server = _serve(port, workdir, log)
    context = browser.new_context(viewport={"width": 1400, "height": 1000})
    try:
        pg = context.new_page()
        pg.goto(f"http://127.0.0.1:{port}/")
        pg.get_by_text("Calibration", exact=True).click()
        table = pg.locator("#run-table")
        table.wait_for(timeout=30_000)
        assert "done" in table.locator(f"tr[data-run='{run_id}']").inner_text()
        cut_row = table.locator("tr[data-run='cutoff1']").inner_text()
        assert "interrupted" in cut_row and "running" not in cut_row
        table.locator(f"tr[data-run='{run_id}'] button.open-run").click()
        held = pg.locator("#held-out")
        held.wait_for(timeout=60_000)
        assert "held-out error (20 poses)" in held.inner_text()
        link = pg.locator("#report-link")
        link.wait_for(timeout=30_000)
        assert pg.request.get(f"http://127.0.0.1:{port}{link.get_attribute('href')}").ok
    finally:
        context.close()
        _stop(server, log)


def test_stopping_the_server_records_its_runs_as_interrupted(sim_csv, tmp_path):  # noqa: F811
    import robocal as rc
    from robocal.model.files import save_model

    runs = tmp_path / "runs"
    runs.mkdir()
    model_file = save_model(rc.calibration_model("ur10", "position"), runs / "m.yaml")
    runner = JobRunner(runs)
    for run_id in ("first", "second"):  # the second is queued behind the first
        job = CalibrationJob(sim_csv, read_options(), model_file, runs / run_id, train_n=40)
        runner.start(job, run_id, "session", "ur10")
    runner.interrupt_all()
    assert not (runs / "first").exists()  # nothing half-written is left
    assert runner.state("first").status == "interrupted"
    again = JobRunner(runs)  # the next server
    assert {i.run_id: i.status for i in again.runs_list()} == {
        "first": "interrupted",
        "second": "interrupted",
    }
    assert not again.state("second").active


def test_workdir_that_is_a_file_or_busy_is_refused_in_one_line(tmp_path):
    from typer.testing import CliRunner

    from robocal.cli import app

    a_file = tmp_path / "notes.txt"
    a_file.write_text("x")
    result = CliRunner().invoke(
        app, ["gui", "--port", str(_free_port()), "--no-browser", "--workdir", str(a_file)]
    )
    assert result.exit_code != 0 and "--workdir" in result.output and "Traceback" not in result.output
    from robocal.folder_lock import lock_beside

    busy = tmp_path / "busy"
    busy.mkdir()
    with lock_beside(busy, 0.0):  # another server holds it
        result = CliRunner().invoke(
            app, ["gui", "--port", str(_free_port()), "--no-browser", "--workdir", str(busy)]
        )
    assert result.exit_code != 0 and "another robocal gui" in result.output
