"""Measuring devices: what each observes of the tool, in its own frame, with its noise.

Every device is an immutable dataclass with

* ``T_device_base`` ``(4, 4)``: the robot base frame expressed in the device frame,
  i.e. ``p_device = T_device_base @ p_base``.  In a real calibration it is unknown and
  identified with the robot (except for a plate or paper whose placement is part of the
  set-up); in a simulation it is part of the truth.
* ``p_tool_target`` ``(3,)`` (m): the observed point in the tool frame (the reflector,
  the marker centre, the probe or pen tip).  The *target frame* is the tool frame moved
  to that point, ``T_base_target = T_base_tool @ transl(p_tool_target)``.
* ``measures``: ``"position"`` (columns ``x y z``) or ``"pose"`` (``x y z`` and the
  orientation, written as ``qw qx qy qz``); ``columns`` lists them.
* ``predict(T_base_tool)``: the noise-free observation; ``observe(T_base_tool, rng)``:
  the observation with the device's noise, as :class:`Observations` (positions in m
  and rotations in the device frame, and the per-row 1-sigma of the position along the
  device axes).
* ``with_noise(sigma)``: the same device with its main noise figure set to ``sigma``
  (m); ``to_dict()`` / :func:`device_from_dict` for truth files.

Noise figures and where they come from
--------------------------------------
* :class:`LaserTracker`: 20 µm (1-sigma per axis) — seed 003 §3.3: "the volumetric
  accuracy of laser tracker is 20 microns within 10 meters" (FARO); the same section
  reports that the beam was obstructed when the tool turned more than 45° from the
  line of sight (``acceptance_angle``).  Distance-dependent noise ``sigma + sigma_per_m ·
  distance`` models Leica-style specifications U = a + b·L (e.g. AT960 MPE
  15 µm + 6 µm/m, a datasheet figure, not from the seeds).
* :class:`OpticalCMM`: 0.01 mm per marker coordinate and a working range of 2-7 m —
  seed 003 §3.3: the NDI Optotrak's "volumetric resolution ... is 0.01 mm within 2 to 7
  meters and cannot measure in 0 to 2 meters"; three LEDs on the end effector, the
  tool centre point taken as the centroid of the three, their coordinates "used to
  calculate the position as well as the orientation" (here: a Kabsch fit,
  :func:`robocal.spatial.fit_rigid_transform`).
* :class:`Camera`: 0.28 mm across the line of sight — seed 001 "Accuracy measurement":
  the Vicon T-20S motion capture system "has a standard deviation of ±0.28 mm";
  three times that along the line of sight (an assumption: depth from a camera pair at
  distance D with baseline B is worse by about D/B ≈ 3).
* :class:`CalibrationPlate`: 33 known points, a circle and a straight line, on a board
  tilted 11.7° in roll and 11.8° in pitch — seed 001 "Calibration table" and "Obtaining
  experiment data"; the cavity positions were captured with the Vicon system, so the
  touching error defaults to its 0.28 mm.  The seed gives no dimensions of the layout
  (only its photograph); :func:`plate_points` uses 24 points on a 100 mm radius circle
  and 9 on a 240 mm line (assumed).
* :class:`PenOnPaper`: seed 003 §5.5.2 (low-cost set-up: pencil on a spring-loaded
  potentiometer tracing on paper, printed circle on a plane at 45°) gives no
  resolution; the defaults, 0.1 mm in the paper plane and 0.01 mm out of it, are the
  grid and height-sensor resolutions of Ha (2008), the set-up the seed cites for it
  (seed 003 §2.2, literature review).  The spring travel (±10 mm) and the paper size
  (A4) are assumptions.  The thesis' procedure (the trace and the potentiometer along a
  path, pen lift, what it cannot give) is :mod:`robocal.measure.pen_trace`.

The interface lives in :mod:`robocal.measure.device_base`, the plate and the pen in
:mod:`robocal.measure.plates`; this module re-exports them, and the
:class:`~robocal.measure.inclinometer.Inclinometer` (seed 003: a link's tilt angles, not a
tool position, so not among :data:`DEVICES`; ``robocal simulate --device inclinometer``).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, ClassVar, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from robocal import spatial
from robocal.measure.device_base import (
    TRACKER_POSE,
    Device,
    Observations,
    look_at,
    nonneg,
    pose_list,
    vector,
)
from robocal.measure.inclinometer import Inclinometer
from robocal.measure.plates import CalibrationPlate, PenOnPaper, plate_points

__all__ = [
    "DEVICES",
    "CalibrationPlate",
    "Camera",
    "Device",
    "Inclinometer",
    "LaserTracker",
    "Observations",
    "OpticalCMM",
    "PenOnPaper",
    "device_from_dict",
    "look_at",
    "make_device",
    "marker_triangle",
    "plate_points",
]

Array = NDArray[np.float64]


def marker_triangle(radius: float = 0.05) -> Array:
    """Three markers ``(3, 3)`` (m) on an equilateral triangle of circumradius ``radius``
    in the target frame's xy plane, centred on its origin (seed 003 §3.3: the tool centre
    point is the centroid of the three LEDs)."""
    a = np.radians([90.0, 210.0, 330.0])
    return np.stack([radius * np.cos(a), radius * np.sin(a), np.zeros(3)], axis=1)


# Default placements, for an arm of about 1 m reach standing at the base origin.
_CMM_POSE = look_at([4.0, 0.5, 1.2], [0.0, 0.0, 0.5])
_CAMERA_POSE = look_at([2.0, -0.5, 1.5], [0.0, 0.0, 0.5])


@dataclass(frozen=True, eq=False)
class LaserTracker(Device):
    """Laser tracker: position of a retro-reflector (SMR, T-Mac) at ``p_tool_target``.

    Noise: independent normal errors on each device axis with 1-sigma
    ``sigma + sigma_per_m · d``, ``d`` the tracker-to-target distance (m).
    Default 20 µm, seed 003 §3.3.  If ``acceptance_angle`` (rad) is set, a pose whose
    reflector axis (``target_axis``, in the tool frame) points more than that away
    from the tracker cannot be measured (seed 003 §3.3: 45°) and raises ValueError.
    """

    kind: ClassVar[str] = "laser-tracker"
    measures: ClassVar[Literal["position", "pose"]] = "position"

    T_device_base: Array = field(default_factory=lambda: spatial.inverse(TRACKER_POSE))
    p_tool_target: Array = field(default_factory=lambda: np.zeros(3))
    sigma: float = 20e-6
    sigma_per_m: float = 0.0
    acceptance_angle: float | None = None
    target_axis: Array = field(default_factory=lambda: np.array([0.0, 0.0, 1.0]))

    def __post_init__(self) -> None:
        super().__post_init__()
        object.__setattr__(self, "sigma", nonneg(self.sigma, "laser-tracker: sigma"))
        object.__setattr__(self, "sigma_per_m", nonneg(self.sigma_per_m, "laser-tracker: sigma_per_m"))
        if self.acceptance_angle is not None:
            object.__setattr__(
                self, "acceptance_angle", nonneg(self.acceptance_angle, "laser-tracker: acceptance_angle")
            )
        axis = vector(self.target_axis, (3,), "laser-tracker: target_axis")
        if np.linalg.norm(axis) == 0:
            raise ValueError("laser-tracker: target_axis must not be zero")
        axis = axis / np.linalg.norm(axis)
        axis.setflags(write=False)
        object.__setattr__(self, "target_axis", axis)

    def _check(self, F: Array) -> None:
        if self.acceptance_angle is None:
            return
        p = F[:, :3, 3]
        to_tracker = -p / np.linalg.norm(p, axis=1, keepdims=True)
        facing = F[:, :3, :3] @ self.target_axis
        angle = np.arccos(np.clip(np.einsum("ni,ni->n", facing, to_tracker), -1.0, 1.0))
        bad = np.flatnonzero(angle > self.acceptance_angle)
        if bad.size:
            raise ValueError(
                f"laser-tracker: the reflector turns {np.degrees(angle[bad[0]]):.1f} deg away from the "
                f"line of sight (acceptance {np.degrees(self.acceptance_angle):.1f} deg) at pose(s) "
                f"{pose_list(bad)}: the beam is lost"
            )

    def _sigma(self, F: Array) -> Array:
        d = np.linalg.norm(F[:, :3, 3], axis=1)
        return np.repeat((self.sigma + self.sigma_per_m * d)[:, None], 3, axis=1)

    def _observe(self, F: Array, rng: np.random.Generator) -> Observations:
        s = self._sigma(F)
        p = F[:, :3, 3] + s * rng.standard_normal((len(F), 3))
        return Observations(p, None, s)

    def with_noise(self, sigma: float) -> LaserTracker:
        """Isotropic noise ``sigma`` (m), no distance-dependent part."""
        return dataclasses.replace(self, sigma=sigma, sigma_per_m=0.0)


def _fit_markers(markers: Array, measured: Array) -> tuple[Array, Array]:
    T = spatial.fit_rigid_transform(markers, measured)
    return T[:, :3, 3], T[:, :3, :3]


@dataclass(frozen=True, eq=False)
class OpticalCMM(Device):
    """Optical CMM (NDI Optotrak-like): full pose from three (or more) markers on the tool.

    Each marker (``markers``, ``(m, 3)`` in the target frame) is measured with
    independent normal noise ``sigma`` per coordinate; the reported pose of the target
    frame is the least-squares rigid fit of the layout to the measured markers (Kabsch).
    With the default layout centred on the target (seed 003 §3.3: TCP = centroid of the
    three LEDs) the position's 1-sigma is ``sigma / sqrt(m)`` per axis.  Markers outside
    ``working_range`` (m, distance from the device) raise ValueError (Optotrak: 2-7 m).
    """

    kind: ClassVar[str] = "optical-cmm"
    measures: ClassVar[Literal["position", "pose"]] = "pose"

    T_device_base: Array = field(default_factory=lambda: spatial.inverse(_CMM_POSE))
    p_tool_target: Array = field(default_factory=lambda: np.zeros(3))
    markers: Array = field(default_factory=marker_triangle)
    sigma: float = 0.01e-3
    working_range: tuple[float, float] | None = (2.0, 7.0)

    def __post_init__(self) -> None:
        super().__post_init__()
        _check_markers(self)
        object.__setattr__(self, "sigma", nonneg(self.sigma, f"{self.kind}: sigma"))
        if self.working_range is not None:
            lo, hi = (float(v) for v in self.working_range)
            if not 0 <= lo < hi:
                raise ValueError(f"{self.kind}: working_range {self.working_range} needs 0 <= near < far")
            object.__setattr__(self, "working_range", (lo, hi))

    def marker_positions(self, T_base_tool: ArrayLike) -> Array:
        """Noise-free marker positions ``(n, m, 3)`` in the device frame."""
        return self._marker_positions(self.target_frames(T_base_tool))

    def _marker_positions(self, F: Array) -> Array:
        return np.einsum("nij,mj->nmi", F[:, :3, :3], self.markers) + F[:, None, :3, 3]

    def _check(self, F: Array) -> None:
        if self.working_range is None:
            return
        d = np.linalg.norm(self._marker_positions(F), axis=2)
        lo, hi = self.working_range
        bad = np.flatnonzero(np.any((d < lo) | (d > hi), axis=1))
        if bad.size:
            i = bad[0]
            raise ValueError(
                f"{self.kind}: markers at {d[i].min():.3f}-{d[i].max():.3f} m from the device at pose(s) "
                f"{pose_list(bad)}, outside the working range {lo:g}-{hi:g} m; move the device "
                "(T_device_base)"
            )

    def _sigma(self, F: Array) -> Array:
        return np.full((len(F), 3), self.sigma / math.sqrt(len(self.markers)))

    def _observe(self, F: Array, rng: np.random.Generator) -> Observations:
        M = self._marker_positions(F)
        M = M + self.sigma * rng.standard_normal(M.shape)
        p, R = _fit_markers(self.markers, M)
        return Observations(p, R, self._sigma(F))

    def with_noise(self, sigma: float) -> OpticalCMM:
        """Marker noise ``sigma`` (m) per coordinate."""
        return dataclasses.replace(self, sigma=sigma)


def _check_markers(dev: OpticalCMM | Camera) -> None:
    M = np.array(dev.markers, dtype=float)
    if M.ndim != 2 or M.shape[1] != 3 or M.shape[0] < 3 or not np.all(np.isfinite(M)):
        raise ValueError(f"{dev.kind}: markers must be (m >= 3, 3) finite positions (m), got {M.shape}")
    s = np.linalg.svd(M - M.mean(axis=0), compute_uv=False)
    if s[1] <= 1e-9 * max(s[0], 1e-300):
        raise ValueError(f"{dev.kind}: the markers are collinear; their pose cannot be measured")
    M.setflags(write=False)
    object.__setattr__(dev, "markers", M)


@dataclass(frozen=True, eq=False)
class Camera(OpticalCMM):
    """Camera tracking markers: full pose with noise larger along the line of sight.

    Each marker's error is normal with covariance
    ``sigma_lateral² (I − u uᵀ) + (depth_ratio · sigma_lateral)² u uᵀ``, ``u`` the unit
    ray from the camera (device origin) to the marker; the pose is fitted as for
    :class:`OpticalCMM`.  The reported position 1-sigma per device axis is that of the
    marker centroid.  The camera looks along its +z axis: markers behind it, or outside
    ``half_fov`` (rad) when set, raise ValueError.  Defaults: seed 001 (Vicon, 0.28 mm).
    """

    kind: ClassVar[str] = "camera"
    measures: ClassVar[Literal["position", "pose"]] = "pose"

    T_device_base: Array = field(default_factory=lambda: spatial.inverse(_CAMERA_POSE))
    p_tool_target: Array = field(default_factory=lambda: np.zeros(3))
    markers: Array = field(default_factory=marker_triangle)
    sigma: float = 0.28e-3
    working_range: tuple[float, float] | None = None
    depth_ratio: float = 3.0
    half_fov: float | None = None

    def __post_init__(self) -> None:
        super().__post_init__()
        object.__setattr__(self, "depth_ratio", nonneg(self.depth_ratio, "camera: depth_ratio"))
        if self.half_fov is not None:
            object.__setattr__(self, "half_fov", nonneg(self.half_fov, "camera: half_fov"))

    @property
    def sigma_lateral(self) -> float:
        """1-sigma across the line of sight (m) (= ``sigma``)."""
        return self.sigma

    @property
    def sigma_depth(self) -> float:
        """1-sigma along the line of sight (m)."""
        return self.sigma * self.depth_ratio

    def _check(self, F: Array) -> None:
        super()._check(F)
        M = self._marker_positions(F)
        ang = np.arctan2(np.linalg.norm(M[..., :2], axis=2), M[..., 2])
        limit = np.pi / 2 if self.half_fov is None else self.half_fov
        bad = np.flatnonzero(np.any(ang >= limit, axis=1))
        if bad.size:
            where = "behind the camera" if self.half_fov is None else "outside the field of view"
            raise ValueError(
                f"camera: markers {where} at pose(s) {pose_list(bad)}; move the camera (T_device_base)"
            )

    def _sigma(self, F: Array) -> Array:
        p = F[:, :3, 3]
        u = p / np.linalg.norm(p, axis=1, keepdims=True)
        var = self.sigma_lateral**2 * (1 - u**2) + self.sigma_depth**2 * u**2
        return np.sqrt(var / len(self.markers))

    def _observe(self, F: Array, rng: np.random.Generator) -> Observations:
        M = self._marker_positions(F)
        u = M / np.linalg.norm(M, axis=2, keepdims=True)
        e = rng.standard_normal(M.shape)
        along = np.einsum("nmi,nmi->nm", e, u)[..., None] * u
        M = M + self.sigma_lateral * (e - along) + self.sigma_depth * along
        p, R = _fit_markers(self.markers, M)
        return Observations(p, R, self._sigma(F))

    def with_noise(self, sigma: float) -> Camera:
        """Lateral noise ``sigma`` (m); the depth noise keeps ``depth_ratio``."""
        return dataclasses.replace(self, sigma=sigma)


#: Devices by name, as used on the command line and in truth files.
DEVICES: dict[str, type[Device]] = {
    cls.kind: cls for cls in (LaserTracker, OpticalCMM, Camera, CalibrationPlate, PenOnPaper)
}


def make_device(name: str, **kwargs: Any) -> Device:
    """A device by name (``laser-tracker``, ``optical-cmm``, ``camera``, ``plate``, ``pen``)."""
    try:
        cls = DEVICES[name]
    except KeyError:
        raise KeyError(f"unknown device {name!r}; known: {', '.join(DEVICES)}") from None
    return cls(**kwargs)


def device_from_dict(data: Mapping[str, Any]) -> Device:
    """The device described by :meth:`Device.to_dict` output."""
    data = dict(data)
    kind = data.pop("type", None)
    if kind not in DEVICES:
        raise ValueError(f"device type {kind!r} is not one of {', '.join(DEVICES)}")
    cls = DEVICES[kind]
    names = {f.name for f in dataclasses.fields(cls)}
    unknown = sorted(set(data) - names)
    if unknown:
        raise ValueError(f"device {kind!r}: unknown field(s) {', '.join(unknown)}")
    for key, value in data.items():
        if isinstance(value, list) and key in ("working_range", "size"):
            data[key] = tuple(value)
    return cls(**data)
