"""Step 3 of a calibration — what the parameters really are: identification and validation."""

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
