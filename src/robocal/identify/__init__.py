"""Step 3 of a calibration — what the parameters really are: identification and validation."""

from robocal.identify.calibrate import CalibrationResult, calibrate
from robocal.identify.observability import Dropped, IdentifiableSubset, identifiable_subset
from robocal.identify.validate import ValidationStats, cross_validate, validate

__all__ = [
    "CalibrationResult",
    "Dropped",
    "IdentifiableSubset",
    "ValidationStats",
    "calibrate",
    "cross_validate",
    "identifiable_subset",
    "validate",
]
