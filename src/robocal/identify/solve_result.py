"""What every solver returns: :class:`SolveResult` (its own module so that the solvers'
dispatcher, :mod:`robocal.identify.solvers`, and the methods it dispatches to, e.g.
:mod:`robocal.identify.influence`, share it without importing each other)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

__all__ = ["SolveResult"]

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
