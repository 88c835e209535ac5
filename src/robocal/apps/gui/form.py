"""The model builder's form, without any web framework: typed text -> joint geometry.

The form holds what the user typed, as text: per joint a name, the type and the
position (relative to the previous joint, base coordinates, mm), axis and limits (deg
for revolute, mm for prismatic joints); the TCP position (mm, relative to the last
joint) and orientation (roll, pitch, yaw in degrees, ``Rz(yaw) Ry(pitch) Rx(roll)``);
the model's name, title and measure.  That is exactly the geometry YAML format of
``examples/geometry/*.yaml`` (``unit: mm``, ``angle_unit: deg``), so the form is turned
into that file's text and read back by :func:`robocal.model.builder.load_geometry`: the
GUI builds with the same reader and builder as ``robocal model build`` and writes the
same model file.  Problems are reported per field (``FieldKey``) so the page can mark
the field that is wrong.
"""

from __future__ import annotations

import math
import re
import tempfile
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from robocal import spatial
from robocal.model.builder import BuildResult, Geometry, load_geometry
from robocal.model.conventions import SCHROER_SETS
from robocal.model.geometry import GeometryError, JointGeometry, Tcp
from robocal.outdir import atomic_write_text

__all__ = [
    "JOINT_FIELDS",
    "TCP_FIELDS",
    "BuilderForm",
    "FormCheck",
    "LinkRow",
    "build_form",
    "check_form",
    "form_from_catalog",
    "form_from_geometry",
    "form_from_geometry_text",
    "form_from_urdf",
    "geometry_yaml",
    "link_rows",
    "model_file_text",
    "shown_value",
]

#: Joint fields of the form: name, type, position x y z (mm), axis x y z, limits (deg or mm).
JOINT_FIELDS = ("name", "type", "px", "py", "pz", "ax", "ay", "az", "lo", "hi")
#: TCP fields: position x y z (mm) relative to the last joint, roll pitch yaw (deg).
TCP_FIELDS = ("tx", "ty", "tz", "roll", "pitch", "yaw")
#: A field of the form: ``(row, field)`` for a joint (row 0-based), ``("tcp", field)``,
#: ``("meta", field)``.
FieldKey = tuple[int | str, str]

_NUMERIC = ("px", "py", "pz", "ax", "ay", "az", "lo", "hi")
_NAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_.\-]*$")


@dataclass(frozen=True)
class BuilderForm:
    """What the user typed (all text).

    Attributes:
        joints: one mapping per joint with the keys of :data:`JOINT_FIELDS`.
        tcp: a mapping with the keys of :data:`TCP_FIELDS`.
        name, title: the model's name and title.
        measure: ``"pose"`` or ``"position"``.
    """

    joints: tuple[Mapping[str, str], ...]
    tcp: Mapping[str, str]
    name: str = "built"
    title: str = ""
    measure: str = "pose"


@dataclass(frozen=True)
class FormCheck:
    """The form read: the geometry file's content, or what is wrong where.

    Attributes:
        errors: message per field (:data:`FieldKey`); empty when the form is valid.
        general: messages not tied to one field (the builder's, naming the joint).
        geometry: the geometry file as a mapping (``unit: mm``, ``angle_unit: deg``),
            None when a field is invalid.
    """

    errors: Mapping[FieldKey, str] = field(default_factory=dict)
    general: tuple[str, ...] = ()
    geometry: Mapping[str, Any] | None = None

    @property
    def ok(self) -> bool:
        return not self.errors and not self.general and self.geometry is not None


def _number(text: Any) -> float | None:
    """A finite number from typed text (decimal point or comma), or None."""
    if isinstance(text, int | float) and not isinstance(text, bool):
        value = float(text)
    else:
        s = str(text if text is not None else "").strip().replace(",", ".")
        if not s:
            return None
        try:
            value = float(s)
        except ValueError:
            return None
    return value if math.isfinite(value) else None


def _exact(value: float) -> int | float:
    """A typed number as YAML should carry it: integers as integers (like a hand-written file)."""
    return int(value) if value.is_integer() and abs(value) < 2**53 else value


def check_form(form: BuilderForm) -> FormCheck:
    """Read every field; on success the geometry file's mapping (mm, deg)."""
    errors: dict[FieldKey, str] = {}
    if not form.joints:
        return FormCheck({}, ("add at least one joint",), None)
    name = (form.name or "").strip()
    if not name:
        errors[("meta", "name")] = "the model needs a name"
    if form.measure not in ("pose", "position"):
        errors[("meta", "measure")] = "pose or position"
    seen: dict[str, int] = {}
    joints = [_check_joint(i, row, errors, seen) for i, row in enumerate(form.joints)]
    tcp_values = {}
    for key in TCP_FIELDS:
        text = form.tcp.get(key, "")
        value = _number(text)
        if value is None and (str(text or "").strip() or key in ("tx", "ty", "tz")):
            errors[("tcp", key)] = f"TCP: {key} must be a number"
        tcp_values[key] = value
    if errors:
        return FormCheck(errors, (), None)
    position = [v for k in ("tx", "ty", "tz") if (v := tcp_values[k]) is not None]  # all given here
    tcp: dict[str, Any] = {"position": [_exact(v) for v in position]}
    rpy = [tcp_values[k] for k in ("roll", "pitch", "yaw")]
    if any(v is not None for v in rpy):
        tcp["rpy"] = [_exact(v or 0.0) for v in rpy]
    geometry: dict[str, Any] = {"name": name}
    if form.title.strip():
        geometry["title"] = form.title.strip()
    geometry |= {"unit": "mm", "angle_unit": "deg", "measure": form.measure, "joints": joints, "tcp": tcp}
    return FormCheck({}, (), geometry)


def _check_joint(
    i: int, row: Mapping[str, Any], errors: dict[FieldKey, str], seen: dict[str, int]
) -> dict[str, Any]:
    """Joint row ``i`` of the form as the geometry file's entry; its problems go to ``errors``
    (``seen``: joint names -> first row, updated)."""
    values: dict[str, float | None] = {}
    for key in _NUMERIC:
        text = row.get(key, "")
        values[key] = _number(text)
        optional = key in ("lo", "hi")
        if values[key] is None and (str(text or "").strip() or not optional):
            errors[(i, key)] = f"joint {i + 1}: {key} must be a number" + (
                "" if str(text or "").strip() else " (empty)"
            )
    kind = row.get("type")
    if kind not in ("revolute", "prismatic"):
        errors[(i, "type")] = f"joint {i + 1}: revolute or prismatic"
    axis = [values[k] for k in ("ax", "ay", "az")]
    if all(v is not None for v in axis) and float(np.linalg.norm([v or 0.0 for v in axis])) < 1e-12:
        for k in ("ax", "ay", "az"):
            errors[(i, k)] = f"joint {i + 1}: the axis has zero length"
    lo, hi = values["lo"], values["hi"]
    if (lo is None) != (hi is None) and (i, "lo") not in errors and (i, "hi") not in errors:
        errors[(i, "lo" if lo is None else "hi")] = f"joint {i + 1}: give both limits or neither"
    elif lo is not None and hi is not None and not lo < hi:
        errors[(i, "lo")] = errors[(i, "hi")] = f"joint {i + 1}: the lower limit must be below the upper"
    jname = (row.get("name") or "").strip()
    if jname:
        if not _NAME.match(jname):
            errors[(i, "name")] = f"joint {i + 1}: a name of letters, digits, _ . - (not {jname[:20]!r})"
        elif jname in seen:
            errors[(i, "name")] = f"joint {i + 1}: the name {jname!r} is used by joint {seen[jname] + 1}"
        seen.setdefault(jname, i)
    entry: dict[str, Any] = {}
    if jname:
        entry["name"] = jname
    entry["type"] = kind
    entry["position"] = [_exact(values[k] or 0.0) for k in ("px", "py", "pz")]
    entry["axis"] = [_exact(v or 0.0) for v in axis]
    if lo is not None and hi is not None:
        entry["limits"] = [_exact(lo), _exact(hi)]
    return entry


def geometry_yaml(geometry: Mapping[str, Any]) -> str:
    """The geometry file's text (the format of ``examples/geometry/ur10.yaml``)."""
    head = "# joint geometry written by robocal gui (unit mm, angles deg); build: robocal model build FILE\n"
    return head + yaml.safe_dump(dict(geometry), sort_keys=False, default_flow_style=None, width=110)


def _load_text(text: str, label: str) -> Geometry:
    """:func:`load_geometry` on text (through a temporary file: the reader takes a path);
    the messages name ``label`` instead of the temporary file."""
    with tempfile.TemporaryDirectory(prefix="robocal-gui-") as tmp:
        path = Path(tmp) / "geometry.yaml"
        atomic_write_text(path, text)
        try:
            return load_geometry(path)
        except GeometryError as err:
            raise GeometryError(str(err).replace(str(path), label)) from None


def build_form(form: BuilderForm) -> tuple[FormCheck, BuildResult | None]:
    """Check the form and, when it is valid, build the model as ``robocal model build`` does.

    Returns the check (with the builder's message in ``general`` when it refuses the
    geometry, e.g. coincident axes) and the build result (None when it failed).
    """
    check = check_form(form)
    if not check.ok or check.geometry is None:
        return check, None
    try:
        geometry = _load_text(geometry_yaml(check.geometry), "the form")
        return check, geometry.build()
    except (GeometryError, ValueError) as err:
        message = str(err)
        errors: dict[FieldKey, str] = {}
        found = re.search(r"joint (\d+)", message)
        if found and 1 <= int(found.group(1)) <= len(form.joints):
            row = int(found.group(1)) - 1
            for key in ("px", "py", "pz", "ax", "ay", "az"):
                errors[(row, key)] = message
        return FormCheck(errors, (message,), check.geometry), None


def model_file_text(result: BuildResult) -> str:
    """The model file ``robocal model build`` writes for this build (:func:`rc.save_model`)."""
    from robocal.model.files import save_model

    with tempfile.TemporaryDirectory(prefix="robocal-gui-") as tmp:
        path = save_model(result.model, Path(tmp) / "model.yaml")
        return path.read_text(encoding="utf-8")


# ----------------------------------------------------------------------- filling the form
def _text(value: float) -> str:
    """A number for a form field: short and exact to the display (1e-9 mm or deg)."""
    if abs(value) < 1e-9:
        return "0"
    text = f"{value:.10g}"
    return text[:-2] if text.endswith(".0") else text


def form_from_geometry(
    name: str, joints: Sequence[JointGeometry], tcp: Tcp, title: str = "", measure: str = "pose"
) -> BuilderForm:
    """The form of a joint geometry (SI units in, mm and degrees in the fields)."""
    rows = []
    for g in joints:
        f = 180.0 / math.pi if g.type == "revolute" else 1000.0
        row = {"name": g.name or "", "type": g.type}
        row |= {k: _text(v * 1000.0) for k, v in zip(("px", "py", "pz"), g.position, strict=True)}
        row |= {k: _text(v) for k, v in zip(("ax", "ay", "az"), g.axis, strict=True)}
        row |= (
            {"lo": "", "hi": ""}
            if g.limits is None
            else {"lo": _text(g.limits[0] * f), "hi": _text(g.limits[1] * f)}
        )
        rows.append(row)
    tcp_row = {k: _text(v * 1000.0) for k, v in zip(("tx", "ty", "tz"), tcp.position, strict=True)}
    if tcp.rotation is None:
        tcp_row |= {"roll": "", "pitch": "", "yaw": ""}
    else:
        rpy = np.degrees(spatial.matrix_to_euler(np.asarray(tcp.rotation, dtype=float), "xyz"))
        tcp_row |= {k: _text(float(v)) for k, v in zip(("roll", "pitch", "yaw"), rpy, strict=True)}
    return BuilderForm(tuple(rows), tcp_row, name, title, measure)


def form_from_geometry_text(text: str, label: str = "the geometry file") -> BuilderForm:
    """The form of a geometry YAML file's text (errors: :class:`GeometryError` naming ``label``)."""
    g = _load_text(text, label)
    return form_from_geometry(g.name, g.joints, g.tcp, g.title, g.measure)


def form_from_catalog(name: str) -> BuilderForm:
    """The form of a catalog robot's joint geometry at q = 0 (what ``rc.calibration_model`` builds from)."""
    import robocal as rc
    from robocal.model.complete import geometry_from_model

    chain = rc.robot(name)
    joints, tcp = geometry_from_model(chain)
    return form_from_geometry(f"{chain.name}_built", joints, tcp, f"{chain.title} (from the catalog)")


def form_from_urdf(text: str, label: str = "the URDF") -> BuilderForm:
    """The form of a URDF robot's serial chain (root to the deepest joint's last frame)."""
    from robocal.model.urdf.read import URDFError, geometry_from_urdf

    with tempfile.TemporaryDirectory(prefix="robocal-gui-") as tmp:
        path = Path(tmp) / "robot.urdf"
        atomic_write_text(path, text)
        try:
            name, joints, tcp = geometry_from_urdf(path)
        except URDFError as err:
            raise URDFError(str(err).replace(str(path), label)) from None
    return form_from_geometry(name, joints, tcp, f"{name} (from {label})")


# ----------------------------------------------------------------------- the link table
@dataclass(frozen=True)
class LinkRow:
    """One link of a built model as the page lists it.

    Attributes:
        link: ``"base → q1"``, ``"q1 → q2"``, ..., ``"q6 → TCP"``.
        label: the parameterisation and its seed 000 equation number.
        equation: the link transform as a product of elementary motions.
        parameters: ``(name, identified)`` in chain order.
        values: each parameter's nominal value as shown, with its unit (``"612.7 mm"``,
            ``"90°"``), in the order of ``parameters``.
        verdict: the link parameterisation's rank check (``ok`` / ``near-singular`` / ``singular``).
        continuity: the distal joint's continuity check, ``"continuous"`` or what is wrong.
    """

    link: str
    label: str
    equation: str
    parameters: tuple[tuple[str, bool], ...]
    values: tuple[str, ...]
    verdict: str
    continuity: str


def shown_value(value_si: float, rotation: bool) -> str:
    """A parameter's value for the page: mm or degrees, as many digits as the number needs
    (up to 10 significant, :func:`_text`), with the unit."""
    if rotation:
        return f"{_text(math.degrees(value_si))}°"
    return f"{_text(value_si * 1000.0)} mm"


def link_rows(result: BuildResult) -> tuple[tuple[LinkRow, ...], str]:
    """Per link the parameterisation, its equation and its checks; and the count line
    (4R + 2P + 6 or + 3, the Jacobian's rank)."""
    from robocal.model.singularity import check_model

    model = result.model
    check = check_model(model, result.measure)
    verdicts = {c.index: c for c in check.links}
    continuity = {c.joint: c for c in check.continuity}
    free = set(model.free_names)
    steps = {s.name: s for s in model.steps}
    names = ["base", *model.joint_names, "TCP"]
    rows = []
    for info in result.links:
        motions = SCHROER_SETS[info.equation][: len(info.parameters)]
        equation = " · ".join(f"{m}({p})" for m, p in zip(motions, info.parameters, strict=True))
        link_check = verdicts.get(info.index)
        verdict = "-" if link_check is None else link_check.verdict
        joint = names[info.index + 1] if info.index + 1 < len(names) - 1 else None
        cont = "-"
        if joint is not None and joint in continuity:
            c = continuity[joint]
            cont = "continuous" if c.continuous else f"jumps (change {c.parameter_change:.3g}/rad)"
        rows.append(
            LinkRow(
                f"{names[info.index]} → {names[info.index + 1]}",
                info.label,
                equation,
                tuple((p, p in free) for p in info.parameters),
                tuple(shown_value(steps[p].value, steps[p].is_rotation) for p in info.parameters),
                verdict,
                cont,
            )
        )
    R = model.joint_types.count("revolute")
    P = model.dof - R
    extra = 6 if result.measure == "pose" else 3
    count = (
        f"{len(free)} identifiable parameters: 4R + 2P + {extra} = 4·{R} + 2·{P} + {extra} = "
        f"{result.expected_free} ({result.measure} measurement); identification Jacobian rank {result.rank}"
        + ("" if result.complete_and_minimal else " — NOT complete and minimal")
    )
    return tuple(rows), count
