"""Fitting the learned residual, and choosing it by cross-validation on the training poses.

The residual model (:class:`robocal.model.residual.JointAngleResidual`) is linear in its
coefficients ``c``: the position residual of the physical fit is ``r ≈ A(q) c`` with
``A = ∂p/∂δθ_j · [cos h q_j, sin h q_j]`` (the perturbation Jacobian times the Fourier
basis).  With the prior ``c ~ N(0, S)``, ``S = diag(a_j² w_h)``, ``w_h ∝ exp(-(h ℓ)²/2)``
normalised so that ``a_j`` is the RMS of joint j's angle error — a stationary Gaussian
process on each joint's circle — and noise ``σ²``, the posterior is Gaussian
(Bayesian linear regression) and the hyperparameters ``a_j, ℓ, σ`` maximise the
evidence (type-II maximum likelihood).  Everything is in the *whitened* coordinates
``c = S^½ v`` so that the matrix factored, ``S^½ G S^½ / σ² + I``, is positive definite
whatever the prior; the evidence's gradient is analytic (MacKay 1992: ``∂(−log E)/∂log s_k
= ½(1 − Σ_kk/s_k − μ_k²/s_k)``, ``∂(−log E)/∂log σ² = ½(N − γ − |r − Aμ|²/σ²)``).

Memory and time: the design is never held whole; ``G = AᵀA`` and ``Aᵀr`` are accumulated
over chunks of poses from per-joint blocks (:func:`_gram`), so memory is ``O(m²)`` plus one
chunk whatever the number of poses (m = joints · 2H: 576 for 6 joints at 48 harmonics,
2.7 MB); one pass at the largest H serves every candidate H (:func:`_grams`).  With fewer
equations than coefficients the design ``(N, m)`` is kept instead and the evidence is
maximised in its dual form (``N x N`` factorisations, :func:`_nll_and_grad_dual`), the same
function.

Model choice (:func:`cross_validate_residual`): k folds of the *training* poses; in each
fold the physical model is calibrated again on the other folds, and each candidate —
physics only, and the residual with each number of harmonics — predicts the held-out
fold.  The residual is fitted jointly with the physical parameters (their columns are
projected out of its design; in the folds their linear response is added to the
prediction, and the final model is calibrated again with the residual known).  Each
fold maximises its own evidence (fixing the hyperparameters found on all training poses
leaked the held-out fold into the choice, which then picked a residual for robots
without one).  The simplest candidate within three standard errors of the lowest mean
cross-validated error wins (:func:`_one_standard_error`).  Held-out data never enters.
"""

from __future__ import annotations

import contextlib
import dataclasses
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.linalg import cho_solve, cholesky, solve_triangular
from scipy.linalg.lapack import dtrtri
from scipy.optimize import minimize

from robocal.model.residual import FADE, JointAngleResidual, covered_intervals

__all__ = [
    "DEFAULT_HARMONICS",
    "CVCandidate",
    "CVTable",
    "Hyper",
    "calibrate_with_residual",
    "cross_validate_residual",
    "fit_joint_fourier",
]

Array = NDArray[np.float64]

#: the numbers of harmonics cross-validation chooses from (per revolution)
DEFAULT_HARMONICS: tuple[int, ...] = (8, 24, 48)
_CHUNK = 2048  # poses per chunk of the design matrix
MAX_AMPLITUDE = 2e-3  # rad, the largest prior RMS of a joint's angle error
SELECTION_SE = 3.0  # a more complex candidate must beat the simpler ones by this many standard errors


@dataclass(frozen=True)
class Hyper:
    """Prior amplitude per joint (rad), spectral length scale ℓ (rad) and noise σ (m)."""

    amplitudes: tuple[float, ...]
    length_scale: float
    noise: float


def _gram(
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
    with _one_blas_thread():
        return _gram_blocks(q, r, P, template, J)


def _one_blas_thread():
    """A context in which BLAS/LAPACK run on one thread (threadpoolctl): the evidence's
    factorisations of ``(m, m)`` matrices ran 4x slower with OpenBLAS's threads on a shared
    2-core machine; without threadpoolctl, nothing changes."""
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:  # pragma: no cover - threadpoolctl comes with scikit-learn
        return contextlib.nullcontext()
    return threadpool_limits(1, user_api="blas")


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


def _grams(
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
        (G, b, rr, N), A, y = _gram(q, r, P, big, J), None, None
    out = {}
    for H in harmonics:
        keep = (np.arange(len(template.joints))[:, None] * 2 * top + np.arange(2 * H)).reshape(-1)
        out[H] = _Normal(G[np.ix_(keep, keep)], b[keep], rr, N, None if A is None else A[:, keep], y)
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
    k, h2 = len(template.joints), 2 * template.harmonics
    m = template.size
    G, b, rr = np.zeros((m, m)), np.zeros(m), 0.0
    Q = None if J is None else np.linalg.qr(J.reshape(-1, J.shape[-1]))[0]
    p = 0 if Q is None else Q.shape[1]
    QA, Qr = np.zeros((p, m)), (np.zeros(0) if Q is None else Q.T @ r.reshape(-1))
    index = list(template.joint_index)
    for s in range(0, len(q), _CHUNK):
        B = template.basis(q[s : s + _CHUNK])  # (c, k, 2H)
        cols = np.ascontiguousarray(P[s : s + _CHUNK, :, index, 2])  # (c, 3, k)
        y = r[s : s + _CHUNK]  # (c, 3)
        W = np.einsum("crj,crl->cjl", cols, cols)  # (c, k, k): P_j · P_l per pose
        for j in range(k):  # block row j, blocks j' >= j (G is symmetric)
            right = (W[:, j, j:, None] * B[:, j:, :]).reshape(len(B), -1)  # (c, (k - j) 2H)
            G[j * h2 : (j + 1) * h2, j * h2 :] += B[:, j, :].T @ right
        b += np.einsum("cj,cjh->jh", np.einsum("crj,cr->cj", cols, y), B).reshape(-1)
        rr += float(np.sum(y * y))
        if Q is not None:
            Qs = Q[3 * s : 3 * (s + len(y))].reshape(len(y), 3, p)
            V = np.einsum("cri,crj->jic", Qs, cols)  # (k, p, c)
            for j in range(k):
                QA[:, j * h2 : (j + 1) * h2] += V[j] @ B[:, j, :]
    G = np.triu(G) + np.triu(G, 1).T
    N = r.size
    if Q is not None:
        G -= QA.T @ QA
        b -= QA.T @ Qr
        rr -= float(Qr @ Qr)
        N -= p
    return G, b, rr, N


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


def _apply(learned: JointAngleResidual, q: Array, P: Array) -> Array:
    """``A(q) c`` ``(n, r)``: the residual's position (or pose) correction, the angle errors
    times their perturbation columns (the design itself is not formed)."""
    cols = P[:, :, list(learned.joint_index), 2]  # (n, r, k)
    return np.einsum("nrk,nk->nr", cols, learned.angle_errors(q))


def _prior(theta: Array, groups: Array, freq: Array) -> Array:
    """log prior variance per coefficient from ``theta = [log a_j..., log ℓ, log σ]``."""
    k = len(theta) - 2
    return 2.0 * theta[:k][groups] + _spectrum(theta[k], freq)[0]


def _posterior(G: Array, b: Array, log_s: Array, noise2: float) -> tuple[Array, Array, Array]:
    """Whitened Cholesky factor ``L``, mean ``μ`` and ``v = μ / s^½`` of the coefficients."""
    d = np.exp(0.5 * log_s)
    K = (d[:, None] * G * d[None, :]) / noise2
    K[np.diag_indices_from(K)] += 1.0
    L = cholesky(K, lower=True, check_finite=False)
    v = cho_solve((L, True), d * b / noise2, check_finite=False)
    return L, d * v, v


def _nll_and_grad(theta: Array, G: Array, b: Array, rr: float, N: int, groups: Array, freq: Array):
    k = len(theta) - 2
    log_s = _prior(theta, groups, freq)
    noise2 = float(np.exp(2.0 * theta[-1]))
    L, mu, v = _posterior(G, b, log_s, noise2)
    z = solve_triangular(L, np.exp(0.5 * log_s) * b / noise2, lower=True, check_finite=False)
    nll = 0.5 * (rr / noise2 - z @ z + 2.0 * np.log(np.diag(L)).sum() + N * np.log(noise2))
    Linv = _inverse_lower(L)
    kinv_diag = np.einsum("ij,ij->j", Linv, Linv)  # diag of K⁻¹ = Σ_kk / s_k
    g_s = 0.5 * (1.0 - kinv_diag - v**2)  # ∂nll/∂log s_k
    gamma = float(np.sum(1.0 - kinv_diag))
    misfit = rr - 2.0 * mu @ b + mu @ G @ mu
    grad = np.empty_like(theta)
    grad[:k] = 2.0 * np.bincount(groups, weights=g_s, minlength=k)
    grad[k] = float(np.sum(g_s * _spectrum(theta[k], freq)[1]))
    grad[-1] = 2.0 * 0.5 * (N - gamma - misfit / noise2)  # ∂/∂log σ = 2 ∂/∂log σ²
    return float(nll), grad


def _nll_and_grad_dual(theta: Array, A: Array, r: Array, rr: float, N: int, groups: Array, freq: Array):
    """:func:`_nll_and_grad` from the design ``A`` ``(N, m)`` and residuals ``r`` ``(N,)``
    instead of ``G`` and ``b``, through the ``(N, N)`` matrix ``M = I + Ã Ãᵀ/σ²``
    (``Ã = A S^½``): ``det K = det M``, ``K⁻¹ = I − Ãᵀ M⁻¹ Ã/σ²`` (Woodbury).  The same
    function; cheaper when ``N`` is well below ``m`` (60 poses and 48 harmonics: 155 x 155
    instead of 576 x 576)."""
    k = len(theta) - 2
    log_s = _prior(theta, groups, freq)
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


def _inverse_lower(L: Array) -> Array:
    """``L⁻¹`` of a lower-triangular Cholesky factor (LAPACK's triangular inverse: a third of
    the work of solving against the identity)."""
    Linv, info = dtrtri(L, lower=1)
    if info != 0:
        raise np.linalg.LinAlgError(f"triangular inverse failed (info {info})")
    return Linv


def _layout(template: JointAngleResidual) -> tuple[Array, Array]:
    H = template.harmonics
    groups = np.repeat(np.arange(len(template.joints)), 2 * H)
    freq = np.tile(np.repeat(np.arange(1, H + 1), 2), len(template.joints)).astype(float)
    return groups, freq


def _template(
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
    template = _template(joint_names, joint_index, harmonics, q)
    if gram is None:
        gram = _grams(q, residuals, P, template, [harmonics], J)[harmonics]
    with _one_blas_thread():
        model, hyper = _fit(template, gram, hyper, start)
    rms = np.sqrt(np.mean(model.angle_errors(q) ** 2, axis=0))
    return dataclasses.replace(model, angle_rms=tuple(float(v) for v in rms)), hyper


def _fit(
    template: JointAngleResidual, normal: _Normal, hyper: Hyper | None, start: Hyper | None
) -> tuple[JointAngleResidual, Hyper]:
    """:func:`fit_joint_fourier` from its normal equations (without ``angle_rms``); the
    evidence in its dual form when that is cheaper."""
    G, b, rr, N = normal.G, normal.b, normal.rr, normal.N
    joint_names, joint_index, harmonics = template.joints, template.joint_index, template.harmonics
    groups, freq = _layout(template)
    k = len(joint_names)
    if hyper is None:
        noise0 = max(float(np.sqrt(rr / N)), 1e-7)
        theta0 = np.r_[np.full(k, np.log(2e-4)), np.log(0.02), np.log(noise0)]
        if start is not None:
            theta0 = np.r_[np.log(start.amplitudes), np.log(start.length_scale), np.log(start.noise)]
        # a joint's angle error is physically small: transmission errors of robot gears are
        # arcminutes (0.3 mrad); 2 mrad bounds the prior well above that and keeps the evidence
        # out of the degenerate optimum where huge coefficients cancel (seen at H = 12)
        bounds = [(np.log(1e-9), np.log(MAX_AMPLITUDE))] * k + [
            (np.log(1e-4), np.log(2.0)),
            (np.log(1e-7), np.log(1e-2)),
        ]
        fun, data = _nll_and_grad, (G, b)
        if normal.A is not None and _dual_is_cheaper(*normal.A.shape):
            fun, data = _nll_and_grad_dual, (normal.A, normal.r)
        opt = minimize(
            fun, theta0, args=(*data, rr, N, groups, freq), jac=True, method="L-BFGS-B",
            bounds=bounds, options={"maxiter": 200, "ftol": 1e-8},
        )  # fmt: skip
        theta = opt.x
        hyper = Hyper(
            tuple(float(np.exp(t)) for t in theta[:k]), float(np.exp(theta[k])), float(np.exp(theta[-1]))
        )
    theta = np.r_[np.log(hyper.amplitudes), np.log(hyper.length_scale), np.log(hyper.noise)]
    log_s = _prior(theta, groups, freq)
    L, mu, _ = _posterior(G, b, log_s, hyper.noise**2)
    d = np.exp(0.5 * log_s)
    Linv = _inverse_lower(L)
    cov = (d[:, None] * (Linv.T @ Linv)) * d[None, :]
    model = JointAngleResidual(
        tuple(joint_names), tuple(joint_index), harmonics, mu, 0.5 * (cov + cov.T), hyper.noise,
        hyper.amplitudes, hyper.length_scale, template.coverage,
    )  # fmt: skip
    return model, hyper


# ---------------------------------------------------------------------- model choice
@dataclass(frozen=True)
class CVCandidate:
    """One row of the cross-validation table: mean and RMS position error (m) over the
    held-out folds of the training poses, and the time of one fit on all of them (s)."""

    name: str
    physics: str
    harmonics: int | None
    cv_mean: float
    cv_rms: float
    fit_seconds: float

    def to_dict(self) -> dict[str, object]:
        return {
            "name": self.name,
            "physics": self.physics,
            "harmonics": self.harmonics,
            "cv_mean_mm": self.cv_mean * 1e3,
            "cv_rms_mm": self.cv_rms * 1e3,
            "fit_seconds": self.fit_seconds,
        }


@dataclass(frozen=True)
class CVTable:
    """The candidates compared and the one chosen (the simplest within ``SELECTION_SE``
    standard errors of the lowest CV mean error)."""

    folds: int
    candidates: tuple[CVCandidate, ...]
    chosen: str

    def to_dict(self) -> dict[str, object]:
        return {
            "folds": self.folds,
            "chosen": self.chosen,
            "candidates": [c.to_dict() for c in self.candidates],
        }

    @classmethod
    def from_dict(cls, data: dict) -> CVTable:
        rows = tuple(
            CVCandidate(
                c["name"],
                c["physics"],
                c["harmonics"],
                c["cv_mean_mm"] / 1e3,
                c["cv_rms_mm"] / 1e3,
                c["fit_seconds"],
            )
            for c in data["candidates"]
        )
        return cls(int(data["folds"]), rows, str(data["chosen"]))

    def lines(self) -> list[str]:
        """The table as text lines (mm, ms)."""
        out = [
            f"model choice by {self.folds}-fold cross-validation on the calibration poses:",
            f"  {'candidate':<42} {'mean':>6} {'RMS':>6} {'fit':>6}   (CV error mm, fit ms)",
        ]
        for c in self.candidates:
            mark = "  <- chosen" if c.name == self.chosen else ""
            cv = f"{c.cv_mean * 1e3:6.4f} {c.cv_rms * 1e3:6.4f}"
            out.append(f"  {c.name:<42} {cv} {c.fit_seconds * 1e3:6.0f}{mark}")
        return out


@dataclass(frozen=True)
class PhysicalFit:
    """A physical calibration on some training poses, as the residual stage needs it."""

    result: Any  # the CalibrationResult
    residuals: Array  # (n_train, 3) measured − predicted, device frame (m)
    P: Array  # (n_train, 3, dof, 3) perturbation Jacobian
    J: Array  # (n_train, 3, p) derivatives wrt the estimated physical parameters

    def predict(self, q: Array) -> tuple[Array, Array, Array]:
        """Positions ``(n, 3)``, perturbation Jacobian and parameter columns at ``q``."""
        r = self.result
        P = r.measurement_chain.perturbation_jacobian(q, "position", r.joint_perturbations(q))
        return r.predict(q)[:, :3, 3], P, r.position_columns(q)


def cross_validate_residual(
    q: Array,
    position: Array,
    physics: dict[str, Callable[[Array], PhysicalFit]],
    joint_names: Sequence[str],
    joint_index: Sequence[int],
    harmonics: Sequence[int] = DEFAULT_HARMONICS,
    folds: int = 5,
    seed: int = 0,
    include_none: bool = True,
) -> tuple[CVTable, dict[str, Hyper]]:
    """k-fold CV over physical variants × (no residual, Fourier residual with H harmonics).

    ``physics[name](train_indices)`` calibrates that physical variant on those training
    poses.  Returns the table and the hyperparameters found for each residual candidate on
    all poses.
    """
    n = len(q)
    order = np.random.default_rng(seed).permutation(n)
    parts = np.array_split(order, folds)
    everything = np.arange(n)
    rows: list[CVCandidate] = []
    hypers: dict[str, Hyper] = {}
    per_pose: dict[str, Array] = {}
    for pname, physics_fit in physics.items():
        full = physics_fit(everything)
        specs: list[tuple[str, int | None]] = [(pname, None)] if include_none else []
        fit_time: dict[str, float] = {pname: full.result.seconds}
        t1 = time.perf_counter()
        grams = _grams(
            q, full.residuals, full.P, _template(joint_names, joint_index, 1, q), harmonics, full.J
        )
        gram_time = (time.perf_counter() - t1) / len(harmonics)  # shared: each candidate's share
        for H in harmonics:
            t1 = time.perf_counter() - gram_time
            _, hyper = fit_joint_fourier(
                q, full.residuals, full.P, joint_names, joint_index, H, J=full.J, gram=grams[H]
            )
            name = f"{pname} + angle errors H={H}"
            hypers[name] = hyper
            fit_time[name] = full.result.seconds + time.perf_counter() - t1
            specs.append((name, H))
        errors = {name: np.empty(n) for name, _ in specs}
        for held in parts:
            train = np.setdiff1d(everything, held)
            try:
                fold = physics_fit(train)
            except (ValueError, np.linalg.LinAlgError):  # this variant fails on a fold: not a candidate
                for name, _ in specs:
                    errors[name][:] = np.inf
                break
            p_held, P_held, J_held = fold.predict(q[held])
            base = position[held] - p_held
            # least squares of the physical parameters over the fold's training poses
            J2 = fold.J.reshape(-1, fold.J.shape[-1])
            fold_grams = _grams(
                q[train], fold.residuals, fold.P, _template(joint_names, joint_index, 1, q[train]),
                harmonics, fold.J,
            )  # fmt: skip
            for name, H in specs:
                if H is None:
                    e = base
                else:
                    learned, _ = fit_joint_fourier(
                        q[train],
                        fold.residuals,
                        fold.P,
                        joint_names,
                        joint_index,
                        H,
                        J=fold.J,
                        start=hypers[name],
                        gram=fold_grams[H],
                    )
                    Ac = _apply(learned, q[train], fold.P)
                    dg = -np.linalg.lstsq(J2, Ac.reshape(-1), rcond=None)[0]
                    moved = J_held @ dg + _apply(learned, q[held], P_held)
                    e = base - moved
                errors[name][held] = np.linalg.norm(e, axis=1)
        for name, H in specs:
            e = errors[name]
            if not np.all(np.isfinite(e)):
                continue
            per_pose[name] = e
            rows.append(
                CVCandidate(name, pname, H, float(e.mean()), float(np.sqrt(np.mean(e**2))), fit_time[name])
            )
    if not rows:
        raise ValueError("no candidate model could be calibrated on every cross-validation fold")
    return CVTable(folds, tuple(rows), _one_standard_error(rows, per_pose, list(physics)).name), hypers


def _one_standard_error(
    rows: list[CVCandidate], per_pose: dict[str, Array], physics: list[str]
) -> CVCandidate:
    """The simplest candidate (fewer harmonics, then the physical variants in the order
    given) whose CV error is within ``SELECTION_SE`` standard errors of the lowest (Breiman's
    one-standard-error rule, made stricter), the standard error of the mean of the per-pose
    differences to the lowest: with few poses the CV errors are noisy, and noise over
    several candidates is no reason for more parameters.  A virtual UR10 without
    unmodelled errors, 60 poses, 5 twins (``tests/test_residual.py``): the plain minimum
    picked a residual in 3 twins (held-out 1.33x the Cramér–Rao bound), one standard error
    in 1 (1.18x), two in 0 or 1 depending on the optimiser's tolerance, three in none; on
    the real UR10 the residual wins by 15, 30 and 54 standard errors at 100, 300 and 1,000
    poses."""
    lowest = min(rows, key=lambda c: c.cv_mean)
    for c in sorted(rows, key=lambda c: (c.harmonics or 0, physics.index(c.physics))):
        d = per_pose[c.name] - per_pose[lowest.name]
        if d.mean() <= SELECTION_SE * d.std(ddof=1) / np.sqrt(len(d)):
            return c
    return lowest  # pragma: no cover - the lowest itself always qualifies


# ---------------------------------------------------------------------- the stage
MIN_CV_POSES = 20  # fewer poses than this: too few folds of useful size, physics only
MAX_HARMONICS = 128  # per revolution: m = joints x 2H coefficients, an (m, m) matrix to factor
_COMPLIANCE_VARIANT = "geometry + compliance"


def _physics_name(options: dict[str, Any]) -> str:
    if options.get("compliance"):
        return _COMPLIANCE_VARIANT
    effects, level = options.get("effects"), options.get("level")
    if effects not in (None, "none") or str(level) in ("3", "non-geometric"):
        return f"geometry + joint effects ({effects or 'identify'})"
    return "geometry"


def calibrate_with_residual(
    calibrate_physics: Callable[..., Any],
    model: Any,
    data: Any,
    method: str,
    options: dict[str, Any],
    kind: str = "auto",
    harmonics: int | Sequence[int] | None = None,
    folds: int = 5,
) -> Any:
    """The physical calibration plus the learned residual chosen by cross-validation on
    ``data`` (see the module docstring); returns a
    :class:`~robocal.identify.calibrate.CalibrationResult` whose ``model.residual`` is the
    residual (None when CV chose the physics alone) and whose ``diagnostics.cv`` is the table."""
    t0 = time.perf_counter()
    grid = DEFAULT_HARMONICS if harmonics is None else tuple(np.atleast_1d(harmonics).astype(int).tolist())
    if not grid or min(grid) < 1 or max(grid) > MAX_HARMONICS:
        raise ValueError(f"residual_harmonics must be integers from 1 to {MAX_HARMONICS}, got {harmonics!r}")
    if not 2 <= folds <= 20:
        raise ValueError(f"cv_folds must lie between 2 and 20, got {folds}")
    base = calibrate_physics(model, data, method, **options)
    # revolute joints only: the angle errors of a joint as a function of its own angle
    revolute = [s.is_rotation for s in model.steps if s.joint is not None]
    joints = [j for j, rot in enumerate(revolute) if rot]
    if data.n < max(MIN_CV_POSES, 2 * folds) or not joints:
        return base.with_warnings(
            f"{data.n} poses are too few to choose a learned residual by {folds}-fold cross-validation "
            f"(at least {max(MIN_CV_POSES, 2 * folds)}): the physical model alone",
            code="residual",
        )
    names = [model.joint_names[j] for j in joints]
    variants = {_physics_name(options): options}
    asked = any(options.get(k) not in (None, False, "none") for k in ("compliance", "effects", "level"))
    if kind == "auto" and model.bodies and not asked:
        variants[_COMPLIANCE_VARIANT] = {**options, "compliance": True}

    def physics(name: str) -> Callable[[Array], PhysicalFit]:
        def fit(train: Array) -> PhysicalFit:
            everything = len(train) == data.n
            if everything and name == _physics_name(options):
                result = base
            else:
                result = calibrate_physics(
                    model, data if everything else data.subset(train), method, **variants[name]
                )
            q = data.q[train]
            p, P, J = PhysicalFit(result, np.empty(0), np.empty(0), np.empty(0)).predict(q)
            return PhysicalFit(result, data.position[train] - p, P, J)

        return fit

    usable: dict[str, Callable[[Array], PhysicalFit]] = {}
    full: dict[str, PhysicalFit] = {}
    for name in variants:
        try:  # a variant that cannot be calibrated on these poses is left out of the choice
            full[name] = physics(name)(np.arange(data.n))
        except (ValueError, np.linalg.LinAlgError):
            continue
        usable[name] = _memo(physics(name), full[name], data.n)
    try:
        table, hypers = cross_validate_residual(
            data.q, data.position, usable, names, joints, grid, folds, include_none=kind == "auto"
        )
    except ValueError as err:
        return base.with_warnings(f"{err}: the physical model alone", code="residual")
    chosen = next(c for c in table.candidates if c.name == table.chosen)
    fit = full[chosen.physics]
    result = fit.result
    if chosen.harmonics is not None:
        learned, _ = fit_joint_fourier(
            data.q, fit.residuals, fit.P, names, joints, chosen.harmonics, hypers[chosen.name], J=fit.J
        )
        # the physical parameters refitted with the learned angle errors known (the joint fit's
        # exact version of what the CV did linearly)
        try:
            result = _refit_with_residual(
                calibrate_physics, dataclasses.replace(model, residual=learned), data, method,
                variants[chosen.physics],
            )  # fmt: skip
        except (ValueError, np.linalg.LinAlgError) as err:
            return fit.result.with_warnings(
                f"the physical model with the learned residual could not be calibrated ({err}): the "
                "physical model alone",
                code="residual",
            ).with_diagnostics(cv=table.to_dict())
        e = data.position - result.predict(data.q)[:, :3, 3]
        rms_mm = float(np.sqrt(np.mean(np.sum(e**2, axis=1)))) * 1e3
        result = result.with_diagnostics(residual_rms_after_mm=rms_mm)
    return result.with_diagnostics(cv=table.to_dict()).replace(seconds=time.perf_counter() - t0)


def _refit_with_residual(
    calibrate_physics: Callable[..., Any], model: Any, data: Any, method: str, options: dict[str, Any]
) -> Any:
    """The physical calibration of ``model`` (its learned residual known) with the joint
    uncertainty of both (:func:`_joint_uncertainty`).  A joint effect the learned angle
    errors explain as well (a wrist's compliance under its own weight is a smooth function
    of the wrist's angle: the real UR10's wrist compliances came out at -136 ± 400
    µrad/N·m) is below zero or within 3σ of it once both are fitted: it is held at its
    start value and the physics refitted (:func:`~robocal.identify.calibrate.effects_to_hold`)."""
    from robocal.identify.effects import effects_to_hold

    held = dict(options.get("hold_effects") or {})
    for _ in range(8):  # one refit settles it but for the problem's nonlinearity
        result = _joint_uncertainty(
            calibrate_physics(model, data, method, **{**options, "hold_effects": held}), data.q
        )
        effects = set(result.effect_names)
        start = {n: float(v) for n, v in zip(result.names, result.nominal, strict=True) if n in effects}
        learned = "the learned joint angle errors"
        _, verdicts = effects_to_hold(
            result.names, result.estimates, result.covariance, start, confounder=learned
        )
        if not verdicts:
            break
        held.update({v.name: v for v in verdicts})
    return result


def _memo(fit: Callable[[Array], PhysicalFit], whole: PhysicalFit, n: int) -> Callable[[Array], PhysicalFit]:
    """``fit`` that returns ``whole`` for all ``n`` poses instead of calibrating again."""
    return lambda train: whole if len(train) == n else fit(train)


def _joint_uncertainty(result: Any, q: Array) -> Any:
    """``result`` with the covariance of its parameters and of the residual's coefficients
    from their *joint* fit (Fisher matrix of both, the residual's prior included, noise σ
    from the evidence): directions of the residual that the physical parameters can absorb
    are uncertain in both but cancel in predictions, which the cross-covariance carries.
    In whitened coordinates ``c = S^½ v`` so that the matrix inverted is well conditioned."""
    learned: JointAngleResidual = result.model.residual
    chain = result.measurement_chain
    groups, freq = _layout(learned)
    theta = np.r_[
        np.log(learned.amplitudes), np.log(learned.length_scale), np.log(max(learned.noise_std, 1e-12))
    ]
    d = np.exp(0.5 * _prior(theta, groups, freq))
    p, m = len(result.names), learned.size
    F = np.zeros((p + m, p + m))
    for s in range(0, len(q), _CHUNK):  # the Fisher matrix over chunks of poses: O((p + m)²) memory
        qs = q[s : s + _CHUNK]
        P = chain.perturbation_jacobian(qs, "position", result.joint_perturbations(qs))
        B = np.hstack([result.position_columns(qs).reshape(-1, p), learned.design(qs, P).reshape(-1, m) * d])
        F += B.T @ B
    F[p:, p:] += learned.noise_std**2 * np.eye(m)
    scale = np.sqrt(np.maximum(np.diag(F), 1e-300))  # columns scaled: J's units differ widely
    try:
        cov = np.linalg.inv(F / np.outer(scale, scale)) / np.outer(scale, scale) * learned.noise_std**2
    except np.linalg.LinAlgError:
        return result
    cov = 0.5 * (cov + cov.T)
    cov_g = cov[:p, :p]
    cov_c = d[:, None] * cov[p:, p:] * d[None, :]
    std = np.sqrt(np.maximum(np.diag(cov_g), 0.0))
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = cov_g / np.outer(std, std)
    joint = dataclasses.replace(learned, covariance=cov_c)
    return dataclasses.replace(
        result,
        model=dataclasses.replace(result.model, residual=joint),
        covariance=cov_g,
        std=std,
        correlation=corr,
        residual_cross_covariance=cov[:p, p:] * d[None, :],
    )
