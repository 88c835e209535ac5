"""Seed 001 end to end: calibration table, bounded L1 calibration, compensated commands.

Li, Yang, Chan & Lin, "An optimization technique for identifying robot manipulator
parameters under uncertainty", SpringerPlus 5:1771 (2016).  The seed's workflow, in
simulation:

1. **Arm** — the 3-DOF PUMA-style arm of its appendix (catalog ``li2016_3dof``); the
   real arm deviates from it in the twelve DH parameters the seed identifies
   (δd, δθ, δL, δα of joints 1–3), drawn uniformly within the seed's own bounds
   (±5 mm, ±2°).  Of 20 such arms (seeds 0–19) the one whose mean initial error at the
   verification points is closest to the seed's 26.850 mm is the table arm; the
   Monte Carlo of the full run uses all 20.
2. **Calibration table** — 33 cavities, a circle and a line
   (:func:`robocal.measure.devices.plate_points`: 24 on a 100 mm circle, 9 on a
   240 mm line; the seed shows the layout only in a photograph), on a board in front of
   the arm, flat ("normal"), tilted 11.7° in roll or 11.8° in pitch.  The tool tip is
   placed in each cavity in turn and the encoders' joint angles are recorded; the
   cavity positions are known with the Vicon system's 0.28 mm (1σ per axis).
3. **Identification** — ``rc.calibrate(..., method="bounded")``: min Σ|X − X'| over the
   DH deviations with |δd|, |δL| ≤ 5 mm and |δθ|, |δα| ≤ 2° (seed eq. 4; the board's
   pose is known, so only the arm's parameters are estimated).  One calibration per
   board orientation, as in the seed's Table 4.
4. **Verification** — the arm is commanded to six other points (verification points
   1–6) and along a different trajectory, a Cartesian cubic spline through five
   waypoints (seed eq. 3), with the nominal model's IK ("before") and with
   :func:`robocal.compensate.compensate_targets` on the calibrated model ("after"); a Vicon
   camera (0.28 mm across, 0.84 mm along its line of sight) measures where the tip
   went.  Mean errors with 95 % confidence intervals of the mean
   (t-distribution) and the improvement ``(before − after) / before`` in %, like the
   seed's Tables 4 and 6.
5. **Backlash** — the seed found the pitch results spoilt by motor backlash.  The
   virtual arm gets a direction-dependent backlash on its two pitch joints (2 and 3):
   the link lags the motor by half the play against the direction of the last motion,
   δθ = −(b/2)·sign(Δq).  No model in robocal describes it (it depends on the motion
   history, not on the pose), so it is in the calibration data and in the verification
   but not in the compensation: the run shows how the improvement falls as the play
   grows.

``robocal reproduce seed001 [--quick] [--json] [--out DIR]``; ``quick`` runs the table
arm with and without a 1° play only (a few seconds), the full run adds the play sweep
and the 20-arm Monte Carlo.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from robocal.compensate import compensate_cartesian_path, compensate_targets
from robocal.experiments.seed001_report import differences, plot, print_numbers, report, sweep_row
from robocal.experiments.seed001_setup import (
    BACKLASH_DEG,
    BOARD_CENTER,
    BOARDS,
    N_ARMS,
    PUBLISHED,
    Q_BRANCH,
    SWEEP_DEG,
    DirectionalBacklash,
    backlash_of,
    nominal_arm,
    spline_targets,
    table_arm,
    true_arm,
    verification_points,
)
from robocal.experiments.seed001_setup import Q_HOME as Q_HOME
from robocal.identify.calibrate import calibrate
from robocal.identify.guards import CalibrationGuardError
from robocal.measure.devices import Camera
from robocal.measure.ik import solve_ik
from robocal.measure.measurements import Measurements
from robocal.measure.paths import joint_path
from robocal.measure.plates import CalibrationPlate
from robocal.measure.simulate import VirtualRobot, simulate
from robocal.model.chain import Model
from robocal.safe_output import strict_json

__all__ = [
    "BOARDS",
    "PUBLISHED",
    "DirectionalBacklash",
    "calibration_data",
    "run",
    "spline_targets",
    "table_arm",
    "verification_points",
]

Array = NDArray[np.float64]


# ---------------------------------------------------------------------- steps
def calibration_data(
    true: Model, board: CalibrationPlate, backlash: DirectionalBacklash | None, seed: int
) -> Measurements:
    """The table measurement: the tip placed in every cavity in order, the encoder
    angles recorded (with the backlash between motor and link), the cavity positions
    (plate frame, Vicon noise) as the observations."""
    nominal = nominal_arm()
    ik = solve_ik(true, board.points_base, q0=Q_BRANCH, restarts=0)
    if not ik.success:  # pragma: no cover - the layout is reachable for all 20 arms
        raise RuntimeError(f"the table arm cannot reach the board: {ik.message}")
    q_link = ik.q
    data = simulate(VirtualRobot(nominal, true, board), q_link, seed=seed)
    assert data.position is not None  # the board's cavities are positions
    q_encoder = q_link if backlash is None else q_link - backlash(true, q_link)[:, :, 2]
    return Measurements(q=q_encoder, position=data.position, sigma=data.sigma, metadata=dict(data.metadata))


def _run_commands(robot_: VirtualRobot, q: Array, targets: Array, seed: int) -> Array:
    """Execute ``q`` in order on the virtual arm, measured by its camera: the position
    errors (m) against ``targets`` (base frame)."""
    measured = simulate(robot_, q, seed=seed).position
    assert measured is not None  # a camera measures positions
    T = robot_.device.T_device_base
    return np.linalg.norm(measured - (targets @ T[:3, :3].T + T[:3, 3]), axis=1)


def _stats(e: Array) -> dict[str, float]:
    from scipy.stats import t

    n = len(e)
    half = float(t.ppf(0.975, n - 1) * e.std(ddof=1) / math.sqrt(n)) if n > 1 else float("nan")
    return {"n": n, "mean_mm": float(e.mean() * 1e3), "ci95_mm": half * 1e3, "max_mm": float(e.max() * 1e3)}


def _compare(before: Array, after: Array) -> dict[str, Any]:
    b, a = _stats(before), _stats(after)
    return {
        "before": b,
        "after": a,
        "improvement_pct": 100.0 * (b["mean_mm"] - a["mean_mm"]) / b["mean_mm"],
        "errors_before_mm": (before * 1e3).tolist(),
        "errors_after_mm": (after * 1e3).tolist(),
    }


def _board_run(
    nominal: Model,
    true: Model,
    executed: VirtualRobot,
    board: CalibrationPlate,
    backlash: DirectionalBacklash | None,
    before: tuple[Array, Array],
    q_points_nominal: Array,
    seeds: tuple[int, int, int],
) -> dict[str, Any]:
    """Calibrate on one board and verify at the points and along the spline; a fit that
    fails is recorded as ``{"failed": message}`` (one line), not raised."""
    P, S = verification_points(), spline_targets()
    try:
        data = calibration_data(true, board, backlash, seeds[0])
        result = calibrate(nominal, data, method="bounded", frame=board.T_device_base, tool=None)
        points = compensate_targets(result, P, nominal, q0=q_points_nominal)
        spline = compensate_cartesian_path(result, S, nominal, q0=Q_BRANCH, kind="position")
    except (CalibrationGuardError, ValueError, RuntimeError, np.linalg.LinAlgError) as err:
        # CalibrationGuardError is a ValueError: named for the reader
        return {"failed": f"{type(err).__name__}: {err}".splitlines()[0]}
    return {
        "calibration": {
            "points": data.n,
            "rms_before_mm": result.rms_before * 1e3,
            "rms_after_mm": result.rms_after * 1e3,
            "mean_distance_before_mm": result.metadata["objective"]["mean_distance_before"] * 1e3,
            "mean_distance_after_mm": result.metadata["objective"]["mean_distance_after"] * 1e3,
            "converged": bool(result.success),
            "solver_message": result.message,
            "not_identified": [d.name for d in result.dropped],
            "at_bounds": list(result.metadata["at_bounds"]),
        },
        "points": _compare(before[0], _run_commands(executed, points.q, P, seeds[1])),
        "trajectory": _compare(before[1], _run_commands(executed, spline.q, S, seeds[2])),
        "trajectory_smooth": bool(spline.smooth),
        "commands_reached": bool(points.success and spline.success),
    }


def experiment(arm_seed: int, play_deg: float, noise_seed: int = 0) -> dict[str, Any]:
    """One arm, one backlash play: calibrate on each board and verify on the six points
    and the spline.  Returns plain numbers (mm, %)."""
    nominal = nominal_arm()
    true = true_arm(arm_seed, nominal)
    backlash = backlash_of(play_deg)
    camera = Camera()
    executed = VirtualRobot(nominal, true, camera, joint_effects=backlash)
    P = verification_points()
    S = spline_targets()
    q_points_nominal = solve_ik(nominal, P, q0=Q_BRANCH, restarts=0).q
    q_spline_nominal = joint_path(nominal, S, q0=Q_BRANCH).q
    points_before = _run_commands(executed, q_points_nominal, P, noise_seed + 101)
    spline_before = _run_commands(executed, q_spline_nominal, S, noise_seed + 102)
    boards: dict[str, Any] = {}
    for k, (name, (roll, pitch)) in enumerate(BOARDS.items()):
        board = CalibrationPlate.tilted(BOARD_CENTER, roll=math.radians(roll), pitch=math.radians(pitch))
        seeds = (noise_seed + k, noise_seed + 103 + k, noise_seed + 106 + k)
        boards[name] = _board_run(
            nominal, true, executed, board, backlash, (points_before, spline_before), q_points_nominal, seeds
        )
    return {"arm_seed": arm_seed, "backlash_play_deg": play_deg, "boards": boards}


def run(out: Path | None = None, quick: bool = False, verbose: bool = True) -> dict[str, Any]:
    """Seed 001's experiment (module docstring).  Returns its numbers (mm, %); writes
    ``report.md``, ``results.json`` and ``trajectory_errors.png`` to ``out`` when given."""
    nominal = nominal_arm()
    arm, e0 = table_arm(nominal)
    plays = [0.0, BACKLASH_DEG]
    variants = [experiment(arm, p) for p in plays]
    numbers: dict[str, Any] = {
        "published": PUBLISHED,
        "arm_seed": arm,
        "arms_considered": N_ARMS,
        "initial_error_mm": e0 * 1e3,
        "variants": variants,
        "assumptions": {
            "board_center_m": list(BOARD_CENTER),
            "board_points": "24 on a 100 mm circle + 9 on a 240 mm line (plate_points)",
            "verification_points_m": verification_points().tolist(),
            "spline_samples": len(spline_targets()),
            "backlash": "direction-dependent, joints 2 and 3, play in degrees as listed",
            "camera": "Vicon: 0.28 mm across, 0.84 mm along the line of sight",
        },
    }
    if not quick:
        rows = []
        for play in SWEEP_DEG:
            runs = [experiment(s, play, noise_seed=s) for s in range(N_ARMS)]
            rows.append(sweep_row(play, runs))
        numbers["sweep"] = {"arms": N_ARMS, "rows": rows}
    numbers["differences"] = differences(numbers)
    if verbose:
        print_numbers(numbers)
    if out is not None:
        out = Path(out)
        out.mkdir(parents=True, exist_ok=True)
        from robocal.outdir import write_together

        write_together(  # the numbers, their report and their plot: all of this run or none
            {
                out / "results.json": (strict_json(numbers, indent=2) + "\n").encode("utf-8"),
                out / "report.md": report(numbers).encode("utf-8"),
                out / "trajectory_errors.png": plot(numbers),
            }
        )
        if verbose:
            from robocal.console import console

            console.print(f"wrote {out / 'report.md'}, {out / 'results.json'}", highlight=False)
    return numbers
