"""Calibration speed: robocal's analytic-Jacobian identification vs finite differences.

The same problem for both: a UR10 built from joint geometry (complete, minimal model),
errors of ±0.5 mm / ±0.05° on every parameter, a laser tracker at an unknown place
measuring a probe at an unknown tool offset with 20 µm noise, 100 random poses.

* robocal: ``rc.calibrate(model, data)`` end to end (start values, identifiable set,
  Levenberg-Marquardt on the analytic Jacobian, covariance).
* baseline: scipy ``least_squares`` (same ``lm`` method, same unknowns, same start
  values) with a 2-point finite-difference Jacobian, on residuals computed the way a
  user of a kinematics library would: a new model per evaluation and its FK.  Only
  the solve is timed for the baseline (its set-up is free), which favours it.

Run: ``python benchmarks/bench_calibrate.py [--repeats 7] [--poses 100]``.
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # small problems: threads only add noise
os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np
from scipy.optimize import least_squares

import robocal as rc
from robocal.measure.devices import LaserTracker
from robocal.measure.simulate import VirtualRobot, draw_true_model, simulate
from robocal.model.builder import Tcp, load_geometry

ROOT = Path(__file__).resolve().parents[1]
PROBE = (0.06, -0.04, 0.109)  # the reflector, off the flange axis (on it, two parameters are lost)


def problem(n_poses: int, seed: int):
    g = load_geometry(ROOT / "examples" / "geometry" / "ur10.yaml")
    model = g.__class__(**{**g.__dict__, "tcp": Tcp(PROBE)}).build("position").model
    true = draw_true_model(model, seed=seed)
    tracker = rc.spatial.homogeneous(rc.spatial.rotvec_to_matrix([0.1, -0.2, 2.0]), [2.0, -1.0, 0.3])
    device = LaserTracker(T_device_base=tracker, p_tool_target=np.zeros(3), sigma=20e-6)
    lim = np.clip(model.joint_limits, -np.pi, np.pi)
    q = np.random.default_rng(seed + 1).uniform(lim[:, 0], lim[:, 1], (n_poses, model.dof))
    return model, simulate(VirtualRobot(model, true, device), q, seed=seed + 2)


def baseline(result, data):
    """scipy least_squares with finite differences on the same unknowns and start values."""
    chain = result.measurement_chain
    names = [n for n in result.names if n in chain.names]
    start = chain.with_values(dict(zip(names, result.nominal, strict=True))).with_free(None, False)
    start = start.with_free(names)

    def residual(x):
        return (start.with_free_values(x).fk(data.q)[:, :3, 3] - data.position).ravel()

    x0 = start.free_values
    t = time.perf_counter()
    res = least_squares(
        residual, x0, jac="2-point", method="lm", x_scale="jac", ftol=1e-12, xtol=1e-12, gtol=1e-12
    )
    seconds = time.perf_counter() - t
    rms = float(np.sqrt(np.mean(np.sum(residual(res.x).reshape(-1, 3) ** 2, axis=1))))
    return seconds, rms, res.nfev


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--poses", type=int, default=100)
    parser.add_argument("--repeats", type=int, default=7)
    parser.add_argument("--seed", type=int, default=1)
    args = parser.parse_args(argv)
    model, data = problem(args.poses, args.seed)
    print("robocal calibration benchmark")
    print(f"  platform  {platform.platform()}, {os.cpu_count()} CPUs, Python {platform.python_version()}")
    print(
        f"  numpy {np.__version__}, robocal {rc.__version__}, "
        f"BLAS threads {os.environ['OPENBLAS_NUM_THREADS']}"
    )
    result = rc.calibrate(model, data)  # warm-up
    print(
        f"  problem   UR10 (built, {len(model.free_names)} free robot parameters), {data.n} poses, "
        f"{len(result.names)} unknowns identified (robot + tracker frame + tool point)"
    )
    ours, solves, theirs = [], [], []
    for _ in range(args.repeats):
        t = time.perf_counter()
        result = rc.calibrate(model, data)
        ours.append(time.perf_counter() - t)
        solves.append(result.metadata["solve_seconds"])
        seconds, rms_fd, _nfev = baseline(result, data)
        theirs.append(seconds)
    t_ours, t_solve, t_fd = min(ours), min(solves), min(theirs)
    print()
    print(f"| method | wall time (min of {args.repeats}) | RMS residual | ratio |")
    print("|---|---:|---:|---:|")
    print(
        f"| robocal `rc.calibrate` (analytic Jacobian, LM), end to end | {t_ours * 1e3:.1f} ms | "
        f"{result.rms_after * 1e3:.4f} mm | 1 |"
    )
    print(f"| robocal, the Levenberg-Marquardt solve inside it | {t_solve * 1e3:.1f} ms | | |")
    print(
        f"| scipy `least_squares` LM, 2-point finite differences, solve only | "
        f"{t_fd * 1e3:.1f} ms | {rms_fd * 1e3:.4f} mm | {t_fd / t_ours:.1f}× slower end to end, "
        f"{t_fd / t_solve:.1f}× solve to solve |"
    )
    print()
    print(f"speed-up: {t_fd / t_ours:.1f}x end to end, {t_fd / t_solve:.1f}x solve to solve (target: 20x)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
