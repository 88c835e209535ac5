"""The device interface every measuring device implements (:class:`Device`, :class:`Observations`)
and the checks they share; the devices and their noise figures: :mod:`robocal.measure.devices`."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Any, ClassVar, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from robocal import spatial

Array = NDArray[np.float64]


_POSITION_COLUMNS = ("x", "y", "z")


_POSE_COLUMNS = ("x", "y", "z", "qw", "qx", "qy", "qz")


@dataclass(frozen=True, eq=False)
class Observations:
    """What a device reports for ``n`` poses, in the device frame.

    Attributes:
        position: ``(n, 3)`` positions of the target (m).
        orientation: ``(n, 3, 3)`` rotations of the target frame, or None for
            position-only devices.
        sigma: ``(n, 3)`` 1-sigma of each position coordinate along the device axes (m).
    """

    position: Array
    orientation: Array | None
    sigma: Array


def look_at(eye: ArrayLike, target: ArrayLike, up: ArrayLike = (0.0, 0.0, 1.0)) -> Array:
    """Pose ``T_base_device`` ``(4, 4)`` of a device at ``eye`` (m, base frame) whose z axis
    points at ``target`` and whose y axis points away from ``up`` (camera convention:
    x right, y down, z along the line of sight)."""
    eye = np.asarray(eye, dtype=float)
    z = np.asarray(target, dtype=float) - eye
    if np.linalg.norm(z) == 0:
        raise ValueError("look_at: eye and target coincide")
    z /= np.linalg.norm(z)
    x = np.cross(z, np.asarray(up, dtype=float))
    if np.linalg.norm(x) < 1e-9:
        x = np.cross(z, [1.0, 0.0, 0.0])
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    return spatial.homogeneous(np.stack([x, y, z], axis=1), eye)


def _rigid(T: ArrayLike, what: str) -> Array:
    T = np.array(T, dtype=float)
    if T.shape != (4, 4) or not np.all(np.isfinite(T)):
        raise ValueError(f"{what} must be a finite (4, 4) transform, got shape {T.shape}")
    R = T[:3, :3]
    if not np.allclose(R @ R.T, np.eye(3), atol=1e-9) or np.linalg.det(R) < 0:
        raise ValueError(f"{what}: the rotation part is not a rotation matrix")
    if not np.allclose(T[3], [0, 0, 0, 1]):
        raise ValueError(f"{what}: the last row must be [0, 0, 0, 1]")
    T.setflags(write=False)
    return T


def vector(v: ArrayLike, shape: tuple[int, ...], what: str) -> Array:
    a = np.array(v, dtype=float)
    if a.shape != shape or not np.all(np.isfinite(a)):
        raise ValueError(f"{what} must be finite numbers shaped {shape}, got {a.shape}")
    a.setflags(write=False)
    return a


def nonneg(value: float, what: str) -> float:
    value = float(value)
    if not (math.isfinite(value) and value >= 0):
        raise ValueError(f"{what} must be finite and >= 0, got {value!r}")
    return value


def _poses(T_base_tool: ArrayLike) -> Array:
    T = np.asarray(T_base_tool, dtype=float)
    if T.ndim == 2:
        T = T[None]
    if T.ndim != 3 or T.shape[1:] != (4, 4):
        raise ValueError(f"T_base_tool shaped {T.shape}; expected (n, 4, 4)")
    return T


def pose_list(idx: NDArray[np.intp], limit: int = 8) -> str:
    shown = ", ".join(str(int(i)) for i in idx[:limit])
    return shown + (f" ... ({len(idx)} poses)" if len(idx) > limit else "")


# The default placement of a device: a tracker for an arm of about 1 m reach at the base origin.
TRACKER_POSE = spatial.compose(spatial.transl(2.5, 0.8, 0.3), spatial.homogeneous(spatial.rotz(np.pi - 0.3)))


@dataclass(frozen=True, eq=False)
class Device:
    """Base of all devices (see the module docstring for the common attributes)."""

    kind: ClassVar[str] = ""
    measures: ClassVar[Literal["position", "pose"]] = "position"

    T_device_base: Array = field(default_factory=lambda: spatial.inverse(TRACKER_POSE))
    p_tool_target: Array = field(default_factory=lambda: np.zeros(3))

    def __post_init__(self) -> None:
        object.__setattr__(self, "T_device_base", _rigid(self.T_device_base, f"{self.kind}: T_device_base"))
        object.__setattr__(
            self, "p_tool_target", vector(self.p_tool_target, (3,), f"{self.kind}: p_tool_target")
        )

    @property
    def columns(self) -> tuple[str, ...]:
        """Observation columns of a measurement file: ``x y z`` (+ ``qw qx qy qz`` for poses)."""
        return _POSE_COLUMNS if self.measures == "pose" else _POSITION_COLUMNS

    @property
    def T_base_device(self) -> Array:
        """The device's pose in the robot base frame, ``(4, 4)``."""
        return spatial.inverse(self.T_device_base)

    def target_frames(self, T_base_tool: ArrayLike) -> Array:
        """``T_device_target`` ``(n, 4, 4)`` for tool frames ``T_base_tool`` ``(n, 4, 4)``."""
        T = _poses(T_base_tool)
        T_tool_target = spatial.transl(*self.p_tool_target)
        return self.T_device_base @ T @ T_tool_target

    def predict(self, T_base_tool: ArrayLike) -> Observations:
        """Noise-free observation of tool frames ``T_base_tool`` ``(n, 4, 4)``."""
        F = self.target_frames(T_base_tool)
        self._check(F)
        n = len(F)
        return Observations(
            F[:, :3, 3].copy(),
            F[:, :3, :3].copy() if self.measures == "pose" else None,
            np.broadcast_to(self._sigma(F), (n, 3)).copy(),
        )

    def observe(self, T_base_tool: ArrayLike, rng: np.random.Generator | int | None = None) -> Observations:
        """Observation with noise of tool frames ``T_base_tool`` ``(n, 4, 4)``.

        ``rng`` is a numpy Generator or a seed; the same seed gives the same output.
        """
        rng = np.random.default_rng(rng)
        F = self.target_frames(T_base_tool)
        self._check(F)
        return self._observe(F, rng)

    # -- to be specialised
    def _check(self, F: Array) -> None:
        """Raise ValueError for poses the device cannot observe."""

    def _sigma(self, F: Array) -> Array:
        raise NotImplementedError

    def _observe(self, F: Array, rng: np.random.Generator) -> Observations:
        raise NotImplementedError

    def with_noise(self, sigma: float) -> Device:
        raise NotImplementedError

    # -- files
    def to_dict(self) -> dict[str, Any]:
        """Plain data (SI units, lists) for YAML; :func:`device_from_dict` reverses it."""
        out: dict[str, Any] = {"type": self.kind}
        for f in dataclasses.fields(self):
            v = getattr(self, f.name)
            if isinstance(v, np.ndarray):
                v = v.tolist()
            elif isinstance(v, tuple):
                v = [float(x) for x in v]
            elif isinstance(v, float | int) and not isinstance(v, bool):
                v = float(v)
            out[f.name] = v
        return out
