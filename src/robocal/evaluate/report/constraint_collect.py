"""The report of a constraint calibration (fixed points, planes, distances): its data.

A constraint calibration has no measuring device: no position errors, no device frame,
no ISO 9283 poses.  What it has is each kind's own figures — the spread of the tool point
around each fixed point, the error of each known distance, the plane residuals — before
(the nominal robot) and after (the calibrated robot), on the calibration's own file and on
a held-out file, and what the kind cannot see (:mod:`robocal.identify.constraints.result`).
:func:`collect_constraint_report` computes them once into a frozen
:class:`ConstraintReport`; :mod:`.constraint_sections` renders it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from robocal.identify.constraints.fit import ConstraintFigures, constraint_figures, tool_points
from robocal.identify.constraints.result import ConstraintCalibration, TrackerValidation
from robocal.measure.constraints.data_set import ConstraintSet

__all__ = ["ConstraintReport", "DataSetFigures", "collect_constraint_report", "data_set_figures"]

Array = NDArray[np.float64]


@dataclass(frozen=True)
class DataSetFigures:
    """A constraint file judged by the nominal and the calibrated robot (m).

    Attributes:
        label: ``"calibration data"`` or ``"held-out data"``.
        source: the file's name.
        n: poses.
        kinds: its measurement kinds.
        before: the nominal robot's figures (None: the nominal robot is not recorded).
        after: the calibrated robot's figures.
        radial_before, radial_after: ``(m,)`` each fixed-point pose's distance from its
            point's centroid (the spread per pose), in file order.
    """

    label: str
    source: str
    n: int
    kinds: tuple[str, ...]
    before: ConstraintFigures | None
    after: ConstraintFigures
    radial_before: Array | None
    radial_after: Array


@dataclass(frozen=True)
class ConstraintReport:
    """Everything the page of a constraint calibration shows.

    Attributes:
        calibration: the folder's content.
        sets: the calibration file's and a held-out file's figures (those given).
        missing: why a data set is not shown (e.g. the recorded file is gone or changed).
        title, version: the page's heading and robocal's version.
        tracker: the position errors on a tracker file (before and after), or None.
    """

    calibration: ConstraintCalibration
    sets: tuple[DataSetFigures, ...]
    missing: tuple[str, ...]
    title: str
    version: str
    tracker: TrackerValidation | None = None


def _radial(robot, data: ConstraintSet) -> Array:
    """Each fixed-point pose's distance (m) from its point's centroid."""
    on = data.point >= 0
    p = tool_points(robot, data.q[on])
    labels = data.point[on]
    out = np.zeros(len(p))
    for k in np.unique(labels):
        rows = labels == k
        out[rows] = np.linalg.norm(p[rows] - p[rows].mean(axis=0), axis=1)
    return out


def data_set_figures(
    cal: ConstraintCalibration, data: ConstraintSet, label: str, source: str
) -> DataSetFigures:
    """``data`` judged by ``cal``'s nominal robot (when recorded) and its calibrated robot."""
    from robocal.measure.constraints.mounts import mounts_in

    nominal = cal.nominal
    data = mounts_in(data, cal.model if nominal is None else nominal)  # sensors stated at home: the start's
    return DataSetFigures(
        label=label,
        source=source,
        n=data.n,
        kinds=data.kinds,
        before=None if nominal is None else constraint_figures(nominal, data),
        after=constraint_figures(cal.model, data, tilt=cal.tilt),  # with the joint effects identified
        radial_before=None if nominal is None else _radial(nominal, data),
        radial_after=_radial(cal.model, data),
    )


def collect_constraint_report(
    cal: ConstraintCalibration,
    data: ConstraintSet | None = None,
    test_data: ConstraintSet | None = None,
    *,
    sources: tuple[str, str] = ("", ""),
    missing: tuple[str, ...] = (),
    title: str | None = None,
    tracker: TrackerValidation | None = None,
) -> ConstraintReport:
    """The report's content: ``data`` (the calibration file) and ``test_data`` (a held-out
    file) judged before and after; ``sources`` their file names; ``missing`` the reasons a
    set is absent, shown on the page; ``tracker`` the position errors on a tracker file
    (:func:`~robocal.identify.constraints.result.validate_on_tracker`)."""
    from robocal._version import __version__

    sets = []
    if data is not None:
        sets.append(data_set_figures(cal, data, "calibration data", sources[0]))
    if test_data is not None:
        sets.append(data_set_figures(cal, test_data, "held-out data", sources[1]))
    heading = title or f"Calibration report: {cal.model.title or cal.model.name} (no tracker)"
    return ConstraintReport(cal, tuple(sets), missing, heading, __version__, tracker)


def rms(values: Array) -> float:
    """Root mean square (NaN for none)."""
    return math.sqrt(float(np.mean(values**2))) if len(values) else math.nan
