"""Damped (regularised) inverse kinematics near singular configurations.

Where the joint Jacobian is nearly singular the exact inverse kinematics of a slightly moved
target can need a large joint motion along the singular direction (a UR wrist at ``q5 ≈ 0``
turns wrist 1 and wrist 3 by opposite radians for a millimetre).  :func:`solve_regularized`
solves instead, per target,

    min_q  |e(q)|² + λ² |q − q_ref|²,

the damped least-squares (Tikhonov) problem around the reference joints ``q_ref``: along a
direction of singular value ``σ`` the motion is ``σ e / (σ² + λ²) ≤ e / (2 λ)``, so it stays
bounded however singular the configuration, while well-conditioned directions (``σ ≫ λ``)
are corrected almost fully.  Gauss–Newton steps
``dq = (JᵀJ + λ² I)⁻¹ (Jᵀ e − λ² (q − q_ref))`` from ``q_ref``; joint limits by clipping.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from robocal.measure.ik import IKResult, PerturbationFunction, Problem, target_array
from robocal.measure.ik_starts import TargetKind
from robocal.model.chain import Model

__all__ = ["solve_regularized"]

Array = NDArray[np.float64]


def solve_regularized(
    model: Model,
    targets: Array,
    q_ref: Array,
    *,
    kind: TargetKind,
    damping: float,
    iterations: int = 30,
    tool_axis: int = 2,
    orientation_weight: float = 1.0,
    joint_effects: PerturbationFunction | None = None,
) -> IKResult:
    """Joints near ``q_ref`` minimising ``|e|² + damping² |q − q_ref|²`` (module docstring).

    Args:
        model: the chain whose tool should reach ``targets``.
        targets: ``(n, 3)`` positions or ``(n, 4, 4)`` frames (m), base frame.
        q_ref: ``(n, dof)`` reference joints (rad, m): the start and the regulariser's centre.
        kind: ``"position"``, ``"pose"`` or ``"axis"`` (as :func:`robocal.measure.ik.solve_ik`).
        damping: ``λ`` in the units of the weighted residual per joint unit (m/rad with
            orientation rows weighted by ``orientation_weight``).
        iterations: Gauss–Newton steps (the problem is nearly linear for small corrections).

    Returns:
        :class:`IKResult`; ``reachable`` is all false (a damped solution leaves a residual by
        design: read ``position_error`` and ``angle_error``).
    """
    T, kind = target_array(targets, kind)
    q_ref = np.asarray(q_ref, dtype=float).reshape(len(T), model.dof)
    problem = Problem(model, T, kind, tool_axis, float(orientation_weight), joint_effects)
    lim = model.joint_limits
    idx = np.arange(len(T))
    lam2 = float(damping) ** 2
    q = q_ref.copy()
    eye = np.eye(model.dof)
    for _ in range(int(iterations)):
        e, J, _, _ = problem.evaluate(q, idx)
        A = np.swapaxes(J, 1, 2) @ J + lam2 * eye
        g = np.einsum("mrd,mr->md", J, e) - lam2 * (q - q_ref)
        q = np.clip(q + np.linalg.solve(A, g[:, :, None])[:, :, 0], lim[:, 0], lim[:, 1])
    _, _, dist, angle = problem.evaluate(q, idx)
    n = len(T)
    steps = np.full(n, int(iterations), dtype=np.int64)
    return IKResult(q, dist, angle, np.zeros(n, dtype=bool), steps, np.ones(n, dtype=np.int64), kind)
