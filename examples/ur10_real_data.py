"""Calibrate the real UR10 of ../shared/data/ur10_laser_tracker/ and validate on held-out poses.

100 random rows (seeded) calibrate, the other 11,811 validate, for five seeds.  Models:

* frames only   — the nominal UR10, only the tracker frame and the probe point fitted;
* plain DH      — every UR DH parameter free (the baseline of the issue: 0.42 mm);
* complete      — the model built from joint geometry (Hayati on the parallel joints 2-4);
* + compliance  — the complete model plus joint compliance under gravity;
* robocal default — cross-validation on the training rows chooses among these physics and
  the learned per-joint angle errors (``residual="auto"``, what the CLI does).

Run: ``python examples/ur10_real_data.py [--data PATH] [--seeds 5]``.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

import robocal as rc

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT.parent / "shared" / "data" / "ur10_laser_tracker" / "measurements_grid.csv"
COLUMNS = (
    "q1=shoulder_pan_joint,q2=shoulder_lift_joint,q3=elbow_joint,q4=wrist_1_joint,"
    "q5=wrist_2_joint,q6=wrist_3_joint,x=measurement_x,y=measurement_y,z=measurement_z"
)


def read_or_exit(parser: argparse.ArgumentParser, path: Path):
    """The series read with its options, or one line naming what is missing (exit 2)."""
    if not path.is_file():
        parser.exit(
            2,
            f"error: {path}: no such file; this example needs the real UR10 series "
            "(ur10_laser_tracker/measurements_grid.csv of ../shared/data beside the clone): "
            "pass --data PATH\n",
        )
    try:
        return rc.read_measurements(
            path, length_unit="mm", decimal=",", sep=";", columns=COLUMNS, orientation="none"
        )
    except (ValueError, OSError) as err:  # the reader's MeasurementFileError is a ValueError
        parser.exit(2, f"error: {err}\n".splitlines()[0] + "\n")


def complete_ur10() -> rc.Model:
    """The UR10's complete calibration model (built from the catalog's joint geometry,
    Hayati on the parallel joints 2-4), with the catalog's masses carried over."""
    return rc.calibration_model("ur10", "position")


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, default=DATA)
    parser.add_argument("--seeds", type=int, default=5)
    parser.add_argument("--train-n", type=int, default=100)
    args = parser.parse_args(argv)
    data = read_or_exit(parser, args.data)
    dh = rc.robot("ur10")
    complete = complete_ur10()
    variants = {
        "frames only": (dh.with_free(None, free=False), {}),
        "plain DH": (dh, {}),
        "complete (built)": (complete, {}),
        "complete + compliance": (complete, {"compliance": True}),
        # what `robocal calibrate ur10` does: CV on the training poses chooses the
        # physics and the learned per-joint angle errors
        "robocal default (CV + learned residual)": (complete, {"residual": "auto"}),
    }
    rows: dict[str, list] = {name: [] for name in variants}
    for seed in range(args.seeds):
        split = data.with_split(args.train_n, seed=seed)
        train, test = split.split_rows("train"), split.split_rows("test")
        for name, (model, options) in variants.items():
            t = time.perf_counter()
            result = rc.calibrate(model, train, tool_guess=[0, 0, 0.109], **options)
            seconds = time.perf_counter() - t
            stats = rc.validate(result, test)
            rows[name].append((stats.mean, stats.rms, stats.p95, stats.max, seconds))
    print(f"UR10, {args.train_n} training poses, {data.n - args.train_n} held-out poses, {args.seeds} seeds")
    print("| model | held-out mean mm | RMS mm | p95 mm | max mm | calibration time |")
    print("|---|---:|---:|---:|---:|---:|")
    for name, r in rows.items():
        r = np.array(r)
        mean, rms, p95, worst, seconds = (r[:, k].mean() for k in range(5))
        print(
            f"| {name} | {mean * 1e3:.3f} (± {r[:, 0].std() * 1e3:.3f}) | {rms * 1e3:.3f} | "
            f"{p95 * 1e3:.3f} | {worst * 1e3:.3f} | {seconds * 1e3:.0f} ms |"
        )


if __name__ == "__main__":
    main()
