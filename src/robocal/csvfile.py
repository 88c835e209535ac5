"""The one CSV reader of robocal: a file's head, then its rows chunk by chunk (bounded memory).

Every CSV file robocal reads (measurements and poses, compensation targets, ISO 9283
logs, program target tables, study and fleet tables) goes through this module, so that
they all split lines, skip comments, sniff separators and name rows the same way:

* the file is UTF-8 (a byte-order mark is skipped; UTF-16 is named as such);
* ``#`` lines and blank lines before the header are comments; ``# key: value`` ones are
  kept as metadata; Excel's ``sep=;`` line names the separator;
* the header is the first other line; a separator not given is sniffed from it;
* every following line that is not blank and does not start with ``#`` is one row; a
  quote opened on one line does not swallow the next lines;
* rows are 1-based line numbers of the file, as an editor shows them.

:func:`read_head` reads the head (a few kB); :func:`iter_chunks` then reads the body in
chunks of about ``chunk_bytes`` (default 256 kB) as rows of cells, with each row's line
number and byte offset (from which :func:`row_at` reads a row again for a message).
Callers convert the columns they need with :func:`to_numbers` and keep only arrays, so
a large file costs its numbers, not its text.

Written by hand on the ``csv`` module rather than ``pandas.read_csv``: pandas' chunks
would also bound memory, but it joins lines inside an open quote, fills short rows with
NaN without saying so, counts lines differently once comments and blank lines are
skipped, and its fast float parser does not round-trip every number; the messages this
module makes need the file's own line numbers and cells.

The exact path costs about 30 ms per MB (5 s for a 1,000,000-row measurement file), so a
reader of numbers may ask for the fast path (:func:`iter_chunks` with ``decimal``): a
chunk that is plain numbers only (:class:`PlainNumbers`: no quotes, comments, blank,
short or long rows, text or a space inside a cell; exactly the header's count of finite
numbers on every line) is read at once by pandas' C reader, whose floats are correctly
rounded (the same bits as :func:`to_numbers`); every other chunk is read as above (a
fast-path block that is not, in parts each tried again: a bad cell now and then costs its
part's cells, not the block's), so that messages and line numbers do not depend on the path.
"""

from __future__ import annotations

import csv
import io
import re
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import BinaryIO

import numpy as np
from numpy.typing import NDArray

__all__ = [
    "Chunk",
    "CsvError",
    "Head",
    "PlainNumbers",
    "cells_with_offsets",
    "iter_chunks",
    "read_head",
    "row_at",
    "short",
    "sniff",
    "split_rows",
    "to_numbers",
]

#: Bytes of a file read to find its header (the comments before it included).
HEAD_BYTES = 1 << 16
#: Longest header or comment line read (a header of 200 000 columns is 1.4 MB).
MAX_HEADER_BYTES = 16 << 20
#: Bytes of rows read at a time (about 1 500 rows of a 6-joint measurement file).
CHUNK_BYTES = 1 << 18
#: A body of at least this many bytes is read on the fast path, when asked (importing
#: pandas, ~0.2 s, pays off: the exact path reads about 35 MB/s).
FAST_MIN_BYTES = 8 << 20
#: Bytes of rows read at a time on the fast path (pandas' call costs ~1 ms).
FAST_CHUNK_BYTES = 1 << 20
#: The bytes of a plain number table, besides its separator and decimal mark.
_PLAIN = b"0123456789+-.eE \r\n"

_EXCEL_SEP = re.compile(r"^\ufeff?sep=(.)\s*$")
DECIMAL_COMMA = re.compile(r"^[+-]?\d+,\d+([eE][+-]?\d+)?$")


class CsvError(ValueError):
    """A file that cannot be read as a CSV table: ``code`` (``file`` or ``header``), the
    message and the 1-based ``line`` (None for the whole file)."""

    def __init__(self, code: str, message: str, line: int | None = None) -> None:
        super().__init__(message)
        self.code, self.message, self.line = code, message, line


def short(cell: str, limit: int = 40) -> str:
    """A cell for a message: quoted, and cut to ``limit`` characters."""
    return repr(cell) if len(cell) <= limit else repr(cell[:limit]) + f"... ({len(cell)} characters)"


@dataclass(frozen=True)
class Head:
    """What comes before a file's rows.

    Attributes:
        path: the file.
        metadata: the ``# key: value`` lines before the header.
        header: the header's cells (stripped).
        header_line: the header's line number (1-based).
        sep: the separator (given, named by a ``sep=`` line, or sniffed).
        body_offset: byte offset of the line after the header.
        strict: a quote left open on a line is an error (else the cell runs to the end
            of the line).
    """

    path: Path
    metadata: dict[str, str]
    header: list[str]
    header_line: int
    sep: str
    body_offset: int
    strict: bool = False


def _encoding_hint(raw: bytes) -> str | None:
    if raw.startswith((b"\xff\xfe", b"\xfe\xff")):
        return "it is UTF-16 (byte-order mark); save it as UTF-8 (CSV UTF-8 in Excel)"
    return None


def _sniff(header_text: str, candidates: Sequence[str], decimal: str, spaces: bool) -> str:
    sep = max(candidates, key=header_text.count)
    if sep == decimal:
        sep = ";"
    if spaces and not header_text.count(sep) and len(header_text.split()) > 1:
        sep = " "  # columns separated by runs of spaces
    return sep


def _check_text(raw: bytes) -> None:
    """Refuse a file whose first bytes are not UTF-8 text (UTF-16 is named as such)."""
    hint = _encoding_hint(raw)
    if hint:
        raise CsvError("file", f"cannot be read as UTF-8 text: {hint}")
    sample = raw[:4096]
    if b"\x00" in sample and sample.count(b"\x00") > len(sample) // 4:
        raise CsvError(
            "file",
            "cannot be read as UTF-8 text: it looks like UTF-16 (a NUL byte between the characters); "
            "save it as UTF-8 (CSV UTF-8 in Excel)",
        )
    cut = raw.rfind(b"\n") + 1 if len(raw) == HEAD_BYTES else len(raw)
    try:  # the first 64 kB as a whole: a binary file fails here, not at its header's cells
        raw[:cut].decode("utf-8")
    except UnicodeDecodeError as err:
        raise CsvError("file", f"cannot be read as UTF-8 text: {err}") from None


def _head_lines(fh, sep: str | None) -> tuple[str | None, dict[str, str], str, int]:
    """Read comment lines, a ``sep=`` line and the header line from ``fh``: the separator
    (as given or named), the ``# key: value`` metadata, the header text and its line."""
    metadata: dict[str, str] = {}
    line_no = 0
    while True:
        raw = fh.readline(MAX_HEADER_BYTES + 1)
        if not raw:
            raise CsvError("header", "no header row (the file is empty or only has comments)")
        if len(raw) > MAX_HEADER_BYTES:
            message = f"line {line_no + 1} is longer than {MAX_HEADER_BYTES} bytes"
            raise CsvError("header", message, line_no + 1)
        line_no += 1
        try:
            line = raw.decode("utf-8").rstrip("\r\n")
        except UnicodeDecodeError as err:
            raise CsvError("file", f"cannot be read as UTF-8 text: {err}", line_no) from None
        if line.startswith("#") or not line.strip():
            text = line.lstrip("#").strip()
            if ":" in text:
                key, value = text.split(":", 1)
                metadata[key.strip()] = value.strip()
            continue
        excel = _EXCEL_SEP.match(line)
        if excel:  # Excel's "sep=;" line names the separator
            sep = sep if sep is not None else excel.group(1)
            continue
        return sep, metadata, line, line_no


def read_head(
    path: str | Path,
    *,
    sep: str | None = None,
    decimal: str = ".",
    candidates: Sequence[str] = (";", "\t", ","),
    spaces: bool = True,
    strict: bool = False,
) -> Head:
    """Read the comments, the ``sep=`` line and the header of a CSV file.

    Args:
        sep: the separator, or None to sniff the most frequent of ``candidates`` in the
            header (never the decimal mark; runs of spaces when none occurs and
            ``spaces``).

    Raises:
        CsvError: the file cannot be read, is not UTF-8, or has no header.
        FileNotFoundError: there is no such file.
    """
    path = Path(path)
    try:
        with open(path, "rb") as fh:
            raw = fh.read(HEAD_BYTES)
            _check_text(raw)
            fh.seek(3 if raw.startswith(b"\xef\xbb\xbf") else 0)
            sep, metadata, line, line_no = _head_lines(fh, sep)
            offset = fh.tell()
    except (FileNotFoundError, CsvError):
        raise
    except OSError as err:
        raise CsvError("file", f"cannot be read: {err.strerror or err}") from None
    if sep is None:
        sep = _sniff(line, candidates, decimal, spaces)
    try:
        header = [h.strip() for h in next(_reader([line.strip()], sep, strict), [])]
    except csv.Error as err:
        raise CsvError("header", f"the header cannot be read as CSV: {err}", line_no) from None
    return Head(path, metadata, header, line_no, sep, offset, strict)


def _reader(lines: Sequence[str], sep: str, strict: bool = False):
    """csv rows of ``lines``; a space separator means runs of spaces."""
    return csv.reader(lines, delimiter=sep, skipinitialspace=sep == " ", strict=strict)


def split_rows(
    lines: Sequence[str], sep: str, strict: bool = False
) -> tuple[list[list[str]], list[tuple[int, str]]]:
    """One row of cells per line (a quote opened on one line does not swallow the next);
    a line the csv module cannot read is an empty row and listed as ``(index, message)``."""
    lines = [ln.strip() if sep == " " else ln for ln in lines]
    try:
        rows = list(_reader(lines, sep, strict))
        if len(rows) == len(lines):
            return rows, []
    except csv.Error:
        pass
    rows, unreadable = [], []
    for i, ln in enumerate(lines):
        try:
            rows.append(next(_reader([ln], sep, strict), []))
        except csv.Error as err:
            rows.append([])
            unreadable.append((i, f"cannot be read as CSV: {err}"))
    return rows, unreadable


@dataclass
class Chunk:
    """Rows of a file: ``rows`` (cells, not stripped), each row's ``line`` number and
    byte ``offset``, and the rows that could not be read or have another number of
    cells than the header: ``problems`` as ``(index, code, message)``, code ``file``
    (not UTF-8, not CSV: its cells are empty) or ``ragged``.

    ``numbers``: on the fast path (:func:`iter_chunks` with ``decimal``), a chunk whose
    every cell is a plain finite number comes as these numbers, ``(rows, header
    columns)`` floats, with ``rows`` empty and no problems."""

    rows: list[list[str]]
    line: NDArray[np.int64]
    offset: NDArray[np.int64]
    problems: list[tuple[int, str, str]] = field(default_factory=list)
    numbers: NDArray[np.float64] | None = None

    def __len__(self) -> int:
        return len(self.line)


def _blocks(fh: BinaryIO, size: int) -> Iterator[bytes]:
    """Whole lines of ``fh``, about ``size`` bytes at a time (a longer line whole)."""
    carry = b""
    while block := fh.read(size):
        block = carry + block
        cut = block.rfind(b"\n") + 1
        carry = block[cut:]
        if cut:
            yield block[:cut]
    if carry:
        yield carry


def _exact_chunk(block: bytes, head: Head, offset: int, no: int) -> Chunk:
    """The rows of ``block`` (whole lines from byte ``offset``, the first after line
    ``no``) split cell by cell by the csv module, with each problem named."""
    width = len(head.header)
    nos, offs, texts, problems = [], [], [], []
    for raw in io.BytesIO(block).readlines():  # lines end at \n only, as the file's
        no += 1
        if raw.strip() and not raw.lstrip().startswith(b"#"):
            try:
                texts.append(raw.decode("utf-8").rstrip("\r\n"))
            except UnicodeDecodeError:
                problems.append((len(texts), "file", "cannot be read as UTF-8 text"))
                texts.append("")
            nos.append(no)
            offs.append(offset)
        offset += len(raw)
    rows, unreadable = split_rows(texts, head.sep, head.strict)
    problems += [(i, "file", message) for i, message in unreadable]
    failed = {i for i, _, _ in problems}
    for i, r in enumerate(rows):
        if len(r) != width and i not in failed:
            message = f"has {len(r)} cells but the header has {width} (separator {head.sep!r})"
            problems.append((i, "ragged", message))
    problems.sort()
    return Chunk(rows, np.array(nos, dtype=np.int64), np.array(offs, dtype=np.int64), problems)


@dataclass(frozen=True)
class PlainNumbers:
    """The fast path of :func:`iter_chunks`: a block of whole lines read at once by
    pandas' C reader when it is plain numbers, else None (the block is then read cell
    by cell, and every problem named as it would be anyway).

    Plain: only digits, ``+ - . e E``, spaces, the separator, the decimal mark and line
    ends (``\\r`` only before ``\\n``): no quotes, comments, letters (``nan``, ``inf``)
    or non-ASCII bytes; then exactly ``width`` finite numbers on every line (a blank,
    short or long line, an empty cell or one pandas cannot read sends the block to the
    exact path).  pandas reads floats correctly rounded (its default converter since
    3.1, ``float_precision="round_trip"`` before), the same numbers as :func:`to_numbers`.

    Attributes:
        sep: the separator (``,``, ``;`` or tab).
        decimal: the decimal mark (``.`` or ``,``, not ``sep``).
        width: the header's number of columns.
    """

    sep: str
    decimal: str
    width: int

    def read(self, block: bytes) -> tuple[NDArray[np.float64], NDArray[np.int64]] | None:
        """``(values (lines, width), each line's byte offset in block)``, or None."""
        if block.translate(None, _PLAIN + f"{self.sep}{self.decimal}".encode()):
            return None  # another character
        if block.count(b"\r") != block.count(b"\r\n"):
            return None  # a carriage return inside a line
        codes = np.frombuffer(block, dtype=np.uint8)
        if b" " in block and self._space_inside_cell(codes):
            return None  # "1 2" or "1e 5": pandas would read some of these
        ends = np.flatnonzero(codes == 10)
        if not block.endswith(b"\n"):
            ends = np.append(ends, len(block))
        starts = np.concatenate(([0], ends[:-1] + 1)).astype(np.int64)
        values = self._parse(block)
        if values is None or values.shape != (len(starts), self.width) or not np.isfinite(values).all():
            return None
        return values, starts

    def _space_inside_cell(self, codes: NDArray[np.uint8]) -> bool:
        """Whether a run of spaces stands between two characters of one cell (the exact
        path strips cells, and a cell with a space inside is not a number)."""
        kept = np.flatnonzero(codes != 32)
        edge = np.zeros(256, dtype=bool)
        edge[[ord(self.sep), 10, 13]] = True
        inner = ~edge[codes[kept]]
        return bool(np.any((np.diff(kept) > 1) & inner[:-1] & inner[1:]))

    def _parse(self, block: bytes) -> NDArray[np.float64] | None:
        import pandas as pd  # imported for large files only (~0.2 s)

        try:
            table = pd.read_csv(
                io.BytesIO(block), sep=self.sep, decimal=self.decimal, header=None, dtype=np.float64,
                engine="c", na_filter=False, skip_blank_lines=False, quoting=csv.QUOTE_NONE,
                low_memory=False, **_exact_floats(pd.__version__),
            )  # fmt: skip
        except (ValueError, pd.errors.ParserError, pd.errors.EmptyDataError):
            return None  # a cell that is not a number, or a row longer than the first
        return np.ascontiguousarray(table.to_numpy(dtype=np.float64))


def _exact_floats(version: str) -> dict[str, str]:
    """pandas' option for correctly rounded floats: the default since 3.1 (the option
    deprecated), ``float_precision="round_trip"`` before."""
    major, minor = (int(part) for part in version.split(".")[:2])
    return {} if (major, minor) >= (3, 1) else {"float_precision": "round_trip"}


def iter_chunks(
    head: Head,
    *,
    chunk_bytes: int = CHUNK_BYTES,
    decimal: str | None = None,
    fast_min_bytes: int | None = None,
) -> Iterator[Chunk]:
    """The rows after ``head``, about ``chunk_bytes`` of the file at a time.

    ``decimal``: also try the fast path (:class:`PlainNumbers`) when the body has at
    least ``fast_min_bytes`` bytes (None: :data:`FAST_MIN_BYTES`): a chunk of plain
    numbers comes as :attr:`Chunk.numbers`, read at once (chunks of
    :data:`FAST_CHUNK_BYTES` then, an irregular one tried again in parts); any other chunk
    (quotes, comments, blank or short rows, text cells) comes as rows, exactly as without
    ``decimal``, so that messages and line numbers are the same either way."""
    fast = None
    plain = decimal is not None and head.sep in (",", ";", "\t") and head.sep != decimal
    least = FAST_MIN_BYTES if fast_min_bytes is None else fast_min_bytes
    if plain and head.path.stat().st_size - head.body_offset >= least:
        fast = PlainNumbers(head.sep, str(decimal), len(head.header))
        chunk_bytes = FAST_CHUNK_BYTES  # fewer, larger calls of pandas
    with open(head.path, "rb") as fh:
        fh.seek(head.body_offset)
        offset, no = head.body_offset, head.header_line
        for block in _blocks(fh, chunk_bytes):
            yield from _block_chunks(block, head, offset, no, fast)
            no += block.count(b"\n")
            offset += len(block)


def _block_chunks(
    block: bytes, head: Head, offset: int, no: int, fast: PlainNumbers | None, whole: bool = True
) -> Iterator[Chunk]:
    """``block`` (lines from byte ``offset``, the first after line ``no``) as chunks, fast or
    cell by cell; an irregular fast-path block in parts of :data:`CHUNK_BYTES`, plain ones still
    fast: an exact chunk's cells hold ~5x its bytes (a 1 MB block peaked at 6.6 MB)."""
    parsed = fast.read(block) if fast is not None else None
    if parsed is not None:
        values, starts = parsed
        yield Chunk([], np.arange(no + 1, no + 1 + len(values), dtype=np.int64), starts + offset, [], values)
    elif fast is None or not whole or len(block) <= CHUNK_BYTES:
        yield _exact_chunk(block, head, offset, no)
    else:
        for part in _blocks(io.BytesIO(block), CHUNK_BYTES):
            yield from _block_chunks(part, head, offset, no, fast, whole=False)
            no += part.count(b"\n")
            offset += len(part)


def sniff(header_text: str, candidates: Sequence[str] = (",", ";", "\t")) -> str:
    """The most frequent of ``candidates`` in a header line (the first on a tie)."""
    return max(candidates, key=header_text.count)


def cells_with_offsets(line: str, sep: str) -> list[tuple[str, int]]:
    """The cells of ``line`` split at ``sep`` (no quoting), each with its offset in the
    line: for files edited in place, whose numbers are replaced where they stand."""
    out, start = [], 0
    for cell in line.split(sep):
        out.append((cell, start))
        start += len(cell) + len(sep)
    return out


def row_at(head: Head, offset: int) -> list[str]:
    """The cells of the row at byte ``offset`` (read again, for a message)."""
    with open(head.path, "rb") as fh:
        fh.seek(int(offset))
        line = fh.readline().decode("utf-8", errors="replace").rstrip("\r\n")
    rows, _ = split_rows([line], head.sep, head.strict)
    return rows[0]


def to_numbers(
    cells: Sequence[str], decimal: str = "."
) -> tuple[NDArray[np.float64], list[tuple[int, str, str]]]:
    """Cells as floats (exact: shortest round-trip text reads back to the same number).

    Returns:
        ``(values, problems)``: a bad cell is NaN in ``values`` and listed as ``(index,
        code, message)`` with code ``empty``, ``not-a-number`` (with a hint when it looks
        like a decimal comma) or ``not-finite``.
    """
    text = [c.strip() for c in cells]
    if decimal == ",":
        text = [c.replace(",", ".") for c in text]
    try:
        if "\x00" in "".join(text):  # numpy's text arrays drop trailing NULs: "3\x00" would read as 3
            raise ValueError("NUL")
        values = np.array(text).astype(float) if text else np.zeros(0)
        problems: list[tuple[int, str, str]] = []
    except ValueError:
        values = np.full(len(text), np.nan)
        problems = []
        for m, t in enumerate(text):
            try:
                values[m] = float(t)
            except ValueError:
                raw = cells[m].strip()
                if not raw:
                    problems.append((m, "empty", "empty cell (missing value)"))
                    continue
                hint = ""
                if decimal == "." and DECIMAL_COMMA.match(raw):
                    hint = "; it looks like a decimal comma: pass decimal=','"
                problems.append((m, "not-a-number", f"{short(raw)} is not a number{hint}"))
    bad = ~np.isfinite(values)
    if bad.any():
        flagged = {m for m, _, _ in problems}
        for row in map(int, np.flatnonzero(bad)):
            if row not in flagged:
                problems.append((row, "not-finite", f"value {short(cells[row].strip())} is not finite"))
        values[bad] = np.nan
        problems.sort()
    return values, problems
