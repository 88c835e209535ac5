"""``robocal iso9283 LOG``: the fourteen ISO 9283 characteristics of a measurement log,
and the ``robocal simulate ROBOT --log -o LOG`` generator of a simulated log.

Commands:
    robocal iso9283 LOG [--band 0.1mm] [-o FILE.html] [--json] [--force]
    robocal simulate ROBOT --log -o LOG.csv [--seed 1] [--noise 0.005mm] [--force]
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated

import typer
from rich.table import Table

from robocal.cli.options import Force, out_option, resolve_model
from robocal.console import console, fail, refuse_overwrite

__all__ = ["iso9283_command", "register", "simulate_log_command"]


def iso9283_command(
    log: Annotated[
        Path,
        typer.Argument(
            metavar="LOG", help="ISO 9283 measurement log (CSV, docs/iso9283.md)", show_default=False
        ),
    ],
    band: Annotated[
        str | None,
        typer.Option(
            "--band",
            metavar="LENGTH",
            help="limit band of stabilisation, overshoot and positioning time, e.g. 0.1mm "
            "(default: the log's limit_band_mm, else 0.1mm)",
        ),
    ] = None,
    out: Annotated[Path | None, out_option("also write a small HTML report to this file")] = None,
    as_json: Annotated[
        bool, typer.Option("--json", help="print JSON (mm, deg, s) instead of the table")
    ] = False,
    force: Force = False,
) -> None:
    """The fourteen ISO 9283 characteristics of a measurement log (those it cannot support: why)."""
    from robocal.evaluate.iso9283.eval_pose import EvaluationOptions
    from robocal.evaluate.iso9283.log import Iso9283LogError, read_iso9283_log
    from robocal.evaluate.iso9283.report import evaluate_log, results_html, results_text
    from robocal.measure.true_model import parse_quantity_option
    from robocal.outdir import atomic_write_text

    if out is not None:
        refuse_overwrite(out, force, "report")
    try:
        band_m = None if band is None else parse_quantity_option(band, "length", "--band")
        if band_m is not None and not band_m > 0:
            raise ValueError(f"--band {band}: the limit band must be > 0")
        data = read_iso9283_log(log)
        results = evaluate_log(data, EvaluationOptions(band=band_m))
    except Iso9283LogError as err:
        raise fail(str(str(err))) from None
    except ValueError as err:
        raise fail(str(f"{log}: {err}" if str(log) not in str(err) else str(err))) from None
    if out is not None:
        atomic_write_text(out, results_html(results, f"ISO 9283 characteristics of {log.name}"))
    if as_json:
        print(json.dumps(results.to_dict(), indent=1, allow_nan=False))
        return
    table = Table(title=str(f"ISO 9283 characteristics of {log}"), title_justify="left", show_lines=True)
    for col in ("#", "characteristic", "clause", "result", "cycles"):
        table.add_column(col, overflow="fold")
    for row, r in zip(results_text(results), results.rows, strict=True):
        style = "" if r.measured else "dim"
        table.add_row(*(str(c) for c in row), style=style)
    console.print(table)
    measured = sum(r.measured for r in results.rows)
    console.print(f"{measured} of 14 measured; limit band {results.band * 1e3:g} mm", highlight=False)
    if out is not None:
        console.print(f"wrote {str(out)!s}", highlight=False)


def simulate_log_command(robot: str, log: Path, seed: int | None, noise: str | None, force: bool) -> None:
    """Write a simulated ISO 9283 log of ROBOT and its truth (``LOG.truth.yaml``)."""
    from robocal.evaluate.iso9283.log import save_simulated_log
    from robocal.evaluate.iso9283.sim import LogErrors, simulate_log
    from robocal.measure.true_model import parse_quantity_option

    refuse_overwrite(log, force, "log")
    model = resolve_model(robot)
    try:
        errors = LogErrors()
        if noise is not None:
            sigma = parse_quantity_option(noise, "length", "--noise")
            if sigma < 0:
                raise ValueError(f"--noise {noise}: must be >= 0")
            errors = LogErrors(noise=sigma)
        sim = simulate_log(model, errors=errors, seed=0 if seed is None else seed)
    except ValueError as err:
        raise fail(str(str(err))) from None
    _, truth_path = save_simulated_log(sim.log, sim.truth, log)  # both or neither
    console.print(
        str(f"wrote {log} ({sim.log.n} samples, tests: {', '.join(sim.log.tests())})")
        + str(f" and the truth {truth_path}"),
        highlight=False,
        soft_wrap=True,
    )
    console.print(str(f"next: robocal iso9283 {log} -o {log.with_suffix('.html')}"), highlight=False)


def register(app: typer.Typer) -> None:
    """Add ``iso9283`` to the ``robocal`` app."""
    app.command("iso9283")(iso9283_command)
