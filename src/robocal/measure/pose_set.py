"""A set of poses (what every pose generator returns), its conditioning and its order."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from robocal.measure.cube import TOOL_DOWN as TOOL_DOWN
from robocal.measure.measurements import Measurements
from robocal.model.chain import Model

Array = NDArray[np.float64]


# ------------------------------------------------------------------------ ISO 9283 poses
@dataclass(frozen=True)
class PoseSet:
    """Joint configurations to measure, with what they were built for.

    Attributes:
        q: ``(n, dof)`` joint values (rad or m).
        positions: ``(n, 3)`` nominal tool positions (m) in the base frame.
        labels: ``(n,)`` one label per pose (``"P1"``..``"P5"``, ``"plane"``, ``"boundary"``, ``"point3"``).
        reachable: ``(n,)`` whether the IK reached each target.
        info: extra description (strings and numbers).
    """

    q: Array
    positions: Array
    labels: tuple[str, ...]
    reachable: NDArray[np.bool_]
    info: Mapping[str, object] = field(default_factory=dict)

    def __len__(self) -> int:
        return len(self.q)

    def to_measurements(self, metadata: Mapping[str, str] | None = None) -> Measurements:
        """A poses :class:`Measurements` (joint columns only)."""
        meta = {str(k): str(v) for k, v in (metadata or {}).items()}
        return Measurements(q=self.q, metadata=meta)


# ------------------------------------------------------------------------ random poses
def position_sigma_min(model: Model, q: ArrayLike, rows: Literal["position", "pose"] = "position") -> Array:
    """Smallest singular value ``(n,)`` of the joint Jacobian's position rows (m/rad).

    It is the smallest tool-point speed per unit joint rate over all directions of
    joint motion: zero at a singular configuration.  ``rows="pose"`` uses all six
    rows (mixing m/rad and rad/rad).
    """
    J = model.joint_jacobian(np.atleast_2d(np.asarray(q, dtype=float)))
    if rows == "position":
        J = J[:, :3]
    elif rows != "pose":
        raise ValueError(f"rows must be 'position' or 'pose', got {rows!r}")
    return np.linalg.svd(J, compute_uv=False)[:, -1].astype(np.float64, copy=False)


# ------------------------------------------------------------------------ ordering
def order_all_joints_move(q: ArrayLike, start: int = 0) -> tuple[NDArray[np.intp], float]:
    """Order poses so that every joint moves between consecutive poses (seed 003 §3.4).

    Maximises the bottleneck ``min over consecutive pairs of min over joints |Δq_j|``:
    a greedy path from ``start`` (always to the unvisited pose whose smallest joint
    change is largest), then 2-opt segment reversals that remove the current
    bottleneck pair while every new pair is better, until none helps.

    Args:
        q: ``(n, dof)`` configurations (rad or m).
        start: index of the first pose.

    Returns:
        The order (indices into ``q``) and the achieved bottleneck (rad or m).
    """
    q = np.asarray(q, dtype=float)
    if q.ndim != 2:
        raise ValueError(f"configurations must be (n, dof), got shape {q.shape}")
    n = len(q)
    if n <= 1:
        return np.arange(n), float("inf")
    if not 0 <= start < n:
        raise ValueError(f"start index {start} out of range for {n} poses")
    S = np.abs(q[:, None, :] - q[None, :, :]).min(axis=2)  # (n, n) smallest joint change
    order = [start]
    free = np.ones(n, dtype=bool)
    free[start] = False
    for _ in range(n - 1):
        cand = np.flatnonzero(free)
        nxt = cand[np.argmax(S[order[-1], cand])]
        order.append(int(nxt))
        free[nxt] = False
    path = np.array(order)
    for _ in range(10 * n):
        edges = S[path[:-1], path[1:]]
        i = int(np.argmin(edges))  # bottleneck pair (path[i], path[i+1])
        worst = edges[i]
        best_gain, best_move = worst, None
        # reverse path[i+1 .. b]: new pairs (path[i], path[b]) and (path[i+1], path[b+1])
        b = np.arange(i + 1, n)
        first = S[path[i], path[b]]
        second = np.where(b + 1 < n, S[path[i + 1], path[np.minimum(b + 1, n - 1)]], np.inf)
        old = np.where(b + 1 < n, edges[np.minimum(b, n - 2)], np.inf)
        gain = np.minimum(first, second)
        valid = (gain > worst) & (np.minimum(gain, old) >= np.minimum(worst, old)) & (b > i + 1)
        if valid.any():
            k = int(np.argmax(np.where(valid, gain, -np.inf)))
            best_gain, best_move = gain[k], (i + 1, int(b[k]))
        # reverse path[a .. i]: new pairs (path[a-1], path[i]) and (path[a], path[i+1])
        a = np.arange(1, i + 1)  # the start stays first
        first = S[path[a - 1], path[i]]
        second = S[path[a], path[i + 1]]
        gain = np.minimum(first, second)
        valid = (gain > worst) & (a < i)
        if valid.any():
            k = int(np.argmax(np.where(valid, gain, -np.inf)))
            if gain[k] > best_gain:
                best_gain, best_move = gain[k], (int(a[k]), i)
        if best_move is None:
            break
        lo, hi = best_move
        new = path.copy()
        new[lo : hi + 1] = path[lo : hi + 1][::-1]
        if S[new[:-1], new[1:]].min() < worst:  # never make the bottleneck worse
            break
        path = new
    return path, float(S[path[:-1], path[1:]].min())
