"""The :class:`Measurements` a calibration reads (one row per measured pose), the limits a
measurement file is held to, and the problems reading one can report."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from robocal import choices

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
LimitsMode = choices.LimitsMode  # the one table of choices (robocal.choices)

POSITION = ("x", "y", "z")
QUATERNION = ("qw", "qx", "qy", "qz")
ANGLES = ("rx", "ry", "rz")
SIGMA = ("sx", "sy", "sz")
KNOWN = {*POSITION, *QUATERNION, *ANGLES, *SIGMA, "set", "temperature"}


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
