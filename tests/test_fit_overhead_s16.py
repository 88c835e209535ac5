"""The calibration's overhead cut in session 16 (issue 35): the sequential rank test from the
normal equations of the unit-norm columns (no QR where its margins decide), and the
extreme eigenvalues of a covariance's normal matrix, give the verdicts and numbers the
general code gave, and hand what they cannot decide to it."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg

from robocal.model import rank, rank_kernels


def _unit_columns(rng, rows, rank_, cols, copies=False):
    """A random ``(rows, cols)`` matrix of rank ``rank_`` with unit-norm columns (an exact copy
    of the first column last with ``copies``, as a kinematic Jacobian's redundant pairs)."""
    B = rng.normal(size=(rows, rank_))
    A = B @ rng.normal(size=(rank_, cols))
    if copies:
        A[:, -1] = A[:, 0]
    return A / np.linalg.norm(A, axis=0)


def _qr_test(A, tolerance=1e-7):
    """The QR form of the test (:func:`robocal.model.rank_kernels.sequential_test`)."""
    return rank_kernels.sequential_test(scipy.linalg.lapack.dgeqrf(A)[0], tolerance)


@pytest.mark.parametrize("seed", range(40))
def test_the_gram_test_decides_as_the_qr_on_calibration_sized_matrices(seed):
    rng = np.random.default_rng(seed)
    rows = int(rng.integers(150, 400))
    rank_ = int(rng.integers(6, 30))
    A = _unit_columns(rng, rows, rank_, rank_ + int(rng.integers(0, 10)), copies=seed % 3 == 0)
    diag, keep, coefs, left, decided = rank_kernels.gram_sequential_test(np.ascontiguousarray(A.T), 1e-7)
    qr_diag, qr_keep, qr_coefs, _, explained = _qr_test(A)
    assert decided and explained
    np.testing.assert_array_equal(keep, qr_keep)
    assert keep.sum() == np.linalg.matrix_rank(A)
    # the kept columns' distances to those before them, as |R_kk|; the dropped ones' fits
    np.testing.assert_allclose(diag[keep], qr_diag[keep], rtol=1e-8)
    np.testing.assert_allclose(coefs, qr_coefs, atol=1e-8)
    assert np.all(left <= 1e-9) and np.all(diag[~keep] <= 1e-9)
    np.testing.assert_allclose(left, np.linalg.norm(A[:, keep] @ coefs - A[:, ~keep], axis=0), atol=1e-13)


def test_a_column_near_the_tolerance_goes_to_the_qr():
    # a column 3e-7 from the span of the others: kept by the QR (> 1e-7), but neither margin
    # of the normal equations decides it
    rng = np.random.default_rng(5)
    A = _unit_columns(rng, 300, 8, 8)
    orthogonal = rng.normal(size=300)
    orthogonal -= A @ np.linalg.lstsq(A, orthogonal, rcond=None)[0]
    near = A[:, :3] @ np.array([0.5, -0.3, 0.2])
    near = near / np.linalg.norm(near) + 3e-7 * orthogonal / np.linalg.norm(orthogonal)
    A = np.column_stack([A, near / np.linalg.norm(near)])
    *_, decided = rank_kernels.gram_sequential_test(np.ascontiguousarray(A.T), 1e-7)
    assert not decided
    keep, _, diag, _ = rank._sequential_rank_test(A, 1e-7)
    assert keep.all() and diag[-1] == pytest.approx(3e-7, rel=1e-3)  # the QR's verdict


def test_an_ill_conditioned_span_goes_to_the_qr():
    # two nearly parallel kept columns (1e-5 apart): a column redundant in them has
    # coefficients ~1e5, past what the normal equations' round-off allows a verdict on
    rng = np.random.default_rng(6)
    base = rng.normal(size=(300, 4))
    a, b = base[:, 0], base[:, 0] + 1e-5 * base[:, 1]
    redundant = 3.0 * a - 2.0 * b + 1e-6 * base[:, 2]  # 1e-6 off their span: kept by the QR
    A = np.column_stack([a, b, base[:, 3], redundant])
    A /= np.linalg.norm(A, axis=0)
    *_, decided = rank_kernels.gram_sequential_test(np.ascontiguousarray(A.T), 1e-7)
    assert not decided
    keep, *_ = rank._sequential_rank_test(A, 1e-7)
    np.testing.assert_array_equal(keep, _qr_test(A)[1])


def test_few_rows_go_to_the_qr():
    # with about as many rows as columns the QR's verdicts also depend on the directions of
    # the dropped columns' round-off: the normal equations leave those to it
    rng = np.random.default_rng(7)
    A = _unit_columns(rng, 20, 6, 9, copies=True)
    *_, decided = rank_kernels.gram_sequential_test(np.ascontiguousarray(A.T), 1e-7)
    assert not decided
    keep, *_ = rank._sequential_rank_test(A, 1e-7)
    np.testing.assert_array_equal(keep, _qr_test(A)[1])


def test_nan_is_never_decided_by_the_normal_equations():
    rng = np.random.default_rng(8)
    A = _unit_columns(rng, 100, 5, 5)
    A[3, 2] = np.nan
    *_, decided = rank_kernels.gram_sequential_test(np.ascontiguousarray(A.T), 1e-7)
    assert not decided


@pytest.mark.parametrize("seed", range(6))
def test_the_extreme_eigenvalues_are_lapacks(seed):
    from robocal.identify.kernels import stage

    rng = np.random.default_rng(seed)
    for p in (1, 2, 5, 27, 36):
        J = rng.normal(size=(3 * p + 3, p)) * np.logspace(0, rng.uniform(0, 5), p)
        if p > 2 and seed % 2:  # a nearly redundant pair: a tiny smallest eigenvalue
            J[:, -1] = 2.0 * J[:, 0] + 1e-8 * rng.normal(size=len(J))
        _, A = stage.normalised(J.T @ J)
        lam = np.linalg.eigvalsh(A)
        ends = stage.extreme_eigenvalues(A)
        np.testing.assert_allclose(ends, lam[[0, -1]], rtol=0, atol=1e-14 * lam[-1])
    # indefinite and diagonal matrices (a Gershgorin bound on an eigenvalue): the same ends
    S = rng.normal(size=(9, 9))
    for M in (S + S.T, np.diag([3.0, -1.0, 2.0])):
        np.testing.assert_allclose(stage.extreme_eigenvalues(M), np.linalg.eigvalsh(M)[[0, -1]], atol=1e-13)
    assert stage.extreme_eigenvalues(np.zeros((0, 0))).shape == (0,)


def test_the_covariance_reads_the_same_condition_number_and_singularity():
    from robocal.identify.kernels import stage

    rng = np.random.default_rng(11)
    J = rng.normal(size=(300, 27)) * np.logspace(0, 3, 27)
    G = J.T @ J
    cov, _, _, cond, ok = stage.normal_covariance(G, 2.0, 1e-14)
    assert ok and cond == pytest.approx(np.linalg.cond(J / np.linalg.norm(J, axis=0)), rel=1e-12)
    np.testing.assert_allclose(cov, 2.0 * np.linalg.inv(G), rtol=1e-9)
    J[:, 5] = J[:, 4]  # exactly redundant: singular, no covariance
    *_, cond, ok = stage.normal_covariance(J.T @ J, 1.0, 1e-14)
    assert not ok and cond == np.inf


def test_one_robots_size_is_the_batchs():
    from robocal.identify.stages import robot_size, robot_sizes

    rng = np.random.default_rng(12)
    for spread in (2.0, 0.01):  # a robot smaller than 0.1 m counts as 0.1 m
        T = np.tile(np.eye(4), (80, 1, 1))
        T[:, :3, 3] = rng.normal(scale=spread, size=(80, 3))
        T[60, :3, 3] = 50.0  # past the first 50 poses: not read
        assert robot_size(T) == robot_sizes(T[None])[0]
