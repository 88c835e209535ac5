"""The stages of a calibration, shared by :func:`robocal.calibrate` and the batched engine.

Both calibration engines — :func:`robocal.identify.calibrate.calibrate_physics` (one
robot, any method, device and joint effects) and :func:`robocal.identify.batch.calibrate_batch`
(many robots of one model at once, for studies) — call these functions, so that a
study's calibration is ``rc.calibrate``'s to round-off:

* start values: :func:`initial_frames_and_tools` (device frame by Kabsch/Horn, tool by
  linear least squares, alternated) and :func:`robot_sizes`;
* the identifiable set: :func:`identifiable_set` (the sequential rank test preferring
  the device frame, then the tool, then the robot in chain order);
* screening before the first fit: :func:`screen_unidentifiable`;
* the solver: :func:`robocal.identify.solvers.levenberg_marquardt_batch`;
* uncertainty: :func:`uncertainty` (σ̂²(JᵀWJ)⁻¹, condition number);
* pruning after the fit: :func:`tool_displacement_scale`, :func:`poorly_identifiable`;
* their one order: :func:`fit_selection` (screening, the fit, pruning), over an engine's
  :class:`FitStages`.

Functions with a leading batch axis ``K`` work on many robots at once; the others on one
(the batched engine calls them per robot: they are cheap next to the fits).
Units: SI (m, rad); weighted residuals are in units of their σ.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import NamedTuple, Protocol, TypeVar

import numpy as np
from numpy.typing import ArrayLike, NDArray

from robocal.identify.kernel_cache import stage_kernels, start_kernels
from robocal.identify.rules import NO_CANDIDATE, Rules, condition_number
from robocal.model.rank import IdentifiableSubset, identifiable_subset
from robocal.model.steps import Role

__all__ = [
    "Covariance",
    "FitStages",
    "chi2_bounds",
    "fit_selection",
    "identifiable_set",
    "initial_frames_and_tools",
    "median",
    "normal_inverse",
    "poorly_identifiable",
    "preference_columns",
    "preference_order",
    "residual_variance",
    "robot_size",
    "robot_sizes",
    "screen_unidentifiable",
    "tool_displacement_scale",
    "uncertainty",
]

Array = NDArray[np.float64]
S = TypeVar("S")
F = TypeVar("F")


# ---------------------------------------------------------------------- the one order
class FitStages(Protocol[S, F]):
    """Stages 5-6 as an engine provides them, on its own selection (``S``: the unknowns
    chosen, for one robot or ``K``) and fit (``F``) values: the staged single calibration
    (:mod:`robocal.identify.pipeline`) and the batched engine (:mod:`robocal.identify.batch`).
    The compiled fused path runs the same order inside one kernel with the same rules."""

    def screen(self, selection: S) -> S:
        """Fix the hopeless unknowns before the first fit (:func:`screen_unidentifiable`)."""
        ...

    def solve(self, selection: S) -> F:
        """Fit the selection from its start values, with the :func:`uncertainty` there."""
        ...

    def prune(self, fit: F) -> F:
        """Fix the worst poorly identifiable unknown (:func:`poorly_identifiable`) and refit
        from the start values, until none is left."""
        ...


def fit_selection(stages: FitStages[S, F], selection: S) -> F:
    """Stages 5-6 in their one order: screening, the fit from the screened start values,
    pruning.  Every engine that fits in Python calls this; a new stage goes here once."""
    return stages.prune(stages.solve(stages.screen(selection)))


# ---------------------------------------------------------------------- start values
def initial_frames_and_tools(
    T_flange: Array,
    position: Array,
    *,
    orientation: Array | None = None,
    T_tool: Array | None = None,
    T_frame: Array | None = None,
    fit_frame: bool = True,
    fit_tool: bool = True,
    rounds: int = 4,
) -> tuple[Array, Array]:
    """Start values of the device frame and the tool of ``K`` robots: alternating
    closed-form fits (Kabsch/Horn for ``T_device_base``, the mean of the least-squares
    tool points, and for pose data the nearest rotation of the tool's orientation).

    Computed by :func:`robocal.identify.kernels.start.frames_and_tools` (numba; numpy's
    batched form cost ~20 calls on 3x3 matrices per round, 200 µs for one robot).

    Args:
        T_flange: ``(K, n, 4, 4)`` the robots' end frames at the measured joint values.
        position: ``(K, n, 3)`` measured positions (m, device frame).
        orientation: ``(K, n, 3, 3)`` measured rotations (pose data) or None.
        T_tool: ``(4, 4)`` or ``(K, 4, 4)`` start of the tool (default identity).
        T_frame: ``(4, 4)`` or ``(K, 4, 4)`` the known device frame when it is not
            fitted (default identity).
        fit_frame, fit_tool: which of the two are fitted (both: ``rounds`` rounds).

    Returns:
        ``(K, 4, 4)`` device frames and ``(K, 4, 4)`` tools.

    Raises:
        ValueError: ``position`` has NaN or inf (frame fitted), or a robot's points are
            (nearly) collinear.
        numpy.linalg.LinAlgError: the flange frames, start tool or orientations are not finite.
    """
    sk = start_kernels()  # compiled (numba, imported on first use) or numpy while the cache is cold

    K, n = T_flange.shape[:2]
    if T_flange.shape[2:] != (4, 4):
        raise ValueError(f"T_flange must have shape (K, n, 4, 4), got {T_flange.shape}")
    T_tool, T_frame = _frames(T_tool, K), _frames(T_frame, K)
    has_orientation = orientation is not None
    status = sk.frames_and_tools(  # the kernel reads (K, n, ...) arrays unchecked: broadcast here
        np.ascontiguousarray(T_flange, dtype=float),
        _pose_array(position, (K, n, 3)),
        _pose_array(orientation, (K, n, 3, 3)) if orientation is not None else _NO_ORIENTATION,
        has_orientation,
        T_frame,
        T_tool,
        bool(fit_frame),
        bool(fit_tool),
        int(rounds),
    )
    if status == sk.NON_FINITE_POINTS:
        raise ValueError("point sets contain NaN or inf")
    if status == sk.SVD_FAILED:
        raise np.linalg.LinAlgError("SVD did not converge")
    if status >= sk.COLLINEAR:
        where = status - sk.COLLINEAR
        raise ValueError(
            f"points of fit ({where},) are (nearly) collinear; a rigid transform is not determined"
        )
    return T_frame, T_tool


_NO_ORIENTATION = np.zeros((1, 1, 3, 3))


def _pose_array(x: ArrayLike, shape: tuple[int, ...]) -> Array:
    """``x`` as a C-contiguous float array of ``shape`` (broadcast, as numpy's fits did)."""
    x = np.asarray(x, dtype=float)
    return np.ascontiguousarray(x if x.shape == shape else np.broadcast_to(x, shape))


def _frames(T: Array | None, K: int) -> Array:
    """A new ``(K, 4, 4)`` array of ``T`` (``(4, 4)`` or ``(K, 4, 4)``; None: identity)."""
    out = np.empty((K, 4, 4))
    out[...] = _EYE4 if T is None else T
    return out


_EYE4 = np.eye(4)


def robot_sizes(T_flange: Array) -> Array:
    """``(K,)`` the robots' sizes (m), to weigh rotations against lengths: the largest
    coordinate of their end frames ``(K, n, 4, 4)`` at the first 50 poses (at least 0.1)."""
    return np.maximum(np.abs(T_flange[:, :50, :3, 3]).max(axis=(1, 2)), 0.1)


def robot_size(T_flange: Array) -> float:
    """:func:`robot_sizes` of one robot's end frames ``(n, 4, 4)`` (m; one reduction instead
    of a batch's: every calibration asks)."""
    return max(float(np.abs(T_flange[:50, :3, 3]).max()), 0.1)


# ---------------------------------------------------------------------- identifiable set
_PREFERENCE = {Role.DEVICE: 0, Role.TOOL: 1}  # the others: 2


def preference_columns(names: Sequence[str], roles: Mapping[str, Role]) -> NDArray[np.intp]:
    """The indices into ``names`` of the unknowns to keep first when some are redundant:
    the device frame's, then the tool's, then the others in chain order (``roles``: the
    chain's :attr:`Model.roles`; names it lacks, the joint-effect coefficients, come last)."""
    rank = [_PREFERENCE.get(roles.get(x), 2) for x in names]  # type: ignore[arg-type]
    return np.argsort(np.array(rank, dtype=np.intp), kind="stable")  # stable: chain order within a role


def preference_order(names: Sequence[str], roles: Mapping[str, Role]) -> list[str]:
    """``names`` in :func:`preference_columns` order."""
    return [names[i] for i in preference_columns(names, roles).tolist()]


def identifiable_set(
    J_scaled: Array, names: Sequence[str], explain: bool = True, *, roles: Mapping[str, Role]
) -> IdentifiableSubset:
    """The calibration's identifiable set: the sequential rank test
    (:func:`~robocal.identify.observability.identifiable_subset`, ``order="preference"``)
    over the weighted Jacobian ``(m, p)`` with every unknown as a tool displacement;
    ``roles``: the measurement chain's (:func:`preference_order`)."""
    prefer = preference_order(names, roles)
    return identifiable_subset(J_scaled, names, order="preference", prefer=prefer, explain=explain)


def tool_displacement_scale(J_position: Array) -> Array:
    """``(..., p)`` the largest displacement (m) of the measured point per unit of each
    unknown over the poses, from the unweighted position rows of the Jacobian
    ``(..., n, 3, p)`` (:meth:`robocal.identify.problem.Problem.effect_scale`)."""
    return np.sqrt(np.einsum("...nrp,...nrp->...np", J_position, J_position).max(axis=-2))


# ---------------------------------------------------------------------- screening
def normal_inverse(J: Array, singular: float = Rules.screen_singular) -> tuple[Array, Array, Array, Array]:
    """``J`` with unit-norm columns, the column norms, and the eigenvalues and inverse of
    the normalised normal matrix ``JnᵀJn`` (the inverse is meaningful only when the
    smallest eigenvalue is well above round-off).

    Compiled (:func:`robocal.identify.kernels.stage.normal_inverse`: eigenvalues without
    vectors, the inverse from a Cholesky factorisation); a numerically singular matrix
    (smallest eigenvalue at most ``singular`` of the largest, or a failed factorisation)
    gets the inverse from the eigendecomposition instead."""
    sk = stage_kernels()  # compiled (numba, imported on first use) or numpy while the cache is cold

    Jn, norms, lam, inverse, ok = sk.normal_inverse(np.ascontiguousarray(J, dtype=float), float(singular))
    if not ok:
        lam, V = np.linalg.eigh(Jn.T @ Jn)
        with np.errstate(divide="ignore", invalid="ignore"):
            inverse = (V / lam) @ V.T
    return Jn, norms, lam, inverse


def median(v: Array) -> float:
    """The median of a short non-empty vector ``(n,)`` (numpy's ``median`` costs ~30 µs of
    set-up here)."""
    s = np.sort(v)
    n = len(s)
    return 0.5 * float(s[(n - 1) // 2] + s[n // 2])


def screen_unidentifiable(
    r: Array,
    J: Array,
    scale: Array,
    max_std: float = Rules.max_std,
    max_std_ratio: float = Rules.max_std_ratio,
    margin: float = Rules.screen_margin,
    known_noise: bool = False,
    *,
    rules: Rules | None = None,
) -> list[tuple[int, float]]:
    """Unknowns the measurements leave far beyond the pruning thresholds, found before
    any fit: their column indices and σ as tool displacement (m), worst first.

    The σ of the problem linearised at the start values — weighted residuals ``r``
    ``(m,)`` and Jacobian ``J`` ``(m, p)``, residual variance 1 for a stated noise
    (``known_noise``) or from one Gauss-Newton step, ``scale`` ``(p,)`` tool displacement
    per unit of each unknown (:meth:`~robocal.identify.problem.Problem.effect_scale`) —
    predict those of the fit.  An unknown whose σ exceeds ``margin`` times the pruning
    threshold (``max(max_std, max_std_ratio × median σ)``) would be pruned after the fit
    anyway, but could first drag the fit along a nearly flat valley (real UR10 data, plain
    DH: θ5, α5 and d5, a5 at σ of millimetres to decimetres; 16-24 evaluations instead
    of 3 on simulated DH UR10s).  Worst first, re-evaluated after each (correlated
    unknowns often become determined once their partner is fixed); borderline cases are
    left to the pruning after the fit.  A numerically singular problem is left to the
    fit and its checks.  Compiled: :func:`robocal.identify.kernels.stage.screen` (from the
    normal equations).  ``rules``: the thresholds as one value (:class:`Rules`; in place
    of ``max_std``, ``max_std_ratio`` and ``margin``).
    """
    sk = stage_kernels()

    r, J = np.asarray(r, dtype=float), np.asarray(J, dtype=float)
    p = J.shape[1]
    columns, sigmas = np.empty(p, dtype=np.intp), np.empty(p)
    G, g, rr = np.ascontiguousarray(J.T @ J), J.T @ r, float(r @ r)  # the normal equations
    if rules is None:
        rules = Rules(float(max_std), float(max_std_ratio), float(margin))
    screening = rules.screening(known_noise)
    count = sk.screen(G, g, rr, len(r), np.asarray(scale, dtype=float), screening, columns, sigmas)
    return list(zip(columns[:count].tolist(), sigmas[:count].tolist(), strict=True))


# ---------------------------------------------------------------------- uncertainty and pruning
class Covariance(NamedTuple):
    """The uncertainty of a fit (:func:`uncertainty`): σ̂² (the variance factor of the
    weighted residuals), covariance ``(p, p)`` and standard deviations ``(p,)`` of the
    unknowns (their units: m, rad), correlations ``(p, p)`` and the condition number of
    the unit-norm weighted Jacobian.  A named record; it unpacks as the 5-tuple it replaces."""

    variance: float
    covariance: Array
    std: Array
    correlation: Array
    condition: float


def uncertainty(
    r: Array, J: Array, rows: int, known_noise: bool = False, rules: Rules | None = None
) -> Covariance:
    """The :class:`Covariance` of a fit with weighted residuals ``r`` ``(m,)`` and Jacobian
    ``J`` ``(m, p)``, ``rows`` (3 or 6) rows per pose.

    The covariance is σ̂²(JᵀWJ)⁻¹ with σ̂² from :func:`residual_variance` (1 when the
    weights come from a stated noise the residuals agree with; ``rules``: its χ² test's
    significance).  Pose measurements have
    two groups of rows whose relative weight is a choice (``orientation_weight``), not a
    noise ratio: each group gets its own σ̂² (its share of the degrees of freedom) and
    the covariance is the sandwich (JᵀJ)⁻¹ Jᵀ diag(σ̂²) J (JᵀJ)⁻¹ of the weighted rows,
    which is σ̂²(JᵀJ)⁻¹ when the two agree (one pooled σ̂² overstated the σ of the
    UR10 with an optical CMM twice).  Compiled
    (:func:`robocal.identify.kernels.stage.covariance`) unless the normal matrix is nearly
    singular (eigenvalue ratio ≤ :attr:`Rules.covariance_singular`): then the condition
    number (:func:`robocal.identify.rules.condition_number`) comes from the singular values
    and the inverse is the pseudo-inverse."""
    sk = stage_kernels()

    m, p = J.shape
    rules = rules or _DEFAULT_RULES
    row_s2 = _row_variances(r, m, p, rows, known_noise, rules.significance)
    s2 = float(row_s2[0]) if m else 1.0
    uniform = rows == 3 or bool(np.all(row_s2 == s2))
    J = np.ascontiguousarray(J, dtype=float)
    cov, std, corr, cond, ok = sk.covariance(J, row_s2, uniform, float(rules.covariance_singular))
    if ok:  # cond(Jn) < 1e6: the normal matrix keeps enough digits, and gives the condition number
        return Covariance(s2, cov, std, corr, float(cond))
    Jn, norms, _, _ = normal_inverse(J)
    sv = np.linalg.svd(Jn, compute_uv=False)  # descending: λ of JnᵀJn are their squares, ascending
    cond = condition_number(np.asarray(sv[::-1] ** 2, dtype=np.float64))
    inverse = np.linalg.pinv(Jn.T @ Jn)
    if not uniform:
        inverse = inverse @ (Jn.T @ (Jn * row_s2[:, None])) @ inverse
    cov = (s2 * inverse if uniform else inverse) / np.outer(norms, norms)
    std = np.sqrt(np.clip(np.diag(cov), 0, None))
    outer = np.outer(std, std)
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = np.where(outer > 0, cov / outer, 0.0)
    return Covariance(s2, cov, std, corr, cond)


_DEFAULT_RULES = Rules()


def _row_variances(r: Array, m: int, p: int, rows: int, known_noise: bool, significance: float) -> Array:
    """``(m,)`` the variance factor of each row (:func:`residual_variance`): one for
    positions; for poses one per group (positions, orientations), each with its share of
    the degrees of freedom."""
    if rows == 3:  # positions only: one group
        return np.full(m, residual_variance(float(r @ r), m - p, known_noise, significance))
    position = np.tile(np.arange(rows) < 3, m // rows)
    row_s2 = np.empty(m)
    for group, known in ((position, known_noise), (~position, False)):
        if group.any():
            dof = group.sum() - p * group.sum() / m
            row_s2[group] = residual_variance(float(r[group] @ r[group]), dof, known, significance)
    return row_s2


def poorly_identifiable(
    std: Array, scale: Array, max_std: float, max_std_ratio: float
) -> tuple[int, float] | None:
    """The unknown to prune after a fit, ``(index, σ as tool displacement in m)``, or None.

    σ as a tool displacement (``std`` times ``scale``, both ``(p,)``) beyond the absolute
    threshold ``max_std`` and beyond ``max_std_ratio`` times the median of all unknowns'
    (noisy data makes every σ large; that is not a reason): the worst such one.  The rule
    is :func:`robocal.identify.rules.prune_candidate`, compiled (the fused kernels call
    the same)."""
    sk = stage_kernels()

    move = np.ascontiguousarray(std * scale, dtype=float)
    worst = int(sk.prune_candidate(move, float(max_std), float(max_std_ratio), 1.0))
    if worst == NO_CANDIDATE:
        return None
    return worst, float(move[worst])


def residual_variance(
    chi2: float, dof: float, known: bool, significance: float = Rules.significance
) -> float:
    """The variance factor of weighted residuals for a covariance, ``χ²/dof`` or 1.

    With weights 1/σ from a stated noise (``known``) the factor is 1 — the Cramér–Rao
    covariance — unless a χ² test rejects the stated noise at ``significance`` (either
    way): a few degrees of freedom cannot estimate it, and a model that explains the
    data leaves χ²/dof ≈ 1 anyway.  Without a stated noise it is estimated, ``χ²/dof``
    (``dof`` at least 1).
    """
    sk = stage_kernels()

    dof = max(float(dof), 1.0)
    low = high = math.nan  # no test without a stated noise (and no scipy.special)
    if known:
        bounds = chi2_bounds(np.array([dof]), significance)
        low, high = float(bounds[0][0]), float(bounds[1][0])
    return float(sk.variance_factor(float(chi2), dof, bool(known), low, high))


def chi2_bounds(dof: Array, significance: float = Rules.significance) -> tuple[Array, Array]:
    """The χ² values ``(k,)`` below and above which :func:`residual_variance` rejects a stated
    noise for ``dof`` ``(k,)`` degrees of freedom: ``P(χ² ≤ low) = P(χ² ≥ high) =
    significance`` (the compiled fit, :mod:`robocal.identify.kernels.fused`, takes them as
    tables: numba cannot call scipy.special)."""
    return Rules(significance=significance).chi2_bounds(dof)
