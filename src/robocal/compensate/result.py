"""The result of a compensation: corrected joint commands, the errors predicted before
and after, reachability and branch changes (:class:`Compensation`), and its CSV/JSON files."""

from __future__ import annotations

import csv
import io
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from robocal.identify.calibrate import CalibrationResult
from robocal.measure.ik import TargetKind
from robocal.model.chain import Model
from robocal.model.files import atomic_write_text
from robocal.safe_output import csv_text, strict_json
from robocal.units import joint_unit_factors

__all__ = ["Compensation"]

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

    @property
    def n(self) -> int:
        return len(self.q)

    @property
    def success(self) -> bool:
        """Every target reached in the nominal configuration branch."""
        return bool(np.all(self.reachable & self.branch_kept))

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
        header.append("reachable")
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
            if pose:
                row += [
                    _fmt(math.degrees(self.angle_before[i]), 6),
                    _fmt(math.degrees(self.angle_after[i]), 6),
                ]
            w.writerow(row)
        return buf.getvalue()

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


def _num(v: float) -> float | None:
    return None if not math.isfinite(v) else float(v)


def _fmt(v: float, digits: int = 12) -> str:
    if not math.isfinite(v):
        return "nan"
    return f"{v:.{digits}g}"
