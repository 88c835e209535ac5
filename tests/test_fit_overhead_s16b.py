"""Calibration overhead, session 16 (issue 35): the fused fit's evaluations and the facts
every calibration records, checked against the reference computations they replace."""

from __future__ import annotations

import math

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


def _serial_squares(column) -> float:
    s = 0.0
    for v in column.tolist():
        s += v * v
    return s


@pytest.mark.parametrize("p", [1, 3, 4, 7, 36])
def test_the_interleaved_sums_are_the_serial_ones_to_the_bit(p):
    # the first pass's column norms and the displacement scales run four columns at a time;
    # each sum and maximum keeps its own order: the same bits as one column at a time (the
    # staged rank test's norms, numpy's along the rows, are held to them in test_fused)
    import robocal.identify.kernels.fused as fused_kernels

    rng = np.random.default_rng(p)
    m = 3 * 41
    St = rng.normal(size=(p + 2, m)) * rng.uniform(1e-3, 1e3, size=(p + 2, 1))
    row = rng.permutation(p + 2)[:p].astype(np.intp)
    norm = fused_kernels._squared_norms(St, row)
    assert norm.tolist() == [_serial_squares(St[r]) for r in row]
    J = np.asfortranarray(St[:p].T)
    scale = fused_kernels._displacement_scale(J)
    points = J.reshape(-1, 3, p)
    expected = [math.sqrt(max([0.0] + [_serial_squares(points[i, :, a]) for i in range(len(points))]))
                for a in range(p)]  # fmt: skip
    assert scale.tolist() == expected
