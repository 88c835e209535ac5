"""The compensation's inverse-kinematics settings as one frozen value (issue 32 item 4):
:class:`robocal.compensate.IKOptions`, taken by compensate_targets, filter_program and
compensate_path (the documented keywords still work and replace one field each)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import robocal as rc
from robocal.compensate import IKOptions, compensate_path, compensate_targets, filter_program
from robocal.compensate.safety import sigma_min
from robocal.measure import draw_true_model, random_poses


@pytest.fixture(scope="module")
def puma():
    nominal = rc.robot("puma560")
    real = draw_true_model(nominal, length=2e-3, angle=np.radians(0.2), seed=5)
    q = random_poses(nominal, 12, seed=4)
    q = q[sigma_min(nominal, q, None, "pose") > 0.05]  # away from singularities: no damping
    return nominal, real, q


def test_options_are_frozen_and_refuse_bad_settings_by_name():
    options = IKOptions()
    with pytest.raises(dataclasses.FrozenInstanceError):
        options.tol = 1.0  # type: ignore[misc]
    for field, bad in [("tol", 0.0), ("tol", float("nan")), ("tol_angle", -1e-6), ("max_iter", 0),
                       ("restarts", -1), ("seed", 1.5), ("orientation_weight", float("inf")),
                       ("tool_axis", 3)]:  # fmt: skip
        with pytest.raises(ValueError, match=field):
            IKOptions(**{field: bad})
    with pytest.raises(TypeError):
        IKOptions.of(None, tolerance=1e-3)  # an unknown setting is not silently dropped
    # a keyword given replaces its field; None keeps the options'
    assert IKOptions.of(IKOptions(max_iter=7), max_iter=None, seed=3) == IKOptions(max_iter=7, seed=3)


def test_the_options_reach_the_ik_and_equal_the_keywords(puma):
    nominal, real, q = puma
    T = nominal.fk(q)
    default = compensate_targets(real, T, nominal, q0=q)
    explicit = compensate_targets(real, T, nominal, q0=q, ik=IKOptions())
    np.testing.assert_array_equal(default.q, explicit.q)
    assert default.error_after.max() < 1e-6
    # few iterations: the correction stops short (the setting reaches the calibrated IK) ...
    short = compensate_targets(real, T, nominal, q0=q, ik=IKOptions(max_iter=1, restarts=0))
    assert short.iterations.max() <= 1 and short.error_after.max() > 1e-6
    # ... and the documented keyword is the same setting, replacing the options' field
    keyword = compensate_targets(real, T, nominal, q0=q, max_iter=1, restarts=0)
    np.testing.assert_array_equal(short.q, keyword.q)
    overridden = compensate_targets(real, T, nominal, q0=q, ik=IKOptions(max_iter=1), max_iter=100)
    np.testing.assert_array_equal(overridden.q, default.q)


def test_filter_program_and_path_take_the_options(puma):
    nominal, real, q = puma
    loose = IKOptions(tol=1e-2, tol_angle=1e-2, max_iter=1)
    program = filter_program(real, q, nominal, ik=loose)
    assert program.iterations.max() <= 1
    np.testing.assert_array_equal(program.q, filter_program(real, q, nominal, max_iter=1, tol=1e-2,
                                                           tol_angle=1e-2).q)  # fmt: skip
    path = compensate_path(real, q, nominal, ik=IKOptions(max_iter=1))
    full = compensate_path(real, q, nominal)
    assert np.abs(path.q - full.q).max() > 0  # the setting reached the path's IK
    with pytest.raises(ValueError, match="tool_axis"):
        compensate_path(real, q, nominal, tool_axis=5)
