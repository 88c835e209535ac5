"""Measurements: joint values and what a device observed, with CSV input and output.

A :class:`Measurements` holds one row per measured pose:

* ``q`` ``(n, dof)`` joint values (rad, or m for prismatic joints);
* optional ``position`` ``(n, 3)`` (m) and ``orientation`` ``(n, 3, 3)`` rotation
  matrices, both in the measuring device's own frame;
* optional per-row standard deviations ``sigma`` ``(n, 3)`` (m), a ``split`` label
  per row (``"train"``/``"test"``), a ``temperature`` (°C) and any ``extra``
  numeric columns kept by name;
* ``metadata``: device, frame, units and source file as plain strings.

CSV layout (DESIGN.md): columns ``q1..qN``, ``x, y, z`` and optionally
``qw, qx, qy, qz`` (or ``rx, ry, rz``), ``sx, sy, sz``, ``set`` and ``temperature``.
Files written by :func:`write_measurements` are SI with ``# key: value`` metadata
lines at the top.  A poses file (what to measure) is the same format with joint
columns only.

Reading (:func:`read_measurements`) converts units at the edge: lengths (positions,
standard deviations, prismatic joints) in ``length_unit``, angles (revolute joints,
rotation vectors, Euler angles) in ``angle_unit``.  Orientation columns are read as

* ``"quaternion"``: ``qw qx qy qz`` (scalar first, normalised on read);
* ``"rotvec"``: ``rx ry rz`` rotation vector (axis × angle);
* ``"euler:SEQ"`` or ``"euler:SEQ:UNIT"``: ``rx ry rz`` are Euler angles in scipy's
  sequence ``SEQ`` (upper case intrinsic, lower case extrinsic, see
  :mod:`robocal.spatial`); ``UNIT`` (``deg``/``rad``) overrides ``angle_unit`` for
  these columns only, for files whose joints are in rad and angles in degrees;
* ``"auto"`` (default): quaternion columns if present, else ``rx ry rz`` as a
  rotation vector; ``"none"`` ignores orientation columns.

The UR10 laser-tracker file (``shared/data/ur10_laser_tracker``) stores the T-Mac
orientation as ``measurement_rx/ry/rz`` in degrees.  They are **intrinsic** XYZ Euler
angles, ``R = Rx(rx) Ry(ry) Rz(rz)`` (``orientation="euler:XYZ:deg"``).  Found by
fitting ``R_measured = A · R_fk(q) · B`` (constant tracker rotation A and constant
flange-to-T-Mac rotation B) over all 11,910 rows: intrinsic XYZ leaves a residual of
0.10° median / 0.29° max (the arm's own orientation error), extrinsic ``xyz`` 2.6°
median and up to 172° (it breaks down near ry = -90°, where the file has many rows).
The robot's commanded ``Goal roll/pitch/yaw`` are extrinsic ``xyz`` (ROS RPY,
``R = Rz(yaw) Ry(pitch) Rx(roll)``): they agree with the nominal FK to 0.07° median
once the controller's base is turned by 180° about z and the tool by 90° about z, and
the measured XYZ angles agree with them to 0.12° median (tests/test_dataset.py).

Everything rejected names the file, the row (1-based line number in the file) and the
column.  :func:`check_measurements` lists all problems of a file at once.
"""

from __future__ import annotations

import dataclasses
import warnings
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from robocal.choices import AngleUnit, LengthUnit
from robocal.measure.dataset.columns import (
    IncompleteMode,
)
from robocal.measure.dataset.options import ReaderOptions
from robocal.measure.dataset.reader import Reader
from robocal.measure.dataset.writer import write_measurements
from robocal.measure.measurements import (
    MAX_FILE_BYTES,
    LimitsMode,
    MeasurementFileError,
    Measurements,
    MeasurementWarning,
    Problem,
)
from robocal.model.chain import Model

__all__ = [
    "MeasurementFileError",
    "MeasurementWarning",
    "Measurements",
    "Problem",
    "check_measurements",
    "read_measurements",
    "write_measurements",
]


def _collect(path: str | Path, options: dict) -> tuple[Measurements | None, list[Problem]]:
    reader = Reader(Path(path), **options)
    reader.max_file_bytes = MAX_FILE_BYTES  # looked up here, so that it can be set on this module
    data = reader.read()
    return data, reader.problems


def _options(options: ReaderOptions, dof: int | None, model: Model | None) -> dict[str, Any]:
    """The reader's keyword arguments: the options' fields, the expected joint count and the robot."""
    return {**options.as_kwargs(), "dof": dof, "model": model}


def read_measurements(  # noqa: PLR0913 - public API: the reader options, unchanged
    path: str | Path,
    *,
    options: ReaderOptions | None = None,
    length_unit: LengthUnit = "m",
    angle_unit: AngleUnit = "rad",
    columns: Mapping[str, str] | Sequence[str] | str | None = None,
    sep: str | None = None,
    decimal: str = ".",
    dof: int | None = None,
    model: Model | None = None,
    limits: LimitsMode = "error",
    orientation: str = "auto",
    extra: Sequence[str] = (),
    incomplete: IncompleteMode = "error",
) -> Measurements:
    """Read a measurement (or poses) CSV file; all or nothing (or the complete rows).

    Args:
        path: the file.
        options: all the options below but ``dof`` and ``model`` as one
            :class:`~robocal.measure.dataset.options.ReaderOptions` (what the command line
            and :func:`robocal.workflow.calibrate_file` pass); those keywords are then
            left at their defaults (a TypeError otherwise: two sources for one option).
        length_unit: ``"m"``, ``"mm"`` or ``"um"`` for positions, standard deviations
            and prismatic joint values.
        angle_unit: ``"rad"`` or ``"deg"`` for revolute joint values and orientation
            angles (see ``orientation`` for a separate unit of Euler angles).
        columns: renames from robocal's column names to the file's, e.g.
            ``{"q1": "shoulder_pan_joint", "x": "measurement_x"}``,
            ``["q1=shoulder_pan_joint", ...]`` or ``"q1=shoulder_pan_joint,x=measurement_x"``.
            With a model, joint columns may also be keyed (or named in the file) by the
            model's joint names.
        sep: column separator; sniffed from the header when None (``;`` tab ``,``).
        decimal: decimal mark, ``"."`` or ``","`` (real exports use ``;`` and ``,``).
        dof: expected number of joint columns when no model is given; when None,
            ``q1, q2, ...`` are taken while present.
        model: the robot; the file must then have exactly its joints (missing and extra
            joint columns are named), prismatic joints are read in ``length_unit`` and
            revolute ones in ``angle_unit``, and values are checked against its limits.
        limits: what a joint value outside the model's limits is: ``"error"``,
            ``"warn"`` (a :class:`MeasurementWarning`) or ``"ignore"``.
        orientation: ``"auto"``, ``"none"``, ``"quaternion"``, ``"rotvec"``,
            ``"euler:SEQ"`` or ``"euler:SEQ:UNIT"`` (module docstring).
        extra: further numeric columns to keep, by their names in the file, in
            :attr:`Measurements.extra` (unconverted).
        incomplete: a row with an empty, non-numeric or non-finite cell or the wrong
            number of cells is an error (``"error"``) or is left out with a warning
            (``"drop"``: a tracker that lost the beam leaves such rows); the number left
            out is in ``metadata["rows_left_out"]``.

    Returns:
        :class:`Measurements` in SI units; ``metadata`` has the ``# key: value`` lines
        of the file, ``file`` and the units and orientation convention read.

    Raises:
        MeasurementFileError: naming the file, row (1-based line number) and column of
            the first error, with every problem in ``.problems``.  Rejected: NaN/inf,
            empty and non-numeric cells, ragged rows, missing/extra joint columns,
            incomplete column groups, joint values outside the limits (unless
            ``limits`` says otherwise), duplicated rows, positions or angles whose size
            suggests the wrong unit, non-unit quaternions, negative standard
            deviations, train/test labels other than ``train``/``test``.  Repeated joint
            values in a joints-only (poses) file are only warned about: repeating a
            pose is how repeatability is measured.
        ValueError: on invalid options.
    """
    given = ReaderOptions(length_unit, angle_unit, columns, sep, decimal, orientation, limits, incomplete,
                          tuple(extra))  # fmt: skip
    opts = _options(_one_source(options, given), dof, model)
    data, problems = _collect(path, opts)
    return _checked(path, data, problems)


def _checked(path: str | Path, data: Measurements | None, problems: list[Problem]) -> Measurements:
    """``data`` when no problem is an error (the warnings issued, in one MeasurementWarning),
    else a MeasurementFileError naming the first error."""
    errors = [p for p in problems if p.severity == "error"]
    if errors or data is None:
        more = f" (and {len(errors) - 1} more problem(s); `robocal data check` lists them all)"
        raise MeasurementFileError(str(errors[0]) + (more if len(errors) > 1 else ""), problems)
    found = [p for p in problems if p.severity == "warning"]
    if found:
        shown = "\n".join(f"  {p}" for p in found[:10])
        rest = f"\n  ... and {len(found) - 10} more" if len(found) > 10 else ""
        warnings.warn(
            MeasurementWarning(f"{len(found)} warning(s) reading {path}:\n{shown}{rest}"), stacklevel=3
        )
    return data


def _one_source(options: ReaderOptions | None, keywords: ReaderOptions) -> ReaderOptions:
    """``options`` when given (the keywords must then be at their defaults), else the keywords'."""
    if options is None:
        return keywords
    if not isinstance(options, ReaderOptions):
        raise TypeError(f"options must be a ReaderOptions, got {type(options).__name__}")
    mixed = [f.name for f in dataclasses.fields(keywords) if getattr(keywords, f.name) != f.default]
    if mixed:
        raise TypeError(
            f"reader option(s) {', '.join(mixed)} given both as keywords and in options=ReaderOptions"
        )
    return options


def check_measurements(
    path: str | Path, model: Model | None = None, *, options: ReaderOptions | None = None, **read_options: Any
) -> list[Problem]:
    """Every problem of a measurement file (errors and warnings), in file order.

    Takes the options of :func:`read_measurements` (as keywords or ``options``); an empty
    list means the file reads cleanly.  ``limits`` defaults to ``"error"`` as in
    :func:`read_measurements`.
    """
    dof = read_options.pop("dof", None)
    keywords = ReaderOptions(**read_options)
    opts = _options(_one_source(options, keywords), dof, model)
    _, problems = _collect(path, opts)
    return sorted(problems, key=lambda p: (p.row is not None, p.row or 0))
