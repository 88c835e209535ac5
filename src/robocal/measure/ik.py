"""Batched numerical inverse kinematics for any :class:`~robocal.model.chain.Model`.

The solver is a damped least-squares (Levenberg–Marquardt) iteration on the
geometric Jacobian :meth:`Model.joint_jacobian`, run for all targets at once:
each iteration is one batched forward-kinematics pass, one batched Jacobian and
one batched ``dof x dof`` (or ``rows x rows``) linear solve over the targets that
are still active.  Joint limits are respected by projection: every step is clipped
to the limits, and a joint sitting on a limit that the gradient pushes further out
is frozen for the next step (a simple active set), so the iteration can slide along
the limit instead of stalling against it.

Targets
-------
``kind="position"``  tool-point positions ``(n, 3)`` (m); 3 equations per target.
``kind="pose"``      tool frames ``(n, 4, 4)``; 6 equations: position and the rotation
                     vector ``log(R_target R_toolᵀ)`` (rad) in the base frame.
``kind="axis"``      tool frames ``(n, 4, 4)`` of which only the position and one tool
                     axis (``tool_axis``, default z, the approach direction) are
                     imposed: 5 independent equations, the natural task of a 5-DOF arm
                     such as the Katana 450 (seed 003).

Orientation rows are multiplied by ``orientation_weight`` (m/rad) so that one
objective mixes metres and radians; the reported residuals are unweighted.

A target is *reachable* when the final position error is below ``tol`` (m) and the
orientation error below ``tol_angle`` (rad), with all joints inside their limits.
Targets that fail from their first seed are restarted from random configurations
(seeded, uniform within the joint limits, revolute joints restricted to [-π, π] when
the limits are wider); the best solution over all seeds is returned.  Give ``q0`` to
start from known configurations (e.g. the previous sample of a path, to keep the
configuration branch) and ``restarts=0`` to forbid switching branch.

Non-geometric joint effects
---------------------------
``joint_effects(q) -> (n, dof, 3)`` (or None) gives joint perturbations (δα, δβ, δθ)
that depend on the commanded configuration (e.g. compliance under gravity,
:meth:`robocal.identify.CalibrationResult.joint_perturbations`).  They are evaluated
at every iterate and passed to ``fk`` and ``joint_jacobian``; the Jacobian neglects
their own derivative with respect to ``q``, so the iteration converges to the fixed
point ``fk(q, joint_effects(q)) = target`` as long as the effects change slowly with
``q`` (used by :mod:`robocal.compensate`).

Starting configurations (random ones and the cached pool): :mod:`robocal.measure.ik_starts`.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Literal, TypedDict

import numpy as np
from numpy.typing import ArrayLike, NDArray

from robocal import spatial
from robocal.measure.ik_starts import TargetKind, nearest_pool, random_configurations
from robocal.model.chain import Model

__all__ = [
    "IKResult",
    "IKSettings",
    "PerturbationFunction",
    "TargetKind",
    "random_configurations",
    "solve_ik",
]

Array = NDArray[np.float64]


class IKSettings(TypedDict, total=False):
    """The convergence settings of :func:`solve_ik`, for functions that pass them on
    (``**ik_options``); each absent one takes :func:`solve_ik`'s default."""

    tol: float
    tol_angle: float
    max_iter: int
    orientation_weight: float
    damping: float
    seed_pool: int


#: ``joint_effects(q (m, dof)) -> (m, dof, 3)`` joint perturbations, or None for none
PerturbationFunction = Callable[[NDArray[np.float64]], NDArray[np.float64] | None]
#: m: a target coordinate beyond this is refused, not searched for (no arm reaches 1000 km, and
#: errors of 1e200 m overflow the solver's squares); a wrong length unit is the usual cause
FARTHEST_TARGET = 1e6


@dataclass(frozen=True)
class IKResult:
    """Outcome of :func:`solve_ik` for ``n`` targets.

    Attributes:
        q: ``(n, dof)`` best joint values found (rad or m), inside the joint limits.
        position_error: ``(n,)`` distance between target and reached tool position (m).
        angle_error: ``(n,)`` orientation error (rad): rotation angle between target
            and reached tool frame (``"pose"``), angle between the target and reached
            tool axis (``"axis"``), zeros for ``"position"``.
        reachable: ``(n,)`` position error < ``tol`` and angle error < ``tol_angle``.
        iterations: ``(n,)`` LM iterations spent on each target, over all seeds.
        seeds_used: ``(n,)`` number of starting configurations tried per target.
        kind: the target kind that was solved.
    """

    q: Array
    position_error: Array
    angle_error: Array
    reachable: NDArray[np.bool_]
    iterations: NDArray[np.int64]
    seeds_used: NDArray[np.int64]
    kind: TargetKind

    @property
    def success(self) -> bool:
        """Whether every target was reached."""
        return bool(self.reachable.all())

    @property
    def residual(self) -> Array:
        """``(n,)`` position error (m); see also :attr:`angle_error`."""
        return self.position_error

    @property
    def message(self) -> str:
        n = len(self.reachable)
        bad = np.flatnonzero(~self.reachable)
        if not len(bad):
            return f"all {n} targets reached"
        worst = bad[np.argmax(self.position_error[bad])]
        return (
            f"{len(bad)} of {n} targets not reached (first: target {bad[0]}); worst position error "
            f"{self.position_error[worst] * 1e3:.3g} mm at target {worst}"
        )


def target_array(targets: ArrayLike, kind: TargetKind | Literal["auto"]) -> tuple[Array, TargetKind]:
    """Targets as ``(n, 4, 4)`` frames plus the resolved kind."""
    T = np.asarray(targets, dtype=float)
    if kind == "auto":
        if T.shape[-1:] == (3,) and T.ndim in (1, 2):
            kind = "position"
        elif T.shape[-2:] == (4, 4) and T.ndim in (2, 3):
            kind = "pose"
        else:
            raise ValueError(f"IK targets shaped {T.shape}: expected positions (n, 3) or frames (n, 4, 4)")
    if kind not in ("position", "pose", "axis"):
        raise ValueError(f"IK target kind must be 'position', 'pose' or 'axis', got {kind!r}")
    if kind == "position" and T.shape[-1:] == (3,) and T.ndim in (1, 2):
        T = spatial.homogeneous(p=T.reshape(-1, 3))
    elif T.shape[-2:] == (4, 4) and T.ndim in (2, 3):
        T = T.reshape(-1, 4, 4)
    else:
        raise ValueError(
            f"IK targets shaped {T.shape} do not fit kind {kind!r}: "
            "positions (n, 3) for 'position', frames (n, 4, 4) for 'pose' and 'axis'"
        )
    if not np.all(np.isfinite(T)):
        bad = int(np.flatnonzero(~np.isfinite(T).reshape(len(T), -1).all(axis=1))[0])
        raise ValueError(f"IK target {bad} contains NaN or inf")
    # |x|, |y| or |z| (m); the largest coordinate, not the norm, which overflows at 1e200
    reach = np.max(np.abs(T[:, :3, 3]), axis=1)
    if np.any(reach > FARTHEST_TARGET):
        far = int(np.flatnonzero(reach > FARTHEST_TARGET)[0])
        raise ValueError(
            f"IK target {far} lies {reach[far]:.3g} m from the base: beyond any robot's reach "
            f"(targets are refused beyond {FARTHEST_TARGET:g} m; check the length unit)"
        )
    return T, kind


class Problem:
    """Residuals and Jacobians of one IK problem, batched over configurations."""

    def __init__(
        self,
        model: Model,
        T_target: Array,
        kind: TargetKind,
        tool_axis: int,
        weight: float,
        joint_effects: PerturbationFunction | None = None,
    ) -> None:
        self.model = model
        self.effects = joint_effects
        self.T = T_target
        self.kind = kind
        self.k = tool_axis
        self.w = weight
        self.rows = 3 if kind == "position" else 6

    def evaluate(self, q: Array, idx: NDArray[np.intp]) -> tuple[Array, Array, Array, Array]:
        """For configurations ``q`` (m, dof) solving targets ``idx``: weighted residuals
        ``e`` (m, rows), weighted Jacobians ``J`` (m, rows, dof), position errors (m)
        and angle errors (rad)."""
        model = self.model
        d = None if self.effects is None else self.effects(q)
        T = model.fk(q, d)
        Jg = model.joint_jacobian(q, d)
        Tt = self.T[idx]
        e_p = Tt[:, :3, 3] - T[:, :3, 3]
        dist = np.linalg.norm(e_p, axis=1)
        if self.kind == "position":
            return e_p, Jg[:, :3], dist, np.zeros(len(q))
        R = T[:, :3, :3]
        if self.kind == "pose":
            e_r = spatial.matrix_to_rotvec(Tt[:, :3, :3] @ np.swapaxes(R, -1, -2))
            angle = np.linalg.norm(e_r, axis=1)
            J_r = Jg[:, 3:]
        else:
            a = R[:, :, self.k]
            a_t = Tt[:, :3, self.k]
            c = np.cross(a, a_t)
            s = np.linalg.norm(c, axis=1)
            angle = np.arctan2(s, np.einsum("ij,ij->i", a, a_t))
            # rotation vector perpendicular to a that turns a onto a_t; at 180° any
            # perpendicular axis works: take one from the Jacobian's own frame
            with np.errstate(invalid="ignore", divide="ignore"):
                u = np.where(s[:, None] > 1e-12, c / s[:, None], 0.0)
            flip = (s <= 1e-12) & (angle > 1.0)
            if flip.any():
                u[flip] = R[flip][:, :, (self.k + 1) % 3]
            e_r = u * angle[:, None]
            P = np.eye(3) - a[:, :, None] * a[:, None, :]
            J_r = P @ Jg[:, 3:]
        e = np.concatenate([e_p, self.w * e_r], axis=1)
        J = np.concatenate([Jg[:, :3], self.w * J_r], axis=1)
        return e, J, dist, angle


def _lm_step(J: Array, e: Array, mu: Array) -> Array:
    """Damped least-squares steps ``dq`` (m, dof) minimising |J dq − e|² + mu |dq|²."""
    _, rows, dof = J.shape
    if rows < dof:  # dual form: dq = Jᵀ (J Jᵀ + mu I)⁻¹ e, a rows x rows solve
        A = J @ np.swapaxes(J, 1, 2) + mu[:, None, None] * np.eye(rows)
        y = np.linalg.solve(A, e[:, :, None])
        return (np.swapaxes(J, 1, 2) @ y)[:, :, 0]
    A = np.swapaxes(J, 1, 2) @ J + mu[:, None, None] * np.eye(dof)
    g = np.einsum("mrd,mr->md", J, e)
    return np.linalg.solve(A, g[:, :, None])[:, :, 0]


def _run_lm(
    problem: Problem,
    q_start: Array,
    idx: NDArray[np.intp],
    limits: Array,
    tol: float,
    tol_angle: float,
    max_iter: int,
    damping: float,
) -> tuple[Array, Array, Array, NDArray[np.int64]]:
    """Projected Levenberg–Marquardt from ``q_start`` (m, dof) for targets ``idx``.

    Returns final configurations, position errors, angle errors and iteration counts.
    """
    lo, hi = limits[:, 0], limits[:, 1]
    q = np.clip(q_start, lo, hi)
    m = len(q)
    e, J, dist, angle = problem.evaluate(q, idx)
    cost = np.einsum("ij,ij->i", e, e)
    scale = np.einsum("mrd,mrd->m", J, J) / J.shape[2] + 1e-30  # mean squared column norm
    mu = damping * scale
    iters = np.zeros(m, dtype=np.int64)
    # converge well past the reachability tolerance: Newton's quadratic convergence
    # makes the last steps nearly free, and callers (compensation) want exact joints
    done_p, done_a = 1e-4 * tol, 1e-4 * tol_angle
    active = np.flatnonzero(~((dist < done_p) & (angle < done_a)))
    for _ in range(max_iter):
        if not len(active):
            break
        qa, ea, Ja = q[active], e[active], J[active]
        cost_before = cost[active]
        g = np.einsum("mrd,mr->md", Ja, ea)  # descent direction in joint space
        frozen = ((qa <= lo + 1e-12) & (g < 0)) | ((qa >= hi - 1e-12) & (g > 0))
        if frozen.any():
            Ja = Ja * ~frozen[:, None, :]
        dq = _lm_step(Ja, ea, mu[active])
        q_new = np.clip(qa + dq, lo, hi)
        e_n, J_n, dist_n, angle_n = problem.evaluate(q_new, idx[active])
        cost_n = np.einsum("ij,ij->i", e_n, e_n)
        iters[active] += 1
        ok = cost_n < cost[active]
        acc = active[ok]
        q[acc], e[acc], J[acc] = q_new[ok], e_n[ok], J_n[ok]
        dist[acc], angle[acc], cost[acc] = dist_n[ok], angle_n[ok], cost_n[ok]
        mu[acc] = np.maximum(mu[acc] / 3.0, 1e-15 * scale[acc])
        rej = active[~ok]
        mu[rej] *= 4.0
        step = np.abs(q_new - qa).max(axis=1)
        converged = (dist[active] < done_p) & (angle[active] < done_a)
        # stalled: a local minimum (unreachable target or a joint limit in the way)
        slow = ok & (cost[active] > (1.0 - 1e-6) * cost_before)
        stalled = (mu[active] > 1e8 * scale[active]) | (ok & (step < 1e-13)) | slow
        active = active[~(converged | stalled)]
    return q, dist, angle, iters


def solve_ik(  # noqa: PLR0913 - keyword-only options of a public function
    model: Model,
    targets: ArrayLike,
    *,
    kind: TargetKind | Literal["auto"] = "auto",
    q0: ArrayLike | None = None,
    restarts: int = 20,
    seed: int | np.random.Generator | None = 0,
    tol: float = 1e-6,
    tol_angle: float = 1e-6,
    max_iter: int = 100,
    tool_axis: int = 2,
    orientation_weight: float = 1.0,
    damping: float = 1e-3,
    seed_pool: int = 50000,
    joint_effects: PerturbationFunction | None = None,
) -> IKResult:
    """Joint values that put the tool on ``targets``, batched over targets.

    Args:
        model: any chain model (uses ``fk``, ``joint_jacobian`` and ``joint_limits``).
        targets: positions ``(n, 3)`` / ``(3,)`` (m) or tool frames ``(n, 4, 4)`` /
            ``(4, 4)`` in the model's base frame.
        kind: ``"position"``, ``"pose"``, ``"axis"`` (position + one tool axis, see the
            module docstring) or ``"auto"`` (position for ``(n, 3)``, pose for frames).
        q0: starting configurations ``(n, dof)`` or one ``(dof,)`` for all targets;
            random (seeded) when None.
        restarts: extra random starting configurations tried for targets not yet
            reached (0 keeps the solutions from ``q0`` only).
        seed: seed or generator for the random starts.
        tol: position tolerance (m) for ``reachable``.
        tol_angle: orientation tolerance (rad) for ``reachable``.
        max_iter: LM iterations per start.
        tool_axis: the tool-frame axis (0, 1, 2 = x, y, z) imposed by ``kind="axis"``.
        orientation_weight: weight (m/rad) of orientation rows in the objective.
        damping: initial LM damping relative to the mean squared Jacobian column norm.
        seed_pool: size of a fixed pool of random configurations (built once per model
            and cached, with a k-d tree over their tool frames): without ``q0`` each
            target starts from the pool configuration whose tool frame is nearest to the
            target, and restarts alternate between next-nearest pool configurations and
            fresh random ones (0: random starts only).
        joint_effects: configuration-dependent joint perturbations ``q (m, dof) ->
            (m, dof, 3)`` (or None) applied at every iterate (module docstring); the
            starting configurations from the pool ignore them.

    Returns:
        :class:`IKResult`; ``q`` is ``(n, dof)`` even for a single target.
    """
    T, kind = target_array(targets, kind)
    n, dof = len(T), model.dof
    _check_options(tool_axis, restarts, max_iter, tol, tol_angle)
    q_start = None if q0 is None else _start_configurations(q0, n, model)
    problem = Problem(model, T, kind, tool_axis, float(orientation_weight), joint_effects)
    if n == 0:
        empty = np.zeros(0)
        zeros = np.zeros(0, np.int64)
        return IKResult(np.zeros((0, dof)), empty, empty, np.zeros(0, bool), zeros, zeros, kind)
    search = _Search(
        problem, np.random.default_rng(seed), tol, tol_angle, max_iter, damping, seed_pool, restarts
    )
    idx = np.arange(n)
    if q_start is None:
        q_start = search.nearest(0, idx)
        search.used_near = 1
        if q_start is None:
            q_start = random_configurations(model, n, search.rng)
    q, dist, angle, iters = search.run(q_start, idx)
    seeds_used = np.ones(n, dtype=np.int64)
    search.restart(q, dist, angle, iters, seeds_used, restarts, orientation_weight**2)
    reachable = (dist < tol) & (angle < tol_angle)
    return IKResult(
        q=q,
        position_error=dist,
        angle_error=angle,
        reachable=reachable,
        iterations=iters,
        seeds_used=seeds_used,
        kind=kind,
    )


def _check_options(tool_axis: int, restarts: int, max_iter: int, tol: float, tol_angle: float) -> None:
    if tool_axis not in (0, 1, 2):
        raise ValueError(f"tool_axis must be 0, 1 or 2 (x, y, z), got {tool_axis!r}")
    if restarts < 0 or max_iter < 1:
        raise ValueError(f"restarts must be >= 0 and max_iter >= 1, got {restarts}, {max_iter}")
    if not (tol > 0 and tol_angle > 0):
        raise ValueError(f"tolerances must be positive, got tol={tol}, tol_angle={tol_angle}")


def _start_configurations(q0: ArrayLike, n: int, model: Model) -> Array:
    """``q0`` as ``(n, dof)`` starting configurations (one ``(dof,)`` row serves every target)."""
    dof = model.dof
    q_start = np.asarray(q0, dtype=float)
    if q_start.ndim == 1:
        q_start = np.broadcast_to(q_start, (n, len(q_start)))
    if q_start.shape != (n, dof):
        raise ValueError(
            f"q0 shaped {np.shape(q0)} does not fit {n} targets of model {model.name!r} "
            f"with {dof} joints; expected ({n}, {dof}) or ({dof},)"
        )
    if not np.all(np.isfinite(q_start)):
        raise ValueError("q0 contains NaN or inf")
    return q_start


class _Search:
    """Starting configurations and LM runs of one :func:`solve_ik` call: q0, else the pool
    configuration nearest to the target; restarts alternate between the next-nearest pool
    configurations and fresh random ones."""

    def __init__(
        self,
        problem: Problem,
        rng: np.random.Generator,
        tol: float,
        tol_angle: float,
        max_iter: int,
        damping: float,
        seed_pool: int,
        restarts: int,
    ) -> None:
        self.problem, self.rng = problem, rng
        self.limits = problem.model.joint_limits
        self.tol, self.tol_angle, self.max_iter, self.damping = tol, tol_angle, max_iter, damping
        self.seed_pool = int(seed_pool)
        self.max_rank = 1 + (restarts + 1) // 2
        self.used_near = 0

    def nearest(self, rank: int, rows: NDArray[np.intp]) -> Array | None:
        """Starts for targets ``rows``: their ``rank``-th nearest pool configurations."""
        if self.seed_pool <= 0 or rank >= min(self.max_rank, self.seed_pool):
            return None
        return nearest_pool(self.problem, self.seed_pool, rows, rank)

    def run(self, q_start: Array, rows: NDArray[np.intp]) -> tuple[Array, Array, Array, NDArray[np.int64]]:
        return _run_lm(
            self.problem, q_start, rows, self.limits, self.tol, self.tol_angle, self.max_iter, self.damping
        )

    def restart(
        self,
        q: Array,
        dist: Array,
        angle: Array,
        iters: NDArray[np.int64],
        seeds_used: NDArray[np.int64],
        restarts: int,
        w2: float,
    ) -> None:
        """Restarts in rounds of 1, 2, 4, 8, 8, ... starts per unreached target, solved together;
        the arrays are updated in place where a restart does better."""

        def badness(d: Array, a: Array) -> Array:
            return d**2 + w2 * a**2

        remaining, rounds, slot = restarts, 0, 0
        while remaining > 0:
            todo = np.flatnonzero(~((dist < self.tol) & (angle < self.tol_angle)))
            if not len(todo):
                break
            k = min(2**rounds, 8, remaining)
            starts = []
            for _ in range(k):
                start = self.nearest(self.used_near, todo) if slot % 2 == 0 else None
                if start is None:
                    start = random_configurations(self.problem.model, len(todo), self.rng)
                else:
                    self.used_near += 1
                starts.append(start)
                slot += 1
            q_r, d_r, a_r, it_r = self.run(np.concatenate(starts), np.tile(todo, k))
            bad_r = badness(d_r, a_r).reshape(k, len(todo))
            best = np.argmin(bad_r, axis=0)
            pick = best * len(todo) + np.arange(len(todo))
            better = bad_r[best, np.arange(len(todo))] < badness(dist[todo], angle[todo])
            sel = todo[better]
            q[sel], dist[sel], angle[sel] = q_r[pick[better]], d_r[pick[better]], a_r[pick[better]]
            iters[todo] += it_r.reshape(k, len(todo)).sum(axis=0)
            seeds_used[todo] += k
            remaining -= k
            rounds += 1
