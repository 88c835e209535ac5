"""Constraint measurement files: fixed points, planes and distances (no tracker needed).

One CSV, one header line, one row per recorded configuration; ``#`` lines are comments:

* joint columns ``q1 … qN`` (rad; ``--angle-unit deg`` for degrees), always;
* ``point``: the fixed point (0, 1, …) the tool point sat in (ball in socket ``k``);
* ``plane``: the plane (0, 1, …) the tool point touched;
* ``pair`` and ``distance_mm``: the two rows with the same ``pair`` id had their tool
  points ``distance_mm`` apart (ball-bar, a table of known points); both rows state it;
* ``x, y, z`` (m, optional): a tracker's position of the tool point, blank where none
  (mixed data: tracker points and socket poses calibrate together);
* ``link``, ``axis`` and ``tilt_deg``: an inclinometer reading (degrees) of the sensor on
  the link moved by joint ``link`` (1..N, as the joint columns ``qK``), channel ``axis``
  (``x`` or ``y``: the sensor's axes), blank where none
  (:mod:`robocal.identify.constraints.tilt_rows`);
* ``mount_rx_deg``, ``mount_ry_deg``, ``mount_rz_deg`` (optional, with the tilt columns):
  the sensor's orientation on its link, degrees about the link's joint-frame x, y, z
  axes (fixed axes, in that order: ``R_joint_sensor = Rz Ry Rx``); absent or blank: the
  sensor's axes are the joint frame's.  These angles are in the frames of the robot's own
  chain (the catalog's, the model file's), whichever chain is calibrated;
* ``home_rx_deg``, ``home_ry_deg``, ``home_rz_deg`` (optional, instead of the mount
  columns on a row): the sensor's orientation in the robot's base frame with every joint
  at zero (``R_base_sensor = Rz Ry Rx`` at home): 0, 0, 0 is a sensor mounted level at
  home with its x axis along the base's x.  It does not depend on any chain
  (:mod:`robocal.measure.constraints.mounts`).  Every row of a link states the same mount.

A blank ``point``/``plane`` cell means the row has no such constraint.  Known distances
between fixed points are not rows: ``--distance 0,1=50mm`` (points 0 and 1 are 50 mm apart).
The file's kind (``point``, ``plane``, ``distance``) is told from its columns
(:func:`constraint_kind`).  Example (``robocal simulate --kind point`` writes one)::

    q1,q2,q3,q4,q5,q6,point
    0.1,-1.2,1.5,0.3,1.1,0.0,0
    0.4,-1.0,1.2,0.9,0.7,1.3,0
"""

from __future__ import annotations

import csv
import dataclasses
import io
import math
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from robocal.csvfile import short
from robocal.measure.constraints.data_set import KINDS, TILT_AXES, ConstraintSet
from robocal.units import unit_factor

__all__ = [
    "KIND_COLUMNS",
    "ConstraintFileError",
    "checked_text",
    "constraint_kind",
    "has_tilt_rows",
    "number_cell",
    "parse_distance",
    "read_constraints",
    "tilt_only",
    "write_constraints",
]

KIND_COLUMNS = {"point": ("point",), "plane": ("plane",), "distance": ("pair", "distance_mm"),
                "tilt": ("link", "axis", "tilt_deg")}  # fmt: skip
MOUNT_COLUMNS = ("mount_rx_deg", "mount_ry_deg", "mount_rz_deg")
HOME_COLUMNS = ("home_rx_deg", "home_ry_deg", "home_rz_deg")
MAX_BYTES = 50_000_000  # a constraint file holds thousands of rows, not gigabytes
MAX_INDEX = 1000  # points, planes: a handful; an index beyond this is a wrong column


class ConstraintFileError(ValueError):
    """A constraint file that cannot be read; the message names the file, row and column."""


def _header(path: Path) -> list[str]:
    with open(path, encoding="utf-8-sig", newline="") as fh:
        for line in fh:
            if line.strip() and not line.lstrip().startswith("#"):
                return [c.strip() for c in next(csv.reader([line]))]
    return []


def constraint_kind(path: str | Path) -> str | None:
    """``"point"``, ``"plane"`` or ``"distance"`` when the file has that kind's columns
    (the first of them in that order; a file may mix them), else None (a tracker file)."""
    try:
        columns = set(_header(Path(path)))
    except (OSError, UnicodeDecodeError):
        return None
    for kind in KINDS:
        if set(KIND_COLUMNS[kind]) <= columns:
            return kind
    return None


def tilt_only(path: str | Path) -> bool:
    """Whether ``path`` holds inclinometer readings only: the tilt columns and no other
    kind's (``point``, ``plane``, ``pair``/``distance_mm``) nor a tracker's ``x, y, z``."""
    try:
        columns = set(_header(Path(path)))
    except (OSError, UnicodeDecodeError):
        return False
    others = {c for kind in KINDS if kind != "tilt" for c in KIND_COLUMNS[kind]} | {"x", "y", "z"}
    return set(KIND_COLUMNS["tilt"]) <= columns and not columns & others


def has_tilt_rows(path: str | Path) -> bool:
    """Whether ``path``'s columns include the inclinometer's (``link, axis, tilt_deg``),
    alone or beside another kind's."""
    try:
        columns = set(_header(Path(path)))
    except (OSError, UnicodeDecodeError):
        return False
    return set(KIND_COLUMNS["tilt"]) <= columns


def parse_distance(text: str) -> tuple[int, int, float]:
    """``"0,1=50mm"`` -> (0, 1, 0.05): points 0 and 1 are 50 mm apart (unit required)."""
    from robocal.measure.true_model import parse_quantity

    pair, sep, length = text.partition("=")
    parts = pair.split(",")
    if not sep or len(parts) != 2 or not all(p.strip().isdigit() for p in parts):
        raise ValueError(f"--distance {text!r}: expected A,B=LENGTH with point numbers, e.g. 0,1=50mm")
    try:
        float(length)
    except ValueError:
        value = parse_quantity(length.strip(), "length")
    else:  # a bare number: metres or millimetres? say it
        raise ValueError(f"--distance {text!r}: give the length with its unit, e.g. {pair}=50mm")
    if not (math.isfinite(value) and value > 0):
        raise ValueError(f"--distance {text!r}: the length must be > 0")
    a, b = int(parts[0]), int(parts[1])
    if a == b:
        raise ValueError(f"--distance {text!r}: a distance joins two different points")
    return a, b, value


def number_cell(value: str, where: str, integer: bool = False) -> float:
    """A finite number read from a cell (an index 0..MAX_INDEX with ``integer``);
    ConstraintFileError naming ``where`` otherwise."""
    text = value.strip()
    try:
        number = float(text)
    except ValueError:
        raise ConstraintFileError(f"{where}: {short(text)} is not a number") from None
    if not math.isfinite(number):
        raise ConstraintFileError(f"{where}: {short(text)} is not a finite number")
    if integer and (number != int(number) or not 0 <= number <= MAX_INDEX):
        raise ConstraintFileError(f"{where}: {short(text)} is not an index 0..{MAX_INDEX}")
    return number


def checked_text(path: Path) -> str:
    """The text of a measurement file: refused by name when over ``MAX_BYTES``, not UTF-8 or
    unreadable (ConstraintFileError)."""
    if path.stat().st_size > MAX_BYTES:
        raise ConstraintFileError(f"{path}: larger than {MAX_BYTES // 1_000_000} MB")
    try:
        return path.read_text(encoding="utf-8-sig")
    except UnicodeDecodeError:
        raise ConstraintFileError(f"{path}: not UTF-8 text") from None
    except OSError as err:
        raise ConstraintFileError(f"{path}: cannot be read ({err.strerror})") from None


def _rows(path: Path) -> tuple[list[str], list[tuple[int, list[str]]]]:
    if not path.is_file():
        raise ConstraintFileError(f"{path}: no such file")
    text = checked_text(path)
    lines = [
        (k + 1, line)
        for k, line in enumerate(text.splitlines())
        if line.strip() and not line.lstrip().startswith("#")
    ]
    if not lines:
        raise ConstraintFileError(f"{path}: no header line")
    header = [c.strip() for c in next(csv.reader([lines[0][1]]))]
    rows = [(number, next(csv.reader([line]))) for number, line in lines[1:]]
    return header, rows


def _index_column(cells: list[str], where: str) -> int:
    return -1 if not cells or not cells[0].strip() else int(number_cell(cells[0], where, integer=True))


def read_constraints(
    path: str | Path,
    dof: int,
    *,
    angle_unit: str = "rad",
    distances: Sequence[tuple[int, int, float]] = (),
    sigma: float = 1e-5,
) -> ConstraintSet:
    """Read a constraint file (module docstring) for a robot with ``dof`` joints.

    Raises:
        ConstraintFileError: a missing column, a bad cell (named by row and column), a pair
            that is not two rows with one length, a known distance naming a missing point.
    """
    path = Path(path)
    header, rows = _rows(path)
    joints = [f"q{k + 1}" for k in range(dof)]
    missing = [c for c in joints if c not in header]
    if missing:
        raise ConstraintFileError(
            f"{path}: no joint column(s) {', '.join(missing)} (header: {short(','.join(header), 80)})"
        )
    if f"q{dof + 1}" in header:  # another robot's file: its last joints would be dropped unseen
        raise ConstraintFileError(f"{path}: a joint column q{dof + 1}, but the robot has {dof} joints")
    if not any(set(cols) <= set(header) for cols in KIND_COLUMNS.values()):
        raise ConstraintFileError(
            f"{path}: no constraint column (point, plane, pair and distance_mm, or link, axis and tilt_deg)"
        )
    col = {name: header.index(name) for name in header}
    scale = unit_factor(angle_unit, "angle", "angle_unit")
    _check_mount_columns(path, header, MOUNT_COLUMNS)
    _check_mount_columns(path, header, HOME_COLUMNS)
    q, point, plane, xyz, pair, length, tilt, mount = [], [], [], [], [], [], [], []
    for number, cells in rows:
        if len(cells) != len(header):
            raise ConstraintFileError(
                f"{path}, row {number}: {len(cells)} cells; the header has {len(header)}"
            )

        def get(name: str, number=number, cells=cells) -> list[str]:
            return [cells[col[name]]] if name in col else []

        q.append([number_cell(cells[col[j]], f"{path}, row {number}, column {j}") * scale for j in joints])
        point.append(_index_column(get("point"), f"{path}, row {number}, column point"))
        plane.append(_index_column(get("plane"), f"{path}, row {number}, column plane"))
        pair.append(_index_column(get("pair"), f"{path}, row {number}, column pair"))
        length.append(
            number_cell(get("distance_mm")[0], f"{path}, row {number}, column distance_mm") * 1e-3
            if pair[-1] >= 0
            else math.nan
        )
        xyz.append(_tracker(get, number, path))
        tilt.append(_tilt(get, number, path, dof))
        mount.append(_mount(get, number, path, tilt[-1][0] >= 0))
    data = _assemble(path, np.array(q).reshape(-1, dof), point, plane, xyz, pair, length, distances, sigma)
    if not any(t[0] >= 0 for t in tilt):
        return data
    link, axis, reading = (np.array(c) for c in zip(*tilt, strict=True))
    _check_one_mount(path, rows, link, mount)
    angles, home = np.array([m[:3] for m in mount]), np.array([m[3] > 0 for m in mount])
    return dataclasses.replace(data, tilt_link=link, tilt_axis=axis, tilt=reading, tilt_mount=angles,
                               tilt_home=home)  # fmt: skip


def _check_mount_columns(path: Path, header: list[str], columns: tuple[str, ...]) -> None:
    """All three of a mount's ``columns`` or none; only beside the tilt columns."""
    present = [c for c in columns if c in header]
    if present and len(present) < 3:
        missing = [c for c in columns if c not in header]
        raise ConstraintFileError(f"{path}: column {present[0]} without {', '.join(missing)}")
    if present and not set(KIND_COLUMNS["tilt"]) <= set(header):
        raise ConstraintFileError(f"{path}: mount columns without the tilt columns (link, axis, tilt_deg)")


def _mount(get, number: int, path: Path, tilted: bool) -> list[float]:
    """A tilt row's mount: three angles (rad) and 1.0 when they are stated at home (the
    home columns), else 0.0 (the mount columns; all blank or no columns: the joint frame)."""
    stated = [
        (columns, [c for name in columns for c in get(name)]) for columns in (MOUNT_COLUMNS, HOME_COLUMNS)
    ]
    given = [(columns, cells) for columns, cells in stated if any(c.strip() for c in cells)]
    if not tilted or not given:
        return [0.0, 0.0, 0.0, 0.0]
    where = f"{path}, row {number}, column"
    if len(given) > 1:
        raise ConstraintFileError(f"{where}s {', '.join(HOME_COLUMNS)}: a mount at home and on the link "
                                  "on one row; state one of them")  # fmt: skip
    columns, cells = given[0]
    angles = [math.radians(number_cell(c, f"{where} {name}")) for c, name in zip(cells, columns, strict=True)]
    return angles + [1.0 if columns == HOME_COLUMNS else 0.0]


def _check_one_mount(path: Path, rows: list, link: np.ndarray, mount: list[list[float]]) -> None:
    """Refuse a link whose rows state different mounts, naming the first such row."""
    first: dict[int, list[float]] = {}
    for (number, _), k, angles in zip(rows, link.tolist(), mount, strict=True):
        if k < 0:
            continue
        seen = first.setdefault(k, angles)
        if seen != angles:
            raise ConstraintFileError(
                f"{path}, row {number}, mount columns: link {k + 1}'s sensor was "
                "stated with another mount on an earlier row; one sensor (one mount) per link"
            )


def _tilt(get, number: int, path: Path, dof: int) -> tuple[int, int, float]:
    """``(joint index, axis index, reading in rad)`` of a row, ``(-1, 0, nan)`` where none."""
    cells = [c for name in ("link", "axis", "tilt_deg") for c in get(name)]
    if len(cells) < 3 or not any(c.strip() for c in cells):
        return -1, 0, math.nan
    where = f"{path}, row {number}, column"
    link = int(number_cell(cells[0], f"{where} link", integer=True))
    if not 1 <= link <= dof:
        raise ConstraintFileError(f"{where} link: {link} is not a joint 1..{dof}")
    axis = cells[1].strip()
    if axis not in TILT_AXES:
        raise ConstraintFileError(f"{where} axis: {short(axis)} is not one of {', '.join(TILT_AXES)}")
    return link - 1, TILT_AXES.index(axis), math.radians(number_cell(cells[2], f"{where} tilt_deg"))


def _tracker(get, number: int, path: Path) -> list[float]:
    cells = [c for name in "xyz" for c in get(name)]
    if len(cells) < 3 or not any(c.strip() for c in cells):
        return [math.nan] * 3
    return [
        number_cell(c, f"{path}, row {number}, column {name}") for c, name in zip(cells, "xyz", strict=True)
    ]


def _pairs(path: Path, pair: list[int], length: list[float]) -> tuple[np.ndarray, np.ndarray]:
    """``(m, 2)`` row indices and ``(m,)`` lengths of the distance pairs."""
    groups: dict[int, list[int]] = {}
    for row, k in enumerate(pair):
        if k >= 0:
            groups.setdefault(k, []).append(row)
    pairs, lengths = [], []
    for k, rows in sorted(groups.items()):
        if len(rows) != 2:
            raise ConstraintFileError(f"{path}: pair {k} has {len(rows)} rows; a distance joins two")
        if not math.isclose(length[rows[0]], length[rows[1]], rel_tol=1e-9) or not length[rows[0]] > 0:
            raise ConstraintFileError(
                f"{path}: pair {k}: its two rows state different or non-positive distance_mm"
            )
        pairs.append(rows)
        lengths.append(length[rows[0]])
    return np.array(pairs, dtype=np.intp).reshape(-1, 2), np.array(lengths)


def _assemble(path, q, point, plane, xyz, pair, length, distances, sigma) -> ConstraintSet:
    point_arr = np.array(point, dtype=np.intp)
    n_points = int(point_arr.max()) + 1 if len(point_arr) else 0
    for k in range(n_points):
        if not np.any(point_arr == k):
            raise ConstraintFileError(
                f"{path}: points are numbered 0..{n_points - 1} but point {k} has no row"
            )
    for a, b, _ in distances:
        if max(a, b) >= n_points:
            raise ConstraintFileError(f"--distance {a},{b}: {path} has points 0..{n_points - 1} only")
    pairs, lengths = _pairs(path, pair, length)
    position = np.array(xyz, dtype=float).reshape(-1, 3)
    try:
        return ConstraintSet(
            q, point_arr, np.array(plane, dtype=np.intp),
            position=position if np.isfinite(position).any() else None,
            pairs=pairs, pair_length=lengths,
            point_pairs=np.array([(a, b) for a, b, _ in distances], dtype=np.intp).reshape(-1, 2),
            point_length=np.array([d for *_, d in distances], dtype=float),
            sigma=sigma,
        )  # fmt: skip
    except ValueError as err:
        raise ConstraintFileError(f"{path}: {err}") from None


def _tilt_cells(data: ConstraintSet, i: int) -> list[str]:
    if data.tilt_link[i] < 0:
        return ["", "", ""]
    return [
        str(int(data.tilt_link[i]) + 1),
        TILT_AXES[int(data.tilt_axis[i])],
        repr(math.degrees(data.tilt[i])),
    ]


def _mount_cells(data: ConstraintSet, i: int, columns: list[str]) -> list[str]:
    """Row ``i``'s cells under the mount ``columns`` written (joint-frame, then home angles)."""
    cells = {c: "" for c in columns}
    if data.tilt_link[i] >= 0 and (data.tilt_home[i] or MOUNT_COLUMNS[0] in cells):
        names = HOME_COLUMNS if data.tilt_home[i] else MOUNT_COLUMNS
        cells |= {c: repr(math.degrees(float(v))) for c, v in zip(names, data.tilt_mount[i], strict=True)}
    return list(cells.values())


def _mount_header(data: ConstraintSet) -> list[str]:
    """The mount columns ``data`` needs: joint-frame angles where a row's are not zero, the
    home columns where a row is stated at home."""
    on = data.tilted
    joint = bool(np.any(data.tilt_mount[on & ~data.tilt_home] != 0.0))
    return (list(MOUNT_COLUMNS) if joint else []) + (list(HOME_COLUMNS) if data.tilt_home.any() else [])


def write_constraints(data: ConstraintSet, path: str | Path | None = None) -> str:
    """The CSV text of ``data`` (module docstring); written to ``path`` when given (atomically)."""
    dof = data.q.shape[1]
    header = [f"q{k + 1}" for k in range(dof)]
    kinds = data.kinds
    header += [c for kind in KINDS if kind in kinds for c in KIND_COLUMNS[kind]]
    mounts = _mount_header(data) if "tilt" in kinds else []
    header += mounts
    if "tracker" in kinds:
        header += ["x", "y", "z"]
    pair_of = {int(i): (k, data.pair_length[k]) for k, rows in enumerate(data.pairs) for i in rows}
    out = io.StringIO()
    writer = csv.writer(out, lineterminator="\n")
    writer.writerow(header)
    for i in range(data.n):
        row = [repr(float(v)) for v in data.q[i]]
        if "point" in kinds:
            row.append(str(data.point[i]) if data.point[i] >= 0 else "")
        if "plane" in kinds:
            row.append(str(data.plane[i]) if data.plane[i] >= 0 else "")
        if "distance" in kinds:
            pair = pair_of.get(i)
            row += ["", ""] if pair is None else [str(pair[0]), repr(float(pair[1]) * 1e3)]
        if "tilt" in kinds:
            row += _tilt_cells(data, i)
            row += _mount_cells(data, i, mounts)
        if "tracker" in kinds:
            row += ["", "", ""] if not data.tracked[i] else [repr(float(v)) for v in data.positions[i]]
        writer.writerow(row)
    text = out.getvalue()
    if path is not None:
        from robocal.outdir import atomic_write_text

        atomic_write_text(path, text)
    return text
