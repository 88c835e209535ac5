# long: the evidence fit is one concept (normal equations by blocks, evidence, gradient, search)
"""The learned residual's evidence fit: Bayesian linear regression of the physical fit's
position residual on the joints' Fourier angle errors, hyperparameters by type-II maximum
likelihood (:func:`fit_joint_fourier`; the method, memory and time:
:mod:`robocal.identify.residual.stage`).  Units: SI (m, rad).
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.linalg import cho_solve, cholesky, solve_triangular
from scipy.linalg.blas import dtrmm
from scipy.linalg.lapack import dpotrf, dpotri, dtrtri, dtrtrs

from robocal.identify.residual.boxmin import Gradient, minimize_in_box
from robocal.model.fourier import fourier_basis
from robocal.model.residual import FADE, JointAngleResidual, covered_intervals, fourier_gram, one_blas_thread

__all__ = ["Hyper", "fit_joint_fourier"]

Array = NDArray[np.float64]
Index = NDArray[np.integer[Any]]  # indices (of coefficients, joints, poses)

CHUNK = 2048  # poses per chunk of the design matrix
#: poses x harmonics of a chunk from which :func:`raw_blocks` forms its diagonal blocks from
#: sums of harmonics rather than as products
SUMS_FROM = 40_000
MAX_AMPLITUDE = 2e-3  # rad, the largest prior RMS of a joint's angle error


@dataclass(frozen=True)
class Hyper:
    """Prior amplitude per joint (rad), spectral length scale ℓ (rad) and noise σ (m); as an
    evidence maximisation's start, optionally the curvature of ``−log E`` there along
    ``[log a_j..., log ℓ, log σ]`` (:mod:`robocal.identify.residual.curvature`)."""

    amplitudes: tuple[float, ...]
    length_scale: float
    noise: float
    curvature: tuple[float, ...] | None = dataclasses.field(default=None, compare=False, repr=False)


def gram_matrix(
    q: Array, r: Array, P: Array, template: JointAngleResidual, J: Array | None = None
) -> tuple[Array, Array, float, int]:
    """``G = AᵀA`` ``(m, m)``, ``b = Aᵀr`` ``(m,)``, ``rᵀr`` and the number of equations,
    accumulated over chunks of poses.  With the physical model's columns ``J`` ``(n, 3, p)``
    they are taken in the complement of ``J``'s column space (``A ← (I − QQᵀ) A``): the
    residual is fitted *jointly* with the physical parameters, which take back whatever
    part of the angle errors they can represent (a flat prior on them).

    The design is never formed: ``A[n, r, (j, h)] = P_j[n, r] B[n, j, h]`` (joint j's
    perturbation column times its basis), so block ``(j, j')`` of ``G`` is
    ``B_jᵀ diag(P_j · P_j') B_j'``: ``k(k+1)/2`` products of ``(2H, n) @ (n, 2H)`` instead of
    one ``(m, 3n) @ (3n, m)`` (5x fewer operations for six joints, no ``(3n, m)`` temporary).
    """
    with one_blas_thread_limit():
        return _gram_blocks(q, r, P, template, J)


one_blas_thread_limit = one_blas_thread  # the stage's BLAS limit (defined with the residual model)


@dataclass(frozen=True)
class _Normal:
    """What the evidence of one residual layout needs: ``G = AᵀA``, ``b = Aᵀr``, ``rᵀr``, the
    number of equations ``N``; with few equations (``N`` well below ``m``) also the design
    itself, ``A`` ``(N, m)`` and ``r`` ``(N,)`` in an orthonormal basis of the complement
    of the physical columns, for the evidence's dual form (:func:`_nll_and_grad_dual`)."""

    G: Array
    b: Array
    rr: float
    N: int
    A: Array | None = None
    r: Array | None = None


def gram_matrices(
    q: Array, r: Array, P: Array, template: JointAngleResidual, harmonics: Sequence[int], J: Array | None
) -> dict[int, _Normal]:
    """:func:`_gram` for each number of harmonics in ``harmonics`` from one pass at the
    largest: the basis of H harmonics is the first ``2H`` columns of each joint's basis of
    more (the fade depends on the angles only), so its ``G`` and ``b`` are a sub-block.
    With fewer equations than coefficients the design is kept (:class:`_Normal`)."""
    top = max(harmonics)
    m = len(template.joints) * 2 * top
    big = dataclasses.replace(template, harmonics=top, coefficients=np.zeros(m), covariance=np.zeros((m, m)))
    if r.size < m:
        A, y = _complement_design(q, r, P, big, J)
        G, b, rr, N = A.T @ A, A.T @ y, float(y @ y), len(y)
    else:
        (G, b, rr, N), A, y = gram_matrix(q, r, P, big, J), None, None
    out = {}
    for H in harmonics:
        keep = kept_columns(template, top, H)
        out[H] = _Normal(square_block(G, keep), b[keep], rr, N, None if A is None else A[:, keep], y)
    return out


def _complement_design(
    q: Array, r: Array, P: Array, template: JointAngleResidual, J: Array | None
) -> tuple[Array, Array]:
    """The design ``(N, m)`` and the residuals ``(N,)`` in an orthonormal basis ``U`` of the
    complement of ``J``'s columns (``N = 3n − p``; all equations without ``J``): ``UᵀA``
    gives :func:`_gram`'s ``G``, ``b`` and ``rᵀr`` exactly.  For few poses only (it is
    ``(3n, m)``)."""
    A = template.design(q, P).reshape(-1, template.size)
    y = r.reshape(-1)
    if J is None:
        return A, y
    J2 = J.reshape(-1, J.shape[-1])
    U = np.linalg.qr(J2, mode="complete")[0][:, J2.shape[1] :]
    return U.T @ A, U.T @ y


def _gram_blocks(
    q: Array, r: Array, P: Array, template: JointAngleResidual, J: Array | None
) -> tuple[Array, Array, float, int]:
    Q = None if J is None else np.linalg.qr(J.reshape(-1, J.shape[-1]))[0]
    raw = raw_blocks(q, r, P, template, None if Q is None else Q.reshape(len(q), 3, -1))
    G, b, rr, N = raw.AA, raw.Ar, raw.rr, raw.N
    if Q is not None:  # the complement of J's columns: QᵀQ = I
        G, b = G - raw.JA.T @ raw.JA, b - raw.JA.T @ raw.Jr
        rr, N = rr - float(raw.Jr @ raw.Jr), N - Q.shape[1]
    return G, b, rr, N


@dataclass(frozen=True)
class Raw:
    """The residual's normal equations before the physical columns ``J`` are projected out:
    ``AᵀA`` ``(m, m)``, ``JᵀA`` ``(p, m)``, ``Aᵀr``, ``JᵀJ``, ``Jᵀr``, ``rᵀr`` and the number of
    equations.  Sums over poses: a fold's training poses are all poses minus the fold's."""

    AA: Array
    JA: Array
    Ar: Array
    JJ: Array
    Jr: Array
    rr: float
    N: int

    def __sub__(self, other: Raw) -> Raw:
        return Raw(*(getattr(self, f.name) - getattr(other, f.name) for f in dataclasses.fields(self)))

    def __add__(self, other: Raw) -> Raw:
        return Raw(*(getattr(self, f.name) + getattr(other, f.name) for f in dataclasses.fields(self)))

    def projected(self, keep: Index) -> tuple[_Normal, Solver]:
        """The normal equations of the coefficients ``keep`` in the complement of ``J``'s
        columns (the physical parameters' least squares eliminated: ``G = AᵀA − AᵀJ (JᵀJ)⁻¹
        JᵀA``), and the solver of the physical parameters' step."""
        solver = Solver.of(self)
        W = solver.whiten(self.JA[:, keep])  # (p, m)
        w = solver.whiten(self.Jr)
        G = square_block(self.AA, keep) - W.T @ W
        normal = _Normal(0.5 * (G + G.T), self.Ar[keep] - W.T @ w, self.rr - float(w @ w), self.N - len(w))
        return normal, solver


@dataclass(frozen=True)
class Solver:
    """``JᵀJ``'s Cholesky factor with its columns scaled to unit diagonal (their units differ
    widely), and the pieces of :class:`_Raw` it solves with."""

    L: Array
    scale: Array
    raw: Raw

    @classmethod
    def of(cls, raw: Raw) -> Solver:
        scale = np.sqrt(np.maximum(np.diag(raw.JJ), 1e-300))
        return cls(cholesky(raw.JJ / np.outer(scale, scale), lower=True, check_finite=False), scale, raw)

    def whiten(self, X: Array) -> Array:
        """``L⁻¹ S⁻¹ X``: ``(JᵀJ)⁻¹ = S⁻¹ L⁻ᵀ L⁻¹ S⁻¹``."""
        scaled = X / (self.scale[:, None] if X.ndim == 2 else self.scale)
        return solve_triangular(self.L, scaled, lower=True, check_finite=False)

    def step(self, keep: Index | None = None, c: Array | None = None) -> Array:
        """``(p,)`` the physical parameters' least squares ``(JᵀJ)⁻¹ Jᵀ(r − A c)`` (``c`` the
        coefficients ``keep``; None: ``(JᵀJ)⁻¹ Jᵀ r``)."""
        rhs = self.raw.Jr if c is None else self.raw.Jr - self.raw.JA[:, keep] @ c
        return cho_solve((self.L, True), rhs / self.scale, check_finite=False) / self.scale


def raw_blocks(q: Array, r: Array, P: Array, template: JointAngleResidual, J: Array | None) -> Raw:
    """:class:`_Raw` over chunks of poses; ``J`` ``(n, 3, p)`` (None: no physical columns).

    Block ``(j, l)`` of ``AᵀA`` is ``B_jᵀ diag(P_j · P_l) B_l``, one product per pair ``l >= j``
    (the matrix is symmetric) from the basis laid out joint by joint, harmonic by pose
    (``(k, 2H, c)``, contiguous: the scaled copies and products of the ``(c, k, 2H)`` layout's
    strided slices took twice the time); on chunks of enough poses (:data:`SUMS_FROM`) where
    nothing fades the diagonal blocks come from their sums of harmonics
    (:func:`~robocal.model.residual.fourier_gram`)."""
    k, h2 = len(template.joints), 2 * template.harmonics
    m, p = template.size, 0 if J is None else J.shape[-1]
    AA, Ar, rr = np.zeros((m, m)), np.zeros(m), 0.0
    JA, JJ, Jr = np.zeros((p, m)), np.zeros((p, p)), np.zeros(p)
    index = list(template.joint_index)
    block = [slice(j * h2, (j + 1) * h2) for j in range(k)]
    for s in range(0, len(q), CHUNK):
        qs = q[s : s + CHUNK]
        Bt, faded = _joint_basis(template, qs)  # (k, 2H, c)
        cols = np.ascontiguousarray(P[s : s + CHUNK, :, index, 2])  # (c, 3, k)
        y = r[s : s + CHUNK]  # (c, 3)
        Wt = np.ascontiguousarray(np.einsum("crj,crl->jlc", cols, cols))  # (k, k, c): P_j · P_l per pose
        # sums of harmonics pay a fixed ~0.2 ms a joint (their 4H-harmonic basis): below
        # SUMS_FROM (poses x harmonics) the block's own product is cheaper (a 60-pose CV fold
        # at 48 harmonics: 0.02 ms a joint instead of 0.19; equal near 800 poses)
        plain = len(qs) * template.harmonics >= SUMS_FROM and not faded
        for j in range(k):
            if plain:  # unfaded: the diagonal block from its sums of harmonics
                AA[block[j], block[j]] += fourier_gram(qs[:, index[j]], Wt[j, j], h2 // 2)
            for i in range(j + 1 if plain else j, k):
                AA[block[j], block[i]] += (Bt[j] * Wt[j, i]) @ Bt[i].T
        u = np.einsum("crj,cr->jc", cols, y)  # (k, c)
        Ar += np.concatenate([Bt[j] @ u[j] for j in range(k)])
        rr += float(np.sum(y * y))
        if J is not None:
            Js = J[s : s + CHUNK]  # (c, 3, p)
            V = np.einsum("cri,crj->jic", Js, cols)  # (k, p, c)
            for j in range(k):
                JA[:, block[j]] += V[j] @ Bt[j].T
            J2 = Js.reshape(-1, p)
            JJ += J2.T @ J2
            Jr += J2.T @ y.reshape(-1)
    # the symmetric matrix from its upper triangle, block by block (two (m, m) triu copies
    # cost more than the blocks): lower blocks the upper ones transposed, diagonal blocks too
    for j in range(k):
        D = AA[block[j], block[j]]
        AA[block[j], block[j]] = np.triu(D) + np.triu(D, 1).T
        for i in range(j + 1, k):
            AA[block[i], block[j]] = AA[block[j], block[i]].T
    return Raw(AA, JA, Ar, JJ, Jr, rr, r.size)


def _joint_basis(template: JointAngleResidual, q: Array) -> tuple[Array, bool]:
    """``template.basis(q)`` laid out joint by joint, harmonic by pose (``(k, 2H, n)``,
    contiguous), and whether any of it fades at ``q``: the basis formed in that layout (the
    ``(n, k, 2H)`` basis copied to it took 2.0 of 0.8 ms at 2,000 poses, 48 harmonics) and
    the fade evaluated once for both; the same numbers."""
    g = template.global_harmonics
    B = np.ascontiguousarray(
        fourier_basis(q[:, list(template.joint_index)].T, template.harmonics).transpose(0, 2, 1)
    )
    fade = None if template.coverage is None else template.fade(q)  # (n, k)
    faded = fade is not None and not bool(np.all(fade == 1.0))
    if faded:
        assert fade is not None
        B[:, 2 * g :, :] *= fade.T[:, None, :]
    return B, faded


def kept_normal(normal: _Normal, keep: Index) -> _Normal:
    """The normal equations of the coefficients ``keep`` among those of ``normal`` (its
    sub-block: the physical columns' projection acts on the equations, not the coefficients),
    without the design."""
    return _Normal(square_block(normal.G, keep), normal.b[keep], normal.rr, normal.N)


def square_block(M: Array, keep: Index) -> Array:
    """``M[keep][:, keep]`` of a square ``M``: ``M`` itself (no copy) when ``keep`` is every
    index in order (the largest number of harmonics: a fold's (m, m) copy was half of its
    projection's time).  The evidence and the posterior only read it."""
    if len(keep) == len(M) and np.array_equal(keep, np.arange(len(M))):
        return M
    return M[np.ix_(keep, keep)]


def kept_columns(template: JointAngleResidual, top: int, H: int) -> Index:
    """The coefficients of H harmonics among those of ``top`` (joint by joint)."""
    return (np.arange(len(template.joints))[:, None] * 2 * top + np.arange(2 * H)).reshape(-1)


def _spectrum(log_ell: float, freq: Array) -> tuple[Array, Array]:
    """log of the normalised spectral weights per coefficient (they sum to 1 over one
    joint's coefficients, so that ``a_j`` is the RMS of the joint's angle error) and their
    derivative wrt ``log ℓ``."""
    u = -0.5 * (freq * np.exp(log_ell)) ** 2
    du = -((freq * np.exp(log_ell)) ** 2)
    _, first = np.unique(freq, return_index=True)
    w = np.exp(u[first] - u[first].max())
    log_z = np.log(2.0 * w.sum()) + u[first].max()
    dlog_z = float(np.sum(w * du[first]) / w.sum())
    return u - log_z, du - dlog_z


def apply(learned: JointAngleResidual, q: Array, P: Array) -> Array:
    """``A(q) c`` ``(n, r)``: the residual's position (or pose) correction, the angle errors
    times their perturbation columns (the design itself is not formed)."""
    cols = P[:, :, list(learned.joint_index), 2]  # (n, r, k)
    return np.einsum("nrk,nk->nr", cols, learned.angle_errors(q))


def prior(theta: Array, groups: Index, freq: Array) -> Array:
    """log prior variance per coefficient from ``theta = [log a_j..., log ℓ, log σ]``."""
    k = len(theta) - 2
    return 2.0 * theta[:k][groups] + _spectrum(theta[k], freq)[0]


def _posterior(G: Array, b: Array, log_s: Array, noise2: float) -> tuple[Array, Array, Array]:
    """Whitened Cholesky factor ``L``, mean ``μ`` and ``v = μ / s^½`` of the coefficients."""
    d = np.exp(0.5 * log_s)
    L = _whitened_factor(G, d, noise2)
    v = cho_solve((L, True), d * b / noise2, check_finite=False)
    return L, d * v, v


def _whitened_factor(G: Array, d: Array, noise2: float) -> Array:
    """The lower Cholesky factor ``(m, m)`` of ``K = D G D / σ² + I`` (``D = diag(d)``), formed
    in one array and factored in place: the temporaries of ``d[:, None] * G * d[None, :]``
    and LAPACK's copy to Fortran order cost as much as the factorisation itself at m = 576
    (the evidence's every evaluation)."""
    scale = d / np.sqrt(noise2)
    K = G * scale[:, None]
    K *= scale[None, :]
    K.flat[:: len(K) + 1] += 1.0  # the diagonal
    # K is symmetric: its transpose is the same matrix in Fortran order (no copy)
    L, info = dpotrf(K.T, lower=1, clean=1, overwrite_a=1)
    if info != 0:
        raise np.linalg.LinAlgError(f"Cholesky factorisation failed (info {info})")
    return L


def nll_and_grad(theta: Array, G: Array, b: Array, rr: float, N: int, groups: Index, freq: Array):
    """``−log E`` and its gradient at ``theta = [log a_j..., log ℓ, log σ]`` from the normal
    equations ``G``, ``b``, ``rr``, ``N`` (see the module docstring)."""
    nll, gradient, _ = nll_parts(theta, G, b, rr, N, groups, freq)
    return nll, gradient()


def nll_parts(
    theta: Array, G: Array, b: Array, rr: float, N: int, groups: Index, freq: Array
) -> tuple[float, Callable[[], Array], Array]:
    """:func:`nll_and_grad` with the gradient on demand, and the coefficients' posterior mean
    ``μ`` ``(m,)`` (rad) at ``theta``.  The gradient's triangular inverse is the larger half of
    an evaluation (1.4 of 2.9 ms at m = 480): a search needs none where it stops or rejects a
    step, and the mean saves the fold's posterior its own factorisation."""
    k = len(theta) - 2
    spectrum, dspectrum = _spectrum(theta[k], freq)
    log_s = 2.0 * theta[:k][groups] + spectrum  # prior(theta, groups, freq), its spectrum reused
    noise2 = float(np.exp(2.0 * theta[-1]))
    d = np.exp(0.5 * log_s)
    L = _whitened_factor(G, d, noise2)
    # LAPACK's triangular solves direct: scipy's solve_triangular checks cost 20 µs a call here
    z = _triangular_solve(L, d * b / noise2)
    v = _triangular_solve(L, z, transposed=True)  # K⁻¹ D b / σ² = μ / s^½
    mu = d * v
    nll = 0.5 * (rr / noise2 - z @ z + 2.0 * np.log(np.diag(L)).sum() + N * np.log(noise2))

    @functools.cache  # once: the inverse overwrites L
    def gradient() -> Array:
        Linv = _inverse_lower(L, overwrite=True)  # L is not used after this
        kinv_diag = np.einsum("ij,ij->j", Linv, Linv)  # diag of K⁻¹ = Σ_kk / s_k
        g_s = 0.5 * (1.0 - kinv_diag - v**2)  # ∂nll/∂log s_k
        gamma = float(np.sum(1.0 - kinv_diag))
        misfit = rr - 2.0 * mu @ b + mu @ G @ mu
        grad = np.empty_like(theta)
        grad[:k] = 2.0 * np.bincount(groups, weights=g_s, minlength=k)
        grad[k] = float(np.sum(g_s * dspectrum))
        grad[-1] = 2.0 * 0.5 * (N - gamma - misfit / noise2)  # ∂/∂log σ = 2 ∂/∂log σ²
        return grad

    return float(nll), gradient, mu


def nll_and_grad_dual(theta: Array, A: Array, r: Array, rr: float, N: int, groups: Index, freq: Array):
    """:func:`_nll_and_grad` from the design ``A`` ``(N, m)`` and residuals ``r`` ``(N,)``
    instead of ``G`` and ``b``, through the ``(N, N)`` matrix ``M = I + Ã Ãᵀ/σ²``
    (``Ã = A S^½``): ``det K = det M``, ``K⁻¹ = I − Ãᵀ M⁻¹ Ã/σ²`` (Woodbury).  The same
    function; cheaper when ``N`` is well below ``m`` (60 poses and 48 harmonics: 155 x 155
    instead of 576 x 576)."""
    k = len(theta) - 2
    log_s = prior(theta, groups, freq)
    noise2 = float(np.exp(2.0 * theta[-1]))
    At = A * np.exp(0.5 * log_s)
    M = (At @ At.T) / noise2
    M[np.diag_indices_from(M)] += 1.0
    L = cholesky(M, lower=True, check_finite=False)
    W = solve_triangular(L, At, lower=True, check_finite=False)
    kinv_diag = 1.0 - np.einsum("ij,ij->j", W, W) / noise2  # diag of K⁻¹ = Σ_kk / s_k
    v = At.T @ cho_solve((L, True), r, check_finite=False) / noise2  # μ / s^½
    Atr = At.T @ r
    nll = 0.5 * (rr / noise2 - Atr @ v / noise2 + 2.0 * np.log(np.diag(L)).sum() + N * np.log(noise2))
    g_s = 0.5 * (1.0 - kinv_diag - v**2)
    gamma = float(np.sum(1.0 - kinv_diag))
    e = r - At @ v
    misfit = float(e @ e)
    grad = np.empty_like(theta)
    grad[:k] = 2.0 * np.bincount(groups, weights=g_s, minlength=k)
    grad[k] = float(np.sum(g_s * _spectrum(theta[k], freq)[1]))
    grad[-1] = 2.0 * 0.5 * (N - gamma - misfit / noise2)
    return float(nll), grad


def _dual_is_cheaper(N: int, m: int) -> bool:
    """The dual form's operations (``2N²m + N³/3``) below the primal's (``2m³/3``)."""
    return 2.0 * N * N * m + N**3 / 3.0 < 2.0 * m**3 / 3.0


def _triangular_solve(L: Array, y: Array, transposed: bool = False) -> Array:
    """``L⁻¹ y`` (``L⁻ᵀ y`` when ``transposed``) for a lower-triangular ``L`` (LAPACK's dtrtrs,
    as scipy's solve_triangular without its argument checks)."""
    x, info = dtrtrs(L, y, lower=1, trans=int(transposed))
    if info != 0:
        raise np.linalg.LinAlgError(f"triangular solve failed (info {info})")
    return x


#: the order below which :func:`_inverse_lower` calls LAPACK's dtrtri itself
INVERSE_LEAF = 128


def _inverse_lower(L: Array, overwrite: bool = False) -> Array:
    """``L⁻¹`` of a lower-triangular Cholesky factor whose upper triangle is zero (as
    :func:`_whitened_factor` returns it), by halves: ``[[A, 0], [B, C]]⁻¹ = [[A⁻¹, 0],
    [−C⁻¹ B A⁻¹, C⁻¹]]``, the off-diagonal block by two triangular products (BLAS-3 dtrmm)
    and the halves the same way down to :data:`INVERSE_LEAF` (LAPACK's dtrtri).  The same
    operations as dtrtri's (a third of the work of solving against the identity), but
    OpenBLAS runs its own dtrtri at about half its triangular products' rate: 480 x 480
    1.44 -> 1.02 ms, the larger half of the evidence gradient's time at 48 harmonics.
    ``overwrite``: the leaf may reuse ``L``'s memory (in Fortran order)."""
    n = len(L)
    if n <= INVERSE_LEAF:
        Linv, info = dtrtri(L, lower=1, overwrite_c=int(overwrite))
        if info != 0:
            raise np.linalg.LinAlgError(f"triangular inverse failed (info {info})")
        return Linv
    h = n // 2
    top, bottom = _inverse_lower(L[:h, :h]), _inverse_lower(L[h:, h:])
    below = dtrmm(1.0, top, L[h:, :h], side=1, lower=1)  # B A⁻¹
    below = dtrmm(-1.0, bottom, below, lower=1, overwrite_b=1)  # −C⁻¹ B A⁻¹
    out = np.zeros((n, n), order="F")
    out[:h, :h], out[h:, :h], out[h:, h:] = top, below, bottom
    return out


def _inverse_from_factor(L: Array) -> Array:
    """``K⁻¹`` ``(m, m)`` from the lower Cholesky factor ``L`` of ``K`` (LAPACK's dpotri: the
    triangular inverse times its transpose as one triangular multiply, a third of the
    general product's work), both triangles filled."""
    lower, info = dpotri(L, lower=1)
    if info != 0:
        raise np.linalg.LinAlgError(f"inverse from the Cholesky factor failed (info {info})")
    return np.tril(lower) + np.tril(lower, -1).T


def layout(template: JointAngleResidual) -> tuple[Index, Array]:
    H = template.harmonics
    groups = np.repeat(np.arange(len(template.joints)), 2 * H)
    freq = np.tile(np.repeat(np.arange(1, H + 1), 2), len(template.joints)).astype(float)
    return groups, freq


def residual_template(
    joint_names: Sequence[str], joint_index: Sequence[int], harmonics: int, q: Array | None = None
) -> JointAngleResidual:
    """An empty residual of this layout; with ``q`` it covers the angles of ``q``."""
    m = len(joint_names) * 2 * harmonics
    ranges = None if q is None else tuple(covered_intervals(q[:, j], 2 * FADE) for j in joint_index)
    return JointAngleResidual(
        tuple(joint_names), tuple(joint_index), harmonics, np.zeros(m), np.zeros((m, m)), 0.0,
        (0.0,) * len(joint_names), 0.0, ranges,
    )  # fmt: skip


def fit_joint_fourier(
    q: Array,
    residuals: Array,
    P: Array,
    joint_names: Sequence[str],
    joint_index: Sequence[int],
    harmonics: int,
    hyper: Hyper | None = None,
    J: Array | None = None,
    start: Hyper | None = None,
    gram: _Normal | None = None,
) -> tuple[JointAngleResidual, Hyper]:
    """Fit per-joint Fourier angle errors to position residuals.

    Args:
        q: ``(n, dof)`` joint values (rad).
        residuals: ``(n, 3)`` measured minus predicted position (m) of the physical model.
        P: ``(n, 3, dof, 3)`` perturbation Jacobian of the physical model at ``q``, in the
            same frame as ``residuals``.
        joint_names, joint_index: the joints whose angle errors are modelled.
        harmonics: H.
        hyper: fixed hyperparameters (skip the evidence maximisation), e.g. in CV folds.
        J: ``(n, 3, p)`` the physical model's columns at ``q`` (its derivatives wrt its
            estimated parameters): fit jointly with them (see :func:`_gram`).
        start: start values of the evidence maximisation (e.g. the hyperparameters found
            on all poses, for a CV fold); default a neutral start.
        gram: the normal equations of these arguments when already computed (:func:`_grams`).

    Returns the residual model and its hyperparameters.
    """
    template = residual_template(joint_names, joint_index, harmonics, q)
    if gram is None:
        gram = gram_matrices(q, residuals, P, template, [harmonics], J)[harmonics]
    with one_blas_thread_limit():
        model, hyper = _fit(template, gram, hyper, start)
    model = model.covering(q)  # fades within its prior's correlation length of the poses' angles
    # the size of what fades (the harmonics above the global ones) on the calibration poses
    fading = model.coefficients.reshape(len(model.joints), harmonics, 2).copy()
    fading[:, : model.global_harmonics] = 0.0
    rms = np.sqrt(
        np.mean(dataclasses.replace(model, coefficients=fading.reshape(-1)).angle_errors(q) ** 2, axis=0)
    )
    return dataclasses.replace(model, angle_rms=tuple(float(v) for v in rms)), hyper


def _fit(
    template: JointAngleResidual, normal: _Normal, hyper: Hyper | None, start: Hyper | None
) -> tuple[JointAngleResidual, Hyper]:
    """:func:`fit_joint_fourier` from its normal equations (without ``angle_rms``)."""
    if hyper is None:
        hyper = evidence(template, normal, start)
    groups, freq = layout(template)
    log_s = prior(_theta(hyper), groups, freq)
    L, mu, _ = _posterior(normal.G, normal.b, log_s, hyper.noise**2)
    d = np.exp(0.5 * log_s)
    cov = (d[:, None] * _inverse_from_factor(L)) * d[None, :]
    model = JointAngleResidual(
        template.joints, template.joint_index, template.harmonics, mu, 0.5 * (cov + cov.T), hyper.noise,
        hyper.amplitudes, hyper.length_scale, template.coverage,
    )  # fmt: skip
    return model, hyper


def _theta(hyper: Hyper) -> Array:
    """``[log a_j..., log ℓ, log σ]`` of ``hyper``."""
    return np.r_[np.log(hyper.amplitudes), np.log(hyper.length_scale), np.log(hyper.noise)]


def evidence(
    template: JointAngleResidual, normal: _Normal, start: Hyper | None, maxiter: int = 200, ftol: float = 1e-8
) -> Hyper:
    """The hyperparameters that maximise the evidence (projected BFGS in the box of their
    bounds, :func:`~robocal.identify.residual.boxmin.minimize_in_box`, from ``start``, else a
    neutral start), in its dual form when that is cheaper."""
    return evidence_and_mean(template, normal, start, maxiter, ftol)[0]


def evidence_and_mean(
    template: JointAngleResidual, normal: _Normal, start: Hyper | None, maxiter: int = 200, ftol: float = 1e-8
) -> tuple[Hyper, Array | None]:
    """:func:`evidence` and the coefficients' posterior mean ``(m,)`` (rad) there, as the
    search's last evaluation found it (:func:`posterior_mean` of the result, to rounding;
    None from the dual form)."""
    G, b, rr, N = normal.G, normal.b, normal.rr, normal.N
    groups, freq = layout(template)
    k = len(template.joints)
    theta0 = np.r_[np.full(k, np.log(2e-4)), np.log(0.02), np.log(max(float(np.sqrt(rr / N)), 1e-7))]
    if start is not None:
        theta0 = _theta(start)
    # a joint's angle error is physically small: transmission errors of robot gears are
    # arcminutes (0.3 mrad); 2 mrad bounds the prior well above that and keeps the evidence
    # out of the degenerate optimum where huge coefficients cancel (seen at H = 12)
    bounds = [(np.log(1e-9), np.log(MAX_AMPLITUDE))] * k + [
        (np.log(1e-4), np.log(2.0)),
        (np.log(1e-7), np.log(1e-2)),
    ]
    # the start's curvature known: the search in θ·√h, where its gradient step is near Newton's
    w = (
        np.ones(k + 2)
        if start is None or start.curvature is None
        else np.sqrt(np.maximum(start.curvature, 1.0))
    )
    means: dict[bytes, Array] = {}  # the posterior mean at each point evaluated, by its φ
    fun: Callable[..., tuple[float, Gradient]]
    if normal.A is not None and _dual_is_cheaper(*normal.A.shape):
        fun, data = _scaled(nll_and_grad_dual, w), (normal.A, normal.r)
    else:
        fun, data = _scaled_lazy(w, means), (G, b)
    lower, upper = (np.array(side) * w for side in zip(*bounds, strict=True))
    found = minimize_in_box(
        fun,
        theta0 * w,
        lower,
        upper,
        (*data, rr, N, groups, freq),
        maxiter,
        ftol,
        newton_scaled=start is not None and start.curvature is not None,
    )
    theta = found.x / w
    hyper = Hyper(
        tuple(float(np.exp(t)) for t in theta[:k]), float(np.exp(theta[k])), float(np.exp(theta[-1]))
    )
    return hyper, means.get(found.x.tobytes())


def _scaled(fun: Callable[..., tuple[float, Array]], w: Array) -> Callable[..., tuple[float, Array]]:
    """``fun`` of ``θ`` as a function of ``φ = θ·w`` (its gradient in ``φ``)."""

    def scaled(phi: Array, *args: Any) -> tuple[float, Array]:
        f, g = fun(phi / w, *args)
        return f, g / w

    return scaled


def _scaled_lazy(w: Array, means: dict[bytes, Array]) -> Callable[..., tuple[float, Callable[[], Array]]]:
    """:func:`nll_parts` as a function of ``φ = θ·w``: ``−log E`` and its gradient in ``φ`` on
    demand; each point's posterior mean goes into ``means`` by the bytes of its ``φ``."""

    def scaled(phi: Array, *args: Any) -> tuple[float, Callable[[], Array]]:
        f, gradient, mu = nll_parts(phi / w, *args)
        means[phi.tobytes()] = mu
        return f, lambda: gradient() / w

    return scaled


def posterior_mean(template: JointAngleResidual, normal: _Normal, hyper: Hyper) -> Array:
    """``(m,)`` the coefficients' posterior mean (rad) for ``hyper`` (no covariance: what a
    cross-validation fold needs)."""
    groups, freq = layout(template)
    return _posterior(normal.G, normal.b, prior(_theta(hyper), groups, freq), hyper.noise**2)[1]
