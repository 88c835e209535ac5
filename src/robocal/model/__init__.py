"""Step 1 of a calibration — what the robot is: chains, conventions, files and the catalog."""

from typing import TYPE_CHECKING

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

if TYPE_CHECKING:  # what the lazy map provides, for type checkers (tests/test_typing.py keeps them equal)
    from robocal.model.catalog import robot, robots
    from robocal.model.chain import Body, Joint, JointEffects, Model, Role, Step
    from robocal.model.complete import calibration_model
    from robocal.model.files import ModelFileError, load_model, save_model

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
