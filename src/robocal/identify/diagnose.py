"""The last stage of a calibration: what the user should know about it.

:func:`diagnose` adds to a :class:`~robocal.identify.result.CalibrationResult` its warnings
(outlier poses, too little redundancy, residuals beyond the stated noise, parameters at
their bounds, an RMS error that rose under seed 001's objective) and diagnostics
(fit-to-noise, outliers, the bounded method's objective), then runs the solution guard
(:func:`robocal.identify.guards.check_solution`).  Units: SI (m, rad).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from robocal.identify.guards import CalibrationGuardError, check_solution
from robocal.identify.noise_check import FitToNoise
from robocal.identify.problem import Problem
from robocal.identify.result import CalibrationResult, CalibrationWarning, Diagnostics
from robocal.identify.stages import median
from robocal.measure.measurements import Measurements
from robocal.model.chain import Model
from robocal.model.geometry import Measure

__all__ = ["diagnose", "outlier_poses", "parameterisation_warnings"]

Array = NDArray[np.float64]
_NO_SIGMA = np.zeros((0, 3))  # position_errors' "no stated noise"


@functools.lru_cache(maxsize=64)
def _cached_parameterisation_warnings(model: Model, measure: Measure) -> tuple[str, ...]:
    from robocal.model.singularity import parameterisation_warnings as warnings

    return tuple(warnings(model, measure))


def parameterisation_warnings(model: Model, measure: Measure) -> list[str]:
    """Why ``model`` is a poor chain to calibrate (singular or discontinuous at its nominal
    values: e.g. plain DH for parallel axes), with the fix; ``[]`` for a complete model.
    15-25 ms per chain, so cached per model (models are immutable and hashable)."""
    try:
        return list(_cached_parameterisation_warnings(model, measure))
    except TypeError:  # pragma: no cover - an unhashable model: check it every time
        from robocal.model.singularity import parameterisation_warnings as warnings

        return warnings(model, measure)


def outlier_poses(errors: Array, sigma: Array | None, factor: float = 5.0) -> list[int]:
    """Indices of the poses whose position residual ``errors`` ``(n,)`` (m) exceeds
    ``factor`` times the median residual (and ``factor`` times the 3D noise when the data
    states it): a residual of a well fitted pose is rarely over 3x the median (3D
    Gaussian), so these are measurement glitches or poses the model cannot reach."""
    if len(errors) < 10:
        return []
    return _outliers(errors, median(errors), None if sigma is None else float(np.vdot(sigma, sigma)), factor)


def _outliers(errors: Array, median_error: float, noise: float | None, factor: float = 5.0) -> list[int]:
    """:func:`outlier_poses` from the errors' median (m) and ``Σσ²`` (m², None: not stated)."""
    if len(errors) < 10:
        return []
    limit = factor * median_error
    if noise is not None:  # the 3D noise: √ of the mean of Σσ² over the poses
        limit = max(limit, factor * math.sqrt(noise / len(errors)))
    return (errors > limit).nonzero()[0].tolist()  # errors: 1-D (flatnonzero without its ravel)


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
    mean = result.diagnostics.objective  # seed 001's objective: set by method="bounded"
    if result.rms_after <= result.rms_before or mean is None:
        return None
    large = int(np.sum(pose_errors > 3.0 * float(np.median(pose_errors))))
    return (
        f"the RMS error rose from {result.rms_before * 1e3:.4g} to {result.rms_after * 1e3:.4g} mm while the "
        f"mean distance fell from {mean['mean_distance_before'] * 1e3:.4g} to "
        f"{mean['mean_distance_after'] * 1e3:.4g} mm: the sum of distances (Li et al. 2016) fits most "
        f"poses and leaves {large} of {len(pose_errors)} with errors over 3x the median, an error the model "
        "does not describe (backlash? a second robot configuration?); method='lm' minimises the RMS "
        "error instead"
    )


def _bounds_warnings(
    result: CalibrationResult, pose_errors: Array, at: Sequence[str]
) -> list[CalibrationWarning]:
    out = []
    if (rose := _rms_rose(result, pose_errors)) is not None:
        out.append(CalibrationWarning("rms-rose", rose))
    if at:
        out.append(CalibrationWarning(
            "at-bounds",
            f"{', '.join(at)} ended at {'its bound' if len(at) == 1 else 'their bounds'}: the bound, not "
            "the data, decided the value and the fit may be poor; widen the bounds (bounds='widened' for "
            "parameters that absorb redundant ones, or your own arrays) or use method='lm'",
        ))  # fmt: skip
    return out


def _outlier_warning(outliers: list[int], errors: Array, data: Measurements, loss: str) -> CalibrationWarning:
    worst = sorted(outliers, key=lambda i: -errors[i])[:5]
    shown = ", ".join(
        f"{i} ({errors[i] * 1e3:.3g} mm at q = [{', '.join(f'{v:.4g}' for v in data.q[i])}])" for i in worst
    )
    return CalibrationWarning(
        "outliers",
        f"{len(outliers)} pose(s) with residuals far beyond the others (more than 5x their median"
        + (" and 5x the noise" if data.sigma is not None else "")
        + f"): {shown}{' ...' if len(outliers) > 5 else ''}; measurement glitches? "
        + ("a robust loss (loss='soft_l1' / --loss soft_l1) down-weights them" if loss == "linear" else ""),
    )


def _redundancy_warning(n: int, rows: int, unknowns: int) -> CalibrationWarning | None:
    if n * rows >= 2 * unknowns:
        return None
    needed = -(-2 * unknowns // rows)  # poses for twice as many equations as unknowns
    return CalibrationWarning(
        "few-equations",
        f"{n} poses give {n * rows} equations for {unknowns} unknowns: so little redundancy makes the "
        "estimates sensitive to every measurement and their uncertainty itself uncertain; measure at "
        f"least {needed} poses",
    )


def _with_changes(diagnostics: Diagnostics, changes: dict[str, Any]) -> Diagnostics:
    """``diagnostics`` with some fields changed, copied as :meth:`CalibrationResult.replace`
    copies a result (a Diagnostics has no checks to repeat; ``dataclasses.replace`` costs
    a few µs more per calibration); TypeError for an unknown field."""
    if unknown := changes.keys() - vars(diagnostics).keys():
        raise TypeError(f"Diagnostics has no field(s) {', '.join(sorted(unknown))}")
    new = object.__new__(Diagnostics)
    new.__dict__.update(vars(diagnostics), **changes)
    return new


def diagnose(
    result: CalibrationResult,
    problem: Problem,
    data: Measurements,
    warnings: Sequence[CalibrationWarning],
    known_noise: bool,
    loss: str,
    x0: Array,
    at_bounds: Sequence[str] | None,
    orientation_hint: str = "",
) -> CalibrationResult:
    """``result`` with its warnings (``warnings`` of the earlier stages first) and
    diagnostics, after the solution guard.

    Raises:
        CalibrationGuardError: the solution guard's (with the orientation hint, if any).
    """
    import robocal.identify.kernels.check as check_kernels  # numba: imported on first use

    out = list(warnings)
    r = np.ascontiguousarray(result.residuals)
    sigma = _NO_SIGMA if data.sigma is None else np.ascontiguousarray(data.sigma, dtype=float)
    # (n,) 3D position errors (m), their median; Σr², Σ(r/σ)² and Σσ² over the position rows
    errors, median_error, squares, chi2, noise = check_kernels.position_errors(r, sigma)
    outliers = _outliers(errors, median_error, None if data.sigma is None else noise)
    changes: dict[str, Any] = {"outlier_poses": tuple(outliers)}
    if at_bounds is not None:
        changes |= {
            "at_bounds": tuple(at_bounds),
            "objective": _distance_objective(problem, x0, result.estimates),
        }
        result = result.with_diagnostics(**changes)
        out += _bounds_warnings(result, errors, at_bounds)
    if outliers:
        out.append(_outlier_warning(outliers, errors, data, loss))
    if (few := _redundancy_warning(data.n, problem.rows, len(result.estimates))) is not None:
        out.append(few)
    if known_noise:
        # does the model explain the data down to the noise? (position rows; for pose
        # measurements their share of the estimated parameters)
        n_estimated = len(result.estimates) * 3 / problem.rows
        fit = FitToNoise.from_sums(chi2, squares, noise, data.n, n_estimated)
        changes["fit_to_noise"] = fit
        if (text := fit.warning()) is not None:
            out.append(CalibrationWarning("fit-to-noise", text))
    # the guard reads the estimates, the errors and a bounded fit's objective (set above), not
    # the outliers or the fit to noise: one new result with all of them
    try:
        out += [CalibrationWarning("solution", w) for w in check_solution(result)]
    except CalibrationGuardError as err:
        raise CalibrationGuardError(f"{err}; {orientation_hint}" if orientation_hint else str(err)) from None
    diagnostics = _with_changes(result.diagnostics, changes)
    return result.replace(diagnostics=diagnostics, warnings=tuple(out))
