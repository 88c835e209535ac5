"""``robocal register CAL --data FEW.csv --out NEW``: calibrate once, re-register later.

The robot of the calibration folder CAL (joint geometry, joint effects, learned residual)
is kept frozen; the device frame (``--tool``: and the tool point) is fitted again to the
few poses of a new series (:mod:`robocal.identify.register`).  The fit is scored on rows
it was not fitted to (K-fold, K = min(5, n); ``--holdout FRACTION``: one held-out part),
then fitted on every row and written to NEW as a complete calibration folder that records
what it inherited (``registered_from`` in its ``result.json``).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Annotated, Any

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
    Json,
    LengthUnit,
    Limits,
    Orientation,
    Sep,
    as_cli_text,
    out_option,
)
from robocal.cli.reading import load_result, read_data, written_files
from robocal.console import console, fail, safe
from robocal.safe_output import strict_json

__all__ = ["register"]

CalibrationDir = Annotated[
    Path,
    typer.Argument(
        metavar="CAL",
        help="a calibration folder (model.yaml, result.json) whose robot is kept",
        show_default=False,
    ),
]
Data = Annotated[
    Path, typer.Option("--data", metavar="FILE", help="measurements of the new series (a few poses)")
]
OutDir = Annotated[Path, out_option("the registered calibration folder to write", "DIR")]
RefitTool = Annotated[bool, typer.Option("--tool", help="also refit the tool point on the flange")]
Holdout = Annotated[
    float | None,
    typer.Option(
        "--holdout",
        metavar="FRACTION",
        help="score on this fraction of the rows, held out (default: K-fold over all rows, K = min(5, n))",
    ),
]


def register_command(
    calibration: CalibrationDir,
    data_path: Data,
    out: OutDir,
    tool: RefitTool = False,
    holdout: Holdout = None,
    seed: Annotated[int, options.seed("seed of the folds (or of the held-out draw)")] = 0,
    force: Force = False,
    as_json: Json = False,
    length_unit: LengthUnit = "m",
    angle_unit: AngleUnit = "rad",
    columns: Columns = None,
    sep: Sep = None,
    decimal: Decimal = ".",
    orientation: Orientation = "auto",
    limits: Limits = "error",
    incomplete: Incomplete = "error",
) -> None:
    """Re-register a calibration's device frame (--tool: and tool point) on a few poses.

    The poses of a new series; the robot kept frozen; scored on rows the frame was not
    fitted to; written as a new calibration folder."""
    from robocal.identify import register as reg

    _check_out(calibration, out, force)
    source = load_result(calibration)
    reader = dict(length_unit=length_unit, angle_unit=angle_unit, columns=columns, sep=sep, decimal=decimal)
    reader |= dict(orientation=orientation, limits=limits, incomplete=incomplete)
    data = read_data(data_path, source.model, **reader)
    try:
        reg.check_registrable(source, data, tool)
        robot = reg.frozen_robot(source, data)
        score = reg.score_registration(robot, data.position, tool, holdout, seed)
        fit = reg.fit_frame(robot, data.position, tool)
    except ValueError as err:
        raise fail(f"{data_path}: {as_cli_text(str(err))}") from None
    inherited = _registered_from(calibration, source, data_path, data.n, fit, score)
    result = reg.registered_result(source, data, fit, score, inherited)
    result = _with_provenance(result, data_path, reader)
    _save(result, out)
    summary = _summary(source, fit, score, out)
    if as_json:
        print(strict_json(summary))
        return
    _print(source, data_path, data.n, fit, score, summary)


def _check_out(calibration: Path, out: Path, force: bool) -> None:
    """Refuse NEW = CAL, a file, a folder holding something else than a robocal result, a
    result without --force, or a folder being written."""
    from robocal.folder_lock import FolderBusyError, check_not_busy

    if out.resolve() == calibration.resolve():
        raise fail(
            f"--out {out} is the calibration folder itself; write the registered calibration elsewhere"
        )
    if out.exists() and not out.is_dir():
        raise fail(f"--out {out} is a file; give a directory for the registered calibration")
    if out.is_dir() and any(out.iterdir()) and not (out / "result.json").is_file():
        raise fail(f"--out {out} holds files that are not a robocal calibration; give a new or empty folder")
    if (out / "result.json").exists() and not force:
        raise fail(f"{out} already holds a calibration result; use --force to overwrite it")
    try:
        check_not_busy(out)
    except FolderBusyError as err:
        raise fail(str(err)) from None


def _registered_from(calibration: Path, source, data_path: Path, n: int, fit, score) -> dict[str, Any]:
    """``result.json``'s ``registered_from``: the source folder, its run and result file's
    digest, the rows used and what was refitted."""
    from robocal.identify.result_io import file_hash

    return {
        "folder": str(calibration.resolve()),
        "run_id": source.run_id,
        "result_sha256": file_hash(calibration / "result.json"),
        "model": source.model.name,
        "data_file": str(data_path.resolve()),
        "data_sha256": file_hash(data_path),
        "rows": n,
        "refitted": ["device frame", *(["tool point"] if fit.tool_fitted else [])],
        "kept": "the robot: joint geometry, joint effects, learned residual; the coverage of its poses",
        "scoring": score.scoring,
        "variance_factor": fit.variance_factor if math.isfinite(fit.variance_factor) else None,
    }


def _with_provenance(result, data_path: Path, reader: dict):
    """The registered result reads back its own data: ``validate`` without --data finds
    every row used (and asks for held-out data)."""
    from robocal.identify.provenance import Provenance
    from robocal.identify.result_io import file_hash

    sha256 = file_hash(data_path)
    provenance = Provenance.record(data_path, sha256, reader, None, None, 0)
    return result.with_provenance(provenance, data_file=str(data_path), data_sha256=sha256, train_n=None)


def _save(result, out: Path) -> None:
    from robocal.folder_lock import FolderBusyError
    from robocal.run_ids import ForeignFileError

    try:
        result.save(out)
    except (FolderBusyError, ForeignFileError) as err:
        raise fail(str(err)) from None


def _frame_change(source, fit) -> tuple[float, float]:
    """How far the device moved: the translation (m) and rotation (rad) from the source frame."""
    from robocal import spatial

    D = fit.T_device_base @ np.linalg.inv(source.T_device_base)
    return float(np.linalg.norm(D[:3, 3])), float(np.linalg.norm(spatial.matrix_to_rotvec(D[:3, :3])))


def _summary(source, fit, score, out: Path) -> dict[str, Any]:
    moved, turned = _frame_change(source, fit)
    in_sample = np.linalg.norm(fit.residuals, axis=1)
    out_dict = {
        "held_out": score.to_dict(),
        "in_sample": {
            "n": len(in_sample),
            "mean_mm": float(in_sample.mean()) * 1e3,
            "rms_mm": float(np.sqrt(np.mean(in_sample**2))) * 1e3,
            "note": "the frame fitted and scored on the same rows (looks better than it is)",
        },
        "frame_moved_mm": moved * 1e3,
        "frame_turned_deg": math.degrees(turned),
        "T_device_base": fit.T_device_base.tolist(),
        "out": str(out),
    }
    if fit.tool_fitted:
        out_dict["tool_mm"] = (fit.tool * 1e3).tolist()
    return out_dict


def _print(source, data_path: Path, n: int, fit, score, summary: dict[str, Any]) -> None:
    h = summary["held_out"]
    what = "device frame and tool point" if fit.tool_fitted else "device frame"
    console.print(
        f"re-registered the {what} of {safe(source.model.name)} on {n} poses of {safe(data_path.name)} "
        "(the robot frozen)",
        highlight=False,
        markup=False,
    )
    table = Table(title=f"on rows the frame was not fitted to ({h['scoring']})", title_justify="left")
    for col in ("poses", "mean mm", "RMS mm", "p95 mm", "max mm", "expected RMS mm", "expected/measured"):
        table.add_column(col, justify="right")
    table.add_row(
        str(h["n"]),
        *(f"{h[k]:.4f}" for k in ("mean_mm", "rms_mm", "p95_mm", "max_mm", "expected_rms_mm")),
        f"{h['expected_over_measured']:.2f}",
    )
    console.print(table)
    s = summary["in_sample"]
    console.print(
        f"in-sample (fitted and scored on the same {s['n']} rows, looks better than it is): "
        f"mean {s['mean_mm']:.4f} mm, RMS {s['rms_mm']:.4f} mm",
        highlight=False,
    )
    console.print(
        f"the device moved {summary['frame_moved_mm']:.1f} mm and turned {summary['frame_turned_deg']:.3f}° "
        f"from the calibration's frame; the frame's own uncertainty adds {h['frame_rms_mm']:.4f} mm RMS",
        highlight=False,
    )
    if fit.tool_fitted:
        console.print(f"tool point on the flange: ({', '.join(f'{v:.3f}' for v in summary['tool_mm'])}) mm")
    if h["rms_mm"] > 1.5 * h["expected_rms_mm"]:
        console.print(
            f"[yellow]warning:[/] the error on rows not fitted is {h['rms_mm'] / h['expected_rms_mm']:.2g}x "
            "the expected: the robot may have changed since the calibration, or these poses are unlike "
            "its poses; calibrate again",
            highlight=False,
        )
    console.print(f"wrote {written_files(summary['out'])}", highlight=False, soft_wrap=True)


def register(app: typer.Typer) -> None:
    """Add ``register`` to the ``robocal`` app."""
    app.command("register")(register_command)
