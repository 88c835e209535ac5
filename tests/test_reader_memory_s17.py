"""Reading memory of the one CSV reader on files with a bad cell now and then (session 17).

A fast-path block (:data:`robocal.csvfile.FAST_CHUNK_BYTES`) that is not plain numbers is
read in parts of :data:`robocal.csvfile.CHUNK_BYTES`: each plain part still on the fast path,
only the part holding the irregular line cell by cell.  Reading a whole 1 MB block cell by
cell held ~12 MB of Python strings at once, and a bad cell in every block (a tracker that
loses the beam now and then) did so all through the file.
"""

from __future__ import annotations

import io
import tracemalloc
import warnings

import numpy as np
import pytest

from robocal import csvfile
from robocal.measure.dataset.read import check_measurements, read_measurements

HEADER = "q1,q2,q3,q4,q5,q6,x,y,z"


def _text(n: int, every: int, seed: int = 0) -> str:
    """``n`` rows of 9 numbers (17 digits) with an empty or "bad" cell every ``every`` rows."""
    rng = np.random.default_rng(seed)
    table = np.hstack([rng.uniform(-3, 3, (n, 6)), rng.uniform(-1, 1, (n, 3))])
    buf = io.StringIO()
    np.savetxt(buf, table, fmt="%.17g", delimiter=",")
    lines = buf.getvalue().splitlines()
    for i in range(7, n, every):
        cells = lines[i].split(",")
        cells[i % 9] = "" if i % 2 else "bad"
        lines[i] = ",".join(cells)
    return HEADER + "\n" + "\n".join(lines) + "\n"


def _chunks(path) -> list[csvfile.Chunk]:
    head = csvfile.read_head(path)
    return list(csvfile.iter_chunks(head, decimal=".", fast_min_bytes=0))


def test_an_irregular_fast_block_is_read_in_parts(tmp_path, monkeypatch):
    """Only the part with the bad line is read cell by cell; line numbers, offsets and
    problems are the exact path's."""
    monkeypatch.setattr(csvfile, "FAST_CHUNK_BYTES", 8192)
    monkeypatch.setattr(csvfile, "CHUNK_BYTES", 1024)
    path = tmp_path / "d.csv"
    path.write_text(_text(2000, 97))
    chunks = _chunks(path)
    exact = list(csvfile.iter_chunks(csvfile.read_head(path)))
    assert np.array_equal(np.concatenate([c.line for c in chunks]), np.concatenate([c.line for c in exact]))
    assert np.array_equal(
        np.concatenate([c.offset for c in chunks]), np.concatenate([c.offset for c in exact])
    )
    slow = [c for c in chunks if c.numbers is None]
    fast_rows = sum(len(c) for c in chunks if c.numbers is not None)
    # every 8 kB block has a bad line (about every 17 kB of rows): most rows stay fast anyway
    assert fast_rows > 0.8 * 2000, fast_rows  # 94% now, 52% when the whole block was read cell by cell
    line_bytes = max(len(line) + 1 for line in path.read_text().splitlines())
    for c in slow:  # no cell-by-cell chunk holds more than a part of the file
        assert sum(len(",".join(r)) + 1 for r in c.rows) <= 1024 + line_bytes
    bad_lines = {int(c.line[i]) for c in slow for i in range(len(c)) if "" in c.rows[i] or "bad" in c.rows[i]}
    assert bad_lines == {i + 2 for i in range(7, 2000, 97)}  # line 1 is the header


def test_a_long_irregular_line_is_read_whole(tmp_path, monkeypatch):
    """A line longer than a part: read cell by cell in one piece, its line number right."""
    monkeypatch.setattr(csvfile, "FAST_CHUNK_BYTES", 4096)
    monkeypatch.setattr(csvfile, "CHUNK_BYTES", 64)
    path = tmp_path / "d.csv"
    text = _text(300, 1000).splitlines()
    text[40] = ",".join(["1.5"] * 8 + ["x" * 300])
    path.write_text("\n".join(text) + "\n")
    chunks = _chunks(path)
    where = [(c, i) for c in chunks for i in range(len(c)) if int(c.line[i]) == 41]
    assert len(where) == 1 and where[0][0].rows[where[0][1]][-1] == "x" * 300
    assert np.array_equal(np.concatenate([c.line for c in chunks]), np.arange(2, 302))


def test_problems_and_numbers_are_the_same_through_the_parts(tmp_path, monkeypatch):
    """Messages, line numbers and floats (to the bit) as on the exact path alone."""
    monkeypatch.setattr(csvfile, "FAST_CHUNK_BYTES", 8192)
    monkeypatch.setattr(csvfile, "CHUNK_BYTES", 1024)
    path = tmp_path / "d.csv"
    path.write_text(_text(3000, 131, seed=2))
    out = []
    for least in (0, 1 << 60):
        monkeypatch.setattr(csvfile, "FAST_MIN_BYTES", least)
        with pytest.warns(UserWarning):
            data = read_measurements(path, dof=6, incomplete="drop")
        out.append((check_measurements(path, dof=6), data))
    (fast_problems, fast), (exact_problems, exact) = out
    assert fast_problems == exact_problems and len(fast_problems) == len(range(7, 3000, 131))
    assert np.array_equal(fast.q.view(np.uint64), exact.q.view(np.uint64))
    assert np.array_equal(fast.position.view(np.uint64), exact.position.view(np.uint64))


def test_reading_memory_with_a_bad_cell_in_every_fast_block(tmp_path, monkeypatch):
    """A bad cell in every fast-path block: the peak (tracemalloc) stays within 3x the
    numbers as float64 (the cell-by-cell 1 MB blocks held 6x)."""
    import pandas  # noqa: F401  - the fast path's one import, a fixed cost, is not reading memory

    monkeypatch.setattr(csvfile, "FAST_MIN_BYTES", 0)  # a smaller file than 8 MB on the fast path
    n = 60_000
    path = tmp_path / "d.csv"
    path.write_text(_text(n, 4000))
    tracemalloc.start()
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            data = read_measurements(path, dof=6, incomplete="drop")
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert data.n == n - len(range(7, n, 4000))
    numbers = n * 9 * 8
    assert peak <= 3 * numbers, f"peak {peak / 1e6:.1f} MB for {numbers / 1e6:.1f} MB of numbers"
