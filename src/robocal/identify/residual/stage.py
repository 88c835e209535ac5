"""Fitting the learned residual, and choosing it by cross-validation on the training poses.

The residual model (:class:`robocal.model.residual.JointAngleResidual`) is linear in its
coefficients ``c``: the position residual of the physical fit is ``r ≈ A(q) c`` with
``A = ∂p/∂δθ_j · [cos h q_j, sin h q_j]`` (the perturbation Jacobian times the Fourier
basis).  With the prior ``c ~ N(0, S)``, ``S = diag(a_j² w_h)``, ``w_h ∝ exp(-(h ℓ)²/2)``
normalised so that ``a_j`` is the RMS of joint j's angle error — a stationary Gaussian
process on each joint's circle — and noise ``σ²``, the posterior is Gaussian
(Bayesian linear regression) and the hyperparameters ``a_j, ℓ, σ`` maximise the
evidence (type-II maximum likelihood).  Everything is in the *whitened* coordinates
``c = S^½ v`` so that the matrix factored, ``S^½ G S^½ / σ² + I``, is positive definite
whatever the prior; the evidence's gradient is analytic (MacKay 1992: ``∂(−log E)/∂log s_k
= ½(1 − Σ_kk/s_k − μ_k²/s_k)``, ``∂(−log E)/∂log σ² = ½(N − γ − |r − Aμ|²/σ²)``).

Memory and time: the design is never held whole; ``G = AᵀA`` and ``Aᵀr`` are accumulated
over chunks of poses from per-joint blocks (:func:`~robocal.identify.residual.fit._gram`), so
memory is ``O(m²)`` plus one chunk whatever the number of poses (m = joints · 2H: 576 for 6
joints at 48 harmonics, 2.7 MB); one pass at the largest H serves every candidate H
(:func:`~robocal.identify.residual.fit._grams`).  With fewer equations than coefficients the
design ``(N, m)`` is kept instead and the evidence is maximised in its dual form (``N x N``
factorisations, :func:`~robocal.identify.residual.fit._nll_and_grad_dual`), the same function.

Model choice (:func:`cross_validate_residual`): k folds of the *training* poses; in each
fold the physical model is refitted on the other folds — as the linear response of its fit
on all poses (the Gauss-Newton step to the fold's poses; calibrating it again on every fold,
:func:`~robocal.identify.residual.cv.cross_validate_residual_refitted`, gave the same CV
errors to 4 digits on series A and the tests' robots, at 4x the time on 10,000 poses) — and each
candidate — physics only, and the residual with each number of harmonics — predicts the
held-out fold.  The residual is fitted jointly with the physical parameters (their columns
are projected out of its design; in the folds their linear response is added to the
prediction, and the final model is calibrated again with the residual known; under
compliance alone these fits take the joint loads of the geometry already calibrated on the
same poses, in one pass: :func:`warm_loads`).  A fold's
normal equations are all poses' minus its own (one pass over the poses for all folds and
numbers of harmonics, :func:`~robocal.identify.residual.cv._fold_raws`).  Each fold
maximises its own evidence from the hyperparameters found on all poses (fixing those
leaked the held-out fold into the choice, which then picked a residual for robots without
one).  The simplest candidate within three standard errors of the lowest mean
cross-validated error wins (:func:`~robocal.identify.residual.cv._one_standard_error`); once
that is a learned residual, its harmonics are those of the lowest residual candidate
(``cv.HARMONICS_SE``) on the richest physics within one standard error of it
(``cv.PHYSICS_SE``), and a residual whose CV error at the 95th percentile is above
the physics alone's is no candidate (the tail).  Held-out data never enters.  The whole
stage runs on one BLAS thread (idle OpenBLAS threads doubled its CPU time on a 2-core
machine).  A joint whose angle error cannot move the measured point (a probe on the last
joint's axis) is left out of the residual and named in the table
(:func:`observable_joints`): its coefficients would stay at their prior and cost every
evidence evaluation its share of the ``(m, m)`` factorisation.

The evidence fit is in :mod:`robocal.identify.residual.fit`, the model choice in
:mod:`robocal.identify.residual.cv`; this module is the calibration stage that runs both
(:func:`calibrate_with_residual`) and re-exports their names.
"""

from __future__ import annotations

import dataclasses
import functools
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.linalg.lapack import dpotrf, dpotri

from robocal.identify.residual.cv import (
    DEFAULT_HARMONICS,
    CVCandidate,
    CVTable,
    PhysicalFit,
    cross_validate_residual,
)
from robocal.identify.residual.cv import (
    SELECTION_SE as SELECTION_SE,
)
from robocal.identify.residual.fit import (
    CHUNK,
    Hyper,
    Index,
    fit_joint_fourier,
    layout,
    one_blas_thread_limit,
    prior,
    raw_blocks,
)
from robocal.identify.residual.fit import (
    MAX_AMPLITUDE as MAX_AMPLITUDE,
)
from robocal.identify.residual.fit import (
    apply as apply,
)
from robocal.identify.residual.fit import (
    gram_matrices as gram_matrices,
)
from robocal.identify.residual.fit import (
    gram_matrix as gram_matrix,
)
from robocal.identify.residual.fit import (
    nll_and_grad as nll_and_grad,
)
from robocal.identify.residual.fit import (
    nll_and_grad_dual as nll_and_grad_dual,
)
from robocal.identify.residual.fit import (
    residual_template as residual_template,
)
from robocal.model.residual import JointAngleResidual

__all__ = [
    "DEFAULT_HARMONICS",
    "CVCandidate",
    "CVTable",
    "Hyper",
    "calibrate_with_residual",
    "cross_validate_residual",
    "fit_joint_fourier",
]

Array = NDArray[np.float64]


MIN_CV_POSES = 20  # fewer poses than this: too few folds of useful size, physics only
#: a joint whose largest learned angle error moves the measured point by less than this share of
#: the physical fit's RMS residual is left out of the learned residual (:func:`observable_joints`)
UNOBSERVABLE = 0.01
MAX_HARMONICS = 128  # per revolution: m = joints x 2H coefficients, an (m, m) matrix to factor
_COMPLIANCE_VARIANT = "geometry + compliance"


def _physics_name(options: dict[str, Any]) -> str:
    if options.get("compliance"):
        return _COMPLIANCE_VARIANT
    effects, level = options.get("effects"), options.get("level")
    if effects not in (None, "none") or str(level) in ("3", "non-geometric"):
        return f"geometry + joint effects ({effects or 'identify'})"
    return "geometry"


def calibrate_with_residual(
    calibrate_physics: Callable[..., Any],
    model: Any,
    data: Any,
    method: str,
    options: dict[str, Any],
    kind: str = "auto",
    harmonics: int | Sequence[int] | None = None,
    folds: int = 5,
    progress: Callable[[float], None] | None = None,
) -> Any:
    """The physical calibration plus the learned residual chosen by cross-validation on
    ``data`` (see the module docstring; ``progress``: the share done, after the physical fit
    and after each variant's cross-validation, or None); returns a
    :class:`~robocal.identify.calibrate.CalibrationResult` whose ``model.residual`` is the
    residual (None when CV chose the physics alone) and whose ``diagnostics.cv`` is the table."""
    with one_blas_thread_limit():  # the whole stage: BLAS threads idling between small products cost CPU
        return _calibrate_with_residual(
            calibrate_physics, model, data, method, options, kind, harmonics, folds, progress
        )


def _calibrate_with_residual(
    calibrate_physics: Callable[..., Any],
    model: Any,
    data: Any,
    method: str,
    options: dict[str, Any],
    kind: str,
    harmonics: int | Sequence[int] | None,
    folds: int,
    progress: Callable[[float], None] | None = None,
) -> Any:
    t0 = time.perf_counter()
    grid = _harmonics_grid(harmonics, folds)
    base = calibrate_physics(model, data, method, **options)
    cv_progress = None if progress is None else (lambda f: progress(0.2 + 0.7 * f))  # the CV: 20-90 %
    if progress is not None:
        progress(0.2)
    # revolute joints only: the angle errors of a joint as a function of its own angle
    revolute = [s.is_rotation for s in model.steps if s.joint is not None]
    joints = [j for j, rot in enumerate(revolute) if rot]
    if data.n < max(MIN_CV_POSES, 2 * folds) or not joints:
        return base.with_warnings(
            f"{data.n} poses are too few to choose a learned residual by {folds}-fold cross-validation "
            f"(at least {max(MIN_CV_POSES, 2 * folds)}): the physical model alone",
            code="residual",
        )
    variants = _physics_variants(model, options, kind)
    fits = _PhysicsFits(calibrate_physics, model, data, method, variants, _physics_name(options), base)
    usable, full = fits.usable()
    joints, left_out = observable_joints(joints, next(iter(full.values()), None))
    if not joints:
        return base.with_warnings(
            "no joint's angle errors move the measured point measurably: the physical model alone",
            code="residual",
        )
    names = [model.joint_names[j] for j in joints]
    try:
        normals: dict[str, Any] = {}  # each candidate's normal equations on all poses: the final fit's
        table, hypers = cross_validate_residual(
            data.q, data.position, usable, names, joints, grid, folds, include_none=kind == "auto",
            normals=normals, progress=cv_progress,
        )  # fmt: skip
    except ValueError as err:
        return base.with_warnings(f"{err}: the physical model alone", code="residual")
    table = dataclasses.replace(table, left_out=tuple((model.joint_names[j], e) for j, e in left_out))
    chosen = next(c for c in table.candidates if c.name == table.chosen)
    fit = full[chosen.physics]
    result = fit.result
    if chosen.harmonics is not None:
        learned, _ = fit_joint_fourier(
            data.q, fit.residuals, fit.P, names, joints, chosen.harmonics, hypers[chosen.name], J=fit.J,
            gram=normals.get(chosen.name),
        )  # fmt: skip
        # the physical parameters refitted with the learned angle errors known (the joint fit's
        # exact version of what the CV did linearly)
        try:
            result = _refit_with_residual(
                calibrate_physics, dataclasses.replace(model, residual=learned), data, method,
                warm_loads(model, variants[chosen.physics], fit.result),
            )  # fmt: skip
        except (ValueError, np.linalg.LinAlgError) as err:
            return fit.result.with_warnings(
                f"the physical model with the learned residual could not be calibrated ({err}): the "
                "physical model alone",
                code="residual",
            ).with_diagnostics(cv=table.to_dict())
        e = data.position - result.predict(data.q)[:, :3, 3]
        rms_mm = float(np.sqrt(np.mean(np.sum(e**2, axis=1)))) * 1e3
        result = result.with_diagnostics(residual_rms_after_mm=rms_mm).with_records(
            physics_only=_physics_only_record(table, full, chosen)
        )
    return result.with_diagnostics(cv=table.to_dict()).replace(seconds=time.perf_counter() - t0)


def observable_joints(
    joints: Sequence[int], fit: PhysicalFit | None
) -> tuple[list[int], list[tuple[int, float]]]:
    """The joints among ``joints`` whose learned angle errors the residual models, and those
    left out with the largest position change (m) their angle error could make: a joint
    whose angle error of :data:`MAX_AMPLITUDE` (the prior's bound) moves the measured point
    at every pose by less than :data:`UNOBSERVABLE` of the physical fit's RMS residual has
    no angle error the data can see (a probe on the last joint's axis: series A's wrist 3
    moves it 0.39 mm per rad, 0.8 µm at the bound against 0.44 mm of residual).  Its
    coefficients would stay at their prior and cost every evidence evaluation a sixth of the
    coefficients (an (m, m) factorisation: 42 % of its time at six joints).  ``fit``: the
    physical fit on all poses (None: all kept)."""
    if fit is None or not len(fit.residuals):
        return list(joints), []
    lever = np.sqrt(np.max(np.sum(fit.P[:, :, list(joints), 2] ** 2, axis=1), axis=0))  # (k,) m/rad
    scale = float(np.sqrt(np.mean(np.sum(fit.residuals**2, axis=1))))
    largest = MAX_AMPLITUDE * lever
    seen = largest >= UNOBSERVABLE * scale
    kept = [j for j, ok in zip(joints, seen, strict=True) if ok]
    return kept, [(j, float(e)) for j, e, ok in zip(joints, largest, seen, strict=True) if not ok]


def _physics_only_record(table: CVTable, full: dict[str, PhysicalFit], chosen: CVCandidate) -> dict[str, Any]:
    """The best physics-only calibration of the same poses (the physics-only CV candidate with
    the lowest mean CV error, else the variant the hybrid's physics is), for the exports that
    cannot hold a learned residual (URDF, UR kinematics): its model, device frame and CV errors
    (mm) next to the hybrid's.  Stored in ``result.json`` as ``physics_only``."""
    from robocal.model.files import model_to_dict

    rows = [c for c in table.candidates if c.harmonics is None and c.physics in full]
    best = min(rows, key=lambda c: c.cv_mean) if rows else None
    fit = full[best.physics if best is not None else chosen.physics].result
    return {
        "candidate": best.name if best is not None else chosen.physics,
        "cv_mean_mm": None if best is None else best.cv_mean * 1e3,
        "cv_rms_mm": None if best is None else best.cv_rms * 1e3,
        "hybrid": chosen.name,
        "hybrid_cv_mean_mm": chosen.cv_mean * 1e3,
        "hybrid_cv_rms_mm": chosen.cv_rms * 1e3,
        "rms_after_mm": fit.rms_after * 1e3,
        "T_device_base": np.asarray(fit.T_device_base, dtype=float).tolist(),
        "compliance": {str(k): float(v) for k, v in fit.compliance.items()},
        "model": model_to_dict(dataclasses.replace(fit.model, residual=None)),
    }


def _harmonics_grid(harmonics: int | Sequence[int] | None, folds: int) -> tuple[int, ...]:
    """The numbers of harmonics to compare (default :data:`DEFAULT_HARMONICS`); bad numbers of
    harmonics or folds are refused."""
    grid = DEFAULT_HARMONICS if harmonics is None else tuple(np.atleast_1d(harmonics).astype(int).tolist())
    if not grid or min(grid) < 1 or max(grid) > MAX_HARMONICS:
        raise ValueError(f"residual_harmonics must be integers from 1 to {MAX_HARMONICS}, got {harmonics!r}")
    if not 2 <= folds <= 20:
        raise ValueError(f"cv_folds must lie between 2 and 20, got {folds}")
    return grid


def _physics_variants(model: Any, options: dict[str, Any], kind: str) -> dict[str, dict[str, Any]]:
    """The physical variants compared, by name: the one asked for, and with ``kind="auto"`` on a
    model with bodies whose options ask for no joint effects also the one with compliance."""
    variants = {_physics_name(options): options}
    asked = any(options.get(k) not in (None, False, "none") for k in ("compliance", "effects", "level"))
    if kind == "auto" and model.bodies and not asked:
        variants[_COMPLIANCE_VARIANT] = {**options, "compliance": True}
    return variants


@dataclass(frozen=True, eq=False)
class _PhysicsFits:
    """The physical variants' calibrations on subsets of the poses (``base``, the one asked for
    on all poses, is already done)."""

    calibrate_physics: Callable[..., Any]
    model: Any
    data: Any
    method: str
    variants: dict[str, dict[str, Any]]
    base_name: str
    base: Any

    def fit(self, name: str, train: Index) -> PhysicalFit:
        """Variant ``name`` calibrated on the poses ``train``, with its residuals and Jacobians."""
        data = self.data
        everything = len(train) == data.n
        if everything and name == self.base_name:
            result = self.base
        else:
            subset = data if everything else data.subset(train)
            options = warm_loads(self.model, self.variants[name], self.base)
            result = self.calibrate_physics(self.model, subset, self.method, **options)
        q = data.q[train]
        p, P, J = PhysicalFit(result, np.empty(0), np.empty(0), np.empty(0)).predict(q)
        return PhysicalFit(result, data.position[train] - p, P, J)

    def usable(self) -> tuple[dict[str, Callable[[Index], PhysicalFit]], dict[str, PhysicalFit]]:
        """``(fit functions, fits on all poses)`` of the variants that can be calibrated on all
        poses; one that cannot is left out of the choice."""
        usable: dict[str, Callable[[Index], PhysicalFit]] = {}
        full: dict[str, PhysicalFit] = {}
        for name in self.variants:
            try:  # a variant that cannot be calibrated on these poses is left out of the choice
                full[name] = self.fit(name, np.arange(self.data.n))
            except (ValueError, np.linalg.LinAlgError):
                continue
            usable[name] = _memo(functools.partial(self.fit, name), full[name], self.data.n)
        return usable, full


def _refit_with_residual(
    calibrate_physics: Callable[..., Any], model: Any, data: Any, method: str, options: dict[str, Any]
) -> Any:
    """The physical calibration of ``model`` (its learned residual known) with the joint
    uncertainty of both (:func:`_joint_uncertainty`).  A joint effect the learned angle
    errors explain as well (a wrist's compliance under its own weight is a smooth function
    of the wrist's angle: the real UR10's wrist compliances came out at -136 ± 400
    µrad/N·m) is below zero or within 3σ of it once both are fitted: it is held at its
    start value and the physics refitted (:func:`~robocal.identify.calibrate.effects_to_hold`)."""
    from robocal.identify.effects import effects_to_hold

    held = dict(options.get("hold_effects") or {})
    for _ in range(8):  # one refit settles it but for the problem's nonlinearity
        result = _joint_uncertainty(
            calibrate_physics(model, data, method, **{**options, "hold_effects": held}), data.q
        )
        effects = set(result.effect_names)
        start = {n: float(v) for n, v in zip(result.names, result.nominal, strict=True) if n in effects}
        learned = "the learned joint angle errors"
        _, verdicts = effects_to_hold(
            result.names, result.estimates, result.covariance, start, confounder=learned
        )
        if not verdicts:
            break
        held.update({v.name: v for v in verdicts})
    return result


def warm_loads(model: Any, options: dict[str, Any], fitted: Any) -> dict[str, Any]:
    """``options`` of a physical fit of ``model`` whose joint effects depend on the joint
    loads' values only (compliance: ``δθ = -c τ``; not their signs, as backlash and clearance
    tilt do), with the loads of the geometry ``fitted`` (a calibration of the same poses)
    calibrated, in one pass; other ``options`` unchanged.

    The load passes (:func:`~robocal.identify.pipeline.calibrate_physics`) recompute the
    loads with the geometry just calibrated until their *signs* stop changing: under
    compliance alone a sign flipping near zero load changes nothing but the count, and from
    the nominal geometry series A's 10,000 poses took the full three passes for the
    compliance variant and two for its refit (0.9 s of CPU), one each now.  The loads of a
    calibrated geometry are what those passes approach: on series A the CV table is the same
    to 1e-4 relative, the calibrated parameters within 0.012 σ and the held-out errors to
    1e-5; on a twin 1 mm off its nominal geometry one pass lands 0.003 σ from the passes'
    fit, one pass from the nominal loads 0.07 σ (tests/test_residual_warm_start.py)."""
    sign_free = (
        bool(options.get("compliance"))
        and options.get("effects") in (None, "none")
        and str(options.get("level")) not in ("3", "non-geometric")
        and not model.joint_effects
    )
    if not sign_free:
        return options
    values = dict(zip(fitted.model.names, np.asarray(fitted.model.values, dtype=float).tolist(), strict=True))
    geometry = dataclasses.replace(model, residual=None).with_values(
        {n: values[n] for n in model.names if n in values}
    )
    return {**options, "load_passes": 1, "load_geometry": geometry}


def _memo(fit: Callable[[Index], PhysicalFit], whole: PhysicalFit, n: int) -> Callable[[Index], PhysicalFit]:
    """``fit`` that returns ``whole`` for all ``n`` poses instead of calibrating again."""
    return lambda train: whole if len(train) == n else fit(train)


def _joint_uncertainty(result: Any, q: Array) -> Any:
    """``result`` with the covariance of its parameters and of the residual's coefficients
    from their *joint* fit (Fisher matrix of both, the residual's prior included, noise σ
    from the evidence): directions of the residual that the physical parameters can absorb
    are uncertain in both but cancel in predictions, which the cross-covariance carries.
    In whitened coordinates ``c = S^½ v`` so that the matrix inverted is well conditioned."""
    learned: JointAngleResidual = result.model.residual
    chain = result.measurement_chain
    groups, freq = layout(learned)
    theta = np.r_[
        np.log(learned.amplitudes), np.log(learned.length_scale), np.log(max(learned.noise_std, 1e-12))
    ]
    d = np.exp(0.5 * prior(theta, groups, freq))
    p, m = len(result.names), learned.size
    raw = None
    for s in range(0, len(q), CHUNK):  # the Fisher matrix over chunks of poses: O((p + m)²) memory
        qs = q[s : s + CHUNK]
        perturbations = result.joint_perturbations(qs)  # once for P and the parameters' columns
        P = chain.perturbation_jacobian(qs, "position", perturbations)
        # by joint blocks (:func:`~robocal.identify.residual.fit._raw_blocks`): 5x fewer
        # operations than the products of the whole design
        J = result.position_columns(qs, perturbations, P)
        part = raw_blocks(qs, np.zeros((len(qs), 3)), P, learned, J)
        raw = part if raw is None else raw + part
    assert raw is not None
    F = np.block([[raw.JJ, raw.JA * d], [(raw.JA * d).T, d[:, None] * raw.AA * d]])
    F[p:, p:] += learned.noise_std**2 * np.eye(m)
    scale = np.sqrt(np.maximum(np.diag(F), 1e-300))  # columns scaled: J's units differ widely
    try:
        cov = _spd_inverse(F / np.outer(scale, scale)) / np.outer(scale, scale) * learned.noise_std**2
    except np.linalg.LinAlgError:
        return result
    cov = 0.5 * (cov + cov.T)
    cov_g = cov[:p, :p]
    cov_c = d[:, None] * cov[p:, p:] * d[None, :]
    std = np.sqrt(np.maximum(np.diag(cov_g), 0.0))
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = cov_g / np.outer(std, std)
    joint = dataclasses.replace(learned, covariance=cov_c)
    return dataclasses.replace(
        result,
        model=dataclasses.replace(result.model, residual=joint),
        covariance=cov_g,
        std=std,
        correlation=corr,
        residual_cross_covariance=cov[:p, p:] * d[None, :],
    )


def _spd_inverse(F: Array) -> Array:
    """``F⁻¹`` of a symmetric positive definite ``F`` (a Fisher matrix with its prior) from its
    Cholesky factor (LAPACK's dpotrf and dpotri: half the work of the general inverse's LU,
    507 x 507: 6 -> 3 ms); the general inverse when rounding leaves ``F`` not quite positive
    definite (LinAlgError when it is singular)."""
    L, info = dpotrf(F, lower=1, clean=1)
    if info == 0:
        lower, info = dpotri(L, lower=1, overwrite_c=1)
    if info != 0:
        return np.asarray(np.linalg.inv(F), dtype=float)
    return np.tril(lower) + np.tril(lower, -1).T
