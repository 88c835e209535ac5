"""Terminal output shared by the ``robocal`` commands: one console each for results
and errors, and the one way a command stops on bad input."""

from __future__ import annotations

import typer
from rich.console import Console

__all__ = ["console", "err_console", "fail", "refuse_overwrite"]

console = Console()
err_console = Console(stderr=True, soft_wrap=True)  # an error message is never wrapped mid-word


def fail(message: str) -> typer.Exit:
    """Print ``error: message`` on stderr; ``raise fail(...)`` exits with status 2."""
    err_console.print(f"[bold red]error:[/] {message}", highlight=False)
    return typer.Exit(code=2)


def refuse_overwrite(path, force: bool, what: str = "file") -> None:
    """Stop (exit 2) when ``path`` already holds a result and ``--force`` was not given.

    A directory counts as a result when it is not empty.
    """
    from pathlib import Path

    path = Path(path)
    exists = path.is_file() or (path.is_dir() and any(path.iterdir()))
    if exists and not force:
        raise fail(f"{path} already exists; use --force to overwrite this {what}")
