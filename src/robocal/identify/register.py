"""Calibrate once, re-register later: a calibrated robot kept frozen, the device frame
``T_device_base`` (and optionally the measured tool point) fitted again to a few poses.

The robot of a :class:`~robocal.identify.result.CalibrationResult` — its joint geometry, joint
effects and learned residual — predicts the measured point in its base frame, ``b_i``
(m).  A new placement of the device sees ``y_i = T (b_i) + e_i``; :func:`fit_frame` fits
``T`` (six parameters, the measurement chain's ``frame_*`` corrections at zero: a
translation along the base axes and a small rotation about them, applied after the
current frame) and, with ``tool=True``, the tool point on the flange (``tcp_*``), by
weighted Gauss-Newton from the closed-form rigid fit.  Each pose is weighted by the error
the calibration predicts there (its parameters' and learned residual's uncertainty, the
error it does not explain and the device's noise), so the frame's covariance
``(JᵀWJ)⁻¹`` is what the few poses leave.

Scoring is honest: :func:`score_registration` fits the frame on all but one fold of the
rows (K-fold, ``K = min(5, n)``) or on a part of them (``holdout``) and measures the error
on the rows it did not fit, next to the error expected there (the predicted scatter plus
the frame's own uncertainty).  A frame fitted and scored on the same rows looks better
than it is: by the ``3n - 6`` degrees of freedom it spent on them.

Units: SI (m, rad).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from robocal import spatial
from robocal.identify.result import CalibrationResult
from robocal.measure.measurements import Measurements
from robocal.model.flange_tool import split_tool

__all__ = [
    "FRAME_NAMES",
    "MAX_FOLDS",
    "TOOL_NAMES",
    "FrameFit",
    "FrozenRobot",
    "RegistrationScore",
    "fit_frame",
    "frozen_robot",
    "min_rows",
    "score_registration",
]

Array = NDArray[np.float64]

#: the measurement chain's device-frame corrections, in the order :class:`FrameFit` holds them
FRAME_NAMES = ("frame_x", "frame_y", "frame_z", "frame_rz", "frame_ry", "frame_rx")
#: the measured tool point on the flange (position calibrations)
TOOL_NAMES = ("tcp_x", "tcp_y", "tcp_z")
#: K of the K-fold scoring (fewer rows: one fold per row)
MAX_FOLDS = 5
#: a column-scaled Jacobian whose smallest singular value is below this fraction of its
#: largest cannot determine the frame (poses all alike, or one tool orientation with --tool)
DEGENERATE_RATIO = 1e-6


def min_rows(tool: bool) -> int:
    """The fewest position rows a registration takes: every K-fold training set keeps three
    points off one line (frame only), or enough for the tool's three more unknowns."""
    return 6 if tool else 4


@dataclass(frozen=True)
class FrozenRobot:
    """What the frozen robot predicts at ``n`` poses (base frame, m).

    Attributes:
        point: ``(n, 3)`` the measured point with the calibration's tool.
        flange_rotation: ``(n, 3, 3)`` the flange's orientation (moves the tool point).
        tool: ``(3,)`` the calibration's tool point on the flange (zeros without one).
        scatter_ms: ``(n,)`` mean square 3D error expected at each pose with the device
            frame known (m²): the robot's parameter and residual uncertainty, the error it
            does not explain and the device's noise.
    """

    point: Array
    flange_rotation: Array
    tool: Array
    scatter_ms: Array

    def subset(self, rows: NDArray[np.intp]) -> FrozenRobot:
        return FrozenRobot(self.point[rows], self.flange_rotation[rows], self.tool, self.scatter_ms[rows])

    @property
    def n(self) -> int:
        return len(self.point)


def _tool_point(result: CalibrationResult) -> Array | None:
    """The tool point (tcp_x, tcp_y, tcp_z translations at the model's end), None when the
    model ends otherwise (no measured tool, or a tool frame of a pose calibration)."""
    tail = split_tool(result.model).steps
    if [s.name for s in tail] != list(TOOL_NAMES) or any(s.motion[0] != "T" for s in tail):
        return None
    return np.array([s.value for s in tail])


def frozen_robot(result: CalibrationResult, data: Measurements, noise_ms: float | None = None) -> FrozenRobot:
    """The frozen robot's predictions at the poses of ``data``; ``noise_ms``: the device's
    mean square 3D noise per pose (default: the data's σ, else the calibration's)."""
    q = data.q
    T = result.predict(q, frame=np.eye(4))
    tool = _tool_point(result)
    R = T[:, :3, :3]  # with a pure-translation tool the flange's orientation is the tool's
    expected_ms = result.expected_position_error(q) ** 2
    if noise_ms is None:
        noise_ms = _noise_ms(result, data)
    return FrozenRobot(T[:, :3, 3], R, np.zeros(3) if tool is None else tool, expected_ms + noise_ms)


def _noise_ms(result: CalibrationResult, data: Measurements) -> float:
    """The device noise to add to the calibration's expected error (mean square, 3D, m²):
    none when the calibration's unexplained error already holds it (no stated noise)."""
    if result.fit_to_noise is None:
        return 0.0
    if data.sigma is not None:
        return float(np.mean(np.sum(data.sigma**2, axis=1)))
    return float(result.fit_to_noise.noise_rms**2)


@dataclass(frozen=True)
class FrameFit:
    """A device frame (and tool point) fitted to poses of a frozen robot.

    Attributes:
        T_device_base: ``(4, 4)`` the fitted frame.
        tool: ``(3,)`` the tool point on the flange (m): fitted with ``tool=True``, else
            the calibration's.
        tool_fitted: whether the tool point was fitted.
        covariance: ``(k, k)`` of the fitted parameters (:data:`FRAME_NAMES` and, when the
            tool was fitted, :data:`TOOL_NAMES`), m and rad, from the predicted scatter.
        variance_factor: χ² of the weighted residuals per degree of freedom (≈ 1 when the
            poses scatter as the calibration predicts; nan without degrees of freedom).
            Above 1 the poses scatter more than predicted (a robot that changed since, poses
            unlike the calibration's): the expectation is scaled up by it (:attr:`scale`).
        residuals: ``(n, 3)`` predicted minus measured at the fitted poses (device frame, m).
    """

    T_device_base: Array
    tool: Array
    tool_fitted: bool
    covariance: Array
    variance_factor: float
    residuals: Array = field(repr=False)

    @property
    def names(self) -> tuple[str, ...]:
        return FRAME_NAMES + (TOOL_NAMES if self.tool_fitted else ())

    @property
    def scale(self) -> float:
        """The factor on the predicted variances: the variance factor where the poses
        scatter more than predicted (never below 1: a few poses that happen to fit well do
        not make the calibration's own prediction smaller)."""
        return max(1.0, self.variance_factor) if math.isfinite(self.variance_factor) else 1.0

    @property
    def scaled_covariance(self) -> Array:
        """:attr:`covariance` times :attr:`scale` (m, rad)."""
        return self.covariance * self.scale

    def predict(self, robot: FrozenRobot) -> Array:
        """``(n, 3)`` the measured point predicted in the device frame (m)."""
        return _points(robot, self.tool) @ self.T_device_base[:3, :3].T + self.T_device_base[:3, 3]

    def frame_ms(self, robot: FrozenRobot) -> Array:
        """``(n,)`` mean square 3D error (m²) the fitted parameters' uncertainty adds at the poses."""
        J = _jacobian(robot, self.T_device_base, self.tool, self.tool_fitted)
        return np.einsum("nik,kl,nil->n", J, self.scaled_covariance, J)

    def expected_ms(self, robot: FrozenRobot) -> Array:
        """``(n,)`` mean square 3D error (m²) expected at poses it was not fitted to: the
        predicted scatter (times :attr:`scale`) and the fitted parameters' uncertainty."""
        return self.scale * robot.scatter_ms + self.frame_ms(robot)


def _points(robot: FrozenRobot, tool: Array) -> Array:
    """``(n, 3)`` base-frame points with the tool point ``tool`` instead of the calibration's."""
    return robot.point + robot.flange_rotation @ (tool - robot.tool)


def _jacobian(robot: FrozenRobot, T: Array, tool: Array, tool_fitted: bool) -> Array:
    """``(n, 3, k)`` derivatives of the device-frame point wrt the frame corrections (x, y,
    z along the base axes; rz, ry, rx about them, applied after ``T``) and the tool point."""
    R = T[:3, :3]
    b = _points(robot, tool)
    translation = np.broadcast_to(R, (robot.n, 3, 3))
    # a small rotation ω (base frame) moves b by ω × b = -[b]× ω; columns ordered rz, ry, rx
    skew = np.zeros((robot.n, 3, 3))
    skew[:, 0, 1], skew[:, 0, 2], skew[:, 1, 2] = -b[:, 2], b[:, 1], -b[:, 0]
    skew -= np.swapaxes(skew, 1, 2)
    rotation = -(R @ skew)[:, :, ::-1]
    blocks = [translation, rotation] + ([R @ robot.flange_rotation] if tool_fitted else [])
    return np.concatenate(blocks, axis=2)


def _apply(T: Array, step: Array) -> Array:
    """``T`` followed by the frame correction ``step`` (x, y, z, rz, ry, rx)."""
    correction = spatial.homogeneous(spatial.rotvec_to_matrix(step[5:2:-1]), step[:3])
    return T @ correction


def fit_frame(robot: FrozenRobot, measured: Array, tool: bool = False, max_iterations: int = 20) -> FrameFit:
    """Fit the device frame (and the tool point with ``tool``) to the measured points
    ``(n, 3)`` (device frame, m) of the frozen robot's poses.

    Raises:
        ValueError: too few poses, or poses that cannot determine the frame (or the tool).
    """
    k = 9 if tool else 6
    if robot.n < 3 or 3 * robot.n < k:
        raise ValueError(
            f"a device frame{' and tool' if tool else ''} needs at least {math.ceil(k / 3)} "
            f"poses (3 points off one line), got {robot.n}"
        )
    w = 3.0 / np.maximum(robot.scatter_ms, 1e-18)  # 1/σ² per axis
    try:
        T = spatial.fit_rigid_transform(robot.point, measured, weights=w)
    except ValueError as err:
        raise ValueError(f"degenerate poses: they cannot determine a device frame ({err})") from None
    p = robot.tool.copy()
    for _ in range(max_iterations):
        J, r = _weighted_system(robot, measured, T, p, tool, w)
        step = np.asarray(-np.linalg.lstsq(J, r, rcond=None)[0], dtype=float)
        T, p = _apply(T, step[:6]), p + (step[6:] if tool else 0.0)
        if np.max(np.abs(step)) < 1e-12:
            break
    J, r = _weighted_system(robot, measured, T, p, tool, w)
    _check_rank(J, tool)
    dof = 3 * robot.n - k
    return FrameFit(
        T_device_base=T,
        tool=p,
        tool_fitted=tool,
        covariance=np.asarray(np.linalg.inv(J.T @ J), dtype=float),
        variance_factor=float(r @ r / dof) if dof > 0 else math.nan,
        residuals=r.reshape(-1, 3) / np.sqrt(w)[:, None],
    )


def _weighted_system(robot, measured, T, p, tool, w) -> tuple[Array, Array]:
    """The weighted Jacobian ``(3n, k)`` and residuals ``(3n,)`` at ``T``, ``p``."""
    J = _jacobian(robot, T, p, tool)
    r = _points(robot, p) @ T[:3, :3].T + T[:3, 3] - measured
    s = np.sqrt(w)[:, None]
    return (J * s[:, :, None]).reshape(-1, J.shape[2]), (r * s).reshape(-1)


def _check_rank(J: Array, tool: bool) -> None:
    norms = np.linalg.norm(J, axis=0)
    sv = np.linalg.svd(J / np.where(norms > 0, norms, 1.0), compute_uv=False)
    if norms.min() == 0 or sv[-1] < DEGENERATE_RATIO * sv[0]:
        what = "the device frame and the tool point" if tool else "the device frame"
        hint = " (--tool needs poses with different tool orientations)" if tool else ""
        raise ValueError(
            f"degenerate poses: they cannot determine {what}{hint}; measure poses spread over the workspace"
        )


@dataclass(frozen=True)
class RegistrationScore:
    """Errors of a re-registered frame on rows it was not fitted to.

    Attributes:
        scoring: ``"5-fold"`` (K-fold over the rows) or ``"holdout"``.
        rows: ``(m,)`` indices of the scored rows (all rows for K-fold).
        error_vectors: ``(m, 3)`` predicted minus measured (device frame, m).
        expected_ms: ``(m,)`` mean square 3D error expected at each (m²): the predicted
            scatter plus the uncertainty of the frame fitted without the row.
        frame_ms: ``(m,)`` the part of ``expected_ms`` from that frame's uncertainty.
        variance_factor: median over the fits of their :attr:`FrameFit.variance_factor`.
    """

    scoring: str
    rows: NDArray[np.intp]
    error_vectors: Array = field(repr=False)
    expected_ms: Array = field(repr=False)
    frame_ms: Array = field(repr=False)
    variance_factor: float = math.nan

    @property
    def errors(self) -> Array:
        return np.linalg.norm(self.error_vectors, axis=1)

    @property
    def rms(self) -> float:
        return float(np.sqrt(np.mean(self.errors**2)))

    @property
    def expected_rms(self) -> float:
        return float(np.sqrt(np.mean(self.expected_ms)))

    @property
    def ratio(self) -> float:
        """Expected / measured RMS (≈ 1 for an honest prediction)."""
        return self.expected_rms / self.rms if self.rms > 0 else math.inf

    def to_dict(self) -> dict[str, Any]:
        """The figures in mm (``result.json``'s ``validation`` of a registered calibration)."""
        e = self.errors
        return {
            "scoring": self.scoring,
            "n": len(e),
            "mean_mm": float(e.mean()) * 1e3,
            "rms_mm": self.rms * 1e3,
            "p95_mm": float(np.percentile(e, 95)) * 1e3,
            "max_mm": float(e.max()) * 1e3,
            "expected_rms_mm": self.expected_rms * 1e3,
            "frame_rms_mm": float(np.sqrt(np.mean(self.frame_ms))) * 1e3,
            "expected_over_measured": self.ratio,
            "variance_factor": self.variance_factor,
            "frame": "registered",
        }


def _folds(n: int, holdout: float | None, seed: int | None) -> list[NDArray[np.intp]]:
    """The rows each fit leaves out: K folds (K = min(5, n)) or one held-out part."""
    order = np.random.default_rng(seed).permutation(n)
    if holdout is None:
        return list(np.array_split(order, min(MAX_FOLDS, n)))
    if not 0.0 < holdout < 1.0:
        raise ValueError(f"the held-out fraction must be between 0 and 1, got {holdout:g}")
    m = round(holdout * n)
    return [np.sort(order[:m])]


def score_registration(
    robot: FrozenRobot,
    measured: Array,
    tool: bool = False,
    holdout: float | None = None,
    seed: int | None = 0,
) -> RegistrationScore:
    """Fit the frame on part of the rows, score it on the others (K-fold over all rows,
    ``K = min(5, n)``, or one held-out ``holdout`` fraction).

    Raises:
        ValueError: too few rows for a fit without the scored ones, or degenerate poses.
    """
    n = robot.n
    need = min_rows(tool)
    if n < need:
        raise ValueError(
            f"{n} position rows: re-registering the device frame{' and the tool' if tool else ''} needs "
            f"at least {need}, to score it on rows it was not fitted to (a frame needs 3 points)"
        )
    folds = _folds(n, holdout, seed)
    if holdout is not None and not 1 <= len(folds[0]) <= n - need + 1:
        raise ValueError(
            f"--holdout {holdout:g} of {n} rows leaves {len(folds[0])} to score and "
            f"{n - len(folds[0])} to fit; the fit needs at least {need - 1}"
        )
    vectors, expected, frame, factors = [], [], [], []
    for fold in folds:
        train = np.setdiff1d(np.arange(n), fold)
        fit = fit_frame(robot.subset(train), measured[train], tool)
        held = robot.subset(fold)
        vectors.append(fit.predict(held) - measured[fold])
        frame.append(fit.frame_ms(held))
        expected.append(fit.expected_ms(held))
        factors.append(fit.variance_factor)
    rows = np.concatenate(folds)
    order = np.argsort(rows)
    return RegistrationScore(
        scoring=f"{len(folds)}-fold" if holdout is None else "holdout",
        rows=rows[order],
        error_vectors=np.concatenate(vectors)[order],
        expected_ms=np.concatenate(expected)[order],
        frame_ms=np.concatenate(frame)[order],
        variance_factor=float(np.nanmedian(factors)) if np.isfinite(factors).any() else math.nan,
    )


# ------------------------------------------------------------------ the registered calibration
def check_registrable(result: CalibrationResult, data: Measurements, tool: bool) -> None:
    """Refuse (ValueError) what cannot be re-registered: no measured positions, another
    robot's joints, a result without its measurement chain, --tool without a tool point."""
    if data.position is None:
        raise ValueError("the data has no measured positions (columns x, y, z) to register the frame with")
    if data.dof != result.model.dof:
        raise ValueError(
            f"the data has {data.dof} joint columns but the calibration's robot "
            f"{result.model.name!r} has {result.model.dof} joints: another robot"
        )
    chain = result.measurement_chain
    if chain is None or not set(FRAME_NAMES) <= set(chain.names) or not set(FRAME_NAMES) <= set(result.names):
        raise ValueError(
            "the calibration holds no fitted device frame (saved by an older robocal?): calibrate again"
        )
    if tool and _tool_point(result) is None:
        raise ValueError("--tool: the calibration has no measured tool point (tcp_x, tcp_y, tcp_z) to refit")


def registered_result(
    source: CalibrationResult,
    data: Measurements,
    fit: FrameFit,
    score: RegistrationScore,
    registered_from: dict[str, Any],
) -> CalibrationResult:
    """``source`` with the re-registered device frame (and tool point): its measurement
    chain's fixed frame set to the new one (corrections ``frame_*`` at zero), their
    covariance the fit's (no correlation with the frozen robot's parameters left), the
    held-out figures of ``score`` as its validation, and ``registered_from`` recorded; the
    stored physics-only fit (``physics_only``, for the exports) gets its own frame fitted to
    the same rows of ``data``."""
    chain = source.measurement_chain
    assert chain is not None  # check_registrable
    values = dict(
        zip(
            ("frame0_x", "frame0_y", "frame0_z", "frame0_rz", "frame0_ry", "frame0_rx"),
            [*fit.T_device_base[:3, 3].tolist(), *spatial.zyx_angles(fit.T_device_base[:3, :3])],
            strict=True,
        )
    )
    values |= dict.fromkeys(FRAME_NAMES, 0.0)
    tool_values = dict(zip(TOOL_NAMES, fit.tool.tolist(), strict=True)) if fit.tool_fitted else {}
    new = source.replace(
        T_device_base=fit.T_device_base,
        measurement_chain=chain.with_values(values | tool_values),
        model=source.model.with_values(tool_values) if tool_values else source.model,
        validation=score.to_dict(),
        run_id=None,
    )
    new = _with_fit_covariance(new, fit)
    records = dict(source.records) | {"registered_from": registered_from}
    if isinstance(records.get("physics_only"), dict):  # what the exports carry: its own frame, refitted
        records["physics_only"] = _physics_only_refit(source, records["physics_only"], data, fit.tool_fitted)
    if fit.tool_fitted:
        from robocal.identify.measured_tool import measured_tool

        tool_record = measured_tool(new)
        if tool_record is not None:
            records["measured_tool"] = tool_record.to_dict()
    return new.replace(records=records)


def _with_fit_covariance(result: CalibrationResult, fit: FrameFit) -> CalibrationResult:
    """The fitted parameters' estimates, standard deviations and covariance block replaced
    by the fit's (their cross terms with the frozen robot's parameters and residual zero)."""
    index = [result.names.index(n) for n in fit.names]
    estimates = np.array(result.estimates, dtype=float)
    estimates[index] = np.r_[np.zeros(6), fit.tool] if fit.tool_fitted else 0.0
    cov = np.array(result.covariance, dtype=float)
    cov[index, :] = 0.0
    cov[:, index] = 0.0
    cov[np.ix_(index, index)] = fit.scaled_covariance
    std = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    with np.errstate(invalid="ignore", divide="ignore"):
        correlation = cov / np.outer(std, std)
    cross = result.residual_cross_covariance
    if cross is not None:
        cross = np.array(cross, dtype=float)
        cross[index] = 0.0
    return result.replace(
        estimates=estimates, covariance=cov, std=std, correlation=correlation, residual_cross_covariance=cross
    )


def _physics_only_refit(
    source: CalibrationResult, record: dict[str, Any], data: Measurements, tool: bool
) -> dict[str, Any]:
    """The physics-only record with its device frame (and tool point) fitted to ``data``
    (equal weights: its own uncertainty is not stored)."""
    from robocal.model.files import model_from_dict, model_to_dict

    model = model_from_dict(record["model"], origin="result.json: physics_only.model")
    compliance = {str(k): float(v) for k, v in dict(record.get("compliance") or {}).items()}
    physics = source.replace(model=model, compliance=compliance, residual_cross_covariance=None)
    T = physics.predict(data.q, frame=np.eye(4))
    point = _tool_point(physics)
    robot = FrozenRobot(T[:, :3, 3], T[:, :3, :3], np.zeros(3) if point is None else point, np.ones(data.n))
    position = np.asarray(data.position)
    fit = fit_frame(robot, position, tool and point is not None)
    out = dict(record) | {"T_device_base": fit.T_device_base.tolist()}
    if fit.tool_fitted:
        out["model"] = model_to_dict(model.with_values(dict(zip(TOOL_NAMES, fit.tool.tolist(), strict=True))))
    return out
