"""Pose planning for inclinometer readings (seed 003's joint tilting set-up): which
configurations to read so that clearance, backlash, compliance, the channels' zeros and
the angles of the geometry that turn the sensed links are best determined.

The candidates are random configurations within the joint limits whose every channel
reads within its sensor's range (a configuration beyond it cannot be read).  A candidate's
rows are the readings of every channel there: the tilt Jacobian
(:func:`robocal.identify.tilt_identification.tilt_jacobian`, at the nominal values:
effects zero, the nominal geometry) weighted by each reading's 1/σ, over the parameters
the whole pool can see (:func:`robocal.identify.tilt_identification.visible`).  Columns
of different units (rad, rad/(N·m)) are scaled to unit RMS over the pool, so that the
indices weigh every parameter alike.  The choice is the greedy construction of
:func:`robocal.identify.constraints.poses.greedy_blocks` maximising O1..O5.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from robocal.identify.constraints.poses import greedy_blocks
from robocal.identify.observability_indices import INDICES, ObservabilityIndices
from robocal.identify.tilt_identification import (
    KINDS,
    orientation_parameters,
    parameter_names,
    tilt_jacobian,
    visible,
)
from robocal.measure.inclinometer import Inclinometer, TiltReadings, channel_rows, readings

__all__ = ["TiltPoseSelection", "select_tilt_poses", "tilt_candidates"]

Array = NDArray[np.float64]


@dataclass(frozen=True)
class TiltPoseSelection:
    """Chosen configurations and their observability.

    Attributes:
        q: ``(n, dof)`` the configurations to read (rad), in the order chosen.
        index: the index maximised; value: its value; indices: O1..O5 of the choice.
        baseline: O1..O5 of as many candidates taken in pool order (a random choice).
        params: the parameters the indices are over (those the pool can see).
        not_seen: the parameters no candidate can see, and why.
    """

    q: Array
    index: str
    value: float
    indices: ObservabilityIndices
    baseline: ObservabilityIndices
    params: tuple[str, ...]
    not_seen: dict[str, str]


def tilt_candidates(model, q: Array, sensors: Sequence[Inclinometer]) -> NDArray[np.bool_]:
    """``(n,)`` whether every channel of ``sensors`` reads within its range at ``q`` ``(n, dof)``
    on the nominal ``model``."""
    q = np.atleast_2d(np.asarray(q, dtype=float))
    q_rows, link, axis, mounts = channel_rows(model, q, tuple(sensors))
    tilt = readings(model, q_rows, link, axis, mounts)
    limit = {s.link: s.max_tilt for s in sensors}
    inside = np.abs(tilt) <= np.array([limit[name] for name in link])
    return np.asarray(inside.reshape(len(q), -1).all(axis=1), dtype=bool)


def select_tilt_poses(
    model,
    pool: Array,
    n: int,
    sensors: Sequence[Inclinometer],
    *,
    index: str = "O1",
    kinds: Sequence[str] = KINDS,
    geometry: bool = True,
    shortlist: int = 16,
) -> TiltPoseSelection:
    """Choose ``n`` configurations of ``pool`` ``(N, dof)`` (rad) for ``sensors`` on the
    nominal ``model`` (its mass properties give the loads) maximising ``index``.

    Raises:
        ValueError: an unknown index, ``n`` outside 1..the readable candidates, or no
            parameter the readings can see.
    """
    if index not in INDICES:
        raise ValueError(f"index must be one of {', '.join(INDICES)}, got {index!r}")
    sensors = tuple(sensors)
    pool = np.atleast_2d(np.asarray(pool, dtype=float))
    pool = pool[tilt_candidates(model, pool, sensors)]
    if not 1 <= n <= len(pool):
        raise ValueError(f"cannot choose {n} of {len(pool)} candidates that every sensor can read")
    q_rows, link, axis, _ = channel_rows(model, pool, sensors)
    sigma = np.array([{s.link: s.sigma_reading for s in sensors}[name] for name in link])
    data = TiltReadings(q_rows, link, axis, np.zeros(len(q_rows)), np.maximum(sigma, 1e-12))
    geometry_names = orientation_parameters(model, data.link) if geometry else ()
    names = parameter_names(model, data, kinds, None, geometry_names)
    J = tilt_jacobian(model, data, sensors, names, np.zeros(len(names))) / data.sigma[:, None]
    keep, not_seen = visible(J, names)
    if not keep:
        raise ValueError("the readings see no parameter at these configurations")
    J = J[:, keep]
    J = J / np.sqrt(np.mean(J * J, axis=0))  # unit RMS per column over the pool
    width = len(q_rows) // len(pool)  # the channels: rows per configuration
    blocks = [J[k * width : (k + 1) * width] for k in range(len(pool))]
    chosen, indices, baseline = greedy_blocks(blocks, n, index, shortlist)
    params = tuple(names[i] for i in keep)
    return TiltPoseSelection(pool[chosen], index, float(indices[index]), indices, baseline, params, not_seen)
