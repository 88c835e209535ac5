"""The settings of a calibration, grouped in frozen option objects.

:func:`robocal.calibrate` accepts the groups (``joint_effects=JointEffects(level=3)``,
``weights=Weights(orientation=0.05)``, ``loss=RobustLoss("soft_l1")``...) or, as before,
their fields as plain keywords (``level=3``, ``orientation_weight=0.05``,
``loss="soft_l1"``): :meth:`CalibrationOptions.from_keywords` maps each keyword to its
group, and an unknown keyword is an error naming it.  Units: SI (m, rad).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike

from robocal.choices import BOUNDS_NAMES, LOSSES, Loss
from robocal.identify.rules import Rules
from robocal.model.chain import Model
from robocal.model.dynamics import Payload

__all__ = [
    "BOUNDS_CHOICES",
    "Bounds",
    "CalibrationOptions",
    "JointEffects",
    "PerPose",
    "Pruning",
    "RobustLoss",
    "Setup",
    "Weights",
]

#: ``bounds=`` of ``method="bounded"`` by name (:data:`robocal.choices.BOUNDS_NAMES`)
BOUNDS_CHOICES: tuple[str, ...] = BOUNDS_NAMES


@dataclass(frozen=True)
class Setup:
    """What is measured and what is known about the measurement set-up.

    measure: ``"position"`` or ``"pose"`` (None: pose when the data has orientations);
    frame: ``"fit"``, ``"fixed"`` or a known 4x4 ``T_device_base``; tool: ``"fit"``,
    ``"fixed"``, a known tool (position (3,) m or 4x4) or None (no tool); tool_guess: the
    tool's start value; max_iterations: the solver's budget (LM: ``max_iterations·(p+1)``
    evaluations)."""

    measure: Literal["position", "pose"] | None = None
    frame: Any = "fit"
    tool: Any = "fit"
    tool_guess: ArrayLike | None = None
    max_iterations: int = 200


@dataclass(frozen=True)
class Weights:
    """Row weights: ``by="sigma"`` weighs rows by 1/σ when the data states a noise;
    ``orientation`` (m per rad) weighs orientation rows against position rows."""

    by: Literal["sigma", "none"] = "sigma"
    orientation: float = 0.1

    def __post_init__(self) -> None:
        if self.by not in ("sigma", "none"):
            raise ValueError(f"weights must be 'sigma' or 'none', got {self.by!r}")


@dataclass(frozen=True)
class RobustLoss:
    """``method="lm"``'s loss: ``"linear"`` or a robust loss of scipy (``"soft_l1"``,
    ``"huber"``...) that down-weights residuals beyond ``f_scale`` (m)."""

    loss: Loss = "linear"
    f_scale: float = 1e-4

    def __post_init__(self) -> None:
        if self.loss not in LOSSES:  # the one table of robocal.choices, as the command line's
            raise ValueError(f"loss must be one of {', '.join(LOSSES)}, got {self.loss!r}")


@dataclass(frozen=True)
class Bounds:
    """``method="bounded"``'s bounds: ``"default"`` (seed 001, ±5 mm / ±2° around the
    start values), ``"widened"``, explicit ``(lower, upper)`` arrays over the free
    parameters, or None (unbounded)."""

    value: Any = "default"

    def __post_init__(self) -> None:
        if isinstance(self.value, str) and self.value not in BOUNDS_CHOICES:
            choices = ", ".join(BOUNDS_CHOICES)
            raise ValueError(f"bounds must be one of {choices}, two arrays or None, got {self.value!r}")


@dataclass(frozen=True)
class PerPose:
    """Settings of the per-pose methods (``pinv``, ``influence``): the measurement
    ``resolution`` (m, stop criterion), the relaxation C < 1, ``per_pose`` (``pinv``
    per pose), how per-pose sets combine and how many passes (None: until stable)."""

    resolution: float = 1e-5
    relaxation: float = 0.5
    per_pose: bool = False
    combine: Literal["mean", "best", "fit"] = "mean"
    passes: int | None = None


@dataclass(frozen=True)
class Pruning:
    """Unknowns whose σ as tool displacement exceeds ``max_std`` (m) and ``max_std_ratio``
    times the median are fixed and the fit repeated; before the fit, those beyond
    ``screen_margin`` times that threshold are fixed at once; ``significance``: each tail of
    the χ² test of a stated noise (the decision rules: :class:`robocal.identify.rules.Rules`)."""

    # the defaults are the rules' (defined once, in robocal.identify.rules)
    max_std: float = Rules.max_std
    max_std_ratio: float = Rules.max_std_ratio
    screen_margin: float = Rules.screen_margin
    significance: float = Rules.significance


@dataclass(frozen=True)
class JointEffects:
    """The non-geometric joint effects (:mod:`robocal.model.joints`).

    level: 1 (joint offsets), 2 (kinematic) or 3 (non-geometric; ``effects`` defaults to
    ``"identify"``), or a name; effects: ``"none"``, ``"predict"``, ``"identify"`` or a
    list of kinds; joints: the joints whose effects are identified (None: all);
    compliance: True or joint names (``effects=["compliance"]`` on those joints);
    gravity (m/s², base frame), payload, velocities and accelerations ``(n, dof)`` give
    the joint loads; load_passes: recompute the loads with the calibrated geometry until
    their signs stop changing, at most this many passes."""

    level: int | str | None = None
    effects: str | Sequence[str] | None = None
    joints: Sequence[str] | None = None
    compliance: bool | Sequence[str] = False
    gravity: tuple[float, float, float] = (0.0, 0.0, -9.81)
    payload: Payload | None = None
    velocities: ArrayLike | None = field(default=None, repr=False)
    accelerations: ArrayLike | None = field(default=None, repr=False)
    load_passes: int = 3

    def __post_init__(self) -> None:
        object.__setattr__(self, "gravity", tuple(float(g) for g in np.asarray(self.gravity, dtype=float)))
        if int(self.load_passes) < 1:
            raise ValueError(f"load_passes must be at least 1, got {self.load_passes}")


#: every plain keyword of rc.calibrate's physical fit: (group, field)
_KEYWORDS: dict[str, tuple[str, str]] = {
    "measure": ("setup", "measure"),
    "frame": ("setup", "frame"),
    "tool": ("setup", "tool"),
    "tool_guess": ("setup", "tool_guess"),
    "max_iterations": ("setup", "max_iterations"),
    "weights": ("weights", "by"),
    "orientation_weight": ("weights", "orientation"),
    "loss": ("loss", "loss"),
    "f_scale": ("loss", "f_scale"),
    "bounds": ("bounds", "value"),
    "resolution": ("per_pose", "resolution"),
    "relaxation": ("per_pose", "relaxation"),
    "per_pose": ("per_pose", "per_pose"),
    "combine": ("per_pose", "combine"),
    "passes": ("per_pose", "passes"),
    "max_std": ("pruning", "max_std"),
    "max_std_ratio": ("pruning", "max_std_ratio"),
    "level": ("joint_effects", "level"),
    "effects": ("joint_effects", "effects"),
    "effect_joints": ("joint_effects", "joints"),
    "compliance": ("joint_effects", "compliance"),
    "gravity": ("joint_effects", "gravity"),
    "payload": ("joint_effects", "payload"),
    "velocities": ("joint_effects", "velocities"),
    "accelerations": ("joint_effects", "accelerations"),
    "load_passes": ("joint_effects", "load_passes"),
}
_GROUPS: dict[str, type] = {
    "setup": Setup,
    "weights": Weights,
    "loss": RobustLoss,
    "bounds": Bounds,
    "per_pose": PerPose,
    "pruning": Pruning,
    "joint_effects": JointEffects,
}


@dataclass(frozen=True)
class CalibrationOptions:
    """Every setting of the physical fit, by group (defaults: ``rc.calibrate``'s)."""

    setup: Setup = Setup()
    weights: Weights = Weights()
    loss: RobustLoss = RobustLoss()
    bounds: Bounds = Bounds()
    per_pose: PerPose = PerPose()
    pruning: Pruning = Pruning()
    joint_effects: JointEffects = JointEffects()

    @classmethod
    def from_keywords(cls, options: CalibrationOptions | None = None, **keywords: Any) -> CalibrationOptions:
        """``options`` (default: the defaults) changed by ``keywords``: a group object by
        its name (``joint_effects=JointEffects(...)``, ``weights=Weights(...)``,
        ``loss=RobustLoss(...)``, ``bounds=Bounds(...)``...) or one of its fields by its
        plain name (``level=3``, ``loss="soft_l1"``, ``bounds="widened"``).

        Raises:
            TypeError: an unknown keyword (named), or a field given both ways.
        """
        base = options if options is not None else cls()
        if not keywords:
            return base
        groups = {name: getattr(base, name) for name in _GROUPS}
        given = {name: v for name, v in keywords.items() if isinstance(v, _GROUPS.get(name, ()))}
        groups.update(given)
        changes: dict[str, dict[str, Any]] = {}
        for name, value in keywords.items():
            if name in given:
                continue
            if name not in _KEYWORDS:
                known = ", ".join(sorted(set(_KEYWORDS) | set(_GROUPS)))
                raise TypeError(f"calibrate got an unknown option {name!r}; known options: {known}")
            group, attr = _KEYWORDS[name]
            if group in given:
                raise TypeError(f"option {name!r} given both on its own and in {group}=")
            changes.setdefault(group, {})[attr] = value
        for group, fields in changes.items():
            groups[group] = dataclasses.replace(groups[group], **fields)
        return cls(**groups)

    def keywords(self) -> dict[str, Any]:
        """The plain keywords that :meth:`from_keywords` maps back to these options."""
        return {name: getattr(getattr(self, g), a) for name, (g, a) in _KEYWORDS.items()}

    def replace(self, **keywords: Any) -> CalibrationOptions:
        """These options with some changed (as :meth:`from_keywords`)."""
        return CalibrationOptions.from_keywords(self, **keywords)


def check_load_model(load_model: Model, model: Model) -> Model:
    """``load_model`` (the geometry whose joint loads drive the joint effects) when its
    joints are ``model``'s."""
    if load_model.joint_names != model.joint_names:
        raise ValueError(
            f"load_model {load_model.name!r} has joints {load_model.joint_names}, model {model.name!r} "
            f"{model.joint_names}"
        )
    return load_model


def known_keywords() -> Mapping[str, tuple[str, str]]:
    """Plain keyword → (group, field)."""
    return dict(_KEYWORDS)
