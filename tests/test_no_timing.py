"""No test asserts how long something took: a shared or loaded machine makes such a test
fail for no fault of the code (speed is measured in benchmarks/).  A polling loop's
deadline (``while time.monotonic() < deadline``) is a hang guard and allowed."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

TESTS = Path(__file__).parent
#: the standard library's clocks (``time.time()``, ``perf_counter()``, ...)
CLOCKS = {"time", "perf_counter", "perf_counter_ns", "monotonic", "monotonic_ns", "process_time", "time_ns"}
#: names of durations read from a program's output (``numbers["seconds"] < 60``)
DURATION_WORDS = ("seconds", "elapsed", "duration")


def _is_clock_call(node: ast.AST) -> bool:
    if not isinstance(node, ast.Call):
        return False
    func = node.func
    if isinstance(func, ast.Attribute):  # time.perf_counter(), time.time()
        return func.attr in CLOCKS and isinstance(func.value, ast.Name) and func.value.id == "time"
    return isinstance(func, ast.Name) and func.id in CLOCKS - {"time"}  # from time import perf_counter


def _reads_clock(node: ast.AST, tainted: set[str]) -> bool:
    """Whether ``node`` holds a clock reading: a clock call, or a name assigned from one."""
    return any(_is_clock_call(n) or (isinstance(n, ast.Name) and n.id in tainted) for n in ast.walk(node))


def _tainted_names(scope: ast.AST) -> set[str]:
    """Names assigned in ``scope`` (a function, or a module's top level) from an expression
    holding a clock reading."""
    tainted: set[str] = set()
    assigns = [n for n in _walk_scope(scope) if isinstance(n, ast.Assign | ast.AnnAssign | ast.AugAssign)]
    while True:
        before = len(tainted)
        for node in assigns:
            if node.value is not None and _reads_clock(node.value, tainted):
                targets = node.targets if isinstance(node, ast.Assign) else [node.target]
                tainted |= {n.id for t in targets for n in ast.walk(t) if isinstance(n, ast.Name)}
        if len(tainted) == before:
            return tainted


def _walk_scope(scope: ast.AST):
    """The nodes of ``scope`` without those of the functions defined in it."""
    todo = list(ast.iter_child_nodes(scope))
    while todo:
        node = todo.pop()
        yield node
        if not isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef | ast.Lambda):
            todo.extend(ast.iter_child_nodes(node))


def _is_duration(node: ast.AST) -> bool:
    """A duration read from output: ``x["seconds"]``, ``seconds``, ``result.elapsed``."""
    if isinstance(node, ast.Subscript) and isinstance(node.slice, ast.Constant):
        return isinstance(node.slice.value, str) and any(w in node.slice.value for w in DURATION_WORDS)
    name = node.id if isinstance(node, ast.Name) else node.attr if isinstance(node, ast.Attribute) else ""
    return any(w in name.lower() for w in DURATION_WORDS)


def _bounds_a_duration(node: ast.Compare) -> bool:
    """``duration < limit`` (or ``limit > duration``): an upper bound on a duration."""
    left = node.left
    for op, right in zip(node.ops, node.comparators, strict=True):
        if isinstance(op, ast.Lt | ast.LtE) and _is_duration(left):
            return True
        if isinstance(op, ast.Gt | ast.GtE) and _is_duration(right):
            return True
        left = right
    return False


def timing_assertions(source: str) -> list[int]:
    """Line numbers of comparisons on a clock reading or upper bounds on a duration, outside
    the test of a ``while`` loop (a polling loop's hang guard)."""
    tree = ast.parse(source)
    guards = {id(n.test) for n in ast.walk(tree) if isinstance(n, ast.While)}
    scopes = [tree, *(n for n in ast.walk(tree) if isinstance(n, ast.FunctionDef | ast.AsyncFunctionDef))]
    lines = set()
    for scope in scopes:
        tainted = _tainted_names(scope)
        for node in _walk_scope(scope):
            if not isinstance(node, ast.Compare) or id(node) in guards:
                continue
            if _reads_clock(node, tainted) or _bounds_a_duration(node):
                lines.add(node.lineno)
    return sorted(lines)


@pytest.mark.parametrize(
    "source",
    [
        "start = time.perf_counter()\nrun()\nassert time.perf_counter() - start < 5\n",
        "t = time.time()\nrun()\nseconds = time.time() - t\nassert seconds < 0.2, seconds\n",
        "assert numbers['seconds'] < 60\n",
        "from time import monotonic\nt0 = monotonic()\nwall = monotonic() - t0\nassert wall == approx(1.0)\n",
        "def check(seconds):\n    assert seconds < SECONDS\n",
    ],
)
def test_the_scan_finds_a_timing_assertion(source):
    assert timing_assertions(source)


def test_the_scan_allows_hang_guards_and_reported_durations():
    source = (
        "def timed():\n"
        "    t = time.perf_counter()\n"
        "def other(types):\n"
        "    assert sum(t == 'revolute' for t in types) == 6\n"
        "deadline = time.monotonic() + 60\n"
        "while time.monotonic() < deadline:\n"
        "    poll()\n"
        "assert numbers['seconds'] > 0\n"
        "assert len(rows) < 10\n"
    )
    assert timing_assertions(source) == []


def test_no_test_asserts_a_duration():
    found = {
        path.name: lines
        for path in sorted(TESTS.rglob("*.py"))
        if (lines := timing_assertions(path.read_text(encoding="utf-8")))
    }
    assert not found, f"comparisons on a wall clock or a duration (file: lines): {found}"
