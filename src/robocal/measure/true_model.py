"""Quantities with units and a "real" robot drawn around a nominal model.

* :func:`parse_quantity` / :func:`parse_quantity_option`: ``"0.5mm"``, ``"0.05deg"`` or a
  bare SI number -> SI (m or rad).
* :func:`draw_true_model`: every free parameter deviating by a random amount within its
  tolerance (default ±0.5 mm for lengths and ±0.05° for angles, uniform in ±tol;
  ``distribution="normal"`` draws normal errors with 1-sigma = tol).

Part of :mod:`robocal.measure.simulate`, which re-exports them.
"""

from __future__ import annotations

import math
import re
from collections.abc import Iterable, Mapping
from typing import Literal

import numpy as np

from robocal.choices import Distribution
from robocal.model.chain import Model
from robocal.units import ANGLE_UNITS, LENGTH_UNITS, SPELLINGS

__all__ = ["draw_true_model", "parse_quantity", "parse_quantity_option"]

_QUANTITY = re.compile(r"^\s*([+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?)\s*([A-Za-zµμ°]*)\s*$")


def parse_quantity_option(value: str, kind: Literal["length", "angle"], option: str) -> float:
    """A command-line length (m) or angle (rad): text that must carry its unit
    (``0.02mm``, ``0.05deg``); a bare number is an error, since on a command line it is
    as likely meant in mm or degrees as in SI units."""
    m = _QUANTITY.match(value)
    if m is not None and not m.group(2) and float(m.group(1)) != 0.0:
        example = f"{value}mm" if kind == "length" else f"{value}deg"
        raise ValueError(f"{option} {value}: give the unit, e.g. {example}")
    try:
        return parse_quantity(value, kind)
    except ValueError as err:
        raise ValueError(f"{option}: {err}") from None


def parse_quantity(value: str | float, kind: Literal["length", "angle"]) -> float:
    """A length (m) or angle (rad) from a number (already SI) or text with a unit.

    Lengths: ``m``, ``mm``, ``um``/``µm``; angles: ``rad``, ``mrad``, ``urad``,
    ``deg``/``°``.  ``parse_quantity("0.02mm", "length") == 2e-5``.  A bare number in
    text is SI.
    """
    if not isinstance(value, str):
        out = float(value)
    else:
        m = _QUANTITY.match(value)
        units = LENGTH_UNITS if kind == "length" else ANGLE_UNITS
        unit = SPELLINGS.get(m.group(2), m.group(2)) if m is not None else None
        if m is None or (unit and unit not in units):
            raise ValueError(
                f"{value!r} is not a {kind} such as {'0.02mm' if kind == 'length' else '0.05deg'} "
                f"(units: {', '.join(units)})"
            )
        out = float(m.group(1)) * (units[unit] if unit else 1.0)
    if not math.isfinite(out):
        raise ValueError(f"{kind} {value!r} is not finite")
    return out


def draw_true_model(
    model: Model,
    tolerances: Mapping[str, float | str] | None = None,
    *,
    length: float | str = 0.5e-3,
    angle: float | str = math.radians(0.05),
    distribution: Distribution = "uniform",
    seed: int | np.random.Generator | None = None,
    params: Literal["free", "all"] | Iterable[str] = "free",
) -> Model:
    """A model whose parameters deviate randomly from ``model``'s (the "real" robot).

    Args:
        model: the nominal model.
        tolerances: per-parameter tolerances by name, SI numbers or text with a unit,
            e.g. ``{"theta2": "0.2deg", "d1": 1e-3}``; they override ``length`` and
            ``angle`` and also select a fixed parameter when ``params="free"``.
        length: tolerance of length parameters (m, or text such as ``"0.5mm"``).
        angle: tolerance of angle parameters (rad, or text such as ``"0.05deg"``).
        distribution: ``"uniform"``: deviation uniform in ``[-tol, tol]``;
            ``"normal"``: normal with standard deviation ``tol``.
        seed: seed or Generator; the same seed gives the same model.
        params: which parameters deviate: ``"free"`` (default; the ones identification
            may change), ``"all"``, or a list of names.

    Returns:
        A new model with the same structure (free flags, bounds, joints) and drawn values.
    """
    if distribution not in ("uniform", "normal"):
        raise ValueError(f"distribution must be 'uniform' or 'normal', got {distribution!r}")
    tol_len = parse_quantity(length, "length")
    tol_ang = parse_quantity(angle, "angle")
    overrides: dict[str, float] = {}
    for name, value in (tolerances or {}).items():
        step = model.step(name)  # KeyError naming the parameter and the model
        overrides[name] = parse_quantity(value, "angle" if step.is_rotation else "length")
    if params == "free":
        names = [*model.free_names, *(n for n in overrides if n not in model.free_names)]
    elif params == "all":
        names = list(model.names)
    else:
        names = list(params)
        for n in names:
            model.step(n)
    tol = np.array(
        [overrides.get(n, tol_ang if model.step(n).is_rotation else tol_len) for n in names], dtype=float
    )
    if np.any(tol < 0):
        raise ValueError("tolerances must be >= 0")
    rng = np.random.default_rng(seed)
    if distribution == "uniform":
        delta = rng.uniform(-1.0, 1.0, len(names)) * tol
    else:
        delta = rng.standard_normal(len(names)) * tol
    values = model.values
    index = {n: i for i, n in enumerate(model.names)}
    return model.with_values({n: values[index[n]] + d for n, d in zip(names, delta, strict=True)})
