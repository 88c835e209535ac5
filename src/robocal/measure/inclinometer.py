"""Inclinometers on the links: tilt readings at configurations (seed 003 Figs. 4.6, 5.4).

Seed 003 measures joint tilting with inclinometers "with the resolution of 0.001°"
(§4.4.1; §5.3: from Level Developments) fixed on the links: the change of a reading
between two configurations whose load moments differ gives a joint's clearance tilt
(moment about X flipped), axial stiffness (moment about Z changed) or backlash (moment
about Z flipped, small) — Table 4.3, 4.4 and 5.2.  The thesis notes that
"inclinometers cannot work without gravity component": a rotation about the vertical
is invisible to them (joint 1 of the Katana), so it measured joint 1's backlash and
stiffness with end-effector poses instead.

Reading model
-------------
A sensor on the child link of joint ``link`` has the orientation ``R_base_sensor =
R_base_joint(q, δ) @ mount`` (``mount``: ``R_joint_sensor``, fixed; by default the
sensor is level at the home configuration, :meth:`Inclinometer.level_at`).  With
``up = −g/|g|`` in the base frame, its two channels read

* ``x``: the rotation about the sensor's x axis, ``asin(up · R e_y)``;
* ``y``: the rotation about the sensor's y axis, ``−asin(up · R e_x)``;

plus an unknown constant offset per channel (the sensor's mounting and zero; the thesis
uses changes of readings, which cancel it).  A reading is the true one plus normal noise
``sigma``, rounded to ``resolution``.  Defaults: resolution 0.001° (the thesis);
``sigma`` 0.001° (one count — an assumption: the thesis gives only the resolution) and
a range of ±60° (an assumption: a common range of such sensors).

The joint perturbations ``δ`` are those of :mod:`robocal.model.joints` (eqs. 5.15-5.19)
under the static load moments of eq. 4.21; :func:`readings` evaluates them exactly.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "AXES",
    "Inclinometer",
    "TiltReadings",
    "channel_rows",
    "readings",
    "simulate_readings",
    "up_vector",
]

Array = NDArray[np.float64]

#: the channels of a dual-axis sensor: rotation about its x axis, about its y axis
AXES: tuple[str, ...] = ("x", "y")
RESOLUTION = math.radians(0.001)  # seed 003 §4.4.1 and §5.3
GRAVITY = (0.0, 0.0, -9.81)


@dataclass(frozen=True, eq=False)
class Inclinometer:
    """A dual- (or single-) axis inclinometer fixed on the child link of joint ``link``.

    Attributes:
        link: the joint whose child link carries the sensor (``q3``: the link after joint 3).
        mount: ``R_joint_sensor`` ``(3, 3)``, the sensor in that joint's frame.
        axes: the channels read (``x``, ``y``).
        resolution: one count (rad); readings are rounded to it (0 for none).
        sigma: 1σ of a reading's noise (rad).
        max_tilt: the sensor's range (rad): a reading beyond it cannot be taken.
    """

    link: str
    mount: Array = field(default_factory=lambda: np.eye(3))
    axes: tuple[str, ...] = AXES
    resolution: float = RESOLUTION
    sigma: float = RESOLUTION
    max_tilt: float = math.radians(60.0)

    def __post_init__(self) -> None:
        M = np.array(self.mount, dtype=float)
        if M.shape != (3, 3) or not np.allclose(M @ M.T, np.eye(3), atol=1e-9):
            raise ValueError(f"inclinometer on {self.link}: mount must be a (3, 3) rotation matrix")
        M.setflags(write=False)
        object.__setattr__(self, "mount", M)
        axes = tuple(self.axes)
        if not axes or set(axes) - set(AXES) or len(set(axes)) != len(axes):
            raise ValueError(f"inclinometer on {self.link}: axes must be some of {AXES}, got {axes}")
        object.__setattr__(self, "axes", axes)
        for name in ("resolution", "sigma", "max_tilt"):
            v = float(getattr(self, name))
            if not (math.isfinite(v) and v >= 0):
                raise ValueError(f"inclinometer on {self.link}: {name} must be finite and >= 0, got {v}")
            object.__setattr__(self, name, v)

    @property
    def sigma_reading(self) -> float:
        """1σ of a reading (rad): the noise and the rounding, ``√(σ² + res²/12)``."""
        return math.sqrt(self.sigma**2 + self.resolution**2 / 12.0)

    @classmethod
    def level_at(cls, model, link: str, q_home: ArrayLike | None = None, **kwargs) -> Inclinometer:
        """A sensor on ``link`` mounted level (its axes along the base axes) at ``q_home``
        (default all joints zero) of the nominal ``model``."""
        if link not in model.joint_names:
            raise ValueError(f"inclinometer: model {model.name!r} has no joint {link!r}")
        q = np.zeros(model.dof) if q_home is None else np.asarray(q_home, dtype=float)
        R = model.joint_frames(q[None])[0, model.joint_names.index(link), :3, :3]
        return cls(link=link, mount=R.T, **kwargs)


@dataclass(frozen=True)
class TiltReadings:
    """Inclinometer readings, one row per (configuration, sensor, channel).

    Attributes:
        q: ``(m, dof)`` joint values of each row (rad).
        link: ``(m,)`` the joint whose child link carries the sensor.
        axis: ``(m,)`` the channel (``x`` or ``y``).
        tilt: ``(m,)`` the reading (rad).
        sigma: ``(m,)`` its 1σ (rad).
    """

    q: Array
    link: tuple[str, ...]
    axis: tuple[str, ...]
    tilt: Array
    sigma: Array

    def __post_init__(self) -> None:
        q = np.atleast_2d(np.asarray(self.q, dtype=float))
        m = len(q)
        tilt = np.asarray(self.tilt, dtype=float).reshape(-1)
        sigma = np.broadcast_to(np.asarray(self.sigma, dtype=float), (m,)).copy()
        if len(tilt) != m or len(self.link) != m or len(self.axis) != m:
            raise ValueError("tilt readings: q, link, axis, tilt and sigma need one entry per row")
        if set(self.axis) - set(AXES):
            raise ValueError(f"tilt readings: axis must be one of {AXES}")
        if not (np.all(np.isfinite(q)) and np.all(np.isfinite(tilt)) and np.all(sigma > 0)):
            raise ValueError("tilt readings: q and tilt must be finite and sigma > 0")
        object.__setattr__(self, "q", q)
        object.__setattr__(self, "tilt", tilt)
        object.__setattr__(self, "sigma", sigma)
        object.__setattr__(self, "link", tuple(self.link))
        object.__setattr__(self, "axis", tuple(self.axis))

    @property
    def n(self) -> int:
        return len(self.tilt)

    def channels(self) -> tuple[tuple[str, str], ...]:
        """The distinct ``(link, axis)`` channels, in order of appearance."""
        return tuple(dict.fromkeys(zip(self.link, self.axis, strict=True)))


def up_vector(gravity: ArrayLike = GRAVITY) -> Array:
    """``−g/|g|``: the vertical the sensors level against, in the base frame."""
    g = np.asarray(gravity, dtype=float)
    return -g / np.linalg.norm(g)


def channel_rows(
    model, q: ArrayLike, sensors: tuple[Inclinometer, ...]
) -> tuple[Array, tuple[str, ...], tuple[str, ...], Array]:
    """Rows of reading every channel of ``sensors`` at each configuration of ``q``:
    ``(q_rows (m, dof), link, axis, mounts (m, 3, 3))``, configuration-major."""
    q = np.atleast_2d(np.asarray(q, dtype=float))
    for s in sensors:
        if s.link not in model.joint_names:
            raise ValueError(f"inclinometer: model {model.name!r} has no joint {s.link!r}")
    chans = [(s.link, a, s.mount) for s in sensors for a in s.axes]
    q_rows = np.repeat(q, len(chans), axis=0)
    link = tuple(c[0] for c in chans) * len(q)
    axis = tuple(c[1] for c in chans) * len(q)
    mounts = np.tile(np.array([c[2] for c in chans]), (len(q), 1, 1))
    return q_rows, link, axis, mounts


def sensor_vectors(model, q: Array, link, axis, mounts: Array, perturbations: Array | None):
    """Per row: the sensed unit vector (sensor's e_y for x, e_x for y) in the base frame,
    its sign (+1 for x, −1 for y), the joint index of the link and the joint frames."""
    F = model.joint_frames(q, perturbations)
    idx = np.array([model.joint_names.index(name) for name in link])
    R = np.einsum("nij,njk->nik", F[np.arange(len(q)), idx, :3, :3], mounts)
    col = np.array([1 if a == "x" else 0 for a in axis])
    v = R[np.arange(len(q)), :, col]
    sign = np.where(col == 1, 1.0, -1.0)
    return v, sign, idx, F


def readings(
    model,
    q: ArrayLike,
    link: tuple[str, ...],
    axis: tuple[str, ...],
    mounts: ArrayLike,
    perturbations: ArrayLike | None = None,
    gravity: ArrayLike = GRAVITY,
) -> Array:
    """Noise-free readings ``(m,)`` (rad) of rows ``(q, link, axis, mount)`` of ``model``
    with joint perturbations ``(m, dof, 3)`` (the joint effects; None for none)."""
    q = np.atleast_2d(np.asarray(q, dtype=float))
    d = None if perturbations is None else np.asarray(perturbations, dtype=float)
    v, sign, _, _ = sensor_vectors(model, q, link, axis, np.asarray(mounts, dtype=float), d)
    return sign * np.arcsin(np.clip(v @ up_vector(gravity), -1.0, 1.0))


def simulate_readings(
    true_model,
    q: ArrayLike,
    sensors: tuple[Inclinometer, ...],
    rng: np.random.Generator,
    offsets: dict[tuple[str, str], float] | None = None,
    gravity: ArrayLike = GRAVITY,
) -> TiltReadings:
    """What ``sensors`` read on the true robot (its geometry and ``joint_effects`` under
    the static loads of eq. 4.21) at commanded configurations ``q`` ``(n, dof)``.

    ``offsets``: each channel's zero (rad), ``{(link, axis): offset}`` (default 0).
    Raises ValueError when a reading is beyond a sensor's range (naming the row).
    """
    from robocal.model.joints import joint_perturbations

    q_rows, link, axis, mounts = channel_rows(true_model, q, sensors)
    d = joint_perturbations(true_model, q_rows, gravity=np.asarray(gravity, dtype=float))
    tilt = readings(true_model, q_rows, link, axis, mounts, d, gravity)
    by_link = {s.link: s for s in sensors}
    sensor = [by_link[name] for name in link]
    limit = np.array([s.max_tilt for s in sensor])
    beyond = np.flatnonzero(np.abs(tilt) > limit)
    if beyond.size:
        i = beyond[0]
        raise ValueError(
            f"inclinometer on {link[i]}: channel {axis[i]} reads {math.degrees(tilt[i]):.1f} deg at "
            f"configuration {i // max(1, sum(len(s.axes) for s in sensors)) + 1}, beyond its "
            f"±{math.degrees(limit[i]):g} deg range"
        )
    zero = np.array([(offsets or {}).get((name, a), 0.0) for name, a in zip(link, axis, strict=True)])
    sig = np.array([s.sigma for s in sensor])
    res = np.array([s.resolution for s in sensor])
    raw = tilt + zero + sig * rng.standard_normal(len(tilt))
    read = np.where(res > 0, np.round(raw / np.where(res > 0, res, 1.0)) * res, raw)
    return TiltReadings(q_rows, link, axis, read, np.array([s.sigma_reading for s in sensor]))
