"""Step 2 of a calibration — what was observed: datasets, devices, simulation, poses."""

from robocal.measure.dataset import (
    MeasurementFileError,
    Measurements,
    MeasurementWarning,
    Problem,
    check_measurements,
    read_measurements,
    write_measurements,
)
from robocal.measure.devices import (
    CalibrationPlate,
    Camera,
    Device,
    LaserTracker,
    Observations,
    OpticalCMM,
    PenOnPaper,
    make_device,
    plate_points,
)
from robocal.measure.simulate import (
    EncoderNoise,
    PayloadCompliance,
    Truth,
    VirtualRobot,
    draw_true_model,
    load_truth,
    save_simulation,
    simulate,
)

__all__ = [
    "CalibrationPlate",
    "Camera",
    "Device",
    "EncoderNoise",
    "LaserTracker",
    "MeasurementFileError",
    "MeasurementWarning",
    "Measurements",
    "Observations",
    "OpticalCMM",
    "PayloadCompliance",
    "PenOnPaper",
    "Problem",
    "Truth",
    "VirtualRobot",
    "check_measurements",
    "draw_true_model",
    "load_truth",
    "make_device",
    "plate_points",
    "read_measurements",
    "save_simulation",
    "simulate",
    "write_measurements",
]
