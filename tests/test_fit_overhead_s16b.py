"""Calibration overhead, session 16 (issue 35): the fused fit's evaluations and the facts
every calibration records, checked against the reference computations they replace."""

from __future__ import annotations

import numpy as np
import pytest

import robocal as rc
from robocal.model.kernels import segment_data
from robocal.model.kernels_evaluate import position_columns_transposed


def _columns_transposed(model: rc.Model, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    plan = model._plan
    seg, local = segment_data(model.values, plan.step_axis, plan.step_rot, plan.step_joint, model.dof)
    offsets = model.values[plan.joint_steps].copy()
    free = np.flatnonzero(model.free_mask)
    return position_columns_transposed(
        np.ascontiguousarray(q), seg, local, offsets, plan.joint_axis_array, plan.joint_rot_array,
        plan.anchor_of, plan.step_axis, plan.step_rot, free,
    )  # fmt: skip


@pytest.mark.parametrize("robot, n", [("ur10", 1), ("ur10", 100), ("kr16", 300), ("puma560_mdh", 257)])
def test_the_transposed_position_columns_are_the_identification_jacobian(robot, n):
    # the fused fit's evaluation: J's columns as rows (contiguous), the same numbers as the
    # compiled evaluation (the same formulas) and the numpy path's to round-off; more poses
    # than a block (256) and fewer (the work arrays are sized to the poses)
    model = rc.calibration_model(robot)
    rng = np.random.default_rng(n)
    lim = np.clip(model.joint_limits, -np.pi, np.pi)
    q = rng.uniform(lim[:, 0], lim[:, 1], (n, model.dof))
    T, Jt = _columns_transposed(model, q)
    T_compiled, J_compiled = model.fk_jacobian(q, compiled=True)
    T_numpy, J_numpy = model.fk_jacobian(q, compiled=False)
    assert Jt.shape == (int(model.free_mask.sum()), 3 * n) and Jt.flags.c_contiguous
    np.testing.assert_array_equal(T, np.asarray(T_compiled).reshape(n, 4, 4))
    np.testing.assert_array_equal(Jt.T, J_compiled)
    np.testing.assert_allclose(Jt.T, J_numpy, rtol=0, atol=1e-12)
    np.testing.assert_allclose(T, np.asarray(T_numpy).reshape(n, 4, 4), rtol=0, atol=1e-12)


def test_the_transposed_columns_of_no_poses_and_no_steps():
    model = rc.calibration_model("ur10")
    T, Jt = _columns_transposed(model, np.zeros((0, model.dof)))
    assert T.shape == (0, 4, 4) and Jt.shape == (int(model.free_mask.sum()), 0)
    fixed = model.with_free(None, free=False)
    T1, Jt1 = _columns_transposed(fixed, np.zeros((3, model.dof)))
    assert Jt1.shape == (0, 9)
    np.testing.assert_array_equal(T1, fixed.fk(np.zeros((3, model.dof)), compiled=True))
