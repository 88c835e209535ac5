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
``qw, qx, qy, qz`` (or ``rx, ry, rz`` as a rotation vector), ``sx, sy, sz``, ``set``
and ``temperature``.  Files written by :func:`write_measurements` are SI with
``# key: value`` metadata lines at the top.  A poses file (what to measure) is the
same format with joint columns only.
"""

from __future__ import annotations

import csv
import dataclasses
import io
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray

from robocal import spatial
from robocal.model.files import atomic_write_text

__all__ = ["MeasurementFileError", "Measurements", "read_measurements", "write_measurements"]

Array = NDArray[np.float64]

LENGTH_UNITS = {"m": 1.0, "mm": 1e-3}
ANGLE_UNITS = {"rad": 1.0, "deg": math.pi / 180.0}


class MeasurementFileError(ValueError):
    """A measurement file could not be used; the message names file, row and column."""


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
        sigma: ``(n, 3)`` per-row position standard deviations (m), or None.
        split: ``(n,)`` labels ``"train"``/``"test"``, or None.
        temperature: ``(n,)`` °C, or None.
        extra: other numeric columns by name, each ``(n,)``.
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


def write_measurements(data: Measurements, path: str | Path) -> Path:
    """Write ``data`` as CSV (SI units, ``,`` separator) atomically.

    Columns: joint names as ``q1..qN``, then ``x y z``, ``qw qx qy qz``, ``sx sy sz``,
    ``temperature``, extra columns and ``set`` when present.
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
    meta.setdefault("units", "m, rad")
    if data.joint_names != tuple(header[: data.dof]):
        meta["joints"] = " ".join(data.joint_names)
    for key, value in meta.items():
        buf.write(f"# {key}: {value}\n")
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(header + (["set"] if data.split is not None else []))
    for i, row in enumerate(table):
        cells = [_fmt(v) for v in row]
        if data.split is not None:
            cells.append(str(data.split[i]))
        writer.writerow(cells)
    return atomic_write_text(path, buf.getvalue())


# ------------------------------------------------------------------------ reading
def read_measurements(
    path: str | Path,
    *,
    length_unit: str = "m",
    angle_unit: str = "rad",
    columns: Mapping[str, str] | Sequence[str] | None = None,
    sep: str | None = None,
    decimal: str = ".",
    dof: int | None = None,
) -> Measurements:
    """Read a measurement (or poses) CSV file.

    Args:
        path: the file.
        length_unit: ``"m"`` or ``"mm"`` for positions and standard deviations.
        angle_unit: ``"rad"`` or ``"deg"`` for revolute joint values and rotation
            vectors.
        columns: renames from robocal's column names to the file's, e.g.
            ``{"q1": "shoulder_pan_joint", "x": "measurement_x"}`` or
            ``["q1=shoulder_pan_joint", ...]``.
        sep: column separator; sniffed from the header when None (``,`` ``;`` tab).
        decimal: decimal mark, ``"."`` or ``","`` (real exports use ``;`` and ``,``).
        dof: expected number of joint columns; when None, ``q1, q2, ...`` are taken
            while present.

    Raises:
        MeasurementFileError: naming the file, row (1-based line number) and column.
    """
    path = Path(path)
    if length_unit not in LENGTH_UNITS:
        raise ValueError(f"length_unit must be one of {sorted(LENGTH_UNITS)}, got {length_unit!r}")
    if angle_unit not in ANGLE_UNITS:
        raise ValueError(f"angle_unit must be one of {sorted(ANGLE_UNITS)}, got {angle_unit!r}")
    rename = _parse_columns(columns)
    text = path.read_text(encoding="utf-8-sig")
    lines = text.splitlines()
    metadata: dict[str, str] = {}
    first = 0
    while first < len(lines) and (lines[first].startswith("#") or not lines[first].strip()):
        line = lines[first].lstrip("#").strip()
        if ":" in line:
            key, value = line.split(":", 1)
            metadata[key.strip()] = value.strip()
        first += 1
    if first >= len(lines):
        raise MeasurementFileError(f"{path}: no header row")
    if sep is None:
        header_line = lines[first]
        sep = max((";", "\t", ","), key=header_line.count)
    reader = csv.reader(lines[first:], delimiter=sep)
    header = [h.strip() for h in next(reader)]
    where = {name: k for k, name in enumerate(header)}
    for dup in {h for h in header if header.count(h) > 1}:
        raise MeasurementFileError(f"{path}: column {dup!r} appears more than once in the header")

    def col(name: str) -> str:
        return rename.get(name, name)

    def has(name: str) -> bool:
        return col(name) in where

    if dof is None:
        dof = 0
        while has(f"q{dof + 1}"):
            dof += 1
    if dof == 0:
        raise MeasurementFileError(
            f"{path}: no joint columns: expected q1, q2, ... (or renames such as "
            f"columns={{'q1': 'shoulder_pan_joint'}}); header is {header}"
        )
    missing = [f"q{j + 1}" for j in range(dof) if not has(f"q{j + 1}")]
    if missing:
        raise MeasurementFileError(f"{path}: missing joint column(s) {', '.join(col(m) for m in missing)}")

    rows = [r for r in reader]
    body_start = first + 2  # 1-based line number of the first data row

    def numbers(names: list[str]) -> Array:
        out = np.empty((len(rows), len(names)))
        for c, name in enumerate(names):
            k = where[col(name)]
            for i, r in enumerate(rows):
                cell = r[k].strip() if k < len(r) else ""
                if decimal == ",":
                    cell = cell.replace(",", ".")
                try:
                    v = float(cell)
                except ValueError:
                    raise MeasurementFileError(
                        f"{path}: row {body_start + i}, column {col(name)!r}: {cell!r} is not a number"
                    ) from None
                if not math.isfinite(v):
                    raise MeasurementFileError(
                        f"{path}: row {body_start + i}, column {col(name)!r}: value {cell!r} is not finite"
                    )
                out[i, c] = v
        return out

    for i, r in enumerate(rows):
        if len(r) != len(header) and any(cell.strip() for cell in r):
            raise MeasurementFileError(
                f"{path}: row {body_start + i} has {len(r)} cells but the header has {len(header)}"
            )
    L, A = LENGTH_UNITS[length_unit], ANGLE_UNITS[angle_unit]
    q = numbers([f"q{j + 1}" for j in range(dof)]) * A
    position = numbers(["x", "y", "z"]) * L if all(has(c) for c in "xyz") else None
    orientation = None
    if all(has(c) for c in ("qw", "qx", "qy", "qz")):
        orientation = spatial.quaternion_to_matrix(numbers(["qw", "qx", "qy", "qz"]))
    elif all(has(c) for c in ("rx", "ry", "rz")):
        orientation = spatial.rotvec_to_matrix(numbers(["rx", "ry", "rz"]) * A)
    sigma = numbers(["sx", "sy", "sz"]) * L if all(has(c) for c in ("sx", "sy", "sz")) else None
    temperature = numbers(["temperature"])[:, 0] if has("temperature") else None
    split = None
    if has("set"):
        k = where[col("set")]
        split = np.array([r[k].strip().lower() for r in rows])
        bad = [i for i, s in enumerate(split) if s not in ("train", "test")]
        if bad:
            raise MeasurementFileError(
                f"{path}: row {body_start + bad[0]}, column {col('set')!r}: "
                f"{rows[bad[0]][k]!r} is not 'train' or 'test'"
            )
    joint_names = tuple(metadata.pop("joints", "").split()) or tuple(col(f"q{j + 1}") for j in range(dof))
    if len(joint_names) != dof:
        joint_names = tuple(col(f"q{j + 1}") for j in range(dof))
    metadata.setdefault("file", str(path))
    return Measurements(
        q=q,
        position=position,
        orientation=orientation,
        sigma=sigma,
        split=split,
        temperature=temperature,
        joint_names=joint_names,
        metadata=metadata,
    )


def _parse_columns(columns: Mapping[str, str] | Sequence[str] | None) -> dict[str, str]:
    if columns is None:
        return {}
    if isinstance(columns, Mapping):
        return {str(k): str(v) for k, v in columns.items()}
    out = {}
    for item in columns:
        if "=" not in item:
            raise ValueError(f"column rename {item!r} must look like 'q1=shoulder_pan_joint'")
        k, v = item.split("=", 1)
        out[k.strip()] = v.strip()
    return out
