"""The reproduction documents (docs/reproductions/*.md) and the numbers docs/sources.md quotes
(the README's once) are what the code produces: ``robocal reproduce all --md docs/reproductions
--readme docs/sources.md --force`` regenerates them.  The default run recomputes the cheap sections
(seed 000 whole, seed 001's table arm, seed 003's chapter 3); ``-m slow`` all of them."""

import re
from pathlib import Path

import pytest
from typer.testing import CliRunner

from robocal.cli import app
from robocal.experiments.reproductions import (
    SECTIONS,
    readme_block,
    render_markdown,
    render_rows,
    replace_readme_block,
)

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs" / "reproductions"
QUOTES = ROOT / "docs" / "sources.md"  # the page whose <!-- reproduce:NAME --> blocks quote them
REGENERATE = "robocal reproduce all --md docs/reproductions --readme docs/sources.md --force"


def _section(text: str, title: str) -> str:
    """The text of section ``## title`` of a document (up to the next section)."""
    match = re.search(rf"^## {re.escape(title)}\n(.*?)(?=^## |\Z)", text, re.S | re.M)
    assert match, f"no section {title!r}: regenerate with {REGENERATE}"
    return match.group(1).strip()


def _check_sections(name, sections, quoted_only=False):
    doc = (DOCS / f"{name}.md").read_text(encoding="utf-8")
    readme = QUOTES.read_text(encoding="utf-8")
    for section in sections:
        generated = render_markdown(name, "x", [section]).split(f"## {section.title}\n", 1)[1].strip()
        assert _section(doc, section.title) == generated, f"{name}.md is stale: regenerate with {REGENERATE}"
        for line in render_rows([r for r in section.rows if r.quote], why=False)[2:]:
            assert line in readme, (
                f"docs/sources.md quotes a stale {name} number ({line}): regenerate with {REGENERATE}"
            )


def test_seed000_document_and_quotes_are_current():
    from robocal.experiments.seed000 import run

    numbers = run(verbose=False)
    title, sections_of = SECTIONS["seed000"]
    sections = sections_of(numbers)
    assert (DOCS / "seed000.md").read_text(encoding="utf-8") == render_markdown("seed000", title, sections)
    readme = QUOTES.read_text(encoding="utf-8")
    assert readme_block("seed000", sections) in readme, f"regenerate with {REGENERATE}"


def test_seed003_chapter_3_is_current():
    from robocal.experiments import seed003

    n_test, draws, _ = seed003.run_sizes(quick=False)
    t34 = seed003.influence_experiment(seed003.katana_setup(n_test=n_test), seed003.noise_seeds(draws))
    numbers = {"table_3_4": t34, "table_3_4_notes": seed003.table_3_4_notes(t34)}
    _check_sections("seed003", SECTIONS["seed003"][1](numbers))


def test_reproduce_md_writes_the_document_and_the_readme_block(tmp_path):
    """seed 001's quick run computes its table arm exactly as the full run does: the
    section written by --md must be the committed one."""
    readme = tmp_path / "README.md"
    readme.write_text("intro\n<!-- reproduce:seed001 -->\nold\n<!-- /reproduce:seed001 -->\nend\n")
    args = ["reproduce", "seed001", "--quick", "--md", str(tmp_path / "md"), "--readme", str(readme)]
    result = CliRunner().invoke(app, args)
    assert result.exit_code == 0, result.output
    written = (tmp_path / "md" / "seed001.md").read_text(encoding="utf-8")
    assert "(a --quick run)" in written and "| quantity | seed | robocal | what differs and why |" in written
    text = readme.read_text()
    assert (
        text.startswith("intro\n<!-- reproduce:seed001 -->\n| quantity | seed | robocal |")
        and "old" not in text
    )
    assert text.endswith("<!-- /reproduce:seed001 -->\nend\n") and "docs/reproductions/seed001.md" in text
    committed = (DOCS / "seed001.md").read_text(encoding="utf-8")
    first = re.findall(r"^## (.*)$", written, re.M)[0]  # the table arm: the same in quick and full runs
    assert _section(committed, first) == _section(written, first), f"seed001.md is stale: {REGENERATE}"
    readme_now = QUOTES.read_text(encoding="utf-8")
    for line in text.splitlines()[4:]:  # the quoted rows of the quick run (the table arm's)
        if line.startswith("| "):
            assert line in readme_now, f"docs/sources.md quotes a stale seed001 number ({line}): {REGENERATE}"


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["reproduce", "seed999"], "unknown experiment 'seed999'; choose all or one of"),
        (["reproduce", "all", "--readme", "README.md"], "--readme needs --md"),
    ],
)
def test_reproduce_bad_input_is_one_line(args, message):
    result = CliRunner().invoke(app, args)
    assert result.exit_code == 2 and message in result.output and "Traceback" not in result.output


def test_reproduce_refuses_a_readme_without_the_block_and_an_existing_document(tmp_path):
    readme = tmp_path / "README.md"
    readme.write_text("no markers\n")
    md = tmp_path / "md"
    result = CliRunner().invoke(app, ["reproduce", "seed001", "--md", str(md), "--readme", str(readme)])
    assert result.exit_code == 2 and "no '<!-- reproduce:seed001 -->'" in result.output
    assert not md.exists()  # nothing run, nothing written
    md.mkdir()
    (md / "seed001.md").write_text("old\n")
    result = CliRunner().invoke(app, ["reproduce", "seed001", "--md", str(md)])
    assert result.exit_code == 2 and "use --force" in result.output
    assert (md / "seed001.md").read_text() == "old\n"


def test_replace_readme_block_keeps_the_rest():
    text = "a\n<!-- reproduce:x -->\nold\n<!-- /reproduce:x -->\nb\n"
    assert replace_readme_block(text, "x", "<!-- reproduce:x -->new<!-- /reproduce:x -->") == (
        "a\n<!-- reproduce:x -->new<!-- /reproduce:x -->\nb\n"
    )
    with pytest.raises(ValueError, match="reproduce:y"):
        replace_readme_block(text, "y", "")


@pytest.mark.slow
def test_every_document_and_quote_is_current(tmp_path):
    """The whole regeneration, into a copy of the README (a few minutes)."""
    readme = tmp_path / "README.md"
    readme.write_text(QUOTES.read_text(encoding="utf-8"), encoding="utf-8")
    args = ["reproduce", "all", "--md", str(tmp_path / "md"), "--readme", str(readme), "--json"]
    result = CliRunner().invoke(app, args)
    assert result.exit_code == 0, result.output
    for name in SECTIONS:
        assert (tmp_path / "md" / f"{name}.md").read_text(encoding="utf-8") == (
            DOCS / f"{name}.md"
        ).read_text(encoding="utf-8"), f"{name}.md is stale: regenerate with {REGENERATE}"
    assert readme.read_text(encoding="utf-8") == QUOTES.read_text(encoding="utf-8")
