"""Inclinometer readings as rows of the constraint fit (seed 003 §4.4.1, §5.3; issue 33).

A tilt row is a configuration ``q``, the link carrying an inclinometer (the child link of
joint ``K``) and the channel read (its ``x`` or ``y`` axis).  The sensor's axes are the
link's joint-frame axes (:meth:`robocal.model.chain.Model.joint_frames`) turned by the
row's mount (``ConstraintSet.tilt_mount``, the mount of
:class:`robocal.measure.inclinometer.Inclinometer`; the identity by default).  The mount
matters for what the rows can see: a sensor whose two axes are both perpendicular to a
horizontal joint axis cannot see that axis lean sideways (the clearance of a parallel
joint); mounted level at the home configuration, as the thesis' sensors are, one channel
lies along it.  With ``up`` the vertical in the base
frame (gravity along −z of the base), channel ``x`` reads ``asin(up · R e_y)`` and
channel ``y`` reads ``−asin(up · R e_x)``
(:func:`robocal.measure.inclinometer.readings`), plus the channel's zero
(``tilt_zero_<joint>_<axis>``, rad, an unknown per channel) and normal noise
``ConstraintSet.tilt_sigma``.

What a reading sees: the orientation of the sensed link only.  The chain's angle steps
up to that link enter (the analytic columns of
:func:`robocal.identify.tilt_identification.tilt_jacobian`: a step turns every later
link about its axis ``ω``, the reading moves by ``±(up · ω × v)/cos(reading)``); a
length moves no link's orientation and has a zero column, so the rank test reports it as
not identifiable.  A rotation about the vertical (the base's yaw, joint 1 of a vertical
arm) is invisible too.

Joint effects (seed 003's clearance tilt, backlash and compliance, ``clearance_<joint>``,
``backlash_<joint>``, ``compliance_<joint>``, :mod:`robocal.model.joints`, eqs. 5.15-5.19
under the static gravity loads of eq. 4.21 from the model's mass properties) turn the
links as the thesis identifies them from tilts; they are unknowns of the tilt rows only:
the position rows of the same fit (a tracker, sockets) are predicted without them (the
fit says so, :func:`mixed_effects_note`).

Clearance and backlash turn a link by ``±C``, ``±δθ_bkl`` with the *sign* of a load moment
(the bending moment ``(ηx, ηy)`` picks the side the shaft leans on, ``ηz`` the flank of
the gear), so a reading is smooth in the parameters but jumps where that moment crosses
zero.  The thesis avoids that by choosing configurations whose moments are clearly on
one side (§4.4.1: the last link inclined 5° either side of the vertical; Fig. 4.6).  The
tilt rows do the same with any configurations: a row where a sensed joint's moment of
either kind is within :data:`CONTACT_FRACTION` of zero (relative to that joint's largest
over the rows) is left out of the fit (:func:`unclear_contact`), since an error of the
model's loads (its geometry, its masses) could put the contact on the other side and
the row would be off by ``2C``; the sign of every row kept is that of the held loads.

The loads are those of the start geometry, held fixed in the fit (as
:func:`robocal.identify.tilt_identification.identify_tilt`: a change of 0.1° changes them
by about 0.2 %), so the Jacobian is exact for this model.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from robocal.measure.constraints.data_set import TILT_AXES, ConstraintSet
from robocal.measure.constraints.mounts import loads_about, mounts_in
from robocal.model.chain import Model

if TYPE_CHECKING:
    from robocal.identify.constraints.tilt_record import TiltCalibration

__all__ = [
    "ALL_KINDS",
    "CONTACT_FRACTION",
    "EFFECT_KINDS",
    "FIXED_TILT",
    "PLAN_TRIES",
    "ZERO_PREFIX",
    "TiltTerms",
    "fixed_tilt_hints",
    "fixed_tilt_joints",
    "fixed_tilt_note",
    "link_rotations_free",
    "mixed_effects_note",
    "tilt_chain",
    "tilt_figures",
    "tilt_rows",
    "tilt_terms",
    "unclear_contact",
]

Array = NDArray[np.float64]
ALL_KINDS = ("clearance", "backlash", "compliance")
# every kind by default, as the thesis identifies them; a clearance the rows cannot tell from
# the geometry (its bending moment on one side at every row: fixed_tilt_joints) is held by
# the pruning with its reason, the geometry kept (effect_groups.held_for)
EFFECT_KINDS = ALL_KINDS
#: a load within this fraction of its joint's largest over the rows has no reliable sign:
#: 2 % is a 1.1° error of the moment's direction; the thesis' ±5° about the vertical is 8.7 %
CONTACT_FRACTION = 0.02
ZERO_PREFIX = "tilt_zero_"
#: the mean of the clearance's unit tilt vectors (one per row) at least this long: a fixed
#: tilt (0.99: fewer than 0.5 % of the rows with the moment on the other side)
FIXED_TILT = 0.99
PLAN_TRIES = 2000  # random configurations tried for a pose that turns a bending moment over
MOMENT_FLOOR = 1.0  # N·m: the compliance column's scale when the loads are smaller
MAX_EFFECT_ANGLE = 0.5  # rad: a clearance or backlash an LM trial step is capped at (real ones: < 1°)


@dataclass(frozen=True)
class TiltTerms:
    """The tilt rows' unknowns beyond the chain's.

    Attributes:
        robot: the robot whose links carry the sensors (its step names are the chain's).
        geometry: the chain's free rotation steps of the robot (their columns are analytic).
        zeros: ``tilt_zero_<joint>_<axis>``, one per channel read.
        channel: ``(m,)`` each tilt row's channel (index into ``zeros``).
        effects: the joint effects' names (``clearance_<joint>`` …): every kind at every
            joint up to the deepest sensed link.
        effect_scale: ``(len(effects),)`` a reading's change (rad) per unit of each effect
            at a typical load: 1 for an angle, the largest load (N·m) for a compliance.
        loads: ``(m, dof, 3)`` the tilt rows' load moments (eq. 4.21) at the start geometry.
    """

    robot: Model
    geometry: tuple[str, ...]
    zeros: tuple[str, ...]
    channel: NDArray[np.intp]
    effects: tuple[str, ...]
    effect_scale: Array
    loads: Array


def _sensors(robot: Model, data: ConstraintSet):
    from robocal.measure.inclinometer import Inclinometer, TiltReadings

    on = data.tilted
    names = robot.joint_names
    links = tuple(names[k] for k in data.tilt_link[on])
    readings = TiltReadings(data.q[on], links, tuple(TILT_AXES[a] for a in data.tilt_axis[on]),
                            data.tilt[on], np.full(int(on.sum()), data.tilt_sigma))  # fmt: skip
    sensed = dict.fromkeys(data.tilt_link[on].tolist())
    sensors = tuple(Inclinometer(link=names[k], mount=data.mount_matrix(k)) for k in sensed)
    return readings, sensors


def tilt_terms(
    robot: Model, chain: Model, data: ConstraintSet, kinds: tuple[str, ...] = EFFECT_KINDS,
    frames: Model | None = None,
) -> TiltTerms:  # fmt: skip
    """The tilt rows' unknowns for ``robot`` (measured through ``chain``) and ``data``,
    the joint effects of ``kinds``; ``frames``: the robot's own chain, whose joint frames'
    origins the effects' bending moments are taken about (:func:`loads_about`; None:
    ``robot``'s)."""
    from robocal.model.joints import EFFECT_PREFIXES, effect_of

    on = data.tilted
    names = robot.joint_names
    keys = list(zip(data.tilt_link[on].tolist(), data.tilt_axis[on].tolist(), strict=True))
    order = list(dict.fromkeys(keys))
    zeros = tuple(f"{ZERO_PREFIX}{names[k]}_{TILT_AXES[a]}" for k, a in order)
    channel = np.array([order.index(key) for key in keys], dtype=np.intp)
    robot_names = set(robot.names)
    geometry = tuple(s.name for s in chain.steps if s.free and s.is_rotation and s.name in robot_names)
    deepest = int(data.tilt_link[on].max())
    joints = names[: deepest + 1]
    effects = tuple(EFFECT_PREFIXES[kind][0] + j for kind in kinds for j in joints)
    eta = loads_about(robot, data.q[on], frames)
    moment = max(float(np.abs(eta[:, :, 2]).max()) if eta.size else 0.0, MOMENT_FLOOR)
    scale = np.array([moment if (effect_of(e) or ("",))[0] == "compliance" else 1.0 for e in effects])
    return TiltTerms(robot, geometry, zeros, channel, effects, scale, eta)


def tilt_rows(terms: TiltTerms, data: ConstraintSet, values: dict[str, float], zeros: Array,
              effects: Array) -> tuple[Array, Array, Array]:  # fmt: skip
    """The tilt rows at the chain's ``values`` (by step name), the channel ``zeros`` (rad)
    and the ``effects`` (SI): residuals ``(m,)`` (rad, predicted − read), their Jacobian
    over ``terms.geometry`` ``(m, g)`` and over ``terms.effects`` ``(m, e)`` (analytic;
    the zeros' columns are the rows' channel indicators)."""
    from robocal.identify.tilt_identification import GEOM, jacobian_at_loads, predict_at_loads

    robot = terms.robot.with_values({n: values[n] for n in terms.robot.names if n in values})
    readings, sensors = _sensors(robot, data)
    names = terms.effects + tuple(GEOM + g for g in terms.geometry)
    # an LM trial step may ask for an angle the joint model refuses (a clearance of 90°):
    # such a step is only ever rejected, so the angles are capped far beyond any real one
    angles = terms.effect_scale == 1.0
    effects = np.where(angles, np.clip(effects, -MAX_EFFECT_ANGLE, MAX_EFFECT_ANGLE), effects)
    x = np.concatenate([effects, np.zeros(len(terms.geometry))])
    predicted = predict_at_loads(robot, readings, sensors, names, x, terms.loads)
    J = jacobian_at_loads(robot, readings, sensors, names, x, terms.loads)
    r = predicted + zeros[terms.channel] - readings.tilt
    return r, J[:, len(terms.effects) :], J[:, : len(terms.effects)]


def tilt_figures(
    robot: Model, data: ConstraintSet, learned: TiltCalibration | None = None
) -> tuple[tuple[str, ...], Array, str]:
    """What ``robot`` makes of ``data``'s tilt rows: each channel's name, its RMS residual
    (rad) and a sentence saying what predicted the readings.

    ``learned``: the joint effects and channel zeros a calibration identified
    (:class:`~robocal.identify.constraints.tilt_record.TiltCalibration`): the readings are
    predicted with those effects (the rows whose contact side is unclear left out, as in
    the fit) and each channel with a saved zero is judged against it; else (a nominal
    robot) the geometry alone, each channel about its mean (the best zero)."""
    from robocal.identify.constraints.tilt_record import channel_zero_array

    if not data.tilted.any():
        return (), np.zeros(0), ""
    data = mounts_in(data, robot)  # callers with the nominal robot at hand resolve against it first
    effects = {} if learned is None else learned.effect_values
    left_out = 0
    if effects:  # backlash and clearance act with the load's sign: the fit's rows only
        unclear = unclear_contact(robot, data)
        if unclear.any() and not unclear[data.tilted].all():
            data, left_out = data.select(~unclear), int(unclear.sum())
    kinds = tuple(k for k in ALL_KINDS if any(n.startswith(k + "_") for n in effects)) or EFFECT_KINDS
    terms = tilt_terms(robot, robot, data, kinds)
    names = tuple(z[len(ZERO_PREFIX) :] for z in terms.zeros)
    zeros, known = channel_zero_array(learned, names)
    values = dict(zip(robot.names, robot.values.tolist(), strict=True))
    x = np.array([effects.get(n, 0.0) for n in terms.effects])
    r = tilt_rows(terms, data, values, zeros, x)[0]
    rms = []
    for k in range(len(names)):
        rk = r[terms.channel == k]
        rk = rk if known[k] else rk - rk.mean()
        rms.append(math.sqrt(float(np.mean(rk**2))))
    return names, np.array(rms), _figures_basis(tuple(n for n in terms.effects if n in effects), known,
                                                left_out)  # fmt: skip


def _figures_basis(effects: tuple[str, ...], known: NDArray[np.bool_], left_out: int) -> str:
    """The sentence saying what :func:`tilt_figures` predicted the readings with."""
    if not effects and not known.any():
        return "the geometry alone (no joint effects), each channel about its mean (the best zero)"
    text = "the calibrated geometry" + (f" with its joint effects ({', '.join(effects)})" if effects else "")
    if known.all():
        text += " and each channel's calibrated zero"
    elif known.any():
        text += f"; the calibrated zeros of {int(known.sum())} channels, the others about their mean"
    else:
        text += ", each channel about its mean"
    if left_out:
        text += f"; {left_out} rows whose contact side is unclear left out (the fit leaves such rows out)"
    return text


def unclear_contact(robot: Model, data: ConstraintSet) -> NDArray[np.bool_]:
    """``(n,)`` the tilt rows whose contact side is not known: at some joint up to the
    sensed link, the bending moment ``|ηx| + |ηy|`` (clearance, the total of eq. 5.16) or
    the axial moment ``|ηz|`` (backlash) of ``robot``'s loads is below
    :data:`CONTACT_FRACTION` of that joint's largest over the tilt rows (a joint whose
    moment of that kind is zero at every row has no such effect and counts as clear)."""
    from robocal.model.joints import DEADBAND, load_moments

    out = np.zeros(data.n, dtype=bool)
    on = np.flatnonzero(data.tilted)
    if not len(on):
        return out
    eta = load_moments(robot, data.q[on])  # (m, dof, 3)
    unclear = np.zeros((len(on), robot.dof), dtype=bool)
    for load in (np.abs(eta[:, :, 0]) + np.abs(eta[:, :, 1]), np.abs(eta[:, :, 2])):
        largest = load.max(axis=0)
        unclear |= (load < CONTACT_FRACTION * largest) & (largest > DEADBAND)
    sensed = np.arange(robot.dof)[None, :] <= data.tilt_link[on][:, None]
    out[on] = np.any(unclear & sensed, axis=1)
    return out


def tilt_chain(model: Model) -> Model:
    """``model``'s own chain with the base's tilt free in front (``base_rx``, ``base_ry``,
    rad, 0: the nominal robot unchanged, its FK, frames and loads the same): what a file of
    tilt rows alone calibrates with ``robocal calibrate --chain catalog``.

    The catalog chain is the one Table 5.2's joint effects are stated in; it is not the
    default, since a catalog chain need not carry every tilt of a real robot's links (the
    UR10's DH chain has no twist between its parallel joints): the default is the complete
    model with its link rotations freed (:func:`link_rotations_free`), which spans this
    chain's tilt columns.  The joint effects' bending moments are taken about the robot's own
    chain's joint frame origins in either (:func:`loads_about`).  A base that is not level
    turns every link's reading with joint 1, hence its tilt (a chain that already has a step
    of that name keeps its own)."""
    import dataclasses

    from robocal.model.steps import Step

    names = {s.name for s in model.steps}
    base = tuple(
        Step(axis, name) for axis, name in (("Rx", "base_rx"), ("Ry", "base_ry")) if name not in names
    )
    return dataclasses.replace(model, steps=base + tuple(model.steps))


def link_rotations_free(model: Model) -> Model:
    """``model`` (a complete *position* model) with the rotation steps it holds fixed up to
    its last joint freed: the chain a fit with tilt rows calibrates (``robocal
    calibrate``'s default for a catalog robot, tilt rows alone or beside tracker rows).

    Why: a position model holds an angle fixed where positions cannot tell it from the tool
    (the last joint's offset, the Katana's ``theta5``; the UR10's ``alpha5`` and
    ``theta6``), but a sensor on that link reads it: on the thesis' Katana the catalog's
    ``beta4``/``theta5`` direction lies outside the position model's tilt Jacobian (0.67 of
    a unit column) and that fit was left at 0.025° RMS against 0.001° noise.  Freed, the
    model spans every orientation column of the catalog chain and of the complete one (rank
    31 of both's 31 at the thesis' configurations, tests/test_tilt_default_chain.py), so it
    holds for a robot whose catalog chain lacks an angle (the UR10's DH chain has no twist
    between its parallel joints) as for one whose position model does.  What the rows do not
    see is the fit's rank test's to drop (a freed angle of an unsensed link is reported not
    identifiable); the tool's rotations stay fixed (no link sensor turns with them)."""
    last = max((k for k, s in enumerate(model.steps) if s.joint is not None), default=-1)
    names = [s.name for s in model.steps[: last + 1] if s.is_rotation and not s.free]
    return model.with_free(names) if names else model


def mixed_effects_note(data: ConstraintSet, effects: tuple[str, ...]) -> str | None:
    """One sentence when a fit identifies joint ``effects`` from its tilt rows while other
    rows of the same fit (tracker, points, planes, pairs) are predicted without them; else None."""
    others = [k for k in data.kinds if k != "tilt"]
    if not effects or "tilt" not in data.kinds or not others:
        return None
    return (
        f"joint effects ({', '.join(effects)}) are identified from the tilt rows only: the "
        f"{', '.join(others)} rows are predicted without the joints' deflections, so under load "
        "they carry them as error (calibrate those rows alone to compare)"
    )


def fixed_tilt_joints(terms: TiltTerms, data: ConstraintSet) -> tuple[str, ...]:
    """The joints (names) whose clearance turns their link by one fixed tilt at every tilt
    row of ``data``: what the sensors' zeros and the geometry's rotation steps carry too.

    A clearance tilts the joint's link by ``C`` about the bending moment's direction ``b``
    (a unit vector perpendicular to the axis), which turns the vertical as the link sees it
    by ``C (g × b)`` (``g``: the vertical in the link's frame).  Where ``g × b`` is the same
    vector at every row (the mean of the unit vectors at least :data:`FIXED_TILT` long) the
    clearance is a constant tilt: a UR10's parallel joints under gravity, where ``g × b`` is
    ± the joint's axis with the sign of the links' offset along it, the same at every
    configuration.  Poses where the bending moment is on the other side of zero tell them
    apart (the thesis' last link 5° either side of the vertical, §4.4.1); a moment whose
    direction turns as the link sees it (joint 1's, about a vertical axis) does too.  A
    joint with no bending moment is not listed."""
    return _fixed_tilts(terms.robot, data.q[data.tilted], terms.loads)


def _fixed_tilts(robot: Model, q: Array, loads: Array) -> tuple[str, ...]:
    """:func:`fixed_tilt_joints` at configurations ``q`` ``(m, dof)`` under ``loads``
    ``(m, dof, 3)`` (N·m, each joint's frame)."""
    from robocal.model.joints import DEADBAND

    if not len(q):
        return ()
    steps = [s for s in robot.steps if s.joint is not None]
    up = robot.joint_frames(q)[:, :, 2, :3]  # the base's z in each joint frame: (m, dof, 3)
    out = []
    for j, step in enumerate(steps[: loads.shape[1]]):
        if not step.is_rotation:
            continue
        k = step.axis
        b = np.zeros((len(q), 3))
        b[:, (k + 1) % 3], b[:, (k + 2) % 3] = loads[:, j, 0], loads[:, j, 1]
        size = np.linalg.norm(b, axis=1)
        if size.max() <= DEADBAND:
            continue
        w = np.cross(up[:, j], b / np.maximum(size, DEADBAND)[:, None])
        if np.linalg.norm(w.mean(axis=0)) >= FIXED_TILT:
            out.append(robot.joint_names[j])
    return tuple(out)


def fixed_tilt_hints(terms: TiltTerms | None, data: ConstraintSet) -> dict[str, str]:
    """A sentence per ``clearance_<joint>`` of :func:`fixed_tilt_joints` saying why the rows
    cannot see it and what poses would: the pruning's reason when it holds one."""
    if terms is None:
        return {}
    prefix = "clearance_"
    return {
        f"{prefix}{j}": (
            f"{j}'s bending moment keeps its side at every row, so its clearance tilts the link by the "
            f"same angle everywhere, as the sensors' zeros and the geometry do; read poses with {j}'s "
            "bending moment on both sides of zero to identify it"
        )
        for j in fixed_tilt_joints(terms, data)
        if f"{prefix}{j}" in terms.effects
    }


def fixed_tilt_note(terms: TiltTerms | None, data: ConstraintSet, held: set[str]) -> str | None:
    """One sentence naming the joints whose clearance was ``held`` because it is a fixed
    tilt at every row (:func:`fixed_tilt_joints`), and whether any configuration of the
    robot under its own weight would turn their bending moment over (:data:`PLAN_TRIES`
    random ones: the plan), else None."""
    from robocal.measure.ik_starts import random_configurations
    from robocal.model.joints import load_moments

    if terms is None:
        return None
    joints = [j for j in fixed_tilt_joints(terms, data) if f"clearance_{j}" in held]
    if not joints:
        return None
    q = random_configurations(terms.robot, PLAN_TRIES, rng=np.random.default_rng(0))
    never = set(_fixed_tilts(terms.robot, q, load_moments(terms.robot, q)))
    text = (
        f"clearance of {', '.join(joints)} not identified: the joint's bending moment keeps its side at "
        "every row, so its clearance tilts the link by a fixed angle the geometry and the sensors' zeros "
        "carry; add poses with that joint's bending moment on both sides of zero"
    )
    can = [j for j in joints if j not in never]
    cannot = [j for j in joints if j in never]
    if can:
        text += f" (some configurations of this robot do so for {', '.join(can)})"
    if cannot:
        text += (
            f"; for {', '.join(cannot)} none of {PLAN_TRIES} random configurations does under the robot's "
            "own weight: a payload off the joint's axis or a tilted base would"
        )
    return text
