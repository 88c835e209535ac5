"""Each kind's noise from the residuals: mixed data weighted by its own σ.

Socket poses and tracker positions carry different noise (a ball seated by hand: tens of
µm; a laser tracker: a few µm per axis).  Weighting both by one σ lets the noisier kind
pull the fit; the stated σ are rarely known.  :func:`weigh_by_kind` estimates them with
the fit (variance component estimation, Förstner 1979): each group's σ̂² is its weighted
squared residuals over its redundancy ``m_g − tr(H_gg)``, ``H = J (JᵀJ)⁻¹ Jᵀ`` the hat
matrix of the weighted least-squares fit; the weights are updated and the fit repeated.
With one group this is σ̂ of the fit (the prior's weighting needs it: a stated σ ten times
the real one would make the prior ten times too strong).

Groups: the constraint rows (points, planes and pose pairs: the tool point's σ), the
tracker rows (``tracker_sigma``) and the inclinometer rows (``tilt_sigma``, rad); a stated
distance between fixed points keeps its σ.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from robocal.identify.constraints.model import ConstraintProblem
from robocal.identify.solvers import solve
from robocal.measure.constraints.data_set import ConstraintSet

__all__ = ["kind_noise", "weigh_by_kind"]

GROUPS = {"constraint": "sigma", "pair": "sigma", "tracker": "tracker", "tilt": "tilt"}
SMALLEST = 1e-9  # m: a σ̂ of noise-free data, kept positive


def kind_noise(problem: ConstraintProblem, x: np.ndarray) -> dict[str, float]:
    """σ̂ (m) of each noise component at the least-squares solution ``x`` of ``problem``
    (no prior rows): ``{"sigma": …, "tracker": …}`` for the components present."""
    r = problem.measurement_residual(x)
    J = problem.jacobian(x)[: len(r)]
    h = np.sum(np.linalg.qr(J)[0] ** 2, axis=1)  # the hat matrix' diagonal
    squares: dict[str, float] = {}
    redundancy: dict[str, float] = {}
    for name, rows in problem.row_groups():
        if name in GROUPS:
            key = GROUPS[name]
            squares[key] = squares.get(key, 0.0) + float(r[rows] @ r[rows])
            redundancy[key] = redundancy.get(key, 0.0) + float(len(r[rows]) - h[rows].sum())
    stated = {"sigma": problem.data.sigma, "tracker": problem.data.position_sigma,
              "tilt": problem.data.tilt_sigma}  # fmt: skip
    return {
        key: max(stated[key] * math.sqrt(squares[key] / max(redundancy[key], 1.0)), SMALLEST)
        for key in squares
    }


def weigh_by_kind(problem: ConstraintProblem, iterations: int = 4) -> ConstraintSet:
    """``problem``'s data with each kind's σ estimated from the residuals of least-squares
    fits (module docstring); ``problem`` holds only identifiable unknowns."""
    plain = problem.with_data(problem.data, prior=False)
    groups = {GROUPS[name] for name, _ in plain.row_groups() if name in GROUPS}
    for _ in range(iterations if len(groups) > 1 else 1):
        sigma = kind_noise(plain, solve(plain, plain.x0, "lm").x)
        data = dataclasses.replace(
            plain.data, sigma=sigma.get("sigma", plain.data.sigma),
            tracker_sigma=sigma.get("tracker", plain.data.tracker_sigma),
            tilt_sigma=sigma.get("tilt", plain.data.tilt_sigma),
        )  # fmt: skip
        pairs = ((data.sigma, plain.data.sigma), (data.position_sigma, plain.data.position_sigma),
                 (data.tilt_sigma, plain.data.tilt_sigma))  # fmt: skip
        done = all(math.isclose(v, w, rel_tol=1e-3) for v, w in pairs)
        plain = plain.with_data(data, prior=False)
        if done:
            break
    return plain.data
