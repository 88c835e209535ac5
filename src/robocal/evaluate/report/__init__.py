"""One self-contained HTML report per calibration.

:func:`write_report` turns a :class:`~robocal.identify.calibrate.CalibrationResult`
(or a directory written by :meth:`CalibrationResult.save`) and, when given, the
calibration and held-out measurements and an *evaluation* (ISO 9283 poses and paths,
compensation, the truth of a simulation) into one HTML file with these sections:

1. summary — the numbers that matter, before and after;
2. robot and model — interactive 3D view with the joint frames
   (:func:`robocal.model.view.model_figure`), how every link is parameterised;
3. data — where the measured poses lie in the workspace, the joint ranges covered;
4. identifiability — dropped parameters and why, condition number, observability
   indices O1-O5, singular values;
5. parameters — estimates with their deltas and σ (and the true deltas of a
   simulation);
6. residuals — before and after: histograms, per-pose bars, 3D error vectors;
7. held-out validation — statistics, histograms, the seeds' min / max / average
   table with the improvement in per cent and its 95 % confidence interval;
8. ISO 9283 — pose accuracy AP and repeatability RP at P1-P5, path accuracy AT and
   repeatability RT (:mod:`robocal.evaluate.metrics`), and the characteristics of a
   measurement log;
9. joint effects — identified joint compliances (µrad/(N·m), stiffness kN·m/rad) and what
   they move the tool by;
10. compensation — the method, and the path errors with nominal and compensated
    commands;
11. provenance.

How it is built: :func:`collect_report` computes everything once into a frozen
:class:`ReportData` (:mod:`.data`; the result's own data read by
:func:`report_data_from_result` alone), and :func:`render_report` formats it, one function
per section (:mod:`.sections`, :mod:`.sections_eval`) and the page's style sheet and template
as package data (``report.css``, ``page.html``).

plotly.js is embedded once (``include_plotlyjs=True`` for the first figure), so the
file works offline and makes no external request.  "Before calibration" is the
nominal robot with the device frame and tool fitted to the calibration data (the
start of the identification), the same reference as ``rms_before``.

The *evaluation* is plain JSON-able data (SI units), as ``robocal demo`` writes to
``evaluation.json``::

    {"iso_poses": {"labels": [...], "commanded": (5, 3), "cube": {"center", "side", "plane"},
                   "cycles": n, "cases": {name: (5, n, 3) attained positions}},
     "paths": [{"name": str, "commanded": (m, 3), "cases": {name: (n, k, 3)}}],
     "compensation": {"method": str, ...},
     "comparison": [{"model": str, **ValidationStats.to_dict()}],
     "truth": {"parameter_deltas": {name: value}, "compliance_rad_per_Nm": {joint: c}},
     "timings_s": {step: seconds},
     "iso9283": Iso9283Results.to_dict() of a measurement log (robocal iso9283 --json)}

Positions of ``iso_poses`` and ``paths`` are in the robot's base frame (m).
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from robocal.evaluate.report.collect import collect_report
from robocal.evaluate.report.data import ReportData, ReportOptions, ResultFacts
from robocal.evaluate.report.facts import before_validation, report_data_from_result, start_chain
from robocal.evaluate.report.markup import report_css
from robocal.evaluate.report.render import render_report
from robocal.identify.result import CalibrationResult
from robocal.measure.measurements import Measurements

__all__ = [
    "ReportData",
    "ReportOptions",
    "ResultFacts",
    "before_validation",
    "build_report",
    "collect_report",
    "render_report",
    "report_css",
    "report_data_from_result",
    "start_chain",
    "write_report",
]


def build_report(
    result: CalibrationResult,
    *,
    data: Measurements | None = None,
    test_data: Measurements | None = None,
    evaluation: Mapping[str, Any] | None = None,
    title: str | None = None,
) -> str:
    """The report as one HTML string: :func:`collect_report`, then :func:`render_report`."""
    report = collect_report(
        result, data=data, test_data=test_data, evaluation=evaluation, options=ReportOptions(title=title)
    )
    return render_report(report)


def _load_dir(
    directory: Path,
) -> tuple[CalibrationResult, Measurements | None, Measurements | None, dict | None]:
    from robocal.measure.dataset.read import read_measurements

    if not (directory / "result.json").is_file():
        raise FileNotFoundError(f"{directory} holds no calibration result (result.json)")
    result = CalibrationResult.load(directory)
    train = read_measurements(directory / "train.csv") if (directory / "train.csv").is_file() else None
    test = read_measurements(directory / "test.csv") if (directory / "test.csv").is_file() else None
    ev = None
    if (directory / "evaluation.json").is_file():
        ev = json.loads((directory / "evaluation.json").read_text(encoding="utf-8"))
    return result, train, test, ev


def write_report(
    result_or_dir: CalibrationResult | str | Path,
    out_path: str | Path,
    *,
    data: Measurements | None = None,
    test_data: Measurements | None = None,
    evaluation: Mapping[str, Any] | None = None,
    title: str | None = None,
    run_id: str | None = None,
) -> Path:
    """Write the self-contained HTML report of a calibration to ``out_path`` (atomically).

    Args:
        result_or_dir: a :class:`CalibrationResult`, or a directory written by
            :meth:`CalibrationResult.save`; from a directory, ``train.csv``,
            ``test.csv`` and ``evaluation.json`` beside ``result.json`` are used when
            the corresponding argument is None.
        out_path: the HTML file to write.
        data: the calibration measurements (residual plots, pose coverage,
            observability indices).
        test_data: held-out measurements (validation section, the seeds' table).
        evaluation: ISO 9283 poses and paths, compensation, truth, timings (see the
            module docstring).
        title: the report's heading.
        run_id: the run id of the result folder the report belongs to (default: that of
            ``result_or_dir/result.json``, or the one a saved or loaded result carries),
            stamped as ``<meta name="robocal-run">`` (:mod:`robocal.outdir`).

    Returns:
        ``out_path``.
    """
    from robocal.outdir import atomic_write_text
    from robocal.run_ids import read_run_id, run_id_meta

    if isinstance(result_or_dir, CalibrationResult):
        result = result_or_dir
    else:
        run_id = run_id if run_id is not None else read_run_id(Path(result_or_dir) / "result.json")
        result, d_train, d_test, d_ev = _load_dir(Path(result_or_dir))
        data = data if data is not None else d_train
        test_data = test_data if test_data is not None else d_test
        evaluation = evaluation if evaluation is not None else d_ev
    report = collect_report(
        result, data=data, test_data=test_data, evaluation=evaluation, options=ReportOptions(title=title)
    )
    run_id = run_id if run_id is not None else report.facts.run_id
    page = render_report(report)
    if run_id is not None:
        head = '<meta charset="utf-8">'
        page = page.replace(head, head + "\n" + run_id_meta(run_id), 1)
    return atomic_write_text(out_path, page)
