"""``robocal report`` (the HTML report of a calibration) and ``robocal demo``."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated

import typer

from robocal.cli import options
from robocal.cli.options import (
    AngleUnit,
    Columns,
    Decimal,
    Force,
    Incomplete,
    Json,
    LengthUnit,
    Limits,
    Orientation,
    Sep,
    out_option,
)
from robocal.cli.validate import CALIBRATION_DIR
from robocal.console import console, fail, refuse_overwrite
from robocal.safe_output import strict_json

__all__ = ["register"]


def report_command(
    ctx: typer.Context,
    directory: Annotated[Path, CALIBRATION_DIR],
    out: Annotated[Path, out_option("HTML file to write")] = Path("report.html"),
    data_path: Annotated[
        Path | None,
        typer.Option(
            "--data",
            metavar="FILE",
            help="calibration measurements (default: DIR/train.csv if present, else the calibration's own "
            "file, read with its options and split as calibrated)",
        ),
    ] = None,
    test_path: Annotated[
        Path | None,
        typer.Option(
            "--test-data",
            metavar="FILE",
            help="held-out measurements (default: DIR/test.csv if present, else the held-out rows of the "
            "calibration's own file)",
        ),
    ] = None,
    title: Annotated[str | None, typer.Option("--title", metavar="TEXT", help="the report's heading")] = None,
    length_unit: LengthUnit = "m",
    angle_unit: AngleUnit = "rad",
    columns: Columns = None,
    sep: Sep = None,
    decimal: Decimal = ".",
    orientation: Orientation = "auto",
    limits: Limits = "error",
    incomplete: Incomplete = "error",
    force: Force = False,
    iso9283_log: Annotated[
        Path | None,
        typer.Option(
            "--iso9283",
            metavar="FILE",
            help="add the ISO 9283 characteristics of a measurement log (docs/iso9283.md)",
        ),
    ] = None,
) -> None:
    """Write the self-contained HTML report of a calibration (works offline).

    A constraint calibration (points, planes, distances): its kind's figures on its file and --test-data."""
    refuse_overwrite(out, force, "report")
    from robocal.identify.constraints.result import is_constraint_folder

    values = dict(length_unit=length_unit, angle_unit=angle_unit, columns=columns, sep=sep, decimal=decimal)
    values |= dict(orientation=orientation, limits=limits, incomplete=incomplete)
    if is_constraint_folder(directory):  # fixed points, planes, distances: the kind's own report
        from robocal.cli.report_constraints import constraint_report

        if iso9283_log is not None:
            raise fail("--iso9283: the report of a constraint calibration does not take a measurement log")
        given = _given(ctx, "angle_unit")
        constraint_report(directory, out, data_path, test_path, angle_unit if given else None, title, values)
        return
    from robocal.cli.reading import load_result
    from robocal.evaluate.report import write_report

    result = load_result(directory)
    data, test = _data_sets(ctx, directory, result, data_path, test_path, values)
    evaluation = _evaluation(directory, iso9283_log)
    try:
        with console.status("writing the report ..."):
            path = write_report(result, out, data=data, test_data=test, evaluation=evaluation, title=title)
    except ValueError as err:
        raise fail(str(err)) from None
    console.print(f"wrote {path}", highlight=False)


def _given(ctx: typer.Context, name: str) -> bool:
    """Whether option ``name`` was given on the command line (not its default)."""
    return getattr(ctx.get_parameter_source(name), "name", None) in ("COMMANDLINE", "ENVIRONMENT")


def _data_sets(ctx: typer.Context, directory: Path, result, data_path, test_path, values: dict):
    """The report's calibration and held-out measurements: given with --data/--test-data, else
    DIR/train.csv and DIR/test.csv, else the calibration's own file split as calibrated."""
    from robocal.cli.reading import own_data, read_data
    from robocal.identify.provenance import READER_DEFAULTS

    def read(path: Path | None, default: str):
        if path is None:
            path = directory / default
            return read_data(path, result.model, **READER_DEFAULTS) if path.is_file() else None
        return read_data(path, result.model, **values)

    data = test = None
    if data_path is not None or not (directory / "train.csv").is_file():
        has_provenance = "provenance" in result.metadata
        own = own_data(ctx, directory, result, data_path, values) if has_provenance or data_path else None
        if own is not None:  # the calibration's own file: its calibration rows and its held-out rows
            data, test = own[1].train, own[1].test
        elif data_path is not None:
            data = read(data_path, "")
    else:
        data = read(None, "train.csv")
    if test_path is not None or test is None:
        test = read(test_path, "test.csv")
    return data, test


def _evaluation(directory: Path, iso9283_log: Path | None) -> dict | None:
    """DIR/evaluation.json, with the ISO 9283 characteristics of ``--iso9283`` added."""
    evaluation = None
    ev_path = directory / "evaluation.json"
    if ev_path.is_file():
        try:
            evaluation = json.loads(ev_path.read_text(encoding="utf-8"))
        except (ValueError, RecursionError) as err:  # not JSON, not UTF-8, nested too deeply
            raise fail(f"{ev_path}: not valid JSON: {err or 'nested too deeply'}") from None
        if not isinstance(evaluation, dict):
            raise fail(f"{ev_path}: not a robocal evaluation (a JSON object expected)")
    if iso9283_log is not None:
        from robocal.evaluate.iso9283.log import read_iso9283_log
        from robocal.evaluate.iso9283.report import evaluate_log

        try:  # a bad log is an Iso9283LogError, a ValueError naming file, row and column
            iso = evaluate_log(read_iso9283_log(iso9283_log)).to_dict()
        except ValueError as err:
            raise fail(str(err)) from None
        evaluation = {**(evaluation or {}), "iso9283": iso}
    return evaluation


def demo_command(
    robot: Annotated[
        str, typer.Argument(metavar="ROBOT", help="catalog robot of the virtual twin (robocal robots)")
    ] = "ur10",
    out: Annotated[
        Path | None,
        out_option(
            "directory for the calibration, data and report (default: robocal-demo in your home "
            "directory, never the working directory, which may be a checkout)",
            "DIR",
        ),
    ] = None,
    seed: Annotated[int, options.seed("seeds the whole demo")] = 0,
    n: Annotated[
        int,
        typer.Option("--n", max=10_000, metavar="N", help="calibration poses (O1-optimal; at most 10 000)"),
    ] = 50,
    quick: Annotated[bool, typer.Option("--quick", help="fewer poses and cycles: a faster run")] = False,
    as_json: Json = False,
    force: Force = False,
) -> None:
    """Calibrate a virtual robot end to end and write the report (under a minute)."""
    from robocal.demo import run_demo
    from robocal.model.catalog import robots

    # the options first: a bad one is the error, whatever an earlier demo left in --out
    if robot not in robots():
        raise fail(f"unknown robot {robot!r}; choose one of {', '.join(robots())}")
    if n < 10:
        raise fail(f"--n {n}: a calibration needs at least 10 poses")
    if out is None:
        from robocal.demo.folder import default_folder

        try:  # HOME/robocal-demo; an empty HOME is not the root
            out = default_folder()
        except ValueError as err:
            raise fail(str(err)) from None
    refuse_overwrite(out, force, "demo folder")
    try:
        numbers = run_demo(robot, out, seed=seed, n_calibration=n, quick=quick, verbose=not as_json)
    except ValueError as err:
        raise fail(f"demo on {robot}: {err}") from None
    if as_json:
        print(strict_json(numbers))


def register(app: typer.Typer) -> None:
    """Add ``report`` and ``demo`` to the ``robocal`` app."""
    app.command("report")(report_command)
    app.command("demo")(demo_command)
