"""The first stages of a calibration (:mod:`robocal.identify.pipeline`): the working
state of a pass (:class:`Run`), the start values of the device frame and the tool, and the
calibration problem — measurement chain, row weights, joint-effect patterns and the
perturbations known in advance.  Units: SI (m, rad)."""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, Literal, NamedTuple

import numpy as np
from numpy.typing import NDArray

from robocal import spatial
from robocal.identify.effects import EffectPlan
from robocal.identify.options import CalibrationOptions, check_load_model
from robocal.identify.problem import Problem, measurement_chain_and_preference
from robocal.identify.result import CalibrationWarning
from robocal.identify.solve_result import SolveResult
from robocal.identify.stages import Covariance, initial_frames_and_tools, robot_size
from robocal.measure.measurements import Measurements
from robocal.model.chain import Model
from robocal.model.chain_plan import read_only
from robocal.model.flange_tool import split_tool
from robocal.model.rank import Dropped
from robocal.model.steps import Role

__all__ = [
    "LEVELS",
    "Fit",
    "Run",
    "Selection",
    "Start",
    "build_problem",
    "parse_level",
    "without_measured_tool",
]

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
    its end, and their transform (4x4; None when there are none): a calibrated model's
    tool is the start value of the next calibration's (:func:`robocal.model.flange_tool.split_tool`)."""
    if model.residual is None:  # the cache's key, the model's hash, leaves a learned residual out
        try:
            return _split_tool(model)
        except TypeError:  # pragma: no cover - an unhashable model: split it every time
            pass
    parts = split_tool(model)
    return parts.robot, parts.T_flange_tool


@functools.lru_cache(maxsize=16)
def _split_tool(model: Model) -> tuple[Model, Array | None]:
    """:func:`without_measured_tool`, once per model (models are immutable and hashable; every
    calibration asks, and the measurement chain's templates hash the model anyway); the
    tool read-only."""
    parts = split_tool(model)
    T = parts.T_flange_tool
    return parts.robot, None if T is None else read_only(T)


_EYE4 = read_only(np.eye(4))  # the tool's start without a guess (the fits copy it)


def _positions(data: Measurements) -> Array:
    """The measured positions ``(n, 3)`` (m); the pipeline's checks refuse data without."""
    if data.position is None:
        raise ValueError("the measurements have no positions to calibrate against")
    return data.position


def _zeros(names: Any) -> dict[str, Any]:
    """``{name: 0.0}`` for each of ``names`` (fields for :func:`dataclasses.replace`)."""
    return dict.fromkeys(names, 0.0)


def _as_frame(value: Any) -> Array:
    """A tool or frame given as a position (3,) or a 4x4 transform, as 4x4."""
    g = np.asarray(value, dtype=float)
    return g if g.shape == (4, 4) else spatial.homogeneous(p=g)


# ---------------------------------------------------------------------- the working state
@dataclass
class Run:
    """The inputs of one pass of the pipeline, as checked (internal and short-lived; the
    stages' values are frozen: :class:`Start`, :class:`Selection`, :class:`Fit`), and the
    log of its warnings, which the stages append to."""

    given_model: Model  # the model as given (tool steps of an earlier calibration removed)
    model: Model  # its candidates (level 1: the joint offsets only)
    data: Measurements
    method: str
    options: CalibrationOptions
    measure: Literal["position", "pose"]
    plan: EffectPlan
    level: int | None
    warnings: list[CalibrationWarning] = field(default_factory=list)

    def warn(self, code: str, message: str) -> None:
        self.warnings.append(CalibrationWarning(code, message))


@dataclass(frozen=True)
class Start:
    """The calibration problem at the start values (:func:`build_problem`): ``problem``
    (measurement chain, weights, joint-effect patterns), whether the weights come from a
    stated noise (``known_noise``), the robot's size ``length`` (m, weighs rotations
    against lengths), the identified joint effects' coefficient names, ``(kind, joint)``
    pairs and start values ``(k,)``, and the orientation convention's hint (pose data whose
    rotations disagree with the model; empty otherwise)."""

    problem: Problem
    known_noise: bool
    length: float
    effect_names: tuple[str, ...] = ()
    effect_kinds: tuple[tuple[str, str], ...] = ()
    effect_start: Array | None = None
    orientation_hint: str = ""


@dataclass(frozen=True)
class Selection:
    """The unknowns of a fit: ``problem`` (its free unknowns), their start values ``x0``
    ``(p,)``, the unknowns left out so far and why, and the solver's settings for them
    (:func:`robocal.identify.solvers.solve`'s keywords)."""

    problem: Problem
    x0: Array
    dropped: tuple[Dropped, ...]
    solver: Mapping[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class Fit:
    """A fit of a :class:`Selection`: the solution ``x`` ``(p,)``, the solver's result and
    the covariance there; ``evaluations`` and ``solve_seconds``: of all fits of the pass so
    far (screening, pruning and held effects refit); ``plain_residuals``: the unweighted
    residuals ``(n * rows,)`` at ``x`` and at ``selection.x0`` where the fit formed them
    already (the compiled stages), else None (the result evaluates them)."""

    selection: Selection
    x: Array
    solve: SolveResult
    covariance: Covariance
    evaluations: int
    solve_seconds: float
    plain_residuals: tuple[Array, Array] | None = None


# ---------------------------------------------------------------------- 2. start values
def _start_values(run: Run) -> tuple[Array, Array, Array, bool]:
    """Start values of the device frame and the tool (4x4 each), the flange frames
    ``(n, 4, 4)`` at the data's joint values, and whether the frame is fitted."""
    setup, data = run.options.setup, run.data
    fit_frame = isinstance(setup.frame, str) and setup.frame == "fit"
    T_known = None
    if not isinstance(setup.frame, str):
        T_known = np.asarray(setup.frame, dtype=float)
        if T_known.shape != (4, 4):
            raise ValueError(f"frame must be 'fit', 'fixed' or a 4x4 transform, got shape {T_known.shape}")
    T_tool0 = _EYE4 if setup.tool_guess is None else _as_frame(setup.tool_guess)  # read, not written
    fit_tool = isinstance(setup.tool, str) and setup.tool == "fit"
    if setup.tool is not None and not isinstance(setup.tool, str):
        T_tool0 = _as_frame(setup.tool)
    T_flange = run.model.fk(data.q)
    orientation = data.orientation if run.measure == "pose" else None
    T_frame, T_tool = initial_frames_and_tools(
        T_flange[None],
        _positions(data)[None],
        orientation=None if orientation is None else orientation[None],
        T_tool=T_tool0,
        T_frame=T_known,
        fit_frame=fit_frame,
        fit_tool=fit_tool and setup.tool is not None,
    )
    return T_frame[0], T_tool[0], T_flange, fit_frame


# ---------------------------------------------------------------------- 3. the problem
def _row_weights(run: Run, rows: int) -> tuple[Array, bool]:
    """``(n, rows)`` weights: 1/σ of a stated noise, orientation rows by ``orientation``;
    and whether they come from a stated noise."""
    data, weights = run.data, run.options.weights
    sigma = data.sigma if weights.by == "sigma" else None
    position = np.ones((data.n, 3)) if sigma is None else 1.0 / np.maximum(sigma, 1e-12)
    if rows == 3:
        return position, sigma is not None
    w = np.empty((data.n, 6))
    w[:, :3] = position
    w[:, 3:] = weights.orientation * position.mean(axis=1, keepdims=True)
    return w, sigma is not None


class _EffectTerms(NamedTuple):
    """The joint effects of a problem (:func:`_effect_terms`)."""

    basis: Array | None  # (k, n, dof, 3) the identified effects' patterns
    known: Array | None  # (n, dof, 3) the other effects' perturbations, known in advance
    names: tuple[str, ...]  # the identified coefficients
    kinds: tuple[tuple[str, str], ...]  # their (kind, joint)
    start: Array  # (k,) their start values (the model's)


def _effect_terms(run: Run, load_model: Model | None) -> _EffectTerms:
    """The identified joint effects' patterns ``(k, n, dof, 3)``, names and start values,
    and the perturbations of the model's other joint effects, known and predicted at every
    pose."""
    from robocal.model.joints import EFFECT_KINDS, EFFECT_PREFIXES, effect_basis, load_moments
    from robocal.model.joints import joint_perturbations as predict_effects

    model, q, plan, e = run.model, run.data.q, run.plan, run.options.joint_effects
    geometry = model if load_model is None else check_load_model(load_model, model)
    loads = load_moments(geometry, q, e.velocities, e.accelerations, gravity=np.asarray(e.gravity),
                         payload=e.payload)  # fmt: skip
    basis: Array | None = None
    names: tuple[str, ...] = ()
    kinds: tuple[tuple[str, str], ...] = ()
    if plan.kinds:
        joints = plan.joints if plan.joints is not None else e.joints
        basis, found, pairs = effect_basis(model, q, kinds=plan.kinds, joints=joints, loads=loads)
        names, kinds = tuple(found), tuple(pairs)
    by_joint = {x.joint: x for x in model.joint_effects}
    start = np.array(
        [getattr(by_joint[j], EFFECT_PREFIXES[k][1]) if j in by_joint else 0.0 for k, j in kinds]
    )
    if not model.joint_effects:
        return _EffectTerms(basis, None, names, kinds, start)
    # the model's joint effects that are not identified are known: predicted at every pose
    identified = set(kinds)
    rest = [
        dataclasses.replace(
            x, **_zeros(EFFECT_PREFIXES[k][1] for k in EFFECT_KINDS if (k, x.joint) in identified)
        )
        for x in model.joint_effects
    ]
    known = predict_effects(model, q, effects=rest, loads=loads)
    if not np.any(known):
        return _EffectTerms(basis, None, names, kinds, start)
    predicted = {k: [x.joint for x in rest if getattr(x, EFFECT_PREFIXES[k][1])] for k in EFFECT_KINDS}
    listed = "; ".join(f"{k} ({', '.join(j)})" for k, j in predicted.items() if j)
    run.warn(  # a robot whose joints differ from its model's would be mis-corrected
        "effects-predicted",
        f"joint effects of model {model.name!r} predicted as known, not identified: {listed}; if this "
        "robot's differ, identify them too (level=3 / --level 3) or calibrate a model without them",
    )
    return _EffectTerms(basis, known, names, kinds, start)


def build_problem(run: Run, load_model: Model | None) -> Start:
    """The measurement chain at the start values, weights and joint-effect patterns
    (warnings to ``run``'s log)."""
    setup, data, measure = run.options.setup, run.data, run.measure
    T_frame, T_tool, T_flange, fit_frame = _start_values(run)
    chain, order = measurement_chain_and_preference(
        run.model, T_frame, None if setup.tool is None else T_tool, measure, fit_frame
    )
    preference: NDArray[np.intp] | None = order
    if setup.tool is not None and not (isinstance(setup.tool, str) and setup.tool == "fit"):
        chain, preference = chain.fixed(chain.names_with_role(Role.TOOL)), None  # other unknowns
    length = robot_size(T_flange)
    rows = 3 if measure == "position" else 6
    w, known_noise = _row_weights(run, rows)
    effects = _effect_terms(run, load_model) if run.plan.mode != "none" else None
    known = None if effects is None else effects.known
    if run.model.residual is not None:  # a learned residual given with the model is known: applied
        learned = run.model.residual.perturbations(data.q, run.model.dof)
        known = learned if known is None else known + learned
    names, kinds = (effects.names, effects.kinds) if effects is not None else ((), ())
    start = None if effects is None else effects.start  # a pass without joint effects: none
    basis = None if effects is None else effects.basis
    problem = Problem(chain, data.q, _positions(data), data.orientation if rows == 6 else None, w.reshape(-1),
                      length, basis, names, known, start, None if names else preference)  # fmt: skip
    hint = _check_orientations(run, problem) if rows == 6 else ""
    return Start(problem, known_noise, length, names, kinds, start, hint)


def _check_orientations(run: Run, problem: Problem) -> str:
    """With the device frame and the tool fitted, a real robot's orientations agree with
    its model to a degree or so; far more means the file's rotations are read wrongly: the
    hint (also a warning in ``run``'s log), or empty."""
    r = problem.residual(problem.x0, weighted=False).reshape(run.data.n, 6)
    angle = np.degrees(np.median(np.linalg.norm(r[:, 3:], axis=1)))
    if angle <= 5.0:
        return ""
    hint = (
        f"the measured orientations differ from the model's by {angle:.3g}° (median) after the "
        "device frame and the tool were fitted: check the orientation convention of the data "
        "(orientation='euler:XYZ:deg' / --orientation: intrinsic XYZ is upper case, extrinsic "
        "xyz lower case), or calibrate positions only (measure='position')"
    )
    run.warn("orientation", hint)
    return hint
