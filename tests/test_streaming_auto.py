"""rc.calibrate streams large inputs by itself (robocal.identify.streaming_calibrate): the
decisions on a well-spread subsample, the final fit on all poses from normal equations
accumulated by chunks.  Just above a lowered threshold the streamed fit must agree with
the dense fit of the same poses: the same chosen model, estimates within a small fraction
of their σ, the same σ."""

import dataclasses

import numpy as np
import pytest

import robocal as rc
from robocal.identify.streaming_calibrate import Streaming, well_spread_subsample
from robocal.measure.measurements import Measurements
from robocal.model.joints import JointEffects, joint_perturbations

PROBE = np.array([0.0, 0.0, 0.1])
NOISE = 20e-6  # m
DENSE = Streaming(threshold=None)
STREAM = Streaming(threshold=1000, subsample=900, chunk=700)  # several chunks, a real subsample


def _data(n, *, compliance=False, angle_errors=False, seed=1):
    """UR10 poses uniform in its joint limits, tracker positions of a true robot with
    ±1 mm / ±0.05° errors (and joint compliances, and smooth joint angle errors), 20 µm noise."""
    model = rc.calibration_model("ur10")
    true = rc.measure.draw_true_model(model, length=1e-3, angle=np.radians(0.05), seed=seed)
    rng = np.random.default_rng(seed + 1)
    lim = np.clip(model.joint_limits, -np.pi, np.pi)
    q = rng.uniform(lim[:, 0], lim[:, 1], (n, model.dof))
    pert = np.zeros((n, model.dof, 3))
    if compliance:
        effects = (JointEffects("shoulder_lift", compliance=4e-6), JointEffects("elbow", compliance=6e-6))
        pert += joint_perturbations(dataclasses.replace(true, joint_effects=effects), q)
    if angle_errors:
        pert[:, 1, 2] += 3e-4 * np.sin(2 * q[:, 1] + 0.3)
        pert[:, 2, 2] += 2e-4 * np.cos(3 * q[:, 2])
    T = true.fk(q, pert)
    T_device_base = rc.spatial.homogeneous(rc.spatial.rotvec_to_matrix([0.1, -0.2, 2.0]), [2.0, -1.0, 0.3])
    p_base = T[:, :3, :3] @ PROBE + T[:, :3, 3]
    position = p_base @ T_device_base[:3, :3].T + T_device_base[:3, 3] + rng.normal(0, NOISE, (n, 3))
    return model, Measurements(q=q, position=position)


def _agree(dense, streamed, max_sigma):
    """The same unknowns; the robot's, tool's and joint effects' estimates within
    ``max_sigma`` of their σ, the same σ (2 %); the same device frame (its corrections
    ``frame_*`` are relative to each fit's start frame, so the frame is compared whole)."""
    assert streamed.names == dense.names
    keep = np.array([not n.startswith("frame_") for n in dense.names])
    z = (streamed.estimates - dense.estimates)[keep] / dense.std[keep]
    assert np.abs(z).max() < max_sigma, dict(zip(np.array(dense.names)[keep], np.round(z, 3), strict=True))
    np.testing.assert_allclose(streamed.std, dense.std, rtol=0.02)
    np.testing.assert_allclose(streamed.T_device_base, dense.T_device_base, atol=2e-6)
    assert streamed.n == dense.n and streamed.residuals.shape == dense.residuals.shape
    assert streamed.rms_after == pytest.approx(dense.rms_after, rel=0.01)


def test_geometric_calibration_streams_and_agrees_with_the_dense_fit():
    model, data = _data(1500)
    dense = rc.calibrate(model, data, tool_guess=PROBE, streaming=DENSE)
    streamed = rc.calibrate(model, data, tool_guess=PROBE, streaming=STREAM)
    assert dense.diagnostics.streaming is None
    record = streamed.diagnostics.streaming
    assert record["poses"] == 1500 and 900 <= record["subsample"] < 1500 and record["chunk"] == 700
    _agree(dense, streamed, 0.05)
    # the covariance comes from the streamed normal matrix: the prediction's uncertainty too
    np.testing.assert_allclose(
        streamed.position_uncertainty(data.q[:50]), dense.position_uncertainty(data.q[:50]), rtol=0.02
    )


def test_joint_compliance_streams_with_the_geometry():
    model, data = _data(1500, compliance=True, seed=3)
    dense = rc.calibrate(model, data, tool_guess=PROBE, compliance=True, streaming=DENSE)
    streamed = rc.calibrate(model, data, tool_guess=PROBE, compliance=True, streaming=STREAM)
    assert {"compliance_shoulder_lift", "compliance_elbow"} <= set(streamed.names)
    _agree(dense, streamed, 0.1)
    assert streamed.compliance["elbow"] == pytest.approx(dense.compliance["elbow"], rel=0.02)
    # the calibrated model carries the identified effects: its predictions are the fit's
    e = streamed.predict(data.q)[:, :3, 3] - data.position
    assert np.sqrt(np.mean(np.sum(e**2, axis=1))) == pytest.approx(streamed.rms_after, rel=1e-6)


def test_learned_residual_is_refitted_on_all_poses():
    model, data = _data(1500, angle_errors=True, seed=5)
    options = dict(tool_guess=PROBE, residual="auto", residual_harmonics=[8])
    dense = rc.calibrate(model, data, streaming=DENSE, **options)
    streamed = rc.calibrate(model, data, streaming=STREAM, **options)
    assert dense.model.residual is not None and streamed.model.residual is not None
    assert streamed.diagnostics.cv["chosen"] == dense.diagnostics.cv["chosen"]  # the same chosen model
    # the residual's coverage is all poses', not the subsample's
    assert streamed.model.residual.coverage == dense.model.residual.coverage
    assert streamed.residual_cross_covariance is not None
    _agree(dense, streamed, 0.3)
    q = data.q[:300]
    gap = np.linalg.norm(streamed.predict(q)[:, :3, 3] - dense.predict(q)[:, :3, 3], axis=1)
    assert gap.max() < 0.25 * NOISE  # the two calibrated robots predict the same


def test_small_inputs_and_other_solvers_stay_dense():
    model, data = _data(300)
    assert rc.calibrate(model, data, tool_guess=PROBE, streaming=STREAM).diagnostics.streaming is None
    big = data.subset(np.r_[np.arange(300), np.arange(300), np.arange(300), np.arange(300)])
    pinv = rc.calibrate(model, big, "pinv", tool_guess=PROBE, streaming=STREAM)
    assert pinv.diagnostics.streaming is None


def test_subsample_is_deterministic_and_spans_every_joint():
    q = np.random.default_rng(0).uniform(-3, 3, (10_000, 6))
    index = well_spread_subsample(q, 500)
    np.testing.assert_array_equal(index, well_spread_subsample(q, 500))
    assert 500 <= len(index) <= 512 and np.all(np.diff(index) > 0)
    np.testing.assert_array_equal(q[index].min(axis=0), q.min(axis=0))
    np.testing.assert_array_equal(q[index].max(axis=0), q.max(axis=0))
    with pytest.raises(ValueError, match="subsample"):
        Streaming(subsample=5)
