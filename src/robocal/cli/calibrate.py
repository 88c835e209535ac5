"""``robocal calibrate ROBOT --data FILE -o DIR``: identify the robot's parameters from
measurements and write the calibrated model (``robocal validate`` is in :mod:`robocal.cli.validate`)."""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Annotated

import numpy as np
import typer
from rich.table import Table

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
from robocal.cli.reading import read_data
from robocal.cli.validate import _stats_table, _validation_notes
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
Chain = Annotated[str | None, typer.Option("--chain", metavar="complete|catalog", help=CHAIN_HELP)]
Residual = Annotated[str, typer.Option("--residual", metavar="auto|joint_fourier|none", help=RESIDUAL_HELP)]
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
Data = Annotated[Path, typer.Option("--data", metavar="FILE", help="measurement CSV file")]


Method = Annotated[str, typer.Option("--method", metavar="lm|pinv|bounded|influence", help="the solver")]
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
    str | None,
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
        'method) | identify (default of --level 3) | kinds, e.g. "compliance,backlash"',
    ),
]
Loss = Annotated[
    str,
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
    data_path: Data,
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

    if is_constraint_file(data_path, measure):
        return calibrate_constraint_command(model, from_catalog, chain, data_path, out, angle_unit=angle_unit,
                                            distances=distance, level=level, noise=noise,
                                            force=force)  # fmt: skip
    _check_choices(measure, residual, loss, method, bounds, per_pose)
    tool_guess = None if tool is None else length_vector(tool, 3, "--tool")  # before the data is read
    reader = dict(length_unit=length_unit, angle_unit=angle_unit, columns=columns, sep=sep, decimal=decimal)
    reader |= dict(orientation=orientation, limits=limits, incomplete=incomplete)
    data = read_data(data_path, model, **reader)
    if data.position is None:
        raise fail(
            f"{data_path}: no measured positions (columns x, y, z) to calibrate against; map the file's "
            "columns with e.g. --columns 'x=meas_x,y=meas_y,z=meas_z'"
        )
    data, noise_sigma = _with_noise(data, noise, data_path)
    train, test = _split(data, train_n, seed)
    model = _chain_to_calibrate(model, from_catalog, chain, measure, data)
    settings = dict(method=method, measure=measure, compliance=compliance, level=level, loss=loss)
    settings |= dict(residual=residual, effects=_effects(effects))
    settings |= {"bounds": bounds} if bounds is not None else {}
    settings |= {"per_pose": True} if per_pose else {}
    settings |= {"tool_guess": tool_guess} if tool_guess is not None else {}
    result = _calibrate(model, train, data_path, settings)
    result = _record(result, data_path, reader, noise_sigma, train_n, seed, train)
    validation = None
    if test is not None:
        import robocal as rc

        validation = rc.validate(result, test)
        result = _physics_only_held_out(result.with_validation(validation.to_dict()), test)
    _save(result, out, report, train, test)
    _print_result(result)
    if validation is not None:
        console.print(_stats_table(f"held-out validation ({validation.n} poses)", validation))
        for note in _validation_notes(validation, result, frame_note=False)[0]:  # frame: the calibrated one
            console.print(note, highlight=False, markup=True)
    console.print(f"wrote {out / 'model.yaml'} and {out / 'result.json'}", highlight=False)
    if report:
        console.print(f"report: {out / 'report.html'}", highlight=False)


def _check_out(out: Path, force: bool) -> None:
    """Refuse an output that is a file, holds a result (without --force) or is being written."""
    from robocal.outdir import FolderBusyError, check_not_busy

    if out.exists() and not out.is_dir():
        raise fail(f"--out {out} is a file; give a directory for model.yaml and result.json")
    if (out / "result.json").exists() and not force:
        raise fail(f"{out} already holds a calibration result; use --force to overwrite it")
    try:  # before the work: a second writer learns it at once, not after the calibration
        check_not_busy(out)
    except FolderBusyError as err:
        raise fail(str(err)) from None


def _check_choices(measure, residual, loss, method, bounds, per_pose) -> None:
    """One line naming the option for a value it does not take, or a combination that does not go."""
    from robocal.identify.calibrate import BOUNDS_CHOICES
    from robocal.identify.solvers import METHODS

    if measure not in (None, "position", "pose"):
        raise fail(f"--measure {measure!r}: position or pose")
    if residual not in ("auto", "none", "joint_fourier"):
        raise fail(f"--residual {residual!r}: auto, none or joint_fourier")
    if loss not in ("linear", "soft_l1", "huber", "cauchy", "arctan"):
        raise fail(f"--loss {loss!r}: linear, soft_l1, huber, cauchy or arctan")
    if method not in METHODS:
        raise fail(f"--method {method!r}: {', '.join(METHODS)}")
    if loss != "linear" and method != "lm":
        raise fail(f"--loss {loss} needs --method lm")
    if bounds is not None and bounds not in BOUNDS_CHOICES:
        raise fail(f"--bounds {bounds!r}: {' or '.join(BOUNDS_CHOICES)}")
    if bounds is not None and method != "bounded":
        raise fail(f"--bounds {bounds} needs --method bounded")
    if per_pose and method != "pinv":
        raise fail("--per-pose needs --method pinv")


def _with_noise(data, noise: str | None, data_path: Path):
    """``data`` with the ``--noise`` σ on every row, and that σ in m (None without --noise)."""
    if noise is None:
        return data, None
    from robocal.measure.dataset import MAX_SIGMA, MIN_SIGMA
    from robocal.measure.simulate import parse_quantity_option

    try:
        sigma = parse_quantity_option(noise, "length", "--noise")
    except ValueError as err:
        raise fail(str(err)) from None
    if not MIN_SIGMA <= sigma <= MAX_SIGMA:
        raise fail(
            f"--noise {noise}: a standard deviation between {MIN_SIGMA * 1e3:g} mm and "
            f"{MAX_SIGMA * 1e3:g} mm, e.g. 0.03mm"
        )
    if data.sigma is not None:
        raise fail(f"--noise: {data_path} has its own sigma columns; leave --noise out")
    return dataclasses.replace(data, sigma=np.full((data.n, 3), sigma)), float(sigma)


def _split(data, train_n: int | None, seed: int):
    """The calibration rows and the held-out rows (None): ``--train-n`` random rows, else the
    file's set column, else every row."""
    if train_n is not None:
        if not 0 < train_n < data.n:
            raise fail(f"--train-n {train_n} must be between 1 and {data.n - 1} (the file has {data.n} rows)")
        split = data.with_split(train_n, seed=seed)
        return split.split_rows("train"), split.split_rows("test")
    if data.split is not None and "test" in set(data.split.tolist()):
        return data.split_rows("train"), data.split_rows("test")
    return data, None


def _effects(effects: str | None):
    """``--effects``: a mode, or the list of effect kinds."""
    if effects is None or effects in ("none", "predict", "identify"):
        return effects
    return [k.strip() for k in effects.split(",") if k.strip()]


def _physics_only_held_out(result, test):
    """A hybrid's stored physics-only fit (what a URDF or UR kinematics export carries)
    scored on the same held-out poses, so the export can state both errors."""
    record = result.records.get("physics_only")
    if not isinstance(record, dict) or result.model.residual is None:
        return result
    import robocal as rc
    from robocal.compensate.export import kinematic_part

    physics = rc.validate(kinematic_part(result).calibrated, test)
    held_out = {"held_out_mean_mm": physics.mean * 1e3, "held_out_n": physics.n}
    return result.with_records(physics_only={**record, **held_out})


def _calibrate(model, train, data_path: Path, settings: dict):
    """rc.calibrate with a spinner; the data's problem as one line naming the file."""
    import robocal as rc
    from robocal.identify.kernel_cache import first_use

    what = settings["method"] + (
        ", choosing the model by cross-validation" if settings["residual"] != "none" else ""
    )
    try:
        with first_use(console), console.status(f"calibrating {model.name} on {train.n} poses ({what}) ..."):
            return rc.calibrate(model, train, **settings)
    except ValueError as err:
        message = as_cli_text(str(err))  # the data's problem: name the file unless the message does
        raise fail(message if str(data_path) in message else f"{data_path}: {message}") from None


def _record(result, data_path: Path, reader: dict, noise_sigma, train_n, seed: int, train):
    """The result with its provenance: the data file, its hash, the reader options and the split."""
    from robocal.identify.calibrate import file_hash
    from robocal.identify.provenance import Provenance

    sha256 = file_hash(data_path)
    provenance = Provenance.record(data_path, sha256, reader, noise_sigma, train_n, seed)
    return result.with_provenance(
        provenance, data_file=str(data_path), data_sha256=sha256, train_n=train.n, seed=seed
    )


def _save(result, out: Path, report: bool, train, test) -> None:
    """model.yaml, measurement_model.yaml, result.json (and report.html): all or nothing."""
    from robocal.outdir import FolderBusyError

    def write_report_too(stage_dir: Path) -> None:
        from robocal.evaluate.report import write_report
        from robocal.outdir import read_run_id

        run_id = read_run_id(stage_dir / "result.json")  # the report is one file of this result
        with console.status("writing the report ..."):
            write_report(result, stage_dir / "report.html", data=train, test_data=test, run_id=run_id)

    try:
        result.save(out, also=write_report_too if report else None)
    except FolderBusyError as err:
        raise fail(str(err)) from None


def _chain_to_calibrate(model, from_catalog: bool, chain: str | None, measure: str | None, data):
    """The model the command calibrates, announced in one line: for a catalog ROBOT the complete
    model built from the robot's geometry (``--chain catalog``: the catalog's chain), for a
    model file the file's chain (``--chain complete``: the complete model built from
    it); a chain calibrated as it is gets the parameterisation warnings of rc.calibrate."""
    from robocal.model.complete import calibration_model

    effective = measure or ("pose" if data.orientation is not None else "position")
    complete = chain == "complete" or (chain is None and from_catalog)
    if complete:
        try:
            built = calibration_model(model, effective)
        except ValueError as err:
            raise fail(f"no complete model of {model.name}: {err}") from None
        option = "" if from_catalog and chain is None else " (--chain complete)"
        plain = " (--chain catalog: the catalog's chain)" if from_catalog else ""
        console.print(
            f"model: {built.name}, the complete model built from {model.name}'s joint geometry for "
            f"{effective} measurements{option}{plain}",
            highlight=False,
        )
        return built
    what = "the catalog's chain (--chain catalog)" if from_catalog else "the model file's chain"
    console.print(f"model: {model.name}, {what} as it is", highlight=False)
    # its parameterisation warnings come with the calibration's (rc.calibrate checks every chain)
    return model


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
    from robocal.identify.calibrate import display_unit, effect_lines

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
