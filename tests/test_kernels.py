"""The compiled kernels (robocal.model.kernels, numba) against the numpy reference of
robocal.model.chain: forward kinematics, joint frames, the identification Jacobian and the
fused evaluation with joint and perturbation columns, to 1e-12."""

import numpy as np
import pytest

import robocal as rc
from robocal.model.chain import Model
from robocal.model.steps import Joint, Step

pytest.importorskip("numba")

TOL = 1e-12


def mixed_chain() -> Model:
    """Revolute and prismatic joints about all three axes, constant steps between them and
    a joint first and last (segments of every length, including empty ones)."""
    steps = (
        Step("Rz", "t1", 0.1, joint=Joint("q1")),
        Step("Tz", "d1", 0.3),
        Step("Rx", "a1", -0.2),
        Step("Ty", "s2", 0.05, joint=Joint("q2")),
        Step("Ry", "t3", 0.4, joint=Joint("q3")),
        Step("Tx", "a3", 0.25),
        Step("Ty", "b3", -0.1),
        Step("Rz", "g3", 0.3),
        Step("Tx", "s4", 0.0, joint=Joint("q4")),
        Step("Rx", "t5", -0.3, joint=Joint("q5")),
        Step("Tz", "tool", 0.12),
    )
    return Model("mixed", steps)


MODELS = {
    "ur10-calibration": lambda: rc.calibration_model("ur10"),
    "puma560": lambda: rc.robot("puma560"),
    "mixed": mixed_chain,
}


def close(a, b):
    assert a.shape == b.shape
    np.testing.assert_allclose(a, b, rtol=0, atol=TOL)


@pytest.fixture(params=sorted(MODELS))
def case(request):
    model = MODELS[request.param]()
    rng = np.random.default_rng(7)
    q = rng.uniform(-2.5, 2.5, (9, model.dof))
    pert = rng.normal(0.0, 0.02, (9, model.dof, 3))
    values = model.values + rng.normal(0.0, 1e-3, len(model.values))
    return model, q, pert, values


def test_fk_and_joint_frames(case):
    model, q, pert, _ = case
    for d in (None, pert):
        close(model.fk(q, d, compiled=True), model.fk(q, d, compiled=False))
        close(model.joint_frames(q, d, compiled=True), model.joint_frames(q, d, compiled=False))
    close(model.fk(q[0], compiled=True), model.fk(q[0], compiled=False))  # one configuration, (4, 4)
    # a non-contiguous q (a column slice) gives the same frames
    wide = np.concatenate([q, q], axis=1)[:, : model.dof]
    close(model.fk(wide, compiled=True), model.fk(q, compiled=False))


@pytest.mark.parametrize("rows", ["position", "pose"])
def test_identification_jacobian_and_fused_evaluation(case, rows):
    model, q, pert, values = case
    for a, b in zip(
        model.fk_jacobian(q, rows, pert, compiled=True),
        model.fk_jacobian(q, rows, pert, compiled=False),
        strict=True,
    ):
        close(a, b)
    for d in (None, pert):
        for options in (
            dict(jacobian=False),
            dict(),
            dict(joint_columns=True),
            dict(joint_columns=True, perturbation_columns=True),
            dict(jacobian=False, perturbation_columns=True),
        ):
            fast = model.evaluate(q, values, rows, perturbations=d, compiled=True, **options)
            ref = model.evaluate(q, values, rows, perturbations=d, compiled=False, **options)
            assert len(fast) == len(ref)
            for a, b in zip(fast, ref, strict=True):
                if b is None:
                    assert a is None
                else:
                    close(a, b)


@pytest.mark.parametrize("name", sorted(MODELS))
def test_block_kernels_over_several_blocks(name):
    """The structure-of-arrays kernels (batch FK, the identification Jacobian without
    perturbations) over two full blocks of poses and a partial one."""
    from robocal.model.kernels import BLOCK

    model = MODELS[name]()
    q = np.random.default_rng(3).uniform(-2.5, 2.5, (2 * BLOCK + 3, model.dof))
    close(model.fk(q, compiled=True), model.fk(q, compiled=False))
    for rows in ("position", "pose"):
        for a, b in zip(model.fk_jacobian(q, rows, compiled=True), model.fk_jacobian(q, rows, compiled=False),
                        strict=True):  # fmt: skip
            close(a, b)


def test_joint_jacobian_and_perturbation_jacobian(case):
    model, q, pert, _ = case
    from robocal.model import chain

    compiled = model.joint_jacobian(q, pert)
    P = model.perturbation_jacobian(q, "pose", pert)
    original = chain.kernels_loader
    try:
        chain.kernels_loader = lambda compiled=None: None  # the numpy path throughout
        close(compiled, model.joint_jacobian(q, pert))
        close(P, model.perturbation_jacobian(q, "pose", pert))
    finally:
        chain.kernels_loader = original


def test_calibration_is_the_same_with_the_numpy_path(monkeypatch):
    """A whole calibration through the compiled kernels equals the numpy one."""
    from robocal.model import chain

    model = rc.calibration_model("ur10")
    true = rc.measure.draw_true_model(model, length=1e-3, angle=np.radians(0.05), seed=2)
    robot = rc.measure.VirtualRobot(model, true, rc.measure.LaserTracker(p_tool_target=np.array([0, 0, 0.1])))
    data = rc.measure.simulate(robot, rc.measure.random_poses(model, 30, seed=4), seed=1)
    fast = rc.calibrate(model, data, tool_guess=[0, 0, 0.1])
    monkeypatch.setattr(chain, "kernels_loader", lambda compiled=None: None)
    ref = rc.calibrate(model, data, tool_guess=[0, 0, 0.1])
    np.testing.assert_allclose(fast.model.values, ref.model.values, rtol=0, atol=1e-10)


def test_leading_frame_is_the_product_of_the_first_steps():
    from robocal import spatial
    from robocal.identify.problem import measurement_chain
    from robocal.model import kernels

    rng = np.random.default_rng(3)
    T = spatial.homogeneous(R=spatial.rotvec_to_matrix(rng.normal(size=3)), p=rng.normal(size=3))
    chain = measurement_chain(rc.robot("ur10"), T, np.eye(4), "position", fit_frame=True)
    values = chain.values + rng.normal(scale=0.1, size=len(chain.values))
    plan = chain._plan

    def leading(values, n):
        return kernels.leading_frame(values, plan.step_axis, plan.step_rot, n)

    for n in (0, 6, 12):  # the fixed start, then with the free corrections
        want = spatial.chain_product([s.motion for s in chain.steps[:n]], values[:n])
        np.testing.assert_allclose(leading(values, n), want, atol=1e-15)
    np.testing.assert_allclose(leading(chain.values, 6), T, atol=1e-12)


@pytest.mark.parametrize("name", sorted(MODELS))
def test_direct_entry_points_equal_the_numpy_reference(name):
    """The one-configuration kernels (every joint turned into a z joint at packing) give
    the numpy path's frames and joint Jacobian, one configuration and many."""
    from robocal.model.chain_compiled import direct

    model = MODELS[name]()
    d = direct(model)
    q = np.random.default_rng(11).uniform(-2.5, 2.5, (7, model.dof))
    T_ref = model.fk(q, compiled=False)
    J_ref = model.joint_jacobian(q)
    for k in range(len(q)):
        assert d.fk(q[k], d.data)
        close(d.T, T_ref[k])
        d.T[:] = np.nan
        assert d.fk_jacobian(q[k], d.data)
        close(d.T, T_ref[k])
        np.testing.assert_allclose(d.J, J_ref[k], rtol=0, atol=1e-12)
        T1 = np.empty((4, 4))
        assert model.fk(q[k]) is not None and rc.model.kernels.fk_one(q[k], model._fk_one_data, T1)
        close(T1, T_ref[k])
    Ts, Js = np.empty((len(q), 4, 4)), np.empty((len(q), 6, model.dof))
    assert d.fk_many(q, d.data, Ts, Js, True)
    close(Ts, T_ref)
    np.testing.assert_allclose(Js, J_ref, rtol=0, atol=1e-12)


def test_direct_joint_jacobian_is_the_derivative_of_fk():
    """Central differences of the direct FK (prismatic joints and joints about x, y, z)."""
    from robocal.model.chain_compiled import direct

    model = mixed_chain()
    d = direct(model)
    q = np.random.default_rng(5).uniform(-2.0, 2.0, model.dof)
    assert d.fk_jacobian(q, d.data)
    J = d.J.copy()
    h = 1e-6
    for j in range(model.dof):
        dq = np.zeros(model.dof)
        dq[j] = h
        d.fk(q + dq, d.data)
        Tp = d.T.copy()
        d.fk(q - dq, d.data)
        Tm = d.T.copy()
        S = (Tp[:3, :3] - Tm[:3, :3]) @ (Tp[:3, :3] + Tm[:3, :3]).T / (4 * h)  # skew(ω)
        np.testing.assert_allclose(J[:3, j], (Tp[:3, 3] - Tm[:3, 3]) / (2 * h), atol=1e-8)
        np.testing.assert_allclose(J[3:, j], [S[2, 1], S[0, 2], S[1, 0]], atol=1e-8)


def test_direct_entry_points_refuse_what_does_not_fit():
    """Wrong length, NaN/inf or a wrong output shape: False and the outputs left as they were."""
    from robocal.model.chain_compiled import direct

    model = rc.robot("ur10")
    d = direct(model)
    d.T[:] = 7.0
    for bad in (np.zeros(5), np.zeros(7), np.array([0, 0, np.nan, 0, 0, 0.0]), np.full(6, np.inf)):
        assert not d.fk(bad, d.data)
        assert not d.fk_jacobian(bad, d.data)
        assert not rc.model.kernels.fk_one(bad, model._fk_one_data, np.empty((4, 4)))
    assert np.all(d.T == 7.0)
    q = np.zeros((3, 6))
    assert not d.fk_many(q, d.data, np.empty((2, 4, 4)), np.empty((3, 6, 6)), True)
    assert not d.fk_many(q, d.data, np.empty((3, 4, 4)), np.empty((3, 6, 5)), True)
    assert not rc.model.kernels.fk_jacobian_one(q[0], d.data, np.empty((4, 4)), np.empty((6, 5)))
    assert not d.fk(q[0], d.data[:-1])  # no room for the outputs


@pytest.mark.parametrize("name", sorted(MODELS))
def test_model_fk_of_one_configuration_takes_every_layout(name):
    """``Model.fk(q)`` and ``Model.joint_jacobian(q)`` of one configuration (the kernels'
    wrappers called without numba's dispatch) equal the general paths for float64 vectors
    of any strides, alignment or writeability, and for the inputs the wrapper must not see
    (other dtypes, byte order, subclasses, lists) through the general path; a new array
    per call."""
    model = MODELS[name]()
    rng = np.random.default_rng(17)
    q = rng.uniform(-2.5, 2.5, model.dof)
    want = model.fk(q, compiled=False)
    wide = np.repeat(q, 3)[::3]  # strided
    raw = np.zeros(8 * model.dof + 1, dtype=np.uint8)
    unaligned = np.frombuffer(raw[1:].data, dtype=np.float64)
    unaligned[:] = q
    readonly = q.copy()
    readonly.flags.writeable = False
    inputs = [q, wide, unaligned, readonly, q.astype(">f8"), q.astype(np.float32).astype(float), list(q)]
    inputs += [np.asarray(q).view(np.recarray).view(np.ndarray), q.astype(np.longdouble)]
    for x in inputs:
        as_float = np.asarray(x, dtype=float)
        close(model.fk(x), model.fk(as_float, compiled=False))
        J_want = model.joint_jacobian(as_float[None])[0]  # the general (batched) path
        np.testing.assert_allclose(model.joint_jacobian(x), J_want, rtol=0, atol=TOL)
    close(model.fk(q), want)
    assert model.fk(q) is not model.fk(q)
    assert model.joint_jacobian(q) is not model.joint_jacobian(q)
    assert not np.shares_memory(model.fk(q), model._fk_one_data)
    if model.dof == 6:
        qi = np.arange(6)  # int64: same item size as float64, so must not reach the wrapper
        close(model.fk(qi), model.fk(qi.astype(float), compiled=False))


def test_model_fk_of_one_configuration_refuses_what_does_not_fit():
    """A wrong length or NaN/inf: the general path's ValueError, not a frame or Jacobian."""
    model = rc.robot("ur10")
    for bad in (np.zeros(5), np.zeros(7), np.array([0, 0, np.nan, 0, 0, 0.0]), np.zeros((1, 1, 6))):
        with pytest.raises(ValueError):
            model.fk(bad)
        with pytest.raises(ValueError):
            model.joint_jacobian(bad)
