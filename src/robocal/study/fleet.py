"""Fleet calibrations: one robot per measurement file of a folder (:func:`run_fleet`)."""

from __future__ import annotations

import hashlib
import os
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from robocal.model.chain import Model
from robocal.study.cluster import Executor, check_workers, executor_for
from robocal.study.config import StudyError
from robocal.study.table import Table, remove_table
from robocal.study.tasks import FIT_COLUMNS, error_stats, fill_fit

#: Columns of ``fleet.csv``.
FLEET_COLUMNS = (
    "file",
    "sha256",
    "status",
    "message",
    "n_poses",
    "n_params",
    *FIT_COLUMNS,
    "seconds",
    "result_dir",
)


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
    """Read, calibrate and validate one measurement file (:func:`robocal.workflow.calibrate_file`,
    as ``robocal calibrate``; the result is saved where the table is): ``(row,
    CalibrationResult | None)``."""
    from robocal.workflow import CalibrateRequest, FitOptions, ReaderOptions, calibrate_file

    t0 = time.perf_counter()
    row: dict[str, Any] = dict.fromkeys(FLEET_COLUMNS, "")
    row["file"] = item.name
    try:
        row["sha256"] = _sha256(item.path)
        fit = FitOptions.from_kwargs(item.calibrate_options)
        chain = "complete" if item.complete else None
        request = CalibrateRequest(
            item.path, item.model, None, ReaderOptions(**item.read_options), fit, chain
        )
        run = calibrate_file(request)
        result = run.result
        fill_fit(row, result, run.train.n, 0.0)
        row.pop("iterations", None)
        row.pop("dropped", None)
        if run.validation is not None:
            row.update(error_stats(run.validation.errors))
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


def run_fleet(  # noqa: PLR0913 - public keyword options, documented in README and docs/dask.md
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
    if scheduler is None and client is None and workers:
        check_workers(workers)  # before anything is written
    directory = Path(directory)
    files = _measurement_files(directory, pattern)
    out = Path(out) if out is not None else directory / "calibrated"
    table_path = out / "fleet.csv"
    files = [p for p in files if p.resolve() != table_path.resolve()]  # --out DIR: not its own table
    if not files:
        raise StudyError(f"{directory}: no measurement files match {pattern!r}")
    _check_names(directory, files, out, table_path)  # before anything is written
    table = _open_table(table_path, force)
    names = {p: str(p.relative_to(directory)) for p in files}
    todo, skipped, resumed = _fleet_todo(files, names, table)
    items = [
        _FleetItem(p, names[p], model, dict(read_options or {}), dict(calibrate_options or {}), complete)
        for p in todo
    ]
    executor = executor_for(workers, scheduler, client)

    def report(finished: int) -> None:
        if progress is not None:
            progress(resumed + finished, len(files))

    t1 = time.perf_counter()
    try:
        calibrated, errors = _calibrate_files(executor, items, out, table, report)
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


def _open_table(path: Path, force: bool) -> Table:
    """The fleet table (its folder made); ``force`` starts it over when robocal wrote it
    (a user's file of that name is refused, never deleted)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    if force:
        remove_table(path, FLEET_COLUMNS)
    return Table(path, FLEET_COLUMNS, "file")


def _measurement_files(directory: Path, pattern: str) -> list[Path]:
    """The files of ``directory`` matching ``pattern``, sorted; none is refused."""
    if not directory.is_dir():
        raise StudyError(f"{directory} is not a directory")
    files = sorted(p for p in directory.glob(pattern) if p.is_file())
    if not files:
        raise StudyError(f"{directory}: no files match {pattern!r}")
    return files


def _check_names(directory: Path, files: Sequence[Path], out: Path, table_path: Path) -> None:
    """Refuse files whose result folders (``OUT/<file stem>``) would clash with each other or
    with the fleet table, or would not be a plain folder of ``OUT`` (``...csv``: ``OUT/..``;
    a hidden name; a link to elsewhere)."""
    stems = [p.stem for p in files]
    for path, stem in zip(files, stems, strict=True):
        if stem in ("", ".", "..") or stem.startswith(".") or os.sep in stem:
            raise StudyError(
                f"{path}: its result folder would be {stem!r}, not a plain folder inside {out}; "
                "rename the file (or leave it out with --pattern)"
            )
        if os.path.islink(out / stem):
            raise StudyError(
                f"{out / stem}: a symbolic link where {path.name}'s result folder goes; robocal does "
                "not write through it: remove it or choose another --out"
            )
    twice = sorted({s for s in stems if stems.count(s) > 1})
    if twice:
        raise StudyError(
            f"{directory}: several files share the name(s) {', '.join(twice)} (their results would clash)"
        )
    if table_path.name in stems:  # its result folder would be the table itself
        clash = files[stems.index(table_path.name)]
        raise StudyError(f"{clash}: a file named like the fleet table {table_path.name}; rename it")


def _fleet_todo(
    files: Sequence[Path], names: Mapping[Path, str], table: Table
) -> tuple[list[Path], list[str], int]:
    """``(files to calibrate, names of files changed since their calibration, files done)``:
    a file without a row, or with an ``error`` row, is (re)calibrated."""
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
    return todo, skipped, resumed


def _failed_file(item: _FleetItem, err: BaseException) -> tuple[dict[str, Any], None]:
    row: dict[str, Any] = dict.fromkeys(FLEET_COLUMNS, "")
    row.update(file=item.name, status="error", message=f"task failed: {type(err).__name__}: {err}")
    return row, None


def _save(result: Any, target: Path, row: dict[str, Any]) -> tuple[dict[str, Any], Any]:
    """Save ``result`` in ``target``: ``(row, result)``, or an ``error`` row and None when
    the folder holds files robocal did not write or is being written (the other files go on)."""
    from robocal.folder_lock import FolderBusyError
    from robocal.run_ids import FolderMixedError

    try:
        result.save(target)
    except (FolderBusyError, FolderMixedError) as err:
        row.update(status="error", message=" ".join(str(err).split()))
        return row, None
    row["result_dir"] = str(target)
    return row, result


def _calibrate_files(
    executor: Executor,
    items: Sequence[_FleetItem],
    out: Path,
    table: Table,
    report: Callable[[int], None],
) -> tuple[int, int]:
    """Calibrate the files, saving each result in ``out/<file stem>`` and its row in the table as
    it completes: ``(files calibrated, files failed)``; ``report(files finished)`` after each."""
    calibrated = errors = 0
    for item, (row, result) in executor.map(_fleet_task, items, _failed_file):
        if result is not None:
            row, result = _save(result, out / item.path.stem, row)
        if result is not None:
            calibrated += 1
        else:
            errors += 1
        table.append([row])
        report(calibrated + errors)
    return calibrated, errors
