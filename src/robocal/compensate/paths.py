"""Compensation of sampled paths: every sample by inverse kinematics of the calibrated
model or by seed 003 eq. 5.22 (the Jacobian correction), with the smoothness of the
correction checked (:class:`PathCompensation`)."""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from robocal import spatial
from robocal.compensate import safety
from robocal.compensate.compensation import (
    Setup,
    as_frames,
    compensation_setup,
    correct,
    errors,
    joint_names,
    predict,
    program,
    to_base,
)
from robocal.compensate.ik_options import IKOptions
from robocal.compensate.result import Compensation
from robocal.identify.result import CalibrationResult
from robocal.measure.ik import IKResult, PerturbationFunction
from robocal.measure.ik_starts import TargetKind
from robocal.measure.paths import joint_path
from robocal.model.chain import Model

__all__ = ["PathCompensation", "compensate_cartesian_path", "compensate_path"]

Array = NDArray[np.float64]
Calibrated = CalibrationResult | Model
Frame = Literal["base", "measurement"]


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
    setup: Setup,
    q_nominal: Array,
    T: Array,
    kind: TargetKind,
    iterations: int,
    damping: float,
) -> Array:
    """Seed 003 eq. 5.22, batched over samples, ``iterations`` times."""
    if kind not in ("position", "pose"):
        raise ValueError(
            "method='jacobian' (the Katana thesis' eq. 5.22) corrects position or pose targets, not 'axis'"
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


def _path_targets(
    setup: Setup, q_nom: Array, targets: ArrayLike | None, kind: TargetKind | None, frame: Frame | ArrayLike
) -> tuple[Array, TargetKind]:
    """The path's target frames ``(n, 4, 4)`` in the base frame (default: the nominal
    model's along ``q_nom``) and what of them is imposed."""
    kind_: TargetKind = kind or ("pose" if setup.real.dof >= 6 else "position")
    if targets is None:
        return setup.nominal.fk(q_nom), kind_
    T, _ = as_frames(targets, "auto")
    if len(T) != len(q_nom):
        raise ValueError(f"{len(T)} targets for a path of {len(q_nom)} samples")
    if kind_ != "position" and np.asarray(targets).shape[-1:] == (3,):
        kind_ = "position"
    return to_base(T, frame, setup), kind_


def _jacobian_solved(setup: Setup, q: Array, q_nom: Array, T: Array, kind: TargetKind, iterations: int):
    """Eq. 5.22's commands ``q`` as an :class:`IKResult` for the invariants of
    :mod:`robocal.compensate.safety`: a sample counts as solved when the step did not make
    its error worse (one step leaves a second-order residual by design)."""
    after, angle_after = errors(predict(setup, q), T, kind, 2)
    before, angle_before = errors(predict(setup, q_nom), T, kind, 2)
    ok = np.isfinite(after) & (np.hypot(after, angle_after) <= np.hypot(before, angle_before) + 1e-12)
    n = len(q)
    return IKResult(
        q, after, angle_after, ok, np.full(n, iterations, dtype=np.int64), np.ones(n, np.int64), kind
    )


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
    ik: IKOptions | None = None,
    tol: float | None = None,
    tol_angle: float | None = None,
    max_iter: int | None = None,
    orientation_weight: float | None = None,
    tool_axis: int | None = None,
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
    options = IKOptions.of(ik, tol=tol, tol_angle=tol_angle, max_iter=max_iter,
                           orientation_weight=orientation_weight, tool_axis=tool_axis)  # fmt: skip
    setup = compensation_setup(calibrated, nominal_model, joint_effects)
    q_nom = program(q_path, setup.real.dof, "q_path")
    T, kind_ = _path_targets(setup, q_nom, targets, kind, frame)
    labels = joint_names(names, len(q_nom))
    outside = safety.outside_limits(setup.real, q_nom)  # refused by name, as filter_program's
    if method == "ik":
        base = correct(
            setup, T, kind_, q_nom, np.ones(len(q_nom), dtype=bool), labels, ik=options,
            max_joint_change=max_joint_change, nominal_reasons=outside,
        )  # fmt: skip
    elif method == "jacobian":
        if iterations < 1:
            raise ValueError(f"iterations must be >= 1, got {iterations}")
        q = _eq522(setup, q_nom, T, kind_, int(iterations), float(damping))
        solved = _jacobian_solved(setup, q, q_nom, T, kind_, int(iterations))
        base = correct(
            setup, T, kind_, q_nom, np.ones(len(q_nom), dtype=bool), labels, ik=options,
            max_joint_change=max_joint_change, solved=solved, nominal_reasons=outside,
        )  # fmt: skip
        after, angle_after = base.error_after, base.angle_after  # reachable: within tol, as for "ik"
        base = dataclasses.replace(base, reachable=(after < options.tol) & (angle_after < options.tol_angle))
    else:
        raise ValueError(f"method must be 'ik' or 'jacobian', got {method!r}")
    correction = base.q - q_nom
    step = np.r_[0.0, np.abs(np.diff(correction, axis=0)).max(axis=1, initial=0.0)][: len(q_nom)]
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
    setup = compensation_setup(calibrated, nominal_model, options.get("joint_effects"))
    T, kind_ = as_frames(targets, "auto" if kind is None else kind)
    T = to_base(T, frame, setup)
    tool_axis = IKOptions.of(options.get("ik"), tool_axis=options.get("tool_axis")).tool_axis
    nominal = joint_path(setup.nominal, T, kind=kind_, q0=q0, tool_axis=tool_axis)
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
