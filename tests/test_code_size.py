"""Modules and functions stay small enough to read, or say why not.

A module over ``MAX_MODULE_LINES`` lines needs a ``# long: <reason>`` comment among its first
ten lines; a function over ``MAX_FUNCTION_LINES`` lines (decorators to last line) needs one on
its ``def`` line or on the line just above its first decorator or ``def``. The reason must be
words, not just the marker.
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "src" / "robocal"
MAX_MODULE_LINES = 500
MAX_FUNCTION_LINES = 80
_LONG = re.compile(r"#\s*long:\s*\S.{5,}")


def _has_reason(lines: list[str], *line_numbers: int) -> bool:
    return any(1 <= n <= len(lines) and _LONG.search(lines[n - 1]) for n in line_numbers)


def oversized(path: Path) -> list[str]:
    """What in one module is over the limits without a ``# long:`` reason (empty if nothing)."""
    text = path.read_text(encoding="utf-8")
    lines = text.splitlines()
    found = []
    if len(lines) > MAX_MODULE_LINES and not _has_reason(lines, *range(1, 11)):
        found.append(f"module: {len(lines)} lines > {MAX_MODULE_LINES}")
    for node in ast.walk(ast.parse(text)):
        if not isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
            continue
        first = min([node.lineno] + [d.lineno for d in node.decorator_list])
        length = node.end_lineno - first + 1
        if length > MAX_FUNCTION_LINES and not _has_reason(lines, first - 1, node.lineno):
            found.append(f"{node.name} (line {node.lineno}): {length} lines > {MAX_FUNCTION_LINES}")
    return found


def _modules() -> list[str]:
    return sorted(p.relative_to(PACKAGE).as_posix() for p in PACKAGE.rglob("*.py"))


@pytest.mark.parametrize("module", _modules())
def test_module_and_functions_are_within_limits(module):
    problems = oversized(PACKAGE / module)
    hint = " (split it, or say why: `# long: ...`)"
    assert not problems, f"src/robocal/{module}: " + "; ".join(problems) + hint


def test_the_checker_finds_long_code_and_accepts_reasons(tmp_path):
    body = "\n".join(f"    x{i} = {i}" for i in range(MAX_FUNCTION_LINES))
    long_fn = tmp_path / "a.py"
    long_fn.write_text(f"def f():\n{body}\n")
    assert oversized(long_fn) == [f"f (line 1): {MAX_FUNCTION_LINES + 1} lines > {MAX_FUNCTION_LINES}"]
    long_fn.write_text(f"# long: a flat table of constants\ndef f():\n{body}\n")
    assert oversized(long_fn) == []
    long_fn.write_text(f"# long:\ndef f():\n{body}\n")  # the marker alone is no reason
    assert len(oversized(long_fn)) == 1
    big = tmp_path / "b.py"
    big.write_text("x = 1\n" * (MAX_MODULE_LINES + 1))
    assert oversized(big) == [f"module: {MAX_MODULE_LINES + 1} lines > {MAX_MODULE_LINES}"]
    big.write_text('"""Doc."""\n# long: generated table\n' + "x = 1\n" * MAX_MODULE_LINES)
    assert oversized(big) == []
