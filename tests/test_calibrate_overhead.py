"""The fixed Python cost of a calibration (issue 35: the 100-pose calibration in 0.5 ms):
what it must not do again per call, counted (no timing here: benchmarks/bench_calibrate.py
times it), and the faster helpers held to the plain definitions they replace."""

from __future__ import annotations

import numpy as np
import pytest

import robocal as rc
from robocal.identify.coverage import COVER_M, COVER_RAD, joint_coverage
from robocal.measure import LaserTracker, VirtualRobot, draw_true_model, simulate
from robocal.measure.poses import random_poses
from robocal.model.chain import Model
from robocal.model.flange_tool import split_tool, tool_steps

TOOL = np.array([0.05, 0.0, 0.109])


def _data(name: str = "ur10", n: int = 100, seed: int = 1):
    model = rc.robot(name)
    device = LaserTracker(p_tool_target=TOOL, sigma=20e-6)
    true = draw_true_model(model, seed=seed)
    poses = random_poses(model, n, seed=seed + 1)
    return model, simulate(VirtualRobot(model, true, device), poses, seed=seed + 2)


def test_a_calibration_builds_no_checked_model(monkeypatch):
    """Every model a calibration makes is derived from checked ones (its steps and values
    already checked): none goes through ``Model.__post_init__``'s checks again, the
    calibrated robot's tool facts included (they read the tool's steps, not a robot
    rebuilt without them)."""
    model, data = _data()
    first = rc.calibrate(model, data)
    built = []
    original = Model.__post_init__

    def counted(self):
        built.append(self.name)
        original(self)

    monkeypatch.setattr(Model, "__post_init__", counted)
    again = rc.calibrate(model, data)
    assert built == []
    assert again.records["measured_tool"] == first.records["measured_tool"]
    assert again.records["coverage"] == first.records["coverage"]


def test_tool_steps_are_split_tools_steps():
    """:func:`tool_steps` (no robot model built) answers as :func:`split_tool`, and refuses
    the same misplaced tool step."""
    model, data = _data(n=40)
    calibrated = rc.calibrate(model, data).model
    assert tool_steps(calibrated) == split_tool(calibrated).steps
    assert [s.name for s in tool_steps(calibrated)] == ["tcp_x", "tcp_y", "tcp_z"]
    assert tool_steps(model) == () == split_tool(model).steps
    misplaced = Model("misplaced", (tool_steps(calibrated)[0], *model.steps))
    with pytest.raises(ValueError, match="tcp_x"):
        tool_steps(misplaced)
    with pytest.raises(ValueError, match="tcp_x"):
        split_tool(misplaced)


def _union(values, half):
    """The union of ``[v - half, v + half]`` over the finite values, one value at a time."""
    out: list[list[float]] = []
    for v in np.sort(values[np.isfinite(values)]):
        if out and v - half <= out[-1][1]:
            out[-1][1] = float(v + half)
        else:
            out.append([float(v - half), float(v + half)])
    return tuple((lo, hi) for lo, hi in out)


class _Joints:
    """A stand-in for a model with revolute and prismatic joints (what joint_coverage reads)."""

    joint_types = ("revolute", "prismatic", "revolute", "prismatic")
    joint_names = ("a", "b", "c", "d")
    dof = 4


def test_joint_coverage_of_mixed_joints_is_each_joints_union():
    """The coverage of all joints at once (one set of numpy operations) is each joint's own
    union: revolute values wrapped onto the circle, prismatic ones as they are, NaN left
    out, a joint without a finite value covered nowhere, no poses at all."""
    rng = np.random.default_rng(7)
    model = _Joints()
    for k in range(200):
        q = rng.uniform(-4.0, 4.0, (int(rng.integers(0, 30)), 4)) * rng.choice([0.01, 0.1, 1.0], 4)
        if k % 3 == 0 and len(q):
            q[rng.random(q.shape) < 0.3] = np.nan
        if k % 5 == 0:
            q[:, 3] = np.nan
        got = joint_coverage(model, q)
        wrapped = np.remainder(q + np.pi, 2 * np.pi) - np.pi
        expected = tuple(
            _union(wrapped[:, j], COVER_RAD) if revolute else _union(q[:, j], COVER_M)
            for j, revolute in enumerate((True, False, True, False))
        )
        assert got.intervals == expected
        assert got.revolute == (True, False, True, False)
