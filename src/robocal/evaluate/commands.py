"""``robocal report`` (the HTML report of a calibration) and ``robocal demo``."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated

import typer

from robocal.console import check_input, console, fail, refuse_overwrite
from robocal.model.files import strict_json

__all__ = ["register"]


def report_command(
    directory: Annotated[
        Path, typer.Argument(help="a calibration output directory (result.json, model.yaml)")
    ],
    output: Annotated[Path, typer.Option("-o", "--output", help="HTML file to write")] = Path("report.html"),
    data_path: Annotated[
        Path | None,
        typer.Option("--data", help="calibration measurements (default: DIR/train.csv if present)"),
    ] = None,
    test_path: Annotated[
        Path | None,
        typer.Option("--test-data", help="held-out measurements (default: DIR/test.csv if present)"),
    ] = None,
    title: Annotated[str | None, typer.Option("--title", help="the report's heading")] = None,
    length_unit: Annotated[
        str, typer.Option("--length-unit", help="m | mm | um: positions in the files")
    ] = "m",
    angle_unit: Annotated[
        str, typer.Option("--angle-unit", help="rad | deg: joint angles in the files")
    ] = "rad",
    columns: Annotated[
        str | None, typer.Option("--columns", help='renames, e.g. "q1=shoulder_pan_joint,x=measurement_x"')
    ] = None,
    sep: Annotated[str | None, typer.Option("--sep", help="column separator (default: sniffed)")] = None,
    decimal: Annotated[str, typer.Option("--decimal", help='decimal mark: "." or ","')] = ".",
    orientation: Annotated[
        str, typer.Option("--orientation", help="auto | none | quaternion | rotvec | euler:SEQ[:UNIT]")
    ] = "auto",
    force: Annotated[bool, typer.Option("--force", help="overwrite an existing output")] = False,
) -> None:
    """Write the self-contained HTML report of a calibration (works offline)."""
    if output is not None:
        refuse_overwrite(output, force, "report")
    from robocal.evaluate.report import write_report
    from robocal.identify.calibrate import CalibrationResult
    from robocal.measure.dataset import MeasurementFileError, read_measurements
    from robocal.outdir import restore

    restore(directory)  # a writer killed mid-swap on a system without atomic exchange
    if not (directory / "result.json").is_file():
        raise fail(f"{directory} holds no calibration result (result.json)")
    try:
        result = CalibrationResult.load(directory)
    except (OSError, ValueError, KeyError) as err:
        raise fail(f"{directory}: cannot read the result: {err}") from None

    def read(path: Path | None, default: str):
        if path is None:
            path = directory / default
            if not path.is_file():
                return None
            options = {}
        else:
            check_input(path, "measurement file")
            options = {
                "length_unit": length_unit,
                "angle_unit": angle_unit,
                "columns": columns,
                "sep": sep,
                "decimal": decimal,
                "orientation": orientation,
            }
        try:
            return read_measurements(path, model=result.model, **options)
        except (MeasurementFileError, ValueError) as err:
            raise fail(str(err)) from None

    data = read(data_path, "train.csv")
    test = read(test_path, "test.csv")
    evaluation = None
    ev_path = directory / "evaluation.json"
    if ev_path.is_file():
        try:
            evaluation = json.loads(ev_path.read_text(encoding="utf-8"))
        except (ValueError, RecursionError) as err:  # not JSON, not UTF-8, nested too deeply
            raise fail(f"{ev_path}: not valid JSON: {err or 'nested too deeply'}") from None
        if not isinstance(evaluation, dict):
            raise fail(f"{ev_path}: not a robocal evaluation (a JSON object expected)")
    try:
        with console.status("writing the report ..."):
            path = write_report(result, output, data=data, test_data=test, evaluation=evaluation, title=title)
    except ValueError as err:
        raise fail(str(err)) from None
    console.print(f"wrote {path}", highlight=False)


def demo_command(
    robot: Annotated[str, typer.Option("--robot", help="catalog robot of the virtual twin")] = "ur10",
    out: Annotated[Path, typer.Option("--out", help="directory for the calibration, data and report")] = Path(
        "robocal-demo"
    ),
    seed: Annotated[int, typer.Option("--seed", min=0, help="seeds the whole demo")] = 0,
    poses: Annotated[
        int, typer.Option("--poses", max=10_000, help="calibration poses (O1-optimal; at most 10 000)")
    ] = 50,
    quick: Annotated[bool, typer.Option("--quick", help="fewer poses and cycles: a faster run")] = False,
    as_json: Annotated[bool, typer.Option("--json", help="print the numbers as JSON")] = False,
    force: Annotated[bool, typer.Option("--force", help="overwrite an existing output")] = False,
) -> None:
    """Calibrate a virtual robot end to end and write the report (under a minute)."""
    from robocal.demo import run_demo
    from robocal.model.catalog import robots

    # the options first: a bad one is the error, whatever an earlier demo left in --out
    if robot not in robots():
        raise fail(f"unknown robot {robot!r}; choose one of {', '.join(robots())}")
    if poses < 10:
        raise fail(f"--poses {poses}: a calibration needs at least 10 poses")
    if out is not None:
        refuse_overwrite(out, force, "demo folder")
    try:
        numbers = run_demo(robot, out, seed=seed, n_calibration=poses, quick=quick, verbose=not as_json)
    except ValueError as err:
        raise fail(f"demo on {robot}: {err}") from None
    if as_json:
        print(strict_json(numbers))


def register(app: typer.Typer) -> None:
    """Add ``report`` and ``demo`` to the ``robocal`` app."""
    app.command("report")(report_command)
    app.command("demo")(demo_command)
