"""Hostile input beyond the corpus of test_fuzz_inputs: CSV, YAML, URDF, command-line
options, result folders and numerical edge cases, each run through the ``robocal``
command in-process.  Every case must end within a time bound in exactly one ``error:``
line naming the input (or Typer's usage error naming the option), with the expected exit
code, no traceback and nothing written.  Cases that must succeed check that data with
Rich markup or terminal escapes is printed as written, never interpreted."""

from __future__ import annotations

import errno
import json
import os
import shutil
import signal
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from robocal.cli import app
from robocal.measure import LaserTracker, VirtualRobot, draw_true_model, simulate
from robocal.measure.dataset.writer import write_measurements
from robocal.measure.poses import random_poses
from robocal.model.catalog import robot

SECONDS = 180  # a hang guard (SIGALRM): a hang fails the case instead of blocking the run
UR10_URDF = Path(__file__).parent / "data" / "ur10.urdf"
GEOMETRY = Path(__file__).parents[1] / "examples" / "geometry" / "irb2400.yaml"


@contextmanager
def time_limit(seconds: int = SECONDS):
    def expired(signum, frame):
        raise TimeoutError(f"took more than {seconds} s")

    old = signal.signal(signal.SIGALRM, expired)
    signal.alarm(seconds)
    try:
        yield
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, old)


# ------------------------------------------------------------------ fixtures
@pytest.fixture(scope="module")
def base(tmp_path_factory) -> Path:
    """A folder with good measurements (meas.csv, 30 poses of a UR10 with a laser tracker)
    and their calibration (cal/)."""
    root = tmp_path_factory.mktemp("hostile")
    ur10 = robot("ur10")
    q = random_poses(ur10, 30, seed=5)
    virtual = VirtualRobot(
        ur10, draw_true_model(ur10, seed=5), LaserTracker(p_tool_target=np.array([0, 0, 0.1]))
    )
    write_measurements(simulate(virtual, q, seed=5), root / "meas.csv")
    result = CliRunner().invoke(
        app,
        [
            "calibrate",
            "ur10",
            "--data",
            str(root / "meas.csv"),
            "--out",
            str(root / "cal"),
            "--residual",
            "none",
        ],
    )
    assert result.exit_code == 0, result.output
    return root


def _csv_text(base: Path) -> str:
    return (base / "meas.csv").read_text()


def _body(base: Path) -> list[str]:
    return [ln for ln in _csv_text(base).splitlines() if not ln.startswith("#")]


@dataclass(frozen=True)
class Case:
    """One hostile input: files to create (name -> text, bytes or a function of the base
    folder), the command (``{dir}`` is the case's folder, ``{base}`` the fixture's), the
    exit code, words the error line must contain, and paths that must not be written."""

    id: str
    args: tuple[str, ...]
    files: dict = field(default_factory=dict)
    code: int = 2
    says: tuple[str, ...] = ()
    usage: bool = False  # Typer's usage error (names the option)
    writes: tuple[str, ...] = ("out",)


def _materialise(case: Case, base: Path, where: Path) -> list[str]:
    for name, content in case.files.items():
        path = where / name
        path.parent.mkdir(parents=True, exist_ok=True)
        if callable(content):
            content = content(base)
        if content is None:
            continue
        if isinstance(content, str):
            content = content.encode("utf-8")
        path.write_bytes(content)
    return [a.format(dir=where, base=base) for a in case.args]


def _check(case: Case, result, where: Path) -> None:
    output = result.output
    assert "Traceback" not in output, output
    assert result.exception is None or isinstance(result.exception, SystemExit), repr(result.exception)
    assert result.exit_code == case.code, (case.id, result.exit_code, output)
    if case.code != 2:  # 0: read as written; 1: a check that lists the file's problems
        return
    err = result.stderr
    if case.usage:
        assert "Invalid value" in err or "Error" in err, err
    else:
        errors = [ln for ln in err.splitlines() if ln.startswith("error:")]
        assert len(errors) == 1, err
        assert "\x1b" not in errors[0] and "internal error" not in errors[0], errors[0]
        # the message is one line: nothing follows the error line
        assert err.rstrip("\n").endswith(errors[0]), err
    for word in case.says:
        assert word.format(dir=where) in err, (case.id, err)
    for name in case.writes:
        assert not (where / name).exists(), f"{case.id}: {name} was written"


def _run(case: Case, base: Path, tmp_path: Path) -> None:
    args = _materialise(case, base, tmp_path)
    with time_limit():
        result = CliRunner().invoke(app, args)
    _check(case, result, tmp_path)


def _replace_cell(row: int, col: int, value: str):
    def make(base: Path) -> str:
        lines = _body(base)
        cells = lines[row].split(",")
        cells[col] = value
        lines[row] = ",".join(cells)
        return "\n".join(lines) + "\n"

    return make


def _rename_header(old: str, new: str):
    def make(base: Path) -> str:
        lines = _body(base)
        lines[0] = lines[0].replace(old, new, 1)
        return "\n".join(lines) + "\n"

    return make


def _with_body(transform):
    def make(base: Path) -> str:
        return transform(_body(base))

    return make


CAL = ("calibrate", "ur10", "--data", "{dir}/d.csv", "--out", "{dir}/out", "--residual", "none")
CHECK = ("data", "check", "{dir}/d.csv", "ur10")


def _cal(*extra: str) -> tuple[str, ...]:
    return (*CAL, *extra)


# ------------------------------------------------------------------ CSV
CSV_CASES = [
    Case("header-markup", _cal(), {"d.csv": _rename_header("q1", "[/x]")}, says=("{dir}/d.csv", "[/x]")),
    Case(
        "header-markup-red", _cal(), {"d.csv": _rename_header("q1", "[red]q[/red]")}, says=("[red]q[/red]",)
    ),
    Case("header-escape", _cal(), {"d.csv": _rename_header("q1", "\x1b[31mq1")}, says=("\\x1b[31mq1",)),
    Case("header-bell", _cal(), {"d.csv": _rename_header("q1", "q\x07\x08")}, says=("d.csv",)),
    Case("cell-markup", _cal(), {"d.csv": _replace_cell(3, 2, "[/x]")}, says=("row 4", "'q3'", "[/x]")),
    Case(
        "cell-escape", _cal(), {"d.csv": _replace_cell(3, 2, "\x1b]0;pwned\x07")}, says=("row 4", "\\x1b]0;")
    ),
    Case("cell-backslash", _cal(), {"d.csv": _replace_cell(3, 2, "x\\")}, says=("row 4",)),
    Case("cell-nan", _cal(), {"d.csv": _replace_cell(2, 7, "nan")}, says=("row 3", "not finite")),
    Case("cell-inf", _cal(), {"d.csv": _replace_cell(2, 7, "-inf")}, says=("row 3", "not finite")),
    Case("cell-1e999", _cal(), {"d.csv": _replace_cell(2, 0, "1e999")}, says=("row 3", "not finite")),
    Case("cell-hex", _cal(), {"d.csv": _replace_cell(2, 0, "0x10")}, says=("row 3", "not a number")),
    Case("cell-empty", _cal(), {"d.csv": _replace_cell(2, 0, "")}, says=("row 3", "empty cell")),
    Case("cell-formula", _cal(), {"d.csv": _replace_cell(2, 0, "=1+2")}, says=("row 3", "'=1+2'")),
    Case("cell-huge-joint", _cal(), {"d.csv": _replace_cell(2, 0, "1e300")}, says=("d.csv", "q1")),
    Case("cell-huge-position", _cal(), {"d.csv": _replace_cell(2, 6, "1e300")}, says=("d.csv",)),
    Case(
        "sigma-zero",
        _cal(),
        {"d.csv": _replace_cell(2, 9, "0")},
        says=("row 3", "'sx'", "standard deviation"),
    ),
    Case("sigma-tiny", _cal(), {"d.csv": _replace_cell(2, 9, "1e-300")}, says=("row 3", "1e-300")),
    Case("sigma-huge", _cal(), {"d.csv": _replace_cell(2, 9, "1e300")}, says=("row 3", "1e300")),
    Case("sigma-negative", _cal(), {"d.csv": _replace_cell(2, 9, "-1e-5")}, says=("row 3", "negative")),
    Case("utf16-bom", _cal(), {"d.csv": lambda b: _csv_text(b).encode("utf-16")}, says=("d.csv", "UTF-16")),
    Case("utf16-no-bom", _cal(), {"d.csv": lambda b: _csv_text(b).encode("utf-16-le")}, says=("UTF-16",)),
    Case("utf32", _cal(), {"d.csv": lambda b: _csv_text(b).encode("utf-32")}, says=("d.csv", "UTF-8")),
    Case("latin1", _cal(), {"d.csv": lambda b: ("# é\n" + _csv_text(b)).encode("latin-1")}, says=("UTF-8",)),
    Case("binary", _cal(), {"d.csv": bytes(range(256)) * 4}, says=("d.csv",)),
    Case("nul-bytes", _cal(), {"d.csv": b"\x00" * 1000}, says=("d.csv",)),
    Case("empty", _cal(), {"d.csv": ""}, says=("d.csv", "no header row")),
    Case("bom-only", _cal(), {"d.csv": b"\xef\xbb\xbf"}, says=("d.csv", "no header row")),
    Case("only-newlines", _cal(), {"d.csv": "\n\n\n\r\n"}, says=("no header row",)),
    Case("header-only", _cal(), {"d.csv": lambda b: _body(b)[0] + "\n"}, says=("no data rows",)),
    Case("one-row", _cal(), {"d.csv": lambda b: "\n".join(_body(b)[:2]) + "\n"}, says=("d.csv",)),
    Case(
        "ragged",
        _cal(),
        {"d.csv": _with_body(lambda L: "\n".join(L[:3] + [L[3] + ",1"] + L[4:]))},
        says=("row 4", "cells"),
    ),
    Case(
        "unterminated-quote",
        _cal(),
        {"d.csv": _with_body(lambda L: "\n".join(L[:3] + ['"' + L[3]] + L[4:]))},
        says=("row 4",),
    ),
    Case(
        "duplicate-row",
        _cal(),
        {"d.csv": _with_body(lambda L: "\n".join(L + [L[1]]) + "\n")},
        says=("duplicates row 2",),
    ),
    Case(
        "all-rows-same",
        _cal(),
        {"d.csv": _with_body(lambda L: "\n".join([L[0]] + [L[1]] * 20) + "\n")},
        says=("d.csv",),
    ),
    Case(
        "excel-sep-line-bad",
        _cal(),
        {"d.csv": _with_body(lambda L: "sep=;\n" + "\n".join(L) + "\n")},
        says=("d.csv",),
    ),
    Case(
        "semicolon-comma-decimal",
        _cal(),
        {"d.csv": _with_body(lambda L: "\n".join(ln.replace(",", ";").replace(".", ",") for ln in L))},
        says=("decimal comma",),
    ),
    Case("wide-cell", _cal(), {"d.csv": _replace_cell(2, 0, "1" * 200_000)}, says=("row 3",)),
    Case(
        "many-columns",
        _cal(),
        {"d.csv": ",".join(f"c{i}" for i in range(50_000)) + "\n" + "1," * 49_999 + "1\n"},
        says=("d.csv", "columns)"),
    ),
    Case("columns-markup", _cal("--columns", "[/x]=q1"), {"d.csv": _csv_text}, says=("[/x]",)),
    Case("columns-escape", _cal("--columns", "q1=\x1b[2J"), {"d.csv": _csv_text}, says=("\\x1b[2J",)),
    Case("columns-garbage", _cal("--columns", "===,,,"), {"d.csv": _csv_text}, says=("columns",)),
    Case("directory", _cal(), {"d.csv/x": "x"}, says=("d.csv", "directory")),
    Case("missing", _cal(), {}, says=("d.csv", "does not exist")),
    Case("data-check-markup", CHECK, {"d.csv": _rename_header("q1", "[/x]")}, code=1, writes=()),
    Case("data-check-escape", CHECK, {"d.csv": _rename_header("q1", "\x1b[31m")}, code=1, writes=()),
]

# ------------------------------------------------------------------ YAML (model, geometry)
GOOD_MODEL = (
    "name: {name}\nchain:\n"
    "  - {{motion: Rz, param: t1, joint: q1}}\n"
    "  - {{motion: Tx, param: a1, value: 0.5}}\n"
)
SHOW = ("robots", "show", "{dir}/m.yaml")


def _deep(n: int) -> str:
    return "name: x\nnotes: " + "[" * n + "]" * n + "\n"


YAML_CASES = [
    Case("model-alias", SHOW, {"m.yaml": "name: &a x\ntitle: *a\nchain: []\n"}, says=("m.yaml", "aliases")),
    Case("model-deep", SHOW, {"m.yaml": _deep(5000)}, says=("m.yaml", "nested too deeply")),
    Case(
        "model-deep-map",
        SHOW,
        {"m.yaml": "name: x\nnotes: " + "{a: " * 3000 + "1" + "}" * 3000 + "\n"},
        says=("m.yaml",),
    ),
    Case("model-6mb", SHOW, {"m.yaml": "name: x\nnotes: '" + "x" * 6_000_000 + "'\n"}, says=("too large",)),
    Case(
        "model-many-entries",
        SHOW,
        {
            "m.yaml": "name: x\nchain:\n"
            + "".join(f"  - {{motion: Tx, param: p{i}}}\n" for i in range(60_000))
        },
        says=("m.yaml", "entries"),
    ),
    Case("model-tab", SHOW, {"m.yaml": "name: x\nchain:\n\t- 1\n"}, says=("m.yaml", "line 3")),
    Case(
        "model-dup-key", SHOW, {"m.yaml": GOOD_MODEL.format(name="x") + "name: y\n"}, says=("appears twice",)
    ),
    Case(
        "model-python-tag",
        SHOW,
        {"m.yaml": "name: !!python/object/apply:os.system ['echo hi']\n"},
        says=("m.yaml", "constructor"),
    ),
    Case("model-list", SHOW, {"m.yaml": "- 1\n- 2\n"}, says=("m.yaml", "mapping")),
    Case("model-scalar", SHOW, {"m.yaml": "42\n"}, says=("m.yaml", "mapping")),
    Case("model-empty", SHOW, {"m.yaml": ""}, says=("m.yaml", "mapping")),
    Case("model-nan", SHOW, {"m.yaml": GOOD_MODEL.format(name="x").replace("0.5", ".nan")}, says=("finite",)),
    Case(
        "model-inf", SHOW, {"m.yaml": GOOD_MODEL.format(name="x").replace("0.5", "-.inf")}, says=("finite",)
    ),
    Case("model-not-utf8", SHOW, {"m.yaml": "name: caf\xe9\n".encode("latin-1")}, says=("m.yaml", "UTF-8")),
    Case("model-utf16", SHOW, {"m.yaml": GOOD_MODEL.format(name="x").encode("utf-16")}, says=("m.yaml",)),
    Case(
        "model-unknown-field",
        SHOW,
        {"m.yaml": GOOD_MODEL.format(name="x") + "colour: red\n"},
        says=("colour",),
    ),
    Case("model-name-markup-error", SHOW, {"m.yaml": "name: '[/x]'\nchain: 5\n"}, says=("m.yaml",)),
    Case("model-fifo", SHOW, {}, says=("m.yaml", "not a regular file")),
    Case("model-directory", SHOW, {"m.yaml/x": "x"}, says=("m.yaml",)),
    Case("model-missing", SHOW, {}, says=("m.yaml", "does not exist")),
    Case(
        "geometry-zero-quaternion",
        ("model", "build", "{dir}/g.yaml", "-o", "{dir}/out"),
        {"g.yaml": lambda b: GEOMETRY.read_text().replace("rpy: [0, 90, 0]", "quaternion: [0, 0, 0, 0]")},
        says=("g.yaml", "quaternion", "norm"),
    ),
    Case(
        "geometry-quaternion-norm-2",
        ("model", "build", "{dir}/g.yaml", "-o", "{dir}/out"),
        {"g.yaml": lambda b: GEOMETRY.read_text().replace("rpy: [0, 90, 0]", "quaternion: [2, 0, 0, 0]")},
        says=("g.yaml", "norm 2"),
    ),
    Case(
        "geometry-nan-axis",
        ("model", "build", "{dir}/g.yaml", "-o", "{dir}/out"),
        {"g.yaml": lambda b: GEOMETRY.read_text().replace("axis: [0, 0, 1]", "axis: [.nan, 0, 1]", 1)},
        says=("g.yaml",),
    ),
    Case(
        "geometry-as-model",
        ("fk", "{dir}/g.yaml", "--q", "0,0,0,0,0,0"),
        {"g.yaml": lambda b: GEOMETRY.read_text()},
        says=("joint-geometry file",),
        writes=(),
    ),
    Case(
        "study-huge-robots",
        ("study", "{dir}/s.yaml", "--out", "{dir}/out"),
        {"s.yaml": "robots: 10000000000000000000000\n"},
        says=("s.yaml",),
    ),
    Case(
        "study-ten-million",
        ("study", "{dir}/s.yaml", "--out", "{dir}/out"),
        {"s.yaml": "robot: ur10\nrobots: 10000000\npose_sets: [{name: a, n: 30}]\n"},
        says=("s.yaml",),
    ),
    Case(
        "study-missing",
        ("study", "{dir}/s.yaml", "--out", "{dir}/out"),
        {},
        says=("s.yaml", "does not exist"),
    ),
]

# ------------------------------------------------------------------ URDF
BUILD = ("model", "build", "{dir}/r.urdf", "-o", "{dir}/out")


def _urdf(transform):
    return lambda b: transform(UR10_URDF.read_text())


def _fixed_chain(n: int) -> str:
    joints = "".join(
        f'<link name="f{i + 1}"/><joint name="fj{i}" type="fixed"><parent link="f{i}"/>'
        f'<child link="f{i + 1}"/></joint>'
        for i in range(n)
    )
    return f'<?xml version="1.0"?><robot name="x"><link name="f0"/>{joints}</robot>'


URDF_CASES = [
    Case(
        "urdf-mimic",
        BUILD,
        {
            "r.urdf": _urdf(
                lambda t: t.replace(
                    '<joint name="elbow_joint" type="revolute">',
                    '<joint name="elbow_joint" type="revolute">'
                    '<mimic joint="shoulder_lift_joint" multiplier="1"/>',
                )
            )
        },
        says=("r.urdf", "mimic"),
    ),
    Case("urdf-fixed-100k", BUILD, {"r.urdf": lambda b: _fixed_chain(100_000)}, says=("r.urdf", "joints")),
    Case(
        "urdf-big-comment",
        BUILD,
        {"r.urdf": _urdf(lambda t: t.replace("<robot", "<!--" + "x" * 19_000_000 + "--><robot", 1))},
        code=0,
    ),
    Case(
        "urdf-too-large",
        BUILD,
        {"r.urdf": _urdf(lambda t: t + " " * 21_000_000)},
        says=("r.urdf", "too large"),
    ),
    Case(
        "urdf-name-markup",
        BUILD,
        {"r.urdf": _urdf(lambda t: t.replace('"elbow_joint"', '"[/x]"'))},
        code=0,
        writes=(),
    ),
    Case(
        "urdf-nan-limit",
        BUILD,
        {"r.urdf": _urdf(lambda t: t.replace('lower="-6.2832"', 'lower="nan"', 1))},
        says=("r.urdf",),
    ),
    Case(
        "urdf-xxe",
        BUILD,
        {
            "r.urdf": '<?xml version="1.0"?><!DOCTYPE r [<!ENTITY x SYSTEM "file:///etc/passwd">]>'
            '<robot name="a">&x;</robot>'
        },
        says=("r.urdf", "DOCTYPE"),
    ),
    Case("urdf-empty", BUILD, {"r.urdf": ""}, says=("r.urdf",)),
    Case(
        "urdf-utf16", BUILD, {"r.urdf": _urdf(lambda t: t).__call__(None).encode("utf-16")}, says=("r.urdf",)
    ),
]

# ------------------------------------------------------------------ command-line options
FK = ("fk", "ur10", "--q")
OPTION_CASES = [
    Case("fk-nan", (*FK, "nan,0,0,0,0,0"), says=("--q", "finite"), writes=()),
    Case("fk-inf", (*FK, "0,inf,0,0,0,0"), says=("--q", "finite"), writes=()),
    Case("fk-huge", (*FK, "1e308,0,0,0,0,0"), code=0, writes=()),
    Case("fk-empty", (*FK, ""), says=("--q",), writes=()),
    Case("fk-markup", (*FK, "[/x]"), says=("--q", "[/x]"), writes=()),
    Case("fk-escape", (*FK, "\x1b[2J"), says=("\\x1b[2J",), writes=()),
    Case("fk-too-many", (*FK, "0," * 100 + "0"), says=("--q", "101 values"), writes=()),
    Case("fk-robot-markup", ("fk", "[/x]", "--q", "0"), says=("[/x]",), writes=()),
    Case("fk-robot-escape", ("fk", "\x1b[31mred", "--q", "0"), says=("\\x1b[31mred",), writes=()),
    Case("fk-robot-empty", ("fk", " ", "--q", "0"), says=("no robot given",), writes=()),
    Case("poses-n-huge", ("poses", "ur10", "--n", "100000000", "-o", "{dir}/out"), usage=True, says=("--n",)),
    Case("poses-n-zero", ("poses", "ur10", "--n", "0", "-o", "{dir}/out"), usage=True, says=("--n",)),
    Case(
        "poses-pool-huge",
        ("poses", "ur10", "--method", "optimal", "--pool", "1000000000", "-o", "{dir}/out"),
        usage=True,
        says=("--pool",),
    ),
    Case(
        "poses-seed-negative",
        ("poses", "ur10", "--seed", "-1", "-o", "{dir}/out"),
        usage=True,
        says=("--seed",),
    ),
    Case(
        "poses-region-nan",
        ("poses", "ur10", "--method", "iso9283", "--region", "nan,0,0,1,1,1", "-o", "{dir}/out"),
        says=("--region",),
    ),
    Case(
        "poses-markup-index",
        ("poses", "ur10", "--method", "optimal", "--index", "[/x]", "-o", "{dir}/out"),
        usage=True,  # a choice of robocal.choices: Typer's usage error names the option and the value
        says=("--index", "[/x]"),
    ),
    Case("calibrate-noise-zero", _cal("--noise", "0mm"), {"d.csv": _csv_text}, says=("--noise",)),
    Case("calibrate-noise-tiny", _cal("--noise", "1e-300mm"), {"d.csv": _csv_text}, says=("--noise",)),
    Case("calibrate-noise-huge", _cal("--noise", "1e300mm"), {"d.csv": _csv_text}, says=("--noise",)),
    Case("calibrate-noise-nan", _cal("--noise", "nanmm"), {"d.csv": _csv_text}, says=("--noise",)),
    Case("calibrate-noise-markup", _cal("--noise", "[/x]"), {"d.csv": _csv_text}, says=("[/x]",)),
    Case("calibrate-seed-negative", _cal("--seed", "-1"), {"d.csv": _csv_text}, usage=True, says=("--seed",)),
    Case("calibrate-tool-nan", _cal("--tool", "nan,0,0"), {"d.csv": _csv_text}, says=("--tool",)),
    Case("calibrate-tool-short", _cal("--tool", "1,2"), {"d.csv": _csv_text}, says=("--tool",)),
    Case("calibrate-train-n-zero", _cal("--train-n", "0"), {"d.csv": _csv_text}, says=("--train-n",)),
    Case("calibrate-train-n-huge", _cal("--train-n", "99999999"), {"d.csv": _csv_text}, says=("--train-n",)),
    Case(
        "calibrate-method-markup", _cal("--method", "[/x]"), {"d.csv": _csv_text}, usage=True, says=("[/x]",)
    ),
    Case(
        "calibrate-loss-markup",
        _cal("--loss", "[bold]x"),
        {"d.csv": _csv_text},
        usage=True,  # a choice of robocal.choices: Typer's usage error names the option and the value
        says=("--loss", "[bold]x"),
    ),
    Case(
        "calibrate-length-unit-markup",
        _cal("--length-unit", "[/x]"),
        {"d.csv": _csv_text},
        usage=True,  # a choice of robocal.choices: Typer's usage error names the option and the value
        says=("--length-unit", "[/x]"),
    ),
    Case("calibrate-sep-markup", _cal("--sep", "[/x]"), {"d.csv": _csv_text}, says=("[/x]",)),
    Case(
        "calibrate-out-is-file",
        (*CAL[:-4], "--out", "{dir}/d.csv", "--residual", "none"),
        {"d.csv": _csv_text},
        says=("is a file",),
    ),
    Case(
        "calibrate-model-markup-path",
        ("calibrate", "{dir}/[/x].yaml", "--data", "{dir}/d.csv", "--out", "{dir}/out"),
        {"d.csv": _csv_text},
        says=("[/x].yaml",),
    ),
    Case(
        "simulate-length-tol",
        ("simulate", "ur10", "--poses", "{base}/meas.csv", "--length-tol", "1e300mm", "-o", "{dir}/out.csv"),
        says=("--length-tol",),
        writes=("out.csv",),
    ),
    Case(
        "simulate-angle-tol",
        ("simulate", "ur10", "--poses", "{base}/meas.csv", "--angle-tol", "1e300deg", "-o", "{dir}/out.csv"),
        says=("--angle-tol",),
        writes=("out.csv",),
    ),
    Case(
        "simulate-tol-huge",
        ("simulate", "ur10", "--poses", "{base}/meas.csv", "--tol", "d1=1e300mm", "-o", "{dir}/out.csv"),
        says=("not finite",),
        writes=("out.csv",),
    ),
    Case(
        "simulate-noise-huge",
        ("simulate", "ur10", "--poses", "{base}/meas.csv", "--noise", "1e300mm", "-o", "{dir}/out.csv"),
        says=("--noise",),
        writes=("out.csv",),
    ),
    Case(
        "simulate-seed-negative",
        ("simulate", "ur10", "--poses", "{base}/meas.csv", "--seed", "-1", "-o", "{dir}/out.csv"),
        usage=True,
        says=("--seed",),
        writes=("out.csv",),
    ),
    Case("demo-seed-negative", ("demo", "--seed", "-3", "--out", "{dir}/out"), usage=True, says=("--seed",)),
    Case(
        "demo-poses-huge",
        ("demo", "--n", "100000000", "--out", "{dir}/out"),
        usage=True,
        says=("--n",),
    ),
    Case(
        "usage-choice-markup",
        ("poses", "ur10", "--method", "[/x]", "-o", "{dir}/out"),
        usage=True,
        says=("[/x]",),
    ),
    Case("usage-option-markup", ("poses", "ur10", "--[/x]"), usage=True, says=("--[/x]",)),
    Case("usage-command-markup", ("[/x]",), usage=True, says=("[/x]",)),
    Case("stdin-data", (*CAL[:3], "/dev/stdin", *CAL[4:]), says=("/dev/stdin", "not a regular file")),
    Case("fifo-data", _cal(), {}, says=("d.csv", "not a regular file")),
]

# ------------------------------------------------------------------ result folders
VALIDATE = ("validate", "{dir}/res", "--data", "{base}/meas.csv")
REPORT = ("report", "{dir}/res", "-o", "{dir}/out.html")
COMPENSATE = ("compensate", "{dir}/res", "--targets", "{base}/meas.csv", "-o", "{dir}/out.csv")
EXPORT = ("export", "ur-kinematics", "{dir}/res", "-o", "{dir}/out.yaml")
READERS = {"validate": VALIDATE, "report": REPORT, "compensate": COMPENSATE, "export": EXPORT}


def _result(transform):
    """A copy of the fixture's calibration with result.json transformed (text -> text)."""

    def make(base: Path) -> str:
        return transform((base / "cal" / "result.json").read_text())

    return make


def _model(base: Path) -> str:
    return (base / "cal" / "model.yaml").read_text()


def _json_edit(edit):
    def transform(text: str) -> str:
        data = json.loads(text)
        edit(data)
        return json.dumps(data)

    return transform


FOLDERS = {
    "list": ({"res/result.json": "[]", "res/model.yaml": _model}, ("not a calibration result", "list")),
    "null": ({"res/result.json": "null", "res/model.yaml": _model}, ("not a calibration result",)),
    "empty-object": ({"res/result.json": "{}", "res/model.yaml": _model}, ("result.json",)),
    "not-json": ({"res/result.json": "{oops", "res/model.yaml": _model}, ("not valid JSON", "line 1")),
    "truncated": (
        {"res/result.json": _result(lambda t: t[: len(t) // 2]), "res/model.yaml": _model},
        ("not valid JSON",),
    ),
    "utf16": (
        {
            "res/result.json": lambda b: (b / "cal" / "result.json").read_text().encode("utf-16"),
            "res/model.yaml": _model,
        },
        ("result.json",),
    ),
    "deep": ({"res/result.json": "[" * 100_000 + "]" * 100_000, "res/model.yaml": _model}, ("result.json",)),
    "parameters-not-list": (
        {"res/result.json": _result(_json_edit(lambda d: d.update(parameters=5))), "res/model.yaml": _model},
        ("result.json",),
    ),
    "covariance-shape": (
        {
            "res/result.json": _result(_json_edit(lambda d: d.update(covariance=[[1.0]]))),
            "res/model.yaml": _model,
        },
        ("result.json",),
    ),
    "no-model": ({"res/result.json": _result(lambda t: t)}, ("model.yaml",)),
    "mixed-runs": (
        {
            "res/result.json": _result(_json_edit(lambda d: d.update(run_id="0" * 32))),
            "res/model.yaml": _model,
        },
        ("different runs", "model.yaml"),
    ),
    "model-without-run": (
        {
            "res/result.json": _result(lambda t: t),
            "res/model.yaml": lambda b: "\n".join(
                ln for ln in _model(b).splitlines() if not ln.startswith("# robocal run")
            ),
        },
        ("different runs", "model.yaml (run none)"),
    ),
}
FOLDER_CASES = [
    Case(f"{reader}-{name}", args, files, says=says, writes=("out.html", "out.csv", "out.yaml"))
    for name, (files, says) in FOLDERS.items()
    for reader, args in READERS.items()
    if reader in ("validate", "report", "compensate") or name in ("list", "mixed-runs")
]
FOLDER_CASES += [
    Case(
        "report-evaluation-not-json",
        REPORT,
        {"res/result.json": _result(lambda t: t), "res/model.yaml": _model, "res/evaluation.json": "{x"},
        says=("evaluation.json", "not valid JSON"),
        writes=("out.html",),
    ),
    Case(
        "report-evaluation-list",
        REPORT,
        {"res/result.json": _result(lambda t: t), "res/model.yaml": _model, "res/evaluation.json": "[1]"},
        says=("evaluation.json",),
        writes=("out.html",),
    ),
    Case(
        "report-evaluation-utf16",
        REPORT,
        {
            "res/result.json": _result(lambda t: t),
            "res/model.yaml": _model,
            "res/evaluation.json": "{}".encode("utf-16"),
        },
        says=("evaluation.json",),
        writes=("out.html",),
    ),
    Case("validate-no-folder", VALIDATE, {}, says=("res", "no calibration result"), writes=()),
    Case(
        "validate-result-dir",
        VALIDATE,
        {"res/result.json/x": "x", "res/model.yaml": _model},
        says=("res",),
        writes=(),
    ),
]

ALL_CASES = CSV_CASES + YAML_CASES + URDF_CASES + OPTION_CASES + FOLDER_CASES


def test_there_are_more_than_a_hundred_cases():
    assert len(ALL_CASES) >= 100
    assert len({c.id for c in ALL_CASES}) == len(ALL_CASES)


@pytest.mark.parametrize("case", ALL_CASES, ids=lambda c: c.id)
def test_hostile_input_ends_in_one_line(case, base, tmp_path):
    if "fifo" in case.id:
        os.mkfifo(tmp_path / ("m.yaml" if case.id.startswith("model") else "d.csv"))
    _run(case, base, tmp_path)


# ------------------------------------------------------------------ printed as written
@pytest.mark.parametrize(
    ("name", "shown"),
    [("[/x]", "[/x]"), ("[red]arm[/red]", "[red]arm[/red]"), ("a\x1b[2Jb", "a\\x1b[2Jb"), ("x\\", "x\\")],
)
def test_names_with_markup_or_escapes_are_printed_as_written(tmp_path, name, shown):
    path = tmp_path / "m.yaml"
    path.write_text(GOOD_MODEL.format(name=json.dumps(name)))
    for args in (["robots", "show", str(path)], ["fk", str(path), "--q", "0"]):
        result = CliRunner().invoke(app, args)
        assert result.exit_code == 0, result.output
        assert shown in result.output and "\x1b[2J" not in result.output


def test_a_file_name_with_markup_is_printed_as_written(base, tmp_path):
    folder = tmp_path / "a[" / "x]"  # the path holds "[/x]"
    folder.mkdir(parents=True)
    shutil.copy(base / "meas.csv", folder / "[red].csv")
    out = tmp_path / "c[/y][red]"
    result = CliRunner().invoke(
        app, [*CAL[:3], str(folder / "[red].csv"), "--out", str(out), "--residual", "none"]
    )
    assert result.exit_code == 0, result.output
    assert f"wrote {out} (model.yaml" in result.output.replace("\n", ""), result.output
    args = ["validate", str(out), "--data", str(folder / "[red].csv"), "--all-rows"]
    result = CliRunner().invoke(app, args)
    assert result.exit_code == 0 and "[red].csv" in result.output, result.output


def test_an_unexpected_exception_is_one_line_and_a_traceback_file(monkeypatch, tmp_path):
    import robocal.cli.robots as cli

    def boom(*args, **kwargs):
        raise ZeroDivisionError("[/x] \x1b[31m")

    monkeypatch.setattr(cli, "resolve_model", boom)
    monkeypatch.setenv("TMPDIR", str(tmp_path))
    import tempfile

    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    result = CliRunner().invoke(app, ["fk", "ur10", "--q", "0"])
    assert result.exit_code == 1
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(
        "error: internal error (ZeroDivisionError: [/x] \\x1b[31m)"
    )
    written = list(tmp_path.glob("robocal-traceback-*.txt"))
    assert len(written) == 1 and str(written[0]) in lines[0]
    assert "Traceback" in written[0].read_text() and "boom" in written[0].read_text()


# ------------------------------------------------------------------ CSV formula cells
def test_formula_cells_are_neutralised_in_csv_outputs(tmp_path):
    from robocal.safe_output import csv_text, csv_untext

    for cell, written in [
        ('=HYPERLINK("x")', '\'=HYPERLINK("x")'),
        ("+cmd|' /C calc'!A0", "'+cmd|' /C calc'!A0"),
        ("@SUM(A1)", "'@SUM(A1)"),
        ("-2+3", "'-2+3"),
        ("\tx", "'\tx"),
        ("\rx", "'\rx"),
        ("-0.5", "-0.5"),
        ("+1e3", "+1e3"),
        ("P1", "P1"),
        ("", ""),
    ]:
        assert csv_text(cell) == written
        assert csv_untext(csv_text(cell)) == cell


def test_compensate_csv_neutralises_target_names(base, tmp_path):
    targets = tmp_path / "targets.csv"
    targets.write_text(
        'name,x,y,z\n=HYPERLINK("http://x"),0.6,0.2,0.5\n@SUM(A1),0.5,0.1,0.6\nP3,0.55,0.15,0.55\n'
    )
    out = tmp_path / "out.csv"
    result = CliRunner().invoke(
        app, ["compensate", str(base / "cal"), "--targets", str(targets), "--frame", "base", "-o", str(out)]
    )
    assert result.exit_code in (0, 1), result.output
    names = [line.split(",")[0] for line in out.read_text().splitlines()[1:]]
    assert names[0].startswith("\"'=HYPERLINK") and names[1] == "'@SUM(A1)" and names[2] == "P3", names


# ------------------------------------------------------------------ disk full, permissions
def test_a_full_disk_leaves_the_earlier_result_and_one_line(base, tmp_path, monkeypatch):
    import sys

    calibrate_module = sys.modules["robocal.identify.result_io"]  # writes result.json

    out = tmp_path / "cal"
    shutil.copytree(base / "cal", out)
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    real = calibrate_module.atomic_write_text

    def full(path, text):
        if Path(path).name == "result.json":
            raise OSError(errno.ENOSPC, "No space left on device", str(path))
        return real(path, text)

    monkeypatch.setattr(calibrate_module, "atomic_write_text", full)
    result = CliRunner().invoke(
        app, [*CAL[:3], str(base / "meas.csv"), "--out", str(out), "--residual", "none", "--force"]
    )
    assert result.exit_code == 2, result.output
    errors = [ln for ln in result.stderr.splitlines() if ln.startswith("error:")]
    assert len(errors) == 1 and "result.json: the disk is full" in errors[0], result.stderr
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cal"]  # no staging directory left


def test_a_full_disk_on_a_single_file_names_it(base, tmp_path, monkeypatch):
    import robocal.model.files as files

    def full(fd, mode):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(files.os, "fdopen", full)
    out = tmp_path / "p.csv"
    result = CliRunner().invoke(app, ["poses", "ur10", "-o", str(out)])
    assert result.exit_code == 2, result.output
    assert (
        result.stderr.strip() == f"error: {out}: the disk is full: free space or write elsewhere, then run "
        "again (nothing was half-written)"
    )
    assert list(tmp_path.iterdir()) == []


def test_an_unwritable_folder_is_one_line(base, tmp_path, monkeypatch):
    import robocal.outdir as outdir

    def denied(path, *args, **kwargs):
        raise PermissionError(errno.EACCES, "Permission denied", str(path))

    monkeypatch.setattr(outdir.os, "mkdir", denied)
    result = CliRunner().invoke(
        app, [*CAL[:3], str(base / "meas.csv"), "--out", str(tmp_path / "c"), "--residual", "none"]
    )
    assert result.exit_code == 2
    assert "permission denied" in result.stderr and result.stderr.count("\n") == 1, result.stderr


# ------------------------------------------------------------------ session 6: readers and writers
def _one_error_line(result) -> str:
    assert "Traceback" not in result.output, result.output
    assert result.exception is None or isinstance(result.exception, SystemExit), repr(result.exception)
    errors = [ln for ln in result.stderr.splitlines() if ln.startswith("error:")]
    assert len(errors) == 1 and result.stderr.rstrip("\n").endswith(errors[0]), result.stderr
    return errors[0]


def _many_chunks(base: Path, where: Path, bad: dict[int, tuple[int, str]]) -> tuple[Path, list[str]]:
    """meas.csv's rows repeated (each shifted, so no two are equal) until the file spans
    several of the reader's chunks, with ``bad`` cells (data row -> (column, text))."""
    from robocal import csvfile

    lines = _body(base)
    header, rows = lines[0], [ln.split(",") for ln in lines[1:]]
    out = [header]
    k = 0
    while sum(map(len, out)) < 3 * csvfile.CHUNK_BYTES:
        for cells in rows:
            shifted = [repr(float(c) + 1e-9 * k) if j < 6 else c for j, c in enumerate(cells)]
            out.append(",".join(shifted))
            k += 1
    for row, (col, text) in bad.items():
        cells = out[row].split(",")
        cells[col] = text
        out[row] = ",".join(cells)
    path = where / "d.csv"
    path.write_text("\n".join(out) + "\n")
    return path, out


def test_a_large_file_with_bad_cells_in_several_columns_names_each(base, tmp_path):
    """Bad cells in several columns and in several chunks: every one is found (not only the
    first of each column), the first named in the one error line; with --incomplete drop
    exactly those rows are left out."""
    from robocal import csvfile
    from robocal.measure.dataset.read import check_measurements, read_measurements

    bad = {5: (2, "abc"), 900: (7, ""), 2500: (0, "nan"), 2501: (4, "x"), 4000: (8, "1;5")}
    path, lines = _many_chunks(base, tmp_path, bad)
    assert path.stat().st_size > 2 * csvfile.CHUNK_BYTES
    found = [
        (p.row, p.column, p.code) for p in check_measurements(path, robot("ur10")) if p.severity == "error"
    ]
    assert found == [
        (6, "q3", "not-a-number"),
        (901, "y", "empty"),
        (2501, "q1", "not-finite"),
        (2502, "q5", "not-a-number"),
        (4001, "z", "not-a-number"),
    ]
    with time_limit():
        result = CliRunner().invoke(
            app, [*CAL[:3], str(path), "--out", str(tmp_path / "out"), "--residual", "none"]
        )
    assert result.exit_code == 2
    line = _one_error_line(result)
    assert f"{path}: row 2501, column 'q1': value 'nan' is not finite" in line, line
    assert "and 4 more problem(s)" in line, line
    assert not (tmp_path / "out").exists()
    with pytest.warns(UserWarning, match="5 warning"):
        data = read_measurements(path, model=robot("ur10"), incomplete="drop")
    assert data.n == len(lines) - 1 - len(bad) and data.metadata["rows_left_out"] == "5"


def test_a_large_file_with_ragged_rows_and_incomplete_drop(base, tmp_path):
    from robocal.measure.dataset.read import read_measurements

    path, lines = _many_chunks(base, tmp_path, {})
    text = path.read_text().splitlines()
    text[10] += ",1.0"  # a row with a cell too many
    text[3000] = ",".join(text[3000].split(",")[:4])  # a row cut short
    path.write_text("\n".join(text) + "\n")
    result = CliRunner().invoke(
        app, [*CAL[:3], str(path), "--out", str(tmp_path / "out"), "--residual", "none"]
    )
    assert result.exit_code == 2
    width = len(lines[0].split(","))
    assert f"{path}: row 11: has {width + 1} cells but the header has {width}" in _one_error_line(result)
    with pytest.warns(UserWarning, match="2 warning"):
        data = read_measurements(path, model=robot("ur10"), incomplete="drop")
    assert data.n == len(lines) - 3


def test_a_million_bad_cells_are_counted_not_listed(tmp_path):
    """Problems beyond the first 1000 of a kind cost one line, not one object each."""
    from robocal.measure.dataset.columns import MAX_LISTED
    from robocal.measure.dataset.read import check_measurements, read_measurements

    path = tmp_path / "d.csv"
    path.write_text("q1,q2\n" + "x,1\n" * 5000 + "1,2\n")
    problems = check_measurements(path, dof=2)
    assert len(problems) == MAX_LISTED + 1
    summary = [p for p in problems if p.row is None]
    assert len(summary) == 1 and summary[0].message.startswith("and 4000 more row(s)"), summary
    assert summary[0].column == "q1" and summary[0].severity == "error"
    with pytest.warns(UserWarning):
        data = read_measurements(path, dof=2, incomplete="drop")
    assert data.n == 1 and data.metadata["rows_left_out"] == "5000"


MEMORY_CASES = [
    pytest.param("pose+sigma+set", "drop", 20_000, id="pose-drop-20k"),
    *(
        pytest.param(kind, incomplete, 100_000, id=f"{kind}-{incomplete}-100k", marks=pytest.mark.slow)
        for kind in ("position", "pose+sigma+set")
        for incomplete in ("error", "drop")
    ),
]


@pytest.mark.parametrize(("kind", "incomplete", "n"), MEMORY_CASES)
def test_reading_memory_is_bounded_by_the_numbers(tmp_path, kind, incomplete, n):
    """Peak memory (tracemalloc) of reading a file with bad cells, in each combination of
    options that changes the path taken, is at most 3x its numbers (as float64, or the
    arrays returned when larger: rotation matrices for quaternions)."""
    import io
    import tracemalloc
    import warnings

    from robocal.measure.dataset.read import read_measurements

    rng = np.random.default_rng(0)
    cols = {f"q{j + 1}": rng.uniform(-3, 3, n) for j in range(6)}
    cols.update(x=rng.uniform(-1, 1, n), y=rng.uniform(-1, 1, n), z=rng.uniform(-1, 1, n))
    if kind != "position":
        quat = rng.normal(size=(n, 4))
        quat /= np.linalg.norm(quat, axis=1, keepdims=True)
        cols.update(qw=quat[:, 0], qx=quat[:, 1], qy=quat[:, 2], qz=quat[:, 3])
        cols.update(sx=np.full(n, 1e-5), sy=np.full(n, 1e-5), sz=np.full(n, 1e-5))
    table = np.column_stack(list(cols.values()))
    buf = io.StringIO()
    np.savetxt(buf, table, fmt="%.17g", delimiter=",")
    lines = buf.getvalue().splitlines()
    if kind != "position":
        lines = [ln + (",train" if i % 2 else ",test") for i, ln in enumerate(lines)]
    for i in range(7, n, 5000):  # a bad cell now and then, in changing columns
        cells = lines[i].split(",")
        cells[i % 9] = "" if i % 2 else "bad"
        lines[i] = ",".join(cells)
    header = ",".join(cols) + (",set" if kind != "position" else "")
    path = tmp_path / "d.csv"
    path.write_text(header + "\n" + "\n".join(lines) + "\n")
    del lines, table
    # pandas, the fast path's reader, is imported once per process: ~25 MB traced whatever
    # the file's size, not reading memory (numpy.loadtxt, without it, reads 2.5x slower)
    import pandas  # noqa: F401

    tracemalloc.start()
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            try:
                data = read_measurements(path, dof=6, incomplete=incomplete)
            except ValueError:
                data = None
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    width = len(cols)
    numbers = n * width * 8  # the file's numbers as float64
    assert (data is None) == (incomplete == "error")
    if data is not None:
        kept = [a for a in (data.q, data.position, data.orientation, data.sigma) if a is not None]
        assert data.n == n - len(range(7, n, 5000))
        numbers = max(numbers, sum(a.nbytes for a in kept))
    print(f"{kind} {incomplete}: peak {peak / 1e6:.2f} MB for {numbers / 1e6:.2f} MB, {peak / numbers:.2f}x")
    assert peak <= 3 * numbers, f"peak {peak / 1e6:.1f} MB for {numbers / 1e6:.1f} MB of numbers"


def _krl_pair(tmp_path: Path) -> Path:
    examples = Path(__file__).resolve().parents[1] / "examples" / "programs"
    folder = tmp_path / "in"
    folder.mkdir()
    for name in ("pick.src", "pick.dat", "$config.dat"):
        (folder / name).write_bytes((examples / name).read_bytes())
    return folder / "pick.src"


def test_krl_pair_killed_between_its_renames_is_refused(tmp_path):
    """kill -9 between the .dat's and the .src's rename (the test hook): the new .dat beside
    the earlier .src is refused by the next reader, naming both files; filtering again repairs."""
    import subprocess
    import sys
    import textwrap

    import robocal as rc
    from robocal.compensate.programs.filter_file import filter_program_file
    from robocal.compensate.programs.krl import krl_run_id

    program = _krl_pair(tmp_path)
    out = tmp_path / "out" / "pick.src"
    filter_program_file(program, rc.robot("kr16"), out)
    before = out.read_text(encoding="latin-1")
    script = textwrap.dedent(
        f"""
        import robocal as rc
        from robocal.compensate.programs.filter_file import filter_program_file
        filter_program_file({str(program)!r}, rc.robot("kr16"), {str(out)!r})
        """
    )
    env = dict(os.environ, ROBOCAL_TEST_KILL_AT="set-renaming")
    proc = subprocess.run([sys.executable, "-c", script], env=env, capture_output=True, timeout=120)
    assert proc.returncode == -9, proc.stderr.decode()
    assert out.read_text(encoding="latin-1") == before  # the .src was not renamed yet ...
    dat = out.with_suffix(".dat").read_text(encoding="latin-1")
    assert krl_run_id(dat) != krl_run_id(before)  # ... the .dat was
    rc.save_model(rc.robot("kr16"), tmp_path / "kr16.yaml")
    result = CliRunner().invoke(
        app,
        ["filter", str(tmp_path / "kr16.yaml"), str(out), "-o", str(tmp_path / "again.src")],
    )
    assert result.exit_code == 2, result.output
    line = _one_error_line(result)
    assert str(out) in line and str(out.with_suffix(".dat")) in line and "not written together" in line, line
    assert not (tmp_path / "again.src").exists()
    filter_program_file(program, rc.robot("kr16"), out)  # writing again repairs the pair
    assert krl_run_id(out.read_text(encoding="latin-1")) == krl_run_id(
        out.with_suffix(".dat").read_text(encoding="latin-1")
    )
    assert not [p for p in out.parent.iterdir() if p.name.endswith(".tmp")]  # leftovers removed


@pytest.fixture(scope="module")
def iso_log(tmp_path_factory) -> Path:
    """A simulated ISO 9283 log of a UR10 and its truth, written by ``robocal simulate --log``."""
    log = tmp_path_factory.mktemp("iso") / "iso.csv"
    result = CliRunner().invoke(app, ["simulate", "ur10", "--log", "-o", str(log), "--seed", "1"])
    assert result.exit_code == 0, result.output
    return log


@pytest.mark.parametrize("first", [pytest.param(True, marks=pytest.mark.slow), False])
def test_a_full_disk_during_simulate_log_writes_neither_file(tmp_path, monkeypatch, first, iso_log):
    """ENOSPC on the truth's rename: the log is not left without (or beside another) truth."""
    from robocal.evaluate.iso9283.log import load_log_truth

    log = tmp_path / "iso.csv"
    if not first:
        for name in ("iso.csv", "iso.truth.yaml"):
            shutil.copy(iso_log.with_name(name), tmp_path / name)
    before = {p.name: p.read_bytes() for p in tmp_path.iterdir()}
    real = os.replace

    def replace(src, dst, *args, **kwargs):
        if Path(dst).name == "iso.truth.yaml":
            raise OSError(errno.ENOSPC, "No space left on device", str(dst))
        return real(src, dst, *args, **kwargs)

    monkeypatch.setattr(os, "replace", replace)
    with time_limit(60):
        result = CliRunner().invoke(
            app, ["simulate", "ur10", "--log", "-o", str(log), "--seed", "2", "--force"]
        )
    monkeypatch.undo()
    assert result.exit_code == 2, result.output
    assert "iso.truth.yaml: the disk is full" in _one_error_line(result)
    assert {p.name: p.read_bytes() for p in tmp_path.iterdir()} == before  # the earlier pair, or nothing
    if not first:
        assert load_log_truth(log)  # still one run


def test_simulated_log_and_truth_carry_one_run_id_and_a_mix_is_refused(tmp_path, iso_log):
    from robocal.evaluate.iso9283.log import Iso9283LogError, load_log_truth, read_iso9283_log
    from robocal.run_ids import new_run_id, read_run_id, run_id_line

    truth = iso_log.with_name("iso.truth.yaml")
    assert read_run_id(iso_log) == read_run_id(truth) is not None
    assert "robocal run" not in read_iso9283_log(iso_log).conditions
    assert load_log_truth(iso_log)["AD_mm_expected"] >= 0
    log = tmp_path / "iso.csv"
    shutil.copy(iso_log, log)
    other = truth.read_text().replace(run_id_line(read_run_id(truth)), run_id_line(new_run_id()))
    (tmp_path / "iso.truth.yaml").write_text(other)  # the truth of another simulation run
    with pytest.raises(Iso9283LogError, match=r"iso\.truth\.yaml.*iso\.csv is run.*different simulations"):
        load_log_truth(log)


def test_a_short_row_before_the_set_column_and_a_long_label(tmp_path):
    """A row cut short before the ``set`` column is ragged (left out by drop), and a label
    longer than 'train' is not cut to it ('trainee' is refused, not read as 'train')."""
    import warnings

    from robocal.measure.dataset.read import read_measurements
    from robocal.measure.measurements import MeasurementFileError

    path = tmp_path / "d.csv"
    path.write_text("q1,q2,set\n1,2,train\n3\n4,5,test\n")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        data = read_measurements(path, dof=2, incomplete="drop")
    assert data.n == 2 and data.split.tolist() == ["train", "test"]
    path.write_text("q1,q2,set\n1,2,train\n4,5,trainee\n")
    with pytest.raises(
        MeasurementFileError, match=r"row 3, column 'set': 'trainee' is not a train/test label"
    ):
        read_measurements(path, dof=2)
