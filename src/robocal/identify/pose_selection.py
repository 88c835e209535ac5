"""Optimal pose selection (greedy construction and DETMAX exchanges) and the design-efficiency bound."""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np
import scipy.linalg
import scipy.optimize
from numpy.typing import ArrayLike, NDArray

from robocal.identify.identifiable import (
    identifiable_parameters,
)
from robocal.identify.indices import ANGLE_TOLERANCE as ANGLE_TOLERANCE
from robocal.identify.indices import (
    INDICES,
    IndexName,
    ObservabilityIndices,
    Rows,
    observability_indices,
    scaled_jacobian,
    singular_values,
)
from robocal.identify.indices import LENGTH_TOLERANCE as LENGTH_TOLERANCE
from robocal.model.chain import Model

Array = NDArray[np.float64]


# ------------------------------------------------------------------------ pose selection
@dataclass(frozen=True)
class PoseSelection:
    """Result of :func:`select_poses`.

    Attributes:
        indices: ``(n,)`` rows of the candidate pool that were selected (in the order
            they ended up in the selection).
        q: ``(n, dof)`` the selected configurations.
        index: the index maximised (``"O1"`` .. ``"O5"``).
        value: its value for the selection (exact, from the SVD of the scaled ``J``).
        greedy_value: its value after the greedy construction, before exchanges.
        indices_all: all five indices of the selection.
        params: parameters the Jacobian was built for.
        scale: ``(p,)`` column scale factors used.
        swaps: accepted exchanges.
        passes: exchange passes over the selection.
    """

    indices: NDArray[np.intp]
    q: Array
    index: str
    value: float
    greedy_value: float
    indices_all: ObservabilityIndices
    params: tuple[str, ...]
    scale: Array
    swaps: int
    passes: int


def _index_from_eig(lam: Array, n: int, name: str) -> Array:
    """Index ``name`` from eigenvalues ``(..., p)`` (ascending) of ``J_sᵀ J_s``."""
    s = np.sqrt(np.maximum(lam, 0.0))
    smin, smax = s[..., 0], s[..., -1]
    with np.errstate(divide="ignore", invalid="ignore"):
        if name == "O1":
            out = np.exp(np.mean(np.log(np.maximum(s, 1e-300)), axis=-1)) / math.sqrt(n)
        elif name == "O2":
            out = smin / smax
        elif name == "O3":
            out = smin
        elif name == "O4":
            out = smin**2 / smax
        else:
            out = 1.0 / np.sum(1.0 / s, axis=-1)
    return np.where(smin > 0, out, 0.0)


def _logdet_gain(Minv_solve: Array, B: Array) -> Array:
    """``log det(I + B_c M⁻¹ B_cᵀ)`` for candidate blocks ``B`` ``(N, r, p)``, given
    ``X = M⁻¹ Bᵀ`` laid out as ``(N, p, r)``."""
    G = B @ Minv_solve + np.eye(B.shape[1])
    sign, logdet = np.linalg.slogdet(G)
    return np.where(sign > 0, logdet, -np.inf)


class _Pool:
    """A candidate pool's per-pose blocks ``B`` ``(N, r, p)`` and the index being maximised."""

    def __init__(self, B: Array, index: IndexName, shortlist: int) -> None:
        N, _, p = B.shape
        self.B, self.Bt = B, np.swapaxes(B, 1, 2)
        self.info = np.einsum("nrp,nrq->npq", B, B)  # per-candidate B_cᵀ B_c
        self.ridge = 1e-9 * float(np.trace(self.info.sum(axis=0))) / (N * p)
        self.I_p = np.eye(p)
        self.index, self.shortlist = index, shortlist

    def value(self, M: Array, count: int) -> float:
        lam = np.linalg.eigvalsh(M - self.ridge * self.I_p)
        return float(_index_from_eig(lam, count, self.index))

    def scores(self, M: Array, free: NDArray[np.intp], count: int) -> Array:
        """Index after adding each free candidate to information ``M`` (with ridge)."""
        _, r, p = self.B.shape
        X = np.linalg.solve(M, self.Bt[free].transpose(1, 0, 2).reshape(p, -1))
        gain = _logdet_gain(X.reshape(p, len(free), r).transpose(1, 0, 2), self.B[free])
        if self.index == "O1" or count * r < p:  # determinant while the rank cannot be full
            return gain
        top = np.argsort(-gain)[: max(self.shortlist, 1)]
        lam = np.linalg.eigvalsh(M[None] + self.info[free[top]] - self.ridge * self.I_p)
        out = np.full(len(free), -np.inf)
        out[top] = _index_from_eig(lam, count, self.index)
        return out

    def exchange(
        self, sel: list[int], chosen: NDArray[np.bool_], M: Array, value: float, max_passes: int
    ) -> tuple[int, int]:
        """DETMAX-style exchanges on ``sel``/``chosen`` (updated in place) until no swap helps;
        returns the number of swaps and passes."""
        n = len(sel)
        current = float(np.linalg.slogdet(M)[1]) if self.index == "O1" else value
        swaps = passes = 0
        for passes in range(1, max_passes + 1):  # noqa: B007 - the count is reported
            improved = False
            for pos in range(n):
                out = sel[pos]
                M_minus = M - self.info[out]
                free = np.flatnonzero(~chosen)
                sc = self.scores(M_minus, free, n)
                j = int(np.argmax(sc))
                new = float(np.linalg.slogdet(M_minus)[1]) + sc[j] if self.index == "O1" else sc[j]
                if new > current + 1e-9 * max(abs(current), 1.0):
                    k = int(free[j])
                    chosen[out], chosen[k] = False, True
                    sel[pos] = k
                    M = M_minus + self.info[k]
                    current = new
                    swaps += 1
                    improved = True
            if not improved:
                break
        return swaps, passes


def select_poses(
    model: Model,
    candidates: ArrayLike,
    n: int,
    *,
    index: IndexName = "O1",
    rows: Rows = "position",
    params: Sequence[str] | None = None,
    scale: Literal["norm", "tolerance"] | ArrayLike = "tolerance",
    initial: ArrayLike | None = None,
    max_passes: int = 20,
    shortlist: int = 64,
) -> PoseSelection:
    """Choose ``n`` poses from ``candidates`` ``(N, dof)`` maximising an observability index.

    Greedy construction, then DETMAX-style exchanges (module docstring).

    Args:
        model: the robot (its free parameters define the Jacobian).
        candidates: the candidate pool (e.g. :func:`robocal.measure.poses.random_poses`).
        n: number of poses to select.
        index: ``"O1"`` .. ``"O5"``.
        rows: ``"position"`` or ``"pose"`` measurements.
        params: parameters to make observable; default the identifiable subset of the
            free parameters over the whole pool (unidentifiable ones would make every
            index but O1 zero).
        scale: column scaling (``"tolerance"`` by default, so that values are
            comparable with :func:`observability` of other sets); computed once on the
            pool for ``"norm"``.
        initial: indices into ``candidates`` to start the exchange from instead of the
            greedy construction.
        max_passes: maximum exchange passes.
        shortlist: for O2..O5, candidates per step scored exactly (the best by the O1
            determinant gain).
    """
    if index not in INDICES:
        raise ValueError(f"index must be one of {INDICES}, got {index!r}")
    Q = np.atleast_2d(np.asarray(candidates, dtype=float))
    N = len(Q)
    n = int(n)
    if not 1 <= n <= N:
        raise ValueError(f"cannot select n={n} poses from a pool of {N} candidates")
    if params is None:
        params = identifiable_parameters(model, Q, rows=rows).kept
    Js, s, names = scaled_jacobian(model, Q, rows=rows, params=params, scale=scale)
    r, p = (3 if rows == "position" else 6), len(names)
    design = _Pool(Js.reshape(N, r, p), index, shortlist)
    chosen = np.zeros(N, dtype=bool)
    if initial is not None:
        sel = [int(i) for i in np.asarray(initial).reshape(-1)]
        if len(sel) != n or len(set(sel)) != n or min(sel) < 0 or max(sel) >= N:
            raise ValueError(f"initial must be {n} distinct indices into {N} candidates")
    else:
        sel = []
    M = design.ridge * design.I_p + design.info[sel].sum(axis=0)
    chosen[sel] = True
    while len(sel) < n:  # greedy construction
        free = np.flatnonzero(~chosen)
        k = int(free[np.argmax(design.scores(M, free, len(sel) + 1))])
        sel.append(k)
        chosen[k] = True
        M = M + design.info[k]
    greedy_value = design.value(M, n)
    swaps, passes = design.exchange(sel, chosen, M, greedy_value, max_passes)
    idx = np.array(sel, dtype=np.intp)
    final = observability_indices(singular_values(Js.reshape(N, r, p)[idx].reshape(-1, p)), n, p)
    return PoseSelection(
        indices=idx,
        q=Q[idx],
        index=index,
        value=final[index],
        greedy_value=greedy_value,
        indices_all=final,
        params=tuple(names),
        scale=s,
        swaps=swaps,
        passes=passes,
    )


# ------------------------------------------------------------------------ design efficiency bound
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
    r, p = (3 if rows == "position" else 6), len(names)
    o1 = observability_indices(singular_values(Js), len(Q), p).O1
    M = Js.T @ Js / len(Q)
    lam = np.linalg.eigvalsh(M)
    if lam[0] <= 1e-12 * max(lam[-1], 1e-300):
        return DesignBound(o1, math.inf, p, 0.0, math.inf, math.inf, C[0].copy())
    L = np.linalg.cholesky(M)

    def variance(X: Array) -> Array:
        B = scaled_jacobian(model, X, rows=rows, params=names, scale="tolerance")[0]
        Y = scipy.linalg.solve_triangular(L, B.T, lower=True)  # (p, r·len(X))
        return np.sum(Y.reshape(p, len(X), r) ** 2, axis=(0, 2))

    points = np.r_[C, Q]
    d = variance(points)
    k = int(np.argmax(d))
    best, q_best = float(d[k]), points[k].copy()
    best, q_best = _polish_maximum(model, variance, points, d, polish, (best, q_best))
    ratio = math.sqrt(best / p)
    return DesignBound(o1, best, p, p / best, ratio, o1 * ratio, q_best)


def _polish_maximum(
    model: Model,
    variance: Callable[[Array], Array],
    points: Array,
    d: Array,
    polish: int,
    best: tuple[float, Array],
) -> tuple[float, Array]:
    """The largest ``variance`` found by L-BFGS-B (within the joint limits, central-difference
    gradient) from the ``polish`` points with the largest ``d``, or ``best`` if larger."""
    top, q_top = best
    lim = model.joint_limits
    bounds = [(lo if np.isfinite(lo) else None, hi if np.isfinite(hi) else None) for lo, hi in lim]
    h, eye = 1e-6, np.eye(model.dof)

    def negative(q: Array) -> tuple[float, Array]:
        dq = variance(np.r_[q[None], q + h * eye, q - h * eye])
        return -float(dq[0]), -(dq[1 : model.dof + 1] - dq[model.dof + 1 :]) / (2 * h)

    for i in np.argsort(-d)[: max(int(polish), 0)]:
        start = np.clip(points[i], lim[:, 0], lim[:, 1])
        res = scipy.optimize.minimize(negative, start, jac=True, method="L-BFGS-B", bounds=bounds)
        if -res.fun > top:
            top, q_top = float(-res.fun), np.asarray(res.x, dtype=float)
    return top, q_top
