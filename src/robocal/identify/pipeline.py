"""The physical calibration as a sequence of named stages (:func:`calibrate_physics`).

1. :func:`_check_inputs` — the method, the data, the model (guards of
   :mod:`robocal.identify.guards`: bad data is refused before any fit);
2. start values — device frame and tool by closed-form fits
   (:func:`robocal.identify.stages.initial_frames_and_tools`), and
3. the problem — the measurement chain, row weights and joint-effect patterns
   (:func:`robocal.identify.problem_setup.build_problem`);
4. :func:`_identifiable` — the identifiable set by the sequential rank test, and the
   rank guard;
5. :func:`_screen` — unknowns the data leaves hopeless, fixed before the first fit;
6. :func:`_solve` — the solver (:mod:`robocal.identify.solvers`), then :func:`_prune`
   (poorly identifiable unknowns fixed and the fit repeated) and :func:`_hold_effects`
   (joint effects not ≥ 3σ above zero held);
7. :func:`_assemble` — the calibrated model, device frame and residuals;
8. :func:`robocal.identify.diagnose.diagnose` — warnings, fit-to-noise, the solution guard.

Joint-effect load passes (:func:`_with_load_passes`) repeat 2-8 with the joint loads of
the calibrated geometry.  The residual model (:func:`robocal.calibrate` with
``residual=...``) and the uncertainty of the learned residual are stages of
:mod:`robocal.identify.residual.stage` around this one.  Units: SI (m, rad).
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from robocal.identify import fused
from robocal.identify.bounds import bounded_method_bounds, parameters_at_bounds
from robocal.identify.diagnose import diagnose, parameterisation_warnings
from robocal.identify.effects import effect_plan, effects_to_hold
from robocal.identify.guards import check_data, check_rank
from robocal.identify.kernel_cache import work_clock
from robocal.identify.options import CalibrationOptions
from robocal.identify.problem import Problem
from robocal.identify.problem_setup import (
    LEVELS,
    Fit,
    Run,
    Selection,
    Start,
    build_problem,
    parse_level,
    without_measured_tool,
)
from robocal.identify.result import CalibrationResult, Diagnostics
from robocal.identify.rules import Rules
from robocal.identify.solvers import METHODS, solve
from robocal.identify.stages import (
    fit_selection,
    identifiable_set,
    poorly_identifiable,
    screen_unidentifiable,
    uncertainty,
)
from robocal.measure.measurements import Measurements
from robocal.model.chain import Model
from robocal.model.chain_plan import derived_copy
from robocal.model.joints import effect_of
from robocal.model.rank import Dropped, IdentifiableSubset
from robocal.model.steps import Step

__all__ = ["LEVELS", "calibrate_physics", "parse_level", "without_measured_tool"]

Array = NDArray[np.float64]


# ---------------------------------------------------------------------- 1. checks
def _check_inputs(
    model: Model, data: Measurements, method: str, options: CalibrationOptions, hold: dict | None
) -> Run:
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
    run = Run(model, model, data, method, options, measure, effect_plan(model, level, effects.effects,
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


# ---------------------------------------------------------------------- 4. identifiable set
def _identifiable(run: Run, start: Start, hold: dict | None) -> Selection:
    """The identifiable set, preferring the frame, then the tool, then the robot in chain
    order (one factorisation of the scaled Jacobian at the start values); the rank guard;
    joint effects the caller holds."""
    problem = start.problem
    subset = identifiable_set(problem.scaled_jacobian(problem.x0), problem.free_names,
                              roles=problem.chain.roles)  # fmt: skip
    _rank_guard(run, subset, problem.free_names)
    selection = _fix_unidentifiable(problem, subset, hold)
    return dataclasses.replace(
        selection, solver=_solver_options(run, start, selection.problem, subset.dropped)
    )


def _rank_guard(run: Run, subset: IdentifiableSubset, candidates: Sequence[str]) -> None:
    """The rank guard's warnings (or its refusal) for the identifiable set among ``candidates``."""
    setup = run.options.setup
    for text in check_rank(run.given_model, run.data, measure=run.measure, frame=setup.frame, tool=setup.tool,
                           tool_guess=setup.tool_guess, kept=subset.kept,
                           candidates=candidates):  # fmt: skip
        run.warn("rank", text)


def _fix_unidentifiable(problem: Problem, subset: IdentifiableSubset, hold: dict | None) -> Selection:
    """``problem`` with the unidentifiable unknowns and the held joint effects fixed."""
    if subset.dropped:
        problem = problem.fix([d.name for d in subset.dropped])
    held = [
        why if isinstance(why, Dropped) else Dropped(name, "undetermined", detail=str(why))
        for name, why in (hold or {}).items()
        if name in problem.effect_names
    ]
    if held:
        problem = problem.fix([d.name for d in held])
    return Selection(problem, problem.x0, (*subset.dropped, *held))


def _solver_options(
    run: Run, start: Start, problem: Problem, rank_dropped: Sequence[Dropped]
) -> dict[str, Any]:
    """The chosen method's settings for ``problem``'s unknowns (each method takes only its own)."""
    o, method = run.options, run.method
    solver: dict[str, Any] = {"max_iterations": o.setup.max_iterations}
    if method == "lm" and o.loss.loss != "linear":  # where a robust loss starts to down-weight
        f_scale = o.loss.f_scale * float(np.median(problem.weights.reshape(run.data.n, -1)[:, :3]))
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
        lo, hi, widened = bounded_method_bounds(
            o.bounds.value, problem, list(rank_dropped), start.length, robot
        )
        if widened is not None:
            run.warn("bounds-widened", widened)
        solver["bounds"] = (lo, hi)
    return solver


# ---------------------------------------------------------------------- 5. screening
def _rules(run: Run) -> Rules:
    """The decision rules of this calibration (its pruning options)."""
    return Rules.of(run.options.pruning)


def _screen(run: Run, start: Start, selection: Selection) -> Selection:
    """The hopeless unknowns, fixed before the first fit (they would be pruned anyway);
    not for ``bounded`` (its bounds keep a poorly determined unknown from running away)."""
    if run.method == "bounded":
        return selection
    problem, x0 = selection.problem, selection.x0
    r, J = problem.residual(x0), problem.jacobian(x0)
    found = screen_unidentifiable(r, J, problem.effect_scale(x0), known_noise=start.known_noise,
                                  rules=_rules(run))  # fmt: skip
    if not found:
        return selection
    names = problem.free_names
    poor = tuple(Dropped(names[c], "poorly identifiable", sigma=sigma) for c, sigma in found)
    problem = problem.fix([names[c] for c, _ in found])
    return dataclasses.replace(selection, problem=problem, x0=problem.x0, dropped=selection.dropped + poor)


# ---------------------------------------------------------------------- 6. solve, prune, hold
def _solve(run: Run, start: Start, selection: Selection, x_start: Array, before: Fit | None = None) -> Fit:
    """One fit of ``selection`` from ``x_start`` and the uncertainty at its solution (from
    the solver's last Jacobian when it has it: no second evaluation); ``before``: the
    pass's previous fit (its evaluations and seconds are counted on)."""
    t = time.perf_counter()
    solved = solve(selection.problem, x_start, run.method, **selection.solver)
    seconds = time.perf_counter() - t
    r, J = solved.r, solved.J
    if r is None or J is None:
        r, J = selection.problem.residual(solved.x), selection.problem.jacobian(solved.x)
    covariance = uncertainty(r, J, selection.problem.rows, start.known_noise, _rules(run))
    evaluations, solve_seconds = (0, 0.0) if before is None else (before.evaluations, before.solve_seconds)
    return Fit(
        selection, solved.x, solved, covariance, evaluations + solved.evaluations, solve_seconds + seconds
    )


def _prune(run: Run, start: Start, fit: Fit) -> Fit:
    """Drop what these measurements cannot determine, worst first, and refit from the
    start values (the dropped unknown may have dragged others along a nearly flat valley
    of the first fit: real UR10 data, plain DH, a5 +143 mm).  Not after an unconverged
    fit (its σ say nothing) nor a bounded one (its bounds keep every unknown in range)."""
    rules = _rules(run)
    if not fit.solve.success or run.method == "bounded":
        return fit
    for _ in range(len(fit.x) - 1):
        selection = fit.selection
        scale = selection.problem.effect_scale(fit.x)
        found = poorly_identifiable(fit.covariance.std, scale, rules.max_std, rules.max_std_ratio)
        if found is None:
            break
        worst, sigma = found
        names = selection.problem.free_names
        pruned = dataclasses.replace(
            selection,
            problem=selection.problem.fix([names[worst]]),
            x0=selection.x0[np.arange(len(fit.x)) != worst],
            dropped=(*selection.dropped, Dropped(names[worst], "poorly identifiable", sigma=sigma)),
        )
        fit = _solve(run, start, pruned, pruned.x0, fit)
    return fit


def _hold_effects(run: Run, start: Start, fit: Fit) -> Fit:
    """Joint effects are physical (≥ 0) and identified only when the data tells them from
    zero: the others are held at their start values and the fit repeated from the
    linearised solution with them held (:func:`effects_to_hold`)."""
    for _ in range(fit.selection.problem.n_effects if fit.solve.success else 0):
        selection = fit.selection
        problem = selection.problem
        if not problem.n_effects or problem.effect_start is None or problem.effect_basis is None:
            break
        names = problem.free_names
        held_at = dict(zip(problem.effect_names, problem.effect_start.tolist(), strict=True))
        peaks = dict(zip(problem.effect_names, np.abs(problem.effect_basis).max(axis=(1, 2, 3)), strict=True))
        x_held, verdicts = effects_to_hold(names, fit.x, fit.covariance.covariance, held_at, peaks)
        if not verdicts:
            break
        held = {v.name for v in verdicts}
        keep = np.array([name not in held for name in names], dtype=bool)
        solver = dict(selection.solver)
        x_start = x_held[keep]
        if run.method == "bounded":
            solver["bounds"] = tuple(b[keep] for b in solver["bounds"])
            x_start = np.clip(x_start, *solver["bounds"])
        kept = Selection(problem.fix([v.name for v in verdicts]), selection.x0[keep],
                         (*selection.dropped, *verdicts), solver)  # fmt: skip
        fit = _solve(run, start, kept, x_start, fit)
    return fit


# ---------------------------------------------------------------------- 7. the result
def _calibrated_models(run: Run, start: Start, fit: Fit) -> tuple[Model, Model, Array]:
    """The calibrated measurement chain, the calibrated robot (tool appended, the given
    model's free flags) and ``T_device_base`` (4x4)."""
    from robocal.model import kernels  # numba: imported on first use

    problem, x = fit.selection.problem, fit.x
    chain, given = problem.chain, run.given_model
    calibrated_chain = chain.with_free_values(x[: len(x) - problem.n_effects])
    # the device frame's steps come first (0, 6 or 12 of them), then the robot's (the given
    # model's names: level 1 fixes some of them) and the tool's
    n_frame = chain._index[given.steps[0].name]
    plan = chain._plan
    T_device_base = kernels.leading_frame(calibrated_chain.values, plan.step_axis, plan.step_rot, n_frame)
    robot_steps = _with_given_free_flags(calibrated_chain, n_frame, given)
    # the given robot's checked steps with checked values, and the measured tool's
    effects = () if run.plan.mode == "none" else given.joint_effects
    notes = (given.notes + " calibrated").strip()
    calibrated = derived_copy(given, robot_steps, (), notes=notes, joint_effects=effects)
    if run.plan.mode != "none" and run.plan.kinds and start.effect_start is not None:
        from robocal.model.joints import effects_from_values

        estimated = dict(zip(problem.free_names, x, strict=True))
        pairs = zip(start.effect_names, start.effect_kinds, start.effect_start, strict=True)
        effect_values = {pair: estimated.get(c, s0) for c, pair, s0 in pairs}
        calibrated = dataclasses.replace(
            calibrated, joint_effects=effects_from_values(run.model, effect_values)
        )
    return calibrated_chain, calibrated, T_device_base


def _with_given_free_flags(chain: Model, n_frame: int, given: Model) -> tuple[Step, ...]:
    """The calibrated ``chain``'s robot and tool steps (from ``n_frame``: ``given``'s steps,
    in order, then the tool's) with ``given``'s free flags and the tool's steps free: a step
    the fit kept at its start value is ``given``'s own (no copy), a fitted one whose flag
    differs a copy.  Only the steps whose flags differ are looked at (by the free masks)."""
    steps = list(chain.steps[n_frame:])
    n = len(given.steps)
    differ = chain.free_mask[n_frame : n_frame + n] != given.free_mask
    for i in differ.nonzero()[0].tolist():
        c, g = steps[i], given.steps[i]
        steps[i] = g if c.value == g.value else c._with_free(g.free)
    for i in range(n, len(steps)):
        if not steps[i].free:
            steps[i] = steps[i]._with_free(True)
    return tuple(steps)


def _mean_square(r: Array) -> float:
    """The mean squared position error of residuals ``(n, rows)`` (m²)."""
    # position rows only: all of them (a view, the same order) or a contiguous copy
    p = r.reshape(-1) if r.shape[1] == 3 else np.ascontiguousarray(r[:, :3]).reshape(-1)
    return float(p @ p) / len(r)


def _assemble(run: Run, start: Start, fit: Fit, t_start: float) -> CalibrationResult:
    """The frozen result of this pass (warnings and diagnostics added by :func:`diagnose`)."""
    selection, x, n = fit.selection, fit.x, run.data.n
    problem = selection.problem
    names = problem.free_names
    # the fit's own unweighted residuals where it formed them (the same numbers: T - measured)
    at_x, at_start = fit.plain_residuals or (problem.residual(x, weighted=False),
                                             problem.residual(selection.x0, weighted=False))  # fmt: skip
    r_plain, r_start = at_x.reshape(n, problem.rows), at_start.reshape(n, problem.rows)
    cov = fit.covariance
    after = _mean_square(r_plain)
    chain, calibrated, T_device_base = _calibrated_models(run, start, fit)
    effects = run.options.joint_effects
    level = run.level if run.level is not None else (3 if run.plan.mode != "none" else 2)
    return CalibrationResult(
        model=calibrated, T_device_base=T_device_base, measure=run.measure, method=run.method,
        names=names, estimates=x, nominal=selection.x0, std=cov.std, covariance=cov.covariance,
        correlation=cov.correlation, dropped=selection.dropped,
        residual_std=math.sqrt(after * n / max(3 * n - len(x), 1)),
        rms_before=math.sqrt(_mean_square(r_start)), rms_after=math.sqrt(after),
        condition_number=cov.condition, n=n, success=fit.solve.success, message=fit.solve.message,
        iterations=fit.solve.iterations, seconds=work_clock() - t_start, measurement_chain=chain,
        compliance={
            effect[1]: float(v)
            for name, v in zip(problem.effect_names, x[len(x) - problem.n_effects :], strict=True)
            if (effect := effect_of(name)) is not None and effect[0] == "compliance"
        },
        gravity=effects.gravity, payload=effects.payload, residuals=r_plain,
        diagnostics=Diagnostics(solve_seconds=fit.solve_seconds, evaluations=fit.evaluations, level=level,
                                effects=run.plan.mode),
    )  # fmt: skip


# ---------------------------------------------------------------------- the sequence
def _calibrate_once(
    run: Run, load_model: Model | None, hold: dict | None, t_start: float
) -> CalibrationResult:
    """Stages 2-8 for the joint loads of ``load_model``'s geometry."""
    start = build_problem(run, load_model)
    fit = _fused(run, start, hold)
    if fit is None:
        fit = _fit_staged(run, start, _identifiable(run, start, hold))
    fit = _hold_effects(run, start, fit)
    result = _assemble(run, start, fit, t_start)
    selection = fit.selection
    bounds = selection.solver.get("bounds") if run.method == "bounded" else None
    at_bounds = None if bounds is None else parameters_at_bounds(result.names, fit.x, *bounds)
    return diagnose(result, selection.problem, run.data, run.warnings, start.known_noise,
                    run.options.loss.loss, selection.x0, at_bounds, start.orientation_hint)  # fmt: skip


def _fused(run: Run, start: Start, hold: dict | None) -> Fit | None:
    """Stages 4-6 as compiled calls (:mod:`robocal.identify.fused`) where they apply; None
    where they do not (the staged functions run them)."""
    problem = start.problem
    first = fused.rank_test(problem) if fused.applies(run, problem) else None
    if first is None:
        return None
    _rank_guard(run, first.selection, problem.free_names)
    # lm's settings: the problem does not matter
    solver = _solver_options(run, start, problem, first.selection.dropped)
    fit = fused.fit(start, first, solver, _rules(run))
    if fit is None:  # a nearly singular covariance: the staged SVD path
        selection = dataclasses.replace(_fix_unidentifiable(problem, first.selection, hold), solver=solver)
        fit = _fit_staged(run, start, selection)
    return fit


@dataclasses.dataclass(frozen=True)
class _Staged:
    """Stages 5-6 of one calibration (:class:`~robocal.identify.stages.FitStages`)."""

    run: Run
    start: Start

    def screen(self, selection: Selection) -> Selection:
        return _screen(self.run, self.start, selection)

    def solve(self, selection: Selection) -> Fit:
        return _solve(self.run, self.start, selection, selection.x0)

    def prune(self, fit: Fit) -> Fit:
        return _prune(self.run, self.start, fit)


def _fit_staged(run: Run, start: Start, selection: Selection) -> Fit:
    """Stages 5-6 by the staged functions, in :func:`~robocal.identify.stages.fit_selection`'s
    order: screening, the fit, pruning."""
    return fit_selection(_Staged(run, start), selection)


def calibrate_physics(
    model: Model,
    data: Measurements,
    method: str = "lm",
    options: CalibrationOptions | None = None,
    *,
    hold_effects: dict[str, str | Dropped] | None = None,
    load_geometry: Model | None = None,
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
        load_geometry: the geometry of the first load pass's joint loads (``model`` with
            other values of its parameters; default ``model``): the learned residual's stage
            passes a calibrated one (:func:`_with_load_passes`).
    """
    t_start = work_clock()  # stopped while numba compiles: the seconds are the calibration's
    options = CalibrationOptions.from_keywords(options, **keywords)
    run = _check_inputs(model, data, method, options, hold_effects)
    loads = None if run.plan.mode == "none" else load_geometry  # no joint effects: no loads
    if run.plan.mode != "none" and options.joint_effects.load_passes > 1:
        return _with_load_passes(run, model if loads is None else loads, hold_effects, t_start)
    return _calibrate_once(run, loads, hold_effects, t_start)


# ---------------------------------------------------------------------- joint-effect load passes
def _load_signs(run: Run, geometry: Model) -> NDArray[np.int8]:
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


def _with_load_passes(run: Run, model: Model, hold: dict | None, t_start: float) -> CalibrationResult:
    """Calibrate, then recompute the joint loads with the calibrated geometry and
    calibrate again, until the loads' signs stop changing (at most ``load_passes``):
    near a load's sign change the nominal geometry can predict the wrong side of the
    backlash at a few poses (Katana 450: 31 of 118 poses, up to 0.4 mm).  ``model``: the
    model as given, whose geometry gives the first pass's loads."""
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
    return result.with_diagnostics(load_passes=done).replace(seconds=work_clock() - t_start)
