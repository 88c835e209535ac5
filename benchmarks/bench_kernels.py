"""Compiled kernels (numba) against robocal's numpy code, Pinocchio and Pinocchio's RNEA, in the
same run: forward kinematics of one configuration and of 10,000, the identification
Jacobian and the fused evaluation of a calibration at 100 poses, the static joint loads, and
the first call of a new process (numba compiling the kernels, or loading them from its cache).

Minimum over rounds of the per-call time (one BLAS thread), as CPU time of this thread
(``time.thread_time``: on a machine shared with other jobs the wall time also counts the
time the process waited for a core — it is printed too); the targets of issue 20 are
checked against the CPU time.  Every compiled result is checked against the numpy one to
1e-12 before timing.

Run: ``python benchmarks/bench_kernels.py [--rounds 7] [--cold] [--md docs/performance.md]``
(``--cold`` also times a compilation from scratch in a temporary cache directory: tens of
seconds; ``--md`` writes the table into the performance page's ``<!-- bench:kernels -->`` block).
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

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import readme_table
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
    """CPU seconds per call: the minimum over ``rounds`` of the mean of a batch of calls."""
    return best_both(fn, rounds, budget)[0]


def best_both(fn, rounds: int, budget: float = 0.05) -> tuple[float, float]:
    """(CPU, wall) seconds per call: the minima over ``rounds`` of the means of a batch of calls."""
    fn()
    number = max(1, int(budget / max(timeit.timeit(fn, number=1), 1e-7)))
    cpu = wall = float("inf")
    for _ in range(rounds):
        c, w = time.thread_time(), time.perf_counter()
        for _ in range(number):
            fn()
        cpu = min(cpu, (time.thread_time() - c) / number)
        wall = min(wall, (time.perf_counter() - w) / number)
    return cpu, wall


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
    parser.add_argument("--md", metavar="PAGE", help="write the table into this file's bench:kernels block")
    args = parser.parse_args()
    rounds = args.rounds
    if args.md and (why := readme_table.check(args.md, "kernels")):
        parser.error(why)
    load_start = readme_table.load()

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
        "`fk`, one configuration": (
            1,
            lambda: robot.fk(q1, compiled=True),
            lambda: robot.fk(q1, compiled=False),
            pin_fk,
            2.0,
        ),
        "`fk`, batch of 10,000": (
            10_000,
            lambda: robot.fk(q10k, compiled=True),
            lambda: robot.fk(q10k, compiled=False),
            None,
            0.15,
        ),
        f"identification Jacobian, 100 poses, position rows, {len(calib.free_names)} parameters": (
            100,
            lambda: calib.fk_jacobian(q100, compiled=True),
            lambda: calib.fk_jacobian(q100, compiled=False),
            None,
            0.5,
        ),
        "fused evaluation (frames + Jacobian at new values), 100 poses, pose rows": (
            100,
            lambda: calib.evaluate(q100, values, "pose", compiled=True),
            lambda: calib.evaluate(q100, values, "pose", compiled=False),
            None,
            None,
        ),
    }
    print(f"robocal kernels: UR10, min of {rounds} rounds, µs per configuration (CPU time; wall in brackets)")
    print(f"{'':<82} {'compiled':>17} {'numpy':>9} {'speed-up':>8} {'Pinocchio':>9} {'target':>7}")
    rows = []
    for name, (n, fast, ref, other, target) in cases.items():
        (t_fast, w_fast), t_ref = (v / n for v in best_both(fast, rounds)), best(ref, rounds) / n
        t_other = f"{best(other, rounds) / n * 1e6:.3f}" if other is not None else ""
        verdict = "" if target is None else f"≤ {target:g} " + ("met" if t_fast * 1e6 <= target else "MISSED")
        print(
            f"{name:<82} {t_fast * 1e6:7.3f} ({w_fast * 1e6:7.3f}) {t_ref * 1e6:9.3f} "
            f"{t_ref / t_fast:7.1f}x {t_other:>9} {verdict}"
        )
        rows.append(
            [name, f"{t_fast * 1e6:.3f} ({w_fast * 1e6:.3f})", f"{t_ref * 1e6:.3f}",
             f"{t_ref / t_fast:.1f}×", t_other, verdict]
        )  # fmt: skip

    print("\nstatic joint loads (wrenches at every joint, payload), µs per pose")
    payload = Payload(2.0, (0.0, 0.0, 0.1))
    loads = []
    for n in (100, 1000):
        q, zero = q10k[:n], np.zeros((n, robot.dof))
        vec = best(lambda q=q: _static_wrenches(robot, q, None, payload), rounds) / n
        rnea = best(lambda q=q, zero=zero: _rnea_wrenches(robot, q, zero, zero, None, payload), 3) / n
        loads.append((vec, rnea))
        print(
            f"  {n:>5} poses: vectorised pass {vec * 1e6:7.2f}   "
            f"Pinocchio RNEA per pose (model built per call) {rnea * 1e6:8.2f}   {rnea / vec:5.1f}x"
        )
    rows.append(
        ["static joint loads (payload), 100 / 1,000 poses",
         " / ".join(f"{v * 1e6:.2f}" for v, _ in loads), "", "", "RNEA " + " / ".join(
             f"{r * 1e6:.1f}" for _, r in loads), ""]
    )  # fmt: skip

    print("\nfirst call in a new process (s): imports | first fk (loads fk kernels) | first evaluate")
    imports, fk, evaluate = first_call(None)
    print(f"  numba cache present:   {imports:.3f} | {fk:.3f} | {evaluate:.3f}")
    first = (
        f"First call in a new process, numba's cache present (wall): imports (robocal, numpy, the "
        f"catalog model) {imports:.2f} s, first `fk` (numba and the cached kernels loaded) {fk:.2f} s, "
        f"first `evaluate` {evaluate:.3f} s."
    )
    if args.cold:
        with tempfile.TemporaryDirectory() as tmp:
            t = time.perf_counter()
            imports, fk, evaluate = first_call(tmp)
            print(
                f"  compiling from scratch: {imports:.3f} | {fk:.3f} | {evaluate:.3f}  "
                f"({time.perf_counter() - t:.1f} s)"
            )
            first += f" Compiling from scratch (empty cache): {time.perf_counter() - t:.0f} s in all."
    if args.md:
        header = ["UR10, µs per configuration, CPU (wall)", "compiled", "numpy", "speed-up", "Pinocchio",
                  "target (issue 20)"]  # fmt: skip
        body = [
            f"`python benchmarks/bench_kernels.py --rounds {rounds}{' --cold' * args.cold} "
            "--md docs/performance.md` "
            f"(minimum over "
            f"{rounds} rounds; CPU time of the thread, wall time in brackets):",
            "",
            *readme_table.markdown_table(header, rows),
            "",
            first,
            "",
            readme_table.machine(load_start),
        ]
        readme_table.write_block(args.md, "kernels", "\n".join(body))


if __name__ == "__main__":
    main()
