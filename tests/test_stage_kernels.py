"""The compiled linear algebra between the fits (robocal.identify.kernels.stage, behind
robocal.identify.stages) against the numpy code it replaced, kept here as the reference."""

from __future__ import annotations

import numpy as np
import pytest

from robocal.identify import stages
from robocal.identify.stages import residual_variance


# ---------------------------------------------------------------------- the numpy reference
def normal_inverse_reference(J):
    norms = np.sqrt(np.einsum("ij,ij->j", J, J))
    norms[norms == 0] = 1.0
    Jn = J / norms
    lam, V = np.linalg.eigh(Jn.T @ Jn)
    with np.errstate(divide="ignore", invalid="ignore"):
        inverse = (V / lam) @ V.T
    return Jn, norms, lam, inverse


def screen_reference(r, J, scale, max_std=5e-4, max_std_ratio=3.0, margin=3.0, known_noise=False):
    keep = np.ones(J.shape[1], dtype=bool)
    out = []
    while keep.sum() > 1:
        Jn, norms, lam, inverse = normal_inverse_reference(J[:, keep])
        if lam[0] <= 1e-14 * lam[-1]:
            break
        e = r - Jn @ (inverse @ (Jn.T @ r))
        s2 = 1.0 if known_noise else float(e @ e) / max(len(r) - int(keep.sum()), 1)
        move = np.sqrt(s2 * np.diag(inverse)) / norms * scale[keep]
        worst = int(np.argmax(move))
        if move[worst] <= margin * max(max_std, max_std_ratio * np.median(move)):
            break
        column = int(np.flatnonzero(keep)[worst])
        out.append((column, float(move[worst])))
        keep[column] = False
    return out


def uncertainty_reference(r, J, rows, known_noise=False):
    m, p = J.shape
    if rows == 3:
        row_s2 = np.full(m, residual_variance(float(r @ r), m - p, known_noise))
    else:
        position = np.tile(np.arange(rows) < 3, m // rows)
        row_s2 = np.empty(m)
        for group, known in ((position, known_noise), (~position, False)):
            dof = group.sum() - p * group.sum() / m
            row_s2[group] = residual_variance(float(r[group] @ r[group]), dof, known)
    s2 = float(row_s2[0])
    Jn, norms, lam, inverse = normal_inverse_reference(J)
    cond = np.sqrt(lam[-1] / lam[0])
    cov = inverse @ (Jn.T @ (Jn * row_s2[:, None])) @ inverse / np.outer(norms, norms)
    std = np.sqrt(np.clip(np.diag(cov), 0, None))
    corr = cov / np.outer(std, std)
    return s2, cov, std, corr, cond


# ---------------------------------------------------------------------- problems
def _problem(seed, m=300, p=27, spread=1e3, noise=1e-3):
    """A weighted Jacobian with columns of very different norms and correlations, and
    residuals of a linear model at ``noise``."""
    rng = np.random.default_rng(seed)
    J = rng.normal(size=(m, p)) @ (np.eye(p) + 0.3 * rng.normal(size=(p, p)))
    J *= np.logspace(0, np.log10(spread), p)[rng.permutation(p)]
    r = J @ rng.normal(scale=1e-4, size=p) + rng.normal(scale=noise, size=m)
    return r, J


@pytest.mark.parametrize("seed", range(5))
def test_normal_inverse_matches_the_eigendecomposition(seed):
    _, J = _problem(seed)
    scale = 1e-3 * np.linalg.norm(J[:, 5]) / len(J) ** 0.5
    noise = np.random.default_rng(seed).normal(scale=scale, size=len(J))
    J[:, 3] = J[:, 4] * 1e-3 + J[:, 5] + noise  # nearly dependent: condition ~1e3
    for got, want in zip(stages.normal_inverse(J), normal_inverse_reference(J), strict=True):
        np.testing.assert_allclose(got, want, rtol=1e-8, atol=1e-9)


def test_normal_inverse_keeps_a_zero_column_at_norm_one():
    _, J = _problem(0, p=6)
    J[:, 3] = 0.0
    Jn, norms, lam, _ = stages.normal_inverse(J)
    assert norms[3] == 1.0 and not Jn[:, 3].any()
    np.testing.assert_allclose(norms, normal_inverse_reference(J)[1], rtol=1e-14)
    assert abs(lam[0]) <= 1e-14 * lam[-1]


def test_normal_inverse_of_a_singular_matrix_falls_back_to_the_eigendecomposition():
    _, J = _problem(0, p=6)
    J[:, 2] = 2 * J[:, 1]
    _, _, lam, inverse = stages.normal_inverse(J)
    assert lam[0] <= 1e-14 * lam[-1]
    np.testing.assert_allclose(lam, normal_inverse_reference(J)[2], atol=1e-12)
    assert inverse.shape == (6, 6)


@pytest.mark.parametrize("seed", range(8))
def test_screening_matches_numpy(seed):
    r, J = _problem(seed, p=12, spread=1e2)
    J[:, seed % 12] *= 1e-4  # one nearly flat direction: screened
    rng = np.random.default_rng(seed)
    J[:, (seed + 5) % 12] = J[:, (seed + 6) % 12] + 0.01 * rng.normal(size=len(r))  # a correlated pair
    scale = np.full(12, 0.5)
    for known in (False, True):
        got = stages.screen_unidentifiable(r, J, scale, known_noise=known)
        want = screen_reference(r, J, scale, known_noise=known)
        assert [c for c, _ in got] == [c for c, _ in want]
        np.testing.assert_allclose([s for _, s in got], [s for _, s in want], rtol=1e-6)
    assert stages.screen_unidentifiable(r, J, scale)  # the flat direction is found


def test_screening_stops_at_a_singular_matrix():
    r, J = _problem(1, p=6)
    J[:, 4] = J[:, 5]
    assert stages.screen_unidentifiable(r, J, np.ones(6)) == []


@pytest.mark.parametrize(("rows", "known"), [(3, False), (3, True), (6, False), (6, True)])
def test_uncertainty_matches_numpy(rows, known):
    r, J = _problem(rows + known, noise=1.0)
    if rows == 6:
        r[3::6] *= 4.0  # orientation rows noisier: the sandwich covariance
    got = stages.uncertainty(r, J, rows, known_noise=known)
    want = uncertainty_reference(r, J, rows, known_noise=known)
    assert got[0] == pytest.approx(want[0], rel=1e-12)
    for a, b in zip(got[1:4], want[1:4], strict=True):
        np.testing.assert_allclose(a, b, rtol=1e-8, atol=1e-14)
    assert got[4] == pytest.approx(want[4], rel=1e-8)


def test_uncertainty_of_a_nearly_singular_fit_uses_the_singular_values():
    r, J = _problem(2, p=5)
    J[:, 4] = J[:, 3] + 1e-9 * J[:, 0]  # condition ~1e9: past the eigenvalues' digits
    _, _, std, corr, cond = stages.uncertainty(r, J, 3)
    Jn = J / np.linalg.norm(J, axis=0)
    sv = np.linalg.svd(Jn, compute_uv=False)
    assert cond == pytest.approx(sv[0] / sv[-1], rel=1e-6)
    assert np.all(np.isfinite(std)) and np.all(np.abs(corr) <= 1 + 1e-9)


@pytest.mark.parametrize("seed", range(6))
def test_rank_test_fit_matches_numpy(seed):
    """The compiled rank decision and normal-equation fit of the dropped columns in the
    kept ones, from the QR, against numpy on the columns themselves."""
    import scipy.linalg

    from robocal.model.rank_kernels import sequential_test

    rng = np.random.default_rng(seed)
    A = rng.normal(size=(60, 8)) @ rng.normal(size=(8, 12))  # rank 8 of 12
    A /= np.linalg.norm(A, axis=0)
    qr = scipy.linalg.lapack.dgeqrf(A)[0]
    diag, keep, coefs, left, ok = sequential_test(qr, 1e-7)
    assert ok and keep.sum() == 8
    np.testing.assert_array_equal(diag, np.abs(np.diag(scipy.linalg.qr(A, mode="r")[0])))
    K, D = A[:, keep], A[:, ~keep]
    want = np.linalg.solve(K.T @ K, K.T @ D)
    np.testing.assert_allclose(coefs, want, rtol=1e-7, atol=1e-9)
    np.testing.assert_allclose(left, np.linalg.norm(D - K @ want, axis=0), atol=1e-10)
    assert np.all(left < 1e-7)  # the dropped columns lie in the span of the kept ones
    nothing_kept = sequential_test(np.zeros((5, 3)), 1e-7)
    assert not nothing_kept[4] and not nothing_kept[1].any()


def test_kernel_cache_check_names_the_kernels_without_machine_code(monkeypatch):
    """The first-use notice: a kernel whose cache index is empty (never compiled, or
    compiled for another source) is listed; a cached one is not."""
    from robocal.identify import kernel_cache
    from robocal.model import kernels

    monkeypatch.setattr(kernel_cache, "KERNELS", (("robocal.model.kernels", "forward"),))
    cache_file = kernels.forward._cache._cache_file
    monkeypatch.setattr(cache_file, "_load_index", lambda: {})
    assert kernel_cache.kernels_to_compile() == ["robocal.model.kernels.forward"]
    monkeypatch.setattr(cache_file, "_load_index", lambda: {"a signature": "its machine code"})
    assert kernel_cache.kernels_to_compile() == []
