"""result.json without the learned residual's large covariances (issue 35 item 1).

The residual's ``(m, m)`` covariance and its ``(p, m)`` cross-covariance with the parameters
live in ``residual_covariance.npz`` beside ``result.json`` (named there with its SHA-256):
they read back bit for bit, an altered or missing sidecar is refused by name, and a folder
written before the sidecar (``tests/data/result_before_sidecar``: saved by robocal at
5766086, the covariances inline to 9 digits) loads as it did.  The held-out validation's
expected error is the mean trace of the predicted position covariances, computed without
forming them: the same number as the full computation.
"""

from __future__ import annotations

import dataclasses
import json
import shutil
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

import robocal as rc
from robocal.cli.app import app
from robocal.demo import GravityCompliance, complete_model
from robocal.identify.result_io import RESIDUAL_COVARIANCE_FILE
from robocal.identify.validate import mean_position_variance
from robocal.measure import LaserTracker, VirtualRobot, draw_true_model, random_poses, simulate
from robocal.measure.dataset.writer import write_measurements
from robocal.outdir import MANIFEST

OLD = Path(__file__).resolve().parent / "data" / "result_before_sidecar"
runner = CliRunner()


@pytest.fixture(scope="module")
def hybrid():
    """A virtual UR10 with gravity compliance (identified) and a learned residual fitted
    jointly (6 harmonics): ``(result, held-out data)``."""
    model = complete_model("ur10")
    true = draw_true_model(model, length=1e-3, angle=np.radians(0.1), seed=4)
    robot = VirtualRobot(
        model,
        true,
        LaserTracker(p_tool_target=np.array([0, 0, 0.1])),
        GravityCompliance({"shoulder_lift": 4e-6, "elbow": 6e-6}),
    )
    train = simulate(robot, random_poses(model, 120, seed=1), seed=1)
    test = simulate(robot, random_poses(model, 400, seed=2), seed=2)
    result = rc.calibrate(
        model,
        train,
        tool_guess=[0, 0, 0.1],
        compliance=["shoulder_lift", "elbow"],
        residual="joint_fourier",
        residual_harmonics=6,
    )
    assert result.model.residual is not None and result.residual_cross_covariance is not None
    assert result.effect_names  # the effect columns take part in the covariance
    return result, test


def _same_bits(a: np.ndarray, b: np.ndarray) -> bool:
    return a.dtype == b.dtype and a.shape == b.shape and a.tobytes() == b.tobytes()


def test_round_trip_is_bit_identical_and_listed(hybrid, tmp_path):
    result, _ = hybrid
    result.save(tmp_path / "cal")
    saved = json.loads((tmp_path / "cal" / "result.json").read_text())
    assert "residual_covariance_upper" not in saved and "residual_cross_covariance" not in saved
    assert saved["residual_covariance_file"]["name"] == RESIDUAL_COVARIANCE_FILE
    manifest = (tmp_path / "cal" / MANIFEST).read_text().splitlines()
    assert RESIDUAL_COVARIANCE_FILE in manifest
    loaded = rc.CalibrationResult.load(tmp_path / "cal")
    assert _same_bits(loaded.model.residual.covariance, result.model.residual.covariance)
    assert _same_bits(loaded.residual_cross_covariance, result.residual_cross_covariance)
    assert _same_bits(loaded.covariance, result.covariance)
    assert "residual_covariance_file" not in loaded.records  # a field of the file, not a record


def test_folder_written_before_the_sidecar_loads(tmp_path):
    shutil.copytree(OLD, tmp_path / "old")
    text = json.loads((OLD / "result.json").read_text())
    old = rc.CalibrationResult.load(tmp_path / "old")
    m = old.model.residual.size
    upper = np.zeros((m, m))
    upper[np.triu_indices(m)] = text["residual_covariance_upper"]
    assert np.array_equal(old.model.residual.covariance, upper + np.triu(upper, 1).T)
    assert np.array_equal(old.residual_cross_covariance, np.array(text["residual_cross_covariance"]))
    # saved again in the new layout, it reads back the same bits
    old.save(tmp_path / "new")
    assert (tmp_path / "new" / RESIDUAL_COVARIANCE_FILE).is_file()
    new = rc.CalibrationResult.load(tmp_path / "new")
    assert _same_bits(new.model.residual.covariance, old.model.residual.covariance)
    assert _same_bits(new.residual_cross_covariance, old.residual_cross_covariance)
    q = random_poses(old.model, 50, seed=3)
    assert np.array_equal(new.position_covariance(q), old.position_covariance(q))


@pytest.mark.parametrize("damage", ["altered", "missing", "renamed"])
def test_a_damaged_sidecar_is_refused_by_name(hybrid, tmp_path, damage):
    result, test = hybrid
    folder = tmp_path / "cal"
    result.save(folder)
    sidecar = folder / RESIDUAL_COVARIANCE_FILE
    if damage == "altered":
        raw = bytearray(sidecar.read_bytes())
        raw[-20] ^= 1  # a bit of the last number: a valid .npz, other values
        sidecar.write_bytes(bytes(raw))
    elif damage == "missing":
        sidecar.unlink()
    else:  # result.json pointing elsewhere (../../x): refused, nothing else is read
        saved = json.loads((folder / "result.json").read_text())
        saved["residual_covariance_file"]["name"] = "../model.yaml"
        (folder / "result.json").write_text(json.dumps(saved))
    with pytest.raises(ValueError, match="residual_covariance"):
        rc.CalibrationResult.load(folder)
    write_measurements(test, tmp_path / "test.csv")
    done = runner.invoke(app, ["validate", str(folder), "--data", str(tmp_path / "test.csv")])
    assert done.exit_code != 0
    assert "residual_covariance" in done.output and "Traceback" not in done.output


def test_cli_reads_the_new_layout_and_a_physics_result_drops_the_sidecar(hybrid, tmp_path):
    result, test = hybrid
    folder = tmp_path / "cal"
    result.save(folder)
    write_measurements(test, tmp_path / "test.csv")
    done = runner.invoke(app, ["validate", str(folder), "--data", str(tmp_path / "test.csv"), "--json"])
    assert done.exit_code == 0, done.output
    printed = json.loads(done.output)
    expected = rc.validate(result, test)
    assert printed["expected_rms_mm"] == pytest.approx(expected.expected_rms * 1e3, rel=1e-12)
    # a result without a residual replacing it leaves no stale covariances behind
    physics_model = dataclasses.replace(result.model, residual=None)
    physics = result.replace(model=physics_model, residual_cross_covariance=None)
    physics.save(folder)
    assert not (folder / RESIDUAL_COVARIANCE_FILE).exists()
    assert rc.CalibrationResult.load(folder).model.residual is None


def test_held_out_expected_error_equals_the_full_computation(hybrid):
    """The mean trace of the predicted position covariances — parameters (joint effects
    among them), learned residual, their cross-covariance, the faded-out angle errors —
    computed without forming them equals the per-pose computation."""
    result, test = hybrid
    learned = result.model.residual
    q = np.vstack([test.q, test.q[:100] * 1.4])  # some beyond the calibrated angles
    assert learned.fade(q).min() < 0.5  # the faded-out term takes part
    full = float(np.mean(np.trace(result.position_covariance(q), axis1=1, axis2=2)))
    assert mean_position_variance(result, q) == pytest.approx(full, rel=1e-10)
    stats = rc.validate(result, test)
    held_out = float(np.mean(np.trace(result.position_covariance(test.q), axis1=1, axis2=2)))
    assert stats.parameter_rms**2 == pytest.approx(held_out, rel=1e-10)
    # without the learned residual: the parameters' part alone
    physics_model = dataclasses.replace(result.model, residual=None)
    physics = result.replace(model=physics_model, residual_cross_covariance=None)
    full = float(np.mean(np.trace(physics.position_covariance(q), axis1=1, axis2=2)))
    assert mean_position_variance(physics, q) == pytest.approx(full, rel=1e-10)
