"""Joint-effect coefficients (clearance tilt, backlash, compliance: seed 003 ch. 5) once
estimated: their units, whether an estimate stands (:func:`effect_verdict`) and which to
hold at their start values (:func:`effects_to_hold`).

Its own module so that the calibration (:mod:`robocal.identify.calibrate`) and the learned
residual's refits (:mod:`robocal.identify.residual.stage`) share it without importing each other.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from robocal.model.chain import Model
from robocal.model.joints import EFFECT_PREFIXES, effect_of
from robocal.model.rank import Dropped

__all__ = [
    "COMPLIANCE_PREFIX",
    "EFFECT_SIGNIFICANCE",
    "EffectPlan",
    "display_unit",
    "effect_lines",
    "effect_plan",
    "effect_verdict",
    "effects_to_hold",
    "parameter_unit",
]

Array = NDArray[np.float64]


#: the name prefix of axial compliance coefficients (robocal.model.joints.EFFECT_PREFIXES)
COMPLIANCE_PREFIX = EFFECT_PREFIXES["compliance"][0]
_EFFECT_UNITS = {  # effect kind -> (SI unit, display factor, display unit)
    "radial": ("rad/(N·m)", 1e6, "µrad/(N·m)"),
    "compliance": ("rad/(N·m)", 1e6, "µrad/(N·m)"),
    "clearance": ("rad", math.degrees(1), "deg"),
    "backlash": ("rad", math.degrees(1), "deg"),
}


def parameter_unit(name: str, rotation: bool) -> str:
    """The SI unit of an estimated parameter (``m``, ``rad``, ``rad/(N·m)``)."""
    effect = effect_of(name)
    if effect is not None:
        return _EFFECT_UNITS[effect[0]][0]
    return "rad" if rotation else "m"


def display_unit(name: str, rotation: bool) -> tuple[float, str]:
    """Factor and unit to show an estimated parameter (mm, deg, µrad/(N·m))."""
    effect = effect_of(name)
    if effect is not None:
        return _EFFECT_UNITS[effect[0]][1:]
    return (math.degrees(1), "deg") if rotation else (1e3, "mm")


def effect_lines(effects: dict[str, dict[str, tuple[float, float | None]]]) -> list[str]:
    """Human-readable joint-effect parameters: tilts in deg, compliances in µrad/(N·m) with
    the stiffness in kN·m/rad (robocal's one convention, as in the report)."""
    from robocal.model.joints import COMPLIANCE_UNIT, STIFFNESS_UNIT

    (cu, ck), (su, sk) = COMPLIANCE_UNIT, STIFFNESS_UNIT

    def pm(s: float | None, f: float, fmt: str) -> str:
        return "" if s is None else f" ± {s * f:{fmt}}"

    lines = []
    for joint, row in effects.items():
        parts = []
        for attr, (v, s) in row.items():
            if attr in ("clearance_tilt", "backlash"):
                parts.append(f"{attr} {math.degrees(v):.4f}{pm(s, math.degrees(1), '.4f')} deg")
                continue
            parts.append(f"{attr} {v * ck:.4g}{pm(s, ck, '.3g')} {cu}")
            if v > 0:  # the stiffness k = 1/c; its 1σ interval [1/(c + σ), 1/(c − σ)] is skewed
                label = "stiffness" if attr == "compliance" else "radial stiffness"
                interval = ""
                if s is not None and v > s:
                    interval = f" (1σ: {sk / (v + s):.4g}-{sk / (v - s):.4g})"
                parts.append(f"{label} {sk / v:.4g}{interval} {su}")
        lines.append(f"{joint}: " + ", ".join(parts))
    return lines


#: an identified joint effect (clearance tilt, backlash, compliance: physically >= 0) lies at
#: least this many standard deviations above zero; otherwise it is not identified
EFFECT_SIGNIFICANCE = 3.0


def effect_verdict(
    name: str,
    value: float,
    sigma: float,
    start: float = 0.0,
    peak_load: float | None = None,
    significance: float = EFFECT_SIGNIFICANCE,
    confounder: str | None = None,
) -> Dropped | None:
    """Whether a joint-effect coefficient's estimate may be reported as identified.

    Clearance tilts, backlashes and compliances are physically ≥ 0.  An estimate below
    zero is ``"unphysical"``; one less than ``significance`` σ above zero is
    ``"undetermined"`` — the data cannot tell it from zero, and its stiffness 1/c would
    be meaningless (σ_k = σ_c/c² understates the spread: seed 003's Katana q5, 57 ± 23
    µrad/(N·m) for a true 22, read as a stiffness of 31 ± 12 kgf·m/deg for a true 80).
    Either way the coefficient is kept at its ``start`` value.  ``peak_load``: the joint's
    largest load at the measured poses (N·m), quoted for compliances (a small load is the
    usual reason); ``confounder``: what else was fitted that explains the same errors
    (the learned joint angle errors).  Returns None when the estimate stands."""
    if np.isfinite(value) and np.isfinite(sigma) and value >= 0.0 and value >= significance * sigma:
        return None
    f, unit = display_unit(name, False)
    fitted = f"the fit with {confounder}" if confounder else "the fit"
    fit = f"{fitted} gave {value * f:.3g} ± {sigma * f:.2g} {unit}"
    kept = f"kept at its start value {start * f:.3g} {unit}"
    if value < 0:
        return Dropped(name, "unphysical", detail=f"{fit}: below zero, not physical; {kept}")
    if confounder:
        why = f"within {significance:g}σ of zero: {confounder} explain the same errors"
    else:
        why = f"within {significance:g}σ of zero: the data cannot tell it from zero"
        if peak_load is not None and (effect_of(name) or ("",))[0] in ("compliance", "radial"):
            why += f" (the joint's load reaches {peak_load:.3g} N·m at these poses; more load would tell)"
    return Dropped(name, "undetermined", detail=f"{fit}: {why}; {kept}")


def effects_to_hold(
    names: Sequence[str],
    x: Array,
    covariance: Array,
    start: dict[str, float],
    peak_load: dict[str, float] | None = None,
    confounder: str | None = None,
) -> tuple[Array, list[Dropped]]:
    """The joint-effect coefficients (``start``'s keys, physically ≥ 0) to hold at their
    start values, and the other estimates once they are held.

    An active set on the linearised problem: the least supported coefficient that
    :func:`effect_verdict` rejects is held, the others move to their conditional mean
    ``x − Σ_k (x_k − start_k) / Σ_kk`` with covariance ``Σ − Σ_k Σ_kᵀ / Σ_kk`` (what a
    Gauss-Newton refit with it fixed gives), and the next is judged — one refit at the
    end instead of one per coefficient.

    Args:
        names, x, covariance: the estimated parameters ``(p,)``, SI, and their ``(p, p)``
            covariance.
        start: start value of each joint-effect coefficient among ``names``.
        peak_load, confounder: passed to :func:`effect_verdict`.

    Returns:
        ``x`` conditioned on the held coefficients (the held ones at their start values)
        and one :class:`Dropped` per held coefficient, in the order they were held.
    """
    x, C = np.array(x, dtype=float), np.array(covariance, dtype=float)
    active = [k for k, n in enumerate(names) if n in start]
    held: list[Dropped] = []
    while active:
        sigma = np.sqrt(np.maximum(np.diag(C), 0.0))
        verdicts = {}
        for k in active:
            verdict = effect_verdict(
                names[k], float(x[k]), float(sigma[k]), start[names[k]], (peak_load or {}).get(names[k]),
                confounder=confounder,
            )  # fmt: skip
            if verdict is not None:
                verdicts[k] = verdict
        if not verdicts:
            break
        k = min(verdicts, key=lambda i: float(x[i]) / max(float(sigma[i]), 1e-300))
        held.append(verdicts[k])
        active.remove(k)
        if C[k, k] > 0:
            gain = C[:, k] / C[k, k]
            x = x - gain * (x[k] - start[names[k]])
            C = C - np.outer(gain, C[k])
        x[k] = start[names[k]]
        C[k, :] = C[:, k] = 0.0
    return x, held


@dataclass(frozen=True)
class EffectPlan:
    """What a calibration does with joint effects (:func:`effect_plan`)."""

    mode: str  # "none" | "predict" | "identify"
    kinds: tuple[str, ...]  # identified kinds
    joints: tuple[str, ...] | None  # identified joints (None: all)


def effect_plan(
    model: Model, level: int | None, effects: str | Sequence[str] | None, compliance: bool | Sequence[str]
) -> EffectPlan:
    from robocal.model.joints import EFFECT_KINDS

    if compliance and effects is not None:
        raise ValueError("give either compliance=... or effects=..., not both")
    if compliance:
        joints = None if compliance is True else tuple(compliance)
        return EffectPlan("identify", ("compliance",), joints)
    if effects is None:
        effects = "identify" if level == 3 else "none"
    if isinstance(effects, str):
        if effects == "none":
            return EffectPlan("none", (), None)
        if effects == "predict":
            if not model.joint_effects:
                raise ValueError(
                    f"effects='predict' needs measured joint parameters, but model {model.name!r} has no "
                    "joint_effects (give them in the model file's joint_effects section, or use "
                    "effects='identify')"
                )
            return EffectPlan("predict", (), None)
        if effects == "identify":
            return EffectPlan("identify", ("clearance", "backlash", "compliance"), None)
        effects = [effects]
    kinds = tuple(effects)
    unknown = set(kinds) - set(EFFECT_KINDS)
    if unknown:
        raise ValueError(
            f"effects: unknown {sorted(unknown)}; use 'none', 'predict', 'identify' or kinds from "
            f"{', '.join(EFFECT_KINDS)}"
        )
    return EffectPlan("identify", kinds, None)
