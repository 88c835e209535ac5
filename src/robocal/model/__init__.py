"""Step 1 of a calibration — what the robot is: chains, conventions, files and the catalog."""

from robocal.model.catalog import robot, robots
from robocal.model.chain import Body, Joint, JointEffects, Model, Step
from robocal.model.complete import calibration_model
from robocal.model.files import ModelFileError, load_model, save_model

__all__ = [
    "Body",
    "Joint",
    "JointEffects",
    "Model",
    "ModelFileError",
    "Step",
    "calibration_model",
    "load_model",
    "robot",
    "robots",
    "save_model",
]
