"""``robocal calibrate`` and ``robocal validate`` through the CLI."""

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

import robocal as rc
from robocal.cli import app
from robocal.measure.dataset.writer import write_measurements
from robocal.measure.measurements import Measurements

runner = CliRunner()
TRACKER = rc.spatial.homogeneous(rc.spatial.rotvec_to_matrix([0.1, 0.2, -2.0]), [1.5, 2.0, -0.2])


@pytest.fixture(scope="module")
def measured(tmp_path_factory):
    """A UR10 with 0.3 mm / 0.03° errors measured by a tracker at a 109 mm probe, in mm."""
    from robocal.measure.true_model import draw_true_model

    model = rc.robot("ur10")
    true = draw_true_model(model, length=3e-4, angle=np.radians(0.03), seed=2)
    rng = np.random.default_rng(3)
    q = rng.uniform(-np.pi, np.pi, (160, 6))
    T = true.fk(q)
    p = T[:, :3, :3] @ [0.001, -0.002, 0.109] + T[:, :3, 3]
    y = p @ TRACKER[:3, :3].T + TRACKER[:3, 3] + rng.normal(scale=1e-5, size=p.shape)
    folder = tmp_path_factory.mktemp("data")
    path = write_measurements(Measurements(q=q, position=y * 1000.0), folder / "meas.csv")
    return path, folder


def test_calibrate_then_validate(measured, tmp_path):
    path, _ = measured
    out = tmp_path / "cal"
    args = [
        "calibrate",
        "ur10",
        "--data",
        str(path),
        "--length-unit",
        "mm",
        "--train-n",
        "100",
        "--seed",
        "1",
        "--tool",
        "0,0,109mm",
        "--out",
        str(out),
    ]
    result = runner.invoke(app, args)
    assert result.exit_code == 0, result.output
    assert "held-out validation (60 poses)" in result.output and "absorbed by frame_rz" in result.output
    saved = json.loads((out / "result.json").read_text())
    assert saved["train_n"] == 100 and len(saved["data_sha256"]) == 64
    assert saved["validation"]["mean_mm"] < 0.05
    assert (out / "model.yaml").exists()
    # validating on the calibration's own file: its held-out rows only, with the calibrated tracker frame
    result = runner.invoke(app, ["validate", str(out), "--data", str(path), "--length-unit", "mm", "--json"])
    assert result.exit_code == 0, result.output
    stats = json.loads(result.output)
    assert set(stats) >= {"n", "mean_mm", "rms_mm", "max_mm", "p95_mm"}
    assert stats["n"] == 60 and stats["rows"] == "held-out" and stats["frame"] == "calibrated"
    assert stats["mean_mm"] == pytest.approx(saved["validation"]["mean_mm"], rel=1e-9)
    # without --data: the recorded file, read with the recorded options (mm), split as calibrated
    own = json.loads(runner.invoke(app, ["validate", str(out), "--json"]).output)
    assert own["n"] == 60 and own["mean_mm"] == pytest.approx(stats["mean_mm"], rel=1e-12)
    every = json.loads(runner.invoke(app, ["validate", str(out), "--all-rows", "--json"]).output)
    assert every["n"] == 160 and every["rows"] == "all" and every["mean_mm"] < 0.05
    assert saved["provenance"]["reader"]["length_unit"] == "mm" and saved["provenance"]["train_n"] == 100
    # the report re-reads the calibration's own data too: 100 calibration poses, 60 held out
    page_path = tmp_path / "report.html"
    assert runner.invoke(app, ["report", str(out), "-o", str(page_path)]).exit_code == 0
    page = page_path.read_text(encoding="utf-8")
    assert "position error on the 100 calibration poses" in page and "60 held-out poses" in page
    assert "converged: converged" not in page
    refit = json.loads(
        runner.invoke(
            app, ["validate", str(out), "--data", str(path), "--length-unit", "mm", "--json", "--refit-frame"]
        ).output
    )
    assert refit["frame"] == "refit"
    # results are not overwritten without --force
    again = runner.invoke(app, args)
    assert again.exit_code == 2 and "--force" in again.output
    assert runner.invoke(app, [*args, "--force", "--method", "pinv"]).exit_code == 0
    per_pose = runner.invoke(app, [*args, "--force", "--method", "pinv", "--per-pose", "--residual", "none"])
    assert per_pose.exit_code == 0, per_pose.output
    wrong = runner.invoke(app, [*args, "--force", "--per-pose"])
    assert wrong.exit_code == 2 and "--per-pose needs --method pinv" in wrong.output
    with_report = runner.invoke(app, [*args, "--force", "--report"])
    assert with_report.exit_code == 0, with_report.output
    page = (out / "report.html").read_text()
    assert "plotly" in page.lower() and "held-out" in page.lower()


def test_calibrate_errors_are_clear(measured, tmp_path):
    path, _ = measured
    result = runner.invoke(app, ["calibrate", "--data", str(path), "--out", str(tmp_path / "o")])
    assert result.exit_code == 2 and "Missing argument 'ROBOT'" in result.output
    result = runner.invoke(
        app, ["calibrate", "ur10", "--data", str(tmp_path / "x.csv"), "--out", str(tmp_path)]
    )
    assert result.exit_code == 2 and "does not exist" in result.output
    result = runner.invoke(
        app,
        [
            "calibrate",
            "katana450",
            "--data",
            str(path),
            "--length-unit",
            "mm",
            "--out",
            str(tmp_path),
        ],
    )
    assert result.exit_code == 2 and "Traceback" not in result.output
    result = runner.invoke(app, ["validate", str(tmp_path), "--data", str(path)])
    assert result.exit_code == 2 and "no calibration result" in result.output


def test_noise_option_tests_the_fit_against_the_device_noise(measured, tmp_path):
    """The file has 10 µm noise per axis: stated as 0.01 mm the model explains it; stated
    as 0.001 mm the residuals are ten times the noise and the output says so."""
    path, _ = measured
    base = ["calibrate", "ur10", "--data", str(path), "--length-unit", "mm", "--tool", "0,0,109mm"]
    right = runner.invoke(app, [*base, "--noise", "0.01mm", "--out", str(tmp_path / "a")])
    assert right.exit_code == 0, right.output
    assert "explains the data down to the measurement noise" in " ".join(right.output.split())
    saved = json.loads((tmp_path / "a" / "result.json").read_text())
    assert 0.8 < saved["fit_to_noise"]["ratio"] < 1.2
    wrong = runner.invoke(app, [*base, "--noise", "1um", "--out", str(tmp_path / "b")])
    assert wrong.exit_code == 0, wrong.output
    assert "does not represent" in " ".join(wrong.output.split()) and "warning" in wrong.output
    bad = runner.invoke(app, [*base, "--noise", "-1mm", "--out", str(tmp_path / "c")])
    assert bad.exit_code == 2 and "--noise -1mm" in bad.output
    bare = runner.invoke(app, [*base, "--noise", "0.01", "--out", str(tmp_path / "c")])
    assert bare.exit_code == 2 and "give the unit, e.g. 0.01mm" in bare.output


def _write_mm(data, path):
    """Write measurements read in m back in mm, as the fixture's file."""
    return write_measurements(dataclasses.replace(data, position=data.position * 1000.0), path)


def test_validate_and_calibrate_corner_cases(measured, tmp_path):
    path, _ = measured
    base = ["--length-unit", "mm", "--tool", "0,0,109mm"]
    out = tmp_path / "cal"
    result = runner.invoke(app, ["calibrate", "ur10", "--data", str(path), *base, "--out", str(out)])
    assert result.exit_code == 0, result.output
    # --out naming a file: refused before the fit
    (tmp_path / "afile").write_text("x")
    result = runner.invoke(
        app, ["calibrate", "ur10", "--data", str(path), *base, "--out", str(tmp_path / "afile")]
    )
    assert result.exit_code == 2 and "is a file" in result.output
    # the calibrated model.yaml is a start model: its tool becomes the tool's start value
    again = tmp_path / "again"
    result = runner.invoke(
        app,
        [
            "calibrate",
            str(out / "model.yaml"),
            "--data",
            str(path),
            "--length-unit",
            "mm",
            "--out",
            str(again),
        ],
    )
    assert result.exit_code == 0, result.output
    first, second = (json.loads((d / "result.json").read_text()) for d in (out, again))
    assert second["rms_after_mm"] == pytest.approx(first["rms_after_mm"], rel=1e-3)
    measurement_model = runner.invoke(
        app,
        [
            "calibrate",
            str(out / "measurement_model.yaml"),
            "--data",
            str(path),
            "--length-unit",
            "mm",
            "--out",
            str(tmp_path / "m"),
        ],
    )
    assert measurement_model.exit_code == 2 and "calibrate from the model.yaml" in " ".join(
        measurement_model.output.split()
    )
    # too few rows to refit the frame: an error line, not a traceback
    data = rc.measure.read_measurements(path, length_unit="mm")
    two = _write_mm(data.subset(np.arange(2)), tmp_path / "two.csv")
    result = runner.invoke(
        app, ["validate", str(out), "--data", str(two), "--length-unit", "mm", "--refit-frame"]
    )
    assert result.exit_code == 2 and result.output.startswith("error: ") and "3 points" in result.output
    # the device moved: the output says what to try
    moved = rc.spatial.homogeneous(rc.spatial.rotvec_to_matrix([0.0, 0.0, 0.3]), [0.2, 0.0, 0.0])
    shifted = dataclasses.replace(data, position=data.position @ moved[:3, :3].T + moved[:3, 3])
    moved_path = _write_mm(shifted, tmp_path / "moved.csv")
    result = runner.invoke(
        app, ["validate", str(out), "--data", str(moved_path), "--length-unit", "mm", "--json"]
    )
    stats = json.loads(result.output)
    assert stats["mean_mm"] > 50 and "--refit-frame" in stats["warning"]
    result = runner.invoke(
        app,
        ["validate", str(out), "--data", str(moved_path), "--length-unit", "mm", "--refit-frame", "--json"],
    )
    assert "warning" not in json.loads(result.output)


def test_validate_uses_the_rows_marked_test(measured, tmp_path):
    path, _ = measured
    data = rc.measure.read_measurements(path, length_unit="mm")
    split = data.with_split(100, seed=1)
    split_path = _write_mm(split, tmp_path / "split.csv")
    out = tmp_path / "cal"
    result = runner.invoke(
        app,
        [
            "calibrate",
            "ur10",
            "--data",
            str(split_path),
            "--length-unit",
            "mm",
            "--tool",
            "0,0,109mm",
            "--out",
            str(out),
        ],
    )
    assert result.exit_code == 0, result.output
    assert "held-out validation (60 poses)" in result.output
    held_out = json.loads(
        runner.invoke(
            app, ["validate", str(out), "--data", str(split_path), "--length-unit", "mm", "--json"]
        ).output
    )
    assert held_out["n"] == 60 and held_out["rows"] == "test"
    every = json.loads(
        runner.invoke(
            app,
            ["validate", str(out), "--data", str(split_path), "--length-unit", "mm", "--json", "--all-rows"],
        ).output
    )
    assert every["n"] == 160 and every["rows"] == "all"


def test_space_separated_files_and_separator_names(measured, tmp_path):
    path, _ = measured
    text = path.read_text()
    spaced = tmp_path / "spaced.txt"
    spaced.write_text(text.replace(",", "   "))
    tabbed = tmp_path / "tabbed.csv"
    tabbed.write_text(text.replace(",", "\t"))
    reference = rc.measure.read_measurements(path, length_unit="mm")
    np.testing.assert_array_equal(rc.measure.read_measurements(spaced, length_unit="mm").q, reference.q)
    np.testing.assert_array_equal(
        rc.measure.read_measurements(tabbed, length_unit="mm", sep="tab").q, reference.q
    )
    result = runner.invoke(
        app,
        [
            "calibrate",
            "ur10",
            "--data",
            str(tabbed),
            "--sep",
            "\\t",
            "--length-unit",
            "mm",
            "--tool",
            "0,0,109mm",
            "--out",
            str(tmp_path / "o"),
        ],
    )
    assert result.exit_code == 0, result.output


def test_reader_messages_name_the_command_line_options():
    from robocal.cli.options import as_cli_text

    assert (
        as_cli_text("looks like a decimal comma: pass decimal=','")
        == 'looks like a decimal comma: pass --decimal ","'
    )
    assert as_cli_text("pass angle_unit='deg'") == "pass --angle-unit deg"
    assert as_cli_text("pass orientation='euler:XYZ:deg'") == "pass --orientation euler:XYZ:deg"
    assert (
        as_cli_text("rename with e.g. columns={'q1': '<file column>'}")
        == "rename with e.g. --columns 'q1=<file column>'"
    )
    assert as_cli_text("(given for 'q1' in columns=)") == "(given for 'q1' in --columns)"


def test_calibrate_explains_what_to_change(measured, tmp_path):
    path, _ = measured
    root = Path(__file__).resolve().parents[1]

    def run(*args):
        result = runner.invoke(app, ["calibrate", *args, "--out", str(tmp_path / "o")])
        return result.exit_code, " ".join(result.output.split())

    base = ["--data", str(path), "--length-unit", "mm"]
    code, text = run(str(root / "examples" / "geometry" / "ur10.yaml"), *base)
    assert code == 2 and "joint-geometry file" in text and "robocal model build" in text
    code, text = run("ur10", *base, "--measure", "bogus")
    assert code == 2 and "--measure 'bogus'" in text
    code, text = run("ur10", *base, "--measure", "pose")
    assert code == 2 and "--measure pose needs measured orientations" in text
    joints_only = write_measurements(
        Measurements(q=np.zeros((3, 6)) + np.arange(3)[:, None]), tmp_path / "q.csv"
    )
    code, text = run("ur10", "--data", str(joints_only))
    assert code == 2 and "no measured positions" in text and "--columns" in text
    code, text = run("irb120", *base)
    assert code == 2 and "outside the limits" in text and "--limits warn" in text
    code, text = run("UR10", *base, "--tool", "0,0,109mm")  # catalog names in any case
    assert code == 0, text


def test_bounds_option_is_explicit_and_printed(measured, tmp_path):
    path, _ = measured
    base = ["calibrate", "ur10", "--chain", "catalog", "--data", str(path), "--length-unit", "mm"]
    base += ["--tool", "0,0,109mm", "--residual", "none", "--method", "bounded"]
    result = runner.invoke(app, [*base, "--bounds", "widened", "--out", str(tmp_path / "w")])
    assert result.exit_code == 0, result.output
    assert "bounds='widened'" in " ".join(result.output.split())
    plain = runner.invoke(app, [*base, "--out", str(tmp_path / "d")])
    assert plain.exit_code == 0, plain.output
    assert "bounds='widened':" not in " ".join(plain.output.split())
    wrong = runner.invoke(app, [*base, "--bounds", "wide", "--out", str(tmp_path / "x")])
    # a choice of robocal.choices: Typer's usage error names the option and the value
    assert wrong.exit_code == 2 and "--bounds" in wrong.output and "wide" in wrong.output
    lm = runner.invoke(app, [*base[:-2], "--bounds", "widened", "--out", str(tmp_path / "y")])
    assert lm.exit_code != 0 and "needs --method bounded" in lm.output
