"""A module's private names stay in the module (issue 32: sub-packages with real APIs).

No module of ``src/robocal`` imports another module's ``_name`` (a function, class or constant
whose name starts with one underscore) or a module whose name does (``_version`` excepted: the
build writes it).  What another module needs is public, named without the underscore; what is
private can change without looking elsewhere.
"""

from __future__ import annotations

import ast
from pathlib import Path

SRC = Path(__file__).resolve().parents[1] / "src"
ALLOWED_MODULES = {"_version"}


def _module_name(path: Path, src: Path) -> str:
    name = ".".join(path.relative_to(src).with_suffix("").parts)
    return name.removesuffix(".__init__")


def _absolute(node: ast.ImportFrom, module: str, is_package: bool) -> str:
    if not node.level:
        return node.module or ""
    parts = module.split(".") if is_package else module.split(".")[:-1]
    parts = parts[: len(parts) - (node.level - 1)]
    return ".".join([*parts, node.module] if node.module else parts)


def private_imports(src: Path = SRC) -> list[str]:
    """``file:line: name`` for each import of another module's private name."""
    found = []
    for path in sorted((src / "robocal").rglob("*.py")):
        module = _module_name(path, src)
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.ImportFrom):
                source = _absolute(node, module, path.name == "__init__.py")
                names = [alias.name for alias in node.names]
            elif isinstance(node, ast.Import):
                source, names = "", [alias.name for alias in node.names]
            else:
                continue
            for part in [*source.split("."), *(n for name in names for n in name.split("."))]:
                if part.startswith("_") and not part.startswith("__") and part not in ALLOWED_MODULES:
                    found.append(f"{path.relative_to(src)}:{node.lineno}: {source} {', '.join(names)}")
                    break
    return found


def test_no_module_imports_another_modules_private_names():
    assert private_imports() == []


def test_the_check_sees_a_private_import(tmp_path):
    """The scan is not vacuous: a private import in a module of the package is reported."""
    package = tmp_path / "robocal"
    package.mkdir()
    (package / "a.py").write_text("def _hidden():\n    return 1\n")
    (package / "b.py").write_text("def f():\n    from robocal.a import _hidden\n    return _hidden()\n")
    (package / "c.py").write_text("from .a import _hidden as shown\n")
    found = private_imports(tmp_path)
    assert len(found) == 2 and all("_hidden" in line for line in found)
