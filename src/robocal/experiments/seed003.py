"""Seed 003 reproduced in simulation: the Katana 450 with joint tilting.

``robocal reproduce seed003 [--json] [--quick] [--out DIR]``

The thesis (seed 003) calibrates a Katana 450 whose joints tilt under load because
of clearance, backlash and compliance.  This experiment rebuilds its two studies on a
virtual Katana whose errors are the thesis' own numbers:

* geometry: the deviations the thesis identified (Table 3.2, standard
  identification), mapped onto robocal's Katana model (the modified-DH + Hayati form
  of eqs. 4.2-4.7, :data:`THESIS_GEOMETRIC_ERRORS`);
* joints: Table 5.2 (clearance tilt, backlash, axial stiffness; the catalog model's
  ``joint_effects``), loads from the Table 4.2 masses (Pinocchio RNEA);
* measurement: an Optotrak-like optical CMM, 0.01 mm per marker coordinate, in the
  robot's structural base frame {R} (as the thesis' digitising probe sets it);
* poses: the 118 ISO 9283 poses on the diagonal planes of the frontal cube
  (:func:`robocal.measure.poses.diagonal_plane_poses`); held-out poses drawn at random
  over the workspace above the table.

**Influence-based identification (ch. 3, Fig. 3.8, Table 3.4)**: the thesis' parameters
(Table 3.2's) identified from the 118 poses by the thesis' standard method (eq. 3.6 at
each pose, the per-pose sets averaged) and its influence-based one (eqs. 3.7-3.8), one
pass each as the thesis describes them, by the best per-pose set, repeated until the set
stops moving, by least squares over all poses and by the least sum of distances (the
floor of Table 3.4's average |ΔP| for any set of those parameters); the influence
analysis of Fig. 3.8 (:mod:`robocal.identify.influence`).

**Static calibration (ch. 4, Tables 4.5/4.6)**: before; conventional (geometric,
level 2); the thesis' two-stage "tilt-aware" method (tilting predicted from the
measured joint parameters and removed, then geometric identification: eqs.
4.20-4.22, one pass with the nominal geometry's loads, as in the thesis); and
robocal's simultaneous method (level 3: geometry, clearance tilts, backlash and
stiffness identified together from the poses alone, with the loads recomputed at
the calibrated geometry).  Tables of min/max/average |ΔX| |ΔY| |ΔZ| |ΔP| |ΔΦ| |Δθ| |ΔΨ|
(ZXZ Euler angles as in the thesis) on the calibration poses and on the held-out
poses.  A robustness run repeats it with joint parameters that differ from the
"measured" Table 5.2 by up to ±25 %.

**Trajectory (§5.4-5.5)**: the thesis' circle (centre [0 −300 139.29] mm, radius
100 mm, on the 45° plane, in the nominal base frame {0}, which is [55 55 201.5] mm
from the model's base {R}), one revolution in :data:`CIRCLE_PERIOD` s; the joint
loads include the motion's inertial forces (eq. 5.14).  The robot is calibrated from
a few measured samples of the circle (eq. 5.20) — geometric only, with the stiffness
predicted first, with the full tilting predicted first, and with the influence-based
identification of ch. 3 combined with the tilting model (§6.2, the thesis' future
work) — the joint commands are corrected by eq. 5.22, and the tracking error of the
corrected circle is measured; a straight line (the circle's horizontal diameter)
checks the calibration away from the circle.

``run()`` returns the numbers; the JSON keys ``before``, ``conventional``,
``tilt_aware`` and ``simultaneous`` hold the held-out average |ΔP| (mm).
"""

from __future__ import annotations

import math
import time
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from robocal.experiments.seed003_inclinometer import inclinometer_experiment, print_inclinometer
from robocal.experiments.seed003_report import mean_sd, notes, print_numbers, table_3_4_notes, write
from robocal.experiments.seed003_setup import ABOVE_TABLE as ABOVE_TABLE
from robocal.experiments.seed003_setup import (
    BASE_OFFSET,
    CIRCLE_PERIOD,
    DEG,
    MM,
    NOISE,
    STATIC_METHODS,
    THESIS,
    THESIS_GEOMETRIC_ERRORS,
    KatanaSetup,
    katana_setup,
    measure,
    measured_frames,
    pose_errors,
    summary,
)
from robocal.experiments.seed003_setup import CUBE_CENTER as CUBE_CENTER
from robocal.experiments.seed003_setup import CUBE_SIDE as CUBE_SIDE
from robocal.experiments.seed003_setup import HELD_OUT_BOX as HELD_OUT_BOX
from robocal.experiments.seed003_trajectory import TRAJECTORY_METHODS as TRAJECTORY_METHODS
from robocal.experiments.seed003_trajectory import compensate_path, trajectory_experiment
from robocal.experiments.seed003_trajectory import smooth_joint_path as smooth_joint_path
from robocal.model.joints import effect_of

__all__ = [
    "BASE_OFFSET",
    "CIRCLE_PERIOD",
    "THESIS",
    "THESIS_GEOMETRIC_ERRORS",
    "KatanaSetup",
    "compensate_path",
    "katana_setup",
    "pose_errors",
    "run",
    "static_experiment",
    "trajectory_experiment",
]

Array = NDArray[np.float64]


THESIS["held_out_average_dP"] = {
    k: round(float(np.mean(v)), 3) for k, v in THESIS["table_4_6_uncalibrated_dP"].items()
}


# ------------------------------------------------------------------ static calibration


def static_experiment(setup: KatanaSetup, noise_seed: int = 1) -> dict[str, Any]:
    """Calibrate the virtual Katana on its 118 poses by every method; errors on the
    calibration and held-out poses (simulated measurements, seed ``noise_seed``)."""
    import robocal as rc

    train = measure(setup, setup.train_q, noise_seed)
    test = measure(setup, setup.test_q, noise_seed + 1000)
    T_train, T_test = measured_frames(train), measured_frames(test)
    out: dict[str, Any] = {"calibration": {}, "held_out": {}, "per_pose": {}, "results": {}}
    out["calibration"]["before"] = summary(pose_errors(T_train, setup.geometric.fk(train.q)))
    e_before = pose_errors(T_test, setup.geometric.fk(test.q))
    out["held_out"]["before"] = summary(e_before)
    out["per_pose"]["before"] = e_before[:10, 3].tolist()
    from robocal.model.joints import joint_perturbations

    q = setup.train_q
    moved = setup.true.fk(q, joint_perturbations(setup.true, q))[:, :3, 3] - setup.true.fk(q)[:, :3, 3]
    out["joint_effects_alone_mm"] = float(np.linalg.norm(moved, axis=1).mean() / MM)
    T_true = setup.true.fk(test.q, joint_perturbations(setup.true, test.q))
    out["cmm_noise"] = pose_errors(T_test, T_true).mean(axis=0).tolist()  # the measurement's own error
    for key, (_, which, options) in STATIC_METHODS.items():
        model = setup.geometric if which == "geometric" else setup.nominal
        result = rc.calibrate(model, train, frame="fixed", tool=None, measure="position", **options)
        out["results"][key] = result
        out["calibration"][key] = summary(pose_errors(T_train, result.predict(train.q)))
        e = pose_errors(T_test, result.predict(test.q))
        out["held_out"][key] = summary(e)
        out["per_pose"][key] = e[:10, 3].tolist()
    return out


# ------------------------------------------------------------------ Table 3.4 (ch. 3)
#: the identification methods of ch. 3 compared on the thesis' parameters (Table 3.2's,
#: geometry only, the base as the digitising probe sets it): key -> (label, solve options)
TABLE_3_4_METHODS: dict[str, tuple[str, dict[str, Any]]] = {
    "least_squares": ("least squares over all poses (lm; (JᵀJ)⁻¹Jᵀ gives the same)", {"method": "lm"}),
    "standard": ("eq. 3.6 per pose, mean of the 118 sets (thesis)", {"per_pose": True, "passes": 1}),
    "influence": ("eqs. 3.7-3.8 per pose, C = 0.5, mean of the sets (thesis)", {"passes": 1}),
    "standard_best": (
        "eq. 3.6 per pose, the set that fits all poses best",
        {"per_pose": True, "passes": 1, "combine": "best"},
    ),
    "influence_best": (
        "eqs. 3.7-3.8 per pose, the set fitting all poses best",
        {"passes": 1, "combine": "best"},
    ),
    "standard_repeated": ("eq. 3.6, mean of the sets, repeated until it stops moving", {"per_pose": True}),
    "influence_repeated": ("eqs. 3.7-3.8, mean of the sets, repeated until it stops moving", {}),
    "least_average": (
        "the least average |ΔP| any set of these parameters reaches (min Σ|ΔP|)",
        {"method": "bounded", "bounds": None},
    ),
}


def thesis_problem(setup: KatanaSetup, data):
    """The ch. 3 identification problem: the Table 3.2 parameters
    (:data:`THESIS_GEOMETRIC_ERRORS`) of the geometric model, positions in the base {R},
    rows weighted by the CMM's σ; and the model it varies."""
    from robocal.identify.problem import Problem, measurement_chain

    robot = setup.geometric.fixed([n for n in setup.geometric.names if n not in THESIS_GEOMETRIC_ERRORS])
    chain = measurement_chain(robot, np.eye(4), None, "position", fit_frame=False)
    weights = np.full(data.n * 3, 1.0 / NOISE)
    return Problem(chain, data.q, data.position, None, weights, length_scale=0.6), robot


def _identified(problem, robot, x):
    """The robot model with the identified values ``x`` of ``problem``'s unknowns."""
    return robot.with_values(dict(zip(problem.chain.free_names, x, strict=True)))


def _unit(setup: KatanaSetup, name: str) -> float:
    return DEG if setup.geometric.step(name).is_rotation else MM


def influence_experiment(setup: KatanaSetup, noise_seeds: tuple[int, ...] = (1,)) -> dict[str, Any]:
    """Seed 003 ch. 3: the influence analysis of Fig. 3.8 at the 118 poses and Table 3.4
    (average errors over the 118 poses) for each method of :data:`TABLE_3_4_METHODS`,
    with the held-out error, per noise draw (``noise_seeds``)."""
    from robocal.identify.influence import influence_analysis
    from robocal.identify.solvers import solve

    per_draw: dict[str, list[dict[str, Any]]] = {k: [] for k in ("before", *TABLE_3_4_METHODS)}
    analysis = None
    identified: dict[str, dict[str, float]] = {}
    for draw, noise_seed in enumerate(noise_seeds):
        train = measure(setup, setup.train_q, noise_seed)
        test = measure(setup, setup.test_q, noise_seed + 1000)
        T_train, T_test = measured_frames(train), measured_frames(test)
        problem, robot = thesis_problem(setup, train)
        x0 = problem.x0
        if analysis is None:
            analysis = influence_analysis(problem, x0)
        fits = {"before": x0}
        for key, (_, options) in TABLE_3_4_METHODS.items():
            opts = dict(options)
            method = opts.pop("method", "pinv" if opts.get("per_pose") else "influence")
            fits[key] = solve(problem, x0, method, **opts).x
        for key, x in fits.items():
            model = _identified(problem, robot, x)
            e_train = pose_errors(T_train, model.fk(train.q))
            e_test = pose_errors(T_test, model.fk(test.q))
            per_draw[key].append(
                {
                    "average": e_train.mean(axis=0).tolist(),
                    "rms_dP": float(np.sqrt(np.mean(e_train[:, 3] ** 2))),
                    "held_out_dP": float(e_test[:, 3].mean()),
                }
            )
            if draw == 0:
                identified[key] = {
                    name: (v - setup.geometric.step(name).value) / _unit(setup, name)
                    for name, v in zip(problem.chain.free_names, x, strict=True)
                }
    assert analysis is not None
    out: dict[str, Any] = {
        "influence_analysis": analysis.table(),
        "table_3_4": {k: np.mean([d["average"] for d in v], axis=0).tolist() for k, v in per_draw.items()},
        "calibration_dP": {k: mean_sd([d["average"][3] for d in v]) for k, v in per_draw.items()},
        "calibration_rms_dP": {k: mean_sd([d["rms_dP"] for d in v]) for k, v in per_draw.items()},
        "held_out_dP": {k: mean_sd([d["held_out_dP"] for d in v]) for k, v in per_draw.items()},
        "identified_mm_deg": identified,
        "true_mm_deg": {k: v / _unit(setup, k) for k, v in THESIS_GEOMETRIC_ERRORS.items()},
        "labels": {k: label for k, (label, _) in TABLE_3_4_METHODS.items()},
    }
    return out


# ------------------------------------------------------------------ the run
def _joint_parameters(result, true_model) -> dict[str, Any]:
    """Identified joint parameters with σ next to the true ones (deg, kgf·m/deg)."""
    from robocal.model.files import STIFFNESS_SCALE

    kgfm = STIFFNESS_SCALE["kgf*m/deg"]
    true = {e.joint: e for e in true_model.joint_effects}
    out: dict[str, dict[str, dict[str, Any]]] = {}  # {joint: {quantity: {estimate, sigma, true...}}}
    for joint, row in result.effect_estimates().items():
        t = true.get(joint)
        entry: dict[str, dict[str, Any]] = {}
        for attr, (v, s) in row.items():
            tv = getattr(t, attr) if t is not None else 0.0
            if attr in ("clearance_tilt", "backlash"):
                entry[attr + "_deg"] = {
                    "estimate": math.degrees(v),
                    "sigma": None if s is None else math.degrees(s),
                    "true": math.degrees(tv),
                }
            elif attr == "compliance":
                entry["stiffness_kgfm_per_deg"] = {
                    "estimate": (1.0 / v / kgfm) if v > 0 else math.inf,
                    "sigma": None if (s is None or v <= 0) else s / v**2 / kgfm,
                    "true": (1.0 / tv / kgfm) if tv > 0 else math.inf,
                    # 1σ of the compliance mapped to the stiffness: [1/(c + σ), 1/(c − σ)]
                    "interval_1sigma": (
                        None if (s is None or v <= s) else [1 / (v + s) / kgfm, 1 / (v - s) / kgfm]
                    ),
                }
        out[joint] = entry
    # joint effects the poses cannot tell (below zero, within 3σ of it, or unloaded): the reason
    keys = {  # effect kind -> (entry, JointEffects field)
        "clearance": ("clearance_tilt_deg", "clearance_tilt"),
        "backlash": ("backlash_deg", "backlash"),
        "compliance": ("stiffness_kgfm_per_deg", "compliance"),
    }
    for d in result.dropped:
        effect = effect_of(d.name)
        if effect is None or effect[0] not in keys:
            continue
        kind, joint = effect
        cell = out.setdefault(joint, {}).setdefault(keys[kind][0], {"estimate": None, "sigma": None})
        t = true.get(joint)
        tv = getattr(t, keys[kind][1], 0.0)
        if t is None or kind != "compliance":
            cell["true"] = math.degrees(tv) if t is not None else 0.0
        else:
            cell["true"] = (1.0 / tv / kgfm) if tv > 0 else math.inf
        cell["not_identified"] = str(d).split(": ", 1)[1]
    return out


def noise_seeds(draws: int) -> tuple[int, ...]:
    """The measurement-noise seeds of ``draws`` noise draws (those of :func:`run`)."""
    return tuple(1 + 10 * k for k in range(draws))


def run_sizes(quick: bool) -> tuple[int, int, int]:
    """Held-out poses, noise draws and circle samples of :func:`run`."""
    return (100, 2, 120) if quick else (200, 5, 360)


def run(out: Path | None = None, quick: bool = False, verbose: bool = True) -> dict[str, Any]:
    """Run the seed 003 experiment; see the module docstring.

    Args:
        out: directory for ``seed003.json``, ``seed003.md`` and ``seed003_circle.png``.
        quick: 100 held-out poses, 2 noise draws, 120 circle samples (instead of 200,
            5 and 360).
        verbose: print the tables with the thesis' numbers beside them.

    Returns:
        Plain data; ``before``, ``conventional``, ``tilt_aware``, ``simultaneous``:
        held-out average |ΔP| (mm), averaged over the noise draws.
    """
    t0 = time.perf_counter()
    n_test, draws, n_samples = run_sizes(quick)
    setup = katana_setup(n_test=n_test)
    runs = [static_experiment(setup, noise_seed=seed) for seed in noise_seeds(draws)]
    first = runs[0]
    keys = ["before", *STATIC_METHODS]
    held = {k: mean_sd([r["held_out"][k]["average"][3] for r in runs]) for k in keys}
    calib = {k: mean_sd([r["calibration"][k]["average"][3] for r in runs]) for k in keys}
    robust_setup = katana_setup(n_test=n_test, joint_parameter_error=0.25, error_seed=3)
    robust = static_experiment(robust_setup, noise_seed=5)
    static = {f"{k}_static": first["results"][k] for k in ("simultaneous", "simultaneous_measured")}
    trajectory = trajectory_experiment(setup, static, n_samples=n_samples)
    chapter_3 = influence_experiment(setup, noise_seeds(draws))
    inclinometer = inclinometer_experiment(setup)
    from robocal.experiments.seed003_pen import pen_experiment, public

    pen = public(pen_experiment(setup, n_samples=n_samples))
    numbers: dict[str, Any] = {
        **{k: round(held[k]["mean"], 4) for k in ("before", "conventional", "tilt_aware", "simultaneous")},
        "units": "mm and deg; held-out = poses not used for calibration",
        "held_out_average_dP": held,
        "calibration_average_dP": calib,
        "tables": {"calibration_poses": first["calibration"], "held_out_poses": first["held_out"]},
        "held_out_first_10_dP": first["per_pose"],
        "joint_parameters": _joint_parameters(first["results"]["simultaneous"], setup.true),
        "robustness_joint_parameters_25pct": {k: v["average"][3] for k, v in robust["held_out"].items()},
        "trajectory": {k: v for k, v in trajectory.items() if not k.startswith("_")},
        "table_3_4": chapter_3,
        "inclinometer": inclinometer,
        "pen": pen,
        "setup": {
            "poses": len(setup.train_q),
            "held_out_poses": len(setup.test_q),
            "noise_draws": draws,
            "noise_mm_per_marker": NOISE / MM,
            "geometric_errors_mm_deg": {
                k: v / (DEG if setup.nominal.step(k).is_rotation else MM)
                for k, v in THESIS_GEOMETRIC_ERRORS.items()
            },
        },
        "thesis": THESIS,
    }
    numbers["notes"] = notes(numbers, first)
    numbers["table_3_4_notes"] = table_3_4_notes(chapter_3)
    numbers["seconds"] = round(time.perf_counter() - t0, 2)
    if verbose:
        print_numbers(numbers, first)
        print_inclinometer(inclinometer)
    if out is not None:
        write(Path(out), numbers, trajectory)
    return numbers
