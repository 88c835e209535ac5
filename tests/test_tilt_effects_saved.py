"""Joint effects identified from tilt rows are kept, shown and used (issue 33): saved in
constraints.json and read back, used by the tilt figures of validate / report / GUI, printed
by the calibration summary; tracker + tilt prints what each kind alone identifies; the
recorded data paths are the user's (the GUI's: the uploads' own names)."""

from __future__ import annotations

import dataclasses
import json
import math
from types import SimpleNamespace

import numpy as np
import pytest
from typer.testing import CliRunner

import robocal as rc
from robocal.cli.app import app
from robocal.identify.constraints.fit import constraint_figures
from robocal.identify.constraints.result import load_constraint_calibration
from robocal.measure.constraints.data import read_constraints, write_constraints
from robocal.measure.constraints.mounts import mounts_at_home
from robocal.measure.constraints.sim import simulate_tilt_rows, simulate_tracker_rows
from robocal.measure.true_model import draw_true_model
from robocal.model.joints import effects_from_values

# the true joints: gravity loads bend the shoulder and the elbow, the wrist has backlash
TRUE_EFFECTS = {
    ("compliance", "shoulder_lift"): 2e-6,
    ("compliance", "elbow"): 3e-6,
    ("backlash", "wrist_1"): 1e-4,
}


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    """A true UR10 (seed 4) with joint effects: a calibration tilt file, a held-out tilt
    file and a tracker file of the same robot."""
    ur10 = rc.calibration_model("ur10")
    true = draw_true_model(ur10, length="1mm", angle="0.1deg", seed=4)
    true = dataclasses.replace(true, joint_effects=effects_from_values(true, TRUE_EFFECTS, start=()))
    folder = tmp_path_factory.mktemp("tilt_effects")
    paths = SimpleNamespace(
        dir=folder, tilt=folder / "tilt.csv", test=folder / "held_out.csv", tracker=folder / "tracker.csv"
    )
    # the sensors along the complete model's joint frames, stated at home (chain-independent)
    write_constraints(mounts_at_home(simulate_tilt_rows(true, 30, seed=4), ur10), paths.tilt)
    write_constraints(mounts_at_home(simulate_tilt_rows(true, 30, seed=5), ur10), paths.test)
    write_constraints(simulate_tracker_rows(true, 40, sigma=1e-5, seed=6), paths.tracker)
    return paths


@pytest.fixture(scope="module")
def calibrated(files):
    """``robocal calibrate ur10 --data tilt.csv`` run from the files' folder (relative path)."""
    import os

    cwd = os.getcwd()
    os.chdir(files.dir)
    try:
        run = CliRunner().invoke(app, ["calibrate", "ur10", "--data", "tilt.csv", "-o", "out"])
    finally:
        os.chdir(cwd)
    assert run.exit_code == 0, run.output
    return SimpleNamespace(out=files.dir / "out", output=run.output)


def test_effects_and_zeros_saved_and_read_back(files, calibrated):
    doc = json.loads((calibrated.out / "constraints.json").read_text())
    effects = {e["name"]: e for e in doc["joint_effects"]}
    assert (
        effects["compliance_elbow"]["estimate_rad_per_Nm"] > 0
        and "std_rad_per_Nm" in effects["compliance_elbow"]
    )
    assert "estimate_rad" in effects["backlash_wrist_1"]
    assert doc["data"] == "tilt.csv"  # the path as the user gave it
    cal = load_constraint_calibration(calibrated.out)
    by_name = {e.name: e for e in cal.joint_effects}
    for (kind, joint), true in TRUE_EFFECTS.items():  # the truth within 4σ
        e = by_name[f"{kind}_{joint}"]
        assert math.isfinite(e.std) and e.std > 0 and abs(e.value - true) < 4 * e.std
    channels = {z.name for z in cal.tilt_zeros}
    assert {"elbow_x", "elbow_y", "wrist_1_x"} <= channels
    assert all(math.isfinite(z.value) for z in cal.tilt_zeros)
    held = cal.model_with_effects()
    assert {e.joint: e.compliance for e in held.joint_effects}["elbow"] == by_name["compliance_elbow"].value
    # a folder written before the record (no joint_effects/tilt_zeros keys) still loads
    old = dict(doc)
    del old["joint_effects"], old["tilt_zeros"]
    (calibrated.out / "constraints.json").write_text(json.dumps(old))
    try:
        again = load_constraint_calibration(calibrated.out)
        assert {e.name for e in again.joint_effects} == set(by_name)
        bad = dict(doc, joint_effects=[{"name": "compliance_elbow", "estimate_rad_per_Nm": "x"}])
        (calibrated.out / "constraints.json").write_text(json.dumps(bad))
        with pytest.raises(ValueError, match="joint_effects"):
            load_constraint_calibration(calibrated.out)
    finally:
        (calibrated.out / "constraints.json").write_text(json.dumps(doc, indent=1) + "\n")


def _validate_tilt(output: str) -> dict[str, float]:
    """validate's first block of tilt figures (the calibrated robot's, deg)."""
    out: dict[str, float] = {}
    for line in output.split("before calibration")[0].splitlines():
        if line.strip().startswith("tilt ") and "RMS residual" in line:
            out[line.split()[1].rstrip(":")] = float(line.split("RMS residual")[1].split()[0])
    return out


def test_held_out_tilt_figures_use_the_saved_effects(files, calibrated):
    from robocal.evaluate.report.constraint_collect import collect_constraint_report

    cal = load_constraint_calibration(calibrated.out)
    test = read_constraints(files.test, cal.model.dof)
    sigma_deg = math.degrees(test.tilt_sigma)
    geometry = constraint_figures(cal.model, test)  # what was shown before: no joint effects
    assert np.degrees(geometry.tilt_rms).max() > 3 * sigma_deg  # the effects matter on this robot
    report = collect_constraint_report(cal, None, test, sources=("", "held_out.csv"))
    after = report.sets[0].after
    assert len(after.tilt_channels) >= 10 and np.degrees(after.tilt_rms).max() <= 2 * sigma_deg
    assert "joint effects" in after.tilt_basis
    val = CliRunner().invoke(app, ["validate", str(calibrated.out), "--data", str(files.test)])
    assert val.exit_code == 0, val.output
    shown = _validate_tilt(val.output)
    assert len(shown) >= 10 and max(shown.values()) <= 2 * sigma_deg
    assert "tilt figures: the calibrated geometry with its joint effects" in val.output


def test_summary_prints_the_effects(calibrated):
    text = calibrated.output
    assert "joint effects from the tilt rows" in text
    elbow = next(line for line in text.splitlines() if line.strip().startswith("elbow:"))
    assert "compliance" in elbow and "±" in elbow and "µrad/(N·m)" in elbow
    wrist = next(line for line in text.splitlines() if line.strip().startswith("wrist_1:"))
    assert "backlash" in wrist and "deg" in wrist
    # the base joint carries no bending moment about its axis: named as not identified
    held = next(line for line in text.splitlines() if line.startswith("joint effects not identified"))
    assert "compliance_shoulder_pan" in held


def test_tracker_and_tilt_print_what_each_kind_identifies(files, tmp_path):
    out = tmp_path / "mixed"
    args = ["calibrate", "ur10", "--data", str(files.tilt), "--data", str(files.tracker), "-o", str(out)]
    run = CliRunner().invoke(app, args)
    assert run.exit_code == 0, run.output
    tilt = next(line for line in run.output.splitlines() if line.startswith("tilt rows alone"))
    tracker = next(line for line in run.output.splitlines() if line.startswith("tracker rows alone"))
    assert "a2" in tilt.split("; not")[1]  # no length turns a link
    assert "joint effects" in tilt and "identify" in tracker
    doc = json.loads((out / "constraints.json").read_text())
    assert doc["tracker_data"][0]["path"] == str(files.tracker)  # as given on the command line


def test_gui_run_records_the_uploads_names_only(files, tmp_path):
    from robocal.apps.gui.constraint_job import FIGURES_FILE, ConstraintOptions, run_constraint_job
    from robocal.apps.gui.jobs import read_options
    from robocal.model.files import save_model

    server = tmp_path / "server_workdir"
    uploads = []
    for token, path in (("a1b2c3", files.tilt), ("d4e5f6", files.tracker)):
        target = server / "data" / token / path.name
        target.parent.mkdir(parents=True)
        target.write_bytes(path.read_bytes())
        uploads.append(target)
    model_file = save_model(rc.calibration_model("ur10"), server / "runs" / "m.model.yaml")
    options = ConstraintOptions(more_data=(uploads[1],))
    job = SimpleNamespace(data=uploads[0], reader=read_options(), model_file=model_file,
                          out=server / "runs" / "r1", constraints=options)  # fmt: skip
    run_constraint_job(job, lambda stage, fraction: None)
    doc = json.loads((job.out / "constraints.json").read_text())
    assert doc["data"] == "tilt.csv" and doc["tracker_data"][0]["path"] == "tracker.csv"
    for name in ("constraints.json", FIGURES_FILE, "report.html"):
        text = (job.out / name).read_text(encoding="utf-8")
        assert str(server) not in text and "server_workdir" not in text, name
    assert load_constraint_calibration(job.out).joint_effects  # the mixed fit's tilt effects kept too
    report = (job.out / "report.html").read_text(encoding="utf-8")
    assert "inclinometer elbow_x" in report and "with its joint effects" in report  # the report's tilt table
