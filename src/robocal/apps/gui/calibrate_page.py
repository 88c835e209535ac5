"""The calibration page: measurement file, reader options, model, method, run, results.

The file is read with :func:`rc.read_measurements` on every change of an option (the
preview shows the parsed table in mm and degrees, or the reader's message with its
row and column); a run is a :class:`robocal.apps.gui.jobs.CalibrationJob` in a child
process, polled by a ``dcc.Interval``; the results are read back with
``CalibrationResult.load`` and shown with ``rc.validate``; the report, the
compensation (``rc.compensate_targets``) and the exports (``robocal.compensate.export``) work
on the saved result.
"""

from __future__ import annotations

import uuid
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from dash import Dash, Input, Output, State, dcc, html, no_update

from robocal.apps.gui import columns_view, constraint_view, export_page, mixed_files, program_view, runs_page
from robocal.apps.gui.calibrate_views import PREVIEW_ROWS as PREVIEW_ROWS
from robocal.apps.gui.calibrate_views import (
    decode_bytes,
    parse_float,
    preview_table,
    problems_view,
    radio,
    raw_head,
    read,
    row,
    text_input,
)
from robocal.apps.gui.columns_view import gui_words
from robocal.apps.gui.constraint_job import ConstraintOptions
from robocal.apps.gui.jobs import MAX_UPLOAD_BYTES, CalibrationJob, JobRunner, public_text, read_options
from robocal.outdir import atomic_write_bytes, atomic_write_text

__all__ = ["RUN_STATES", "layout", "register"]


def layout(catalog: Sequence[str]) -> html.Div:
    """The calibration page."""
    reader, model, after = _reader_fieldset(), _model_fieldset(catalog), export_page.fieldset()
    return html.Div(
        [
            html.Div([reader, html.Div(id="csv-preview")], className="left"),
            html.Div(
                [
                    constraint_view.fieldset(),
                    model,
                    html.Div(id="cal-results"),
                    after,
                    program_view.fieldset(),
                ],
                className="right",
            ),
            # fires once per arming (max_intervals = n_intervals + 1): polls never overlap
            dcc.Interval(id="cal-poll", interval=400, max_intervals=0),
            dcc.Interval(id="runs-refresh", interval=3000),
            dcc.Store(id="session", storage_type="session"),
            dcc.Store(id="cal-run-id", storage_type="session"),
            dcc.Store(id="cal-phase"),
            dcc.Store(id="cal-finished"),
            dcc.Store(id="csv-upload"),
            dcc.Store(id="csv-file", storage_type="session"),
            dcc.Store(id="column-header"),  # the file's header as the mapping read it
            dcc.Store(id="column-renames", storage_type="session"),  # the mapping as columns=
            dcc.Download(id="cal-download"),
        ],
        className="page",
    )


def _reader_fieldset() -> html.Fieldset:
    # the reader's text options: re-read once the typing pauses
    return html.Fieldset(
        [
            html.Legend("measurement file and reader options"),
            dcc.Upload(html.Button("open measurement CSV"), id="upload-csv"),
            html.Span(id="csv-name", className="hint"),
            mixed_files.controls(),
            row("lengths", radio("opt-length", ("m", "mm", "um"), "m")),
            row("angles", radio("opt-angle", ("rad", "deg"), "rad")),
            row("separator", radio("opt-sep", ("auto", ";", ",", "tab", "space"), "auto")),
            row("decimal mark", radio("opt-decimal", (".", ","), ".")),
            row(
                "orientation",
                text_input("opt-orientation", "auto", "12em", debounce=0.5),
                "auto | none | quaternion | rotvec | euler:SEQ[:deg|rad]",
            ),
            html.Div(
                [
                    html.Span("columns", className="lab"),
                    html.Span(
                        "what each column of the file holds (guessed from the header)", className="hint"
                    ),
                ],
                className="opt",
            ),
            html.Div(id="column-map"),
            html.Div(id="column-message", className="message"),
            row("incomplete rows", radio("opt-incomplete", ("error", "drop"), "error")),
            row("joint limits", radio("opt-limits", ("error", "warn", "ignore"), "error")),
        ]
    )


def _model_fieldset(catalog: Sequence[str]) -> html.Fieldset:
    return html.Fieldset(
        [
            html.Legend("model and method"),
            row(
                "robot",
                dcc.RadioItems(
                    id="cal-model",
                    options=[{"label": "the model built on the builder page", "value": "@built"}]
                    + [{"label": n, "value": n} for n in catalog],
                    value=None,
                    inline=True,
                    persistence=True,
                    persistence_type="session",
                ),
                "catalog robots: their complete model (rc.calibration_model)",
            ),
            row("measure", radio("cal-measure", ("auto", "position", "pose"), "auto")),
            row("method", radio("cal-method", ("lm", "pinv", "bounded", "influence"), "lm")),
            row(
                "model choice",
                radio("cal-residual", ("auto", "none", "joint_fourier"), "auto"),
                "auto: cross-validation chooses compliance and learned joint angle errors",
            ),
            row(
                "calibration poses",
                text_input("cal-train-n", "100", "6em"),
                "random rows to calibrate on; the rest are held out (empty: all rows)",
            ),
            row("seed", text_input("cal-seed", "0", "4em")),
            row(
                "tool start mm",
                text_input("cal-tool", "", "10em"),
                "x, y, z of the measured point from the flange (empty: fitted from zero)",
            ),
            row(
                "device noise mm",
                text_input("cal-noise", "", "6em"),
                "1σ per axis, for the fit-to-noise test (empty: not tested)",
            ),
            dcc.Checklist(
                id="cal-compliance",
                options=[{"label": "identify joint compliance", "value": "yes"}],
                persistence=True,
                persistence_type="session",
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
            html.H4("runs"),
            html.Div(id="run-list"),
        ]
    )


# ----------------------------------------------------------------------- callbacks
def register(app: Dash, workdir: Path) -> None:
    """The calibration page's callbacks; files live in ``workdir`` (uploads, runs)."""
    runner = JobRunner(workdir / "runs")
    app.server.extensions["robocal_runner"] = runner  # for shutting down (serve)
    page = _Page(workdir, runner)
    _register_data(app, page)
    runs_page.register(app, runner, workdir, RUN_STATES, lambda session, *a: _start_run(page, session, *a))
    export_page.register(app, workdir)
    program_view.register(app, workdir)


_READER_INPUTS = (
    ("opt-length", "value"),
    ("opt-angle", "value"),
    ("opt-sep", "value"),
    ("opt-decimal", "value"),
    ("column-renames", "data"),
    ("opt-orientation", "value"),
    ("opt-incomplete", "value"),
    ("opt-limits", "value"),
)

#: the page's values a run starts from (after the session id)
RUN_STATES = (
    *[State(*i) for i in _READER_INPUTS],
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
    State("con-distances", "data"),
    State("con-level", "value"),
    State("more-files", "data"),
)

# the upload's size is checked in the browser: a file over the limit never reaches the server
# (which would answer HTTP 413 where the page cannot show it) and the page says why
_CHECK_UPLOAD = """
function(contents, filename) {
    if (!contents) { return window.dash_clientside.no_update; }
    if (contents.length > %d) {
        return {"error": (filename || "the file") + ": larger than the GUI's limit of %g MB; "
                + "use the command line (robocal calibrate)"};
    }
    return {"contents": contents, "filename": filename};
}
"""


def _register_data(app: Dash, page: _Page) -> None:
    """Upload of the measurement file and its preview with the reader options."""
    encoded = (MAX_UPLOAD_BYTES + 2) // 3 * 4 + 200  # base64 and its data: header
    app.clientside_callback(
        _CHECK_UPLOAD % (encoded, MAX_UPLOAD_BYTES / 2**20),
        Output("csv-upload", "data"),
        Input("upload-csv", "contents"),
        State("upload-csv", "filename"),
        prevent_initial_call=True,
    )

    @app.callback(Output("csv-file", "data"), Input("csv-upload", "data"), prevent_initial_call=True)
    def upload(checked):
        if not checked or "error" in checked:
            return {"error": (checked or {}).get("error", "the upload could not be read")}
        return _upload(page, checked["contents"], checked["filename"])

    @app.callback(Output("csv-name", "children"), Input("csv-file", "data"))
    def file_name(file):
        if not file:
            return ""
        if "error" in file:
            return html.Span(file["error"], className="error", id="upload-error")
        return file["label"]

    columns_view.register(app, page.data_file)
    mixed_files.register(app, lambda contents, name: _upload(page, contents, name))

    @app.callback(Output("con-fieldset", "style"), Output("con-kind", "children"), Input("csv-file", "data"))
    def constraint_options(file):
        kind = constraint_view.constraint_file_kind(page.data_file((file or {}).get("token")))
        if kind is None:
            return {"display": "none"}, ""
        words = {"point": "fixed points (ball in socket)", "plane": "plane touches",
                 "distance": "known distances", "tilt": "inclinometer readings (tilt)"}  # fmt: skip
        return {}, f"the file holds {words.get(kind, kind)} (its columns): calibrated without a tracker"

    @app.callback(
        Output("csv-preview", "children"),
        Input("csv-file", "data"),
        *[Input(*i) for i in _READER_INPUTS],
        Input("cal-model", "value"),
        State("built-model", "data"),
    )
    def preview(file, *args):
        return _preview(page, (file or {}).get("token"), *args)


class _Page:
    """The calibration page's server state: its working directory and its job runner."""

    def __init__(self, workdir: Path, runner: JobRunner) -> None:
        self.workdir, self.runner = workdir, runner

    def model_for(self, choice: str | None, built: dict | None, measure: str):
        import robocal as rc

        if choice is None:
            return None
        if choice == "@built":
            if not built:
                raise ValueError("no model built yet: build one on the builder page (build → model file)")
            path = self.workdir / f"built-{uuid.uuid4().hex[:12]}.yaml"  # one per request: tabs
            atomic_write_text(path, built["text"])
            try:
                return rc.load_model(path)
            finally:
                path.unlink(missing_ok=True)
        return rc.calibration_model(choice, "pose" if measure == "pose" else "position")

    def data_file(self, token: str | None) -> Path | None:
        """The uploaded file of this page (each upload has its own directory)."""
        if not token:
            return None
        path = self.workdir / "data" / token
        return path if path.is_file() and path.parent.parent == self.workdir / "data" else None


def _upload(page: _Page, contents, filename):
    try:
        data = decode_bytes(contents)
    except ValueError as err:
        return {"error": str(err)}
    name = Path(filename or "measurements.csv").name or "measurements.csv"
    token = f"{uuid.uuid4().hex[:12]}/{name}"
    target = page.workdir / "data" / token
    target.parent.mkdir(parents=True)
    atomic_write_bytes(target, data)
    return {"token": token, "label": f"{name} ({len(data):,} bytes)"}


def _preview(page: _Page, token, *args):
    *options, choice, built = args
    path = page.data_file(token)
    if path is None:
        return html.Div("open a measurement CSV", className="hint")
    if constraint_view.constraint_file_kind(path) is not None:
        try:
            model = page.model_for(choice, built, "position")
        except ValueError as err:
            return html.Div(str(err), className="error")
        dof = None if model is None else model.dof
        return [
            *constraint_view.preview(path, dof, options[1]),
            html.H4("the file's first lines"),
            raw_head(path),
        ]
    try:
        opts = _reader_options(options)
        model = page.model_for(choice, built, "position")
        data, warns = read(path, opts, model)
    except ValueError as err:
        return [problems_view(err, path), html.H4("the file's first lines"), raw_head(path)]
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
        *[html.Div(f"warning: {gui_words(w)}", className="warning") for w in warns],
        preview_table(data, None if model is None else model.joint_types),
        html.H4("the file's first lines"),
        raw_head(path),
    ]


def _reader_options(values: Sequence[Any]) -> dict[str, Any]:
    """The reader's keyword options from the page's values (in :data:`_READER_INPUTS`'
    order); ValueError with the column mapping's problem when it has one."""
    length, angle, sep, decimal, columns, orientation, incomplete, limits = values
    columns = columns or {}
    if "error" in columns:
        raise ValueError(columns["error"])
    return read_options(length, angle, sep, decimal, columns.get("columns"), orientation, incomplete, limits)


def _start_run(page: _Page, session: str, *args: Any) -> tuple:
    """Check the page's values and queue the run: ``(run_id, status)``, or ``(no_update, the
    error)`` when a value is wrong."""
    choice, built, measure, method, residual, train_n, seed, tool, noise, compliance, file = args[8:19]
    path = page.data_file((file or {}).get("token"))
    if constraint_view.constraint_file_kind(path) is not None or (path is not None and args[21]):
        assert path is not None  # a constraint file is a file
        return _start_constraint_run(page, session, path, args)  # several files: one fit, as the CLI
    try:
        options = _reader_options(args[:8])
        if path is None:
            raise ValueError("open a measurement CSV first")
        if choice is None:
            raise ValueError("choose the robot (its model)")
        effective = measure
        if measure == "auto":
            data, _ = read(path, options)
            effective = "pose" if data.orientation is not None else "position"
        model = page.model_for(choice, built, effective)
        n = parse_float(train_n, "calibration poses")
        if n is not None and (n != int(n) or n < 1):
            raise ValueError(f"calibration poses: a whole number, not {train_n!r}")
        s = parse_float(seed, "seed")
        tool_mm = None
        if (tool or "").strip():
            from robocal.spatial import parse_vector

            try:
                tool_mm = tuple(parse_vector(tool, 3))
            except ValueError as err:
                raise ValueError(f"tool start: {err}, in mm, e.g. 0, 0, 109 (not {tool!r})") from None
        noise_mm = parse_float(noise, "device noise")
        if noise_mm is not None and not noise_mm > 0:
            raise ValueError("device noise: a positive standard deviation in mm")
    except ValueError as err:
        message = gui_words(public_text(str(err), page.workdir))
        return no_update, html.Span(message, className="error", id="cal-error")
    from robocal.model.files import save_model

    run_id = uuid.uuid4().hex[:12]
    (page.workdir / "runs").mkdir(exist_ok=True)
    model_file = save_model(model, page.workdir / "runs" / f"{run_id}.model.yaml")
    job = CalibrationJob(
        data=path,
        reader=options,
        model_file=model_file,
        out=page.workdir / "runs" / run_id,
        method=method,
        residual=residual,
        train_n=None if n is None else int(n),
        seed=0 if s is None else int(s),
        tool_mm=tool_mm,
        noise_mm=noise_mm,
        compliance=bool(compliance),
        measure=None if measure == "auto" else measure,
    )
    page.runner.start(job, run_id, session, model.name)
    return run_id, f"calibrating {model.name} on {path.name} ..."


def _start_constraint_run(page: _Page, session: str, path: Path, args: Sequence[Any]) -> tuple:
    """Queue a constraint file's run (the robot's complete position model for a catalog
    robot, the built model's chain as it is): ``(run_id, status)`` or ``(no_update, error)``."""
    import robocal as rc
    from robocal.model.files import save_model
    from robocal.workflow.constraints import constraint_model

    choice, built, *_ = args[8:]
    rows, level, added = args[19], args[20], args[21]
    try:
        options = _reader_options(args[:8])
        if choice is None:
            raise ValueError("choose the robot (its model)")
        distances = constraint_view.distances_of(rows)
        more = mixed_files.more_paths(added, page.data_file)
        catalog = choice != "@built"  # the CLI's choice of model and of the mounts' frames
        robot = rc.robot(choice) if catalog else page.model_for(choice, built, "position")
        model, frames = constraint_model(robot, (path, *more), from_catalog=catalog)
    except ValueError as err:
        message = gui_words(public_text(str(err), page.workdir))
        return no_update, html.Span(message, className="error", id="cal-error")
    run_id = uuid.uuid4().hex[:12]
    (page.workdir / "runs").mkdir(exist_ok=True)
    model_file = save_model(model, page.workdir / "runs" / f"{run_id}.model.yaml")
    frames_file = (
        None if frames is None else save_model(frames, page.workdir / "runs" / f"{run_id}.frames.yaml")
    )
    kind = ConstraintOptions(distances, int(level or 2), more, frames_file)
    job = CalibrationJob(data=path, reader=options, model_file=model_file, out=page.workdir / "runs" / run_id,
                         constraints=kind)  # fmt: skip
    page.runner.start(job, run_id, session, model.name)
    names = ", ".join(p.name for p in (path, *more))
    return run_id, f"calibrating {model.name} on {names} (constraints) ..."
