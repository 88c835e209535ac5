"""Compiled kernels (numba) against robocal's numpy code, Pinocchio and Pinocchio's RNEA, in the
same run: forward kinematics of one configuration and of 10,000, the identification
Jacobian and the fused evaluation of a calibration at 100 poses, the static joint loads, and
the first call of a new process (numba compiling the kernels, or loading them from its cache).

Minimum over interleaved rounds of the per-call time (one BLAS thread).  Every compiled
result is checked against the numpy one to 1e-12 before timing.

Run: ``python benchmarks/bench_kernels.py [--rounds 7] [--cold]`` (``--cold`` also times a
compilation from scratch in a temporary cache directory: tens of seconds).
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
import timeit

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np

import robocal as rc
from robocal.model.dynamics import Payload, _rnea_wrenches, _static_wrenches, to_pinocchio

FIRST_CALL = """
import time
t0 = time.perf_counter()
import numpy as np
from robocal.model.catalog import robot
m = robot("ur10")
q = np.zeros((3, 6))
t1 = time.perf_counter()
m.fk(q)
t2 = time.perf_counter()
m.evaluate(q, m.values, rows="pose", joint_columns=True, perturbation_columns=True)
t3 = time.perf_counter()
print(t1 - t0, t2 - t1, t3 - t2)
"""


def best(fn, rounds: int, budget: float = 0.05) -> float:
    """Seconds per call: the minimum over ``rounds`` of the mean of a batch of calls."""
    fn()
    number = max(1, int(budget / max(timeit.timeit(fn, number=1), 1e-7)))
    return min(timeit.repeat(fn, number=number, repeat=rounds)) / number


def first_call(cache_dir: str | None) -> tuple[float, float, float]:
    env = dict(os.environ)
    if cache_dir is not None:
        env["NUMBA_CACHE_DIR"] = cache_dir
    out = subprocess.run(
        [sys.executable, "-c", FIRST_CALL], capture_output=True, text=True, env=env, check=True
    )
    imports, fk, evaluate = (float(v) for v in out.stdout.split())
    return imports, fk, evaluate


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=7)
    parser.add_argument("--cold", action="store_true", help="also time compiling from scratch")
    args = parser.parse_args()
    rounds = args.rounds

    robot = rc.robot("ur10")
    calib = rc.calibration_model("ur10")
    rng = np.random.default_rng(0)
    lim = np.clip(robot.joint_limits, -np.pi, np.pi)
    q10k = rng.uniform(lim[:, 0], lim[:, 1], (10_000, robot.dof))
    q100, q1 = q10k[:100], q10k[0]
    values = calib.values + rng.normal(0, 1e-4, len(calib.values))

    # the same results first
    assert np.abs(robot.fk(q10k, compiled=True) - robot.fk(q10k, compiled=False)).max() < 1e-12
    for a, b in zip(
        calib.fk_jacobian(q100, compiled=True), calib.fk_jacobian(q100, compiled=False), strict=True
    ):
        assert np.abs(a - b).max() < 1e-12
    for a, b in zip(
        calib.evaluate(q100, values, "pose", compiled=True),
        calib.evaluate(q100, values, "pose", compiled=False),
        strict=True,
    ):
        assert np.abs(a - b).max() < 1e-12

    import pinocchio as pin

    pm = to_pinocchio(robot)
    data = pm.createData()
    tool = pm.getFrameId("tool")

    def pin_fk():
        pin.forwardKinematics(pm, data, q1)
        return pin.updateFramePlacement(pm, data, tool)

    assert np.abs(pin_fk().homogeneous - robot.fk(q1)).max() < 1e-12

    cases = {
        "fk, one configuration": (
            1,
            lambda: robot.fk(q1, compiled=True),
            lambda: robot.fk(q1, compiled=False),
            pin_fk,
        ),
        "fk, batch of 10,000": (
            10_000,
            lambda: robot.fk(q10k, compiled=True),
            lambda: robot.fk(q10k, compiled=False),
            None,
        ),
        f"identification Jacobian, 100 poses, position rows, {len(calib.free_names)} parameters": (
            100,
            lambda: calib.fk_jacobian(q100, compiled=True),
            lambda: calib.fk_jacobian(q100, compiled=False),
            None,
        ),
        "fused evaluation (frames + Jacobian at new values), 100 poses, pose rows": (
            100,
            lambda: calib.evaluate(q100, values, "pose", compiled=True),
            lambda: calib.evaluate(q100, values, "pose", compiled=False),
            None,
        ),
    }
    print(f"robocal kernels: UR10, min of {rounds} rounds, µs per configuration")
    print(f"{'':<82} {'compiled':>9} {'numpy':>9} {'speed-up':>8} {'Pinocchio':>9}")
    for name, (n, fast, ref, other) in cases.items():
        t_fast, t_ref = best(fast, rounds) / n, best(ref, rounds) / n
        t_other = f"{best(other, rounds) / n * 1e6:9.3f}" if other is not None else f"{'':>9}"
        print(f"{name:<82} {t_fast * 1e6:9.3f} {t_ref * 1e6:9.3f} {t_ref / t_fast:7.1f}x {t_other}")

    print("\nstatic joint loads (wrenches at every joint, payload), µs per pose")
    payload = Payload(2.0, (0.0, 0.0, 0.1))
    for n in (100, 1000):
        q, zero = q10k[:n], np.zeros((n, robot.dof))
        vec = best(lambda q=q: _static_wrenches(robot, q, None, payload), rounds) / n
        rnea = best(lambda q=q, zero=zero: _rnea_wrenches(robot, q, zero, zero, None, payload), 3) / n
        print(
            f"  {n:>5} poses: vectorised pass {vec * 1e6:7.2f}   "
            f"Pinocchio RNEA per pose (model built per call) {rnea * 1e6:8.2f}   {rnea / vec:5.1f}x"
        )

    print("\nfirst call in a new process (s): imports | first fk (loads fk kernels) | first evaluate")
    imports, fk, evaluate = first_call(None)
    print(f"  numba cache present:   {imports:.3f} | {fk:.3f} | {evaluate:.3f}")
    if args.cold:
        with tempfile.TemporaryDirectory() as tmp:
            t = time.perf_counter()
            imports, fk, evaluate = first_call(tmp)
            print(
                f"  compiling from scratch: {imports:.3f} | {fk:.3f} | {evaluate:.3f}  "
                f"({time.perf_counter() - t:.1f} s)"
            )


if __name__ == "__main__":
    main()
