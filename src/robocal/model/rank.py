"""The identifiable subset of a Jacobian's columns: which parameters the measurements
determine, which are redundant and what absorbs them (column-pivoted QR, or the sequential
rank test the calibration and the model builder use).

Plain linear algebra on an ``(m, p)`` Jacobian: it lives in the model layer because the
model builder (:mod:`robocal.model.builder`) picks a minimal parameter set with it;
:mod:`robocal.identify.observability` re-exports it.
"""

from __future__ import annotations

import functools
import importlib
from collections.abc import Sequence
from dataclasses import dataclass
from types import ModuleType
from typing import Literal

import numpy as np
import scipy.linalg
from numpy.typing import ArrayLike, NDArray

from robocal.model.kernel_mode import compiled_wanted

__all__ = [
    "Dropped",
    "IdentifiableSubset",
    "identifiable_subset",
    "preference_subset",
    "sequential_test_numpy",
]

Array = NDArray[np.float64]


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
    J, names, prefer = _checked(J, names, order, prefer)
    p = len(names)
    norm = np.linalg.norm(J, axis=0)
    zero = norm <= 1e-12 * max(norm.max(initial=0.0), 1e-300)
    Js = J / np.where(zero, 1.0, norm)
    rank_pref = {n: k for k, n in enumerate(prefer)}
    ordered = _column_order(names, [k for k in range(p) if not zero[k]], rank_pref, order)
    if not ordered:
        dropped = tuple(Dropped(names[k], "no effect") for k in range(p))
        return IdentifiableSubset((), dropped, 0, names, np.zeros(p))
    if order == "preference":
        return preference_subset(Js[:, ordered], ordered, norm, zero, names, rtol=rtol, threshold=threshold,
                                 explain=explain)  # fmt: skip
    n_preferred = sum(1 for k in ordered if names[k] in rank_pref) if prefer else None
    cols, rank, rel = _pivoted_rank(Js[:, ordered], ordered, n_preferred, 1e-6 if rtol is None else rtol)
    kept_cols, red_cols = cols[:rank], cols[rank:]
    fit = None
    if red_cols and explain and kept_cols:
        kept, redundant = Js[:, kept_cols], Js[:, red_cols]
        coef = _lstsq(kept, redundant)
        fit = coef, np.linalg.norm(redundant - kept @ coef, axis=0)
    return _subset(names, norm, zero, cols, kept_cols, red_cols, rel, fit, threshold)


def preference_subset(
    A: Array,
    ordered: Sequence[int],
    norm: Array,
    zero: NDArray[np.bool_],
    names: tuple[str, ...],
    *,
    rtol: float | None = None,
    threshold: float = 0.05,
    explain: bool = True,
) -> IdentifiableSubset:
    """:func:`identifiable_subset` with ``order="preference"`` from its unit-norm columns
    ``A`` ``(m, k)``, already in test order (the columns ``ordered`` of the Jacobian, whose
    column norms are ``norm`` ``(p,)`` and zero ones ``zero``): the sequential rank test
    (:func:`_sequential_rank_test`) and the absorbers of the dropped columns."""
    keep, coef, rel, unexplained = _sequential_rank_test(A, 1e-7 if rtol is None else rtol)
    verdicts = list(zip(ordered, keep.tolist(), strict=True))
    kept_cols = [c for c, k in verdicts if k]
    red_cols = [c for c, k in verdicts if not k]
    return _subset(names, norm, zero, list(ordered), kept_cols, red_cols, rel,
                   (coef, unexplained) if explain else None, threshold)  # fmt: skip


def _subset(
    names: tuple[str, ...],
    norm: Array,
    zero: NDArray[np.bool_],
    cols: list[int],
    kept_cols: list[int],
    red_cols: list[int],
    rel: Array,
    fit: tuple[Array, Array] | None,
    threshold: float,
) -> IdentifiableSubset:
    """The :class:`IdentifiableSubset` of a rank test: columns ``cols`` in test order, the
    kept and the redundant ones, ``|R_kk|`` along ``cols``; ``fit``: the redundant
    columns' coefficients in the kept ones and what they leave (None: not explained);
    ``threshold``: the smallest listed coefficient."""
    zero_cols = np.flatnonzero(zero).tolist()
    dropped = {k: Dropped(names[k], "no effect") for k in zero_cols}
    if red_cols:
        if fit is None:
            dropped.update({c: Dropped(names[c], "redundant") for c in red_cols})
        else:
            dropped.update(_absorbers(norm, names, kept_cols, red_cols, fit[0], fit[1], threshold))
    # list comprehensions: a calibration's hot path, where a generator into tuple() costs twice
    kept = tuple([names[k] for k in sorted(kept_cols)])
    pivots = tuple([names[k] for k in cols + zero_cols])
    r_diag = np.concatenate([rel, np.zeros(len(zero_cols))]) if zero_cols else rel
    dropped_in_order = tuple([dropped[k] for k in sorted(dropped)])
    return IdentifiableSubset(kept, dropped_in_order, len(kept_cols), pivots, r_diag)


def _checked(
    J: ArrayLike, names: Sequence[str], order: str, prefer: Sequence[str] | None
) -> tuple[Array, tuple[str, ...], tuple[str, ...]]:
    """The Jacobian as floats, the names and preferred names as tuples; ValueError for a wrong
    shape, NaN/inf or an unknown ``order``, KeyError for a preferred name not among ``names``."""
    J = np.asarray(J, dtype=float)
    names = tuple(names)
    if J.ndim != 2 or J.shape[1] != len(names):
        raise ValueError(f"Jacobian shaped {J.shape} does not fit {len(names)} parameter names")
    if not np.all(np.isfinite(J)):
        raise ValueError("Jacobian contains NaN or inf")
    if order not in ("pivoted", "preference"):
        raise ValueError(f"order must be 'pivoted' or 'preference', got {order!r}")
    prefer = tuple(prefer or ())
    known = set(names)
    unknown = [n for n in prefer if n not in known]
    if unknown:
        raise KeyError(f"preferred parameter(s) {unknown} are not among the Jacobian's columns")
    return J, names, prefer


def _column_order(
    names: tuple[str, ...], live: list[int], rank_pref: dict[str, int], order: str
) -> list[int]:
    """The columns with an effect (``live``) in the order the rank test considers them: the
    preferred first (in ``prefer``'s order), then the rest latest-first (``"pivoted"``) or in
    column order (``"preference"``)."""
    sign = -1 if order == "pivoted" else 1
    return sorted(live, key=lambda k: (0, rank_pref[names[k]]) if names[k] in rank_pref else (1, sign * k))


def _pivoted_rank(
    Js: Array, ordered: list[int], n_preferred: int | None, tol: float
) -> tuple[list[int], int, Array]:
    """Column-pivoted QR of the unit-norm columns ``Js`` (already in ``ordered`` order): the
    columns in pivot order, the rank and the relative diagonal ``|R_kk| / |R_00|``.
    ``n_preferred``: how many of the first columns are preferred (None: no preference)."""
    # a relative weight of 1e-9 decreasing along `ordered` breaks (numerical) ties
    # between redundant columns in favour of the earlier one; real norm differences
    # are larger
    A = Js * (1.0 + 1e-9 * np.linspace(1.0, 0.0, len(ordered)))
    if n_preferred is not None:
        # QR of the preferred block first, then of the rest projected off it, so that
        # a preferred column is never displaced by a later one with a larger norm
        piv = _two_stage_pivots(A, n_preferred)
    else:
        piv = scipy.linalg.qr(A, mode="economic", pivoting=True)[2]
    d = np.abs(np.diag(scipy.linalg.qr(A[:, piv], mode="r")[0]))
    d = np.r_[d, np.zeros(len(piv) - len(d))]
    rel = d / d[0] if d[0] > 0 else d
    return [ordered[k] for k in piv], int(np.sum(rel > tol)), rel


def _absorbers(
    norm: Array,
    names: tuple[str, ...],
    kept_cols: list[int],
    red_cols: list[int],
    coef: Array,
    unexplained: Array,
    threshold: float,
) -> dict[int, Dropped]:
    """Each redundant column's :class:`Dropped` with its absorbers: the kept parameters whose
    least-squares coefficient ``coef`` (on unit-norm columns) exceeds ``threshold``, largest
    first, converted back to the Jacobian's units; ``unexplained``: the norm of what the
    fit leaves of each (unit-norm) redundant column."""
    k, j = np.nonzero(np.abs(coef) > threshold)  # the listed (kept, redundant) pairs: a few of them
    values = coef[k, j]
    # by redundant column, then largest |coefficient| first, ties in test order
    order = np.lexsort((k, -np.abs(values), j)).tolist()
    k_list, j_list, v_list = k.tolist(), j.tolist(), values.tolist()
    scale, residuals = norm.tolist(), unexplained.tolist()
    listed: list[list[tuple[str, float]]] = [[] for _ in red_cols]
    for n in order:
        a, c = kept_cols[k_list[n]], red_cols[j_list[n]]
        listed[j_list[n]].append((names[a], v_list[n] * scale[c] / scale[a]))
    return {
        c: _redundant(names[c], tuple(pairs), residuals[i])
        for i, (c, pairs) in enumerate(zip(red_cols, listed, strict=True))
    }


def _redundant(name: str, absorbed_by: tuple[tuple[str, float], ...], residual: float) -> Dropped:
    """``Dropped(name, "redundant", absorbed_by, residual)`` without the frozen dataclass's
    ``__init__`` (one ``object.__setattr__`` per field: every calibration drops a few)."""
    dropped = object.__new__(Dropped)
    dropped.__dict__.update(name=name, reason="redundant", absorbed_by=absorbed_by, residual=residual,
                            sigma=None, detail="")  # fmt: skip
    return dropped


def sequential_test_numpy(qr: Array, tolerance: float) -> tuple[Array, NDArray[np.bool_], Array, Array, bool]:
    """:func:`robocal.model.rank_kernels.sequential_test` in numpy (same arguments and
    returns: ``|R_kk|``, the kept mask, the dropped columns' coefficients in the kept ones,
    what they leave, whether the verdicts stand)."""
    m, p = qr.shape
    d = min(m, p)
    diag = np.zeros(p)
    diag[:d] = np.abs(np.diagonal(qr)[:d])
    keep = diag > tolerance
    kept, dropped = np.flatnonzero(keep), np.flatnonzero(~keep)
    coefs, left = np.zeros((len(kept), len(dropped))), np.zeros(len(dropped))
    if len(dropped) == 0 or len(kept) == 0:
        return diag, keep, coefs, left, len(dropped) == 0
    R = np.triu(qr[:d])
    RK, RD = R[:, kept], R[:, dropped]
    try:
        factor = scipy.linalg.cho_factor(RK.T @ RK, lower=True)
    except np.linalg.LinAlgError:
        return diag, keep, coefs, left, False
    coefs = scipy.linalg.cho_solve(factor, RK.T @ RD)
    left = np.linalg.norm(RD - RK @ coefs, axis=0)
    return diag, keep, coefs, left, bool(np.all(left <= tolerance))


def _sequential_rank_test(A: Array, tolerance: float) -> tuple[NDArray[np.bool_], Array, Array, Array]:
    """Keep each unit-norm column of ``A`` (in order) unless it lies within ``tolerance``
    of the span of the kept ones before it.

    Returns the mask of kept columns, the coefficients ``(kept, dropped)`` of every
    dropped column in the kept ones, ``|R_kk|`` along the columns, and the norm of what
    the coefficients leave of each dropped column.

    One unpivoted QR answers it for all columns: ``|R_kk|`` is the part of column k
    orthogonal to all the columns before it.  A kept column passes against a span that
    includes the dropped columns, so it passes against the kept ones alone too; a
    dropped column still enters the QR as a (numerically random) direction, so its
    verdict is checked by a least-squares fit in the kept columns (the normal equations
    of ``R``, compiled: :func:`robocal.model.rank_kernels.sequential_test`; an SVD fit when
    they fail), and if the check disagrees (possible only with about as many rows as
    columns) the exact sequential Gram-Schmidt (:func:`_gram_schmidt`) decides.
    """
    if compiled_wanted() and A.size:
        # the normal equations first (a fifth of the QR's cost); they hand every verdict
        # they cannot make with a wide margin to the QR below
        diag, keep, coefs, left, decided = _kernels().gram_sequential_test(
            np.ascontiguousarray(A.T), tolerance
        )
        if decided:
            return keep, coefs, diag, left
    # LAPACK's QR directly: numpy's and scipy's wrappers cost more than the factorisation
    # itself at 300 x 36
    qr = scipy.linalg.lapack.dgeqrf(A)[0] if A.size else np.zeros(A.shape)
    if compiled_wanted():
        diag, keep, coefs, left, explained = _kernels().sequential_test(qr, tolerance)
    else:  # the process computes with numpy (numba's cache cold)
        diag, keep, coefs, left, explained = sequential_test_numpy(qr, tolerance)
    if explained:
        return keep, coefs, diag, left
    fit = _absorbing(A, keep, tolerance)
    if fit is None:
        keep = _gram_schmidt(A, tolerance)
        fit = _absorbing(A, keep, tolerance)
        if fit is None:  # cannot happen: Gram-Schmidt keeps a basis of the span
            coefs = _lstsq(A[:, keep], A[:, ~keep])
            fit = coefs, np.linalg.norm(A[:, ~keep] - A[:, keep] @ coefs, axis=0)
    return keep, fit[0], diag, fit[1]


@functools.cache
def _kernels() -> ModuleType:
    """:mod:`robocal.model.rank_kernels`, imported on first use (numba), then at hand."""
    return importlib.import_module("robocal.model.rank_kernels")


def _lstsq(K: Array, D: Array) -> Array:
    """The least-squares coefficients ``(k, d)`` of the columns of ``D`` in those of ``K``."""
    return np.linalg.lstsq(K, D, rcond=None)[0].astype(np.float64, copy=False)


def _absorbing(A: Array, keep: NDArray[np.bool_], tolerance: float) -> tuple[Array, Array] | None:
    """Coefficients of the dropped (unit-norm) columns of ``A`` in the kept ones by an SVD
    least-squares fit, and the norms of what they leave of each; None if some dropped
    column is not within ``tolerance`` of their span (or none is kept)."""
    K, D = A[:, keep], A[:, ~keep]
    if not D.shape[1]:
        return np.zeros((K.shape[1], 0)), np.zeros(0)
    if not K.shape[1]:
        return None
    coefs = _lstsq(K, D)
    left = np.linalg.norm(D - K @ coefs, axis=0)
    return (coefs, left) if np.all(left <= tolerance) else None


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
