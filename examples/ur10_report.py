"""The HTML report of a real calibration: the UR10 of ../shared/data/ur10_laser_tracker/.

100 random rows (seed 0) calibrate the complete model (seed 000's builder, the
catalog's masses) with joint compliance under gravity; the other 11,811 rows are the
held-out validation.  Writes ``ur10-real/`` (calibration, data) and
``ur10-real/report.html``.

Run: ``python examples/ur10_report.py [--data PATH] [--out DIR]``.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import robocal as rc
from robocal.demo import complete_model
from robocal.evaluate.report import write_report

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


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, default=DATA)
    parser.add_argument("--out", type=Path, default=Path("ur10-real"))
    parser.add_argument("--train-n", type=int, default=100)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)
    t = time.perf_counter()
    data = read_or_exit(parser, args.data)
    split = data.with_split(args.train_n, seed=args.seed)
    train, test = split.split_rows("train"), split.split_rows("test")
    model = complete_model("ur10", "position")
    result = rc.calibrate(model, train, tool_guess=[0, 0, 0.109], compliance=True)
    stats = rc.validate(result, test)
    result = result.with_records(data_file=str(args.data), train_n=train.n, seed=args.seed)
    result = result.with_validation(stats.to_dict()).save(args.out)
    path = write_report(
        result,
        args.out / "report.html",
        data=train,
        test_data=test,
        title="UR10 and laser tracker: real data",
    )
    print(f"{train.n} calibration poses, {test.n} held-out: {stats}")
    print(f"wrote {path} ({path.stat().st_size / 1e6:.1f} MB) in {time.perf_counter() - t:.1f} s")


if __name__ == "__main__":
    main()
