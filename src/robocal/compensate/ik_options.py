"""The inverse kinematics' settings of a compensation as one frozen value (:class:`IKOptions`):
what :func:`robocal.compensate_targets`, :func:`robocal.filter_program`,
:func:`robocal.compensate_path` and ``robocal compensate`` pass to the IK
(:func:`robocal.measure.ik.solve_ik`) of the nominal model and of the calibrated one, as
:class:`robocal.measure.dataset.options.ReaderOptions` is the reader's.  The functions take
the same settings as keywords too (a keyword given replaces the options' field).

Imports only :mod:`dataclasses` and :mod:`math` (no numpy): the command line builds it.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any

__all__ = ["IKOptions"]


@dataclass(frozen=True)
class IKOptions:
    """Settings of the compensation's inverse kinematics (SI units).

    Attributes:
        tol: a target is reached when the position error is at most this (m).
        tol_angle: ... and the orientation error at most this (rad; pose and axis targets).
        max_iter: IK iterations per start.
        restarts: random restarts of the nominal IK only (the correction never restarts: it
            starts from the nominal solution, to keep its configuration).
        seed: seed of those restarts (the same seed: the same commands).
        orientation_weight: m per rad of the orientation rows in the IK objective.
        tool_axis: the tool axis (0, 1, 2: x, y, z) an ``"axis"`` target imposes.

    Raises:
        ValueError: a setting out of its range, named.
    """

    tol: float = 1e-6
    tol_angle: float = 1e-6
    max_iter: int = 100
    restarts: int = 20
    seed: int = 0
    orientation_weight: float = 1.0
    tool_axis: int = 2

    def __post_init__(self) -> None:
        for name in ("tol", "tol_angle", "orientation_weight"):
            value = getattr(self, name)
            if not (isinstance(value, int | float) and math.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be a positive finite number, got {value!r}")
        for name, low in (("max_iter", 1), ("restarts", 0), ("seed", 0)):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < low:
                raise ValueError(f"{name} must be an integer >= {low}, got {value!r}")
        if self.tool_axis not in (0, 1, 2) or isinstance(self.tool_axis, bool):
            raise ValueError(f"tool_axis must be 0, 1 or 2 (x, y, z), got {self.tool_axis!r}")

    @classmethod
    def of(cls, options: IKOptions | None = None, **keywords: Any) -> IKOptions:
        """``options`` (default: the defaults) with the keywords that are not None replacing
        its fields (the public functions' keywords; an unknown one is a TypeError)."""
        given = {name: value for name, value in keywords.items() if value is not None}
        return dataclasses.replace(options if options is not None else cls(), **given)

    def solve_ik_keywords(self, kind: str) -> dict[str, Any]:
        """The keywords of :func:`robocal.measure.ik.solve_ik` for targets of ``kind``
        (``restarts`` apart: the nominal IK uses them, the correction does not)."""
        return {
            "kind": kind,
            "seed": self.seed,
            "tol": self.tol,
            "tol_angle": self.tol_angle,
            "max_iter": self.max_iter,
            "tool_axis": self.tool_axis,
            "orientation_weight": self.orientation_weight,
        }
