"""Seed 003 §5.5.2's low-cost check: a pencil on a spring-loaded potentiometer (procedure).

The thesis fixes a pencil, on a potentiometer "with a spring in between", to the Katana's
end effector; the robot traces its circle on a paper on the 45° plane (the printed circle
taught by jogging to four points a quarter apart) and "the output of potentiometer
(+/-Z-direction) and a profile plotted (XY-direction) on a paper by the robot combinedly
provide Cartesian errors" — and reports only that the set-up "can be used to visually
recognise an improvement in trajectory tracking accuracy before and after the
calibration" (Fig. 5.13).

Model (:class:`~robocal.measure.plates.PenOnPaper` gives the paper's placement, the
noises, the sheet size and the spring's travel): the paper frame has x, y in the sheet and
z along its normal; the pen is held along the normal.  A commanded path holds the pen
pressed by ``preload`` (m) at the paper; when the tool is ``z`` off the paper plane

* the potentiometer reads the change of the spring's compression, ``−z`` (plus its noise
  ``sigma_z``), while the pen touches: ``z < preload``;
* beyond that the pen lifts: no trace, the potentiometer reads ``−preload`` (the spring
  at rest); beyond ``travel`` towards the paper the spring bottoms out (refused);
* the trace is the tip's ``(x, y)`` where the pen touches, read off the paper with
  ``sigma_xy``.

What the trace gives: the deviation *across* the printed curve (:func:`across_deviation`:
the signed distance of each trace point from it); the potentiometer the deviation *out of*
the paper.  What it does not give: the error *along* the path (a trace carries no time: a
tool late or early on the circle draws the same line), the paper's placement in the robot
frame (a sheet placed 1 mm off shifts every across-deviation by 1 mm; the thesis teaches
four points to place the circle), and numbers the thesis would report (it reports a
visual improvement only).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial import cKDTree

__all__ = ["PenTrace", "across_deviation", "pen_trace"]

Array = NDArray[np.float64]
PRELOAD = 1.0e-3  # the spring's compression on the paper (m): an assumption, the thesis gives none


@dataclass(frozen=True)
class PenTrace:
    """What the set-up records along a path of ``n`` samples.

    Attributes:
        xy: ``(n, 2)`` the trace in the paper frame (m); NaN where the pen was lifted.
        potentiometer: ``(n,)`` the change of the spring's compression (m; + towards the paper).
        lifted: ``(n,)`` True where the pen left the paper.
    """

    xy: Array
    potentiometer: Array
    lifted: NDArray[np.bool_]


def pen_trace(
    pen, p_base: ArrayLike, rng: np.random.Generator | None = None, preload: float = PRELOAD
) -> PenTrace:
    """The trace and potentiometer signal of the pen tip's path ``p_base`` ``(n, 3)`` (m, robot
    base) on ``pen`` (:class:`~robocal.measure.plates.PenOnPaper`); ``rng`` None: noise-free.
    ValueError naming the sample when the tip leaves the sheet or bottoms the spring out."""
    p = np.atleast_2d(np.asarray(p_base, dtype=float))
    local = p @ pen.T_device_base[:3, :3].T + pen.T_device_base[:3, 3]
    if pen.size is not None:
        off = np.flatnonzero(np.any(np.abs(local[:, :2]) > np.array(pen.size) / 2, axis=1))
        if off.size:
            raise ValueError(f"pen: the tip leaves the sheet at sample {off[0] + 1}")
    z = local[:, 2]
    if pen.travel is not None and np.any(-z > pen.travel - preload):
        i = int(np.argmax(-z))
        raise ValueError(
            f"pen: the spring bottoms out at sample {i + 1} ({-z[i] * 1000:.2f} mm into the paper)"
        )
    lifted = z > preload
    noise = (
        (lambda s, shape: np.zeros(shape))
        if rng is None
        else (lambda s, shape: s * rng.standard_normal(shape))
    )
    xy = local[:, :2] + noise(pen.sigma_xy, (len(p), 2))
    xy[lifted] = np.nan
    pot = np.where(lifted, -preload, -z + noise(pen.sigma_z, len(p)))
    return PenTrace(xy, pot, lifted)


def across_deviation(xy: ArrayLike, printed_xy: ArrayLike, spacing: float = 2e-5) -> Array:
    """Signed distance ``(n,)`` (m) of trace points ``xy`` ``(n, 2)`` from the printed curve
    (the polyline ``printed_xy`` ``(k, 2)``, in order; + to its left), NaN where ``xy`` is;
    the polyline is resampled every ``spacing`` m (the reading resolution it allows)."""
    xy = np.atleast_2d(np.asarray(xy, dtype=float))
    c = np.asarray(printed_xy, dtype=float)
    seg = np.diff(c, axis=0)
    steps = np.maximum(1, np.ceil(np.linalg.norm(seg, axis=1) / spacing).astype(int))
    dense = np.concatenate(
        [c[i] + seg[i] * np.linspace(0, 1, k, endpoint=False)[:, None] for i, k in enumerate(steps)]
    )
    dense = np.vstack([dense, c[-1]])
    ok = np.all(np.isfinite(xy), axis=1)
    out = np.full(len(xy), np.nan)
    _, j = cKDTree(dense).query(xy[ok])
    best = np.full(len(j), np.inf)
    for lo in (np.maximum(j - 1, 0), j):  # the two segments at the nearest sample
        hi = np.minimum(lo + 1, len(dense) - 1)
        seg = dense[hi] - dense[lo]
        length2 = np.maximum(np.einsum("ni,ni->n", seg, seg), 1e-300)
        t = np.clip(np.einsum("ni,ni->n", xy[ok] - dense[lo], seg) / length2, 0.0, 1.0)
        d = xy[ok] - (dense[lo] + t[:, None] * seg)
        dist = np.hypot(d[:, 0], d[:, 1])
        side = np.where(seg[:, 0] * d[:, 1] - seg[:, 1] * d[:, 0] < 0, -1.0, 1.0)
        best = np.where(dist < np.abs(best), side * dist, best)
    out[ok] = best
    return out
