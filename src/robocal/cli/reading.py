"""What ``calibrate``, ``validate`` and ``report`` read: a measurement file with the reader's
options (:func:`read_data`), a result folder (:func:`load_result`) and the calibration's own
data, re-read with its own options and split (:func:`own_data`)."""

from __future__ import annotations

import warnings
from pathlib import Path

import typer

from robocal.cli.options import as_cli_text
from robocal.console import check_input, err_console, fail, warn

__all__ = ["load_result", "own_data", "read_data", "written_files"]


def read_data(
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
    from robocal.measure.dataset.options import ReaderOptions
    from robocal.measure.dataset.read import read_measurements
    from robocal.measure.measurements import MeasurementFileError, MeasurementWarning

    if path.is_dir():
        raise fail(f"{path} is a directory; --data takes a measurement file")
    check_input(path, "measurement file")
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", MeasurementWarning)
            options = ReaderOptions(
                length_unit=length_unit,
                angle_unit=angle_unit,
                columns=columns,
                sep=sep,
                decimal=decimal,
                orientation=orientation,
                limits=limits,
                incomplete=incomplete,
            )
            data = read_measurements(path, model=model, options=options)
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
    # by name: typer 0.29 runs on its own copy of click, whose enum is not click.core's
    given = ("COMMANDLINE", "ENVIRONMENT", "PROMPT")
    source = ctx.get_parameter_source
    return {k: v for k, v in values.items() if getattr(source(k), "name", None) in given}


def load_result(directory: Path):
    """The calibration result in ``directory`` (exit 2 with one line when there is none or it
    cannot be read); a writer killed mid-swap is undone first."""
    from robocal.identify.result import CalibrationResult
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
    from robocal.identify.provenance import Provenance, split_rows
    from robocal.identify.result_io import file_hash

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
    data = read_data(path, result.model, **reader)
    try:
        return path, split_rows(data, provenance)
    except ValueError as err:
        raise fail(f"{path}: {err}") from None


def written_files(directory: str | Path) -> str:
    """``"DIR (model.yaml, result.json, …)"``: the result folder and the files of
    :data:`RESULT_FILES` that are in it, for a command's "wrote" line (the ``.npz`` sidecars
    and the report included when they were written)."""
    folder = Path(directory)
    from robocal.identify.result_io import RESULT_FILES  # lazy: keeps `--help` fast

    names = [name for name in RESULT_FILES if (folder / name).is_file()]
    return f"{folder} ({', '.join(names)})"
