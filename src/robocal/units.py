"""robocal's one table of units: SI per unit of every length, angle and stiffness unit a
file, a command-line option or a CSV column may use.

Everything inside robocal is SI (m, rad, N·m/rad); a value read in ``unit`` is multiplied
by ``LENGTH_UNITS[unit]`` (or ``ANGLE_UNITS``, ``STIFFNESS_UNITS``).  :func:`unit_factor`
looks a unit up and, for an unknown one, raises an error that names where it came from
(the option or column) and lists the units there are.
"""

from __future__ import annotations

import math
from typing import Literal

__all__ = [
    "ANGLE_UNITS",
    "LENGTH_UNITS",
    "SPELLINGS",
    "STANDARD_GRAVITY",
    "STIFFNESS_UNITS",
    "UnitKind",
    "joint_unit_factors",
    "unit_factor",
]

UnitKind = Literal["length", "angle", "stiffness"]

#: m per unit
LENGTH_UNITS: dict[str, float] = {"m": 1.0, "mm": 1e-3, "um": 1e-6}
#: rad per unit
ANGLE_UNITS: dict[str, float] = {"rad": 1.0, "mrad": 1e-3, "urad": 1e-6, "deg": math.pi / 180.0}
#: m/s² in a kgf (the standard gravity, CGPM 1901)
STANDARD_GRAVITY = 9.80665
#: N·m/rad per unit of joint stiffness (seed 003 gives stiffnesses in kgf·m/deg)
STIFFNESS_UNITS: dict[str, float] = {
    "N*m/rad": 1.0,
    "N*m/deg": 180.0 / math.pi,
    "kgf*m/deg": STANDARD_GRAVITY * 180.0 / math.pi,
}
#: other spellings of the same units (micro sign, Greek mu, degree sign)
SPELLINGS: dict[str, str] = {"µm": "um", "μm": "um", "°": "deg", "µrad": "urad", "μrad": "urad"}

_TABLES: dict[str, dict[str, float]] = {
    "length": LENGTH_UNITS,
    "angle": ANGLE_UNITS,
    "stiffness": STIFFNESS_UNITS,
}


def unit_factor(unit: str, kind: UnitKind, where: str) -> float:
    """SI per ``unit`` of a ``kind`` quantity (``unit_factor("mm", "length", ...) == 1e-3``).

    Args:
        unit: the unit's name (``SPELLINGS`` are accepted too).
        kind: ``"length"``, ``"angle"`` or ``"stiffness"``.
        where: what gave the unit, for the error: an option (``"--length-unit"``), a
            keyword (``"length_unit"``) or a file's column.

    Raises:
        ValueError: ``unit`` is not a ``kind`` unit; the message starts with ``where``
            (``"length_unit must be a length unit, one of m, mm, um; got 'inch'"``).
    """
    table = _TABLES[kind]
    key = SPELLINGS.get(unit, unit) if isinstance(unit, str) else unit
    try:
        return table[key]
    except (KeyError, TypeError):
        article = "an" if kind[0] in "aeiou" else "a"
        known = ", ".join(table)
        raise ValueError(f"{where} must be {article} {kind} unit, one of {known}; got {unit!r}") from None


def joint_unit_factors(angle_unit: str, length_unit: str) -> tuple[float, float]:
    """rad per ``angle_unit`` and m per ``length_unit``: the factors of revolute and
    prismatic joint values in a file (errors name ``angle_unit`` / ``length_unit``)."""
    return unit_factor(angle_unit, "angle", "angle_unit"), unit_factor(length_unit, "length", "length_unit")
