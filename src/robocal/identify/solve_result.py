"""What every solver returns: :class:`SolveResult`, and :class:`BatchSolveResult` for
:func:`robocal.identify.solvers.levenberg_marquardt_batch` (their own module so that the
solvers' dispatcher, :mod:`robocal.identify.solvers`, the methods it dispatches to, e.g.
:mod:`robocal.identify.influence`, and the tests' numpy reference of the iteration,
``tests/reference_lm.py``, share them without importing each other)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

__all__ = ["BatchSolveResult", "SolveResult", "lm_message"]

Array = NDArray[np.float64]


@dataclass
class SolveResult:
    """What a solver returns (scipy-style)."""

    x: Array
    success: bool
    message: str
    iterations: int
    evaluations: int = 0
    history: list[float] = field(default_factory=list)  # RMS residual per iteration (weighted)
    # weighted residuals (m,) and Jacobian (m, p) at x, when the solver has them (LM: its
    # last evaluation), so that the uncertainty needs no second evaluation
    r: Array | None = field(default=None, repr=False)
    J: Array | None = field(default=None, repr=False)


@dataclass
class BatchSolveResult:
    """What :func:`~robocal.identify.solvers.levenberg_marquardt_batch` returns for ``K`` problems.

    Attributes:
        x: ``(K, p)`` the solutions; r, J: weighted residuals ``(K, m)`` and Jacobians
            ``(K, m, p)`` there.
        success: ``(K,)`` converged; iterations: ``(K,)`` accepted steps + 1;
            evaluations: ``(K,)`` residual-and-Jacobian evaluations.
        max_evaluations: the budget (for the message of a fit that ran out of it).
    """

    x: Array
    r: Array
    J: Array
    success: NDArray[np.bool_]
    iterations: NDArray[np.intp]
    evaluations: NDArray[np.intp]
    max_evaluations: int
    histories: list[list[float]] = field(default_factory=list)

    def message(self, k: int) -> str:
        return lm_message(bool(self.success[k]), int(self.evaluations[k]), self.max_evaluations)

    def result(self, k: int) -> SolveResult:
        """Problem ``k``'s :class:`SolveResult`."""
        return SolveResult(
            self.x[k].copy(),
            bool(self.success[k]),
            self.message(k),
            int(self.iterations[k]),
            int(self.evaluations[k]),
            self.histories[k],
            self.r[k],
            self.J[k],
        )


def lm_message(success: bool, evaluations: int, max_evaluations: int) -> str:
    """Why a Levenberg-Marquardt fit stopped."""
    if success:
        return "converged: the next step would not improve the fit"
    if evaluations < max_evaluations:  # the compiled iteration's stop
        return "stopped: NaN or inf in the Jacobian (no damping makes the step solvable)"
    return f"no convergence in {max_evaluations} evaluations"
