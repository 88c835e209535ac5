"""What the report shows, computed once: frozen, typed section data.

:func:`robocal.evaluate.report.collect.collect_report` fills a :class:`ReportData` from a
calibration result, its measurements and an evaluation; the renderers
(:mod:`~robocal.evaluate.report.sections`, :mod:`~robocal.evaluate.report.sections_eval`)
only format it.  A section whose data is absent is None (the renderer says so in one
sentence or leaves the section out).  Units: SI (m, rad) unless a field's name says
otherwise (``_mm``, ``_deg``).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from robocal.evaluate.error_tables import ErrorTable, Improvement
from robocal.evaluate.metrics import PathAccuracy, PoseCharacteristics
from robocal.identify.validate import ValidationStats
from robocal.model.chain import Model

__all__ = [
    "CompensationData",
    "ComplianceRow",
    "CoverageData",
    "EffectsData",
    "IdentifiabilityData",
    "IsoData",
    "IsoLogData",
    "LearnedCurve",
    "ModelChoiceData",
    "ParameterRow",
    "PathData",
    "PoseSet",
    "ReportData",
    "ReportOptions",
    "ResidualsData",
    "ResultFacts",
    "ValidationData",
]

Array = NDArray[np.float64]


@dataclass(frozen=True)
class ReportOptions:
    """How the report is written.

    Attributes:
        title: the page's heading (default "Calibration report: <model>").
        written: the time stamp shown under provenance (ISO 8601; default: now).
    """

    title: str | None = None
    written: str | None = None


@dataclass(frozen=True)
class ResultFacts:
    """Everything the report reads from a calibration result, read in one place
    (:func:`robocal.evaluate.report.facts.report_data_from_result`)."""

    model: Model
    measurement_chain: Model | None
    T_device_base: Array  # (4, 4)
    measure: str
    method: str
    converged: bool
    message: str
    n: int
    iterations: int
    seconds: float
    residual_std_m: float
    rms_before_m: float
    rms_after_m: float
    condition_number: float
    names: tuple[str, ...]
    nominal: Array
    estimates: Array
    std: Array
    dropped: tuple[Any, ...]  # robocal.identify Dropped records
    correlations: tuple[tuple[str, str, float], ...]  # |ρ| > 0.9
    compliance: Mapping[str, float]  # joint -> rad/(N·m)
    effects: Mapping[str, Mapping[str, tuple[float, float | None]]]  # joint -> field -> (value, σ)
    fit_to_noise: str | None  # its one-line summary
    warnings: tuple[str, ...]
    cv: Any | None  # robocal.identify.residual.stage.CVTable
    stored_validation: Mapping[str, Any] | None  # ValidationStats.to_dict() of the held-out rows
    inputs: tuple[tuple[str, str], ...]  # (label, value): data file, its SHA-256, split
    run_id: str | None


@dataclass(frozen=True)
class PoseSet:
    """One set of measured poses, for the coverage figures and table."""

    name: str
    colour: str
    n: int
    observes: str
    position_base_mm: Array  # (n, 3): tool positions by the calibrated model
    extent_mm: Array  # (3,): their extent along x, y, z
    joint_display: Array  # (n, dof): deg for revolute joints, mm for prismatic ones
    median_sigma_mm: float | None
    device: str | None


@dataclass(frozen=True)
class CoverageData:
    """Where the poses lie, with the ISO 9283 cube and the test paths (mm, base frame)."""

    sets: tuple[PoseSet, ...]
    joint_names: tuple[str, ...]
    limits_display: Array  # (dof, 2), deg / mm, non-finite where a joint is unlimited
    cube_edges_mm: Array | None  # (k, 3) with NaN rows between edges
    iso_points_mm: Array | None  # (5, 3)
    iso_labels: tuple[str, ...]
    paths_mm: tuple[tuple[str, Array], ...]


@dataclass(frozen=True)
class IdentifiabilityData:
    """The numbers that tell which parameters the measurements determine."""

    indices: tuple[tuple[str, float], ...]  # O1-O5 (label with its meaning, value); () without data
    singular_values: Array | None
    dropped: tuple[tuple[str, str, str], ...]  # (parameter, reason, absorbed by / detail)


@dataclass(frozen=True)
class ParameterRow:
    """One estimated parameter in display units (mm or deg)."""

    name: str
    group: str  # robot, device frame, tool
    unit: str
    start: float
    estimate: float
    std: float
    true_delta: float | None

    @property
    def delta(self) -> float:
        return self.estimate - self.start

    @property
    def kind(self) -> str:
        return "angle" if self.unit == "deg" else "length"


@dataclass(frozen=True)
class ResidualsData:
    """Errors on the calibration poses, before (start model) and after calibration."""

    before: ValidationStats | None
    after: ValidationStats
    points_base_m: Array  # (n, 3) measured positions in the robot base frame
    vectors_before_m: Array | None  # (n, 3) base frame
    vectors_after_m: Array


@dataclass(frozen=True)
class ValidationData:
    """Errors on held-out poses."""

    rows: tuple[tuple[str, Mapping[str, Any]], ...]  # (model, ValidationStats.to_dict())
    after: ValidationStats | None  # None: only the statistics stored in the result
    before: ValidationStats | None = None
    improvement: Improvement | None = None  # of the mean error, before -> after
    seed_table: ErrorTable | None = None
    orientation_table: ErrorTable | None = None


@dataclass(frozen=True)
class PathData:
    """A test path and its ISO 9283 path accuracy per command case."""

    name: str
    along_mm: Array  # (m,) arc length of the commanded path
    accuracy: Mapping[str, PathAccuracy]


@dataclass(frozen=True)
class IsoData:
    """ISO 9283 pose and path characteristics of the evaluation."""

    poses: Mapping[str, PoseCharacteristics]  # per command case
    cycles: int | None
    cube_side_m: float | None
    cube_plane: int | None
    paths: tuple[PathData, ...]


@dataclass(frozen=True)
class IsoLogData:
    """The fourteen characteristics of a measurement log (``robocal iso9283 --json``)."""

    source: str
    band_mm: float | None
    rows: tuple[tuple[str, str, str, str, str], ...]  # (#, characteristic, clause, result, cycles)


@dataclass(frozen=True)
class ComplianceRow:
    """An identified joint compliance (rad/(N·m)) with its σ and, in a simulation, the truth."""

    joint: str
    compliance: float
    sigma: float | None
    true: float | None


@dataclass(frozen=True)
class EffectsData:
    """Joint effects of the calibrated robot."""

    compliance: tuple[ComplianceRow, ...]
    other: tuple[tuple[str, str, float, float | None], ...]  # (joint, field, value SI, σ)
    held: tuple[tuple[str, str], ...]  # (coefficient, why it was not identified)
    displacement_m: Array | None  # (n,) tool displacement they cause at the poses


@dataclass(frozen=True)
class CompensationData:
    """The compensation method's settings (``evaluation["compensation"]``)."""

    items: tuple[tuple[str, str], ...]


@dataclass(frozen=True)
class LearnedCurve:
    """The learned angle error of one joint over its range."""

    joint: str
    angle_deg: Array
    error_urad: Array


@dataclass(frozen=True)
class ModelChoiceData:
    """The cross-validation that chose the model, and the learned residual when chosen."""

    candidates: tuple[tuple[str, float, float, float], ...]  # (name, CV mean m, CV RMS m, fit s)
    chosen: str
    folds: int
    curves: tuple[LearnedCurve, ...]
    harmonics: int | None
    noise_std_m: float | None


@dataclass(frozen=True)
class ReportData:
    """The whole report's content.  Sections that are None have no data."""

    title: str
    facts: ResultFacts
    n_calibration: int  # poses the calibration used
    n_held_out: int | None
    coverage: CoverageData | None
    identifiability: IdentifiabilityData
    parameters: tuple[ParameterRow, ...]
    residuals: ResidualsData | None
    validation: ValidationData | None
    iso: IsoData | None
    iso_error: str | None
    iso_log: IsoLogData | None
    effects: EffectsData | None
    compensation: CompensationData | None
    model_choice: ModelChoiceData | None
    timings_s: tuple[tuple[str, float], ...]
    written: str
    version: str
