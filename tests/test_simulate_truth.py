"""``robocal simulate --kind K --also-tracker N`` (issue 33): a tracker file from the same
true robot as the constraint file, so the two calibrations can be compared with the truth."""

from __future__ import annotations

import json

import numpy as np
from typer.testing import CliRunner

import robocal as rc
from robocal.cli.app import app
from robocal.model.files import load_model

# parameters the drawn errors move far (0.2-0.7 mm or mrad) and both kinds identify
COMPARED = ("a2", "a3", "d5", "alpha2", "alpha3", "beta2")


def test_tracker_file_and_socket_file_recover_the_same_true_robot(tmp_path):
    runner = CliRunner()
    sockets = tmp_path / "sock.csv"
    sim = runner.invoke(app, ["simulate", "ur10", "--kind", "point", "--n", "40", "-o", str(sockets),
                              "--seed", "5", "--also-tracker", "60"])  # fmt: skip
    assert sim.exit_code == 0, sim.output
    tracker = tmp_path / "sock.tracker.csv"
    truth = json.loads((tmp_path / "sock.csv.truth.json").read_text())
    assert truth["tracker_file"]["file"] == tracker.name and truth["tracker_file"]["rows"] == 60
    assert len(tracker.read_text().splitlines()) == 61 and tracker.read_text().startswith(
        "q1,q2,q3,q4,q5,q6,x,y,z"
    )
    length = truth["point_distances_m"][0][2] * 1e3
    runs = {
        "tracker": ["--data", str(tracker), "--residual", "none", "--level", "2"],
        "sockets": ["--data", str(sockets), "--distance", f"0,1={length:.6f}mm"],
    }
    true = truth["true_parameters"]
    nominal = rc.calibration_model("ur10")
    nominal_error = np.array([nominal.step(n).value - true[n] for n in COMPARED])
    assert np.abs(nominal_error).min() > 1e-4  # the comparison can fail
    for name, args in runs.items():
        out = tmp_path / name
        run = runner.invoke(app, ["calibrate", "ur10", *args, "-o", str(out)])
        assert run.exit_code == 0, run.output
        fitted = load_model(out / "model.yaml")
        values = dict(zip(fitted.names, fitted.values.tolist(), strict=True))
        error = np.array([values[n] - true[n] for n in COMPARED])
        assert np.all(np.abs(error) < 0.1 * np.abs(nominal_error)), (name, error, nominal_error)


def test_also_tracker_refuses_to_overwrite_the_tracker_file(tmp_path):
    runner = CliRunner()
    out = tmp_path / "p.csv"
    (tmp_path / "p.tracker.csv").write_text("keep\n")
    run = runner.invoke(app, ["simulate", "ur10", "--kind", "plane", "--n", "12", "-o", str(out),
                              "--also-tracker", "5"])  # fmt: skip
    assert run.exit_code != 0 and "p.tracker.csv" in run.output
    assert (tmp_path / "p.tracker.csv").read_text() == "keep\n" and not out.exists()
