"""URScript targets: ``movej/movel/...`` literals and named ``p[...]``/``[...]`` values, ``set_tcp``."""

from __future__ import annotations

import math
import re
from typing import Literal

from robocal import spatial
from robocal.compensate.programs.syntax import (
    NUM,
    Array,
    ProgramError,
    ProgramTarget,
    Token,
    Unsupported,
    line_of,
    line_text,
    matching,
    split_args,
    tokens_between,
)

# ---------------------------------------------------------------------- URScript
# characters a target literal or a motion call spans at most (longer ones are not targets:
# bounded, so nested brackets to the end of a file are not rescanned for each one)
_LITERAL_CHARS = 4000
_UR_MOVE = re.compile(r"\b(movej|movel|movep|movec|servoj|servoc)\s*\(")
_UR_ASSIGN = re.compile(r"^[ \t]*(?:(?:global|local)\s+)?([A-Za-z_]\w*)\s*=\s*(p?)\[", re.M)
_UR_ANY_ASSIGN = re.compile(r"^[ \t]*(?:(?:global|local)\s+)?([A-Za-z_]\w*)\s*=(?!=)", re.M)
_UR_TCP = re.compile(r"\bset_tcp\s*\(\s*p\[")


def _ur_literal(
    text: str, i: int, dof: int, what: str, path: str
) -> tuple[Literal["joint", "pose"], list[Token], int] | None:
    """At ``i`` a ``p[...]`` (pose) or ``[...]`` (joint list): kind, tokens, end."""
    pose = text[i] == "p"
    b = i + 1 if pose else i
    end = matching(text, b, "[", "]")
    if end < 0:
        raise ProgramError(f"{path}: line {line_of(text, i)}: unclosed '[' in {what}")
    if end - b > _LITERAL_CHARS:  # no target is this long: not read (nor copied, for each one)
        return None
    inner = text[b + 1 : end - 1]
    parts = [s.strip() for s in inner.split(",")]
    if not all(re.fullmatch(NUM, s) for s in parts):
        return None
    toks = tokens_between(text, b + 1, end - 1)
    if pose and len(toks) != 6:
        raise ProgramError(f"{path}: line {line_of(text, i)}: a pose p[...] needs 6 numbers, got {len(toks)}")
    if not pose and len(toks) != dof:
        return None
    return ("pose" if pose else "joint"), toks, end


def parse_urscript(
    text: str, dof: int, path: str, uses: list | None = None
) -> tuple[list[ProgramTarget], list[Unsupported], Array | None]:
    targets: list[ProgramTarget] = []
    unsupported: list[Unsupported] = []
    names: set[str] = set()
    literal_at: set[int] = set()
    for m in _UR_ASSIGN.finditer(text):
        i = m.end() - 1 - len(m.group(2))
        lit = _ur_literal(text, i, dof, f"the assignment to {m.group(1)}", path)
        if lit is not None:
            kind, toks, _ = lit
            names.add(m.group(1))
            literal_at.add(m.start())
            targets.append(ProgramTarget(m.group(1), line_of(text, i), kind, path, tuple(toks), "urscript"))
    for m in _UR_MOVE.finditer(text):
        call_end = matching(text, m.end() - 1, "(", ")")
        line = line_of(text, m.start())
        if call_end < 0:
            raise ProgramError(f"{path}: line {line}: unclosed '(' in {m.group(1)}")
        if call_end - m.end() > _LITERAL_CHARS:
            reason = "the call is too long to be a motion to a target"
            unsupported.append(Unsupported(path, line, line_text(text, m.start())[:200], reason))
            continue
        args = split_args(text, m.end(), call_end - 1)
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
                            line_text(text, m.start()),
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
                unsupported.append(Unsupported(path, line, line_text(text, m.start()), reason))
    _reassigned(text, path, names, literal_at, unsupported)
    tool = None
    tcp = _UR_TCP.search(text)
    if tcp:
        lit = _ur_literal(text, tcp.end() - 2, dof, "set_tcp", path)
        if lit is not None:
            v = [t.value for t in lit[1]]
            if not all(map(math.isfinite, v)):
                raise ProgramError(f"{path}: line {line_of(text, tcp.start())}: set_tcp: not finite numbers")
            tool = spatial.homogeneous(spatial.rotvec_to_matrix(v[3:]), v[:3])
    targets.sort(key=lambda t: t.tokens[0].start)
    return targets, unsupported, tool


def _reassigned(text: str, path: str, names: set[str], literal_at: set[int], unsupported: list) -> None:
    """List the assignments of anything but a literal to a target's name (``p = pose_trans(p,
    ...)``; ``literal_at``: where the literal assignments start): motions to the name after
    them go to a value the filter did not correct."""
    for m in _UR_ANY_ASSIGN.finditer(text):
        if m.group(1) in names and m.start() not in literal_at:
            reason = f"{m.group(1)} is assigned an expression here: later motions to it are not corrected"
            unsupported.append(
                Unsupported(path, line_of(text, m.start()), line_text(text, m.start()), reason)
            )
