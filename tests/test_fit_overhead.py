"""The fixed Python cost of a fit (issue 35, the 100-pose calibration in 0.5 ms): what a
calibration no longer works out eagerly, or works out from what the fit already has, gives
the same numbers as before.

* ``result.records``' ``coverage`` and ``measured_tool`` are worked out when first read
  (:class:`robocal.identify.measured_tool.PoseFacts`): equal to the eager computation,
  computed once, from the poses as they were at the call, and pickled as a plain dict;
* the tool axes from the measurement chain the calibration built equal those of a new
  robot model's forward kinematics;
* the measured tool's covariance from the estimated block equals ``J Σ Jᵀ`` over all tool
  steps, and its derivative matches finite differences for a tool with rotations.
"""

from __future__ import annotations

import pickle

import numpy as np
import pytest

import robocal as rc
from robocal import spatial
from robocal.identify import coverage
from robocal.identify import measured_tool as mt
from robocal.measure.devices import LaserTracker
from robocal.measure.measurements import Measurements
from robocal.measure.simulate import VirtualRobot, simulate
from robocal.measure.true_model import draw_true_model


@pytest.fixture(scope="module")
def calibrated():
    """A UR10 calibrated from 60 simulated tracker poses: (model, data, result)."""
    model = rc.calibration_model("ur10")
    true = draw_true_model(model, seed=3)
    frame = spatial.homogeneous(spatial.rotvec_to_matrix([0.1, -0.2, 1.0]), [2.0, -1.0, 0.3])
    device = LaserTracker(T_device_base=frame, p_tool_target=np.zeros(3), sigma=20e-6)
    lim = np.clip(model.joint_limits, -np.pi, np.pi)
    q = np.random.default_rng(4).uniform(lim[:, 0], lim[:, 1], (60, model.dof))
    data = simulate(VirtualRobot(model, true, device), q, seed=5)
    return model, data, rc.calibrate(model, data, tool_guess=np.array([0.0, 0.0, 0.1]))


def _eager_records(result, q):
    tool = mt.measured_tool(result)
    return {
        "coverage": coverage.joint_coverage(result.model, q).to_dict(),
        "measured_tool": tool.to_dict() | mt.tool_axis_coverage(result.model, q),
    }


def _assert_close(a, b):
    """Nested dicts/lists of numbers equal to 1e-12 (relative), other values exactly."""
    if isinstance(a, dict):
        assert list(a) == list(b)
        for key in a:
            _assert_close(a[key], b[key])
    elif isinstance(a, list | tuple):
        assert len(a) == len(b)
        for x, y in zip(a, b, strict=True):
            _assert_close(x, y)
    elif isinstance(a, float):
        assert a == pytest.approx(b, rel=1e-12, abs=1e-12)
    else:
        assert a == b


def test_lazy_records_equal_the_eager_ones(calibrated):
    _, data, result = calibrated
    assert list(result.records) == ["coverage", "measured_tool"]
    _assert_close(dict(result.records), _eager_records(result, data.q))
    assert result.records["measured_tool"]["given_mm"] == pytest.approx([0.0, 0.0, 100.0])


def test_records_are_worked_out_once_when_read(calibrated, monkeypatch):
    model, data, _ = calibrated
    calls = []
    real = coverage.joint_coverage

    def counted(*args, **kwargs):
        calls.append(1)
        return real(*args, **kwargs)

    monkeypatch.setattr(coverage, "joint_coverage", counted)
    result = rc.calibrate(model, data)
    assert calls == []  # the calibration itself did not work it out
    first = result.records["coverage"]
    assert len(calls) == 1
    assert result.records["coverage"] is first
    assert len(calls) == 1
    assert result.records.get("missing") is None and "coverage" in result.records


def test_records_keep_the_poses_of_the_call(calibrated):
    model, data, _ = calibrated
    q = data.q.copy()
    mine = Measurements(q=q, position=data.position.copy())
    result = rc.calibrate(model, mine)
    q[:] = 0.0  # the caller's array changes after the call: the records do not
    _assert_close(dict(result.records), _eager_records(result, data.q))


def test_records_pickle_as_a_plain_dict(calibrated):
    _, data, result = calibrated
    back = pickle.loads(pickle.dumps(result.records))
    assert type(back) is dict
    _assert_close(back, _eager_records(result, data.q))
    assert result.records == back and back == result.records
    assert pickle.loads(pickle.dumps(result)).records == back


def test_records_keep_the_given_keys_first():
    later = {"b": lambda: 2, "c": lambda: 3}
    facts = mt.PoseFacts({"a": 1, "b": 0}, later)
    assert list(facts) == ["a", "b", "c"] and len(facts) == 3
    assert dict(facts) == {"a": 1, "b": 2, "c": 3}
    with pytest.raises(KeyError):
        facts["d"]


def test_tool_axes_from_the_measurement_chain(calibrated):
    _, data, result = calibrated
    from_chain = mt.result_tool_axis_coverage(result, data.q)
    from_model = mt.tool_axis_coverage(result.model, data.q)
    assert from_chain["tool_axis_base"] == pytest.approx(from_model["tool_axis_base"], abs=1e-13)
    assert from_chain["tool_axis_spread_deg"] == pytest.approx(from_model["tool_axis_spread_deg"], abs=1e-9)


def test_tool_point_derivative_with_rotations():
    motions = ["Tx", "Rz", "Ty", "Ry", "Tz", "Rx", "Tz"]
    values = [0.02, 0.3, -0.05, -0.4, 0.11, 0.2, 0.03]
    p, J = mt._point_and_derivative(motions, values)
    assert p == pytest.approx(spatial.chain_product(motions, values)[:3, 3], abs=1e-15)
    h = 1e-7
    for k in range(len(values)):
        up, down = list(values), list(values)
        up[k] += h
        down[k] -= h
        numeric = (
            spatial.chain_product(motions, up)[:3, 3] - spatial.chain_product(motions, down)[:3, 3]
        ) / (2 * h)
        assert J[:, k] == pytest.approx(numeric, abs=1e-8)


def test_tool_covariance_from_the_estimated_block(calibrated):
    _, _, result = calibrated
    steps = mt.tool_steps(result.model)
    names = list(result.names)
    # drop one tool component from the estimates: it adds nothing to the point's covariance
    gone = names.index(steps[1].name)
    keep = [k for k in range(len(names)) if k != gone]
    partial = result.replace(
        names=tuple(names[k] for k in keep), covariance=result.covariance[np.ix_(keep, keep)]
    )
    tool = mt.measured_tool(partial)
    _, J = mt._point_and_derivative([s.motion for s in steps], [s.value for s in steps])
    Sigma = np.zeros((len(steps), len(steps)))
    at = [names.index(s.name) for s in steps]
    for a, i in enumerate(at):
        for b, j in enumerate(at):
            if gone not in (i, j):
                Sigma[a, b] = result.covariance[i, j]
    assert np.asarray(tool.covariance_m2) == pytest.approx(J @ Sigma @ J.T, rel=1e-12, abs=1e-30)
    assert tool.estimated == (True, False, True)
