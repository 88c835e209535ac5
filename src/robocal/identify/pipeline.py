"""The physical calibration as a sequence of named stages (:func:`calibrate_physics`).

1. :func:`_check_inputs` — the method, the data, the model (guards of
   :mod:`robocal.identify.guards`: bad data is refused before any fit);
2. :func:`_start_values` — device frame and tool by closed-form fits
   (:func:`robocal.identify.stages.initial_frames_and_tools`);
3. :func:`_build_problem` — the measurement chain, row weights and joint-effect
   patterns (:class:`~robocal.identify.problem.Problem`);
4. :func:`_identifiable` — the identifiable set by the sequential rank test, and the
   rank guard;
5. :func:`_screen` — unknowns the data leaves hopeless, fixed before the first fit;
6. :func:`_solve` — the solver (:mod:`robocal.identify.solvers`), then :func:`_prune`
   (poorly identifiable unknowns fixed and the fit repeated) and :func:`_hold_effects`
   (joint effects not ≥ 3σ above zero held);
7. :func:`_assemble` — the calibrated model, device frame and residuals;
8. :func:`_diagnose` — warnings, fit-to-noise, the solution guard.

Joint-effect load passes (:func:`_with_load_passes`) repeat 2-8 with the joint loads of
the calibrated geometry.  The residual model (:func:`robocal.calibrate` with
``residual=...``) and the uncertainty of the learned residual are stages of
:mod:`robocal.identify.residual` around this one.  Units: SI (m, rad).
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from robocal import spatial
from robocal.identify.bounds import bounded_method_bounds, parameters_at_bounds
from robocal.identify.diagnose import diagnose, parameterisation_warnings
from robocal.identify.effects import COMPLIANCE_PREFIX, EffectPlan, effect_plan, effects_to_hold
from robocal.identify.guards import check_data, check_rank
from robocal.identify.observability import Dropped
from robocal.identify.options import CalibrationOptions, check_load_model
from robocal.identify.problem import FRAME_PREFIX, TOOL_PREFIX, Problem, measurement_chain
from robocal.identify.result import CalibrationResult, CalibrationWarning, Diagnostics
from robocal.identify.solvers import METHODS, SolveResult, solve
from robocal.identify.stages import (
    identifiable_set,
    initial_frames_and_tools,
    poorly_identifiable,
    robot_sizes,
    screen_unidentifiable,
    uncertainty,
)
from robocal.measure.dataset import Measurements
from robocal.model.chain import Model

__all__ = ["calibrate_physics", "parse_level", "without_measured_tool"]

Array = NDArray[np.float64]

#: calibration levels by name (seed 003 §1.2)
LEVELS: dict[str, int] = {
    "1": 1, "offsets": 1, "joint-offsets": 1, "zero-offset": 1,
    "2": 2, "kinematic": 2, "geometric": 2,
    "3": 3, "non-geometric": 3,
}  # fmt: skip


def parse_level(level: int | str | None) -> int | None:
    """1, 2 or 3 from a number or a name (``offsets``, ``kinematic``, ``non-geometric``)."""
    if level is None:
        return None
    key = str(level).strip().lower()
    if key not in LEVELS:
        raise ValueError(
            f"unknown calibration level {level!r}: 1 (joint offsets), 2 (kinematic) or 3 (non-geometric)"
        )
    return LEVELS[key]


def without_measured_tool(model: Model) -> tuple[Model, Array | None]:
    """``model`` without the tool steps (``tcp_*``) an earlier calibration appended to
    its end, and their transform (4x4; None when there are none)."""
    k = len(model.steps)
    while k and model.steps[k - 1].name.startswith(TOOL_PREFIX) and model.steps[k - 1].joint is None:
        k -= 1
    if k == len(model.steps):
        return model, None
    tool = model.steps[k:]
    T = spatial.chain_product([s.motion for s in tool], [s.value for s in tool])
    return dataclasses.replace(model, steps=model.steps[:k]), T


def _as_frame(value: Any) -> Array:
    """A tool or frame given as a position (3,) or a 4x4 transform, as 4x4."""
    g = np.asarray(value, dtype=float)
    return g if g.shape == (4, 4) else spatial.homogeneous(p=g)


# ---------------------------------------------------------------------- the working state
@dataclass
class _Run:
    """What one pass of the pipeline knows; internal and short-lived (the result it
    produces is frozen)."""

    given_model: Model  # the model as given (tool steps of an earlier calibration removed)
    model: Model  # its candidates (level 1: the joint offsets only)
    data: Measurements
    method: str
    options: CalibrationOptions
    measure: str
    plan: EffectPlan
    level: int | None
    warnings: list[CalibrationWarning] = field(default_factory=list)
    orientation_hint: str = ""
    known_noise: bool = False
    length: float = 1.0
    solver: dict[str, Any] = field(default_factory=dict)
    dropped: list[Dropped] = field(default_factory=list)
    problem: Problem | None = None
    x0: Array | None = None
    x: Array | None = None
    fit: SolveResult | None = None
    covariance: tuple[float, Array, Array, Array, float] | None = None
    solve_seconds: float = 0.0
    evaluations: int = 0
    effect_names: tuple[str, ...] = ()
    effect_kinds: tuple[tuple[str, str], ...] = ()
    effect_start: Array | None = None

    def warn(self, code: str, message: str) -> None:
        self.warnings.append(CalibrationWarning(code, message))


# ---------------------------------------------------------------------- 1. checks
def _check_inputs(
    model: Model, data: Measurements, method: str, options: CalibrationOptions, hold: dict | None
) -> _Run:
    """The method, the data and the model; refuses what cannot be calibrated."""
    if method not in METHODS:
        raise ValueError(f"unknown method {method!r}; choose one of {', '.join(METHODS)}")
    if data.position is None:
        raise ValueError("the measurements have no positions to calibrate against")
    if data.dof != model.dof:
        raise ValueError(
            f"the data has {data.dof} joint columns but model {model.name!r} has {model.dof} joints"
        )
    setup = options.setup
    measure = setup.measure or ("pose" if data.orientation is not None else "position")
    if measure == "pose" and data.orientation is None:
        raise ValueError("measure='pose' needs measured orientations")
    # a calibrated model (model.yaml of an earlier calibration) carries its measured tool:
    # it becomes the tool's start value
    model, carried_tool = without_measured_tool(model)
    if carried_tool is not None and setup.tool_guess is None:
        options = options.replace(tool_guess=carried_tool)
        setup = options.setup
    effects = options.joint_effects
    level = parse_level(effects.level)
    run = _Run(model, model, data, method, options, measure, effect_plan(model, level, effects.effects,
               effects.compliance), level)  # fmt: skip
    # stop with an explanation when the data cannot determine the model (identical
    # poses, joints that never move, too few poses...) rather than fit a silent bad model
    for text in check_data(model, data):
        run.warn("data", text)
    for text in parameterisation_warnings(model, measure):
        run.warn("parameterisation", text)
    if (3 if measure == "position" else 6) * data.n < len(model.free_names) + 12:
        # so few poses that there may be fewer equations than unknowns: say so before fitting
        check_rank(
            model, data, measure=measure, frame=setup.frame, tool=setup.tool, tool_guess=setup.tool_guess
        )
    if level == 1:  # joint offsets only: every other robot parameter is kept
        run.model = model.fixed([s.name for s in model.steps if s.joint is None])
    return run


# ---------------------------------------------------------------------- 2. start values
def _start_values(run: _Run) -> tuple[Array, Array, Array, bool]:
    """Start values of the device frame and the tool (4x4 each), the flange frames
    ``(n, 4, 4)`` at the data's joint values, and whether the frame is fitted."""
    setup, data = run.options.setup, run.data
    fit_frame = isinstance(setup.frame, str) and setup.frame == "fit"
    T_known = None
    if not isinstance(setup.frame, str):
        T_known = np.asarray(setup.frame, dtype=float)
        if T_known.shape != (4, 4):
            raise ValueError(f"frame must be 'fit', 'fixed' or a 4x4 transform, got shape {T_known.shape}")
    T_tool0 = np.eye(4) if setup.tool_guess is None else _as_frame(setup.tool_guess)
    fit_tool = isinstance(setup.tool, str) and setup.tool == "fit"
    if setup.tool is not None and not isinstance(setup.tool, str):
        T_tool0 = _as_frame(setup.tool)
    T_flange = run.model.fk(data.q)
    T_frame, T_tool = initial_frames_and_tools(
        T_flange[None],
        data.position[None],
        orientation=data.orientation[None] if run.measure == "pose" else None,
        T_tool=T_tool0,
        T_frame=T_known,
        fit_frame=fit_frame,
        fit_tool=fit_tool and setup.tool is not None,
    )
    return T_frame[0], T_tool[0], T_flange, fit_frame


# ---------------------------------------------------------------------- 3. the problem
def _row_weights(run: _Run, rows: int) -> Array:
    """``(n, rows)`` weights: 1/σ of a stated noise, orientation rows by ``orientation``."""
    data, weights = run.data, run.options.weights
    w = np.ones((data.n, rows))
    run.known_noise = weights.by == "sigma" and data.sigma is not None
    if run.known_noise:
        w[:, :3] = 1.0 / np.maximum(data.sigma, 1e-12)
    if rows == 6:
        w[:, 3:] = weights.orientation * (w[:, :3].mean(axis=1, keepdims=True))
    return w


def _effect_terms(run: _Run, load_model: Model | None) -> tuple[Array | None, Array | None]:
    """The identified joint effects' patterns ``(k, n, dof, 3)`` and the perturbations
    of the model's other joint effects, known and predicted at every pose."""
    from robocal.model.joints import EFFECT_KINDS, EFFECT_PREFIXES, effect_basis, load_moments
    from robocal.model.joints import joint_perturbations as predict_effects

    model, q, plan, e = run.model, run.data.q, run.plan, run.options.joint_effects
    geometry = model if load_model is None else check_load_model(load_model, model)
    loads = load_moments(geometry, q, e.velocities, e.accelerations, gravity=np.asarray(e.gravity),
                         payload=e.payload)  # fmt: skip
    basis = None
    if plan.kinds:
        joints = plan.joints if plan.joints is not None else e.joints
        basis, run.effect_names, run.effect_kinds = effect_basis(model, q, kinds=plan.kinds, joints=joints,
                                                                 loads=loads)  # fmt: skip
        run.effect_names, run.effect_kinds = tuple(run.effect_names), tuple(run.effect_kinds)
    by_joint = {x.joint: x for x in model.joint_effects}
    run.effect_start = np.array(
        [getattr(by_joint[j], EFFECT_PREFIXES[k][1]) if j in by_joint else 0.0 for k, j in run.effect_kinds]
    )
    if not model.joint_effects:
        return basis, None
    # the model's joint effects that are not identified are known: predicted at every pose
    identified = set(run.effect_kinds)
    rest = [
        dataclasses.replace(
            x, **{EFFECT_PREFIXES[k][1]: 0.0 for k in EFFECT_KINDS if (k, x.joint) in identified}
        )
        for x in model.joint_effects
    ]
    known = predict_effects(model, q, effects=rest, loads=loads)
    if not np.any(known):
        return basis, None
    predicted = {k: [x.joint for x in rest if getattr(x, EFFECT_PREFIXES[k][1])] for k in EFFECT_KINDS}
    listed = "; ".join(f"{k} ({', '.join(j)})" for k, j in predicted.items() if j)
    run.warn(  # a robot whose joints differ from its model's would be mis-corrected
        "effects-predicted",
        f"joint effects of model {model.name!r} predicted as known, not identified: {listed}; if this "
        "robot's differ, identify them too (level=3 / --level 3) or calibrate a model without them",
    )
    return basis, known


def _build_problem(run: _Run, load_model: Model | None) -> None:
    """The measurement chain at the start values, weights and joint-effect patterns."""
    setup, data, measure = run.options.setup, run.data, run.measure
    T_frame, T_tool, T_flange, fit_frame = _start_values(run)
    chain = measurement_chain(run.model, T_frame, None if setup.tool is None else T_tool, measure, fit_frame)
    if setup.tool is not None and not (isinstance(setup.tool, str) and setup.tool == "fit"):
        chain = chain.fixed([s.name for s in chain.steps if s.name.startswith(TOOL_PREFIX)])
    run.length = float(robot_sizes(T_flange[None])[0])
    rows = 3 if measure == "position" else 6
    w = _row_weights(run, rows)
    basis, known = _effect_terms(run, load_model) if run.plan.mode != "none" else (None, None)
    if run.model.residual is not None:  # a learned residual given with the model is known: applied
        learned = run.model.residual.perturbations(data.q, run.model.dof)
        known = learned if known is None else known + learned
    start = run.effect_start if run.plan.mode != "none" else None
    run.problem = Problem(chain, data.q, data.position, data.orientation if rows == 6 else None,
                          w.reshape(-1), run.length, basis, run.effect_names, known, start)  # fmt: skip
    if rows == 6:
        _check_orientations(run)


def _check_orientations(run: _Run) -> None:
    """With the device frame and the tool fitted, a real robot's orientations agree with
    its model to a degree or so; far more means the file's rotations are read wrongly."""
    problem = run.problem
    r = problem.residual(problem.x0, weighted=False).reshape(run.data.n, 6)
    angle = np.degrees(np.median(np.linalg.norm(r[:, 3:], axis=1)))
    if angle > 5.0:
        run.orientation_hint = (
            f"the measured orientations differ from the model's by {angle:.3g}° (median) after the "
            "device frame and the tool were fitted: check the orientation convention of the data "
            "(orientation='euler:XYZ:deg' / --orientation: intrinsic XYZ is upper case, extrinsic "
            "xyz lower case), or calibrate positions only (measure='position')"
        )
        run.warn("orientation", run.orientation_hint)


# ---------------------------------------------------------------------- 4. identifiable set
def _identifiable(run: _Run, hold: dict | None) -> None:
    """The identifiable set, preferring the frame, then the tool, then the robot in chain
    order (one factorisation of the scaled Jacobian at the start values); the rank guard;
    joint effects the caller holds."""
    problem, setup = run.problem, run.options.setup
    names = problem.free_names
    selection = identifiable_set(problem.scaled_jacobian(problem.x0), names)
    for text in check_rank(run.given_model, run.data, measure=run.measure, frame=setup.frame, tool=setup.tool,
                           tool_guess=setup.tool_guess, kept=selection.kept, candidates=names):  # fmt: skip
        run.warn("rank", text)
    if selection.dropped:
        problem = problem.fix([d.name for d in selection.dropped])
    held = [
        why if isinstance(why, Dropped) else Dropped(name, "undetermined", detail=str(why))
        for name, why in (hold or {}).items()
        if name in problem.effect_names
    ]
    if held:
        problem = problem.fix([d.name for d in held])
    run.problem, run.x0 = problem, problem.x0
    run.dropped = list(selection.dropped) + held
    run.solver = _solver_options(run, selection.dropped)


def _solver_options(run: _Run, rank_dropped: list[Dropped]) -> dict[str, Any]:
    """The chosen method's settings (each method takes only its own)."""
    o, method = run.options, run.method
    solver: dict[str, Any] = {"max_iterations": o.setup.max_iterations}
    if method == "lm":
        f_scale = o.loss.f_scale * float(np.median(run.problem.weights.reshape(run.data.n, -1)[:, :3]))
        solver |= {"loss": o.loss.loss, "f_scale": f_scale}
    elif method in ("pinv", "influence"):
        p = o.per_pose
        solver["resolution"] = p.resolution
        if method == "influence" or p.per_pose:
            solver |= {
                "combine": p.combine,
                "passes": p.passes,
                "per_pose": p.per_pose,
                "relaxation": p.relaxation,
            }
    elif method == "bounded":
        robot = set(run.model.names)
        lo, hi, widened = bounded_method_bounds(o.bounds.value, run.problem, rank_dropped, run.length, robot)
        if widened is not None:
            run.warn("bounds-widened", widened)
        solver["bounds"] = (lo, hi)
    return solver


# ---------------------------------------------------------------------- 5. screening
def _screen(run: _Run) -> None:
    """The hopeless unknowns, fixed before the first fit (they would be pruned anyway);
    not for ``bounded`` (its bounds keep a poorly determined unknown from running away)."""
    if run.method == "bounded":
        return
    problem, x0, pruning = run.problem, run.x0, run.options.pruning
    r, J = problem.residual(x0), problem.jacobian(x0)
    found = screen_unidentifiable(r, J, problem.effect_scale(x0), pruning.max_std, pruning.max_std_ratio,
                                  known_noise=run.known_noise)  # fmt: skip
    if found:
        names = problem.free_names
        run.dropped += [Dropped(names[c], "poorly identifiable", sigma=sigma) for c, sigma in found]
        run.problem = problem.fix([names[c] for c, _ in found])
        run.x0 = run.problem.x0


# ---------------------------------------------------------------------- 6. solve, prune, hold
def _solve(run: _Run, x_start: Array) -> None:
    """One fit from ``x_start`` and the uncertainty at its solution (from the solver's
    last Jacobian when it has it: no second evaluation)."""
    t = time.perf_counter()
    run.fit = solve(run.problem, x_start, run.method, **run.solver)
    run.solve_seconds += time.perf_counter() - t
    run.evaluations += run.fit.evaluations
    run.x = run.fit.x
    r, J = run.fit.r, run.fit.J
    if r is None or J is None:
        r, J = run.problem.residual(run.x), run.problem.jacobian(run.x)
    run.covariance = uncertainty(r, J, run.problem.rows, run.known_noise)


def _prune(run: _Run) -> None:
    """Drop what these measurements cannot determine, worst first, and refit from the
    start values (the dropped unknown may have dragged others along a nearly flat valley
    of the first fit: real UR10 data, plain DH, a5 +143 mm).  Not after an unconverged
    fit (its σ say nothing) nor a bounded one (its bounds keep every unknown in range)."""
    pruning = run.options.pruning
    if not run.fit.success or run.method == "bounded":
        return
    for _ in range(len(run.x) - 1):
        std = run.covariance[2]
        found = poorly_identifiable(
            std, run.problem.effect_scale(run.x), pruning.max_std, pruning.max_std_ratio
        )
        if found is None:
            return
        worst, sigma = found
        names = run.problem.free_names
        run.dropped.append(Dropped(names[worst], "poorly identifiable", sigma=sigma))
        run.problem = run.problem.fix([names[worst]])
        run.x0 = run.x0[np.arange(len(run.x)) != worst]
        _solve(run, run.x0)


def _hold_effects(run: _Run) -> None:
    """Joint effects are physical (≥ 0) and identified only when the data tells them from
    zero: the others are held at their start values and the fit repeated from the
    linearised solution with them held (:func:`effects_to_hold`)."""
    for _ in range(run.problem.n_effects if run.fit.success else 0):
        problem = run.problem
        if not problem.n_effects:
            return
        names = problem.free_names
        held_at = dict(zip(problem.effect_names, problem.effect_start.tolist(), strict=True))
        peaks = dict(zip(problem.effect_names, np.abs(problem.effect_basis).max(axis=(1, 2, 3)), strict=True))
        x_held, verdicts = effects_to_hold(names, run.x, run.covariance[1], held_at, peaks)
        if not verdicts:
            return
        run.dropped += verdicts
        held = {v.name for v in verdicts}
        keep = np.array([name not in held for name in names], dtype=bool)
        run.problem = problem.fix([v.name for v in verdicts])
        run.x0, x_start = run.x0[keep], x_held[keep]
        if run.method == "bounded":
            run.solver["bounds"] = tuple(b[keep] for b in run.solver["bounds"])
            x_start = np.clip(x_start, *run.solver["bounds"])
        _solve(run, x_start)


# ---------------------------------------------------------------------- 7. the result
def _calibrated_models(run: _Run) -> tuple[Model, Model, Array]:
    """The calibrated measurement chain, the calibrated robot (tool appended, the given
    model's free flags) and ``T_device_base`` (4x4)."""
    chain = run.problem.chain
    values = run.problem.values(run.x)
    calibrated_chain = chain.with_values(dict(zip(chain.names, values, strict=True)))
    frame_names = {s.name for s in chain.steps if s.name.startswith(("frame0_", FRAME_PREFIX))}
    frame_steps_ = calibrated_chain.steps[: len(frame_names)]  # the frame steps come first
    T_device_base = spatial.chain_product([s.motion for s in frame_steps_], [s.value for s in frame_steps_])
    free_before = {s.name: s.free for s in run.given_model.steps}
    robot_steps = tuple(
        s if s.free == free_before.get(s.name, True) else dataclasses.replace(s, free=not s.free)
        for s in calibrated_chain.steps
        if s.name not in frame_names
    )
    given = run.given_model
    calibrated = dataclasses.replace(given, steps=robot_steps, notes=(given.notes + " calibrated").strip())
    if run.plan.mode == "none":
        calibrated = dataclasses.replace(calibrated, joint_effects=())
    elif run.plan.kinds:
        from robocal.model.joints import effects_from_values

        estimated = dict(zip(run.problem.free_names, run.x, strict=True))
        pairs = zip(run.effect_names, run.effect_kinds, run.effect_start, strict=True)
        effect_values = {pair: estimated.get(c, s0) for c, pair, s0 in pairs}
        calibrated = dataclasses.replace(
            calibrated, joint_effects=effects_from_values(run.model, effect_values)
        )
    return calibrated_chain, calibrated, T_device_base


def _assemble(run: _Run, t_start: float) -> CalibrationResult:
    """The frozen result of this pass (warnings and diagnostics added by :func:`diagnose`)."""
    problem, x, n = run.problem, run.x, run.data.n
    names = problem.free_names
    r_plain = problem.residual(x, weighted=False).reshape(n, problem.rows)
    r_start = problem.residual(run.x0, weighted=False).reshape(n, problem.rows)
    _, cov, std, corr, cond = run.covariance
    chain, calibrated, T_device_base = _calibrated_models(run)
    effects = run.options.joint_effects
    level = run.level if run.level is not None else (3 if run.plan.mode != "none" else 2)
    return CalibrationResult(
        model=calibrated, T_device_base=T_device_base, measure=run.measure, method=run.method,
        names=names, estimates=x, nominal=run.x0, std=std, covariance=cov, correlation=corr,
        dropped=tuple(run.dropped),
        residual_std=float(np.sqrt(np.sum(r_plain[:, :3] ** 2) / max(3 * n - len(x), 1))),
        rms_before=float(np.sqrt(np.mean(np.sum(r_start[:, :3] ** 2, axis=1)))),
        rms_after=float(np.sqrt(np.mean(np.sum(r_plain[:, :3] ** 2, axis=1)))),
        condition_number=cond, n=n, success=run.fit.success, message=run.fit.message,
        iterations=run.fit.iterations, seconds=time.perf_counter() - t_start, measurement_chain=chain,
        compliance={
            name.removeprefix(COMPLIANCE_PREFIX): float(v)
            for name, v in zip(names, x, strict=True)
            if name.startswith(COMPLIANCE_PREFIX)
        },
        gravity=effects.gravity, payload=effects.payload, residuals=r_plain,
        diagnostics=Diagnostics(solve_seconds=run.solve_seconds, evaluations=run.evaluations, level=level,
                                effects=run.plan.mode),
    )  # fmt: skip


# ---------------------------------------------------------------------- the sequence
def _calibrate_once(
    run: _Run, load_model: Model | None, hold: dict | None, t_start: float
) -> CalibrationResult:
    """Stages 2-8 for the joint loads of ``load_model``'s geometry."""
    _build_problem(run, load_model)
    _identifiable(run, hold)
    _screen(run)
    _solve(run, run.x0)
    _prune(run)
    _hold_effects(run)
    result = _assemble(run, t_start)
    bounds = run.solver.get("bounds") if run.method == "bounded" else None
    at_bounds = None if bounds is None else parameters_at_bounds(result.names, run.x, *bounds)
    return diagnose(result, run.problem, run.data, run.warnings, run.known_noise, run.options.loss.loss,
                    run.x0, at_bounds, run.orientation_hint)  # fmt: skip


def calibrate_physics(
    model: Model,
    data: Measurements,
    method: str = "lm",
    options: CalibrationOptions | None = None,
    *,
    hold_effects: dict[str, str | Dropped] | None = None,
    **keywords: Any,
) -> CalibrationResult:
    """Identify the physical robot's parameters (geometry and joint effects) from
    measurements; :func:`robocal.calibrate` documents the options and adds the learned
    residual.

    Args:
        model, data, method: as :func:`robocal.calibrate`.
        options: the settings (:class:`~robocal.identify.options.CalibrationOptions`),
            changed by ``keywords`` (its groups or their fields by plain name; an unknown
            one is an error).
        hold_effects: joint-effect coefficients kept at their start values and not
            identified, with the reason reported in ``dropped`` (the learned residual's
            stage holds those it confounds).
    """
    t_start = time.perf_counter()
    options = CalibrationOptions.from_keywords(options, **keywords)
    run = _check_inputs(model, data, method, options, hold_effects)
    if run.plan.mode != "none" and options.joint_effects.load_passes > 1:
        return _with_load_passes(run, hold_effects, t_start)
    return _calibrate_once(run, None, hold_effects, t_start)


# ---------------------------------------------------------------------- joint-effect load passes
def _load_signs(run: _Run, geometry: Model) -> NDArray[np.int8]:
    from robocal.model.joints import DEADBAND, load_moments

    e = run.options.joint_effects
    eta = load_moments(geometry, run.data.q, e.velocities, e.accelerations, gravity=np.asarray(e.gravity),
                       payload=e.payload)  # fmt: skip
    return np.where(np.abs(eta) > DEADBAND, np.sign(eta), 0).astype(np.int8)


def _geometry_of(result: CalibrationResult, model: Model) -> Model:
    """``model`` with the calibrated values of its own parameters (the tool steps the
    calibration appended left out): the geometry for the joint loads."""
    calibrated = dict(zip(result.model.names, result.model.values.tolist(), strict=True))
    return model.with_values({n: calibrated[n] for n in model.names if n in calibrated})


def _with_load_passes(run: _Run, hold: dict | None, t_start: float) -> CalibrationResult:
    """Calibrate, then recompute the joint loads with the calibrated geometry and
    calibrate again, until the loads' signs stop changing (at most ``load_passes``):
    near a load's sign change the nominal geometry can predict the wrong side of the
    backlash at a few poses (Katana 450: 31 of 118 poses, up to 0.4 mm)."""
    model = run.given_model
    signs = _load_signs(run, model)
    fresh = dataclasses.replace(run, warnings=list(run.warnings))
    result = _calibrate_once(fresh, model, hold, t_start)
    done = 1
    while done < run.options.joint_effects.load_passes:
        geometry = _geometry_of(result, model)
        new_signs = _load_signs(run, geometry)
        if np.array_equal(new_signs, signs):
            break
        signs = new_signs
        fresh = dataclasses.replace(run, warnings=list(run.warnings))
        result = _calibrate_once(fresh, geometry, hold, t_start)
        done += 1
    return result.with_diagnostics(load_passes=done).replace(seconds=time.perf_counter() - t_start)
