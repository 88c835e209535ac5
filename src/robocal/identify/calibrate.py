"""The calibration pipeline: ``rc.calibrate(model, data) -> CalibrationResult``.

1. Start: the nominal robot; the tool (a point for position measurements, a frame for
   pose measurements) and the device frame ``T_device_base`` from alternating
   closed-form fits (Kabsch/Horn for the frame, linear least squares for the tool).
2. Choose the unknowns: the robot's free parameters, the device frame and the tool,
   reduced to an identifiable set by a sequential rank test over the scaled Jacobian
   at the measured poses, preferring the device frame, then the tool, then the
   robot's parameters in chain order; every parameter left out is reported with the
   parameters that absorb it.
3. Solve with the chosen method (:mod:`robocal.identify.solvers`).
4. Tell the truth: residual standard deviation, parameter covariance
   σ̂²(JᵀWJ)⁻¹ and standard deviations, correlations above 0.9, the condition number,
   and the predicted position uncertainty at any pose.

Calibration levels (seed 003 §1.2, after Mooring et al.): ``level=1`` corrects the
joint offsets only, ``level=2`` the kinematic (geometric) parameters, ``level=3``
adds the non-geometric joint effects of :mod:`robocal.model.joints` — either
predicted from measured joint parameters and removed before the geometric
identification (``effects="predict"``, seed 003's two-stage method, eqs. 4.20-4.22,
5.13, 5.20) or identified together with the geometric parameters, with their
uncertainty (``effects="identify"``, the default of level 3: clearance tilt, backlash
and axial compliance of every joint, where observable).  A joint effect is physically
≥ 0 and counts as identified only at least 3σ above zero; otherwise it is kept at its
start value and reported as not identified, with the reason (:func:`effect_verdict`).
"""

from __future__ import annotations

import dataclasses
import functools
import hashlib
import json
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from robocal import spatial
from robocal.identify.guards import (
    CalibrationGuardError,
    FitToNoise,
    check_data,
    check_rank,
    check_solution,
    fit_to_noise,
)
from robocal.identify.observability import Dropped
from robocal.identify.problem import FRAME_PREFIX, TOOL_PREFIX, Problem, measurement_chain
from robocal.identify.solvers import METHODS, SolveResult, solve
from robocal.identify.stages import (
    identifiable_set,
    initial_frames_and_tools,
    poorly_identifiable,
    robot_sizes,
    screen_unidentifiable,
    uncertainty,
)
from robocal.measure.dataset import Measurements
from robocal.model.chain import Model
from robocal.model.dynamics import Payload
from robocal.model.files import ModelFileError, atomic_write_text, load_model, save_model, strict_json

__all__ = [
    "BOUNDS_CHOICES",
    "EFFECT_SIGNIFICANCE",
    "LEVELS",
    "RESIDUAL_CHOICES",
    "CalibrationResult",
    "calibrate",
    "calibrate_physics",
    "default_bounds",
    "effect_verdict",
    "effects_to_hold",
    "parameters_at_bounds",
    "parse_level",
]

Array = NDArray[np.float64]
Method = Literal["lm", "pinv", "bounded", "influence"]
ResidualChoice = Literal["none", "auto", "joint_fourier"]
RESIDUAL_CHOICES: tuple[str, ...] = ("none", "auto", "joint_fourier")
#: ``bounds=`` of ``method="bounded"`` by name: seed 001's ±5 mm / ±2° on every robot
#: parameter, or those bounds widened for the parameters that absorb redundant ones
BOUNDS_CHOICES: tuple[str, ...] = ("default", "widened")
#: a parameter is at a bound when it is within this fraction of the bounds' width of it
AT_BOUND_TOLERANCE = 1e-6

#: calibration levels by name (seed 003 §1.2)
LEVELS: dict[str, int] = {
    "1": 1,
    "offsets": 1,
    "joint-offsets": 1,
    "zero-offset": 1,
    "2": 2,
    "kinematic": 2,
    "geometric": 2,
    "3": 3,
    "non-geometric": 3,
}


def parse_level(level: int | str | None) -> int | None:
    """1, 2 or 3 from a number or a name (``offsets``, ``kinematic``, ``non-geometric``)."""
    if level is None:
        return None
    key = str(level).strip().lower()
    if key not in LEVELS:
        raise ValueError(
            f"unknown calibration level {level!r}: 1 (joint offsets), 2 (kinematic) or 3 (non-geometric)"
        )
    return LEVELS[key]


# ---------------------------------------------------------------------- start values
def initial_frame_and_tool(
    robot: Model,
    data: Measurements,
    measure: str,
    tool: Array | None,
    fit_frame: bool,
    fit_tool: bool,
    T_device_base: Array | None = None,
    rounds: int = 4,
    T_flange: Array | None = None,
) -> tuple[Array, Array]:
    """Alternate closed-form fits of the device frame and the tool (both 4x4): one robot
    of :func:`robocal.identify.stages.initial_frames_and_tools`.

    ``T_flange``: the robot's end frames ``(n, 4, 4)`` at the data's joint values, when
    the caller has them (default: computed)."""
    if T_flange is None:
        T_flange = robot.fk(data.q)
    T_frame, T_tool = initial_frames_and_tools(
        T_flange[None],
        data.position[None],
        orientation=data.orientation[None] if measure == "pose" else None,
        T_tool=None if tool is None else np.asarray(tool, dtype=float),
        T_frame=None if T_device_base is None else np.asarray(T_device_base, dtype=float),
        fit_frame=fit_frame,
        fit_tool=fit_tool,
        rounds=rounds,
    )
    return T_frame[0], T_tool[0]


#: Seed 001's bounds around the nominal robot parameters: ±5 mm on lengths, ±2° on angles.
SEED001_LENGTH_BOUND = 5e-3
SEED001_ANGLE_BOUND = math.radians(2.0)


def _outlier_poses(errors: Array, sigma: Array | None, factor: float = 5.0) -> list[int]:
    """Indices of the poses whose position residual ``errors`` ``(n,)`` (m) exceeds
    ``factor`` times the median residual (and ``factor`` times the 3D noise when the data
    states it): a residual of a well fitted pose is rarely over 3x the median (3D
    Gaussian), so these are measurement glitches or poses the model cannot reach."""
    limit = factor * float(np.median(errors))
    if sigma is not None:
        limit = max(limit, factor * float(np.sqrt(np.mean(np.sum(sigma**2, axis=1)))))
    return [int(i) for i in np.flatnonzero(errors > limit)] if len(errors) >= 10 else []


def _without_measured_tool(model: Model) -> tuple[Model, Array | None]:
    """``model`` without the tool steps (``tcp_*``) an earlier calibration appended to
    its end, and their transform (4x4; None when there are none)."""
    k = len(model.steps)
    while k and model.steps[k - 1].name.startswith(TOOL_PREFIX) and model.steps[k - 1].joint is None:
        k -= 1
    if k == len(model.steps):
        return model, None
    tool = model.steps[k:]
    T = spatial.chain_product([s.motion for s in tool], [s.value for s in tool])
    return dataclasses.replace(model, steps=model.steps[:k]), T


def _widen_for_absorbed(
    lo: Array,
    hi: Array,
    names: Sequence[str],
    dropped: Sequence[Dropped],
    chain: Model,
    length: float,
    robot: set[str],
    length_bound: float = SEED001_LENGTH_BOUND,
    angle_bound: float = SEED001_ANGLE_BOUND,
) -> tuple[Array, Array]:
    """Seed 001's bounds of the kept parameters widened by those of the redundant
    parameters they absorb: with d3 dropped, d2 carries d2 + d3 and may need ±10 mm
    (the coefficients of ``absorbed_by`` are in tool-displacement units, rotations times
    the robot's ``length``)."""
    rotation = {s.name: s.is_rotation for s in chain.steps}
    scale = {n: length if rotation.get(n, False) else 1.0 for n in rotation}
    index = {n: k for k, n in enumerate(names)}
    lo, hi = lo.copy(), hi.copy()
    for d in dropped:
        if d.reason != "redundant" or d.name not in robot:
            continue
        width = (angle_bound if rotation.get(d.name, False) else length_bound) * scale[d.name]
        for name, coefficient in d.absorbed_by:
            k = index.get(name)
            if k is not None and name in robot and np.isfinite(lo[k]):
                extra = abs(coefficient) * width / scale[name]
                lo[k], hi[k] = lo[k] - extra, hi[k] + extra
    return lo, hi


def default_bounds(
    names: Sequence[str],
    rotation: Sequence[bool],
    nominal: Array,
    length: float = SEED001_LENGTH_BOUND,
    angle: float = SEED001_ANGLE_BOUND,
    robot: set[str] | None = None,
) -> tuple[Array, Array]:
    """Seed 001's bounds: ±5 mm on lengths and ±2° on angles around the nominal robot
    parameters (those in ``robot``, default: all but ``frame_*``/``tcp_*``); the device
    frame, the tool and effect coefficients are left free."""
    lo, hi = np.full(len(names), -np.inf), np.full(len(names), np.inf)
    for k, (name, rot) in enumerate(zip(names, rotation, strict=True)):
        if name.startswith((FRAME_PREFIX, TOOL_PREFIX)) or (robot is not None and name not in robot):
            continue
        w = angle if rot else length
        lo[k], hi[k] = nominal[k] - w, nominal[k] + w
    return lo, hi


def parameters_at_bounds(
    names: Sequence[str], x: Array, lo: Array, hi: Array, tolerance: float = AT_BOUND_TOLERANCE
) -> list[str]:
    """The parameters at a bound: within ``tolerance`` times the bounds' width (or times
    1 m or 1 rad for a one-sided bound) of their lower or upper bound.  A value beyond its
    bound counts as at it (the bounded solver clips its result, so none is); one strictly
    inside by more than the tolerance does not."""
    out = []
    for name, v, a, b in zip(names, x, lo, hi, strict=True):
        width = b - a if np.isfinite(b - a) else 1.0
        near = tolerance * width
        if (np.isfinite(a) and v - a <= near) or (np.isfinite(b) and b - v <= near):
            out.append(name)
    return out


def _bounded_method_bounds(
    bounds: tuple[ArrayLike, ArrayLike] | str | None,
    problem: Problem,
    dropped: Sequence[Dropped],
    length: float,
    robot: set[str],
) -> tuple[Array, Array, str | None]:
    """``(lower, upper)`` over the free parameters of ``problem`` for ``method="bounded"``
    (SI), and a note when they were widened (:data:`BOUNDS_CHOICES`)."""
    names, x0 = problem.free_names, problem.x0
    if bounds is None:
        return np.full(len(x0), -np.inf), np.full(len(x0), np.inf), None
    if isinstance(bounds, str):
        rot = [s.is_rotation for s in problem.chain.steps if s.free] + [False] * problem.n_effects
        lo, hi = default_bounds(names, rot, x0, robot=robot)
        if bounds == "default":
            return lo, hi, None
        wide_lo, wide_hi = _widen_for_absorbed(lo, hi, names, dropped, problem.chain, length, robot)
        changed = [
            f"{n} ±{_bound_text(n, h - v, r)}"
            for n, v, h, h0, r in zip(names, x0, wide_hi, hi, rot, strict=True)
            if h != h0
        ]
        note = (
            "bounds='widened': seed 001's ±5 mm / ±2° widened for the parameters that absorb redundant "
            f"ones: {', '.join(changed) or 'none absorbs any'}"
        )
        return wide_lo, wide_hi, note
    lo, hi = (np.asarray(b, dtype=float) for b in bounds)
    if lo.shape != x0.shape or hi.shape != x0.shape:
        raise ValueError(f"bounds must be two arrays over the {len(x0)} estimated parameters {names}")
    return lo, hi, None


def _bound_text(name: str, half_width: float, rotation: bool) -> str:
    """A bound's half width in mm or degrees."""
    return f"{math.degrees(half_width):.3g}°" if rotation else f"{half_width * 1e3:.3g} mm"


# ---------------------------------------------------------------------- result
@dataclass
class CalibrationResult:
    """A calibrated model with its uncertainty and the record of how it was obtained.

    Attributes:
        model: the calibrated robot model with the measured tool appended (base frame:
            the robot's base).
        frame: ``T_device_base`` (4, 4), the measuring device's frame identified.
        names: estimated parameters (robot, ``frame_*`` corrections, ``tcp_*``).
        estimates, nominal, std: their values (SI), start values and standard deviations.
        covariance, correlation: ``(p, p)``.
        dropped: parameters not identified and why.
        residual_std: σ̂ of the weighted residuals (m for unit weights).
        rms_before, rms_after: RMS position error on the calibration data (m), with the
            start model (fitted frame and tool) and after calibration.
        condition_number: of the column-scaled Jacobian.
    """

    model: Model
    frame: Array
    measure: str
    method: str
    names: tuple[str, ...]
    estimates: Array
    nominal: Array
    std: Array
    covariance: Array
    correlation: Array
    dropped: tuple[Dropped, ...]
    residual_std: float
    rms_before: float
    rms_after: float
    condition_number: float
    n: int
    success: bool
    message: str
    iterations: int
    seconds: float
    measurement_chain: Model | None = field(default=None, repr=False)
    compliance: dict[str, float] = field(default_factory=dict)  # joint -> rad per N·m
    gravity: tuple[float, float, float] = (0.0, 0.0, -9.81)
    metadata: dict[str, Any] = field(default_factory=dict)
    payload: Payload | None = None
    # (p, m) covariance of the estimated parameters with the learned residual's coefficients
    # (model.residual), from their joint fit; None without a residual
    residual_cross_covariance: Array | None = field(default=None, repr=False)

    def joint_perturbations(
        self, q: ArrayLike, qd: ArrayLike | None = None, qdd: ArrayLike | None = None
    ) -> Array | None:
        """Joint perturbations ``(n, dof, 3)`` (δα, δβ, δθ) of every joint effect of the
        calibrated robot at ``q`` — identified, or predicted from the measured joint
        parameters — under the calibration's gravity and payload; ``qd``, ``qdd``
        (``(n, dof)``, rad/s, rad/s²) add the inertial loads of a motion.  None for a
        geometric calibration."""
        q = np.atleast_2d(np.asarray(q, dtype=float))
        physical = self.physical_perturbations(q, qd, qdd)
        if self.model.residual is None:
            return physical
        learned = self.model.residual.perturbations(q, self.model.dof)
        return learned if physical is None else physical + learned

    def physical_perturbations(
        self, q: ArrayLike, qd: ArrayLike | None = None, qdd: ArrayLike | None = None
    ) -> Array | None:
        """The joint perturbations ``(n, dof, 3)`` of the physical joint effects alone
        (:meth:`joint_perturbations` without the learned residual); None when there are none."""
        q = np.atleast_2d(np.asarray(q, dtype=float))
        if self.model.joint_effects:
            from robocal.model.joints import joint_perturbations

            return joint_perturbations(
                self._load_robot(), q, qd, qdd, gravity=np.asarray(self.gravity), payload=self.payload
            )
        if not self.compliance:
            return None
        from robocal.model.dynamics import gravity_torques  # results saved before joint effects

        tau = gravity_torques(self.model, q, np.asarray(self.gravity))
        pert = np.zeros((len(q), self.model.dof, 3))
        for name, c in self.compliance.items():
            j = self.model.joint_names.index(name)
            pert[:, j, 2] = -c * tau[:, j]
        return pert

    def _load_robot(self) -> Model:
        """The calibrated robot without the measured tool steps: the geometry whose joint
        loads drive the joint effects (a payload sits at the robot's end)."""
        steps = tuple(s for s in self.model.steps if not s.name.startswith(TOOL_PREFIX))
        if len(steps) == len(self.model.steps):
            return self.model
        return dataclasses.replace(self.model, steps=steps)

    def predict(
        self,
        q: ArrayLike,
        frame: ArrayLike | None = None,
        qd: ArrayLike | None = None,
        qdd: ArrayLike | None = None,
    ) -> Array:
        """Tool frames ``(n, 4, 4)`` of the calibrated robot (with its joint effects) at
        ``q`` (``qd``, ``qdd``: along a motion), in the device frame (default: the
        calibrated one; identity for the base)."""
        q = np.atleast_2d(np.asarray(q, dtype=float))
        T = self.model.fk(q, self.joint_perturbations(q, qd, qdd))
        return (self.frame if frame is None else np.asarray(frame, dtype=float)) @ T

    @property
    def high_correlations(self) -> list[tuple[str, str, float]]:
        """Parameter pairs with |correlation| > 0.9."""
        out = []
        p = len(self.names)
        for i in range(p):
            for j in range(i + 1, p):
                if abs(self.correlation[i, j]) > 0.9:
                    out.append((self.names[i], self.names[j], float(self.correlation[i, j])))
        return out

    @property
    def effect_names(self) -> tuple[str, ...]:
        """The identified joint-effect coefficients among :attr:`names` (``compliance_q2``...)."""
        return tuple(n for n in self.names if _effect_prefix(n) is not None)

    def deltas(self) -> dict[str, float]:
        return {n: float(e - v) for n, e, v in zip(self.names, self.estimates, self.nominal, strict=True)}

    def position_covariance(self, q: ArrayLike, frame: Literal["device", "base"] = "device") -> Array:
        """Covariance ``(n, 3, 3)`` (m²) of the predicted tool position at joint values ``q``.

        ``frame="device"`` (default): the prediction of a measurement, in the device
        frame, with the uncertainty of every estimated parameter — geometric ones
        including the device frame's, and identified joint-effect coefficients (their
        patterns at ``q`` under the calibration's gravity and payload).  ``frame="base"``:
        the position in the robot's base frame, without the device frame's parameters.
        """
        q = np.atleast_2d(np.asarray(q, dtype=float))
        chain = self.measurement_chain if frame == "device" else self.model
        if chain is None:
            raise ValueError("this result has no measurement chain (saved by an older robocal?)")
        names = [
            n
            for n in self.names
            if n in set(chain.names) and not (frame == "base" and n.startswith(FRAME_PREFIX))
        ]
        effects = [n for n in self.names if _effect_prefix(n) is not None]
        perturbations = self.joint_perturbations(q)
        model = chain.with_free(None, free=False).with_free(names)
        J = model.jacobian(q, perturbations=perturbations).reshape(len(q), 3, -1)
        J = J[:, :, [model.free_names.index(n) for n in names]]
        if effects:  # d position / d coefficient = (d position / d joint perturbation) · pattern
            J = np.concatenate([J, self._effect_columns(chain, q, perturbations, effects)], axis=2)
        idx = [self.names.index(n) for n in names + effects]
        C = self.covariance[np.ix_(idx, idx)]
        # J C Jᵀ per pose, by matmuls (an einsum over both sums is 40x slower)
        cov = (J @ C) @ np.swapaxes(J, 1, 2)
        if self.model.residual is not None:  # the learned residual, fitted jointly with the parameters
            P = chain.perturbation_jacobian(q, "position", perturbations)
            cov = cov + self.model.residual.position_covariance(q, P)
            if self.residual_cross_covariance is not None:
                A = self.model.residual.design(q, P[:, :3])
                cross = (J @ self.residual_cross_covariance[idx]) @ np.swapaxes(A, 1, 2)
                cov = cov + cross + np.swapaxes(cross, 1, 2)
        return cov

    def _effect_columns(self, chain: Model, q: Array, perturbations: Array | None, names: list[str]) -> Array:
        """``(n, 3, m)`` derivatives of the tool position wrt the joint-effect coefficients
        ``names`` at ``q`` (the patterns the calibration identified them with)."""
        from robocal.model.joints import EFFECT_KINDS, effect_basis

        B, basis_names, _ = effect_basis(
            self._load_robot(), q, kinds=EFFECT_KINDS, gravity=np.asarray(self.gravity), payload=self.payload
        )
        B = B[[basis_names.index(n) for n in names]]  # (m, n, dof, 3)
        P = chain.perturbation_jacobian(q, "position", perturbations)  # (n, 3, dof, 3)
        return np.einsum("nrjc,knjc->nrk", P, B)

    def position_columns(self, q: ArrayLike) -> Array:
        """``(n, 3, p)`` derivatives of the predicted measurement (device frame, m) wrt the
        estimated parameters (:attr:`names`, SI) at ``q``."""
        q = np.atleast_2d(np.asarray(q, dtype=float))
        chain = self.measurement_chain
        if chain is None:
            raise ValueError("this result has no measurement chain (saved by an older robocal?)")
        perturbations = self.joint_perturbations(q)
        geometric = [n for n in self.names if n in set(chain.names)]
        effects = [n for n in self.names if _effect_prefix(n) is not None]
        model = chain.with_free(None, free=False).with_free(geometric)
        J = model.jacobian(q, perturbations=perturbations).reshape(len(q), 3, -1)
        J = J[:, :, [model.free_names.index(n) for n in geometric]]
        if effects:
            J = np.concatenate([J, self._effect_columns(chain, q, perturbations, effects)], axis=2)
        order = [(geometric + effects).index(n) for n in self.names]
        return J[:, :, order]

    def position_uncertainty(self, q: ArrayLike, frame: Literal["device", "base"] = "device") -> Array:
        """1-σ radial position uncertainty ``sqrt(trace(cov))`` (m) at each pose, ``(n,)``."""
        return np.sqrt(np.trace(self.position_covariance(q, frame), axis1=1, axis2=2))

    def unexplained_rms(self) -> float:
        """RMS 3D position error of the robot that the calibrated model does not explain (m).

        With stated measurement noise: the part of the residuals beyond that noise (0 when the
        χ² test cannot tell the residuals from noise).  Without it: the learned residual's
        estimate of what remains per axis, or the residual σ — both include the device's
        noise, so they bound the robot's unexplained error from above.
        """
        noise = self.fit_to_noise
        if noise is not None:
            return noise.unmodelled_rms if noise.ratio > 1 and noise.warning() is not None else 0.0
        learned = self.model.residual
        if learned is not None:
            return math.sqrt(3.0) * float(learned.noise_std)
        return math.sqrt(3.0) * float(self.residual_std)

    def expected_position_error(self, q: ArrayLike) -> Array:
        """``(n,)`` RMS 3D position error (m) the calibrated model is expected to leave at
        commands ``q`` (base frame): its parameters' and learned residual's uncertainty
        (``position_uncertainty(q, "base")``) and the error it does not explain
        (:meth:`unexplained_rms`), added in quadrature."""
        return np.sqrt(self.position_uncertainty(q, "base") ** 2 + self.unexplained_rms() ** 2)

    def summary(self) -> str:
        """A plain-text report of the calibration."""
        lines = [
            f"calibration of {self.model.name!r}: {self.method}, {self.measure} measurements, {self.n} poses",
            f"  {'converged' if self.success else 'NOT CONVERGED'}: {self.message} "
            f"({self.iterations} iterations, {self.seconds * 1e3:.1f} ms)",
            f"  RMS position error on the calibration poses: {self.rms_before * 1e3:.4f} mm -> "
            f"{self.rms_after * 1e3:.4f} mm",
            f"  residual standard deviation {self.residual_std * 1e3:.4f} mm, "
            f"condition number {self.condition_number:.3g}",
            *([f"  {noise.summary()}"] if (noise := self.fit_to_noise) is not None else []),
            *[f"  {line}" for line in self.residual_lines()],
            "  parameter                nominal       estimate          delta           sigma",
        ]
        rot = {s.name: s.is_rotation for s in (self.measurement_chain or self.model).steps}
        for n, v0, v, s in zip(self.names, self.nominal, self.estimates, self.std, strict=True):
            f, unit = display_unit(n, rot.get(n, False))
            lines.append(
                f"  {n:<20} {v0 * f:>12.5f} {v * f:>14.5f} {(v - v0) * f:>14.5f} {s * f:>11.5f} {unit}"
            )
        effects = self.effect_estimates()
        if effects:
            lines.append(
                f"  joint effects ({self.metadata.get('effects', 'identify')}; values ± 1σ where identified):"
            )
            lines += [f"    {line}" for line in effect_lines(effects)]
        if self.dropped:
            lines.append("  not identified:")
            lines += [f"    {d}" for d in self.dropped]
        for a, b, rho in self.high_correlations:
            lines.append(f"  warning: {a} and {b} are correlated ({rho:+.3f})")
        lines += [f"  warning: {w}" for w in self.metadata.get("warnings", [])]
        return "\n".join(lines)

    def residual_lines(self) -> list[str]:
        """The model choice (CV table) and the learned residual, as text lines (empty when
        the calibration did not consider one)."""
        if "cv" not in self.metadata:
            return []
        from robocal.identify.residual import CVTable

        lines = CVTable.from_dict(self.metadata["cv"]).lines()
        learned = self.model.residual
        if learned is None:
            return [*lines, "learned residual: none (the physical model alone predicts best)"]
        amplitudes = ", ".join(
            f"{j} {a * 1e6:.0f}" for j, a in zip(learned.joints, learned.amplitudes, strict=True)
        )
        return [
            *lines,
            f"learned residual: joint angle errors, {learned.harmonics} harmonics per revolution on "
            f"{len(learned.joints)} joints (prior RMS µrad: {amplitudes}); RMS error on the calibration "
            f"poses {self.metadata.get('residual_rms_after_mm', float('nan')):.4f} mm, remaining σ "
            f"{learned.noise_std * 1e3:.4f} mm per axis",
        ]

    @property
    def fit_to_noise(self) -> FitToNoise | None:
        """The residuals against the stated measurement noise (None when the data gave
        no noise level)."""
        d = self.metadata.get("fit_to_noise")
        return None if d is None else FitToNoise.from_dict(d)

    def effect_estimates(self) -> dict[str, dict[str, tuple[float, float | None]]]:
        """Every joint effect of the calibrated robot, ``{joint: {field: (value, σ)}}``
        (SI; σ None where the value was not identified but predicted or kept)."""
        from robocal.model.joints import EFFECT_PREFIXES

        sigma = dict(zip(self.names, self.std, strict=True))
        out: dict[str, dict[str, tuple[float, float | None]]] = {}
        for e in self.model.joint_effects:
            row = {}
            for prefix, attr in EFFECT_PREFIXES.values():
                value = getattr(e, attr)
                s = sigma.get(prefix + e.joint)
                if value or s is not None:
                    row[attr] = (value, None if s is None else float(s))
            if row:
                out[e.joint] = row
        return out

    def to_dict(self) -> dict[str, Any]:
        rot = {s.name: s.is_rotation for s in (self.measurement_chain or self.model).steps}
        return {
            "robocal_version": _version(),
            "model": self.model.name,
            "method": self.method,
            "measure": self.measure,
            "n": self.n,
            "success": self.success,
            "message": self.message,
            "iterations": self.iterations,
            "seconds": self.seconds,
            "rms_before_mm": self.rms_before * 1e3,
            "rms_after_mm": self.rms_after * 1e3,
            "residual_std_mm": self.residual_std * 1e3,
            "condition_number": self.condition_number,
            "frame": {"T_device_base": self.frame.tolist()},
            "parameters": [
                {
                    "name": n,
                    "unit": _unit(n, rot.get(n, False)),
                    "nominal": float(v0),
                    "estimate": float(v),
                    "delta": float(v - v0),
                    "std": float(s),
                }
                for n, v0, v, s in zip(self.names, self.nominal, self.estimates, self.std, strict=True)
            ],
            "covariance": self.covariance.tolist(),
            "dropped": [
                {
                    "name": d.name,
                    "reason": d.reason,
                    "absorbed_by": [list(a) for a in d.absorbed_by],
                    **({"sigma_mm": d.sigma * 1e3} if d.sigma is not None else {}),
                    **({"detail": d.detail} if d.detail else {}),
                }
                for d in self.dropped
            ],
            "high_correlations": [list(c) for c in self.high_correlations],
            "compliance_rad_per_Nm": self.compliance,
            "gravity": list(self.gravity),
            **({"payload": _payload_dict(self.payload)} if self.payload is not None else {}),
            **(
                {
                    "residual_covariance_upper": self.model.residual.covariance_upper(),
                    "residual_cross_covariance": [
                        [float(f"{v:.9g}") for v in row] for row in self.residual_cross_covariance
                    ],
                }
                if self.residual_cross_covariance is not None and self.model.residual is not None
                else {}
            ),
            **self.metadata,
        }

    def save(self, directory: str | Path, also: Callable[[Path], object] | None = None) -> Path:
        """Write ``model.yaml`` (calibrated), ``measurement_model.yaml`` (the chain with
        the device frame and tool, for pose/tool calibrations) and ``result.json`` to
        ``directory`` as one transaction (:mod:`robocal.outdir`): the folder holds the
        earlier result or this one, never a mix, also if the process dies or the disk is
        full.  ``also(stage_dir)`` may write more files of the result (a report, the data)
        into the staging directory; each file carries the same run id.

        Raises:
            robocal.outdir.FolderBusyError: another process is writing ``directory``.
            OSError: the folder cannot be written (it is left as it was).
        """
        from robocal.outdir import transaction

        with transaction(directory, RESULT_FILES) as stage:
            save_model(self.model, stage.path / "model.yaml", run_id=stage.run_id)
            if self.measurement_chain is not None:
                save_model(self.measurement_chain, stage.path / "measurement_model.yaml", run_id=stage.run_id)
            text = strict_json(self.to_dict() | {"run_id": stage.run_id}, indent=2) + "\n"
            atomic_write_text(stage.path / "result.json", text)
            if also is not None:
                also(stage.path)
        # a report written later from this object carries the run id of the files it belongs to
        self.metadata["saved_run_id"] = stage.run_id
        return Path(directory)

    @classmethod
    def load(cls, directory: str | Path) -> CalibrationResult:
        """Read a result written by :meth:`save`.

        Raises:
            ValueError: the folder holds no complete, consistent result (the message names
                the file and what is wrong; :class:`robocal.outdir.FolderMixedError` when its
                files come from different runs).
        """
        from robocal.outdir import check_consistent

        directory = Path(directory)
        path = directory / "result.json"
        try:
            data = json.loads(path.read_text(encoding="utf-8"))
        except UnicodeDecodeError as err:
            raise ValueError(f"{path}: not UTF-8 text (byte {err.start})") from None
        except json.JSONDecodeError as err:
            raise ValueError(
                f"{path}: not valid JSON (line {err.lineno}, column {err.colno}: {err.msg})"
            ) from None
        except RecursionError:
            raise ValueError(f"{path}: nested too deeply to be a calibration result") from None
        if not isinstance(data, dict):
            raise ValueError(
                f"{path}: not a calibration result (a JSON object expected, got {type(data).__name__})"
            )
        # not train.csv, test.csv or evaluation.json: a user may put their own there for `report`
        check_consistent(directory, ("model.yaml", "measurement_model.yaml", "report.html"))
        if not (directory / "model.yaml").is_file():
            raise ValueError(f"{directory}: model.yaml is missing beside result.json; calibrate again")
        try:
            result = cls._from_dict(directory, data)
        except (KeyError, TypeError, ValueError, IndexError, AttributeError) as err:
            if isinstance(err, ModelFileError):
                raise
            what = f"missing field {err.args[0]!r}" if isinstance(err, KeyError) else str(err)
            raise ValueError(f"{path}: not a calibration result written by robocal ({what})") from None
        result.metadata.pop("saved_run_id", None)
        if data.get("run_id") is not None:  # a report written from it belongs to these files
            result.metadata["saved_run_id"] = data["run_id"]
        return result

    @classmethod
    def _from_dict(cls, directory: Path, data: dict[str, Any]) -> CalibrationResult:
        model = load_model(directory / "model.yaml")
        chain_path = directory / "measurement_model.yaml"
        params = data["parameters"]
        cov = np.array(data["covariance"], dtype=float).reshape(len(params), len(params))
        std = np.array([p["std"] for p in params], dtype=float)
        with np.errstate(invalid="ignore", divide="ignore"):
            corr = cov / np.outer(std, std)
        known = {f.name for f in dataclasses.fields(cls)}
        extra = {k: v for k, v in data.items() if k not in known and k not in _DICT_ONLY}
        if model.residual is not None and data.get("residual_covariance_upper") is not None:
            model = dataclasses.replace(
                model, residual=model.residual.with_covariance_upper(data["residual_covariance_upper"])
            )
        return cls(
            model=model,
            frame=np.array(data["frame"]["T_device_base"], dtype=float),
            measure=data["measure"],
            method=data["method"],
            names=tuple(p["name"] for p in params),
            estimates=np.array([p["estimate"] for p in params], dtype=float),
            nominal=np.array([p["nominal"] for p in params], dtype=float),
            std=std,
            covariance=cov,
            correlation=corr,
            dropped=tuple(
                Dropped(
                    d["name"],
                    d["reason"],
                    tuple(tuple(a) for a in d["absorbed_by"]),
                    sigma=d["sigma_mm"] / 1e3 if "sigma_mm" in d else None,
                    detail=d.get("detail", ""),
                )
                for d in data["dropped"]
            ),
            residual_std=data["residual_std_mm"] / 1e3,
            rms_before=data["rms_before_mm"] / 1e3,
            rms_after=data["rms_after_mm"] / 1e3,
            condition_number=math.inf
            if data["condition_number"] is None
            else float(data["condition_number"]),
            n=data["n"],
            success=data["success"],
            message=data["message"],
            iterations=data["iterations"],
            seconds=data["seconds"],
            measurement_chain=load_model(chain_path) if chain_path.exists() else None,
            compliance=dict(data.get("compliance_rad_per_Nm", {})),
            gravity=tuple(data.get("gravity", (0.0, 0.0, -9.81))),
            metadata=extra,
            payload=Payload(**data["payload"]) if data.get("payload") else None,
            residual_cross_covariance=(
                np.array(data["residual_cross_covariance"], dtype=float)
                if data.get("residual_cross_covariance") is not None
                else None
            ),
        )


#: the files of a calibration result folder (written and replaced together)
RESULT_FILES = (
    "model.yaml",
    "measurement_model.yaml",
    "result.json",
    "report.html",
    "train.csv",
    "test.csv",
    "evaluation.json",
    "true_model.yaml",
)

_DICT_ONLY = {
    "run_id",
    "robocal_version",
    "residual_cross_covariance",
    "residual_covariance_upper",
    "payload",
    "model",
    "rms_before_mm",
    "rms_after_mm",
    "residual_std_mm",
    "parameters",
    "high_correlations",
    "frame",
}


def _version() -> str:
    from robocal import __version__

    return __version__


def file_hash(path: str | Path) -> str:
    """SHA-256 of a file (recorded in results so that a calibration can be traced)."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for chunk in iter(lambda: fh.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


# ---------------------------------------------------------------------- pipeline
def _uncertainty(
    problem: Problem, x: Array, known_noise: bool = False
) -> tuple[float, Array, Array, Array, float]:
    """σ̂², covariance, standard deviations, correlations, condition number of ``problem``
    at ``x`` (:func:`robocal.identify.stages.uncertainty`)."""
    return uncertainty(problem.residual(x), problem.jacobian(x), problem.rows, known_noise)


def _screen(
    problem: Problem, x0: Array, max_std: float, max_std_ratio: float, known_noise: bool = False
) -> list[tuple[str, float]]:
    """:func:`screen_unidentifiable` of ``problem`` at its start values ``x0``, by name."""
    r, J = problem.residual(x0), problem.jacobian(x0)
    found = screen_unidentifiable(
        r, J, problem.effect_scale(x0), max_std, max_std_ratio, known_noise=known_noise
    )
    return [(problem.free_names[c], sigma) for c, sigma in found]


COMPLIANCE_PREFIX = "compliance_"
_EFFECT_UNITS = {  # coefficient prefix -> (SI unit, display factor, display unit)
    "radial_compliance_": ("rad/(N·m)", 1e6, "µrad/(N·m)"),  # robocal.model.joints.COMPLIANCE_UNIT
    "compliance_": ("rad/(N·m)", 1e6, "µrad/(N·m)"),
    "clearance_": ("rad", math.degrees(1), "deg"),
    "backlash_": ("rad", math.degrees(1), "deg"),
}


def _effect_prefix(name: str) -> str | None:
    return next((p for p in _EFFECT_UNITS if name.startswith(p)), None)


def _unit(name: str, rotation: bool) -> str:
    prefix = _effect_prefix(name)
    if prefix is not None:
        return _EFFECT_UNITS[prefix][0]
    return "rad" if rotation else "m"


def display_unit(name: str, rotation: bool) -> tuple[float, str]:
    """Factor and unit to show an estimated parameter (mm, deg, µrad/(N·m))."""
    prefix = _effect_prefix(name)
    if prefix is not None:
        return _EFFECT_UNITS[prefix][1:]
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
        if peak_load is not None and name.startswith(("compliance_", "radial_compliance_")):
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
        k = min(verdicts, key=lambda i: x[i] / max(sigma[i], 1e-300))
        held.append(verdicts[k])
        active.remove(k)
        if C[k, k] > 0:
            gain = C[:, k] / C[k, k]
            x = x - gain * (x[k] - start[names[k]])
            C = C - np.outer(gain, C[k])
        x[k] = start[names[k]]
        C[k, :] = C[:, k] = 0.0
    return x, held


def _payload_dict(payload: Payload) -> dict[str, Any]:
    out: dict[str, Any] = {"mass": payload.mass, "com": list(payload.com)}
    if payload.inertia is not None:
        out["inertia"] = list(payload.inertia)
    return out


@dataclass(frozen=True)
class _EffectPlan:
    """What a calibration does with joint effects."""

    mode: str  # "none" | "predict" | "identify"
    kinds: tuple[str, ...]  # identified kinds
    joints: tuple[str, ...] | None  # identified joints (None: all)


def _effect_plan(
    model: Model, level: int | None, effects: str | Sequence[str] | None, compliance: bool | Sequence[str]
) -> _EffectPlan:
    from robocal.model.joints import EFFECT_KINDS

    if compliance and effects is not None:
        raise ValueError("give either compliance=... or effects=..., not both")
    if compliance:
        joints = None if compliance is True else tuple(compliance)
        return _EffectPlan("identify", ("compliance",), joints)
    if effects is None:
        effects = "identify" if level == 3 else "none"
    if isinstance(effects, str):
        if effects == "none":
            return _EffectPlan("none", (), None)
        if effects == "predict":
            if not model.joint_effects:
                raise ValueError(
                    f"effects='predict' needs measured joint parameters, but model {model.name!r} has no "
                    "joint_effects (give them in the model file's joint_effects section, or use "
                    "effects='identify')"
                )
            return _EffectPlan("predict", (), None)
        if effects == "identify":
            return _EffectPlan("identify", ("clearance", "backlash", "compliance"), None)
        effects = [effects]
    kinds = tuple(effects)
    unknown = set(kinds) - set(EFFECT_KINDS)
    if unknown:
        raise ValueError(
            f"effects: unknown {sorted(unknown)}; use 'none', 'predict', 'identify' or kinds from "
            f"{', '.join(EFFECT_KINDS)}"
        )
    return _EffectPlan("identify", kinds, None)


@functools.lru_cache(maxsize=64)
def _cached_parameterisation_warnings(model: Model, measure: str) -> tuple[str, ...]:
    from robocal.model.singularity import parameterisation_warnings

    return tuple(parameterisation_warnings(model, measure))


def _parameterisation_warnings(model: Model, measure: str) -> list[str]:
    """Why ``model`` is a poor chain to calibrate (singular or discontinuous at its nominal
    values: e.g. plain DH for parallel axes), with the fix; ``[]`` for a complete model.
    15-25 ms per chain, so cached per model (models are immutable and hashable)."""
    try:
        return list(_cached_parameterisation_warnings(model, measure))
    except TypeError:  # pragma: no cover - an unhashable model: check it every time
        from robocal.model.singularity import parameterisation_warnings

        return parameterisation_warnings(model, measure)


def _distance_objective(problem: Problem, x0: Array, x: Array) -> dict[str, Any]:
    """Seed 001's objective, the sum of the poses' weighted error distances (what
    ``method="bounded"`` minimises; 1 per σ), at the start values and at the solution,
    with the plain mean distances (m) for display."""

    def sums(z: Array) -> tuple[float, float]:
        weighted = problem.residual(z).reshape(-1, problem.rows)
        plain = problem.residual(z, weighted=False).reshape(-1, problem.rows)
        return float(np.linalg.norm(weighted, axis=1).sum()), float(np.linalg.norm(plain, axis=1).mean())

    (before, mean_before), (after, mean_after) = sums(x0), sums(x)
    return {
        "name": "sum of distances",
        "before": before,
        "after": after,
        "mean_distance_before": mean_before,
        "mean_distance_after": mean_after,
    }


def _rms_rose(result: CalibrationResult, pose_errors: Array) -> str | None:
    """A warning when a sum-of-distances fit raised the RMS error (legitimately: it fits
    most poses and leaves a minority with large errors), or ``None``."""
    if result.rms_after <= result.rms_before:
        return None
    large = int(np.sum(pose_errors > 3.0 * float(np.median(pose_errors))))
    mean = result.metadata["objective"]
    return (
        f"the RMS error rose from {result.rms_before * 1e3:.4g} to {result.rms_after * 1e3:.4g} mm while the "
        f"mean distance fell from {mean['mean_distance_before'] * 1e3:.4g} to "
        f"{mean['mean_distance_after'] * 1e3:.4g} mm: the sum of distances (seed 001) fits most poses and "
        f"leaves {large} of {len(pose_errors)} with errors over 3x the median, an error the model does not "
        "describe (backlash? a second robot configuration?); method='lm' minimises the RMS error instead"
    )


def _check_load_model(load_model: Model, model: Model) -> Model:
    if load_model.joint_names != model.joint_names:
        raise ValueError(
            f"load_model {load_model.name!r} has joints {load_model.joint_names}, model {model.name!r} "
            f"{model.joint_names}"
        )
    return load_model


def _geometry_of(result: CalibrationResult, model: Model) -> Model:
    """``model`` with the calibrated values of its own parameters (the tool steps the
    calibration appended left out): the geometry for the joint loads."""
    calibrated = dict(zip(result.model.names, result.model.values.tolist(), strict=True))
    return model.with_values({n: calibrated[n] for n in model.names if n in calibrated})


def _load_signs(model: Model, call: dict[str, Any]) -> NDArray[np.int8]:
    from robocal.model.joints import DEADBAND, load_moments

    eta = load_moments(
        model,
        call["data"].q,
        call["velocities"],
        call["accelerations"],
        gravity=np.asarray(call["gravity"], dtype=float),
        payload=call["payload"],
    )
    return np.where(np.abs(eta) > DEADBAND, np.sign(eta), 0).astype(np.int8)


def _with_load_passes(call: dict[str, Any]) -> CalibrationResult:
    """Calibrate, then recompute the joint loads with the calibrated geometry and
    calibrate again, until the loads' signs stop changing (``load_passes``)."""
    t0 = time.perf_counter()
    model = call["model"]
    passes = int(call["load_passes"])
    geometry = call["load_model"] or model
    signs = _load_signs(geometry, call)
    result = calibrate_physics(**{**call, "load_passes": 1, "load_model": geometry})
    done = 1
    while done < passes:
        geometry = _geometry_of(result, model)
        new_signs = _load_signs(geometry, call)
        if np.array_equal(new_signs, signs):
            break
        signs = new_signs
        result = calibrate_physics(**{**call, "load_passes": 1, "load_model": geometry})
        done += 1
    result.seconds = time.perf_counter() - t0
    result.metadata["load_passes"] = done
    return result


def calibrate(
    model: Model,
    data: Measurements,
    method: Method = "lm",
    *,
    residual: ResidualChoice = "none",
    residual_harmonics: int | Sequence[int] | None = None,
    cv_folds: int = 5,
    **options: Any,
) -> CalibrationResult:
    """Identify the robot's parameters from measurements: the physical model (see
    :func:`calibrate_physics` for ``method`` and every option of the physical fit) and,
    optionally, a learned residual on top of it.

    Args:
        model: the robot model; its free parameters are the candidates.  A catalog robot's
            complete model is :func:`robocal.calibration_model`.
        data: joint values and measured positions (and orientations) in the device frame.
        method: ``"lm"`` (default), ``"pinv"``, ``"bounded"`` or ``"influence"``.
        residual: ``"none"`` (the physical model only, the default of the API),
            ``"auto"`` (k-fold cross-validation on ``data`` chooses among the physical
            model, the physical model with joint compliance when the model has masses and
            no joint effects were asked for, and each with the learned joint angle errors
            of :mod:`robocal.model.residual` with each number of harmonics; the default of
            ``robocal calibrate``) or ``"joint_fourier"`` (always the learned residual; CV
            chooses the harmonics only).
        residual_harmonics: the numbers of harmonics CV chooses from (default
            :data:`robocal.identify.residual.DEFAULT_HARMONICS`).
        cv_folds: folds of the cross-validation.
        **options: the physical fit's options (:func:`calibrate_physics`); an unknown
            one is an error.
    """
    if residual not in RESIDUAL_CHOICES:
        raise ValueError(f"residual must be one of {', '.join(RESIDUAL_CHOICES)}, got {residual!r}")
    if model.residual is not None:  # a calibrated model calibrated again: its residual is refitted
        model = dataclasses.replace(model, residual=None)
    if residual == "none":
        return calibrate_physics(model, data, method, **options)
    from robocal.identify.residual import calibrate_with_residual

    return calibrate_with_residual(
        calibrate_physics, model, data, method, options,
        kind=residual, harmonics=residual_harmonics, folds=cv_folds,
    )  # fmt: skip


def calibrate_physics(
    model: Model,
    data: Measurements,
    method: Method = "lm",
    *,
    measure: Literal["position", "pose"] | None = None,
    frame: Literal["fit", "fixed"] | ArrayLike = "fit",
    tool: Literal["fit", "fixed"] | ArrayLike | None = "fit",
    tool_guess: ArrayLike | None = None,
    weights: Literal["sigma", "none"] = "sigma",
    orientation_weight: float = 0.1,
    loss: str = "linear",
    f_scale: float = 1e-4,
    bounds: tuple[ArrayLike, ArrayLike] | Literal["default", "widened"] | None = "default",
    resolution: float = 1e-5,
    relaxation: float = 0.5,
    per_pose: bool = False,
    combine: Literal["mean", "best", "fit"] = "mean",
    passes: int | None = None,
    max_iterations: int = 200,
    max_std: float = 5e-4,
    max_std_ratio: float = 3.0,
    compliance: bool | Sequence[str] = False,
    gravity: ArrayLike = (0.0, 0.0, -9.81),
    level: int | str | None = None,
    effects: Literal["none", "predict", "identify"] | Sequence[str] | None = None,
    effect_joints: Sequence[str] | None = None,
    payload: Payload | None = None,
    velocities: ArrayLike | None = None,
    accelerations: ArrayLike | None = None,
    load_passes: int = 3,
    load_model: Model | None = None,
    hold_effects: dict[str, str | Dropped] | None = None,
) -> CalibrationResult:
    """Identify the physical robot's parameters from measurements (geometry and joint
    effects; :func:`calibrate` adds the learned residual).

    Args:
        model: the robot model; its free parameters are the candidates.
        data: joint values and measured positions (and orientations) in the device frame.
        method: ``"lm"`` (default), ``"pinv"``, ``"bounded"`` or ``"influence"``
            (see :mod:`robocal.identify.solvers`).
        measure: ``"position"`` or ``"pose"``; default: pose when the data has
            orientations.
        frame: ``"fit"`` (identify ``T_device_base``, default), ``"fixed"`` (the data is
            in the robot's base frame) or a known 4x4 ``T_device_base``.
        tool: ``"fit"`` (identify the tool point/frame), ``"fixed"`` (use ``tool_guess``
            as known), a known 4x4 tool transform or position, or ``None`` (no tool:
            the model's end is measured).
        tool_guess: start value of the tool (position (3,) or 4x4).
        weights: ``"sigma"`` weights rows by 1/σ when the data has ``sigma``.
        orientation_weight: metres per radian, the weight of orientation residuals
            relative to position residuals for pose measurements.
        loss: ``"linear"`` or a robust loss of scipy (``"soft_l1"``, ``"huber"``...) for
            ``lm``; ``f_scale`` (m) is where it starts to down-weight.
        bounds: ``method="bounded"`` only: ``"default"`` (seed 001: every identified robot
            parameter within ±5 mm, ±2° of its start value), ``"widened"`` (those bounds
            widened for the parameters that absorb redundant ones — with d3 dropped, d2
            carries d2 + d3 and may move ±10 mm; a warning lists the widened bounds),
            ``(lower, upper)`` arrays over the free parameters' values, or ``None``
            (unbounded).  The parameters that end at a bound are listed in
            ``result.metadata["at_bounds"]`` and in a warning.
        resolution: measurement resolution (m): the ``pinv``/``influence`` stop criterion.
        relaxation: C < 1 of the ``influence`` method.
        per_pose: ``pinv`` only: seed 003's per-pose pseudo-inverse Jᵢᵀ(JᵢJᵢᵀ)⁻¹ at each
            pose, then the best-fit set (:mod:`robocal.identify.influence`), instead of
            (JᵀJ)⁻¹Jᵀ over all poses.
        combine: per-pose methods (``influence``, ``pinv`` with ``per_pose``): how the
            per-pose sets become one: ``"mean"``, ``"best"`` or ``"fit"``
            (:mod:`robocal.identify.influence`).
        passes: per-pose methods: ``1`` is the thesis' single pass; ``None`` repeats it
            until the combined set stops moving.
        max_std: a parameter whose standard deviation, as a displacement of the tool (m:
            σ times the largest displacement of the measured point per unit of the
            parameter over the measured poses; for joint-effect coefficients σ times the
            robot's size and the pattern's peak, see
            :meth:`~robocal.identify.problem.Problem.effect_scale`), exceeds this is fixed
            at its start value and the fit repeated: it is not identifiable from these
            measurements.
        max_std_ratio: ... and exceeds this many times the median standard deviation of
            all estimated parameters (as tool displacement): with noisy measurements
            every σ is large, which is not a reason to drop a parameter.  The default 3
            has the lowest 5-fold cross-validated error on the *training* poses among
            3, 5, 7, 10 and 30, over the real UR10 (series A, 100 and 300 poses) and
            FIGAROH's TIAGo training day (``benchmarks/bench_pruning_cv.py``; the
            differences are small: 0.5 % on average).
        compliance: also identify joint compliances under gravity, δθ_j = -c_j τ_j(q)
            (c in rad per N·m, τ the torque that holds the arm against gravity, from
            the model's mass properties: the joint gives way under its load): ``True`` for every
            joint or a list of joint names; the same as ``effects=["compliance"]``
            restricted to those joints.  Needs ``model.bodies``.
        gravity: gravity in the robot's base frame (m/s²) for joint effects.
        level: ``1`` (or ``"offsets"``): identify the joint offsets only (with the
            device frame and the tool); ``2`` (``"kinematic"``): every free geometric
            parameter (the default); ``3`` (``"non-geometric"``): level 2 plus joint
            effects (``effects`` defaults to ``"identify"``).
        effects: joint effects (:mod:`robocal.model.joints`): ``"none"`` (geometric
            calibration; the result carries no joint effects), ``"predict"`` (seed
            003's two-stage method: the perturbations predicted from the model's
            measured ``joint_effects`` are removed before the geometric
            identification), ``"identify"`` (clearance tilt, backlash and axial
            compliance of every joint identified with the geometric parameters, where
            observable; unobservable ones are reported and kept at the model's values)
            or a list of kinds (``clearance``, ``backlash``, ``compliance``,
            ``radial``).  With ``"identify"`` the model's joint effects of other kinds
            are predicted as known.  Needs ``model.bodies``.
        effect_joints: joints whose effects are identified (default all).
        payload: a load on the tool for the joint loads.
        velocities, accelerations: ``(n, dof)`` joint rates of each measurement when
            the robot was moving (rad/s, rad/s²): inertial loads (seed 003 eq. 5.14).
        load_passes: the joint loads (and so the signs of backlash and clearance tilt)
            depend on the geometry; the first pass computes them with ``model``, each
            further pass with the geometry just calibrated, until their signs stop
            changing (at most ``load_passes`` passes).  Near a load's sign change the
            nominal geometry can predict the wrong side of the backlash at a few poses
            (Katana 450: 31 of 118 poses, up to 0.4 mm); the second pass removes this.
        load_model: the model whose geometry gives the joint loads (default ``model``;
            set by the passes).
        hold_effects: joint-effect coefficients (``compliance_wrist_2``) kept at their start
            values and not identified, with the reason to report in ``dropped`` (a text or a
            :class:`~robocal.identify.observability.Dropped`); the learned residual's stage
            holds those it confounds.

    Joint effects are physical: an identified clearance tilt, backlash or compliance is at
    least :data:`EFFECT_SIGNIFICANCE` σ above zero.  One that the fit puts below zero, or
    closer to it, is kept at its start value and the fit repeated (a non-negativity active
    set with a significance test, chosen least supported first on the linearised problem:
    :func:`effects_to_hold`); ``dropped`` says why (:func:`effect_verdict`).
    """
    call = dict(locals())
    t_start = time.perf_counter()
    if method not in METHODS:
        raise ValueError(f"unknown method {method!r}; choose one of {', '.join(METHODS)}")
    if isinstance(bounds, str) and bounds not in BOUNDS_CHOICES:
        choices = ", ".join(BOUNDS_CHOICES)
        raise ValueError(f"bounds must be one of {choices}, two arrays or None, got {bounds!r}")
    if data.position is None:
        raise ValueError("the measurements have no positions to calibrate against")
    if data.dof != model.dof:
        raise ValueError(
            f"the data has {data.dof} joint columns but model {model.name!r} has {model.dof} joints"
        )
    if measure is None:
        measure = "pose" if data.orientation is not None else "position"
    if measure == "pose" and data.orientation is None:
        raise ValueError("measure='pose' needs measured orientations")
    # a calibrated model (model.yaml of an earlier calibration) carries its measured tool:
    # it becomes the tool's start value
    model, carried_tool = _without_measured_tool(model)
    if carried_tool is not None and tool_guess is None:
        tool_guess = carried_tool
    n = data.n
    # stop with an explanation when the data cannot determine the model (identical
    # poses, joints that never move, too few poses...) rather than fit a silent bad model
    problem_warnings = check_data(model, data) + _parameterisation_warnings(
        model, measure if measure is not None else ("pose" if data.orientation is not None else "position")
    )
    if (3 if measure == "position" else 6) * data.n < len(model.free_names) + 12:
        # so few poses that there may be fewer equations than unknowns: say so before fitting
        # (otherwise the rank check below, which reuses the fit's own rank test, decides)
        check_rank(model, data, measure=measure, frame=frame, tool=tool, tool_guess=tool_guess)
    level_number = parse_level(level)
    plan = _effect_plan(model, level_number, effects, compliance)
    if plan.mode != "none" and load_passes > 1:
        return _with_load_passes(call)
    given_model = model
    if level_number == 1:  # joint offsets only: every other robot parameter is kept
        model = model.fixed([s.name for s in model.steps if s.joint is None])

    # tool and frame start values
    fit_frame = isinstance(frame, str) and frame == "fit"
    T_known = None
    if not isinstance(frame, str):
        T_known = np.asarray(frame, dtype=float)
        if T_known.shape != (4, 4):
            raise ValueError(f"frame must be 'fit', 'fixed' or a 4x4 transform, got shape {T_known.shape}")
    T_tool0 = np.eye(4)
    if tool_guess is not None:
        g = np.asarray(tool_guess, dtype=float)
        T_tool0 = g if g.shape == (4, 4) else spatial.homogeneous(p=g)
    fit_tool = isinstance(tool, str) and tool == "fit"
    if tool is not None and not isinstance(tool, str):
        g = np.asarray(tool, dtype=float)
        T_tool0 = g if g.shape == (4, 4) else spatial.homogeneous(p=g)
    T_flange = model.fk(data.q)
    T_frame, T_tool = initial_frame_and_tool(
        model, data, measure, T_tool0, fit_frame, fit_tool and tool is not None, T_known, T_flange=T_flange
    )

    chain = measurement_chain(model, T_frame, None if tool is None else T_tool, measure, fit_frame)
    if tool is not None and not fit_tool:
        chain = chain.fixed([s.name for s in chain.steps if s.name.startswith(TOOL_PREFIX)])
    length = float(robot_sizes(T_flange[None])[0])
    rows = 3 if measure == "position" else 6
    w = np.ones((n, rows))
    known_noise = weights == "sigma" and data.sigma is not None  # weights 1/σ of a stated noise
    if known_noise:
        w[:, :3] = 1.0 / np.maximum(data.sigma, 1e-12)
    if rows == 6:
        w[:, 3:] = orientation_weight * (w[:, :3].mean(axis=1, keepdims=True))
    basis, effect_names, effect_kinds, known, start = None, (), (), None, None
    if plan.mode != "none":
        from robocal.model.joints import EFFECT_KINDS, EFFECT_PREFIXES, effect_basis, load_moments
        from robocal.model.joints import joint_perturbations as predict_effects

        g = np.asarray(gravity, dtype=float)
        geometry = model if load_model is None else _check_load_model(load_model, model)
        loads = load_moments(geometry, data.q, velocities, accelerations, gravity=g, payload=payload)
        if plan.kinds:
            joints = plan.joints if plan.joints is not None else effect_joints
            basis, effect_names, effect_kinds = effect_basis(
                model, data.q, kinds=plan.kinds, joints=joints, loads=loads
            )
        by_joint = {e.joint: e for e in model.joint_effects}
        start = np.array(
            [getattr(by_joint[j], EFFECT_PREFIXES[k][1]) if j in by_joint else 0.0 for k, j in effect_kinds]
        )
        # the model's joint effects that are not identified are known: predicted at every pose
        if model.joint_effects:
            identified = set(effect_kinds)
            rest = [
                dataclasses.replace(
                    e, **{EFFECT_PREFIXES[k][1]: 0.0 for k in EFFECT_KINDS if (k, e.joint) in identified}
                )
                for e in model.joint_effects
            ]
            known = predict_effects(model, data.q, effects=rest, loads=loads)
            if not np.any(known):
                known = None
            else:  # say so: a robot whose joints differ from its model's would be mis-corrected
                predicted = {
                    k: [e.joint for e in rest if getattr(e, EFFECT_PREFIXES[k][1])] for k in EFFECT_KINDS
                }
                listed = "; ".join(f"{k} ({', '.join(j)})" for k, j in predicted.items() if j)
                problem_warnings.append(
                    f"joint effects of model {model.name!r} predicted as known, not identified: {listed}; "
                    "if this robot's differ, identify them too (level=3 / --level 3) or calibrate a "
                    "model without them"
                )
    if model.residual is not None:  # a learned residual given with the model is known: applied, not fitted
        learned = model.residual.perturbations(data.q, model.dof)
        known = learned if known is None else known + learned
    problem = Problem(
        chain,
        data.q,
        data.position,
        data.orientation if rows == 6 else None,
        w.reshape(-1),
        length,
        basis,
        effect_names,
        known,
        start,
    )

    orientation_hint = ""
    if rows == 6:
        # with the device frame and the tool fitted, a real robot's orientations agree with
        # its model to a degree or so; far more means the file's rotations are read wrongly
        angle = np.degrees(
            np.median(
                np.linalg.norm(problem.residual(problem.x0, weighted=False).reshape(n, 6)[:, 3:], axis=1)
            )
        )
        if angle > 5.0:
            orientation_hint = (
                f"the measured orientations differ from the model's by {angle:.3g}° (median) after the "
                "device frame and the tool were fitted: check the orientation convention of the data "
                "(orientation='euler:XYZ:deg' / --orientation: intrinsic XYZ is upper case, extrinsic "
                "xyz lower case), or calibrate positions only (measure='position')"
            )
            problem_warnings.append(orientation_hint)

    # identifiable set, preferring the frame, then the tool, then the robot in chain order
    names = problem.free_names
    selection = identifiable_set(problem.scaled_jacobian(problem.x0), names)
    problem_warnings += check_rank(
        given_model,
        data,
        measure=measure,
        frame=frame,
        tool=tool,
        tool_guess=tool_guess,
        kept=selection.kept,
        candidates=names,
    )
    if selection.dropped:
        problem = problem.fix([d.name for d in selection.dropped])
    held = [
        why if isinstance(why, Dropped) else Dropped(name, "undetermined", detail=str(why))
        for name, why in (hold_effects or {}).items()
        if name in problem.effect_names
    ]
    if held:
        problem = problem.fix([d.name for d in held])
    names = problem.free_names
    x0 = problem.x0

    options: dict[str, Any] = {"max_iterations": max_iterations}
    if method == "lm":
        options |= {"loss": loss, "f_scale": f_scale * float(np.median(w[:, :3]))}
    elif method in ("pinv", "influence"):
        options |= {"resolution": resolution}
        if method == "influence" or per_pose:
            options |= {"combine": combine, "passes": passes, "per_pose": per_pose, "relaxation": relaxation}
    elif method == "bounded":
        lo, hi, widened = _bounded_method_bounds(bounds, problem, selection.dropped, length, set(model.names))
        if widened is not None:
            problem_warnings.append(widened)
        options["bounds"] = (lo, hi)
    dropped = list(selection.dropped) + held
    if method != "bounded":  # the hopeless ones before the first fit (they are pruned anyway)
        screened = _screen(problem, x0, max_std, max_std_ratio, known_noise)
        if screened:
            dropped += [Dropped(name, "poorly identifiable", sigma=sigma) for name, sigma in screened]
            problem = problem.fix([name for name, _ in screened])
            names, x0 = problem.free_names, problem.x0
    t_solve = time.perf_counter()
    result: SolveResult = solve(problem, x0, method, **options)
    solve_seconds = time.perf_counter() - t_solve
    evaluations = result.evaluations
    x = result.x
    _, cov, std, corr, cond = _uncertainty(problem, x, known_noise)
    # drop what these measurements cannot determine, worst first, and refit
    # an unconverged fit says nothing about σ; a bounded fit keeps every parameter within
    # its bounds, so a poorly determined one cannot run away and is better kept
    prune = result.success and method != "bounded"
    for _ in range(len(x) - 1 if prune else 0):
        # σ as tool displacement at the measured poses: beyond the thresholds?
        found = poorly_identifiable(std, problem.effect_scale(x), max_std, max_std_ratio)
        if found is None:
            break
        worst, sigma = found
        dropped.append(Dropped(names[worst], "poorly identifiable", sigma=sigma))
        keep = np.arange(len(x)) != worst
        problem = problem.fix([names[worst]])
        names = problem.free_names
        x0 = x0[keep]
        t_solve = time.perf_counter()
        # from the start values: the dropped parameter may have dragged others along a
        # nearly flat valley of the first fit (real UR10 data, plain DH: a5 +143 mm)
        result = solve(problem, x0, method, **options)
        solve_seconds += time.perf_counter() - t_solve
        evaluations += result.evaluations
        x = result.x
        _, cov, std, corr, cond = _uncertainty(problem, x, known_noise)
    # joint effects are physical (>= 0) and identified only when the data tells them from zero
    for _ in range(problem.n_effects if result.success else 0):
        if not problem.n_effects:
            break
        held_at = dict(zip(problem.effect_names, problem.effect_start.tolist(), strict=True))
        peaks = dict(zip(problem.effect_names, np.abs(problem.effect_basis).max(axis=(1, 2, 3)), strict=True))
        x_held, verdicts = effects_to_hold(names, x, cov, held_at, peaks)
        if not verdicts:
            break
        dropped += verdicts
        keep = np.array([name not in {v.name for v in verdicts} for name in names], dtype=bool)
        problem = problem.fix([v.name for v in verdicts])
        names, x0, x_start = problem.free_names, x0[keep], x_held[keep]
        if method == "bounded":
            options["bounds"] = tuple(b[keep] for b in options["bounds"])
            x_start = np.clip(x_start, *options["bounds"])
        t_solve = time.perf_counter()
        # from the linearised solution with them held (a Gauss-Newton step from the fit found)
        result = solve(problem, x_start, method, **options)
        solve_seconds += time.perf_counter() - t_solve
        evaluations += result.evaluations
        x = result.x
        _, cov, std, corr, cond = _uncertainty(problem, x, known_noise)

    r_plain = problem.residual(x, weighted=False).reshape(n, rows)
    rms_after = float(np.sqrt(np.mean(np.sum(r_plain[:, :3] ** 2, axis=1))))
    pose_errors = np.linalg.norm(r_plain[:, :3], axis=1)  # (n,) m
    outliers = _outlier_poses(pose_errors, data.sigma)
    rms_before = float(
        np.sqrt(np.mean(np.sum(problem.residual(x0, weighted=False).reshape(n, rows)[:, :3] ** 2, axis=1)))
    )

    # the calibrated chain, and the robot model with the tool in the base frame
    chain = problem.chain
    values = problem.values(x)
    calibrated_chain = chain.with_values(dict(zip(chain.names, values, strict=True)))
    frame_names = [s.name for s in chain.steps if s.name.startswith(("frame0_", FRAME_PREFIX))]
    frame_steps_ = calibrated_chain.steps[: len(frame_names)]  # the frame steps come first
    T_device_base = spatial.chain_product([s.motion for s in frame_steps_], [s.value for s in frame_steps_])
    robot_steps = [s for s in calibrated_chain.steps if s.name not in set(frame_names)]
    free_before = {s.name: s.free for s in given_model.steps}
    robot_steps = [
        s if s.free == free_before.get(s.name, True) else dataclasses.replace(s, free=not s.free)
        for s in robot_steps
    ]
    calibrated = dataclasses.replace(
        given_model, steps=tuple(robot_steps), notes=(given_model.notes + " calibrated").strip()
    )
    effects = {
        name.removeprefix(COMPLIANCE_PREFIX): float(v)
        for name, v in zip(names, x, strict=True)
        if name.startswith(COMPLIANCE_PREFIX)
    }
    if plan.mode == "none":
        calibrated = dataclasses.replace(calibrated, joint_effects=())
    elif plan.kinds:
        from robocal.model.joints import effects_from_values

        estimated = dict(zip(names, x, strict=True))
        values = {
            pair: estimated.get(c, s0) for c, pair, s0 in zip(effect_names, effect_kinds, start, strict=True)
        }
        calibrated = dataclasses.replace(calibrated, joint_effects=effects_from_values(model, values))
    seconds = time.perf_counter() - t_start
    calibration = CalibrationResult(
        model=calibrated,
        frame=T_device_base,
        measure=measure,
        method=method,
        names=names,
        estimates=x,
        nominal=x0,
        std=std,
        covariance=cov,
        correlation=corr,
        dropped=tuple(dropped),
        residual_std=float(np.sqrt(np.sum(r_plain[:, :3] ** 2) / max(3 * n - len(x), 1))),
        rms_before=rms_before,
        rms_after=rms_after,
        condition_number=cond,
        n=n,
        success=result.success,
        message=result.message,
        iterations=result.iterations,
        seconds=seconds,
        measurement_chain=calibrated_chain,
        compliance=effects,
        gravity=tuple(float(g) for g in np.asarray(gravity, dtype=float)),
        metadata={
            "solve_seconds": solve_seconds,
            # residual (and, for lm, fused residual-and-Jacobian) evaluations of all fits
            "evaluations": evaluations,
            # per pose, predicted minus measured (device frame) at the solution
            "residuals_mm": np.round(r_plain * 1e3, 6).tolist(),
            "level": level_number if level_number is not None else (3 if plan.mode != "none" else 2),
            "outlier_poses": outliers,
            "effects": plan.mode,
        },
        payload=payload,
    )
    if method == "bounded":
        lo, hi = options["bounds"]
        at = parameters_at_bounds(names, x, lo, hi)
        calibration.metadata["at_bounds"] = at
        calibration.metadata["objective"] = _distance_objective(problem, x0, x)
        if (rose := _rms_rose(calibration, pose_errors)) is not None:
            problem_warnings.append(rose)
        if at:
            problem_warnings.append(
                f"{', '.join(at)} ended at {'its bound' if len(at) == 1 else 'their bounds'}: the bound, not "
                "the data, decided the value and the fit may be poor; widen the bounds (bounds='widened' for "
                "parameters that absorb redundant ones, or your own arrays) or use method='lm'"
            )
    if outliers:
        worst = sorted(outliers, key=lambda i: -pose_errors[i])[:5]
        shown = ", ".join(
            f"{i} ({pose_errors[i] * 1e3:.3g} mm at q = [{', '.join(f'{v:.4g}' for v in data.q[i])}])"
            for i in worst
        )
        problem_warnings.append(
            f"{len(outliers)} pose(s) with residuals far beyond the others (more than 5x their median"
            + (" and 5x the noise" if data.sigma is not None else "")
            + f"): {shown}{' ...' if len(outliers) > 5 else ''}; measurement glitches? "
            + (
                "a robust loss (loss='soft_l1' / --loss soft_l1) down-weights them"
                if loss == "linear"
                else ""
            )
        )
    equations = n * rows
    if equations < 2 * len(x):
        needed = -(-2 * len(x) // rows)  # poses for twice as many equations as unknowns
        problem_warnings.append(
            f"{n} poses give {equations} equations for {len(x)} unknowns: so little redundancy "
            "makes the estimates sensitive to every measurement and their uncertainty itself "
            f"uncertain; measure at least {needed} poses"
        )
    if known_noise:
        # does the model explain the data down to the noise? (position rows; for pose
        # measurements their share of the estimated parameters)
        noise = fit_to_noise(r_plain[:, :3], data.sigma, len(x) * 3 / rows)
        calibration.metadata["fit_to_noise"] = noise.to_dict()
        if (noise_warning := noise.warning()) is not None:
            problem_warnings.append(noise_warning)
    try:
        calibration.metadata["warnings"] = problem_warnings + check_solution(calibration)
    except CalibrationGuardError as err:
        raise CalibrationGuardError(f"{err}; {orientation_hint}" if orientation_hint else str(err)) from None
    return calibration
