"""Throughput of complete calibrations: simulate + calibrate + validate, per second.

The problem (a Monte Carlo study, :mod:`robocal.study`): virtual UR10s (6R) with uniform
errors of ±0.5 mm / ±0.05° on every free parameter, a laser tracker (20 µm) measuring a
reflector 109 mm from the flange at 50 random poses, each robot calibrated (device frame
and tool point fitted) and validated on 200 held-out poses.  Two models:

* ``built``: the complete, minimal model robocal builds from the UR10's joint geometry
  (examples/geometry/ur10.yaml, seed 000), the model of examples/study_ur10.yaml;
* ``dh``: the catalog's plain DH UR10, whose wrist parameters θ5/α5 50 random poses
  leave poorly identifiable: both engines screen them out before the first fit (their
  linearised σ is far beyond the pruning threshold), so it costs about what ``built``
  costs.

Rows (same machine, same run, interleaved rounds, the best of ``--rounds``):

* ``rc.calibrate``: one ``rc.calibrate`` + ``rc.validate`` per robot, this process
  (the study's ``engine: calibrate``);
* ``batched``: the study's batched engine, this process (``workers=0``);
* ``Dask 1 worker`` / ``Dask 2 workers``: the batched engine on a Dask LocalCluster (one
  single-threaded process per worker); the time is from the first task submitted to the
  last row written, the cluster's start-up is reported apart.

``--malloc`` adds a Dask row with Dask's default worker environment
(``MALLOC_TRIM_THRESHOLD_=65536``, glibc's mmap threshold then frozen at 128 KiB) instead
of robocal's (16 MiB mmap threshold, 64 MiB trim threshold), to show why study.py sets it.

Why two workers were once no faster than one (0.8–1.3x), and what changed: the first task
on each worker paid ~0.25 s of one-off loading (numba's cached kernels, the chain's plans) —
twice a whole later task of 50 robots — inside the timed window; the workers now import the
kernels at warm-up and calibrate one robot before the clock starts (reported as start-up).
Each worker also holds its next task while computing one (``worker-saturation`` 2; the
default hands a single-threaded worker its next task only after a scheduler round trip).
The study's prepared model (23 KB pickled) and BLAS threads (one per worker) were not it.
What kept two workers at 1.74–1.78x after that: the main process (client and scheduler)
took ~7 % of the two cores and Dask's housekeeping woke every process (the event-loop
watchdog every 20 ms, the system monitor every 500 ms, the memory monitor every 100 ms);
robocal's local cluster now runs them every 0.5–2 s and turns work stealing off (equal
tasks), and the tasks format their own CSV rows: the workers' CPU per robot fell ~4 %,
the main process's by a third, 1.76x -> 1.85x for 800 robots.  Shrinking the last tasks
(guided scheduling) was tried and cost more than the idle tail it saved.

Run: ``python benchmarks/bench_throughput.py [--robots 400] [--rounds 3] [--model built|dh|both]
[--md docs/performance.md]`` (about two minutes for both models; ``--md`` writes the page's
``<!-- bench:throughput -->`` block).
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # small matrices: threads only add noise
os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import readme_table
from robocal.study import StudyConfig, run_study

ROOT = Path(__file__).resolve().parents[1]


def config(model: str, robots: int, engine: str, seed: int) -> StudyConfig:
    robot = (
        {"geometry": str(ROOT / "examples" / "geometry" / "ur10.yaml")}
        if model == "built"
        else {"robot": "ur10"}
    )
    return StudyConfig.model_validate(
        dict(
            name=f"throughput-{model}",
            robots=robots,
            seed=seed,
            tool=(0.0, 0.0, 109.0),
            pose_sets=[{"name": "random50", "kind": "random", "n": 50}],
            devices=[{"name": "tracker-20um", "kind": "laser-tracker", "noise": "0.02mm"}],
            validation={"n": 200},
            engine=engine,
            chunk=50,
            **robot,
        )
    )


def measure(model: str, robots: int, engine: str, workers: int, seed: int, dask_defaults: bool = False):
    """(calibrations per second, start-up seconds, workers' CPU seconds) of one fresh study.

    Dask rows run on a cluster made here (robocal's :func:`~robocal.study.local_cluster`, or
    with ``dask_defaults`` a LocalCluster with Dask's own worker environment), warmed up by a
    one-robot study first; the workers' CPU time over the measured study says what the
    calibrations cost there (None in this process).
    """
    with tempfile.TemporaryDirectory() as tmp:
        if workers == 0:
            run = run_study(config(model, robots, engine, seed), Path(tmp) / "s", workers=0)
            assert run.errors == 0 and run.computed == robots, (run.errors, run.computed)
            return run.calibrations_per_second, run.startup_seconds, None
        from distributed import Client

        t0 = time.perf_counter()
        with _cluster(workers, dask_defaults) as cluster, Client(cluster) as client:
            run_study(config(model, 1, engine, seed + 1), Path(tmp) / "warm", client=client)
            startup = time.perf_counter() - t0
            cpu0 = sum(client.run(time.process_time).values())
            run = run_study(config(model, robots, engine, seed), Path(tmp) / "s", client=client)
            cpu = sum(client.run(time.process_time).values()) - cpu0
    assert run.errors == 0 and run.computed == robots, (run.errors, run.computed)
    return run.calibrations_per_second, startup, cpu


def _cluster(workers: int, dask_defaults: bool):
    """robocal's local cluster, or one with Dask's default worker environment."""
    if not dask_defaults:
        from robocal.study import local_cluster

        return local_cluster(workers)
    import logging

    from distributed import LocalCluster

    for name in ("MALLOC_MMAP_THRESHOLD_", "MALLOC_TRIM_THRESHOLD_"):
        os.environ.pop(name, None)
    return LocalCluster(
        n_workers=workers, threads_per_worker=1, dashboard_address=None, silence_logs=logging.CRITICAL
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument(
        "--robots", type=int, default=400, help="virtual robots per measurement (Dask rows: 2x)"
    )
    parser.add_argument("--rounds", type=int, default=3, help="interleaved rounds; the best is reported")
    parser.add_argument("--model", choices=["built", "dh", "both"], default="both")
    parser.add_argument("--malloc", action="store_true", help="also Dask with its default malloc settings")
    parser.add_argument("--md", metavar="PAGE", help="write the performance page's bench:throughput block")
    args = parser.parse_args()
    if args.md and (why := readme_table.check(args.md, "throughput")):
        parser.error(why)
    load_start = readme_table.load()

    import dask
    import distributed
    import scipy

    print(
        f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores, Python "
        f"{platform.python_version()}, numpy {np.__version__}, scipy {scipy.__version__}, dask "
        f"{dask.__version__}, distributed {distributed.__version__}; load average at start "
        f"{' '.join(f'{v:.2f}' for v in os.getloadavg())}"
    )
    models = ["built", "dh"] if args.model == "both" else [args.model]
    table: dict[str, dict[str, float]] = {}
    scaling: dict[str, float] = {}
    cost: dict[tuple[str, str], tuple[float, float]] = {}
    rows = [
        ("rc.calibrate, this process", "calibrate", 0, max(args.robots // 4, 20)),
        ("batched, this process", "batched", 0, args.robots),
        ("batched, Dask 1 worker", "batched", 1, 2 * args.robots),
        ("batched, Dask 2 workers", "batched", 2, 2 * args.robots),
    ]
    for model in models:
        best: dict[str, float] = {}
        startup: dict[str, float] = {}
        for r in range(args.rounds):
            for label, engine, workers, robots in rows:
                rate, start, cpu = measure(model, robots, engine, workers, seed=1000 * r + 7)
                if rate > best.get(label, 0.0):
                    best[label], startup[label] = rate, start
                    if cpu is not None:  # the workers' CPU ms per robot and their busy share of the wall time
                        cost[(model, label)] = (cpu / robots * 1e3, cpu / (workers * robots / rate))
                print(f"  [{model} round {r + 1}] {label}: {rate:.1f}/s", file=sys.stderr, flush=True)
            if args.malloc:
                label = "batched, Dask 1 worker, Dask's default malloc"
                rate, start, _ = measure(
                    model, 2 * args.robots, "batched", 1, seed=1000 * r + 7, dask_defaults=True
                )
                best[label] = max(best.get(label, 0.0), rate)
                startup[label] = start
        base = best["rc.calibrate, this process"]
        one = best["batched, this process"]
        print(
            f"\n{model} UR10, 50 poses, 200 validation poses: complete calibrations per second "
            f"(best of {args.rounds})"
        )
        print(f"{'':44s} {'cal/s':>8s} {'per core':>9s} {'vs rc.calibrate':>16s} {'start-up s':>11s}")
        for label, rate in best.items():
            workers = 2 if "2 workers" in label else 1
            ms, busy = cost.get((model, label), (float("nan"), float("nan")))
            print(
                f"{label:44s} {rate:8.1f} {rate / workers:9.1f} {rate / base:15.2f}x {startup[label]:11.1f}"
                + (f"   worker CPU {ms:.2f} ms/robot, busy {busy:.0%}" if ms == ms else "")
            )
        d1, d2 = best["batched, Dask 1 worker"], best["batched, Dask 2 workers"]
        print(f"scaling 1 -> 2 workers: {d2 / d1:.2f}x; Dask 1 worker vs this process: {d1 / one:.2f}x")
        table[model], scaling[model] = best, d2 / d1
    print(f"load average at the end {' '.join(f'{v:.2f}' for v in os.getloadavg())}")
    if args.md:
        _write_md(args, table, scaling, cost, load_start)


def _write_md(args, table, scaling, cost, load_start: str) -> None:
    """The performance page's throughput block: calibrations per second per row and model."""
    import dask
    import distributed

    names = {"built": "complete UR10 model", "dh": "catalog DH UR10"}
    models = list(table)
    rows = []
    for label in table[models[0]]:
        cells = []
        for model in models:
            rate = table[model][label]
            per_core = f" ({rate / 2:.0f} per worker)" if "2 workers" in label else ""
            ms, busy = cost.get((model, label), (None, None))
            extra = "" if ms is None else f"; worker CPU {ms:.2f} ms/robot, busy {busy:.0%}"
            cells.append(f"{rate:.1f}/s{per_core}{extra}")
        rows.append([label, *cells])
    rows.append(["scaling, 2 workers / 1 worker (target ≥ 1.8×)", *(f"{scaling[m]:.2f}×" for m in models)])
    body = [
        f"`python benchmarks/bench_throughput.py --robots {args.robots} --rounds {args.rounds} --model "
        f"{args.model} --md docs/performance.md` (50 poses, 200 validation poses; a complete calibration = "
        f"simulate + calibrate + validate; best of {args.rounds} interleaved rounds; Dask rows "
        f"{2 * args.robots} robots from the first task submitted to the last row written, the "
        "cluster's start-up and warm-up apart; *worker CPU*: the workers' CPU time per robot, *busy*: "
        "their CPU time over workers × wall time — below 100 % the workers waited, for a core "
        "on a loaded machine or for Dask):",
        "",
        *readme_table.markdown_table(["", *(names[m] for m in models)], rows),
        "",
        readme_table.machine(load_start, f"dask {dask.__version__}, distributed {distributed.__version__}"),
    ]
    readme_table.write_block(args.md, "throughput", "\n".join(body))


if __name__ == "__main__":
    main()
