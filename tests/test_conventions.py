"""Every link parameterisation of seed 000 eqs. (11)-(27) is expressible as a chain.

The motion sequences below are typed in again from the seed's text (not taken from
robocal) so that a transcription error in ``SCHROER_SETS`` fails here too.
"""

import numpy as np
import pytest

from robocal.model.conventions import (
    SCHROER_SETS,
    dh,
    frame6,
    hayati,
    mdh,
    model_from_steps,
    schroer,
    sequence,
    tool_point,
    veitschegger,
)
from tests.reference import dh_matrix, mdh_matrix, product

D = np.pi / 180

# seed 000, as printed: (equation, motions, starts at a joint)
SEED000 = [
    (11, "TX TY TZ RZ RX", False),
    (12, "TX TY TZ RX RY", False),
    (13, "TY TZ RZ RX", False),
    (14, "TX TZ RZ RX", False),
    (15, "TX TY RX RY", False),
    (16, "RZ TZ TX RX TZ", True),
    (17, "RZ TX RX RY TZ", True),
    (18, "TZ RZ TX RX TZ", True),
    (19, "TZ TX TY RX RY TZ", True),
    (20, "TZ TX TY RZ RX", True),
    (21, "TZ TX TY RX RY", True),
    (22, "RZ TX TY TZ RX", True),
    (23, "RZ TX TY TZ RX RY", True),
    (24, "TZ TY TX RZ RY RZ", True),
    (25, "TZ TY TX RZ RY RX", True),
    (26, "RZ TX TY TZ RZ RY RZ", True),
    (27, "RZ TX TY TZ RZ RY RX", True),
]


def _motions(text):
    return [m[0] + m[1].lower() for m in text.split()]


@pytest.mark.parametrize(
    ("equation", "text", "starts_at_joint"), SEED000, ids=[f"eq{e}" for e, _, _ in SEED000]
)
def test_seed000_link_parameterisation_is_expressible(equation, text, starts_at_joint):
    motions = _motions(text)
    assert SCHROER_SETS[equation] == tuple(motions)
    rng = np.random.default_rng(equation)
    values = rng.uniform(-1, 1, len(motions))
    names = [f"p{equation}_{k}" for k in range(len(motions))]
    steps = schroer(equation, values, names)
    model = model_from_steps(f"eq{equation}", steps)
    assert model.names == tuple(names)
    assert model.dof == (1 if starts_at_joint else 0)
    if starts_at_joint:
        kind = "revolute" if motions[0] == "Rz" else "prismatic"
        assert model.joint_types == (kind,)
        for q in (-0.7, 0.0, 1.3):
            v = values.copy()
            v[0] += q
            np.testing.assert_allclose(model.fk([q]), product(motions, v), atol=1e-14)
    else:
        np.testing.assert_allclose(model.fk(np.zeros(0)), product(motions, values), atol=1e-14)
    # each parameter moves the frame (no dead parameter in the chain)
    q = np.zeros(model.dof)
    J = model.jacobian(q, rows="pose")
    assert np.all(np.linalg.norm(J, axis=0) > 0)


def _frame_after(steps):
    model = model_from_steps("x", steps)
    return model.fk(np.zeros(model.dof))


@pytest.mark.parametrize(
    ("equation", "values_deg_or_len", "z_axis"),
    [
        # seed 000 eq. (28): z of the next joint along +x_r
        (28, (90, "pz", "py", 90, "px"), (1, 0, 0)),
        # eq. (29): z along -x_r
        (29, (90, "pz", "py", -90, "-px"), (-1, 0, 0)),
        # eq. (30) as printed, RZ(0) TZ(pz) TX(py) RX(-90) TZ(-py), puts the origin at
        # (py, -py, pz): a typo.  With TX(px) and TZ(py) the origin is (px, py, pz), z along +y_r.
        (30, (0, "pz", "px", -90, "py"), (0, 1, 0)),
        # eq. (31): z along -y_r
        (31, (0, "pz", "px", 90, "-py"), (0, -1, 0)),
    ],
)
def test_seed000_dh_cases_reach_the_next_joint(equation, values_deg_or_len, z_axis):
    px, py, pz = 0.3, -0.2, 0.5
    lengths = {"px": px, "py": py, "pz": pz, "-px": -px, "-py": -py}
    vals = [lengths[v] if isinstance(v, str) else v * D for v in values_deg_or_len]
    vals[0], vals[3] = values_deg_or_len[0] * D, values_deg_or_len[3] * D
    T = _frame_after(schroer(16, vals, ["t", "d", "a", "al", "d2"]))
    np.testing.assert_allclose(T[:3, 2], z_axis, atol=1e-15)
    np.testing.assert_allclose(T[:3, 3], [px, py, pz], atol=1e-15)


@pytest.mark.parametrize(
    ("equation", "theta", "along", "alpha", "z_sign"),
    [
        (32, 0, "x", 0, 1),  # eq. (32)
        (33, 0, "x", 180, -1),  # eq. (33)
        (34, 90, "y", 0, 1),  # eq. (34)
        # eq. (35) is printed with RX(0) although z is reversed: RX(180) is meant.
        (35, 90, "y", 180, -1),
    ],
)
def test_seed000_hayati_cases_reach_the_next_joint(equation, theta, along, alpha, z_sign):
    offset, pz = 0.4, 0.25
    T = _frame_after(
        schroer(17, [theta * D, offset, alpha * D, 0.0, z_sign * pz], ["t", "a", "al", "b", "d"])
    )
    expected = [offset, 0, pz] if along == "x" else [0, offset, pz]
    np.testing.assert_allclose(T[:3, 3], expected, atol=1e-15)
    np.testing.assert_allclose(T[:3, 2], [0, 0, z_sign], atol=1e-15)


def test_standard_dh_matches_closed_form():
    model = model_from_steps("dh", dh(1, 0.1, 0.2, 0.3, 0.4), dh(2, -0.5, 0.6, -0.7, 0.8))
    for q in np.random.default_rng(0).uniform(-3, 3, (5, 2)):
        expected = dh_matrix(0.1 + q[0], 0.2, 0.3, 0.4) @ dh_matrix(-0.5 + q[1], 0.6, -0.7, 0.8)
        np.testing.assert_allclose(model.fk(q), expected, atol=1e-14)


def test_prismatic_dh_joint_drives_d():
    model = model_from_steps("p", dh(1, 0.1, 0.2, 0.3, 0.4, joint="prismatic"))
    assert model.joint_types == ("prismatic",)
    np.testing.assert_allclose(model.fk([0.05]), dh_matrix(0.1, 0.25, 0.3, 0.4), atol=1e-15)


def test_modified_dh_matches_craig_closed_form_and_names():
    steps = mdh(1, 0.0, 0.0, 0.2, 0.1) + mdh(2, -np.pi / 2, 0.05, -0.3, 0.02)
    model = model_from_steps("mdh", steps)
    assert model.names == ("alpha0", "a0", "theta1", "d1", "alpha1", "a1", "theta2", "d2")
    for q in np.random.default_rng(1).uniform(-3, 3, (5, 2)):
        expected = mdh_matrix(0.0, 0.0, 0.2 + q[0], 0.1) @ mdh_matrix(-np.pi / 2, 0.05, -0.3 + q[1], 0.02)
        np.testing.assert_allclose(model.fk(q), expected, atol=1e-14)


def test_hayati_is_seed000_eq7_and_eq17():
    h = model_from_steps("h", hayati(2, 0.1, 0.4, 0.01, -0.02))
    assert [s.motion for s in h.steps] == ["Rz", "Tx", "Rx", "Ry"]
    np.testing.assert_allclose(
        h.fk([0.3]), product(["Rz", "Tx", "Rx", "Ry"], [0.4, 0.4, 0.01, -0.02]), atol=1e-15
    )
    h17 = model_from_steps("h", hayati(2, 0.1, 0.4, 0.01, -0.02, d=0.05))
    assert [s.motion for s in h17.steps] == list(SCHROER_SETS[17])
    with pytest.raises(ValueError, match="revolute"):
        hayati(1, joint="prismatic")


def test_veitschegger_is_seed000_eq9():
    v = model_from_steps("v", veitschegger(1, 0.1, 0.2, 0.3, 0.4, 0.5))
    np.testing.assert_allclose(
        v.fk([0.2]), product(["Rz", "Tz", "Tx", "Rx", "Ry"], [0.3, 0.2, 0.3, 0.4, 0.5]), atol=1e-15
    )


def test_frame6_is_seed000_eq1_and_tool_point():
    f = model_from_steps("f", frame6("base", 1, 2, 3, 0.1, 0.2, 0.3), tool_point(0.01, 0.02, 0.03))
    assert f.names[:6] == ("base_x", "base_y", "base_z", "base_rz", "base_ry", "base_rx")
    assert f.names[6:] == ("tool_x", "tool_y", "tool_z")
    expected = product(
        ["Tx", "Ty", "Tz", "Rz", "Ry", "Rx", "Tx", "Ty", "Tz"],
        [1, 2, 3, 0.1, 0.2, 0.3, 0.01, 0.02, 0.03],
    )
    np.testing.assert_allclose(f.fk(np.zeros(0)), expected, atol=1e-15)


def test_sequence_validates_lengths_and_equation_numbers():
    with pytest.raises(ValueError, match="do not match"):
        sequence(["Rz", "Tx"], [0.0], ["a", "b"])
    with pytest.raises(ValueError, match=r"eqs\. 11-27"):
        schroer(10, [], [])
