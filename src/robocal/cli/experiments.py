"""``robocal reproduce NAME|all``: run the seeds' experiments."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Any

import typer

from robocal.cli.options import Force, Json, out_option
from robocal.console import fail, refuse_overwrite
from robocal.safe_output import strict_json

__all__ = ["register"]


def _check_readme(readme: Path, names: list[str]) -> str:
    """The README's text, after checking it has a block for every seed (exit 2 if not)."""
    from robocal.experiments.reproductions import replace_readme_block

    try:
        text = readme.read_text(encoding="utf-8")
    except OSError as err:
        raise fail(f"--readme {readme}: cannot read it ({err.strerror or err})") from None
    for name in names:
        try:
            replace_readme_block(text, name, "")
        except ValueError as err:
            raise fail(f"--readme {readme}: {err}") from None
    return text


def _write_md(md: Path, name: str, numbers: dict[str, Any], quick: bool) -> str:
    """Write ``md/NAME.md``; return the README block of ``name``."""
    from robocal.experiments.reproductions import SECTIONS, readme_block, render_markdown
    from robocal.outdir import atomic_write_text

    title, sections_of = SECTIONS[name]
    sections = sections_of(numbers)
    md.mkdir(parents=True, exist_ok=True)
    atomic_write_text(md / f"{name}.md", render_markdown(name, title, sections, quick=quick))
    return readme_block(name, sections)


def reproduce_command(
    name: Annotated[
        str, typer.Argument(metavar="seed000|seed001|seed003|all", help="the experiment", show_default=False)
    ],
    out: Annotated[Path | None, out_option("directory for the report and files", "DIR")] = None,
    as_json: Json = False,
    quick: Annotated[bool, typer.Option("--quick", help="a smaller, faster run")] = False,
    md: Annotated[
        Path | None,
        typer.Option("--md", metavar="DIR", help="write NAME.md (the seed's and robocal's numbers) here"),
    ] = None,
    readme: Annotated[
        Path | None,
        typer.Option(
            "--readme",
            metavar="FILE",
            help="rewrite this page's '<!-- reproduce:NAME -->' blocks (docs/sources.md; with --md)",
        ),
    ] = None,
    force: Force = False,
) -> None:
    """Reproduce a seed's experiment and print its published numbers next to robocal's.

    ``robocal reproduce all --md docs/reproductions --readme docs/sources.md --force``
    regenerates the reproduction documents and the numbers docs/sources.md quotes."""
    from robocal.experiments import EXPERIMENTS, get
    from robocal.identify.guards import CalibrationGuardError

    names = list(EXPERIMENTS) if name == "all" else [name]
    runs = []
    for n in names:
        try:
            runs.append((n, get(n)))
        except (KeyError, NotImplementedError) as err:
            raise fail(str(err.args[0]).replace("choose one of ", "choose all or one of ")) from None
    if readme is not None and md is None:
        raise fail("--readme needs --md (the page quotes the documents --md writes)")
    readme_text = _check_readme(readme, names) if readme is not None else None
    if out is not None:
        refuse_overwrite(out, force, "folder")
    if md is not None:
        for n in names:
            refuse_overwrite(md / f"{n}.md", force)
    blocks: dict[str, str] = {}
    results: dict[str, Any] = {}
    for n, run in runs:
        target = out if out is None or len(names) == 1 else out / n
        try:
            numbers = run(out=target, quick=quick, verbose=not as_json)
        except CalibrationGuardError as err:  # a seed whose run cannot carry on without the fit
            raise fail(f"{n}: a calibration failed: {err}") from None
        results[n] = numbers
        if md is not None:
            blocks[n] = _write_md(md, n, numbers, quick)
    if readme is not None and readme_text is not None:
        from robocal.experiments.reproductions import replace_readme_block
        from robocal.outdir import atomic_write_text

        for n, block in blocks.items():
            readme_text = replace_readme_block(readme_text, n, block)
        atomic_write_text(readme, readme_text)
    if as_json:
        print(strict_json(results[names[0]] if len(names) == 1 else results))


def register(app: typer.Typer) -> None:
    """Add ``reproduce`` to the ``robocal`` app."""
    app.command("reproduce")(reproduce_command)
