"""``robocal gui`` under CPU load with two tabs and a reload, and its refusals of other sites.

A busy-loop process runs beside the server for the whole module (the machine is shared:
the issue's results never arrived at load 3).  Two tabs calibrate 60 simulated rows
each; the first tab is reloaded while the runs are queued or running: each tab shows its
own run's result, neither run stops the other, and the status poll never has two
requests in flight.  The security tests need no browser: the headers, the compressed
JavaScript and the 403 for another Host or Origin.
"""

from __future__ import annotations

import gzip
import json
import re
import subprocess
import sys
import urllib.error
import urllib.request

import numpy as np
import pytest

from tests.test_gui import _radio, browser, gui_url  # noqa: F401 (fixtures)

HOG = "while True: pass"


@pytest.fixture(scope="module")
def cpu_hog():
    """A busy loop beside the server for the module's duration."""
    proc = subprocess.Popen([sys.executable, "-c", HOG])
    yield proc
    proc.kill()
    proc.wait(timeout=10)


@pytest.fixture(scope="module")
def sim_csv(tmp_path_factory):
    """60 simulated UR10 rows (laser tracker, m and rad: the page's default options)."""
    where = tmp_path_factory.mktemp("sim")
    q = np.random.default_rng(0).uniform(-2.0, 2.0, (60, 6))
    np.savetxt(where / "poses.csv", q, delimiter=",", header="q1,q2,q3,q4,q5,q6", comments="")
    out = where / "sim60.csv"
    cmd = [sys.executable, "-m", "robocal.cli", "simulate", "ur10", "--poses", str(where / "poses.csv")]
    subprocess.run([*cmd, "-o", str(out), "--seed", "1"], check=True, capture_output=True)
    return out


def _get(url: str, headers: dict[str, str] | None = None, data: bytes | None = None):
    request = urllib.request.Request(url, headers=headers or {}, data=data)
    try:
        with urllib.request.urlopen(request, timeout=60) as response:
            return response.status, response.headers, response.read()
    except urllib.error.HTTPError as err:
        return err.code, err.headers, err.read()


def test_security_headers_compression_and_foreign_hosts(gui_url):  # noqa: F811
    status, headers, body = _get(gui_url)
    assert status == 200
    csp = headers["Content-Security-Policy"]
    assert "frame-ancestors 'none'" in csp and "default-src 'self'" in csp
    assert headers["X-Frame-Options"] == "DENY" and headers["X-Content-Type-Options"] == "nosniff"
    script = re.search(rb'src="(/_dash-component-suites/[^"]*dash_renderer[^"]*\.js)"', body)
    assert script is not None
    status, headers, packed = _get(gui_url + script.group(1).decode()[1:], {"Accept-Encoding": "gzip"})
    assert status == 200 and headers["Content-Encoding"] == "gzip"
    assert b"DashRenderer" in gzip.decompress(packed) and len(packed) < len(gzip.decompress(packed)) / 2
    # DNS rebinding: the page of another name that resolves to 127.0.0.1
    port = gui_url.rsplit(":", 1)[1].strip("/")
    assert _get(gui_url, {"Host": f"attacker.example:{port}"})[0] == 403
    # a cross-site POST must not start work
    update = gui_url + "_dash-update-component"
    evil = {"Origin": "http://attacker.example", "Content-Type": "application/json"}
    status, headers, _ = _get(update, evil, json.dumps({"output": "cal-run-id.data"}).encode())
    assert status == 403 and "frame-ancestors" in headers["Content-Security-Policy"]
    assert _get(gui_url, {"Origin": f"http://localhost:{port}"})[0] == 200


def _poll_counter(pg) -> dict[str, int]:
    """Count the status polls in flight (the largest number at once); a reload abandons the
    page's requests, so the count starts again with the new page."""
    count = {"most": 0}
    flying: set = set()

    def started(request):
        if "_dash-update-component" in request.url and "cal-poll.max_intervals" in (request.post_data or ""):
            flying.add(request)
            count["most"] = max(count["most"], len(flying))

    pg.on("request", started)
    pg.on("requestfinished", lambda request: flying.discard(request))
    pg.on("requestfailed", lambda request: flying.discard(request))
    pg.on("framenavigated", lambda frame: flying.clear() if frame == pg.main_frame else None)
    return count


def _start(pg, url: str, csv, train_n: str) -> None:
    pg.goto(url)
    pg.get_by_text("Calibration", exact=True).click()
    pg.locator("#upload-csv input[type=file]").set_input_files(str(csv))
    _radio(pg, "cal-model", "ur10")
    pg.locator("#csv-summary").wait_for(timeout=60_000)
    pg.fill("#cal-train-n", train_n)
    pg.fill("#cal-seed", "3")
    pg.click("#cal-run")
    started = pg.locator("#cal-status", has_text=re.compile("calibrat|queued|starting|reading"))
    started.wait_for(timeout=30_000)


def test_two_tabs_and_a_reload_under_load(browser, gui_url, sim_csv, cpu_hog):  # noqa: F811
    context = browser.new_context(viewport={"width": 1400, "height": 1000})
    tab_a, tab_b = context.new_page(), context.new_page()
    polls = [_poll_counter(tab_a), _poll_counter(tab_b)]
    csp: list[str] = []
    for tab in (tab_a, tab_b):
        tab.on("console", lambda m: csp.append(m.text) if "Content Security Policy" in m.text else None)
    try:
        _start(tab_a, gui_url, sim_csv, "40")  # 20 held out
        _start(tab_b, gui_url, sim_csv, "30")  # 30 held out: B's run is queued or runs beside A's
        tab_a.reload()  # mid-run: the tab follows the same run again
        tab_a.get_by_text("Calibration", exact=True).click()
        assert tab_a.locator("#cal-train-n").input_value() == "40"  # the page's values are kept
        tab_a.locator("#csv-name", has_text="sim60.csv").wait_for(timeout=30_000)  # and the file
        for tab, held in ((tab_a, 20), (tab_b, 30)):
            result = tab.locator("#held-out")
            result.wait_for(timeout=240_000)
            assert f"held-out error ({held} poses)" in result.inner_text()
            tab.locator("#report-link").wait_for(timeout=120_000)
            status = tab.locator("#cal-status").inner_text()
            assert "done" in status and "/tmp" not in status and "cancel" not in status
        rows = tab_a.locator("#run-table tbody tr")
        rows.nth(1).wait_for(timeout=10_000)
        assert rows.count() >= 2 and "this tab" in tab_a.locator("#run-table").inner_text()
        assert [p["most"] for p in polls] == [1, 1]  # no poll sent while another was in flight
        assert not csp, csp
    finally:
        context.close()
