"""Constraint measurements as data: joint values and what each pose's tool point satisfies
(a fixed point, a plane, a known distance to another pose's tool point, a tracker position).
The measurement model and its Jacobian: :mod:`robocal.identify.constraints.model`; files:
:mod:`robocal.measure.constraints.data`."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

__all__ = ["KINDS", "TILT_AXES", "TILT_SIGMA", "ConstraintSet", "merge_sets"]

Array = NDArray[np.float64]
IntArray = NDArray[np.intp]
KINDS = ("point", "plane", "distance", "tilt")
TILT_AXES = ("x", "y")  # an inclinometer's channels: its x axis, its y axis
TILT_SIGMA = 1.75e-5  # rad: 0.001°, seed 003's inclinometer resolution


def _per_row(v, n: int, fill, dtype):
    """``v`` as ``(n,)``; an empty ``v`` (the default): ``n`` times ``fill``."""
    a = np.asarray(v, dtype=dtype).reshape(-1)
    return np.full(n, fill, dtype=dtype) if a.size == 0 else a


def _mounts(v, link: IntArray, home: NDArray[np.bool_]) -> Array:
    """``v`` as ``(n, 3)`` mount angles (rad; empty: zeros), one mount (angles and the
    frame they are in, ``home``) per sensed link."""
    n = len(link)
    a = np.asarray(v, dtype=float)
    a = np.zeros((n, 3)) if a.size == 0 else a.reshape(n, 3)
    if not np.isfinite(a).all():
        raise ValueError("a tilt row's mount angles must be finite")
    for k in np.unique(link[link >= 0]):
        rows = np.column_stack([a, home])[link == k]
        if np.ptp(rows, axis=0).max() > 0:
            raise ValueError(
                f"the tilt rows of link {int(k) + 1} carry different mounts; one sensor per link"
            )
    return a


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
        sigma: the tool point's noise (m, isotropic) in the constraint rows (points,
            planes, pairs).
        tracker_sigma: the tracker positions' noise (m, per axis); None: ``sigma``.  Mixed
            data weights each kind by its own noise.
        distance_sigma: the uncertainty of a stated distance between fixed points (m).
        tilt_link: ``(n,)`` the joint index (0-based) whose child link carries the
            inclinometer read at pose ``i``, ``-1`` none (empty: no tilt rows).
        tilt_axis: ``(n,)`` the channel read: 0 the sensor's x axis, 1 its y axis
            (:mod:`robocal.identify.constraints.tilt_rows`).
        tilt: ``(n,)`` the reading (rad), NaN where none.
        tilt_sigma: a reading's noise (rad).
        tilt_mount: ``(n, 3)`` the sensor's orientation on its link, as angles (rad) about
            the link's joint-frame x, y and z axes (fixed axes, in that order:
            ``R_joint_sensor = Rz Ry Rx``); zeros (the default): the sensor's axes are the
            joint frame's.  One mount per link (the rows of a link share it).
        tilt_home: ``(n,)`` whether row ``i``'s ``tilt_mount`` is instead the sensor's
            orientation in the robot's base frame with every joint at zero (``R_base_sensor
            = Rz Ry Rx`` at home; zeros: level, its x axis along the base's x), a statement
            that does not depend on the chain calibrated
            (:func:`robocal.measure.constraints.mounts.mounts_in` resolves it against a
            chain's nominal robot at home).  Empty (the default): False.
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
    tracker_sigma: float | None = None
    tilt_link: IntArray = field(default_factory=lambda: np.zeros(0, dtype=np.intp))
    tilt_axis: IntArray = field(default_factory=lambda: np.zeros(0, dtype=np.intp))
    tilt: Array = field(default_factory=lambda: np.zeros(0))
    tilt_sigma: float = TILT_SIGMA
    tilt_mount: Array = field(default_factory=lambda: np.zeros((0, 3)))
    tilt_home: NDArray[np.bool_] = field(default_factory=lambda: np.zeros(0, dtype=bool))

    def __post_init__(self) -> None:
        q = np.asarray(self.q, dtype=float)
        n = len(q)
        object.__setattr__(self, "q", q)
        object.__setattr__(self, "tilt_link", _per_row(self.tilt_link, n, -1, np.intp))
        object.__setattr__(self, "tilt_axis", _per_row(self.tilt_axis, n, 0, np.intp))
        object.__setattr__(self, "tilt", _per_row(self.tilt, n, np.nan, float))
        if not (len(self.tilt_link) == len(self.tilt_axis) == len(self.tilt) == n):
            raise ValueError(f"tilt_link, tilt_axis and tilt need one entry per pose ({n})")
        on = self.tilt_link >= 0
        if not (np.isfinite(self.tilt[on]).all() and np.isin(self.tilt_axis[on], (0, 1)).all()):
            raise ValueError("a tilt row needs a finite reading and axis 0 (x) or 1 (y)")
        if not self.tilt_sigma > 0:
            raise ValueError("tilt_sigma must be > 0 (rad)")
        object.__setattr__(self, "tilt_home", _per_row(self.tilt_home, n, False, bool) & on)
        object.__setattr__(self, "tilt_mount", _mounts(self.tilt_mount, self.tilt_link, self.tilt_home))
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
        if not self.sigma > 0 or not self.distance_sigma > 0 or not self.position_sigma > 0:
            raise ValueError("sigma, tracker_sigma and distance_sigma must be > 0 (m)")

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
    def position_sigma(self) -> float:
        """The tracker rows' noise (m): ``tracker_sigma``, else ``sigma``."""
        return self.sigma if self.tracker_sigma is None else float(self.tracker_sigma)

    @property
    def tilted(self) -> NDArray[np.bool_]:
        """``(n,)`` whether pose ``i`` is an inclinometer reading."""
        return self.tilt_link >= 0

    @property
    def mounted(self) -> bool:
        """Whether any tilt row's sensor is mounted otherwise than along the joint frame
        (stated in the joint frame or at home)."""
        return bool(np.any(self.tilt_mount[self.tilted] != 0.0) or self.tilt_home.any())

    def mount_matrix(self, link: int) -> Array:
        """``R_joint_sensor`` ``(3, 3)`` of the sensor on ``link``'s rows (joint index, 0-based)."""
        from scipy.spatial.transform import Rotation

        rows = np.flatnonzero(self.tilt_link == link)
        if self.tilt_home[rows].any():  # a statement at home: resolve it against a chain first
            raise ValueError(f"link {link + 1}'s sensor is stated at home; resolve it (mounts_in) first")
        angles = self.tilt_mount[rows[0]] if len(rows) else np.zeros(3)
        return np.asarray(Rotation.from_euler("xyz", angles).as_matrix(), dtype=float)

    @property
    def constrained(self) -> NDArray[np.bool_]:
        """``(n,)`` whether pose ``i`` is in a constraint row (a point, a plane or a pair)."""
        out = (self.point >= 0) | (self.plane >= 0)
        out[self.pairs.reshape(-1)] = True
        return out

    def select(self, rows: NDArray[np.bool_]) -> ConstraintSet:
        """The poses where ``rows`` ``(n,)`` is True (pairs with both poses kept; points and
        planes keep their numbers, so the known distances and planes still apply)."""
        rows = np.asarray(rows, dtype=bool)
        new = np.cumsum(rows) - 1
        both = rows[self.pairs[:, 0]] & rows[self.pairs[:, 1]] if len(self.pairs) else np.zeros(0, bool)
        return ConstraintSet(
            self.q[rows], self.point[rows], self.plane[rows],
            position=None if self.position is None else self.positions[rows],
            pairs=new[self.pairs[both]], pair_length=self.pair_length[both],
            point_pairs=self.point_pairs, point_length=self.point_length, known_planes=self.known_planes,
            sigma=self.sigma, distance_sigma=self.distance_sigma, tracker_sigma=self.tracker_sigma,
            tilt_link=self.tilt_link[rows], tilt_axis=self.tilt_axis[rows], tilt=self.tilt[rows],
            tilt_sigma=self.tilt_sigma, tilt_mount=self.tilt_mount[rows], tilt_home=self.tilt_home[rows],
        )  # fmt: skip

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
        """The kinds present: ``point``, ``plane``, ``distance``, ``tracker``, ``tilt``."""
        found = [
            ("point", self.n_points > 0),
            ("plane", self.n_planes > 0),
            ("distance", len(self.pairs) > 0),
            ("tracker", bool(self.tracked.any())),
            ("tilt", bool(self.tilted.any())),
        ]
        return tuple(k for k, present in found if present)

    def unknown_plane(self, k: int) -> bool:
        return (
            self.known_planes is None
            or k >= len(self.known_planes)
            or not np.isfinite(self.known_planes[k]).all()
        )


def merge_sets(first: ConstraintSet, *others: ConstraintSet) -> ConstraintSet:
    """One set of the poses of all: ``others``' points and planes numbered after the ones
    before them (two files' socket 0 are two sockets), their pairs re-indexed; the noise
    (``sigma``, ``tracker_sigma``, ``distance_sigma``, ``tilt_sigma``) and the known planes
    of ``first``.

    Raises:
        ValueError: the sets have different numbers of joints.
    """
    sets = (first, *others)
    if len({s.q.shape[1] for s in sets}) > 1:
        raise ValueError("the files have different numbers of joint columns")
    point, plane, pairs, point_pairs = [], [], [], []
    n = n_points = n_planes = 0
    for s in sets:
        point.append(np.where(s.point >= 0, s.point + n_points, -1))
        plane.append(np.where(s.plane >= 0, s.plane + n_planes, -1))
        pairs.append(s.pairs + n)
        point_pairs.append(s.point_pairs + n_points)
        n, n_points, n_planes = n + s.n, n_points + s.n_points, n_planes + s.n_planes
    tracked = any(s.position is not None for s in sets)
    return ConstraintSet(
        np.vstack([s.q for s in sets]), np.concatenate(point), np.concatenate(plane),
        position=np.vstack([s.positions for s in sets]) if tracked else None,
        pairs=np.vstack(pairs), pair_length=np.concatenate([s.pair_length for s in sets]),
        point_pairs=np.vstack(point_pairs), point_length=np.concatenate([s.point_length for s in sets]),
        known_planes=first.known_planes,  # its planes keep their numbers
        sigma=first.sigma, distance_sigma=first.distance_sigma, tracker_sigma=first.tracker_sigma,
        tilt_link=np.concatenate([s.tilt_link for s in sets]),
        tilt_axis=np.concatenate([s.tilt_axis for s in sets]),
        tilt=np.concatenate([s.tilt for s in sets]), tilt_sigma=first.tilt_sigma,
        tilt_mount=np.concatenate([s.tilt_mount for s in sets]),
        tilt_home=np.concatenate([s.tilt_home for s in sets]),
    )  # fmt: skip
