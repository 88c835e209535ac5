"""Issue 33 ("validate reports ... position error when a device is given"): ``robocal validate``
of a constraint calibration folder on a tracker file, through the CLI.

One true UR10 simulated twice with the same seed: the calibration's socket file and tracker
file, and a held-out tracker file of the same robot at other configurations (``--placements
2`` draws them from another stream).  A mixed calibration (sockets + tracker rows) is judged
in the device frame its tracker rows identified; a socket-only one (with the sockets' known
distance) has no device frame: refused without ``--refit-frame``, scored K-fold with it."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from typer.testing import CliRunner

from robocal.cli.app import app

NOISE_3D_MM = 3**0.5 * 0.01  # the simulated tracker's 10 um per axis, as a 3-D RMS


def _run(*args: object):
    return CliRunner().invoke(app, [str(a) for a in args])


def _ok(*args: object):
    res = _run(*args)
    assert res.exit_code == 0, res.output
    return res


def _json(*args: object) -> dict:
    return json.loads(_ok(*args, "--json").stdout)


def _refused(res, *words: str) -> None:
    """Exit 2, one ``error:`` line naming ``words``, no traceback."""
    lines = [line for line in res.output.splitlines() if line.strip()]
    assert res.exit_code == 2 and "Traceback" not in res.output, res.output
    assert lines[0].startswith("error:") and all(w in res.output for w in words), res.output


@pytest.fixture(scope="module")
def scene(tmp_path_factory) -> Path:
    d = tmp_path_factory.mktemp("h5")
    common = ("--kind", "point", "--n", 40, "--count", 2, "--seed", 3, "--also-tracker", 30)
    _ok("simulate", "ur10", *common, "-o", d / "sock.csv")
    _ok("simulate", "ur10", *common, "--placements", 2, "-o", d / "held.csv")  # same truth
    truth = json.loads((d / "sock.csv.truth.json").read_text())
    assert truth["true_parameters"] == json.loads((d / "held.csv.truth.json").read_text())["true_parameters"]
    _ok("calibrate", "ur10", "--data", d / "sock.csv", "--data", d / "sock.tracker.csv", "-o", d / "mixed")
    length_mm = truth["point_distances_m"][0][2] * 1e3  # the sockets' true distance, stated
    sockets = ("--data", d / "sock.csv", "--distance", f"0,1={length_mm:.6f}mm")
    _ok("calibrate", "ur10", *sockets, "-o", d / "sockets")
    other = ("--kind", "point", "--n", 20, "--also-tracker", 20, "--seed", 1)  # another robot: 5 joints
    _ok("simulate", "katana450", *other, "-o", d / "katana.csv")
    return d


def test_mixed_calibration_on_held_out_tracker_rows_reaches_the_noise(scene):
    doc = _json("validate", scene / "mixed", "--data", scene / "held.tracker.csv")
    assert doc["frame"] == "calibrated" and doc["n"] == 30 and doc["calibration"] == "constraint"
    # closed loop on the simulated truth: near the tracker's noise; the nominal robot: about a mm
    assert 0.7 * NOISE_3D_MM < doc["rms_mm"] < 1.5 * NOISE_3D_MM
    assert doc["nominal"]["rms_mm"] > 0.3 and doc["nominal"]["rms_mm"] > 20 * doc["rms_mm"]
    assert doc["expected_rms_mm"] is None and doc["fitted_file"] is False
    # the same frame refitted to the held-out file (scored K-fold) stays at the noise
    refit = _json("validate", scene / "mixed", "--data", scene / "held.tracker.csv", "--refit-frame")
    assert refit["frame"] == "refit" and refit["scoring"] == "5-fold"
    assert refit["rms_mm"] < 1.5 * NOISE_3D_MM and refit["in_sample"]["n"] == 30


def test_the_calibrations_own_tracker_file_is_called_in_sample(scene):
    own = scene / "sock.tracker.csv"
    assert _json("validate", scene / "mixed", "--data", own)["fitted_file"] is True
    text = _ok("validate", scene / "mixed", "--data", own).output
    assert "in-sample" in text and "nominal robot" in text


def test_socket_only_calibration_needs_and_takes_a_refitted_frame(scene):
    held = scene / "held.tracker.csv"
    _refused(_run("validate", scene / "sockets", "--data", held), "--refit-frame", str(scene / "sockets"))
    doc = _json("validate", scene / "sockets", "--data", held, "--refit-frame")
    assert doc["frame"] == "refit" and doc["scoring"] == "5-fold" and doc["expected_rms_mm"] is None
    # the sockets and their known distance calibrate the arm: well below the nominal robot's error
    assert doc["rms_mm"] < 0.2 and doc["rms_mm"] < 0.2 * doc["nominal"]["rms_mm"]
    assert doc["in_sample"]["rms_mm"] <= doc["rms_mm"]  # a frame fitted to the scored rows flatters


def test_wrong_robot_and_missing_data_are_refused_by_name(scene):
    wrong = scene / "katana.tracker.csv"  # five joint columns for a six-joint calibration
    _refused(_run("validate", scene / "mixed", "--data", wrong), wrong.name, "q6")
    _refused(_run("validate", scene / "mixed"), "--data")
    _refused(_run("validate", scene / "mixed", "--data", scene / "absent.csv"), "absent.csv")


def test_report_shows_the_tracker_files_position_errors(scene):
    held = scene / "held.tracker.csv"
    doc = _json("validate", scene / "mixed", "--data", held)
    _ok("report", scene / "mixed", "--test-data", held, "-o", scene / "mixed.html")
    page = (scene / "mixed.html").read_text()
    section = page[page.rindex("Position errors on a tracker file") :]
    # the page's table is the validation's: the calibrated and the nominal robot's RMS, mm
    assert f"{doc['rms_mm']:.4f}" in section and f"{doc['nominal']['rms_mm']:.4f}" in section
    refit = _json("validate", scene / "sockets", "--data", held, "--refit-frame")
    _ok("report", scene / "sockets", "--test-data", held, "-o", scene / "sockets.html")
    section = (scene / "sockets.html").read_text().split("Position errors on a tracker file")[-1]
    assert f"{refit['rms_mm']:.4f}" in section and "5-fold" in section
    wrong = _run(
        "report", scene / "mixed", "--test-data", scene / "katana.tracker.csv", "-o", scene / "w.html"
    )
    _refused(wrong, "katana.tracker.csv")
    assert not (scene / "w.html").exists()


def test_sockets_without_a_stated_length_are_said_to_leave_the_scale(scene):
    """Fixed points of unknown distance measure no length: the tracker shows the arm's scale
    off (an error several times the stated-distance calibration's) and validate says why."""
    held = scene / "held.tracker.csv"
    _ok("calibrate", "ur10", "--data", scene / "sock.csv", "-o", scene / "unscaled")
    unscaled = _json("validate", scene / "unscaled", "--data", held, "--refit-frame")
    scaled = _json("validate", scene / "sockets", "--data", held, "--refit-frame")
    assert unscaled["rms_mm"] > 3 * scaled["rms_mm"]
    said = [
        _ok("validate", scene / d, "--data", held, "--refit-frame").output for d in ("unscaled", "sockets")
    ]
    assert ["scale is not calibrated" in " ".join(text.split()) for text in said] == [True, False]
