"""robocal — calibration of serial robot arms.

>>> import robocal as rc
>>> model = rc.robot("ur10")                  # the catalog's chain (UR's DH table)
>>> calib = rc.calibration_model("ur10")     # the complete model to calibrate it with
>>> T = model.fk([[0, -1.57, 1.57, 0, 1.57, 0]])   # (1, 4, 4) tool frame, m
"""

from importlib.metadata import PackageNotFoundError, version

from robocal import spatial
from robocal.compensate import compensate
from robocal.identify import CalibrationResult, calibrate, cross_validate, validate
from robocal.measure import Measurements, read_measurements, write_measurements
from robocal.model import (
    Body,
    Joint,
    JointEffects,
    Model,
    ModelFileError,
    Step,
    calibration_model,
    load_model,
    robot,
    robots,
    save_model,
)
from robocal.model.builder import build_model

try:
    __version__ = version("robocal")
except PackageNotFoundError:  # pragma: no cover - running from a source tree
    __version__ = "0.0.0"

__all__ = [
    "Body",
    "CalibrationResult",
    "Joint",
    "JointEffects",
    "Measurements",
    "Model",
    "ModelFileError",
    "Step",
    "__version__",
    "build_model",
    "calibrate",
    "calibration_model",
    "compensate",
    "cross_validate",
    "load_model",
    "model_from_urdf",
    "read_measurements",
    "robot",
    "robots",
    "save_model",
    "spatial",
    "validate",
    "write_measurements",
]


def model_from_urdf(path, measure: str = "pose", tip: str | None = None) -> Model:
    """A complete, minimal, singularity-free calibration model of a URDF robot."""
    from robocal.model.urdf import model_from_urdf as _from_urdf  # Pinocchio: imported on use

    return _from_urdf(path, measure, tip)
