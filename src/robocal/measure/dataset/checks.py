"""The reader's checks across rows: the length unit, joint values within limits, duplicate rows."""

from __future__ import annotations

import numpy as np

from robocal.measure.dataset.columns import ReaderState, short
from robocal.measure.measurements import (
    MAX_MEDIAN_DISTANCE,
    MAX_POSITION,
    MAX_REVOLUTE_RAD,
    MIN_MEDIAN_DISTANCE,
    Array,
)


class RowChecks(ReaderState):
    """Checks across a file's rows, mixed into :class:`robocal.measure.dataset.reader._Reader`."""

    def _rows_text(self) -> str:
        return f"rows {self.line_no[0]}-{self.line_no[-1]}"

    def _check_length_unit(self, position: Array, names: list[str]) -> None:
        with np.errstate(over="ignore", invalid="ignore"):
            far = np.isfinite(position) & (np.abs(position) > MAX_POSITION)  # NaN/inf: reported already
        for i, c in np.argwhere(far)[:10]:
            self.error(
                "range",
                f"{short(self._cell(int(i), names[c]))} {self.length_unit} is farther than any device "
                f"measures ({MAX_POSITION / 1000:g} km)",
                int(self.line_no[i]),
                names[c],
            )
        dist = np.linalg.norm(position, axis=1)
        dist = dist[np.isfinite(dist)]
        if dist.size == 0:
            return
        med = float(np.median(dist))
        cols = "/".join(names)
        if med > MAX_MEDIAN_DISTANCE and self.length_unit != "mm":
            self.error(
                "length-unit",
                f"median distance of the positions from the device origin is {med:.4g} m with "
                f"length_unit={self.length_unit!r} ({self._rows_text()}): "
                "looks like mm: pass length_unit='mm'",
                None,
                cols,
            )
        elif med < MIN_MEDIAN_DISTANCE and self.length_unit != "m":
            self.error(
                "length-unit",
                f"median distance of the positions from the device origin is {med * 1000:.4g} mm with "
                f"length_unit={self.length_unit!r} ({self._rows_text()}): "
                "looks like m: pass length_unit='m'",
                None,
                cols,
            )

    def _check_joints(self, q: Array, names: list[str]) -> None:
        model = self.model
        types = model.joint_types if model is not None else ("revolute",) * len(names)
        for j, name in enumerate(names):
            if types[j] != "revolute" or self.angle_unit != "rad":
                continue
            col = q[:, j]
            big = np.nanmax(np.abs(col), initial=0.0)
            if big > MAX_REVOLUTE_RAD:
                i = int(np.nanargmax(np.abs(col)))
                self.error(
                    "angle-unit",
                    f"revolute joint values up to {big:.4g} rad (row {self.line_no[i]}): looks like "
                    "degrees: pass angle_unit='deg'",
                    None,
                    name,
                )
        if model is None or self.limits == "ignore":
            return
        lim = model.joint_limits
        outside = (q < lim[:, 0]) | (q > lim[:, 1])
        report = self.error if self.limits == "error" else self.warn
        for i, j in self._listed(
            np.argwhere(outside), "limits", names[0], "warning" if self.limits == "warn" else "error"
        ):
            kind = model.joint_types[j]
            unit, scale = (self.angle_unit, self.A) if kind == "revolute" else (self.length_unit, self.L)
            lo, hi = lim[j] / scale
            report(
                "limits",
                f"joint {model.joint_names[j]} = {q[i, j] / scale:.6g} {unit} is outside the limits "
                f"[{lo:.6g}, {hi:.6g}] {unit} of model {model.name!r} (a different robot, joint order or "
                "unit? if the robot really goes there, pass limits='warn')",
                int(self.line_no[i]),
                names[j],
            )

    def _check_duplicates(self, q, position, ori_values, sigma, split) -> None:
        parts = [q] + [a for a in (position, ori_values, sigma) if a is not None]
        if split is not None:
            parts.append((split == "train")[:, None].astype(float))
        ok = self.good.copy()
        for a in parts:
            ok &= np.all(np.isfinite(a), axis=1)
        usable = np.flatnonzero(ok)
        if usable.size < 2:
            return
        # equal rows found through a 64-bit hash of their bits (sorting one number per row
        # instead of whole rows: memory linear in the rows, not a copy of the table), each
        # candidate then compared exactly
        h = np.zeros(usable.size, dtype=np.uint64)
        for a in parts:
            for c in range(a.shape[1]):
                bits = (a[usable, c] + 0.0).view(np.uint64)  # + 0.0: -0.0 and 0.0 are equal
                h = (h * np.uint64(0x100000001B3)) ^ bits
        order = np.argsort(h, kind="stable")  # stable: within a run, rows in file order
        hs = h[order]
        is_start = np.r_[True, hs[1:] != hs[:-1]]
        run_first = order[np.flatnonzero(is_start)][np.cumsum(is_start) - 1]  # first row of each run
        later = np.flatnonzero(~is_start)
        rows, firsts = usable[order[later]], usable[run_first[later]]
        same = np.ones(len(later), dtype=bool)
        for a in parts:
            same &= np.all(a[rows] == a[firsts], axis=1)
        pairs = np.stack([rows[same], firsts[same]], axis=1)
        pairs = pairs[np.argsort(pairs[:, 0], kind="stable")]
        joints_only = position is None
        code = "repeated-pose" if joints_only else "duplicate"
        for i, i0 in self._listed(pairs, code, None, "warning" if joints_only else "error"):
            if joints_only:
                self.warn(
                    "repeated-pose",
                    f"repeats the joint values of row {self.line_no[i0]} (a repeated pose)",
                    int(self.line_no[i]),
                )
            else:
                self.error(
                    "duplicate",
                    f"duplicates row {self.line_no[i0]} (joint values and measurements identical: "
                    "a copied row?)",
                    int(self.line_no[i]),
                )
