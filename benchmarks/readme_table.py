"""The documentation's performance tables, written by the benchmarks that measure them.

A benchmark run with ``--md PAGE`` (``docs/performance.md``; ``docs/tutorials/ur10-real.md``
for ``bench_residual.py``) replaces the block between
``<!-- bench:NAME -->`` and ``<!-- /bench:NAME -->`` in that file with its table and a
line naming the machine, the versions and the load average during the run (as the
reproductions do with ``<!-- reproduce:NAME -->``).  The file is replaced whole
(written next to it, then renamed), or left as it was when its markers are missing.
"""

from __future__ import annotations

import os
import platform
import re
from collections.abc import Sequence
from pathlib import Path

import numpy as np


def cpu_model() -> str:
    """The processor's name (``/proc/cpuinfo``), else what ``platform`` says."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def load() -> str:
    """The 1-, 5- and 15-minute load averages, as text."""
    return " / ".join(f"{v:.1f}" for v in os.getloadavg())


def machine(load_start: str, extra: str = "") -> str:
    """One line: processor, cores, Python, numpy (and ``extra``), load average at start and end."""
    return (
        f"Machine: {cpu_model()}, {os.cpu_count()} cores, Python {platform.python_version()}, "
        f"numpy {np.__version__}{', ' + extra if extra else ''}; one BLAS thread; load average "
        f"(1 / 5 / 15 min) {load_start} at the start, {load()} at the end."
    )


def markdown_table(header: Sequence[str], rows: Sequence[Sequence[str]], align: str = "") -> list[str]:
    """A Markdown table; ``align``: one letter per column, ``l`` or ``r`` (default: first
    column left, the others right)."""
    align = align or "l" + "r" * (len(header) - 1)
    rule = ["---" if a == "l" else "---:" for a in align]
    return [f"| {' | '.join(r)} |" for r in (header, rule, *rows)]


def replace_block(text: str, name: str, body: str) -> str:
    """``text`` with the block ``name`` replaced by ``body``; ValueError without its markers."""
    start, end = f"<!-- bench:{name} -->", f"<!-- /bench:{name} -->"
    pattern = re.compile(re.escape(start) + ".*?" + re.escape(end), re.S)
    if not pattern.search(text):
        raise ValueError(f"no '{start}' ... '{end}' block")
    return pattern.sub(lambda _: f"{start}\n{body.strip()}\n{end}", text, count=1)


def check(path: str | os.PathLike[str], name: str) -> str | None:
    """Why the block ``name`` of ``path`` cannot be written (one line), or None: benchmarks
    check before they measure."""
    try:
        replace_block(Path(path).read_text(encoding="utf-8"), name, "")
    except (OSError, UnicodeDecodeError, ValueError) as err:
        return f"{path}: {err}"
    return None


def write_block(path: str | os.PathLike[str], name: str, body: str) -> None:
    """Replace the block ``name`` of the file ``path`` (atomically)."""
    from robocal.outdir import atomic_write_bytes

    path = Path(path)
    text = replace_block(path.read_text(encoding="utf-8"), name, body)
    atomic_write_bytes(path, text.encode("utf-8"))
    print(f"wrote the '{name}' table into {path}")
