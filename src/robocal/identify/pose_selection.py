"""Optimal pose selection: choose poses from a candidate pool that maximise an observability
index (greedy construction, then DETMAX-style exchanges; the method:
:mod:`robocal.identify.observability`, which re-exports this module)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from robocal.identify.observability_indices import (
    INDICES,
    IndexName,
    ObservabilityIndices,
    Rows,
    identifiable_parameters,
    index_from_eig,
    observability_indices,
    scaled_jacobian,
    singular_values,
)
from robocal.model.chain import Model

__all__ = ["PoseSelection", "select_poses"]

Array = NDArray[np.float64]


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


def _logdet_gain(Minv_solve: NDArray[np.floating], B: Array) -> Array:
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
        return float(index_from_eig(lam, count, self.index))

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
        out[top] = index_from_eig(lam, count, self.index)
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
