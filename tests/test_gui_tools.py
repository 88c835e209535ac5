"""``robocal gui``'s tools beside the calibration: pose planning, the measured points and the
errors in 3D, and filtering a robot program through the run's calibration.

The planner is the command line's: the page's poses CSV equals ``robocal poses``' file.  In
Chromium: a plan shows its indices, its 3D view and hands out the CSV; after a calibration
of 60 simulated rows the 3D view holds every measured point and one error line per point;
a URScript program is filtered (its per-target table, the untouched statement named) and
downloaded, a RAPID program for another robot is refused target by target and not handed out.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

from robocal.apps.gui.poses_page import plan_poses, poses_csv
from tests.test_gui import _radio, browser, gui_url  # noqa: F401 (fixtures)
from tests.test_gui_runs import sim_csv  # noqa: F401 (fixture)

PROGRAMS = Path(__file__).resolve().parents[1] / "examples" / "programs"


def test_the_page_plans_the_poses_robocal_poses_writes(tmp_path):
    out = tmp_path / "cli.csv"
    cmd = [sys.executable, "-m", "robocal.cli", "poses", "ur10", "--method", "optimal", "--n", "12"]
    subprocess.run([*cmd, "--pool", "300", "--seed", "2", "-o", str(out)], check=True, capture_output=True)
    plan = plan_poses("ur10", "optimal", 12, "O1", 300, 2)
    assert poses_csv("ur10", plan.q.tolist(), plan.metadata) == out.read_text(encoding="utf-8")
    assert plan.indices["O1"] >= plan.reference["O1"]  # chosen for O1: at least the pool's first 12


def test_plan_calibrate_3d_and_filter_a_program(browser, gui_url, sim_csv, tmp_path):  # noqa: F811
    context = browser.new_context(viewport={"width": 1600, "height": 1000}, accept_downloads=True)
    pg = context.new_page()
    try:
        pg.goto(gui_url)
        pg.get_by_text("Pose planning", exact=True).click()
        _radio(pg, "plan-robot", "ur10")
        _radio(pg, "plan-method", "random")
        pg.fill("#plan-n", "0")
        pg.click("#plan-run")
        pg.locator("#plan-error", has_text="poses").wait_for(timeout=30_000)  # names the control
        pg.fill("#plan-n", "20")
        pg.click("#plan-run")
        pg.locator("#plan-ok").wait_for(timeout=60_000)
        assert pg.locator("#plan-index-table tbody tr").count() == 5
        pg.locator("#plan-3d .main-svg").first.wait_for(timeout=30_000)
        with pg.expect_download() as download:
            pg.click("#plan-download-button")
        lines = [x for x in download.value.path().read_text().splitlines() if not x.startswith("#")]
        assert lines[0] == "q1,q2,q3,q4,q5,q6" and len(lines) == 21

        pg.get_by_text("Calibration", exact=True).click()
        pg.locator("#upload-csv input[type=file]").set_input_files(str(sim_csv))
        _radio(pg, "cal-model", "ur10")
        pg.locator("#csv-summary").wait_for(timeout=60_000)
        pg.fill("#cal-train-n", "40")
        pg.click("#cal-run")
        pg.locator("#held-out").wait_for(timeout=240_000)
        figure = pg.locator("#residual-3d .js-plotly-plot")
        figure.wait_for(timeout=30_000)
        traces = json.loads(figure.evaluate("g => JSON.stringify(g._fullData.map(t => [t.mode, t._length]))"))
        # 40 calibration points and 20 held out, each with its error line (point, end, gap)
        assert traces == [["markers", 40], ["lines", 120], ["markers", 20], ["lines", 60]]

        with pg.expect_download() as download:
            pg.locator("#upload-program input[type=file]").set_input_files(str(PROGRAMS / "pick.script"))
        filtered = download.value.path().read_text()
        original = (PROGRAMS / "pick.script").read_text()
        assert filtered != original and filtered.count("\n") == original.count("\n")
        assert "7 corrected" in pg.locator("#program-summary").inner_text()
        assert pg.locator("#program-table tbody tr").count() == 7
        assert "pose_trans" in pg.locator("#program-untouched").inner_text()  # named, left as written

        pg.locator("#upload-program input[type=file]").set_input_files(str(PROGRAMS / "pick.mod"))
        pg.locator("#program-error").wait_for(timeout=30_000)
        refused = pg.locator("#program-refused li")
        assert refused.count() >= 1 and "pApproach" in pg.locator("#program-refused").inner_text()
    finally:
        context.close()
