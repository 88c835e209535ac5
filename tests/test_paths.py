"""Cartesian paths and joint paths (robocal.measure.paths)."""

import math

import numpy as np
import pytest

import robocal as rc
from robocal.measure.paths import (
    THESIS_CIRCLE_MM,
    Circle,
    circle_path,
    circle_through,
    cubic_spline,
    joint_path,
    line_path,
)

KATANA_NOMINAL_BASE = np.array([0.055, 0.055, 0.2015])  # seed 003: T_R_0 = [55 55 201.5] mm


def test_thesis_circle_centre_radius_and_plane():
    c = circle_through(THESIS_CIRCLE_MM * 1e-3)
    np.testing.assert_allclose(c.center * 1e3, [0.0, -300.0, 139.2893], atol=1e-4)
    assert c.radius * 1e3 == pytest.approx(100.0, abs=1e-4)
    # the 45° diagonal plane y + z = const: normal along (0, 1, 1)/√2
    assert abs(abs(c.normal @ np.array([0, 1, 1]) / math.sqrt(2)) - 1) < 1e-9
    # the points follow each other counter-clockwise about the normal, 90° apart
    angles = c.angle_of(THESIS_CIRCLE_MM * 1e-3)
    np.testing.assert_allclose(angles, [0, np.pi / 2, np.pi, 3 * np.pi / 2], atol=1e-6)


def test_circle_through_three_points_and_bad_points():
    p = np.array([[1.0, 0, 0], [0, 1.0, 0], [-1.0, 0, 0]]) * 0.3 + [0.1, 0.2, 0.3]
    c = circle_through(p)
    np.testing.assert_allclose(c.center, [0.1, 0.2, 0.3], atol=1e-12)
    assert c.radius == pytest.approx(0.3)
    np.testing.assert_allclose(c.at(0.0), p[0], atol=1e-12)
    with pytest.raises(ValueError, match="not coplanar: point"):
        circle_through(np.vstack([p, [0.1, 0.2, 0.5]]))
    with pytest.raises(ValueError, match="not on one circle: point 3"):
        circle_through(np.vstack([p, [0.1, 0.2 - 0.25, 0.3]]))
    with pytest.raises(ValueError, match="collinear"):
        circle_through([[0, 0, 0], [1, 1, 1], [2, 2, 2]])
    with pytest.raises(ValueError, match=">= 3"):
        circle_through(p[:2])


def test_circle_and_line_paths():
    c = circle_through(THESIS_CIRCLE_MM * 1e-3)
    pts = circle_path(c, 100)
    assert pts.shape == (100, 3)
    np.testing.assert_allclose(np.linalg.norm(pts - c.center, axis=1), c.radius, atol=1e-12)
    np.testing.assert_allclose(pts[0], THESIS_CIRCLE_MM[0] * 1e-3, atol=1e-7)
    np.testing.assert_allclose(pts[25], THESIS_CIRCLE_MM[1] * 1e-3, atol=1e-7)  # a quarter turn later
    arc = circle_path(THESIS_CIRCLE_MM * 1e-3, 11, sweep=np.pi)
    np.testing.assert_allclose(arc[-1], THESIS_CIRCLE_MM[2] * 1e-3, atol=1e-7)
    line = line_path([0, 0, 0], [1, 2, 3], 5)
    np.testing.assert_allclose(line[[0, -1]], [[0, 0, 0], [1, 2, 3]])
    np.testing.assert_allclose(np.diff(line, axis=0), np.tile([0.25, 0.5, 0.75], (4, 1)))


def test_spline_passes_through_waypoints_with_the_given_velocities():
    p = np.array([[0.3, 0, 0.2], [0.35, 0.1, 0.25], [0.3, 0.2, 0.3], [0.2, 0.25, 0.2]])
    v = np.array([[0, 0, 0], [0.05, 0.1, 0.0], [-0.1, 0.05, 0.02], [0, 0, 0]])
    t = np.array([0.0, 1.0, 2.5, 3.0])
    s = cubic_spline(p, v, t)
    np.testing.assert_allclose(s(t), p, atol=1e-12)
    np.testing.assert_allclose(s.velocity(t), v, atol=1e-12)
    # continuous position and velocity at the inner waypoints, seen from both segments
    eps = 1e-9
    np.testing.assert_allclose(s(t[1:-1] - eps), s(t[1:-1] + eps), atol=1e-8)
    np.testing.assert_allclose(s.velocity(t[1:-1] - eps), s.velocity(t[1:-1] + eps), atol=1e-7)
    # each segment is one cubic (seed 001 eq. 3): the third derivative is constant on it
    tau = np.linspace(1.0, 2.5, 7)
    d3 = np.diff(s(tau), n=3, axis=0)
    np.testing.assert_allclose(d3, d3[:1].repeat(len(d3), 0), atol=1e-12)
    times, pts = s.sample(31)
    assert times[0] == 0 and times[-1] == 3.0 and pts.shape == (31, 3)
    # default velocities: zero at the ends, central differences inside
    d = cubic_spline(p)
    np.testing.assert_allclose(d.velocity([0.0, 3.0]), 0, atol=1e-12)
    np.testing.assert_allclose(d.velocity(1.0), (p[2] - p[0]) / 2)
    with pytest.raises(ValueError, match=r"times must increase: t\[2\]"):
        cubic_spline(p, v, [0, 1, 1, 2])
    with pytest.raises(ValueError, match="velocities must be"):
        cubic_spline(p, v[:2], t)


def test_joint_path_of_the_thesis_circle_on_the_katana():
    model = rc.robot("katana450")
    c = circle_through(THESIS_CIRCLE_MM * 1e-3)
    c = Circle(c.center + KATANA_NOMINAL_BASE, c.radius, c.normal, c.u)  # nominal base -> model base
    pts = circle_path(c, 120)
    jp = joint_path(model, pts, seed=1)
    assert jp.success, (jp.unreachable, jp.jumps)
    np.testing.assert_allclose(model.fk(jp.q)[:, :3, 3], pts, atol=1e-6)
    assert np.abs(np.diff(jp.q, axis=0)).max() < 0.1  # smooth: 3 deg of circle per sample
    lim = model.joint_limits
    assert np.all((jp.q >= lim[:, 0]) & (jp.q <= lim[:, 1]))


def test_joint_path_keeps_the_branch_and_reports_unreachable_samples():
    model = rc.robot("ur10")
    q0 = np.radians([10, -80, 100, -110, -90, 0])
    start = model.fk(q0)[:3, 3]
    out = np.array([start[0], start[1], 0.0]) / np.hypot(start[0], start[1])
    pts = line_path(start, start + 1.5 * out, 41)  # radially out, leaving the 1.3 m workspace
    jp = joint_path(model, pts, q0=q0)
    np.testing.assert_allclose(jp.q[0], q0, atol=1e-8)
    assert jp.reachable[:5].all() and not jp.reachable[-5:].any()
    assert jp.unreachable.tolist() == list(range(int(jp.unreachable[0]), 41))
    reached = jp.reachable
    steps = np.abs(np.diff(jp.q[reached], axis=0)).max(axis=1)
    assert steps.max() < 0.35  # no branch jump while reachable
    assert not jp.success
