"""Calibrations run in a separate process, so that the page stays live and can cancel them.

:class:`CalibrationJob` describes a run (file, reader options, model, method); the
process runs the use case :func:`robocal.workflow.calibrate_file`, the one the command
line's ``robocal calibrate`` runs (read, split off the held-out rows, calibrate, record
the provenance, validate, save ``model.yaml`` and ``result.json`` and write the HTML
report), then writes the calibration and held-out rows (``train.csv``, ``test.csv``) and
the per-pose errors the page plots (``errors.json``).  The use case's progress callback
reports each stage through a queue (the progress is the stage reached); cancelling
terminates the process (a thread could not be stopped), and nothing of a cancelled run is
kept.  The GUI holds no calibration logic.
"""

from __future__ import annotations

import dataclasses
import multiprocessing as mp
import shutil
import threading
import time
import traceback
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from robocal.workflow.request import STAGES as WORKFLOW_STAGES

if TYPE_CHECKING:
    from robocal.apps.gui.constraint_job import ConstraintOptions

__all__ = [
    "MAX_UPLOAD_BYTES",
    "STAGES",
    "CalibrationJob",
    "JobRunner",
    "JobState",
    "RunInfo",
    "public_text",
    "read_options",
]

#: the largest file the GUI accepts as an upload (bytes); a request that carries a larger one
#: (base64 adds a third) is answered HTTP 413 before it is read: no upload can exhaust memory;
#: the page checks the size before sending (calibrate_page) and says why
MAX_UPLOAD_BYTES = 32 * 1024 * 1024

#: The stages of a run (key, text, share of the bar done when it starts): the use case's
#: (:data:`robocal.workflow.STAGES`), reported through its progress callback
STAGES = WORKFLOW_STAGES


@dataclass(frozen=True)
class CalibrationJob:
    """One calibration run (the options of ``robocal calibrate``).

    Attributes:
        data: the measurement CSV.
        reader: keyword options of :func:`rc.read_measurements` (see :func:`read_options`).
        model_file: the model to calibrate (a model YAML file).
        method: ``lm``, ``pinv``, ``bounded`` or ``influence``.
        residual: ``auto``, ``none`` or ``joint_fourier``.
        train_n: calibrate on this many random rows, validate on the rest (None: every row).
        seed: seed of that draw.
        tool_mm: start value of the tool point (mm) or None.
        noise_mm: the device's position noise (1σ per axis, mm) or None.
        compliance: also identify joint compliance.
        measure: ``position``, ``pose`` or None (pose when the data has orientations).
        out: the directory for the result.
        constraints: a constraint file's options (``data`` holds fixed points, planes or
            distances: :func:`robocal.workflow.constraints.calibrate_constraint_files`), or None.
    """

    data: Path
    reader: dict[str, Any]
    model_file: Path
    out: Path
    method: str = "lm"
    residual: str = "auto"
    train_n: int | None = 100
    seed: int = 0
    tool_mm: tuple[float, float, float] | None = None
    noise_mm: float | None = None
    compliance: bool = False
    measure: str | None = None
    constraints: ConstraintOptions | None = None


def read_options(
    length_unit: str = "m",
    angle_unit: str = "rad",
    sep: str | None = None,
    decimal: str = ".",
    columns: str | None = None,
    orientation: str = "auto",
    incomplete: str = "error",
    limits: str = "error",
) -> dict[str, Any]:
    """The reader's keyword options from the page's controls (``sep``: ``auto``, ``tab``,
    ``space`` or one character, as ``--sep`` on the command line)."""
    separators = {"auto": None, "": None, None: None, "tab": "\t", "space": " "}
    return {
        "length_unit": length_unit,
        "angle_unit": angle_unit,
        "sep": separators.get(sep, sep),
        "decimal": decimal,
        "columns": (columns or "").strip() or None,
        "orientation": orientation or "auto",
        "incomplete": incomplete,
        "limits": limits,
    }


def _send(queue, kind: str, *payload: Any) -> None:
    queue.put((kind, *payload))


def _stage(queue, name: str, fraction: float = 0.0) -> None:
    for key, text, _ in STAGES:
        if key == name:
            _send(queue, "stage", key, text, fraction)


def request_of(job: CalibrationJob, queue) -> Any:
    """The use case's request (:class:`robocal.workflow.CalibrateRequest`) of ``job``, its
    stages and the reader's warnings reported on ``queue``."""
    import robocal as rc
    from robocal.workflow import CalibrateRequest, FitOptions, ReaderOptions

    tool = None if job.tool_mm is None else tuple(v * 1e-3 for v in job.tool_mm)
    fit = FitOptions(method=job.method, measure=job.measure, residual=job.residual,
                     compliance=job.compliance, tool_guess_m=tool)  # fmt: skip
    noise_m = None if job.noise_mm is None else job.noise_mm * 1e-3

    def notify(kind: str, text: str) -> None:
        if kind in ("warning", "dropped"):
            _send(queue, "warning", text)

    return CalibrateRequest(
        job.data, rc.load_model(job.model_file), job.out, ReaderOptions(**job.reader), fit,
        noise_m=noise_m, train_n=job.train_n, seed=job.seed, report=True, force=True,
        progress=lambda stage, fraction: _stage(queue, stage, fraction), notify=notify,
        iteration=lambda evaluations, rms: _send(queue, "iteration", evaluations, rms),
    )  # fmt: skip


def _run(job: CalibrationJob, queue) -> None:
    """The process: :func:`robocal.workflow.calibrate_file` (read, split, calibrate, record,
    validate, save, report) and the files the page shows beside it; the outcome on ``queue``."""
    import robocal as rc
    import robocal.workflow as workflow
    from robocal.model.yaml_files import ModelFileError

    try:
        _stage(queue, "read")
        if job.constraints is not None:  # fixed points, planes, distances: the CLI's use case
            from robocal.apps.gui.constraint_job import run_constraint_job

            run_constraint_job(job, lambda stage, fraction: _stage(queue, stage, fraction))
            _send(queue, "saved", str(job.out))
            _send(queue, "done", str(job.out))
            return
        run = workflow.calibrate_file(request_of(job, queue))
        rc.write_measurements(run.train, job.out / "train.csv")
        if run.test is not None:
            rc.write_measurements(run.test, job.out / "test.csv")
        _write_errors(job.out / "errors.json", run.result, run.train, run.validation, run.test)
        _send(queue, "saved", str(job.out))
        _send(queue, "done", str(job.out))
    except (workflow.CalibrateFileError, ModelFileError) as err:
        _send(queue, "error", _gui_message(err).replace(str(job.data), job.data.name))
    except Exception as err:  # an unexpected failure still ends the run with one line
        _send(queue, "error", f"calibration failed: {type(err).__name__}: {err}")
        _send(queue, "trace", traceback.format_exc())


def _gui_message(err: Exception) -> str:
    """A refusal in the page's words (its controls, not the API's fields)."""
    problem = getattr(err, "problem", str(err))
    field_name = getattr(err, "field", None)
    if field_name == "train_n":
        return f"calibration poses: {problem}"
    if field_name == "noise_m":
        return f"device noise: {problem}"
    return str(err)


def _write_errors(path: Path, result, train, validation, validation_data=None) -> None:
    """The per-pose position errors the page plots (mm) and their statistics: the start model
    and the calibrated one on the calibration poses, the calibrated one on the held-out poses."""
    import json

    import robocal as rc
    from robocal.evaluate.report import before_validation
    from robocal.outdir import atomic_write_text

    def entry(stats) -> dict[str, Any] | None:
        if stats is None:
            return None
        return stats.to_dict() | {"errors_mm": (stats.errors * 1e3).round(6).tolist()}

    sets = {
        "before": entry(before_validation(result, train)),
        "after": entry(rc.validate(result, train)),
        "held_out": entry(validation),
        "points": {
            "train": _error_vectors(result, train),
            "held_out": _error_vectors(result, validation_data),
        },
    }
    atomic_write_text(path, json.dumps(sets))


def _error_vectors(result, data) -> dict[str, Any] | None:
    """The measured points and the calibrated model's error at each (predicted - measured),
    device frame, mm, rows as in ``data`` (the page's 3D view); None without data."""
    if data is None or data.position is None:
        return None
    predicted = result.predict(data.q)[:, :3, 3]
    return {
        "measured_mm": (data.position * 1e3).round(4).tolist(),
        "error_mm": ((predicted - data.position) * 1e3).round(5).tolist(),
    }


@dataclass
class JobState:
    """What the page shows of a run: stage, share done, messages, outcome."""

    stage: str = "queued"
    text: str = "queued behind another run"
    fraction: float = 0.0
    status: str = "queued"  # queued | running | done | error | cancelled | interrupted
    saved: bool = False  # the result is saved (the report may still be being written)
    error: str | None = None
    warnings: list[str] = field(default_factory=list)
    started: float = field(default_factory=time.monotonic)
    seconds: float = 0.0
    #: the stages reached, in order: (key, text, seconds from the start of the run)
    stages: list[tuple[str, str, float]] = field(default_factory=list)

    def shown_fraction(self, now: float) -> float:
        """The bar's share: the stage's start, and inside the calibrate stage the engine's own
        progress (its physical fit, each variant's cross-validation: :func:`robocal.calibrate`'s
        ``progress``, forwarded by the use case); ``now`` is kept for the callers."""
        return self.fraction

    @property
    def active(self) -> bool:
        """Queued or running: the page keeps polling."""
        return self.status in ("queued", "running")


@dataclass(frozen=True)
class RunInfo:
    """A run as the run list shows it (``created``: seconds since the epoch; ``error``: a
    failed run's message, without the server's paths, kept in its record across restarts)."""

    run_id: str
    session: str
    data_name: str
    robot: str
    created: float
    status: str
    seconds: float
    error: str = ""


@dataclass
class _Run:
    job: CalibrationJob
    info: RunInfo
    state: JobState
    process: mp.process.BaseProcess | None = None
    queue: Any = None


class JobRunner:
    """Calibrations of every browser session, one at a time (the machine's cores are shared),
    the others queued in order: no run stops another.  A monitor thread collects the running
    child's reports and starts the next queued run, so a run finishes with no page polling it.
    Each run's record (``<run_id>.run.json`` beside its folder in ``runs``) is read back
    when the server starts again: the run list outlives the process."""

    def __init__(self, runs: Path) -> None:
        self.runs = runs
        self._lock = threading.Lock()
        self._runs: dict[str, _Run | RunInfo] = {info.run_id: info for info in _read_records(runs)}
        self._order: list[str] = []  # queued run ids, oldest first
        self._monitor: threading.Thread | None = None
        self._stop = threading.Event()

    def start(self, job: CalibrationJob, run_id: str, session: str, robot: str) -> None:
        """Queue ``job`` as ``run_id`` of ``session``; it starts when no other run is running."""
        info = RunInfo(run_id, session, job.data.name, robot, time.time(), "queued", 0.0)
        with self._lock:
            if job.out.exists():
                shutil.rmtree(job.out)
            self._runs[run_id] = _Run(job, info, JobState())
            self._order.append(run_id)
            _write_record(self.runs, info)
            if self._monitor is None:
                self._monitor = threading.Thread(target=self._watch, daemon=True, name="robocal-runs")
                self._monitor.start()
            self._advance()

    def state(self, run_id: str | None) -> JobState | None:
        """The run's state (cheap: the monitor thread keeps it current)."""
        with self._lock:
            run = self._runs.get(run_id or "")
            if isinstance(run, RunInfo):  # a run of an earlier server: done, or interrupted
                return JobState(
                    stage=run.status, text=run.status, status=run.status, saved=run.status == "done",
                    fraction=1.0 if run.status == "done" else 0.0, seconds=run.seconds,
                    error=run.error or None,
                )  # fmt: skip
            if run is None:
                return None
            if run.state.active:
                run.state.seconds = time.monotonic() - run.state.started
            return dataclasses.replace(
                run.state, warnings=list(run.state.warnings), stages=list(run.state.stages)
            )

    def runs_list(self) -> list[RunInfo]:
        """Every run, newest first."""
        with self._lock:
            infos = [r if isinstance(r, RunInfo) else r.info for r in self._runs.values()]
        return sorted(infos, key=lambda i: i.created, reverse=True)

    def cancel(self, run_id: str | None) -> bool:
        """Stop that run (queued or running) and discard what it wrote; whether it was active."""
        with self._lock:
            run = self._runs.get(run_id or "")
            if not isinstance(run, _Run) or not run.state.active:
                return False
            _stop_process(run)
            if run_id in self._order:
                self._order.remove(run_id)
            run.state.status, run.state.text = "cancelled", "cancelled"
            shutil.rmtree(run.job.out, ignore_errors=True)
            self._finish(run)
            self._advance()
            return True

    def cancel_all(self) -> None:
        """Stop every run and discard what it wrote (the server is stopping; its work dir goes)."""
        self._stop.set()  # first: stopping one run must not start a queued one
        for info in self.runs_list():
            if info.status in ("queued", "running"):
                self.cancel(info.run_id)

    def interrupt_all(self) -> None:
        """Stop every run and record it as interrupted (the server is stopping; its work dir
        stays, so that the next server lists these runs as cut off, never as running)."""
        self._stop.set()
        with self._lock:
            for run in self._runs.values():
                if isinstance(run, _Run) and run.state.active:
                    _stop_process(run)
                    run.state.status, run.state.text = "interrupted", "interrupted"
                    shutil.rmtree(run.job.out, ignore_errors=True)  # a half-written folder
                    self._finish(run)
            self._order.clear()

    # ------------------------------------------------------------------ inside the lock
    def _advance(self) -> None:
        """Start the oldest queued run when none is running (and the server is not stopping)."""
        if self._stop.is_set() or any(
            isinstance(r, _Run) and r.state.status == "running" for r in self._runs.values()
        ):
            return
        if not self._order:
            return
        run = self._runs[self._order.pop(0)]
        assert isinstance(run, _Run)
        run.job.out.mkdir(parents=True)
        ctx = mp.get_context("spawn")  # a clean interpreter: no web-server threads forked
        run.queue = ctx.Queue()
        run.process = ctx.Process(target=_run, args=(run.job, run.queue), daemon=True)
        run.state = JobState(stage="start", text="starting", status="running")
        run.info = dataclasses.replace(run.info, status="running")
        run.process.start()

    def _finish(self, run: _Run) -> None:
        state = run.state
        state.seconds = time.monotonic() - state.started
        # the work dir is the runs folder's parent: the record never holds the server's paths
        error = public_text(state.error or "", self.runs.parent) if state.status == "error" else ""
        run.info = dataclasses.replace(
            run.info, status=state.status, seconds=round(state.seconds, 1), error=error
        )
        _write_record(self.runs, run.info)

    def _collect(self, run: _Run) -> None:
        """Read the child's reports; detect a child that died without one."""
        state = run.state
        while True:
            try:
                kind, *payload = run.queue.get_nowait()
            except Exception:  # queue.Empty (the spawn context's queue raises the stdlib's)
                break
            _apply(state, kind, payload)
        alive = run.process is not None and run.process.is_alive()
        if state.status == "running" and not alive and run.queue.empty():
            state.status, state.text = "error", "failed"
            code = None if run.process is None else run.process.exitcode
            state.error = f"the calibration process ended unexpectedly (exit code {code})"
        if state.status != "running":
            if run.process is not None:
                run.process.join(timeout=5)
                run.process = None
            self._finish(run)

    def _watch(self) -> None:
        while not self._stop.wait(0.2):
            with self._lock:
                for run in self._runs.values():
                    if isinstance(run, _Run) and run.state.status == "running":
                        self._collect(run)
                self._advance()


def _apply(state: JobState, kind: str, payload: list[Any]) -> None:
    """One report of the child on the run's state."""
    if kind == "stage":
        state.stage, state.text, state.fraction = payload
        if not state.stages or state.stages[-1][0] != state.stage:
            state.stages.append((state.stage, state.text, time.monotonic() - state.started))
    elif kind == "iteration":  # the streamed LM's pass: the stage's text says which and where
        state.text = f"calibrating: LM pass {payload[0]}, RMS {payload[1] * 1e3:.4f} mm"
    elif kind == "saved":
        state.saved = True
    elif kind == "warning":
        state.warnings.append(payload[0])
    elif kind == "done":
        state.status, state.fraction, state.text = "done", 1.0, "done"
    elif kind == "error":
        state.status, state.error, state.text = "error", payload[0], "failed"


def _stop_process(run: _Run) -> None:
    process = run.process
    if process is None:
        return
    process.terminate()
    process.join(timeout=10)
    if process.is_alive():
        process.kill()
        process.join(timeout=5)
    run.process = None


def _write_record(runs: Path, info: RunInfo) -> None:
    import json

    from robocal.outdir import atomic_write_text

    runs.mkdir(parents=True, exist_ok=True)
    atomic_write_text(runs / f"{info.run_id}.run.json", json.dumps(dataclasses.asdict(info)))


def _read_records(runs: Path) -> list[RunInfo]:
    """The records of an earlier server's runs; one that was active then is interrupted now."""
    import json

    infos = []
    for path in sorted(runs.glob("*.run.json")) if runs.is_dir() else []:
        try:
            info = RunInfo(**json.loads(path.read_text(encoding="utf-8")))
        except (OSError, ValueError, TypeError):
            continue  # a record this version cannot read is left out of the list
        if info.status in ("queued", "running"):
            info = dataclasses.replace(info, status="interrupted")
        elif info.status == "done" and not any(
            (runs / info.run_id / name).is_file() for name in ("result.json", "constraints.json")
        ):
            continue
        infos.append(info)
    return infos


def public_text(text: str, root: Path) -> str:
    """``text`` with every path under the server's work dir ``root`` cut to its file name: a
    message on the page never shows where the server keeps its files."""
    import re

    pattern = re.escape(str(root)) + r"[^\s'\"]*"
    return re.sub(pattern, lambda m: Path(m.group(0)).name, text)
