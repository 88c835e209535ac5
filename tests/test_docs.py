"""The documentation site builds offline with no warning, and its examples run.

* The site (mkdocs.yml, docs/) builds with ``mkdocs build --strict`` into a temporary folder:
  a broken link, a missing page, an API docstring griffe cannot read or a failing hook fails.
* The command-line reference is generated from the CLI: every command is on the page.
* Runnable examples: a fenced ``bash`` or ``python`` block preceded by the line
  ``<!-- run -->`` is executed (a page with a ``<!-- run slow -->`` block only with
  ``-m slow``), the blocks of a page in order, in one scratch folder per page that looks
  like a checkout (``examples/`` and a ``../shared`` beside it), so the pages' commands run
  as printed.  A page whose blocks need ``../shared/data`` is skipped
  when it is absent (a clone without the data), saying so.
* The README's marked blocks run the same way (README.md counts as a page), and its demo
  transcript is what ``robocal demo`` prints.  The example scripts: tests/test_examples.py.
"""

from __future__ import annotations

import importlib.util
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
SHARED = ROOT.parent / "shared"
RUN_MARK = re.compile(r"^<!-- run( slow)? -->\n```(bash|python)\n(.*?)^```", re.MULTILINE | re.DOTALL)
HOOK_HANG_GUARD_S = 600  # a hang guard only: a build takes seconds


def runnable_blocks(page: Path) -> list[tuple[str, str, bool]]:
    """(language, code, slow) of every block marked ``<!-- run -->`` on a page, in order."""
    text = page.read_text(encoding="utf-8")
    return [(m.group(2), m.group(3), bool(m.group(1))) for m in RUN_MARK.finditer(text)]


def pages_with_examples() -> list[Path]:
    """The site's pages with runnable blocks, then the README."""
    pages = sorted(p for p in DOCS.rglob("*.md") if runnable_blocks(p))
    return pages + [ROOT / "README.md"]


def _page_id(page: Path) -> str:
    return page.relative_to(ROOT if page.parent == ROOT else DOCS).as_posix()


def test_runnable_convention_is_found() -> None:
    """The collector sees the tutorials' blocks (a renamed marker would silently run nothing)."""
    names = {_page_id(p) for p in pages_with_examples()}
    assert {"getting-started.md", "tutorials/own-robot.md", "README.md"} <= names
    assert runnable_blocks(ROOT / "README.md")


def test_site_builds_offline_with_no_warning(tmp_path: Path) -> None:
    if importlib.util.find_spec("mkdocs") is None:
        pytest.skip('mkdocs is not installed: pip install -e ".[docs]" builds the site')
    site = tmp_path / "site"
    env = {**os.environ, "NO_MKDOCS_2_WARNING": "1"}
    done = subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "-f", str(ROOT / "mkdocs.yml")]
        + ["-d", str(site)],
        cwd=ROOT,
        capture_output=True,
        text=True,
        env=env,
        timeout=HOOK_HANG_GUARD_S,
    )
    assert done.returncode == 0, done.stdout + done.stderr
    cli = (site / "reference" / "cli.html").read_text(encoding="utf-8")
    assert "robocal calibrate" in cli and "--length-unit" in cli
    api = (site / "reference" / "api.html").read_text(encoding="utf-8")
    assert "read_measurements" in api and "calibrate" in api
    assert not (ROOT / "site").exists() or (ROOT / "site").stat().st_mtime < site.stat().st_mtime


def test_cli_reference_lists_every_command() -> None:
    sys.path.insert(0, str(DOCS / "hooks"))
    try:
        import cli_reference
    finally:
        sys.path.remove(str(DOCS / "hooks"))
    from robocal.cli.app import COMMANDS

    page = cli_reference.on_page_markdown("<!-- cli-reference -->", None, None, None)
    for name in COMMANDS:
        assert f"## `robocal {name}`" in page, name
    assert "## `robocal model build`" in page and "## `robocal export urdf`" in page
    assert "<!-- cli-reference -->" not in page


def _scratch_checkout(tmp_path: Path) -> Path:
    """A folder laid out like the repository's root: examples/, benchmarks/ (its data) and
    ../shared beside it."""
    work = tmp_path / "work"
    work.mkdir()
    (work / "examples").symlink_to(ROOT / "examples")
    (work / "benchmarks").symlink_to(ROOT / "benchmarks")
    if SHARED.is_dir():
        (tmp_path / "shared").symlink_to(SHARED)
    return work


def _run_block(language: str, code: str, cwd: Path) -> subprocess.CompletedProcess:
    command = ["bash", "-euo", "pipefail", "-c", code] if language == "bash" else [sys.executable, "-c", code]
    env = {**os.environ, "HOME": str(cwd), "COLUMNS": "100"}
    return subprocess.run(
        command, cwd=cwd, capture_output=True, text=True, env=env, timeout=HOOK_HANG_GUARD_S
    )


def _page_params() -> list:
    params = []
    for page in pages_with_examples():
        slow = any(slow for _, _, slow in runnable_blocks(page))  # one slow block makes the page slow
        marks = [pytest.mark.slow] if slow else []
        params.append(pytest.param(page, id=_page_id(page), marks=marks))
    return params


@pytest.mark.parametrize("page", _page_params())
def test_page_examples_run_as_printed(page: Path, tmp_path: Path) -> None:
    blocks = runnable_blocks(page)
    if any("../shared/" in code for _, code, _ in blocks) and not (SHARED / "data").is_dir():
        pytest.skip(f"{page.name} uses ../shared/data, absent beside this checkout")
    work = _scratch_checkout(tmp_path)
    for number, (language, code, _) in enumerate(blocks, start=1):
        done = _run_block(language, code, work)
        output = done.stdout[-3000:] + done.stderr[-3000:]
        assert done.returncode == 0, f"{page.name} block {number}:\n{code}\n{output}"


def _demo_rows(text: str) -> dict[str, tuple[str, ...]]:
    """The held-out table's rows (mean, RMS, p95, max mm) and the improvement line's numbers."""
    rows = {
        m.group(1): m.groups()[1:]
        for m in re.finditer(r"^│ ([a-z +()]+?)\s*│\s+(\S+) │\s+(\S+) │\s+(\S+) │\s+(\S+) │$", text, re.M)
    }
    if m := re.search(
        r"mean held-out error (\S+) mm → (\S+) mm: (\S+) % smaller \(95 % CI (\S+) to (\S+) %\)", text
    ):
        rows["improvement"] = m.groups()
    return rows


def test_readme_demo_transcript_is_what_the_demo_prints(tmp_path: Path) -> None:
    """The README's first command's numbers are the demo's (default robot, seed and poses)."""
    from typer.testing import CliRunner

    from robocal.cli.app import app

    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    shown = _demo_rows(readme[readme.index("robocal demo — ur10: held-out poses") :])
    assert len(shown) == 4, shown  # three models and the improvement
    result = CliRunner().invoke(app, ["demo", "--out", str(tmp_path / "demo")], env={"COLUMNS": "200"})
    assert result.exit_code == 0, result.output
    assert _demo_rows(result.output) == shown
