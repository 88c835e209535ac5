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
    "BOUNDS_NAMES",
    "CHAIN_CHOICES",
    "DISTRIBUTIONS",
    "FRAMES",
    "INCOMPLETE_MODES",
    "INDEX_NAMES",
    "LENGTH_UNIT_NAMES",
    "LIMITS_MODES",
    "LOSSES",
    "MEASURES",
    "POSE_METHODS",
    "POSE_ROWS",
    "RESIDUAL_CHOICES",
    "SOLVER_METHODS",
    "TARGET_KINDS",
    "AngleUnit",
    "BoundsName",
    "ChainChoice",
    "Distribution",
    "Frame",
    "IncompleteMode",
    "IndexName",
    "LengthUnit",
    "LimitsMode",
    "Loss",
    "Measure",
    "PoseMethod",
    "PoseRows",
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

#: ``method="lm"``'s loss: least squares, or one of scipy's robust losses that down-weight
#: residuals beyond ``f_scale``
Loss = Literal["linear", "soft_l1", "huber", "cauchy", "arctan"]
LOSSES: tuple[Loss, ...] = get_args(Loss)

#: ``method="bounded"``'s bounds by name: seed 001's ±5 mm / ±2° on every robot parameter, or
#: those bounds widened for the parameters that absorb redundant ones
BoundsName = Literal["default", "widened"]
BOUNDS_NAMES: tuple[BoundsName, ...] = get_args(BoundsName)

#: the chain calibrated for a catalog robot: the complete model from its joint geometry, or
#: the catalog's chain as published
ChainChoice = Literal["complete", "catalog"]
CHAIN_CHOICES: tuple[ChainChoice, ...] = get_args(ChainChoice)

#: the quantities a pose plan is for: tool positions or poses, constraint configurations at a
#: socket (point), on a plate (plane), ball-bar pairs (distance), or inclinometer readings (tilt)
PoseRows = Literal["position", "pose", "point", "plane", "distance", "tilt"]
POSE_ROWS: tuple[PoseRows, ...] = get_args(PoseRows)
