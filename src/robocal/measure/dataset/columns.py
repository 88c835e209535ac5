"""Which columns of a measurement file hold what: ``columns=`` renames, the ``orientation=``
spec, and the reader's column resolution (joints, position, sigma, orientation, ...)."""

from __future__ import annotations

import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Literal, TypeVar

import numpy as np
from numpy.typing import NDArray

from robocal import choices, csvfile
from robocal.measure.measurements import (
    ANGLES,
    KNOWN,
    POSITION,
    QUATERNION,
    SIGMA,
    Array,
    LimitsMode,
    Problem,
    Severity,
)
from robocal.units import unit_factor

if TYPE_CHECKING:
    from robocal.model.chain import Model

_Item = TypeVar("_Item", bound=np.generic)


@dataclass(frozen=True)
class _Orientation:
    kind: Literal["auto", "none", "quaternion", "rotvec", "euler"]
    seq: str = ""
    unit: str | None = None


def parse_orientation(spec: str) -> _Orientation:
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


def parse_columns(columns: Mapping[str, str] | Sequence[str] | str | None) -> dict[str, str]:
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


short = csvfile.short


#: Problems that make a row incomplete: with ``incomplete="drop"`` the row is left out.
INCOMPLETE_CODES = frozenset({"empty", "not-a-number", "not-finite", "ragged"})
IncompleteMode = choices.IncompleteMode  # the one table of choices (robocal.choices)

#: Problems of one kind listed at most (one more line counts the rest): a file with a
#: million bad cells must not cost a million messages' memory.
MAX_LISTED = 1000

#: Names a separator may be given by (on a command line a tab is hard to type).
SEPARATOR_NAMES = {"tab": "\t", "\\t": "\t", "space": " ", "whitespace": " ", "semicolon": ";", "comma": ","}


_JOINT_LIKE = re.compile(r"q(\d+)$")


class ReaderState:
    """What :class:`robocal.measure.dataset.reader._Reader` knows of a file (its options, set
    by its ``__init__``; the header and the rows' arrays, set while reading) and its problem
    list; the base of the reader's parts (:class:`_ColumnResolver`, ``_RowChecks``)."""

    # the options (SI factors ``L`` per length unit, ``A`` per angle unit)
    path: Path
    L: float
    A: float
    length_unit: str
    angle_unit: str
    rename: dict[str, str]
    sep: str | None
    decimal: str
    dof: int | None
    model: Model | None
    limits: LimitsMode
    orientation: _Orientation
    extra_names: list[str]
    incomplete: IncompleteMode
    problems: list[Problem]
    # the header: its cells, line number (1-based) and each name's column index
    head: csvfile.Head
    header_line: int
    header: list[str]
    where: dict[str, int]
    # the rows, shape (n,): line numbers, byte offsets, split into cells, with a missing/bad value
    line_no: NDArray[np.int64]
    offsets: NDArray[np.int64]
    good: NDArray[np.bool_]
    incomplete_rows: NDArray[np.bool_]
    # per column index: its numbers (NaN where bad), problems (code, message, line), counts, uses left
    columns: dict[int, Array]
    labels: NDArray[np.str_]
    found: dict[int, list[tuple[str, str, int]]]
    counts: dict[int, int]
    uses: dict[int, int]

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

    def _listed(
        self, items: NDArray[_Item], code: str, column: str | None, severity: Severity = "error"
    ) -> NDArray[_Item]:
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

    def _cell(self, i: int, name: str) -> str:
        """Row ``i``'s cell of column ``name`` as written (read again from the file)."""
        cells = csvfile.row_at(self.head, int(self.offsets[i]))
        k = self.where[name]
        return cells[k].strip() if k < len(cells) else ""


class ColumnResolver(ReaderState):
    """The reader's column resolution: which header columns hold the joints, the position,
    sigma, orientation, temperature, set and extra values (``columns=`` renames applied).
    Mixed into :class:`robocal.measure.dataset.reader._Reader`, whose header and problem
    list it uses."""

    def _header_text(self, limit: int = 20) -> str:
        shown = ", ".join(self.header[:limit])
        return shown + (f", ... ({len(self.header)} columns)" if len(self.header) > limit else "")

    def _col(self, name: str) -> str:
        return self.rename.get(name, name)

    def _has(self, name: str) -> bool:
        return self._col(name) in self.where

    def _resolve_columns(self) -> dict | None:
        self._check_renames()
        if self.model is not None:
            joints, dof = self._model_joints(self.model), self.model.dof
        else:
            joints, dof = self._counted_joints()
        self._check_extra_joints(dof)
        types = self.model.joint_types if self.model is not None else ("revolute",) * len(joints)
        joint_scale = np.array([self.A if t == "revolute" else self.L for t in types[: len(joints)]])
        position = self._group(POSITION, "a position")
        sigma = self._group(SIGMA, "a per-row standard deviation")
        ori_cols, kind = self._orientation_columns()
        if ori_cols and not position:
            self.error(
                "columns",
                "orientation columns without position columns x, y, z",
                self.header_line,
                ori_cols[0],
            )
        for name in self.extra_names:
            if name not in self.where:
                self.error(
                    "columns",
                    f"column {name!r} (asked for in extra=) is not in the header",
                    self.header_line,
                    name,
                )
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

    def _check_renames(self) -> None:
        """``columns=``: every key a robocal column name (else ValueError), every target in the header."""
        model = self.model
        known_keys = set(KNOWN) | set(model.joint_names if model else ())
        for key, target in self.rename.items():
            if not (key in known_keys or _JOINT_LIKE.match(key)):
                raise ValueError(
                    f"columns: {key!r} is not a robocal column name (q1.., x y z, qw qx qy qz, "
                    f"rx ry rz, sx sy sz, set, temperature{', model joint names' if model else ''})"
                )
            if target not in self.where:
                self.error(
                    "columns",
                    f"column {target!r} (given for {key!r} in columns=) is not in the header; header: "
                    f"{self._header_text()}",
                    self.header_line,
                    target,
                )

    def _model_joints(self, model: Model) -> list[str]:
        """The model's joint columns (``q<j>`` or the joint's name, renames first)."""
        joints: list[str] = []
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
                self.header_line,
            )
        return joints

    def _counted_joints(self) -> tuple[list[str], int]:
        """Without a model: ``q1..q<dof>`` (``dof`` given, else counted while present)."""
        hl = self.header_line
        dof = self.dof
        if dof is None:
            dof = 0
            while self._has(f"q{dof + 1}"):
                dof += 1
        missing = [f"q{j + 1}" for j in range(dof) if not self._has(f"q{j + 1}")]
        if missing:
            self.error(
                "missing-joint", f"missing joint column(s) {', '.join(missing)} (expected {dof} joints)", hl
            )
        joints = [self._col(f"q{j + 1}") for j in range(dof) if self._has(f"q{j + 1}")]
        if dof == 0:
            self.error(
                "missing-joint",
                "no joint columns: expected q1, q2, ... (or renames such as "
                f"columns={{'q1': 'shoulder_pan_joint'}}); header is {self._header_text()}",
                hl,
            )
        return joints, dof

    def _check_extra_joints(self, dof: int) -> None:
        """Joint-like columns beyond the model's or the counted joints."""
        model, hl = self.model, self.header_line
        if model is not None:
            expected = f"model {model.name!r} has {dof} joints ({', '.join(model.joint_names)})"
        elif self.dof is not None:
            expected = f"dof={dof} joints expected"
        else:
            expected = f"joints are read as q1..q{dof} while present, and q{dof + 1} is missing"
        for name in self.header:
            m = _JOINT_LIKE.match(name)
            if m and int(m.group(1)) > dof and name not in self.rename.values():
                self.error("extra-joint", f"extra joint column {name!r}: {expected}", hl, name)
        for key in self.rename:
            m = _JOINT_LIKE.match(key)
            if m and int(m.group(1)) > dof:
                self.error(
                    "extra-joint",
                    f"extra joint column {self.rename[key]!r} (given for {key!r}): {expected}",
                    hl,
                    self.rename[key],
                )

    def _group(self, names: Sequence[str], what: str, required: bool = False) -> list[str]:
        """The columns of a group that is all present or all absent (``required``: present)."""
        present = [n for n in names if self._has(n)]
        if (present and len(present) < len(names)) or (required and not present):
            absent = [self._col(n) for n in names if not self._has(n)]
            listed = ", ".join(map(self._col, names))
            self.error(
                "columns",
                f"{what} needs columns {listed}; missing {', '.join(absent)}",
                self.header_line,
                absent[0],
            )
            return []
        return [self._col(n) for n in names] if present else []

    def _orientation_columns(self) -> tuple[list[str], str]:
        """The orientation columns and how to read them (``orientation=``)."""
        ori = self.orientation
        if ori.kind == "auto":
            if any(self._has(n) for n in QUATERNION):
                return self._group(QUATERNION, "a quaternion"), "quaternion"
            if any(self._has(n) for n in ANGLES):
                return self._group(ANGLES, "a rotation vector"), "rotvec"
        elif ori.kind == "quaternion":
            return self._group(QUATERNION, "orientation='quaternion'", True), "quaternion"
        elif ori.kind == "rotvec":
            return self._group(ANGLES, "orientation='rotvec'", True), "rotvec"
        elif ori.kind == "euler":
            cols = self._group(ANGLES, f"orientation='euler:{ori.seq}'", True)
            return cols, f"euler:{ori.seq}:{ori.unit or self.angle_unit}"
        return [], ""


# ----------------------------------------------------------------------- guessing the columns
#: Joint column families the reader recognises, each ``(pattern, first number)``: UR's RTDE
#: log ``actual_q_0..5``, ``rostopic echo -p /joint_states`` ``field.position0..``, and
#: ``joint_1`` / ``j1`` / ``A1`` / ``axis1`` numbering.
_JOINT_FAMILIES = (
    (re.compile(r"actual_q_(\d+)$"), 0),
    (re.compile(r"field\.position(\d+)$"), 0),
    (re.compile(r"(?:joint|j|a|axis)[ _]?(\d+)(?:_joint)?$", re.IGNORECASE), None),
)
#: ROS joint names of the common arms, in chain order (UR: ``shoulder_pan_joint`` ...).
_ROS_CHAINS = (
    ("shoulder_pan_joint", "shoulder_lift_joint", "elbow_joint", "wrist_1_joint", "wrist_2_joint",
     "wrist_3_joint"),
    tuple(f"panda_joint{i}" for i in range(1, 8)),
    tuple(f"joint_a{i}" for i in range(1, 8)),
)  # fmt: skip
#: Prefixes of a measuring device's position columns (``measurement_x`` ...): never the
#: robot's own idea of its pose (``actual_TCP_pose_0``, ``Goal x``).
_DEVICE_PREFIX = re.compile(r"(meas\w*|track\w*|laser\w*|marker\w*|smr\w*|probe\w*)[ _.]?$", re.IGNORECASE)


def guess_columns(header: Sequence[str]) -> dict[str, str]:
    """The renames (robocal name -> file column, as ``columns=``) the header suggests.

    Joints: ``q1..qN`` as they are; else UR ``actual_q_0..``, ROS ``joint_states`` names
    (``shoulder_pan_joint`` ...), ``field.position0..``, ``joint_1``/``j1``/``A1``.
    Position: ``x, y, z`` as they are; else a measuring device's ``measurement_x`` ... (the
    commanded or the robot's own pose columns are never taken).  Orientation, sigma,
    temperature and set only under their own names: a guessed convention could read
    angles wrongly.  Returns only renames (columns already named as robocal names are not
    listed)."""
    names = [h.strip() for h in header]
    present = set(names)
    renames: dict[str, str] = {}
    if "q1" not in present:
        renames |= {f"q{j + 1}": c for j, c in enumerate(_guess_joints(names))}
    if not {"x", "y", "z"} & present:
        renames |= _guess_position(names)
    return renames


def _guess_joints(names: Sequence[str]) -> list[str]:
    """The joint columns in order (the first family found with joint 1 present), or []."""
    for chain in _ROS_CHAINS:
        found = [c for c in chain if c in names]
        if found and found == list(chain[: len(found)]):
            return found
    for pattern, first in _JOINT_FAMILIES:
        numbered = {int(m.group(1)): n for n in names if (m := pattern.match(n))}
        start = first if first is not None else (0 if 0 in numbered else 1)
        joints: list[str] = []
        while start + len(joints) in numbered:
            joints.append(numbered[start + len(joints)])
        if joints:
            return joints
    return []


def _guess_position(names: Sequence[str]) -> dict[str, str]:
    """``x, y, z`` from one device prefix with all three axes (``measurement_x`` ...), or {}."""
    for name in names:
        if name[-1:].lower() != "x" or not _DEVICE_PREFIX.fullmatch(name[:-1]):
            continue
        trio = {axis: name[:-1] + (axis if name[-1] == "x" else axis.upper()) for axis in "xyz"}
        if all(c in names for c in trio.values()):
            return trio
    return {}
