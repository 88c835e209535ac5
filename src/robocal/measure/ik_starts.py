"""Starting configurations of the IK (:mod:`robocal.measure.ik`): random configurations within the
joint limits and a fixed, cached pool of them with a k-d tree over their tool frames."""

from __future__ import annotations

import math
from functools import lru_cache
from typing import Protocol

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from robocal import choices
from robocal.model.chain import Model

Array = NDArray[np.float64]
TargetKind = choices.TargetKind  # the one table of choices (robocal.choices)


_POOL_SEED = 20240917  # the seed pool is fixed: results depend on `seed` only through random restarts
#: feature magnitude (m) beyond which a target's features are pulled in along their direction:
#: the pool's tool frames lie within a few metres, and a target at 1e200 m would give an
#: infinite squared distance, for which the k-d tree reports no neighbour at all
_FAR_FEATURE = 1e6


def _sampling_box(model: Model) -> Array:
    """``(dof, 2)`` box for random configurations: the joint limits, revolute joints
    clipped to [-π, π], prismatic joints without limits to [-1, 1] m."""
    box = model.joint_limits.copy()
    revolute = np.array([t == "revolute" for t in model.joint_types])
    wide = np.where(revolute, math.pi, 1.0)
    box[:, 0] = np.maximum(box[:, 0], -wide)
    box[:, 1] = np.minimum(box[:, 1], wide)
    # a limit range entirely outside [-π, π] keeps its own limits
    empty = box[:, 0] > box[:, 1]
    box[empty] = model.joint_limits[empty]
    return box


def random_configurations(model: Model, n: int, rng: np.random.Generator | int | None = 0) -> Array:
    """``(n, dof)`` configurations drawn uniformly within the joint limits (seeded).

    Revolute joints whose limits are wider than [-π, π] are drawn in [-π, π] (every
    orientation of the joint once); joints without limits in [-π, π] rad or [-1, 1] m.
    """
    rng = np.random.default_rng(rng)
    box = _sampling_box(model)
    return box[:, 0] + rng.random((int(n), model.dof)) * (box[:, 1] - box[:, 0])


def _features(T: Array, kind: TargetKind, w: float, k: int) -> Array:
    """Task-space feature vectors whose squared Euclidean distance is the squared
    position distance plus ``w²`` times a squared orientation distance
    (``3 − trace(R_aᵀ R_b) ≈ angle²`` for poses, ``2 (1 − a·b) ≈ angle²`` for an axis)."""
    p = T[:, :3, 3]
    if kind == "position":
        return p
    if kind == "pose":
        return np.concatenate([p, (w / math.sqrt(2.0)) * T[:, :3, :3].reshape(-1, 9)], axis=1)
    return np.concatenate([p, w * T[:, :3, k]], axis=1)


@lru_cache(maxsize=4)
def _seed_pool(model: Model, size: int) -> tuple[Array, Array]:
    """A fixed pool of ``size`` random configurations (seeded, cached per model) and
    their tool frames."""
    q = random_configurations(model, size, _POOL_SEED)
    return q, model.fk(q)


@lru_cache(maxsize=8)
def _seed_tree(model: Model, size: int, kind: TargetKind, w: float, k: int) -> cKDTree:
    return cKDTree(_features(_seed_pool(model, size)[1], kind, w, k))


class _Targets(Protocol):
    """What :func:`_nearest_pool` reads of the IK's problem (``robocal.measure.ik._Problem``)."""

    model: Model
    T: Array  # (n, 4, 4) target frames
    kind: TargetKind
    w: float  # orientation weight, m/rad
    k: int  # the tool axis of kind "axis"


def _within_reach(features: Array) -> Array:
    """``(n, m)`` features with every row whose largest entry exceeds :data:`_FAR_FEATURE`
    scaled down to it (same direction), so that squared distances stay finite."""
    largest = np.max(np.abs(features), axis=1, keepdims=True)
    return features * np.where(largest > _FAR_FEATURE, _FAR_FEATURE / np.maximum(largest, _FAR_FEATURE), 1.0)


def nearest_pool(problem: _Targets, size: int, idx: NDArray[np.intp], rank: int) -> Array:
    """For targets ``idx``: the pool configuration whose tool frame is the ``rank``-th
    nearest (0 = nearest) to the target's, ``(len(idx), dof)``."""
    tree = _seed_tree(problem.model, size, problem.kind, problem.w, problem.k)
    features = _within_reach(_features(problem.T[idx], problem.kind, problem.w, problem.k))
    _, nn = tree.query(features, k=rank + 1)
    nn = np.asarray(nn).reshape(len(idx), rank + 1)
    return _seed_pool(problem.model, size)[0][nn[:, rank]]
