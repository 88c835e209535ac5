"""Smoke run of examples/pose_count_study.py (slow: run with -m slow)."""

import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.slow
def test_pose_count_study_runs(tmp_path):
    out = tmp_path / "study.png"
    result = subprocess.run(
        [sys.executable, str(ROOT / "examples" / "pose_count_study.py"), "--quick", "--out", str(out)],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert result.returncode == 0, result.stdout + result.stderr
    assert out.stat().st_size > 10_000
    assert "first n within 10 % of the asymptote" in result.stdout
