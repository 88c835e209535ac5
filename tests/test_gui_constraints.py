"""Constraint files in ``robocal gui`` (fixed points, planes, distances; issue 36 item 5 /
issue 33 item 3): recognised on upload, calibrated by the command line's use case
(:func:`robocal.workflow.constraints.calibrate_constraint_files`), the kind's figures shown.

In Chromium: a simulated two-socket file (``robocal simulate --kind point``) opened on the
calibration page shows the constraint options instead of the tracker's column mapping; a
known distance typed in the table reaches the fit (the saved ``constraints.json`` records
it); the result shows each socket's spread before and after (smaller after), the known
distance's error, the base placement named as not identifiable, and the report opens.  A
bad row of the distance table is refused by its row.
"""

from __future__ import annotations

import json
import subprocess
import sys
import urllib.request

import pytest

from robocal.apps.gui.constraint_view import distances_of
from tests.test_gui import _radio, browser, gui_url  # noqa: F401 (fixtures)


@pytest.fixture(scope="module")
def socket_csv(tmp_path_factory):
    out = tmp_path_factory.mktemp("socket") / "socket.csv"
    cmd = [sys.executable, "-m", "robocal.cli", "simulate", "ur10", "--kind", "point", "--n", "60"]
    subprocess.run([*cmd, "--count", "2", "--seed", "3", "-o", str(out)], check=True, capture_output=True)
    return out


def test_the_distance_table_reads_filled_rows_and_names_a_bad_one():
    rows = [
        {"a": 0, "b": 1, "mm": 250},
        {"a": None, "b": None, "mm": None},
        {"a": "2", "b": "0", "mm": "50.5"},
    ]
    assert distances_of(rows) == ((0, 1, 0.25), (2, 0, 0.0505))
    for bad in ({"a": 0, "b": 0, "mm": 10}, {"a": 0, "b": 1, "mm": -1}, {"a": 0, "b": None, "mm": 5}):
        with pytest.raises(ValueError, match="row 2"):
            distances_of([{"a": 0, "b": 1, "mm": 1}, bad])


def test_a_socket_file_is_calibrated_in_the_page(browser, gui_url, socket_csv):  # noqa: F811
    truth = json.loads(socket_csv.with_name(socket_csv.name + ".truth.json").read_text())
    (a, b, metres) = truth["point_distances_m"][0]
    context = browser.new_context(viewport={"width": 1600, "height": 1000})
    pg = context.new_page()
    try:
        pg.goto(gui_url)
        pg.get_by_text("Calibration", exact=True).click()
        pg.locator("#upload-csv input[type=file]").set_input_files(str(socket_csv))
        _radio(pg, "cal-model", "ur10")
        pg.locator("#con-fieldset").wait_for(state="visible", timeout=60_000)
        pg.locator("#csv-preview", has_text="point 1: 30 poses").wait_for(timeout=60_000)
        cell = pg.locator("#con-distances td[data-dash-column='a']").first
        cell.click()
        pg.keyboard.type(str(a))
        pg.keyboard.press("Tab")
        pg.keyboard.type(str(b))
        pg.keyboard.press("Tab")
        pg.keyboard.type(f"{metres * 1e3:.4f}")
        pg.keyboard.press("Enter")
        pg.click("#cal-run")
        pg.locator("#constraint-figures").wait_for(timeout=240_000)

        rows = pg.locator("#constraint-figures tbody tr")
        texts = [rows.nth(k).inner_text().split("\t") for k in range(rows.count())]
        spreads = [t for t in texts if "RMS spread" in t[0]]
        assert len(spreads) == 2
        for _, before, after in spreads:  # the nominal robot misses the sockets; the calibrated one not
            assert float(after) < float(before)
        assert any("known distance 0" in t[0] for t in texts)  # the typed distance reached the fit
        assert "base" in pg.locator("#dropped").inner_text().lower()  # a socket cannot see the base

        link = pg.locator("#report-link")
        link.wait_for(timeout=60_000)
        with urllib.request.urlopen(gui_url.rstrip("/") + link.get_attribute("href"), timeout=30) as r:
            assert r.status == 200 and b"no tracker" in r.read()
        recorded = pg.locator("#cal-report a", has_text="constraints.json").get_attribute("href")
        with urllib.request.urlopen(gui_url.rstrip("/") + recorded, timeout=30) as r:
            doc = json.loads(r.read())
        assert doc["distances_m"] == [[a, b, pytest.approx(metres, abs=1e-7)]]
    finally:
        context.close()
