"""Monte Carlo studies and fleet calibrations, on one process or on Dask.

A **study** answers "which pose set, which device, how good will it be?" before anyone
measures: N virtual robots drawn from tolerances (:func:`robocal.measure.draw_true_model`)
× pose-set choices × device-noise choices, each one simulated
(:class:`~robocal.measure.VirtualRobot`, :func:`~robocal.measure.simulate`),
calibrated and validated on held-out poses.  One row per case goes to
``DIR/results.csv`` the moment the case is finished, so a crashed task, a killed
worker or a killed study loses nothing that was finished: running the same study
again resumes from the table.  ``robocal study config.yaml --out DIR`` (config format:
:class:`StudyConfig`, example ``examples/study_ur10.yaml``).

A **fleet** run calibrates one robot per measurement file of a folder
(``robocal fleet ROBOT DIR``): ``OUT/<file stem>/`` gets the calibration
(``model.yaml``, ``result.json``) and ``OUT/fleet.csv`` one row per file, also
resumable.

Where the work runs (both): ``workers=0`` in this process; ``workers=None`` (default)
a Dask ``LocalCluster`` with one single-threaded worker process per core; ``workers=N``
N processes; ``scheduler="tcp://host:8786"`` an existing Dask cluster (whose workers
need robocal installed and, for fleets, the files on a shared path).  Results are
gathered by the client as they complete and written there, by one writer.

Two calibration engines compute the same thing:

* ``"calibrate"``: :func:`robocal.calibrate` then :func:`robocal.validate` per case,
  any method and device;
* ``"batched"`` (:func:`robocal.identify.batch.calibrate_batch`, default when it
  applies: position measurements, ``method: lm``, ``residual: none``): the chunk's
  robots are calibrated together, with ``rc.calibrate``'s own stage functions, solver
  and guards (:mod:`robocal.identify.stages`) but their chains evaluated in one batched
  call; estimates agree with ``rc.calibrate`` to round-off (tests/test_study.py).

A case the calibration's guards refuse (too few poses for the unknowns, poses that
leave parameters undetermined, a diverged fit) gets ``status=failed`` with the reason
in ``message``, with either engine; it is not recomputed on resume.

Units: SI inside; the tables use mm (columns ending ``_mm``) and seconds.
"""

from __future__ import annotations

import csv
import hashlib
import io
import math
import os
import time
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np
import yaml
from numpy.typing import NDArray
from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator, model_validator

from robocal import csvfile
from robocal.model.chain import Model
from robocal.model.files import (
    Count,
    Number,
    atomic_write_text,
    csv_text,
    csv_untext,
    format_validation_error,
    strict_json,
)
from robocal.outdir import new_run_id, write_together

__all__ = [
    "FLEET_COLUMNS",
    "RESULT_COLUMNS",
    "Case",
    "DeviceSpec",
    "FleetRun",
    "PoseSetSpec",
    "StudyConfig",
    "StudyError",
    "StudyRun",
    "load_study_config",
    "local_cluster",
    "read_study_summary",
    "run_fleet",
    "run_study",
    "study_cases",
]

Array = NDArray[np.float64]

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
    "rms_before_mm",
    "rms_after_mm",
    "residual_std_mm",
    "condition_number",
    "val_n",
    "val_mean_mm",
    "val_rms_mm",
    "val_p95_mm",
    "val_max_mm",
    "true_rms_mm",
    "true_max_mm",
    "seconds",
)

#: Columns of ``fleet.csv``.
FLEET_COLUMNS = (
    "file",
    "sha256",
    "status",
    "message",
    "n_poses",
    "n_params",
    "rms_before_mm",
    "rms_after_mm",
    "residual_std_mm",
    "condition_number",
    "val_n",
    "val_mean_mm",
    "val_rms_mm",
    "val_p95_mm",
    "val_max_mm",
    "seconds",
    "result_dir",
)


def __getattr__(name: str) -> Any:
    """``robocal.study.calibrate_batch`` and ``BatchFit``: the batched engine, now in
    :mod:`robocal.identify.batch` (imported when first used)."""
    if name in ("calibrate_batch", "BatchFit"):
        from robocal.identify import batch

        return getattr(batch, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


class StudyError(ValueError):
    """A study or fleet cannot run; the message names the file, field or directory."""


# =============================================================== configuration
_Config = ConfigDict(extra="forbid", allow_inf_nan=False, str_strip_whitespace=True)
Quantity = Number | str


class _Errors(BaseModel):
    model_config = _Config
    length: Quantity = "0.5mm"
    angle: Quantity = "0.05deg"
    distribution: Literal["uniform", "normal"] = "uniform"
    tolerances: dict[str, Quantity] = {}


class PoseSetSpec(BaseModel):
    """One pose-set choice: ``random`` (``n`` random poses away from singularities),
    ``optimal`` (``n`` poses chosen from a random ``pool`` maximising ``index``) or
    ``file`` (a poses CSV, ``path`` relative to the config file)."""

    model_config = _Config
    name: str = Field(min_length=1, pattern=r"^[A-Za-z0-9_.+-]+$")
    kind: Literal["random", "optimal", "file"] = "random"
    n: Count | None = Field(default=None, ge=1, le=100_000)
    seed: Count | None = None
    pool: Count = Field(default=1000, ge=1, le=1_000_000)
    index: Literal["O1", "O2", "O3", "O4", "O5"] = "O1"
    path: str | None = None
    per_robot: bool = False  # random: a new draw for every robot


class DeviceSpec(BaseModel):
    """One device choice: a device kind of :mod:`robocal.measure.devices` with its noise
    (a length such as ``0.02mm``; the device's main noise figure) and further fields."""

    model_config = _Config
    name: str = Field(min_length=1, pattern=r"^[A-Za-z0-9_.+-]+$")
    kind: str = "laser-tracker"
    noise: Quantity | None = None
    options: dict[str, Any] = {}


class _Validation(BaseModel):
    model_config = _Config
    n: Count = Field(default=200, ge=1, le=1_000_000)
    seed: Count | None = None


class _Dask(BaseModel):
    """Where a study runs, unless the call (``--scheduler``/``--workers``) says otherwise."""

    model_config = _Config
    scheduler: str | None = Field(default=None, min_length=1)
    workers: Count | None = Field(default=None, ge=0, le=4096)  # 0: this process

    @field_validator("scheduler")
    @classmethod
    def _address(cls, value: str | None) -> str | None:
        import re

        if value is not None and not re.fullmatch(r"[a-z][a-z0-9+.-]*://\S+|[^\s:/]+:\d+", value):
            raise ValueError(f"{value!r} is not a Dask scheduler address (e.g. tcp://host:8786)")
        return value


#: Calibrations a study may have (robots x pose sets x devices): a million take about a
#: quarter of an hour with the batched engine and its table about 0.3 GB
MAX_STUDY_CASES = 1_000_000


class StudyConfig(BaseModel):
    """A Monte Carlo study (YAML file; lengths as text with a unit or SI numbers).

    ::

        robocal_study: 1
        name: ur10_1000
        robot: ur10                 # catalog name or model file (relative to this file), or
        # geometry: ../examples/geometry/ur10.yaml   # joint geometry: the complete model built from it
        robots: 1000                # virtual robots drawn from the tolerances
        seed: 2024                  # everything below is reproducible from it
        errors: {length: 0.5mm, angle: 0.05deg, distribution: uniform}
        tool: [0, 0, 100]           # mm: measured target point in the flange frame
        pose_sets: [{name: random50, kind: random, n: 50}]
        devices: [{name: tracker-20um, kind: laser-tracker, noise: 0.02mm}]
        validation: {n: 200}        # held-out poses per robot
        method: lm                  # rc.calibrate method
        engine: auto                # auto | batched | calibrate
        residual: none              # none | auto | joint_fourier (rc.calibrate's; not none: engine calibrate)
        chunk: 50                   # robots per task
        dask: {scheduler: "tcp://host:8786"}   # an existing Dask cluster (or {workers: 2}:
                                    # a local one); default a local cluster, one worker per core
    """

    model_config = _Config
    robocal_study: Literal[1] = 1
    name: str = Field(default="study", min_length=1)
    robot: str | None = Field(default=None, min_length=1)
    geometry: str | None = Field(default=None, min_length=1)
    robots: Count = Field(ge=1, le=1_000_000)
    seed: Count = 0
    errors: _Errors = _Errors()
    tool: tuple[Number, Number, Number] = (0.0, 0.0, 0.0)
    pose_sets: list[PoseSetSpec] = Field(min_length=1)
    devices: list[DeviceSpec] = Field(
        default_factory=lambda: [DeviceSpec(name="laser-tracker")], min_length=1
    )
    validation: _Validation = _Validation()
    method: Literal["lm", "pinv", "bounded", "influence"] = "lm"
    max_std: Quantity = "0.5mm"
    engine: Literal["auto", "batched", "calibrate"] = "auto"
    residual: Literal["none", "auto", "joint_fourier"] = "none"
    chunk: Count = Field(default=50, ge=1, le=100_000)
    dask: _Dask = _Dask()

    @model_validator(mode="after")
    def _size(self) -> StudyConfig:
        cases = self.robots * len(self.pose_sets) * len(self.devices)
        if cases > MAX_STUDY_CASES:
            raise ValueError(
                f"robots x pose_sets x devices = {cases} calibrations; a study may have up to "
                f"{MAX_STUDY_CASES} (split it into several studies)"
            )
        return self

    @model_validator(mode="after")
    def _one_robot(self) -> StudyConfig:
        if (self.robot is None) == (self.geometry is None):
            raise ValueError("give exactly one of 'robot' (catalog name or model file) and 'geometry'")
        return self

    @model_validator(mode="after")
    def _quantities(self) -> StudyConfig:
        from robocal.measure.simulate import parse_quantity

        checks = [
            ("errors.length", self.errors.length, "length"),
            ("errors.angle", self.errors.angle, "angle"),
        ]
        checks += [("max_std", self.max_std, "length")]
        checks += [(f"devices[{i}].noise", d.noise, "length") for i, d in enumerate(self.devices) if d.noise]
        for where, value, kind in checks:
            try:
                if parse_quantity(value, kind) < 0:
                    raise ValueError(f"{value!r} is negative")
            except ValueError as err:
                raise ValueError(f"{where}: {err}") from None
        return self

    @field_validator("pose_sets", "devices")
    @classmethod
    def _unique_names(cls, items: list) -> list:
        names = [i.name for i in items]
        twice = sorted({n for n in names if names.count(n) > 1})
        if twice:
            raise ValueError(f"names must be unique, {', '.join(twice)} used twice")
        return items


def load_study_config(path: str | os.PathLike[str]) -> StudyConfig:
    """Read and validate a study YAML file.

    Raises:
        StudyError: naming the file and the offending field.
        FileNotFoundError: when the file does not exist.
    """
    from robocal.model.files import read_yaml

    path = Path(path)
    data = read_yaml(path, "study", StudyError)
    if not isinstance(data, dict):
        raise StudyError(f"{path}: a study file must be a mapping, got {type(data).__name__}")
    try:
        config = StudyConfig.model_validate(data)
    except ValidationError as err:
        raise StudyError(f"{path}: {format_validation_error(err)}") from None
    # paths relative to the config file
    base = path.parent
    robot, geometry = config.robot, config.geometry
    if robot is not None and robot.endswith((".yaml", ".yml")) and not Path(robot).is_absolute():
        robot = str((base / robot).resolve())
    if geometry is not None and not Path(geometry).is_absolute():
        geometry = str((base / geometry).resolve())
    sets = [
        s.model_copy(update={"path": str((base / s.path).resolve())})
        if s.path is not None and not Path(s.path).is_absolute()
        else s
        for s in config.pose_sets
    ]
    return config.model_copy(update={"robot": robot, "geometry": geometry, "pose_sets": sets})


# =============================================================== the cases
@dataclass(frozen=True)
class Case:
    """One virtual robot, pose set and device: a row of the results table."""

    robot: int
    pose_set: str
    device: str

    @property
    def key(self) -> str:
        return f"r{self.robot:07d}/{self.pose_set}/{self.device}"


def study_cases(config: StudyConfig) -> list[Case]:
    """Every case of a study, in the order they are computed (pose set, device, robot)."""
    return [
        Case(k, s.name, d.name)
        for s in config.pose_sets
        for d in config.devices
        for k in range(config.robots)
    ]


def _seed(config: StudyConfig, *parts: int) -> np.random.SeedSequence:
    return np.random.SeedSequence([int(config.seed) & 0xFFFFFFFF, *parts])


def _quantity(value: Quantity, kind: Literal["length", "angle"], where: str) -> float:
    from robocal.measure.simulate import parse_quantity

    try:
        return parse_quantity(value, kind)
    except ValueError as err:
        raise StudyError(f"{where}: {err}") from None


def _resolve_model(name_or_path: str) -> Model:
    """The study's robot (robocal.model.catalog.find_model); its error as a StudyError."""
    from robocal.model.catalog import find_model
    from robocal.model.files import ModelFileError

    try:
        return find_model(name_or_path)
    except ModelFileError as err:
        raise StudyError(str(err)) from None


def _make_device(spec: DeviceSpec, p_tool_target: Array, index: int):
    from robocal.measure.devices import DEVICES, make_device

    where = f"devices[{index}] ({spec.name})"
    if spec.kind not in DEVICES:
        raise StudyError(f"{where}: unknown device kind {spec.kind!r}; known: {', '.join(DEVICES)}")
    options = dict(spec.options)
    options.setdefault("p_tool_target", p_tool_target)
    try:
        device = make_device(spec.kind, **options)
        if spec.noise is not None:
            device = device.with_noise(_quantity(spec.noise, "length", where + ".noise"))
    except (TypeError, ValueError, NotImplementedError) as err:
        raise StudyError(f"{where}: {err}") from None
    return device


def _pose_set(config: StudyConfig, spec: PoseSetSpec, index: int, model: Model) -> Array:
    """``(n, dof)`` joint values of a shared pose set (per-robot draws are made in the tasks)."""
    from robocal.measure.poses import random_poses, read_poses

    where = f"pose_sets[{index}] ({spec.name})"
    seed = np.random.default_rng(_seed(config, 4, index) if spec.seed is None else spec.seed)
    try:
        if spec.kind == "file":
            if spec.path is None:
                raise StudyError(f"{where}: kind 'file' needs 'path'")
            return read_poses(spec.path, model)
        if spec.n is None:
            raise StudyError(f"{where}: kind {spec.kind!r} needs 'n' (number of poses)")
        if spec.kind == "random":
            return random_poses(model, spec.n, seed=seed)
        from robocal.identify.observability import select_poses

        pool = random_poses(model, max(spec.pool, spec.n), seed=seed)
        chosen = select_poses(model, pool, spec.n, index=spec.index)
        return pool[np.asarray(chosen.indices)]
    except StudyError:
        raise
    except (ValueError, OSError) as err:
        raise StudyError(f"{where}: {err}") from None


@dataclass(frozen=True, eq=False)
class _Prepared:
    """Everything a task needs, computed once by the client (small, picklable)."""

    config: StudyConfig
    nominal: Model
    devices: dict[str, Any]
    pose_sets: dict[str, Array | None]  # None: drawn per robot
    q_test: Array
    tool_guess: Array
    engine: str
    max_std: float


def _built_model(path: str, measure: str) -> Model:
    from robocal.model.builder import GeometryError, load_geometry

    try:
        return load_geometry(path).build(measure).model
    except FileNotFoundError:
        raise StudyError(f"geometry file {path} does not exist") from None
    except (GeometryError, ValueError) as err:
        raise StudyError(f"geometry: {err}") from None


def _prepare(config: StudyConfig) -> _Prepared:
    tool = np.asarray(config.tool, dtype=float) * 1e-3
    devices = {d.name: _make_device(d, tool, i) for i, d in enumerate(config.devices)}
    if config.geometry is not None:
        measure = "position" if all(d.measures == "position" for d in devices.values()) else "pose"
        nominal = _built_model(config.geometry, measure)
    else:
        nominal = _resolve_model(config.robot)
    sets: dict[str, Array | None] = {}
    for i, s in enumerate(config.pose_sets):
        if s.per_robot and s.kind != "random":
            raise StudyError(f"pose_sets[{i}] ({s.name}): per_robot draws need kind 'random'")
        sets[s.name] = None if s.per_robot else _pose_set(config, s, i, nominal)
    from robocal.measure.poses import random_poses

    seed = config.validation.seed
    q_test = random_poses(
        nominal, config.validation.n, seed=np.random.default_rng(_seed(config, 3) if seed is None else seed)
    )
    _quantity(config.errors.length, "length", "errors.length")
    _quantity(config.errors.angle, "angle", "errors.angle")
    for name in config.errors.tolerances:
        if name not in nominal.names:
            raise StudyError(f"errors.tolerances: model {nominal.name!r} has no parameter {name!r}")
    batched_ok = (
        config.method == "lm"
        and config.residual == "none"  # the batched engine fits the physical model only
        and all(d.measures == "position" for d in devices.values())
    )
    engine = config.engine
    if engine == "auto":
        engine = "batched" if batched_ok else "calibrate"
    elif engine == "batched" and not batched_ok:
        raise StudyError(
            "engine 'batched' needs method 'lm', residual 'none' and position-measuring devices "
            "(laser-tracker); use engine 'calibrate' or 'auto'"
        )
    return _Prepared(
        config=config,
        nominal=nominal,
        devices=devices,
        pose_sets=sets,
        q_test=q_test,
        tool_guess=tool,
        engine=engine,
        max_std=_quantity(config.max_std, "length", "max_std"),
    )


# =============================================================== the tasks
@dataclass(frozen=True, eq=False)
class _Chunk:
    """One task: some robots of one pose set and one device."""

    prepared: _Prepared
    pose_set: str
    device: str
    robots: tuple[int, ...]

    def describe(self) -> str:
        lo, hi = self.robots[0], self.robots[-1]
        span = f"robot {lo}" if lo == hi else f"robots {lo}-{hi}"
        seed = self.prepared.config.seed
        return f"{span} of pose set {self.pose_set!r}, device {self.device!r} (study seed {seed})"


def _empty_row(case: Case, engine: str) -> dict[str, Any]:
    row: dict[str, Any] = dict.fromkeys(RESULT_COLUMNS, "")
    row.update(case=case.key, robot=case.robot, pose_set=case.pose_set, device=case.device, engine=engine)
    return row


def _stats(errors: Array) -> dict[str, float]:
    """Validation statistics (mm) of position errors ``(m,)`` (m), as rc.validate."""
    return {
        "val_n": len(errors),
        "val_mean_mm": float(errors.mean() * 1e3),
        "val_rms_mm": float(np.sqrt(np.mean(errors**2)) * 1e3),
        "val_p95_mm": float(np.percentile(errors, 95) * 1e3),
        "val_max_mm": float(errors.max() * 1e3),
    }


def _simulate_case(chunk: _Chunk, k: int):
    """True robot, calibration data, validation data and noise-free truth of robot ``k``."""
    from robocal.measure.poses import random_poses
    from robocal.measure.simulate import VirtualRobot, draw_true_model, simulate

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
        seed=np.random.default_rng(_seed(config, 0, k)),
    )
    device = prep.devices[chunk.device]
    robot = VirtualRobot(prep.nominal, true, device)
    q = prep.pose_sets[chunk.pose_set]
    if q is None:  # a new random draw for every robot
        spec = config.pose_sets[i_set]
        q = random_poses(prep.nominal, spec.n, seed=np.random.default_rng(_seed(config, 5, i_set, k)))
    data = simulate(robot, q, seed=np.random.default_rng(_seed(config, 1, k, i_set, i_dev)))
    test = simulate(robot, prep.q_test, seed=np.random.default_rng(_seed(config, 2, k, i_dev)))
    truth = device.predict(robot.T_base_tool(prep.q_test)).position
    return data, test, truth


def _fill_fit(row: dict[str, Any], fit, n: int, seconds: float) -> None:
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


def _error_row(case: Case, engine: str, chunk: _Chunk, err: BaseException) -> dict[str, Any]:
    row = _empty_row(case, engine)
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
    row = _empty_row(case, engine)
    row.update(status="failed", message=" ".join(str(err).split()), n_poses=n)
    return row


def _run_chunk(chunk: _Chunk) -> list[dict[str, Any]]:
    """Simulate, calibrate and validate the robots of one chunk; one row per robot.

    A robot whose calibration the guards refuse gets a ``failed`` row with the reason;
    one whose simulation or calibration raises otherwise an ``error`` row naming its
    input; the others are unaffected.
    """
    from robocal.identify.guards import CalibrationGuardError

    prep = chunk.prepared
    rows: dict[int, dict[str, Any]] = {}
    sims: dict[int, tuple] = {}
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


def _calibrate_row(chunk: _Chunk, case: Case, data, test, truth, t_sim: float) -> dict[str, Any]:
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
    row = _empty_row(case, "calibrate")
    _fill_fit(row, result, data.n, 0.0)
    row.update(_stats(stats.errors))
    true_err = np.linalg.norm(result.predict(prep.q_test)[:, :3, 3] - truth, axis=1)
    row.update(
        true_rms_mm=float(np.sqrt(np.mean(true_err**2)) * 1e3), true_max_mm=float(true_err.max() * 1e3)
    )
    return row


def _batched_rows(chunk: _Chunk, todo: list[int], sims: dict, rows: dict, t_sim: float) -> None:
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
            row = _empty_row(case, "batched")
            _fill_fit(row, fit, data.n, 0.0)
            row.update(_stats(np.linalg.norm(pred[i] - test.position, axis=1)))
            true_err = np.linalg.norm(pred[i] - truth, axis=1)
            row.update(
                true_rms_mm=float(np.sqrt(np.mean(true_err**2)) * 1e3),
                true_max_mm=float(true_err.max() * 1e3),
            )
            rows[k] = row
    per_robot = (time.perf_counter() - t0) / max(len(todo), 1)
    for k in todo:
        rows[k]["seconds"] = t_sim + per_robot


# =============================================================== the results table
class _Table:
    """An append-only CSV journal: a row is flushed to disk as soon as it is known.

    On opening, rows already there are read (a last line cut short by a crash is
    dropped, and the file rewritten atomically without it); :meth:`append` adds rows
    and ``fsync``s them.
    """

    def __init__(self, path: Path, columns: Sequence[str], key: str) -> None:
        self.path, self.columns, self.key = path, tuple(columns), key
        self.rows: dict[str, dict[str, str]] = {}
        if path.exists():
            self._load()
        else:
            atomic_write_text(path, ",".join(self.columns) + "\n")

    def _load(self) -> None:
        text = self.path.read_text(encoding="utf-8")
        lines = text.splitlines(keepends=True)
        if not lines or lines[0].strip() != ",".join(self.columns):
            raise StudyError(
                f"{self.path}: not a robocal results table of this version (header differs); "
                "use --force to start over"
            )
        good: list[str] = [lines[0]]
        for i, line in enumerate(lines[1:], start=2):
            cells = csvfile.split_rows([line.rstrip("\r\n")], ",")[0][0]
            complete = line.endswith("\n") and len(cells) == len(self.columns)
            if not complete:
                if i == len(lines):  # cut short by a crash: drop it
                    break
                raise StudyError(f"{self.path}: row {i} has {len(cells)} cells, expected {len(self.columns)}")
            row = dict(zip(self.columns, cells, strict=True))
            self.rows[csv_untext(row[self.key])] = row
            good.append(line)
        if len(good) != len(lines):
            atomic_write_text(self.path, "".join(good))

    def append(self, rows: Iterable[Mapping[str, Any]]) -> None:
        buf = io.StringIO()
        writer = csv.writer(buf, lineterminator="\n")
        new = []
        for row in rows:
            cells = [_cell(row.get(c, "")) for c in self.columns]
            writer.writerow(cells)
            new.append(dict(zip(self.columns, cells, strict=True)))
        with open(self.path, "a", encoding="utf-8") as fh:
            fh.write(buf.getvalue())
            fh.flush()
            os.fsync(fh.fileno())
        for row in new:
            self.rows[csv_untext(row[self.key])] = row


def _cell(value: Any) -> str:
    if isinstance(value, float | np.floating):
        return repr(float(value))
    return csv_text(str(value))  # a file name or message is never run as a spreadsheet formula


# =============================================================== running
@dataclass
class StudyRun:
    """What :func:`run_study` did.

    Attributes:
        out: the study directory.
        total: cases in the study; computed: cases computed by this run; resumed: cases
            found in the table already; errors: error rows written by this run.
        seconds: wall time of the computation (from the first task submitted to the
            last row written; the cluster's start-up excluded), ``startup_seconds`` that.
        calibrations_per_second: ``computed / seconds``.
        workers: Dask worker processes (0: this process).
        engine: ``"batched"`` or ``"calibrate"``.
        summary: per (pose set, device) statistics (also in ``summary.json``).
    """

    out: Path
    total: int
    computed: int
    resumed: int
    errors: int
    seconds: float
    startup_seconds: float
    workers: int
    engine: str
    summary: dict[str, Any] = field(default_factory=dict)

    @property
    def calibrations_per_second(self) -> float:
        return self.computed / self.seconds if self.seconds > 0 else 0.0


def _config_text(config: StudyConfig) -> str:
    return yaml.safe_dump(config.model_dump(mode="json"), sort_keys=True, default_flow_style=None, width=100)


def _identity(dumped: Mapping[str, Any]) -> dict[str, Any]:
    """The part of a configuration that decides the rows (not how many robots, the chunking, nor
    where it runs)."""
    return {k: v for k, v in dumped.items() if k not in ("robots", "chunk", "dask")}


def _chunks(prep: _Prepared, todo: Sequence[Case], size: int) -> list[_Chunk]:
    groups: dict[tuple[str, str], list[int]] = {}
    for c in todo:
        groups.setdefault((c.pose_set, c.device), []).append(c.robot)
    out = []
    for (pose_set, device), robots in groups.items():
        for i in range(0, len(robots), size):
            out.append(_Chunk(prep, pose_set, device, tuple(robots[i : i + size])))
    return out


def _warm_up() -> bool:
    import contextlib

    import robocal.identify.calibrate
    import robocal.identify.validate
    import robocal.measure.poses
    import robocal.measure.simulate  # noqa: F401

    with contextlib.suppress(ImportError):  # numba and the compiled kernels (~0.3 s per process)
        pass
    return True


def _prime(fn: Callable, item: Any) -> bool:
    """Run ``fn(item)`` and drop the result: the first task of a process pays the cached
    kernels' loading and the chain's plans (0.25 s, twice a later task of 50 robots)."""
    try:
        fn(item)
    except Exception:  # the real task reports it
        return False
    return True


def local_cluster(workers: int | None = None):
    """A Dask ``LocalCluster`` set up for robocal's tasks: ``workers`` single-threaded worker
    processes (default one per core), no dashboard, and the settings below (use it as
    ``Client(local_cluster(2))``; :func:`run_study` makes one unless given a client or a
    scheduler address)."""
    import logging

    import dask
    from distributed import LocalCluster

    n = workers if workers is not None else (os.cpu_count() or 1)
    # Dask starts workers with MALLOC_TRIM_THRESHOLD_=65536, which also freezes glibc's
    # mmap threshold at 128 KiB: every Jacobian-sized array is then mmapped and
    # page-faulted afresh, and freed heap is given back at once, ~1.5x slower here
    # (benchmarks/bench_throughput.py --malloc).  Arrays up to 16 MiB come from the
    # heap instead, and up to 64 MiB of freed heap is kept.  (The nanny sets these
    # variables in this process before it spawns a worker: put them back after.)
    environ = dict(dask.config.get("distributed.nanny.pre-spawn-environ", {}))
    environ["MALLOC_MMAP_THRESHOLD_"] = 16 << 20
    environ["MALLOC_TRIM_THRESHOLD_"] = 64 << 20
    environ.setdefault("OPENBLAS_NUM_THREADS", 1)  # one core per worker: BLAS threads only contend
    environ.setdefault("OMP_NUM_THREADS", 1)
    environ.setdefault("MKL_NUM_THREADS", 1)
    saved = {k: os.environ.get(k) for k in environ}
    settings = {
        "distributed.nanny.pre-spawn-environ": environ,
        # the statistical profiler feeds the dashboard (off here) and samples the
        # task's stack every 10 ms: ~15 % of a worker's time in this code
        "distributed.worker.profile.enabled": False,
        # each worker holds its next task while computing one (the default 1.1 hands a
        # single-threaded worker its next task only when it asks: a scheduler round trip
        # between tasks); the tasks are few and of equal size
        "distributed.scheduler.worker-saturation": 2.0,
    }
    try:
        with dask.config.set(settings):
            return LocalCluster(
                n_workers=n,
                threads_per_worker=1,
                processes=True,
                dashboard_address=None,
                silence_logs=logging.CRITICAL,  # not the workers' shutdown chatter
            )
    finally:
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


class _Executor:
    """In-process execution or a Dask client (local cluster or a scheduler address)."""

    def __init__(self, workers: int | None, scheduler: str | None) -> None:
        self.client = None
        self.cluster = None
        self.workers = 0
        if scheduler is None and workers == 0:
            return
        from distributed import Client

        if scheduler is not None:
            try:
                self.client = Client(scheduler, timeout="30s")
            except (OSError, ValueError) as err:  # unreachable, or not an address Dask knows
                raise StudyError(f"Dask scheduler {scheduler}: {' '.join(str(err).split())}") from None
            self.workers = len(self.client.scheduler_info().get("workers", {}))
        else:
            n = workers if workers is not None else (os.cpu_count() or 1)
            if n < 1:
                raise StudyError(f"workers={n}: give 1 or more (0 runs in this process)")
            self.cluster = local_cluster(n)
            self.client = Client(self.cluster)
            self.workers = n
        self.warm_up()

    def warm_up(self) -> None:
        """Import robocal on every worker now, not inside the first task (excluded from timing)."""
        if self.client is not None:
            self.client.run(_warm_up)

    def prime(self, fn: Callable, item: Any) -> None:
        """Run ``fn(item)`` once on every worker (a small task: start-up, not throughput)."""
        if self.client is not None:
            self.client.run(_prime, fn, item)

    def map(self, fn: Callable, items: Sequence, on_error: Callable) -> Iterator[tuple[Any, Any]]:
        """``(item, fn(item))`` as they complete; a failed task yields ``(item, on_error(item, exc))``."""
        if self.client is None:
            for item in items:
                try:
                    yield item, fn(item)
                except Exception as err:
                    yield item, on_error(item, err)
            return
        from distributed import as_completed

        futures = {self.client.submit(fn, item, pure=False): item for item in items}
        for future in as_completed(futures):
            item = futures[future]
            try:
                yield item, future.result()
            except Exception as err:
                yield item, on_error(item, err)
            future.release()

    def close(self) -> None:
        if self.client is not None:
            self.client.close()
        if self.cluster is not None:
            self.cluster.close()


def run_study(
    config: StudyConfig | str | os.PathLike[str],
    out: str | os.PathLike[str],
    *,
    workers: int | None = None,
    scheduler: str | None = None,
    force: bool = False,
    robots: int | None = None,
    progress: Callable[[int, int], None] | None = None,
    client: Any = None,
) -> StudyRun:
    """Run (or resume) a Monte Carlo study; rows go to ``out/results.csv`` as they finish.

    Args:
        config: a :class:`StudyConfig` or the path of its YAML file.
        out: the study directory: ``study.yaml`` (the configuration), ``results.csv``
            (one row per case, :data:`RESULT_COLUMNS`), ``summary.json``, ``summary.png``.
        workers: Dask worker processes of a local cluster (default: the study file's
            ``dask.workers``, else one per core); 0 runs in this process.
        scheduler: address of a running Dask scheduler (instead of a local cluster;
            default: the study file's ``dask.scheduler``).
        force: start over when ``out`` holds a study with another configuration (its
            results are deleted); without it such a directory is refused.
        robots: run only the first N robots of the configuration (a smaller study with
            the same seeds; rows are the same as the full study's).
        progress: called with ``(done, total)`` after every task.
        client: an existing ``distributed.Client`` to use (tests, notebooks).

    Returns:
        A :class:`StudyRun`.

    Raises:
        StudyError: bad configuration, or ``out`` holds another study (without ``force``).
    """
    if not isinstance(config, StudyConfig):
        config = load_study_config(config)
    if robots is not None:
        if robots < 1:
            raise StudyError(f"robots={robots} must be >= 1")
        config = config.model_copy(update={"robots": min(robots, config.robots)})
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    cfg_path = out / "study.yaml"
    results_path = out / "results.csv"
    if cfg_path.exists():
        try:
            old = yaml.safe_load(cfg_path.read_text(encoding="utf-8"))
        except (yaml.YAMLError, UnicodeDecodeError):
            old = None
        same = isinstance(old, dict) and _identity(old) == _identity(config.model_dump(mode="json"))
        if not same:
            if not force:
                raise StudyError(
                    f"{out} holds a study with another configuration ({cfg_path}); use --force to "
                    "start over (its results are deleted) or choose another --out"
                )
            results_path.unlink(missing_ok=True)
    elif results_path.exists():
        if not force:
            raise StudyError(f"{results_path} exists without its study.yaml; use --force to start over")
        results_path.unlink()
    prep = _prepare(config)
    atomic_write_text(cfg_path, _config_text(config))
    table = _Table(results_path, RESULT_COLUMNS, "case")
    cases = study_cases(config)
    done = {c.key for c in cases if c.key in table.rows and table.rows[c.key]["status"] != "error"}
    todo = [c for c in cases if c.key not in done]
    chunks = _chunks(prep, todo, config.chunk)
    t0 = time.perf_counter()
    if scheduler is None and workers is None:  # the call decides, else the study file
        scheduler, workers = config.dask.scheduler, config.dask.workers
    executor = _Executor(workers, scheduler) if client is None else None
    if client is not None:
        executor = _Executor(0, None)
        executor.client = client
        executor.workers = len(client.scheduler_info().get("workers", {}))
        executor.warm_up()
    if chunks:  # one robot on every worker before the clock starts
        first = chunks[0]
        executor.prime(_run_chunk, _Chunk(first.prepared, first.pose_set, first.device, first.robots[:1]))
    startup = time.perf_counter() - t0
    computed = errors = finished = 0

    def on_error(chunk: _Chunk, err: BaseException) -> list[dict[str, Any]]:
        text = " ".join(f"{type(err).__name__}: {err}".split())
        rows = []
        for k in chunk.robots:
            row = _empty_row(Case(k, chunk.pose_set, chunk.device), prep.engine)
            row.update(status="error", message=f"task failed: {text} [input: {chunk.describe()}]")
            rows.append(row)
        return rows

    t1 = time.perf_counter()
    try:
        for _chunk, rows in executor.map(_run_chunk, chunks, on_error):
            table.append(rows)
            computed += len(rows)
            errors += sum(r["status"] == "error" for r in rows)
            finished += 1
            if progress is not None:
                progress(len(done) + computed, len(cases))
    finally:
        seconds = time.perf_counter() - t1
        if client is None:
            executor.close()
    mine = [table.rows[c.key] for c in cases if c.key in table.rows]
    summary = _summarise(config, mine)
    summary["seconds"] = seconds
    summary["calibrations_per_second"] = computed / seconds if seconds > 0 else 0.0
    summary["run_id"] = new_run_id()
    write_together(  # the summary and its plot: both of this run or neither
        {
            out / "summary.json": (strict_json(summary, indent=2) + "\n").encode("utf-8"),
            out / "summary.png": _summary_png(config, mine, summary["run_id"]),
        }
    )
    return StudyRun(
        out=out,
        total=len(cases),
        computed=computed,
        resumed=len(done),
        errors=errors,
        seconds=seconds,
        startup_seconds=startup,
        workers=executor.workers,
        engine=prep.engine,
        summary=summary,
    )


def _floats(rows: Sequence[Mapping[str, str]], column: str) -> Array:
    out = []
    for r in rows:
        try:
            v = float(r[column])
        except (KeyError, ValueError):
            continue
        if math.isfinite(v):
            out.append(v)
    return np.array(out)


def _summarise(config: StudyConfig, rows: Iterable[Mapping[str, str]]) -> dict[str, Any]:
    """Per (pose set, device): counts and statistics of the ok rows (mm)."""
    rows = list(rows)
    groups = []
    for s in config.pose_sets:
        for d in config.devices:
            mine = [r for r in rows if r["pose_set"] == s.name and r["device"] == d.name]
            ok = [r for r in mine if r["status"] == "ok"]
            entry: dict[str, Any] = {
                "pose_set": s.name,
                "device": d.name,
                "cases": len(mine),
                "ok": len(ok),
                "not_converged": sum(r["status"] == "not-converged" for r in mine),
                "failed": sum(r["status"] == "failed" for r in mine),
                "errors": sum(r["status"] == "error" for r in mine),
            }
            for col in ("true_rms_mm", "val_rms_mm", "rms_after_mm", "rms_before_mm"):
                v = _floats(ok, col)
                if len(v):
                    entry[col] = {
                        "mean": float(v.mean()),
                        "median": float(np.median(v)),
                        "p95": float(np.percentile(v, 95)),
                        "max": float(v.max()),
                    }
            groups.append(entry)
    robot = config.robot if config.robot is not None else f"built from {config.geometry}"
    return {"study": config.name, "robot": robot, "robots": config.robots, "groups": groups}


def read_study_summary(out: str | Path) -> dict[str, Any]:
    """A study's ``summary.json``; refuses a ``summary.png`` of another run beside it (a
    run killed between the two renames, or a file copied in by hand).

    Raises:
        StudyError: naming both files and their run ids, or ``summary.json`` when it is
            missing or not a summary.
    """
    import json

    from robocal.outdir import read_run_id

    out = Path(out)
    path, png = out / "summary.json", out / "summary.png"
    try:
        summary = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, ValueError) as err:
        raise StudyError(f"{path}: cannot read the study summary ({err.__class__.__name__})") from None
    if not isinstance(summary, dict):
        raise StudyError(f"{path}: not a study summary")
    want = summary.get("run_id")
    got = read_run_id(png) if png.is_file() else want
    if got != want:
        raise StudyError(
            f"{path} is run {want or 'none'} but {png} is run {got or 'none'}: the two were not written "
            "together; run the study again (it resumes) to write both"
        )
    return summary


def _summary_png(config: StudyConfig, rows: Iterable[Mapping[str, str]], run_id: str) -> bytes:
    """Box plot of the held-out error against the true robot per (pose set, device), as PNG
    bytes (``run_id`` in its ``Description``, the ``run_id`` of ``summary.json``)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = list(rows)
    labels, values = [], []
    for s in config.pose_sets:
        for d in config.devices:
            v = _floats(
                [
                    r
                    for r in rows
                    if r["pose_set"] == s.name and r["device"] == d.name and r["status"] == "ok"
                ],
                "true_rms_mm",
            )
            labels.append(f"{s.name}\n{d.name}\n({len(v)} robots)")
            values.append(v if len(v) else np.array([np.nan]))
    fig, ax = plt.subplots(figsize=(max(4.0, 1.6 * len(labels)), 4.0), dpi=100)
    ax.boxplot(values, showfliers=True)
    ax.set_xticks(range(1, len(labels) + 1), labels, fontsize=8)
    ax.set_ylabel("held-out RMS error vs. the true robot (mm)")
    robot = Path(config.robot or config.geometry or "").stem
    ax.set_title(f"{config.name}: {config.robots} virtual robots ({robot})", fontsize=10)
    ax.grid(axis="y", alpha=0.3)
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", metadata={"Description": f"robocal run: {run_id}"})
    plt.close(fig)
    return buf.getvalue()


# =============================================================== fleets
@dataclass(frozen=True, eq=False)
class _FleetItem:
    path: Path
    name: str
    model: Model
    read_options: Mapping[str, Any]
    calibrate_options: Mapping[str, Any]
    complete: bool = False


def _sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def _fleet_task(item: _FleetItem) -> tuple[dict[str, Any], Any]:
    """Read, calibrate and validate one measurement file: ``(row, CalibrationResult | None)``."""
    from robocal.identify.calibrate import calibrate
    from robocal.identify.validate import validate
    from robocal.measure.dataset import read_measurements

    t0 = time.perf_counter()
    row: dict[str, Any] = dict.fromkeys(FLEET_COLUMNS, "")
    row["file"] = item.name
    try:
        row["sha256"] = _sha256(item.path)
        data = read_measurements(item.path, model=item.model, **item.read_options)
        train, test = data, None
        if data.split is not None and "test" in set(data.split.tolist()):
            train, test = data.split_rows("train"), data.split_rows("test")
        model = item.model
        if item.complete:
            from robocal.model.complete import calibration_model

            measure = item.calibrate_options.get("measure") or (
                "pose" if data.orientation is not None else "position"
            )
            model = calibration_model(model, measure)
        result = calibrate(model, train, **item.calibrate_options)
        result = result.with_records(data_file=str(item.path), data_sha256=row["sha256"], train_n=train.n)
        _fill_fit(row, result, train.n, 0.0)
        row.pop("iterations", None)
        row.pop("dropped", None)
        if test is not None:
            stats = validate(result, test)
            result = result.with_validation(stats.to_dict())
            row.update(_stats(stats.errors))
    except Exception as err:
        row.update(status="error", message=" ".join(str(err).split()) or type(err).__name__)
        result = None
    row["seconds"] = time.perf_counter() - t0
    return row, result


@dataclass
class FleetRun:
    """What :func:`run_fleet` did: files calibrated now, found done, failed, skipped
    (changed since their calibration, without ``force``), and where the table is."""

    out: Path
    table: Path
    calibrated: int
    resumed: int
    errors: int
    skipped: list[str]
    seconds: float
    workers: int
    rows: list[dict[str, str]]

    @property
    def calibrations_per_second(self) -> float:
        return self.calibrated / self.seconds if self.seconds > 0 else 0.0


def run_fleet(
    directory: str | os.PathLike[str],
    model: Model,
    out: str | os.PathLike[str] | None = None,
    *,
    pattern: str = "*.csv",
    read_options: Mapping[str, Any] | None = None,
    calibrate_options: Mapping[str, Any] | None = None,
    workers: int | None = None,
    scheduler: str | None = None,
    force: bool = False,
    progress: Callable[[int, int], None] | None = None,
    client: Any = None,
    complete: bool = False,
) -> FleetRun:
    """Calibrate one robot per measurement file of ``directory`` (files matching ``pattern``).

    Every file is read with ``read_options`` (those of
    :func:`robocal.read_measurements`), calibrated with ``calibrate_options`` (those of
    :func:`robocal.calibrate`) and, when it has ``set`` = ``test`` rows, validated on
    them.  ``out/<file stem>/`` receives ``model.yaml`` and ``result.json``;
    ``out/fleet.csv`` one row per file (:data:`FLEET_COLUMNS`), written as each file is
    done.  A file already calibrated with the same content (SHA-256) is not redone;
    one changed since its calibration is skipped unless ``force`` (which recalibrates
    every file and replaces the results).  A file that cannot be read or calibrated
    gets an ``error`` row with the reason (file, row, column) and is retried next time.

    Args:
        directory: the folder of measurement files.
        model: the robot model.
        out: output folder (default ``directory/calibrated``).
        workers, scheduler, client: where to run, as :func:`run_study`.
        progress: called with ``(done, total)`` after every file.
        complete: calibrate every file with ``model``'s complete model
            (:func:`robocal.calibration_model`, for pose measurements when the file has
            orientations and ``calibrate_options`` do not say ``measure="position"``)
            instead of ``model`` as it is.
    """
    directory = Path(directory)
    if not directory.is_dir():
        raise StudyError(f"{directory} is not a directory")
    files = sorted(p for p in directory.glob(pattern) if p.is_file())
    if not files:
        raise StudyError(f"{directory}: no files match {pattern!r}")
    out = Path(out) if out is not None else directory / "calibrated"
    out.mkdir(parents=True, exist_ok=True)
    table_path = out / "fleet.csv"
    files = [p for p in files if p.resolve() != table_path.resolve()]  # --out DIR: not its own table
    if not files:
        raise StudyError(f"{directory}: no measurement files match {pattern!r}")
    if force:
        table_path.unlink(missing_ok=True)
    table = _Table(table_path, FLEET_COLUMNS, "file")
    names = {p: str(p.relative_to(directory)) for p in files}
    stems = [p.stem for p in files]
    twice = sorted({s for s in stems if stems.count(s) > 1})
    if twice:
        raise StudyError(
            f"{directory}: several files share the name(s) {', '.join(twice)} (their results would clash)"
        )
    if table_path.name in stems:  # its result folder would be the table itself
        clash = files[stems.index(table_path.name)]
        raise StudyError(f"{clash}: a file named like the fleet table {table_path.name}; rename it")
    todo, skipped, resumed = [], [], 0
    for p in files:
        old = table.rows.get(names[p])
        if old is None or old["status"] == "error":
            todo.append(p)
            continue
        if old["sha256"] == _sha256(p):
            resumed += 1
        else:
            skipped.append(names[p])
    items = [
        _FleetItem(p, names[p], model, dict(read_options or {}), dict(calibrate_options or {}), complete)
        for p in todo
    ]
    executor = _Executor(workers, scheduler) if client is None else _Executor(0, None)
    if client is not None:
        executor.client = client
        executor.workers = len(client.scheduler_info().get("workers", {}))
        executor.warm_up()
    calibrated = errors = 0

    def on_error(item: _FleetItem, err: BaseException) -> tuple[dict[str, Any], None]:
        row: dict[str, Any] = dict.fromkeys(FLEET_COLUMNS, "")
        row.update(file=item.name, status="error", message=f"task failed: {type(err).__name__}: {err}")
        return row, None

    t1 = time.perf_counter()
    try:
        for item, (row, result) in executor.map(_fleet_task, items, on_error):
            if result is not None:
                target = out / item.path.stem
                result.save(target)
                row["result_dir"] = str(target)
                calibrated += 1
            else:
                errors += 1
            table.append([row])
            if progress is not None:
                progress(resumed + calibrated + errors, len(files))
    finally:
        seconds = time.perf_counter() - t1
        if client is None:
            executor.close()
    return FleetRun(
        out=out,
        table=table_path,
        calibrated=calibrated,
        resumed=resumed,
        errors=errors,
        skipped=skipped,
        seconds=seconds,
        workers=executor.workers,
        rows=[table.rows[names[p]] for p in files if names[p] in table.rows],
    )
