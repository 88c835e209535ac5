"""The invariants every command robocal writes must hold (issue 31), checked per target.

A corrected command is written only when it is the nominal command moved a little, in the
same arm configuration; otherwise the target is *refused* and left as written (the
nominal command), named with its reason, and the CLI exits non-zero unless ``--partial``.

* **Joint-change bound** (:func:`joint_bound`), per target: the exact correction ``Δq``
  solves ``J Δq = e`` to first order, with ``e`` the calibrated model's predicted error at
  the nominal command (position m and orientation rad, 1 m per rad: ``|e|² = d² + θ²``)
  and ``J`` the task Jacobian, so ``|Δq| ≤ |e| / σ_min``; a damped correction (below)
  moves at most ``|e| / (2 λ)``.  The bound is

      clip(BOUND_FACTOR · |e| / max(σ_min, 2 λ if damped), 0.05°, 5°)

  per revolute joint (``0.05 mm .. 5 mm`` per prismatic one), with :data:`BOUND_FACTOR` =
  1.5: the largest ``|Δq|_∞ σ_min / |e|`` of calibrated UR10, KR 16 and IRB 2400 arms over
  256 random configurations each (default calibration, ±0.5 mm / ±0.05° errors) is 0.58,
  so the factor leaves a 2.6x margin for the IK's non-linearity.  A calibrated arm with a
  few mm of error gets ~1° where it is well conditioned (``σ_min ≥ 0.2``: ≤ 1.7° at 4 mm,
  0.4° at 1 mm) and never more than 5°; a correction beyond its bound is refused (a 2π
  winding change or a jump to another IK branch is always far beyond it).
* **Singularities** (:func:`sigma_min`): the smallest singular value of the task Jacobian
  at the nominal command (position rows in m, orientation rows in rad, 1 m per rad — the
  IK's weighting; ``"axis"`` targets with their two orientation rows across the tool
  axis).  Below :data:`SINGULAR_SIGMA` the exact correction can be arbitrarily large
  along the singular direction, so the correction is *damped*: the regularised IK
  (:func:`robocal.measure.ik_regularized.solve_regularized`, ``λ =`` :data:`DAMPING`)
  then scaled down, when needed, so that no joint moves more than the bound and no
  revolute joint more than :data:`MAX_DAMPED` rad.
* **Configuration** (:func:`configurations`): for arms with 6 or more joints, where the
  wrist centre is against axis 1 (front/back), against the lower arm (elbow up/down) and
  the sign of joint 5 (wrist) — the configuration KUKA's status and ABB's ``cfx`` encode.
  A correction that changes one of them from one side of its boundary to the other, both
  farther than :data:`BOUNDARY_M` / :data:`BOUNDARY_RAD` from it, is refused; near a
  singularity the damped, bounded correction may cross it by a hair.  (Away from
  singularities two configurations are far apart in joint space, so the joint-change bound
  alone already keeps the branch; this check is the second, independent guard.)
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from robocal.measure.ik import PerturbationFunction
from robocal.measure.ik_starts import TargetKind
from robocal.model.chain import Model

__all__ = [
    "BOUND_FACTOR",
    "DAMPING",
    "MAX_DAMPED",
    "SINGULAR_SIGMA",
    "Verdict",
    "configurations",
    "joint_bound",
    "judge",
    "outside_limits",
    "same_configuration",
    "sigma_min",
]

Array = NDArray[np.float64]

#: σ_min (1 m per rad) below which a target counts as near a singularity (UR10: |q5| < ~1.8°)
SINGULAR_SIGMA = 0.02
#: λ of the damped correction near a singularity (same units as σ)
DAMPING = 0.02
#: rad: the largest revolute-joint move of a damped correction
MAX_DAMPED = 0.1
#: the joint-change bound is this many times the first-order size of the correction, |e| / σ_min
BOUND_FACTOR = 1.5
_REVOLUTE_CLIP = (math.radians(0.05), math.radians(5.0))  # rad
_PRISMATIC_CLIP = (0.05e-3, 5e-3)  # m
#: m: the wrist centre this close to axis 1 or to the lower arm's line is on a boundary (a
#: UR's wrist centre crosses axis 1 without any singularity: a hair is no configuration change)
BOUNDARY_M = 5e-3
#: rad: joint 5 this close to 0 is on the wrist boundary
BOUNDARY_RAD = 1e-2


def _task_jacobian(
    model: Model, q: Array, effects: PerturbationFunction | None, kind: TargetKind, tool_axis: int
) -> Array:
    """``(n, rows, dof)`` Jacobian of the imposed rows: position (m) and orientation (rad)."""
    d = None if effects is None else effects(q)
    J = model.joint_jacobian(q, d)
    if kind == "position":
        return J[:, :3]
    if kind == "pose":
        return J
    a = model.fk(q, d)[:, :3, tool_axis]  # the tool axis; orientation rows across it only
    helper = np.where(np.abs(a[:, :1]) < 0.9, np.array([1.0, 0, 0]), np.array([0, 1.0, 0]))
    u = np.cross(a, helper)
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    v = np.cross(a, u)
    basis = np.stack([u, v], axis=1)  # (n, 2, 3)
    return np.concatenate([J[:, :3], basis @ J[:, 3:]], axis=1)


def sigma_min(
    model: Model, q: Array, effects: PerturbationFunction | None, kind: TargetKind, tool_axis: int = 2
) -> Array:
    """``(n,)`` smallest singular value of the task Jacobian at ``q`` (module docstring)."""
    if not len(q):
        return np.zeros(0)
    J = _task_jacobian(model, np.asarray(q, dtype=float), effects, kind, tool_axis)
    return np.asarray(np.linalg.svd(J, compute_uv=False)[:, -1], dtype=float)


def joint_bound(error: Array, sigma: Array, damped: NDArray[np.bool_], joint_types: tuple[str, ...]) -> Array:
    """``(n, dof)`` the largest joint change (rad, m) each target's correction may make
    (module docstring).

    Args:
        error: ``(n,)`` ``|e|`` at the nominal command (m, rad at 1 m per rad).
        sigma: ``(n,)`` :func:`sigma_min` at the nominal command.
        damped: ``(n,)`` the correction is damped (``σ_min <`` :data:`SINGULAR_SIGMA`).
        joint_types: the robot's ``"revolute"``/``"prismatic"`` joints.
    """
    e = np.nan_to_num(np.asarray(error, dtype=float), nan=np.inf)
    size = np.where(damped, e / (2 * DAMPING), e / np.maximum(sigma, 1e-12))  # first-order |Δq|
    revolute = np.array([t == "revolute" for t in joint_types])
    lo = np.where(revolute, _REVOLUTE_CLIP[0], _PRISMATIC_CLIP[0])
    hi = np.where(revolute, _REVOLUTE_CLIP[1], _PRISMATIC_CLIP[1])
    return np.clip(BOUND_FACTOR * size[:, None], lo, hi)


def _sides(model: Model, q: Array) -> Array:
    """``(n, 3)`` signed configuration quantities (front m, elbow m, sin q5 ≈ rad); NaN for
    arms with fewer than 6 joints."""
    if model.dof < 6:
        return np.full((len(q), 3), np.nan)
    from robocal.compensate.arm_geometry import arm_sides  # the KUKA/ABB definitions

    out = np.empty((len(q), 3))
    for i, qi in enumerate(q):
        out[i, :2] = arm_sides(model, qi)
        # the wrist's side, whatever the winding: sin q5 (0 at both wrist singularities, 0 and π)
        out[i, 2] = math.sin(qi[4])
    return out


def _label(s: Array) -> str:
    if np.isnan(s).any():
        return "-"
    bands = (BOUNDARY_M, BOUNDARY_M, BOUNDARY_RAD)
    names = (("back", "front"), ("down", "up"), ("q5-", "q5+"))
    parts = [
        f"{pair[1] if v > 0 else pair[0]}{'~' if abs(v) < band else ''}"
        for v, band, pair in zip(s, bands, names, strict=True)
    ]
    return "/".join(parts)


def configurations(model: Model, q: Array) -> tuple[str, ...]:
    """Configuration labels ``front|back/up|down/q5+|q5-`` of joints ``q`` (``~``: on the
    boundary; ``-`` for arms with fewer than 6 joints)."""
    return tuple(_label(s) for s in _sides(model, np.asarray(q, dtype=float).reshape(-1, model.dof)))


def same_configuration(model: Model, q: Array, q_ref: Array) -> NDArray[np.bool_]:
    """``(n,)`` whether each of ``q`` ``(n, dof)`` has the configuration of ``q_ref``
    (``(dof,)`` for all, or ``(n, dof)`` row by row): front/back, elbow, wrist side; a side
    on its boundary band matches either."""
    a = _sides(model, np.asarray(q_ref, dtype=float).reshape(-1, model.dof))
    b = _sides(model, np.asarray(q, dtype=float).reshape(-1, model.dof))
    bands = np.array([BOUNDARY_M, BOUNDARY_M, BOUNDARY_RAD])
    same = (np.sign(a) == np.sign(b)) | (np.abs(a) < bands) | (np.abs(b) < bands) | np.isnan(a) | np.isnan(b)
    return same.all(axis=1)


@dataclass(frozen=True)
class Verdict:
    """Per target: ``status`` (``corrected``, ``damped`` or ``refused``), the reason (empty
    when corrected), whether the configuration was kept, and the configuration labels."""

    status: tuple[str, ...]
    reasons: tuple[str, ...]
    config_kept: NDArray[np.bool_]
    configuration: tuple[str, ...]


def _config_kept(nominal: Model, q: Array, q_nom: Array, near: NDArray[np.bool_]) -> NDArray[np.bool_]:
    return same_configuration(nominal, q, q_nom) | near


def judge(
    nominal: Model,
    q: Array,
    q_nom: Array,
    bound: Array,
    near: NDArray[np.bool_],
    reached: NDArray[np.bool_],
    nominal_reached: NDArray[np.bool_],
    sigma: Array,
    nominal_reasons: tuple[str, ...] = (),
) -> Verdict:
    """Every target's status and reason (module docstring); ``bound`` ``(n, dof)``;
    ``nominal_reasons``: why a target's nominal command is refused (empty: it is not)."""
    kept = _config_kept(nominal, q, q_nom, near)
    labels = configurations(nominal, q_nom)
    status, reasons = [], []
    for i in range(len(q)):
        why = _refusal(nominal, q[i], q_nom[i], bound[i], bool(near[i]), bool(reached[i]), bool(kept[i]))
        if not nominal_reached[i]:
            why = "not reachable by the controller's model (no nominal command)"
        elif nominal_reasons and nominal_reasons[i]:
            why = nominal_reasons[i]
        if why:
            status.append("refused")
        elif near[i]:
            status.append("damped")
            why = (
                f"near a singularity (sigma_min {sigma[i]:.2g} < {SINGULAR_SIGMA:g}): correction damped, "
                f"each joint within {_amount(min(float(bound[i].max()), MAX_DAMPED), nominal, 0)}"
            )
        else:
            status.append("corrected")
        reasons.append(why)
    return Verdict(tuple(status), tuple(reasons), kept, labels)


def _refusal(
    nominal: Model, q: Array, q_nom: Array, bound: Array, near: bool, reached: bool, kept: bool
) -> str:
    """Why one target's correction ``q`` is refused (empty: it is not)."""
    dq = np.abs(q - q_nom)
    j = int(np.argmax(dq / bound))
    if not (reached or near):
        return "not reachable by the calibrated robot"
    if dq[j] > bound[j] * (1 + 1e-9):
        return (
            f"joint {j + 1} would move {_amount(dq[j], nominal, j)} (bound {_amount(bound[j], nominal, j)})"
        )
    if not kept:
        now = configurations(nominal, q)[0]
        return f"the correction changes the configuration ({configurations(nominal, q_nom)[0]} -> {now})"
    return ""


def _amount(v: float, model: Model, j: int) -> str:
    if model.joint_types[j] == "revolute":
        return f"{math.degrees(v):.3g} deg"
    return f"{v * 1e3:.3g} mm"


def limit_damped(dq: Array, bound: Array, revolute: NDArray[np.bool_]) -> Array:
    """``(m, dof)`` damped corrections scaled down (direction kept) so that no joint exceeds
    ``bound`` (``(m, dof)``) and no revolute joint :data:`MAX_DAMPED`."""
    cap = np.where(revolute, np.minimum(bound, MAX_DAMPED), bound)
    ratio = (np.abs(dq) / cap).max(axis=1, initial=0.0)
    return dq / np.maximum(ratio, 1.0)[:, None]


def outside_limits(model: Model, q: Array) -> tuple[str, ...]:
    """Per row of ``q`` ``(n, dof)``: why it is outside ``model``'s joint limits (the first
    joint beyond them, its value and the limits), or empty.  A command there is no command
    to correct: the IK stays within the limits, so it would start from another
    configuration and move the joints by whatever brings it back."""
    q = np.asarray(q, dtype=float).reshape(-1, model.dof)
    lim = model.joint_limits
    slack = 1e-9  # rad, m: a value written at its limit is within it
    out = (q < lim[:, 0] - slack) | (q > lim[:, 1] + slack)
    reasons = []
    for i, row in enumerate(out):
        if not row.any():
            reasons.append("")
            continue
        j = int(np.argmax(row))
        value, lo, hi = (_amount(float(v), model, j) for v in (q[i, j], lim[j, 0], lim[j, 1]))
        reasons.append(f"the programmed {model.joint_names[j]} = {value} is outside its limits [{lo}, {hi}]")
    return tuple(reasons)
