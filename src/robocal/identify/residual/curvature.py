"""The curvature of the learned residual's evidence in its hyperparameters, for the CV folds.

Each cross-validation fold maximises its own evidence from the hyperparameters found on all
poses (:func:`~robocal.identify.residual.fit.evidence`).  A quasi-Newton search's first step is
the raw gradient, in log units whose curvatures differ by three orders of magnitude (series A, 300
poses, 48 harmonics: ~45 per log-unit² along a joint's amplitude, ~1,300 along the noise),
so it overshoots and its line search spends most of a fold's 4-6 evaluations.  In the
coordinates ``θ_i √h_i`` (``h`` the diagonal of the Hessian of ``−log E`` at the optimum on
all poses, :func:`evidence_curvature`) the gradient step is close to Newton's: series A's
folds took 81 evaluations instead of 146 (300 poses; 60 instead of 129 at 10,000) and ended
8x closer to their own optimum (mean gap in ``−log E`` 0.055 instead of 0.45; 0.27 instead
of 1.45).  The optimum is the same point whatever the coordinates.

The Hessian of ``−log E`` in the coefficients' log prior variances ``u_i = log s_i``, with
``C = σ²I + A S Aᵀ``, ``Q = S^½ Aᵀ C⁻¹ A S^½ = I − K⁻¹`` and ``v = μ / s^½``:
``∂²/∂u_i∂u_j = ½(δ_ij (Q_ii − v_i²) − Q_ij² + 2 v_i v_j Q_ij)``; along ``η = log σ²``:
``½(|r − Aμ|²/σ² − 2 vᵀK⁻¹v + tr K⁻¹ − ‖K⁻¹‖²_F)`` (the ``N − m`` terms of the equations
outside ``A``'s span cancel).  The chain rule takes them to ``θ = [log a_j, log ℓ, log σ]``
(``u`` is linear in ``log a_j`` and ``log σ``; the spectrum's second derivative in ``log ℓ``
adds ``Σ g_i ∂²u_i/∂(log ℓ)²``).  Checked against finite differences of the analytic
gradient (``tests/test_residual_warm_start.py``).
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.linalg import cho_solve, cholesky
from scipy.linalg.lapack import dpotri

__all__ = ["evidence_curvature", "with_curvature"]

Array = NDArray[np.float64]
Index = NDArray[np.integer[Any]]


def evidence_curvature(theta: Array, G: Array, b: Array, rr: float, groups: Index, freq: Array) -> Array:
    """``(k + 2,)`` the diagonal of the Hessian of ``−log E`` in ``theta = [log a_j..., log ℓ,
    log σ]`` (per log-unit²) for the normal equations ``G`` ``(m, m)``, ``b`` ``(m,)``, ``rr``
    (m²) of the coefficients laid out by joint ``groups`` ``(m,)`` and frequency ``freq``
    ``(m,)`` (:func:`~robocal.identify.residual.fit.layout`)."""
    k = len(theta) - 2
    du, d2u = _spectrum_derivatives(theta[k], freq)
    log_s = 2.0 * theta[:k][groups] + _log_spectrum(theta[k], freq)
    noise2 = float(np.exp(2.0 * theta[-1]))
    d = np.exp(0.5 * log_s)
    K = (d[:, None] * G * d[None, :]) / noise2
    K[np.diag_indices_from(K)] += 1.0
    L = cholesky(K, lower=True, check_finite=False)
    v = cho_solve((L, True), d * b / noise2, check_finite=False)  # μ / s^½
    # K⁻¹ from its Cholesky factor by LAPACK's dpotri (its lower triangle): the triangular
    # inverse and its product with itself as one triangular multiply, a third of the
    # general product Linv.T @ Linv's work (480 x 480: 3.8 -> 2.3 ms)
    lower, info = dpotri(L, lower=1)
    if info != 0:
        raise np.linalg.LinAlgError(f"inverse from the Cholesky factor failed (info {info})")
    Kinv = np.tril(lower) + np.tril(lower, -1).T
    Q = -Kinv
    Q[np.diag_indices_from(Q)] += 1.0
    q_diag = np.diag(Q)
    mu = d * v
    misfit = rr - 2.0 * mu @ b + mu @ G @ mu
    Q2 = Q**2  # once for every direction (an (m, m) array)

    def along(x: Array) -> float:  # xᵀ (∂²/∂u∂u) x
        xv = x * v
        return 0.5 * float(np.sum(x**2 * (q_diag - v**2)) - x @ Q2 @ x + 2.0 * xv @ Q @ xv)

    out = np.empty(k + 2)
    for j in range(k):
        out[j] = along(2.0 * (groups == j))  # ∂u/∂log a_j = 2 on the joint's coefficients
    out[k] = along(du) + float(0.5 * (q_diag - v**2) @ d2u)
    out[k + 1] = 4.0 * 0.5 * (misfit / noise2 - 2.0 * v @ Kinv @ v + np.trace(Kinv) - np.sum(Kinv**2))
    return out


def with_curvature(hyper: Any, normal: Any, groups: Index, freq: Array) -> Any:
    """``hyper`` (a :class:`~robocal.identify.residual.fit.Hyper`) carrying the evidence's
    curvature at it for ``normal``'s equations (:func:`evidence_curvature`)."""
    theta = np.r_[np.log(hyper.amplitudes), np.log(hyper.length_scale), np.log(hyper.noise)]
    h = evidence_curvature(theta, normal.G, normal.b, normal.rr, groups, freq)
    if not np.all(np.isfinite(h)):  # no scaling rather than a broken one
        return hyper
    return dataclasses.replace(hyper, curvature=tuple(float(x) for x in h))


def _log_spectrum(log_ell: float, freq: Array) -> Array:
    """log of the normalised spectral weights per coefficient (as the evidence's prior)."""
    u = -0.5 * (freq * np.exp(log_ell)) ** 2
    _, first = np.unique(freq, return_index=True)
    top = u[first].max()
    return u - (np.log(2.0 * np.exp(u[first] - top).sum()) + top)


def _spectrum_derivatives(log_ell: float, freq: Array) -> tuple[Array, Array]:
    """The first and second derivatives of :func:`_log_spectrum` in ``log ℓ``: with
    ``x = −(f ℓ)²`` and the weights' mean ``⟨x⟩`` and variance over the frequencies,
    ``x − ⟨x⟩`` and ``2x − 2⟨x⟩ − var x``."""
    x = -((freq * np.exp(log_ell)) ** 2)
    _, first = np.unique(freq, return_index=True)
    u = 0.5 * x[first]
    w = np.exp(u - u.max())
    w /= w.sum()
    mean = float(w @ x[first])
    var = float(w @ (x[first] - mean) ** 2)
    return x - mean, 2.0 * x - 2.0 * mean - var
