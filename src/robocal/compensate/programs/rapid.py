"""ABB RAPID targets: ``robtarget``/``jointtarget`` literals, Moves, ``tooldata`` and ``wobjdata``."""

from __future__ import annotations

import math
import re

import numpy as np

from robocal import spatial
from robocal.compensate.programs.syntax import (
    Array,
    ProgramError,
    ProgramTarget,
    Unsupported,
    line_of,
    line_text,
    matching,
    split_args,
    tokens_between,
)

# ---------------------------------------------------------------------- RAPID
_RAPID_DECL = re.compile(
    r"\b(?:CONST|PERS|VAR)\s+(robtarget|jointtarget|tooldata|wobjdata)\s+(\w+)\s*:=\s*\[", re.I
)
# a statement runs to its ';' within 4000 characters (bounded: a file of unterminated
# statements is not rescanned to its end for each one)
_RAPID_MOVE = re.compile(r"^[ \t]*(MoveJ|MoveL|MoveC|MoveAbsJ)\b([^;]{0,4000});", re.M | re.I)
# declarations whose values are not corrected: arrays (``path{3}``), no value (set at run time)
_RAPID_OTHER_DECL = re.compile(
    r"\b(?:CONST|PERS|VAR)\s+(robtarget|jointtarget)\s+(\w+)\s*(\{[^}]{0,200}\}|;)", re.I
)
# motion instructions with targets outside the supported grammar (MoveLDO, SearchL, TriggL ...)
_RAPID_OTHER_MOTION = re.compile(
    r"^[ \t]*((?:Move|Search|Trigg|Arc|Cap)\w*|SMove\w*)\b[^;]{0,4000};", re.M | re.I
)
_RAPID_MOTION_START = re.compile(r"^[ \t]*(?:(?:Move|Search|Trigg|Arc|Cap)\w*|SMove\w*)\b", re.M | re.I)
_SUPPORTED = {"movej", "movel", "movec", "moveabsj"}


def _rapid_groups(text: str, b: int, path: str) -> tuple[list[tuple[int, int]], int]:
    """The top-level ``[...]`` groups inside the bracket at ``b``, and its end."""
    end = matching(text, b, "[", "]")
    if end < 0:
        raise ProgramError(f"{path}: line {line_of(text, b)}: unclosed '['")
    groups, k = [], b + 1
    while k < end - 1:
        if text[k] == "[":
            e = matching(text, k, "[", "]")
            groups.append((k, e))
            k = e
        else:
            k += 1
    return groups, end


def _rapid_target(text: str, b: int, kind: str, dof: int, name: str, path: str) -> tuple[ProgramTarget, int]:
    groups, end = _rapid_groups(text, b, path)
    line = line_of(text, b)
    if kind == "robtarget":
        if len(groups) < 2:
            raise ProgramError(f"{path}: line {line}: robtarget {name} needs [[x,y,z],[q1,q2,q3,q4],...]")
        toks = tokens_between(text, *groups[0]) + tokens_between(text, *groups[1])
        if len(toks) != 7:
            raise ProgramError(f"{path}: line {line}: robtarget {name}: trans and rot need 3 + 4 numbers")
        config = None
        if len(groups) >= 3:
            cf = [t.value for t in tokens_between(text, *groups[2])]
            if len(cf) == 4 and all(v == int(v) for v in cf):
                config = tuple(int(v) for v in cf)
        return ProgramTarget(name, line, "pose", path, tuple(toks), "rapid", config), end
    if not groups:
        raise ProgramError(f"{path}: line {line}: jointtarget {name} needs [[j1..j6],[eax..]]")
    toks = tokens_between(text, *groups[0])
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
    p = [t.value for t in tokens_between(text, *inner[0])]
    qv = [t.value for t in tokens_between(text, *inner[1])]
    if len(p) != 3 or len(qv) != 4:
        return None
    norm = float(np.linalg.norm(qv))
    if not (math.isfinite(norm) and norm > 1e-9 and all(map(math.isfinite, p))):
        raise ProgramError(f"{path}: line {line_of(text, b)}: {what} is not a frame")
    R = spatial.quaternion_to_matrix(np.array(qv) / norm)
    return spatial.homogeneous(R, np.array(p) * 1e-3)


def _rapid_move_frames(text: str, m: re.Match) -> tuple[str | None, str | None]:
    """The tool and work object (names, upper case) a Move statement names."""
    args = [text[a:b].strip() for a, b in split_args(text, m.start(2), m.end(2))]
    positional = [a for a in args if a and not a.startswith("\\")]
    k = {"movec": 4}.get(m.group(1).lower(), 3)
    tool = None
    if len(positional) > k:
        word = re.match(r"\w+", positional[k])
        tool = word.group() if word else None
    wobj = re.search(r"\\WObj\s*:=\s*(\w+)", m.group(2), re.I)
    return tool, (wobj.group(1) if wobj else None)


def parse_rapid(
    text: str, dof: int, path: str, uses: list | None = None, data: dict | None = None
) -> tuple[list[ProgramTarget], list[Unsupported], Array | None]:
    targets, tool = _rapid_declarations(text, dof, path, data)
    unsupported: list[Unsupported] = []
    _rapid_moves(text, dof, path, uses, data, targets, unsupported)
    _rapid_others(text, path, unsupported)
    targets.sort(key=lambda t: t.tokens[0].start)
    return targets, unsupported, tool


def _rapid_others(text: str, path: str, unsupported: list[Unsupported]) -> None:
    """Target declarations and motion instructions the filter does not correct, listed."""
    for m in _RAPID_OTHER_DECL.finditer(text):
        what = "an array: its elements are" if m.group(3).startswith("{") else "declared without a value:"
        unsupported.append(
            Unsupported(
                path, line_of(text, m.start()), m.group(0).strip(), f"{m.group(2)} is {what} not corrected"
            )
        )
    ended = set()
    for m in _RAPID_OTHER_MOTION.finditer(text):
        ended.add(m.start())
        if m.group(1).lower() not in _SUPPORTED:
            reason = f"{m.group(1)} is not supported: its targets are not corrected"
            unsupported.append(Unsupported(path, line_of(text, m.start()), m.group(0).strip(), reason))
    for m in _RAPID_MOTION_START.finditer(text):
        if m.start() not in ended:
            line = line_of(text, m.start())
            reason = "no ';' ends the statement: its targets are not corrected"
            unsupported.append(Unsupported(path, line, line_text(text, m.start()), reason))


def _rapid_declarations(
    text: str, dof: int, path: str, data: dict | None
) -> tuple[list[ProgramTarget], Array | None]:
    """The declared targets and the last tool; ``data`` collects tooldata and wobjdata frames."""
    targets: list[ProgramTarget] = []
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
            uframe, oframe = (*frames, None, None)[:2]
            if uframe is None or oframe is None:
                line = line_of(text, b)
                raise ProgramError(f"{path}: line {line}: wobjdata {name} needs uframe and oframe")
            if data is not None:
                data["wobjs"][name.upper()] = uframe @ oframe
            continue
        t, _ = _rapid_target(text, b, kind, dof, name, path)
        targets.append(t)
    return targets, tool


def _rapid_not_a_name(arg_text: str, first: re.Match | None) -> str | None:
    """Why a Move's target argument is not corrected (None: a plain name)."""
    head = arg_text.split(",")[0].strip()
    if first is None or first.group().startswith("\\"):
        return "target is not a name or literal"
    rest = arg_text[first.end() :].lstrip()
    if rest.startswith("{"):
        return f"target {head} is an array element: not corrected"
    if rest.startswith("("):
        return f"target {first.group()}(...) is computed (an offset or relative target): not corrected"
    if rest and not rest.startswith(","):
        return f"target {head} is an expression: not corrected"
    return None


def _rapid_moves(
    text: str,
    dof: int,
    path: str,
    uses: list | None,
    data: dict | None,
    targets: list[ProgramTarget],
    unsupported: list[Unsupported],
) -> None:
    """The Move statements: literal targets into ``targets``, named ones into ``uses``."""
    for m in _RAPID_MOVE.finditer(text):
        cmd = m.group(1)
        line = line_of(text, m.start())
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
                reason = _rapid_not_a_name(arg_text, first)
                if reason is not None or first is None:  # (no name: a reason is given)
                    unsupported.append(Unsupported(path, line, m.group(0).strip(), reason or ""))
                    break
                k = len(args) - len(arg_text) + first.end()
                if uses is not None:
                    uses.append((pos, first.group()))
            count += 1
            comma = args.find(",", k)
            if comma < 0:
                break
            k = comma + 1
