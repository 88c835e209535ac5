"""Measurements written as CSV (SI units), atomically."""

from __future__ import annotations

import csv
import io
from pathlib import Path

import numpy as np

from robocal import spatial
from robocal.measure.measurements import (
    Array,
    Measurements,
)
from robocal.outdir import atomic_write_text
from robocal.safe_output import csv_text


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
