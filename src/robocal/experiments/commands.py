"""``robocal reproduce NAME``: run one of the seeds' experiments."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from robocal.console import fail, refuse_overwrite
from robocal.model.files import strict_json

__all__ = ["register"]


def reproduce_command(
    name: Annotated[str, typer.Argument(help="seed000 | seed001 | seed003")],
    out: Annotated[Path | None, typer.Option("--out", help="directory for the report and files")] = None,
    as_json: Annotated[bool, typer.Option("--json", help="print the numbers as JSON")] = False,
    quick: Annotated[bool, typer.Option("--quick", help="a smaller, faster run")] = False,
    force: Annotated[bool, typer.Option("--force", help="overwrite an existing output")] = False,
) -> None:
    """Reproduce a seed's experiment and print its published numbers next to robocal's."""
    if out is not None:
        refuse_overwrite(out, force, "folder")
    from robocal.experiments import get
    from robocal.identify.guards import CalibrationGuardError

    try:
        run = get(name)
    except (KeyError, NotImplementedError) as err:
        raise fail(str(err.args[0])) from None
    try:
        numbers = run(out=out, quick=quick, verbose=not as_json)
    except CalibrationGuardError as err:  # a seed whose run cannot carry on without the fit
        raise fail(f"{name}: a calibration failed: {err}") from None
    if as_json:
        print(strict_json(numbers))


def register(app: typer.Typer) -> None:
    """Add ``reproduce`` to the ``robocal`` app."""
    app.command("reproduce")(reproduce_command)
