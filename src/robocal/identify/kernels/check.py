"""Compiled kernels (numba) of the checks around a calibration: the ranges of the data
before the fit (:func:`data_ranges`, for :func:`robocal.identify.guards.check_data`) and
the sizes of the residuals after it (:func:`position_errors`, for the outlier and
fit-to-noise diagnostics of :mod:`robocal.identify.diagnose`).

One pass over the arrays instead of about ten numpy reductions, each of which costs more
in fixed overhead than its arithmetic on a hundred poses: a few per cent of a whole
calibration.  ``tests/test_check_kernels.py`` holds them to the numpy expressions they
replace.  Compiled with ``cache=True`` (see :mod:`robocal.model.kernels`); imported on
first use only (it imports numba).
"""

from __future__ import annotations

import math

import numba
import numpy as np

from robocal.identify.kernels.stage import median

__all__ = ["data_ranges", "position_errors"]

_jit = numba.njit(cache=True, nogil=True)


@_jit
def data_ranges(q, y):
    """Joint values ``q`` ``(n, dof)`` and measured positions ``y`` ``(n, 3)`` (m), n ≥ 1:
    whether all of ``q`` and all of ``y`` are finite, each joint's range
    ``max − min`` ``(dof,)``, and the largest range of the positions' coordinates (m).
    The ranges mean nothing when the values are not all finite."""
    n, dof = q.shape
    finite_q = finite_y = True
    q_low, q_high = q[0].copy(), q[0].copy()
    y_low, y_high = y[0].copy(), y[0].copy()
    for i in range(n):
        for j in range(dof):
            v = q[i, j]
            finite_q = finite_q and math.isfinite(v)
            q_low[j] = min(q_low[j], v)
            q_high[j] = max(q_high[j], v)
        for c in range(3):
            v = y[i, c]
            finite_y = finite_y and math.isfinite(v)
            y_low[c] = min(y_low[c], v)
            y_high[c] = max(y_high[c], v)
    spread = 0.0
    for c in range(3):
        spread = max(spread, y_high[c] - y_low[c])
    return finite_q, finite_y, q_high - q_low, spread


@_jit
def position_errors(r, sigma):
    """Residuals ``r`` ``(n, rows)`` (m; position rows first, n ≥ 1) and their standard
    deviations ``sigma`` ``(n, 3)`` (m; ``(0, 3)`` when not stated): each pose's 3D position
    error ``(n,)``, their median, ``Σr²``, ``Σ(r/σ)²`` and ``Σσ²`` over the position rows
    (the last two 0 without ``sigma``; σ below 1e-300 counts as 1e-300)."""
    n = r.shape[0]
    stated = sigma.shape[0] > 0
    errors = np.empty(n)
    squares = chi2 = noise = 0.0
    for i in range(n):
        e = 0.0
        for c in range(3):
            v = r[i, c]
            e += v * v
            if stated:
                s = sigma[i, c]
                z = v / max(s, 1e-300)
                chi2 += z * z
                noise += s * s
        errors[i] = math.sqrt(e)
        squares += e
    return errors, median(errors), squares, chi2, noise
