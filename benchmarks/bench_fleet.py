"""A fleet of virtual robots calibrated through a ``distributed.Client``, with a progress bar.

10,000 virtual UR10s (the complete model built from examples/geometry/ur10.yaml, uniform
errors of ±0.5 mm / ±0.05°), each simulated on 50 random poses with a 20 µm laser tracker,
calibrated by the batched engine and validated on 200 held-out poses: the study of
``bench_throughput.py`` at fleet size, run by :func:`robocal.study.run_study` on a Dask
cluster this script connects to (``--scheduler tcp://host:8786``) or starts
(``--workers N`` single-threaded worker processes on this machine).  Prints the rate, the
cluster's start-up and the machine's load average, which on a shared machine says how far
the rate is from what the cores could do.

Run: ``python benchmarks/bench_fleet.py [--robots 10000] [--workers 2 | --scheduler ADDR]``.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_throughput import config
from robocal.study import StudyRun, local_cluster, run_study


def calibrate_fleet(client, robots: int, out: Path, show: bool = True, on_progress=None) -> StudyRun:
    """``robots`` virtual UR10s calibrated on ``client``'s cluster, rows in ``out/results.csv``;
    a rich progress bar on the terminal while it runs (``show``); ``on_progress(done, total)``
    is called with it."""
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn

    cfg = config("built", robots, "batched", seed=2026).model_copy(update={"name": "fleet"})
    columns = (TextColumn("fleet"), BarColumn(), MofNCompleteColumn(), TimeRemainingColumn())
    with Progress(*columns, disable=not show, transient=True) as bar:
        task = bar.add_task("fleet", total=robots)

        def progress(done: int, total: int) -> None:
            bar.update(task, completed=done)
            if on_progress is not None:
                on_progress(done, total)

        return run_study(cfg, out, client=client, progress=progress)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robots", type=int, default=10_000)
    parser.add_argument("--workers", type=int, default=2, help="local worker processes (without --scheduler)")
    parser.add_argument("--scheduler", help="address of a running Dask scheduler, e.g. tcp://host:8786")
    args = parser.parse_args()

    from distributed import Client

    load = " ".join(f"{v:.2f}" for v in os.getloadavg())
    t0 = time.perf_counter()
    if args.scheduler:
        cluster, client = None, Client(args.scheduler, timeout="30s")
    else:
        cluster = local_cluster(args.workers)  # robocal's settings (study.py); any cluster will do
        client = Client(cluster)
    startup = time.perf_counter() - t0
    try:
        with tempfile.TemporaryDirectory() as tmp:
            run = calibrate_fleet(client, args.robots, Path(tmp) / "fleet")
    finally:
        client.close()
        if cluster is not None:
            cluster.close()
    group = run.summary["groups"][0]
    print(
        f"{run.computed} virtual UR10s calibrated on {run.workers} Dask worker(s) in {run.seconds:.1f} s "
        f"({run.calibrations_per_second:.0f}/s; cluster start-up {startup:.1f} s + "
        f"{run.startup_seconds:.1f} s warm-up); ok {group['ok']}, failed {group['failed']}, "
        f"errors {run.errors}; true RMS {group['true_rms_mm']['mean']:.4f} mm (mean)"
    )
    print(f"load average at start {load}, at the end {' '.join(f'{v:.2f}' for v in os.getloadavg())}")


if __name__ == "__main__":
    main()
