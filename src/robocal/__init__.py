"""robocal — calibration of serial robot arms.

>>> import robocal as rc
>>> model = rc.robot("ur10")                  # the catalog's chain (UR's DH table)
>>> calib = rc.calibration_model("ur10")     # the complete model to calibrate it with
>>> T = model.fk([[0, -1.57, 1.57, 0, 1.57, 0]])   # (1, 4, 4) tool frame, m
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Literal

from robocal.lazy_imports import lazy_package

# Loaded on first use (robocal.lazy_imports): the command line starts without numpy (robocal.spatial),
# importlib.metadata (the version) or numpy's heavier neighbours (scipy.stats, Pinocchio,
# plotly, Dask); tests/test_startup.py checks it.
lazy_package(
    __name__,
    {
        "robocal._version": ("__version__",),
        "robocal.compensate.compensation": ("compensate_targets",),
        "robocal.identify.calibrate": ("calibrate",),
        "robocal.identify.result": ("CalibrationResult",),
        "robocal.identify.validate": ("cross_validate", "validate"),
        "robocal.measure.dataset.read": ("read_measurements",),
        "robocal.measure.dataset.writer": ("write_measurements",),
        "robocal.measure.measurements": ("Measurements",),
        "robocal.model.builder": ("build_model",),
        "robocal.model.catalog": ("robot", "robots"),
        "robocal.model.chain": ("Model",),
        "robocal.model.complete": ("calibration_model",),
        "robocal.model.files": ("load_model", "save_model"),
        "robocal.model.steps": ("Body", "Joint", "JointEffects", "Step"),
        "robocal.model.yaml_files": ("ModelFileError",),
    },
    submodules=("spatial",),
)

if TYPE_CHECKING:  # what the lazy map provides, for type checkers (tests/test_typing.py keeps them equal)
    from pathlib import Path

    from robocal import spatial
    from robocal._version import __version__
    from robocal.compensate.compensation import compensate_targets
    from robocal.identify.calibrate import calibrate
    from robocal.identify.result import CalibrationResult
    from robocal.identify.validate import cross_validate, validate
    from robocal.measure.dataset.read import read_measurements
    from robocal.measure.dataset.writer import write_measurements
    from robocal.measure.measurements import Measurements
    from robocal.model.builder import build_model
    from robocal.model.catalog import robot, robots
    from robocal.model.chain import Model
    from robocal.model.complete import calibration_model
    from robocal.model.files import load_model, save_model
    from robocal.model.steps import Body, Joint, JointEffects, Step
    from robocal.model.yaml_files import ModelFileError


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
    """A complete, minimal, singularity-free calibration model of a URDF robot.

    The chain runs from the URDF's root to ``tip`` (default: the end of its one chain of
    joints; a branching robot must name it); what is off the chain is ignored.  The links'
    ``<inertial>`` masses become the model's ``bodies`` (each on the frame after the last
    joint before it), so joint compliance under gravity can be identified
    (``effects=("compliance",)``, ``--effects compliance``).
    """
    from robocal.model.urdf.read import model_from_urdf as _from_urdf  # Pinocchio: imported on use

    return _from_urdf(path, measure, tip)
