"""Issue 33: ``robocal data sockets``: ball-in-socket recordings as MUKCa writes them (a
placement folder of headerless ``hole_<k>.csv`` joint-angle files) -> the constraint CSV.

The real Panda's ``front`` placement goes through the three documented commands (model build,
data sockets, calibrate) and lands on the benchmark's default fit; hostile inputs are refused
with one line naming the file, row and column, a non-zero exit and nothing written."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from robocal.cli.app import app
from robocal.identify.constraints.figures import pooled_spread
from robocal.identify.constraints.fit import calibrate_constraints, constraint_figures
from robocal.identify.constraints.model import NominalPrior
from robocal.identify.options import Pruning
from robocal.measure.constraints.data import ConstraintFileError, read_constraints
from robocal.measure.constraints.data_set import ConstraintSet
from robocal.measure.constraints.sockets_import import read_socket_recordings
from robocal.model.files import load_model

PANDA = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "ball_in_socket"
needs_panda = pytest.mark.skipif(not PANDA.is_dir(), reason="the ball-in-socket recordings are not here")
RNG = np.random.default_rng(33)


def _run(*args: object):
    return CliRunner().invoke(app, [str(a) for a in args])


def _recording(path: Path, rows: int = 5, dof: int = 6) -> np.ndarray:
    q = RNG.uniform(-2.0, 2.0, size=(rows, dof))
    np.savetxt(path, q, delimiter=",")
    return q


def _placement(folder: Path, sockets: int = 2, dof: int = 6) -> list[np.ndarray]:
    folder.mkdir(parents=True, exist_ok=True)
    q = [_recording(folder / f"hole_{k}.csv", rows=4 + k, dof=dof) for k in range(sockets)]
    for k in range(sockets):  # the controller's pose estimate: 7 columns, not joint angles
        np.savetxt(folder / f"hole_{k}_pose.csv", RNG.normal(size=(4 + k, 7)), delimiter=",")
    return q


def _spread_mm(model, data: ConstraintSet) -> float:
    return pooled_spread(constraint_figures(model, data), data) * 1e3


# ------------------------------------------------------------------ the real Panda
@needs_panda
def test_panda_front_through_the_three_commands_is_the_benchmarks_default_fit(tmp_path):
    urdf = PANDA / "urdf" / "panda.urdf"
    built = _run("model", "build", urdf, "--tip", "ball_link", "--measure", "position", "-o",
                 tmp_path / "panda.yaml")  # fmt: skip
    assert built.exit_code == 0, built.output
    front = PANDA / "panda_1" / "front"
    out = tmp_path / "front.csv"
    converted = _run("data", "sockets", front, "-o", out)
    assert converted.exit_code == 0, converted.output
    assert "--distance 0,1=50mm" in converted.output  # the next command is shown

    # the file holds the recordings bit for bit, point 0 = hole_0, point 1 = hole_1
    holes = [np.loadtxt(front / f"hole_{k}.csv", delimiter=",") for k in (0, 1)]
    data = read_constraints(out, 7, distances=[(0, 1, 0.05)], sigma=1e-4)
    assert np.array_equal(data.q, np.vstack(holes))
    assert np.array_equal(data.point, np.repeat([0, 1], [len(h) for h in holes]))

    cal = tmp_path / "cal"
    fit = _run("calibrate", tmp_path / "panda.yaml", "--data", out, "--distance", "0,1=50mm", "-o", cal)
    assert fit.exit_code == 0, fit.output
    assert json.loads((cal / "constraints.json").read_text())["prior"] is not None
    model = load_model(tmp_path / "panda.yaml")
    # benchmarks/bench_ball_in_socket.py's default ("complete + prior") on the same placement
    bench = calibrate_constraints(model, data, pruning=Pruning(), prior=NominalPrior())
    cli_spread = _spread_mm(load_model(cal / "model.yaml"), data)
    assert cli_spread == pytest.approx(_spread_mm(bench.model, data), abs=1e-3)
    assert 0.15 < cli_spread < 0.4  # in-sample: 0.25-0.33 mm; the nominal URDF spreads 8-11 mm
    assert _spread_mm(model, data) > 5.0


# ------------------------------------------------------------------ layouts
def test_folder_reads_holes_in_numeric_order_and_ignores_pose_files(tmp_path):
    q = _placement(tmp_path / "p", sockets=11)  # hole_10 is point 10, not point 2
    recording = read_socket_recordings([tmp_path / "p"])
    assert [s.name for s in recording.sources] == [f"hole_{k}.csv" for k in range(11)]
    assert np.allclose(recording.data.q, np.vstack(q), rtol=0, atol=0)
    assert recording.rows_per_point == tuple(4 + k for k in range(11))


def test_files_in_the_order_given_are_points_0_1(tmp_path):
    a, b = _recording(tmp_path / "a.csv", rows=3), _recording(tmp_path / "b.csv", rows=6)
    out = tmp_path / "out.csv"
    run = _run("data", "sockets", tmp_path / "b.csv", tmp_path / "a.csv", "-o", out)
    assert run.exit_code == 0, run.output
    data = read_constraints(out, 6)
    assert np.array_equal(data.q, np.vstack([b, a]))
    assert np.array_equal(data.point, [0] * 6 + [1] * 3)


def test_degrees_are_converted_with_deg(tmp_path):
    q = RNG.uniform(-170.0, 170.0, size=(4, 6))
    np.savetxt(tmp_path / "hole_0.csv", q, delimiter=",")
    np.savetxt(tmp_path / "hole_1.csv", q[::-1], delimiter=",")
    plain = _run("data", "sockets", tmp_path, "-o", tmp_path / "rad.csv")
    assert plain.exit_code != 0 and "--deg" in plain.output  # degrees read as rad: refused
    assert not (tmp_path / "rad.csv").exists()
    run = _run("data", "sockets", tmp_path, "-o", tmp_path / "out.csv", "--deg")
    assert run.exit_code == 0, run.output
    assert np.allclose(read_constraints(tmp_path / "out.csv", 6).q[:4], np.radians(q), atol=1e-15)


# ------------------------------------------------------------------ hostile inputs
def _refused(tmp_path: Path, *paths: Path, expect: tuple[str, ...] = ()) -> str:
    out = tmp_path / "out.csv"
    run = _run("data", "sockets", *paths, "-o", out)
    assert run.exit_code != 0
    assert "Traceback" not in run.output and run.output.lower().startswith("error:")
    assert len(run.output.strip().splitlines()) <= 3  # one line (wrapped at most)
    assert not out.exists()
    flat = " ".join(run.output.split())
    for word in expect:
        assert word in flat, run.output
    return flat


@pytest.mark.parametrize(
    ("text", "where"),
    [
        ("0.1,0.2,0.3\n0.1,abc,0.3\n", ("row 2", "column 2")),
        ("0.1,0.2,0.3\n0.1,0.2,nan\n", ("row 2", "column 3")),
        ("0.1,0.2,0.3\n0.1,0.2,inf\n", ("row 2", "column 3")),
        ("0.1,0.2,0.3\n\n0.1,0.2\n", ("row 3",)),  # a row with fewer joints (line 3 of the file)
        ("0.1,0.2,0.3\n0.1,0.2,0.3,0.4\n", ("row 2",)),
        ("q1,q2,q3\n0.1,0.2,0.3\n", ("row 1", "column 1")),  # a header is not a configuration
        ("", ()),
        ("\n\n", ()),
    ],
)
def test_bad_cells_are_refused_naming_file_row_and_column(tmp_path, text, where):
    _recording(tmp_path / "hole_0.csv", dof=3)
    (tmp_path / "hole_1.csv").write_text(text)
    _refused(tmp_path, tmp_path, expect=("hole_1.csv", *where))


def test_files_with_different_joint_counts_are_refused(tmp_path):
    _recording(tmp_path / "a.csv", dof=7)
    _recording(tmp_path / "b.csv", dof=6)
    _refused(tmp_path, tmp_path / "a.csv", tmp_path / "b.csv", expect=("b.csv",))


def test_folders_without_holes_or_with_a_gap_are_refused(tmp_path):
    empty = tmp_path / "empty"
    empty.mkdir()
    np.savetxt(empty / "hole_0_pose.csv", np.zeros((2, 7)), delimiter=",")  # pose files only
    _refused(tmp_path, empty, expect=("empty",))
    gap = tmp_path / "gap"
    _placement(gap, sockets=3)
    (gap / "hole_1.csv").unlink()  # points 0 and 2: hole_2 must not silently become point 1
    _refused(tmp_path, gap, expect=("hole_1.csv",))
    _refused(tmp_path, tmp_path / "nowhere", expect=("nowhere",))


def test_a_file_given_twice_is_refused(tmp_path):
    _placement(tmp_path / "p")
    _refused(tmp_path, tmp_path / "p", tmp_path / "p" / "hole_0.csv", expect=("hole_0.csv",))


def test_existing_output_needs_force_and_inputs_are_never_overwritten(tmp_path):
    q = _placement(tmp_path / "p")
    out = tmp_path / "out.csv"
    out.write_text("keep\n")
    run = _run("data", "sockets", tmp_path / "p", "-o", out)
    assert run.exit_code != 0 and out.read_text() == "keep\n"
    assert _run("data", "sockets", tmp_path / "p", "-o", out, "--force").exit_code == 0
    assert np.array_equal(read_constraints(out, 6).q, np.vstack(q))
    hole = tmp_path / "p" / "hole_0.csv"
    before = hole.read_bytes()
    run = _run("data", "sockets", tmp_path / "p", "-o", hole, "--force")
    assert run.exit_code != 0 and hole.read_bytes() == before


def test_control_characters_from_the_data_are_escaped(tmp_path):
    _recording(tmp_path / "hole_0.csv", dof=3)
    (tmp_path / "hole_1.csv").write_text("0.1,\x1b[31mred\x07,0.3\n")
    run = _run("data", "sockets", tmp_path, "-o", tmp_path / "out.csv")
    assert run.exit_code != 0 and "\x1b" not in run.output and "\x07" not in run.output


def test_api_raises_the_constraint_error(tmp_path):
    (tmp_path / "hole_0.csv").write_text("0.1,x\n")
    with pytest.raises(ConstraintFileError, match="column 2"):
        read_socket_recordings([tmp_path])
