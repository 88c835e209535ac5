"""Observability of the parameters: scaled Jacobians, singular values, identifiable
subsets, the observability indices O1–O5 and optimal pose selection.

Column scaling
--------------
The identification Jacobian mixes m/m and m/rad columns, so its singular values
depend on units.  :func:`column_scales` offers

* ``"norm"`` — every column scaled to unit norm over the given poses (the usual
  choice for rank decisions; the result is unit-free but depends on the pose set);
* ``"tolerance"`` — every column multiplied by the parameter's expected error, by
  default 0.1 mm for lengths and 0.05° for angles, the deviations seed 003 §3.5
  imposes in its influence analysis.  Scaled columns are then metres of tool error
  per expected parameter error, the same for every pose set, so indices of different
  sets (and sizes) can be compared;
* an explicit ``(p,)`` array of factors.

The scaled Jacobian is ``J_s = J diag(s)``; a parameter step is ``dx = diag(s) dx_s``.

Observability indices (Sun & Hollerbach 2008, "Observability index selection for
robot calibration", ICRA, which compares them), from the singular values σ1 ≥ … ≥ σp
of the scaled ``J`` (``3n x p`` or ``6n x p`` — singular values of ``J`` itself,
not eigenvalues of ``JᵀJ``) for ``n`` poses:

* O1 = (σ1 σ2 … σp)^(1/p) / √n — Borm & Menq 1991 (IJRR 10(1)); maximising it is
  D-optimal design (the determinant of ``JᵀJ``);
* O2 = σp / σ1 — the inverse condition number (Driels & Pathre 1990); we use the
  inverse so that, like the others, larger is better;
* O3 = σp — the minimum singular value (Nahvi, Hollerbach & Hayward 1994);
* O4 = σp² / σ1 — the noise amplification index (Nahvi & Hollerbach 1996);
* O5 = 1 / (1/σ1 + … + 1/σp) — Sun & Hollerbach 2008 (A-optimality).

Pose selection (:func:`select_poses`) maximises one index over subsets of a candidate
pool: a greedy construction (each step adds the candidate that raises the index
most; until ``JᵀJ`` has full rank a tiny ridge keeps the determinant informative),
then exchanges in the spirit of DETMAX (Mitchell 1974): a selected pose is swapped
for the candidate that improves the index most, pass after pass, until no swap
helps.  Each pose adds ``B_iᵀ B_i`` to the information matrix ``M = J_sᵀ J_s``, so
adding and swapping are rank-3 (or rank-6) updates: for O1 the determinant lemma
``det(M + Bᵀ B) = det M · det(I + B M⁻¹ Bᵀ)`` scores every candidate with one small
batched product; for O2–O5 the exact index is computed (batched ``eigvalsh``, whose
square roots are the singular values of the stacked ``J``) for a shortlist of
candidates ranked by that determinant gain.

How far any pose set can get: :func:`design_efficiency_bound` turns one design into
an upper bound on the O1 of every design (Kiefer–Wolfowitz equivalence theorem), so a
selection can be certified near-optimal and impossible targets recognised.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np
import scipy.linalg
import scipy.optimize
from numpy.typing import ArrayLike, NDArray

from robocal.model.chain import Model
from robocal.model.rank import Dropped, IdentifiableSubset, identifiable_subset

__all__ = [
    "INDICES",
    "DesignBound",
    "Dropped",
    "IdentifiableSubset",
    "ObservabilityIndices",
    "PoseSelection",
    "column_scales",
    "design_efficiency_bound",
    "identifiable_parameters",
    "identifiable_subset",
    "observability",
    "observability_indices",
    "parameter_tolerances",
    "scaled_jacobian",
    "select_poses",
    "singular_values",
]

Array = NDArray[np.float64]
IndexName = Literal["O1", "O2", "O3", "O4", "O5"]
Rows = Literal["position", "pose"]
INDICES: tuple[str, ...] = ("O1", "O2", "O3", "O4", "O5")

#: Default expected parameter errors: seed 003 §3.5 (0.1 mm on lengths, 0.05° on angles).
LENGTH_TOLERANCE = 1e-4
ANGLE_TOLERANCE = math.radians(0.05)


# ------------------------------------------------------------------------ scaling
def parameter_tolerances(
    model: Model,
    names: Sequence[str] | None = None,
    *,
    length: float = LENGTH_TOLERANCE,
    angle: float = ANGLE_TOLERANCE,
) -> Array:
    """Expected errors ``(p,)`` of the named (default: free) parameters: ``length`` (m)
    for translations, ``angle`` (rad) for rotations."""
    names = model.free_names if names is None else tuple(names)
    return np.array([angle if model.step(n).is_rotation else length for n in names])


def column_scales(
    J: ArrayLike,
    scale: Literal["norm", "tolerance"] | ArrayLike = "norm",
    *,
    tolerances: ArrayLike | None = None,
) -> Array:
    """Column scale factors ``(p,)`` for ``J`` ``(m, p)``: ``J_s = J * s``.

    Args:
        J: the Jacobian.
        scale: ``"norm"`` (``1/‖J_j‖``; columns without effect get 1), ``"tolerance"``
            (``s = tolerances``) or an explicit ``(p,)`` array.
        tolerances: ``(p,)`` expected parameter errors (SI) for ``"tolerance"``.
    """
    J = np.asarray(J, dtype=float)
    if J.ndim != 2:
        raise ValueError(f"Jacobian must be 2-D (m, p), got shape {J.shape}")
    p = J.shape[1]
    if isinstance(scale, str):
        if scale == "norm":
            norm = np.linalg.norm(J, axis=0)
            return np.where(norm > 0, 1.0 / np.where(norm > 0, norm, 1.0), 1.0)
        if scale == "tolerance":
            if tolerances is None:
                raise ValueError(
                    "scale='tolerance' needs the parameter tolerances (see parameter_tolerances)"
                )
            s = np.asarray(tolerances, dtype=float)
        else:
            raise ValueError(f"scale must be 'norm', 'tolerance' or an array, got {scale!r}")
    else:
        s = np.asarray(scale, dtype=float)
    if s.shape != (p,) or not np.all(np.isfinite(s)) or np.any(s <= 0):
        raise ValueError(f"column scales must be {p} positive finite numbers, got shape {s.shape}")
    return s


def scaled_jacobian(
    model: Model,
    q: ArrayLike,
    *,
    rows: Rows = "position",
    params: Sequence[str] | None = None,
    scale: Literal["norm", "tolerance"] | ArrayLike = "tolerance",
) -> tuple[Array, Array, tuple[str, ...]]:
    """The column-scaled identification Jacobian of ``model`` at ``q`` ``(n, dof)``.

    Returns ``(J_s, s, names)``: ``J_s`` ``(3n, p)`` or ``(6n, p)``, the scale factors
    and the parameter names (``params``, default all free parameters, in that order).
    """
    J = model.jacobian(q, rows=rows)
    names = model.free_names
    if params is not None:
        index = {n: k for k, n in enumerate(names)}
        missing = [p for p in params if p not in index]
        if missing:
            raise KeyError(f"model {model.name!r} has no free parameter(s) {missing}")
        J = J[:, [index[p] for p in params]]
        names = tuple(params)
    tol = parameter_tolerances(model, names) if isinstance(scale, str) and scale == "tolerance" else None
    s = column_scales(J, scale, tolerances=tol)
    return J * s, s, names


# ------------------------------------------------------------------------ indices
def singular_values(J: ArrayLike) -> Array:
    """Singular values of ``J`` ``(m, p)``, largest first (``min(m, p)`` of them)."""
    J = np.asarray(J, dtype=float)
    if J.ndim != 2:
        raise ValueError(f"Jacobian must be 2-D (m, p), got shape {J.shape}")
    return scipy.linalg.svdvals(J)


@dataclass(frozen=True)
class ObservabilityIndices:
    """O1..O5 of a (scaled) Jacobian; see the module docstring for the definitions.

    Attributes:
        O1, O2, O3, O4, O5: the indices (0 when a parameter is unobservable).
        sigma: the singular values used, largest first.
        n_poses: number of poses ``n`` in O1's ``√n``.
    """

    O1: float
    O2: float
    O3: float
    O4: float
    O5: float
    sigma: Array
    n_poses: int

    def __getitem__(self, name: str) -> float:
        if name not in INDICES:
            raise KeyError(f"unknown observability index {name!r}; expected one of {INDICES}")
        return float(getattr(self, name))

    def as_dict(self) -> dict[str, float]:
        return {k: self[k] for k in INDICES}


def observability_indices(
    sigma: ArrayLike, n_poses: int, n_params: int | None = None
) -> ObservabilityIndices:
    """The indices O1..O5 from singular values ``sigma`` of a scaled Jacobian.

    Args:
        sigma: singular values (any order).
        n_poses: number of poses ``n`` (O1 divides by √n).
        n_params: number of parameters ``p``; when ``sigma`` has fewer values (fewer
            rows than columns) the missing ones are zero.
    """
    s = np.sort(np.asarray(sigma, dtype=float).reshape(-1))[::-1]
    p = len(s) if n_params is None else int(n_params)
    if len(s) > p:
        raise ValueError(f"{len(s)} singular values for {p} parameters")
    if len(s) < p:
        s = np.r_[s, np.zeros(p - len(s))]
    if p == 0 or n_poses < 1:
        raise ValueError(f"need at least one parameter and one pose, got p={p}, n={n_poses}")
    if np.any(s < 0) or not np.all(np.isfinite(s)):
        raise ValueError("singular values must be finite and >= 0")
    s1, sp = s[0], s[-1]
    if sp <= 0:
        o1 = o2 = o3 = o4 = o5 = 0.0
    else:
        o1 = math.exp(np.mean(np.log(s))) / math.sqrt(n_poses)
        o2, o3, o4 = sp / s1, sp, sp**2 / s1
        o5 = 1.0 / float(np.sum(1.0 / s))
    return ObservabilityIndices(o1, o2, o3, o4, o5, s, int(n_poses))


def observability(
    model: Model,
    q: ArrayLike,
    *,
    rows: Rows = "position",
    params: Sequence[str] | None = None,
    scale: Literal["norm", "tolerance"] | ArrayLike = "tolerance",
) -> ObservabilityIndices:
    """O1..O5 of the poses ``q`` ``(n, dof)`` for ``params`` (default: all free
    parameters — unidentifiable ones make every index 0; pass
    ``identifiable_parameters(...).kept``)."""
    q = np.atleast_2d(np.asarray(q, dtype=float))
    Js, _, names = scaled_jacobian(model, q, rows=rows, params=params, scale=scale)
    return observability_indices(singular_values(Js), len(q), len(names))


# ------------------------------------------------------------------------ identifiable subset
# the rank test itself: robocal.model.rank (the model builder uses it too)


def identifiable_parameters(
    model: Model,
    q: ArrayLike,
    *,
    rows: Rows = "position",
    rtol: float = 1e-6,
    prefer: Sequence[str] | None = None,
    threshold: float = 0.05,
) -> IdentifiableSubset:
    """:func:`identifiable_subset` of the model's free parameters at poses ``q`` ``(n, dof)``."""
    J = model.jacobian(np.atleast_2d(np.asarray(q, dtype=float)), rows=rows)
    return identifiable_subset(J, model.free_names, rtol=rtol, prefer=prefer, threshold=threshold)


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
    ratio = math.sqrt(best / p)
    return DesignBound(o1, best, p, p / best, ratio, o1 * ratio, q_best)
