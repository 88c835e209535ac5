"""ISO 9283 characteristics and the seeds' error tables on hand-made data."""

import math

import numpy as np
import pytest
from scipy import stats

from robocal import spatial
from robocal.evaluate.error_tables import (
    ERROR_QUANTITIES,
    PoseErrors,
    error_table,
    improvement,
    mean_ci,
    pose_errors,
)
from robocal.evaluate.metrics import (
    iso9283_pose_characteristics,
    path_accuracy,
    pose_accuracy,
    pose_repeatability,
)


def test_pose_accuracy_is_the_distance_to_the_barycentre():
    attained = np.array([[3.0, 0, 0], [1.0, 0, 0], [2.0, 0, 2], [2.0, 0, -2]])
    acc = pose_accuracy(attained, [0.0, 0.0, 0.0])
    assert pytest.approx(2.0) == acc.AP
    np.testing.assert_allclose(acc.AP_xyz, [2.0, 0.0, 0.0])
    np.testing.assert_allclose(acc.barycentre, [2.0, 0.0, 0.0])
    assert acc.AP_abc is None and acc.n == 4
    shifted = pose_accuracy(attained + [0.5, -1.0, 0.25], [0.5, -1.0, 0.25])
    assert pytest.approx(2.0) == shifted.AP


def test_pose_repeatability_is_mean_distance_plus_three_sample_deviations():
    attained = np.array([[3.0, 0, 0], [1.0, 0, 0], [2.0, 0, 2], [2.0, 0, -2]])  # l = 1, 1, 2, 2
    rep = pose_repeatability(attained)
    s_l = math.sqrt(4 * 0.25 / 3)  # n - 1 in the denominator
    assert rep.l_mean == pytest.approx(1.5)
    assert rep.S_l == pytest.approx(s_l)
    assert pytest.approx(1.5 + 3 * s_l) == rep.RP
    same = pose_repeatability(np.array([[1.0, 0, 0], [-1.0, 0, 0], [0, 1.0, 0], [0, -1.0, 0]]))
    assert pytest.approx(1.0) == same.RP and same.S_l == pytest.approx(0.0)
    with pytest.raises(ValueError, match="n >= 2"):
        pose_repeatability(attained[:1])


def test_orientation_accuracy_and_repeatability_wrap_around_pi():
    commanded_roll = math.pi - 0.001
    offsets = np.array([0.01, 0.03, -0.01, 0.01])  # attained rolls cross +-pi
    R = spatial.rotx(commanded_roll + offsets)
    frames = spatial.homogeneous(R, np.zeros((4, 3)))
    target = spatial.homogeneous(spatial.rotx(commanded_roll), np.zeros(3))
    acc = pose_accuracy(frames, target)
    np.testing.assert_allclose(acc.AP_abc, [0.01, 0.0, 0.0], atol=1e-12)
    rep = pose_repeatability(frames)
    np.testing.assert_allclose(rep.RP_abc, [3 * offsets.std(ddof=1), 0.0, 0.0], atol=1e-12)


def test_iso_pose_characteristics_of_several_poses():
    rng = np.random.default_rng(1)
    commanded = rng.normal(size=(5, 3))
    bias = rng.normal(size=(5, 3)) * 1e-3
    attained = commanded[:, None, :] + bias[:, None, :] + rng.normal(size=(5, 30, 3)) * 1e-5
    ch = iso9283_pose_characteristics(commanded, attained)
    assert ch.labels == ("P1", "P2", "P3", "P4", "P5")
    rows = ch.rows()
    for i, row in enumerate(rows):
        expected = np.linalg.norm(attained[i].mean(axis=0) - commanded[i]) * 1e3
        assert row["AP_mm"] == pytest.approx(expected)
        assert row["n"] == 30 and row["RP_mm"] > 0
    with pytest.raises(ValueError, match="5 commanded poses"):
        iso9283_pose_characteristics(commanded, attained[:4])


def test_path_accuracy_of_offset_straight_paths():
    commanded = np.column_stack([np.linspace(0, 1, 11), np.zeros(11), np.zeros(11)])
    s = np.linspace(-0.05, 1.05, 37)  # sampled elsewhere than the commanded points
    cycles = [np.column_stack([s, np.full_like(s, dy), np.zeros_like(s)]) for dy in (0.001, 0.003)]
    pa = path_accuracy(commanded, cycles)
    assert pytest.approx(0.002) == pa.AT  # barycentre 2 mm off at every point
    assert pytest.approx(0.001) == pa.RT  # each cycle 1 mm from the barycentre, S = 0
    np.testing.assert_allclose(pa.at, 0.002)
    np.testing.assert_allclose(pa.barycentres[:, 1], 0.002)
    assert pa.n_cycles == 2 and pa.crossings.shape == (2, 11, 3)


def test_path_accuracy_takes_the_crossing_near_the_commanded_point_on_a_circle():
    angles = np.linspace(0, 2 * np.pi, 60, endpoint=False)
    commanded = np.column_stack([np.cos(angles), np.sin(angles), np.zeros(60)]) * 0.2
    fine = np.linspace(0, 2 * np.pi, 400, endpoint=False)
    attained = [np.column_stack([np.cos(fine), np.sin(fine), np.zeros(400)]) * r for r in (0.2005, 0.2015)]
    pa = path_accuracy(commanded, attained)
    assert pytest.approx(0.001, abs=2e-5) == pa.AT  # never the far side of the circle (0.4 m)
    assert np.nanmax(pa.at) < 0.0011


def test_path_accuracy_ignores_points_no_cycle_reaches():
    commanded = np.column_stack([np.linspace(0, 1, 11), np.zeros(11), np.zeros(11)])
    short = np.column_stack([np.linspace(0.15, 1.0, 20), np.full(20, 1e-3), np.zeros(20)])
    pa = path_accuracy(commanded, [short, short + [0, 1e-3, 0]])
    assert np.isnan(pa.at[:2]).all() and pytest.approx(1.5e-3) == pa.AT
    with pytest.raises(ValueError, match="commanded path"):
        path_accuracy(commanded[:1], [short])


def test_pose_errors_and_the_seed_table():
    commanded = np.zeros((4, 3))
    before = PoseErrors(
        np.array([[1.0, -2.0, 2.0], [0.0, 3.0, 4.0], [-1.0, 0.0, 0.0], [2.0, 2.0, 1.0]]) * 1e-3
    )
    after = PoseErrors(before.delta / 10)
    assert before.distance == pytest.approx(np.array([3.0, 5.0, 1.0, 3.0]) * 1e-3)
    table = error_table({"before": before, "after": after})
    assert table.quantities == ERROR_QUANTITIES[:4]
    np.testing.assert_allclose(table.maximum[:, 0] * 1e3, [2.0, 3.0, 4.0, 5.0])
    np.testing.assert_allclose(table.minimum[:, 0] * 1e3, [0.0, 0.0, 0.0, 1.0])
    np.testing.assert_allclose(table.average[:, 0] * 1e3, [1.0, 1.75, 1.75, 3.0])
    imp = table.improvements["after"]["|ΔP|"]
    assert imp.percent == pytest.approx(90.0) and imp.percent_low == pytest.approx(90.0)  # exact ratio
    d = table.to_dict()
    assert d["average"]["|ΔP|"]["before"] == pytest.approx(3.0)
    assert "Average" in table.to_text()
    errs = pose_errors(commanded + [0.0, 0.0, 1e-3], commanded)
    assert errs.distance == pytest.approx(np.full(4, 1e-3)) and errs.angles is None


def test_pose_errors_with_euler_angles():
    R_c = spatial.euler_to_matrix(np.tile([0.3, 1.0, -0.5], (3, 1)), "ZXZ")
    R_a = spatial.euler_to_matrix(np.array([[0.31, 1.0, -0.5], [0.3, 0.98, -0.5], [0.3, 1.0, -0.47]]), "ZXZ")
    errs = pose_errors(spatial.homogeneous(R_a, np.zeros((3, 3))), spatial.homogeneous(R_c, np.zeros((3, 3))))
    np.testing.assert_allclose(errs.angles, [[0.01, 0, 0], [0, -0.02, 0], [0, 0, 0.03]], atol=1e-12)
    table = error_table({"a": errs})
    assert table.quantities == ERROR_QUANTITIES
    np.testing.assert_allclose(table.maximum[4:, 0], [0.01, 0.02, 0.03], atol=1e-12)


def test_mean_confidence_interval_matches_student_t():
    x = np.array([1.2, 0.8, 1.1, 0.9, 1.4, 1.0])
    mean, half = mean_ci(x)
    lo, hi = stats.t.interval(0.95, len(x) - 1, loc=x.mean(), scale=stats.sem(x))
    assert mean == pytest.approx(x.mean()) and half == pytest.approx((hi - lo) / 2)


def test_improvement_interval_for_independent_samples():
    b = np.array([2.0, 2.2, 1.8, 2.4, 1.6])
    a = np.array([0.5, 0.7, 0.3, 0.6])
    imp = improvement(b, a)
    assert not imp.paired
    R = a.mean() / b.mean()
    se = math.sqrt(a.var(ddof=1) / (4 * b.mean() ** 2) + R**2 * b.var(ddof=1) / (5 * b.mean() ** 2))
    t = stats.t.ppf(0.975, 3)
    assert imp.percent == pytest.approx(100 * (1 - R))
    assert imp.percent_high - imp.percent == pytest.approx(100 * t * se)
    with pytest.raises(ValueError, match="same length"):
        improvement(b, a, paired=True)


def test_improvement_interval_covers_the_truth_about_95_percent_of_the_time():
    rng = np.random.default_rng(7)
    hits = 0
    reps = 400
    for _ in range(reps):
        before = rng.gamma(4.0, 0.5, 40)  # mean 2
        after = 0.2 * before + rng.gamma(2.0, 0.05, 40)  # mean 0.4 + 0.1 = 0.5: 75 % better
        imp = improvement(before, after)
        hits += imp.percent_low <= 75.0 <= imp.percent_high
    assert 0.91 <= hits / reps <= 0.99
