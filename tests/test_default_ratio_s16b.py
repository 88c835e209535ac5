"""The default calibration's extra cost over the physics alone (issue 35, session 16, second
pass): the learned residual's arithmetic by cheaper but equivalent routes.

Each route is checked against the direct one it replaces: the triangular inverse by halves
against LAPACK's dtrtri, the inverses from a Cholesky factor against the general inverse,
the normal equations of every number of harmonics as sub-blocks of the largest's projection
against their own projections, a physical fit's rows formed with the perturbations once
against the result's own methods.
"""

from __future__ import annotations

import functools
import operator

import numpy as np
import pytest
from scipy.linalg.lapack import dpotrf, dtrtri

import robocal.identify.residual.fit as fit
from robocal.identify.residual import cv, stage


def _spd(m: int, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    A = rng.normal(size=(m, 2 * m))
    return A @ A.T / m + np.eye(m)


def _factor(K: np.ndarray) -> np.ndarray:
    """The lower Cholesky factor in Fortran order, its upper triangle zero (as the evidence's)."""
    L, info = dpotrf(np.asfortranarray(K), lower=1, clean=1)
    assert info == 0
    return L


@pytest.mark.parametrize("m", [5, fit.INVERSE_LEAF, fit.INVERSE_LEAF + 1, 300, 480])
def test_the_triangular_inverse_by_halves_is_lapacks(m):
    L = _factor(_spd(m, seed=m))
    reference, info = dtrtri(L, lower=1)
    assert info == 0
    for overwrite in (False, True):
        Linv = fit._inverse_lower(np.array(L, order="F"), overwrite=overwrite)
        assert np.max(np.abs(Linv - reference)) <= 1e-13 * np.max(np.abs(reference))
        assert np.all(np.triu(Linv, 1) == 0.0)  # the gradient sums squares of its columns
        assert np.max(np.abs(Linv @ L - np.eye(m))) < 1e-12


def test_a_singular_triangle_is_refused_at_every_size():
    for m in (4, 300):
        L = _factor(_spd(m))
        L[m - 2, m - 2] = 0.0
        with pytest.raises(np.linalg.LinAlgError):
            fit._inverse_lower(L)


@pytest.mark.parametrize("m", [3, 200])
def test_inverses_from_a_cholesky_factor_are_the_inverse(m):
    K = _spd(m, seed=3)
    inverse = np.linalg.inv(K)
    tol = 1e-12 * np.max(np.abs(inverse))
    from_factor = fit._inverse_from_factor(_factor(K))
    assert np.max(np.abs(from_factor - inverse)) < tol
    assert np.array_equal(from_factor, from_factor.T)
    assert np.max(np.abs(stage._spd_inverse(K) - inverse)) < tol


def test_the_fisher_inverse_falls_back_to_the_general_one_and_refuses_a_singular_matrix():
    indefinite = np.array([[1.0, 2.0], [2.0, 1.0]])  # symmetric, not positive definite
    assert stage._spd_inverse(indefinite) == pytest.approx(np.linalg.inv(indefinite))
    with pytest.raises(np.linalg.LinAlgError):
        stage._spd_inverse(np.zeros((3, 3)))


def test_a_square_block_of_every_index_is_the_matrix_itself_and_otherwise_the_block():
    M = np.arange(36.0).reshape(6, 6)
    assert fit.square_block(M, np.arange(6)) is M
    for keep in (np.array([0, 1, 3, 4]), np.array([1, 0, 2, 3, 4, 5]), np.arange(5)):
        assert np.array_equal(fit.square_block(M, keep), M[np.ix_(keep, keep)])


@pytest.fixture(scope="module")
def twin():
    """``(result, data)``: the physical fit of a UR10 twin with transmission errors the physics
    lacks (``tests/test_residual.py``'s), 300 poses."""
    from robocal.identify.pipeline import calibrate_physics
    from tests.test_residual import PROBE, _case, _ur10

    (data, _), model = _case(errors=True, n_train=300, seed=3), _ur10()
    return calibrate_physics(model, data, "lm", tool_guess=PROBE), data


def _fit_of(result, data) -> cv.PhysicalFit:
    p, P, J = cv.PhysicalFit(result, np.empty(0), np.empty(0), np.empty(0)).predict(data.q)
    return cv.PhysicalFit(result, data.position - p, P, J)


def test_a_physical_fits_rows_equal_the_results_own(twin):
    """``PhysicalFit.predict`` forms the joint perturbations and the perturbation Jacobian
    once for the positions, ``P`` and the parameters' columns: the result's own methods give
    the same arrays, bit for bit."""
    result, q = twin[0], twin[1].q[:40]
    p, P, J = cv.PhysicalFit(result, np.empty(0), np.empty(0), np.empty(0)).predict(q)
    assert np.array_equal(p, result.predict(q)[:, :3, 3])
    chain = result.measurement_chain
    assert np.array_equal(P, chain.perturbation_jacobian(q, "position", result.joint_perturbations(q)))
    assert np.array_equal(J, result.position_columns(q))


def test_fewer_harmonics_normal_equations_are_sub_blocks_of_the_largest_projection(twin):
    """The CV's fits on all poses take each number of harmonics' normal equations as the
    sub-block of the largest's projection (one projection instead of one per number): the
    same equations as projecting each layout on its own, to rounding."""
    result, data = twin
    full = _fit_of(result, data)
    names, index, q = [f"j{i}" for i in range(6)], list(range(6)), data.q
    problem = cv._Problem(q, data.position, tuple(names), tuple(index), (4, 12, 24))
    parts = np.array_split(np.random.default_rng(0).permutation(len(q)), 5)
    raws = cv._fold_raws(problem, full, parts)
    assert raws is not None
    total = functools.reduce(operator.add, raws)
    top = total.projected(np.arange(len(total.Ar)))[0]
    one = fit.residual_template(names, index, 1)
    for H in (4, 12, 24):
        keep = fit.kept_columns(one, 24, H)
        own, sub = total.projected(keep)[0], fit.kept_normal(top, keep)
        scale = np.max(np.abs(own.G))
        assert np.max(np.abs(sub.G - own.G)) < 1e-10 * scale
        assert np.array_equal(sub.G, sub.G.T)
        assert sub.b == pytest.approx(own.b, rel=1e-9, abs=1e-12 * np.max(np.abs(own.b)))
        assert (sub.rr, sub.N) == (own.rr, own.N)


def test_small_chunks_diagonal_blocks_by_products_equal_the_sums_of_harmonics(twin, monkeypatch):
    """:func:`fit.raw_blocks` forms a chunk's diagonal blocks as products below
    ``SUMS_FROM`` poses x harmonics (a CV fold's 60 poses), from sums of harmonics above:
    the same normal equations either way, to rounding."""
    result, data = twin
    full = _fit_of(result, data)
    rows = slice(0, 60)
    q, r, P, J = data.q[rows], full.residuals[rows], full.P[rows], full.J[rows]
    template = fit.residual_template([f"j{i}" for i in range(6)], list(range(6)), 24, data.q)
    assert len(q) * template.harmonics < fit.SUMS_FROM
    by_products = fit.raw_blocks(q, r, P, template, J)
    monkeypatch.setattr(fit, "SUMS_FROM", 0)
    by_sums = fit.raw_blocks(q, r, P, template, J)
    scale = np.max(np.abs(by_sums.AA))
    assert np.max(np.abs(by_products.AA - by_sums.AA)) < 1e-12 * scale
    assert np.array_equal(by_products.AA, by_products.AA.T)
    for name in ("JA", "Ar", "JJ", "Jr"):
        assert np.array_equal(getattr(by_products, name), getattr(by_sums, name))


def test_the_joint_by_joint_basis_is_the_templates_basis_faded_or_not(twin):
    """``fit._joint_basis`` forms the basis in the normal equations' layout directly: equal,
    bit for bit, to the residual's own ``basis`` transposed, where it fades and where not."""
    q = twin[1].q
    names, index = [f"j{i}" for i in range(6)], list(range(6))
    covering_all = fit.residual_template(names, index, 12, q)
    few = fit.residual_template(names, index, 12, q[:15]).covering(q[:15])  # fades elsewhere
    no_coverage = fit.residual_template(names, index, 12)
    for template, fades in ((covering_all, False), (few, True), (no_coverage, False)):
        B, faded = fit._joint_basis(template, q)
        assert faded == fades
        assert B.flags.c_contiguous
        assert np.array_equal(B, template.basis(q).transpose(1, 2, 0))
