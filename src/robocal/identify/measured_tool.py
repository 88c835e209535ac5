"""The measured tool (probe) a calibration identified, and what the poses left undetermined.

A calibration identifies the measured point (position measurements) or frame (pose
measurements) on the robot's flange: the ``tcp_*`` steps appended to ``result.model``.
Its position on the flange, with its covariance, is :class:`MeasuredTool`
(:func:`measured_tool`): stored in ``result.json`` (``measured_tool``), used by
``robocal filter`` and ``robocal compensate`` unless told otherwise, and compared with a
tool the user states (:func:`check_tool`): one that differs from the identified tool by
more than :data:`AGREE_SIGMAS` σ *and* :data:`FLANGE_TOLERANCE_M` is refused, naming both.

Within that tolerance the difference is the robot's, not the tool's: position measurements
cannot tell the probe's offset from the flange's own (the last link's length, its offset
along the last axis), so the identified tool carries both.  A program filter attaches the
program's own tool to the flange, so it keeps the difference with the robot (the flange
correction ``identified ∘ as_built⁻¹``); the tool as built is the one stated at the
calibration (``calibrate --tool``) unless ``--probe`` says otherwise (:func:`probe_for`).

The flange is the controller's: the complete model keeps the flange's offset along the
last axis (``tool_z``, UR's d6) at its nominal value, since position measurements cannot
tell it from the tool's length (it is reported as absorbed by ``tcp_z``), so the
identified tool is the flange-to-TCP vector as the controller understands it.

:func:`tool_start_warnings` reports a stated start value the fit moved by more than
:data:`START_REPORT_M` or 3σ; :func:`undetermined_warnings` the parameters the pose
set could not determine (kept at their start value, or a tool component whose σ exceeds
:data:`UNDETERMINED_STD_M`, e.g. the tool length from poses with one tool orientation).
Units: SI (m) unless a name says mm.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from robocal import spatial
from robocal.model.chain import Model
from robocal.model.flange_tool import tool_steps

__all__ = [
    "AGREE_SIGMAS",
    "FLANGE_TOLERANCE_M",
    "ORIENTATION_MARGIN_DEG",
    "START_FLOOR_M",
    "START_REPORT_M",
    "UNDETERMINED_STD_M",
    "MeasuredTool",
    "PoseFacts",
    "check_tool",
    "measured_tool",
    "orientation_warnings",
    "pose_facts",
    "probe_for",
    "result_tool_axis_coverage",
    "tool_axis_coverage",
    "tool_start_warnings",
    "undetermined_warnings",
]

Array = NDArray[np.float64]

#: a stated tool this many σ from the identified one disagrees with it ...
AGREE_SIGMAS = 3.0
#: ... if it is also farther than this (m): up to it, a difference is the flange's own geometry
#: (a few tenths of a millimetre on a new arm, ±0.5 mm per parameter in simulated ones; a
#: wrong or mis-typed tool is millimetres to centimetres off: the real UR10's 109 mm vs 93 mm)
FLANGE_TOLERANCE_M = 2e-3
#: a stated start value this far (m) and 3σ from the fit is reported (not refused)
START_FLOOR_M = 0.5e-3
#: a start value the fit moved farther than this (m) is reported (also beyond 3σ and the floor)
START_REPORT_M = 5e-3
#: a tool component with a larger σ (m) is not determined by the calibration's poses
UNDETERMINED_STD_M = 0.5e-3


def _mm(v: ArrayLike) -> str:
    """``"x, y, z"`` in mm of a vector in m."""
    return ", ".join(f"{x * 1e3:.2f}" for x in np.asarray(v, dtype=float).reshape(-1))


@dataclass(frozen=True)
class MeasuredTool:
    """The measured point a calibration identified on the (controller's) flange.

    Attributes:
        position_m: ``(3,)`` the point in the flange frame (m).
        covariance_m2: ``(3, 3)`` its covariance (m²) from the estimated ``tcp_*``
            parameters (zero for components that were not estimated).
        estimated: whether each of ``tcp_x``, ``tcp_y``, ``tcp_z`` (when present) was
            estimated (False: kept at its start value).
        given_m: the tool the user stated as the start value (m), None when none was.
    """

    position_m: tuple[float, float, float]
    covariance_m2: tuple[tuple[float, float, float], ...]
    estimated: tuple[bool, ...] = ()
    given_m: tuple[float, float, float] | None = None

    @property
    def std_m(self) -> Array:
        """``(3,)`` the 1σ of each component (m)."""
        return np.sqrt(np.clip(np.diag(np.asarray(self.covariance_m2)), 0.0, None))

    def text(self) -> str:
        """``"x, y, z mm ± sx, sy, sz"``."""
        return f"({_mm(self.position_m)}) mm ± ({_mm(self.std_m)})"

    def separation(self, point_m: ArrayLike) -> tuple[float, float]:
        """Distance (m) of ``point_m`` (flange frame) from the identified point, and that
        distance in σ of the identified point along the line between them (inf when the
        identified point has no uncertainty in that direction)."""
        d = np.asarray(point_m, dtype=float)[:3] - np.asarray(self.position_m)
        distance = float(np.linalg.norm(d))
        if distance == 0.0:
            return 0.0, 0.0
        u = d / distance
        sigma = math.sqrt(max(float(u @ np.asarray(self.covariance_m2) @ u), 0.0))
        return distance, (distance / sigma if sigma > 0 else math.inf)

    def disagrees(self, point_m: ArrayLike, floor_m: float = FLANGE_TOLERANCE_M) -> bool:
        """``point_m`` is more than :data:`AGREE_SIGMAS` σ and ``floor_m`` away."""
        distance, sigmas = self.separation(point_m)
        return distance > floor_m and sigmas > AGREE_SIGMAS

    def to_dict(self) -> dict[str, Any]:
        """``result.json``'s ``measured_tool`` (mm)."""
        out: dict[str, Any] = {
            "frame": "flange",
            "position_mm": [x * 1e3 for x in self.position_m],
            "std_mm": [float(x) * 1e3 for x in self.std_m],
            "covariance_mm2": [[x * 1e6 for x in row] for row in self.covariance_m2],
            "estimated": list(self.estimated),
        }
        if self.given_m is not None:
            out["given_mm"] = [x * 1e3 for x in self.given_m]
        return out

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> MeasuredTool:
        """The inverse of :meth:`to_dict`."""
        given = data.get("given_mm")
        return cls(
            position_m=_triple(x * 1e-3 for x in data["position_mm"]),
            covariance_m2=tuple(_triple(x * 1e-6 for x in row) for row in data["covariance_mm2"]),
            estimated=tuple(bool(x) for x in data.get("estimated", ())),
            given_m=None if given is None else _triple(x * 1e-3 for x in given),
        )


def _triple(values: Any) -> tuple[float, float, float]:
    a, b, c = (float(x) for x in values)
    return a, b, c


def _tool_steps(model: Model) -> list:
    """The measured tool's steps (``tcp_*``) at the end of ``model``."""
    return list(tool_steps(model))


def _point_and_derivative(motions: list[str], values: list[float]) -> tuple[Array, Array]:
    """The point ``(3,)`` at the end of the elementary ``motions`` with ``values`` (m, rad;
    as :func:`robocal.spatial.chain_product`) and its derivative ``(3, k)`` by each value:
    a translation moves it along the step's axis, a rotation turns it about that axis
    through the step's origin (both in the chain's first frame)."""
    R = np.eye(3)
    t = np.zeros(3)
    J = np.empty((3, len(motions)))
    turns = []  # (column, axis, origin) of the rotations: their derivative needs the end point
    for k, (motion, value) in enumerate(zip(motions, values, strict=True)):
        a = R[:, "xyz".index(motion[1])]
        if motion[0] == "T":
            J[:, k] = a
            t = t + a * value
        else:
            turns.append((k, a.copy(), t))
            R = R @ spatial.rot(motion[1], value)
    for k, a, origin in turns:
        J[:, k] = np.cross(a, t - origin)
    return t, J


def measured_tool(result: Any, given_m: ArrayLike | None = None) -> MeasuredTool | None:
    """The measured tool of a :class:`~robocal.identify.result.CalibrationResult` (None
    when the calibration measured the model's end without a tool).  ``given_m``: the
    stated tool (position (3,) or 4x4; default: the one recorded with the result)."""
    steps = tool_steps(result.model)
    if not steps:
        return None
    names = result.names  # the tool's few steps looked up among them (no table of all)
    cols = [names.index(s.name) if s.name in names else None for s in steps]
    motions, values = [s.motion for s in steps], [s.value for s in steps]
    if sorted(motions) == ["Tx", "Ty", "Tz"]:  # a probe point: every position calibration
        position, covariance = _probe_point(motions, values, cols, np.asarray(result.covariance))
    else:
        p, J = _point_and_derivative(motions, values)
        estimated = [a for a, c in enumerate(cols) if c is not None]
        at = np.array([c for c in cols if c is not None], dtype=np.intp)
        # the covariance of the point from the estimated steps' block (the others add nothing)
        J_estimated = J[:, estimated]
        C = J_estimated @ np.asarray(result.covariance)[at[:, None], at] @ J_estimated.T
        position, covariance = _triple(p.tolist()), tuple(_triple(row) for row in C.tolist())
    if given_m is None:
        recorded = (getattr(result, "records", None) or {}).get("measured_tool") or {}
        given_m = None if recorded.get("given_mm") is None else np.asarray(recorded["given_mm"]) * 1e-3
    given = None if given_m is None else _given_point(given_m)
    return MeasuredTool(
        position_m=position,
        covariance_m2=covariance,
        estimated=tuple(c is not None for c in cols),
        given_m=None if given is None else _triple(given.tolist()),
    )


def _probe_point(
    motions: list[str], values: list[float], cols: list[int | None], covariance: Array
) -> tuple[tuple[float, float, float], tuple[tuple[float, float, float], ...]]:
    """:func:`measured_tool`'s point (m) and covariance (m²) for the translations Tx, Ty, Tz
    (in any order), in floats: the point's coordinates are the steps' values and its
    covariance the estimated steps' block of ``covariance`` (``cols``: each step's column
    there, None: not estimated, no variance), the numbers :func:`_point_and_derivative`'s
    unit columns give (``+ 0.0``: as their sums, a zero is +0)."""
    step_on = {motion[1]: k for k, motion in enumerate(motions)}
    order = [step_on["x"], step_on["y"], step_on["z"]]
    x, y, z = 0.0 + values[order[0]], 0.0 + values[order[1]], 0.0 + values[order[2]]
    at = [cols[k] for k in order]  # each component's column, None: not estimated
    item = covariance.item  # nine floats read one by one (no arrays for a 3 x 3 block)

    def row(a: int | None) -> tuple[float, float, float]:
        if a is None:
            return 0.0, 0.0, 0.0
        u, v, w = ((0.0 if b is None else 0.0 + item(a, b)) for b in at)
        return u, v, w

    return (x, y, z), (row(at[0]), row(at[1]), row(at[2]))


def _given_point(value: ArrayLike) -> Array:
    g = np.asarray(value, dtype=float)
    return g[:3, 3] if g.shape == (4, 4) else g.reshape(3)


def check_tool(tool: MeasuredTool, given: ArrayLike, what: str) -> None:
    """Refuse a stated tool (``given``: (3,) or 4x4, m, flange frame) that disagrees with
    the identified one (:meth:`MeasuredTool.disagrees`).

    Raises:
        ValueError: one line naming ``what`` (e.g. ``"--probe"``) and both values.
    """
    point = _given_point(given)
    if not tool.disagrees(point):
        return
    distance, sigmas = tool.separation(point)
    raise ValueError(
        f"{what} ({_mm(point)}) mm disagrees with the measured tool the calibration identified, "
        f"{tool.text()}: {distance * 1e3:.2f} mm ({sigmas:.0f}σ) apart; leave {what} out to use the "
        "identified tool, or recalibrate with the tool as built"
    )


def tool_start_warnings(tool: MeasuredTool | None) -> list[tuple[str, str]]:
    """``("tool-start", message)`` when the stated tool (``tool.given_m``) and the fit
    differ by more than :data:`START_REPORT_M`, or by more than 3σ and :data:`START_FLOOR_M`."""
    if tool is None or tool.given_m is None:
        return []
    distance, sigmas = tool.separation(tool.given_m)
    if distance <= START_REPORT_M and not tool.disagrees(tool.given_m, START_FLOOR_M):
        return []
    if not tool.disagrees(tool.given_m):
        use = (
            "filter takes the stated tool as built and keeps the difference with the robot's flange "
            "(position measurements cannot tell the two apart)"
        )
    else:
        use = (
            f"beyond the flange's tolerance ({FLANGE_TOLERANCE_M * 1e3:.0f} mm), so filter and compensate "
            "use the identified tool and refuse the stated one: set the identified tool as the "
            "controller's TCP, or check the probe's mounting and the value given"
        )
    return [
        (
            "tool-start",
            f"the tool given as start value, ({_mm(tool.given_m)}) mm, is {distance * 1e3:.2f} mm "
            f"({sigmas:.0f}σ) from the measured tool the calibration identified on the controller's "
            f"flange, {tool.text()}; {use}",
        )
    ]


def undetermined_warnings(result: Any, tool: MeasuredTool | None) -> list[tuple[str, str]]:
    """``("undetermined", message)``: the parameters the pose set left at their start value
    (poorly identifiable, not structurally redundant) and the tool components whose σ
    exceeds :data:`UNDETERMINED_STD_M`: predictions that depend on them (another tool
    orientation than the calibration poses had) carry that error."""
    out: list[tuple[str, str]] = []
    poor = [d for d in result.dropped if d.reason == "poorly identifiable"]
    if poor:
        listed = ", ".join(
            d.name + (f" (σ {d.sigma * 1e3:.3g} mm)" if d.sigma is not None else "") for d in poor
        )
        out.append(
            (
                "undetermined",
                f"not determined by these poses, kept at their start values: {listed}; poses with "
                "more varied joint values and tool orientations would identify them",
            )
        )
    if tool is not None:
        # tool.std_m's values, from the diagonal as floats (no arrays for three numbers)
        std = [math.sqrt(max(row[i], 0.0)) for i, row in enumerate(tool.covariance_m2)]
        loose = [f"tcp_{a} (σ {s * 1e3:.3g} mm)" for a, s in zip("xyz", std, strict=True)
                 if s > UNDETERMINED_STD_M]  # fmt: skip
        if loose:
            out.append(
                (
                    "undetermined",
                    f"the measured tool is poorly determined by these poses: {', '.join(loose)} "
                    "(e.g. poses with one tool orientation do not separate the tool's length from "
                    "the device frame); targets with other tool orientations may be off by that much",
                )
            )
    return out


def probe_for(calibrated: Any, given: ArrayLike | None, what: str = "--probe") -> Any:
    """The measured tool as built that a program filter assumes (4x4 on the flange, m):
    ``given`` (position (3,) or 4x4) checked against the identified tool
    (:func:`check_tool`); when none is given, the tool stated at the calibration
    (``calibrate --tool``) if it agrees with the identified one, else the identified tool
    itself.  ``given`` unchanged for a bare model or a calibration without a tool.  What
    separates the tool as built from the identified one is kept with the robot's flange
    (:mod:`robocal.compensate.programs.frames`).

    Raises:
        ValueError: ``given`` disagrees with the identified tool (names ``what``).
    """
    if not hasattr(calibrated, "covariance"):  # a model file: nothing identified to compare with
        return given
    tool = measured_tool(calibrated)
    if tool is None:
        return given
    if given is not None:
        check_tool(tool, given, what)
        return given
    steps = _tool_steps(calibrated.model)
    identified = spatial.chain_product([s.motion for s in steps], [s.value for s in steps])
    if tool.given_m is not None and not tool.disagrees(tool.given_m):
        as_built = identified.copy()  # the identified orientation (pose tools), the stated point
        as_built[:3, 3] = tool.given_m
        return as_built
    return identified


#: a target's tool axis this much (deg) beyond the calibration poses' spread is "another
#: tool orientation" for a calibration that left parameters undetermined
ORIENTATION_MARGIN_DEG = 5.0


def tool_axis_coverage(model: Model, q: ArrayLike, T_device_base: ArrayLike | None = None) -> dict[str, Any]:
    """The tool orientations the calibration poses covered: the mean direction of the
    flange's z axis in the robot base and the largest angle (deg) of a pose's axis from it.
    ``T_device_base`` (4x4): ``model`` is a measurement chain, whose frames are in the device
    frame (the robot's base at ``T_device_base``): its tool axes are turned into the base."""
    axes = model.fk(np.asarray(q, dtype=float))[:, :3, 2]
    if T_device_base is not None:
        axes = axes @ np.asarray(T_device_base, dtype=float)[:3, :3]  # each row a: Rᵀa
    mean = axes.mean(axis=0)
    mean = mean / max(float(np.linalg.norm(mean)), 1e-12)
    spread = np.degrees(np.arccos(np.clip(axes @ mean, -1.0, 1.0)))
    return {"tool_axis_base": [float(x) for x in mean], "tool_axis_spread_deg": float(spread.max())}


def result_tool_axis_coverage(result: Any, q: ArrayLike) -> dict[str, Any]:
    """:func:`tool_axis_coverage` of a calibration result's model, from its measurement chain
    when it has one: that chain shares the calibration's plan (a new robot model works its
    own out, ~25 µs a calibration); the axes agree to round-off."""
    if result.measurement_chain is None:
        return tool_axis_coverage(result.model, q)
    return tool_axis_coverage(result.measurement_chain, q, result.T_device_base)


class PoseFacts(Mapping[str, Any]):
    """A result's ``records``: ``given`` and, under the keys of ``later``, values worked out by
    ``later[key]()`` when first read (:func:`pose_facts`: the calibration poses' joint
    coverage and tool axes, ~70 µs of a 100-pose calibration that most callers of
    ``rc.calibrate`` never read).  Read-only and deterministic (each value is a function of
    frozen inputs); keys in the order of ``{**given, **later}``; pickles and copies as the
    plain dict of all its values."""

    def __init__(self, given: Mapping[str, Any], later: Mapping[str, Callable[[], Any]]) -> None:
        self._values = {k: v for k, v in given.items() if k not in later}
        self._later = dict(later)
        self._keys = tuple(dict.fromkeys([*given, *later]))

    def __getitem__(self, key: str) -> Any:
        work = self._later.get(key)
        if work is not None:  # set before it leaves _later: another thread reads one or the other
            self._values[key] = work()
            self._later.pop(key, None)
        return self._values[key]

    def __iter__(self) -> Iterator[str]:
        return iter(self._keys)

    def __len__(self) -> int:
        return len(self._keys)

    def __repr__(self) -> str:
        return repr(dict(self))

    def __reduce__(self) -> tuple[Any, ...]:
        return (dict, (dict(self),))


def _tool_record(tool: MeasuredTool, result: Any, q: Array) -> dict[str, Any]:
    return tool.to_dict() | result_tool_axis_coverage(result, q)


def _coverage_record(robot: Model, q: Array) -> dict[str, Any]:
    from robocal.identify.coverage import joint_coverage

    return joint_coverage(robot, q).to_dict()


def pose_facts(result: Any, tool: MeasuredTool | None, robot: Model, q: ArrayLike) -> PoseFacts:
    """``result.records`` with the facts of its calibration poses ``q`` ``(n, dof)``, worked
    out when first read (:class:`PoseFacts`): ``"coverage"``, the joint coverage
    (:func:`robocal.identify.coverage.joint_coverage` of ``robot``, a model with the
    calibrated one's joints), and with a measured ``tool`` ``"measured_tool"``, its record
    with the tool axes the poses covered (:func:`result_tool_axis_coverage`)."""
    q = np.array(q, dtype=float)  # a copy: the caller's array may change afterwards
    q.flags.writeable = False
    later: dict[str, Callable[[], Any]] = {"coverage": functools.partial(_coverage_record, robot, q)}
    if tool is not None:
        later["measured_tool"] = functools.partial(_tool_record, tool, result, q)
    return PoseFacts(result.records, later)


def orientation_warnings(calibrated: Any, q: ArrayLike, names: Sequence[str]) -> list[str]:
    """For a calibration that left parameters undetermined (its ``undetermined`` warnings):
    one line naming the commands ``q`` ``(n, dof)`` whose tool axis lies more than
    :data:`ORIENTATION_MARGIN_DEG` beyond the calibration poses' spread: there the
    undetermined parameters (e.g. the tool's length) move the tool, and the error after
    compensation may be that large.  Empty otherwise (or for a bare model)."""
    record = (getattr(calibrated, "records", None) or {}).get("measured_tool") or {}
    codes = {w.code for w in getattr(calibrated, "warnings", ())}
    if "undetermined" not in codes or "tool_axis_base" not in record:
        return []
    q = np.asarray(q, dtype=float).reshape(-1, calibrated.model.dof)
    ok = np.all(np.isfinite(q), axis=1)
    axes = calibrated.model.fk(q[ok])[:, :3, 2]
    angle = np.degrees(np.arccos(np.clip(axes @ np.asarray(record["tool_axis_base"]), -1.0, 1.0)))
    limit = float(record["tool_axis_spread_deg"]) + ORIENTATION_MARGIN_DEG
    far = [str(n) for n, a in zip(np.asarray(names, dtype=object)[ok], angle, strict=True) if a > limit]
    if not far:
        return []
    shown = ", ".join(far[:10]) + (" ..." if len(far) > 10 else "")
    return [
        f"{len(far)} target(s) with a tool orientation the calibration poses did not cover (more than "
        f"{limit:.3g}° from their mean tool axis): {shown}; the calibration left parameters undetermined "
        "(see its warnings), which may put these targets off by more than the expected error"
    ]
