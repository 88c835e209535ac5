"""MkDocs hook: the command-line reference generated from the CLI itself.

A page holding the line ``<!-- cli-reference -->`` gets, in its place, the ``--help`` of
``robocal`` and of every command and subcommand, in the order ``robocal --help`` lists them,
rendered by Typer in-process (no subprocess per command).  The reference therefore follows
the code: a new option appears on the next build.  tests/test_docs.py checks that every
command of :data:`robocal.cli.app.COMMANDS` is on the page.
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from typing import Any

MARKER = "<!-- cli-reference -->"
WIDTH = 100  # columns of the rendered help: wide enough for the option tables


def command_paths() -> Iterator[tuple[list[str], str]]:
    """Every command path (``[]`` for ``robocal`` itself, ``["model", "build"]``, ...) with its summary."""
    import click
    import typer

    from robocal.cli.app import app

    root = typer.main.get_command(app)
    yield [], "robocal: calibration of serial robot arms."

    def walk(group: Any, path: list[str]) -> Iterator[tuple[list[str], str]]:
        ctx = click.Context(group, info_name="robocal")
        for name in group.list_commands(ctx):
            command = group.get_command(ctx, name)
            yield [*path, name], command.get_short_help_str(limit=200)
            if hasattr(command, "list_commands"):  # a group (model, data, export, robots)
                yield from walk(command, [*path, name])

    yield from walk(root, [])


def help_text(path: list[str]) -> str:
    """``robocal PATH --help`` as plain text (no colour), :data:`WIDTH` columns wide."""
    from typer.testing import CliRunner

    from robocal.cli.app import app

    env = {"COLUMNS": str(WIDTH), "NO_COLOR": "1", "TERM": "dumb"}
    result = CliRunner().invoke(app, [*path, "--help"], env=env, prog_name="robocal")
    if result.exit_code != 0:
        raise RuntimeError(f"robocal {' '.join(path)} --help exited {result.exit_code}: {result.output}")
    lines = [line.rstrip() for line in result.output.splitlines()]
    return "\n".join(lines).strip("\n")


def reference_markdown() -> str:
    """The whole reference: one section per command, its help in a text block."""
    parts = []
    for path, summary in command_paths():
        name = " ".join(["robocal", *path])
        parts.append(f"## `{name}`\n\n{summary}\n\n```text\n{help_text(path)}\n```\n")
    return "\n".join(parts)


def on_page_markdown(markdown: str, page: Any, config: Any, files: Any) -> str:
    """Replace the marker with the generated reference (MkDocs hook)."""
    if MARKER not in markdown:
        return markdown
    os.environ.setdefault("COLUMNS", str(WIDTH))
    return markdown.replace(MARKER, reference_markdown())
