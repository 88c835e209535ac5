"""The calibrated robot leaves robocal: a calibrated URDF and UR kinematics from a
calibration, with what they cannot carry stated and measured.

* :func:`export_urdf` — :func:`robocal.model.urdf.export.calibrated_urdf` for a
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

from robocal.identify.result import CalibrationResult
from robocal.model.chain import Model
from robocal.model.ur_kinematics import URKinematics, ur_kinematics
from robocal.model.urdf.export import URDFExport, calibrated_urdf
from robocal.outdir import atomic_write_text

__all__ = [
    "KinematicPart",
    "LeftOut",
    "check_exportable",
    "check_result_files",
    "export_ur_kinematics",
    "export_urdf",
    "kinematic_part",
    "left_out",
]

Array = NDArray[np.float64]
#: A device frame or model length beyond this (m) is not a robot cell's: a hand-edited
#: or corrupted file, refused before anything is written.
MAX_LENGTH_M = 1e3


@dataclass(frozen=True)
class KinematicPart:
    """What a kinematic export (URDF, UR kinematics) carries of a calibration.

    Attributes:
        calibrated: a result or model without a learned residual: the calibration itself,
            or — for a hybrid calibration (physics + learned residual) — the best
            physics-only calibration of the same poses stored with it.
        notes: what was chosen and why, with both CV errors (mm).
    """

    calibrated: CalibrationResult | Model
    notes: tuple[str, ...] = ()


def kinematic_part(calibrated: CalibrationResult | Model) -> KinematicPart:
    """The part of ``calibrated`` a URDF or a UR kinematics file can hold.

    A learned residual cannot be written into either; the hybrid's physical part alone is
    not a calibration (it was fitted with the residual beside it, and predicts worse than a
    physics-only fit), so a hybrid result gives the physics-only calibration stored in its
    ``result.json`` (``physics_only``) with both cross-validated errors stated.

    Raises:
        ValueError: a model or result with a learned residual and no physics-only calibration.
    """
    model = calibrated.model if isinstance(calibrated, CalibrationResult) else calibrated
    if model.residual is None:
        return KinematicPart(calibrated)
    record = calibrated.records.get("physics_only") if isinstance(calibrated, CalibrationResult) else None
    if not isinstance(record, dict):
        raise ValueError(
            f"model {model.name!r} has a learned residual, which a URDF or UR kinematics file cannot hold, "
            "and no physics-only calibration stored with it (its physical part alone was fitted beside "
            "the residual): calibrate again (robocal stores one) or with --residual none"
        )
    assert isinstance(calibrated, CalibrationResult)
    return KinematicPart(_physics_only(calibrated, record), (_physics_only_note(calibrated, record),))


def _physics_only(result: CalibrationResult, record: dict) -> CalibrationResult:
    """The stored physics-only calibration as a result (model, device frame, compliance)."""
    from robocal.model.files import model_from_dict
    from robocal.model.yaml_files import ModelFileError

    where = "result.json: physics_only"
    try:
        model = model_from_dict(record.get("model"), origin=f"{where}.model")
        frame = np.array(record["T_device_base"], dtype=float).reshape(4, 4)
        compliance = {str(k): float(v) for k, v in dict(record.get("compliance") or {}).items()}
    except (KeyError, TypeError, ValueError, ModelFileError) as err:
        raise ValueError(f"{where}: not a physics-only calibration written by robocal ({err})") from None
    if model.joint_names != result.model.joint_names or model.residual is not None:
        raise ValueError(f"{where}: its model is not the calibration's robot without a residual")
    _check_frame(frame, f"{where}.T_device_base")
    _check_values(model, f"{where}.model")
    return result.replace(
        model=model, T_device_base=frame, compliance=compliance, residual_cross_covariance=None
    )


def _physics_only_note(result: CalibrationResult, record: dict) -> str:
    def mm(key: str) -> str:
        v = record.get(key)
        return f"{float(v):.4f} mm" if isinstance(v, int | float) else "not cross-validated"

    held_out = ""
    if result.validation is not None and "mean_mm" in result.validation:
        v = result.validation
        held_out = f", {float(v['mean_mm']):.4f} mm mean on {v.get('n')} held-out poses"
    physics = f"CV mean error {mm('cv_mean_mm')}"
    if isinstance(record.get("held_out_mean_mm"), int | float):
        n = record.get("held_out_n")
        physics += f", {float(record['held_out_mean_mm']):.4f} mm mean on {n} held-out poses"
    return (
        f"kinematics of the best physics-only calibration of the same poses ({record.get('candidate')}: "
        f"{physics}); the calibration's hybrid ({record.get('hybrid')}: CV mean "
        f"error {mm('hybrid_cv_mean_mm')}{held_out}) has a learned residual this file cannot hold: "
        "compensate and filter use the hybrid"
    )


def check_exportable(calibrated: CalibrationResult | Model, where: str = "") -> None:
    """Refuse (ValueError naming ``where``) a calibration whose numbers cannot be a robot:
    non-finite or implausibly large model values (beyond :data:`MAX_LENGTH_M`), or a device
    frame that is not a finite rigid transform within that distance."""
    model = calibrated.model if isinstance(calibrated, CalibrationResult) else calibrated
    _check_values(model, f"{where}model {model.name!r}")
    if isinstance(calibrated, CalibrationResult):
        _check_frame(np.asarray(calibrated.T_device_base, dtype=float), f"{where}result.json: T_device_base")


def check_result_files(directory: str | Path, result: CalibrationResult) -> None:
    """Refuse (ValueError naming the file) a calibration folder whose ``model.yaml`` is not
    the one the calibration wrote: its SHA-256 differs from ``result.json``'s
    ``model_sha256``, or — in a folder written before the digest — a parameter of
    ``result.json`` has another value in the model (relative 1e-9)."""
    from robocal.identify.result_io import file_hash

    path = Path(directory) / "model.yaml"
    digest = result.records.get("model_sha256")
    if isinstance(digest, str):
        if file_hash(path) != digest:
            raise ValueError(
                f"{path}: changed since the calibration wrote it (its SHA-256 is not result.json's "
                "model_sha256): calibrate again, or export a model file of your own"
            )
        return
    values = dict(zip(result.model.names, result.model.values, strict=True))
    for name, estimate in zip(result.names, result.estimates, strict=True):
        v = values.get(name)
        if v is not None and not abs(v - estimate) <= 1e-9 * max(1.0, abs(estimate)):
            raise ValueError(
                f"{path}: parameter {name} is {v!r}, result.json says {float(estimate)!r}: the model "
                "does not belong to this result; calibrate again"
            )


def _check_values(model: Model, where: str) -> None:
    for s in model.steps:
        limit = math.inf if s.is_rotation else MAX_LENGTH_M
        if not math.isfinite(s.value) or abs(s.value) > limit:
            raise ValueError(f"{where}: parameter {s.name} = {s.value!r} is not a plausible value")


def _check_frame(T: Array, where: str) -> None:
    if T.shape != (4, 4) or not np.all(np.isfinite(T)):
        raise ValueError(f"{where}: not a finite 4x4 transform")
    R = T[:3, :3]
    rigid = np.abs(R.T @ R - np.eye(3)).max() < 1e-6 and np.abs(T[3] - (0, 0, 0, 1)).max() == 0
    if not rigid or np.linalg.det(R) < 0:
        raise ValueError(f"{where}: not a rigid transform (rotation not orthonormal)")
    distance = float(np.abs(T[:3, 3]).max())  # not the norm: 1e308 would overflow it
    if distance > MAX_LENGTH_M:
        raise ValueError(
            f"{where}: the device is {distance:.4g} m from the robot base along an axis (more than "
            f"{MAX_LENGTH_M:g} m): not a plausible device frame"
        )


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
    from robocal.measure.ik_starts import random_configurations

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
    joint_map: dict[str, str] | None = None,
    notes: tuple[str, ...] = (),
) -> tuple[URDFExport, tuple[LeftOut, ...]]:
    """A calibrated URDF (see :func:`robocal.model.urdf.export.calibrated_urdf`) and what
    it leaves out.

    Args:
        calibrated: a calibration result (model, device frame, joint effects) or a model.
        source: the URDF the model was built from, or ``None`` for a kinematic URDF.
        nominal: the model before calibration (default: the result's start values).
        device_link, tool_link: names of the optional new links at the device frame
            (the new root) and at the measured tool.
        samples: configurations for sizing what is left out.
        joint_map: model joint -> source URDF joint, where the names differ (default: by
            name, else by chain order; checked and stated).
        notes: more to state in the file's comment (e.g. a constraint calibration's
            nominal base frame).

    A hybrid calibration exports its best physics-only calibration (:func:`kinematic_part`).
    """
    from robocal.compensate.compensation import nominal_model

    part = kinematic_part(calibrated)
    calibrated = part.calibrated
    check_exportable(calibrated)
    if isinstance(calibrated, CalibrationResult):
        model = calibrated.model
        frame: Array | None = np.asarray(calibrated.frame, dtype=float)
        nominal = nominal_model(calibrated) if nominal is None else nominal
    else:
        model, frame = calibrated, None
        if device_link is not None:
            raise ValueError("a device link needs a calibration result (its device frame)")
    missing = left_out(calibrated, samples)
    stated = [*part.notes, *notes, *(m.note for m in missing)]
    if device_link is None and frame is not None:
        stated.append("the measuring device's frame is not in this file (device link not requested)")
    ex = calibrated_urdf(
        model,
        source,
        nominal=nominal,
        tip=tip,
        T_device_base=frame,
        device_link=device_link,
        tool_link=tool_link,
        notes=stated,
        joint_map=joint_map,
    )
    return ex, missing


def export_ur_kinematics(
    calibrated: CalibrationResult | Model,
    path: str | Path | None = None,
    *,
    T_base_urbase: ArrayLike | None = None,
    hash: str = "robocal_calibration",
) -> URKinematics:
    """The calibrated UR kinematics (of :func:`kinematic_part`: a hybrid calibration's
    best physics-only calibration); written atomically to ``path`` when given."""
    calibrated = kinematic_part(calibrated).calibrated
    check_exportable(calibrated)
    model = calibrated.model if isinstance(calibrated, CalibrationResult) else calibrated
    kin = ur_kinematics(model, T_base_urbase, hash)
    if path is not None:
        atomic_write_text(Path(path), kin.to_yaml())
    return kin
