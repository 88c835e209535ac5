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
@dataclass(frozen=True)
class Dropped:
    """A parameter left out of identification, and why.

    Attributes:
        name: the parameter.
        reason: ``"no effect"`` (zero column), ``"redundant"`` (its column is, within
            the rank tolerance, a combination of the kept columns) or ``"poorly
            identifiable"`` (kept out by the calibration because its standard deviation
            is too large; see :func:`robocal.identify.calibrate`); for joint-effect
            coefficients (clearance, backlash, compliance: physically ≥ 0) also
            ``"unphysical"`` (the fit put it below zero) or ``"undetermined"`` (less than
            3σ above zero, or confounded with a learned residual): kept at its start value,
            ``detail`` says why with the numbers.
        absorbed_by: ``(name, coefficient)`` of the kept parameters whose combination
            reproduces its column: a change δ of this parameter moves the tool like
            changes ``coefficient · δ`` of those (in the Jacobian's units), largest
            scaled contribution first, those above the listing threshold only.
        residual: relative norm of the part of its (unit-norm) column the kept columns
            do not explain (≈ 0 for an exact redundancy).
        sigma: poorly identifiable only: its standard deviation as a tool displacement (m).
        detail: unphysical and undetermined: the estimate, its σ and why it is not used.
    """

    name: str
    reason: Literal["no effect", "redundant", "poorly identifiable", "unphysical", "undetermined"]
    absorbed_by: tuple[tuple[str, float], ...] = ()
    residual: float = 0.0
    sigma: float | None = None
    detail: str = ""

    def __str__(self) -> str:
        if self.reason in ("unphysical", "undetermined"):
            return f"{self.name}: {self.detail or self.reason}"
        if self.reason == "no effect":
            return f"{self.name}: no effect on the measurements"
        if self.reason == "poorly identifiable":
            sigma = float("nan") if self.sigma is None else self.sigma
            return (
                f"{self.name}: poorly identifiable from these measurements (σ {sigma * 1e3:.3g} mm "
                "as tool displacement); kept at its start value"
            )
        combo = ", ".join(f"{n} ({c:+.4g})" for n, c in self.absorbed_by) or "(none above threshold)"
        return f"{self.name}: redundant, absorbed by {combo}"


@dataclass(frozen=True)
class IdentifiableSubset:
    """Result of :func:`identifiable_subset`.

    Attributes:
        kept: identifiable parameters, in the input column order.
        dropped: one :class:`Dropped` per parameter left out, in the input column order.
        rank: numerical rank of the Jacobian (``len(kept)``).
        pivots: all names in the order the rank test took them (QR pivots, or the
            order of preference).
        r_diag: along ``pivots``, how independent each column is of those before it:
            ``|R_kk|`` of the QR of the unit-norm columns, relative to ``|R_00|``
            (``"pivoted"``) or to the column itself (``"preference"``).
    """

    kept: tuple[str, ...]
    dropped: tuple[Dropped, ...]
    rank: int
    pivots: tuple[str, ...]
    r_diag: Array

    @property
    def dropped_names(self) -> tuple[str, ...]:
        return tuple(d.name for d in self.dropped)

    def absorbers_of(self, name: str) -> tuple[tuple[str, float], ...]:
        for d in self.dropped:
            if d.name == name:
                return d.absorbed_by
        raise KeyError(f"parameter {name!r} was not dropped")

    def summary(self) -> str:
        lines = [f"{self.rank} identifiable parameters: {', '.join(self.kept)}"]
        lines += [f"  {d}" for d in self.dropped]
        return "\n".join(lines)


def identifiable_subset(
    J: ArrayLike,
    names: Sequence[str],
    *,
    order: Literal["pivoted", "preference"] = "pivoted",
    prefer: Sequence[str] | None = None,
    rtol: float | None = None,
    threshold: float = 0.05,
    explain: bool = True,
) -> IdentifiableSubset:
    """The identifiable parameters: a largest set of independent Jacobian columns.

    Columns are scaled to unit norm first (rank decisions should not depend on units);
    zero columns are "no effect".  Two ways to choose among redundant columns:

    * ``"pivoted"`` (default): column-pivoted QR (``scipy.linalg.qr(pivoting=True)``)
      takes, at each step, the column with the largest part not yet explained by the
      columns taken before; the rank is the number of pivots with
      ``|R_kk| > rtol · |R_00|`` (``rtol`` default 1e-6).  Ties between exactly
      redundant columns (e.g. a base ``Tz`` and the first link's ``d1`` along the same
      axis) go to the parameter in ``prefer`` first, then to the one *later* in the
      column order: as in Schröer's minimal models (seed 000), the first link's
      ``d``/``θ`` absorb the base's ``Tz``/``Rz`` and the tool frame absorbs the last
      link's parameters.
    * ``"preference"``: the sequential rank test the calibration uses.  Each column,
      in the order ``prefer`` and then the others in column order, is kept unless the
      part of it orthogonal to the columns kept before it is at most ``rtol`` (default
      1e-7) of its norm.  Best-conditioned columns do not matter here; which of two
      redundant parameters a user would rather keep does (the measurement frame's x or
      the robot base's x?).  One unpivoted QR answers it for every column (see
      :func:`_sequential_rank_test`).

    Each dropped column's absorbers are the least-squares coefficients of its column in
    the kept columns; those whose coefficient on unit-norm columns exceeds
    ``threshold`` in magnitude are listed, converted back to the Jacobian's units.

    Args:
        J: ``(m, p)`` identification Jacobian (any units).
        names: the ``p`` parameter names.
        order: ``"pivoted"`` or ``"preference"`` (above).
        prefer: names to keep first when there is a choice.
        rtol: rank tolerance (above).
        threshold: smallest |scaled coefficient| listed as an absorber.
        explain: compute the absorbers (skip for a rank decision only).
    """
    J = np.asarray(J, dtype=float)
    names = tuple(names)
    if J.ndim != 2 or J.shape[1] != len(names):
        raise ValueError(f"Jacobian shaped {J.shape} does not fit {len(names)} parameter names")
    if not np.all(np.isfinite(J)):
        raise ValueError("Jacobian contains NaN or inf")
    if order not in ("pivoted", "preference"):
        raise ValueError(f"order must be 'pivoted' or 'preference', got {order!r}")
    p = len(names)
    norm = np.linalg.norm(J, axis=0)
    zero = norm <= 1e-12 * max(norm.max(initial=0.0), 1e-300)
    Js = J / np.where(zero, 1.0, norm)
    prefer = tuple(prefer or ())
    unknown = [n for n in prefer if n not in names]
    if unknown:
        raise KeyError(f"preferred parameter(s) {unknown} are not among the Jacobian's columns")
    rank_pref = {n: k for k, n in enumerate(prefer)}
    live = [k for k in range(p) if not zero[k]]
    if order == "pivoted":  # preferred first, then the rest latest-first
        ordered = sorted(live, key=lambda k: (0, rank_pref[names[k]]) if names[k] in rank_pref else (1, -k))
    else:  # preferred first, then the rest in column order
        ordered = sorted(live, key=lambda k: (0, rank_pref[names[k]]) if names[k] in rank_pref else (1, k))
    if not ordered:
        dropped = tuple(Dropped(names[k], "no effect") for k in range(p))
        return IdentifiableSubset((), dropped, 0, names, np.zeros(p))
    if order == "pivoted":
        tol = 1e-6 if rtol is None else rtol
        # a relative weight of 1e-9 decreasing along `ordered` breaks (numerical) ties
        # between redundant columns in favour of the earlier one; real norm differences
        # are larger
        A = Js[:, ordered] * (1.0 + 1e-9 * np.linspace(1.0, 0.0, len(ordered)))
        if prefer:
            # QR of the preferred block first, then of the rest projected off it, so that
            # a preferred column is never displaced by a later one with a larger norm
            piv = _two_stage_pivots(A, sum(1 for k in ordered if names[k] in rank_pref))
        else:
            piv = scipy.linalg.qr(A, mode="economic", pivoting=True)[2]
        d = np.abs(np.diag(scipy.linalg.qr(A[:, piv], mode="r")[0]))
        d = np.r_[d, np.zeros(len(piv) - len(d))]
        rel = d / d[0] if d[0] > 0 else d
        rank = int(np.sum(rel > tol))
        cols = [ordered[k] for k in piv]
        kept_cols, red_cols = cols[:rank], cols[rank:]
        coef = None
    else:
        tol = 1e-7 if rtol is None else rtol
        keep, coef, rel = _sequential_rank_test(Js[:, ordered], tol)
        cols = ordered
        kept_cols = [c for c, k in zip(ordered, keep, strict=True) if k]
        red_cols = [c for c, k in zip(ordered, keep, strict=True) if not k]
        rank = len(kept_cols)
    dropped = {k: Dropped(names[k], "no effect") for k in range(p) if zero[k]}
    if red_cols:
        K = Js[:, kept_cols]
        if explain and coef is None:
            coef = np.linalg.lstsq(K, Js[:, red_cols], rcond=None)[0] if kept_cols else None
        if not explain or coef is None:
            dropped.update({c: Dropped(names[c], "redundant") for c in red_cols})
        else:
            residuals = np.linalg.norm(Js[:, red_cols] - K @ coef, axis=0).tolist()
            # in the Jacobian's units; listed: scaled |coefficient| above the threshold, largest first
            units = coef * norm[red_cols] / norm[kept_cols][:, None]
            ranked = np.argsort(-np.abs(coef), axis=0, kind="stable").T.tolist()
            listed, units = (np.abs(coef) > threshold).T.tolist(), units.T.tolist()
            for j, c in enumerate(red_cols):
                absorbers = tuple((names[kept_cols[k]], units[j][k]) for k in ranked[j] if listed[j][k])
                dropped[c] = Dropped(names[c], "redundant", absorbers, residuals[j])
    kept = tuple(names[k] for k in sorted(kept_cols))
    pivots = tuple(names[k] for k in cols) + tuple(names[k] for k in range(p) if zero[k])
    r_diag = np.concatenate([rel, np.zeros(int(zero.sum()))])
    return IdentifiableSubset(kept, tuple(dropped[k] for k in sorted(dropped)), rank, pivots, r_diag)


def _sequential_rank_test(A: Array, tolerance: float) -> tuple[NDArray[np.bool_], Array, Array]:
    """Keep each unit-norm column of ``A`` (in order) unless it lies within ``tolerance``
    of the span of the kept ones before it.

    Returns the mask of kept columns, the coefficients ``(kept, dropped)`` of every
    dropped column in the kept ones, and ``|R_kk|`` along the columns.

    One unpivoted QR answers it for all columns: ``|R_kk|`` is the part of column k
    orthogonal to all the columns before it.  A kept column passes against a span that
    includes the dropped columns, so it passes against the kept ones alone too; a
    dropped column still enters the QR as a (numerically random) direction, so its
    verdict is checked by a least-squares fit in the kept columns, and if the check
    disagrees (possible only with about as many rows as columns) the exact sequential
    Gram-Schmidt (:func:`_gram_schmidt`) decides.
    """
    diag = np.abs(np.diag(np.linalg.qr(A, mode="r")))
    diag = np.concatenate([diag, np.zeros(A.shape[1] - len(diag))])
    keep = diag > tolerance
    coefs = _absorbing(A, keep, tolerance)
    if coefs is None:
        keep = _gram_schmidt(A, tolerance)
        coefs = _absorbing(A, keep, tolerance)
        if coefs is None:  # cannot happen: Gram-Schmidt keeps a basis of the span
            coefs = np.linalg.lstsq(A[:, keep], A[:, ~keep], rcond=None)[0]
    return keep, coefs, diag


def _absorbing(A: Array, keep: NDArray[np.bool_], tolerance: float) -> Array | None:
    """Coefficients of the dropped (unit-norm) columns in the kept ones, or None if some
    dropped column is not within ``tolerance`` of their span.  Normal equations first (a
    fraction of the cost of an SVD least-squares fit; fine unless the kept columns are
    badly conditioned, which the check of the fit then catches), the SVD fit otherwise."""
    K, D = A[:, keep], A[:, ~keep]
    if not D.shape[1]:
        return np.zeros((K.shape[1], 0))
    if not K.shape[1]:
        return None
    try:
        coefs = scipy.linalg.cho_solve(scipy.linalg.cho_factor(K.T @ K), K.T @ D)
        if np.all(np.linalg.norm(D - K @ coefs, axis=0) <= tolerance):
            return coefs
    except np.linalg.LinAlgError:
        pass
    coefs = np.linalg.lstsq(K, D, rcond=None)[0]
    return coefs if np.all(np.linalg.norm(D - K @ coefs, axis=0) <= tolerance) else None


def _gram_schmidt(A: Array, tolerance: float) -> NDArray[np.bool_]:
    """The sequential rank test one column at a time (the reference for
    :func:`_sequential_rank_test`), on unit-norm columns."""
    Q = np.zeros((A.shape[0], 0))
    keep = np.zeros(A.shape[1], dtype=bool)
    for k in range(A.shape[1]):
        v = A[:, k] - Q @ (Q.T @ A[:, k])
        v -= Q @ (Q.T @ v)  # twice: orthogonal to working precision
        residual = float(np.linalg.norm(v))
        if residual > tolerance:
            Q = np.column_stack([Q, v / residual])
            keep[k] = True
    return keep


def _two_stage_pivots(A: Array, n_first: int) -> NDArray[np.intp]:
    """Pivot order: pivoted QR of the first ``n_first`` columns, then of the others
    after projecting out the span of the first block."""
    first, rest = A[:, :n_first], A[:, n_first:]
    if n_first == 0:
        return scipy.linalg.qr(rest, mode="economic", pivoting=True)[2]
    Q1, R1, p1 = scipy.linalg.qr(first, mode="economic", pivoting=True)
    d1 = np.abs(np.diag(R1))
    r1 = int(np.sum(d1 > 1e-10 * max(d1[0], 1e-300)))
    Qk = Q1[:, :r1]
    if rest.shape[1] == 0:
        return p1
    proj = rest - Qk @ (Qk.T @ rest)
    p2 = scipy.linalg.qr(proj, mode="economic", pivoting=True)[2]
    # independent preferred columns, then the others, then the dependent preferred ones
    return np.r_[p1[:r1], n_first + p2, p1[r1:]].astype(np.intp)


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
