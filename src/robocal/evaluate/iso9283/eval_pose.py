"""ISO 9283 characteristics 1-7 of a log (the pose tests).

Also what the path tests (:mod:`robocal.evaluate.iso9283.eval_path`) share: the options, the
result row and the dwell visits.
"""

from __future__ import annotations

import math
from collections import defaultdict
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation

import robocal.evaluate.iso9283.characteristics as iso
from robocal import spatial
from robocal.evaluate.iso9283.log import Iso9283Log, Run
from robocal.evaluate.metrics import pose_accuracy, pose_repeatability

Array = NDArray[np.float64]


STILL = 1e-6  # m: the commanded position counts as unchanged within this


@dataclass(frozen=True)
class EvaluationOptions:
    """Choices the standard leaves open (``docs/iso9283.md``).

    Attributes:
        band: limit band of the stabilisation time, overshoot and positioning time (m);
            None: the log's ``limit_band_mm`` condition, else 0.1 mm.
        tail_s: the attained pose is the mean over this last part of a dwell (s).
        speed_window_s: window of the speed estimate (s), :func:`iso9283.path_speeds`.
        plateau: the constant-speed part of a path is where the commanded speed is at
            least this fraction of its largest.
        path_points: the commanded path is thinned to at most this many points for AT/RT.
        corner_angle_deg: a change of direction larger than this is a corner.
    """

    band: float | None = None
    tail_s: float = 0.1
    speed_window_s: float = 0.05
    plateau: float = 0.998
    path_points: int = 200
    corner_angle_deg: float = 20.0


@dataclass(frozen=True)
class Characteristic:
    """One row of the table: a characteristic, its clause and result (mm, deg, s).

    Attributes:
        number: 1..14 as in seed 001 Table 1.
        name, clause, symbols: as in the standard.
        measured: whether the log supports it.
        summary: the result in one line (or why it is not measured).
        cycles: cycles used (per pose or path, the smallest), and the standard's number.
        details: per pose / path / direction values (JSON-ready, mm, deg, s, %).
    """

    number: int
    name: str
    clause: str
    symbols: str
    measured: bool
    summary: str
    cycles: str = ""
    details: list[dict[str, Any]] = field(default_factory=list)


#: number -> (number, name, clause, symbols), as the rows below spell them
NAMES: dict[int, tuple[int, str, str, str]] = {
    1: (1, "pose accuracy and repeatability", "7.2.1, 7.2.2", "AP, RP"),
    2: (2, "multi-directional pose accuracy variation", "7.2.3", "vAP"),
    3: (3, "distance accuracy and repeatability", "7.3", "AD, RD"),
    4: (4, "pose stabilisation time", "7.4", "t"),
    5: (5, "pose overshoot", "7.5", "OV"),
    6: (6, "drift of pose characteristics", "7.6", "dAP, dRP"),
    7: (7, "exchangeability", "7.7", "E"),
    8: (8, "path accuracy and repeatability", "8.2, 8.3", "AT, RT"),
    9: (9, "path accuracy on reorientation", "8.4", "AT_a,b,c, RT_a,b,c"),
    10: (10, "cornering deviations", "8.5", "CR, CO"),
    11: (11, "path velocity characteristics", "8.6", "AV, RV, FV"),
    12: (12, "minimum positioning time", "9", "t_p"),
    13: (13, "static compliance", "10", "mm/N"),
    14: (14, "weaving deviations", "11", "WS, WF"),
}


# ------------------------------------------------------------------ visits
@dataclass(frozen=True)
class _Visit:
    run: Run
    dwell: int  # index into run.index where the dwell starts
    attained: Array  # (3,) m
    attained_rot: Array | None
    commanded: Array  # (3,)
    commanded_rot: Array | None

    def frame(self, commanded: bool = False) -> Array:
        p, R = (self.commanded, self.commanded_rot) if commanded else (self.attained, self.attained_rot)
        return p if R is None else spatial.homogeneous(R, p)


def _visit(log: Iso9283Log, run: Run, tail_s: float) -> _Visit:
    idx = run.index
    cmd = log.commanded[idx]
    moved = np.linalg.norm(cmd - cmd[-1], axis=1) > STILL
    dwell = 0 if not moved.any() else int(np.flatnonzero(moved)[-1]) + 1
    t = log.time[idx]
    tail = idx[(np.arange(len(idx)) >= dwell) & (t >= t[-1] - tail_s)]
    p = log.position[tail].mean(axis=0)
    R = Rc = None
    if log.rotation is not None and log.commanded_rotation is not None:
        R = Rotation.from_matrix(log.rotation[tail]).mean().as_matrix()
        Rc = log.commanded_rotation[idx[-1]]
    return _Visit(run, dwell, p, R, cmd[-1], Rc)


def pose_visits(log: Iso9283Log, test: str, opts: EvaluationOptions) -> list[_Visit]:
    return [_visit(log, r, opts.tail_s) for r in log.runs(test)]


def _by(visits: list[_Visit], key: Callable[[_Visit], str]) -> dict[str, list[_Visit]]:
    out: dict[str, list[_Visit]] = defaultdict(list)
    for v in visits:
        out[key(v)].append(v)
    return dict(out)


def mm(v: float | np.floating) -> float:
    return float(v) * 1e3


def deg(a: Array | None) -> list[float] | None:
    return None if a is None else [float(x) for x in np.degrees(a)]


def worst_detail(details: list[dict[str, Any]], key: str, label: str) -> tuple[float, str]:
    vals = [(d[key], d[label]) for d in details if d.get(key) is not None and math.isfinite(d[key])]
    if not vals:
        return float("nan"), "-"
    return max(vals, key=lambda x: abs(x[0]))


def spread(symbol: str, value: float, where: str) -> str:
    """``"RP 0.012 mm (P1)"``; a repeatability no pose or path supports (every one visited
    once: no spread to measure) says so instead of printing NaN."""
    if math.isfinite(value):
        return f"{symbol} {value:.3f} mm ({where})"
    return f"{symbol} not measured (a single cycle: a repeatability needs >= 2)"


def cycles_text(counts: list[int], iso_cycles: int) -> str:
    return f"{min(counts) if counts else 0} (ISO {iso_cycles})"


def missing(number: int, name: str, clause: str, symbols: str, reason: str) -> Characteristic:
    return Characteristic(number, name, clause, symbols, False, f"not measured: {reason}")


def no_rows(test: str) -> str:
    return f"the log has no rows with test={test}"


# ------------------------------------------------------------------ 1 AP/RP
def pose_characteristic(log: Iso9283Log, visits: list[_Visit]) -> Characteristic:
    args = NAMES[1]
    if not visits:
        return missing(*args, no_rows("pose"))
    details: list[dict[str, Any]] = []
    for target, vs in _by(visits, lambda v: v.run.target).items():
        att = np.array([v.frame() for v in vs])
        acc = pose_accuracy(att, vs[0].frame(commanded=True))
        row: dict[str, Any] = {
            "pose": target,
            "n": len(vs),
            "AP_mm": mm(acc.AP),
            "AP_xyz_mm": [mm(x) for x in acc.AP_xyz],
            "AP_abc_deg": deg(acc.AP_abc),
        }
        if len(vs) >= 2:
            rep = pose_repeatability(att)
            row.update(RP_mm=mm(rep.RP), RP_abc_deg=deg(rep.RP_abc))
        else:
            row.update(RP_mm=None, RP_abc_deg=None)
        details.append(row)
    ap, ap_pose = worst_detail(details, "AP_mm", "pose")
    rp, rp_pose = worst_detail(details, "RP_mm", "pose")
    summary = f"AP {ap:.3f} mm ({ap_pose}), {spread('RP', rp, rp_pose)}; worst of {len(details)} poses"
    return Characteristic(*args, True, summary, cycles_text([d["n"] for d in details], 30), details)


# ------------------------------------------------------------------ 2 vAP
def multidirectional(log: Iso9283Log, opts: EvaluationOptions) -> Characteristic:
    args = NAMES[2]
    visits = pose_visits(log, "multidirectional", opts)
    if not visits:
        return missing(*args, no_rows("multidirectional"))
    details: list[dict[str, Any]] = []
    counts: list[int] = []
    for target, vs in _by(visits, lambda v: v.run.target).items():
        groups = _by(vs, lambda v: v.run.group)
        if len(groups) < 2:
            continue
        names = list(groups)
        mv = iso.multidirectional_variation([np.array([v.frame() for v in groups[g]]) for g in names])
        counts += [len(groups[g]) for g in names]
        details.append(
            {
                "pose": target,
                "directions": names,
                "vAP_mm": mm(mv.vAP),
                "vAP_abc_deg": deg(mv.vAP_abc),
                "pair": [names[mv.pair[0]], names[mv.pair[1]]],
            }
        )
    if not details:
        return missing(*args, "every pose is approached from one direction only (the group column)")
    v, pose = worst_detail(details, "vAP_mm", "pose")
    return Characteristic(
        *args,
        True,
        f"vAP {v:.3f} mm ({pose}); worst of {len(details)} poses",
        cycles_text(counts, 30),
        details,
    )


# ------------------------------------------------------------------ 3 AD/RD
def distance(log: Iso9283Log, opts: EvaluationOptions) -> Characteristic:
    args = NAMES[3]
    visits = pose_visits(log, "distance", opts)
    if not visits:
        return missing(*args, no_rows("distance"))
    targets = list(dict.fromkeys(v.run.target for v in visits))
    if len(targets) != 2:
        return missing(*args, f"the distance test needs exactly two targets, the log has {len(targets)}")
    last = {(v.run.cycle, v.run.target): v for v in visits}
    cycles = sorted({c for c, _ in last if (c, targets[0]) in last and (c, targets[1]) in last})
    if len(cycles) < 2:
        return missing(*args, "fewer than two cycles visit both targets")
    v1 = [last[(c, targets[0])] for c in cycles]
    v2 = [last[(c, targets[1])] for c in cycles]
    d = iso.distance_characteristics(
        np.array([v.frame() for v in v1]),
        np.array([v.frame() for v in v2]),
        v1[0].frame(commanded=True),
        v2[0].frame(commanded=True),
    )
    details: list[dict[str, Any]] = [
        {
            "poses": targets,
            "n": d.n,
            "D_c_mm": mm(d.D_c),
            "AD_mm": mm(d.AD),
            "AD_xyz_mm": [mm(x) for x in d.AD_xyz],
            "RD_mm": mm(d.RD),
            "RD_xyz_mm": [mm(x) for x in d.RD_xyz],
            "AD_abc_deg": deg(d.AD_abc),
            "RD_abc_deg": deg(d.RD_abc),
        }
    ]
    summary = (
        f"AD {mm(d.AD):+.3f} mm, RD {mm(d.RD):.3f} mm over {mm(d.D_c):.1f} mm ({targets[0]}-{targets[1]})"
    )
    return Characteristic(*args, True, summary, cycles_text([d.n], 30), details)


# ------------------------------------------------------------------ 4, 5 stabilisation, overshoot
def stabilisation_rows(
    log: Iso9283Log, visits: list[_Visit], band: float
) -> tuple[Characteristic, Characteristic]:
    a4 = NAMES[4]
    a5 = NAMES[5]
    if not visits:
        return missing(*a4, no_rows("pose")), missing(*a5, no_rows("pose"))
    details: list[dict[str, Any]] = []
    for target, vs in _by(visits, lambda v: v.run.target).items():
        times, overs, unsettled = [], [], 0
        for v in vs:
            idx = v.run.index
            if len(idx) < 3 or v.dwell == 0:
                continue  # a static sample, or no record of the approach
            s = iso.stabilisation(
                log.time[idx], log.position[idx], float(log.time[idx[v.dwell]]), band, v.attained
            )
            if not s.settled:
                unsettled += 1
                continue
            times.append(s.time)
            overs.append(s.overshoot)
        if times:
            details.append(
                {
                    "pose": target,
                    "n": len(times),
                    "time_s": float(np.mean(times)),
                    "time_max_s": float(np.max(times)),
                    "overshoot_mm": mm(np.mean(overs)),
                    "overshoot_max_mm": mm(np.max(overs)),
                    "unsettled": unsettled,
                }
            )
    if not details:
        reason = (
            "no pose run holds a time record of its approach (single samples, or the command never moves)"
        )
        return missing(*a4, reason), missing(*a5, reason)
    counts = [d["n"] for d in details]
    t, tp = worst_detail(details, "time_s", "pose")
    o, op = worst_detail(details, "overshoot_mm", "pose")
    band_text = f"band {band * 1e3:g} mm"
    return (
        Characteristic(
            *a4,
            True,
            f"{t:.3f} s ({tp}), mean of cycles, worst pose; {band_text}",
            cycles_text(counts, 3),
            details,
        ),
        Characteristic(
            *a5,
            True,
            f"{o:.3f} mm ({op}), mean of cycles, worst pose; {band_text}",
            cycles_text(counts, 3),
            details,
        ),
    )


# ------------------------------------------------------------------ 6 drift
def drift(log: Iso9283Log, opts: EvaluationOptions) -> Characteristic:
    args = NAMES[6]
    visits = pose_visits(log, "drift", opts)
    if not visits:
        return missing(*args, no_rows("drift"))
    details: list[dict[str, Any]] = []
    for target, vs in _by(visits, lambda v: v.run.target).items():
        blocks = _by(vs, lambda v: v.run.group)
        order = sorted(blocks, key=lambda g: log.time[blocks[g][0].run.index[0]])
        if len(order) < 2 or any(len(blocks[g]) < 2 for g in order):
            continue
        d = iso.drift([np.array([v.attained for v in blocks[g]]) for g in order], vs[0].commanded)
        t0 = log.time[blocks[order[0]][0].run.index[0]]
        t1 = log.time[blocks[order[-1]][-1].run.index[-1]]
        details.append(
            {
                "pose": target,
                "blocks": order,
                "hours": float((t1 - t0) / 3600.0),
                "dAP_mm": mm(d.dAP),
                "dRP_mm": mm(d.dRP),
                "AP_mm": [mm(x) for x in d.AP],
                "RP_mm": [mm(x) for x in d.RP],
            }
        )
    if not details:
        return missing(*args, "drift needs >= 2 measurement blocks (the group column) of >= 2 cycles each")
    a, ap = worst_detail(details, "dAP_mm", "pose")
    r, rp = worst_detail(details, "dRP_mm", "pose")
    hours = min(d["hours"] for d in details)
    return Characteristic(
        *args,
        True,
        f"dAP {a:.3f} mm ({ap}), dRP {r:.3f} mm ({rp}) over {hours:.2f} h",
        f"{hours:.2f} h (ISO 8 h)",
        details,
    )


# ------------------------------------------------------------------ 7 exchangeability
def exchangeability(log: Iso9283Log, opts: EvaluationOptions) -> Characteristic:
    args = NAMES[7]
    visits = pose_visits(log, "exchangeability", opts)
    if not visits:
        return missing(*args, no_rows("exchangeability"))
    details: list[dict[str, Any]] = []
    counts: list[int] = []
    for target, vs in _by(visits, lambda v: v.run.target).items():
        robots = _by(vs, lambda v: v.run.group)
        if len(robots) < 2:
            continue
        names = list(robots)
        e = iso.exchangeability([np.array([v.attained for v in robots[g]]) for g in names])
        counts += [len(robots[g]) for g in names]
        details.append(
            {"pose": target, "robots": names, "E_mm": mm(e.E), "pair": [names[e.pair[0]], names[e.pair[1]]]}
        )
    if not details:
        return missing(*args, "exchangeability needs >= 2 robots (the group column) at a pose")
    worst, pose = worst_detail(details, "E_mm", "pose")
    return Characteristic(
        *args,
        True,
        f"E {worst:.3f} mm ({pose}); worst of {len(details)} poses",
        cycles_text(counts, 30),
        details,
    )
