"""Regenerate the GUI's screenshots in docs/ at 1600 px and 1024 px wide: the builder with the
UR10 typed in, the calibration page with its results, the pose-planning page.

The builder and calibration pictures come from the browser tests of ``tests/test_gui.py``, run
with ``ROBOCAL_GUI_SCREENSHOTS`` (where they go) and ``ROBOCAL_GUI_WIDTH`` (the window's width);
the planning page is driven here on a server of its own.  The builder and planning pictures
are cropped to the window's first 1100 px of height; the calibration picture is the whole
page (at 1024 px its two columns stack, and the result — held-out error, the CV table, the
3D residuals — sits below the reader options).  Needs Chromium (``apt-get install -y chromium``),
Playwright and ``../shared``.

    python docs/gui_screenshots.py
"""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from PIL import Image

DOCS = Path(__file__).resolve().parent
ROOT = DOCS.parent
#: the test's screenshot -> the docs' name (``{suffix}``: none at 1600 px, the names the README
#: and the tutorial have used; ``_1024`` at 1024 px)
PICKS = {
    "builder_ur10.png": "gui_builder{suffix}.png",
    "calibration_result.png": "gui_calibration{suffix}.png",
}
WIDTHS = (1600, 1024)


def _suffix(width: int) -> str:
    return "" if width == 1600 else f"_{width}"


#: the pictures kept whole (not cropped to :data:`CROP_PX`): the result is far down the page
WHOLE = ("calibration_result.png",)
CROP_PX = 1100


def _save(source: Path, target: Path) -> None:
    with Image.open(source) as image:
        height = image.height if source.name in WHOLE else min(image.height, CROP_PX)
        image.crop((0, 0, image.width, height)).save(target, optimize=True)
    print(f"wrote {target}")


def _test_shots(width: int, tmp: Path) -> None:
    env = dict(os.environ, ROBOCAL_GUI_SCREENSHOTS=str(tmp), ROBOCAL_GUI_WIDTH=str(width))
    tests = "test_builder_types_the_ur10 or test_calibrate_series_a"
    subprocess.run([sys.executable, "-m", "pytest", "-q", str(ROOT / "tests" / "test_gui.py"), "-k", tests],
                   check=True, env=env)  # fmt: skip
    for source, target in PICKS.items():
        _save(tmp / source, DOCS / target.format(suffix=_suffix(width)))


def _server(port: int, log: Path) -> subprocess.Popen:
    cmd = [sys.executable, "-m", "robocal.cli", "gui", "--port", str(port), "--no-browser"]
    with log.open("w") as out:
        proc = subprocess.Popen(cmd, stdout=out, stderr=subprocess.STDOUT)
    for _ in range(300):  # up to 60 s
        with socket.socket() as s:
            if s.connect_ex(("127.0.0.1", port)) == 0:
                return proc
        time.sleep(0.2)
    proc.kill()
    raise SystemExit(f"robocal gui did not start: {log.read_text()}")


def _planning_shots(tmp: Path) -> None:
    """The planning page: 20 random UR10 poses, their indices and 3D view, at each width."""
    from playwright.sync_api import sync_playwright

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    server = _server(port, tmp / "server.log")
    try:
        with sync_playwright() as p:
            browser = p.chromium.launch(executable_path="/usr/bin/chromium", args=["--no-sandbox"])
            for width in WIDTHS:
                pg = browser.new_page(viewport={"width": width, "height": 1000})
                pg.goto(f"http://127.0.0.1:{port}/")
                pg.get_by_text("Pose planning", exact=True).click()
                pg.locator("#plan-robot input[value='ur10']").check()
                pg.locator("#plan-method input[value='random']").check()
                pg.fill("#plan-n", "20")
                pg.click("#plan-run")
                pg.locator("#plan-ok").wait_for(timeout=120_000)
                pg.locator("#plan-3d .main-svg").first.wait_for(timeout=60_000)
                shot = tmp / f"planning_{width}.png"
                pg.screenshot(path=str(shot), full_page=True)
                _save(shot, DOCS / f"gui_planning{_suffix(width)}.png")
                pg.close()
            browser.close()
    finally:
        server.send_signal(signal.SIGINT)
        server.wait(timeout=30)


def main() -> None:
    with tempfile.TemporaryDirectory() as tmp:
        _planning_shots(Path(tmp))
        for width in WIDTHS:
            _test_shots(width, Path(tmp))


if __name__ == "__main__":
    main()
