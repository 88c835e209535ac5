"""Start values of a calibration: the compiled kernel (robocal.identify.kernels.start, behind
``initial_frames_and_tools``) against the numpy implementation it replaced
(``tests/test_start_kernels.py::reference``), in the same run.

* ``initial_frames_and_tools`` for one robot (K = 1) and the study engine's batch (K = 50),
  100 poses of bench_calibrate's UR10 problem, position and pose data;
* ``rc.calibrate`` on ``bench_calibrate.problem(100, 1)`` with either start values;
* the first call in a new process, after the chain kernels (numba loading the kernel from
  its cache), and with ``--cold`` compiling it from scratch (a temporary cache directory).

Per-call times: the minimum over rounds of timeit batches (CPU time of this thread, one BLAS
thread).  Both implementations' results are checked to agree to 1e-12 before timing.

Run: ``python benchmarks/bench_start_values.py [--rounds 15] [--cold] [--md docs/performance.md]`` (``--md``
writes the performance page's ``<!-- bench:start_values -->`` block).
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
import timeit
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the numpy reference: tests/
from tests.test_start_kernels import reference

import readme_table
import robocal as rc
from bench_calibrate import problem
from robocal.identify import problem_setup, stages

FIRST_CALL = """
import time
import numpy as np
from robocal.model.catalog import robot
from robocal.identify.stages import initial_frames_and_tools
m, q = robot("ur10"), np.zeros((3, 6))
m.fk(q)  # numba and the chain kernels, loaded by any calibration before its start values
m.evaluate(q, m.values, rows="position")
T, y = np.tile(np.eye(4), (1, 5, 1, 1)), np.random.default_rng(0).normal(size=(1, 5, 3))
T[0, :, :3, 3] = np.random.default_rng(1).normal(size=(5, 3))
t0 = time.perf_counter()
initial_frames_and_tools(T, y)
print(time.perf_counter() - t0)
"""


def per_call(fn, rounds: int) -> float:
    """CPU seconds per call: the minimum over ``rounds`` of the mean of a batch (~20 ms)."""
    fn()
    t0 = time.thread_time()
    fn()
    number = max(1, int(0.02 / max(time.thread_time() - t0, 1e-7)))
    timer = timeit.Timer(fn, timer=time.thread_time)
    return min(timer.repeat(repeat=rounds, number=number)) / number


def first_call(cache_dir: str | None) -> float:
    env = dict(os.environ)
    if cache_dir is not None:
        env["NUMBA_CACHE_DIR"] = cache_dir
    out = subprocess.run(
        [sys.executable, "-c", FIRST_CALL], capture_output=True, text=True, env=env, check=True
    )
    return float(out.stdout.split()[-1])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=15)
    parser.add_argument("--cold", action="store_true", help="also time a compilation from scratch")
    parser.add_argument("--md", metavar="PAGE", help="write the performance page's bench:start_values block")
    args = parser.parse_args()
    if args.md and (why := readme_table.check(args.md, "start_values")):
        parser.error(why)
    load_start = readme_table.load()
    model, data = problem(100, 1)
    T1, y1 = model.fk(data.q)[None], data.position[None]
    rng = np.random.default_rng(0)
    O1 = rc.spatial.rotvec_to_matrix(rng.normal(0.0, 1.0, (1, 100, 3)))
    T50, O50 = np.repeat(T1, 50, axis=0), np.repeat(O1, 50, axis=0)
    y50 = np.repeat(y1, 50, axis=0) + rng.normal(0.0, 1e-4, (50, 100, 3))
    tool = rc.spatial.homogeneous(p=[0.06, -0.04, 0.1])
    cases = {
        "K=1, position": (T1, y1, {"T_tool": tool}),
        "K=1, pose": (T1, y1, {"orientation": O1}),
        "K=50, position": (T50, y50, {"T_tool": tool}),
        "K=50, pose": (T50, y50, {"orientation": O50}),
    }
    title = f"start values, 100 poses (CPU time per call, min of {args.rounds} rounds)"
    print(title)
    print(f"{'case':16s} {'numpy':>10s} {'kernel':>10s} {'speed-up':>9s}")
    table = []
    for name, (T, y, kw) in cases.items():
        new, ref = stages.initial_frames_and_tools(T, y, **kw), reference(T, y, **kw)
        for a, b in zip(new, ref, strict=True):
            np.testing.assert_allclose(a, b, rtol=0, atol=1e-12)
        t_ref = per_call(lambda T=T, y=y, kw=kw: reference(T, y, **kw), args.rounds)
        t_new = per_call(lambda T=T, y=y, kw=kw: stages.initial_frames_and_tools(T, y, **kw), args.rounds)
        print(f"{name:16s} {t_ref * 1e6:8.1f}µs {t_new * 1e6:8.1f}µs {t_ref / t_new:8.1f}x")
        table.append([name, f"{t_ref * 1e6:.1f} µs", f"{t_new * 1e6:.1f} µs", f"{t_ref / t_new:.1f}×"])

    def calibrate() -> None:
        rc.calibrate(model, data)

    times: dict[str, list[float]] = {"numpy": [], "kernel": []}
    compiled = problem_setup.initial_frames_and_tools
    try:
        for _ in range(3):  # interleaved
            for label, fn in (("numpy", reference), ("kernel", compiled)):
                problem_setup.initial_frames_and_tools = fn
                times[label].append(per_call(calibrate, max(3, args.rounds // 3)))
    finally:
        problem_setup.initial_frames_and_tools = compiled
    a, b = min(times["numpy"]), min(times["kernel"])
    lines = [
        f"`rc.calibrate` (the `bench_calibrate` problem): with the numpy start values {a * 1e3:.3f} ms, "
        f"with the kernel {b * 1e3:.3f} ms (saved {(a - b) * 1e6:.0f} µs, {a / b:.3f}×).",
        f"First call in a new process (kernel from numba's cache): {first_call(None) * 1e3:.0f} ms wall.",
    ]
    if args.cold:
        with tempfile.TemporaryDirectory() as cache:
            lines.append(f"First call, compiling the kernel from scratch: {first_call(cache):.1f} s wall.")
    print(*lines, sep="\n")
    if args.md:
        command = f"python benchmarks/bench_start_values.py --rounds {args.rounds}"
        command += " --cold --md docs/performance.md" if args.cold else " --md docs/performance.md"
        body = [
            f"`{command}` — {title}:",
            "", *readme_table.markdown_table(["case", "numpy", "kernel", "speed-up"], table), "",
            " ".join(lines), "", readme_table.machine(load_start),
        ]  # fmt: skip
        readme_table.write_block(args.md, "start_values", "\n".join(body))


if __name__ == "__main__":
    main()
