"""The seeds' error tables: per-pose errors, mean confidence intervals, improvements and the
table of cases (re-exported by :mod:`robocal.evaluate.metrics`)."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import special  # Student's t quantile; scipy.stats costs robocal report 0.5 s to import

from robocal.evaluate.deviations import angle_deltas, split_poses

Array = NDArray[np.float64]


#: The seeds' error quantities, in table order (seed 003 Tables 3.4, 4.5).
ERROR_QUANTITIES: tuple[str, ...] = ("|ΔX|", "|ΔY|", "|ΔZ|", "|ΔP|", "|ΔΦ|", "|Δθ|", "|ΔΨ|")


# ---------------------------------------------------------------------- seed tables
@dataclass(frozen=True)
class PoseErrors:
    """Attained-minus-commanded errors of ``n`` poses (seed 003 eq. 2.4: ΔP = P_a − P_t).

    Attributes:
        delta: ``(n, 3)`` position errors ΔX, ΔY, ΔZ (m).
        angles: ``(n, 3)`` Euler-angle errors ΔΦ, Δθ, ΔΨ (rad, wrapped), or None.
        euler: the Euler sequence of the angles.
    """

    delta: Array
    angles: Array | None = None
    euler: str = "ZXZ"

    @property
    def n(self) -> int:
        return len(self.delta)

    @property
    def distance(self) -> Array:
        """``(n,)`` |ΔP| (m)."""
        return np.linalg.norm(self.delta, axis=1)

    @property
    def quantities(self) -> tuple[str, ...]:
        return ERROR_QUANTITIES if self.angles is not None else ERROR_QUANTITIES[:4]

    def absolute(self) -> Array:
        """``(n, 4)`` or ``(n, 7)``: |ΔX| |ΔY| |ΔZ| |ΔP| (m) [|ΔΦ| |Δθ| |ΔΨ| (rad)]."""
        cols = [np.abs(self.delta), self.distance[:, None]]
        if self.angles is not None:
            cols.append(np.abs(self.angles))
        return np.hstack(cols)


def pose_errors(attained: ArrayLike, commanded: ArrayLike, euler: str = "ZXZ") -> PoseErrors:
    """Errors of attained poses with respect to commanded (or nominal) poses.

    Args:
        attained: ``(n, 3)`` positions or ``(n, 4, 4)`` frames (m).
        commanded: the same shape.
        euler: Euler sequence of ΔΦ, Δθ, ΔΨ (seed 003: ``"ZXZ"``).
    """
    p, R = split_poses(attained, "attained")
    pc, Rc = split_poses(commanded, "commanded")
    if p.shape != pc.shape or p.ndim != 2:
        raise ValueError(f"attained {p.shape} and commanded {pc.shape} must both be (n, 3) or (n, 4, 4)")
    angles = None
    if R is not None and Rc is not None:
        angles = angle_deltas(R, Rc, euler)
    return PoseErrors(p - pc, angles, euler)


def mean_ci(x: ArrayLike, confidence: float = 0.95) -> tuple[float, float]:
    """Mean and the half-width of its Student-t confidence interval (``x̄ ± t s/√n``)."""
    x = np.asarray(x, dtype=float).reshape(-1)
    if len(x) == 0:
        raise ValueError("mean_ci needs at least one value")
    if not 0 < confidence < 1:
        raise ValueError(f"confidence must lie in (0, 1), got {confidence}")
    if len(x) < 2:
        return float(x.mean()), float("nan")
    t = special.stdtrit(len(x) - 1, 0.5 + confidence / 2)
    return float(x.mean()), float(t * x.std(ddof=1) / math.sqrt(len(x)))


@dataclass(frozen=True)
class Improvement:
    """How much a mean error shrank, in per cent, with a confidence interval.

    ``percent = 100 (1 − mean_after / mean_before)``; ``percent_low``/``percent_high``
    bound it at ``confidence``; the means carry ``± ci`` half-widths.
    """

    mean_before: float
    ci_before: float
    mean_after: float
    ci_after: float
    percent: float
    percent_low: float
    percent_high: float
    n_before: int
    n_after: int
    paired: bool
    confidence: float

    def to_dict(self) -> dict[str, Any]:
        return {k: getattr(self, k) for k in self.__dataclass_fields__}


def improvement(
    before: ArrayLike, after: ArrayLike, confidence: float = 0.95, paired: bool | None = None
) -> Improvement:
    """Improvement of the mean of ``after`` over the mean of ``before`` (errors ≥ 0).

    Args:
        before, after: error samples (any unit, the same for both).
        confidence: of the intervals (default 95 %).
        paired: whether ``before[i]`` and ``after[i]`` belong to the same pose (default:
            when the lengths agree); see the module docstring for the intervals.
    """
    b = np.asarray(before, dtype=float).reshape(-1)
    a = np.asarray(after, dtype=float).reshape(-1)
    if len(b) < 2 or len(a) < 2:
        raise ValueError(f"improvement needs at least two errors before and after, got {len(b)} and {len(a)}")
    if paired is None:
        paired = len(a) == len(b)
    if paired and len(a) != len(b):
        raise ValueError(f"paired samples must have the same length, got {len(b)} and {len(a)}")
    mb, cb = mean_ci(b, confidence)
    ma, ca = mean_ci(a, confidence)
    if mb <= 0:
        raise ValueError("the mean error before must be > 0 to express an improvement in per cent")
    R = ma / mb
    if paired:
        n = len(a)
        cov = np.cov(np.vstack([a, b]), ddof=1)
        var = (cov[0, 0] + R**2 * cov[1, 1] - 2 * R * cov[0, 1]) / (n * mb**2)
        dof = n - 1
    else:
        var = a.var(ddof=1) / (len(a) * mb**2) + R**2 * b.var(ddof=1) / (len(b) * mb**2)
        dof = min(len(a), len(b)) - 1
    half = float(special.stdtrit(dof, 0.5 + confidence / 2) * math.sqrt(max(var, 0.0)))
    return Improvement(
        mean_before=mb,
        ci_before=cb,
        mean_after=ma,
        ci_after=ca,
        percent=100.0 * (1 - R),
        percent_low=100.0 * (1 - R - half),
        percent_high=100.0 * (1 - R + half),
        n_before=len(b),
        n_after=len(a),
        paired=bool(paired),
        confidence=confidence,
    )


@dataclass(frozen=True)
class ErrorTable:
    """Minimum, maximum and average of the seeds' error quantities, per case.

    Attributes:
        cases: case names in column order (e.g. ``("before", "after")``).
        quantities: row quantities (``|ΔX|`` ... ``|ΔP|`` [``|ΔΦ|`` ``|Δθ|`` ``|ΔΨ|``]).
        minimum, maximum, average: ``(quantities, cases)`` arrays, m for positions and
            rad for angles.
        improvements: per case after the first, per quantity: the improvement of the
            average over the first case's.
        n: number of poses per case.
    """

    cases: tuple[str, ...]
    quantities: tuple[str, ...]
    minimum: Array
    maximum: Array
    average: Array
    improvements: dict[str, dict[str, Improvement]]
    n: tuple[int, ...]

    def display(self, row: int, value: float) -> str:
        """A value of quantity ``row`` in mm or degrees, as text."""
        if self.quantities[row] in ERROR_QUANTITIES[4:]:
            return f"{math.degrees(value):.3f}"
        return f"{value * 1e3:.3f}"

    def to_dict(self) -> dict[str, Any]:
        """Plain data in mm and degrees."""

        def conv(q: str, v: float) -> float:
            return float(math.degrees(v)) if q in ERROR_QUANTITIES[4:] else float(v * 1e3)

        out: dict[str, Any] = {"cases": list(self.cases), "n": list(self.n), "units": "mm, deg"}
        for stat, arr in (("minimum", self.minimum), ("maximum", self.maximum), ("average", self.average)):
            out[stat] = {
                q: {c: conv(q, arr[i, j]) for j, c in enumerate(self.cases)}
                for i, q in enumerate(self.quantities)
            }
        out["improvement_percent"] = {
            case: {
                q: {"percent": imp.percent, "low": imp.percent_low, "high": imp.percent_high}
                for q, imp in per.items()
            }
            for case, per in self.improvements.items()
        }
        return out

    def to_text(self) -> str:
        """A plain-text table like the seeds' (mm, degrees)."""
        width = max(12, *(len(c) + 2 for c in self.cases))
        lines = [f"{'':9}{'':8}" + "".join(f"{c:>{width}}" for c in self.cases)]
        for stat, arr in (("Minimum", self.minimum), ("Maximum", self.maximum), ("Average", self.average)):
            for i, q in enumerate(self.quantities):
                unit = "°" if q in ERROR_QUANTITIES[4:] else ""
                values = "".join(f"{self.display(i, arr[i, j]):>{width}}" for j in range(len(self.cases)))
                lines.append(f"{stat if i == 0 else '':9}{q + unit:8}{values}")
        return "\n".join(lines)


def error_table(cases: Mapping[str, PoseErrors], confidence: float = 0.95) -> ErrorTable:
    """The seeds' min / max / average table of ``cases`` (name -> :class:`PoseErrors`),
    with the improvement of every case's averages over the first case's."""
    if not cases:
        raise ValueError("error_table needs at least one case")
    names = tuple(cases)
    errs = [cases[c] for c in names]
    with_angles = all(e.angles is not None for e in errs)
    quantities = ERROR_QUANTITIES if with_angles else ERROR_QUANTITIES[:4]
    cols = [e.absolute()[:, : len(quantities)] for e in errs]
    if any(len(c) == 0 for c in cols):
        raise ValueError("every case needs at least one pose")
    minimum = np.array([c.min(axis=0) for c in cols]).T
    maximum = np.array([c.max(axis=0) for c in cols]).T
    average = np.array([c.mean(axis=0) for c in cols]).T
    imps: dict[str, dict[str, Improvement]] = {}
    first = cols[0]
    for name, c in zip(names[1:], cols[1:], strict=True):
        if len(first) < 2 or len(c) < 2:
            continue
        imps[name] = {}
        for i, q in enumerate(quantities):
            if first[:, i].mean() > 0:
                imps[name][q] = improvement(first[:, i], c[:, i], confidence)
    return ErrorTable(names, quantities, minimum, maximum, average, imps, tuple(len(c) for c in cols))
