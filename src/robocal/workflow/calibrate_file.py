"""The one use case "calibrate a measurement file into a folder": read the file, state its
noise, split off the held-out rows, choose the model, calibrate, record the provenance,
validate, save (and write the report).  ``robocal calibrate``, the GUI's runs and
:func:`robocal.study.run_fleet` all call :func:`calibrate_file`, so they make the same checks
and save the same files; each front end only turns the request's fields into its own words
(options, controls) and shows the progress and the result its own way."""

from __future__ import annotations

import dataclasses
import warnings
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal

import numpy as np

from robocal.workflow.request import STAGES, CalibrateFileError, CalibrateRequest, SavedRun

if TYPE_CHECKING:
    from robocal.identify.provenance import Provenance
    from robocal.identify.result import CalibrationResult
    from robocal.identify.validate import ValidationStats
    from robocal.measure.measurements import Measurements
    from robocal.model.chain import Model

__all__ = ["calibrate_file", "check_noise", "check_out", "split"]


def calibrate_file(request: CalibrateRequest) -> SavedRun:
    """Calibrate ``request.data`` into ``request.out`` (see :class:`CalibrateRequest`).

    Every refusal is a :class:`CalibrateFileError` of one line naming the file or the
    request's field, raised before anything is written; the folder is written as one
    transaction (all files, or none)."""
    if request.out is not None:
        check_out(request.out, request.force)
    check_noise(request.noise_m)
    _stage(request, "read")
    data = _read(request)
    data = _with_noise(data, request.noise_m, request.data)
    train, test = split(data, request.train_n, request.seed)
    model = _model_to_calibrate(request, data)
    _stage(request, "calibrate")
    result = _calibrate(model, train, request)
    result, provenance = _record(result, request, train)
    validation = None
    if test is not None:
        _stage(request, "validate")
        validation, result = _validate(result, test)
    if request.out is not None:
        _stage(request, "save")
        result = _save(result, request, train, test)
    return SavedRun(request.out, result, validation, provenance, train, test)


def check_out(out: Path, force: bool) -> None:
    """Refuse an output that is a file, holds a result (without ``force``) or is being written."""
    from robocal.folder_lock import FolderBusyError, check_not_busy

    if out.exists() and not out.is_dir():
        raise CalibrateFileError(
            "out", "is a file; give a directory for model.yaml and result.json", str(out)
        )
    if (out / "result.json").exists() and not force:
        raise CalibrateFileError("out", "already holds a calibration result; replace it with force", str(out))
    try:  # before the work: a second writer learns it at once, not after the calibration
        check_not_busy(out)
    except FolderBusyError as err:
        raise CalibrateFileError("out", str(err)) from None


def check_noise(noise_m: float | None) -> None:
    """Refuse a stated noise (1σ per axis, m) outside what a measuring device gives."""
    from robocal.measure.measurements import MAX_SIGMA, MIN_SIGMA

    if noise_m is not None and not MIN_SIGMA <= noise_m <= MAX_SIGMA:
        problem = (
            f"a standard deviation between {MIN_SIGMA * 1e3:g} mm and {MAX_SIGMA * 1e3:g} mm, e.g. 0.03mm"
        )
        raise CalibrateFileError("noise_m", problem, f"noise {noise_m * 1e3:g} mm")


def split(data: Measurements, train_n: int | None, seed: int) -> tuple[Measurements, Measurements | None]:
    """The calibration rows and the held-out rows (None): ``train_n`` random rows (drawn with
    ``seed``), else the file's ``set`` column, else every row."""
    if train_n is not None:
        if not 0 < train_n < data.n:
            problem = f"between 1 and {data.n - 1} calibration poses (the file has {data.n} rows)"
            raise CalibrateFileError("train_n", problem, f"train_n {train_n}")
        drawn = data.with_split(train_n, seed=seed)
        return drawn.split_rows("train"), drawn.split_rows("test")
    if data.split is not None and "test" in set(data.split.tolist()):
        return data.split_rows("train"), data.split_rows("test")
    return data, None


def _stage(request: CalibrateRequest, key: str) -> None:
    if request.progress is not None:
        request.progress(key, next(start for k, _, start in STAGES if k == key))


def _notify(request: CalibrateRequest, kind: str, text: str) -> None:
    if request.notify is not None:
        request.notify(kind, text)


def _read(request: CalibrateRequest) -> Measurements:
    """The file's rows with positions; the reader's warnings passed on as they come."""
    from robocal.console import input_problem
    from robocal.measure.dataset.read import read_measurements
    from robocal.measure.measurements import MeasurementFileError, MeasurementWarning

    path = request.data
    if path.is_dir():
        raise CalibrateFileError("data", "is a directory; give a measurement file", str(path))
    problem = input_problem(path, "measurement file")
    if problem is not None:
        raise CalibrateFileError("data", problem)
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", MeasurementWarning)
            data = read_measurements(path, model=request.model, **request.reader.as_kwargs())
    except (MeasurementFileError, ValueError) as err:
        raise CalibrateFileError("data", str(err)) from None
    for w in caught:
        if isinstance(w.message, MeasurementWarning):
            _notify(request, "warning", str(w.message))
    if "rows_left_out" in data.metadata:
        _notify(
            request, "dropped", f"{data.metadata['rows_left_out']} incomplete row(s) of {path.name} left out"
        )
    if data.position is None:
        problem = "no measured positions (columns x, y, z) to calibrate against; map the file's columns"
        example = "with e.g. columns={'x': 'meas_x'} for each of x, y, z"
        raise CalibrateFileError("data", f"{problem} {example}", str(path))
    return data


def _with_noise(data: Measurements, noise_m: float | None, path: Path) -> Measurements:
    """``data`` with the stated σ (m) on every row."""
    if noise_m is None:
        return data
    if data.sigma is not None:
        raise CalibrateFileError("noise_m", f"{path} has its own sigma columns; leave the noise out")
    return dataclasses.replace(data, sigma=np.full((data.n, 3), noise_m))


def _model_to_calibrate(request: CalibrateRequest, data: Measurements) -> Model:
    """The complete model built from the robot's joint geometry (``chain`` complete, or None
    for a catalog robot) or the model's own chain, announced in one line (``model``)."""
    from robocal.model.complete import calibration_model

    model, chain, from_catalog = request.model, request.chain, request.from_catalog
    effective: Literal["position", "pose"] = "pose" if data.orientation is not None else "position"
    if request.fit.measure in ("position", "pose"):
        effective = request.fit.measure  # type: ignore[assignment]  # checked just above
    if chain == "complete" or (chain is None and from_catalog):
        try:
            built = calibration_model(model, effective)
        except ValueError as err:
            raise CalibrateFileError("model", f"no complete model of {model.name}: {err}") from None
        option = "" if from_catalog and chain is None else " (--chain complete)"
        plain = " (--chain catalog: the catalog's chain)" if from_catalog else ""
        _notify(request, "model", f"model: {built.name}, the complete model built from {model.name}'s joint "
                f"geometry for {effective} measurements{option}{plain}")  # fmt: skip
        return built
    what = "the catalog's chain (--chain catalog)" if from_catalog else "the model file's chain"
    # its parameterisation warnings come with the calibration's (calibrate checks every chain)
    _notify(request, "model", f"model: {model.name}, {what} as it is")
    return model


def _calibrate(model: Model, train: Measurements, request: CalibrateRequest) -> CalibrationResult:
    """The fit; the data's problem as one line naming the file."""
    from robocal.identify.calibrate import calibrate

    start, end = (start for key, _, start in STAGES if key in ("calibrate", "validate"))
    report = request.progress
    # the engine's share of the fit done, as the run's share between the calibrate stage's
    # start and the next stage's
    engine = None if report is None else (lambda f: report("calibrate", start + (end - start) * f))
    try:
        return calibrate(
            model, train, **request.fit.as_kwargs(), progress=engine, iteration=request.iteration
        )
    except ValueError as err:
        message = str(err)  # the data's problem: name the file unless the message does
        raise CalibrateFileError(
            "data", message if str(request.data) in message else f"{request.data}: {message}"
        ) from None


def _record(
    result: CalibrationResult, request: CalibrateRequest, train: Measurements
) -> tuple[CalibrationResult, Provenance]:
    """The result with its provenance: the data file, its hash, the reader options and the split."""
    from robocal.identify.provenance import Provenance
    from robocal.identify.result_io import file_hash

    path = request.data
    sha256 = file_hash(path)
    reader = request.reader.as_kwargs()
    provenance = Provenance.record(path, sha256, reader, request.noise_m, request.train_n, request.seed)
    recorded = result.with_provenance(
        provenance, data_file=str(path), data_sha256=sha256, train_n=train.n, seed=request.seed
    )
    return recorded, provenance


def _validate(result: CalibrationResult, test: Measurements) -> tuple[ValidationStats, CalibrationResult]:
    """The held-out statistics and the result carrying them; a hybrid's stored physics-only fit
    (what a URDF or UR kinematics export carries) scored on the same poses, so that an export
    can state both errors."""
    from robocal.compensate.export import kinematic_part
    from robocal.identify.validate import validate

    validation = validate(result, test)
    result = result.with_validation(validation.to_dict())
    record: Any = result.records.get("physics_only")
    if not isinstance(record, dict) or result.model.residual is None:
        return validation, result
    from robocal.identify.result import CalibrationResult  # lazy, as the module's imports

    kinematic = kinematic_part(result).calibrated  # a result here: the hybrid's stored physics-only fit
    frame = kinematic.frame if isinstance(kinematic, CalibrationResult) else None
    physics = validate(kinematic, test, frame=frame)  # its held-out mean only: no expected error
    held_out = {"held_out_mean_mm": physics.mean * 1e3, "held_out_n": physics.n}
    return validation, result.with_records(physics_only={**record, **held_out})


def _save(
    result: CalibrationResult, request: CalibrateRequest, train: Measurements, test: Measurements | None
) -> CalibrationResult:
    """model.yaml, measurement_model.yaml, result.json (and report.html): all or nothing."""
    from robocal.folder_lock import FolderBusyError

    assert request.out is not None

    def write_report_too(stage_dir: Path) -> None:
        from robocal.evaluate.report import write_report
        from robocal.run_ids import read_run_id

        _stage(request, "report")
        run_id = read_run_id(stage_dir / "result.json")  # the report is one file of this result
        write_report(result, stage_dir / "report.html", data=train, test_data=test, run_id=run_id)

    try:
        return result.save(request.out, also=write_report_too if request.report else None)
    except FolderBusyError as err:
        raise CalibrateFileError("out", str(err)) from None
