"""Choosing an identifiable set of parameters in a preferred order.

Column-pivoted QR picks the best-conditioned columns but says nothing about which of
two redundant parameters a user would rather keep (the measurement frame's x or the
robot base's x?).  The sequential rank test below keeps each parameter, in a given
order of preference, unless its Jacobian column lies in the span of the columns kept
before it; for every parameter it drops it reports why: no effect on the
measurements, or the kept parameters that absorb it (the coefficients of its column
in theirs).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import scipy.linalg
from numpy.typing import NDArray

__all__ = ["Dropped", "Selection", "select_columns"]


@dataclass(frozen=True)
class Dropped:
    """A parameter left out of identification, and why."""

    name: str
    reason: str  # "no effect", "redundant" or "poorly identifiable"
    absorbed_by: tuple[tuple[str, float], ...] = ()  # (kept name, coefficient), largest first
    sigma: float | None = None  # poorly identifiable: its standard deviation as tool displacement (m)

    def __str__(self) -> str:
        if self.reason == "no effect":
            return f"{self.name}: no effect on the measurements"
        if self.reason == "poorly identifiable":
            return (
                f"{self.name}: poorly identifiable from these measurements (σ {self.sigma * 1e3:.3g} mm "
                "as tool displacement); kept at its start value"
            )
        combo = ", ".join(f"{name} ({coef:+.3g})" for name, coef in self.absorbed_by)
        return f"{self.name}: redundant, absorbed by {combo}"


@dataclass(frozen=True)
class Selection:
    """The result of :func:`select_columns`."""

    kept: tuple[str, ...]
    dropped: tuple[Dropped, ...]


def select_columns(
    J: NDArray[np.float64],
    names: Sequence[str],
    order: Sequence[str] | None = None,
    tolerance: float = 1e-7,
    explain: bool = True,
) -> Selection:
    """Sequential rank test over the columns of ``J`` in the preferred ``order``.

    Args:
        J: ``(m, p)`` Jacobian whose columns are comparable (scale them first, e.g.
            rotations times a characteristic length).
        names: the ``p`` column names.
        order: names in order of preference (default: ``names``); names not listed
            come last in their column order.
        tolerance: a column is kept when the part of it orthogonal to the kept columns
            is larger than ``tolerance`` times its norm.
        explain: compute the absorbing combination of each redundant column.
    """
    names = list(names)
    if J.shape[1] != len(names):
        raise ValueError(f"J has {J.shape[1]} columns for {len(names)} names")
    order = list(order) if order is not None else names
    order += [n for n in names if n not in set(order)]
    index = {n: k for k, n in enumerate(names)}
    scale = float(np.abs(J).max()) if J.size else 1.0
    columns = [index[n] for n in order]
    norms = np.linalg.norm(J[:, columns], axis=0)
    effect = norms > 1e-12 * max(scale, 1e-300)
    zero = [n for n, e in zip(order, effect, strict=True) if not e]
    candidates = [n for n, e in zip(order, effect, strict=True) if e]
    keep, coefs = _rank_test(J[:, [index[n] for n in candidates]], tolerance)
    kept = [n for n, k in zip(candidates, keep, strict=True) if k]
    redundant = [n for n, k in zip(candidates, keep, strict=True) if not k]
    dropped = [Dropped(n, "no effect") for n in zero]
    for r, name in enumerate(redundant):
        absorbed: tuple[tuple[str, float], ...] = ()
        if explain and kept:
            coef = coefs[:, r]
            big = np.flatnonzero(np.abs(coef) > 1e-3 * np.abs(coef).max())
            big = big[np.argsort(-np.abs(coef[big]))][:4]
            absorbed = tuple((kept[k], float(coef[k])) for k in big)
        dropped.append(Dropped(name, "redundant", absorbed))
    dropped.sort(key=lambda d: index[d.name])
    kept_in_order = tuple(n for n in names if n in set(kept))
    return Selection(kept_in_order, tuple(dropped))


def _rank_test(J: NDArray[np.float64], tolerance: float) -> tuple[NDArray[np.bool_], NDArray[np.float64]]:
    """Keep each column (in order) unless it lies in the span of the kept ones before it.

    Returns the mask of kept columns and the coefficients ``(kept, dropped)`` of every
    dropped column in the kept ones.

    One unpivoted QR answers it for all columns: ``|R_kk|`` is the part of column k
    orthogonal to all the columns before it.  A kept column passes against a span that
    includes the dropped columns, so it passes against the kept ones alone too; a
    dropped column still enters the QR as a (numerically random) direction, so its
    verdict is checked by a least-squares fit in the kept columns, and if the check
    disagrees (possible only with about as many rows as columns) the exact sequential
    Gram-Schmidt decides.
    """
    norms = np.linalg.norm(J, axis=0)
    if J.shape[1] == 0:
        return np.zeros(0, dtype=bool), np.zeros((0, 0))
    diag = np.abs(np.diag(np.linalg.qr(J, mode="r")))
    keep = np.zeros(J.shape[1], dtype=bool)
    keep[: len(diag)] = diag > tolerance * norms[: len(diag)]
    coefs = _absorbing(J, keep, tolerance, norms)
    if coefs is None:
        keep = _gram_schmidt(J, tolerance, norms)
        coefs = _absorbing(J, keep, tolerance, norms)
    return keep, coefs


def _absorbing(
    J: NDArray[np.float64], keep: NDArray[np.bool_], tolerance: float, norms: NDArray[np.float64]
) -> NDArray[np.float64] | None:
    """Coefficients of the dropped columns in the kept ones, or None if some dropped
    column is not in their span.  Normal equations first (a fraction of the cost of an
    SVD least-squares fit; fine unless the kept columns are badly conditioned, which the
    check of the fit then catches), the SVD fit otherwise."""
    K, D = J[:, keep], J[:, ~keep]
    if not D.shape[1]:
        return np.zeros((K.shape[1], 0))
    if not K.shape[1]:
        return None
    limit = tolerance * norms[~keep]
    try:
        coefs = scipy.linalg.cho_solve(scipy.linalg.cho_factor(K.T @ K), K.T @ D)
        if np.all(np.linalg.norm(D - K @ coefs, axis=0) <= limit):
            return coefs
    except np.linalg.LinAlgError:
        pass
    coefs = np.linalg.lstsq(K, D, rcond=None)[0]
    return coefs if np.all(np.linalg.norm(D - K @ coefs, axis=0) <= limit) else None


def _gram_schmidt(J: NDArray[np.float64], tolerance: float, norms: NDArray[np.float64]) -> NDArray[np.bool_]:
    """The sequential rank test one column at a time (the reference for :func:`_rank_test`)."""
    Q = np.zeros((J.shape[0], 0))
    keep = np.zeros(J.shape[1], dtype=bool)
    for k in range(J.shape[1]):
        v = J[:, k] - Q @ (Q.T @ J[:, k])
        v -= Q @ (Q.T @ v)  # twice: orthogonal to working precision
        residual = float(np.linalg.norm(v))
        if residual > tolerance * norms[k]:
            Q = np.column_stack([Q, v / residual])
            keep[k] = True
    return keep
