"""robocal — calibration of serial robot arms.

>>> import robocal as rc
>>> model = rc.robot("ur10")                  # the catalog's chain (UR's DH table)
>>> calib = rc.calibration_model("ur10")     # the complete model to calibrate it with
>>> T = model.fk([[0, -1.57, 1.57, 0, 1.57, 0]])   # (1, 4, 4) tool frame, m
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Literal

from robocal._lazy import lazy_package

# Loaded on first use (robocal._lazy): the command line starts without numpy (robocal.spatial),
# importlib.metadata (the version) or numpy's heavier neighbours (scipy.stats, Pinocchio,
# plotly, Dask); tests/test_startup.py checks it.
lazy_package(
    __name__,
    {
        "robocal._version": ("__version__",),
        "robocal.compensate.compensation": ("compensate_targets",),
        "robocal.identify.calibrate": ("CalibrationResult", "calibrate"),
        "robocal.identify.validate": ("cross_validate", "validate"),
        "robocal.measure.dataset": ("Measurements", "read_measurements", "write_measurements"),
        "robocal.model.chain": ("Body", "Joint", "JointEffects", "Model", "Step"),
        "robocal.model.complete": ("calibration_model",),
        "robocal.model.files": ("ModelFileError", "load_model", "save_model"),
        "robocal.model.catalog": ("robot", "robots"),
        "robocal.model.builder": ("build_model",),
    },
    submodules=("spatial",),
)

if TYPE_CHECKING:  # what the lazy map provides, for type checkers (tests/test_typing.py keeps them equal)
    from pathlib import Path

    from robocal import spatial
    from robocal._version import __version__
    from robocal.compensate.compensation import compensate_targets
    from robocal.identify.calibrate import CalibrationResult, calibrate
    from robocal.identify.validate import cross_validate, validate
    from robocal.measure.dataset import Measurements, read_measurements, write_measurements
    from robocal.model.builder import build_model
    from robocal.model.catalog import robot, robots
    from robocal.model.chain import Body, Joint, JointEffects, Model, Step
    from robocal.model.complete import calibration_model
    from robocal.model.files import ModelFileError, load_model, save_model


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
    "compensate_targets",
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


def model_from_urdf(
    path: str | Path, measure: Literal["position", "pose"] = "pose", tip: str | None = None
) -> Model:
    """A complete, minimal, singularity-free calibration model of a URDF robot."""
    from robocal.model.urdf import model_from_urdf as _from_urdf  # Pinocchio: imported on use

    return _from_urdf(path, measure, tip)
