import dataclasses

import numpy as np
import pytest

import robocal as rc
from robocal.model.chain import Model
from robocal.model.conventions import dh, frame6, model_from_steps, tool_point
from robocal.model.steps import Joint, Step
from robocal.spatial import pose_error
from tests.reference import product

CATALOG = rc.robots()


def random_q(model: Model, n: int, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    lim = np.clip(model.joint_limits, -np.pi, np.pi)
    return rng.uniform(lim[:, 0], lim[:, 1], size=(n, model.dof))


def numeric_jacobian(model: Model, q, rows: str, perturbations=None, h: float = 1e-6) -> np.ndarray:
    """Central finite differences of the tool pose wrt the free parameters."""
    x0 = model.free_values
    cols = []
    for k in range(len(x0)):
        xp, xm = x0.copy(), x0.copy()
        xp[k] += h
        xm[k] -= h
        Tp = model.with_free_values(xp).fk(q, perturbations)
        Tm = model.with_free_values(xm).fk(q, perturbations)
        d = pose_error(Tp, Tm) / (2 * h)
        cols.append((d[:, :3] if rows == "position" else d).reshape(-1))
    return np.stack(cols, axis=1)


def assert_close_relative(J, J_ref, rel=1e-6):
    scale = np.abs(J_ref).max()
    np.testing.assert_allclose(J, J_ref, rtol=rel, atol=rel * scale)


def with_base_and_tool(model: Model) -> Model:
    """The model with a 6-parameter base frame and a tool point, all free (off-nominal)."""
    return model_from_steps(
        model.name + "_bt",
        frame6("mount", 0.1, -0.2, 0.3, 0.4, -0.3, 0.2),
        model.steps,
        tool_point(0.01, 0.02, 0.109, prefix="probe"),
    )


@pytest.mark.parametrize("name", CATALOG)
@pytest.mark.parametrize("rows", ["position", "pose"])
def test_identification_jacobian_matches_finite_differences(name, rows):
    model = with_base_and_tool(rc.robot(name))
    q = random_q(model, 7, seed=sum(map(ord, name)))
    J = model.jacobian(q, rows=rows)
    width = 3 if rows == "position" else 6
    assert J.shape == (width * len(q), len(model.free_names))
    assert_close_relative(J, numeric_jacobian(model, q, rows))


@pytest.mark.parametrize("name", CATALOG)
def test_jacobian_with_joint_perturbations_matches_finite_differences(name):
    model = rc.robot(name)
    q = random_q(model, 5, seed=3)
    pert = np.random.default_rng(4).normal(scale=1e-3, size=(5, model.dof, 3))
    J = model.jacobian(q, rows="pose", perturbations=pert)
    assert_close_relative(J, numeric_jacobian(model, q, "pose", pert))


@pytest.mark.parametrize("name", CATALOG)
def test_joint_jacobian_matches_finite_differences(name):
    model = rc.robot(name)
    q = random_q(model, 6, seed=5)
    J = model.joint_jacobian(q)
    assert J.shape == (6, 6, model.dof)
    h = 1e-6
    for j in range(model.dof):
        qp, qm = q.copy(), q.copy()
        qp[:, j] += h
        qm[:, j] -= h
        num = pose_error(model.fk(qp), model.fk(qm)) / (2 * h)
        assert_close_relative(J[:, :, j], num)


def test_joint_offset_column_equals_joint_column():
    model = rc.robot("ur10")
    q = random_q(model, 4)
    J = model.jacobian(q, rows="pose").reshape(4, 6, -1)
    Jq = model.joint_jacobian(q)
    for j in range(6):
        col = model.free_names.index(f"theta{j + 1}")
        np.testing.assert_allclose(J[:, :, col], Jq[:, :, j], atol=1e-15)


def test_fixed_parameters_leave_the_jacobian():
    model = rc.robot("ur10").fixed(["d1", "alpha6"])
    assert "d1" not in model.free_names and "alpha6" not in model.free_names
    assert model.jacobian(random_q(model, 2)).shape == (6, 22)
    assert model.with_free(["d1"]).jacobian(random_q(model, 2)).shape == (6, 23)


def test_fk_against_explicit_product_for_any_chain():
    """A chain of all six motions, two joints, checked against the plain product."""
    motions = ["Tx", "Rz", "Ty", "Rx", "Tz", "Ry", "Tx", "Rz"]
    values = [0.1, 0.2, -0.3, 0.4, 0.5, -0.6, 0.7, 0.8]
    steps = [
        Step(m, f"p{i}", v, joint=Joint(f"q{i}") if i in (1, 5) else None)
        for i, (m, v) in enumerate(zip(motions, values, strict=True))
    ]
    model = Model("toy", tuple(steps))
    q = np.array([[0.3, -1.2], [2.0, 0.1]])
    for qk, T in zip(q, model.fk(q), strict=True):
        v = list(values)
        v[1] += qk[0]
        v[5] += qk[1]
        np.testing.assert_allclose(T, product(motions, v), atol=1e-14)


def test_prismatic_joint_translates_along_its_axis():
    steps = [
        Step("Tz", "d1", 0.2, joint=Joint("q1")),
        Step("Tx", "a1", 0.1),
        Step("Rz", "theta2", 0.0, joint=Joint("q2")),
    ]
    model = Model("rp", tuple(steps))
    assert model.joint_types == ("prismatic", "revolute")
    T = model.fk([0.5, 0.0])
    np.testing.assert_allclose(T[:3, 3], [0.1, 0.0, 0.7])


def test_joint_frames_are_the_frames_after_each_joint_step():
    model = rc.robot("ur10")
    q = random_q(model, 3)
    frames = model.joint_frames(q)
    assert frames.shape == (3, 6, 4, 4)
    # the last joint frame times the constant rest of the chain is the tool frame
    rest = product(["Tz", "Tx", "Rx"], [model.step(n).value for n in ("d6", "a6", "alpha6")])
    np.testing.assert_allclose(frames[:, -1] @ rest, model.fk(q), atol=1e-14)
    # the joint frame's origin lies on the joint axis: it is the partial chain's end
    partial = model_from_steps("p", model.steps[:5])  # up to and including theta2
    np.testing.assert_allclose(frames[:, 1], partial.fk(q[:, :2]), atol=1e-14)


def test_perturbations_are_joint_angle_then_tilt_in_the_joint_frame():
    """(δα, δβ, δθ) = δθ added to the joint variable, then Rx(δα) Ry(δβ) after a z joint."""
    base = rc.robot("katana450")
    q = random_q(base, 4, seed=9)
    pert = np.random.default_rng(2).normal(scale=1e-2, size=(4, base.dof, 3))
    T = base.fk(q, perturbations=pert)
    for k in range(len(q)):
        steps = []
        j = 0
        for s in base.steps:
            if s.joint is None:
                steps.append(s)
                continue
            steps.append(dataclasses.replace(s, value=s.value + pert[k, j, 2]))
            steps.append(Step("Rx", f"tilt_a{j}", pert[k, j, 0]))
            steps.append(Step("Ry", f"tilt_b{j}", pert[k, j, 1]))
            j += 1
        explicit = Model("explicit", tuple(steps))
        np.testing.assert_allclose(T[k], explicit.fk(q[k]), atol=1e-14)


def test_single_configuration_drops_the_batch_axis():
    model = rc.robot("ur10")
    assert model.fk(np.zeros(6)).shape == (4, 4)
    assert model.jacobian(np.zeros(6)).shape == (3, 24)
    assert model.jacobian(np.zeros(6), rows="pose").shape == (6, 24)
    assert model.joint_jacobian(np.zeros(6)).shape == (6, 6)


def test_bad_joint_values_are_rejected_with_the_joint_named():
    model = rc.robot("ur10")
    with pytest.raises(ValueError, match=r"expected \(n, 6\)"):
        model.fk(np.zeros((2, 5)))
    q = np.zeros((3, 6))
    q[2, 4] = np.nan
    with pytest.raises(ValueError, match="pose 2, joint wrist_2"):
        model.fk(q)
    with pytest.raises(ValueError, match="perturbations"):
        model.fk(np.zeros((2, 6)), perturbations=np.zeros((2, 6, 2)))
    with pytest.raises(ValueError, match="rows must be"):
        model.jacobian(np.zeros(6), rows="orientation")


def test_models_are_immutable_values():
    model = rc.robot("ur10")
    x = model.free_values + 1e-3
    changed = model.with_free_values(x)
    np.testing.assert_array_equal(changed.free_values, x)
    assert model.free_values[0] == 0.0 and changed != model
    assert changed.with_free_values(model.free_values) == model
    with pytest.raises(dataclasses.FrozenInstanceError):
        model.name = "other"
    with pytest.raises(ValueError, match="24 free parameters"):
        model.with_free_values(x[:3])
    with pytest.raises(KeyError, match="no parameter 'nope'"):
        model.with_values({"nope": 1.0})


def test_invalid_chains_are_rejected():
    with pytest.raises(ValueError, match="used twice"):
        Model("m", (Step("Tx", "a", 1.0), Step("Ty", "a", 1.0)))
    with pytest.raises(ValueError, match="motion 'Tw'"):
        Step("Tw", "a")
    with pytest.raises(ValueError, match="not finite"):
        Step("Tx", "a", float("nan"))
    with pytest.raises(ValueError, match="joint name 'q' is used twice"):
        Model("m", (Step("Rz", "a", joint=Joint("q")), Step("Rz", "b", joint=Joint("q"))))
    with pytest.raises(ValueError, match="limits"):
        Joint("q", (1.0, -1.0))
    with pytest.raises(ValueError, match="no steps"):
        Model("m", ())


def test_dh_builder_matches_closed_form_matrix():
    from tests.reference import dh_matrix

    model = model_from_steps("one", dh(1, 0.3, 0.2, 0.5, -0.7))
    for q in (-1.0, 0.0, 2.5):
        np.testing.assert_allclose(model.fk([q]), dh_matrix(0.3 + q, 0.2, 0.5, -0.7), atol=1e-15)
