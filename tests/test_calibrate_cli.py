"""``robocal calibrate`` and ``robocal validate`` through the CLI."""

import json

import numpy as np
import pytest
from typer.testing import CliRunner

import robocal as rc
from robocal.cli import app
from robocal.measure.dataset import Measurements, write_measurements

runner = CliRunner()
TRACKER = rc.spatial.homogeneous(rc.spatial.rotvec_to_matrix([0.1, 0.2, -2.0]), [1.5, 2.0, -0.2])


@pytest.fixture(scope="module")
def measured(tmp_path_factory):
    """A UR10 with 0.3 mm / 0.03° errors measured by a tracker at a 109 mm probe, in mm."""
    from robocal.measure.simulate import draw_true_model

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
        "--robot",
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
        "0,0,109",
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
    # validating on the whole file with the calibrated tracker frame
    result = runner.invoke(app, ["validate", str(out), "--data", str(path), "--length-unit", "mm", "--json"])
    assert result.exit_code == 0, result.output
    stats = json.loads(result.output)
    assert set(stats) >= {"n", "mean_mm", "rms_mm", "max_mm", "p95_mm"}
    assert stats["n"] == 160 and stats["mean_mm"] < 0.05 and stats["frame"] == "calibrated"
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
    with_report = runner.invoke(app, [*args, "--force", "--report"])
    assert with_report.exit_code == 0, with_report.output
    page = (out / "report.html").read_text()
    assert "plotly" in page.lower() and "held-out" in page.lower()


def test_calibrate_errors_are_clear(measured, tmp_path):
    path, _ = measured
    result = runner.invoke(app, ["calibrate", "--data", str(path), "--out", str(tmp_path / "o")])
    assert result.exit_code == 2 and "exactly one of --robot" in result.output
    result = runner.invoke(
        app, ["calibrate", "--robot", "ur10", "--data", str(tmp_path / "x.csv"), "--out", str(tmp_path)]
    )
    assert result.exit_code == 2 and "does not exist" in result.output
    result = runner.invoke(
        app,
        [
            "calibrate",
            "--robot",
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
    base = ["calibrate", "--robot", "ur10", "--data", str(path), "--length-unit", "mm", "--tool", "0,0,109"]
    right = runner.invoke(app, [*base, "--noise", "0.01", "--out", str(tmp_path / "a")])
    assert right.exit_code == 0, right.output
    assert "explains the data down to the measurement noise" in " ".join(right.output.split())
    saved = json.loads((tmp_path / "a" / "result.json").read_text())
    assert 0.8 < saved["fit_to_noise"]["ratio"] < 1.2
    wrong = runner.invoke(app, [*base, "--noise", "0.001", "--out", str(tmp_path / "b")])
    assert wrong.exit_code == 0, wrong.output
    assert "does not represent" in " ".join(wrong.output.split()) and "warning" in wrong.output
    bad = runner.invoke(app, [*base, "--noise", "-1", "--out", str(tmp_path / "c")])
    assert bad.exit_code == 2 and "--noise -1" in bad.output
