"""robocal target CSV programs: ``name,x,y,z[,qw,qx,qy,qz]`` or ``[name,]q1..qN``."""

from __future__ import annotations

import re

from robocal import csvfile
from robocal.compensate.programs.syntax import (
    NUM,
    ProgramError,
    ProgramTarget,
    Token,
)


# ---------------------------------------------------------------------- CSV
def parse_csv(text: str, dof: int, path: str) -> list[ProgramTarget]:
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

        def tok(col: str, cells=cells, offs=offs, k=k, header=header) -> Token:
            j = header.index(col)
            raw = cells[j]
            s = raw.strip()
            if not re.fullmatch(NUM, s):
                raise ProgramError(f"{path}: line {k + 1}, column {col!r}: {s!r} is not a number")
            a = offs[j] + raw.index(s)
            return Token(a, a + len(s), s)

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
