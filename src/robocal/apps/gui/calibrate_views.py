"""What the calibration page shows: the data preview and the reader's problems, the results of a
run and the compensation of uploaded targets."""

from __future__ import annotations

import base64
import binascii
import math
import tempfile
import warnings
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from dash import dcc, html

from robocal.apps.gui.columns_view import gui_words
from robocal.outdir import atomic_write_bytes

PREVIEW_ROWS = 12


# ----------------------------------------------------------------------- controls
#: the controls keep their values over a reload of the tab (its session storage)
KEEP: dict[str, Any] = {"persistence": True, "persistence_type": "session"}


def radio(
    ident: str, options: Sequence[str], value: str, labels: Sequence[str] | None = None
) -> dcc.RadioItems:
    labels = labels or options
    return dcc.RadioItems(
        id=ident,
        options=[{"label": lab, "value": v} for v, lab in zip(options, labels, strict=True)],
        value=value,
        inline=True,
        persistence=True,
        persistence_type="session",
    )


def text_input(ident: str, value: str, width: str, debounce: bool | float = False) -> dcc.Input:
    """A text box kept over a reload of the tab (``debounce``: seconds of no typing before its
    value is sent; False: every key)."""
    return dcc.Input(
        id=ident,
        value=value,
        type="text",
        debounce=debounce,
        style={"width": width},
        persistence=True,
        persistence_type="session",
    )


def row(label: str, control: Any, hint: str = "") -> html.Div:
    return html.Div(
        [html.Span(label, className="lab"), control, html.Span(hint, className="hint")], className="opt"
    )


# ----------------------------------------------------------------------- reading
def read(path: Path, options: dict[str, Any], model=None):
    """Measurements and the reader's warnings (messages), or raise the reader's error."""
    import robocal as rc
    from robocal.measure.measurements import MeasurementWarning

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", MeasurementWarning)
        data = rc.read_measurements(path, model=model, **options)
    return data, [str(w.message) for w in caught if isinstance(w.message, MeasurementWarning)]


def _fmt(v: float, digits: int = 4) -> str:
    return "" if not math.isfinite(v) else f"{v:.{digits}f}"


def preview_table(data, joint_types: Sequence[str] | None = None) -> html.Table:
    """The first rows of the parsed measurements: joints (deg, mm), position (mm), orientation (deg)."""
    from robocal import spatial

    n = min(PREVIEW_ROWS, data.n)
    types = list(joint_types) if joint_types else ["revolute"] * data.dof
    header = [
        f"{name} {'°' if t == 'revolute' else 'mm'}" for name, t in zip(data.joint_names, types, strict=True)
    ]
    cols = [
        np.degrees(data.q[:n, j]) if t == "revolute" else data.q[:n, j] * 1e3 for j, t in enumerate(types)
    ]
    if data.position is not None:
        header += ["x mm", "y mm", "z mm"]
        cols += [data.position[:n, k] * 1e3 for k in range(3)]
    if data.orientation is not None:
        header += ["rx °", "ry °", "rz °"]
        angles = np.degrees(spatial.matrix_to_rotvec(data.orientation[:n]))
        cols += [angles[:, k] for k in range(3)]
    body = [html.Tr([html.Td(_fmt(float(c[i]))) for c in cols]) for i in range(n)]
    return html.Table(
        [html.Thead(html.Tr([html.Th(h) for h in header])), html.Tbody(body)], className="preview"
    )


def problems_view(err, path: Path) -> html.Div:
    problems = [p for p in getattr(err, "problems", []) if p.severity == "error"][:20]
    rows = [
        html.Tr(
            [
                html.Td("" if p.row is None else str(p.row)),
                html.Td(p.column or ""),
                html.Td(gui_words(p.message)),
            ]
        )
        for p in problems
    ]
    table = (
        html.Table(
            [html.Thead(html.Tr([html.Th("row"), html.Th("column"), html.Th("problem")])), html.Tbody(rows)],
            className="problems",
        )
        if rows
        else ""
    )
    message = gui_words(
        str(err).replace(str(path), path.name)
    )  # the name the user knows; the page's controls
    return html.Div([html.Div(message, className="error", id="csv-error"), table])


def raw_head(path: Path, lines: int = 6) -> html.Pre:
    with path.open(encoding="utf-8", errors="replace") as f:
        head = [next(f, "") for _ in range(lines)]
    return html.Pre("".join(head)[:4000], className="raw")


# ----------------------------------------------------------------------- results
def _param_table(result) -> html.Table:
    from robocal.identify.effects import display_unit

    rot = {s.name: s.is_rotation for s in (result.measurement_chain or result.model).steps}
    rows = []
    for name, v0, v, s in zip(result.names, result.nominal, result.estimates, result.std, strict=True):
        f, unit = display_unit(name, rot.get(name, False))
        rows.append(
            html.Tr(
                [html.Td(name)]
                + [html.Td(f"{x:.5f}", className="num") for x in (v0 * f, v * f)]
                + [html.Td(f"{(v - v0) * f:+.5f}", className="num"), html.Td(f"{s * f:.5f}", className="num")]
                + [html.Td(unit)]
            )
        )
    head = html.Tr([html.Th(h) for h in ("parameter", "start", "estimate", "delta", "σ", "unit")])
    return html.Table([html.Thead(head), html.Tbody(rows)], className="params", id="param-table")


def _stats_table(rows: Sequence[tuple[str, dict | None]]) -> html.Table:
    head = html.Tr([html.Th(h) for h in ("poses", "n", "mean mm", "RMS mm", "p95 mm", "max mm")])
    body = [
        html.Tr(
            [html.Td(label), html.Td(str(s["n"]))]
            + [html.Td(f"{s[k]:.4f}", className="num") for k in ("mean_mm", "rms_mm", "p95_mm", "max_mm")]
        )
        for label, s in rows
        if s is not None
    ]
    return html.Table([html.Thead(head), html.Tbody(body)], className="stats", id="validation-table")


def _residual_figure(sets: dict) -> Any:
    """Histograms of the per-pose position errors: before and after on the calibration poses,
    after on the held-out poses (one panel each: their scales differ by orders of magnitude)."""
    import plotly.graph_objects as go
    from plotly.subplots import make_subplots

    panels = (
        ("before", "calibration poses, start model", "#d62728"),
        ("after", "calibration poses, calibrated", "#1f77b4"),
        ("held_out", "held-out poses, calibrated", "#2ca02c"),
    )
    shown = [p for p in panels if sets.get(p[0]) is not None]
    fig = make_subplots(rows=1, cols=len(shown), subplot_titles=[title for _, title, _ in shown])
    for col, (key, title, colour) in enumerate(shown, start=1):
        fig.add_trace(go.Histogram(x=sets[key]["errors_mm"], name=title, marker_color=colour), 1, col)
    fig.update_layout(height=300, margin={"l": 40, "r": 10, "t": 40, "b": 40}, showlegend=False)
    fig.update_xaxes(title_text="position error per pose, mm")
    return fig


def results_view(out: Path) -> list[Any]:
    """The saved result in ``out`` as the page shows it."""
    import json

    from robocal.identify.result import CalibrationResult

    result = CalibrationResult.load(out)
    sets = json.loads((out / "errors.json").read_text(encoding="utf-8"))
    head = (
        f"{result.model.name} — {result.method}, {result.measure} measurements, {result.n} poses: "
        f"{'converged' if result.success else 'NOT CONVERGED'} ({result.iterations} iterations); "
        f"RMS on the calibration poses {result.rms_before * 1e3:.4f} mm → {result.rms_after * 1e3:.4f} mm"
    )
    noise = result.fit_to_noise
    verdict = (
        noise.summary()
        if noise is not None
        else "fit to noise: not tested (give the device's noise to test whether the model explains the data)"
    )
    held = sets.get("held_out")
    held_line = "no held-out poses (all rows calibrated)"
    if held is not None:
        held_line = (
            f"held-out error ({held['n']} poses): mean {held['mean_mm']:.4f} mm, RMS {held['rms_mm']:.4f} mm"
        )
        if "expected_rms_mm" in held:
            held_line += f" (the calibration expected {held['expected_rms_mm']:.4f} mm RMS)"
    dropped = [html.Li(str(d)) for d in result.dropped]
    warns = [html.Div(f"warning: {w}", className="warning") for w in result.metadata.get("warnings", [])]
    return [
        html.H3("result"),
        html.Div(head, id="result-head"),
        html.Div(held_line, id="held-out", className="big"),
        html.Div(verdict, id="fit-to-noise"),
        html.Pre("\n".join(result.residual_lines()), className="cv") if result.residual_lines() else "",
        *warns,
        _stats_table(
            [
                ("calibration, before", sets.get("before")),
                ("calibration, after", sets.get("after")),
                ("held-out", held),
            ]
        ),
        dcc.Graph(figure=_residual_figure(sets), config={"displaylogo": False}),
        _points_3d(sets),
        html.H4("identified parameters (σ: one standard deviation)"),
        _param_table(result),
        html.H4("not identified, and why"),
        html.Ul(dropped or [html.Li("none")], id="dropped"),
    ]


def _points_3d(sets: dict) -> Any:
    """The measured points and the error vectors in 3D (:mod:`residual_view`), if recorded."""
    from robocal.apps.gui.residual_view import residual_figure

    figure = residual_figure(sets)
    if figure is None:
        return ""
    return dcc.Graph(figure=figure, id="residual-3d", config={"displaylogo": False})


def report_links(run_id: str, ready: bool, constraint: bool = False) -> list[Any]:
    """The report's link (once written) and the result's files (``constraint``: a constraint
    calibration's ``constraints.json`` in place of ``result.json``)."""
    names = ("model.yaml", "constraints.json" if constraint else "result.json")
    files = [html.A(f" · {n}", href=f"/runs/{run_id}/{n}", target="_blank") for n in names]
    if not ready:
        return [html.Span("writing the HTML report ...", className="hint"), *files]
    return [
        html.A("open the HTML report", href=f"/runs/{run_id}/report.html", target="_blank", id="report-link")
    ] + files


def decode_bytes(contents: str) -> bytes:
    try:
        return base64.b64decode(contents.split(",", 1)[1])
    except (IndexError, binascii.Error):
        raise ValueError("the upload could not be decoded") from None


def parse_float(text: str | None, what: str) -> float | None:
    s = (text or "").strip().replace(",", ".")
    if not s:
        return None
    try:
        value = float(s)
    except ValueError:
        raise ValueError(f"{what}: {text!r} is not a number") from None
    if not math.isfinite(value):
        raise ValueError(f"{what}: {text!r} is not a number")
    return value


def compensate(
    result: Any,
    contents: str,
    filename: str | None,
    unit: str,
    frame: str,
    sep: str | None = None,
    decimal: str = ".",
    nominal: Any = None,
) -> tuple[dict[str, str], str]:
    """Compensate the uploaded targets CSV (``unit``: m/mm; ``sep``: None to sniff; ``decimal``
    ``.`` or ``,``) through ``result`` (a calibration result or a calibrated model; ``nominal``:
    the controller's model, None for the result's own): the compensated commands' file (each
    target's status in it) and the page's line, which names every refused target."""
    import robocal as rc
    from robocal.compensate.ik_options import IKOptions
    from robocal.compensate.target_files import read_targets

    name = Path(filename or "targets.csv").name
    with tempfile.TemporaryDirectory(prefix="robocal-gui-") as tmp:
        path = Path(tmp) / name
        atomic_write_bytes(path, decode_bytes(contents))
        try:
            targets = read_targets(path, length_unit=unit, sep=sep, decimal=decimal)
        except ValueError as err:
            raise ValueError(str(err).replace(str(path), name)) from None
    comp = rc.compensate_targets(
        result, targets.values, nominal, names=targets.names, frame=frame, ik=IKOptions()
    )
    s = comp.summary()
    refused = [f"{r['name']} ({r['reason']})" for r in comp.table() if r["status"] == "refused"]
    before, after = s["error_before_mm"], s["error_after_mm"]
    message = (
        f"{comp.message}; predicted error mean {before['mean'] or float('nan'):.4f} → "
        f"{after['mean'] or float('nan'):.4f} mm (compensated commands downloaded)"
    )
    if refused:  # left as written in the file (its status column says so), named here
        message += f"; {len(refused)} refused, left as written: {', '.join(refused[:10])}"
    return {"content": comp.to_csv(), "filename": f"{Path(name).stem}_compensated.csv"}, message
