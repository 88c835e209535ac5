"""ISO 9283 characteristics 8-14 of a log: paths, cornering, velocity, positioning time,
compliance and weaving."""

from __future__ import annotations

import itertools
import math
from collections import defaultdict
from typing import Any

import numpy as np
from numpy.typing import NDArray

import robocal.evaluate.iso9283.characteristics as iso
from robocal import spatial
from robocal.evaluate.iso9283.eval_pose import (
    NAMES,
    STILL,
    Characteristic,
    EvaluationOptions,
    cycles_text,
    deg,
    missing,
    mm,
    no_rows,
    pose_visits,
    spread,
    worst_detail,
)
from robocal.evaluate.iso9283.log import Iso9283Log, Run
from robocal.evaluate.metrics import path_accuracy

Array = NDArray[np.float64]


# ------------------------------------------------------------------ 8, 9 AT/RT
def _dedupe(points: Array) -> NDArray[np.int_]:
    keep = [0]
    for k in range(1, len(points)):
        if np.linalg.norm(points[k] - points[keep[-1]]) > STILL:
            keep.append(k)
    return np.array(keep)


def _paths(log: Iso9283Log, test: str) -> dict[str, list[Run]]:
    out: dict[str, list[Run]] = defaultdict(list)
    for r in log.runs(test):
        out[r.target].append(r)
    return dict(out)


def _path_samples(
    log: Iso9283Log, keep: NDArray[np.int_], runs: list[Run], with_angles: bool
) -> tuple[Array, list[Array]]:
    """The commanded samples ``keep`` and each run's attained ones: ``(k, 4, 4)`` frames (m)
    ``with_angles`` when the log holds measured and commanded orientations, else ``(k, 3)``
    positions (m), so that a log without commanded orientations still gives AT and RT."""
    R, R_c = log.rotation, log.commanded_rotation
    if with_angles and R is not None and R_c is not None:
        attained = [spatial.homogeneous(R[r.index], log.position[r.index]) for r in runs]
        return spatial.homogeneous(R_c[keep], log.commanded[keep]), attained
    return log.commanded[keep], [log.position[r.index] for r in runs]


def _path_rows(log: Iso9283Log, test: str, opts: EvaluationOptions) -> list[dict[str, Any]]:
    details: list[dict[str, Any]] = []
    for name, runs in _paths(log, test).items():
        first = runs[0].index
        keep = first[_dedupe(log.commanded[first])]
        if len(keep) < 5:
            continue
        keep = keep[
            np.unique(np.linspace(0, len(keep) - 1, min(opts.path_points, len(keep))).round().astype(int))
        ]
        keep = keep[1:-1]  # the end points: an attained path that stops short never crosses their planes
        commanded, attained = _path_samples(log, keep, runs, test == "reorientation")
        pa = path_accuracy(commanded, attained)
        details.append(
            {
                "path": name,
                "n": len(runs),
                "AT_mm": mm(pa.AT),
                "RT_mm": mm(pa.RT) if math.isfinite(pa.RT) else None,
                "AT_abc_deg": deg(pa.AT_abc),
                "RT_abc_deg": deg(pa.RT_abc),
            }
        )
    return details


def path(log: Iso9283Log, opts: EvaluationOptions) -> Characteristic:
    args = NAMES[8]
    if not log.runs("path"):
        return missing(*args, no_rows("path"))
    details = _path_rows(log, "path", opts)
    if not details:
        return missing(*args, "no path run has five or more distinct commanded points")
    at, ap = worst_detail(details, "AT_mm", "path")
    rt, rp = worst_detail(details, "RT_mm", "path")
    return Characteristic(
        *args,
        True,
        f"AT {at:.3f} mm ({ap}), {spread('RT', rt, rp)}; worst of {len(details)} paths",
        cycles_text([d["n"] for d in details], 10),
        details,
    )


def reorientation(log: Iso9283Log, opts: EvaluationOptions) -> Characteristic:
    args = NAMES[9]
    if not log.runs("reorientation"):
        return missing(*args, no_rows("reorientation"))
    if log.rotation is None or log.commanded_rotation is None:  # both: the deviations need them
        return missing(*args, "the log has no orientation columns (a_deg ... cmd_c_deg)")
    details = _path_rows(log, "reorientation", opts)
    if not details:
        return missing(*args, "no reorientation run has five or more distinct commanded points")
    d = details[0]
    at = ", ".join(f"{x:.3f}" for x in d["AT_abc_deg"])
    rt_abc = d["RT_abc_deg"]
    single = rt_abc is None or not all(map(math.isfinite, rt_abc))  # NaN: a single cycle
    rt = "not measured (a single cycle)" if single else ", ".join(f"{x:.3f}" for x in rt_abc) + " deg"
    summary = f"AT_abc {at} deg, RT_abc {rt}; AT {d['AT_mm']:.3f} mm ({d['path']})"
    return Characteristic(*args, True, summary, cycles_text([x["n"] for x in details], 10), details)


# ------------------------------------------------------------------ 10 cornering
def _corners(points: Array, angle_deg: float) -> list[tuple[Array, Array, Array, float]]:
    """Corners ``(point, d_in, d_out, length_out)`` of a sampled commanded polyline: the
    intersections of consecutive straight stretches (>= 3 segments of one direction)
    whose directions differ by more than ``angle_deg``."""
    seg = np.diff(points, axis=0)
    L = np.linalg.norm(seg, axis=1)
    d = seg / L[:, None]
    runs: list[tuple[int, int]] = []  # segment index ranges [a, b)
    a = 0
    for k in range(1, len(d) + 1):
        if k == len(d) or d[k] @ d[a] < math.cos(math.radians(0.5)):
            if k - a >= 3:
                runs.append((a, k))
            a = k
    out = []
    for (a1, b1), (a2, b2) in itertools.pairwise(runs):
        d1 = points[b1] - points[a1]
        d1 /= np.linalg.norm(d1)
        d2 = points[b2] - points[a2]
        d2 /= np.linalg.norm(d2)
        if d1 @ d2 > math.cos(math.radians(angle_deg)):
            continue
        # closest point between line 1 (through points[b1]) and line 2 (through points[a2])
        p1, p2 = points[b1], points[a2]
        A = np.array([[d1 @ d1, -d1 @ d2], [d1 @ d2, -d2 @ d2]])
        s, u = np.linalg.solve(A, [(p2 - p1) @ d1, (p2 - p1) @ d2])
        corner = 0.5 * (p1 + s * d1 + p2 + u * d2)
        out.append((corner, d1, d2, float(np.linalg.norm(points[b2] - corner))))
    return out


def cornering(log: Iso9283Log, opts: EvaluationOptions) -> Characteristic:
    args = NAMES[10]
    paths = _paths(log, "cornering")
    if not paths:
        return missing(*args, no_rows("cornering"))
    details: list[dict[str, Any]] = []
    counts: list[int] = []
    for name, runs in paths.items():
        first = runs[0].index
        pts = log.commanded[first[_dedupe(log.commanded[first])]]
        for k, (corner, d1, d2, length) in enumerate(_corners(pts, opts.corner_angle_deg)):
            c = iso.cornering(corner, d1, d2, length, [log.position[r.index] for r in runs])
            counts.append(len(runs))
            details.append(
                {
                    "corner": f"{name} #{k + 1}",
                    "point_mm": [mm(x) for x in corner],
                    "CR_mm": mm(c.CR.mean()),
                    "CO_mm": mm(c.CO.mean()),
                    "CR_max_mm": mm(c.CR.max()),
                    "CO_max_mm": mm(c.CO.max()),
                    "n": len(runs),
                }
            )
    if not details:
        return missing(
            *args, f"no corner (a turn of more than {opts.corner_angle_deg:g} deg between straight stretches)"
        )
    cr, cp = worst_detail(details, "CR_mm", "corner")
    co, op = worst_detail(details, "CO_mm", "corner")
    return Characteristic(
        *args,
        True,
        f"CR {cr:.3f} mm ({cp}), CO {co:.3f} mm ({op}); mean of cycles, worst corner",
        cycles_text(counts, 3),
        details,
    )


# ------------------------------------------------------------------ 11 velocity
def velocity(log: Iso9283Log, opts: EvaluationOptions) -> Characteristic:
    args = NAMES[11]
    paths = _paths(log, "velocity")
    if not paths:
        return missing(*args, no_rows("velocity"))
    details: list[dict[str, Any]] = []
    for name, runs in paths.items():
        speeds, v_cmd = [], []
        for r in runs:
            t = log.time[r.index]
            if len(t) < 3:
                continue
            vc = iso.path_speeds(t, log.commanded[r.index], opts.speed_window_s)
            plateau = vc >= opts.plateau * np.nanmax(vc)
            speeds.append(iso.path_speeds(t, log.position[r.index], opts.speed_window_s)[plateau])
            v_cmd.append(vc[plateau])
        if len(speeds) < 2:
            continue
        pv = iso.path_velocity(speeds, float(np.mean(np.concatenate(v_cmd))))
        details.append(
            {
                "path": name,
                "n": len(speeds),
                "v_c_mm_s": mm(pv.v_c),
                "AV_percent": pv.AV,
                "RV_mm_s": mm(pv.RV),
                "RV_percent": pv.RV_percent,
                "FV_mm_s": mm(pv.FV),
            }
        )
    if not details:
        return missing(*args, "velocity needs >= 2 cycles with a time record of the path")
    d = details[0]
    summary = (
        f"AV {d['AV_percent']:+.2f} %, RV {d['RV_mm_s']:.2f} mm/s ({d['RV_percent']:.2f} %), "
        f"FV {d['FV_mm_s']:.2f} mm/s at {d['v_c_mm_s']:.0f} mm/s ({d['path']})"
    )
    return Characteristic(*args, True, summary, cycles_text([x["n"] for x in details], 10), details)


# ------------------------------------------------------------------ 12 positioning time
def positioning(log: Iso9283Log, opts: EvaluationOptions, band: float) -> Characteristic:
    args = NAMES[12]
    visits = pose_visits(log, "positioning", opts)
    if not visits:
        return missing(*args, no_rows("positioning"))
    by_distance: dict[float, list[float]] = defaultdict(list)
    for v in visits:
        idx = v.run.index
        cmd = log.commanded[idx]
        moving = np.flatnonzero(np.linalg.norm(cmd - cmd[0], axis=1) > STILL)
        if len(moving) == 0 or len(idx) < 3:
            continue
        start = float(log.time[idx[max(int(moving[0]) - 1, 0)]])
        tp = iso.positioning_time(log.time[idx], log.position[idx], start, band, v.attained)
        if math.isfinite(tp):
            by_distance[round(mm(np.linalg.norm(cmd[-1] - cmd[0])), 1)].append(tp)
    if not by_distance:
        return missing(*args, "no positioning run holds a time record of a move that settles")
    details: list[dict[str, Any]] = [
        {"distance_mm": d, "n": len(ts), "time_s": float(np.mean(ts))}
        for d, ts in sorted(by_distance.items())
    ]
    text = ", ".join(f"{d['distance_mm']:g} mm {d['time_s']:.3f} s" for d in details)
    return Characteristic(
        *args, True, f"{text}; band {band * 1e3:g} mm", cycles_text([d["n"] for d in details], 3), details
    )


# ------------------------------------------------------------------ 13 compliance
def compliance(log: Iso9283Log) -> Characteristic:
    args = NAMES[13]
    idx = np.flatnonzero(log.test == "compliance")
    if len(idx) == 0:
        return missing(*args, no_rows("compliance"))
    if log.force is None:
        return missing(*args, "the log has no load columns (fx_N, fy_N, fz_N)")
    F, disp, counts = [], [], []
    for c in np.unique(log.cycle[idx]):
        rows = idx[log.cycle[idx] == c]
        zero = rows[np.linalg.norm(log.force[rows], axis=1) == 0]
        loaded = rows[np.linalg.norm(log.force[rows], axis=1) > 0]
        if len(zero) == 0 or len(loaded) == 0:
            continue
        F.append(log.force[loaded])
        disp.append(log.position[loaded] - log.position[zero].mean(axis=0))
        counts.append(int(c))
    if not F:
        return missing(*args, "no cycle has both an unloaded and a loaded measurement")
    try:
        sc = iso.static_compliance(np.vstack(F), np.vstack(disp))
    except ValueError as err:
        return missing(*args, str(err))
    details: list[dict[str, Any]] = [
        {"direction": d, "compliance_mm_per_N": mm(c), "max_load_N": float(loads.max())}
        for d, c, loads in zip(sc.directions, sc.compliance, sc.loads, strict=True)
    ]
    worst, wd = worst_detail(details, "compliance_mm_per_N", "direction")
    text = ", ".join(f"{d['direction']} {d['compliance_mm_per_N']:.5f}" for d in details)
    return Characteristic(
        *args, True, f"{text} mm/N (largest {worst:.5f}, {wd})", f"{len(counts)} (ISO 3)", details
    )


# ------------------------------------------------------------------ 14 weaving
def weaving(log: Iso9283Log) -> Characteristic:
    args = NAMES[14]
    paths = _paths(log, "weaving")
    if not paths:
        return missing(*args, no_rows("weaving"))
    details: list[dict[str, Any]] = []
    for name, runs in paths.items():
        ws = []
        for r in runs:
            if len(r.index) < 16:
                continue
            ws.append(iso.weaving(log.time[r.index], log.commanded[r.index], log.position[r.index]))
        if ws:
            details.append(
                {
                    "path": name,
                    "n": len(ws),
                    "WS_percent": float(np.mean([w.WS for w in ws])),
                    "WF_percent": float(np.mean([w.WF for w in ws])),
                    "stroke_c_mm": mm(ws[0].stroke_c),
                    "frequency_c_Hz": ws[0].frequency_c,
                }
            )
    if not details:
        return missing(*args, "no weaving run holds a time record (>= 16 samples)")
    d = details[0]
    summary = (
        f"WS {d['WS_percent']:+.2f} %, WF {d['WF_percent']:+.2f} % "
        f"(stroke {d['stroke_c_mm']:.2f} mm at {d['frequency_c_Hz']:.2f} Hz, {d['path']})"
    )
    return Characteristic(*args, True, summary, cycles_text([x["n"] for x in details], 3), details)
