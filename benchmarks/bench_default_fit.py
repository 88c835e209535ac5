"""CPU time of the default calibration (``--residual auto``) against the physics fit alone.

``robocal calibrate ur10`` on series A of ``../shared/data/ur10_laser_tracker/`` (the README's
command: mm, tool start 109 mm, 0.03 mm noise, held-out validation on the other rows), as
whole processes: the default (``--residual auto``: the learned residual chosen by 5-fold
cross-validation) and the same command with ``--residual none`` — the reference, measured in
the same run, alternately, ``--repeats`` times each; the figure is the ratio of the median
CPU times (user + system of the child, ``resource.getrusage(RUSAGE_CHILDREN)``).  The first
process of a run only loads the compiled kernels (a cold cache would compile them: that is
compile time, not calibration time, and is left out by a warm-up run).  Held-out mean errors
of both are printed too (the default must not be worse).

Run: ``python benchmarks/bench_default_fit.py [--train-n 300 10000] [--repeats 3]``.
"""

from __future__ import annotations

import argparse
import json
import resource
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT.parent / "shared" / "data" / "ur10_laser_tracker" / "measurements_grid.csv"
COLUMNS = (
    "q1=shoulder_pan_joint,q2=shoulder_lift_joint,q3=elbow_joint,q4=wrist_1_joint,q5=wrist_2_joint,"
    "q6=wrist_3_joint,x=measurement_x,y=measurement_y,z=measurement_z"
)


def command(train_n: int, residual: str, out: Path) -> list[str]:
    """The README's ``robocal calibrate ur10`` of series A on ``train_n`` poses."""
    return [
        sys.executable, "-m", "robocal.cli", "calibrate", "ur10", "--data", str(DATA),
        "--length-unit", "mm", "--sep", ";", "--decimal", ",", "--orientation", "none",
        "--columns", COLUMNS, "--tool", "0,0,109mm", "--noise", "0.03mm",
        "--train-n", str(train_n), "--residual", residual, "--out", str(out), "--force",
    ]  # fmt: skip


def run(train_n: int, residual: str, out: Path) -> tuple[float, float | None]:
    """CPU seconds (user + system) of one whole process, and its held-out mean error (mm)."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    done = subprocess.run(command(train_n, residual, out), capture_output=True, text=True)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if done.returncode != 0:
        raise SystemExit(
            f"robocal calibrate failed ({residual}, {train_n} poses):\n{done.stderr}{done.stdout}"
        )
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    saved = json.loads((out / "result.json").read_text())
    validation = saved.get("validation") or {}
    return cpu, validation.get("mean_mm")


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--train-n", type=int, nargs="+", default=[300, 10000])
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args(argv)
    if not DATA.exists():
        raise SystemExit(f"series A not found at {DATA}")
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp)
        run(100, "none", out / "warm")  # loads (or, on a cold cache, compiles) the kernels
        print(f"{'poses':>6} {'none s':>8} {'auto s':>8} {'ratio':>6} {'none mm':>8} {'auto mm':>8}")
        for n in args.train_n:
            cpu: dict[str, list[float]] = {"none": [], "auto": []}
            mean: dict[str, float | None] = {}
            for _ in range(args.repeats):
                for residual in ("none", "auto"):
                    seconds, mean[residual] = run(n, residual, out / residual)
                    cpu[residual].append(seconds)
            none, auto = statistics.median(cpu["none"]), statistics.median(cpu["auto"])
            held = [f"{v:8.4f}" if v is not None else f"{'-':>8}" for v in (mean["none"], mean["auto"])]
            print(f"{n:6d} {none:8.2f} {auto:8.2f} {auto / none:6.2f} {held[0]} {held[1]}", flush=True)


if __name__ == "__main__":
    main()
