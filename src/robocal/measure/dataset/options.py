"""The measurement reader's options as one frozen value (:class:`ReaderOptions`): what the
command line, the GUI, fleets and :func:`robocal.workflow.calibrate_file` pass to
:func:`robocal.read_measurements` (which takes the same options as keywords too).

Imports only the choice tables (no numpy): the command line builds it at start-up."""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from robocal.choices import AngleUnit, IncompleteMode, LengthUnit, LimitsMode

__all__ = ["ReaderOptions"]


@dataclass(frozen=True)
class ReaderOptions:
    """How a measurement file is written (the keywords of :func:`robocal.read_measurements`,
    which documents each; lengths and angles in the file are in the units named here).

    Attributes:
        length_unit: positions, standard deviations and prismatic joints.
        angle_unit: revolute joints and orientation angles.
        columns: renames from robocal's column names to the file's (``"q1=j1,x=mx"``,
            a sequence of ``"name=column"`` or a mapping).
        sep: column separator; None: sniffed from the header.
        decimal: decimal mark, ``"."`` or ``","``.
        orientation: ``"auto"``, ``"none"``, ``"quaternion"``, ``"rotvec"``, ``"euler:SEQ[:UNIT]"``.
        limits: a joint value beyond the model's limits: error, warn or ignore.
        incomplete: a row with an empty or bad cell: an error, or dropped with a warning.
        extra: further numeric columns to keep, by their names in the file.
    """

    length_unit: LengthUnit = "m"
    angle_unit: AngleUnit = "rad"
    columns: Mapping[str, str] | Sequence[str] | str | None = None
    sep: str | None = None
    decimal: str = "."
    orientation: str = "auto"
    limits: LimitsMode = "error"
    incomplete: IncompleteMode = "error"
    extra: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        object.__setattr__(self, "extra", tuple(self.extra))  # a list given stays hashable and frozen

    def as_kwargs(self) -> dict[str, Any]:
        """The options as keyword arguments of :func:`robocal.read_measurements`."""
        return {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}
