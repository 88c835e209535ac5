"""A virtual robot: a model with true errors, joint effects and a device -> measurements.

The pieces:

* :func:`draw_true_model`: a "real" robot drawn around a nominal model, every free
  parameter deviating by a random amount within its tolerance (default ±0.5 mm for
  lengths and ±0.05° for angles, **uniform** in ±tol; ``distribution="normal"`` draws
  normal errors with 1-sigma = tol).  Per-parameter overrides by name.
* Joint effects: callables ``effect(model, q) -> (n, dof, 3)`` perturbations
  (δα, δβ, δθ) passed to ``true_model.fk(q, perturbations=...)`` (seed 003 eq. 5.9;
  see :mod:`robocal.model.chain`).  Two examples: :class:`EncoderNoise` and
  :class:`PayloadCompliance` (a gravity-proportional joint deflection); clearance,
  backlash and full compliance models plug in the same way.
* :class:`VirtualRobot`: nominal model (what the controller believes), true model,
  device and joint effects; :func:`simulate` commands it to joint values ``q`` and
  returns what the device observes, reproducibly from a seed.
* :func:`save_simulation` writes the measurements (``meas.csv``) and the truth beside
  them (``meas.truth.yaml`` with the device, its frame, target offset, noise, seed and
  parameter deviations; ``meas.true_model.yaml`` and ``meas.nominal_model.yaml`` via
  :func:`robocal.model.files.save_model`); :func:`load_truth` reads them back.
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import numpy as np
import yaml
from numpy.typing import ArrayLike, NDArray

from robocal.measure.dataset import Measurements, write_measurements
from robocal.measure.devices import Device, device_from_dict
from robocal.model.chain import Model
from robocal.model.files import atomic_write_text, load_model, save_model
from robocal.outdir import FolderMixedError, file_set, new_run_id, read_run_id, run_id_line
from robocal.units import ANGLE_UNITS, LENGTH_UNITS, SPELLINGS

__all__ = [
    "EncoderNoise",
    "JointEffect",
    "PayloadCompliance",
    "Truth",
    "VirtualRobot",
    "draw_true_model",
    "load_truth",
    "parse_quantity",
    "parse_quantity_option",
    "save_simulation",
    "simulate",
    "truth_path",
]

Array = NDArray[np.float64]

#: ``effect(model, q (n, dof)) -> (n, dof, 3)`` joint perturbations (δα, δβ, δθ) in rad
#: (δθ in m for a prismatic joint).
JointEffect = Callable[[Model, Array], Array]

_QUANTITY = re.compile(r"^\s*([+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?)\s*([A-Za-zµμ°]*)\s*$")


def parse_quantity_option(value: str, kind: Literal["length", "angle"], option: str) -> float:
    """A command-line length (m) or angle (rad): text that must carry its unit
    (``0.02mm``, ``0.05deg``); a bare number is an error, since on a command line it is
    as likely meant in mm or degrees as in SI units."""
    m = _QUANTITY.match(value)
    if m is not None and not m.group(2) and float(m.group(1)) != 0.0:
        example = f"{value}mm" if kind == "length" else f"{value}deg"
        raise ValueError(f"{option} {value}: give the unit, e.g. {example}")
    try:
        return parse_quantity(value, kind)
    except ValueError as err:
        raise ValueError(f"{option}: {err}") from None


def parse_quantity(value: str | float, kind: Literal["length", "angle"]) -> float:
    """A length (m) or angle (rad) from a number (already SI) or text with a unit.

    Lengths: ``m``, ``mm``, ``um``/``µm``; angles: ``rad``, ``mrad``, ``urad``,
    ``deg``/``°``.  ``parse_quantity("0.02mm", "length") == 2e-5``.  A bare number in
    text is SI.
    """
    if not isinstance(value, str):
        out = float(value)
    else:
        m = _QUANTITY.match(value)
        units = LENGTH_UNITS if kind == "length" else ANGLE_UNITS
        unit = SPELLINGS.get(m.group(2), m.group(2)) if m is not None else None
        if m is None or (unit and unit not in units):
            raise ValueError(
                f"{value!r} is not a {kind} such as {'0.02mm' if kind == 'length' else '0.05deg'} "
                f"(units: {', '.join(units)})"
            )
        out = float(m.group(1)) * units.get(unit, 1.0)
    if not math.isfinite(out):
        raise ValueError(f"{kind} {value!r} is not finite")
    return out


# ------------------------------------------------------------------- true models
def draw_true_model(
    model: Model,
    tolerances: Mapping[str, float | str] | None = None,
    *,
    length: float | str = 0.5e-3,
    angle: float | str = math.radians(0.05),
    distribution: Literal["uniform", "normal"] = "uniform",
    seed: int | np.random.Generator | None = None,
    params: Literal["free", "all"] | Iterable[str] = "free",
) -> Model:
    """A model whose parameters deviate randomly from ``model``'s (the "real" robot).

    Args:
        model: the nominal model.
        tolerances: per-parameter tolerances by name, SI numbers or text with a unit,
            e.g. ``{"theta2": "0.2deg", "d1": 1e-3}``; they override ``length`` and
            ``angle`` and also select a fixed parameter when ``params="free"``.
        length: tolerance of length parameters (m, or text such as ``"0.5mm"``).
        angle: tolerance of angle parameters (rad, or text such as ``"0.05deg"``).
        distribution: ``"uniform"``: deviation uniform in ``[-tol, tol]``;
            ``"normal"``: normal with standard deviation ``tol``.
        seed: seed or Generator; the same seed gives the same model.
        params: which parameters deviate: ``"free"`` (default; the ones identification
            may change), ``"all"``, or a list of names.

    Returns:
        A new model with the same structure (free flags, bounds, joints) and drawn values.
    """
    if distribution not in ("uniform", "normal"):
        raise ValueError(f"distribution must be 'uniform' or 'normal', got {distribution!r}")
    tol_len = parse_quantity(length, "length")
    tol_ang = parse_quantity(angle, "angle")
    overrides: dict[str, float] = {}
    for name, value in (tolerances or {}).items():
        step = model.step(name)  # KeyError naming the parameter and the model
        overrides[name] = parse_quantity(value, "angle" if step.is_rotation else "length")
    if params == "free":
        names = [*model.free_names, *(n for n in overrides if n not in model.free_names)]
    elif params == "all":
        names = list(model.names)
    else:
        names = list(params)
        for n in names:
            model.step(n)
    tol = np.array(
        [overrides.get(n, tol_ang if model.step(n).is_rotation else tol_len) for n in names], dtype=float
    )
    if np.any(tol < 0):
        raise ValueError("tolerances must be >= 0")
    rng = np.random.default_rng(seed)
    if distribution == "uniform":
        delta = rng.uniform(-1.0, 1.0, len(names)) * tol
    else:
        delta = rng.standard_normal(len(names)) * tol
    values = model.values
    index = {n: i for i, n in enumerate(model.names)}
    return model.with_values({n: values[index[n]] + d for n, d in zip(names, delta, strict=True)})


# ------------------------------------------------------------------ joint effects
@dataclass(frozen=True)
class EncoderNoise:
    """Joint effect: normal joint-reading errors δθ with 1-sigma ``sigma`` (rad, m for a
    prismatic joint), drawn from ``seed`` (the same q count gives the same errors)."""

    sigma: float
    seed: int = 0

    def __call__(self, model: Model, q: Array) -> Array:
        q = np.atleast_2d(q)
        d = np.zeros((len(q), model.dof, 3))
        d[:, :, 2] = np.random.default_rng(self.seed).normal(0.0, self.sigma, (len(q), model.dof))
        return d

    def to_dict(self) -> dict[str, Any]:
        return {"type": "encoder-noise", "sigma": float(self.sigma), "seed": int(self.seed)}


@dataclass(frozen=True)
class PayloadCompliance:
    """Joint effect: joints deflected by the gravity moment of a payload at the tool.

    For each joint j with a stiffness ``k_j`` (N·m/rad; N/m for a prismatic joint) the
    payload ``mass`` (kg) at ``p_tool_load`` (m, tool frame) under ``gravity`` (m/s²,
    base frame) exerts the moment ``τ_j = a_j · ((c − o_j) × m g)`` about the joint axis
    (unit ``a_j`` through ``o_j``; a force ``a_j · m g`` for a prismatic joint), and the
    joint gives way by ``δθ_j = τ_j / k_j``.  The link masses are ignored: a first
    example of the hook (seed 003 ch. 5 computes the full moments by Newton-Euler).

    Attributes:
        mass: payload (kg).
        stiffness: by joint name or 1-based joint number, e.g. ``{2: 5e4}``.
        p_tool_load: payload centre in the tool frame (m).
        gravity: gravity vector in the base frame (m/s²).
    """

    mass: float
    stiffness: Mapping[str | int, float]
    p_tool_load: tuple[float, float, float] = (0.0, 0.0, 0.0)
    gravity: tuple[float, float, float] = (0.0, 0.0, -9.81)

    def _joints(self, model: Model) -> list[tuple[int, float]]:
        out = []
        for key, k in self.stiffness.items():
            if isinstance(key, str):
                if key not in model.joint_names:
                    raise KeyError(f"PayloadCompliance: model {model.name!r} has no joint {key!r}")
                j = model.joint_names.index(key)
            else:
                j = int(key) - 1
                if not 0 <= j < model.dof:
                    raise KeyError(f"PayloadCompliance: joint number {key} is not in 1..{model.dof}")
            if not (math.isfinite(k) and k > 0):
                raise ValueError(f"PayloadCompliance: stiffness of joint {key} must be > 0, got {k}")
            out.append((j, float(k)))
        return out

    def __call__(self, model: Model, q: Array) -> Array:
        q = np.atleast_2d(q)
        frames = model.joint_frames(q)  # (n, dof, 4, 4), origin on each joint axis
        T = model.fk(q)
        c = T[:, :3, :3] @ np.asarray(self.p_tool_load, dtype=float) + T[:, :3, 3]
        force = self.mass * np.asarray(self.gravity, dtype=float)
        axes = [s.axis for s in model.steps if s.joint is not None]
        d = np.zeros((len(q), model.dof, 3))
        for j, k in self._joints(model):
            a = frames[:, j, :3, axes[j]]
            if model.joint_types[j] == "revolute":
                moment = np.cross(c - frames[:, j, :3, 3], force)
                d[:, j, 2] = np.einsum("ni,ni->n", a, moment) / k
            else:
                d[:, j, 2] = a @ force / k
        return d

    def to_dict(self) -> dict[str, Any]:
        return {
            "type": "payload-compliance",
            "mass": float(self.mass),
            "stiffness": {k: float(v) for k, v in self.stiffness.items()},
            "p_tool_load": [float(v) for v in self.p_tool_load],
            "gravity": [float(v) for v in self.gravity],
        }


_EFFECTS: dict[str, type] = {"encoder-noise": EncoderNoise, "payload-compliance": PayloadCompliance}


def _effect_from_dict(data: Mapping[str, Any]) -> JointEffect | None:
    data = dict(data)
    if data.get("type") == "joint-tilting":  # seed 003's joint model (robocal.model.joints)
        from robocal.model.joints import JointTilting

        return JointTilting.from_dict(data)
    cls = _EFFECTS.get(data.pop("type", None))
    if cls is None:
        return None
    for key in ("p_tool_load", "gravity"):
        if key in data:
            data[key] = tuple(data[key])
    return cls(**data)


# ------------------------------------------------------------------ virtual robot
@dataclass(frozen=True, eq=False)
class VirtualRobot:
    """A simulated robot and the device that measures it.

    Attributes:
        nominal: the model the controller believes (its joint limits apply to commands).
        true: the real robot (same joints; e.g. from :func:`draw_true_model`).
        device: what measures the tool (:mod:`robocal.measure.devices`).
        joint_effects: one joint effect or a sequence of them (summed), or None.
    """

    nominal: Model
    true: Model
    device: Device
    joint_effects: JointEffect | Sequence[JointEffect] | None = None

    def __post_init__(self) -> None:
        if self.true.dof != self.nominal.dof:
            raise ValueError(
                f"true model {self.true.name!r} has {self.true.dof} joints, nominal "
                f"{self.nominal.name!r} {self.nominal.dof}"
            )
        if not isinstance(self.device, Device):
            raise TypeError(f"device must be a robocal.measure.devices.Device, got {type(self.device)}")

    @property
    def effects(self) -> tuple[JointEffect, ...]:
        if self.joint_effects is None:
            return ()
        if callable(self.joint_effects):
            return (self.joint_effects,)
        return tuple(self.joint_effects)

    def perturbations(self, q: ArrayLike) -> Array | None:
        """Summed joint perturbations ``(n, dof, 3)`` of the joint effects, or None."""
        if not self.effects:
            return None
        q = np.atleast_2d(np.asarray(q, dtype=float))
        total = np.zeros((len(q), self.true.dof, 3))
        for effect in self.effects:
            d = np.asarray(effect(self.true, q), dtype=float)
            if d.shape != total.shape:
                raise ValueError(f"joint effect {effect!r} returned shape {d.shape}; expected {total.shape}")
            if not np.all(np.isfinite(d)):
                raise ValueError(f"joint effect {effect!r} returned NaN or inf")
            total += d
        return total

    def T_base_tool(self, q: ArrayLike) -> Array:
        """True tool frames ``(n, 4, 4)`` at commanded joint values ``q`` ``(n, dof)``."""
        q = np.atleast_2d(np.asarray(q, dtype=float))
        return self.true.fk(q, perturbations=self.perturbations(q))


def _commanded(robot: VirtualRobot, q: ArrayLike | Measurements) -> tuple[Array, Measurements | None]:
    source = q if isinstance(q, Measurements) else None
    qa = np.atleast_2d(np.asarray(source.q if source is not None else q, dtype=float))
    model = robot.nominal
    if qa.ndim != 2 or qa.shape[1] != model.dof:
        raise ValueError(f"joint values shaped {qa.shape}; model {model.name!r} needs (n, {model.dof})")
    if not np.all(np.isfinite(qa)):
        raise ValueError("joint values contain NaN or inf")
    lim = model.joint_limits
    bad = np.argwhere((qa < lim[:, 0]) | (qa > lim[:, 1]))
    if bad.size:
        i, j = bad[0]
        raise ValueError(
            f"pose {i}: joint {model.joint_names[j]} = {qa[i, j]:.6g} is outside the limits "
            f"[{lim[j, 0]:.6g}, {lim[j, 1]:.6g}] of model {model.name!r} ({len(bad)} value(s) outside)"
        )
    return qa, source


def simulate(
    robot: VirtualRobot,
    q: ArrayLike | Measurements,
    seed: int | None = None,
    *,
    metadata: Mapping[str, str] | None = None,
) -> Measurements:
    """Command the virtual robot to ``q`` and measure it with its device.

    Args:
        robot: the virtual robot.
        q: commanded joint values ``(n, dof)`` (rad, m), or the :class:`Measurements` of
            a poses file (its joint names and train/test split are kept).
        seed: seeds the device noise; the same seed gives identical measurements.
        metadata: extra metadata strings.

    Returns:
        :class:`Measurements` with the commanded ``q``, the device's ``position`` (and
        ``orientation`` for pose devices) in its frame, and the per-row ``sigma`` the
        device declares.

    Raises:
        ValueError: joint values outside the nominal model's limits, or poses the device
            cannot observe (out of its range, off the plate...).
    """
    qa, source = _commanded(robot, q)
    obs = robot.device.observe(robot.T_base_tool(qa), np.random.default_rng(seed))
    meta = {
        "source": "robocal simulate",
        "robot": robot.nominal.name,
        "device": robot.device.kind,
        "frame": "device (T_device_base unknown to the calibration)",
        "seed": "none" if seed is None else str(seed),
    }
    meta.update(metadata or {})
    return Measurements(
        q=qa,
        position=obs.position,
        orientation=obs.orientation,
        sigma=obs.sigma,
        split=source.split if source is not None else None,
        joint_names=source.joint_names if source is not None else robot.nominal.joint_names,
        metadata=meta,
    )


# ------------------------------------------------------------------------- truth
def truth_path(data_path: str | Path) -> Path:
    """``meas.csv`` -> ``meas.truth.yaml`` (beside the data)."""
    p = Path(data_path)
    return p.with_name(p.stem + ".truth.yaml")


@dataclass(frozen=True, eq=False)
class Truth:
    """What a simulation knew and the calibration must find.

    Attributes:
        nominal, true: the models.
        device: the device with its frame, target offset and noise.
        seed: the noise seed (None if unseeded).
        data_file: the measurements file name, relative to the truth file.
        joint_effects: the joint effects that could be rebuilt from the file.
        joint_effect_descriptions: one text per joint effect of the simulation.
    """

    nominal: Model
    true: Model
    device: Device
    seed: int | None = None
    data_file: str = ""
    joint_effects: tuple[JointEffect, ...] = ()
    joint_effect_descriptions: tuple[str, ...] = ()

    @property
    def deviations(self) -> dict[str, float]:
        """``true - nominal`` per parameter (SI)."""
        nom = dict(zip(self.nominal.names, self.nominal.values.tolist(), strict=True))
        return {n: v - nom[n] for n, v in zip(self.true.names, self.true.values.tolist(), strict=True)}

    def virtual_robot(self) -> VirtualRobot:
        return VirtualRobot(self.nominal, self.true, self.device, self.joint_effects or None)


def _plain(value: Any) -> Any:
    if isinstance(value, Mapping):
        return {str(k) if not isinstance(k, int) else k: _plain(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_plain(v) for v in value]
    if isinstance(value, np.ndarray):
        return _plain(value.tolist())
    if isinstance(value, np.integer):
        return int(value)
    if isinstance(value, float | np.floating):
        return float(value)
    return value


def save_simulation(
    robot: VirtualRobot,
    data: Measurements,
    path: str | Path,
    seed: int | None = None,
    **info: Any,
) -> tuple[Path, Path]:
    """Write ``data`` to ``path`` (CSV) and the truth beside it.

    Files: ``path`` (e.g. ``meas.csv``), ``meas.truth.yaml``, ``meas.true_model.yaml``
    and ``meas.nominal_model.yaml``, all atomically.  ``info`` (e.g. the tolerances used)
    is stored in the truth file as given.

    Returns:
        The data and truth file paths.
    """
    path = Path(path)
    tpath = truth_path(path)
    stem = path.stem
    true_file = f"{stem}.true_model.yaml"
    nominal_file = f"{stem}.nominal_model.yaml"
    effects = []
    for effect in robot.effects:
        desc = effect.to_dict() if hasattr(effect, "to_dict") else {"type": "callable"}
        desc["description"] = repr(effect)
        effects.append(desc)
    nom = robot.nominal
    deviations = {
        n: float(t - v)
        for n, t, v in zip(robot.true.names, robot.true.values, nom.values, strict=True)
        if t != v
    }
    doc = {
        "robocal_truth": 1,
        "units": "m, rad",
        "data_file": path.name,
        "seed": seed,
        "robot": nom.name,
        "nominal_model_file": nominal_file,
        "true_model_file": true_file,
        "device": robot.device.to_dict(),
        "joint_effects": effects,
        "deviations": deviations,
        "info": _plain(info),
    }
    run_id = new_run_id()
    header = (
        f"# robocal simulation truth for {path.name}: device {robot.device.kind}, robot {nom.name}, "
        "seed " + str(seed) + "; SI units (m, rad)\n" + run_id_line(run_id)
    )
    text = header + yaml.safe_dump(_plain(doc), sort_keys=False, default_flow_style=None, width=100)
    # all four files or none: never new measurements beside an earlier truth
    targets = [path.with_name(true_file), path.with_name(nominal_file), path, tpath]
    with file_set(targets) as (true_tmp, nominal_tmp, data_tmp, truth_tmp):
        save_model(robot.true, true_tmp, run_id=run_id)
        save_model(robot.nominal, nominal_tmp, run_id=run_id)
        write_measurements(data, data_tmp, run_id=run_id)
        atomic_write_text(truth_tmp, text)
    return path, tpath


def _check_same_run(truth_file: Path, doc: dict) -> None:
    """Refuse a truth file beside measurements or models of another simulation (a run
    killed between its renames, or files copied together by hand)."""
    want = read_run_id(truth_file)
    if want is None:  # written before run ids
        return
    names = [doc.get("data_file"), doc.get("nominal_model_file"), doc.get("true_model_file")]
    bad = []
    for name in names:
        if not isinstance(name, str) or not (truth_file.parent / name).is_file():
            continue
        got = read_run_id(truth_file.parent / name)
        if got != want:
            bad.append(f"{name} (run {got or 'none'})")
    if bad:
        raise FolderMixedError(
            f"{truth_file}: the truth is of simulation run {want} but {', '.join(bad)}: "
            "these files come from different simulations; simulate again"
        )


def load_truth(path: str | Path) -> Truth:
    """Read a truth file written by :func:`save_simulation` (or the data file beside it)."""
    path = Path(path)
    if not path.name.endswith(".truth.yaml"):
        path = truth_path(path)
    try:
        doc = yaml.safe_load(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise FileNotFoundError(f"{path}: truth file not found") from None
    if not isinstance(doc, dict) or doc.get("robocal_truth") != 1:
        raise ValueError(f"{path}: not a robocal truth file (no 'robocal_truth: 1')")
    _check_same_run(path, doc)
    try:
        nominal = load_model(path.with_name(doc["nominal_model_file"]))
        true = load_model(path.with_name(doc["true_model_file"]))
        device = device_from_dict(doc["device"])
    except KeyError as err:
        raise ValueError(f"{path}: missing field {err.args[0]!r}") from None
    except ValueError as err:
        raise ValueError(f"{path}: {err}") from None
    effects, descriptions = [], []
    for item in doc.get("joint_effects") or []:
        descriptions.append(str(item.get("description", item.get("type"))))
        effect = _effect_from_dict({k: v for k, v in item.items() if k != "description"})
        if effect is not None:
            effects.append(effect)
    return Truth(
        nominal=nominal,
        true=true,
        device=device,
        seed=doc.get("seed"),
        data_file=str(doc.get("data_file", "")),
        joint_effects=tuple(effects),
        joint_effect_descriptions=tuple(descriptions),
    )
