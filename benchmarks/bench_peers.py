"""Peers side by side: robocal, FIGAROH and a Robotics-Toolbox least-squares fit on
FIGAROH's real TIAGo motion-capture calibration data.

The data (benchmarks/data/figaroh_tiago/, see its README.md): FIGAROH's TIAGo static
postures measured by a Qualisys motion-capture system, point 1 (BL) of the hand rigid
body, in a frame fixed to the robot base; 37 training postures (2021-11-30) and 62
held-out postures of another day (2021-11-26), the roles FIGAROH's own protocol gives
them.  The robot: TIAGo's torso lift and 7-joint arm, kinematics only (joint origins,
axes and limits of FIGAROH's tiago_48_schunk.urdf).

The same calibration problem for everyone, FIGAROH's ``joint_offset`` level: the
mocap frame (6), the marker point on the wrist (3) and the joint offsets (those the
data can tell apart from the frame); then each tool's fullest model: FIGAROH's
``full_params`` and robocal's complete, minimal model (seed 000's builder).  Accuracy:
position RMS on the training postures and on the held-out day (mocap frame from the
training fit: the base frame rigid body is the same on both days); time: the
identification from loaded data (median of ``--repeats``), and FIGAROH end to end
(configuration, data, identification, its validation and report).

* robocal: ``rc.calibrate`` (analytic Jacobian, Levenberg–Marquardt) + ``rc.validate``.
* RTB: Robotics Toolbox for Python's URDF robot and ``fkine`` inside scipy
  ``least_squares`` (Levenberg–Marquardt, finite-difference Jacobian), unknowns as in
  FIGAROH's joint_offset level, start from a rigid Kabsch fit of the mocap frame.
* FIGAROH 1.0 (pip ``figaroh``): ``BaseCalibration`` with a unified configuration,
  run in its own Python (``--figaroh-python``), because it pins its own dependencies.

Run (FIGAROH in a separate virtual environment, so that it cannot change robocal's)::

    python -m venv /tmp/figvenv && /tmp/figvenv/bin/pip install figaroh
    pip install -e ".[bench]"          # roboticstoolbox-python for the RTB row
    python benchmarks/bench_peers.py --figaroh-python /tmp/figvenv/bin/python
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import os
import platform
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
import warnings
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np

DATA = Path(__file__).resolve().parent / "data" / "figaroh_tiago"
URDF = DATA / "tiago_arm.urdf"
TRAIN = DATA / "train_2021-11-30.csv"
HELDOUT = DATA / "heldout_2021-11-26.csv"
JOINTS = [
    "torso_lift_joint",
    "arm_1_joint",
    "arm_2_joint",
    "arm_3_joint",
    "arm_4_joint",
    "arm_5_joint",
    "arm_6_joint",
    "arm_7_joint",
]
TIP = "wrist_ft_tool_link"


def _load(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """``(q (n, 8), p (n, 3))`` from a data file (plain numpy: every peer reads the same)."""
    table = np.genfromtxt(path, delimiter=",", names=True)
    q = np.column_stack([table[name] for name in JOINTS])
    p = np.column_stack([table[c] for c in ("x1", "y1", "z1")])
    return q, p


def _stats(errors: np.ndarray) -> dict[str, float]:
    e = np.linalg.norm(errors, axis=1)
    return {"rms_mm": float(np.sqrt(np.mean(e**2)) * 1e3), "max_mm": float(e.max() * 1e3)}


def _median_time(fn, repeats: int) -> tuple[float, object]:
    times, out = [], None
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times), out


# ------------------------------------------------------------------ robocal
def run_robocal(repeats: int) -> list[dict]:
    import robocal as rc
    from robocal.measure import Measurements
    from robocal.model.urdf.read import build_from_urdf

    complete = build_from_urdf(URDF, "position", TIP).model
    offsets = [s.name for s in complete.steps if s.joint is not None]
    joint_offset = complete.with_free(None, free=False).with_free(offsets)
    (q, p), (qv, pv) = _load(TRAIN), _load(HELDOUT)
    train, heldout = Measurements(q=q, position=p), Measurements(q=qv, position=pv)
    rows = []
    for label, model in (("joint_offset", joint_offset), ("complete model", complete)):
        seconds, result = _median_time(lambda m=model: rc.calibrate(m, train), repeats)
        val = rc.validate(result, heldout)
        rows.append(
            {
                "tool": "robocal",
                "level": label,
                "parameters": len(result.names),
                "train_rms_mm": result.rms_after * 1e3,
                "heldout_rms_mm": val.rms * 1e3,
                "heldout_max_mm": val.max * 1e3,
                "fit_seconds": seconds,
                "note": f"dropped {', '.join(d.name for d in result.dropped if d.name in offsets) or 'none'}"
                if label == "joint_offset"
                else f"{len(result.dropped)} parameters not identifiable, named in result.dropped",
            }
        )
    return rows


# ------------------------------------------------------------------ Robotics Toolbox + scipy
def run_rtb(repeats: int) -> list[dict]:
    try:
        import roboticstoolbox as rtb
    except ImportError:
        return [
            {"tool": "RTB + scipy", "level": "joint_offset", "error": "roboticstoolbox-python not installed"}
        ]
    from scipy.optimize import least_squares
    from scipy.spatial.transform import Rotation

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        robot = rtb.Robot.URDF(str(URDF))
    (q, p), (qv, pv) = _load(TRAIN), _load(HELDOUT)
    # the offsets of the vertical torso lift and arm_1 axes are the mocap frame's z and yaw
    free = [j for j in range(8) if JOINTS[j] not in ("torso_lift_joint", "arm_1_joint")]

    def flange(qs, offsets):
        T = robot.fkine(qs + offsets, end=TIP)
        return np.array(T.A)  # (n, 4, 4)

    def predict(x, qs):
        offsets = np.zeros(8)
        offsets[free] = x[9:]
        T = flange(qs, offsets)
        points = T[:, :3, :3] @ x[6:9] + T[:, :3, 3]
        R = Rotation.from_rotvec(x[3:6]).as_matrix()
        return points @ R.T + x[:3]

    def fit():
        # start: the mocap frame by a rigid (Kabsch) fit of the nominal flange positions
        P = flange(q, np.zeros(8))[:, :3, 3]
        Pc, Qc = P - P.mean(0), p - p.mean(0)
        U, _, Vt = np.linalg.svd(Pc.T @ Qc)
        D = np.diag([1.0, 1.0, np.sign(np.linalg.det(Vt.T @ U.T))])
        R0 = Vt.T @ D @ U.T
        x0 = np.concatenate(
            [p.mean(0) - R0 @ P.mean(0), Rotation.from_matrix(R0).as_rotvec(), np.zeros(3 + len(free))]
        )
        return least_squares(lambda x: (predict(x, q) - p).ravel(), x0, method="lm", x_scale="jac")

    seconds, res = _median_time(fit, repeats)
    return [
        {
            "tool": "RTB + scipy",
            "level": "joint_offset",
            "parameters": len(res.x),
            "train_rms_mm": _stats(predict(res.x, q) - p)["rms_mm"],
            "heldout_rms_mm": _stats(predict(res.x, qv) - pv)["rms_mm"],
            "heldout_max_mm": _stats(predict(res.x, qv) - pv)["max_mm"],
            "fit_seconds": seconds,
            "note": f"{res.nfev} FK passes over all poses (finite differences); arm_7's offset, "
            "redundant with the marker point, left in",
        }
    ]


# ------------------------------------------------------------------ FIGAROH (its own Python)
FIGAROH_CONFIG = """
robot:
  name: tiago_arm
  properties:
    joints:
      active_joints: {joints}
tasks:
  calibration:
    enabled: true
    parameters:
      calibration_level: {level}
      include_non_geometric: false
      outlier_threshold: 0.05
    kinematics:
      base_frame: universe
      tool_frame: {tip}
    measurements:
      markers:
        - name: marker_bl
          reference_joint: arm_7_joint
          measurable_dof: [true, true, true, false, false, false]
      poses:
        base_pose: [0, 0, 0, 0, 0, 0]
        tool_pose: [0, 0, 0, 0, 0, 0]
    data:
      source_file: {train}
      validation_data_file: {heldout}
      number_of_samples: 37
"""


def figaroh_worker(repeats: int) -> None:
    """Runs inside FIGAROH's Python: prints one JSON line with its rows."""
    import logging
    import types

    logging.disable(logging.WARNING)
    import figaroh
    import pinocchio as pin
    from figaroh.calibration.base_calibration import BaseCalibration

    class Calibration(BaseCalibration):
        """FIGAROH's default residuals (position of the marker point)."""

    model = pin.buildModelFromUrdf(str(URDF))
    robot = types.SimpleNamespace(model=model, data=model.createData(), q0=pin.neutral(model))
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for level in ("joint_offset", "full_params"):
            config = Path(tmp) / f"{level}.yaml"
            config.write_text(
                FIGAROH_CONFIG.format(
                    joints=json.dumps(JOINTS), level=level, tip=TIP, train=TRAIN, heldout=HELDOUT
                )
            )

            def prepared(config=config):
                c = Calibration(robot, str(config))
                c.calib_config["known_baseframe"] = False  # the mocap frame is estimated
                c.calib_config["known_tipframe"] = False  # and the marker point
                c.initialize()
                return c

            def end_to_end():
                with contextlib.redirect_stdout(io.StringIO()):
                    c = prepared()
                    c.solve(enable_logging=False)
                return c

            total, c = _median_time(end_to_end, repeats)
            fits = []
            for _ in range(repeats):
                d = prepared()
                t0 = time.perf_counter()
                with contextlib.redirect_stdout(io.StringIO()):
                    d.solve_optimisation(method="lm", enable_logging=False)
                fits.append(time.perf_counter() - t0)
            val = c._compute_validation_metrics()
            rows.append(
                {
                    "tool": f"FIGAROH {figaroh.__version__}",
                    "level": level,
                    "parameters": len(c.calib_config["param_name"]),
                    "train_rms_mm": float(c.evaluation_metrics["rmse"]) * 1e3,
                    "heldout_rms_mm": float(val["pos_rmse_calibrated_mm"]),
                    "heldout_max_mm": float(val["pos_max_calibrated_mm"]),
                    "fit_seconds": statistics.median(fits),
                    "total_seconds": total,
                    "note": f"{c.evaluation_metrics['n_outliers']} outliers excluded",
                }
            )
    print(json.dumps(rows))


def run_figaroh(python: str | None, repeats: int) -> list[dict]:
    if python is None:
        try:
            import figaroh  # noqa: F401
        except ImportError:
            return [{"tool": "FIGAROH", "level": "-", "error": "not installed: pass --figaroh-python"}]
        python = sys.executable
    out = subprocess.run(
        [python, __file__, "--figaroh-worker", "--repeats", str(repeats)],
        capture_output=True,
        text=True,
        timeout=900,
        check=False,
    )
    lines = [ln for ln in out.stdout.splitlines() if ln.startswith("[")]
    if out.returncode != 0 or not lines:
        tail = (out.stderr.strip().splitlines() or ["no output"])[-1]
        return [{"tool": "FIGAROH", "level": "-", "error": f"exit {out.returncode}: {tail}"}]
    return json.loads(lines[-1])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--figaroh-python", help="Python of a virtual environment with figaroh installed")
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--figaroh-worker", action="store_true", help=argparse.SUPPRESS)
    parser.add_argument("--json", action="store_true", help="print the rows as JSON")
    args = parser.parse_args()
    if args.figaroh_worker:
        figaroh_worker(args.repeats)
        return
    python = args.figaroh_python or os.environ.get("FIGAROH_PYTHON")
    if python and not shutil.which(python) and not Path(python).exists():
        sys.exit(f"--figaroh-python {python}: no such interpreter")
    rows = run_robocal(args.repeats) + run_rtb(args.repeats) + run_figaroh(python, args.repeats)
    if args.json:
        print(json.dumps(rows, indent=2))
        return
    import robocal

    print(
        f"machine: {platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}, "
        f"robocal {robocal.__version__}, numpy {np.__version__}; FIGAROH TIAGo mocap data: 37 training "
        f"postures (2021-11-30), 62 held-out (2021-11-26); times: median of {args.repeats}"
    )
    head = f"{'tool':<16s} {'level':<15s} {'params':>6s} {'train RMS mm':>13s} {'held-out RMS mm':>16s} "
    head += f"{'held-out max mm':>16s} {'fit ms':>9s} {'end-to-end ms':>14s}  note"
    print(head)
    for r in rows:
        if "error" in r:
            print(f"{r['tool']:<16s} {r['level']:<15s} {r['error']}")
            continue
        total = f"{r['total_seconds'] * 1e3:14.1f}" if "total_seconds" in r else f"{'':14s}"
        print(
            f"{r['tool']:<16s} {r['level']:<15s} {r['parameters']:6d} {r['train_rms_mm']:13.3f} "
            f"{r['heldout_rms_mm']:16.3f} {r['heldout_max_mm']:16.3f} {r['fit_seconds'] * 1e3:9.1f} {total}  "
            f"{r.get('note', '')}"
        )


if __name__ == "__main__":
    main()
