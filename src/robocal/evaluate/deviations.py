"""Deviations of attained from commanded poses: poses split into positions and rotations,
wrapped angle differences (the conventions: :mod:`robocal.evaluate.metrics`)."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from robocal import spatial

Array = NDArray[np.float64]


ISO_ANGLES = "xyz"  # a, b, c: extrinsic rotations about the base x, y, z axes


def wrap(angle: ArrayLike) -> Array:
    """Angles wrapped to (−π, π]."""
    a = np.asarray(angle, dtype=float)
    return np.pi - np.mod(np.pi - a, 2 * np.pi)


def split_poses(poses: ArrayLike, what: str) -> tuple[Array, Array | None]:
    """Positions ``(..., 3)`` and rotations ``(..., 3, 3)`` (or None) of positions
    ``(..., 3)`` or frames ``(..., 4, 4)``."""
    a = np.asarray(poses, dtype=float)
    if a.shape[-2:] == (4, 4):
        return a[..., :3, 3], a[..., :3, :3]
    if a.shape[-1:] == (3,):
        return a, None
    raise ValueError(f"{what} must be positions (..., 3) or frames (..., 4, 4) in m, got shape {a.shape}")


def angle_deltas(R: Array, R_c: Array, seq: str) -> Array:
    """Euler angles of ``R`` minus those of ``R_c``, wrapped, ``(..., 3)`` rad."""
    return wrap(spatial.matrix_to_euler(R, seq) - spatial.matrix_to_euler(R_c, seq))
