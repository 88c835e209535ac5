"""robocal's one table of units: SI per unit of every length, angle and stiffness unit a
file, a command-line option or a CSV column may use.

Everything inside robocal is SI (m, rad, N·m/rad); a value read in ``unit`` is multiplied
by ``LENGTH_UNITS[unit]`` (or ``ANGLE_UNITS``, ``STIFFNESS_UNITS``).  :func:`unit_factor`
looks a unit up and, for an unknown one, raises an error that names where it came from
(the option or column) and lists the units there are.
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping, Sequence
from typing import Literal

__all__ = [
    "ANGLE_UNITS",
    "LENGTH_UNITS",
    "SPELLINGS",
    "STANDARD_GRAVITY",
    "STIFFNESS_UNITS",
    "UnitKind",
    "joint_unit_factors",
    "parse_quantities",
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


# one number with an optional unit after it (``109``, ``109mm``, ``0.5 deg``, ``1e-3m``)
_TOKEN = re.compile(r"^\s*([+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?)\s*([A-Za-zµμ°]*)\s*$")
_EXAMPLE_UNITS: dict[str, tuple[str, str]] = {"length": ("mm", "m"), "angle": ("deg", "rad")}


def _unit_kind(unit: str) -> str | None:
    """``"length"`` or ``"angle"`` for a unit of either table, None for anything else."""
    key = SPELLINGS.get(unit, unit)
    return "length" if key in LENGTH_UNITS else "angle" if key in ANGLE_UNITS else None


def _missing_unit(text: str, kinds: Sequence[str], missing: set[str], where: str) -> ValueError:
    """The one-line error of bare (unit-less) non-zero values: which kinds lack a unit and
    how to write them."""
    what = " and ".join(f"{k}s ({', '.join(_TABLES[k])})" for k in ("length", "angle") if k in missing)
    if len(set(kinds)) == 1:  # a vector of one kind: one unit at the end
        a, b = _EXAMPLE_UNITS[kinds[0]]
        example = f"{text.strip()}{a} or {text.strip()}{b}"
    else:  # a frame x,y,z,rx,ry,rz: a unit after z, another after rz
        example = "0,0,109mm,0,0,90deg (a unit closes the values before it)"
    return ValueError(f"{where} {text!r}: add the unit of the {what}, e.g. {example}")


def parse_quantities(
    text: str, kinds: Sequence[str], where: str, bare: Mapping[str, str] | None = None
) -> list[float]:
    """Comma-separated values with units, in SI (m, rad), one per entry of ``kinds``.

    A unit after a value applies to it and to the unit-less values before it back to the
    previous unit: ``"0,0,109mm"`` is three lengths in mm, ``"0,0,0.1m,0,0,90deg"`` a
    position in m and a rotation in degrees, ``"0,-90deg,1.5rad"`` two values in degrees
    and one in rad.  A value without a unit must be 0 unless ``bare`` gives its kind's
    unit (``{"angle": "rad"}``: the command's ``--angle-unit``): on a command line a bare
    109 is as likely meant in mm as in m.

    Args:
        text: the option's text, e.g. ``"0,0,109mm"``.
        kinds: ``"length"`` or ``"angle"`` for each value.
        where: the option, for the errors (``"--tool"``).
        bare: the unit of unit-less values by kind (default: none; they must be 0).

    Raises:
        ValueError: a bad number or unit, the wrong count, a unit of the wrong kind, or a
            bare non-zero value; one line that starts with ``where`` and ``text``.
    """
    tokens = text.split(",")
    if len(tokens) != len(kinds):
        raise ValueError(
            f"{where} {text!r}: {len(kinds)} comma-separated values expected, got {len(tokens)} values"
        )
    values: list[float] = []
    pending: list[int] = []  # the unit-less values since the last unit
    factors: list[float | None] = [None] * len(kinds)
    for i, token in enumerate(tokens):
        m = _TOKEN.match(token)
        if m is None:
            raise ValueError(f"{where} {text!r}: {token.strip()!r} is not a number with an optional unit")
        values.append(float(m[1]))
        pending.append(i)
        if m[2]:
            for j in pending:
                if _unit_kind(m[2]) != kinds[j]:
                    raise ValueError(
                        f"{where} {text!r}: {m[2]!r} is not {'an' if kinds[j] == 'angle' else 'a'} "
                        f"{kinds[j]} unit ({', '.join(_TABLES[kinds[j]])}) for value {j + 1}"
                    )
                factors[j] = unit_factor(m[2], kinds[j], where)  # type: ignore[arg-type]
            pending = []
    missing = set()
    for j in pending:
        unit = (bare or {}).get(kinds[j])
        if unit is not None:
            factors[j] = unit_factor(unit, kinds[j], where)  # type: ignore[arg-type]
        elif values[j] == 0.0:
            factors[j] = 1.0  # zero needs no unit
        else:
            missing.add(kinds[j])
    if missing:
        raise _missing_unit(text, kinds, missing, where)
    out = [v * f for v, f in zip(values, factors, strict=True) if f is not None]
    if not all(math.isfinite(v) for v in out):
        raise ValueError(f"{where} {text!r}: values must be finite")
    return out
