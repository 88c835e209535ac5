"""Monte Carlo studies and fleet calibrations, on one process or on Dask.

A **study** answers "which pose set, which device, how good will it be?" before anyone
measures: N virtual robots drawn from tolerances (:func:`robocal.measure.draw_true_model`)
× pose-set choices × device-noise choices, each one simulated
(:class:`~robocal.measure.VirtualRobot`, :func:`~robocal.measure.simulate`),
calibrated and validated on held-out poses.  One row per case goes to
``DIR/results.csv`` the moment the case is finished, so a crashed task, a killed
worker or a killed study loses nothing that was finished: running the same study
again resumes from the table.  ``robocal study config.yaml --out DIR`` (config format:
:class:`StudyConfig`, example ``examples/study_ur10.yaml``).

A **fleet** run calibrates one robot per measurement file of a folder
(``robocal fleet ROBOT DIR``): ``OUT/<file stem>/`` gets the calibration
(``model.yaml``, ``result.json``) and ``OUT/fleet.csv`` one row per file, also
resumable.

Where the work runs (both): ``workers=0`` in this process; ``workers=None`` (default)
a Dask ``LocalCluster`` with one single-threaded worker process per core; ``workers=N``
N processes (at most :data:`~robocal.study.cluster.MAX_WORKERS_PER_CORE` per core);
``scheduler="tcp://host:8786"`` an existing Dask cluster (whose workers need robocal
installed and, for fleets, the files on a shared path), given up after
:data:`~robocal.study.cluster.CONNECT_TIMEOUT_S` seconds when it does not answer.  Results are
gathered by the client as they complete and written there, by one writer.

Two calibration engines compute the same thing:

* ``"calibrate"``: :func:`robocal.calibrate` then :func:`robocal.validate` per case,
  any method and device;
* ``"batched"`` (:func:`robocal.identify.batch.calibrate_batch`, default when it
  applies: position measurements, ``method: lm``, ``residual: none``): the chunk's
  robots are calibrated together, with ``rc.calibrate``'s own stage functions, solver
  and guards (:mod:`robocal.identify.stages`) but their chains evaluated in one batched
  call; estimates agree with ``rc.calibrate`` to round-off (tests/test_study.py).

A case the calibration's guards refuse (too few poses for the unknowns, poses that
leave parameters undetermined, a diverged fit) gets ``status=failed`` with the reason
in ``message``, with either engine; it is not recomputed on resume.

Units: SI inside; the tables use mm (columns ending ``_mm``) and seconds.

The package's modules: :mod:`~robocal.study.config` (the study file and its cases),
:mod:`~robocal.study.prepare` (what every task shares), :mod:`~robocal.study.tasks` (one chunk
of robots), :mod:`~robocal.study.table` (the resumable CSV tables),
:mod:`~robocal.study.cluster` (in-process or Dask), :mod:`~robocal.study.summary`,
:mod:`~robocal.study.run` (:func:`run_study`) and :mod:`~robocal.study.fleet` (:func:`run_fleet`).
"""

from __future__ import annotations

from typing import Any

from robocal.study.cluster import local_cluster
from robocal.study.config import (
    MAX_STUDY_CASES as MAX_STUDY_CASES,
)
from robocal.study.config import (
    Case,
    DeviceSpec,
    PoseSetSpec,
    StudyConfig,
    StudyError,
    load_study_config,
    study_cases,
)
from robocal.study.fleet import FLEET_COLUMNS, FleetRun, run_fleet
from robocal.study.run import StudyRun, run_study
from robocal.study.summary import read_study_summary
from robocal.study.table import Table as Table  # the results table (tests read it)
from robocal.study.tasks import RESULT_COLUMNS

__all__ = [
    "FLEET_COLUMNS",
    "RESULT_COLUMNS",
    "Case",
    "DeviceSpec",
    "FleetRun",
    "PoseSetSpec",
    "StudyConfig",
    "StudyError",
    "StudyRun",
    "load_study_config",
    "local_cluster",
    "read_study_summary",
    "run_fleet",
    "run_study",
    "study_cases",
]


def __getattr__(name: str) -> Any:
    """``robocal.study.calibrate_batch`` and ``BatchFit``: the batched engine, now in
    :mod:`robocal.identify.batch` (imported when first used)."""
    if name in ("calibrate_batch", "BatchFit"):
        from robocal.identify import batch

        return getattr(batch, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
