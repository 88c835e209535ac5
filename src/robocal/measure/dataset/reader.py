"""One pass over a measurement CSV that collects every problem instead of stopping at the first."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from robocal import csvfile, spatial
from robocal.measure.dataset.checks import RowChecks
from robocal.measure.dataset.columns import (
    INCOMPLETE_CODES,
    MAX_LISTED,
    SEPARATOR_NAMES,
    ColumnResolver,
    IncompleteMode,
    parse_columns,
    parse_orientation,
    short,
)
from robocal.measure.measurements import (
    MAX_FILE_BYTES,
    MAX_SIGMA,
    MIN_SIGMA,
    Array,
    LimitsMode,
    Measurements,
    Problem,
)
from robocal.model.chain import Model
from robocal.units import unit_factor


class Reader(ColumnResolver, RowChecks):
    """One pass over a file that collects every problem instead of stopping at the first."""

    max_file_bytes = MAX_FILE_BYTES  # dataset._collect passes dataset.MAX_FILE_BYTES

    def __init__(  # noqa: PLR0913 - the reader options of read_measurements, each a keyword
        self,
        path: Path,
        *,
        length_unit: str,
        angle_unit: str,
        columns: Mapping[str, str] | Sequence[str] | str | None,
        sep: str | None,
        decimal: str,
        dof: int | None,
        model: Model | None,
        limits: LimitsMode,
        orientation: str,
        extra: Sequence[str],
        incomplete: IncompleteMode = "error",
    ) -> None:
        L = unit_factor(length_unit, "length", "length_unit")
        A = unit_factor(angle_unit, "angle", "angle_unit")
        if decimal not in (".", ","):
            raise ValueError(f"decimal must be '.' or ',', got {decimal!r}")
        sep = SEPARATOR_NAMES.get(sep, sep) if sep is not None else None
        if sep is not None and (len(sep) != 1 or sep == decimal or sep in "\"'"):
            raise ValueError(f"sep must be one character other than the decimal mark, got {sep!r}")
        if limits not in ("error", "warn", "ignore"):
            raise ValueError(f"limits must be 'error', 'warn' or 'ignore', got {limits!r}")
        if incomplete not in ("error", "drop"):
            raise ValueError(f"incomplete must be 'error' or 'drop', got {incomplete!r}")
        if model is not None and dof is not None and dof != model.dof:
            raise ValueError(f"dof={dof} contradicts model {model.name!r} with {model.dof} joints")
        self.path = path
        self.L, self.A = L, A
        self.length_unit, self.angle_unit = length_unit, angle_unit
        self.rename = parse_columns(columns)
        self.sep, self.decimal = sep, decimal
        self.dof, self.model, self.limits = dof, model, limits
        self.orientation = parse_orientation(orientation)
        self.extra_names = list(extra)
        self.incomplete = incomplete
        self.problems: list[Problem] = []

    # -- the pass
    def read(self) -> Measurements | None:
        head = self._open()
        if head is None:
            return None
        metadata = dict(head.metadata)
        self._index_header(head)
        cols = self._resolve_columns()
        if cols is None:
            return None
        if not self._stream(cols):
            return None
        if not len(self.line_no):
            self.error("no-data", "no data rows after the header", self.header_line)
            return None
        values = self._values(cols)
        if values["position"] is not None:
            self._check_length_unit(values["position"], cols["position"])
        self._check_joints(values["q"], cols["joints"])
        orientation = values["orientation"]
        ori_flat = None if orientation is None else orientation.reshape(len(orientation), 9)  # a view
        self._check_duplicates(values["q"], values["position"], ori_flat, values["sigma"], values["split"])
        del orientation, ori_flat
        if not self.ok or not self._drop_incomplete(values, metadata):
            return None
        return self._measurements(values, cols, metadata)

    def _open(self) -> csvfile.Head | None:
        """The file's head (metadata, header), or None with the problem recorded."""
        path = self.path
        if path.exists() and not path.is_file():  # a directory, FIFO or device (which never ends)
            self.error("file", "not a regular file")
            return None
        if path.exists() and path.stat().st_size > self.max_file_bytes:
            self.error(
                "file",
                f"{path.stat().st_size} bytes is more than the {self.max_file_bytes} "
                "a measurement file may have",
            )
            return None
        try:
            return csvfile.read_head(path, sep=self.sep, decimal=self.decimal)
        except FileNotFoundError:
            self.error("file", "file not found")
            return None
        except csvfile.CsvError as err:
            self.error(err.code, err.message, err.line)
            return None

    def _index_header(self, head: csvfile.Head) -> None:
        """``self.where``: each header name's column; a name given twice is an error."""
        self.head = head
        self.header_line = head.header_line
        self.header = header = head.header
        where: dict[str, int] = {}
        for k, name in enumerate(header):
            if name in where:
                self.error(
                    "header",
                    f"column {name!r} appears more than once in the header (columns {where[name] + 1} "
                    f"and {k + 1})",
                    self.header_line,
                    name,
                )
            elif name:
                where[name] = k
        self.where = where

    def _values(self, cols: dict) -> dict:
        """The columns' values in SI: ``q``, ``position``, ``sigma``, ``orientation`` (rotation
        matrices), ``temperature``, ``split``, ``extra`` (absent: None)."""
        q = self._numbers(cols["joints"])
        q *= cols["joint_scale"]  # in place: the arrays are not copied
        values: dict = {"q": q, "position": None, "sigma": None, "orientation": None, "temperature": None}
        if cols["position"]:
            values["position"] = self._numbers(cols["position"])
            values["position"] *= self.L
        if cols["sigma"]:
            values["sigma"] = self._sigma(cols["sigma"])
        ori_cols = cols["orientation"]
        ori_values = self._numbers(ori_cols) if ori_cols else None
        if cols["temperature"]:
            values["temperature"] = self._numbers(cols["temperature"])[:, 0]
        values["extra"] = {name: self._numbers([name])[:, 0] for name in cols["extra"]}
        values["split"] = self._split(cols["set"]) if cols["set"] else None
        if ori_values is not None:
            values["orientation"] = self._orientation(ori_values, ori_cols, cols["orientation_kind"])
            del ori_values  # the rotation matrices are kept, not the columns they were made from
        return values

    def _sigma(self, names: list[str]) -> Array:
        """The per-row standard deviations (m), each within ``MIN_SIGMA..MAX_SIGMA``."""
        sigma = self._numbers(names)
        sigma *= self.L
        bad = self.good[:, None] & np.isfinite(sigma) & ((sigma < MIN_SIGMA) | (sigma > MAX_SIGMA))
        for i, c in self._listed(np.argwhere(bad), "sigma", names[0]):
            cell = self._cell(i, names[c])
            self.error(
                "sigma",
                f"standard deviation {cell!r} is negative"
                if sigma[i, c] < 0
                else f"standard deviation {cell!r} is outside {MIN_SIGMA * 1e3:g}..{MAX_SIGMA * 1e3:g} "
                "mm "
                "(leave the sigma columns out when the noise is not known)",
                int(self.line_no[i]),
                names[c],
            )
        return sigma

    def _drop_incomplete(self, values: dict, metadata: dict) -> bool:
        """incomplete='drop': the rows with a missing or bad value go (False: none is left)."""
        dropped = int(self.incomplete_rows.sum()) if self.incomplete == "drop" else 0
        if not dropped:
            return True
        if dropped == len(self.line_no):
            self.error("no-data", "every data row has a missing or bad value")
            return False
        keep = ~self.incomplete_rows
        # one array at a time, so that each earlier one is freed before the next is copied
        for key in ("q", "position", "sigma", "split", "temperature", "orientation"):
            values[key] = None if values[key] is None else values[key][keep]
        values["extra"] = {name: v[keep] for name, v in values["extra"].items()}
        metadata["rows_left_out"] = str(dropped)
        return True

    def _measurements(self, values: dict, cols: dict, metadata: dict) -> Measurements:
        """The :class:`Measurements`, with what was read recorded in its metadata."""
        joint_cols = cols["joints"]
        joint_names = tuple(metadata.pop("joints", "").split())
        if len(joint_names) != len(joint_cols):
            joint_names = tuple(joint_cols)
        metadata.setdefault("file", str(self.path))
        metadata["read_units"] = f"{self.length_unit}, {self.angle_unit}"
        used = {c for key in ("joints", "position", "sigma", "orientation", "temperature", "extra", "set")
                for c in (cols.get(key) or [])}  # fmt: skip
        unused = [h for h in self.header if h and h not in used]
        if unused:
            metadata["unused_columns"] = ", ".join(unused)
        if values["orientation"] is not None:
            metadata["read_orientation"] = cols["orientation_kind"]
        return Measurements(joint_names=joint_names, metadata=metadata, **values)

    def _stream(self, cols: dict) -> bool:
        """Read the rows chunk by chunk (:mod:`robocal.csvfile`), keeping for each column
        in use its numbers (NaN where a cell is bad), its problems (the first
        :data:`MAX_LISTED`), and for the ``set`` column its labels; sets ``line_no``,
        ``offsets``, ``good`` (rows that could be split into cells) and
        ``incomplete_rows``.  False when a row cannot be read at all."""
        names = [*cols["joints"], *cols["position"], *cols["sigma"], *cols["orientation"],
                 *cols["temperature"], *cols["extra"]]  # fmt: skip
        numeric = list(dict.fromkeys(self.where[n] for n in names))
        set_k = self.where[cols["set"]] if cols["set"] else None
        parts: dict[int, list[Array]] = {k: [] for k in numeric}
        found: dict[int, list[tuple[str, str, int]]] = {k: [] for k in [*numeric, -1, -2]}
        counts: dict[int, int] = {}
        labels: list[NDArray[np.str_]] = []
        line_no, offsets, good, incomplete = [], [], [], []

        def note(k: int, code: str, message: str, line: int) -> None:
            counts[k] = counts.get(k, 0) + 1
            if counts[k] <= MAX_LISTED:
                found[k].append((code, message, line))

        # the fast path needs every cell a number: not with the text column ``set``
        for chunk in csvfile.iter_chunks(self.head, decimal=None if set_k is not None else self.decimal):
            if chunk.numbers is not None:  # plain numbers, read at once: no problems
                for k in numeric:
                    parts[k].append(chunk.numbers[:, k].copy())
                line_no.append(chunk.line)
                offsets.append(chunk.offset)
                good.append(np.ones(len(chunk), dtype=bool))
                incomplete.append(np.zeros(len(chunk), dtype=bool))
                continue
            ok = np.ones(len(chunk), dtype=bool)
            for i, code, message in chunk.problems:
                ok[i] = False
                note(-1, code, message, int(chunk.line[i]))
            rows = np.flatnonzero(ok)
            bad_cells = ~ok
            for k in numeric:
                values = np.full(len(chunk), np.nan)
                values[rows], problems = csvfile.to_numbers([chunk.rows[i][k] for i in rows], self.decimal)
                for m, code, message in problems:
                    note(k, code, message, int(chunk.line[rows[m]]))
                    bad_cells[rows[m]] = True
                parts[k].append(values)
            if set_k is not None:
                cells = [r[set_k].strip().lower() if len(r) > set_k else "" for r in chunk.rows]
                valid = np.array([c in ("train", "test") for c in cells], dtype=bool)
                for i in map(int, np.flatnonzero(ok & ~valid)):
                    raw = chunk.rows[i][set_k].strip()
                    message = f"{short(raw)} is not a train/test label (expected 'train' or 'test')"
                    note(-2, "split", message, int(chunk.line[i]))
                kept = [c if v else "" for c, v in zip(cells, valid, strict=True)]
                labels.append(np.array(kept, dtype="<U5"))
            line_no.append(chunk.line)
            offsets.append(chunk.offset)
            good.append(ok)
            incomplete.append(bad_cells)
        self.line_no = np.concatenate(line_no) if line_no else np.zeros(0, dtype=np.int64)
        self.offsets = np.concatenate(offsets) if offsets else np.zeros(0, dtype=np.int64)
        self.good = np.concatenate(good) if good else np.zeros(0, dtype=bool)
        self.incomplete_rows = np.concatenate(incomplete) if incomplete else np.zeros(0, dtype=bool)
        del line_no, offsets, good, incomplete
        self.columns: dict[int, Array] = {}
        for k in numeric:  # column by column: one column's chunks are freed before the next is joined
            self.columns[k] = np.concatenate(parts.pop(k)) if self.line_no.size else np.zeros(0)
        self.labels = np.concatenate(labels) if labels else np.zeros(0, dtype="<U5")
        self.found, self.counts = found, counts
        self.uses = {k: sum(self.where[n] == k for n in names) for k in numeric}
        for code, message, line in found[-1]:
            self.error(code, message, line)
        self._more_rows(-1, None)
        return not any(code == "file" for code, _, _ in found[-1])

    def _more_rows(self, k: int, column: str | None) -> None:
        """One line for the problems of column ``k`` beyond the first :data:`MAX_LISTED`."""
        codes = {code for code, _, _ in self.found[k]}
        drop = self.incomplete == "drop" and k != -2 and codes <= INCOMPLETE_CODES
        code = next(iter(codes)) if len(codes) == 1 else "more"
        self._summary(code, self.counts.get(k, 0) - MAX_LISTED, column, "warning" if drop else "error")

    # -- cells
    def _numbers(self, names: Sequence[str]) -> Array:
        """``(n, len(names))`` floats; bad cells (reported) are NaN.  Each column's array
        is handed over at its last use, so that no column is held twice."""
        out = np.empty((len(self.line_no), len(names)))
        for c, name in enumerate(names):
            k = self.where[name]
            for code, message, line in self.found[k]:
                self.error(code, message, line, name)
            self._more_rows(k, name)
            self.found[k] = []
            self.counts[k] = 0
            self.uses[k] -= 1
            out[:, c] = self.columns[k] if self.uses[k] else self.columns.pop(k)
        return out

    def _split(self, name: str) -> NDArray[np.str_]:
        for code, message, line in self.found[-2]:
            self.error(code, message, line, name)
        self._more_rows(-2, name)
        return self.labels

    def _orientation(self, values: Array, names: list[str], kind: str) -> Array | None:
        ok = self.good & np.all(np.isfinite(values), axis=1)
        if kind == "quaternion":
            norm = np.linalg.norm(values, axis=1)
            for i in self._listed(np.flatnonzero(ok & (np.abs(norm - 1.0) > 1e-2)), "quaternion", names[0]):
                self.error(
                    "quaternion",
                    f"quaternion ({', '.join(names)}) has norm {norm[i]:.6g}, not 1",
                    int(self.line_no[i]),
                    names[0],
                )
            if not self.ok:
                return None
            return spatial.quaternion_to_matrix(values)
        unit = self.A
        if kind.startswith("euler"):
            unit = unit_factor(kind.split(":")[2], "angle", "orientation")
        big = np.nanmax(np.abs(values), axis=0, initial=0.0) * unit
        fix = "angle_unit='deg'"
        if kind.startswith("euler"):
            fix = f"orientation={kind.rsplit(':', 1)[0] + ':deg'!r}"
        elif kind == "rotvec":  # read as a rotation vector by default: Euler angles in degrees?
            fix = (
                "orientation='euler:SEQ:deg' if they are Euler angles (e.g. 'euler:XYZ:deg', intrinsic; "
                "lower case for extrinsic), angle_unit='deg' if they are a rotation vector in degrees "
                "(joints in degrees too), or orientation='none' to ignore them"
            )
        for c in np.flatnonzero(big > 2 * math.pi + 1e-6):
            self.error(
                "angle-unit",
                f"orientation angles up to {big[c]:.4g} rad ({self._rows_text()}): "
                f"looks like degrees: pass {fix}",
                None,
                names[c],
            )
        if not self.ok:
            return None
        if kind == "rotvec":
            return spatial.rotvec_to_matrix(values * unit)
        return spatial.euler_to_matrix(values * unit, kind.split(":")[1])
