"""``robocal calibrate`` and ``robocal validate``."""

from __future__ import annotations

import dataclasses
import warnings
from pathlib import Path
from typing import Annotated

import numpy as np
import typer
from rich.table import Table

from robocal.console import check_input, console, err_console, fail, safe, warn
from robocal.measure.commands import (
    AngleUnit,
    Columns,
    Decimal,
    Incomplete,
    LengthUnit,
    Limits,
    Orientation,
    Sep,
    as_cli_text,
)
from robocal.model.files import strict_json

__all__ = ["register"]


def _read(
    path: Path,
    model,
    length_unit,
    angle_unit,
    columns,
    sep,
    decimal,
    orientation,
    limits="error",
    incomplete="error",
):
    from robocal.measure.dataset import MeasurementFileError, MeasurementWarning, read_measurements

    if path.is_dir():
        raise fail(f"{path} is a directory; --data takes a measurement file")
    check_input(path, "measurement file")
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", MeasurementWarning)
            data = read_measurements(
                path,
                length_unit=length_unit,
                angle_unit=angle_unit,
                columns=columns,
                sep=sep,
                decimal=decimal,
                model=model,
                orientation=orientation,
                limits=limits,
                incomplete=incomplete,
            )
    except (MeasurementFileError, ValueError) as err:
        raise fail(as_cli_text(str(err))) from None
    for w in caught:
        if isinstance(w.message, MeasurementWarning):
            warn(as_cli_text(str(w.message)))
    if "rows_left_out" in data.metadata:
        err_console.print(
            f"{data.metadata['rows_left_out']} incomplete row(s) of {path.name} left out (--incomplete drop)",
            highlight=False,
        )
    return data


def _given_options(ctx: typer.Context, values: dict) -> dict:
    """The reader options among ``values`` that were given on the command line."""
    from click.core import ParameterSource

    given = (ParameterSource.COMMANDLINE, ParameterSource.ENVIRONMENT, ParameterSource.PROMPT)
    return {k: v for k, v in values.items() if ctx.get_parameter_source(k) in given}


def load_result(directory: Path):
    """The calibration result in ``directory`` (exit 2 with one line when there is none or it
    cannot be read); a writer killed mid-swap is undone first."""
    from robocal.identify.calibrate import CalibrationResult
    from robocal.outdir import restore

    restore(directory)  # a writer killed mid-swap on a system without atomic exchange
    if not (directory / "result.json").is_file():
        raise fail(f"{directory} holds no calibration result (result.json)")
    try:
        result = CalibrationResult.load(directory)
    except (OSError, ValueError, KeyError) as err:
        raise fail(f"{directory}: cannot read the result: {err}") from None
    return result


def own_data(ctx: typer.Context, directory: Path, result, data_path: Path | None, values: dict):
    """The calibration's own data, read again with its own reader options and split as it
    was calibrated: ``(path, SplitRows)``, or None when ``data_path`` is another file or the
    result recorded no provenance.

    Without ``data_path`` the recorded file is read (it must still have the recorded
    SHA-256); with the recorded file as ``data_path``, reader options given on the command
    line replace the recorded ones.
    """
    from robocal.identify.calibrate import file_hash
    from robocal.identify.provenance import Provenance, split_rows

    provenance = Provenance.from_metadata(result.metadata)
    if provenance is None:
        if data_path is None:
            raise fail(f"{directory}: the result does not record its data file (older robocal?); give --data")
        return None
    if data_path is None:
        path = Path(provenance.data_file)
        if not path.is_file():
            raise fail(f"{directory}: the calibration's data file {path} is gone; give it with --data")
        if file_hash(path) != provenance.data_sha256:
            raise fail(f"{path} changed since the calibration (its SHA-256 differs); give data with --data")
        reader = provenance.reader
    else:
        if not data_path.is_file() or file_hash(data_path) != provenance.data_sha256:
            return None
        path, reader = data_path, provenance.reader | _given_options(ctx, values)
    data = _read(path, result.model, **reader)
    try:
        return path, split_rows(data, provenance)
    except ValueError as err:
        raise fail(f"{path}: {err}") from None


def _stats_table(title: str, stats) -> Table:
    table = Table(title=title, title_justify="left")
    for col in ("poses", "mean mm", "RMS mm", "p95 mm", "max mm", "|x| |y| |z| mean mm", "frame"):
        table.add_column(col, justify="right")
    axes = " ".join(f"{v * 1e3:.4f}" for v in stats.axis_mean_abs)
    table.add_row(
        str(stats.n),
        f"{stats.mean * 1e3:.4f}",
        f"{stats.rms * 1e3:.4f}",
        f"{stats.p95 * 1e3:.4f}",
        f"{stats.max * 1e3:.4f}",
        axes,
        stats.frame,
    )
    return table


def calibrate_command(
    data_path: Annotated[Path, typer.Option("--data", help="measurement CSV file")],
    out: Annotated[Path, typer.Option("--out", help="directory for model.yaml and result.json")],
    robot_name: Annotated[str | None, typer.Option("--robot", help="catalog robot")] = None,
    model_path: Annotated[Path | None, typer.Option("--model", help="model YAML file")] = None,
    chain: Annotated[
        str | None,
        typer.Option(
            "--chain",
            help="complete (default with --robot): the complete, minimal, continuous model built from the "
            "robot's joint geometry (rc.calibration_model); catalog: the catalog's chain as published (e.g. "
            "plain DH, singular for parallel axes). With --model the file's chain is calibrated unless "
            "--chain complete",
        ),
    ] = None,
    measure: Annotated[str | None, typer.Option("--measure", help="position | pose")] = None,
    method: Annotated[str, typer.Option("--method", help="lm | pinv | bounded | influence")] = "lm",
    per_pose: Annotated[
        bool,
        typer.Option(
            "--per-pose",
            help="with --method pinv: seed 003's per-pose pseudo-inverse Jᵀ(JJᵀ)⁻¹ at each pose, then the "
            "mean of the per-pose sets (instead of (JᵀJ)⁻¹Jᵀ over all poses)",
        ),
    ] = False,
    bounds: Annotated[
        str | None,
        typer.Option(
            "--bounds",
            help="with --method bounded: default (seed 001: every robot parameter within ±5 mm, ±2° of its "
            "nominal) | widened (wider for parameters that absorb redundant ones; warned)",
        ),
    ] = None,
    train_n: Annotated[
        int | None, typer.Option("--train-n", help="calibrate on N random rows, validate on the rest")
    ] = None,
    seed: Annotated[int, typer.Option("--seed", min=0, help="seed of the --train-n draw")] = 0,
    tool: Annotated[str | None, typer.Option("--tool", help='tool point start value in mm, "x,y,z"')] = None,
    compliance: Annotated[bool, typer.Option("--compliance", help="also identify joint compliance")] = False,
    level: Annotated[
        str | None,
        typer.Option(
            "--level",
            help="1 (joint offsets), 2 (kinematic, default) or 3 (non-geometric: with joint effects)",
        ),
    ] = None,
    effects: Annotated[
        str | None,
        typer.Option(
            "--effects",
            help="joint effects: none | predict (from the model's joint_effects, seed 003's two-stage "
            'method) | identify (default of --level 3) | kinds, e.g. "compliance,backlash"',
        ),
    ] = None,
    length_unit: LengthUnit = "m",
    angle_unit: AngleUnit = "rad",
    columns: Columns = None,
    sep: Sep = None,
    decimal: Decimal = ".",
    orientation: Orientation = "auto",
    limits: Limits = "error",
    incomplete: Incomplete = "error",
    loss: Annotated[
        str,
        typer.Option(
            "--loss",
            help="linear (least squares) or a robust loss that down-weights glitches: soft_l1, huber, cauchy",
        ),
    ] = "linear",
    noise: Annotated[
        str | None,
        typer.Option(
            "--noise",
            help="the device's position noise, 1σ per axis with a unit (e.g. 0.03mm), for a file without "
            "sigma columns: tests whether the model explains the data down to it",
        ),
    ] = None,
    residual: Annotated[
        str,
        typer.Option(
            "--residual",
            help="auto (default): k-fold cross-validation on the calibration poses chooses the physical "
            "model alone, with joint compliance (when the model has masses) and with learned joint angle "
            "errors; joint_fourier: always the learned residual; none: the physical model only",
        ),
    ] = "auto",
    force: Annotated[bool, typer.Option("--force", help="overwrite an existing result in --out")] = False,
    report: Annotated[bool, typer.Option("--report", help="also write DIR/report.html")] = False,
) -> None:
    """Identify the robot's parameters from measurements; write the calibrated model."""
    import robocal as rc
    from robocal.cli import resolve_model
    from robocal.identify.calibrate import file_hash

    if (robot_name is None) == (model_path is None):
        raise fail("give exactly one of --robot NAME or --model FILE")
    if chain not in (None, "complete", "catalog"):
        raise fail(f"--chain {chain!r}: complete or catalog")
    if model_path is not None and chain == "catalog":
        raise fail("--chain catalog is for --robot NAME; --model FILE calibrates the file's chain as it is")
    model = resolve_model(robot_name if robot_name is not None else str(model_path))
    if out.exists() and not out.is_dir():
        raise fail(f"--out {out} is a file; give a directory for model.yaml and result.json")
    if (out / "result.json").exists() and not force:
        raise fail(f"{out} already holds a calibration result; use --force to overwrite it")
    from robocal.outdir import FolderBusyError, check_not_busy

    try:  # before the work: a second writer learns it at once, not after the calibration
        check_not_busy(out)
    except FolderBusyError as err:
        raise fail(str(err)) from None
    if measure not in (None, "position", "pose"):
        raise fail(f"--measure {measure!r}: position or pose")
    if residual not in ("auto", "none", "joint_fourier"):
        raise fail(f"--residual {residual!r}: auto, none or joint_fourier")
    if loss not in ("linear", "soft_l1", "huber", "cauchy", "arctan"):
        raise fail(f"--loss {loss!r}: linear, soft_l1, huber, cauchy or arctan")
    from robocal.identify.solvers import METHODS

    if method not in METHODS:
        raise fail(f"--method {method!r}: {', '.join(METHODS)}")
    if loss != "linear" and method != "lm":
        raise fail(f"--loss {loss} needs --method lm")
    from robocal.identify.calibrate import BOUNDS_CHOICES

    if bounds is not None and bounds not in BOUNDS_CHOICES:
        raise fail(f"--bounds {bounds!r}: {' or '.join(BOUNDS_CHOICES)}")
    if bounds is not None and method != "bounded":
        raise fail(f"--bounds {bounds} needs --method bounded")
    if per_pose and method != "pinv":
        raise fail("--per-pose needs --method pinv")
    data = _read(
        data_path, model, length_unit, angle_unit, columns, sep, decimal, orientation, limits, incomplete
    )
    if data.position is None:
        raise fail(
            f"{data_path}: no measured positions (columns x, y, z) to calibrate against; map the file's "
            "columns with e.g. --columns 'x=meas_x,y=meas_y,z=meas_z'"
        )
    noise_sigma = None
    if noise is not None:
        from robocal.measure.simulate import parse_quantity_option

        try:
            sigma = parse_quantity_option(noise, "length", "--noise")
        except ValueError as err:
            raise fail(str(err)) from None
        from robocal.measure.dataset import MAX_SIGMA, MIN_SIGMA

        if not MIN_SIGMA <= sigma <= MAX_SIGMA:
            raise fail(
                f"--noise {noise}: a standard deviation between {MIN_SIGMA * 1e3:g} mm and "
                f"{MAX_SIGMA * 1e3:g} mm, e.g. 0.03mm"
            )
        if data.sigma is not None:
            raise fail(f"--noise: {data_path} has its own sigma columns; leave --noise out")
        data = dataclasses.replace(data, sigma=np.full((data.n, 3), sigma))
        noise_sigma = float(sigma)
    train, test = data, None
    if train_n is not None:
        if not 0 < train_n < data.n:
            raise fail(f"--train-n {train_n} must be between 1 and {data.n - 1} (the file has {data.n} rows)")
        split = data.with_split(train_n, seed=seed)
        train, test = split.split_rows("train"), split.split_rows("test")
    elif data.split is not None and "test" in set(data.split.tolist()):
        train, test = data.split_rows("train"), data.split_rows("test")
    model = _chain_to_calibrate(model, robot_name, chain, measure, data)
    guess = None
    if tool is not None:
        try:
            guess = np.array([float(v) for v in tool.replace(",", " ").split()]) * 1e-3
        except ValueError:
            raise fail(f"--tool {tool!r}: three numbers in mm") from None
        if guess.shape != (3,) or not np.all(np.isfinite(guess)):
            raise fail(f"--tool {tool!r}: three numbers in mm")
    effect_option = effects
    if effects is not None and effects not in ("none", "predict", "identify"):
        effect_option = [k.strip() for k in effects.split(",") if k.strip()]
    try:
        with console.status(
            f"calibrating {model.name} on {train.n} poses ({method}"
            + (", choosing the model by cross-validation" if residual != "none" else "")
            + ") ..."
        ):
            result = rc.calibrate(
                model,
                train,
                method=method,
                measure=measure,
                tool_guess=guess,
                compliance=compliance,
                level=level,
                effects=effect_option,
                loss=loss,
                residual=residual,
                **({"bounds": bounds} if bounds is not None else {}),
                **({"per_pose": True} if per_pose else {}),
            )
    except ValueError as err:
        message = as_cli_text(str(err))  # the data's problem: name the file unless the message does
        raise fail(message if str(data_path) in message else f"{data_path}: {message}") from None
    from robocal.identify.provenance import Provenance

    sha256 = file_hash(data_path)
    reader = dict(length_unit=length_unit, angle_unit=angle_unit, columns=columns, sep=sep, decimal=decimal)
    reader |= dict(orientation=orientation, limits=limits, incomplete=incomplete)
    provenance = Provenance.record(data_path, sha256, reader, noise_sigma, train_n, seed)
    result = result.with_provenance(
        provenance, data_file=str(data_path), data_sha256=sha256, train_n=train.n, seed=seed
    )
    validation = None
    if test is not None:
        validation = rc.validate(result, test)
        result = result.with_validation(validation.to_dict())

    def write_report_too(stage_dir: Path) -> None:
        from robocal.evaluate.report import write_report
        from robocal.outdir import read_run_id

        run_id = read_run_id(stage_dir / "result.json")  # the report is one file of this result
        with console.status("writing the report ..."):
            write_report(result, stage_dir / "report.html", data=train, test_data=test, run_id=run_id)

    try:  # model.yaml, measurement_model.yaml, result.json (and report.html): all or nothing
        result.save(out, also=write_report_too if report else None)
    except FolderBusyError as err:
        raise fail(str(err)) from None
    _print_result(result)
    if validation is not None:
        console.print(_stats_table(f"held-out validation ({validation.n} poses)", validation))
        for note in _validation_notes(validation, result, frame_note=False)[0]:  # frame: the calibrated one
            console.print(note, highlight=False, markup=True)
    console.print(f"wrote {out / 'model.yaml'} and {out / 'result.json'}", highlight=False)
    if report:
        console.print(f"report: {out / 'report.html'}", highlight=False)


def _chain_to_calibrate(model, robot_name: str | None, chain: str | None, measure: str | None, data):
    """The model the command calibrates, announced in one line: for ``--robot`` the complete
    model built from the catalog robot's geometry (``--chain catalog``: the catalog's chain),
    for ``--model`` the file's chain (``--chain complete``: the complete model built from
    it); a chain calibrated as it is gets the parameterisation warnings of rc.calibrate."""
    from robocal.model.complete import calibration_model

    effective = measure or ("pose" if data.orientation is not None else "position")
    complete = chain == "complete" or (chain is None and robot_name is not None)
    if complete:
        try:
            built = calibration_model(model, effective)
        except ValueError as err:
            raise fail(f"no complete model of {model.name}: {err}") from None
        option = "" if robot_name is not None and chain is None else " (--chain complete)"
        plain = " (--chain catalog: the catalog's chain)" if robot_name is not None else ""
        console.print(
            f"model: {built.name}, the complete model built from {model.name}'s joint geometry for "
            f"{effective} measurements{option}{plain}",
            highlight=False,
        )
        return built
    what = "the catalog's chain (--chain catalog)" if robot_name is not None else "the model file's chain"
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
        mode = result.metadata.get("effects", "identify")
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
    for w in result.metadata.get("warnings", []):
        console.print(f"[yellow]warning:[/] {safe(w)}", highlight=False, markup=True)


def _validation_notes(stats, result, frame_note: bool = True) -> tuple[list[str], str | None]:
    """Lines under a validation table (how the device frame was obtained unless
    ``frame_note`` is False, the error the calibration expected) and a warning when the
    error is far from what it should be."""
    frames = {
        "calibrated": "the device frame identified by the calibration was used as it is",
        "refit": "the device frame was refitted to this data (--refit-frame)",
    }
    notes = [frames.get(stats.frame, "")] if frame_note else []
    if stats.expected_rms is not None:
        notes.append(
            f"the calibration expected an RMS error of {stats.expected_rms * 1e3:.4g} mm here "
            f"({stats.parameter_rms * 1e3:.3g} mm from its parameter"
            + (" and learned-residual" if result.model.residual is not None else "")
            + " uncertainty, the rest "
            + {
                "sigma": "the data's stated noise",
                "sigma+unmodelled": "the data's stated noise and the error its residuals showed beyond noise",
                "residual model": "the noise and error the learned residual left unexplained",
            }.get(stats.scatter or "", "the scatter of its own residuals")
            + f"); measured {stats.rms * 1e3:.4g} mm"
        )
    warning = None
    if stats.mean > max(20 * result.rms_after, 5e-3):
        warning = (
            f"the mean error is {stats.mean / max(result.rms_after, 1e-12):.0f}x the calibration's own "
            f"RMS residual ({result.rms_after * 1e3:.3g} mm)"
            + (": if the device was moved since, add --refit-frame;" if stats.frame == "calibrated" else ":")
            + " otherwise check the robot, the units and the column mapping"
        )
    elif stats.worse_than_expected:
        warning = (
            f"the error is {stats.rms / stats.expected_rms:.3g}x what the calibration expected: a robot "
            "or device that changed since, or errors the model does not represent in poses unlike the "
            "calibration's"
        )
    if warning:
        notes.append(f"[yellow]warning:[/] {safe(warning)}")
    return notes, warning


def _own_rows(rows, all_rows: bool, directory: Path, path: Path):
    """The rows of the calibration's own file that ``validate`` uses: the held-out ones (all
    with ``--all-rows``), a note saying which, and their label."""
    if rows.test is None and not all_rows:
        raise fail(
            f"{directory}: the calibration used every row of {path.name}: give held-out "
            "measurements with --data (or --all-rows to see the error on the calibration poses)"
        )
    if all_rows:
        note = f"every row of the calibration's own file ({rows.every.n}), its {rows.train.n} calibration"
        return rows.every, note + " rows included", "all"
    note = (
        f"the {rows.test.n} held-out rows of the calibration's own file (split by {rows.how}; "
        f"its {rows.train.n} calibration rows left out; --all-rows: every row)"
    )
    return rows.test, note, "test" if rows.how == "the file's set column" else "held-out"


def validate_command(
    ctx: typer.Context,
    directory: Annotated[Path, typer.Argument(help="a calibration output directory")],
    data_path: Annotated[
        Path | None,
        typer.Option(
            "--data",
            help="measurement CSV file (default: the calibration's own file, read with its options; "
            "its held-out rows)",
        ),
    ] = None,
    refit_frame: Annotated[
        bool, typer.Option("--refit-frame", help="the device was moved: refit its frame only")
    ] = False,
    as_json: Annotated[bool, typer.Option("--json", help="print JSON")] = False,
    length_unit: LengthUnit = "m",
    angle_unit: AngleUnit = "rad",
    columns: Columns = None,
    sep: Sep = None,
    decimal: Decimal = ".",
    orientation: Orientation = "auto",
    limits: Limits = "error",
    incomplete: Incomplete = "error",
    all_rows: Annotated[
        bool, typer.Option("--all-rows", help="validate every row, also those marked train in a set column")
    ] = False,
) -> None:
    """Error statistics of a calibrated model on (held-out) measurements."""
    import robocal as rc

    result = load_result(directory)
    values = dict(length_unit=length_unit, angle_unit=angle_unit, columns=columns, sep=sep, decimal=decimal)
    values |= dict(orientation=orientation, limits=limits, incomplete=incomplete)
    notes, extra = [], {}
    own = own_data(ctx, directory, result, data_path, values)
    if own is not None:
        data_path, rows = own
        data, note, extra["rows"] = _own_rows(rows, all_rows, directory, data_path)
        notes.append(note)
    else:
        data = _read(data_path, result.model, **values)
    if own is None and data.split is not None and "test" in set(data.split.tolist()) and not all_rows:
        data = data.split_rows("test")
        notes.append(f"the {data.n} rows marked test in the file's set column (--all-rows: every row)")
        extra["rows"] = "test"
    try:
        stats = rc.validate(result, data, refit_frame=refit_frame)
    except ValueError as err:
        raise fail(f"{data_path}: {as_cli_text(str(err))}") from None
    more_notes, warning = _validation_notes(stats, result)
    notes += more_notes
    if warning:
        extra["warning"] = warning
    if as_json:
        print(strict_json(stats.to_dict() | extra))
        return
    console.print(_stats_table(f"{result.model.name} on {data_path.name} ({data.n} poses)", stats))
    for note in filter(None, notes):
        console.print(note, highlight=False, markup=True)


def register(app: typer.Typer) -> None:
    """Add ``calibrate`` and ``validate`` to the ``robocal`` app."""
    app.command("calibrate")(calibrate_command)
    app.command("validate")(validate_command)
