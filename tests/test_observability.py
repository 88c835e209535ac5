"""Observability: scaling, singular values, identifiable subsets, O1-O5, pose selection."""

import math

import numpy as np
import pytest

import robocal as rc
from robocal.identify.design_bound import design_efficiency_bound
from robocal.identify.observability_indices import (
    column_scales,
    identifiable_parameters,
    observability,
    observability_indices,
    parameter_tolerances,
    singular_values,
)
from robocal.identify.pose_selection import select_poses
from robocal.measure.poses import random_poses
from robocal.model.chain import Model
from robocal.model.rank import identifiable_subset
from robocal.model.steps import Joint, Step


def _matrix_with_singular_values(s, rows, seed=0):
    rng = np.random.default_rng(seed)
    U, _ = np.linalg.qr(rng.normal(size=(rows, len(s))))
    V, _ = np.linalg.qr(rng.normal(size=(len(s), len(s))))
    return U @ np.diag(s) @ V.T


def test_indices_of_a_matrix_with_known_singular_values():
    s = np.array([4.0, 2.0, 1.0, 0.5])
    J = _matrix_with_singular_values(s, rows=12)  # 4 "poses" of 3 rows
    np.testing.assert_allclose(singular_values(J), s)
    o = observability_indices(singular_values(J), n_poses=4)
    got = o.as_dict()
    assert got["O1"] == pytest.approx((4 * 2 * 1 * 0.5) ** 0.25 / 2)  # Borm & Menq: geometric mean / √n
    assert got["O2"] == pytest.approx(0.5 / 4)  # inverse condition number
    assert got["O3"] == pytest.approx(0.5)  # smallest singular value
    assert got["O4"] == pytest.approx(0.5**2 / 4)  # noise amplification index
    assert got["O5"] == pytest.approx(1 / (1 / 4 + 1 / 2 + 1 + 2))  # Sun & Hollerbach
    assert o["O3"] == o.O3 and set(got) == {"O1", "O2", "O3", "O4", "O5"}
    # singular values of J, not eigenvalues of JᵀJ
    assert not np.allclose(singular_values(J), np.linalg.eigvalsh(J.T @ J)[::-1])


def test_indices_are_zero_for_a_rank_deficient_matrix():
    o = observability_indices([3.0, 1.0, 0.0], n_poses=2)
    assert o.O1 == o.O2 == o.O3 == o.O4 == o.O5 == 0.0
    o = observability_indices([3.0, 1.0], n_poses=1, n_params=3)  # fewer rows than parameters
    assert o.O3 == 0.0 and len(o.sigma) == 3


def test_column_scales():
    J = np.array([[3.0, 0.0, 1.0], [4.0, 0.0, 0.0]])
    np.testing.assert_allclose(column_scales(J, "norm"), [0.2, 1.0, 1.0])
    model = rc.robot("ur10")
    tol = parameter_tolerances(model, ["theta1", "d1"])
    np.testing.assert_allclose(tol, [math.radians(0.05), 1e-4])  # seed 003 §3.5 deviations
    np.testing.assert_allclose(column_scales(J, "tolerance", tolerances=[1, 2, 3]), [1, 2, 3])
    with pytest.raises(ValueError, match="3 positive finite"):
        column_scales(J, [1.0, -1.0, 1.0])


@pytest.fixture(scope="module")
def ur10_pool():
    return random_poses(rc.robot("ur10"), 2000, seed=11)


def test_qr_subset_reports_a_redundant_base_translation(ur10_pool):
    ur10 = rc.robot("ur10")
    extra = Model("ur10_base_z", (Step("Tz", "base_z", 0.0), *ur10.steps))
    q = ur10_pool[:60]
    sub = identifiable_parameters(extra, q)
    assert "base_z" in sub.dropped_names and "d1" in sub.kept
    absorbers = dict(sub.absorbers_of("base_z"))
    assert list(absorbers) == ["d1"] and absorbers["d1"] == pytest.approx(1.0)
    reasons = {d.name: d.reason for d in sub.dropped}
    assert reasons["theta6"] == reasons["alpha6"] == "no effect"  # a6 = 0: no effect on the flange point
    # joints 2, 3, 4 are parallel: only d2 + d3 + d4 is identifiable
    assert {"d2", "d3"} <= set(sub.dropped_names)
    assert dict(sub.absorbers_of("d2")) == pytest.approx({"d4": 1.0})
    assert sub.rank == len(sub.kept) == 18
    assert "base_z: redundant, absorbed by d1 (+1)" in sub.summary()
    # a preference keeps base_z and drops d1 instead
    J = extra.jacobian(q)
    pref = identifiable_subset(J, extra.free_names, prefer=["base_z"])
    assert "d1" in pref.dropped_names and dict(pref.absorbers_of("d1")) == pytest.approx({"base_z": 1.0})


def test_preference_order_keeps_the_preferred_of_two_redundant_parameters(ur10_pool):
    ur10 = rc.robot("ur10")
    extra = Model("ur10_base_z", (Step("Tz", "base_z", 0.0), *ur10.steps))
    J = extra.jacobian(ur10_pool[:60])
    names = extra.free_names
    first = identifiable_subset(J, names, order="preference")  # column order: base_z before d1
    later = identifiable_subset(J, names, order="preference", prefer=["d1"])
    pivoted = identifiable_subset(J, names)
    assert first.rank == later.rank == pivoted.rank == 18
    assert "base_z" in first.kept and dict(first.absorbers_of("d1")) == pytest.approx({"base_z": 1.0})
    assert "d1" in later.kept and dict(later.absorbers_of("base_z")) == pytest.approx({"d1": 1.0})
    assert first.pivots[0] == "base_z" and later.pivots[0] == "d1"
    assert {d.reason for d in first.dropped} == {"no effect", "redundant"}


def test_sequential_rank_test_matches_gram_schmidt_on_random_deficient_matrices():
    from robocal.model.rank import _gram_schmidt, _sequential_rank_test

    rng = np.random.default_rng(3)
    for trial in range(340):
        rows, rank = int(rng.integers(4, 40)), int(rng.integers(1, 12))
        if trial >= 300:  # the size of a calibration's Jacobian (the blocked QR's)
            rows, rank = int(rng.integers(16, 300)), int(rng.integers(8, 30))
        cols = int(rng.integers(rank, rank + 8))
        B = rng.normal(size=(rows, min(rank, rows)))
        A = B @ rng.normal(size=(B.shape[1], cols))
        if trial % 3 == 0:  # some exact copies and zero-ish mixes, as in kinematic Jacobians
            A[:, -1] = A[:, 0]
        A /= np.linalg.norm(A, axis=0)
        keep, coefs, _, left = _sequential_rank_test(A, 1e-7)
        np.testing.assert_array_equal(keep, _gram_schmidt(A, 1e-7), err_msg=f"trial {trial}")
        np.testing.assert_allclose(A[:, keep] @ coefs, A[:, ~keep], atol=1e-6)
        np.testing.assert_allclose(left, np.linalg.norm(A[:, keep] @ coefs - A[:, ~keep], axis=0), atol=1e-12)
        assert keep.sum() == np.linalg.matrix_rank(A)


def test_select_poses_beats_random_poses(ur10_pool):
    model = rc.robot("ur10")
    params = identifiable_parameters(model, ur10_pool).kept
    sel = select_poses(model, ur10_pool, 30, params=params)
    assert len(set(sel.indices.tolist())) == 30 and sel.q.shape == (30, 6)
    assert sel.value >= sel.greedy_value
    assert sel.value == pytest.approx(observability(model, sel.q, params=params).O1)
    randoms = [observability(model, random_poses(model, 30, seed=s), params=params).O1 for s in range(5)]
    assert sel.value > 1.05 * max(randoms)
    o3 = select_poses(model, ur10_pool[:600], 30, index="O3", params=params)
    assert o3.value >= o3.greedy_value > observability(model, ur10_pool[:30], params=params).O3


@pytest.mark.xfail(
    strict=True,
    reason="issue acceptance check, provably unreachable: for the UR10 (18 identifiable DH parameters, "
    "position rows) O1(optimal 30) / mean O1(random 30) = 1.08 (1.09 after continuous refinement of the "
    "joint angles), and the Kiefer-Wolfowitz bound (design_efficiency_bound) caps ANY design at 1.10x "
    "the mean random O1; see docs/pose_count_study.md",
)
def test_optimal_o1_is_one_and_a_half_times_random(ur10_pool):
    model = rc.robot("ur10")
    params = identifiable_parameters(model, ur10_pool).kept
    sel = select_poses(model, ur10_pool, 30, params=params)
    random_o1 = observability(model, random_poses(model, 30, seed=5), params=params).O1
    assert sel.value >= 1.5 * random_o1


def _circle_model():
    """Base offsets bx, by, joint offset θ1 and link length a1 of a one-joint planar arm:
    per-pose Jacobian rows (1, 0, −a sin q, cos q), (0, 1, a cos q, sin q), (0, 0, 0, 0)."""
    joint = Joint("q1", (-math.pi, math.pi))
    return Model(
        "circle",
        (
            Step("Tx", "bx", 0.0),
            Step("Ty", "by", 0.0),
            Step("Rz", "theta1", 0.0, joint=joint),
            Step("Tx", "a1", 0.5),
        ),
    )


def test_design_bound_is_tight_for_a_known_d_optimal_design():
    model = _circle_model()
    candidates = np.linspace(-math.pi, math.pi, 361)[:, None]
    # equally spaced angles: Σ cos = Σ sin = 0, M = diag(1, 1, a², 1) (unscaled), d(q) ≡ p = 4
    balanced = np.array([[-3.0], [-1.0], [1.0], [3.0]]) * math.pi / 4
    b = design_efficiency_bound(model, balanced, candidates)
    assert b.n_params == 4
    assert b.max_variance == pytest.approx(4.0, rel=1e-9)
    assert b.efficiency == pytest.approx(1.0, rel=1e-9) and b.o1_ratio_bound == pytest.approx(1.0, rel=1e-9)
    # poses bunched in one radian: far from optimal, and the bound covers the gap exactly as derived
    bunched = np.linspace(0.0, 1.0, 4)[:, None]
    c = design_efficiency_bound(model, bunched, candidates)
    gap = observability(model, balanced).O1 / observability(model, bunched).O1
    assert c.o1 == pytest.approx(observability(model, bunched).O1)
    assert gap > 1.5 and c.o1_ratio_bound >= gap and c.efficiency < 1 / gap**2
    assert c.o1_upper >= b.o1 and not 0.0 <= c.q_max[0] <= 1.0  # the worst-covered pose is elsewhere
    # unobservable parameters: no finite bound
    single = design_efficiency_bound(model, bunched[:1], candidates)
    assert single.efficiency == 0.0 and math.isinf(single.o1_ratio_bound)


def test_design_bound_caps_what_pose_selection_can_gain(ur10_pool):
    model = rc.robot("ur10")
    params = identifiable_parameters(model, ur10_pool).kept
    rand = random_poses(model, 30, seed=5)
    sel = select_poses(model, ur10_pool, 30, params=params)
    from_random = design_efficiency_bound(model, rand, ur10_pool, params=params)
    from_selected = design_efficiency_bound(model, sel.q, ur10_pool, params=params)
    random_o1 = observability(model, rand, params=params).O1
    assert from_random.o1 == pytest.approx(random_o1)
    # the bound from either design covers the selected design's gain over the random one
    assert from_random.o1_ratio_bound >= sel.value / random_o1 > 1.0
    assert from_selected.o1_upper >= sel.value and from_random.o1_upper >= sel.value
    # the selection is within 10 % of the best possible O1 ...
    assert 1.0 <= from_selected.o1_ratio_bound < 1.1
    # ... so no set of UR10 poses reaches the 1.5x this random set's O1
    assert from_selected.o1_upper < 1.2 * random_o1


def test_selection_input_errors(ur10_pool):
    model = rc.robot("ur10")
    with pytest.raises(ValueError, match="index must be one of"):
        select_poses(model, ur10_pool, 5, index="O7")
    with pytest.raises(ValueError, match="cannot select n=50"):
        select_poses(model, ur10_pool[:10], 50)
    with pytest.raises(ValueError, match="does not fit 3 parameter names"):
        identifiable_subset(np.zeros((6, 2)), ["a", "b", "c"])
