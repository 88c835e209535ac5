"""Property tests (hypothesis): spatial math, chain FK and Jacobians on random chains.

Complements tests/test_spatial.py (round trips of the conversions) with properties that
hold for any input: batched equals one-by-one, small-angle consistency of the pose
error, exact recovery by the rigid fit, and for random chains of elementary steps: FK
equals the textbook product, the analytic Jacobians equal central differences, joint
perturbations equal the motions they stand for, files round-trip exactly.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from robocal import spatial
from robocal.model.chain import Model
from robocal.model.files import load_model, save_model
from robocal.model.steps import Joint, Step
from tests.reference import ELEMENTARY

FAST = settings(max_examples=60, deadline=None)

finite = st.floats(-10, 10, allow_nan=False, allow_infinity=False)
angle = st.floats(-np.pi, np.pi, allow_nan=False)
small_rotvec = arrays(float, 3, elements=st.floats(-2.5, 2.5, allow_nan=False))


def rigid(rv, p) -> np.ndarray:
    return spatial.homogeneous(spatial.rotvec_to_matrix(rv), p)


# ------------------------------------------------------------------ spatial
@FAST
@given(
    arrays(float, (2, 3, 3), elements=st.floats(-2.5, 2.5, allow_nan=False)),
    arrays(float, (2, 3, 3), elements=finite),
)
def test_batched_transforms_equal_one_by_one(rv, p):
    """Any leading batch shape: the same numbers as a Python loop over the elements."""
    T = spatial.homogeneous(spatial.rotvec_to_matrix(rv), p)
    assert T.shape == (2, 3, 4, 4)
    Ti = spatial.inverse(T)
    w = spatial.matrix_to_rotvec(T[..., :3, :3])
    q = spatial.matrix_to_quaternion(T[..., :3, :3])
    for i in range(2):
        for j in range(3):
            one = rigid(rv[i, j], p[i, j])
            np.testing.assert_allclose(T[i, j], one, atol=1e-15)
            np.testing.assert_allclose(Ti[i, j], spatial.inverse(one), atol=1e-12)
            np.testing.assert_allclose(w[i, j], spatial.matrix_to_rotvec(one[:3, :3]), atol=1e-12)
            np.testing.assert_allclose(q[i, j], spatial.matrix_to_quaternion(one[:3, :3]), atol=1e-12)
    assert np.all(q[..., 0] >= 0)  # canonical: w >= 0


@FAST
@given(st.sampled_from("xyz"), angle, angle)
def test_rotations_about_one_axis_add(axis, a, b):
    np.testing.assert_allclose(
        spatial.rot(axis, a) @ spatial.rot(axis, b), spatial.rot(axis, a + b), atol=1e-12
    )
    R = spatial.rot(axis, a)
    np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-12)
    assert np.linalg.det(R) == pytest.approx(1.0, abs=1e-12)


@FAST
@given(
    st.sampled_from(["xyz", "xzy", "yxz", "yzx", "zxy", "zyx", "XYZ", "ZYX", "ZXZ", "XZX", "yxy", "zyz"]),
    angle,
    st.floats(0.1, 1.4),
    angle,
)
def test_euler_round_trip_away_from_gimbal_lock(seq, a, b, c):
    tait_bryan = len(set(seq.lower())) == 3
    middle = b if tait_bryan else b + 0.1  # proper Euler: middle angle in (0, pi)
    R = spatial.euler_to_matrix([a, middle, c], seq)
    np.testing.assert_allclose(spatial.euler_to_matrix(spatial.matrix_to_euler(R, seq), seq), R, atol=1e-10)


@FAST
@given(small_rotvec, arrays(float, 3, elements=finite), arrays(float, 6, elements=st.floats(-1e-4, 1e-4)))
def test_pose_error_is_the_small_motion_that_separates_two_poses(rv, p, delta):
    """pose_error(exp(δ) T, T) = δ to first order; pose_error(T, T) = 0; antisymmetric."""
    T = rigid(rv, p)
    moved = T.copy()
    moved[:3, :3] = spatial.rotvec_to_matrix(delta[3:]) @ T[:3, :3]
    moved[:3, 3] += delta[:3]
    e = spatial.pose_error(moved, T)
    np.testing.assert_allclose(e, delta, atol=1e-10)
    np.testing.assert_allclose(spatial.pose_error(T, T), np.zeros(6), atol=1e-12)
    np.testing.assert_allclose(spatial.pose_error(T, moved)[:3], -delta[:3], atol=1e-15)
    np.testing.assert_allclose(
        spatial.pose_error(T, moved)[3:],
        -spatial.matrix_to_rotvec(spatial.rotvec_to_matrix(delta[3:])),
        atol=1e-10,
    )


@FAST
@given(
    small_rotvec,
    arrays(float, 3, elements=finite),
    arrays(float, (6, 3), elements=st.floats(-1, 1)),
    st.permutations(range(6)),
    arrays(float, 6, elements=st.floats(0.1, 10)),
)
def test_rigid_fit_recovers_any_transform(rv, p, P, order, w):
    """Noise-free points: the exact transform, whatever the order and the weights."""
    _, s, _ = np.linalg.svd(P - P.mean(axis=0))
    assume(s[1] > 1e-2)  # not (nearly) collinear
    T = rigid(rv, p)
    Q = P @ T[:3, :3].T + T[:3, 3]
    np.testing.assert_allclose(spatial.fit_rigid_transform(P, Q), T, atol=1e-9)
    order = list(order)
    np.testing.assert_allclose(spatial.fit_rigid_transform(P[order], Q[order], w[order]), T, atol=1e-9)


@FAST
@given(small_rotvec, arrays(float, 3, elements=finite), small_rotvec, arrays(float, 3, elements=finite))
def test_inverse_of_a_product_is_the_reversed_product_of_inverses(r1, p1, r2, p2):
    A, B = rigid(r1, p1), rigid(r2, p2)
    np.testing.assert_allclose(spatial.inverse(A @ B), spatial.inverse(B) @ spatial.inverse(A), atol=1e-10)


# ------------------------------------------------------------------ random chains
MOTIONS = ["Tx", "Ty", "Tz", "Rx", "Ry", "Rz"]


@st.composite
def chains(draw, max_steps: int = 9) -> Model:
    """A random chain of elementary steps with at least one joint; some steps fixed."""
    n = draw(st.integers(1, max_steps))
    steps = []
    joints = 0
    for i in range(n):
        motion = draw(st.sampled_from(MOTIONS))
        value = draw(st.floats(-np.pi, np.pi) if motion[0] == "R" else st.floats(-0.8, 0.8))
        is_joint = draw(st.booleans()) or (i == n - 1 and joints == 0)
        joint = Joint(f"j{joints}") if is_joint else None
        joints += bool(is_joint)
        steps.append(Step(motion, f"p{i}", value, free=draw(st.booleans()) or is_joint, joint=joint))
    return Model("random", tuple(steps))


def _reference_fk(model: Model, q: np.ndarray) -> np.ndarray:
    """Textbook product of the elementary matrices (tests/reference.py), one pose."""
    T = np.eye(4)
    j = 0
    for s in model.steps:
        v = s.value
        if s.joint is not None:
            v += q[j]
            j += 1
        T = T @ ELEMENTARY[s.motion](v)
    return T


def _configurations(draw, model: Model, n: int) -> np.ndarray:
    return np.array([[draw(st.floats(-np.pi, np.pi)) for _ in range(model.dof)] for _ in range(n)])


@FAST
@given(chains(), st.data())
def test_fk_is_the_product_of_the_elementary_transforms(model, data):
    q = _configurations(data.draw, model, 4)
    T = model.fk(q)
    assert T.shape == (4, 4, 4)
    for i in range(4):
        np.testing.assert_allclose(T[i], _reference_fk(model, q[i]), atol=1e-12)
        np.testing.assert_allclose(model.fk(q[i]), T[i], atol=1e-15)  # one pose: the same numbers
    np.testing.assert_allclose(T[:, 3], np.tile([0, 0, 0, 1.0], (4, 1)))


@FAST
@given(chains(), st.data())
def test_identification_jacobian_equals_central_differences(model, data):
    assume(model.free_names)
    q = _configurations(data.draw, model, 3)
    h = 1e-6
    J = model.jacobian(q, rows="pose").reshape(3, 6, -1)
    Jp = model.jacobian(q).reshape(3, 3, -1)
    np.testing.assert_allclose(Jp, J[:, :3], atol=1e-15)
    x0 = model.free_values
    for k in range(len(x0)):
        dx = np.zeros_like(x0)
        dx[k] = h
        Tp, Tm = model.with_free_values(x0 + dx).fk(q), model.with_free_values(x0 - dx).fk(q)
        dp = (Tp[:, :3, 3] - Tm[:, :3, 3]) / (2 * h)
        dw = spatial.matrix_to_rotvec(Tp[:, :3, :3] @ np.swapaxes(Tm[:, :3, :3], 1, 2)) / (2 * h)
        np.testing.assert_allclose(J[:, :3, k], dp, atol=1e-7)
        np.testing.assert_allclose(J[:, 3:, k], dw, atol=1e-7)


@FAST
@given(chains(), st.data())
def test_joint_jacobian_equals_central_differences(model, data):
    q = _configurations(data.draw, model, 2)
    h = 1e-6
    Jq = model.joint_jacobian(q)
    assert Jq.shape == (2, 6, model.dof)
    for j in range(model.dof):
        dq = np.zeros(model.dof)
        dq[j] = h
        Tp, Tm = model.fk(q + dq), model.fk(q - dq)
        np.testing.assert_allclose(Jq[:, :3, j], (Tp[:, :3, 3] - Tm[:, :3, 3]) / (2 * h), atol=1e-7)
        dw = spatial.matrix_to_rotvec(Tp[:, :3, :3] @ np.swapaxes(Tm[:, :3, :3], 1, 2)) / (2 * h)
        np.testing.assert_allclose(Jq[:, 3:, j], dw, atol=1e-7)


@FAST
@given(chains(), st.data())
def test_evaluate_at_other_values_equals_the_changed_model(model, data):
    """The solvers' fast path (values without a new model) and the public API agree."""
    q = _configurations(data.draw, model, 3)
    values = model.values + np.array([data.draw(st.floats(-0.1, 0.1)) for _ in model.steps])
    changed = model.with_values(dict(zip(model.names, values, strict=True)))
    T, J, Jq = model.evaluate(q, values, rows="pose", joint_columns=True)
    np.testing.assert_allclose(T, changed.fk(q), atol=1e-12)
    np.testing.assert_allclose(J, changed.jacobian(q, rows="pose"), atol=1e-12)
    np.testing.assert_allclose(Jq.reshape(3, 6, -1), changed.joint_jacobian(q), atol=1e-12)
    np.testing.assert_allclose(model.with_free_values(model.free_values).fk(q), model.fk(q), atol=0)


@FAST
@given(chains(), st.data())
def test_joint_perturbations_are_the_motions_they_stand_for(model, data):
    """δθ shifts the joint value; δα, δβ tilt the child frame about the joint frame's two
    other axes, x then y for a joint about z (chain.py, seed 003 eq. 5.9)."""
    q = _configurations(data.draw, model, 2)
    d = np.array(
        [[[data.draw(st.floats(-0.05, 0.05)) for _ in range(3)] for _ in range(model.dof)] for _ in range(2)]
    )
    T = model.fk(q, perturbations=d)
    for i in range(2):
        expected = np.eye(4)
        j = 0
        for s in model.steps:
            if s.joint is None:
                expected = expected @ ELEMENTARY[s.motion](s.value)
                continue
            expected = expected @ ELEMENTARY[s.motion](s.value + q[i, j] + d[i, j, 2])
            k = "xyz".index(s.motion[1])  # the joint's axis; the tilts are about the next two
            first, second = "xyz"[(k + 1) % 3], "xyz"[(k + 2) % 3]
            expected = expected @ ELEMENTARY["R" + first](d[i, j, 0]) @ ELEMENTARY["R" + second](d[i, j, 1])
            j += 1
        np.testing.assert_allclose(T[i], expected, atol=1e-12)


@FAST
@given(chains(), st.data())
def test_joint_frames_end_each_joint_step(model, data):
    q = _configurations(data.draw, model, 2)
    frames = model.joint_frames(q)
    assert frames.shape == (2, model.dof, 4, 4)
    joint_steps = [i for i, s in enumerate(model.steps) if s.joint is not None]
    for j, last in enumerate(joint_steps):
        head = Model("head", model.steps[: last + 1])
        np.testing.assert_allclose(frames[:, j], head.fk(q[:, : j + 1]), atol=1e-12)


@FAST
@given(chains(), st.data(), st.sampled_from(MOTIONS))
def test_a_zero_step_changes_nothing(model, data, motion):
    q = _configurations(data.draw, model, 2)
    where = data.draw(st.integers(0, len(model.steps)))
    steps = (*model.steps[:where], Step(motion, "extra", 0.0), *model.steps[where:])
    np.testing.assert_allclose(Model("padded", steps).fk(q), model.fk(q), atol=1e-14)


@settings(max_examples=25, deadline=None)
@given(chains())
def test_model_files_round_trip_exactly(model):
    import tempfile
    from pathlib import Path

    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "m.yaml"
        save_model(model, path)
        assert load_model(path) == model
