"""Stages 4-6 of a calibration compiled as two calls, where they apply: position
measurements, Levenberg-Marquardt with the linear loss, no joint effects — the common
calibration, and the one ``bench_calibrate`` times.

:func:`rank_test` evaluates the problem at its start values and runs the sequential rank
test (:func:`robocal.model.rank.preference_subset`) on the columns the compiled first pass
prepared; :func:`fit` runs screening, the fit, its covariance and pruning in one compiled
call (:func:`robocal.identify.kernels.fused.fit`) and returns the frozen
:class:`~robocal.identify.problem_setup.Fit` the staged functions would
(:func:`robocal.identify.pipeline._calibrate_once` calls them where this does not apply,
and after a nearly singular covariance).  The decisions (screening, pruning, the variance
factor) are :mod:`robocal.identify.rules`': a frozen :class:`~robocal.identify.rules.Rules`
handed to the kernels as a tuple and tables.  Every number
comes from the kernels the staged pipeline calls; ``tests/test_fused.py`` holds the two
to round-off.  Units: SI (m, rad).
"""

from __future__ import annotations

import functools
import time
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import NDArray

from robocal.identify.problem import Problem
from robocal.identify.problem_setup import Fit, Run, Selection, Start
from robocal.identify.rules import Rules
from robocal.identify.solve_result import SolveResult, lm_message
from robocal.identify.stages import Covariance, preference_columns
from robocal.model.kernel_mode import compiled_wanted
from robocal.model.rank import Dropped, IdentifiableSubset, preference_subset

__all__ = ["FirstPass", "applies", "fit", "rank_test"]

Array = NDArray[np.float64]
TOLERANCE = 1e-10  # the Levenberg-Marquardt tolerance of robocal.identify.solvers


@dataclass(frozen=True)
class FirstPass:
    """The evaluation at the start values (frames ``(n, 4, 4)``, unweighted residuals
    ``(3n,)`` and Jacobian ``(3n, p)``), the rank test's identifiable set and the
    problem's ``data`` tuple of :mod:`robocal.identify.kernels.fused`."""

    evaluation: tuple[Array, Array, Array]
    selection: IdentifiableSubset
    data: tuple
    free_steps: NDArray[np.intp]  # the unknowns' step indices in the chain


def applies(run: Run, problem: Problem) -> bool:
    """Whether the compiled stages cover this calibration (its inputs, and its ``problem``
    at the start values), and the process computes with the compiled kernels
    (:func:`robocal.model.kernel_mode.compiled_wanted`)."""
    return (
        compiled_wanted()
        and run.method == "lm"
        and run.options.loss.loss == "linear"
        and run.measure == "position"
        and problem.n_effects == 0
        and problem.known_perturbations is None
    )


def _chain_data(problem: Problem) -> tuple:
    """The ``data`` tuple of :mod:`robocal.identify.kernels.fused`."""
    plan = problem.chain._plan
    return (np.ascontiguousarray(problem.q, dtype=float), np.ascontiguousarray(problem.position, dtype=float),
            problem.weights, plan.step_axis, plan.step_rot, plan.step_joint, plan.joint_axis_array,
            plan.joint_rot_array, plan.anchor_of, plan.joint_steps)  # fmt: skip


class _FirstPass(NamedTuple):
    """:func:`robocal.identify.kernels.fused.first_pass`'s result, by name."""

    frames: Array  # (n, 4, 4) tool frames at the start values
    r: Array  # (3n,) unweighted residuals (m)
    J: Array  # (3n, p) unweighted Jacobian
    norm: Array  # (p,) norms of the scaled Jacobian's columns
    zero: NDArray[np.bool_]  # (p,) which of them are zero
    ordered: NDArray[np.intp]  # the non-zero columns in preference order
    At: Array  # (k, m) those columns with unit norm, transposed
    finite: bool


class _Fused(NamedTuple):
    """:func:`robocal.identify.kernels.fused.fit`'s result, by name."""

    status: int
    screened: NDArray[np.intp]  # free-column indices screened before the fit
    screened_sigma: Array  # their σ (m)
    pruned: NDArray[np.intp]  # free-column indices pruned after fits
    pruned_sigma: Array
    live: NDArray[np.intp]  # the final unknowns' free-column indices
    x0: Array  # their start values
    x: Array  # their fitted values
    success: bool
    evaluations: int  # of the last fit
    total: int  # of all fits
    history: Array  # the last fit's RMS history
    last: tuple[Array, Array, Array, Array, Array]  # frames, r, J, weighted r (m,) and J (m, p) at x
    covariance: tuple[float, Array, Array, Array, float]  # as stages.Covariance
    J0: Array  # the first Jacobian's columns of the final unknowns


def rank_test(problem: Problem) -> FirstPass | None:
    """The first evaluation and the identifiable set (as
    :func:`robocal.identify.stages.identifiable_set` on the scaled Jacobian); None when the
    Jacobian is not finite or has no non-zero column (the staged rank test explains)."""
    import robocal.identify.kernels.fused as kernels  # numba: imported on first use

    chain = problem.chain
    names = problem.free_names
    free_steps = chain.free_mask.nonzero()[0]  # (flatnonzero of the 1-D mask without its ravel)
    data = _chain_data(problem)
    order = problem.preference if problem.preference is not None else preference_columns(names, chain.roles)
    out = _FirstPass(*kernels.first_pass(data, chain.values, free_steps, float(problem.length_scale), order))
    if not out.finite or not len(out.ordered):
        return None
    selection = preference_subset(out.At.T, out.ordered.tolist(), out.norm, out.zero, names)
    return FirstPass((out.frames, out.r, out.J), selection, data, free_steps)


@functools.lru_cache(maxsize=64)
def _chi2_table(m: int, p: int, rules: Rules) -> tuple[Array, Array]:
    """:meth:`Rules.chi2_bounds` for ``m`` rows and 0 to ``p`` unknowns (by number of
    unknowns; at least one degree of freedom), read-only: the same for every calibration
    of a data set's size, and the inverse χ² costs ~50 µs."""
    tables = rules.chi2_bounds(np.maximum(m - np.arange(p + 1), 1.0))
    for table in tables:
        table.flags.writeable = False
    return tables


def fit(start: Start, first: FirstPass, solver: Mapping[str, Any], rules: Rules) -> Fit | None:
    """Screening, the fit, its covariance and pruning over the identifiable set, as the
    staged functions fit it (``solver``: the settings of the LM fit, ``rules``: the
    decisions').  None when a covariance's normal matrix is nearly singular: the staged
    functions then take the SVD path."""
    import robocal.identify.kernels.fused as kernels

    problem = start.problem
    names = problem.free_names
    dropped = {d.name for d in first.selection.dropped}
    live = np.array([k for k, name in enumerate(names) if name not in dropped], dtype=np.intp)
    m, p = len(problem.weights), len(names)
    bounds = _chi2_table(m, p, rules) if start.known_noise else (np.zeros(p + 1),) * 2
    budget = int(solver["max_iterations"])
    t = time.perf_counter()
    out = _Fused(*kernels.fit(first.data, problem.chain.values, first.free_steps, live, first.evaluation,
                              rules.screening(start.known_noise), bounds, budget, TOLERANCE))  # fmt: skip
    if out.status != kernels.OK:
        return None
    seconds = time.perf_counter() - t
    columns = out.screened.tolist() + out.pruned.tolist()
    sigmas = out.screened_sigma.tolist() + out.pruned_sigma.tolist()
    poor = [Dropped(names[c], "poorly identifiable", sigma=s) for c, s in zip(columns, sigmas, strict=True)]
    all_dropped = (*first.selection.dropped, *poor)
    fixed = problem.fix([d.name for d in all_dropped])
    x, x0 = out.x, out.x0
    T, r, J, rw, Jw = out.last
    fixed._cache[(x.tobytes(), True)] = (T, J)  # the evaluations the result and checks read
    fixed._cache[(x0.tobytes(), True)] = (first.evaluation[0], out.J0)
    success, evaluations = bool(out.success), int(out.evaluations)
    message = lm_message(success, evaluations, budget * (len(out.live) + 1))
    solved = SolveResult(x, success, message, len(out.history), evaluations, out.history.tolist(), rw, Jw)
    s2, cov, std, corr, cond = out.covariance
    covariance = Covariance(float(s2), cov, std, corr, float(cond))
    # the unweighted residuals at the solution and the start (those of the evaluations above)
    residuals = (r, first.evaluation[1])
    return Fit(
        Selection(fixed, x0, all_dropped, solver), x, solved, covariance, int(out.total), seconds, residuals
    )
