"""A constraint calibration read back from its folder.

``robocal calibrate ROBOT --data FILE`` of a constraint file (fixed points, planes,
distances: :mod:`robocal.cli.constraints`) writes ``model.yaml`` (the calibrated robot)
and ``constraints.json`` (what was identified, what the data cannot see, the scene) in
one transaction.  :func:`load_constraint_calibration` reads both back, checked against
each other, for the report, the exports and compensation.

What such a calibration does not hold, unlike a tracker calibration: a measuring
device's frame (the points are in the robot's base frame) and the base placement — a
rigid motion of the robot and its scene together changes no constraint, so the
parameters placing the chain in the base frame stay at their nominal values
(:attr:`ConstraintCalibration.unseen`).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from robocal.identify.constraints.tilt_record import TiltCalibration, TiltEstimate, tilt_calibration_of
from robocal.model.chain import Model

if TYPE_CHECKING:
    from robocal.identify.result import CalibrationResult
    from robocal.identify.validate import ValidationStats
    from robocal.measure.measurements import Measurements

__all__ = [
    "CONSTRAINT_FILE",
    "ConstraintCalibration",
    "TrackerValidation",
    "is_constraint_folder",
    "load_constraint_calibration",
    "validate_on_tracker",
]

Array = NDArray[np.float64]
#: the constraint calibration's record beside ``model.yaml``
CONSTRAINT_FILE = "constraints.json"
#: reasons of the rank test: the data cannot see the parameter at all (not merely poorly)
_UNSEEN = ("redundant", "no effect")


@dataclass(frozen=True)
class ConstraintCalibration:
    """A constraint calibration folder's content (lengths in m, angles in rad).

    Attributes:
        directory: the folder.
        model: the calibrated robot (``model.yaml``); its end is the point the
            constraints held (the ball centre, the probe tip).
        nominal: the robot before calibration (the estimated parameters at their start
            values), or None for a folder written before the start values were recorded.
        kinds: the measurement kinds (``point``, ``plane``, ``distance``).
        names, estimates, std: the estimated unknowns (robot parameters and the scene's
            ``point*``/``plane*`` unknowns), their values and 1σ.
        dropped: ``(name, reason)`` of what was not identified (held at its start value).
        points: ``(K, 3)`` the fixed points in the base frame. planes: ``(P, 4)`` normal, offset.
        rms_before, rms_after: the fit's RMS residual at the start and after.
        success: whether the fit converged.
        data_path, data_sha256: the calibration's constraint file as recorded.
        angle_unit: the file's joint angle unit (``rad``/``deg``; None: not recorded).
        distances: ``(a, b, metres)`` the stated distances between points.
        prior: ``{"length_std_m", "angle_std_rad"}`` of the prior toward the nominal
            geometry, or None (a least-squares fit).
        run_id: the transaction that wrote the folder.
        joint_effects: the joint effects identified from tilt rows (``backlash_<joint>``,
            ``clearance_<joint>`` in rad, ``compliance_<joint>`` in rad/(N·m)), value and
            1σ; empty without tilt rows (those not identified are in ``dropped``).
        tilt_zeros: each inclinometer channel's zero (``<joint>_<axis>``, rad) and 1σ
            (NaN: held at the channel's mean, not estimated).
        T_device_base: ``(4, 4)`` the tracker's frame the fit identified from tracker rows
            (mixed data), or None: no tracker rows, the device frame is unknown.
        tracker_sha256: the SHA-256 of each tracker file fitted with the constraint rows.
        tracker_noise: the tracker rows' σ per axis the fit estimated (m), or None.
    """

    directory: Path
    model: Model
    nominal: Model | None
    kinds: tuple[str, ...]
    names: tuple[str, ...]
    estimates: Array
    std: Array
    dropped: tuple[tuple[str, str], ...]
    points: Array
    planes: Array
    rms_before: float
    rms_after: float
    success: bool
    data_path: Path | None
    data_sha256: str | None
    angle_unit: str | None
    distances: tuple[tuple[int, int, float], ...]
    prior: dict | None
    run_id: str | None
    joint_effects: tuple[TiltEstimate, ...] = ()
    tilt_zeros: tuple[TiltEstimate, ...] = ()
    T_device_base: Array | None = None
    tracker_sha256: tuple[str, ...] = ()
    tracker_noise: float | None = None

    @property
    def length_measured(self) -> bool:
        """Whether its data measured a length (a stated distance, ball-bar pairs, tracker
        rows); without one the arm's scale rests on a nominal length
        (:mod:`robocal.identify.constraints.scale`)."""
        return bool(self.distances) or "distance" in self.kinds or self.T_device_base is not None

    @property
    def tilt(self) -> TiltCalibration | None:
        """The joint effects and channel zeros as the tilt figures use them (None without)."""
        if not self.joint_effects and not self.tilt_zeros:
            return None
        return TiltCalibration(self.joint_effects, self.tilt_zeros)

    def model_with_effects(self) -> Model:
        """The calibrated robot with the identified joint effects (``model.joint_effects``,
        :func:`robocal.model.joints.effects_from_values`): its predictions under the loads
        the effects were identified with (:data:`~robocal.identify.constraints.tilt_record.LOADS`)."""
        import dataclasses

        from robocal.model.joints import effect_of, effects_from_values

        values = {effect_of(e.name) or ("", ""): e.value for e in self.joint_effects}
        return dataclasses.replace(self.model, joint_effects=effects_from_values(self.model, values))

    def tracker_result(self, robot: Model | None = None) -> CalibrationResult:
        """The calibration as the object :func:`robocal.validate` takes, to judge it on
        tracker (position) rows: ``robot`` (default the calibrated one; :attr:`nominal` for
        the comparison) ending at the constraint point, predicted as the fit predicted its
        tracker rows — with the joints' elastic deflections under gravity only (compliance,
        radial compliance: :func:`~robocal.identify.constraints.figures.deflections`; the
        clearance and backlash tilt rows identify reach no position row) — in
        :attr:`T_device_base` (identity when the calibration had no tracker rows: validate
        with ``refit_frame=True`` then).  It carries no estimates and no covariance (the
        constraint fit's unknowns are not a tracker calibration's): the validation has no
        expected error, and a refitted frame's expectation counts no parameter uncertainty."""
        import dataclasses

        from robocal.identify.result import CalibrationResult

        robot = self.model if robot is None else robot
        elastic = tuple(dataclasses.replace(e, clearance_tilt=0.0, backlash=0.0) for e in robot.joint_effects)
        frame = np.eye(4) if self.T_device_base is None else self.T_device_base
        empty = np.zeros(0)
        return CalibrationResult(
            model=dataclasses.replace(robot, joint_effects=elastic), T_device_base=frame,
            measure="position", method="constraints", names=(), estimates=empty, nominal=empty,
            std=empty, covariance=np.zeros((0, 0)), correlation=np.zeros((0, 0)), dropped=(),
            residual_std=self.tracker_noise or self.rms_after, rms_before=self.rms_before,
            rms_after=self.rms_after, condition_number=math.nan, n=0, success=self.success,
            message="constraint calibration", iterations=0, seconds=0.0, run_id=self.run_id,
        )  # fmt: skip

    def fitted_tracker_file(self, path: Path) -> bool:
        """Whether ``path`` is (by its SHA-256) a tracker file this calibration was fitted to."""
        from robocal.identify.result_io import file_hash

        return bool(self.tracker_sha256) and file_hash(path) in self.tracker_sha256

    @property
    def robot_names(self) -> tuple[str, ...]:
        """The robot's identified parameters (not the scene's unknowns)."""
        return tuple(n for n in self.names if n in self.model.names)

    @property
    def unseen(self) -> tuple[str, ...]:
        """The robot's parameters the data cannot see at all (left nominal), chain order."""
        names = {n for n, reason in self.dropped if reason in _UNSEEN}
        return tuple(n for n in self.model.names if n in names)

    @property
    def poorly_identified(self) -> tuple[str, ...]:
        """The robot's parameters held at their start value for a too large σ."""
        names = {n for n, reason in self.dropped if reason not in _UNSEEN}
        return tuple(n for n in self.model.names if n in names)

    @property
    def base_steps(self) -> tuple[str, ...]:
        """The parameters placing the first joint in the base frame (before joint 1)."""
        out = []
        for s in self.model.steps:
            if s.joint is not None:
                break
            out.append(s.name)
        return tuple(out)

    @property
    def base_identified(self) -> bool:
        """Whether the data saw every free base parameter (tracker rows in mixed data)."""
        free = {s.name for s in self.model.steps if s.free}
        return not any(n in self.unseen for n in self.base_steps if n in free)

    def base_note(self) -> str:
        """One sentence: what stays nominal and why (for exports and compensation)."""
        if not self.unseen:
            return "the constraint data saw every free parameter of the chain"
        if self.base_identified:
            return (
                f"{len(self.unseen)} parameters the {', '.join(self.kinds)} data cannot see stay at their "
                f"nominal values ({', '.join(self.unseen)})"
            )
        return (
            f"the base frame is nominal: {', '.join(self.kinds)} data cannot see the robot's placement "
            f"(a rigid motion of the robot and its {_scene(self.kinds)} together changes no measurement), "
            f"and {len(self.unseen)} parameters it cannot see stay at their nominal values "
            f"({', '.join(self.unseen)}); "
            "the chain is calibrated relative to that nominal base"
        )


@dataclass(frozen=True)
class TrackerValidation:
    """A constraint calibration judged on tracker rows (:func:`validate_on_tracker`).

    Attributes:
        after: the calibrated robot's position errors (m; ``frame`` ``"calibrated"``: the
            device frame its tracker rows identified, ``"refit"``: fitted to these rows, each
            scored by a frame fitted on the others); no expected error (no covariance).
        before: the nominal robot's, its frame obtained the same way (None: not recorded).
        fitted_file: whether the rows are a tracker file the calibration was fitted to
            (in-sample: they flatter it).
        source: the tracker file's name (for a report; empty when not given).
    """

    after: ValidationStats
    before: ValidationStats | None
    fitted_file: bool = False
    source: str = ""


def validate_on_tracker(
    cal: ConstraintCalibration, data: Measurements, refit_frame: bool = False, fitted_file: bool = False
) -> TrackerValidation:
    """``cal``'s calibrated and nominal robots on tracker rows ``data`` (positions in the
    device frame), by :func:`robocal.validate` of :meth:`ConstraintCalibration.tracker_result`.

    Raises:
        ValueError: ``cal`` has no device frame (no tracker rows) and not ``refit_frame``;
            the rows do not fit the robot or cannot determine a frame.
    """
    import dataclasses

    from robocal.identify.validate import validate

    if cal.T_device_base is None and not refit_frame:
        raise ValueError(
            f"calibrated from {', '.join(cal.kinds)} rows without tracker rows: no device frame for "
            "these positions; refit it to them"
        )

    def judged(robot: Model) -> ValidationStats:  # no covariance: no expectation to state
        stats = validate(cal.tracker_result(robot), data, refit_frame=refit_frame)
        return dataclasses.replace(stats, expected_rms=None, parameter_rms=None, scatter=None)

    before = None if cal.nominal is None else judged(cal.nominal)
    return TrackerValidation(judged(cal.model), before, fitted_file)


def _scene(kinds: tuple[str, ...]) -> str:
    words = {"point": "fixed points", "plane": "planes", "distance": "ball-bar pairs"}
    return " and ".join(words.get(k, k) for k in kinds) or "scene"


def is_constraint_folder(directory: Path) -> bool:
    """Whether ``directory`` holds a constraint calibration (and no tracker result)."""
    directory = Path(directory)
    return (
        directory.is_dir()
        and (directory / CONSTRAINT_FILE).is_file()
        and not (directory / "result.json").is_file()
    )


def _array(doc: dict, key: str, width: int) -> Array:
    values = np.asarray(doc.get(key) or [], dtype=float).reshape(-1, width)
    if not np.all(np.isfinite(values)):
        raise ValueError(f"{key}: not finite numbers")
    return values


def _check_model(model: Model, names: tuple[str, ...], estimates: Array, where: Path) -> None:
    """The model must carry the recorded estimates (a hand-edited model.yaml is refused)."""
    values = dict(zip(model.names, model.values.tolist(), strict=True))
    for name, estimate in zip(names, estimates.tolist(), strict=True):
        v = values.get(name)
        if v is not None and not abs(v - estimate) <= 1e-9 * max(1.0, abs(estimate)):
            raise ValueError(
                f"{where / 'model.yaml'}: parameter {name} is {v!r}, {CONSTRAINT_FILE} says {estimate!r}: "
                "the model does not belong to this calibration; calibrate again"
            )


def _nominal(model: Model, doc: dict, names: tuple[str, ...]) -> Model | None:
    start = doc.get("start")
    if not isinstance(start, list) or len(start) != len(names):
        return None
    values = {n: float(v) for n, v in zip(names, start, strict=True) if n in model.names}
    if not all(math.isfinite(float(v)) for v in start):
        raise ValueError("start: not finite numbers")
    return _start_effects(model.with_values(values), names, start)


def _start_effects(robot: Model, names: tuple[str, ...], start: list) -> Model:
    """``robot`` with the joint effects the fit identified on its position rows back at
    their start values (zero, or the model's stated ones): ``model.yaml`` carries the
    identified compliances, the robot it started from (the "before" figures, the
    controller's model of compensate and filter) does not."""
    import dataclasses

    from robocal.model.joints import effect_of, effects_from_values

    started = {effect_of(n): float(v) for n, v in zip(names, start, strict=True) if effect_of(n) is not None}
    if not robot.joint_effects or not started:
        return robot
    values = {k: v for k, v in started.items() if k is not None}
    return dataclasses.replace(robot, joint_effects=effects_from_values(robot, values))


def load_constraint_calibration(directory: str | Path) -> ConstraintCalibration:
    """Read a constraint calibration folder (``model.yaml`` + ``constraints.json``).

    Raises:
        ValueError: a file missing, unreadable or not robocal's, or a ``model.yaml`` that
            does not carry the recorded estimates or run id (one line naming the file).
    """
    from robocal.model.files import load_model
    from robocal.model.yaml_files import ModelFileError
    from robocal.run_ids import read_run_id

    directory = Path(directory)
    path = directory / CONSTRAINT_FILE
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError, RecursionError) as err:  # not there, not UTF-8, not JSON, too deep
        raise ValueError(f"{path}: cannot read the constraint calibration: {err}") from None
    try:
        model = load_model(directory / "model.yaml")
    except (OSError, ValueError, ModelFileError) as err:
        raise ValueError(f"{directory / 'model.yaml'}: cannot read the calibrated model: {err}") from None
    if not isinstance(doc, dict) or doc.get("kind") != "constraints":
        raise ValueError(f"{path}: not a robocal constraint calibration")
    run_id = doc.get("run_id")
    if run_id is not None and read_run_id(directory / "model.yaml") not in (None, run_id):
        raise ValueError(
            f"{directory / 'model.yaml'}: written by another run than {path.name}; calibrate again"
        )
    try:
        names = tuple(str(n) for n in doc["names"])
        estimates = np.asarray(doc["estimates"], dtype=float).reshape(len(names))
        _check_model(model, names, estimates, directory)
        fields = _fields(doc, len(names))
        tilt = tilt_calibration_of(doc, names, estimates, fields["std"])
        calibration = ConstraintCalibration(
            directory=directory, model=model, nominal=_nominal(model, doc, names), names=names,
            estimates=estimates, run_id=run_id if isinstance(run_id, str) else None,
            joint_effects=tilt.effects, tilt_zeros=tilt.zeros, **fields,
        )  # fmt: skip
    except (KeyError, TypeError, ValueError) as err:
        raise ValueError(f"{path}: not a robocal constraint calibration ({err})") from None
    _check_digest(directory / "model.yaml", doc.get("model_sha256"))  # after the estimates' named check
    return calibration


def _fields(doc: dict, n: int) -> dict:
    """The record's plain fields (checked types)."""
    data = doc.get("data")
    unit = doc.get("angle_unit")
    return dict(
        kinds=tuple(str(k) for k in doc.get("measurements", [])),
        std=np.asarray(doc.get("std") or [math.nan] * n, dtype=float).reshape(n),
        dropped=tuple((str(d["name"]), str(d["reason"])) for d in doc.get("not_identifiable", [])),
        points=_array(doc, "points_m", 3),
        planes=_array(doc, "planes", 4),
        rms_before=float(doc.get("rms_before_m", math.nan)),
        rms_after=float(doc.get("rms_after_m", math.nan)),
        success=bool(doc.get("success", False)),
        data_path=None if data is None else Path(str(data)),
        data_sha256=doc.get("data_sha256") if isinstance(doc.get("data_sha256"), str) else None,
        angle_unit=unit if unit in ("rad", "deg") else None,
        distances=tuple((int(a), int(b), float(d)) for a, b, d in doc.get("distances_m", [])),
        prior=doc.get("prior") if isinstance(doc.get("prior"), dict) else None,
        **_tracker_fields(doc),
    )


def _tracker_fields(doc: dict) -> dict:
    """The device frame (only when tracker rows identified it), the tracker files' digests
    and the tracker rows' noise."""
    kinds = doc.get("measurements", [])
    frame = _array(doc, "T_device_base", 4) if "tracker" in kinds and "T_device_base" in doc else None
    if frame is not None and (frame.shape != (4, 4) or not np.allclose(frame[3], [0, 0, 0, 1])):
        raise ValueError("T_device_base: not a (4, 4) rigid transform")
    noise = (doc.get("noise_per_kind_m") or {}).get("tracker")
    return dict(
        T_device_base=frame,
        tracker_sha256=tuple(str(t["sha256"]) for t in doc.get("tracker_data", [])),
        tracker_noise=None if noise is None else float(noise),
    )


def _check_digest(model_path: Path, digest: object) -> None:
    """Refuse a ``model.yaml`` whose SHA-256 is not the one the calibration recorded: an
    edit of any parameter (estimated or not) would otherwise reach exports and commands.
    Folders written before the digest carry none; the estimates' check still applies."""
    from robocal.identify.result_io import file_hash

    if digest is not None and file_hash(model_path) != digest:
        raise ValueError(
            f"{model_path}: changed since the calibration wrote it (its SHA-256 is not the one in "
            f"{CONSTRAINT_FILE}); calibrate again, or export a model file of your own"
        )
