"""Non-geometric joint effects: tilting from clearance, backlash and compliance (seed 003).

A joint with clearance, backlash and elasticity does not turn exactly about its
nominal axis: under the moments acting on it, it tilts and turns a little.  Seed 003
(ch. 4-5) models this per joint by three small rotations added in the joint frame,
the joint perturbations ``(δα, δβ, δθ)`` that :meth:`robocal.model.chain.Model.fk`
accepts (eq. 5.9)::

    δα = sign(ηx) · r sin γ / √((L/2)² + (r sin γ)²)          (5.17)
    δβ = sign(ηy) · r cos γ / √((L/2)² + (r cos γ)²)          (5.18)
    δθ = sign(ηz) · δθ_bkl + ηz / k_z                          (5.19)

with ``η = [ηx ηy ηz]`` the moment of the loads on the joint in its frame (eq. 4.21:
gravity, a payload and, along a trajectory, the inertial forces of eq. 5.14 —
:func:`load_moments`, from Pinocchio), ``r = (L/2) tan C`` the radial clearance of a
shaft of length ``L`` that can tilt by ``C = C_cle_tilt`` in its housing
(:func:`clearance_radius`, eqs. 4.11 and 5.15), ``γ = (π/2) |ηx| / (|ηx| + |ηy|)`` the
direction of the contact (eq. 5.16, :func:`contact_angle`), ``δθ_bkl`` the backlash and
``k_z`` the axial stiffness.  ``L`` cancels: ``r sin γ / √((L/2)² + (r sin γ)²) = s/√(1 +
s²)`` with ``s = tan C sin γ``, so the tilt depends on ``C`` alone (and the thesis'
expression is the sine of the tilt, equal to the angle within 1e-11 rad at C = 0.02°).
An optional radial compliance ``c_r`` adds the elastic tilts ``c_r ηx`` and ``c_r ηy``
(seed 003 names it and neglects it).  For a joint about ``x`` or ``y`` the same holds
with the axes in cyclic order (axis ``k``; tilts about ``k+1`` then ``k+2``); for a
prismatic joint ``ηz`` is replaced by the axial force.

Signs: the joint yields to its load, so η is the moment *of the loads* (seed 003 eq.
4.21), the negative of the support moment that :func:`robocal.model.dynamics.
joint_wrenches` returns.  A moment within ``deadband`` of zero has no sign: no
backlash turn, no clearance tilt (a vertical first joint carries no gravity torque).

Parameters per joint: :class:`~robocal.model.chain.JointEffects` (``model.joint_effects``,
the ``joint_effects`` section of model files; Table 5.2 for the Katana 450).

For identification every effect is linear in its parameter (to first order in ``C``
for the clearance: the error is below ``C³/2`` ≈ 4e-11 rad for C = 0.024°), so
:func:`effect_basis` gives one perturbation pattern per (kind, joint) whose
coefficient is the parameter: the calibration identifies them next to the geometric
parameters (:func:`robocal.identify.calibrate.calibrate`).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from robocal.model.chain import Model
from robocal.model.dynamics import Payload, joint_wrenches
from robocal.model.steps import JointEffects

__all__ = [
    "COMPLIANCE_UNIT",
    "EFFECT_KINDS",
    "EFFECT_PREFIXES",
    "STIFFNESS_UNIT",
    "JointEffects",
    "JointTilting",
    "clearance_radius",
    "clearance_tilt_angle",
    "contact_angle",
    "effect_basis",
    "effect_of",
    "effects_from_values",
    "joint_perturbations",
    "load_moments",
    "tilt_angles",
]

Array = NDArray[np.float64]
EffectKind = Literal["clearance", "backlash", "compliance", "radial"]
ContactRule = Literal["thesis", "direction"]

#: the non-geometric effects of a joint: clearance tilt, backlash, axial and radial compliance
EFFECT_KINDS: tuple[str, ...] = ("clearance", "backlash", "compliance", "radial")
#: kind -> coefficient-name prefix (``clearance_q2`` ...) and the JointEffects field it sets
EFFECT_PREFIXES: dict[str, tuple[str, str]] = {
    "clearance": ("clearance_", "clearance_tilt"),
    "backlash": ("backlash_", "backlash"),
    "compliance": ("compliance_", "compliance"),
    "radial": ("radial_compliance_", "radial_compliance"),
}
#: how robocal shows a joint's compliance and stiffness, everywhere (CLI summary, report):
#: (unit, display value per SI value of rad/(N·m) resp. N·m/rad)
COMPLIANCE_UNIT = ("µrad/(N·m)", 1e6)
STIFFNESS_UNIT = ("kN·m/rad", 1e-3)
DEADBAND = 1e-9  # N·m (N): a load this small has no sign


def effect_of(name: str) -> tuple[str, str] | None:
    """``(kind, joint)`` of a joint-effect coefficient as :func:`joint_perturbations`
    names it (``"compliance_q2"`` -> ``("compliance", "q2")``); None for a parameter of
    the chain.  The one reader of those names: everything else asks it."""
    for kind, (prefix, _) in sorted(EFFECT_PREFIXES.items(), key=lambda item: -len(item[1][0])):
        if name.startswith(prefix):
            return kind, name[len(prefix) :]
    return None


# ------------------------------------------------------------------ clearance geometry
def clearance_tilt_angle(radius: ArrayLike, shaft_length: ArrayLike) -> Array:
    """Tilt ``C = asin(R / √((L/2)² + R²))`` (rad) of a shaft of length ``L`` (m) with
    radial clearance ``R = (D1 − D2)/2`` (m) in its housing (seed 003 eq. 4.11)."""
    R = np.asarray(radius, dtype=float)
    half = 0.5 * np.asarray(shaft_length, dtype=float)
    return np.arcsin(R / np.sqrt(half**2 + R**2))


def clearance_radius(tilt: ArrayLike, shaft_length: ArrayLike) -> Array:
    """Radial clearance ``r = (L/2) / √(1/sin²C − 1) = (L/2) tan C`` (m) of a shaft of
    length ``L`` (m) that tilts by ``C`` (rad) (seed 003 eq. 5.15, the inverse of 4.11)."""
    return 0.5 * np.asarray(shaft_length, dtype=float) * np.tan(np.asarray(tilt, dtype=float))


def _sign(x: Array, deadband: float) -> Array:
    return np.where(np.abs(x) > deadband, np.sign(x), 0.0)


def _flank(x: Array, deadband: float, band: float | None) -> Array:
    """The flank a load ``x`` presses on: its sign, or with ``band`` (N·m, N) the ramp
    ``clip(x / band, -1, 1)`` across it (continuous: see :func:`joint_perturbations`)."""
    if band is None:
        return _sign(x, deadband)
    return np.clip(x / max(float(band), deadband), -1.0, 1.0)


def contact_angle(
    eta_x: ArrayLike, eta_y: ArrayLike, rule: ContactRule = "thesis", deadband: float = DEADBAND
) -> Array:
    """Direction ``γ`` (rad, in [0, π/2]) of the shaft's contact in its housing.

    ``rule="thesis"``: seed 003 eq. 5.16, ``γ = (π/2) |ηx| / (|ηx| + |ηy|)``.
    ``rule="direction"``: ``γ = atan2(|ηx|, |ηy|)``, so that the tilt ``(δα, δβ)`` points
    exactly along the moment ``(ηx, ηy)`` (the thesis' linear ratio bends it by up to 4°).
    Zero where both moments are within ``deadband`` (no load, no contact).
    """
    ax, ay = np.abs(np.asarray(eta_x, dtype=float)), np.abs(np.asarray(eta_y, dtype=float))
    if rule == "thesis":
        total = ax + ay
        with np.errstate(invalid="ignore", divide="ignore"):
            gamma = np.where(total > deadband, 0.5 * math.pi * ax / np.where(total > 0, total, 1.0), 0.0)
    elif rule == "direction":
        gamma = np.arctan2(ax, ay)
    else:
        raise ValueError(f"contact rule must be 'thesis' or 'direction', got {rule!r}")
    return gamma


def tilt_angles(
    clearance_tilt: ArrayLike,
    eta_x: ArrayLike,
    eta_y: ArrayLike,
    rule: ContactRule = "thesis",
    deadband: float = DEADBAND,
) -> tuple[Array, Array]:
    """Clearance tilts ``(δα, δβ)`` (rad) about the joint frame's x and y axes (seed 003
    eqs. 5.16-5.18) for the tilt ``C`` (rad) and the load moments ``ηx, ηy`` (N·m).

    ``r sin γ / √((L/2)² + (r sin γ)²)`` with ``r = (L/2) tan C`` is evaluated as
    ``s / √(1 + s²)``, ``s = tan C sin γ`` (the shaft length cancels).
    """
    C = np.asarray(clearance_tilt, dtype=float)
    ex, ey = np.asarray(eta_x, dtype=float), np.asarray(eta_y, dtype=float)
    gamma = contact_angle(ex, ey, rule, deadband)
    t = np.tan(C)
    sx, sy = t * np.sin(gamma), t * np.cos(gamma)
    loaded = (np.abs(ex) + np.abs(ey)) > deadband
    alpha = np.where(loaded, _sign(ex, deadband) * sx / np.sqrt(1 + sx**2), 0.0)
    beta = np.where(loaded, _sign(ey, deadband) * sy / np.sqrt(1 + sy**2), 0.0)
    return alpha, beta


# ------------------------------------------------------------------ loads
def load_moments(
    model: Model,
    q: ArrayLike,
    qd: ArrayLike | None = None,
    qdd: ArrayLike | None = None,
    *,
    gravity: ArrayLike | None = None,
    payload: Payload | None = None,
) -> Array:
    """Seed 003's η: the load on each joint in its joint frame, ``(n, dof, 3)``.

    Columns in the joint's own cyclic axis order ``(u, w, k)``: the load moments
    (N·m) about the two axes perpendicular to the joint axis ``k`` (x, y for a joint
    about z) and the load about the axis itself (the moment for a revolute joint, the
    force (N) for a prismatic one).  The load is the negative of the support wrench of
    :func:`~robocal.model.dynamics.joint_wrenches` (Pinocchio RNEA): gravity, the
    payload and, with ``qd``/``qdd``, the inertial forces (eq. 5.14).
    """
    W = joint_wrenches(model, q, qd, qdd, gravity=gravity, payload=payload)
    single = W.ndim == 2
    if single:
        W = W[None]
    out = np.empty(W.shape[:2] + (3,))
    steps = [s for s in model.steps if s.joint is not None]
    for j, step in enumerate(steps):
        k = step.axis
        u, w = (k + 1) % 3, (k + 2) % 3
        out[:, j, 0] = -W[:, j, 3 + u]
        out[:, j, 1] = -W[:, j, 3 + w]
        out[:, j, 2] = -W[:, j, 3 + k] if step.is_rotation else -W[:, j, k]
    return out[0] if single else out


def _effects_by_joint(model: Model, effects: Iterable[JointEffects] | None) -> dict[int, JointEffects]:
    chosen = model.joint_effects if effects is None else tuple(effects)
    out = {}
    for e in chosen:
        if not isinstance(e, JointEffects):
            raise TypeError(f"joint effects must be JointEffects, got {e!r}")
        if e.joint not in model.joint_names:
            raise ValueError(f"joint effects refer to joint {e.joint!r}, which model {model.name!r} lacks")
        out[model.joint_names.index(e.joint)] = e
    return out


def _check_kinds(kinds: Iterable[str]) -> tuple[str, ...]:
    kinds = tuple(kinds)
    unknown = set(kinds) - set(EFFECT_KINDS)
    if unknown:
        raise ValueError(f"unknown joint effect(s) {sorted(unknown)}; choose from {', '.join(EFFECT_KINDS)}")
    return kinds


def joint_perturbations(  # noqa: PLR0913 - the load model's keyword-only options, as load_moments
    model: Model,
    q: ArrayLike,
    qd: ArrayLike | None = None,
    qdd: ArrayLike | None = None,
    *,
    effects: Iterable[JointEffects] | None = None,
    kinds: Iterable[str] = EFFECT_KINDS,
    gravity: ArrayLike | None = None,
    payload: Payload | None = None,
    rule: ContactRule = "thesis",
    deadband: float = DEADBAND,
    loads: ArrayLike | None = None,
    flank_band: ArrayLike | None = None,
) -> Array:
    """Joint perturbations ``(n, dof, 3)`` = (δα, δβ, δθ) (rad; δθ in m for a prismatic
    joint) of the joint effects at joint values ``q`` (seed 003 eqs. 5.15-5.19).

    Args:
        model: the chain with mass properties.
        q, qd, qdd: ``(n, dof)`` joint values, velocities and accelerations (static
            when ``qd``/``qdd`` are omitted).
        effects: per-joint parameters (default: ``model.joint_effects``).
        kinds: which effects to include (``clearance``, ``backlash``, ``compliance``,
            ``radial``), e.g. ``("compliance",)`` for the stiffness alone.
        gravity: gravity in the base frame (m/s², default ``[0, 0, -9.81]``).
        payload: a load on the tool.
        rule: contact direction rule (:func:`contact_angle`).
        deadband: loads within this of zero have no sign.
        loads: precomputed :func:`load_moments` ``(n, dof, 3)`` (then ``qd``, ``qdd``,
            ``gravity`` and ``payload`` are not used).
        flank_band: ``(dof, 2)`` loads (N·m; N for a prismatic joint's axial force)
            within which the flank is not known, per joint: the moment across the axis
            (clearance) and the load about it (backlash).  Given, the sign of eqs.
            5.17-5.19 becomes the ramp ``clip(η / band, -1, 1)`` (clearance: the tilt
            scaled by ``min(|(ηx, ηy)| / band, 1)``), so the perturbations are continuous
            in ``q`` (the mid-flank at zero load); None: the thesis' sign (default).

    The result plugs into ``model.fk(q, perturbations=...)``.
    """
    kinds = _check_kinds(kinds)
    q_arr = np.atleast_2d(np.asarray(q, dtype=float))
    by_joint = _effects_by_joint(model, effects)
    bands = None if flank_band is None else np.asarray(flank_band, dtype=float).reshape(model.dof, 2)
    out = np.zeros((len(q_arr), model.dof, 3))
    if not by_joint or not kinds:
        return out
    eta = (
        load_moments(model, q_arr, qd, qdd, gravity=gravity, payload=payload)
        if loads is None
        else np.asarray(loads, dtype=float).reshape(len(q_arr), model.dof, 3)
    )
    for j, e in by_joint.items():
        eu, ew, ek = eta[:, j, 0], eta[:, j, 1], eta[:, j, 2]
        if "clearance" in kinds and e.clearance_tilt:
            a, b = tilt_angles(e.clearance_tilt, eu, ew, rule, deadband)
            if bands is not None:  # the contact's direction fades out with the moment
                scale = _flank(np.hypot(eu, ew), deadband, float(bands[j, 0]))
                a, b = a * scale, b * scale
            out[:, j, 0] += a
            out[:, j, 1] += b
        if "radial" in kinds and e.radial_compliance:
            out[:, j, 0] += e.radial_compliance * eu
            out[:, j, 1] += e.radial_compliance * ew
        if "backlash" in kinds and e.backlash:
            out[:, j, 2] += e.backlash * _flank(ek, deadband, None if bands is None else float(bands[j, 1]))
        if "compliance" in kinds and e.compliance:
            out[:, j, 2] += e.compliance * ek
    return out


# ------------------------------------------------------------------ identification
def effect_basis(  # noqa: PLR0913 - the load model's keyword-only options, as load_moments
    model: Model,
    q: ArrayLike,
    qd: ArrayLike | None = None,
    qdd: ArrayLike | None = None,
    *,
    kinds: Iterable[str] = ("clearance", "backlash", "compliance"),
    joints: Sequence[str] | None = None,
    gravity: ArrayLike | None = None,
    payload: Payload | None = None,
    rule: ContactRule = "thesis",
    deadband: float = DEADBAND,
    loads: ArrayLike | None = None,
) -> tuple[Array, tuple[str, ...], tuple[tuple[str, str], ...]]:
    """Joint-effect patterns with unknown coefficients, for identification.

    For each kind and joint, ``B (n, dof, 3)`` such that the joint perturbation of the
    effect is ``value × B``: clearance (value ``C``, rad): ``δα = sign(ηx) sin γ``,
    ``δβ = sign(ηy) cos γ`` (first order in C); backlash (rad): ``δθ = sign(ηz)``;
    compliance (rad/(N·m)): ``δθ = ηz``; radial compliance: ``δα = ηx, δβ = ηy``.

    Returns:
        ``basis (m, n, dof, 3)``, coefficient names (``clearance_q2``, ``backlash_q2``,
        ``compliance_q2``, ``radial_compliance_q2``) and ``(kind, joint)`` per pattern.
        A pattern is zero at every pose where its load is (e.g. the axial gravity load
        of a vertical joint): the calibration reports it as having no effect.
    """
    kinds = _check_kinds(kinds)
    q_arr = np.atleast_2d(np.asarray(q, dtype=float))
    names = model.joint_names if joints is None else tuple(joints)
    unknown = set(names) - set(model.joint_names)
    if unknown:
        raise ValueError(f"joint effects: model {model.name!r} has no joint(s) {sorted(unknown)}")
    n, dof = q_arr.shape
    eta = (
        load_moments(model, q_arr, qd, qdd, gravity=gravity, payload=payload)
        if loads is None
        else np.asarray(loads, dtype=float).reshape(n, dof, 3)
    )
    basis, coef_names, which = [], [], []
    for kind in kinds:
        for name in names:
            j = model.joint_names.index(name)
            eu, ew, ek = eta[:, j, 0], eta[:, j, 1], eta[:, j, 2]
            B = np.zeros((n, dof, 3))
            if kind == "clearance":
                gamma = contact_angle(eu, ew, rule, deadband)
                loaded = (np.abs(eu) + np.abs(ew)) > deadband
                B[:, j, 0] = np.where(loaded, _sign(eu, deadband) * np.sin(gamma), 0.0)
                B[:, j, 1] = np.where(loaded, _sign(ew, deadband) * np.cos(gamma), 0.0)
            elif kind == "backlash":
                B[:, j, 2] = _sign(ek, deadband)
            elif kind == "compliance":
                B[:, j, 2] = np.where(np.abs(ek) > deadband, ek, 0.0)
            else:
                B[:, j, 0] = np.where(np.abs(eu) > deadband, eu, 0.0)
                B[:, j, 1] = np.where(np.abs(ew) > deadband, ew, 0.0)
            basis.append(B)
            coef_names.append(EFFECT_PREFIXES[kind][0] + name)
            which.append((kind, name))
    return (
        np.array(basis) if basis else np.zeros((0, n, dof, 3)),
        tuple(coef_names),
        tuple(which),
    )


def effects_from_values(
    model: Model,
    values: dict[tuple[str, str], float],
    start: Iterable[JointEffects] | None = None,
) -> tuple[JointEffects, ...]:
    """Per-joint :class:`JointEffects` from ``{(kind, joint): value}`` (SI), the other
    fields taken from ``start`` (default ``model.joint_effects``; zero when absent)."""
    base = {e.joint: e for e in (model.joint_effects if start is None else start)}
    fields: dict[str, dict[str, Any]] = {}
    for (kind, joint), value in values.items():
        if kind not in EFFECT_PREFIXES:
            raise ValueError(f"unknown joint effect {kind!r}")
        fields.setdefault(joint, {})[EFFECT_PREFIXES[kind][1]] = float(value)
    out = []
    for name in model.joint_names:
        if name not in base and name not in fields:
            continue
        e = base.get(name, JointEffects(name))
        new = JointEffects(
            joint=name,
            clearance_tilt=fields.get(name, {}).get("clearance_tilt", e.clearance_tilt),
            backlash=fields.get(name, {}).get("backlash", e.backlash),
            compliance=fields.get(name, {}).get("compliance", e.compliance),
            radial_compliance=fields.get(name, {}).get("radial_compliance", e.radial_compliance),
            shaft_length=e.shaft_length,
        )
        values_ = (new.clearance_tilt, new.backlash, new.compliance, new.radial_compliance)
        if any(values_) or new.shaft_length is not None:  # a joint without effects is left out
            out.append(new)
    return tuple(out)


# ------------------------------------------------------------------ virtual robot hook
@dataclass(frozen=True)
class JointTilting:
    """A joint effect for :class:`robocal.measure.simulate.VirtualRobot`: the joint
    effects of the (true) model under gravity and a payload, static poses.

    ``effect(model, q) -> (n, dof, 3)``; with ``effects=None`` the model's own
    ``joint_effects`` are used, so a true model drawn from a catalog robot with joint
    effects brings them along.

    Attributes:
        effects: per-joint parameters, or None for ``model.joint_effects``.
        kinds: which effects (default all).
        gravity: base frame, m/s².
        payload: a load on the tool, or None.
        rule: contact direction rule (:func:`contact_angle`).
    """

    effects: tuple[JointEffects, ...] | None = None
    kinds: tuple[str, ...] = EFFECT_KINDS
    gravity: tuple[float, float, float] = (0.0, 0.0, -9.81)
    payload: Payload | None = None
    rule: ContactRule = "thesis"

    def __post_init__(self) -> None:
        object.__setattr__(self, "kinds", _check_kinds(self.kinds))
        if self.effects is not None:
            object.__setattr__(self, "effects", tuple(self.effects))
        object.__setattr__(self, "gravity", tuple(float(g) for g in self.gravity))

    def __call__(self, model: Model, q: Array) -> Array:
        return joint_perturbations(
            model,
            q,
            effects=self.effects,
            kinds=self.kinds,
            gravity=np.asarray(self.gravity),
            payload=self.payload,
            rule=self.rule,
        )

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> JointTilting:
        """The inverse of :meth:`to_dict` (SI values), for simulation truth files."""
        effects = data.get("effects")
        payload = data.get("payload")
        return cls(
            effects=None if effects is None else tuple(JointEffects(**e) for e in effects),
            kinds=tuple(data.get("kinds", EFFECT_KINDS)),
            gravity=tuple(data.get("gravity", (0.0, 0.0, -9.81))),
            payload=None
            if payload is None
            else Payload(
                payload["mass"],
                tuple(payload.get("com", (0.0, 0.0, 0.0))),
                None if payload.get("inertia") is None else tuple(payload["inertia"]),
            ),
            rule=data.get("rule", "thesis"),
        )

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {
            "type": "joint-tilting",
            "kinds": list(self.kinds),
            "gravity": list(self.gravity),
            "rule": self.rule,
        }
        if self.effects is not None:
            from robocal.model.files import effects_to_dict

            out["effects"] = [effects_to_dict(e) for e in self.effects]
        if self.payload is not None:
            out["payload"] = {
                "mass": self.payload.mass,
                "com": list(self.payload.com),
                **({"inertia": list(self.payload.inertia)} if self.payload.inertia else {}),
            }
        return out
