"""The staged calibration pipeline: grouped options, the frozen result, result.json."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

import robocal as rc
from robocal.identify.options import Bounds, CalibrationOptions, JointEffects, Pruning, RobustLoss, Weights
from robocal.identify.result import CalibrationResult, CalibrationWarning
from robocal.measure import LaserTracker, VirtualRobot, draw_true_model, simulate
from robocal.measure.poses import random_poses

TOOL = np.array([0.0, 0.0, 0.109])


@pytest.fixture(scope="module")
def ur10():
    return rc.robot("ur10")


@pytest.fixture(scope="module")
def data(ur10):
    device = LaserTracker(p_tool_target=TOOL, sigma=20e-6)
    return simulate(
        VirtualRobot(ur10, draw_true_model(ur10, seed=41), device), random_poses(ur10, 40, seed=42)
    )


@pytest.fixture(scope="module")
def result(ur10, data):
    return rc.calibrate(ur10, data, tool_guess=TOOL)


# ------------------------------------------------------------------ options
def test_grouped_options_equal_plain_keywords(ur10, data, result):
    grouped = rc.calibrate(
        ur10, data, tool_guess=TOOL, pruning=Pruning(max_std=5e-4), weights=Weights("sigma", 0.1)
    )
    np.testing.assert_array_equal(grouped.estimates, result.estimates)
    options = CalibrationOptions.from_keywords(tool_guess=TOOL, max_std=1e-3, level=2)
    assert options.pruning.max_std == 1e-3 and options.joint_effects.level == 2
    assert options.keywords()["max_std"] == 1e-3
    via_options = rc.calibrate(ur10, data, options=CalibrationOptions.from_keywords(tool_guess=TOOL))
    np.testing.assert_array_equal(via_options.estimates, result.estimates)


def test_unknown_or_doubled_options_are_errors(ur10, data):
    with pytest.raises(TypeError, match="unknown option 'max_sdt'"):
        rc.calibrate(ur10, data, max_sdt=1e-3)
    with pytest.raises(TypeError, match="unknown option 'load_model'"):  # internal: not public
        rc.calibrate(ur10, data, load_model=ur10)
    with pytest.raises(TypeError, match="'level' given both"):
        rc.calibrate(ur10, data, level=3, joint_effects=JointEffects(level=2))
    with pytest.raises(ValueError, match="bounds must be one of"):
        Bounds("tight")
    with pytest.raises(ValueError, match="load_passes"):
        JointEffects(load_passes=0)
    # a solver option the method does not take is an error, not silently dropped
    from robocal.identify.solvers import solve

    with pytest.raises(TypeError, match="resolution"):
        solve(None, np.zeros(1), "lm", resolution=1e-5)
    options = CalibrationOptions.from_keywords(loss=RobustLoss("soft_l1", 2e-4))
    assert options.loss.loss == "soft_l1" and options.replace(f_scale=1e-3).loss.f_scale == 1e-3
    with pytest.raises(dataclasses.FrozenInstanceError):
        options.loss.loss = "linear"


# ------------------------------------------------------------------ the frozen result
def test_result_is_frozen_and_typed(result, data):
    with pytest.raises(dataclasses.FrozenInstanceError):
        result.rms_after = 0.0
    with pytest.raises(TypeError):
        result.metadata["validation"] = {}  # a read-only view
    assert result.T_device_base.shape == (4, 4) and result.frame is result.T_device_base
    assert result.residuals.shape == (data.n, 3)  # metres
    rms = float(np.sqrt(np.mean(np.sum(result.residuals**2, axis=1))))
    assert rms == pytest.approx(result.rms_after, rel=1e-12)
    assert np.max(np.abs(result.residuals)) < 1e-3  # metres, not millimetres
    assert all(isinstance(w, CalibrationWarning) and w.code and w.message for w in result.warnings)
    assert result.metadata["warnings"] == [w.message for w in result.warnings]
    assert result.fit_to_noise is not None and result.diagnostics.fit_to_noise is result.fit_to_noise
    assert result.diagnostics.evaluations >= 2 and result.diagnostics.level == 2
    # additions make new results; the original is unchanged
    validated = result.with_validation({"rms_mm": 0.1}).with_records(seed=3).with_warnings("look", code="x")
    assert validated.validation == {"rms_mm": 0.1} and validated.records["seed"] == 3
    assert validated.warnings[-1] == CalibrationWarning("x", "look")
    assert result.validation is None and "seed" not in result.records
    assert len(result.warnings) == len(validated.warnings) - 1


def test_save_load_round_trip(result, tmp_path):
    from robocal.identify.provenance import Provenance

    provenance = Provenance.record(tmp_path / "d.csv", "ab" * 32, {"length_unit": "mm"}, 2e-5, 40, 1)
    full = result.with_provenance(provenance, data_file="d.csv").with_validation({"rms_mm": 0.05})
    saved = full.save(tmp_path / "cal")
    assert saved.run_id is not None and full.run_id is None
    loaded = CalibrationResult.load(tmp_path / "cal")
    assert loaded.run_id == saved.run_id
    for name in ("estimates", "nominal", "std", "covariance", "T_device_base"):
        np.testing.assert_allclose(getattr(loaded, name), getattr(result, name), rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(loaded.residuals, result.residuals, rtol=0, atol=1e-9)  # written to 1 nm
    assert loaded.names == result.names
    assert [(d.name, d.reason, d.absorbed_by) for d in loaded.dropped] == [
        (d.name, d.reason, d.absorbed_by) for d in result.dropped
    ]
    assert loaded.warnings == result.warnings  # codes too
    assert loaded.diagnostics.fit_to_noise == result.diagnostics.fit_to_noise
    assert loaded.diagnostics.outlier_poses == result.diagnostics.outlier_poses
    assert loaded.provenance == provenance and loaded.validation == {"rms_mm": 0.05}
    assert loaded.records["data_file"] == "d.csv"
    assert loaded.summary() == full.summary().replace(
        f"{full.seconds * 1e3:.1f} ms", f"{loaded.seconds * 1e3:.1f} ms"
    )


def test_older_result_json_loads_and_garbage_is_refused(result, tmp_path):
    folder = tmp_path / "old"
    result.save(folder)
    data = json.loads((folder / "result.json").read_text())
    for key in ("warning_codes", "outlier_poses", "level", "effects", "residuals_mm", "evaluations"):
        data.pop(key)  # an older robocal did not write these
    data["custom_note"] = "kept"
    (folder / "result.json").write_text(json.dumps(data))
    old = CalibrationResult.load(folder)
    assert [w.code for w in old.warnings] == ["unknown"] * len(result.warnings)
    assert old.warning_texts == result.warning_texts and old.residuals is None
    assert old.records["custom_note"] == "kept" and old.metadata["custom_note"] == "kept"
    np.testing.assert_allclose(old.estimates, result.estimates, rtol=1e-12)
    data["parameters"] = "none"
    (folder / "result.json").write_text(json.dumps(data))
    with pytest.raises(ValueError, match=r"result\.json: not a calibration result written by robocal"):
        CalibrationResult.load(folder)
