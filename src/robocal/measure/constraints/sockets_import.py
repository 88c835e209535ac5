"""Ball-in-socket recordings as they come (MUKCa's layout) -> robocal's constraint CSV.

A recording is a headerless CSV per socket: one configuration per line, the joint angles
(rad, or degrees with ``angle_unit="deg"``) comma-separated, no header
(``../shared/data/ball_in_socket/README.md``).  A placement folder holds one such file per
socket, ``hole_0.csv``, ``hole_1.csv`` …; its ``hole_<k>_pose.csv`` are the controller's own
pose estimates, not measurements, and are ignored.

:func:`read_socket_recordings` turns files (point 0, 1, … in the order given) and folders
(their ``hole_<k>.csv`` in numeric order of ``k``) into a :class:`ConstraintSet` with a
``point`` per row; :func:`~robocal.measure.constraints.data.write_constraints` writes it as
the documented constraint CSV (``q1..qN`` and ``point``).  Known distances between the
sockets are not in the file: ``robocal calibrate ... --distance 0,1=50mm``.
"""

from __future__ import annotations

import csv
import math
import re
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from robocal.csvfile import short
from robocal.measure.constraints.data import ConstraintFileError, checked_text, number_cell
from robocal.measure.constraints.data_set import ConstraintSet
from robocal.units import unit_factor

__all__ = ["SocketRecording", "read_socket_recordings", "socket_files"]

HOLE_FILE = re.compile(r"hole_(\d+)\.csv")
#: a joint angle beyond two turns (rad) is a recording in degrees read as radians
MAX_ANGLE_RAD = 4.0 * math.pi


@dataclass(frozen=True)
class SocketRecording:
    """Joint angles recorded with the tool's ball seated in fixed points (sockets).

    Attributes:
        data: ``q`` ``(n, dof)`` (rad) and ``point`` ``(n,)`` (0, 1, …: the socket).
        sources: the file each point was read from (point ``k``: ``sources[k]``).
    """

    data: ConstraintSet
    sources: tuple[Path, ...]

    @property
    def rows_per_point(self) -> tuple[int, ...]:
        """Configurations recorded in each point (socket)."""
        return tuple(int(c) for c in np.bincount(self.data.point, minlength=len(self.sources)))


def socket_files(paths: Sequence[str | Path]) -> list[Path]:
    """The recording files of ``paths``, in point order: a file as given, a folder as its
    ``hole_<k>.csv`` files by ``k`` (``*_pose.csv`` and other files left out).

    Raises:
        ConstraintFileError: a missing path, a folder without ``hole_<k>.csv`` or with a gap
            in ``k`` (the points would be renumbered unseen), a file given twice.
    """
    files: list[Path] = []
    for given in map(Path, paths):
        if given.is_dir():
            files += _folder_files(given)
        elif given.is_file():
            files.append(given)
        else:
            raise ConstraintFileError(f"{given}: no such file or folder")
    seen: set[Path] = set()
    for path in files:
        if path.resolve() in seen:  # one socket's rows counted as two points
            raise ConstraintFileError(f"{path}: given twice")
        seen.add(path.resolve())
    return files


def _folder_files(folder: Path) -> list[Path]:
    holes = {
        int(m.group(1)): p for p in folder.iterdir() if (m := HOLE_FILE.fullmatch(p.name)) and p.is_file()
    }
    if not holes:
        raise ConstraintFileError(f"{folder}: no hole_<k>.csv recording in this folder")
    missing = [k for k in range(max(holes) + 1) if k not in holes]
    if missing:
        raise ConstraintFileError(
            f"{folder}: hole_{missing[0]}.csv is missing (the folder has hole_{min(holes)}..{max(holes)})"
        )
    return [holes[k] for k in sorted(holes)]


def _angle(text: str, where: str, scale: float) -> float:
    value = number_cell(text, where)
    if abs(value * scale) > MAX_ANGLE_RAD:
        raise ConstraintFileError(
            f"{where}: {short(text.strip())} rad is more than two turns; a recording in degrees needs --deg"
        )
    return value * scale


def read_joint_file(path: Path, scale: float = 1.0) -> np.ndarray:
    """``(n, dof)`` joint angles (rad) of a headerless recording, each read value times
    ``scale`` (rad per unit); blank lines skipped.

    Raises:
        ConstraintFileError: an empty file, a non-numeric or non-finite cell, a row with
            another number of joints than the first (named by row and column, from 1).
    """
    lines = [(k + 1, line) for k, line in enumerate(checked_text(path).splitlines()) if line.strip()]
    if not lines:
        raise ConstraintFileError(f"{path}: empty: no configuration")
    rows: list[list[float]] = []
    for number, line in lines:
        cells = next(csv.reader([line]))
        if rows and len(cells) != len(rows[0]):
            raise ConstraintFileError(
                f"{path}, row {number}: {len(cells)} joint angles; row {lines[0][0]} has {len(rows[0])}"
            )
        rows.append([_angle(c, f"{path}, row {number}, column {j + 1}", scale) for j, c in enumerate(cells)])
    return np.array(rows, dtype=float)


def read_socket_recordings(
    paths: Sequence[str | Path], *, angle_unit: str = "rad", sigma: float = 1e-4
) -> SocketRecording:
    """Read the recordings of ``paths`` (:func:`socket_files`) as fixed-point rows: the
    ``k``-th file's configurations all put the tool point in point ``k``.  ``sigma`` (m):
    the tool point's noise the set states (a hand-guided seat: about 0.1 mm).

    Raises:
        ConstraintFileError: a bad path or cell (:func:`socket_files`, :func:`read_joint_file`),
            files with different numbers of joints.
    """
    scale = unit_factor(angle_unit, "angle", "angle_unit")
    files = socket_files(paths)
    blocks = [read_joint_file(path, scale) for path in files]
    dof = blocks[0].shape[1]
    for path, block in zip(files, blocks, strict=True):
        if block.shape[1] != dof:
            raise ConstraintFileError(f"{path}, row 1: {block.shape[1]} joint angles; {files[0]} has {dof}")
    point = np.repeat(np.arange(len(blocks), dtype=np.intp), [len(b) for b in blocks])
    data = ConstraintSet(np.vstack(blocks), point, np.full(len(point), -1, dtype=np.intp), sigma=sigma)
    return SocketRecording(data, tuple(files))
