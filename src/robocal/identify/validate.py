"""Held-out validation: how far a (calibrated) model misses real measurements.

``rc.validate(result_or_model, data)`` predicts the measured positions (and
orientations) of ``data`` and reports mean, RMS, max and 95th percentile of the
position error, per axis, and the orientation error where measured.

Which device frame: data from the calibration's own set-up uses the frame identified
by the calibration as it is (pass the :class:`CalibrationResult`, or ``frame=``); data
from another placement of the device may refit the frame only (``refit_frame=True``).
A frame fitted to the rows it is then scored on looks better than it is (it spent six
degrees of freedom on them), so a calibration's refitted frame is scored honestly: each row
with the frame fitted on the other rows (K-fold, K = min(5, n),
:mod:`robocal.identify.register`), its expected error including that frame's own
uncertainty; the in-sample fit comes with it (``in_sample``), labelled so.  A bare model
without a frame is validated with a rigid Kabsch/Horn fit on all rows (in-sample).  The
result says which was done (``frame``, ``scoring``).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from robocal import spatial
from robocal.identify.calibrate import calibrate
from robocal.identify.result import CalibrationResult
from robocal.measure.measurements import Measurements
from robocal.model.chain import Model
from robocal.model.residual import one_blas_thread

__all__ = ["ValidationStats", "cross_validate", "mean_position_variance", "validate", "validation_statistics"]

Array = NDArray[np.float64]


@dataclass(frozen=True)
class ValidationStats:
    """Position (and orientation) errors of a model on measured poses (SI units)."""

    n: int
    mean: float
    rms: float
    max: float
    p95: float
    axis_mean_abs: tuple[float, float, float]
    axis_rms: tuple[float, float, float]
    frame: str  # "calibrated", "given", "refit" or "identity"
    errors: Array = field(repr=False)  # (n,) position error per pose, m
    error_vectors: Array = field(repr=False)  # (n, 3) predicted - measured, device frame
    orientation_mean: float | None = None  # rad
    orientation_max: float | None = None
    # what the calibration expected (a CalibrationResult validated): RMS position error (m)
    # from its parameter uncertainty alone, and with the measurement scatter added
    parameter_rms: float | None = None
    expected_rms: float | None = None
    # where the rest came from: "sigma" (the data's noise), "sigma+unmodelled" (and the error
    # the calibration's residuals showed beyond its noise), "residuals" (their scatter) or
    # "residual model" (what the learned residual's evidence left unexplained), "registration"
    # (the calibration's predicted error and the refitted frame's uncertainty)
    scatter: str | None = None
    # how a refitted frame was scored: "5-fold" (each row by a frame fitted without it) or
    # "in-sample" (fitted and scored on the same rows); None for a frame used as it is
    scoring: str | None = None
    in_sample: ValidationStats | None = field(default=None, repr=False)

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {
            "n": self.n,
            "mean_mm": self.mean * 1e3,
            "rms_mm": self.rms * 1e3,
            "max_mm": self.max * 1e3,
            "p95_mm": self.p95 * 1e3,
            "axis_mean_abs_mm": [v * 1e3 for v in self.axis_mean_abs],
            "axis_rms_mm": [v * 1e3 for v in self.axis_rms],
            "frame": self.frame,
        }
        if self.orientation_mean is not None and self.orientation_max is not None:
            out["orientation_mean_deg"] = float(np.degrees(self.orientation_mean))
            out["orientation_max_deg"] = float(np.degrees(self.orientation_max))
        if self.expected_rms is not None and self.parameter_rms is not None:
            out["expected_rms_mm"] = self.expected_rms * 1e3
            out["parameter_rms_mm"] = self.parameter_rms * 1e3
        if self.scoring is not None:
            out["scoring"] = self.scoring
        if self.in_sample is not None:
            out["in_sample"] = self.in_sample.to_dict()
        return out

    @property
    def worse_than_expected(self) -> bool:
        """The RMS error is well above what the calibration expected (more than 1.5x): a
        robot or device that changed, or errors the model does not represent that the
        calibration's poses did not show."""
        return self.expected_rms is not None and self.rms > 1.5 * self.expected_rms

    def __str__(self) -> str:
        text = (
            f"{self.n} poses, frame {self.frame}: mean {self.mean * 1e3:.4f} mm, "
            f"RMS {self.rms * 1e3:.4f} mm, p95 {self.p95 * 1e3:.4f} mm, max {self.max * 1e3:.4f} mm"
        )
        if self.orientation_mean is not None:
            text += f"; orientation mean {np.degrees(self.orientation_mean):.4f}°"
        return text


def validate(
    model: Model | CalibrationResult,
    data: Measurements,
    frame: ArrayLike | None = None,
    refit_frame: bool = False,
) -> ValidationStats:
    """Error statistics of ``model`` on ``data`` (held-out poses).

    Args:
        model: a :class:`CalibrationResult` (its model and device frame) or a model.
        data: measured poses, in the device frame.
        frame: ``T_device_base`` to use instead of the result's.
        refit_frame: refit the device frame to ``data`` (another placement of the device).
    """
    if data.position is None:
        raise ValueError("the validation data has no measured positions")
    label = "given"
    perturbations = None
    result = None
    if isinstance(model, CalibrationResult):
        result, model = model, model.model
        if frame is None:
            frame, label = result.frame, "calibrated"
        if data.dof == model.dof:
            perturbations = result.joint_perturbations(data.q)
    if data.dof != model.dof:
        raise ValueError(
            f"the data has {data.dof} joint columns but model {model.name!r} has {model.dof} joints"
        )
    if perturbations is None and model.joint_effects:
        from robocal.model.joints import joint_perturbations

        perturbations = joint_perturbations(model, data.q)  # a bare model's own joint effects
    T = model.fk(data.q, perturbations)
    if refit_frame and result is not None:
        return _refit_scored(result, data)
    if refit_frame or frame is None:
        T_frame = spatial.fit_rigid_transform(T[:, :3, 3], data.position)
        stats = validation_statistics(T_frame @ T, data, "refit")
        return dataclasses.replace(stats, scoring="in-sample")
    stats = validation_statistics(np.asarray(frame, dtype=float) @ T, data, label)
    if result is not None and label == "calibrated" and result.measurement_chain is not None:
        stats = _with_expectation(stats, result, data, perturbations)
    return stats


def _refit_scored(result: CalibrationResult, data: Measurements) -> ValidationStats:
    """A calibration's frame refitted to ``data``: each row scored with the frame fitted on
    the other rows (K-fold), expected error with that frame's uncertainty; the in-sample
    fit (every row) beside it."""
    from robocal.identify.register import fit_frame, frozen_robot, score_registration

    robot = frozen_robot(result, data)
    assert data.position is not None  # validate checked
    score = score_registration(robot, data.position)
    fit = fit_frame(robot, data.position)
    T = fit.T_device_base @ result.predict(data.q, frame=np.eye(4))
    in_sample = dataclasses.replace(validation_statistics(T, data, "refit"), scoring="in-sample")
    held_out = _position_statistics(score.error_vectors, "refit")
    robot_ms = result.position_uncertainty(data.q, "base") ** 2
    return dataclasses.replace(
        held_out,
        parameter_rms=math.sqrt(float(np.mean(robot_ms))),
        expected_rms=score.expected_rms,
        scatter="registration",
        scoring=score.scoring,
        in_sample=in_sample,
    )


def _with_expectation(
    stats: ValidationStats, result: CalibrationResult, data: Measurements, perturbations: Array | None
) -> ValidationStats:
    """``stats`` with the RMS error the calibration expected at these poses (its device
    frame): the propagated parameter covariance (Cramér–Rao: mean trace of J Cov Jᵀ,
    :func:`mean_position_variance`) plus the scatter: the data's σ and the error the
    calibration's residuals showed beyond its own noise, or, when the data has no σ, the
    calibration's residual σ per axis."""
    parameter_ms = mean_position_variance(result, data.q, perturbations)
    fit = result.fit_to_noise
    learned = result.model.residual
    if learned is not None:
        # the learned residual's evidence estimated what remains per axis: the noise and the
        # error neither the physics nor the residual represents
        scatter_ms, scatter = 3.0 * learned.noise_std**2, "residual model"
    elif data.sigma is not None:
        # this data's noise, and the error the model left unexplained in the calibration
        scatter_ms, scatter = float(np.mean(np.sum(data.sigma**2, axis=1))), "sigma"
        if fit is not None and fit.ratio > 1 and fit.warning() is not None:  # significant only
            scatter_ms, scatter = scatter_ms + fit.unmodelled_rms**2, "sigma+unmodelled"
    else:
        scatter_ms, scatter = 3.0 * result.residual_std**2, "residuals"
    return dataclasses.replace(
        stats,
        parameter_rms=math.sqrt(parameter_ms),
        expected_rms=math.sqrt(parameter_ms + scatter_ms),
        scatter=scatter,
    )


def mean_position_variance(
    result: CalibrationResult, q: ArrayLike, perturbations: Array | None = None
) -> float:
    """The mean over the poses ``q`` ``(n, dof)`` of ``trace(result.position_covariance(q))``
    (m², device frame): the squared position error the calibration's parameter and learned-
    residual uncertainty make, on average, at these poses.

    Computed without the ``(n, 3, 3)`` covariances: ``mean tr(J C Jᵀ) = ⟨C, JᵀJ⟩ / n`` over
    all poses' rows at once, and the residual's part and its cross-covariance with the
    parameters by :meth:`~robocal.model.residual.JointAngleResidual.mean_position_variance`
    (series A's 11,611 held-out poses, 576 coefficients: 0.32 -> 0.28 s CPU; the residual's
    ``n m²`` products are most of either).  ``perturbations``: the result's joint
    perturbations at ``q`` when the caller has them (``result.joint_perturbations(q)``)."""
    q = np.atleast_2d(np.asarray(q, dtype=float))
    chain = result.measurement_chain
    if chain is None:
        raise ValueError("this result has no measurement chain (saved by an older robocal?)")
    if perturbations is None:
        perturbations = result.joint_perturbations(q)
    learned = result.model.residual
    # the perturbation Jacobian once for the effects' columns and the residual's design
    P = None if learned is None else chain.perturbation_jacobian(q, "position", perturbations)
    J = result.position_columns(q, perturbations, P)  # (n, 3, p), the order of result.names
    rows = J.reshape(-1, J.shape[2])
    with one_blas_thread():  # a thin product: threads would mostly wait (the machine is shared)
        total = float(np.vdot(result.covariance, rows.T @ rows)) / len(q)
    if learned is None:
        return total
    assert P is not None
    return total + learned.mean_position_variance(q, P, J, result.residual_cross_covariance)


def validation_statistics(predicted: Array, data: Measurements, frame: str = "given") -> ValidationStats:
    """Error statistics of predicted tool frames ``(n, 4, 4)`` (device frame) against the
    measured positions (and orientations) of ``data``; ``frame`` says how the device
    frame was obtained."""
    if data.position is None:
        raise ValueError("the validation data has no measured positions")
    stats = _position_statistics(predicted[:, :3, 3] - data.position, frame)
    if data.orientation is None:
        return stats
    w = spatial.matrix_to_rotvec(predicted[:, :3, :3] @ np.swapaxes(data.orientation, -1, -2))
    a = np.linalg.norm(w, axis=1)
    return dataclasses.replace(stats, orientation_mean=float(a.mean()), orientation_max=float(a.max()))


def _position_statistics(d: Array, frame: str) -> ValidationStats:
    """The statistics of position errors ``d`` ``(n, 3)`` (predicted - measured, m)."""
    e = np.linalg.norm(d, axis=1)
    ax, ay, az = (float(v) for v in np.abs(d).mean(axis=0))
    rx, ry, rz = (float(v) for v in np.sqrt(np.mean(d**2, axis=0)))
    return ValidationStats(
        n=len(d),
        mean=float(e.mean()),
        rms=float(np.sqrt(np.mean(e**2))),
        max=float(e.max()),
        p95=float(np.percentile(e, 95)),
        axis_mean_abs=(ax, ay, az),
        axis_rms=(rx, ry, rz),
        frame=frame,
        errors=e,
        error_vectors=d,
    )


def cross_validate(
    model: Model, data: Measurements, k: int = 5, seed: int | None = 0, **calibrate_options: Any
) -> list[ValidationStats]:
    """k-fold cross-validation for small datasets: calibrate on k-1 folds, validate on the
    held-out fold with the calibrated device frame; one :class:`ValidationStats` per fold."""
    if not 2 <= k <= data.n:
        raise ValueError(f"k={k} folds need 2 <= k <= {data.n} poses")
    order = np.random.default_rng(seed).permutation(data.n)
    folds = np.array_split(order, k)
    out = []
    for fold in folds:
        train = np.setdiff1d(order, fold)
        result = calibrate(model, data.subset(train), **calibrate_options)
        out.append(validate(result, data.subset(fold)))
    return out
