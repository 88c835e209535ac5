"""KUKA KRL targets (``.src`` and its ``.dat``), ``$TOOL``/``$BASE`` settings, ``$config.dat``
frames, and the run id that stamps a ``.src``/``.dat`` pair as written together."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from robocal import spatial
from robocal.compensate.programs.syntax import (
    DEG,
    NUM,
    Array,
    ProgramError,
    ProgramTarget,
    Token,
    Unsupported,
    code_only,
    line_of,
    matching,
)

# ---------------------------------------------------------------------- KRL
_KRL_AGG = re.compile(r"\{([^{}]*)\}")
# DECL may be left out for the standard types; GLOBAL makes a .dat's target public
_KRL_DECL = re.compile(
    r"^[ \t]*(?:DECL\s+)?(?:GLOBAL\s+)?(E6POS|POS|E6AXIS|AXIS|FRAME)\s+(\w+)\s*=\s*\{", re.M | re.I
)
_KRL_MOTION = re.compile(r"^[ \t]*(PTP|LIN|CIRC|PTP_REL|LIN_REL|SPTP|SLIN|SCIRC)\b(.*)$", re.M | re.I)
_KRL_POSE_KEYS = ("X", "Y", "Z", "A", "B", "C")


def _krl_fields(text: str, start: int, end: int) -> dict[str, Token]:
    fields = {}
    for m in re.finditer(r"([A-Za-z]\w*)\s+(" + NUM + ")", text[start:end]):
        fields[m.group(1).upper()] = Token(start + m.start(2), start + m.end(2), m.group(2))
    return fields


def _krl_bits(token: Token | None, limit: int) -> int | None:
    """A KRL status or turn as written (``None`` when absent or not an integer in range)."""
    if token is None or token.value != int(token.value) or not 0 <= token.value < limit:
        return None
    return int(token.value)


def _krl_target(text: str, start: int, end: int, dof: int, name: str, path: str) -> ProgramTarget | None:
    f = _krl_fields(text, start, end)
    line = line_of(text, start)
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


def parse_krl(
    text: str, dof: int, path: str, uses: list | None = None
) -> tuple[list[ProgramTarget], list[Unsupported], list[tuple[str, int, str]]]:
    targets: list[ProgramTarget] = []
    unsupported: list[Unsupported] = []
    used: list[tuple[str, int, str]] = []  # names used by motions: (name, line, statement)
    for m in _KRL_DECL.finditer(text):
        kind, name = m.group(1).upper(), m.group(2)
        b = m.end() - 1
        end = matching(text, b, "{", "}")
        if end < 0:
            raise ProgramError(f"{path}: line {line_of(text, b)}: unclosed '{{' in DECL {kind} {name}")
        if kind == "FRAME":
            continue  # bases and tools: data, not targets
        t = _krl_target(text, b, end, dof, name, path)
        if t is None:
            raise ProgramError(
                f"{path}: line {line_of(text, b)}: DECL {kind} {name} lacks "
                + ("X, Y, Z, A, B, C" if "POS" in kind else f"A1..A{dof}")
            )
        targets.append(t)
    for m in _KRL_MOTION.finditer(text):
        cmd, rest = m.group(1).upper(), m.group(2)
        line = line_of(text, m.start())
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


def krl_settings(texts: dict[str, str]) -> dict[str, list[tuple[int, int, str, int]]]:
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
            line = line_of(text, m.start())
            if m.group(1):
                out[label].append((m.start(), line, m.group(1).upper(), int(m.group(2))))
            elif m.group(3).upper() in fdat:
                fields = fdat[m.group(3).upper()]
                for kind in ("TOOL", "BASE"):
                    if f"{kind}_NO" in fields:
                        out[label].append((m.start(), line, kind, int(fields[f"{kind}_NO"])))
    return out


def _krl_frame(fields: dict[str, Token]) -> Array:
    """``{X, Y, Z, A, B, C}`` (mm, deg; ``Rz(A) Ry(B) Rx(C)``) as a frame in m."""
    v = [fields[k].value if k in fields else 0.0 for k in _KRL_POSE_KEYS]
    R = spatial.rotz(v[3] * DEG) @ spatial.roty(v[4] * DEG) @ spatial.rotx(v[5] * DEG)
    return spatial.homogeneous(R, np.array(v[:3]) * 1e-3)


def krl_config_frames(text: str, path: str) -> dict[tuple[str, int], Array]:
    """``TOOL_DATA[n]`` / ``BASE_DATA[n]`` of a ``$config.dat``: ``{("TOOL", n): frame}``."""
    out = {}
    for m in _KRL_DATA.finditer(text):
        fields = _krl_fields(text, m.start(3), m.end(3))
        if not all(k in fields for k in ("X", "Y", "Z")):
            raise ProgramError(f"{path}: line {line_of(text, m.start())}: {m.group(0)[:40]} lacks X, Y, Z")
        out[(m.group(1).upper(), int(m.group(2)))] = _krl_frame(fields)
    return out


#: the comment line that stamps a KRL .src and its .dat as written together
_KRL_RUN = re.compile(r"^;robocal run: ([0-9a-f]{8,64})[ \t]*\r?$", re.MULTILINE)


def krl_run_id(text: str) -> str | None:
    """The run id a KRL file written by robocal carries (``;robocal run: ID``), or None."""
    match = _KRL_RUN.search(text)
    return match.group(1) if match else None


def stamp_krl(text: str, run_id: str) -> str:
    """``text`` with one ``;robocal run: ID`` comment line (an earlier one removed),
    after the leading ``&ACCESS``/``&REL`` lines, which must stay first."""
    bom = "\ufeff" if text.startswith("\ufeff") else ""  # a byte-order mark stays the first character
    text = text[len(bom) :]
    newline = "\r\n" if "\r\n" in text else "\n"
    lines = [ln for ln in text.splitlines(keepends=True) if not _KRL_RUN.match(ln.rstrip("\n"))]
    k = 0
    while k < len(lines) and lines[k].lstrip().startswith("&"):
        k += 1
    lines.insert(k, f";robocal run: {run_id}{newline}")
    return bom + "".join(lines)


_KRL_MODULE = re.compile(
    r"^[ \t]*(?:GLOBAL[ \t]+)?(DEF|DEFFCT|DEFDAT)[ \t]+(?:\w+[ \t]+)??(\w+)", re.M | re.I
)


def krl_module_name(text: str) -> str | None:
    """The module a KRL file defines: the name of its first ``DEF``/``DEFFCT`` (``.src``) or
    its ``DEFDAT`` (``.dat``); None when it has none."""
    match = _KRL_MODULE.search(code_only(text, "krl"))
    return match.group(2) if match else None


def _sibling(path: Path, suffix: str) -> Path:
    """``path`` with ``suffix`` (``.src``/``.dat``), in the case of ``path``'s suffix when a
    file of that case exists or ``path``'s suffix is upper case (``PICK.SRC`` / ``PICK.DAT``)."""
    for candidate in (path.with_suffix(suffix.upper()), path.with_suffix(suffix)):
        if candidate.is_file():
            return candidate
    return path.with_suffix(suffix.upper() if path.suffix.isupper() else suffix)


def krl_inputs(path: Path, out: str | Path | None) -> Path | None:
    """The ``.dat`` read with a ``.src`` (None: none, or ``path`` is a ``.dat``); refuses a
    ``.dat`` that has its ``.src`` beside it and an output of another kind than the program."""
    kind = path.suffix.lower()
    if kind == ".dat":
        src = _sibling(path, ".src")
        if src.is_file():
            raise ProgramError(
                f"{path} is the data list of {src}: give {src.name}, its .dat is filtered with it"
            )
    if out is not None and Path(out).suffix.lower() != kind:
        raise ProgramError(f"-o {out}: a KRL {kind} is written as a {kind} (a .src with its .dat beside it)")
    if kind != ".src":
        return None
    dat = _sibling(path, ".dat")
    return dat if dat.is_file() else None


def krl_outputs(path: Path, out: Path, labels: list[str], overwrite: bool) -> dict[str, Path]:
    """``{file label: output path}`` of a KRL program: the ``.src`` at ``out``, its ``.dat``
    beside it; an existing ``.dat`` there that the program has none for is refused unless
    ``overwrite`` (it would be read with the new ``.src``)."""
    targets = {str(path): out}
    dat = _sibling(out, ".dat")
    for label in labels[1:]:
        targets[label] = dat
    if len(labels) == 1 and out.suffix.lower() == ".src" and dat.exists() and not overwrite:
        raise ProgramError(
            f"{dat} exists and would be read as the data list of {out.name}, but {path.name} has no .dat: "
            "remove it, or use --force"
        )
    return targets


def check_krl_pair(src: Path, src_text: str, dat: Path, dat_text: str) -> None:
    """Refuse a KRL .src and .dat of different runs (a write killed between the two
    renames, or files copied together by hand): their targets would not match."""
    module, datmodule = krl_module_name(src_text), krl_module_name(dat_text)
    if module is not None and datmodule is not None and module.upper() != datmodule.upper():
        raise ProgramError(
            f"{src} (DEF {module}) and {dat} (DEFDAT {datmodule}) are not one module: "
            "a .src and its .dat must name the same module"
        )
    a, b = krl_run_id(src_text), krl_run_id(dat_text)
    if a != b:
        raise ProgramError(
            f"{src} (robocal run {a or 'none'}) and {dat} (robocal run {b or 'none'}) were not written "
            "together: a write was interrupted or one file was replaced; filter the original program again"
        )
