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
    Q = np.zeros((J.shape[0], 0))  # orthonormal basis of the kept columns
    kept: list[str] = []
    zero: list[str] = []
    redundant: list[str] = []
    for name in order:
        col = J[:, index[name]]
        norm = float(np.linalg.norm(col))
        if norm <= 1e-12 * max(scale, 1e-300):
            zero.append(name)
            continue
        v = col - Q @ (Q.T @ col)
        v -= Q @ (Q.T @ v)  # Gram-Schmidt twice: orthogonal to working precision
        residual = float(np.linalg.norm(v))
        if residual > tolerance * norm:
            Q = np.column_stack([Q, v / residual])
            kept.append(name)
        else:
            redundant.append(name)
    dropped = [Dropped(n, "no effect") for n in zero]
    if redundant:
        coefs = None
        if explain and kept:
            K = J[:, [index[n] for n in kept]]
            R = J[:, [index[n] for n in redundant]]
            coefs = np.linalg.lstsq(K, R, rcond=None)[0]  # every redundant column at once
        for r, name in enumerate(redundant):
            absorbed: tuple[tuple[str, float], ...] = ()
            if coefs is not None:
                coef = coefs[:, r]
                big = np.flatnonzero(np.abs(coef) > 1e-3 * np.abs(coef).max())
                big = big[np.argsort(-np.abs(coef[big]))][:4]
                absorbed = tuple((kept[k], float(coef[k])) for k in big)
            dropped.append(Dropped(name, "redundant", absorbed))
    dropped.sort(key=lambda d: index[d.name])
    kept_in_order = tuple(n for n in names if n in set(kept))
    return Selection(kept_in_order, tuple(dropped))
