"""The benchmarks' blocks in the documentation (benchmarks/readme_table.py): replaced between
their markers, the rest of the file untouched, missing markers refused before measuring."""

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


DOCS = Path(__file__).resolve().parents[1] / "docs"
# the page holding each benchmark's block: the name its --md writes (the benchmark's own text)
PAGES = {
    "kernels": "performance.md",
    "fk": "performance.md",
    "lm": "performance.md",
    "start_values": "performance.md",
    "calibrate": "performance.md",
    "throughput": "performance.md",
    "residual": "tutorials/ur10-real.md",
}


@pytest.mark.parametrize(("name", "page"), sorted(PAGES.items()))
def test_the_docs_have_the_benchmarks_blocks(name, page):
    """Each block exists on its page, and the command it quotes writes that page."""
    path = DOCS / page
    assert readme_table.check(path, name) is None, name
    text = path.read_text(encoding="utf-8")
    block = text[text.index(f"<!-- bench:{name} -->") : text.index(f"<!-- /bench:{name} -->")]
    assert f"--md docs/{page}" in block
    source = (DOCS.parent / "benchmarks" / f"bench_{name}.py").read_text(encoding="utf-8")
    assert f"--md docs/{page}" in source and "--md README.md" not in source


def test_the_readme_keeps_no_benchmark_block():
    """The README is a few screens: the measured tables live in the documentation."""
    readme = (DOCS.parent / "README.md").read_text(encoding="utf-8")
    assert "<!-- bench:" not in readme
