"""A virtual robot: a model with true errors, joint effects and a device -> measurements.

The pieces:

* :func:`draw_true_model` (:mod:`robocal.measure.true_model`): a "real" robot drawn around a
  nominal model, every free parameter deviating by a random amount within its tolerance
  (default ±0.5 mm for lengths and ±0.05° for angles, **uniform** in ±tol;
  ``distribution="normal"`` draws normal errors with 1-sigma = tol).  Per-parameter
  overrides by name.
* Joint effects (:mod:`robocal.measure.joint_effects`): callables ``effect(model, q) ->
  (n, dof, 3)`` perturbations (δα, δβ, δθ) passed to ``true_model.fk(q, perturbations=...)``
  (seed 003 eq. 5.9; see :mod:`robocal.model.chain`).  Two examples: :class:`EncoderNoise`
  and :class:`PayloadCompliance` (a gravity-proportional joint deflection); clearance,
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

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from numpy.typing import ArrayLike, NDArray

from robocal.measure.dataset.writer import write_measurements
from robocal.measure.device_base import Device
from robocal.measure.devices import device_from_dict
from robocal.measure.joint_effects import EncoderNoise, JointEffect, PayloadCompliance, effect_from_dict
from robocal.measure.measurements import Measurements
from robocal.measure.true_model import draw_true_model, parse_quantity, parse_quantity_option
from robocal.model.chain import Model
from robocal.model.files import load_model, save_model
from robocal.outdir import atomic_write_text, file_set
from robocal.run_ids import FolderMixedError, new_run_id, read_run_id, run_id_line

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
    seed: int | np.random.Generator | None = None,
    *,
    metadata: Mapping[str, str] | None = None,
) -> Measurements:
    """Command the virtual robot to ``q`` and measure it with its device.

    Args:
        robot: the virtual robot.
        q: commanded joint values ``(n, dof)`` (rad, m), or the :class:`Measurements` of
            a poses file (its joint names and train/test split are kept).
        seed: seeds the device noise (or a generator to draw it from); the same seed gives
            identical measurements.
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
        "seed": "a generator" if isinstance(seed, np.random.Generator) else str(seed).lower(),
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
        effect = effect_from_dict({k: v for k, v in item.items() if k != "description"})
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
