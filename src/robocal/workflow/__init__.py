"""Use cases over the library: what the command line, the GUI and the fleet runs do alike.

:func:`calibrate_file` calibrates one measurement file into a folder (read, noise, split,
model, calibrate, provenance, validate, save, report) from a frozen :class:`CalibrateRequest`
and answers a frozen :class:`SavedRun`."""

from robocal.measure.dataset.options import ReaderOptions
from robocal.workflow.calibrate_file import calibrate_file, check_noise, check_out, split
from robocal.workflow.request import (
    STAGES,
    CalibrateFileError,
    CalibrateRequest,
    FitOptions,
    Iteration,
    Notify,
    Progress,
    SavedRun,
)

__all__ = [
    "STAGES",
    "CalibrateFileError",
    "CalibrateRequest",
    "FitOptions",
    "Iteration",
    "Notify",
    "Progress",
    "ReaderOptions",
    "SavedRun",
    "calibrate_file",
    "check_noise",
    "check_out",
    "split",
]
