"""mypy checks the public API: ``robocal/__init__.py`` and what it exports.

``tests/typing/public_api.py`` uses every name of ``robocal.__all__`` as the README does; mypy
runs on it with ``disallow_untyped_calls`` (a public function without type hints fails) and on
the package's own small modules with ``disallow_untyped_defs``; ``mypy src/robocal`` (the
configuration of ``[tool.mypy]`` in pyproject.toml) reports no error in the whole package.
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
CHECKED = ["src/robocal/__init__.py", "src/robocal/lazy_imports.py", "src/robocal/spatial.py"]


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


#: the packages whose names load lazily (robocal.lazy_imports), each with a TYPE_CHECKING
#: block of the same imports: without it a type checker does not see the lazy names
#: (``from robocal.compensate import compensate_targets`` was an error for mypy)
LAZY_PACKAGES = [
    "robocal",
    *(f"robocal.{p}" for p in ("model", "measure", "identify", "compensate", "evaluate")),
]


def _init_tree(package: str) -> ast.Module:
    path = ROOT / "src" / Path(*package.split(".")) / "__init__.py"
    return ast.parse(path.read_text(encoding="utf-8"))


def _type_checking_imports(package: str) -> set[tuple[str, str]]:
    block = next(
        node
        for node in _init_tree(package).body
        if isinstance(node, ast.If) and ast.unparse(node.test) == "TYPE_CHECKING"
    )
    return {
        (node.module, alias.name)
        for node in block.body
        if isinstance(node, ast.ImportFrom) and (node.module or "").startswith("robocal.")
        for alias in node.names
    }


def _lazy_map(package: str) -> set[tuple[str, str]]:
    """``(module, name)`` of the ``lazy_package(__name__, {...})`` call in the package's __init__."""
    call = next(
        node.value
        for node in _init_tree(package).body
        if isinstance(node, ast.Expr)
        and isinstance(node.value, ast.Call)
        and ast.unparse(node.value.func) == "lazy_package"
    )
    mapping = ast.literal_eval(call.args[1])
    return {(module, name) for module, names in mapping.items() for name in names}


@pytest.mark.parametrize("package", LAZY_PACKAGES)
def test_type_checkers_see_what_the_lazy_map_provides(package):
    """A package loads names lazily; its TYPE_CHECKING imports must name the same ones."""
    assert _lazy_map(package) and _type_checking_imports(package) == _lazy_map(package)


def test_the_usage_file_uses_every_public_name():
    text = USAGE.read_text(encoding="utf-8")
    unused = [name for name in robocal.__all__ if f"rc.{name}" not in text]
    assert not unused, f"tests/typing/public_api.py does not use rc.{', rc.'.join(unused)}"


@pytest.mark.parametrize("package", LAZY_PACKAGES)
def test_every_exported_name_resolves(package):
    """What a package's ``__all__`` and lazy map promise is there (a lazy map entry written
    ``("name")`` instead of ``("name",)`` would map the name's letters)."""
    import importlib

    module = importlib.import_module(package)
    lazy = module.__dict__.get("_lazy_exports", {})
    assert all(len(name) > 1 for name in lazy), sorted(name for name in lazy if len(name) == 1)
    missing = [name for name in module.__all__ if not hasattr(module, name)]
    assert not missing, f"{package}: {missing}"


def _mypy_errors_by_file(output: str) -> dict[str, int]:
    """``{path under src/robocal: error count}`` from mypy's output lines ``path:line: error: ...``."""
    counts: dict[str, int] = {}
    for line in output.splitlines():
        path, _, rest = line.partition(":")
        if path.startswith("src/robocal/") and ": error:" in rest:
            name = path.removeprefix("src/robocal/")
            counts[name] = counts.get(name, 0) + 1
    return counts


def test_mypy_is_clean_on_the_package(tmp_path):
    """``mypy src/robocal`` (the configuration of pyproject.toml) reports no error at all
    (issue 32 item 6)."""
    pytest.importorskip("mypy", reason="mypy is not installed (pip install -e '.[test]')")
    command = [sys.executable, "-m", "mypy", "--cache-dir", str(tmp_path / "cache"), "src/robocal"]
    result = subprocess.run(command, cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert result.returncode in (0, 1), result.stdout + result.stderr  # 1: errors found, 2: mypy failed
    errors = _mypy_errors_by_file(result.stdout)
    assert not errors and result.returncode == 0, f"mypy errors in {errors}:\n{result.stdout}"


def test_the_mypy_error_count_reads_mypy_lines():
    output = (
        "src/robocal/a.py:3: error: x  [misc]\nsrc/robocal/a.py:4: note: y\n"
        "src/robocal/b/c.py:1: error: z  [index]\nFound 2 errors in 2 files\n"
    )
    assert _mypy_errors_by_file(output) == {"a.py": 1, "b/c.py": 1}
