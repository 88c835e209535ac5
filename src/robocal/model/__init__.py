"""Step 1 of a calibration — what the robot is: chains, conventions, files and the catalog."""

from robocal.lazy_imports import lazy_package

lazy_package(
    __name__,
    {
        "robocal.model.catalog": ("robot", "robots"),
        "robocal.model.chain": ("Body", "Joint", "JointEffects", "Model", "Role", "Step"),
        "robocal.model.complete": ("calibration_model",),
        "robocal.model.files": ("ModelFileError", "load_model", "save_model"),
    },
)

__all__ = [
    "Body",
    "Joint",
    "JointEffects",
    "Model",
    "ModelFileError",
    "Role",
    "Step",
    "calibration_model",
    "load_model",
    "robot",
    "robots",
    "save_model",
]
