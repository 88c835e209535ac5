"""Robot programs filtered through a calibration, in their own language.

:func:`filter_program_text` / :func:`filter_program_file` read a robot program, correct
every target through the calibration and write the same program with the corrected
numbers and nothing else changed: every other byte (comments, formatting, other
statements, the numbers of targets that need no correction) is kept.  A program filtered
with a nominal calibration (calibrated = nominal) is byte-identical to its input.

Corrections (:mod:`robocal.compensate.compensation`):

* a **joint target** ``q`` becomes the joint values that put the real (calibrated) tool
  where the nominal model puts it at ``q`` (:func:`~robocal.compensate.compensation.filter_program`);
* a **Cartesian target** ``P`` becomes ``P' = nominal.fk(q')`` with ``q'`` the joint
  values at which the real robot reaches ``P`` (:func:`~robocal.compensate.compensation.compensate`):
  the controller, commanded ``P'``, solves its nominal IK to ``q'`` and the real robot
  lands on ``P``.  The IK branch is that of the configuration the robot comes from:
  the previous target in execution order (motions to named targets count where they
  run, e.g. a KRL ``.src`` ``LIN XP1`` and not its ``.dat`` declaration).

The robot is the calibrated model without the measured tool (``tcp_*``) — but with
how far the identified tool is from the probe as built (``probe``; robot geometry the
tool absorbed, e.g. ``d6`` under position measurement) —; the program's tool
(``set_tcp`` in URScript, a RAPID ``tooldata`` of the module, else ``tool`` given) is
appended as a fixed frame, and targets are taken in the robot's
base frame (``base`` given: ``T_base_frame`` of a KUKA BASE or a RAPID work object).
Without ``tool``/``base`` each Cartesian target takes those of the first motion to it:
a RAPID Move's ``tooldata`` and ``\\WObj`` declared in the module, KRL ``$TOOL``/``$BASE``
(``TOOL_DATA[n]``/``BASE_DATA[n]``, or an ``FDAT``'s ``TOOL_NO``/``BASE_NO``) from the
``$config.dat`` given.

Supported grammar (anything else is left untouched; motion statements outside it are
listed in :attr:`FilteredProgram.unsupported`):

* **URScript** (``.script``, ``.urscript``; m, rad): ``movej/movel/movep/movec/servoj``
  calls whose targets are literals ``p[x, y, z, rx, ry, rz]`` (rotation vector) or joint
  lists ``[q1, ..., qN]``, or names assigned such literals (``name = p[...]``,
  ``global name = [...]``); ``set_tcp(p[...])`` sets the tool.
* **KUKA KRL** (``.src`` and the ``.dat`` of the same name; mm, degrees): aggregates
  ``{X .., Y .., Z .., A .., B .., C .. [, S .., T .., E1 ..]}`` of ``DECL E6POS|POS``
  declarations and of ``PTP/LIN/CIRC`` statements (Cartesian; ``A, B, C`` =
  ``Rz(A) Ry(B) Rx(C)``), ``{A1 .., ..., A6 .. [, E1 ..]}`` of ``DECL E6AXIS|AXIS``
  and ``PTP`` (joint).  ``FRAME`` declarations (bases, tools) are data, not targets.
  Status/turn (``S``, ``T``) and external axes are kept as written and met by the
  correction (:func:`_status_bits`; a target reachable only in another configuration
  is reported and left as written).
* **ABB RAPID** (``.mod``, ``.modx``, ``.prg``; mm, degrees): ``robtarget`` literals
  ``[[x,y,z],[q1,q2,q3,q4],[cf1,cf4,cf6,cfx],[eax..]]`` (quaternion scalar first) in
  declarations and in ``MoveJ/MoveL/MoveC`` statements, ``jointtarget`` literals
  ``[[j1..j6],[eax..]]`` in declarations and ``MoveAbsJ``; ``cf1, cf4, cf6, cfx`` kept
  and met by the correction (:func:`_cfx_bits`).
* **robocal target CSV** (``.csv``): ``name,x,y,z[,qw,qx,qy,qz]`` (Cartesian, in
  ``length_unit``) or ``[name,]q1..qN`` (joint, in ``angle_unit``); ``#`` lines kept.

Units: SI inside; each language's units in its file.
"""

from __future__ import annotations

import dataclasses
import math
import re
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from robocal import csvfile, spatial
from robocal.identify.calibrate import CalibrationResult
from robocal.identify.problem import frame_steps
from robocal.model.chain import Model, Role
from robocal.units import ANGLE_UNITS, LENGTH_UNITS, unit_factor

__all__ = [
    "FilteredProgram",
    "ProgramError",
    "ProgramTarget",
    "Unsupported",
    "filter_program_file",
    "filter_program_text",
    "language_of",
]

Array = NDArray[np.float64]
Language = Literal["urscript", "krl", "rapid", "csv"]
_NUM = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"
_NUM_RE = re.compile(_NUM)
DEG = ANGLE_UNITS["deg"]


class ProgramError(ValueError):
    """A program that cannot be read; the message names the file, the line and what."""


@dataclass(frozen=True)
class _Token:
    start: int  # character offsets in the text
    end: int
    text: str

    @property
    def value(self) -> float:
        return float(self.text)


@dataclass(frozen=True)
class ProgramTarget:
    """One target of a program.

    Attributes:
        name: the target's name (variable, declaration) or ``"line N"``.
        line: 1-based line in its file.
        kind: ``"joint"`` or ``"pose"``.
        file: which file of the program (``.src`` or ``.dat`` for KRL).
        tokens: the number tokens, in the order the format gives them.
        style: how the numbers map to SI (``"urscript"``, ``"krl"``, ``"rapid"``,
            ``"csv"``).
        config: the written configuration the IK must meet: KUKA ``(T, S)`` (turn: bit
            ``j`` set when axis ``j + 1`` is negative; status: see :func:`_status`;
            either ``None`` when not written), ABB ``(cf1, cf4, cf6, cfx)`` (the
            quadrants ``floor(axis / 90°)`` of axes 1, 4, 6; ``cfx`` see :func:`_cfx`);
            ``None`` when not given.
    """

    name: str
    line: int
    kind: Literal["joint", "pose"]
    file: str
    tokens: tuple[_Token, ...]
    style: str
    config: tuple[int | None, ...] | None = None


@dataclass(frozen=True)
class Unsupported:
    """A motion statement outside the supported grammar, left untouched."""

    file: str
    line: int
    text: str
    reason: str


@dataclass(frozen=True)
class FilteredProgram:
    """A filtered program.

    Attributes:
        texts: ``{file label: corrected text}`` (one entry; two for KRL ``.src`` + ``.dat``).
        targets: every target found, in file order.
        q: ``(n,)`` list of corrected joint values per target (rad, m) — the joints the
            robot will move to.
        error_before_mm, error_after_mm: ``(n,)`` predicted position error of the real
            robot (mm) unfiltered and filtered.
        reachable, branch_kept: ``(n,)`` per target.
        changed: ``(n,)`` whether the target's text was rewritten.
        unsupported: motion statements left untouched.
        language: the language.
    """

    texts: dict[str, str]
    targets: tuple[ProgramTarget, ...]
    error_before_mm: Array
    error_after_mm: Array
    reachable: NDArray[np.bool_]
    branch_kept: NDArray[np.bool_]
    changed: NDArray[np.bool_]
    unsupported: tuple[Unsupported, ...] = ()
    language: str = ""
    problems: tuple[str, ...] = field(default=())

    @property
    def ok(self) -> bool:
        return bool(np.all(self.reachable & self.branch_kept))


# ---------------------------------------------------------------------- helpers
def _line_of(text: str, pos: int) -> int:
    return text.count("\n", 0, pos) + 1


def _tokens(text: str, start: int, end: int) -> list[_Token]:
    return [_Token(start + m.start(), start + m.end(), m.group()) for m in _NUM_RE.finditer(text[start:end])]


def _matching(text: str, i: int, open_: str, close: str) -> int:
    """Index after the bracket closing the one at ``i``."""
    depth = 0
    for k in range(i, len(text)):
        if text[k] == open_:
            depth += 1
        elif text[k] == close:
            depth -= 1
            if depth == 0:
                return k + 1
    return -1


def _decimals(token: str) -> int:
    mant = token.split("e")[0].split("E")[0]
    return len(mant.split(".")[1]) if "." in mant else 0


# ---------------------------------------------------------------------- URScript
_UR_MOVE = re.compile(r"\b(movej|movel|movep|movec|servoj)\s*\(")
_UR_ASSIGN = re.compile(r"^[ \t]*(?:(?:global|local)\s+)?([A-Za-z_]\w*)\s*=\s*(p?)\[", re.M)
_UR_TCP = re.compile(r"\bset_tcp\s*\(\s*p\[")


def _ur_literal(text: str, i: int, dof: int, what: str, path: str) -> tuple[str, list[_Token], int] | None:
    """At ``i`` a ``p[...]`` (pose) or ``[...]`` (joint list): kind, tokens, end."""
    pose = text[i] == "p"
    b = i + 1 if pose else i
    end = _matching(text, b, "[", "]")
    if end < 0:
        raise ProgramError(f"{path}: line {_line_of(text, i)}: unclosed '[' in {what}")
    inner = text[b + 1 : end - 1]
    parts = [s.strip() for s in inner.split(",")]
    if not all(re.fullmatch(_NUM, s) for s in parts):
        return None
    toks = _tokens(text, b + 1, end - 1)
    if pose and len(toks) != 6:
        raise ProgramError(
            f"{path}: line {_line_of(text, i)}: a pose p[...] needs 6 numbers, got {len(toks)}"
        )
    if not pose and len(toks) != dof:
        return None
    return ("pose" if pose else "joint"), toks, end


def _parse_urscript(
    text: str, dof: int, path: str, uses: list | None = None
) -> tuple[list[ProgramTarget], list[Unsupported], Array | None]:
    targets: list[ProgramTarget] = []
    unsupported: list[Unsupported] = []
    names: set[str] = set()
    for m in _UR_ASSIGN.finditer(text):
        i = m.end() - 1 - len(m.group(2))
        lit = _ur_literal(text, i, dof, f"the assignment to {m.group(1)}", path)
        if lit is not None:
            kind, toks, _ = lit
            names.add(m.group(1))
            targets.append(ProgramTarget(m.group(1), _line_of(text, i), kind, path, tuple(toks), "urscript"))
    for m in _UR_MOVE.finditer(text):
        call_end = _matching(text, m.end() - 1, "(", ")")
        line = _line_of(text, m.start())
        if call_end < 0:
            raise ProgramError(f"{path}: line {line}: unclosed '(' in {m.group(1)}")
        args = _split_args(text, m.end(), call_end - 1)
        n_targets = 2 if m.group(1) == "movec" else 1
        for a_start, a_end in args[:n_targets]:
            arg = text[a_start:a_end]
            stripped = arg.strip()
            first = a_start + len(arg) - len(arg.lstrip())
            if stripped.startswith(("p[", "[")):
                lit = _ur_literal(text, first, dof, m.group(1), path)
                if lit is None:
                    unsupported.append(
                        Unsupported(
                            path,
                            line,
                            _line_text(text, m.start()),
                            f"target is not a pose p[...] nor {dof} joint values",
                        )
                    )
                    continue
                kind, toks, _ = lit
                targets.append(ProgramTarget(f"line {line}", line, kind, path, tuple(toks), "urscript"))
            elif re.fullmatch(r"[A-Za-z_]\w*", stripped) and stripped in names:
                if uses is not None:  # corrected where it is assigned; executed here
                    uses.append((a_start, stripped))
            else:
                reason = f"target {stripped!r} is not a literal nor a variable assigned a literal"
                unsupported.append(Unsupported(path, line, _line_text(text, m.start()), reason))
    tool = None
    m = _UR_TCP.search(text)
    if m:
        lit = _ur_literal(text, m.end() - 2, dof, "set_tcp", path)
        if lit is not None:
            v = [t.value for t in lit[1]]
            if not all(map(math.isfinite, v)):
                raise ProgramError(f"{path}: line {_line_of(text, m.start())}: set_tcp: not finite numbers")
            tool = spatial.homogeneous(spatial.rotvec_to_matrix(v[3:]), v[:3])
    targets.sort(key=lambda t: t.tokens[0].start)
    return targets, unsupported, tool


def _split_args(text: str, start: int, end: int) -> list[tuple[int, int]]:
    out, depth, s = [], 0, start
    for k in range(start, end):
        c = text[k]
        if c in "([":
            depth += 1
        elif c in ")]":
            depth -= 1
        elif c == "," and depth == 0:
            out.append((s, k))
            s = k + 1
    out.append((s, end))
    return out


def _line_text(text: str, pos: int) -> str:
    a = text.rfind("\n", 0, pos) + 1
    b = text.find("\n", pos)
    return text[a : b if b >= 0 else len(text)].strip()


# ---------------------------------------------------------------------- KRL
_KRL_AGG = re.compile(r"\{([^{}]*)\}")
_KRL_DECL = re.compile(r"^[ \t]*DECL\s+(E6POS|POS|E6AXIS|AXIS|FRAME)\s+(\w+)\s*=\s*\{", re.M | re.I)
_KRL_MOTION = re.compile(r"^[ \t]*(PTP|LIN|CIRC|PTP_REL|LIN_REL|SPTP|SLIN|SCIRC)\b(.*)$", re.M | re.I)
_KRL_POSE_KEYS = ("X", "Y", "Z", "A", "B", "C")


def _krl_fields(text: str, start: int, end: int) -> dict[str, _Token]:
    fields = {}
    for m in re.finditer(r"([A-Za-z]\w*)\s+(" + _NUM + ")", text[start:end]):
        fields[m.group(1).upper()] = _Token(start + m.start(2), start + m.end(2), m.group(2))
    return fields


def _krl_bits(token: _Token | None, limit: int) -> int | None:
    """A KRL status or turn as written (``None`` when absent or not an integer in range)."""
    if token is None or token.value != int(token.value) or not 0 <= token.value < limit:
        return None
    return int(token.value)


def _krl_target(text: str, start: int, end: int, dof: int, name: str, path: str) -> ProgramTarget | None:
    f = _krl_fields(text, start, end)
    line = _line_of(text, start)
    if all(k in f for k in _KRL_POSE_KEYS):
        turn, status = (_krl_bits(f.get(k), 64) for k in ("T", "S"))
        for key, bits in re.findall(r"\b([ST])\s+'B([01]{1,6})'", text[start:end], re.I):
            if key.upper() == "T":
                turn = int(bits, 2)  # KRL binary literal, e.g. T 'B010010'
            else:
                status = int(bits, 2)
        config = None if turn is None and status is None else (turn, status)
        return ProgramTarget(name, line, "pose", path, tuple(f[k] for k in _KRL_POSE_KEYS), "krl", config)
    axes = [f"A{j + 1}" for j in range(dof)]
    if all(k in f for k in axes):
        return ProgramTarget(name, line, "joint", path, tuple(f[k] for k in axes), "krl")
    return None


def _parse_krl(
    text: str, dof: int, path: str, uses: list | None = None
) -> tuple[list[ProgramTarget], list[Unsupported], list[tuple[str, int, str]]]:
    targets: list[ProgramTarget] = []
    unsupported: list[Unsupported] = []
    used: list[tuple[str, int, str]] = []  # names used by motions: (name, line, statement)
    for m in _KRL_DECL.finditer(text):
        kind, name = m.group(1).upper(), m.group(2)
        b = m.end() - 1
        end = _matching(text, b, "{", "}")
        if end < 0:
            raise ProgramError(f"{path}: line {_line_of(text, b)}: unclosed '{{' in DECL {kind} {name}")
        if kind == "FRAME":
            continue  # bases and tools: data, not targets
        t = _krl_target(text, b, end, dof, name, path)
        if t is None:
            raise ProgramError(
                f"{path}: line {_line_of(text, b)}: DECL {kind} {name} lacks "
                + ("X, Y, Z, A, B, C" if "POS" in kind else f"A1..A{dof}")
            )
        targets.append(t)
    for m in _KRL_MOTION.finditer(text):
        cmd, rest = m.group(1).upper(), m.group(2)
        line = _line_of(text, m.start())
        if cmd.endswith("_REL") or cmd.startswith("S"):
            unsupported.append(Unsupported(path, line, m.group(0).strip(), f"{cmd} is not supported"))
            continue
        rest_start = m.start(2)
        code = rest.split(";")[0]  # a KRL comment starts with ';'
        if code.count("{") != code.count("}"):
            raise ProgramError(f"{path}: line {line}: unbalanced '{{' '}}' in {cmd}: {m.group(0).strip()}")
        aggs = list(_KRL_AGG.finditer(rest))
        if aggs:
            for a in aggs[: 2 if cmd == "CIRC" else 1]:
                t = _krl_target(text, rest_start + a.start(), rest_start + a.end(), dof, f"line {line}", path)
                if t is None:
                    unsupported.append(
                        Unsupported(path, line, m.group(0).strip(), "aggregate is not a target")
                    )
                else:
                    targets.append(t)
            continue
        first = rest.strip().split()[0] if rest.strip() else ""
        if not re.fullmatch(r"[A-Za-z_$]\w*(?::\w+(?:\[\d+\])?)*", first.rstrip(",")) or first.startswith(
            "$"
        ):
            unsupported.append(
                Unsupported(path, line, m.group(0).strip(), "target is not a name or aggregate")
            )
        else:
            used.append((first.split(":")[0].rstrip(","), line, m.group(0).strip()))
            if uses is not None:
                uses.append((m.start(), first.split(":")[0].rstrip(",")))
    targets.sort(key=lambda t: t.tokens[0].start)
    return targets, unsupported, used


_KRL_SET = re.compile(
    r"^[ \t]*(?:\$(TOOL|BASE)\s*=\s*(?:TOOL|BASE)_DATA\[(\d+)\]|FDAT_ACT\s*=\s*(\w+))", re.M | re.I
)
_KRL_FDAT = re.compile(r"^[ \t]*DECL\s+FDAT\s+(\w+)\s*=\s*\{([^{}]*)\}", re.M | re.I)
_KRL_DATA = re.compile(r"\b(TOOL|BASE)_DATA\[(\d+)\]\s*=\s*\{([^{}]*)\}", re.I)


def _krl_settings(texts: dict[str, str]) -> dict[str, list[tuple[int, int, str, int]]]:
    """Per file, the tool and base settings in order: ``(position, line, "TOOL"|"BASE", n)``
    from ``$TOOL = TOOL_DATA[n]``, ``$BASE = BASE_DATA[n]`` and ``FDAT_ACT = F``
    (``TOOL_NO``/``BASE_NO`` of the ``DECL FDAT F`` of the program)."""
    fdat = {}
    for text in texts.values():
        for m in _KRL_FDAT.finditer(text):
            fields = {k.upper(): v for k, v in re.findall(r"(\w+)\s+(\d+)", m.group(2))}
            fdat[m.group(1).upper()] = fields
    out: dict[str, list[tuple[int, int, str, int]]] = {}
    for label, text in texts.items():
        out[label] = []
        for m in _KRL_SET.finditer(text):
            line = _line_of(text, m.start())
            if m.group(1):
                out[label].append((m.start(), line, m.group(1).upper(), int(m.group(2))))
            elif m.group(3).upper() in fdat:
                fields = fdat[m.group(3).upper()]
                for kind in ("TOOL", "BASE"):
                    if f"{kind}_NO" in fields:
                        out[label].append((m.start(), line, kind, int(fields[f"{kind}_NO"])))
    return out


def _krl_frame(fields: dict[str, _Token]) -> Array:
    """``{X, Y, Z, A, B, C}`` (mm, deg; ``Rz(A) Ry(B) Rx(C)``) as a frame in m."""
    v = [fields[k].value if k in fields else 0.0 for k in _KRL_POSE_KEYS]
    R = spatial.rotz(v[3] * DEG) @ spatial.roty(v[4] * DEG) @ spatial.rotx(v[5] * DEG)
    return spatial.homogeneous(R, np.array(v[:3]) * 1e-3)


def _krl_config_frames(text: str, path: str) -> dict[tuple[str, int], Array]:
    """``TOOL_DATA[n]`` / ``BASE_DATA[n]`` of a ``$config.dat``: ``{("TOOL", n): frame}``."""
    out = {}
    for m in _KRL_DATA.finditer(text):
        fields = _krl_fields(text, m.start(3), m.end(3))
        if not all(k in fields for k in ("X", "Y", "Z")):
            raise ProgramError(f"{path}: line {_line_of(text, m.start())}: {m.group(0)[:40]} lacks X, Y, Z")
        out[(m.group(1).upper(), int(m.group(2)))] = _krl_frame(fields)
    return out


# ---------------------------------------------------------------------- RAPID
_RAPID_DECL = re.compile(
    r"\b(?:CONST|PERS|VAR)\s+(robtarget|jointtarget|tooldata|wobjdata)\s+(\w+)\s*:=\s*\[", re.I
)
_RAPID_MOVE = re.compile(r"^[ \t]*(MoveJ|MoveL|MoveC|MoveAbsJ)\b([^;]*);", re.M | re.I)


def _rapid_groups(text: str, b: int, path: str) -> tuple[list[tuple[int, int]], int]:
    """The top-level ``[...]`` groups inside the bracket at ``b``, and its end."""
    end = _matching(text, b, "[", "]")
    if end < 0:
        raise ProgramError(f"{path}: line {_line_of(text, b)}: unclosed '['")
    groups, k = [], b + 1
    while k < end - 1:
        if text[k] == "[":
            e = _matching(text, k, "[", "]")
            groups.append((k, e))
            k = e
        else:
            k += 1
    return groups, end


def _rapid_target(text: str, b: int, kind: str, dof: int, name: str, path: str) -> tuple[ProgramTarget, int]:
    groups, end = _rapid_groups(text, b, path)
    line = _line_of(text, b)
    if kind == "robtarget":
        if len(groups) < 2:
            raise ProgramError(f"{path}: line {line}: robtarget {name} needs [[x,y,z],[q1,q2,q3,q4],...]")
        toks = _tokens(text, *groups[0]) + _tokens(text, *groups[1])
        if len(toks) != 7:
            raise ProgramError(f"{path}: line {line}: robtarget {name}: trans and rot need 3 + 4 numbers")
        config = None
        if len(groups) >= 3:
            cf = [t.value for t in _tokens(text, *groups[2])]
            if len(cf) == 4 and all(v == int(v) for v in cf):
                config = tuple(int(v) for v in cf)
        return ProgramTarget(name, line, "pose", path, tuple(toks), "rapid", config), end
    if not groups:
        raise ProgramError(f"{path}: line {line}: jointtarget {name} needs [[j1..j6],[eax..]]")
    toks = _tokens(text, *groups[0])
    if len(toks) < dof:
        raise ProgramError(
            f"{path}: line {line}: jointtarget {name}: {len(toks)} axes for a {dof}-joint robot"
        )
    return ProgramTarget(name, line, "joint", path, tuple(toks[:dof]), "rapid"), end


def _rapid_pose(text: str, b: int, path: str, what: str) -> Array | None:
    """The frame ``[[x,y,z],[q1,q2,q3,q4]]`` (mm, quaternion scalar first) at ``b`` in m."""
    inner, _ = _rapid_groups(text, b, path)
    if len(inner) < 2:
        return None
    p = [t.value for t in _tokens(text, *inner[0])]
    qv = [t.value for t in _tokens(text, *inner[1])]
    if len(p) != 3 or len(qv) != 4:
        return None
    norm = float(np.linalg.norm(qv))
    if not (math.isfinite(norm) and norm > 1e-9 and all(map(math.isfinite, p))):
        raise ProgramError(f"{path}: line {_line_of(text, b)}: {what} is not a frame")
    R = spatial.quaternion_to_matrix(np.array(qv) / norm)
    return spatial.homogeneous(R, np.array(p) * 1e-3)


def _rapid_move_frames(text: str, m: re.Match) -> tuple[str | None, str | None]:
    """The tool and work object (names, upper case) a Move statement names."""
    args = [text[a:b].strip() for a, b in _split_args(text, m.start(2), m.end(2))]
    positional = [a for a in args if a and not a.startswith("\\")]
    k = {"movec": 4}.get(m.group(1).lower(), 3)
    tool = None
    if len(positional) > k:
        word = re.match(r"\w+", positional[k])
        tool = word.group() if word else None
    wobj = re.search(r"\\WObj\s*:=\s*(\w+)", m.group(2), re.I)
    return tool, (wobj.group(1) if wobj else None)


def _parse_rapid(
    text: str, dof: int, path: str, uses: list | None = None, data: dict | None = None
) -> tuple[list[ProgramTarget], list[Unsupported], Array | None]:
    targets: list[ProgramTarget] = []
    unsupported: list[Unsupported] = []
    tool = None
    for m in _RAPID_DECL.finditer(text):
        kind, name = m.group(1).lower(), m.group(2)
        b = m.end() - 1
        if kind == "tooldata":
            groups, _ = _rapid_groups(text, b, path)
            if groups:
                frame = _rapid_pose(text, groups[0][0], path, f"tooldata {name}: tframe")
                if frame is not None:
                    tool = frame
                    if data is not None:
                        data["tools"][name.upper()] = frame
            continue
        if kind == "wobjdata":
            groups, _ = _rapid_groups(text, b, path)
            frames = [
                _rapid_pose(text, g[0], path, f"wobjdata {name}: {w}")
                for g, w in zip(groups[:2], ("uframe", "oframe"), strict=False)
            ]
            if len(frames) != 2 or any(f is None for f in frames):
                line = _line_of(text, b)
                raise ProgramError(f"{path}: line {line}: wobjdata {name} needs uframe and oframe")
            if data is not None:
                data["wobjs"][name.upper()] = frames[0] @ frames[1]
            continue
        t, _ = _rapid_target(text, b, kind, dof, name, path)
        targets.append(t)
    for m in _RAPID_MOVE.finditer(text):
        cmd = m.group(1)
        line = _line_of(text, m.start())
        if data is not None:
            data["moves"].append((m.start(), m.end(), line, *_rapid_move_frames(text, m)))
        args = m.group(2)
        offset = m.start(2)
        k = 0
        count = 0
        wanted = 2 if cmd.lower() == "movec" else 1
        kind = "jointtarget" if cmd.lower() == "moveabsj" else "robtarget"
        while count < wanted:
            arg_text = args[k:].lstrip()
            pos = offset + len(args) - len(arg_text)
            if arg_text.startswith("["):
                t, end = _rapid_target(text, pos, kind, dof, f"line {line}", path)
                targets.append(t)
                k = end - offset
            else:
                first = re.match(r"[\\\w]+", arg_text)
                if first is None or first.group().startswith("\\") or "(" in arg_text.split(",")[0]:
                    unsupported.append(
                        Unsupported(path, line, m.group(0).strip(), "target is not a name or literal")
                    )
                    break
                k = len(args) - len(arg_text) + first.end()
                if uses is not None:
                    uses.append((pos, first.group()))
            count += 1
            comma = args.find(",", k)
            if comma < 0:
                break
            k = comma + 1
    targets.sort(key=lambda t: t.tokens[0].start)
    return targets, unsupported, tool


# ---------------------------------------------------------------------- CSV
def _parse_csv(text: str, dof: int, path: str) -> list[ProgramTarget]:
    lines = text.splitlines(keepends=True)
    pos = 0
    header: list[str] | None = None
    sep = ","
    targets = []
    for k, line in enumerate(lines):
        start, pos = pos, pos + len(line)
        body = line.rstrip("\r\n")
        if not body.strip() or body.lstrip().startswith("#"):
            continue
        if header is None:
            sep = csvfile.sniff(body)
            header = [h.strip().lower() for h, _ in csvfile.cells_with_offsets(body, sep)]
            quat = [c in header for c in ("qw", "qx", "qy", "qz")]
            if any(quat) and not all(quat):
                raise ProgramError(f"{path}: line {k + 1}: orientation needs all of qw, qx, qy, qz")
            continue
        split = csvfile.cells_with_offsets(body, sep)
        cells, offs = [c for c, _ in split], [start + o for _, o in split]
        if len(cells) != len(header):
            raise ProgramError(f"{path}: line {k + 1}: {len(cells)} fields, the header has {len(header)}")

        def tok(col: str, cells=cells, offs=offs, k=k, header=header) -> _Token:
            j = header.index(col)
            raw = cells[j]
            s = raw.strip()
            if not re.fullmatch(_NUM, s):
                raise ProgramError(f"{path}: line {k + 1}, column {col!r}: {s!r} is not a number")
            a = offs[j] + raw.index(s)
            return _Token(a, a + len(s), s)

        name = cells[header.index("name")].strip() if "name" in header else f"line {k + 1}"
        if all(c in header for c in ("x", "y", "z")):
            cols = ["x", "y", "z"] + (["qw", "qx", "qy", "qz"] if "qw" in header else [])
            targets.append(ProgramTarget(name, k + 1, "pose", path, tuple(tok(c) for c in cols), "csv"))
        elif all(f"q{j + 1}" in header for j in range(dof)):
            cols = [f"q{j + 1}" for j in range(dof)]
            targets.append(ProgramTarget(name, k + 1, "joint", path, tuple(tok(c) for c in cols), "csv"))
        else:
            raise ProgramError(f"{path}: line {k + 1}: the header has neither x,y,z nor q1..q{dof}")
    if header is None:
        raise ProgramError(f"{path}: no header line")
    return targets


# ---------------------------------------------------------------------- values
@dataclass(frozen=True)
class _Units:
    length: float  # SI per file unit
    angle: float
    length_decimals: int
    angle_decimals: int


_UNITS = {
    "urscript": _Units(1.0, 1.0, 7, 7),
    "krl": _Units(LENGTH_UNITS["mm"], ANGLE_UNITS["deg"], 4, 5),
    "rapid": _Units(LENGTH_UNITS["mm"], ANGLE_UNITS["deg"], 4, 5),
}


def _read_value(t: ProgramTarget, u: _Units, joint_types: Sequence[str], csv_pose_quat: bool) -> Array:
    v = np.array([k.value for k in t.tokens])
    bad = [k.text for k in t.tokens if not math.isfinite(k.value)]
    if bad:
        raise ProgramError(f"{t.file}: line {t.line}: target {t.name}: {bad[0]} is not a finite number")
    if t.kind == "joint":
        return v * np.array([u.angle if jt == "revolute" else u.length for jt in joint_types])
    p = v[:3] * u.length
    if t.style == "urscript":
        R = spatial.rotvec_to_matrix(v[3:6])
    elif t.style == "krl":
        R = spatial.rotz(v[3] * DEG) @ spatial.roty(v[4] * DEG) @ spatial.rotx(v[5] * DEG)
    elif len(v) == 7:  # rapid, csv with a quaternion (scalar first)
        n = np.linalg.norm(v[3:7])
        if n < 1e-9:
            raise ProgramError(f"{t.file}: line {t.line}: target {t.name}: the quaternion is zero")
        R = spatial.quaternion_to_matrix(v[3:7] / n)
    else:
        R = None
    return spatial.homogeneous(R, p) if R is not None else spatial.homogeneous(p=p)


def _write_values(
    t: ProgramTarget, u: _Units, value: Array, joint_types: Sequence[str]
) -> list[tuple[float, int]]:
    """New numbers (file units) with the decimals to write, for ``t``'s tokens."""
    old = np.array([k.value for k in t.tokens])
    if t.kind == "joint":
        f = np.array([u.angle if jt == "revolute" else u.length for jt in joint_types])
        d = [u.angle_decimals if jt == "revolute" else u.length_decimals for jt in joint_types]
        return list(zip(value / f, d, strict=True))
    T = value
    out = [(float(c), u.length_decimals) for c in T[:3, 3] / u.length]
    if len(t.tokens) == 3:
        return out
    if t.style == "urscript":
        rv = spatial.matrix_to_rotvec(T[:3, :3])
        th = np.linalg.norm(rv)
        if th > 1e-9 and float(rv @ old[3:6]) < 0 and abs(th - math.pi) < 0.5:  # the other side of π
            rv = -rv / th * (2 * math.pi - th)
        out += [(float(c), u.angle_decimals) for c in rv]
    elif t.style == "krl":
        rz, ry, rx = spatial.zyx_angles(T[:3, :3])
        angles = np.degrees([rz, ry, rx])
        angles = old[3:6] + (angles - old[3:6] + 180.0) % 360.0 - 180.0  # nearest to the written angle
        # KRL wants -180..180; what rounds to ±180 at the written resolution stays as written
        beyond = np.abs(angles) > 180.0 + 0.5 * 10.0**-u.angle_decimals
        angles = np.where(beyond, angles - 360.0 * np.sign(angles), angles)
        out += [(float(c), u.angle_decimals) for c in angles]
    else:
        qv = spatial.matrix_to_quaternion(T[:3, :3])
        if float(qv @ old[3:7]) < 0:
            qv = -qv
        qv = qv * np.linalg.norm(old[3:7])  # as normalised as the file's (6 decimals rarely are)
        out += [(float(c), 9) for c in qv]
    return out


def _format(value: float, token: str, decimals: int) -> str:
    d = max(_decimals(token), decimals)
    text = f"{value:.{d}f}"
    if "." in text and "." not in token:
        text = text.rstrip("0").rstrip(".") if d > 0 else text
    if text in ("-0", "-0.0") or re.fullmatch(r"-0\.0*", text):
        text = text[1:]
    return text


# ---------------------------------------------------------------------- configurations
_EPS_DEG = 1e-6  # degrees: an axis at a boundary (0, ±90 ...) meets either side
_EPS_M = 1e-6  # m: a wrist centre on a boundary (axis 1, the lower arm's line) meets either side


def _axis_line(F: Array, model: Model, j: int) -> tuple[Array, Array]:
    """A point (m) and the unit direction of joint ``j``'s axis in the base frame."""
    axis = [s for s in model.steps if s.joint is not None][j].axis
    return F[j][:3, 3], F[j][:3, axis]


def _wrist_centre(F: Array, model: Model) -> Array:
    """The wrist centre (m): the point of axis 5 nearest axis 4 (where they cross)."""
    p4, a4 = _axis_line(F, model, 3)
    p5, a5 = _axis_line(F, model, 4)
    c = float(a4 @ a5)
    d = p5 - p4
    if abs(1 - c * c) < 1e-12:
        return p5
    t = (c * (a4 @ d) - a5 @ d) / (1 - c * c)
    return p5 + t * a5


def _arm_sides(model: Model, q: Array) -> tuple[float, float]:
    """Where the wrist centre is, as signed distances (m; ~0 on a boundary).

    ``front``: in front of axis 1 (> 0) or behind it (overhead), measured along the
    direction the wrist centre has from axis 1 at the zero position, turned with axis 1.
    ``elbow``: ``((p3 - p2) x (w - p3)) . a3`` — > 0 when axis 3 is beyond the angle that
    stretches the arm (wrist centre on the line of axes 2 and 3), i.e. elbow up."""
    F = model.joint_frames(q)
    F0 = model.joint_frames(np.zeros(model.dof))
    p1, a1 = _axis_line(F0, model, 0)
    h0 = _wrist_centre(F0, model) - p1
    h0 -= (h0 @ a1) * a1
    front = 0.0
    w = _wrist_centre(F, model)
    if np.linalg.norm(h0) > 1e-9:
        local = F0[0][:3, :3].T @ (h0 / np.linalg.norm(h0))
        front = float((w - F[0][:3, 3]) @ (F[0][:3, :3] @ local))
    p2, _ = _axis_line(F, model, 1)
    p3, a3 = _axis_line(F, model, 2)
    elbow = float(np.cross(p3 - p2, w - p3) @ a3)
    return front, elbow


def _digit(value: float, eps: float, negative_bit: int) -> set[int]:
    """The bit values a signed quantity allows: ``negative_bit`` when < 0 (both near 0)."""
    if abs(value) < eps:
        return {0, 1}
    return {negative_bit if value < 0 else 1 - negative_bit}


def _status_bits(model: Model, q: Array) -> list[set[int]]:
    """KUKA status bits 0, 1, 2 that joint values ``q`` (rad) allow: bit 0 set when the
    wrist centre is behind axis 1 (overhead), bit 1 set when A3 >= phi (the angle that
    stretches the arm; elbow up), bit 2 set when A5 <= 0."""
    front, elbow = _arm_sides(model, q)
    a5 = math.degrees(q[4])
    return [_digit(front, _EPS_M, 1), _digit(elbow, _EPS_M, 0), _digit(a5, _EPS_DEG, 1)]


def _cfx_bits(model: Model, q: Array) -> list[set[int]]:
    """ABB ``cfx`` = 4 b2 + 2 b1 + b0 for a 6-axis arm: b2 set when the wrist centre is
    behind axis 1, b1 set when it is behind the lower arm (elbow down), b0 set when axis 5
    is negative."""
    front, elbow = _arm_sides(model, q)
    a5 = math.degrees(q[4])
    return [_digit(a5, _EPS_DEG, 1), _digit(elbow, _EPS_M, 1), _digit(front, _EPS_M, 1)]


def _status(model: Model, q: Array) -> int:
    """KUKA status ``S`` (bits 0-2, see :func:`_status_bits`) of joint values ``q`` (rad)."""
    return sum(min(b) << k for k, b in enumerate(_status_bits(model, q)))


def _cfx(model: Model, q: Array) -> int:
    """ABB ``cfx`` (see :func:`_cfx_bits`) of joint values ``q`` (rad)."""
    return sum(min(b) << k for k, b in enumerate(_cfx_bits(model, q)))


def _config_changes(t: ProgramTarget, q: Array, model: Model | None = None) -> list[str]:
    """How joint values ``q`` (rad) differ from the target's written configuration: one
    entry per bit or digit (``[]``: they meet it).  Without ``model`` the status / cfx
    is not checked."""
    if t.config is None or len(q) < 6:
        return []
    deg = np.degrees(q[:6])
    eps = _EPS_DEG
    out = []
    if t.style == "krl":
        turn, status = t.config
        if turn is not None:
            for j in range(6):
                if abs(deg[j]) >= eps and (deg[j] < 0) != bool(turn >> j & 1):
                    out.append(f"T bit {j} (A{j + 1} {'<' if deg[j] < 0 else '>='} 0)")
        if status is not None and model is not None:
            names = ("overhead", "A3 >= phi", "A5 <= 0")
            for k, allowed in enumerate(_status_bits(model, q)):
                if status >> k & 1 not in allowed:
                    out.append(f"S bit {k} ({names[k]}) {status >> k & 1} -> {min(allowed)}")
        return out
    for j, cf, name in zip((0, 3, 5), t.config[:3], ("cf1", "cf4", "cf6"), strict=True):
        if not math.floor((deg[j] - eps) / 90.0) <= cf <= math.floor((deg[j] + eps) / 90.0):
            out.append(f"{name} {cf} -> {math.floor(deg[j] / 90.0)}")
    if len(t.config) > 3 and model is not None:
        cfx = t.config[3]
        bits = _cfx_bits(model, q)
        if not 0 <= cfx < 8 or any(cfx >> k & 1 not in b for k, b in enumerate(bits)):
            out.append(f"cfx {cfx} -> {sum(min(b) << k for k, b in enumerate(bits))}")
    return out


def _config_ok(t: ProgramTarget, q: Array, model: Model | None = None) -> bool:
    """Whether joint values ``q`` (rad) meet the target's written configuration."""
    return not _config_changes(t, q, model)


def _config_starts(t: ProgramTarget, model: Model, rng: np.random.Generator, n: int) -> Array:
    """``(n, dof)`` starting configurations within the limits that meet the configuration."""
    lim = model.joint_limits
    lo, hi = np.maximum(lim[:, 0], -math.pi), np.minimum(lim[:, 1], math.pi)
    q = rng.uniform(lo, hi, (n, model.dof))
    if t.config is None or model.dof < 6:
        return q
    if t.style == "krl":
        turn, status = t.config
        for j in range(6):
            if turn is not None:
                negative = bool(turn >> j & 1)
                q[:, j] = np.where(negative, -np.abs(q[:, j]), np.abs(q[:, j]))
        if status is not None:
            q[:, 4] = np.where(status >> 2 & 1, -np.abs(q[:, 4]), np.abs(q[:, 4]))
    else:
        for j, cf in zip((0, 3, 5), t.config[:3], strict=True):
            q[:, j] = np.radians(90.0 * (cf + rng.uniform(0.1, 0.9, n)))
        if len(t.config) > 3:
            q[:, 4] = np.where(t.config[3] & 1, -np.abs(q[:, 4]), np.abs(q[:, 4]))
    return np.clip(q, lim[:, 0], lim[:, 1])


# ---------------------------------------------------------------------- the filter
def language_of(path: str | Path) -> Language:
    """The language of a program file by its suffix."""
    suffix = Path(path).suffix.lower()
    table: dict[str, Language] = {
        ".script": "urscript",
        ".urscript": "urscript",
        ".src": "krl",
        ".dat": "krl",
        ".mod": "rapid",
        ".modx": "rapid",
        ".prg": "rapid",
        ".csv": "csv",
    }
    if suffix not in table:
        raise ProgramError(f"{path}: unknown program language {suffix!r} (.script, .src, .mod, .csv)")
    return table[suffix]


def _robot_models(
    calibrated: CalibrationResult | Model, nominal: Model | None, tool: Array | None, probe: ArrayLike | None
) -> tuple[Model, Model, Callable[[Array], Array | None] | None]:
    """(real, nominal) robot models with the program's tool, and the joint effects."""
    from robocal.compensate.compensation import nominal_model

    if isinstance(calibrated, CalibrationResult):
        real = calibrated.model
        nom = nominal_model(calibrated) if nominal is None else nominal
        effects = calibrated.joint_perturbations
    else:
        real, nom, effects = calibrated, (calibrated if nominal is None else nominal), None

    def measured_tool(m: Model) -> Array | None:
        steps = [s for s in m.steps if s.role is Role.TOOL]
        if not steps:
            return None
        return spatial.chain_product([s.motion for s in steps], [s.value for s in steps])

    # the measured tool as built (``probe``) is known: how far the identified tool is from it
    # is robot geometry the tool absorbed (e.g. d6 under position measurement), kept with the robot
    tool_real = measured_tool(real)
    absorbed = np.eye(4)
    if tool_real is not None and probe is not None:
        P = np.asarray(probe, dtype=float)
        absorbed = tool_real @ spatial.inverse(P if P.shape == (4, 4) else spatial.homogeneous(p=P))

    def strip(m: Model, correction: Array) -> Model:
        steps = tuple(s for s in m.steps if s.role is not Role.TOOL)
        T = correction @ (np.eye(4) if tool is None else np.asarray(tool, dtype=float))
        if np.abs(T - np.eye(4)).max() > 0:
            steps = (*steps, *frame_steps(T, "program_tool", free=False))
        return dataclasses.replace(m, steps=steps, joint_effects=())

    return strip(real, absorbed), strip(nom, np.eye(4)), effects


def _program_frames(
    texts: dict[str, str],
    language: str,
    rapid_data: dict[str, dict],
    config_dat: tuple[str, str] | None,
    problems: list[str],
) -> Callable[[str, int], tuple[Array | None, Array | None]]:
    """``frame_at(file, position)``: the program's tool and base frames (m) in force at a
    motion (``None``: not given by the program)."""
    if language == "rapid":
        tools = {k: v for d in rapid_data.values() for k, v in d["tools"].items()}
        wobjs = {k: v for d in rapid_data.values() for k, v in d["wobjs"].items()}
        tools.setdefault("TOOL0", np.eye(4))
        wobjs.setdefault("WOBJ0", np.eye(4))
        seen: set[str] = set()

        def rapid_at(label: str, pos: int) -> tuple[Array | None, Array | None]:
            for start, end, line, tool, wobj in rapid_data[label]["moves"]:
                if start <= pos < end:
                    for name, table, what in ((tool, tools, "tooldata"), (wobj, wobjs, "wobjdata")):
                        if name is not None and name.upper() not in table and name.upper() not in seen:
                            seen.add(name.upper())
                            problems.append(
                                f"{label}: line {line}: {what} {name} is declared outside the module; "
                                "the default is used (--tool / --base)"
                            )
                    return tools.get((tool or "TOOL0").upper()), wobjs.get((wobj or "WOBJ0").upper())
            return None, None

        return rapid_at
    if language != "krl" or config_dat is None:
        return lambda label, pos: (None, None)
    cfg_label, cfg_text = config_dat
    data = _krl_config_frames(cfg_text, cfg_label)
    settings = _krl_settings(texts)

    def krl_at(label: str, pos: int) -> tuple[Array | None, Array | None]:
        current: dict[str, Array | None] = {"TOOL": None, "BASE": None}
        for start, line, kind, n in settings.get(label, []):
            if start >= pos:
                break
            if n == 0:
                current[kind] = np.eye(4)
            elif (kind, n) in data:
                current[kind] = data[(kind, n)]
            else:
                raise ProgramError(f"{label}: line {line}: {kind}_DATA[{n}] is not in {cfg_label}")
        return current["TOOL"], current["BASE"]

    return krl_at


def _report_other_frames(
    t: ProgramTarget,
    runs: list[tuple[str, int]],
    first: tuple[Array | None, Array | None],
    frame_at: Callable[[str, int], tuple[Array | None, Array | None]],
    texts: dict[str, str],
    problems: list[str],
) -> None:
    """A problem when motions to target ``t`` run with other tools or bases than the first."""

    def same(a: Array | None, b: Array | None) -> bool:
        return (a is None and b is None) or (a is not None and b is not None and np.allclose(a, b))

    lines = [
        f"{label}: line {_line_of(texts[label], pos)}"
        for label, pos in runs[1:]
        if not all(same(x, y) for x, y in zip(frame_at(label, pos), first, strict=True))
    ]
    message = (
        f"{t.file}: line {t.line}: target {t.name}: moved to with another tool or base at "
        f"{', '.join(lines)}; corrected for the first motion to it"
    )
    if lines and message not in problems:
        problems.append(message)


def filter_program_text(
    texts: dict[str, str],
    language: Language,
    calibrated: CalibrationResult | Model,
    nominal: Model | None = None,
    *,
    tool: ArrayLike | None = None,
    base: ArrayLike | None = None,
    probe: ArrayLike | None = None,
    length_unit: str = "m",
    angle_unit: str = "rad",
    tol: float = 1e-9,
    config_dat: tuple[str, str] | None = None,
    require_probe: bool = False,
) -> FilteredProgram:
    """Filter a program given as texts ``{file label: text}`` (KRL: the ``.src`` and the
    ``.dat``; other languages one file).

    Args:
        calibrated: a calibration result or a calibrated model (with ``nominal``).
        nominal: the controller's model (default: the result's start values).
        tool: ``(4, 4)`` the program's tool frame on the flange (m); default the
            program's own (``set_tcp``, a ``tooldata``) or the flange.
        base: ``(4, 4)`` ``T_base_frame`` of the frame the Cartesian targets are in
            (KUKA BASE, RAPID work object); default the robot's base frame.
        probe: the calibration's measured tool as built (position ``(3,)`` or ``(4, 4)``
            on the flange, m): the identified tool's distance from it is robot geometry
            the tool absorbed (e.g. ``d6`` under position measurement) and is kept with
            the robot.  Default: the identified tool is the probe as built (nothing
            absorbed; right when the program's tool is the probe itself).
        length_unit, angle_unit: units of a CSV program (``m|mm``, ``rad|deg``).
        config_dat: KRL ``(label, text)`` of the ``$config.dat`` whose ``TOOL_DATA[n]`` and
            ``BASE_DATA[n]`` the program's ``$TOOL``/``$BASE`` (or ``FDAT`` ``TOOL_NO``,
            ``BASE_NO``) name; without it those are not read.  RAPID: each Move's tool
            and ``\\WObj`` (``uframe · oframe``) are read from the module.  Each Cartesian
            target is taken with the tool and base of the first motion to it; ``tool`` /
            ``base`` given override them all.
        require_probe: refuse (:class:`ProgramError`) a calibration that measured
            positions only, without ``probe``, when the program has Cartesian targets (the
            identified tool absorbed robot geometry, e.g. ``d6``; about 2 mm can be lost).
        tol: IK tolerance (m, rad); corrections smaller than it leave the text as is.
    """
    from robocal.compensate.compensation import compensate_targets, filter_program

    model = calibrated.model if isinstance(calibrated, CalibrationResult) else calibrated
    dof = model.dof
    targets: list[ProgramTarget] = []
    unsupported: list[Unsupported] = []
    found_tool = None
    krl_used: list[tuple[str, str, int, str]] = []
    events: list[tuple[int, int, str]] = []  # (file, position, name) of motions to named targets
    rapid_data: dict[str, dict] = {}
    for f, (label, text) in enumerate(texts.items()):
        uses: list[tuple[int, str]] = []
        rapid_data[label] = {"tools": {}, "wobjs": {}, "moves": []}
        if language == "urscript":
            t, u, found_tool = _parse_urscript(text, dof, label, uses)
        elif language == "krl":
            t, u, used = _parse_krl(text, dof, label, uses)
            krl_used += [(label, *x) for x in used]
        elif language == "rapid":
            t, u, found_tool = _parse_rapid(text, dof, label, uses, rapid_data[label])
        elif language == "csv":
            t, u = _parse_csv(text, dof, label), []
        else:
            raise ValueError(f"unknown language {language!r}")
        targets += t
        unsupported += u
        events += [(f, pos, name) for pos, name in uses]
    label_of = list(texts)
    declared = {t.name.upper() for t in targets}
    for label, name, line, statement in krl_used:
        if name.upper() not in declared:
            unsupported.append(Unsupported(label, line, statement, f"{name} is declared outside the program"))
    if require_probe and probe is None and getattr(calibrated, "measure", "") == "position":
        pose = next((t for t in targets if t.kind == "pose"), None)
        if pose is not None:
            raise ProgramError(
                f"{pose.file}: line {pose.line}: Cartesian target {pose.name} and a calibration that "
                "measured positions only: give the probe as built with --probe x,y,z (m)"
            )
    if language == "csv":
        lf = unit_factor(length_unit, "length", "length_unit")
        af = unit_factor(angle_unit, "angle", "angle_unit")
        units = _Units(lf, af, 7 if lf == 1.0 else 4, 7 if af == 1.0 else 5)
    else:
        units = _UNITS[language]
    T_tool = np.asarray(tool, dtype=float) if tool is not None else found_tool
    real, nom, effects = _robot_models(calibrated, nominal, T_tool, probe)
    B = np.eye(4) if base is None else np.asarray(base, dtype=float)
    problems: list[str] = []
    frame_at = _program_frames(texts, language, rapid_data, config_dat, problems)
    cache: dict[bytes, tuple[Model, Model]] = {}

    def frames_of(i: int) -> tuple[Model, Model, Array]:
        """The (real, nominal) models with target ``i``'s tool, and its base."""
        t = targets[i]
        runs = [(label_of[f], pos) for f, pos, name in events if name.upper() == t.name.upper()]
        T_i, B_i = frame_at(*(runs[0] if runs else (t.file, t.tokens[0].start)))
        if tool is None or base is None:
            _report_other_frames(t, runs, (T_i, B_i), frame_at, texts, problems)
        T_i = T_tool if tool is not None or T_i is None else T_i
        B_i = B if base is not None or B_i is None else B_i
        key = b"" if T_i is None else np.asarray(T_i).tobytes()
        if key not in cache:
            cache[key] = _robot_models(calibrated, nominal, T_i, probe)[:2]
        return (*cache[key], B_i)

    types = model.joint_types
    n = len(targets)
    reported: set[int] = set()  # targets whose configuration change is already reported
    values = [_read_value(t, units, types, False) for t in targets]
    new_values: list[Array] = list(values)
    before = np.full(n, np.nan)
    after = np.full(n, np.nan)
    reach = np.ones(n, dtype=bool)
    kept = np.ones(n, dtype=bool)
    joint_idx = [i for i, t in enumerate(targets) if t.kind == "joint"]
    pose_idx = [i for i, t in enumerate(targets) if t.kind == "pose"]
    groups: dict[int, list[int]] = {}  # joint targets by the tool of their motion
    for i in joint_idx:
        groups.setdefault(id(frames_of(i)[0]), []).append(i)
    for idx in groups.values():
        real_g, nom_g, _ = frames_of(idx[0])
        q = np.array([values[i] for i in idx])
        res = filter_program(real_g, q, nom_g, joint_effects=effects, tol=tol, tol_angle=tol)
        for k, i in enumerate(idx):
            new_values[i] = res.q[k]
        before[idx], after[idx] = res.error_before * 1e3, res.error_after * 1e3
        reach[idx], kept[idx] = res.reachable, res.branch_kept
    if pose_idx:
        # execution order: motions to named targets where they run, literal targets where
        # they stand, declared targets never moved to at the end (file order)
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
        sequence = list(dict.fromkeys(i for _, _, i in order))
        # the branch of each Cartesian target: the configuration the robot comes from
        q_prev = values[joint_idx[0]] if joint_idx else np.zeros(dof)
        rng = np.random.default_rng(0)
        for i in sequence:
            if targets[i].kind == "joint":
                q_prev = values[i]
                continue
            real, nom, B_i = frames_of(i)
            T = B_i @ values[i]
            position_only = len(targets[i].tokens) == 3
            goal = T[:3, 3][None] if position_only else T[None]
            kind = "position" if position_only else "pose"
            opts = {"joint_effects": effects, "tol": tol, "tol_angle": tol}
            res = compensate_targets(real, goal, nom, kind=kind, q0=q_prev, **opts)
            config_kept = True
            if not (res.nominal_reachable[0] and _config_ok(targets[i], res.q_nominal[0], nom)):
                # the written configuration (KUKA S/T, ABB cf/cfx) chooses the branch: starts within it
                starts = _config_starts(targets[i], nom, rng, 24)
                for q_start in starts:
                    trial = compensate_targets(real, goal, nom, kind=kind, q0=q_start, restarts=0, **opts)
                    if trial.nominal_reachable[0] and _config_ok(targets[i], trial.q_nominal[0], nom):
                        res = trial
                        break
                else:
                    t = targets[i]
                    if t.config is not None and res.reachable[0]:
                        config_kept = False
                        changes = ", ".join(_config_changes(t, res.q_nominal[0], nom))
                        problems.append(
                            f"{t.file}: line {t.line}: target {t.name}: reachable only in another "
                            f"configuration ({changes}); left as written"
                        )
            q_prev = res.q_nominal[0] if res.nominal_reachable[0] else q_prev
            corrected = spatial.inverse(B_i) @ nom.fk(res.q)[0]
            new_values[i] = corrected if res.reachable[0] and config_kept else values[i]
            before[i], after[i] = res.error_before[0] * 1e3, res.error_after[0] * 1e3
            reach[i], kept[i] = bool(res.reachable[0]), bool(res.branch_kept[0]) and config_kept
            if not config_kept:
                reported.add(i)
    # write: the numbers that moved, file by file, last first
    changed = np.zeros(n, dtype=bool)
    edits: dict[str, list[tuple[int, int, str]]] = {label: [] for label in texts}
    for i, t in enumerate(targets):
        if not reach[i]:
            continue
        for tok, (v, d) in zip(t.tokens, _write_values(t, units, new_values[i], types), strict=True):
            if abs(v - tok.value) <= 0.5 * 10.0 ** (-max(_decimals(tok.text), d)):
                continue  # below the written resolution: keep the token as written
            edits[t.file].append((tok.start, tok.end, _format(v, tok.text, d)))
            changed[i] = True
    out = {}
    for label, text in texts.items():
        for s, e, new in sorted(edits[label], reverse=True):
            text = text[:s] + new + text[e:]
        out[label] = text
    for i, t in enumerate(targets):
        if not reach[i]:
            problems.append(
                f"{t.file}: line {t.line}: target {t.name}: not reachable by the calibrated robot"
            )
        elif not kept[i] and i not in reported:
            problems.append(
                f"{t.file}: line {t.line}: target {t.name}: the correction changes the configuration"
            )
    return FilteredProgram(
        texts=out,
        targets=tuple(targets),
        error_before_mm=before,
        error_after_mm=after,
        reachable=reach,
        branch_kept=kept,
        changed=changed,
        unsupported=tuple(unsupported),
        language=language,
        problems=tuple(problems),
    )


def _read(path: Path) -> tuple[str, str]:
    """The text and its encoding (UTF-8, else Latin-1 as KRL and RAPID files often are)."""
    try:
        data = path.read_bytes()
    except OSError as err:
        raise ProgramError(f"{path}: cannot read: {err.strerror or err}") from None
    try:
        return data.decode("utf-8"), "utf-8"
    except UnicodeDecodeError:
        return data.decode("latin-1"), "latin-1"


#: the comment line that stamps a KRL .src and its .dat as written together
_KRL_RUN = re.compile(r"^;robocal run: ([0-9a-f]{8,64})[ \t]*\r?$", re.MULTILINE)


def krl_run_id(text: str) -> str | None:
    """The run id a KRL file written by robocal carries (``;robocal run: ID``), or None."""
    match = _KRL_RUN.search(text)
    return match.group(1) if match else None


def stamp_krl(text: str, run_id: str) -> str:
    """``text`` with one ``;robocal run: ID`` comment line (an earlier one removed),
    after the leading ``&ACCESS``/``&REL`` lines, which must stay first."""
    newline = "\r\n" if "\r\n" in text else "\n"
    lines = [ln for ln in text.splitlines(keepends=True) if not _KRL_RUN.match(ln.rstrip("\n"))]
    k = 0
    while k < len(lines) and lines[k].lstrip().startswith("&"):
        k += 1
    lines.insert(k, f";robocal run: {run_id}{newline}")
    return "".join(lines)


def _check_krl_pair(src: Path, src_text: str, dat: Path, dat_text: str) -> None:
    """Refuse a KRL .src and .dat of different runs (a write killed between the two
    renames, or files copied together by hand): their targets would not match."""
    a, b = krl_run_id(src_text), krl_run_id(dat_text)
    if a != b:
        raise ProgramError(
            f"{src} (robocal run {a or 'none'}) and {dat} (robocal run {b or 'none'}) were not written "
            "together: a write was interrupted or one file was replaced; filter the original program again"
        )


def filter_program_file(
    path: str | Path,
    calibrated: CalibrationResult | Model,
    out: str | Path | None = None,
    *,
    language: Language | None = None,
    config_dat: str | Path | None = None,
    **options,
) -> FilteredProgram:
    """Filter a program file (see :func:`filter_program_text`); written to ``out``
    atomically when given (KRL: ``out`` and the ``.dat`` next to it, both or neither).  Nothing is
    written when the program cannot be read.

    KRL: ``config_dat`` is the ``$config.dat`` holding ``TOOL_DATA``/``BASE_DATA``
    (default: the one in the program's folder, when there is one)."""
    path = Path(path)
    if not path.is_file():
        raise ProgramError(f"{path}: no such program file")
    language = language or language_of(path)
    texts, encodings = {}, {}
    texts[str(path)], encodings[str(path)] = _read(path)
    dat = path.with_suffix(".dat")
    if language == "krl" and path.suffix.lower() == ".src" and dat.is_file():
        texts[str(dat)], encodings[str(dat)] = _read(dat)
        _check_krl_pair(path, texts[str(path)], dat, texts[str(dat)])
    if language == "krl":
        cfg = Path(config_dat) if config_dat is not None else path.parent / "$config.dat"
        if config_dat is not None and not cfg.is_file():
            raise ProgramError(f"{cfg}: no such $config.dat")
        if cfg.is_file():
            options["config_dat"] = (str(cfg), _read(cfg)[0])
    result = filter_program_text(texts, language, calibrated, **options)
    if out is not None:
        from robocal.outdir import new_run_id, write_together

        out = Path(out)
        files = {}
        run_id = new_run_id()
        for label, text in result.texts.items():
            target = out if label == str(path) else out.with_suffix(Path(label).suffix)
            if language == "krl":  # the pair carries one run id: a mix is refused when read
                text = stamp_krl(text, run_id)
            files[target] = text.encode(encodings[label])
        # KRL: the .src and its .dat both or neither; the .dat renamed first, so that a
        # process killed in between leaves no new .src without its .dat
        write_together(dict(sorted(files.items(), key=lambda item: item[0].suffix.lower() != ".dat")))
    return result
