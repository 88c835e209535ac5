"""Constraint measurements: calibrate from fixed points, planes and distances (no tracker).

Each measurement states where the tool point ``p_i = FK(q_i)`` (device frame; the robot's
base frame when no device measures) is, not what it reads:

* **fixed point** ``k``: ``p_i - c_k = 0`` (3 rows; a ball seated in socket ``k``, a sphere
  probed from many orientations), the point ``c_k`` (m) an unknown estimated with the
  robot; a known distance ``L`` between points ``a`` and ``b`` adds ``|c_a - c_b| - L = 0``;
* **plane** ``k``: ``n_k · p_i - d_k = 0`` (1 row), the unit normal and offset (m) unknown
  (``n = (n0 + a t1 + b t2) / |…|`` around a start normal ``n0`` with tangents ``t1, t2``:
  no singular direction near the start) or known;
* **distance**: ``|p_i - p_j| - L = 0`` (1 row) for a pair of poses whose tool points are a
  known length apart (ball-bar, a table of known points);
* **tracker point**: ``p_i - y_i = 0`` (3 rows), mixed with the others, weighted by the
  tracker's own σ (``ConstraintSet.tracker_sigma``); the device frame is then estimated
  too (its start by Kabsch on these rows);
* **inclinometer reading**: the tilt of a link's joint-frame axis against the horizontal
  (1 row, rad, weighted by ``tilt_sigma``), with a zero per channel and the joint effects
  as unknowns (:mod:`robocal.identify.constraints.tilt_rows`).

Residuals are weighted by 1/σ (the tool point's noise σ, isotropic; σ√2 for a distance
between two tool points; ``distance_sigma`` for a stated distance between fixed points).
The Jacobian is analytic: the chain's position Jacobian ``∂p_i/∂θ`` (m per unit) times the
constraint's gradient.  The unknowns are the chain's free parameters followed by the
points' coordinates and the planes' parameters; :func:`robocal.identify.constraints.fit`
fits them with the engine's stages.

An optional :class:`NominalPrior` adds one row per robot parameter,
``(θ - θ_nominal) / σ_prior`` (a Gaussian prior around the nominal geometry: the fit is
the MAP estimate), after the measurement rows; the rank test and the residual figures use
the measurement rows only.

What a kind cannot see is a null space of this Jacobian: rigid motions of the whole scene
for fixed points (the base frame), motion within the plane for a plane, every absolute
position for distances; a scale needs a known length (a distance).
"""

from __future__ import annotations

import dataclasses
import functools
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from robocal.identify.constraints.position_effects import PositionEffects
from robocal.identify.constraints.prior import NominalPrior
from robocal.identify.constraints.tilt_rows import TiltTerms, tilt_rows
from robocal.measure.constraints.data_set import ConstraintSet
from robocal.model.chain import Model
from robocal.model.steps import Role

__all__ = ["ConstraintProblem", "NominalPrior", "plane_normal"]

Array = NDArray[np.float64]
IntArray = NDArray[np.intp]


def plane_normal(n0: Array, tangents: Array, ab: Array) -> tuple[Array, Array]:
    """The unit normal ``n = (n0 + a t1 + b t2)/|…|`` and its derivatives ``(3, 2)``
    with respect to ``(a, b)``; ``tangents`` ``(2, 3)``."""
    v = n0 + ab[0] * tangents[0] + ab[1] * tangents[1]
    norm = float(np.linalg.norm(v))
    n = v / norm
    projector = (np.eye(3) - np.outer(n, n)) / norm
    return n, projector @ tangents.T


def _tangents(n0: Array) -> Array:
    """Two unit vectors orthogonal to ``n0`` and to each other ``(2, 3)``."""
    helper = np.eye(3)[int(np.argmin(np.abs(n0)))]
    t1 = np.cross(n0, helper)
    t1 /= np.linalg.norm(t1)
    return np.stack([t1, np.cross(n0, t1)])


@dataclass(frozen=True)
class _Layout:
    """Where the scene's unknowns sit in ``x`` after the chain's free parameters."""

    n_chain: int
    n_points: int
    planes: tuple[int, ...]  # the unknown planes' indices
    n_zeros: int = 0  # the inclinometer channels' zeros, then the joint effects
    n_effects: int = 0
    n_position: int = 0  # the position rows' joint effects not shared with the tilt rows

    @property
    def n_scene(self) -> int:
        return 3 * self.n_points + 3 * len(self.planes) + self.n_zeros

    @property
    def size(self) -> int:
        return self.n_chain + self.n_scene + self.n_effects + self.n_position

    @property
    def zeros(self) -> slice:
        at = self.n_chain + 3 * self.n_points + 3 * len(self.planes)
        return slice(at, at + self.n_zeros)

    @property
    def effects(self) -> slice:
        return slice(self.size - self.n_position - self.n_effects, self.size - self.n_position)

    def point(self, k: int) -> int:
        return self.n_chain + 3 * k

    def plane(self, k: int) -> int:
        return self.n_chain + 3 * self.n_points + 3 * self.planes.index(k)


class ConstraintProblem:
    """Weighted residuals and their analytic Jacobian for a :class:`ConstraintSet`.

    ``x`` holds the unknowns that are not fixed (:meth:`fix`): the chain's free
    parameters, then each point's ``x, y, z`` (m), then each unknown plane's ``a, b``
    (tilts of the normal, rad-like) and ``d`` (offset, m).  The interface is the one the
    engine's stages and solvers use (``residual``, ``jacobian``, ``x0``, ``free_names``,
    ``fix``, ``effect_scale``)."""

    rows = 3  # one group of rows for the residual variance (stages.uncertainty)
    n_effects = 0

    def __init__(self, chain: Model, data: ConstraintSet, full0: Array, planes0: Array, length_scale: float,
                 prior_weight: Array | None = None, tilt: TiltTerms | None = None,
                 position: PositionEffects | None = None):  # fmt: skip
        self.chain, self.data, self.length_scale = chain, data, float(length_scale)
        self.tilt = tilt  # the inclinometer rows' unknowns, None without tilt rows
        # (p_chain,) 1/σ of a prior about full0's chain values (NominalPrior.weights), or None
        self.prior_weight = None if prior_weight is None else np.asarray(prior_weight, dtype=float)
        planes = tuple(k for k in range(data.n_planes) if data.unknown_plane(k))
        n_zeros, n_effects = (0, 0) if tilt is None else (len(tilt.zeros), len(tilt.effects))
        self.position = position  # joint effects on the position rows (position_effects), or None
        shared = () if tilt is None else tilt.effects  # one unknown per effect for every row kind
        n_position = 0 if position is None else sum(n not in shared for n in position.names)
        self.layout = _Layout(len(chain.free_names), data.n_points, planes, n_zeros, n_effects, n_position)
        self.full0 = np.asarray(full0, dtype=float)
        self.planes0 = np.asarray(planes0, dtype=float)  # (P, 4): start / known normal, offset
        self.tangents = (
            np.stack([_tangents(p[:3]) for p in self.planes0]) if len(self.planes0) else np.zeros((0, 2, 3))
        )
        self.keep = np.ones(self.layout.size, dtype=bool)
        self._cache: dict = {}

    # ------------------------------------------------------------------ names and values
    @functools.cached_property
    def all_names(self) -> tuple[str, ...]:
        names = list(self.chain.free_names)
        names += [f"point{k}_{c}" for k in range(self.data.n_points) for c in "xyz"]
        names += [f"plane{k}_{c}" for k in self.layout.planes for c in ("a", "b", "d")]
        if self.tilt is not None:
            names += [*self.tilt.zeros, *self.tilt.effects]
        if self.position is not None:
            names += [n for n in self.position.names if n not in names]
        return tuple(names)

    @property
    def position_names(self) -> tuple[str, ...]:
        """The joint effects the position rows carry (empty without)."""
        return () if self.position is None else self.position.names

    @functools.cached_property
    def _position_columns(self) -> IntArray:
        """Where the position rows' joint effects sit in ``full``."""
        names = () if self.position is None else self.position.names
        return np.array([self.all_names.index(n) for n in names], dtype=np.intp)

    @property
    def free_names(self) -> tuple[str, ...]:
        return tuple(n for n, k in zip(self.all_names, self.keep, strict=True) if k)

    @property
    def scene_names(self) -> tuple[str, ...]:
        """The points', planes' and inclinometer zeros' unknowns (never pruned)."""
        return self.all_names[self.layout.n_chain : self.layout.n_chain + self.layout.n_scene]

    @property
    def roles(self) -> dict[str, Role]:
        """The chain's roles, the scene's unknowns as the device's (kept first by the rank
        test), the joint effects as the robot's (last)."""
        effects = {} if self.tilt is None else dict.fromkeys(self.tilt.effects, Role.KINEMATIC)
        effects |= {} if self.position is None else dict.fromkeys(self.position.names, Role.KINEMATIC)
        return {**self.chain.roles, **{n: Role.DEVICE for n in self.scene_names}, **effects}

    @property
    def x0(self) -> Array:
        return self.full0[self.keep]

    def full(self, x: Array) -> Array:
        v = self.full0.copy()
        v[self.keep] = x
        return v

    def fix(self, names) -> ConstraintProblem:
        """The same problem with ``names`` held at their start values."""
        fixed = object.__new__(ConstraintProblem)
        fixed.__dict__.update(self.__dict__)
        fixed.keep = self.keep & ~np.isin(np.array(self.all_names), list(names))
        fixed._cache = {}
        return fixed

    @functools.cached_property
    def _full_scale(self) -> Array:
        rot = [s.is_rotation for s in self.chain.steps if s.free]
        scene = [  # angles (plane tilts, inclinometer zeros) as the displacement they make
            self.length_scale if (n[-1] in "ab" and n.startswith("plane")) or n.startswith("tilt") else 1.0
            for n in self.scene_names
        ]
        effects = np.zeros(0) if self.tilt is None else self.length_scale * self.tilt.effect_scale
        out = np.concatenate(
            [np.where(rot, self.length_scale, 1.0), scene, effects, np.zeros(self.layout.n_position)]
        )
        if self.position is not None:  # the largest tool displacement per unit (m)
            out[self._position_columns] = self.position.scale
        return out

    @property
    def free_scale(self) -> Array:
        """Displacement (m) per unit of each unknown: 1 for lengths, the robot's size for angles."""
        return self._full_scale[self.keep]

    def effect_scale(self, x: Array) -> Array:
        """``(p,)`` displacement (m) per unit of each unknown (pruning judges σ by it): the
        largest tool displacement over the poses for the chain's, else :attr:`free_scale`."""
        from robocal.identify.stages import tool_displacement_scale

        Jp = self._chain(x)[1].reshape(self.data.n, 3, -1)
        scale = self._full_scale.copy()
        scale[: self.layout.n_chain] = tool_displacement_scale(Jp)
        return scale[self.keep]

    def scaled_jacobian(self, x: Array) -> Array:
        return self.jacobian(x) * self.free_scale

    # ------------------------------------------------------------------ evaluation
    def _chain(self, x: Array) -> tuple[Array, Array, Array | None]:
        """Tool points ``(n, 3)``, their Jacobian ``(3n, p_chain)`` over the chain's free
        parameters and ``(n, 3, m)`` over the position rows' joint effects (None without)."""
        full = self.full(np.asarray(x, dtype=float))
        key = full.tobytes()
        if key not in self._cache:
            self._cache.clear()
            values = self.chain.values.copy()
            values[self.chain.free_mask] = full[: self.layout.n_chain]
            effects = self.position
            if effects is None:
                T, J = self.chain.evaluate(self.data.q, values, rows="position", jacobian=True)[:2]
                self._cache[key] = (T[:, :3, 3], J, None)
            else:  # the joints' deflections under the held loads, exact as Model.fk takes them
                d = effects.perturbations(full[self._position_columns])
                out = self.chain.evaluate(self.data.q, values, "position", True, d, perturbation_columns=True)
                P = out[-1].reshape(self.data.n, 3, self.chain.dof, 3)
                self._cache[key] = (out[0][:, :3, 3], out[1], effects.columns(P))
        return self._cache[key]

    def consistent_jacobian(self, x: Array) -> Array:
        """The weighted Jacobian ``(m, p)`` at consistent data: each pose's joint values
        moved (IK of the chain at ``x``, a few µm to mm) so that its tool point lies on what
        it touches (its point, its plane, its tracker position, its pair's length).  There a
        rigid motion of the whole scene, and without a known length its scale, are exact
        null vectors whatever the residuals were; at the measured joint values a residual of
        17 mm on a 0.8 m arm made the base frame's rotations look identifiable (the rank
        test tells columns apart to 1e-7).  For the rank test only."""
        from robocal.measure.ik import solve_ik

        full = self.full(np.asarray(x, dtype=float))
        chain = self.chain.with_free_values(full[: self.layout.n_chain])
        p = self._chain(x)[0]
        ik = solve_ik(chain, self._touched(x, p), kind="position", q0=self.data.q, restarts=0, tol=1e-12,
                      seed_pool=0)  # fmt: skip
        return self.with_data(dataclasses.replace(self.data, q=ik.q)).jacobian(x)

    def with_data(self, data: ConstraintSet, prior: bool = True) -> ConstraintProblem:
        """The same unknowns, start values and fixed set on ``data`` (the same rows, moved
        joint values or other noise weights); ``prior=False``: without the prior rows."""
        moved = object.__new__(ConstraintProblem)
        moved.__dict__.update(self.__dict__)
        moved.data = data
        moved.prior_weight = self.prior_weight if prior else None
        moved._cache = {}
        return moved

    def _touched(self, x: Array, p: Array) -> Array:
        """``(n, 3)`` the point each pose's tool point touches (itself for distances only)."""
        d = self.data
        out = p.copy()
        on_plane = d.plane >= 0
        if on_plane.any():
            planes = self.plane_values(x)[d.plane[on_plane]]
            dist = np.einsum("ij,ij->i", p[on_plane], planes[:, :3]) - planes[:, 3]
            out[on_plane] = p[on_plane] - dist[:, None] * planes[:, :3]
        on_point = d.point >= 0
        if on_point.any():
            out[on_point] = self.points(x)[d.point[on_point]]
        if len(d.pairs):
            a, b = d.pairs[:, 0], d.pairs[:, 1]
            delta = out[b] - out[a]
            out[b] = out[a] + delta * (d.pair_length / np.linalg.norm(delta, axis=1))[:, None]
        if d.position is not None:
            tracked = d.tracked
            out[tracked] = d.positions[tracked]
        return out

    def plane_values(self, x: Array) -> Array:
        """``(P, 4)`` every plane's unit normal and offset (m) at ``x``."""
        full = self.full(np.asarray(x, dtype=float))
        out = self.planes0.copy()
        for k in self.layout.planes:
            at = self.layout.plane(k)
            out[k, :3] = plane_normal(self.planes0[k, :3], self.tangents[k], full[at : at + 2])[0]
            out[k, 3] = full[at + 2]
        return out

    def points(self, x: Array) -> Array:
        """``(K, 3)`` the fixed points at ``x`` (m)."""
        full = self.full(np.asarray(x, dtype=float))
        return full[self.layout.point(0) : self.layout.point(0) + 3 * self.data.n_points].reshape(-1, 3)

    def _blocks(self, x: Array) -> tuple[Array, Array]:
        """Weighted residuals ``(m,)`` and Jacobian ``(m, size)`` over every unknown."""
        full = self.full(np.asarray(x, dtype=float))
        p, Jc, Je = self._chain(x)
        d, lay = self.data, self.layout
        Jp = np.zeros((d.n, 3, lay.size))
        Jp[:, :, : lay.n_chain] = Jc.reshape(d.n, 3, -1)
        if Je is not None:
            Jp[:, :, self._position_columns] += Je
        r_parts, J_parts = [], []
        on_point = np.flatnonzero(d.point >= 0)
        if len(on_point):
            r, J = self._point_rows(full, p, Jp, on_point)
            r_parts.append(r)
            J_parts.append(J)
        on_plane = np.flatnonzero(d.plane >= 0)
        if len(on_plane):
            r, J = self._plane_rows(full, p, Jp, on_plane)
            r_parts.append(r)
            J_parts.append(J)
        if r_parts:
            r_parts, J_parts = [np.concatenate(r_parts) / d.sigma], [np.concatenate(J_parts) / d.sigma]
        tracked = d.tracked
        if tracked.any():  # each kind weighted by its own noise (mixed data)
            r_parts.append((p[tracked] - d.positions[tracked]).reshape(-1) / d.position_sigma)
            J_parts.append(Jp[tracked].reshape(-1, lay.size) / d.position_sigma)
        if len(d.pairs):
            r, J = self._pair_rows(p, Jp)
            r_parts.append(r / (d.sigma * np.sqrt(2)))
            J_parts.append(J / (d.sigma * np.sqrt(2)))
        if len(d.point_pairs):
            r, J = self._point_distance_rows(full)
            r_parts.append(r / d.distance_sigma)
            J_parts.append(J / d.distance_sigma)
        if d.tilted.any():
            r, J = self._tilt_rows(full)
            r_parts.append(r / d.tilt_sigma)
            J_parts.append(J / d.tilt_sigma)
        if self.n_prior_rows:
            r, J = self._prior_rows(full)
            r_parts.append(r)
            J_parts.append(J)
        return np.concatenate(r_parts), np.concatenate(J_parts)

    @property
    def _prior_columns(self) -> IntArray:
        """The chain columns (of ``full``) with a prior that are not fixed."""
        if self.prior_weight is None:
            return np.zeros(0, dtype=np.intp)
        n = self.layout.n_chain
        return np.flatnonzero((self.prior_weight > 0) & self.keep[:n])

    @property
    def n_prior_rows(self) -> int:
        """How many prior rows follow the measurement rows (0 without a prior)."""
        return len(self._prior_columns)

    def _prior_rows(self, full: Array) -> tuple[Array, Array]:
        """``(θ - θ_nominal)/σ`` of each chain unknown with a prior (already weighted)."""
        on = self._prior_columns
        w = self.prior_weight[on] if self.prior_weight is not None else np.zeros(0)
        J = np.zeros((len(on), self.layout.size))
        J[np.arange(len(on)), on] = w
        return w * (full[on] - self.full0[on]), J

    def measurement_residual(self, x: Array) -> Array:
        """Weighted residuals of the measurements alone (no prior rows)."""
        r = self.residual(x)
        return r[: len(r) - self.n_prior_rows]

    def _point_rows(self, full: Array, p: Array, Jp: Array, rows: IntArray) -> tuple[Array, Array]:
        k = self.data.point[rows]
        at = self.layout.n_chain + 3 * k
        c = full[at[:, None] + np.arange(3)]
        J = Jp[rows].copy()
        J[np.arange(len(rows))[:, None], np.arange(3)[None, :], at[:, None] + np.arange(3)] -= 1.0
        return (p[rows] - c).reshape(-1), J.reshape(-1, self.layout.size)

    def _plane_rows(self, full: Array, p: Array, Jp: Array, rows: IntArray) -> tuple[Array, Array]:
        r = np.empty(len(rows))
        J = np.zeros((len(rows), self.layout.size))
        for row, i in enumerate(rows):
            k = int(self.data.plane[i])
            if k in self.layout.planes:
                at = self.layout.plane(k)
                n, dn = plane_normal(self.planes0[k, :3], self.tangents[k], full[at : at + 2])
                offset = full[at + 2]
                J[row, at : at + 2] = p[i] @ dn
                J[row, at + 2] = -1.0
            else:
                n, offset = self.planes0[k, :3], self.planes0[k, 3]
            r[row] = n @ p[i] - offset
            J[row] += n @ Jp[i]
        return r, J

    def _pair_rows(self, p: Array, Jp: Array) -> tuple[Array, Array]:
        a, b = self.data.pairs[:, 0], self.data.pairs[:, 1]
        delta = p[a] - p[b]
        length = np.linalg.norm(delta, axis=1)
        u = delta / np.maximum(length, 1e-300)[:, None]
        J = np.einsum("mr,mrp->mp", u, Jp[a] - Jp[b])
        return length - self.data.pair_length, J

    def _tilt_rows(self, full: Array) -> tuple[Array, Array]:
        """The inclinometer rows (rad) and their Jacobian over every unknown."""
        assert self.tilt is not None  # tilt rows are built with their terms
        lay, terms = self.layout, self.tilt
        values = dict(zip(self.chain.free_names, full[: lay.n_chain].tolist(), strict=True))
        r, J_geom, J_effects = tilt_rows(terms, self.data, values, full[lay.zeros], full[lay.effects])
        J = np.zeros((len(r), lay.size))
        column = {n: k for k, n in enumerate(self.chain.free_names)}
        J[:, [column[g] for g in terms.geometry]] = J_geom
        J[np.arange(len(r)), lay.zeros.start + terms.channel] = 1.0
        J[:, lay.effects] = J_effects
        return r, J

    def _point_distance_rows(self, full: Array) -> tuple[Array, Array]:
        d, lay = self.data, self.layout
        c = full[lay.point(0) : lay.point(0) + 3 * d.n_points].reshape(-1, 3)
        a, b = d.point_pairs[:, 0], d.point_pairs[:, 1]
        delta = c[a] - c[b]
        length = np.linalg.norm(delta, axis=1)
        u = delta / np.maximum(length, 1e-300)[:, None]
        J = np.zeros((len(a), lay.size))
        for row in range(len(a)):
            J[row, lay.point(int(a[row])) : lay.point(int(a[row])) + 3] += u[row]
            J[row, lay.point(int(b[row])) : lay.point(int(b[row])) + 3] -= u[row]
        return length - d.point_length, J

    def row_groups(self) -> tuple[tuple[str, slice], ...]:
        """The measurement rows of each noise group in the residual's order: ``constraint``
        (points, planes; σ), ``tracker`` (its own σ), ``pair`` (σ√2), ``known distance``,
        ``tilt`` (inclinometer readings, rad)."""
        d = self.data
        sizes = [
            ("constraint", 3 * int(np.sum(d.point >= 0)) + int(np.sum(d.plane >= 0))),
            ("tracker", 3 * int(d.tracked.sum())),
            ("pair", len(d.pairs)),
            ("known distance", len(d.point_pairs)),
            ("tilt", int(d.tilted.sum())),
        ]
        out, at = [], 0
        for name, size in sizes:
            if size:
                out.append((name, slice(at, at + size)))
            at += size
        return tuple(out)

    def row_sigma(self) -> Array:
        """``(m,)`` each measurement row's noise (m; rad for tilt rows): the weights' inverse."""
        d = self.data
        sigma = {"constraint": d.sigma, "pair": d.sigma * np.sqrt(2), "tracker": d.position_sigma,
                 "known distance": d.distance_sigma, "tilt": d.tilt_sigma}  # fmt: skip
        out = np.empty(sum(s.stop - s.start for _, s in self.row_groups()))
        for name, rows in self.row_groups():
            out[rows] = sigma[name]
        return out

    def residual(self, x: Array, weighted: bool = True) -> Array:
        """Weighted residuals ``(m,)`` (``weighted=False``: the measurement rows in m), the
        prior rows last."""
        r = self._blocks(x)[0]
        return r if weighted else r[: len(r) - self.n_prior_rows] * self.row_sigma()

    def jacobian(self, x: Array, weighted: bool = True) -> Array:
        """d residual / d x ``(m, p)`` over the unknowns not fixed."""
        J = self._blocks(x)[1][:, self.keep]
        return J if weighted else J[: len(J) - self.n_prior_rows] * self.row_sigma()[:, None]
