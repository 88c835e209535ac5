"""The ISO 9283:1998 characteristics beyond AP, RP, AT and RT, on arrays.

Each characteristic is a small function on arrays in SI units (m, rad, s, N) returning a
frozen result; AP/RP (§7.2.1, §7.2.2) and AT/RT (§8.2–§8.4) are in
:mod:`robocal.evaluate.metrics` and are reused here, never re-implemented.  Clause numbers
are those of ISO 9283:1998 (second edition).  Where the standard leaves a choice (the limit
band, how a speed is obtained from positions, which part of a path counts), the choice made
here is stated in the function's docstring and in ``docs/iso9283.md``.

Characteristics (seed 001 Table 1 lists the same fourteen):

====  ===========================================  =======  ==============================
 #    characteristic                               clause   function
====  ===========================================  =======  ==============================
 1    pose accuracy and repeatability AP, RP       7.2.1-2  metrics.pose_accuracy/-repeatability
 2    multi-directional pose accuracy variation    7.2.3    :func:`multidirectional_variation`
 3    distance accuracy and repeatability AD, RD   7.3      :func:`distance_characteristics`
 4    pose stabilisation time                      7.4      :func:`stabilisation`
 5    pose overshoot                               7.5      :func:`stabilisation`
 6    drift of pose characteristics dAP, dRP       7.6      :func:`drift`
 7    exchangeability E                            7.7      :func:`exchangeability`
 8    path accuracy and repeatability AT, RT       8.2-8.3  metrics.path_accuracy
 9    path accuracy on reorientation               8.4      metrics.path_accuracy (frames)
 10   cornering deviations CR, CO                  8.5      :func:`cornering`
 11   path velocity characteristics AV, RV, FV     8.6      :func:`path_velocity`
 12   minimum positioning time                     9        :func:`positioning_time`
 13   static compliance                            10       :func:`static_compliance`
 14   weaving deviations WS, WF                    11       :func:`weaving`
====  ===========================================  =======  ==============================

The path characteristics (8.5, 8.6, 11) live in :mod:`robocal.evaluate.iso9283.path`;
this module re-exports them.
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from robocal import spatial
from robocal.evaluate.deviations import ISO_ANGLES, angle_deltas, split_poses, wrap
from robocal.evaluate.iso9283.path import (
    Cornering,
    PathVelocity,
    Weaving,
    cornering,
    path_speeds,
    path_velocity,
    weaving,
)
from robocal.evaluate.metrics import pose_accuracy, pose_repeatability

__all__ = [
    "Cornering",
    "DistanceCharacteristics",
    "Drift",
    "Exchangeability",
    "MultiDirectional",
    "PathVelocity",
    "Stabilisation",
    "StaticCompliance",
    "Weaving",
    "cornering",
    "distance_characteristics",
    "drift",
    "exchangeability",
    "multidirectional_variation",
    "path_speeds",
    "path_velocity",
    "positioning_time",
    "stabilisation",
    "static_compliance",
    "weaving",
]

Array = NDArray[np.float64]


def _mean_angles(R: Array, seq: str) -> Array:
    """Mean orientation angles ``(3,)`` (rad) of frames ``R`` ``(n, 3, 3)``: angles taken
    relative to the first frame's so that a cluster around ±π averages correctly."""
    ref = np.broadcast_to(R[0], R.shape)
    return wrap(spatial.matrix_to_euler(R[0], seq) + angle_deltas(R, ref, seq).mean(axis=0))


def _max_pairwise(points: Sequence[Array]) -> tuple[float, tuple[int, int]]:
    """Largest distance between any two of ``points`` (each ``(d,)``), and the pair."""
    best, pair = 0.0, (0, 0)
    for h, k in itertools.combinations(range(len(points)), 2):
        d = float(np.linalg.norm(points[h] - points[k]))
        if d > best:
            best, pair = d, (h, k)
    return best, pair


# ------------------------------------------------------------------ 7.2.3 multi-directional
@dataclass(frozen=True)
class MultiDirectional:
    """ISO 9283 §7.2.3 multi-directional pose accuracy variation of one commanded pose.

    Attributes:
        vAP: ``vAP_P = max_{h,k} |G_h − G_k|`` (m), ``G_h`` the barycentre of the poses
            attained when approaching from direction ``h``.
        vAP_abc: ``max_{h,k} |ā_h − ā_k|`` … (rad), or None without orientations.
        barycentres: ``(directions, 3)`` (m).
        pair: the two directions (indices) that are farthest apart.
    """

    vAP: float  # noqa: N815 (the standard's symbol)
    vAP_abc: Array | None  # noqa: N815 (the standard's symbol)
    barycentres: Array
    pair: tuple[int, int]


def multidirectional_variation(
    attained_by_direction: Sequence[ArrayLike], angles: str = ISO_ANGLES
) -> MultiDirectional:
    """ISO 9283 §7.2.3: how far apart the barycentres of one commanded pose lie when it
    is approached from different directions (the standard: three mutually perpendicular
    directions parallel to the base axes, 30 cycles each, at P1, P2 and P4).

    Args:
        attained_by_direction: per approach direction, ``(n_h, 3)`` positions or
            ``(n_h, 4, 4)`` frames (m).
    """
    groups = [split_poses(a, "attained") for a in attained_by_direction]
    if len(groups) < 2:
        raise ValueError(f"multi-directional variation needs >= 2 approach directions, got {len(groups)}")
    bary = np.array([np.atleast_2d(p).mean(axis=0) for p, _ in groups])
    vAP, pair = _max_pairwise(list(bary))
    abc = None
    if all(R is not None for _, R in groups):
        means = [_mean_angles(R.reshape(-1, 3, 3), angles) for _, R in groups]  # type: ignore[union-attr]
        abc = np.max(
            [np.abs(wrap(means[h] - means[k])) for h, k in itertools.combinations(range(len(means)), 2)],
            axis=0,
        )
    return MultiDirectional(vAP, abc, bary, pair)


# ------------------------------------------------------------------ 7.3 distance
@dataclass(frozen=True)
class DistanceCharacteristics:
    """ISO 9283 §7.3 distance accuracy and repeatability between two commanded poses.

    Attributes:
        AD: ``AD_P = D̄ − D_c`` (m): mean attained distance minus the commanded distance
            (signed: negative when the robot travels short).
        AD_xyz: ``D̄_x − D_cx`` … with ``D_xj = |x_1j − x_2j|`` (m).
        RD: ``RD = 3 S_D`` (m; the standard writes ±), ``S_D`` the standard deviation
            (n − 1) of the attained distances ``D_j``.
        RD_xyz: ``3 S_Dx`` … (m).
        AD_abc, RD_abc: the same for the orientation angles (rad), or None.
        D_c: commanded distance (m).
        n: number of cycles.
    """

    AD: float
    AD_xyz: Array
    RD: float
    RD_xyz: Array
    AD_abc: Array | None
    RD_abc: Array | None
    D_c: float
    n: int


def distance_characteristics(
    attained_1: ArrayLike,
    attained_2: ArrayLike,
    commanded_1: ArrayLike,
    commanded_2: ArrayLike,
    angles: str = ISO_ANGLES,
) -> DistanceCharacteristics:
    """ISO 9283 §7.3 AD and RD of the distance between two poses attained in the same
    cycle (the standard: P2 and P4, 30 cycles).

    Args:
        attained_1, attained_2: ``(n, 3)`` positions or ``(n, 4, 4)`` frames (m), row
            ``j`` of both from cycle ``j``.
        commanded_1, commanded_2: ``(3,)`` positions or ``(4, 4)`` frames (m).
    """
    p1, R1 = split_poses(attained_1, "attained_1")
    p2, R2 = split_poses(attained_2, "attained_2")
    c1, Rc1 = split_poses(commanded_1, "commanded_1")
    c2, Rc2 = split_poses(commanded_2, "commanded_2")
    if p1.shape != p2.shape or p1.ndim != 2 or len(p1) < 2:
        raise ValueError(
            f"distance needs the same n >= 2 cycles of both poses, got {p1.shape} and {p2.shape}"
        )
    n = len(p1)
    D = np.linalg.norm(p1 - p2, axis=1)
    D_xyz = np.abs(p1 - p2)
    D_c = float(np.linalg.norm(c1 - c2))
    AD = float(D.mean() - D_c)
    AD_xyz = D_xyz.mean(axis=0) - np.abs(c1 - c2)
    RD = float(3.0 * D.std(ddof=1))
    RD_xyz = 3.0 * D_xyz.std(axis=0, ddof=1)
    AD_abc = RD_abc = None
    if R1 is not None and R2 is not None and Rc1 is not None and Rc2 is not None:
        D_abc = np.abs(angle_deltas(R1, R2, angles))  # |a_1j − a_2j|, wrapped
        D_cabc = np.abs(angle_deltas(Rc1, Rc2, angles))
        AD_abc = D_abc.mean(axis=0) - D_cabc
        RD_abc = 3.0 * D_abc.std(axis=0, ddof=1)
    return DistanceCharacteristics(AD, AD_xyz, RD, RD_xyz, AD_abc, RD_abc, D_c, n)


# ------------------------------------------------------------------ 7.4, 7.5 stabilisation
@dataclass(frozen=True)
class Stabilisation:
    """ISO 9283 §7.4 stabilisation time and §7.5 overshoot of one visit of a pose.

    Attributes:
        time: stabilisation time (s): from the "attained pose" instant to the first sample
            after which the position stays within the limit band around the stabilised
            position (0 when it never leaves the band after that instant).
        overshoot: ``OV`` (m): after the position first enters the band, the largest
            distance from the stabilised position if that exceeds the band, else 0.
        stable: ``(3,)`` the stabilised position (m).
        settled: whether the position ends within the band for at least ``hold`` seconds
            (False: the record is too short to tell, and ``time`` is NaN).
    """

    time: float
    overshoot: float
    stable: Array
    settled: bool


def stabilisation(
    t: ArrayLike,
    positions: ArrayLike,
    t_attained: float,
    band: float,
    stable: ArrayLike | None = None,
    hold: float = 0.05,
) -> Stabilisation:
    """Stabilisation time (§7.4) and overshoot (§7.5) of one approach to a pose.

    The standard measures both from a time record of the approach (3 cycles, the result
    the mean of the cycles) against a limit band given by the manufacturer.  Read here:

    * ``t_attained`` is the instant the robot signals "attained pose"; a log that does
      not record that signal uses the instant its commanded position reaches the
      target (:mod:`robocal.evaluate.iso9283.log`);
    * the stabilised position is ``stable`` (default: the last sample);
    * the distance is the 3-D distance ``D_k = |p_k − p_stable|``;
    * time: ``t_s − t_attained`` with ``t_s`` the time of the first sample of the final
      run of samples within ``band`` (0 when that run starts before ``t_attained``);
    * overshoot: ``OV = max D_k`` over the samples after the first one within ``band``,
      if that exceeds ``band``, else 0 (the record may start before ``t_attained``, so
      that an overshoot while the command is still running counts);
    * the record shows a settled pose only if its final run within the band lasts at
      least ``hold`` seconds (a record that merely ends at a zero crossing of an
      oscillation is not settled).

    Args:
        t: ``(k,)`` sample times (s), increasing.
        positions: ``(k, 3)`` measured positions (m).
        t_attained: the "attained pose" instant (s).
        band: limit band radius (m), > 0.
        stable: ``(3,)`` stabilised position (m).
        hold: how long the final run within the band must last (s).
    """
    t = np.asarray(t, dtype=float)
    p = np.asarray(positions, dtype=float)
    if p.ndim != 2 or p.shape[1] != 3 or len(p) != len(t) or len(t) < 2:
        raise ValueError(
            f"stabilisation needs (k >= 2,) times and (k, 3) positions, got {t.shape}, {p.shape}"
        )
    if not band > 0:
        raise ValueError(f"the limit band must be > 0 m, got {band!r}")
    ref = p[-1] if stable is None else np.asarray(stable, dtype=float)
    D = np.linalg.norm(p - ref, axis=1)
    inside = band >= D
    outside = np.flatnonzero(~inside)
    first_in_final = 0 if len(outside) == 0 else int(outside[-1]) + 1
    if first_in_final >= len(t) or t[-1] - t[first_in_final] < hold:
        return Stabilisation(float("nan"), float("nan"), ref, False)
    time = max(0.0, float(t[first_in_final] - t_attained))
    first_in = int(np.argmax(inside))
    peak = float(D[first_in:].max())
    return Stabilisation(time, peak if peak > band else 0.0, ref, True)


def positioning_time(
    t: ArrayLike, positions: ArrayLike, t_start: float, band: float, stable: ArrayLike | None = None
) -> float:
    """ISO 9283 §9 positioning time of one move (s): from leaving the start pose to the
    stabilised end pose.  Read here: from ``t_start`` (the instant the commanded motion
    starts) to the first sample of the final run within ``band`` of the stabilised
    position (as in :func:`stabilisation`); NaN when the record ends outside the band.
    The minimum positioning time of a distance is the mean over its cycles (3)."""
    s = stabilisation(t, positions, t_start, band, stable)
    return s.time if s.settled else float("nan")


# ------------------------------------------------------------------ 7.6 drift
@dataclass(frozen=True)
class Drift:
    """ISO 9283 §7.6 drift of pose accuracy and repeatability.

    Attributes:
        dAP: ``|AP_{t=1} − AP_{t=T}|`` (m).
        dRP: ``|RP_{t=1} − RP_{t=T}|`` (m).
        AP, RP: ``(blocks,)`` AP and RP of every measurement block in time order (m).
    """

    dAP: float  # noqa: N815 (the standard's symbol)
    dRP: float  # noqa: N815 (the standard's symbol)
    AP: Array
    RP: Array


def drift(attained_by_block: Sequence[ArrayLike], commanded: ArrayLike) -> Drift:
    """ISO 9283 §7.6: the change of AP and RP of one pose (the standard: P1, cycling
    continuously for 8 h from cold, measured at intervals) between the first and the
    last measurement block.

    Args:
        attained_by_block: per block in time order, ``(n_b >= 2, 3)`` positions (m).
        commanded: ``(3,)`` commanded position (m).
    """
    if len(attained_by_block) < 2:
        raise ValueError(f"drift needs >= 2 measurement blocks, got {len(attained_by_block)}")
    c, _ = split_poses(commanded, "commanded")
    blocks = [split_poses(a, "attained")[0] for a in attained_by_block]
    AP = np.array([pose_accuracy(b, c).AP for b in blocks])
    RP = np.array([pose_repeatability(b).RP for b in blocks])
    return Drift(float(abs(AP[0] - AP[-1])), float(abs(RP[0] - RP[-1])), AP, RP)


# ------------------------------------------------------------------ 7.7 exchangeability
@dataclass(frozen=True)
class Exchangeability:
    """ISO 9283 §7.7 exchangeability of one commanded pose.

    Attributes:
        E: the largest distance between the barycentres of robots of the same type
            exchanged on the same mounting (m).
        barycentres: ``(robots, 3)`` (m).
        pair: the two robots (indices) farthest apart.
    """

    E: float
    barycentres: Array
    pair: tuple[int, int]


def exchangeability(attained_by_robot: Sequence[ArrayLike]) -> Exchangeability:
    """ISO 9283 §7.7 ``E`` of one pose from ``(n_r, 3)`` attained positions (m) of each
    robot (the standard: P1..P5, 30 cycles, robots exchanged under the same conditions)."""
    if len(attained_by_robot) < 2:
        raise ValueError(f"exchangeability needs >= 2 robots, got {len(attained_by_robot)}")
    bary = np.array([np.atleast_2d(split_poses(a, "attained")[0]).mean(axis=0) for a in attained_by_robot])
    E, pair = _max_pairwise(list(bary))
    return Exchangeability(E, bary, pair)


# ------------------------------------------------------------------ 10 static compliance
@dataclass(frozen=True)
class StaticCompliance:
    """ISO 9283 §10 static compliance per load direction.

    Attributes:
        directions: labels ``"+x"``, ``"-x"``, … of the directions loaded.
        compliance: ``(d,)`` the largest displacement per unit load over the load steps
            of each direction (m/N).
        displacement: per direction, ``(steps, 3)`` mean displacement at each load step (m).
        loads: per direction, ``(steps,)`` load magnitudes (N).
    """

    directions: tuple[str, ...]
    compliance: Array
    displacement: tuple[Array, ...]
    loads: tuple[Array, ...]


def static_compliance(forces: ArrayLike, displacements: ArrayLike) -> StaticCompliance:
    """ISO 9283 §10: the displacement of the loaded mechanical interface per unit load
    (the standard: at P1, loads along ±x, ±y, ±z of the base raised in steps to the
    rated load, 3 cycles).  Read here: displacement = the 3-D distance from the unloaded
    position; per direction the largest ratio over the load steps, each step's
    displacement averaged over its cycles.

    Args:
        forces: ``(k, 3)`` applied loads (N), each along one base axis.
        displacements: ``(k, 3)`` displacements from the unloaded position (m).
    """
    F = np.asarray(forces, dtype=float)
    d = np.asarray(displacements, dtype=float)
    if F.ndim != 2 or F.shape[1] != 3 or d.shape != F.shape:
        raise ValueError(f"compliance needs (k, 3) forces and displacements, got {F.shape}, {d.shape}")
    mag = np.linalg.norm(F, axis=1)
    loaded = mag > 0
    if not loaded.any():
        raise ValueError("static compliance needs at least one loaded measurement")
    axis = np.argmax(np.abs(F), axis=1)
    off_axis = np.linalg.norm(F - np.eye(3)[axis] * F[np.arange(len(F)), axis][:, None], axis=1)
    if np.any(off_axis[loaded] > 1e-6 * mag[loaded]):
        raise ValueError("each load must act along one base axis (x, y or z)")
    sign = np.sign(F[np.arange(len(F)), axis])
    labels, comp, disp, loads = [], [], [], []
    for k, name in enumerate("xyz"):
        for s, sym in ((1, "+"), (-1, "-")):
            sel = loaded & (axis == k) & (sign == s)
            if not sel.any():
                continue
            steps = np.unique(np.round(mag[sel], 6))
            mean_d = np.array([d[sel][np.isclose(mag[sel], m, rtol=1e-6)].mean(axis=0) for m in steps])
            labels.append(f"{sym}{name}")
            comp.append(float(np.max(np.linalg.norm(mean_d, axis=1) / steps)))
            disp.append(mean_d)
            loads.append(steps)
    return StaticCompliance(tuple(labels), np.array(comp), tuple(disp), tuple(loads))
