"""Seed 003 ch. 3: configuration-dependent influence analysis and per-pose identification.

The thesis (§3.5-3.6) identifies the geometric errors pose by pose, then combines them:

* **Influence analysis (§3.5, Fig. 3.8).**  Each parameter is given a test deviation,
  +0.05° on angles and +0.1 mm on lengths, and the displacement of the tool point it
  causes is computed at every pose (a finite deviation of the model, as the thesis
  simulates it).  At each pose the influence vector ``k`` is each parameter's
  displacement divided by the largest one at that pose (the most influential parameter
  has ``k = 1``).  :func:`influence_analysis`.
* **Per-pose identification (eq. 3.6).**  At pose ``i`` (three position equations,
  ``p`` unknowns) the correction ``ΔE = Jᵢᵀ(JᵢJᵢᵀ)⁻¹ΔPᵢ`` is applied and the remaining
  error recomputed with eq. 3.5 (``ΔP ← ΔP − JᵢΔE``), repeated until the error is below
  the measurement resolution (0.01 mm): a parameter set ``Eᵢ`` per pose.
* **Influence-based identification (eqs. 3.7-3.8).**  The same, with each correction
  multiplied by the pose's influence vector and by ``C < 1``:
  ``ΔE = C·k∘Jᵢᵀ(JᵢJᵢᵀ)⁻¹ΔP``.  Because ``0 < k ≤ 1`` and ``C < 1`` every step shrinks the
  error (the step's error map has eigenvalues in (0, 1]), and the sum of the steps tends
  to ``K Jᵢᵀ(Jᵢ K Jᵢᵀ)⁻¹ΔPᵢ`` (``K = diag k``), the correction of least
  ``Σⱼ ΔEⱼ²/kⱼ``: the pose's error is put on the parameters that influence it most.  ``C``
  changes the number of iterations, not where they end (up to the resolution).
* **The best-fit set (§3.6).**  "From the sets of errors in the kinematics parameters of
  all poses, a set of kinematics parameters is calculated that best fit the accuracy to
  all measured poses."  The thesis does not give the formula; three readings
  (``combine``):

  ``"mean"``  the set nearest to all per-pose sets, argmin_E Σᵢ |E − Eᵢ|² = the mean of
              the sets (the default);
  ``"best"``  the per-pose set with the smallest mean |ΔP| over all poses;
  ``"fit"``   the set that best reproduces every pose's corrected position,
              argmin_E Σᵢ |Jᵢ(E − Eᵢ)|².  Every per-pose set reproduces its pose's error
              (JᵢEᵢ = ΔPᵢ up to the resolution), so this *is* linear least squares over
              all poses and ``k`` cannot change it.

Unknowns are measured in units of their test deviation (0.05°, 0.1 mm; effect
coefficients: the value that moves the tool by 0.1 mm at the robot's size), so that the
minimum-norm corrections weigh an angle and a length as the thesis' analysis does.

One pass is the thesis' procedure (its errors are small, its model linear); ``passes``
repeats it from the combined set, relinearised, until the set stops moving.  Repeating
the ``"mean"`` pass is Cimmino's method of averaged projections: with data the model
fits exactly it ends at the least-squares solution; with errors the model cannot
describe it ends where the per-pose corrections balance, Σᵢ Mᵢ ΔPᵢ = 0 (``Mᵢ`` the
pose's correction map), a per-pose weighting that differs from least squares.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from robocal.identify.solve_result import SolveResult

__all__ = [
    "ANGULAR_STEP",
    "LINEAR_STEP",
    "InfluenceAnalysis",
    "PerPoseSets",
    "deviation_steps",
    "influence_analysis",
    "per_pose_sets",
    "solve_per_pose",
]

Array = NDArray[np.float64]
Combine = Literal["mean", "best", "fit"]

#: the thesis' test deviations (§3.5): +0.05° on angles, +0.1 mm on lengths
ANGULAR_STEP = math.radians(0.05)
LINEAR_STEP = 1e-4


def deviation_steps(problem, angular_step: float = ANGULAR_STEP, linear_step: float = LINEAR_STEP) -> Array:
    """``(p,)`` test deviation of each unknown of ``problem`` (rad or m; an effect
    coefficient: the value that moves the tool by ``linear_step`` at the robot's size)."""
    rot = np.array([s.is_rotation for s in problem.chain.steps if s.free], dtype=bool)
    geometric = np.where(rot, angular_step, linear_step)
    n_geo = len(geometric)
    effects = linear_step / problem.free_scale[n_geo:]
    return np.concatenate([geometric, effects])


@dataclass(frozen=True)
class InfluenceAnalysis:
    """Seed 003 Fig. 3.8: what each parameter's test deviation does to the tool at each pose.

    Attributes:
        names: the ``p`` parameters.
        steps: ``(p,)`` their test deviations (rad or m).
        displacement_mm: ``(n, p)`` tool-point displacement caused by each deviation at
            each pose (mm).
        k: ``(n, p)`` the influence vectors: displacement over the pose's largest one
            (for pose measurements, of the weighted position and orientation change).
    """

    names: tuple[str, ...]
    steps: Array
    displacement_mm: Array
    k: Array

    @property
    def minimum_mm(self) -> Array:
        return self.displacement_mm.min(axis=0)

    @property
    def maximum_mm(self) -> Array:
        return self.displacement_mm.max(axis=0)

    @property
    def average_mm(self) -> Array:
        return self.displacement_mm.mean(axis=0)

    @property
    def k_of_average(self) -> Array:
        """The k ratios of the average influence (the thesis' example: θ2 0.34 mm -> k = 1,
        α2 -> 0.59)."""
        a = self.average_mm
        return a / max(float(a.max()), 1e-300)

    def table(self) -> dict[str, dict[str, float]]:
        """name -> minimum, maximum, average displacement (mm), k of the average, and how
        many poses it is the most influential parameter at."""
        top = np.bincount(np.argmax(self.displacement_mm, axis=1), minlength=len(self.names))
        return {
            name: {
                "minimum_mm": float(self.minimum_mm[j]),
                "maximum_mm": float(self.maximum_mm[j]),
                "average_mm": float(self.average_mm[j]),
                "k_of_average": float(self.k_of_average[j]),
                "k_min": float(self.k[:, j].min()),
                "k_max": float(self.k[:, j].max()),
                "most_influential_poses": int(top[j]),
            }
            for j, name in enumerate(self.names)
        }


def influence_analysis(
    problem, x: Array, angular_step: float = ANGULAR_STEP, linear_step: float = LINEAR_STEP
) -> InfluenceAnalysis:
    """Seed 003 §3.5: impose each test deviation on the model at ``x`` and measure the tool
    point's displacement at every pose of ``problem`` (finite deviations, not derivatives)."""
    x = np.asarray(x, dtype=float)
    steps = deviation_steps(problem, angular_step, linear_step)
    n, width = len(problem.q), problem.rows
    p0 = problem.predicted(x)[:, :3, 3]
    r0 = problem.residual(x).reshape(n, width)
    moved = np.empty((n, len(x)))
    weighted = np.empty((n, len(x)))
    for j, step in enumerate(steps):
        xj = x.copy()
        xj[j] += step
        moved[:, j] = np.linalg.norm(problem.predicted(xj)[:, :3, 3] - p0, axis=1)
        weighted[:, j] = np.linalg.norm(problem.residual(xj).reshape(n, width) - r0, axis=1)
    # k on the rows the problem measures, as weighted there (position: the displacement;
    # pose: with the orientation rows, or the tool's rotations would never be corrected)
    top = np.maximum(weighted.max(axis=1, keepdims=True), 1e-300)
    return InfluenceAnalysis(tuple(problem.free_names), steps, moved * 1e3, weighted / top)


@dataclass(frozen=True)
class PerPoseSets:
    """The per-pose parameter sets of one pass.

    Attributes:
        corrections: ``(n, p)`` each pose's correction ``Eᵢ − x`` (the unknowns' units).
        iterations: ``(n,)`` iterations each pose needed.
        remaining_mm: ``(n,)`` each pose's linearised position error left (mm).
    """

    corrections: Array
    iterations: Array
    remaining_mm: Array


def per_pose_sets(
    problem,
    x: Array,
    k: Array | None = None,
    *,
    relaxation: float = 1.0,
    resolution: float = 1e-5,
    max_iterations: int = 10_000,
) -> PerPoseSets:
    """Eq. 3.6 (``k=None``, ``relaxation=1``) or eqs. 3.7-3.8 (influence vectors ``k``
    ``(n, p)``, ``relaxation`` = C < 1) at every pose, linearised at ``x``: repeat
    ``ΔE = C·k∘Jᵢᵀ(JᵢJᵢᵀ)⁻¹ΔP``, ``ΔP ← ΔP − JᵢΔE`` until |ΔP| < ``resolution`` (m)."""
    if not 0 < relaxation <= 1:
        raise ValueError(f"the relaxation C must be in (0, 1], got {relaxation}")
    x = np.asarray(x, dtype=float)
    width = problem.rows
    n = len(problem.q)
    w = problem.weights.reshape(n, width)
    scale = deviation_steps(problem)  # unknowns in units of their test deviation
    J = problem.jacobian(x).reshape(n, width, -1) * scale  # weighted rows (1/σ), as the other methods
    r = -problem.residual(x).reshape(n, width)  # ΔP = measured − predicted (weighted)
    JJt_inv = np.linalg.pinv(J @ J.transpose(0, 2, 1), rcond=1e-12, hermitian=True)
    Jplus = J.transpose(0, 2, 1) @ JJt_inv  # (n, p, w): Jᵢᵀ(JᵢJᵢᵀ)⁻¹
    gain = relaxation * (np.ones((n, J.shape[2])) if k is None else np.asarray(k, dtype=float))
    e = np.zeros((n, J.shape[2]))
    iterations = np.zeros(n, dtype=int)
    active = np.ones(n, dtype=bool)
    for _ in range(max_iterations):
        error = np.linalg.norm(r[:, :3] / w[:, :3], axis=1)
        active &= error >= resolution
        if not active.any():
            break
        step = gain[active] * np.einsum("npw,nw->np", Jplus[active], r[active])
        e[active] += step
        r[active] -= np.einsum("nwp,np->nw", J[active], step)
        iterations[active] += 1
    remaining = np.linalg.norm(r[:, :3] / w[:, :3], axis=1) * 1e3
    return PerPoseSets(e * scale, iterations, remaining)


def _combine(problem, x: Array, sets: PerPoseSets, how: Combine) -> Array:
    """The best-fit set from the per-pose sets (see the module docstring)."""
    if how == "mean":
        return x + sets.corrections.mean(axis=0)
    if how == "best":
        n, width = len(problem.q), problem.rows
        scores = [
            np.linalg.norm(problem.residual(x + e, weighted=False).reshape(n, width)[:, :3], axis=1).mean()
            for e in sets.corrections
        ]
        return x + sets.corrections[int(np.argmin(scores))]
    if how == "fit":
        n, width = len(problem.q), problem.rows
        J = problem.jacobian(x).reshape(n, width, -1)
        targets = np.einsum("nwp,np->nw", J, sets.corrections).reshape(-1)
        A = J.reshape(n * width, -1)
        norms = np.linalg.norm(A, axis=0)
        norms[norms == 0] = 1.0
        return x + np.linalg.lstsq(A / norms, targets, rcond=None)[0] / norms
    raise ValueError(f"combine must be 'mean', 'best' or 'fit', got {how!r}")


def _correction_maps(problem, x: Array, k: Array | None) -> tuple[Array, Array]:
    """Each pose's limit correction map ``Mᵢ = K Jᵢᵀ(Jᵢ K Jᵢᵀ)⁻¹`` (``(n, p, w)``, unknowns'
    units, weighted rows; ``K = I`` for eq. 3.6) and the weighted Jacobian ``(n, w, p)``."""
    n, width = len(problem.q), problem.rows
    scale = deviation_steps(problem)
    J = problem.jacobian(x).reshape(n, width, -1)
    Js = J * scale
    gain = np.ones((n, J.shape[2])) if k is None else np.asarray(k, dtype=float)
    JK = Js * gain[:, None, :]
    inv = np.linalg.pinv(JK @ Js.transpose(0, 2, 1), rcond=1e-12)
    M = JK.transpose(0, 2, 1) @ inv * scale[None, :, None]
    return M, J


def _balanced_step(problem, x: Array, k: Array | None) -> Array:
    """A Newton step towards the set where the per-pose corrections balance,
    Σᵢ Mᵢ ΔPᵢ(E) = 0: the limit of repeating the ``"mean"`` pass, reached in a few steps."""
    M, J = _correction_maps(problem, x, k)
    r = -problem.residual(x).reshape(len(problem.q), problem.rows)
    g = np.einsum("npw,nw->p", M, r)
    A = np.einsum("npw,nwq->pq", M, J)
    scale = deviation_steps(problem)
    return np.linalg.lstsq(A * scale, g, rcond=1e-12)[0] * scale


def solve_per_pose(
    problem,
    x0: Array,
    *,
    influence: bool = True,
    relaxation: float = 0.5,
    resolution: float = 1e-5,
    combine: Combine = "mean",
    passes: int | None = None,
    max_iterations: int = 200,
) -> SolveResult:
    """Seed 003's identification: per-pose sets (eq. 3.6, or eqs. 3.7-3.8 when
    ``influence``), combined into one set (``combine``).

    ``passes=N`` repeats the thesis' pass N times (``1``: the thesis' procedure), each
    relinearised at the combined set.  ``None``: until the combined set stops moving
    (it moves the tool by less than a thousandth of ``resolution``, at most
    ``max_iterations`` steps); for ``"mean"`` by Newton steps on Σᵢ Mᵢ ΔPᵢ(E) = 0 (the
    limit of repeated passes, which averaged projections approach only slowly)."""
    if combine not in ("mean", "best", "fit"):
        raise ValueError(f"combine must be 'mean', 'best' or 'fit', got {combine!r}")
    if influence and not 0 < relaxation < 1:
        raise ValueError(f"the influence method needs 0 < C < 1, got C={relaxation}")
    x = np.asarray(x0, dtype=float).copy()
    history: list[float] = []
    limit = max_iterations if passes is None else passes
    for it in range(1, limit + 1):
        history.append(float(np.sqrt(np.mean(problem.residual(x, weighted=False) ** 2))))
        k = influence_analysis(problem, x).k if influence else None
        if passes is None and combine == "mean":
            x_new = x + _balanced_step(problem, x, k)
        else:
            c = relaxation if influence else 1.0
            sets = per_pose_sets(problem, x, k, relaxation=c, resolution=resolution)
            x_new = _combine(problem, x, sets, combine)
        moved = float(np.max(np.abs(x_new - x) * problem.free_scale))
        x = x_new
        # per-pose sets stop at the resolution, so repeated passes move by a fraction of it
        tol = 1e-3 * resolution if combine == "mean" else 0.1 * resolution
        if passes is None and moved < tol:
            return SolveResult(x, True, f"the combined set stopped moving ({it} passes)", it, it, history)
    if passes is not None:
        return SolveResult(x, True, f"{passes} pass(es) of per-pose identification", passes, passes, history)
    return SolveResult(x, False, f"no convergence in {max_iterations} passes", limit, limit, history)
