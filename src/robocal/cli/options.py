"""Every option shared by robocal's commands, defined once: its spelling, metavar and help.

* the robot: the positional ``ROBOT`` (a catalog name or a model file), :data:`Robot`;
* an output path: ``-o/--out`` everywhere (:func:`out_option`), never ``--output``;
* the measurement reader's options wherever a CSV of measurements is read
  (:data:`LengthUnit`, :data:`AngleUnit`, :data:`Columns`, :data:`Sep`, :data:`Decimal`,
  :data:`Orientation`, :data:`Limits`, :data:`Incomplete`);
* ``--force``, ``--json``, ``--seed``, ``--workers``, ``--scheduler``, ``--no-progress``;
* ``-h`` beside ``--help`` (:data:`CONTEXT`), and flags shown without a ``<bool>`` type
  (:func:`tidy_help`).

The one model lookup (:func:`resolve_model`) and the one vector parser (:func:`parse_vector`)
of the command line are here too: both call the library's (``robocal.model.catalog.find_model``,
``robocal.spatial.parse_vector``) and turn its error into one line naming the option.

Only typer is imported at the top (the command line starts fast).
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import typer

from robocal.console import fail

if TYPE_CHECKING:
    import numpy as np

    from robocal.model.chain import Model

__all__ = [
    "CONTEXT",
    "AngleUnit",
    "Columns",
    "Decimal",
    "Force",
    "Incomplete",
    "Json",
    "LengthUnit",
    "Limits",
    "NoProgress",
    "Orientation",
    "Robot",
    "Scheduler",
    "Sep",
    "Workers",
    "as_cli_text",
    "measure_option",
    "out_option",
    "parse_vector",
    "resolve_model",
    "robot_and_chain",
    "seed",
    "tidy_help",
]

#: every command and group: ``-h`` is ``--help``
CONTEXT: dict[str, Any] = {"help_option_names": ["-h", "--help"]}

ROBOT_HELP = "catalog name (robocal robots) or model file (.yaml)"

#: the robot, positional in every command that takes one
Robot = Annotated[str, typer.Argument(metavar="ROBOT", help=ROBOT_HELP, show_default=False)]


def out_option(help: str, metavar: str = "FILE") -> Any:
    """The ``-o/--out`` option of a command that writes ``help`` (``metavar`` FILE or DIR)."""
    return typer.Option("-o", "--out", metavar=metavar, help=help)


def seed(help: str = "random seed (the same seed gives the same result)") -> Any:
    """The ``--seed N`` option."""
    return typer.Option("--seed", min=0, metavar="N", help=help)


def measure_option(help: str) -> Any:
    """The ``--measure position|pose`` option."""
    return typer.Option("--measure", metavar="position|pose", help=help)


Force = Annotated[bool, typer.Option("--force", help="overwrite an existing output")]
Json = Annotated[bool, typer.Option("--json", help="print JSON instead of tables")]
Workers = Annotated[
    int | None,
    typer.Option(
        "--workers",
        min=0,
        metavar="N",
        help="Dask worker processes on this machine (default: one per core; 0: no Dask)",
    ),
]
Scheduler = Annotated[
    str | None,
    typer.Option(
        "--scheduler", metavar="ADDRESS", help="address of a running Dask scheduler, e.g. tcp://host:8786"
    ),
]
NoProgress = Annotated[bool, typer.Option("--no-progress", help="no progress bar")]

# The measurement reader's options, on every command that reads a CSV of measurements.
LengthUnit = Annotated[
    str,
    typer.Option(
        "--length-unit",
        metavar="m|mm|um",
        help="unit of positions, standard deviations and prismatic joints in the file",
    ),
]
AngleUnit = Annotated[
    str,
    typer.Option(
        "--angle-unit", metavar="rad|deg", help="unit of revolute joints and orientation angles in the file"
    ),
]
Columns = Annotated[
    str | None,
    typer.Option(
        "--columns",
        metavar='"NAME=COLUMN,..."',
        help='column renames, e.g. "q1=shoulder_pan_joint,x=measurement_x"',
    ),
]
Sep = Annotated[str | None, typer.Option("--sep", metavar="CHAR", help="column separator (default: sniffed)")]
Decimal = Annotated[str, typer.Option("--decimal", metavar='"."|","', help="decimal mark")]
Orientation = Annotated[
    str,
    typer.Option(
        "--orientation",
        metavar="auto|none|quaternion|rotvec|euler:SEQ[:UNIT]",
        help="how the file's orientation columns are written",
    ),
]
Limits = Annotated[
    str,
    typer.Option(
        "--limits", metavar="error|warn|ignore", help="what to do with joint values beyond the model's limits"
    ),
]
Incomplete = Annotated[
    str,
    typer.Option(
        "--incomplete",
        metavar="error|drop",
        help="rows with an empty or bad cell: an error, or left out with a warning",
    ),
]

_API_OPTION = re.compile(
    r"\b(decimal|angle_unit|length_unit|orientation|sep|limits|measure|incomplete)=('[^']*')"
)
_API_COLUMNS = re.compile(r"columns=\{'(\w+)': '([^']*)'\}")
_API_NAME = re.compile(r"\b(decimal|angle_unit|length_unit|orientation|sep|limits|incomplete) must\b")


def _shell_word(text: str) -> str:
    return text if re.fullmatch(r"[\w.:+-]+", text) else f'"{text}"'


def as_cli_text(message: str) -> str:
    """A reader's message with its keyword arguments (``decimal=','``, ``columns={'q1':
    'j1'}``, ``length_unit must be ...``) written as the command-line options that do the same."""
    message = _API_OPTION.sub(lambda m: f"--{m[1].replace('_', '-')} {_shell_word(m[2][1:-1])}", message)
    message = _API_COLUMNS.sub(lambda m: f"--columns '{m[1]}={m[2]}'", message)
    message = _API_NAME.sub(lambda m: f"--{m[1].replace('_', '-')} must", message)
    return message.replace(" in columns=)", " in --columns)")


def resolve_model(name_or_path: str | Path) -> Model:
    """The robot named on the command line (:func:`robocal.model.catalog.find_model`); exit 2
    with its one line when there is none."""
    from robocal.model.catalog import find_model
    from robocal.model.files import ModelFileError

    try:
        return find_model(name_or_path)
    except ModelFileError as err:
        raise fail(str(err)) from None


def robot_and_chain(robot: str, chain: str | None) -> tuple[Model, bool]:
    """ROBOT's model and whether it came from the catalog, with ``--chain`` checked
    (``complete`` or ``catalog``; ``catalog`` only for a catalog robot)."""
    from robocal.model.catalog import is_model_path

    from_catalog = not is_model_path(robot)
    if chain not in (None, "complete", "catalog"):
        raise fail(f"--chain {chain!r}: complete or catalog")
    if not from_catalog and chain == "catalog":
        raise fail("--chain catalog is for a catalog ROBOT; a model file's chain is calibrated as it is")
    return resolve_model(robot), from_catalog


def parse_vector(text: str, count: int | tuple[int, ...] | None, option: str, what: str = "") -> np.ndarray:
    """``text`` given to ``option`` as numbers (:func:`robocal.spatial.parse_vector`); exit 2
    with a line naming the option and what it takes (``what``, e.g. ``"x,y,z in mm"``)."""
    from robocal.spatial import parse_vector as parse

    try:
        return parse(text, count)
    except ValueError as err:
        hint = f" (give {what})" if what else ""
        raise fail(f"{option} {text!r}: {err}{hint}") from None


def tidy_help(command: Any) -> None:
    """Walk ``command`` and its subcommands: a flag shows no ``<bool>`` type (its metavar is
    empty), the help option of each command too."""
    params = getattr(command, "params", [])
    for param in params:
        if getattr(param, "is_flag", False) and param.metavar is None:
            param.metavar = ""
    get_help_option = command.get_help_option

    def help_option(ctx):  # built lazily by click, once per command
        option = get_help_option(ctx)
        if option is not None and option.metavar is None:
            option.metavar = ""
        return option

    command.get_help_option = help_option
    for sub in getattr(command, "commands", {}).values():
        tidy_help(sub)
