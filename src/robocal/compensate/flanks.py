"""Backlash and clearance near zero load, for the commands robocal writes.

Seed 003's backlash turns a joint by ``±δθ_bkl`` and its clearance tilts it by ``C``, both
with the sign of the joint's load (:mod:`robocal.model.joints`).  A real joint whose load is
small sits on whichever flank friction left it on: that depends on how the joint came
there, which no static model knows.  Two consequences for compensation:

* **No fixed point at the sign change.**  With the thesis' step, a target whose correction
  moves the load across zero has no command ``q`` with ``real(q, effects(q)) = target``: on
  one flank the command needed is on the other side of zero.  The IK chattered between the
  flanks and called such a target unreachable (a Katana 450 program point where joint 2's
  load is 0.008 N·m).
* **An uncertainty no command removes.**  On either flank the tool lands ``δθ_bkl`` x lever
  apart (Katana 450: ~1 mrad at ~0.4 m, ~0.4 mm).

The rule (:class:`FlankEffects`, the joint effects every compensation, filter and path
evaluates):

* a joint's flank is *not known* where its load is within :data:`FLANK_FRACTION` of the
  largest static load the joint carries over its range (gravity and the calibration's
  payload, the largest over :data:`FLANK_SAMPLES` seeded configurations within the joint
  limits; never below :data:`~robocal.model.joints.DEADBAND`), per joint and separately
  for the moment across its axis (clearance) and the load about it (backlash): gear
  friction, a few percent of a joint's rated torque, holds a joint on the flank it came
  from against loads that small;
* there the command aims at the ramp ``clip(η / band, -1, 1)`` of the flank (the
  mid-flank at zero load; ``joint_perturbations(..., flank_band=...)``): the joint effects
  are continuous in ``q``, so the IK converges without chattering, and outside the band
  the model is the thesis' own;
* each such target reports its *flank spread* (:meth:`FlankEffects.spread`): the largest
  tool displacement (m) between where the command aims and where either flank would put
  it, summed over the joints whose flank is not known.  The command is written (it is
  nearer the target on either flank than the uncorrected one, which refusing would write)
  and the target is named with that spread wherever it exceeds the compensation's position
  tolerance.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from robocal.identify.result import CalibrationResult
from robocal.measure.ik import PerturbationFunction
from robocal.measure.ik_starts import random_configurations
from robocal.model.chain import Model
from robocal.model.dynamics import Payload
from robocal.model.joints import DEADBAND, EFFECT_KINDS, joint_perturbations, load_moments

__all__ = ["FLANK_FRACTION", "FLANK_SAMPLES", "FlankEffects", "command_effects", "flank_bands", "flank_note"]

Array = NDArray[np.float64]

#: a load within this fraction of the joint's largest static load leaves its flank unknown
FLANK_FRACTION = 0.05
#: seeded configurations within the joint limits over which the largest static load is taken
FLANK_SAMPLES = 1024
_GRAVITY = (0.0, 0.0, -9.81)  # m/s², base frame: how a bare model's effects were identified
# tilt directions (unit, in the joint's frame) a clearance of unknown contact may take
_DIRECTIONS = tuple((np.cos(a), np.sin(a)) for a in np.arange(8) * np.pi / 4)


def flank_bands(
    robot: Model,
    gravity: ArrayLike = _GRAVITY,
    payload: Payload | None = None,
    extra: ArrayLike | None = None,
) -> Array:
    """``(dof, 2)`` loads (N·m; N for a prismatic joint's axial force) within which each
    joint's flank is not known: :data:`FLANK_FRACTION` of the largest moment across the
    axis and of the largest load about it over :data:`FLANK_SAMPLES` seeded configurations
    within the joint limits (and ``extra`` ``(m, dof)`` configurations, e.g. the program's),
    at least :data:`~robocal.model.joints.DEADBAND`."""
    q = random_configurations(robot, FLANK_SAMPLES, np.random.default_rng(0))
    if extra is not None:
        q = np.concatenate([q, np.asarray(extra, dtype=float).reshape(-1, robot.dof)])
    eta = load_moments(robot, q, gravity=np.asarray(gravity, dtype=float), payload=payload)
    largest = np.stack(
        [np.hypot(eta[:, :, 0], eta[:, :, 1]).max(axis=0), np.abs(eta[:, :, 2]).max(axis=0)], 1
    )
    return np.asarray(np.maximum(FLANK_FRACTION * largest, DEADBAND), dtype=float)


@dataclass(frozen=True, eq=False)
class FlankEffects:
    """The joint effects a command is computed with: ``q (n, dof) -> (n, dof, 3)`` (module
    docstring), plus the learned residual's joint angle errors when the model has one.

    Attributes:
        robot: the chain the loads are computed on (bodies and ``joint_effects``).
        band: ``(dof, 2)`` :func:`flank_bands`.
        gravity: ``(3,)`` m/s² in the base frame.
        payload: a load on the tool, or None.
        residual: the model whose learned residual adds its perturbations, or None.
    """

    robot: Model
    band: Array
    gravity: Array
    payload: Payload | None = None
    residual: Model | None = None

    @classmethod
    def of(
        cls,
        robot: Model,
        gravity: ArrayLike = _GRAVITY,
        payload: Payload | None = None,
        residual: Model | None = None,
    ) -> FlankEffects:
        """The effects ``robot`` states, under ``gravity`` and ``payload``."""
        g = np.asarray(gravity, dtype=float)
        return cls(robot, flank_bands(robot, g, payload), g, payload, residual)

    def _physical(self, q: Array, kinds: tuple[str, ...] = EFFECT_KINDS) -> Array:
        return joint_perturbations(
            self.robot, q, kinds=kinds, gravity=self.gravity, payload=self.payload, flank_band=self.band
        )

    def __call__(self, q: Array) -> Array:
        q = np.atleast_2d(np.asarray(q, dtype=float))
        out = self._physical(q)
        residual = None if self.residual is None else self.residual.residual
        return out if residual is None else out + residual.perturbations(q, self.robot.dof)

    @property
    def never_loaded(self) -> NDArray[np.bool_]:
        """``(dof, 2)`` effects whose load is zero over the whole range (a vertical first
        axis about it): no flank anywhere, left out of every command alike."""
        return np.asarray(self.band <= DEADBAND, dtype=bool)

    def unknown(self, q: Array, never_loaded: bool = False) -> NDArray[np.bool_]:
        """``(n, dof, 2)`` whose flank is not known at ``q``: the clearance's (across the
        axis) and the backlash's (about it), for joints that state that effect and carry a
        load elsewhere in their range (``never_loaded``: those that carry none anywhere)."""
        q = np.atleast_2d(np.asarray(q, dtype=float))
        eta = load_moments(self.robot, q, gravity=self.gravity, payload=self.payload)
        out = np.zeros((len(q), self.robot.dof, 2), dtype=bool)
        for e in self.robot.joint_effects:
            j = self.robot.joint_names.index(e.joint)
            out[:, j, 0] = bool(e.clearance_tilt) & (np.hypot(eta[:, j, 0], eta[:, j, 1]) < self.band[j, 0])
            out[:, j, 1] = bool(e.backlash) & (np.abs(eta[:, j, 2]) < self.band[j, 1])
        return out & (self.never_loaded if never_loaded else ~self.never_loaded)

    def unloaded_note(self, model: Model, q: Array) -> str:
        """One line naming the joints whose backlash or clearance no load ever sets (empty
        when none) and the largest tool displacement (m) their flanks make at ``q``."""
        q = np.atleast_2d(np.asarray(q, dtype=float))
        unknown = self.unknown(q, never_loaded=True)
        if not len(q) or not unknown.any():
            return ""
        rows = np.flatnonzero(unknown.any(axis=(1, 2)))
        worst = float(self._spread(model, q[rows], unknown[rows]).max())
        names = ", ".join(self.robot.joint_names[j] for j in np.flatnonzero(unknown.any(axis=(0, 2))))
        return (
            f"{names}: no static load anywhere in the joint range (e.g. a vertical axis), so no flank to "
            "aim at: its backlash/clearance is left out of every command, which may land up to "
            f"±{worst * 1e3:.3g} mm off depending on the direction the joint last moved"
        )

    def spread(self, model: Model, q: Array) -> tuple[Array, tuple[tuple[str, ...], ...]]:
        """``(n,)`` flank spread (m) of ``model``'s tool point at commands ``q`` (module
        docstring) over the joints loaded elsewhere in their range, and per target the
        joints whose flank is not known."""
        q = np.atleast_2d(np.asarray(q, dtype=float))
        unknown = self.unknown(q)
        spread = np.zeros(len(q))
        rows = np.flatnonzero(unknown.any(axis=(1, 2)))
        if len(rows):
            spread[rows] = self._spread(model, q[rows], unknown[rows])
        names = tuple(
            tuple(self.robot.joint_names[j] for j in np.flatnonzero(u.any(axis=1))) for u in unknown
        )
        return spread, names

    def _spread(self, model: Model, q: Array, unknown: NDArray[np.bool_]) -> Array:
        d = self(q)
        aimed = model.fk(q, d)[:, :3, 3]
        flanked = self._physical(q, ("clearance", "backlash"))
        params = {self.robot.joint_names.index(e.joint): e for e in self.robot.joint_effects}
        total = np.zeros(len(q))
        for j in (int(k) for k in np.flatnonzero(unknown.any(axis=(0, 2)))):
            tilt = np.sin(params[j].clearance_tilt)  # the tilt's size, whatever the contact direction
            worst = np.zeros(len(q))
            for (cx, cy), s in itertools.product(_DIRECTIONS, (-1.0, 1.0)):
                other = d.copy()
                across, about = unknown[:, j, 0], unknown[:, j, 1]
                other[across, j, :2] += tilt * np.array([cx, cy]) - flanked[across, j, :2]
                other[about, j, 2] += s * params[j].backlash - flanked[about, j, 2]
                landed = model.fk(q, other)[:, :3, 3]
                worst = np.maximum(worst, np.linalg.norm(landed - aimed, axis=1))
            total += np.where(unknown[:, j].any(axis=1), worst, 0.0)
        return total


def flank_note(spread_m: float, joints: tuple[str, ...]) -> str:
    """The reason text of a target whose flank is not known (empty when none is)."""
    if not joints:
        return ""
    which = ", ".join(joints)
    return (
        f"load of {which} within its flank band (flank not known): lands within ±{spread_m * 1e3:.3g} mm "
        "of the aimed position, depending on the flank"
    )


def command_effects(calibrated: CalibrationResult | Model) -> PerturbationFunction | None:
    """The joint effects commands for ``calibrated`` are computed with: its physical
    effects as :class:`FlankEffects` (under the calibration's gravity and payload; a bare
    model's under gravity along the base's -z, as identified) with its learned residual;
    the residual alone, or the legacy per-joint compliance of an older result, as they
    are; None when it has none."""
    if isinstance(calibrated, CalibrationResult):
        model, robot = calibrated.model, calibrated.robot
        gravity, payload = calibrated.gravity, calibrated.payload
    else:
        model, robot, gravity, payload = calibrated, calibrated, _GRAVITY, None
    if not model.joint_effects:
        if isinstance(calibrated, CalibrationResult):
            return calibrated.joint_perturbations
        return None if model.residual is None else model.residual.perturbations
    return FlankEffects.of(robot, gravity, payload, model if model.residual is not None else None)
