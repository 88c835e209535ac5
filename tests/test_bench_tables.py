"""The benchmarks' README blocks (benchmarks/readme_table.py): replaced between their
markers, the rest of the file untouched, missing markers refused before measuring."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
import readme_table


def test_a_block_is_replaced_between_its_markers(tmp_path):
    readme = tmp_path / "README.md"
    readme.write_text("intro\n<!-- bench:kernels -->\nold\n<!-- /bench:kernels -->\nend\n", encoding="utf-8")
    table = readme_table.markdown_table(["row", "µs"], [["fk", "0.04"]])
    readme_table.write_block(readme, "kernels", "\n".join(["text", "", *table]))
    assert readme.read_text(encoding="utf-8") == (
        "intro\n<!-- bench:kernels -->\ntext\n\n| row | µs |\n| --- | ---: |\n| fk | 0.04 |\n"
        "<!-- /bench:kernels -->\nend\n"
    )
    assert readme_table.check(readme, "kernels") is None
    assert "no '<!-- bench:residual -->'" in readme_table.check(readme, "residual")
    assert "No such file" in readme_table.check(tmp_path / "missing.md", "kernels")
    with pytest.raises(ValueError, match="bench:throughput"):
        readme_table.write_block(readme, "throughput", "x")


def test_the_machine_line_names_processor_cores_and_load():
    line = readme_table.machine("1.0 / 2.0 / 3.0")
    assert line.startswith("Machine: ") and "cores" in line and "1.0 / 2.0 / 3.0 at the start" in line


def test_the_readme_has_the_benchmarks_blocks():
    readme = Path(__file__).resolve().parents[1] / "README.md"
    for name in ("kernels", "residual", "throughput", "calibrate"):
        assert readme_table.check(readme, name) is None, name
