"""The result of a compensation: corrected joint commands, the errors predicted before
and after, reachability and branch changes (:class:`Compensation`), and its CSV/JSON files."""

from __future__ import annotations

import csv
import io
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from robocal.identify.result import CalibrationResult
from robocal.measure.ik_starts import TargetKind
from robocal.model.chain import Model
from robocal.outdir import atomic_write_text
from robocal.safe_output import csv_text, strict_json
from robocal.units import joint_unit_factors

__all__ = ["TABLE_COLUMNS", "Compensation", "table_csv", "table_path"]

Array = NDArray[np.float64]
Calibrated = CalibrationResult | Model
Frame = Literal["base", "measurement"]


# ---------------------------------------------------------------------- result
@dataclass(frozen=True)
class Compensation:
    """Corrected joint commands for ``n`` targets.

    Attributes:
        q: ``(n, dof)`` corrected commands (rad, m for prismatic joints).
        q_nominal: ``(n, dof)`` the nominal model's solution (what the controller would
            have commanded; the programmed joints for :func:`filter_program`).
        targets: ``(n, 4, 4)`` target frames in the robot's base frame (m).
        kind: ``"position"``, ``"pose"`` or ``"axis"``: what of the targets is imposed.
        error_before: ``(n,)`` predicted position error (m) of the real robot at
            ``q_nominal`` (NaN when no nominal model was known).
        error_after: ``(n,)`` predicted position error (m) at ``q``.
        angle_before, angle_after: ``(n,)`` orientation errors (rad; zeros for
            position targets).
        reachable: ``(n,)`` the calibrated model reaches the target (``tol``,
            ``tol_angle``) within the joint limits.
        nominal_reachable: ``(n,)`` the nominal model reached it.
        joint_change: ``(n,)`` ``max |q − q_nominal|`` over the joints (rad or m).
        branch_kept: ``(n,)`` ``joint_change <= max_joint_change``: the corrected
            command is in the nominal solution's configuration branch.
        names: ``n`` target names.
        joint_names, joint_types: the robot's joints.
        iterations: ``(n,)`` IK iterations of the correction.
        expected_error_after: ``(n,)`` RMS position error (m) to expect at ``q`` on the real
            robot: the calibration's uncertainty there and the error its model leaves
            unexplained (:meth:`CalibrationResult.expected_position_error`); NaN when only a
            bare model, with no uncertainty, was given.  ``error_after`` is only what the IK
            left against the calibrated model itself (below ``tol`` when reached).
        status: ``(n,)`` ``"corrected"``, ``"damped"`` (near a singularity, a bounded
            correction) or ``"refused"`` (``q`` is then ``q_nominal``: left as written);
            see :mod:`robocal.compensate.safety`.
        reasons: ``(n,)`` why a target was refused or damped (empty when corrected).
        sigma_min: ``(n,)`` smallest singular value of the task Jacobian at ``q_nominal``.
        configuration: ``(n,)`` the nominal command's configuration label.
        joint_bound: ``(n, dof)`` the largest joint change (rad, m) each target's correction
            may make (:func:`robocal.compensate.safety.joint_bound`).
        tool_correction: ``(n,)`` how far (m) the corrected command moves the tool on the
            controller's (nominal) model.
        flank_spread: ``(n,)`` how far (m) the tool may land from where the command aims
            because a joint's load is too small to know the flank its backlash or clearance
            sits on (:mod:`robocal.compensate.flanks`; zero where every flank is known).
        flank_notes: ``(n,)`` the warning of a target whose flank spread exceeds the IK's
            position tolerance (also in its reason; empty elsewhere).
        notes: warnings about the whole run (e.g. a joint whose backlash no load ever sets).
    """

    q: Array
    q_nominal: Array
    targets: Array
    kind: TargetKind
    error_before: Array
    error_after: Array
    angle_before: Array
    angle_after: Array
    reachable: NDArray[np.bool_]
    nominal_reachable: NDArray[np.bool_]
    joint_change: Array
    branch_kept: NDArray[np.bool_]
    names: tuple[str, ...]
    joint_names: tuple[str, ...]
    joint_types: tuple[str, ...]
    iterations: NDArray[np.int64]
    expected_error_after: Array
    status: tuple[str, ...] = ()
    reasons: tuple[str, ...] = ()
    sigma_min: Array = field(default_factory=lambda: np.zeros(0))
    configuration: tuple[str, ...] = ()
    joint_bound: Array = field(default_factory=lambda: np.zeros(0))
    tool_correction: Array = field(default_factory=lambda: np.zeros(0))
    flank_spread: Array = field(default_factory=lambda: np.zeros(0))
    flank_notes: tuple[str, ...] = ()
    notes: tuple[str, ...] = ()

    @property
    def n(self) -> int:
        return len(self.q)

    @property
    def accepted(self) -> NDArray[np.bool_]:
        """``(n,)`` the target's command is written corrected (or damped), not refused."""
        if len(self.status) != self.n:
            return self.reachable & self.branch_kept
        return np.array([s != "refused" for s in self.status], dtype=bool)

    @property
    def refused(self) -> tuple[str, ...]:
        """``"name: reason"`` of every refused target."""
        return tuple(f"{self.names[i]}: {self.reasons[i]}" for i in np.flatnonzero(~self.accepted))

    @property
    def success(self) -> bool:
        """Every target corrected (or damped near a singularity) in the nominal configuration."""
        return bool(np.all(self.accepted))

    @property
    def message(self) -> str:
        bad = np.flatnonzero(~self.reachable)
        moved = np.flatnonzero(self.reachable & ~self.branch_kept)
        parts = [f"{self.n - len(bad)} of {self.n} targets reached"]
        if len(bad):
            parts.append(
                "not reached: " + ", ".join(self.names[i] for i in bad[:8]) + (" ..." if len(bad) > 8 else "")
            )
        if len(moved):
            parts.append("configuration changed: " + ", ".join(self.names[i] for i in moved[:8]))
        return "; ".join(parts)

    def summary(self) -> dict[str, Any]:
        """Counts, and mean and max predicted errors before and after (mm, degrees) over
        the reached targets (an unreachable target's errors say nothing of the
        compensation; they are in the per-target arrays)."""

        def stats(v: Array, f: float) -> dict[str, float | None]:
            v = v[self.reachable & np.isfinite(v)]
            if not len(v):
                return {"mean": None, "max": None}
            return {"mean": float(v.mean() * f), "max": float(v.max() * f)}

        out: dict[str, Any] = {
            "n": self.n,
            "reachable": int(self.reachable.sum()),
            "branch_kept": int(self.branch_kept.sum()),
            "error_before_mm": stats(self.error_before, 1e3),
            "error_after_mm": stats(self.error_after, 1e3),
            "expected_error_after_mm": stats(self.expected_error_after, 1e3),
        }
        if self.kind != "position":
            out["angle_before_deg"] = stats(self.angle_before, 180 / math.pi)
            out["angle_after_deg"] = stats(self.angle_after, 180 / math.pi)
        return out

    def _joint_factor(self, angle_unit: str, length_unit: str) -> Array:
        a, ln = joint_unit_factors(angle_unit, length_unit)
        return np.array([1 / a if t == "revolute" else 1 / ln for t in self.joint_types])

    def to_dict(self, angle_unit: str = "rad", length_unit: str = "mm") -> dict[str, Any]:
        """Plain data: per-target commands (joints in ``angle_unit``; prismatic joints
        in ``length_unit``) and predicted errors in mm (degrees for orientation)."""
        f = self._joint_factor(angle_unit, length_unit)
        rows = []
        for i, name in enumerate(self.names):
            row: dict[str, Any] = {
                "name": name,
                "q": (self.q[i] * f).tolist(),
                "nominal_q": (self.q_nominal[i] * f).tolist(),
                "predicted_error_before_mm": _num(self.error_before[i] * 1e3),
                "predicted_error_after_mm": _num(self.error_after[i] * 1e3),
                "expected_error_after_mm": _num(self.expected_error_after[i] * 1e3),
                "reachable": bool(self.reachable[i]),
                "branch_kept": bool(self.branch_kept[i]),
                "status": _at(self.status, i, "corrected" if self.accepted[i] else "refused"),
                "reason": _at(self.reasons, i, ""),
                "flank_spread_mm": _num(_at(self.flank_spread, i, 0.0) * 1e3),
            }
            if self.kind != "position":
                row["predicted_angle_error_before_deg"] = _num(math.degrees(self.angle_before[i]))
                row["predicted_angle_error_after_deg"] = _num(math.degrees(self.angle_after[i]))
            rows.append(row)
        return {
            "kind": self.kind,
            "joints": list(self.joint_names),
            "units": {"revolute": angle_unit, "prismatic": length_unit, "errors": "mm, deg"},
            "summary": self.summary(),
            "targets": rows,
        }

    def to_csv(self, angle_unit: str = "rad", length_unit: str = "mm") -> str:
        """CSV text: ``name, q1..qN, nominal_q1..nominal_qN, predicted_error_before_mm,
        predicted_error_after_mm, reachable`` (+ orientation errors in degrees for pose
        and axis targets); joints in ``angle_unit`` (prismatic in ``length_unit``)."""
        f = self._joint_factor(angle_unit, length_unit)
        dof = self.q.shape[1]
        header = ["name", *(f"q{j + 1}" for j in range(dof)), *(f"nominal_q{j + 1}" for j in range(dof))]
        header += ["predicted_error_before_mm", "predicted_error_after_mm", "expected_error_after_mm"]
        header += ["reachable", "status"]
        pose = self.kind != "position"
        if pose:
            header += ["predicted_angle_error_before_deg", "predicted_angle_error_after_deg"]
        buf = io.StringIO()
        w = csv.writer(buf, lineterminator="\n")
        w.writerow(header)
        for i, name in enumerate(self.names):
            row = [
                csv_text(name),
                *(_fmt(v) for v in self.q[i] * f),
                *(_fmt(v) for v in self.q_nominal[i] * f),
            ]
            row += [_fmt(self.error_before[i] * 1e3, 6), _fmt(self.error_after[i] * 1e3, 6)]
            row.append(_fmt(self.expected_error_after[i] * 1e3, 6))
            row.append("true" if self.reachable[i] else "false")
            row.append(_at(self.status, i, "corrected" if self.accepted[i] else "refused"))
            if pose:
                row += [
                    _fmt(math.degrees(self.angle_before[i]), 6),
                    _fmt(math.degrees(self.angle_after[i]), 6),
                ]
            w.writerow(row)
        return buf.getvalue()

    def table(self) -> list[dict[str, Any]]:
        """The per-target table every run prints and writes beside its output: predicted
        error before (mm, deg), the correction (tool mm on the controller's model), the
        largest joint change (deg or mm, and which joint), the bound, sigma_min, the
        configuration, the status and the reason."""
        rows = []
        accepted = self.accepted  # once: O(n) to build
        for i, name in enumerate(self.names):
            dq = np.abs(self.q[i] - self.q_nominal[i])
            j = int(np.argmax(dq)) if dq.size else 0
            revolute = not self.joint_types or self.joint_types[j] == "revolute"
            f = 180 / math.pi if revolute else 1e3
            rows.append(
                {
                    "name": name,
                    "status": _at(self.status, i, "corrected" if accepted[i] else "refused"),
                    "error_before_mm": _num(self.error_before[i] * 1e3),
                    "angle_before_deg": _num(math.degrees(self.angle_before[i])),
                    "correction_mm": _num(_at(self.tool_correction, i, math.nan) * 1e3),
                    "largest_joint_change": _num(float(dq[j]) * f) if dq.size else None,
                    "joint": self.joint_names[j] if self.joint_names else str(j + 1),
                    "joint_unit": "deg" if revolute else "mm",
                    "joint_bound": _num(self._bound(i, j) * f),
                    "sigma_min": _num(_at(self.sigma_min, i, math.nan)),
                    "configuration": _at(self.configuration, i, "-"),
                    "reason": _at(self.reasons, i, ""),
                }
            )
        return rows

    def _bound(self, i: int, j: int) -> float:
        """Target ``i``'s bound on joint ``j`` (NaN when none was derived)."""
        b = np.asarray(self.joint_bound)
        return float(b[i, j]) if b.ndim == 2 and i < len(b) and j < b.shape[1] else math.nan

    def table_csv(self) -> str:
        """:meth:`table` as CSV text (strings escaped against spreadsheet formulas)."""
        return table_csv(self.table())

    def write_table(self, path: str | Path) -> Path:
        """Write :meth:`table_csv` to ``path`` atomically."""
        return atomic_write_text(Path(path), self.table_csv())

    def write(self, path: str | Path, angle_unit: str = "rad", length_unit: str = "mm") -> Path:
        """Write the corrected program to ``path`` atomically: JSON for a ``.json``
        suffix, CSV otherwise (see :meth:`to_csv` and :meth:`to_dict`)."""
        path = Path(path)
        joint_unit_factors(angle_unit, length_unit)  # a ValueError naming the unit before anything is written
        if path.suffix.lower() == ".json":
            text = strict_json(self.to_dict(angle_unit, length_unit), indent=2) + "\n"
        else:
            text = self.to_csv(angle_unit, length_unit)
        return atomic_write_text(path, text)


TABLE_COLUMNS = (
    "name",
    "status",
    "error_before_mm",
    "angle_before_deg",
    "correction_mm",
    "largest_joint_change",
    "joint",
    "joint_unit",
    "joint_bound",
    "sigma_min",
    "configuration",
    "reason",
)


def table_csv(rows: list[dict[str, Any]]) -> str:
    """Per-target table rows (:meth:`Compensation.table`) as CSV text; strings escaped."""
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(TABLE_COLUMNS)
    for row in rows:
        cells = []
        for col in TABLE_COLUMNS:
            v = row.get(col)
            if v is None:
                cells.append("")
            elif isinstance(v, float):
                cells.append(_fmt(v, 6))
            else:
                cells.append(csv_text(str(v)))
        w.writerow(cells)
    return buf.getvalue()


def table_path(out: str | Path) -> Path:
    """Where the per-target table of an output file goes: beside it, ``NAME.table.csv``."""
    out = Path(out)
    return out.with_name(out.name + ".table.csv")


def _at(values: Any, i: int, default: Any) -> Any:
    return values[i] if len(values) > i else default


def _num(v: float) -> float | None:
    return None if not math.isfinite(v) else float(v)


def _fmt(v: float, digits: int = 12) -> str:
    if not math.isfinite(v):
        return "nan"
    return f"{v:.{digits}g}"
