"""Seed 003 chapter 5: the trajectory experiment (circle and line paths, compensated by the
calibrated model)."""

from __future__ import annotations

import dataclasses
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import NDArray

from robocal.experiments.seed003_setup import (
    BASE_OFFSET,
    CIRCLE_PERIOD,
    MM,
    KatanaSetup,
    measure,
)

Array = NDArray[np.float64]


# ------------------------------------------------------------------ trajectory
def compensate_path(
    result, q: Array, target: Array, qd: Array | None = None, qdd: Array | None = None, iterations: int = 5
) -> Array:
    """Seed 003 eq. 5.22: joint commands whose predicted positions (the calibrated
    model with its joint effects) are the desired ``target`` ``(n, 3)`` (m, base frame):
    ``q ← q + Jᵀ(JJᵀ)⁻¹ (P_theor − P_predicted)`` per sample, iterated."""
    q = np.array(q, dtype=float)
    for _ in range(iterations):
        P = result.predict(q, frame=np.eye(4), qd=qd, qdd=qdd)[:, :3, 3]
        J = result.model.joint_jacobian(q)[:, :3, :]  # (n, 3, dof)
        JJt = J @ J.transpose(0, 2, 1)
        q = q + np.einsum("nij,njk,nk->ni", J.transpose(0, 2, 1), np.linalg.inv(JJt), target - P)
    return q


def smooth_joint_path(model, targets: Array, q_ref: Array, iterations: int = 60) -> Array:
    """Joint values ``(n, dof)`` reaching the positions ``targets`` ``(n, 3)`` (m) nearest to
    the reference configuration ``q_ref``: ``min |q − q_ref|`` subject to ``p(q) = target``.

    A 5-joint arm reaching a point has two joints to spare; resolving them by the
    nearest configuration to one reference makes the joint path a smooth (and, along a
    closed path, periodic) function of the target, so that its velocities and
    accelerations are those of the motion, not of the IK's choices.  Solved for all
    samples at once: ``q ← q + J⁺ e + (I − J⁺J)(q_ref − q)`` (the fixed point satisfies
    the constraint and the optimality condition ``q_ref − q ∈ range(Jᵀ)``).
    """
    q = np.tile(np.asarray(q_ref, dtype=float), (len(targets), 1))
    eye = np.eye(model.dof)
    for _ in range(iterations):
        e = targets - model.fk(q)[:, :3, 3]
        J = model.joint_jacobian(q)[:, :3, :]
        Jp = J.transpose(0, 2, 1) @ np.linalg.inv(J @ J.transpose(0, 2, 1))
        q = q + np.einsum("nij,nj->ni", Jp, e) + np.einsum("nij,nj->ni", eye - Jp @ J, q_ref - q)
    miss = np.linalg.norm(targets - model.fk(q)[:, :3, 3], axis=1).max()
    if miss > 1e-9:
        raise RuntimeError(f"the path is not reached near the reference configuration (miss {miss:.3g} m)")
    lim = model.joint_limits
    if np.any((q < lim[:, 0]) | (q > lim[:, 1])):
        raise RuntimeError("the joint path leaves the joint limits")
    return q


def _periodic_rates(q: Array, dt: float) -> tuple[Array, Array]:
    """Velocities and accelerations of a closed joint path sampled every ``dt`` s."""
    ahead, behind = np.roll(q, -1, axis=0), np.roll(q, 1, axis=0)
    return (ahead - behind) / (2 * dt), (ahead - 2 * q + behind) / dt**2


def _line_rates(q: Array, dt: float) -> tuple[Array, Array]:
    return np.gradient(q, dt, axis=0), np.gradient(np.gradient(q, dt, axis=0), dt, axis=0)


TRAJECTORY_METHODS: dict[str, tuple[str, str, dict[str, Any]]] = {
    "geometric": ("geometric only", "geometric", {"level": 2}),
    "stiffness": ("stiffness predicted first", "stiffness", {"effects": "predict", "load_passes": 1}),
    "tilting": ("full tilting predicted first (thesis)", "nominal", {"effects": "predict", "load_passes": 1}),
    "influence_tilting": (
        "influence-based (ch. 3) + tilting (§6.2)",
        "nominal",
        {"effects": "predict", "load_passes": 1, "method": "influence"},
    ),
}


def trajectory_experiment(
    setup: KatanaSetup,
    static_results: dict[str, Any] | None = None,
    n_samples: int = 360,
    n_calibration: int = 24,
    noise_seed: int = 7,
) -> dict[str, Any]:
    """The circle of §5.4-5.5: errors before, after each calibration and eq. 5.22
    correction; and a straight line with the same calibrations (held out).

    ``static_results``: calibrations from the static poses to apply to the paths too
    (name -> :class:`~robocal.identify.calibrate.CalibrationResult`)."""
    import robocal as rc
    from robocal.model.joints import joint_perturbations, load_moments

    circle, line = thesis_paths(setup, n_samples)
    target, q, qd, qdd = circle
    line_target, line_q, line_qd, line_qdd = line

    def actual(qc: Array, v: Array, a: Array) -> Array:
        return setup.true.fk(qc, joint_perturbations(setup.true, qc, v, a))[:, :3, 3]

    def tracking(res, path: _Path) -> Array:
        qc = compensate_path(res, path.q, path.target, path.qd, path.qdd)
        return np.linalg.norm(actual(qc, path.qd, path.qdd) - path.target, axis=1)

    eta_static = load_moments(setup.true, q)
    eta_motion = load_moments(setup.true, q, qd, qdd)
    sag = joint_perturbations(setup.true, q, qd, qdd, kinds=("compliance",), loads=eta_motion)
    stiffness_alone = np.linalg.norm(setup.true.fk(q, sag)[:, :3, 3] - setup.true.fk(q)[:, :3, 3], axis=1)
    step = n_samples // n_calibration
    idx = np.arange(0, n_samples, step)[:n_calibration]
    data = measure(setup, q[idx], noise_seed, qd[idx], qdd[idx])
    stiffness_only = dataclasses.replace(
        setup.nominal,
        joint_effects=tuple(
            dataclasses.replace(e, clearance_tilt=0.0, backlash=0.0) for e in setup.nominal.joint_effects
        ),
    )
    models = {"geometric": setup.geometric, "nominal": setup.nominal, "stiffness": stiffness_only}
    errors = {"before": np.linalg.norm(actual(q, qd, qdd) - target, axis=1)}
    line_errors = {"before": np.linalg.norm(actual(line_q, line_qd, line_qdd) - line_target, axis=1)}
    dropped = {}
    for key, (_, which, options) in TRAJECTORY_METHODS.items():
        res = rc.calibrate(
            models[which],
            data,
            frame="fixed",
            tool=None,
            measure="position",
            velocities=qd[idx],
            accelerations=qdd[idx],
            **options,
        )
        errors[key] = tracking(res, circle)
        line_errors[key] = tracking(res, line)
        dropped[key] = [d.name for d in res.dropped]
    for key, res in (static_results or {}).items():
        errors[key] = tracking(res, circle)
        line_errors[key] = tracking(res, line)
    return {
        "samples": n_samples,
        "calibration_samples": len(idx),
        "period_s": CIRCLE_PERIOD,
        "dynamic_load_change_Nm": float(np.abs(eta_motion - eta_static).max()),
        "max_joint_torque_Nm": float(np.abs(eta_motion[..., 2]).max()),
        "stiffness_alone_mm": float(stiffness_alone.mean() / MM),
        "circle_average_dP": {k: float(v.mean() / MM) for k, v in errors.items()},
        "circle_max_dP": {k: float(v.max() / MM) for k, v in errors.items()},
        "line_average_dP": {k: float(v.mean() / MM) for k, v in line_errors.items()},
        "not_identified": dropped,
        "_errors_mm": {k: (v / MM).tolist() for k, v in errors.items()},
    }


class _Path(NamedTuple):
    target: Array  # (n, 3) m
    q: Array  # (n, dof) rad, the controller's joint path
    qd: Array  # rad/s
    qdd: Array  # rad/s²


def thesis_paths(setup: KatanaSetup, n_samples: int) -> tuple[_Path, _Path]:
    """The thesis' circle (period :data:`CIRCLE_PERIOD`) and its 200 mm line in 2 s, as the
    controller's joint paths: nearest to the configuration that reaches the circle's centre."""
    from robocal.measure.ik import solve_ik
    from robocal.measure.paths import THESIS_CIRCLE_MM, Circle, circle_path, circle_through, line_path

    c = circle_through(THESIS_CIRCLE_MM * MM)
    circle = Circle(c.center + BASE_OFFSET, c.radius, c.normal, c.u)
    target = circle_path(circle, n_samples)
    dt = CIRCLE_PERIOD / n_samples
    q_ref = solve_ik(setup.geometric, circle.center[None], restarts=20, seed=1).q[0]
    q = smooth_joint_path(setup.geometric, target, q_ref)
    line_target = line_path(
        np.array([-0.1, -0.3, 0.1392893]) + BASE_OFFSET, np.array([0.1, -0.3, 0.1392893]) + BASE_OFFSET, 101
    )
    line_q = smooth_joint_path(setup.geometric, line_target, q_ref)
    line_dt = 2.0 / (len(line_q) - 1)  # 200 mm in 2 s
    return _Path(target, q, *_periodic_rates(q, dt)), _Path(
        line_target, line_q, *_line_rates(line_q, line_dt)
    )
