"""The ISO 9283 measurement log: timestamped tracker samples with the commanded pose.

A log is a CSV file (comma separated, ``.`` decimal mark) whose first lines may be
``# key: value`` comments holding the test conditions (robot, load, speed, limit band,
device, ...; ISO 9283 §6 asks for them in the test report), followed by one header line
and one row per sample.  Units are in the column names: mm, degrees, seconds, newtons.
See ``docs/iso9283.md`` for the full description and an example.

Columns (required ones first):

``time_s``          sample time (s); must not decrease within a test, and must increase by
                    at least :data:`MIN_TIME_STEP` (1 µs) between the samples of a run.
``test``            which ISO 9283 test the sample belongs to, one of :data:`TESTS`.
``cycle``           cycle number (integer >= 1).
``target``          the commanded pose the robot is moving to or standing at (``P1``..),
                    or the name of the path being followed (``line``, ``circle``, ...).
``x_mm y_mm z_mm``  measured position of the tool point, robot base frame (mm).
``cmd_x_mm ...``    commanded (set-point) position at the same instant (mm).
``group``           optional: the approach direction (``multidirectional``), the
                    measurement block (``drift``), the robot (``exchangeability``).
``a_deg b_deg c_deg`` / ``cmd_a_deg cmd_b_deg cmd_c_deg``
                    optional (all six or none): measured and commanded orientation,
                    rotations about the base x, y, z axes (``R = Rz(c) Ry(b) Rx(a)``).
``fx_N fy_N fz_N``  optional (all three or none): load applied to the mechanical
                    interface (N), for the static-compliance test.

A *run* is a maximal stretch of consecutive rows of one test with the same cycle,
target and group: one approach to (and stay at) a pose, or one traversal of a path.
A run may hold a single sample (a static measurement) or a time record.

Every number must lie within the range of its unit (|mm| <= 1e9, |deg| <= 1e6, |N| <= 1e9,
|time_s| <= 1e10, cycle <= 1e9): beyond it a cell is a typo or a corrupted file, whose squares
overflow into NaN characteristics.
"""

from __future__ import annotations

import io
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd
from numpy.typing import NDArray

from robocal import csvfile, spatial
from robocal.outdir import atomic_write_text, write_together
from robocal.run_ids import new_run_id, read_run_id, run_id_line

__all__ = [
    "COLUMNS",
    "OPTIONAL_COLUMNS",
    "REQUIRED_COLUMNS",
    "TESTS",
    "Iso9283Log",
    "Iso9283LogError",
    "Run",
    "read_iso9283_log",
    "write_iso9283_log",
]

Array = NDArray[np.float64]

#: The tests a row may belong to, in the order of the standard.
TESTS: tuple[str, ...] = (
    "pose",  # 7.2 AP/RP, 7.4 stabilisation time, 7.5 overshoot
    "multidirectional",  # 7.2.3 vAP
    "distance",  # 7.3 AD/RD
    "drift",  # 7.6 dAP/dRP
    "exchangeability",  # 7.7 E
    "path",  # 8.2/8.3 AT/RT
    "reorientation",  # 8.4 AT/RT with orientation
    "cornering",  # 8.5 CR/CO
    "velocity",  # 8.6 AV/RV/FV
    "positioning",  # 9 minimum positioning time
    "compliance",  # 10 static compliance
    "weaving",  # 11 WS/WF
)
REQUIRED_COLUMNS = (
    "time_s",
    "test",
    "cycle",
    "target",
    "x_mm",
    "y_mm",
    "z_mm",
    "cmd_x_mm",
    "cmd_y_mm",
    "cmd_z_mm",
)
ORIENTATION_COLUMNS = ("a_deg", "b_deg", "c_deg", "cmd_a_deg", "cmd_b_deg", "cmd_c_deg")
FORCE_COLUMNS = ("fx_N", "fy_N", "fz_N")
OPTIONAL_COLUMNS = ("group", *ORIENTATION_COLUMNS, *FORCE_COLUMNS)
COLUMNS = (*REQUIRED_COLUMNS, *OPTIONAL_COLUMNS)
_TEXT = ("test", "target", "group")
ANGLES = "xyz"  # a, b, c about the base x, y, z axes (scipy "xyz": R = Rz(c) Ry(b) Rx(a))


class Iso9283LogError(ValueError):
    """A log that cannot be read; the message names the file, row and column."""


@dataclass(frozen=True)
class Run:
    """One run of a test: consecutive rows with the same cycle, target and group.

    Attributes:
        test, cycle, target, group: the run's labels.
        index: ``(k,)`` row indices into the log's arrays, in time order.
    """

    test: str
    cycle: int
    target: str
    group: str
    index: NDArray[np.int_]


@dataclass(frozen=True)
class Iso9283Log:
    """A measurement log in SI units.

    Attributes:
        source: the file it was read from (for messages).
        conditions: the header's ``key: value`` test conditions.
        time: ``(N,)`` s.
        test, target, group: ``(N,)`` labels.
        cycle: ``(N,)`` cycle numbers.
        position, commanded: ``(N, 3)`` measured and commanded positions (m).
        rotation, commanded_rotation: ``(N, 3, 3)`` or None.
        force: ``(N, 3)`` applied load (N) or None.
        line: ``(N,)`` the line number of every row in the file (1-based).
    """

    source: str
    conditions: dict[str, str]
    time: Array
    test: NDArray[np.str_]
    cycle: NDArray[np.int_]
    target: NDArray[np.str_]
    group: NDArray[np.str_]
    position: Array
    commanded: Array
    rotation: Array | None = None
    commanded_rotation: Array | None = None
    force: Array | None = None
    line: NDArray[np.int_] = field(default_factory=lambda: np.zeros(0, dtype=int), repr=False)

    @property
    def n(self) -> int:
        return len(self.time)

    def tests(self) -> list[str]:
        """The tests present, in :data:`TESTS` order."""
        present = set(self.test.tolist())
        return [t for t in TESTS if t in present]

    def runs(self, test: str) -> list[Run]:
        """The runs of ``test`` in file order."""
        idx = np.flatnonzero(self.test == test)
        if len(idx) == 0:
            return []
        keys = list(
            zip(self.cycle[idx].tolist(), self.target[idx].tolist(), self.group[idx].tolist(), strict=True)
        )
        out: list[Run] = []
        start = 0
        for k in range(1, len(idx) + 1):
            if k == len(idx) or keys[k] != keys[start] or idx[k] != idx[k - 1] + 1:
                c, tg, g = keys[start]
                out.append(Run(test, int(c), tg, g, idx[start:k]))
                start = k
        return out

    def frames(self, index: NDArray[np.int_], commanded: bool = False) -> Array | None:
        """``(k, 4, 4)`` frames of rows ``index`` (m), or None without orientations."""
        R = self.commanded_rotation if commanded else self.rotation
        if R is None:
            return None
        p = (self.commanded if commanded else self.position)[index]
        return spatial.homogeneous(R[index], p)


def _fail(path: str, line: int | None, column: str | None, message: str) -> Iso9283LogError:
    where = path + (f" row {line}" if line is not None else "") + (f" column {column}" if column else "")
    return Iso9283LogError(f"{where}: {message}")


def _short(value: object) -> str:
    text = str(value)
    return repr(text if len(text) <= 40 else text[:37] + "...")


def _read_head(path: str | Path) -> csvfile.Head:
    name = str(path)
    try:
        return csvfile.read_head(path, sep=",", strict=True)
    except FileNotFoundError:
        raise Iso9283LogError(f"{name}: no such file") from None
    except csvfile.CsvError as err:
        if "UTF-8" in err.message:
            raise Iso9283LogError(f"{name}: not UTF-8 text (a log is a UTF-8 CSV file)") from None
        if err.message.startswith("no header row"):
            what = "no header line (the file is empty or holds only comments)"
            raise _fail(name, None, None, what) from None
        raise _fail(name, err.line, None, err.message) from None


def _read_body(
    head: csvfile.Head,
) -> tuple[dict[str, Array], dict[str, NDArray[np.str_]], NDArray[np.int64]]:
    """The numeric columns, the text columns (stripped) and each row's line number,
    read chunk by chunk (:mod:`robocal.csvfile`); the first bad row or cell is an error."""
    name, header = str(head.path), head.header
    numeric = [c for c in header if c not in _TEXT]
    numbers: dict[str, list[Array]] = {c: [] for c in numeric}
    words: dict[str, list[NDArray[np.str_]]] = {c: [] for c in _TEXT if c in header}
    lines: list[NDArray[np.int64]] = []
    for chunk in csvfile.iter_chunks(head):
        for i, code, message in chunk.problems[:1]:
            what = (
                f"{len(chunk.rows[i])} fields, but the header has {len(header)}"
                if code == "ragged"
                else "not a CSV table: " + message.removeprefix("cannot be read as CSV: ")
            )
            raise _fail(name, int(chunk.line[i]), None, what)
        for c in numeric:
            k = header.index(c)
            num, problems = csvfile.to_numbers([r[k] for r in chunk.rows])
            for m, code, _ in problems[:1]:
                raw = chunk.rows[m][k].strip()
                what = "empty" if code == "empty" else f"{_short(raw)} is not a finite number"
                raise _fail(name, int(chunk.line[m]), c, what)
            numbers[c].append(num)
        for c in words:
            k = header.index(c)
            words[c].append(np.array([r[k].strip() for r in chunk.rows], dtype=str))
        lines.append(chunk.line)
    n = sum(len(x) for x in lines)
    values = {c: np.concatenate(v) if v else np.zeros(0) for c, v in numbers.items()}
    texts = {c: np.concatenate(words[c]) if words.get(c) else np.full(n, "") for c in _TEXT}
    return values, texts, np.concatenate(lines) if lines else np.zeros(0, dtype=np.int64)


def _check_header(name: str, header: list[str], first: int) -> None:
    """The log's columns: no duplicates, none unknown, the required ones, orientation and
    load columns all or none."""
    seen = [c for k, c in enumerate(header) if c in header[:k]]
    if seen:
        raise _fail(name, first, None, f"duplicate column {_short(seen[0])}")
    unknown = [c for c in header if c not in COLUMNS]
    if unknown:
        raise _fail(name, first, None, f"unknown column {_short(unknown[0])} (columns: {', '.join(COLUMNS)})")
    missing = [c for c in REQUIRED_COLUMNS if c not in header]
    if missing:
        raise _fail(name, first, None, f"missing column(s) {', '.join(missing)}")
    for group_cols, what in ((ORIENTATION_COLUMNS, "orientation"), (FORCE_COLUMNS, "load")):
        have = [c for c in group_cols if c in header]
        if have and len(have) != len(group_cols):
            lacking = [c for c in group_cols if c not in header]
            raise _fail(name, first, None, f"{what} columns come all or none: missing {', '.join(lacking)}")


def _check_rows(
    name: str, values: dict[str, Array], texts: dict[str, NDArray], line: NDArray[np.int_]
) -> None:
    """Every row: test and target named, a known test, whole cycle numbers >= 1, time not
    going back within a test."""
    for c in ("test", "target"):
        empty = texts[c] == ""
        if empty.any():
            raise _fail(name, int(line[int(np.argmax(empty))]), c, "empty")
    bad_test = ~np.isin(texts["test"], TESTS)
    if bad_test.any():
        i = int(np.argmax(bad_test))
        raise _fail(
            name, int(line[i]), "test", f"{_short(texts['test'][i])} is not one of {', '.join(TESTS)}"
        )
    cyc = values["cycle"]
    bad_cycle = (cyc < 1) | (cyc != np.round(cyc))
    if bad_cycle.any():
        i = int(np.argmax(bad_cycle))
        raise _fail(name, int(line[i]), "cycle", f"{cyc[i]:g} is not a whole number >= 1")
    t = values["time_s"]
    for test in np.unique(texts["test"]):
        idx = np.flatnonzero(texts["test"] == test)
        back = np.flatnonzero(np.diff(t[idx]) < 0)
        if len(back):
            i = idx[back[0] + 1]
            raise _fail(
                name,
                int(line[i]),
                "time_s",
                f"time goes back within test {test} ({t[i]:g} s after {t[i - 1]:g} s)",
            )


#: the largest magnitude a cell of a column may hold, by unit (the name's suffix): beyond it a
#: value is a typo or a corrupted file, and squares and sums of it overflow to inf or NaN
_RANGE = {"_mm": 1e9, "_deg": 1e6, "_N": 1e9, "time_s": 1e10, "cycle": 1e9}


def _limit(column: str) -> float:
    return next(v for k, v in _RANGE.items() if column.endswith(k))


def _check_ranges(name: str, values: dict[str, Array], line: NDArray[np.int_]) -> None:
    """Every number within :data:`_RANGE` (1e9 mm, 1e6 deg, 1e9 N, 1e10 s, cycle 1e9)."""
    for c, v in values.items():
        big = np.abs(v) > _limit(c)
        if big.any():
            i = int(np.argmax(big))
            raise _fail(
                name, int(line[i]), c, f"{v[i]:g} is out of range: |{c}| must be at most {_limit(c):g}"
            )


#: s: the shortest time between two samples of a run (trackers sample at up to some kHz); a
#: shorter one makes speeds overflow and the fits of a time record degenerate
MIN_TIME_STEP = 1e-6


def _check_time_records(name: str, values: dict[str, Array], texts: dict[str, NDArray], line) -> None:
    """Within a run (consecutive rows of one test, cycle, target and group) the time must
    increase by at least :data:`MIN_TIME_STEP`: a record whose samples share a time has no
    speed or settling to measure."""
    t, cyc = values["time_s"], values["cycle"]
    same_run = (cyc[1:] == cyc[:-1]) & np.all([texts[c][1:] == texts[c][:-1] for c in _TEXT], axis=0)
    short = np.flatnonzero(same_run & (np.diff(t) < MIN_TIME_STEP)) + 1
    if len(short):
        i = int(short[0])
        raise _fail(
            name,
            int(line[i]),
            "time_s",
            f"{t[i]:g} s follows the previous sample of its run (test {texts['test'][i]}, cycle {cyc[i]:g}, "
            f"target {_short(texts['target'][i])}) after {t[i] - t[i - 1]:g} s: the samples of a run need "
            f"increasing times, at least {MIN_TIME_STEP:g} s apart",
        )


def read_iso9283_log(path: str | Path) -> Iso9283Log:
    """Read an ISO 9283 log (see the module docstring).

    Raises:
        Iso9283LogError: one line naming the file, row (line number) and column of the
            first problem.
    """
    name = str(path)
    head = _read_head(path)
    conditions, header, first = dict(head.metadata), head.header, head.header_line
    conditions.pop("robocal run", None)  # the run id of a simulated log and its truth, not a condition
    if len(header) == 1 and (";" in header[0] or "\t" in header[0]):
        raise _fail(name, first, None, "the header has one column: columns must be separated by commas")
    _check_header(name, header, first)
    values, texts, line = _read_body(head)
    if len(line) == 0:
        raise _fail(name, None, None, "no data rows")
    _check_ranges(name, values, line)
    _check_rows(name, values, texts, line)
    _check_time_records(name, values, texts, line)
    t, cyc = values["time_s"], values["cycle"]
    mm = 1e-3
    pos = np.column_stack([values[c] for c in ("x_mm", "y_mm", "z_mm")]) * mm
    cmd = np.column_stack([values[c] for c in ("cmd_x_mm", "cmd_y_mm", "cmd_z_mm")]) * mm
    R = Rc = None
    if "a_deg" in values:
        R = spatial.euler_to_matrix(
            np.radians(np.column_stack([values[c] for c in ORIENTATION_COLUMNS[:3]])), ANGLES
        )
        Rc = spatial.euler_to_matrix(
            np.radians(np.column_stack([values[c] for c in ORIENTATION_COLUMNS[3:]])), ANGLES
        )
    force = np.column_stack([values[c] for c in FORCE_COLUMNS]) if "fx_N" in values else None
    return Iso9283Log(
        source=name,
        conditions=conditions,
        time=t,
        test=texts["test"],
        cycle=cyc.astype(int),
        target=texts["target"],
        group=texts["group"],
        position=pos,
        commanded=cmd,
        rotation=R,
        commanded_rotation=Rc,
        force=force,
        line=line,
    )


def log_text(log: Iso9283Log, decimals: int = 6, run_id: str | None = None) -> str:
    """The CSV text of ``log`` (header comments, then the table; mm, deg, s, N);
    ``run_id`` stamps it as one file of a set (a ``# robocal run: ID`` first line)."""
    out = io.StringIO()
    if run_id is not None:
        out.write(run_id_line(run_id))
    out.write("# robocal ISO 9283 measurement log (docs/iso9283.md)\n")
    for key, value in log.conditions.items():
        if key == "robocal run":
            continue
        out.write(f"# {key}: {value}\n".replace("\r", " "))
    cols: dict[str, object] = {
        "time_s": np.round(log.time, 6),
        "test": log.test,
        "cycle": log.cycle,
        "target": log.target,
        "group": log.group,
    }
    for k, c in enumerate("xyz"):
        cols[f"{c}_mm"] = np.round(log.position[:, k] * 1e3, decimals)
    for k, c in enumerate("xyz"):
        cols[f"cmd_{c}_mm"] = np.round(log.commanded[:, k] * 1e3, decimals)
    if log.rotation is not None and log.commanded_rotation is not None:
        a = np.degrees(spatial.matrix_to_euler(log.rotation, ANGLES))
        ac = np.degrees(spatial.matrix_to_euler(log.commanded_rotation, ANGLES))
        for k, c in enumerate("abc"):
            cols[f"{c}_deg"] = np.round(a[:, k], decimals)
        for k, c in enumerate("abc"):
            cols[f"cmd_{c}_deg"] = np.round(ac[:, k], decimals)
    if log.force is not None:
        for k, c in enumerate(FORCE_COLUMNS):
            cols[c] = np.round(log.force[:, k], decimals)
    pd.DataFrame(cols).to_csv(out, index=False, lineterminator="\n")
    return out.getvalue()


def write_iso9283_log(log: Iso9283Log, path: str | Path) -> Path:
    """Write ``log`` to ``path`` whole (through a temporary file)."""
    return atomic_write_text(path, log_text(log))


def log_truth_path(path: str | Path) -> Path:
    """``LOG.csv`` -> ``LOG.truth.yaml`` (beside the log)."""
    path = Path(path)
    return path.with_name(path.stem + ".truth.yaml")


def save_simulated_log(log: Iso9283Log, truth: dict, path: str | Path) -> tuple[Path, Path]:
    """Write a simulated log and its truth (``LOG.truth.yaml``) both or neither
    (:func:`robocal.outdir.file_set`), stamped with one run id.

    Returns:
        The log and truth paths.
    """
    import yaml

    path = Path(path)
    run_id = new_run_id()
    truth_text = run_id_line(run_id) + yaml.safe_dump(truth, sort_keys=False)
    write_together(
        {
            path: log_text(log, run_id=run_id).encode("utf-8"),
            log_truth_path(path): truth_text.encode("utf-8"),
        }
    )
    return path, log_truth_path(path)


def load_log_truth(path: str | Path) -> dict:
    """The truth of a simulated log (``LOG.csv`` or ``LOG.truth.yaml``); refuses a truth
    and log of different simulation runs (a run killed between its renames).

    Raises:
        Iso9283LogError: naming both files when their run ids differ, or the truth file
            when it cannot be read.
    """
    import yaml

    path = Path(path)
    truth_file = path if path.name.endswith(".truth.yaml") else log_truth_path(path)
    log_file = truth_file.with_name(truth_file.name.removesuffix(".truth.yaml") + ".csv")
    want, got = read_run_id(truth_file), read_run_id(log_file)
    if log_file.is_file() and want != got:
        raise Iso9283LogError(
            f"{truth_file}: the truth is of simulation run {want or 'none'} but {log_file} is run "
            f"{got or 'none'}: these files come from different simulations; simulate again"
        )
    from robocal.model.yaml_files import MAX_FILE_BYTES

    try:
        if truth_file.stat().st_size > MAX_FILE_BYTES:  # checked before parsing: YAML takes seconds per MB
            raise Iso9283LogError(f"{truth_file}: larger than {MAX_FILE_BYTES} bytes: not a truth file")
        doc = yaml.safe_load(truth_file.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, yaml.YAMLError) as err:
        raise Iso9283LogError(f"{truth_file}: cannot read the truth ({err.__class__.__name__})") from None
    if not isinstance(doc, dict):
        raise Iso9283LogError(f"{truth_file}: not a truth file (no mapping)")
    return doc
