"""What every task of a study shares, computed once by the client: the nominal model, the
devices, the shared pose sets, the held-out poses and the engine (:class:`_Prepared`)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from robocal.model.chain import Model
from robocal.model.geometry import Measure
from robocal.study.config import DeviceSpec, PoseSetSpec, StudyConfig, StudyError, quantity, seed_sequence

Array = NDArray[np.float64]


def _resolve_model(name_or_path: str) -> Model:
    """The study's robot (robocal.model.catalog.find_model); its error as a StudyError."""
    from robocal.model.catalog import find_model
    from robocal.model.yaml_files import ModelFileError

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
            device = device.with_noise(quantity(spec.noise, "length", where + ".noise"))
    except (TypeError, ValueError, NotImplementedError) as err:
        raise StudyError(f"{where}: {err}") from None
    return device


def _pose_set(config: StudyConfig, spec: PoseSetSpec, index: int, model: Model) -> Array:
    """``(n, dof)`` joint values of a shared pose set (per-robot draws are made in the tasks)."""
    from robocal.measure.poses import random_poses, read_poses

    where = f"pose_sets[{index}] ({spec.name})"
    seed = np.random.default_rng(seed_sequence(config, 4, index) if spec.seed is None else spec.seed)
    try:
        if spec.kind == "file":
            if spec.path is None:
                raise StudyError(f"{where}: kind 'file' needs 'path'")
            return read_poses(spec.path, model)
        if spec.n is None:
            raise StudyError(f"{where}: kind {spec.kind!r} needs 'n' (number of poses)")
        if spec.kind == "random":
            return random_poses(model, spec.n, seed=seed)
        from robocal.identify.pose_selection import select_poses

        pool = random_poses(model, max(spec.pool, spec.n), seed=seed)
        chosen = select_poses(model, pool, spec.n, index=spec.index)
        return pool[np.asarray(chosen.indices)]
    except StudyError:
        raise
    except (ValueError, OSError) as err:
        raise StudyError(f"{where}: {err}") from None


@dataclass(frozen=True, eq=False)
class Prepared:
    """Everything a task needs, computed once by the client (small, picklable)."""

    config: StudyConfig
    nominal: Model
    devices: dict[str, Any]
    pose_sets: dict[str, Array | None]  # None: drawn per robot
    q_test: Array
    tool_guess: Array
    engine: str
    max_std: float


def _built_model(path: str, measure: Measure) -> Model:
    from robocal.model.builder import load_geometry
    from robocal.model.geometry import GeometryError

    try:
        return load_geometry(path).build(measure).model
    except FileNotFoundError:
        raise StudyError(f"geometry file {path} does not exist") from None
    except (GeometryError, ValueError) as err:
        raise StudyError(f"geometry: {err}") from None


def prepare(config: StudyConfig) -> Prepared:
    tool = np.asarray(config.tool, dtype=float) * 1e-3
    devices = {d.name: _make_device(d, tool, i) for i, d in enumerate(config.devices)}
    if config.geometry is not None:
        measure: Measure = "position" if all(d.measures == "position" for d in devices.values()) else "pose"
        nominal = _built_model(config.geometry, measure)
    elif config.robot is not None:
        nominal = _resolve_model(config.robot)
    else:  # pragma: no cover - the configuration's check asks for one of them
        raise StudyError("give 'robot' or 'geometry'")
    sets: dict[str, Array | None] = {}
    for i, s in enumerate(config.pose_sets):
        if s.per_robot and s.kind != "random":
            raise StudyError(f"pose_sets[{i}] ({s.name}): per_robot draws need kind 'random'")
        if s.per_robot and s.n is None:  # each robot's draw would fail on its own row
            raise StudyError(f"pose_sets[{i}] ({s.name}): kind 'random' needs 'n' (number of poses)")
        sets[s.name] = None if s.per_robot else _pose_set(config, s, i, nominal)
    from robocal.measure.poses import random_poses

    seed = config.validation.seed
    q_test = random_poses(
        nominal,
        config.validation.n,
        seed=np.random.default_rng(seed_sequence(config, 3) if seed is None else seed),
    )
    quantity(config.errors.length, "length", "errors.length")
    quantity(config.errors.angle, "angle", "errors.angle")
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
    return Prepared(
        config=config,
        nominal=nominal,
        devices=devices,
        pose_sets=sets,
        q_test=q_test,
        tool_guess=tool,
        engine=engine,
        max_std=quantity(config.max_std, "length", "max_std"),
    )
