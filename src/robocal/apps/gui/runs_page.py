"""The calibration page's runs: start, follow, cancel, list and re-open them.

Each browser tab has a session id and the id of the run it follows, both in the tab's
session storage (``dcc.Store(storage_type="session")``): a reload follows the same run,
another tab follows its own.  The status poll is cheap (stage, share done, seconds from
:meth:`JobRunner.state`) and never overlaps itself: the ``dcc.Interval`` fires once
(``max_intervals = n_intervals + 1``) and each answer arms the next one, so a slow answer
under load delays the next poll instead of piling polls up.  The results view is built
once per run on the server (:class:`ResultsCache`) and sent once, when the poll first
sees the result saved.
"""

from __future__ import annotations

import threading
import time
import uuid
from pathlib import Path
from typing import Any

from dash import ALL, Dash, Input, Output, State, callback_context, html, no_update

from robocal.apps.gui import constraint_view
from robocal.apps.gui.calibrate_views import report_links, results_view
from robocal.apps.gui.jobs import JobRunner, JobState, RunInfo, public_text

__all__ = ["ResultsCache", "register"]


class ResultsCache:
    """The results view of each finished run, built once (the run folders do not change)."""

    def __init__(self, runs: Path, workdir: Path, keep: int = 8) -> None:
        self.runs, self.workdir, self.keep = runs, workdir, keep
        self._lock = threading.Lock()
        self._views: dict[str, Any] = {}

    def view(self, run_id: str) -> Any:
        with self._lock:  # one build per run even when two tabs ask at once
            if run_id not in self._views:
                try:
                    self._views[run_id] = _results_view(self.runs / run_id)
                except (OSError, ValueError, KeyError) as err:
                    message = public_text(f"cannot show the result: {err}", self.workdir)
                    return html.Span(message, className="error")
                while len(self._views) > self.keep:  # the oldest first (dicts keep order)
                    self._views.pop(next(iter(self._views)))
            return self._views[run_id]


def _results_view(out: Path) -> Any:
    """A tracker calibration's view, or a constraint calibration's (its kind's figures)."""
    if (out / "constraints.json").is_file():
        return constraint_view.results_view(out)
    return results_view(out)


def register(app: Dash, runner: JobRunner, workdir: Path, run_states: tuple, start_run) -> None:
    """The callbacks of the runs; ``start_run(session, *values of run_states)`` validates the
    page and returns ``(run_id or no_update, status)``."""
    cache = ResultsCache(runner.runs, workdir)

    @app.callback(Output("session", "data"), Input("session", "modified_timestamp"), State("session", "data"))
    def session(_ts, current):
        return no_update if current else uuid.uuid4().hex

    @app.callback(
        Output("cal-run-id", "data"),
        Output("cal-status", "children", allow_duplicate=True),
        Output("cal-results", "children", allow_duplicate=True),
        Output("cal-report", "children", allow_duplicate=True),
        Input("cal-run", "n_clicks"),
        State("session", "data"),
        *run_states,
        prevent_initial_call=True,
    )
    def run(_n, session_id, *args):
        run_id, status = start_run(session_id or "", *args)
        cleared = no_update if run_id is no_update else ""
        return run_id, status, cleared, cleared

    @app.callback(
        Output("cal-bar", "style"),
        Output("cal-status", "children"),
        Output("cal-report", "children"),
        Output("cal-finished", "data"),
        Output("cal-phase", "data"),
        Output("cal-poll", "max_intervals"),
        Input("cal-poll", "n_intervals"),
        Input("cal-run-id", "data"),  # set by a run, an open, or the tab's storage on a reload
        State("cal-phase", "data"),
        prevent_initial_call=True,
    )
    def poll(n, run_id, phase):
        return _poll(runner, workdir, n or 0, run_id, phase)

    @app.callback(Output("cal-results", "children"), Input("cal-finished", "data"), prevent_initial_call=True)
    def results(run_id):
        return cache.view(run_id) if run_id else no_update

    @app.callback(
        Output("cal-status", "children", allow_duplicate=True),
        Input("cal-cancel", "n_clicks"),
        State("cal-run-id", "data"),
        prevent_initial_call=True,
    )
    def cancel(_n, run_id):
        # runner.cancel stops the run before it returns: say "cancelled" as the poll does, so
        # the page ends there whichever of the two answers the browser applies last (it
        # showed "cancelling ..." for good when the poll's answer came first)
        return "cancelled" if runner.cancel(run_id) else "nothing is running"

    @app.callback(
        Output("run-list", "children"),
        Input("runs-refresh", "n_intervals"),
        Input("cal-phase", "data"),
        State("session", "data"),
        State("cal-run-id", "data"),
    )
    def run_list(_n, _phase, session_id, run_id):
        return _run_table(runner.runs_list(), session_id, run_id)

    @app.callback(
        Output("cal-run-id", "data", allow_duplicate=True),
        Output("cal-results", "children", allow_duplicate=True),
        Input({"kind": "open-run", "run": ALL}, "n_clicks"),
        prevent_initial_call=True,
    )
    def reopen(clicks):
        trigger = callback_context.triggered_id
        if not trigger or not any(clicks):  # the list was redrawn, nothing clicked
            return no_update, no_update
        return trigger["run"], ""


def _poll(runner: JobRunner, workdir: Path, n: int, run_id: str | None, phase: str | None) -> tuple:
    """Stage, bar and seconds of the tab's run; the report links and the result once."""
    state = runner.state(run_id)
    if state is None:
        text = "" if run_id is None else "that run is not on this server any more"
        return {"width": "0%"}, text, "", no_update, None, n
    now = f"{run_id}:{state.status}:{state.saved}"
    changed = now != phase
    report: Any = no_update
    if changed and run_id is not None:
        constraint = (runner.runs / run_id / "constraints.json").is_file()
        report = report_links(run_id, state.status == "done", constraint) if state.saved else ""
    finished = run_id if changed and state.saved else no_update
    return _bar(state), _status(state, workdir), report, finished, now, n + 1 if state.active else n


def _bar(state: JobState) -> dict[str, str]:
    bar = {"width": f"{100 * state.shown_fraction(time.monotonic()):.0f}%"}
    if state.status in ("error", "cancelled", "interrupted"):
        return {"width": "0%"}
    return bar | {"animation": "pulse 1s infinite"} if state.active else bar


def _status(state: JobState, workdir: Path) -> list[Any]:
    warns = [html.Div(f"warning: {w}", className="warning") for w in state.warnings[-5:]]
    if state.active:
        return [f"{state.text} ({state.seconds:.0f} s)", _stage_list(state), *warns]
    if state.status == "done":
        return [f"done in {state.seconds:.1f} s", _stage_list(state), *warns]
    if state.status == "interrupted":
        return ["interrupted: the server stopped during this run; calibrate again"]
    if state.status == "cancelled":
        return ["cancelled"]
    error = public_text(state.error or "failed", workdir)
    return [html.Span(error, className="error", id="cal-error"), *warns]


def _stage_list(state: JobState) -> html.Div:
    """The stages reached, in order, each with its seconds (the last one's so far)."""
    times = [t for *_, t in state.stages] + [state.seconds]
    items = [
        html.Span(
            f"{text} {times[i + 1] - times[i]:.1f} s",
            className="stage" + (" current" if state.active and i == len(state.stages) - 1 else ""),
            **_data_attributes(stage=key),
        )
        for i, (key, text, _) in enumerate(state.stages)
    ]
    return html.Div(items, id="cal-stages", className="stages")


def _data_attributes(**values: str) -> dict[str, Any]:
    """``data-*`` attributes of an html component (``run="x"`` -> ``data-run="x"``)."""
    return {f"data-{k}": v for k, v in values.items()}


def _run_table(infos: list[RunInfo], session_id: str | None, current: str | None) -> Any:
    if not infos:
        return html.Div("no runs yet", className="hint")
    head = html.Tr([html.Th(h) for h in ("started", "data", "robot", "status", "s", "")])
    rows = [
        html.Tr(
            [
                html.Td(time.strftime("%H:%M:%S", time.localtime(i.created))),
                html.Td(i.data_name),
                html.Td(i.robot),
                html.Td(
                    _status_cell(i) + (" (this tab)" if i.session == session_id else ""),
                    className="run-status",
                ),
                html.Td(f"{i.seconds:.1f}" if i.seconds else "", className="num"),
                html.Td(
                    "shown"
                    if i.run_id == current
                    else html.Button("open", id={"kind": "open-run", "run": i.run_id}, className="open-run")
                ),
            ],
            **_data_attributes(run=i.run_id),
        )
        for i in infos[:20]
    ]
    return html.Table([html.Thead(head), html.Tbody(rows)], id="run-table")


def _status_cell(info: RunInfo) -> str:
    """The run's status; a failed run's with its message (text: React escapes it)."""
    return f"failed: {info.error}" if info.status == "error" and info.error else info.status
