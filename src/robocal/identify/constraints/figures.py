"""What a model makes of constraint data: the figures of :func:`constraint_figures`.

Needs no fit, so it judges held-out data, a nominal model and a calibrated one alike: the
spread of the tool point around each point's centroid, the error of each known distance,
the plane residual, the distances' error and the tilt channels'.  A model carrying joint
effects (``model.joint_effects`` with its link masses: a fit of the position rows' joint
deflections, :mod:`robocal.identify.constraints.position_effects`) predicts its tool
points with the joints' deflections under gravity.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from robocal.identify.constraints.tilt_record import TiltCalibration
from robocal.identify.constraints.tilt_rows import tilt_figures
from robocal.identify.problem import measurement_chain
from robocal.measure.constraints.data_set import ConstraintSet
from robocal.model.chain import Model

__all__ = [
    "ConstraintFigures",
    "constraint_figures",
    "deflections",
    "pooled_spread",
    "robot_and_tool",
    "start_planes",
    "tool_points",
]

Array = NDArray[np.float64]


@dataclass(frozen=True)
class ConstraintFigures:
    """What a model makes of constraint data (all in m).

    Attributes:
        point_spread: ``(K,)`` RMS distance of the tool points from their point's centroid.
        point_distance_error: ``(k,)`` centroid distance minus the stated distance.
        plane_rms: ``(P,)`` RMS distance of the tool points from their plane (the stated
            one when known, else the best-fit plane).
        pair_error: ``(m,)`` distance between the pair's tool points minus the stated length.
        tilt_channels, tilt_rms: each inclinometer channel (``<joint>_<axis>``) and the RMS
            of its readings' residual (rad).
        tilt_basis: what predicted the readings (:func:`~robocal.identify.constraints.
            tilt_rows.tilt_figures`: a calibration's joint effects and zeros, or the geometry
            alone with each channel about its mean).
    """

    point_spread: Array
    point_distance_error: Array
    plane_rms: Array
    pair_error: Array
    tilt_channels: tuple[str, ...] = ()
    tilt_rms: Array = field(default_factory=lambda: np.zeros(0))
    tilt_basis: str = ""

    def as_dict(self) -> dict[str, object]:
        """The figures for a JSON document (mm; the tilt residuals in deg), keyed by unit."""
        mm = 1e3
        out: dict[str, object] = {
            "point_spread_mm": (self.point_spread * mm).tolist(),
            "point_distance_error_mm": (self.point_distance_error * mm).tolist(),
            "plane_rms_mm": (self.plane_rms * mm).tolist(),
            "pair_error_mm": (self.pair_error * mm).tolist(),
        }
        if len(self.tilt_channels):
            out["tilt_rms_deg"] = dict(
                zip(self.tilt_channels, np.degrees(self.tilt_rms).tolist(), strict=True)
            )
            out["tilt_basis"] = self.tilt_basis
        return out

    def lines(self) -> list[str]:
        """One line per figure (mm)."""
        mm = 1e3
        out = [f"point {k}: RMS spread {s * mm:.3f} mm" for k, s in enumerate(self.point_spread)]
        out += [
            f"known distance {k}: error {e * mm:+.3f} mm" for k, e in enumerate(self.point_distance_error)
        ]
        out += [f"plane {k}: RMS residual {s * mm:.3f} mm" for k, s in enumerate(self.plane_rms)]
        if len(self.pair_error):
            rms = math.sqrt(float(np.mean(self.pair_error**2)))
            out.append(
                f"distances: RMS error {rms * mm:.3f} mm, "
                f"max |error| {np.abs(self.pair_error).max() * mm:.3f} mm"
            )
        out += [f"tilt figures: {self.tilt_basis}"] if len(self.tilt_channels) and self.tilt_basis else []
        out += [
            f"tilt {name}: RMS residual {math.degrees(r):.5f} deg"
            for name, r in zip(self.tilt_channels, self.tilt_rms, strict=True)
        ]
        return out


def start_planes(p: Array, data: ConstraintSet) -> Array:
    """``(P, 4)`` each plane's stated normal and offset, or a least-squares fit to ``p``."""
    planes = np.zeros((data.n_planes, 4))
    for k in range(data.n_planes):
        if not data.unknown_plane(k):
            stated = data.planes_stated[k]
            n = stated[:3] / np.linalg.norm(stated[:3])
            planes[k] = [*n, stated[3]]
            continue
        on = p[data.plane == k]
        if len(on) < 3:
            raise ValueError(f"plane {k} has {len(on)} poses; an unknown plane needs at least 3")
        centre = on.mean(axis=0)
        n = np.linalg.svd(on - centre)[2][-1]
        planes[k] = [*n, n @ centre]
    return planes


def robot_and_tool(robot: Model, tool: Array | None) -> Model:
    if tool is None:
        return robot
    T = np.eye(4)
    T[:3, 3] = tool
    return measurement_chain(robot, np.eye(4), T, "position", False)


# ---------------------------------------------------------------------- figures
def deflections(robot: Model, q: Array) -> Array | None:
    """``(n, dof, 3)`` the joints' elastic deflections (rad) under gravity at ``q`` (the
    position rows' kinds, :data:`~robocal.identify.constraints.position_effects.
    POSITION_EFFECT_KINDS`), None when ``robot`` carries none or has no link masses."""
    from robocal.identify.constraints.position_effects import POSITION_EFFECT_KINDS
    from robocal.model.joints import joint_perturbations

    elastic = any(e.compliance or e.radial_compliance for e in robot.joint_effects)
    if not elastic or not robot.bodies:
        return None
    return joint_perturbations(robot, np.atleast_2d(q), kinds=POSITION_EFFECT_KINDS)


def tool_points(
    robot: Model, q: Array, tool: Array | None = None, T_device_base: Array | None = None
) -> Array:
    """``(n, 3)`` the tool point (m) in the device frame (the base frame by default), with
    the joints' elastic deflections under gravity when ``robot`` carries them (its
    compliances in ``joint_effects`` and its link masses)."""
    p = robot_and_tool(robot, tool).fk(q, perturbations=deflections(robot, q))[:, :3, 3]
    if T_device_base is not None:
        p = p @ T_device_base[:3, :3].T + T_device_base[:3, 3]
    return p


def constraint_figures(robot: Model, data: ConstraintSet, tool: Array | None = None,
                       T_device_base: Array | None = None, tilt: TiltCalibration | None = None,
                       ) -> ConstraintFigures:  # fmt: skip
    """What ``robot`` makes of ``data`` (:class:`ConstraintFigures`): needs no fit, so it
    judges held-out data, a nominal model and a calibrated one alike; ``tilt``: the joint
    effects and channel zeros a calibration identified, which predict the tilt rows."""
    p = tool_points(robot, data.q, tool, T_device_base)
    centroids = np.array([p[data.point == k].mean(axis=0) for k in range(data.n_points)]).reshape(-1, 3)
    spread = np.array(
        [
            math.sqrt(float(np.mean(np.sum((p[data.point == k] - centroids[k]) ** 2, axis=1))))
            for k in range(data.n_points)
        ]
    )
    a, b = data.point_pairs.T if len(data.point_pairs) else (np.zeros(0, int), np.zeros(0, int))
    point_error = (
        np.linalg.norm(centroids[a] - centroids[b], axis=1) - data.point_length if len(a) else np.zeros(0)
    )
    planes = start_planes(p, data) if data.n_planes else np.zeros((0, 4))
    plane_rms = np.array(
        [
            math.sqrt(float(np.mean((p[data.plane == k] @ planes[k, :3] - planes[k, 3]) ** 2)))
            for k in range(data.n_planes)
        ]
    )
    pair_error = np.zeros(0)
    if len(data.pairs):
        pair_error = np.linalg.norm(p[data.pairs[:, 0]] - p[data.pairs[:, 1]], axis=1) - data.pair_length
    channels, tilt_rms, basis = tilt_figures(robot, data, tilt)
    return ConstraintFigures(spread, point_error, plane_rms, pair_error, channels, tilt_rms, basis)


def pooled_spread(figures: ConstraintFigures, data: ConstraintSet) -> float:
    """RMS distance (m) of every fixed-point row's tool point from its point's centroid: each
    point's spread weighted by its rows (the ball-in-socket figure, both sockets pooled)."""
    counts = np.bincount(data.point[data.point >= 0], minlength=len(figures.point_spread))
    return math.sqrt(float(np.sum(figures.point_spread**2 * counts) / counts.sum()))
