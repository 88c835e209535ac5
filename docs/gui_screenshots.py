"""Regenerate docs/gui_builder.png and docs/gui_calibration.png (the README's screenshots).

Runs the browser tests of ``tests/test_gui.py`` with ``ROBOCAL_GUI_SCREENSHOTS`` set to a
temporary directory and copies two of their screenshots here, cropped to the window's
first screen.  Needs Chromium (``apt-get install -y chromium``), Playwright and ``../shared``.

    python docs/gui_screenshots.py
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
from pathlib import Path

from PIL import Image

DOCS = Path(__file__).resolve().parent
PICKS = {"builder_ur10.png": "gui_builder.png", "calibration_result.png": "gui_calibration.png"}


def main() -> None:
    with tempfile.TemporaryDirectory() as tmp:
        env = dict(os.environ, ROBOCAL_GUI_SCREENSHOTS=tmp)
        tests = "test_builder_types_the_ur10 or test_calibrate_series_a"
        subprocess.run(
            [sys.executable, "-m", "pytest", "-q", str(DOCS.parent / "tests" / "test_gui.py"), "-k", tests],
            check=True,
            env=env,
        )
        for source, target in PICKS.items():
            with Image.open(Path(tmp) / source) as image:
                image.crop((0, 0, image.width, min(image.height, 1100))).save(DOCS / target, optimize=True)
            print(f"wrote {DOCS / target}")


if __name__ == "__main__":
    main()
