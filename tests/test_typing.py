"""mypy checks the public API: ``robocal/__init__.py`` and what it exports.

``tests/typing/public_api.py`` uses every name of ``robocal.__all__`` as the README does; mypy
runs on it with ``disallow_untyped_calls`` (a public function without type hints fails) and on
the package's own small modules with ``disallow_untyped_defs``. The modules behind the exports
are followed silently (configuration: ``[tool.mypy]`` in pyproject.toml): their signatures are
checked against the use, their bodies are not yet mypy clean.
"""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import pytest

import robocal

ROOT = Path(__file__).resolve().parents[1]
USAGE = ROOT / "tests" / "typing" / "public_api.py"
CHECKED = ["src/robocal/__init__.py", "src/robocal/_lazy.py", "src/robocal/spatial.py"]


def test_mypy_accepts_the_public_api(tmp_path):
    pytest.importorskip("mypy", reason="mypy is not installed (pip install -e '.[test]')")
    command = [sys.executable, "-m", "mypy", "--cache-dir", str(tmp_path / "cache"), "--no-error-summary"]
    checks = ["--disallow-untyped-defs", "--disallow-incomplete-defs", "--disallow-untyped-calls"]
    result = subprocess.run(
        [*command, *checks, str(USAGE), *CHECKED], cwd=ROOT, capture_output=True, text=True, timeout=300
    )
    assert result.returncode == 0, result.stdout + result.stderr
    # and mypy sees robocal's types (an unresolved package would be Any, and anything would pass)
    wrong = tmp_path / "wrong.py"
    wrong.write_text("import robocal as rc\n\nnames: list[int] = rc.robots()\nrc.no_such_name()\n")
    result = subprocess.run([*command, str(wrong)], cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert result.returncode == 1, result.stdout + result.stderr
    assert "list[int]" in result.stdout and "no_such_name" in result.stdout, result.stdout


def _type_checking_imports() -> set[tuple[str, str]]:
    tree = ast.parse((ROOT / "src" / "robocal" / "__init__.py").read_text(encoding="utf-8"))
    block = next(
        node for node in tree.body if isinstance(node, ast.If) and ast.unparse(node.test) == "TYPE_CHECKING"
    )
    return {
        (node.module, alias.name)
        for node in block.body
        if isinstance(node, ast.ImportFrom) and (node.module or "").startswith("robocal.")
        for alias in node.names
    }


def _lazy_map() -> set[tuple[str, str]]:
    """``(module, name)`` of the ``lazy_package(__name__, {...})`` call in robocal/__init__.py."""
    tree = ast.parse((ROOT / "src" / "robocal" / "__init__.py").read_text(encoding="utf-8"))
    call = next(
        node.value
        for node in tree.body
        if isinstance(node, ast.Expr)
        and isinstance(node.value, ast.Call)
        and ast.unparse(node.value.func) == "lazy_package"
    )
    mapping = ast.literal_eval(call.args[1])
    return {(module, name) for module, names in mapping.items() for name in names}


def test_type_checkers_see_what_the_lazy_map_provides():
    """``import robocal`` loads names lazily; its TYPE_CHECKING imports must name the same ones."""
    assert _lazy_map() and _type_checking_imports() == _lazy_map()


def test_the_usage_file_uses_every_public_name():
    text = USAGE.read_text(encoding="utf-8")
    unused = [name for name in robocal.__all__ if f"rc.{name}" not in text]
    assert not unused, f"tests/typing/public_api.py does not use rc.{', rc.'.join(unused)}"


@pytest.mark.parametrize(
    "package",
    ["robocal", *(f"robocal.{p}" for p in ("model", "measure", "identify", "compensate", "evaluate"))],
)
def test_every_exported_name_resolves(package):
    """What a package's ``__all__`` and lazy map promise is there (a lazy map entry written
    ``("name")`` instead of ``("name",)`` would map the name's letters)."""
    import importlib

    module = importlib.import_module(package)
    lazy = module.__dict__.get("_lazy_exports", {})
    assert all(len(name) > 1 for name in lazy), sorted(name for name in lazy if len(name) == 1)
    missing = [name for name in module.__all__ if not hasattr(module, name)]
    assert not missing, f"{package}: {missing}"
