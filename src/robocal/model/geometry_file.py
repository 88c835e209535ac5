"""Joint-geometry files (YAML), read and checked; :func:`robocal.model.builder.load_geometry`
makes one a :class:`~robocal.model.builder.Geometry`."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, ValidationError

from robocal import spatial
from robocal.model.files import Number
from robocal.model.geometry import (
    DEFAULT_PARALLEL_TOLERANCE,
    GeometryError,
    JointGeometry,
    Measure,
    Tcp,
    normalise,
)
from robocal.units import ANGLE_UNITS, LENGTH_UNITS

_Config = ConfigDict(extra="forbid", allow_inf_nan=False)


class _JointSpec(BaseModel):
    model_config = _Config
    type: Literal["revolute", "prismatic"]
    position: tuple[Number, Number, Number]
    axis: tuple[Number, Number, Number]
    name: str | None = Field(default=None, min_length=1)
    limits: tuple[Number, Number] | None = None


class _TcpSpec(BaseModel):
    model_config = _Config
    position: tuple[Number, Number, Number] = (0.0, 0.0, 0.0)
    rpy: tuple[Number, Number, Number] | None = None  # Rz(yaw) Ry(pitch) Rx(roll), angle unit
    quaternion: tuple[Number, Number, Number, Number] | None = None  # w, x, y, z


class _GeometryFile(BaseModel):
    model_config = _Config
    name: str = Field(min_length=1)
    title: str = ""
    source: str = ""
    unit: Literal["m", "mm"] = "m"
    angle_unit: Literal["rad", "deg"] = "deg"
    measure: Literal["position", "pose"] = "pose"
    parallel_tolerance: Number | None = None  # angle unit
    joints: list[_JointSpec] = Field(min_length=1)
    tcp: _TcpSpec = _TcpSpec()


def _times(v: tuple[float, float, float], scale: float) -> tuple[float, float, float]:
    return v[0] * scale, v[1] * scale, v[2] * scale


def read_geometry_file(
    path: str | Path,
) -> tuple[str, tuple[JointGeometry, ...], Tcp, Measure, float, str, str]:
    """A geometry file's fields, checked and in SI units: name, joints, TCP, measure, parallel
    tolerance (rad), title, source (:func:`robocal.model.builder.load_geometry` makes them a
    :class:`~robocal.model.builder.Geometry`)."""
    from robocal.model.files import format_validation_error
    from robocal.model.yaml_files import read_yaml

    path = Path(path)
    data = read_yaml(path, "geometry", GeometryError)
    if not isinstance(data, dict):
        raise GeometryError(f"{path}: a geometry file must be a mapping")
    try:
        spec = _GeometryFile.model_validate(data)
    except ValidationError as err:
        raise GeometryError(f"{path}: {format_validation_error(err)}") from None
    L, A = LENGTH_UNITS[spec.unit], ANGLE_UNITS[spec.angle_unit]  # the schema allows m|mm, rad|deg
    joints = []
    for j in spec.joints:
        lim = None
        if j.limits is not None:
            scale = A if j.type == "revolute" else L
            lim = (j.limits[0] * scale, j.limits[1] * scale)
        joints.append(JointGeometry(j.type, _times(j.position, L), j.axis, j.name, lim))
    rotation = None
    if spec.tcp.rpy is not None and spec.tcp.quaternion is not None:
        raise GeometryError(f"{path}: tcp: give either rpy or quaternion, not both")
    if spec.tcp.rpy is not None:
        r, p, y = (v * A for v in spec.tcp.rpy)
        rotation = spatial.euler_to_matrix([r, p, y], "xyz")
    elif spec.tcp.quaternion is not None:
        norm = math.sqrt(sum(v * v for v in spec.tcp.quaternion))
        if not abs(norm - 1.0) < 0.01:  # a unit quaternion written with four digits is within 1e-4
            raise GeometryError(
                f"{path}: tcp.quaternion: {list(spec.tcp.quaternion)} has norm {norm:.3g}, not 1 (w, x, y, z)"
            )
        rotation = spatial.quaternion_to_matrix(np.asarray(spec.tcp.quaternion) / norm)
    tcp = Tcp(_times(spec.tcp.position, L), None if rotation is None else tuple(map(tuple, rotation)))
    tol = DEFAULT_PARALLEL_TOLERANCE if spec.parallel_tolerance is None else spec.parallel_tolerance * A
    try:
        normalise(joints, tcp)
    except GeometryError as err:
        raise GeometryError(f"{path}: {err}") from None
    return spec.name, tuple(joints), tcp, spec.measure, tol, spec.title, spec.source
