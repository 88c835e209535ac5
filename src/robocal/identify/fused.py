"""Stages 4-6 of a calibration compiled as two calls, where they apply: position
measurements, Levenberg-Marquardt with the linear loss, no joint effects — the common
calibration, and the one ``bench_calibrate`` times.

:func:`rank_test` evaluates the problem at its start values and runs the sequential rank
test (:func:`robocal.model.rank.preference_subset`) on the columns the compiled first pass
prepared; :func:`fit` runs screening, the fit, its covariance and pruning in one compiled
call (:func:`robocal.identify.fused_kernels.fit`) and leaves the pipeline's working state
as the staged functions would (:func:`robocal.identify.pipeline._calibrate_once` calls
them where this does not apply, and after a nearly singular covariance).  Every number
comes from the kernels the staged pipeline calls; ``tests/test_fused.py`` holds the two
to round-off.  Units: SI (m, rad).
"""

from __future__ import annotations

import functools
import time
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from robocal.identify.lm_numpy import lm_message
from robocal.identify.observability import Dropped, IdentifiableSubset
from robocal.identify.problem_setup import Run
from robocal.identify.rules import Rules
from robocal.identify.solve_result import SolveResult
from robocal.identify.stages import Covariance, preference_columns
from robocal.model.rank import preference_subset

__all__ = ["FirstPass", "applies", "fit", "rank_test"]

Array = NDArray[np.float64]
TOLERANCE = 1e-10  # the Levenberg-Marquardt tolerance of robocal.identify.solvers


@dataclass(frozen=True)
class FirstPass:
    """The evaluation at the start values (frames ``(n, 4, 4)``, unweighted residuals
    ``(3n,)`` and Jacobian ``(3n, p)``), the rank test's identifiable set and the
    problem's ``data`` tuple of :mod:`robocal.identify.fused_kernels`."""

    evaluation: tuple[Array, Array, Array]
    selection: IdentifiableSubset
    data: tuple
    free_steps: NDArray[np.intp]  # the unknowns' step indices in the chain


def applies(run: Run) -> bool:
    """Whether the compiled stages cover this calibration."""
    problem = run.problem
    return (
        run.method == "lm"
        and run.options.loss.loss == "linear"
        and run.measure == "position"
        and problem.n_effects == 0
        and problem.known_perturbations is None
    )


def _chain_data(run: Run) -> tuple:
    """The ``data`` tuple of :mod:`robocal.identify.fused_kernels`."""
    problem = run.problem
    plan = problem.chain._plan
    return (np.ascontiguousarray(problem.q, dtype=float), np.ascontiguousarray(problem.position, dtype=float),
            problem.weights, plan.step_axis, plan.step_rot, plan.step_joint, plan.joint_axis_array,
            plan.joint_rot_array, plan.anchor_of, plan.joint_steps)  # fmt: skip


def rank_test(run: Run) -> FirstPass | None:
    """The first evaluation and the identifiable set (as
    :func:`robocal.identify.stages.identifiable_set` on the scaled Jacobian); None when the
    Jacobian is not finite or has no non-zero column (the staged rank test explains)."""
    from robocal.identify import fused_kernels as kernels  # numba: imported on first use

    problem = run.problem
    chain = problem.chain
    names = problem.free_names
    free_steps = np.flatnonzero(chain.free_mask)
    data = _chain_data(run)
    T, r, J, norm, zero, ordered, At, finite = kernels.first_pass(
        data, chain.values, free_steps, float(problem.length_scale), preference_columns(names, chain.roles)
    )
    if not finite or not len(ordered):
        return None
    selection = preference_subset(At.T, ordered.tolist(), norm, zero, names)
    return FirstPass((T, r, J), selection, data, free_steps)


@functools.lru_cache(maxsize=64)
def _chi2_table(m: int, p: int, rules: Rules) -> tuple[Array, Array]:
    """:meth:`Rules.chi2_bounds` for ``m`` rows and 0 to ``p`` unknowns (by number of
    unknowns; at least one degree of freedom), read-only: the same for every calibration
    of a data set's size, and the inverse χ² costs ~50 µs."""
    tables = rules.chi2_bounds(np.maximum(m - np.arange(p + 1), 1.0))
    for table in tables:
        table.flags.writeable = False
    return tables


def fit(run: Run, first: FirstPass) -> bool:
    """Screening, the fit, its covariance and pruning over the identifiable set; the
    pipeline's state (problem, unknowns, dropped, fit, covariance) set as the staged
    functions set it.  False (nothing changed) when a covariance's normal matrix is nearly
    singular: the staged functions then take the SVD path."""
    from robocal.identify import fused_kernels as kernels

    problem, options = run.problem, run.options
    names = problem.free_names
    dropped = {d.name for d in first.selection.dropped}
    live = np.array([k for k, name in enumerate(names) if name not in dropped], dtype=np.intp)
    m, p = len(problem.weights), len(names)
    rules = Rules.of(options.pruning)
    bounds = _chi2_table(m, p, rules) if run.known_noise else (np.zeros(p + 1),) * 2
    screening = rules.screening(run.known_noise)
    budget = int(run.solver["max_iterations"])
    t = time.perf_counter()
    (status, screened, screened_sigma, pruned, pruned_sigma, live, x0, x, success, evaluations, total,
     history, last, covariance, J0) = kernels.fit(first.data, problem.chain.values, first.free_steps, live,
                                                  first.evaluation, screening, bounds, budget,
                                                  TOLERANCE)  # fmt: skip
    if status != kernels.OK:
        return False
    run.solve_seconds += time.perf_counter() - t
    columns, sigmas = screened.tolist() + pruned.tolist(), screened_sigma.tolist() + pruned_sigma.tolist()
    poor = [Dropped(names[c], "poorly identifiable", sigma=s) for c, s in zip(columns, sigmas, strict=True)]
    run.dropped = list(first.selection.dropped) + poor
    run.problem = problem.fix([d.name for d in run.dropped])
    T, _, J, rw, Jw = last
    run.problem._cache[(x.tobytes(), True)] = (T, J)  # the evaluations the result and checks read
    run.problem._cache[(x0.tobytes(), True)] = (first.evaluation[0], J0)
    run.x0, run.x = x0, x
    max_evaluations = budget * (len(live) + 1)
    run.fit = SolveResult(x, bool(success), lm_message(bool(success), int(evaluations), max_evaluations),
                          len(history), int(evaluations), history.tolist(), rw[0], Jw[0])  # fmt: skip
    run.evaluations += int(total)
    s2, cov, std, corr, cond = covariance
    run.covariance = Covariance(float(s2), cov, std, corr, float(cond))
    return True
