"""A constraint file's run in the GUI's child process (no Dash here: the run's process and the
job runner import it): its options (:class:`ConstraintOptions`) and
:func:`run_constraint_job`, which calls the command line's use case
:func:`robocal.workflow.constraints.calibrate_constraint_files` and writes the figures the
page shows (:data:`FIGURES_FILE`: mm, an inclinometer's in degrees)."""

from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

__all__ = ["FIGURES_FILE", "ConstraintOptions", "figures_doc", "run_constraint_job"]

#: the figures the page shows, written beside the run's constraints.json
FIGURES_FILE = "constraint_figures.json"


@dataclass(frozen=True)
class ConstraintOptions:
    """A constraint file's options: known distances ``(a, b, metres)`` between its fixed
    points, the level (1 joint offsets, 2 kinematic) and the further files of the same fit
    (tracker or constraint files, after the job's own: ``robocal calibrate --data a --data b``)
    and the chain their sensor mounts are stated in."""

    distances: tuple[tuple[int, int, float], ...] = ()
    level: int = 2
    more_data: tuple[Path, ...] = ()
    #: the robot's own chain, the frames of the files' joint-frame sensor mounts
    #: (``ConstraintRequest.frames``; None: the calibrated model's)
    frames_file: Path | None = None


def run_constraint_job(job: Any, progress: Callable[[str, float], None]) -> None:
    """The run's process: ``job`` (a :class:`~robocal.apps.gui.jobs.CalibrationJob` with
    ``constraints``) through :func:`robocal.workflow.constraints.calibrate_constraint_files`
    (model.yaml, constraints.json, report.html), then the figures the page shows."""
    import robocal as rc
    from robocal.outdir import atomic_write_text
    from robocal.workflow.constraints import ConstraintRequest, calibrate_constraint_files

    options: ConstraintOptions = job.constraints
    paths = (job.data, *options.more_data)
    request = ConstraintRequest(
        paths, rc.load_model(job.model_file), job.out,
        angle_unit=job.reader["angle_unit"], length_unit=job.reader["length_unit"],
        distances=options.distances, level=options.level,
        report=True, progress=progress,
        names=tuple(p.name for p in paths),  # the uploads' own names: no server path
        frames=None if options.frames_file is None else rc.load_model(options.frames_file),
    )  # fmt: skip
    run = calibrate_constraint_files(request)
    atomic_write_text(job.out / FIGURES_FILE, json.dumps(figures_doc(run)))


def figures_doc(run: Any) -> dict[str, Any]:
    """What the results view shows of a :class:`~robocal.workflow.constraints.ConstraintRun`
    (figures in mm), written to :data:`FIGURES_FILE` by the run's process."""
    after = run.result.figures
    return {
        "summary": run.summary_lines(),
        "each_kind": list(run.each_kind),
        "before": _figures_mm(run.before),
        "after": None if after is None else _figures_mm(after),
        "dropped": [{"name": d.name, "reason": d.reason} for d in run.result.dropped],
        "kinds": list(run.data.kinds),
        "n": run.data.n,
    }


def _figures_mm(f: Any) -> dict[str, Any]:
    """The figures in mm; an inclinometer channel's RMS residual in degrees (``tilt_deg``, one
    per channel named in ``tilt_channels``, ``<joint>_<axis>``)."""
    import numpy as np

    return {
        "point_spread": (f.point_spread * 1e3).tolist(),
        "point_distance_error": (f.point_distance_error * 1e3).tolist(),
        "plane_rms": (f.plane_rms * 1e3).tolist(),
        "pair_error": (f.pair_error * 1e3).tolist(),
        "tilt_channels": list(f.tilt_channels),
        "tilt_deg": np.degrees(f.tilt_rms).tolist(),
        "tilt_basis": getattr(f, "tilt_basis", ""),
    }
