"""The fourteen ISO 9283 characteristics of a measurement log, as a table and a report.

:func:`evaluate_log` cuts an :class:`~robocal.evaluate.iso9283_log.Iso9283Log` into runs
(one approach to a pose, one traversal of a path), takes the attained pose of every
approach and hands the arrays to :mod:`robocal.evaluate.iso9283` and
:mod:`robocal.evaluate.metrics`.  Every characteristic the log cannot support is listed as
"not measured" with the reason.  :func:`results_html` renders a small self-contained page.

Reading of the log (``docs/iso9283.md``):

* the *attained pose* of a run is the mean of its samples in the last ``tail_s`` seconds
  of its *dwell*, the final stretch in which the commanded pose no longer changes (a
  single-sample run: that sample);
* the "attained pose" signal of §7.4 is taken as the first sample of the dwell;
* the commanded path of a path test is the commanded positions of its first cycle,
  thinned to ``path_points`` and without its two end points.
"""

from __future__ import annotations

import html
import itertools
import math
from collections import defaultdict
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation

from robocal import spatial
from robocal.evaluate import iso9283 as iso
from robocal.evaluate.iso9283_log import Iso9283Log, Run
from robocal.evaluate.metrics import path_accuracy, pose_accuracy, pose_repeatability

__all__ = [
    "Characteristic",
    "EvaluationOptions",
    "Iso9283Results",
    "evaluate_log",
    "results_html",
    "results_text",
]

Array = NDArray[np.float64]
_STILL = 1e-6  # m: the commanded position counts as unchanged within this


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


@dataclass(frozen=True)
class Iso9283Results:
    """The fourteen characteristics of one log."""

    source: str
    conditions: dict[str, str]
    band: float
    rows: tuple[Characteristic, ...]

    def to_dict(self) -> dict[str, Any]:
        """Plain data (mm, deg, s, %); a value that could not be computed is None."""
        return _finite(
            {
                "source": self.source,
                "conditions": dict(self.conditions),
                "limit_band_mm": self.band * 1e3,
                "characteristics": [
                    {
                        "number": r.number,
                        "name": r.name,
                        "clause": r.clause,
                        "symbols": r.symbols,
                        "measured": r.measured,
                        "summary": r.summary,
                        "cycles": r.cycles,
                        "details": r.details,
                    }
                    for r in self.rows
                ],
            }
        )


def _finite(value: Any) -> Any:
    """``value`` with every non-finite float replaced by None (valid JSON)."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {k: _finite(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_finite(v) for v in value]
    return value


#: number -> (number, name, clause, symbols), as the rows below spell them
_NAMES: dict[int, tuple[int, str, str, str]] = {
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
    moved = np.linalg.norm(cmd - cmd[-1], axis=1) > _STILL
    dwell = 0 if not moved.any() else int(np.flatnonzero(moved)[-1]) + 1
    t = log.time[idx]
    tail = idx[(np.arange(len(idx)) >= dwell) & (t >= t[-1] - tail_s)]
    p = log.position[tail].mean(axis=0)
    R = Rc = None
    if log.rotation is not None and log.commanded_rotation is not None:
        R = Rotation.from_matrix(log.rotation[tail]).mean().as_matrix()
        Rc = log.commanded_rotation[idx[-1]]
    return _Visit(run, dwell, p, R, cmd[-1], Rc)


def _visits(log: Iso9283Log, test: str, opts: EvaluationOptions) -> list[_Visit]:
    return [_visit(log, r, opts.tail_s) for r in log.runs(test)]


def _by(visits: list[_Visit], key: Callable[[_Visit], str]) -> dict[str, list[_Visit]]:
    out: dict[str, list[_Visit]] = defaultdict(list)
    for v in visits:
        out[key(v)].append(v)
    return dict(out)


def _mm(v: float) -> float:
    return float(v) * 1e3


def _deg(a: Array | None) -> list[float] | None:
    return None if a is None else [float(x) for x in np.degrees(a)]


def _worst(details: list[dict[str, Any]], key: str, label: str) -> tuple[float, str]:
    vals = [(d[key], d[label]) for d in details if d.get(key) is not None and math.isfinite(d[key])]
    if not vals:
        return float("nan"), "-"
    return max(vals, key=lambda x: abs(x[0]))


def _cycles(counts: list[int], iso_cycles: int) -> str:
    return f"{min(counts) if counts else 0} (ISO {iso_cycles})"


def _missing(number: int, name: str, clause: str, symbols: str, reason: str) -> Characteristic:
    return Characteristic(number, name, clause, symbols, False, f"not measured: {reason}")


def _no_rows(test: str) -> str:
    return f"the log has no rows with test={test}"


# ------------------------------------------------------------------ 1 AP/RP
def _pose(log: Iso9283Log, visits: list[_Visit]) -> Characteristic:
    args = _NAMES[1]
    if not visits:
        return _missing(*args, _no_rows("pose"))
    details = []
    for target, vs in _by(visits, lambda v: v.run.target).items():
        att = np.array([v.frame() for v in vs])
        acc = pose_accuracy(att, vs[0].frame(commanded=True))
        row: dict[str, Any] = {
            "pose": target,
            "n": len(vs),
            "AP_mm": _mm(acc.AP),
            "AP_xyz_mm": [_mm(x) for x in acc.AP_xyz],
            "AP_abc_deg": _deg(acc.AP_abc),
        }
        if len(vs) >= 2:
            rep = pose_repeatability(att)
            row.update(RP_mm=_mm(rep.RP), RP_abc_deg=_deg(rep.RP_abc))
        else:
            row.update(RP_mm=None, RP_abc_deg=None)
        details.append(row)
    ap, ap_pose = _worst(details, "AP_mm", "pose")
    rp, rp_pose = _worst(details, "RP_mm", "pose")
    summary = f"AP {ap:.3f} mm ({ap_pose}), RP {rp:.3f} mm ({rp_pose}); worst of {len(details)} poses"
    return Characteristic(*args, True, summary, _cycles([d["n"] for d in details], 30), details)


# ------------------------------------------------------------------ 2 vAP
def _multidirectional(log: Iso9283Log, opts: EvaluationOptions) -> Characteristic:
    args = _NAMES[2]
    visits = _visits(log, "multidirectional", opts)
    if not visits:
        return _missing(*args, _no_rows("multidirectional"))
    details, counts = [], []
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
                "vAP_mm": _mm(mv.vAP),
                "vAP_abc_deg": _deg(mv.vAP_abc),
                "pair": [names[mv.pair[0]], names[mv.pair[1]]],
            }
        )
    if not details:
        return _missing(*args, "every pose is approached from one direction only (the group column)")
    v, pose = _worst(details, "vAP_mm", "pose")
    return Characteristic(
        *args, True, f"vAP {v:.3f} mm ({pose}); worst of {len(details)} poses", _cycles(counts, 30), details
    )


# ------------------------------------------------------------------ 3 AD/RD
def _distance(log: Iso9283Log, opts: EvaluationOptions) -> Characteristic:
    args = _NAMES[3]
    visits = _visits(log, "distance", opts)
    if not visits:
        return _missing(*args, _no_rows("distance"))
    targets = list(dict.fromkeys(v.run.target for v in visits))
    if len(targets) != 2:
        return _missing(*args, f"the distance test needs exactly two targets, the log has {len(targets)}")
    last = {(v.run.cycle, v.run.target): v for v in visits}
    cycles = sorted({c for c, _ in last if (c, targets[0]) in last and (c, targets[1]) in last})
    if len(cycles) < 2:
        return _missing(*args, "fewer than two cycles visit both targets")
    v1 = [last[(c, targets[0])] for c in cycles]
    v2 = [last[(c, targets[1])] for c in cycles]
    d = iso.distance_characteristics(
        np.array([v.frame() for v in v1]),
        np.array([v.frame() for v in v2]),
        v1[0].frame(commanded=True),
        v2[0].frame(commanded=True),
    )
    details = [
        {
            "poses": targets,
            "n": d.n,
            "D_c_mm": _mm(d.D_c),
            "AD_mm": _mm(d.AD),
            "AD_xyz_mm": [_mm(x) for x in d.AD_xyz],
            "RD_mm": _mm(d.RD),
            "RD_xyz_mm": [_mm(x) for x in d.RD_xyz],
            "AD_abc_deg": _deg(d.AD_abc),
            "RD_abc_deg": _deg(d.RD_abc),
        }
    ]
    summary = (
        f"AD {_mm(d.AD):+.3f} mm, RD {_mm(d.RD):.3f} mm over {_mm(d.D_c):.1f} mm ({targets[0]}-{targets[1]})"
    )
    return Characteristic(*args, True, summary, _cycles([d.n], 30), details)


# ------------------------------------------------------------------ 4, 5 stabilisation, overshoot
def _stabilisation_rows(
    log: Iso9283Log, visits: list[_Visit], band: float
) -> tuple[Characteristic, Characteristic]:
    a4 = _NAMES[4]
    a5 = _NAMES[5]
    if not visits:
        return _missing(*a4, _no_rows("pose")), _missing(*a5, _no_rows("pose"))
    details = []
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
                    "overshoot_mm": _mm(np.mean(overs)),
                    "overshoot_max_mm": _mm(np.max(overs)),
                    "unsettled": unsettled,
                }
            )
    if not details:
        reason = (
            "no pose run holds a time record of its approach (single samples, or the command never moves)"
        )
        return _missing(*a4, reason), _missing(*a5, reason)
    counts = [d["n"] for d in details]
    t, tp = _worst(details, "time_s", "pose")
    o, op = _worst(details, "overshoot_mm", "pose")
    band_text = f"band {band * 1e3:g} mm"
    return (
        Characteristic(
            *a4,
            True,
            f"{t:.3f} s ({tp}), mean of cycles, worst pose; {band_text}",
            _cycles(counts, 3),
            details,
        ),
        Characteristic(
            *a5,
            True,
            f"{o:.3f} mm ({op}), mean of cycles, worst pose; {band_text}",
            _cycles(counts, 3),
            details,
        ),
    )


# ------------------------------------------------------------------ 6 drift
def _drift(log: Iso9283Log, opts: EvaluationOptions) -> Characteristic:
    args = _NAMES[6]
    visits = _visits(log, "drift", opts)
    if not visits:
        return _missing(*args, _no_rows("drift"))
    details = []
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
                "dAP_mm": _mm(d.dAP),
                "dRP_mm": _mm(d.dRP),
                "AP_mm": [_mm(x) for x in d.AP],
                "RP_mm": [_mm(x) for x in d.RP],
            }
        )
    if not details:
        return _missing(*args, "drift needs >= 2 measurement blocks (the group column) of >= 2 cycles each")
    a, ap = _worst(details, "dAP_mm", "pose")
    r, rp = _worst(details, "dRP_mm", "pose")
    hours = min(d["hours"] for d in details)
    return Characteristic(
        *args,
        True,
        f"dAP {a:.3f} mm ({ap}), dRP {r:.3f} mm ({rp}) over {hours:.2f} h",
        f"{hours:.2f} h (ISO 8 h)",
        details,
    )


# ------------------------------------------------------------------ 7 exchangeability
def _exchangeability(log: Iso9283Log, opts: EvaluationOptions) -> Characteristic:
    args = _NAMES[7]
    visits = _visits(log, "exchangeability", opts)
    if not visits:
        return _missing(*args, _no_rows("exchangeability"))
    details, counts = [], []
    for target, vs in _by(visits, lambda v: v.run.target).items():
        robots = _by(vs, lambda v: v.run.group)
        if len(robots) < 2:
            continue
        names = list(robots)
        e = iso.exchangeability([np.array([v.attained for v in robots[g]]) for g in names])
        counts += [len(robots[g]) for g in names]
        details.append(
            {"pose": target, "robots": names, "E_mm": _mm(e.E), "pair": [names[e.pair[0]], names[e.pair[1]]]}
        )
    if not details:
        return _missing(*args, "exchangeability needs >= 2 robots (the group column) at a pose")
    e, pose = _worst(details, "E_mm", "pose")
    return Characteristic(
        *args, True, f"E {e:.3f} mm ({pose}); worst of {len(details)} poses", _cycles(counts, 30), details
    )


# ------------------------------------------------------------------ 8, 9 AT/RT
def _dedupe(points: Array) -> NDArray[np.int_]:
    keep = [0]
    for k in range(1, len(points)):
        if np.linalg.norm(points[k] - points[keep[-1]]) > _STILL:
            keep.append(k)
    return np.array(keep)


def _paths(log: Iso9283Log, test: str) -> dict[str, list[Run]]:
    out: dict[str, list[Run]] = defaultdict(list)
    for r in log.runs(test):
        out[r.target].append(r)
    return dict(out)


def _path_rows(log: Iso9283Log, test: str, opts: EvaluationOptions) -> list[dict[str, Any]]:
    details = []
    for name, runs in _paths(log, test).items():
        first = runs[0].index
        keep = first[_dedupe(log.commanded[first])]
        if len(keep) < 5:
            continue
        keep = keep[
            np.unique(np.linspace(0, len(keep) - 1, min(opts.path_points, len(keep))).round().astype(int))
        ]
        keep = keep[1:-1]  # the end points: an attained path that stops short never crosses their planes
        with_angles = test == "reorientation" and log.rotation is not None
        commanded = log.frames(keep, commanded=True) if with_angles else log.commanded[keep]
        attained = [log.frames(r.index) if with_angles else log.position[r.index] for r in runs]
        pa = path_accuracy(commanded, attained)
        details.append(
            {
                "path": name,
                "n": len(runs),
                "AT_mm": _mm(pa.AT),
                "RT_mm": _mm(pa.RT) if math.isfinite(pa.RT) else None,
                "AT_abc_deg": _deg(pa.AT_abc),
                "RT_abc_deg": _deg(pa.RT_abc),
            }
        )
    return details


def _path(log: Iso9283Log, opts: EvaluationOptions) -> Characteristic:
    args = _NAMES[8]
    if not log.runs("path"):
        return _missing(*args, _no_rows("path"))
    details = _path_rows(log, "path", opts)
    if not details:
        return _missing(*args, "no path run has five or more distinct commanded points")
    at, ap = _worst(details, "AT_mm", "path")
    rt, rp = _worst(details, "RT_mm", "path")
    return Characteristic(
        *args,
        True,
        f"AT {at:.3f} mm ({ap}), RT {rt:.3f} mm ({rp}); worst of {len(details)} paths",
        _cycles([d["n"] for d in details], 10),
        details,
    )


def _reorientation(log: Iso9283Log, opts: EvaluationOptions) -> Characteristic:
    args = _NAMES[9]
    if not log.runs("reorientation"):
        return _missing(*args, _no_rows("reorientation"))
    if log.rotation is None:
        return _missing(*args, "the log has no orientation columns (a_deg ... cmd_c_deg)")
    details = _path_rows(log, "reorientation", opts)
    if not details:
        return _missing(*args, "no reorientation run has five or more distinct commanded points")
    d = details[0]
    at = ", ".join(f"{x:.3f}" for x in d["AT_abc_deg"])
    rt = ", ".join(f"{x:.3f}" for x in (d["RT_abc_deg"] or [math.nan] * 3))
    summary = f"AT_abc {at} deg, RT_abc {rt} deg; AT {d['AT_mm']:.3f} mm ({d['path']})"
    return Characteristic(*args, True, summary, _cycles([x["n"] for x in details], 10), details)


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


def _cornering(log: Iso9283Log, opts: EvaluationOptions) -> Characteristic:
    args = _NAMES[10]
    paths = _paths(log, "cornering")
    if not paths:
        return _missing(*args, _no_rows("cornering"))
    details, counts = [], []
    for name, runs in paths.items():
        first = runs[0].index
        pts = log.commanded[first[_dedupe(log.commanded[first])]]
        for k, (corner, d1, d2, length) in enumerate(_corners(pts, opts.corner_angle_deg)):
            c = iso.cornering(corner, d1, d2, length, [log.position[r.index] for r in runs])
            counts.append(len(runs))
            details.append(
                {
                    "corner": f"{name} #{k + 1}",
                    "point_mm": [_mm(x) for x in corner],
                    "CR_mm": _mm(c.CR.mean()),
                    "CO_mm": _mm(c.CO.mean()),
                    "CR_max_mm": _mm(c.CR.max()),
                    "CO_max_mm": _mm(c.CO.max()),
                    "n": len(runs),
                }
            )
    if not details:
        return _missing(
            *args, f"no corner (a turn of more than {opts.corner_angle_deg:g} deg between straight stretches)"
        )
    cr, cp = _worst(details, "CR_mm", "corner")
    co, op = _worst(details, "CO_mm", "corner")
    return Characteristic(
        *args,
        True,
        f"CR {cr:.3f} mm ({cp}), CO {co:.3f} mm ({op}); mean of cycles, worst corner",
        _cycles(counts, 3),
        details,
    )


# ------------------------------------------------------------------ 11 velocity
def _velocity(log: Iso9283Log, opts: EvaluationOptions) -> Characteristic:
    args = _NAMES[11]
    paths = _paths(log, "velocity")
    if not paths:
        return _missing(*args, _no_rows("velocity"))
    details = []
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
                "v_c_mm_s": _mm(pv.v_c),
                "AV_percent": pv.AV,
                "RV_mm_s": _mm(pv.RV),
                "RV_percent": pv.RV_percent,
                "FV_mm_s": _mm(pv.FV),
            }
        )
    if not details:
        return _missing(*args, "velocity needs >= 2 cycles with a time record of the path")
    d = details[0]
    summary = (
        f"AV {d['AV_percent']:+.2f} %, RV {d['RV_mm_s']:.2f} mm/s ({d['RV_percent']:.2f} %), "
        f"FV {d['FV_mm_s']:.2f} mm/s at {d['v_c_mm_s']:.0f} mm/s ({d['path']})"
    )
    return Characteristic(*args, True, summary, _cycles([x["n"] for x in details], 10), details)


# ------------------------------------------------------------------ 12 positioning time
def _positioning(log: Iso9283Log, opts: EvaluationOptions, band: float) -> Characteristic:
    args = _NAMES[12]
    visits = _visits(log, "positioning", opts)
    if not visits:
        return _missing(*args, _no_rows("positioning"))
    by_distance: dict[float, list[float]] = defaultdict(list)
    for v in visits:
        idx = v.run.index
        cmd = log.commanded[idx]
        moving = np.flatnonzero(np.linalg.norm(cmd - cmd[0], axis=1) > _STILL)
        if len(moving) == 0 or len(idx) < 3:
            continue
        start = float(log.time[idx[max(int(moving[0]) - 1, 0)]])
        tp = iso.positioning_time(log.time[idx], log.position[idx], start, band, v.attained)
        if math.isfinite(tp):
            by_distance[round(_mm(np.linalg.norm(cmd[-1] - cmd[0])), 1)].append(tp)
    if not by_distance:
        return _missing(*args, "no positioning run holds a time record of a move that settles")
    details = [
        {"distance_mm": d, "n": len(ts), "time_s": float(np.mean(ts))}
        for d, ts in sorted(by_distance.items())
    ]
    text = ", ".join(f"{d['distance_mm']:g} mm {d['time_s']:.3f} s" for d in details)
    return Characteristic(
        *args, True, f"{text}; band {band * 1e3:g} mm", _cycles([d["n"] for d in details], 3), details
    )


# ------------------------------------------------------------------ 13 compliance
def _compliance(log: Iso9283Log) -> Characteristic:
    args = _NAMES[13]
    idx = np.flatnonzero(log.test == "compliance")
    if len(idx) == 0:
        return _missing(*args, _no_rows("compliance"))
    if log.force is None:
        return _missing(*args, "the log has no load columns (fx_N, fy_N, fz_N)")
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
        return _missing(*args, "no cycle has both an unloaded and a loaded measurement")
    try:
        sc = iso.static_compliance(np.vstack(F), np.vstack(disp))
    except ValueError as err:
        return _missing(*args, str(err))
    details = [
        {"direction": d, "compliance_mm_per_N": _mm(c), "max_load_N": float(loads.max())}
        for d, c, loads in zip(sc.directions, sc.compliance, sc.loads, strict=True)
    ]
    worst, wd = _worst(details, "compliance_mm_per_N", "direction")
    text = ", ".join(f"{d['direction']} {d['compliance_mm_per_N']:.5f}" for d in details)
    return Characteristic(
        *args, True, f"{text} mm/N (largest {worst:.5f}, {wd})", f"{len(counts)} (ISO 3)", details
    )


# ------------------------------------------------------------------ 14 weaving
def _weaving(log: Iso9283Log) -> Characteristic:
    args = _NAMES[14]
    paths = _paths(log, "weaving")
    if not paths:
        return _missing(*args, _no_rows("weaving"))
    details = []
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
                    "stroke_c_mm": _mm(ws[0].stroke_c),
                    "frequency_c_Hz": ws[0].frequency_c,
                }
            )
    if not details:
        return _missing(*args, "no weaving run holds a time record (>= 16 samples)")
    d = details[0]
    summary = (
        f"WS {d['WS_percent']:+.2f} %, WF {d['WF_percent']:+.2f} % "
        f"(stroke {d['stroke_c_mm']:.2f} mm at {d['frequency_c_Hz']:.2f} Hz, {d['path']})"
    )
    return Characteristic(*args, True, summary, _cycles([x["n"] for x in details], 3), details)


# ------------------------------------------------------------------ all
def _band(log: Iso9283Log, opts: EvaluationOptions) -> float:
    if opts.band is not None:
        band = float(opts.band)
    elif "limit_band_mm" in log.conditions:
        try:
            band = float(log.conditions["limit_band_mm"]) * 1e-3
        except ValueError:
            raise ValueError(
                f"{log.source}: header limit_band_mm {log.conditions['limit_band_mm']!r} is not a number"
            ) from None
    else:
        band = 1e-4
    if not (math.isfinite(band) and band > 0):
        raise ValueError(f"{log.source}: the limit band must be > 0 mm, got {band * 1e3:g}")
    return band


def evaluate_log(log: Iso9283Log, options: EvaluationOptions | None = None) -> Iso9283Results:
    """The fourteen ISO 9283 characteristics of ``log`` (those it cannot support are
    listed as not measured, with the reason)."""
    opts = options or EvaluationOptions()
    band = _band(log, opts)

    def guarded(number: int, build: Callable[[], Any]) -> Any:
        """``build()``, or its rows as not measured when the log's data defeat it."""
        try:
            return build()
        except (ValueError, np.linalg.LinAlgError) as err:
            count = 2 if number == 4 else 1
            out = tuple(
                _missing(*_NAMES[number + k], f"the data do not allow it: {err}") for k in range(count)
            )
            return out if count == 2 else out[0]

    pose = _visits(log, "pose", opts)
    stab, over = guarded(4, lambda: _stabilisation_rows(log, pose, band))
    rows = (
        guarded(1, lambda: _pose(log, pose)),
        guarded(2, lambda: _multidirectional(log, opts)),
        guarded(3, lambda: _distance(log, opts)),
        stab,
        over,
        guarded(6, lambda: _drift(log, opts)),
        guarded(7, lambda: _exchangeability(log, opts)),
        guarded(8, lambda: _path(log, opts)),
        guarded(9, lambda: _reorientation(log, opts)),
        guarded(10, lambda: _cornering(log, opts)),
        guarded(11, lambda: _velocity(log, opts)),
        guarded(12, lambda: _positioning(log, opts, band)),
        guarded(13, lambda: _compliance(log)),
        guarded(14, lambda: _weaving(log)),
    )
    return Iso9283Results(log.source, dict(log.conditions), band, rows)


# ------------------------------------------------------------------ output
def results_text(results: Iso9283Results) -> list[tuple[str, str, str, str, str]]:
    """Table rows ``(#, characteristic, clause, result, cycles)`` as plain text."""
    return [(str(r.number), f"{r.name} ({r.symbols})", r.clause, r.summary, r.cycles) for r in results.rows]


def _cell(v: Any) -> str:
    if v is None:
        return "-"
    if isinstance(v, float):
        return "-" if not math.isfinite(v) else f"{v:.4g}"
    if isinstance(v, list):
        return ", ".join(_cell(x) for x in v)
    return str(v)


def results_html(results: Iso9283Results, title: str = "ISO 9283 characteristics") -> str:
    """A small self-contained HTML page: conditions, the table, the details of each row.
    Every string from the log is escaped."""
    e = html.escape
    parts = [
        "<!DOCTYPE html><html><head><meta charset='utf-8'>",
        f"<title>{e(title)}</title><style>body{{font-family:sans-serif;margin:2em}}"
        "table{border-collapse:collapse;margin:.5em 0 1.5em}td,th{border:1px solid #bbb;padding:.25em .6em;"
        "text-align:left;vertical-align:top}.no{color:#777}</style></head><body>",
        f"<h1>{e(title)}</h1><p>log: <code>{e(results.source)}</code>; limit band {results.band * 1e3:g} mm. "
        "Clauses of ISO 9283:1998; how robocal reads them: docs/iso9283.md.</p>",
    ]
    if results.conditions:
        parts.append("<h2>Test conditions</h2><table>")
        parts += [f"<tr><th>{e(k)}</th><td>{e(v)}</td></tr>" for k, v in results.conditions.items()]
        parts.append("</table>")
    parts.append(
        "<h2>Characteristics</h2><table><tr><th>#</th><th>characteristic</th><th>clause</th>"
        "<th>result</th><th>cycles</th></tr>"
    )
    for r in results.rows:
        cls = "" if r.measured else " class='no'"
        parts.append(
            f"<tr{cls}><td>{r.number}</td><td>{e(r.name)} ({e(r.symbols)})</td><td>{e(r.clause)}</td>"
            f"<td>{e(r.summary)}</td><td>{e(r.cycles)}</td></tr>"
        )
    parts.append("</table>")
    for r in results.rows:
        if not r.details:
            continue
        keys = list(dict.fromkeys(k for d in r.details for k in d))
        parts.append(
            f"<h3>{r.number}. {e(r.name)}</h3><table><tr>"
            + "".join(f"<th>{e(k)}</th>" for k in keys)
            + "</tr>"
        )
        for d in r.details:
            parts.append("<tr>" + "".join(f"<td>{e(_cell(d.get(k)))}</td>" for k in keys) + "</tr>")
        parts.append("</table>")
    parts.append("</body></html>")
    return "\n".join(parts)
