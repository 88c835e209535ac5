"""Devices the tool touches: the calibration plate (seed 001) and a pen on paper (seed 003
§5.5.2); their noise figures: :mod:`robocal.measure.devices`."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Any, ClassVar, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from robocal import spatial
from robocal.measure.device_base import Device, Observations, nonneg, pose_list

Array = NDArray[np.float64]


def plate_points(
    n_circle: int = 24,
    radius: float = 0.10,
    n_line: int = 9,
    line_length: float = 0.24,
    line_offset: float = -0.15,
) -> Array:
    """Known points of a calibration plate, ``(n_circle + n_line, 3)`` (m) in the plate frame.

    Seed 001: 33 calibration points (cavities) forming a circular path and a straight
    path on the board.  Here ``n_circle`` points evenly spaced on a circle of ``radius``
    about the plate origin (first point on +x, counter-clockwise), then ``n_line``
    points evenly spaced on a segment of ``line_length`` parallel to x at
    ``y = line_offset``; all at z = 0 (the board's surface is the plate's xy plane).
    The defaults (24 + 9 = 33) are assumed: the seed shows the layout only in a photograph.
    """
    if n_circle < 0 or n_line < 0 or n_circle + n_line == 0:
        raise ValueError("plate_points needs at least one point")
    a = 2 * np.pi * np.arange(n_circle) / max(n_circle, 1)
    circle = np.stack([radius * np.cos(a), radius * np.sin(a), np.zeros(n_circle)], axis=1)
    x = np.linspace(-line_length / 2, line_length / 2, n_line) if n_line > 1 else np.zeros(n_line)
    line = np.stack([x, np.full(n_line, line_offset), np.zeros(n_line)], axis=1)
    return np.concatenate([circle, line])


# extrinsic xyz Euler angles (11.7°, 11.8°, 0°) = Ry(11.8°) Rx(11.7°), written without scipy's
# Rotation so that importing this module stays light (the `robocal` command's start-up)
_PLATE_POSE = spatial.homogeneous(
    spatial.roty(np.radians(11.8)) @ spatial.rotx(np.radians(11.7)), [0.45, 0.0, 0.0]
)


_PAPER_POSE = spatial.homogeneous(spatial.roty(np.pi / 4), [0.4, 0.0, 0.3])


@dataclass(frozen=True, eq=False)
class CalibrationPlate(Device):
    """Calibration plate/table (seed 001): the tool tip touches known points on a board.

    The observation is the touched point's coordinates in the plate frame (the board's
    surface is its xy plane): the tip position (target ``p_tool_target``) in the plate
    frame plus the touching error, normal with 1-sigma ``sigma`` per axis.  Poses must be
    planned to touch ``points`` (e.g. by inverse kinematics); a tip farther than
    ``capture_radius`` (m) from every point raises ValueError (None: no check).
    ``T_device_base`` is the inverse of the plate's pose on the robot base; see
    :meth:`tilted`.
    """

    kind: ClassVar[str] = "plate"
    measures: ClassVar[Literal["position", "pose"]] = "position"

    T_device_base: Array = field(default_factory=lambda: spatial.inverse(_PLATE_POSE))
    p_tool_target: Array = field(default_factory=lambda: np.zeros(3))
    points: Array = field(default_factory=plate_points)
    sigma: float = 0.28e-3
    capture_radius: float | None = 5e-3

    def __post_init__(self) -> None:
        super().__post_init__()
        pts = np.array(self.points, dtype=float)
        if pts.ndim != 2 or pts.shape[1] != 3 or len(pts) == 0 or not np.all(np.isfinite(pts)):
            raise ValueError(f"plate: points must be (k, 3) finite positions (m), got {pts.shape}")
        pts.setflags(write=False)
        object.__setattr__(self, "points", pts)
        object.__setattr__(self, "sigma", nonneg(self.sigma, "plate: sigma"))
        if self.capture_radius is not None:
            object.__setattr__(self, "capture_radius", nonneg(self.capture_radius, "plate: capture_radius"))

    @classmethod
    def tilted(
        cls,
        center: ArrayLike = (0.45, 0.0, 0.0),
        roll: float = math.radians(11.7),
        pitch: float = math.radians(11.8),
        yaw: float = 0.0,
        **kwargs: Any,
    ) -> CalibrationPlate:
        """A plate centred at ``center`` (m, base frame), tilted by ``roll`` about x and
        ``pitch`` about y (rad; extrinsic, R = Rz(yaw) Ry(pitch) Rx(roll)).  Defaults: the
        11.7° roll and 11.8° pitch of seed 001."""
        T_base_plate = spatial.homogeneous(spatial.euler_to_matrix([roll, pitch, yaw], "xyz"), center)
        return cls(T_device_base=spatial.inverse(T_base_plate), **kwargs)

    @property
    def points_base(self) -> Array:
        """The known points ``(k, 3)`` in the robot base frame (m), e.g. as IK targets."""
        T = self.T_base_device
        return self.points @ T[:3, :3].T + T[:3, 3]

    def nearest(self, p_plate: ArrayLike) -> tuple[NDArray[np.intp], Array]:
        """Index of the nearest known point and its distance (m) for positions ``(n, 3)``
        in the plate frame."""
        p = np.atleast_2d(np.asarray(p_plate, dtype=float))
        d = np.linalg.norm(p[:, None, :] - self.points[None], axis=2)
        k = np.argmin(d, axis=1)
        return k, d[np.arange(len(p)), k]

    def _check(self, F: Array) -> None:
        if self.capture_radius is None:
            return
        _, d = self.nearest(F[:, :3, 3])
        bad = np.flatnonzero(d > self.capture_radius)
        if bad.size:
            raise ValueError(
                f"plate: the tool tip is {d[bad[0]] * 1000:.1f} mm from the nearest plate point at pose(s) "
                f"{pose_list(bad)} (capture radius {self.capture_radius * 1000:g} mm): plan the poses to "
                "touch the plate's points (CalibrationPlate.points_base)"
            )

    def _sigma(self, F: Array) -> Array:
        return np.full((len(F), 3), self.sigma)

    def _observe(self, F: Array, rng: np.random.Generator) -> Observations:
        p = F[:, :3, 3] + self.sigma * rng.standard_normal((len(F), 3))
        return Observations(p, None, self._sigma(F))

    def with_noise(self, sigma: float) -> CalibrationPlate:
        """Touching error ``sigma`` (m) per axis."""
        return dataclasses.replace(self, sigma=sigma)


@dataclass(frozen=True, eq=False)
class PenOnPaper(Device):
    """Low-cost set-up of seed 003 §5.5.2: a pencil on a spring-loaded potentiometer.

    The device frame is the paper's: x, y in the sheet, z its normal.  The in-plane
    position (x, y) of the pen tip is read from the trace on the paper with 1-sigma
    ``sigma_xy``; the out-of-plane position z from the potentiometer with ``sigma_z``
    (the pen is assumed to be held along the paper normal).  A tip off the sheet
    (``|x| > size[0]/2`` or ``|y| > size[1]/2``) or beyond the spring's ``travel`` (m)
    from the paper raises ValueError.  Defaults: module docstring.
    """

    kind: ClassVar[str] = "pen"
    measures: ClassVar[Literal["position", "pose"]] = "position"

    T_device_base: Array = field(default_factory=lambda: spatial.inverse(_PAPER_POSE))
    p_tool_target: Array = field(default_factory=lambda: np.zeros(3))
    sigma_xy: float = 0.1e-3
    sigma_z: float = 0.01e-3
    travel: float | None = 0.01
    size: tuple[float, float] | None = (0.297, 0.210)

    def __post_init__(self) -> None:
        super().__post_init__()
        object.__setattr__(self, "sigma_xy", nonneg(self.sigma_xy, "pen: sigma_xy"))
        object.__setattr__(self, "sigma_z", nonneg(self.sigma_z, "pen: sigma_z"))
        if self.travel is not None:
            object.__setattr__(self, "travel", nonneg(self.travel, "pen: travel"))
        if self.size is not None:
            w, h = (nonneg(v, "pen: size") for v in self.size)
            object.__setattr__(self, "size", (w, h))

    @staticmethod
    def circle_points(radius: float = 0.05, n: int = 4) -> Array:
        """``n`` points ``(n, 3)`` (m) evenly spaced on a circle about the paper origin
        (seed 003 §5.5.2: four points a quarter apart on a printed circle; the radius is
        not given, 50 mm assumed)."""
        a = 2 * np.pi * np.arange(n) / n
        return np.stack([radius * np.cos(a), radius * np.sin(a), np.zeros(n)], axis=1)

    def _check(self, F: Array) -> None:
        p = F[:, :3, 3]
        if self.size is not None:
            off = np.flatnonzero((np.abs(p[:, 0]) > self.size[0] / 2) | (np.abs(p[:, 1]) > self.size[1] / 2))
            if off.size:
                raise ValueError(
                    f"pen: the pen tip is off the {self.size[0] * 1000:g} x {self.size[1] * 1000:g} mm "
                    f"sheet at pose(s) {pose_list(off)}"
                )
        if self.travel is not None:
            far = np.flatnonzero(np.abs(p[:, 2]) > self.travel)
            if far.size:
                raise ValueError(
                    f"pen: the pen tip is {p[far[0], 2] * 1000:.1f} mm from the paper at pose(s) "
                    f"{pose_list(far)}, beyond the potentiometer's ±{self.travel * 1000:g} mm travel"
                )

    def _sigma(self, F: Array) -> Array:
        return np.tile([self.sigma_xy, self.sigma_xy, self.sigma_z], (len(F), 1))

    def _observe(self, F: Array, rng: np.random.Generator) -> Observations:
        s = self._sigma(F)
        p = F[:, :3, 3] + s * rng.standard_normal((len(F), 3))
        return Observations(p, None, s)

    def with_noise(self, sigma: float) -> PenOnPaper:
        """In-plane noise ``sigma`` (m); the potentiometer's keeps the default 10:1 ratio."""
        return dataclasses.replace(self, sigma_xy=sigma, sigma_z=sigma / 10.0)
