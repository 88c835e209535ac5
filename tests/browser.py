"""Headless Chromium for the rendering tests (present on developer machines, not on CI)."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

# flags that let Chromium run headless as root in a closed network without phoning home
HEADLESS_FLAGS = (
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--virtual-time-budget=5000",
)


def chromium(profile: Path, *extra: str) -> list[str]:
    """The command line of a headless Chromium with a fresh profile; skips the test when
    Chromium is not installed (``apt install chromium``)."""
    browser = shutil.which("chromium") or shutil.which("chromium-browser")
    if browser is None:
        pytest.skip("chromium is not installed")
    return [browser, *HEADLESS_FLAGS, f"--user-data-dir={profile}", *extra]
