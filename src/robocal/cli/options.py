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
``robocal.spatial.parse_vector``) and turn its error into one line naming the option.  Lengths
and angles carry their units, one spelling in every command (:func:`length_vector`,
:func:`frame_option`: ``"0,0,109mm"``, ``"0,0,0.1m,0,0,90deg"``; a bare non-zero length is
refused), and joint values given in degrees without saying so are refused
(:func:`joint_values`).

Only typer is imported at the top (the command line starts fast).
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any, overload

import typer

from robocal import choices
from robocal.choices import CHAIN_CHOICES, IncompleteMode, LimitsMode
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
    "frame_option",
    "joint_values",
    "length_vector",
    "measure_option",
    "out_option",
    "parse_vector",
    "refuse_degrees_as_radians",
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
    choices.LengthUnit,
    typer.Option(
        "--length-unit",
        metavar="m|mm|um",
        help="unit of positions, standard deviations and prismatic joints in the file",
    ),
]
AngleUnit = Annotated[
    choices.AngleUnit,
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
    LimitsMode,
    typer.Option(
        "--limits", metavar="error|warn|ignore", help="what to do with joint values beyond the model's limits"
    ),
]
Incomplete = Annotated[
    IncompleteMode,
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
    from robocal.model.yaml_files import ModelFileError

    try:
        return find_model(name_or_path)
    except ModelFileError as err:
        raise fail(str(err)) from None


def robot_and_chain(robot: str, chain: str | None) -> tuple[Model, bool]:
    """ROBOT's model and whether it came from the catalog, with ``--chain`` checked
    (``complete`` or ``catalog``; ``catalog`` only for a catalog robot)."""
    from robocal.model.catalog import is_model_path

    from_catalog = not is_model_path(robot)
    if chain is not None and chain not in CHAIN_CHOICES:  # the API's callers; the option is a choice
        raise fail(f"--chain {chain!r}: {' or '.join(CHAIN_CHOICES)}")
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


def length_vector(text: str, count: int, option: str) -> np.ndarray:
    """``count`` lengths (m) given to ``option`` with their unit (``"0,0,109mm"``,
    ``"0,0,0.109m"``; :func:`robocal.units.parse_quantities`); exit 2 with one line for a
    bare non-zero number, a bad unit or count."""
    import numpy as np

    from robocal.units import parse_quantities

    try:
        return np.array(parse_quantities(text, ["length"] * count, option))
    except ValueError as err:
        raise fail(str(err)) from None


@overload
def frame_option(text: str, option: str, position_only: bool = False) -> np.ndarray: ...
@overload
def frame_option(text: None, option: str, position_only: bool = False) -> None: ...
def frame_option(text: str | None, option: str, position_only: bool = False) -> np.ndarray | None:
    """A frame given as ``"x,y,z,rx,ry,rz"`` with units (``"0,0,109mm,0,0,90deg"``; the
    rotation a rotation vector) as a 4x4 transform (m), None for None.  ``position_only``:
    ``"x,y,z"`` is accepted too (a point: the transform has no rotation)."""
    if text is None:
        return None
    import numpy as np

    from robocal import spatial
    from robocal.units import parse_quantities

    count = len(text.split(","))
    kinds = ["length"] * 3 + ([] if position_only and count == 3 else ["angle"] * 3)
    try:
        v = np.array(parse_quantities(text, kinds, option))
    except ValueError as err:
        raise fail(str(err)) from None
    rotation = spatial.rotvec_to_matrix(v[3:]) if len(v) == 6 else np.eye(3)
    return spatial.homogeneous(rotation, v[:3])


def joint_values(
    text: str, model: Model, option: str, angle_unit: str = "rad", length_unit: str | None = None
) -> np.ndarray:
    """A joint configuration given to ``option`` (rad, m): values with or without units
    (``"0,-90,90,0,90,0deg"``; unit-less revolute values in ``angle_unit``, prismatic ones
    in ``length_unit``, or with a unit when that is None).  Exit 2 naming the joint when a
    value in rad is beyond the joint's limits or beyond 4π, saying when it looks like
    degrees (the measurement reader's check of joint columns)."""
    import numpy as np

    from robocal.units import parse_quantities

    kinds = ["angle" if t == "revolute" else "length" for t in model.joint_types]
    try:
        bare = {"angle": angle_unit} | ({"length": length_unit} if length_unit else {})
        q = np.array(parse_quantities(text, kinds, option, bare=bare))
    except ValueError as err:
        raise fail(f"{err} ({model.dof} joint values of {model.name})") from None
    if angle_unit == "rad" and "deg" not in text and "°" not in text:
        refuse_degrees_as_radians(q, model, option, text, f"{text.strip()}deg")
    limits = model.joint_limits
    for j, (value, kind) in enumerate(zip(q, kinds, strict=True)):
        if kind == "angle" and not limits[j, 0] - 1e-9 <= value <= limits[j, 1] + 1e-9:
            raise fail(
                f"{option} {text!r}: {model.joint_names[j]} = {value:.6g} rad is beyond its limits "
                f"[{limits[j, 0]:.4g}, {limits[j, 1]:.4g}] rad"
            )
    return q


def refuse_degrees_as_radians(q: np.ndarray, model: Model, option: str, text: str, fix: str) -> None:
    """Exit 2 when joint values read in rad look like degrees: a revolute joint beyond its
    limits (or 4π, the measurement reader's bound) whose value in degrees is within them.
    ``fix``: how to say degrees (``"0,-90,90deg"``, ``"--deg"``)."""
    import numpy as np

    from robocal.measure.measurements import MAX_REVOLUTE_RAD

    limits = model.joint_limits
    for j, (value, kind) in enumerate(zip(q, model.joint_types, strict=True)):
        beyond = abs(value) > MAX_REVOLUTE_RAD or not limits[j, 0] - 1e-9 <= value <= limits[j, 1] + 1e-9
        if kind == "revolute" and beyond and limits[j, 0] <= np.radians(value) <= limits[j, 1]:
            raise fail(
                f"{option} {text!r}: {model.joint_names[j]} = {value:.6g} rad is beyond its limits "
                f"[{limits[j, 0]:.4g}, {limits[j, 1]:.4g}] rad; looks like degrees: give {fix}"
            )
