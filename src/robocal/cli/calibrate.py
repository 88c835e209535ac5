"""``robocal calibrate ROBOT --data FILE -o DIR``: identify the robot's parameters from
measurements and write the calibrated model (``robocal validate`` is in :mod:`robocal.cli.validate`)."""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Annotated

import typer
from rich.table import Table

from robocal.choices import BoundsName, ChainChoice, ResidualChoice, SolverMethod
from robocal.choices import Loss as LossChoice
from robocal.cli import options
from robocal.cli.options import (
    AngleUnit,
    Columns,
    Decimal,
    Force,
    Incomplete,
    LengthUnit,
    Limits,
    Orientation,
    Robot,
    Sep,
    as_cli_text,
    length_vector,
    measure_option,
    out_option,
    robot_and_chain,
)
from robocal.cli.reading import written_files
from robocal.cli.validate import stats_table, validation_notes
from robocal.console import console, fail, safe

__all__ = ["register"]

CHAIN_HELP = (
    "complete (default for a catalog ROBOT): the complete, minimal, continuous model built from the "
    "robot's joint geometry (rc.calibration_model); catalog: the catalog's chain as published (e.g. plain "
    "DH, singular for parallel axes). A model file's chain is calibrated as it is unless --chain complete"
)
RESIDUAL_HELP = (
    "auto: k-fold cross-validation on the calibration poses chooses the physical model alone, with "
    "joint compliance (when the model has masses) and with learned joint angle errors; joint_fourier: "
    "always the learned residual; none: the physical model only"
)
NOISE_HELP = (
    "the device's position noise, 1σ per axis with a unit (e.g. 0.03mm), for a file without sigma "
    "columns: tests whether the model explains the data down to it"
)
Chain = Annotated[ChainChoice | None, typer.Option("--chain", metavar="complete|catalog", help=CHAIN_HELP)]
Residual = Annotated[
    ResidualChoice, typer.Option("--residual", metavar="auto|joint_fourier|none", help=RESIDUAL_HELP)
]
Tool = Annotated[
    str | None,
    typer.Option(
        "--tool",
        metavar='"x,y,z"',
        help='the measured point (probe) on the flange as built, with a unit, e.g. "0,0,109mm": the '
        "fit's start value, checked against what it identifies",
    ),
]
Compliance = Annotated[bool, typer.Option("--compliance", help="also identify joint compliance")]
Data = Annotated[
    list[Path],
    typer.Option(
        "--data",
        metavar="FILE",
        help="measurement CSV file (repeat: tracker and constraint files in one fit)",
    ),
]


Method = Annotated[
    SolverMethod, typer.Option("--method", metavar="lm|pinv|bounded|influence", help="the solver")
]
PerPose = Annotated[
    bool,
    typer.Option(
        "--per-pose",
        help="with --method pinv: the Katana thesis' (seed 003) per-pose "
        "pseudo-inverse Jᵀ(JJᵀ)⁻¹ at each pose, then the "
        "mean of the per-pose sets (instead of (JᵀJ)⁻¹Jᵀ over all poses)",
    ),
]
Bounds = Annotated[
    BoundsName | None,
    typer.Option(
        "--bounds",
        metavar="default|widened",
        help="with --method bounded: default (Li et al. 2016, seed 001: every robot "
        "parameter within ±5 mm, ±2° of its "
        "nominal) | widened (wider for parameters that absorb redundant ones; warned)",
    ),
]
TrainN = Annotated[
    int | None,
    typer.Option("--train-n", metavar="N", help="calibrate on N random rows, validate on the rest"),
]
Level = Annotated[
    str | None,
    typer.Option(
        "--level",
        metavar="1|2|3",
        help="1 (joint offsets), 2 (kinematic, default) or 3 (non-geometric: with joint effects)",
    ),
]
Effects = Annotated[
    str | None,
    typer.Option(
        "--effects",
        metavar="none|predict|identify|KINDS",
        help="joint effects: none | predict (from the model's joint_effects, the Katana thesis' "
        "(seed 003) two-stage "
        'method) | identify (default of --level 3) | kinds, e.g. "compliance,backlash"; constraint files: '
        "clearance,backlash,compliance on tilt rows, compliance,radial on points, planes, distances",
    ),
]
Loss = Annotated[
    LossChoice,
    typer.Option(
        "--loss",
        metavar="linear|soft_l1|huber|cauchy|arctan",
        help="least squares, or a robust loss that down-weights glitches",
    ),
]
Noise = Annotated[str | None, typer.Option("--noise", metavar="LENGTH", help=NOISE_HELP)]
OutDir = Annotated[Path, out_option("directory for model.yaml and result.json", "DIR")]
Measure = Annotated[
    str | None,
    measure_option("the measured quantities (default: the file's): position|pose|point|plane|distance"),
]
Report = Annotated[bool, typer.Option("--report", help="also write DIR/report.html")]
Distance = Annotated[
    list[str] | None,
    typer.Option(
        "--distance",
        metavar="A,B=LENGTH",
        help="fixed points A and B of a constraint file are LENGTH apart, e.g. 0,1=50mm (repeatable)",
    ),
]


def calibrate_command(
    robot: Robot,
    data_paths: Data,
    out: OutDir,
    chain: Chain = None,
    measure: Measure = None,
    method: Method = "lm",
    per_pose: PerPose = False,
    bounds: Bounds = None,
    train_n: TrainN = None,
    seed: Annotated[int, options.seed("seed of the --train-n draw")] = 0,
    tool: Tool = None,
    compliance: Compliance = False,
    level: Level = None,
    effects: Effects = None,
    length_unit: LengthUnit = "m",
    angle_unit: AngleUnit = "rad",
    columns: Columns = None,
    sep: Sep = None,
    decimal: Decimal = ".",
    orientation: Orientation = "auto",
    limits: Limits = "error",
    incomplete: Incomplete = "error",
    loss: Loss = "linear",
    noise: Noise = None,
    residual: Residual = "auto",
    force: Force = False,
    report: Report = False,
    distance: Distance = None,
) -> None:
    """Identify the robot's parameters from measurements; write the calibrated model.

    A file with a point, plane or pair/distance_mm column (or --measure point|plane|distance)
    holds constraint measurements: fixed points (ball in socket), planes, distances."""
    model, from_catalog = robot_and_chain(robot, chain)
    _check_out(out, force)
    from robocal.cli.constraints import calibrate_constraint_command, is_constraint_file

    data_path = data_paths[0]
    if len(data_paths) > 1 or is_constraint_file(data_path, measure):  # mixed kinds: one fit
        return calibrate_constraint_command(model, from_catalog, chain, data_paths, out,
                                            angle_unit=angle_unit, distances=distance, level=level,
                                            noise=noise, force=force, length_unit=length_unit,
                                            effects=effects)  # fmt: skip
    _check_choices(measure, residual, loss, method, bounds, per_pose)
    tool_guess = None if tool is None else length_vector(tool, 3, "--tool")  # before the data is read
    from robocal.workflow import CalibrateRequest, FitOptions, ReaderOptions

    reader = ReaderOptions(length_unit, angle_unit, columns, sep, decimal, orientation, limits, incomplete)
    fit = FitOptions(method, measure, residual, compliance, level, loss, _effects(effects), bounds, per_pose,
                     None if tool_guess is None else tuple(float(v) for v in tool_guess))  # fmt: skip
    noise_m = _noise(noise)
    request = CalibrateRequest(data_path, model, out, reader, fit, chain, from_catalog, noise_m, train_n,
                               seed, report, force)  # fmt: skip
    run = _run(request, noise, method, residual)
    result, validation = run.result, run.validation
    _print_result(result)
    if validation is not None:
        console.print(stats_table(f"held-out validation ({validation.n} poses)", validation))
        for note in validation_notes(validation, result, frame_note=False)[0]:  # frame: the calibrated one
            console.print(note, highlight=False, markup=True)
    console.print(f"wrote {written_files(out)}", highlight=False, soft_wrap=True)  # a path is not wrapped
    if report:
        console.print(f"report: {out / 'report.html'}", highlight=False)


def _run(request, noise: str | None, method: str, residual: str):
    """:func:`robocal.workflow.calibrate_file` with its stages shown (a spinner while it
    calibrates and while it writes the report) and its refusal as one ``error:`` line naming
    the option or the file."""
    import robocal.workflow as workflow

    what = method + (", choosing the model by cross-validation" if residual != "none" else "")
    with _Stages(what) as stages:
        try:
            return workflow.calibrate_file(
                dataclasses.replace(request, progress=stages.enter, notify=_notify)
            )
        except workflow.CalibrateFileError as err:
            raise fail(_cli_message(err, request.out, request.train_n, noise)) from None


class _Stages:
    """The CLI's view of the stages: the kernels' first-use note and a spinner while calibrating,
    a spinner while writing the report."""

    def __init__(self, what: str) -> None:
        from contextlib import ExitStack

        self.what = what
        self.stack = ExitStack()
        self.stage: str | None = None

    def enter(self, stage: str, fraction: float) -> None:
        from robocal.identify.kernel_cache import first_use

        if stage == self.stage:  # the engine's progress within the stage: the same note and spinner
            return
        self.stage = stage
        self.stack.close()
        if stage == "calibrate":
            self.stack.enter_context(first_use(console))
            self.stack.enter_context(console.status(f"calibrating ({self.what}) ..."))
        elif stage == "report":
            self.stack.enter_context(console.status("writing the report ..."))

    def __enter__(self) -> _Stages:
        return self

    def __exit__(self, *exc: object) -> None:
        self.stack.close()


def _notify(kind: str, text: str) -> None:
    """A line of the use case as the command line prints it."""
    from robocal.console import err_console, warn

    if kind == "warning":
        warn(as_cli_text(text))
    elif kind == "dropped":
        err_console.print(f"{text} (--incomplete drop)", highlight=False)
    else:
        console.print(text, highlight=False)


def _cli_message(err, out: Path | None, train_n: int | None, noise: str | None) -> str:
    """A refusal of the use case in the command line's words (its options)."""
    if err.field == "noise_m" and noise is not None and "sigma columns" not in err.problem:
        return f"--noise {noise}: {err.problem}"
    if err.field == "noise_m":
        return f"--noise: {err.problem}"
    if err.field == "train_n":
        return f"--train-n {train_n}: {err.problem}"
    if err.field == "out" and "already holds" in err.problem:
        return f"{out} already holds a calibration result; use --force to overwrite it"
    if err.field == "out" and "is a file" in err.problem:
        return f"--out {out} is a file; give a directory for model.yaml and result.json"
    return as_cli_text(str(err))


def _noise(noise: str | None) -> float | None:
    """``--noise`` in m (None without it), its range checked."""
    if noise is None:
        return None
    from robocal.measure.true_model import parse_quantity_option
    from robocal.workflow import CalibrateFileError, check_noise

    try:
        sigma = float(parse_quantity_option(noise, "length", "--noise"))
        check_noise(sigma)
    except CalibrateFileError as err:
        raise fail(f"--noise {noise}: {err.problem}") from None
    except ValueError as err:
        raise fail(str(err)) from None
    return sigma


def _check_out(out: Path, force: bool) -> None:
    """Refuse an output that is a file, holds a result (without --force) or is being written:
    before the constraint files' path too, and before the data is read."""
    from robocal.workflow import CalibrateFileError, check_out

    try:
        check_out(out, force)
    except CalibrateFileError as err:
        raise fail(_cli_message(err, out, None, None)) from None


def _check_choices(measure, residual, loss, method, bounds, per_pose) -> None:
    """One line naming the option for a value it does not take, or a combination that does not go."""
    if measure not in (None, "position", "pose"):
        raise fail(f"--measure {measure!r}: position or pose")
    # --residual, --method, --loss and --bounds are choices of robocal.choices: Typer refuses the rest
    if loss != "linear" and method != "lm":
        raise fail(f"--loss {loss} needs --method lm")
    if bounds is not None and method != "bounded":
        raise fail(f"--bounds {bounds} needs --method bounded")
    if per_pose and method != "pinv":
        raise fail("--per-pose needs --method pinv")


def _effects(effects: str | None):
    """``--effects``: a mode, or the list of effect kinds."""
    if effects is None or effects in ("none", "predict", "identify"):
        return effects
    return tuple(k.strip() for k in effects.split(",") if k.strip())


def _print_result(result) -> None:
    head = "converged" if result.success else "[red]NOT CONVERGED[/]"
    console.print(
        f"[bold]{safe(result.model.name)}[/] — {safe(result.method)}, {safe(result.measure)} measurements, "
        f"{result.n} poses: {head} ({result.iterations} iterations, {result.seconds * 1e3:.0f} ms)",
        highlight=False,
        markup=True,
    )
    console.print(
        f"RMS error on the calibration poses {result.rms_before * 1e3:.4f} mm → "
        f"{result.rms_after * 1e3:.4f} mm; condition number {result.condition_number:.3g}",
        highlight=False,
    )
    table = Table(title="identified parameters", title_justify="left")
    for col in ("parameter", "start", "estimate", "delta", "σ", "unit"):
        table.add_column(col, justify="left" if col in ("parameter", "unit") else "right")
    from robocal.identify.effects import display_unit, effect_lines

    rot = {s.name: s.is_rotation for s in (result.measurement_chain or result.model).steps}
    for n, v0, v, s in zip(result.names, result.nominal, result.estimates, result.std, strict=True):
        f, unit = display_unit(n, rot.get(n, False))
        table.add_row(n, f"{v0 * f:.5f}", f"{v * f:.5f}", f"{(v - v0) * f:+.5f}", f"{s * f:.5f}", unit)
    console.print(table)
    effects = result.effect_estimates()
    if effects:
        mode = result.diagnostics.effects
        console.print(f"joint effects ({mode}; ± 1σ where identified):", highlight=False)
        for line in effect_lines(effects):
            console.print(f"  {line}", highlight=False)
    for d in result.dropped:
        console.print(f"  [dim]not identified:[/] {safe(d)}", highlight=False, markup=True)
    for a, b, rho in result.high_correlations:
        console.print(
            f"  [yellow]warning:[/] {safe(a)} and {safe(b)} are correlated ({rho:+.3f})",
            highlight=False,
            markup=True,
        )
    if result.fit_to_noise is not None and result.fit_to_noise.warning() is None:  # else in the warnings
        console.print(result.fit_to_noise.summary(), highlight=False)
    for line in result.residual_lines():
        console.print(line, highlight=False, markup=False)
    for w in result.warning_texts:
        console.print(f"[yellow]warning:[/] {safe(w)}", highlight=False, markup=True)


def register(app: typer.Typer) -> None:
    """Add ``calibrate`` to the ``robocal`` app."""
    app.command("calibrate")(calibrate_command)
