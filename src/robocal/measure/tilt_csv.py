"""Inclinometer readings as CSV (docs/inclinometer.md), through the one CSV reader.

One row per reading::

    # robocal: inclinometer readings
    q1,q2,q3,q4,q5,link,axis,tilt_deg,sigma_deg
    10.0,45.0,-30.0,20.0,0.0,q3,x,-15.2313,0.001

* one column per joint of the robot, by the model's joint name, in degrees;
* ``link``: the joint whose child link carries the sensor; ``axis``: ``x`` or ``y``
  (:mod:`robocal.measure.inclinometer` defines the two readings);
* ``tilt_deg``: the reading (deg); ``sigma_deg`` (optional): its 1σ (deg; default the
  thesis' resolution, 0.001°).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from robocal.csvfile import CsvError, iter_chunks, read_head, short, to_numbers
from robocal.measure.inclinometer import AXES, RESOLUTION, TiltReadings
from robocal.outdir import atomic_write_text

__all__ = ["TILT_COLUMNS", "read_tilt_readings", "write_tilt_readings"]

TILT_COLUMNS = ("link", "axis", "tilt_deg")
MAX_TILT_DEG = 90.0


def _where(path: Path, line: int, column: str) -> str:
    return f"{path}: line {line}, column {column!r}"


def read_tilt_readings(path: str | Path, model) -> TiltReadings:
    """The readings of ``path`` for ``model``; ValueError naming the file, line and column
    of the first problem."""
    path = Path(path)
    try:
        head = read_head(path)
    except CsvError as err:
        raise ValueError(f"{path}: {err.message}") from None
    missing = [c for c in (*model.joint_names, *TILT_COLUMNS) if c not in head.header]
    if missing:
        raise ValueError(f"{path}: missing column(s) {', '.join(missing)} (inclinometer readings need them)")
    col = {name: head.header.index(name) for name in head.header}
    q, link, axis, tilt, sigma = [], [], [], [], []
    for chunk in iter_chunks(head):
        if chunk.problems:
            i, _, message = chunk.problems[0]
            raise ValueError(f"{path}: line {chunk.line[i]}: {message}")
        for row, line in zip(chunk.rows, chunk.line, strict=True):
            numbers = [*model.joint_names, "tilt_deg", *(["sigma_deg"] if "sigma_deg" in col else [])]
            values, problems = to_numbers([row[col[c]] for c in numbers])
            if problems:
                m, _, message = problems[0]
                raise ValueError(f"{_where(path, line, numbers[m])}: {message}")
            lk, ax = row[col["link"]].strip(), row[col["axis"]].strip()
            if lk not in model.joint_names:
                raise ValueError(f"{_where(path, line, 'link')}: {short(lk)} is not a joint of {model.name}")
            if ax not in AXES:
                raise ValueError(f"{_where(path, line, 'axis')}: {short(ax)} is not one of {', '.join(AXES)}")
            if abs(values[model.dof]) > MAX_TILT_DEG:
                raise ValueError(f"{_where(path, line, 'tilt_deg')}: a tilt beyond ±90 deg")
            s = values[model.dof + 1] if "sigma_deg" in col else math.degrees(RESOLUTION)
            if not s > 0:
                raise ValueError(f"{_where(path, line, 'sigma_deg')}: sigma must be > 0")
            q.append(np.radians(values[: model.dof]))
            link.append(lk)
            axis.append(ax)
            tilt.append(math.radians(values[model.dof]))
            sigma.append(math.radians(s))
    if not q:
        raise ValueError(f"{path}: no readings")
    return TiltReadings(np.array(q), tuple(link), tuple(axis), np.array(tilt), np.array(sigma))


def write_tilt_readings(path: str | Path, data: TiltReadings, joint_names: tuple[str, ...]) -> None:
    """Write ``data`` as :func:`read_tilt_readings` reads it (atomically)."""
    lines = ["# robocal: inclinometer readings", ",".join([*joint_names, *TILT_COLUMNS, "sigma_deg"])]
    for q, lk, ax, t, s in zip(data.q, data.link, data.axis, data.tilt, data.sigma, strict=True):
        cells = [repr(float(v)) for v in np.degrees(q)]
        lines.append(",".join([*cells, lk, ax, repr(math.degrees(t)), repr(math.degrees(s))]))
    atomic_write_text(Path(path), "\n".join(lines) + "\n")
