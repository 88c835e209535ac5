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
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from robocal.choices import RESIDUAL_CHOICES, ResidualChoice, SolverMethod
from robocal.identify.bounds import (
    AT_BOUND_TOLERANCE,
    SEED001_ANGLE_BOUND,
    SEED001_LENGTH_BOUND,
    default_bounds,
    parameters_at_bounds,
)
from robocal.identify.diagnose import outlier_poses as _outlier_poses
from robocal.identify.effects import (
    COMPLIANCE_PREFIX,
    EFFECT_SIGNIFICANCE,
    display_unit,
    effect_lines,
    effect_verdict,
    effects_to_hold,
)
from robocal.identify.options import (
    BOUNDS_CHOICES,
    Bounds,
    CalibrationOptions,
    JointEffects,
    PerPose,
    Pruning,
    RobustLoss,
    Setup,
    Weights,
)
from robocal.identify.pipeline import calibrate_physics
from robocal.identify.problem_setup import LEVELS, parse_level
from robocal.identify.problem_setup import without_measured_tool as _without_measured_tool
from robocal.identify.result import CalibrationResult, CalibrationWarning, Diagnostics
from robocal.identify.result_io import RESULT_FILES, file_hash
from robocal.identify.stages import initial_frames_and_tools, screen_unidentifiable
from robocal.identify.streaming_calibrate import Streaming, calibrate_streamed, streams
from robocal.measure.measurements import Measurements
from robocal.model.chain import Model

__all__ = [
    "AT_BOUND_TOLERANCE",
    "BOUNDS_CHOICES",
    "COMPLIANCE_PREFIX",
    "EFFECT_SIGNIFICANCE",
    "LEVELS",
    "RESIDUAL_CHOICES",
    "RESULT_FILES",
    "SEED001_ANGLE_BOUND",
    "SEED001_LENGTH_BOUND",
    "Bounds",
    "CalibrationOptions",
    "CalibrationResult",
    "CalibrationWarning",
    "Diagnostics",
    "JointEffects",
    "PerPose",
    "Pruning",
    "RobustLoss",
    "Setup",
    "Streaming",
    "Weights",
    "calibrate",
    "calibrate_physics",
    "default_bounds",
    "display_unit",
    "effect_lines",
    "effect_verdict",
    "effects_to_hold",
    "file_hash",
    "initial_frame_and_tool",
    "parameters_at_bounds",
    "parse_level",
    "screen_unidentifiable",
]

_KEEP = (_outlier_poses, _without_measured_tool)  # older private names some callers import

Array = NDArray[np.float64]
Method = SolverMethod  # robocal.choices: the table the command line offers too
_STREAMING = Streaming()  # the default (frozen): made once, not at every calibration


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
    position, orientation = data.position, data.orientation
    if position is None or (measure == "pose" and orientation is None):
        raise ValueError(f"initial_frame_and_tool: the data holds no measured {measure}s")
    if T_flange is None:
        T_flange = robot.fk(data.q)
    T_frame, T_tool = initial_frames_and_tools(
        T_flange[None],
        position[None],
        orientation=orientation[None] if orientation is not None and measure == "pose" else None,
        T_tool=None if tool is None else np.asarray(tool, dtype=float),
        T_frame=None if T_device_base is None else np.asarray(T_device_base, dtype=float),
        fit_frame=fit_frame,
        fit_tool=fit_tool,
        rounds=rounds,
    )
    return T_frame[0], T_tool[0]


# long: the docstring is the public reference of every calibration keyword; the code is 13 lines
def calibrate(
    model: Model,
    data: Measurements,
    method: Method = "lm",
    *,
    options: CalibrationOptions | None = None,
    residual: ResidualChoice = "none",
    residual_harmonics: int | Sequence[int] | None = None,
    cv_folds: int = 5,
    streaming: Streaming | None = None,
    progress: Callable[[float], None] | None = None,
    iteration: Callable[[int, float], None] | None = None,
    **settings: Any,
) -> CalibrationResult:
    """Identify the robot's parameters from measurements: the physical model and,
    optionally, a learned residual on top of it.

    The settings come in groups (:mod:`robocal.identify.options`): ``setup=Setup(...)``,
    ``weights=Weights(...)``, ``loss=RobustLoss(...)``, ``bounds=Bounds(...)``,
    ``per_pose=PerPose(...)``, ``pruning=Pruning(...)``,
    ``joint_effects=JointEffects(...)``, or all of them as ``options=CalibrationOptions(...)``;
    each group's fields may also be given as plain keywords (below).  An unknown keyword
    is an error.

    Args:
        model: the robot model; its free parameters are the candidates.  A catalog robot's
            complete model is :func:`robocal.calibration_model`.
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
            ``result.diagnostics.at_bounds`` and in a warning.
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
        residual: ``"none"`` (the physical model only, the default of the API),
            ``"auto"`` (k-fold cross-validation on ``data`` chooses among the physical
            model, the physical model with joint compliance when the model has masses and
            no joint effects were asked for, and each with the learned joint angle errors
            of :mod:`robocal.model.residual` with each number of harmonics; the default of
            ``robocal calibrate``) or ``"joint_fourier"`` (always the learned residual; CV
            chooses the harmonics only).
        residual_harmonics: the numbers of harmonics CV chooses from (default
            :data:`robocal.identify.residual.stage.DEFAULT_HARMONICS`).
        cv_folds: folds of the cross-validation.
        streaming: when a large input streams (:class:`~robocal.identify.streaming_calibrate.Streaming`;
            default: above 50,000 poses with ``method="lm"`` and the linear loss): the
            decisions (start values, identifiable set, pruning, joint-effect holds, the
            residual's choice) on a well-spread subsample, then the chosen parameters and the
            learned residual fitted on all poses from normal equations accumulated by chunks
            (:mod:`robocal.identify.streaming_calibrate`; ``diagnostics.streaming`` says so).
        progress: called with the share of the calibration done (0 to 1, non-decreasing,
            1 at the end): after the physical fit and, with a learned residual, after each
            physical variant's cross-validation; None: not called.
        iteration: a streamed input's LM, after each pass over all poses:
            ``iteration(evaluations, rms)`` (rms of the weighted residuals, m for unit
            weights; see :func:`~robocal.identify.streaming.levenberg_marquardt_streaming`);
            the dense fits (≤ 50,000 poses) take milliseconds to a second and do not call it.

    Joint effects are physical: an identified clearance tilt, backlash or compliance is at
    least :data:`EFFECT_SIGNIFICANCE` σ above zero.  One that the fit puts below zero, or
    closer to it, is kept at its start value and the fit repeated (a non-negativity active
    set with a significance test, chosen least supported first on the linearised problem:
    :func:`effects_to_hold`); ``dropped`` says why (:func:`effect_verdict`).

    Raises:
        TypeError: an unknown option.
        ValueError: bad data or options (named).
        robocal.identify.guards.CalibrationGuardError: data that cannot determine the
            model, or a fit that failed.
    """
    if residual not in RESIDUAL_CHOICES:
        raise ValueError(f"residual must be one of {', '.join(RESIDUAL_CHOICES)}, got {residual!r}")
    physics = CalibrationOptions.from_keywords(options, **settings)
    progress = None if progress is None else _non_decreasing(progress)
    if model.residual is not None:  # a calibrated model calibrated again: its residual is refitted
        model = dataclasses.replace(model, residual=None)

    def dense(some: Measurements, settings: CalibrationOptions) -> CalibrationResult:
        if residual == "none":
            return calibrate_physics(model, some, method, settings)
        from robocal.identify.residual.stage import calibrate_with_residual

        return calibrate_with_residual(
            calibrate_physics, model, some, method, settings.keywords(),
            kind=residual, harmonics=residual_harmonics, folds=cv_folds, progress=progress,
        )  # fmt: skip

    streaming = _STREAMING if streaming is None else streaming
    if streams(data, method, physics, streaming):  # large inputs: decisions on a subsample, fit streamed

        def facts(result: CalibrationResult, some: Measurements) -> CalibrationResult:
            return _with_tool_facts(result, physics.setup, some, model)

        result = calibrate_streamed(dense, data, physics, streaming, facts=facts, iteration=iteration)
    else:
        result = _with_tool_facts(dense(data, physics), physics.setup, data, model)
    if progress is not None:
        progress(1.0)
    return result


def _non_decreasing(progress: Callable[[float], None]) -> Callable[[float], None]:
    """``progress`` called with the largest share reported so far (a subsample's decisions
    and the streamed fit each report from their start)."""
    most = [0.0]

    def report(fraction: float) -> None:
        most[0] = max(most[0], min(1.0, fraction))
        progress(most[0])

    return report


def _with_tool_facts(
    result: CalibrationResult, setup: Setup, data: Measurements, robot: Model | None = None
) -> CalibrationResult:
    """The result with its measured tool recorded (``records["measured_tool"]``, with the
    stated start value) and warned about: a start value the fit moved far, and the
    parameters and tool components these poses could not determine
    (:mod:`robocal.identify.measured_tool`); and the joint coverage of its poses
    (``records["coverage"]``; ``robot``: the model as given, whose joints the calibrated
    one keeps: its plan is worked out already); the records worked out when first read
    (:func:`~robocal.identify.measured_tool.pose_facts`).  One new result (every
    calibration passes here)."""
    from robocal.identify.measured_tool import (
        measured_tool,
        pose_facts,
        tool_start_warnings,
        undetermined_warnings,
    )

    fitted = isinstance(setup.tool, str) and setup.tool == "fit"
    tool = measured_tool(result, setup.tool_guess if fitted and setup.tool_guess is not None else None)
    known = {w.message for w in result.warnings}
    found = tuple(
        CalibrationWarning(c, m)
        for c, m in (*tool_start_warnings(tool), *undetermined_warnings(result, tool))
        if m not in known
    )
    records = pose_facts(result, tool, result.model if robot is None else robot, data.q)
    return result.replace(warnings=result.warnings + found, records=records)
