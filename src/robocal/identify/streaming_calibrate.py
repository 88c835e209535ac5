"""Large inputs: :func:`robocal.calibrate` streams by itself above a number of poses.

Above :attr:`Streaming.threshold` poses (LM with the linear loss, the default), a calibration
runs in two parts:

1. **Decisions on a subsample** (:func:`well_spread_subsample`: evenly spaced through the
   data plus each joint's extreme poses, deterministic): the ordinary calibration —
   start values, the identifiable set, screening, pruning, joint-effect holds and, with
   ``residual=...``, the learned residual's cross-validated choice — on
   :attr:`Streaming.subsample` poses.  These are choices, and a few thousand well-spread
   poses make them as a million would (the σ that pruning judges shrink as 1/√n: a
   subsample prunes at least what all poses would).
2. **The final fit on all poses, streamed**: the chosen parameters (geometry, device
   frame, tool, joint effects) by Levenberg-Marquardt on normal equations accumulated one
   chunk of poses at a time (:class:`~robocal.identify.streaming.ChunkedProblem`: the full
   Jacobian is never formed), their covariance from the accumulated normal matrix; then
   the learned residual and the physics jointly, from the residual's accumulated normal
   equations (:func:`~robocal.identify.residual.stream.fit_residual_streamed`).

The result is an ordinary :class:`~robocal.identify.result.CalibrationResult` over all
poses (estimates, covariance, residuals per pose, RMS after, outlier poses), whose
``diagnostics.streaming`` says that it streamed, the subsample's size, the chunk and the
passes over the data.  What describes the start and the data rather than the fit comes
from the subsample (well spread, each joint's extremes included): ``rms_before`` (the
start model's RMS), the start values ``nominal``, the fit-to-noise check, the measured
tool's and the joints' coverage records (each a further pass over all poses for a
statistic the subsample gives).
Units: SI (m, rad).
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from robocal import spatial
from robocal.identify.diagnose import outlier_poses
from robocal.identify.options import CalibrationOptions
from robocal.identify.problem import Problem
from robocal.identify.result import CalibrationResult, CalibrationWarning
from robocal.identify.rules import Rules
from robocal.identify.stages import Covariance
from robocal.identify.streaming import (
    DEFAULT_CHUNK,
    ChunkedProblem,
    levenberg_marquardt_streaming,
    streamed_covariance,
)
from robocal.measure.measurements import Measurements
from robocal.model.joints import (
    effect_basis,
    effect_of,
    effects_from_values,
    joint_perturbations,
    load_moments,
)
from robocal.model.residual import JointAngleResidual, one_blas_thread
from robocal.model.steps import Role

__all__ = ["STREAM_SUBSAMPLE", "STREAM_THRESHOLD", "Streaming", "calibrate_streamed", "streams",
           "well_spread_subsample"]  # fmt: skip

Array = NDArray[np.float64]

#: poses above which rc.calibrate streams: the dense fit holds its Jacobian and per-pose work
#: arrays (about 4 kB a pose: 3.9 GB at 1,000,000 poses; 200 MB at 50,000), and from there
#: the streamed fit is also faster (benchmarks/bench_streaming.py)
STREAM_THRESHOLD = 50_000
#: poses of the subsample that makes the decisions (start values, identifiable set,
#: pruning, joint-effect holds, the residual's choice)
STREAM_SUBSAMPLE = 5_000
#: the learned residual's final fit: floating-point operations of its normal matrix (about 2 s
#: on one core): all of 1,000,000 poses at 8 harmonics (6 joints), 100,000 at 24, 25,000 at 48
RESIDUAL_FLOPS = 2e10


@dataclass(frozen=True)
class Streaming:
    """When and how a calibration streams.

    Attributes:
        threshold: more poses than this stream (None: never).
        subsample: poses of the decisions' subsample.
        chunk: poses per chunk of the streamed passes (memory: one chunk's Jacobian,
            ``rows · chunk · p`` doubles).
        residual_flops: the learned residual's final fit accumulates its ``(m, m)`` normal
            matrix over all poses when that costs at most this many floating-point
            operations (``joints (joints + 1) (2H)²`` a pose), else over as many well-spread
            poses as it allows (``diagnostics.streaming["residual_poses"]``).
    """

    threshold: int | None = STREAM_THRESHOLD
    subsample: int = STREAM_SUBSAMPLE
    chunk: int = DEFAULT_CHUNK
    residual_flops: float = RESIDUAL_FLOPS

    def __post_init__(self) -> None:
        if self.threshold is not None and int(self.threshold) < 1:
            raise ValueError(f"streaming threshold must be a positive number of poses, got {self.threshold}")
        if int(self.subsample) < 20:
            raise ValueError(f"streaming subsample must be at least 20 poses, got {self.subsample}")
        if int(self.chunk) < 1:
            raise ValueError(f"streaming chunk must be a positive number of poses, got {self.chunk}")


def streams(data: Measurements, method: str, options: CalibrationOptions, streaming: Streaming) -> bool:
    """Whether this calibration streams: more poses than the threshold, and the default
    solver (LM, linear loss: the one whose steps need only the normal equations)."""
    big = streaming.threshold is not None and data.n > streaming.threshold
    return big and method == "lm" and options.loss.loss == "linear" and data.position is not None


def well_spread_subsample(q: Array, k: int) -> NDArray[np.intp]:
    """``k`` poses evenly spaced through ``q`` ``(n, dof)`` (a recording in time order: along
    its whole path; random poses: a random sample) plus each joint's smallest and largest
    angle (the learned residual's coverage and the joint ranges' ends); sorted, unique,
    deterministic."""
    n = len(q)
    if n <= k:
        return np.arange(n)
    even = np.linspace(0, n - 1, k).round().astype(np.intp)
    return np.unique(np.r_[even, np.argmin(q, axis=0), np.argmax(q, axis=0)])


def _rows(values: Any, s: slice) -> Array | None:
    return None if values is None else np.asarray(values, dtype=float)[s]


def _row_weights(data: Measurements, options: CalibrationOptions, s: slice, rows: int) -> Array:
    """``(c, rows)`` weights 1/σ of the pipeline's rule (:mod:`robocal.identify.problem_setup`)."""
    n = s.stop - s.start
    sigma = data.sigma if options.weights.by == "sigma" else None
    position = np.ones((n, 3)) if sigma is None else 1.0 / np.maximum(sigma[s], 1e-12)
    if rows == 3:
        return position
    orientation = options.weights.orientation * position.mean(axis=1, keepdims=True)
    return np.c_[position, np.repeat(orientation, 3, axis=1)]


def _angle_errors(residual: JointAngleResidual, q: Array) -> Array:
    """``(n, dof)`` the learned residual's joint angle errors (rad) at every pose (0 for the
    joints it does not model), computed once (every pass reuses them)."""
    out = np.zeros(q.shape)
    out[:, list(residual.joint_index)] = residual.angle_errors(q)
    return out


def chunk_problems(
    reference: CalibrationResult, data: Measurements, options: CalibrationOptions
) -> Callable[[slice], Problem]:
    """``problem_of(slice)``: the calibration problem of a chunk of poses with
    ``reference``'s unknowns (:attr:`~CalibrationResult.names`) at its estimates; every
    joint effect and the learned residual not estimated are known perturbations."""
    chain = reference.measurement_chain
    if chain is None:
        raise ValueError("streaming needs the subsample calibration's measurement chain")
    effects = tuple(n for n in reference.names if effect_of(n) is not None)
    if tuple(chain.free_names) + effects != tuple(reference.names):
        raise ValueError("the subsample calibration's unknowns are not its chain's and joint effects'")
    start = np.asarray(reference.estimates[len(chain.free_names) :], dtype=float)
    pairs = [effect_of(n) for n in effects]
    kinds = tuple(sorted({p[0] for p in pairs if p is not None}))
    joints = tuple(sorted({p[1] for p in pairs if p is not None}))
    robot, e = reference.robot, options.joint_effects  # the joint loads' geometry: no tool
    gravity, residual = np.asarray(reference.gravity), reference.model.residual
    rows = 6 if reference.measure == "pose" else 3
    learned = None if residual is None else _angle_errors(residual, data.q)

    def problem_of(s: slice) -> Problem:
        q = data.q[s]
        qd, qdd = _rows(e.velocities, s), _rows(e.accelerations, s)
        known, basis = None, None
        if robot.joint_effects or effects:
            loads = load_moments(robot, q, qd, qdd, gravity=gravity, payload=reference.payload)
            if robot.joint_effects:
                known = joint_perturbations(robot, q, gravity=gravity, payload=reference.payload, loads=loads)
            if effects:
                B, names, _ = effect_basis(robot, q, kinds=kinds, joints=joints, loads=loads)
                basis = B[[names.index(n) for n in effects]]
                taken = np.tensordot(start, basis, axes=1)  # the estimated part: from x
                known = -taken if known is None else known - taken
        if learned is not None:  # the learned residual, known: δθ of its joints
            known = np.zeros((len(q), robot.dof, 3)) if known is None else known
            known[:, :, 2] += learned[s]
        orientation = None if rows == 3 or data.orientation is None else data.orientation[s]
        position = data.position[s] if data.position is not None else np.empty((0, 3))
        weights = _row_weights(data, options, s, rows).reshape(-1)
        return Problem(chain, q, position, orientation, weights, 1.0, basis, effects, known,
                       start if effects else None)  # fmt: skip

    return problem_of


def with_estimates(reference: CalibrationResult, x: Array) -> CalibrationResult:
    """``reference`` with new values ``x`` of its unknowns: its measurement chain, device
    frame, calibrated robot (tool steps included) and joint effects."""
    chain = reference.measurement_chain
    assert chain is not None  # chunk_problems checked it
    p = len(chain.free_names)
    fitted = chain.with_free_values(x[:p])
    device = [s for s in fitted.steps if s.role is Role.DEVICE]
    T_device_base = spatial.chain_product([s.motion for s in device], [s.value for s in device])
    own = set(reference.model.names)
    geometry = zip(chain.free_names, x[:p].tolist(), strict=True)
    model = reference.model.with_values({n: v for n, v in geometry if n in own})
    effects = zip(reference.names[p:], x[p:].tolist(), strict=True)
    values = {pair: v for n, v in effects if (pair := effect_of(n)) is not None}
    if values:
        model = dataclasses.replace(model, joint_effects=effects_from_values(model, values))
    compliance = {k[1]: v for k, v in values.items() if k[0] == "compliance"}
    return reference.replace(model=model, measurement_chain=fitted, T_device_base=T_device_base,
                             estimates=np.asarray(x, dtype=float), compliance=compliance)  # fmt: skip


def _with_covariance(result: CalibrationResult, cov: Array, cross: Array | None = None) -> CalibrationResult:
    std = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = np.where(np.outer(std, std) > 0, cov / np.outer(std, std), 0.0)
    return result.replace(covariance=cov, std=std, correlation=corr, residual_cross_covariance=cross)


def _residual_pass(result: CalibrationResult, data: Measurements, chunk: int) -> Array:
    """``(n, rows)`` predicted minus measured (m, rad; device frame) of ``result`` at every
    pose, by chunks."""
    rows = 6 if result.measure == "pose" else 3
    out = np.empty((data.n, rows))
    assert data.position is not None
    for lo in range(0, data.n, chunk):
        s = slice(lo, min(lo + chunk, data.n))
        T = result.predict(data.q[s])
        out[s, :3] = T[:, :3, 3] - data.position[s]
        if rows == 6 and data.orientation is not None:
            out[s, 3:] = spatial.matrix_to_rotvec(T[:, :3, :3] @ np.swapaxes(data.orientation[s], -1, -2))
    return out


def _outlier_warnings(result: CalibrationResult, data: Measurements) -> tuple[tuple[int, ...], list]:
    """The outlier poses of all poses (indices into ``data``) and the warnings without the
    subsample's outlier warning (its pose numbers were the subsample's)."""
    assert result.residuals is not None
    errors = np.linalg.norm(result.residuals[:, :3], axis=1)
    outliers = tuple(outlier_poses(errors, data.sigma))
    kept: list[CalibrationWarning | str] = [w for w in result.warnings if w.code != "outliers"]
    if outliers:
        worst = sorted(outliers, key=lambda i: -errors[i])[:5]
        shown = ", ".join(f"row {i + 1} ({errors[i] * 1e3:.3g} mm)" for i in worst)
        kept.append(CalibrationWarning("outliers", f"{len(outliers)} pose(s) with residuals far beyond the "
                                       f"others (more than 5x their median): {shown}"))  # fmt: skip
    return outliers, kept


def calibrate_streamed(
    decide: Callable[[Measurements, CalibrationOptions], CalibrationResult],
    data: Measurements,
    options: CalibrationOptions,
    streaming: Streaming,
    facts: Callable[[CalibrationResult, Measurements], CalibrationResult] | None = None,
    iteration: Callable[[int, float], None] | None = None,
) -> CalibrationResult:
    """The calibration of a large data set (see the module docstring).

    Args:
        decide: the ordinary calibration of some poses with some options (the subsample's:
            :func:`robocal.calibrate`'s dense path, residual choice included).
        data: all poses; options: the physical calibration's settings.
        streaming: the subsample's size and the chunk.
        facts: adds the records that describe the data (coverage, the measured tool), given
            the result and the subsample.
        iteration: the streamed LM's ``progress(evaluations, rms)`` (see
            :func:`~robocal.identify.streaming.levenberg_marquardt_streaming`), or None.
    """
    t0 = time.perf_counter()
    index = well_spread_subsample(data.q, int(streaming.subsample))
    e = options.joint_effects
    subsample_options = options.replace(
        velocities=None if e.velocities is None else np.asarray(e.velocities)[index],
        accelerations=None if e.accelerations is None else np.asarray(e.accelerations)[index],
    )
    subsample = data.subset(index)
    sub = decide(subsample, subsample_options)
    t_sub = time.perf_counter()
    with one_blas_thread():  # (p, p) products of thin chunks: idle BLAS threads only cost (2-core load)
        result = _fit_all_poses(sub, data, options, streaming, index, (t0, t_sub), iteration)
    return result if facts is None else facts(result, subsample)


def _refit_residual(
    result: CalibrationResult, sub: CalibrationResult, data: Measurements, streaming: Streaming, x: Array
) -> tuple[CalibrationResult, int]:
    """``result`` (the physics fitted on all poses at ``x``, the subsample's residual known) with
    the learned residual and the physics refitted jointly (:mod:`robocal.identify.residual.stream`),
    and the number of poses that fit used (0: no residual)."""
    learned = sub.model.residual
    if learned is None or data.position is None:
        return result, 0
    from robocal.identify.residual.stream import fit_residual_streamed

    k = len(learned.joints)
    per_pose = k * (k + 1) * (2 * learned.harmonics) ** 2  # flops of the normal matrix's blocks
    fitted = well_spread_subsample(data.q, int(streaming.residual_flops / per_pose))
    whole = len(fitted) == data.n
    q, position = (data.q, data.position) if whole else (data.q[fitted], data.position[fitted])
    refit = fit_residual_streamed(result, q, position, chunk=int(streaming.chunk))
    result = with_estimates(result, x + refit.step)
    result = result.replace(model=dataclasses.replace(result.model, residual=refit.residual))
    return _with_covariance(result, refit.covariance, refit.cross_covariance), len(q)


def _fit_all_poses(
    sub: CalibrationResult,
    data: Measurements,
    options: CalibrationOptions,
    streaming: Streaming,
    index: NDArray[np.intp],
    times: tuple[float, float],
    iteration: Callable[[int, float], None] | None = None,
) -> CalibrationResult:
    """The streamed final fit of :func:`calibrate_streamed` from the subsample's ``sub``
    (``times``: ``perf_counter`` at the start and after the subsample's calibration)."""
    t0, t_sub = times
    refits = sub.model.residual is not None  # then the final residuals are the refit's, by a pass
    chunked = ChunkedProblem(chunk_problems(sub, data, options), data.n, int(streaming.chunk), not refits)
    x0 = np.asarray(sub.estimates, dtype=float)
    solved, ne = levenberg_marquardt_streaming(
        chunked, x0, max_iterations=options.setup.max_iterations, progress=iteration
    )
    known_noise = options.weights.by == "sigma" and data.sigma is not None
    covariance: Covariance = streamed_covariance(ne, known_noise, Rules.of(options.pruning))
    result = _with_covariance(with_estimates(sub, solved.x), covariance.covariance)
    result, residual_poses = _refit_residual(result, sub, data, streaming, solved.x)
    residuals = None if refits else chunked.residuals_at(solved.x)  # the last pass's, at the solution
    passes = chunked.passes + (residual_poses > 0) + (residuals is None)
    if residuals is None:
        residuals = _residual_pass(result, data, int(streaming.chunk))
    after = float(np.einsum("ij,ij->", residuals[:, :3], residuals[:, :3])) / data.n
    p = len(result.names)
    result = result.replace(
        residuals=residuals, rms_after=math.sqrt(after), n=data.n,
        residual_std=math.sqrt(after * data.n / max(3 * data.n - p, 1)),
        condition_number=covariance.condition,
        success=solved.success, message=solved.message, iterations=solved.iterations,
    )  # fmt: skip
    outliers, warnings = _outlier_warnings(result, data)
    result = result.replace(warnings=()).with_warnings(*warnings)
    if result.model.residual is not None:
        result = result.with_diagnostics(residual_rms_after_mm=math.sqrt(after) * 1e3)
    record = {"poses": data.n, "subsample": len(index), "chunk": int(streaming.chunk),
              "passes": passes, "residual_poses": residual_poses,
              "subsample_seconds": t_sub - t0, "streamed_seconds": time.perf_counter() - t_sub}  # fmt: skip
    return result.with_diagnostics(
        outlier_poses=outliers, evaluations=sub.diagnostics.evaluations + solved.evaluations,
        solve_seconds=sub.diagnostics.solve_seconds + time.perf_counter() - t_sub, streaming=record,
    ).replace(seconds=time.perf_counter() - t0)  # fmt: skip
