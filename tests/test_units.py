"""One units table (robocal.units): its factors, its errors, and no second table in the code."""

from __future__ import annotations

import math
import re
from pathlib import Path

import pytest

from robocal.units import ANGLE_UNITS, LENGTH_UNITS, STIFFNESS_UNITS, unit_factor

SRC = Path(__file__).resolve().parents[1] / "src" / "robocal"


def test_factors_are_si_per_unit():
    assert unit_factor("mm", "length", "x") == 1e-3
    assert unit_factor("µm", "length", "x") == unit_factor("um", "length", "x") == 1e-6
    assert unit_factor("°", "angle", "x") == unit_factor("deg", "angle", "x") == math.pi / 180
    # seed 003 Table 5.2: 1 kgf·m/deg = 9.80665 N·m per (π/180) rad
    assert STIFFNESS_UNITS["kgf*m/deg"] == pytest.approx(561.87, rel=1e-4)


def test_an_unknown_unit_names_where_it_came_from():
    message = r"^--length-unit must be a length unit, one of m, mm, um; got 'inch'$"
    with pytest.raises(ValueError, match=message):
        unit_factor("inch", "length", "--length-unit")
    message = r"^angle_unit must be an angle unit, one of rad, mrad, urad, deg; got 'grad'$"
    with pytest.raises(ValueError, match=message):
        unit_factor("grad", "angle", "angle_unit")


def test_the_readers_use_the_table():
    from robocal.measure.true_model import parse_quantity

    assert parse_quantity("5µm", "length") == pytest.approx(5e-6)
    assert parse_quantity("2mrad", "angle") == pytest.approx(2e-3)


def test_there_is_no_second_units_table():
    """A unit name mapped to its factor (a dict, or a choice on the name) belongs in robocal/units.py only."""
    table = r"""["'](mm|um|deg|mrad)["']\s*:\s*(1e-3|1e-6|math\.pi|DEG|np\.pi)"""  # {"mm": 1e-3, ...}
    # 1e-3 if unit == "mm" else 1.0
    choice = r"""(1e-3|1e-6|(math|np)\.pi\s*/\s*180\S*)\s+if\s+[\w.]+\s*==\s*["'](mm|um|deg)["']"""
    pattern = re.compile(f"{table}|{choice}")
    found = [
        f"{path.relative_to(SRC)}:{n}"
        for path in sorted(SRC.rglob("*.py"))
        if path.name != "units.py"
        for n, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1)
        if pattern.search(line)
    ]
    assert not found, f"unit tables outside robocal/units.py: {found}"
    assert set(LENGTH_UNITS) >= {"m", "mm", "um"} and set(ANGLE_UNITS) >= {"rad", "deg"}
