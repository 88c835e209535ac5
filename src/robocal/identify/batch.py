# long: the batched engine is one concept (K robots through the one stage sequence, its stages and values)
"""The batched calibration engine: many robots of one model calibrated at once.

:func:`calibrate_batch` computes what ``rc.calibrate(model, d, tool_guess=...,
max_std=...)`` computes for each measurement set ``d`` of a batch (position
measurements, ``method="lm"``, the physical model) — with the same stage functions
(:mod:`robocal.identify.stages`: start values, identifiable set, screening, uncertainty,
pruning), the same solver (:func:`robocal.identify.solvers.levenberg_marquardt_batch`)
and the same guards (:mod:`robocal.identify.guards`: the data, equations against
unknowns, rank, the solution) — but evaluates the robots together.  Their measurement
chains share one structure, so the chain is rewritten with the steps that differ
between robots as joint variables (a step's value becomes a per-row input,
:func:`augmented_chain`) and one call of :meth:`~robocal.model.chain.Model.evaluate`
gives the tool positions and the derivative columns of all robots × poses at once.

Used by Monte Carlo studies (:mod:`robocal.study`), which calibrate thousands of
virtual robots.  Units: SI (m, rad).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from robocal import spatial
from robocal.identify.guards import CalibrationGuardError, check_data, check_rank, check_solution
from robocal.identify.problem import TOOL_PREFIX, frame_steps, measurement_chain
from robocal.identify.rules import Rules
from robocal.identify.solve_result import BatchSolveResult
from robocal.identify.solvers import levenberg_marquardt_batch
from robocal.identify.stages import (
    Covariance,
    fit_selection,
    identifiable_set,
    initial_frames_and_tools,
    poorly_identifiable,
    robot_sizes,
    screen_unidentifiable,
    tool_displacement_scale,
    uncertainty,
)
from robocal.measure.measurements import Measurements
from robocal.model.chain import Model
from robocal.model.rank import Dropped
from robocal.model.steps import Joint, Step

__all__ = ["BatchFit", "augmented_chain", "batch_positions", "calibrate_batch"]

Array = NDArray[np.float64]


@dataclass
class BatchFit:
    """The calibration of one robot by :func:`calibrate_batch` (SI units).

    Attributes:
        names: the identified parameters (robot, ``frame_*``, ``tcp_*``), chain order.
        estimates, start, std: their values, start values and standard deviations;
            covariance ``(p, p)``.
        dropped: the parameters left out and why (as ``rc.calibrate``'s).
        values: all values of the measurement chain after calibration ``(P,)``
            (:attr:`chain` order; ``frame0_*`` are the device frame's start).
        chain: the measurement chain (structure and start values of the batch's first robot).
        rms_before, rms_after, residual_std: m.
        iterations: accepted steps + 1 of the last fit; evaluations: of all fits.
    """

    names: tuple[str, ...]
    estimates: Array
    start: Array
    std: Array
    covariance: Array = field(repr=False)
    dropped: tuple[Dropped, ...]
    values: Array
    chain: Model = field(repr=False)
    rms_before: float
    rms_after: float
    residual_std: float
    condition_number: float
    iterations: int
    evaluations: int
    success: bool
    message: str

    @property
    def nominal(self) -> Array:
        """The start values (``CalibrationResult.nominal``)."""
        return self.start

    @property
    def measurement_chain(self) -> Model:
        return self.chain

    def predict(self, q: ArrayLike) -> Array:
        """Predicted target positions ``(n, 3)`` (m) in the device frame at joint values ``q``."""
        q = np.atleast_2d(np.asarray(q, dtype=float))
        return batch_positions(self.chain, self.values[None], [q])


# ---------------------------------------------------------------------- the augmented chain
_AUG_CACHE: dict[tuple, tuple[Model, NDArray[np.intp], NDArray[np.intp]]] = {}


def augmented_chain(
    chain: Model, values: Array | None = None, varying: NDArray[np.bool_] | None = None
) -> tuple[Model, NDArray[np.intp], NDArray[np.intp]]:
    """The chain with steps made joint variables (value 0), for batches of robots.

    Row ``u`` of the augmented model's joint values holds the original chain's values
    of those steps, plus the joint values on the original joint steps: its FK is the
    original FK at those values, and its joint Jacobian columns are the derivatives
    with respect to those parameters, for a different parameter vector on every row.

    Args:
        chain: the chain.
        values: ``(P,)`` values of the steps that stay constant (default: the chain's).
        varying: ``(P,)`` steps to turn into joint variables (default: all); the
            original joint steps always are.

    Returns:
        The augmented model, the chain indices of its joint variables (in order) and
        the positions among them of the original joint steps.
    """
    P = len(chain.steps)
    joint = np.array([s.joint is not None for s in chain.steps])
    mask = np.ones(P, dtype=bool) if varying is None else (np.asarray(varying, dtype=bool) | joint)
    values = chain.values if values is None else np.asarray(values, dtype=float)
    key = (chain, mask.tobytes(), values[~mask].tobytes())  # by value: an id can be reused
    hit = _AUG_CACHE.get(key)
    if hit is not None:
        return hit
    steps = tuple(
        Step(s.motion, s.name, 0.0, True, None, Joint("u:" + s.name), s.role)
        if mask[i]
        else Step(s.motion, s.name, float(values[i]), False, role=s.role)
        for i, s in enumerate(chain.steps)
    )
    aug = dataclasses.replace(chain, name=chain.name + "+batch", steps=steps, bodies=())
    ucols = np.flatnonzero(mask)
    joint_pos = np.flatnonzero(joint[ucols])
    if len(_AUG_CACHE) > 64:
        _AUG_CACHE.clear()
    _AUG_CACHE[key] = (aug, ucols, joint_pos)
    return aug, ucols, joint_pos


def _rows(values: Array, qs: Sequence[Array], joint_pos: NDArray[np.intp]) -> Array:
    """Augmented joint values ``(Σ n_k, p)``: robot k's values ``(K, p)`` on each of its rows,
    plus its joint values at ``joint_pos``."""
    counts = [len(q) for q in qs]
    u = np.repeat(values, counts, axis=0)
    u[:, joint_pos] += np.concatenate(qs, axis=0)
    return u


def batch_positions(chain: Model, values: Array, qs: Sequence[Array]) -> Array:
    """Positions ``(Σ n_k, 3)`` at the end of ``chain`` for robot k's values ``values[k]``
    ``(P,)`` at its joint values ``qs[k]`` ``(n_k, dof)``, in one batched FK."""
    aug, ucols, joint_pos = augmented_chain(chain)
    return aug.fk(_rows(values[:, ucols], qs, joint_pos))[:, :3, 3]


class _Group:
    """Robots of a batch that share the same unknowns: residuals and Jacobians at once.

    The steps that are unknowns, or whose values differ between the robots, become
    joint variables of one augmented chain (:func:`augmented_chain`); the others stay
    constant steps, which keeps the batched evaluation short.
    """

    def __init__(
        self, chain: Model, V: Array, qs: Sequence[Array], ys: Array, w: Array, cols: NDArray[np.intp]
    ) -> None:
        self.chain = chain
        self.V = V  # (K, P) start values of every chain parameter
        self.qs = qs
        self.ys = ys  # (K, n, 3)
        self.w = w.reshape(len(w), -1)  # (K, 3n) weights 1/σ
        self.cols = cols  # (p,) chain indices of the unknowns
        varying = np.ptp(V, axis=0) > 0
        varying[cols] = True
        self.aug, self.ucols, self.joint_pos = augmented_chain(chain, V[0], varying)
        self.dcols = np.searchsorted(self.ucols, cols)

    def subset(self, idx: NDArray[np.intp]) -> _Group:
        """The group of robots ``idx`` only (same augmented chain)."""
        g = object.__new__(_Group)
        g.chain, g.V, g.qs, g.ys, g.w, g.cols = (
            self.chain,
            self.V[idx],
            [self.qs[k] for k in idx],
            self.ys[idx],
            self.w[idx],
            self.cols,
        )
        g.aug, g.ucols, g.joint_pos, g.dcols = self.aug, self.ucols, self.joint_pos, self.dcols
        return g

    def values(self, x: Array) -> Array:
        V = self.V.copy()
        V[:, self.cols] = x
        return V

    def evaluate(self, x: Array) -> tuple[Array, Array]:
        """Unweighted residuals ``(K, 3n)`` and Jacobians ``(K, 3n, p)`` at unknowns ``x`` ``(K, p)``."""
        K = len(x)
        u = _rows(self.values(x)[:, self.ucols], self.qs, self.joint_pos)
        T, _, Jq = self.aug.evaluate(u, jacobian=False, joint_columns=True)
        n = self.ys.shape[1]
        r = (T[:, :3, 3].reshape(K, n, 3) - self.ys).reshape(K, -1)
        return r, Jq[:, self.dcols].reshape(K, 3 * n, -1)

    def weighted(self, x: Array, which: NDArray[np.intp]) -> tuple[Array, Array]:
        """Weighted residuals and Jacobians of robots ``which`` (the solver's ``evaluate``)."""
        group = self if len(which) == len(self.V) else self.subset(which)
        r, J = group.evaluate(x)
        return r * group.w, J * group.w[:, :, None]


# ---------------------------------------------------------------------- the engine
def _check_before_fit(model: Model, data: Measurements, tool_guess: ArrayLike | None) -> None:
    """``rc.calibrate``'s guards before any fit: the data, and too few equations."""
    check_data(model, data)
    if 3 * data.n < len(model.free_names) + 12:
        check_rank(model, data, measure="position", tool_guess=tool_guess)


def calibrate_batch(
    model: Model,
    data: Sequence[Measurements],
    *,
    tool_guess: ArrayLike | None = None,
    max_std: float = Rules.max_std,
    max_std_ratio: float = Rules.max_std_ratio,
    max_iterations: int = 200,
    rules: Rules | None = None,
) -> list[BatchFit | CalibrationGuardError]:
    """Calibrate many robots of the same model at once (position measurements).

    Computes what ``rc.calibrate(model, d, method="lm", tool_guess=tool_guess,
    max_std=max_std, max_std_ratio=max_std_ratio)`` computes for each ``d`` in ``data``
    — device frame and tool point fitted, rows weighted by 1/σ, identifiable set
    preferring the device frame, then the tool, then the robot in chain order, hopeless
    parameters screened before the fit, poorly identifiable ones pruned after it — with
    the same functions, but evaluates every robot's chain in one batched call per
    iteration (module docstring).

    Args:
        model: the nominal robot model (free parameters: the candidates).
        data: K measurement sets with positions ``(n_k, 3)`` (m) in the device frame and
            the same pose count ``n`` (their joint values may differ).
        tool_guess: start of the tool point (m, flange frame), ``(3,)``.
        max_std, max_std_ratio: pruning thresholds (m as tool displacement, and times the
            median σ), as in ``rc.calibrate``.
        max_iterations: as ``rc.calibrate``'s (Levenberg–Marquardt evaluations:
            ``max_iterations · (p + 1)``).
        rules: screening, pruning and variance rules as one value
            (:class:`~robocal.identify.rules.Rules`, ``rc.calibrate``'s from its pruning
            options); given, it replaces ``max_std`` and ``max_std_ratio``.

    Returns:
        Per measurement set a :class:`BatchFit`, or the
        :class:`~robocal.identify.guards.CalibrationGuardError` ``rc.calibrate`` would
        raise for it (too few poses, rank-deficient poses, a diverged fit...).

    Raises:
        ValueError: no positions, different pose counts or a joint count that does not
            fit the model.
    """
    from robocal.identify.problem_setup import without_measured_tool

    if not data:
        return []
    n = data[0].n
    for k, d in enumerate(data):
        if d.position is None:
            raise ValueError(f"data[{k}] has no measured positions")
        if d.dof != model.dof:
            raise ValueError(f"data[{k}] has {d.dof} joint columns but model {model.name!r} has {model.dof}")
        if d.n != n:
            raise ValueError(f"data[{k}] has {d.n} poses; a batch needs the same count ({n}) for all")
    if model.residual is not None:  # as rc.calibrate: a learned residual is refitted, not used
        model = dataclasses.replace(model, residual=None)
    model, carried_tool = without_measured_tool(model)
    if carried_tool is not None and tool_guess is None:
        tool_guess = carried_tool
    out: list[BatchFit | CalibrationGuardError | None] = [None] * len(data)
    for k, d in enumerate(data):
        try:
            _check_before_fit(model, d, tool_guess)
        except CalibrationGuardError as err:
            out[k] = err
    todo = [k for k in range(len(data)) if out[k] is None]
    if todo:
        rules = rules if rules is not None else Rules(float(max_std), float(max_std_ratio))
        fits = _Batch(model, [data[k] for k in todo], tool_guess, rules, max_iterations).run()
        for k, fit in zip(todo, fits, strict=True):
            out[k] = fit
    return [o for o in out if o is not None]


class _Batch:
    """One :func:`calibrate_batch` over data that passed the checks before the fit."""

    def __init__(
        self,
        model: Model,
        data: Sequence[Measurements],
        tool_guess: ArrayLike | None,
        rules: Rules,
        max_iterations: int,
    ) -> None:
        self.model, self.data, self.tool_guess = model, data, tool_guess
        self.rules, self.max_iterations = rules, max_iterations
        K, n = len(data), data[0].n
        self.K, self.n = K, n
        self.qs = [d.q for d in data]
        self.ys = np.stack([d.position for d in data if d.position is not None])  # all have (checked)
        T_tool0 = np.eye(4)
        if tool_guess is not None:
            g = np.asarray(tool_guess, dtype=float)
            T_tool0 = g if g.shape == (4, 4) else spatial.homogeneous(p=g)
        T_flange = model.fk(np.concatenate(self.qs, axis=0)).reshape(K, n, 4, 4)
        T_frame, T_tool = initial_frames_and_tools(T_flange, self.ys, T_tool=T_tool0)
        chain = measurement_chain(model, T_frame[0], T_tool[0], "position", True)
        self.chain = chain
        index = {name: i for i, name in enumerate(chain.names)}
        V = np.tile(chain.values, (K, 1))
        for k in range(K):  # the device frame's start as rc.calibrate writes it
            for s in frame_steps(T_frame[k], "frame0", free=False):
                V[k, index[s.name]] = s.value
        V[:, [index[f"{TOOL_PREFIX}{c}"] for c in "xyz"]] = T_tool[:, :3, 3]
        self.V = V
        self.w = np.ones((K, n, 3))
        self.known = np.array([d.sigma is not None for d in data])  # a stated noise: weights 1/σ
        for k, d in enumerate(data):
            if d.sigma is not None:
                self.w[k] = 1.0 / np.maximum(d.sigma, 1e-12)
        self.length = robot_sizes(T_flange)
        self.free = np.flatnonzero(chain.free_mask)
        self.rotation = np.array([s.is_rotation for s in chain.steps])[self.free]
        self.free_names = [chain.names[i] for i in self.free]

    # ------------------------------------------------------------------ the stage sequence
    def run(self) -> list[BatchFit | CalibrationGuardError]:
        """:func:`robocal.identify.pipeline.calibrate_physics`'s stages 4-8 for the ``K``
        robots, in its order and with its stage functions (:mod:`robocal.identify.stages`),
        each stage called for all robots still in the sequence: the identifiable set and
        the rank guard, the screening, the fit with its uncertainty, the pruning (refit from
        the start values), the result and the solution guard.  A robot refused by a guard
        leaves the sequence with its error."""
        out: dict[int, BatchFit | CalibrationGuardError] = {}
        start = _BatchStart(self)
        selections = self._identifiable(start, out)
        fits = fit_selection(_BatchStages(self, start), selections)
        for k, fit in fits.items():
            out[k] = self._assemble(start, k, fit)
        return [out[k] for k in range(self.K)]

    def _identifiable(
        self, start: _BatchStart, out: dict[int, BatchFit | CalibrationGuardError]
    ) -> dict[int, _Selection]:
        """Stage 4 per robot: the identifiable set at the start values
        (:func:`~robocal.identify.stages.identifiable_set`, the device frame, then the tool,
        then the robot in chain order) and the rank guard; refused robots go to ``out``."""
        names, selections = self.free_names, {}
        for k in range(self.K):
            scale = np.where(self.rotation, self.length[k], 1.0)  # Problem.free_scale
            subset = identifiable_set(start.J[k] * scale, names, roles=self.chain.roles)
            try:
                check_rank(self.model, self.data[k], measure="position", tool_guess=self.tool_guess,
                           kept=subset.kept, candidates=names)  # fmt: skip
            except CalibrationGuardError as err:
                out[k] = err
                continue
            kept = set(subset.kept)
            selections[k] = _Selection(np.array([name in kept for name in names]), tuple(subset.dropped))
        return selections

    def _assemble(self, start: _BatchStart, k: int, fit: _Fit) -> BatchFit | CalibrationGuardError:
        """Stages 7-8: robot ``k``'s result, or the solution guard's refusal."""
        n, solved, i, mask = self.n, fit.solved, fit.i, fit.selection.mask
        cols = self.free[mask]
        r_plain = (solved.r[i] / fit.w).reshape(n, 3)
        values = self.V[k].copy()
        values[cols] = solved.x[i]
        cov = fit.covariance
        result = BatchFit(
            names=tuple(self.chain.names[c] for c in cols), estimates=solved.x[i].copy(),
            start=start.x[k, mask].copy(), std=cov.std, covariance=cov.covariance,
            dropped=fit.selection.dropped, values=values, chain=self.chain,
            rms_before=float(np.sqrt(np.mean(np.sum(start.r_plain[k].reshape(n, 3) ** 2, axis=1)))),
            rms_after=float(np.sqrt(np.mean(np.sum(r_plain**2, axis=1)))),
            residual_std=float(np.sqrt(np.sum(r_plain**2) / max(3 * n - len(cols), 1))),
            condition_number=cov.condition, iterations=int(solved.iterations[i]),
            evaluations=int(solved.evaluations[i]), success=bool(solved.success[i]),
            message=solved.message(i),
        )  # fmt: skip
        try:
            check_solution(result)
        except CalibrationGuardError as err:
            return err
        return result


@dataclass(frozen=True)
class _BatchStages:
    """Stages 5-6 for the robots still in the sequence
    (:class:`~robocal.identify.stages.FitStages` over ``{robot: selection}``)."""

    batch: _Batch
    start: _BatchStart

    def screen(self, selections: dict[int, _Selection]) -> dict[int, _Selection]:
        return {k: self._screen_one(k, selection) for k, selection in selections.items()}

    def _screen_one(self, k: int, selection: _Selection) -> _Selection:
        """Stage 5: the hopeless unknowns fixed before the first fit
        (:func:`~robocal.identify.stages.screen_unidentifiable`)."""
        b, start = self.batch, self.start
        cols = np.flatnonzero(selection.mask)
        effect = tool_displacement_scale(start.J_plain[k][:, cols].reshape(b.n, 3, -1))
        found = screen_unidentifiable(start.r[k], start.J[k][:, cols], effect,
                                      known_noise=bool(b.known[k]), rules=b.rules)  # fmt: skip
        mask, dropped = selection.mask.copy(), list(selection.dropped)
        for c, sigma in found:
            mask[cols[c]] = False
            dropped.append(Dropped(b.free_names[cols[c]], "poorly identifiable", sigma=sigma))
        return _Selection(mask, tuple(dropped))

    def solve(self, selections: dict[int, _Selection]) -> dict[int, _Fit]:
        """Stage 6: the fit of each robot's selection from its start values and the
        :func:`~robocal.identify.stages.uncertainty` at its solution; robots with the same
        unknowns are one batched solve (:func:`levenberg_marquardt_batch`)."""
        b, start = self.batch, self.start
        groups: dict[bytes, list[int]] = {}
        for k, selection in selections.items():
            groups.setdefault(selection.mask.tobytes(), []).append(k)
        fits: dict[int, _Fit] = {}
        for members in groups.values():
            idx = np.array(members, dtype=np.intp)
            mask = selections[members[0]].mask
            cols = b.free[mask]
            group = _Group(b.chain, b.V[idx], [b.qs[k] for k in idx], b.ys[idx], b.w[idx], cols)
            solved = levenberg_marquardt_batch(group.weighted, start.x[idx][:, mask],
                                               max_evaluations=b.max_iterations * (len(cols) + 1),
                                               tolerance=1e-10)  # fmt: skip
            for i, k in enumerate(members):
                covariance = uncertainty(solved.r[i], solved.J[i], 3, bool(b.known[k]), b.rules)
                fits[k] = _Fit(selections[k], solved, i, group.w[i], covariance)
        return fits

    def prune(self, fits: dict[int, _Fit]) -> dict[int, _Fit]:
        """Stage 6, pruning: after a converged fit the worst poorly identifiable unknown
        (:func:`~robocal.identify.stages.poorly_identifiable`) is fixed and the robot
        refitted from its start values, until none is left."""
        b = self.batch
        todo = dict(fits)
        while todo:
            pruned: dict[int, _Selection] = {}
            for k, fit in todo.items():
                if not fit.solved.success[fit.i]:
                    continue
                J_plain = (fit.solved.J[fit.i] / fit.w[:, None]).reshape(b.n, 3, -1)
                found = poorly_identifiable(fit.covariance.std, tool_displacement_scale(J_plain),
                                            b.rules.max_std, b.rules.max_std_ratio)  # fmt: skip
                if found is not None:
                    mask, c = fit.selection.mask.copy(), int(np.flatnonzero(fit.selection.mask)[found[0]])
                    mask[c] = False
                    why = Dropped(b.free_names[c], "poorly identifiable", sigma=found[1])
                    pruned[k] = _Selection(mask, (*fit.selection.dropped, why))
            todo = self.solve(pruned) if pruned else {}
            fits.update(todo)
        return fits


class _BatchStart:
    """The ``K`` robots at their start values (stages 2-3 of the sequence): unknowns ``x``
    ``(K, p)``, weighted and plain residuals ``(K, 3n)`` and Jacobians ``(K, 3n, p)``."""

    def __init__(self, batch: _Batch) -> None:
        full = _Group(batch.chain, batch.V, batch.qs, batch.ys, batch.w, batch.free)
        self.x = batch.V[:, batch.free]
        self.r_plain, self.J_plain = full.evaluate(self.x)
        self.r, self.J = full.weighted(self.x, np.arange(batch.K))


@dataclass(frozen=True)
class _Selection:
    """A robot's unknowns among the free parameters (``mask`` ``(p,)``) and those left out."""

    mask: NDArray[np.bool_]
    dropped: tuple[Dropped, ...]


@dataclass(frozen=True)
class _Fit:
    """A robot's fit: row ``i`` of a batched solve of its ``selection``, its row weights
    ``w`` ``(3n,)`` and the covariance there."""

    selection: _Selection
    solved: BatchSolveResult
    i: int
    w: Array
    covariance: Covariance
