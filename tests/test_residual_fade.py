"""Never worse at the worst pose (issue 34 item 2): where the calibration had no data the
learned residual fades out and its predicted σ grows; the model choice scores the tail.

A virtual UR10 (tests/test_residual.py's: the complete model, transmission errors the
physics lacks, 15 µm tracker noise) calibrated on poses whose shoulder and elbow angles
stay within ±0.6 and ±0.8 rad, validated on poses that leave that range by 0.3 rad or more
and on poses inside it.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

import robocal as rc
from robocal.identify.residual.cv import CVCandidate, CVTable, _one_standard_error
from robocal.model.residual import FADE, JointAngleResidual, fourier_basis
from tests.test_residual import NOISE, PROBE, _measure, _truth, _ur10

TRAIN_LIMIT = np.array([math.pi, 0.6, 0.8, math.pi, math.pi, math.pi])  # rad, |q| of the training poses
TEST_SPAN = np.array([math.pi, 1.6, 2.2, math.pi, math.pi, math.pi])  # rad, |q| of the validation poses
NOISE_3D = math.sqrt(3.0) * NOISE  # m, the noise of one measured position


@pytest.fixture(scope="module")
def restricted():
    """``(physics-only result, default result, q (n, 6), measured, inside mask, far mask)``."""
    true = _truth(0)
    rng = np.random.default_rng(1)
    train = _measure(true, rng.uniform(-1, 1, (200, 6)) * TRAIN_LIMIT, 2, True)
    q = rng.uniform(-1, 1, (3000, 6)) * TEST_SPAN
    test = _measure(true, q, 4, True)
    inside = np.all(np.abs(q) <= TRAIN_LIMIT, axis=1)
    far = np.any(np.abs(q[:, 1:3]) > TRAIN_LIMIT[1:3] + 0.3, axis=1)
    physics = rc.calibrate(_ur10(), train, tool_guess=PROBE, residual="none")
    default = rc.calibrate(_ur10(), train, tool_guess=PROBE, residual="auto")
    assert default.model.residual is not None  # the transmission errors need it
    return physics, default, q, test.position, inside, far


def _errors(result: rc.CalibrationResult, q: np.ndarray, measured: np.ndarray) -> np.ndarray:
    return np.linalg.norm(result.predict(q)[:, :3, 3] - measured, axis=1)


def test_outside_the_training_range_the_default_is_not_worse_than_physics(restricted):
    physics, default, q, measured, _, far = restricted
    e_default, e_physics = _errors(default, q[far], measured[far]), _errors(physics, q[far], measured[far])
    assert far.sum() > 1000
    assert e_default.mean() <= e_physics.mean() + NOISE_3D
    assert np.percentile(e_default, 95) <= np.percentile(e_physics, 95) + NOISE_3D
    assert e_default.max() <= e_physics.max() + 3 * NOISE_3D


def test_the_predicted_sigma_grows_where_the_residual_fades(restricted):
    _, default, q, measured, inside, far = restricted
    sigma = default.position_uncertainty(q)
    assert np.sqrt(np.mean(sigma[far] ** 2)) > 5 * np.sqrt(np.mean(sigma[inside] ** 2))
    # and it is honest there: the error outside is of the predicted size, not far above it
    e = _errors(default, q[far], measured[far])
    assert np.sqrt(np.mean(e**2)) < 2.0 * np.sqrt(np.mean(sigma[far] ** 2) + 3 * NOISE**2)


def test_inside_the_training_range_the_fade_changes_nothing(restricted):
    physics, default, q, measured, inside, _ = restricted
    unfaded = default.replace(
        model=dataclasses.replace(
            default.model, residual=dataclasses.replace(default.model.residual, coverage=None)
        )
    )
    q_in, measured_in = q[inside], measured[inside]
    e, e_unfaded = _errors(default, q_in, measured_in), _errors(unfaded, q_in, measured_in)
    assert e.mean() <= 1.05 * e_unfaded.mean()
    assert e.mean() < 0.3 * _errors(physics, q_in, measured_in).mean()


# ------------------------------------------------------------------ the model choice's rule
def _row(name: str, harmonics: int | None, e: np.ndarray) -> CVCandidate:
    rms = float(np.sqrt(np.mean(e**2)))
    return CVCandidate(
        name, "geometry", harmonics, float(e.mean()), rms, 0.0, float(np.percentile(e, 95)), float(e.max())
    )


def test_a_residual_that_raises_the_tail_is_not_chosen():
    """Lower mean CV error by many standard errors, but one pose in ten 1 mm worse: the
    physics alone is chosen."""
    rng = np.random.default_rng(0)
    physics = np.abs(rng.normal(3e-4, 1e-4, 500))
    heavy = 0.5 * physics
    heavy[::10] += 1e-3
    rows = [_row("geometry", None, physics), _row("geometry + angle errors H=8", 8, heavy)]
    per_pose = {"geometry": physics, "geometry + angle errors H=8": heavy}
    assert heavy.mean() < physics.mean()
    assert _one_standard_error(rows, per_pose, ["geometry"]).harmonics is None
    light = 0.5 * physics  # the same mean gain without the tail: the residual
    rows[1], per_pose["geometry + angle errors H=8"] = _row("geometry + angle errors H=8", 8, light), light
    assert _one_standard_error(rows, per_pose, ["geometry"]).harmonics == 8


def test_more_harmonics_need_one_standard_error_once_a_residual_is_chosen():
    """Physics far behind; 48 harmonics lower than 24 by about 2 standard errors: 48."""
    rng = np.random.default_rng(1)
    h24 = np.abs(rng.normal(1.5e-4, 5e-5, 400))
    h48 = h24 - 2.0 * 5e-5 / math.sqrt(400) - rng.normal(0, 1e-6, 400)
    physics = h24 + 3e-4
    names = {None: "geometry", 24: "geometry + angle errors H=24", 48: "geometry + angle errors H=48"}
    per_pose = {names[None]: physics, names[24]: h24, names[48]: h48}
    rows = [_row(names[h], h, per_pose[names[h]]) for h in (None, 24, 48)]
    assert _one_standard_error(rows, per_pose, ["geometry"]).harmonics == 48


def test_the_cv_table_keeps_its_tail_and_reads_older_tables():
    row = CVCandidate("geometry + angle errors H=8", "geometry", 8, 1e-4, 2e-4, 0.1, 3e-4, 9e-4)
    table = CVTable(5, (row,), row.name)
    back = CVTable.from_dict(table.to_dict())
    assert back.candidates[0].cv_p95 == pytest.approx(3e-4)
    assert back.candidates[0].cv_max == pytest.approx(9e-4)
    older = table.to_dict()
    for c in older["candidates"]:  # a result.json written before the tail was recorded
        del c["cv_p95_mm"], c["cv_max_mm"]
    old = CVTable.from_dict(older)
    assert math.isnan(old.candidates[0].cv_p95)
    assert "cv_p95_mm" not in old.to_dict()["candidates"][0]  # never a NaN in result.json
    assert any("<- chosen" in line for line in old.lines())


# ------------------------------------------------------------------ the fade's width
def _smooth(length_scale: float) -> JointAngleResidual:
    m = 2 * 4
    return JointAngleResidual(
        ("elbow",), (2,), 4, np.full(m, 1e-4), np.zeros((m, m)), 1e-5, (1e-4,), length_scale
    )


def test_the_fade_reaches_as_far_as_the_priors_correlation_length():
    """A gap of 0.3 rad in the calibration's angles: a smooth residual (ℓ = 0.25 rad) spans
    it, a rough one (ℓ = 0.05 rad) fades out in it within 0.1 rad of each side."""
    dense = np.zeros((40, 6))
    dense[:, 2] = np.r_[np.linspace(-1.0, -0.15, 20), np.linspace(0.15, 1.0, 20)]
    middle = np.zeros((1, 6))
    smooth, rough = _smooth(0.25).covering(dense), _smooth(0.05).covering(dense)
    assert smooth.fade_width == pytest.approx(0.25) and rough.fade_width == pytest.approx(0.1)
    assert smooth.fade(middle)[0, 0] == 1.0  # the 0.3 rad gap is covered
    assert rough.fade(middle)[0, 0] < 1e-12  # 0.15 rad from the data: faded out
    beyond = np.zeros((1, 6))
    beyond[0, 2] = 1.2  # 0.2 rad past the last angle: partly for the smooth one, gone for the rough
    assert 0.0 < smooth.fade(beyond)[0, 0] < 1.0 and rough.fade(beyond)[0, 0] < 1e-12


def test_the_fade_width_goes_through_the_model_file():
    learned = _smooth(0.25).covering(np.zeros((3, 6)) + np.array([0, 0, 0.5, 0, 0, 0]))
    back = JointAngleResidual.from_dict(learned.to_dict(), ("a", "b", "elbow", "d", "e", "f"))
    assert back.fade_width == learned.fade_width and back.coverage == learned.coverage
    older = {k: v for k, v in learned.to_dict().items() if k != "fade_rad"}  # a file from before
    assert JointAngleResidual.from_dict(older, ("a", "b", "elbow", "d", "e", "f")).fade_width == FADE
    with pytest.raises(ValueError, match="fade_width"):
        dataclasses.replace(learned, fade_width=float("nan"))


def test_the_first_harmonics_go_on_where_the_rest_fades():
    """Outside the coverage only the global harmonics (eccentricity, ellipticity) remain;
    the angle errors, the basis and the position covariance agree on it."""
    learned = dataclasses.replace(_smooth(0.05), coverage=(((-1.0, 1.0),),), global_harmonics=2)
    q = np.zeros((3, 6))
    q[:, 2] = [0.5, 1.5, 2.5]  # inside, 0.5 rad and 1.5 rad beyond the coverage
    first_two = learned.coefficients.copy()
    first_two[4:] = 0.0
    plain = fourier_basis(q[:, [2]], 4)[:, 0]
    np.testing.assert_allclose(
        learned.angle_errors(q)[:, 0], [plain[0] @ learned.coefficients, *(plain[1:] @ first_two)]
    )
    np.testing.assert_allclose(learned.basis(q)[:, 0] @ learned.coefficients, learned.angle_errors(q)[:, 0])
    P = np.zeros((3, 3, 6, 3))
    P[:, 0, 2, 2] = 1.0  # x moves 1 m per rad of the elbow
    C = np.diag(np.linspace(1.0, 2.0, 8)) * 1e-8
    cov = dataclasses.replace(learned, covariance=C, angle_rms=(0.0,)).position_covariance(q, P)[:, 0, 0]
    B = learned.basis(q)[:, 0]
    np.testing.assert_allclose(cov, np.einsum("nh,hk,nk->n", B, C, B))
    assert cov[2] > 0.0  # the kept harmonics' uncertainty remains outside
