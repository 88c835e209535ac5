"""How far any pose set can get: an upper bound on the O1 of every design from one design
(Kiefer–Wolfowitz equivalence theorem), so that a selection can be certified near-optimal
and impossible targets recognised."""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
import scipy.linalg
from numpy.typing import ArrayLike, NDArray

from robocal.identify.observability_indices import (
    Rows,
    identifiable_parameters,
    observability_indices,
    scaled_jacobian,
    singular_values,
)
from robocal.model.chain import Model

__all__ = ["DesignBound", "design_efficiency_bound"]

Array = NDArray[np.float64]


@dataclass(frozen=True)
class DesignBound:
    """Result of :func:`design_efficiency_bound`.

    Attributes:
        o1: O1 of the design (``"tolerance"`` column scaling, as :func:`observability`).
        max_variance: ``max d(q)`` over the candidates, the design's own poses and the
            polished maxima (dimensionless; ``inf`` when the design does not make every
            parameter observable).
        n_params: ``p``, the number of parameters.
        efficiency: ``p / max d`` ∈ [0, 1], a lower bound on the design's D-efficiency
            ``(det M(ξ) / det M*)^(1/p)`` relative to the best design of any size on
            the candidate region.
        o1_ratio_bound: ``(max d / p)^(1/2)`` ≥ 1, an upper bound on ``O1(any design) /
            O1(this design)``.
        o1_upper: ``o1 · o1_ratio_bound``, an upper bound on the O1 of any design.
        q_max: ``(dof,)`` the configuration where ``d`` is largest (the pose the
            design misses most).
    """

    o1: float
    max_variance: float
    n_params: int
    efficiency: float
    o1_ratio_bound: float
    o1_upper: float
    q_max: Array


def design_efficiency_bound(
    model: Model,
    poses: ArrayLike,
    candidates: ArrayLike,
    *,
    rows: Rows = "position",
    params: Sequence[str] | None = None,
    polish: int = 8,
) -> DesignBound:
    """Upper bound on the O1 that *any* set of poses can reach, from one design.

    For a design ``ξ`` of ``n`` poses ``q_i`` with per-pose Jacobian blocks ``B_i``
    (``3 x p`` or ``6 x p``), let ``M = Σ B_iᵀ B_i / n`` (so ``O1 = det(M)^(1/(2p))``:
    the singular values of the stacked ``J`` are the square roots of the eigenvalues of
    ``n M``) and let ``d(q) = trace(B_q M⁻¹ B_qᵀ)`` be its variance function.  For any
    other design ``ξ'`` (any size, any weights) with information ``M'``, the AM–GM
    inequality on the eigenvalues of ``M⁻¹ M'`` gives

        det M' / det M ≤ (trace(M⁻¹ M') / p)^p = (mean_ξ' d / p)^p ≤ (max_q d(q) / p)^p,

    hence ``O1(ξ') / O1(ξ) ≤ (max_q d / p)^(1/2)`` and the D-efficiency of ``ξ`` is at
    least ``p / max_q d`` (the weaker ``exp(1 − max d / p)`` follows from the concavity
    of log det).  By the Kiefer–Wolfowitz equivalence theorem the D-optimal
    approximate design has ``max_q d = p`` (Kiefer & Wolfowitz 1960, "The equivalence
    of two extremum problems", Canad. J. Math. 12, 363–366); efficiency bounds of this
    kind are in Atwood 1969, "Optimal and efficient designs of experiments", Ann.
    Math. Statist. 40, 1570–1602.  ``d`` does not depend on the column scaling (nor on
    any invertible reparametrisation), so neither does the bound.

    The maximum is taken over ``candidates``, the design's poses and local maxima of
    ``d`` found by L-BFGS-B (within the joint limits, central-difference gradient)
    from the ``polish`` best candidates.  The bound is rigorous for designs whose
    poses are among those points; for the continuous joint space it holds as far as
    that search finds the global maximum of ``d`` (a dense candidate sample, e.g.
    :func:`robocal.measure.ik.random_configurations`, plus polishing).

    Args:
        model: the robot.
        poses: ``(n, dof)`` the design (rad / m).
        candidates: ``(N, dof)`` configurations spanning the region of interest.
        rows: ``"position"`` or ``"pose"`` measurements.
        params: parameters (default: the identifiable subset over ``candidates``, as in
            :func:`select_poses`).
        polish: number of best candidates to start the local maximisation from (0:
            candidates only).
    """
    Q = np.atleast_2d(np.asarray(poses, dtype=float))
    C = np.atleast_2d(np.asarray(candidates, dtype=float))
    if Q.shape[1] != model.dof or C.shape[1] != model.dof:
        raise ValueError(f"poses {Q.shape} and candidates {C.shape} must have {model.dof} columns")
    if params is None:
        params = identifiable_parameters(model, C, rows=rows).kept
    Js, _, names = scaled_jacobian(model, Q, rows=rows, params=params, scale="tolerance")
    p = len(names)
    o1 = observability_indices(singular_values(Js), len(Q), p).O1
    M = Js.T @ Js / len(Q)
    lam = np.linalg.eigvalsh(M)
    if lam[0] <= 1e-12 * max(lam[-1], 1e-300):
        return DesignBound(o1, math.inf, p, 0.0, math.inf, math.inf, C[0].copy())
    variance = _variance_function(model, rows, names, np.linalg.cholesky(M))
    points = np.r_[C, Q]
    best, q_best = _largest_variance(model, variance, points, polish)
    ratio = math.sqrt(best / p)
    return DesignBound(o1, best, p, p / best, ratio, o1 * ratio, q_best)


def _variance_function(
    model: Model, rows: Rows, names: Sequence[str], L: NDArray[np.floating]
) -> Callable[[Array], Array]:
    """``d(q) = trace(B_q M⁻¹ B_qᵀ)`` of configurations ``X`` ``(k, dof)`` -> ``(k,)``, with
    ``L`` the Cholesky factor of the design's information ``M`` (``"tolerance"`` scaling)."""
    r, p = (3 if rows == "position" else 6), len(names)

    def variance(X: Array) -> Array:
        B = scaled_jacobian(model, X, rows=rows, params=names, scale="tolerance")[0]
        Y = scipy.linalg.solve_triangular(L, B.T, lower=True)  # (p, r·len(X))
        return np.sum(Y.reshape(p, len(X), r) ** 2, axis=(0, 2))

    return variance


def _largest_variance(
    model: Model, variance: Callable[[Array], Array], points: Array, polish: int
) -> tuple[float, Array]:
    """The largest ``variance`` over ``points`` ``(k, dof)`` and over the local maxima found by
    L-BFGS-B (within the joint limits, central-difference gradient) from the ``polish`` best
    points: the value and its configuration ``(dof,)``."""
    import scipy.optimize  # here: reading a calibration (robocal validate, report) needs none of it

    d = variance(points)
    k = int(np.argmax(d))
    best, q_best = float(d[k]), points[k].copy()
    lim = model.joint_limits
    bounds = [(lo if np.isfinite(lo) else None, hi if np.isfinite(hi) else None) for lo, hi in lim]
    h, eye = 1e-6, np.eye(model.dof)

    def negative(q: Array) -> tuple[float, Array]:
        dq = variance(np.r_[q[None], q + h * eye, q - h * eye])
        return -float(dq[0]), -(dq[1 : model.dof + 1] - dq[model.dof + 1 :]) / (2 * h)

    for i in np.argsort(-d)[: max(int(polish), 0)]:
        start = np.clip(points[i], lim[:, 0], lim[:, 1])
        res = scipy.optimize.minimize(negative, start, jac=True, method="L-BFGS-B", bounds=bounds)
        if -res.fun > best:
            best, q_best = float(-res.fun), np.asarray(res.x, dtype=float)
    return best, q_best
