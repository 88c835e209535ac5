"""The ``robocal`` app: the top level (``--version``, ``-h``), and the registration of every
command module of :mod:`robocal.cli`.

Start-up: this module and the command modules it registers import only typer and rich at the
top; each command imports what it uses (tests/test_startup.py checks that ``robocal --help``
loads none of scipy.stats, Pinocchio, plotly, Dask, scikit-learn).
"""

from __future__ import annotations

from typing import Annotated

import typer

from robocal.cli.errors import RobocalGroup
from robocal.cli.options import CONTEXT
from robocal.console import tolerate_terminal_encoding

__all__ = ["app", "main"]

app = typer.Typer(
    help="robocal: calibration of serial robot arms.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
    context_settings=CONTEXT,
    cls=RobocalGroup,  # no traceback: an exception a command lets through becomes one line
)


def _print_version(value: bool) -> None:
    if value:
        from robocal import __version__

        print(f"robocal {__version__}")
        raise typer.Exit()


@app.callback()
def _top(
    version: Annotated[
        bool,
        typer.Option(
            "--version", callback=_print_version, is_eager=True, help="print robocal's version and exit"
        ),
    ] = False,
) -> None:
    """robocal: calibration of serial robot arms."""
    tolerate_terminal_encoding()  # also when the app is called in-process, not through main()


from robocal.cli import (  # noqa: E402  (the modules register their commands on `app`)
    calibrate,
    compensate,
    experiments,
    export,
    gui,
    iso9283,
    measure,
    model,
    poses,
    report,
    robots,
    study,
    validate,
)

for _module in (robots, model, measure, poses, calibrate, validate, experiments, compensate, export, report):
    _module.register(app)
for _module in (iso9283, study, gui):
    _module.register(app)


def main() -> None:  # pragma: no cover - console entry point
    tolerate_terminal_encoding()  # --help and usage errors print before any callback runs
    app()


if __name__ == "__main__":  # pragma: no cover
    main()
