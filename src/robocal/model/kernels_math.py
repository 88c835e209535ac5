"""Scalar functions shared by the compiled kernels (numba): sine and cosine together."""

from __future__ import annotations

import math

import numba
import numpy as np

_jit = numba.njit(cache=True, nogil=True)


# sin and cos on |r| <= π/4 after a two-part Cody-Waite reduction by π/2: fdlibm's minimax
# coefficients (k_sin.c, k_cos.c, e_rem_pio2.c; Sun Microsystems, freely distributable).
# libm's scalar sin and cos cost 25-30 ns a pair here; this branch-free form is vectorised
# over the poses by LLVM (AVX2/AVX-512) and agrees with numpy to a few 1e-16 for the joint
# angles of a robot (|x| < 1e5 rad).
_S = (
    -1.66666666666666324348e-01,
    8.33333333332248946124e-03,
    -1.98412698298579493134e-04,
    2.75573137070700676789e-06,
    -2.50507602534068634195e-08,
    1.58969099521155010221e-10,
)
_C = (
    4.16666666666666019037e-02,
    -1.38888888887411972484e-03,
    2.48015872894767294178e-05,
    -2.75573143513906633035e-07,
    2.08757232129817482790e-09,
    -1.13596475577881948265e-11,
)
_PIO2_1, _PIO2_1T, _INVPIO2 = (
    1.57079632673412561417e00,
    6.07710050650619224932e-11,
    6.36619772367581382433e-01,
)


@_jit
def sincos(x):
    n = math.floor(x * _INVPIO2 + 0.5)
    r = (x - n * _PIO2_1) - n * _PIO2_1T
    z = r * r
    s = r + r * z * (_S[0] + z * (_S[1] + z * (_S[2] + z * (_S[3] + z * (_S[4] + z * _S[5])))))
    c = 1.0 - 0.5 * z + z * z * (_C[0] + z * (_C[1] + z * (_C[2] + z * (_C[3] + z * (_C[4] + z * _C[5])))))
    k = np.int64(n) & 3
    swap = (k & 1) == 1
    sin = c if swap else s
    cos = s if swap else c
    sign_sin = 1.0 - (k & 2)
    sign_cos = 1.0 - ((k + 1) & 2)
    return sin * sign_sin, cos * sign_cos
