"""What the tilt rows identified beyond the geometry, kept with the calibration (issue 33).

A constraint fit with inclinometer rows (:mod:`robocal.identify.constraints.tilt_rows`)
identifies a zero per channel and the joint effects (backlash, compliance, clearance when
asked) under the static gravity loads of the model's mass properties.  They are not part
of ``model.yaml`` (the exports and the compensated commands stay the geometry's: the
tracker, socket and plane rows of a mixed fit are predicted without them), so
``constraints.json`` records them by name (:meth:`TiltCalibration.to_doc`), and
:func:`tilt_calibration_of` reads them back; the tilt figures of a saved calibration
(``validate``, the report, the GUI's table) predict the readings with them.

Units: SI, stated in each key (``estimate_rad``, ``estimate_rad_per_Nm``): clearance and
backlash in rad, a compliance in rad/(N·m), a channel's zero in rad.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from robocal.model.joints import EFFECT_PREFIXES, effect_of

__all__ = [
    "LOADS",
    "TiltCalibration",
    "TiltEstimate",
    "channel_zero_array",
    "effect_summary_lines",
    "tilt_calibration_of",
    "tilt_estimates",
    "zero_channel",
]

#: the loads the joint effects were identified under (and are predicted with)
LOADS = "the static gravity loads (9.81 m/s² along the base's -z) of the model's masses, no payload"
_ZERO_PREFIX = "tilt_zero_"  # robocal.identify.constraints.tilt_rows.ZERO_PREFIX (no import circle)
#: the SI unit of each effect kind's value, as it appears in the record's keys
_UNIT_KEY = {"clearance": "rad", "backlash": "rad", "compliance": "rad_per_Nm", "radial": "rad_per_Nm"}


@dataclass(frozen=True)
class TiltEstimate:
    """One unknown of the tilt rows: a joint effect (``backlash_elbow``, rad;
    ``compliance_elbow``, rad/(N·m); ``clearance_elbow``, rad) or a channel's zero (its
    channel ``<joint>_<axis>``, rad), its value and 1σ (NaN: held, not estimated)."""

    name: str
    value: float
    std: float


@dataclass(frozen=True)
class TiltCalibration:
    """The joint effects and channel zeros a calibration identified from tilt rows.

    Attributes:
        effects: the identified joint effects (SI); the effects not identified were held
            at zero and are not listed (the calibration names them with the reason).
        zeros: each channel's zero (rad) by its channel name ``<joint>_<axis>``.
    """

    effects: tuple[TiltEstimate, ...] = ()
    zeros: tuple[TiltEstimate, ...] = ()

    @property
    def effect_values(self) -> dict[str, float]:
        """``{name: value}`` of the joint effects (SI)."""
        return {e.name: e.value for e in self.effects}

    @property
    def zero_values(self) -> dict[str, float]:
        """``{channel: zero}`` (rad)."""
        return {z.name: z.value for z in self.zeros}

    def to_doc(self) -> dict[str, Any]:
        """The record's keys in ``constraints.json`` (units in the keys; σ null when held)."""
        effects = []
        for e in self.effects:
            kind, joint = effect_of(e.name) or ("", "")
            unit = _UNIT_KEY[kind]
            effects.append({"name": e.name, "kind": kind, "joint": joint, f"estimate_{unit}": e.value,
                            f"std_{unit}": _finite_or_none(e.std)})  # fmt: skip
        zeros = [
            {"channel": z.name, "estimate_rad": z.value, "std_rad": _finite_or_none(z.std)}
            for z in self.zeros
        ]
        return {"joint_effects": effects, "joint_effect_loads": LOADS, "tilt_zeros": zeros}


def _finite_or_none(value: float) -> float | None:
    return float(value) if math.isfinite(value) else None


def zero_channel(name: str) -> str | None:
    """The channel (``<joint>_<axis>``) whose zero the unknown ``name`` is, None for any other
    unknown: the one reader of the channel zeros' name prefix (they are no step of a chain,
    so they have no role)."""
    return name[len(_ZERO_PREFIX) :] if name.startswith(_ZERO_PREFIX) else None


def tilt_estimates(
    names: Sequence[str], values: Iterable[float], std: Mapping[str, float]
) -> TiltCalibration:
    """The tilt unknowns among a fit's ``names`` with their ``values``: the joint effects
    that ``std`` (by name) holds (the estimated ones) and every channel zero (σ NaN when
    held at its start value, the channel's mean)."""
    effects, zeros = [], []
    for name, value in zip(names, values, strict=True):
        sigma = float(std.get(name, math.nan))
        if (channel := zero_channel(name)) is not None:
            zeros.append(TiltEstimate(channel, float(value), sigma))
        elif effect_of(name) is not None and name in std:
            effects.append(TiltEstimate(name, float(value), sigma))
    return TiltCalibration(tuple(effects), tuple(zeros))


def _number(value: Any, what: str, none_ok: bool = False) -> float:
    if value is None and none_ok:
        return math.nan
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise ValueError(f"{what}: not a finite number")
    return float(value)


def _effect(item: Any) -> TiltEstimate:
    if not isinstance(item, dict) or not isinstance(item.get("name"), str):
        raise ValueError("joint_effects: each entry needs a name")
    effect = effect_of(item["name"])
    if effect is None or effect[0] not in _UNIT_KEY:
        raise ValueError(f"joint_effects: {item['name']!r} is not a joint effect")
    unit = _UNIT_KEY[effect[0]]
    value = _number(item.get(f"estimate_{unit}"), f"joint_effects {item['name']}: estimate_{unit}")
    std = _number(item.get(f"std_{unit}"), f"joint_effects {item['name']}: std_{unit}", none_ok=True)
    return TiltEstimate(item["name"], value, std)


def _zero(item: Any) -> TiltEstimate:
    if not isinstance(item, dict) or not isinstance(item.get("channel"), str):
        raise ValueError("tilt_zeros: each entry needs a channel")
    value = _number(item.get("estimate_rad"), f"tilt_zeros {item['channel']}: estimate_rad")
    return TiltEstimate(item["channel"], value, _number(item.get("std_rad"), "tilt_zeros: std_rad", True))


def tilt_calibration_of(
    doc: dict, names: Sequence[str], estimates: Iterable[float], std: Iterable[float]
) -> TiltCalibration:
    """The record's joint effects and channel zeros (``doc``: ``constraints.json``); a
    folder written before they were recorded: those among its estimated ``names``
    (empty without tilt rows).  ValueError naming a malformed entry."""
    if "joint_effects" not in doc and "tilt_zeros" not in doc:
        sigma = dict(zip(names, (float(s) for s in std), strict=True))
        return tilt_estimates(names, estimates, sigma)
    effects, zeros = doc.get("joint_effects") or [], doc.get("tilt_zeros") or []
    if not isinstance(effects, list) or not isinstance(zeros, list):
        raise ValueError("joint_effects, tilt_zeros: lists expected")
    return TiltCalibration(tuple(_effect(e) for e in effects), tuple(_zero(z) for z in zeros))


def effect_summary_lines(
    tilt: TiltCalibration, dropped: Iterable[tuple[str, str]], source: str = "the tilt rows"
) -> list[str]:
    """The joint effects identified from ``source`` (the tilt rows, the position rows'
    deflections) as the tracker calibration prints them (± 1σ; backlash and clearance in
    deg, a compliance in µrad/(N·m) with its stiffness), those the data cannot tell from
    zero, and those not identified (by name, with the reason)."""
    from robocal.identify.effects import EFFECT_SIGNIFICANCE, effect_lines

    lines = []
    if tilt.effects:
        by_joint: dict[str, dict[str, tuple[float, float | None]]] = {}
        for e in tilt.effects:
            kind, joint = effect_of(e.name) or ("", "")
            std = e.std if math.isfinite(e.std) else None
            by_joint.setdefault(joint, {})[EFFECT_PREFIXES[kind][1]] = (e.value, std)
        lines.append(f"joint effects from {source} (± 1σ; under {LOADS}):")
        lines += [f"  {line}" for line in effect_lines(by_joint)]
        weak = [e.name for e in tilt.effects if not (e.value >= EFFECT_SIGNIFICANCE * e.std)]
        if weak:
            lines.append(
                f"  within {EFFECT_SIGNIFICANCE:g}σ of zero or below it (the rows cannot tell them from no "
                f"effect): {', '.join(weak)}"
            )
    held = [f"{name} ({reason})" for name, reason in dropped if effect_of(name) is not None]
    if held:
        lines.append(f"joint effects not identified, held at zero: {', '.join(held)}")
    return lines


def channel_zero_array(
    tilt: TiltCalibration | None, channels: Sequence[str]
) -> tuple[np.ndarray, np.ndarray]:
    """``(zeros, known)``: each of ``channels``' saved zero (rad; 0 where none) and whether
    one was saved."""
    saved = {} if tilt is None else tilt.zero_values
    known = np.array([c in saved for c in channels], dtype=bool)
    return np.array([saved.get(c, 0.0) for c in channels]), known
