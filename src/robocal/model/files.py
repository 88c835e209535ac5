"""YAML model files: read (validated), write (atomic, exact round trip).

A model file describes one chain.  Two forms are accepted and may be combined with
optional ``base`` and ``tool`` step lists:

``links`` with a ``convention`` (``dh``, ``mdh`` or ``hayati``), one row per joint::

    name: ur10
    units: {length: mm, angle: deg}
    convention: dh
    links:
      - {theta: 0, d: 127.3, a: 0, alpha: 90, joint: shoulder_pan, limits: [-360, 360]}

or an explicit ``chain`` of elementary steps::

    chain:
      - {motion: Rz, param: theta1, value: 0, joint: q1, limits: [-169.5, 169.5]}
      - {motion: Tx, param: a2, value: 190, free: false}

Step fields: ``motion`` (Tx Ty Tz Rx Ry Rz), ``param`` (unique name), ``value``
(nominal; the offset for a joint step), ``free`` (default true), ``bounds``
(``[lower, upper]`` on the value), ``joint`` (joint name: the step is driven by that
joint variable) and ``limits`` (joint limits).  Link rows: ``theta d a alpha``
(``beta`` for hayati, optional ``d``), ``type`` (revolute/prismatic), ``joint``,
``limits``, ``free`` and ``fixed`` (names of the row's parameters to keep fixed,
e.g. ``[alpha]``).  ``bodies`` give mass properties: ``name``, ``frame`` (the
parameter after whose step the body frame is taken), ``mass`` (kg), ``com``
(length unit), ``inertia`` (``[Ixx, Iyy, Izz, Ixy, Ixz, Iyz]`` in kg·m², always SI).

``joint_effects`` give each joint's non-geometric parameters (seed 003 Table 5.2,
:class:`~robocal.model.chain.JointEffects`)::

    units: {length: mm, angle: deg, stiffness: kgf*m/deg}
    joint_effects:
      - {joint: q2, clearance_tilt: 0.024, backlash: 0.061, stiffness: 90}

Fields: ``joint``, ``clearance_tilt`` (angle unit), ``backlash`` (angle unit; length
unit for a prismatic joint), ``stiffness`` (``units.stiffness``: ``N*m/rad`` (default),
``N*m/deg`` or ``kgf*m/deg`` as in seed 003; N/m for a prismatic joint, SI files only)
or ``compliance`` (its inverse, always SI: rad/(N·m) or m/N), ``radial_stiffness`` or
``radial_compliance`` (the same for the tilt), ``shaft_length`` (length unit).

Lengths and angles are in ``units`` (default m and rad).  Files written by
:func:`save_model` use m and rad with shortest round-trip float formatting, so
``load_model(save_model(m))`` equals ``m`` exactly.
"""

from __future__ import annotations

import dataclasses
import os
from pathlib import Path
from typing import Annotated, Any, Literal, TypedDict

import yaml
from pydantic import BaseModel, ConfigDict, Field, Strict, ValidationError, model_validator

from robocal.model import conventions
from robocal.model.chain import Model
from robocal.model.steps import Body, Joint, JointEffects, Role, Step
from robocal.model.yaml_files import ModelFileError, read_yaml  # re-exported
from robocal.outdir import atomic_write_bytes, atomic_write_text  # the one atomic writer, re-exported
from robocal.units import ANGLE_UNITS, LENGTH_UNITS, STIFFNESS_UNITS

__all__ = [
    "ModelFileError",
    "atomic_write_bytes",
    "atomic_write_text",
    "load_model",
    "model_from_dict",
    "model_to_dict",
    "read_yaml",
    "save_model",
]

FORMAT_VERSION = 1
#: Elementary steps a model file may describe (a 6-DOF arm has about 30; the limit keeps
#: a hostile file from costing minutes of checks).
MAX_STEPS = 1000

LENGTH_SCALE, ANGLE_SCALE = LENGTH_UNITS, ANGLE_UNITS  # robocal.units (the file schema allows m/mm, rad/deg)


_Config = ConfigDict(extra="forbid", allow_inf_nan=False, str_strip_whitespace=True)
#: A number in a file: an int or a float, never a YAML yes/no/true/false (which pydantic
#: would otherwise take as 1.0 / 0.0) nor a quoted string
Number = Annotated[float, Strict()]
#: A whole number in a file, never a yes/no
Count = Annotated[int, Strict()]
Pair = tuple[Number, Number]
Name = Annotated[str, Field(min_length=1)]


class _Units(BaseModel):
    model_config = _Config
    length: Literal["m", "mm"] = "m"
    angle: Literal["rad", "deg"] = "rad"
    stiffness: Literal["N*m/rad", "N*m/deg", "kgf*m/deg"] = "N*m/rad"


#: N·m/rad per unit of each stiffness unit (kgf: standard gravity 9.80665 m/s²)
STIFFNESS_SCALE = STIFFNESS_UNITS


class _StepSpec(BaseModel):
    model_config = _Config
    motion: Literal["Tx", "Ty", "Tz", "Rx", "Ry", "Rz"]
    param: Name
    value: Number = 0.0
    free: bool = True
    bounds: Pair | None = None
    joint: Name | None = None
    limits: Pair | None = None
    role: Literal["kinematic", "tool", "device"] | None = None  # absent (older files): from the name

    @model_validator(mode="after")
    def _limits_need_joint(self) -> _StepSpec:
        if self.limits is not None and self.joint is None:
            raise ValueError("'limits' given for a step that is not a joint (add 'joint: NAME')")
        return self


class _LinkRow(BaseModel):
    model_config = _Config
    theta: Number = 0.0
    d: Number | None = None
    a: Number = 0.0
    alpha: Number = 0.0
    beta: Number | None = None
    type: Literal["revolute", "prismatic"] = "revolute"
    joint: Name | None = None
    limits: Pair | None = None
    free: bool = True
    fixed: list[Literal["theta", "d", "a", "alpha", "beta"]] = []


class _BodySpec(BaseModel):
    model_config = _Config
    name: Name
    frame: Name
    mass: Annotated[Number, Field(ge=0)]
    com: tuple[Number, Number, Number] = (0.0, 0.0, 0.0)
    inertia: tuple[Number, Number, Number, Number, Number, Number] | None = None


class _JointEffectsSpec(BaseModel):
    model_config = _Config
    joint: Name
    clearance_tilt: Number = 0.0
    backlash: Number = 0.0
    stiffness: Annotated[Number, Field(gt=0)] | None = None
    compliance: Number | None = None
    radial_stiffness: Annotated[Number, Field(gt=0)] | None = None
    radial_compliance: Number | None = None
    shaft_length: Annotated[Number, Field(gt=0)] | None = None

    @model_validator(mode="after")
    def _stiffness_or_compliance(self) -> _JointEffectsSpec:
        for kind in ("", "radial_"):
            k, c = getattr(self, kind + "stiffness"), getattr(self, kind + "compliance")
            if k is not None and c is not None:
                raise ValueError(f"give '{kind}stiffness' or '{kind}compliance' (its inverse), not both")
        return self


class _ModelFile(BaseModel):
    model_config = _Config
    robocal_model: Literal[1] = 1
    name: Name
    title: str = ""
    source: str = ""
    notes: str = ""
    units: _Units = _Units()
    convention: Literal["dh", "mdh", "hayati"] | None = None
    base: list[_StepSpec] = []
    links: list[_LinkRow] = []
    chain: list[_StepSpec] = []
    tool: list[_StepSpec] = []
    bodies: list[_BodySpec] = []
    joint_effects: list[_JointEffectsSpec] = []
    residual: dict[str, Any] | None = None

    @model_validator(mode="after")
    def _one_form(self) -> _ModelFile:
        if self.links and self.chain:
            raise ValueError("give either 'links' (with 'convention') or 'chain', not both")
        if self.links and self.convention is None:
            raise ValueError("'links' needs 'convention: dh | mdh | hayati'")
        if not (self.links or self.chain or self.base or self.tool):
            raise ValueError("the model has no 'links' and no 'chain'")
        return self


def _scaled(pair: Pair | None, scale: float) -> tuple[float, float] | None:
    """``(lower, upper)`` in SI from a file's units (``scale``: SI per file unit)."""
    if pair is None:
        return None
    lo, hi = pair
    return lo * scale, hi * scale


class _JointOptions(TypedDict):
    """The joint keywords of :func:`robocal.model.conventions.dh` (and mdh, hayati)."""

    joint: Literal["revolute", "prismatic"]
    joint_name: str | None
    limits: tuple[float, float] | None
    free: bool


def _step(spec: _StepSpec, units: _Units) -> Step:
    scale = ANGLE_SCALE[units.angle] if spec.motion[0] == "R" else LENGTH_SCALE[units.length]
    joint = None if spec.joint is None else Joint(spec.joint, _scaled(spec.limits, scale))
    bounds = _scaled(spec.bounds, scale)
    role = None if spec.role is None else Role(spec.role)  # None: from the name (older files)
    return Step(spec.motion, spec.param, spec.value * scale, spec.free, bounds, joint, role)


def _link_steps(row: _LinkRow, i: int, convention: str, units: _Units) -> list[Step]:
    L, A = LENGTH_SCALE[units.length], ANGLE_SCALE[units.angle]
    limit_scale = A if row.type == "revolute" else L
    limits = _scaled(row.limits, limit_scale)
    common = _JointOptions(joint=row.type, joint_name=row.joint, limits=limits, free=row.free)
    if convention == "dh":
        if row.beta is not None:
            raise ValueError(f"links[{i - 1}]: 'beta' is not a DH parameter (use convention: hayati)")
        steps = conventions.dh(i, row.theta * A, (row.d or 0.0) * L, row.a * L, row.alpha * A, **common)
    elif convention == "mdh":
        if row.beta is not None:
            raise ValueError(f"links[{i - 1}]: 'beta' is not a modified-DH parameter")
        steps = conventions.mdh(i, row.alpha * A, row.a * L, row.theta * A, (row.d or 0.0) * L, **common)
    else:
        d = None if row.d is None else row.d * L
        steps = conventions.hayati(
            i, row.theta * A, row.a * L, row.alpha * A, (row.beta or 0.0) * A, d, **common
        )
    if row.fixed:
        # parameter names of a row start with the symbol (theta3, alpha2 ...) and end
        # with a link index: fix those whose symbol is listed.
        fixed = set(row.fixed)
        steps = [
            Step(s.motion, s.name, s.value, False, s.bounds, s.joint, s.role)
            if s.name.rstrip("0123456789") in fixed
            else s
            for s in steps
        ]
    return steps


def _joint_effects(specs: list[_JointEffectsSpec], steps: list[Step], units: _Units) -> list[JointEffects]:
    L, A = LENGTH_SCALE[units.length], ANGLE_SCALE[units.angle]
    types = {s.joint.name: s.joint_type for s in steps if s.joint is not None}
    out = []
    for i, e in enumerate(specs):
        where = f"joint_effects[{i}] (joint {e.joint!r})"
        if e.joint not in types:
            raise ValueError(f"{where}: no such joint in the chain ({', '.join(types)})")
        prismatic = types[e.joint] == "prismatic"
        compliance = {}
        for kind in ("", "radial_"):
            k, c = getattr(e, kind + "stiffness"), getattr(e, kind + "compliance")
            if k is not None:
                if prismatic and units.stiffness != "N*m/rad":
                    raise ValueError(
                        f"{where}: {kind}stiffness of a prismatic joint is in N/m; give 'compliance' (m/N) "
                        f"or use units.stiffness N*m/rad, not {units.stiffness}"
                    )
                c = 1.0 / (k * (1.0 if prismatic else STIFFNESS_SCALE[units.stiffness]))
            compliance[kind] = 0.0 if c is None else c
        try:
            out.append(
                JointEffects(
                    joint=e.joint,
                    clearance_tilt=e.clearance_tilt * A,
                    backlash=e.backlash * (L if prismatic else A),
                    compliance=compliance[""],
                    radial_compliance=compliance["radial_"],
                    shaft_length=None if e.shaft_length is None else e.shaft_length * L,
                )
            )
        except ValueError as err:
            raise ValueError(f"{where}: {err}") from None
    return out


def format_validation_error(err: ValidationError) -> str:
    lines = []
    for e in err.errors():
        loc = ""
        for part in e["loc"]:
            loc += f"[{part}]" if isinstance(part, int) else (f".{part}" if loc else str(part))
        got = e.get("input")
        got_text = "" if isinstance(got, dict | list) or got is None else f" (got {got!r})"
        lines.append(f"{loc or '<file>'}: {e['msg']}{got_text}")
    return "; ".join(lines)


def model_from_dict(data: Any, origin: str = "<dict>") -> Model:
    """Build a model from parsed YAML data; errors name ``origin`` and the field."""
    if not isinstance(data, dict):
        raise ModelFileError(f"{origin}: a model file must be a mapping, got {type(data).__name__}")
    try:
        spec = _ModelFile.model_validate(data)
    except ValidationError as err:
        raise ModelFileError(f"{origin}: {format_validation_error(err)}") from None
    count = len(spec.base) + 5 * len(spec.links) + len(spec.chain) + len(spec.tool)
    if count > MAX_STEPS:
        raise ModelFileError(f"{origin}: about {count} steps; a model file may have up to {MAX_STEPS}")
    units = spec.units
    try:
        steps: list[Step] = [_step(s, units) for s in spec.base]
        if spec.links:
            assert spec.convention is not None  # checked by _ModelFile._one_form
            for i, row in enumerate(spec.links, start=1):
                steps += _link_steps(row, i, spec.convention, units)
        steps += [_step(s, units) for s in spec.chain]
        steps += [_step(s, units) for s in spec.tool]
        L = LENGTH_SCALE[units.length]
        bodies = [
            Body(b.name, b.frame, b.mass, (b.com[0] * L, b.com[1] * L, b.com[2] * L), b.inertia)
            for b in spec.bodies
        ]
        model = Model(
            name=spec.name,
            steps=tuple(steps),
            bodies=tuple(bodies),
            title=spec.title,
            source=spec.source.strip(),
            notes=spec.notes.strip(),
            joint_effects=tuple(_joint_effects(spec.joint_effects, steps, units)),
        )
        if spec.residual is not None:
            from robocal.model.residual import JointAngleResidual

            try:
                residual = JointAngleResidual.from_dict(spec.residual, model.joint_names)
            except KeyError as err:
                raise ValueError(f"residual: missing {err.args[0]!r}") from None
            model = dataclasses.replace(model, residual=residual)
        return model
    except (ValueError, TypeError) as err:
        raise ModelFileError(f"{origin}: {err}") from None


def load_model(path: str | os.PathLike[str]) -> Model:
    """Read and validate a YAML model file.

    Raises:
        ModelFileError: naming the file and the offending field or line.
        FileNotFoundError: when the file does not exist.
    """
    return model_from_dict(read_yaml(path, "model"), origin=str(path))


def _step_to_dict(step: Step) -> dict[str, Any]:
    out: dict[str, Any] = {"motion": step.motion, "param": step.name, "value": step.value}
    if not step.free:
        out["free"] = False
    if step.bounds is not None:
        out["bounds"] = list(step.bounds)
    if step.joint is not None:
        out["joint"] = step.joint.name
        if step.joint.limits is not None:
            out["limits"] = list(step.joint.limits)
    if step.role is not Role.KINEMATIC or Role.from_name(step.name) is not step.role:
        out["role"] = str(step.role)  # the robot's own steps need none (files stay as they were)
    return out


def model_to_dict(model: Model) -> dict[str, Any]:
    """The model as plain data in the file format (SI units, explicit chain)."""
    data: dict[str, Any] = {"robocal_model": FORMAT_VERSION, "name": model.name}
    for key in ("title", "source", "notes"):
        if getattr(model, key):
            data[key] = getattr(model, key)
    data["units"] = {"length": "m", "angle": "rad"}
    data["chain"] = [_step_to_dict(s) for s in model.steps]
    if model.bodies:
        data["bodies"] = [
            {
                "name": b.name,
                "frame": b.frame,
                "mass": b.mass,
                "com": list(b.com),
                **({"inertia": list(b.inertia)} if b.inertia is not None else {}),
            }
            for b in model.bodies
        ]
    if model.joint_effects:
        data["joint_effects"] = [effects_to_dict(e) for e in model.joint_effects]
    if model.residual is not None:
        data["residual"] = model.residual.to_dict()
    return data


def effects_to_dict(e: JointEffects) -> dict[str, Any]:
    out: dict[str, Any] = {"joint": e.joint}
    for key in ("clearance_tilt", "backlash", "compliance", "radial_compliance"):
        if getattr(e, key) != 0.0:
            out[key] = getattr(e, key)
    if e.shaft_length is not None:
        out["shaft_length"] = e.shaft_length
    return out


def save_model(model: Model, path: str | os.PathLike[str], run_id: str | None = None) -> Path:
    """Write ``model`` to a YAML file atomically (SI units, exact round trip); ``run_id``
    stamps it as one file of a result folder (:mod:`robocal.outdir`)."""
    name = model.name.replace("\n", " ").replace("\r", " ")
    header = (
        f"# robocal model '{name}': {model.dof} joints, {len(model.steps)} parameters; values in m and rad\n"
    )
    if run_id is not None:
        header += f"# robocal run: {run_id}\n"
    body = yaml.safe_dump(
        model_to_dict(model),
        sort_keys=False,
        default_flow_style=None,
        width=100,
        allow_unicode=True,
    )
    return atomic_write_text(path, header + body)
