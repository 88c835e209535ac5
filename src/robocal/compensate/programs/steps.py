"""The program filter's steps: parse every file, build the robot for each target's tool and
base, correct joint targets and then Cartesian targets in execution order, and write the
numbers that moved (see :func:`robocal.compensate.programs.filter_file.filter_program_text`)."""

from __future__ import annotations

import re
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from robocal import spatial
from robocal.compensate.programs.config import config_changes, config_ok, config_starts
from robocal.compensate.programs.csv_dialect import parse_csv
from robocal.compensate.programs.frames import program_frames, report_other_frames, robot_models
from robocal.compensate.programs.krl import parse_krl
from robocal.compensate.programs.rapid import parse_rapid
from robocal.compensate.programs.syntax import (
    Array,
    Language,
    ProgramError,
    ProgramTarget,
    Unsupported,
    code_only,
    decimals_of,
    line_of,
    line_starts,
    line_text,
)
from robocal.compensate.programs.urscript import parse_urscript
from robocal.compensate.programs.values import UNITS, Units, format_value, write_values
from robocal.compensate.result import TABLE_COLUMNS, Compensation
from robocal.identify.result import CalibrationResult
from robocal.model.chain import Model
from robocal.units import unit_factor


@dataclass
class _Parsed:
    """Everything read from a program's files."""

    targets: list[ProgramTarget] = field(default_factory=list)
    unsupported: list[Unsupported] = field(default_factory=list)
    found_tool: Array | None = None
    events: list[tuple[int, int, str]] = field(default_factory=list)  # (file, position, name) of motions
    rapid_data: dict[str, dict] = field(default_factory=dict)
    code: dict[str, str] = field(default_factory=dict)  # per file: the text with comments, strings blanked


@dataclass
class _Corrections:
    """The corrected values and figures per target, filled in by the correction steps."""

    new_values: list[Array]
    before: Array
    after: Array
    reach: NDArray[np.bool_]
    kept: NDArray[np.bool_]
    problems: list[str]
    # per target, the safety outcome of :mod:`robocal.compensate.safety` (as compensate's):
    # "corrected", "damped" or "refused", its reason, and its per-target table row
    status: list[str] = field(default_factory=list)
    reasons: list[str] = field(default_factory=list)
    rows: list[dict | None] = field(default_factory=list)
    joints: list[Array | None] = field(default_factory=list)  # the command written (rad, m)
    flanks: list[str] = field(default_factory=list)  # Compensation.flank_notes

    @classmethod
    def start(cls, values: list[Array], problems: list[str]) -> _Corrections:
        n = len(values)
        return cls(
            new_values=list(values),
            before=np.full(n, np.nan),
            after=np.full(n, np.nan),
            reach=np.ones(n, dtype=bool),
            kept=np.ones(n, dtype=bool),
            problems=problems,
            status=["corrected"] * n,
            reasons=[""] * n,
            rows=[None] * n,
            joints=[None] * n,
            flanks=[""] * n,
        )

    def take(self, i: int, res: Compensation, k: int, table: list[dict] | None = None) -> None:
        """Target ``i``'s outcome from row ``k`` of a compensation (``table``: its
        ``res.table()``, built once per compensation); a refused target keeps its written
        value (``res.q`` is then the nominal command)."""
        self.before[i], self.after[i] = res.error_before[k] * 1e3, res.error_after[k] * 1e3
        self.status[i], self.reasons[i] = res.status[k], res.reasons[k]
        # reach: a command to write exists (IK reached, or damped near a singularity)
        self.reach[i] = bool(res.reachable[k]) or res.status[k] == "damped"
        self.kept[i] = res.status[k] != "refused"
        self.rows[i] = (res.table() if table is None else table)[k]
        self.joints[i] = np.asarray(res.q[k], dtype=float)
        # a flank not known: the command is written, the target named with its spread
        self.flanks[i] = res.flank_notes[k] if len(res.flank_notes) > k else ""
        self.problems.extend(note for note in res.notes if note not in self.problems)

    def refuse(self, i: int, reason: str) -> None:
        """Target ``i`` refused by the filter itself (e.g. its written configuration)."""
        self.status[i], self.reasons[i], self.kept[i] = "refused", reason, False
        row = self.rows[i]
        if row is not None:  # nothing of the correction is written
            row.update(status="refused", reason=reason, correction_mm=0.0, largest_joint_change=0.0)


FramesOf = Callable[[int], tuple[Model, Model, Array]]


def parse_program(texts: dict[str, str], language: Language, dof: int) -> _Parsed:
    """Parse the code of every file of a program (comments and strings masked, see
    :func:`code_only`: ``parsed.code``); motions to names the program does not declare
    with a value are listed as unsupported."""
    parsed = _Parsed()
    used: list[tuple[str, str, int, str]] = []  # (file, name, line, statement) of named motions
    for f, (label, text) in enumerate(texts.items()):
        code = parsed.code[label] = code_only(text, language)
        uses: list[tuple[int, str]] = []
        parsed.rapid_data[label] = {"tools": {}, "wobjs": {}, "moves": []}
        if language == "urscript":
            t, u, parsed.found_tool = parse_urscript(code, dof, label, uses)
        elif language == "krl":
            t, u, krl_used = parse_krl(code, dof, label, uses)
            used += [(label, *x) for x in krl_used]
        elif language == "rapid":
            t, u, parsed.found_tool = parse_rapid(code, dof, label, uses, parsed.rapid_data[label])
            used += [(label, name, line_of(code, pos), line_text(code, pos)) for pos, name in uses]
        elif language == "csv":
            t, u = parse_csv(text, dof, label), []
        else:
            raise ValueError(f"unknown language {language!r}")
        parsed.targets += t
        parsed.unsupported += u
        parsed.events += [(f, pos, name) for pos, name in uses]
    declared = {t.name.upper() for t in parsed.targets}
    _list_assignments(parsed, language, declared)
    for label, name, line, statement in used:
        if name.upper() not in declared:
            parsed.unsupported.append(
                Unsupported(
                    label,
                    line,
                    statement,
                    f"{name} has no value in this program (another module, run time): not corrected",
                )
            )
    return parsed


# statements that change a declared target at run time (not declarations): KRL ``XP1 = ...``,
# ``XP1.X = ...``; RAPID ``p1 := ...``, ``p1.trans.z := ...``
_ASSIGNMENTS = {
    "krl": re.compile(r"^[ \t]*(?!DECL\b)([A-Za-z_]\w*)(?:\.\w+)*\s*=(?!=)", re.M | re.I),
    "rapid": re.compile(r"^[ \t]*([A-Za-z_]\w*)(?:\.\w+)*\s*:=", re.M),
}


def _list_assignments(parsed: _Parsed, language: Language, declared: set[str]) -> None:
    """List the run-time assignments to declared targets: motions after them go to values
    the filter did not correct."""
    pattern = _ASSIGNMENTS.get(language)
    if pattern is None:
        return
    for label, code in parsed.code.items():
        for m in pattern.finditer(code):
            if m.group(1).upper() in declared:
                reason = f"{m.group(1)} is changed here: later motions to it are not corrected"
                parsed.unsupported.append(
                    Unsupported(label, line_of(code, m.start()), line_text(code, m.start()), reason)
                )


def check_probe(
    targets: list[ProgramTarget], calibrated: CalibrationResult | Model, probe: ArrayLike | None
) -> None:
    """Refuse Cartesian targets with a position-only calibration and no probe as built."""
    if probe is None and getattr(calibrated, "measure", "") == "position":
        pose = next((t for t in targets if t.kind == "pose"), None)
        if pose is not None:
            raise ProgramError(
                f"{pose.file}: line {pose.line}: Cartesian target {pose.name} and a calibration that "
                "measured positions only: give the probe as built with --probe x,y,z (m)"
            )


def program_units(language: Language, length_unit: str, angle_unit: str) -> Units:
    """The units of the program's numbers (CSV: as given; others: the language's)."""
    if language != "csv":
        return UNITS[language]
    lf = unit_factor(length_unit, "length", "length_unit")
    af = unit_factor(angle_unit, "angle", "angle_unit")
    return Units(lf, af, 7 if lf == 1.0 else 4, 7 if af == 1.0 else 5)


def frames_of_targets(
    texts: dict[str, str],
    language: Language,
    parsed: _Parsed,
    calibrated: CalibrationResult | Model,
    nominal: Model | None,
    tool: ArrayLike | None,
    base: ArrayLike | None,
    probe: ArrayLike | None,
    config_dat: tuple[str, str] | None,
    problems: list[str],
) -> FramesOf:
    """``frames_of(i)``: the (real, nominal) models with target ``i``'s tool, and its base."""
    T_tool = np.asarray(tool, dtype=float) if tool is not None else parsed.found_tool
    B = np.eye(4) if base is None else np.asarray(base, dtype=float)
    frame_at = program_frames(texts, language, parsed.rapid_data, config_dat, problems)
    label_of = list(texts)
    cache: dict[bytes, tuple[Model, Model]] = {}
    runs_of: dict[str, list[tuple[str, int]]] = {}  # the motions to each name, in file order
    for f, pos, name in parsed.events:
        runs_of.setdefault(name.upper(), []).append((label_of[f], pos))

    def frames_of(i: int) -> tuple[Model, Model, Array]:
        t = parsed.targets[i]
        runs = runs_of.get(t.name.upper(), [])
        T_i, B_i = frame_at(*(runs[0] if runs else (t.file, t.tokens[0].start)))
        if tool is None or base is None:
            report_other_frames(t, runs, (T_i, B_i), frame_at, texts, problems)
        T_i = T_tool if tool is not None or T_i is None else T_i
        B_i = B if base is not None or B_i is None else B_i
        key = b"" if T_i is None else np.asarray(T_i).tobytes()
        if key not in cache:
            cache[key] = robot_models(calibrated, nominal, T_i, probe)[:2]
        return (*cache[key], B_i)

    return frames_of


def correct_joint_targets(
    values: list[Array], joint_idx: list[int], frames_of: FramesOf, effects, tol: float, c: _Corrections
) -> None:
    """Filter the joint targets, grouped by the tool of their motion."""
    from robocal.compensate.compensation import filter_program

    groups: dict[int, list[int]] = {}
    for i in joint_idx:
        groups.setdefault(id(frames_of(i)[0]), []).append(i)
    for idx in groups.values():
        real_g, nom_g, _ = frames_of(idx[0])
        q = np.array([values[i] for i in idx])
        res = filter_program(real_g, q, nom_g, joint_effects=effects, tol=tol, tol_angle=tol)
        table = res.table()
        for k, i in enumerate(idx):
            c.new_values[i] = res.q[k]  # refused: the programmed joints (q_nominal)
            c.take(i, res, k, table)


def execution_order(texts: dict[str, str], parsed: _Parsed) -> list[int]:
    """Target indices in execution order: motions to named targets where they run, literal
    targets where they stand, declared targets never moved to at the end (file order)."""
    targets, events = parsed.targets, parsed.events
    files = {label: f for f, label in enumerate(texts)}
    by_name = {t.name.upper(): i for i, t in enumerate(targets)}
    used_names = {name.upper() for _, _, name in events}
    order = sorted(
        [(f, pos, by_name[name.upper()]) for f, pos, name in events if name.upper() in by_name]
        + [
            (files[t.file], t.tokens[0].start, i)
            for i, t in enumerate(targets)
            if t.name.upper() not in used_names
        ]
    )
    return list(dict.fromkeys(i for _, _, i in order))


def _solve_pose(
    t: ProgramTarget,
    real: Model,
    nom: Model,
    goal: Array,
    kind: Literal["position", "pose"],
    q_prev: Array,
    rng: np.random.Generator,
    opts: dict[str, Any],
) -> tuple[Compensation, str | None]:
    """Compensate one Cartesian target from ``q_prev``; when the nominal solution misses the
    written configuration (KUKA S/T, ABB cf/cfx), starts within it choose the branch.
    Returns the result and the change description (None: the configuration is met or not
    written)."""
    from robocal.compensate.compensation import compensate_targets

    res = compensate_targets(real, goal, nom, kind=kind, q0=q_prev, **opts)
    if res.nominal_reachable[0] and config_ok(t, res.q_nominal[0], nom):
        return res, None
    for q_start in config_starts(t, nom, rng, 24):
        trial = compensate_targets(real, goal, nom, kind=kind, q0=q_start, restarts=0, **opts)
        if trial.nominal_reachable[0] and config_ok(t, trial.q_nominal[0], nom):
            return trial, None
    if t.config is not None and res.reachable[0]:
        return res, ", ".join(config_changes(t, res.q_nominal[0], nom))
    return res, None


def correct_pose_targets(
    sequence: list[int],
    targets: list[ProgramTarget],
    values: list[Array],
    q_start: Array,
    frames_of: FramesOf,
    effects,
    tol: float,
    c: _Corrections,
) -> None:
    """Compensate the Cartesian targets in execution order; each one's branch is the
    configuration the robot comes from (the previous target)."""
    q_prev = q_start
    rng = np.random.default_rng(0)
    opts = {"joint_effects": effects, "tol": tol, "tol_angle": tol}
    for i in sequence:
        t = targets[i]
        if t.kind == "joint":
            q_prev = values[i]
            continue
        real, nom, B_i = frames_of(i)
        T = B_i @ values[i]
        position_only = len(t.tokens) == 3
        goal = T[:3, 3][None] if position_only else T[None]
        res, changes = _solve_pose(
            t, real, nom, goal, "position" if position_only else "pose", q_prev, rng, opts
        )
        c.take(i, res, 0)
        if changes is not None:
            c.refuse(i, f"reachable only in another configuration ({changes})")
        q_prev = res.q_nominal[0] if res.nominal_reachable[0] else q_prev
        corrected = spatial.inverse(B_i) @ nom.fk(res.q)[0]
        c.new_values[i] = corrected if c.status[i] != "refused" else values[i]


def rewrite_texts(
    texts: dict[str, str], targets: list[ProgramTarget], units: Units, types, c: _Corrections
) -> tuple[dict[str, str], NDArray[np.bool_]]:
    """The texts with the numbers that moved rewritten (file by file, last first), and which
    targets changed; a number within its written resolution is kept as written."""
    changed = np.zeros(len(targets), dtype=bool)
    edits: dict[str, list[tuple[int, int, str]]] = {label: [] for label in texts}
    for i, t in enumerate(targets):
        if c.status[i] == "refused":  # left as written
            continue
        for tok, (v, d) in zip(t.tokens, write_values(t, units, c.new_values[i], types), strict=True):
            if abs(v - tok.value) <= 0.5 * 10.0 ** (-max(decimals_of(tok.text), d)):
                continue  # below the written resolution: keep the token as written
            edits[t.file].append((tok.start, tok.end, format_value(v, tok.text, d)))
            changed[i] = True
    out = {}
    for label, text in texts.items():
        pieces, last = [], 0
        for s, e, new in sorted(edits[label]):  # spliced once, in order: linear in the text
            pieces += [text[last:s], new]
            last = e
        out[label] = "".join([*pieces, text[last:]])
    line_starts.cache_clear()  # the line index holds the texts: not kept past the filter
    return out, changed


def report_refused(targets: list[ProgramTarget], c: _Corrections) -> None:
    """A problem per refused target, with its reason (as compensate gives it)."""
    for i, t in enumerate(targets):
        if c.status[i] == "refused":
            c.problems.append(f"{t.file}: line {t.line}: target {t.name}: {c.reasons[i]}; left as written")
        elif c.flanks[i]:
            c.problems.append(f"{t.file}: line {t.line}: target {t.name}: {c.flanks[i]}")


def target_table(targets: list[ProgramTarget], c: _Corrections) -> tuple[dict, ...]:
    """The per-target table (:meth:`robocal.compensate.result.Compensation.table` rows, as
    compensate writes them), named ``FILE:LINE NAME``, in file order."""
    out = []
    for i, t in enumerate(targets):
        row = dict(c.rows[i] or dict.fromkeys(TABLE_COLUMNS) | {"joint": "-", "configuration": "-"})
        row |= {"status": c.status[i], "reason": c.reasons[i]}
        row["name"] = f"{Path(t.file).name}:{t.line} {t.name}"
        out.append(row)
    return tuple(out)
