"""The fixed choices of robocal's options, each written once for the API and the command line.

Each choice set is a ``Literal`` alias (what the API's signatures take, so mypy checks a
caller's string) and the tuple of its values (``typing.get_args``), which the command line's
options offer: ``robocal`` declares those options with the alias itself, and Typer turns a
``Literal`` into a ``click.Choice`` of exactly these values.  The modules that own each concept
(``robocal.measure.measurements`` for ``LimitsMode`` ...) import their alias from here.

Kept apart from those modules because the command line imports its options at start-up, before
any command runs, and must not load numpy for that (tests/test_startup.py): this module imports
only :mod:`typing`.
"""

from __future__ import annotations

from typing import Literal, get_args

__all__ = [
    "ANGLE_UNIT_NAMES",
    "DISTRIBUTIONS",
    "FRAMES",
    "INCOMPLETE_MODES",
    "INDEX_NAMES",
    "LENGTH_UNIT_NAMES",
    "LIMITS_MODES",
    "MEASURES",
    "POSE_METHODS",
    "RESIDUAL_CHOICES",
    "SOLVER_METHODS",
    "TARGET_KINDS",
    "AngleUnit",
    "Distribution",
    "Frame",
    "IncompleteMode",
    "IndexName",
    "LengthUnit",
    "LimitsMode",
    "Measure",
    "PoseMethod",
    "ResidualChoice",
    "SolverMethod",
    "TargetKind",
]

#: joint values beyond the model's limits: refused, warned about, or accepted
LimitsMode = Literal["error", "warn", "ignore"]
LIMITS_MODES: tuple[LimitsMode, ...] = get_args(LimitsMode)

#: a row with an empty or bad cell: refused, or left out with a warning
IncompleteMode = Literal["error", "drop"]
INCOMPLETE_MODES: tuple[IncompleteMode, ...] = get_args(IncompleteMode)

#: what a device measures of the tool: its position, or its whole pose
Measure = Literal["position", "pose"]
MEASURES: tuple[Measure, ...] = get_args(Measure)

#: what an IK target fixes: the position, the pose, or the position and the tool axis
TargetKind = Literal["position", "pose", "axis"]
TARGET_KINDS: tuple[TargetKind, ...] = get_args(TargetKind)

#: the frame targets are written in: the robot's base, or the measuring device's
Frame = Literal["base", "measurement"]
FRAMES: tuple[Frame, ...] = get_args(Frame)

#: how a simulated robot's parameter errors are drawn within their tolerances
Distribution = Literal["uniform", "normal"]
DISTRIBUTIONS: tuple[Distribution, ...] = get_args(Distribution)

#: the observability indices of Sun and Hollerbach (O1 .. O5)
IndexName = Literal["O1", "O2", "O3", "O4", "O5"]
INDEX_NAMES: tuple[IndexName, ...] = get_args(IndexName)

#: how ``robocal poses`` chooses poses: random, maximising an index, ISO 9283's P1..P5, or
#: the thesis' diagonal planes
PoseMethod = Literal["random", "optimal", "iso9283", "diagonal"]
POSE_METHODS: tuple[PoseMethod, ...] = get_args(PoseMethod)

#: the unit of lengths in a file or an option's values (robocal.units.LENGTH_UNITS' names)
LengthUnit = Literal["m", "mm", "um"]
LENGTH_UNIT_NAMES: tuple[LengthUnit, ...] = get_args(LengthUnit)

#: the unit of angles in a file or an option's values
AngleUnit = Literal["rad", "deg"]
ANGLE_UNIT_NAMES: tuple[AngleUnit, ...] = get_args(AngleUnit)

#: the calibration's solver: Levenberg-Marquardt, the pseudo-inverse, bounded least squares,
#: or the influence-coefficient method
SolverMethod = Literal["lm", "pinv", "bounded", "influence"]
SOLVER_METHODS: tuple[SolverMethod, ...] = get_args(SolverMethod)

#: the learned residual: none, chosen by cross-validation, or always the joint-angle Fourier one
ResidualChoice = Literal["none", "auto", "joint_fourier"]
RESIDUAL_CHOICES: tuple[ResidualChoice, ...] = get_args(ResidualChoice)
