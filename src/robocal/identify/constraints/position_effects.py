"""Joint deflections on the position rows of a constraint fit (issue 33).

A joint that yields to its load turns the links beyond it: under gravity an elastic joint
turns by ``δθ = c ηz`` about its axis (``compliance_<joint>``, rad/(N·m)) and, with radial
elasticity, tilts by ``c_r ηx``, ``c_r ηy`` about the two other axes
(``radial_compliance_<joint>``; :mod:`robocal.model.joints`, seed 003 eqs. 5.15-5.19).
The joints are perturbed by ``B · c`` (rad), ``B`` the effects' patterns
(:func:`robocal.model.joints.effect_basis`) under the static gravity loads of the robot's
link masses (:class:`robocal.model.steps.Body`), and the chain is evaluated with those
perturbations, exactly as :func:`~robocal.identify.constraints.figures.tool_points` and
``Model.fk`` predict them; each effect's column is ``P · B`` with ``P = ∂p/∂(δα, δβ, δθ)``
the chain's perturbation Jacobian there.  The loads are the start geometry's, held (the
tilt rows do the same: a change of the geometry by 0.1° changes them by about 0.2 %).  Every
position-like row carries them: fixed points, planes, distances and tracker points alike.

Without link masses there are no loads and no deflections to fit: a compliance model
needs each link's mass and centre of mass (a model file's ``bodies``; for the Panda the
published values of Gaz et al. 2019, RA-L 4(4), 4147-4154).

Clearance and backlash are not offered here (:data:`SIGN_KINDS`, refused by name:
:func:`check_sign_kinds`): they act with the sign of a joint's load, and a configuration
guided by hand sits on whichever flank the hand last pushed it to.  Tried on MUKCa's
ball-in-socket recordings (issue 33, session 17; docs/tutorials/no-tracker.md), backlash on
the position rows did not earn its place on the Kinova Gen3 lite: the 5-fold CV within the
training placement moved by under 1 % on one arm and got worse on the other at every
deadband tried, the fitted values changed sign between placements (without a deadband they
put 0.1-0.5 rad on the unloaded wrist roll), and pairs of configurations that differ only by
the wrist's roll (the loads on joints 1-5 equal within 0.02 N·m) are 1.4-1.8 mm apart under
every fit: an error no load-driven effect can model.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from robocal.measure.constraints.data_set import ConstraintSet
from robocal.model.chain import Model

__all__ = [
    "POSITION_EFFECT_KINDS",
    "SIGN_KINDS",
    "PositionEffects",
    "check_effect_kinds",
    "check_sign_kinds",
    "position_effects",
    "stated_effects",
    "stated_kinds",
    "with_position_effects",
]

Array = NDArray[np.float64]
#: the joint effects a position row can carry (clearance and backlash act with a load's
#: sign, a jump a hand-guided configuration can sit on either side of: not offered here)
POSITION_EFFECT_KINDS = ("compliance", "radial")
#: the joint effects only tilt rows identify: they act with the sign of a load (the module's
#: docstring says why position rows do not carry them)
SIGN_KINDS = ("clearance", "backlash")
DISPLACEMENT_FLOOR = 1e-9  # m per unit: an effect column this small is none (the rank test drops it)


@dataclass(frozen=True)
class PositionEffects:
    """The joint effects of the position rows and what each does to every tool point.

    Attributes:
        names: the effects' coefficient names (``compliance_<joint>``, SI units).
        basis: ``(m, n, dof, 3)`` each coefficient's joint perturbation pattern per unit.
        scale: ``(m,)`` the largest tool displacement (m) per unit of each over the rows.
    """

    names: tuple[str, ...]
    basis: Array
    scale: Array

    def perturbations(self, values: Array) -> Array:
        """``(n, dof, 3)`` the joints' deflections (rad) at coefficient ``values`` ``(m,)``."""
        return np.einsum("k,knjc->njc", values, self.basis)

    def columns(self, P: Array) -> Array:
        """``(n, 3, m)`` the tool point's derivatives wrt the coefficients, from the
        perturbation Jacobian ``P`` ``(n, 3, dof, 3)`` at the deflected joints."""
        return np.einsum("nrjc,knjc->nrk", P, self.basis)


def position_effects(robot: Model, chain: Model, q: Array, kinds: tuple[str, ...] = ("compliance",),
                     frames: Model | None = None) -> PositionEffects:  # fmt: skip
    """The effects of ``kinds`` at every joint of ``robot`` on the tool point of ``chain``
    (``robot``'s measurement chain) at configurations ``q`` ``(n, dof)``; ``frames``: the
    robot's own chain, whose joint origins the bending moments are taken about.

    Raises:
        ValueError: an unknown kind, or a robot without link masses (no loads to deflect by).
    """
    from robocal.measure.constraints.mounts import loads_about
    from robocal.model.joints import effect_basis

    check_effect_kinds(robot, kinds)
    q = np.atleast_2d(np.asarray(q, dtype=float))
    loads = loads_about(robot, q, frames)
    B, names, _ = effect_basis(robot, q, kinds=kinds, loads=loads)  # (m, n, dof, 3)
    P = chain.perturbation_jacobian(q, "position")  # (n, 3, dof, 3)
    patterns = np.einsum("nrjc,knjc->nrk", P, B)
    scale = np.maximum(np.linalg.norm(patterns, axis=1).max(axis=0, initial=0.0), DISPLACEMENT_FLOOR)
    return PositionEffects(tuple(names), B, scale)


def check_effect_kinds(robot: Model, kinds: tuple[str, ...]) -> None:
    """Refuse joint effects a position row cannot carry, or ``robot`` without link masses
    (no loads to deflect by): ValueError of one line naming the kinds or the model."""
    unknown = sorted(set(kinds) - set(POSITION_EFFECT_KINDS))
    if unknown:
        raise ValueError(f"joint effects {unknown} cannot be fitted on position rows; choose from "
                         f"{', '.join(POSITION_EFFECT_KINDS)}")  # fmt: skip
    if kinds and (not robot.bodies or not any(b.mass > 0 for b in robot.bodies)):
        raise ValueError(
            f"joint compliance needs the link masses of model {robot.name!r} (the gravity loads "
            "the joints yield to): give a model file with bodies (mass and centre of mass per link)"
        )


def check_sign_kinds(kinds: tuple[str, ...], tilt_rows: bool) -> None:
    """Refuse clearance or backlash asked of data without tilt rows (ValueError of one line
    naming them): only tilt rows identify them, and a fit that quietly left them out would
    give the user a robot without what was asked for."""
    named = [k for k in SIGN_KINDS if k in kinds]
    if named and not tilt_rows:
        verb = "are" if len(named) > 1 else "is"
        raise ValueError(
            f"{' and '.join(named)} {verb} identified from tilt rows only and these files hold none "
            "(the sign of a joint's load picks the flank, and a hand-guided configuration can sit "
            "on either); ask for compliance or radial, or add inclinometer rows"
        )


def with_position_effects(robot: Model, values: dict[str, float]) -> Model:
    """``robot`` carrying the position rows' joint effects at ``values`` (by coefficient
    name, SI) in ``model.joint_effects`` (:func:`robocal.model.joints.effects_from_values`);
    ``robot`` itself when there are none."""
    import dataclasses

    from robocal.model.joints import effect_of, effects_from_values

    if not values:
        return robot
    by_kind = {effect_of(n) or ("", n): float(v) for n, v in values.items()}
    return dataclasses.replace(robot, joint_effects=effects_from_values(robot, by_kind))


def stated_effects(robot: Model) -> dict[str, float]:
    """The robot's own compliances (coefficient name -> SI, the nonzero ones) when it has
    the link masses they act under; empty otherwise."""
    from robocal.model.joints import EFFECT_PREFIXES

    if not robot.bodies:
        return {}
    out = {}
    for e in robot.joint_effects:
        for kind, value in (("compliance", e.compliance), ("radial", e.radial_compliance)):
            if value:
                out[EFFECT_PREFIXES[kind][0] + e.joint] = float(value)
    return out


def stated_kinds(robot: Model, data: ConstraintSet) -> tuple[str, ...]:
    """The kinds of the robot's own compliances that deflect ``data``'s position rows
    (points, planes, distances, tracker points).  None with tilt rows: those identify the
    effects, and their position rows carry them only when asked (``effects``)."""
    from robocal.model.joints import effect_of

    if data.tilted.any() or not (data.constrained.any() or data.tracked.any()):
        return ()
    stated = {(effect_of(n) or ("",))[0] for n in stated_effects(robot)}
    return tuple(k for k in POSITION_EFFECT_KINDS if k in stated)
