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

import csv
import dataclasses
import io
import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from robocal import csvfile, spatial
from robocal.identify.calibrate import CalibrationResult
from robocal.measure.ik import PerturbationFunction, TargetKind, solve_ik
from robocal.measure.paths import joint_path
from robocal.model.chain import Model, Role
from robocal.model.files import atomic_write_text, csv_text, strict_json
from robocal.units import unit_factor

__all__ = [
    "Compensation",
    "PathCompensation",
    "TargetFileError",
    "Targets",
    "compensate_cartesian_path",
    "compensate_path",
    "compensate_targets",
    "filter_program",
    "nominal_model",
    "read_program",
    "read_targets",
]

Array = NDArray[np.float64]
Calibrated = CalibrationResult | Model
Frame = Literal["base", "measurement"]



def _factors(angle_unit: str, length_unit: str) -> tuple[float, float]:
    """rad per ``angle_unit`` and m per ``length_unit`` (:mod:`robocal.units`)."""
    return unit_factor(angle_unit, "angle", "angle_unit"), unit_factor(length_unit, "length", "length_unit")


# ---------------------------------------------------------------------- models
def nominal_model(result: CalibrationResult) -> Model:
    """The model the controller believed before calibration: ``result.model`` with every
    estimated robot and tool parameter at its start value (``result.nominal``) and no
    joint effects."""
    names = set(result.model.names)
    start = {n: float(v) for n, v in zip(result.names, result.nominal, strict=True) if n in names}
    model = result.model.with_values(start)
    changes: dict[str, Any] = {"notes": (model.notes.replace("calibrated", "").strip() + " nominal").strip()}
    if getattr(model, "joint_effects", ()):
        changes["joint_effects"] = ()
    return dataclasses.replace(model, **changes)


def _with_tool(nominal: Model, real: Model) -> Model:
    """``nominal`` with ``real``'s tool steps (``tcp_*``) appended when it has none."""
    tool = [s for s in real.steps if s.role is Role.TOOL]
    if not tool or any(s.role is Role.TOOL for s in nominal.steps):
        return nominal
    clash = {s.name for s in tool} & set(nominal.names)
    if clash:  # pragma: no cover - names with the tool prefix are caught above
        raise ValueError(f"nominal model {nominal.name!r} already uses {sorted(clash)}")
    return dataclasses.replace(nominal, steps=(*nominal.steps, *tool))


@dataclass(frozen=True)
class _Setup:
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


def _setup(
    calibrated: Calibrated, nominal: Model | None, joint_effects: PerturbationFunction | None
) -> _Setup:
    if isinstance(calibrated, CalibrationResult):
        real = calibrated.model
        effects: PerturbationFunction | None = calibrated.joint_perturbations
        frame: Array | None = np.asarray(calibrated.frame, dtype=float)
        nom = nominal_model(calibrated) if nominal is None else nominal
        has_nominal = True
    elif isinstance(calibrated, Model):
        real, frame = calibrated, None
        # a bare calibrated model still carries its learned residual (joint angle errors)
        effects = None if calibrated.residual is None else calibrated.residual.perturbations
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
    return _Setup(real, nom, has_nominal, effects, frame, result)


def _predict(setup: _Setup, q: Array) -> Array:
    """Tool frames ``(n, 4, 4)`` of the real robot (base frame) at commands ``q``."""
    d = None if setup.effects is None else setup.effects(q)
    return setup.real.fk(q, d)


# ---------------------------------------------------------------------- targets
def _as_frames(targets: ArrayLike, kind: TargetKind | Literal["auto"]) -> tuple[Array, TargetKind]:
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


def _to_base(T: Array, frame: Frame | ArrayLike, setup: _Setup) -> Array:
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


def _errors(T: Array, T_target: Array, kind: TargetKind, tool_axis: int) -> tuple[Array, Array]:
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


# ---------------------------------------------------------------------- result
@dataclass(frozen=True)
class Compensation:
    """Corrected joint commands for ``n`` targets.

    Attributes:
        q: ``(n, dof)`` corrected commands (rad, m for prismatic joints).
        q_nominal: ``(n, dof)`` the nominal model's solution (what the controller would
            have commanded; the programmed joints for :func:`filter_program`).
        targets: ``(n, 4, 4)`` target frames in the robot's base frame (m).
        kind: ``"position"``, ``"pose"`` or ``"axis"``: what of the targets is imposed.
        error_before: ``(n,)`` predicted position error (m) of the real robot at
            ``q_nominal`` (NaN when no nominal model was known).
        error_after: ``(n,)`` predicted position error (m) at ``q``.
        angle_before, angle_after: ``(n,)`` orientation errors (rad; zeros for
            position targets).
        reachable: ``(n,)`` the calibrated model reaches the target (``tol``,
            ``tol_angle``) within the joint limits.
        nominal_reachable: ``(n,)`` the nominal model reached it.
        joint_change: ``(n,)`` ``max |q − q_nominal|`` over the joints (rad or m).
        branch_kept: ``(n,)`` ``joint_change <= max_joint_change``: the corrected
            command is in the nominal solution's configuration branch.
        names: ``n`` target names.
        joint_names, joint_types: the robot's joints.
        iterations: ``(n,)`` IK iterations of the correction.
        expected_error_after: ``(n,)`` RMS position error (m) to expect at ``q`` on the real
            robot: the calibration's uncertainty there and the error its model leaves
            unexplained (:meth:`CalibrationResult.expected_position_error`); NaN when only a
            bare model, with no uncertainty, was given.  ``error_after`` is only what the IK
            left against the calibrated model itself (below ``tol`` when reached).
    """

    q: Array
    q_nominal: Array
    targets: Array
    kind: TargetKind
    error_before: Array
    error_after: Array
    angle_before: Array
    angle_after: Array
    reachable: NDArray[np.bool_]
    nominal_reachable: NDArray[np.bool_]
    joint_change: Array
    branch_kept: NDArray[np.bool_]
    names: tuple[str, ...]
    joint_names: tuple[str, ...]
    joint_types: tuple[str, ...]
    iterations: NDArray[np.int64]
    expected_error_after: Array

    @property
    def n(self) -> int:
        return len(self.q)

    @property
    def success(self) -> bool:
        """Every target reached in the nominal configuration branch."""
        return bool(np.all(self.reachable & self.branch_kept))

    @property
    def message(self) -> str:
        bad = np.flatnonzero(~self.reachable)
        moved = np.flatnonzero(self.reachable & ~self.branch_kept)
        parts = [f"{self.n - len(bad)} of {self.n} targets reached"]
        if len(bad):
            parts.append(
                "not reached: " + ", ".join(self.names[i] for i in bad[:8]) + (" ..." if len(bad) > 8 else "")
            )
        if len(moved):
            parts.append("configuration changed: " + ", ".join(self.names[i] for i in moved[:8]))
        return "; ".join(parts)

    def summary(self) -> dict[str, Any]:
        """Counts, and mean and max predicted errors before and after (mm, degrees) over
        the reached targets (an unreachable target's errors say nothing of the
        compensation; they are in the per-target arrays)."""

        def stats(v: Array, f: float) -> dict[str, float | None]:
            v = v[self.reachable & np.isfinite(v)]
            if not len(v):
                return {"mean": None, "max": None}
            return {"mean": float(v.mean() * f), "max": float(v.max() * f)}

        out: dict[str, Any] = {
            "n": self.n,
            "reachable": int(self.reachable.sum()),
            "branch_kept": int(self.branch_kept.sum()),
            "error_before_mm": stats(self.error_before, 1e3),
            "error_after_mm": stats(self.error_after, 1e3),
            "expected_error_after_mm": stats(self.expected_error_after, 1e3),
        }
        if self.kind != "position":
            out["angle_before_deg"] = stats(self.angle_before, 180 / math.pi)
            out["angle_after_deg"] = stats(self.angle_after, 180 / math.pi)
        return out

    def _joint_factor(self, angle_unit: str, length_unit: str) -> Array:
        a, ln = _factors(angle_unit, length_unit)
        return np.array([1 / a if t == "revolute" else 1 / ln for t in self.joint_types])

    def to_dict(self, angle_unit: str = "rad", length_unit: str = "mm") -> dict[str, Any]:
        """Plain data: per-target commands (joints in ``angle_unit``; prismatic joints
        in ``length_unit``) and predicted errors in mm (degrees for orientation)."""
        f = self._joint_factor(angle_unit, length_unit)
        rows = []
        for i, name in enumerate(self.names):
            row: dict[str, Any] = {
                "name": name,
                "q": (self.q[i] * f).tolist(),
                "nominal_q": (self.q_nominal[i] * f).tolist(),
                "predicted_error_before_mm": _num(self.error_before[i] * 1e3),
                "predicted_error_after_mm": _num(self.error_after[i] * 1e3),
                "expected_error_after_mm": _num(self.expected_error_after[i] * 1e3),
                "reachable": bool(self.reachable[i]),
                "branch_kept": bool(self.branch_kept[i]),
            }
            if self.kind != "position":
                row["predicted_angle_error_before_deg"] = _num(math.degrees(self.angle_before[i]))
                row["predicted_angle_error_after_deg"] = _num(math.degrees(self.angle_after[i]))
            rows.append(row)
        return {
            "kind": self.kind,
            "joints": list(self.joint_names),
            "units": {"revolute": angle_unit, "prismatic": length_unit, "errors": "mm, deg"},
            "summary": self.summary(),
            "targets": rows,
        }

    def to_csv(self, angle_unit: str = "rad", length_unit: str = "mm") -> str:
        """CSV text: ``name, q1..qN, nominal_q1..nominal_qN, predicted_error_before_mm,
        predicted_error_after_mm, reachable`` (+ orientation errors in degrees for pose
        and axis targets); joints in ``angle_unit`` (prismatic in ``length_unit``)."""
        f = self._joint_factor(angle_unit, length_unit)
        dof = self.q.shape[1]
        header = ["name", *(f"q{j + 1}" for j in range(dof)), *(f"nominal_q{j + 1}" for j in range(dof))]
        header += ["predicted_error_before_mm", "predicted_error_after_mm", "expected_error_after_mm"]
        header.append("reachable")
        pose = self.kind != "position"
        if pose:
            header += ["predicted_angle_error_before_deg", "predicted_angle_error_after_deg"]
        buf = io.StringIO()
        w = csv.writer(buf, lineterminator="\n")
        w.writerow(header)
        for i, name in enumerate(self.names):
            row = [
                csv_text(name),
                *(_fmt(v) for v in self.q[i] * f),
                *(_fmt(v) for v in self.q_nominal[i] * f),
            ]
            row += [_fmt(self.error_before[i] * 1e3, 6), _fmt(self.error_after[i] * 1e3, 6)]
            row.append(_fmt(self.expected_error_after[i] * 1e3, 6))
            row.append("true" if self.reachable[i] else "false")
            if pose:
                row += [
                    _fmt(math.degrees(self.angle_before[i]), 6),
                    _fmt(math.degrees(self.angle_after[i]), 6),
                ]
            w.writerow(row)
        return buf.getvalue()

    def write(self, path: str | Path, angle_unit: str = "rad", length_unit: str = "mm") -> Path:
        """Write the corrected program to ``path`` atomically: JSON for a ``.json``
        suffix, CSV otherwise (see :meth:`to_csv` and :meth:`to_dict`)."""
        path = Path(path)
        _factors(angle_unit, length_unit)  # a ValueError naming the unit before anything is written
        if path.suffix.lower() == ".json":
            text = strict_json(self.to_dict(angle_unit, length_unit), indent=2) + "\n"
        else:
            text = self.to_csv(angle_unit, length_unit)
        return atomic_write_text(path, text)


def _num(v: float) -> float | None:
    return None if not math.isfinite(v) else float(v)


def _fmt(v: float, digits: int = 12) -> str:
    if not math.isfinite(v):
        return "nan"
    return f"{v:.{digits}g}"


# ---------------------------------------------------------------------- core
def _names(names: Sequence[str] | None, n: int) -> tuple[str, ...]:
    if names is None:
        return tuple(str(i + 1) for i in range(n))
    out = tuple(str(v) for v in names)
    if len(out) != n:
        raise ValueError(f"{len(out)} names for {n} targets")
    return out


def _correct(  # noqa: PLR0913 - the IK settings of compensate_targets, passed through
    setup: _Setup,
    T: Array,
    kind: TargetKind,
    q_nominal: Array,
    nominal_reachable: NDArray[np.bool_],
    names: tuple[str, ...],
    *,
    tol: float,
    tol_angle: float,
    max_iter: int,
    orientation_weight: float,
    tool_axis: int,
    max_joint_change: float,
) -> Compensation:
    """The calibrated-model IK from the nominal solution, and the bookkeeping."""
    res = solve_ik(
        setup.real,
        T,
        kind=kind,
        q0=q_nominal,
        restarts=0,
        tol=tol,
        tol_angle=tol_angle,
        max_iter=max_iter,
        tool_axis=tool_axis,
        orientation_weight=orientation_weight,
        joint_effects=setup.effects,
    )
    before, angle_before = _errors(_predict(setup, q_nominal), T, kind, tool_axis)
    if not setup.has_nominal:
        before, angle_before = np.full(len(T), np.nan), np.full(len(T), np.nan)
    change = np.abs(res.q - q_nominal).max(axis=1) if len(T) else np.zeros(0)
    return Compensation(
        q=res.q,
        q_nominal=q_nominal,
        targets=T,
        kind=kind,
        error_before=before,
        error_after=res.position_error,
        angle_before=angle_before,
        angle_after=res.angle_error,
        reachable=res.reachable,
        nominal_reachable=np.asarray(nominal_reachable, dtype=bool),
        joint_change=change,
        branch_kept=change <= max_joint_change,
        names=names,
        joint_names=setup.real.joint_names,
        joint_types=setup.real.joint_types,
        iterations=res.iterations,
        expected_error_after=setup.expected_error(res.q),
    )


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
    tol: float = 1e-6,
    tol_angle: float = 1e-6,
    max_iter: int = 100,
    restarts: int = 20,
    seed: int = 0,
    orientation_weight: float = 1.0,
    tool_axis: int = 2,
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
            IK's nearest-pool start.
        names: target names (default ``"1"``, ``"2"``, ...).
        joint_effects: override the joint effects ``q (m, dof) -> (m, dof, 3)`` (default:
            ``result.joint_perturbations`` for a result, none for a model).
        tol, tol_angle: reachability tolerances (m, rad).
        max_iter: IK iterations per start.
        restarts: random restarts of the nominal IK only (the correction never restarts).
        seed: seed of those restarts.
        orientation_weight: m per rad of orientation rows in the IK objective.
        tool_axis: tool axis (0, 1, 2) imposed by ``kind="axis"``.
        max_joint_change: a correction moving any joint by more than this (rad or m)
            is reported as a change of configuration (``branch_kept`` false).

    Returns:
        :class:`Compensation` with commands, nominal commands and predicted errors.
    """
    setup = _setup(calibrated, nominal_model, joint_effects)
    T, kind_ = _as_frames(targets, kind)
    T = _to_base(T, frame, setup)
    labels = _names(names, len(T))
    nom = solve_ik(
        setup.nominal,
        T,
        kind=kind_,
        q0=q0,
        restarts=restarts,
        seed=seed,
        tol=tol,
        tol_angle=tol_angle,
        max_iter=max_iter,
        tool_axis=tool_axis,
        orientation_weight=orientation_weight,
    )
    return _correct(
        setup,
        T,
        kind_,
        nom.q,
        nom.reachable,
        labels,
        tol=tol,
        tol_angle=tol_angle,
        max_iter=max_iter,
        orientation_weight=orientation_weight,
        tool_axis=tool_axis,
        max_joint_change=max_joint_change,
    )


def _program(q: ArrayLike, dof: int, what: str) -> Array:
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
    tol: float = 1e-6,
    tol_angle: float = 1e-6,
    max_iter: int = 100,
    orientation_weight: float = 1.0,
    tool_axis: int = 2,
    max_joint_change: float = 0.2,
) -> Compensation:
    """Corrected joint targets for a program computed with the nominal model.

    The target of each programmed configuration is where the nominal model puts the
    tool there (``nominal.fk(q_program)``); the correction is the calibrated-model IK
    started from the programmed joints (with the joint effects at the commanded
    configuration, iterated to the fixed point).

    Args:
        calibrated: :class:`CalibrationResult` or calibrated :class:`Model`.
        q_program: ``(n, dof)`` programmed joint values (rad, m).
        nominal_model: the controller's model (default: see the module docstring).
        kind: what to keep of the nominal tool frame: ``"pose"`` (default for 6 or more
            joints), ``"axis"`` (position and tool axis; default for 5 joints) or
            ``"position"`` (default for fewer).
        Other arguments: as for :func:`compensate_targets`.
    """
    setup = _setup(calibrated, nominal_model, joint_effects)
    q = _program(q_program, setup.real.dof, "q_program")
    kind_ = kind or _default_kind(setup.real.dof)
    if kind_ not in ("position", "pose", "axis"):
        raise ValueError(f"kind must be 'position', 'pose' or 'axis', got {kind_!r}")
    T = setup.nominal.fk(q)
    return _correct(
        setup,
        T,
        kind_,
        q,
        np.ones(len(q), dtype=bool),
        _names(names, len(q)),
        tol=tol,
        tol_angle=tol_angle,
        max_iter=max_iter,
        orientation_weight=orientation_weight,
        tool_axis=tool_axis,
        max_joint_change=max_joint_change,
    )


# ---------------------------------------------------------------------- paths
@dataclass(frozen=True)
class PathCompensation(Compensation):
    """A corrected sampled path (a :class:`Compensation` whose targets are in path order).

    Attributes (besides :class:`Compensation`'s):
        method: ``"ik"`` or ``"jacobian"`` (seed 003 eq. 5.22).
        correction: ``(n, dof)`` ``q − q_nominal``.
        correction_step: ``(n,)`` ``max |correction_i − correction_{i−1}|`` over the
            joints (0 for the first sample): how much the correction changes between
            neighbouring samples.
        jumps: indices ``i`` where ``correction_step`` exceeds ``max_correction_step``:
            the corrected path is not as smooth as the nominal one there.
    """

    method: str = "ik"
    correction: Array = dataclasses.field(default_factory=lambda: np.zeros((0, 0)))
    correction_step: Array = dataclasses.field(default_factory=lambda: np.zeros(0))
    jumps: NDArray[np.intp] = dataclasses.field(default_factory=lambda: np.zeros(0, dtype=np.intp))

    @property
    def smooth(self) -> bool:
        return not len(self.jumps)

    def summary(self) -> dict[str, Any]:
        out = super().summary()
        out |= {
            "method": self.method,
            "max_correction": float(np.abs(self.correction).max()) if self.correction.size else 0.0,
            "max_correction_step": float(self.correction_step.max()) if self.correction_step.size else 0.0,
            "jumps": [int(i) for i in self.jumps],
        }
        return out


def _eq522(
    setup: _Setup,
    q_nominal: Array,
    T: Array,
    kind: TargetKind,
    iterations: int,
    damping: float,
) -> Array:
    """Seed 003 eq. 5.22, batched over samples, ``iterations`` times."""
    if kind not in ("position", "pose"):
        raise ValueError(
            "method='jacobian' (seed 003 eq. 5.22) corrects position or pose targets, not 'axis'"
        )
    rows = 3 if kind == "position" else 6
    q = q_nominal.copy()
    lim = setup.real.joint_limits
    for _ in range(iterations):
        d = None if setup.effects is None else setup.effects(q)
        P = setup.real.fk(q, d)
        e = spatial.pose_error(P, T)[:, :rows]  # P_tilting-geom − P_theor
        J = setup.real.joint_jacobian(q, d)[:, :rows]  # ∂P/∂θ
        dof = J.shape[2]
        if rows <= dof:  # Jᵀ (J Jᵀ)⁻¹ e (minimum-norm step), the seed's form
            A = J @ np.swapaxes(J, 1, 2) + damping * np.eye(rows)
            step = (np.swapaxes(J, 1, 2) @ np.linalg.solve(A, e[:, :, None]))[:, :, 0]
        else:  # more rows than joints: the least-squares step (Jᵀ J)⁻¹ Jᵀ e
            A = np.swapaxes(J, 1, 2) @ J + damping * np.eye(dof)
            step = np.linalg.solve(A, np.einsum("nrd,nr->nd", J, e)[:, :, None])[:, :, 0]
        q = np.clip(q - step, lim[:, 0], lim[:, 1])
    return q


def compensate_path(  # noqa: PLR0913 - public keyword options, documented in README and docs
    calibrated: Calibrated,
    q_path: ArrayLike,
    nominal_model: Model | None = None,
    *,
    method: Literal["ik", "jacobian"] = "ik",
    targets: ArrayLike | None = None,
    kind: TargetKind | None = None,
    frame: Frame | ArrayLike = "base",
    names: Sequence[str] | None = None,
    joint_effects: PerturbationFunction | None = None,
    iterations: int = 1,
    damping: float = 1e-12,
    tol: float = 1e-6,
    tol_angle: float = 1e-6,
    max_iter: int = 100,
    orientation_weight: float = 1.0,
    tool_axis: int = 2,
    max_joint_change: float = 0.2,
    max_correction_step: float = 0.02,
) -> PathCompensation:
    """Correct a sampled joint path programmed with the nominal model.

    Args:
        calibrated: :class:`CalibrationResult` or calibrated :class:`Model`.
        q_path: ``(n, dof)`` nominal joint path (rad, m), in path order.
        nominal_model: the controller's model (module docstring for the default).
        method: ``"ik"``: the calibrated-model IK of every sample, started from its own
            nominal sample (batched); ``"jacobian"``: seed 003 eq. 5.22 (module
            docstring), ``iterations`` steps.
        targets: the desired path ``P_theor``: positions ``(n, 3)`` or frames
            ``(n, 4, 4)`` in ``frame``; default the nominal model's tool frames along
            ``q_path``.
        kind: ``"position"`` (default for fewer than 6 joints, and seed 003's form),
            ``"pose"`` (default for 6 or more) or, for ``"ik"`` only, ``"axis"``.
        iterations: eq. 5.22 steps (1 = the seed's single correction).
        damping: added to ``J Jᵀ`` in eq. 5.22 (m², rad²) against singular samples.
        max_correction_step: a change of the correction between neighbouring samples
            larger than this (rad or m) is reported as a jump.
        Other arguments: as for :func:`compensate_targets`.
    """
    setup = _setup(calibrated, nominal_model, joint_effects)
    q_nom = _program(q_path, setup.real.dof, "q_path")
    kind_ = kind or ("pose" if setup.real.dof >= 6 else "position")
    if targets is None:
        T = setup.nominal.fk(q_nom)
    else:
        T, _ = _as_frames(targets, "auto")
        if len(T) != len(q_nom):
            raise ValueError(f"{len(T)} targets for a path of {len(q_nom)} samples")
        T = _to_base(T, frame, setup)
        if kind_ != "position" and np.asarray(targets).shape[-1:] == (3,):
            kind_ = "position"
    labels = _names(names, len(q_nom))
    opts = {
        "tol": tol,
        "tol_angle": tol_angle,
        "max_iter": max_iter,
        "orientation_weight": orientation_weight,
        "tool_axis": tool_axis,
        "max_joint_change": max_joint_change,
    }
    if method == "ik":
        base = _correct(setup, T, kind_, q_nom, np.ones(len(q_nom), dtype=bool), labels, **opts)
    elif method == "jacobian":
        if iterations < 1:
            raise ValueError(f"iterations must be >= 1, got {iterations}")
        q = _eq522(setup, q_nom, T, kind_, int(iterations), float(damping))
        after, angle_after = _errors(_predict(setup, q), T, kind_, tool_axis)
        before, angle_before = _errors(_predict(setup, q_nom), T, kind_, tool_axis)
        if not setup.has_nominal:
            before, angle_before = np.full(len(T), np.nan), np.full(len(T), np.nan)
        change = np.abs(q - q_nom).max(axis=1)
        base = Compensation(
            q=q,
            q_nominal=q_nom,
            targets=T,
            kind=kind_,
            error_before=before,
            error_after=after,
            angle_before=angle_before,
            angle_after=angle_after,
            reachable=(after < tol) & (angle_after < tol_angle),
            nominal_reachable=np.ones(len(q), dtype=bool),
            joint_change=change,
            branch_kept=change <= max_joint_change,
            names=labels,
            joint_names=setup.real.joint_names,
            joint_types=setup.real.joint_types,
            iterations=np.full(len(q), int(iterations), dtype=np.int64),
            expected_error_after=setup.expected_error(q),
        )
    else:
        raise ValueError(f"method must be 'ik' or 'jacobian', got {method!r}")
    correction = base.q - q_nom
    step = (
        np.r_[0.0, np.abs(np.diff(correction, axis=0)).max(axis=1)]
        if len(q_nom) > 1
        else np.zeros(len(q_nom))
    )
    fields = {f.name: getattr(base, f.name) for f in dataclasses.fields(Compensation)}
    return PathCompensation(
        **fields,
        method=method,
        correction=correction,
        correction_step=step,
        jumps=np.flatnonzero(step > max_correction_step),
    )


def compensate_cartesian_path(
    calibrated: Calibrated,
    targets: ArrayLike,
    nominal_model: Model | None = None,
    *,
    method: Literal["ik", "jacobian"] = "ik",
    kind: TargetKind | None = None,
    frame: Frame | ArrayLike = "base",
    q0: ArrayLike | None = None,
    **options: Any,
) -> PathCompensation:
    """Correct a sampled Cartesian path: the nominal joint path first
    (:func:`robocal.measure.paths.joint_path`, warm-started from sample to sample from
    ``q0``, so one configuration branch), then :func:`compensate_path`.

    Args:
        targets: ``(n, 3)`` positions or ``(n, 4, 4)`` frames (m) in ``frame``, in path
            order.
        kind: default position for positions, pose for frames.
        q0: ``(dof,)`` configuration choosing the branch at the first sample.
        options: passed to :func:`compensate_path`.
    """
    setup = _setup(calibrated, nominal_model, options.get("joint_effects"))
    T, kind_ = _as_frames(targets, "auto" if kind is None else kind)
    T = _to_base(T, frame, setup)
    nominal = joint_path(setup.nominal, T, kind=kind_, q0=q0, tool_axis=options.get("tool_axis", 2))
    targets_base = T[:, :3, 3] if kind_ == "position" else T
    return compensate_path(
        calibrated,
        nominal.q,
        nominal_model,
        method=method,
        targets=targets_base,
        kind=kind_,
        frame="base",
        **options,
    )


# ---------------------------------------------------------------------- files
class TargetFileError(ValueError):
    """A targets/program file that cannot be used; the message names file, row and column."""


@dataclass(frozen=True)
class Targets:
    """Targets read from a file: ``names`` and ``(n, 3)`` positions or ``(n, 4, 4)``
    frames (m) in the file's frame; ``kind`` ``"position"`` or ``"pose"``."""

    names: tuple[str, ...]
    values: Array
    kind: TargetKind


def _read_head(path: Path, sep: str | None, decimal: str) -> csvfile.Head:
    """The header of a targets file (:mod:`robocal.csvfile`: ``#`` lines and blank lines
    are skipped, the separator is sniffed among ``, ; tab``)."""
    try:
        head = csvfile.read_head(path, sep=sep, decimal=decimal, candidates=(",", ";", "\t"), spaces=False)
    except OSError as err:
        raise TargetFileError(f"{path}: cannot read: {err.strerror or err}") from None
    except csvfile.CsvError as err:
        what = "no header line" if err.message.startswith("no header row") else err.message
        raise TargetFileError(f"{path}: {what}") from None
    if decimal == "," and head.sep == ",":
        raise TargetFileError(f"{path}: decimal comma needs another separator (--sep ';')")
    return head


def _read_columns(
    head: csvfile.Head, header: list[str], cols: list[str], decimal: str
) -> tuple[Array, tuple[str, ...], list[int]]:
    """``(n, len(cols))`` numbers of columns ``cols``, the row names (the ``name`` column,
    else the line number) and the line numbers, chunk by chunk; the first bad row or cell
    is an error naming it."""
    path, idx = head.path, [header.index(c) for c in cols]
    name_k = header.index("name") if "name" in header else None
    blocks: list[Array] = []
    names: list[str] = []
    lines: list[int] = []
    for chunk in csvfile.iter_chunks(head):
        for i, code, message in chunk.problems[:1]:
            width = len(chunk.rows[i])
            what = message if code != "ragged" else f"{width} fields, the header has {len(header)}"
            raise TargetFileError(f"{path}, row {chunk.line[i]}: {what}")
        block = np.empty((len(chunk), len(cols)))
        for c, (col, k) in enumerate(zip(cols, idx, strict=True)):
            block[:, c], problems = csvfile.to_numbers([r[k] for r in chunk.rows], decimal)
            for m, code, _ in problems[:1]:
                text = chunk.rows[m][k].strip()
                what = "is not finite" if code == "not-finite" else "is not a number"
                raise TargetFileError(f"{path}, row {chunk.line[m]}, column {col!r}: {text!r} {what}")
        blocks.append(block)
        lines += chunk.line.tolist()
        if name_k is not None:
            rows_lines = zip(chunk.rows, chunk.line.tolist(), strict=True)
            names += [r[name_k].strip() or str(no) for r, no in rows_lines]
    values = np.concatenate(blocks) if blocks else np.zeros((0, len(cols)))
    if name_k is None:
        names = [str(k + 1) for k in range(len(values))]
    return values, tuple(names), lines


def read_targets(
    path: str | Path, *, length_unit: str = "m", sep: str | None = None, decimal: str = "."
) -> Targets:
    """Targets from a CSV file with columns ``name,x,y,z`` and optionally
    ``qw,qx,qy,qz`` (tool orientation, scalar first; normalised).

    Args:
        path: the file; ``#`` lines are comments.
        length_unit: ``m``, ``mm`` or ``um`` for ``x, y, z``.
        sep: column separator (default: sniffed among ``, ; tab``).
        decimal: decimal mark, ``"."`` or ``","``.

    Raises:
        TargetFileError: naming the file, the row (line number) and the column.
    """
    path = Path(path)
    try:
        length = unit_factor(length_unit, "length", "length_unit")
    except ValueError as err:
        raise TargetFileError(f"{path}: {err}") from None
    head = _read_head(path, sep, decimal)
    header = [h.lower() for h in head.header]
    missing = [c for c in ("x", "y", "z") if c not in header]
    if missing:
        raise TargetFileError(f"{path}: missing column(s) {', '.join(missing)} (header: {', '.join(header)})")
    quat_cols = ["qw", "qx", "qy", "qz"]
    has_q = [c in header for c in quat_cols]
    values, names, lines = _read_columns(head, header, ["x", "y", "z"] + quat_cols * all(has_q), decimal)
    if not len(values):
        raise TargetFileError(f"{path}: no targets")
    if any(has_q) and not all(has_q):
        absent = ", ".join(c for c in quat_cols if c not in header)
        raise TargetFileError(f"{path}: orientation needs all of qw, qx, qy, qz; missing {absent}")
    p = values[:, :3] * length
    if not all(has_q):
        return Targets(names, p, "position")
    quat = values[:, 3:]
    norm = np.linalg.norm(quat, axis=1)
    bad = np.flatnonzero(norm < 1e-9)
    if len(bad):
        raise TargetFileError(f"{path}, row {lines[int(bad[0])]}, columns qw..qz: the quaternion is zero")
    T = spatial.homogeneous(spatial.quaternion_to_matrix(quat / norm[:, None]), p)
    return Targets(names, T, "pose")


def read_program(
    path: str | Path,
    dof: int,
    *,
    angle_unit: str = "rad",
    length_unit: str = "m",
    joint_types: Sequence[str] | None = None,
    sep: str | None = None,
    decimal: str = ".",
) -> tuple[tuple[str, ...], Array]:
    """A joint program from a CSV file with columns ``q1..qN`` (and optionally ``name``).

    Revolute joints in ``angle_unit``, prismatic ones (``joint_types``) in
    ``length_unit``.  Returns the names and ``(n, dof)`` joint values (rad, m).
    """
    path = Path(path)
    try:
        angle, length = _factors(angle_unit, length_unit)
    except ValueError as err:
        raise TargetFileError(f"{path}: {err}") from None
    head = _read_head(path, sep, decimal)
    header = [h.lower() for h in head.header]
    cols = [f"q{j + 1}" for j in range(dof)]
    missing = [c for c in cols if c not in header]
    if missing:
        raise TargetFileError(f"{path}: missing joint column(s) {', '.join(missing)} for a {dof}-joint robot")
    extra = [h for h in header if h.startswith("q") and h[1:].isdigit() and int(h[1:]) > dof]
    if extra:
        raise TargetFileError(f"{path}: joint column(s) {', '.join(extra)} but the robot has {dof} joints")
    q, names, _ = _read_columns(head, header, cols, decimal)
    if not len(q):
        raise TargetFileError(f"{path}: no rows")
    types = list(joint_types) if joint_types is not None else ["revolute"] * dof
    f = np.array([angle if t == "revolute" else length for t in types])
    return names, q * f
