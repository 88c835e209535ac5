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
from robocal.identify.solvers import levenberg_marquardt_batch
from robocal.identify.stages import (
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

    def run(self) -> list[BatchFit | CalibrationGuardError]:
        K, n = self.K, self.n
        out: list[BatchFit | CalibrationGuardError | None] = [None] * K
        full = _Group(self.chain, self.V, self.qs, self.ys, self.w, self.free)
        x_start = self.V[:, self.free]
        r0_plain, J0_plain = full.evaluate(x_start)
        r0, J0 = full.weighted(x_start, np.arange(K))
        masks = np.zeros((K, len(self.free)), dtype=bool)
        dropped: list[list[Dropped]] = [[] for _ in range(K)]
        for k in range(K):
            try:
                masks[k], dropped[k] = self._unknowns(k, r0[k], J0[k], J0_plain[k])
            except CalibrationGuardError as err:
                out[k] = err
        pending = [k for k in range(K) if out[k] is None]
        while pending:  # robots with the same unknowns are solved together
            groups: dict[bytes, list[int]] = {}
            for k in pending:
                groups.setdefault(masks[k].tobytes(), []).append(k)
            pending = []
            for members in groups.values():
                idx = np.array(members, dtype=np.intp)
                mask = masks[idx[0]].copy()  # a copy: the loop below prunes members' rows of masks
                cols = self.free[mask]
                group = _Group(
                    self.chain, self.V[idx], [self.qs[k] for k in idx], self.ys[idx], self.w[idx], cols
                )
                fit = levenberg_marquardt_batch(
                    group.weighted,
                    x_start[idx][:, mask],
                    max_evaluations=self.max_iterations * (len(cols) + 1),
                    tolerance=1e-10,
                )
                for i, k in enumerate(idx):
                    _, cov, std, _, cond = uncertainty(fit.r[i], fit.J[i], 3, bool(self.known[k]), self.rules)
                    J_plain = (fit.J[i] / group.w[i][:, None]).reshape(n, 3, -1)
                    rules = self.rules
                    found = (
                        poorly_identifiable(
                            std, tool_displacement_scale(J_plain), rules.max_std, rules.max_std_ratio
                        )
                        if fit.success[i]
                        else None
                    )
                    if found is not None:  # refitted from the start values, as rc.calibrate
                        c = int(np.flatnonzero(mask)[found[0]])
                        masks[k, c] = False
                        dropped[k].append(Dropped(self.free_names[c], "poorly identifiable", sigma=found[1]))
                        pending.append(int(k))
                        continue
                    r_plain = (fit.r[i] / group.w[i]).reshape(n, 3)
                    values = self.V[k].copy()
                    values[cols] = fit.x[i]
                    result = BatchFit(
                        names=tuple(self.chain.names[c] for c in cols),
                        estimates=fit.x[i].copy(),
                        start=x_start[k, mask].copy(),
                        std=std,
                        covariance=cov,
                        dropped=tuple(dropped[k]),
                        values=values,
                        chain=self.chain,
                        rms_before=float(np.sqrt(np.mean(np.sum(r0_plain[k].reshape(n, 3) ** 2, axis=1)))),
                        rms_after=float(np.sqrt(np.mean(np.sum(r_plain**2, axis=1)))),
                        residual_std=float(np.sqrt(np.sum(r_plain**2) / max(3 * n - len(cols), 1))),
                        condition_number=cond,
                        iterations=int(fit.iterations[i]),
                        evaluations=int(fit.evaluations[i]),
                        success=bool(fit.success[i]),
                        message=fit.message(i),
                    )
                    try:
                        check_solution(result)
                        out[k] = result
                    except CalibrationGuardError as err:
                        out[k] = err
        return [o for o in out if o is not None]

    def _unknowns(
        self, k: int, r0: Array, J0: Array, J0_plain: Array
    ) -> tuple[NDArray[np.bool_], list[Dropped]]:
        """Robot ``k``'s unknowns among the free parameters (mask) and those left out:
        the identifiable set at the start values, the rank guard, then the screening."""
        names = self.free_names
        scale = np.where(self.rotation, self.length[k], 1.0)  # Problem.free_scale
        selection = identifiable_set(J0 * scale, names, roles=self.chain.roles)
        check_rank(
            self.model,
            self.data[k],
            measure="position",
            tool_guess=self.tool_guess,
            kept=selection.kept,
            candidates=names,
        )
        kept = set(selection.kept)
        mask = np.array([name in kept for name in names])
        dropped = list(selection.dropped)
        cols = np.flatnonzero(mask)
        effect = tool_displacement_scale(J0_plain[:, cols].reshape(self.n, 3, -1))
        found = screen_unidentifiable(
            r0, J0[:, cols], effect, known_noise=bool(self.known[k]), rules=self.rules
        )
        for c, sigma in found:
            mask[cols[c]] = False
            dropped.append(Dropped(names[cols[c]], "poorly identifiable", sigma=sigma))
        return mask, dropped
