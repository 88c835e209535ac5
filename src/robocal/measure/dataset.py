"""Measurements: joint values and what a device observed, with CSV input and output.

A :class:`Measurements` holds one row per measured pose:

* ``q`` ``(n, dof)`` joint values (rad, or m for prismatic joints);
* optional ``position`` ``(n, 3)`` (m) and ``orientation`` ``(n, 3, 3)`` rotation
  matrices, both in the measuring device's own frame;
* optional per-row standard deviations ``sigma`` ``(n, 3)`` (m), a ``split`` label
  per row (``"train"``/``"test"``), a ``temperature`` (°C) and any ``extra``
  numeric columns kept by name;
* ``metadata``: device, frame, units and source file as plain strings.

CSV layout (DESIGN.md): columns ``q1..qN``, ``x, y, z`` and optionally
``qw, qx, qy, qz`` (or ``rx, ry, rz``), ``sx, sy, sz``, ``set`` and ``temperature``.
Files written by :func:`write_measurements` are SI with ``# key: value`` metadata
lines at the top.  A poses file (what to measure) is the same format with joint
columns only.

Reading (:func:`read_measurements`) converts units at the edge: lengths (positions,
standard deviations, prismatic joints) in ``length_unit``, angles (revolute joints,
rotation vectors, Euler angles) in ``angle_unit``.  Orientation columns are read as

* ``"quaternion"``: ``qw qx qy qz`` (scalar first, normalised on read);
* ``"rotvec"``: ``rx ry rz`` rotation vector (axis × angle);
* ``"euler:SEQ"`` or ``"euler:SEQ:UNIT"``: ``rx ry rz`` are Euler angles in scipy's
  sequence ``SEQ`` (upper case intrinsic, lower case extrinsic, see
  :mod:`robocal.spatial`); ``UNIT`` (``deg``/``rad``) overrides ``angle_unit`` for
  these columns only, for files whose joints are in rad and angles in degrees;
* ``"auto"`` (default): quaternion columns if present, else ``rx ry rz`` as a
  rotation vector; ``"none"`` ignores orientation columns.

The UR10 laser-tracker file (``shared/data/ur10_laser_tracker``) stores the T-Mac
orientation as ``measurement_rx/ry/rz`` in degrees.  They are **intrinsic** XYZ Euler
angles, ``R = Rx(rx) Ry(ry) Rz(rz)`` (``orientation="euler:XYZ:deg"``).  Found by
fitting ``R_measured = A · R_fk(q) · B`` (constant tracker rotation A and constant
flange-to-T-Mac rotation B) over all 11,910 rows: intrinsic XYZ leaves a residual of
0.10° median / 0.29° max (the arm's own orientation error), extrinsic ``xyz`` 2.6°
median and up to 172° (it breaks down near ry = -90°, where the file has many rows).
The robot's commanded ``Goal roll/pitch/yaw`` are extrinsic ``xyz`` (ROS RPY,
``R = Rz(yaw) Ry(pitch) Rx(roll)``): they agree with the nominal FK to 0.07° median
once the controller's base is turned by 180° about z and the tool by 90° about z, and
the measured XYZ angles agree with them to 0.12° median (tests/test_dataset.py).

Everything rejected names the file, the row (1-based line number in the file) and the
column.  :func:`check_measurements` lists all problems of a file at once.
"""

from __future__ import annotations

import csv
import dataclasses
import io
import math
import re
import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from robocal import csvfile, spatial
from robocal.model.chain import Model
from robocal.model.files import atomic_write_text, csv_text
from robocal.units import unit_factor

__all__ = [
    "MeasurementFileError",
    "MeasurementWarning",
    "Measurements",
    "Problem",
    "check_measurements",
    "read_measurements",
    "write_measurements",
]

Array = NDArray[np.float64]


#: A position column set whose median distance from the device origin (in m, after
#: conversion) exceeds this is taken to be in mm although read as m (50 m is beyond
#: any arm-calibration set-up).
MAX_MEDIAN_DISTANCE = 50.0
#: ... and below this (m) to be in m although read as mm: 5 mm from the device origin
#: for the median pose is implausible even for plate and paper frames, whose points lie
#: centimetres from their origin.
MIN_MEDIAN_DISTANCE = 0.005
#: Revolute joint values beyond this (rad) in magnitude look like degrees.
MAX_REVOLUTE_RAD = 4.0 * math.pi
#: Largest measurement file read (bytes): about five million poses; the file is read in
#: chunks (:mod:`robocal.csvfile`), its numbers kept as arrays: about twice their size in memory.
MAX_FILE_BYTES = 512 * 1024 * 1024
#: A stated measurement noise (1σ, m) must lie in [MIN_SIGMA, MAX_SIGMA]: 0 or a tiny σ
#: makes the weights infinite, a huge one makes them vanish
MIN_SIGMA = 1e-9
MAX_SIGMA = 1.0

Severity = Literal["error", "warning"]

#: The kinds of problem :func:`check_measurements` reports (``Problem.code``).
PROBLEM_CODES = {
    "file": "the file cannot be read",
    "header": "no header, or a column named twice",
    "columns": "a renamed or required column is absent, or a column group is incomplete",
    "missing-joint": "fewer joint columns than the robot has joints",
    "extra-joint": "more joint columns than the robot has joints",
    "no-data": "no data rows",
    "ragged": "a row with more or fewer cells than the header",
    "empty": "an empty cell",
    "not-a-number": "a cell that is not a number",
    "not-finite": "NaN or inf",
    "length-unit": "positions whose size suggests another length unit",
    "angle-unit": "angles whose size suggests degrees read as radians",
    "limits": "a joint value outside the robot's joint limits",
    "duplicate": "a row identical to an earlier one",
    "repeated-pose": "joint values repeated in a poses file (a warning)",
    "split": "a train/test label other than 'train' or 'test'",
    "quaternion": "a quaternion whose norm is not 1",
    "sigma": "a standard deviation that is negative, zero or out of range",
    "range": "a position farther than any device measures (more than 10 km)",
    "more": "further problems of several kinds in one column, beyond the first ones listed",
}
#: A measured position farther than this from the device (m) is a wrong cell, not a reach
MAX_POSITION = 1e4
LimitsMode = Literal["error", "warn", "ignore"]

_POSITION = ("x", "y", "z")
_QUATERNION = ("qw", "qx", "qy", "qz")
_ANGLES = ("rx", "ry", "rz")
_SIGMA = ("sx", "sy", "sz")
_KNOWN = {*_POSITION, *_QUATERNION, *_ANGLES, *_SIGMA, "set", "temperature"}


class MeasurementFileError(ValueError):
    """A measurement file could not be used; the message names file, row and column.

    Attributes:
        problems: every problem found (errors and warnings), as :class:`Problem`.
    """

    def __init__(self, message: str, problems: Sequence[Problem] = ()) -> None:
        super().__init__(message)
        self.problems = list(problems)


class MeasurementWarning(UserWarning):
    """A measurement file was read but something in it looks doubtful."""


@dataclass(frozen=True)
class Problem:
    """One problem found in a measurement file.

    Attributes:
        severity: ``"error"`` (the file is rejected) or ``"warning"``.
        code: the kind of problem, one of :data:`PROBLEM_CODES`.
        message: what is wrong, with a hint on how to fix it where one is known.
        file: the file.
        row: 1-based line number in the file (the header's line for header problems),
            or None when the problem concerns a whole column.
        column: the column's name as written in the file, or None for a whole row.
    """

    severity: Severity
    code: str
    message: str
    file: str
    row: int | None = None
    column: str | None = None

    def __str__(self) -> str:
        where = [self.file]
        loc = []
        if self.row is not None:
            loc.append(f"row {self.row}")
        if self.column is not None:
            loc.append(f"column {self.column!r}")
        if loc:
            where.append(", ".join(loc))
        return ": ".join([*where, self.message])


def _optional(a: ArrayLike | None, shape_tail: tuple[int, ...], n: int, what: str) -> Array | None:
    if a is None:
        return None
    a = np.asarray(a, dtype=float)
    if a.shape != (n, *shape_tail):
        raise ValueError(f"{what} shaped {a.shape}; expected {(n, *shape_tail)}")
    return a


@dataclass(frozen=True, eq=False)
class Measurements:
    """Joint values plus observations; immutable, arrays in SI units.

    Attributes:
        q: ``(n, dof)`` joint values (rad or m).
        position: ``(n, 3)`` measured positions (m) in the device frame, or None.
        orientation: ``(n, 3, 3)`` measured rotations in the device frame, or None.
        sigma: ``(n, 3)`` per-row position standard deviations (m) along the device
            axes, or None.
        split: ``(n,)`` labels ``"train"``/``"test"``, or None.
        temperature: ``(n,)`` °C, or None.
        extra: other numeric columns by name, each ``(n,)`` (as in the file, no unit
            conversion).
        joint_names: names of the joint columns in the source (default q1..qN).
        metadata: free-form strings (device, frame, units, file...).
    """

    q: Array
    position: Array | None = None
    orientation: Array | None = None
    sigma: Array | None = None
    split: NDArray[np.str_] | None = None
    temperature: Array | None = None
    extra: Mapping[str, Array] = field(default_factory=dict)
    joint_names: tuple[str, ...] = ()
    metadata: Mapping[str, str] = field(default_factory=dict)

    def __post_init__(self) -> None:
        q = np.asarray(self.q, dtype=float)
        if q.ndim != 2:
            raise ValueError(f"joint values must be (n, dof), got shape {q.shape}")
        n = q.shape[0]
        set_ = object.__setattr__
        set_(self, "q", q)
        set_(self, "position", _optional(self.position, (3,), n, "position"))
        set_(self, "orientation", _optional(self.orientation, (3, 3), n, "orientation"))
        set_(self, "sigma", _optional(self.sigma, (3,), n, "sigma"))
        set_(self, "temperature", _optional(self.temperature, (), n, "temperature"))
        if self.split is not None:
            split = np.asarray(self.split, dtype=str)
            if split.shape != (n,):
                raise ValueError(f"split shaped {split.shape}; expected ({n},)")
            bad = sorted(set(split.tolist()) - {"train", "test"})
            if bad:
                raise ValueError(f"split labels must be 'train' or 'test', got {bad}")
            set_(self, "split", split)
        set_(self, "extra", {k: _optional(v, (), n, f"column {k!r}") for k, v in self.extra.items()})
        names = tuple(self.joint_names) or tuple(f"q{j + 1}" for j in range(q.shape[1]))
        if len(names) != q.shape[1]:
            raise ValueError(f"{len(names)} joint names for {q.shape[1]} joint columns")
        set_(self, "joint_names", names)
        set_(self, "metadata", {str(k): str(v) for k, v in self.metadata.items()})

    @property
    def n(self) -> int:
        """Number of rows (poses)."""
        return self.q.shape[0]

    def __len__(self) -> int:
        return self.n

    @property
    def dof(self) -> int:
        return self.q.shape[1]

    @property
    def observes(self) -> Literal["joints", "position", "pose"]:
        """What the rows hold besides joints: ``"joints"`` only (a poses file),
        ``"position"`` or ``"pose"`` (position and orientation)."""
        if self.position is None:
            return "joints"
        return "position" if self.orientation is None else "pose"

    def subset(self, rows: ArrayLike) -> Measurements:
        """The rows selected by an index array or boolean mask, in that order."""
        idx = np.asarray(rows)
        if idx.dtype == bool:
            idx = np.flatnonzero(idx)

        def take(a):
            return None if a is None else a[idx]

        return dataclasses.replace(
            self,
            q=self.q[idx],
            position=take(self.position),
            orientation=take(self.orientation),
            sigma=take(self.sigma),
            split=take(self.split),
            temperature=take(self.temperature),
            extra={k: v[idx] for k, v in self.extra.items()},
        )

    def split_rows(self, label: str) -> Measurements:
        """Rows whose ``split`` label is ``label`` (``"train"`` or ``"test"``)."""
        if self.split is None:
            raise ValueError("these measurements have no train/test split column")
        return self.subset(self.split == label)

    def with_split(self, n_train: int, seed: int | None = 0) -> Measurements:
        """A copy labelled with ``n_train`` random training rows (seeded), the rest test."""
        if not 0 < n_train <= self.n:
            raise ValueError(f"n_train={n_train} must be in 1..{self.n}")
        rng = np.random.default_rng(seed)
        split = np.full(self.n, "test", dtype="<U5")
        split[rng.choice(self.n, n_train, replace=False)] = "train"
        return dataclasses.replace(self, split=split)


# ------------------------------------------------------------------------ writing
def _fmt(v: float) -> str:
    return repr(float(v))


def write_measurements(data: Measurements, path: str | Path, run_id: str | None = None) -> Path:
    """Write ``data`` as CSV (SI units, ``,`` separator) atomically; ``run_id`` stamps it as
    one file of a set written together (a ``# robocal run: ID`` first line; a run id read
    with the data is never copied into another file).

    Columns: joint names as ``q1..qN``, then ``x y z``, ``qw qx qy qz``, ``sx sy sz``,
    ``temperature``, extra columns and ``set`` when present.  Floats are written with
    shortest round-trip formatting, so reading the file back gives the same numbers.
    """
    header = [f"q{j + 1}" for j in range(data.dof)]
    cols: list[Array] = [data.q]
    if data.position is not None:
        header += ["x", "y", "z"]
        cols.append(data.position)
    if data.orientation is not None:
        header += ["qw", "qx", "qy", "qz"]
        cols.append(spatial.matrix_to_quaternion(data.orientation))
    if data.sigma is not None:
        header += ["sx", "sy", "sz"]
        cols.append(data.sigma)
    if data.temperature is not None:
        header.append("temperature")
        cols.append(data.temperature[:, None])
    for name, values in data.extra.items():
        header.append(name)
        cols.append(values[:, None])
    table = np.concatenate(cols, axis=1) if cols else np.zeros((data.n, 0))
    buf = io.StringIO()
    meta = dict(data.metadata)
    meta.pop("robocal run", None)
    meta.setdefault("units", "m, rad")
    if run_id is not None:
        buf.write(f"# robocal run: {run_id}\n")
    if data.joint_names != tuple(header[: data.dof]):
        meta["joints"] = " ".join(data.joint_names)
    for key, value in meta.items():
        buf.write(f"# {key}: {' '.join(str(value).split())}\n")
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow([csv_text(h) for h in header] + (["set"] if data.split is not None else []))
    for i, row in enumerate(table):
        cells = [_fmt(v) for v in row]
        if data.split is not None:
            cells.append(str(data.split[i]))
        writer.writerow(cells)
    return atomic_write_text(path, buf.getvalue())


# ------------------------------------------------------------------------ reading
@dataclass(frozen=True)
class _Orientation:
    kind: Literal["auto", "none", "quaternion", "rotvec", "euler"]
    seq: str = ""
    unit: str | None = None


def _parse_orientation(spec: str) -> _Orientation:
    text = str(spec).strip()
    low = text.lower()
    if low in ("auto", "none", "rotvec"):
        return _Orientation(low)  # type: ignore[arg-type]
    if low in ("quaternion", "quat"):
        return _Orientation("quaternion")
    if low.startswith("euler"):
        parts = text.split(":")
        if len(parts) not in (2, 3) or parts[0].lower() != "euler":
            raise ValueError(f"orientation={spec!r}: expected 'euler:SEQ' or 'euler:SEQ:deg'")
        seq = parts[1]
        if not re.fullmatch(r"[xyz]{3}|[XYZ]{3}", seq) or seq[0] == seq[1] or seq[1] == seq[2]:
            raise ValueError(
                f"orientation={spec!r}: Euler sequence {seq!r} must be three axes, all upper case "
                "(intrinsic, e.g. 'XYZ') or all lower case (extrinsic, e.g. 'xyz'), no axis twice in a row"
            )
        unit = parts[2].lower() if len(parts) == 3 else None
        if unit is not None:
            unit_factor(unit, "angle", f"orientation={spec!r}")
        return _Orientation("euler", seq, unit)
    raise ValueError(
        f"orientation={spec!r}: expected 'auto', 'none', 'quaternion', 'rotvec', 'euler:SEQ' "
        "or 'euler:SEQ:UNIT'"
    )


def _parse_columns(columns: Mapping[str, str] | Sequence[str] | str | None) -> dict[str, str]:
    """Renames robocal name -> file column from a mapping, ``["q1=a", ...]`` or ``"q1=a,q2=b"``."""
    if columns is None:
        return {}
    if isinstance(columns, Mapping):
        return {str(k).strip(): str(v).strip() for k, v in columns.items()}
    items = columns.split(",") if isinstance(columns, str) else list(columns)
    out = {}
    for item in items:
        if not str(item).strip():
            continue
        if "=" not in item:
            raise ValueError(f"column rename {item!r} must look like 'q1=shoulder_pan_joint'")
        k, v = item.split("=", 1)
        out[k.strip()] = v.strip()
    return out


_short = csvfile.short


#: Problems that make a row incomplete: with ``incomplete="drop"`` the row is left out.
INCOMPLETE_CODES = frozenset({"empty", "not-a-number", "not-finite", "ragged"})
IncompleteMode = Literal["error", "drop"]

#: Problems of one kind listed at most (one more line counts the rest): a file with a
#: million bad cells must not cost a million messages' memory.
MAX_LISTED = 1000

#: Names a separator may be given by (on a command line a tab is hard to type).
SEPARATOR_NAMES = {"tab": "\t", "\\t": "\t", "space": " ", "whitespace": " ", "semicolon": ";", "comma": ","}


class _Reader:
    """One pass over a file that collects every problem instead of stopping at the first."""

    def __init__(
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
        self.rename = _parse_columns(columns)
        self.sep, self.decimal = sep, decimal
        self.dof, self.model, self.limits = dof, model, limits
        self.orientation = _parse_orientation(orientation)
        self.extra_names = list(extra)
        self.incomplete = incomplete
        self.problems: list[Problem] = []

    # -- problem helpers
    def error(self, code: str, message: str, row: int | None = None, column: str | None = None) -> None:
        if self.incomplete == "drop" and code in INCOMPLETE_CODES and row is not None:
            self.warn(code, f"{message}; row left out (incomplete='drop')", row, column)
            return
        if code in INCOMPLETE_CODES and row is not None:
            message += " (incomplete='drop' leaves such rows out)"
        self.problems.append(Problem("error", code, message, str(self.path), row, column))

    def warn(self, code: str, message: str, row: int | None = None, column: str | None = None) -> None:
        self.problems.append(Problem("warning", code, message, str(self.path), row, column))

    @property
    def ok(self) -> bool:
        return not any(p.severity == "error" for p in self.problems)

    # -- the pass
    def read(self) -> Measurements | None:
        path = self.path
        if path.exists() and not path.is_file():  # a directory, FIFO or device (which never ends)
            self.error("file", "not a regular file")
            return None
        if path.exists() and path.stat().st_size > MAX_FILE_BYTES:
            self.error(
                "file",
                f"{path.stat().st_size} bytes is more than the {MAX_FILE_BYTES} a measurement file may have",
            )
            return None
        try:
            head = csvfile.read_head(path, sep=self.sep, decimal=self.decimal)
        except FileNotFoundError:
            self.error("file", "file not found")
            return None
        except csvfile.CsvError as err:
            self.error(err.code, err.message, err.line)
            return None
        self.head = head
        metadata = dict(head.metadata)
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

        cols = self._resolve_columns()
        if cols is None:
            return None
        if not self._stream(cols):
            return None
        if not len(self.line_no):
            self.error("no-data", "no data rows after the header", self.header_line)
            return None
        good = self.good

        joint_cols, joint_scale = cols["joints"], cols["joint_scale"]
        q = self._numbers(joint_cols)
        q *= joint_scale  # in place: the arrays are not copied
        position = sigma = orientation = temperature = None
        if cols["position"]:
            position = self._numbers(cols["position"])
            position *= self.L
        if cols["sigma"]:
            sigma = self._numbers(cols["sigma"])
            sigma *= self.L
            bad = good[:, None] & np.isfinite(sigma) & ((sigma < MIN_SIGMA) | (sigma > MAX_SIGMA))
            for i, c in self._listed(np.argwhere(bad), "sigma", cols["sigma"][0]):
                cell = self._cell(i, cols["sigma"][c])
                self.error(
                    "sigma",
                    f"standard deviation {cell!r} is negative"
                    if sigma[i, c] < 0
                    else f"standard deviation {cell!r} is outside {MIN_SIGMA * 1e3:g}..{MAX_SIGMA * 1e3:g} "
                    "mm "
                    "(leave the sigma columns out when the noise is not known)",
                    int(self.line_no[i]),
                    cols["sigma"][c],
                )
        ori_cols = cols["orientation"]
        ori_values = self._numbers(ori_cols) if ori_cols else None
        if cols["temperature"]:
            temperature = self._numbers(cols["temperature"])[:, 0]
        extra = {name: self._numbers([name])[:, 0] for name in cols["extra"]}
        split = self._split(cols["set"]) if cols["set"] else None

        if ori_values is not None:
            orientation = self._orientation(ori_values, ori_cols, cols["orientation_kind"])
            del ori_values  # the rotation matrices are kept, not the columns they were made from

        if position is not None:
            self._check_length_unit(position, cols["position"])
        self._check_joints(q, joint_cols)
        ori_flat = None if orientation is None else orientation.reshape(len(orientation), 9)  # a view
        self._check_duplicates(q, position, ori_flat, sigma, split)

        if not self.ok:
            return None
        dropped = int(self.incomplete_rows.sum()) if self.incomplete == "drop" else 0
        if dropped:  # incomplete='drop': the rows with a missing or bad value go
            if dropped == len(self.line_no):
                self.error("no-data", "every data row has a missing or bad value")
                return None
            keep = ~self.incomplete_rows
            # one array at a time, so that each earlier one is freed before the next is copied
            q = q[keep]
            position = None if position is None else position[keep]
            sigma = None if sigma is None else sigma[keep]
            split = None if split is None else split[keep]
            temperature = None if temperature is None else temperature[keep]
            orientation = None if orientation is None else orientation[keep]
            extra = {name: values[keep] for name, values in extra.items()}
            metadata["rows_left_out"] = str(dropped)
        joint_names = tuple(metadata.pop("joints", "").split())
        if len(joint_names) != len(joint_cols):
            joint_names = tuple(joint_cols)
        metadata.setdefault("file", str(path))
        metadata["read_units"] = f"{self.length_unit}, {self.angle_unit}"
        used = {c for key in ("joints", "position", "sigma", "orientation", "temperature", "extra", "set")
                for c in (cols.get(key) or [])}  # fmt: skip
        unused = [h for h in self.header if h and h not in used]
        if unused:
            metadata["unused_columns"] = ", ".join(unused)
        if orientation is not None:
            metadata["read_orientation"] = cols["orientation_kind"]
        return Measurements(
            q=q,
            position=position,
            orientation=orientation,
            sigma=sigma,
            split=split,
            temperature=temperature,
            extra=extra,
            joint_names=joint_names,
            metadata=metadata,
        )

    def _listed(self, items, code: str, column: str | None, severity: Severity = "error"):
        """The first :data:`MAX_LISTED` of ``items`` (problems of one kind); one line counts
        the rest, so that a file with a million bad cells costs no more memory."""
        self._summary(code, len(items) - MAX_LISTED, column, severity)
        return items[:MAX_LISTED]

    def _summary(self, code: str, more: int, column: str | None, severity: Severity) -> None:
        if more > 0:
            message = f"and {more} more row(s) with such problems (only the first {MAX_LISTED} are listed)"
            if severity == "warning":
                message += "; left out (incomplete='drop')"
            self.problems.append(Problem(severity, code, message, str(self.path), None, column))

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

        for chunk in csvfile.iter_chunks(self.head):
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
                for i in np.flatnonzero(ok & ~valid):
                    raw = chunk.rows[i][set_k].strip()
                    message = f"{_short(raw)} is not a train/test label (expected 'train' or 'test')"
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
    def _cell(self, i: int, name: str) -> str:
        """Row ``i``'s cell of column ``name`` as written (read again from the file)."""
        cells = csvfile.row_at(self.head, int(self.offsets[i]))
        k = self.where[name]
        return cells[k].strip() if k < len(cells) else ""

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

    def _header_text(self, limit: int = 20) -> str:
        shown = ", ".join(self.header[:limit])
        return shown + (f", ... ({len(self.header)} columns)" if len(self.header) > limit else "")

    # -- columns
    def _col(self, name: str) -> str:
        return self.rename.get(name, name)

    def _has(self, name: str) -> bool:
        return self._col(name) in self.where

    def _resolve_columns(self) -> dict | None:
        hl = self.header_line
        model = self.model
        joint_like = re.compile(r"q(\d+)$")
        known_keys = set(_KNOWN) | set(model.joint_names if model else ())
        for key, target in self.rename.items():
            if not (key in known_keys or joint_like.match(key)):
                raise ValueError(
                    f"columns: {key!r} is not a robocal column name (q1.., x y z, qw qx qy qz, "
                    f"rx ry rz, sx sy sz, set, temperature{', model joint names' if model else ''})"
                )
            if target not in self.where:
                self.error(
                    "columns",
                    f"column {target!r} (given for {key!r} in columns=) is not in the header; header: "
                    f"{self._header_text()}",
                    hl,
                    target,
                )
        # joints
        joints: list[str] = []
        if model is not None:
            missing = []
            for j, jname in enumerate(model.joint_names):
                candidates = [self.rename.get(f"q{j + 1}"), self.rename.get(jname), f"q{j + 1}", jname]
                found = next((c for c in candidates if c is not None and c in self.where), None)
                if found is None:
                    missing.append(f"q{j + 1} ({jname})")
                else:
                    joints.append(found)
            if missing:
                self.error(
                    "missing-joint",
                    f"missing joint column(s) {', '.join(missing)}: model {model.name!r} has "
                    f"{model.dof} joints ({', '.join(model.joint_names)}); rename with e.g. "
                    f"columns={{'q1': '<file column>'}}; header is {self._header_text()}",
                    hl,
                )
            dof = model.dof
        else:
            dof = self.dof
            if dof is None:
                dof = 0
                while self._has(f"q{dof + 1}"):
                    dof += 1
            missing = [f"q{j + 1}" for j in range(dof) if not self._has(f"q{j + 1}")]
            if missing:
                self.error(
                    "missing-joint",
                    f"missing joint column(s) {', '.join(missing)} (expected {dof} joints)",
                    hl,
                )
            joints = [self._col(f"q{j + 1}") for j in range(dof) if self._has(f"q{j + 1}")]
            if dof == 0:
                self.error(
                    "missing-joint",
                    "no joint columns: expected q1, q2, ... (or renames such as "
                    f"columns={{'q1': 'shoulder_pan_joint'}}); header is {self._header_text()}",
                    hl,
                )
        # joint-like columns beyond the model's or the counted joints
        if model is not None:
            expected = f"model {model.name!r} has {dof} joints ({', '.join(model.joint_names)})"
        elif self.dof is not None:
            expected = f"dof={dof} joints expected"
        else:
            expected = f"joints are read as q1..q{dof} while present, and q{dof + 1} is missing"
        for name in self.header:
            m = joint_like.match(name)
            if m and int(m.group(1)) > dof and name not in self.rename.values():
                self.error("extra-joint", f"extra joint column {name!r}: {expected}", hl, name)
        for key in self.rename:
            m = joint_like.match(key)
            if m and int(m.group(1)) > dof:
                self.error(
                    "extra-joint",
                    f"extra joint column {self.rename[key]!r} (given for {key!r}): {expected}",
                    hl,
                    self.rename[key],
                )
        types = model.joint_types if model is not None else ("revolute",) * len(joints)
        joint_scale = np.array([self.A if t == "revolute" else self.L for t in types[: len(joints)]])

        def group(names: Sequence[str], what: str, required: bool = False) -> list[str]:
            present = [n for n in names if self._has(n)]
            if (present and len(present) < len(names)) or (required and not present):
                absent = [self._col(n) for n in names if not self._has(n)]
                listed = ", ".join(map(self._col, names))
                self.error(
                    "columns", f"{what} needs columns {listed}; missing {', '.join(absent)}", hl, absent[0]
                )
                return []
            return [self._col(n) for n in names] if present else []

        position = group(_POSITION, "a position")
        sigma = group(_SIGMA, "a per-row standard deviation")
        ori = self.orientation
        ori_cols: list[str] = []
        kind = ""
        if ori.kind == "auto":
            if any(self._has(n) for n in _QUATERNION):
                ori_cols, kind = group(_QUATERNION, "a quaternion"), "quaternion"
            elif any(self._has(n) for n in _ANGLES):
                ori_cols, kind = group(_ANGLES, "a rotation vector"), "rotvec"
        elif ori.kind == "quaternion":
            ori_cols, kind = group(_QUATERNION, "orientation='quaternion'", True), "quaternion"
        elif ori.kind == "rotvec":
            ori_cols, kind = group(_ANGLES, "orientation='rotvec'", True), "rotvec"
        elif ori.kind == "euler":
            ori_cols = group(_ANGLES, f"orientation='euler:{ori.seq}'", True)
            kind = f"euler:{ori.seq}:{ori.unit or self.angle_unit}"
        if ori_cols and not position:
            self.error("columns", "orientation columns without position columns x, y, z", hl, ori_cols[0])
        for name in self.extra_names:
            if name not in self.where:
                self.error("columns", f"column {name!r} (asked for in extra=) is not in the header", hl, name)
        if not self.ok:
            return None
        return {
            "joints": joints,
            "joint_scale": joint_scale,
            "position": position,
            "sigma": sigma,
            "orientation": ori_cols,
            "orientation_kind": kind,
            "temperature": [self._col("temperature")] if self._has("temperature") else [],
            "set": self._col("set") if self._has("set") else None,
            "extra": [n for n in self.extra_names if n in self.where],
        }

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

    # -- checks across rows
    def _rows_text(self) -> str:
        return f"rows {self.line_no[0]}-{self.line_no[-1]}"

    def _check_length_unit(self, position: Array, names: list[str]) -> None:
        with np.errstate(over="ignore", invalid="ignore"):
            far = np.isfinite(position) & (np.abs(position) > MAX_POSITION)  # NaN/inf: reported already
        for i, c in np.argwhere(far)[:10]:
            self.error(
                "range",
                f"{_short(self._cell(int(i), names[c]))} {self.length_unit} is farther than any device "
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


def _collect(path: str | Path, options: dict) -> tuple[Measurements | None, list[Problem]]:
    reader = _Reader(Path(path), **options)
    data = reader.read()
    return data, reader.problems


def _options(
    length_unit: str = "m",
    angle_unit: str = "rad",
    columns: Mapping[str, str] | Sequence[str] | str | None = None,
    sep: str | None = None,
    decimal: str = ".",
    dof: int | None = None,
    model: Model | None = None,
    limits: LimitsMode = "error",
    orientation: str = "auto",
    extra: Sequence[str] = (),
    incomplete: IncompleteMode = "error",
) -> dict:
    return dict(
        incomplete=incomplete,
        length_unit=length_unit,
        angle_unit=angle_unit,
        columns=columns,
        sep=sep,
        decimal=decimal,
        dof=dof,
        model=model,
        limits=limits,
        orientation=orientation,
        extra=extra,
    )


def read_measurements(
    path: str | Path,
    *,
    length_unit: str = "m",
    angle_unit: str = "rad",
    columns: Mapping[str, str] | Sequence[str] | str | None = None,
    sep: str | None = None,
    decimal: str = ".",
    dof: int | None = None,
    model: Model | None = None,
    limits: LimitsMode = "error",
    orientation: str = "auto",
    extra: Sequence[str] = (),
    incomplete: IncompleteMode = "error",
) -> Measurements:
    """Read a measurement (or poses) CSV file; all or nothing (or the complete rows).

    Args:
        path: the file.
        length_unit: ``"m"``, ``"mm"`` or ``"um"`` for positions, standard deviations
            and prismatic joint values.
        angle_unit: ``"rad"`` or ``"deg"`` for revolute joint values and orientation
            angles (see ``orientation`` for a separate unit of Euler angles).
        columns: renames from robocal's column names to the file's, e.g.
            ``{"q1": "shoulder_pan_joint", "x": "measurement_x"}``,
            ``["q1=shoulder_pan_joint", ...]`` or ``"q1=shoulder_pan_joint,x=measurement_x"``.
            With a model, joint columns may also be keyed (or named in the file) by the
            model's joint names.
        sep: column separator; sniffed from the header when None (``;`` tab ``,``).
        decimal: decimal mark, ``"."`` or ``","`` (real exports use ``;`` and ``,``).
        dof: expected number of joint columns when no model is given; when None,
            ``q1, q2, ...`` are taken while present.
        model: the robot; the file must then have exactly its joints (missing and extra
            joint columns are named), prismatic joints are read in ``length_unit`` and
            revolute ones in ``angle_unit``, and values are checked against its limits.
        limits: what a joint value outside the model's limits is: ``"error"``,
            ``"warn"`` (a :class:`MeasurementWarning`) or ``"ignore"``.
        orientation: ``"auto"``, ``"none"``, ``"quaternion"``, ``"rotvec"``,
            ``"euler:SEQ"`` or ``"euler:SEQ:UNIT"`` (module docstring).
        extra: further numeric columns to keep, by their names in the file, in
            :attr:`Measurements.extra` (unconverted).
        incomplete: a row with an empty, non-numeric or non-finite cell or the wrong
            number of cells is an error (``"error"``) or is left out with a warning
            (``"drop"``: a tracker that lost the beam leaves such rows); the number left
            out is in ``metadata["rows_left_out"]``.

    Returns:
        :class:`Measurements` in SI units; ``metadata`` has the ``# key: value`` lines
        of the file, ``file`` and the units and orientation convention read.

    Raises:
        MeasurementFileError: naming the file, row (1-based line number) and column of
            the first error, with every problem in ``.problems``.  Rejected: NaN/inf,
            empty and non-numeric cells, ragged rows, missing/extra joint columns,
            incomplete column groups, joint values outside the limits (unless
            ``limits`` says otherwise), duplicated rows, positions or angles whose size
            suggests the wrong unit, non-unit quaternions, negative standard
            deviations, train/test labels other than ``train``/``test``.  Repeated joint
            values in a joints-only (poses) file are only warned about: repeating a
            pose is how repeatability is measured.
        ValueError: on invalid options.
    """
    opts = _options(
        length_unit, angle_unit, columns, sep, decimal, dof, model, limits, orientation, extra, incomplete
    )
    data, problems = _collect(path, opts)
    errors = [p for p in problems if p.severity == "error"]
    if errors or data is None:
        more = f" (and {len(errors) - 1} more problem(s); `robocal data check` lists them all)"
        raise MeasurementFileError(str(errors[0]) + (more if len(errors) > 1 else ""), problems)
    found = [p for p in problems if p.severity == "warning"]
    if found:
        shown = "\n".join(f"  {p}" for p in found[:10])
        rest = f"\n  ... and {len(found) - 10} more" if len(found) > 10 else ""
        warnings.warn(
            MeasurementWarning(f"{len(found)} warning(s) reading {path}:\n{shown}{rest}"), stacklevel=2
        )
    return data


def check_measurements(path: str | Path, model: Model | None = None, **read_options) -> list[Problem]:
    """Every problem of a measurement file (errors and warnings), in file order.

    Takes the options of :func:`read_measurements`; an empty list means the file reads
    cleanly.  ``limits`` defaults to ``"error"`` as in :func:`read_measurements`.
    """
    opts = _options(model=model, **read_options)
    _, problems = _collect(path, opts)
    return sorted(problems, key=lambda p: (p.row is not None, p.row or 0))
