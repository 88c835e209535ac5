"""Step 3 of a calibration — what the parameters really are: identification and validation."""

from typing import TYPE_CHECKING

from robocal.lazy_imports import lazy_package

lazy_package(
    __name__,
    {
        "robocal.identify.calibrate": ("CalibrationResult", "calibrate"),
        "robocal.identify.observability": ("Dropped", "IdentifiableSubset", "identifiable_subset"),
        "robocal.identify.options": (
            "Bounds",
            "CalibrationOptions",
            "JointEffects",
            "PerPose",
            "Pruning",
            "RobustLoss",
            "Setup",
            "Weights",
        ),
        "robocal.identify.result": ("CalibrationWarning", "Diagnostics"),
        "robocal.identify.validate": ("ValidationStats", "cross_validate", "validate"),
    },
)

if TYPE_CHECKING:  # what the lazy map provides, for type checkers (tests/test_typing.py keeps them equal)
    from robocal.identify.calibrate import CalibrationResult, calibrate
    from robocal.identify.observability import Dropped, IdentifiableSubset, identifiable_subset
    from robocal.identify.options import (
        Bounds,
        CalibrationOptions,
        JointEffects,
        PerPose,
        Pruning,
        RobustLoss,
        Setup,
        Weights,
    )
    from robocal.identify.result import CalibrationWarning, Diagnostics
    from robocal.identify.validate import ValidationStats, cross_validate, validate

__all__ = [
    "Bounds",
    "CalibrationOptions",
    "CalibrationResult",
    "CalibrationWarning",
    "Diagnostics",
    "Dropped",
    "IdentifiableSubset",
    "JointEffects",
    "PerPose",
    "Pruning",
    "RobustLoss",
    "Setup",
    "ValidationStats",
    "Weights",
    "calibrate",
    "cross_validate",
    "identifiable_subset",
    "validate",
]
