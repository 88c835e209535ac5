"""Every example script runs with its defaults, or ends with one line naming what it needs.

* Each ``examples/*.py`` runs as ``python examples/NAME.py`` (no argument) from a scratch
  folder, with exit status 0 and no traceback; the scripts that take more than a few seconds
  are marked ``slow``.  A script added to examples/ without an entry here fails the suite.
* The scripts that read the real UR10 series default to ``../shared/data/...`` beside the
  clone; copied into a folder without it they stop with exit status 2 and one ``error:``
  line naming the missing file and ``--data``, as they do for a file that is not the series.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ROOT / "examples"
SHARED_DATA = ROOT.parent / "shared" / "data"
HANG_GUARD_S = 900  # a hang guard only: the slowest example takes about half a minute

# every example, and whether its default run is a slow one (seconds on a quiet 2-core machine)
SCRIPTS = {
    "seed001_table": False,  # 2 s
    "seed003_katana": True,  # 5 s
    "ur10_report": True,  # 9 s, needs ../shared/data
    "ur10_real_data": True,  # 18 s, needs ../shared/data
    "o1_bound_study": True,  # 23 s
    "pose_count_study": True,  # 32 s
}
NEED_SHARED = ("ur10_report", "ur10_real_data")


def _run(script: Path, cwd: Path, *args: str) -> subprocess.CompletedProcess:
    env = {**os.environ, "HOME": str(cwd), "MPLBACKEND": "Agg"}
    return subprocess.run(
        [sys.executable, str(script), *args],
        cwd=cwd,
        capture_output=True,
        text=True,
        env=env,
        timeout=HANG_GUARD_S,
    )


def test_every_example_is_listed() -> None:
    assert {p.stem for p in EXAMPLES.glob("*.py")} == set(SCRIPTS)


@pytest.mark.parametrize(
    "name", [pytest.param(n, marks=[pytest.mark.slow] if slow else []) for n, slow in SCRIPTS.items()]
)
def test_example_runs_with_its_defaults(name: str, tmp_path: Path) -> None:
    if name in NEED_SHARED and not SHARED_DATA.is_dir():
        pytest.skip(f"{name}.py reads ../shared/data, absent beside this checkout")
    done = _run(EXAMPLES / f"{name}.py", tmp_path)
    assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-3000:]
    assert "Traceback" not in done.stderr
    assert not list(ROOT.glob(f"{name}*")), "an example wrote into the repository's root"


def _copy_without_shared(tmp_path: Path, name: str) -> Path:
    """The script in a folder laid out like a clone with no ../shared beside it."""
    examples = tmp_path / "clone" / "examples"
    examples.mkdir(parents=True)
    return Path(shutil.copy(EXAMPLES / f"{name}.py", examples))


@pytest.mark.parametrize("name", NEED_SHARED)
def test_example_without_its_data_says_so_in_one_line(name: str, tmp_path: Path) -> None:
    script = _copy_without_shared(tmp_path, name)
    done = _run(script, tmp_path)
    lines = done.stderr.strip().splitlines()
    assert done.returncode == 2 and len(lines) == 1, done.stderr
    assert lines[0].startswith("error: ") and "measurements_grid.csv" in lines[0] and "--data" in lines[0]
    assert not (tmp_path / "ur10-real").exists()  # nothing written


@pytest.mark.parametrize("name", NEED_SHARED)
def test_example_refuses_a_file_that_is_not_the_series_in_one_line(name: str, tmp_path: Path) -> None:
    wrong = tmp_path / "wrong.csv"
    wrong.write_text("a,b\n1,2\n", encoding="utf-8")
    done = _run(EXAMPLES / f"{name}.py", tmp_path, "--data", str(wrong))
    lines = done.stderr.strip().splitlines()
    assert done.returncode == 2 and len(lines) == 1 and str(wrong) in lines[0], done.stderr
    assert "Traceback" not in done.stderr
