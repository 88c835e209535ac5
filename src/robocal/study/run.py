"""Running (or resuming) a Monte Carlo study: :func:`run_study`."""

from __future__ import annotations

import os
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from robocal.outdir import atomic_write_text
from robocal.run_ids import ForeignFileError, check_robocal_files, new_run_id, run_id_line
from robocal.study.cluster import Executor, check_workers, executor_for
from robocal.study.config import Case, StudyConfig, StudyError, load_study_config, study_cases
from robocal.study.prepare import Prepared, prepare
from robocal.study.summary import write_summary
from robocal.study.table import Table, remove_table, table_cells
from robocal.study.tasks import RESULT_COLUMNS, Chunk, empty_row, run_chunk


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
    """The study's ``study.yaml``: a run id line (it marks the file as robocal's), then the
    configuration."""
    return run_id_line(new_run_id()) + yaml.safe_dump(
        config.model_dump(mode="json"), sort_keys=True, default_flow_style=None, width=100
    )


def _identity(dumped: Mapping[str, Any]) -> dict[str, Any]:
    """The part of a configuration that decides the rows (not how many robots, the chunking, nor
    where it runs)."""
    return {k: v for k, v in dumped.items() if k not in ("robots", "chunk", "dask")}


def _chunks(prep: Prepared, todo: Sequence[Case], size: int) -> list[Chunk]:
    """The tasks: robots of one pose set and device, ``size`` at a time (on two workers,
    tasks shrinking towards the end so both finish together cost more in Dask's overhead
    and smaller batches than the idle tail they saved: 1.77x against 1.85x for 800
    robots)."""
    groups: dict[tuple[str, str], list[int]] = {}
    for c in todo:
        groups.setdefault((c.pose_set, c.device), []).append(c.robot)
    out = []
    for (pose_set, device), robots in groups.items():
        for i in range(0, len(robots), size):
            out.append(Chunk(prep, pose_set, device, tuple(robots[i : i + size])))
    return out


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
        scheduler: address of a running Dask scheduler (instead of a local cluster).  A
            study file's ``dask.scheduler`` is used only when named here: a study file alone
            never opens a network connection (:class:`StudyError` otherwise).
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
    config = _limited(config, robots)
    scheduler, workers = _where(config, scheduler, workers, client)  # refused before anything is written
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    _claim_directory(out, config, force)
    prep = prepare(config)
    atomic_write_text(out / "study.yaml", _config_text(config))
    table = Table(out / "results.csv", RESULT_COLUMNS, "case")
    cases = study_cases(config)
    done = {c.key for c in cases if c.key in table.rows and table.rows[c.key]["status"] != "error"}
    t0 = time.perf_counter()
    executor = executor_for(workers, scheduler, client)
    chunks = _chunks(prep, [c for c in cases if c.key not in done], config.chunk)
    _prime(executor, chunks)
    startup = time.perf_counter() - t0

    def report(computed: int) -> None:
        if progress is not None:
            progress(len(done) + computed, len(cases))

    t1 = time.perf_counter()
    try:
        computed, errors = _compute(executor, chunks, table, report)
    finally:
        seconds = time.perf_counter() - t1
        if client is None:
            executor.close()
    mine = [table.rows[c.key] for c in cases if c.key in table.rows]
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
        summary=write_summary(out, config, mine, seconds, computed),
    )


def _where(
    config: StudyConfig, scheduler: str | None, workers: int | None, client: Any
) -> tuple[str | None, int | None]:
    """Where the study runs: the call's ``scheduler`` / ``workers`` / ``client``, else the
    study file's ``dask.workers``.  A study file's ``dask.scheduler`` never opens a network
    connection by itself (a Dask connection unpickles what the scheduler sends): the call
    must name that scheduler (``--scheduler``)."""
    local = scheduler is None and client is None
    if local and workers is None:
        if config.dask.scheduler is not None:
            raise StudyError(
                f"the study file names the Dask scheduler {config.dask.scheduler}; a study file does "
                f"not connect to a network by itself: give --scheduler {config.dask.scheduler} to run "
                "there, or --workers N for a local cluster (0: this process)"
            )
        workers = config.dask.workers
    if local and workers:
        check_workers(workers)
    return scheduler, workers


def _limited(config: StudyConfig | str | os.PathLike[str], robots: int | None) -> StudyConfig:
    """The study's configuration (read when a path), with only its first ``robots`` robots."""
    if not isinstance(config, StudyConfig):
        config = load_study_config(config)
    if robots is not None:
        if robots < 1:
            raise StudyError(f"robots={robots} must be >= 1")
        config = config.model_copy(update={"robots": min(robots, config.robots)})
    return config


def _claim_directory(out: Path, config: StudyConfig, force: bool) -> None:
    """Refuse ``out`` when it holds another study (or results without their ``study.yaml``)
    unless ``force``, which deletes those results; the same study's results stay (resume).
    Files robocal did not write (a ``study.yaml`` without its run id line, a table with
    another header, a user's ``summary.json``) are refused, with or without ``force``."""
    cfg_path = out / "study.yaml"
    results_path = out / "results.csv"
    try:
        check_robocal_files(out, ("study.yaml", "summary.json", "summary.png"))
    except ForeignFileError as err:
        raise StudyError(str(err)) from None
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
            remove_table(results_path, RESULT_COLUMNS)
    elif results_path.exists():
        if not force:
            raise StudyError(f"{results_path} exists without its study.yaml; use --force to start over")
        remove_table(results_path, RESULT_COLUMNS)


def _prime(executor: Executor, chunks: Sequence[Chunk]) -> None:
    """One robot on every worker before the clock starts."""
    if chunks:
        first = chunks[0]
        executor.prime(_chunk_cells, Chunk(first.prepared, first.pose_set, first.device, first.robots[:1]))


def _failed_chunk(chunk: Chunk, err: BaseException) -> list[dict[str, Any]]:
    """The rows of a task that failed as a whole (a killed worker, out of memory...): an
    ``error`` row per robot naming the task's input (retried on resume)."""
    text = " ".join(f"{type(err).__name__}: {err}".split())
    rows = []
    for k in chunk.robots:
        row = empty_row(Case(k, chunk.pose_set, chunk.device), chunk.prepared.engine)
        row.update(status="error", message=f"task failed: {text} [input: {chunk.describe()}]")
        rows.append(row)
    return rows


def _chunk_cells(chunk: Chunk) -> list[list[str]]:
    """A task: the chunk's rows (:func:`~robocal.study.tasks.run_chunk`) as results-table cells, formatted
    where they are computed (on a Dask worker the main process then only writes them; with two
    workers on two cores it shares a core with them)."""
    return table_cells(run_chunk(chunk), RESULT_COLUMNS)


def _failed_cells(chunk: Chunk, err: BaseException) -> list[list[str]]:
    return table_cells(_failed_chunk(chunk, err), RESULT_COLUMNS)


def _compute(
    executor: Executor, chunks: Sequence[Chunk], table: Table, report: Callable[[int], None]
) -> tuple[int, int]:
    """Run the chunks and append their rows as they complete: ``(rows computed, error rows)``;
    ``report(rows computed so far)`` after every task."""
    computed = errors = 0
    status = RESULT_COLUMNS.index("status")
    for _chunk, cells in executor.map(_chunk_cells, chunks, _failed_cells):
        table.append_cells(cells)
        computed += len(cells)
        errors += sum(row[status] == "error" for row in cells)
        report(computed)
    return computed, errors
