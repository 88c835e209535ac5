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

Run: ``python benchmarks/bench_default_fit.py [--train-n 300 10000] [--repeats 3] [--md docs/performance.md]``
(``--md`` writes the table into the performance page's ``<!-- bench:default_fit -->`` block).
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

sys.path.insert(0, str(Path(__file__).resolve().parent))
import readme_table

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


#: issue 35's acceptance: the default's CPU at most this many times the physics alone's
TARGET = {300: 1.5, 10000: 2.0}


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--train-n", type=int, nargs="+", default=[300, 10000])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--md", metavar="PAGE", help="write the bench:default_fit block of PAGE")
    args = parser.parse_args(argv)
    if not DATA.exists():
        raise SystemExit(f"series A not found at {DATA}")
    if args.md and (why := readme_table.check(args.md, "default_fit")):
        raise SystemExit(why)
    load_start = readme_table.load()
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp)
        run(100, "none", out / "warm")  # loads (or, on a cold cache, compiles) the kernels
        print(f"{'poses':>6} {'none s':>8} {'auto s':>8} {'ratio':>6} {'none mm':>8} {'auto mm':>8}")
        for n in args.train_n:
            rows.append(_row(n, args.repeats, out))
            n_, none, auto, ratio, _, held_none, held_auto = rows[-1]
            print(f"{n_} {none} {auto} {ratio[:-1]:>6} {held_none:>8} {held_auto:>8}", flush=True)
    print(f"load average (1 / 5 / 15 min): {load_start} at the start, {readme_table.load()} at the end")
    if args.md:
        header = ["training poses", "`--residual none` CPU s", "default CPU s", "ratio", "target",
                  "held-out mean, none (mm)", "held-out mean, default (mm)"]  # fmt: skip
        body = [
            f"`python benchmarks/bench_default_fit.py --train-n {' '.join(map(str, args.train_n))} "
            f"--repeats {args.repeats} --md docs/performance.md` (whole `robocal calibrate ur10` "
            "processes on series A, median CPU time of the child over the repeats, the two "
            "commands alternating; the rest of the file validates):",
            "",
            *readme_table.markdown_table(header, [[cell.strip() for cell in row] for row in rows]),
            "",
            readme_table.machine(load_start),
        ]
        readme_table.write_block(args.md, "default_fit", "\n".join(body))


def _row(n: int, repeats: int, out: Path) -> list[str]:
    """One table row: the medians of ``repeats`` alternating runs of both commands."""
    cpu: dict[str, list[float]] = {"none": [], "auto": []}
    mean: dict[str, float | None] = {}
    for _ in range(repeats):
        for residual in ("none", "auto"):
            seconds, mean[residual] = run(n, residual, out / residual)
            cpu[residual].append(seconds)
    for residual, runs in cpu.items():  # every run, so that the spread is seen, not only the median
        print(f"  {n} poses --residual {residual}: " + " ".join(f"{s:.2f}" for s in runs), flush=True)
    pairs = " ".join(f"{a / b:.2f}" for a, b in zip(cpu["auto"], cpu["none"], strict=True))
    print(f"  {n} poses ratios of the pairs: {pairs}", flush=True)
    none, auto = statistics.median(cpu["none"]), statistics.median(cpu["auto"])
    held = [f"{v:.4f}" if v is not None else "-" for v in (mean["none"], mean["auto"])]
    target = f"{TARGET[n]:.1f}x" if n in TARGET else "-"
    return [f"{n:6d}", f"{none:8.2f}", f"{auto:8.2f}", f"{auto / none:5.2f}x", target, *held]


if __name__ == "__main__":
    main()
