"""What a calibration's poses covered in joint space, and the commands outside it.

A calibration predicts well where its poses were.  The learned residual is a sum of
functions of each joint's angle (:mod:`robocal.model.residual`), so what matters is, per
joint, whether some calibration pose had a value near the command's: on a real UR10 a
single held-out pose got 1.56 mm worse where one angle lay 0.22 rad from every training
angle (issue 34).  :func:`joint_coverage` records, per joint, the intervals within
:data:`COVER_RAD` (:data:`COVER_M` for a prismatic joint) of a calibration pose's value —
revolute values on the circle, since the residual and the joint effects repeat every
turn — and :meth:`JointCoverage.outside` names the joints of a command that fall outside
them.  ``robocal compensate`` and ``robocal filter`` list such targets: their expected
error is an extrapolation there.  Stored in ``result.json`` as ``coverage``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from robocal.model.chain import Model

__all__ = ["COVER_M", "COVER_RAD", "JointCoverage", "coverage_warnings", "joint_coverage"]

#: a revolute joint value within this (rad) of a calibration pose's is covered: 100 random
#: poses leave gaps of ~0.3 rad between neighbouring values of a joint (2π ln n / n), and a
#: real UR10's held-out pose got 1.56 mm worse 0.22 rad from every training angle
COVER_RAD = 0.2
#: a prismatic joint value within this (m) of a calibration pose's is covered
COVER_M = 0.02
_TWO_PI = 2.0 * math.pi


@dataclass(frozen=True)
class JointCoverage:
    """Per joint, the covered intervals of its value (rad on ``(-π, π]`` for a revolute
    joint, whose intervals may reach past ±π; m for a prismatic one).

    Attributes:
        joint_names: ``(dof,)`` the joints.
        revolute: ``(dof,)`` whether each joint turns (its values are compared on the circle).
        intervals: per joint, sorted disjoint ``(low, high)`` intervals.
    """

    joint_names: tuple[str, ...]
    revolute: tuple[bool, ...]
    intervals: tuple[tuple[tuple[float, float], ...], ...]

    def distance(self, j: int, value: float) -> float:
        """How far ``value`` of joint ``j`` lies from the covered intervals (0: inside)."""
        shifts = (-_TWO_PI, 0.0, _TWO_PI) if self.revolute[j] else (0.0,)
        v = math.remainder(value, _TWO_PI) if self.revolute[j] else value
        best = math.inf
        for lo, hi in self.intervals[j]:
            for s in shifts:
                best = min(best, max(lo - (v + s), (v + s) - hi, 0.0))
        return best

    def outside(self, q: ArrayLike) -> list[str]:
        """For each command of ``q`` ``(n, dof)``: the joints outside the coverage with how
        far every calibration pose's value is (``""`` when all are covered)."""
        q = np.asarray(q, dtype=float).reshape(-1, len(self.joint_names))
        out = []
        for row in q:
            parts = []
            for j, v in enumerate(row):
                if not math.isfinite(v):
                    continue
                d = self.distance(j, float(v))
                if d > 0.0:
                    margin, unit = (COVER_RAD, "rad") if self.revolute[j] else (COVER_M, "m")
                    parts.append(
                        f"{self.joint_names[j]} {v:.3g} {unit}, {d + margin:.2g} {unit} from every pose's"
                    )
            out.append("; ".join(parts))
        return out

    def to_dict(self) -> dict[str, Any]:
        """``result.json``'s ``coverage``."""
        return {
            "cover_rad": COVER_RAD,
            "cover_m": COVER_M,
            "joints": [
                {"name": n, "revolute": r, "intervals": [list(i) for i in iv]}
                for n, r, iv in zip(self.joint_names, self.revolute, self.intervals, strict=True)
            ],
        }

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> JointCoverage:
        """The inverse of :meth:`to_dict`."""
        joints = list(data["joints"])
        return cls(
            joint_names=tuple(str(j["name"]) for j in joints),
            revolute=tuple(bool(j["revolute"]) for j in joints),
            intervals=tuple(tuple((float(lo), float(hi)) for lo, hi in j["intervals"]) for j in joints),
        )


_Intervals = tuple[tuple[float, float], ...]


def _intervals(values: np.ndarray, finite: list[int], half: np.ndarray) -> tuple[_Intervals, ...]:
    """Per column of ``values`` ``(n, dof)`` (each column sorted, its ``finite[j]`` finite
    values first): the union of ``[v - half[j], v + half[j]]`` over the finite ``v``, as
    sorted disjoint intervals (one ends where the next value's ``v - half`` passes its
    ``v + half``).  One set of numpy operations for all joints: every calibration records it."""
    if not len(values):
        return ((),) * len(finite)
    lo, hi = (values - half).T, (values + half).T  # (dof, n); NaN compares False: no gap
    joint, k = np.nonzero(lo[:, 1:] > hi[:, :-1])  # joint-major, in order along each joint
    starts, ends = lo[joint, k + 1].tolist(), hi[joint, k].tolist()
    first = np.searchsorted(joint, np.arange(len(finite) + 1)).tolist()
    lows = lo[:, 0].tolist()
    highs = hi[np.arange(len(finite)), np.maximum(np.array(finite) - 1, 0)].tolist()
    out = []
    for j, m in enumerate(finite):
        a, b = first[j], first[j + 1]
        out.append(tuple(zip([lows[j], *starts[a:b]], [*ends[a:b], highs[j]], strict=True)) if m else ())
    return tuple(out)


def joint_coverage(model: Model, q: ArrayLike) -> JointCoverage:
    """The joint coverage of the calibration poses ``q`` ``(n, dof)`` (see the module docstring)."""
    q = np.asarray(q, dtype=float).reshape(-1, model.dof)
    revolute = tuple(t == "revolute" for t in model.joint_types)
    turns = np.array(revolute, dtype=bool)
    if turns.all():  # the common case: no column to pick
        values = np.remainder(q + math.pi, _TWO_PI) - math.pi
    else:
        values = q.copy()
        values[:, turns] = np.remainder(q[:, turns] + math.pi, _TWO_PI) - math.pi
    finite = np.isfinite(values).sum(axis=0).tolist()
    values = np.sort(values, axis=0)  # NaN last in each column
    intervals = _intervals(values, finite, np.where(turns, COVER_RAD, COVER_M))
    return JointCoverage(model.joint_names, revolute, intervals)


def coverage_warnings(calibrated: Any, q: ArrayLike, names: Sequence[str]) -> list[str]:
    """One line naming the commands ``q`` ``(n, dof)`` with a joint value no calibration
    pose came near (``calibrated.records["coverage"]``); empty when all are covered or the
    calibration recorded no coverage (a bare model, an older result)."""
    record = (getattr(calibrated, "records", None) or {}).get("coverage")
    if not isinstance(record, Mapping):
        return []
    coverage = JointCoverage.from_dict(record)
    q = np.asarray(q, dtype=float)
    if q.ndim != 2 or q.shape[1] != len(coverage.joint_names):
        return []
    far = [(str(n), why) for n, why in zip(names, coverage.outside(q), strict=True) if why]
    if not far:
        return []
    shown = "; ".join(f"{n} ({why})" for n, why in far[:5]) + (" ..." if len(far) > 5 else "")
    return [
        f"{len(far)} of {len(q)} target(s) need joint values no calibration pose came within "
        f"{COVER_RAD:g} rad ({COVER_M * 1e3:g} mm) of: {shown}; the calibration's prediction and its "
        "expected error are extrapolated there (measure poses that reach these values)"
    ]
