"""Simulated constraint measurements with known truth (:mod:`robocal.identify.constraints.model`).

The *true* robot puts its tool point where the constraint says, up to the tool point's
noise σ (isotropic, m): a ball seated in a socket ``c_k + e``, a probe touching a plane
``p + (n·e) n``, two tool points ``L + √2 σ e`` apart.  The recorded joint values are
those the true robot needs for it (IK from random starting configurations, so the
orientations vary as when the arm is moved by hand); a calibration sees only them.

A true robot that states joint compliances (``joint_effects``) and its link masses
(``bodies``) yields to gravity: its tool point is where the chain puts it with the joints
deflected by those loads (:func:`tool_points`, as
:func:`robocal.identify.constraints.figures.tool_points` predicts it), and the recorded
joint values seat the deflected tool point (tracker rows: the deflected point measured,
when asked: :func:`simulate_tracker_rows`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation

from robocal.measure.constraints.data_set import KINDS, TILT_SIGMA, ConstraintSet
from robocal.measure.ik import solve_ik
from robocal.measure.ik_starts import random_configurations
from robocal.model.chain import Model

__all__ = [
    "MAX_TILT",
    "SceneTruth",
    "level_mounts",
    "moved_scene",
    "simulate_constraints",
    "simulate_tilt_rows",
    "simulate_tracker_rows",
    "tool_points",
]

Array = NDArray[np.float64]


@dataclass(frozen=True)
class SceneTruth:
    """The scene a simulation used (m): fixed points ``(K, 3)``, planes ``(P, 4)`` (unit
    normal, offset), the distance pairs' length."""

    points: Array
    planes: Array
    length: float


def _deflections(true: Model, q: Array) -> Array | None:
    """``(n, dof, 3)`` the joints' elastic deflections (rad) under the gravity loads of
    ``true``'s link masses (its compliance and radial compliance), None when it states none
    or has no masses."""
    from robocal.model.joints import joint_perturbations

    elastic = any(e.compliance or e.radial_compliance for e in true.joint_effects)
    if not elastic or not true.bodies:
        return None
    return joint_perturbations(true, np.atleast_2d(q), kinds=("compliance", "radial"))


def tool_points(true: Model, q: Array) -> Array:
    """``(n, 3)`` the ``true`` robot's tool point (m) at joint values ``q`` ``(n, dof)``,
    its joints deflected under gravity when it states compliances (module docstring)."""
    q = np.atleast_2d(np.asarray(q, dtype=float))
    return true.fk(q, perturbations=_deflections(true, q))[:, :3, 3]


#: rounds of IK with the deflection taken off the target (each shrinks the error by the
#: deflection's change over the step: ~1e-3 of it for 5 mrad, below 1 nm after three)
_SEAT_ROUNDS = 4


def _reach(true: Model, targets: Array, rng: np.random.Generator) -> tuple[Array, NDArray[np.bool_]]:
    """Joint values whose (deflected) tool point is at ``targets``, and which reached them."""
    q0 = random_configurations(true, len(targets), rng=rng)
    res = solve_ik(true, targets, kind="position", q0=q0, restarts=3, seed=rng, tol=1e-9)
    q, ok = res.q, res.reachable
    if _deflections(true, q[:1]) is None:
        return q, ok
    for _ in range(_SEAT_ROUNDS):  # the rigid chain's target is the socket less the deflection
        bend = tool_points(true, q) - true.fk(q)[:, :3, 3]
        res = solve_ik(true, targets - bend, kind="position", q0=q, restarts=0, tol=1e-12)
        q, ok = res.q, ok & res.reachable
    return q, ok & (np.linalg.norm(tool_points(true, q) - targets, axis=1) < 1e-7)


def _workspace(true: Model, rng: np.random.Generator, count: int) -> Array:
    """``(count, 3)`` tool points of random configurations (reachable by construction)."""
    return tool_points(true, random_configurations(true, count, rng=rng))


def _points(true, n, n_points, sigma, rng, scene=None) -> tuple[ConstraintSet, SceneTruth]:
    centres = _workspace(true, rng, n_points) if scene is None else scene.points
    n_points = len(centres)
    label = np.arange(n) % n_points
    q, ok = _reach(true, centres[label] + sigma * rng.standard_normal((n, 3)), rng)
    data = ConstraintSet(q[ok], label[ok], -np.ones(ok.sum(), dtype=np.intp), sigma=sigma)
    return data, SceneTruth(centres, np.zeros((0, 4)), 0.0)


def _planes(true, n, n_planes, sigma, rng, scene=None) -> tuple[ConstraintSet, SceneTruth]:
    if scene is None:
        normals = rng.standard_normal((n_planes, 3))
        normals /= np.linalg.norm(normals, axis=1)[:, None]
        through = _workspace(true, rng, n_planes)
        planes = np.column_stack([normals, np.einsum("ij,ij->i", normals, through)])
    else:
        planes = scene.planes
        n_planes = len(planes)
    label = np.arange(n) % n_planes
    p = _workspace(true, rng, n)  # projected onto their plane: reachable near the workspace
    n_k = planes[label, :3]
    dist = np.einsum("ij,ij->i", p, n_k) - planes[label, 3]
    targets = p - dist[:, None] * n_k + sigma * rng.standard_normal((n, 3))
    q, ok = _reach(true, targets, rng)
    data = ConstraintSet(q[ok], -np.ones(ok.sum(), dtype=np.intp), label[ok], sigma=sigma)
    return data, SceneTruth(np.zeros((0, 3)), planes, 0.0)


def _distances(true, n, length, sigma, rng) -> tuple[ConstraintSet, SceneTruth]:
    m = n // 2
    qa = random_configurations(true, m, rng=rng)
    pa = tool_points(true, qa)
    u = rng.standard_normal((m, 3))
    u /= np.linalg.norm(u, axis=1)[:, None]
    # each tool point carries noise σ: their distance along u, √2 σ
    targets = pa + (length + np.sqrt(2) * sigma * rng.standard_normal(m))[:, None] * u
    qb, ok = _reach(true, targets, rng)
    q = np.concatenate([qa[ok], qb[ok]])
    k = int(ok.sum())
    pairs = np.column_stack([np.arange(k), k + np.arange(k)])
    none = -np.ones(2 * k, dtype=np.intp)
    data = ConstraintSet(q, none, none, pairs=pairs, pair_length=np.full(k, length), sigma=sigma)
    return data, SceneTruth(np.zeros((0, 3)), np.zeros((0, 4)), length)


def simulate_constraints(
    true: Model,
    kind: str,
    n: int,
    *,
    sigma: float = 1e-5,
    count: int = 2,
    length: float = 0.3,
    seed: int | np.random.Generator | None = 0,
    scene: SceneTruth | None = None,
) -> tuple[ConstraintSet, SceneTruth]:
    """Constraint data of ``kind`` recorded on the ``true`` robot (module docstring).

    Args:
        true: the real robot (its end is the tool point).
        kind: ``"point"``, ``"plane"``, ``"distance"`` or ``"tilt"`` (:func:`simulate_tilt_rows`
            with its defaults: every link's inclinometer, zero channel zeros).
        n: poses (distance: ``n // 2`` pairs; tilt: configurations); targets the robot
            cannot reach are left out.
        sigma: the tool point's noise (m); tilt: a reading's (rad).
        count: fixed points or planes.
        length: the distance pairs' length (m).
        seed: the random draw.
        scene: the points or planes to touch (e.g. :func:`moved_scene`); None: drawn.
    """
    if kind not in KINDS:
        raise ValueError(f"kind must be one of {', '.join(KINDS)}, got {kind!r}")
    if n < 2 or count < 1:
        raise ValueError("n must be >= 2 and count >= 1")
    rng = np.random.default_rng(seed)
    if kind == "point":
        return _points(true, n, count, sigma, rng, scene)
    if kind == "plane":
        return _planes(true, n, count, sigma, rng, scene)
    if kind == "tilt":
        data = simulate_tilt_rows(true, n, sigma=sigma, seed=rng)
        return data, SceneTruth(np.zeros((0, 3)), np.zeros((0, 4)), 0.0)
    return _distances(true, n, length, sigma, rng)


def simulate_tracker_rows(
    true: Model,
    n: int,
    *,
    sigma: float = 1e-5,
    T_device_base: Array | None = None,
    seed: int | np.random.Generator | None = 0,
    deflected: bool = False,
) -> ConstraintSet:
    """``n`` tracker rows to mix with constraint rows: random configurations of the
    ``true`` robot and its tool point in the device frame ``T_device_base`` (identity by
    default) with noise ``sigma`` (m per axis); its ``tracker_sigma`` is ``sigma``.
    ``deflected``: the tool point with the joints deflected under gravity by ``true``'s
    compliances (:func:`tool_points`, as the fixed-point, plane and distance rows are);
    False: the rigid chain (beside tilt rows, which carry the joint effects)."""
    rng = np.random.default_rng(seed)
    q = random_configurations(true, n, rng=rng)
    T = np.eye(4) if T_device_base is None else np.asarray(T_device_base, dtype=float)
    p = (
        (tool_points(true, q) if deflected else true.fk(q)[:, :3, 3]) @ T[:3, :3].T
        + T[:3, 3]
        + sigma * rng.standard_normal((n, 3))
    )
    none = -np.ones(n, dtype=np.intp)
    return ConstraintSet(q, none, none, position=p, sigma=sigma, tracker_sigma=sigma)


def moved_scene(scene: SceneTruth, seed: int | np.random.Generator | None = 0) -> SceneTruth:
    """The same sockets or plates placed elsewhere (a held-out placement): the whole scene
    turned about the base's z axis by 60-300° and lifted by up to ±50 mm, a rigid motion,
    so the distances between its points are kept.  Turning about the first joint's axis
    keeps the points within reach of an arm whose first joint is vertical and unlimited
    enough; a target out of reach is left out by :func:`simulate_constraints`."""
    rng = np.random.default_rng(seed)
    angle = rng.uniform(np.pi / 3, 5 * np.pi / 3)
    c, s = np.cos(angle), np.sin(angle)
    R = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    t = np.array([0.0, 0.0, rng.uniform(-0.05, 0.05)])
    points = scene.points @ R.T + t
    normals = scene.planes[:, :3] @ R.T
    planes = np.column_stack([normals, scene.planes[:, 3] + normals @ t]) if len(normals) else scene.planes
    return SceneTruth(points, planes, scene.length)


#: a sensor's range (rad): readings beyond it are not taken (Inclinometer.max_tilt's default)
MAX_TILT = float(np.radians(60.0))


def simulate_tilt_rows(
    true: Model,
    n: int,
    *,
    links: tuple[int, ...] | None = None,
    sigma: float = TILT_SIGMA,
    zeros: dict[tuple[int, int], float] | None = None,
    seed: int | np.random.Generator | None = 0,
    configurations: Array | None = None,
    mounts: dict[int, Array] | None = None,
    resolution: float = 0.0,
    frames: Model | None = None,
) -> ConstraintSet:
    """Inclinometer readings of the ``true`` robot (its geometry and ``joint_effects`` under
    gravity, :func:`robocal.measure.inclinometer.readings`) at ``n`` random configurations:
    both channels of a sensor on each link of ``links`` (joint indices, 0-based; None:
    every joint's link), plus each channel's zero ``zeros[(link, axis)]`` (rad, default 0)
    and normal noise ``sigma`` (rad).  Readings beyond :data:`MAX_TILT` (a sensor's range;
    near the vertical a reading is insensitive) are left out.  ``configurations``
    ``(n, dof)``: read at these (a plan) instead of random ones.  ``mounts``: each sensed
    link's sensor orientation on it (joint index -> ``(3,)`` angles, rad, as
    ``ConstraintSet.tilt_mount``; e.g. :func:`level_mounts`), None or a link not named: the
    joint frame.  ``resolution``: a reading is rounded to it (rad; 0: not rounded).
    ``frames``: the robot's own chain (its catalog chain when ``true`` is drawn around
    another chain of it, the complete model), whose joint frame origins the effects'
    bending moments are taken about, as the fit takes them
    (:func:`~robocal.measure.constraints.mounts.loads_about`; None: ``true``'s own)."""
    from robocal.measure.constraints.mounts import loads_about
    from robocal.measure.inclinometer import readings
    from robocal.model.joints import joint_perturbations

    rng = np.random.default_rng(seed)
    links = tuple(range(true.dof)) if links is None else tuple(links)
    q = (
        random_configurations(true, n, rng=rng)
        if configurations is None
        else np.asarray(configurations, float)
    )
    n = len(q)
    link = np.tile(np.repeat(np.array(links, dtype=np.intp), 2), n)
    axis = np.tile(np.array([0, 1] * len(links), dtype=np.intp), n)
    q_rows = np.repeat(q, 2 * len(links), axis=0)
    names = tuple(true.joint_names[k] for k in link)
    angles = np.array([(mounts or {}).get(int(k), np.zeros(3)) for k in link], dtype=float).reshape(-1, 3)
    matrices = Rotation.from_euler("xyz", angles).as_matrix() if len(angles) else np.zeros((0, 3, 3))
    axes = tuple("xy"[a] for a in axis)
    loads = loads_about(true, q_rows, frames)  # the effects as stated in the robot's own chain
    tilt = readings(true, q_rows, names, axes, matrices, joint_perturbations(true, q_rows, loads=loads))
    zero = np.array([(zeros or {}).get((int(k), int(a)), 0.0) for k, a in zip(link, axis, strict=True)])
    ok = np.abs(tilt) <= MAX_TILT
    read = tilt + zero + sigma * rng.standard_normal(len(tilt))
    if resolution > 0:  # the sensor's count (seed 003: 0.001°)
        read = np.round(read / resolution) * resolution
    none = -np.ones(int(ok.sum()), dtype=np.intp)
    return ConstraintSet(q_rows[ok], none, none, sigma=1e-5, tilt_link=link[ok], tilt_axis=axis[ok],
                         tilt=read[ok], tilt_sigma=sigma, tilt_mount=angles[ok])  # fmt: skip


def level_mounts(model: Model, links: tuple[int, ...] | None = None, q_home: Array | None = None
                 ) -> dict[int, Array]:  # fmt: skip
    """The mount (joint index -> ``(3,)`` angles, rad, as ``ConstraintSet.tilt_mount``) of a
    sensor on each of ``links`` (None: every joint's) mounted level at ``q_home`` (default all
    joints zero) of ``model``: its axes along the base's x and y there, as the thesis' sensors
    (:meth:`robocal.measure.inclinometer.Inclinometer.level_at`)."""
    links = tuple(range(model.dof)) if links is None else tuple(links)
    q = np.zeros((1, model.dof)) if q_home is None else np.asarray(q_home, float).reshape(1, -1)
    frames = model.joint_frames(q)[0]
    return {k: Rotation.from_matrix(frames[k, :3, :3].T).as_euler("xyz") for k in links}
