"""``robocal study`` (Monte Carlo studies) and ``robocal fleet`` (one calibration per file).

Commands:
    robocal study CONFIG.yaml --out DIR [--workers N | --scheduler ADDR] [--robots N] [--force]
        run or resume a study; the last line printed is ``calibrations/s: <number>``
    robocal fleet ROBOT DIR [-o OUT] [--pattern "*.csv"] [read options] [--force]
        calibrate every measurement file of a folder; the last line is ``calibrations/s: <number>``
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn
from rich.table import Table
from rich.text import Text

from robocal.cli.calibrate import Chain, Compliance, Method, Residual, Tool
from robocal.cli.options import (
    AngleUnit,
    Columns,
    Decimal,
    Incomplete,
    Json,
    LengthUnit,
    Limits,
    NoProgress,
    Orientation,
    Robot,
    Scheduler,
    Sep,
    Workers,
    as_cli_text,
    length_vector,
    out_option,
    robot_and_chain,
)
from robocal.console import console, err_console, fail, input_problem, safe
from robocal.safe_output import strict_json

__all__ = ["register"]


def _progress(enabled: bool, what: str):
    if not enabled:
        return None, None
    bar = Progress(
        TextColumn(f"[bold]{safe(what)}[/]"),
        BarColumn(),
        MofNCompleteColumn(),
        TimeRemainingColumn(),
        console=err_console,
        transient=True,
    )
    task = bar.add_task(what, total=None)

    def update(done: int, total: int) -> None:
        bar.update(task, completed=done, total=total)

    return bar, update


def _mm(stats: dict | None, key: str = "mean") -> str:
    return "-" if not stats else f"{stats[key]:.4f}"


def study_command(
    config: Annotated[Path, typer.Argument(metavar="CONFIG", help="study configuration (YAML)")],
    out: Annotated[Path, out_option("study directory (results.csv, summary.json/png)", "DIR")],
    workers: Workers = None,
    scheduler: Scheduler = None,
    robots: Annotated[
        int | None,
        typer.Option("--robots", metavar="N", help="only the first N robots (same seeds as the full study)"),
    ] = None,
    force: Annotated[
        bool, typer.Option("--force", help="--out holds another study: delete its results and start over")
    ] = False,
    as_json: Json = False,
    no_progress: NoProgress = False,
) -> None:
    """Monte Carlo study: virtual robots x pose sets x devices, each simulated, calibrated and
    validated; resumes from OUT/results.csv."""
    from robocal.study import StudyError, load_study_config, run_study

    if not config.is_file():
        problem = input_problem(config, "study file") or f"study file {config}: not a file"
        raise fail(f"study file {problem}" if problem.endswith("does not exist") else problem)
    try:
        cfg = load_study_config(config)
    except StudyError as err:
        raise fail(str(err)) from None
    bar, update = _progress(not no_progress, f"{cfg.name}")
    try:
        if bar is not None:
            bar.start()
        run = run_study(
            cfg, out, workers=workers, scheduler=scheduler, force=force, robots=robots, progress=update
        )
    except StudyError as err:
        raise fail(str(err)) from None
    except OSError as err:
        raise fail(f"{out}: {err}") from None
    finally:
        if bar is not None:
            bar.stop()
    if as_json:
        print(strict_json(run.summary))
    else:
        console.print(_study_table(cfg, run))
    _print_study_end(run)


def _study_table(cfg, run) -> Table:
    """The study's summary: one row per pose set and device."""
    table = Table(
        title=f"{cfg.name}: {run.total} cases (RMS: mean over the robots; true: against the true robot)",
        title_justify="left",
    )
    table.add_column("pose set", no_wrap=True)
    table.add_column("device", no_wrap=True)
    for col in ("ok", "not conv.", "failed", "errors", "true RMS mm", "p95 mm", "val RMS mm"):
        table.add_column(col, justify="right")
    for g in run.summary["groups"]:
        table.add_row(
            g["pose_set"],
            g["device"],
            str(g["ok"]),
            str(g["not_converged"]),
            str(g.get("failed", 0)),  # refused by the calibration's guards (see the message column)
            str(g["errors"]),
            _mm(g.get("true_rms_mm")),
            _mm(g.get("true_rms_mm"), "p95"),
            _mm(g.get("val_rms_mm")),
        )
    return table


def _print_study_end(run) -> None:
    where = f"{run.workers} Dask worker(s)" if run.workers else "this process"
    console.print(
        f"wrote {run.out / 'results.csv'}, {run.out / 'summary.json'} and {run.out / 'summary.png'}; "
        f"{run.computed} computed on {where} (engine {run.engine}) in {run.seconds:.2f} s"
        + (f" + {run.startup_seconds:.1f} s start-up" if run.startup_seconds >= 0.05 else "")
        + (f", {run.resumed} already in the table" if run.resumed else "")
        + (f", [red]{run.errors} error(s)[/] (see the message column)" if run.errors else ""),
        highlight=False,
        markup=True,
    )
    console.print(f"calibrations/s: {run.calibrations_per_second:.1f}", highlight=False)


DirectoryOption = Annotated[
    Path,
    typer.Argument(metavar="DIR", help="folder of measurement files, one per robot", show_default=False),
]
ForceOption = Annotated[
    bool, typer.Option("--force", help="recalibrate every file and replace the previous results")
]


def fleet_command(
    robot: Robot,
    directory: DirectoryOption,
    chain: Chain = None,
    out: Annotated[Path | None, out_option("output folder (default DIR/calibrated)", "DIR")] = None,
    pattern: Annotated[str, typer.Option("--pattern", metavar="GLOB", help="which files of DIR")] = "*.csv",
    method: Method = "lm",
    tool: Tool = None,
    compliance: Compliance = False,
    residual: Residual = "auto",
    length_unit: LengthUnit = "m",
    angle_unit: AngleUnit = "rad",
    columns: Columns = None,
    sep: Sep = None,
    decimal: Decimal = ".",
    orientation: Orientation = "auto",
    limits: Limits = "error",
    incomplete: Incomplete = "error",
    workers: Workers = None,
    scheduler: Scheduler = None,
    force: ForceOption = False,
    no_progress: NoProgress = False,
) -> None:
    """Calibrate every measurement file of a folder (one robot each); resumes from OUT/fleet.csv."""
    from robocal.study import StudyError, run_fleet

    model, from_catalog = robot_and_chain(robot, chain)
    complete = chain == "complete" or (chain is None and from_catalog)
    if complete:
        console.print(
            f"model: the complete model built from {model.name}'s joint geometry (rc.calibration_model; "
            "--chain catalog: the catalog's chain)",
            highlight=False,
        )
    # --residual and --method: choices of robocal.choices (Typer refuses the rest)
    calibrate_options: dict = {"method": method, "compliance": compliance, "residual": residual}
    if tool is not None:
        calibrate_options["tool_guess"] = length_vector(tool, 3, "--tool")
    read_options = dict(length_unit=length_unit, angle_unit=angle_unit, columns=columns, sep=sep)
    read_options |= dict(decimal=decimal, orientation=orientation, limits=limits, incomplete=incomplete)
    bar, update = _progress(not no_progress, "fleet")
    try:
        if bar is not None:
            bar.start()
        run = run_fleet(
            directory,
            model,
            out,
            pattern=pattern,
            read_options=read_options,
            calibrate_options=calibrate_options,
            workers=workers,
            scheduler=scheduler,
            force=force,
            progress=update,
            complete=complete,
        )
    except StudyError as err:
        raise fail(str(err)) from None
    finally:
        if bar is not None:
            bar.stop()
    _print_fleet(run, model, directory)


def _print_fleet(run, model, directory: Path) -> None:
    """The fleet's table, its failures and skipped files, and where it wrote."""
    table = Table(title=f"{model.name} fleet: {directory}", title_justify="left")
    for col in ("file", "status", "poses", "RMS before mm", "RMS after mm", "held-out RMS mm"):
        table.add_column(col, justify="left" if col in ("file", "status") else "right")
    for row in run.rows:
        status = Text(row["status"], "" if row["status"] == "ok" else "red")
        table.add_row(
            row["file"],
            status,
            row["n_poses"] or "-",
            _fmt(row["rms_before_mm"]),
            _fmt(row["rms_after_mm"]),
            _fmt(row["val_rms_mm"]),
        )
    console.print(table)
    for row in run.rows:
        if row["status"] != "ok" and row["message"]:
            err_console.print(
                f"[red]{safe(row['file'])}:[/] {safe(as_cli_text(row['message']))}",
                highlight=False,
                markup=True,
            )
    for name in run.skipped:
        err_console.print(
            f"[yellow]skipped {safe(name)}:[/] changed since its calibration; --force recalibrates it "
            "(and replaces the previous result)",
            highlight=False,
            markup=True,
        )
    console.print(
        f"wrote {run.table} and one folder per calibrated file in {run.out}; {run.calibrated} calibrated, "
        f"{run.errors} failed, {run.resumed} already done, {len(run.skipped)} skipped, "
        f"in {run.seconds:.2f} s",
        highlight=False,
    )
    console.print(f"calibrations/s: {run.calibrations_per_second:.1f}", highlight=False)


def _fmt(text: str) -> str:
    try:
        return f"{float(text):.4f}"
    except ValueError:
        return "-"


def register(app: typer.Typer) -> None:
    """Add ``study`` and ``fleet`` to the ``robocal`` app."""
    app.command("study")(study_command)
    app.command("fleet")(fleet_command)
