"""Cartesian paths — lines, circles, cubic splines — and their joint paths by IK.

* :func:`line_path` — straight segments sampled uniformly.
* :class:`Circle`, :func:`circle_through`, :func:`circle_path` — the circle through
  three or more points (checked to be coplanar and concyclic), sampled by angle.
  Seed 003 §5.5 defines its test trajectory as the circle through [0 −370.7107 210],
  [−100 −300 139.2893], [0 −229.2893 68.5786] and [100 −300 139.2893] mm: centre
  [0 −300 139.2893] mm, radius 100 mm, on the 45° plane y + z = −160.7107 mm (normal
  (0, 1, 1)/√2) — a diagonal plane of a cube with edges along the base axes.
* :class:`CubicSpline`, :func:`cubic_spline` — seed 001's Cartesian cubic spline
  (eq. 3): on each segment ``s(t) = a0 + a1 t + a2 t² + a3 t³`` with the waypoints'
  positions and velocities as the four boundary conditions.
* :func:`joint_path` — joint values along a sampled path by the batched IK, warm
  started from sample to sample so the configuration branch is kept; unreachable
  samples and branch jumps are reported, not hidden.

Positions are metres in the robot's base frame, times seconds, velocities m/s.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Unpack

import numpy as np
from numpy.typing import ArrayLike, NDArray

from robocal.measure.ik import IKSettings, solve_ik
from robocal.measure.ik_starts import TargetKind
from robocal.model.chain import Model

__all__ = [
    "THESIS_CIRCLE_MM",
    "Circle",
    "CubicSpline",
    "JointPath",
    "circle_path",
    "circle_through",
    "cubic_spline",
    "joint_path",
    "line_path",
]

Array = NDArray[np.float64]

#: Seed 003 §5.5: the points of the circular test trajectory, Katana 450 base frame, mm.
THESIS_CIRCLE_MM = np.array(
    [
        [0.0, -370.7107, 210.0],
        [-100.0, -300.0, 139.2893],
        [0.0, -229.2893, 68.5786],
        [100.0, -300.0, 139.2893],
    ]
)


def _points(points: ArrayLike, what: str, minimum: int = 1) -> Array:
    p = np.asarray(points, dtype=float)
    if p.ndim != 2 or p.shape[1] != 3 or len(p) < minimum:
        raise ValueError(
            f"{what} must be ({'n' if minimum <= 1 else f'>= {minimum}'}, 3) points (m), got shape {p.shape}"
        )
    if not np.all(np.isfinite(p)):
        raise ValueError(f"{what} contain NaN or inf (row {int(np.flatnonzero(~np.isfinite(p).all(1))[0])})")
    return p


# ------------------------------------------------------------------------ lines
def line_path(start: ArrayLike, end: ArrayLike, n: int) -> Array:
    """``(n, 3)`` points from ``start`` to ``end`` (m), both included, evenly spaced."""
    a = np.asarray(start, dtype=float).reshape(3)
    b = np.asarray(end, dtype=float).reshape(3)
    if n < 2:
        raise ValueError(f"a line needs n >= 2 samples, got {n}")
    return a + np.linspace(0.0, 1.0, int(n))[:, None] * (b - a)


# ------------------------------------------------------------------------ circles
@dataclass(frozen=True)
class Circle:
    """A circle in space.

    Attributes:
        center: ``(3,)`` centre (m).
        radius: m.
        normal: ``(3,)`` unit normal; the circle runs counter-clockwise about it.
        u: ``(3,)`` unit vector from the centre to the angle-0 point (the first
            point it was fitted through).
    """

    center: Array
    radius: float
    normal: Array
    u: Array

    @property
    def v(self) -> Array:
        """``(3,)`` unit vector at angle +90°: ``normal × u``."""
        return np.cross(self.normal, self.u)

    def at(self, angle: ArrayLike) -> Array:
        """Points ``S + (3,)`` (m) at angles ``S`` (rad) from ``u`` about ``normal``."""
        a = np.asarray(angle, dtype=float)[..., None]
        return self.center + self.radius * (np.cos(a) * self.u + np.sin(a) * self.v)

    def angle_of(self, points: ArrayLike) -> Array:
        """Angles ``(n,)`` in [0, 2π) of points (projected onto the circle's plane)."""
        d = np.asarray(points, dtype=float) - self.center
        return np.mod(np.arctan2(d @ self.v, d @ self.u), 2 * math.pi)


def circle_through(points: ArrayLike, tol: float = 1e-6) -> Circle:
    """The circle through three or more points ``(k, 3)`` (m), given in order along it.

    The plane is the least-squares plane of the points (SVD), the circle the algebraic
    least-squares circle in that plane (exact for three points).  The normal is
    oriented so that the points follow each other counter-clockwise; angle 0 is the
    first point.

    Raises:
        ValueError: fewer than three points, collinear points, or a point farther than
            ``tol`` (m) from the fitted plane or circle (named in the message).
    """
    p = _points(points, "circle points", minimum=3)
    mean = p.mean(axis=0)
    _, s, Vt = np.linalg.svd(p - mean)
    if s[1] <= 1e-12 * max(s[0], 1e-300):
        raise ValueError("circle points are collinear (or coincide): no circle passes through them")
    e1, e2, normal = Vt
    off = (p - mean) @ normal
    worst = int(np.argmax(np.abs(off)))
    if abs(off[worst]) > tol:
        raise ValueError(
            f"circle points are not coplanar: point {worst} lies {abs(off[worst]):.3g} m from the "
            f"best plane (tolerance {tol:g} m)"
        )
    x, y = (p - mean) @ e1, (p - mean) @ e2
    A = np.column_stack([x, y, np.ones_like(x)])
    D, E, F = np.linalg.lstsq(A, -(x**2 + y**2), rcond=None)[0]
    cx, cy = -D / 2, -E / 2
    radius = math.sqrt(max(cx**2 + cy**2 - F, 0.0))
    center = mean + cx * e1 + cy * e2
    radial = np.abs(np.hypot(x - cx, y - cy) - radius)
    worst = int(np.argmax(radial))
    if radial[worst] > tol:
        raise ValueError(
            f"circle points are not on one circle: point {worst} is {radial[worst]:.3g} m off the "
            f"fitted circle of radius {radius:.6g} m (tolerance {tol:g} m)"
        )
    u = p[0] - center
    u -= normal * (u @ normal)
    u /= np.linalg.norm(u)
    circle = Circle(center, radius, normal, u)
    angles = circle.angle_of(p[1:])
    if not np.all(np.diff(angles) > 0):  # points run clockwise about this normal: flip it
        circle = Circle(center, radius, -normal, u)
    return circle


def circle_path(
    circle: Circle | ArrayLike, n: int, *, sweep: float = 2 * math.pi, start: float = 0.0
) -> Array:
    """``(n, 3)`` points (m) along a circle (or the circle through the given points).

    A full circle (``sweep = 2π``) is sampled without repeating the first point; an
    arc includes both ends.  Angles are measured from the circle's first point,
    counter-clockwise about its normal (the order of the points it was fitted through).
    """
    c = circle if isinstance(circle, Circle) else circle_through(circle)
    if n < 2:
        raise ValueError(f"a circle path needs n >= 2 samples, got {n}")
    closed = math.isclose(abs(sweep), 2 * math.pi)
    t = np.linspace(0.0, 1.0, int(n), endpoint=not closed)
    return c.at(start + sweep * t)


# ------------------------------------------------------------------------ cubic splines
@dataclass(frozen=True)
class CubicSpline:
    """Piecewise cubic Cartesian path, seed 001 eq. (3).

    Attributes:
        times: ``(m,)`` waypoint times (s), increasing.
        coefficients: ``(m - 1, 4, 3)``: ``a0..a3`` of each segment, ``s(τ) = a0 + a1 τ
            + a2 τ² + a3 τ³`` with ``τ`` the time since the segment's start.
    """

    times: Array
    coefficients: Array

    @property
    def duration(self) -> float:
        return float(self.times[-1] - self.times[0])

    def _locate(self, t: ArrayLike) -> tuple[NDArray[np.intp], Array]:
        t = np.asarray(t, dtype=float)
        if np.any((t < self.times[0] - 1e-12) | (t > self.times[-1] + 1e-12)):
            raise ValueError(f"times must lie in [{self.times[0]}, {self.times[-1]}] s")
        k = np.clip(np.searchsorted(self.times, t, side="right") - 1, 0, len(self.times) - 2)
        return k, t - self.times[k]

    def __call__(self, t: ArrayLike) -> Array:
        """Positions ``S + (3,)`` (m) at times ``S`` (s)."""
        k, tau = self._locate(t)
        a = self.coefficients[k]
        tau = tau[..., None]
        return a[..., 0, :] + tau * (a[..., 1, :] + tau * (a[..., 2, :] + tau * a[..., 3, :]))

    def velocity(self, t: ArrayLike) -> Array:
        """Velocities ``S + (3,)`` (m/s) at times ``S`` (s)."""
        k, tau = self._locate(t)
        a = self.coefficients[k]
        tau = tau[..., None]
        return a[..., 1, :] + tau * (2 * a[..., 2, :] + 3 * tau * a[..., 3, :])

    def sample(self, n: int) -> tuple[Array, Array]:
        """``n`` times (s) evenly spread over the spline, both ends included, and the
        positions ``(n, 3)`` (m) there."""
        if n < 2:
            raise ValueError(f"a spline path needs n >= 2 samples, got {n}")
        t = np.linspace(self.times[0], self.times[-1], int(n))
        return t, self(t)


def cubic_spline(
    waypoints: ArrayLike, velocities: ArrayLike | None = None, times: ArrayLike | None = None
) -> CubicSpline:
    """The Cartesian cubic spline of seed 001 through ``waypoints`` ``(m, 3)`` (m).

    Each segment ``i`` is ``s(τ) = a0 + a1 τ + a2 τ² + a3 τ³`` (seed 001 eq. 3) with the
    four conditions ``s(0) = p_i``, ``s(T) = p_{i+1}``, ``s'(0) = v_i``, ``s'(T) = v_{i+1}``
    (``T`` the segment's duration), so

        a0 = p_i,  a1 = v_i,
        a2 = (3 (p_{i+1} − p_i) − (2 v_i + v_{i+1}) T) / T²,
        a3 = (−2 (p_{i+1} − p_i) + (v_i + v_{i+1}) T) / T³.

    Args:
        waypoints: ``(m, 3)`` positions (m), m >= 2.
        velocities: ``(m, 3)`` velocities at the waypoints (m/s).  Default: zero at the
            ends and, inside, the central difference ``(p_{i+1} − p_{i−1}) / (t_{i+1} −
            t_{i−1})`` (a Catmull–Rom choice; the seed leaves them to the user).
        times: ``(m,)`` increasing waypoint times (s); default 0, 1, 2, ... s.
    """
    p = _points(waypoints, "spline waypoints", minimum=2)
    m = len(p)
    t = np.arange(m, dtype=float) if times is None else np.asarray(times, dtype=float).reshape(-1)
    if t.shape != (m,) or not np.all(np.isfinite(t)):
        raise ValueError(f"times must be {m} finite values (s), got shape {t.shape}")
    if np.any(np.diff(t) <= 0):
        bad = int(np.flatnonzero(np.diff(t) <= 0)[0])
        raise ValueError(f"times must increase: t[{bad + 1}] = {t[bad + 1]} <= t[{bad}] = {t[bad]}")
    if velocities is None:
        v = np.zeros_like(p)
        if m > 2:
            v[1:-1] = (p[2:] - p[:-2]) / (t[2:] - t[:-2])[:, None]
    else:
        v = np.asarray(velocities, dtype=float)
        if v.shape != (m, 3) or not np.all(np.isfinite(v)):
            raise ValueError(f"velocities must be ({m}, 3) finite values (m/s), got shape {v.shape}")
    T = np.diff(t)[:, None]
    dp = p[1:] - p[:-1]
    v0, v1 = v[:-1], v[1:]
    coeffs = np.stack(
        [p[:-1], v0, (3 * dp - (2 * v0 + v1) * T) / T**2, (-2 * dp + (v0 + v1) * T) / T**3], axis=1
    )
    return CubicSpline(times=t, coefficients=coeffs)


# ------------------------------------------------------------------------ joint paths
@dataclass(frozen=True)
class JointPath:
    """Joint values along a sampled Cartesian path.

    Attributes:
        q: ``(n, dof)`` joint values (rad or m); for unreachable samples the IK's
            closest attempt.
        reachable: ``(n,)`` whether each sample was reached (see :func:`solve_ik`).
        position_error: ``(n,)`` m.
        angle_error: ``(n,)`` rad (zeros for position targets).
        jumps: indices ``i`` where ``max |q_i − q_{i−1}|`` exceeds ``max_joint_step``:
            a branch switch or a discontinuity between samples ``i − 1`` and ``i``.
    """

    q: Array
    reachable: NDArray[np.bool_]
    position_error: Array
    angle_error: Array
    jumps: NDArray[np.intp]

    @property
    def success(self) -> bool:
        """All samples reached, no jumps."""
        return bool(self.reachable.all() and not len(self.jumps))

    @property
    def unreachable(self) -> NDArray[np.intp]:
        """Indices of the samples that were not reached."""
        return np.flatnonzero(~self.reachable)


def joint_path(
    model: Model,
    targets: ArrayLike,
    *,
    kind: TargetKind | None = None,
    q0: ArrayLike | None = None,
    max_joint_step: float = 0.35,
    block: int = 16,
    tool_axis: int = 2,
    seed: int = 0,
    **ik_options: Unpack[IKSettings],
) -> JointPath:
    """Joint values along a sampled path: positions ``(n, 3)`` or frames ``(n, 4, 4)`` (m).

    The first sample starts from ``q0`` (to choose the configuration branch; random
    restarts only if it fails or when ``q0`` is None).  Every later sample starts from
    the solution of the sample before it, so the branch is kept and the joint path is
    smooth.  For speed, samples are solved in blocks of ``block`` from the last solved
    configuration; where a block's solution is not reached or jumps by more than
    ``max_joint_step`` (rad or m, any joint) between samples, the rest of the block is
    re-solved one sample at a time from its predecessor.  No random restarts happen
    after the first sample, so an unreachable stretch is reported (``reachable``),
    and the path continues from the last reached configuration.

    Args:
        model: the robot.
        targets: ``(n, 3)`` positions or ``(n, 4, 4)`` frames, base frame, m.
        kind: ``"position"``, ``"pose"`` or ``"axis"``; default from the targets' shape.
        q0: ``(dof,)`` starting configuration for the first sample.
        max_joint_step: joint change between consecutive samples above which the
            change is flagged as a jump.
        block: samples solved together from one starting configuration.
        tool_axis: the tool axis imposed by ``kind="axis"``.
        seed: seed of the first sample's random restarts.
        **ik_options: passed to :func:`solve_ik` (``tol``, ``tol_angle``, ``max_iter``...).
    """
    T = np.asarray(targets, dtype=float)
    kind_ = kind or ("position" if T.shape[-1:] == (3,) and T.ndim == 2 else "pose")
    n = len(T)
    if n == 0:
        raise ValueError("joint_path needs at least one sample")
    dof = model.dof
    q = np.zeros((n, dof))
    dist, angle = np.zeros(n), np.zeros(n)
    reach = np.zeros(n, dtype=bool)

    def ik(sl: slice, start: Array, restarts: int = 0) -> None:
        r = solve_ik(
            model,
            T[sl],
            kind=kind_,
            q0=start,
            restarts=restarts,
            seed=seed,
            tool_axis=tool_axis,
            **ik_options,
        )
        q[sl], dist[sl], angle[sl], reach[sl] = r.q, r.position_error, r.angle_error, r.reachable

    if q0 is None:
        ik(slice(0, 1), None, restarts=20)  # type: ignore[arg-type]
    else:
        q0 = np.asarray(q0, dtype=float).reshape(dof)
        ik(slice(0, 1), q0)
        if not reach[0]:
            ik(slice(0, 1), q0, restarts=20)
    _follow(ik, q, reach, block, max_joint_step)
    steps = np.r_[0.0, np.abs(np.diff(q, axis=0)).max(axis=1)] if n > 1 else np.zeros(1)
    jumps = np.flatnonzero(steps > max_joint_step)
    return JointPath(q=q, reachable=reach, position_error=dist, angle_error=angle, jumps=jumps)


def _follow(
    ik: Callable[[slice, Array], None], q: Array, reach: NDArray[np.bool_], block: int, max_joint_step: float
) -> None:
    """Solve samples 1.. of a path (``ik`` fills ``q`` and ``reach`` for a slice) in blocks from
    the last reached configuration; a block that misses a sample or jumps by more than
    ``max_joint_step`` is re-solved one sample at a time from its first doubtful sample on."""
    n = len(q)
    last = q[0].copy()
    i = 1
    while i < n:
        j = min(i + block, n)
        ik(slice(i, j), last)
        steps = np.abs(np.diff(np.vstack([last, q[i:j]]), axis=0)).max(axis=1)
        bad = np.flatnonzero(~reach[i:j] | (steps > max_joint_step))
        if len(bad):  # sequential from the first doubtful sample on
            for k in range(i + int(bad[0]), j):
                ik(slice(k, k + 1), last)
                if reach[k]:
                    last = q[k].copy()
        elif reach[j - 1]:
            last = q[j - 1].copy()
        i = j
