"""The documentation's `robocal calibrate` transcript on the real UR10 series (series A, 100
calibration poses; docs/concepts/identifiability.md, once the README's) is what the command
prints: its numbers are the code's, not an older version's (the model-choice table once kept
compliance rows from before a change).

The command is taken from the page itself and run as written (only ``--out`` moved to a
temporary folder); the calibration RMS line, every cross-validation row (mean and RMS; the
fit times vary) and the held-out row (mean, RMS, p95, max) must match."""

from __future__ import annotations

import re
import shlex
from pathlib import Path

import pytest
from typer.testing import CliRunner

from robocal.cli.app import app

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT.parent / "shared" / "data" / "ur10_laser_tracker" / "measurements_grid.csv"
PAGE = ROOT / "docs" / "concepts" / "identifiability.md"
START = "$ robocal calibrate ur10 --data ../shared/data/ur10_laser_tracker/measurements_grid.csv"


def _transcript() -> tuple[list[str], str]:
    """The command's arguments and the page's output lines after it (to the block's end)."""
    text = PAGE.read_text(encoding="utf-8")
    start = text.index(START)
    block = text[start : text.index("```", start)]
    lines = block.splitlines()
    command = []
    for line in lines:
        command.append(line.rstrip("\\").strip())
        if not line.endswith("\\"):
            break
    args = shlex.split(" ".join(command))[2:]  # after "$ robocal"
    return args, "\n".join(lines[len(command) :])


def _numbers(text: str) -> dict[str, tuple[str, ...]]:
    """The compared lines: the calibration RMS, the CV rows (mean, RMS) and the held-out row."""
    out: dict[str, tuple[str, ...]] = {}
    if m := re.search(r"RMS error on the calibration poses (\S+) mm → (\S+) mm", text):
        out["calibration RMS"] = m.groups()
    for m in re.finditer(r"^  (geometry[^\d\n]*?(?:H=\d+)?)\s+(\d\.\d{4}) (\d\.\d{4})\s+\d+", text, re.M):
        out["CV " + m.group(1).strip()] = m.groups()[1:]
    if m := re.search(r"│ 11811 │\s+(\S+) │\s+(\S+) │\s+(\S+) │\s+(\S+) │", text):
        out["held-out"] = m.groups()
    return out


@pytest.mark.skipif(not DATA.is_file(), reason="the real UR10 series is in ../shared/data")
def test_the_docs_calibrate_transcript_is_what_the_command_prints(tmp_path, monkeypatch):
    args, shown = _transcript()
    args[args.index("--out") + 1] = str(tmp_path / "ur10cal")
    monkeypatch.chdir(ROOT)  # the page's data path is relative to the repository
    monkeypatch.setenv("COLUMNS", "200")  # one line per table row
    result = CliRunner().invoke(app, args)
    assert result.exit_code == 0, result.output
    expected = _numbers(shown)
    assert len(expected) == 10, sorted(expected)  # the RMS line, 8 CV rows, the held-out row
    assert _numbers(result.output) == expected
