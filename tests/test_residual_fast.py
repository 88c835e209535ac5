"""The residual fit's fast paths against their plain definitions: the Gram matrix from
per-joint blocks, one Gram for several numbers of harmonics, the evidence's dual form, the
correction A·c from angle errors (identify/residual.py)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from robocal.identify.residual.fit import (
    apply,
    gram_matrices,
    gram_matrix,
    layout,
    nll_and_grad,
    nll_and_grad_dual,
    residual_template,
)

JOINTS = ["a", "b", "c", "d"]


def _problem(n: int, seed: int = 0):
    rng = np.random.default_rng(seed)
    q = rng.uniform(-3, 3, (n, 6))
    q[:, 1] = rng.uniform(-1, 1, n)  # a joint with a gap-free partial range: the fade is used
    P = rng.normal(size=(n, 3, 6, 3))
    r = rng.normal(size=(n, 3)) * 1e-4
    J = rng.normal(size=(n, 3, 7))
    return q, r, P, J


def _explicit(q, r, P, template, J):
    """G, b, rᵀr and N from the whole design, projected out of J's columns."""
    A = template.design(q, P).reshape(-1, template.size)
    y = r.reshape(-1)
    Q = np.linalg.qr(J.reshape(-1, J.shape[-1]))[0]
    A, y = A - Q @ (Q.T @ A), y - Q @ (Q.T @ y)
    return A.T @ A, A.T @ y, float(y @ y), r.size - Q.shape[1]


@pytest.mark.parametrize("n", [50, 2500])  # one chunk; two chunks and a part
def test_block_gram_equals_the_design_products(n):
    q, r, P, J = _problem(n)
    template = residual_template(JOINTS, [0, 1, 2, 4], 6, q)
    G, b, rr, N = gram_matrix(q, r, P, template, J)
    G0, b0, rr0, N0 = _explicit(q, r, P, template, J)
    assert N == N0 and rr == pytest.approx(rr0, rel=1e-12)
    np.testing.assert_allclose(G, G0, rtol=0, atol=1e-12 * np.abs(G0).max())
    np.testing.assert_allclose(b, b0, rtol=0, atol=1e-12 * np.abs(b0).max())


@pytest.mark.parametrize("n", [30, 400])  # few equations (the design kept), many
def test_one_gram_serves_every_number_of_harmonics(n):
    q, r, P, J = _problem(n, 1)
    grams = gram_matrices(q, r, P, residual_template(JOINTS, [0, 1, 2, 4], 1, q), [2, 5, 9], J)
    assert (grams[9].A is not None) == (r.size < 4 * 2 * 9)
    for H in (2, 5, 9):
        G0, b0, rr0, N0 = _explicit(q, r, P, residual_template(JOINTS, [0, 1, 2, 4], H, q), J)
        assert grams[H].N == N0 and grams[H].rr == pytest.approx(rr0, rel=1e-12)
        np.testing.assert_allclose(grams[H].G, G0, rtol=0, atol=1e-12 * np.abs(G0).max())
        np.testing.assert_allclose(grams[H].b, b0, rtol=0, atol=1e-12 * np.abs(b0).max())


def test_the_dual_evidence_is_the_same_function():
    q, r, P, J = _problem(20, 2)
    template = residual_template(JOINTS, [0, 1, 2, 4], 8, q)
    normal = gram_matrices(q, r, P, template, [8], J)[8]
    assert normal.A is not None and normal.A.shape == (60 - 7, 64)
    groups, freq = layout(template)
    rng = np.random.default_rng(3)
    for _ in range(3):
        theta = np.r_[np.log(rng.uniform(1e-5, 1e-3, 4)), np.log(rng.uniform(0.01, 1)), np.log(1e-4)]
        nll, grad = nll_and_grad(theta, normal.G, normal.b, normal.rr, normal.N, groups, freq)
        nll_d, grad_d = nll_and_grad_dual(theta, normal.A, normal.r, normal.rr, normal.N, groups, freq)
        assert nll_d == pytest.approx(nll, rel=1e-10)
        np.testing.assert_allclose(grad_d, grad, rtol=1e-8, atol=1e-8 * np.abs(grad).max())


def test_the_correction_from_angle_errors_is_the_design_times_the_coefficients():
    q, _, P, _ = _problem(300, 4)
    template = residual_template(JOINTS, [0, 1, 2, 4], 5, q)
    c = np.random.default_rng(5).normal(0, 1e-4, template.size)
    learned = dataclasses.replace(template, coefficients=c)
    expected = np.einsum("nrm,m->nr", learned.design(q, P), learned.coefficients)
    np.testing.assert_allclose(apply(learned, q, P), expected, rtol=0, atol=1e-13)


def test_angle_errors_sum_the_basis():
    """The angle errors summed harmonic by harmonic equal the basis times the coefficients,
    with and without the fade outside the covered angles."""
    q, _, _, _ = _problem(500, 6)
    for covered in (None, q[:100]):
        template = residual_template(JOINTS, [0, 1, 2, 4], 7, covered)
        c = np.random.default_rng(7).normal(0, 1e-4, template.size)
        learned = dataclasses.replace(template, coefficients=c)
        expected = np.einsum("nkh,kh->nk", learned.basis(q), c.reshape(4, -1))
        np.testing.assert_allclose(learned.angle_errors(q), expected, rtol=0, atol=1e-15)


def test_position_covariance_and_cross_map_are_the_design_products():
    """A C Aᵀ per pose through the per-joint basis covariance (in chunks of poses), and
    A Xᵀ without the design, against the design itself (with the fade and without)."""
    q, _, P, _ = _problem(300, 7)
    template = residual_template(JOINTS, [0, 1, 2, 4], 5, q)
    rng = np.random.default_rng(8)
    F = rng.normal(size=(template.size, template.size))
    learned = dataclasses.replace(template, covariance=F @ F.T * 1e-10)
    X = rng.normal(size=(7, template.size))
    for covered in (learned, dataclasses.replace(learned, coverage=None)):
        A = covered.design(q, P[:, :3])
        expected = (A @ covered.covariance) @ np.swapaxes(A, 1, 2)
        if covered.coverage is not None:  # the fade's missing-variance term, as the method adds it
            cols = P[:, :3, list(covered.joint_index), 2]
            rms = np.asarray(covered.amplitudes if covered.angle_rms is None else covered.angle_rms)
            missing = (1.0 - covered.fade(q) ** 2) * rms**2
            expected = expected + np.einsum("nrk,nk,nsk->nrs", cols, missing, cols)
        got = covered.position_covariance(q, P)
        np.testing.assert_allclose(got, expected, rtol=1e-10, atol=1e-12 * np.abs(expected).max())
        M = covered._basis_covariance(covered.basis(q), chunk=64)  # several chunks
        np.testing.assert_allclose(M, covered._basis_covariance(covered.basis(q)), rtol=1e-12, atol=0)
        np.testing.assert_allclose(covered.coefficient_map(q, P, X), A @ X.T, rtol=1e-10, atol=1e-14)
