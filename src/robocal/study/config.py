"""A study's configuration (its YAML file, :class:`StudyConfig`) and its cases.

Lengths are text with a unit or SI numbers; :func:`load_study_config` resolves paths relative
to the file.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator, model_validator

from robocal.choices import Distribution, IndexName, ResidualChoice, SolverMethod
from robocal.model.files import Count, Number, format_validation_error


class StudyError(ValueError):
    """A study or fleet cannot run; the message names the file, field or directory."""


# =============================================================== configuration
_Config = ConfigDict(extra="forbid", allow_inf_nan=False, str_strip_whitespace=True)
Quantity = Number | str


class _Errors(BaseModel):
    model_config = _Config
    length: Quantity = "0.5mm"
    angle: Quantity = "0.05deg"
    distribution: Distribution = "uniform"
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
    index: IndexName = "O1"
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
    """Where a study runs, unless the call (``--scheduler``/``--workers``) says otherwise; a
    ``scheduler`` here is only a note: the call must name it (``--scheduler``) before robocal
    connects to it (a study file never opens a network connection by itself)."""

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
        dask: {workers: 2}          # a local cluster of 2 processes; default one per core
                                    # ({scheduler: ADDRESS}: used only with --scheduler ADDRESS)
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
    method: SolverMethod = "lm"
    max_std: Quantity = "0.5mm"
    engine: Literal["auto", "batched", "calibrate"] = "auto"
    residual: ResidualChoice = "none"
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
        from robocal.measure.true_model import parse_quantity

        checks: list[tuple[str, float | str, Literal["length", "angle"]]] = [
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
    from robocal.model.yaml_files import read_yaml

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


def seed_sequence(config: StudyConfig, *parts: int) -> np.random.SeedSequence:
    return np.random.SeedSequence([int(config.seed) & 0xFFFFFFFF, *parts])


def quantity(value: Quantity, kind: Literal["length", "angle"], where: str) -> float:
    from robocal.measure.true_model import parse_quantity

    try:
        return parse_quantity(value, kind)
    except ValueError as err:
        raise StudyError(f"{where}: {err}") from None
