"""Fourier series of joint angles: the basis ``[cos h q, sin h q]``, its weighted Gram matrix
from sums of harmonics, and Clenshaw's summation of a series (the learned residual's arithmetic,
:mod:`robocal.model.residual`).  Units: angles in rad.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["fourier_basis", "fourier_gram", "fourier_series"]

Array = NDArray[np.float64]


def fourier_basis(angles: ArrayLike, harmonics: int) -> Array:
    """``[cos(h q), sin(h q)]`` for ``h = 1..harmonics``: ``(n, k, 2 H)`` for angles ``(n, k)``
    (rad); column ``2(h-1)`` is ``cos(h q)``, ``2(h-1)+1`` is ``sin(h q)``."""
    q = np.asarray(angles, dtype=float)
    cs = np.empty((harmonics + 1, 2, *q.shape))  # contiguous per harmonic, reordered at the end
    c1 = np.cos(q)
    cs[0, 0], cs[0, 1] = 1.0, 0.0
    cs[1, 0], cs[1, 1] = c1, np.sin(q)
    x2 = 2.0 * c1
    # Chebyshev's three-term recurrence, f((h+1) q) = 2 cos q f(h q) - f((h-1) q) for f = cos
    # and sin: 2 operations per value instead of a cos or sin (or the angle addition's 3);
    # its rounding error grows at most like h² 1e-16 (near q = 0, π): < 1e-12 for h ≤ 64
    for h in range(1, harmonics):
        np.multiply(x2, cs[h], out=cs[h + 1])
        cs[h + 1] -= cs[h - 1]
    return np.moveaxis(cs[1:], (0, 1), (-2, -1)).reshape(*q.shape, 2 * harmonics)


def fourier_gram(angles: Array, weights: Array, harmonics: int) -> Array:
    """``Bᵀ diag(w) B`` ``(2H, 2H)`` for the Fourier basis ``B`` ``(n, 2H)`` of ``angles``
    ``(n,)`` (rad; :func:`fourier_basis`'s column order) and weights ``w`` ``(n,)`` (or one
    such matrix per row of ``weights`` ``(s, n)``: ``(s, 2H, 2H)``), from the weighted sums
    ``Σ w cos(d q)``, ``Σ w sin(d q)`` for ``d = 0..2H`` (``cos a cos b = ½(cos(a − b) +
    cos(a + b))`` and its kin): ``8 H n`` operations instead of the product's ``8 H² n`` (the
    diagonal blocks of the residual's normal equations and of its mean position variance)."""
    F = fourier_basis(angles[:, None], 2 * harmonics)[:, 0, :]  # (n, 4H): cos d q, sin d q, d = 1..2H
    w = np.atleast_2d(weights)  # (s, n)
    sums = w @ F  # (s, 4H)
    C = np.concatenate([w.sum(axis=1)[:, None], sums[:, 0::2]], axis=1)  # (s, 2H + 1) Σ w cos(d q)
    S = np.concatenate([np.zeros((len(w), 1)), sums[:, 1::2]], axis=1)  # Σ w sin(d q)
    h = np.arange(1, harmonics + 1)
    diff, total = h[:, None] - h[None, :], h[:, None] + h[None, :]  # h - h', h + h'
    out = np.empty((len(w), 2 * harmonics, 2 * harmonics))
    out[:, 0::2, 0::2] = 0.5 * (C[:, np.abs(diff)] + C[:, total])  # Σ w cos(h q) cos(h' q)
    out[:, 1::2, 1::2] = 0.5 * (C[:, np.abs(diff)] - C[:, total])  # Σ w sin(h q) sin(h' q)
    cos_sin = 0.5 * (S[:, total] - np.sign(diff) * S[:, np.abs(diff)])  # Σ w cos(h q) sin(h' q)
    out[:, 0::2, 1::2] = cos_sin
    out[:, 1::2, 0::2] = np.swapaxes(cos_sin, 1, 2)
    return out[0] if np.ndim(weights) == 1 else out


def fourier_series(cos_q: Array, sin_q: Array, coefficients: Array) -> Array:
    """``Σ_h a_jh cos(h q_j) + b_jh sin(h q_j)`` ``(n, k)`` at angles given by their
    ``cos_q``, ``sin_q`` ``(n, k)``, for ``coefficients`` ``(k, H, 2)`` (``[j, h-1] = (a, b)``).

    Clenshaw's summation of the Chebyshev recurrence (``y_h = c_h + 2 cos q y_{h+1} -
    y_{h+2}`` for the cosine and the sine parts, then ``cos q y_1 - y_2 + sin q y'_1``):
    3 operations per harmonic and part, no ``cos(h q)`` formed; its error is a few
    ``H² 1e-16`` times the coefficients' sum at most."""
    x2 = 2.0 * cos_q
    u1, u2, v1, v2, tmp = (np.zeros_like(cos_q) for _ in range(5))
    for h in range(coefficients.shape[1] - 1, -1, -1):
        np.multiply(x2, u1, out=tmp)
        tmp -= u2
        tmp += coefficients[:, h, 0]
        u2, u1, tmp = u1, tmp, u2
        np.multiply(x2, v1, out=tmp)
        tmp -= v2
        tmp += coefficients[:, h, 1]
        v2, v1, tmp = v1, tmp, v2
    return cos_q * u1 - u2 + sin_q * v1
