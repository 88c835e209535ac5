"""Constraint measurements as data: joint values and what each pose's tool point satisfies
(a fixed point, a plane, a known distance to another pose's tool point, a tracker position).
The measurement model and its Jacobian: :mod:`robocal.identify.constraints.model`; files:
:mod:`robocal.measure.constraints.data`."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

__all__ = ["KINDS", "ConstraintSet"]

Array = NDArray[np.float64]
IntArray = NDArray[np.intp]
KINDS = ("point", "plane", "distance")


def _ints(v, shape) -> IntArray:
    return np.asarray(v, dtype=np.intp).reshape(shape)


@dataclass(frozen=True)
class ConstraintSet:
    """Joint values and what each pose's tool point satisfies.

    Attributes:
        q: ``(n, dof)`` joint values (rad or m).
        point: ``(n,)`` the fixed point pose ``i``'s tool point sits in, ``-1`` none.
        plane: ``(n,)`` the plane pose ``i``'s tool point touches, ``-1`` none.
        position: ``(n, 3)`` tracker positions (m, device frame), NaN rows none; or None.
        pairs: ``(m, 2)`` poses whose tool points are ``pair_length`` apart.
        pair_length: ``(m,)`` (m).
        point_pairs: ``(k, 2)`` fixed points ``point_length`` apart.
        point_length: ``(k,)`` (m).
        known_planes: ``(P, 4)`` unit normal and offset (m) of each plane, NaN rows unknown;
            or None (all unknown).
        sigma: the tool point's noise (m, isotropic).
        distance_sigma: the uncertainty of a stated distance between fixed points (m).
    """

    q: Array
    point: IntArray
    plane: IntArray
    position: Array | None = None
    pairs: IntArray = field(default_factory=lambda: np.zeros((0, 2), dtype=np.intp))
    pair_length: Array = field(default_factory=lambda: np.zeros(0))
    point_pairs: IntArray = field(default_factory=lambda: np.zeros((0, 2), dtype=np.intp))
    point_length: Array = field(default_factory=lambda: np.zeros(0))
    known_planes: Array | None = None
    sigma: float = 1e-5
    distance_sigma: float = 1e-6

    def __post_init__(self) -> None:
        q = np.asarray(self.q, dtype=float)
        n = len(q)
        object.__setattr__(self, "q", q)
        object.__setattr__(self, "point", _ints(self.point, (n,)))
        object.__setattr__(self, "plane", _ints(self.plane, (n,)))
        object.__setattr__(self, "pairs", _ints(self.pairs, (-1, 2)))
        object.__setattr__(self, "pair_length", np.asarray(self.pair_length, dtype=float).reshape(-1))
        object.__setattr__(self, "point_pairs", _ints(self.point_pairs, (-1, 2)))
        object.__setattr__(self, "point_length", np.asarray(self.point_length, dtype=float).reshape(-1))
        if len(self.pairs) != len(self.pair_length) or len(self.point_pairs) != len(self.point_length):
            raise ValueError("every pair needs one length")
        if len(self.pairs) and (self.pairs.min() < 0 or self.pairs.max() >= n):
            raise ValueError(f"a distance pair names a pose outside 0..{n - 1}")
        if len(self.point_pairs) and (self.point_pairs.min() < 0 or self.point_pairs.max() >= self.n_points):
            raise ValueError(f"a known distance names a point outside 0..{self.n_points - 1}")
        if self.position is not None and np.shape(self.position) != (n, 3):
            raise ValueError(f"tracker positions shaped {np.shape(self.position)}; expected ({n}, 3)")
        if not self.sigma > 0 or not self.distance_sigma > 0:
            raise ValueError("sigma and distance_sigma must be > 0 (m)")

    @property
    def n(self) -> int:
        return len(self.q)

    @property
    def n_points(self) -> int:
        return int(self.point.max()) + 1 if self.n else 0

    @property
    def n_planes(self) -> int:
        return int(self.plane.max()) + 1 if self.n else 0

    @property
    def tracked(self) -> NDArray[np.bool_]:
        """``(n,)`` whether a tracker measured pose ``i``."""
        if self.position is None:
            return np.zeros(self.n, dtype=bool)
        return np.all(np.isfinite(self.position), axis=1)

    @property
    def positions(self) -> Array:
        """``(n, 3)`` the tracker positions (m), NaN rows where none measured."""
        if self.position is None:
            return np.full((self.n, 3), np.nan)
        return np.asarray(self.position, dtype=float)

    @property
    def planes_stated(self) -> Array:
        """``(P, 4)`` the stated planes (unit normal, offset in m), NaN rows unknown."""
        out = np.full((self.n_planes, 4), np.nan)
        if self.known_planes is not None:
            known = np.asarray(self.known_planes, dtype=float)[: self.n_planes]
            out[: len(known)] = known
        return out

    @property
    def kinds(self) -> tuple[str, ...]:
        """The kinds present: ``point``, ``plane``, ``distance``, ``tracker``."""
        found = [
            ("point", self.n_points > 0),
            ("plane", self.n_planes > 0),
            ("distance", len(self.pairs) > 0),
            ("tracker", bool(self.tracked.any())),
        ]
        return tuple(k for k, present in found if present)

    def unknown_plane(self, k: int) -> bool:
        return (
            self.known_planes is None
            or k >= len(self.known_planes)
            or not np.isfinite(self.known_planes[k]).all()
        )
