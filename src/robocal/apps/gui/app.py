"""The ``robocal gui`` web app: Dash on localhost, every script served from installed packages.

Dash serves its renderer, React and plotly.js (bundled with ``dash.dcc``) from the
installed Python packages (``serve_locally``); there are no external stylesheets,
fonts or scripts, so the app works without a network and no request leaves the
machine (the browser tests fail on any request to another host).  The app's files
(uploads, calibration results, reports) live in a temporary directory removed on exit.
"""

from __future__ import annotations

import atexit
import shutil
import tempfile
import threading
import webbrowser
from pathlib import Path

from robocal.apps.gui.jobs import MAX_UPLOAD_BYTES

__all__ = ["MAX_UPLOAD_BYTES", "create_app", "serve"]

#: the largest request body (bytes): one upload in base64 and the page's other values
MAX_REQUEST_BYTES = MAX_UPLOAD_BYTES * 4 // 3 + 1024 * 1024

CSS = """
body { font-family: system-ui, sans-serif; margin: 0; color: #222; font-size: 14px; }
header { background: #1f3b57; color: white; padding: 0.5rem 1rem; }
header b { font-size: 1.2rem; margin-right: 1rem; }
.page { display: flex; gap: 1rem; padding: 0.5rem 1rem; align-items: flex-start; }
.left, .right { flex: 1 1 50%; min-width: 0; overflow-x: auto; }
.toolbar { margin: 0.4rem 0; display: flex; gap: 0.4rem; align-items: center; flex-wrap: wrap; }
.toolbar > div { display: inline-block; }
button { padding: 0.25rem 0.6rem; cursor: pointer; }
button.primary { background: #1f77b4; color: white; border: 1px solid #1f77b4; }
/* the builder's joint table: one table, so every heading sits over its column at any width;
   each box is as wide as its text (field-sizing), so no typed or computed number is cut */
table.joint-table { border-collapse: collapse; margin: 0.2rem 0; font-size: 0.9rem; }
table.joint-table th { color: #555; font-weight: normal; font-size: 0.85rem; padding: 0.1rem 0.2rem; }
table.joint-table td { border: none; padding: 0.1rem 0.2rem; vertical-align: middle; }
table.joint-table tr.subhead th { padding-top: 0.5rem; }
table.joint-table tr.msgrow td { padding: 0; }
table.joint-table td.acts { white-space: nowrap; }
.rownum { text-align: right; color: #555; }
.field { font-family: inherit; }
/* Dash's box has size containment (it never grows with its text): the form's boxes do */
.dash-input-container.field { width: auto; container-type: normal; height: 28px; }
.dash-input-container.field input { field-sizing: content; flex: 0 0 auto; min-width: 4ch;
  padding: 0.1rem 0.3rem; font-variant-numeric: tabular-nums; }
.invalid, .invalid input { border-color: #d62728 !important; background: #fdecea !important; }
.dash-input-container.invalid { outline: 2px solid #d62728; }
.rowmsg { color: #d62728; font-size: 0.85rem; margin-left: 2.6em; }
.rowmsg:empty { display: none; }
.type, .type label { display: inline-flex; } .type label, .catalog label { margin-right: 0.5rem; }
.joint-row .dash-input-container { box-sizing: border-box; }
table.colmap td { padding: 0.05rem 0.4rem; vertical-align: middle; }
table.colmap .role { min-width: 11em; } table.colmap td.colname { font-family: ui-monospace, monospace; }
td.params .param { display: inline-block; margin-right: 0.7rem; white-space: nowrap; }
/* the builder below 1500 px: the table above the view, each the page's full width */
@media (max-width: 1500px) {
  .page.builder { flex-wrap: wrap; }
  .page.builder > .left, .page.builder > .right { flex: 1 1 100%; }
}
/* the other pages below 1200 px (1024 px screenshots: hints and selects were cut at each
   column's right edge): their two columns one above the other */
@media (max-width: 1200px) {
  .page:not(.builder) { flex-wrap: wrap; }
  .page:not(.builder) > .left, .page:not(.builder) > .right { flex: 1 1 100%; min-width: 0; }
}
.meta label { margin-right: 1rem; }
.note, .hint { color: #666; font-size: 0.85rem; margin-left: 0.5rem; }
.message { margin: 0.3rem 0; min-height: 1.2em; }
.error { color: #b00020; font-weight: 600; } .warning { color: #8a5a00; } .ok { color: #1a7f37; }
.bad { color: #b00020; }
.count { font-weight: 600; margin: 0.3rem 0; }
/* the builder's joint sliders: two or more per line, each name beside its track */
.sliders { display: grid; grid-template-columns: repeat(auto-fill, minmax(280px, 1fr)); gap: 0 1.5rem;
  padding-right: 1.25rem; }
.sliders > .dim { grid-column: 1 / -1; } .slider-row { display: flex; align-items: center; }
.slider-label { flex: 0 0 7.5em; font-size: 0.85rem; } .slider-track { flex: 1 1 auto; min-width: 0; }
table { border-collapse: collapse; font-size: 0.85rem; margin: 0.3rem 0; }
td, th { border-bottom: 1px solid #ddd; padding: 0.15rem 0.45rem; text-align: left; }
td.num { text-align: right; font-variant-numeric: tabular-nums; }
td.eq { font-family: ui-monospace, monospace; font-size: 0.8rem; }
.dim { color: #999; }
fieldset { border: 1px solid #ccc; margin: 0.4rem 0; }
.opt { margin: 0.2rem 0; } .opt .lab { display: inline-block; width: 9.5em; color: #333; }
.opt label { margin-right: 0.6rem; }
.progress { height: 14px; background: #eee; border-radius: 7px; overflow: hidden; margin: 0.4rem 0; }
.stages { font-size: 0.8rem; color: #555; } .stage { margin-right: 0.8rem; }
.stage::before { content: "✓ "; color: #1a7f37; } .stage.current::before { content: "▸ "; color: #1f77b4; }
.bar { height: 100%; width: 0%; background: #1f77b4; transition: width 0.3s; }
@keyframes pulse { 0% { opacity: 1; } 50% { opacity: 0.55; } 100% { opacity: 1; } }
pre.cv { font-size: 0.78rem; background: #f6f6f6; padding: 0.3rem; white-space: pre-wrap; }
#columns-cli { overflow-wrap: anywhere; }
pre.raw { background: #f6f6f6; padding: 0.4rem; font-size: 0.75rem; overflow-x: auto; }
.big { font-size: 1.05rem; font-weight: 600; margin: 0.3rem 0; }
"""

INDEX = (
    """<!DOCTYPE html>
<html lang="en"><head>{%metas%}<title>robocal</title>{%favicon%}{%css%}<style>"""
    + CSS
    + """</style>
</head><body>{%app_entry%}<footer>{%config%}{%scripts%}{%renderer%}</footer></body></html>"""
)


def create_app(workdir: Path):
    """The Dash app; its files (uploads, results) in ``workdir``."""
    from dash import Dash, dcc, html
    from flask import abort, send_from_directory

    import robocal as rc
    from robocal.apps.gui import builder_page, calibrate_page, poses_page

    app = Dash(
        __name__,
        title="robocal",
        serve_locally=True,
        external_scripts=[],
        external_stylesheets=[],
        assets_folder=str(workdir / "assets"),  # none: the style is in the page
        suppress_callback_exceptions=True,
        update_title="",  # the tab title stays "robocal" while callbacks run
        compress=True,  # flask-compress: the 6 MB of JavaScript travel gzipped
    )
    app.index_string = INDEX
    catalog = rc.robots()
    app.layout = html.Div(
        [
            html.Header(
                [html.B("robocal"), html.Span(f"calibration of serial robot arms · {rc.__version__}")]
            ),
            dcc.Store(id="built-model", storage_type="session"),  # survives a reload
            dcc.Tabs(
                id="tabs",
                value="builder",
                children=[
                    dcc.Tab(label="Model builder", value="builder", children=builder_page.layout(catalog)),
                    dcc.Tab(label="Pose planning", value="poses", children=poses_page.layout(catalog)),
                    dcc.Tab(label="Calibration", value="calibrate", children=calibrate_page.layout(catalog)),
                ],
            ),
        ]
    )
    builder_page.register(app)
    calibrate_page.register(app, workdir)
    poses_page.register(app)
    _bound_requests(app.server)
    _guard(app)
    runs = workdir / "runs"

    @app.server.route("/runs/<run_id>/<name>")
    def run_file(run_id: str, name: str):
        allowed = {"report.html", "model.yaml", "result.json", "constraints.json", "train.csv", "test.csv"}
        if name not in allowed or not run_id.isalnum() or not (runs / run_id / name).is_file():
            abort(404)
        return send_from_directory(runs / run_id, name)

    return app


def _bound_requests(server) -> None:
    """Cap request bodies (HTTP 413) and answer a request the app cannot handle (not JSON, no
    callback of that name, values no control can hold, such as a robot outside the catalog)
    with HTTP 400 and one line, logged in one line without a traceback."""
    from flask import jsonify, request
    from werkzeug.exceptions import HTTPException, RequestEntityTooLarge

    server.config["MAX_CONTENT_LENGTH"] = MAX_REQUEST_BYTES

    @server.errorhandler(RequestEntityTooLarge)
    def too_large(_err):
        mb = MAX_UPLOAD_BYTES / 2**20
        return jsonify(
            error=f"the upload is larger than the GUI's limit of {mb:g} MB; use the command line"
        ), 413

    @server.errorhandler(Exception)
    def refused(err: Exception):
        if isinstance(err, HTTPException):  # 404, 405, a body that is not JSON ...: as Flask words it
            return jsonify(error=err.description or err.name), err.code or 400
        text = str(err.args[0]) if isinstance(err, KeyError) and err.args else str(err)  # no quotes
        message = f"{type(err).__name__}: {text.splitlines()[0] if text else ''}"[:300]
        server.logger.warning("robocal gui: refused %s %s (%s)", request.method, request.path, message)
        return jsonify(error=f"the request could not be handled: {message}"), 400


#: the names this server answers to: a page of another site that resolves its own name to
#: 127.0.0.1 (DNS rebinding) or posts across sites is refused before any work starts
LOCAL_HOSTS = frozenset({"127.0.0.1", "localhost", "::1"})
#: the app's pages: scripts from the server only (the renderer's inline ones by hash; plotly
#: compiles some code, hence unsafe-eval), no frames of it anywhere, no other host reached
_CSP = (
    "default-src 'self'; script-src 'self' 'unsafe-eval' {hashes}; style-src 'self' 'unsafe-inline'; "
    "img-src 'self' data: blob:; font-src 'self' data:; connect-src 'self'; worker-src 'self' blob:; "
    "object-src 'none'; base-uri 'self'; form-action 'self'; frame-ancestors 'none'"
)
#: the saved report (one self-contained HTML file with plotly inline): nothing from anywhere
_REPORT_CSP = (
    "default-src 'none'; script-src 'unsafe-inline' 'unsafe-eval'; style-src 'unsafe-inline'; "
    "img-src data: blob:; font-src data:; frame-ancestors 'none'; form-action 'none'"
)


def _local(value: str | None) -> bool:
    """Whether a Host header or an Origin's host names this machine's loopback."""
    from urllib.parse import urlsplit

    if not value:
        return False
    try:
        host = urlsplit(value if "//" in value else f"//{value}").hostname
    except ValueError:
        return False
    return host in LOCAL_HOSTS


def _guard(app) -> None:
    """Refuse (HTTP 403) a request whose Host or Origin is not localhost; give every answer the
    security headers (CSP, frame-ancestors and X-Frame-Options, nosniff, no referrer)."""
    from flask import jsonify, request

    server = app.server
    policy = _CSP.format(hashes=" ".join(app.csp_hashes()))  # quoted already

    @server.before_request
    def check_origin():
        origin = request.headers.get("Origin")
        if not _local(request.host) or (origin is not None and not _local(origin)):
            return jsonify(error="refused: robocal gui answers pages of localhost only"), 403
        return None

    @server.after_request
    def headers(response):
        report = request.path.startswith("/runs/")
        response.headers["Content-Security-Policy"] = _REPORT_CSP if report else policy
        response.headers["X-Frame-Options"] = "DENY"
        response.headers["X-Content-Type-Options"] = "nosniff"
        response.headers["Referrer-Policy"] = "no-referrer"
        response.headers["Cross-Origin-Opener-Policy"] = "same-origin"
        return response


def serve(
    port: int = 8050, open_browser: bool = True, host: str = "127.0.0.1", workdir: Path | None = None
) -> None:
    """Run the app on ``host:port`` until Ctrl-C or SIGTERM; open the browser unless told not to.

    ``workdir``: where uploads, runs and results are kept across restarts (runs cut off by the
    stop are listed as interrupted by the next server); None: a temporary directory removed
    when the server stops."""
    import signal

    # Ctrl-C (SIGINT) stops the server even when it was started with SIGINT ignored (a
    # background job of a script inherits that): interrupting it is how it ends
    signal.signal(signal.SIGINT, signal.default_int_handler)
    # SIGTERM (kill, systemd, a closing terminal's job control) ends it the same way: the
    # runs are stopped and (without --workdir) the uploaded data removed in the finally below
    signal.signal(signal.SIGTERM, signal.default_int_handler)
    keep = workdir is not None
    if workdir is None:
        workdir = Path(tempfile.mkdtemp(prefix="robocal-gui-"))
        atexit.register(shutil.rmtree, workdir, ignore_errors=True)
    app = create_app(workdir)
    url = f"http://{host}:{port}/"
    print(f"robocal gui on {url} (Ctrl-C stops it)", flush=True)
    if open_browser:
        threading.Timer(1.0, webbrowser.open, args=(url,)).start()
    try:
        app.run(host=host, port=port, debug=False)
    except KeyboardInterrupt:
        pass  # the way it ends (Ctrl-C, SIGTERM): tidy up below, exit 0
    finally:
        runner = app.server.extensions["robocal_runner"]
        if keep:
            runner.interrupt_all()
        else:
            runner.cancel_all()
            shutil.rmtree(workdir, ignore_errors=True)
