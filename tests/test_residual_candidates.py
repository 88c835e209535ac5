"""The learned residual's joints: a joint whose angle error cannot move the measured point (a
probe on its axis) is left out of the residual, which changes no cross-validated error or
choice and costs a sixth less per evidence evaluation (issue 35 item 1); the table says so.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import robocal as rc
import robocal.identify.residual.stage as stage
from robocal.identify.pipeline import calibrate_physics
from robocal.identify.residual.cv import CVCandidate, CVTable, PhysicalFit, cross_validate_residual
from robocal.identify.residual.fit import (
    MAX_AMPLITUDE,
    one_blas_thread_limit,
    raw_blocks,
    residual_template,
)
from robocal.model.residual import fourier_basis, fourier_gram
from tests.test_residual import PROBE, _case, _ur10


def _fit(levers: list[float], residual_rms: float, n: int = 50) -> PhysicalFit:
    """A physical fit whose joint j moves the point by ``levers[j]`` m/rad at its farthest
    pose (less at the others) and leaves residuals of about ``residual_rms`` m."""
    rng = np.random.default_rng(0)
    P = np.zeros((n, 3, len(levers), 3))
    direction = rng.normal(size=(n, 3, len(levers)))
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    scale = np.linspace(0.2, 1.0, n)[:, None] * np.asarray(levers)[None, :]
    P[:, :, :, 2] = direction * scale[:, None, :]
    residuals = rng.normal(size=(n, 3))
    residuals *= residual_rms / np.sqrt(np.mean(np.sum(residuals**2, axis=1)))
    return PhysicalFit(None, residuals, P, np.zeros((n, 3, 1)))


def test_a_joint_that_cannot_move_the_point_is_left_out():
    # a probe 0.4 mm from the last axis, 0.4 mm of residual: 2 mrad move it 0.8 µm
    kept, left_out = stage.observable_joints([0, 1, 2, 3], _fit([1.2, 0.8, 0.2, 4e-4], 4e-4))
    assert kept == [0, 1, 2]
    assert [j for j, _ in left_out] == [3]
    assert left_out[0][1] == pytest.approx(MAX_AMPLITUDE * 4e-4)
    # the same joint with a 50 mm lever arm moves the point 0.1 mm: kept
    kept, left_out = stage.observable_joints([0, 1, 2, 3], _fit([1.2, 0.8, 0.2, 0.05], 4e-4))
    assert kept == [0, 1, 2, 3] and left_out == []
    # no physical fit to judge by: every joint kept
    assert stage.observable_joints([0, 2], None) == ([0, 2], [])


def test_the_table_names_the_joints_left_out_and_reads_them_back():
    row = CVCandidate("geometry", "geometry", None, 1e-4, 2e-4, 0.01, 3e-4, 5e-4)
    table = CVTable(5, (row,), "geometry", (("wrist_3", 8e-7),))
    again = CVTable.from_dict(table.to_dict())
    assert again == table
    assert any("wrist_3" in line for line in table.lines())
    older = table.to_dict()
    del older["joints_left_out"]
    assert CVTable.from_dict(older).left_out == ()


@pytest.fixture(scope="module")
def on_axis():
    """The tests' virtual UR10 with errors the physics lacks, its probe on the last axis."""
    model, (data, _) = _ur10(), _case(errors=True, n_train=80, seed=6)
    with one_blas_thread_limit():
        options = {"tool_guess": PROBE}
        base = calibrate_physics(model, data, "lm", **options)
        variants = stage._physics_variants(model, options, "auto")
        fits = stage._PhysicsFits(calibrate_physics, model, data, "lm", variants, "geometry", base)
        usable, full = fits.usable()
    return model, data, usable, full


def test_leaving_out_the_unseen_joint_changes_no_cv_error(on_axis):
    model, data, usable, full = on_axis
    joints = list(range(model.dof))
    kept, left_out = stage.observable_joints(joints, next(iter(full.values())))
    assert [j for j, _ in left_out] == [model.dof - 1]  # the probe is on the last joint's axis
    tables = []
    with one_blas_thread_limit():
        for chosen in (joints, kept):
            names = [model.joint_names[j] for j in chosen]
            tables.append(cross_validate_residual(data.q, data.position, usable, names, chosen, (4, 8), 5)[0])
    every, fewer = tables
    assert fewer.chosen == every.chosen and "angle errors" in every.chosen
    for a, b in zip(every.candidates, fewer.candidates, strict=True):
        assert a.name == b.name
        assert b.cv_mean == pytest.approx(a.cv_mean, rel=1e-3)
        assert b.cv_p95 == pytest.approx(a.cv_p95, rel=1e-3)


def test_the_calibration_models_the_seen_joints_only(on_axis):
    model, data, _, _ = on_axis
    result = rc.calibrate(model, data, tool_guess=PROBE, residual="auto", residual_harmonics=(4, 8))
    learned = result.model.residual
    assert learned is not None
    last = model.joint_names[-1]
    assert last not in learned.joints and len(learned.joints) == model.dof - 1
    assert [j["joint"] for j in result.diagnostics.cv["joints_left_out"]] == [last]
    # what it predicts and its uncertainty stay finite at new poses
    q = data.q[:5] + 0.01
    assert np.all(np.isfinite(result.predict(q))) and np.all(np.isfinite(result.position_uncertainty(q)))


@pytest.mark.parametrize("harmonics", [1, 7, 48])
def test_the_gram_of_a_fourier_basis_from_its_sums_of_harmonics(harmonics):
    rng = np.random.default_rng(harmonics)
    angles, weights = rng.uniform(-np.pi, np.pi, 400), rng.uniform(0.0, 2.0, 400)
    B = fourier_basis(angles[:, None], harmonics)[:, 0, :]
    expected = B.T @ (weights[:, None] * B)
    assert fourier_gram(angles, weights, harmonics) == pytest.approx(
        expected, abs=1e-12 * np.abs(expected).max()
    )


@pytest.mark.parametrize("covered", [700, 300])  # every pose covered (no fade) / some poses faded
def test_the_normal_equations_by_blocks_are_the_design_products(covered):
    rng = np.random.default_rng(covered)
    n, k, p = 700, 5, 7
    q = rng.uniform(-3.0, 3.0, (n, 6))
    r, P, J = rng.normal(size=(n, 3)), rng.normal(size=(n, 3, 6, 3)), rng.normal(size=(n, 3, p))
    template = residual_template([f"j{i}" for i in range(k)], list(range(k)), 12, q[:covered]).covering(
        q[:covered]
    )
    assert (covered == n) == bool(np.all(template.fade(q) == 1.0))
    A = template.design(q, P).reshape(-1, template.size)
    J2 = J.reshape(-1, p)
    raw = raw_blocks(q, r, P, template, J)
    for got, expected in ((raw.AA, A.T @ A), (raw.Ar, A.T @ r.reshape(-1)), (raw.JA, J2.T @ A)):
        assert got == pytest.approx(expected, abs=1e-12 * np.abs(expected).max())


@pytest.mark.parametrize("covered", [400, 150])  # no pose faded / many poses faded
def test_the_mean_position_variance_from_sums_of_harmonics_is_the_covariances_trace(covered):
    rng = np.random.default_rng(covered)
    n, k = 400, 5
    q, P = rng.uniform(-3.0, 3.0, (n, 6)), rng.normal(size=(n, 3, 6, 3))
    names, seen = [f"j{i}" for i in range(k)], q[:covered]
    learned = residual_template(names, list(range(k)), 10, seen)
    root = rng.normal(size=(learned.size, learned.size)) * 1e-4
    learned = dataclasses.replace(learned, covariance=root @ root.T, length_scale=0.3).covering(seen)
    assert learned.global_harmonics > 0 and (covered < n) == bool(np.any(learned.fade(q) < 1.0))
    expected = np.mean(np.trace(learned.position_covariance(q, P), axis1=1, axis2=2))
    assert learned.mean_position_variance(q, P) == pytest.approx(expected, rel=1e-10)
