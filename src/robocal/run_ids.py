"""Run ids: every file of one result carries the same id, so that a reader can refuse a
folder or a set of files that mixes two runs (:func:`check_consistent`).

``result.json`` keeps it as ``"run_id"``; YAML and CSV files as a ``# robocal run: ID``
comment line among their first lines; the HTML report as ``<meta name="robocal-run"
content="ID">``; a PNG in its ``tEXt`` ``Description`` (``robocal run: ID``).  Written by
the transactions of :mod:`robocal.outdir`, which also list the files they wrote in the
folder's manifest (:data:`MANIFEST`, with the run id): those and the files carrying a run
id are robocal's (:func:`robocal_names`); robocal replaces or deletes nothing else
(:class:`ForeignFileError`).
"""

from __future__ import annotations

import os
import re
import secrets
import stat
from collections.abc import Collection
from pathlib import Path
from typing import Any

__all__ = [
    "MANIFEST",
    "FolderMixedError",
    "ForeignFileError",
    "check_consistent",
    "check_robocal_files",
    "figure_png",
    "input_names",
    "is_mine",
    "is_own_regular_file",
    "is_run_id",
    "manifest_text",
    "named_inputs",
    "new_run_id",
    "read_run_id",
    "robocal_names",
    "run_id_line",
    "run_id_meta",
]

#: the hidden file in which a transaction lists the files it wrote into a folder (after a
#: ``# robocal run: ID`` line, one name a line)
MANIFEST = ".robocal-files"
_MANIFEST_MAX_BYTES = 1 << 20

_RUN_LINE = re.compile(r"^# robocal run: ([0-9a-f]{8,64})\s*$")
_RUN_META = re.compile(r'<meta name="robocal-run" content="([0-9a-f]{8,64})">')
_RUN_ID = re.compile(r"[0-9a-f]{8,64}")


class FolderMixedError(ValueError):
    """The files of a result folder come from different runs (the message names them)."""


class ForeignFileError(FolderMixedError):
    """A file robocal did not write (no run id, not in the folder's manifest), a link, or
    another user's file stands where robocal would write, replace or delete one: refused,
    with or without ``--force`` (the message names it)."""


def new_run_id() -> str:
    """A fresh run id (32 hex digits)."""
    return secrets.token_hex(16)


def run_id_line(run_id: str) -> str:
    """The comment line that stamps a YAML or CSV file with ``run_id``."""
    return f"# robocal run: {run_id}\n"


def is_run_id(value: object) -> bool:
    """Whether ``value`` is a run id (hex text, as :func:`new_run_id` makes)."""
    return isinstance(value, str) and _RUN_ID.fullmatch(value) is not None


def run_id_meta(run_id: str) -> str:
    """The ``<meta>`` element that stamps an HTML report with ``run_id`` (a run id is hex)."""
    if not _RUN_ID.fullmatch(run_id):
        raise ValueError(f"not a run id: {run_id!r}")
    return f'<meta name="robocal-run" content="{run_id}">'


def read_run_id(path: Path) -> str | None:
    """The run id of a file written by a transaction: ``result.json``'s ``run_id``, an HTML
    report's ``<meta name="robocal-run">`` in its first 4 kB, a PNG's ``Description``
    (``robocal run: ID``), or a ``# robocal run: ID`` line among the first lines of a
    text file; None when it has none."""
    path = Path(path)
    if path.suffix == ".png":
        return _png_run_id(path)
    if path.suffix in (".html", ".htm"):
        try:
            with open(path, encoding="utf-8", errors="replace") as fh:
                match = _RUN_META.search(fh.read(4096))
        except OSError:
            return None
        return match.group(1) if match else None
    if path.suffix == ".json":
        import json

        try:
            data = json.loads(path.read_text(encoding="utf-8"))
        except (OSError, ValueError):
            return None
        value = data.get("run_id") if isinstance(data, dict) else None
        return value if isinstance(value, str) else None
    try:
        with open(path, encoding="utf-8", errors="replace") as fh:
            for _ in range(5):
                match = _RUN_LINE.match(fh.readline(200))
                if match:
                    return match.group(1)
    except OSError:
        return None
    return None


def _png_run_id(path: Path) -> str | None:
    """The run id in a PNG's ``tEXt`` ``Description`` (``robocal run: ID``), read from
    the chunks before the image data; None when it has none."""
    import struct

    try:
        with open(path, "rb") as fh:
            if fh.read(8) != b"\x89PNG\r\n\x1a\n":
                return None
            while len(head := fh.read(8)) == 8:
                length, kind = struct.unpack(">I4s", head)
                if kind == b"IDAT" or length > 1 << 20:
                    return None
                data = fh.read(length)
                fh.read(4)  # the CRC
                key, _, text = data.partition(b"\x00")
                if kind == b"tEXt" and key == b"Description":
                    match = _RUN_LINE.match("# " + text.decode("latin-1"))
                    return match.group(1) if match else None
    except OSError:
        return None
    return None


def check_consistent(directory: Path, files: Collection[str], anchor: str = "result.json") -> None:
    """Raise :class:`FolderMixedError` when the files of a result folder disagree.

    ``anchor``'s run id (None for a folder written before run ids) must be the run id of
    every other file of ``files`` present in ``directory``; the message names each file that
    differs and its run id.
    """
    directory = Path(directory)
    want = read_run_id(directory / anchor)
    bad = []
    for name in files:
        if name == anchor or not (directory / name).is_file():
            continue
        got = read_run_id(directory / name)
        if got != want:
            bad.append(f"{name} (run {got or 'none'})")
    if bad:
        raise FolderMixedError(
            f"{directory}: the files come from different runs: {anchor} is run {want or 'none'} but "
            f"{', '.join(bad)}; calibrate again into this folder (--force) or a new one"
        )


def figure_png(fig: Any, *, dpi: float | None = None, run_id: str | None = None) -> bytes:
    """A matplotlib figure as PNG bytes (for :func:`robocal.outdir.write_together` or
    :func:`~robocal.outdir.atomic_write_bytes`), stamped with ``run_id`` (read back by
    :func:`read_run_id`); the figure is closed."""
    import io

    import matplotlib.pyplot as plt

    buf = io.BytesIO()
    try:
        metadata = None if run_id is None else {"Description": f"robocal run: {run_id}"}
        fig.savefig(buf, format="png", dpi=dpi, metadata=metadata)
    finally:
        plt.close(fig)
    return buf.getvalue()


def manifest_text(run_id: str, names: Collection[str]) -> str:
    """The :data:`MANIFEST` of a folder: its run id line, then ``names`` one a line."""
    return run_id_line(run_id) + "".join(f"{name}\n" for name in sorted(names))


def is_own_regular_file(path: Path) -> bool:
    """Whether ``path`` is a regular file (not a symbolic link) of this user."""
    try:
        info = os.lstat(path)
    except OSError:
        return False
    return stat.S_ISREG(info.st_mode) and is_mine(info)


def is_mine(info: os.stat_result) -> bool:
    """Whether the file of ``info`` belongs to this process's user (always, without uids)."""
    return not hasattr(os, "geteuid") or info.st_uid == os.geteuid()


def _listed(directory: Path) -> frozenset[str]:
    """The names in ``directory``'s manifest (none when it has none, or one not robocal's)."""
    path = directory / MANIFEST
    if not is_own_regular_file(path):
        return frozenset()
    try:
        with open(path, encoding="utf-8", errors="replace") as fh:
            lines = fh.read(_MANIFEST_MAX_BYTES).splitlines()
    except OSError:
        return frozenset()
    if not lines or not _RUN_LINE.match(lines[0]):
        return frozenset()
    return frozenset(line for line in lines[1:] if line and "/" not in line)


def robocal_names(directory: Path, names: Collection[str]) -> frozenset[str]:
    """Those of ``names`` in ``directory`` that robocal wrote: regular files (not links) of
    this user, listed in the folder's :data:`MANIFEST` or carrying a run id."""
    directory = Path(directory)
    listed = _listed(directory)
    return frozenset(
        name
        for name in names
        if is_own_regular_file(directory / name)
        and (name in listed or read_run_id(directory / name) is not None)
    )


def check_robocal_files(directory: Path, names: Collection[str], doing: str = "replace") -> None:
    """Raise :class:`ForeignFileError` naming the first of ``names`` present in
    ``directory`` that robocal did not write (see :func:`robocal_names`)."""
    directory = Path(directory)
    present = [n for n in sorted(names) if os.path.lexists(directory / n)]
    ours = robocal_names(directory, present)
    for name in present:
        if name not in ours:
            raise ForeignFileError(
                f"{directory / name}: not a file robocal wrote (no run id; or a link, or another "
                f"user's file); robocal does not {doing} it, even with --force: move it away or "
                "choose another output"
            )


def named_inputs(result_json: Path) -> frozenset[Path]:
    """The input files a ``result.json`` names (``data_file``, ``provenance.data_file``), as
    absolute paths: a transaction never replaces or drops them (``--data cal/train.csv --out
    cal`` keeps ``train.csv``); none when the file is missing or not a result."""
    import json

    try:
        data = json.loads(Path(result_json).read_text(encoding="utf-8"))
    except (OSError, ValueError, RecursionError):
        return frozenset()
    if not isinstance(data, dict):
        return frozenset()
    provenance = data.get("provenance")
    names = [data.get("data_file"), provenance.get("data_file") if isinstance(provenance, dict) else None]
    return frozenset(Path(os.path.abspath(n)) for n in names if isinstance(n, str) and n)


def input_names(directory: Path, written: Collection[str], result_json: Path) -> frozenset[str]:
    """The names of the inputs ``result_json`` names (:func:`named_inputs`) that lie in
    ``directory``; :class:`ForeignFileError` when ``written`` would replace one of them."""
    directory = Path(directory).resolve()
    names = frozenset(p.name for p in named_inputs(result_json) if p.parent.resolve() == directory)
    for name in sorted(names.intersection(written)):
        raise ForeignFileError(
            f"{directory / name}: an input of this run; robocal does not replace it: write elsewhere"
        )
    return names
