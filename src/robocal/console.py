"""Terminal output shared by the ``robocal`` commands: one console each for results
and errors, and the one way a command stops on bad input."""

from __future__ import annotations

import typer
from rich.console import Console

__all__ = ["console", "err_console", "fail"]

console = Console()
err_console = Console(stderr=True, soft_wrap=True)  # an error message is never wrapped mid-word


def fail(message: str) -> typer.Exit:
    """Print ``error: message`` on stderr; ``raise fail(...)`` exits with status 2."""
    err_console.print(f"[bold red]error:[/] {message}", highlight=False)
    return typer.Exit(code=2)
