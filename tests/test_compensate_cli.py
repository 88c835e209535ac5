"""``robocal compensate`` through the CLI: an off-line program in the cell frame, corrected."""

import csv
import json

import numpy as np
import pytest
from typer.testing import CliRunner

import robocal as rc
from robocal.cli import app
from robocal.measure import LaserTracker, VirtualRobot, draw_true_model, random_poses, simulate

runner = CliRunner()
TOOL = np.array([0.0, 0.0, 0.1])


@pytest.fixture(scope="module")
def cell(tmp_path_factory):
    """A calibrated UR10 (saved) and a program of cell-frame targets (mm) it can reach."""
    nominal = rc.robot("ur10")
    true = draw_true_model(nominal, length=2e-3, angle=np.radians(0.2), seed=3)
    robot = VirtualRobot(nominal, true, LaserTracker(p_tool_target=TOOL))
    result = rc.calibrate(
        nominal, simulate(robot, random_poses(nominal, 100, seed=1), seed=1), tool_guess=TOOL
    )
    folder = tmp_path_factory.mktemp("cell")
    result.save(folder / "cal")
    q = random_poses(nominal, 30, seed=7)
    # away from singular configurations, where a corrected pose can leave the nominal branch's reach
    q = q[np.linalg.svd(nominal.joint_jacobian(q), compute_uv=False)[:, -1] > 0.05][:8]
    p_cell = robot.device.predict(true.fk(q)).position * 1e3
    with open(folder / "targets.csv", "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["name", "x", "y", "z"])
        for i, row in enumerate(p_cell):
            w.writerow([f"P{i + 1}", *(f"{v:.6f}" for v in row)])
    return folder, robot, p_cell / 1e3, q


def _text(result):
    """The command's output with Rich's line wrapping undone."""
    return " ".join(result.output.split())


def _wrote(result, path) -> bool:
    """Whether the output says it wrote ``path`` (Rich may wrap a long path anywhere)."""
    return f"wrote{path}" in "".join(result.output.split())


def _read_csv(path):
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


def test_targets_in_the_cell_frame_land_on_target(cell, tmp_path):
    folder, robot, p_cell, _ = cell
    out = tmp_path / "corrected.csv"
    args = ["compensate", str(folder / "cal"), "--targets", str(folder / "targets.csv")]
    args += ["--frame", "measurement", "--length-unit", "mm", "-o", str(out)]
    result = runner.invoke(app, args)
    assert result.exit_code == 0, result.output
    assert "8 position targets" in _text(result) and _wrote(result, out)
    rows = _read_csv(out)
    assert list(rows[0]) == [
        "name",
        *(f"q{j}" for j in range(1, 7)),
        *(f"nominal_q{j}" for j in range(1, 7)),
        "predicted_error_before_mm",
        "predicted_error_after_mm",
        "expected_error_after_mm",
        "reachable",
        "status",
    ]
    assert [r["name"] for r in rows] == [f"P{i}" for i in range(1, 9)]
    q = np.array([[float(r[f"q{j}"]) for j in range(1, 7)] for r in rows])
    q_nominal = np.array([[float(r[f"nominal_q{j}"]) for j in range(1, 7)] for r in rows])
    # executed on the real (virtual) robot: the corrected commands land within the
    # calibration's accuracy, the nominal ones millimetres off
    after = np.linalg.norm(robot.device.predict(robot.T_base_tool(q)).position - p_cell, axis=1)
    before = np.linalg.norm(robot.device.predict(robot.T_base_tool(q_nominal)).position - p_cell, axis=1)
    assert after.max() < 0.1e-3 and before.mean() > 1e-3
    assert all(r["reachable"] == "true" for r in rows)
    np.testing.assert_allclose([float(r["predicted_error_before_mm"]) for r in rows], before * 1e3, atol=0.1)
    # "after" is the error to expect from the calibration's uncertainty, not the IK's 0.0000 mm:
    # of the size of what the corrected commands really leave
    expected = np.array([float(r["expected_error_after_mm"]) for r in rows]) * 1e-3
    rms_after = np.sqrt(np.mean(after**2))
    assert 0.3 * rms_after < np.sqrt(np.mean(expected**2)) < 3 * rms_after + 5e-6
    printed = _text(result)
    assert "expected from its uncertainty" in printed and " 0.0000 " not in printed


def test_json_output_and_degrees(cell, tmp_path):
    folder, _, _, _ = cell
    out = tmp_path / "corrected.json"
    args = ["compensate", str(folder / "cal"), "--targets", str(folder / "targets.csv"), "--frame"]
    args += ["measurement", "--length-unit", "mm", "--angle-unit", "deg", "-o", str(out), "--json"]
    result = runner.invoke(app, args)
    assert result.exit_code == 0, result.output
    printed = json.loads(result.stdout)
    saved = json.loads(out.read_text())
    assert printed == saved
    assert saved["units"]["revolute"] == "deg" and saved["summary"]["reachable"] == 8
    assert max(abs(v) for t in saved["targets"] for v in t["q"]) > 10  # degrees, not rad


def test_program_filter(cell, tmp_path):
    folder, _, _, q = cell
    program = tmp_path / "program.csv"
    with open(program, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["name", *(f"q{j}" for j in range(1, 7))])
        for i, row in enumerate(np.degrees(q[:3])):
            w.writerow([f"J{i}", *row])
    out = tmp_path / "filtered.csv"
    result = runner.invoke(
        app,
        ["compensate", str(folder / "cal"), "--program", str(program), "--angle-unit", "deg", "-o", str(out)],
    )
    assert result.exit_code == 0, result.output
    rows = _read_csv(out)
    assert [r["name"] for r in rows] == ["J0", "J1", "J2"]
    assert "predicted_angle_error_after_deg" in rows[0]  # pose targets for a 6-axis arm
    np.testing.assert_allclose([float(rows[0][f"nominal_q{j}"]) for j in range(1, 7)], np.degrees(q[0]))


def test_unreachable_target_exit_status_1(cell, tmp_path):
    folder, _, _, _ = cell
    targets = tmp_path / "far.csv"
    targets.write_text((folder / "targets.csv").read_text() + "far,9000,0,0\n")
    out = tmp_path / "o.csv"
    args = ["compensate", str(folder / "cal"), "--targets", str(targets), "--frame", "measurement"]
    result = runner.invoke(app, [*args, "--length-unit", "mm", "-o", str(out)])
    assert result.exit_code == 1
    assert "1 target(s) not reached: far" in _text(result)
    assert _read_csv(out)[-1]["reachable"] == "false"


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        ([], "give exactly one of --targets"),
        (["--targets", "T", "--frame", "cell"], "--frame"),  # the option's choices refuse it
        (["--targets", "T", "-o", "x.txt.gz"], "must be a .csv or .json"),
        (["--targets", "BAD"], "row 3, column 'z'"),
        (["--targets", "T", "--kind", "pose"], "needs orientation columns"),
        (["--targets", "T", "--q0", "1,2"], "got 2 values"),
    ],
)
def test_bad_input_exits_2_with_a_clear_message(cell, tmp_path, extra, message):
    folder, _, _, _ = cell
    bad = tmp_path / "bad.csv"
    bad.write_text("name,x,y,z\nA,1,2,3\nB,1,2,oops\n")
    extra = [str(folder / "targets.csv") if e == "T" else str(bad) if e == "BAD" else e for e in extra]
    result = runner.invoke(app, ["compensate", str(folder / "cal"), *extra])
    assert result.exit_code == 2, result.output
    assert message in _text(result)


def test_model_file_and_missing_directory(cell, tmp_path):
    folder, _, _, _ = cell
    model = folder / "cal" / "model.yaml"
    result = runner.invoke(
        app, ["compensate", str(model), "--targets", str(folder / "targets.csv"), "--frame"]
    )
    assert result.exit_code == 2  # --frame without a value
    result = runner.invoke(
        app, ["compensate", str(model), "--targets", str(folder / "targets.csv"), "--frame", "measurement"]
    )
    assert result.exit_code == 2 and "needs a calibration directory" in _text(result)
    result = runner.invoke(app, ["compensate", str(tmp_path / "nothing"), "--targets", "x.csv"])
    assert result.exit_code == 2 and "does not exist" in _text(result)
