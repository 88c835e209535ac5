"""The results tables of studies and fleets: append-only CSV journals (:class:`Table`)."""

from __future__ import annotations

import csv
import io
import os
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from robocal import csvfile
from robocal.outdir import atomic_write_text
from robocal.run_ids import is_own_regular_file
from robocal.safe_output import csv_text, csv_untext
from robocal.study.config import StudyError


class Table:
    """An append-only CSV journal: a row is flushed to disk as soon as it is known.

    On opening, rows already there are read (a last line cut short by a crash is
    dropped, and the file rewritten atomically without it); :meth:`append` adds rows
    and ``fsync``s them.
    """

    def __init__(self, path: Path, columns: Sequence[str], key: str) -> None:
        self.path, self.columns, self.key = path, tuple(columns), key
        self.rows: dict[str, dict[str, str]] = {}
        if os.path.lexists(path) and not is_own_regular_file(path):  # appended to: never through a link
            raise StudyError(
                f"{path}: a link or another user's file, not a table robocal wrote; move it away"
            )
        if path.exists():
            self._load()
        else:
            atomic_write_text(path, ",".join(self.columns) + "\n")

    def _load(self) -> None:
        text = self.path.read_text(encoding="utf-8")
        lines = text.splitlines(keepends=True)
        if not lines or lines[0].strip() != ",".join(self.columns):
            raise StudyError(
                f"{self.path}: not a robocal results table of this version (header differs); "
                "use --force to start over"
            )
        good: list[str] = [lines[0]]
        for i, line in enumerate(lines[1:], start=2):
            cells = csvfile.split_rows([line.rstrip("\r\n")], ",")[0][0]
            complete = line.endswith("\n") and len(cells) == len(self.columns)
            if not complete:
                if i == len(lines):  # cut short by a crash: drop it
                    break
                raise StudyError(f"{self.path}: row {i} has {len(cells)} cells, expected {len(self.columns)}")
            row = dict(zip(self.columns, cells, strict=True))
            self.rows[csv_untext(row[self.key])] = row
            good.append(line)
        if len(good) != len(lines):
            atomic_write_text(self.path, "".join(good))

    def append(self, rows: Iterable[Mapping[str, Any]]) -> None:
        self.append_cells(table_cells(rows, self.columns))

    def append_cells(self, cells: Sequence[Sequence[str]]) -> None:
        """Append rows already formatted by :func:`table_cells` for these columns."""
        buf = io.StringIO()
        csv.writer(buf, lineterminator="\n").writerows(cells)
        with open(self.path, "a", encoding="utf-8") as fh:
            fh.write(buf.getvalue())
            fh.flush()
            os.fsync(fh.fileno())
        for row_cells in cells:
            row = dict(zip(self.columns, row_cells, strict=True))
            self.rows[csv_untext(row[self.key])] = row


def remove_table(path: Path, columns: Sequence[str]) -> None:
    """Delete the results table at ``path`` (``--force``) when robocal wrote it: this user's
    plain file whose header is ``columns``; anything else is refused, never deleted."""
    if not os.path.lexists(path):
        return
    header = None
    if is_own_regular_file(path):
        with open(path, encoding="utf-8", errors="replace") as fh:
            header = fh.readline(64 * 1024).strip()
    if header != ",".join(columns):
        raise StudyError(
            f"{path}: not a results table robocal wrote (another header, a link, or another user's "
            "file); robocal does not delete it, even with --force: move it away or choose another output"
        )
    path.unlink()


def table_cells(rows: Iterable[Mapping[str, Any]], columns: Sequence[str]) -> list[list[str]]:
    """The rows as a table's text cells in ``columns`` order (a missing value is empty);
    a task formats its own rows, on its worker, so the process writing the table does
    little more than write."""
    return [[_cell(row.get(c, "")) for c in columns] for row in rows]


def _cell(value: Any) -> str:
    if isinstance(value, float | np.floating):
        return repr(float(value))
    return csv_text(str(value))  # a file name or message is never run as a spreadsheet formula
