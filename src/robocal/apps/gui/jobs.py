"""Calibrations run in a separate process, so that the page stays live and can cancel them.

:class:`CalibrationJob` describes a run (file, reader options, model, method); the
process reads the file, splits off the held-out rows, calibrates (``rc.calibrate``),
validates (``rc.validate``), saves the result (``result.save``: ``model.yaml`` and
``result.json``) with the calibration and held-out rows (``train.csv``, ``test.csv``)
and writes the HTML report (``robocal.evaluate.report.write_report``), reporting each
stage through a queue.  robocal's solvers give no progress callback, so the progress
is the stage reached; cancelling terminates the process (a thread could not be
stopped), and nothing of a cancelled run is kept.  Everything it does is robocal's
public API: the GUI holds no calibration logic.
"""

from __future__ import annotations

import dataclasses
import multiprocessing as mp
import shutil
import threading
import time
import traceback
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

__all__ = ["STAGES", "CalibrationJob", "JobRunner", "JobState", "read_options"]

#: The stages of a run and the share of the bar each one completes.
STAGES = (
    ("read", "reading the measurements", 0.05),
    ("calibrate", "calibrating", 0.80),
    ("validate", "validating on the held-out poses", 0.88),
    ("save", "saving the result", 0.92),
    ("report", "writing the HTML report", 1.0),
)


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


def _stage(queue, name: str) -> None:
    for key, text, _ in STAGES:
        if key == name:
            _send(queue, "stage", key, text)


def _run(job: CalibrationJob, queue) -> None:
    """The process: every stage of the run; results in ``job.out``, the outcome on ``queue``."""
    import numpy as np

    import robocal as rc
    from robocal.evaluate.report import write_report
    from robocal.identify.calibrate import file_hash
    from robocal.measure.dataset import MeasurementFileError, MeasurementWarning

    try:
        _stage(queue, "read")
        model = rc.load_model(job.model_file)
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", MeasurementWarning)
            data = rc.read_measurements(job.data, model=model, **job.reader)
        for w in caught:
            if isinstance(w.message, MeasurementWarning):
                _send(queue, "warning", str(w.message))
        if data.position is None:
            raise ValueError("no measured positions (columns x, y, z): map the file's columns")
        if job.noise_mm is not None:
            if data.sigma is not None:
                raise ValueError("the file has its own sigma columns: leave the noise empty")
            data = dataclasses.replace(data, sigma=np.full((data.n, 3), job.noise_mm * 1e-3))
        train, test = data, None
        if job.train_n is not None:
            if not 0 < job.train_n < data.n:
                raise ValueError(
                    f"calibration poses: between 1 and {data.n - 1} (the file has {data.n} rows)"
                )
            split = data.with_split(job.train_n, seed=job.seed)
            train, test = split.split_rows("train"), split.split_rows("test")
        _stage(queue, "calibrate")
        options: dict[str, Any] = {"compliance": job.compliance, "measure": job.measure}
        if job.tool_mm is not None:
            options["tool_guess"] = np.asarray(job.tool_mm, dtype=float) * 1e-3
        result = rc.calibrate(model, train, method=job.method, residual=job.residual, **options)
        result = result.with_records(
            data_file=job.data.name, data_sha256=file_hash(job.data), train_n=train.n, seed=job.seed
        )
        validation = None
        if test is not None:
            _stage(queue, "validate")
            validation = rc.validate(result, test)
            result = result.with_validation(validation.to_dict())
        _stage(queue, "save")
        result = result.save(job.out)  # carries the saved files' run id (for the report)
        rc.write_measurements(train, job.out / "train.csv")
        if test is not None:
            rc.write_measurements(test, job.out / "test.csv")
        _write_errors(job.out / "errors.json", result, train, validation)
        _send(queue, "saved", str(job.out))
        _stage(queue, "report")
        write_report(result, job.out / "report.html", data=train, test_data=test)
        _send(queue, "done", str(job.out))
    except (MeasurementFileError, ValueError) as err:
        _send(queue, "error", str(err).replace(str(job.data), job.data.name))
    except Exception as err:  # an unexpected failure still ends the run with one line
        _send(queue, "error", f"calibration failed: {type(err).__name__}: {err}")
        _send(queue, "trace", traceback.format_exc())


def _write_errors(path: Path, result, train, validation) -> None:
    """The per-pose position errors the page plots (mm) and their statistics: the start model
    and the calibrated one on the calibration poses, the calibrated one on the held-out poses."""
    import json

    import robocal as rc
    from robocal.evaluate.report import before_validation
    from robocal.model.files import atomic_write_text

    def entry(stats) -> dict[str, Any] | None:
        if stats is None:
            return None
        return stats.to_dict() | {"errors_mm": (stats.errors * 1e3).round(6).tolist()}

    sets = {
        "before": entry(before_validation(result, train)),
        "after": entry(rc.validate(result, train)),
        "held_out": entry(validation),
    }
    atomic_write_text(path, json.dumps(sets))


@dataclass
class JobState:
    """What the page shows of a run: stage, share done, messages, outcome."""

    stage: str = "start"
    text: str = "starting"
    fraction: float = 0.0
    status: str = "running"  # running | done | error | cancelled
    saved: bool = False  # the result is saved (the report may still be being written)
    error: str | None = None
    warnings: list[str] = field(default_factory=list)
    started: float = field(default_factory=time.monotonic)
    seconds: float = 0.0


class JobRunner:
    """One calibration at a time in a child process; :meth:`poll` collects its reports."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._process: mp.process.BaseProcess | None = None
        self._queue = None
        self._job: CalibrationJob | None = None
        self.state: JobState | None = None

    @property
    def running(self) -> bool:
        return self.state is not None and self.state.status == "running"

    def start(self, job: CalibrationJob) -> None:
        """Start ``job`` (a running one is cancelled first)."""
        self.cancel()
        with self._lock:
            if job.out.exists():
                shutil.rmtree(job.out)
            job.out.mkdir(parents=True)
            ctx = mp.get_context("spawn")  # a clean interpreter: no web-server threads forked
            self._queue = ctx.Queue()
            self._process = ctx.Process(target=_run, args=(job, self._queue), daemon=True)
            self._job = job
            self.state = JobState()
            self._process.start()

    def poll(self) -> JobState | None:
        """Read the child's reports; detect a child that died without one."""
        with self._lock:
            state = self.state
            if state is None or state.status != "running" or self._queue is None:
                return state
            fractions = {key: f for key, _, f in STAGES}
            order = [key for key, _, _ in STAGES]
            while True:
                try:
                    kind, *payload = self._queue.get_nowait()
                except Exception:  # queue.Empty (the spawn context's queue raises the stdlib's)
                    break
                if kind == "stage":
                    key, text = payload
                    state.stage, state.text = key, text
                    i = order.index(key)
                    state.fraction = fractions[order[i - 1]] if i else 0.0
                elif kind == "saved":
                    state.saved = True
                elif kind == "warning":
                    state.warnings.append(payload[0])
                elif kind == "done":
                    state.status, state.fraction, state.text = "done", 1.0, "done"
                elif kind == "error":
                    state.status, state.error, state.text = "error", payload[0], "failed"
            state.seconds = time.monotonic() - state.started
            alive = self._process is not None and self._process.is_alive()
            if state.status == "running" and not alive and self._queue.empty():
                state.status, state.text = "error", "failed"
                code = None if self._process is None else self._process.exitcode
                state.error = f"the calibration process ended unexpectedly (exit code {code})"
            if state.status != "running" and self._process is not None:
                self._process.join(timeout=5)
                self._process = None
            return state

    def cancel(self) -> bool:
        """Stop a running calibration and discard what it wrote; whether one was running."""
        with self._lock:
            process, job = self._process, self._job
            if process is None or self.state is None or self.state.status != "running":
                return False
            process.terminate()
            process.join(timeout=10)
            if process.is_alive():
                process.kill()
                process.join(timeout=5)
            self._process = None
            self.state.status, self.state.text = "cancelled", "cancelled"
            if job is not None and job.out.exists():
                shutil.rmtree(job.out, ignore_errors=True)
            return True
