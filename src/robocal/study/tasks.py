"""The tasks of a study: simulate, calibrate and validate the robots of one chunk, one row of
``results.csv`` per robot, with either engine (``"calibrate"`` or ``"batched"``)."""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from robocal.study.config import Case, seed_sequence
from robocal.study.prepare import Prepared

if TYPE_CHECKING:
    from robocal.measure.measurements import Measurements

Array = NDArray[np.float64]

#: Columns of a fit and its held-out validation (:func:`_fill_fit`, :func:`_stats`), shared by
#: a study's results and a fleet's.
FIT_COLUMNS = (
    "rms_before_mm",
    "rms_after_mm",
    "residual_std_mm",
    "condition_number",
    "val_n",
    "val_mean_mm",
    "val_rms_mm",
    "val_p95_mm",
    "val_max_mm",
)

#: Columns of ``results.csv`` (one row per case; lengths in mm).
RESULT_COLUMNS = (
    "case",
    "robot",
    "pose_set",
    "device",
    "status",
    "message",
    "engine",
    "n_poses",
    "n_params",
    "dropped",
    "iterations",
    *FIT_COLUMNS,
    "true_rms_mm",
    "true_max_mm",
    "seconds",
)


@dataclass(frozen=True, eq=False)
class Chunk:
    """One task: some robots of one pose set and one device."""

    prepared: Prepared
    pose_set: str
    device: str
    robots: tuple[int, ...]

    def describe(self) -> str:
        lo, hi = self.robots[0], self.robots[-1]
        span = f"robot {lo}" if lo == hi else f"robots {lo}-{hi}"
        seed = self.prepared.config.seed
        return f"{span} of pose set {self.pose_set!r}, device {self.device!r} (study seed {seed})"


def empty_row(case: Case, engine: str) -> dict[str, Any]:
    row: dict[str, Any] = dict.fromkeys(RESULT_COLUMNS, "")
    row.update(case=case.key, robot=case.robot, pose_set=case.pose_set, device=case.device, engine=engine)
    return row


def error_stats(errors: Array) -> dict[str, float]:
    """Validation statistics (mm) of position errors ``(m,)`` (m), as rc.validate."""
    return {
        "val_n": len(errors),
        "val_mean_mm": float(errors.mean() * 1e3),
        "val_rms_mm": float(np.sqrt(np.mean(errors**2)) * 1e3),
        "val_p95_mm": float(np.percentile(errors, 95) * 1e3),
        "val_max_mm": float(errors.max() * 1e3),
    }


def _simulate_case(chunk: Chunk, k: int) -> tuple[Measurements, Measurements, Array]:
    """True robot, calibration data, validation data and noise-free truth of robot ``k``."""
    from robocal.measure.poses import random_poses
    from robocal.measure.simulate import VirtualRobot, simulate
    from robocal.measure.true_model import draw_true_model

    prep = chunk.prepared
    config = prep.config
    i_set = [s.name for s in config.pose_sets].index(chunk.pose_set)
    i_dev = [d.name for d in config.devices].index(chunk.device)
    errors = config.errors
    true = draw_true_model(
        prep.nominal,
        errors.tolerances or None,
        length=errors.length,
        angle=errors.angle,
        distribution=errors.distribution,
        seed=np.random.default_rng(seed_sequence(config, 0, k)),
    )
    device = prep.devices[chunk.device]
    robot = VirtualRobot(prep.nominal, true, device)
    q = prep.pose_sets[chunk.pose_set]
    if q is None:  # a new random draw for every robot
        n = config.pose_sets[i_set].n
        if n is None:  # pragma: no cover - refused when the study is prepared
            raise ValueError("a per-robot pose set needs 'n'")
        q = random_poses(prep.nominal, n, seed=np.random.default_rng(seed_sequence(config, 5, i_set, k)))
    data = simulate(robot, q, seed=np.random.default_rng(seed_sequence(config, 1, k, i_set, i_dev)))
    test = simulate(robot, prep.q_test, seed=np.random.default_rng(seed_sequence(config, 2, k, i_dev)))
    truth = device.predict(robot.T_base_tool(prep.q_test)).position
    return data, test, truth


def fill_fit(row: dict[str, Any], fit, n: int, seconds: float) -> None:
    row.update(
        status="ok" if fit.success else "not-converged",
        message="" if fit.success else fit.message,
        n_poses=n,
        n_params=len(fit.names),
        dropped=" ".join(d.name for d in fit.dropped),
        iterations=fit.iterations,
        rms_before_mm=fit.rms_before * 1e3,
        rms_after_mm=fit.rms_after * 1e3,
        residual_std_mm=fit.residual_std * 1e3,
        condition_number=fit.condition_number,
        seconds=seconds,
    )


def _error_row(case: Case, engine: str, chunk: Chunk, err: BaseException) -> dict[str, Any]:
    row = empty_row(case, engine)
    text = " ".join(f"{type(err).__name__}: {err}".split())
    row.update(
        status="error",
        message=f"{text} [input: robot {case.robot} (true-model seed [{chunk.prepared.config.seed}, 0, "
        f"{case.robot}]), pose set {case.pose_set!r}, device {case.device!r}]",
    )
    return row


def _failed_row(case: Case, engine: str, n: int, err: BaseException) -> dict[str, Any]:
    """The row of a calibration the guards refused (too few poses, rank-deficient poses, a
    diverged fit...): status ``failed`` with the guard's reason (not retried on resume)."""
    row = empty_row(case, engine)
    row.update(status="failed", message=" ".join(str(err).split()), n_poses=n)
    return row


def run_chunk(chunk: Chunk) -> list[dict[str, Any]]:
    """Simulate, calibrate and validate the robots of one chunk; one row per robot.

    A robot whose calibration the guards refuse gets a ``failed`` row with the reason;
    one whose simulation or calibration raises otherwise an ``error`` row naming its
    input; the others are unaffected.
    """
    from robocal.identify.guards import CalibrationGuardError

    prep = chunk.prepared
    rows: dict[int, dict[str, Any]] = {}
    sims: dict[int, tuple[Measurements, Measurements, Array]] = {}
    t0 = time.perf_counter()
    for k in chunk.robots:
        case = Case(k, chunk.pose_set, chunk.device)
        try:
            sims[k] = _simulate_case(chunk, k)
        except Exception as err:
            rows[k] = _error_row(case, prep.engine, chunk, err)
    t_sim = (time.perf_counter() - t0) / max(len(chunk.robots), 1)
    todo = [k for k in chunk.robots if k in sims]
    if prep.engine == "batched" and todo:
        try:
            _batched_rows(chunk, todo, sims, rows, t_sim)
            todo = []
        except Exception:
            todo = [k for k in todo if k not in rows]
    for k in todo:
        case = Case(k, chunk.pose_set, chunk.device)
        t1 = time.perf_counter()
        try:
            rows[k] = _calibrate_row(chunk, case, *sims[k], t_sim)
        except CalibrationGuardError as err:
            rows[k] = _failed_row(case, "calibrate", sims[k][0].n, err)
        except Exception as err:
            rows[k] = _error_row(case, "calibrate", chunk, err)
        rows[k]["seconds"] = t_sim + time.perf_counter() - t1
    return [rows[k] for k in chunk.robots]


def _calibrate_row(chunk: Chunk, case: Case, data, test, truth, t_sim: float) -> dict[str, Any]:
    from robocal.identify.calibrate import calibrate
    from robocal.identify.validate import validate

    prep = chunk.prepared
    result = calibrate(
        prep.nominal,
        data,
        method=prep.config.method,
        tool_guess=prep.tool_guess,
        max_std=prep.max_std,
        residual=prep.config.residual,
    )
    stats = validate(result, test)
    row = empty_row(case, "calibrate")
    fill_fit(row, result, data.n, 0.0)
    row.update(error_stats(stats.errors))
    true_err = np.linalg.norm(result.predict(prep.q_test)[:, :3, 3] - truth, axis=1)
    row.update(
        true_rms_mm=float(np.sqrt(np.mean(true_err**2)) * 1e3), true_max_mm=float(true_err.max() * 1e3)
    )
    return row


def _batched_rows(chunk: Chunk, todo: list[int], sims: dict, rows: dict, t_sim: float) -> None:
    from robocal.identify.batch import batch_positions, calibrate_batch
    from robocal.identify.guards import CalibrationGuardError

    prep = chunk.prepared
    t0 = time.perf_counter()
    by_count: dict[int, list[int]] = {}
    for k in todo:
        by_count.setdefault(sims[k][0].n, []).append(k)
    for members in by_count.values():
        results = calibrate_batch(
            prep.nominal, [sims[k][0] for k in members], tool_guess=prep.tool_guess, max_std=prep.max_std
        )
        fitted = []
        for k, r in zip(members, results, strict=True):
            if isinstance(r, CalibrationGuardError):
                rows[k] = _failed_row(Case(k, chunk.pose_set, chunk.device), "batched", sims[k][0].n, r)
            else:
                fitted.append((k, r))
        if not fitted:
            continue
        # validation: predictions of every robot at the held-out poses in one call
        values = np.stack([fit.values for _, fit in fitted])
        m = len(prep.q_test)
        pred = batch_positions(fitted[0][1].chain, values, [prep.q_test] * len(fitted)).reshape(-1, m, 3)
        for i, (k, fit) in enumerate(fitted):
            case = Case(k, chunk.pose_set, chunk.device)
            data, test, truth = sims[k]
            row = empty_row(case, "batched")
            fill_fit(row, fit, data.n, 0.0)
            row.update(error_stats(np.linalg.norm(pred[i] - test.position, axis=1)))
            true_err = np.linalg.norm(pred[i] - truth, axis=1)
            row.update(
                true_rms_mm=float(np.sqrt(np.mean(true_err**2)) * 1e3),
                true_max_mm=float(true_err.max() * 1e3),
            )
            rows[k] = row
    per_robot = (time.perf_counter() - t0) / max(len(todo), 1)
    for k in todo:
        rows[k]["seconds"] = t_sim + per_robot
