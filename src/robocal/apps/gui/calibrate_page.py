"""The calibration page: measurement file, reader options, model, method, run, results.

The file is read with :func:`rc.read_measurements` on every change of an option (the
preview shows the parsed table in mm and degrees, or the reader's message with its
row and column); a run is a :class:`robocal.apps.gui.jobs.CalibrationJob` in a child
process, polled by a ``dcc.Interval``; the results are read back with
``CalibrationResult.load`` and shown with ``rc.validate``; the report, the
compensation (``rc.compensate``) and the exports (``robocal.compensate.export``) work
on the saved result.
"""

from __future__ import annotations

import base64
import binascii
import math
import tempfile
import uuid
import warnings
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from dash import Dash, Input, Output, State, dcc, html, no_update

from robocal.apps.gui.jobs import CalibrationJob, JobRunner, read_options
from robocal.outdir import atomic_write_bytes, atomic_write_text

__all__ = ["layout", "register"]

PREVIEW_ROWS = 12


def _radio(
    ident: str, options: Sequence[str], value: str, labels: Sequence[str] | None = None
) -> dcc.RadioItems:
    labels = labels or options
    return dcc.RadioItems(
        id=ident,
        options=[{"label": lab, "value": v} for v, lab in zip(options, labels, strict=True)],
        value=value,
        inline=True,
    )


def _row(label: str, control: Any, hint: str = "") -> html.Div:
    return html.Div(
        [html.Span(label, className="lab"), control, html.Span(hint, className="hint")], className="opt"
    )


def layout(catalog: Sequence[str]) -> html.Div:
    """The calibration page."""
    text = {"type": "text", "debounce": False}
    reread = {"type": "text", "debounce": 0.5}  # the reader's text options: re-read once the typing pauses
    reader = html.Fieldset(
        [
            html.Legend("measurement file and reader options"),
            dcc.Upload(html.Button("open measurement CSV"), id="upload-csv"),
            html.Span(id="csv-name", className="hint"),
            _row("lengths", _radio("opt-length", ("m", "mm", "um"), "m")),
            _row("angles", _radio("opt-angle", ("rad", "deg"), "rad")),
            _row("separator", _radio("opt-sep", ("auto", ";", ",", "tab", "space"), "auto")),
            _row("decimal mark", _radio("opt-decimal", (".", ","), ".")),
            _row(
                "orientation",
                dcc.Input(id="opt-orientation", value="auto", style={"width": "12em"}, **reread),
                "auto | none | quaternion | rotvec | euler:SEQ[:deg|rad]",
            ),
            _row(
                "column renames",
                dcc.Input(id="opt-columns", value="", style={"width": "46em"}, **reread),
                "q1=file_column, x=..., (robocal name = the file's)",
            ),
            _row("incomplete rows", _radio("opt-incomplete", ("error", "drop"), "error")),
            _row("joint limits", _radio("opt-limits", ("error", "warn", "ignore"), "error")),
        ]
    )
    model = html.Fieldset(
        [
            html.Legend("model and method"),
            _row(
                "robot",
                dcc.RadioItems(
                    id="cal-model",
                    options=[{"label": "the model built on the builder page", "value": "@built"}]
                    + [{"label": n, "value": n} for n in catalog],
                    value=None,
                    inline=True,
                ),
                "catalog robots: their complete model (rc.calibration_model)",
            ),
            _row("measure", _radio("cal-measure", ("auto", "position", "pose"), "auto")),
            _row("method", _radio("cal-method", ("lm", "pinv", "bounded", "influence"), "lm")),
            _row(
                "model choice",
                _radio("cal-residual", ("auto", "none", "joint_fourier"), "auto"),
                "auto: cross-validation chooses compliance and learned joint angle errors",
            ),
            _row(
                "calibration poses",
                dcc.Input(id="cal-train-n", value="100", style={"width": "6em"}, **text),
                "random rows to calibrate on; the rest are held out (empty: all rows)",
            ),
            _row("seed", dcc.Input(id="cal-seed", value="0", style={"width": "4em"}, **text)),
            _row(
                "tool start mm",
                dcc.Input(id="cal-tool", value="", style={"width": "10em"}, **text),
                "x, y, z of the measured point from the flange (empty: fitted from zero)",
            ),
            _row(
                "device noise mm",
                dcc.Input(id="cal-noise", value="", style={"width": "6em"}, **text),
                "1σ per axis, for the fit-to-noise test (empty: not tested)",
            ),
            dcc.Checklist(
                id="cal-compliance", options=[{"label": "identify joint compliance", "value": "yes"}]
            ),
            html.Div(
                [
                    html.Button("calibrate", id="cal-run", className="primary"),
                    html.Button("cancel", id="cal-cancel"),
                ],
                className="toolbar",
            ),
            html.Div(html.Div(id="cal-bar", className="bar"), className="progress"),
            html.Div(id="cal-status", className="message"),
            html.Div(id="cal-report", className="toolbar"),
        ]
    )
    after = html.Fieldset(
        [
            html.Legend("compensate targets and export (after a calibration)"),
            dcc.Upload(
                html.Button("compensate a targets CSV (name, x, y, z [, qw..qz])"), id="upload-targets"
            ),
            _row("targets in", _radio("targets-unit", ("m", "mm"), "mm")),
            _row(
                "targets frame",
                _radio("targets-frame", ("base", "measurement"), "base", ("robot base", "device")),
            ),
            html.Div(
                [
                    html.Button("calibrated URDF", id="export-urdf"),
                    html.Button("UR kinematics YAML", id="export-ur"),
                ],
                className="toolbar",
            ),
            html.Div(id="export-message", className="message"),
        ]
    )
    return html.Div(
        [
            html.Div([reader, html.Div(id="csv-preview")], className="left"),
            html.Div([model, html.Div(id="cal-results"), after], className="right"),
            dcc.Interval(id="cal-poll", interval=400, disabled=True),
            dcc.Store(id="cal-run-id"),
            dcc.Store(id="cal-shown"),
            dcc.Store(id="csv-file"),
            dcc.Download(id="cal-download"),
        ],
        className="page",
    )


# ----------------------------------------------------------------------- reading
def _read(path: Path, options: dict[str, Any], model=None):
    """Measurements and the reader's warnings (messages), or raise the reader's error."""
    import robocal as rc
    from robocal.measure.dataset import MeasurementWarning

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


def _problems(err, path: Path) -> html.Div:
    problems = [p for p in getattr(err, "problems", []) if p.severity == "error"][:20]
    rows = [
        html.Tr([html.Td("" if p.row is None else str(p.row)), html.Td(p.column or ""), html.Td(p.message)])
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
    message = str(err).replace(str(path), path.name)  # the name the user knows, not the upload's copy
    return html.Div([html.Div(message, className="error", id="csv-error"), table])


def _raw_head(path: Path, lines: int = 6) -> html.Pre:
    with path.open(encoding="utf-8", errors="replace") as f:
        head = [next(f, "") for _ in range(lines)]
    return html.Pre("".join(head)[:4000], className="raw")


# ----------------------------------------------------------------------- results
def _param_table(result) -> html.Table:
    from robocal.identify.calibrate import display_unit

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

    from robocal.identify.calibrate import CalibrationResult

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
        html.H4("identified parameters (σ: one standard deviation)"),
        _param_table(result),
        html.H4("not identified, and why"),
        html.Ul(dropped or [html.Li("none")], id="dropped"),
    ]


def _report_links(run_id: str, ready: bool) -> list[Any]:
    files = [
        html.A(f" · {n}", href=f"/runs/{run_id}/{n}", target="_blank") for n in ("model.yaml", "result.json")
    ]
    if not ready:
        return [html.Span("writing the HTML report ...", className="hint"), *files]
    return [
        html.A("open the HTML report", href=f"/runs/{run_id}/report.html", target="_blank", id="report-link")
    ] + files


def _decode_bytes(contents: str) -> bytes:
    try:
        return base64.b64decode(contents.split(",", 1)[1])
    except (IndexError, binascii.Error):
        raise ValueError("the upload could not be decoded") from None


def _float(text: str | None, what: str) -> float | None:
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


# ----------------------------------------------------------------------- callbacks
def register(app: Dash, workdir: Path) -> None:
    """The calibration page's callbacks; files live in ``workdir`` (a temporary directory)."""
    runner = JobRunner()
    app.robocal_runner = runner  # for shutting down
    reader_inputs = [
        Input("opt-length", "value"),
        Input("opt-angle", "value"),
        Input("opt-sep", "value"),
        Input("opt-decimal", "value"),
        Input("opt-columns", "value"),
        Input("opt-orientation", "value"),
        Input("opt-incomplete", "value"),
        Input("opt-limits", "value"),
    ]

    def model_for(choice: str | None, built: dict | None, measure: str):
        import robocal as rc

        if choice is None:
            return None
        if choice == "@built":
            if not built:
                raise ValueError("no model built yet: build one on the builder page (build → model file)")
            path = workdir / "built_model.yaml"
            atomic_write_text(path, built["text"])
            return rc.load_model(path)
        return rc.calibration_model(choice, measure)

    def data_file(token: str | None) -> Path | None:
        """The uploaded file of this page (each upload has its own directory)."""
        if not token:
            return None
        path = workdir / "data" / token
        return path if path.is_file() and path.parent.parent == workdir / "data" else None

    @app.callback(
        Output("csv-name", "children"),
        Output("csv-file", "data"),
        Input("upload-csv", "contents"),
        State("upload-csv", "filename"),
        prevent_initial_call=True,
    )
    def upload(contents, filename):
        try:
            data = _decode_bytes(contents)
        except ValueError as err:
            return html.Span(str(err), className="error"), None
        name = Path(filename or "measurements.csv").name or "measurements.csv"
        token = f"{uuid.uuid4().hex[:12]}/{name}"
        target = workdir / "data" / token
        target.parent.mkdir(parents=True)
        atomic_write_bytes(target, data)
        return f"{name} ({len(data):,} bytes)", token

    @app.callback(
        Output("csv-preview", "children"),
        Input("csv-file", "data"),
        *reader_inputs,
        Input("cal-model", "value"),
        State("built-model", "data"),
    )
    def preview(token, *args):
        *options, choice, built = args
        path = data_file(token)
        if path is None:
            return html.Div("open a measurement CSV", className="hint")
        try:
            opts = read_options(*options)
            model = model_for(choice, built, "position")
            data, warns = _read(path, opts, model)
        except ValueError as err:
            return [_problems(err, path), html.H4("the file's first lines"), _raw_head(path)]
        observed = {
            "joints": "joint values only",
            "position": "positions",
            "pose": "positions and orientations",
        }
        summary = f"{path.name}: {data.n} rows, {data.dof} joints, {observed[data.observes]}" + (
            "" if model is None else f"; checked against {model.name}'s joints and limits"
        )
        return [
            html.Div(summary, className="ok", id="csv-summary"),
            *[html.Div(f"warning: {w}", className="warning") for w in warns],
            preview_table(data, None if model is None else model.joint_types),
            html.H4("the file's first lines"),
            _raw_head(path),
        ]

    @app.callback(
        Output("cal-run-id", "data"),
        Output("cal-poll", "disabled"),
        Output("cal-status", "children", allow_duplicate=True),
        Output("cal-results", "children", allow_duplicate=True),
        Output("cal-report", "children", allow_duplicate=True),
        Input("cal-run", "n_clicks"),
        *[State(i.component_id, i.component_property) for i in reader_inputs],
        State("cal-model", "value"),
        State("built-model", "data"),
        State("cal-measure", "value"),
        State("cal-method", "value"),
        State("cal-residual", "value"),
        State("cal-train-n", "value"),
        State("cal-seed", "value"),
        State("cal-tool", "value"),
        State("cal-noise", "value"),
        State("cal-compliance", "value"),
        State("csv-file", "data"),
        prevent_initial_call=True,
    )
    def run(_n, *args):
        options = read_options(*args[:8])
        choice, built, measure, method, residual, train_n, seed, tool, noise, compliance, token = args[8:]
        path = data_file(token)
        try:
            if path is None:
                raise ValueError("open a measurement CSV first")
            if choice is None:
                raise ValueError("choose the robot (its model)")
            effective = measure
            if measure == "auto":
                data, _ = _read(path, options)
                effective = "pose" if data.orientation is not None else "position"
            model = model_for(choice, built, effective)
            n = _float(train_n, "calibration poses")
            if n is not None and (n != int(n) or n < 1):
                raise ValueError(f"calibration poses: a whole number, not {train_n!r}")
            s = _float(seed, "seed")
            tool_mm = None
            if (tool or "").strip():
                parts = [p for p in tool.replace(";", " ").replace(",", " ").split() if p]
                if len(parts) != 3:
                    raise ValueError(f"tool start: three numbers in mm, e.g. 0, 0, 109 (not {tool!r})")
                tool_mm = tuple(_float(p, "tool start") for p in parts)
            noise_mm = _float(noise, "device noise")
            if noise_mm is not None and not noise_mm > 0:
                raise ValueError("device noise: a positive standard deviation in mm")
        except ValueError as err:
            return (
                no_update,
                True,
                html.Span(str(err), className="error", id="cal-error"),
                no_update,
                no_update,
            )
        from robocal.model.files import save_model

        run_id = uuid.uuid4().hex[:12]
        model_file = save_model(model, workdir / "runs" / f"{run_id}.model.yaml")
        job = CalibrationJob(
            data=path,
            reader=options,
            model_file=model_file,
            out=workdir / "runs" / run_id,
            method=method,
            residual=residual,
            train_n=None if n is None else int(n),
            seed=0 if s is None else int(s),
            tool_mm=tool_mm,
            noise_mm=noise_mm,
            compliance=bool(compliance),
            measure=None if measure == "auto" else measure,
        )
        runner.start(job)
        return run_id, False, f"calibrating {model.name} on {path.name} ...", "", ""

    @app.callback(
        Output("cal-bar", "style"),
        Output("cal-status", "children"),
        Output("cal-results", "children"),
        Output("cal-shown", "data"),
        Output("cal-report", "children"),
        Output("cal-poll", "disabled", allow_duplicate=True),
        Input("cal-poll", "n_intervals"),
        State("cal-run-id", "data"),
        State("cal-shown", "data"),
        prevent_initial_call=True,
    )
    def poll(_n, run_id, shown):
        state = runner.poll()
        if state is None or run_id is None:
            return no_update, no_update, no_update, no_update, no_update, True
        bar = {"width": f"{100 * state.fraction:.0f}%"}
        warns = [html.Div(f"warning: {w}", className="warning") for w in state.warnings[-5:]]
        results, report = no_update, no_update
        if state.saved and shown != run_id:
            try:
                results = results_view(workdir / "runs" / run_id)
            except (OSError, ValueError, KeyError) as err:
                results = html.Span(f"cannot show the result: {err}", className="error")
            report = _report_links(run_id, state.status == "done")
        elif state.status == "done":
            report = _report_links(run_id, True)
        if state.status == "running":
            text = f"{state.text} ({state.seconds:.0f} s)"
            return (
                bar | {"animation": "pulse 1s infinite"},
                [text, *warns],
                results,
                run_id if state.saved else shown,
                report,
                False,
            )
        if state.status == "done":
            return bar, [f"done in {state.seconds:.1f} s", *warns], results, run_id, report, True
        if state.status == "cancelled":
            return {"width": "0%"}, "cancelled", no_update, shown, "", True
        error = html.Span(state.error or "failed", className="error", id="cal-error")
        return {"width": "0%"}, [error, *warns], "", shown, "", True

    @app.callback(
        Output("cal-status", "children", allow_duplicate=True),
        Input("cal-cancel", "n_clicks"),
        prevent_initial_call=True,
    )
    def cancel(_n):
        return "cancelling ..." if runner.cancel() else "nothing is running"

    @app.callback(
        Output("cal-download", "data"),
        Output("export-message", "children"),
        Input("upload-targets", "contents"),
        Input("export-urdf", "n_clicks"),
        Input("export-ur", "n_clicks"),
        State("upload-targets", "filename"),
        State("targets-unit", "value"),
        State("targets-frame", "value"),
        State("cal-run-id", "data"),
        prevent_initial_call=True,
    )
    def compensate_or_export(targets, _urdf, _ur, filename, unit, frame, run_id):
        from dash import callback_context

        from robocal.identify.calibrate import CalibrationResult

        trigger = callback_context.triggered_id
        if run_id is None or not (workdir / "runs" / run_id / "result.json").is_file():
            return no_update, html.Span("calibrate first", className="error")
        result = CalibrationResult.load(workdir / "runs" / run_id)
        try:
            if trigger == "upload-targets":
                return _compensate(result, targets, filename, unit, frame)
            if trigger == "export-urdf":
                from robocal.compensate.export import export_urdf

                ex, missing = export_urdf(result)
                notes = "; ".join(m.note for m in missing) or "everything calibrated is carried"
                return {"content": ex.text, "filename": f"{result.model.name}_calibrated.urdf"}, notes
            from robocal.compensate.export import export_ur_kinematics

            kin = export_ur_kinematics(result)
            return {"content": kin.to_yaml(), "filename": "default_kinematics.yaml"}, "UR kinematics written"
        except ValueError as err:
            return no_update, html.Span(str(err), className="error")


def _compensate(result, contents: str, filename: str | None, unit: str, frame: str):
    import robocal as rc
    from robocal.compensate.commands import read_targets

    name = Path(filename or "targets.csv").name
    with tempfile.TemporaryDirectory(prefix="robocal-gui-") as tmp:
        path = Path(tmp) / name
        atomic_write_bytes(path, _decode_bytes(contents))
        try:
            targets = read_targets(path, length_unit=unit)
        except ValueError as err:
            raise ValueError(str(err).replace(str(path), name)) from None
    comp = rc.compensate(result, targets.values, names=targets.names, frame=frame)
    s = comp.summary()
    before, after = s["error_before_mm"], s["error_after_mm"]
    message = (
        f"{comp.message}; predicted error mean {before['mean'] or float('nan'):.4f} → "
        f"{after['mean'] or float('nan'):.4f} mm (compensated commands downloaded)"
    )
    return {"content": comp.to_csv(), "filename": f"{Path(name).stem}_compensated.csv"}, message
