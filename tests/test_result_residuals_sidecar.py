"""A calibration of many poses keeps its per-pose residuals beside result.json
(robocal.identify.result_io: residuals.npz above RESIDUALS_INLINE_POSES poses, float64, named
with its SHA-256) instead of a JSON list of tens of MB; fewer poses keep them inline; a
sidecar that is missing, altered or of another size is refused by name."""

import json

import numpy as np
import pytest

import robocal as rc
from robocal.identify.result import CalibrationResult
from robocal.identify.result_io import RESIDUALS_FILE, RESIDUALS_INLINE_POSES, ResultFileError
from robocal.measure.measurements import Measurements


@pytest.fixture(scope="module")
def calibrated():
    model = rc.calibration_model("ur10")
    true = rc.measure.draw_true_model(model, length=1e-3, angle=np.radians(0.05), seed=11)
    rng = np.random.default_rng(11)
    lim = np.clip(model.joint_limits, -np.pi, np.pi)
    q = rng.uniform(lim[:, 0], lim[:, 1], (200, model.dof))
    position = true.fk(q)[:, :3, 3] + rng.normal(0.0, 20e-6, (200, 3))
    return rc.calibrate(model, Measurements(q=q, position=position))


def _many(result, n):
    """``result`` as if fitted to ``n`` poses: random residuals of the fit's size (m)."""
    residuals = np.random.default_rng(n).normal(0.0, 3e-5, (n, 3))
    return result.replace(residuals=residuals, n=n)


def test_many_poses_residuals_go_beside_result_json_bit_for_bit(calibrated, tmp_path):
    many = _many(calibrated, RESIDUALS_INLINE_POSES + 1)
    many.save(tmp_path / "run")
    data = json.loads((tmp_path / "run" / "result.json").read_text())
    assert "residuals_mm" not in data and data["residuals_file"]["name"] == RESIDUALS_FILE
    loaded = CalibrationResult.load(tmp_path / "run")
    np.testing.assert_array_equal(loaded.residuals, many.residuals)  # exact, not rounded to 1 nm
    assert loaded.rms_after == many.rms_after
    # saved again with few poses into the same folder: inline, and the stale sidecar gone
    calibrated.save(tmp_path / "run")
    assert "residuals_mm" in json.loads((tmp_path / "run" / "result.json").read_text())
    assert not (tmp_path / "run" / RESIDUALS_FILE).exists()
    np.testing.assert_allclose(
        CalibrationResult.load(tmp_path / "run").residuals, calibrated.residuals, atol=1e-9
    )


def test_few_poses_keep_their_residuals_inline(calibrated, tmp_path):
    few = _many(calibrated, RESIDUALS_INLINE_POSES)
    few.save(tmp_path / "few")
    data = json.loads((tmp_path / "few" / "result.json").read_text())
    assert len(data["residuals_mm"]) == RESIDUALS_INLINE_POSES and "residuals_file" not in data
    assert not (tmp_path / "few" / RESIDUALS_FILE).exists()


@pytest.mark.parametrize("damage", ["missing", "altered", "other_size"])
def test_a_damaged_residuals_file_is_refused_by_name(calibrated, tmp_path, damage):
    folder = tmp_path / damage
    _many(calibrated, RESIDUALS_INLINE_POSES + 5).save(folder)
    sidecar = folder / RESIDUALS_FILE
    if damage == "missing":
        sidecar.unlink()
    elif damage == "altered":
        raw = bytearray(sidecar.read_bytes())
        raw[-3] ^= 0xFF
        sidecar.write_bytes(bytes(raw))
    else:  # a consistent file of another run's size: the hash matches, the size does not
        path = folder / "result.json"
        data = json.loads(path.read_text())
        data["n"] = data["n"] + 1
        path.write_text(json.dumps(data))
    with pytest.raises(ResultFileError, match=RESIDUALS_FILE):
        CalibrationResult.load(folder)
