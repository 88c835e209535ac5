"""The use case "calibrate constraint files into a folder" (fixed points, planes, distances:
no tracker), shared by ``robocal calibrate`` and the GUI's runs.

:func:`calibrate_constraint_files` reads the files (constraint files and tracker files of one
fit), calibrates the robot with :func:`robocal.identify.constraints.fit.calibrate_constraints`
under the default prior, saves ``model.yaml`` and ``constraints.json`` as one transaction and,
when asked, writes the kind's HTML report; it prints nothing.  Every refusal is a
:class:`~robocal.workflow.request.CalibrateFileError` of one line naming the file or field.
"""

from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from robocal.choices import AngleUnit, LengthUnit
from robocal.workflow.request import CalibrateFileError, Progress

if TYPE_CHECKING:
    from robocal.identify.constraints.fit import ConstraintFigures, ConstraintResult
    from robocal.measure.constraints.data_set import ConstraintSet
    from robocal.model.chain import Model

__all__ = [
    "CONSTRAINT_RESULT_FILE",
    "ConstraintRequest",
    "ConstraintRun",
    "calibrate_constraint_files",
    "constraint_model",
    "each_kind_lines",
    "parse_distances",
    "read_constraint_file",
    "read_mixed",
    "tilt_rows_only",
]

#: the constraint calibration's record beside model.yaml
CONSTRAINT_RESULT_FILE = "constraints.json"

#: the share of the run done when each stage starts (``progress(stage, fraction)``)
_STAGE_STARTS = {"read": 0.0, "calibrate": 0.05, "save": 0.88, "report": 0.92}


@dataclass(frozen=True)
class ConstraintRequest:
    """Calibrate constraint files (and tracker files fitted with them) into a folder.

    Attributes:
        data: the files of one fit; the first constraint file names the calibration.
        model: the model to calibrate (a catalog robot's complete position model, or a model
            file's chain as it is).
        out: the folder for ``model.yaml`` and ``constraints.json`` (and ``report.html``).
        angle_unit, length_unit: the files' joint unit and the tracker files' length unit.
        distances: known distances ``(point a, point b, metres)`` between fixed points.
        level: 1 identifies the joint offsets, 2 the kinematic parameters.
        noise_m: the constraint rows' stated noise (1σ, m; a start: σ̂ weighs the fit).
        report: also write ``report.html`` (the kind's figures on the calibration file).
        progress: ``progress(stage, fraction)`` as each stage starts, or None.
        names: what ``constraints.json`` records as each of ``data``'s path (empty: the
            paths as given; the GUI gives the uploads' own file names, never its server paths).
        tilt_kinds: the joint effects the tilt rows identify.
        effects: the joint effects every position row carries (fixed points, planes,
            distances, tracker points: ``compliance``, ``radial``), identified with the
            geometry under the gravity loads of the model's link masses (refused without);
            a compliance is one unknown with the tilt rows' own.  Empty (the default): none
            fitted; a model that states its compliances predicts the rows with them, held.
        frames: the robot's own chain (a catalog robot's published chain) when ``model`` is
            another chain of it (its complete model): the joint frames a file's
            ``mount_r*_deg`` angles are stated in, and the joint effects' load moments are
            taken at.  None: ``model``'s own.
    """

    data: tuple[Path, ...]
    model: Model
    out: Path
    angle_unit: AngleUnit = "rad"
    length_unit: LengthUnit = "m"
    distances: tuple[tuple[int, int, float], ...] = ()
    level: int = 2
    noise_m: float = 1e-4
    report: bool = False
    progress: Progress | None = field(default=None, compare=False)
    names: tuple[str, ...] = ()
    tilt_kinds: tuple[str, ...] = ("clearance", "backlash", "compliance")  # tilt rows' joint effects
    frames: Model | None = None
    effects: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        if self.names and len(self.names) != len(self.data):
            raise CalibrateFileError("names", f"{len(self.names)} names for {len(self.data)} files")

    def recorded(self, path: Path) -> str:
        """The name ``constraints.json`` records for ``path`` (one of :attr:`data`)."""
        if not self.names:
            return str(path)
        return self.names[self.data.index(path)]


@dataclass(frozen=True)
class ConstraintRun:
    """A calibrated constraint file: the folder, the fit and what the front ends show.

    Attributes:
        folder: where ``model.yaml`` and ``constraints.json`` were saved.
        result: the fit.
        data: the merged measurements (all files).
        before: the kind's figures of the model calibrated from, on ``data`` (m).
        each_kind: mixed data: what each kind alone identifies beside the union (lines).
    """

    folder: Path
    result: ConstraintResult
    data: ConstraintSet
    before: ConstraintFigures
    each_kind: tuple[str, ...] = ()

    def summary_lines(self) -> list[str]:
        """The fit's summary (mm, deg)."""
        return self.result.summary_lines()


def constraint_model(
    robot: Model, paths: tuple[Path, ...] | list[Path], *, from_catalog: bool, chain: str | None = None
) -> tuple[Model, Model | None]:
    """The model a fit of the constraint files ``paths`` calibrates, and the chain their
    joint-frame sensor mounts are stated in (``ConstraintRequest.frames``), as ``robocal
    calibrate`` and the GUI choose them: a catalog robot's complete position model, its link
    rotations freed when a file holds tilt rows (sensors read the angles a position model
    leaves to the tool); ``chain="catalog"`` with inclinometer files alone: the published
    chain with its base tilt free; a model file's chain (``from_catalog`` False) as it is.

    Raises:
        ValueError: the robot has no complete model (one line naming it).
    """
    from robocal.identify.constraints.tilt_rows import link_rotations_free, tilt_chain
    from robocal.measure.constraints.data import has_tilt_rows
    from robocal.model.complete import calibration_model

    frames = robot if from_catalog else None  # the robot's own chain (its mount_r*_deg frames)
    if chain == "catalog" and tilt_rows_only(paths):
        return tilt_chain(robot), frames
    if chain == "complete" or (chain is None and from_catalog):
        try:
            model = calibration_model(robot, "position")
        except ValueError as err:
            raise ValueError(f"no complete model of {robot.name}: {err}") from None
        if any(has_tilt_rows(p) for p in paths):
            model = link_rotations_free(model)
        return model, frames
    return robot, frames


def tilt_rows_only(paths: tuple[Path, ...] | list[Path]) -> bool:
    """Whether every file of the fit holds inclinometer readings only: then ``--chain catalog``
    calibrates the catalog chain with the base's tilt free
    (:func:`robocal.identify.constraints.tilt_rows.tilt_chain`).  Not the default: a catalog
    chain need not carry every tilt of a real robot's links (the UR10's DH chain has no
    twist between its parallel joints; a tilt file of a true UR10 drawn around its complete
    model is left at 0.03° there); the default's complete model with its link rotations
    freed spans the catalog chain's tilt columns and the complete model's
    (:func:`~robocal.identify.constraints.tilt_rows.link_rotations_free`).

    The sensors are the same in every chain: a mount stated at home (``home_r*_deg``) is
    resolved against the calibrated chain's nominal robot at home, and joint-frame angles
    (``mount_r*_deg``, none: the joint frame) are the robot's own chain's
    (:mod:`robocal.measure.constraints.mounts`), so the same tilt file fitted alone or with
    a tracker file (the complete position model) describes the same sensors."""
    from robocal.measure.constraints.data import tilt_only

    return bool(paths) and all(tilt_only(p) for p in paths)


def parse_distances(items: list[str] | None) -> tuple[tuple[int, int, float], ...]:
    """``0,1=50mm`` strings as ``(a, b, metres)``; ValueError naming the bad one."""
    from robocal.measure.constraints.data import parse_distance

    return tuple(parse_distance(item) for item in items or [])


def read_constraint_file(
    path: Path, dof: int, angle_unit: str, distances: Any, sigma: float
) -> ConstraintSet:
    """One constraint file's rows; CalibrateFileError naming the file, row or column."""
    from robocal.measure.constraints.data import ConstraintFileError, read_constraints

    if angle_unit not in ("rad", "deg"):
        raise CalibrateFileError("angle_unit", f"{angle_unit!r}: rad or deg")
    try:
        return read_constraints(path, dof, angle_unit=angle_unit, distances=distances, sigma=sigma)
    except ConstraintFileError as err:
        raise CalibrateFileError("data", str(err)) from None


def _read_tracker(
    path: Path, model: Model, angle_unit: AngleUnit, length_unit: LengthUnit, sigma: float
) -> ConstraintSet:
    """A tracker file's rows (joint values, x y z in the device frame) as constraint-set rows."""
    from robocal.measure.constraints.data_set import ConstraintSet
    from robocal.measure.dataset.read import read_measurements
    from robocal.measure.measurements import MeasurementFileError

    try:
        m = read_measurements(path, length_unit=length_unit, angle_unit=angle_unit, model=model)
    except MeasurementFileError as err:
        raise CalibrateFileError("data", str(err)) from None
    if m.position is None:
        problem = "neither constraint columns (point, plane, pair) nor tracker positions (x, y, z)"
        raise CalibrateFileError("data", problem, str(path))
    none = -np.ones(len(m.q), dtype=np.intp)
    return ConstraintSet(m.q, none, none, position=m.position, sigma=sigma)


def read_mixed(
    paths: list[Path] | tuple[Path, ...], model: Model, angle_unit: AngleUnit, length_unit: LengthUnit,
    stated: Any, sigma: float,
) -> tuple[Path, list[Path], ConstraintSet]:  # fmt: skip
    """The files of one fit: ``(first constraint file, tracker files, merged set)``.  The
    constraint files' points and planes are numbered in the order given (the known distances
    name them so); the tracker files' rows have their own noise (estimated in the fit)."""
    from robocal.measure.constraints.data import constraint_kind
    from robocal.measure.constraints.data_set import merge_sets

    for path in paths:
        if not path.is_file():
            raise CalibrateFileError("data", "no such file", str(path))
    constraint = [p for p in paths if constraint_kind(p) is not None]
    trackers = [p for p in paths if p not in constraint]
    if not constraint:
        problem = (
            "several files calibrate together when one is a constraint file (a point, plane or pair column)"
        )
        raise CalibrateFileError("data", problem)
    stated = list(stated)
    one = stated if len(constraint) == 1 else []
    sets = [read_constraint_file(p, model.dof, angle_unit, one, sigma) for p in constraint]
    sets += [_read_tracker(p, model, angle_unit, length_unit, sigma) for p in trackers]
    try:
        data = merge_sets(*sets)
    except ValueError as err:
        raise CalibrateFileError("data", str(err)) from None
    if stated and len(constraint) > 1:  # the merged numbering: the first file's points first
        if max(max(a, b) for a, b, _ in stated) >= data.n_points:
            raise CalibrateFileError("distances", f"the files have points 0..{data.n_points - 1} only")
        pairs = np.array([(a, b) for a, b, _ in stated], dtype=np.intp)
        data = dataclasses.replace(data, point_pairs=pairs, point_length=np.array([d for *_, d in stated]))
    return constraint[0], trackers, data


def each_kind_lines(model: Model, data: ConstraintSet, deflected: bool = False) -> list[str]:
    """What each kind alone could identify beside what the union does (mixed data);
    ``deflected``: the position rows carried joint effects too (not the tilt rows' alone)."""
    from robocal.identify.constraints.fit import kind_identifiable

    union = set(kind_identifiable(model, data)[0])
    lines = []
    groups = (
        ("constraint rows", data.constrained),
        ("tilt rows", data.tilted),
        ("tracker rows", data.tracked),
    )
    for kind, rows in ((kind, rows) for kind, rows in groups if rows.any()):
        try:
            alone = set(kind_identifiable(model, data.select(rows))[0])
        except ValueError as err:  # too few rows of the kind for its start values
            lines.append(f"{kind} alone: {err}")
            continue
        missing = sorted(union - alone, key=list(model.names).index)
        line = f"{kind} alone ({int(rows.sum())} poses) identify {len(alone)} of the union's {len(union)}"
        line += f"; not {', '.join(missing)}" if missing else ""
        alone_sees = kind == "tilt rows" and not deflected  # else the position rows see them too
        lines.append(line + ("; and the joint effects (only these rows see them)" if alone_sees else ""))
    return lines


def _groups(data: ConstraintSet) -> int:
    """How many row groups (constraint, tilt, tracker rows) ``data`` mixes."""
    return sum(bool(rows.any()) for rows in (data.constrained, data.tilted, data.tracked))


def calibrate_constraint_files(request: ConstraintRequest) -> ConstraintRun:
    """Calibrate ``request.data`` into ``request.out`` (see :class:`ConstraintRequest`).

    The fit is the MAP estimate under :class:`~robocal.identify.constraints.model.NominalPrior`'s
    default (lengths σ 0.3 mm, angles σ 5 mrad about the nominal geometry; the measurements
    weighted by σ̂ of a least-squares fit): on the real Panda's ball-in-socket recordings,
    leave-one-placement-out cross-validation put the held-out spread at 0.94 mm with it
    against 1.04 mm by least squares (benchmarks/bench_ball_in_socket.py)."""
    from robocal.identify.constraints.fit import calibrate_constraints, constraint_figures
    from robocal.identify.constraints.model import NominalPrior
    from robocal.identify.options import Pruning

    if request.out.exists() and not request.out.is_dir():
        raise CalibrateFileError("out", "is a file; give a directory", str(request.out))
    _stage(request, "read")
    model, paths = request.model, list(request.data)
    _check_effects(model, request.effects)
    first, trackers, data = read_mixed(
        paths, model, request.angle_unit, request.length_unit, request.distances, request.noise_m
    )
    effects = _position_effects(request.effects, data)
    if request.frames is not None:  # joint-frame mounts: the robot's own chain's, stated at home
        from robocal.measure.constraints.mounts import mounts_at_home

        data = mounts_at_home(data, request.frames)
    _stage(request, "calibrate")
    try:
        result = calibrate_constraints(model, data, level=request.level, pruning=Pruning(), known_noise=False,
                                       prior=NominalPrior(), tilt_kinds=request.tilt_kinds,
                                       frames=request.frames, effects=effects)  # fmt: skip
    except ValueError as err:
        raise CalibrateFileError("data", str(err), ", ".join(str(p) for p in paths)) from None
    _stage(request, "save")
    _save(result, request, first, trackers)
    each = each_kind_lines(model, data, bool(result.position_effects)) if _groups(data) > 1 else []
    if request.report:
        _stage(request, "report")
        _write_report(request.out, first, request.angle_unit)
    return ConstraintRun(request.out, result, data, constraint_figures(model, data), tuple(each))


def _check_effects(model: Model, effects: tuple[str, ...]) -> None:
    """The position rows' joint effects need the model's link masses: refused before the
    files are read (CalibrateFileError on ``effects``)."""
    from robocal.identify.constraints.position_effects import check_effect_kinds

    try:
        check_effect_kinds(model, effects)
    except ValueError as err:
        raise CalibrateFileError("effects", str(err)) from None


def _position_effects(effects: tuple[str, ...], data: ConstraintSet) -> tuple[str, ...]:
    """``effects`` when ``data`` has position rows (points, planes, distances, tracker
    points); none for tilt rows alone (their compliance is a tilt kind), where a radial
    compliance, which only a position row carries here, is refused by name."""
    if data.constrained.any() or data.tracked.any():
        return effects
    if "radial" in effects:
        raise CalibrateFileError(
            "effects", "radial compliance is fitted on position rows (points, planes, distances, tracker "
            "points); these files hold tilt rows only"
        )  # fmt: skip
    return ()


def _stage(request: ConstraintRequest, key: str) -> None:
    if request.progress is not None:
        request.progress(key, _STAGE_STARTS[key])


def _result_doc(result: ConstraintResult, data_path: Path, stated: Any, recorded: str) -> dict:
    """constraints.json's content (``recorded``: the name of ``data_path`` to record)."""
    from robocal.identify.result_io import file_hash

    tilt = {} if result.tilt is None else result.tilt.to_doc()  # the joint effects, the channels' zeros
    return tilt | {
        "kind": "constraints",
        "measurements": list(result.kinds),
        "data": recorded,
        "data_sha256": file_hash(data_path),
        "distances_m": [[a, b, d] for a, b, d in stated],
        "success": result.success,
        "names": list(result.names),
        "estimates": result.estimates.tolist(),
        "start": result.start.tolist(),  # the nominal model: the report's and validate's "before"
        "std": result.std.tolist(),
        "not_identifiable": [{"name": d.name, "reason": d.reason} for d in result.dropped],
        "points_m": result.points.tolist(),
        "planes": result.planes.tolist(),
        "T_device_base": result.T_device_base.tolist(),
        "rms_before_m": result.rms_before,
        "rms_after_m": result.rms_after,
        "prior": None
        if result.prior is None
        else {"length_std_m": result.prior.length_std, "angle_std_rad": result.prior.angle_std},
        "summary": result.summary_lines(),
    }


def _save(result: ConstraintResult, request: ConstraintRequest, first: Path, trackers: list[Path]) -> None:
    """model.yaml and constraints.json, all or nothing (the tracker files fitted with the
    first constraint file recorded by name and SHA-256)."""
    from robocal.folder_lock import FolderBusyError
    from robocal.identify.result_io import file_hash
    from robocal.model.files import save_model
    from robocal.outdir import transaction

    doc = _result_doc(result, first, request.distances, request.recorded(first))
    doc["angle_unit"] = request.angle_unit
    if trackers:
        doc["tracker_data"] = [{"path": request.recorded(p), "sha256": file_hash(p)} for p in trackers]
        doc["noise_per_kind_m"] = dict(result.kind_sigma)
    out = request.out
    try:
        with transaction(out, ("model.yaml", CONSTRAINT_RESULT_FILE)) as stage:
            save_model(result.model, stage.path / "model.yaml", run_id=stage.run_id)
            # the digest lets every reader refuse a model.yaml edited after the calibration
            doc |= {"run_id": stage.run_id, "model_sha256": file_hash(stage.path / "model.yaml")}
            text = json.dumps(doc, indent=1) + "\n"
            (stage.path / CONSTRAINT_RESULT_FILE).write_text(text)
    except FolderBusyError as err:
        raise CalibrateFileError("out", str(err)) from None


def _write_report(out: Path, first: Path, angle_unit: str) -> Path:
    """``out``/report.html: the kind's figures of the saved calibration on its first
    constraint file (as ``robocal report`` of the folder writes it)."""
    from robocal.evaluate.report.constraint_collect import collect_constraint_report
    from robocal.evaluate.report.constraint_sections import write_constraint_report
    from robocal.identify.constraints.result import load_constraint_calibration

    cal = load_constraint_calibration(out)
    data = read_constraint_file(first, cal.model.dof, angle_unit, list(cal.distances), 1e-4)
    why = ("no held-out file: calibrate one placement and judge another with robocal report --test-data",)
    report = collect_constraint_report(cal, data, None, sources=(first.name, ""), missing=why)
    return write_constraint_report(report, out / "report.html")
