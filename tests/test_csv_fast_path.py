"""The CSV reader's fast path (issue 32 item 1: ``robocal calibrate`` on 1,000,000 rows).

A chunk of plain numbers is read at once by pandas' C reader (csvfile.PlainNumbers); any
other chunk is read cell by cell as before.  These tests hold the two paths equal: the
same floats to the bit (exponents, negative zero, many digits, decimal comma), the same
line numbers and byte offsets, and the same problems (rows, columns, messages) for bad
files, because a chunk that is not plain is declined and read by the exact path.
"""

from __future__ import annotations

import random

import numpy as np
import pytest

from robocal import csvfile
from robocal.measure.dataset.read import check_measurements, read_measurements
from robocal.model.catalog import robot

HEADER = "q1,q2,q3,q4,q5,q6,x,y,z"


def _bits(values) -> np.ndarray:
    return np.ascontiguousarray(values, dtype=np.float64).view(np.int64)


def _random_cells(rng: np.random.Generator, n: int) -> list[str]:
    """Numbers as a file may write them: shortest repr, many digits, exponents, integers,
    negative zero, signs, subnormals and numbers near the largest float."""
    x = rng.standard_normal(n) * 10.0 ** rng.integers(-30, 30, n)
    cells = []
    for i, v in enumerate(x):
        kind = i % 9
        if kind == 0:
            cells.append(repr(float(v)))
        elif kind == 1:
            cells.append(f"{v:.25g}")  # more digits than a double holds
        elif kind == 2:
            cells.append(f"{v:.3E}")
        elif kind == 3:
            cells.append(str(int(v * 1e-20 if abs(v) > 1e20 else v)))
        elif kind == 4:
            cells.append(rng.choice(["-0", "-0.0", "+0", "0e0", "-0E-5", "00.500"]))
        elif kind == 5:
            cells.append(f"+{abs(v):.17e}")
        elif kind == 6:
            cells.append(repr(float(rng.choice([5e-324, 2.2250738585072014e-308, 1.7976931348623157e308]))))
        elif kind == 7:
            cells.append(
                "".join(rng.choice(list("0123456789"), 30))
                + "."
                + "".join(rng.choice(list("0123456789"), 30))
            )
        else:
            cells.append(f"{v:.17g}")
    return cells


@pytest.mark.parametrize("sep,decimal", [(",", "."), (";", ","), ("\t", ".")])
def test_plain_numbers_are_the_exact_paths_floats_to_the_bit(sep, decimal):
    rng = np.random.default_rng(3)
    width = 9
    cells = _random_cells(rng, 900 * width)
    if decimal == ",":
        cells = [c.replace(".", ",") for c in cells]
    lines = [sep.join(cells[i : i + width]) for i in range(0, len(cells), width)]
    block = ("\n".join(lines) + "\n").encode()
    parsed = csvfile.PlainNumbers(sep, decimal, width).read(block)
    assert parsed is not None  # plain numbers: the fast path takes the block
    values, starts = parsed
    exact, problems = csvfile.to_numbers(cells, decimal)
    assert not problems
    assert np.array_equal(_bits(values.ravel()), _bits(exact))
    assert np.signbit(values).any() and (values == 0).any()  # negative zero kept as such
    assert [block[s : s + 20] for s in starts[:3]] == [ln.encode()[:20] for ln in lines[:3]]


def test_random_cells_the_fast_path_takes_read_as_the_exact_path_reads_them():
    """Random short strings of the fast path's characters ("1e", "+74E 0", "1,5,3", " -0 ")
    in one column: whatever it takes is the number the exact path reads, and a cell the
    exact path refuses is never taken."""
    rng = random.Random(7)
    taken = declined = 0
    for sep, decimal in ((",", "."), (";", ","), ("\t", ".")):
        reader = csvfile.PlainNumbers(sep, decimal, 2)
        alphabet = "0123456789+-.eE " + ("," if decimal == "," else "")
        cells = ["".join(rng.choice(alphabet) for _ in range(rng.randint(1, 7))) for _ in range(3000)]
        cells += ["1e", "1e+", "e5", ".", "1.2.3", "+74E 0", "1 2", "1e309", "1e-400", "1,5,3", " 1.5 "]
        for cell in cells:
            parsed = reader.read(f"{cell}{sep}1\n".encode())
            exact, problems = csvfile.to_numbers([cell], decimal)
            if parsed is None:
                declined += 1
                continue
            taken += 1
            assert not problems, (cell, decimal)
            assert _bits(parsed[0][0, :1]) == _bits(exact), (cell, decimal)
    assert taken > 1000 and declined > 1000  # both paths exercised


@pytest.mark.parametrize(
    "body",
    [
        '1,2,3\n"4",5,6\n',  # a quote
        "1,2,3\n# a comment\n4,5,6\n",  # a comment inside the body
        "1,2,3\n\n4,5,6\n",  # a blank line
        "1,2,3\n4,5\n",  # a short row
        "1,2,3\n4,5,6,7\n",  # a long row
        "1,2,3,\n",  # a trailing separator
        "1,2,3\n4,,6\n",  # an empty cell
        "1,2,3\n4,nan,6\n",  # text
        "1,2,3\n4,1e999,6\n",  # not finite
        "1,2,3\r4,5,6\n",  # a carriage return inside a line
        "1,2,3\n4,5\xa0,6\n",  # a non-ASCII character
        "1,2,3\n4,5 5,6\n",  # a space inside a cell
    ],
)
def test_an_irregular_block_is_declined(body):
    assert csvfile.PlainNumbers(",", ".", 3).read(body.encode()) is None


def test_crlf_line_ends_and_spaces_around_cells_are_plain():
    parsed = csvfile.PlainNumbers(",", ".", 3).read(b"1,2,3\r\n 4 , 5,-0\r\n")
    assert parsed is not None
    assert np.array_equal(_bits(parsed[0]), _bits([[1.0, 2.0, 3.0], [4.0, 5.0, -0.0]]))
    assert list(parsed[1]) == [0, 7]


def _write(path, rows: list[str], header: str = HEADER) -> None:
    path.write_text("# units: m, rad\n" + header + "\n" + "\n".join(rows) + "\n")


def _rows(n: int, seed: int = 0) -> list[str]:
    rng = np.random.default_rng(seed)
    q = rng.uniform(-1.0, 1.0, (n, 6))
    p = rng.uniform(-1.0, 1.0, (n, 3))
    return [",".join(repr(float(v)) for v in row) for row in np.hstack([q, p])]


def _chunks(path, **kwargs) -> tuple[np.ndarray, np.ndarray, list[int]]:
    head = csvfile.read_head(path)
    lines, offsets, fast = [], [], []
    for chunk in csvfile.iter_chunks(head, chunk_bytes=4096, **kwargs):
        lines.append(chunk.line)
        offsets.append(chunk.offset)
        fast.append(chunk.numbers is not None)
    return np.concatenate(lines), np.concatenate(offsets), fast


def test_fast_chunks_have_the_exact_chunks_line_numbers_and_offsets(tmp_path, monkeypatch):
    monkeypatch.setattr(csvfile, "FAST_CHUNK_BYTES", 4096)
    rows = _rows(600)
    rows[300] = "# a comment in the middle"
    rows[301] = ""
    _write(tmp_path / "m.csv", rows)
    exact = _chunks(tmp_path / "m.csv")
    fast = _chunks(tmp_path / "m.csv", decimal=".", fast_min_bytes=0)
    assert np.array_equal(fast[0], exact[0]) and np.array_equal(fast[1], exact[1])
    assert any(fast[2]) and not all(fast[2])  # the comment's chunk read cell by cell
    head = csvfile.read_head(tmp_path / "m.csv")
    assert csvfile.row_at(head, int(fast[1][-1])) == rows[-1].split(",")


def _read_both(monkeypatch, path, **options):
    """``check_measurements`` and ``read_measurements`` with the fast path on every
    chunk (1 kB chunks) and with the exact path alone."""
    taken = []
    plain_read = csvfile.PlainNumbers.read

    def spy(self, block):
        parsed = plain_read(self, block)
        taken.append(parsed is not None)
        return parsed

    monkeypatch.setattr(csvfile.PlainNumbers, "read", spy)
    monkeypatch.setattr(csvfile, "FAST_CHUNK_BYTES", 1024)
    out = []
    for least in (0, 1 << 60):
        monkeypatch.setattr(csvfile, "FAST_MIN_BYTES", least)
        problems = check_measurements(path, **options)
        try:
            data = read_measurements(path, **options)
        except ValueError as err:
            data = str(err)
        out.append((problems, data))
        if least:
            assert not taken  # the exact path alone
        else:
            assert sum(taken) > len(taken) // 2  # most chunks through the fast path
            taken.clear()
    return out


def test_read_measurements_is_the_same_through_the_fast_path(tmp_path, monkeypatch):
    rows = _rows(800, seed=1)
    _write(tmp_path / "ok.csv", rows)
    (fast_problems, fast), (exact_problems, exact) = _read_both(monkeypatch, tmp_path / "ok.csv")
    assert fast_problems == exact_problems == []
    assert np.array_equal(_bits(fast.q), _bits(exact.q))
    assert np.array_equal(_bits(fast.position), _bits(exact.position))
    assert fast.metadata == exact.metadata


@pytest.mark.parametrize(
    "row,bad",
    [
        (500, "0.1,0.2,abc,0.4,0.5,0.6,1,2,3"),  # a text cell
        (500, "0.1,0.2,0.3,0.4,0.5,0.6,1,2"),  # a short row
        (500, "0.1,0.2,0.3,0.4,0.5,0.6,1,2,3,4"),  # a long row
        (500, "0.1,0.2,,0.4,0.5,0.6,1,2,3"),  # an empty cell
        (500, '0.1,0.2,"0,3",0.4,0.5,0.6,1,2,3'),  # a quoted cell with a decimal comma
        (500, "0.1,0.2,inf,0.4,0.5,0.6,1,2,3"),  # not finite
        (799, "0.1,0.2,0.3,0.4,0.5,0.6,1,2,3e5"),  # a position in the wrong unit, the last row
    ],
)
def test_a_bad_file_gets_the_same_problems_through_the_fast_path(tmp_path, monkeypatch, row, bad):
    rows = _rows(800, seed=2)
    rows[row] = bad
    _write(tmp_path / "bad.csv", rows)
    (fast_problems, fast), (exact_problems, exact) = _read_both(monkeypatch, tmp_path / "bad.csv")
    assert exact_problems  # the file is bad ...
    assert fast_problems == exact_problems  # ... and named alike: row, column, message
    assert isinstance(fast, str) and fast == exact


def test_a_joint_outside_its_limits_is_named_by_row_through_the_fast_path(tmp_path, monkeypatch):
    """A problem found after reading (joint limits) names its row by the line numbers the
    fast path kept."""
    model = robot("ur10")
    rows = _rows(800, seed=3)
    cells = rows[650].split(",")
    cells[2] = "7.5"  # beyond the elbow's limit
    rows[650] = ",".join(cells)
    _write(tmp_path / "limits.csv", rows)
    (fast_problems, _), (exact_problems, _) = _read_both(monkeypatch, tmp_path / "limits.csv", model=model)
    assert any(p.row == 653 for p in exact_problems)  # the comment and the header before
    assert fast_problems == exact_problems


def test_decimal_comma_file_reads_alike(tmp_path, monkeypatch):
    rows = [r.replace(",", ";").replace(".", ",") for r in _rows(700, seed=4)]
    _write(tmp_path / "comma.csv", rows, header=HEADER.replace(",", ";"))
    (fast_problems, fast), (_, exact) = _read_both(monkeypatch, tmp_path / "comma.csv", decimal=",")
    assert fast_problems == []
    assert np.array_equal(_bits(fast.q), _bits(exact.q))
    assert np.array_equal(_bits(fast.position), _bits(exact.position))
