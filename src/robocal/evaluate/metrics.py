"""ISO 9283 performance characteristics and the seeds' error tables.

All inputs and outputs are SI (m, rad); convert to mm and degrees at the edges.

ISO 9283:1998 pose characteristics (§7.2), for one commanded pose ``c`` visited in
``n`` cycles, attained positions ``(x_j, y_j, z_j)`` and orientation angles
``(a_j, b_j, c_j)`` (rotations about the base x, y and z axes), ``j = 1..n``:

* pose accuracy (§7.2.1): the distance from the command to the barycentre of the
  attained positions, ``AP_P = sqrt((x̄ − x_c)² + (ȳ − y_c)² + (z̄ − z_c)²)`` with
  ``x̄ = (1/n) Σ x_j`` …, its components ``AP_x = x̄ − x_c`` …, and for the
  orientation ``AP_a = ā − a_c``, ``AP_b = b̄ − b_c``, ``AP_c = c̄ − c_c``;
* pose repeatability (§7.2.2): the radius of the sphere around the barycentre,
  ``RP_l = l̄ + 3 S_l`` with ``l_j = sqrt((x_j − x̄)² + (y_j − ȳ)² + (z_j − z̄)²)``,
  ``l̄ = (1/n) Σ l_j`` and ``S_l = sqrt(Σ (l_j − l̄)² / (n − 1))``, and for the
  orientation ``RP_a = ±3 S_a`` with ``S_a = sqrt(Σ (a_j − ā)² / (n − 1))`` (also b, c).

Path characteristics (§8.2, §8.3), for a commanded path sampled at points ``c_i``,
``i = 1..m``, followed in ``n`` cycles: the attained path of cycle ``j`` is cut by the
plane normal to the commanded path at ``c_i`` (the point ``x_ij``), and

* path accuracy ``AT_P = max_i sqrt((x̄_i − x_ci)² + (ȳ_i − y_ci)² + (z̄_i − z_ci)²)``
  with ``x̄_i = (1/n) Σ_j x_ij`` …;
* path repeatability ``RT_P = max_i (l̄_i + 3 S_li)`` with ``l_ij`` the distance of
  ``x_ij`` from the barycentre ``(x̄_i, ȳ_i, z̄_i)``;
* with orientations (§8.4, path accuracy on reorientation): ``AT_a = max_i |ā_i − a_ci|``
  and ``RT_a = max_i 3 S_ai`` (also b, c), the attained orientation at a crossing
  interpolated (slerp) between the two samples around it.

Angles: the standard leaves the orientation convention to the robot; here ``a, b, c``
are extrinsic rotations about the base x, y, z axes (``R = Rz(c) Ry(b) Rx(a)``,
scipy ``"xyz"``), and every angle difference is wrapped to (−π, π] so that a cluster
of poses around ±180° averages correctly.

The seeds' tables (seed 003 Tables 3.4, 4.5, 4.6; seed 001 Tables 4, 6):
:func:`pose_errors` gives ``|ΔX| |ΔY| |ΔZ| |ΔP|`` and the Euler-angle errors
``|ΔΦ| |Δθ| |ΔΨ|`` (seed 003 §2: ZXZ Euler angles, the default; note that ZXZ angles
are singular when the tool z axis is parallel to the base z axis, so prefer ``"xyz"``
for tool-down poses), :func:`error_table` their minimum, maximum and average per
case (before / after calibration ...), and :func:`improvement` the improvement of a
mean error in per cent with its confidence interval (seed 001: "with a 95 %
confidence interval").

Improvement confidence interval: ``I = 1 − ā/b̄`` for errors ``a`` (after) and ``b``
(before).  Its standard error comes from the delta method,
``se(ā/b̄)² = (s_a² + R² s_b² − 2 R s_ab) / (n b̄²)`` with ``R = ā/b̄`` for paired
samples (the same poses before and after; ``s_ab`` their covariance), and
``s_a²/(n_a b̄²) + R² s_b²/(n_b b̄²)`` for independent samples; the interval is
``I ± t_{(1+γ)/2, ν} se`` with Student's t (ν = n − 1, or the smaller sample's
n − 1 for independent samples).  Mean errors get ``x̄ ± t s/√n``.

The seeds' error tables (:func:`error_table` and its parts) live in
:mod:`robocal.evaluate.error_tables`, re-exported here.
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from robocal import spatial
from robocal.evaluate.deviations import ISO_ANGLES, angle_deltas, split_poses, wrap
from robocal.evaluate.error_tables import (
    ERROR_QUANTITIES,
    ErrorTable,
    Improvement,
    PoseErrors,
    error_table,
    improvement,
    mean_ci,
    pose_errors,
)

__all__ = [
    "ERROR_QUANTITIES",
    "ErrorTable",
    "Improvement",
    "PathAccuracy",
    "PoseAccuracy",
    "PoseCharacteristics",
    "PoseErrors",
    "PoseRepeatability",
    "error_table",
    "improvement",
    "iso9283_pose_characteristics",
    "mean_ci",
    "path_accuracy",
    "pose_accuracy",
    "pose_errors",
    "pose_repeatability",
]

Array = NDArray[np.float64]


# ---------------------------------------------------------------------- ISO 9283 poses
@dataclass(frozen=True)
class PoseAccuracy:
    """ISO 9283 §7.2.1 pose accuracy of one commanded pose over ``n`` cycles.

    Attributes:
        AP: ``AP_P`` (m), the distance from the commanded position to the barycentre.
        AP_xyz: ``(AP_x, AP_y, AP_z)`` (m), barycentre minus command.
        AP_abc: ``(AP_a, AP_b, AP_c)`` (rad), mean attained minus commanded angles, or
            None without orientations.
        barycentre: ``(3,)`` mean attained position (m).
        n: number of cycles.
    """

    AP: float
    AP_xyz: Array
    AP_abc: Array | None
    barycentre: Array
    n: int


def pose_accuracy(attained: ArrayLike, commanded: ArrayLike, angles: str = ISO_ANGLES) -> PoseAccuracy:
    """ISO 9283 pose accuracy AP of ``n`` attained poses of one commanded pose.

    Args:
        attained: ``(n, 3)`` positions or ``(n, 4, 4)`` frames (m), robot base frame.
        commanded: ``(3,)`` position or ``(4, 4)`` frame (m).
        angles: Euler sequence of the orientation angles a, b, c (scipy convention;
            default ``"xyz"``, rotations about the base x, y, z axes).
    """
    p, R = split_poses(attained, "attained")
    pc, Rc = split_poses(commanded, "commanded")
    p = np.atleast_2d(p)
    if p.ndim != 2 or pc.shape != (3,):
        raise ValueError(
            f"attained must be (n, 3)/(n, 4, 4) and commanded (3,)/(4, 4); got {p.shape}, {pc.shape}"
        )
    if len(p) == 0:
        raise ValueError("pose accuracy needs at least one attained pose")
    bary = p.mean(axis=0)
    d = bary - pc
    abc = None
    if R is not None and Rc is not None:
        abc = wrap(angle_deltas(R.reshape(-1, 3, 3), Rc, angles).mean(axis=0))
    return PoseAccuracy(float(np.linalg.norm(d)), d, abc, bary, len(p))


@dataclass(frozen=True)
class PoseRepeatability:
    """ISO 9283 §7.2.2 pose repeatability of one commanded pose over ``n`` cycles.

    Attributes:
        RP: ``RP_l = l̄ + 3 S_l`` (m).
        l_mean: ``l̄`` (m), mean distance of the attained positions from their barycentre.
        S_l: ``S_l`` (m), the standard deviation of those distances (n − 1).
        RP_abc: ``(3 S_a, 3 S_b, 3 S_c)`` (rad; the standard writes ±), or None.
        n: number of cycles.
    """

    RP: float
    l_mean: float
    S_l: float
    RP_abc: Array | None
    n: int


def pose_repeatability(attained: ArrayLike, angles: str = ISO_ANGLES) -> PoseRepeatability:
    """ISO 9283 pose repeatability RP of ``n >= 2`` attained poses of one commanded pose.

    Args:
        attained: ``(n, 3)`` positions or ``(n, 4, 4)`` frames (m).
        angles: Euler sequence of a, b, c (see :func:`pose_accuracy`).
    """
    p, R = split_poses(attained, "attained")
    if p.ndim != 2 or len(p) < 2:
        raise ValueError(f"pose repeatability needs n >= 2 attained poses (n, 3), got shape {p.shape}")
    n = len(p)
    dist = np.linalg.norm(p - p.mean(axis=0), axis=1)  # l_j
    l_mean = float(dist.mean())
    S_l = float(np.sqrt(np.sum((dist - l_mean) ** 2) / (n - 1)))
    abc = None
    if R is not None:
        a = angle_deltas(R, R[0], angles)  # relative to one attained pose: no wrap across ±π
        abc = 3.0 * np.sqrt(np.sum((a - a.mean(axis=0)) ** 2, axis=0) / (n - 1))
    return PoseRepeatability(l_mean + 3.0 * S_l, l_mean, S_l, abc, n)


@dataclass(frozen=True)
class PoseCharacteristics:
    """AP and RP at several commanded poses (ISO 9283 P1..P5)."""

    labels: tuple[str, ...]
    accuracy: tuple[PoseAccuracy, ...]
    repeatability: tuple[PoseRepeatability, ...]

    def rows(self) -> list[dict[str, Any]]:
        """One dict per pose in mm and degrees: label, AP, APx..APz, RP [, APa..APc, RPa..RPc]."""
        out = []
        for label, acc, rep in zip(self.labels, self.accuracy, self.repeatability, strict=True):
            row: dict[str, Any] = {
                "pose": label,
                "n": acc.n,
                "AP_mm": acc.AP * 1e3,
                "APx_mm": float(acc.AP_xyz[0] * 1e3),
                "APy_mm": float(acc.AP_xyz[1] * 1e3),
                "APz_mm": float(acc.AP_xyz[2] * 1e3),
                "RP_mm": rep.RP * 1e3,
            }
            if acc.AP_abc is not None and rep.RP_abc is not None:
                for k, c in enumerate("abc"):
                    row[f"AP{c}_deg"] = float(np.degrees(acc.AP_abc[k]))
                for k, c in enumerate("abc"):
                    row[f"RP{c}_deg"] = float(np.degrees(rep.RP_abc[k]))
            out.append(row)
        return out


def iso9283_pose_characteristics(
    commanded: ArrayLike,
    attained: ArrayLike,
    labels: Sequence[str] | None = None,
    angles: str = ISO_ANGLES,
) -> PoseCharacteristics:
    """AP and RP of ``k`` commanded poses (e.g. P1..P5), each attained in ``n`` cycles.

    Args:
        commanded: ``(k, 3)`` positions or ``(k, 4, 4)`` frames (m).
        attained: ``(k, n, 3)`` or ``(k, n, 4, 4)``: pose ``i`` of cycle ``j`` at ``[i, j]``.
        labels: pose names (default ``P1``..``Pk``).
    """
    c = np.asarray(commanded, dtype=float)
    a = np.asarray(attained, dtype=float)
    k = len(c)
    if len(a) != k:
        raise ValueError(f"{k} commanded poses but attained has {len(a)} rows (shape {a.shape})")
    labels = tuple(labels) if labels is not None else tuple(f"P{i + 1}" for i in range(k))
    if len(labels) != k:
        raise ValueError(f"{len(labels)} labels for {k} poses")
    acc = tuple(pose_accuracy(a[i], c[i], angles) for i in range(k))
    rep = tuple(pose_repeatability(a[i], angles) for i in range(k))
    return PoseCharacteristics(labels, acc, rep)


# ---------------------------------------------------------------------- ISO 9283 paths
@dataclass(frozen=True)
class PathAccuracy:
    """ISO 9283 §8.2-8.3 path accuracy and repeatability (positions).

    Attributes:
        AT: ``AT_P`` (m), the largest distance from a commanded point to the barycentre
            of the attained path's crossings of its normal plane.
        RT: ``RT_P`` (m), the largest ``l̄_i + 3 S_li`` (NaN for one cycle).
        at: ``(m,)`` the distance at every commanded point (NaN where no cycle crossed).
        rt: ``(m,)`` ``l̄_i + 3 S_li`` at every commanded point.
        barycentres: ``(m, 3)`` barycentres of the crossings (m).
        crossings: ``(n, m, 3)`` crossing points per cycle (NaN where the attained path
            does not cross the normal plane near the commanded point).
        n_cycles: ``n``.
        AT_abc: ``(AT_a, AT_b, AT_c)`` (rad), the largest mean orientation deviation at a
            commanded point (§8.4), or None without orientations.
        RT_abc: ``(RT_a, RT_b, RT_c)`` (rad), the largest ``3 S_a`` ..., or None.
    """

    AT: float
    RT: float
    at: Array
    rt: Array
    barycentres: Array
    crossings: Array = field(repr=False)
    n_cycles: int = 0
    AT_abc: Array | None = None
    RT_abc: Array | None = None


def _tangents(c: Array) -> Array:
    t = np.gradient(c, axis=0)
    norm = np.linalg.norm(t, axis=1, keepdims=True)
    if np.any(norm == 0):
        raise ValueError("the commanded path has repeated consecutive points: no tangent")
    return t / norm


def _arc_fraction(points: Array) -> Array:
    """Cumulative arc length of a polyline as a fraction of its length, ``(k,)``."""
    s = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(points, axis=0), axis=1))]
    return s / s[-1] if s[-1] > 0 else np.linspace(0.0, 1.0, len(points))


def _crossings(c: Array, t: Array, path: Array, window: float) -> tuple[Array, Array, Array]:
    """Where polyline ``path`` ``(k, 3)`` crosses the planes through ``c`` ``(m, 3)``
    normal to ``t``: of the crossings on segments within ``window`` (fraction of the
    path's length) of the commanded point's place along its path, the one nearest to
    ``c_i``.  Returns the points ``(m, 3)`` (NaN if none), the segment index ``(m,)``
    and the fraction ``(m,)`` along that segment."""
    s = np.einsum("mi,kmi->mk", t, path[:, None, :] - c[None, :, :])  # (m, k) signed distances
    s0, s1 = s[:, :-1], s[:, 1:]
    cross = ((s0 <= 0) & (s1 > 0)) | ((s0 >= 0) & (s1 < 0))
    f = _arc_fraction(path)
    g = _arc_fraction(c)
    near = (f[None, 1:] >= g[:, None] - window) & (f[None, :-1] <= g[:, None] + window)  # (m, k-1)
    cross &= near
    with np.errstate(divide="ignore", invalid="ignore"):
        u = np.where(cross, s0 / (s0 - s1), np.nan)  # (m, k-1) fraction along each segment
    pts = path[None, :-1, :] + u[..., None] * (path[None, 1:, :] - path[None, :-1, :])  # (m, k-1, 3)
    dist = np.linalg.norm(pts - c[:, None, :], axis=2)
    dist = np.where(cross, dist, np.inf)
    rows = np.arange(len(c))
    best = np.argmin(dist, axis=1)
    out = pts[rows, best]
    out[~np.isfinite(dist[rows, best])] = np.nan
    return out, best, u[rows, best]


def _crossing_angles(R: Array, seg: Array, u: Array, R_c: Array, seq: str) -> Array:
    """Orientation deviations ``(m, 3)`` (rad) at the crossings: the attained rotation
    slerped between samples ``seg`` and ``seg + 1`` of ``R`` ``(k, 3, 3)`` by ``u``,
    as angles minus those of the commanded ``R_c`` ``(m, 3, 3)`` (NaN where no crossing)."""
    ok = np.isfinite(u)
    out = np.full((len(seg), 3), np.nan)
    if ok.any():
        R0, R1 = R[seg[ok]], R[seg[ok] + 1]
        step = spatial.matrix_to_rotvec(np.swapaxes(R0, -1, -2) @ R1) * u[ok, None]
        out[ok] = angle_deltas(R0 @ spatial.rotvec_to_matrix(step), R_c[ok], seq)
    return out


def path_accuracy(
    commanded: ArrayLike,
    attained: NDArray[np.floating] | Sequence[ArrayLike],
    window: float = 0.1,
    angles: str = ISO_ANGLES,
) -> PathAccuracy:
    """ISO 9283 path accuracy AT and repeatability RT (§8.2, §8.3; with frames also the
    orientation terms of §8.4).

    Args:
        commanded: ``(m, 3)`` points or ``(m, 4, 4)`` frames of the commanded path (m), in order.
        attained: the attained paths of ``n`` cycles, each ``(k_j, 3)`` points or
            ``(k_j, 4, 4)`` frames in order (an array or a list), sampled finely enough
            that the segments between samples are straight.
        window: a crossing counts for commanded point ``c_i`` only on the part of the
            attained path within this fraction of its length of ``c_i``'s place along
            the commanded path (so that a closed or folded path is not cut on its far
            side).
        angles: Euler sequence of the orientation angles a, b, c (see :func:`pose_accuracy`).

    A commanded point whose normal plane no attained path crosses (e.g. an end point
    that every cycle stops short of) gets NaN and is left out of AT and RT; an error is
    raised if that leaves no point.
    """
    c, R_c = split_poses(commanded, "commanded path")
    if c.ndim != 2 or len(c) < 2:
        raise ValueError(f"commanded path must be (m >= 2, 3) points (m), got shape {c.shape}")
    split = [split_poses(p, f"attained path {j}") for j, p in enumerate(attained)]
    if not split:
        raise ValueError("path accuracy needs at least one attained path")
    for j, (p, _) in enumerate(split):
        if p.ndim != 2 or len(p) < 2:
            raise ValueError(f"attained path {j} must be (k >= 2, 3) points (m), got shape {p.shape}")
    attained_R = [R for _, R in split if R is not None]  # all or none of them: frames or points
    t = _tangents(c)
    found = [_crossings(c, t, p, window) for p, _ in split]  # a loop over cycles, not points
    X = np.array([f[0] for f in found])  # (n, m, 3)
    n = len(split)
    with np.errstate(invalid="ignore"):
        count = np.sum(np.isfinite(X[..., 0]), axis=0)
        bary = np.nanmean(np.where(count[None, :, None] > 0, X, 0.0), axis=0)
        bary[count == 0] = np.nan
        at = np.linalg.norm(bary - c, axis=1)
        dist = np.linalg.norm(X - bary[None], axis=2)  # (n, m): l_ij
        l_mean = np.nanmean(np.where(count[None] > 0, dist, 0.0), axis=0)
        S = np.sqrt(np.nansum((dist - l_mean) ** 2, axis=0) / np.maximum(count - 1, 1))
    rt = np.where(count >= 2, l_mean + 3 * S, np.nan)
    at = np.where(count > 0, at, np.nan)
    if not np.any(np.isfinite(at)):
        raise ValueError("no attained path crosses the normal plane of any commanded point")
    RT = float(np.nanmax(rt)) if np.any(np.isfinite(rt)) else float("nan")
    AT_abc = RT_abc = None
    if R_c is not None and len(attained_R) == n:
        A = np.array(
            [_crossing_angles(R, f[1], f[2], R_c, angles) for R, f in zip(attained_R, found, strict=True)]
        )
        with np.errstate(invalid="ignore"), warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN columns: no crossing there
            a_mean = np.nanmean(A, axis=0)  # (m, 3)
            AT_abc = np.nanmax(np.abs(a_mean), axis=0)
            S_a = np.sqrt(np.nansum((A - a_mean) ** 2, axis=0) / np.maximum(count - 1, 1)[:, None])
            S_a[count < 2] = np.nan
            RT_abc = 3.0 * np.nanmax(S_a, axis=0) if n >= 2 else np.full(3, np.nan)
    return PathAccuracy(float(np.nanmax(at)), RT, at, rt, bary, X, n, AT_abc, RT_abc)
