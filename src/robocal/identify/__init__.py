"""Step 3 of a calibration — what the parameters really are: identification and validation."""

from robocal.identify.calibrate import CalibrationResult, calibrate
from robocal.identify.subset import Dropped, select_columns
from robocal.identify.validate import ValidationStats, cross_validate, validate

__all__ = [
    "CalibrationResult",
    "Dropped",
    "ValidationStats",
    "calibrate",
    "cross_validate",
    "select_columns",
    "validate",
]
