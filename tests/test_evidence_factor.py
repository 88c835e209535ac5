"""The learned residual's evidence as it is evaluated on every step of its maximisation (issue
35: the matrix ``K = D G D / σ² + I`` formed in one array and factored in place): the same
function as the Gaussian marginal likelihood written out, the normal equations left as they
were, and a matrix that is not positive definite refused rather than factored."""

from __future__ import annotations

import numpy as np
import pytest

from robocal.identify.residual.fit import layout, nll_and_grad, prior, residual_template


def _problem(seed: int = 0, n_rows: int = 90, harmonics: int = 4):
    """A random design ``(N, m)``, residuals ``(N,)`` and the layout of 3 joints' coefficients."""
    rng = np.random.default_rng(seed)
    template = residual_template(["a", "b", "c"], [0, 1, 2], harmonics)
    A = rng.normal(size=(n_rows, template.size)) * 1e-2
    r = rng.normal(size=n_rows) * 1e-4
    groups, freq = layout(template)
    theta = np.r_[np.log([3e-4, 1e-3, 5e-4]), np.log(0.3), np.log(2e-5)]
    return A, r, groups, freq, theta


def _direct_nll(A, r, theta, groups, freq) -> float:
    """``-log p(r)`` without the ``2π`` constant: ``r ~ N(0, σ² I + A S Aᵀ)``."""
    S = np.exp(prior(theta, groups, freq))
    C = np.exp(2.0 * theta[-1]) * np.eye(len(r)) + (A * S) @ A.T
    return 0.5 * (r @ np.linalg.solve(C, r) + np.linalg.slogdet(C)[1])


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_evidence_is_the_gaussian_marginal_likelihood(seed):
    A, r, groups, freq, theta = _problem(seed)
    G, b = A.T @ A, A.T @ r
    G_before, b_before = G.copy(), b.copy()
    for shift in (0.0, 0.7, -0.9):  # prior wide and narrow, noise large and small
        t = theta + shift * np.r_[np.ones(3), 0.5, -1.0]
        nll, grad = nll_and_grad(t, G, b, float(r @ r), len(r), groups, freq)
        assert nll == pytest.approx(_direct_nll(A, r, t, groups, freq), rel=1e-9, abs=1e-6)
        for i in range(len(t)):  # the analytic gradient of that same function
            e = np.zeros_like(t)
            e[i] = 1e-6
            numeric = (_direct_nll(A, r, t + e, groups, freq) - _direct_nll(A, r, t - e, groups, freq)) / 2e-6
            assert grad[i] == pytest.approx(numeric, rel=1e-4, abs=1e-3)
    # the factorisation works on its own array: the normal equations are the caller's
    np.testing.assert_array_equal(G, G_before)
    np.testing.assert_array_equal(b, b_before)


def test_a_matrix_that_is_not_positive_definite_is_refused():
    A, r, groups, freq, theta = _problem()
    G = A.T @ A
    G -= 2.0 * np.abs(np.linalg.eigvalsh(G)).max() * np.eye(len(G))  # K = I + D G D / σ² indefinite
    with pytest.raises(np.linalg.LinAlgError):
        nll_and_grad(theta, G, A.T @ r, float(r @ r), len(r), groups, freq)
