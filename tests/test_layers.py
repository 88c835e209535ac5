"""robocal's layers cannot rot: the import contracts in ``.importlinter`` hold (checked by
import-linter, function-level imports included), and the checker does catch a broken
layer, a late upward import and an import circle (on small packages written here)."""

from __future__ import annotations

import os
import re
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

pytest.importorskip("importlinter", reason="import-linter is not installed (pip install -e '.[test]')")


def _lint_imports(config: Path, cwd: Path, pythonpath: Path | None = None) -> subprocess.CompletedProcess:
    """``lint-imports`` on ``config``, without a cache (nothing is written into ``cwd``)."""
    env = dict(os.environ)
    if pythonpath is not None:
        env["PYTHONPATH"] = os.pathsep.join([str(pythonpath), env.get("PYTHONPATH", "")])
    code = "import sys; from importlinter.cli import lint_imports_command; sys.exit(lint_imports_command())"
    return subprocess.run(
        [sys.executable, "-c", code, "--config", str(config), "--no-cache"],
        cwd=cwd,
        env=env,
        capture_output=True,
        text=True,
    )


def test_robocal_keeps_its_import_contracts():
    result = _lint_imports(ROOT / ".importlinter", ROOT)
    assert result.returncode == 0, result.stdout[-4000:] + result.stderr[-2000:]
    kept = re.search(r"Contracts: (\d+) kept, 0 broken", result.stdout)
    assert kept is not None and int(kept.group(1)) >= 3, result.stdout[-2000:]  # layers, acyclic, facade


def _package(tmp_path: Path, files: dict[str, str]) -> Path:
    for name, text in files.items():
        path = tmp_path / "toy" / name
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(textwrap.dedent(text))
    return tmp_path


_CONFIG = """
[importlinter]
root_package = toy

[importlinter:contract:layers]
name = layers
type = layers
containers =
    toy
exhaustive = true
layers =
    high
    (sub)
    low

[importlinter:contract:acyclic]
name = acyclic
type = acyclic_siblings
ancestors =
    toy
"""


@pytest.mark.parametrize(
    "low_text",
    [
        "from toy import high\n",  # a module-level upward import
        "def f():\n    from toy.high import g  # late: still a dependency\n    return g\n",
    ],
    ids=["module-level", "function-level"],
)
def test_the_checker_catches_an_upward_import(tmp_path, low_text):
    root = _package(tmp_path, {"__init__.py": "", "high.py": "def g():\n    pass\n", "low.py": low_text})
    config = tmp_path / "contracts.ini"
    config.write_text(_CONFIG)
    result = _lint_imports(config, tmp_path, pythonpath=root)
    assert result.returncode == 1, result.stdout + result.stderr
    assert "toy.low is not allowed to import toy.high" in result.stdout


def test_the_checker_catches_a_circle_and_passes_a_clean_package(tmp_path):
    files = {
        "__init__.py": "",
        "high.py": "from toy import low\n",
        "low.py": "",
        "sub/__init__.py": "",
        "sub/a.py": "from toy.sub import b\n",
        "sub/b.py": "",
    }
    root = _package(tmp_path, files)
    config = tmp_path / "contracts.ini"
    config.write_text(_CONFIG)
    clean = _lint_imports(config, tmp_path, pythonpath=root)
    assert clean.returncode == 0, clean.stdout + clean.stderr
    (tmp_path / "toy" / "sub" / "b.py").write_text("def f():\n    from toy.sub import a\n    return a\n")
    circle = _lint_imports(config, tmp_path, pythonpath=root)
    assert circle.returncode == 1, circle.stdout + circle.stderr
    assert "No cycles are allowed in toy.sub" in circle.stdout


def test_the_checker_asks_a_new_module_for_its_layer(tmp_path):
    root = _package(tmp_path, {"__init__.py": "", "high.py": "", "low.py": "", "newcomer.py": ""})
    config = tmp_path / "contracts.ini"
    config.write_text(_CONFIG)
    result = _lint_imports(config, tmp_path, pythonpath=root)
    assert result.returncode == 1, result.stdout + result.stderr
    assert "toy.newcomer" in result.stdout and "not listed as layers" in result.stdout
