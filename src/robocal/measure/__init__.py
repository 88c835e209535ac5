"""Step 2 of a calibration — what was observed: datasets, devices, simulation, poses."""

from robocal.measure.dataset import (
    MeasurementFileError,
    Measurements,
    read_measurements,
    write_measurements,
)

__all__ = ["MeasurementFileError", "Measurements", "read_measurements", "write_measurements"]
