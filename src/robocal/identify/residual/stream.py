"""The learned residual's final fit on all poses of a large data set, streamed.

Given the physical calibration (``x̂``, its measurement chain and joint effects) and the
residual's layout and hyperparameters chosen on a subsample, the residual is linear: the
physics' position residual ``r = p_measured − p(x̂)`` is ``r ≈ J δx + A c`` (``J`` the
physical parameters' columns, ``A`` the residual's design, :mod:`robocal.identify.residual.fit`).
The maximum a posteriori ``(δx, c)`` with the prior ``c ~ N(0, S)`` and a flat prior on
``δx`` solves ``[JᵀJ, JᵀA; AᵀJ, AᵀA + σ² S⁻¹] [δx; c] = [Jᵀr; Aᵀr]``, whose sums are
accumulated chunk by chunk (:func:`~robocal.identify.residual.fit.raw_blocks`: memory
``O((p + m)²)`` plus one chunk, whatever the number of poses); the same matrix, inverted,
is the joint covariance of both (the dense path's
:func:`~robocal.identify.residual.stage.calibrate_with_residual` computes it so too).
Units: SI (m, rad).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.linalg import cho_factor, cho_solve

from robocal.identify.residual.cv import PhysicalFit
from robocal.identify.residual.fit import Raw, layout, one_blas_thread_limit, prior, raw_blocks
from robocal.model.residual import JointAngleResidual

__all__ = ["STREAM_CHUNK", "StreamedResidual", "fit_residual_streamed"]

Array = NDArray[np.float64]

#: poses per chunk of the residual's pass (its perturbation Jacobian is 72 doubles a pose for
#: six joints; the design itself is formed 2,048 poses at a time by raw_blocks)
STREAM_CHUNK = 20_000
_RMS_CHUNK = 4096  # poses per chunk of the angle errors' RMS ((chunk, joints, 2H) basis)


@dataclass(frozen=True)
class StreamedResidual:
    """The learned residual refitted on all poses with the physical parameters.

    Attributes:
        residual: the residual (coefficients, their covariance, coverage of all poses).
        step: ``(p,)`` the physical parameters' change ``δx`` of the joint solution (SI).
        covariance: ``(p, p)`` the physical parameters' covariance from the joint fit.
        cross_covariance: ``(p, m)`` between the physical parameters and the coefficients.
        poses: the number of poses fitted.
    """

    residual: JointAngleResidual
    step: Array
    covariance: Array
    cross_covariance: Array
    poses: int


def _sums(physics: Any, template: JointAngleResidual, q: Array, position: Array, chunk: int) -> Raw:
    """The residual's normal equations with the physical columns (:class:`Raw`), over all poses."""
    fit = PhysicalFit(physics, np.empty(0), np.empty(0), np.empty(0))
    raw: Raw | None = None
    for lo in range(0, len(q), chunk):
        s = slice(lo, min(lo + chunk, len(q)))
        predicted, P, J = fit.predict(q[s])
        part = raw_blocks(q[s], position[s] - predicted, P, template, J)
        raw = part if raw is None else raw + part
    if raw is None:
        raise ValueError("no poses to fit the learned residual to")
    return raw


def _angle_rms(residual: JointAngleResidual, q: Array) -> tuple[float, ...]:
    """RMS (rad) per joint of the fading part's angle errors (the harmonics above the global
    ones) over the poses ``q``, by chunks."""
    fading = residual.coefficients.reshape(len(residual.joints), residual.harmonics, 2).copy()
    fading[:, : residual.global_harmonics] = 0.0
    part = dataclasses.replace(residual, coefficients=fading.reshape(-1))
    total = np.zeros(len(residual.joints))
    for lo in range(0, len(q), _RMS_CHUNK):
        total += np.sum(part.angle_errors(q[lo : lo + _RMS_CHUNK]) ** 2, axis=0)
    return tuple(float(v) for v in np.sqrt(total / max(len(q), 1)))


def fit_residual_streamed(
    result: Any, q: Array, position: Array, *, chunk: int = STREAM_CHUNK
) -> StreamedResidual:
    """Refit ``result``'s learned residual (its layout and hyperparameters kept) jointly
    with its physical parameters on all poses (see the module docstring).

    Args:
        result: a :class:`~robocal.identify.result.CalibrationResult` whose ``model.residual``
            is the residual to refit and whose physics is the fit it corrects.
        q: ``(n, dof)`` joint values (rad, m); position: ``(n, 3)`` measured (m, device frame).
        chunk: poses per pass chunk.

    Raises:
        ValueError: a result without a learned residual, or no poses.
        numpy.linalg.LinAlgError: a singular joint normal matrix.
    """
    learned: JointAngleResidual | None = result.model.residual
    if learned is None:
        raise ValueError("this calibration has no learned residual to refit")
    physics = result.replace(model=dataclasses.replace(result.model, residual=None))
    template = learned.covering(q)  # its fade follows the coverage of all poses
    with one_blas_thread_limit():
        raw = _sums(physics, template, q, position, chunk)
    groups, freq = layout(template)
    theta = np.r_[
        np.log(learned.amplitudes), np.log(learned.length_scale), np.log(max(learned.noise_std, 1e-12))
    ]
    d = np.exp(0.5 * prior(theta, groups, freq))  # whitened coefficients: c = d v
    p, m, noise2 = raw.JJ.shape[0], template.size, max(learned.noise_std, 1e-12) ** 2
    F = np.block([[raw.JJ, raw.JA * d], [(raw.JA * d).T, d[:, None] * raw.AA * d]])
    F[p:, p:] += noise2 * np.eye(m)
    rhs = np.r_[raw.Jr, d * raw.Ar]
    scale = np.sqrt(np.maximum(np.diag(F), 1e-300))  # columns scaled: their units differ widely
    factor = cho_factor(F / np.outer(scale, scale), lower=True)
    solution = cho_solve(factor, rhs / scale) / scale
    inverse = cho_solve(factor, np.eye(p + m)) / np.outer(scale, scale) * noise2
    inverse = 0.5 * (inverse + inverse.T)
    cov_c = d[:, None] * inverse[p:, p:] * d[None, :]
    refitted = dataclasses.replace(template, coefficients=d * solution[p:], covariance=cov_c)
    refitted = dataclasses.replace(refitted, angle_rms=_angle_rms(refitted, q))
    return StreamedResidual(refitted, solution[:p], inverse[:p, :p], inverse[:p, p:] * d[None, :], len(q))
