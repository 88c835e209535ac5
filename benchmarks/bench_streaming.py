"""Calibration at scale through the default API: ``rc.calibrate(model, data)`` at 10,000,
100,000 and 1,000,000 poses (above 50,000 it streams by itself: decisions on a subsample,
the final fit on all poses from normal equations accumulated by chunks,
:mod:`robocal.identify.streaming_calibrate`), time and peak memory beyond the data, as ratios
against the dense physics-only fit of 10,000 poses measured in the same run.

Each size runs in its own process under ``/usr/bin/time -v`` (peak resident set size of the
whole process: Python, numpy, numba, the data and the fit); "beyond the data" subtracts the
RSS after the data was generated and the kernels loaded (measured in the child just before
the calibration).  The problem: the UR10's complete calibration model, errors of ±1 mm /
±0.05°, a laser tracker frame and a probe offset to identify, 20 µm noise; poses uniform in
the joint limits.  Variants: ``physics`` (the API's default), ``compliance`` (joint
compliance identified with the geometry) and ``residual`` (``residual="auto"``: the learned
residual's cross-validated choice, ``robocal calibrate``'s default, on a robot whose joints 2
and 3 have smooth angle errors, so that the residual is chosen and refitted on all poses).

Run: ``python benchmarks/bench_streaming.py [--sizes 10000,100000,1000000]
[--variants physics,compliance,residual]``.  The machine's load average is printed with
each row, and the calibration's CPU time beside its wall time (one BLAS thread: on a busy
machine the wall time is the CPU time plus the waits for a core).

``python benchmarks/bench_streaming.py --cli N [--csv FILE]`` instead times the command
line on a CSV file of ``N`` such poses (written once to ``FILE``, default
``/tmp/robocal_bench_N.csv``, by :func:`write_measurements`): ``robocal calibrate ur10
--data FILE --out DIR`` with its default options (the learned residual's cross-validation
included) against reading the same file with ``numpy.loadtxt`` and ``pandas.read_csv`` and
with :func:`read_measurements` alone, each in its own process under ``/usr/bin/time -v``
(wall time, CPU time, peak RSS of the whole process).
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

PROBE = (0.0, 0.0, 0.1)


def make_data(n: int, seed: int = 1, angle_errors: bool = False):
    """Joint values and simulated tracker positions of ``n`` poses, generated in chunks;
    ``angle_errors``: the true robot's joints 2 and 3 also have smooth angle errors (0.3 and
    0.2 mrad, 2 and 3 per revolution: what the learned residual models)."""
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
        qs = q[lo : lo + 50_000]
        pert = None
        if angle_errors:
            pert = np.zeros((len(qs), model.dof, 3))
            pert[:, 1, 2] = 3e-4 * np.sin(2 * qs[:, 1] + 0.3)
            pert[:, 2, 2] = 2e-4 * np.cos(3 * qs[:, 2])
        T = true.fk(qs, pert)
        p_base = T[:, :3, :3] @ np.array(PROBE) + T[:, :3, 3]
        position[lo : lo + 50_000] = p_base @ T_device_base[:3, :3].T + T_device_base[:3, 3]
    position += rng.normal(0.0, 20e-6, position.shape)
    return model, q, position


def _rss_mb() -> float:
    """The current resident set size of this process (MB)."""
    with open("/proc/self/status") as f:
        line = next(x for x in f if x.startswith("VmRSS:"))
    return int(line.split()[1]) / 1024


VARIANTS = {"physics": {}, "compliance": {"compliance": True}, "residual": {"residual": "auto"}}


def run(n: int, variant: str) -> dict:
    """One size in this process: data, then ``rc.calibrate`` (default API, ``variant``'s options)."""
    import numpy as np

    import robocal as rc
    from robocal.measure.measurements import Measurements

    model, q, position = make_data(n, angle_errors=variant == "residual")
    data = Measurements(q=q, position=position)
    warm = data.subset(np.arange(300))  # numba kernels loaded from the cache before the clock starts
    rc.calibrate(model, warm, tool_guess=list(PROBE), **VARIANTS[variant])
    rss_data = _rss_mb()
    t0, c0 = time.perf_counter(), time.process_time()
    result = rc.calibrate(model, data, tool_guess=list(PROBE), **VARIANTS[variant])
    seconds, cpu = time.perf_counter() - t0, time.process_time() - c0
    streaming = result.diagnostics.streaming or {}
    return {
        "n": n,
        "variant": variant,
        "seconds": seconds,
        "cpu_seconds": cpu,
        "rss_before_fit_mb": rss_data,
        "data_mb": (q.nbytes + position.nbytes) / 2**20,
        "rms_um": result.rms_after * 1e6,
        "p": len(result.names),
        "streamed": bool(streaming),
        "subsample_seconds": streaming.get("subsample_seconds", float("nan")),
        "passes": streaming.get("passes", 0),
        "residual": result.model.residual is not None,
    }


def measure(n: int, variant: str) -> dict:
    """:func:`run` in a child process under ``/usr/bin/time -v``."""
    cmd = ["/usr/bin/time", "-v", sys.executable, __file__, "--child", str(n), "--variant", variant]
    out = subprocess.run(cmd, capture_output=True, text=True, check=True)
    row = json.loads(out.stdout.strip().splitlines()[-1])
    rss = re.search(r"Maximum resident set size \(kbytes\): (\d+)", out.stderr)
    row["peak_rss_mb"] = int(rss.group(1)) / 1024 if rss else float("nan")
    # beyond the data: the peak minus what the process held with its data, before the fit
    row["beyond_data_mb"] = row["peak_rss_mb"] - row["rss_before_fit_mb"] + row["data_mb"]
    row["load"] = os.getloadavg()[0]
    return row


#: The reading references of ``--cli``: Python run in a child process on the CSV file.
READERS = {
    "numpy.loadtxt": "import numpy as np; np.loadtxt(PATH, delimiter=',', comments='#', skiprows=2)",
    "pandas.read_csv": "import pandas as pd; pd.read_csv(PATH, comment='#').to_numpy()",
    "read_measurements": "from robocal.measure.dataset.read import read_measurements as r; r(PATH)",
}


def _timed(cmd: list[str]) -> dict:
    """``cmd`` under ``/usr/bin/time -v``: wall and CPU seconds, peak RSS (MB), the load."""
    out = subprocess.run(["/usr/bin/time", "-v", *cmd], capture_output=True, text=True, check=True)

    def field(name: str) -> float:
        found = re.search(name + r": ([\d.:]+)", out.stderr)
        return float(found.group(1)) if found else float("nan")

    wall = re.search(r"Elapsed \(wall clock\) time \(h:mm:ss or m:ss\): (\d+):([\d.]+)", out.stderr)
    return {
        "wall_seconds": int(wall.group(1)) * 60 + float(wall.group(2)) if wall else float("nan"),
        "cpu_seconds": field(r"User time \(seconds\)") + field(r"System time \(seconds\)"),
        "peak_rss_mb": field(r"Maximum resident set size \(kbytes\)") / 1024,
        "load": os.getloadavg()[0],
    }


def cli_case(n: int, csv_path: str | None) -> None:
    """``robocal calibrate`` on a CSV file of ``n`` poses against reading it (``--cli``)."""
    import shutil
    import tempfile
    from pathlib import Path

    path = Path(csv_path or f"{tempfile.gettempdir()}/robocal_bench_{n}.csv")
    if not path.exists():
        from robocal.measure.dataset.read import write_measurements
        from robocal.measure.measurements import Measurements

        _, q, position = make_data(n)
        write_measurements(Measurements(q=q, position=position), path)
        del q, position
    robocal = shutil.which("robocal") or "robocal"
    print(f"{path}: {path.stat().st_size / 2**20:.0f} MB, {n:,} poses", flush=True)
    out = Path(tempfile.mkdtemp(prefix="robocal_bench_cli_"))
    calibrate = [robocal, "calibrate", "ur10", "--data", str(path), "--out"]
    _timed([*calibrate, str(out / "warm")])  # the numba kernels compiled or loaded once
    rows = {name: _timed([sys.executable, "-c", code.replace("PATH", repr(str(path)))])
            for name, code in READERS.items()}  # fmt: skip
    rows["robocal calibrate"] = _timed([*calibrate, str(out / "run")])
    shutil.rmtree(out, ignore_errors=True)
    data_mb = n * 9 * 8 / 2**20
    for name, row in rows.items():
        print(
            f"{name:<18} wall {row['wall_seconds']:6.2f} s  CPU {row['cpu_seconds']:6.2f} s  "
            f"peak RSS {row['peak_rss_mb']:6.0f} MB (the arrays {data_mb:.0f} MB)  load {row['load']:.1f}",
            flush=True,
        )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", default="10000,100000,1000000")
    parser.add_argument("--variants", default="physics,compliance,residual")
    parser.add_argument("--cli", type=int, help="time robocal calibrate on a CSV file of this many poses")
    parser.add_argument("--csv", help="the CSV file of --cli (written when missing)")
    parser.add_argument("--child", type=int, help=argparse.SUPPRESS)
    parser.add_argument("--variant", default="physics", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        print(json.dumps(run(args.child, args.variant)))
        return
    if args.cli:
        cli_case(args.cli, args.csv)
        return
    measure(1000, "residual")  # compile or load the kernels once (numba's cache) before timing
    reference = measure(10_000, "physics")  # the dense physics-only fit of 10,000 poses
    print(
        f"reference: dense physics-only, 10,000 poses: {reference['seconds']:.2f} s, "
        f"{reference['beyond_data_mb']:.0f} MB beyond the data (load {reference['load']:.1f})",
        flush=True,
    )
    for variant in args.variants.split(","):
        for n in (int(s) for s in args.sizes.split(",")):
            row = reference if (n, variant) == (10_000, "physics") else measure(n, variant)
            print(
                f"{variant:<10} {n:>9,} poses  {'streamed' if row['streamed'] else 'dense   '}  "
                f"{row['seconds']:6.2f} s ({row['seconds'] / reference['seconds']:5.2f}x, "
                f"CPU {row['cpu_seconds']:.2f} s)  "
                f"beyond data {row['beyond_data_mb']:6.0f} MB "
                f"({row['beyond_data_mb'] / reference['beyond_data_mb']:5.2f}x)  peak RSS "
                f"{row['peak_rss_mb']:6.0f} MB  RMS {row['rms_um']:.1f} µm  p={row['p']}  "
                f"residual={row['residual']}  subsample {row['subsample_seconds']:.2f} s  "
                f"passes {row['passes']}  load {row['load']:.1f}",
                flush=True,
            )


if __name__ == "__main__":
    main()
