"""Clearance, backlash and compliance from inclinometer readings (seed 003 §4.4.1, §5.3).

The thesis reads, per joint, the change of an inclinometer between configuration pairs
chosen one joint at a time (Figs. 4.6, 5.4): the clearance tilt ``C`` from a flip of the
moment about X (the tilt goes from +C to −C, eqs. 4.11-4.12 / 5.16-5.18), the axial
stiffness ``k_z`` from a change of the moment about Z (eq. 4.15: ``δθ = η_z / k_z``), the
backlash from a small flip of it (eq. 5.19: ``δθ = sign(η_z) δθ_bkl + η_z / k_z``), with
the moments of eq. 4.21.  :func:`identify_tilt` fits the same model to all the readings
at once — weighted least squares, each channel's zero estimated with the joint
parameters (the thesis' differences cancel it; a pair is the special case of two
configurations) — so that every reading counts and the covariance is stated:

* unknowns: ``clearance_<joint>`` (rad), ``backlash_<joint>`` (rad),
  ``compliance_<joint>`` (rad/(N·m), ``1/k_z``), ``offset_<link>_<axis>`` (rad) and, by
  default, ``geom_<step>`` (rad): the change of each angle of the geometry that turns a
  sensed link (:func:`orientation_parameters`: joint offsets and the twists before the
  last sensed joint).  The readings see the links' orientation, so geometric errors that
  turn the links would otherwise be read as joint effects (on the thesis' Katana with
  Table 3.2's errors the weighted residual is 34 instead of 1 and joint 5's clearance
  off by 0.1°); lengths do not turn a link and cannot be seen;
* readings: :func:`robocal.measure.inclinometer.readings` of the nominal geometry with
  the joint perturbations of :func:`robocal.model.joints.joint_perturbations`;
* Jacobian: analytic (:func:`tilt_jacobian`): a perturbation at joint ``j`` turns every
  link after it about the joint frame's axis ``ω``, so the sensed vector ``v`` moves by
  ``ω × v`` and the reading by ``±(up · ω × v) / cos(reading)``; the perturbations'
  derivatives are those of eqs. 5.17-5.19 (exact, not first order); an angle step of
  the geometry turns every link after it about its own axis (same rule);
* covariance ``(JᵀWJ)⁻¹`` (W: the readings' 1/σ²), the Cramér–Rao bound of this model.

A parameter the readings cannot see is reported, not invented: one whose column is zero
(no load of its kind at any configuration, or a rotation about the vertical — the thesis:
"inclinometers cannot work without gravity component", joint 1's backlash and
stiffness), or one the configurations cannot tell from the others (pivoted QR).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.linalg import qr
from scipy.spatial.transform import Rotation

from robocal.measure.inclinometer import GRAVITY, Inclinometer, TiltReadings, readings, up_vector
from robocal.model.joints import (
    DEADBAND,
    EFFECT_PREFIXES,
    contact_angle,
    effect_of,
    effects_from_values,
    load_moments,
)

__all__ = [
    "TiltFit",
    "identify_tilt",
    "jacobian_at_loads",
    "orientation_parameters",
    "parameter_names",
    "predict_at_loads",
    "predict_readings",
    "tilt_jacobian",
]

Array = NDArray[np.float64]
KINDS = ("clearance", "backlash", "compliance")
GEOM = "geom_"  # prefix of a geometry angle's change (rad)
ZERO_COLUMN = 1e-9  # a column this small (relative to the largest) shows nothing
SEPARATE = 1e-8  # a pivot this small (relative) cannot be told from the columns before it


@dataclass(frozen=True)
class TiltFit:
    """The identification's result.

    Attributes:
        names: the identified parameters (``clearance_q2`` ..., ``offset_q3_x``,
            ``geom_alpha2``: the change of the model's ``alpha2``).
        values: their estimates (SI: rad, rad/(N·m)).
        covariance: ``(p, p)`` of the estimates (SI).
        not_identified: ``{name: reason}`` of the parameters the readings cannot see.
        rms_residual: RMS of the weighted residuals (≈ 1 when the model and σ hold).
        readings: number of readings used.
    """

    names: tuple[str, ...]
    values: Array
    covariance: Array
    not_identified: dict[str, str]
    rms_residual: float
    readings: int

    @property
    def sigma(self) -> Array:
        return np.sqrt(np.diag(self.covariance))

    def value(self, name: str) -> tuple[float, float] | None:
        """``(estimate, 1σ)`` of ``name``, None when it was not identified."""
        if name not in self.names:
            return None
        i = self.names.index(name)
        return float(self.values[i]), float(self.sigma[i])


def orientation_parameters(model, links: Sequence[str]) -> tuple[str, ...]:
    """The model's angle steps that turn a link carrying a sensor: the rotation steps
    (joint offsets included) up to the deepest joint of ``links``.  Length steps and
    the angles after the deepest sensed joint do not change any reading."""
    deepest = max(model.joint_names.index(link) for link in links)
    out: list[str] = []
    seen = -1
    for step in model.steps:
        fixed = step.joint is None
        seen += not fixed
        # a fixed step turns the links from the next joint on, a joint's offset its own
        if step.is_rotation and seen + fixed <= deepest:
            out.append(step.name)
    return tuple(out)


def parameter_names(
    model,
    data: TiltReadings,
    kinds: Sequence[str] = KINDS,
    joints: Sequence[str] | None = None,
    geometry: Sequence[str] = (),
) -> tuple[str, ...]:
    """The unknowns: effect coefficients per kind and joint, each channel's offset, then
    the changes of the ``geometry`` angle steps (names of the model's steps)."""
    joints = model.joint_names if joints is None else tuple(joints)
    effects = [EFFECT_PREFIXES[k][0] + j for k in kinds for j in joints]
    offsets = [f"offset_{link}_{axis}" for link, axis in data.channels()]
    return tuple(effects) + tuple(offsets) + tuple(GEOM + g for g in geometry)


def _geometry(model, names: Sequence[str], x: Array):
    """``model`` with its angle steps changed by the ``geom_`` entries of ``x``."""
    change = {n[len(GEOM) :]: float(v) for n, v in zip(names, x, strict=True) if n.startswith(GEOM)}
    if not any(change.values()):
        return model
    return model.with_values({k: model.step(k).value + v for k, v in change.items()})


def _split(names: Sequence[str]) -> tuple[list[tuple[str, str, int]], list[int]]:
    """``(kind, joint, index)`` of the effect names and the indices of the offsets."""
    effects, offsets = [], []
    for i, name in enumerate(names):
        if name.startswith("offset_"):
            offsets.append(i)
            continue
        if name.startswith(GEOM):
            continue
        kind, joint = effect_of(name) or ("", "")
        if kind not in KINDS:
            raise ValueError(f"{name!r} is no joint-effect coefficient of {', '.join(KINDS)}")
        effects.append((kind, joint, i))
    return effects, offsets


def _perturbations(model, q: Array, eta: Array, names, x: Array) -> Array:
    from robocal.model.joints import joint_perturbations

    effects, _ = _split(names)
    values = {(kind, joint): float(x[i]) for kind, joint, i in effects}
    chosen = effects_from_values(model, values, start=())
    return joint_perturbations(model, q, effects=chosen, loads=eta)


def _mounts(data: TiltReadings, sensors: Sequence[Inclinometer]) -> Array:
    by_link = {s.link: s.mount for s in sensors}
    missing = sorted(set(data.link) - set(by_link))
    if missing:
        raise ValueError(f"tilt readings name link(s) {missing} that carry no inclinometer of the set-up")
    return np.array([by_link[link] for link in data.link])


def predict_readings(
    model, data: TiltReadings, sensors: Sequence[Inclinometer], names, x: Array, gravity=GRAVITY
) -> Array:
    """The readings ``(m,)`` (rad) the parameters ``x`` (named ``names``) predict."""
    eta = load_moments(model, data.q, gravity=np.asarray(gravity, dtype=float))
    return _predict(model, data, _mounts(data, sensors), names, x, eta, gravity)


def predict_at_loads(model, data: TiltReadings, sensors: Sequence[Inclinometer], names, x: Array,
                     eta: Array, gravity=GRAVITY) -> Array:  # fmt: skip
    """:func:`predict_readings` under given load moments ``eta`` ``(m, dof, 3)`` (held
    fixed while the geometry changes, as :func:`identify_tilt` does)."""
    return _predict(model, data, _mounts(data, sensors), names, x, eta, gravity)


def jacobian_at_loads(model, data: TiltReadings, sensors: Sequence[Inclinometer], names, x: Array,
                      eta: Array, gravity=GRAVITY) -> Array:  # fmt: skip
    """:func:`tilt_jacobian` under given load moments ``eta`` ``(m, dof, 3)``."""
    return _jacobian(model, data, _mounts(data, sensors), names, x, eta, gravity)


def _predict(model, data, mounts, names, x, eta, gravity) -> Array:
    model = _geometry(model, names, x)
    d = _perturbations(model, data.q, eta, names, x)
    r = readings(model, data.q, data.link, data.axis, mounts, d, gravity)
    _, offsets = _split(names)
    chan = {names[i][len("offset_") :]: x[i] for i in offsets}
    return r + np.array([chan.get(f"{lk}_{ax}", 0.0) for lk, ax in zip(data.link, data.axis, strict=True)])


def _effect_derivatives(eta: Array, kind: str, j: int, value: float) -> Array:
    """d(δα, δβ, δθ)/d(value) ``(m, 3)`` at joint ``j`` (eqs. 5.17-5.19, exact)."""
    eu, ew, ek = eta[:, j, 0], eta[:, j, 1], eta[:, j, 2]
    out = np.zeros((len(eta), 3))
    sgn = lambda v: np.where(np.abs(v) > DEADBAND, np.sign(v), 0.0)  # noqa: E731
    if kind == "clearance":
        gamma = contact_angle(eu, ew)
        sec2 = 1.0 / math.cos(value) ** 2
        for col, (m, trig) in enumerate(((eu, np.sin(gamma)), (ew, np.cos(gamma)))):
            s = math.tan(value) * trig
            out[:, col] = sgn(m) * trig * sec2 / (1.0 + s**2) ** 1.5
        out[(np.abs(eu) + np.abs(ew)) <= DEADBAND, :2] = 0.0
    elif kind == "backlash":
        out[:, 2] = sgn(ek)
    else:
        out[:, 2] = np.where(np.abs(ek) > DEADBAND, ek, 0.0)
    return out


def _axes(model, F: Array, d: Array) -> Array:
    """World axes ``(m, dof, 3, 3)`` of (δα, δβ, δθ) at each joint: ``R_J e_u``, ``R_F e_w``,
    ``R_J e_k`` with ``R_F = R_J R_u(δα) R_w(δβ)`` the joint frame after its tilt."""
    steps = [s for s in model.steps if s.joint is not None]
    out = np.zeros(F.shape[:2] + (3, 3))
    for j, step in enumerate(steps):
        k = step.axis
        u, w = (k + 1) % 3, (k + 2) % 3
        eu, ew = np.eye(3)[u], np.eye(3)[w]
        RF = F[:, j, :3, :3]
        undo = Rotation.from_rotvec(-d[:, j, 1, None] * ew) * Rotation.from_rotvec(-d[:, j, 0, None] * eu)
        RJ = np.einsum("nij,njk->nik", RF, undo.as_matrix())
        out[:, j, 0] = RJ[:, :, u]
        out[:, j, 1] = RF[:, :, w]
        out[:, j, 2] = RJ[:, :, k]
    return out


def tilt_jacobian(
    model, data: TiltReadings, sensors: Sequence[Inclinometer], names, x: Array, gravity=GRAVITY
) -> Array:
    """Analytic d(readings)/d(parameters) ``(m, p)`` at ``x`` (see the module docstring)."""
    eta = load_moments(model, data.q, gravity=np.asarray(gravity, dtype=float))
    return _jacobian(model, data, _mounts(data, sensors), names, x, eta, gravity)


def _geometry_axes(model, F: Array, W: Array, wanted: set[str]) -> dict[str, tuple[Array, int]]:
    """World axis ``(m, 3)`` of each ``wanted`` angle step and the first joint whose link
    it turns: a joint's offset turns about the joint's axis (``W``: :func:`_axes`); a
    fixed rotation between joints ``j−1`` and ``j`` about its axis in the frame after
    joint ``j−1`` and the fixed rotations since."""
    out: dict[str, tuple[Array, int]] = {}
    seen = -1
    C = np.eye(3)
    for step in model.steps:
        if step.joint is not None:
            seen += 1
            C = np.eye(3)
            if step.name in wanted:
                out[step.name] = (W[:, seen, 2], seen)
            continue
        if not step.is_rotation:
            continue
        if step.name in wanted:
            before = F[:, seen, :3, :3] @ C if seen >= 0 else np.broadcast_to(C, (len(F), 3, 3))
            out[step.name] = (before[:, :, step.axis], seen + 1)
        C = C @ Rotation.from_rotvec(step.value * np.eye(3)[step.axis]).as_matrix()
    return out


def _jacobian(model, data, mounts, names, x, eta, gravity) -> Array:
    from robocal.measure.inclinometer import sensor_vectors

    model = _geometry(model, names, x)
    d = _perturbations(model, data.q, eta, names, x)
    v, sign, idx, F = sensor_vectors(model, data.q, data.link, data.axis, mounts, d)
    up = up_vector(gravity)
    cos_r = np.sqrt(np.clip(1.0 - (v @ up) ** 2, 1e-12, None))
    W = _axes(model, F, d)  # (m, dof, 3 perturbations, 3 xyz)
    # d reading / d perturbation (m, dof, 3): up · (ω × v) = ω · (v × up)
    dr_dp = sign[:, None, None] * np.einsum("mjpi,mi->mjp", W, np.cross(v, up)) / cos_r[:, None, None]
    dr_dp[np.arange(model.dof)[None, :] > idx[:, None]] = 0.0  # joints after the sensor's link
    effects, offsets = _split(names)
    J = np.zeros((data.n, len(names)))
    for kind, joint, i in effects:
        j = model.joint_names.index(joint)
        J[:, i] = np.einsum("mp,mp->m", dr_dp[:, j], _effect_derivatives(eta, kind, j, float(x[i])))
    for i in offsets:
        J[:, i] = [f"offset_{lk}_{ax}" == names[i] for lk, ax in zip(data.link, data.axis, strict=True)]
    geometry = {n[len(GEOM) :]: i for i, n in enumerate(names) if n.startswith(GEOM)}
    turned = sign * np.cross(v, up).T / cos_r  # (3, m): d reading / d(rotation vector), world
    for step, (axis, first) in _geometry_axes(model, F, W, set(geometry)).items():
        J[:, geometry[step]] = np.where(idx >= first, np.einsum("mi,im->m", axis, turned), 0.0)
    return J


def visible(J: Array, names: Sequence[str]) -> tuple[list[int], dict[str, str]]:
    """Columns the readings can determine, and the reason for each of the others."""
    norms = np.linalg.norm(J, axis=0)
    dropped: dict[str, str] = {}
    keep = []
    for i, name in enumerate(names):
        if norms[i] <= ZERO_COLUMN * max(norms.max(), 1e-300):
            dropped[name] = (
                "no reading changes with it: it turns the links about the vertical, which an "
                "inclinometer cannot see, or its load is zero at every configuration"
            )
        else:
            keep.append(i)
    Js = J[:, keep] / norms[keep]
    _, R, piv = qr(Js, mode="economic", pivoting=True)
    diag = np.abs(np.diag(R))
    bad = [keep[piv[k]] for k in range(len(diag)) if diag[k] <= SEPARATE * diag[0]]
    for i in bad:
        dropped[names[i]] = "the configurations cannot tell it from the other parameters"
    return [i for i in keep if i not in bad], dropped


def identify_tilt(
    model,
    data: TiltReadings,
    sensors: Sequence[Inclinometer],
    kinds: Sequence[str] = KINDS,
    joints: Sequence[str] | None = None,
    gravity=GRAVITY,
    iterations: int = 8,
    geometry: bool | Sequence[str] = True,
) -> TiltFit:
    """Weighted least squares (Gauss-Newton) of the joint effects and channel offsets from
    inclinometer readings of ``model`` (its nominal geometry; loads of eq. 4.21 from its
    mass properties) with the set-up's ``sensors`` (their mounts).

    ``geometry``: the angle steps of the model estimated with them (True: every one that
    turns a sensed link, :func:`orientation_parameters`; False: none, the nominal
    geometry taken as exact).  Loads stay those of the nominal geometry (a change of
    0.1° changes them by about 0.2 %)."""
    if set(kinds) - set(KINDS):
        raise ValueError(f"tilt identification: kinds must be some of {KINDS}")
    if geometry is True:
        geometry = orientation_parameters(model, data.link)
    names = parameter_names(model, data, kinds, joints, geometry or ())
    eta = load_moments(model, data.q, gravity=np.asarray(gravity, dtype=float))
    mounts = _mounts(data, sensors)
    w = 1.0 / data.sigma
    x = np.zeros(len(names))
    keep, dropped = visible(_jacobian(model, data, mounts, names, x, eta, gravity), names)
    for _ in range(iterations):
        r = (data.tilt - _predict(model, data, mounts, names, x, eta, gravity)) * w
        J = _jacobian(model, data, mounts, names, x, eta, gravity)[:, keep] * w[:, None]
        step = np.linalg.lstsq(J, r, rcond=None)[0]
        x[keep] += step
        if np.max(np.abs(step)) < 1e-12 * max(1.0, float(np.max(np.abs(x)))):
            break
    r = (data.tilt - _predict(model, data, mounts, names, x, eta, gravity)) * w
    J = _jacobian(model, data, mounts, names, x, eta, gravity)[:, keep] * w[:, None]
    cov = np.asarray(np.linalg.inv(J.T @ J), dtype=float)
    return TiltFit(
        names=tuple(names[i] for i in keep),
        values=x[keep],
        covariance=cov,
        not_identified=dropped,
        rms_residual=float(np.sqrt(np.mean(r**2))),
        readings=data.n,
    )
