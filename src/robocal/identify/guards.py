"""Numerical guards: stop a calibration with an explanation instead of a silent bad model.

Checks around :func:`robocal.calibrate`:

* :func:`check_problem` before the fit — the data cannot determine the model:
  non-finite values, all poses the same, measured positions that never change, fewer
  equations than identifiable parameters, or poses that leave parameters undetermined
  which richer poses would determine (rank-deficient data: a joint that never moves,
  poses all in one plane...).  The last one compares the identifiable set of the
  measured poses with that of random poses over the joint ranges, with the same
  sequential rank test as the calibration (:func:`robocal.identify.observability.identifiable_subset`),
  and names the parameters lost and the joints that do not move.
* :func:`fit_to_noise` (:mod:`robocal.identify.noise_check`) after the fit, when the
  measurement noise is known — the model
  does not explain the data: residuals significantly larger than the noise (χ² test)
  mean errors the model does not represent, whose size it estimates.
* :func:`check_solution` after the fit — the fit did not work: not converged,
  diverged (what the method minimises larger after calibration than before: the RMS
  error, or the sum of distances for ``method="bounded"``), non-finite estimates or
  uncertainties, or parameters moved further from their start than any manufacturing
  error (a sign of data from another robot, wrong units or a wrong joint order).

They raise :class:`CalibrationGuardError` (a ``ValueError``) saying what is wrong and what
to do; :func:`check_problem` returns warnings (strings) for doubtful but usable data.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from robocal.choices import Measure
from robocal.identify.noise_check import FitToNoise, fit_to_noise  # re-exported: the guards
from robocal.measure.measurements import Measurements
from robocal.model.chain import Model
from robocal.model.steps import Role

__all__ = [
    "CalibrationGuardError",
    "FitToNoise",
    "check_data",
    "check_problem",
    "check_rank",
    "check_solution",
    "fit_to_noise",
]

Array = NDArray[np.float64]


class CalibrationGuardError(ValueError):
    """The calibration cannot be trusted; the message explains why and what to do."""


def _rows_text(rows: Sequence[int], limit: int = 6) -> str:
    shown = ", ".join(str(r) for r in rows[:limit])
    return shown + (f" ... ({len(rows)} rows)" if len(rows) > limit else "")


def _measurement_chain(
    model: Model, measure: Measure, frame: Any, tool: Any, tool_guess: ArrayLike | None
) -> Model:
    from robocal import spatial
    from robocal.identify.problem import measurement_chain

    fit_frame = isinstance(frame, str) and frame == "fit"
    T_frame = np.eye(4) if isinstance(frame, str) else np.asarray(frame, dtype=float)
    T_tool: Array | None = None
    if tool is not None:
        T_tool = np.eye(4)
        source = tool if not isinstance(tool, str) else tool_guess
        if source is not None:
            g = np.asarray(source, dtype=float)
            T_tool = g if g.shape == (4, 4) else spatial.homogeneous(p=g)
    chain = measurement_chain(model, T_frame, T_tool, measure, fit_frame)
    if tool is not None and not (isinstance(tool, str) and tool == "fit"):
        chain = chain.fixed(chain.names_with_role(Role.TOOL))
    return chain


def _identifiable(
    chain: Model, q: Array, measure: Measure, length: float, explain: bool = False
) -> tuple[set[str], Any]:
    """Identifiable free parameters of ``chain`` at poses ``q`` (the calibration's rank test)."""
    from robocal.identify.stages import identifiable_set

    J = chain.jacobian(q, rows=measure)
    rot = np.array([s.is_rotation for s in chain.steps if s.free])
    J = J * np.where(rot, length, 1.0)
    if measure == "pose":
        J = J.reshape(len(q), 6, -1)
        J[:, 3:] *= length  # orientation rows as displacements at the robot's size
        J = J.reshape(6 * len(q), -1)
    # the calibration's own rank test
    selection = identifiable_set(J, chain.free_names, explain=explain, roles=chain.roles)
    return set(selection.kept), selection


def _transform_key(x: Any) -> Any:
    """A hashable stand-in for a frame or tool argument (a string, None or an array)."""
    if x is None or isinstance(x, str):
        return x
    a = np.asarray(x, dtype=float)
    return (a.shape, a.tobytes())


def _distinct_rows(q: Array) -> Array:
    """The distinct rows of ``q`` ``(n, dof)``, sorted (``np.unique(q, axis=0)``, whose
    structured-array path costs ~100 µs at 100 poses; a lexicographic sort ~10 µs)."""
    if len(q) < 2:
        return np.array(q)
    ordered = q[np.lexsort(q.T[::-1])]
    new = np.empty(len(q), dtype=bool)
    new[0] = True
    np.any(ordered[1:] != ordered[:-1], axis=1, out=new[1:])
    return ordered[new]


_GENERIC: dict[Any, tuple[frozenset[str], float]] = {}  # the last few _generic answers


def _generic(
    model: Model, measure: Measure, frame: Any, tool: Any, tool_guess: Any, n: int, seed: int
) -> tuple[frozenset[str], float]:
    """Parameters identifiable from ``n`` random poses (seeded), and the robot's size (m).

    Cached: a model's identifiable set does not depend on the data."""
    key = (model, measure, _transform_key(frame), _transform_key(tool), _transform_key(tool_guess), n, seed)
    if key not in _GENERIC:
        from robocal.measure.ik_starts import random_configurations

        chain = _measurement_chain(model, measure, frame, tool, tool_guess)
        q = random_configurations(model, n, np.random.default_rng(seed))
        length = max(float(np.abs(model.fk(q)[:, :3, 3]).max()), 0.1)
        kept, _ = _identifiable(chain, q, measure, length)
        if len(_GENERIC) >= 32:
            _GENERIC.pop(next(iter(_GENERIC)))
        _GENERIC[key] = (frozenset(kept), length)
    return _GENERIC[key]


def check_problem(
    model: Model,
    data: Measurements,
    *,
    measure: Literal["position", "pose"] | None = None,
    frame: Literal["fit", "fixed"] | ArrayLike = "fit",
    tool: Literal["fit", "fixed"] | ArrayLike | None = "fit",
    tool_guess: ArrayLike | None = None,
    allow_rank_deficient: bool = False,
    reference_poses: int = 200,
    seed: int = 0,
) -> list[str]:
    """Check that ``data`` can determine the calibration of ``model`` (before fitting).

    Args:
        model, data, measure, frame, tool, tool_guess: as for :func:`robocal.calibrate`.
        allow_rank_deficient: accept poses that leave some generally identifiable
            parameters undetermined (they are then fixed and reported by the
            calibration); the other checks still apply.
        reference_poses: random poses (seeded) over the joint ranges that define which
            parameters are identifiable at all.
        seed: their seed.

    Returns:
        Warnings (e.g. joints that never move) — the data can be used.

    Raises:
        CalibrationGuardError: NaN/inf, a single distinct pose, measured positions that
            do not change, fewer equations than identifiable parameters, or (unless
            ``allow_rank_deficient``) rank-deficient poses; the message names rows,
            joints and parameters.
    """
    measure = measure or ("pose" if data.orientation is not None else "position")
    warnings = check_data(model, data)
    return warnings + check_rank(
        model,
        data,
        measure=measure,
        frame=frame,
        tool=tool,
        tool_guess=tool_guess,
        allow_rank_deficient=allow_rank_deficient,
        reference_poses=reference_poses,
        seed=seed,
    )


def check_data(model: Model, data: Measurements) -> list[str]:
    """The checks of :func:`check_problem` that need no model evaluation: non-finite
    values, a single distinct pose, positions that never change.  Returns warnings
    (joints that never move)."""
    if data.position is None:
        raise CalibrationGuardError("the measurements have no positions to calibrate against")
    if data.dof != model.dof:
        raise CalibrationGuardError(
            f"the data has {data.dof} joint columns but model {model.name!r} has {model.dof} joints"
        )
    import robocal.identify.kernels.check as check_kernels  # numba: imported on first use

    if data.n == 0:
        raise CalibrationGuardError("no measured poses")
    q, y = np.ascontiguousarray(data.q, dtype=float), np.ascontiguousarray(data.position, dtype=float)
    finite_q, finite_y, q_range, spread = check_kernels.data_ranges(q, y)  # q_range (dof,): rad or m
    for what, a, finite in (("joint values", q, finite_q), ("positions", y, finite_y)):
        if not finite:
            bad = np.flatnonzero(~np.all(np.isfinite(a), axis=1))
            raise CalibrationGuardError(f"{what} are NaN or inf in row(s) {_rows_text((bad + 1).tolist())}")
    if not q_range.any():
        raise CalibrationGuardError(
            f"all {data.n} poses have the same joint values ({', '.join(f'{v:.6g}' for v in q[0])}): "
            "a calibration needs poses that move the joints"
        )
    if spread < 1e-9:
        raise CalibrationGuardError(
            f"the measured positions do not change over {data.n} poses (spread {spread * 1e3:.3g} mm): "
            "is the device following the target?"
        )
    still = _still_joints(model, q_range)
    return [f"joint(s) {', '.join(still)} do not move in the data"] if still else []


def _still_joints(model: Model, q_range: Array) -> list[str]:
    """The joints whose range ``q_range`` ``(dof,)`` in the data is nil."""
    return [model.joint_names[j] for j, r in enumerate(q_range.tolist()) if r < 1e-9]


def check_rank(  # noqa: PLR0913 - keyword-only options, as check_problem passes them
    model: Model,
    data: Measurements,
    *,
    measure: Literal["position", "pose"],
    frame: Literal["fit", "fixed"] | ArrayLike = "fit",
    tool: Literal["fit", "fixed"] | ArrayLike | None = "fit",
    tool_guess: ArrayLike | None = None,
    allow_rank_deficient: bool = False,
    reference_poses: int = 200,
    seed: int = 0,
    kept: Sequence[str] | None = None,
    candidates: Sequence[str] | None = None,
) -> list[str]:
    """The rank checks of :func:`check_problem`: enough equations, and no parameter
    left undetermined by these poses that varied poses determine.

    ``kept`` is the identifiable set the calibration found at these poses (its own rank
    test on the same Jacobian, so it is not computed twice) among its ``candidates``
    (its free parameters); by default both are computed here.
    """
    rows = 3 if measure == "position" else 6
    generic, length = _generic(model, measure, frame, tool, tool_guess, reference_poses, seed)
    if kept is not None and candidates is not None and generic <= set(kept):
        return []  # every parameter varied poses determine is determined (so are the equations)
    distinct = _distinct_rows(data.q)
    if rows * len(distinct) < len(generic):
        raise CalibrationGuardError(
            f"{len(distinct)} distinct poses give {rows * len(distinct)} equations for the {len(generic)} "
            f"parameters of {model.name!r} that {measure} measurements can identify (device frame and tool "
            f"included): measure at least {math.ceil(len(generic) / rows)} distinct poses, better "
            f"{3 * math.ceil(len(generic) / rows)} or more"
        )
    chain: Model | None = None
    if kept is None or candidates is None:  # the caller's rank test is not at hand: this one's
        chain = _measurement_chain(model, measure, frame, tool, tool_guess)
        kept_set = set(kept) if kept is not None else _identifiable(chain, distinct, measure, length)[0]
        pool = chain.free_names if candidates is None else tuple(candidates)
    else:
        kept_set, pool = set(kept), tuple(candidates)
    lost = [n for n in pool if n in generic and n not in kept_set]
    if not lost:
        return []
    # confirmed by this guard's own rank test (the caller's may differ at the margin: its
    # start values, weights and joint-effect columns are not the reference's)
    chain = chain or _measurement_chain(model, measure, frame, tool, tool_guess)
    kept_set, selection = _identifiable(chain, distinct, measure, length, explain=True)
    lost = [n for n in pool if n in generic and n not in kept_set]
    if not lost:
        return []
    why = {d.name: d for d in selection.dropped}
    parts = []
    for name in lost[:8]:
        d = why.get(name)
        if d is not None and d.absorbed_by:
            with_ = ", ".join(n for n, _ in d.absorbed_by[:3])
            parts.append(f"{name} (cannot be told from {with_})")
        else:
            parts.append(f"{name} (no effect)")
    more = f" and {len(lost) - 8} more" if len(lost) > 8 else ""
    text = (
        f"rank-deficient data: these {len(distinct)} distinct poses determine {len(kept_set & generic)} of "
        f"the {len(generic)} parameters that varied poses determine; "
        f"undetermined: {'; '.join(parts)}{more}"
    )
    still = _still_joints(model, np.ptp(data.q, axis=0))
    if still:
        text += f"; joint(s) {', '.join(still)} never move"
    text += ": add poses that move every joint over its range (or allow_rank_deficient=True to fix them)"
    if not allow_rank_deficient:
        raise CalibrationGuardError(text)
    return [text]


def _diverged(result: Any) -> str | None:
    """What grew during the fit, or ``None``: the method's own objective when it records
    one (``diagnostics.objective``: ``method="bounded"`` minimises the sum of distances,
    which may legitimately raise the RMS error), else the RMS position error."""
    objective = getattr(getattr(result, "diagnostics", None), "objective", None)
    if objective is not None:
        if objective["after"] > objective["before"] * (1 + 1e-9) + 1e-12:
            return (
                f"{objective['name']} grew; mean distance {objective['mean_distance_before'] * 1e3:.4g} mm "
                f"before, {objective['mean_distance_after'] * 1e3:.4g} mm after"
            )
        return None
    if result.rms_after > result.rms_before * (1 + 1e-9) + 1e-12:
        return f"RMS error {result.rms_before * 1e3:.4g} mm before, {result.rms_after * 1e3:.4g} mm after"
    return None


def check_solution(
    result: Any,
    *,
    max_length_change: float = 0.05,
    max_angle_change: float = math.radians(15.0),
    require_convergence: bool = False,
) -> list[str]:
    """Check a :class:`~robocal.identify.calibrate.CalibrationResult` (after fitting); returns
    warnings (not converged).

    Args:
        result: the calibration result.
        max_length_change: largest plausible change of a robot length parameter (m)
            from its start value; the device frame (``frame_*``) and the tool
            (``tcp_*``) are exempt.
        max_angle_change: the same for angles (rad).
        require_convergence: a fit that did not converge is an error (by default a
            warning: a solver that stopped at its iteration limit may still have
            improved the model, which the divergence check verifies).

    Raises:
        CalibrationGuardError: not converged, diverged (RMS error after the fit larger
            than before), non-finite estimates or standard deviations, or implausible
            parameter changes (named, with their change).
    """
    warnings: list[str] = []
    if not result.success:
        text = (
            f"the fit did not converge ({result.message}, {result.iterations} iterations): "
            "check units, joint order and the start values (tool_guess)"
        )
        if require_convergence:
            raise CalibrationGuardError(text)
        warnings.append(text)
    estimates = np.asarray(result.estimates, dtype=float)  # a finite sum: all finite
    finite = math.isfinite(float(estimates.sum())) or bool(np.isfinite(estimates).all())
    if not (finite and math.isfinite(result.rms_after) and math.isfinite(result.rms_before)):
        bad = [n for n, v in zip(result.names, result.estimates, strict=True) if not math.isfinite(v)]
        raise CalibrationGuardError(
            "the fit produced non-finite values" + (f" for {', '.join(bad)}" if bad else "")
        )
    if not math.isfinite(float(np.asarray(result.std).sum())) and not np.isfinite(result.std).all():
        bad = [n for n, v in zip(result.names, result.std, strict=True) if not math.isfinite(v)]
        raise CalibrationGuardError(f"the uncertainty of {', '.join(bad)} is not finite: the fit is singular")
    if (diverged := _diverged(result)) is not None:
        raise CalibrationGuardError(
            f"the fit diverged: {diverged}; check units, joint order and the start values"
        )
    limit = min(max_length_change, max_angle_change)
    if not (np.abs(estimates - result.nominal) > limit).any():
        return warnings  # no change large enough to look at each
    rot = {}
    chain = result.measurement_chain or result.model
    for s in chain.steps:
        if s.role is Role.KINEMATIC:  # the device frame and the tool may move far
            rot[s.name] = s.is_rotation
    implausible = []
    for name, v, v0 in zip(result.names, result.estimates, result.nominal, strict=True):
        if name not in rot:
            continue
        change = abs(float(v - v0))
        if rot[name] and change > max_angle_change:
            implausible.append(f"{name} {math.degrees(v - v0):+.3g} deg")
        elif not rot[name] and change > max_length_change:
            implausible.append(f"{name} {(v - v0) * 1e3:+.4g} mm")
    if implausible:
        raise CalibrationGuardError(
            f"implausible parameter changes ({', '.join(implausible)}; limits "
            f"{max_length_change * 1e3:g} mm, {math.degrees(max_angle_change):g} deg): the data may belong "
            "to another robot or model, or be in other units or joint order"
        )
    return warnings
