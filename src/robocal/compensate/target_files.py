"""Files of targets and joint programs for compensation: CSV with ``x, y, z`` (and
``qw..qz``) or ``q1..qN`` columns, read through :mod:`robocal.csvfile`; errors name the
file, the row and the column."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from robocal import csvfile, spatial
from robocal.identify.result import CalibrationResult
from robocal.measure.ik_starts import TargetKind
from robocal.model.chain import Model
from robocal.units import joint_unit_factors, unit_factor

__all__ = ["TargetFileError", "Targets", "read_program", "read_targets"]

Array = NDArray[np.float64]
Calibrated = CalibrationResult | Model
Frame = Literal["base", "measurement"]


# ---------------------------------------------------------------------- files
class TargetFileError(ValueError):
    """A targets/program file that cannot be used; the message names file, row and column."""


@dataclass(frozen=True)
class Targets:
    """Targets read from a file: ``names`` and ``(n, 3)`` positions or ``(n, 4, 4)``
    frames (m) in the file's frame; ``kind`` ``"position"`` or ``"pose"``."""

    names: tuple[str, ...]
    values: Array
    kind: TargetKind


def _read_head(path: Path, sep: str | None, decimal: str) -> csvfile.Head:
    """The header of a targets file (:mod:`robocal.csvfile`: ``#`` lines and blank lines
    are skipped, the separator is sniffed among ``, ; tab``)."""
    try:
        head = csvfile.read_head(path, sep=sep, decimal=decimal, candidates=(",", ";", "\t"), spaces=False)
    except OSError as err:
        raise TargetFileError(f"{path}: cannot read: {err.strerror or err}") from None
    except csvfile.CsvError as err:
        what = "no header line" if err.message.startswith("no header row") else err.message
        raise TargetFileError(f"{path}: {what}") from None
    if decimal == "," and head.sep == ",":
        raise TargetFileError(f"{path}: decimal comma needs another separator (--sep ';')")
    return head


def _read_columns(
    head: csvfile.Head, header: list[str], cols: list[str], decimal: str
) -> tuple[Array, tuple[str, ...], list[int]]:
    """``(n, len(cols))`` numbers of columns ``cols``, the row names (the ``name`` column,
    else the line number) and the line numbers, chunk by chunk; the first bad row or cell
    is an error naming it."""
    path, idx = head.path, [header.index(c) for c in cols]
    name_k = header.index("name") if "name" in header else None
    blocks: list[Array] = []
    names: list[str] = []
    lines: list[int] = []
    for chunk in csvfile.iter_chunks(head):
        for i, code, message in chunk.problems[:1]:
            width = len(chunk.rows[i])
            what = message if code != "ragged" else f"{width} fields, the header has {len(header)}"
            raise TargetFileError(f"{path}, row {chunk.line[i]}: {what}")
        block = np.empty((len(chunk), len(cols)))
        for c, (col, k) in enumerate(zip(cols, idx, strict=True)):
            block[:, c], problems = csvfile.to_numbers([r[k] for r in chunk.rows], decimal)
            for m, code, _ in problems[:1]:
                text = chunk.rows[m][k].strip()
                what = "is not finite" if code == "not-finite" else "is not a number"
                raise TargetFileError(f"{path}, row {chunk.line[m]}, column {col!r}: {text!r} {what}")
        blocks.append(block)
        lines += chunk.line.tolist()
        if name_k is not None:
            rows_lines = zip(chunk.rows, chunk.line.tolist(), strict=True)
            names += [r[name_k].strip() or str(no) for r, no in rows_lines]
    values = np.concatenate(blocks) if blocks else np.zeros((0, len(cols)))
    if name_k is None:
        names = [str(k + 1) for k in range(len(values))]
    return values, tuple(names), lines


def read_targets(
    path: str | Path, *, length_unit: str = "m", sep: str | None = None, decimal: str = "."
) -> Targets:
    """Targets from a CSV file with columns ``name,x,y,z`` and optionally
    ``qw,qx,qy,qz`` (tool orientation, scalar first; normalised).

    Args:
        path: the file; ``#`` lines are comments.
        length_unit: ``m``, ``mm`` or ``um`` for ``x, y, z``.
        sep: column separator (default: sniffed among ``, ; tab``).
        decimal: decimal mark, ``"."`` or ``","``.

    Raises:
        TargetFileError: naming the file, the row (line number) and the column.
    """
    path = Path(path)
    try:
        length = unit_factor(length_unit, "length", "length_unit")
    except ValueError as err:
        raise TargetFileError(f"{path}: {err}") from None
    head = _read_head(path, sep, decimal)
    header = [h.lower() for h in head.header]
    missing = [c for c in ("x", "y", "z") if c not in header]
    if missing:
        raise TargetFileError(f"{path}: missing column(s) {', '.join(missing)} (header: {', '.join(header)})")
    quat_cols = ["qw", "qx", "qy", "qz"]
    has_q = [c in header for c in quat_cols]
    values, names, lines = _read_columns(head, header, ["x", "y", "z"] + quat_cols * all(has_q), decimal)
    if not len(values):
        raise TargetFileError(f"{path}: no targets")
    if any(has_q) and not all(has_q):
        absent = ", ".join(c for c in quat_cols if c not in header)
        raise TargetFileError(f"{path}: orientation needs all of qw, qx, qy, qz; missing {absent}")
    p = values[:, :3] * length
    if not all(has_q):
        return Targets(names, p, "position")
    quat = values[:, 3:]
    norm = np.linalg.norm(quat, axis=1)
    bad = np.flatnonzero(norm < 1e-9)
    if len(bad):
        raise TargetFileError(f"{path}, row {lines[int(bad[0])]}, columns qw..qz: the quaternion is zero")
    T = spatial.homogeneous(spatial.quaternion_to_matrix(quat / norm[:, None]), p)
    return Targets(names, T, "pose")


def read_program(
    path: str | Path,
    dof: int,
    *,
    angle_unit: str = "rad",
    length_unit: str = "m",
    joint_types: Sequence[str] | None = None,
    sep: str | None = None,
    decimal: str = ".",
) -> tuple[tuple[str, ...], Array]:
    """A joint program from a CSV file with columns ``q1..qN`` (and optionally ``name``).

    Revolute joints in ``angle_unit``, prismatic ones (``joint_types``) in
    ``length_unit``.  Returns the names and ``(n, dof)`` joint values (rad, m).
    """
    path = Path(path)
    try:
        angle, length = joint_unit_factors(angle_unit, length_unit)
    except ValueError as err:
        raise TargetFileError(f"{path}: {err}") from None
    head = _read_head(path, sep, decimal)
    header = [h.lower() for h in head.header]
    cols = [f"q{j + 1}" for j in range(dof)]
    missing = [c for c in cols if c not in header]
    if missing:
        raise TargetFileError(f"{path}: missing joint column(s) {', '.join(missing)} for a {dof}-joint robot")
    extra = [h for h in header if h.startswith("q") and h[1:].isdigit() and int(h[1:]) > dof]
    if extra:
        raise TargetFileError(f"{path}: joint column(s) {', '.join(extra)} but the robot has {dof} joints")
    q, names, _ = _read_columns(head, header, cols, decimal)
    if not len(q):
        raise TargetFileError(f"{path}: no rows")
    types = list(joint_types) if joint_types is not None else ["revolute"] * dof
    f = np.array([angle if t == "revolute" else length for t in types])
    return names, q * f
