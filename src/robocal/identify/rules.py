"""The decision rules of a calibration, defined once for every engine.

A calibration decides three things besides the fit itself:

* **screening** — which unknowns the measurements leave hopeless before the first fit
  (σ beyond :attr:`Rules.screen_margin` times the pruning threshold);
* **pruning** — after a converged fit, which unknown to fix and refit, and when to stop
  (:func:`prune_candidate`: σ as tool displacement beyond ``max(max_std,
  max_std_ratio × median σ)``);
* **the variance factor of the covariance** — ``χ²/dof``, or 1 when a stated noise
  passes the two-sided χ² test at :attr:`Rules.significance` (:func:`variance_factor`);

and when a normal matrix is too nearly singular for them: the screening leaves such a
problem to the fit (:attr:`Rules.screen_singular`), the covariance takes the SVD path
(:attr:`Rules.covariance_singular`).  The condition number reported with a covariance is
:func:`condition_number` of the unit-norm normal matrix's eigenvalues.

The staged pipeline (:mod:`robocal.identify.pipeline`), the compiled fused stages
(:mod:`robocal.identify.kernels.fused`) and the batched engine
(:mod:`robocal.identify.batch`) all take their thresholds from one :class:`Rules` value
and their arithmetic from the functions here: numba compiles these same functions
(:mod:`robocal.identify.kernels.stage`), and Python calls the compiled ones, so no rule is
written twice.  The functions use only what numba compiles (loops over float arrays).
Units: SI (m); σ are tool displacements (m).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Protocol

import numpy as np
from numpy.typing import NDArray

__all__ = ["NO_CANDIDATE", "Rules", "condition_number", "prune_candidate", "variance_factor"]


class Pruning(Protocol):
    """What :meth:`Rules.of` reads of the pruning options
    (:class:`robocal.identify.options.Pruning`, whose defaults are the fields of
    :class:`Rules`: this module does not import it, to keep the options importing the rules)."""

    @property
    def max_std(self) -> float: ...
    @property
    def max_std_ratio(self) -> float: ...
    @property
    def screen_margin(self) -> float: ...
    @property
    def significance(self) -> float: ...


Array = NDArray[np.float64]

#: :func:`prune_candidate`'s answer when nothing is to be pruned
NO_CANDIDATE = -1


@dataclass(frozen=True)
class Rules:
    """The thresholds of screening, pruning and the covariance's variance factor.

    Attributes:
        max_std: m, an unknown whose σ as tool displacement is at most this is kept.
        max_std_ratio: an unknown whose σ is at most this times the median σ is kept
            (noisy data makes every σ large; that is not a reason to prune).
        screen_margin: screening before the fit fixes an unknown only beyond this times
            the pruning threshold (borderline ones are left to the pruning after the fit).
        significance: each tail of the χ² test of a stated noise (:func:`variance_factor`).
        screen_singular: the screening stops (leaves the rest to the fit and its checks)
            once the unit-norm normal matrix's condition (eigenvalue ratio, or its 1-norm
            estimate) is at or below this.
        covariance_singular: a covariance whose unit-norm normal matrix has an eigenvalue
            ratio at or below this is computed by the SVD and pseudo-inverse instead of a
            Cholesky factorisation (cond(J) ≥ 10⁶: the normal matrix has lost the digits).
    """

    max_std: float = 5e-4
    max_std_ratio: float = 3.0
    screen_margin: float = 3.0
    significance: float = 1e-3
    screen_singular: float = 1e-14
    covariance_singular: float = 1e-12

    @classmethod
    def of(cls, pruning: Pruning) -> Rules:
        """The rules of a calibration's pruning options."""
        return cls(
            float(pruning.max_std),
            float(pruning.max_std_ratio),
            float(pruning.screen_margin),
            float(pruning.significance),
        )

    def screening(self, known_noise: bool) -> tuple[float, float, float, bool, float, float]:
        """The rules as the kernels take them (numba: a plain tuple), ``(max_std,
        max_std_ratio, margin, known_noise, screen_singular, covariance_singular)``
        (:func:`robocal.identify.kernels.stage.screen`, :func:`robocal.identify.kernels.fused.fit`)."""
        return (float(self.max_std), float(self.max_std_ratio), float(self.screen_margin), bool(known_noise),
                float(self.screen_singular), float(self.covariance_singular))  # fmt: skip

    def chi2_bounds(self, dof: Array) -> tuple[Array, Array]:
        """The χ² values ``(k,)`` below and above which a stated noise is rejected for
        ``dof`` ``(k,)`` degrees of freedom: ``P(χ² ≤ low) = P(χ² ≥ high) = significance``
        (tables for the kernels: numba cannot call scipy.special)."""
        import scipy.special  # on use: reading a calibration needs none of it

        dof = np.asarray(dof, dtype=float)
        return (
            scipy.special.chdtri(dof, 1.0 - self.significance),
            scipy.special.chdtri(dof, self.significance),
        )


# ---------------------------------------------------------------------- the arithmetic (numba-compatible)
# Each function stands alone (numba compiles a function only with the compiled functions
# it calls; these are plain so that this module needs no numba).
def prune_candidate(move: Array, max_std: float, max_std_ratio: float, margin: float) -> int:
    """The pruning rule: the index of the unknown to fix, or :data:`NO_CANDIDATE`.

    ``move`` ``(p,)``: each unknown's σ as tool displacement (m).  The worst one (the first
    of equal ones; a NaN first of all) is fixed unless it is at most ``margin`` times the
    threshold ``max(max_std, max_std_ratio × median σ)`` (``margin`` 1 after a fit;
    :attr:`Rules.screen_margin` for the screening before it); the last unknown is never
    fixed.  The median by insertion sort: numba's ``np.sort`` costs most of a second of
    compilation."""
    n = len(move)
    if n < 2:
        return NO_CANDIDATE
    s = move.copy()
    for i in range(1, n):
        v = s[i]
        j = i - 1
        while j >= 0 and s[j] > v:
            s[j + 1] = s[j]
            j -= 1
        s[j + 1] = v
    median = 0.5 * (s[(n - 1) // 2] + s[n // 2])
    worst = int(np.argmax(move))
    if move[worst] <= margin * max(max_std, max_std_ratio * median):
        return NO_CANDIDATE
    return worst


def variance_factor(chi2: float, dof: float, known: bool, low: float, high: float) -> float:
    """The covariance's variance factor of weighted residuals with ``Σr² = chi2`` and
    ``dof`` degrees of freedom (at least 1): ``χ²/dof``, or 1 for a stated noise
    (``known``) that the χ² test accepts (``low ≤ χ² ≤ high``: :meth:`Rules.chi2_bounds`
    for ``max(dof, 1)``): the Cramér–Rao covariance; a few degrees of freedom cannot
    estimate the noise, and a model that explains the data leaves χ²/dof ≈ 1 anyway."""
    if known and low <= chi2 <= high:
        return 1.0
    return chi2 / max(dof, 1.0)


def condition_number(lam: Array) -> float:
    """The condition number of a matrix ``J`` from the ascending eigenvalues ``lam`` ``(p,)``
    of its normal matrix ``JᵀJ`` (of the unit-norm columns, for a calibration's):
    ``√(λ_max / λ_min)``, infinite when the smallest is not positive (and for no column)."""
    p = len(lam)
    if p == 0 or not lam[0] > 0.0:
        return math.inf
    return math.sqrt(lam[p - 1] / lam[0])
