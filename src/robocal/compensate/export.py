"""The calibrated robot leaves robocal: a calibrated URDF and UR kinematics from a
calibration, with what they cannot carry stated and measured.

* :func:`export_urdf` — :func:`robocal.model.urdf_export.calibrated_urdf` for a
  :class:`~robocal.identify.calibrate.CalibrationResult` (or a model): the nominal
  model (the calibration's start values) places the links on their joints, the device
  frame ``T_device_base`` and the measured tool may be added as a fixed joint pair,
  and the XML comment states what a URDF cannot hold with its size at sample
  configurations (:func:`left_out`).
* :func:`export_ur_kinematics` — the UR description's ``default_kinematics.yaml``
  (:mod:`robocal.model.ur_kinematics`).

What a URDF cannot carry: joint effects (compliance, clearance, backlash: the joint
perturbations ``(δα, δβ, δθ)`` depend on the configuration and the load) and a learned
residual.  :func:`left_out` measures them as the largest and RMS displacement (mm) of
the tool point they cause over random configurations within the joint limits.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray

from robocal.identify.calibrate import CalibrationResult
from robocal.model.chain import Model
from robocal.model.files import atomic_write_text
from robocal.model.ur_kinematics import URKinematics, ur_kinematics
from robocal.model.urdf_export import URDFExport, calibrated_urdf

__all__ = ["LeftOut", "export_ur_kinematics", "export_urdf", "left_out"]

Array = NDArray[np.float64]


@dataclass(frozen=True)
class LeftOut:
    """A part of the calibrated robot an export cannot hold, and its size.

    Attributes:
        what: e.g. ``"joint effects (compliance, clearance)"``.
        max_mm, rms_mm: largest and RMS displacement of the tool point (mm) it causes
            over ``n`` random configurations (NaN when it cannot be evaluated).
        max_deg: largest tool rotation (degrees) it causes.
        n: configurations sampled.
    """

    what: str
    max_mm: float
    rms_mm: float
    max_deg: float
    n: int

    @property
    def note(self) -> str:
        if not math.isfinite(self.max_mm):
            return f"not carried: {self.what} (size unknown)"
        return (
            f"not carried: {self.what}; it contributes up to {self.max_mm:.3f} mm "
            f"(RMS {self.rms_mm:.3f} mm, up to {self.max_deg:.4f} deg) at {self.n} random configurations"
        )


def left_out(calibrated: CalibrationResult | Model, n: int = 200, seed: int = 0) -> tuple[LeftOut, ...]:
    """What a kinematic export leaves out of ``calibrated``, measured at ``n`` random
    configurations within the joint limits (seeded)."""
    from robocal.measure.ik import random_configurations

    model = calibrated.model if isinstance(calibrated, CalibrationResult) else calibrated
    out: list[LeftOut] = []
    q = random_configurations(model, n, np.random.default_rng(seed))
    d = None
    if isinstance(calibrated, CalibrationResult):
        d = calibrated.physical_perturbations(q)
    elif model.joint_effects and model.bodies:
        from robocal.model.joints import joint_perturbations

        d = joint_perturbations(model, q)
    if d is not None:
        kinds = sorted({k for e in model.joint_effects for k in _effect_kinds(e)}) or ["compliance"]
        out.append(_size(f"joint effects ({', '.join(kinds)}; pose- and load-dependent)", model, q, d))
    if model.residual is not None:
        learned = model.residual.perturbations(q, model.dof)
        d_all = learned if d is None else d + learned
        learned_model = model.residual
        what = (
            f"the learned residual (angle errors of {len(learned_model.joints)} joints, "
            f"{learned_model.harmonics} harmonics)"
        )
        out.append(_size(what, model, q, d_all, d))
    return tuple(out)


def _size(
    what: str, model: Model, q: np.ndarray, d: np.ndarray, without: np.ndarray | None = None
) -> LeftOut:
    """How far the perturbations ``d`` move the tool from where ``without`` (default none)
    puts it, at the configurations ``q``."""
    T0, T1 = model.fk(q, without), model.fk(q, d)
    dist = np.linalg.norm(T1[:, :3, 3] - T0[:, :3, 3], axis=1) * 1e3
    R = np.einsum("nij,nkj->nik", T1[:, :3, :3], T0[:, :3, :3])
    angle = np.degrees(np.arccos(np.clip((np.trace(R, axis1=1, axis2=2) - 1) / 2, -1, 1)))
    return LeftOut(what, float(dist.max()), float(np.sqrt(np.mean(dist**2))), float(angle.max()), len(q))


def _effect_kinds(effects) -> list[str]:
    names = []
    for attr, label in (
        ("compliance", "compliance"),
        ("radial_compliance", "radial compliance"),
        ("clearance_tilt", "clearance"),
        ("backlash", "backlash"),
    ):
        v = getattr(effects, attr, None)
        if v:
            names.append(label)
    return names


def export_urdf(
    calibrated: CalibrationResult | Model,
    source: str | Path | None = None,
    *,
    nominal: Model | None = None,
    tip: str | None = None,
    device_link: str | None = None,
    tool_link: str | None = None,
    samples: int = 200,
) -> tuple[URDFExport, tuple[LeftOut, ...]]:
    """A calibrated URDF (see :func:`robocal.model.urdf_export.calibrated_urdf`) and what
    it leaves out.

    Args:
        calibrated: a calibration result (model, device frame, joint effects) or a model.
        source: the URDF the model was built from, or ``None`` for a kinematic URDF.
        nominal: the model before calibration (default: the result's start values).
        device_link, tool_link: names of the optional new links at the device frame
            (the new root) and at the measured tool.
        samples: configurations for sizing what is left out.
    """
    from robocal.compensate.compensation import nominal_model

    if isinstance(calibrated, CalibrationResult):
        model = calibrated.model
        frame: Array | None = np.asarray(calibrated.frame, dtype=float)
        nominal = nominal_model(calibrated) if nominal is None else nominal
    else:
        model, frame = calibrated, None
        if device_link is not None:
            raise ValueError("a device link needs a calibration result (its device frame)")
    missing = left_out(calibrated, samples)
    notes = [m.note for m in missing]
    if device_link is None and frame is not None:
        notes.append("the measuring device's frame is not in this file (device link not requested)")
    ex = calibrated_urdf(
        model,
        source,
        nominal=nominal,
        tip=tip,
        T_device_base=frame,
        device_link=device_link,
        tool_link=tool_link,
        notes=notes,
    )
    return ex, missing


def export_ur_kinematics(
    calibrated: CalibrationResult | Model,
    path: str | Path | None = None,
    *,
    T_base_urbase: ArrayLike | None = None,
    hash: str = "robocal_calibration",
) -> URKinematics:
    """The calibrated UR kinematics; written atomically to ``path`` when given."""
    model = calibrated.model if isinstance(calibrated, CalibrationResult) else calibrated
    kin = ur_kinematics(model, T_base_urbase, hash)
    if path is not None:
        atomic_write_text(Path(path), kin.to_yaml())
    return kin
