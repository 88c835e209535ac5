"""Calibrate from constraint measurements (:mod:`robocal.identify.constraints.model`).

The engine's stages on a :class:`~robocal.identify.constraints.model.ConstraintProblem`: start
values (the points at the nominal tool points' centroids, the planes by a least-squares
fit to them, the device frame by Kabsch when a tracker measured some poses), the
identifiable set by the sequential rank test (the scene's unknowns kept first, then the
device frame, the tool, the robot in chain order), screening, the Levenberg-Marquardt
fit, pruning of poorly identifiable unknowns and the covariance σ̂²(JᵀJ)⁻¹
(:mod:`robocal.identify.stages`, :mod:`robocal.identify.solvers`).  The compiled fused
kernels do not apply: the problem evaluates through numpy (the chain's compiled
evaluation, the constraint rows in numpy).

:func:`constraint_figures` judges any model on any constraint data (held-out
placements): the spread of the tool point around each point's centroid, the error of
each known distance, the plane residual.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from robocal.identify.constraints.effect_groups import held_for, held_groups
from robocal.identify.constraints.figures import (
    ConstraintFigures,
    constraint_figures,
    robot_and_tool,
    start_planes,
    tool_points,
)
from robocal.identify.constraints.model import ConstraintProblem, NominalPrior
from robocal.identify.constraints.noise import weigh_by_kind
from robocal.identify.constraints.position_effects import (
    position_effects,
    stated_effects,
    stated_kinds,
    with_position_effects,
)
from robocal.identify.constraints.scale import scale_anchor, scale_note
from robocal.identify.constraints.tilt_record import TiltCalibration, effect_summary_lines, tilt_estimates
from robocal.identify.constraints.tilt_rows import (
    EFFECT_KINDS,
    fixed_tilt_hints,
    fixed_tilt_note,
    mixed_effects_note,
    tilt_rows,
    tilt_terms,
    unclear_contact,
)
from robocal.identify.options import Pruning
from robocal.identify.problem import measurement_chain
from robocal.identify.solvers import solve
from robocal.identify.stages import (
    initial_frames_and_tools,
    poorly_identifiable,
    preference_order,
    robot_sizes,
    screen_unidentifiable,
    uncertainty,
)
from robocal.measure.constraints.data_set import ConstraintSet
from robocal.measure.constraints.mounts import mounts_in
from robocal.model.chain import Model
from robocal.model.joints import effect_of
from robocal.model.rank import Dropped, identifiable_subset
from robocal.model.steps import Role

__all__ = [
    "ConstraintFigures",
    "ConstraintResult",
    "calibrate_constraints",
    "constraint_figures",
    "tool_points",
]

Array = NDArray[np.float64]


@dataclass(frozen=True)
class ConstraintResult:
    """A calibration from constraint measurements.

    Attributes:
        model: the calibrated robot (the given model's parameters at their estimates).
        tool: ``(3,)`` the tool point on the model's end (m) when one was fitted, else None.
        T_device_base: ``(4, 4)`` the device frame (identity without tracker rows).
        names, estimates, start, std: the unknowns kept, their values, start values and σ.
        covariance, correlation: ``(p, p)``.
        dropped: what was not identified, and why (never invented: held at the start).
        identifiable: the names the rank test kept before pruning.
        points: ``(K, 3)`` the fixed points (m). planes: ``(P, 4)`` normal and offset (m).
        rms_before, rms_after: RMS of the position rows (m) at the start and after (rad
            for inclinometer readings alone; a stated distance is in ``figures``).
        residual_std: σ̂ of the tool point (m; a reading's, rad, for readings alone).
        kinds: the measurement kinds used.
        prior: the prior toward the nominal geometry the fit used (None: a least-squares fit).
        kind_sigma: mixed data: the noise (m) each kind was weighted by, ``(("point", σ),
            ("tracker", σ_t))`` (estimated unless ``known_noise``); empty for one kind.
        notes: sentences on what the fit left out or could not model (tilt rows whose
            contact side is unknown, joint effects seen by the tilt rows only).
        tilt: the joint effects and channel zeros identified from tilt rows and the joint
            effects the position rows' deflections identified (None without either).
        position_effects: the joint effects fitted on the position rows (names; the
            calibrated ``model`` carries them in ``joint_effects``).
    """

    model: Model
    tool: Array | None
    T_device_base: Array
    names: tuple[str, ...]
    estimates: Array
    start: Array
    std: Array
    covariance: Array
    correlation: Array
    dropped: tuple[Dropped, ...]
    identifiable: tuple[str, ...]
    points: Array
    planes: Array
    rms_before: float
    rms_after: float
    residual_std: float
    success: bool
    message: str
    kinds: tuple[str, ...]
    figures: ConstraintFigures | None = field(default=None)
    prior: NominalPrior | None = field(default=None)
    kind_sigma: tuple[tuple[str, float], ...] = ()
    notes: tuple[str, ...] = ()
    tilt: TiltCalibration | None = None
    position_effects: tuple[str, ...] = ()

    def summary_lines(self) -> list[str]:
        """A short human summary (mm, deg)."""
        robot = [n for n in self.names if not n.startswith(("point", "plane"))]
        scale, unit, digits = (180 / math.pi, "deg", 5) if self.kinds == ("tilt",) else (1e3, "mm", 3)
        lines = [
            f"measurements: {', '.join(self.kinds)}; "
            f"fit {'converged' if self.success else 'FAILED: ' + self.message}",
            f"identified ({len(robot)}): {', '.join(robot) or '-'}",
            f"residual: {self.rms_before * scale:.{digits}f} {unit} -> {self.rms_after * scale:.{digits}f} "
            f"{unit} RMS (sigma-hat {self.residual_std * scale:.{digits}f} {unit})",
        ]
        if self.prior is not None:
            lines.append(self.prior.line())
        if self.kind_sigma:
            each = ", ".join(
                f"{kind} {math.degrees(sigma):.5f} deg" if kind == "tilt" else f"{kind} {sigma * 1e3:.4f} mm"
                for kind, sigma in self.kind_sigma
            )
            lines.append(f"noise per kind (the rows' weights): {each}")
        scene = {"redundant", "no effect"}
        seen = [d.name for d in self.dropped if d.reason in scene]
        if seen:
            lines.append(f"not identifiable from these measurements ({len(seen)}): {', '.join(seen)}")
        poor = [d.name for d in self.dropped if d.reason not in scene]
        if poor:
            lines.append(f"poorly identifiable, held at the start value ({len(poor)}): {', '.join(poor)}")
        for k, c in enumerate(self.points):
            lines.append(f"point {k}: ({c[0] * 1e3:.3f}, {c[1] * 1e3:.3f}, {c[2] * 1e3:.3f}) mm")
        for k, p in enumerate(self.planes):
            lines.append(
                f"plane {k}: normal ({p[0]:.5f}, {p[1]:.5f}, {p[2]:.5f}), offset {p[3] * 1e3:.3f} mm"
            )
        if self.tilt is not None:
            held = [(d.name, f"{d.reason}: {d.detail}" if d.detail else d.reason) for d in self.dropped]
            lines += effect_summary_lines(self.tilt, held, self._effect_source())
        if self.figures is not None:
            lines += self.figures.lines()
        return lines + [f"note: {note}" for note in self.notes]

    def _effect_source(self) -> str:
        """What identified the joint effects, as the summary says it."""
        deflected = "the position rows' deflections"
        if not self.position_effects:
            return "the tilt rows"
        return f"the tilt rows and {deflected}" if "tilt" in self.kinds else deflected


# ---------------------------------------------------------------------- start values
def _start_frame(robot: Model, data: ConstraintSet, tool: Array | None) -> tuple[Array, bool]:
    """``T_device_base`` from the tracker rows by Kabsch (identity without), and whether to fit it."""
    tracked = data.tracked
    if tracked.sum() < 3:
        return np.eye(4), False
    T_flange = robot.fk(data.q[tracked])
    T_tool = np.eye(4)
    if tool is not None:
        T_tool[:3, 3] = tool
    T_frame, _ = initial_frames_and_tools(T_flange[None], data.positions[tracked][None], T_tool=T_tool,
                                          fit_frame=True, fit_tool=False)  # fmt: skip
    return T_frame[0], True


def build_constraint_problem(
    robot: Model,
    data: ConstraintSet,
    tool: Array | None = None,
    prior: NominalPrior | None = None,
    tilt_kinds: tuple[str, ...] = EFFECT_KINDS, frames: Model | None = None, effects: tuple[str, ...] = (),
) -> ConstraintProblem:  # fmt: skip
    """The problem at its start values; ``tool``: a tool point (m) on the robot's end fitted
    with it (None: the robot's end); ``prior``, ``frames``, ``effects``: as
    :func:`calibrate_constraints`'."""
    if data.q.shape[1] != robot.dof:
        raise ValueError(
            f"the data has {data.q.shape[1]} joint columns but model {robot.name!r} has {robot.dof} joints"
        )
    data = mounts_in(data, robot)  # sensors stated at home: in this chain's frames, from its start
    T_frame, fit_frame = _start_frame(robot, data, tool)
    T_tool = None
    if tool is not None:
        T_tool = np.eye(4)
        T_tool[:3, 3] = tool
    chain = measurement_chain(robot, T_frame, T_tool, "position", fit_frame)  # T_tool None: no tool
    p = chain.fk(data.q)[:, :3, 3]
    points = np.array([p[data.point == k].mean(axis=0) for k in range(data.n_points)]).reshape(-1, 3)
    planes = start_planes(p, data)
    unknown = [k for k in range(data.n_planes) if data.unknown_plane(k)]
    plane_start = np.array([[0.0, 0.0, planes[k, 3]] for k in unknown]).reshape(-1)
    full0 = np.concatenate([chain.free_values, points.reshape(-1), plane_start])
    size = float(np.median(robot_sizes(robot.fk(data.q)[None])))
    weights = None if prior is None else prior.weights(chain, robot.names)
    # the joints' deflections on the position rows; loads about the robot's own joint
    # origins, as constraint_figures predicts them from the calibrated model
    kinds = effects or stated_kinds(robot, data)  # the model's own compliances predict the rows
    position = position_effects(robot, chain, data.q, kinds) if kinds else None
    n_position = 0 if position is None else len(position.names)
    if not data.tilted.any():
        full0 = np.concatenate([full0, np.zeros(n_position)])
        problem = ConstraintProblem(chain, data, full0, planes, max(size, 1e-3), weights, None, position)
        return _stated_start(problem, robot)
    terms = tilt_terms(robot, chain, data, tilt_kinds, frames)
    empty = np.zeros(len(terms.zeros))
    values = dict(zip(chain.free_names, chain.free_values.tolist(), strict=True))
    r = tilt_rows(terms, data, values, empty, np.zeros(len(terms.effects)))[0]
    zeros = np.array([-r[terms.channel == k].mean() for k in range(len(empty))])  # each channel's mean
    shared = 0 if position is None else sum(n in terms.effects for n in position.names)
    full0 = np.concatenate([full0, zeros, np.zeros(len(terms.effects) + n_position - shared)])
    problem = ConstraintProblem(chain, data, full0, planes, max(size, 1e-3), weights, terms, position)
    return _stated_start(problem, robot)


def _stated_start(problem: ConstraintProblem, robot: Model) -> ConstraintProblem:
    """The position rows' joint effects start at the robot's own values (the tilt rows' own
    unknowns at zero, as before)."""
    shared = set(() if problem.tilt is None else problem.tilt.effects)
    for name, value in stated_effects(robot).items():
        if name in problem.position_names and name not in shared:
            problem.full0[problem.all_names.index(name)] = value
    return problem


# ---------------------------------------------------------------------- the fit
def _robot_columns(problem: ConstraintProblem) -> NDArray[np.bool_]:
    """Which unknowns are the chain's (pruned when poorly determined; the scene's never are:
    a point or a plane the data touches is what the constraint is about)."""
    scene = set(problem.scene_names)
    return np.array([n not in scene for n in problem.free_names], dtype=bool)


def _prune(problem: ConstraintProblem, x: Array, cov: tuple, pruning: Pruning, dropped: list[Dropped],
           known_noise: bool):  # fmt: skip
    """Fix the worst poorly identifiable chain unknown and refit, until none is left."""
    fit = None
    for _ in range(len(x) - 1):
        robot = np.flatnonzero(_robot_columns(problem))
        scale = problem.effect_scale(x)[robot]
        found = poorly_identifiable(cov[2][robot], scale, pruning.max_std, pruning.max_std_ratio)
        if found is None:
            break
        worst, sigma, names = int(robot[found[0]]), found[1], list(problem.free_names)
        hints = fixed_tilt_hints(problem.tilt, problem.data)  # what poses would separate a clearance
        held, records = held_for(names, worst, sigma, cov[1], problem.effect_scale(x), pruning.max_std,
                                 _robot_columns(problem), hints)  # fmt: skip
        dropped += records  # effects told apart by none: all held; the geometry before the effects
        problem = problem.fix([names[k] for k in held])
        fit = solve(problem, problem.x0, "lm")
        x = fit.x
        cov = uncertainty(problem.residual(x), problem.jacobian(x), 3, known_noise)
    return problem, x, cov, fit


def _screen(problem: ConstraintProblem, pruning: Pruning, known_noise: bool, dropped: list[Dropped]):
    """The hopeless chain unknowns, fixed before the fit (:func:`screen_unidentifiable`)."""
    x0 = problem.x0
    found = screen_unidentifiable(problem.residual(x0), problem.jacobian(x0), problem.effect_scale(x0),
                                  pruning.max_std, pruning.max_std_ratio,
                                  known_noise=known_noise)  # fmt: skip
    robot = _robot_columns(problem)
    found = [(c, s) for c, s in found if robot[c]]
    cov = uncertainty(problem.residual(x0), problem.jacobian(x0), 3, known_noise)[1] if found else None
    held = held_groups(list(problem.free_names), found, cov, problem.effect_scale(x0), pruning.max_std,
                       robot, fixed_tilt_hints(problem.tilt, problem.data))  # fmt: skip
    dropped += held
    return problem.fix([d.name for d in held])


def identifiable(problem: ConstraintProblem, last: str | None = None):
    """The rank test (scene unknowns first, then the device frame, the tool, the robot) on
    the Jacobian at consistent data (:meth:`ConstraintProblem.consistent_jacobian`);
    ``last``: a parameter tested after all others (held if anything it shares is kept:
    :func:`~robocal.identify.constraints.scale.scale_anchor`)."""
    J = problem.consistent_jacobian(problem.x0) * problem.free_scale
    J = J[: len(J) - problem.n_prior_rows]  # what the measurements see, not the prior
    prefer = preference_order(problem.free_names, problem.roles)
    if last in prefer:
        prefer = [n for n in prefer if n != last] + [last]
    return identifiable_subset(J, problem.free_names, order="preference", prefer=prefer)


def calibrate_constraints(  # noqa: PLR0913 - keyword-only options of the one constraint fit
    model: Model,
    data: ConstraintSet,
    *,
    tool: Array | None = None,
    level: int = 2,
    fixed: tuple[str, ...] = (),
    pruning: Pruning | None = None,
    known_noise: bool = False,
    prior: NominalPrior | None = None,
    tilt_kinds: tuple[str, ...] = EFFECT_KINDS, frames: Model | None = None,
    effects: tuple[str, ...] = (),
) -> ConstraintResult:  # fmt: skip
    """Identify the robot (and the points, planes, device frame) from constraint data.

    Args:
        model: the robot; its free parameters are the candidates.
        data: the constraint measurements.
        tool: a tool point (m) on the model's end fitted with the robot, or None.
        level: 1 identifies the joint offsets only, 2 every free geometric parameter.
        fixed: parameters held at their values.
        pruning: the pruning thresholds (None: no pruning beyond the rank test).
        known_noise: the covariance uses ``data.sigma`` (and ``data.tracker_sigma`` for the
            tracker rows) as the noise; else σ̂ from the residuals, each kind's own when the
            data mixes tracker rows with constraint rows
            (:func:`robocal.identify.constraints.noise.weigh_by_kind`).
        prior: a prior of the robot's geometry about the model's values (a MAP fit; the
            rank test still drops what the measurements cannot see; pruning judges the
            posterior σ).  The measurements are weighted by their noise: ``data.sigma``
            with ``known_noise``, else σ̂ of a least-squares fit first (a stated σ ten
            times the real one would make the prior ten times too strong).  None: least
            squares.
        tilt_kinds: the joint effects the tilt rows identify (``ALL_KINDS`` adds clearance).
        frames: the robot's own chain, the effects' moment points (tilt_rows.loads_about).
        effects: the joint effects every position row carries (``("compliance",)``,
            ``"radial"``: :mod:`robocal.identify.constraints.position_effects`); needs the
            model's link masses.  The calibrated model carries them in ``joint_effects``.
    """
    if level == 1:
        model = model.fixed([s.name for s in model.steps if s.joint is None])
    if fixed:
        model = model.fixed(fixed)
    data, notes = _clear_rows(model, data)
    problem = build_constraint_problem(model, data, tool, prior, tilt_kinds, frames, effects)
    if not effects:  # a model's stated compliances are held: they predict, they are not fitted
        shared = () if problem.tilt is None else problem.tilt.effects
        problem = problem.fix([n for n in problem.position_names if n not in shared])
    anchor = scale_anchor(model, data)  # no length measured: the scale held on the longest length
    selection = identifiable(problem, last=anchor)
    dropped = list(selection.dropped)
    problem = problem.fix(selection.dropped_names)
    mixed = sum((bool(data.constrained.any()), "tracker" in data.kinds, "tilt" in data.kinds)) > 1
    if not known_noise and (prior is not None or mixed):  # each kind weighted by its own σ̂
        problem = problem.with_data(weigh_by_kind(problem))
    if pruning is not None:
        problem = _screen(problem, pruning, known_noise, dropped)
    fit = solve(problem, problem.x0, "lm")
    x = fit.x
    cov = uncertainty(problem.residual(x), problem.jacobian(x), 3, known_noise)
    if pruning is not None:
        problem, x, cov, refit = _prune(problem, x, cov, pruning, dropped, known_noise)
        fit = refit or fit
    result = _result(problem, model, x, cov, fit, dropped, selection.kept, tool is not None)
    found = tuple(n for n in result.names if effect_of(n) is not None and n not in problem.position_names)
    notes += [note] if (note := mixed_effects_note(data, found)) else []
    held = {d.name for d in dropped}  # a clearance held as a fixed tilt: which poses would identify it
    notes += [note] if (note := fixed_tilt_note(problem.tilt, problem.data, held)) else []
    if anchor is not None:
        notes.append(scale_note(anchor, anchor in held))
    return dataclasses.replace(result, prior=prior, notes=tuple(notes))


def _clear_rows(model: Model, data: ConstraintSet) -> tuple[ConstraintSet, list[str]]:
    """``data`` without the tilt rows whose contact side is unknown
    (:func:`~robocal.identify.constraints.tilt_rows.unclear_contact`), and a note saying
    how many were left out.  Refuses when no tilt row is left."""
    unclear = unclear_contact(model, data)
    if not unclear.any():
        return data, []
    if unclear.sum() == data.tilted.sum():
        raise ValueError(
            "every tilt row has a joint whose load moment is near zero (its clearance or backlash "
            "could act either way); read at configurations whose moments are clearly on one side"
        )
    note = (
        f"{int(unclear.sum())} of {int(data.tilted.sum())} tilt rows left out: a joint's load moment "
        "is near zero there, so the side its clearance or backlash acts on is not known"
    )
    return data.select(~unclear), [note]


def _result(problem, model, x, cov, fit, dropped, kept, has_tool) -> ConstraintResult:
    chain = problem.chain
    full = problem.full(x)
    calibrated_chain = chain.with_free_values(full[: problem.layout.n_chain])
    values = dict(zip(calibrated_chain.names, calibrated_chain.values.tolist(), strict=True))
    deflect = {n: float(full[problem.all_names.index(n)]) for n in problem.position_names}
    robot = with_position_effects(model.with_values({n: values[n] for n in model.names}), deflect)
    tool = np.array([values[f"tcp_{c}"] for c in "xyz"]) if has_tool else None
    T_frame = chain.with_free_values(full[: problem.layout.n_chain]).fk(np.zeros((1, model.dof)))[0]
    T_frame = T_frame @ np.linalg.inv(robot_and_tool(robot, tool).fk(np.zeros((1, model.dof)))[0])
    r = problem.measurement_residual(x)
    tilt_only = problem.data.kinds == ("tilt",)  # the figures in rad, not m
    sigma = problem.data.tilt_sigma if tilt_only else problem.data.sigma
    dof = max(len(r) - len(x), 1)
    tilt = None
    fitted = tuple(n for n in problem.position_names if n in problem.free_names)
    if problem.tilt is not None or fitted:  # the effects and zeros, as saved and as the figures use them
        tilt = tilt_estimates(
            problem.all_names, problem.full(x), dict(zip(problem.free_names, cov[2], strict=True))
        )
    figures = constraint_figures(robot, problem.data, tool, T_frame, tilt)
    return ConstraintResult(
        model=robot, tool=tool, T_device_base=T_frame, names=problem.free_names, estimates=x,
        start=problem.x0, std=cov[2], covariance=cov[1], correlation=cov[3], dropped=tuple(dropped),
        identifiable=tuple(kept), points=problem.points(x), planes=problem.plane_values(x),
        rms_before=_rms_in_units(problem, problem.x0, tilt_only),
        rms_after=_rms_in_units(problem, x, tilt_only),
        residual_std=sigma * math.sqrt(float(r @ r) / dof), success=bool(fit.success),
        message=str(fit.message),
        kinds=problem.data.kinds, figures=figures, kind_sigma=_kind_sigma(problem.data), tilt=tilt,
        position_effects=fitted,
    )  # fmt: skip


def _rms_in_units(problem, x: Array, tilt_only: bool) -> float:
    """RMS of the measurement rows in their own unit (m; rad for inclinometer readings alone).

    The position rows (points, planes, pairs, tracker) when there are any, else the tilt
    rows.  A stated distance between fixed points is not among them: it is held to
    ``distance_sigma`` (1 µm), and its row weighted and scaled back by the points' σ read
    σ/distance_sigma times its error (a Gen3 lite's start printed as 178 mm against a 5 mm
    spread); the figures report the distance on its own.
    """
    r = problem.residual(x, weighted=False)
    groups = ("tilt",) if tilt_only else ("constraint", "pair", "tracker")
    rows = [r[s] for name, s in problem.row_groups() if name in groups]
    if not rows:  # e.g. tilt rows mixed only with a stated distance: the weighted figure
        w = problem.measurement_residual(x)
        return float(problem.data.sigma * math.sqrt(float(w @ w) / len(w)))
    kept = np.concatenate(rows)
    return float(math.sqrt(float(kept @ kept) / len(kept)))


def _kind_sigma(data: ConstraintSet) -> tuple[tuple[str, float], ...]:
    """Each noise group's σ (m; rad for tilt) when the data mixes groups, else empty."""
    constraint = "+".join(k for k in data.kinds if k not in ("tracker", "tilt"))
    groups = [(constraint, float(data.sigma))] if data.constrained.any() else []
    groups += [("tracker", data.position_sigma)] if "tracker" in data.kinds else []
    groups += [("tilt", float(data.tilt_sigma))] if "tilt" in data.kinds else []
    return tuple(groups) if len(groups) > 1 else ()


def kind_identifiable(
    robot: Model, data: ConstraintSet, tool: Array | None = None
) -> tuple[tuple[str, ...], tuple[Dropped, ...]]:
    """The identifiable set of ``robot``'s parameters from ``data`` (rank test at the start
    values): the kept robot parameters and what was dropped."""
    problem = build_constraint_problem(robot, _clear_rows(robot, data)[0], tool)
    selection = identifiable(problem.fix(problem.position_names))  # stated compliances: held
    roles = problem.chain.roles
    kept = tuple(n for n in selection.kept if roles.get(n) not in (Role.DEVICE,) and n in roles)
    return kept, selection.dropped
