"""The pieces every program language shares: targets, number tokens, the result, text helpers."""

from __future__ import annotations

import re
from bisect import bisect_right
from dataclasses import dataclass, field
from functools import lru_cache
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from robocal.units import ANGLE_UNITS

Array = NDArray[np.float64]
Language = Literal["urscript", "krl", "rapid", "csv"]
NUM = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"
_NUM_RE = re.compile(NUM)
DEG = ANGLE_UNITS["deg"]


class ProgramError(ValueError):
    """A program that cannot be read; the message names the file, the line and what."""


@dataclass(frozen=True)
class Token:
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
    tokens: tuple[Token, ...]
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
        error_before_mm, error_after_mm: ``(n,)`` predicted position error of the real
            robot (mm) unfiltered and filtered.
        reachable: ``(n,)`` a command to write exists (the calibrated IK reached the target,
            or damped it near a singularity).
        branch_kept: ``(n,)`` the target is not refused (written corrected or damped).
        changed: ``(n,)`` whether the target's text was rewritten.
        unsupported: motion statements left untouched.
        language: the language.
        problems: one line per refused target (file, line, name, reason) and per frame issue.
        status, reasons: ``(n,)`` ``"corrected"``, ``"damped"`` or ``"refused"`` and why, the
            invariants of :mod:`robocal.compensate.safety` (a refused target is left as written).
        table: the per-target table (:meth:`robocal.compensate.result.Compensation.table`
            rows, named ``FILE:LINE NAME``).
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
    status: tuple[str, ...] = ()
    reasons: tuple[str, ...] = ()
    table: tuple[dict, ...] = ()

    @property
    def ok(self) -> bool:
        return bool(np.all(self.reachable & self.branch_kept))

    @property
    def refused(self) -> tuple[str, ...]:
        """``"FILE:LINE NAME: reason"`` of every refused target (left as written)."""
        return tuple(f"{r['name']}: {r['reason']}" for r in self.table if r["status"] == "refused")


# ---------------------------------------------------------------------- code and text
#: a program file above this size (bytes) is refused before it is read: the filter keeps a few
#: copies of the text and its tokens, and no robot program comes near it
MAX_PROGRAM_BYTES = 20_000_000

# what is not code, per language: comments to the end of the line and strings (a string
# ends at its closing quote or, unclosed, at the end of the line; RAPID's "" inside a string
# reads as two strings, both masked).  KRL's 'B0101' / 'H1F' literals are code (status, turn).
_NOT_CODE = {
    "urscript": re.compile(r"#[^\n]*|\"[^\"\n]*\"?|'[^'\n]*'?"),
    "krl": re.compile(r";[^\n]*|\"[^\"\n]*\"?"),
    "rapid": re.compile(r"![^\n]*|\"[^\"\n]*\"?"),
}


def code_only(text: str, language: str) -> str:
    """``text`` with its comments and strings (and a leading byte-order mark) blanked out:
    the same length and the same line breaks, so offsets and lines are the text's, and only
    code is scanned for targets (a ``movej([...])`` in a comment or a ``textmsg`` string is
    not a target).  Languages without a mask (CSV) are returned as they are."""
    pattern = _NOT_CODE.get(language)
    if pattern is None:
        return text
    code = pattern.sub(lambda m: " " * (m.end() - m.start()), text)
    return " " + code[1:] if code.startswith("\ufeff") else code


@lru_cache(maxsize=4)
def line_starts(text: str) -> list[int]:
    """Offsets at which the lines of ``text`` start (computed once per text: line numbers
    are looked up by bisection, so a long program is read in linear time)."""
    return [0] + [m.end() for m in re.finditer("\n", text)]


def line_of(text: str, pos: int) -> int:
    """1-based line of offset ``pos`` in ``text``."""
    return bisect_right(line_starts(text), pos)


def tokens_between(text: str, start: int, end: int) -> list[Token]:
    return [Token(start + m.start(), start + m.end(), m.group()) for m in _NUM_RE.finditer(text[start:end])]


@lru_cache(maxsize=8)
def _bracket_pairs(text: str, open_: str, close: str) -> dict[int, int]:
    """``{offset of an opening bracket: offset after its closing one}`` for the whole text,
    in one pass (a bracket never closed has no entry)."""
    pairs: dict[int, int] = {}
    stack: list[int] = []
    for m in re.finditer(re.escape(open_) + "|" + re.escape(close), text):
        if m.group() == open_:
            stack.append(m.start())
        elif stack:
            pairs[stack.pop()] = m.end()
    return pairs


def matching(text: str, i: int, open_: str, close: str) -> int:
    """Index after the bracket closing the one at ``i`` (-1: never closed); looked up, so
    many unclosed brackets cost no rescans."""
    return _bracket_pairs(text, open_, close).get(i, -1)


def decimals_of(token: str) -> int:
    mant = token.split("e")[0].split("E")[0]
    return len(mant.split(".")[1]) if "." in mant else 0


def split_args(text: str, start: int, end: int) -> list[tuple[int, int]]:
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


def line_text(text: str, pos: int) -> str:
    a = text.rfind("\n", 0, pos) + 1
    b = text.find("\n", pos)
    return text[a : b if b >= 0 else len(text)].strip()
