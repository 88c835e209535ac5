"""Evaluation — did it work, shown to a person: ISO 9283 metrics, the seeds' error
tables and the self-contained HTML report."""

from typing import TYPE_CHECKING

from robocal.lazy_imports import lazy_package

lazy_package(
    __name__,
    {
        "robocal.evaluate.metrics": (
            "ERROR_QUANTITIES",
            "ErrorTable",
            "Improvement",
            "PathAccuracy",
            "PoseAccuracy",
            "PoseCharacteristics",
            "PoseErrors",
            "PoseRepeatability",
            "error_table",
            "improvement",
            "iso9283_pose_characteristics",
            "mean_ci",
            "path_accuracy",
            "pose_accuracy",
            "pose_errors",
            "pose_repeatability",
        ),
        "robocal.evaluate.report": ("build_report", "write_report"),
    },
)

if TYPE_CHECKING:  # what the lazy map provides, for type checkers (tests/test_typing.py keeps them equal)
    from robocal.evaluate.metrics import (
        ERROR_QUANTITIES,
        ErrorTable,
        Improvement,
        PathAccuracy,
        PoseAccuracy,
        PoseCharacteristics,
        PoseErrors,
        PoseRepeatability,
        error_table,
        improvement,
        iso9283_pose_characteristics,
        mean_ci,
        path_accuracy,
        pose_accuracy,
        pose_errors,
        pose_repeatability,
    )
    from robocal.evaluate.report import build_report, write_report

__all__ = [
    "ERROR_QUANTITIES",
    "ErrorTable",
    "Improvement",
    "PathAccuracy",
    "PoseAccuracy",
    "PoseCharacteristics",
    "PoseErrors",
    "PoseRepeatability",
    "build_report",
    "error_table",
    "improvement",
    "iso9283_pose_characteristics",
    "mean_ci",
    "path_accuracy",
    "pose_accuracy",
    "pose_errors",
    "pose_repeatability",
    "write_report",
]
