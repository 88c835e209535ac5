"""ISO 9283 path characteristics: cornering (clause 8.5), path velocity (8.6) and weaving (11)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import optimize

Array = NDArray[np.float64]


# ------------------------------------------------------------------ 8.5 cornering
@dataclass(frozen=True)
class Cornering:
    """ISO 9283 §8.5 cornering deviations at one corner, per cycle.

    Attributes:
        CR: ``(n,)`` cornering round-off error (m): the smallest distance from the
            corner point to the attained path.
        CO: ``(n,)`` cornering overshoot (m): the largest deviation of the attained path
            beyond the second segment, outwards, after the corner (0 if none).
        corner: ``(3,)`` the corner point (m).
    """

    CR: Array
    CO: Array
    corner: Array


def _point_polyline_distance(point: Array, path: Array) -> tuple[float, int]:
    """Smallest distance from ``point`` to polyline ``path`` ``(k, 3)`` and the index of
    the sample that starts the nearest segment."""
    a, b = path[:-1], path[1:]
    ab = b - a
    L2 = np.einsum("ij,ij->i", ab, ab)
    u = np.clip(np.einsum("ij,ij->i", point - a, ab) / np.where(L2 > 0, L2, 1.0), 0.0, 1.0)
    d = np.linalg.norm(a + u[:, None] * ab - point, axis=1)
    i = int(np.argmin(d))
    return float(d[i]), i


def cornering(
    corner: ArrayLike, d_in: ArrayLike, d_out: ArrayLike, length_out: float, attained: Sequence[ArrayLike]
) -> Cornering:
    """ISO 9283 §8.5 CR and CO at one corner of a commanded path (the standard: the
    corners of a rectangular path, 3 cycles; the corner is taken without a stop).

    Read here:

    * ``CR_j`` = the smallest distance from the corner point to the attained polyline of
      cycle ``j`` (a path that passes through the corner has CR 0);
    * ``CO_j`` = the largest signed distance of an attained sample from the line of the
      second segment, positive outwards (the side the first segment came from:
      ``n = d_in − (d_in·d_out) d_out``, normalised), over the samples after the one
      nearest the corner whose projection on the second segment lies within
      ``[0, length_out]`` of the corner; 0 when the path stays inside.

    Args:
        corner: ``(3,)`` corner point (m).
        d_in, d_out: unit directions of the segments into and out of the corner.
        length_out: length of the second segment (m).
        attained: per cycle, ``(k_j, 3)`` attained positions around the corner (m).
    """
    c = np.asarray(corner, dtype=float)
    d1 = np.asarray(d_in, dtype=float) / np.linalg.norm(d_in)
    d2 = np.asarray(d_out, dtype=float) / np.linalg.norm(d_out)
    n_out = d1 - (d1 @ d2) * d2
    if np.linalg.norm(n_out) < 1e-9:
        raise ValueError("the segments into and out of a corner are parallel: no corner")
    n_out /= np.linalg.norm(n_out)
    CR, CO = [], []
    for path in attained:
        p = np.asarray(path, dtype=float)
        if p.ndim != 2 or p.shape[1] != 3 or len(p) < 2:
            raise ValueError(f"an attained path must be (k >= 2, 3) positions (m), got shape {p.shape}")
        d, i = _point_polyline_distance(c, p)
        after = p[i + 1 :]
        along = (after - c) @ d2
        within = (along >= 0) & (along <= length_out)
        dev = (after[within] - c) @ n_out
        CR.append(d)
        CO.append(max(0.0, float(dev.max())) if len(dev) else 0.0)
    return Cornering(np.array(CR), np.array(CO), c)


# ------------------------------------------------------------------ 8.6 path velocity
def path_speeds(t: ArrayLike, positions: ArrayLike, window: float) -> Array:
    """Speeds ``(k,)`` (m/s) along a measured path: ``|p(t + w/2) − p(t − w/2)| / w``
    with the positions linearly interpolated at ``t ± w/2`` (``w = window`` s), clipped
    at the ends of the record.  The standard does not say how the speed is obtained; a
    difference over a window rather than between neighbouring samples keeps the
    device's noise (σ√2/Δt for samples Δt apart) out of FV."""
    t = np.asarray(t, dtype=float)
    p = np.asarray(positions, dtype=float)
    if len(t) < 2 or p.shape != (len(t), 3):
        raise ValueError(f"path speeds need (k >= 2,) times and (k, 3) positions, got {t.shape}, {p.shape}")
    if not window > 0:
        raise ValueError(f"the speed window must be > 0 s, got {window!r}")
    lo = np.clip(t - window / 2, t[0], t[-1])
    hi = np.clip(t + window / 2, t[0], t[-1])
    p_lo = np.column_stack([np.interp(lo, t, p[:, k]) for k in range(3)])
    p_hi = np.column_stack([np.interp(hi, t, p[:, k]) for k in range(3)])
    dt = hi - lo
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(dt > 0, np.linalg.norm(p_hi - p_lo, axis=1) / np.where(dt > 0, dt, 1.0), np.nan)


@dataclass(frozen=True)
class PathVelocity:
    """ISO 9283 §8.6 path velocity characteristics.

    Attributes:
        AV: ``(v̄ − v_c) / v_c`` in per cent, ``v̄`` the mean over cycles of each cycle's
            mean speed ``v̄_j``.
        RV: ``3 S_v`` (m/s; the standard writes ±), ``S_v`` the standard deviation (n − 1)
            of the ``v̄_j``.
        RV_percent: ``RV / v_c`` in per cent.
        FV: the largest, over cycles, difference between the highest and lowest speed
            within a cycle (m/s).
        v_c: commanded speed (m/s).
        v_mean: ``(n,)`` the ``v̄_j`` (m/s).
    """

    AV: float
    RV: float
    RV_percent: float
    FV: float
    v_c: float
    v_mean: Array


def path_velocity(speeds: Sequence[ArrayLike], v_c: float) -> PathVelocity:
    """ISO 9283 §8.6 AV, RV and FV from the speeds measured along the constant-speed
    part of the path in each of ``n`` cycles (the standard: 10 cycles).

    Args:
        speeds: per cycle, ``(m_j,)`` speeds (m/s).
        v_c: the commanded speed (m/s), > 0.
    """
    if not v_c > 0:
        raise ValueError(f"the commanded speed must be > 0 m/s, got {v_c!r}")
    vs = [np.asarray(v, dtype=float).reshape(-1) for v in speeds]
    vs = [v[np.isfinite(v)] for v in vs]
    if not vs or any(len(v) == 0 for v in vs):
        raise ValueError("path velocity needs speeds in every cycle")
    v_mean = np.array([v.mean() for v in vs])
    RV = float(3.0 * v_mean.std(ddof=1)) if len(vs) >= 2 else float("nan")
    FV = float(max(v.max() - v.min() for v in vs))
    return PathVelocity(
        float(100.0 * (v_mean.mean() - v_c) / v_c), RV, 100.0 * RV / v_c, FV, float(v_c), v_mean
    )


# ------------------------------------------------------------------ 11 weaving
@dataclass(frozen=True)
class Weaving:
    """ISO 9283 §11 weaving deviations of one cycle.

    Attributes:
        WS: weaving stroke error ``(S_a − S_c) / S_c`` in per cent.
        WF: weaving frequency error ``(F_a − F_c) / F_c`` in per cent.
        stroke_c, stroke_a: commanded and attained stroke (peak to peak, m).
        frequency_c, frequency_a: commanded and attained weaving frequency (Hz).
    """

    WS: float
    WF: float
    stroke_c: float
    stroke_a: float
    frequency_c: float
    frequency_a: float


def _weave_frequency(t: Array, w: Array) -> tuple[float, float]:
    """Frequency (Hz) and phase of the dominant oscillation of ``w(t)``: the peak of the
    periodogram on a uniform resampling, refined by least squares on a sine with a
    linear trend."""
    n = len(t)
    tu = np.linspace(t[0], t[-1], n)
    wu = np.interp(tu, t, w)
    wu = wu - np.polyval(np.polyfit(tu, wu, 1), tu)
    spec = np.abs(np.fft.rfft(wu * np.hanning(n)))
    freqs = np.fft.rfftfreq(n, tu[1] - tu[0])
    k = 1 + int(np.argmax(spec[1:]))
    f0 = float(freqs[k])
    tc = t - t[0]

    def resid(x: Array) -> Array:
        a, b, f, c0, c1 = x
        return a * np.sin(2 * np.pi * f * tc) + b * np.cos(2 * np.pi * f * tc) + c0 + c1 * tc - w

    amp = np.std(w) * np.sqrt(2)
    fit = optimize.least_squares(resid, [amp, 0.0, f0, float(np.mean(w)), 0.0], x_scale="jac")
    a, b, f = fit.x[:3]
    return float(abs(f)), float(np.arctan2(b, a))


def _strokes(t: Array, w: Array, f: float, phase: float) -> Array:
    """Peak-to-peak of ``w`` over each full period ``[t_k, t_k + 1/f)``, the periods
    starting at the fitted sine's upward zero crossings."""
    t0 = t[0] + ((-phase / (2 * np.pi)) % 1.0) / f
    out = []
    k = 0
    while t0 + (k + 1) / f <= t[-1] + 1e-12:
        sel = (t >= t0 + k / f) & (t < t0 + (k + 1) / f)
        if sel.sum() >= 4:
            out.append(float(w[sel].max() - w[sel].min()))
        k += 1
    return np.array(out)


def weaving(t: ArrayLike, commanded: ArrayLike, attained: ArrayLike) -> Weaving:
    """ISO 9283 §11 WS and WF of one weaving cycle (a weave superimposed on a straight
    path).  Read here: the weave is the component of the positions along the direction
    across the path in which the commanded positions vary most; the frequency is the
    fitted frequency of that component; the stroke the mean peak-to-peak over the full
    weave periods in which the commanded stroke is at least 90 % of its largest.  The
    commanded stroke and frequency are measured from the commanded positions the same
    way, so that the method's own bias cancels.

    Args:
        t: ``(k,)`` times (s).
        commanded, attained: ``(k, 3)`` positions (m).
    """
    t = np.asarray(t, dtype=float)
    c = np.asarray(commanded, dtype=float)
    a = np.asarray(attained, dtype=float)
    if c.shape != (len(t), 3) or a.shape != c.shape or len(t) < 16:
        raise ValueError(
            f"weaving needs (k >= 16,) times and (k, 3) positions, got {t.shape}, {c.shape}, {a.shape}"
        )
    axis = c[-1] - c[0]
    if np.linalg.norm(axis) == 0:
        raise ValueError("the weaving path has no length (first and last commanded points coincide)")
    axis = axis / np.linalg.norm(axis)
    r = c - c[0]
    r = r - np.outer(r @ axis, axis)
    across = np.linalg.svd(r - r.mean(axis=0), full_matrices=False)[2][0]
    wc, wa = (c - c[0]) @ across, (a - c[0]) @ across
    fc, phase = _weave_frequency(t, wc)
    fa, _ = _weave_frequency(t, wa)
    sc, sa = _strokes(t, wc, fc, phase), _strokes(t, wa, fc, phase)
    if len(sc) == 0:
        raise ValueError("the record holds no full weave period")
    full = sc >= 0.9 * sc.max()
    Sc, Sa = float(sc[full].mean()), float(sa[full].mean())
    return Weaving(100.0 * (Sa - Sc) / Sc, 100.0 * (fa - fc) / fc, Sc, Sa, fc, fa)
