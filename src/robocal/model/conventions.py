"""Builders that turn the usual kinematic conventions into chain steps.

Every function returns a list of :class:`~robocal.model.chain.Step`; concatenate
them (and pass them to :func:`model_from_steps`) to make a model.  Values are SI
(m, rad).  Parameter names carry the link index so that they are unique in a chain.

=================  =====================================================  ==========
convention         elementary transforms                                  source
=================  =====================================================  ==========
standard DH        Rz(θ) Tz(d) Tx(a) Rx(α)                                seed 000 eq. 5
modified DH        Rx(α_{i-1}) Tx(a_{i-1}) Rz(θ_i) Tz(d_i)  (Craig)       seed 003 eq. 4.1
Hayati             Rz(θ) Tx(a) Rx(α) Ry(β) [Tz(d)]                        seed 000 eqs. 7, 17
Veitschegger       Rz(θ) Tz(d) Tx(a) Rx(α) Ry(β)                          seed 000 eq. 9
6-parameter frame  Tx Ty Tz Rz(γ) Ry(β) Rx(α)                             seed 000 eq. 1
tool point         Tx Ty Tz
Schröer link sets  :data:`SCHROER_SETS`, seed 000 eqs. (11)-(27)
=================  =====================================================  ==========
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Literal

from robocal.model.chain import Model
from robocal.model.steps import Body, Joint, Role, Step

__all__ = [
    "SCHROER_SETS",
    "dh",
    "frame6",
    "hayati",
    "mdh",
    "model_from_steps",
    "schroer",
    "sequence",
    "tool_point",
    "veitschegger",
]

JointKind = Literal["revolute", "prismatic"] | None

#: Schröer's complete, minimal, model-continuous link parameterisations, seed 000
#: eqs. (11)-(27), as elementary-motion sequences.  For links that start at a joint
#: (eqs. 16-27) the first motion is that joint's variable.  In eqs. (24)-(27) the
#: last three rotations are the orientation part (bracketed in the seed), identifiable
#: only when the tool orientation is measured.
SCHROER_SETS: dict[int, tuple[str, ...]] = {
    11: ("Tx", "Ty", "Tz", "Rz", "Rx"),  # base ⊥ prismatic joint
    12: ("Tx", "Ty", "Tz", "Rx", "Ry"),  # base ∥ prismatic joint
    13: ("Ty", "Tz", "Rz", "Rx"),  # base ⊥ revolute joint, axis near x
    14: ("Tx", "Tz", "Rz", "Rx"),  # base ⊥ revolute joint, axis near y
    15: ("Tx", "Ty", "Rx", "Ry"),  # base ∥ revolute joint (axis near z)
    16: ("Rz", "Tz", "Tx", "Rx", "Tz"),  # R ⊥ R (Denavit-Hartenberg)
    17: ("Rz", "Tx", "Rx", "Ry", "Tz"),  # R ∥ R (Hayati)
    18: ("Tz", "Rz", "Tx", "Rx", "Tz"),  # T ⊥ R
    19: ("Tz", "Tx", "Ty", "Rx", "Ry", "Tz"),  # T ∥ R
    20: ("Tz", "Tx", "Ty", "Rz", "Rx"),  # T ⊥ T
    21: ("Tz", "Tx", "Ty", "Rx", "Ry"),  # T ∥ T
    22: ("Rz", "Tx", "Ty", "Tz", "Rx"),  # R ⊥ T
    23: ("Rz", "Tx", "Ty", "Tz", "Rx", "Ry"),  # R ∥ T
    24: ("Tz", "Ty", "Tx", "Rz", "Ry", "Rz"),  # T ⊥ TCP
    25: ("Tz", "Ty", "Tx", "Rz", "Ry", "Rx"),  # T ∥ TCP
    26: ("Rz", "Tx", "Ty", "Tz", "Rz", "Ry", "Rz"),  # R ⊥ TCP
    27: ("Rz", "Tx", "Ty", "Tz", "Rz", "Ry", "Rx"),  # R ∥ TCP
}

#: Whether the first motion of a Schröer set is the variable of the joint it starts at.
_SCHROER_STARTS_AT_JOINT = {eq: eq >= 16 for eq in SCHROER_SETS}


def _joint(kind: JointKind, index: int | str, name: str | None, limits) -> Joint | None:
    if kind is None:
        return None
    if kind not in ("revolute", "prismatic"):
        raise ValueError(f"joint type must be 'revolute' or 'prismatic', got {kind!r}")
    return Joint(name or f"q{index}", tuple(limits) if limits is not None else None)


def sequence(
    motions: Sequence[str],
    values: Sequence[float],
    names: Sequence[str],
    *,
    joint_step: int | None = None,
    joint_name: str | None = None,
    limits: tuple[float, float] | None = None,
    free: bool | Sequence[bool] = True,
    role: Role | None = None,
) -> list[Step]:
    """Steps for any sequence of elementary motions.

    Args:
        motions: e.g. ``("Rz", "Tz", "Tx", "Rx")``; case-insensitive.
        values: nominal values, SI (m or rad), one per motion.
        names: parameter names, one per motion.
        joint_step: index of the motion driven by a joint variable (its value is the
            joint offset), or ``None``.
        joint_name: the joint's name (default ``"q"`` + the parameter name's index).
        limits: joint limits (rad or m).
        free: one flag for all steps or one per step.
        role: what the steps stand for (:class:`~robocal.model.chain.Role`; default: from
            each name, :meth:`~robocal.model.chain.Role.from_name`).
    """
    motions = [m[0].upper() + m[1].lower() for m in motions]
    if not (len(motions) == len(values) == len(names)):
        raise ValueError(f"{len(motions)} motions, {len(values)} values and {len(names)} names do not match")
    flags = [free] * len(motions) if isinstance(free, bool) else list(free)
    if len(flags) != len(motions):
        raise ValueError(f"{len(flags)} free flags for {len(motions)} motions")
    steps = []
    for k, (motion, value, name, flag) in enumerate(zip(motions, values, names, flags, strict=True)):
        joint = None
        if k == joint_step:
            joint = Joint(joint_name or f"q_{name}", limits)  # Joint checks and stores (lower, upper)
        steps.append(Step(motion, name, value, free=flag, joint=joint, role=role))
    return steps


def dh(
    i: int | str,
    theta: float = 0.0,
    d: float = 0.0,
    a: float = 0.0,
    alpha: float = 0.0,
    *,
    joint: JointKind = "revolute",
    joint_name: str | None = None,
    limits: tuple[float, float] | None = None,
    free: bool = True,
) -> list[Step]:
    """Standard Denavit-Hartenberg link ``Rz(θ) Tz(d) Tx(a) Rx(α)`` (seed 000 eq. 5).

    For a revolute joint θ is the joint offset, for a prismatic joint d is.
    Parameters are named ``theta{i}, d{i}, a{i}, alpha{i}``.
    """
    j = _joint(joint, i, joint_name, limits)
    return [
        Step("Rz", f"theta{i}", theta, free, joint=j if joint == "revolute" else None),
        Step("Tz", f"d{i}", d, free, joint=j if joint == "prismatic" else None),
        Step("Tx", f"a{i}", a, free),
        Step("Rx", f"alpha{i}", alpha, free),
    ]


def mdh(
    i: int,
    alpha: float = 0.0,
    a: float = 0.0,
    theta: float = 0.0,
    d: float = 0.0,
    *,
    joint: JointKind = "revolute",
    joint_name: str | None = None,
    limits: tuple[float, float] | None = None,
    free: bool = True,
) -> list[Step]:
    """Modified (Craig) DH link ``Rx(α_{i-1}) Tx(a_{i-1}) Rz(θ_i) Tz(d_i)`` (seed 003 eq. 4.1).

    Parameters are named as in Craig's tables: ``alpha{i-1}, a{i-1}, theta{i}, d{i}``.
    """
    jt = _joint(joint, i, joint_name, limits)
    return [
        Step("Rx", f"alpha{i - 1}", alpha, free),
        Step("Tx", f"a{i - 1}", a, free),
        Step("Rz", f"theta{i}", theta, free, joint=jt if joint == "revolute" else None),
        Step("Tz", f"d{i}", d, free, joint=jt if joint == "prismatic" else None),
    ]


def hayati(
    i: int | str,
    theta: float = 0.0,
    a: float = 0.0,
    alpha: float = 0.0,
    beta: float = 0.0,
    d: float | None = None,
    *,
    joint: JointKind = "revolute",
    joint_name: str | None = None,
    limits: tuple[float, float] | None = None,
    free: bool = True,
) -> list[Step]:
    """Hayati link ``Rz(θ) Tx(a) Rx(α) Ry(β)`` (seed 000 eq. 7) for parallel revolute
    axes; with ``d`` the trailing ``Tz(d)`` of Schröer's eq. (17) is added.

    Parameters are named ``theta{i}, a{i}, alpha{i}, beta{i}[, d{i}]``.
    """
    if joint == "prismatic":
        raise ValueError("the Hayati parameterisation is for revolute joints")
    jt = _joint(joint, i, joint_name, limits)
    steps = [
        Step("Rz", f"theta{i}", theta, free, joint=jt),
        Step("Tx", f"a{i}", a, free),
        Step("Rx", f"alpha{i}", alpha, free),
        Step("Ry", f"beta{i}", beta, free),
    ]
    if d is not None:
        steps.append(Step("Tz", f"d{i}", d, free))
    return steps


def veitschegger(
    i: int | str,
    theta: float = 0.0,
    d: float = 0.0,
    a: float = 0.0,
    alpha: float = 0.0,
    beta: float = 0.0,
    *,
    joint: JointKind = "revolute",
    joint_name: str | None = None,
    limits: tuple[float, float] | None = None,
    free: bool = True,
) -> list[Step]:
    """Veitschegger-Wu link ``Rz(θ) Tz(d) Tx(a) Rx(α) Ry(β)`` (seed 000 eq. 9; not minimal).

    Parameters are named ``theta{i}, d{i}, a{i}, alpha{i}, beta{i}``.
    """
    jt = _joint(joint, i, joint_name, limits)
    return [
        Step("Rz", f"theta{i}", theta, free, joint=jt if joint == "revolute" else None),
        Step("Tz", f"d{i}", d, free, joint=jt if joint == "prismatic" else None),
        Step("Tx", f"a{i}", a, free),
        Step("Rx", f"alpha{i}", alpha, free),
        Step("Ry", f"beta{i}", beta, free),
    ]


def frame6(
    prefix: str,
    x: float = 0.0,
    y: float = 0.0,
    z: float = 0.0,
    rz: float = 0.0,
    ry: float = 0.0,
    rx: float = 0.0,
    *,
    free: bool = True,
    role: Role | None = None,
) -> list[Step]:
    """A 6-parameter frame ``Tx Ty Tz Rz(γ) Ry(β) Rx(α)`` (seed 000 eq. 1), for a robot
    base or a tool.  Parameters are named ``{prefix}_x ... {prefix}_rx``; ``role``: what
    the frame stands for (default: from the names, the robot's base unless ``tcp``/``frame``).

    Note the parameterisation is singular at β = ±90° (seed 000 eq. 2).
    """
    return sequence(
        ("Tx", "Ty", "Tz", "Rz", "Ry", "Rx"),
        (x, y, z, rz, ry, rx),
        [f"{prefix}_{s}" for s in ("x", "y", "z", "rz", "ry", "rx")],
        free=free,
        role=role,
    )


def tool_point(
    x: float = 0.0, y: float = 0.0, z: float = 0.0, *, prefix: str = "tool", free: bool = True
) -> list[Step]:
    """A 3-parameter tool point ``Tx Ty Tz`` named ``{prefix}_x, {prefix}_y, {prefix}_z``."""
    return sequence(("Tx", "Ty", "Tz"), (x, y, z), [f"{prefix}_{s}" for s in "xyz"], free=free)


def schroer(
    equation: int,
    values: Sequence[float],
    names: Sequence[str],
    *,
    joint_name: str | None = None,
    limits: tuple[float, float] | None = None,
    free: bool | Sequence[bool] = True,
) -> list[Step]:
    """The link parameterisation of seed 000 equation ``equation`` (11-27).

    For eqs. (16)-(27) the first motion is driven by the joint the link starts at;
    eqs. (11)-(15) describe the constant base-to-first-joint transform.
    """
    if equation not in SCHROER_SETS:
        raise ValueError(
            f"Motta 2005 (seed 000) defines link parameterisations in eqs. 11-27, not {equation}"
        )
    return sequence(
        SCHROER_SETS[equation],
        values,
        names,
        joint_step=0 if _SCHROER_STARTS_AT_JOINT[equation] else None,
        joint_name=joint_name,
        limits=limits,
        free=free,
    )


def model_from_steps(
    name: str,
    *links: Sequence[Step],
    bodies: Sequence[Body] = (),
    title: str = "",
    source: str = "",
    notes: str = "",
) -> Model:
    """A model from lists of steps (base, links, tool...) concatenated in order."""
    steps = [s for link in links for s in link]
    return Model(name=name, steps=tuple(steps), bodies=tuple(bodies), title=title, source=source, notes=notes)
