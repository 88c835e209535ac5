"""Step 4 of a calibration — what to command instead: corrected joint commands for
Cartesian targets, calibration filters for joint programs, path correction (full IK or
seed 003 eq. 5.22) and off-line program files (``robocal compensate``)."""

from typing import TYPE_CHECKING

from robocal.lazy_imports import lazy_package

lazy_package(
    __name__,
    {
        "robocal.compensate.compensation": ("compensate_targets", "filter_program", "nominal_model"),
        "robocal.compensate.ik_options": ("IKOptions",),
        "robocal.compensate.result": ("Compensation",),
        "robocal.compensate.paths": ("PathCompensation", "compensate_cartesian_path", "compensate_path"),
        "robocal.compensate.target_files": ("TargetFileError", "Targets", "read_program", "read_targets"),
    },
)

if TYPE_CHECKING:  # what the lazy map provides, for type checkers (tests/test_typing.py keeps them equal)
    from robocal.compensate.compensation import compensate_targets, filter_program, nominal_model
    from robocal.compensate.ik_options import IKOptions
    from robocal.compensate.paths import PathCompensation, compensate_cartesian_path, compensate_path
    from robocal.compensate.result import Compensation
    from robocal.compensate.target_files import TargetFileError, Targets, read_program, read_targets

__all__ = [
    "Compensation",
    "IKOptions",
    "PathCompensation",
    "TargetFileError",
    "Targets",
    "compensate_cartesian_path",
    "compensate_path",
    "compensate_targets",
    "filter_program",
    "nominal_model",
    "read_program",
    "read_targets",
]
