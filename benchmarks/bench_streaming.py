"""Calibration at scale: streaming normal equations (robocal.identify.streaming) from 1,000 to
1,000,000 poses, time per pose and peak memory, against the dense calibration in the same run.

Each size runs in its own process under ``/usr/bin/time -v`` (peak resident set size of the
whole process: Python, numpy, numba, the data and the fit).  The problem: the UR10's complete
calibration model, errors of ±1 mm / ±0.05°, a laser tracker frame and a probe offset to
identify, 20 µm noise; poses uniform in the joint limits.  Streaming: ``rc.calibrate`` on a
2,000-pose subsample (the identifiable set, the device frame, the tool and the start values),
then :func:`robocal.identify.streaming.refit` on all poses in chunks of 20,000.  Dense: one
``rc.calibrate`` on all poses (the reference, up to ``--dense-max`` poses).

Run: ``python benchmarks/bench_streaming.py [--sizes 1000,10000,100000,1000000] [--dense-max 100000]``.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
import time

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

SUBSAMPLE = 2000
PROBE = (0.0, 0.0, 0.1)


def make_data(n: int, seed: int = 1):
    """Joint values and simulated tracker positions of ``n`` poses, generated in chunks."""
    import numpy as np

    import robocal as rc

    model = rc.calibration_model("ur10")
    true = rc.measure.draw_true_model(model, length=1e-3, angle=np.radians(0.05), seed=seed)
    T_device_base = rc.spatial.homogeneous(rc.spatial.rotvec_to_matrix([0.1, -0.2, 2.0]), [2.0, -1.0, 0.3])
    rng = np.random.default_rng(seed + 1)
    lim = np.clip(model.joint_limits, -np.pi, np.pi)
    q = rng.uniform(lim[:, 0], lim[:, 1], (n, model.dof))
    position = np.empty((n, 3))
    for lo in range(0, n, 50_000):
        T = true.fk(q[lo : lo + 50_000])
        p_base = T[:, :3, :3] @ np.array(PROBE) + T[:, :3, 3]
        position[lo : lo + 50_000] = p_base @ T_device_base[:3, :3].T + T_device_base[:3, 3]
    position += rng.normal(0.0, 20e-6, position.shape)
    return model, q, position


def run(n: int, mode: str) -> dict:
    """One size in this process: data, then the streaming or the dense calibration."""
    import robocal as rc
    from robocal.identify.streaming import refit
    from robocal.measure.measurements import Measurements

    model, q, position = make_data(n)
    t0 = time.perf_counter()
    if mode == "dense":
        result = rc.calibrate(model, Measurements(q=q, position=position), tool_guess=list(PROBE))
        seconds = time.perf_counter() - t0
        return {
            "n": n,
            "mode": mode,
            "seconds": seconds,
            "rms_um": result.rms_after * 1e6,
            "p": len(result.names),
        }
    k = min(n, SUBSAMPLE)
    sub = Measurements(q=q[:k], position=position[:k])
    start = rc.calibrate(model, sub, tool_guess=list(PROBE))
    t1 = time.perf_counter()
    fit = refit(start, q, position)
    t2 = time.perf_counter()
    return {
        "n": n,
        "mode": mode,
        "seconds": t2 - t0,
        "subsample_seconds": t1 - t0,
        "refit_seconds": t2 - t1,
        "rms_um": fit.rms_after * 1e6,
        "p": len(fit.names),
        "evaluations": fit.evaluations,
        "success": fit.success,
    }


def measure(n: int, mode: str) -> dict:
    """:func:`run` in a child process under ``/usr/bin/time -v``."""
    cmd = ["/usr/bin/time", "-v", sys.executable, __file__, "--child", str(n), "--mode", mode]
    out = subprocess.run(cmd, capture_output=True, text=True, check=True)
    row = json.loads(out.stdout.strip().splitlines()[-1])
    rss = re.search(r"Maximum resident set size \(kbytes\): (\d+)", out.stderr)
    row["peak_rss_mb"] = int(rss.group(1)) / 1024 if rss else float("nan")
    cpu = [float(m) for m in re.findall(r"(?:User|System) time \(seconds\): ([\d.]+)", out.stderr)]
    row["process_cpu_seconds"] = sum(cpu)  # the whole child: imports, data generation and the fit
    return row


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", default="1000,10000,100000,1000000")
    parser.add_argument("--dense-max", type=int, default=100_000)
    parser.add_argument("--child", type=int, help=argparse.SUPPRESS)
    parser.add_argument("--mode", default="streaming", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        print(json.dumps(run(args.child, args.mode)))
        return
    measure(1000, "streaming")  # compile or load the kernels once (numba's cache) before timing
    rows = []
    for n in (int(s) for s in args.sizes.split(",")):
        modes = ["streaming"] + (["dense"] if n <= args.dense_max else [])
        for mode in modes:
            row = measure(n, mode)
            rows.append(row)
            per_pose = row["seconds"] / n * 1e6
            extra = (
                f"  (subsample {row['subsample_seconds']:.2f} s + refit {row['refit_seconds']:.2f} s, "
                f"{row['evaluations']} passes)"
                if mode == "streaming"
                else ""
            )
            print(
                f"{n:>9,} poses  {mode:<9}  {row['seconds']:7.2f} s  {per_pose:7.2f} µs/pose  "
                f"peak RSS {row['peak_rss_mb']:7.0f} MB  process CPU {row['process_cpu_seconds']:6.2f} s  "
                f"RMS {row['rms_um']:.1f} µm  p={row['p']}{extra}",
                flush=True,
            )
    dense = {r["n"]: r for r in rows if r["mode"] == "dense"}
    for r in rows:
        if r["mode"] == "streaming" and r["n"] in dense:
            d = dense[r["n"]]
            print(
                f"{r['n']:>9,} poses: streaming / dense time {r['seconds'] / d['seconds']:.2f}, "
                f"peak RSS {r['peak_rss_mb'] / d['peak_rss_mb']:.2f}"
            )


if __name__ == "__main__":
    main()
