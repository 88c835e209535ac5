"""Step 4 of a calibration — what to command instead.

A calibrated model tells where the real robot goes for given joint values; this module
inverts it: the joint commands that bring the real robot onto Cartesian targets.

* :func:`compensate_targets` — Cartesian targets (positions ``(n, 3)`` or tool frames
  ``(n, 4, 4)``, in the robot's base frame or in the measurement/cell frame identified
  by the calibration) -> joint commands.  First the *nominal* solution: the batched
  damped least-squares IK (:func:`robocal.measure.ik.solve_ik`) on the nominal model,
  which is what the controller would command (the configuration branch is chosen
  there, from ``q0``).  Then the same IK on the calibrated (real) model, started from
  the nominal solution with no restarts, so it converges to the nearby solution of the
  same branch (elbow/wrist configuration); joint limits are respected by projection.
  Per target: the predicted error of the real robot before (at the nominal command)
  and after, whether it was reached, and how far the joints moved.
* :func:`filter_program` — the "calibration filter" of commercial controllers: joint
  targets computed with the nominal model in, corrected joint targets out.  The
  nominal model's tool frame at each programmed configuration is the target.
* Non-geometric joint effects (e.g. compliance under gravity) depend on the commanded
  configuration; they are evaluated at every iterate of the IK, so the iteration
  converges to the fixed point ``real(q, effects(q)) = target`` (see
  :mod:`robocal.measure.ik`).
* :func:`compensate_path` / :func:`compensate_cartesian_path` — sampled joint or
  Cartesian paths, by the full IK (every sample started from its own nominal sample,
  so the corrected path follows the nominal one without jumps) or by seed 003 eq. 5.22,
  one Jacobian step per sample,

      Δθ = Jᵀ (J Jᵀ)⁻¹ (P_tilting-geom − P_theor),   θ_corrected = θ − Δθ,

  where ``P_tilting-geom`` is the calibrated model's prediction (geometry and joint
  effects) at the nominal joints, ``P_theor`` the desired path and ``J`` the
  position Jacobian ∂P/∂θ (3 x dof, seed 003 uses the 3 position rows of its 5-axis
  arm); ``iterations > 1`` repeats the step (Gauss–Newton).
* Off-line programs: :func:`read_targets` reads ``name,x,y,z[,qw,qx,qy,qz]`` CSV files;
  :meth:`Compensation.write` writes the corrected program as CSV or JSON (atomically).

Which models
------------
``calibrated`` is a :class:`~robocal.identify.calibrate.CalibrationResult` (its
``model`` — robot and measured tool, base frame —, its device frame ``frame`` =
``T_device_base`` and its joint effects ``joint_perturbations``) or a bare
:class:`~robocal.model.chain.Model`.  The nominal model (what the controller believes)
defaults, for a result, to the calibrated model with every estimated parameter back at
its start value (the nominal robot with the tool as first fitted, the model behind
``result.rms_before``).  A given nominal model without the calibrated model's tool
steps (``tcp_*``) gets them appended: the controller is assumed to know its tool.  A
bare model without a nominal model is its own nominal model; the errors "before" are
then unknown (NaN).

Units: SI inside (m, rad); files and tables in mm (and degrees where said).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from robocal import choices, spatial
from robocal.compensate import safety
from robocal.compensate.flanks import FlankEffects, command_effects, flank_note
from robocal.compensate.ik_options import IKOptions
from robocal.compensate.nominal_ik import nominal_solutions
from robocal.compensate.result import Compensation
from robocal.identify.result import CalibrationResult
from robocal.measure.ik import IKResult, PerturbationFunction, solve_ik
from robocal.measure.ik_regularized import solve_regularized
from robocal.measure.ik_starts import TargetKind
from robocal.model.chain import Model
from robocal.model.flange_tool import split_tool

__all__ = ["compensate_targets", "filter_program", "model_perturbations", "nominal_model"]

Array = NDArray[np.float64]
Calibrated = CalibrationResult | Model
Frame = choices.Frame  # the one table of choices (robocal.choices)


# ---------------------------------------------------------------------- models
def nominal_model(result: CalibrationResult) -> Model:
    """The model the controller believed before calibration: ``result.model`` with every
    estimated robot parameter at its start value (``result.nominal``) and no joint
    effects.  Its tool is the measured one the calibration identified (the controller's
    TCP set to it): the error "before" is the robot's, not a change of tool."""
    names = set(result.robot.names)  # the tool's steps keep their calibrated values
    start = {n: float(v) for n, v in zip(result.names, result.nominal, strict=True) if n in names}
    model = result.model.with_values(start)
    changes: dict[str, Any] = {"notes": (model.notes.replace("calibrated", "").strip() + " nominal").strip()}
    if getattr(model, "joint_effects", ()):
        changes["joint_effects"] = ()
    return dataclasses.replace(model, **changes)


def _with_tool(nominal: Model, real: Model) -> Model:
    """``nominal`` with ``real``'s tool steps (``tcp_*``) appended when it has none."""
    tool = split_tool(real)
    if not tool.steps or split_tool(nominal).steps:
        return nominal
    clash = {s.name for s in tool.steps} & set(nominal.names)
    if clash:  # pragma: no cover - names with the tool prefix are caught above
        raise ValueError(f"nominal model {nominal.name!r} already uses {sorted(clash)}")
    return tool.on(nominal)


@dataclass(frozen=True)
class Setup:
    real: Model
    nominal: Model
    has_nominal: bool
    effects: PerturbationFunction | None
    T_device_base: Array | None
    result: CalibrationResult | None = None

    def expected_error(self, q: Array) -> Array:
        """``(n,)`` RMS position error (m) to expect at commands ``q`` (NaN without a
        calibration result, whose uncertainty it is)."""
        if self.result is None or not len(q):
            return np.full(len(q), np.nan)
        return self.result.expected_position_error(q)


def model_perturbations(model: Model) -> PerturbationFunction | None:
    """A bare model's joint perturbations ``q (n, dof) -> (n, dof, 3)``: the joint effects it
    states (e.g. compliance a constraint calibration identified) under gravity along the
    base's -z with no payload, as they were identified, and its learned residual (joint
    angle errors); None when it has neither.  A model that states joint effects without the
    link masses their loads need is refused (ValueError naming it): its commands would leave
    the deflection out silently.  Backlash and clearance are evaluated as
    :class:`~robocal.compensate.flanks.FlankEffects` (continuous across a zero load)."""
    physical = bool(model.joint_effects)
    if physical and not model.bodies:
        raise ValueError(
            f"model {model.name!r} states joint effects but no link masses: their gravity loads "
            "cannot be computed, so commands from it would leave the deflections out"
        )
    return command_effects(model)


def compensation_setup(
    calibrated: Calibrated, nominal: Model | None, joint_effects: PerturbationFunction | None
) -> Setup:
    if isinstance(calibrated, CalibrationResult):
        real = calibrated.model
        effects = command_effects(calibrated)
        frame: Array | None = np.asarray(calibrated.frame, dtype=float)
        nom = nominal_model(calibrated) if nominal is None else nominal
        has_nominal = True
    elif isinstance(calibrated, Model):
        real, frame = calibrated, None
        effects = model_perturbations(calibrated)
        nom = calibrated if nominal is None else nominal
        has_nominal = nominal is not None
    else:
        raise TypeError(f"calibrated must be a CalibrationResult or a Model, got {type(calibrated).__name__}")
    if joint_effects is not None:
        effects = joint_effects
    if not isinstance(nom, Model):
        raise TypeError(f"nominal_model must be a Model, got {type(nom).__name__}")
    if nom.dof != real.dof:
        raise ValueError(
            f"nominal model {nom.name!r} has {nom.dof} joints but the calibrated model "
            f"{real.name!r} has {real.dof}"
        )
    nom = _with_tool(nom, real)
    result = calibrated if isinstance(calibrated, CalibrationResult) else None
    return Setup(real, nom, has_nominal, effects, frame, result)


def predict(setup: Setup, q: Array) -> Array:
    """Tool frames ``(n, 4, 4)`` of the real robot (base frame) at commands ``q``."""
    d = None if setup.effects is None else setup.effects(q)
    return setup.real.fk(q, d)


# ---------------------------------------------------------------------- targets
def as_frames(targets: ArrayLike, kind: TargetKind | Literal["auto"]) -> tuple[Array, TargetKind]:
    """``(n, 4, 4)`` target frames and the resolved kind."""
    T = np.asarray(targets, dtype=float)
    if T.ndim in (1, 2) and T.shape[-1:] == (3,):
        if kind not in ("auto", "position"):
            raise ValueError(f"targets shaped {T.shape} are positions; kind {kind!r} needs (n, 4, 4) frames")
        T, kind = spatial.homogeneous(p=T.reshape(-1, 3)), "position"
    elif T.ndim in (2, 3) and T.shape[-2:] == (4, 4):
        T = T.reshape(-1, 4, 4)
        kind = "pose" if kind == "auto" else kind
    else:
        raise ValueError(f"targets shaped {T.shape}: expected positions (n, 3) or tool frames (n, 4, 4), m")
    if kind not in ("position", "pose", "axis"):
        raise ValueError(f"kind must be 'auto', 'position', 'pose' or 'axis', got {kind!r}")
    bad = np.flatnonzero(~np.isfinite(T).reshape(len(T), -1).all(axis=1))
    if len(bad):
        raise ValueError(f"target {int(bad[0])} contains NaN or inf")
    return T, kind


def to_base(T: Array, frame: Frame | ArrayLike, setup: Setup) -> Array:
    """Targets given in ``frame`` -> the robot's base frame."""
    if isinstance(frame, str):
        if frame == "base":
            return T
        if frame != "measurement":
            raise ValueError(f"frame must be 'base', 'measurement' or a 4x4 transform, got {frame!r}")
        if setup.T_device_base is None:
            raise ValueError(
                "frame='measurement' needs a CalibrationResult (its identified device frame); "
                "a bare model has only its base frame"
            )
        T_frame_base = setup.T_device_base
    else:
        T_frame_base = np.asarray(frame, dtype=float)
        if T_frame_base.shape != (4, 4):
            raise ValueError(
                f"frame must be 'base', 'measurement' or a 4x4 T_frame_base, got {T_frame_base.shape}"
            )
    return spatial.inverse(T_frame_base) @ T


def errors(T: Array, T_target: Array, kind: TargetKind, tool_axis: int) -> tuple[Array, Array]:
    """Position (m) and orientation (rad) errors ``(n,)`` of ``T`` against the targets."""
    dist = np.linalg.norm(T[:, :3, 3] - T_target[:, :3, 3], axis=1)
    if kind == "position":
        return dist, np.zeros(len(T))
    if kind == "pose":
        return dist, np.linalg.norm(
            spatial.matrix_to_rotvec(T[:, :3, :3] @ np.swapaxes(T_target[:, :3, :3], 1, 2)), axis=1
        )
    a, b = T[:, :3, tool_axis], T_target[:, :3, tool_axis]
    return dist, np.arctan2(np.linalg.norm(np.cross(a, b), axis=1), np.einsum("ij,ij->i", a, b))


def _default_kind(dof: int) -> TargetKind:
    return "pose" if dof >= 6 else ("axis" if dof == 5 else "position")


# ---------------------------------------------------------------------- core
def joint_names(names: Sequence[str] | None, n: int) -> tuple[str, ...]:
    if names is None:
        return tuple(str(i + 1) for i in range(n))
    out = tuple(str(v) for v in names)
    if len(out) != n:
        raise ValueError(f"{len(out)} names for {n} targets")
    return out


def correct(
    setup: Setup,
    T: Array,
    kind: TargetKind,
    q_nominal: Array,
    nominal_reachable: NDArray[np.bool_],
    names: tuple[str, ...],
    *,
    ik: IKOptions,
    max_joint_change: float,
    solved: IKResult | None = None,
    nominal_reasons: tuple[str, ...] = (),
) -> Compensation:
    """The calibrated-model IK from the nominal solution (damped near singularities), the
    invariants of :mod:`robocal.compensate.safety` (a refused target keeps its nominal
    command), and the bookkeeping.  ``solved``: commands found otherwise (seed 003 eq. 5.22
    for paths), put through the same invariants instead of the IK; ``ik``: the IK's settings
    (its restarts and seed are the nominal IK's: the correction starts from the nominal solution)."""
    tool_axis, orientation_weight = ik.tool_axis, ik.orientation_weight
    res = solved or solve_ik(
        setup.real, T, q0=q_nominal, restarts=0, tol=ik.tol, tol_angle=ik.tol_angle, max_iter=ik.max_iter,
        joint_effects=setup.effects, kind=kind, tool_axis=tool_axis, orientation_weight=orientation_weight,
    )  # fmt: skip
    q, reached = res.q.copy(), res.reachable.copy()
    before, angle_before = errors(predict(setup, q_nominal), T, kind, tool_axis)
    sigma = safety.sigma_min(setup.real, q_nominal, setup.effects, kind, tool_axis)
    near = sigma < safety.SINGULAR_SIGMA
    # |e| weighted as sigma_min's Jacobian (1 m per rad)
    size = np.hypot(before, angle_before)
    bound = safety.joint_bound(size, sigma, near, setup.real.joint_types)
    if near.any():
        damped = solve_regularized(
            setup.real, T[near], q_nominal[near], damping=safety.DAMPING, joint_effects=setup.effects,
            kind=kind, tool_axis=tool_axis, orientation_weight=orientation_weight,
        )  # fmt: skip
        revolute = np.array([t == "revolute" for t in setup.real.joint_types])
        q[near] = q_nominal[near] + safety.limit_damped(damped.q - q_nominal[near], bound[near], revolute)
    verdict = safety.judge(
        setup.nominal, q, q_nominal, bound, near, reached, np.asarray(nominal_reachable, dtype=bool), sigma,
        nominal_reasons,
    )  # fmt: skip
    refused = np.array([st == "refused" for st in verdict.status], dtype=bool)
    q[refused] = q_nominal[refused]  # left as written: the controller's own command
    after, angle_after = errors(predict(setup, q), T, kind, tool_axis)
    if not setup.has_nominal and setup.effects is None:  # a bare model: its own nominal, no error known
        before, angle_before = np.full(len(T), np.nan), np.full(len(T), np.nan)
    spread, flank_notes, notes = flank_spread(setup, q, verdict, ik.tol)
    reasons = tuple(
        f"{r}; {f}" if r and f else r or f for r, f in zip(verdict.reasons, flank_notes, strict=True)
    )
    change = np.abs(q - q_nominal).max(axis=1) if len(T) else np.zeros(0)
    moved = setup.nominal.fk(q)[:, :3, 3] - setup.nominal.fk(q_nominal)[:, :3, 3]
    return Compensation(
        q=q,
        q_nominal=q_nominal,
        targets=T,
        kind=kind,
        error_before=before,
        error_after=after,
        angle_before=angle_before,
        angle_after=angle_after,
        reachable=reached,
        nominal_reachable=np.asarray(nominal_reachable, dtype=bool),
        joint_change=change,
        branch_kept=verdict.config_kept & (change <= max_joint_change) & ~refused,
        names=names,
        joint_names=setup.real.joint_names,
        joint_types=setup.real.joint_types,
        iterations=res.iterations,
        expected_error_after=setup.expected_error(q),
        status=verdict.status,
        reasons=reasons,
        sigma_min=sigma,
        configuration=verdict.configuration,
        joint_bound=bound,
        tool_correction=np.linalg.norm(moved, axis=1),
        flank_spread=spread,
        flank_notes=flank_notes,
        notes=notes,
    )


def flank_spread(
    setup: Setup, q: Array, verdict: safety.Verdict, tol: float
) -> tuple[Array, tuple[str, ...], tuple[str, ...]]:
    """``(n,)`` each command's flank spread (m; :mod:`robocal.compensate.flanks`, zeros
    without backlash or clearance), per target the note naming it where it exceeds ``tol``
    (m) on a target not refused (else empty), and the run's notes (joints no load sets)."""
    reasons = [""] * len(q)
    if not isinstance(setup.effects, FlankEffects) or not len(q):
        return np.zeros(len(q)), tuple(reasons), ()
    spread, joints = setup.effects.spread(setup.real, q)
    unloaded = setup.effects.unloaded_note(setup.real, q)
    for i in np.flatnonzero(spread > tol):
        if verdict.status[i] != "refused":
            reasons[i] = flank_note(float(spread[i]), joints[i])
    return spread, tuple(reasons), (unloaded,) if unloaded else ()


def compensate_targets(  # noqa: PLR0913 - public keyword options, documented in README and docs
    calibrated: Calibrated,
    targets: ArrayLike,
    nominal_model: Model | None = None,
    *,
    kind: TargetKind | Literal["auto"] = "auto",
    frame: Frame | ArrayLike = "base",
    q0: ArrayLike | None = None,
    names: Sequence[str] | None = None,
    joint_effects: PerturbationFunction | None = None,
    ik: IKOptions | None = None,
    tol: float | None = None,
    tol_angle: float | None = None,
    max_iter: int | None = None,
    restarts: int | None = None,
    seed: int | None = None,
    orientation_weight: float | None = None,
    tool_axis: int | None = None,
    max_joint_change: float = 0.2,
) -> Compensation:
    """Joint commands that bring the calibrated (real) robot onto ``targets``.

    Args:
        calibrated: a :class:`CalibrationResult` (robot, tool, device frame and joint
            effects) or a calibrated :class:`Model`.
        targets: tool positions ``(n, 3)`` or tool frames ``(n, 4, 4)`` (m), in ``frame``.
        nominal_model: what the controller believes (module docstring for the default).
        kind: ``"position"``, ``"pose"``, ``"axis"`` (position and one tool axis, e.g.
            for a 5-axis arm) or ``"auto"`` (position for ``(n, 3)``, pose for frames).
        frame: ``"base"`` (targets in the robot's base frame), ``"measurement"`` (in the
            device/cell frame identified by the calibration, ``result.frame``) or a
            ``(4, 4)`` ``T_frame_base``.
        q0: ``(dof,)`` or ``(n, dof)`` configuration(s) choosing the branch of the
            nominal IK (e.g. the robot's home or current configuration); default: the
            first target's solution from the IK's nearest-pool start, for every target
            (one configuration for all; restarts only for targets not reached from it).
        names: target names (default ``"1"``, ``"2"``, ...).
        joint_effects: override the joint effects ``q (m, dof) -> (m, dof, 3)`` (default:
            ``result.joint_perturbations`` for a result, none for a model).
        ik: the inverse kinematics' settings (:class:`~robocal.compensate.ik_options.IKOptions`:
            tolerances, iterations, restarts and seed of the nominal IK, orientation weight,
            tool axis); default ``IKOptions()``.
        tol, tol_angle, max_iter, restarts, seed, orientation_weight, tool_axis: one field
            of ``ik`` each (None: ``ik``'s): reachability tolerances (m, rad), IK iterations
            per start, random restarts of the nominal IK only (the correction never
            restarts) and their seed, m per rad of orientation rows in the IK objective, the
            tool axis (0, 1, 2) imposed by ``kind="axis"``.
        max_joint_change: a correction moving any joint by more than this (rad or m)
            is reported as a change of configuration (``branch_kept`` false); the
            calibration's own per-target bound (:func:`robocal.compensate.safety.joint_bound`:
            1.5 |e| / σ_min, at most 5°) refuses such a correction.

    Returns:
        :class:`Compensation` with commands, nominal commands and predicted errors.
    """
    setup = compensation_setup(calibrated, nominal_model, joint_effects)
    T, kind_ = as_frames(targets, kind)
    T = to_base(T, frame, setup)
    labels = joint_names(names, len(T))
    options = IKOptions.of(ik, tol=tol, tol_angle=tol_angle, max_iter=max_iter, restarts=restarts, seed=seed,
                           orientation_weight=orientation_weight, tool_axis=tool_axis)  # fmt: skip
    nom, held = nominal_solutions(setup.nominal, T, q0, options, kind_)
    return correct(
        setup, T, kind_, nom.q, nom.reachable, labels, ik=options, max_joint_change=max_joint_change,
        nominal_reasons=held,
    )  # fmt: skip


def program(q: ArrayLike, dof: int, what: str) -> Array:
    qa = np.asarray(q, dtype=float)
    if qa.ndim == 1:
        qa = qa[None]
    if qa.ndim != 2 or qa.shape[1] != dof:
        raise ValueError(f"{what} shaped {np.shape(q)}: expected (n, {dof}) joint values")
    bad = np.flatnonzero(~np.isfinite(qa).all(axis=1))
    if len(bad):
        raise ValueError(f"{what}: row {int(bad[0])} contains NaN or inf")
    return qa


def filter_program(  # noqa: PLR0913 - public keyword options, documented in README and docs
    calibrated: Calibrated,
    q_program: ArrayLike,
    nominal_model: Model | None = None,
    *,
    kind: TargetKind | None = None,
    names: Sequence[str] | None = None,
    joint_effects: PerturbationFunction | None = None,
    ik: IKOptions | None = None,
    tol: float | None = None,
    tol_angle: float | None = None,
    max_iter: int | None = None,
    orientation_weight: float | None = None,
    tool_axis: int | None = None,
    max_joint_change: float = 0.2,
) -> Compensation:
    """Corrected joint targets for a program computed with the nominal model.

    The target of each programmed configuration is where the nominal model puts the
    tool there (``nominal.fk(q_program)``); the correction is the calibrated-model IK
    started from the programmed joints (with the joint effects at the commanded
    configuration, iterated to the fixed point).  A programmed configuration outside the
    model's joint limits is refused naming the joint, its value and the limits (the IK,
    which stays within them, would start elsewhere and find another configuration).

    Args:
        calibrated: :class:`CalibrationResult` or calibrated :class:`Model`.
        q_program: ``(n, dof)`` programmed joint values (rad, m).
        nominal_model: the controller's model (default: see the module docstring).
        kind: what to keep of the nominal tool frame: ``"pose"`` (default for 6 or more
            joints), ``"axis"`` (position and tool axis; default for 5 joints) or
            ``"position"`` (default for fewer).
        Other arguments: as for :func:`compensate_targets` (no nominal IK: its restarts and
            seed are unused).
    """
    options = IKOptions.of(ik, tol=tol, tol_angle=tol_angle, max_iter=max_iter,
                           orientation_weight=orientation_weight, tool_axis=tool_axis)  # fmt: skip
    setup = compensation_setup(calibrated, nominal_model, joint_effects)
    q = program(q_program, setup.real.dof, "q_program")
    kind_ = kind or _default_kind(setup.real.dof)
    if kind_ not in ("position", "pose", "axis"):
        raise ValueError(f"kind must be 'position', 'pose' or 'axis', got {kind_!r}")
    T = setup.nominal.fk(q)
    return correct(
        setup,
        T,
        kind_,
        q,
        np.ones(len(q), dtype=bool),
        joint_names(names, len(q)),
        ik=options,
        max_joint_change=max_joint_change,
        nominal_reasons=safety.outside_limits(setup.real, q),
    )
