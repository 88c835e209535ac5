"""The ``robocal`` app: the top level (``--version``, ``-h``), and the commands of every
module of :mod:`robocal.cli`, each module imported when one of its commands runs.

Start-up: ``robocal --help`` lists the commands from :data:`COMMANDS` (name, module, summary)
without importing a command module; ``robocal fk ...`` imports :mod:`robocal.cli.robots`
and what ``fk`` uses, nothing else. Each command imports its heavy libraries when it runs.
tests/test_startup.py checks the modules each of ``--help``, ``robots``, ``fk``, ``validate``
loads, and that the summaries here are the commands' own.
"""

from __future__ import annotations

import importlib
from collections.abc import Iterator, Mapping, MutableMapping
from typing import Annotated, Any

import typer
from typer.core import TyperCommand

from robocal.cli.errors import RobocalGroup
from robocal.cli.options import CONTEXT
from robocal.console import tolerate_terminal_encoding

__all__ = ["COMMANDS", "app", "main"]

#: every command in ``--help``'s order: name -> (the module of :mod:`robocal.cli` that registers
#: it, its summary in the listing: the start of its own help; tests/test_startup.py checks both)
COMMANDS: dict[str, tuple[str, str]] = {
    "fk": ("robots", "Tool pose of a robot at the given joint values (rad and m unless --deg)."),
    "simulate": (
        "measure",
        "Simulate measurements of ROBOT with randomly drawn errors; write the truth beside them.",
    ),
    "poses": (
        "poses",
        "Choose poses to measure and write them as a poses CSV (joint columns only, rad/m).",
    ),
    "calibrate": (
        "calibrate",
        "Identify the robot's parameters from measurements; write the calibrated model.",
    ),
    "validate": (
        "validate",
        "Error statistics of a calibrated model on (held-out) measurements; for a constraint file "
        "(point, plane, pair/distance_mm columns) its own figures.",
    ),
    "register": (
        "register",
        "Re-register a calibration's device frame (--tool: and tool point) on a few poses.",
    ),
    "reproduce": (
        "experiments",
        "Reproduce a seed's experiment and print its published numbers next to robocal's.",
    ),
    "compensate": (
        "compensate",
        "Corrected joint commands that bring the calibrated robot onto an off-line program's targets.",
    ),
    "filter": (
        "export",
        "Correct every target of a robot program through a calibration; "
        "everything else stays byte-identical.",
    ),
    "report": ("report", "Write the self-contained HTML report of a calibration (works offline)."),
    "demo": ("report", "Calibrate a virtual robot end to end and write the report (under a minute)."),
    "iso9283": (
        "iso9283",
        "The fourteen ISO 9283 characteristics of a measurement log (those it cannot support: why).",
    ),
    "study": (
        "study",
        "Monte Carlo study: virtual robots x pose sets x devices, each simulated, calibrated and "
        "validated; resumes from OUT/results.csv.",
    ),
    "fleet": (
        "study",
        "Calibrate every measurement file of a folder (one robot each); resumes from OUT/fleet.csv.",
    ),
    "gui": (
        "gui",
        "The model builder and the calibration in a browser window (localhost, offline; Ctrl-C stops it).",
    ),
    "robots": ("robots", "The robot catalog."),
    "model": ("model", "Build, view and check calibration models."),
    "data": ("measure", "Measurement files: check them before a calibration."),
    "export": ("export", "Export a calibration: calibrated URDF, UR kinematics."),
}


def module_commands(module: str) -> dict[str, Any]:
    """The click commands that module ``robocal.cli.<module>`` registers, by name (imports it)."""
    from robocal.cli.options import tidy_help

    sub = typer.Typer(add_completion=False)
    importlib.import_module(f"robocal.cli.{module}").register(sub)
    commands = dict(typer.main.get_group(sub).commands)
    for name, command in commands.items():
        tidy_help(command)  # no `<bool>` shown for a flag
        if name in COMMANDS:  # the listing reads the same whether the module is loaded or not
            command.short_help = COMMANDS[name][1]
    return commands


class _Commands(MutableMapping[str, Any]):
    """The group's commands, each module of :mod:`robocal.cli` imported when one of its
    commands is first looked up (``click.Group.get_command`` is ``commands.get``); iterating
    the names imports nothing."""

    def __init__(self, loaded: Mapping[str, Any]) -> None:
        self._loaded = dict(loaded)

    def __getitem__(self, name: str) -> Any:
        if name not in self._loaded and name in COMMANDS:
            for new, command in module_commands(COMMANDS[name][0]).items():
                self._loaded.setdefault(new, command)
        return self._loaded[name]

    def __setitem__(self, name: str, command: Any) -> None:
        self._loaded[name] = command

    def __delitem__(self, name: str) -> None:
        del self._loaded[name]

    def __iter__(self) -> Iterator[str]:
        yield from COMMANDS
        yield from (name for name in self._loaded if name not in COMMANDS)

    def __len__(self) -> int:
        return len(COMMANDS.keys() | self._loaded.keys())

    def loaded(self, name: str) -> bool:
        return name in self._loaded


class _LazyGroup(RobocalGroup):
    """:class:`RobocalGroup` whose commands load on first use; its own ``--help`` lists them
    by the summaries of :data:`COMMANDS` without importing them."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.commands = _Commands(self.commands)
        self._summaries_only = False

    def list_commands(self, ctx: Any) -> list[str]:
        return list(self.commands)  # the names: TyperGroup's walks the items, loading each

    def get_command(self, ctx: Any, cmd_name: str) -> Any:
        commands = self.commands
        if self._summaries_only and isinstance(commands, _Commands) and not commands.loaded(cmd_name):
            summary = COMMANDS.get(cmd_name)
            return None if summary is None else TyperCommand(name=cmd_name, help=summary[1])
        return super().get_command(ctx, cmd_name)

    def format_help(self, ctx: Any, formatter: Any) -> None:
        self._summaries_only = True  # the listing needs each command's summary, not its module
        try:
            super().format_help(ctx, formatter)
        finally:
            self._summaries_only = False


app = typer.Typer(
    help="robocal: calibration of serial robot arms.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
    context_settings=CONTEXT,
    cls=_LazyGroup,  # no traceback: an exception a command lets through becomes one line
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


def main() -> None:  # pragma: no cover - console entry point
    tolerate_terminal_encoding()  # --help and usage errors print before any callback runs
    app()


if __name__ == "__main__":  # pragma: no cover
    main()
